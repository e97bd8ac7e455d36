"""The agronomist's questions for a season, answered from the swaths of every machine:
dose per field, per management zone and per machine, applied against prescribed; ground two
machines both covered; ground inside a boundary nobody covered.

A swath belongs to the field (and the zone of that field's prescription) its inner point lies
in. Its applied kg are what the cab metered over it (the swaths add up to the session's
summary); its prescribed kg are its area times the office's prescription for its zone, or the
rate the cab's own prescription gave it where the office has none."""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from datetime import date
from pathlib import Path
from typing import Any, Final, TextIO

import numpy as np
import psycopg
import pyarrow as pa
import pyogrio
import shapely

from topdress.errors import OfficeError
from topdress.office.schema import check, office_errors

NO_FIELD: Final = "(outside every field)"


@dataclass
class Line:
    """One row of the dose tables."""

    kind: str  # machine, field, zone
    name: str
    sessions: int
    area_ha: float
    applied_kg: float
    target_kg: float
    prescribed_kg: float | None  # None: no prescription for any of its swaths
    summary_kg: float | None = None  # machines: the sessions' own summaries
    summary_area_ha: float | None = None

    @property
    def applied_kg_ha(self) -> float | None:
        return self.applied_kg / self.area_ha if self.area_ha > 0 else None

    @property
    def prescribed_kg_ha(self) -> float | None:
        if self.prescribed_kg is None or self.area_ha <= 0:
            return None
        return self.prescribed_kg / self.area_ha

    @property
    def diff_kg(self) -> float | None:
        return None if self.prescribed_kg is None else self.applied_kg - self.prescribed_kg

    @property
    def diff_pct(self) -> float | None:
        if self.prescribed_kg is None or self.prescribed_kg <= 0:
            return None
        return (self.applied_kg - self.prescribed_kg) / self.prescribed_kg * 100.0


@dataclass
class Overlap:
    field: str
    machine_a: str
    machine_b: str
    area_ha: float
    geom: Any


@dataclass
class Uncovered:
    field: str
    field_ha: float
    uncovered_ha: float
    geom: Any


@dataclass
class Filters:
    field: str | None = None
    machine: str | None = None
    since: date | None = None
    until: date | None = None  # inclusive


@dataclass
class Report:
    season: int
    farm: str
    filters: Filters
    machines: list[Line] = field(default_factory=list)
    fields: list[Line] = field(default_factory=list)
    zones: list[Line] = field(default_factory=list)
    double: list[Overlap] = field(default_factory=list)
    uncovered: list[Uncovered] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)  # sync problems of the season
    shapes: dict[str, Any] = field(default_factory=dict)  # field and zone lines' polygons

    @property
    def lines(self) -> list[Line]:
        return [*self.machines, *self.fields, *self.zones]


_SWATHS: Final = """
CREATE TEMP TABLE r ON COMMIT DROP AS
SELECT w.session_id, w.area_ha, w.applied_kg, w.target_kg, w.geom, w.utc, ss.machine_id,
       coalesce(f.name, %(nofield)s) AS field, z.zone AS pzone,
       w.area_ha * coalesce(z.rate_kg_ha, w.prescribed_kg_ha) AS prescribed_kg
FROM swath w
JOIN session ss ON ss.id = w.session_id
LEFT JOIN LATERAL (
    SELECT name FROM field f WHERE ST_Intersects(f.boundary, ST_PointOnSurface(w.geom)) LIMIT 1
) f ON true
LEFT JOIN LATERAL (
    SELECT zone, rate_kg_ha FROM prescription_zone z
    WHERE z.field = f.name AND ST_Intersects(z.geom, ST_PointOnSurface(w.geom))
    ORDER BY z.seq LIMIT 1
) z ON true
WHERE w.season = %(season)s
  AND (%(machine)s::text IS NULL OR ss.machine_id = %(machine)s)
  AND (%(since)s::date IS NULL OR w.utc >= %(since)s::date)
  AND (%(until)s::date IS NULL OR w.utc < %(until)s::date + 1)
"""

_GROUP: Final = """
SELECT {key}, count(DISTINCT session_id), sum(area_ha), sum(applied_kg), sum(target_kg),
       sum(prescribed_kg)
FROM r {where} GROUP BY {key} ORDER BY {key}
"""


