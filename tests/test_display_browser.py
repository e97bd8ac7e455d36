"""End to end in a real browser: `topdress demo` serving its display to headless Chromium.

Starts the demo (one 40 m pass at 8 km/h, then the machine stands), presses Start and sees the
speed and the rate move, stops, changes a PID gain and sees the ECU acknowledge it, switches to
Chinese, runs the catch-test wizard with the machine standing, and saves a screenshot of every
screen in both languages (into $TOPDRESS_SCREENSHOTS, `make screenshots` -> docs/).
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from browser import DemoProcess, chromium, missing_browser, until

pytestmark = [
    pytest.mark.browser,
    pytest.mark.skipif(missing_browser() is not None, reason=str(missing_browser())),
]

SCREENS = {"main": "/", "communication": "/communication", "control": "/control",
           "calibration": "/calibration"}  # fmt: skip


@pytest.fixture
def demo(tmp_path: Path) -> Iterator[DemoProcess]:
    proc = DemoProcess(tmp_path / "demo", passes=1, duration_s=240.0)
    try:
        proc.wait_served()
        yield proc
    finally:
        code = proc.stop()
        assert code == 0, proc.output()


def test_the_operator_works_the_demo_in_a_browser(demo: DemoProcess, tmp_path: Path) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    shots = Path(os.environ.get("TOPDRESS_SCREENSHOTS", tmp_path / "screenshots"))
    shots.mkdir(parents=True, exist_ok=True)
    driver = chromium(tmp_path / "profile", 1400, 1300)

    def el(tid: str) -> Any:
        return driver.find_element(By.CSS_SELECTOR, f'[data-testid="{tid}"]')

    def text(tid: str) -> str:
        return str(el(tid).text)

    def number(tid: str) -> float:
        return float(text(tid))

    def open_screen(name: str) -> None:
        driver.get(demo.url + SCREENS[name])
        until(f"the {name} screen", lambda: text("clock").startswith("t"))

    def type_into(tid: str, value: str) -> None:
        box = el(tid)  # Quasar puts the attribute on the <input> itself
        if box.tag_name != "input":
            box = box.find_element(By.TAG_NAME, "input")
        box.send_keys(Keys.CONTROL, "a")
        box.send_keys(value)

    def shoot(name: str, lang: str) -> None:
        driver.save_screenshot(str(shots / f"display-{name}-{lang}.png"))

    def details() -> None:
        """The main screen's panel of NDVI, meters and links (one touch from the map)."""
        driver.find_element(By.XPATH, "//button[.//span[text()='NDVI, links']]").click()

    try:
        open_screen("main")
        details()
        until("the ECU acknowledging its parameters", lambda: text("link_ecu") == "ECU: ok")
        assert text("op_state") == "STOPPED"  # the meters wait for the operator
        el("start").click()
        until("RUNNING", lambda: text("op_state") == "RUNNING")
        until("speed moving", lambda: number("v_selected") > 5.0)
        until("the rate commanded", lambda: number("rate_upper") > 50.0)
        until("the meters turning", lambda: number("meter_upper") > 5.0)
        first = number("v_selected"), number("meter_upper")
        until("speed and meters changing", lambda: (number("v_selected"), number("meter_upper"))
              != first)  # fmt: skip
        until("the swath on the map", lambda: len(driver.find_elements(
            By.CSS_SELECTOR, ".leaflet-overlay-pane path")) > 10)  # fmt: skip
        until("the fused speed in use (the default mode)", lambda: text("source") == "fused")
        shoot("main", "en")
        el("stop").click()
        until("STOPPED", lambda: text("op_state") == "STOPPED")

        open_screen("control")
        type_into("field_ecu.pid_kp", "0.02")
        el("apply_ecu").click()
        answer = until("the ECU's answer", lambda: text("answer_ecu") if "[ecu]" in
                       text("answer_ecu") else "")  # fmt: skip
        assert "applied" in answer, answer
        shoot("control", "en")
        assert "pid_kp = 0.02" in (demo.out_dir / "sessions" / "topdress-demo.toml").read_text()

        open_screen("communication")
        el("test_gnss").click()
        until("the GNSS lines", lambda: "RMC" in text("lines_gnss"))
        shoot("communication", "en")
        open_screen("calibration")
        shoot("calibration", "en")

        # 简体中文, at run time, on every page
        el("language").click()
        until("the language menu", lambda: [o for o in driver.find_elements(
            By.CSS_SELECTOR, ".q-menu .q-item") if o.text == "简体中文"])[0].click()  # fmt: skip
        until("the Chinese screen names", lambda: text("nav_calibration") == "标定")

        # The catch test wants the machine standing: after its one pass it does.
        until("the machine standing", lambda: "0.0" == "0.0" and _standing(driver, demo.url),
              timeout_s=90.0)  # fmt: skip
        open_screen("calibration")
        type_into("cal_revs", "2")
        type_into("cal_rpm", "40")
        el("start_catch").click()
        until("the meter turned, waiting for the weight",
              lambda: "称重" in text("cal_state"), timeout_s=30.0)  # fmt: skip
        type_into("cal_kg", "0.61")
        el("finish_catch").click()
        result = until("the kg per revolution", lambda: text("cal_result_kg_per_rev"))
        kg_per_rev = float(result.split(":")[1])
        assert kg_per_rev == pytest.approx(0.61 / 2.0, rel=0.05)  # 0.61 kg over ~2 rev
        shoot("calibration", "zh")
        el("cal_close").click()
        until("the wizard closed", lambda: text("cal_state") == "无进行中的标定")

        for name in ("main", "communication", "control"):
            open_screen(name)
            if name == "communication":
                el("test_crop").click()
                until("the crop lines", lambda: len(text("lines_crop")) > 20)
            time.sleep(1.5)  # charts and map drawn
            shoot(name, "zh")
        assert text("nav_main") == "主界面"
    finally:
        driver.quit()
    for name in SCREENS:
        for lang in ("en", "zh"):
            assert (shots / f"display-{name}-{lang}.png").stat().st_size > 10_000


def _standing(driver: Any, url: str) -> bool:
    from selenium.webdriver.common.by import By

    if not driver.current_url.rstrip("/").endswith(url.rsplit(":", 1)[1].split("/")[0]):
        driver.get(url + "/")
    values = driver.find_elements(By.CSS_SELECTOR, '[data-testid="v_wheel"]')
    return bool(values) and values[0].text in ("0.0", "-0.0")
