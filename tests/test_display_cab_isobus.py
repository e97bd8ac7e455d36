"""The ISOBUS implement at 800×480 in Chromium, in English and in Chinese: on the main screen the
implement's line (designator, state, sections) with the alarm banner and the prescription line
shown, and the working set still in view without scrolling; on the communication screen the
ISOBUS card's table of control functions (makers' names, what each is) within the screen's
width, no cell cut."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from browser import answers, chromium, free_port, missing_browser, until, viewport

pytestmark = [
    pytest.mark.browser,
    pytest.mark.skipif(missing_browser() is not None, reason=str(missing_browser())),
]

W, H = 800, 480
IN_VIEW = ("start", "pause", "stop", "alarm_banner", "rate_upper", "rate_lower",
           "applied_upper", "applied_lower", "prescription", "implement", "v_selected",
           "tank", "area")  # fmt: skip

#: The display's pages alone, serving one snapshot: the worst case for height (an alarm in
#: the banner, the prescription line, the implement's line).
SERVE = """
import sys
from nicegui import ui
from topdress.config import default_config
from topdress.display.hub import DisplayHub
from topdress.display.pages import register_pages
from topdress import i18n
from topdress.i18n import text
from topdress.view.snapshot import AlarmView, TankView
from test_display import isobus_view, working

hub = DisplayHub(default_config)
low = AlarmView("tank_low", text("alarm.text.tank_low", kg=4.5), "active", 11.0)
hub.publish(working(prescription_kg_ha=150.0, zone="field", alarms=(low,),
                    tank=TankView(5.0, 4.5, 4.7), isobus=isobus_view()))
i18n.set_language(sys.argv[2])
register_pages(hub)
ui.run(host="127.0.0.1", port=int(sys.argv[1]), reload=False, show=False,
       show_welcome_message=False)
"""


#: What the main screen's implement line says in each language.
IMPLEMENT = {"en": "Spreader 2400: ok · ■■□■□■", "zh": "Spreader 2400：正常 · ■■□■□■"}
ALARM = {"en": "tank low", "zh": "料箱肥量低"}
#: The card's words for the served implement (its function translated) in each language.
SERVED = {
    "en": "implement served: Fertilizers Machine Control",
    "zh": "所服务的机具：施肥机机器控制",
}


@pytest.fixture(params=["en", "zh"])
def served(request: pytest.FixtureRequest) -> Iterator[tuple[str, str]]:
    lang = str(request.param)
    port = free_port()
    env = dict(os.environ)
    env.pop("PYTEST_CURRENT_TEST", None)  # a real server, not NiceGUI's test one
    env["PYTHONPATH"] = os.pathsep.join([str(Path(__file__).parent), *sys.path])
    proc = subprocess.Popen(
        [sys.executable, "-c", SERVE, str(port), lang],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        stdin=subprocess.DEVNULL,
    )
    url = f"http://127.0.0.1:{port}"
    try:
        until("the display served", lambda: answers(url + "/"), timeout_s=60.0)
        yield url, lang
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_the_implement_fits_the_cab_screen(served: tuple[str, str], tmp_path: Path) -> None:
    from selenium.webdriver.common.by import By

    url, lang = served
    driver = chromium(tmp_path / "profile", W, H)
    viewport(driver, W, H)

    def el(tid: str) -> Any:
        return driver.find_element(By.CSS_SELECTOR, f'[data-testid="{tid}"]')

    def in_view(tid: str) -> bool:
        r = driver.execute_script(
            "const r = arguments[0].getBoundingClientRect();"
            "return [r.left, r.top, r.right, r.bottom];",
            el(tid),
        )
        return bool(r[0] >= 0 and r[1] >= 0 and r[2] <= W + 0.5 and r[3] <= H + 0.5)

    try:
        driver.get(url + "/")
        until("the implement", lambda: el("implement").text == IMPLEMENT[lang])
        until("the alarm", lambda: ALARM[lang] in el("alarm_banner").text)
        assert driver.execute_script("return document.documentElement.scrollHeight") <= H
        assert [tid for tid in IN_VIEW if not in_view(tid)] == []
        assert not el("source_why").is_displayed()  # its place given to the implement

        # the communication screen: it scrolls down, but nothing of the ISOBUS card is wider
        # than the screen or cut in its cell
        driver.get(url + "/communication")
        until("the control functions", lambda: SERVED[lang] in el("isobus_functions").text)
        assert "Rauch (299)" in el("isobus_functions").text
        assert driver.execute_script("return document.documentElement.scrollWidth") <= W
        for tid in ("isobus_tc", "isobus_implement", "isobus_products", "isobus_functions"):
            left, right = driver.execute_script(
                "const r = arguments[0].getBoundingClientRect(); return [r.left, r.right];",
                el(tid),
            )
            assert left >= 0 and right <= W + 0.5, (tid, left, right)
        wide = driver.execute_script(
            "return [...arguments[0].querySelectorAll('td, th, .q-table__middle')]"
            ".filter(c => c.scrollWidth > c.clientWidth + 1).map(c => c.textContent);",
            el("isobus_functions"),
        )
        assert wide == []
        # each column's heading on one line (a narrow column breaks "地址" in two)
        lines = driver.execute_script(
            "return [...arguments[0].querySelectorAll('th')].map(th => {"
            "  const r = document.createRange(); r.selectNodeContents(th);"
            "  return [th.textContent.trim(),"
            "          new Set([...r.getClientRects()].map(b => Math.round(b.top))).size]; });",
            el("isobus_functions"),
        )
        assert [t for t, n in lines if n > 1] == []
    finally:
        driver.quit()
