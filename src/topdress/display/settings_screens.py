"""The paper's two settings screens: communication (serial ports, CAN) and control (the NDVI ->
rate model with its live plot, the layer split, the speed rule, the ECU's PID gains).

Each section is checked with the configuration's own checks as it is typed (the refused value
shown at its field), then applied by the terminal (`ApplySettings`: saved atomically, the
device reopened or the ECU given the values with acknowledgement; nothing half-applied).
"""

from __future__ import annotations

from typing import Any

from nicegui import ui

from topdress.config import ECU_KEYS, SPEED_MODE_IDS, SWITCH_COMPARE_IDS, TerminalConfig
from topdress.config_edit import section_values, section_version, validate_section
from topdress.crop.rate import rate_curve
from topdress.devices.ports import list_serial_ports
from topdress.display import fmt, isobus_names
from topdress.display.actions import Actions
from topdress.display.forms import SectionForm
from topdress.display.hub import DisplayHub
from topdress.display.units import Units
from topdress.errors import ConfigError
from topdress.i18n import render, tr
from topdress.view import commands as op
from topdress.view.snapshot import IsobusView, ProductView, Snapshot

BAUDS = [4800, 9600, 19200, 38400, 57600, 115200]
CAN_INTERFACES = [
    "socketcan",
    "slcan",
    "pcan",
    "kvaser",
    "ixxat",
    "vector",
    "udp_multicast",
    "virtual",
]
#: The ECU's tuning keys on the control screen (the [ecu] section); the rest stay in the file.
ECU_TUNING = ("pid_kp", "pid_ki", "pid_kd", "pid_kff", "fan_min_rpm", "blocked_time_ms")


def reason(exc: ConfigError) -> str:
    """The message of a ConfigError without its key (shown at the key's field)."""
    return str(exc).removeprefix(f"{exc.key}: ")


class SectionCard:
    """One section's form with its apply button and the terminal's answer."""

    def __init__(
        self,
        hub: DisplayHub,
        actions: Actions,
        section: str,
        form: SectionForm,
        only_changed: bool = False,
    ) -> None:
        self.hub = hub
        self.actions = actions
        self.section = section
        self.form = form
        self._initial = form.values()
        self._only_changed = only_changed
        # What the form was filled from: applied from another screen since, it is refused.
        self.base = section_version(hub.config(), section)
        with ui.row().classes("items-center gap-2"):
            self.button = ui.button(tr("action.save_apply"), on_click=self.apply).mark(
                f"apply_{section}"
            )
            self.answer = ui.label("").classes("text-sm").mark(f"answer_{section}")

    def values(self) -> dict[str, Any]:
        values = self.form.values()
        if self._only_changed:
            values = {k: v for k, v in values.items() if self._initial.get(k) != v}
        return values

    def check(self) -> bool:
        """The configuration's checks on what is typed; the refused value shown at its field."""
        unreadable = self.form.text_errors()
        if unreadable:
            self.form.show_errors(unreadable)
            return False
        try:
            validate_section(self.hub.config(), self.section, self.values())
        except ConfigError as exc:
            self.form.show_errors({exc.key: reason(exc)})
            return False
        self.form.show_errors({})
        return True

    async def apply(self) -> None:
        if not self.check():
            self.answer.set_text(tr("settings.refused_here"))
            self.answer.classes(replace="text-sm td-bad")
            return
        if self.section == "can" and self.hub.latest()[2].operator != op.STOPPED:
            # Reopening the bus leaves the ECU unheard for a moment: not under running meters.
            if not await self._ask(tr("settings.link_cut_ask"), tr("settings.stop_apply")):
                return
            await self.actions.send(op.Stop())
        self.answer.set_text(tr("settings.sending"))
        self.answer.classes(replace="text-sm")
        result = await self.actions.send(op.ApplySettings(self.section, self.values(), self.base))
        if result is None:
            self.answer.set_text("")
            return
        if result.data == "stale":
            self.answer.set_text(render(result.message))
            self.answer.classes(replace="text-sm td-bad")
            if await self._ask(render(result.message), tr("settings.reload")):
                ui.navigate.reload()
            return
        self.form.show_errors(result.errors)
        self.answer.set_text(render(result.message))
        self.answer.classes(replace="text-sm " + ("td-ok" if result.ok else "td-bad"))
        if result.ok:
            self._initial = self.form.values()
            if isinstance(result.data, str):
                self.base = result.data  # this screen's own change is the new base

    async def _ask(self, question: str, yes: str) -> bool:
        with ui.dialog() as dialog, ui.card():
            ui.label(question).classes("text-lg").mark(f"ask_{self.section}")
            with ui.row():
                ui.button(yes, on_click=lambda: dialog.submit(True)).props(
                    "color=red-9 no-caps"
                ).mark(f"ask_{self.section}_yes")
                ui.button(tr("action.cancel"), on_click=lambda: dialog.submit(False)).props(
                    "outline no-caps"
                )
        ok = bool(await dialog)
        dialog.delete()
        return ok


