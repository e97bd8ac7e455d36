"""The CAN adapter in the field, measured: a USB-CAN adapter (python-can's real `slcan` on an
emulated adapter behind a pty, tests/slcan_twin.py) pulled for 5 s and plugged back, and the
`[can]` settings applied while running. Prints how long after its return the first command went
out again, and the longest command period while a new bus opened.

    .venv/bin/python bench/can_bench.py        # about 40 s
"""

from __future__ import annotations

import itertools
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

# The adapter's and the ECU's twins are test code, shared with the tests.
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from slcan_twin import EcuOnChannel, LiveTerminal, SlcanAdapter
from topdress.config import TerminalConfig, default_config
from topdress.view import commands as op

PULLED_S = 5.0


def _config(channel: str, **slcan: object) -> TerminalConfig:
    cfg = default_config()
    can_cfg = replace(cfg.can, channel=channel)
    if slcan:
        options = {k: v for k, v in slcan.items() if k != "path"}
        can_cfg = replace(can_cfg, interface="slcan", channel=str(slcan["path"]), options=options)
    return replace(cfg, can=can_cfg)


def _until(cond: object, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond() and time.monotonic() < deadline:  # type: ignore[operator]
        time.sleep(0.01)


def pulled(tmp: Path, sleep_after_open: float | None) -> float:
    """Seconds from the adapter's return to the first command sent through it."""
    channel = f"bench-can-pulled-{sleep_after_open}"
    link = tmp / f"usb-slcan-{sleep_after_open}"
    adapter, ecu = SlcanAdapter(link, channel), EcuOnChannel(channel)
    options = {} if sleep_after_open is None else {"sleep_after_open": sleep_after_open}
    opening = 2.0 if sleep_after_open is None else sleep_after_open
    live = LiveTerminal(_config(channel, path=link, **options), tmp / "logs")
    try:
        _until(lambda: live.term.snapshot.ecu_link == "ok", 8.0)
        time.sleep(1.0)
        adapter.pull()
        time.sleep(PULLED_S)
        adapter.plug()
        t_plug = time.monotonic()
        time.sleep(opening + 1.5)
    finally:
        live.join()
        adapter.close()
        ecu.close()
    back = [t for t in live.commands() if t > t_plug]
    return back[0] - t_plug if back else float("nan")


def applied(tmp: Path) -> tuple[float, float, int, int]:
    """The longest command period and state-row period (the loop's tick) while [can] moved to
    an slcan adapter (python-can's 2 s wait on open), the ECU's command-timeout steps, and how
    often the process could not run for 50 ms (a loaded machine)."""
    channel = "bench-can-apply"
    link = tmp / "usb-slcan-apply"
    adapter, ecu = SlcanAdapter(link, channel), EcuOnChannel(channel)
    live = LiveTerminal(_config(channel), tmp / "logs")
    try:
        _until(lambda: live.term.snapshot.ecu_link == "ok", 8.0)
        time.sleep(1.0)
        fut = live.term.post(op.ApplySettings("can", {"interface": "slcan", "channel": str(link)}))
        result = fut.result(timeout=20.0)
        assert result.ok, result.message
        time.sleep(1.5)
    finally:
        live.join()
        adapter.close()
        ecu.close()
    cmd = max(b - a for a, b in itertools.pairwise(live.commands()))
    tick = max(b - a for a, b in itertools.pairwise(live.state_times()))
    return cmd, tick, ecu.timeouts, len(live.stalls)


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        fast = pulled(Path(tmp), 0.05)
        slow = pulled(Path(tmp), None)
        cmd, tick, timeouts, stalls = applied(Path(tmp))
    print(f"can_pulled_{PULLED_S:.0f}s_back_after_return_s (sleep_after_open 0.05): {fast:.2f}")
    print(f"can_pulled_{PULLED_S:.0f}s_back_default_sleep_s (python-can's 2 s): {slow:.2f}")
    print(f"can_apply_cmd_period_max_s: {cmd:.3f}  (target <= 0.6)")
    print(f"can_apply_tick_period_max_s: {tick:.3f}")
    print(f"can_apply_ecu_cmd_timeout_steps: {timeouts}")
    print(f"process_stalls_over_50ms: {stalls}  (the machine's load, not the loop)")


if __name__ == "__main__":
    main()
