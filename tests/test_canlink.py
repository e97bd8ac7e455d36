"""The terminal's CAN link against the ECU's twin (the C core) on a virtual bus, in virtual time."""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import can
import pytest
import serial

from ecu_twin import SimulatedEcu
from topdress import protocol
from topdress.cli.main import main
from topdress.config import CanConfig, default_config, loads_config
from topdress.devices.can import open_bus
from topdress.errors import DeviceError, EcuParamError, ProtocolError
from topdress.terminal.canlink import CanLink

_channels = itertools.count()


class Rig:
    """A link, the ECU twin and a listener on one virtual bus; `run` advances virtual time."""

    def __init__(self, cfg: CanConfig | None = None, **link_kw: float) -> None:
        channel = f"test-canlink-{next(_channels)}"
        self.cfg = replace(cfg or CanConfig(), channel=channel)
        self.pc_bus = open_bus(self.cfg)
        self.ecu_bus = open_bus(self.cfg)
        self.spy = open_bus(self.cfg)
        self.events: list[tuple[float, str]] = []
        self.t = 0.0
        self.link = CanLink(
            self.pc_bus,
            self.cfg,
            fan_rpm=3000,
            on_event=lambda text: self.events.append((self.t, str(text))),
            **link_kw,  # type: ignore[arg-type]
        )
        self.twin = SimulatedEcu(self.ecu_bus)
        self.seen: list[tuple[float, can.Message]] = []

    def run(self, until: float) -> None:
        while self.t < until - 1e-9:
            self.t = round(self.t + 0.01, 6)
            self.twin.pump(self.t)
            while (msg := self.pc_bus.recv(timeout=0)) is not None:
                self.link.on_frame(msg, self.t)
            self.link.poll(self.t)
            while (msg := self.spy.recv(timeout=0)) is not None:
                self.seen.append((self.t, msg))

    def commands(self) -> list[tuple[float, protocol.PcCommand]]:
        out = []
        for t, msg in self.seen:
            if msg.arbitration_id == protocol.DEFAULT_IDS.command:
                decoded = protocol.decode(msg)
                assert isinstance(decoded, protocol.PcCommand)
                out.append((t, decoded))
        return out

    def close(self) -> None:
        for bus in (self.pc_bus, self.ecu_bus, self.spy):
            bus.shutdown()


@pytest.fixture
def rig() -> Iterator[Rig]:
    r = Rig()
    yield r
    r.close()


def test_parameters_pushed_and_acknowledged_one_by_one(rig: Rig) -> None:
    cfg = loads_config(
        "[machine]\nwidth_m = 4.2\nkg_per_rev_lower = 0.25\n[speed]\nqueue_len = 7\n"
    )
    params = cfg.ecu_params()
    rig.link.begin(params, 0.0)
    assert not rig.link.params_done
    rig.run(1.0)
    assert rig.link.params_done
    p = rig.twin.ecu.params
    assert p.working_width_m == pytest.approx(4.2)
    assert p.kg_per_rev[1] == pytest.approx(0.25)
    assert p.queue_len == 7
    assert rig.link.counters.tx_params == len(params)
    assert rig.link.counters.param_retries == 0
    # no command before every parameter is in force, then one at once
    first_cmd_t = rig.commands()[0][0]
    sets = [t for t, m in rig.seen if m.arbitration_id == protocol.DEFAULT_IDS.param_set]
    assert first_cmd_t >= max(sets)


def test_refused_parameter_fails_at_once_naming_it(rig: Rig) -> None:
    # queue_len 3 is in range but inconsistent with the ECU's cv_window 5 -> the core refuses
    rig.link.begin({6: 3}, 0.0)
    with pytest.raises(EcuParamError, match=r"QueueLength = 3: refused by the ECU: inconsistent"):
        rig.run(0.5)
    assert rig.twin.ecu.params.queue_len == 5


def test_parameter_inconsistent_only_with_the_ecus_old_values_goes_after_the_others(
    rig: Rig,
) -> None:
    # both 3 in the file; in id order queue_len 3 reaches an ECU still on cv_window 5
    params = loads_config("[speed]\nqueue_len = 3\ncv_window = 3\n").ecu_params()
    rig.link.begin(params, 0.0)
    rig.run(1.0)
    assert rig.link.params_done
    p = rig.twin.ecu.params
    assert (p.queue_len, p.cv_window) == (3, 3)
    ids = [i for _, i in _param_sets(rig)]
    assert ids[:6] == [1, 2, 3, 4, 5, 6] and ids[6] == 7 and ids[-1] == 6
    assert len(ids) == len(params) + 1


