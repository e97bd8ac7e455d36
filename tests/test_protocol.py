"""The Python side of the CAN protocol: cantools on protocol/topdress.dbc, typed and validated."""

from __future__ import annotations

from pathlib import Path

import can
import pytest

from topdress import protocol
from topdress.errors import ProtocolError
from topdress.protocol import (
    DEFAULT_IDS,
    AckResult,
    Compare,
    EcuDiag,
    EcuParamAck,
    EcuSpeeds,
    EcuStatus,
    EcuTargets,
    Fault,
    FrameIds,
    PcCommand,
    PcParamSet,
    Source,
    SpeedMode,
    database,
    dbc_text,
    decode,
    encode_command,
    encode_param_set,
    is_known_id,
    param,
    param_name,
    params,
)

REPO = Path(__file__).resolve().parents[1]


def test_packaged_dbc_is_the_repository_dbc() -> None:
    assert dbc_text() == (REPO / "protocol" / "topdress.dbc").read_text(encoding="utf-8")


def test_frame_ids_are_the_dbc_ids_and_the_papers() -> None:
    db = database()
    by_name = {m.name: m.frame_id for m in db.messages}
    assert by_name == {
        "EcuStatus": DEFAULT_IDS.status,
        "PcCommand": DEFAULT_IDS.command,
        "EcuDiag": DEFAULT_IDS.diag,
        "EcuSpeeds": DEFAULT_IDS.speeds,
        "EcuTargets": DEFAULT_IDS.targets,
        "PcParamSet": DEFAULT_IDS.param_set,
        "EcuParamAck": DEFAULT_IDS.param_ack,
        "PcCalCommand": DEFAULT_IDS.cal_command,
        "EcuCalStatus": DEFAULT_IDS.cal_status,
        "PcGnssTime": DEFAULT_IDS.gnss_time,
        "EcuFused": DEFAULT_IDS.fused,
        "EcuFusedAux": DEFAULT_IDS.fused_aux,
        "EcuGnssLag": DEFAULT_IDS.gnss_lag,
        "EcuIdent": DEFAULT_IDS.ident,
        "EcuCanHealth": DEFAULT_IDS.can_health,
        "EcuFaultRecord": DEFAULT_IDS.fault_record,
    }
    assert DEFAULT_IDS.status == 0x185C6465 and DEFAULT_IDS.command == 0x0A5C6465
    assert all(m.is_extended_frame and m.length == 8 for m in db.messages)


def test_enum_codes_match_the_dbc_value_tables() -> None:
    diag = database().get_message_by_name("EcuDiag")
    sources = {int(k): str(v) for k, v in diag.get_signal_by_name("SpeedSource").choices.items()}
    assert sources == {Source.WHEEL.code: "Wheel", Source.GNSS.code: "Gnss", 2: "None", 3: "Fused"}
    assert Source.NONE.code == 2 and Source.FUSED.code == 3
    modes = {int(k): str(v) for k, v in diag.get_signal_by_name("SpeedMode").choices.items()}
    assert modes == {
        SpeedMode.PAPER.code: "Dual",
        SpeedMode.WHEEL_ONLY.code: "WheelOnly",
        SpeedMode.GNSS_ONLY.code: "GnssOnly",
        SpeedMode.FUSED.code: "Fused",
    }
    assert (Compare.GNSS.code, Compare.WHEEL.code) == (0, 1)
    ack = database().get_message_by_name("EcuParamAck").get_signal_by_name("AckResult")
    assert {int(k): str(v) for k, v in ack.choices.items()} == {
        r.value: "".join(w.capitalize() for w in r.name.split("_")) for r in AckResult
    }


