"""The office database's schema, made and moved forward by numbered migrations, and the
connection with every server failure turned into an OfficeError a user can act on.

Sessions are keyed by the id the cab made at the session's start; their rows (state at 10 Hz,
events, swaths) by (season, session, sequence number in the cab's file). The row tables are
partitioned by season (declarative LIST partitions, one a year, made on first use), so a
season is dropped, archived or moved to another tablespace whole; swaths and fields carry GiST
indexes on their geometry, state rows a BRIN index on their time (they arrive in time order)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any, Final

import psycopg
from psycopg import errors as pgerr

from topdress.errors import OfficeConflict, OfficeError, OfficeUnavailable
from topdress.log.model import STATE_COLUMNS

#: state columns and their server types (the cab's SQLite types)
_TEXT: Final = frozenset({"source", "utc_source", "zone"})
STATE_TYPES: Final = {
    c: "text" if c in _TEXT else "bigint" if c == "faults" else "double precision"
    for c in STATE_COLUMNS
}
ROW_TABLES: Final = ("state", "event", "swath")

_STATE_DDL: Final = ",\n    ".join(f"{c} {t}" for c, t in STATE_TYPES.items())

MIGRATIONS: Final = (
    # 1: the first schema
    f"""
CREATE EXTENSION IF NOT EXISTS postgis;
CREATE TABLE office (
    id int PRIMARY KEY CHECK (id = 1),
    farm text NOT NULL
);
CREATE TABLE machine (id text PRIMARY KEY, first_push timestamptz NOT NULL DEFAULT now());
CREATE TABLE session (
    id uuid PRIMARY KEY,
    machine_id text NOT NULL REFERENCES machine,
    season int NOT NULL,
    file_name text NOT NULL,
    created_utc text NOT NULL,
    start_utc timestamptz,
    end_utc timestamptz,
    closed boolean NOT NULL DEFAULT false,
    config_toml text NOT NULL,
    state_rows bigint NOT NULL DEFAULT 0,
    state_digest text NOT NULL DEFAULT '',
    event_rows bigint NOT NULL DEFAULT 0,
    event_digest text NOT NULL DEFAULT '',
    swaths_of_rows bigint NOT NULL DEFAULT -1,
    applied_kg double precision,
    area_ha double precision,
    summary jsonb,
    cover geometry(Geometry, 4326),  -- the union of its swaths: the ground it covered
    first_push timestamptz NOT NULL DEFAULT now(),
    last_push timestamptz NOT NULL DEFAULT now()
);
CREATE INDEX session_season ON session (season, machine_id);
CREATE INDEX session_cover ON session USING gist (cover);
CREATE TABLE state (
    season int NOT NULL,
    session_id uuid NOT NULL,
    seq bigint NOT NULL,
    {_STATE_DDL},
    geom geometry(Point, 4326) GENERATED ALWAYS AS (
        ST_SetSRID(ST_MakePoint(coalesce(outlet_lon, lon), coalesce(outlet_lat, lat)), 4326)
    ) STORED,
    PRIMARY KEY (season, session_id, seq)
) PARTITION BY LIST (season);
CREATE INDEX state_utc ON state USING brin (utc);
CREATE TABLE event (
    season int NOT NULL,
    session_id uuid NOT NULL,
    seq bigint NOT NULL,
    t double precision NOT NULL,
    kind text NOT NULL,
    detail jsonb NOT NULL,
    PRIMARY KEY (season, session_id, seq)
) PARTITION BY LIST (season);
CREATE TABLE swath (
    season int NOT NULL,
    session_id uuid NOT NULL,
    seq int NOT NULL,
    utc timestamptz,
    product text NOT NULL,
    layer text NOT NULL,
    applied_kg_ha double precision,
    target_kg_ha double precision,
    prescribed_kg_ha double precision,
    applied_kg double precision NOT NULL,
    target_kg double precision NOT NULL,
    area_ha double precision NOT NULL,
    zone text,
    overlap_pct double precision,
    geom geometry(Geometry, 4326) NOT NULL,
    PRIMARY KEY (season, session_id, seq)
) PARTITION BY LIST (season);
CREATE INDEX swath_geom ON swath USING gist (geom);
CREATE INDEX swath_utc ON swath USING brin (utc);
CREATE TABLE field (
    name text PRIMARY KEY,
    boundary geometry(MultiPolygon, 4326) NOT NULL,
    source text NOT NULL
);
CREATE INDEX field_boundary ON field USING gist (boundary);
CREATE TABLE prescription_zone (
    field text NOT NULL REFERENCES field ON DELETE CASCADE,
    seq int NOT NULL,
    zone text NOT NULL,
    rate_kg_ha double precision NOT NULL,
    geom geometry(MultiPolygon, 4326) NOT NULL,
    PRIMARY KEY (field, seq)
);
CREATE INDEX prescription_zone_geom ON prescription_zone USING gist (geom);
CREATE TABLE sync_problem (
    id bigserial PRIMARY KEY,
    session_id uuid NOT NULL,
    machine_id text NOT NULL,
    file_name text NOT NULL,
    detected timestamptz NOT NULL DEFAULT now(),
    problem text NOT NULL
);
""",
)
SCHEMA_VERSION: Final = len(MIGRATIONS)


@contextlib.contextmanager
def office_errors(where: str) -> Iterator[None]:
    """The server's failures as OfficeErrors naming what to do; never a traceback."""
    try:
        yield
    except OfficeError:
        raise
    except pgerr.ReadOnlySqlTransaction as exc:
        raise OfficeUnavailable(f"{where}: the office database is read-only now ({exc})") from exc
    except (pgerr.DiskFull, pgerr.OutOfMemory, pgerr.ProgramLimitExceeded) as exc:
        raise OfficeUnavailable(f"{where}: the office database is full ({exc})") from exc
    except pgerr.UndefinedTable as exc:
        raise OfficeError(
            f"{where}: the database has no topdress office schema (run `topdress office init`)"
        ) from exc
    except (pgerr.UniqueViolation, pgerr.ForeignKeyViolation) as exc:
        raise OfficeConflict(f"{where}: another push got there first ({exc})") from exc
    except psycopg.OperationalError as exc:
        text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise OfficeUnavailable(f"{where}: cannot reach the office database: {text}") from exc
    except psycopg.Error as exc:
        raise OfficeError(f"{where}: the office database refused: {exc}") from exc


