"""Frames into the ECU core: malformed ones refused and counted, parameter frames acknowledged,
and the C codec and cantools agreeing on every frame of the DBC."""

from __future__ import annotations

import random
from typing import Any

import can
import pytest
from topdress.ecu._core import ffi, lib

from topdress.ecu import Ecu, EcuParams
from topdress.errors import EcuError, ProtocolError
from topdress.protocol import (
    DEFAULT_IDS,
    LATCHED_FAULTS,
    AckResult,
    Compare,
    EcuParamAck,
    Fault,
    PcCommand,
    Source,
    SpeedMode,
    database,
    decode,
    encode_command,
    encode_param_set,
    param,
    params,
)

CMD = DEFAULT_IDS.command
GOOD = bytes(encode_command(True, 3000, 200.0, 150.0, 6.5).data)


def _running_ecu() -> Ecu:
    ecu = Ecu()
    assert ecu.rx((CMD, GOOD), 0) == lib.TD_OK
    ecu.step_raw(10_000, 0, 0, 0, 0, 0)
    ecu.tx_raw()
    return ecu


# ---- malformed frames: counted, never acted on ------------------------------------------------


@pytest.mark.parametrize(
    ("frame", "code", "counter"),
    [
        ((0x185C6466, GOOD), lib.TD_E_UNKNOWN_ID, "rx_unknown_id"),
        ((DEFAULT_IDS.status, GOOD), lib.TD_E_UNKNOWN_ID, "rx_unknown_id"),  # its own status id
        (
            can.Message(arbitration_id=CMD & 0x7FF, data=GOOD, is_extended_id=False),
            lib.TD_E_UNKNOWN_ID,
            "rx_unknown_id",
        ),
        ((CMD, GOOD[:7]), lib.TD_E_LENGTH, "rx_bad_length"),
        ((CMD, b""), lib.TD_E_LENGTH, "rx_bad_length"),
        ((CMD, GOOD + bytes(4)), lib.TD_E_LENGTH, "rx_bad_length"),  # a CAN FD frame
        ((CMD, bytes([0x05]) + GOOD[1:]), lib.TD_E_RANGE, "rx_out_of_range"),  # StartStop 5
        ((CMD, GOOD[:7] + bytes([252])), lib.TD_E_RANGE, "rx_out_of_range"),  # GNSS 25.2
        (
            (CMD, GOOD[:3] + (60001).to_bytes(2, "little") + GOOD[5:]),
            lib.TD_E_RANGE,
            "rx_out_of_range",
        ),
        (
            (CMD, bytes([0x0A]) + (6001).to_bytes(2, "little") + GOOD[3:]),
            lib.TD_E_RANGE,
            "rx_out_of_range",
        ),
    ],
)
def test_malformed_frames_are_counted_and_ignored(
    frame: can.Message | tuple[int, bytes], code: int, counter: str
) -> None:
    ecu = Ecu()
    assert ecu.rx((CMD, bytes(encode_command(False, 1000, 50.0, 40.0, 3.0).data)), 0) == 0
    before = ecu.state
    assert ecu.rx(frame, 5000) == code
    after = ecu.state
    assert not after.running  # a rejected start never starts
    assert (after.rate_kg_ha, after.fan_target_rpm, after.v_gnss_kmh) == (
        before.rate_kg_ha,
        before.fan_target_rpm,
        before.v_gnss_kmh,
    )
    counts = ecu.counters
    assert getattr(counts, counter) == 1 and counts.rx_ok == 1
    # and the PC sees the count in EcuSpeeds.RxRejected
    ecu.step_raw(100_000, 0, 0, 0, 0, 0)
    speeds = [decode(f) for f in ecu.tx_raw() if f[0] == DEFAULT_IDS.speeds]
    assert speeds[-1].rx_rejected == 1  # type: ignore[union-attr]


def test_rejected_frames_never_reset_the_command_timeout() -> None:
    ecu = _running_ecu()
    bad = (CMD, bytes([0x05]) + GOOD[1:])
    for k in range(1, 200):
        t = 10_000 + k * 10_000
        ecu.rx(bad, t)
        ecu.step_raw(t, 0, 0, 0, 0, 0)
    assert Fault.CMD_TIMEOUT in ecu.state.faults
    assert ecu.counters.rx_out_of_range == 199


