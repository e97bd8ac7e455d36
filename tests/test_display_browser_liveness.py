"""A dead display never looks alive, in a real browser at a cab screen's 800×480.

`topdress demo` with its display in headless Chromium: Start, then `kill -9` of the display
process: the page goes to its full-screen stale state (no green RUNNING, the values greyed under
it); the terminal starts a new display process and the page comes back by itself, live. Then
SIGTERM of the terminal: the stale state again. Night mode and the units chosen before the kill
are what the new display shows. A terminal stopped for 5 s (SIGSTOP) leaves the healthy display
running and reported up. The times are printed (bench/display_bench.py
measures them against their targets); the test checks what is shown.
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest

from browser import STALE_JS, DemoProcess, chromium, display_pid, missing_browser, until

pytestmark = [
    pytest.mark.browser,
    pytest.mark.skipif(missing_browser() is not None, reason=str(missing_browser())),
]


def test_a_killed_display_shows_stale_then_comes_back(tmp_path: Path) -> None:
    from selenium.webdriver.common.by import By

    demo = DemoProcess(tmp_path / "demo", passes=30, duration_s=180.0)
    driver = None
    try:
        demo.wait_served()
        driver = chromium(tmp_path / "profile", 800, 480)

        def text(tid: str) -> str:
            return str(driver.find_element(By.CSS_SELECTOR, f'[data-testid="{tid}"]').text)

        def content(tid: str) -> str:
            """An element's text whether or not its panel is the one shown."""
            query = f"return document.querySelector('[data-testid=\"{tid}\"]').textContent"
            return str(driver.execute_script(query))

        def stale() -> bool:
            return bool(driver.execute_script(STALE_JS))

        def night() -> bool:
            return bool(driver.execute_script(
                "return document.body.classList.contains('body--dark')"))  # fmt: skip

        def mph() -> bool:
            return bool(driver.find_elements(By.XPATH, "//*[text()='mph']"))

        driver.get(demo.url)
        until("the ECU acknowledging its parameters", lambda: content("link_ecu") == "ECU: ok")
        driver.find_element(By.CSS_SELECTOR, '[data-testid="start"]').click()
        until("RUNNING", lambda: text("op_state") == "RUNNING")
        assert not stale()
        # night and US units, chosen before the kill, come back with the new display process

        def choose(item: str) -> bool:
            """Open the view menu and touch `item` (the page redraws after each choice)."""
            driver.find_element(By.CSS_SELECTOR, '[data-testid="view_menu"]').click()
            until(f"the {item} item", lambda: driver.find_element(
                By.CSS_SELECTOR, f'[data-testid="{item}"]').is_displayed())  # fmt: skip
            driver.find_element(By.CSS_SELECTOR, f'[data-testid="{item}"]').click()
            return True

        # (each a toggle: touched again only if the page did not take it)
        until("night chosen", lambda: night() or (choose("night") and until("night", night, 3.0)))
        until("US units chosen", lambda: mph() or (choose("units") and until("mph", mph, 3.0)))
        until("night and mph", lambda: night() and mph())
        first = display_pid(demo.proc.pid)
        assert first is not None

        os.kill(first, signal.SIGKILL)
        killed = time.monotonic()
        until("the stale state", stale, timeout_s=10.0)
        shown_s = time.monotonic() - killed
        cover = driver.find_element(By.CSS_SELECTOR, '[data-testid="stale"]')
        assert "No connection to the terminal" in cover.text
        size = cover.size  # the whole viewport
        viewport = driver.execute_script("const e = document.documentElement;"
                                         "return [e.clientWidth, window.innerHeight]")  # fmt: skip
        assert [size["width"], size["height"]] == viewport
        # The page under it is greyed: nothing green reads RUNNING.
        assert "grayscale" in driver.execute_script(
            "return getComputedStyle(document.getElementById('app')).filter"
        )
        time.sleep(0.5)
        assert stale()  # and it stays until a server answers

        until("a new display process", lambda: display_pid(demo.proc.pid) not in (None, first))
        until("the page live again", lambda: not stale() and text("op_state") != "", 30.0)
        back_s = time.monotonic() - killed
        clock = text("clock")
        until("the values moving", lambda: text("clock") != clock)
        assert night() and mph()  # the operator's view, not the defaults
        # the terminal stalled 5 s (SIGSTOP): a stall of the terminal, not a hang of the
        # display, so the healthy display is neither killed nor reported down
        second = display_pid(demo.proc.pid)
        downs = demo.output().count("display down")
        demo.proc.send_signal(signal.SIGSTOP)
        time.sleep(5.0)
        demo.proc.send_signal(signal.SIGCONT)
        clock = text("clock")
        until("the page live after the stall", lambda: not stale() and text("clock") != clock)
        time.sleep(2.0)  # the terminal's watch has looked again
        assert display_pid(demo.proc.pid) == second
        assert demo.output().count("display down") == downs, demo.output()
        print(f"\nstale shown {shown_s:.2f} s after kill -9; live again after {back_s:.2f} s")
        assert "display down (killed by signal 9)" in demo.output()
        assert "display started again (1 restarts)" in demo.output()

        demo.proc.send_signal(signal.SIGTERM)  # the terminal itself ends
        stopped = time.monotonic()
        until("the stale state after SIGTERM", stale, timeout_s=10.0)
        print(f"stale shown {time.monotonic() - stopped:.2f} s after SIGTERM of the terminal")
    finally:
        if driver is not None:
            driver.quit()
        assert demo.stop() == 0, demo.output()
