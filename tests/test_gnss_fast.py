"""The decoder's fast path for clean RMC, VTG and GGA gives exactly what the full path (the
field parser, pynmeagps) gives: on every sentence of the recorded receiver logs, and on mutants
of them with each field emptied or made odd (the fast path must hand those over, and the full
path then names the error or the dropped field)."""

from __future__ import annotations

import random
from pathlib import Path

import pytest

from topdress.gnss import nmea
from topdress.gnss.nmea import GnssFix, NmeaDecoder, make_sentence

LOGS = Path("/work/shared/nmea/gpsd-logs")
ODD = (
    "",
    "x",
    "-1",
    "1e5",
    "inf",
    "nan",
    "2_2",
    ".5",
    "5.",
    "0",
    "360",
    "360.1",
    "181",
    "91",
    "9000.0",
    "18100.0",
    "00",
    "0a",
    "N",
    "S",
    "E",
    "W",
    "T",
    "M",
    "Q",
    "246000",
    "235960",
    "235959.1234567",
    "12345",
    "123456.",
    "310224",
    "290223",
    "290224",
    "000000",
    "011369",
    "010168",
    "1" * 400,
    "12.5.1",
    " 1",
    "+1",
)


def _both(lines: list[bytes]) -> tuple[list[GnssFix], list[GnssFix], NmeaDecoder, NmeaDecoder]:
    fast, full = NmeaDecoder(), NmeaDecoder()
    got = [fast.decode(line) for line in lines]
    saved = nmea._FAST
    nmea._FAST = {k: (lambda f, talker: None) for k in saved}
    try:
        want = [full.decode(line) for line in lines]
    finally:
        nmea._FAST = saved
    return got, want, fast, full


def _fields(line: bytes) -> list[bytes]:
    return line[line.rindex(b"$") + 1 : line.rindex(b"*")].split(b",")[1:]


def _log_lines() -> list[bytes]:
    if not LOGS.is_dir():
        pytest.skip(f"{LOGS} not present")
    return [raw for p in sorted(LOGS.glob("*.log")) for raw in p.read_bytes().splitlines()]


def test_fast_path_equals_the_field_parser_on_every_recorded_sentence() -> None:
    lines = _log_lines()
    got, want, fast, full = _both(lines)
    for line, a, b in zip(lines, got, want, strict=True):
        assert a == b, line
    assert fast.counters == full.counters
    taken = [
        nmea._FAST[f.type](_fields(line), f.talker or "")
        for line, f in zip(lines, got, strict=True)
        if f.ok and f.type in nmea._FAST and not f.dropped
    ]
    kinds = [f.type for f in taken if f is not None]
    assert min(kinds.count(k) for k in ("RMC", "VTG", "GGA")) > 300  # the fast path was taken


def test_fast_path_equals_the_field_parser_on_odd_fields() -> None:
    rng = random.Random(5)
    base = [raw for raw in _log_lines() if raw[3:6] in (b"RMC", b"VTG", b"GGA") and b"*" in raw]
    base = [
        *rng.sample(base, 150),
        b"$GNRMC,020000.20,A,4353.11800,S,12519.47000,W,4.320,90.0,150626,3.1,W,A*00",
        b"$GNVTG,90.0,T,,M,4.320,N,8.000,K,N*00",
        b"$GNGGA,020000.20,4353.11800,N,12519.47000,E,1,12,1.1,-15.0,M,0.0,M,1.5,0042*00",
    ]
    lines: list[bytes] = []
    for raw in base:
        body = raw[1 : raw.rindex(b"*")].decode("latin-1")
        fields = body.split(",")
        lines.append(make_sentence(body))
        for i in range(1, len(fields)):
            for odd in rng.sample(ODD, 8):
                lines.append(make_sentence(",".join([*fields[:i], odd, *fields[i + 1 :]])))
        lines.append(make_sentence(",".join(fields[:-2])))  # too few fields, or no mode
        lines.append(make_sentence(body)[:-4] + b"00\r\n")  # a bad checksum
    got, want, fast, full = _both(lines)
    for line, a, b in zip(lines, got, want, strict=True):
        assert a == b, line
    assert fast.counters == full.counters
    # every path was taken: clean fixes, dropped fields, refused lines
    assert fast.counters["ok"] > 1000 and fast.counters["bad_field"] > 100
    assert fast.counters["malformed"] > 100 and fast.counters["out_of_range"] > 10