def test_frame_ids_outside_29_bits_are_an_error() -> None:
    with pytest.raises(ProtocolError, match="identifier"):
        Ecu().rx((1 << 29, GOOD), 0)
    with pytest.raises(ProtocolError, match="identifier"):
        Ecu().rx((-1, GOOD), 0)


def test_transmit_queue_overflow_is_counted() -> None:
    ecu = _running_ecu()
    for k in range(2, 102):  # 1 s without draining: 10 periods x 7 frames into 16 slots
        ecu.step_raw(k * 10_000, 0, 0, 0, 0, 0)
    assert len(ecu.tx_raw()) == 16
    assert ecu.counters.tx_dropped == 70 - 16


# ---- parameter frames: cantools -> ECU -> acknowledgement -> cantools ---------------------------


def _param_round_trip(ecu: Ecu, data: bytes) -> dict[str, Any]:
    rc = ecu.rx((DEFAULT_IDS.param_set, data), 0)
    acks = [d for i, d in ecu.tx_raw() if i == DEFAULT_IDS.param_ack]
    assert len(acks) == 1
    ack: dict[str, Any] = database().decode_message(
        DEFAULT_IDS.param_ack, acks[0], decode_choices=False
    )
    ack["rc"] = rc
    return ack


def test_parameter_frame_accepted_while_stopped() -> None:
    ecu = Ecu()
    data = database().encode_message("PcParamSet", {"ParamId": 8, "CvThreshold": 3.5})
    ack = _param_round_trip(ecu, data)
    assert ack == {"AckParamId": 8, "AckResult": 0, "AckRaw": 350, "rc": lib.TD_OK}
    assert ecu.params.cv_threshold_pct == pytest.approx(3.5)
    assert ecu.counters.rx_ok == 1


@pytest.mark.parametrize("spec", params(), ids=lambda s: s.signal)
def test_every_parameter_is_settable_over_can(spec: Any) -> None:
    ecu = Ecu()
    defaults = EcuParams.defaults()
    # a value inside the range, other than the default, that keeps the set consistent
    value = {
        "queue_len": 7,
        "cv_window": 3,
        "speed_mode": 2,
        "switch_compare": 1,
        "slip_comp": 1,
        "drive_adapt": 0,
        "gnss_lag_auto": 0,
    }.get(spec.key, spec.minimum + 5 * spec.scale if spec.integer else spec.maximum / 2)
    msg = encode_param_set(spec.key, value)
    assert ecu.rx(msg, 0) == lib.TD_OK
    (ack_frame,) = ecu.tx_raw()
    ack = decode(ack_frame)
    assert isinstance(ack, EcuParamAck)
    assert (ack.param_id, ack.result) == (spec.id, AckResult.OK)
    assert ack.value == pytest.approx(value, rel=1e-4)
    assert ecu.params.get(spec.key) == pytest.approx(value, rel=1e-4)
    assert defaults.get(spec.key) != pytest.approx(value, rel=1e-4)


def test_parameter_frames_refused() -> None:
    ecu = Ecu()
    db = database()
    # out of range on the wire (cantools would refuse to encode it: build the bytes)
    raw_17 = bytes([6, 0, 0, 0, 17, 0, 0, 0])  # QueueLength 17 > 16
    ack = _param_round_trip(ecu, raw_17)
    assert (ack["AckResult"], ack["AckRaw"], ack["rc"]) == (2, 5, lib.TD_E_RANGE)  # 5 in force
    # inconsistent: CvWindow 6 > QueueLength 5
    ack = _param_round_trip(ecu, db.encode_message("PcParamSet", {"ParamId": 7, "CvWindow": 6}))
    assert (ack["AckResult"], ack["AckRaw"], ack["rc"]) == (4, 5, lib.TD_E_INCONSISTENT)
    # unknown parameter id
    ack = _param_round_trip(ecu, bytes([40, 0, 0, 0, 1, 0, 0, 0]))
    assert (ack["AckParamId"], ack["AckResult"]) == (40, 1)
    # wrong length
    ack = _param_round_trip(ecu, bytes([8, 0, 0, 0, 1, 0]))
    assert (ack["AckParamId"], ack["AckResult"], ack["rc"]) == (8, 5, lib.TD_E_LENGTH)
    assert ecu.params == EcuParams.defaults()
    assert ecu.counters.rx_param_rejected == 3 and ecu.counters.rx_bad_length == 1


