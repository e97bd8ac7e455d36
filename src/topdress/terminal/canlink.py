"""The terminal's CAN link to the implement ECU.

One `CanLink` speaks the protocol of protocol/topdress.dbc over any python-can bus (socketcan,
slcan, pcan, kvaser, virtual, udp_multicast, ...). It never reads a clock and never blocks: the
terminal loop hands it every received frame (`on_frame`) and calls `poll(now)` often; `now` is
seconds on any monotonic clock (virtual in tests). It

- pushes the ECU parameters at start, one PcParamSet each, and waits for each EcuParamAck:
  a refusal fails at once naming the parameter; a silent ECU (not powered yet, the implement
  not hitched) is waited for, retrying with a backoff, and the push goes on at once when its
  first status frame is heard;
- sends the paper's PcCommand every `command_period_s`, at once on a new GNSS speed when
  `send_on_gnss` is set, and at once when start, fan or a rate changes when `send_on_rate` is
  set (the terminal sets the command once per 100 ms tick, so at most every 100 ms);
- decodes EcuStatus, EcuDiag, EcuSpeeds, EcuTargets and EcuGnssLag, counting foreign and
  malformed frames;
- takes the ECU's EcuIdent (target, firmware, protocol version, transport, reset cause): says
  who the ECU is when that changes, warns when its protocol version is not the terminal's own
  (the DBC's VERSION), and hands it to `on_ident` (the terminal logs it);
- tracks ECU liveness: no EcuStatus for `ecu_timeout_s` reports "ECU lost", the next one "ECU back"
  and pushes the parameters again (an ECU that rebooted meanwhile runs on its defaults); an ECU
  that rebooted faster than that says so in its EcuIdent (`OnDefaults`), and is pushed them
  again too; both with
  the values the terminal `renew`ed meanwhile (the GNSS lag learned so far), and tells
  `on_again` once they are in force. A running ECU that answers Busy to a `GnssLag` while it
  reports a lag learned since it was heard again is not stopped for it: that value is only where
  learning starts, and it has learned.
  An ECU never heard is waited for ("wait"), not lost.

On an ISOBUS (`isobus=True`) the same link speaks to a topdress ECU the Task Controller serves,
its frames carried on Proprietary A/B by terminal.proplink's `PropLink` (the `bus` it sends on):
everything above but the PcCommand, which has no ISOBUS form (the Task Controller sets the
rates and sections); the paper's identifiers are used whatever `[can.ids]` says, since the
mapping to the proprietary PGNs is by them (protocol/topdress.dbc, IsobusPgn).

The parameter push is terminal.parampush's `ParamPusher`; what the link knows of the ECU
(its frames as last heard, the counters, who it is) terminal.ecuview's. It sends on anything
with python-can's `send`: the terminal's `devices.can.CanPort`, which
keeps the adapter open (and reopens it) in its own thread, or a bus itself in tests.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Protocol

import can

from topdress import protocol
from topdress.config import CanConfig
from topdress.errors import DeviceError, ProtocolError
from topdress.i18n import Text, text
from topdress.terminal.ecuhealth import FaultRecord, health_event
from topdress.terminal.ecuview import (
    Command,
    EcuView,
    LinkCounters,
    frame_ids,
    ident_mismatch,
    ident_text,
    terminal_protocol,
)
from topdress.terminal.parampush import PARAM_BACKOFF_S, ParamPusher

log = logging.getLogger(__name__)

# Limits of PcCommand (DBC): values beyond them are clamped rather than failing the loop.
MAX_GNSS_KMH = 25.0
MAX_RATE_KG_HA = 600.0
MAX_FAN_RPM = 6000.0
# Tolerance of time comparisons: a deadline met to the microsecond counts as met.
_EPS_S = 1e-6


class Sender(Protocol):
    """What the link sends on: python-can's `send` (a bus, or devices.can.CanPort)."""

    def send(self, msg: can.Message, timeout: float | None = None) -> None: ...


def _clamp(value: float, hi: float) -> float:
    return min(max(value, 0.0), hi)


