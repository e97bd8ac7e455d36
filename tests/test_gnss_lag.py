"""The GNSS lag the ECU learns, on the terminal's side: shown, logged, kept per receiver and
pushed as the next session's start (the terminal against the simulated machine, virtual time)."""

from __future__ import annotations

import csv
import json
from collections import deque
from dataclasses import replace
from pathlib import Path
from typing import Any

import can
import pytest
from topdress.ecu._core import lib

from test_replay import drive_events
from test_terminal import VirtualRig
from topdress import protocol
from topdress.cli.main import main
from topdress.config import DEFAULT_TOML, loads_config
from topdress.ecu.params import EcuParams, check
from topdress.gnss.nmea import NmeaDecoder, make_sentence
from topdress.log.events import write
from topdress.log.model import LogEvent
from topdress.log.session import SessionLog, SessionReader
from topdress.log.summary import lag_summary, summarise
from topdress.sim.tractor import Drive, Segment
from topdress.terminal.canlink import CanLink
from topdress.terminal.gnsslag import LagWatch
from topdress.terminal.lagstore import STORE_FILE, LagStore
from topdress.terminal.receiver import ReceiverId, ReceiverWatch, input_key

NMEA_LOGS = Path("/work/shared/nmea/gpsd-logs")
SIM_LAG_MS = 1300  # the simulated receiver: 0.3 s latency + a 1.0 s velocity filter
GNSS_LAG = protocol.param("GnssLag").id
GNSS_LAG_AUTO = protocol.param("GnssLagAuto").id
SIM_RECEIVER = ReceiverId("serial:/dev/ttyUSB0", ("GNGGA", "GNRMC", "GNVTG"))


def _session(
    tmp_path: Path, toml: str, talker: str = "GN", until_s: float = 20.0, stand_s: float = 2.0
) -> VirtualRig:
    """One session: standing `stand_s`, then a start from rest to 8 km/h; its log in tmp_path;
    the rig is closed."""
    session = SessionLog.create(tmp_path, toml)
    drive = Drive(
        [
            Segment("stop", duration_s=stand_s),
            Segment("straight", speed_kmh=8.0, length_m=30.0, hold=True),
            Segment("stop", duration_s=5.0),
        ]
    )
    rig = VirtualRig(loads_config(toml), drive, session)
    rig.world.gnss.p = replace(rig.world.gnss.p, talker=talker)
    try:
        rig.run(until_s)
    finally:
        rig.close()
    return rig


def _cruising(tmp_path: Path, toml: str) -> VirtualRig:
    """A session left open: standing 2 s, then a start from rest to 8 km/h held for 60 m."""
    drive = Drive(
        [
            Segment("stop", duration_s=2.0),
            Segment("straight", speed_kmh=8.0, length_m=60.0, hold=True),
            Segment("stop", duration_s=5.0),
        ]
    )
    return VirtualRig(loads_config(toml), drive, SessionLog.create(tmp_path, toml))


def _power_cycle(rig: VirtualRig, off_s: float = 1.0) -> None:
    """The ECU off the bus for `off_s` (longer than the link's 0.5 s: the terminal reports it
    lost), then its core starts over on the firmware's defaults: parameters and learned lag
    gone, as after a power cut to the implement."""
    rig.ecu_off = True
    rig.run(rig.world.t_s + off_s)
    w = rig.world
    defaults = (w.cfg.ecu or EcuParams.defaults()).to_c()
    check(lib.td_app_init(w.ecu._app, defaults, w.now_us), "power cycle")
    rig.ecu_off = False


def _sent(rig: VirtualRig, since_s: float = 0.0) -> list[tuple[float, protocol.Frame]]:
    """The frames the terminal sent to the ECU from `since_s` on, decoded, in time order."""
    assert rig.term.session is not None
    with SessionReader(rig.term.session.path) as reader:
        rows = [r for r in reader.raw() if r.kind == "can_tx" and r.t >= since_s]
    out = []
    for r in rows:
        assert r.can_id is not None and r.data is not None
        out.append((r.t, protocol.decode((r.can_id, r.data))))
    return out


def _lag_sets(rig: VirtualRig, since_s: float = 0.0) -> list[tuple[int, float]]:
    """The GnssLag and GnssLagAuto values the terminal wrote from `since_s` on."""
    return [
        (f.param_id, f.value)
        for _, f in _sent(rig, since_s)
        if isinstance(f, protocol.PcParamSet) and f.param_id in (GNSS_LAG, GNSS_LAG_AUTO)
    ]


