"""`topdress demo` and `topdress run`: the terminal against the simulated or the real machine.

The demo is the real terminal, unchanged, against the simulated machine of `topdress.sim.live`:
NMEA and crop sensor lines through pseudo-terminals opened with pyserial, the ECU on a
python-can virtual bus, the World paced to the wall clock in another thread. The ECU is the C
core in-process (`ecu="host"`) or the STM32F4 firmware image in QEMU (`ecu="qemu"`, stepped in
lockstep with the World by `topdress.sim.qemu_ecu`): the terminal cannot tell them apart but by
the ECU's EcuIdent. Only the configuration is embedded (ports and bus point at the simulation).
"""

from __future__ import annotations

import json
import logging
import os
import sys
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import tomlkit

from topdress import i18n
from topdress.config import TerminalConfig, default_config, loads_config, redacted_text
from topdress.devices.can import open_bus
from topdress.devices.lines import open_line_source
from topdress.display.console import Console
from topdress.display.keyboard import KeyboardCommands
from topdress.errors import ConfigError, DeviceError
from topdress.log.session import SessionLog
from topdress.sim.live import LiveMachine
from topdress.sim.qemu_ecu import QemuEcu, QemuOptions, QemuWorld, ensure_image, qemu_missing
from topdress.sim.tractor import Drive
from topdress.sim.world import SimConfig, World
from topdress.terminal.app import Terminal
from topdress.terminal.site import load_maps
from topdress.view.commands import CONSOLE_HELP
from topdress.view.snapshot import Snapshot

if TYPE_CHECKING:
    from topdress.display.options import DisplayOptions

log = logging.getLogger(__name__)

#: The demo's field work: passes of 40 m at 8 km/h (GNSS territory in uniform motion) with a
#: stop and a turn at each headland (wheel territory), as many as any sensible duration needs.
DEMO_PASSES = 30
DEMO_PASS_M = 40.0
DEMO_SPEED_KMH = 8.0
#: The ECUs the demo can run: the core in-process, or the firmware image in QEMU.
ECUS = ("host", "qemu")


def demo_config_toml(
    gnss_port: str, crop_port: str, channel: str, log_dir: Path, user_text: str = ""
) -> str:
    """The demo's configuration: the user's file (`topdress demo --config`), or the defaults,
    with ports and bus pointing at the simulation and the session logs in `log_dir`."""
    if user_text:
        return _user_config_toml(user_text, gnss_port, crop_port, channel, log_dir)
    q = _toml_str
    return (
        "# topdress demo: the terminal's defaults, wired to the simulated machine\n"
        f'[gnss]\nsource = "serial"\nport = {q(gnss_port)}\nbaud = 115200\n'
        f'[crop]\nsource = "serial"\nport = {q(crop_port)}\nbaud = 115200\n'
        f'[can]\ninterface = "virtual"\nchannel = {q(channel)}\n'
        f"[log]\ndir = {q(str(log_dir))}\n"
    )


def _user_config_toml(
    text: str, gnss_port: str, crop_port: str, channel: str, log_dir: Path
) -> str:
    """The user's file, comments kept, with its devices replaced by the simulation's: the line
    sources on the simulated machine's pseudo-terminals, CAN on its bus (the simulated ECU
    answers on the DBC's identifiers, with no adapter options), the logs in `log_dir`."""
    doc = tomlkit.parse(text)
    for section, port in (("gnss", gnss_port), ("crop", crop_port)):
        table = _table(doc, section)
        table["source"], table["port"], table["baud"] = "serial", port, 115200
    can_table = _table(doc, "can")
    can_table["interface"], can_table["channel"] = "virtual", channel
    for whole in ("ids", "options"):
        can_table.pop(whole, None)
    _table(doc, "log")["dir"] = str(log_dir)
    return "# topdress demo: your configuration, wired to the simulated machine\n" + tomlkit.dumps(
        doc
    )


def _table(doc: Any, name: str) -> Any:
    if name not in doc:
        doc[name] = tomlkit.table()
    return doc[name]


def _toml_str(text: str) -> str:
    # A JSON string is a TOML basic string: quotes and backslashes in a path stay intact.
    # Not ASCII-escaped: JSON writes an emoji as a surrogate pair, which TOML refuses.
    return json.dumps(text, ensure_ascii=False)


def _check_out_dir(out_dir: Path) -> None:
    """The log directory goes into a TOML file, which holds text only: a path with bytes that
    are not UTF-8 (kept by Python as lone surrogates) cannot be written there."""
    try:
        str(out_dir).encode("utf-8")
    except UnicodeEncodeError:
        shown = str(out_dir).encode("utf-8", "backslashreplace").decode("ascii", "replace")
        raise ConfigError(
            "--out", f"{shown}: the path has bytes that are not UTF-8; choose another directory"
        ) from None