def test_parameter_still_inconsistent_after_the_others_is_refused(rig: Rig) -> None:
    rig.link.begin({6: 3, 7: 5}, 0.0)  # a window longer than the queue: never consistent
    with pytest.raises(EcuParamError, match=r"QueueLength = 3: refused by the ECU: inconsistent"):
        rig.run(0.5)
    assert [i for _, i in _param_sets(rig)] == [6, 7, 6]
    assert (rig.twin.ecu.params.queue_len, rig.twin.ecu.params.cv_window) == (5, 5)


def _param_sets(rig: Rig) -> list[tuple[float, int]]:
    """(time seen, parameter id) of every PcParamSet on the bus."""
    out = []
    for t, msg in rig.seen:
        if msg.arbitration_id == protocol.DEFAULT_IDS.param_set:
            decoded = protocol.decode(msg)
            assert isinstance(decoded, protocol.PcParamSet)
            out.append((t, decoded.param_id))
    return out


def _unplug(twin: SimulatedEcu) -> None:
    twin.mute = twin.deaf_to_params = True  # neither heard nor listening: not on the bus


def test_ecu_not_on_the_bus_is_waited_for_with_a_backoff(rig: Rig) -> None:
    _unplug(rig.twin)
    rig.link.begin(default_config().ecu_params(), 0.0)
    rig.run(10.0)  # no error: the implement may be hitched later
    # 4 fast tries 0.2 s apart, then every 1 s for 5 s, then every 2 s; always the first one
    times = [0.01, 0.2, 0.4, 0.6, 1.6, 2.6, 3.6, 4.6, 5.6, 7.6, 9.6]
    assert [t for t, _ in _param_sets(rig)] == pytest.approx(times)
    assert {p for _, p in _param_sets(rig)} == {1}  # WorkingWidth
    assert rig.link.counters.param_retries == len(times) - 1
    # said once, with where it listens; an ECU never heard is waited for, not "lost"
    assert [e for _, e in rig.events] == [
        f"ECU wait: WorkingWidth unacknowledged after 4 tries on CAN virtual:{rig.cfg.channel};"
        " still trying (is the ECU powered, on this bus?)"
    ]
    assert rig.events[0][0] == pytest.approx(0.8)
    assert rig.link.state == "wait" and not rig.link.ready and rig.link.counters.ecu_lost == 0
    assert rig.commands() == []  # nothing is commanded before the parameters are in force


def test_ecu_powered_later_gets_the_parameters_at_once_and_works(rig: Rig) -> None:
    _unplug(rig.twin)
    params = default_config().ecu_params()
    rig.link.begin(params, 0.0)
    rig.link.set_command(True, 3000, 200, 100)
    rig.run(3.0)  # the last try went at 2.6 s; the next is due at 3.6 s
    rig.twin = SimulatedEcu(rig.ecu_bus, now=rig.t)  # powered at 3.0 s
    rig.run(5.0)
    heard = min(t for t, msg in rig.seen if msg.arbitration_id == protocol.DEFAULT_IDS.status)
    sets = [t for t, _ in _param_sets(rig) if t > 3.0]
    # the push goes on as soon as the ECU's first status is heard, not at the next backoff
    assert sets[0] == pytest.approx(heard, abs=0.011) and sets[0] < 3.2
    assert len(sets) == len(params) and rig.link.ready and rig.link.state == "ok"
    assert rig.twin.ecu.params.working_width_m == pytest.approx(3.6)
    text = [e for _, e in rig.events]
    assert text[0].startswith("ECU wait: WorkingWidth") and len(text) == 3
    assert text[1] == "ECU: host firmware 0.1.0, protocol 1.1 (in-process)"  # it says who it is
    assert text[2].startswith("ECU ready: every parameter acknowledged, 3.")
    # then it works: commands flow and the ECU runs them
    assert rig.commands()[0][0] >= max(sets)
    assert rig.twin.ecu.state.running