def test_command_bytes_follow_table_1_little_endian() -> None:
    msg = encode_command(True, 3000, 200.0, 150.5, 6.5)
    assert msg.arbitration_id == 0x0A5C6465 and msg.is_extended_id and msg.dlc == 8
    # byte 0 start 0x0A; fan 3000 rpm = 0x0BB8; 200.00 kg/ha = 20000 = 0x4E20;
    # 150.50 kg/ha = 15050 = 0x3ACA; 6.5 km/h = 65 = 0x41
    assert bytes(msg.data) == bytes([0x0A, 0xB8, 0x0B, 0x20, 0x4E, 0xCA, 0x3A, 0x41])
    assert decode(msg) == PcCommand(True, 3000.0, 200.0, 150.5, 6.5)


def test_command_without_gnss_sends_0xff_and_stop_sends_0x00() -> None:
    msg = encode_command(False, 0, 0, 0, None)
    assert bytes(msg.data) == bytes([0x00, 0, 0, 0, 0, 0, 0, 0xFF])
    assert decode(msg) == PcCommand(False, 0.0, 0.0, 0.0, None)


def test_command_gnss_boundaries() -> None:
    assert bytes(encode_command(True, 0, 0, 0, 25.0).data)[7] == 250
    assert bytes(encode_command(True, 0, 0, 0, 0.0).data)[7] == 0
    for bad in (25.1, -0.1, float("nan")):
        with pytest.raises(ProtocolError, match="GnssSpeed"):
            encode_command(True, 0, 0, 0, bad)


@pytest.mark.parametrize(
    ("fan", "upper", "lower", "what"),
    [
        (6001, 0, 0, "FanSpeed"),
        (-1, 0, 0, "FanSpeed"),
        (0, 600.01, 0, "UpperRate"),
        (0, 0, -5, "LowerRate"),
        (0, float("inf"), 0, "UpperRate"),
    ],
)
def test_command_out_of_range_is_refused(fan: float, upper: float, lower: float, what: str) -> None:
    with pytest.raises(ProtocolError, match=what):
        encode_command(True, fan, upper, lower, 5.0)


def _cmd(data: list[int]) -> tuple[int, bytes]:
    return (DEFAULT_IDS.command, bytes(data))


def test_decode_rejects_malformed_commands() -> None:
    ok = [0x0A, 0xB8, 0x0B, 0x20, 0x4E, 0xCA, 0x3A, 0x41]
    assert decode(_cmd(ok)).start  # type: ignore[union-attr]
    with pytest.raises(ProtocolError, match="7 data bytes, expected 8"):
        decode(_cmd(ok[:7]))
    with pytest.raises(ProtocolError, match="StartStop: undefined value 5"):
        decode(_cmd([5, *ok[1:]]))
    for raw in (251, 252, 253, 254):
        with pytest.raises(ProtocolError, match="GnssSpeed raw"):
            decode(_cmd([*ok[:7], raw]))
    assert decode(_cmd([*ok[:7], 250])).gnss_kmh == 25.0  # type: ignore[union-attr]
    with pytest.raises(ProtocolError, match=r"UpperRate = 600.01 outside 0..600"):
        decode(_cmd([0x0A, 0, 0, 0x61, 0xEA, 0, 0, 0]))  # raw 60001
    with pytest.raises(ProtocolError, match="FanSpeed = 6001"):
        decode(_cmd([0x0A, 0x71, 0x17, 0, 0, 0, 0, 0]))


def test_decode_rejects_unknown_ids_and_remote_frames() -> None:
    with pytest.raises(ProtocolError, match="unknown CAN id 0x185C6466"):
        decode((0x185C6466, bytes(8)))
    with pytest.raises(ProtocolError, match="remote"):
        decode(can.Message(arbitration_id=DEFAULT_IDS.command, is_remote_frame=True, dlc=8))


def test_identifiers_are_configurable() -> None:
    ids = FrameIds(command=0x0A5C6401)
    msg = encode_command(True, 1, 2, 3, 4.0, ids=ids)
    assert msg.arbitration_id == 0x0A5C6401
    assert decode(msg, ids) == PcCommand(True, 1.0, 2.0, 3.0, 4.0)
    with pytest.raises(ProtocolError, match="unknown CAN id"):
        decode(msg)


