"""The farm office against a real PostgreSQL + PostGIS: schema, pushes exactly once over a link
cut at random points, sessions that grow or change, bad input, and the report checked against
the sessions' own summaries."""

from __future__ import annotations

import hashlib
import os
import pwd
import random
import shutil
import sqlite3
import threading
from pathlib import Path

import psycopg
import pytest

from office_rig import (
    FARM,
    CuttingProxy,
    config,
    fill,
    latlon,
    needs_postgres,
    session,
)
from topdress.cli.main import main
from topdress.errors import LogError, OfficeConflict, OfficeError
from topdress.log.session import SessionLog, SessionReader
from topdress.log.summary import summarise
from topdress.office import report, schema
from topdress.office.cluster import SERVICE_USERS, Cluster
from topdress.office.push import push, sync

pytestmark = needs_postgres


def _rows(db: str, sid: str) -> tuple[int, int, float]:
    with psycopg.connect(db) as conn:
        row = conn.execute(
            "SELECT count(*), count(DISTINCT seq), coalesce(sum(v_kmh * seq), 0) FROM state "
            "WHERE session_id = %s",
            (sid,),
        ).fetchone()
    assert row is not None
    return int(row[0]), int(row[1]), float(row[2])


def _file_rows(path: Path) -> tuple[int, float]:
    c = sqlite3.connect(path.resolve().as_uri() + "?immutable=1", uri=True)
    try:
        n, s = c.execute("SELECT count(*), sum(v_kmh * id) FROM state").fetchone()
    finally:
        c.close()
    return int(n), float(s)


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_schema_partitions_and_indexes(office_db: str, tmp_path: Path) -> None:
    path = session(tmp_path, "m1", seconds=5)
    with psycopg.connect(office_db) as conn:
        assert schema.schema_version(conn) == schema.SCHEMA_VERSION
        assert schema.init(conn, FARM) == []  # up to date: nothing applied again
        push(conn, path)
        parts = {
            r[0]
            for r in conn.execute(
                "SELECT c.relname FROM pg_inherits i JOIN pg_class c ON c.oid = i.inhrelid"
            )
        }
        assert {"state_2026", "event_2026", "swath_2026"} <= parts
        idx = {
            r[0]: r[1]
            for r in conn.execute(
                "SELECT i.relname, am.amname FROM pg_index x JOIN pg_class i ON i.oid = "
                "x.indexrelid JOIN pg_am am ON am.oid = i.relam"
            )
        }
        assert idx["swath_geom"] == "gist" and idx["state_utc"] == "brin"
        assert idx["field_boundary"] == "gist"


def test_push_twice_keeps_one_copy_and_never_writes_the_file(
    office_db: str, tmp_path: Path
) -> None:
    path = session(tmp_path, "m1", seconds=30)
    before = _sha(path)
    with psycopg.connect(office_db) as conn:
        first = push(conn, path)
        again = push(conn, path)
    assert (first.state_sent, first.events_sent, first.closed) == (300, 1, True)
    assert (again.state_sent, again.events_sent, again.swaths) == (0, 0, 0)
    n, distinct, total = _rows(office_db, first.session_id)
    assert (n, distinct) == (300, 300)
    assert total == pytest.approx(_file_rows(path)[1])
    assert _sha(path) == before
    assert [p.name for p in tmp_path.iterdir()] == ["m1.sqlite"]


def test_push_exactly_once_over_a_link_cut_at_random_points(
    office_cluster, office_db: str, tmp_path: Path
) -> None:
    path = session(tmp_path, "m1", seconds=120)
    proxy = CuttingProxy(office_cluster)
    db = proxy.conninfo(office_db.split("dbname=")[1].split()[0])
    rng = random.Random(31)
    try:
        for _attempt in range(200):
            proxy.cut_after(rng.randrange(500, 200_000))
            out = sync(
                lambda: schema.connect(db, timeout_s=5),
                [path],
                retries=0,
                batch_rows=97,
            )
            if not out.failed:
                break
            assert out.exit_code == 3, out.failed  # unreachable: try again later
        else:
            pytest.fail("no push got through")
        proxy.cut_after(None)
    finally:
        proxy.close()
    assert proxy.cuts >= 3  # the link did break, and more than once
    with SessionReader(path) as reader:
        sid = reader.session_id
    n, distinct, total = _rows(office_db, sid)
    assert (n, distinct) == (1200, 1200)
    assert total == pytest.approx(_file_rows(path)[1])
    with psycopg.connect(office_db) as conn:
        again = push(conn, path)  # and the office's checksum agrees with the file
        events = conn.execute("SELECT count(*) FROM event WHERE session_id = %s", (sid,))
        assert events.fetchone() == (1,)
    assert again.state_sent == 0 and again.closed


