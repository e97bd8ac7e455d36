"""The display in a real browser: Debian's headless Chromium driven by Selenium through
Debian's chromedriver (nothing downloads a browser), and `topdress demo` as a child process.

Test code, no part of the package: used by the end-to-end test (tests/test_display_browser.py)
and bench/display_bench.py; needs the dev extras (selenium) and scripts/sysdeps.sh's browser
packages.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from topdress.display.cpu import yield_to_the_terminal

if TYPE_CHECKING:
    from selenium.webdriver.remote.webdriver import WebDriver

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
#: No network beyond the page, no first-run or background traffic.
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-dev-shm-usage",
)


def missing_browser() -> str | None:
    """Why a browser cannot be driven here (None: it can)."""
    for path in (CHROMIUM, CHROMEDRIVER):
        if not Path(path).exists():
            return f"{path} missing (scripts/sysdeps.sh browser installs chromium, chromium-driver)"
    return None


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def chromium(
    profile_dir: Path, width: int = 1400, height: int = 1200, niceness: int = 0
) -> WebDriver:
    """A fresh headless Chromium (its own profile directory); `niceness` > 0 runs it (and its
    driver) at a lower CPU priority than the terminal and off the first CPU, as a cab PC's
    kiosk browser should run."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for flag in CHROMIUM_FLAGS:
        opts.add_argument(flag)
    opts.add_argument(f"--user-data-dir={profile_dir}")
    opts.add_argument(f"--window-size={width},{height}")

    def lower() -> None:
        yield_to_the_terminal(niceness)

    service = Service(CHROMEDRIVER, popen_kw={"preexec_fn": lower if niceness else None})
    return webdriver.Chrome(options=opts, service=service)


def viewport(driver: WebDriver, width: int, height: int) -> None:
    """The page's own size, exactly (a cab terminal's screen: 800×480, 1024×600), whatever the
    headless window's frame takes."""
    driver.execute_cdp_cmd(  # type: ignore[attr-defined]
        "Emulation.setDeviceMetricsOverride",
        {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False},
    )


def answers(url: str) -> bool:
    """Whether a page is served at `url`."""
    try:
        with urllib.request.urlopen(url, timeout=2) as response:
            return bool(response.status == 200)
    except OSError:
        return False


class DemoProcess:
    """`topdress demo` with its display on a free port, its output in a file."""

    def __init__(
        self,
        out_dir: Path,
        passes: int = 30,
        duration_s: float = 300.0,
        extra: tuple[str, ...] = (),
    ) -> None:
        self.out_dir = out_dir
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.log_path = out_dir / "demo-output.txt"
        out_dir.mkdir(parents=True, exist_ok=True)
        env = dict(os.environ)
        # Under pytest NiceGUI would take its test port: this is a real run.
        env.pop("PYTEST_CURRENT_TEST", None)
        self._log = self.log_path.open("w")
        self.proc = subprocess.Popen(
            [
                sys.executable, "-m", "topdress.cli", "demo",
                "--port", str(self.port),
                "--out", str(out_dir / "sessions"),
                "--passes", str(passes),
                "--duration", str(duration_s),
                *extra,
            ],
            stdout=self._log,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            env=env,
        )  # fmt: skip

    def output(self) -> str:
        return self.log_path.read_text(errors="replace")

    def wait_served(self, timeout_s: float = 60.0) -> str:
        """The address the demo printed, once it answers."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            found = re.search(r"display: (http://\S+)", self.output())
            if found and answers(found.group(1)):
                return found.group(1)
            if self.proc.poll() is not None:
                break
            time.sleep(0.1)
        raise RuntimeError(f"the demo did not serve its display:\n{self.output()}")

    def stop(self, timeout_s: float = 20.0) -> int:
        """SIGTERM, as a service manager stops it; the exit code."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._log.close()
        return int(self.proc.returncode)


def display_pid(terminal_pid: int) -> int | None:
    """The display process a terminal started (its child running topdress.display)."""
    for task in Path(f"/proc/{terminal_pid}/task").iterdir():
        for pid in (task / "children").read_text().split():
            try:
                cmdline = Path(f"/proc/{pid}/cmdline").read_bytes()
            except OSError:
                continue
            if b"topdress.display" in cmdline:
                return int(pid)
    return None


#: In the page: whether it shows its full-screen stale state (topdress.display.liveness).
STALE_JS = (
    "return document.documentElement.classList.contains('td-stale')"
    " && document.getElementById('td-stale').offsetHeight > 0"
)


def until(what: str, check: Callable[[], Any], timeout_s: float = 30.0) -> Any:
    """Poll `check` until it gives something true; its last answer (or error) in the failure."""
    deadline = time.monotonic() + timeout_s
    last: Any = None
    while time.monotonic() < deadline:
        try:
            last = check()
        except Exception as exc:  # an element not drawn yet, a stale one, a reload
            last = exc
        else:
            if last:
                return last
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what} (last: {last!r})")