def test_parameters_are_writable_only_while_stopped() -> None:
    ecu = _running_ecu()
    data = database().encode_message("PcParamSet", {"ParamId": 9, "SwitchSpeed": 7.0})
    ack = _param_round_trip(ecu, data)
    assert (ack["AckResult"], ack["AckRaw"], ack["rc"]) == (3, 600, lib.TD_E_BUSY)
    assert ecu.params.switch_speed_kmh == 6.0
    ecu.rx(encode_command(False, 0, 0, 0, None), 20_000)
    assert _param_round_trip(ecu, data)["AckResult"] == 0
    assert ecu.params.switch_speed_kmh == 7.0


# ---- EcuParams ----------------------------------------------------------------------------------


def test_defaults_are_the_papers() -> None:
    p = EcuParams.defaults()
    assert (p.working_width_m, p.wheel_radius_m, p.wheel_ppr) == (3.6, 0.0615, 500)
    assert (p.queue_len, p.cv_threshold_pct, p.switch_speed_kmh) == (5, 4.2, 6.0)
    assert (p.wheel_update_ms, p.wheel_samples, p.status_period_ms) == (500, 4, 100)
    assert (p.speed_mode, p.switch_compare) == (SpeedMode.PAPER.code, Compare.GNSS.code)
    assert (p.status_id, p.command_id) == (0x185C6465, 0x0A5C6465)
    assert p.validate() == p


def test_bad_parameter_sets_raise() -> None:
    p = EcuParams.defaults()
    with pytest.raises(EcuError, match="out of range") as exc:
        Ecu(p.replace(queue_len=1))
    assert exc.value.code == lib.TD_E_RANGE
    with pytest.raises(EcuError, match="inconsistent"):
        Ecu(p.replace(cv_window=6))
    with pytest.raises(EcuError, match="inconsistent"):
        p.replace(status_id=p.command_id).validate()
    with pytest.raises(EcuError, match="out of range"):
        p.replace(wheel_ppr=70000).validate()  # does not even fit the C field
    with pytest.raises(EcuError, match="out of range"):
        p.with_param("cv_threshold_pct", 60.0)
    with pytest.raises(ProtocolError, match="unknown ECU parameter"):
        p.with_param("nope", 1.0)
    q = p.with_param("kg_per_rev[1]", 0.25)
    assert q.kg_per_rev == (0.3, 0.25) and q.get(3) == 0.25 and p.kg_per_rev == (0.3, 0.3)


def test_custom_command_identifier() -> None:
    ecu = Ecu(EcuParams.defaults().replace(command_id=0x0A5C6401, status_id=0x185C6401))
    assert ecu.rx((CMD, GOOD), 0) == lib.TD_E_UNKNOWN_ID
    assert ecu.rx((0x0A5C6401, GOOD), 0) == lib.TD_OK
    ecu.step_raw(100_000, 0, 0, 0, 0, 0)
    assert ecu.tx_raw()[0][0] == 0x185C6401


# ---- C and Python agree on the DBC --------------------------------------------------------------


