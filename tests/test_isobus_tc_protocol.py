"""The Task Controller's protocol features against the topdress ECU's C TC client (virtual time,
one process) and the AgIsoStack++ client's recorded pool: known pools kept beside the session
logs and offered back by their labels (a corrupt one set aside and asked for again), measurement
commands by time, distance, threshold and change as the pool offers them, acknowledges awaited
and their errors read, the client's options (TC-GEO) read from its version message."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from tc_rig import (
    AGISO_NAME,
    CLIENT,
    DATA,
    DDOP,
    ECU_NAME,
    STEP_US,
    TC,
    client_frames,
    connected,
    replay_agiso,
)
from topdress.errors import ProtocolError
from topdress.isobus.devicemap import (
    TRIG_CHANGE,
    TRIG_DISTANCE,
    TRIG_THRESHOLD,
    TRIG_TIME,
    map_device,
)
from topdress.isobus.node import Frame, IsobusNode, split_id
from topdress.isobus.poolstore import PoolStore
from topdress.isobus.tcserver import (
    PD_PGN,
    PDACK,
    Client,
    TcServer,
    pd_frame,
    pdack_texts,
    tc_name,
)


def test_pool_kept_and_offered_back_by_its_labels(tmp_path: Path) -> None:
    store = PoolStore.beside(tmp_path)
    first = connected(TcServer(tc_name(7), store=store))
    assert first.uploads() == 1
    c = first.tc.client
    assert c is not None and c.name == ECU_NAME and c.device is not None and not c.from_store
    files = list((tmp_path / "ddop").glob("*.ddop"))
    label = c.device.structure_label
    assert [f.name for f in files] == [
        f"{ECU_NAME:016X}_{label.hex()}_{c.device.localization_label.hex()}.ddop"
    ]
    # the terminal restarted: a new server on the same folder; the client is told its labels
    # match and activates the pool without sending it
    again = connected(TcServer(tc_name(7), store=PoolStore.beside(tmp_path)))
    assert again.uploads() == 0
    c2 = again.tc.client
    assert c2 is not None and c2.from_store and c2.pool == c.pool
    answers = [f.data for f in again.from_tc if split_id(f.can_id)[3] == 0x84]
    assert bytes([0x11]) + label in answers
    assert bytes([0x31]) + c.device.localization_label in answers
    assert again.tc.counters["uploads_saved"] == 1 and again.tc.errors == []
    again.tc.set_value(3, 6, 15000)  # and it is served as before
    again.run(0.5)
    assert again.node.rate_kg_ha(0) == 150.0


def test_a_client_whose_pool_changed_uploads_the_new_one(tmp_path: Path) -> None:
    """The folder holds another description for this NAME (the machine was reconfigured): the
    TC offers that pool's structure label, the client's differs, so it uploads and the new pool
    replaces the old."""
    store = PoolStore.beside(tmp_path)
    other = (
        Path(__file__).parent / "data" / "agiso_spreader_ddop_2bins_6sections.bin"
    ).read_bytes()
    store.save(ECU_NAME, other, b"1234567", b"en\x50\x00\x00\x00\xff")
    bus = connected(TcServer(tc_name(7), store=store))
    c = bus.tc.client
    assert c is not None and c.device is not None
    offered = [f.data for f in bus.from_tc if split_id(f.can_id)[3] == 0x84 and f.data[0] == 0x11]
    assert offered and offered[0][1:] != c.device.structure_label  # the old pool's label
    assert bus.uploads() == 1 and not c.from_store and c.device.designator == "topdress"
    assert store.load(ECU_NAME) == c.pool
    assert len(list((tmp_path / "ddop").glob("*.ddop"))) == 1


@pytest.mark.parametrize("damage", ["flip", "cut", "garbage", "not_a_pool"])
def test_corrupt_stored_pool_set_aside_and_asked_for_again(tmp_path: Path, damage: str) -> None:
    store = PoolStore.beside(tmp_path)
    connected(TcServer(tc_name(7), store=store))
    (path,) = (tmp_path / "ddop").glob("*.ddop")
    raw = bytearray(path.read_bytes())
    if damage == "flip":
        raw[-100] ^= 0x40
    elif damage == "cut":
        del raw[len(raw) // 2 :]
    elif damage == "garbage":
        raw[:] = b"\x00" * 10
    path.write_bytes(bytes(raw))
    if damage == "not_a_pool":  # the checksum holds but the bytes are no DDOP
        store.save(ECU_NAME, b"DVC\x00\x00junk", b"1234567", b"en\x50\x00\x00\x00\xff")
    tc = TcServer(tc_name(7), store=store)
    bus = connected(tc)
    assert bus.uploads() == 1  # asked for again, sent, activated
    assert tc.counters["stored_pools_corrupt"] == 1
    reason = "DDOP malformed" if damage == "not_a_pool" else "set aside"
    assert any(reason in e and "asked for again" in e for e in tc.errors), tc.errors
    assert list((tmp_path / "ddop").glob("*.corrupt"))  # kept for a look
    assert store.load(ECU_NAME) == bus.tc.client.pool  # type: ignore[union-attr]


def test_store_that_cannot_write_is_said_and_the_session_goes_on(tmp_path: Path) -> None:
    blocker = tmp_path / "ddop"
    blocker.write_text("a file where the folder should be")
    tc = TcServer(tc_name(7), store=PoolStore(blocker))
    connected(tc)
    assert tc.counters["store_errors"] == 1 and "not kept" in tc.errors[-1]


def test_client_delete_forgets_the_kept_pool(tmp_path: Path) -> None:
    store = PoolStore.beside(tmp_path)
    bus = connected(TcServer(tc_name(7), store=store))
    delete = Frame(5 << 26 | 0xCB00 << 8 | 0xF7 << 8 | 0x84, bytes([0xA1]) + b"\xff" * 7)
    out = bus.tc.step(bus.now + STEP_US, [delete])
    assert any(f.data[:2] == b"\xb1\x00" for f in out)
    assert store.load(ECU_NAME) is None


def test_measurements_by_time_distance_and_change() -> None:
    bus = connected(TcServer(tc_name(7)))
    tc, node = bus.tc, bus.node
    c = tc.client
    assert c is not None and c.device is not None
    # the topdress pool: actual rate by time, distance, threshold and change; work state by
    # change and threshold only
    assert c.device.triggers[(3, 7)] == TRIG_TIME | TRIG_DISTANCE | TRIG_THRESHOLD | TRIG_CHANGE
    assert c.device.measured(0, 141, TRIG_CHANGE) and not c.device.measured(0, 141, TRIG_TIME)
    start = c.heard.get((3, 7), 0)
    tc.measure_distance(3, 7, 5_000)  # every 5 m; the client drives 2.8 m/s
    bus.run(18.0)
    assert c.heard[(3, 7)] - start in (10, 11)  # one at once, then one per 5 m over 50.4 m
    tc.measure_distance(3, 7, 0)
    tc.measure_on_change(4, 7, 500)  # 5 kg/ha
    bus.run(0.5)
    before = c.heard.get((4, 7), 0)
    for value in (1000, 1200, 1600, 1700, 2300):  # moves of 200, 400, 100, 600 from 1000
        node.set_actual(4, 7, value)
        bus.run(0.2)
    assert c.values[(4, 7)] == 2300
    # reported at once (1000 after 0), then at 1600 (600 from 1000) and 2300 (700 from 1600)
    assert c.heard[(4, 7)] - before == 3
    tc.measure_threshold(4, 75, maximum=500_000)  # content over 500 kg
    sent = [f.data for f in tc.step(bus.now + STEP_US, [])]
    assert pd_frame(7, 4, 75, 500_000) in sent


def test_measurement_the_pool_does_not_offer_is_refused_before_the_bus() -> None:
    bus = connected(TcServer(tc_name(7)))
    tc = bus.tc
    with pytest.raises(ProtocolError, match="no time trigger for DDI 141 of element 0"):
        tc.measure_every(0, 141, 1000)
    with pytest.raises(ProtocolError, match="no distance trigger"):
        tc.measure_distance(3, 75, 1000)
    with pytest.raises(ProtocolError, match="no on-change trigger for DDI 7 of element 9"):
        tc.measure_on_change(9, 7, 1)
    with pytest.raises(ProtocolError, match="minimum or a maximum"):
        tc.measure_threshold(3, 7)
    with pytest.raises(ProtocolError, match="above maximum"):
        tc.measure_threshold(3, 7, minimum=10, maximum=5)
    with pytest.raises(ProtocolError, match="below 0"):
        tc.measure_distance(3, 7, -1)
    assert tc.counters["measurements_asked"] == 0


def test_pdack_errors_read_and_a_missing_acknowledge_reported() -> None:
    bus = connected(TcServer(tc_name(7)))
    tc = bus.tc
    c = tc.client
    assert c is not None
    tc.set_value(3, 6, 1_000_000)  # 10,000 kg/ha: over the pool's maximum, the client refuses
    bus.run(0.3)
    assert c.pdacks[-1][:2] == (3, 6) and c.pdacks[-1][2] != 0
    assert tc.counters["pdack_errors"] == 1
    assert tc.errors[-1].startswith("client 0x84 refused DDI 6 of element 3: ")
    assert "outside the operational range" in tc.errors[-1] or "conform" in tc.errors[-1]
    tc.set_value(3, 6, 15000)
    bus.run(0.3)
    assert tc.counters["pdacks_ok"] >= 1 and not c.awaiting
    # the client stops hearing us: the acknowledge never comes
    tc.set_value(3, 6, 12000)
    for _ in range(120):
        bus.now += STEP_US
        tc.step(bus.now, [])
    assert tc.counters["pdacks_missing"] == 1
    assert "did not acknowledge DDI 6 of element 3 within 1000 ms" in tc.errors[-1]


def test_missing_acknowledges_said_once_per_silence_and_the_answer_again_said() -> None:
    """A client that stops hearing the TC misses the acknowledges of the values set (two rates
    every 0.5 s for 4 s): counted each, said once; when it acknowledges again, that is said."""
    bus = connected(TcServer(tc_name(7)))
    tc = bus.tc
    c = tc.client
    assert c is not None
    said = len(tc.errors)
    for k in range(8):  # its frames no longer reach it (the bus is not run)
        tc.set_value(3, 6, 12000 + k)
        tc.set_value(4, 6, 12000 + k)
        for _ in range(50):
            bus.now += STEP_US
            tc.step(bus.now, [])
    missing = tc.counters["pdacks_missing"]
    # an awaited acknowledge is due 1 s after the first set of its DDI: at 1 s and 2.5 s each
    assert missing == 4
    new = tc.errors[said:]
    assert new == ["client 0x84 did not acknowledge DDI 6 of element 3 within 1000 ms"]
    bus.run(0.2)  # it hears the TC again within its 6 s (the two set at 3 s are missed too)
    missing = tc.counters["pdacks_missing"]
    assert missing == 6 and tc.errors[said + 1 :] == []
    tc.set_value(3, 6, 15000)
    bus.run(0.3)
    assert tc.errors[said + 1 :] == [
        f"client 0x84 acknowledges again ({missing} acknowledges were missing)"
    ]
    assert c.unanswered == 0 and not c.lost
    tc.set_value(3, 6, 15500)  # a later miss is a new silence: said again
    for _ in range(120):
        bus.now += STEP_US
        tc.step(bus.now, [])
    assert tc.errors[-1] == "client 0x84 did not acknowledge DDI 6 of element 3 within 1000 ms"


def test_a_client_that_never_acknowledges_one_value_is_said_once() -> None:
    """A client that acknowledges element 4's rate but never element 3's (both set every
    1.5 s for 12 s): each of element 3's misses is counted, said once; element 4's
    acknowledges are no end of that silence, so nothing more is said."""
    bus = connected(TcServer(tc_name(7)))
    tc, node = bus.tc, bus.node
    said = len(tc.errors)

    def kept(f: Frame) -> bool:  # the client's acknowledges of element 3's DDI 6 are lost
        d = f.data
        pdack = split_id(f.can_id)[1] == PD_PGN and d[0] & 0x0F == PDACK
        return not (pdack and (d[0] >> 4 | d[1] << 4, d[2] | d[3] << 8) == (3, 6))

    pending: list[Frame] = []
    for k in range(8):
        tc.set_value(3, 6, 12000 + 100 * k)
        tc.set_value(4, 6, 12000 + 100 * k)
        for _ in range(150):
            bus.now += STEP_US
            for f in pending:
                node.rx(f.can_id, f.data, bus.now)
            node.step(bus.now, 0)
            pending = tc.step(bus.now, [f for f in node.tx() if kept(f)])
    assert tc.counters["pdacks_missing"] == 8 and tc.counters["pdacks_ok"] >= 8
    assert tc.errors[said:] == ["client 0x84 did not acknowledge DDI 6 of element 3 within 1000 ms"]


def test_a_tc_started_after_the_implement_asks_for_its_claim() -> None:
    """The implement claimed 0x84 before the TC was on the bus: the TC's first frame is a
    request for address claim from the null address, the implement claims again, and the TC
    knows its NAME (PropLink judges a topdress ECU by it)."""
    node = IsobusNode(ECU_NAME, tc_timeout_ms=6000)
    node.start(0)
    now = 0
    for _ in range(50):  # 0.5 s alone: claimed, its frames heard by nobody
        now += STEP_US
        node.step(now, 0)
        node.tx()
    assert node.address == 0x84
    tc = TcServer(tc_name(7))
    tc.start(now)
    out = tc.step(now, [])
    assert (out[0].can_id, bytes(out[0].data)) == (0x18EAFFFE, b"\x00\xee\x00")
    for _ in range(10):
        now += STEP_US
        for f in out:
            node.rx(f.can_id, f.data, now)
        node.step(now, 0)
        out = tc.step(now, node.tx())
    assert tc.names[0x84] == ECU_NAME


def test_the_server_offers_tc_geo_with_position_based_control() -> None:
    """The version the TC answers, read as a client reads it: ISO 11783-10 version 4, TC-BAS,
    TC-GEO with position-based control and TC-SC, 1 boom, 16 sections, 2 position-based
    control channels; the ECU's C client takes the options."""
    bus = connected(TcServer(tc_name(7)))
    (answer,) = {
        f.data
        for f in bus.from_tc
        if split_id(f.can_id)[1] == 0xCB00 and f.data[0] == 0x10 and split_id(f.can_id)[3] != 0xFF
    }
    server = Client(0, 0, version=answer)  # its options read with the client's own words
    assert server.option_names == [
        "documentation",
        "TC-GEO with position-based control",
        "implement section control",
    ]
    assert answer[1] == 4 and tuple(answer[5:8]) == (1, 16, 2)
    assert bus.node.tc_state == "connected"