class CanLink:
    """The PC side of the protocol on one bus. Not thread-safe: one control loop owns it."""

    def __init__(
        self,
        bus: Sender,
        cfg: CanConfig,
        fan_rpm: float = 0.0,
        param_ack_timeout_s: float = 0.2,
        param_retries: int = 3,
        param_backoff_s: tuple[float, ...] = PARAM_BACKOFF_S,
        on_tx: Callable[[can.Message], None] | None = None,
        on_event: Callable[[Text], None] | None = None,
        on_ident: Callable[[protocol.EcuIdent, float], None] | None = None,
        on_again: Callable[[Mapping[int, float], float], None] | None = None,
        isobus: bool = False,
    ) -> None:
        """`on_again(params, now)`: the parameters pushed again to an ECU back from a loss are
        all in force. `isobus`: the ECU is on an ISOBUS behind `bus` (no PcCommand)."""
        self.isobus = isobus
        self._ack_timeout_s = param_ack_timeout_s
        self._on_ident = on_ident
        self._on_again = on_again
        self._retries = param_retries
        self._backoff_s = param_backoff_s
        self._on_tx = on_tx
        self._on_event = on_event
        self._start(bus, cfg, Command(fan_rpm=_clamp(fan_rpm, MAX_FAN_RPM)))

    def _start(self, bus: Sender, cfg: CanConfig, command: Command) -> None:
        """The state of a link fresh on `bus`."""
        self._bus = bus
        self.cfg = cfg
        self.ids = protocol.DEFAULT_IDS if self.isobus else frame_ids(cfg)
        self.counters = LinkCounters()
        self.command = command
        self.ecu = EcuView()
        self._fault_record = FaultRecord()  # a firmware's EcuFaultRecord round
        self._params = ParamPusher(
            self._send,
            self._send_stop,
            self.ids,
            self.where,
            self.counters,
            lambda: self.ecu,
            self._event,
            self._on_again,
            self._ack_timeout_s,
            self._retries,
            self._backoff_s,
            self.isobus,
        )
        self._next_cmd_t: float | None = None
        self._alive = False
        self._lost = False
        self._warned_open_bus = False
        self._send_failing = False
        self._gnss_seq = 0  # PcGnssTime: one number per new fix
        # start, fan, rates of the last command sent (send_on_rate compares against them)
        self._sent: tuple[bool, float, float, float] | None = None

    @property
    def bus(self) -> Sender:
        return self._bus

    def move_to(self, bus: Sender, cfg: CanConfig, params: Mapping[int, float], now: float) -> None:
        """Go on on the bus of a changed `[can]` section, already open, as a link fresh on it
        (counters, the ECU's frames and the parameter push start over; the command carries
        on). Closing the old bus is the caller's."""
        self._start(bus, cfg, self.command)
        self.begin(params, now)

    # ---- start-up: parameters (terminal.parampush) ---------------------------------------
    def begin(self, params: Mapping[int, float], now: float) -> None:
        """Start pushing `params` (PcParamSet id -> physical value); see `params_done`.

        Raises ProtocolError at once for a value the frame cannot carry."""
        if self.cfg.interface == "udp_multicast" and not self._warned_open_bus:
            self._warned_open_bus = True
            self._event(text("event.udp_multicast"))
        self._params.begin(params, now)

    @property
    def params_done(self) -> bool:
        return self._params.done

    @property
    def refused(self) -> tuple[str, float, protocol.AckResult] | None:
        """The parameter the ECU refused in the push at start (name, value, its answer); the
        push stops there until a new one begins."""
        return self._params.refused

    @property
    def ready(self) -> bool:
        """Every parameter was acknowledged once: the ECU has worked for this terminal."""
        return self._params.ready

    @property
    def state(self) -> str:
        """`wait` until every parameter is acknowledged (at start, and again after the ECU
        came back from a loss), then `ok`; `lost` while it is not heard."""
        if self._lost:
            return "lost"
        return "ok" if self.ready and self._alive and self.params_done else "wait"

    @property
    def where(self) -> str:
        """The interface and channel the link listens on, e.g. `socketcan:can0`."""
        return f"{self.cfg.interface}:{self.cfg.channel}"

    def push_params(
        self,
        params: Mapping[int, float],
        now: float,
        on_done: Callable[[str | None, list[int]], None],
    ) -> None:
        """The settings' parameter push (`ParamPush.push_params`)."""
        self._params.push_params(params, now, on_done)

    def renew(self, params: Mapping[int, float]) -> None:
        """Values to push again, in place of those in force, when the ECU comes back from a loss
        (it may have restarted on its defaults); nothing is sent now. ProtocolError for a value
        the frame cannot carry."""
        self._params.renew(params)

    def send(self, msg: can.Message) -> bool:
        """Send one frame now (calibration commands); a failure is counted as for commands."""
        return self._send(msg)

    # ---- running --------------------------------------------------------------------------
    def set_command(
        self, start: bool, fan_rpm: float, rate_upper_kg_ha: float, rate_lower_kg_ha: float
    ) -> bool:
        """Set what the next PcCommand carries (sent on the period; at once with send_on_rate
        when start, fan or a rate changed). True when it was sent here."""
        values = (fan_rpm, rate_upper_kg_ha, rate_lower_kg_ha)
        limits = (MAX_FAN_RPM, MAX_RATE_KG_HA, MAX_RATE_KG_HA)
        fan, upper, lower = (_clamp(v, hi) for v, hi in zip(values, limits, strict=True))
        if (fan, upper, lower) != values:
            self.counters.clamped += 1
        self.command = replace(
            self.command, start=start, fan_rpm=fan, rate_upper_kg_ha=upper, rate_lower_kg_ha=lower
        )
        changed = self._sent is not None and self._sent != (start, fan, upper, lower)
        if self.cfg.send_on_rate and changed and self.params_done and not self.isobus:
            return self._send_command()
        return False

    def set_gnss(self, kmh: float | None, now: float) -> None:
        """A new GNSS speed (None: not available). Sent at once when send_on_gnss is set."""
        if kmh is not None and not 0.0 <= kmh <= MAX_GNSS_KMH:
            self.counters.clamped += 1
            kmh = _clamp(kmh, MAX_GNSS_KMH)
        self.command = replace(self.command, gnss_kmh=kmh)
        if self.cfg.send_on_gnss:
            self.send_now()

    def send_gnss_time(self, kmh: float | None, age_ms: float) -> None:
        """PcGnssTime for a new fix: its speed (0.01 km/h) and how old it is now, so the ECU's
        fused estimate applies it at its time of validity (docs/speed.md)."""
        if not self.params_done:
            return
        if kmh is not None:
            kmh = _clamp(kmh, MAX_GNSS_KMH)
        self._gnss_seq = (self._gnss_seq + 1) & 0xFF
        age = round(min(max(age_ms, 0.0), 10000.0))
        self._send(protocol.encode_gnss_time(kmh, age, self._gnss_seq, ids=self.ids))

    def send_now(self) -> None:
        """Send the command at once (once the parameters are in force), off the period."""
        if self.params_done and not self.isobus:
            self._send_command()

    def poll(self, now: float) -> None:
        """Periodic work: parameter retries, the command period, ECU liveness.

        Raises EcuParamError when a parameter is refused."""
        self._params.poll(now)
        # No PcCommand on an ISOBUS: the Task Controller sets the rates.
        next_t = self._next_cmd_t
        if not self.isobus and self.params_done and (next_t is None or now >= next_t - _EPS_S):
            # On a fixed grid, so send-on-GNSS frames in between do not shift the period;
            # after a stall the grid restarts from now.
            period = self.cfg.command_period_s
            due = now if next_t is None else next_t
            self._next_cmd_t = due + period if now - due < period else now + period
            self._send_command()
        self._poll_liveness(now)

    def _send_command(self) -> bool:
        c = self.command
        msg = protocol.encode_command(
            c.start, c.fan_rpm, c.rate_upper_kg_ha, c.rate_lower_kg_ha, c.gnss_kmh, ids=self.ids
        )
        if self._send(msg):
            self.counters.tx_commands += 1
            self._sent = (c.start, c.fan_rpm, c.rate_upper_kg_ha, c.rate_lower_kg_ha)
            return True
        # A failed send is not retried early: the next period carries fresher values.
        return False

    def _send_stop(self) -> bool:
        """The stop command now, to an ECU running when it should take a parameter; False when
        not sent (on an ISOBUS the Task Controller's work state stops it: terminal.busswitch
        holds it off while a push is under way)."""
        if self.isobus:
            return False
        return self._send(protocol.encode_command(False, 0.0, 0.0, 0.0, None, ids=self.ids))

    def _send(self, msg: can.Message) -> bool:
        try:
            self._bus.send(msg, timeout=0.01)
        except DeviceError:
            # No adapter open (it is being opened again): its loss is an event of its own.
            self.counters.tx_errors += 1
            return False
        # OSError too: a serial adapter (slcan) pulled out raises pyserial's errors as they are.
        except (can.CanError, OSError) as exc:
            self.counters.tx_errors += 1
            if not self._send_failing:  # once per failure spell, not twice a second
                self._send_failing = True
                self._event(text("event.can_tx_failed", error=str(exc)))
            return False
        if self._send_failing:
            self._send_failing = False
            self._event(text("event.can_tx_again"))
        if self._on_tx is not None:
            self._on_tx(msg)
        return True

    # ---- receiving --------------------------------------------------------------------------
    def on_frame(self, msg: can.Message, now: float) -> None:
        """Take one received frame; foreign or malformed frames are counted, never acted on."""
        self.counters.rx_frames += 1
        try:
            decoded = protocol.decode(msg, self.ids)
        except ProtocolError as exc:
            if protocol.is_known_id(msg.arbitration_id, self.ids):
                self.counters.rx_malformed += 1
                log.debug("malformed frame: %s", exc)
            else:
                self.counters.rx_foreign += 1
                log.debug("foreign frame 0x%08X", msg.arbitration_id)
            return
        if isinstance(decoded, protocol.EcuStatus):
            first = self.ecu.status_t is None
            self.ecu = replace(self.ecu, status=decoded, status_t=now)
            self._alive = True
            if first or self._lost:
                self._on_heard(now, back=self._lost)
        elif isinstance(decoded, protocol.EcuDiag):
            self.ecu = replace(self.ecu, diag=decoded)
        elif isinstance(decoded, protocol.EcuSpeeds):
            self.ecu = replace(self.ecu, speeds=decoded)
        elif isinstance(decoded, protocol.EcuTargets):
            self.ecu = replace(self.ecu, targets=decoded)
        elif isinstance(decoded, protocol.EcuParamAck):
            self._params.on_ack(decoded, now)
        elif isinstance(decoded, protocol.EcuCalStatus):
            self.ecu = replace(self.ecu, cal=decoded, cal_t=now)
        elif isinstance(decoded, protocol.EcuGnssLag):
            self.ecu = replace(self.ecu, lag=decoded)
        elif isinstance(decoded, protocol.EcuIdent):
            self._take_ident(decoded, now)
        elif isinstance(decoded, protocol.EcuCanHealth):
            said = health_event(self.ecu.can_health, decoded)
            self.ecu = replace(self.ecu, can_health=decoded)
            if said is not None:
                self._event(said)
        elif isinstance(decoded, protocol.EcuFaultRecord):
            said = self._fault_record.take(decoded)
            if said is not None:
                self._event(said)
        # PC frames (another PC on the bus, or our own echo) are not for us.

    def _take_ident(self, ident: protocol.EcuIdent, now: float) -> None:
        """The ECU says who it is (at power-up, when a PC starts commanding it, on a new
        listener): said when it differs from what it said last, warned of when its protocol
        version is not this terminal's, always handed on (its reset cause is news)."""
        before = self.ecu.ident
        self.ecu = replace(self.ecu, ident=ident)
        if before is None or before.target != ident.target or before.firmware != ident.firmware:
            self._event(text("event.ecu_ident", ecu=ident_text(ident), transport=ident.transport))
        if ident_mismatch(ident) and (before is None or before.protocol != ident.protocol):
            ours = terminal_protocol()
            self._event(text("event.ecu_protocol", ecu=ident.protocol_version, terminal=ours))
        if ident.on_defaults:
            had = before is not None and not before.on_defaults
            self._params.restarted(now, had, self._lost)
        if self._on_ident is not None:
            self._on_ident(ident, now)

    def reconnected(self, now: float) -> None:
        """On an ISOBUS: the ECU connected to the Task Controller again, the first sign of a
        reboot within `ecu_timeout_s`: what it took may be gone, and the parameters in force
        are pushed again. Not while a push is under way: that one sends those not yet taken,
        and those taken before a reboot are sent again on its EcuIdent (OnDefaults)."""
        if self._params.done:
            self._params.restarted(now, True, self._lost, "event.ecu_reconnected")

    def _on_heard(self, now: float, back: bool) -> None:
        """The first status frame, or the first after a loss."""
        if back:
            self._lost = False
            self._event(text("event.ecu_back"))
        self._params.heard(now, back)

    def _poll_liveness(self, now: float) -> None:
        # An ECU never heard is waited for (see `state`), not lost.
        last = self.ecu.status_t
        if last is None or self._lost or now - last <= self.cfg.ecu_timeout_s + _EPS_S:
            return
        self._lost = True
        self._alive = False
        # What it said of its GNSS lag may not hold when it is back (it may have restarted).
        self.ecu = replace(self.ecu, lag=None)
        self.counters.ecu_lost += 1
        self._event(text("event.ecu_lost", s=now - last))

    @property
    def ecu_alive(self) -> bool:
        return self._alive

    def _event(self, message: Text) -> None:
        log.info("%s", message)
        if self._on_event is not None:
            self._on_event(message)
