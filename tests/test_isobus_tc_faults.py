"""Bad input and faults at the terminal's Task Controller: a client whose address is taken or
that moves, nonsense process data, a flooding client, two clients at once, a second TC on the
bus, garbage of every kind through the process-data path and the DDOP parser. The server says
each fault once in words, counts it, raises nothing and keeps serving."""

from __future__ import annotations

import random
import struct

import pytest

from tc_rig import AGISO_NAME, CLIENT, DATA, DDOP, STEP_US, TC, Bus, connected, replay_agiso
from topdress.errors import ProtocolError
from topdress.isobus.ddop import Machine, build, parse
from topdress.isobus.devicemap import map_device
from topdress.isobus.node import Frame, IsobusNode, TpEndpoint, split_id, topdress_name
from topdress.isobus.tcserver import FLOOD_PER_S, TcServer, tc_name


def _pd(sa: int, data: bytes, da: int = TC) -> Frame:
    return Frame(6 << 26 | 0xCB00 << 8 | da << 8 | sa, data)


def _claim(sa: int, name: int) -> Frame:
    return Frame(6 << 26 | 0xEE00 << 8 | 0xFF << 8 | sa, name.to_bytes(8, "little"))


def _status_times(frames: list[Frame]) -> list[int]:
    return [i for i, f in enumerate(frames) if split_id(f.can_id)[1:4:2] == (0xCB00, 0xFF)]


def test_served_client_address_taken_by_another_name() -> None:
    tc, _ = replay_agiso()
    c = tc.client
    assert c is not None and c.active and c.name == AGISO_NAME
    thief = AGISO_NAME - 0x1000  # a lower NAME wins 0x80 from the client
    tc.step(60_000_000, [_claim(CLIENT, thief)])
    assert c.lost and tc.counters["clients_displaced"] == 1
    assert tc.errors[-1] == f"client 0x80's address taken by NAME {thief:016X}: client dropped"
    # the displaced client claims 0x81 and announces itself again: served from there
    wsm = Frame(6 << 26 | 0xFE0D << 8 | 0x81, bytes([1]) + b"\xff" * 7)
    out = tc.step(60_010_000, [_claim(0x81, AGISO_NAME), wsm])
    assert tc.client is not None and tc.client.address == 0x81 and tc.client.name == AGISO_NAME
    assert any(split_id(f.can_id)[3] == 0x81 and f.data[0] == 0x00 for f in out)  # version?


def test_served_client_moving_to_another_address_is_dropped_and_served_anew() -> None:
    tc, _ = replay_agiso()
    c = tc.client
    assert c is not None
    tc.step(60_000_000, [_claim(0x85, AGISO_NAME)])
    assert c.lost and "moved from 0x80 to 0x85" in tc.errors[-1]
    with_version = tc.step(60_010_000, [_pd(0x85, bytes([0]) + b"\xff" * 7)])
    assert tc.client is not None and tc.client.address == 0x85
    # its version answered, and its own asked (it has not said it at the new address yet)
    to_it = [f.data[:2] for f in with_version if split_id(f.can_id)[3] == 0x85]
    assert to_it == [b"\x10\x04", b"\x00\xff"]


def test_nonsense_process_data_counted_once_said_and_not_taken() -> None:
    tc, _ = replay_agiso()
    c = tc.client
    assert c is not None
    values = dict(c.values)
    junk = [
        _pd(CLIENT, bytes([0x03 | 9 << 4, 6]) + struct.pack("<Hi", 7, 1)),  # element 105
        _pd(CLIENT, bytes([0x33, 0]) + struct.pack("<Hi", 999, -1)),  # DDI 999 on element 3
        _pd(CLIENT, bytes([0x33, 0]) + struct.pack("<Hi", 999, -2)),  # the same again
        _pd(CLIENT, bytes([0x09, 0]) + b"\xff" * 6),  # reserved command 9
        _pd(CLIENT, b"\x03\x00"),  # 2 bytes
    ]
    tc.step(50_000_000, junk)
    assert c.values == values and not c.lost  # nothing taken, the client still served
    assert tc.counters["unknown_values"] == 3
    said = [e for e in tc.errors if "which its DDOP does not have" in e]
    assert said == [
        "client 0x80 reports DDI 7 of element 105, which its DDOP does not have",
        "client 0x80 reports DDI 999 of element 3, which its DDOP does not have",
    ]