def _events(rig: VirtualRig, kind: str) -> list[LogEvent]:
    assert rig.term.session is not None
    with SessionReader(rig.term.session.path) as reader:
        return [e for e in reader.events() if e.kind == kind]


def _lags(rig: VirtualRig) -> list[tuple[int, int | None, str]]:
    return [
        (s.gnss_lag.in_use_ms, s.gnss_lag.learned_ms, s.gnss_lag.state)
        for _, s in rig.snapshots
        if s.gnss_lag is not None
    ]


def test_the_learned_lag_is_kept_and_starts_the_next_session(tmp_path: Path) -> None:
    first = _session(tmp_path, DEFAULT_TOML)
    lags = _lags(first)
    # no lag kept yet: the ECU starts from its own 0 ms and learns on the first start
    assert lags[0] == (0, None, "start")
    learned = [x for x in lags if x[2] == "learned"]
    assert learned, "the launch from rest teaches the lag"
    in_use, kept_ms, _ = learned[-1]
    assert in_use == kept_ms and abs(kept_ms - SIM_LAG_MS) <= 250  # docs/speed.md: ~1.17 s
    # logged: the first frame (start) and the learning; the receiver; what was kept
    changes = _events(first, "gnss_lag.changed")
    assert [(e.detail["was"], e.detail["state"]) for e in changes[:2]] == [
        (None, "start"),
        ("start", "learned"),
    ]
    assert changes[0].detail["lag_ms"] == 0 and changes[0].detail["learned_ms"] is None
    assert [str(x[1]) for x in first.events if "GNSS lag learned" in x[1]]
    (receiver,) = _events(first, "gnss_lag.receiver")
    assert receiver.detail["sentences"] == ["GNGGA", "GNRMC", "GNVTG"]
    assert receiver.detail["start_ms"] is None and receiver.detail["same_receiver"] is None
    (kept,) = _events(first, "gnss_lag.kept")
    assert kept.detail["lag_ms"] == kept_ms and kept.detail["error"] is None
    (start,) = _events(first, "gnss_lag.start")
    assert start.detail == {
        "input": "serial:/dev/ttyUSB0",
        "kept_ms": None,
        "fixed_ms": None,
        "error": None,
    }
    doc = json.loads((tmp_path / STORE_FILE).read_text())
    assert [(r["input"], r["sentences"], r["lag_ms"]) for r in doc["receivers"]] == [
        ("serial:/dev/ttyUSB0", ["GNGGA", "GNRMC", "GNVTG"], kept_ms)
    ]
    # the summary prints it
    assert first.term.session is not None
    with SessionReader(first.term.session.path) as reader:
        s = summarise(reader)
    assert s.gnss_lag is not None and s.gnss_lag.learned_ms == kept_ms
    # the next session pushes it: the ECU's lag in use is the kept one from its first frame
    second = _session(tmp_path, DEFAULT_TOML, until_s=11.0, stand_s=30.0)  # nothing learned
    assert _lags(second)[-1] == (kept_ms, None, "start")
    (start,) = _events(second, "gnss_lag.start")
    assert start.detail["kept_ms"] == kept_ms
    (receiver,) = _events(second, "gnss_lag.receiver")
    assert receiver.detail["start_ms"] == kept_ms and receiver.detail["same_receiver"] is True
    # nothing learned standing still: the kept lag stays as it was
    assert json.loads((tmp_path / STORE_FILE).read_text())["receivers"][0]["lag_ms"] == kept_ms
    assert not [e for e in second.events if "not the one whose lag was kept" in e[1]]


