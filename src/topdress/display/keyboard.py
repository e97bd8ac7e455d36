"""Operator commands typed on the console (`start`, `stop`, `manual fixed 200 150`, ...).

A reader thread turns each line of the input stream into a command
(topdress.view.commands.parse_command) and posts it to the terminal; the answer is printed as an
event when the loop has acted on it.
Used by `topdress run` and `topdress demo` when their input is a terminal; the display posts
the very same commands.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any, TextIO

from topdress.i18n import render, tr
from topdress.view.commands import CommandResult, Help, OperatorError, parse_command

log = logging.getLogger(__name__)


def describe(result: CommandResult) -> str:
    """The answer to a typed command, with the data of a device test line by line."""
    message = render(result.message)
    text = message if result.ok else tr("con.refused", message=message)
    if isinstance(result.data, list):
        text += "".join(
            f"\n  {line.t_s:8.2f}  {line.raw[:40]:<40}  {line.decoded}" for line in result.data
        )
    return text


class KeyboardCommands:
    """Reads commands from `stream` in a daemon thread until it ends."""

    def __init__(
        self,
        post: Callable[[Any], Future[CommandResult]],
        stream: TextIO,
        say: Callable[[str], None],
    ) -> None:
        """`post`: the terminal's (Terminal.post): a command in, its result as a Future."""
        self._post = post
        self._stream = stream
        self._say = say  # called on the loop's thread (the Future's callback)
        self._thread = threading.Thread(target=self._run, name="keyboard", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _run(self) -> None:
        try:
            for line in self._stream:
                if line.strip():
                    self._one(line)
        except (OSError, ValueError) as exc:  # the terminal went away
            log.debug("keyboard input ended: %s", exc)

    def _one(self, line: str) -> None:
        try:
            command = parse_command(line)
        except OperatorError as exc:
            command = Help(str(exc))
        fut = self._post(command)
        fut.add_done_callback(self._answer)

    def _answer(self, fut: Future[CommandResult]) -> None:
        result = fut.result()
        if result.ok and result.data is None:
            return  # said already: the terminal's event for it
        self._say(describe(result))
