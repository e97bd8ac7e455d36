"""`topdress config init FILE` and `topdress config check FILE`: set-up from nothing.

`init` writes the commented default file with what this machine has filled in where it can:
the serial ports pyserial lists (the first two become the GNSS and crop sensor ports, the
others are named in a comment) and a SocketCAN interface when the kernel has one (else the
simulator's `virtual` bus, said so in a comment). `check` loads a file with every check of
`topdress run` and says what it would open.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import tomlkit

from topdress.config import DEFAULT_TOML, LOCAL_HOSTS, TerminalConfig, load_config
from topdress.errors import ConfigError

SYS_NET = Path("/sys/class/net")
ARPHRD_CAN = 280  # the link type of a CAN network interface (linux/if_arp.h)


def register(sub: Any) -> None:
    p = sub.add_parser("config", help="write or check a terminal configuration file")
    csub = p.add_subparsers(dest="config_command", required=True, metavar="ACTION")
    init = csub.add_parser(
        "init", help="write a commented configuration with this machine's ports filled in"
    )
    init.add_argument("file", type=Path, metavar="FILE")
    init.add_argument("--force", action="store_true", help="replace an existing file")
    init.set_defaults(func=_init)
    check = csub.add_parser("check", help="check a configuration file as `topdress run` does")
    check.add_argument("file", type=Path, metavar="FILE")
    check.set_defaults(func=_check)


def can_interfaces(sys_net: Path = SYS_NET) -> list[str]:
    """The SocketCAN network interfaces the kernel has (can0, vcan0, ...), sorted."""
    found = []
    try:
        entries = list(sys_net.iterdir())
    except OSError:
        return []
    for entry in entries:
        try:
            if int((entry / "type").read_text().strip()) == ARPHRD_CAN:
                found.append(entry.name)
        except (OSError, ValueError):
            continue
    return sorted(found)


def init_text(ports: list[str], can_ifaces: list[str]) -> str:
    """The default file with the machine's serial ports and CAN interface filled in."""
    doc = tomlkit.parse(DEFAULT_TOML)
    notes = []
    if ports:
        notes.append(f"# Serial ports found on this machine: {', '.join(ports)}")
        doc["gnss"]["port"] = ports[0]
        if len(ports) > 1:
            doc["crop"]["port"] = ports[1]
        notes.append("# (check which device is which: topdress gnss / config check)")
    else:
        notes.append("# No serial port found on this machine: plug the adapters in and edit")
        notes.append("# [gnss] port and [crop] port (or run `topdress config init` again).")
    if can_ifaces:
        can = doc["can"]
        can["interface"] = "socketcan"
        can["channel"] = can_ifaces[0]
        notes.append(f"# SocketCAN interfaces found: {', '.join(can_ifaces)}")
    else:
        notes.append('# No SocketCAN interface found: [can] stays on "virtual", the simulator\'s')
        notes.append("# bus, where no ECU can answer. Set interface and channel to your adapter.")
    head, _, rest = tomlkit.dumps(doc).partition("\n")
    return head + "\n" + "\n".join(notes) + "\n" + rest


def _init(args: argparse.Namespace) -> int:
    from topdress.devices.ports import list_serial_ports

    path: Path = args.file
    if path.exists() and not args.force:
        raise ConfigError(str(path), "exists already (use --force to replace it)")
    text = init_text([p.device for p in list_serial_ports()], can_interfaces())
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise ConfigError(str(path), f"cannot write: {exc}") from exc
    cfg = load_config(path)  # what was written loads: a check of init itself
    print(f"wrote {path}")
    _describe(cfg)
    return 0


def _check(args: argparse.Namespace) -> int:
    from topdress.terminal.site import load_maps

    cfg = load_config(args.file)
    # the maps as `run` reads them, with the same errors (relative paths: from here, as run)
    maps = load_maps(cfg, print)
    print(f"{args.file}: ok")
    _describe(cfg)
    for line in maps.describe():
        print(f"  {line}")
    return 0


def warnings(cfg: TerminalConfig) -> list[str]:
    """What a valid file may still get wrong on this machine."""
    out = []
    if cfg.can.interface == "virtual":
        out.append('can.interface = "virtual" is the simulator\'s bus: no ECU can answer there')
    for key, src in (("gnss", cfg.gnss), ("crop", cfg.crop)):
        if src.source == "serial" and not Path(src.port).exists():
            out.append(f"{key}.port {src.port} does not exist on this machine (yet)")
        if src.source == "file" and not Path(src.path).is_file():
            out.append(f"{key}.path {src.path} is not a file")
    if cfg.can.implement == "isobus" and cfg.can.bitrate != 250000:
        out.append(f"can.bitrate {cfg.can.bitrate}: an ISOBUS runs at 250000 bit/s")
    if cfg.display.enabled and cfg.display.host not in LOCAL_HOSTS:
        out.append(f"display.host {cfg.display.host}: the display is reachable from the network")
    return out


def _describe(cfg: TerminalConfig) -> None:
    g, c, can = cfg.gnss, cfg.crop, cfg.can
    print(f"  GNSS:  {g.source} {g.port if g.source == 'serial' else g.path} @ {g.baud}")
    print(f"  crop:  {c.source} {c.port if c.source == 'serial' else c.path} @ {c.baud}")
    print(f"  CAN:   {can.interface}:{can.channel} @ {can.bitrate} bit/s")
    if can.implement == "isobus":
        iso = cfg.isobus
        print(
            f"  ISOBUS: the terminal is the Task Controller (address 0x{iso.tc_address:02X}, "
            f"NAME identity {iso.tc_identity}) of the implement that connects"
        )
    print(f"  log:   {cfg.log.dir}")
    d = cfg.display
    pin = ", PIN set" if d.pin else ""
    print(f"  display: http://{d.host}:{d.port}{pin}" if d.enabled else "  display: off")
    for w in warnings(cfg):
        print(f"  warning: {w}")