def test_an_ecu_rebooted_mid_session_starts_from_the_lag_learned_so_far(tmp_path: Path) -> None:
    LagStore(tmp_path / STORE_FILE).keep(SIM_RECEIVER, 500)  # an earlier session's lag
    rig = _cruising(tmp_path, DEFAULT_TOML)
    try:
        rig.run(12.0)
        assert rig.world.ecu.params.gnss_lag_ms == 500  # the start value, pushed at open
        _power_cycle(rig)  # 12.0 .. 13.0 s, in the cruise at 8 km/h
        assert rig.world.ecu.params.gnss_lag_ms == 0  # the firmware's default
        rig.run(16.0)
    finally:
        rig.close()
    learned = [x[1] for x in _lags(rig) if x[2] == "learned"]
    assert learned and learned[-1] is not None and abs(learned[-1] - SIM_LAG_MS) <= 250
    lag_ms = learned[-1]  # the last lag the ECU reported as learned before it went
    # the parameters pushed again carry the learned lag as the start, not the session's 500 ms
    assert _lag_sets(rig) == [
        (GNSS_LAG, 500),
        (GNSS_LAG_AUTO, 1),
        (GNSS_LAG, lag_ms),
        (GNSS_LAG_AUTO, 1),
    ]
    p = rig.world.ecu.params
    assert (p.gnss_lag_ms, p.gnss_lag_auto) == (lag_ms, 1)
    # the ECU learns again from it (nothing to learn in the cruise): in use at once
    assert _lags(rig)[-1] == (lag_ms, None, "start")
    (restored,) = _events(rig, "gnss_lag.restored")
    assert 13.0 < restored.t < 13.5
    assert restored.detail == {"input": "serial:/dev/ttyUSB0", "lag_ms": lag_ms, "start_ms": 500}
    assert [m for _, m in rig.events if m.startswith("GNSS lag: the ECU restarted")] == [
        f"GNSS lag: the ECU restarted; it learns again from the {lag_ms / 1000:.2f} s learned "
        "in this session"
    ]
    # the ECU works for the terminal again, and the kept lag is the learned one
    assert rig.snapshots[-1][1].ecu_link == "ok" and rig.world.ecu.state.running
    assert json.loads((tmp_path / STORE_FILE).read_text())["receivers"][0]["lag_ms"] == lag_ms
    assert rig.term.session is not None
    with SessionReader(rig.term.session.path) as reader:
        summary = lag_summary(reader.events())
    assert summary is not None and (summary.learned_ms, summary.restored) == (lag_ms, 1)


def test_an_ecu_rebooted_before_any_lag_is_learned_gets_the_start_value_again(
    tmp_path: Path,
) -> None:
    LagStore(tmp_path / STORE_FILE).keep(SIM_RECEIVER, 500)
    rig = _cruising(tmp_path, DEFAULT_TOML)
    try:
        rig.run(1.5)  # standing: nothing learned
        _power_cycle(rig)
        rig.run(3.0)
    finally:
        rig.close()
    assert _lag_sets(rig) == [(GNSS_LAG, 500), (GNSS_LAG_AUTO, 1)] * 2
    assert rig.world.ecu.params.gnss_lag_ms == 500
    assert _events(rig, "gnss_lag.restored") == []


def test_a_fixed_lag_survives_a_reboot_unchanged(tmp_path: Path) -> None:
    LagStore(tmp_path / STORE_FILE).keep(SIM_RECEIVER, 500)  # not used: the lag is fixed
    toml = DEFAULT_TOML.replace('gnss_lag_ms = "auto"', "gnss_lag_ms = 3000")
    rig = _cruising(tmp_path, toml)
    try:
        rig.run(12.0)
        _, learned, state = _lags(rig)[-1]  # the data overrule it meanwhile
        assert state == "overruled" and learned is not None and abs(learned - SIM_LAG_MS) <= 250
        _power_cycle(rig)
        rig.run(16.0)
    finally:
        rig.close()
    assert _lag_sets(rig) == [(GNSS_LAG, 3000), (GNSS_LAG_AUTO, 0)] * 2
    p = rig.world.ecu.params
    assert (p.gnss_lag_ms, p.gnss_lag_auto) == (3000, 0)
    assert _lags(rig)[-1] == (3000, None, "fixed")  # the user's setting, as set
    assert _events(rig, "gnss_lag.restored") == []


