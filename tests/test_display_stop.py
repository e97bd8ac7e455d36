"""Stop is never gated: touched with a finger (touch events over the DevTools protocol) at
800×480 while the meters run, it stops them with every overlay open (the counter-reset
confirmation, the view menu, the language list) and during a lockout of every address, on a
page that has not given the PIN.

The browser is a tablet behind the cab's trusted proxy (its requests carry X-Forwarded-For), a
PIN is set and the cab's browser is recognised by its kiosk cookie, so this browser needs the
PIN to start. One demo and one browser for the whole module.
"""

from __future__ import annotations

import http.server
import threading
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from browser import DemoProcess, chromium, missing_browser, until, viewport
from topdress.cli.display import kiosk_token
from topdress.log.session import SessionReader

pytestmark = [
    pytest.mark.browser,
    pytest.mark.skipif(missing_browser() is not None, reason=str(missing_browser())),
]

W, H = 800, 480
PIN = "4321"
TABLET = "10.9.9.9"


@pytest.fixture(scope="module")
def where(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("stop")


@pytest.fixture(scope="module")
def tablet(where: Path) -> Iterator[tuple[DemoProcess, Any]]:
    config = where / "cab.toml"
    config.write_text(
        f'[display]\npin = "{PIN}"\ntrusted_proxies = ["127.0.0.1"]\n'
        f'kiosk_token_file = "{where / "kiosk-token"}"\n'
    )
    demo = DemoProcess(where / "demo", passes=1, duration_s=600.0,
                       extra=("--config", str(config)))  # fmt: skip
    driver: Any = None
    try:
        demo.wait_served()
        driver = chromium(where / "profile", W, H)
        viewport(driver, W, H)
        driver.execute_cdp_cmd("Network.enable", {})
        driver.execute_cdp_cmd(
            "Network.setExtraHTTPHeaders", {"headers": {"X-Forwarded-For": TABLET}}
        )
        driver.execute_cdp_cmd(
            "Emulation.setTouchEmulationEnabled", {"enabled": True, "maxTouchPoints": 1}
        )
        yield demo, driver
    finally:
        if driver is not None:
            driver.quit()
        code = demo.stop()
        assert code == 0, demo.output()


def _el(driver: Any, tid: str) -> Any:
    from selenium.webdriver.common.by import By

    return driver.find_element(By.CSS_SELECTOR, f'[data-testid="{tid}"]')


def _text(driver: Any, tid: str) -> str:
    return str(_el(driver, tid).text)


def _touch(driver: Any, tid: str) -> None:
    """A finger on the element's centre: touchStart and touchEnd, nothing else."""
    r = driver.execute_script(
        "const r = arguments[0].getBoundingClientRect();"
        "return [r.left + r.width / 2, r.top + r.height / 2];",
        _el(driver, tid),
    )
    point = {"x": r[0], "y": r[1]}
    driver.execute_cdp_cmd(
        "Input.dispatchTouchEvent", {"type": "touchStart", "touchPoints": [point]}
    )
    driver.execute_cdp_cmd("Input.dispatchTouchEvent", {"type": "touchEnd", "touchPoints": []})


def _press(driver: Any, tid: str) -> None:
    """A pointer's press and release on the element's centre (the controls around Stop)."""
    from selenium.webdriver.common.action_chains import ActionChains

    ActionChains(driver).move_to_element(_el(driver, tid)).click().perform()


def _live(driver: Any) -> None:
    first = _text(driver, "clock")
    until("the page connected", lambda: _text(driver, "clock") != first)


def _run(driver: Any) -> None:
    _press(driver, "start")
    until("RUNNING", lambda: _text(driver, "op_state") == "RUNNING")


def _open_reset(driver: Any) -> None:
    from selenium.webdriver.common.by import By

    driver.find_element(By.XPATH, "//button[.//span[text()='Counters']]").click()
    _press(driver, "reset_field")
    until("the reset confirmation", lambda: _el(driver, "reset_ask").is_displayed())


def _open_menu(driver: Any) -> None:
    _press(driver, "view_menu")
    until("the view menu", lambda: _el(driver, "night").is_displayed())


def _open_language(driver: Any) -> None:
    from selenium.webdriver.common.by import By

    _press(driver, "language")
    until("the language list", lambda: driver.find_elements(By.CSS_SELECTOR, ".q-menu .q-item"))


def test_stop_over_every_overlay_and_through_a_lockout(
    tablet: tuple[DemoProcess, Any],
) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    demo, driver = tablet
    driver.get(demo.url + "/")
    until(
        "the ECU",
        lambda: _text(driver, "op_state") == "STOPPED" and "tank" in _text(driver, "tank"),
    )
    _live(driver)
    # Starting needs the PIN here (a tablet); the tab keeps it.
    _press(driver, "start")
    box = until("the PIN dialog", lambda: driver.find_element(By.CSS_SELECTOR, ".q-dialog input"))
    box.send_keys(PIN)
    box.send_keys(Keys.ENTER)
    until("RUNNING", lambda: _text(driver, "op_state") == "RUNNING")

    for name, open_overlay in (
        ("reset confirmation", _open_reset),
        ("view menu", _open_menu),
        ("language list", _open_language),
    ):
        if _text(driver, "op_state") != "RUNNING":
            _run(driver)
        open_overlay(driver)
        _touch(driver, "stop")
        until(f"STOPPED by a touch on Stop over the {name}",
              lambda: _text(driver, "op_state") == "STOPPED", 10.0)  # fmt: skip
        driver.get(demo.url + "/")  # whatever the overlay left behind
        until("the page", lambda: _text(driver, "op_state") == "STOPPED")
        _live(driver)
        # the reload forgot the PIN: start again with it
        _press(driver, "start")
        box = until(
            "the PIN dialog", lambda: driver.find_element(By.CSS_SELECTOR, ".q-dialog input")
        )
        box.send_keys(PIN)
        box.send_keys(Keys.ENTER)
        until("RUNNING", lambda: _text(driver, "op_state") == "RUNNING")

    # Everyone locked out: 20 wrong kiosk tokens from rotating forwarded addresses.
    for n in range(20):
        request = urllib.request.Request(
            f"{demo.url}/?kiosk=guess{n}", headers={"X-Forwarded-For": f"10.0.1.{n}"}
        )
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(request, timeout=5)
        assert refused.value.code in (403, 429)
    # A fresh page (no PIN given) under the lockout: Stop still stops, no dialog asked.
    driver.get(demo.url + "/")
    until("the page", lambda: _text(driver, "op_state") == "RUNNING")
    _live(driver)
    _touch(driver, "stop")
    until("STOPPED by Stop during a lockout", lambda: _text(driver, "op_state") == "STOPPED", 10.0)
    assert not driver.find_elements(By.CSS_SELECTOR, ".q-dialog input")


def _serve(page: str) -> http.server.ThreadingHTTPServer:
    """`page` at / of a local server on a port of its own: another origin than the display's."""

    class Page(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            body = page.encode()
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args: object) -> None:
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Page)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