def _title(key: str) -> None:
    ui.label(tr(key)).classes("text-base font-bold")


class CommunicationScreen:
    """Serial ports of the GNSS receiver and the crop sensors' logger, and the CAN adapter."""

    def __init__(self, hub: DisplayHub, actions: Actions) -> None:
        self.hub = hub
        self.actions = actions
        cfg = hub.config()
        ports = [p.device for p in list_serial_ports()]
        self.links: dict[str, ui.label] = {}
        with ui.row().classes("w-full items-start gap-3"):
            for section, keys in (
                ("gnss", ["port", "baud", "stale_s"]),
                ("crop", ["port", "baud", "sensors", "columns", "sensor_to_meter_m"]),
                (
                    "can",
                    [
                        "interface",
                        "channel",
                        "bitrate",
                        "command_period_s",
                        "send_on_gnss",
                        "send_on_rate",
                        "options",
                    ],
                ),
            ):
                with ui.card().classes("w-96 gap-2"):
                    _title(f"comm.{section}")
                    self.links[section] = ui.label("").classes("text-sm").mark(f"state_{section}")
                    choices: dict[str, list[Any] | dict[Any, str]] = {
                        "port": ports,
                        "baud": BAUDS,
                        "interface": CAN_INTERFACES,
                    }
                    form = SectionForm(
                        section,
                        section_values(cfg, section),
                        keys,
                        choices=choices,
                        free_choice=("port", "interface"),
                        tables_as_text=("options",),
                    )
                    SectionCard(hub, actions, section, form)
                    self._test_view(section)
            self.isobus = IsobusCard(Units(hub.prefs.units))

    def _test_view(self, device: str) -> None:
        table = (
            ui.table(
                columns=[
                    {"name": "t", "label": tr("unit.s"), "field": "t", "align": "right"},
                    {"name": "raw", "label": tr("comm.raw"), "field": "raw", "align": "left"},
                    {
                        "name": "decoded",
                        "label": tr("comm.decoded"),
                        "field": "decoded",
                        "align": "left",
                    },
                ],
                rows=[],
            )
            .props("dense flat wrap-cells")
            .classes("w-full text-xs")
        )
        table.set_visibility(False)

        async def test() -> None:
            result = await self.actions.send(op.TestDevice(device), guarded=False)
            if result is None or not result.ok:
                return
            table.rows = [
                {"t": f"{line.t_s:.1f}", "raw": line.raw, "decoded": line.decoded}
                for line in result.data or []
            ]
            table.set_visibility(True)
            table.update()

        ui.button(tr("comm.test"), icon="search", on_click=test).props("outline").mark(
            f"test_{device}"
        )
        table.mark(f"lines_{device}")

    def update(self, s: Snapshot) -> None:
        for section, state in (("gnss", s.gnss_link), ("crop", s.crop_link), ("can", s.ecu_link)):
            line = f"{tr('comm.state')}: {fmt.link_text(state)}"
            if section == "can" and s.ecu_ident is not None:  # who the ECU is (EcuIdent)
                line += " · " + tr("comm.ecu", ecu=render(s.ecu_ident))
            if section == "can" and s.ecu_can_health is not None:  # a firmware's controller
                line += " · " + render(s.ecu_can_health)
            self.links[section].set_text(line)
        self.isobus.update(s.isobus)


def _column(name: str, key: str, align: str = "left") -> dict[str, str]:
    return {"name": name, "label": tr(key), "field": name, "align": align}


