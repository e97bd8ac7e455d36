"""The live console: an ANSI block redrawn in place on a TTY, one line per second otherwise."""

from __future__ import annotations

import io
import unicodedata
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import pytest

from topdress.display.console import Console, fault_names, render_line, render_lines, width
from topdress.i18n import set_language, text, tr
from topdress.protocol import Fault
from topdress.view.commands import ManualView
from topdress.view.snapshot import AlarmView, CalibrationView, LagView, Snapshot

WORKING = Snapshot(
    t_s=12.3,
    running=True,
    source="gnss",
    v_kmh=8.02,
    v_wheel_kmh=7.61,
    v_gnss_kmh=8.0,
    gnss_kmh=8.0,
    cv_pct=2.51,
    uniform=True,
    ndvi_sensors=0.612,
    ndvi=0.587,
    rate_kg_ha=(138.9, 138.9),
    target_rpm=(22.09, 22.09),
    meter_rpm=(22.69, 22.5),
    fan_rpm=(3020.0, 3000.0),
    faults=int(Fault.UPPER_FAN_LOW | Fault.GNSS_LOST),
    ecu_live=True,
    ecu_link="ok",
    gnss_link="ok",
    crop_link="3/4",
    counters={"nmea": 120, "nmea_bad": 2},
    last_event=text("event.gnss", state=text("link.ok")),
)


@pytest.fixture(autouse=True)
def english() -> Iterator[None]:
    set_language("en")
    yield
    set_language("en")


def columns(line: str) -> int:
    """Terminal columns, counted here independently of the console's own helper."""
    return sum(2 if unicodedata.east_asian_width(c) in "WF" else 1 for c in line)


def test_fault_names_follow_the_fault_word() -> None:
    assert fault_names(0) == []
    assert fault_names(int(Fault.CMD_TIMEOUT | Fault.NO_SPEED)) == ["CMD_TIMEOUT", "NO_SPEED"]
    assert fault_names(1 << 9) == ["BIT9"]
    # the console's names are the protocol's
    assert [fault_names(int(f)) for f in Fault] == [[f.name] for f in Fault]