def test_decode_status_of_the_paper_frame() -> None:
    # running, 24.00 r/min, 12.34 r/min, fans 3000 and 2980 rpm (150, 149 x 20), 6.1 km/h
    data = bytes([0x0A, 0x60, 0x09, 0xD2, 0x04, 150, 149, 61])
    assert decode((DEFAULT_IDS.status, data)) == EcuStatus(True, 24.0, 12.34, 3000.0, 2980.0, 6.1)
    with pytest.raises(ProtocolError, match="RunState: undefined value 1"):
        decode((DEFAULT_IDS.status, bytes([1, *data[1:]])))


def test_decode_diag_speeds_targets() -> None:
    # source GNSS (1), mode dual (0), gnss valid, uniform, compare GNSS; CV 3.21 %;
    # faults CMD_TIMEOUT|WHEEL_ENCODER; 0x012345 pulses
    diag = bytes([0x01 | 0x10 | 0x20, 0x41, 0x01, 0x05, 0x00, 0x45, 0x23, 0x01])
    assert decode((DEFAULT_IDS.diag, diag)) == EcuDiag(
        Source.GNSS,
        SpeedMode.PAPER,
        True,
        True,
        Compare.GNSS,
        3.21,
        Fault.CMD_TIMEOUT | Fault.WHEEL_ENCODER,
        0x012345,
    )
    undefined_cv = bytes([0x02 | 0x40, 0xFF, 0xFF, 0, 0, 0, 0, 0])
    d = decode((DEFAULT_IDS.diag, undefined_cv))
    assert isinstance(d, EcuDiag)
    assert d.cv_pct is None and d.source is Source.NONE and d.compare is Compare.WHEEL
    fused = decode((DEFAULT_IDS.diag, bytes([0x03 | 0x0C, 0, 0, 0, 0, 0, 0, 0])))
    assert isinstance(fused, EcuDiag)
    assert (fused.source, fused.mode) == (Source.FUSED, SpeedMode.FUSED)

    speeds = bytes([0x62, 0x02, 0xFF, 0xFF, 0x62, 0x02, 0x07, 0x00])  # 6.10, n/a, 6.10, 7
    assert decode((DEFAULT_IDS.speeds, speeds)) == EcuSpeeds(6.1, None, 6.1, 7)

    targets = bytes([0x60, 0x09, 0, 0, 100, 200, 201, 0])
    with pytest.raises(ProtocolError, match=r"UpperFanDuty = 100.5 outside 0..100"):
        decode((DEFAULT_IDS.targets, targets))
    targets = bytes([0x60, 0x09, 0, 0, 100, 200, 120, 0])
    assert decode((DEFAULT_IDS.targets, targets)) == EcuTargets(24.0, 0.0, 50.0, 100.0, 60.0, 0.0)


def test_parameter_table_covers_every_id_once() -> None:
    specs = params()
    assert [s.id for s in specs] == list(range(1, 40))
    assert len({s.key for s in specs}) == 39
    assert param("CvThreshold") is param(8) is param("cv_threshold_pct")
    assert param("kg_per_rev[1]").signal == "LowerKgPerRev"
    assert (param(8).unit, param(8).minimum, param(8).maximum, param(8).scale) == (
        "%",
        0.1,
        50.0,
        0.01,
    )
    assert (param("LeadStop").id, param(38).unit, param(38).maximum) == (38, "ms", 5000.0)
    for bad in (0, 40, "kg_per_rev", "Nope"):
        with pytest.raises(ProtocolError, match="unknown ECU parameter"):
            param(bad)


