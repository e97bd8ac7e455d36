"""The terminal's inbox: bounded line queues per source, control items first, and a terminal
that keeps commanding the ECU while a GNSS input floods it."""

from __future__ import annotations

import threading
import time
from dataclasses import replace

from ecu_twin import SimulatedEcu
from topdress.config import default_config
from topdress.devices.can import open_bus
from topdress.devices.lines import FakeLineSource
from topdress.gnss.nmea import make_sentence
from topdress.terminal.app import Terminal
from topdress.terminal.inbox import Inbox


def test_a_flooding_source_loses_its_oldest_lines_counted_and_nothing_else() -> None:
    box = Inbox(line_limit=4)
    for i in range(10):
        box.put(("nmea", float(i), b"gnss %d" % i))
    box.put(("crop", 0.5, b"crop"))
    assert box.dropped == {"nmea": 6}
    assert box.depth() == 5 and box.high_water["nmea"] == 4
    got = [box.get(0) for _ in range(5)]
    assert [i[2] for i in got if i is not None and i[0] == "nmea"] == [
        b"gnss 6",
        b"gnss 7",
        b"gnss 8",
        b"gnss 9",
    ]  # the newest four, in order
    assert box.get(0) is None and box.empty()


def test_control_items_never_wait_behind_lines() -> None:
    box = Inbox(line_limit=100)
    for i in range(100):
        box.put(("nmea", float(i), b"x"))
    box.put(("can", 100.0, "frame"))
    box.put(("op", 100.1, "stop"))
    first = box.get(0)
    second = box.get(0)
    assert first is not None and first[0] == "can"
    assert second is not None and second[0] == "op"


def test_sources_take_turns() -> None:
    box = Inbox()
    for i in range(3):
        box.put(("nmea", float(i), b"n"))
        box.put(("crop", float(i), b"c"))
    kinds = [item[0] for item in iter(lambda: box.get(0), None)]
    assert kinds == ["nmea", "crop"] * 3


def test_get_waits_for_a_put_from_another_thread() -> None:
    box = Inbox()
    threading.Timer(0.05, box.put, args=(("can", 1.0, "late"),)).start()
    assert box.get(timeout=5.0) == ("can", 1.0, "late")


def test_control_bound_drops_oldest_counted() -> None:
    box = Inbox(control_limit=3)
    for i in range(5):
        box.put(("can", float(i), i))
    assert box.dropped == {"can": 2}
    first = box.get(0)
    assert first is not None and first[2] == 2


def test_terminal_keeps_the_ecu_link_while_gnss_floods() -> None:
    # A receiver flooding the terminal (a file replayed as fast as read) grew the one shared
    # queue without bound; CAN frames waited behind the lines and the ECU was declared lost.
    cfg = default_config()
    cfg = replace(cfg, can=replace(cfg.can, channel="test-inbox-flood"))
    gnss = FakeLineSource()
    pc_bus, ecu_bus = open_bus(cfg.can), open_bus(cfg.can)
    ecu = SimulatedEcu(ecu_bus, now=time.monotonic())
    events: list[str] = []
    term = Terminal(cfg, gnss, FakeLineSource(), pc_bus, on_event=events.append)
    stop = threading.Event()

    def run_ecu() -> None:
        while not stop.wait(0.01):
            ecu.pump(time.monotonic())

    def flood() -> None:
        line = make_sentence("GNRMC,000001.00,A,4500.0,N,12600.0,E,3.5,0.0,010126,,,A")
        while not stop.is_set():
            for _ in range(500):
                gnss.emit(time.monotonic(), line)
            time.sleep(0)  # let the other threads in, as a reader thread blocked on read does

    threads = [threading.Thread(target=f, daemon=True) for f in (run_ecu, flood)]
    for th in threads:
        th.start()
    try:
        term.run(duration_s=2.5)
    finally:
        stop.set()
        for th in threads:
            th.join(2.0)
        pc_bus.shutdown()
        ecu_bus.shutdown()
    assert term.link.params_done  # the parameter push went through during the flood
    assert not any("ECU lost" in str(e) for e in events), [str(e) for e in events]
    # Command period 0.5 s: every period kept sending (the first after the push, ~0.1 s in).
    assert term.link.counters.tx_commands >= 3
    assert term.snapshot.counters["nmea_dropped"] > 0  # the flood was cut, and counted
    # and it never reached the ECU's bus: one PcGnssTime per 25 ms at most, the rest counted
    assert term.counters["gnss_send_skipped"] > 0
    assert term.inbox.high_water["nmea"] <= 256  # bounded: memory cannot grow
