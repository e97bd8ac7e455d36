"""The calibration wizards: metering catch test, ground-wheel distance, fan check, look-ahead.

The wizards' logic is the terminal's (topdress.terminal.calibration, the catch test in the
ECU): this screen starts them, shows their step and progress from the Snapshot, takes the
operator's measurement and offers the result to be applied (saved and sent to the ECU) or
dropped. Nothing else changes.
"""

from __future__ import annotations

from nicegui import ui

from topdress.display.actions import Actions
from topdress.display.hub import DisplayHub
from topdress.i18n import render, tr
from topdress.i18n.catalogue import CATALOGUE
from topdress.view import commands as op
from topdress.view.snapshot import CalibrationView, Snapshot


class CalibrationScreen:
    def __init__(self, hub: DisplayHub, actions: Actions) -> None:
        self.hub = hub
        self.actions = actions
        self._view: CalibrationView | None = None
        self._applied = ""
        send = actions.send
        with ui.row().classes("w-full items-start gap-3"):
            with ui.card().classes("w-80 gap-2"):
                ui.label(tr("cal.catch")).classes("text-base font-bold")
                ui.label(tr("cal.catch_how")).classes("text-sm td-muted")
                layer = (
                    ui.radio({"upper": tr("main.upper"), "lower": tr("main.lower")}, value="upper")
                    .props("inline")
                    .mark("cal_layer")
                )
                revs = ui.number(tr("cal.revolutions"), value=20, min=1, max=200).mark("cal_revs")
                revs.classes("w-44")
                rpm = ui.number(f"{tr('cal.meter_speed')} ({tr('unit.rpm')})", value=20, min=1)
                rpm.classes("w-44").mark("cal_rpm")
                ui.button(
                    tr("cal.start"),
                    on_click=lambda: send(
                        op.StartCatchTest(
                            str(layer.value), float(revs.value or 0), float(rpm.value or 0)
                        )
                    ),
                ).mark("start_catch")
            with ui.card().classes("w-80 gap-2"):
                ui.label(tr("cal.wheel")).classes("text-base font-bold")
                ui.label(tr("cal.wheel_how")).classes("text-sm td-muted")
                dist = ui.number(f"{tr('cal.distance')} ({tr('unit.m')})", value=40.0, min=1)
                dist.classes("w-44").mark("cal_distance")
                ui.button(
                    tr("cal.start"),
                    on_click=lambda: send(op.StartWheelCal(float(dist.value or 0))),
                ).mark("start_wheel")
            with ui.card().classes("w-80 gap-2"):
                ui.label(tr("cal.fan")).classes("text-base font-bold")
                ui.label(tr("cal.fan_how")).classes("text-sm td-muted")
                ui.button(tr("cal.start"), on_click=lambda: send(op.StartFanCheck())).mark(
                    "start_fan"
                )
            with ui.card().classes("w-80 gap-2"):
                ui.label(tr("cal.lead")).classes("text-base font-bold")
                ui.label(tr("cal.lead_how")).classes("text-sm td-muted")
                lead_layer = (
                    ui.radio({"upper": tr("main.upper"), "lower": tr("main.lower")}, value="upper")
                    .props("inline")
                    .mark("lead_layer")
                )
                trials = ui.number(tr("cal.trials"), value=3, min=1, max=10).mark("lead_trials")
                trials.classes("w-44")
                ui.button(
                    tr("cal.start"),
                    on_click=lambda: send(
                        op.StartLeadCal(str(lead_layer.value), int(trials.value or 3))
                    ),
                ).mark("start_lead")
            with ui.card().classes("flex-1 min-w-80 gap-2"):
                ui.label(tr("cal.now")).classes("text-base font-bold")
                self._build_panel()

    def _build_panel(self) -> None:
        """Every element the wizard can show, built once: an update (5 a second while a
        wizard runs) changes their text, value and visibility, never the elements, so a press
        on Seen, Close or Enter weight is never lost to a redraw."""
        send = self.actions.send
        self.state = ui.label(tr("cal.none")).classes("text-lg font-bold").mark("cal_state")
        self.progress = ui.linear_progress(value=0.0, show_value=False).classes("w-full")
        self.text = ui.label("").classes("text-sm td-muted").mark("cal_text")
        self.results: dict[str, ui.label] = {}
        for key in CATALOGUE:
            if key.startswith("cal.result."):
                name = key.removeprefix("cal.result.")
                self.results[name] = ui.label("").classes("font-mono").mark(f"cal_result_{name}")
        self.others = ui.label("").classes("font-mono").mark("cal_result_other")
        self.last = ui.label("").classes("text-sm td-muted").mark("cal_last")
        with ui.row().classes("items-center gap-2"):
            self.kg = ui.number(f"{tr('cal.weighed')} ({tr('unit.kg')})", min=0).mark("cal_kg")
            self.kg.classes("w-40")
            self.finish_catch = (
                ui.button(
                    tr("cal.finish"),
                    on_click=lambda: self._send(op.FinishCatchTest(float(self.kg.value or 0.0))),
                )
                .props("no-caps")
                .mark("finish_catch")
            )
            self.finish_wheel = (
                ui.button(tr("cal.finish_drive"), on_click=lambda: self._send(op.FinishWheelCal()))
                .props("no-caps")
                .mark("finish_wheel")
            )
            self.seen = (
                ui.button(tr("cal.seen"), on_click=lambda: send(op.LeadSeen()))
                .props("color=orange-10 size=lg no-caps")
                .mark("lead_seen")
            )
            self.apply = (
                ui.button("", on_click=lambda: self._send(op.CloseCalibration(apply=True)))
                .props("color=green-9 no-caps")
                .mark("cal_apply")
            )
            self.close = (
                ui.button(
                    tr("cal.close"),
                    on_click=lambda: self._send(op.CloseCalibration(apply=False)),
                )
                .props("outline no-caps")
                .mark("cal_close")
            )
        self._draw(None)

    async def _send(self, command: object) -> None:
        """A wizard's step: its answer (the result, what was saved) is said on the screen."""
        result = await self.actions.send(command)
        if result is not None and result.ok:
            ui.notify(render(result.message), type="positive", multi_line=True)
            if isinstance(command, op.CloseCalibration) and command.apply:
                self._applied = render(result.message)

    def update(self, s: Snapshot) -> None:
        if s.calibration == self._view:
            return
        if s.calibration is None and isinstance(self._view, CalibrationView):
            self._closed(self._view)
        self._view = s.calibration
        self._draw(s.calibration)

    def _closed(self, v: CalibrationView) -> None:
        """The last wizard's result stays on the screen after it closed."""
        if v.step == "done":
            what = render(v.text)
            applied = self._applied
            self.last.set_text(tr("cal.last", what=what) + (f" · {applied}" if applied else ""))
            self._applied = ""

    def _draw(self, v: CalibrationView | None) -> None:
        shown = v is not None
        self.state.set_text(
            f"{tr(f'cal.{v.kind}')} · {tr(f'cal.step.{v.step}')}" if v else tr("cal.none")
        )
        self.progress.set_visibility(shown)
        self.progress.set_value(v.progress if v else 0.0)
        self.text.set_text(render(v.text) if v else "")
        result = v.result if v else {}
        for name, label in self.results.items():
            if name in result:
                label.set_text(f"{tr(f'cal.result.{name}')}: {result[name]:.4g}")
            label.set_visibility(name in result)
        others = [f"{k}: {x:.4g}" for k, x in result.items() if k not in self.results]
        self.others.set_text("  ".join(others))
        self.others.set_visibility(bool(others))
        weigh = v is not None and v.kind == "catch" and v.step == "weigh"
        self.kg.set_visibility(weigh)
        self.finish_catch.set_visibility(weigh)
        self.finish_wheel.set_visibility(v is not None and v.kind == "wheel" and v.step == "drive")
        self.seen.set_visibility(v is not None and v.kind == "lead" and v.step == "running")
        can_apply = v is not None and v.step == "done" and bool(v.key)
        if v is not None and can_apply:
            self.apply.set_text(tr("cal.apply", setting=v.key))
        self.apply.set_visibility(can_apply)
        self.close.set_visibility(shown)
