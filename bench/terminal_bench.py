"""Terminal benchmark: NMEA-to-command latency and the terminal's CPU use.

    .venv/bin/python bench/terminal_bench.py [--duration 22]

This process plays the machine: it writes 10 Hz GNSS (RMC + GGA) to one pseudo-terminal and
four crop sensors at 10 Hz each to another, and runs the ECU's twin (the C core) on a
udp_multicast CAN bus. The terminal runs in a child process (`topdress run` code, send_on_gnss
enabled, session log on), exactly as in the cab. Each RMC carries a new speed; the latency is
from writing its line to the pty to receiving the PcCommand carrying that speed on the bus.
The child measures its own CPU time with time.process_time over the whole run.

Then a flood: the same terminal (commands every can.command_period_s, 0.5 s) while this
process writes RMC lines to the GNSS pty as fast as the terminal reads them, for `--flood`
seconds (40); the spy records every PcCommand on the bus, and the longest gap between two
commands after the warm-up is reported against the 1.5 x command period target.

Then ISOBUS (`--isobus` seconds, 22): the same terminal with `[can] implement = "isobus"` is the
Task Controller of an ISOBUS implement, the topdress ECU's C ISOBUS node (address claim, DDOP
upload over TP, process data) run by this process on the bus; the crop lines are steady, so the
rate changes only when the terminal decides anew. With send_on_gnss each new fix sends the rate
in force to the implement's setpoint DDI (6) at once; the latency is from writing the RMC to the
first Set Value of DDI 6 from the TC after it (counted once the implement has been connected
for a second); the CPU is the terminal process's over the whole run, TC and client connected.

Prints:
    nmea_to_command_p50_ms: X
    nmea_to_command_p99_ms: X
    terminal_cpu_pct_of_core: X
    flood_cmd_gap_max_ms: X
    nmea_to_rate_isobus_p50_ms: X
    nmea_to_rate_isobus_p99_ms: X
    terminal_cpu_pct_of_core_isobus: X
"""

from __future__ import annotations

import argparse
import collections
import itertools
import json
import random
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import can
import numpy as np

from topdress import protocol
from topdress.gnss import sentences as nmea
from topdress.sim.live import PtyPort

# The ECU's twin is test code (tests/ecu_twin.py), shared with the tests.
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from ecu_twin import SimulatedEcu

GNSS_HZ = 10.0
CROP_HZ = 10.0
SENSORS = 4
WARMUP_S = 3.0  # parameter push and first commands; latencies counted after it
# A port of this run's own: on Linux a socket bound to a port hears every group joined on it
# (IP_MULTICAST_ALL), so other udp_multicast buses on the machine would be heard at the default.
UDP_PORT = random.randrange(40000, 50000)


def udp_bus(group: str) -> can.BusABC:
    return can.Bus(interface="udp_multicast", channel=group, port=UDP_PORT, fd=False)


def child(config: Path, duration_s: float) -> None:
    """The terminal, as `topdress run` runs it, without the console; prints its CPU use."""
    from topdress.config import load_config
    from topdress.devices.can import open_bus
    from topdress.devices.lines import open_line_source
    from topdress.log.session import SessionLog
    from topdress.terminal.app import Terminal

    cfg = load_config(config)
    session = SessionLog.create(cfg.log.dir, config.read_text())
    bus = open_bus(cfg.can)
    term = Terminal(cfg, open_line_source(cfg.gnss), open_line_source(cfg.crop), bus, session)
    cpu0, wall0 = time.process_time(), time.monotonic()
    term.run(duration_s)
    cpu, wall = time.process_time() - cpu0, time.monotonic() - wall0
    bus.shutdown()
    print(json.dumps({"cpu_s": cpu, "wall_s": wall, "counters": term.snapshot.counters}))


