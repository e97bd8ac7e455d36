"""`topdress log export`, `topdress log summary` and `topdress replay`."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from topdress.errors import LogError


def register(sub: Any) -> None:
    """Add `log` (export, summary) and `replay` to the top-level parser."""
    log = sub.add_parser("log", help="export and summarise recorded sessions")
    log_sub = log.add_subparsers(dest="log_command", required=True, metavar="ACTION")

    export = log_sub.add_parser("export", help="raw inputs as NDJSON events, state as CSV")
    export.add_argument("session", type=Path, help="session file (.sqlite)")
    export.add_argument("--events", type=Path, metavar="OUT.ndjson", help="write the events")
    export.add_argument("--csv", type=Path, metavar="OUT.csv", help="write the decoded state")
    export.add_argument(
        "--config",
        type=Path,
        metavar="OUT.toml",
        help="write the configuration the session ran with",
    )
    export.set_defaults(func=_export)

    summary = log_sub.add_parser("summary", help="duration, distance, area, fertilizer, faults")
    summary.add_argument("session", type=Path, help="session file (.sqlite)")
    summary.add_argument("--json", action="store_true", help="print JSON instead of text")
    summary.set_defaults(func=_summary)

    replay = sub.add_parser("replay", help="run recorded events through the ECU core")
    replay.add_argument("events", type=Path, metavar="EVENTS.ndjson")
    replay.add_argument(
        "--speed-mode",
        choices=("paper", "gnss", "wheel", "fused"),
        default="paper",
        help="paper = the dual speed mode; gnss / wheel = one source only; fused = the fused "
        "estimate (default: paper)",
    )
    replay.add_argument("--config", type=Path, metavar="FILE", help="terminal configuration")
    replay.add_argument("--out", type=Path, required=True, metavar="OUT.csv")
    replay.set_defaults(func=_replay)


def _open_out(path: Path) -> Any:
    try:
        return path.open("w", encoding="utf-8", newline="")
    except OSError as exc:
        raise LogError(f"cannot write {path}: {exc}") from exc


def _export(args: argparse.Namespace) -> int:
    from topdress.log.events import write
    from topdress.log.export import ExportStats, session_events, write_state_csv
    from topdress.log.session import SessionReader

    outs = [p for p in (args.events, args.csv, args.config) if p is not None]
    if not outs:
        raise LogError(
            "nothing to do: give --events OUT.ndjson, --csv OUT.csv or --config OUT.toml"
        )
    for out_path in outs:  # a typo must not truncate the session it reads
        if out_path.exists() and args.session.exists() and out_path.samefile(args.session):
            raise LogError(f"{out_path} is the session file itself: give another output")
    with SessionReader(args.session) as reader:
        if args.events is not None:
            stats = ExportStats()
            with _open_out(args.events) as out:
                write(session_events(reader, stats), out)
            print(
                f"{args.events}: {stats.events} events ({stats.wheel_counts} wheel counts)"
                + (f", {stats.bad_diag} EcuDiag frames not decoded" if stats.bad_diag else "")
            )
        if args.csv is not None:
            with _open_out(args.csv) as out:
                rows = write_state_csv(reader, out)
            print(f"{args.csv}: {rows} state rows")
        if args.config is not None:
            with _open_out(args.config) as out:
                out.write(reader.config_toml)
            print(f"{args.config}: the session's configuration")
    return 0


def _summary(args: argparse.Namespace) -> int:
    from topdress.log.session import SessionReader
    from topdress.log.summary import format_text, summarise

    with SessionReader(args.session) as reader:
        summary = summarise(reader)
    if args.json:
        print(json.dumps(summary.as_dict(), indent=2))
    else:
        print(format_text(summary))
    return 0


def _replay(args: argparse.Namespace) -> int:
    from topdress.config import default_config, load_config
    from topdress.log.events import read_file
    from topdress.log.replay import MAX_IDLE_S, ReplayStats, replay, write_csv

    cfg = load_config(args.config) if args.config is not None else default_config()
    read = read_file(args.events)
    for number, reason in read.bad:
        print(f"{args.events}:{number}: skipped: {reason}", file=sys.stderr)
    stats = ReplayStats()
    rows = replay(read.events, cfg, args.speed_mode, stats)
    with _open_out(args.out) as out:
        write_csv(rows, out)
    print(
        f"{args.out}: {len(rows)} speed updates from {len(read.events)} events"
        + (f" ({len(read.bad)} malformed lines skipped)" if read.bad else "")
        + (f", {stats.gaps_cut} pauses over {MAX_IDLE_S:g} s cut" if stats.gaps_cut else "")
    )
    return 0
