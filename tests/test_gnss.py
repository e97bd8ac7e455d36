"""NMEA decoding, the GNSS speed choice, the real gpsd captures and `topdress gnss decode`."""

from __future__ import annotations

import datetime as dt
import io
import json
import math
import random
import select
import subprocess
import sys
from pathlib import Path

import pytest

from topdress.cli.gnss import decode_stream
from topdress.cli.main import main
from topdress.gnss.nmea import GnssFix, NmeaDecoder, make_sentence, nmea_checksum
from topdress.gnss.tracker import GnssSpeedTracker

GPSD_LOGS = Path(__file__).resolve().parents[1].parent / "shared" / "nmea" / "gpsd-logs"

# Trimble RTK line from the gpsd captures: 3.252 kn = 6.0227 km/h = 1.673 m/s.
TRIMBLE_RMC = (
    b"$GPRMC,132820.60,A,4134.49821229,N,09345.03351845,W,3.252,92.308,180320,11.5985,E,D*1A"
)


def test_rmc_fields() -> None:
    fix = NmeaDecoder().decode(TRIMBLE_RMC + b"\r\n")
    assert fix.ok and fix.fix_valid and fix.error is None
    assert (fix.talker, fix.type) == ("GP", "RMC")
    assert fix.speed_kmh == pytest.approx(3.252 * 1.852)
    assert fix.course_deg == pytest.approx(92.308)
    assert fix.lat == pytest.approx(41 + 34.49821229 / 60)
    assert fix.lon == pytest.approx(-(93 + 45.03351845 / 60))
    assert fix.utc == "2020-03-18T13:28:20.600Z"


@pytest.mark.parametrize("talker", ["GP", "BD", "GB", "GN", "GL", "GA", "GQ"])
def test_any_talker(talker: str) -> None:
    line = make_sentence(f"{talker}RMC,081836.00,A,4304.5678,N,12534.1234,E,3.24,87.5,210526,,,A")
    fix = NmeaDecoder().decode(line)
    assert fix.ok and fix.fix_valid
    assert fix.talker == talker
    assert fix.speed_kmh == pytest.approx(6.00048)
    assert fix.lat == pytest.approx(43.07613)
    assert fix.utc == "2026-05-21T08:18:36.000Z"


def test_make_sentence_checksum_matches_a_receiver() -> None:
    assert make_sentence("GPGSA,A,1,,,,,,,,,,,,,,,,") == b"$GPGSA,A,1,,,,,,,,,,,,,,,,*32\r\n"
    assert nmea_checksum(b"BDGSA,A,1,,,,,,,,,,,,,,,,") == 0x23


def test_status_v_and_mode_n_are_no_valid_fix() -> None:
    d = NmeaDecoder()
    void = d.decode(make_sentence("GNRMC,074150.799,V,,,,,,,250215,,,N"))
    assert void.ok and not void.fix_valid and void.speed_kmh is None
    mode_n = d.decode(
        make_sentence("GPRMC,081836.00,A,4304.5678,N,12534.1234,E,3.24,87.5,210526,,,N")
    )
    assert mode_n.ok and not mode_n.fix_valid
    assert not d.decode(make_sentence("GPVTG,87.5,T,,M,3.24,N,6.00,K,N")).fix_valid
    assert not d.decode(
        make_sentence("GPGGA,081836.00,4304.5678,N,12534.1234,E,0,00,,,M,,M,,")
    ).fix_valid


def test_vtg_and_gga() -> None:
    d = NmeaDecoder()
    vtg = d.decode(make_sentence("BDVTG,054.7,T,034.4,M,005.5,N,010.2,K,A"))
    assert vtg.ok and vtg.fix_valid
    assert vtg.speed_kmh == pytest.approx(10.2)  # the km/h field is taken as given
    assert vtg.course_deg == pytest.approx(54.7)
    knots_only = d.decode(make_sentence("GPVTG,054.7,T,,M,005.5,N,,K"))
    assert knots_only.speed_kmh == pytest.approx(5.5 * 1.852)
    gga = d.decode(
        make_sentence("GNGGA,081836.00,4304.5678,N,12534.1234,E,1,12,0.8,210.0,M,8.0,M,,")
    )
    assert gga.ok and gga.fix_valid and gga.speed_kmh is None
    assert gga.utc == "08:18:36.000"
    assert gga.lon == pytest.approx(125.56872)