def seasons(conn: psycopg.Connection[Any]) -> list[int]:
    with office_errors("reading the seasons"):
        rows = conn.execute("SELECT DISTINCT season FROM session ORDER BY season").fetchall()
        conn.rollback()
    return [int(r[0]) for r in rows]


def build(
    conn: psycopg.Connection[Any], season: int | None = None, filters: Filters | None = None
) -> Report:
    """The season's report (the latest season with sessions when None)."""
    farm = check(conn)
    filters = filters or Filters()
    if season is None:
        have = seasons(conn)
        if not have:
            raise OfficeError("the office has no sessions yet (send some: topdress office push)")
        season = have[-1]
    out = Report(season, farm, filters)
    args = {
        "season": season,
        "machine": filters.machine,
        "since": filters.since,
        "until": filters.until,
        "nofield": NO_FIELD,
    }
    with office_errors("office report"):
        conn.execute(_SWATHS, args)
        if filters.field is not None:
            conn.execute("DELETE FROM r WHERE field <> %s", (filters.field,))
        out.machines = _lines(conn, "machine", "machine_id")
        _add_summaries(conn, out, args)
        out.fields = _lines(conn, "field", "field")
        out.zones = _lines(conn, "zone", "field || ' / ' || pzone", "WHERE pzone IS NOT NULL")
        conn.execute("CREATE INDEX ON r (session_id)")
        out.double = _double(conn)
        out.uncovered = _uncovered(conn, filters.field)
        out.shapes = {
            str(name): shapely.from_wkb(bytes(wkb))
            for name, wkb in conn.execute(
                "SELECT name, ST_AsBinary(boundary) FROM field UNION ALL "
                "SELECT field || ' / ' || zone, ST_AsBinary(ST_Union(geom)) "
                "FROM prescription_zone GROUP BY field, zone"
            )
        }
        out.problems = [
            f"{r[0]:%Y-%m-%d %H:%M} {r[1]} {r[2]}: {r[3]}"
            for r in conn.execute(
                "SELECT p.detected, p.machine_id, p.file_name, p.problem FROM sync_problem p "
                "LEFT JOIN session s ON s.id = p.session_id "
                "WHERE s.season IS NULL OR s.season = %s ORDER BY p.id",
                (season,),
            )
        ]
        conn.rollback()  # the temporary table goes with it: the report wrote nothing
    return out


def _lines(conn: psycopg.Connection[Any], kind: str, key: str, where: str = "") -> list[Line]:
    rows = conn.execute(_GROUP.format(key=key, where=where)).fetchall()
    return [
        Line(
            kind,
            str(r[0]),
            int(r[1]),
            float(r[2] or 0),
            float(r[3] or 0),
            float(r[4] or 0),
            None if r[5] is None else float(r[5]),
        )
        for r in rows
    ]


def _add_summaries(conn: psycopg.Connection[Any], out: Report, args: dict[str, Any]) -> None:
    """The sessions' own summaries beside each machine's swaths (they should agree)."""
    rows = conn.execute(
        "SELECT machine_id, sum(applied_kg), sum(area_ha) FROM session "
        "WHERE season = %(season)s AND session.id IN (SELECT DISTINCT session_id FROM r) "
        "GROUP BY machine_id",
        args,
    ).fetchall()
    got = {str(r[0]): (float(r[1] or 0), float(r[2] or 0)) for r in rows}
    for line in out.machines:
        if line.name in got:
            line.summary_kg, line.summary_area_ha = got[line.name]


def _double(conn: psycopg.Connection[Any]) -> list[Overlap]:
    """Ground two machines both covered: the sessions' covers (the unions of their swaths,
    made when they were sent) of different machines that meet (found by their GiST index),
    intersected pair by pair, then joined per field and pair of machines."""
    rows = conn.execute(
        """
        WITH p AS (
            SELECT a.machine_id AS ma, b.machine_id AS mb,
                   ST_CollectionExtract(ST_Intersection(a.cover, b.cover), 3) AS g
            FROM session a JOIN session b
              ON a.cover && b.cover AND a.machine_id < b.machine_id
             AND ST_Intersects(a.cover, b.cover)
            WHERE a.id IN (SELECT session_id FROM r) AND b.id IN (SELECT session_id FROM r)),
        f AS (
            SELECT coalesce(f.name, %s) AS field, p.ma, p.mb,
                   CASE WHEN f.name IS NULL THEN p.g
                        ELSE ST_CollectionExtract(ST_Intersection(p.g, f.boundary), 3) END AS g
            FROM p LEFT JOIN field f ON ST_Intersects(p.g, f.boundary)),
        x AS (SELECT field, ma, mb, ST_UnaryUnion(ST_Collect(g)) AS g FROM f
              WHERE NOT ST_IsEmpty(g) GROUP BY field, ma, mb)
        SELECT field, ma, mb, ST_Area(g::geography) / 10000, ST_AsBinary(g) FROM x
        ORDER BY field, ma, mb
        """,
        (NO_FIELD,),
    ).fetchall()
    return [
        Overlap(str(r[0]), str(r[1]), str(r[2]), float(r[3]), shapely.from_wkb(bytes(r[4])))
        for r in rows
    ]


