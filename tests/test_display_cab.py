"""The display on a cab terminal's screen (800×480) in a real browser, pressed with real pointer
events: Debian's headless Chromium through Selenium, `topdress demo` with a field boundary, a
prescription map and a tank as its configuration.

On every screen: Stop in view, 64 px, and working; the alarm banner in view; every control at
least 48 px; no label cut off; text contrast at least 4.5:1 and controls 3:1, computed from the
colours the browser rendered, by day and by night. The main screen shows what the driver works
with without scrolling; Stop ends a running calibration. The screenshots of docs/display.md's
cab layout are taken here ($TOPDRESS_SCREENSHOTS, `make screenshots`).
"""

from __future__ import annotations

import io
import json
import math
import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from browser import DemoProcess, chromium, missing_browser, until, viewport

pytestmark = [
    pytest.mark.browser,
    pytest.mark.skipif(missing_browser() is not None, reason=str(missing_browser())),
]

W, H = 800, 480
LAT0, LON0 = 43.8853, 125.3245  # the simulated field's origin (topdress.sim.gnss)
SCREENS = ("communication", "control", "calibration")

#: What the driver works with: on the main screen, in view without scrolling.
MAIN_IN_VIEW = ("start", "pause", "stop", "op_state", "alarm_banner", "rate_upper",
                "rate_lower", "applied_upper", "applied_lower", "v_selected", "source", "map",
                "tank", "area")  # fmt: skip

#: For each visible element with text of its own: its colour against the colour behind it;
#: for each filled button, its colour against the colour behind the button. Colours are
#: parsed by a canvas, so any CSS colour (oklch too) comes back as sRGB.
CONTRAST_JS = """
const cv = document.createElement('canvas'); cv.width = cv.height = 1;
const cx = cv.getContext('2d', {willReadFrequently: true});
function rgba(c) { cx.clearRect(0, 0, 1, 1); cx.fillStyle = '#000'; cx.fillStyle = c;
  cx.fillRect(0, 0, 1, 1); const d = cx.getImageData(0, 0, 1, 1).data;
  return [d[0], d[1], d[2], d[3] / 255]; }
function transparent(c) { return rgba(c)[3] < 0.5 || c === 'transparent'; }
function behind(el) {
  for (let e = el; e; e = e.parentElement) {
    const c = getComputedStyle(e).backgroundColor;
    if (!transparent(c)) return rgba(c);
  }
  return [255, 255, 255, 1];  // the browser's canvas
}
function visible(el) {
  const r = el.getBoundingClientRect(), s = getComputedStyle(el);
  return r.width > 0 && r.height > 0 && s.visibility !== 'hidden' && s.opacity !== '0'
    && r.bottom > 0 && r.right > 0 && r.top < innerHeight && r.left < innerWidth;
}
function name(el) { return (el.getAttribute('data-testid') || el.className || el.tagName)
  .toString().slice(0, 60); }
const texts = [], controls = [], targets = [], cut = [];
for (const el of document.querySelectorAll('body *')) {
  if (!visible(el) || el.closest('.leaflet-container') || el.closest('.q-field--disabled'))
    continue;
  const own = [...el.childNodes].some(n => n.nodeType === 3 && n.textContent.trim());
  if (own) {
    const s = getComputedStyle(el);
    texts.push([name(el) + ': ' + el.textContent.trim().slice(0, 30), rgba(s.color), behind(el)]);
    if (el.scrollWidth > el.clientWidth + 1 && s.overflow !== 'visible')
      cut.push(name(el) + ': ' + el.textContent.trim().slice(0, 40));
  }
  if (el.matches('.q-btn') && !el.matches('.q-btn--flat, .q-btn--outline')) {
    const s = getComputedStyle(el), bg = s.backgroundColor;
    if (!transparent(bg)) controls.push([name(el), rgba(bg), behind(el.parentElement),
      rgba(s.borderTopColor), parseFloat(s.borderTopWidth)]);
  }
  if (el.matches('.q-btn, .q-field__control, .q-radio, .q-toggle, .q-checkbox, .q-tab')) {
    const r = el.getBoundingClientRect();
    targets.push([name(el), Math.round(r.width), Math.round(r.height)]);
  }
}
for (const el of document.querySelectorAll('.q-field__label')) {
  if (visible(el) && el.scrollWidth > el.clientWidth + 1) cut.push('label: ' + el.textContent);
}
return JSON.stringify({texts, controls, targets, cut});
"""