def test_other_sentences_are_accepted_without_a_fix() -> None:
    d = NmeaDecoder()
    gsv = d.decode(b"$GPGSV,7,7,25,04,08,012,*41")
    assert gsv == GnssFix(talker="GP", type="GSV", ok=True)
    prop = d.decode(b"$PSRFEPE,074150.799,V,,,,,*23")
    assert (prop.talker, prop.type, prop.ok) == ("P", "SRFEPE", True)


@pytest.mark.parametrize(
    ("line", "reason"),
    [
        (b"", "empty"),
        (b"\r\n", "empty"),
        (b"\xb5b\x01\x07\x5c\x00\xff\x10\x80", "binary"),
        (b"GPRMC,081836.00,A*1F", "no_start"),
        (b"$GPRMC,081836.00,A,4304.5678,N,12534.1234,E,3.24", "no_checksum"),
        (b"$GPRMC,081836.00,A,4304.5678,N,12534.1234,E,3.24,87.5,210526,,,A*", "truncated"),
        (b"$GPRMC,081836.00,A,4304.5678,N,12534.1234,E,3.24,87.5,210526,,,A*1", "truncated"),
        (b"$GPRMC,081836.00,A,4304.5678,N,12534.1234,E,3.24,87.5,210526,,,A*00", "bad_checksum"),
        (b"$GPRMC,081836.00,A,4304.5678,N,12534.1234,E,3.24,87.5,210526,,,A*G1", "malformed"),
        (b"$GPRMC,08\xff836.00,A,4304.5678,N,12534.1234,E,3.24*00", "binary"),
        (make_sentence("GPRMC,081836.00,A,4304.5678,N,12534.1234,E,3.24"), "truncated"),
        (make_sentence("GPGGA,081836.00,4304.5678,N"), "truncated"),
        (make_sentence("GPVTG,054.7,T"), "truncated"),
        (
            make_sentence("GPRMC,081836.00,A,43x4.5678,N,12534.1234,E,3.24,87.5,210526,,,A"),
            "malformed",
        ),
        (
            make_sentence("GPRMC,081836.00,A,4304.5678,N,12534.1234,E,fast,87.5,210526,,,A"),
            "malformed",
        ),
        (make_sentence("GPVTG,054.7,T,034.4,M,005.5,N,ten,K,A"), "malformed"),
        # text that Python's float() reads but NMEA does not write: not a number field
        (
            make_sentence("GPRMC,081836.00,A,4304.5678,N,12534.1234,E,nan,87.5,210526,,,A"),
            "malformed",
        ),
        (
            make_sentence("GPRMC,081836.00,A,4304.5678,N,12534.1234,E,1e999,87.5,210526,,,A"),
            "malformed",
        ),
        (
            make_sentence("GPRMC,081836.00,A,4304.5678,N,12534.1234,E,-3.2,87.5,210526,,,A"),
            "malformed",
        ),
        # numbers a checksum cannot vouch for: latitude 99, longitude 185
        (
            make_sentence("GPRMC,081836.00,A,9904.5678,N,12534.1234,E,3.24,87.5,210526,,,A"),
            "out_of_range",
        ),
        (
            make_sentence("GPRMC,081836.00,A,4304.5678,N,18534.1234,E,3.24,87.5,210526,,,A"),
            "out_of_range",
        ),
        (make_sentence("GPVTG,054.7,T,034.4,M,005.5,N,-10.2,K,A"), "malformed"),
        (
            make_sentence("GPGGA,081836.00,9104.5678,S,12534.1234,E,1,08,1.0,100,M,0,M,,"),
            "out_of_range",
        ),
        (make_sentence("gprmc,1"), "malformed"),
        (make_sentence(",,,"), "malformed"),
    ],
)
def test_bad_lines_are_rejected_and_counted(line: bytes, reason: str) -> None:
    d = NmeaDecoder()
    fix = d.decode(line)
    assert not fix.ok and not fix.fix_valid and fix.speed_kmh is None
    assert fix.error is not None and fix.error.startswith(reason + ":")
    assert d.counters == {reason: 1}


