"""Display benchmark: the terminal with its display served and one browser watching it.

    .venv/bin/python bench/display_bench.py [--duration 60]

As bench/terminal_bench.py (this process plays the machine: 10 Hz GNSS and crop sensors on
pseudo-terminals, the ECU's twin on a udp_multicast bus; the terminal runs in a child process,
send_on_gnss on, session log on, meters started), plus the display served by the child and a
headless Chromium (Debian's, through Selenium; at nice 10 and off the first CPU, as the kiosk
set-up of docs/display.md) showing its main screen the whole time. The terminal runs with the
real-time policy docs/display.md sets it up with (`SCHED_RR` 10, as `chrt -r 10`) where this
user may set one (`--no-realtime`: the normal policy); the figures' last line says which.

- `display_tick_late_p99_ms`: how late the control loop's 10 Hz tick ran (the child records
  each tick against the loop's own grid);
- `nmea_to_command_p99_ms_with_display`: writing an RMC line to the pty until the PcCommand
  carrying its speed is on the bus;
- `display_update_p95_ms`: from the control loop publishing a snapshot until the browser's
  page shows it (a MutationObserver in the page timestamps each new snapshot's publication
  mark; both clocks are this machine's wall clock);
- `display_rss_mb`: peak resident memory (VmHWM) of the whole terminal: its process and the
  display process it starts;
- `display_stale_after_kill_s`: at the end, `kill -9` of the display process until the page
  shows its full-screen stale state; `display_live_after_kill_s`: until the display the
  terminal started again serves the page and it is live again.
- `display_stop_to_command_max_ms`: the header's Stop pressed in the browser (a pointer
  event) until the PcCommand with its start bit off is on the bus, worst of three (the ECU's
  core sets the meters' duty to zero at its next 10 ms step).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from terminal_bench import WARMUP_S, Machine, terminal_toml

# The browser driver is test code (tests/browser.py), shared with the end-to-end test.
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from browser import STALE_JS, answers, chromium, display_pid, free_port, missing_browser

BROWSER_NICENESS = 10
RESTART_MARGIN_S = 20.0  # the terminal runs this much longer: the display killed and back
TERMINAL_RT_PRIORITY = 10  # `chrt -r 10`, systemd's CPUSchedulingPolicy=rr + Priority=10
STOP_TRIES = 3  # Stop pressed in the browser, at the end of the run

#: In the page: every new snapshot drawn -> (now - its publication time) in ms.
OBSERVER_JS = """
window.tdLatencies = [];
const clock = document.querySelector('[data-testid="clock"]');
new MutationObserver(() => {
  const published = parseFloat(clock.getAttribute('data-published'));
  if (published) window.tdLatencies.push(Date.now() - published * 1000);
}).observe(clock, {attributes: true, attributeFilter: ['data-published']});
return clock !== null;
"""


def _stop_times(driver: Any, m: Machine) -> list[float]:
    """Stop (the header's, pressed with a pointer as a finger does) with the meters on,
    STOP_TRIES times (Start pressed again in between): from the press until the first
    PcCommand with its start bit off is on the bus (the ECU's core takes the meters to zero
    at its next 10 ms step), in ms."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    def press(tid: str) -> float:
        button = driver.find_element(By.CSS_SELECTOR, f'[data-testid="{tid}"]')
        ActionChains(driver).move_to_element(button).perform()  # the finger over it
        t = time.perf_counter()
        ActionChains(driver, duration=0).click().perform()
        return t

    def until(start: bool, after: float) -> float | None:
        deadline = time.perf_counter() + 2.0
        while time.perf_counter() < deadline:
            seen = [t for t, s in list(m.start_changes) if s == start and t >= after]
            if seen:
                return seen[0]
            time.sleep(0.005)
        return None

    out: list[float] = []
    for _ in range(STOP_TRIES):
        running = bool(m.start_changes) and m.start_changes[-1][1]
        if not running and until(True, press("start")) is None:
            continue  # the meters did not start: nothing to stop
        time.sleep(1.0)
        pressed = press("stop")
        seen = until(False, pressed)
        if seen is not None:
            out.append((seen - pressed) * 1e3)
    return out


def _scheduling(realtime: bool) -> str:
    """The terminal's scheduling as docs/display.md sets it up, where permitted."""
    if not realtime:
        return "normal policy (--no-realtime)"
    try:
        os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(TERMINAL_RT_PRIORITY))
    except PermissionError:
        return "normal policy (a real-time one is not permitted to this user)"
    return f"SCHED_RR {TERMINAL_RT_PRIORITY}"