@pytest.mark.parametrize("spec", params(), ids=lambda s: s.signal)
def test_every_parameter_round_trips_at_its_limits(spec: object) -> None:
    s = param(spec.id)  # type: ignore[attr-defined]
    for value in (s.minimum, s.maximum):
        msg = encode_param_set(s.id, value)
        assert msg.arbitration_id == DEFAULT_IDS.param_set
        assert bytes(msg.data)[0] == s.id
        assert int.from_bytes(bytes(msg.data)[4:8], "little") == s.to_raw(value)
        out = decode(msg)
        assert isinstance(out, PcParamSet) and out.param_id == s.id
        assert out.value == pytest.approx(value)
    below = s.minimum - s.scale
    with pytest.raises(ProtocolError, match="outside"):
        encode_param_set(s.signal, below if below >= 0 else s.maximum + s.scale)
    with pytest.raises(ProtocolError, match="outside"):
        encode_param_set(s.key, s.maximum + s.scale)


def test_parameter_values_are_checked() -> None:
    assert bytes(encode_param_set("wheel_radius_m", 0.0615).data) == bytes(
        [4, 0, 0, 0, 0x67, 0x02, 0, 0]
    )  # 615 x 0.0001 m
    with pytest.raises(ProtocolError, match=r"QueueLength .* is not whole"):
        encode_param_set("queue_len", 5.5)
    with pytest.raises(ProtocolError, match="outside"):
        encode_param_set("pid_kp", float("nan"))
    # raw values on the wire outside the range, and ids without a parameter
    bad_raw = bytes([6, 0, 0, 0, 17, 0, 0, 0])  # QueueLength 17 > 16
    with pytest.raises(ProtocolError, match=r"QueueLength = 17 outside 2..16"):
        decode((DEFAULT_IDS.param_set, bad_raw))
    with pytest.raises(ProtocolError, match="PcParamSet"):
        decode((DEFAULT_IDS.param_set, bytes([40, 0, 0, 0, 1, 0, 0, 0])))


def test_parameter_ack() -> None:
    data = bytes([8, 0, 0, 0, 0xA4, 0x01, 0, 0])  # CvThreshold ok, raw 420 = 4.20 %
    ack = decode((DEFAULT_IDS.param_ack, data))
    assert ack == EcuParamAck(8, AckResult.OK, 420)
    assert isinstance(ack, EcuParamAck) and ack.value == pytest.approx(4.2)
    unknown = decode((DEFAULT_IDS.param_ack, bytes([99, 1, 0, 0, 0, 0, 0, 0])))
    assert isinstance(unknown, EcuParamAck)
    assert unknown.result is AckResult.UNKNOWN_PARAM and unknown.value is None
    with pytest.raises(ProtocolError, match="AckResult: undefined value 6"):
        decode((DEFAULT_IDS.param_ack, bytes([8, 6, 0, 0, 0, 0, 0, 0])))


def test_known_ids_and_parameter_names() -> None:
    assert is_known_id(0x185C6465) and is_known_id(0x0A606465)
    assert not is_known_id(0x185C6466)
    assert is_known_id(0x123, FrameIds(status=0x123)) and not is_known_id(
        0x185C6465, FrameIds(status=0x123)
    )
    assert param_name(8) == "CvThreshold" and param_name("kg_per_rev[0]") == "UpperKgPerRev"
    with pytest.raises(ProtocolError):
        param_name(0)


def test_speeds_not_available_are_named_in_the_dbc() -> None:
    # 0xFFFF of the 0.01 km/h speeds is "not available", not 655.35 km/h, in any DBC tool
    db = protocol.database()
    for frame, signal in (("EcuSpeeds", "GnssSpeedFine"), ("PcGnssTime", "GnssSpeedPrecise")):
        msg = db.get_message_by_name(frame)
        raw = {s.name: 0 for s in msg.signals} | {signal: 0xFFFF}
        data = msg.encode(raw, scaling=False, strict=False)
        assert str(msg.decode(data)[signal]) == "not available"
        assert msg.decode(msg.encode(raw | {signal: 812}, scaling=False, strict=False))[
            signal
        ] == pytest.approx(8.12)
    speeds = protocol.decode((protocol.DEFAULT_IDS.speeds, bytes.fromhex("D007FFFFD0070000")))
    assert isinstance(speeds, protocol.EcuSpeeds) and speeds.gnss_kmh is None
    assert speeds.wheel_kmh == pytest.approx(20.0)
