"""Fields, their boundaries and prescriptions, imported from the files the terminal reads
(the same loaders: `topdress.geo.boundary`, `topdress.geo.prescription`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import psycopg
import shapely

from topdress.config import BoundaryConfig, PrescriptionConfig
from topdress.errors import OfficeError
from topdress.geo.boundary import load_boundary
from topdress.geo.prescription import PolygonPrescription, load_prescription
from topdress.office.schema import check, office_errors


def _multi(geom: Any) -> str:
    multi = shapely.multipolygons(shapely.get_parts(geom))
    return str(shapely.to_wkb(shapely.set_srid(multi, 4326), hex=True, include_srid=True))


def import_field(
    conn: psycopg.Connection[Any],
    name: str,
    boundary: Path,
    prescription: Path | None = None,
    attribute: str = "rate",
    units: str = "kg/ha",
) -> int:
    """Add or replace field `name`; the number of prescription zones imported."""
    check(conn)
    outline = load_boundary(BoundaryConfig(path=str(boundary)))
    zones: list[tuple[str, float, str]] = []
    if prescription is not None:
        rx = load_prescription(
            PrescriptionConfig(path=str(prescription), attribute=attribute, units=units)
        )
        if not isinstance(rx, PolygonPrescription):
            raise OfficeError(
                f"{prescription}: the office imports polygon prescriptions (GeoPackage, "
                "Shapefile, GeoJSON), not ISOXML grids"
            )
        zones = [
            (rx.label(i), float(rx.rate[i]), _multi(rx.geoms[i])) for i in range(rx.geoms.size)
        ]
    with office_errors(f"importing field {name}"):
        conn.execute("DELETE FROM field WHERE name = %s", (name,))
        conn.execute(
            "INSERT INTO field (name, boundary, source) VALUES (%s, %s::geometry, %s)",
            (name, _multi(outline.boundary), str(boundary)),
        )
        with conn.cursor() as cur:
            cur.executemany(
                "INSERT INTO prescription_zone (field, seq, zone, rate_kg_ha, geom) "
                "VALUES (%s, %s, %s, %s, %s::geometry)",
                [(name, i, z, r, g) for i, (z, r, g) in enumerate(zones)],
            )
        conn.commit()
    return len(zones)
