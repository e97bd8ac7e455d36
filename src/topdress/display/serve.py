"""The display beside a running terminal: what `topdress run` and `topdress demo` call."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from topdress.config import TerminalConfig
from topdress.display.hub import DisplayHub
from topdress.display.server import DisplayError, DisplayOptions, DisplayServer, check_security
from topdress.terminal.app import Snapshot, Terminal


def display_options(
    cfg: TerminalConfig, enabled: bool | None, host: str | None, port: int | None
) -> DisplayOptions | None:
    """The `[display]` settings with the command line's over them; None when off."""
    dc: Any = cfg.display
    on = getattr(dc, "enabled", True) if enabled is None else enabled
    if not on:
        return None
    opts = DisplayOptions(
        host=host if host else str(getattr(dc, "host", "127.0.0.1")),
        port=port if port else int(getattr(dc, "port", 8080)),
        pin=str(getattr(dc, "pin", "")),
    )
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
    term: Terminal,
    cfg: TerminalConfig,
    opts: DisplayOptions,
    message: Callable[[str], None],
) -> AttachedDisplay:
    """Serve the display for `term`; a display that cannot start is said and left out (the
    terminal works without it)."""
    del term  # commands go through the terminal's inbox once the operator API is in
    hub = DisplayHub()
    server = DisplayServer(hub, opts, cfg)
    try:
        url = server.start()
    except DisplayError as exc:
        message(f"display not served: {exc}")
        return AttachedDisplay(hub, None)
    message(f"display: {url}")
    return AttachedDisplay(hub, server)