def test_flooding_client_dropped_past_the_cap_server_keeps_its_status() -> None:
    tc, _ = replay_agiso()
    c = tc.client
    assert c is not None
    value = _pd(CLIENT, bytes([0x33, 0]) + struct.pack("<Hi", 7, 4242))
    t = 60_000_000 - STEP_US
    out: list[Frame] = []
    for _ in range(100):  # 5,000 messages in one second, 50 each 10 ms
        t += STEP_US
        out += tc.step(t, [value] * 50)
    assert tc.counters["flood_dropped"] == 5000 - FLOOD_PER_S
    assert c.heard[(3, 7)] >= FLOOD_PER_S and c.values[(3, 7)] == 4242
    assert sum("floods the TC" in e for e in tc.errors) == 1  # said once, not 4,800 times
    assert not c.lost
    for _ in range(300):  # and on: 3 s of the client's normal traffic
        t += STEP_US
        out += tc.step(t, [value] if t % 1_000_000 == 0 else [])
    assert tc.counters["flood_dropped"] == 5000 - FLOOD_PER_S  # nothing dropped after
    assert len(_status_times(out)) == 2  # the status every 2 s all along


def test_two_clients_at_once_the_second_nacked_then_served_when_the_first_goes() -> None:
    tc = TcServer(tc_name(7))
    tc.start(0)
    nodes = [
        IsobusNode(topdress_name(1407, bytes(range(12))), tc_timeout_ms=6000),
        IsobusNode(topdress_name(1407, bytes(range(1, 13))), preferred=0x85, tc_timeout_ms=6000),
    ]
    alive = [True, True]
    for n in nodes:
        n.start(0)
    now, pending = 0, list[Frame]()

    def run(seconds: float) -> None:
        nonlocal now, pending
        for _ in range(round(seconds * 1e6 / STEP_US)):
            now += STEP_US
            sent: list[tuple[int, Frame]] = []
            for i, n in enumerate(nodes):
                if alive[i]:
                    for f in pending:
                        n.rx(f.can_id, f.data, now)
                    n.step(now, 0)
                    sent += [(i, f) for f in n.tx()]
            for i, f in sent:  # the nodes hear each other too
                nodes[1 - i].rx(f.can_id, f.data, now)
            pending = tc.step(now, [f for _, f in sent])

    run(8.0)
    served = tc.client
    assert served is not None and served.active
    first = next(i for i, n in enumerate(nodes) if n.address == served.address)
    other = nodes[1 - first]
    assert nodes[first].tc_state == "connected" and other.tc_state != "connected"
    assert (
        f"client {other.address:#x} refused: the TC serves {served.address:#x}, one at a time"
        in tc.errors
    )
    assert tc.counters["refused_frames"] > 0
    alive[first] = False  # the first one is switched off
    run(14.0)
    assert tc.counters["clients_lost"] == 1
    assert tc.client is not None and tc.client.address == other.address and tc.client.active
    assert other.tc_state == "connected"


def test_a_second_tc_on_the_bus_is_named_and_alarms_on_the_same_number() -> None:
    ours = TcServer(tc_name(7))
    same = TcServer(tc_name(8))  # also TC number 1
    other = TcServer(tc_name(9, function_instance=1))  # TC number 2
    servers = [ours, same, other]
    for s in servers:
        s.start(0)
    wire: list[Frame] = []
    for t in range(0, 5_000_000, STEP_US):
        heard, wire = wire, []
        for s in servers:
            wire += s.step(t, [f for f in heard if split_id(f.can_id)[2] != s.address])
    assert len({s.address for s in servers}) == 3  # the contest gave each its own address
    assert ours.address == TC
    assert sorted(ours.other_tcs) == sorted(a for a in (same.address, other.address) if a)
    assert ours.alarms == [f"another Task Controller number 1 at {same.address:#x}"]
    assert ours.other_tcs[other.address] == other.name  # type: ignore[index]
    assert sum(e.endswith(", TC number 2") for e in ours.errors) == 1
    assert ours.counters["other_tcs"] == 2  # each said once, though it sends every 2 s