def test_status_block_shows_every_figure() -> None:
    text = "\n".join(render_lines(WORKING))
    for part in (
        "8.02 km/h from GNSS",
        "wheel  7.61",
        "GNSS  8.00 km/h",
        "CV 2.51 % (uniform)",
        "sensors 0.612  at meters 0.587",
        "rate upper  138.9  lower  138.9 kg/ha",
        "target  22.09 /  22.09 r/min",
        "actual  22.69 /  22.50 r/min",
        "3020 /  3000 rpm",
        "faults:  GNSS speed lost  upper fan too slow",
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


def test_ecu_values_are_dashes_while_the_ecu_is_lost() -> None:
    # the last frames of a lost ECU (WORKING's) must not pass for live values
    lost = replace(WORKING, ecu_live=False, ecu_link="lost")
    block = "\n".join(render_lines(lost))
    for stale in ("8.02", "7.61", "2.51", "uniform", "22.09", "22.69", "3020", "RUNNING"):
        assert stale not in block, stale
    assert "GNSS_LOST" not in block and "faults:  --" in block
    assert "speed      -- km/h from --    wheel    --" in block
    assert "target     -- /     -- r/min   actual     -- /     -- r/min" in block
    # the columns stay put: the figures where they were
    assert render_lines(lost)[1].index("CV") == render_lines(WORKING)[1].index("CV")
    assert len(render_lines(lost)[3]) == len(render_lines(WORKING)[3])
    # what the terminal knows by itself stays: GNSS speed read, NDVI, rates computed
    for own in ("GNSS  8.00 km/h", "sensors 0.612", "at meters 0.587", "upper  138.9"):
        assert own in block, own
    line = render_line(lost)
    assert line == (
        "t=12.3s v=--km/h src=-- cv=--% ndvi=0.587 rate=138.9/138.9kg/ha target=--/-- "
        "meter=--/--r/min fan=--/--rpm faults=-- ecu=lost gnss=ok crop=3/4"
        " op=stopped rate=off alarms=0 lag=--"
    )


def test_ecu_wait_says_where_the_terminal_listens() -> None:
    waiting = replace(Snapshot(), ecu_where="socketcan:can0")
    assert "ECU waiting (socketcan:can0)" in render_lines(waiting)[0]
    assert " ecu=wait(socketcan:can0) " in render_line(waiting)
    # once it works the place is not repeated
    assert " ecu=ok " in render_line(replace(WORKING, ecu_where="socketcan:can0"))


def test_the_block_fits_80_columns_and_shows_the_operator_state() -> None:
    lines = render_lines(BUSY)
    assert max(columns(x) for x in lines) <= 80
    text = "\n".join(lines)
    assert "operator RUNNING           rate MANUAL 200.0 / 100.0 kg/ha" in text
    # waiting for the ECU with a long bus name, the first line packs so the run state shows
    assert lines[0].endswith("  ECU waiting (socketcan:can0)  GNSS ok  CROP 3/4 fresh  RUNNING")
    assert "source  GNSS: CV 2.51 % < 4.2 %, GNSS 8.0 km/h > 6 km/h" in text
    assert "alarms  lower meter blocked  upper meter off rate (acknowledged)" in text
    assert "crop sensors lost: no NDVI (gone, not acknowledged)" in text
    assert "calib   Metering catch test weigh and enter kg 100 %: upper meter: 20.012" in text
    # every fault and every counter is shown, on as many lines as it takes
    for name in fault_names(0x1FF):
        assert tr(f"fault.{name}") in text, name
    for i in range(12):
        assert f"counter_{i} {i * 1000}" in text


BUSY = replace(
    WORKING,
    ecu_link="wait",
    ecu_where="socketcan:can0",
    faults=0x1FF,
    operator="running",
    manual=ManualView("fixed", 200.0, 100.0),
    speed_why=text(
        "why.gnss",
        cv=text("why.cv", cv=2.51),
        threshold=4.2,
        compare=text("source.gnss"),
        kmh=8.0,
        switch_kmh=6.0,
    ),
    alarms=(
        AlarmView("blocked_lower", text("alarm.text.blocked_lower"), "active", 3.0),
        AlarmView("off_rate_upper", text("alarm.text.off_rate_upper"), "acked", 2.0),
        AlarmView("crop_lost", text("alarm.text.crop_lost", state="lost"), "cleared", 1.0),
    ),
    calibration=CalibrationView(
        "catch", "weigh", text("cal.text.catch_weigh", layer=text("main.upper"), rev=20.012), 1.0
    ),
    counters={f"counter_{i}": i * 1000 for i in range(12)},
    last_event=text(
        "event.gnss_lost", why="serial:/dev/ttyUSB0: [Errno 2] could not open port " + "x" * 80
    ),
)


def test_the_block_follows_the_language_and_fits_80_columns_in_chinese() -> None:
    lost = replace(BUSY, ecu_live=False, ecu_link="lost", operator="stopped", manual=ManualView())
    set_language("zh")
    for snap in (WORKING, BUSY, lost, Snapshot()):
        lines = render_lines(snap)
        assert max(columns(x) for x in lines) <= 80, lines
        assert [width(x) for x in lines] == [columns(x) for x in lines]
    text = "\n".join(render_lines(BUSY))
    for key in ("con.speed", "con.operator", "con.alarms", "count.field", "count.season"):
        assert tr(key) in text, key
    assert f"{tr('link_name.ecu')} {tr('link.wait')} (socketcan:can0)" in text
    assert tr("op.state.running") == "作业中" and tr("op.state.running") in text
    assert tr("alarm.blocked_lower") in text and tr("alarm.state.acked") in text
    assert tr("manual.shown_fixed", upper="200.0", lower="100.0", unit="kg/ha") in text
    assert tr("cal.catch") in text and tr("cal.step.weigh") in text
    # the terminal's own messages in the language: why the source, the wizard, the last event
    assert "GNSS：变异系数 2.51 % < 4.2 %，GNSS 8.0 km/h > 6 km/h" in text
    assert "上层排肥器：已转" in text
    assert "GNSS 丢失（serial:/dev/ttyUSB0" in text
    working = "\n".join(render_lines(WORKING))
    assert f"来自 {tr('source.gnss')}" in working and f"{tr('con.crop')} 3/4 有效" in working
    assert tr("fault.GNSS_LOST") in working and tr("fault.UPPER_FAN_LOW") in working
    assert "GNSS speed lost" not in working and "RUNNING" not in working
    # the ECU stopped: the catalogue's word for it
    stopped = "\n".join(render_lines(replace(WORKING, running=False)))
    assert tr("op.state.stopped") == "已停止" and "已停止" in stopped
    assert "alarms" not in working and tr("alarm.none") == "无报警" and "无报警" in working
    # the compact line for logs stays English
    assert render_line(WORKING).startswith("t=12.3s v=8.02km/h src=gnss cv=2.51%")


def test_switching_back_to_english_at_the_next_redraw() -> None:
    out = io.StringIO()
    con = Console(out, tty=True, period_s=0.3)
    set_language("zh")
    con.update(WORKING, 0.0)
    set_language("en")
    con.update(WORKING, 0.3)
    first, second = out.getvalue().split(f"\x1b[{len(render_lines(WORKING))}F")
    assert "作业中" in first and "速度" in first
    assert "RUNNING" not in first
    assert "RUNNING" in second and "speed" in second and "作业中" not in second
    assert not any("\u4e00" <= c <= "\u9fff" for c in second)


def test_long_chinese_text_is_cut_by_columns() -> None:
    set_language("zh")
    long_event = replace(WORKING, last_event="控制器丢失" * 30)
    last = render_lines(long_event)[-1]
    assert last.endswith("...") and columns(last) in (79, 80)


def test_the_configured_language_applies_at_start_without_the_display(tmp_path: Path) -> None:
    from topdress.cli.main import main
    from topdress.i18n import language

    cfg = tmp_path / "t.toml"
    # a CAN interface that does not exist: the run stops right after the language is applied
    cfg.write_text(
        f'[log]\ndir = "{tmp_path}"\n[display]\nlanguage = "zh"\n'
        '[can]\ninterface = "no_such_interface"\n'
    )
    assert main(["run", "--config", str(cfg), "--no-display", "--duration", "1"]) == 2
    assert language() == "zh"
    assert "已停止" in "\n".join(render_lines(Snapshot()))


def test_the_gnss_lag_follows_the_speed_source_in_both_languages() -> None:
    learned = replace(WORKING, gnss_lag=LagView(950, 950, "learned"))
    lines = render_lines(learned)
    source = next(x for x in lines if x.startswith("source"))
    assert source.endswith("  GNSS lag 0.95 s (learned)")
    assert render_line(learned).endswith(" lag=0.95s/learned")
    # a fixed lag the data contradict says both; too long beside a long reason: a line of its own
    overruled = replace(BUSY, gnss_lag=LagView(500, 500, "overruled", fixed_ms=1800.0))
    lines = render_lines(overruled)
    i = next(i for i, x in enumerate(lines) if x.startswith("source"))
    assert lines[i + 1] == "        GNSS lag 0.50 s (learned, not the set 1.80 s)"
    assert max(columns(x) for x in lines) <= 80
    set_language("zh")
    text_zh = "\n".join(render_lines(learned))
    assert "GNSS 滞后 0.95 秒（已学习）" in text_zh
    assert max(columns(x) for x in render_lines(overruled)) <= 80
    set_language("en")
    # the start value while learning, a fixed lag; nothing while the ECU is not heard
    start = replace(WORKING, gnss_lag=LagView(1300, None, "start"))
    assert "GNSS lag 1.30 s (learning)" in "\n".join(render_lines(start))
    fixed = replace(WORKING, gnss_lag=LagView(1300, 1250, "fixed", 1300.0))
    assert render_line(fixed).endswith(" lag=1.30s/fixed")
    lost = replace(learned, ecu_live=False)
    assert "GNSS lag" not in "\n".join(render_lines(lost))
    assert render_line(lost).endswith(" lag=--")
