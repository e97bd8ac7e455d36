"""The terminal's side of EcuIdent: who the ECU is reaches the event log, the Snapshot, the
console's events and `topdress log summary`; a protocol version other than the terminal's own
(the DBC's VERSION) is warned of, as an event and an alarm."""

from __future__ import annotations

from pathlib import Path

import can
import pytest
from topdress.ecu._core import lib

from test_terminal import VirtualRig, _drive
from topdress import protocol
from topdress.config import DEFAULT_TOML, loads_config
from topdress.ecu.params import EcuParams, check
from topdress.i18n import render
from topdress.log.session import SessionLog, SessionReader
from topdress.log.summary import format_text, summarise
from topdress.terminal.alarms import AlarmBook, AlarmInputs
from topdress.terminal.ecuview import ident_mismatch


def _ident_frame(protocol_minor: int, target: int = 1, reset: int = 2) -> can.Message:
    """An EcuIdent as a firmware built from protocol 1.<protocol_minor> sends it."""
    msg = protocol.database().get_message_by_name("EcuIdent")
    data = msg.encode(
        {
            "Target": target,
            "FirmwareMajor": 0,
            "FirmwareMinor": 2,
            "FirmwarePatch": 7,
            "ProtocolMajor": 1,
            "ProtocolMinor": protocol_minor,
            "Transport": 1,
            "ResetCause": reset,
            "ClockFallback": 0,
            "OnDefaults": 0,
        }
    )
    return can.Message(arbitration_id=msg.frame_id, data=data, is_extended_id=True)


def test_the_dbc_version_is_the_terminals_protocol() -> None:
    assert protocol.protocol_version() == (1, 1)


def test_the_host_core_is_logged_shown_and_summarised(tmp_path: Path) -> None:
    session = SessionLog.create(tmp_path, DEFAULT_TOML)
    rig = VirtualRig(loads_config(DEFAULT_TOML), _drive(8.0, 20.0), session)
    try:
        rig.run(3.0)
    finally:
        rig.close()
    said = [e for _, e in rig.events if e.startswith("ECU: ")]
    assert said == ["ECU: host firmware 0.1.0, protocol 1.1 (in-process)"]
    assert not any("warning: the ECU speaks protocol" in e for _, e in rig.events)
    snap = rig.snapshots[-1][1]
    assert render(snap.ecu_ident, "en") == "host firmware 0.1.0, protocol 1.1"
    assert snap.ecu_protocol is None
    assert "ecu_protocol" not in {a.name for a in snap.alarms}
    with SessionReader(session.path) as reader:
        events = [e for e in reader.events() if e.kind == "ecu.ident"]
        summary = summarise(reader)
    # at power-up and again when the terminal starts commanding: logged each time, said once
    # (the first parameter reached the core before its first step: not on its defaults)
    assert len(events) == 2
    assert (
        dict(events[0].detail)
        == dict(events[1].detail)
        == {
            "target": "host",
            "firmware": "0.1.0",
            "protocol": "1.1",
            "terminal_protocol": "1.1",
            "transport": "in-process",
            "reset_cause": "unknown",
            "clock_fallback": False,
            "on_defaults": False,
        }
    )
    assert (
        "ECU              host firmware 0.1.0, protocol 1.1 (in-process, last reset: unknown)"
        in format_text(summary).splitlines()
    )


def test_another_protocol_version_is_warned_of_once_and_raised_as_an_alarm(tmp_path: Path) -> None:
    session = SessionLog.create(tmp_path, DEFAULT_TOML)
    rig = VirtualRig(loads_config(DEFAULT_TOML), _drive(8.0, 20.0), session)
    try:
        rig.run(1.0)
        for at in (1.0, 1.5):  # the firmware says it twice (a second listener)
            rig.term.inbox.put(("can", at, _ident_frame(protocol_minor=0)))
            rig.run(at + 0.5)
    finally:
        rig.close()
    warnings = [e for _, e in rig.events if e.startswith("warning: the ECU speaks protocol")]
    assert warnings == [
        "warning: the ECU speaks protocol 1.0, this terminal 1.1: frames may be misread; "
        "update the ECU's firmware or the terminal"
    ]
    assert "ECU: stm32f4 firmware 0.2.7, protocol 1.0 (can)" in [e for _, e in rig.events]
    snap = rig.snapshots[-1][1]
    assert snap.ecu_protocol == ("1.0", "1.1")
    (alarm,) = [a for a in snap.alarms if a.name == "ecu_protocol"]
    assert render(alarm.text, "en") == "the ECU speaks protocol 1.0, this terminal 1.1"
    with SessionReader(session.path) as reader:
        idents = [dict(e.detail) for e in reader.events() if e.kind == "ecu.ident"]
        text = format_text(summarise(reader))
    assert [(d["target"], d["protocol"], d["reset_cause"]) for d in idents] == [
        ("host", "1.1", "unknown"),
        ("host", "1.1", "unknown"),
        ("stm32f4", "1.0", "pin"),
        ("stm32f4", "1.0", "pin"),
    ]
    assert (
        "ECU              stm32f4 firmware 0.2.7, protocol 1.0 (can, last reset: pin); "
        "the terminal spoke protocol 1.1" in text.splitlines()
    )