class Machine:
    """Pty writers, the ECU twin and a command spy, in this process."""

    def __init__(self, group: str) -> None:
        self.gnss = PtyPort()
        self.crop = PtyPort()
        self.ecu_bus = udp_bus(group)
        self.spy = udp_bus(group)
        self.twin = SimulatedEcu(self.ecu_bus, now=time.monotonic())
        self.stop = threading.Event()
        self.written: dict[int, float] = {}  # speed in 0.1 km/h -> time its RMC was written
        self.latencies_s: list[float] = []
        self.measure_after = float("inf")
        self.lock = threading.Lock()
        self.command_times: list[float] = []
        self.flood_lines = 0
        self.ecu_idle = threading.Event()  # the twin is not pumping: its bus may be shut
        self.ecu_idle.set()
        # (arrival time, start bit) of each PcCommand whose start bit changed: Stop's path
        self.start_changes: list[tuple[float, bool]] = []

    def run_ecu(self) -> None:
        self.ecu_idle.clear()
        try:
            while not self.stop.wait(0.01):
                self.twin.pump(time.monotonic())
        finally:
            self.ecu_idle.set()

    def run_spy(self) -> None:
        ids = protocol.DEFAULT_IDS
        while not self.stop.is_set():
            try:
                msg = self.spy.recv(timeout=0.1)
            except OSError:  # the bus was shut down under it: the run is over
                return
            t = time.perf_counter()
            if msg is None or msg.arbitration_id != ids.command:
                continue
            cmd = protocol.decode(msg)
            assert isinstance(cmd, protocol.PcCommand)
            if not self.start_changes or self.start_changes[-1][1] != cmd.start:
                self.start_changes.append((t, cmd.start))
            if cmd.gnss_kmh is None:
                continue
            with self.lock:
                t_w = self.written.pop(round(cmd.gnss_kmh * 10), None)
            if t_w is not None and t_w >= self.measure_after:
                self.latencies_s.append(t - t_w)

    def run_command_spy(self) -> None:
        """Every PcCommand's arrival time (the flood phase)."""
        while not self.stop.is_set():
            try:
                msg = self.spy.recv(timeout=0.1)
            except OSError:  # the bus was shut down under it: the run is over
                return
            if msg is not None and msg.arbitration_id == protocol.DEFAULT_IDS.command:
                self.command_times.append(time.monotonic())

    def run_flood(self, duration_s: float) -> None:
        """RMC lines as fast as the pty takes them (its buffer blocks this writer)."""
        line = nmea.rmc("GN", 36000.0, True, 43.8853, 125.3245, 6.5 / 3.6, 90.0, "210526")
        block = line.encode() * 64
        t0 = time.monotonic()
        while not self.stop.is_set() and time.monotonic() - t0 < duration_s:
            self.gnss.write(block)
            self.flood_lines += 64

    def run_gnss(self, duration_s: float, on_write: Callable[[float], None] | None = None) -> None:
        t0 = time.monotonic()
        k = 0
        while not self.stop.is_set() and time.monotonic() - t0 < duration_s:
            k += 1
            v_kmh = 5.0 + (k % 40) / 10.0  # a new speed every epoch, 5.0..8.9 km/h
            t_utc = 36000.0 + k / GNSS_HZ
            lat, lon = 43.8853 + k * 1e-7, 125.3245
            rmc = nmea.rmc("GN", t_utc, True, lat, lon, v_kmh / 3.6, 90.0, "210526")
            gga = nmea.gga("GN", t_utc, True, lat, lon, 12, 1.1, 210.0)
            with self.lock:
                self.written[round(v_kmh * 10)] = time.perf_counter()
            if on_write is not None:
                on_write(time.perf_counter())
            self.gnss.write(rmc.encode())
            self.gnss.write(gga.encode())
            self._sleep_until(t0 + k / GNSS_HZ)

    def run_crop(self, duration_s: float, noisy: bool = True) -> None:
        t0 = time.monotonic()
        rng = random.Random(1)
        k = 0
        while not self.stop.is_set() and time.monotonic() - t0 < duration_s:
            k += 1
            lines = []
            for sid in range(1, SENSORS + 1):
                red, edge, nir = 0.04 + (rng.random() * 0.01 if noisy else 0.005), 0.21, 0.44
                ndvi = (nir - red) / (nir + red)
                lines.append(f"{sid},{red:.4f},{edge:.4f},{nir:.4f},0.3541,{ndvi:.4f}\r\n")
            self.crop.write("".join(lines).encode())
            self._sleep_until(t0 + k / CROP_HZ)

    def _sleep_until(self, t: float) -> None:
        self.stop.wait(max(0.0, t - time.monotonic()))

    def close(self) -> None:
        self.stop.set()
        self.ecu_idle.wait(1.0)  # not under the twin's feet
        self.ecu_bus.shutdown()
        self.spy.shutdown()
        self.gnss.close()
        self.crop.close()


def terminal_toml(m: Machine, group: str, log_dir: str, can_extra: str = "") -> str:
    """The terminal's configuration against this process's machine: its ptys and bus."""
    return (
        f'[gnss]\nport = "{m.gnss.path}"\nbaud = 115200\n'
        f'[crop]\nport = "{m.crop.path}"\nbaud = 115200\n'
        f'[can]\ninterface = "udp_multicast"\nchannel = "{group}"\n{can_extra}'
        f"[can.options]\nport = {UDP_PORT}\n"
        f'[log]\ndir = "{log_dir}"\n'
    )


