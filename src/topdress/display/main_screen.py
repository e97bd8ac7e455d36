"""The main screen: what the machine does now, the last minute in charts, and the map."""

from __future__ import annotations

from nicegui import ui

from topdress.display import fmt
from topdress.display.actions import Actions
from topdress.display.charts import meter_options, speed_options
from topdress.display.hub import DisplayHub
from topdress.display.map_view import LiveMap
from topdress.i18n import render, tr
from topdress.view import commands as op
from topdress.view.snapshot import AlarmView, CounterView, Snapshot

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

    def __init__(self, hub: DisplayHub, actions: Actions, width_m: float, max_kg_ha: float) -> None:
        self.hub = hub
        self.actions = actions
        self._chart_t = -1e9
        self._alarms: tuple[AlarmView, ...] | None = None
        self._build_controls()
        self._build(width_m, max_kg_ha)

    def _build_controls(self) -> None:
        send = self.actions.send
        with ui.row().classes("w-full items-center gap-3"):
            ui.button(tr("op.start"), icon="play_arrow", on_click=lambda: send(op.Start())).props(
                "color=green-8 size=xl"
            ).classes("w-44 h-20").mark("start")
            # Stop: always there, always one touch.
            ui.button(tr("op.stop"), icon="stop", on_click=lambda: send(op.Stop())).props(
                "color=red-9 size=xl"
            ).classes("w-44 h-20").mark("stop")
            ui.button(tr("op.pause"), icon="pause", on_click=lambda: send(op.Pause())).props(
                "color=amber-9 size=lg"
            ).classes("w-36 h-20").mark("pause")
            with ui.column().classes("gap-0"):
                self.state = ui.label("--").classes("text-3xl font-bold").mark("op_state")
                self.manual = ui.label("").classes("text-lg font-bold").mark("manual_state")
            ui.space()
            with ui.expansion(tr("manual.title"), icon="tune").classes("border rounded"):
                self._build_manual()

    def _build_manual(self) -> None:
        kgha = tr("unit.kgha")
        modes = {m: tr(f"manual.{m}") for m in op.MANUAL_MODES}
        mode = ui.radio(modes, value="off").props("inline").mark("manual_mode")
        with ui.row().classes("gap-2"):
            upper = ui.number(f"{tr('main.upper')} ({kgha})", value=100.0, min=0, max=600)
            lower = ui.number(f"{tr('main.lower')} ({kgha})", value=100.0, min=0, max=600)
            pct = ui.number(f"± {tr('unit.pct')}", value=0.0, min=-100, max=200)
        upper.classes("w-32").mark("manual_upper")
        lower.classes("w-32").mark("manual_lower")
        pct.classes("w-24").mark("manual_percent")

        async def apply() -> None:
            await self.actions.send(
                op.SetManual(
                    str(mode.value),
                    float(upper.value or 0.0),
                    float(lower.value or 0.0),
                    float(pct.value or 0.0),
                )
            )

        ui.button(tr("action.apply"), on_click=apply).mark("manual_apply")

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
                self.lag = ui.label("").classes("text-sm").mark("gnss_lag")
            with ui.card().classes("gap-2"):
                ui.label(tr("main.ndvi")).classes("text-sm font-bold")
                with ui.row().classes("gap-4"):
                    self.ndvi_sensors = _value(tr("main.ndvi_sensors"), "ndvi_sensors")
                    self.ndvi_meters = _value(tr("main.ndvi_meters"), "ndvi_meters")
                self.per_sensor = ui.label("").classes("text-sm font-mono").mark("ndvi_per_sensor")
                self.crop = ui.label("").classes("text-sm").mark("crop_sensors")
            with ui.card().classes("gap-2"):
                ui.label(tr("main.metering")).classes("text-sm font-bold")
                with ui.grid(columns=3).classes("gap-x-4 gap-y-1 items-baseline"):
                    ui.label("")
                    ui.label(tr("main.upper")).classes("text-xs text-gray-500")
                    ui.label(tr("main.lower")).classes("text-xs text-gray-500")
                    self.model = self._pair(f"{tr('main.rate_model')} ({kgha})", "rate_model")
                    self.rate = self._pair(f"{tr('main.rate_set')} ({kgha})", "rate")
                    self.applied = self._pair(f"{tr('main.rate_applied')} ({kgha})", "applied")
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
            with ui.card().classes("gap-1 min-w-64"):
                with ui.row().classes("items-center"):
                    ui.label(tr("alarm.title")).classes("text-sm font-bold")
                    ui.button(
                        tr("alarm.ack_all"), on_click=lambda: self.actions.send(op.AckAlarm(None))
                    ).props("dense flat").mark("ack_all")
                self.alarm_list = ui.column().classes("gap-1")
            with ui.card().classes("gap-1"):
                ui.label(tr("count.title")).classes("text-sm font-bold")
                self.counters = {}
                with ui.grid(columns=3).classes("gap-x-4 gap-y-0 items-baseline"):
                    ui.label("")
                    for which in ("field", "season"):
                        with ui.row().classes("items-center gap-1"):
                            ui.label(tr(f"count.{which}")).classes("text-xs text-gray-500")
                            ui.button(
                                icon="restart_alt",
                                on_click=lambda w=which: self.actions.send(op.ResetCounter(w)),
                            ).props("dense flat size=sm").mark(f"reset_{which}")
                    for row in ("area", "kg_upper", "kg_lower", "time", "distance"):
                        ui.label(tr(f"count.{row}")).classes("text-xs text-gray-500")
                        for which in ("field", "season"):
                            self.counters[(which, row)] = (
                                ui.label("--").classes("font-mono").mark(f"count_{which}_{row}")
                            )
        with ui.row().classes("w-full gap-3 items-stretch"):
            with ui.card().classes("flex-1 min-w-80"):
                ui.label(tr("chart.speed_title")).classes("text-sm font-bold")
                self.speed_chart = ui.echart(speed_options([])).classes("w-full h-64")
            with ui.card().classes("flex-1 min-w-80"):
                ui.label(tr("chart.meter_title")).classes("text-sm font-bold")
                self.meter_chart = ui.echart(meter_options([])).classes("w-full h-64")
            with ui.card().classes("flex-1 min-w-80 gap-1"):
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
        self._update_operator(s)
        live = s.ecu_live
        self.v_sel.set_text(fmt.ecu(s, s.v_kmh, ".1f"))
        self.v_wheel.set_text(fmt.ecu(s, s.v_wheel_kmh, ".1f"))
        self.v_gnss.set_text(fmt.num(s.gnss_kmh, ".1f"))
        source = s.source if live else "none"
        self.source.set_text(tr(f"source.{source}") if source != "none" else "--")
        colour = "primary" if source == "gnss" else "orange"
        if self.source.props.get("color") != colour:
            self.source.props["color"] = colour
        self.why.set_text(render(s.speed_why) if live else "")
        self.lag.set_text(render(s.gnss_lag.text()) if live and s.gnss_lag else "")
        self.ndvi_sensors.set_text(fmt.num(s.ndvi_sensors, ".3f"))
        self.ndvi_meters.set_text(fmt.num(s.ndvi, ".3f"))
        self.per_sensor.set_text(
            "  ".join(f"{i}: {fmt.num(v, '.3f')}" for i, v in enumerate(s.ndvi_per_sensor, 1))
        )
        self.crop.set_text(f"{tr('main.crop_sensors')}: {fmt.link_text(s.crop_link)}")
        for (up, lo), (vu, vl), ecu_value in (
            (self.model, s.rate_model_kg_ha, False),
            (self.rate, s.rate_kg_ha, False),
            (self.applied, s.applied_kg_ha, True),
            (self.target, s.target_rpm, True),
            (self.meter, s.meter_rpm, True),
            (self.fan, s.fan_rpm, True),
        ):
            spec = ".0f" if (up, lo) == self.fan else ".1f"
            up.set_text(fmt.ecu(s, vu, spec) if ecu_value else fmt.num(vu, spec))
            lo.set_text(fmt.ecu(s, vl, spec) if ecu_value else fmt.num(vl, spec))
        where = f" ({s.ecu_where})" if s.ecu_link == "wait" and s.ecu_where else ""
        for kind, state in (("ecu", s.ecu_link), ("gnss", s.gnss_link), ("crop", s.crop_link)):
            text = f"{tr(f'link_name.{kind}')}: {fmt.link_text(state)}"
            self.links[kind].set_text(text + (where if kind == "ecu" else ""))
            ok = state == "ok"
            fmt.restyle(
                self.links[kind],
                "text-base " + ("text-green-700" if ok else "text-red-700 font-bold"),
            )
        self.faults.set_text(fmt.faults_text(s))
        self.event.set_text(render(s.last_event))
        if s.t_s - self._chart_t >= CHART_PERIOD_S or s.t_s < self._chart_t:
            self._chart_t = s.t_s
            history = self.hub.history()
            self.speed_chart.options.update(speed_options(history))
            self.speed_chart.update()
            self.meter_chart.options.update(meter_options(history))
            self.meter_chart.update()
            self.map.update()

    def _update_operator(self, s: Snapshot) -> None:
        self.state.set_text(tr(f"op.state.{s.operator}"))
        colour = {"running": "text-green-700", "paused": "text-amber-700"}.get(s.operator, "")
        fmt.restyle(self.state, f"text-3xl font-bold {colour}")
        m = s.manual
        if m.mode == "fixed":
            text = tr(
                "manual.shown_fixed", upper=f"{m.upper_kg_ha:.1f}", lower=f"{m.lower_kg_ha:.1f}"
            )
        elif m.mode == "percent":
            text = tr("manual.shown_percent", percent=f"{m.percent:+.0f}")
        else:
            text = ""
        self.manual.set_text(text)
        fmt.restyle(
            self.manual, "text-lg font-bold text-white bg-orange-700 px-2 rounded" if text else ""
        )
        for which, c in (("field", s.count_field), ("season", s.count_season)):
            self._update_counter(which, c)
        if s.alarms != self._alarms:
            self._alarms = s.alarms
            self._draw_alarms(s.alarms)

    def _update_counter(self, which: str, c: CounterView) -> None:
        h, rem = divmod(int(c.work_s), 3600)
        values = {
            "area": f"{c.area_ha:.3f} {tr('unit.ha')}",
            "kg_upper": f"{c.kg[0]:.1f} {tr('unit.kg')}",
            "kg_lower": f"{c.kg[1]:.1f} {tr('unit.kg')}",
            "time": f"{h}:{rem // 60:02d}:{rem % 60:02d}",
            "distance": f"{c.distance_m:.0f} {tr('unit.m')}",
        }
        for row, text in values.items():
            self.counters[(which, row)].set_text(text)

    def _draw_alarms(self, alarms: tuple[AlarmView, ...]) -> None:
        self.alarm_list.clear()
        with self.alarm_list:
            if not alarms:
                ui.label(tr("alarm.none")).classes("text-green-700").mark("alarm_none")
            for a in alarms:
                text = render(a.text)  # with its figures
                colour = {"active": "text-red-700 font-bold", "acked": "text-amber-800"}.get(
                    a.state, "text-gray-600"
                )
                with ui.row().classes("items-center gap-2"):
                    ui.label(f"{text} · {tr(f'alarm.state.{a.state}')}").classes(colour).mark(
                        f"alarm_{a.name}"
                    )
                    if a.state != "acked":
                        ui.button(
                            tr("alarm.ack"),
                            on_click=lambda n=a.name: self.actions.send(op.AckAlarm(n)),
                        ).props("dense size=sm").mark(f"ack_{a.name}")