def test_tc_that_cannot_claim_any_address_alarms() -> None:
    tc = TcServer(tc_name(7))
    tc.start(0)
    lower = [_claim(a, 0x8000000000000000 + a) for a in range(128, 248)]  # every address taken
    for t in range(0, 2_000_000, STEP_US):
        tc.step(t, lower if t in (0, 300_000) else [])
    assert tc.address is None
    assert tc.alarms == ["the TC found no free address: no client can reach it"]


def test_lost_client_alarms_until_one_connects_again() -> None:
    bus = connected(TcServer(tc_name(7)))
    assert bus.tc.alarms == []
    for _ in range(700):
        bus.now += STEP_US
        bus.tc.step(bus.now, [])
    assert bus.tc.alarms == ["the implement at 0x84 stopped answering"]
    bus.run(8.0)  # the client heard again: it connects anew
    assert bus.tc.alarms == [] and bus.tc.client is not None and bus.tc.client.active


def test_process_data_path_fuzzed_server_keeps_serving() -> None:
    """20,000 random process-data frames from the served client and strangers, random TP/ETP
    messages into the TC, random claims: no exception, the status on time, and the client
    still set and acknowledged after."""
    bus = connected(TcServer(tc_name(7)))
    tc = bus.tc
    rng = random.Random(3030)
    tp = TpEndpoint(0x84, 4096)
    t = bus.now
    out: list[Frame] = []
    cmds = list(range(16))
    for i in range(2000):
        t += STEP_US
        frames = []
        for _ in range(10):
            sa = rng.choice([0x84, 0x84, 0x84, 0x90, 0x00, 0xFE])
            kind = rng.random()
            if kind < 0.7:
                head = bytes([rng.choice(cmds) | rng.randrange(16) << 4, rng.randrange(256)])
                ddi = rng.choice([6, 7, 141, 161, 290, 57343, rng.randrange(65536)])
                data = head + struct.pack("<Hi", ddi, rng.randrange(-(2**31), 2**31))
                frames.append(_pd(sa, data[: rng.choice([8, 8, 8, 3, 0])]))
            elif kind < 0.9:
                frames.append(_pd(sa, rng.randbytes(8), da=rng.choice([TC, 0xFF])))
            else:
                frames.append(_claim(rng.randrange(0x80, 0x88), rng.getrandbits(64)))
        if i % 200 == 0 and tp.send_state != "busy":
            body = bytes([rng.choice([0x61, 0x03, 0x41, 0x81, 0xA1])]) + rng.randbytes(
                rng.randint(8, 2500)
            )
            tp.send(0xCB00, TC, body, t)
        tp.step(t)
        frames += tp.tx()
        got = tc.step(t, frames)
        for f in got:
            tp.rx(f.can_id, f.data, t)
        out += got
    assert len(_status_times(out)) == 10  # every 2 s over 20 s
    assert tc.ignored > 0 and tc.counters["unknown_values"] > 0
    assert len(tc.errors) <= 200  # the words kept are bounded however much garbage came
    # a fresh connection after all that: the C client connects and its rate is set
    fresh = Bus(TcServer(tc_name(7)))
    fresh.run(4.0)
    fresh.tc.set_value(3, 6, 15000)
    fresh.run(0.3)
    assert fresh.node.rate_kg_ha(0) == 150.0 and fresh.tc.counters["pdacks_ok"] == 1


