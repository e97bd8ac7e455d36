"""The compiled frame layouts decode and check exactly as cantools and the DBC's ranges do."""

from __future__ import annotations

import random
from typing import Any

import pytest

from topdress import protocol
from topdress.errors import ProtocolError
from topdress.protocol.layout import encoder, layout, layouts, signal_check
from topdress.protocol.params import decimals

RNG_SEED = 20260611


def _plain_messages() -> list[Any]:
    return [m for m in protocol.database().messages if layouts()[m.name] is not None]


def _reference_check(frame: str, sig: Any, raw: int) -> float:
    """The range check as the protocol wrote it before the layouts: scale, round to the
    resolution, value table, DBC range with half a step of tolerance."""
    value = float(round(raw * sig.scale + sig.offset, decimals(sig.scale)))
    if sig.choices is not None and not sig.unit and raw not in sig.choices:
        raise ProtocolError(f"{frame}.{sig.name}: undefined value {raw}")
    tol = sig.scale / 2
    if not sig.minimum - tol <= value <= sig.maximum + tol:
        raise ProtocolError(
            f"{frame}.{sig.name} = {value:g} outside {sig.minimum:g}..{sig.maximum:g}"
        )
    return value


def _reference_values(msg: Any, raw: tuple[int, ...]) -> tuple[float, ...]:
    return tuple(_reference_check(msg.name, s, r) for s, r in zip(msg.signals, raw, strict=True))


def _outcome(fn: Any, *args: Any) -> tuple[str, Any]:
    try:
        return "ok", fn(*args)
    except ProtocolError as exc:
        return "error", str(exc)


def _raw_values(sig: Any, rng: random.Random) -> list[int]:
    """Every raw value of a signal up to 10 bits; else the ends, around the accepted range's
    bounds and a random sample."""
    lo, hi = (
        (-(1 << (sig.length - 1)), (1 << (sig.length - 1)) - 1)
        if sig.is_signed
        else (
            0,
            (1 << sig.length) - 1,
        )
    )
    if sig.length <= 10:
        return list(range(lo, hi + 1))
    chk = signal_check("x", sig)
    edges = {lo, hi, chk.raw_lo, chk.raw_hi}
    near = {v + d for v in edges for d in range(-3, 4)}
    return sorted({v for v in near if lo <= v <= hi} | {rng.randint(lo, hi) for _ in range(1500)})


def test_every_plain_frame_of_the_dbc_has_a_layout() -> None:
    names = {m.name for m in _plain_messages()}
    # PcParamSet is multiplexed: cantools decodes it
    assert layouts()["PcParamSet"] is None
    assert names == {m.name for m in protocol.database().messages} - {"PcParamSet"}


def test_raw_values_equal_cantools_on_random_payloads() -> None:
    rng = random.Random(RNG_SEED)
    for msg in _plain_messages():
        lay = layout(msg.name)
        assert lay is not None
        for _ in range(2000):
            data = rng.randbytes(msg.length)
            ref = msg.decode(data, decode_choices=False, scaling=False)
            assert lay.names == tuple(ref), msg.name
            assert lay.raw(data) == tuple(ref.values()), (msg.name, data.hex())


def test_signal_checks_equal_the_reference_on_every_raw_value() -> None:
    rng = random.Random(RNG_SEED)
    for msg in protocol.database().messages:
        for sig in msg.signals:
            chk = signal_check(msg.name, sig)
            for raw in _raw_values(sig, rng):
                ref = _outcome(_reference_check, msg.name, sig, raw)
                assert _outcome(chk.check, raw) == ref, (msg.name, sig.name, raw)
                if ref[0] == "ok":
                    assert _outcome(chk.physical, raw) == ref, (msg.name, sig.name, raw)


def test_frame_values_equal_the_reference_first_error_included() -> None:
    rng = random.Random(RNG_SEED)
    for msg in _plain_messages():
        lay = layout(msg.name)
        assert lay is not None
        for _ in range(3000):
            data = rng.randbytes(msg.length)
            raw = lay.raw(data)

            assert _outcome(lay.values, raw) == _outcome(_reference_values, msg, raw), (
                msg.name,
                data.hex(),
            )


def test_the_exact_quotient_equals_the_rounded_value() -> None:
    # physical = raw * k / 10**decimals is used for every signal with an integral k
    used = 0
    for msg in protocol.database().messages:
        for sig in msg.signals:
            chk = signal_check(msg.name, sig)
            if chk.ratio is None:
                continue
            used += 1
            k, d = chk.ratio
            for raw in _raw_values(sig, random.Random(RNG_SEED)):
                assert raw * k / d == chk.physical(raw), (msg.name, sig.name, raw)
    assert used > 40


