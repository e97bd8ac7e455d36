"""Numbers as the operator reads them: "--" for unknown, units from the catalogue."""

from __future__ import annotations

from nicegui import ui

from topdress.i18n import tr
from topdress.terminal.app import Snapshot
from topdress.terminal.console import fault_names


def num(value: float | None, spec: str) -> str:
    return "--" if value is None else format(value, spec)


def ecu(s: Snapshot, value: float | None, spec: str) -> str:
    """A value from the ECU's frames: unknown ("--") while the ECU is not heard."""
    return num(value if s.ecu_live else None, spec)


def faults_text(s: Snapshot) -> str:
    """The fault word in plain words (the catalogue's), "--" while the ECU is not heard."""
    if not s.ecu_live:
        return "--"
    names = fault_names(s.faults)
    if not names:
        return tr("fault.none")
    return "; ".join(tr(f"fault.{n}") if not n.startswith("BIT") else n for n in names)


def link_text(state: str) -> str:
    """A link state in words: "ok", "wait", "lost", "no fix", "silent", or "3/4" sensors."""
    if "/" in state:
        return tr("link.partial", fresh=state)
    return tr(f"link.{state.replace(' ', '_')}")


def restyle(element: ui.element, classes: str) -> None:
    """Replace the element's classes when they differ: every change is a message to the browser,
    and the page redraws 5 times a second."""
    if list(element.classes) != classes.split():
        element.classes(replace=classes)
