"""The display beside a running terminal: what `topdress run` and `topdress demo` call."""

from __future__ import annotations

from collections.abc import Callable

from topdress import i18n
from topdress.config import TerminalConfig
from topdress.display.hub import DisplayHub
from topdress.display.server import DisplayError, DisplayOptions, DisplayServer, check_security
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
    """The hub the control loop publishes into, and the server reading it."""

    def __init__(self, hub: DisplayHub, server: DisplayServer | None) -> None:
        self.hub = hub
        self.server = server

    def publish(self, snapshot: Snapshot) -> None:
        self.hub.publish(snapshot)

    def stop(self) -> None:
        if self.server is not None:
            self.server.stop()


def serve_display(
    term: Terminal, opts: DisplayOptions, message: Callable[[str], None]
) -> AttachedDisplay:
    """Serve the display for `term`; a display that cannot start is said and left out (the
    terminal works without it)."""
    i18n.set_language(term.cfg.display.language)
    hub = DisplayHub(lambda: term.cfg, getattr(term, "post", None))
    server = DisplayServer(hub, opts)
    try:
        url = server.start()
    except DisplayError as exc:
        message(f"display not served: {exc}")
        return AttachedDisplay(hub, None)
    message(f"display: {url}")
    return AttachedDisplay(hub, server)