def child(config: Path, duration_s: float, port: int, realtime: bool) -> None:
    """The terminal as `topdress run --start` runs it, with its display and no console."""
    from topdress.cli.display import serve_display
    from topdress.config import load_config
    from topdress.devices.can import open_bus
    from topdress.devices.lines import open_line_source
    from topdress.display.options import DisplayOptions
    from topdress.log.session import SessionLog
    from topdress.terminal.app import Terminal
    from topdress.view.snapshot import TICK_S, Snapshot

    scheduling = _scheduling(realtime)  # before any thread: they inherit it
    cfg = load_config(config)
    session = SessionLog.create(cfg.log.dir, config.read_text())
    bus = open_bus(cfg.can)
    term = Terminal(cfg, open_line_source(cfg.gnss), open_line_source(cfg.crop), bus, session)
    shown = serve_display(term, DisplayOptions(port=port), lambda m: print(m, file=sys.stderr))
    late: list[float] = []
    sched: list[float] = []

    def on_tick(snapshot: Snapshot, now: float) -> None:
        shown.publish(snapshot)
        # The loop's grid: the next tick TICK_S after the last one due, or restarted after a
        # stall of a whole tick (as Terminal._loop does).
        due = sched[0] if sched else term._t0 or now  # the grid starts where the loop's did
        late.append(now - due)
        sched[:] = [due + TICK_S if now - due < TICK_S else now + TICK_S]

    term.run(duration_s, on_tick=on_tick)
    display_pid = shown.link.pid if shown.link is not None else None
    # The whole terminal: its own process and the display process it started.
    hwm = (_status_kb("VmHWM") + (_status_kb("VmHWM", display_pid) if display_pid else 0)) / 1024
    shown.stop()
    bus.shutdown()
    result = {
        "late_s": late,
        "rss_mb": hwm,
        "counters": term.snapshot.counters,
        "sched": scheduling,
    }
    print(json.dumps(result))


def _status_kb(field: str, pid: int | None = None) -> int:
    status = Path(f"/proc/{pid if pid is not None else 'self'}/status")
    for line in status.read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise RuntimeError(f"no {field} in /proc/self/status")