def _lin(c: float) -> float:
    c /= 255.0
    return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4


def _over(fg: list[float], bg: list[float]) -> list[float]:
    """A colour with alpha over an opaque one."""
    a = fg[3]
    return [fg[i] * a + bg[i] * (1 - a) for i in range(3)]


def ratio(fg: list[float], bg: list[float]) -> float:
    """WCAG 2 contrast of `fg` (alpha composited) on `bg`."""
    f = _over(fg, bg)
    la, lb = (0.2126 * _lin(c[0]) + 0.7152 * _lin(c[1]) + 0.0722 * _lin(c[2]) for c in (f, bg))
    hi, lo = max(la, lb), min(la, lb)
    return (hi + 0.05) / (lo + 0.05)


def _png(png: bytes) -> np.ndarray:
    """A screenshot as an H×W×3 array of 0..255."""
    from matplotlib.image import imread

    return np.asarray(imread(io.BytesIO(png), format="png"))[:, :, :3] * 255.0


def _most_contrast(px: np.ndarray, bg: np.ndarray) -> float:
    """The highest WCAG contrast of any pixel in `px` against the colour `bg`: the core of a
    glyph's stroke or a line, where anti-aliasing leaves the colour as drawn."""
    lin = np.where(px / 255 <= 0.04045, px / 255 / 12.92, ((px / 255 + 0.055) / 1.055) ** 2.4)
    lum = lin @ np.array([0.2126, 0.7152, 0.0722])
    lb = float(np.array([_lin(c) for c in bg]) @ np.array([0.2126, 0.7152, 0.0722]))
    return float(np.max((np.maximum(lum, lb) + 0.05) / (np.minimum(lum, lb) + 0.05)))


def _background(px: np.ndarray) -> np.ndarray:
    colours, counts = np.unique(px.reshape(-1, 3).round(), axis=0, return_counts=True)
    return np.asarray(colours[counts.argmax()])


FIELD_JS = """const m = getElement(document.querySelector('[data-testid="map"]')).map;
const sw = m.latLngToContainerPoint(arguments[0]), ne = m.latLngToContainerPoint(arguments[1]);
return [sw.x, ne.y, sw.y];"""


def drawn_contrast(driver: Any) -> dict[str, float]:
    """The contrast of what the page drew, read from screenshots: the charts' axis words
    against the chart, the field boundary's left edge against the map beside it."""
    from selenium.webdriver.common.by import By

    def shot(tid: str) -> np.ndarray:
        return _png(
            driver.find_element(By.CSS_SELECTOR, f'[data-testid="{tid}"]').screenshot_as_png
        )

    out: dict[str, float] = {}
    for chart in ("speed_chart", "meter_chart"):
        px = shot(chart)
        h, w = px.shape[:2]
        bg = _background(px)
        # the grid: 50 px left, 24 right, 40 top, 28 bottom (charts.py); the strips hold words
        # only: below the source bands' names (at the grid's top), below the x axis's ticks
        out[f"{chart}_y_words"] = _most_contrast(px[58 : h - 30, 0:44], bg)
        out[f"{chart}_x_words"] = _most_contrast(px[h - 21 : h, 50 : w - 24], bg)
    return out


