"""Event format (NDJSON) and `topdress log export`."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from topdress import protocol
from topdress.cli.main import main
from topdress.log.events import (
    CanEvent,
    CropEvent,
    Event,
    NmeaEvent,
    WheelEvent,
    parse,
    read_file,
    read_lines,
    to_json,
)
from topdress.log.export import WHEEL_PULSES_MOD, WheelUnwrap, session_events
from topdress.log.model import StateRow
from topdress.log.session import SessionLog, SessionReader

RMC = "$GPRMC,123519,A,4807.038,N,01131.000,E,3.78,084.4,230394,003.1,W*6E"
CROP = "2,0.0412,0.2104,0.4419,0.3541,0.8295"


def diag_frame(pulses: int, ids: protocol.FrameIds = protocol.DEFAULT_IDS) -> tuple[int, bytes]:
    data = (
        protocol.database()
        .get_message_by_name("EcuDiag")
        .encode(
            {
                "SpeedSource": 1,
                "SpeedMode": 0,
                "GnssValid": 1,
                "Uniform": 1,
                "SwitchCompare": 0,
                "Cv": 1.5,
                "FaultWord": 0,
                "WheelPulses": pulses,
            }
        )
    )
    return ids.diag, bytes(data)


@pytest.mark.parametrize(
    "event",
    [
        NmeaEvent(12.5, RMC),
        WheelEvent(0.1 + 0.2, 16_777_300),
        CropEvent(1e-3, CROP),
        CanEvent(3.0, 0x0A5C6465, bytes.fromhex("0ab80b983a000037"), "tx"),
        CanEvent(3.0, 0x123, b"", None),
    ],
)
def test_every_event_round_trips_exactly(event: Event) -> None:
    line = to_json(event)
    assert "\n" not in line
    assert parse(line) == event


def test_documented_examples_parse() -> None:
    assert parse('{"t": 100.02, "can": {"id": 408708197, "data": "0a"}}') == CanEvent(
        100.02, 0x185C6465, b"\x0a"
    )
    assert parse('{"t": 7, "wheel_count": 1500, "note": "x"}') == WheelEvent(7.0, 1500)


def test_malformed_lines_are_reported_with_their_number_and_skipped() -> None:
    lines = [
        '{"t": 1.0, "nmea": "' + RMC + '"}',  # 1 ok
        "not json",  # 2
        "[1, 2]",  # 3
        '{"nmea": "x"}',  # 4 no t
        '{"t": true, "crop": "x"}',  # 5
        '{"t": 2.0, "nmea": "x", "crop": "y"}',  # 6 two payloads
        '{"t": 2.0, "speed": 3}',  # 7 no payload
        '{"t": 2.0, "wheel_count": -5}',  # 8
        '{"t": 2.0, "wheel_count": 2.5}',  # 9
        '{"t": 2.0, "can": {"id": 536870912, "data": "00"}}',  # 10 id > 29 bits
        '{"t": 2.0, "can": {"id": 1, "data": "zz"}}',  # 11
        '{"t": 2.0, "can": {"id": 1, "data": "000000000000000000"}}',  # 12 9 bytes
        "",  # 13 blank: skipped silently
        '{"t": 0.5, "crop": "' + CROP + '"}',  # 14 ok: earlier than line 1 (replay sorts)
        '{"t": 2.0, "wheel_count": 40, "extra": {"a": 1}}',  # 15 ok (unknown key)
        '{"t": 2.0, "can": {"id": 1, "data": "00", "dir": "up"}}',  # 16
        '{"t": NaN, "nmea": "x"}',  # 17
    ]
    result = read_lines(lines)
    assert result.events == [NmeaEvent(1.0, RMC), CropEvent(0.5, CROP), WheelEvent(2.0, 40)]
    numbers = [n for n, _ in result.bad]
    assert numbers == [2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 16, 17]
    reasons = dict(result.bad)
    assert "not JSON" in reasons[2]
    assert "exactly one" in reasons[6] and "nmea, crop" in reasons[6]
    assert "0x1FFFFFFF" in reasons[10] and "at most 8" in reasons[12]


def test_unwrap_counts_forward_across_the_24_bit_wrap() -> None:
    u = WheelUnwrap()
    assert u.update(WHEEL_PULSES_MOD - 10) == WHEEL_PULSES_MOD - 10
    assert u.update(5) == WHEEL_PULSES_MOD + 5
    assert u.update(5) == WHEEL_PULSES_MOD + 5
    assert u.update(105) == WHEEL_PULSES_MOD + 105


def make_session(directory: Path) -> Path:
    with SessionLog.create(directory, "[machine]\nwidth_m = 3.6\n") as log:
        log.raw("nmea", 100.0, RMC)
        log.raw("crop", 100.01, CROP)
        log.raw("can_rx", 100.05, diag_frame(WHEEL_PULSES_MOD - 100))
        log.raw("can_tx", 100.08, (0x0A5C6465, bytes.fromhex("0ab80b983a000037")))
        log.raw("can_rx", 100.15, diag_frame(50))
        log.raw("can_rx", 100.16, (0x185D6465, b"\x00\x01"))  # short EcuDiag: not decodable
        log.state(StateRow(100.1, 45.5, 126.5, None, 1.2, 1.2, "wheel", None, 0.83, *[0.0] * 8, 2))
    return log.path


def test_export_turns_diag_frames_into_cumulative_wheel_counts(tmp_path: Path) -> None:
    path = make_session(tmp_path)
    with SessionReader(path) as reader:
        events = list(session_events(reader))
    assert events == [
        NmeaEvent(100.0, RMC),
        CropEvent(100.01, CROP),
        CanEvent(100.05, *diag_frame(WHEEL_PULSES_MOD - 100), "rx"),
        WheelEvent(100.05, WHEEL_PULSES_MOD - 100),
        CanEvent(100.08, 0x0A5C6465, bytes.fromhex("0ab80b983a000037"), "tx"),
        CanEvent(100.15, *diag_frame(50), "rx"),
        WheelEvent(100.15, WHEEL_PULSES_MOD + 50),
        CanEvent(100.16, 0x185D6465, b"\x00\x01", "rx"),
    ]


def test_export_command_writes_events_and_csv(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = make_session(tmp_path)
    events, table = tmp_path / "out.ndjson", tmp_path / "out.csv"
    assert main(["log", "export", str(path), "--events", str(events), "--csv", str(table)]) == 0
    assert "8 events (2 wheel counts), 1 EcuDiag frames not decoded" in capsys.readouterr().out
    lines = events.read_text().splitlines()
    assert json.loads(lines[3]) == {"t": 100.05, "wheel_count": WHEEL_PULSES_MOD - 100}
    assert read_file(events).events[0] == NmeaEvent(100.0, RMC)
    with table.open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 1
    assert rows[0]["lat"] == "45.5" and rows[0]["v_gnss_kmh"] == "" and rows[0]["faults"] == "2"
    assert rows[0]["ndvi"] == "0.83" and rows[0]["source"] == "wheel"


def test_export_is_in_time_order_when_threads_logged_out_of_order(tmp_path: Path) -> None:
    # A serial reader thread stamps its line, then the CAN thread logs a later frame first.
    with SessionLog.create(tmp_path, "") as log:
        log.raw("can_rx", 10.2502, (0x123, b"\x01"))
        log.raw("nmea", 10.2500, RMC)
        log.raw("crop", 10.2502, CROP)
    with SessionReader(log.path) as reader:
        events = list(session_events(reader))
    assert events == [
        NmeaEvent(10.25, RMC),
        CanEvent(10.2502, 0x123, b"\x01", "rx"),
        CropEvent(10.2502, CROP),
    ]


def test_export_writes_the_session_configuration(tmp_path: Path) -> None:
    path = make_session(tmp_path)
    out = tmp_path / "session.toml"
    assert main(["log", "export", str(path), "--config", str(out)]) == 0
    assert out.read_text() == "[machine]\nwidth_m = 3.6\n"


def test_export_errors_are_clear(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["log", "export", str(tmp_path / "none.sqlite"), "--events", "x"]) == 2
    assert "no such session file" in capsys.readouterr().err
    path = make_session(tmp_path)
    assert main(["log", "export", str(path)]) == 2
    assert "nothing to do" in capsys.readouterr().err
    out = tmp_path / "missing-dir" / "e.ndjson"
    assert main(["log", "export", str(path), "--events", str(out)]) == 2
    assert "cannot write" in capsys.readouterr().err
    # a typo that names the session as the output leaves the session whole
    size = path.stat().st_size
    assert main(["log", "export", str(path), "--csv", str(path)]) == 2
    assert "is the input" in capsys.readouterr().err
    assert path.stat().st_size == size
    assert main(["log", "summary", str(path)]) == 0


def test_a_byte_order_mark_does_not_cost_the_first_event(tmp_path: Path) -> None:
    path = tmp_path / "edited.ndjson"
    path.write_bytes(
        "\ufeff".encode() + b'{"t": 1.0, "wheel_count": 7}\n{"t": 2.0, "wheel_count": 9}\n'
    )
    result = read_file(path)
    assert result.bad == [] and result.events == [WheelEvent(1.0, 7), WheelEvent(2.0, 9)]


@pytest.mark.parametrize(
    "event",
    [
        NmeaEvent(5123.207, '$GNRMC,08"15\\03\r\n'),
        CropEvent(1e-7, "2,0.04\x00,é,\u2028"),
        WheelEvent(3.0, 2**40),
        CanEvent(0.1, 0x1FFFFFFF, b"\x00\xff", "rx"),
        CanEvent(12.5, 0, b"", None),
        NmeaEvent(float("nan"), "x"),
    ],
)
def test_the_fast_json_is_what_json_dumps_gives(event: Event) -> None:
    from topdress.log.events import _to_json_slow

    assert to_json(event) == _to_json_slow(event)


def _lines_in_every_form() -> list[str]:
    """Lines in `to_json`'s form and near misses: each must parse as the full parser parses
    it, or fail with its reason."""
    written = [
        to_json(e)
        for e in (
            NmeaEvent(1000.25, RMC + "\r\n"),
            NmeaEvent(-3.5e-7, "$GN\u00e9\u2028"),
            CropEvent(1e22, CROP + "\r\n"),
            CropEvent(0.0, ""),
            WheelEvent(7.0, 0),
            WheelEvent(7.1, 2**40),
            CanEvent(1.0, 0x1FFFFFFF, bytes(range(8)), "rx"),
            CanEvent(2.0, 0, b"", "tx"),
            CanEvent(3.0, 0x185C6465, b"\x0a", None),
        )
    ]
    near = [
        '{"t":1e999,"crop":"x"}',  # not finite
        '{"t":01.5,"crop":"x"}',  # not JSON (leading zero)
        '{"t":1,"wheel_count":' + "9" * 40 + "}",  # long integers: the full parser's
        '{"t":1,"can":{"id":536870912,"data":"00","dir":"rx"}}',  # id > 29 bits
        '{"t":1,"can":{"id":1,"data":"000000000000000000","dir":"rx"}}',  # 9 bytes
        '{"t":1,"can":{"id":1,"data":"0A","dir":"rx"}}',  # upper case: valid, full parser
        '{"t":1,"can":{"id":1,"data":"0","dir":"rx"}}',  # odd hex
        '{"t":1,"nmea":"a\\tb"}',  # another escape: full parser
        '{"t":1,"nmea":"a\\"b"}',
        '{"t":1,"nmea":"a\\\\rb"}',  # an escaped backslash before r
        '{"t":1,"nmea":"a\tb"}',  # a raw control character: not JSON
        '{"t":1,"crop":"x"} ',
        '{"t":1,"crop":"x"}\n',
        '{"t":1,"crop":"x"}\n\n',
        '{"t":1,"crop":"x","crop":"y"}',
        '{"t":1,"can":{"id":1,"data":"00","dir":"up"}}',
        '{"t":-0,"wheel_count":3}',
        '{"t":2E+3,"wheel_count":3}',
    ]
    return written + near


def test_the_fast_reading_is_what_the_full_parser_gives() -> None:
    from topdress.log.events import _FAST, _parse_json

    lines = _lines_in_every_form()
    assert sum(_FAST.match(line) is not None for line in lines) >= 14  # the fast path is taken
    for line in lines:
        try:
            expected: Event | str = _parse_json(line)
        except ValueError as exc:
            expected = f"error: {exc}"
        try:
            got: Event | str = parse(line)
        except ValueError as exc:
            got = f"error: {exc}"
        assert got == expected, line
        assert type(got) is type(expected)
        if isinstance(got, Event.__args__):  # type: ignore[attr-defined]
            assert type(got.t) is float


def test_lines_dropped_unbuilt_are_those_the_predicate_drops() -> None:
    from topdress.log.replay import DROP, needed

    lag = protocol.DEFAULT_IDS.gnss_lag
    events = [
        NmeaEvent(1.0, RMC + "\r\n"),
        CropEvent(1.1, CROP),
        CanEvent(1.2, protocol.DEFAULT_IDS.status, b"\x00" * 8, "rx"),
        CanEvent(1.3, lag, b"\x01" * 8, "rx"),
        CanEvent(1.4, protocol.DEFAULT_IDS.command, b"\x02" * 8, "tx"),
        CanEvent(1.5, protocol.DEFAULT_IDS.status, b"\x03", None),
        WheelEvent(1.6, 12),
    ]
    lines = [to_json(e) for e in events] + ['{"t": 2.0, "crop": "spaced"}', '{"t":1e999,"crop":""}']
    plain = read_lines(lines, needed)
    dropped = read_lines(lines, needed, DROP)
    assert dropped.events == plain.events == [e for e in events if needed(e)]
    assert dropped.parsed == plain.parsed == len(events) + 1
    assert dropped.bad == plain.bad and [n for n, _ in plain.bad] == [9]
