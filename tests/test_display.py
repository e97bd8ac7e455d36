"""The operator display's screen logic, in NiceGUI's simulated browser (the `user` fixture)."""

from __future__ import annotations

import asyncio
import contextlib
import math
import sys
from collections.abc import Callable, Iterator
from concurrent.futures import Future
from dataclasses import replace
from itertools import pairwise

import pytest
from nicegui import Client, ui
from nicegui.testing import User

from topdress import i18n
from topdress.config import TerminalConfig, default_config, loads_config
from topdress.display import pages
from topdress.display.charts import meter_options, speed_options
from topdress.display.hub import DisplayHub, bearing_deg, distance_m
from topdress.display.map_view import machine_arrow, rate_colour, swath_quad
from topdress.display.options import DisplayError, DisplayOptions, check_security, is_loopback
from topdress.display.pages import register_pages
from topdress.i18n import text
from topdress.view import commands as op
from topdress.view.commands import CommandResult, ManualView
from topdress.view.snapshot import (
    AlarmView,
    CalibrationView,
    ControlFunctionView,
    CounterView,
    DeviceLine,
    IsobusView,
    LagView,
    ProductView,
    Snapshot,
)

LAT0, LON0 = 43.8853, 125.3245


def working(t_s: float = 12.0, **kw: object) -> Snapshot:
    """The demo at 8 km/h on GNSS in uniform motion."""
    base: dict[str, object] = dict(
        t_s=t_s,
        running=True,
        source="gnss",
        v_kmh=8.0,
        v_wheel_kmh=7.61,
        v_gnss_kmh=8.0,
        gnss_kmh=8.0,
        cv_pct=2.51,
        uniform=True,
        ndvi_sensors=0.612,
        ndvi=0.587,
        rate_kg_ha=(138.9, 138.9),
        target_rpm=(22.09, 22.09),
        meter_rpm=(22.69, 22.59),
        fan_rpm=(3020.0, 3020.0),
        faults=0,
        ecu_live=True,
        ecu_link="ok",
        gnss_link="ok",
        crop_link="ok",
        lat=LAT0,
        lon=LON0,
        operator="running",
        rate_model_kg_ha=(138.9, 138.9),
        applied_kg_ha=(141.9, 141.2),
        ndvi_per_sensor=(0.605, 0.621, None, 0.610),
        speed_why=text(
            "why.gnss",
            cv=text("why.cv", cv=2.51),
            threshold=4.2,
            compare=text("source.gnss"),
            kmh=8.0,
            switch_kmh=6.0,
        ),
    )
    base.update(kw)
    return Snapshot(**base)  # type: ignore[arg-type]


@pytest.fixture(autouse=True)
def keep_modules() -> Iterator[None]:
    """NiceGUI's simulated browser, resetting itself, drops the modules that defined pages (and
    their parents: `topdress`) from sys.modules; later tests would import a second copy of the
    package beside the first. Put the first back."""
    saved = {k: v for k, v in sys.modules.items() if k.split(".")[0] == "topdress"}
    yield
    # Modules first imported during the test belong to the dropped copy (their parents do not
    # know them): dropped too, so that the next import binds them to the first copy.
    for name in [k for k in sys.modules if k.split(".")[0] == "topdress" and k not in saved]:
        del sys.modules[name]
    sys.modules.update(saved)


@pytest.fixture(autouse=True)
def english() -> Iterator[None]:
    i18n.set_language("en")
    yield
    i18n.set_language("en")


def text_of(user: User, marker: str) -> str:
    (element,) = user.find(marker=marker).elements
    return str(element.text)  # type: ignore[attr-defined]


def panel(user: User, name: str) -> None:
    """One touch on the main screen's panel row (map, charts, crop, counters, manual)."""
    (toggle,) = user.find(marker="panels").elements
    toggle.value = name  # type: ignore[attr-defined]


async def shows(user: User, marker: str, expected: str, timeout_s: float = 3.0) -> None:
    """Wait until the page's timer has drawn `expected` at `marker` (virtual clocks aside,
    the page pulls the snapshot every 0.2 s)."""
    for _ in range(round(timeout_s / 0.05)):
        with contextlib.suppress(AssertionError):  # not drawn yet
            if text_of(user, marker) == expected:
                return
        await asyncio.sleep(0.05)
    assert text_of(user, marker) == expected


async def test_main_screen_shows_the_snapshot(user: User) -> None:
    hub = DisplayHub(default_config)
    hub.publish(working())
    register_pages(hub)
    await user.open("/")
    assert text_of(user, "v_selected") == "8.0"
    assert text_of(user, "v_wheel") == "7.6"
    assert text_of(user, "v_gnss") == "8.0"
    assert text_of(user, "source") == "GNSS"
    assert text_of(user, "source_why") == "GNSS: CV 2.51 % < 4.2 %, GNSS 8.0 km/h > 6 km/h"
    assert text_of(user, "op_state") == "RUNNING"
    assert text_of(user, "manual_state") == ""
    assert text_of(user, "rate_upper") == "138.9"
    assert text_of(user, "applied_lower") == "141.2"
    panel(user, "crop")
    assert text_of(user, "ndvi_sensors") == "0.612"
    assert text_of(user, "ndvi_meters") == "0.587"
    assert text_of(user, "ndvi_per_sensor") == "1: 0.605  2: 0.621  3: --  4: 0.610"
    assert text_of(user, "target_lower") == "22.1"
    assert text_of(user, "meter_upper") == "22.7"
    assert text_of(user, "fan_lower") == "3020"
    assert text_of(user, "faults") == "none"
    assert text_of(user, "link_ecu") == "ECU: ok"
    await user.should_see("km/h")
    await user.should_see("kg/ha")


async def test_main_screen_follows_new_snapshots(user: User) -> None:
    hub = DisplayHub(default_config)
    why = text(
        "why.not_uniform",
        cv=text("why.cv", cv=9.5),
        threshold=4.2,
        compare=text("source.gnss"),
        speed=3.0,
        switch=6.0,
    )
    hub.publish(working(v_kmh=3.0, source="wheel", speed_why=why))
    register_pages(hub)
    await user.open("/")
    assert text_of(user, "source") == "wheel"
    assert text_of(user, "source_why") == "wheel: CV 9.50 % ≥ 4.2 % (not uniform)"
    hub.publish(working(t_s=12.1, v_kmh=6.5))
    await shows(user, "v_selected", "6.5")
    assert text_of(user, "source") == "GNSS"


async def test_ecu_values_are_dashes_while_the_ecu_is_not_heard(user: User) -> None:
    hub = DisplayHub(default_config)
    hub.publish(working(ecu_live=False, ecu_link="lost", gnss_link="ok"))
    register_pages(hub)
    await user.open("/")
    panel(user, "crop")
    for marker in (
        "v_selected",
        "v_wheel",
        "target_upper",
        "meter_lower",
        "applied_upper",
        "fan_upper",
        "faults",
    ):
        assert text_of(user, marker) == "--", marker
    # What the terminal knows by itself stays: the GNSS speed, the NDVI, the rate it commands.
    assert text_of(user, "v_gnss") == "8.0"
    assert text_of(user, "rate_upper") == "138.9"
    assert text_of(user, "link_ecu") == "ECU: lost"


