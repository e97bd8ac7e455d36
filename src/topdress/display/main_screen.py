"""The main screen, laid out for a cab terminal (800×480 and up, no scrolling).

Left, what the driver works with: Start and Pause (Stop and the alarm banner are in the header
of every screen), the rate per layer (target and applied) with one-touch +/- steps and the
manual mode in force, the speed with its source, the tank and the area left. Right, one touch
apart: the map (boundary, prescription zones, swath, machine), the last minute in charts, NDVI
and the links, the counters and the tank, the manual rate. Every element is built once; an
update changes text, values and colours in place, never a control under a finger.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from nicegui import ui

from topdress.display import fmt
from topdress.display.actions import Actions
from topdress.display.charts import meter_options, speed_options
from topdress.display.hub import DisplayHub
from topdress.display.map_view import FieldMaps, LiveMap
from topdress.display.units import Units
from topdress.i18n import render, tr
from topdress.view import commands as op
from topdress.view.snapshot import CounterView, Snapshot

CHART_PERIOD_S = 1.0  # charts and map redraw at 1 Hz; the numbers at the page's timer rate
RATE_STEP_PCT = 10.0  # one touch of + or -
PANELS = ("map", "charts", "crop", "counters", "manual")
#: The screen below the header: what is left of the viewport (the header is about 124 px).
BODY_HEIGHT = "calc(100vh - 140px)"


def rate_step(manual: op.ManualView, up: bool) -> op.SetManual:
    """The manual rate one +/- touch gives: fixed rates move by RATE_STEP_PCT of themselves
    (within what PcCommand carries), otherwise the model's rate by RATE_STEP_PCT more or less
    (within the percent range)."""
    sign = 1.0 if up else -1.0
    if manual.mode == "fixed":
        k = 1.0 + sign * RATE_STEP_PCT / 100.0

        def moved(v: float) -> float:
            return round(min(max(v * k, 0.0), op.MAX_RATE_KG_HA), 1)

        return op.SetManual("fixed", moved(manual.upper_kg_ha), moved(manual.lower_kg_ha))
    lo, hi = op.PERCENT_RANGE
    pct = manual.percent if manual.mode == "percent" else 0.0
    new = min(max(pct + sign * RATE_STEP_PCT, lo), hi)
    return op.SetManual("off") if new == 0.0 else op.SetManual("percent", percent=new)


def clipped(s: Snapshot) -> bool:
    """Whether the manual percent asks more than PcCommand carries (the rate is cut to it)."""
    m = s.manual
    if m.mode != "percent" or s.operator != op.RUNNING:
        return False
    k = 1.0 + m.percent / 100.0
    return any(r * k > op.MAX_RATE_KG_HA + 1e-9 for r in s.rate_model_kg_ha)


class MainScreen:
    """Built once per page; `update(snapshot)` rewrites the values."""

    def __init__(
        self,
        hub: DisplayHub,
        actions: Actions,
        width_m: float,
        max_kg_ha: float,
        maps: FieldMaps | None = None,
    ) -> None:
        self.hub = hub
        self.actions = actions
        self.units = Units(hub.prefs.units)
        self.maps = maps or FieldMaps()
        self._chart_t = -1e9
        self._manual: op.ManualView | None = None
        self._last = Snapshot()
        with ui.row().classes("w-full no-wrap items-stretch gap-2").style(f"height: {BODY_HEIGHT}"):
            with ui.column().classes("gap-1 shrink-0").style("width: 21rem"):
                self._build_controls()
                self._build_rates()
                self._build_speed()
                self._build_left()
            with ui.column().classes("flex-1 min-w-0 gap-1 no-wrap"):
                self._build_panels(width_m, max_kg_ha)

    # ---- left: what the driver works with ------------------------------------------------
    def _build_controls(self) -> None:
        send = self.actions.send
        with ui.row().classes("w-full no-wrap gap-2"):
            ui.button(tr("op.start"), icon="play_arrow", on_click=lambda: send(op.Start())).props(
                "color=green-9 size=lg no-caps"
            ).classes("flex-1 h-16 text-lg").mark("start")
            ui.button(
                tr("op.pause"), icon="pause", on_click=lambda: send(op.Pause(), guarded=False)
            ).props("color=amber-8 text-color=black size=lg no-caps").classes(
                "flex-1 h-16 text-lg td-edge"
            ).mark("pause")

    def _build_rates(self) -> None:
        u = self.units
        with ui.card().tight().classes("w-full td-card p-1 gap-0"):
            with ui.row().classes("w-full no-wrap items-center gap-1"):
                with ui.grid(columns="auto 1fr 1fr").classes(
                    "flex-1 gap-x-2 gap-y-0 items-baseline"
                ):
                    ui.label(u.rate_unit).classes("text-sm td-muted")
                    ui.label(tr("main.rate_target")).classes("text-sm td-muted text-right")
                    ui.label(tr("main.rate_applied")).classes("text-sm td-muted text-right")
                    self.rate: dict[str, ui.label] = {}
                    self.applied: dict[str, ui.label] = {}
                    for layer in op.LAYERS:
                        ui.label(tr(f"main.{layer}")).classes("text-base")
                        self.rate[layer] = (
                            ui.label("--")
                            .classes("text-2xl font-mono text-right")
                            .mark(f"rate_{layer}")
                        )
                        self.applied[layer] = (
                            ui.label("--")
                            .classes("text-2xl font-mono font-bold text-right")
                            .mark(f"applied_{layer}")
                        )
                with ui.column().classes("gap-1"):
                    ui.button(f"+{RATE_STEP_PCT:g} %", on_click=lambda: self._step(True)).props(
                        "outline no-caps"
                    ).classes("text-base").mark("rate_plus")
                    ui.button(f"−{RATE_STEP_PCT:g} %", on_click=lambda: self._step(False)).props(
                        "outline no-caps"
                    ).classes("text-base").mark("rate_minus")
            self.manual_state = (
                ui.label("").classes("text-sm font-bold px-1 rounded").mark("manual_state")
            )
            self.rx = ui.label("").classes("text-sm td-muted").mark("prescription")
            # can.implement isobus: the implement metering these rates, its state and sections
            self.implement = ui.label("").classes("text-sm truncate").mark("implement")
            self.implement.set_visibility(False)

    async def _step(self, up: bool) -> None:
        await self.actions.send(rate_step(self._last.manual, up))

    def _build_speed(self) -> None:
        u = self.units
        with ui.card().tight().classes("w-full td-card p-1 gap-0"):
            with ui.row().classes("w-full items-baseline no-wrap gap-2"):
                self.v_sel = ui.label("--").classes("text-3xl font-mono").mark("v_selected")
                ui.label(u.speed_unit).classes("text-sm td-muted")
                ui.space()
                self.source = (
                    ui.badge("--").props("color=grey-9").classes("text-base").mark("source")
                )
            with ui.row().classes("w-full items-baseline no-wrap gap-3 text-sm"):
                for name, attr in (("main.wheel", "v_wheel"), ("main.gnss", "v_gnss")):
                    with ui.row().classes("items-baseline no-wrap gap-1"):
                        ui.label(tr(name)).classes("td-muted")
                        setattr(self, attr, ui.label("--").classes("font-mono").mark(attr))
                        ui.label(u.speed_unit).classes("td-muted")
                # the GNSS lag in use, short; its source and state in the "NDVI, links" panel
                self.lag_short = ui.label("").classes("font-mono td-muted").mark("gnss_lag_short")
            self.why = ui.label("").classes("text-xs").mark("source_why")

    def _build_left(self) -> None:
        with ui.card().tight().classes("w-full td-card p-1 gap-0"):
            self.tank_line = ui.label("--").classes("text-base").mark("tank")
            self.area_line = ui.label("--").classes("text-base").mark("area")

    # ---- right: one touch apart ------------------------------------------------------------
    def _build_panels(self, width_m: float, max_kg_ha: float) -> None:
        names = {
            "map": tr("map.title"),
            "charts": tr("tab.charts"),
            "crop": tr("tab.crop"),
            "counters": tr("count.title"),
            "manual": tr("manual.title"),
        }
        self.tabs = (
            ui.toggle(names, value="map", on_change=lambda e: self._show(str(e.value)))
            .props("no-caps unelevated toggle-color=green-9 text-color=green-10")
            .classes("w-full td-panels")
            .mark("panels")
        )
        self.panels: dict[str, ui.column] = {}
        for name in PANELS:
            with ui.column().classes("w-full flex-1 min-h-0 gap-1") as panel:
                self.panels[name] = panel
                build: Callable[..., Any] = getattr(self, f"_panel_{name}")
                if name == "map":
                    build(width_m, max_kg_ha)
                else:
                    build()
            panel.set_visibility(name == "map")

    def _show(self, name: str) -> None:
        for key, panel in self.panels.items():
            panel.set_visibility(key == name)

    def _panel_map(self, width_m: float, max_kg_ha: float) -> None:
        u = self.units
        legend = tr("map.legend", max=f"{u.rate(max_kg_ha):.0f}", unit=u.rate_unit)
        ui.label(legend).classes("text-xs td-muted")
        self.map = LiveMap(self.hub, width_m, max_kg_ha, self.maps)

    def _panel_charts(self) -> None:
        with ui.row().classes("w-full flex-1 no-wrap gap-1"):
            with ui.column().classes("flex-1 min-w-0 h-full gap-0"):
                ui.label(tr("chart.speed_title")).classes("text-sm font-bold")
                self.speed_chart = (
                    ui.echart(speed_options([], units=self.units, night=self.hub.prefs.night))
                    .classes("w-full flex-1")
                    .mark("speed_chart")
                )
            with ui.column().classes("flex-1 min-w-0 h-full gap-0"):
                ui.label(tr("chart.meter_title")).classes("text-sm font-bold")
                self.meter_chart = (
                    ui.echart(meter_options([], night=self.hub.prefs.night))
                    .classes("w-full flex-1")
                    .mark("meter_chart")
                )

    def _panel_crop(self) -> None:
        rpm = tr("unit.rpm")
        with ui.row().classes("w-full gap-4 items-start"):
            with ui.column().classes("gap-0"):
                ui.label(tr("main.ndvi")).classes("text-sm font-bold")
                with ui.grid(columns=2).classes("gap-x-3 gap-y-0 items-baseline"):
                    ui.label(tr("main.ndvi_sensors")).classes("text-sm td-muted")
                    self.ndvi_sensors = ui.label("--").classes("font-mono").mark("ndvi_sensors")
                    ui.label(tr("main.ndvi_meters")).classes("text-sm td-muted")
                    self.ndvi_meters = ui.label("--").classes("font-mono").mark("ndvi_meters")
                self.per_sensor = ui.label("").classes("text-sm font-mono").mark("ndvi_per_sensor")
                self.crop = ui.label("").classes("text-sm").mark("crop_sensors")
            with ui.column().classes("gap-0"):
                ui.label(tr("main.metering")).classes("text-sm font-bold")
                with ui.grid(columns=3).classes("gap-x-3 gap-y-0 items-baseline"):
                    ui.label("")
                    ui.label(tr("main.upper")).classes("text-sm td-muted")
                    ui.label(tr("main.lower")).classes("text-sm td-muted")
                    u = self.units
                    self.model = self._pair(
                        f"{tr('main.rate_model')} ({u.rate_unit})", "rate_model"
                    )
                    self.target = self._pair(f"{tr('main.target')} ({rpm})", "target")
                    self.meter = self._pair(f"{tr('main.measured')} ({rpm})", "meter")
                    self.fan = self._pair(f"{tr('main.fans')} ({rpm})", "fan")
            with ui.column().classes("gap-0"):
                ui.label(tr("main.links")).classes("text-sm font-bold")
                self.links = {
                    k: ui.label("--").classes("text-base").mark(f"link_{k}")
                    for k in ("ecu", "gnss", "crop")
                }
                # the GNSS lag the ECU uses and where it comes from (learned or set)
                self.lag = ui.label("").classes("text-sm").mark("gnss_lag")
                ui.label(tr("main.faults")).classes("text-sm td-muted")
                self.faults = ui.label("--").classes("text-base").mark("faults")
                self.event = ui.label("").classes("text-sm td-muted").mark("last_event")
                ui.button(
                    tr("alarm.ack_all"), on_click=lambda: self.actions.send(op.AckAlarm(None))
                ).props("outline no-caps").mark("ack_all")

    def _pair(self, caption: str, marker: str) -> tuple[ui.label, ui.label]:
        ui.label(caption).classes("text-sm td-muted")
        return (
            ui.label("--").classes("font-mono").mark(f"{marker}_upper"),
            ui.label("--").classes("font-mono").mark(f"{marker}_lower"),
        )

    def _panel_counters(self) -> None:
        u = self.units
        self.counters: dict[tuple[str, str], ui.label] = {}
        self.undo: dict[str, ui.button] = {}
        with ui.grid(columns=3).classes("gap-x-4 gap-y-0 items-center"):
            ui.label("")
            for which in ("field", "season"):
                ui.label(tr(f"count.{which}")).classes("text-sm font-bold")
            for row in ("area", "kg_upper", "kg_lower", "time", "distance"):
                ui.label(tr(f"count.{row}")).classes("text-sm td-muted")
                for which in ("field", "season"):
                    self.counters[(which, row)] = (
                        ui.label("--").classes("font-mono").mark(f"count_{which}_{row}")
                    )
            ui.label("")
            for which in ("field", "season"):
                with ui.row().classes("gap-1 no-wrap"):
                    ui.button(
                        tr("count.reset"),
                        icon="restart_alt",
                        on_click=lambda w=which: self._confirm_reset(w),
                    ).props("outline no-caps").mark(f"reset_{which}")
                    self.undo[which] = (
                        ui.button(
                            tr("count.undo"),
                            icon="undo",
                            on_click=lambda w=which: self.actions.send(op.UndoReset(w)),
                        )
                        .props("outline no-caps")
                        .mark(f"undo_{which}")
                    )
                    self.undo[which].set_visibility(False)
        with ui.row().classes("items-center gap-2 no-wrap"):
            self.tank_fill = (
                ui.number(f"{tr('tank.fill')} ({u.mass_unit})", min=0, format="%.0f")
                .classes("w-44")
                .mark("tank_fill")
            )
            self.tank_alarm = (
                ui.number(f"{tr('tank.alarm')} ({u.mass_unit})", min=0, format="%.0f")
                .classes("w-40")
                .mark("tank_alarm")
            )
            ui.button(tr("tank.set"), icon="local_gas_station", on_click=self._fill).props(
                "no-caps"
            ).mark("tank_set")

    async def _fill(self) -> None:
        u = self.units
        fill = u.mass_to_kg(float(self.tank_fill.value or 0.0))
        alarm = u.mass_to_kg(float(self.tank_alarm.value or 0.0))
        await self.actions.send(op.FillTank(fill, alarm))

    async def _confirm_reset(self, which: str) -> None:
        """A reset asks first, naming what it sets to zero; an undo stays offered after."""
        c = self._last.count_field if which == "field" else self._last.count_season
        u = self.units
        what = tr(
            "count.reset_ask",
            which=tr(f"count.{which}"),
            area=f"{u.area(c.area_ha):.2f} {u.area_unit}",
            kg=f"{u.mass(c.kg[0] + c.kg[1]):.0f} {u.mass_unit}",
        )
        with ui.dialog() as dialog, ui.card():
            ui.label(what).classes("text-lg").mark("reset_ask")
            with ui.row():
                ui.button(tr("count.reset"), on_click=lambda: dialog.submit(True)).props(
                    "color=red-9 no-caps"
                ).mark("reset_yes")
                ui.button(tr("action.cancel"), on_click=lambda: dialog.submit(False)).props(
                    "outline no-caps"
                ).mark("reset_no")
        ok = bool(await dialog)
        dialog.delete()
        if ok:
            await self.actions.send(op.ResetCounter(which))

    def _panel_manual(self) -> None:
        u = self.units
        modes = {m: tr(f"manual.{m}") for m in op.MANUAL_MODES}
        self.mode = ui.radio(modes, value="off").props("inline").mark("manual_mode")
        with ui.row().classes("gap-2 no-wrap"):
            # No min/max here: a value out of range goes to the terminal, which refuses it
            # with the reason (a field that clamps would change 9999 to 600 without a word).
            self.upper = ui.number(f"{tr('main.upper')} ({u.rate_unit})", value=100.0)
            self.lower = ui.number(f"{tr('main.lower')} ({u.rate_unit})", value=100.0)
            self.pct = ui.number(f"± {tr('unit.pct')}", value=0.0)
        self.upper.classes("w-36").mark("manual_upper")
        self.lower.classes("w-36").mark("manual_lower")
        self.pct.classes("w-28").mark("manual_percent")
        with ui.row().classes("items-center gap-2"):
            ui.button(tr("action.apply"), on_click=self._apply_manual).props("no-caps").mark(
                "manual_apply"
            )
            self.in_force = ui.label("").classes("text-base").mark("manual_in_force")

    async def _apply_manual(self) -> None:
        u = self.units
        result = await self.actions.send(
            op.SetManual(
                str(self.mode.value),
                u.rate_to_kg_ha(float(self.upper.value or 0.0)),
                u.rate_to_kg_ha(float(self.lower.value or 0.0)),
                float(self.pct.value or 0.0),
            )
        )
        why = render(result.message) if result is not None and not result.ok else None
        for field in (self.upper, self.lower, self.pct):
            field.props.set_bool("error", why is not None)
            field.props.set_optional("error-message", why)

    # ---- update ----------------------------------------------------------------------------
    v_wheel: ui.label
    v_gnss: ui.label

    def update(self, s: Snapshot) -> None:
        self._last = s
        u = self.units
        live = s.ecu_live
        self.v_sel.set_text(fmt.ecu(s, u.speed(s.v_kmh), ".1f"))
        self.v_wheel.set_text(fmt.ecu(s, u.speed(s.v_wheel_kmh), ".1f"))
        gnss = None if s.gnss_kmh is None else u.speed(s.gnss_kmh)
        self.v_gnss.set_text(fmt.num(gnss, ".1f"))
        source = s.source if live else "none"
        self.source.set_text(tr(f"source.{source}") if source != "none" else "--")
        colour = {"gnss": "blue-9", "wheel": "deep-orange-10", "fused": "purple-9"}.get(
            source, "grey-9"
        )
        if self.source.props.get("color") != colour:
            self.source.props["color"] = colour
            self.source.update()
        # An ISOBUS implement meters on the GNSS speed the terminal sends: the ECU's rule for
        # its speed source does not apply, and its line makes room for the implement's.
        self.why.set_visibility(s.isobus is None)
        self.why.set_text(render(u.shown(s.speed_why)) if live and s.isobus is None else "")
        for i, layer in enumerate(op.LAYERS):
            self.rate[layer].set_text(fmt.num(u.rate(s.rate_kg_ha[i]), ".1f"))
            self.applied[layer].set_text(fmt.ecu(s, u.rate(s.applied_kg_ha[i]), ".1f"))
        self._update_manual(s)
        self._update_implement(s)
        self._update_tank(s)
        self._update_details(s)
        self._update_counters(s)
        if s.t_s - self._chart_t >= CHART_PERIOD_S or s.t_s < self._chart_t:
            self._chart_t = s.t_s
            history = self.hub.history()
            night = self.hub.prefs.night
            self.speed_chart.options.update(speed_options(history, units=self.units, night=night))
            self.speed_chart.update()
            self.meter_chart.options.update(meter_options(history, night=night))
            self.meter_chart.update()
            self.map.update()

    def _update_manual(self, s: Snapshot) -> None:
        u = self.units
        m = s.manual
        if m.mode == "fixed":
            text = tr(
                "manual.shown_fixed",
                upper=f"{u.rate(m.upper_kg_ha):.1f}",
                lower=f"{u.rate(m.lower_kg_ha):.1f}",
                unit=u.rate_unit,
            )
        elif m.mode == "percent":
            text = tr("manual.shown_percent", percent=f"{m.percent:+.0f}")
        else:
            text = ""
        if clipped(s):
            text += " · " + tr("manual.clipped", max=f"{u.rate(op.MAX_RATE_KG_HA):.0f}")
        self.manual_state.set_text(text)
        fmt.restyle(
            self.manual_state, "text-sm font-bold px-1 rounded" + (" td-manual" if text else "")
        )
        self.in_force.set_text(tr("manual.in_force", what=text or tr("manual.off")))
        if m != self._manual:
            # What is in force, also when another screen or the console changed it.
            self._manual = m
            self.mode.set_value(m.mode)
            if m.mode == "fixed":
                self.upper.set_value(round(u.rate(m.upper_kg_ha), 1))
                self.lower.set_value(round(u.rate(m.lower_kg_ha), 1))
            if m.mode == "percent":
                self.pct.set_value(m.percent)
        rx = []
        if s.prescription_kg_ha is not None:
            rx.append(
                tr(
                    "main.prescription",
                    rate=f"{u.rate(s.prescription_kg_ha):.0f}",
                    unit=u.rate_unit,
                )
            )
        if s.zone is not None:
            rx.append(tr(f"zone.{s.zone}"))
        self.rx.set_text(" · ".join(rx))

    def _update_implement(self, s: Snapshot) -> None:
        v = s.isobus
        self.implement.set_visibility(v is not None)
        if v is None:
            return
        line = tr("main.implement", name=v.implement or "ISOBUS", state=fmt.link_text(v.state))
        if v.sections:
            line += " · " + fmt.marks(v.sections)
        self.implement.set_text(line)
        fmt.restyle(
            self.implement, "text-sm truncate " + ("td-ok" if v.state == "ok" else "td-bad")
        )

    def _update_tank(self, s: Snapshot) -> None:
        u = self.units
        t = s.tank
        if t.remaining_kg is None:
            tank = tr("main.tank_none")
        else:
            left = max(0.0, t.remaining_kg)
            rate = s.applied_kg_ha[0] + s.applied_kg_ha[1] if s.ecu_live else 0.0
            tank = tr("main.tank_left", kg=f"{u.mass(left):.0f}", unit=u.mass_unit)
            if rate > 1.0:
                covers = u.area(left / rate)
                tank += " · " + tr("main.covers", area=f"{covers:.2f}", unit=u.area_unit)
        self.tank_line.set_text(tank)
        low = t.remaining_kg is not None and t.remaining_kg <= t.alarm_kg
        fmt.restyle(self.tank_line, "text-base" + (" td-bad" if low else ""))
        done = s.count_field.area_ha
        area = tr("main.area_done", area=f"{u.area(done):.2f}", unit=u.area_unit)
        if self.maps.field_ha is not None:
            left_ha = max(0.0, self.maps.field_ha - done)
            area += " · " + tr("main.area_left", area=f"{u.area(left_ha):.2f}", unit=u.area_unit)
        self.area_line.set_text(area)

    def _update_details(self, s: Snapshot) -> None:
        live = s.ecu_live
        lag = s.gnss_lag if live else None
        self.lag.set_text(render(lag.text()) if lag else "")
        self.lag_short.set_text(tr("main.lag", s=lag.in_use_ms / 1000) if lag else "")
        self.ndvi_sensors.set_text(fmt.num(s.ndvi_sensors, ".3f"))
        self.ndvi_meters.set_text(fmt.num(s.ndvi, ".3f"))
        self.per_sensor.set_text(
            "  ".join(f"{i}: {fmt.num(v, '.3f')}" for i, v in enumerate(s.ndvi_per_sensor, 1))
        )
        self.crop.set_text(f"{tr('main.crop_sensors')}: {fmt.link_text(s.crop_link)}")
        u = self.units
        self.model[0].set_text(fmt.num(u.rate(s.rate_model_kg_ha[0]), ".1f"))
        self.model[1].set_text(fmt.num(u.rate(s.rate_model_kg_ha[1]), ".1f"))
        for (up, lo), (vu, vl), spec in (
            (self.target, s.target_rpm, ".1f"),
            (self.meter, s.meter_rpm, ".1f"),
            (self.fan, s.fan_rpm, ".0f"),
        ):
            up.set_text(fmt.ecu(s, vu, spec))
            lo.set_text(fmt.ecu(s, vl, spec))
        where = f" ({s.ecu_where})" if s.ecu_link == "wait" and s.ecu_where else ""
        for kind, state in (("ecu", s.ecu_link), ("gnss", s.gnss_link), ("crop", s.crop_link)):
            text = f"{tr(f'link_name.{kind}')}: {fmt.link_text(state)}"
            self.links[kind].set_text(text + (where if kind == "ecu" else ""))
            fmt.restyle(self.links[kind], "text-base " + ("td-ok" if state == "ok" else "td-bad"))
        self.faults.set_text(fmt.faults_text(s))
        self.event.set_text(render(s.last_event))

    def _update_counters(self, s: Snapshot) -> None:
        for which, c in (("field", s.count_field), ("season", s.count_season)):
            for row, text in self._counter_texts(c).items():
                self.counters[(which, row)].set_text(text)
            self.undo[which].set_visibility(which in s.count_undo)

    def _counter_texts(self, c: CounterView) -> dict[str, str]:
        u = self.units
        h, rem = divmod(int(c.work_s), 3600)
        return {
            "area": f"{u.area(c.area_ha):.3f} {u.area_unit}",
            "kg_upper": f"{u.mass(c.kg[0]):.1f} {u.mass_unit}",
            "kg_lower": f"{u.mass(c.kg[1]):.1f} {u.mass_unit}",
            "time": f"{h}:{rem // 60:02d}:{rem % 60:02d}",
            "distance": f"{u.length(c.distance_m):.0f} {u.length_unit}",
        }
