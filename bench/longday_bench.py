"""Long-day benchmark: a generated 12 h session through the log commands, time and memory.

    .venv/bin/python bench/longday_bench.py [--hours 12] [--keep DIR]

The session is written with the session writer itself (`SessionLog`), not by simulating 12 h:
the simulator drives two 100 m passes at 8 km/h with a turn (about two minutes, every raw
input and a 10 Hz state row, as the terminal logs them), and that piece is logged again and
again, shifted in time, until the day is full; the ECU's wheel pulse counter in each EcuDiag
frame and the UTC of each state row go on counting, so the day reads as one drive.

Each command then runs as its own process (`topdress log export --events`, `topdress replay`,
the map exports `--format gpkg`, `shp`, `geojson`, `isoxml`, and `log map --out X.html`); its
wall and CPU time and its peak resident memory (the process's ru_maxrss) are printed per log
hour, and for the events export and replay the speed as a multiple of real time, on the wall
clock and (beside it, the figure to compare on a shared machine) on the process's CPU time.
Targets (issue 22): events export and replay at least 800x real time; every command at most
300 MB peak for a 12 h session (the map exports read the session in chunks: their memory is a
base of about 110 MB, imports, plus some 13 MB per log hour of numbers).

Prints, per command:
    <command>_s_per_log_hour: X  (CPU X)
    <command>_mb_per_log_hour: X  (peak X MB, target <= 300)
    <command>_x_real_time: X  (CPU X, target >= 800)      (events export and replay)

`--only events_export,replay` runs only those commands; `--session FILE` uses a session
generated before (with `--keep DIR`: DIR/longday.sqlite) instead of writing one.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from topdress import protocol
from topdress.config import default_config
from topdress.geo.outlet import OutletTracker
from topdress.gnss.nmea import NmeaDecoder
from topdress.gnss.tracker import GnssSpeedTracker
from topdress.gnss.utc import UtcClock
from topdress.log.model import StateRow
from topdress.log.session import SessionLog
from topdress.sim.tractor import Drive
from topdress.sim.world import SimConfig, World
from topdress.view.snapshot import ecu_values

RATE = (180.0, 150.0)
DIAG_ID = protocol.DEFAULT_IDS.diag
PULSES_MOD = 1 << 24

Item = tuple[str, float, object]  # ("nmea"|"crop"|"can_rx"|"can_tx"|"state", t, payload)


def record_piece() -> tuple[list[Item], float, int]:
    """Two passes with a turn, as the terminal logs them: (items, duration s, wheel pulses)."""
    cfg = default_config()
    world = World(SimConfig(), seed=7, drive=Drive.field_passes(2, 100.0, 8.0))
    decoder = NmeaDecoder()
    tracker = GnssSpeedTracker(cfg.gnss.rmc_timeout_s, cfg.gnss.stale_s)
    utc = UtcClock()
    outlet = OutletTracker(cfg.machine.outlet_along_m, cfg.machine.outlet_across_m)
    odometer_m = 0.0  # the selected speed integrated at 10 Hz, as the terminal's odometer
    latest: dict[type, object] = {}
    items: list[Item] = []
    pulses: list[int] = []
    n = 0
    while not world.drive.finished:
        out = world.step()
        t = out.t_s
        for frame in out.can:
            items.append(("can_rx", t, frame))
            decoded = protocol.decode(frame)
            latest[type(decoded)] = decoded
            if isinstance(decoded, protocol.EcuDiag):
                pulses.append(decoded.wheel_pulses)
        for line in out.nmea:
            items.append(("nmea", t, line))
            fix = decoder.decode(line)
            tracker.update(t, fix)
            if fix.ok and fix.fix_valid:
                utc.on_fix(t, fix.utc)
                outlet.on_fix(fix.lat, fix.lon, fix.course_deg, fix.speed_kmh, odometer_m)
        for line in out.crop:
            items.append(("crop", t, line))
        if n % 50 == 0 or n % 10 == 0:  # a command every 0.5 s and on each fix (10 Hz)
            msg = protocol.encode_command(True, 3000, *RATE, tracker.current(t))
            items.append(("can_tx", t, (msg.arbitration_id, bytes(msg.data))))
            world.deliver_can(msg)
        if n % 10 == 9:
            pos = tracker.position
            ecu = ecu_values(
                latest.get(protocol.EcuStatus),  # type: ignore[arg-type]
                latest.get(protocol.EcuDiag),  # type: ignore[arg-type]
                latest.get(protocol.EcuSpeeds),  # type: ignore[arg-type]
                latest.get(protocol.EcuTargets),  # type: ignore[arg-type]
            )
            odometer_m += ecu["v_kmh"] / 3.6 * 0.1
            here = outlet.position(odometer_m)
            now_utc = utc.now(t)
            row = StateRow(
                t=t,
                lat=None if pos is None else pos.lat,
                lon=None if pos is None else pos.lon,
                v_gnss_kmh=ecu["v_gnss_kmh"],
                v_wheel_kmh=ecu["v_wheel_kmh"],
                v_kmh=ecu["v_kmh"],
                source=ecu["source"],
                cv_pct=ecu["cv_pct"],
                ndvi=None,
                rate_kg_ha_upper=RATE[0],
                rate_kg_ha_lower=RATE[1],
                target_rpm_upper=ecu["target_rpm"][0],
                target_rpm_lower=ecu["target_rpm"][1],
                meter_rpm_upper=ecu["meter_rpm"][0],
                meter_rpm_lower=ecu["meter_rpm"][1],
                fan_rpm_upper=ecu["fan_rpm"][0],
                fan_rpm_lower=ecu["fan_rpm"][1],
                faults=ecu["faults"],
                utc=None if now_utc is None else now_utc[0],
                utc_source=None if now_utc is None else now_utc[1],
                heading_deg=None if here is None else here.heading_deg,
                outlet_lat=None if here is None else here.lat,
                outlet_lon=None if here is None else here.lon,
            )
            items.append(("state", t, row))
        n += 1
    duration = (n // 10) * 0.1  # a whole number of 10 Hz rows, so pieces join on the grid
    return items, duration, (pulses[-1] - pulses[0]) % PULSES_MOD


def _shift_diag(data: bytes, add: int) -> bytes:
    # WheelPulses: 24 bits little-endian from bit 40 (bytes 5..7)
    value = (int.from_bytes(data[5:8], "little") + add) % PULSES_MOD
    return data[:5] + value.to_bytes(3, "little")


def write_day(directory: Path, hours: float) -> Path:
    """A session of `hours` hours, written with SessionLog: the piece logged again and again."""
    items, duration, pulses = record_piece()
    total_s = hours * 3600.0
    log = SessionLog.create(directory, "", name="longday", queue_size=400_000)
    k = 0
    t0 = 1000.0  # the terminal's monotonic clock at the start
    while k * duration < total_s:
        shift = t0 + k * duration
        add = k * pulses
        for kind, t, payload in items:
            if kind == "state":
                assert isinstance(payload, StateRow)
                row_utc = None if payload.utc is None else payload.utc + k * duration
                log.state(replace(payload, t=t + shift, utc=row_utc))
            elif kind == "can_rx" and payload[0] == DIAG_ID:  # type: ignore[index]
                can_id, data = payload  # type: ignore[misc]
                log.raw(kind, t + shift, (can_id, _shift_diag(data, add)))
            else:
                log.raw(kind, t + shift, payload)
        log.sync(60.0)
        k += 1
    log.close()
    if log.dropped or log.lost or log.errors:
        sys.exit(f"generating the session lost rows: {log.dropped} {log.lost} {log.errors}")
    return log.path


def run(label: str, argv: list[str], hours: float, rate: bool, only: set[str] | None) -> None:
    """Run one command as its own process; print its time and peak memory per log hour."""
    if only is not None and label not in only:
        return
    start = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-m", "topdress.cli", *argv],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    err = proc.stderr.read().decode() if proc.stderr else ""
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        print(f"{label}: exit {proc.returncode}: {err.strip()}", file=sys.stderr)
        return
    mb = usage.ru_maxrss / 1024.0
    cpu = usage.ru_utime + usage.ru_stime
    print(f"{label}_s_per_log_hour: {wall / hours:.2f}  (CPU {cpu / hours:.2f})")
    print(f"{label}_mb_per_log_hour: {mb / hours:.1f}  (peak {mb:.0f} MB, target <= 300)")
    if rate:
        print(
            f"{label}_x_real_time: {hours * 3600.0 / wall:.0f}  "
            f"(CPU {hours * 3600.0 / cpu:.0f}, target >= 800)"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=12.0)
    parser.add_argument("--keep", type=Path, help="write the session and outputs here")
    parser.add_argument("--session", type=Path, help="a session generated before (its hours)")
    parser.add_argument("--only", help="comma-separated commands to run (default: all)")
    parser.add_argument("--skip-maps", action="store_true", help="only events export, replay")
    args = parser.parse_args()
    only = set(args.only.split(",")) if args.only else None
    if args.skip_maps:
        only = (only or {"events_export", "replay"}) & {"events_export", "replay"}
    with tempfile.TemporaryDirectory(prefix="topdress-longday-") as tmp:
        where = args.keep or Path(tmp)
        where.mkdir(parents=True, exist_ok=True)
        start = time.perf_counter()
        if args.session is not None:
            session = args.session
        else:
            session = write_day(where, args.hours)
            print(f"session: {args.hours:g} h generated in {time.perf_counter() - start:.1f} s")
        size = session.stat().st_size / 1e6
        print(f"session_mb_per_log_hour: {size / args.hours:.1f}")
        h = args.hours
        events = where / "events.ndjson"
        run(
            "events_export", ["log", "export", str(session), "--events", str(events)], h, True, only
        )
        if only is None or "replay" in only:
            if not events.exists():
                run(
                    "events_export",
                    ["log", "export", str(session), "--events", str(events)],
                    h,
                    True,
                    None,
                )
            replay = ["replay", str(events), "--out", str(where / "replay.csv")]
            run("replay", replay, h, True, only)
        for fmt in ("gpkg", "shp", "geojson", "isoxml"):
            out = where / (f"map.{fmt}" if fmt != "isoxml" else "taskdata")
            argv = ["log", "export", str(session), "--out", str(out), "--format", fmt]
            run(f"export_{fmt}", argv, h, False, only)
        html = ["log", "map", str(session), "--out", str(where / "map.html")]
        run("map_html", html, h, False, only)


if __name__ == "__main__":
    main()