def boundary_contrast(driver: Any) -> float:
    sw, ne = rect(-8, -6, 16, 48)[0], rect(-8, -6, 16, 48)[2]
    x, top, bottom = (round(v) for v in driver.execute_script(FIELD_JS, sw[::-1], ne[::-1]))
    from selenium.webdriver.common.by import By

    px = _png(driver.find_element(By.CSS_SELECTOR, '[data-testid="map"]').screenshot_as_png)
    # rows 5..15 m north of the field's south edge: inside one zone, clear of the zones' edges
    span = bottom - top
    mid = slice(bottom - span * 15 // 54, bottom - span * 5 // 54)
    beside = np.median(px[mid, x - 20 : x - 10].reshape(-1, 3), axis=0)
    return _most_contrast(px[mid, x - 3 : x + 4], beside)


def control(fill: list[float], behind: list[float], edge: list[float], edge_px: float) -> float:
    """A control's contrast with what is around it: its fill, or its edge if it has one of
    at least 2 px (WCAG 1.4.11: the boundary that makes it visible)."""
    return max(ratio(fill, behind), ratio(edge, behind) if edge_px >= 2 else 0.0)


def ring(points_m: list[tuple[float, float]]) -> list[list[float]]:
    """(east, north) metres from the field's origin as GeoJSON (lon, lat), closed."""
    cos = math.cos(math.radians(LAT0))
    out = [
        [LON0 + math.degrees(x / (6_371_000.0 * cos)), LAT0 + math.degrees(y / 6_371_000.0)]
        for x, y in points_m
    ]
    return [*out, out[0]]


def rect(x0: float, y0: float, x1: float, y1: float) -> list[list[float]]:
    return ring([(x0, y0), (x1, y0), (x1, y1), (x0, y1)])


def field_files(where: Path) -> Path:
    """A boundary around the demo's 40 m pass, two prescription zones along it, and the
    demo's configuration naming them."""
    where.mkdir(parents=True, exist_ok=True)
    outline = {"type": "Polygon", "coordinates": [rect(-8, -6, 16, 48)]}
    feature = {"type": "Feature", "properties": {}, "geometry": outline}
    boundary = {"type": "FeatureCollection", "features": [feature]}
    zones = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"rate": rate},
         "geometry": {"type": "Polygon", "coordinates": [rect(-8, y0, 16, y1)]}}
        for rate, y0, y1 in ((150.0, -6, 20), (250.0, 20, 48))]}  # fmt: skip
    (where / "boundary.geojson").write_text(json.dumps(boundary))
    (where / "zones.geojson").write_text(json.dumps(zones))
    config = where / "cab.toml"
    config.write_text(
        f'[boundary]\npath = "{where / "boundary.geojson"}"\n'
        f'[prescription]\npath = "{where / "zones.geojson"}"\n'
    )
    return config


@pytest.fixture
def demo(tmp_path: Path) -> Iterator[DemoProcess]:
    config = field_files(tmp_path / "field")
    proc = DemoProcess(tmp_path / "demo", passes=1, duration_s=240.0,
                       extra=("--config", str(config)))  # fmt: skip
    try:
        proc.wait_served()
        yield proc
    finally:
        code = proc.stop()
        assert code == 0, proc.output()


