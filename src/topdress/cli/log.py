"""`topdress log export`, `topdress log summary` and `topdress replay`."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from topdress.errors import LogError, OutputError
from topdress.outpath import check_output, is_stdout, open_text_output, write_output
from topdress.protocol.model import SpeedMode


def register(sub: Any) -> None:
    """Add `log` (export, summary) and `replay` to the top-level parser."""
    log = sub.add_parser("log", help="export and summarise recorded sessions")
    log_sub = log.add_subparsers(dest="log_command", required=True, metavar="ACTION")

    export = log_sub.add_parser("export", help="raw inputs as NDJSON events, state as CSV")
    export.add_argument("session", type=Path, help="session file (.sqlite)")
    export.add_argument("--events", type=Path, metavar="OUT.ndjson", help="write the events")
    export.add_argument("--csv", type=Path, metavar="OUT.csv", help="write the decoded state")
    export.add_argument(
        "--log-events",
        type=Path,
        metavar="OUT.ndjson",
        help="write what happened (operator actions, settings, alarms, links, faults, "
        "calibrations)",
    )
    export.add_argument(
        "--config",
        type=Path,
        metavar="OUT.toml",
        help="write the configuration the session ran with",
    )
    export.add_argument(
        "--out",
        type=Path,
        metavar="PATH",
        help="write the as-applied points and swaths (or the ISOXML task data directory)",
    )
    export.add_argument(
        "--format",
        choices=("gpkg", "shp", "geojson", "isoxml", "csv"),
        default="gpkg",
        help="format of --out (default: gpkg)",
    )
    export.add_argument(
        "--crs",
        choices=("wgs84", "utm"),
        default="wgs84",
        help="coordinates of --out: WGS 84 (default) or the field's UTM zone",
    )
    export.add_argument(
        "--fmis",
        action="store_true",
        help="with --format shp: numeric attributes only (at most 20, names of at most 10 "
        "characters), units in NAME_units.txt, as farm management software imports them",
    )
    export.add_argument(
        "--can", type=Path, metavar="OUT.log|OUT.asc", help="write the CAN traffic (candump/asc)"
    )
    export.set_defaults(func=_export)

    amap = log_sub.add_parser("map", help="the as-applied map as PNG or offline HTML")
    amap.add_argument("session", type=Path, help="session file (.sqlite)")
    amap.add_argument("--out", type=Path, required=True, metavar="map.png|map.html")
    amap.add_argument(
        "--classes",
        choices=("rate", "rpm"),
        default="rate",
        help="colour by applied rate classes (default) or the paper's metering-speed classes",
    )
    amap.set_defaults(func=_map)

    salvage = log_sub.add_parser(
        "salvage", help="copy what can still be read of a damaged session into a new file"
    )
    salvage.add_argument("session", type=Path, help="session file (.sqlite)")
    salvage.add_argument("--out", type=Path, required=True, metavar="NEW.sqlite")
    salvage.set_defaults(func=_salvage)

    summary = log_sub.add_parser("summary", help="duration, distance, area, fertilizer, faults")
    summary.add_argument("session", type=Path, help="session file (.sqlite)")
    summary.add_argument("--json", action="store_true", help="print JSON instead of text")
    summary.set_defaults(func=_summary)

    replay = sub.add_parser("replay", help="run recorded events through the ECU core")
    replay.add_argument("events", type=Path, metavar="EVENTS.ndjson")
    replay.add_argument(
        "--speed-mode",
        choices=[str(m) for m in SpeedMode],
        default=str(SpeedMode.FUSED),
        help="fused = the fused estimate (default); paper = the dual speed mode; gnss / wheel = "
        "one source only",
    )
    replay.add_argument("--config", type=Path, metavar="FILE", help="terminal configuration")
    replay.add_argument("--out", type=Path, required=True, metavar="OUT.csv")
    replay.set_defaults(func=_replay)


def _export(args: argparse.Namespace) -> int:
    from topdress.log.events import write
    from topdress.log.export import (
        ExportStats,
        session_events,
        write_log_events,
        write_state_csv,
    )
    from topdress.log.session import SessionReader

    outs = [
        p
        for p in (args.events, args.csv, args.log_events, args.config, args.out, args.can)
        if p is not None
    ]
    if not outs:
        raise LogError(
            "nothing to do: give --out PATH [--format ...], --events OUT.ndjson, --csv OUT.csv, "
            "--log-events OUT.ndjson, --config OUT.toml or --can OUT.log"
        )
    for out_path in outs:  # a typo must not truncate the session it reads (or its WAL)
        check_output(out_path, [args.session])
    if args.can is not None:  # before anything is written, naming the user's path
        from topdress.geo.cantrace import check_trace_path

        check_trace_path(args.can)
    if len({str(p) for p in outs if not is_stdout(p)}) < len([p for p in outs if not is_stdout(p)]):
        raise OutputError("two outputs name the same file: give each its own")
    if args.fmis and (args.out is None or args.format != "shp"):
        raise OutputError("--fmis is a Shapefile option: give --out NAME.shp --format shp")
    if args.out is not None and is_stdout(args.out):
        raise OutputError(f"--out -: the {args.format} export writes files; give a path")
    # Reports go to standard error when an output is standard output, so the data stays clean.
    report = sys.stderr if any(is_stdout(p) for p in outs) else sys.stdout
    with SessionReader(args.session) as reader:
        if args.events is not None:
            stats = ExportStats()
            with open_text_output(args.events, [args.session]) as out:
                write(session_events(reader, stats), out)
            print(
                f"{args.events}: {stats.events} events ({stats.wheel_counts} wheel counts)"
                + (f", {stats.bad_diag} EcuDiag frames not decoded" if stats.bad_diag else ""),
                file=report,
            )
        if args.csv is not None:
            with open_text_output(args.csv, [args.session]) as out:
                rows = write_state_csv(reader, out)
            print(f"{args.csv}: {rows} state rows", file=report)
        if args.log_events is not None:
            with open_text_output(args.log_events, [args.session]) as out:
                n = write_log_events(reader, out)
            old = " (a version-1 session file: it records none)" if reader.version < 2 else ""
            print(f"{args.log_events}: {n} logged events{old}", file=report)
        if args.config is not None:
            with open_text_output(args.config, [args.session]) as out:
                out.write(reader.config_toml)
            print(f"{args.config}: the session's configuration", file=report)
        if args.out is not None:
            from topdress.geo.export import export_maps

            for line in export_maps(reader, args.out, args.format, args.crs, None, args.fmis):
                print(line, file=report)
        if args.can is not None:
            from topdress.geo.cantrace import write_trace

            # python-can picks the trace format by the file's extension: keep it on the temp.
            n = write_output(
                args.can,
                [args.session],
                lambda tmp: write_trace(reader, tmp, shown=args.can),
                args.can.suffix,
            )
            print(f"{args.can}: {n} CAN frames", file=report)
    _warn(reader)
    return 0


def _map(args: argparse.Namespace) -> int:
    from topdress.geo.mapview import render
    from topdress.log.session import SessionReader

    suffix = ".html" if is_stdout(args.out) else args.out.suffix
    with SessionReader(args.session) as reader:
        line = write_output(
            args.out,
            [args.session],
            lambda tmp: render(reader, tmp, args.classes).replace(str(tmp), str(args.out)),
            suffix,
        )
    print(line, file=sys.stderr if is_stdout(args.out) else sys.stdout)
    _warn(reader)
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
    _warn(reader)
    return 0


def _warn(reader: Any) -> None:
    """What the reader skipped or found damaged: the command still did its work (exit 0)."""
    for line in reader.warnings():
        print(f"topdress: warning: {line}", file=sys.stderr)


def _salvage(args: argparse.Namespace) -> int:
    from topdress.log.salvage import salvage

    if is_stdout(args.out):
        raise OutputError("--out -: a salvaged session is a file; give a path")
    if args.out.exists():
        raise OutputError(f"{args.out}: exists; give a new file for the salvaged session")
    if not args.session.is_file():
        raise LogError(f"{args.session}: no such session file")
    report = write_output(args.out, [args.session], lambda tmp: salvage(args.session, tmp))
    print(report.text().replace(report.out, str(args.out)))
    return 0


def _replay(args: argparse.Namespace) -> int:
    from topdress import protocol
    from topdress.config import default_config, load_config
    from topdress.log.events import Event, ReadResult, iter_file
    from topdress.log.replay import MAX_IDLE_S, ReplayStats, kept, replay_stream, write_csv

    cfg = load_config(args.config) if args.config is not None else default_config()
    # with the configuration's frame ids: the ECU's learned lag is kept under its own id
    keep, drop = kept(protocol.FrameIds(**cfg.can.ids))
    reads: list[ReadResult] = []

    def events() -> Iterator[Event]:
        """The file read again (replay goes through it twice, never holding it)."""
        reads.append(ReadResult())
        return iter_file(args.events, reads[-1], keep, drop)

    stats = ReplayStats()
    with open_text_output(args.out, [args.events]) as out:
        rows = write_csv(replay_stream(events, cfg, args.speed_mode, stats), out)
    read = reads[0]
    for number, reason in read.bad:
        print(f"{args.events}:{number}: skipped: {reason}", file=sys.stderr)
    print(
        f"{args.out}: {rows} speed updates from {read.parsed} events"
        + (f" ({len(read.bad)} malformed lines skipped)" if read.bad else "")
        + (f", {stats.gaps_cut} pauses over {MAX_IDLE_S:g} s cut" if stats.gaps_cut else ""),
        file=sys.stderr if is_stdout(args.out) else sys.stdout,
    )
    return 0