def _wait_http(url: str, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not answers(url):
        if time.monotonic() > deadline:
            raise RuntimeError(f"the display at {url} did not answer")
        time.sleep(0.2)


def parent(duration_s: float, realtime: bool) -> int:
    why = missing_browser()
    if why is not None:
        print(f"display bench needs a browser: {why}", file=sys.stderr)
        return 1
    group = f"239.74.{random.randrange(1, 250)}.{random.randrange(1, 250)}"
    port = free_port()
    m = Machine(group)
    with tempfile.TemporaryDirectory() as tmp:
        cfg = Path(tmp) / "terminal.toml"
        cfg.write_text(terminal_toml(m, group, tmp, "send_on_gnss = true\n"))
        for target in (m.run_ecu, m.run_spy):
            threading.Thread(target=target, daemon=True).start()
        proc = subprocess.Popen(
            [sys.executable, __file__, "--child", str(cfg), "--duration",
             str(duration_s + RESTART_MARGIN_S),
             "--port", str(port), *([] if realtime else ["--no-realtime"])],
            stdout=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        url = f"http://127.0.0.1:{port}/"
        _wait_http(url, 30.0)
        # The browser at a lower priority than the terminal, as docs/display.md sets up the
        # cab PC's kiosk browser: on 2 cores its rendering would otherwise take the CPU from
        # the control loop (the figures without: ~7-18 ms NMEA p99 on a busy machine).
        driver = chromium(Path(tmp) / "profile", niceness=BROWSER_NICENESS)
        try:
            driver.get(url)
            deadline = time.monotonic() + 20.0
            while not driver.execute_script(
                "return document.querySelector('[data-testid=\"clock\"]') !== null"
            ):
                if time.monotonic() > deadline:
                    raise RuntimeError("the main screen did not load")
                time.sleep(0.1)
            driver.execute_script(OBSERVER_JS)
            m.measure_after = time.perf_counter() + WARMUP_S
            feeders = [
                threading.Thread(target=m.run_gnss, args=(duration_s,), daemon=True),
                threading.Thread(target=m.run_crop, args=(duration_s,), daemon=True),
            ]
            for th in feeders:
                th.start()
            time.sleep(max(1.0, duration_s - 6.0 - STOP_TRIES * 3.0))
            updates_ms = list(driver.execute_script("return window.tdLatencies"))
            stops_ms = _stop_times(driver, m)
            for th in feeders:  # the latencies measured: the display killed after them
                th.join()
            stale_s, live_s = _kill_the_display(driver, proc.pid)
        finally:
            driver.quit()
        out, _ = proc.communicate(timeout=duration_s + RESTART_MARGIN_S + 60)
        m.close()
    if proc.returncode != 0:
        print(f"terminal process failed with exit code {proc.returncode}", file=sys.stderr)
        return 1
    result = json.loads(out.strip().splitlines()[-1])
    late_ms = np.array(result["late_s"][int(WARMUP_S * 10) :]) * 1e3
    lat_ms = np.array(m.latencies_s) * 1e3
    upd_ms = np.array(updates_ms[5:])  # after the page settled
    if lat_ms.size < 50 or upd_ms.size < 20:
        print(f"too few samples: {lat_ms.size} latencies, {upd_ms.size} updates", file=sys.stderr)
        return 1
    print(f"display_tick_late_p99_ms: {np.percentile(late_ms, 99):.2f}")
    print(f"nmea_to_command_p99_ms_with_display: {np.percentile(lat_ms, 99):.2f}")
    print(f"display_update_p95_ms: {np.percentile(upd_ms, 95):.1f}")
    print(f"display_rss_mb: {result['rss_mb']:.1f}")
    print(f"display_stale_after_kill_s: {stale_s:.2f}")
    print(f"display_live_after_kill_s: {live_s:.2f}")
    if stops_ms:
        print(f"display_stop_to_command_max_ms: {max(stops_ms):.1f}")
    print(
        f"# {late_ms.size} ticks (p50 late {np.percentile(late_ms, 50):.2f} ms), "
        f"{lat_ms.size} NMEA latencies (p50 {np.percentile(lat_ms, 50):.2f} ms), "
        f"{upd_ms.size} page updates (p50 {np.percentile(upd_ms, 50):.1f} ms); "
        f"Stop pressed to PcCommand start off: {[round(x, 1) for x in stops_ms]} ms; "
        f"terminal counters {result['counters']}; terminal scheduling: {result['sched']}",
        file=sys.stderr,
    )
    return 0


def _kill_the_display(driver: Any, terminal_pid: int) -> tuple[float, float]:
    """`kill -9` of the display process: (seconds until the page is stale, until it is live
    again from the display the terminal started again)."""
    first = display_pid(terminal_pid)
    if first is None:
        raise RuntimeError("no display process found")
    os.kill(first, signal.SIGKILL)
    killed = time.monotonic()
    while not driver.execute_script(STALE_JS):
        if time.monotonic() - killed > 30.0:
            raise RuntimeError("the page never showed its stale state")
        time.sleep(0.02)
    stale_s = time.monotonic() - killed
    while True:
        try:
            live = not driver.execute_script(STALE_JS) and driver.execute_script(
                "return document.querySelector('[data-testid=\"clock\"]') !== null"
            )
        except Exception:  # the page reloading from the new process
            live = False
        if live:
            return stale_s, time.monotonic() - killed
        if time.monotonic() - killed > RESTART_MARGIN_S - 2.0:
            raise RuntimeError("the page did not come back from a new display process")
        time.sleep(0.02)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=60.0, help="seconds")
    ap.add_argument("--child", type=Path, metavar="CONFIG", help=argparse.SUPPRESS)
    ap.add_argument("--port", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--no-realtime", action="store_true", help="the terminal at the normal policy")
    args = ap.parse_args()
    if args.child is not None:
        child(args.child, args.duration, args.port, not args.no_realtime)
        return 0
    return parent(args.duration, not args.no_realtime)


if __name__ == "__main__":
    sys.exit(main())