def test_an_ecu_only_unheard_for_a_while_keeps_running_on_its_learned_lag(tmp_path: Path) -> None:
    LagStore(tmp_path / STORE_FILE).keep(SIM_RECEIVER, 500)
    rig = _cruising(tmp_path, DEFAULT_TOML)
    try:
        rig.run(12.0)
        rig.ecu_silent = True  # its frames are lost; it hears the commands and meters on
        rig.run(13.0)
        rig.ecu_silent = False
        rig.run(16.0)
    finally:
        rig.close()
    assert [x for x in rig.events if x[1] == "ECU back"]
    # the parameters pushed again: the running ECU answers Busy with its own start value 500 ms
    # and goes on with the lag it learned; it is not stopped to write a start value
    assert [pid for pid, _ in _lag_sets(rig, since_s=12.0)] == [GNSS_LAG, GNSS_LAG_AUTO]
    commands = [
        f for t, f in _sent(rig, since_s=12.0) if isinstance(f, protocol.PcCommand) and t < 15.9
    ]
    assert len(commands) >= 7 and all(c.start for c in commands)
    assert rig.world.ecu.state.running and rig.world.ecu.params.gnss_lag_ms == 500
    in_use, learned, state = _lags(rig)[-1]
    assert state == "learned" and in_use == learned and abs(in_use - SIM_LAG_MS) <= 250
    assert _events(rig, "gnss_lag.restored") == []


def test_another_receiver_on_the_input_is_told_and_kept_apart(tmp_path: Path) -> None:
    _session(tmp_path, DEFAULT_TOML, until_s=12.0)
    # same port, a receiver that speaks GP: the kept lag started it, the operator is told
    other = _session(tmp_path, DEFAULT_TOML, talker="GP", until_s=12.0)
    told = [m for _, m in other.events if "not the one whose lag was kept" in m]
    assert told == [
        "GNSS receiver on serial:/dev/ttyUSB0 is not the one whose lag was kept: its lag is "
        "learned at the first start"
    ]
    receivers = json.loads((tmp_path / STORE_FILE).read_text())["receivers"]
    assert [r["sentences"] for r in receivers] == [
        ["GNGGA", "GNRMC", "GNVTG"],
        ["GPGGA", "GPRMC", "GPVTG"],
    ]


def test_a_fixed_lag_the_data_contradict_is_an_event_and_a_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    toml = DEFAULT_TOML.replace('gnss_lag_ms = "auto"', "gnss_lag_ms = 3000")
    assert toml != DEFAULT_TOML
    rig = _session(tmp_path, toml, until_s=25.0)
    states = [x[2] for x in _lags(rig)]
    # (the ECU's first frames, before the terminal's parameters, show its own defaults)
    assert "fixed" in states and states.index("fixed") < states.index("overruled")
    over = [e for e in _events(rig, "gnss_lag.changed") if e.detail["state"] == "overruled"]
    assert over[0].detail["was"] == "fixed" and over[0].detail["fixed_ms"] == 3000
    in_use, learned, state = _lags(rig)[-1]  # the learned lag is used
    assert state == "overruled" and in_use == learned and abs(in_use - SIM_LAG_MS) <= 250
    warned = [m for _, m in rig.events if "contradicts the data" in m]
    assert warned[0].startswith(
        "warning: the configured gnss_lag_ms (3.00 s) contradicts the data; the learned lag ("
    )
    assert any(
        "contradicts the data" in r.message and r.levelname == "WARNING" for r in caplog.records
    )
    snap = next(s for _, s in rig.snapshots if s.gnss_lag and s.gnss_lag.state == "overruled")
    assert str(snap.gnss_lag.text()).endswith("(learned, not the set 3.00 s)")
    assert rig.term.session is not None
    with SessionReader(rig.term.session.path) as reader:
        lag = summarise(reader).gnss_lag
    assert lag is not None and lag.overruled == 1 and lag.fixed_ms == 3000


def test_a_right_fixed_lag_is_never_overruled(tmp_path: Path) -> None:
    # the simulated receiver's own 1.3 s, fixed: the lag learned meanwhile agrees with it from
    # the first start on, so the data never overrule it (a learner that came out short did,
    # for ~5 s early in the session)
    toml = DEFAULT_TOML.replace('gnss_lag_ms = "auto"', f"gnss_lag_ms = {SIM_LAG_MS}")
    rig = _session(tmp_path, toml, until_s=25.0)
    lags = _lags(rig)
    assert "overruled" not in {state for _, _, state in lags}
    fixed = [(in_use, learned) for in_use, learned, state in lags if state == "fixed"]
    assert all(in_use == SIM_LAG_MS for in_use, _ in fixed)
    learned = [ms for _, ms in fixed if ms is not None]
    assert learned and abs(learned[-1] - SIM_LAG_MS) <= 100
    assert not [e for e in _events(rig, "gnss_lag.changed") if e.detail["state"] == "overruled"]
    assert not [m for _, m in rig.events if "contradicts the data" in m]


