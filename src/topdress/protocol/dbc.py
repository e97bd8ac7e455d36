"""The CAN database: protocol/topdress.dbc, shipped inside the package.

`src/topdress/protocol/topdress.dbc` is a symbolic link to the repository's `protocol/topdress.dbc`
(the single source of truth); building a wheel copies the file it points to, so an installed
package reads the same text.
"""

from __future__ import annotations

import re
from functools import cache
from importlib import resources
from typing import Any

from topdress.errors import ProtocolError


def dbc_text() -> str:
    """The DBC file as text."""
    return (resources.files("topdress.protocol") / "topdress.dbc").read_text(encoding="utf-8")


# Read from the DBC's text, not through cantools, so that the codes and ids are there without
# loading cantools and python-can (tests hold this reading to cantools').
_FRAME = re.compile(r"^BO_ (\d+) (\w+) *:", re.M)
_VALUES = re.compile(r"^VAL_ (\d+) (\w+) ((?:\d+ \"[^\"]*\" *)+);", re.M)
_VALUE = re.compile(r"(\d+) \"([^\"]*)\"")
_EXTENDED = 0x80000000  # the DBC's flag of a 29-bit identifier


@cache
def frame_ids() -> dict[str, int]:
    """Every frame's 29-bit identifier by the frame's name, as the DBC gives them."""
    return {name: int(raw) & ~_EXTENDED for raw, name in _FRAME.findall(dbc_text())}


@cache
def value_table(frame: str, signal: str) -> dict[int, str]:
    """The DBC's value table (VAL_) of a signal: code -> name, in code order."""
    ident = frame_ids().get(frame)
    if ident is None:
        raise ProtocolError(f"no frame named {frame!r} in the protocol")
    for raw, name, values in _VALUES.findall(dbc_text()):
        if int(raw) & ~_EXTENDED == ident and name == signal:
            return dict(sorted((int(k), v) for k, v in _VALUE.findall(values)))
    raise ProtocolError(f"{frame}.{signal} has no value table in the protocol")


@cache
def bit_names(frame: str, signal: str) -> tuple[str, ...]:
    """The names of a bit word's bits, lowest first (the signal's TdBits attribute)."""
    ident = frame_ids().get(frame)
    pattern = rf'^BA_ "TdBits" SG_ (\d+) {signal} "([^"]*)";'
    for raw, names in re.findall(pattern, dbc_text(), re.M):
        if int(raw) & ~_EXTENDED == ident:
            return tuple(names.split())
    raise ProtocolError(f"{frame}.{signal} has no TdBits attribute in the protocol")


def snake(name: str) -> str:
    """A DBC name in snake case: "GnssLagAuto" -> "gnss_lag_auto", "Stm32f4" -> "stm32f4"."""
    return re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name).lower()


@cache
def database() -> Any:
    """The cantools database of the protocol (loaded once; cantools, and python-can with it,
    only when a frame is encoded or decoded)."""
    import cantools

    return cantools.database.load_string(dbc_text(), database_format="dbc")


@cache
def protocol_version() -> tuple[int, int]:
    """The protocol's version (the DBC's VERSION "major.minor"): what this terminal speaks, and
    what an ECU built from the same DBC reports in EcuIdent."""
    major, _, minor = str(database().version).partition(".")
    try:
        return int(major), int(minor)
    except ValueError:
        version = database().version
        raise ProtocolError(f"the DBC's VERSION {version!r} is not major.minor") from None


def message(name: str) -> Any:
    """A cantools message of the protocol by name."""
    try:
        return database().get_message_by_name(name)
    except KeyError:
        raise ProtocolError(f"no frame named {name!r} in the protocol") from None