def _uncovered(conn: psycopg.Connection[Any], only: str | None) -> list[Uncovered]:
    """Each field's ground no session's cover reached."""
    rows = conn.execute(
        """
        WITH d AS (
            SELECT f.name, f.boundary, (
                SELECT ST_UnaryUnion(ST_Collect(s.cover)) FROM session s
                WHERE s.cover && f.boundary AND s.id IN (SELECT session_id FROM r)
            ) AS u
            FROM field f WHERE %s::text IS NULL OR f.name = %s),
        g AS (SELECT name, boundary,
                     CASE WHEN u IS NULL THEN boundary
                          ELSE ST_CollectionExtract(ST_Difference(boundary, u), 3) END AS g
              FROM d)
        SELECT name, ST_Area(boundary::geography) / 10000, ST_Area(g::geography) / 10000,
               ST_AsBinary(g)
        FROM g ORDER BY name
        """,
        (only, only),
    ).fetchall()
    return [
        Uncovered(str(r[0]), float(r[1]), float(r[2]), shapely.from_wkb(bytes(r[3]))) for r in rows
    ]


# ---- output ----


def figure(value: float | None, fmt: str = ".1f") -> str:
    return "-" if value is None else format(value, fmt)


def text(report: Report) -> str:
    f = report.filters
    shown = [
        f"field {f.field}" if f.field else "",
        f"machine {f.machine}" if f.machine else "",
        f"from {f.since}" if f.since else "",
        f"to {f.until}" if f.until else "",
    ]
    head = f"season {report.season}" + (f" of farm {report.farm}" if report.farm else "")
    out = [head + "".join(f", {s}" for s in shown if s)]
    for title, lines in (
        ("machine", report.machines),
        ("field", report.fields),
        ("field / zone", report.zones),
    ):
        out.append("")
        out.append(
            f"{title:<28} {'sessions':>8} {'ha':>9} {'applied kg':>11} {'kg/ha':>7} "
            f"{'prescr. kg':>11} {'kg/ha':>7} {'diff kg':>9} {'diff %':>7}"
        )
        for x in lines:
            out.append(
                f"{x.name:<28} {x.sessions:>8} {x.area_ha:>9.3f} {x.applied_kg:>11.1f} "
                f"{figure(x.applied_kg_ha):>7} {figure(x.prescribed_kg):>11} "
                f"{figure(x.prescribed_kg_ha):>7} {figure(x.diff_kg, '+.1f'):>9} "
                f"{figure(x.diff_pct, '+.1f'):>7}"
            )
        if not lines:
            out.append("  (none)")
        if title == "machine" and lines:
            out.append("  the sessions' own summaries (topdress log summary):")
            out.extend(
                f"  {x.name}: {figure(x.summary_kg)} kg over {figure(x.summary_area_ha, '.3f')} ha"
                for x in lines
            )
    out.append("")
    out.append("ground covered by two machines")
    for o in report.double:
        out.append(f"  {o.field}: {o.machine_a} and {o.machine_b}: {o.area_ha:.4f} ha")
    if not report.double:
        out.append("  (none)")
    out.append("")
    out.append("ground inside the boundary never covered")
    for u in report.uncovered:
        pct = 100.0 * u.uncovered_ha / u.field_ha if u.field_ha > 0 else 0.0
        out.append(f"  {u.field}: {u.uncovered_ha:.4f} ha of {u.field_ha:.4f} ha ({pct:.1f} %)")
    if not report.uncovered:
        out.append("  (no field boundaries in the office: topdress office field)")
    if report.problems:
        out.append("")
        out.append("sessions the office refused (changed or conflicting)")
        out.extend(f"  {p}" for p in report.problems)
    return "\n".join(out)