def test_the_cab_screen_at_800x480(demo: DemoProcess, tmp_path: Path) -> None:
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    shots = Path(os.environ.get("TOPDRESS_SCREENSHOTS", tmp_path / "screenshots"))
    shots.mkdir(parents=True, exist_ok=True)
    driver = chromium(tmp_path / "profile", W, H)
    viewport(driver, W, H)
    figures: dict[str, Any] = {"contrast": {}, "targets": {}}

    def el(tid: str) -> Any:
        return driver.find_element(By.CSS_SELECTOR, f'[data-testid="{tid}"]')

    def text(tid: str) -> str:
        return str(el(tid).text)

    def press(tid: str) -> None:
        """A finger: pointer down and up on the element's centre (no scrolling, no script)."""
        ActionChains(driver).move_to_element(el(tid)).click().perform()

    def in_view(tid: str, w: int = W, h: int = H) -> bool:
        r = driver.execute_script(
            "const r = arguments[0].getBoundingClientRect();"
            "return [r.left, r.top, r.right, r.bottom];",
            el(tid),
        )
        return bool(r[0] >= 0 and r[1] >= 0 and r[2] <= w + 0.5 and r[3] <= h + 0.5)

    def live() -> None:
        """The page connected: its clock moves (the first view is drawn before that, and a
        press before the connection would be lost)."""
        first = text("clock")
        until("the page connected", lambda: text("clock") != first)

    def open_screen(name: str) -> None:
        press(f"nav_{name}")  # the header's tab, as a driver does
        until(f"the {name} screen", lambda: driver.current_url.endswith(
            "/" if name == "main" else f"/{name}") and text("clock").startswith("t"))  # fmt: skip
        live()

    def type_into(tid: str, value: str) -> None:
        box = el(tid)
        if box.tag_name != "input":
            box = box.find_element(By.TAG_NAME, "input")
        box.send_keys(Keys.CONTROL, "a")
        box.send_keys(value)

    def check_page(name: str) -> None:
        """Stop and the banner in view, targets, labels, contrast on the page as drawn."""
        assert in_view("stop") and in_view("alarm_banner"), name
        stop = el("stop").size
        assert stop["height"] >= 64 and stop["width"] >= 64, (name, stop)
        found = json.loads(driver.execute_script(CONTRAST_JS))
        low_text = [(n, round(ratio(f, b), 2)) for n, f, b in found["texts"]
                    if ratio(f, b) < 4.5]  # fmt: skip
        low_ctrl = [(n, round(control(*c), 2)) for n, *c in found["controls"]
                    if control(*c) < 3.0]  # fmt: skip
        small = [t for t in found["targets"] if t[1] < 48 or t[2] < 48]
        assert not low_text, (
            name,
            low_text,
            [t for t in found["texts"] if ratio(t[1], t[2]) < 4.5][:3],
        )
        assert not low_ctrl, (name, low_ctrl)
        assert not small, (name, small)
        assert not found["cut"], (name, found["cut"])
        figures["contrast"][name] = (
            round(min(ratio(f, b) for _, f, b in found["texts"]), 2),
            round(min((control(*c) for _, *c in found["controls"]), default=21.0), 2),
        )
        figures["targets"][name] = min(min(t[1], t[2]) for t in found["targets"])

    def stop_works_on(name: str) -> None:
        open_screen("main")
        press("start")
        until("RUNNING", lambda: text("op_state") == "RUNNING")
        if name != "main":
            open_screen(name)
        press("stop")
        until(f"STOPPED by the Stop of the {name} screen", lambda: text("op_state") == "STOPPED")

    try:
        driver.get(demo.url + "/")
        until("the ECU", lambda: text("op_state") == "STOPPED" and "tank" in text("tank"))
        live()
        # the tank: 5 kg in it, an alarm below 4.7 kg (reached within a few metres)
        press("panels")
        driver.find_element(By.XPATH, "//button[.//span[text()='Counters']]").click()
        type_into("tank_fill", "5")
        type_into("tank_alarm", "4.7")
        press("tank_set")
        until("the tank filled", lambda: text("tank").startswith("tank 5 kg left"))
        driver.find_element(By.XPATH, "//button[.//span[text()='Map']]").click()
        press("start")
        until("the speed", lambda: float(text("v_selected")) > 5.0)
        until("the tank alarm in the banner", lambda: "tank low" in text("alarm_banner"),
              timeout_s=40.0)  # fmt: skip
        # the main screen: everything the driver works with, no scrolling
        assert driver.execute_script("return document.documentElement.scrollHeight") <= H
        for tid in MAIN_IN_VIEW:
            assert in_view(tid), tid
        assert "prescription" in text("prescription")
        assert text("area").startswith("done") and "left" in text("area")
        # the map: boundary, two zones, the swath and the machine
        until("the map drawn", lambda: len(driver.find_elements(
            By.CSS_SELECTOR, ".leaflet-overlay-pane path")) > 6)  # fmt: skip
        # the alarm tone plays in the page (Web Audio), while unacknowledged
        until("the tone", lambda: driver.execute_script("return window.tdAudio.beeps") > 0)
        check_page("main")
        driver.save_screenshot(str(shots / "display-cab-day-en.png"))
        for name in ("main", *SCREENS):
            stop_works_on(name)
            check_page(name)
        press("banner_ack")
        until("acknowledged", lambda: "acknowledged" in text("alarm_banner"))
        assert driver.execute_script("return document.body.dataset.alarmTone") == "off"

        # by night
        open_screen("main")
        press("view_menu")
        until("the menu", lambda: el("night").is_displayed())
        press("night")
        until("night", lambda: "body--dark" in driver.find_element(
            By.TAG_NAME, "body").get_attribute("class"))  # fmt: skip
        time.sleep(1.5)  # charts and map drawn
        for name in ("main", *SCREENS):
            if name != "main":
                open_screen(name)
            check_page(f"{name} (night)")
        open_screen("main")
        time.sleep(1.0)
        driver.save_screenshot(str(shots / "display-cab-night-en.png"))
        # the pixels as drawn (the DOM check above cannot see into a canvas or an SVG map)
        figures["night_boundary"] = round(boundary_contrast(driver), 2)
        driver.find_element(By.XPATH, "//button[.//span[text()='Charts']]").click()
        time.sleep(1.5)  # the charts drawn at their size
        drawn = drawn_contrast(driver)
        figures["night_charts"] = {k: round(v, 2) for k, v in drawn.items()}
        assert figures["night_boundary"] >= 3.0, figures["night_boundary"]
        assert min(drawn.values()) >= 4.5, drawn
        driver.find_element(By.XPATH, "//button[.//span[text()='Map']]").click()

        # Stop during a running calibration (the machine stands after its one pass)
        until("the machine standing", lambda: text("v_wheel") in ("0.0", "-0.0"), 120.0)
        open_screen("calibration")
        type_into("cal_revs", "30")
        press("start_catch")
        until("the catch test running", lambda: "running" in text("cal_state"), 20.0)
        time.sleep(1.0)  # the panel follows the progress meanwhile
        press("stop")
        until("the calibration ended by Stop",
              lambda: text("cal_state") == "no calibration running" and text("op_state")
              == "STOPPED", 10.0)  # fmt: skip

        # 简体中文, night and day
        open_screen("main")
        press("language")
        until("the language menu", lambda: [o for o in driver.find_elements(
            By.CSS_SELECTOR, ".q-menu .q-item") if o.text == "简体中文"])[0].click()  # fmt: skip
        until("Chinese", lambda: text("nav_main") == "主界面")
        time.sleep(1.5)
        check_page("main (zh, night)")
        driver.save_screenshot(str(shots / "display-cab-night-zh.png"))
        press("view_menu")
        until("the menu", lambda: el("night").is_displayed())
        press("night")
        until("day", lambda: "body--dark" not in driver.find_element(
            By.TAG_NAME, "body").get_attribute("class"))  # fmt: skip
        time.sleep(1.5)
        check_page("main (zh)")
        driver.save_screenshot(str(shots / "display-cab-day-zh.png"))
        for name in SCREENS:
            open_screen(name)
            check_page(f"{name} (zh)")

        # a 1024×600 screen: the main screen's working set, again without scrolling
        viewport(driver, 1024, 600)
        open_screen("main")
        time.sleep(1.0)
        assert driver.execute_script("return document.documentElement.scrollHeight") <= 600
        for tid in MAIN_IN_VIEW:
            assert in_view(tid, 1024, 600), (tid, "1024x600")

        # resized to 1280×800 (no reload): the field fitted again, as a page opened at that size
        sw, ne = rect(-8, -6, 16, 48)[0], rect(-8, -6, 16, 48)[2]
        field = [[sw[1], sw[0]], [ne[1], ne[0]]]  # lat, lon
        fit_js = (
            "const m = getElement(document.querySelector('[data-testid=\"map\"]')).map;"
            "const c = m.latLngToContainerPoint(m.getCenter()),"
            " f = m.latLngToContainerPoint([(arguments[0][0][0] + arguments[0][1][0]) / 2,"
            " (arguments[0][0][1] + arguments[0][1][1]) / 2]);"
            "return [m.getZoom(), m.getBoundsZoom(arguments[0], false, [16, 16]),"
            " Math.hypot(c.x - f.x, c.y - f.y)];"
        )
        zoom, fit, _ = driver.execute_script(fit_js, field)
        assert zoom == fit, ("1024x600", zoom, fit)
        viewport(driver, 1280, 800)
        until(
            "the field fitted at 1280x800", lambda: driver.execute_script(fit_js, field)[0] > zoom
        )
        zoom, fit, off_px = driver.execute_script(fit_js, field)
        assert zoom == fit and off_px < 30, ("1280x800", zoom, fit, off_px)
    except Exception:
        driver.save_screenshot(str(tmp_path / "failed.png"))
        print("screenshot of the failure:", tmp_path / "failed.png")
        raise
    finally:
        driver.quit()
    print("cab figures:", json.dumps(figures))
