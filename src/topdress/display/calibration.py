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
        self._view: CalibrationView | bool | None = False  # False: nothing drawn yet
        send = actions.send
        with ui.row().classes("w-full items-start gap-3"):
            with ui.card().classes("w-80 gap-2"):
                ui.label(tr("cal.catch")).classes("text-base font-bold")
                ui.label(tr("cal.catch_how")).classes("text-xs text-gray-600")
                layer = (
                    ui.radio({"upper": tr("main.upper"), "lower": tr("main.lower")}, value="upper")
                    .props("inline")
                    .mark("cal_layer")
                )
                revs = ui.number(tr("cal.revolutions"), value=20, min=1, max=200).mark("cal_revs")
                rpm = ui.number(f"{tr('cal.meter_speed')} ({tr('unit.rpm')})", value=20, min=1)
                rpm.mark("cal_rpm")
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
                ui.label(tr("cal.wheel_how")).classes("text-xs text-gray-600")
                dist = ui.number(f"{tr('cal.distance')} ({tr('unit.m')})", value=40.0, min=1)
                dist.mark("cal_distance")
                ui.button(
                    tr("cal.start"),
                    on_click=lambda: send(op.StartWheelCal(float(dist.value or 0))),
                ).mark("start_wheel")
            with ui.card().classes("w-80 gap-2"):
                ui.label(tr("cal.fan")).classes("text-base font-bold")
                ui.label(tr("cal.fan_how")).classes("text-xs text-gray-600")
                ui.button(tr("cal.start"), on_click=lambda: send(op.StartFanCheck())).mark(
                    "start_fan"
                )
            with ui.card().classes("w-80 gap-2"):
                ui.label(tr("cal.lead")).classes("text-base font-bold")
                ui.label(tr("cal.lead_how")).classes("text-xs text-gray-600")
                lead_layer = (
                    ui.radio({"upper": tr("main.upper"), "lower": tr("main.lower")}, value="upper")
                    .props("inline")
                    .mark("lead_layer")
                )
                trials = ui.number(tr("cal.trials"), value=3, min=1, max=10).mark("lead_trials")
                ui.button(
                    tr("cal.start"),
                    on_click=lambda: send(
                        op.StartLeadCal(str(lead_layer.value), int(trials.value or 3))
                    ),
                ).mark("start_lead")
            with ui.card().classes("flex-1 min-w-96 gap-2"):
                ui.label(tr("cal.now")).classes("text-base font-bold")
                self.panel = ui.column().classes("w-full gap-2")

    def update(self, s: Snapshot) -> None:
        if s.calibration == self._view:
            return
        self._view = s.calibration
        self.panel.clear()
        with self.panel:
            self._draw(s.calibration)

    def _draw(self, v: CalibrationView | None) -> None:
        send = self.actions.send
        if v is None:
            ui.label(tr("cal.none")).mark("cal_state")
            return
        ui.label(f"{tr(f'cal.{v.kind}')} · {tr(f'cal.step.{v.step}')}").classes(
            "text-lg font-bold"
        ).mark("cal_state")
        ui.linear_progress(value=v.progress, show_value=False).classes("w-full")
        ui.label(render(v.text)).classes("text-sm text-gray-700").mark("cal_text")
        for name, value in v.result.items():
            label = tr(f"cal.result.{name}") if f"cal.result.{name}" in CATALOGUE else name
            ui.label(f"{label}: {value:.4g}").classes("font-mono").mark(f"cal_result_{name}")
        with ui.row().classes("items-center gap-2"):
            if v.kind == "catch" and v.step == "weigh":
                kg = ui.number(f"{tr('cal.weighed')} ({tr('unit.kg')})", min=0).mark("cal_kg")
                ui.button(
                    tr("cal.finish"),
                    on_click=lambda: send(op.FinishCatchTest(float(kg.value or 0.0))),
                ).mark("finish_catch")
            if v.kind == "wheel" and v.step == "drive":
                ui.button(tr("cal.finish_drive"), on_click=lambda: send(op.FinishWheelCal())).mark(
                    "finish_wheel"
                )
            if v.kind == "lead" and v.step == "running":
                ui.button(tr("cal.seen"), on_click=lambda: send(op.LeadSeen())).props(
                    "color=orange-9 size=lg"
                ).mark("lead_seen")
            if v.step == "done" and v.key:
                ui.button(
                    tr("cal.apply", setting=v.key),
                    on_click=lambda: send(op.CloseCalibration(apply=True)),
                ).props("color=green-8 no-caps").mark("cal_apply")
            ui.button(
                tr("cal.close"), on_click=lambda: send(op.CloseCalibration(apply=False))
            ).props("outline").mark("cal_close")
            ui.button(tr("op.stop"), icon="stop", on_click=lambda: send(op.Stop())).props(
                "color=red-9"
            )