def _objects(pool: bytes) -> list[tuple[int, int]]:
    """(start, end) byte range of each object of a pool: the first end at which the bytes
    from its start parse as one whole object."""
    spans: list[tuple[int, int]] = []
    at = 0
    while at < len(pool):
        for end in range(at + 5, len(pool) + 1):
            try:
                if len(parse(pool[at:end])) == 1:
                    break
            except ValueError:
                continue
        spans.append((at, end))
        at = end
    return spans


def test_ddop_parser_fuzzed_structure_aware() -> None:
    """Mutations aimed at the fields of whole objects (ids, element numbers, parents, child
    counts and lists, DDIs, text lengths) of topdress's and AgIsoStack++'s pools, objects
    dropped, doubled and swapped: each pool maps or gives a ProtocolError that says what."""
    pools = [
        build(Machine(3600, 6, 2, -500, 0, 20.0, 600.0))[0],
        (DATA / "agiso_spreader_ddop_2bins_6sections.bin").read_bytes(),
    ]
    rng = random.Random(3031)
    outcomes = {"mapped": 0, "refused": 0}
    kinds = ("malformed", "used twice", "names missing object", "missing parent",
             "device objects", "over 4095")  # fmt: skip
    said: dict[str, int] = dict.fromkeys(kinds, 0)
    for pool in pools:
        spans = _objects(pool)
        objs = [pool[a:b] for a, b in spans]
        for _ in range(1500):
            chosen = list(objs)
            for _ in range(rng.randint(1, 3)):
                k = rng.randrange(len(chosen))
                o = bytearray(chosen[k])
                op = rng.random()
                if op < 0.5:  # a field of the head: id, type, counts, numbers
                    at = rng.randrange(3, min(len(o), 16))
                    o[at] = rng.choice([0, 1, 0xFF, rng.randrange(256)])
                    chosen[k] = bytes(o)
                elif op < 0.65:
                    del chosen[k]
                elif op < 0.8:
                    chosen.insert(k, chosen[k])
                else:
                    j = rng.randrange(len(chosen))
                    chosen[k], chosen[j] = chosen[j], chosen[k]
                if not chosen:
                    chosen = [objs[0]]
            try:
                map_device(b"".join(chosen))
                outcomes["mapped"] += 1
            except ProtocolError as exc:
                outcomes["refused"] += 1
                said[next(k for k in kinds if k in str(exc))] += 1
    assert outcomes["mapped"] > 100 and outcomes["refused"] > 500
    assert all(n > 0 for k, n in said.items() if k != "over 4095"), said


def test_endless_new_nonsense_is_counted_past_the_words_kept() -> None:
    tc, _ = replay_agiso()
    t = 60_000_000
    for ddi in range(3000):  # 3,000 DDIs its pool does not have, each once
        t += STEP_US
        tc.step(t, [_pd(CLIENT, bytes([0x33, 0]) + struct.pack("<Hi", 1000 + ddi, 1))])
    assert tc.counters["unknown_values"] == 3000
    assert tc.counters["errors_suppressed"] > 1900 and len(tc.errors) == 200
    assert tc.client is not None and tc.client.active and not tc.client.lost


def test_a_tc_status_from_an_address_that_never_claimed_is_another_tc() -> None:
    tc, _ = replay_agiso()
    status = Frame(
        3 << 26 | 0xCB00 << 8 | 0xFF << 8 | 0xF0, bytes([0xFE, 0xFF, 0xFF, 0xFF, 0, 0xFF, 0, 0xFF])
    )
    assert tc.client is not None
    t0 = tc.client.last_heard_us + STEP_US
    for k in range(3):  # every second, within the client's timeout
        tc.step(t0 + k * 1_000_000, [status])
    assert tc.other_tcs == {0xF0: None} and tc.counters["other_tcs"] == 1
    assert tc.alarms == ["another Task Controller at 0xf0 (its number not known)"]
    assert tc.client is not None and tc.client.active  # its own client still served


