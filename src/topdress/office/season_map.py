"""What the office's web page draws for a season: the fields, their prescription zones and
every session's cover (its swaths' union) by machine, as rings of (lat, lon) — read from the
database, no UI here (the page is topdress.display.office_page)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any, Final

import psycopg

from topdress.office.report import Filters
from topdress.office.schema import office_errors

Ring = list[tuple[float, float]]
MAX_SESSIONS: Final = 2000  # covers drawn at most (a season of 10 machines x 200 sessions)
#: drawn at about 0.5 m: a browser draws a season of covers at once
DRAW_TOLERANCE_DEG: Final = 5e-6


@dataclass
class Shape:
    rings: list[Ring]  # outer rings of the polygons (holes left out of the overview)
    label: str
    value: float = 0.0  # a zone's rate, kg/ha


@dataclass
class SeasonMap:
    fields: list[Shape] = field(default_factory=list)
    zones: list[Shape] = field(default_factory=list)
    covers: list[Shape] = field(default_factory=list)  # label: the machine
    machines: list[str] = field(default_factory=list)
    field_names: list[str] = field(default_factory=list)
    seasons: list[int] = field(default_factory=list)


def _rings(geojson: str | None) -> list[Ring]:
    if geojson is None:
        return []
    g = json.loads(geojson)
    polys = g["coordinates"] if g["type"] == "MultiPolygon" else [g["coordinates"]]
    if g["type"] not in ("Polygon", "MultiPolygon"):
        return []
    return [[(lat, lon) for lon, lat, *_ in poly[0]] for poly in polys if poly]


def season_map(conn: psycopg.Connection[Any], season: int, filters: Filters) -> SeasonMap:
    out = SeasonMap()
    with office_errors("reading the season's map"):
        out.seasons = [
            int(r[0]) for r in conn.execute("SELECT DISTINCT season FROM session ORDER BY 1")
        ]
        out.machines = [str(r[0]) for r in conn.execute("SELECT id FROM machine ORDER BY id")]
        out.field_names = [str(r[0]) for r in conn.execute("SELECT name FROM field ORDER BY 1")]
        for name, gj in conn.execute(
            "SELECT name, ST_AsGeoJSON(boundary, 7) FROM field "
            "WHERE %(f)s::text IS NULL OR name = %(f)s ORDER BY name",
            {"f": filters.field},
        ):
            out.fields.append(Shape(_rings(gj), str(name)))
        for name, rate, gj in conn.execute(
            "SELECT zone, rate_kg_ha, ST_AsGeoJSON(geom, 7) FROM prescription_zone "
            "WHERE %(f)s::text IS NULL OR field = %(f)s ORDER BY field, seq",
            {"f": filters.field},
        ):
            out.zones.append(Shape(_rings(gj), str(name), float(rate)))
        rows = conn.execute(
            """
            SELECT s.machine_id, ST_AsGeoJSON(ST_Simplify(
                CASE WHEN f.boundary IS NULL THEN s.cover
                     ELSE ST_CollectionExtract(ST_Intersection(s.cover, f.boundary), 3) END,
                %(tol)s), 7)
            FROM session s LEFT JOIN field f ON f.name = %(f)s
            WHERE s.season = %(season)s AND s.cover IS NOT NULL
              AND (%(m)s::text IS NULL OR s.machine_id = %(m)s)
              AND (%(since)s::date IS NULL OR s.end_utc >= %(since)s::date)
              AND (%(until)s::date IS NULL OR s.start_utc < %(until)s::date + 1)
              AND (f.boundary IS NULL OR s.cover && f.boundary)
            ORDER BY s.start_utc LIMIT %(n)s
            """,
            {
                "season": season,
                "f": filters.field,
                "m": filters.machine,
                "since": filters.since,
                "until": filters.until,
                "tol": DRAW_TOLERANCE_DEG,
                "n": MAX_SESSIONS,
            },
        )
        for machine, gj in rows:
            out.covers.append(Shape(_rings(gj), str(machine)))
        conn.rollback()
    return out