def test_a_damaged_lag_file_is_told_and_logged_never_a_crash(tmp_path: Path) -> None:
    (tmp_path / STORE_FILE).write_text('{"version": 1, "receivers": [{"input": "serial:x", ')
    rig = _session(tmp_path, DEFAULT_TOML, until_s=12.0)
    told = [m for _, m in rig.events if m.startswith("GNSS lag file:")]
    assert len(told) == 1 and "damaged" in told[0] and "learned anew" in told[0]
    (start,) = _events(rig, "gnss_lag.start")
    assert start.detail["kept_ms"] is None and "damaged" in start.detail["error"]
    assert (tmp_path / (STORE_FILE + ".damaged")).read_text().startswith('{"version": 1')
    # the session's lag is kept in a sound file again
    receivers = json.loads((tmp_path / STORE_FILE).read_text())["receivers"]
    assert len(receivers) == 1 and abs(receivers[0]["lag_ms"] - SIM_LAG_MS) <= 250


@pytest.mark.parametrize(
    ("content", "why"),
    [
        ("not json", "Expecting value"),
        ('{"receivers": {}}', "not an object with a list of receivers"),
        ('{"receivers": [{"input": "serial:a", "lag_ms": 3001}]}', "lag_ms 3001"),
        ('{"receivers": [{"input": "serial:a", "lag_ms": 1.5}]}', "lag_ms 1.5"),
        ('{"receivers": [{"lag_ms": 100}]}', "has no input"),
        ('{"receivers": [{"input": "a", "lag_ms": 9, "sentences": [1]}]}', "sentences"),
    ],
)
def test_lag_store_refuses_a_bad_file(tmp_path: Path, content: str, why: str) -> None:
    path = tmp_path / STORE_FILE
    path.write_text(content)
    store = LagStore(path)
    assert store.kept == [] and store.error is not None and why in store.error
    assert not path.exists() and path.with_name(STORE_FILE + ".damaged").read_text() == content


def test_lag_store_keeps_the_most_recent_per_receiver(tmp_path: Path) -> None:
    path = tmp_path / "sub" / STORE_FILE
    store = LagStore(path)
    a = ReceiverId("serial:/dev/ttyUSB0", ("GNGGA", "GNRMC"))
    b = ReceiverId("serial:/dev/ttyUSB0", ("GPGGA", "GPRMC"))
    store.keep(a, 950)
    store.keep(b, 480, wait=False)
    store.keep(a, 1010, wait=False)
    store.wait()
    again = LagStore(path)
    assert again.error is None
    assert [(k.receiver, k.lag_ms) for k in again.kept] == [(b, 480), (a, 1010)]
    assert again.for_input("serial:/dev/ttyUSB0") == again.kept[-1]
    assert again.for_input("serial:/dev/ttyUSB1") is None
    assert again.for_receiver(b) is not None and again.for_receiver(b).lag_ms == 480
    store.keep(a, 4000)  # bounded to GnssLag's range
    assert LagStore(path).for_receiver(a).lag_ms == 3000  # type: ignore[union-attr]
    # a directory in the way: an error to tell, no exception
    blocked = LagStore(tmp_path / "blocked")
    (tmp_path / "blocked").mkdir()
    blocked.keep(a, 900)
    assert blocked.error is not None and "cannot save" in blocked.error


def test_receiver_identity_from_real_receivers_lines() -> None:
    def seen(name: str) -> ReceiverId:
        watch, decoder = ReceiverWatch("serial:/dev/ttyUSB0", settle_s=1e9), NmeaDecoder()
        for i, line in enumerate((NMEA_LOGS / name).read_bytes().splitlines()):
            if line.startswith(b"$"):
                watch.see(i * 0.01, decoder.decode(line), line)
        return watch.receiver

    ublox = seen("ublox-lea-5h.log")
    assert ublox.sentences == ("GPGGA", "GPGLL", "GPRMC", "GPVTG")  # GSV, GSA, TXT left out
    # its power-up TXT lines name hardware, firmware and module
    assert ublox.versions == (
        "HW UBX-G50xx 00040005",
        "ROM BASE 4.00 (25682) Jan 14 2008 16:29:23",
        "MOD LEA-5H-0",
    )
    ublox = replace(ublox, versions=())
    sirf = seen("beidou-bd.log")
    assert "PSRF" in sirf.sentences and "GNRMC" in sirf.sentences  # by its manufacturer
    assert not ublox.same(sirf) and ublox.same(seen("ublox-lea-5h.log"))
    # versions tell two receivers apart only when both were seen and share no line
    v1 = replace(ublox, versions=("ROM CORE 7.03",))
    assert v1.same(ublox) and not v1.same(replace(ublox, versions=("ROM CORE 6.02",)))
    assert v1.same(replace(ublox, versions=("HW UBX-G60", "ROM CORE 7.03")))
    assert not ublox.same(replace(ublox, input="serial:/dev/ttyUSB1"))