@pytest.mark.interop
def test_two_agiso_clients_live_the_second_nacked_then_served() -> None:
    """Recorded live: this server and two AgIsoStack++ clients (commit in docs/isobus.md), A at
    0x80 from 1 s to 25 s, B at 0x81 from 3 s. B is refused and NACKed; the library says "The TC
    Server is NACK-ing our messages. Disconnecting." and tries again after its start-up delay,
    three times, until A has gone (lost 6 s after its last frame); then B uploads its pool and
    is activated. Both clients' side replayed here."""
    tc, sent = replay_agiso(DATA / "topdress_tc_two_agiso_clients.log", sources=(0x80, 0x81))
    nacks = [f for f in sent if split_id(f.can_id)[1:4:2] == (0xE800, 0x81)]
    assert len(nacks) >= 3 and all(f.data[0] == 1 for f in nacks)
    assert tc.errors[:2] == [
        "client 0x81 refused: the TC serves 0x80, one at a time",
        "client 0x80 silent for 6000 ms",
    ]
    c = tc.client
    assert c is not None and c.address == 0x81 and c.active and c.name == 0xA00A8000AFE00007
    assert tc.counters["activations"] == 2 and tc.counters["clients_lost"] == 1


@pytest.mark.interop
def test_beside_agiso_tc_live_named_alarmed_and_its_client_let_go() -> None:
    """Recorded live: this server (0xF7), AgIsoStack++'s TaskControllerServer (TC number 1 too;
    it took 0x80) and its client (0x81) on one bus. The client announced itself to both, chose
    the other TC and was activated there. Replayed (the other TC's and the client's frames):
    the server names the other TC, raises the alarm, and lets the client go instead of waiting
    for it and reporting it lost."""
    tc, _ = replay_agiso(DATA / "topdress_tc_beside_agiso_tc.log", sources=(0x80, 0x81))
    assert tc.address == TC and tc.other_tcs == {0x80: 0xA0008200AFE00014}
    assert tc.alarms == ["another Task Controller number 1 at 0x80"]
    assert tc.errors == [
        "another Task Controller at 0x80, TC number 1",
        "client 0x81 works with the Task Controller at 0x80",
    ]
    assert tc.client is None and tc.counters["clients_lost"] == 0


def test_a_slow_pool_transfer_is_no_silence() -> None:
    """A client whose 1750-byte pool takes longer than the 6 s client timeout to arrive (it
    takes each clear-to-send 0.6 s late, sending no task message meanwhile): its transport
    frames count as heard, so it is not lost halfway, and the pool is activated."""
    tc = TcServer(tc_name(7))
    tc.start(0)
    tp = TpEndpoint(0x8A, 4096)
    pool = DDOP.read_bytes()
    t, answers, held = 0, list[bytes](), list[Frame]()

    def step(frames: list[Frame], slow: bool = False) -> None:
        nonlocal t
        t += STEP_US
        tp.step(t)
        held.extend(tc.step(t, frames + tp.tx()))
        if slow and t % 600_000:
            return
        for f in held:
            tp.rx(f.can_id, f.data, t)
            if split_id(f.can_id)[1:4:2] == (0xCB00, 0x8A):
                answers.append(f.data)
        held.clear()

    for _ in range(40):
        step([])
    step([Frame(6 << 26 | 0xFE0D << 8 | 0x8A, bytes([1]) + b"\xff" * 7)])
    step([_pd(0x8A, bytes([0x41]) + len(pool).to_bytes(4, "little") + b"\xff" * 3)])
    start = t
    tp.send(0xCB00, TC, bytes([0x61]) + pool, t)
    while tp.send_state == "busy":
        step([], slow=True)
    step([_pd(0x8A, bytes([0x81]) + b"\xff" * 7)])
    assert t - start > 6_000_000  # slower than the client timeout
    assert tp.send_state == "done" and tc.counters["clients_lost"] == 0
    c = tc.client
    assert c is not None and c.active and c.pool == pool
    assert answers[-1] == bytes([0x91, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0, 0xFF])
