"""The HIL frames (protocol/topdress_hil.dbc) never take a bus frame's identifier, and the
firmware's identifiers are the DBC's (the codec's freshness: tests/test_protocol_codec.py)."""

from __future__ import annotations

import re
from pathlib import Path

from topdress import protocol
from topdress.sim.qemu_ecu import hil_database

REPO = Path(__file__).resolve().parents[1]


def test_hil_frames_are_apart_from_the_bus_frames() -> None:
    hil = {m.frame_id for m in hil_database().messages}
    assert len(hil) == 5
    assert not hil & {m.frame_id for m in protocol.database().messages}
    assert all(not protocol.is_known_id(i) for i in hil)
    # the firmware's identifiers (td_hil.h) are the DBC's
    header = (REPO / "ecu" / "ports" / "common" / "td_hil.h").read_text(encoding="utf-8")
    for m in hil_database().messages:
        # the port's names for them are the generated codec's, never a number written by hand
        generated = "TD_HILCAN_" + re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", m.name).upper()
        assert f"{generated}_FRAME_ID" in header, m.name
        assert f"{m.frame_id:08X}" not in header.upper(), m.name
