"""`topdress office`: the farm office's database (docs/office.md).

Exit codes a cron job can act on: 0 done, 2 bad input or setting (fix it), 3 the office cannot
be reached or written now (try again later), 4 a session that conflicts with the office's copy
(look at it)."""

from __future__ import annotations

import argparse
import sys
from datetime import date
from pathlib import Path
from typing import Any


def register(sub: Any) -> None:
    office = sub.add_parser("office", help="the farm office: every cab's sessions in PostgreSQL")
    osub = office.add_subparsers(dest="office_command", required=True, metavar="ACTION")

    def db_args(p: argparse.ArgumentParser) -> None:
        g = p.add_mutually_exclusive_group()
        g.add_argument(
            "--db", metavar="URL", help="postgresql://... (default: the PG* environment)"
        )
        g.add_argument("--data", type=Path, metavar="DIR", help="the local cluster in DIR")

    start = osub.add_parser("start", help="run a local cluster in DIR (made the first time)")
    start.add_argument("--data", type=Path, metavar="DIR", required=True)
    start.set_defaults(func=_start)
    stop = osub.add_parser("stop", help="stop the local cluster in DIR")
    stop.add_argument("--data", type=Path, metavar="DIR", required=True)
    stop.set_defaults(func=_stop)

    init = osub.add_parser("init", help="create or migrate the office schema")
    db_args(init)
    init.add_argument("--farm", default="", help="the farm this database is for")
    init.set_defaults(func=_init)

    def push_args(p: argparse.ArgumentParser) -> None:
        db_args(p)
        p.add_argument(
            "--machine",
            default="",
            help="machine id (default: the session's [office] machine, else this host's name)",
        )
        p.add_argument("--farm", default="", help="refuse a database of another farm")
        p.add_argument(
            "--retries",
            type=int,
            default=3,
            help="tries again when the office cannot be reached (default 3, with backoff)",
        )

    push = osub.add_parser("push", help="send sessions (what the office lacks of them)")
    push.add_argument("sessions", nargs="+", type=Path, metavar="SESSION")
    push_args(push)
    push.set_defaults(func=_push)
    sync = osub.add_parser("sync", help="send every session of a directory")
    sync.add_argument("--sessions", type=Path, required=True, metavar="DIR")
    push_args(sync)
    sync.set_defaults(func=_sync)

    fld = osub.add_parser("field", help="import a field's boundary and prescription")
    fld.add_argument("name")
    fld.add_argument("--boundary", type=Path, required=True, metavar="FILE")
    fld.add_argument("--prescription", type=Path, metavar="FILE")
    fld.add_argument("--attribute", default="rate", help="the prescription's rate attribute")
    fld.add_argument("--units", choices=("kg/ha", "lb/ac", "t/ha"), default="kg/ha")
    db_args(fld)
    fld.set_defaults(func=_field)

    report = osub.add_parser("report", help="a season's dose, overlaps and gaps")
    _report_args(report)
    db_args(report)
    report.add_argument("--csv", type=Path, metavar="OUT.csv", help="also as CSV ('-': stdout)")
    report.add_argument(
        "--gpkg", type=Path, metavar="OUT.gpkg", help="the overlaps and gaps as a GeoPackage"
    )
    report.set_defaults(func=_report)

    serve = osub.add_parser("serve", help="the season's map and report on a read-only web page")
    db_args(serve)
    serve.add_argument("--host", default="127.0.0.1")
    serve.add_argument("--port", type=int, default=8090)
    serve.set_defaults(func=_serve)


def _report_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--season", type=int, help="the year (default: the latest)")
    p.add_argument("--field")
    p.add_argument("--machine")
    p.add_argument("--since", type=date.fromisoformat, metavar="YYYY-MM-DD")
    p.add_argument("--until", type=date.fromisoformat, metavar="YYYY-MM-DD")


def conninfo(args: argparse.Namespace) -> str:
    from topdress.office.cluster import Cluster

    if getattr(args, "data", None) is not None:
        return Cluster(args.data).conninfo
    return str(args.db or "")  # "": libpq reads PGHOST, PGDATABASE, ... itself


def _connect(args: argparse.Namespace) -> Any:
    from topdress.office.schema import connect

    return connect(conninfo(args))


def _start(args: argparse.Namespace) -> int:
    from topdress.office.cluster import Cluster

    cluster = Cluster(args.data)
    started = cluster.start()
    print(f"office database {'started' if started else 'running'}: {cluster.conninfo}")
    return 0


def _stop(args: argparse.Namespace) -> int:
    from topdress.office.cluster import Cluster

    Cluster(args.data).stop()
    return 0


def _init(args: argparse.Namespace) -> int:
    from topdress.office import schema

    with _connect(args) as conn:
        done = schema.init(conn, args.farm)
    print(
        f"office schema {schema.SCHEMA_VERSION}"
        + (f" (applied {done})" if done else ", up to date")
    )
    return 0


def _sync_paths(args: argparse.Namespace, paths: list[Path]) -> int:
    from topdress.office.push import sync

    outcome = sync(lambda: _connect(args), paths, args.machine, args.farm, args.retries)
    for r in outcome.pushed:
        print(r.text())
        for w in r.warnings:
            print(f"topdress: warning: {w}", file=sys.stderr)
    for path, exc in outcome.failed:
        print(f"topdress: error: {path}: {exc}", file=sys.stderr)
    return outcome.exit_code


def _push(args: argparse.Namespace) -> int:
    return _sync_paths(args, list(args.sessions))


def _sync(args: argparse.Namespace) -> int:
    from topdress.office.push import session_files

    return _sync_paths(args, session_files(args.sessions))


def _field(args: argparse.Namespace) -> int:
    from topdress.office.fields import import_field

    with _connect(args) as conn:
        n = import_field(
            conn, args.name, args.boundary, args.prescription, args.attribute, args.units
        )
    print(f"field {args.name}: boundary and {n} prescription zones")
    return 0


def _report(args: argparse.Namespace) -> int:
    from topdress.office import report

    filters = report.Filters(args.field, args.machine, args.since, args.until)
    with _connect(args) as conn:
        rep = report.build(conn, args.season, filters)
    if args.csv is not None and str(args.csv) == "-":
        report.write_csv(rep, sys.stdout)
        return 0
    print(report.text(rep))
    if args.csv is not None:
        with args.csv.open("w", newline="", encoding="utf-8") as f:
            report.write_csv(rep, f)
    if args.gpkg is not None:
        report.write_gpkg(rep, args.gpkg)
    return 0


def _serve(args: argparse.Namespace) -> int:
    from topdress.display.office_page import serve

    serve(conninfo(args), args.host, args.port)
    return 0