@pytest.mark.interop
def test_agiso_client_live_against_the_tc_offering_tc_geo() -> None:
    """Recorded live (docs/isobus.md): AgIsoStack++'s client against this server announcing
    TC-GEO with position-based control (0x15, 2 channels). It activated its pool, took the
    rates (150, then 180 kg/ha) and sections and reported; its side replayed here too."""
    trace = DATA / "topdress_tc_geo_session.log"
    server = [f.data for _, f in client_frames(trace, sources=(TC,))]
    assert bytes([0x10, 4, 0xFF, 0x15, 0, 1, 16, 2]) in server
    assert bytes([0x91, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0, 0xFF]) in server  # activated
    reported = [
        struct.unpack_from("<i", f.data, 4)[0]
        for _, f in client_frames(trace)
        if split_id(f.can_id)[1] == 0xCB00 and f.data[0] == 0x33 and f.data[2:4] == b"\x07\x00"
    ]
    assert reported and reported[-1] == pytest.approx(18000, rel=0.01)  # bin 1 at 180 kg/ha
    tc, _ = replay_agiso(trace)
    c = tc.client
    assert c is not None and c.active and c.geo and tc.errors == []


def test_pdack_error_bits_in_words() -> None:
    assert pdack_texts(0) == [] and pdack_texts(0xFF) == []  # AgIsoStack++: no code given
    assert [str(t) for t in pdack_texts(0x04)] == ["DDI not supported by the element"]
    assert [str(t) for t in pdack_texts(0x90)] == [
        "process data not settable",
        "value outside the operational range",
    ]