class IsobusCard:
    """The terminal as a Task Controller on ISOBUS: its address and state, the implement it
    serves with its products, sections and delays, and every control function heard. Shown only
    with can.implement isobus (Snapshot.isobus set)."""

    def __init__(self, units: Units) -> None:
        self.units = units
        self._products: list[dict[str, str]] = []
        self._functions: list[dict[str, str]] = []
        with ui.card().classes("w-full gap-1") as self.card:
            _title("comm.isobus")
            self.tc = ui.label("").classes("text-sm").mark("isobus_tc")
            self.implement = ui.label("").classes("text-sm").mark("isobus_implement")
            self.products = (
                ui.table(
                    columns=[
                        _column("element", "isobus.element", "right"),
                        _column("unit", "isobus.unit"),
                        _column("setpoint", "isobus.setpoint", "right"),
                        _column("actual", "isobus.actual", "right"),
                        _column("total", "isobus.total", "right"),
                    ],
                    rows=[],
                )
                .props("dense flat")
                .classes("text-sm")
                .mark("isobus_products")
            )
            self.sections = ui.label("").classes("text-sm font-mono").mark("isobus_sections")
            self.timing = ui.label("").classes("text-sm").mark("isobus_timing")
            self.problem = ui.label("").classes("text-sm td-bad").mark("isobus_problem")
            ui.label(tr("isobus.functions")).classes("text-sm font-bold")
            self.functions = (
                ui.table(
                    columns=[
                        # "地址" kept on one line: the narrow column would break it in two
                        {
                            **_column("address", "isobus.address", "right"),
                            "headerClasses": "text-no-wrap",
                        },
                        _column("name", "isobus.name"),
                        _column("decoded", "comm.decoded"),
                        _column("what", "isobus.what"),
                    ],
                    rows=[],
                )
                .props("dense flat wrap-cells")
                .classes("w-full text-xs")
                .mark("isobus_functions")
            )
        self.card.set_visibility(False)

    def update(self, v: IsobusView | None) -> None:
        self.card.set_visibility(v is not None)
        if v is None:
            return
        address = "--" if v.tc_address is None else str(v.tc_address)
        self.tc.set_text(tr("isobus.tc", address=address, state=fmt.link_text(v.state)))
        if v.implement_address is None:
            self.implement.set_text(tr("isobus.no_implement"))
        else:
            name = v.implement or "--"
            work = "" if v.work_state is None else " · " + tr(f"isobus.work_{v.work_state}")
            self.implement.set_text(
                tr("isobus.implement", name=name, address=v.implement_address) + work
            )
        self._rows(self.products, "_products", [self._product(p) for p in v.products])
        on = sum(v.sections)
        self.sections.set_text(
            tr("isobus.sections", marks=fmt.marks(v.sections), on=on, n=len(v.sections))
            if v.sections
            else ""
        )
        self.timing.set_text(
            tr(
                "isobus.timing",
                lookahead=f"{v.lookahead_s:.2f}",
                setpoint=fmt.num(v.setpoint_latency_ms, "d"),
                actual=fmt.num(v.actual_latency_ms, "d"),
            )
        )
        self.problem.set_text(render(v.problem))
        self._rows(
            self.functions,
            "_functions",
            [
                {
                    "address": str(f.address),
                    "name": f"{f.name:016X}",
                    "decoded": tr(
                        "isobus.decoded",
                        function=f.function,
                        device_class=f.device_class,
                        group=f.industry_group,
                        manufacturer=isobus_names.maker(f.manufacturer_code),
                        identity=f.identity_number,
                    ),
                    "what": isobus_names.what(f, v),
                }
                for f in v.functions
            ],
        )

    def _product(self, p: ProductView) -> dict[str, str]:
        """A product's rates in the operator's units where they are mass per area."""
        u = self.units
        mass = p.unit == "kg/ha"
        rate = u.rate if mass else float
        total = u.mass if mass else float
        return {
            "element": str(p.element),
            "unit": u.rate_unit if mass else tr("unit.lha"),
            "setpoint": f"{rate(p.setpoint):.1f}",
            "actual": "--" if p.actual is None else f"{rate(p.actual):.1f}",
            "total": "--"
            if p.total is None
            else f"{total(p.total):.1f} " + (u.mass_unit if mass else tr("unit.l")),
        }

    def _rows(self, table: ui.table, attr: str, rows: list[dict[str, str]]) -> None:
        """New rows only when they changed: every change is a message to the browser."""
        if rows != getattr(self, attr):
            setattr(self, attr, rows)
            table.rows = rows
            table.update()


