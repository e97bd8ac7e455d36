"""`topdress demo` and `topdress run` (registered by topdress.cli)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TextIO

from topdress.config import load_config, read_config_text
from topdress.terminal.signals import StopSignals

#: `topdress run` ended (duration, Ctrl-C, SIGTERM) without the ECU ever acknowledging its
#: parameters: the inputs were logged, nothing was metered.
EXIT_NO_ECU = 3


def register(sub: Any) -> None:
    """Add `demo` and `run` to the top-level parser."""
    demo = sub.add_parser(
        "demo", help="the terminal against the simulated machine (ptys + CAN), live status"
    )
    demo.add_argument(
        "--duration", type=_seconds, metavar="S", help="stop after S seconds (default: Ctrl-C)"
    )
    demo.add_argument(
        "--out",
        type=Path,
        default=Path("topdress-sessions"),
        metavar="DIR",
        help="where the session log goes (default: ./topdress-sessions)",
    )
    demo.add_argument(
        "--config",
        type=Path,
        metavar="FILE",
        help="run with this configuration (its devices replaced by the simulation's; the "
        "simulated machine takes its geometry); default: the defaults",
    )
    demo.add_argument("--seed", type=int, default=1, help="seed of the simulated machine")
    demo.add_argument(
        "--passes",
        type=_passes,
        default=30,
        metavar="N",
        help="passes of 40 m driven, then the machine stands (for calibrations; default 30)",
    )
    _display_args(demo)
    demo.add_argument(
        "--ecu",
        choices=("host", "qemu"),
        default="host",
        help="the ECU: host = the C core in-process (default); qemu = the STM32F4 firmware "
        "image in QEMU (make firmware; built first when missing)",
    )
    demo.add_argument(
        "--start",
        action="store_true",
        help="start the meters at once (default: the operator's start)",
    )
    demo.add_argument(
        "--isobus",
        action="store_true",
        help="the ECU on ISOBUS, the terminal its Task Controller (docs/isobus.md)",
    )
    demo.set_defaults(func=_demo)

    run = sub.add_parser(
        "run",
        help="the terminal against real devices (serial ports, CAN)",
        epilog=(
            "Waits for an ECU not on the bus yet. Exit codes: 0 done; 2 an error (a bad "
            f"configuration, a device, a parameter the ECU refuses); {EXIT_NO_ECU} the ECU "
            "never answered (inputs logged, nothing metered)."
        ),
    )
    run.add_argument("--config", type=Path, required=True, metavar="FILE", help="TOML file")
    run.add_argument(
        "--duration", type=_seconds, metavar="S", help="stop after S seconds (default: Ctrl-C)"
    )
    _display_args(run)
    run.add_argument(
        "--start",
        action="store_true",
        help="start the meters at once, headless (as [operator] autostart = true); "
        "default: the operator's start, typed here or on the display",
    )
    run.set_defaults(func=_run)


def _display_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--display",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="serve the operator display in the browser (default: display.enabled, on)",
    )
    parser.add_argument(
        "--port", type=int, metavar="N", help="the display's port (default: display.port, 8080)"
    )
    parser.add_argument(
        "--host",
        metavar="ADDR",
        help="the display's address (default: display.host, 127.0.0.1; others need display.pin)",
    )


def _passes(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number of passes: {text!r}") from None
    if not 1 <= value <= 1000:
        raise argparse.ArgumentTypeError(f"must be 1..1000 passes, not {text}")
    return value


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number of seconds: {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0 seconds, not {text}")
    return value


@contextmanager
def _sigterm_stops() -> Iterator[None]:
    """SIGTERM (a service stop, the cab PC shutting down) stops the terminal as Ctrl-C does:
    the stop command to the ECU, the log closed, where the data went; a second signal of
    either kind while that happens is ignored, never a torn log."""
    with StopSignals().installed():
        yield


def _demo(args: argparse.Namespace) -> int:
    from topdress.cli.demo import run_demo
    from topdress.cli.display import display_options
    from topdress.config import default_config

    user_text = ""
    cfg = default_config()
    if args.config is not None:
        cfg = load_config(args.config)  # a bad file stops here, naming the file
        user_text = read_config_text(args.config)
    if args.isobus:
        from topdress.cli.isobus_demo import run_terminal_isobus_demo

        with _sigterm_stops():
            return run_terminal_isobus_demo(
                cfg, args.duration or 40.0, args.out, args.seed, sys.stdout, user_text
            )
    display = display_options(cfg, args.display, args.host, args.port)
    with _sigterm_stops():
        return run_demo(
            args.duration,
            args.out,
            seed=args.seed,
            start=args.start,
            keyboard=_keyboard(),
            display=display,
            passes=args.passes,
            user_text=user_text,
            ecu=args.ecu,
        )


def _run(args: argparse.Namespace) -> int:
    from topdress.cli.demo import run_terminal
    from topdress.cli.display import display_options

    cfg = load_config(args.config)
    display = display_options(cfg, args.display, args.host, args.port)
    start = args.start or cfg.operator.autostart
    # A line source reading stdin owns it; else typed commands come from there.
    reads_stdin = "stdin" in (cfg.gnss.source, cfg.crop.source)
    with _sigterm_stops():
        result = run_terminal(
            cfg,
            read_config_text(args.config),
            args.duration,
            sys.stdout,
            start=start,
            config_path=args.config,
            keyboard=None if reads_stdin else _keyboard(),
            display=display,
        )
    return 0 if result.ecu_ready else EXIT_NO_ECU


def _keyboard() -> TextIO | None:
    """The operator's typed commands: stdin when it is a terminal."""
    return sys.stdin if sys.stdin is not None and sys.stdin.isatty() else None