def parent(duration_s: float) -> int:
    group = f"239.74.{random.randrange(1, 250)}.{random.randrange(1, 250)}"
    m = Machine(group)
    with tempfile.TemporaryDirectory() as tmp:
        cfg = Path(tmp) / "terminal.toml"
        cfg.write_text(terminal_toml(m, group, tmp, "send_on_gnss = true\n"))
        threads = [
            threading.Thread(target=m.run_ecu, daemon=True),
            threading.Thread(target=m.run_spy, daemon=True),
        ]
        for th in threads:
            th.start()
        proc = subprocess.Popen(
            [sys.executable, __file__, "--child", str(cfg), "--duration", str(duration_s)],
            stdout=subprocess.PIPE,
            text=True,
        )
        time.sleep(0.5)  # the child opens its ports
        m.measure_after = time.perf_counter() + WARMUP_S
        feeders = [
            threading.Thread(target=m.run_gnss, args=(duration_s,), daemon=True),
            threading.Thread(target=m.run_crop, args=(duration_s,), daemon=True),
        ]
        for th in feeders:
            th.start()
        out, _ = proc.communicate(timeout=duration_s + 60)
        m.close()
    return _figures(proc, out, m.latencies_s, ("nmea_to_command", "terminal_cpu_pct_of_core"), "")


def flood(flood_s: float) -> int:
    """The longest gap between commands while the GNSS pty is flooded."""
    group = f"239.75.{random.randrange(1, 250)}.{random.randrange(1, 250)}"
    m = Machine(group)
    period_s = 0.5
    with tempfile.TemporaryDirectory() as tmp:
        cfg = Path(tmp) / "terminal.toml"
        cfg.write_text(terminal_toml(m, group, tmp, f"command_period_s = {period_s}\n"))
        for target in (m.run_ecu, m.run_command_spy):
            threading.Thread(target=target, daemon=True).start()
        run_s = flood_s + WARMUP_S + 1.0
        proc = subprocess.Popen(
            [sys.executable, __file__, "--child", str(cfg), "--duration", str(run_s)],
            stdout=subprocess.PIPE,
            text=True,
        )
        time.sleep(WARMUP_S)  # the child opens its ports and pushes its parameters
        t_from = time.monotonic()
        writer = threading.Thread(target=m.run_flood, args=(flood_s,), daemon=True)
        writer.start()
        writer.join(flood_s + 5.0)
        t_to = time.monotonic()
        out, _ = proc.communicate(timeout=run_s + 60)
        m.close()
    if proc.returncode != 0:
        print(f"terminal process failed with exit code {proc.returncode}", file=sys.stderr)
        return 1
    counters = json.loads(out.strip().splitlines()[-1])["counters"]
    sent = [t for t in m.command_times if t_from <= t <= t_to]
    # The window's ends count as bounds: a terminal that stops sending shows as one long gap.
    times = [t_from, *sent, t_to]
    gap_ms = max(b - a for a, b in itertools.pairwise(times)) * 1e3
    print(f"flood_cmd_gap_max_ms: {gap_ms:.1f}")
    print(
        f"# target <= {1.5 * period_s * 1e3:.0f} (1.5 x command period); {len(sent)} commands "
        f"in {t_to - t_from:.1f} s of flood, {m.flood_lines} lines written; terminal counters "
        f"{counters}",
        file=sys.stderr,
    )
    return 0


class IsobusImplement:
    """The topdress ECU's ISOBUS node on the bus (its C layer through cffi), stepped every
    10 ms, and a spy on the TC's Set Value frames of DDI 6; the RMC write times for the
    latency."""

    def __init__(self, group: str) -> None:
        from topdress.isobus.node import IsobusNode, topdress_name

        self.bus = udp_bus(group)
        self.spy_bus = udp_bus(group)
        # Not the terminal's [isobus] ecu_manufacturer (0): the node alone has no core to
        # answer the topdress ECU's private frames, so it is served as any ISOBUS implement.
        self.node = IsobusNode(topdress_name(1, b"bench"), tc_timeout_ms=3000)
        self.stop = threading.Event()
        self.lock = threading.Lock()
        self.writes: list[float] = []  # RMC write times not yet matched
        self.latencies_s: list[float] = []
        self.first_rate_t: float | None = None
        self.echo: collections.deque[tuple[int, bytes]] = collections.deque(maxlen=512)

    def wrote(self, t: float) -> None:
        with self.lock:
            self.writes.append(t)

    def run(self) -> None:
        t0 = time.monotonic()
        self.node.start(1)
        next_step = 0.0
        while not self.stop.is_set():
            try:
                msg = self.bus.recv(timeout=0.002)
            except OSError:
                return
            now = time.monotonic() - t0
            if msg is not None and msg.is_extended_id:
                key = (msg.arbitration_id, bytes(msg.data))
                if key in self.echo:
                    self.echo.remove(key)  # our own frame looped back
                else:
                    self.node.rx(msg.arbitration_id, bytes(msg.data), round(now * 1e6) + 1)
            if now >= next_step:
                next_step = now + 0.01
                self.node.step(round(now * 1e6) + 1, 0)
            for f in self.node.tx():
                self.echo.append((f.can_id, f.data))
                self.bus.send(can.Message(arbitration_id=f.can_id, data=f.data))

    def run_spy(self) -> None:
        """The TC's frames as they arrive, on a socket of its own (the node's thread steps
        and sends besides: its receive times would be late)."""
        while not self.stop.is_set():
            try:
                msg = self.spy_bus.recv(timeout=0.1)
            except OSError:
                return
            if msg is not None:
                self._spy(msg, time.perf_counter())

    def _spy(self, msg: can.Message, t: float) -> None:
        d = bytes(msg.data)
        pgn, sa = (msg.arbitration_id >> 8) & 0x3FF00, msg.arbitration_id & 0xFF
        if pgn != 0xCB00 or sa != 0xF7 or len(d) != 8 or d[0] & 0x0F not in (3, 10):
            return
        if d[2] | d[3] << 8 != 6:  # DDI 6: setpoint mass per area
            return
        if self.first_rate_t is None:
            self.first_rate_t = t
        with self.lock:
            before = [w for w in self.writes if w <= t]
            if before and t - self.first_rate_t > 1.0:
                self.latencies_s.append(t - before[-1])
            self.writes = [w for w in self.writes if w > t]

    def close(self) -> None:
        self.stop.set()
        time.sleep(0.15)
        self.bus.shutdown()
        self.spy_bus.shutdown()


