"""The farm office's web page (`topdress office serve`): a season's map of every machine's
covered ground over the fields and prescription zones, filterable by field, machine and date,
with the report beside it. Its own process, NiceGUI as the cab's display; it only reads (the
report's scratch table is a temporary one, rolled back; a role with SELECT and TEMPORARY is
enough, docs/office.md), and the queries run off the event loop."""

from __future__ import annotations

import asyncio
from datetime import date
from typing import Any

import psycopg
from nicegui import ui

from topdress.display.map_view import rate_colour
from topdress.errors import OfficeError
from topdress.office import report
from topdress.office.schema import connect
from topdress.office.season_map import SeasonMap, season_map

#: a machine's colour on the map, by its place in the list of machines
PALETTE = (
    "#1b9e77",
    "#d95f02",
    "#7570b3",
    "#e7298a",
    "#66a61e",
    "#e6ab02",
    "#a6761d",
    "#666666",
    "#1f78b4",
    "#b2df8a",
)


def _read(conninfo: str, season: int | None, filters: report.Filters) -> tuple[Any, SeasonMap]:
    conn: psycopg.Connection[Any] = connect(conninfo)
    try:
        rep = report.build(conn, season, filters)
        return rep, season_map(conn, rep.season, filters)
    finally:
        conn.close()


def _date(text: str | None) -> date | None:
    try:
        return date.fromisoformat(text) if text else None
    except ValueError:
        return None


def register(conninfo: str) -> None:
    @ui.page("/")
    async def office_page() -> None:
        ui.page_title("topdress office")
        with ui.row().classes("w-full no-wrap items-end gap-4"):
            ui.label("topdress office").classes("text-h6")
            season = ui.select([], label="season").classes("w-28").mark("season")
            fld = ui.select({"": "all fields"}, value="", label="field").classes("w-48")
            fld.mark("field")
            machine = ui.select({"": "all machines"}, value="", label="machine")
            machine.classes("w-48").mark("machine")
            since = ui.input("from (YYYY-MM-DD)").classes("w-40").mark("since")
            until = ui.input("to (YYYY-MM-DD)").classes("w-40").mark("until")
        status = ui.label("").mark("status")
        with ui.row().classes("w-full no-wrap gap-4"):
            fmap = (
                ui.leaflet(center=(0.0, 0.0), zoom=16, options={"attributionControl": False})
                .style("height: 75vh; width: 55%")
                .mark("map")
            )
            fmap.clear_layers()  # no tile server: the shapes on a blank ground
            with ui.column().classes("flex-1"):
                table = (
                    ui.table(
                        columns=[
                            {"name": c, "label": c, "field": c, "align": "left"}
                            for c in (
                                "table",
                                "name",
                                "ha",
                                "applied kg",
                                "kg/ha",
                                "prescribed kg",
                                "diff kg",
                                "diff %",
                            )
                        ],
                        rows=[],
                    )
                    .props("dense flat")
                    .classes("w-full")
                    .mark("report")
                )
                extra = ui.column().classes("text-sm").mark("areas")
        layers: list[Any] = []

        async def refresh() -> None:
            filters = report.Filters(
                fld.value or None, machine.value or None, _date(since.value), _date(until.value)
            )
            try:
                rep, smap = await asyncio.to_thread(_read, conninfo, season.value, filters)
            except OfficeError as exc:
                status.set_text(str(exc))
                return
            status.set_text(f"season {rep.season}: {len(smap.covers)} sessions drawn")
            season.set_options(smap.seasons, value=rep.season)
            fld.set_options({"": "all fields"} | {n: n for n in smap.field_names})
            machine.set_options({"": "all machines"} | {m: m for m in smap.machines})
            table.rows = [
                {
                    "table": x.kind,
                    "name": x.name,
                    "ha": f"{x.area_ha:.3f}",
                    "applied kg": f"{x.applied_kg:.1f}",
                    "kg/ha": report.figure(x.applied_kg_ha),
                    "prescribed kg": report.figure(x.prescribed_kg),
                    "diff kg": report.figure(x.diff_kg, "+.1f"),
                    "diff %": report.figure(x.diff_pct, "+.1f"),
                }
                for x in rep.lines
            ]
            table.update()
            extra.clear()
            with extra:
                for o in rep.double:
                    ui.label(
                        f"covered twice: {o.field}: {o.machine_a} + {o.machine_b}: "
                        f"{o.area_ha:.4f} ha"
                    )
                for u in rep.uncovered:
                    ui.label(
                        f"never covered: {u.field}: {u.uncovered_ha:.4f} of {u.field_ha:.4f} ha"
                    )
            _draw(smap)

        def _draw(smap: SeasonMap) -> None:
            for layer in layers:
                fmap.remove_layer(layer)
            layers.clear()
            top = max((z.value for z in smap.zones), default=1.0) or 1.0
            for z in smap.zones:
                style = {
                    "color": "#37474f",
                    "weight": 1,
                    "fillColor": rate_colour(z.value, top),
                    "fillOpacity": 0.2,
                }
                layers.append(fmap.generic_layer(name="polygon", args=[z.rings, style]))
            colours = {m: PALETTE[i % len(PALETTE)] for i, m in enumerate(smap.machines)}
            for c in smap.covers:
                style = {
                    "stroke": False,
                    "fillColor": colours.get(c.label, "#000"),
                    "fillOpacity": 0.55,
                }
                layers.append(fmap.generic_layer(name="polygon", args=[c.rings, style]))
            for f in smap.fields:
                style = {"color": "#000", "weight": 3, "fill": False}
                layers.append(fmap.generic_layer(name="polygon", args=[f.rings, style]))
            points = [p for s in (*smap.fields, *smap.covers) for r in s.rings for p in r]
            if points:
                lats, lons = [p[0] for p in points], [p[1] for p in points]
                bounds = [[min(lats), min(lons)], [max(lats), max(lons)]]
                fmap.run_map_method("fitBounds", bounds, {"padding": [8, 8]})

        for control in (season, fld, machine):
            control.on_value_change(refresh)
        for box in (since, until):
            box.on("keydown.enter", refresh)
            box.on("blur", refresh)
        await ui.context.client.connected()
        await refresh()
        for element in list(ui.context.client.elements.values()):
            if element._markers and "data-testid" not in element.props:
                element.props["data-testid"] = element._markers[0]
                element.update()


def serve(conninfo: str, host: str, port: int) -> None:
    """Serve the page until stopped (Ctrl-C)."""
    register(conninfo)
    ui.run(
        host=host,
        port=port,
        title="topdress office",
        reload=False,
        show=False,
        show_welcome_message=False,
        uvicorn_logging_level="warning",
    )