def test_a_page_of_another_origin_guessing_the_kiosk_token_leaves_the_cab_in(
    tablet: tuple[DemoProcess, Any], where: Path
) -> None:
    """Six `<img src=".../?kiosk=guessN">` on a page of another local origin (no-cors GETs carry
    no Origin) lock 127.0.0.1 out; the cab's kiosk coming back with its token is still the cab:
    its page, Start without the PIN, Stop."""
    from selenium.webdriver.common.by import By

    demo, driver = tablet

    def guesses() -> int:
        """The kiosk-token guesses from 127.0.0.1 in the session log so far."""
        (path,) = (demo.out_dir / "sessions").glob("*.sqlite")
        with SessionReader(path) as reader:
            return sum(
                1
                for e in reader.events()
                if e.kind == "display.pin_failed"
                and e.detail == {**e.detail, "address": "127.0.0.1", "what": "kiosk"}
            )

    before = guesses()
    driver.execute_cdp_cmd("Network.setExtraHTTPHeaders", {"headers": {}})  # the PC's own
    imgs = "".join(f'<img src="{demo.url}/?kiosk=guess{n}" width=1>' for n in range(6))
    attacker = _serve(f"<!doctype html><title>another site</title>{imgs}")
    try:
        driver.get(f"http://127.0.0.1:{attacker.server_address[1]}/")

        def locked() -> bool:
            try:
                urllib.request.urlopen(f"{demo.url}/?kiosk=guess", timeout=5)
            except urllib.error.HTTPError as refused:
                return refused.code == 429
            return False

        until("the six guesses counted and logged", lambda: guesses() >= before + 6)
        until("127.0.0.1 locked out by the guesses", locked)
        driver.get(f"{demo.url}/?kiosk={kiosk_token(str(where / 'kiosk-token'))}")
        until("the cab's page", lambda: _text(driver, "op_state") in ("STOPPED", "RUNNING"))
        assert "?kiosk" not in driver.current_url  # the token left the address bar
        _live(driver)
        if _text(driver, "op_state") == "RUNNING":
            _touch(driver, "stop")
            until("STOPPED", lambda: _text(driver, "op_state") == "STOPPED")
        _press(driver, "start")  # the cab: no PIN asked
        until("RUNNING without the PIN", lambda: _text(driver, "op_state") == "RUNNING", 10.0)
        assert not driver.find_elements(By.CSS_SELECTOR, ".q-dialog input")
        _touch(driver, "stop")
        until("STOPPED", lambda: _text(driver, "op_state") == "STOPPED", 10.0)
    finally:
        attacker.shutdown()
        driver.delete_all_cookies()  # the tablet again for the module's other tests
        driver.execute_cdp_cmd(
            "Network.setExtraHTTPHeaders", {"headers": {"X-Forwarded-For": TABLET}}
        )


