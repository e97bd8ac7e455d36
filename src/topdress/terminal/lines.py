"""The terminal's two line sources, GNSS and crop, and their replacement when a setting changes.

Each source reads in its own thread and puts `(kind, t, line)` on the loop's inbox, `t` the
time the line arrived (the source's receive timestamp). A changed [gnss] or [crop] section
opens a new source in place of the one in use; the old one stops in a thread of its own.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from topdress.config import TerminalConfig
from topdress.devices.lines import LineSource, open_line_source
from topdress.terminal.inbox import Inbox

KINDS = {"gnss": "nmea", "crop": "crop"}  # section -> the inbox kind of its lines


class Lines:
    """The GNSS and the crop line sources in use."""

    def __init__(self, gnss: LineSource, crop: LineSource, inbox: Inbox) -> None:
        self.gnss = gnss
        self.crop = crop
        self._inbox = inbox

    def _sink(self, kind: str) -> Callable[[float, bytes], None]:
        inbox = self._inbox
        return lambda t, line: inbox.put((kind, t, line))

    def start(self) -> None:
        self.gnss.start(self._sink("nmea"))
        self.crop.start(self._sink("crop"))

    def stop(self) -> None:
        self.gnss.stop()
        self.crop.stop()

    def reopen(self, section: str, new: TerminalConfig) -> None:
        """Open the line source of a changed [gnss] or [crop] section in place of the one in
        use; DeviceError when it cannot be made (the old one stays). A serial port opens in
        its reader thread."""
        source = open_line_source(new.gnss if section == "gnss" else new.crop)
        if section == "gnss":
            old, self.gnss = self.gnss, source
        else:
            old, self.crop = self.crop, source
        in_background(old.stop, f"stop-{old.name}")
        source.start(self._sink(KINDS[section]))


def why(source: LineSource) -> str:
    """Why a source is not delivering, for the operator."""
    return f"{source.name}: {source.last_error or 'disconnected'}"


def in_background(stop: Callable[[], None], name: str) -> None:
    """Stop a device the loop no longer uses without waiting for it (a reader thread leaving
    a blocking read, a bus shutting down)."""
    threading.Thread(target=stop, name=name, daemon=True).start()