async def test_faults_in_plain_words_and_waiting_ecu_named(user: User) -> None:
    hub = DisplayHub(default_config)
    # bits 1 (GNSS_LOST) and 3 (UPPER_BLOCKED), and an undefined bit 12
    hub.publish(working(faults=(1 << 1) | (1 << 3) | (1 << 12)))
    register_pages(hub)
    await user.open("/")
    panel(user, "crop")
    assert text_of(user, "faults") == "GNSS speed lost; upper meter blocked; BIT12"
    hub.publish(working(ecu_live=False, ecu_link="wait", ecu_where="socketcan:can0"))
    await user.open("/")
    panel(user, "crop")
    assert text_of(user, "link_ecu") == "ECU: waiting (socketcan:can0)"


async def test_language_switches_at_run_time(user: User) -> None:
    hub = DisplayHub(default_config)
    hub.publish(working(faults=1 << 3, last_event=text("event.ecu_lost", s=1.0)))
    register_pages(hub)
    await user.open("/")
    await user.should_see("applied")
    panel(user, "crop")
    assert text_of(user, "last_event") == "ECU lost: no status for 1.0 s"
    user.find(marker="language").click()
    user.find("简体中文").click()
    assert i18n.language() == "zh"
    await user.should_see("实际施肥量", retries=20)
    await user.should_not_see("applied")
    panel(user, "crop")  # the content is built anew in the language
    await shows(user, "faults", "上层排肥器堵转")
    assert text_of(user, "source") == "GNSS"
    # the terminal's messages too: why this source, the last event
    assert text_of(user, "source_why") == "GNSS：变异系数 2.51 % < 4.2 %，GNSS 8.0 km/h > 6 km/h"
    assert text_of(user, "last_event") == "控制器丢失：1.0 秒无状态帧"
    await user.should_see("km/h")  # units shown in both languages


def test_speed_chart_marks_the_source_spans() -> None:
    hist = [working(t_s=t / 10, source="wheel" if t < 30 else "gnss") for t in range(50)]
    opts = speed_options(hist)
    selected = opts["series"][2]
    assert [p[1] for p in selected["data"][:2]] == [8.0, 8.0]
    bands = selected["markArea"]["data"]
    # charted at 2.5 Hz, ending with the latest snapshot: t 0.1, 0.5, ... 4.9
    assert [(b[0]["name"], b[0]["xAxis"], b[1]["xAxis"]) for b in bands] == [
        ("wheel", 0.1, 2.9),
        ("GNSS", 3.3, 4.9),
    ]
    assert opts["xAxis"]["min"] == 0.1 and opts["xAxis"]["max"] == 4.9


def test_charts_leave_gaps_while_the_ecu_is_not_heard() -> None:
    hist = [working(t_s=1.0 + i / 10, ecu_live=i not in range(3, 7)) for i in range(9)]
    sel = speed_options(hist)["series"][2]["data"]
    assert [p[1] for p in sel] == [8.0, None, 8.0]  # t 1.0, 1.4, 1.8
    meter = meter_options(hist)["series"][2]["data"]
    assert [p[1] for p in meter] == [22.69, None, 22.69]


def test_chart_window_is_the_last_minute() -> None:
    hub = DisplayHub(default_config, history_s=60.0)
    for i in range(700):
        hub.publish(working(t_s=i / 10))
    hist = hub.history()
    assert len(hist) == 600
    assert hist[0].t_s == pytest.approx(10.0) and hist[-1].t_s == pytest.approx(69.9)
    opts = speed_options(hist)
    assert opts["xAxis"]["min"] == pytest.approx(10.3)  # the first charted of the last minute
    assert len(opts["series"][0]["data"]) == 150


def test_track_points_every_metre_with_heading() -> None:
    hub = DisplayHub(default_config)
    # North at 2.22 m/s (8 km/h), 10 Hz: a point every metre, not every tick.
    for i in range(50):
        north = 0.222 * i
        hub.publish(working(t_s=i / 10, lat=LAT0 + math.degrees(north / 6_371_000.0)))
    total, points = hub.track_since(0)
    # 0.222 m a tick: the first tick at or beyond 1 m from the last point is every 5th (1.11 m)
    assert total == len(points) == 10
    assert distance_m(points[0].lat, 0, points[-1].lat, 0) == pytest.approx(9.99, abs=1e-3)
    assert all(p.heading_deg == pytest.approx(0.0, abs=1e-6) for p in points[1:])
    assert points[1].rate_kg_ha == pytest.approx(283.1)  # applied, both layers
    again, none = hub.track_since(total)
    assert again == total and none == []