#: Every tab's and header button's label whose text runs over more than one line.
WRAPPED_JS = """
const out = [];
for (const el of document.querySelectorAll(
    '.q-tab__label, header .q-btn .block, [data-testid="panels"] .q-btn .block')) {
  const r = el.getBoundingClientRect(), s = getComputedStyle(el);
  const line = parseFloat(s.lineHeight) || parseFloat(s.fontSize) * 1.2;
  if (r.width > 0 && r.height > line * 1.5) out.push([el.textContent.trim(), r.height, line]);
}
return out;
"""


#: The language selector's field: its fill as drawn (r, g, b).
SELECT_FILL_JS = """
const el = document.querySelector('[data-testid="language"]');
const field = el.querySelector('.q-field__control') || el.closest('.q-field').querySelector(
  '.q-field__control');
const c = getComputedStyle(field).backgroundColor.match(/[0-9.]+/g).map(Number);
return c.length > 3 && c[3] === 0 ? [0, 0, 0] : c.slice(0, 3);
"""


def test_chinese_labels_do_not_wrap_and_the_language_field_stays_dark_at_night(
    tablet: tuple[DemoProcess, Any],
) -> None:
    from selenium.webdriver.common.by import By

    demo, driver = tablet
    driver.get(demo.url + "/")
    until("the page", lambda: _text(driver, "op_state"))
    _press(driver, "view_menu")
    until("the menu", lambda: _el(driver, "night").is_displayed())
    _el(driver, "night").click()
    until("night", lambda: driver.execute_script(
        "return document.body.classList.contains('body--dark')"))  # fmt: skip
    _press(driver, "language")
    item = "//div[contains(@class,'q-menu')]//div[contains(@class,'q-item')]"
    until("the language list", lambda: driver.find_element(
        By.XPATH, f"{item}[.//span[contains(text(),'中文')]]")).click()  # fmt: skip
    try:
        until("Chinese", lambda: "主" in _text(driver, "nav_main"))
        assert driver.execute_script(WRAPPED_JS) == []
        # chosen (the field focused) by night: not a white field with white text on it
        assert max(driver.execute_script(SELECT_FILL_JS)) < 128
    finally:
        _press(driver, "language")
        until("the list", lambda: driver.find_element(By.XPATH, f"{item}[1]")).click()