def test_receiver_settles_and_reads_version_lines() -> None:
    watch, decoder = ReceiverWatch("stdin", settle_s=2.0), NmeaDecoder()
    lines = [
        make_sentence("GPTXT,01,01,02,u-blox ag - www.u-blox.com"),
        make_sentence("GPTXT,01,01,02,ANTSTATUS=OK"),
        make_sentence("GPTXT,01,01,02,HW  UBX-G70xxx   00070000 FF7FFFFFo"),
        b"$GPRMC,bad,checksum*00",
    ]
    times = (0.0, 1.0, 2.0, 3.0)
    settled = [watch.see(t, decoder.decode(x), x) for t, x in zip(times, lines, strict=True)]
    assert settled == [False, False, True, False]
    assert watch.receiver.versions == ("HW UBX-G70xxx 00070000 FF7FFFFFo",)
    assert watch.receiver.sentences == () and not watch.receiver.known  # TXT only


def test_input_key_names_the_configured_input() -> None:
    cfg = loads_config(DEFAULT_TOML).gnss
    assert input_key(cfg) == "serial:/dev/ttyUSB0"
    assert input_key(replace(cfg, source="file", path="/data/a.nmea")) == "file:/data/a.nmea"
    assert input_key(replace(cfg, source="stdin")) == "stdin"


def _frame(in_use: int, learned: int | None, state: int, auto: bool = True) -> protocol.EcuGnssLag:
    return protocol.EcuGnssLag(in_use, learned, 3.0, 0.1, state, auto)


def test_lag_watch_reports_state_changes_and_moves_beyond_100_ms() -> None:
    watch = LagWatch()
    first = watch.update(0.0, _frame(0, None, 0), None)
    assert first is not None and first.was is None and not first.tell()
    assert watch.update(0.1, _frame(0, None, 0), None) is None
    learned = watch.update(0.2, _frame(950, 950, 1), None)
    assert learned is not None and learned.tell()
    assert str(learned.message()) == "GNSS lag learned: 0.95 s"
    assert watch.update(0.3, _frame(1050, 1050, 1), None) is None  # 100 ms: not a move
    moved = watch.update(0.4, _frame(1051, 1051, 1), None)
    assert moved is not None and moved.detail()["moved_from_ms"] == 950 and not moved.tell()
    assert str(moved.message()) == "GNSS lag learned: 1.05 s (was 0.95 s)"
    # an ECU that restarted learns again from its start value
    again = watch.update(0.5, _frame(1051, None, 0), None)
    assert again is not None and again.tell()
    assert str(again.message()) == "GNSS lag: learning from 1.05 s"
    assert watch.learned_ms == 1051  # the last learned is kept through it
    # a lag in LagLearned while the ECU says it is at its start value is not taken as learned
    watch.update(0.6, _frame(1400, 1400, 0), None)
    assert watch.learned_ms == 1051


def test_lag_watch_warns_of_an_overrule_that_holds() -> None:
    watch = LagWatch()
    assert watch.update(0.0, _frame(3000, None, 2, False), 3000.0) is not None
    assert watch.update(1.0, _frame(3000, 2950, 2, False), 3000.0) is None  # learned, agreeing
    over = watch.update(2.0, _frame(700, 700, 3, False), 3000.0)
    assert over is not None and over.detail()["state"] == "overruled" and not over.tell()
    assert watch.warning(2.0) is None and watch.warning(11.9) is None
    watch.update(12.0, _frame(1300, 1300, 3, False), 3000.0)
    warning = watch.warning(12.0)
    assert str(warning) == (
        "warning: the configured gnss_lag_ms (3.00 s) contradicts the data; the learned lag "
        "(1.30 s) is used"
    )
    assert watch.warning(30.0) is None  # once
    back = watch.update(40.0, _frame(3000, 2900, 2, False), 3000.0)
    assert back is not None and back.tell() and back.warned
    assert (
        str(back.message()) == "GNSS lag: the configured 3.00 s is in use (it agrees with the data)"
    )
    # an overrule that ends before WARN_S is logged, not told
    assert watch.update(50.0, _frame(800, 800, 3, False), 3000.0) is not None
    short = watch.update(55.0, _frame(3000, 2900, 2, False), 3000.0)
    assert short is not None and not short.tell() and watch.warning(70.0) is None