def test_ecu_that_talks_but_never_acknowledges_is_named_so(rig: Rig) -> None:
    rig.twin.deaf_to_params = True  # e.g. parameter frames on other identifiers
    rig.link.begin({1: 3.0}, 0.0)
    rig.run(3.0)
    assert rig.link.ecu_alive and rig.link.state == "wait" and not rig.link.params_done
    assert [e for _, e in rig.events] == [
        "ECU: host firmware 0.1.0, protocol 1.1 (in-process)",  # at its first step
        f"ECU wait: WorkingWidth unacknowledged after 4 tries on CAN virtual:{rig.cfg.channel};"
        " the ECU sends status but does not answer (check [can.ids]); still trying",
    ]


def test_ecu_that_wakes_up_during_retries_is_accepted(rig: Rig) -> None:
    rig.twin.deaf_to_params = True
    rig.link.begin({1: 3.0}, 0.0)
    rig.run(0.3)
    rig.twin.deaf_to_params = False
    rig.run(1.0)
    assert rig.link.params_done
    assert rig.link.counters.param_retries == 2
    assert rig.twin.ecu.params.working_width_m == pytest.approx(3.0)


def test_running_ecu_is_stopped_before_parameters_are_written(rig: Rig) -> None:
    rig.link.begin({}, 0.0)
    rig.link.set_command(True, 3000, 200, 100)
    rig.run(1.0)
    assert rig.twin.ecu.state.running
    # the terminal restarts while the ECU still runs
    link2 = CanLink(rig.pc_bus, rig.cfg)
    rig.link = link2
    link2.begin({1: 4.0}, rig.t)
    rig.run(2.0)
    assert link2.params_done
    assert rig.twin.ecu.params.working_width_m == pytest.approx(4.0)
    assert not rig.twin.ecu.state.running


def test_restart_with_the_values_in_force_does_not_stop_the_ecu(rig: Rig) -> None:
    params = default_config().ecu_params()
    rig.link.begin(params, 0.0)
    rig.link.set_command(True, 3000, 200, 100)
    rig.run(1.0)
    assert rig.twin.ecu.state.running
    link2 = CanLink(rig.pc_bus, rig.cfg)
    rig.link = link2
    link2.begin(params, rig.t)
    link2.set_command(True, 3000, 200, 100)
    rig.run(2.0)
    # every parameter answered Busy with the value already in force: accepted, no stop sent
    assert link2.params_done
    assert rig.twin.ecu.state.running
    assert all(c.start for _, c in rig.commands())


def test_ecu_rebooted_while_lost_gets_the_parameters_again(rig: Rig) -> None:
    rig.link.begin({1: 4.2, 6: 7}, 0.0)
    rig.run(1.0)
    assert rig.twin.ecu.params.working_width_m == pytest.approx(4.2)
    rig.twin.mute = True
    rig.run(2.0)
    # power cycle: a fresh ECU on its defaults
    rig.twin = SimulatedEcu(rig.ecu_bus, now=rig.t)
    assert rig.twin.ecu.params.working_width_m == pytest.approx(3.6)
    rig.run(3.0)
    assert [e for _, e in rig.events][-1] == "ECU back"
    assert rig.link.params_done
    assert rig.twin.ecu.params.working_width_m == pytest.approx(4.2)
    assert rig.twin.ecu.params.queue_len == 7
    assert rig.link.counters.tx_params == 4


def test_ecu_back_without_acknowledging_is_waited_for_not_ok(rig: Rig) -> None:
    rig.link.begin({1: 4.2}, 0.0)
    rig.link.set_command(True, 3000, 200, 100)
    rig.run(1.0)
    assert rig.link.state == "ok"
    rig.twin.mute = True
    rig.run(2.0)
    assert rig.link.state == "lost"
    # a rebooted ECU that talks but does not take parameters
    rig.twin = SimulatedEcu(rig.ecu_bus, now=rig.t)
    rig.twin.deaf_to_params = True
    rig.run(4.0)
    assert rig.link.ecu_alive and not rig.link.params_done
    assert rig.link.state == "wait"
    assert not [t for t, _ in rig.commands() if t > 2.1]  # nothing commanded meanwhile


def test_value_the_frame_cannot_carry_is_refused_before_sending(rig: Rig) -> None:
    with pytest.raises(ProtocolError, match="WorkingWidth"):
        rig.link.begin({1: 31.0}, 0.0)
    assert rig.link.counters.tx_params == 0


