"""Sending the operator's commands: the PIN when one is set, then the terminal's inbox.

The page never blocks its event loop: it awaits the command's future. With a PIN set, a browser
on another machine (a tablet on the cab's network) needs it to operate: start/stop, pause, the
manual rate, alarms, counters, settings and calibrations ask for it once per browser tab (a
reload locks again); viewing needs none, and neither does the cab PC's own screen (a loopback
client). The PIN typed is compared in constant time and never logged or echoed.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

from nicegui import ui

from topdress.display.hub import DisplayHub
from topdress.i18n import render, tr
from topdress.view.commands import CommandResult

COMMAND_TIMEOUT_S = 15.0  # settings for the ECU wait for every acknowledgement
WRONG_PIN_DELAY_S = 1.0


class Actions:
    """One browser tab's command path."""

    def __init__(
        self, hub: DisplayHub, remote: bool, address: str = "", client_id: str = ""
    ) -> None:
        self.hub = hub
        self.remote = remote  # not the cab's own browser (topdress.display.guard)
        self.address = address  # the client's, for counting wrong PINs
        self.client_id = client_id  # the page's: one that sends a command is the operator's
        # One PIN try a second from the tab, across its dialogs (a new dialog is no new try).
        self._pin_lock = asyncio.Lock()
        self._next_try = 0.0
        self.unlocked = False

    async def unlock(self) -> bool:
        """Ask for the PIN if one is set, the browser is remote and has not given it yet."""
        if self.unlocked or not self.remote or not self.hub.pin_required:
            return True
        with ui.dialog() as dialog, ui.card():
            ui.label(tr("pin.title")).classes("text-lg")
            pin = ui.input(tr("pin.label"), password=True).props("autofocus").mark("pin")
            wrong = ui.label("").classes("td-bad")

            async def submit() -> None:
                # One try a second from a tab, however fast keys, clicks, dialogs or a script
                # come: guessing stays slow even before a lockout.
                async with self._pin_lock:
                    await asyncio.sleep(max(0.0, self._next_try - time.monotonic()))
                    wait_s = self.hub.try_pin(self.address, pin.value or "")
                    if wait_s is None:
                        dialog.submit(True)
                        return
                    self._next_try = time.monotonic() + WRONG_PIN_DELAY_S
                pin.value = ""
                wrong.set_text(tr("pin.locked", s=wait_s) if wait_s > 0 else tr("pin.wrong"))

            pin.on("keydown.enter", submit)
            with ui.row():
                ui.button(tr("pin.ok"), on_click=submit).mark("pin_ok")
                ui.button(tr("action.cancel"), on_click=lambda: dialog.submit(False)).props("flat")
        ok = bool(await dialog)
        dialog.delete()
        self.unlocked = ok
        return ok

    async def send(self, command: Any, *, guarded: bool = True) -> CommandResult | None:
        """Post `command`; None when not sent (PIN refused, no command path). A refused command
        is told to the operator; the result is returned for the caller to show at its fields."""
        if self.hub.post is None:
            ui.notify(tr("action.view_only"), type="warning")
            return None
        if guarded and not await self.unlock():
            return None
        if self.client_id:
            self.hub.operator_pages.add(self.client_id)  # this page claimed operation
        future = self.hub.post(command)
        try:
            result = await asyncio.wait_for(asyncio.wrap_future(future), COMMAND_TIMEOUT_S)
        except TimeoutError:
            ui.notify(tr("action.timeout"), type="negative")
            return None
        if not result.ok:
            ui.notify(
                render(result.message) or tr("action.refused"), type="negative", multi_line=True
            )
        return result
