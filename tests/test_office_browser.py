"""`topdress office serve` in a real Chromium: the season's map and report of two machines,
filtered by machine, from a database the page only reads."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import psycopg
import pytest

from browser import answers, chromium, free_port, missing_browser
from office_rig import needs_postgres, session
from topdress.office.push import push

pytestmark = [
    pytest.mark.browser,
    needs_postgres,
    pytest.mark.skipif(missing_browser() is not None, reason=str(missing_browser())),
]


@pytest.fixture
def served(office_db: str, tmp_path: Path) -> Iterator[str]:
    with psycopg.connect(office_db) as conn:
        push(conn, session(tmp_path / "a", "m1", north_m=0.0, seconds=50))
        push(conn, session(tmp_path / "b", "m2", north_m=2.0, seconds=50))
    port = free_port()
    log = (tmp_path / "serve.log").open("w")
    # NiceGUI takes a process with this variable for its own test harness
    env = {k: v for k, v in os.environ.items() if k != "PYTEST_CURRENT_TEST"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "topdress", "office", "serve", "--db", office_db,
         "--port", str(port)],
        stdout=log, stderr=subprocess.STDOUT, env=env,
    )  # fmt: skip
    url = f"http://127.0.0.1:{port}/"
    try:
        end = time.monotonic() + 60
        while not answers(url):
            assert proc.poll() is None, (tmp_path / "serve.log").read_text()
            assert time.monotonic() < end, "the office page never answered"
            time.sleep(0.2)
        yield url
    finally:
        proc.terminate()
        proc.wait(10)
        log.close()


def test_the_season_map_and_report_in_a_browser(served: str, tmp_path: Path) -> None:
    from selenium.common.exceptions import StaleElementReferenceException
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    driver = chromium(tmp_path / "profile")
    try:
        driver.get(served)
        # the report is rebuilt when a filter changes: a row read mid-rebuild is stale, not wrong
        wait = WebDriverWait(driver, 30, ignored_exceptions=(StaleElementReferenceException,))

        def rows() -> list[str]:
            return [
                r.text
                for r in driver.find_elements(By.CSS_SELECTOR, '[data-testid="report"] tbody tr')
            ]

        wait.until(lambda d: any(r.startswith("machine m2") for r in rows()))
        got = rows()
        assert any(r.startswith("machine m1") for r in got)
        assert (
            "season 2026: 2 sessions drawn"
            in driver.find_element(By.CSS_SELECTOR, '[data-testid="status"]').text
        )
        areas = driver.find_element(By.CSS_SELECTOR, '[data-testid="areas"]').text
        assert "covered twice: (outside every field): m1 + m2" in areas
        shapes: Any = driver.find_elements(By.CSS_SELECTOR, '[data-testid="map"] path')
        assert len(shapes) == 2  # one cover a session
        # filter: machine m2 only
        driver.find_element(By.CSS_SELECTOR, '[data-testid="machine"]').click()
        wait.until(lambda d: d.find_elements(By.XPATH, "//div[@role='option']//span[text()='m2']"))
        driver.find_element(By.XPATH, "//div[@role='option']//span[text()='m2']").click()
        wait.until(lambda d: not any(r.startswith("machine m1") for r in rows()))
        assert any(r.startswith("machine m2") for r in rows())
        wait.until(lambda d: len(d.find_elements(By.CSS_SELECTOR, '[data-testid="map"] path')) == 1)
    finally:
        driver.quit()