def test_the_summary_finds_the_ecu_in_the_received_frames_without_the_event(tmp_path: Path) -> None:
    frame = _ident_frame(protocol_minor=1, reset=3)
    with SessionLog.create(tmp_path, DEFAULT_TOML) as log:
        log.raw("can_rx", 1.0, (frame.arbitration_id, b"\x01\x02"))  # malformed: skipped
        log.raw("can_rx", 2.0, (frame.arbitration_id, bytes(frame.data)))
    with SessionReader(log.path) as reader:
        s = summarise(reader)
    assert s.ecu is not None and s.ecu["target"] == "stm32f4"
    assert "ECU              stm32f4 firmware 0.2.7, protocol 1.1 (can, last reset: watchdog)" in (
        format_text(s).splitlines()
    )
    with SessionLog.create(tmp_path / "none", DEFAULT_TOML) as log:
        log.raw("can_rx", 1.0, (protocol.DEFAULT_IDS.status, bytes(8)))
    with SessionReader(log.path) as reader:
        text = format_text(summarise(reader))
    assert "ECU              not identified (no EcuIdent from the ECU in this session)" in text


def test_the_protocol_alarm_comes_and_goes_with_the_mismatch() -> None:
    book = AlarmBook(10.0, 5.0)
    base = dict(
        metering=False,
        target_rpm=(0.0, 0.0),
        meter_rpm=(0.0, 0.0),
        faults=0,
        gnss_link="ok",
        crop_link="ok",
        ecu_link="ok",
    )
    new = book.update(1.0, AlarmInputs(**base, ecu_protocol=("2.0", "1.1")))  # type: ignore[arg-type]
    assert [name for name, _ in new] == ["ecu_protocol"]
    assert book.update(2.0, AlarmInputs(**base)) == []  # type: ignore[arg-type]
    assert book.ack("ecu_protocol") == ["ecu_protocol"]
    assert [v.name for v in book.views()] == []


@pytest.mark.parametrize(("minor", "differs"), [(1, False), (0, True), (2, True)])
def test_mismatch_is_any_other_version(minor: int, differs: bool) -> None:
    ident = protocol.decode(_ident_frame(minor))
    assert isinstance(ident, protocol.EcuIdent)
    assert ident_mismatch(ident) is differs


def test_an_ecu_restarted_faster_than_the_timeout_is_sent_its_parameters_again(
    tmp_path: Path,
) -> None:
    """A reset shorter than `[can] ecu_timeout_s` never makes the ECU lost; its EcuIdent says it
    runs on its firmware defaults (OnDefaults), and the terminal pushes its parameters again."""
    session = SessionLog.create(tmp_path, DEFAULT_TOML)
    rig = VirtualRig(loads_config(DEFAULT_TOML), _drive(8.0, 60.0), session)
    fused = protocol.SpeedMode.FUSED.code
    try:
        rig.run(8.0)
        w = rig.world
        assert w.ecu.params.speed_mode == fused and w.ecu.state.running  # the file's mode
        restarted_t = w.t_s
        defaults = (w.cfg.ecu or EcuParams.defaults()).to_c()
        check(lib.td_app_init(w.ecu._app, defaults, w.now_us), "reset")
        assert w.ecu.params.speed_mode != fused  # the firmware's default: the paper's rule
        rig.run(11.0)
    finally:
        rig.close()
    after = [s for t, s in rig.snapshots if t > restarted_t]
    assert all(s.ecu_link != "lost" for s in after)  # never unheard for 0.5 s
    assert rig.term.link.counters.ecu_lost == 0 and rig.term.link.counters.ecu_restarts == 1
    assert rig.world.ecu.params.speed_mode == fused  # pushed again
    assert rig.world.ecu.state.running and after[-1].ecu_link == "ok"
    said = [(t, e) for t, e in rig.events if e.startswith("ECU restarted")]
    assert [e for _, e in said] == ["ECU restarted on its defaults: its parameters are sent again"]
    assert restarted_t < said[0][0] < restarted_t + 0.1
    with SessionReader(session.path) as reader:
        idents = [e for e in reader.events() if e.kind == "ecu.ident"]
    assert [e.detail["on_defaults"] for e in idents if e.t > restarted_t][:1] == [True]