def test_command_every_period_with_the_values_set(rig: Rig) -> None:
    rig.link.begin({}, 0.0)
    rig.link.set_command(True, 3200, 250.5, 120.25)
    rig.link.set_gnss(7.3, 0.0)
    rig.run(5.0)
    cmds = rig.commands()
    times = [t for t, _ in cmds]
    # first at once (t = 0.01), then every 0.5 s
    assert times[0] == pytest.approx(0.01)
    gaps = [b - a for a, b in itertools.pairwise(times)]
    assert all(g == pytest.approx(0.5) for g in gaps)
    assert len(cmds) == 10
    last = cmds[-1][1]
    assert last.start and last.fan_rpm == 3200
    assert (last.rate_upper_kg_ha, last.rate_lower_kg_ha) == (250.5, 120.25)
    assert last.gnss_kmh == pytest.approx(7.3)
    # the ECU acts on them
    s = rig.twin.ecu.state
    assert s.running and s.rate_kg_ha == pytest.approx((250.5, 120.25))
    assert s.v_gnss_kmh == pytest.approx(7.3)


def test_send_on_gnss_sends_at_once_and_none_is_not_available() -> None:
    rig = Rig(replace(CanConfig(), send_on_gnss=True))
    try:
        rig.link.begin({}, 0.0)
        rig.run(0.2)
        rig.link.set_gnss(5.5, rig.t)
        rig.link.set_gnss(None, rig.t)
        rig.run(0.21)
        cmds = rig.commands()
        assert [c.gnss_kmh for _, c in cmds] == [None, 5.5, None]
        assert rig.link.counters.tx_commands == 3
    finally:
        rig.close()


@pytest.mark.parametrize("on_rate", [True, False])
def test_send_on_rate_sends_a_changed_rate_at_once_and_only_a_change(on_rate: bool) -> None:
    rig = Rig(replace(CanConfig(), send_on_rate=on_rate))
    try:
        rig.link.begin({}, 0.0)
        rig.run(0.1)  # parameters done, the first periodic command out at 0.01 s
        assert len(rig.commands()) == 1
        sent = rig.link.set_command(True, 3000.0, 200.0, 100.0)
        same = rig.link.set_command(True, 3000.0, 200.0, 100.0)  # no change: nothing more
        rig.run(0.2)
        assert (sent, same) == (on_rate, False)
        cmds = rig.commands()
        # on: the new rate is on the bus 0.1 s after the period's frame; off: it waits for 0.51 s
        assert len(cmds) == (2 if on_rate else 1)
        rig.run(0.6)
        cmds = rig.commands()
        assert cmds[-1][1].rate_upper_kg_ha == 200.0 and cmds[-1][0] == pytest.approx(0.51)
        assert len(cmds) == (3 if on_rate else 2)
    finally:
        rig.close()


def test_gnss_speed_without_send_on_gnss_waits_for_the_period(rig: Rig) -> None:
    rig.link.begin({}, 0.0)
    rig.run(0.2)
    rig.link.set_gnss(5.5, rig.t)
    rig.run(0.4)
    assert len(rig.commands()) == 1
    rig.run(0.6)
    assert [c.gnss_kmh for _, c in rig.commands()] == [None, 5.5]


def test_values_beyond_the_frame_are_clamped_and_counted(rig: Rig) -> None:
    rig.link.begin({}, 0.0)
    rig.link.set_command(True, 7000, 700, -5)
    rig.link.set_gnss(31.0, 0.0)
    rig.run(0.05)
    cmd = rig.commands()[0][1]
    assert (cmd.fan_rpm, cmd.rate_upper_kg_ha, cmd.rate_lower_kg_ha) == (6000, 600, 0)
    assert cmd.gnss_kmh == 25.0
    assert rig.link.counters.clamped == 2


def test_ecu_frames_decoded(rig: Rig) -> None:
    rig.link.begin({}, 0.0)
    rig.link.set_command(True, 3000, 200, 200)
    rig.link.set_gnss(4.0, 0.0)
    rig.run(1.0)
    ecu = rig.link.ecu
    assert ecu.status is not None and ecu.status.running
    assert ecu.diag is not None and ecu.diag.source is protocol.Source.WHEEL
    assert ecu.speeds is not None and ecu.speeds.gnss_kmh == pytest.approx(4.0)
    assert ecu.targets is not None
    assert ecu.status_t == pytest.approx(1.0, abs=0.1)
    assert rig.link.ecu_alive