def test_client_options_read_from_its_version_message() -> None:
    """AgIsoStack++'s client says 0x15 (documentation, TC-GEO with position-based control,
    section control): the TC knows it can do TC-GEO; the topdress ECU says what it does."""
    tc, _ = replay_agiso()
    c = tc.client
    assert c is not None and c.options == 0x15 and c.geo and c.section_control
    assert c.option_names == [
        "documentation",
        "TC-GEO with position-based control",
        "implement section control",
    ]
    ecu = connected(TcServer(tc_name(7))).tc.client
    assert ecu is not None and ecu.version is not None
    assert ecu.geo == bool(ecu.options & 0x06) and ecu.section_control


def test_sections_set_and_read_back_condensed() -> None:
    bus = connected(TcServer(tc_name(7)))
    tc = bus.tc
    assert tc.sections_working() is None or len(tc.sections_working() or []) == 6
    tc.set_value(2, 160, 1)  # section control: automatic
    tc.set_value(2, 289, 1)
    tc.set_sections([True, True, False, False, True, None])
    tc.measure_on_change(2, 161, 1)
    bus.run(0.5)
    assert bus.node.sections_on == 0b010011  # the ECU takes "leave as is" (11) for off
    # the machine reports what its sections do (here 1 and 6 working), by change
    bus.node.set_actual(2, 161, -4096 + 0b01_00_00_00_00_01)
    bus.run(0.3)
    assert tc.sections_working() == [True, False, False, False, False, True]
    with pytest.raises(ProtocolError, match="7 section states for 6 sections"):
        tc.set_sections([True] * 7)