@dataclass(frozen=True)
class RunResult:
    session_path: Path | None  # None when the log could not be written
    ticks: int
    last: Snapshot
    ecu_ready: bool  # the ECU acknowledged every parameter: the terminal could work


def run_terminal(
    cfg: TerminalConfig,
    config_toml: str,
    duration_s: float | None,
    out: TextIO,
    machine: LiveMachine | None = None,
    start: bool = True,
    config_path: Path | None = None,
    keyboard: TextIO | None = None,
    display: DisplayOptions | None = None,
    watch: Callable[[Snapshot, float], None] | None = None,
) -> RunResult:
    """Open the devices of `cfg`, run the terminal with a live console, report where data went.

    `start`: the meters start at once; else at the operator's start (typed on `keyboard`, or
    from the display). `config_path`: where settings changed while running are saved.
    `watch(snapshot, now)`: also called each tick (a demo's own lines)."""
    # The console speaks the configured language even without the display, which may switch it.
    i18n.set_language(cfg.display.language)
    console = Console(out, period_s=cfg.display.refresh_s)
    if cfg.can.interface == "virtual" and machine is None:
        console.message(
            'warning: can.interface = "virtual" is the simulator\'s in-process bus: no ECU can '
            "answer there (set [can] interface and channel, e.g. socketcan can0)"
        )
    # The maps first: a prescription or boundary that cannot be used stops here, before any
    # device is opened or a session file made; what was loaded is said.
    maps = load_maps(cfg, console.message)
    for line in maps.describe():
        console.message(line)
    # Devices next: one that cannot be opened stops here, before a session file is made.
    bus = open_bus(cfg.can)
    try:
        gnss, crop = open_line_source(cfg.gnss), open_line_source(cfg.crop)
    except DeviceError:
        bus.shutdown()
        raise
    session = SessionLog.create(  # never the PIN
        cfg.log.dir,
        redacted_text(config_toml),
        min_free_bytes=round(cfg.log.min_free_mib * 1024 * 1024),
    )
    opened = session.ok  # `ok` turns False once closed
    if not opened:
        console.message(f"warning: session log not written: {session.last_error}")
    term = Terminal(
        cfg,
        gnss,
        crop,
        bus,
        session,
        start=start,
        on_event=console.message,
        config_path=config_path,
        maps=maps,
    )
    office = None
    if cfg.office.url:  # the cab sends its sessions to the farm office by itself
        from topdress.office.autosync import OfficeSync

        office = OfficeSync(cfg.office, cfg.log.dir, on_message=console.message)
        office.start()
    shown = None
    if display is not None:  # the web display beside the console (topdress.display)
        from topdress.cli.display import serve_display

        shown = serve_display(term, display, console.message)
    if keyboard is not None:
        KeyboardCommands(term.post, keyboard, console.message).start()
    if not start:
        console.message(
            "meters stopped until the operator starts them (type start, or the display)"
        )
        if keyboard is not None:
            console.message(CONSOLE_HELP)
    rows = 0

    def on_tick(snapshot: Snapshot, now: float) -> None:
        nonlocal rows
        rows += 1
        console.update(snapshot, now)
        if shown is not None:
            shown.publish(snapshot)
        if watch is not None:
            watch(snapshot, now)
        if machine is not None and machine.error is not None:
            raise DeviceError(f"the simulated machine failed: {machine.error}")

    path = session.path if opened else None
    try:
        term.run(duration_s, on_tick=on_tick)
    except KeyboardInterrupt as exc:
        console.message(f"stopped by {exc}" if exc.args else "stopped by the operator (Ctrl-C)")
    finally:
        # Also after an error: the operator needs to know where the data went.
        if shown is not None:
            shown.stop()
        if office is not None:
            office.stop()
        term.port.stop()  # the bus in use (after a [can] change, not the one opened here)
        console.draw(term.snapshot)
        if not term.can.ready:
            out.write(
                f"the ECU never acknowledged its parameters on CAN {term.link.where}: "
                "nothing was metered\n"
                if term.can.tc is None
                else f"no ISOBUS implement activated its DDOP on CAN {term.link.where}: "
                "nothing was metered\n"
            )
        _report(out, path, session.errors + session.dropped + session.lost)
    return RunResult(path, rows, term.snapshot, term.can.ready)