def test_ecu_lost_and_back(rig: Rig) -> None:
    rig.link.begin({}, 0.0)
    rig.run(2.0)
    assert rig.link.ecu_alive
    assert [e for _, e in rig.events] == ["ECU: host firmware 0.1.0, protocol 1.1 (in-process)"]
    del rig.events[:]
    rig.twin.mute = True
    rig.run(4.0)
    assert not rig.link.ecu_alive and rig.link.state == "lost"
    assert len(rig.events) == 1
    t_lost, text = rig.events[0]
    assert text.startswith("ECU lost")
    # last status at ~2.0 s, timeout 0.5 s
    assert 2.5 < t_lost <= 2.62
    rig.twin.mute = False
    rig.run(5.0)
    assert rig.link.ecu_alive and rig.link.state == "ok"
    assert [e for _, e in rig.events] == [rig.events[0][1], "ECU back"]
    assert rig.link.counters.ecu_lost == 1


def test_ecu_never_heard_is_waited_for_not_lost(rig: Rig) -> None:
    rig.twin.mute = True
    rig.link.begin({}, 0.0)
    rig.run(1.0)
    assert rig.link.counters.ecu_lost == 0 and rig.events == []
    assert not rig.link.ecu_alive and rig.link.state == "wait"


def test_bad_frames_counted_and_ignored(rig: Rig) -> None:
    rig.link.begin({}, 0.0)
    rig.run(0.5)
    before = rig.link.ecu
    ids = protocol.DEFAULT_IDS
    bad = [
        can.Message(arbitration_id=0x123, data=b"\x00" * 8),  # foreign
        can.Message(arbitration_id=ids.status, data=b"\x0a\x00"),  # short
        can.Message(arbitration_id=ids.status, data=b"\x07" + b"\x00" * 7),  # RunState 7
        can.Message(arbitration_id=ids.targets, data=bytes(4) + b"\xc9" + bytes(3)),  # duty 100.5
        can.Message(arbitration_id=ids.param_ack, data=b"\x01\x09" + b"\x00" * 6),  # result 9
    ]
    for msg in bad:
        rig.link.on_frame(msg, 0.5)
    c = rig.link.counters
    assert (c.rx_foreign, c.rx_malformed) == (1, 4)
    assert rig.link.ecu == before


def test_configured_identifiers_are_used() -> None:
    cfg = loads_config("[can.ids]\ncommand = 0x0A5C6499\n").can
    rig = Rig(cfg)
    try:
        rig.link.begin({}, 0.0)
        rig.run(0.1)
        assert [m.arbitration_id for _, m in rig.seen if m.arbitration_id >> 24 == 0x0A] == [
            0x0A5C6499
        ]
        # the twin uses the paper's identifier, so it rejects the command as unknown
        assert rig.twin.ecu.counters.rx_unknown_id == 1
    finally:
        rig.close()


def test_unopenable_interface_is_a_device_error() -> None:
    cfg = replace(CanConfig(), interface="socketcan", channel="nosuchcan9")
    with pytest.raises(DeviceError, match="nosuchcan9"):
        open_bus(cfg)


def test_adapter_pulled_send_errors_are_counted_and_reported_once(rig: Rig) -> None:
    rig.link.begin({}, 0.0)
    rig.run(0.6)  # commands flowing
    send = rig.pc_bus.send

    def pulled(msg: can.Message, timeout: float | None = None) -> None:
        # what pyserial raises under python-can's slcan when the USB adapter is gone
        raise serial.SerialException("write failed: [Errno 5] Input/output error")

    rig.pc_bus.send = pulled  # type: ignore[method-assign]
    rig.run(2.0)
    assert rig.link.counters.tx_errors >= 2
    failures = [e for _, e in rig.events if e.startswith("CAN send failed")]
    assert failures == ["CAN send failed: write failed: [Errno 5] Input/output error"]
    rig.pc_bus.send = send  # type: ignore[method-assign]
    rig.run(2.6)
    assert rig.events[-1][1] == "CAN send works again"