@pytest.mark.interop
def test_agiso_client_live_upload_then_labels_match_and_no_upload(tmp_path: Path) -> None:
    """Two sessions recorded live between this server (kept pools in a folder) and AgIsoStack++'s
    client (commit in docs/isobus.md): the first uploads its 1750-byte pool, which is kept; in
    the second the client hears its structure and localization labels, activates without
    sending the pool (93 frames on the bus, not 361), and is served. Replayed here: the
    client's side of each against a fresh server on one store."""
    store = PoolStore.beside(tmp_path)
    first, _ = replay_agiso(DATA / "topdress_tc_agiso_client_upload.log", store)
    c1 = first.client
    assert c1 is not None and c1.active and not c1.from_store and first.errors == []
    assert c1.pool == DDOP.read_bytes() and c1.geo  # version 4, options 0x15: TC-GEO
    kept = store.load(AGISO_NAME)
    assert kept == DDOP.read_bytes()
    second, sent2 = replay_agiso(DATA / "topdress_tc_agiso_client_stored.log", store)
    c2 = second.client
    assert c2 is not None and c2.active and c2.from_store and second.errors == []
    assert second.counters["uploads_saved"] == 1
    to_client = [f.data for f in sent2 if split_id(f.can_id)[3] == CLIENT]
    device = map_device(DDOP.read_bytes())
    assert bytes([0x11]) + device.structure_label in to_client
    assert bytes([0x31]) + device.localization_label in to_client
    assert bytes([0x91, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0, 0xFF]) in to_client
    # the recorded client sent no pool: no TP from it in the second session
    frames = client_frames(DATA / "topdress_tc_agiso_client_stored.log")
    assert not [f for _, f in frames if split_id(f.can_id)[1] in (0xEC00, 0xEB00, 0xC800)]
    # and what it reported in the live run: the upper bin at 180 kg/ha, sections 4-6 working
    assert c2.values[(3, 7)] == 18000
    assert second.sections_working() == [False, False, False, True, True, True]