@pytest.mark.parametrize("name", [m.name for m in protocol.database().messages])
def test_malformed_lengths_are_refused_by_name(name: str) -> None:
    msg = protocol.database().get_message_by_name(name)
    frame_id = msg.frame_id
    for n in (0, 1, msg.length - 1, msg.length + 1, 64):
        with pytest.raises(ProtocolError, match=f"{name}: {n} data bytes, expected {msg.length}"):
            protocol.decode((frame_id, bytes(n)))


# the frames whose typed decoders check every signal in DBC order (the others check some
# signals, with rules of their own first: PcCommand's GnssSpeed 251..254, PcGnssTime's)
CHECK_ALL = ("EcuStatus", "EcuDiag", "EcuSpeeds", "EcuTargets", "EcuFused", "EcuFusedAux")


def test_typed_decode_is_refused_exactly_when_a_signal_check_fails() -> None:
    rng = random.Random(RNG_SEED)
    accepted = refused = 0
    for name in CHECK_ALL:
        msg = protocol.database().get_message_by_name(name)
        for _ in range(1500):
            data = rng.randbytes(msg.length)
            raw = msg.decode(data, decode_choices=False, scaling=False)
            first_error = next(
                (
                    err
                    for s in msg.signals
                    if (err := _outcome(_reference_check, msg.name, s, raw[s.name]))[0] == "error"
                ),
                None,
            )
            got = _outcome(protocol.decode, (msg.frame_id, data))
            if first_error is not None:
                assert got == first_error, (msg.name, data.hex())
                refused += 1
            else:
                assert got[0] == "ok", (msg.name, data.hex(), got)
                accepted += 1
    assert accepted > 1000 and refused > 1000


def test_typed_decode_of_the_status_frame() -> None:
    data = (
        bytes([0x0A])
        + (2712).to_bytes(2, "little")
        + (1).to_bytes(2, "little")
        + bytes([150, 151, 65])
    )
    st = protocol.decode((protocol.DEFAULT_IDS.status, data))
    assert st == protocol.EcuStatus(True, 27.12, 0.01, 3000.0, 3020.0, 6.5)
    with pytest.raises(ProtocolError, match=r"EcuStatus\.RunState: undefined value 3"):
        protocol.decode((protocol.DEFAULT_IDS.status, bytes([3]) + data[1:]))


def _near_range_value(rng: random.Random, sig: Any) -> float:
    """A physical value inside the DBC range, on its edges (within and beyond cantools'
    tolerance of a millionth of the scale), between steps, or off the range by steps."""
    lo, hi, step = sig.minimum, sig.maximum, abs(sig.scale)
    edge = rng.choice([lo, hi])
    return rng.choice(
        [
            rng.uniform(lo, hi),
            edge,
            edge + rng.choice([-1, 1]) * step * rng.choice([5e-7, 2e-6, 0.5, 1.0]),
            round(rng.uniform(lo, hi) / step) * step + step / 2,
            float(rng.randint(int(lo) - 2, int(hi) + 2)),
        ]
    )


def test_compiled_encoders_give_cantools_bytes_or_leave_the_values_to_it() -> None:
    rng = random.Random(RNG_SEED)
    taken = 0
    for msg in _plain_messages():
        encode = encoder(msg.name)
        assert encode is not None
        for _ in range(2000):
            values = {s.name: _near_range_value(rng, s) for s in msg.signals}
            payload = encode(values)
            if payload is None:
                continue  # cantools encodes or refuses it
            taken += 1
            assert payload == msg.encode(values, strict=True), (msg.name, values)
    assert taken > 1000
    # what the fast form leaves to cantools: a missing or extra signal, a value off the range
    cmd = {"StartStop": 10, "FanSpeed": 3000.0, "UpperRate": 250.0, "LowerRate": 1.5}
    encode = encoder("PcCommand")
    assert encode is not None
    assert encode(cmd) is None
    assert encode({**cmd, "GnssSpeed": 6.5, "Other": 1.0}) is None
    assert encode({**cmd, "GnssSpeed": 25.6}) is None
    assert encode({**cmd, "GnssSpeed": 6.5}) == bytes.fromhex("0ab80ba861960041")
    with pytest.raises(ProtocolError, match="GnssSpeed"):
        protocol.encode_command(True, 3000.0, 250.0, 1.5, 25.6)