def test_track_heading_is_the_receivers_course_when_it_has_one() -> None:
    hub = DisplayHub(default_config)
    # North along the track, but each fix 0.3 m off sideways (alternating): the bearing between
    # points swings by about 31 degrees, the course over ground does not.
    for i in range(30):
        north = 0.222 * i
        east = 0.3 if (i // 5) % 2 else -0.3
        hub.publish(
            working(
                t_s=i / 10,
                lat=LAT0 + math.degrees(north / 6_371_000.0),
                lon=LON0 + math.degrees(east / (6_371_000.0 * math.cos(math.radians(LAT0)))),
                heading_deg=2.0,
            )
        )
    _, points = hub.track_since(0)
    assert len(points) == 6
    assert [p.heading_deg for p in points] == [2.0] * 6
    swing = [bearing_deg(a.lat, a.lon, b.lat, b.lon) for a, b in pairwise(points)]
    assert max(abs((b + 180.0) % 360.0 - 180.0) for b in swing) > 25.0


def test_track_heading_falls_back_to_the_bearing_without_a_course() -> None:
    hub = DisplayHub(default_config)
    for i in range(20):
        east = 0.222 * i  # due east, no course in the snapshot
        lon = LON0 + math.degrees(east / (6_371_000.0 * math.cos(math.radians(LAT0))))
        hub.publish(working(t_s=i / 10, lon=lon, heading_deg=None))
    _, points = hub.track_since(0)
    assert points[0].heading_deg == 0.0  # nothing to take a bearing from yet
    assert all(p.heading_deg == pytest.approx(90.0, abs=1e-3) for p in points[1:])


def test_track_of_a_stopped_machine_is_not_metered() -> None:
    hub = DisplayHub(default_config)
    hub.publish(working(meter_rpm=(0.0, 0.0), running=False))
    (p,) = hub.track_since(0)[1]
    assert not p.metering and p.rate_kg_ha == 0.0


def test_swath_is_the_working_width_across_the_heading() -> None:
    hub = DisplayHub(default_config)
    for lat in (LAT0, LAT0 + math.degrees(2.0 / 6_371_000.0)):
        hub.publish(working(lat=lat))
    a, b = hub.track_since(0)[1]
    quad = swath_quad(a, b, 3.6)
    left, right = quad[0], quad[1]
    assert distance_m(*left, *right) == pytest.approx(3.6, rel=1e-6)
    assert bearing_deg(*left, *right) == pytest.approx(90.0)  # heading north: right is east
    assert distance_m(*quad[1], *quad[2]) == pytest.approx(2.0, rel=1e-3)
    tip, back_r, back_l = machine_arrow(LAT0, LON0, 90.0, 3.0)
    assert tip == (LAT0, LON0)
    mid = ((back_r[0] + back_l[0]) / 2, (back_r[1] + back_l[1]) / 2)
    assert bearing_deg(*mid, *tip) == pytest.approx(90.0)  # points east, as headed
    assert distance_m(*mid, *tip) == pytest.approx(3.0, rel=1e-6)
    assert bearing_deg(*back_l, *back_r) == pytest.approx(180.0)  # right of east is south


def test_rate_colour_scale() -> None:
    assert rate_colour(0.0, 600.0) == "#bdbdbd"
    assert rate_colour(1.0, 600.0) == "hsl(240, 80%, 45%)"
    assert rate_colour(300.0, 600.0) == "hsl(120, 80%, 45%)"
    assert rate_colour(900.0, 600.0) == "hsl(0, 80%, 45%)"


@pytest.mark.parametrize(
    ("host", "loopback"),
    [
        ("127.0.0.1", True),
        ("127.0.0.2", True),
        ("localhost", True),
        ("::1", True),
        ("0.0.0.0", False),
        ("192.168.1.20", False),
        ("cab-pc", False),
    ],
)
def test_loopback_addresses(host: str, loopback: bool) -> None:
    assert is_loopback(host) is loopback


def test_any_other_address_needs_a_pin() -> None:
    check_security(DisplayOptions("127.0.0.1", 8080, ""))
    check_security(DisplayOptions("0.0.0.0", 8080, "4711"))
    with pytest.raises(DisplayError, match=r"display\.pin"):
        check_security(DisplayOptions("0.0.0.0", 8080, ""))
    assert DisplayOptions("::1", 8081).url == "http://[::1]:8081"


# ---- commands -------------------------------------------------------------------------------
class Terminal:
    """The terminal's command path as the display sees it: `post` answers at once."""

    def __init__(self, answer: Callable[[object], CommandResult] | None = None) -> None:
        self.sent: list[object] = []
        self.answer = answer or (lambda c: CommandResult(True, f"{type(c).__name__} done"))

    def post(self, command: object) -> Future[CommandResult]:
        self.sent.append(command)
        fut: Future[CommandResult] = Future()
        fut.set_result(self.answer(command))
        return fut


async def settle(user: User, term: Terminal, count: int) -> None:
    for _ in range(40):
        if len(term.sent) >= count:
            return
        await asyncio.sleep(0.05)
    assert len(term.sent) >= count, term.sent


def pinned() -> TerminalConfig:
    return loads_config('[display]\nhost = "0.0.0.0"\npin = "4711"\n')


async def test_start_stop_pause_go_to_the_terminal(user: User) -> None:
    term = Terminal()
    hub = DisplayHub(default_config, term.post)
    hub.publish(working(operator="stopped"))
    register_pages(hub)
    await user.open("/")
    assert text_of(user, "op_state") == "STOPPED"
    user.find(marker="start").click()
    user.find(marker="pause").click()
    user.find(marker="stop").click()
    await settle(user, term, 3)
    assert term.sent == [op.Start(), op.Pause(), op.Stop()]


async def test_manual_rate_is_sent_and_shown_as_such(user: User) -> None:
    term = Terminal()
    hub = DisplayHub(default_config, term.post)
    hub.publish(working())
    register_pages(hub)
    await user.open("/")
    panel(user, "manual")
    user.find(marker="manual_mode").click()  # the radio: pick "fixed"
    (radio,) = user.find(marker="manual_mode").elements
    radio.value = "fixed"  # type: ignore[attr-defined]
    for marker, value in (("manual_upper", 120.0), ("manual_lower", 80.0)):
        (field,) = user.find(marker=marker).elements
        field.value = value  # type: ignore[attr-defined]
    user.find(marker="manual_apply").click()
    await settle(user, term, 1)
    assert term.sent == [op.SetManual("fixed", 120.0, 80.0, 0.0)]
    hub.publish(working(t_s=13.0, manual=ManualView("fixed", 120.0, 80.0)))
    await shows(user, "manual_state", "MANUAL 120.0 / 80.0 kg/ha")
    hub.publish(working(t_s=13.1, manual=ManualView("percent", percent=-20.0)))
    await shows(user, "manual_state", "MANUAL -20 % of plan")


async def test_alarms_show_as_a_banner_on_every_screen_and_are_acknowledged(user: User) -> None:
    term = Terminal()
    hub = DisplayHub(default_config, term.post)
    alarms = (
        AlarmView("gnss_lost", text("alarm.gnss_lost"), "acked", 1.0),
        AlarmView("blocked_upper", text("alarm.text.blocked_upper"), "active", 3.0),
    )
    hub.publish(working(alarms=alarms))
    register_pages(hub)
    for path in ("/", "/communication", "/control", "/calibration"):
        await user.open(path)
        # the unacknowledged one first, whatever came before it
        assert text_of(user, "alarm_banner") == (
            "upper meter blocked (stopped by the ECU) · active (+1 more)"
        ), path
    user.find(marker="banner_ack").click()
    await settle(user, term, 1)
    assert term.sent == [op.AckAlarm("blocked_upper")]
    hub.publish(working(t_s=12.1, alarms=(alarms[0],)))
    await shows(user, "alarm_banner", "GNSS lost: metering on the ground wheel · acknowledged")
    await user.should_not_see(marker="banner_ack")  # acknowledged already
    await user.open("/")
    panel(user, "crop")
    user.find(marker="ack_all").click()
    await settle(user, term, 2)
    assert term.sent[1] == op.AckAlarm(None)
    hub.publish(working(t_s=13.0, alarms=()))
    await shows(user, "alarm_banner", "no alarm")


async def test_counters_reset_only_once_confirmed_and_can_be_undone(user: User) -> None:
    term = Terminal()
    hub = DisplayHub(default_config, term.post)
    field = CounterView(area_ha=1.2345, kg=(170.2, 168.9), work_s=3725.0, distance_m=3429.0)
    hub.publish(working(count_field=field, count_season=CounterView(area_ha=12.5)))
    register_pages(hub)
    await user.open("/")
    panel(user, "counters")
    assert text_of(user, "count_field_area") == "1.234 ha"  # 1.2345 rounds half to even
    assert text_of(user, "count_field_kg_upper") == "170.2 kg"
    assert text_of(user, "count_field_time") == "1:02:05"
    assert text_of(user, "count_field_distance") == "3429 m"
    assert text_of(user, "count_season_area") == "12.500 ha"
    await user.should_not_see(marker="undo_field")
    # one tap only asks, naming what would go
    user.find(marker="reset_field").click()
    await user.should_see(marker="reset_ask")
    assert text_of(user, "reset_ask").startswith("Reset the field counter? 1.23 ha and 339 kg")
    user.find(marker="reset_no").click()
    await asyncio.sleep(0.2)
    assert term.sent == []
    user.find(marker="reset_season").click()
    await user.should_see(marker="reset_ask")
    user.find(marker="reset_yes").click()
    await settle(user, term, 1)
    assert term.sent == [op.ResetCounter("season")]
    # the terminal offers the undo while it runs
    hub.publish(working(t_s=12.1, count_field=field, count_undo=("season",)))
    await user.should_see(marker="undo_season", retries=20)
    await user.should_not_see(marker="undo_field")
    user.find(marker="undo_season").click()
    await settle(user, term, 2)
    assert term.sent[1] == op.UndoReset("season")


async def test_a_remote_browser_needs_the_pin_to_operate(
    user: User, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(pages, "client_is_remote", lambda: True)
    term = Terminal()
    hub = DisplayHub(pinned, term.post)
    hub.publish(working(operator="stopped"))
    register_pages(hub)
    await user.open("/")
    assert text_of(user, "v_selected") == "8.0"  # viewing needs no PIN
    user.find(marker="start").click()
    await user.should_see(marker="pin")
    user.find(marker="pin").type("1234")
    user.find(marker="pin_ok").click()
    await user.should_see("wrong PIN")
    assert term.sent == []
    user.find(marker="pin").type("4711")
    user.find(marker="pin_ok").click()
    await settle(user, term, 1)
    assert term.sent == [op.Start()]
    user.find(marker="stop").click()  # once per tab
    await settle(user, term, 2)
    assert term.sent == [op.Start(), op.Stop()]


async def test_the_cab_screen_itself_needs_no_pin(user: User) -> None:
    term = Terminal()
    hub = DisplayHub(pinned, term.post)
    hub.publish(working(operator="running"))
    register_pages(hub)
    await user.open("/")  # the simulated browser is on 127.0.0.1, as the cab PC's is
    user.find(marker="stop").click()
    await settle(user, term, 1)
    assert term.sent == [op.Stop()]
    await user.should_not_see(marker="pin")


async def test_a_refused_value_is_shown_at_its_field_and_not_sent(user: User) -> None:
    term = Terminal()
    hub = DisplayHub(default_config, term.post)
    hub.publish(working())
    register_pages(hub)
    await user.open("/control")
    (split,) = user.find(marker="field_rate.split_upper").elements
    split.value = 1.5  # type: ignore[attr-defined]
    user.find(marker="apply_rate").click()
    await shows(user, "answer_rate", "refused: see the field marked")
    assert split.props["error"] is True
    assert "1" in str(split.props["error-message"])  # the configuration's own reason
    assert term.sent == []


async def test_a_pid_gain_goes_to_the_ecu_and_its_answer_is_shown(user: User) -> None:
    def answer(c: object) -> CommandResult:
        assert isinstance(c, op.ApplySettings)
        if c.values.get("pid_kp") == 9.0:
            return CommandResult(False, "refused", {"ecu.pid_kp": "ECU: out of range"})
        return CommandResult(True, "settings [ecu] applied, saved to demo-config.toml")

    term = Terminal(answer)
    hub = DisplayHub(default_config, term.post)
    hub.publish(working(operator="stopped"))
    register_pages(hub)
    await user.open("/control")
    (kp,) = user.find(marker="field_ecu.pid_kp").elements
    kp.value = 0.02  # type: ignore[attr-defined]
    user.find(marker="apply_ecu").click()
    await settle(user, term, 1)
    (sent,) = term.sent
    assert isinstance(sent, op.ApplySettings)
    assert (sent.section, sent.values) == ("ecu", {"pid_kp": 0.02})  # the changed gain only
    await shows(user, "answer_ecu", "settings [ecu] applied, saved to demo-config.toml")
    kp.value = 9.0  # type: ignore[attr-defined]
    user.find(marker="apply_ecu").click()
    await settle(user, term, 2)
    await shows(user, "answer_ecu", "refused")
    assert kp.props["error-message"] == "ECU: out of range"
    hub.publish(working(t_s=13.0, settings_pending=True))
    await shows(user, "pending", "waiting for the ECU's acknowledgement …")


async def test_rate_curve_follows_the_model_typed(user: User) -> None:
    hub = DisplayHub(default_config)
    hub.publish(working(ndvi=0.55, rate_model_kg_ha=(150.0, 150.0)))
    register_pages(hub)
    await user.open("/control")
    (chart,) = user.find(kind=ui.echart).elements
    line = chart.options["series"][0]["data"]
    assert line[0] == [0.0, 600.0] and line[-1] == [1.0, 30.0]  # 450 at 0.3, 150 at 0.8
    (r1,) = user.find(marker="field_rate.linear.rate_1_kg_ha").elements
    r1.value = 250.0  # type: ignore[attr-defined]
    line = chart.options["series"][0]["data"]
    assert [p for p in line if p[0] == 0.8] == [[0.8, 250.0]]
    await shows(user, "operating_point", "operating point: NDVI 0.550 → 300.0 kg/ha")


async def test_catch_test_wizard(user: User) -> None:
    term = Terminal()
    hub = DisplayHub(default_config, term.post)
    hub.publish(working(operator="stopped"))
    register_pages(hub)
    await user.open("/calibration")
    assert text_of(user, "cal_state") == "no calibration running"
    user.find(marker="start_catch").click()
    await settle(user, term, 1)
    assert term.sent == [op.StartCatchTest("upper", 20.0, 20.0)]
    view = CalibrationView("catch", "weigh", "upper meter: 20.000 revolutions", 1.0)
    hub.publish(working(t_s=13.0, operator="calibrating", calibration=view))
    await shows(user, "cal_state", "Metering catch test · weigh and enter kg")
    (kg,) = user.find(marker="cal_kg").elements
    kg.value = 6.02  # type: ignore[attr-defined]
    user.find(marker="finish_catch").click()
    await settle(user, term, 2)
    assert term.sent[1] == op.FinishCatchTest(6.02)
    done = CalibrationView(
        "catch",
        "done",
        "upper: 0.3010 kg/rev",
        1.0,
        {"kg_per_rev": 0.301},
        "machine.kg_per_rev_upper",
    )
    hub.publish(working(t_s=13.1, operator="calibrating", calibration=done))
    await shows(user, "cal_result_kg_per_rev", "kg per revolution: 0.301")
    user.find(marker="cal_apply").click()
    await settle(user, term, 3)
    assert term.sent[2] == op.CloseCalibration(apply=True)


async def test_lookahead_wizard_presses_seen_and_applies_both_times(user: User) -> None:
    term = Terminal()
    hub = DisplayHub(default_config, term.post)
    hub.publish(working(operator="stopped"))
    register_pages(hub)
    await user.open("/calibration")
    user.find(marker="start_lead").click()
    await settle(user, term, 1)
    assert term.sent == [op.StartLeadCal("upper", 3)]
    view = CalibrationView("lead", "running", "trial 1 of 3", 0.0, {}, "lookahead")
    hub.publish(working(t_s=13.0, operator="calibrating", calibration=view))
    await shows(user, "cal_state", "Look-ahead: meter to outlet · running")
    user.find(marker="lead_seen").click()
    await settle(user, term, 2)
    assert term.sent[1] == op.LeadSeen()
    result = {"meter_ms": 60.0, "airline_ms": 200.0}
    done = CalibrationView("lead", "done", "meter 60 ms", 1.0, result, "lookahead")
    hub.publish(working(t_s=20.0, operator="calibrating", calibration=done))
    await shows(user, "cal_result_airline_ms", "air-line time ms: 200")
    user.find(marker="cal_apply").click()
    await settle(user, term, 3)
    assert term.sent[2] == op.CloseCalibration(apply=True)


async def test_device_test_shows_the_last_lines(user: User) -> None:
    lines = [DeviceLine(1.5, "$GNRMC,...*7A", "RMC 8.00 km/h")]
    term = Terminal(lambda c: CommandResult(True, "", data=lines))
    hub = DisplayHub(default_config, term.post)
    hub.publish(working())
    register_pages(hub)
    await user.open("/communication")
    await shows(user, "state_gnss", "state: ok")
    i18n.set_language("zh")  # the link's state in the language, as on the main screen
    await shows(user, "state_crop", "状态: 正常")
    i18n.set_language("en")
    user.find(marker="test_gnss").click()
    await settle(user, term, 1)
    assert term.sent == [op.TestDevice("gnss")]
    (table,) = user.find(marker="lines_gnss").elements
    for _ in range(20):
        if table.rows:  # type: ignore[attr-defined]
            break
        await asyncio.sleep(0.05)
    assert table.rows == [{"t": "1.5", "raw": "$GNRMC,...*7A", "decoded": "RMC 8.00 km/h"}]  # type: ignore[attr-defined]


async def test_communication_screen_names_the_ecu(user: User) -> None:
    term = Terminal(lambda c: CommandResult(True, ""))
    hub = DisplayHub(default_config, term.post)
    hub.publish(working())
    register_pages(hub)
    await user.open("/communication")
    await shows(user, "state_can", "state: ok")  # not identified yet: the state only
    ident = text("view.ecu_ident", target="stm32f4", firmware="0.1.0", protocol="1.1")
    hub.publish(working(ecu_ident=ident))
    await shows(user, "state_can", "state: ok · ECU: stm32f4 firmware 0.1.0, protocol 1.1")
    i18n.set_language("zh")
    await shows(user, "state_can", "状态: 正常 · 控制器：stm32f4 固件 0.1.0，协议 1.1")
    i18n.set_language("en")


def slcan_config() -> TerminalConfig:
    return loads_config(
        '[can]\ninterface = "slcan"\nchannel = "/dev/ttyACM0"\n'
        "[can.options]\ntty_baudrate = 115200\n"
    )


async def test_can_adapter_options_are_edited_as_name_value_lines(user: User) -> None:
    def answer(c: object) -> CommandResult:
        assert isinstance(c, op.ApplySettings)
        if c.values["options"].get("tty_baudrate") == 9600:  # the adapter did not open
            reason = "cannot open CAN interface 'slcan' channel '/dev/ttyACM0': no reply"
            return CommandResult(False, reason, {"can.options": reason})
        return CommandResult(True, "settings [can] applied")

    term = Terminal(answer)
    hub = DisplayHub(slcan_config, term.post)
    hub.publish(working(operator="stopped"))
    register_pages(hub)
    await user.open("/communication")
    (options,) = user.find(marker="field_can.options").elements
    assert options.value == "tty_baudrate = 115200\n"  # type: ignore[attr-defined]
    # not name = value lines: said at the field, nothing sent
    options.value = "tty_baudrate 115200"  # type: ignore[attr-defined]
    user.find(marker="apply_can").click()
    await shows(user, "answer_can", "refused: see the field marked")
    assert options.props["error"] is True and term.sent == []
    # a name the configuration refuses, named by its own check
    options.value = "bitrate = 250000"  # type: ignore[attr-defined]
    user.find(marker="apply_can").click()
    for _ in range(40):  # the click's handler runs as a task
        if options.props["error-message"] != "bitrate: is set by can.bitrate":
            await asyncio.sleep(0.05)
    assert options.props["error-message"] == "bitrate: is set by can.bitrate"
    assert term.sent == []
    # typed values (TOML): a number and a boolean; one line removed, one added
    options.value = "tty_baudrate = 921600\nrtscts = true\n"  # type: ignore[attr-defined]
    user.find(marker="apply_can").click()
    await settle(user, term, 1)
    (sent,) = term.sent
    assert isinstance(sent, op.ApplySettings) and sent.section == "can"
    assert sent.values["options"] == {"tty_baudrate": 921600, "rtscts": True}
    await shows(user, "answer_can", "settings [can] applied")
    assert not options.props.get("error")
    # the terminal could not reopen the adapter: its reason at the options, the old bus kept
    options.value = "tty_baudrate = 9600"  # type: ignore[attr-defined]
    user.find(marker="apply_can").click()
    await settle(user, term, 2)
    await shows(
        user, "answer_can", "cannot open CAN interface 'slcan' channel '/dev/ttyACM0': no reply"
    )
    assert "no reply" in str(options.props["error-message"])


def test_a_taken_port_is_said_before_anything_starts() -> None:
    import socket

    from topdress.cli.display import DisplayLink

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        link = DisplayLink(object(), DisplayOptions("127.0.0.1", port), print)  # type: ignore[arg-type]
        with pytest.raises(DisplayError, match=f"127.0.0.1:{port} is in use"):
            link.start()
        assert link.pid is None  # no display process was started


async def test_main_screen_shows_the_gnss_lag(user: User) -> None:
    hub = DisplayHub(default_config)
    hub.publish(working(gnss_lag=LagView(950, 950, "learned")))
    register_pages(hub)
    await user.open("/")
    assert text_of(user, "gnss_lag_short") == "lag 0.95 s"  # on the speed card, no touch
    panel(user, "crop")  # where it comes from: one touch away
    assert text_of(user, "gnss_lag") == "GNSS lag 0.95 s (learned)"
    hub.publish(working(t_s=12.1, gnss_lag=LagView(500, 500, "overruled", fixed_ms=1800.0)))
    await shows(user, "gnss_lag", "GNSS lag 0.50 s (learned, not the set 1.80 s)")
    hub.publish(working(t_s=12.2, ecu_live=False, gnss_lag=LagView(950, 950, "learned")))
    await shows(user, "gnss_lag", "")  # not while the ECU is not heard
    assert text_of(user, "gnss_lag_short") == ""
    i18n.set_language("zh")
    hub.publish(working(t_s=12.3, gnss_lag=LagView(1300, None, "start")))
    await user.open("/")
    panel(user, "crop")
    assert text_of(user, "gnss_lag") == "GNSS 滞后 1.30 秒（学习中）"
    assert text_of(user, "gnss_lag_short") == "滞后 1.30 秒"


# ---- the cab: Stop on every screen, never redrawn; states never silent ----------------------
async def test_stop_is_on_every_screen_and_works_in_every_state(user: User) -> None:
    term = Terminal()
    hub = DisplayHub(default_config, term.post)
    running = CalibrationView("catch", "running", "upper meter: 20 revolutions", 0.1)
    hub.publish(working(operator="calibrating", calibration=running))
    register_pages(hub)
    for n, path in enumerate(("/", "/communication", "/control", "/calibration"), 1):
        await user.open(path)
        assert text_of(user, "op_state") == "CALIBRATING"
        user.find(marker="stop").click()
        await settle(user, term, n)
    assert term.sent == [op.Stop()] * 4


async def test_the_calibration_panel_is_updated_in_place_never_rebuilt(user: User) -> None:
    """The wizard's panel follows the progress 5 times a second: its buttons must stay the
    same elements, or a press lands on one that is being replaced and is lost."""
    term = Terminal()
    hub = DisplayHub(default_config, term.post)
    lead = CalibrationView("lead", "running", "trial 1 of 3", 0.0, {}, "lookahead")
    hub.publish(working(operator="calibrating", calibration=lead))
    register_pages(hub)
    await user.open("/calibration")
    (seen,) = user.find(marker="lead_seen").elements
    (close,) = user.find(marker="cal_close").elements
    (stop,) = user.find(marker="stop").elements
    for i in range(1, 6):
        hub.publish(
            working(
                t_s=12 + i / 10, operator="calibrating", calibration=replace(lead, progress=i / 10)
            )
        )
        await asyncio.sleep(0.25)
        assert user.find(marker="lead_seen").elements == {seen}
        assert user.find(marker="cal_close").elements == {close}
        assert user.find(marker="stop").elements == {stop}
    user.find(marker="lead_seen").click()
    await settle(user, term, 1)
    assert term.sent == [op.LeadSeen()]
    # done: Seen goes (hidden, not replaced), the result shows, Apply appears
    done = CalibrationView("lead", "done", "meter 60 ms", 1.0, {"meter_ms": 60.0}, "lookahead")
    hub.publish(working(t_s=20.0, operator="calibrating", calibration=done))
    await shows(user, "cal_result_meter_ms", "meter time ms: 60")
    await user.should_not_see(marker="lead_seen")
    assert user.find(marker="cal_close").elements == {close}


async def test_the_catch_tests_result_stays_on_screen_after_it_is_applied(user: User) -> None:
    term = Terminal(lambda c: CommandResult(True, "settings [machine] applied, saved to t.toml"))
    hub = DisplayHub(default_config, term.post)
    done = CalibrationView(
        "catch",
        "done",
        text(
            "cal.text.catch_done", layer=text("main.upper"), kg_per_rev=0.3012, kg=6.02, rev=19.987
        ),
        1.0,
        {"kg_per_rev": 0.3012},
        "machine.kg_per_rev_upper",
    )
    hub.publish(working(operator="calibrating", calibration=done))
    register_pages(hub)
    await user.open("/calibration")
    user.find(marker="cal_apply").click()
    await settle(user, term, 1)
    await user.should_see("settings [machine] applied")  # the answer, said
    hub.publish(working(t_s=13.0, operator="stopped", calibration=None))
    await shows(
        user,
        "cal_last",
        "last result: upper: 0.3012 kg/rev (6.02 kg over 19.987 rev) · "
        "settings [machine] applied, saved to t.toml",
    )


async def test_ecu_integer_settings_are_sent_as_integers(user: User) -> None:
    term = Terminal()
    hub = DisplayHub(default_config, term.post)
    hub.publish(working(operator="stopped"))
    register_pages(hub)
    await user.open("/control")
    (fan,) = user.find(marker="field_ecu.fan_min_rpm").elements
    fan.value = 2500.0  # type: ignore[attr-defined]  # what a number field gives
    user.find(marker="apply_ecu").click()
    await settle(user, term, 1)
    (sent,) = term.sent
    assert isinstance(sent, op.ApplySettings) and sent.values == {"fan_min_rpm": 2500}
    assert isinstance(sent.values["fan_min_rpm"], int)
    assert not fan.props.get("error")


async def test_a_section_changed_meanwhile_asks_for_a_reload(user: User) -> None:
    from topdress.config_edit import section_version

    def answer(c: object) -> CommandResult:
        assert isinstance(c, op.ApplySettings)
        if c.base != "newer":  # another tab applied since this one was filled
            return CommandResult(
                False, text("op.error.stale", section="speed"), {"speed": "stale"}, "stale"
            )
        return CommandResult(True, "ok")

    term = Terminal(answer)
    hub = DisplayHub(default_config, term.post)
    hub.publish(working(operator="stopped"))
    register_pages(hub)
    await user.open("/control")
    user.find(marker="apply_speed").click()
    await settle(user, term, 1)
    (sent,) = term.sent
    assert isinstance(sent, op.ApplySettings)
    assert sent.base == section_version(default_config(), "speed")
    await user.should_see(marker="ask_speed")
    assert "changed from another screen meanwhile" in text_of(user, "ask_speed")
    await user.should_see(marker="ask_speed_yes")  # Reload


async def test_can_settings_with_the_meters_on_ask_to_stop_first(user: User) -> None:
    term = Terminal()
    hub = DisplayHub(default_config, term.post)
    hub.publish(working(operator="running"))
    register_pages(hub)
    await user.open("/communication")
    user.find(marker="apply_can").click()
    await user.should_see(marker="ask_can")
    user.find(marker="ask_can_yes").click()
    await settle(user, term, 2)
    assert term.sent[0] == op.Stop()
    assert isinstance(term.sent[1], op.ApplySettings) and term.sent[1].section == "can"


async def test_the_manual_panel_shows_what_is_in_force_and_a_refused_rate_says_why(
    user: User,
) -> None:
    term = Terminal(
        lambda c: CommandResult(
            False, text("op.error.rate_range", name="upper_kg_ha", value=9999.0, max=600.0)
        )
    )
    hub = DisplayHub(default_config, term.post)
    hub.publish(working(manual=ManualView("fixed", 120.0, 80.0)))
    register_pages(hub)
    await user.open("/")
    panel(user, "manual")
    (mode,) = user.find(marker="manual_mode").elements
    (upper,) = user.find(marker="manual_upper").elements
    (lower,) = user.find(marker="manual_lower").elements
    assert (mode.value, upper.value, lower.value) == ("fixed", 120.0, 80.0)  # type: ignore[attr-defined]
    assert text_of(user, "manual_in_force") == "in force: MANUAL 120.0 / 80.0 kg/ha"
    upper.value = 9999.0  # type: ignore[attr-defined]
    user.find(marker="manual_apply").click()
    await settle(user, term, 1)
    assert term.sent == [op.SetManual("fixed", 9999.0, 80.0, 0.0)]  # not cut to 600 unsaid
    for _ in range(40):
        if upper.props.get("error"):
            break
        await asyncio.sleep(0.05)
    assert upper.props["error-message"] == "upper_kg_ha: 9999 is outside 0..600 kg/ha"
    # a percent that asks more than PcCommand carries: the rate is cut, and it says so
    hub.publish(
        working(
            t_s=13.0,
            manual=ManualView("percent", percent=200.0),
            rate_model_kg_ha=(250.0, 250.0),
            rate_kg_ha=(600.0, 600.0),
        )
    )
    await shows(user, "manual_state", "MANUAL +200 % of plan · limited to 600")


async def test_rate_steps_are_one_touch(user: User) -> None:
    term = Terminal()
    hub = DisplayHub(default_config, term.post)
    hub.publish(working())
    register_pages(hub)
    await user.open("/")
    user.find(marker="rate_plus").click()
    await settle(user, term, 1)
    hub.publish(working(t_s=12.1, manual=ManualView("percent", percent=10.0)))
    await shows(user, "manual_state", "MANUAL +10 % of plan")
    user.find(marker="rate_plus").click()
    await settle(user, term, 2)
    hub.publish(working(t_s=12.2, manual=ManualView("fixed", 120.0, 80.0)))
    await shows(user, "manual_state", "MANUAL 120.0 / 80.0 kg/ha")
    user.find(marker="rate_minus").click()
    await settle(user, term, 3)
    assert term.sent == [
        op.SetManual("percent", percent=10.0),
        op.SetManual("percent", percent=20.0),
        op.SetManual("fixed", 108.0, 72.0),
    ]


async def test_units_tank_and_area_left(user: User) -> None:
    from topdress.display.map_view import FieldMaps
    from topdress.view.snapshot import TankView

    term = Terminal()
    hub = DisplayHub(default_config, term.post)
    low = AlarmView("tank_low", text("alarm.text.tank_low", kg=95.0), "active", 11.0)
    hub.publish(
        working(
            tank=TankView(500.0, 120.0, 100.0),
            count_field=CounterView(area_ha=0.5),
            alarms=(low,),
        )
    )
    monkey_maps = FieldMaps(field_ha=2.0)
    pages_load = pages.load_field_maps
    pages.load_field_maps = lambda cfg: monkey_maps  # type: ignore[assignment]
    try:
        register_pages(hub)
        await user.open("/")
    finally:
        pages.load_field_maps = pages_load  # type: ignore[assignment]
    # 120 kg left at 283.1 kg/ha applied: 0.42 ha
    assert text_of(user, "tank") == "tank 120 kg left · enough for 0.42 ha"
    assert text_of(user, "area") == "done 0.50 ha · left 1.50 ha"
    assert text_of(user, "v_selected") == "8.0"
    hub.set_prefs(units="imperial")  # display only: lb/ac, mph, ac, lb
    await shows(user, "v_selected", "5.0")
    assert text_of(user, "applied_upper") == "126.6"  # 141.9 kg/ha
    assert text_of(user, "tank") == "tank 265 lb left · enough for 1.05 ac"
    assert text_of(user, "area") == "done 1.24 ac · left 3.71 ac"
    # the alarm and the speed source's rule in the same units (95 kg = 209 lb; 6 km/h = 3.7 mph)
    assert text_of(user, "alarm_banner") == "tank low: 209 lb left · active"
    assert text_of(user, "source_why") == "GNSS: CV 2.51 % < 4.2 %, GNSS 5.0 mph > 3.73 mph"
    hub.set_prefs(units="metric")
    await shows(user, "alarm_banner", "tank low: 95 kg left · active")
    assert text_of(user, "source_why") == "GNSS: CV 2.51 % < 4.2 %, GNSS 8.0 km/h > 6 km/h"
    hub.set_prefs(units="imperial")
    await shows(user, "v_selected", "5.0")
    panel(user, "counters")
    (fill,) = user.find(marker="tank_fill").elements
    (alarm,) = user.find(marker="tank_alarm").elements
    fill.value, alarm.value = 1000.0, 200.0  # type: ignore[attr-defined]  # lb
    user.find(marker="tank_set").click()
    await settle(user, term, 1)
    (sent,) = term.sent
    assert isinstance(sent, op.FillTank)
    assert (sent.fill_kg, sent.alarm_kg) == pytest.approx((453.59237, 90.718474))


async def test_a_viewer_tab_is_not_the_operators_page_and_stop_needs_no_pin(
    user: User, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A tablet's tab (not the cab's browser, a PIN set) only viewing does not count as the
    operator's page for the pause rule; its Stop and Pause go out at once, no PIN asked, and
    with them the tab becomes an operator's page."""
    monkeypatch.setattr(pages, "client_is_remote", lambda: True)
    term = Terminal()
    hub = DisplayHub(pinned, term.post)
    hub.publish(working(operator="running"))
    register_pages(hub)
    await user.open("/")
    open_ids = [*Client.instances, "gone"]
    assert hub.operator_pages_connected(open_ids) == 0
    user.find(marker="stop").click()
    user.find(marker="pause").click()
    await settle(user, term, 2)
    assert term.sent == [op.Stop(), op.Pause()]
    await user.should_not_see(marker="pin")
    assert hub.operator_pages_connected(open_ids) == 1
    assert hub.operator_pages_connected([]) == 0  # closed: forgotten


async def test_the_cab_page_is_the_operators_page(user: User) -> None:
    hub = DisplayHub(default_config)
    hub.publish(working())
    register_pages(hub)
    await user.open("/")
    assert len(hub.operator_pages) == 1
    assert hub.operator_pages_connected(hub.operator_pages) == 1


def test_the_speed_chart_follows_the_units() -> None:
    from topdress.display.units import Units

    hist = [working(t_s=t / 10) for t in range(10)]
    metric = speed_options(hist)
    imperial = speed_options(hist, units=Units("imperial"))
    assert metric["series"][2]["data"][-1][1] == 8.0
    assert imperial["series"][2]["data"][-1][1] == pytest.approx(8.0 / 1.609344, abs=0.01)
    assert "mph" in str(imperial["yAxis"]) and "km/h" in str(metric["yAxis"])


def test_only_values_shown_with_their_unit_word_change_units() -> None:
    from topdress.display.units import Units

    imperial = Units("imperial")
    tank = text("alarm.text.tank_low", kg=100.0)
    assert i18n.render(imperial.shown(tank), "en") == "tank low: 220 lb left"
    assert i18n.render(Units("metric").shown(tank), "en") == "tank low: 100 kg left"
    assert i18n.render(tank, "zh") == "料箱肥量低：剩余 100 kg"
    # a value written with a fixed unit in its template stays as it is
    far = text("alarm.text.wrong_field_boundary", distance_m=12, file="f.geojson", limit_m=5.0)
    assert imperial.shown(far) == far
    assert imperial.shown("plain words") == "plain words" and imperial.shown(None) is None


def isobus_view(**kw: object) -> IsobusView:
    """A spreader served as Task Controller: two products, six sections (two off), four
    control functions (a virtual terminal, the implement, a tractor ECU of a maker not in the
    manufacturer table, the terminal), their NAMEs encoded from the fields given."""
    base: dict[str, object] = dict(
        tc_address=247,
        state="ok",
        implement_address=134,
        implement="Spreader 2400",
        products=(
            ProductView(1, 6, "kg/ha", 138.9, 141.2, 52.4),
            ProductView(2, 1, "L/ha", 80.0, None, None),
        ),
        sections=(True, True, False, True, False, True),
        work_state=True,
        setpoint_latency_ms=650,
        actual_latency_ms=None,
        lookahead_s=1.25,
        functions=(
            ControlFunctionView(38, 0xA0001D00_0C400017, 29, 0, 2, 98, 23),
            ControlFunctionView(134, 0xA00A8400_256001A2, 132, 5, 2, 299, 418),
            ControlFunctionView(240, 0x20008600_4BE01B59, 134, 0, 2, 607, 7001),
            ControlFunctionView(247, 0xA0008200_AFE000C8, 130, 0, 2, 1407, 200),
        ),
    )
    base.update(kw)
    return IsobusView(**base)  # type: ignore[arg-type]


async def test_communication_screen_shows_the_isobus_implement(user: User) -> None:
    hub = DisplayHub(default_config)
    hub.publish(working(isobus=isobus_view()))
    register_pages(hub)
    await user.open("/communication")
    await shows(user, "isobus_tc", "task controller at address 247: ok")
    assert text_of(user, "isobus_implement") == "implement Spreader 2400 at address 134 · working"
    assert text_of(user, "isobus_sections") == "sections ■■□■□■ (4 of 6 on)"
    assert text_of(user, "isobus_timing") == (
        "look-ahead 1.25 s · implement's delays: setpoint 650 ms, actual -- ms"
    )
    assert text_of(user, "isobus_problem") == ""
    (products,) = user.find(marker="isobus_products").elements
    assert products.rows == [  # type: ignore[attr-defined]
        {
            "element": "1",
            "unit": "kg/ha",
            "setpoint": "138.9",
            "actual": "141.2",
            "total": "52.4 kg",
        },
        {"element": "2", "unit": "L/ha", "setpoint": "80.0", "actual": "--", "total": "--"},
    ]
    (functions,) = user.find(marker="isobus_functions").elements
    rows = functions.rows  # type: ignore[attr-defined]
    assert [(r["address"], r["name"], r["what"]) for r in rows] == [
        ("38", "A0001D000C400017", "Virtual Terminal (in cab)"),
        ("134", "A00A8400256001A2", "implement served: Fertilizers Machine Control"),
        ("240", "200086004BE01B59", "Tractor ECU"),
        ("247", "A0008200AFE000C8", "task controller (this terminal)"),
    ]
    assert [r["decoded"] for r in rows] == [
        "function 29, class 0, group 2, manufacturer Mueller-Elektronik GmbH & Co (98), "
        "identity 23",
        "function 132, class 5, group 2, manufacturer Rauch (299), identity 418",
        "function 134, class 0, group 2, manufacturer 607, identity 7001",  # not in the table
        "function 130, class 0, group 2, manufacturer Open-Agriculture (1407), identity 200",
    ]
    # the implement lost, with the terminal's words for it
    hub.publish(working(isobus=isobus_view(state="lost", problem="implement 134 silent 3.0 s")))
    await shows(user, "isobus_tc", "task controller at address 247: lost")
    assert text_of(user, "isobus_problem") == "implement 134 silent 3.0 s"
    # in US units: kg/ha as lb/ac, kg as lb; a volume rate stays L/ha
    hub.set_prefs(units="imperial")
    await shows(user, "isobus_tc", "task controller at address 247: lost")
    for _ in range(40):
        with contextlib.suppress(AssertionError):  # the screen is built anew, then drawn
            (products,) = user.find(marker="isobus_products").elements
            if products.rows and products.rows[0]["unit"] == "lb/ac":  # type: ignore[attr-defined]
                break
        await asyncio.sleep(0.05)
    assert products.rows == [  # type: ignore[attr-defined]
        {
            "element": "1",
            "unit": "lb/ac",
            "setpoint": "123.9",
            "actual": "126.0",
            "total": "115.5 lb",
        },
        {"element": "2", "unit": "L/ha", "setpoint": "80.0", "actual": "--", "total": "--"},
    ]
    hub.set_prefs(units="metric")
    i18n.set_language("zh")
    await shows(user, "isobus_tc", "任务控制器地址 247：丢失")
    assert text_of(user, "isobus_sections") == "作业段 ■■□■□■（6 段中 4 段开）"
    assert text_of(user, "isobus_implement") == "机具 Spreader 2400，地址 134 · 作业中"
    i18n.set_language("en")


async def test_the_chinese_screen_names_the_control_functions_in_chinese(user: User) -> None:
    hub = DisplayHub(default_config)
    hub.publish(working(isobus=isobus_view()))
    register_pages(hub)
    i18n.set_language("zh")
    try:
        await user.open("/communication")
        await shows(user, "isobus_tc", "任务控制器地址 247：正常")
        (functions,) = user.find(marker="isobus_functions").elements
        rows = functions.rows  # type: ignore[attr-defined]
        assert [(r["address"], r["what"]) for r in rows] == [
            ("38", "虚拟终端（驾驶室）"),
            ("134", "所服务的机具：施肥机机器控制"),
            ("240", "拖拉机控制单元"),
            ("247", "任务控制器（本终端）"),
        ]
        # the makers' names as they are written, the rest of the fields in Chinese
        assert rows[1]["decoded"] == "功能 132，设备类 5，行业组 2，制造商 Rauch (299)，标识号 418"
        assert rows[2]["decoded"] == "功能 134，设备类 0，行业组 2，制造商 607，标识号 7001"
        # and back to English when the operator switches
        i18n.set_language("en")
        await shows(user, "isobus_tc", "task controller at address 247: ok")
        for _ in range(40):
            with contextlib.suppress(AssertionError):  # the screen is built anew, then drawn
                (functions,) = user.find(marker="isobus_functions").elements
                if functions.rows and functions.rows[0]["what"].isascii():  # type: ignore[attr-defined]
                    break
            await asyncio.sleep(0.05)
        assert functions.rows[2]["what"] == "Tractor ECU"  # type: ignore[attr-defined]
    finally:
        i18n.set_language("en")


async def test_no_isobus_card_with_the_topdress_ecu(user: User) -> None:
    hub = DisplayHub(default_config)
    hub.publish(working())
    register_pages(hub)
    await user.open("/communication")
    await shows(user, "state_can", "state: ok")
    await user.should_not_see("ISOBUS (Task Controller)")
    await user.should_not_see(marker="isobus_tc")
    await user.open("/")
    await user.should_not_see(marker="implement")
    await shows(user, "source_why", "GNSS: CV 2.51 % < 4.2 %, GNSS 8.0 km/h > 6 km/h")
    # an implement waiting for its pool: the card with no implement in it
    hub.publish(working(isobus=IsobusView(tc_address=None)))
    await user.open("/communication")
    await shows(user, "isobus_tc", "task controller at address --: waiting")
    assert text_of(user, "isobus_implement") == "no implement connected"
    assert text_of(user, "isobus_sections") == ""


async def test_main_screen_shows_the_implement_and_its_sections(user: User) -> None:
    hub = DisplayHub(default_config)
    hub.publish(working(isobus=isobus_view()))
    register_pages(hub)
    await user.open("/")
    await shows(user, "implement", "Spreader 2400: ok · ■■□■□■")
    assert text_of(user, "rate_upper") == "138.9"  # the rates as for the topdress ECU
    # the ECU's speed-source rule does not apply to it: its line gives the implement room
    await user.should_not_see(marker="source_why")
    hub.publish(working(isobus=isobus_view(state="refused", implement="", sections=())))
    await shows(user, "implement", "ISOBUS: refused")
    i18n.set_language("zh")
    await shows(user, "implement", "ISOBUS：被拒绝")
    i18n.set_language("en")
