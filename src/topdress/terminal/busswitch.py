"""The CAN bus in use, its adapter's life cycle, and the move to the bus of a changed [can].

`BusSwitch` owns the CAN port (`devices.can.CanPort`, which opens and reopens the adapter in
its own thread) and the `CanLink` speaking over it. The port's thread hands the loop what it
reads and what happens to it (`sink`); the loop hands those on to `take`. A changed `[can]`
section opens its bus in its own thread while the old one keeps working; once it is open the
ECU there is given its parameters while it is still commanded on the old bus, and the link
moves to it when it has them (at once when nothing works on the old one). No device is opened
on the loop's thread.

With `[can] implement = "isobus"` the bus is an ISOBUS: every frame goes to the Task Controller
(`TcLink`, terminal.tclink), which turns the command the desk decided into the implement's
setpoints. The topdress ECU's link speaks only when the implement served is a topdress ECU
(terminal.proplink): its private frames on Proprietary A/B, the parameters pushed once it is
recognised; while they are not all in force the TC is given the stop command, as no PcCommand
goes out on the private bus before them. A parameter the ECU refuses there does not end the
program as at start on its own bus (the ECU may be recognised mid-field, and every implement
depends on the TC going on): it is an alarm naming it, the implement held at rate 0 until the
ECU connects again or the operator changes a setting of its parameters.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import can

from topdress.config import CanConfig, TerminalConfig
from topdress.devices.can import CanPort
from topdress.errors import EcuParamError
from topdress.i18n import Text, text
from topdress.protocol import EcuIdent
from topdress.terminal.canlink import CanLink
from topdress.terminal.ecuview import terminal_protocol
from topdress.terminal.inbox import Inbox
from topdress.terminal.journal import Journal, Settings
from topdress.terminal.lines import in_background
from topdress.terminal.proplink import PropLink
from topdress.terminal.tclink import PARAMS, TcLink

log = logging.getLogger(__name__)

#: How long the ECU has to take its parameters on a changed [can] bus while the old one works
#: (it answers within milliseconds; the fast retries take 0.8 s).
NEW_BUS_WAIT_S = 3.0


@dataclass
class _Opening:
    """The bus of a changed [can] section, from the moment it starts opening until in use."""

    port: CanPort
    cfg: TerminalConfig
    done: Callable[[str | None], None]
    next: CanLink | None = None  # the link given the parameters there while the old one works
    since: float = 0.0


class BusSwitch:
    """The CAN port and link in use; `start_ms()` is the GNSS lag pushed with the parameters,
    `on_again(params, now)` is told when they are in force again in an ECU back from a loss."""

    def __init__(
        self,
        bus: can.BusABC | CanPort,
        settings: Settings,
        journal: Journal,
        inbox: Inbox,
        start_ms: Callable[[], int | None],
        on_again: Callable[[Mapping[int, float], float], None],
    ) -> None:
        cfg = settings.cfg
        self._settings = settings
        self._journal = journal
        self._inbox = inbox
        self._start_ms = start_ms
        self._on_again = on_again
        clock = journal.clock
        self.port = bus if isinstance(bus, CanPort) else CanPort(cfg.can, bus, clock=clock)
        self._opening: _Opening | None = None
        self._port_down_since: float | None = None
        self._failing = False  # a receive error was told; the next frame ends the spell
        self.tc = self._new_tc(self.port, cfg)
        self.prop = self._new_prop(self.port, cfg)
        self.link = self._new_link(self.port, cfg.can, cfg.machine.fan_rpm)

    def _new_tc(self, port: CanPort, cfg: TerminalConfig) -> TcLink | None:
        """The Task Controller on an ISOBUS (None: the bus is the topdress ECU's)."""
        if cfg.can.implement != "isobus":
            return None
        return TcLink(port, self._settings, self._journal, on_tx=self._log_tx)

    def _new_prop(self, port: CanPort, cfg: TerminalConfig) -> PropLink | None:
        """The topdress ECU's private frames beside the Task Controller (None: no ISOBUS)."""
        if self.tc is None:
            return None

        def say(what: Text) -> None:
            self._journal.event(text("event.isobus", what=what))

        server = self.tc.server
        return PropLink(port, server, cfg.isobus.ecu_manufacturer, self._log_tx, say)

    @property
    def ecu_state(self) -> str:
        """The ECU link's state: the CAN link's, or the ISOBUS implement's (ok, lost, wait: none
        served yet, or its pool refused; a topdress ECU served is ok once its own link is, its
        parameters in force and its status heard, as on its own bus), and `lost` while no
        adapter is open."""
        if not self.port.connected:
            return "lost"
        if self.tc is not None:
            state = self.tc.state
            if state == "ok" and self.prop is not None and self.prop.serving:
                return self.link.state
            return state if state in ("ok", "lost") else "wait"
        return self.link.state

    @property
    def ready(self) -> bool:
        """The machine has worked for this terminal: the ECU took every parameter, or an ISOBUS
        implement activated its pool."""
        return self.tc.connected_once if self.tc is not None else self.link.ready

    @property
    def pushes_params(self) -> bool:
        """The topdress ECU's parameters are pushed: on its own bus, or on an ISOBUS once it is
        recognised as the implement served (another implement has none)."""
        return self.prop is None or self.prop.serving

    def params(self, cfg: TerminalConfig) -> dict[int, float]:
        """The ECU parameters pushed at start, the GNSS lag's start value included."""
        return cfg.ecu_params(self._start_ms())

    def _new_link(self, port: CanPort, cfg: CanConfig, fan_rpm: float) -> CanLink:
        """The topdress ECU's link: on `port`, or on an ISOBUS through the PropLink (which
        logs the frames as they go on the bus)."""
        return CanLink(
            port if self.prop is None else self.prop,
            cfg,
            fan_rpm=fan_rpm,
            on_tx=self._log_tx if self.prop is None else None,
            on_event=self._journal.event,
            on_ident=self._log_ident,
            on_again=self._on_again,
            isobus=self.prop is not None,
        )

    def begin(self, now: float) -> None:
        """The parameter push at open (the topdress ECU's; on an ISOBUS once one is served)."""
        if self.tc is None:
            self.link.begin(self.params(self._settings.cfg), now)

    def start(self) -> None:
        """The port's reader thread (a caller driving the loop itself hands frames in)."""
        self.port.start(self.sink(self.port))

    def on_gnss(self, now: float) -> None:
        """A new GNSS speed was set on the link (sent at once with send_on_gnss there): with
        send_on_gnss an ISOBUS implement gets its setpoints at once too."""
        if self.tc is not None and self._settings.cfg.can.send_on_gnss:
            self.tc.send_now(now)

    def stop_implement(self, now: float) -> None:
        """The terminal closes: the stop command to whichever implement it commands."""
        self.link.set_command(False, 0.0, 0.0, 0.0)
        if self.tc is not None:
            self.tc.send_stop(now)
        else:
            self.link.send_now()

    def close(self) -> None:
        if self._opening is not None:
            self._give_up("the terminal closed before the new CAN bus was in use")
        self.port.stop()

    def open_can(self, new: TerminalConfig, done: Callable[[str | None], None]) -> None:
        """Open the bus of a changed [can] section in its own thread (slcan's open alone
        sleeps 2 s); the bus in use keeps working meanwhile. Once it is open the link moves to
        it and `done(None)` is called; if it cannot be opened, `done(reason)` and the old one
        stays. Both in the loop."""
        port = CanPort(new.can, clock=self._journal.clock)
        self._opening = _Opening(port, new, done)
        port.start(self.sink(port))

    def sink(self, port: CanPort) -> Callable[[float, str, Any], None]:
        """What a CAN port's thread hands the loop: the frames of the port in use, and what
        happens to any port (opened, lost, an error), for the loop to act on in turn."""
        inbox = self._inbox

        def sink(t: float, what: str, payload: Any) -> None:
            if what == "frame":
                if port is self.port:
                    inbox.put(("can", t, payload))
                elif self._opening is not None and port is self._opening.port:
                    inbox.put(("can_next", t, payload))  # the ECU readied on a new bus
                # else a bus being left: not ours any more
            elif what == "rx_error":
                if port is self.port:
                    inbox.put(("can_error", t, payload))
            else:
                inbox.put(("can_port", t, (port, what, payload)))

        return sink

    def take(self, kind: str, t: float, payload: Any) -> None:
        """One of the inbox's CAN items (`can`, `can_error`, `can_port`, `can_next`)."""
        if kind == "can":
            self._failing = False
            self._journal.raw("can_rx", t, (payload.arbitration_id, bytes(payload.data)))
            if self.tc is None:
                self.link.on_frame(payload, t)
                return
            self.tc.on_frame(payload, t)
            self._follow(t)  # the frame may have connected it: its EcuIdent follows at once
            assert self.prop is not None
            private = self.prop.take(payload)
            if private is None:
                return
            try:
                self.link.on_frame(private, t)
            except EcuParamError as exc:  # held by `held()` while it stands: said, logged
                self._journal.event(text("event.isobus", what=str(exc)))
                self._journal.log_event(t, "isobus.problem", what=str(exc))
        elif kind == "can_error":
            self._journal.counters["can_rx_errors"] += 1
            if not self._failing:  # once per failure spell (the reader retries)
                self._failing = True
                self._journal.event(text("event.can_rx_error", error=str(payload)))
        elif kind == "can_port":
            self._on_port(t, *payload)
        elif kind == "can_next":
            self._poll_new_bus(t, payload)

    def poll(self, now: float, command: tuple[bool, float, float, float]) -> None:
        """The tick's turn: the next command (start, fan rpm, upper and lower kg/ha) set on the
        link in use, the link readied on a new bus, then the link in use (it may be that one
        now)."""
        self.link.set_command(*command)
        self._poll_new_bus(now)
        if self.tc is None:
            self.link.poll(now)
            return
        self._follow(now)
        held = self.held(command)  # the command itself, or the stop while parameters are due
        self.tc.poll(now, held, PARAMS if held is not command else "")
        self.link.poll(now)

    def _follow(self, now: float) -> None:
        """The client the TC serves, followed on each frame and tick (the ECU announces itself
        within milliseconds of its pool's activation, its frames taken only once it is known
        to be served)."""
        assert self.prop is not None
        served = self.prop.watch()
        # A topdress ECU served: its parameters, then it may meter; one that refused one
        # gets another try from the top when it connects again.
        if served == "first" or (served == "again" and self.link.refused is not None):
            self.push_again(now)
        elif served == "again":  # connected again (a reboot is not heard otherwise)
            self.link.reconnected(now)

    @property
    def refused(self) -> Text | None:
        """The alarm of a parameter the topdress ECU served on an ISOBUS refused (None: none)."""
        refused = self.link.refused if self.prop is not None and self.prop.serving else None
        if refused is None:
            return None
        name, value, result = refused
        why = text(f"ecu.ack.{result.name.lower()}")
        return text("alarm.text.ecu_param_refused", param=name, value=value, why=why)

    def push_again(self, now: float) -> None:
        """The parameters pushed from the top, as the configuration has them now."""
        self.link.begin(self.params(self._settings.cfg), now)

    def held(self, command: tuple[bool, float, float, float]) -> tuple[bool, float, float, float]:
        """The command for the Task Controller: the stop while a topdress ECU served has not all
        its parameters in force (on its own bus no PcCommand goes out before them)."""
        if self.prop is not None and self.prop.serving and not self.link.params_done:
            return (False, command[1], 0.0, 0.0)
        return command

    def _on_port(self, t: float, port: CanPort, what: str, detail: Any) -> None:
        if port is self.port:
            self._on_adapter(t, what, detail)
            return
        opening = self._opening
        if opening is None or port is not opening.port:
            return  # a port left behind
        if what == "open_failed":
            self._give_up(str(detail))
        elif what == "open" and opening.next is None:
            isobus = "isobus" in (opening.cfg.can.implement, self._settings.cfg.can.implement)
            if not isobus and self.port.connected and self.link.ready and self.link.ecu_alive:
                # The ECU works on the old bus: commanded there until it has its parameters
                # on the new one, so the change never leaves it without a command.
                opening.next = self._new_link(port, opening.cfg.can, self.link.command.fan_rpm)
                opening.since = t
                opening.next.begin(self.params(opening.cfg), t)
            else:  # nothing works on the old one: on at once
                self._use_new_bus(t)

    def _poll_new_bus(self, t: float, frame: Any = None) -> None:
        """The link readied on a changed [can] bus: a frame for it, its retries; it is used
        once the ECU there has every parameter, given up when the ECU refuses one or is not
        heard there within NEW_BUS_WAIT_S (the old bus stays)."""
        opening = self._opening
        if opening is None or opening.next is None:
            return
        try:
            if frame is not None:
                opening.next.on_frame(frame, t)
            opening.next.poll(t)
        except EcuParamError as exc:
            self._give_up(f"on {opening.port.name}: {exc}")
            return
        if opening.next.params_done:
            self._use_new_bus(t)
        elif t - opening.since > NEW_BUS_WAIT_S:
            self._give_up(
                str(text("event.can_new_bus_silent", where=opening.port.name, s=NEW_BUS_WAIT_S))
            )

    def _use_new_bus(self, t: float) -> None:
        opening = self._opening
        assert opening is not None
        self._opening = None
        old, self.port = self.port, opening.port
        # An ISOBUS TC starts over on the new bus (it claims its address there); the ECU's
        # parameters go to an ISOBUS once a topdress ECU is served there.
        was, self.tc = self.tc, self._new_tc(self.port, opening.cfg)
        if self.tc is not None and was is not None:
            self.tc.carry(was)  # the ground covered so far goes on with it
        self.prop = self._new_prop(self.port, opening.cfg)
        if self.tc is not None or self.link.isobus:  # the link's kind of bus changes
            self.link = self._new_link(self.port, opening.cfg.can, self.link.command.fan_rpm)
            if self.tc is None:
                self.link.begin(self.params(opening.cfg), t)
        elif opening.next is not None:
            opening.next.command = self.link.command  # what the ECU is doing carries on
            self.link = opening.next
        else:
            self.link.move_to(opening.port, opening.cfg.can, self.params(opening.cfg), t)
        self._failing = False
        self._port_down_since = None
        in_background(old.stop, "can-retire")
        opening.done(None)

    def _give_up(self, why: str) -> None:
        opening = self._opening
        assert opening is not None
        self._opening = None
        in_background(opening.port.stop, "can-retire")
        opening.done(why)

    def _on_adapter(self, t: float, what: str, detail: Any) -> None:
        """The adapter in use was lost, opened again, or cannot be opened yet."""
        where, journal = self.port.name, self._journal
        if what == "lost":
            journal.counters["can_lost"] += 1
            self._port_down_since = t
            journal.event(text("event.can_adapter_lost", why=f"{where}: {detail}"))
            journal.log_event(
                t, "link.lost", link="can", state="lost", where=where, why=str(detail)
            )
        elif what == "open" and self._port_down_since is not None:
            lost_s = round(t - self._port_down_since, 3)
            self._port_down_since = None
            self._failing = False
            journal.event(text("event.can_adapter_back", where=where, s=lost_s))
            journal.log_event(t, "link.restored", link="can", state="ok", lost_s=lost_s)
        elif what == "open_failed":
            # Said in the program log only: the operator was told it is lost and reopened.
            log.info("CAN %s cannot be opened yet: %s", where, detail)

    def _log_tx(self, msg: can.Message) -> None:
        self._journal.raw("can_tx", self._journal.clock(), (msg.arbitration_id, bytes(msg.data)))

    def _log_ident(self, ident: EcuIdent, t: float) -> None:
        self._journal.log_event(
            t,
            "ecu.ident",
            target=ident.target,
            firmware=ident.firmware_version,
            protocol=ident.protocol_version,
            terminal_protocol=terminal_protocol(),
            transport=ident.transport,
            reset_cause=ident.reset_cause,
            clock_fallback=ident.clock_fallback,
            on_defaults=ident.on_defaults,
        )
