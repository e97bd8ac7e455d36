"""`topdress` and `python -m topdress`: a Ctrl-C while the program is still loading (numpy,
python-can, cantools take a moment) ends it with exit code 130 and no traceback."""

from __future__ import annotations

import os
import signal
import sys
from types import FrameType


def _interrupted(signum: int, frame: FrameType | None) -> None:
    # Only imports run now: no file, port or bus is open yet, so leaving at once loses nothing
    # (an exception raised inside an import machinery frame can end as a death by SIGINT).
    sys.stderr.write("topdress: interrupted while loading\n")
    sys.stderr.flush()
    os._exit(130)


def run() -> None:
    signal.signal(signal.SIGINT, _interrupted)
    from topdress.cli.main import main  # the heavy imports happen here and in main()

    # Loaded: Ctrl-C is a KeyboardInterrupt again, which main() and the terminal handle.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    code = main()
    if code == 130:
        # Everything is closed by now (the interrupt came through every finally). Leave without
        # the interpreter's exit: a KeyboardInterrupt that went through an extension's import
        # leaves CPython's "unhandled interrupt" mark set, and it would die by SIGINT instead.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(130)
    sys.exit(code)


if __name__ == "__main__":
    run()