def _report(out: TextIO, path: Path | None, errors: int) -> None:
    if path is None:
        out.write("no session log was written (see the warning above)\n")
        return
    out.write(
        f"\nsession log: {path}"
        + (f"  ({errors} write errors or rows lost)" if errors else "")
        + "\n"
        + f"  summary:  topdress log summary {path}\n"
        + f"  export:   topdress log export {path} --events events.ndjson --csv state.csv\n"
        + "  replay:   topdress replay events.ndjson --speed-mode fused --out replay.csv\n"
    )
    out.flush()


def run_demo(
    duration_s: float | None,
    out_dir: Path,
    seed: int = 1,
    out: TextIO | None = None,
    start: bool = True,
    keyboard: TextIO | None = None,
    display: DisplayOptions | None = None,
    passes: int = DEMO_PASSES,
    user_text: str = "",
    ecu: str = "host",
) -> int:
    """The simulated machine in a thread, the terminal in front of it; returns the exit code.

    `user_text`: the user's configuration (`--config FILE`; "" the defaults): the terminal runs
    with it, and the simulated machine has its geometry (crop sensors, working width, outlet
    offsets). The demo's configuration is written to `out_dir/topdress-demo.toml`, where
    settings changed while it runs are saved (never into the user's file). `ecu`: "host" (the
    core in-process) or "qemu" (the firmware image in the emulator, built first if need be)."""
    out = out if out is not None else sys.stdout  # the stdout of the call, not of the import
    _check_out_dir(out_dir)
    if ecu not in ECUS:
        raise ConfigError("--ecu", f"{ecu!r}: one of {', '.join(ECUS)}")
    machine_cfg = loads_config(user_text, "--config") if user_text else default_config()
    drive = Drive.field_passes(passes, DEMO_PASS_M, DEMO_SPEED_KMH)
    sim_cfg = SimConfig.of_machine(machine_cfg)
    with ExitStack() as stack:
        if ecu == "qemu":
            world: World = _qemu_world(stack, out, sim_cfg, seed, drive)
        else:
            world = World(sim_cfg, seed=seed, drive=drive)
        _run_machine(world, duration_s, out_dir, out, start, keyboard, display, user_text)
    return 0


def _qemu_world(
    stack: ExitStack, out: TextIO, cfg: SimConfig, seed: int, drive: Drive
) -> QemuWorld:
    """The firmware image booted in QEMU (closed with `stack`), in lockstep with a World."""
    why = qemu_missing()
    if why is not None:
        raise DeviceError(f"--ecu qemu: {why}")
    image = ensure_image()
    qemu = stack.enter_context(QemuEcu(QemuOptions(image=image)))
    out.write(f"topdress demo: ECU firmware {image} in {' '.join(qemu.command[:3])}\n")
    return QemuWorld(qemu, cfg, seed=seed, drive=drive)


def _run_machine(
    world: World,
    duration_s: float | None,
    out_dir: Path,
    out: TextIO,
    start: bool,
    keyboard: TextIO | None,
    display: DisplayOptions | None,
    user_text: str,
) -> None:
    """The World live on its ptys and a virtual bus, the terminal in front of it."""
    channel = f"topdress-demo-{os.getpid()}"
    sim_bus = open_bus(loads_config(f'[can]\nchannel = "{channel}"\n').can)
    try:
        machine = LiveMachine(world, sim_bus)
    except OSError as exc:
        sim_bus.shutdown()
        raise DeviceError(f"cannot make the simulated machine's pseudo-terminals: {exc}") from exc
    try:
        text = demo_config_toml(
            machine.gnss_port.path, machine.crop_port.path, channel, out_dir, user_text
        )
        cfg = loads_config(text)
        config_path = out_dir / "topdress-demo.toml"
        out_dir.mkdir(parents=True, exist_ok=True)
        config_path.write_text(text, encoding="utf-8")
        out.write(
            f"topdress demo: simulated machine on {machine.gnss_port.path} (GNSS NMEA), "
            f"{machine.crop_port.path} (crop sensors), CAN virtual:{channel}\n"
        )
        machine.start()
        run_terminal(cfg, text, duration_s, out, machine, start, config_path, keyboard, display)
    finally:
        machine.stop()
        sim_bus.shutdown()
    truth = world.truth
    out.write(
        f"simulated machine: {truth.t_s:.1f} s, {truth.odometer_m:.1f} m driven, "
        f"{truth.applied_kg[0] + truth.applied_kg[1]:.2f} kg applied"
        + "".join(f", {k} {v}" for k, v in sorted(machine.counters.items()) if v)
        + "\n"
    )
