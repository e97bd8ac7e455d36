"""Numbers as the operator reads them: "--" for unknown, units from the catalogue."""

from __future__ import annotations

from nicegui import ui

from topdress.i18n import tr
from topdress.view.links import fault_texts, link_text
from topdress.view.snapshot import Snapshot

__all__ = ["ecu", "faults_text", "link_text", "marks", "num", "restyle"]


def num(value: float | None, spec: str) -> str:
    return "--" if value is None else format(value, spec)


def ecu(s: Snapshot, value: float | None, spec: str) -> str:
    """A value from the ECU's frames: unknown ("--") while the ECU is not heard."""
    return num(value if s.ecu_live else None, spec)


def faults_text(s: Snapshot) -> str:
    """The fault word in plain words (the catalogue's), "--" while the ECU is not heard."""
    if not s.ecu_live:
        return "--"
    return "; ".join(fault_texts(s.faults)) or tr("fault.none")


def marks(sections: tuple[bool, ...]) -> str:
    """Sections as a row of on/off marks in pool order: "■■□■■■" (■ on, □ off)."""
    return "".join("■" if on else "□" for on in sections)


def restyle(element: ui.element, classes: str) -> None:
    """Replace the element's classes when they differ: every change is a message to the browser,
    and the page redraws 5 times a second."""
    if list(element.classes) != classes.split():
        element.classes(replace=classes)