def test_sentence_after_binary_garbage_is_found() -> None:
    d = NmeaDecoder()
    fix = d.decode(b"\xb5b\x01\x07\x00\xff" + TRIMBLE_RMC)
    assert fix.ok and fix.speed_kmh == pytest.approx(6.0227, abs=1e-4)
    assert d.counters == {"ok": 1, "resync": 1}


def test_str_input_and_counters_by_reason() -> None:
    d = NmeaDecoder()
    d.decode(TRIMBLE_RMC.decode())
    d.decode("$GPRMC,junk*00")
    d.decode("$GPRMC,junk*00")
    d.decode(b"\x00\x01\x02")
    assert d.counters == {"ok": 1, "bad_checksum": 2, "binary": 1}


def _fix(kind: str, speed: float | None, valid: bool = True) -> GnssFix:
    return GnssFix(talker="GN", type=kind, ok=True, fix_valid=valid, speed_kmh=speed)


def test_tracker_prefers_rmc_and_uses_vtg_only_without_rmc() -> None:
    tr = GnssSpeedTracker(rmc_timeout_s=1.5, stale_s=2.0)
    assert tr.current(0.0) is None
    assert tr.update(0.0, _fix("VTG", 5.0)) is not None  # no RMC yet: VTG is used
    assert tr.current(0.1) == 5.0
    sample = tr.update(0.2, _fix("RMC", 6.1))
    assert sample is not None and sample.sentence == "RMC"
    assert tr.update(0.25, _fix("VTG", 9.9)) is None  # RMC present: VTG ignored
    assert tr.current(0.3) == 6.1
    assert tr.update(1.7, _fix("VTG", 7.0)) is None  # 1.5 s after the RMC: still ignored
    assert tr.update(1.71, _fix("VTG", 7.0)) is not None  # RMC silent > 1.5 s: VTG used
    assert tr.current(1.8) == 7.0


def test_tracker_loses_gnss_on_status_v_stale_or_disconnect() -> None:
    tr = GnssSpeedTracker(rmc_timeout_s=1.5, stale_s=2.0)
    tr.update(10.0, _fix("RMC", 8.0))
    assert tr.current(11.9) == 8.0
    assert tr.current(12.01) is None  # stale
    assert tr.current(10.5, connected=False) is None
    tr.update(12.1, _fix("RMC", None, valid=False))
    assert tr.current(12.2) is None  # status V forwards "not available" at once
    tr.update(12.3, _fix("GSV", None, valid=False))
    bad = GnssFix(talker=None, type=None, ok=False, error="bad_checksum: x")
    assert tr.update(12.4, bad) is None
    tr.update(12.5, _fix("RMC", 8.2))
    assert tr.current(12.6) == 8.2


def test_tracker_keeps_the_position() -> None:
    tr = GnssSpeedTracker()
    tr.update(1.0, NmeaDecoder().decode(TRIMBLE_RMC))
    assert tr.position is not None
    assert (tr.position.t, round(tr.position.lat, 6)) == (1.0, 41.57497)


def _gpsd_files() -> list[Path]:
    if not GPSD_LOGS.is_dir():
        pytest.skip(f"{GPSD_LOGS} not present")
    return sorted(GPSD_LOGS.glob("*.log"))


def _tpv_speeds(chk: Path) -> dict[dt.datetime, set[float]]:
    speeds: dict[dt.datetime, set[float]] = {}
    for raw in chk.read_bytes().splitlines():
        if not raw.startswith(b'{"class":"TPV"'):
            continue
        obj = json.loads(raw)
        if "time" in obj and "speed" in obj:
            speeds.setdefault(_when(obj["time"]), set()).add(obj["speed"])
    return speeds


