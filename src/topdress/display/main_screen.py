"""The main screen: what the machine does now, the last minute in charts, and the map."""

from __future__ import annotations

from nicegui import ui

from topdress.display import fmt
from topdress.display.charts import meter_options, speed_options
from topdress.display.hub import DisplayHub
from topdress.display.map_view import LiveMap
from topdress.i18n import tr
from topdress.terminal.app import Snapshot

CHART_PERIOD_S = 1.0  # charts and map redraw at 1 Hz; the numbers at the page's timer rate


def _value(label: str, marker: str, unit: str = "") -> ui.label:
    """A caption over a large value; returns the value's label."""
    with ui.column().classes("gap-0 min-w-28"):
        ui.label(label).classes("text-xs text-gray-500")
        with ui.row().classes("items-baseline gap-1"):
            value = ui.label("--").classes("text-2xl font-mono").mark(marker)
            if unit:
                ui.label(unit).classes("text-xs text-gray-500")
    return value


class MainScreen:
    """Built once per page; `update(snapshot)` rewrites the values."""

    def __init__(self, hub: DisplayHub, width_m: float, max_kg_ha: float) -> None:
        self.hub = hub
        self._chart_t = -1e9
        self._build(width_m, max_kg_ha)

    def _build(self, width_m: float, max_kg_ha: float) -> None:
        kmh, kgha, rpm = tr("unit.kmh"), tr("unit.kgha"), tr("unit.rpm")
        with ui.row().classes("w-full items-stretch gap-3"):
            with ui.card().classes("gap-2"):
                ui.label(tr("main.speed")).classes("text-sm font-bold")
                with ui.row().classes("gap-4"):
                    self.v_sel = _value(tr("main.selected"), "v_selected", kmh)
                    self.v_wheel = _value(tr("main.wheel"), "v_wheel", kmh)
                    self.v_gnss = _value(tr("main.gnss"), "v_gnss", kmh)
                with ui.row().classes("items-center gap-2"):
                    ui.label(tr("main.source")).classes("text-xs text-gray-500")
                    self.source = ui.badge("--").classes("text-base").mark("source")
                self.why = ui.label("").classes("text-sm").mark("source_why")
            with ui.card().classes("gap-2"):
                ui.label(tr("main.ndvi")).classes("text-sm font-bold")
                with ui.row().classes("gap-4"):
                    self.ndvi_sensors = _value(tr("main.ndvi_sensors"), "ndvi_sensors")
                    self.ndvi_meters = _value(tr("main.ndvi_meters"), "ndvi_meters")
                self.crop = ui.label("").classes("text-sm").mark("crop_sensors")
            with ui.card().classes("gap-2"):
                ui.label(tr("main.metering")).classes("text-sm font-bold")
                with ui.grid(columns=3).classes("gap-x-4 gap-y-1 items-baseline"):
                    ui.label("")
                    ui.label(tr("main.upper")).classes("text-xs text-gray-500")
                    ui.label(tr("main.lower")).classes("text-xs text-gray-500")
                    self.rate = self._pair(f"{tr('main.rate_set')} ({kgha})", "rate")
                    self.target = self._pair(f"{tr('main.target')} ({rpm})", "target")
                    self.meter = self._pair(f"{tr('main.measured')} ({rpm})", "meter")
                    self.fan = self._pair(f"{tr('main.fans')} ({rpm})", "fan")
            with ui.card().classes("gap-2"):
                ui.label(tr("main.links")).classes("text-sm font-bold")
                self.links = {
                    k: ui.label("--").classes("text-base").mark(f"link_{k}")
                    for k in ("ecu", "gnss", "crop")
                }
                ui.label(tr("main.faults")).classes("text-xs text-gray-500")
                self.faults = ui.label("--").classes("text-base").mark("faults")
                self.event = ui.label("").classes("text-xs text-gray-600").mark("last_event")
        with ui.row().classes("w-full gap-3"):
            with ui.card().classes("flex-1 min-w-80"):
                ui.label(tr("chart.speed_title")).classes("text-sm font-bold")
                self.speed_chart = ui.echart(speed_options([])).classes("w-full h-56")
            with ui.card().classes("flex-1 min-w-80"):
                ui.label(tr("chart.meter_title")).classes("text-sm font-bold")
                self.meter_chart = ui.echart(meter_options([])).classes("w-full h-56")
        with ui.card().classes("w-full"):
            with ui.row().classes("items-center gap-3"):
                ui.label(tr("map.title")).classes("text-sm font-bold")
                ui.label(tr("map.legend", max=f"{max_kg_ha:.0f}", unit=kgha)).classes(
                    "text-xs text-gray-600"
                )
            self.map = LiveMap(self.hub, width_m, max_kg_ha)

    def _pair(self, caption: str, marker: str) -> tuple[ui.label, ui.label]:
        ui.label(caption).classes("text-xs text-gray-500")
        return (
            ui.label("--").classes("text-xl font-mono").mark(f"{marker}_upper"),
            ui.label("--").classes("text-xl font-mono").mark(f"{marker}_lower"),
        )

    def update(self, s: Snapshot) -> None:
        live = s.ecu_live
        self.v_sel.set_text(fmt.ecu(s, s.v_kmh, ".1f"))
        self.v_wheel.set_text(fmt.ecu(s, s.v_wheel_kmh, ".1f"))
        self.v_gnss.set_text(fmt.num(s.v_gnss_kmh, ".1f"))
        source = s.source if live else "none"
        self.source.set_text(tr(f"source.{source}") if source != "none" else "--")
        self.source.props(f"color={'primary' if source == 'gnss' else 'orange'}")
        self.why.set_text(self._why(s))
        self.ndvi_sensors.set_text(fmt.num(s.ndvi_sensors, ".3f"))
        self.ndvi_meters.set_text(fmt.num(s.ndvi, ".3f"))
        self.crop.set_text(f"{tr('main.crop_sensors')}: {fmt.link_text('crop', s.crop_link)}")
        for (up, lo), (vu, vl), ecu_value in (
            (self.rate, s.rate_kg_ha, False),
            (self.target, s.target_rpm, True),
            (self.meter, s.meter_rpm, True),
            (self.fan, s.fan_rpm, True),
        ):
            spec = ".0f" if (up, lo) == self.fan else ".1f"
            up.set_text(fmt.ecu(s, vu, spec) if ecu_value else fmt.num(vu, spec))
            lo.set_text(fmt.ecu(s, vl, spec) if ecu_value else fmt.num(vl, spec))
        where = f" ({s.ecu_where})" if s.ecu_link == "wait" and s.ecu_where else ""
        for kind, state in (("ecu", s.ecu_link), ("gnss", s.gnss_link), ("crop", s.crop_link)):
            text = f"{tr(f'link_name.{kind}')}: {fmt.link_text(kind, state)}"
            self.links[kind].set_text(text + (where if kind == "ecu" else ""))
            ok = state == "ok"
            self.links[kind].classes(
                replace="text-base " + ("text-green-700" if ok else "text-red-700 font-bold")
            )
        self.faults.set_text(fmt.faults_text(s))
        self.event.set_text(s.last_event or "")
        if s.t_s - self._chart_t >= CHART_PERIOD_S or s.t_s < self._chart_t:
            self._chart_t = s.t_s
            history = self.hub.history()
            self.speed_chart.options.update(speed_options(history))
            self.speed_chart.update()
            self.meter_chart.options.update(meter_options(history))
            self.meter_chart.update()
            self.map.update()

    @staticmethod
    def _why(s: Snapshot) -> str:
        """Why the ECU runs on its source: the CV against uniform motion (the ECU decides)."""
        if not s.ecu_live or s.cv_pct is None:
            return ""
        motion = tr("main.uniform") if s.uniform else tr("main.varying")
        return tr("main.why", cv=f"{s.cv_pct:.2f}", motion=motion)
