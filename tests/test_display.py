"""The operator display's screen logic, in NiceGUI's simulated browser (the `user` fixture)."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Iterator

import pytest
from nicegui.testing import User

from topdress import i18n
from topdress.config import default_config
from topdress.display.charts import meter_options, speed_options
from topdress.display.hub import DisplayHub, bearing_deg, distance_m
from topdress.display.map_view import machine_arrow, rate_colour, swath_quad
from topdress.display.pages import register_pages
from topdress.display.server import DisplayError, DisplayOptions, check_security, is_loopback
from topdress.terminal.app import Snapshot

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
        speed_why="gnss: CV 2.51 % < 4.2 %, GNSS 8.0 > 6.0 km/h",
    )
    base.update(kw)
    return Snapshot(**base)  # type: ignore[arg-type]


@pytest.fixture(autouse=True)
def english() -> Iterator[None]:
    i18n.set_language("en")
    yield
    i18n.set_language("en")


def text_of(user: User, marker: str) -> str:
    (element,) = user.find(marker=marker).elements
    return str(element.text)  # type: ignore[attr-defined]


async def shows(user: User, marker: str, expected: str, timeout_s: float = 3.0) -> None:
    """Wait until the page's timer has drawn `expected` at `marker` (virtual clocks aside,
    the page pulls the snapshot every 0.2 s)."""
    for _ in range(round(timeout_s / 0.05)):
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
    assert text_of(user, "source_why") == "gnss: CV 2.51 % < 4.2 %, GNSS 8.0 > 6.0 km/h"
    assert text_of(user, "op_state") == "RUNNING"
    assert text_of(user, "manual_state") == ""
    assert text_of(user, "ndvi_sensors") == "0.612"
    assert text_of(user, "ndvi_meters") == "0.587"
    assert text_of(user, "rate_upper") == "138.9"
    assert text_of(user, "target_lower") == "22.1"
    assert text_of(user, "meter_upper") == "22.7"
    assert text_of(user, "fan_lower") == "3020"
    assert text_of(user, "faults") == "none"
    assert text_of(user, "link_ecu") == "ECU: ok"
    await user.should_see("km/h")
    await user.should_see("kg/ha")


async def test_main_screen_follows_new_snapshots(user: User) -> None:
    hub = DisplayHub(default_config)
    hub.publish(working(v_kmh=3.0, source="wheel", speed_why="wheel: CV 9.50 % ≥ 4.2 %"))
    register_pages(hub)
    await user.open("/")
    assert text_of(user, "source") == "wheel"
    assert text_of(user, "source_why") == "wheel: CV 9.50 % ≥ 4.2 %"
    hub.publish(working(t_s=12.1, v_kmh=6.5))
    await shows(user, "v_selected", "6.5")
    assert text_of(user, "source") == "GNSS"


async def test_ecu_values_are_dashes_while_the_ecu_is_not_heard(user: User) -> None:
    hub = DisplayHub(default_config)
    hub.publish(working(ecu_live=False, ecu_link="lost", gnss_link="ok"))
    register_pages(hub)
    await user.open("/")
    for marker in ("v_selected", "v_wheel", "target_upper", "meter_lower", "fan_upper", "faults"):
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
    assert text_of(user, "faults") == "GNSS speed lost; upper meter blocked; BIT12"
    hub.publish(working(ecu_live=False, ecu_link="wait", ecu_where="socketcan:can0"))
    await user.open("/")
    assert text_of(user, "link_ecu") == "ECU: waiting (socketcan:can0)"


async def test_language_switches_at_run_time(user: User) -> None:
    hub = DisplayHub(default_config)
    hub.publish(working(faults=1 << 3))
    register_pages(hub)
    await user.open("/")
    await user.should_see("Speed")
    user.find(marker="language").click()
    user.find("简体中文").click()
    assert i18n.language() == "zh"
    await user.should_see("作业速度", retries=20)
    await user.should_not_see("Speed, last minute")
    await shows(user, "faults", "上层排肥器堵转")
    assert text_of(user, "source") == "GNSS"
    await user.should_see("km/h")  # units shown in both languages


def test_speed_chart_marks_the_source_spans() -> None:
    hist = [working(t_s=t / 10, source="wheel" if t < 30 else "gnss") for t in range(50)]
    opts = speed_options(hist)
    selected = opts["series"][2]
    assert [p[1] for p in selected["data"][:2]] == [8.0, 8.0]
    bands = selected["markArea"]["data"]
    assert [(b[0]["name"], b[0]["xAxis"], b[1]["xAxis"]) for b in bands] == [
        ("wheel", 0.0, 2.9),
        ("GNSS", 3.0, 4.9),
    ]
    assert opts["xAxis"]["min"] == 0.0 and opts["xAxis"]["max"] == 4.9


def test_charts_leave_gaps_while_the_ecu_is_not_heard() -> None:
    hist = [working(t_s=1.0), working(t_s=1.1, ecu_live=False), working(t_s=1.2)]
    sel = speed_options(hist)["series"][2]["data"]
    assert [p[1] for p in sel] == [8.0, None, 8.0]
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
    assert opts["xAxis"]["min"] == pytest.approx(10.0)


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
    assert points[1].rate_kg_ha == pytest.approx(277.8)
    again, none = hub.track_since(total)
    assert again == total and none == []


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
