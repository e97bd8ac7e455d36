"""Farm office benchmark: a 12 h session into PostgreSQL, and a season's report.

    .venv/bin/python bench/office_bench.py [--hours 12] [--machines 10] [--sessions 200]

Starts its own local cluster (`topdress office start`, in a temporary directory, removed
after) and prints:

    ingest_rows: X  (swaths X)      the 12 h session's state rows, and the swaths made of them
    ingest_rows_per_s: X            state rows a second of `office push` of the 12 h session
    ingest_wall_s: X  (target <= 60 for 12 h of 10 Hz rows: rows, events, swaths, summary;
                       beside it the pushing process's CPU time, the server's not counted)
    season: X sessions, X swaths, X machines
    report_s: X  (target <= 5)      `office report` of the season
    database_mb: X                  the database's size after both

The 12 h session is written with the session writer itself (10 Hz state rows of a machine
driving 100 m passes at 8 km/h across a field, turning at the ends). The season: 10 machines
x 200 sessions of two minutes each; one two-minute session per machine is pushed through
`office push`, the other 199 are copies the database makes of its rows and swaths (new session
ids, the swaths moved to that session's own strip of the farm), so the report reads a season
of that size without the bench pushing 2000 files on a shared machine.
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
import tempfile
import time
from pathlib import Path

import psycopg

from topdress.log.model import LogEvent, StateRow
from topdress.log.session import SessionLog
from topdress.office import report, schema
from topdress.office.cluster import Cluster
from topdress.office.push import push

LAT0, LON0 = 43.8853, 125.3245
UTC0 = 1_780_000_000.0
M_LAT = 111_320.0
M_LON = M_LAT * math.cos(math.radians(LAT0))
V_KMH = 8.0
PASS_M = 100.0
WIDTH_M = 3.6


def drive(log: SessionLog, seconds: float, east0: float = 0.0) -> None:
    """Passes of PASS_M, each WIDTH_M north of the last, at V_KMH, metering all along."""
    v = V_KMH / 3.6
    log.event(LogEvent(0.0, "operator.start", {"was": "stopped"}))
    pass_s = PASS_M / v
    for i in range(round(seconds * 10)):
        t = i * 0.1
        k, s = divmod(t, pass_s)
        east = east0 + (s * v if int(k) % 2 == 0 else PASS_M - s * v)
        north = k * WIDTH_M
        lat, lon = LAT0 + north / M_LAT, LON0 + east / M_LON
        heading = 90.0 if int(k) % 2 == 0 else 270.0
        log.state(
            StateRow(
                t, lat, lon, V_KMH, V_KMH, V_KMH, "gnss", 1.2, 0.8, 150.0, 120.0,
                20.0, 16.0, 20.0, 16.0, 3000.0, 3000.0, 0, utc=UTC0 + t, utc_source="gnss",
                heading_deg=heading, outlet_lat=lat, outlet_lon=lon,
            )
        )  # fmt: skip
    log.event(LogEvent(seconds, "operator.stop", {"was": "running"}))


def write_session(directory: Path, name: str, seconds: float, machine: str) -> Path:
    cfg = f'[machine]\nwidth_m = {WIDTH_M}\n\n[office]\nmachine = "{machine}"\n'
    with SessionLog.create(directory, cfg, name=name, queue_size=2_000_000) as log:
        drive(log, seconds)
    return log.path


def season(conn: psycopg.Connection, work: Path, machines: int, sessions: int) -> None:
    for m in range(machines):
        path = write_session(work, f"m{m}", 120.0, f"m{m:02d}")
        push(conn, path)
    # the other sessions: copies of each machine's, each on its own strip of the farm
    conn.execute(
        """
        CREATE TEMP TABLE copies AS
        SELECT s.id AS src, gen_random_uuid() AS id, s.machine_id, k
        FROM session s JOIN machine m ON m.id = s.machine_id, generate_series(1, %s) k
        WHERE s.season = 2026 AND s.machine_id LIKE 'm%%'
        """,
        (sessions - 1,),
    )
    conn.execute(
        """
        INSERT INTO session (id, machine_id, season, file_name, created_utc, config_toml,
            state_rows, state_digest, event_rows, event_digest, swaths_of_rows, closed,
            applied_kg, area_ha, summary, start_utc, end_utc, cover)
        SELECT c.id, s.machine_id, s.season, s.file_name || '-' || c.k, s.created_utc,
            s.config_toml, s.state_rows, s.state_digest, s.event_rows, s.event_digest,
            s.swaths_of_rows, true, s.applied_kg, s.area_ha, s.summary,
            s.start_utc + c.k * interval '1 hour', s.end_utc + c.k * interval '1 hour',
            ST_Translate(s.cover, (c.k % 20) * 0.0015, ((c.k / 20) + 10 * m.n) * 0.0005)
        FROM copies c JOIN session s ON s.id = c.src
        JOIN (SELECT id, row_number() OVER (ORDER BY id) - 1 AS n FROM machine) m
          ON m.id = c.machine_id
        """
    )
    cols = ", ".join(schema.STATE_TYPES)
    conn.execute(
        f"INSERT INTO state (season, session_id, seq, {cols}) "
        f"SELECT season, c.id, seq, {cols.replace('utc,', 'utc + c.k * 3600,', 1)} "
        "FROM state s JOIN copies c ON c.src = s.session_id"
    )
    conn.execute(
        """
        INSERT INTO swath SELECT w.season, c.id, w.seq, w.utc + c.k * interval '1 hour',
            w.product, w.layer, w.applied_kg_ha, w.target_kg_ha, w.prescribed_kg_ha,
            w.applied_kg, w.target_kg, w.area_ha, w.zone, w.overlap_pct,
            ST_Translate(w.geom, (c.k % 20) * 0.0015, ((c.k / 20) + 10 * m.n) * 0.0005)
        FROM swath w JOIN copies c ON c.src = w.session_id
        JOIN (SELECT id, row_number() OVER (ORDER BY id) - 1 AS n FROM machine) m
          ON m.id = c.machine_id
        """
    )
    conn.commit()
    conn.execute("ANALYZE")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--hours", type=float, default=12.0)
    ap.add_argument("--machines", type=int, default=10)
    ap.add_argument("--sessions", type=int, default=200)
    args = ap.parse_args()
    data = Path(tempfile.mkdtemp(prefix="topdress-office-bench-"))
    work = Path(tempfile.mkdtemp(prefix="topdress-office-bench-files-"))
    cluster = Cluster(data)
    try:
        cluster.start()
        with psycopg.connect(cluster.conninfo) as conn:
            schema.init(conn, "bench")
            t0 = time.perf_counter()
            day = write_session(work, "day", args.hours * 3600.0, "day")
            print(f"# 12 h session written in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
            t0, c0 = time.perf_counter(), time.process_time()
            got = push(conn, day)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            print(f"ingest_rows: {got.state_rows}  (swaths {got.swaths})")
            print(f"ingest_rows_per_s: {got.state_rows / wall:.0f}")
            print(
                f"ingest_wall_s: {wall:.1f}  (target <= 60 for 12 h; CPU of the push {cpu:.1f} s)"
            )
            conn.execute("DELETE FROM session WHERE machine_id = 'day'")
            conn.execute("DELETE FROM state WHERE session_id = %s", (got.session_id,))
            conn.execute("DELETE FROM event WHERE session_id = %s", (got.session_id,))
            conn.execute("DELETE FROM swath WHERE session_id = %s", (got.session_id,))
            conn.commit()
            season(conn, work, args.machines, args.sessions)
            n = conn.execute("SELECT count(*), (SELECT count(*) FROM swath) FROM session")
            sessions, swaths = n.fetchone()
            conn.rollback()
            t0 = time.perf_counter()
            rep = report.build(conn, 2026)
            took = time.perf_counter() - t0
            size = conn.execute("SELECT pg_database_size(current_database())").fetchone()[0]
            print(f"season: {sessions} sessions, {swaths} swaths, {len(rep.machines)} machines")
            print(f"report_s: {took:.2f}  (target <= 5)")
            print(f"database_mb: {size / 1e6:.0f}")
    finally:
        cluster.stop()
        shutil.rmtree(data, ignore_errors=True)
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