def test_summary_takes_the_kept_lag_else_the_last_reported() -> None:
    def ev(kind: str, **d: object) -> LogEvent:
        return LogEvent(0.0, kind, d)

    assert lag_summary([ev("operator.start")]) is None
    cut = [
        ev("gnss_lag.start", kept_ms=900, fixed_ms=None),
        ev("gnss_lag.changed", state="learned", was="start", learned_ms=1010),
    ]
    lag = lag_summary(cut)
    assert lag is not None and (lag.learned_ms, lag.start_ms, lag.state) == (1010, 900, "learned")
    lag = lag_summary([*cut, ev("gnss_lag.kept", lag_ms=1060)])
    assert lag is not None and lag.learned_ms == 1060


def test_config_init_writes_fused_and_a_learned_lag(tmp_path: Path) -> None:
    path = tmp_path / "terminal.toml"
    assert main(["config", "init", str(path)]) == 0
    written = path.read_text()
    assert '\nmode = "fused"' in written and '\ngnss_lag_ms = "auto"' in written
    cfg = loads_config(written)
    assert cfg.speed.mode == "fused" and "gnss_lag_ms" not in cfg.ecu.overrides
    params = cfg.ecu_params()
    assert params[protocol.param("GnssLagAuto").id] == 1
    assert params[protocol.param("SpeedMode").id] == protocol.SpeedMode.FUSED.code


def test_replay_defaults_to_the_fused_mode(tmp_path: Path) -> None:
    events = tmp_path / "drive.ndjson"
    with events.open("w") as f:
        write(drive_events(20.0), f)
    outs = {}
    for name, mode in (
        ("default", []),
        ("fused", ["--speed-mode", "fused"]),
        ("paper", ["--speed-mode", "paper"]),
    ):
        outs[name] = tmp_path / f"{name}.csv"
        assert main(["replay", str(events), *mode, "--out", str(outs[name])]) == 0
    text = {k: p.read_text() for k, p in outs.items()}
    assert text["default"] == text["fused"] and text["default"] != text["paper"]
    with outs["default"].open() as f:
        sources = {row["source"] for row in csv.DictReader(f)}
    assert "fused" in sources


class _Wire:
    """What a link sends, kept (a bus of one listener)."""

    def __init__(self) -> None:
        self.sent: list[protocol.Frame] = []

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.sent.append(protocol.decode(msg))


def _ecu_frame(name: str, **signals: int) -> can.Message:
    msg = protocol.database().get_message_by_name(name)
    return can.Message(arbitration_id=msg.frame_id, data=msg.encode(signals), is_extended_id=True)


def _busy(param_id: int, raw: int) -> can.Message:
    return _ecu_frame("EcuParamAck", AckParamId=param_id, AckResult=3, AckRaw=raw)


def _learned_lag(automatic: int) -> can.Message:
    return _ecu_frame(
        "EcuGnssLag",
        LagInUse=1165,
        LagLearned=1165,
        LagEvidence=6.2,
        LagFit=3,
        LagState=1 if automatic else 3,
        LagAuto=automatic,
    )


@pytest.mark.parametrize(
    ("lag_auto", "ecu_auto", "stopped"),
    [
        (1, 1, False),  # learning on both sides: the learned lag stands, no stop
        (0, 1, True),  # the push turns learning off: GnssLag becomes the lag in use
        (1, 0, True),  # the ECU does not learn: its GnssLag is the lag in use
    ],
)
def test_a_running_ecu_is_stopped_for_another_gnss_lag_only_when_it_is_the_lag_in_use(
    lag_auto: int, ecu_auto: int, stopped: bool
) -> None:
    wire = _Wire()
    link = CanLink(wire, loads_config("").can)
    link.on_frame(_learned_lag(ecu_auto), 0.0)
    link.begin({GNSS_LAG: 1300, GNSS_LAG_AUTO: lag_auto}, 0.0)
    link.on_frame(_busy(GNSS_LAG, 500), 0.01)  # running, with 500 ms as its GnssLag
    stops = [f for f in wire.sent if isinstance(f, protocol.PcCommand) and not f.start]
    lag_sets = [f for f in wire.sent if isinstance(f, protocol.PcParamSet)]
    assert len(stops) == int(stopped)
    # a stop is followed by GnssLag written again; else the push goes on to GnssLagAuto
    assert lag_sets[-1].param_id == (GNSS_LAG if stopped else GNSS_LAG_AUTO)