def _when(iso: str) -> dt.datetime:
    return dt.datetime.fromisoformat(iso.replace("Z", "+00:00"))


def test_gpsd_captures_decode_and_rmc_speeds_agree_with_gpsd() -> None:
    files = _gpsd_files()
    assert len(files) >= 10
    compared = 0
    for path in files:
        tpv = _tpv_speeds(path.with_name(path.name + ".chk"))
        out, err = io.StringIO(), io.StringIO()
        with path.open("rb") as stream:
            assert decode_stream(stream, out, err) == 0
        for row in map(json.loads, out.getvalue().splitlines()):
            if row["type"] != "RMC" or row["speed_kmh"] is None or "T" not in (row["utc"] or ""):
                continue
            gpsd = tpv.get(_when(row["utc"]))
            if gpsd is None:  # gpsd reported no speed for that epoch
                continue
            # gpsd prints m/s with 3 decimals.
            assert any(abs(row["speed_kmh"] / 3.6 - s) < 6e-4 for s in gpsd), (path.name, row)
            compared += 1
    assert compared >= 600


def test_gpsd_binary_and_cut_lines_are_counted_not_raised() -> None:
    path = next((p for p in _gpsd_files() if p.name == "ublox-8.log"), None)
    if path is None:
        pytest.skip("ublox-8.log not present")
    err = io.StringIO()
    with path.open("rb") as stream:
        decode_stream(stream, io.StringIO(), err)
    assert "no_checksum=1" in err.getvalue()
    assert "resync=1" in err.getvalue()


def test_gnss_decode_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "capture.nmea"
    path.write_bytes(b"# header\r\n" + TRIMBLE_RMC + b"\r\n\r\n$GPRMC,cut\r\n")
    assert main(["gnss", "decode", str(path)]) == 0
    out, err = capsys.readouterr()
    rows = [json.loads(x) for x in out.splitlines()]
    assert [r["line"] for r in rows] == [2, 4]
    assert list(rows[0]) == [
        "line",
        "talker",
        "type",
        "ok",
        "error",
        "fix_valid",
        "speed_kmh",
        "course_deg",
        "lat",
        "lon",
        "utc",
        "dropped",
    ]
    assert rows[0]["ok"] and rows[0]["speed_kmh"] == pytest.approx(6.022704)
    assert rows[1]["ok"] is False and rows[1]["error"].startswith("no_checksum")
    assert "no_checksum=1" in err and "ok=1" in err


def test_gnss_decode_missing_file(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["gnss", "decode", "/nonexistent/capture.nmea"]) == 2
    assert "cannot read /nonexistent/capture.nmea" in capsys.readouterr().err