def isobus(duration_s: float) -> int:
    """NMEA -> rate on the bus with the implement connected, and the terminal's CPU."""
    group = f"239.76.{random.randrange(1, 250)}.{random.randrange(1, 250)}"
    m = Machine(group)
    implement = IsobusImplement(group)
    with tempfile.TemporaryDirectory() as tmp:
        cfg = Path(tmp) / "terminal.toml"
        extra = 'send_on_gnss = true\nimplement = "isobus"\n'
        cfg.write_text(terminal_toml(m, group, tmp, extra))
        threading.Thread(target=implement.run, daemon=True).start()
        threading.Thread(target=implement.run_spy, daemon=True).start()
        proc = subprocess.Popen(
            [sys.executable, __file__, "--child", str(cfg), "--duration", str(duration_s)],
            stdout=subprocess.PIPE,
            text=True,
        )
        time.sleep(0.5)  # the child opens its ports
        feeders = [
            threading.Thread(target=m.run_gnss, args=(duration_s, implement.wrote), daemon=True),
            threading.Thread(target=m.run_crop, args=(duration_s, False), daemon=True),
        ]
        for th in feeders:
            th.start()
        out, _ = proc.communicate(timeout=duration_s + 60)
        implement.close()
        m.close()
    names = ("nmea_to_rate_isobus", "terminal_cpu_pct_of_core_isobus")
    return _figures(
        proc, out, implement.latencies_s, names, f"implement {implement.node.tc_state}; "
    )


def _figures(
    proc: subprocess.Popen[str],
    out: str,
    latencies_s: list[float],
    names: tuple[str, str],
    said: str,
) -> int:
    """The run's latency percentiles and the terminal's CPU share as figures `names`; 1 when
    the terminal failed or too few latencies were measured."""
    if proc.returncode != 0:
        print(f"terminal process failed with exit code {proc.returncode}", file=sys.stderr)
        return 1
    result = json.loads(out.strip().splitlines()[-1])
    lat_ms = np.array(latencies_s) * 1e3
    if lat_ms.size < 50:
        print(f"only {lat_ms.size} latencies measured ({names[0]})", file=sys.stderr)
        return 1
    print(f"{names[0]}_p50_ms: {np.percentile(lat_ms, 50):.2f}")
    print(f"{names[0]}_p99_ms: {np.percentile(lat_ms, 99):.2f}")
    print(f"{names[1]}: {100.0 * result['cpu_s'] / result['wall_s']:.2f}")
    print(
        f"# {lat_ms.size} latencies; {said}terminal counters {result['counters']}", file=sys.stderr
    )
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=22.0, help="seconds (>= 20 for the CPU)")
    ap.add_argument("--flood", type=float, default=40.0, help="seconds of GNSS flood (0: none)")
    ap.add_argument("--isobus", type=float, default=22.0, help="seconds of ISOBUS (0: none)")
    ap.add_argument("--child", type=Path, metavar="CONFIG", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child is not None:
        child(args.child, args.duration)
        return 0
    rc = parent(args.duration) if args.duration > 0 else 0
    if args.flood > 0:
        rc = max(rc, flood(args.flood))
    if args.isobus > 0:
        rc = max(rc, isobus(args.isobus))
    return rc


if __name__ == "__main__":
    sys.exit(main())