def _forged_ack(param_id: int, result: protocol.AckResult, raw: int) -> can.Message:
    db = protocol.database()
    msg = db.get_message_by_name("EcuParamAck")
    data = msg.encode({"AckParamId": param_id, "AckResult": int(result), "AckRaw": raw})
    return can.Message(arbitration_id=msg.frame_id, data=data, is_extended_id=True)


def test_forged_acknowledgements_are_ignored_not_obeyed(rig: Rig) -> None:
    # Any host on a udp_multicast LAN can write frames: a forged refusal used to stop the
    # terminal (EcuParamError). Answers the ECU cannot give are counted and ignored.
    attacker = open_bus(rig.cfg)
    try:
        params = default_config().ecu_params()
        first_id, first_value = sorted(params.items())[0]
        spec = protocol.param(first_id)
        # for the parameter being pushed, ahead of the ECU's answer: refusals whose value in
        # force (AckRaw: 0 and 0.007 m) no ECU can hold, and "ok" with another value in force
        rig.link.begin(params, 0.0)
        attacker.send(_forged_ack(first_id, protocol.AckResult.OUT_OF_RANGE, 0))
        attacker.send(_forged_ack(first_id, protocol.AckResult.OUT_OF_RANGE, 7))
        attacker.send(_forged_ack(first_id, protocol.AckResult.OK, spec.to_raw(first_value) + 1))
        rig.run(1.5)  # would raise EcuParamError on the forged refusal
        assert rig.link.params_done
        assert rig.link.counters.rx_implausible == 3
        assert rig.twin.ecu.params.working_width_m == pytest.approx(first_value)
    finally:
        attacker.shutdown()


def test_udp_multicast_is_warned_about_at_start() -> None:
    cfg = loads_config('[can]\ninterface = "udp_multicast"\nchannel = "239.74.163.2"\n').can
    bus = can.Bus(interface="virtual", channel="test-canlink-udp-warning")
    events: list[str] = []
    try:
        link = CanLink(bus, cfg, fan_rpm=3000, on_event=lambda e: events.append(str(e)))
        link.begin({}, 0.0)
        link.begin({}, 1.0)  # a re-push: said once
    finally:
        bus.shutdown()
    warnings = [e for e in events if "udp_multicast" in e]
    assert len(warnings) == 1 and "any host on this network" in warnings[0]


def test_interface_without_its_driver_is_a_device_error_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # kvaser without the vendor's canlib raised NameError: a traceback and exit code 1
    cfg = replace(CanConfig(), interface="kvaser", channel="0")
    with pytest.raises(DeviceError, match="'kvaser': its driver or the vendor library"):
        open_bus(cfg)
    empty = tmp_path / "empty.txt"
    empty.write_text("")
    config = tmp_path / "kvaser.toml"
    config.write_text(
        f'[gnss]\nsource = "file"\npath = "{empty}"\n[crop]\nsource = "file"\npath = "{empty}"\n'
        f'[can]\ninterface = "kvaser"\nchannel = "0"\n[log]\ndir = "{tmp_path}"\n'
    )
    assert main(["run", "--config", str(config), "--duration", "1"]) == 2
    err = capsys.readouterr().err
    assert "kvaser" in err and "Traceback" not in err


def test_ecu_rebooted_within_the_timeout_gets_the_parameters_again(rig: Rig) -> None:
    """No silence to lose it by: the fresh ECU's EcuIdent (OnDefaults) says it restarted."""
    rig.link.begin({1: 4.2, 6: 7}, 0.0)
    rig.link.set_command(True, 3000, 200, 100)
    rig.run(1.0)
    assert rig.link.ecu.ident is not None and not rig.link.ecu.ident.on_defaults
    rig.twin = SimulatedEcu(rig.ecu_bus, now=rig.t)  # a reset between two of its steps
    assert rig.twin.ecu.params.working_width_m == pytest.approx(3.6)
    rig.run(2.0)
    assert rig.link.counters.ecu_lost == 0 and rig.link.counters.ecu_restarts == 1
    assert rig.twin.ecu.params.working_width_m == pytest.approx(4.2)
    assert rig.twin.ecu.params.queue_len == 7
    assert rig.link.counters.tx_params == 4 and rig.link.state == "ok"
    assert rig.twin.ecu.state.running  # commanded again once its parameters were in force
    assert [e for _, e in rig.events][-1] == (
        "ECU restarted on its defaults: its parameters are sent again"
    )