def test_gnss_decode_reads_stdin(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    data = TRIMBLE_RMC + b"\r\n\xb5b\x01\x07\r\n"
    monkeypatch.setattr("sys.stdin", io.TextIOWrapper(io.BytesIO(data)))
    assert main(["gnss", "decode", "-"]) == 0
    rows = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert [(r["line"], r["ok"]) for r in rows] == [(1, True), (2, False)]
    assert rows[1]["error"].startswith("binary:")


class _Chunks(io.RawIOBase):
    """A stream that hands out the given chunks one read at a time, as a pipe does."""

    def __init__(self, chunks: list[bytes]) -> None:
        self._chunks = chunks

    def read1(self, size: int = -1) -> bytes:
        return self._chunks.pop(0) if self._chunks else b""


def test_gnss_decode_numbers_lines_across_chunks() -> None:
    # CRLF split between two reads is one line end; CR alone and LF alone are one each.
    rmc = TRIMBLE_RMC
    chunks = [rmc + b"\r", b"\n" + rmc[:20], rmc[20:] + b"\r" + rmc + b"\n\n" + rmc]
    out = io.StringIO()
    decode_stream(_Chunks(chunks), out, io.StringIO())  # type: ignore[arg-type]
    rows = [json.loads(x) for x in out.getvalue().splitlines()]
    assert [(r["line"], r["ok"]) for r in rows] == [(1, True), (2, True), (3, True), (5, True)]
    # a long stretch without a line end over many reads is one line
    out = io.StringIO()
    chunks = [b"\xb5b" * 40_000] * 5 + [b"\r\n" + rmc + b"\r"]
    decode_stream(_Chunks(chunks), out, io.StringIO())  # type: ignore[arg-type]
    rows = [json.loads(x) for x in out.getvalue().splitlines()]
    assert [(r["line"], r["ok"], r["type"]) for r in rows] == [(1, False, None), (2, True, "RMC")]


def test_gnss_decode_shows_a_live_receiver_line_by_line() -> None:
    # `cat /dev/ttyUSB0 | topdress gnss decode -`: each line is printed as it comes, not at EOF
    proc = subprocess.Popen(
        [sys.executable, "-m", "topdress.cli", "gnss", "decode", "-"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert proc.stdin is not None and proc.stdout is not None
    try:
        proc.stdin.write(TRIMBLE_RMC + b"\r\n")
        proc.stdin.flush()
        ready, _, _ = select.select([proc.stdout], [], [], 30.0)  # a bound, not a measurement
        assert ready, "nothing decoded while the receiver keeps the pipe open"
        row = json.loads(proc.stdout.readline())
        assert row["line"] == 1 and row["speed_kmh"] == pytest.approx(6.022704)
    finally:
        proc.stdin.close()
        proc.wait(timeout=30)
        proc.stdout.close()
        assert proc.stderr is not None
        proc.stderr.close()


# A checksum-valid sentence with a second '*' inside: framing (last '*') and the field parser
# (first '*') disagreed on where the body ends and the parser raised AttributeError.
@pytest.mark.parametrize(
    "line",
    [
        b"$GPRMC,,*,,,,,,,,,,*61",
        b"$GPVTG,,T,,M,,N*,,K,N*06",
        b"$GPGGA,,,*,,,,,,,,,,,*7C",
        # the first checksum wrong, a second one right over the whole text: not accepted
        b"$GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W*00*40",
    ],
)
def test_second_star_is_malformed(line: bytes) -> None:
    body = line[1 : line.rindex(b"*")]
    assert int(line[-2:], 16) == nmea_checksum(body)  # the reproducer's checksum holds
    d = NmeaDecoder()
    fix = d.decode(line)
    assert not fix.ok and fix.speed_kmh is None
    assert fix.error is not None and fix.error.startswith("malformed:")
    assert d.counters == {"malformed": 1}


@pytest.mark.parametrize(
    "body",
    [
        # 1e308 knots passed the finiteness check and overflowed to an infinite km/h
        "GPRMC,123519,A,4807.038,N,01131.000,E,1e308,084.4,230394,003.1,W",
        "GPVTG,054.7,T,034.4,M,1e308,N,,K,A",
        "GPRMC,123519,A,4807.038,N,01131.000,E,2_2.4,084.4,230394,003.1,W",
        "GPRMC,123519,A,-4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W",
        "GPRMC,123519,A,4807.038,Q,01131.000,E,022.4,084.4,230394,003.1,W",
        "GPRMC,123519,A,4807.038,N,01131.000,,022.4,084.4,230394,003.1,W",
        "GPGGA,123519,4807.038,N,01131.000,X,1,08,0.9,545.4,M,46.9,M,,",
        "GPRMC,123519,A,4807.038,N,01131.000,E,+22.4,084.4,230394,003.1,W",
        "GPRMC,123519,A,4807.038,N,01131.000,E,inf,084.4,230394,003.1,W",
    ],
)
def test_number_fields_take_nmea_forms_only(body: str) -> None:
    d = NmeaDecoder()
    fix = d.decode(make_sentence(body))
    assert not fix.ok and fix.speed_kmh is None
    assert fix.error is not None and fix.error.startswith("malformed:"), fix.error
    assert d.counters == {"malformed": 1}


def test_long_number_that_overflows_after_conversion_is_refused() -> None:
    # 10**309 knots: an NMEA-form number whose float is already infinite
    d = NmeaDecoder()
    fix = d.decode(make_sentence(f"GPVTG,054.7,T,034.4,M,1{'0' * 309},N,,K,A"))
    assert not fix.ok and fix.error is not None and fix.error.startswith("out_of_range:")
    # 10**308 knots is finite, but knots * 1.852 overflows: checked after converting
    fix = d.decode(make_sentence(f"GPVTG,054.7,T,034.4,M,1{'0' * 308},N,,K,A"))
    assert not fix.ok and fix.error is not None and fix.error.startswith("out_of_range:")
    assert d.counters == {"out_of_range": 2}


def test_worked_rmc_still_decodes_with_the_stricter_fields() -> None:
    # the classic example sentence, with its real checksum: 22.4 kn = 41.4848 km/h
    fix = NmeaDecoder().decode(
        b"$GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W*6A"
    )
    assert fix.ok and fix.fix_valid
    assert fix.speed_kmh == pytest.approx(22.4 * 1.852)
    assert fix.lat == pytest.approx(48 + 7.038 / 60)
    assert fix.lon == pytest.approx(11 + 31.0 / 60)


def test_mutated_sentences_never_raise_and_never_give_a_non_finite_number() -> None:
    # Deterministic mutations of real sentences, checksum recomputed so they reach the field
    # parser: every one is a fix or a counted rejection, with finite numbers only.
    rng = random.Random(11)
    bases = [
        "GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W",
        "GPVTG,054.7,T,034.4,M,005.5,N,010.2,K,A",
        "GNGGA,081836.00,4304.5678,N,12534.1234,E,1,08,1.0,100,M,0,M,,",
        "BDRMC,081836.00,A,4304.5678,N,12534.1234,E,3.24,87.5,210526,,,A",
    ]
    alphabet = "0123456789.,*-+_eENSWQ$AVnaif "
    d = NmeaDecoder()
    for _ in range(8_000):
        body = list(rng.choice(bases))
        for _ in range(rng.randint(1, 4)):
            i = rng.randrange(len(body))
            if rng.random() < 0.5:
                body[i] = rng.choice(alphabet)
            else:
                body.insert(i, rng.choice(["*", "1e308", "9" * 320, ",", "-"]))
        fix = d.decode(make_sentence("".join(body)))
        for value in (fix.speed_kmh, fix.course_deg, fix.lat, fix.lon):
            assert value is None or math.isfinite(value), fix
        assert fix.ok or fix.error is not None
    assert sum(d.counters.values()) - d.counters["resync"] - d.counters["bad_field"] == 8_000
    assert d.counters["ok"] > 400 and d.counters["malformed"] > 400


@pytest.mark.parametrize(
    ("body", "dropped"),
    [
        # a real receiver's RMC: a date of "2208-1" (GPSD keeps the position and the speed)
        ("GNRMC,083150.00,A,4352.9170,N,12519.4720,E,0.15,212.28,2208-1,,,A", ("date",)),
        ("GNRMC,083150.00,A,4352.9170,N,12519.4720,E,0.15,212.28,310226,,,A", ("date",)),
        ("GNRMC,083150.00,A,4352.9170,N,12519.4720,E,0.15,400.0,150626,,,A", ("course",)),
        ("GNRMC,083150.00,A,4352.9170,N,12519.4720,E,0.15,21x.2,150626,,,A", ("course",)),
        (
            "GNRMC,083150.00,A,4352.9170,N,12519.4720,E,0.15,212.28,150626,7.x,Q,A",
            ("magvar", "magvar_ew"),
        ),
    ],
)
def test_rmc_with_one_malformed_optional_field_keeps_position_and_speed(
    body: str, dropped: tuple[str, ...]
) -> None:
    d = NmeaDecoder()
    fix = d.decode(make_sentence(body))
    assert fix.ok and fix.fix_valid and fix.dropped == dropped
    assert (fix.lat, fix.lon) == pytest.approx((43 + 52.917 / 60, 125 + 19.472 / 60))
    assert fix.speed_kmh == pytest.approx(0.15 * 1.852)
    if "date" in dropped:  # the time of day stays; UTC needs the date, so no UTC from it
        assert fix.utc == "08:31:50.000" and fix.course_deg == pytest.approx(212.28)
    else:
        assert fix.utc == "2026-06-15T08:31:50.000Z"
    if "course" in dropped:
        assert fix.course_deg is None
    assert d.counters == {"ok": 1, "bad_field": 1}


def test_vtg_and_gga_keep_their_speed_and_position_without_a_bad_optional_field() -> None:
    d = NmeaDecoder()
    vtg = d.decode(make_sentence("GPVTG,nan,T,034.4,M,005.5,N,10.2,K,A"))
    assert vtg.ok and vtg.speed_kmh == pytest.approx(10.2) and vtg.course_deg is None
    assert vtg.dropped == ("course",)
    gga = d.decode(make_sentence("GNGGA,081836.00,4304.5678,N,12534.1234,E,1,08,1.x,-31.4,M,,M,,"))
    assert gga.ok and gga.fix_valid and gga.dropped == ("hdop",)
    assert gga.lat == pytest.approx(43 + 4.5678 / 60)
    # a negative altitude is a number, not a malformed field
    gga = d.decode(
        make_sentence("GNGGA,081836.00,4304.5678,N,12534.1234,E,1,08,0.9,-31.4,M,-2,M,,")
    )
    assert gga.ok and gga.dropped == ()
    # the essential fields still refuse the sentence: a bad speed or position is not guessed
    bad = d.decode(make_sentence("GNRMC,083150.00,A,4352.9170,N,12519.4720,E,0.1x,,2208-1,,,A"))
    assert not bad.ok and bad.error is not None and bad.error.startswith("malformed:")
    assert d.counters == {"ok": 3, "bad_field": 2, "malformed": 1}


def test_gpsd_captures_rmc_with_a_broken_date_keep_gpsds_position_and_speed() -> None:
    # Every RMC of the GPSD captures with a valid fix, its date cut as the real receiver's
    # ("2208-1") and the checksum made again: the same position and speed as the whole line.
    logs = Path("/work/shared/nmea/gpsd-logs")
    if not logs.is_dir():
        pytest.skip(f"{logs} not present")
    d = NmeaDecoder()
    n = 0
    for path in sorted(logs.glob("*.log")):
        for raw in path.read_bytes().splitlines():
            whole = d.decode(raw) if raw[3:6] == b"RMC" else None
            if whole is None or not whole.fix_valid or whole.utc is None or "T" not in whole.utc:
                continue
            fields = raw[1 : raw.rindex(b"*")].decode().split(",")
            fields[9] = fields[9][:4] + "-1"
            cut = d.decode(make_sentence(",".join(fields)))
            assert cut.ok and cut.fix_valid and cut.dropped == ("date",), raw
            assert (cut.lat, cut.lon, cut.speed_kmh) == (whole.lat, whole.lon, whole.speed_kmh)
            assert cut.utc == whole.utc.split("T")[1].rstrip("Z")
            n += 1
    assert n > 600 and d.counters["bad_field"] == n


def test_the_terminal_counts_a_dropped_field_apart_from_bad_lines() -> None:
    from topdress.config import loads_config
    from topdress.devices.can import open_bus
    from topdress.devices.lines import FakeLineSource
    from topdress.terminal.app import Terminal

    cfg = loads_config('[can]\nchannel = "test-gnss-bad-field"\n')
    bus = open_bus(cfg.can)
    try:
        term = Terminal(cfg, FakeLineSource(), FakeLineSource(), bus, clock=lambda: 1.0)
        body = "GNRMC,083150.00,A,4352.9170,N,12519.4720,E,4.15,212.28,2208-1,,,A"
        term.handle("nmea", 1.0, make_sentence(body))
        term.handle("nmea", 1.1, b"$GPRMC,cut")
        term.tick(1.2)
        counters = term.snapshot.counters
        assert (counters["nmea"], counters["nmea_bad"], counters["nmea_bad_field"]) == (1, 1, 1)
        assert term.snapshot.lat == pytest.approx(43 + 52.917 / 60)  # the position was kept
    finally:
        bus.shutdown()
