"""The CAN database: protocol/topdress.dbc, shipped inside the package.

`src/topdress/protocol/topdress.dbc` is a symbolic link to the repository's `protocol/topdress.dbc`
(the single source of truth); building a wheel copies the file it points to, so an installed
package reads the same text.
"""

from __future__ import annotations

from functools import cache
from importlib import resources
from typing import Any

from topdress.errors import ProtocolError


def dbc_text() -> str:
    """The DBC file as text."""
    return (resources.files("topdress.protocol") / "topdress.dbc").read_text(encoding="utf-8")


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