def test_growing_session_is_sent_as_it_grows(office_db: str, tmp_path: Path) -> None:
    log = SessionLog.create(tmp_path, config("m1"), name="live")
    fill(log, 0.0, 10.0)
    assert log.sync()
    with psycopg.connect(office_db) as conn:
        part = push(conn, log.path)
        assert (part.state_rows, part.closed) == (100, False)
        fill(log, 0.0, 10.0, start=100)
        assert log.sync()
        more = push(conn, log.path)
        assert (more.state_sent, more.state_rows, more.closed) == (100, 200, False)
        log.close()
        done = push(conn, log.path)
        assert (done.state_sent, done.closed) == (0, True)
        kg = conn.execute("SELECT applied_kg FROM session WHERE id = %s", (done.session_id,))
        got = kg.fetchone()
    with SessionReader(log.path) as reader:
        s = summarise(reader)
    assert got is not None
    assert got[0] == pytest.approx(sum(x.applied_kg for x in s.layers.values()), rel=1e-9)


def test_changed_session_is_reported_never_merged(office_db: str, tmp_path: Path) -> None:
    path = session(tmp_path, "m1", seconds=20)
    with psycopg.connect(office_db) as conn:
        sid = push(conn, path).session_id
        changed = tmp_path / "changed" / path.name
        changed.parent.mkdir()
        shutil.copyfile(path, changed)
        with sqlite3.connect(changed) as c:
            c.execute("UPDATE state SET meter_rpm_upper = 25.0 WHERE id = 50")
        with pytest.raises(OfficeConflict, match="changed on the cab after it was sent"):
            push(conn, changed)
        truncated = tmp_path / "truncated" / path.name
        truncated.parent.mkdir()
        shutil.copyfile(path, truncated)
        with sqlite3.connect(truncated) as c:
            c.execute("DELETE FROM state WHERE id > 150")
        with pytest.raises(OfficeConflict, match="150 state rows where the office has 200"):
            push(conn, truncated)
        problems = conn.execute("SELECT count(*) FROM sync_problem WHERE session_id = %s", (sid,))
        assert problems.fetchone() == (2,)
        rpm = conn.execute(
            "SELECT meter_rpm_upper, (SELECT count(*) FROM state WHERE session_id = %s) "
            "FROM state WHERE session_id = %s AND seq = 50",
            (sid, sid),
        ).fetchone()
    assert rpm == (20.0, 200)  # the office's copy is as first sent


def test_two_cabs_one_session_and_wrong_farm(office_db: str, tmp_path: Path) -> None:
    path = session(tmp_path, "m1", seconds=5)
    other = session(tmp_path / "x", "m9", seconds=5, farm="Other Farm")
    with psycopg.connect(office_db) as conn:
        push(conn, path)
        with pytest.raises(OfficeConflict, match="sent by machine 'm1' already, not 'm2'"):
            push(conn, path, machine="m2")
        with pytest.raises(OfficeConflict, match="belongs to farm 'Test Farm', not 'Other Farm'"):
            push(conn, other)
        assert conn.execute("SELECT count(*) FROM session").fetchone() == (1,)