def test_constants_agree() -> None:
    assert {f.name: f.value for f in Fault} == {
        "CMD_TIMEOUT": lib.TD_FAULT_CMD_TIMEOUT,
        "GNSS_LOST": lib.TD_FAULT_GNSS_LOST,
        "WHEEL_ENCODER": lib.TD_FAULT_WHEEL_ENCODER,
        "UPPER_BLOCKED": lib.TD_FAULT_UPPER_BLOCKED,
        "LOWER_BLOCKED": lib.TD_FAULT_LOWER_BLOCKED,
        "UPPER_FAN_LOW": lib.TD_FAULT_UPPER_FAN_LOW,
        "LOWER_FAN_LOW": lib.TD_FAULT_LOWER_FAN_LOW,
        "NO_SPEED": lib.TD_FAULT_NO_SPEED,
        "GNSS_FROZEN": lib.TD_FAULT_GNSS_FROZEN,
    }
    assert LATCHED_FAULTS == lib.TD_FAULT_LATCHED_MASK
    assert [s.code for s in Source] == [
        lib.TD_SRC_WHEEL,
        lib.TD_SRC_GNSS,
        lib.TD_SRC_NONE,
        lib.TD_SRC_FUSED,
    ]
    assert [m.code for m in SpeedMode] == [
        lib.TD_MODE_DUAL,
        lib.TD_MODE_WHEEL_ONLY,
        lib.TD_MODE_GNSS_ONLY,
        lib.TD_MODE_FUSED,
    ]
    assert [c.code for c in Compare] == [lib.TD_CMP_GNSS, lib.TD_CMP_WHEEL]
    ids = DEFAULT_IDS
    assert (ids.status, ids.command, ids.diag, ids.speeds) == (
        lib.TD_ID_ECU_STATUS,
        lib.TD_ID_PC_COMMAND,
        lib.TD_ID_ECU_DIAG,
        lib.TD_ID_ECU_SPEEDS,
    )
    assert (ids.targets, ids.param_set, ids.param_ack) == (
        lib.TD_ID_ECU_TARGETS,
        lib.TD_ID_PC_PARAM_SET,
        lib.TD_ID_ECU_PARAM_ACK,
    )
    assert (ids.gnss_time, ids.fused, ids.fused_aux, ids.gnss_lag) == (
        lib.TD_ID_PC_GNSS_TIME,
        lib.TD_ID_ECU_FUSED,
        lib.TD_ID_ECU_FUSED_AUX,
        lib.TD_ID_ECU_GNSS_LAG,
    )
    assert len(params()) == lib.TD_PARAM_COUNT


def test_parameter_encodings_agree() -> None:
    scale, lo, hi = ffi.new("float *"), ffi.new("uint32_t *"), ffi.new("uint32_t *")
    for spec in params():
        assert lib.td_params_encoding(spec.id, scale, lo, hi) == lib.TD_OK
        assert scale[0] == pytest.approx(spec.scale, rel=1e-6)
        assert (lo[0], hi[0]) == (spec.to_raw(spec.minimum), spec.to_raw(spec.maximum))
        assert lib.td_proto_param_raw(spec.id, spec.maximum) == spec.to_raw(spec.maximum)
    assert lib.td_params_encoding(40, scale, lo, hi) == lib.TD_E_UNKNOWN_PARAM


def _c_frame(fn: Any, value: Any) -> tuple[int, bytes]:
    f = ffi.new("td_can_frame_t *")
    assert fn(value, f) == lib.TD_OK
    assert f.extended == 1 and f.dlc == 8
    return int(f.id), bytes(ffi.buffer(f.data, 8))


def _near(rng: random.Random, lo_raw: int, hi_raw: int, scale: float) -> tuple[float, int]:
    """A physical value off the rounding ties and the raw value it must encode to."""
    raw = rng.randint(lo_raw, hi_raw)
    off = rng.uniform(-0.3, 0.3) if lo_raw < raw < hi_raw else 0.0
    return (raw + off) * scale, raw


