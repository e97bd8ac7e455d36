"""`topdress sim ecu --can INTERFACE:CHANNEL`: the simulated machine alone, for a real terminal.

The ECU core and the plant (tractor, ground wheel, meters, fans, crop sensors, GNSS receiver)
run in real time as in `topdress demo`, but the CAN side is a real bus (socketcan, slcan,
udp_multicast, ...) and the GNSS and crop sensor lines go to pseudo-terminals whose names are
printed: point a terminal's configuration at them (`topdress run`, on this PC or, through a
CAN adapter, on another) and test a real set-up without writing Python.
"""

from __future__ import annotations

import argparse
import json
import re
import time
from pathlib import Path
from typing import Any

from topdress.config import default_config, load_config, loads_config
from topdress.devices.can import open_bus
from topdress.errors import ConfigError, DeviceError
from topdress.protocol import CAL_REASONS
from topdress.sim.live import LiveMachine
from topdress.sim.tractor import Drive, Segment
from topdress.sim.world import SimConfig, World

# Polled often enough that the meter has hardly turned when the start of a test is seen.
_POLL_S = 0.02
_SETTLE_S = 0.5  # the shaft coasts a little after the stop


def register(sub: Any) -> None:
    p = sub.add_parser("sim", help="the simulated machine on its own (for a real terminal)")
    ssub = p.add_subparsers(dest="sim_command", required=True, metavar="PART")
    ecu = ssub.add_parser(
        "ecu",
        help="the ECU core and plant on a real CAN bus, GNSS and crop lines on pseudo-terminals",
    )
    ecu.add_argument(
        "--can",
        required=True,
        metavar="INTERFACE:CHANNEL",
        help="python-can interface and channel, e.g. socketcan:vcan0, udp_multicast:239.0.0.1",
    )
    ecu.add_argument("--bitrate", type=int, default=250000, help="for hardware interfaces")
    ecu.add_argument(
        "--option",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="the adapter's own python-can option, as [can.options] (e.g. port=43200 for "
        "udp_multicast, tty_baudrate=115200 for slcan); repeatable",
    )
    ecu.add_argument(
        "--drive",
        choices=("field", "stand"),
        default="field",
        help="field: passes of 40 m at 8 km/h with headland turns; stand: the machine stands "
        "(calibration)",
    )
    ecu.add_argument(
        "--config",
        type=Path,
        metavar="FILE",
        help="the terminal's configuration: the simulated machine takes its geometry (crop "
        "sensors, working width, outlet offsets); default: the defaults'",
    )
    ecu.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    ecu.add_argument("--seed", type=int, default=1)
    ecu.set_defaults(func=_run)


def parse_can(text: str) -> tuple[str, str]:
    """INTERFACE:CHANNEL -> (interface, channel); the channel may hold colons itself."""
    interface, sep, channel = text.partition(":")
    if not sep or not interface or not channel:
        raise ConfigError(
            "--can", f"must be INTERFACE:CHANNEL (e.g. socketcan:vcan0), not {text!r}"
        )
    return interface, channel


def parse_options(items: list[str]) -> str:
    """KEY=VALUE items as the lines of a [can.options] table (a value that is a TOML number or
    boolean stays one, anything else is a string)."""
    lines = []
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ConfigError("--option", f"must be KEY=VALUE, not {item!r}")
        literal = value if re.fullmatch(r"-?\d+(\.\d+)?|true|false", value) else json.dumps(value)
        lines.append(f"{key} = {literal}\n")
    return "".join(lines)


def terminal_snippet(gnss: str, crop: str, interface: str, channel: str, options: str) -> str:
    """The configuration lines that point a terminal at this simulated machine."""
    q = json.dumps
    return (
        f"[gnss]\nport = {q(gnss)}\nbaud = 115200\n"
        f"[crop]\nport = {q(crop)}\nbaud = 115200\n"
        f"[can]\ninterface = {q(interface)}\nchannel = {q(channel)}\n"
        + (f"[can.options]\n{options}" if options else "")
    )


def _run(args: argparse.Namespace) -> int:
    interface, channel = parse_can(args.can)
    toml = f"[can]\ninterface = {json.dumps(interface)}\nchannel = {json.dumps(channel)}\n"
    toml += f"bitrate = {args.bitrate}\n"
    options = parse_options(args.option)
    if options:
        toml += f"[can.options]\n{options}"
    can_cfg = loads_config(toml).can
    if args.drive == "stand":
        drive = Drive([Segment("stop", duration_s=1e9)])
    else:
        drive = Drive.field_passes(30, 40.0, 8.0)
    machine_cfg = load_config(args.config) if args.config is not None else default_config()
    world = World(SimConfig.of_machine(machine_cfg), seed=args.seed, drive=drive)
    bus = open_bus(can_cfg)
    try:
        try:
            machine = LiveMachine(world, bus)
        except OSError as exc:
            raise DeviceError(f"cannot make the pseudo-terminals: {exc}") from exc
        g, c = machine.gnss_port.path, machine.crop_port.path
        print(f"topdress sim ecu: the simulated machine on CAN {interface}:{channel}")
        print(f"  GNSS NMEA (RMC, VTG, GGA at 5 Hz):  {g}")
        n = machine_cfg.crop.sensors
        print(f"  crop sensors ({n}, at 2 Hz):".ljust(38) + c)
        snippet = terminal_snippet(g, c, interface, channel, options)
        print("a terminal reaches it with:\n" + snippet)
        print("Ctrl-C stops it.", flush=True)
        machine.start()
        try:
            _watch(machine, args.duration)
        except KeyboardInterrupt:
            pass
        finally:
            machine.stop()
    finally:
        bus.shutdown()
    t = world.truth
    print(
        f"simulated machine: {t.t_s:.1f} s, {t.odometer_m:.1f} m driven, "
        f"{t.applied_kg[0] + t.applied_kg[1]:.2f} kg applied"
    )
    if machine.error is not None:
        raise DeviceError(f"the simulated machine failed: {machine.error}")
    return 0


def _watch(machine: LiveMachine, duration_s: float | None) -> None:
    """Until the duration: say what a scale would show after each catch test."""
    end = None if duration_s is None else time.monotonic() + duration_s
    world = machine.world
    start_kg: float | None = None
    while (end is None or time.monotonic() < end) and machine.error is None:
        time.sleep(_POLL_S)
        cal = world.ecu.cal_state  # read-only view; the machine thread writes it
        running = cal is not None and cal.state == "running"
        if running and start_kg is None and cal is not None:
            start_kg = world.metered_kg(cal.layer)
        elif not running and start_kg is not None:
            layer = cal.layer if cal is not None else 0
            # the shaft coasts a little after the stop: let it settle before weighing
            time.sleep(_SETTLE_S)
            kg = world.metered_kg(layer) - start_kg
            what = cal.state if cal is not None else "ended"
            if cal is not None and cal.state == "aborted":
                what += f" ({CAL_REASONS[cal.reason]})"
            print(
                f"catch test {what}: the {('upper', 'lower')[layer]} meter let out {kg:.3f} kg "
                "(what the scale shows)",
                flush=True,
            )
            start_kg = None