def test_bad_input_and_faults_give_exit_codes_not_tracebacks(
    office_db: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    good = session(tmp_path, "m1", seconds=5)
    damaged = tmp_path / "damaged.sqlite"
    damaged.write_bytes(b"SQLite format 3\x00" + b"\xff" * 3000)
    newer = tmp_path / "newer.sqlite"
    shutil.copyfile(good, newer)
    with sqlite3.connect(newer) as c:
        c.execute("PRAGMA user_version = 99")
    url = office_db.replace(" ", " ")
    assert main(["office", "push", str(damaged), str(newer), str(good), "--db", url]) == 2
    err = capsys.readouterr().err
    assert "damaged.sqlite" in err and "session schema 99, this software reads" in err
    assert "Traceback" not in err
    with psycopg.connect(office_db) as conn:  # the good file went in despite the bad ones
        assert conn.execute("SELECT count(*) FROM session").fetchone() == (1,)
    down = f"host={tmp_path} dbname=x user=topdress connect_timeout=2"
    assert main(["office", "push", str(good), "--db", down, "--retries", "0"]) == 3
    assert "cannot reach the office database" in capsys.readouterr().err
    with psycopg.connect(office_db, autocommit=True) as conn:
        name = conn.info.dbname
        conn.execute(f"ALTER DATABASE {name} SET default_transaction_read_only = on")
    fresh = session(tmp_path / "y", "m1", seconds=5)
    assert main(["office", "push", str(fresh), "--db", url, "--retries", "0"]) == 3
    assert "read-only" in capsys.readouterr().err
    with psycopg.connect(office_db, autocommit=True) as conn:
        conn.execute("SET default_transaction_read_only = off")
        conn.execute(f"ALTER DATABASE {name} RESET default_transaction_read_only")
        conn.execute("UPDATE office_schema SET version = 99")
    assert main(["office", "report", "--db", url]) == 2
    assert "has schema 99, this topdress knows up to 1" in capsys.readouterr().err
    with psycopg.connect(office_db, autocommit=True) as conn:
        conn.execute("DROP TABLE office_schema")
    assert main(["office", "report", "--db", url]) == 2
    assert "run `topdress office init`" in capsys.readouterr().err


def _geojson(path: Path, polygons: list[tuple[list[tuple[float, float]], float]]) -> Path:
    import json

    feats = [
        {
            "type": "Feature",
            "properties": {"rate": rate},
            "geometry": {
                "type": "Polygon",
                "coordinates": [[[lon, lat] for lat, lon in ring + ring[:1]]],
            },
        }
        for ring, rate in polygons
    ]
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    return path


def _box(e0: float, n0: float, e1: float, n1: float) -> list[tuple[float, float]]:
    return [latlon(e0, n0), latlon(e1, n0), latlon(e1, n1), latlon(e0, n1)]


def test_report_against_the_sessions_summaries(office_db: str, tmp_path: Path) -> None:
    # Two machines side by side, 2 m apart with 3.6 m swaths: 1.6 m strips covered twice;
    # a third pass of m1 elsewhere. The field: 0..120 m east, -10..10 m north; two zones.
    paths = [
        session(tmp_path / "a", "m1", north_m=0.0, seconds=50),
        session(tmp_path / "b", "m2", north_m=2.0, seconds=50),
        session(tmp_path / "c", "m1", north_m=-6.0, seconds=40),
    ]
    field = _geojson(tmp_path / "field.geojson", [(_box(-5, -10, 120, 10), 0)])
    rx = _geojson(
        tmp_path / "rx.geojson", [(_box(-5, -10, 60, 10), 200.0), (_box(60, -10, 120, 10), 300.0)]
    )
    url = office_db
    assert main(["office", "field", "north", "--boundary", str(field), "--prescription",
                 str(rx), "--db", url]) == 0  # fmt: skip
    assert main(["office", "push", *map(str, paths), "--db", url]) == 0
    summaries = {}
    for p in paths:
        with SessionReader(p) as r:
            s = summarise(r)
        m = p.parent.name
        kg = sum(x.applied_kg for x in s.layers.values())
        summaries[m] = (kg, s.area_ha)
    with psycopg.connect(url) as conn:
        rep = report.build(conn, 2026)
    by = {x.name: x for x in rep.machines}
    m1_kg = summaries["a"][0] + summaries["c"][0]
    m1_ha = summaries["a"][1] + summaries["c"][1]
    assert by["m1"].sessions == 2 and by["m2"].sessions == 1
    assert by["m1"].applied_kg == pytest.approx(m1_kg, rel=0.005)
    assert by["m1"].area_ha == pytest.approx(m1_ha, rel=0.005)
    assert by["m2"].applied_kg == pytest.approx(summaries["b"][0], rel=0.005)
    assert by["m2"].area_ha == pytest.approx(summaries["b"][1], rel=0.005)
    assert by["m1"].summary_kg == pytest.approx(m1_kg, rel=1e-9)
    # the meters turned at 20 and 16 r/min: 125 + 100 kg/ha at 8 km/h over 3.6 m
    assert by["m1"].applied_kg_ha == pytest.approx(225.0, rel=0.005)
    fields = {x.name: x for x in rep.fields}
    assert fields["north"].applied_kg == pytest.approx(
        sum(k for k, _ in summaries.values()), rel=0.005
    )
    zones = {x.name: x for x in rep.zones}
    low, high = zones["north / feature 0 (fid 0)"], zones["north / feature 1 (fid 1)"]
    assert low.prescribed_kg_ha == pytest.approx(200.0)
    assert high.prescribed_kg_ha == pytest.approx(300.0)
    assert low.diff_kg == pytest.approx(low.applied_kg - 200.0 * low.area_ha)
    # 8 km/h x 50 s = 111 m; the strips 1.6 m wide overlap over that length
    (double,) = rep.double
    assert (double.machine_a, double.machine_b) == ("m1", "m2")
    assert double.area_ha == pytest.approx(111.1 * 1.6 / 10_000, rel=0.03)
    (gap,) = rep.uncovered
    assert gap.field_ha == pytest.approx(125 * 20 / 10_000, rel=0.01)
    covered = m1_ha + summaries["b"][1] - double.area_ha
    assert gap.uncovered_ha == pytest.approx(gap.field_ha - covered, rel=0.05)
    # filters: one machine, and the CSV and GeoPackage outputs
    with psycopg.connect(url) as conn:
        only = report.build(conn, 2026, report.Filters(machine="m2"))
    assert [x.name for x in only.machines] == ["m2"] and not only.double
    out = tmp_path / "r.gpkg"
    assert main(["office", "report", "--db", url, "--csv", str(tmp_path / "r.csv"),
                 "--gpkg", str(out)]) == 0  # fmt: skip
    text = (tmp_path / "r.csv").read_text()
    assert "machine,m1,2," in text and "double,north / m1 + m2" in text
    import pyogrio

    names = ["fields", "zones", "double_coverage", "never_covered"]
    assert [str(n) for n, _ in pyogrio.list_layers(out)] == names
    _, table = pyogrio.read_arrow(out, layer="zones")
    assert table["name"].to_pylist() == ["north / feature 0 (fid 0)", "north / feature 1 (fid 1)"]
    assert table["applied_kg"].to_pylist() == pytest.approx([low.applied_kg, high.applied_kg])


def test_two_pushes_of_one_session_at_once_leave_one_copy(office_db: str, tmp_path: Path) -> None:
    path = session(tmp_path, "m1", seconds=60)
    errors: list[Exception] = []

    def one() -> None:
        try:
            with psycopg.connect(office_db) as conn:
                push(conn, path, batch_rows=50)
        except OfficeError as exc:  # the loser is told to try again
            errors.append(exc)

    threads = [threading.Thread(target=one) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    with psycopg.connect(office_db) as conn:
        push(conn, path)
    with SessionReader(path) as reader:
        assert _rows(office_db, reader.session_id)[:2] == (600, 600)
    assert all(getattr(e, "exit_code", 0) in (3, 4) for e in errors)


def test_old_session_without_id_gets_a_stable_one(tmp_path: Path) -> None:
    path = session(tmp_path, "m1", seconds=1)
    c = sqlite3.connect(path)
    c.execute("DELETE FROM meta WHERE key = 'session_id'")
    c.commit()
    c.close()
    copy = tmp_path / "copy.sqlite"
    shutil.copyfile(path, copy)
    with SessionReader(path) as a, SessionReader(copy) as b:
        assert a.session_id == b.session_id
        assert len(a.session_id) == 36


def test_damaged_file_is_a_log_error(tmp_path: Path) -> None:
    bad = tmp_path / "x.sqlite"
    bad.write_bytes(b"not a database at all" * 100)
    with pytest.raises(LogError):
        SessionReader(bad)


def test_sync_of_a_directory_and_the_conflict_exit_code(
    office_db: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    session(tmp_path / "cab", "m1", seconds=5)
    session(tmp_path / "cab", "m2", north_m=5.0, seconds=5)
    assert main(["office", "sync", "--sessions", str(tmp_path / "cab"), "--db", office_db]) == 0
    assert capsys.readouterr().out.count("50 new state rows") == 2
    assert main(["office", "sync", "--sessions", str(tmp_path / "cab"), "--db", office_db]) == 0
    assert capsys.readouterr().out.count("nothing new") == 2
    one = str(tmp_path / "cab" / "m1.sqlite")
    assert main(["office", "push", one, "--machine", "m7", "--db", office_db]) == 4
    assert "sent by machine 'm1' already" in capsys.readouterr().err
    assert main(["office", "sync", "--sessions", str(tmp_path / "none"), "--db", office_db]) == 2


def test_local_cluster_runs_unprivileged_with_its_socket_in_the_directory(
    office_cluster: Cluster, capsys: pytest.CaptureFixture[str]
) -> None:
    assert office_cluster.running()
    assert (office_cluster.socket_dir / ".s.PGSQL.5432").is_socket()
    owner = office_cluster.pgdata.stat().st_uid
    assert owner != 0  # the server refuses root: it runs as an unprivileged user
    if os.geteuid() != 0:
        assert owner == os.geteuid()
    else:
        users = {u.pw_name: u.pw_uid for u in pwd.getpwall()}
        assert owner == next(users[n] for n in SERVICE_USERS if n in users)
    assert main(["office", "start", "--data", str(office_cluster.data)]) == 0
    assert "office database running" in capsys.readouterr().out  # not started twice
    with psycopg.connect(office_cluster.conninfo) as conn:
        row = conn.execute("SELECT extversion FROM pg_extension WHERE extname = 'postgis'")
        assert row.fetchone() is not None


def test_a_full_database_is_exit_3_and_loses_nothing(
    office_db: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The server's own answer when its disk is full (SQLSTATE 53100), made by a trigger: the
    push says so with the cron exit code 3, the cab's file is untouched, and once there is room
    the same push sends the session once."""
    good = session(tmp_path, "m1", seconds=5)
    before = hashlib.sha256(good.read_bytes()).hexdigest()
    with psycopg.connect(office_db, autocommit=True) as conn:
        conn.execute(
            "CREATE FUNCTION td_full() RETURNS trigger LANGUAGE plpgsql AS $$ BEGIN"
            " RAISE EXCEPTION 'could not extend file: No space left on device'"
            " USING ERRCODE = 'disk_full'; END $$"
        )
        conn.execute(
            "CREATE TRIGGER td_full BEFORE INSERT ON session"
            " FOR EACH ROW EXECUTE FUNCTION td_full()"
        )
    assert main(["office", "push", str(good), "--db", office_db, "--retries", "0"]) == 3
    err = capsys.readouterr().err
    assert "the office database is full" in err and "Traceback" not in err
    assert hashlib.sha256(good.read_bytes()).hexdigest() == before
    with psycopg.connect(office_db, autocommit=True) as conn:
        assert conn.execute("SELECT count(*) FROM session").fetchone() == (0,)
        conn.execute("DROP TRIGGER td_full ON session")
    assert main(["office", "push", str(good), "--db", office_db, "--retries", "0"]) == 0
    assert main(["office", "push", str(good), "--db", office_db, "--retries", "0"]) == 0
    with psycopg.connect(office_db) as conn:
        assert conn.execute("SELECT count(*) FROM session").fetchone() == (1,)