@pytest.mark.interop
def test_agiso_client_live_corrupt_kept_pool_asked_for_again(tmp_path: Path) -> None:
    """Recorded live with a kept pool whose bytes were flipped on disk: the server sets the
    file aside, answers "none stored", and AgIsoStack++'s client uploads its pool again (TP) and
    is activated; the pool is kept anew."""
    store = PoolStore.beside(tmp_path)
    device = map_device(DDOP.read_bytes())
    path = store.save(AGISO_NAME, DDOP.read_bytes(), device.structure_label,
                      device.localization_label)  # fmt: skip
    raw = bytearray(path.read_bytes())
    raw[-300] ^= 0x10  # as on the recording's disk
    path.write_bytes(bytes(raw))
    tc, sent = replay_agiso(DATA / "topdress_tc_agiso_client_corrupt_kept.log", store)
    c = tc.client
    assert c is not None and c.active and not c.from_store and c.pool == DDOP.read_bytes()
    assert tc.counters["stored_pools_corrupt"] == 1 and "fails its checksum" in tc.errors[0]
    assert bytes([0x11]) + b"\xff" * 7 in [f.data for f in sent]
    assert store.load(AGISO_NAME) == DDOP.read_bytes()
    assert len(list((tmp_path / "ddop").glob("*.corrupt"))) == 1