def test_c_encoded_ecu_frames_decode_with_cantools_to_the_same_values() -> None:
    rng = random.Random(7)
    db = database()
    for _ in range(200):
        (m0, m0r), (m1, m1r) = _near(rng, 0, 65535, 0.01), _near(rng, 0, 65535, 0.01)
        (f0, f0r), (f1, f1r) = _near(rng, 0, 255, 20), _near(rng, 0, 255, 20)
        w, wr = _near(rng, 0, 255, 0.1)
        running = rng.random() < 0.5
        s = ffi.new("td_status_t *", [running, [m0, m1], [f0, f1], w])
        fid, data = _c_frame(lib.td_proto_encode_status, s)
        assert fid == DEFAULT_IDS.status
        assert db.decode_message(fid, data, decode_choices=False, scaling=False) == {
            "RunState": 0x0A if running else 0,
            "UpperMeterSpeed": m0r,
            "LowerMeterSpeed": m1r,
            "UpperFanSpeed": f0r,
            "LowerFanSpeed": f1r,
            "WheelSpeed": wr,
        }
        back = ffi.new("td_status_t *")
        assert lib.td_proto_decode_status(ffi.new("td_can_frame_t *", [fid, 1, 8, data]), back) == 0
        py = decode((fid, data))
        assert py.meter_rpm_upper == pytest.approx(back.meter_rpm[0], abs=1e-4)  # type: ignore[union-attr]
        assert py.wheel_kmh == pytest.approx(back.wheel_kmh, abs=1e-5)  # type: ignore[union-attr]

        cv, cvr = _near(rng, 0, 65534, 0.01)
        faults, pulses = rng.randint(0, 255), rng.randint(0, (1 << 32) - 1)
        src, mode, cmp = rng.randint(0, 2), rng.randint(0, 2), rng.randint(0, 1)
        d = ffi.new("td_diag_t *", [src, mode, True, False, cmp, cv, faults, pulses])
        fid, data = _c_frame(lib.td_proto_encode_diag, d)
        assert db.decode_message(fid, data, decode_choices=False) == {
            "SpeedSource": src,
            "SpeedMode": mode,
            "GnssValid": 1,
            "Uniform": 0,
            "SwitchCompare": cmp,
            "Cv": pytest.approx(cvr * 0.01),
            "FaultWord": faults,
            "WheelPulses": pulses % (1 << 24),
        }

        (a, ar), (b, br), (c, cr) = (_near(rng, 0, 65534, 0.01) for _ in range(3))
        sp = ffi.new("td_speeds_t *", [a, b, c, 17])
        fid, data = _c_frame(lib.td_proto_encode_speeds, sp)
        assert db.decode_message(fid, data, scaling=False) == {
            "WheelSpeedFine": ar,
            "GnssSpeedFine": br,
            "SelectedSpeed": cr,
            "RxRejected": 17,
        }

        vals = [_near(rng, 0, 65535, 0.01) for _ in range(2)] + [
            _near(rng, 0, 200, 0.5) for _ in range(4)
        ]
        t = ffi.new(
            "td_targets_t *",
            [[vals[0][0], vals[1][0]], [vals[2][0], vals[3][0]], [vals[4][0], vals[5][0]]],
        )
        fid, data = _c_frame(lib.td_proto_encode_targets, t)
        names = ["UpperTargetSpeed", "LowerTargetSpeed", "UpperDuty", "LowerDuty"]
        names += ["UpperFanDuty", "LowerFanDuty"]
        assert db.decode_message(fid, data, scaling=False) == {
            n: r for n, (_, r) in zip(names, vals, strict=True)
        }


def test_c_marks_undefined_cv_and_missing_gnss_as_the_dbc_says() -> None:
    d = ffi.new("td_diag_t *", [0, 0, False, False, 0, -1.0, 0, 0])
    diag = decode(_c_frame(lib.td_proto_encode_diag, d))
    assert diag.cv_pct is None  # type: ignore[union-attr]
    sp = ffi.new("td_speeds_t *", [1.0, -1.0, 1.0, 0])
    speeds = decode(_c_frame(lib.td_proto_encode_speeds, sp))
    assert speeds.gnss_kmh is None and speeds.wheel_kmh == 1.0  # type: ignore[union-attr]


def test_python_commands_decode_in_c_to_the_same_values() -> None:
    rng = random.Random(11)
    out = ffi.new("td_command_t *")
    for _ in range(300):
        start = rng.random() < 0.5
        fan, up, lo = rng.randint(0, 6000), rng.randint(0, 60000) / 100, rng.randint(0, 60000) / 100
        gnss = None if rng.random() < 0.2 else rng.randint(0, 250) / 10
        msg = encode_command(start, fan, up, lo, gnss)
        frame = ffi.new("td_can_frame_t *", [msg.arbitration_id, 1, 8, bytes(msg.data)])
        assert lib.td_proto_decode_command(frame, out) == lib.TD_OK
        py = decode(msg)
        assert py == PcCommand(start, float(fan), up, lo, gnss)
        assert (out.start, out.fan_rpm, out.gnss_valid) == (start, fan, gnss is not None)
        assert out.rate_kg_ha[0] == pytest.approx(up, abs=1e-3)
        assert out.rate_kg_ha[1] == pytest.approx(lo, abs=1e-3)
        if gnss is not None:
            assert out.gnss_kmh == pytest.approx(gnss, abs=1e-4)
        # and C encodes the same bytes back
        c_cmd = ffi.new("td_command_t *", [start, fan, [up, lo], gnss is not None, gnss or 0.0])
        assert _c_frame(lib.td_proto_encode_command, c_cmd) == (CMD, bytes(msg.data))


