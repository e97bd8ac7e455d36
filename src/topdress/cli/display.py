"""The display beside a running terminal: what `topdress run` and `topdress demo` call."""

from __future__ import annotations

from collections.abc import Callable

from topdress import i18n
from topdress.config import TerminalConfig
from topdress.display.process import DisplayLink
from topdress.display.server import DisplayError, DisplayOptions, check_security
from topdress.terminal.app import Snapshot, Terminal


def display_options(
    cfg: TerminalConfig, enabled: bool | None, host: str | None, port: int | None
) -> DisplayOptions | None:
    """The `[display]` settings with the command line's over them; None when off.
    DisplayError when the address needs a PIN that is not set."""
    dc = cfg.display
    if not (dc.enabled if enabled is None else enabled):
        return None
    opts = DisplayOptions(host=host or dc.host, port=port or dc.port, pin=dc.pin)
    check_security(opts)
    return opts


class AttachedDisplay:
    """What the control loop publishes into; None inside when the display could not start."""

    def __init__(self, link: DisplayLink | None) -> None:
        self.link = link

    def publish(self, snapshot: Snapshot) -> None:
        if self.link is not None:
            self.link.publish(snapshot)

    def stop(self) -> None:
        if self.link is not None:
            self.link.stop()


def serve_display(
    term: Terminal, opts: DisplayOptions, message: Callable[[str], None]
) -> AttachedDisplay:
    """Serve the display for `term` from its own process; a display that cannot start is
    said and left out (the terminal works without it)."""
    i18n.set_language(term.cfg.display.language)
    link = DisplayLink(term, opts, message)
    try:
        url = link.start()
    except DisplayError as exc:
        message(f"display not served: {exc}")
        return AttachedDisplay(None)
    message(f"display: {url}")
    return AttachedDisplay(link)
