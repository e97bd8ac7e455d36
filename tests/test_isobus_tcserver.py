"""The terminal's Task Controller (topdress.isobus.tcserver) against a client nobody here wrote:
the client's side of a session recorded between AgIsoStack++'s TaskControllerClient (a spreader,
2 bins, 6 sections) and its TaskControllerServer (commit in docs/isobus.md) replayed against the
topdress server, which must claim, take the pool by TP, map it, activate it, command the rate and
sections and take the client's measurements and PDACKs."""

from __future__ import annotations

import random

import pytest

from tc_rig import CLIENT, DATA, DDOP, TC, replay_agiso
from topdress.errors import ProtocolError
from topdress.isobus.node import Frame, TpEndpoint, name_fields, split_id
from topdress.isobus.tcserver import TcServer, map_device, pd_frame, tc_name


@pytest.mark.interop
def test_agiso_client_pool_accepted_activated_and_measured() -> None:
    tc, sent = replay_agiso()
    assert tc.address == TC
    c = tc.client
    assert c is not None and c.address == CLIENT
    assert c.pool is not None and len(c.pool) == DDOP.stat().st_size
    assert c.pool == DDOP.read_bytes()  # the transfer over TP delivered the pool unchanged
    assert c.active and not c.lost and tc.errors == []
    assert c.device is not None
    assert sorted(c.device.bins) == [3, 4] and c.device.sections == [5, 6, 7, 8, 9, 10]
    assert c.device.condensed == {290: 2, 161: 2}
    mine = [f.data for f in sent if split_id(f.can_id)[3] == CLIENT]
    # version 4: TC-BAS, TC-GEO with position-based control, TC-SC; 1 boom, 16 sections, 2
    # position-based control channels
    assert bytes([0x10, 4, 0xFF, 0x15, 0, 1, 16, 2]) in mine
    assert bytes([0x00]) + b"\xff" * 7 in mine  # its working-set master heard: version asked
    assert c.version is not None and c.version[:2] == b"\x10\x04"  # it answered: version 4
    assert bytes([0x11]) + b"\xff" * 7 in mine  # no structure label stored
    assert any(split_id(f.can_id)[1] == 0xFE0F and f.data[:2] == b"en" for f in sent)  # language
    assert any(d[:2] == b"\x71\x00" for d in mine)  # transfer response: OK
    assert bytes([0x91, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0, 0xFF]) in mine  # activated
    # the client's values (its answers and time-interval measurements, as recorded): bin 3's
    # maximum rate and its last actual rate
    assert c.values[(3, 8)] == 15000 and c.values[(3, 7)] == 0xAB
    # its PDACKs carry 0xFFFFFFFF after the DDI: taken, the error byte read as it stands
    assert (2, 160, 0xFF) in c.pdacks


@pytest.mark.interop
def test_agiso_client_pool_over_etp() -> None:
    """2 bins, 16 sections: a 2667-byte pool, over the 1785 bytes of TP, so ETP."""
    tc, sent = replay_agiso(DATA / "agiso_tc_session_etp_agiso_client.log")
    c = tc.client
    assert c is not None and c.active and tc.errors == []
    assert c.pool == (DATA / "agiso_spreader_ddop_2bins_16sections.bin").read_bytes()
    assert c.device is not None and len(c.device.sections) == 16
    assert any(split_id(f.can_id)[1] == 0xC800 for f in sent)  # the server's ETP CTS


def test_second_client_refused_first_kept() -> None:
    tc, _ = replay_agiso()
    ignored = tc.ignored
    second = Frame(5 << 26 | 0xCB00 << 8 | TC << 8 | 0x81, bytes([0]) + b"\xff" * 7)  # version?
    out = tc.step(60_000_000, [second, second])
    # one negative acknowledgement (J1939 ACK PGN, control 1, for PGN 0xCB00), nothing else
    to_second = [f for f in out if split_id(f.can_id)[3] == 0x81]
    assert [(split_id(f.can_id)[1], f.data) for f in to_second] == [
        (0xE800, bytes([1, 0xFF, 0xFF, 0xFF, 0x81, 0x00, 0xCB, 0x00]))
    ]
    assert tc.client is not None and tc.client.address == CLIENT and tc.client.active
    assert tc.ignored == ignored + 2 and tc.errors == [
        "client 0x81 refused: the TC serves 0x80, one at a time"
    ]
    tc.step(70_000_000, [])  # the first client silent past its timeout: the second is served
    out = tc.step(70_000_000, [second])
    assert next(f.data for f in out if split_id(f.can_id)[3] == 0x81)[:2] == b"\x10\x04"


def test_bad_values_refused_before_the_bus() -> None:
    """The values AgIsoStack++'s client acknowledged alike in a recorded run (agiso_tc_bad_values):
    not settable, no such element, no such DDI, negative rate; the topdress TC sends none."""
    tc, _ = replay_agiso()
    for element, ddi, value in ((3, 7, 12345), (99, 6, 15000), (2, 65000, 1), (3, 6, -5000)):
        with pytest.raises(ProtocolError):
            tc.set_value(element, ddi, value)
    assert not [f for f in tc.step(60_000_000, []) if f.data[0] & 0x0F == 10]


