"""EcuIdent: the core says who it is, with the versions the DBC and the release carry."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

from topdress import protocol
from topdress.ecu import Ecu
from topdress.errors import ProtocolError

REPO = Path(__file__).resolve().parents[1]
CMD = protocol.DEFAULT_IDS.command


def _define(name: str) -> int:
    text = (REPO / "ecu" / "include" / "td_version.h").read_text(encoding="utf-8")
    m = re.search(rf"#define {name} (\d+)u", text)
    assert m is not None, name
    return int(m[1])


def test_versions_are_the_dbcs_and_the_releases() -> None:
    dbc = re.search(r'^VERSION "(\d+)\.(\d+)"', protocol.dbc_text(), re.MULTILINE)
    assert dbc is not None
    assert (_define("TD_PROTO_VERSION_MAJOR"), _define("TD_PROTO_VERSION_MINOR")) == (
        int(dbc[1]),
        int(dbc[2]),
    )
    release = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    fw = tuple(_define(f"TD_FW_VERSION_{p}") for p in ("MAJOR", "MINOR", "PATCH"))
    assert ".".join(map(str, fw)) == release["version"]


def _idents(ecu: Ecu, steps: range, command_at: set[int]) -> list[protocol.EcuIdent]:
    found = []
    good = protocol.encode_command(True, 3000, 100.0, 100.0, 5.0)
    for k in steps:
        if k in command_at:
            ecu.rx(good, k * 10_000)
        ecu.step_raw(k * 10_000, 0, 0, 0, 0, 0)
        for frame in ecu.tx_raw():
            f = protocol.decode(frame)
            if isinstance(f, protocol.EcuIdent):
                found.append(f)
    return found


def test_the_simulators_core_says_host() -> None:
    ecu = Ecu()
    (ident,) = _idents(ecu, range(1, 50), set())
    assert ident.target == "host" and ident.transport == "in-process"
    assert ident.reset_cause == "unknown" and not ident.clock_fallback
    assert ident.protocol_version == "1.1" and ident.firmware_version == "0.1.0"
    # commands every 500 ms: none; silence past the 1.5 s timeout, then a command: one
    assert len(_idents(ecu, range(50, 300), set(range(50, 300, 50)))) == 1
    assert _idents(ecu, range(300, 500), set()) == []
    assert len(_idents(ecu, range(500, 560), {510, 530})) == 1


def test_ident_bytes_and_refused_values() -> None:
    data = bytes([1, 0, 1, 0, 1, 1, 0x32, 0x01])
    ident = protocol.decode((protocol.DEFAULT_IDS.ident, data))
    assert ident == protocol.EcuIdent("stm32f4", (0, 1, 0), (1, 1), "slcan-hil", "watchdog", True)
    with pytest.raises(ProtocolError, match="Target: undefined value 2"):
        protocol.decode((protocol.DEFAULT_IDS.ident, bytes([2, *data[1:]])))
    with pytest.raises(ProtocolError, match="ResetCause: undefined value 7"):
        protocol.decode((protocol.DEFAULT_IDS.ident, bytes([*data[:6], 0x72, 0])))