CSV_COLUMNS: Final = (
    "season",
    "table",
    "name",
    "sessions",
    "area_ha",
    "applied_kg",
    "applied_kg_ha",
    "prescribed_kg",
    "prescribed_kg_ha",
    "diff_kg",
    "diff_pct",
    "target_kg",
)


def write_csv(report: Report, out: TextIO) -> None:
    w = csv.writer(out)
    w.writerow(CSV_COLUMNS)
    for x in report.lines:
        w.writerow(
            [
                report.season,
                x.kind,
                x.name,
                x.sessions,
                _r(x.area_ha),
                _r(x.applied_kg),
                _r(x.applied_kg_ha),
                _r(x.prescribed_kg),
                _r(x.prescribed_kg_ha),
                _r(x.diff_kg),
                _r(x.diff_pct),
                _r(x.target_kg),
            ]
        )
    for o in report.double:
        w.writerow(
            [
                report.season,
                "double",
                f"{o.field} / {o.machine_a} + {o.machine_b}",
                "",
                _r(o.area_ha),
            ]
            + [""] * 7
        )
    for u in report.uncovered:
        w.writerow([report.season, "uncovered", u.field, "", _r(u.uncovered_ha)] + [""] * 7)


def _r(value: float | None) -> str:
    return "" if value is None else f"{value:.6g}"


_TEXT_COLUMNS: Final = frozenset({"name", "field", "machine_a", "machine_b"})


def write_gpkg(report: Report, path: Path) -> None:
    """The report for a GIS: the dose per field and per zone on their polygons (`fields`,
    `zones`), and the ground covered twice and never (`double_coverage`, `never_covered`)."""
    if path.exists():
        path.unlink()

    def dose(lines: list[Line]) -> tuple[dict[str, list[Any]], list[Any]]:
        drawn = [x for x in lines if x.name in report.shapes]
        cols: dict[str, list[Any]] = {
            "name": [x.name for x in drawn],
            "sessions": [float(x.sessions) for x in drawn],
            "area_ha": [x.area_ha for x in drawn],
            "applied_kg": [x.applied_kg for x in drawn],
            "applied_kg_ha": [x.applied_kg_ha for x in drawn],
            "prescribed_kg": [x.prescribed_kg for x in drawn],
            "prescribed_kg_ha": [x.prescribed_kg_ha for x in drawn],
            "diff_kg": [x.diff_kg for x in drawn],
            "diff_pct": [x.diff_pct for x in drawn],
        }
        return cols, [report.shapes[x.name] for x in drawn]

    layers: tuple[tuple[str, dict[str, list[Any]], list[Any]], ...] = (
        ("fields", *dose(report.fields)),
        ("zones", *dose(report.zones)),
        (
            "double_coverage",
            {
                "field": [o.field for o in report.double],
                "machine_a": [o.machine_a for o in report.double],
                "machine_b": [o.machine_b for o in report.double],
                "area_ha": [o.area_ha for o in report.double],
            },
            [o.geom for o in report.double],
        ),
        (
            "never_covered",
            {
                "field": [u.field for u in report.uncovered],
                "field_ha": [u.field_ha for u in report.uncovered],
                "uncovered_ha": [u.uncovered_ha for u in report.uncovered],
            },
            [u.geom for u in report.uncovered],
        ),
    )
    try:
        for i, (name, cols, geoms) in enumerate(layers):
            multi = [shapely.multipolygons(shapely.get_parts(g)) for g in geoms]
            table = pa.table(
                {
                    k: pa.array(v, type=pa.string() if k in _TEXT_COLUMNS else pa.float64())
                    for k, v in cols.items()
                }
                | {
                    "geometry": pa.array(
                        shapely.to_wkb(np.array(multi, dtype=object)).tolist(), type=pa.binary()
                    )
                }
            )
            pyogrio.write_arrow(
                table,
                str(path),
                layer=name,
                driver="GPKG",
                geometry_name="geometry",
                geometry_type="MultiPolygon",
                crs="EPSG:4326",
                append=i > 0,
            )
    except (pyogrio.errors.DataSourceError, pyogrio.errors.FieldError, OSError) as exc:
        raise OfficeError(f"cannot write {path}: {exc}") from exc