@pytest.mark.interop
def test_rate_and_sections_commanded_after_activation() -> None:
    tc, _ = replay_agiso()
    tc.set_value(3, 6, 15000)  # 150 kg/ha in the DDOP's mg/m^2
    tc.set_value(2, 290, -4096 + 0x555, ack=False)
    tc.measure_every(3, 7, 1000)
    out = tc.step(60_000_000, [])
    pd = [f.data for f in out if split_id(f.can_id)[1] == 0xCB00 and split_id(f.can_id)[3] == 0x80]
    assert pd_frame(10, 3, 6, 15000) in pd
    assert pd_frame(3, 2, 290, -4096 + 0x555) in pd
    assert pd_frame(4, 3, 7, 1000) in pd


def test_silent_client_reported_lost_and_refused_commands() -> None:
    tc, _ = replay_agiso()
    c = tc.client
    assert c is not None
    last = c.last_heard_us
    tc.step(last + 5_900_000, [])
    assert not c.lost
    tc.step(last + 6_100_000, [])
    assert c.lost and "silent" in tc.errors[-1]
    with pytest.raises(ProtocolError):
        tc.set_value(3, 6, 15000)


def test_pd_frame_out_of_range_is_a_protocol_error() -> None:
    with pytest.raises(ProtocolError):
        pd_frame(10, 4096, 6, 0)
    with pytest.raises(ProtocolError):
        pd_frame(10, 3, 6, 2**31)


def test_tc_name_fields() -> None:
    f = name_fields(tc_name(7))
    assert (f["function"], f["industry_group"], f["identity_number"]) == (130, 2, 7)
    assert f["self_configurable"] == 1


@pytest.mark.interop
def test_ddop_mutations_give_clear_errors_only() -> None:
    """Random byte flips, cuts and splices of the AgIsoStack++ pool: mapped or ProtocolError."""
    pool = DDOP.read_bytes()
    rng = random.Random(30)
    errors = 0
    for _ in range(1500):
        b = bytearray(pool)
        for _ in range(rng.randint(1, 6)):
            op, at = rng.random(), rng.randrange(len(b))
            if op < 0.6:
                b[at] = rng.randrange(256)
            elif op < 0.8:
                del b[at:]
            else:
                b[at:at] = rng.randbytes(rng.randint(1, 9))
            if not b:
                b = bytearray(b"D")
        try:
            map_device(bytes(b))
        except ProtocolError as exc:
            errors += 1
            assert str(exc)
    assert 100 < errors < 1500  # both outcomes reached


def test_bad_pool_refused_at_activation_and_oversized_refused_for_memory() -> None:
    tc = TcServer(tc_name(7))
    tc.start(0)
    for t in range(0, 400_000, 10_000):
        tc.step(t, [])
    assert tc.address == TC

    def send(data: bytes, t: int) -> list[bytes]:
        f = Frame(5 << 26 | 0xCB00 << 8 | TC << 8 | CLIENT, data)
        return [o.data for o in tc.step(t, [f]) if split_id(o.can_id)[3] == CLIENT]

    big = send(bytes([0x41]) + (70_000).to_bytes(4, "little") + b"\xff\xff\xff", 500_000)
    assert big == [bytes([0x51, 1]) + b"\xff" * 6] and "too large" in tc.errors[-1]
    bad = DDOP.read_bytes()[:200]  # cut inside an object, sent whole (7 bytes at a time, by TP)
    tp = TpEndpoint(CLIENT)
    tp.send(0xCB00, TC, bytes([0x61]) + bad, 600_000)
    t, answers = 600_000, list[bytes]()
    for _ in range(200):
        t += 10_000
        for o in tc.step(t, tp.tx()):
            tp.rx(o.can_id, o.data, t)
            answers += [o.data] if split_id(o.can_id)[3] == CLIENT else []
        tp.step(t)
    assert any(a[:2] == b"\x71\x00" for a in answers)
    assert "malformed" in tc.errors[-1]
    assert send(bytes([0x81]) + b"\xff" * 7, t + 10_000) == [
        bytes([0x91, 1, 0xFF, 0xFF, 0xFF, 0xFF, 4, 0xFF])
    ]
    assert tc.client is not None and not tc.client.active


def test_process_data_garbage_counted_never_raised() -> None:
    tc, _ = replay_agiso()
    rng = random.Random(31)
    t = 60_000_000
    for _ in range(2000):
        t += 1000
        data = rng.randbytes(rng.randint(0, 8))
        tc.step(t, [Frame(5 << 26 | 0xCB00 << 8 | TC << 8 | CLIENT, data)])
    assert tc.ignored > 0


def test_tc_address_taken_by_a_higher_priority_name_moves_on() -> None:
    tc = TcServer(tc_name(7))
    tc.start(0)
    for t in range(0, 400_000, 10_000):
        tc.step(t, [])
    assert tc.address == TC
    rival = Frame(6 << 26 | 0xEE00 << 8 | 0xFF << 8 | TC, (1).to_bytes(8, "little"))  # NAME 1
    out: list[Frame] = []
    for t in range(400_000, 1_200_000, 10_000):
        out += tc.step(t, [rival] if t == 400_000 else [])
    moved = tc.address
    assert moved is not None and moved != TC and 128 <= moved <= 247
    assert any(split_id(f.can_id)[1] == 0xEE00 and split_id(f.can_id)[2] == moved for f in out)
    # the TC answers from its new address
    ask = Frame(5 << 26 | 0xCB00 << 8 | moved << 8 | CLIENT, bytes([0]) + b"\xff" * 7)
    answer = [f for f in tc.step(1_300_000, [ask]) if split_id(f.can_id)[3] == CLIENT]
    assert answer and split_id(answer[0].can_id)[2] == moved
