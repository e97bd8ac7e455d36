"""The project's private frames on an ISOBUS (docs/isobus.md, "The private frames on ISOBUS"):
the DBC's IsobusPgn attribute is the mapping, generated for the C layer; the simulated ECU sends
its frames on Proprietary B from its claimed address and answers on Proprietary A to the Task
Controller, and takes the terminal's frames only from the TC's address (others counted)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import cantools
import pytest

from topdress.errors import ProtocolError
from topdress.isobus.node import Frame, IsobusNode, from_bus, split_id, to_bus, topdress_name
from topdress.protocol import AckResult, frames
from topdress.protocol.dbc import frame_ids
from topdress.sim.isobus import IsobusMachine, tc_timeout_ms
from topdress.sim.tc import MiniTc
from topdress.sim.world import World

REPO = Path(__file__).resolve().parents[1]
PROP_A, PROP_A2 = 0xEF00, 0x1EF00
TC_ADDR, ECU_ADDR, STRANGER = 0xF7, 0x84, 0x90


def _gen() -> object:
    spec = importlib.util.spec_from_file_location("gen_prop", REPO / "scripts" / "gen_prop.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _db() -> cantools.database.can.Database:
    db = cantools.database.load_file(str(REPO / "protocol" / "topdress.dbc"))
    assert isinstance(db, cantools.database.can.Database)
    return db


def test_the_committed_table_is_the_dbcs() -> None:
    gen = _gen()
    committed = REPO / "ecu" / "isobus" / "src" / "gen" / "td_prop_gen.h"
    assert committed.read_text(encoding="utf-8") == gen.generate(_db())  # type: ignore[attr-defined]


def test_every_private_frame_has_a_proprietary_pgn() -> None:
    db = _db()
    pgns = {m.name: int(m.dbc.attributes["IsobusPgn"].value) for m in db.messages if m.dbc}
    # the paper's PcCommand has none: on an ISOBUS the Task Controller sets the rates
    assert pgns["PcCommand"] == 0
    # the paper's frames themselves stay as they were (Table 1)
    assert frame_ids()["EcuStatus"] == 0x185C6465 and frame_ids()["PcCommand"] == 0x0A5C6465
    for m in db.messages:
        if m.name == "PcCommand":
            continue
        pgn = pgns[m.name]
        assert pgn in (PROP_A, PROP_A2) or 0xFF00 <= pgn <= 0xFFFF, m.name
    # Proprietary A only for the request and answer to one address
    assert {n for n, p in pgns.items() if p in (PROP_A, PROP_A2)} == {
        "PcParamSet",
        "EcuParamAck",
        "PcCalCommand",
    }


def test_frames_keep_their_bytes_and_take_the_claimed_addresses() -> None:
    status = Frame(frame_ids()["EcuStatus"], bytes([10, 0x10, 0x27, 0x88, 0x13, 150, 140, 70]))
    bus = to_bus(status, by_ecu=True, sa=0x85)
    assert bus is not None and bus.data == status.data
    assert split_id(bus.can_id) == (6, 0xFF5C, 0x85, 0xFF)
    assert from_bus(bus, by_ecu=True, peer=0x85, my_address=TC_ADDR) == status
    with pytest.raises(ProtocolError, match="from address 0x85, not from 0x84"):
        from_bus(bus, by_ecu=True, peer=0x84, my_address=TC_ADDR)
    cmd = frames.encode_command(True, 3000.0, 150.0, 100.0, 7.0)
    assert to_bus(Frame(cmd.arbitration_id, bytes(cmd.data)), by_ecu=False, sa=TC_ADDR) is None
    ps = frames.encode_param_set("MeterTau", 300)
    bus = to_bus(Frame(ps.arbitration_id, bytes(ps.data)), by_ecu=False, sa=TC_ADDR, da=0x84)
    assert bus is not None and split_id(bus.can_id) == (2, PROP_A, TC_ADDR, 0x84)
    # Proprietary A to another ECU is other traffic, not an error
    assert from_bus(bus, by_ecu=False, peer=TC_ADDR, my_address=0x85) is None


def _machine() -> tuple[IsobusMachine, MiniTc]:
    world = World(seed=3)
    node = IsobusNode(topdress_name(1407, bytes(range(12))), tc_timeout_ms=tc_timeout_ms(1500))
    return IsobusMachine(world, node, 3.6, 6), MiniTc()


def _run(m: IsobusMachine, tc: MiniTc, seconds: float, extra: list[Frame]) -> list[Frame]:
    heard: list[Frame] = []
    pending = list(extra)
    for _ in range(round(seconds / m.world.dt)):
        out = m.step(pending)
        heard += out
        pending = tc.step(m.world.now_us, out)
    return heard


def _param_set(sa: int) -> Frame:
    msg = frames.encode_param_set("MeterTau", 300)
    bus = to_bus(Frame(msg.arbitration_id, bytes(msg.data)), by_ecu=False, sa=sa, da=ECU_ADDR)
    assert bus is not None
    return bus


def test_sim_ecu_speaks_proprietary_from_its_address() -> None:
    m, tc = _machine()
    heard = _run(m, tc, 3.0, [])
    assert tc.activated and m.node.address == ECU_ADDR
    paper_ids = set(frame_ids().values())
    assert not [f for f in heard if f.can_id in paper_ids], "a fixed paper identifier on ISOBUS"
    status = [f for f in heard if split_id(f.can_id)[1:3] == (0xFF5C, ECU_ADDR)]
    assert len(status) >= 25  # every 100 ms once claimed
    back = from_bus(status[-1], by_ecu=True, peer=ECU_ADDR, my_address=TC_ADDR)
    assert back is not None
    st = frames.decode((back.can_id, back.data))
    assert isinstance(st, frames.EcuStatus) and not st.running

    # a parameter from the TC's address is taken and answered on Proprietary A to the TC
    heard = _run(m, tc, 0.1, [_param_set(TC_ADDR)])
    acks = [f for f in heard if split_id(f.can_id)[1] == PROP_A]
    assert len(acks) == 1 and split_id(acks[0].can_id)[2:] == (ECU_ADDR, TC_ADDR)
    ack = from_bus(acks[0], by_ecu=True, peer=ECU_ADDR, my_address=TC_ADDR)
    assert ack is not None
    decoded = frames.decode((ack.can_id, ack.data))
    assert isinstance(decoded, frames.EcuParamAck)
    assert decoded.result == AckResult.OK and decoded.param_id == 37
    assert m.node.counters["prop_rx"] == 1

    # the same frame from another address: ignored (no answer) and counted
    heard = _run(m, tc, 0.1, [_param_set(STRANGER), _param_set(STRANGER)])
    assert not [f for f in heard if split_id(f.can_id)[1] == PROP_A]
    assert m.node.counters["prop_wrong_source"] == 2
    assert m.node.counters["prop_rx"] == 1
