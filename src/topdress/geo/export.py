"""A session's as-applied map to a file, in the format asked for: vector formats (GeoPackage,
shapefile, GeoJSON, CSV) or ISO 11783-10 task data, and its CAN traffic as a trace."""

from __future__ import annotations

from pathlib import Path

from topdress.geo import asapplied, cantrace, isoxml, vector
from topdress.log.session import SessionReader


def export_maps(
    reader: SessionReader,
    out: Path | None,
    fmt: str,
    crs: str,
    can_out: Path | None,
    fmis: bool = False,
) -> list[str]:
    """As-applied points and swaths (or ISO 11783-10 task data) to `out`, the CAN traffic to
    `can_out`; returns one line per file written, and what the session lacked. `fmis`: the
    Shapefile for farm management software (numeric attributes only)."""
    lines: list[str] = []
    if out is not None:
        # written a chunk of the session at a time
        stream = asapplied.AsAppliedStream(reader)
        asapplied.require_any_point(stream)
        if fmt == "isoxml":
            implement = isoxml.implement_of(reader)
            files = isoxml.write_taskdata(stream, out, reader.path.stem, implement)
        else:
            files = vector.write(stream, out, fmt, crs, fmis)
        lines += [str(f) for f in files]
        lines.append(
            f"{stream.points} points, "
            + ("" if fmt == "isoxml" else f"{stream.swaths} swaths, ")  # a time log: points
            + f"{stream.applied_kg:.2f} kg "
            f"applied (of {stream.rows} state rows)"
        )
        lines += [f"note: {n}" for n in stream.notes]
    if can_out is not None:
        n = cantrace.write_trace(reader, can_out)
        lines.append(f"{can_out}: {n} CAN frames")
    return lines