def connect(conninfo: str, timeout_s: float = 10.0) -> psycopg.Connection[Any]:
    """A connection (explicit transactions); its statements and idle links time out, so a
    dead link fails the push instead of hanging it."""
    with office_errors("connecting"):
        return psycopg.connect(
            conninfo,
            connect_timeout=max(1, round(timeout_s)),
            keepalives=1,
            keepalives_idle=10,
            keepalives_interval=5,
            keepalives_count=3,
            application_name="topdress office",
        )


def schema_version(conn: psycopg.Connection[Any]) -> int:
    """The database's schema version, 0 for one without the office schema."""
    with office_errors("reading the schema version"):
        row = conn.execute("SELECT to_regclass('office_schema')").fetchone()
        if row is None or row[0] is None:
            conn.rollback()
            return 0
        got = conn.execute("SELECT max(version) FROM office_schema").fetchone()
        conn.rollback()
        return int(got[0]) if got and got[0] is not None else 0


def init(conn: psycopg.Connection[Any], farm: str) -> list[int]:
    """Create or migrate the schema; the migrations applied (none: up to date)."""
    with office_errors("office init"):
        conn.execute(
            "CREATE TABLE IF NOT EXISTS office_schema ("
            "version int PRIMARY KEY, applied timestamptz NOT NULL DEFAULT now())"
        )
        conn.execute("LOCK TABLE office_schema IN EXCLUSIVE MODE")  # two inits: one migrates
        row = conn.execute("SELECT coalesce(max(version), 0) FROM office_schema").fetchone()
        have = int(row[0]) if row else 0
        if have > SCHEMA_VERSION:
            conn.rollback()
            raise _newer(have)
        done = []
        for version in range(have + 1, SCHEMA_VERSION + 1):
            conn.execute(MIGRATIONS[version - 1])
            conn.execute("INSERT INTO office_schema (version) VALUES (%s)", (version,))
            done.append(version)
        owner = conn.execute("SELECT farm FROM office WHERE id = 1").fetchone()
        if owner is None:
            conn.execute("INSERT INTO office (id, farm) VALUES (1, %s)", (farm,))
        elif farm and owner[0] != farm:
            conn.rollback()
            raise OfficeConflict(f"this office database belongs to farm {owner[0]!r}, not {farm!r}")
        conn.commit()
    return done


def _newer(have: int) -> OfficeError:
    return OfficeError(
        f"the office database has schema {have}, this topdress knows up to {SCHEMA_VERSION}: "
        "update topdress on this computer"
    )


def check(conn: psycopg.Connection[Any], farm: str = "") -> str:
    """That the database holds this schema version (and, when `farm` is given, that farm);
    the farm's name."""
    have = schema_version(conn)
    if have == 0:
        raise OfficeError("the database has no topdress office schema (run `topdress office init`)")
    if have > SCHEMA_VERSION:
        raise _newer(have)
    if have < SCHEMA_VERSION:
        raise OfficeError(
            f"the office database has schema {have}, older than this topdress's "
            f"{SCHEMA_VERSION}: run `topdress office init` to migrate it"
        )
    with office_errors("reading the farm"):
        row = conn.execute("SELECT farm FROM office WHERE id = 1").fetchone()
        conn.rollback()
    owner = str(row[0]) if row else ""
    if farm and owner and farm != owner:
        raise OfficeConflict(f"this office database belongs to farm {owner!r}, not {farm!r}")
    return owner


def ensure_season(conn: psycopg.Connection[Any], season: int) -> None:
    """The season's partitions of the row tables (inside the caller's transaction)."""
    if not 1970 <= season <= 9999:
        raise OfficeError(f"season {season} is not a year")
    conn.execute("SELECT pg_advisory_xact_lock(31, %s)", (season,))
    for table in ROW_TABLES:
        conn.execute(
            f"CREATE TABLE IF NOT EXISTS {table}_{season} PARTITION OF {table} "
            f"FOR VALUES IN ({season})"
        )
