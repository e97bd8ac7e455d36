"""The live console: an ANSI block redrawn in place on a TTY, one line per second otherwise."""

from __future__ import annotations

import io

from topdress.protocol import Fault
from topdress.terminal.app import Snapshot
from topdress.terminal.console import Console, fault_names, render_line, render_lines

WORKING = Snapshot(
    t_s=12.3,
    running=True,
    source="gnss",
    v_kmh=8.02,
    v_wheel_kmh=7.61,
    v_gnss_kmh=8.0,
    cv_pct=2.51,
    uniform=True,
    ndvi_sensors=0.612,
    ndvi=0.587,
    rate_kg_ha=(138.9, 138.9),
    target_rpm=(22.09, 22.09),
    meter_rpm=(22.69, 22.5),
    fan_rpm=(3020.0, 3000.0),
    faults=int(Fault.UPPER_FAN_LOW | Fault.GNSS_LOST),
    ecu_link="ok",
    gnss_link="ok",
    crop_link="3/4",
    counters={"nmea": 120, "nmea_bad": 2},
    last_event="GNSS ok",
)


def test_fault_names_follow_the_fault_word() -> None:
    assert fault_names(0) == []
    assert fault_names(int(Fault.CMD_TIMEOUT | Fault.NO_SPEED)) == ["CMD_TIMEOUT", "NO_SPEED"]
    assert fault_names(1 << 9) == ["BIT9"]
    # the console's names are the protocol's
    assert [fault_names(int(f)) for f in Fault] == [[f.name] for f in Fault]


def test_status_block_shows_every_figure() -> None:
    text = "\n".join(render_lines(WORKING))
    for part in (
        "8.02 km/h from gnss",
        "wheel  7.61",
        "GNSS  8.00 km/h",
        "CV 2.51 % (uniform)",
        "sensors 0.612  at meters 0.587",
        "rate upper  138.9  lower  138.9 kg/ha",
        "target  22.09 /  22.09 r/min",
        "actual  22.69 /  22.50 r/min",
        "3020 /  3000 rpm",
        "faults: GNSS_LOST, UPPER_FAN_LOW",
        "ECU ok",
        "GNSS ok",
        "CROP 3/4",
        "RUNNING",
        "nmea 120  nmea_bad 2",
        "last    GNSS ok",
    ):
        assert part in text, part


def test_unknown_values_show_as_dashes() -> None:
    line = render_line(Snapshot())
    assert "cv=--%" in line and "ndvi=--" in line and "ecu=wait" in line and "crop=wait" in line
    # as wide as a number, so the columns do not jump when GNSS comes and goes
    assert "GNSS    -- km/h" in render_lines(Snapshot())[1]
    assert "GNSS  8.00 km/h" in render_lines(WORKING)[1]


def test_not_a_tty_prints_one_line_per_second_at_10_hz() -> None:
    out = io.StringIO()
    con = Console(out, tty=False)
    drawn = [con.update(WORKING, k * 0.1) for k in range(51)]  # 0.0 .. 5.0 s
    assert sum(drawn) == 6
    lines = out.getvalue().splitlines()
    assert len(lines) == 6
    assert "\x1b" not in out.getvalue()
    assert lines[0].startswith("t=12.3s v=8.02km/h src=gnss cv=2.51%")


def test_tty_redraws_the_block_in_place() -> None:
    out = io.StringIO()
    con = Console(out, tty=True, period_s=0.3)
    n = len(render_lines(WORKING))
    assert [con.update(WORKING, t) for t in (0.0, 0.1, 0.2, 0.3, 0.4)] == [
        True,
        False,
        False,
        True,
        False,
    ]
    text = out.getvalue()
    first, second = text.split(f"\x1b[{n}F")
    assert first.count("\x1b[2K") == n and second.count("\x1b[2K") == n
    # an event is printed above the block, which then starts afresh below it
    con.message("ECU lost: no status for 0.6 s")
    assert out.getvalue().endswith(f"\x1b[{n}F\x1b[JECU lost: no status for 0.6 s\n")
    con.update(WORKING, 0.6)
    assert out.getvalue().split("ECU lost: no status for 0.6 s\n")[1].startswith("\x1b[2K")