def test_what_the_ecu_said_of_its_lag_is_forgotten_when_it_is_lost() -> None:
    # back, it may have restarted: its learned lag from before is no reason to keep a GnssLag
    lost = CanLink(_Wire(), loads_config("").can)
    lost.on_frame(_learned_lag(1), 0.0)
    status = can.Message(arbitration_id=protocol.DEFAULT_IDS.status, data=bytes(8))
    lost.on_frame(status, 0.0)
    lost.poll(1.0)  # no status for 1 s: lost
    assert lost.state == "lost" and lost.ecu.lag is None


class _HeldRig(VirtualRig):
    """The rig with the terminal's inbox held back: every GNSS line waits `hold_s` there before
    the loop takes it (a busy loop, a flood of other inputs), though it arrived, and was
    stamped, on time. The ECU's frames are taken at once (its parameter push goes on)."""

    def __init__(self, hold_s: float, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.hold_s = hold_s
        self._held: deque[tuple[str, float, Any]] = deque()

    def run(self, until_s: float) -> None:
        w, term = self.world, self.term
        while w.t_s < until_s - 1e-9:
            while (msg := self.ecu_bus.recv(timeout=0)) is not None:
                w.deliver_can(msg)
            out = w.step()
            t = out.t_s
            msgs = (can.Message(arbitration_id=i, data=d) for i, d in out.can)
            self.deliver(t, out.nmea, out.crop, msgs)
            while not term.inbox.empty():
                item = term.inbox.get()
                assert item is not None
                if item[0] == "nmea":
                    self._held.append(item)
                else:
                    term.handle(*item)
            while self._held and self._held[0][1] <= t - self.hold_s + 1e-9:
                term.handle(*self._held.popleft())
            if round(t * 100) % 10 == 0:
                term.tick(t)
                self.snapshots.append((t, term.snapshot))


def _learned_with_inbox_held(tmp_path: Path, hold_s: float) -> tuple[int, list[int]]:
    """The lag the ECU learned on a start from rest, and the fix ages the terminal sent."""
    drive = Drive(
        [
            Segment("stop", duration_s=2.0),
            Segment("straight", speed_kmh=8.0, length_m=30.0, hold=True),
            Segment("stop", duration_s=5.0),
        ]
    )
    session = SessionLog.create(tmp_path, DEFAULT_TOML)
    rig = _HeldRig(hold_s, loads_config(DEFAULT_TOML), drive, session)
    try:
        rig.run(20.0)
    finally:
        rig.close()
    learned = [x[1] for x in _lags(rig) if x[2] == "learned"]
    assert learned and learned[-1] is not None
    ages = [f.age_ms for _, f in _sent(rig) if isinstance(f, protocol.PcGnssTime)]
    return learned[-1], ages


def test_a_fix_held_in_the_inbox_is_sent_with_its_true_age_and_the_lag_does_not_move(
    tmp_path: Path,
) -> None:
    """The age sent with each GNSS speed is the time from the line's arrival (its receive
    timestamp) to the frame's transmission, so the loop's own wait is not learned as lag."""
    free, free_ages = _learned_with_inbox_held(tmp_path / "free", 0.0)
    held, held_ages = _learned_with_inbox_held(tmp_path / "held", 0.4)
    assert abs(free - SIM_LAG_MS) <= 250
    assert free_ages and set(free_ages) == {0}  # taken at once: no age
    # every fix went out 400 ms after it came in (the wait of the 10 ms step included)
    assert held_ages and min(held_ages) >= 400 and max(held_ages) <= 410
    # the lag the ECU learns is the receiver's, not the receiver's plus the inbox's 400 ms
    assert abs(held - free) <= 60, (held, free)