class ControlScreen:
    """The NDVI -> rate model with its live plot, the layer split, the speed rule, PID gains."""

    def __init__(self, hub: DisplayHub, actions: Actions) -> None:
        self.hub = hub
        self.actions = actions
        cfg = hub.config()
        with ui.row().classes("w-full items-start gap-3"):
            with ui.card().classes("w-[28rem] gap-2"):
                _title("control.rate")
                self.rate_form = SectionForm(
                    "rate",
                    section_values(cfg, "rate"),
                    ["model", "split_upper", "linear", "table.points"],
                    choices={"model": ["linear", "table", "sufficiency"]},
                    on_change=self._replot,
                )
                self.rate_card = SectionCard(hub, actions, "rate", self.rate_form)
            with ui.card().classes("flex-1 min-w-96"):
                _title("control.curve")
                self.curve = ui.echart(self._curve_options([], None)).classes("w-full h-72")
                self.point = ui.label("").classes("text-sm").mark("operating_point")
            with ui.card().classes("w-80 gap-2"):
                _title("control.speed")
                speed = SectionForm(
                    "speed",
                    section_values(cfg, "speed"),
                    choices={
                        "mode": list(SPEED_MODE_IDS),
                        "switch_compare": list(SWITCH_COMPARE_IDS),
                    },
                )
                SectionCard(hub, actions, "speed", speed)
            with ui.card().classes("w-80 gap-2"):
                _title("control.ecu")
                ui.label(tr("control.ecu_note")).classes("text-sm td-muted")
                values = ecu_tuning_values(cfg)
                ecu = SectionForm("ecu", values)
                self.ecu_card = SectionCard(hub, actions, "ecu", ecu, only_changed=True)
                self.pending = ui.label("").classes("text-sm td-warn").mark("pending")
        self._curve: list[tuple[float, float]] = []
        self._drawn_t = -1e9
        self._replot()

    def _replot(self) -> None:
        """The curve of what is typed, checked as the file is (the last good one stays)."""
        try:
            new = validate_section(self.hub.config(), "rate", self.rate_form.values())
        except ConfigError as exc:
            self.rate_form.show_errors({exc.key: reason(exc)})
            return
        self.rate_form.show_errors({})
        self._curve = rate_curve(new.rate)
        self._draw(None)

    def _draw(self, s: Snapshot | None) -> None:
        point = None
        if s is not None and s.ndvi is not None:
            point = (s.ndvi, s.rate_model_kg_ha[0] + s.rate_model_kg_ha[1])
        self.curve.options.update(self._curve_options(self._curve, point))
        self.curve.update()

    def _curve_options(
        self, curve: list[tuple[float, float]], point: tuple[float, float] | None
    ) -> dict[str, Any]:
        return {
            "animation": False,
            "grid": {"left": 56, "right": 16, "top": 24, "bottom": 40},
            "xAxis": {
                "type": "value",
                "min": 0,
                "max": 1,
                "name": "NDVI",
                "nameLocation": "middle",
                "nameGap": 26,
            },
            "yAxis": {
                "type": "value",
                "min": 0,
                "name": tr("control.total_rate"),
                "nameLocation": "middle",
                "nameGap": 40,
            },
            "series": [
                {
                    "type": "line",
                    "showSymbol": False,
                    "data": [[round(x, 3), round(y, 1)] for x, y in curve],
                },
                {
                    "type": "scatter",
                    "symbolSize": 14,
                    "itemStyle": {"color": "#c62828"},
                    "data": [[round(point[0], 3), round(point[1], 1)]] if point else [],
                },
            ],
        }

    def update(self, s: Snapshot) -> None:
        if s.ndvi is not None:
            total = s.rate_model_kg_ha[0] + s.rate_model_kg_ha[1]
            self.point.set_text(
                tr("control.point", ndvi=f"{s.ndvi:.3f}", rate=f"{total:.1f}", unit=tr("unit.kgha"))
            )
        if abs(s.t_s - self._drawn_t) >= 1.0:  # the operating point once a second
            self._drawn_t = s.t_s
            self._draw(s)
        self.pending.set_text(tr("control.pending") if s.settings_pending else "")


def ecu_tuning_values(cfg: TerminalConfig) -> dict[str, float | int]:
    """The ECU's tuning keys as in force, in their own type: an integer parameter as an int
    (a float would be refused on saving: "must be an integer, not 2500.0")."""
    out: dict[str, float | int] = {}
    for key in ECU_TUNING:
        spec = ECU_KEYS[key]
        value = cfg.ecu.overrides.get(key, spec.default)
        out[key] = round(value) if spec.integer else _round(value)
    return out


def _round(value: float) -> float:
    """An ECU default as float32 carries it (0.3 not 0.30000001)."""
    return float(f"{value:.6g}")