def test_python_parameter_frames_decode_in_c() -> None:
    pid, value = ffi.new("uint8_t *"), ffi.new("float *")
    for spec in params():
        for v in (spec.minimum, spec.maximum, (spec.minimum + spec.maximum) / 2):
            v = spec.from_raw(spec.to_raw(v))
            msg = encode_param_set(spec.id, v)
            frame = ffi.new("td_can_frame_t *", [msg.arbitration_id, 1, 8, bytes(msg.data)])
            assert lib.td_proto_decode_param_set(frame, pid, value) == lib.TD_OK
            assert pid[0] == spec.id
            assert value[0] == pytest.approx(v, rel=1e-6, abs=spec.scale / 10)
    assert param("WheelRadius").id == 4


def _random_frame(rng: random.Random) -> tuple[int, bytes]:
    """A frame as a bus may carry it: mostly the PC's two identifiers with shaped or random
    payloads, also the ECU's own ids, foreign ids, and lengths of 0..64 bytes (CAN FD)."""
    kind = rng.randrange(10)
    frame_id = (
        CMD
        if kind < 4
        else DEFAULT_IDS.param_set
        if kind < 7
        else DEFAULT_IDS.status
        if kind < 8
        else rng.randrange(0x800, 1 << 29)
    )
    data = bytearray(rng.randbytes(8))
    if frame_id == CMD and rng.random() < 0.7:
        data[0] = rng.choice((0x00, 0x0A))
        data[1:3] = rng.randrange(7000).to_bytes(2, "little")
        data[3:5] = rng.randrange(61000).to_bytes(2, "little")
        data[7] = rng.choice((rng.randrange(256), rng.randrange(251), 0xFF))
    elif frame_id == DEFAULT_IDS.param_set and rng.random() < 0.7:
        spec = param(rng.randrange(1, 28))
        data[0] = spec.id
        data[1:4] = bytes(3)
        lo, hi = spec.to_raw(spec.minimum), spec.to_raw(spec.maximum)
        data[4:8] = rng.randrange(max(0, lo - 1), hi + 2).to_bytes(4, "little")
    length = rng.choice((8, 8, 8, rng.randrange(9), rng.randrange(9, 65)))
    return frame_id, bytes(data[:length]) + rng.randbytes(max(0, length - 8))


def test_random_frames_c_and_python_agree_and_every_frame_is_counted() -> None:
    rng = random.Random(20260615)
    ecu = Ecu()
    decodable = {lib.TD_OK, lib.TD_E_BUSY, lib.TD_E_INCONSISTENT}
    n = 20_000
    for k in range(n):
        frame = _random_frame(rng)
        rc = ecu.rx(frame, k * 5_000)
        assert rc <= 0
        if frame[0] in (CMD, DEFAULT_IDS.param_set):
            try:
                decode(frame)
                python_ok = True
            except ProtocolError:
                python_ok = False
            # the C core and cantools accept and refuse the very same frames
            assert (rc in decodable) == python_ok, (hex(frame[0]), frame[1].hex(), rc)
        else:
            assert rc == lib.TD_E_UNKNOWN_ID
        if k % 2:
            ecu.step_raw(k * 5_000, k, k, k, 40 * k, 40 * k)
            ecu.tx_raw()
    c = ecu.counters
    total = c.rx_ok + c.rx_unknown_id + c.rx_bad_length + c.rx_out_of_range + c.rx_param_rejected
    assert total == n
    assert min(c.rx_ok, c.rx_unknown_id, c.rx_bad_length, c.rx_out_of_range) > 500
    ecu.params.validate()
