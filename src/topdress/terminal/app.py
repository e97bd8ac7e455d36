"""The cab terminal: GNSS and crop lines in, the rate per layer out to the ECU, everything logged.

Sources (GNSS line source, crop line source, the CAN bus) run in their own reader threads and
put `(kind, t, payload)` on one queue; the control loop alone touches the state. It never waits
on a device, only on that queue, with a timeout that keeps its 10 Hz tick:

- an NMEA line: decoded; a new GNSS speed goes to the CAN link (sent at once with send_on_gnss);
- a crop line: parsed into the sensor table;
- a CAN frame: to the CAN link (status, diagnostics, speeds, targets, parameter acks);
- every tick: the NDVI where the meters are now (sensor mean through the distance queue, driven
  by the ECU's selected speed), the rate per layer from the NDVI model, the next command, one
  state row to the session log, and a fresh `Snapshot` for the display.

What happens (operator actions, settings, alarms, links lost and back, the ECU's fault word,
calibration results, the GNSS lag the ECU learns) also goes to the session log as events
(`log_event`), on the same clock.

The GNSS lag learned with this receiver in an earlier session (topdress.terminal.gnsslag, kept
beside the session logs) is the start value pushed to the ECU; the lag learned now is kept for
the next session, and is the start value pushed again to an ECU that comes back from a loss
(rebooted, it would start from the session's start value or its own default again).

GNSS lost (port vanished, no valid fix, stale speed) is forwarded as "not available", so the
ECU falls back to the wheel.

No device is opened on the loop's thread: the CAN adapter (`devices.can.CanPort`) and the serial
ports open, and reopen after a loss, in their own threads; a changed `[can]` section opens its bus
there too while the old one keeps working, and the link moves to it once it is open.
"""

from __future__ import annotations

import gc
import logging
import math
import threading
import time
from collections import Counter
from collections.abc import Callable, Mapping
from concurrent.futures import Future
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import can

from topdress.config import CanConfig, TerminalConfig
from topdress.crop.rate import RateModel, build_rate_model, split_layers
from topdress.crop.sensors import CompensatedNdvi
from topdress.devices.can import CanPort
from topdress.devices.lines import LineSource, open_line_source
from topdress.errors import EcuParamError
from topdress.geo.outlet import OutletTracker
from topdress.gnss.nmea import NmeaDecoder
from topdress.gnss.tracker import GnssSpeedTracker
from topdress.gnss.utc import UtcClock
from topdress.i18n import Text, text
from topdress.log.model import LogEvent
from topdress.log.rows import state_row
from topdress.log.session import SessionLog
from topdress.protocol import EcuIdent, fault_names
from topdress.terminal import signals
from topdress.terminal.canlink import (
    GNSS_LAG_ID,
    CanLink,
    EcuView,
    ident_mismatch,
    ident_text,
    terminal_protocol,
)
from topdress.terminal.desk import OperatorDesk
from topdress.terminal.ecuhealth import health_text
from topdress.terminal.gnsslag import MAX_LAG_MS, STORE_FILE, LagStore, LagWatch
from topdress.terminal.inbox import Inbox
from topdress.terminal.receiver import ReceiverWatch, input_key
from topdress.terminal.site import Maps, build_map_guard, build_site_rate
from topdress.view.commands import RUNNING, CommandResult
from topdress.view.links import link_state
from topdress.view.snapshot import TICK_S, LagView, Snapshot, ecu_values

log = logging.getLogger(__name__)

CROP_HOLD_S = 0.5  # a crop sensor state must hold this long to be an event
#: The states of each link that are a loss (an event when entered, another when left).
LOST_STATES = {"ecu": ("lost",), "gnss": ("lost", "no fix"), "crop": ("lost", "silent")}
HINT_LINES = 20  # unusable lines in a row from one input before the operator is told why
#: How long the ECU has to take its parameters on a changed [can] bus while the old one works
#: (it answers within milliseconds; the fast retries take 0.8 s).
NEW_BUS_WAIT_S = 3.0
# At most one GNSS speed to the ECU this often (a 40 Hz cap, above any receiver's rate): a
# receiver or a replayed file flooding lines must not flood the bus to the ECU with PcGnssTime
GNSS_SEND_MIN_S = 0.025


class Terminal:
    """The terminal's control loop over its three sources and the session log."""

    def __init__(
        self,
        cfg: TerminalConfig,
        gnss: LineSource,
        crop: LineSource,
        bus: can.BusABC | CanPort,
        session: SessionLog | None = None,
        clock: Callable[[], float] = time.monotonic,
        start: bool = True,
        on_event: Callable[[Text], None] | None = None,
        config_path: Path | None = None,
        maps: Maps | None = None,
    ) -> None:
        """`bus`: the `[can]` interface, open (kept open and reopened by a CanPort, which the
        terminal owns from now on: `close` shuts it down).
        `start`: the meters start at once (headless); else at the operator's Start.
        `config_path`: where settings changed while running are saved (None: not saved).
        `maps`: the prescription and boundary loaded already (None: loaded here)."""
        self.cfg = cfg
        self.gnss = gnss
        self.crop = crop
        self.session = session
        self.clock = clock
        self._on_event = on_event
        self.inbox = Inbox()
        self.port = bus if isinstance(bus, CanPort) else CanPort(cfg.can, bus, clock=clock)
        self._opening: _Opening | None = None  # a changed [can] section's bus
        self._port_down_since: float | None = None
        self.link = self._new_link(self.port, cfg.can, cfg.machine.fan_rpm)
        self.nmea = NmeaDecoder()
        self.tracker = GnssSpeedTracker(cfg.gnss.rmc_timeout_s, cfg.gnss.stale_s)
        self.ndvi = CompensatedNdvi(cfg.crop, cfg.lookahead.total_s)
        # The prescription map and boundary files (`run` reads them before any device opens).
        self.site = build_site_rate(cfg, build_rate_model(cfg.rate), maps)
        # How far the machine is from each map: said at the first fix, an alarm when too far.
        self.guard = build_map_guard(cfg, Maps(self.site.prescription, self.site.boundary))
        self._map_distance_said = False
        self.utc = UtcClock()
        self.outlet = OutletTracker(cfg.machine.outlet_along_m, cfg.machine.outlet_across_m)
        self.counters: Counter[str] = Counter()
        self.snapshot = Snapshot()
        self._t0: float | None = None
        self._gnss_state = "wait"
        self._gnss_seen = False
        self._gnss_sent_t = -math.inf
        self._crop_state = self._crop_reported = "wait"
        self._crop_since = 0.0
        self._can_failing = False
        self._hinted: set[str] = set()
        self._crop_ok_once = False
        self._last_event: Text | None = None
        self._lost_since: dict[str, float] = {}  # link -> when it was lost
        self._faults = 0  # the ECU's fault word as last heard
        self.desk = OperatorDesk(self, start, config_path)
        # The GNSS lag: kept per receiver beside the session logs (in memory without a log).
        self.receiver = ReceiverWatch(input_key(cfg.gnss))
        where = session.path.parent if session is not None else None
        self.lags = LagStore(where / STORE_FILE if where is not None else None)
        self.lag_watch = LagWatch()
        self.lag_start = self.lags.for_input(self.receiver.input)
        self._lag_renewed_ms: int | None = None  # the learned lag an ECU back is pushed
        if self.lags.error:
            self.event(text("event.gnss_lag_store", error=self.lags.error))

    @property
    def bus(self) -> can.BusABC | None:
        """The python-can bus in use (a changed [can] section moves the link to another; None
        while the adapter is being opened again)."""
        return self.port.bus

    @property
    def ecu_state(self) -> str:
        """The ECU link's state: the CAN link's, and `lost` while no adapter is open."""
        return self.link.state if self.port.connected else "lost"

    @property
    def model(self) -> RateModel:
        """The NDVI -> rate model in force."""
        return self.site.model

    @property
    def started_at(self) -> float | None:
        """The loop's clock when it opened (None before)."""
        return self._t0

    def post(self, command: Any) -> Future[CommandResult]:
        """Hand an operator command (topdress.view.commands) to the loop; thread-safe."""
        return self.desk.post(command)

    # ---- settings changed while running: the desk decides, the parts take them ---------------
    def reopen(self, section: str, new: TerminalConfig, now: float) -> None:
        """Open the line source of a changed [gnss] or [crop] section in place of the one in
        use; DeviceError when it cannot be made (the old one stays). A serial port opens in
        its reader thread; the old reader is stopped in a thread of its own."""
        kind = "nmea" if section == "gnss" else "crop"
        source = open_line_source(new.gnss if section == "gnss" else new.crop)
        if section == "gnss":
            old, self.gnss = self.gnss, source
        else:
            old, self.crop = self.crop, source
        _in_background(old.stop, f"stop-{old.name}")
        source.start(lambda t, line: self.inbox.put((kind, t, line)))

    def open_can(self, new: TerminalConfig, done: Callable[[str | None], None]) -> None:
        """Open the bus of a changed [can] section in its own thread (slcan's open alone
        sleeps 2 s); the bus in use keeps working meanwhile. Once it is open the link moves to
        it and `done(None)` is called; if it cannot be opened, `done(reason)` and the old one
        stays. Both in the loop."""
        port = CanPort(new.can, clock=self.clock)
        self._opening = _Opening(port, new, done)
        port.start(self._port_sink(port))

    def _new_link(self, port: CanPort, cfg: CanConfig, fan_rpm: float) -> CanLink:
        return CanLink(
            port,
            cfg,
            fan_rpm=fan_rpm,
            on_tx=self._log_tx,
            on_event=self.event,
            on_ident=self._log_ident,
            on_again=self._on_params_again,
        )

    def take(self, section: str, new: TerminalConfig) -> None:
        """The configuration with `section` changed, taken by the parts that read it."""
        self.cfg = new
        if section == "gnss":
            self.tracker.retune(new.gnss.rmc_timeout_s, new.gnss.stale_s)
        elif section in ("crop", "lookahead"):
            self.ndvi.retune(new.crop, new.lookahead.total_s)
        elif section == "rate":
            self.site.retune(new.rate)

    # ---- life cycle ---------------------------------------------------------------------------
    def open(self) -> None:
        """Start the line sources and the parameter push. `run` also starts the CAN port's
        reader; a caller driving `handle`/`tick` itself (virtual time) hands CAN frames in
        directly."""
        now = self.clock()
        self._t0 = now
        self.gnss.start(lambda t, line: self.inbox.put(("nmea", t, line)))
        self.crop.start(lambda t, line: self.inbox.put(("crop", t, line)))
        self.link.begin(self.cfg.ecu_params(self._lag_start_ms()), now)
        start = self.lag_start
        self.log_event(
            now,
            "gnss_lag.start",
            input=self.receiver.input,
            kept_ms=start.lag_ms if start is not None else None,
            fixed_ms=self._fixed_lag_ms(),
            error=self.lags.error,
        )
        if self.desk.op.state == RUNNING:  # headless: the meters start without an operator
            self.log_event(now, "operator.start", was="stopped", auto=True)

    def close(self) -> None:
        """Stop the ECU (a stop command), the readers, and the log; a stop signal arriving
        meanwhile is held until the log is closed (see topdress.terminal.signals)."""
        with signals.deferred():
            self._close()

    def _close(self) -> None:
        self.desk.close()
        self.link.set_command(False, 0.0, 0.0, 0.0)
        self.link.send_now()
        self.gnss.stop()
        self.crop.stop()
        if self._opening is not None:
            self._give_up_opening("the terminal closed before the new CAN bus was in use")
        self.port.stop()
        self._keep_lag(self.clock(), final=True)
        if self.session is not None:
            self.session.close()

    def _port_sink(self, port: CanPort) -> Callable[[float, str, Any], None]:
        """What a CAN port's thread hands the loop: the frames of the port in use, and what
        happens to any port (opened, lost, an error), for the loop to act on in turn."""

        def sink(t: float, what: str, payload: Any) -> None:
            if what == "frame":
                if port is self.port:
                    self.inbox.put(("can", t, payload))
                elif self._opening is not None and port is self._opening.port:
                    self.inbox.put(("can_next", t, payload))  # the ECU readied on a new bus
                # else a bus being left: not ours any more
            elif what == "rx_error":
                if port is self.port:
                    self.inbox.put(("can_error", t, payload))
            else:
                self.inbox.put(("can_port", t, (port, what, payload)))

        return sink

    def _on_port(self, t: float, port: CanPort, what: str, detail: Any) -> None:
        if port is self.port:
            self._on_adapter(t, what, detail)
            return
        opening = self._opening
        if opening is None or port is not opening.port:
            return  # a port left behind
        if what == "open_failed":
            self._give_up_opening(str(detail))
        elif what == "open" and opening.next is None:
            if self.port.connected and self.link.ready and self.link.ecu_alive:
                # The ECU works on the old bus: commanded there until it has its parameters
                # on the new one, so the change never leaves it without a command.
                opening.next = self._new_link(port, opening.cfg.can, self.link.command.fan_rpm)
                opening.since = t
                opening.next.begin(opening.cfg.ecu_params(self._lag_start_ms()), t)
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
            self._give_up_opening(f"on {opening.port.name}: {exc}")
            return
        if opening.next.params_done:
            self._use_new_bus(t)
        elif t - opening.since > NEW_BUS_WAIT_S:
            self._give_up_opening(
                str(text("event.can_new_bus_silent", where=opening.port.name, s=NEW_BUS_WAIT_S))
            )

    def _use_new_bus(self, t: float) -> None:
        opening = self._opening
        assert opening is not None
        self._opening = None
        old, self.port = self.port, opening.port
        if opening.next is not None:
            opening.next.command = self.link.command  # what the ECU is doing carries on
            self.link = opening.next
        else:
            self.link.move_to(
                opening.port, opening.cfg.can, opening.cfg.ecu_params(self._lag_start_ms()), t
            )
        self._can_failing = False
        self._port_down_since = None
        _in_background(old.stop, "can-retire")
        opening.done(None)

    def _give_up_opening(self, why: str) -> None:
        opening = self._opening
        assert opening is not None
        self._opening = None
        _in_background(opening.port.stop, "can-retire")
        opening.done(why)

    def _on_adapter(self, t: float, what: str, detail: Any) -> None:
        """The adapter in use was lost, opened again, or cannot be opened yet."""
        where = self.port.name
        if what == "lost":
            self.counters["can_lost"] += 1
            self._port_down_since = t
            self.event(text("event.can_adapter_lost", why=f"{where}: {detail}"))
            self.log_event(t, "link.lost", link="can", state="lost", where=where, why=str(detail))
        elif what == "open" and self._port_down_since is not None:
            lost_s = round(t - self._port_down_since, 3)
            self._port_down_since = None
            self._can_failing = False
            self.event(text("event.can_adapter_back", where=where, s=lost_s))
            self.log_event(t, "link.restored", link="can", state="ok", lost_s=lost_s)
        elif what == "open_failed":
            # Said in the program log only: the operator was told it is lost and reopened.
            log.info("CAN %s cannot be opened yet: %s", where, detail)

    def run(
        self,
        duration_s: float | None = None,
        on_tick: Callable[[Snapshot, float], None] | None = None,
    ) -> None:
        """Open, loop until `duration_s` has passed (or Ctrl-C), close (always)."""
        try:
            self.open()
            # Everything imported and opened so far lives as long as the process: kept out of
            # the collector's full passes, which otherwise scan it all (~20 ms) in some tick.
            gc.collect()
            gc.freeze()
            self.port.start(self._port_sink(self.port))
            assert self._t0 is not None
            self._loop(self._t0, duration_s, on_tick)
        finally:
            self.close()

    def _loop(
        self,
        t0: float,
        duration_s: float | None,
        on_tick: Callable[[Snapshot, float], None] | None,
    ) -> None:
        end = None if duration_s is None else t0 + duration_s
        next_tick = t0
        while end is None or self.clock() < end:
            now = self.clock()
            item = self.inbox.get(timeout=max(0.0, next_tick - now))
            if item is not None:
                self.handle(*item)
            now = self.clock()
            if now >= next_tick:
                self.tick(now)
                # Keep the 10 Hz grid; after a stall, restart it rather than burst.
                next_tick = next_tick + TICK_S if now - next_tick < TICK_S else now + TICK_S
                if on_tick is not None:
                    on_tick(self.snapshot, now)

    # ---- inputs -------------------------------------------------------------------------------
    def handle(self, kind: str, t: float, payload: Any) -> None:
        """Act on one queued input."""
        self.desk.record(kind, t, payload)
        if kind == "op":
            self.desk.handle(t, payload)
        elif kind == "nmea":
            self._on_nmea(t, payload)
        elif kind == "crop":
            self._on_crop(t, payload)
        elif kind == "can":
            self._can_failing = False
            if self.session is not None:
                self.session.raw("can_rx", t, (payload.arbitration_id, bytes(payload.data)))
            self.link.on_frame(payload, t)
        elif kind == "can_error":
            self.counters["can_rx_errors"] += 1
            if not self._can_failing:  # once per failure spell (the reader retries)
                self._can_failing = True
                self.event(text("event.can_rx_error", error=str(payload)))
        elif kind == "can_port":
            self._on_port(t, *payload)
        elif kind == "can_next":
            self._poll_new_bus(t, payload)
        self.link.poll(t)

    def _on_nmea(self, t: float, line: bytes) -> None:
        if self.session is not None:
            self.session.raw("nmea", t, line.decode("latin-1"))
        fix = self.nmea.decode(line)
        if self.receiver.see(t, fix, line):
            self._on_receiver(t)
        if not fix.ok:
            return
        if fix.fix_valid:
            self.utc.on_fix(t, fix.utc)
            self.outlet.on_fix(
                fix.lat, fix.lon, fix.course_deg, fix.speed_kmh, self.ndvi.odometer.distance_m
            )
            if not self._map_distance_said and fix.lat is not None and fix.lon is not None:
                self._map_distance_said = True
                self._say_map_distances(t, fix.lat, fix.lon)
        if self.tracker.update(t, fix) is not None:
            self._gnss_seen = True
            if t - self._gnss_sent_t < GNSS_SEND_MIN_S:
                self.counters["gnss_send_skipped"] += 1
                return
            self._gnss_sent_t = t
            kmh = self.tracker.current(t, self.gnss.connected)
            self.link.set_gnss(kmh, t)
            self.link.send_gnss_time(kmh, 0.0)

    def _on_crop(self, t: float, line: bytes) -> None:
        if self.session is not None:
            self.session.raw("crop", t, line.decode("latin-1"))
        reading = self.ndvi.sensors.feed(t, line)
        if reading is not None:
            self.model.observe(reading.ndvi)

    # ---- the tick -----------------------------------------------------------------------------
    def tick(self, now: float) -> None:
        """10 Hz: GNSS state, NDVI at the meters, rates, command, state row, snapshot."""
        gnss_kmh = self.tracker.current(now, self.gnss.connected)
        if gnss_kmh is None and self.link.command.gnss_kmh is not None:
            # Lost: sent at once (not at the next period), so the ECU falls back to the wheel.
            self.link.set_gnss(None, now)
            if not self.cfg.can.send_on_gnss:  # else set_gnss has sent it
                self.link.send_now()
        self._track_gnss_state(gnss_kmh, now)
        self._track_crop_state(now)
        self._hint_unusable_input()
        ecu = self.link.ecu
        v_sel = ecu.speeds.selected_kmh if ecu.speeds is not None and self.link.ecu_alive else 0.0
        ndvi_sensors = self.ndvi.sensors.mean_ndvi(now)
        ndvi_meters = self.ndvi.update(now, v_sel)
        # Before the meters reach the first spot sensed, the nearest information is the sensors'.
        ndvi = ndvi_meters if ndvi_meters is not None else ndvi_sensors
        odometer = self.ndvi.odometer.distance_m
        outlet = self.outlet.position(odometer)
        # The boundary at the outlet; the prescription where the outlet will be when the
        # product commanded now lands (speed x the look-ahead, as the NDVI); the NDVI model.
        ahead_m = max(v_sel, 0.0) / 3.6 * self.ndvi.lookahead_s
        target = self.outlet.position(odometer + ahead_m) if ahead_m > 0.0 else outlet
        site = self.site.decide(
            ndvi,
            (outlet.lat, outlet.lon) if outlet is not None else None,
            (target.lat, target.lon) if target is not None else None,
        )
        if ndvi is None and site.used_ndvi:
            self.counters["no_ndvi_ticks"] += 1
        rates = split_layers(site.total_kg_ha, self.cfg.rate.split_upper, self.cfg.machine.layers)
        # No command goes out before the parameters are in force anyway; while they are pushed
        # again (ECU back), a stop here would stop a running ECU for a command period.
        # The operator's state (stopped, paused, manual, a calibration) decides what goes out.
        start, fan, upper, lower = self.desk.rates((rates.upper_kg_ha, rates.lower_kg_ha))
        self.link.set_command(start, fan, upper, lower)
        self._poll_new_bus(now)
        self.link.poll(now)
        snap = self._snapshot(
            now,
            ndvi_sensors,
            ndvi,
            (upper, lower),
            utc=self.utc.now(now),
            heading_deg=outlet.heading_deg if outlet is not None else None,
            outlet_lat=outlet.lat if outlet is not None else None,
            outlet_lon=outlet.lon if outlet is not None else None,
            zone=site.zone,
            prescription_kg_ha=site.prescription_kg_ha,
        )
        # Before the desk's alarms: a link lost is logged ahead of the alarm it raises.
        self._track_links(now)
        self._track_faults(now)
        self._track_lag(now)
        if outlet is not None:
            off_map = self.guard.outside(outlet.lat, outlet.lon)
        else:
            off_map = ()
            self.guard.forget()
        self.snapshot = replace(snap, **vars(self.desk.after_tick(now, snap, off_map)))
        if self.session is not None:
            self.session.state(state_row(now, self.snapshot))

    def _say_map_distances(self, t: float, lat: float, lon: float) -> None:
        """Once, at the first fix: how far each map is from the machine (a map of another field
        shows before the meters start)."""
        for which, name, d in self.guard.distances(lat, lon):
            self.log_event(t, "map.distance", map=which, file=name, distance_m=round(d, 1))
            what = text(f"map.{which}")
            if d <= 0.0:
                self.event(text("event.map_inside", map=what, file=name))
            elif d < 1000.0:
                self.event(text("event.map_far_m", map=what, file=name, distance_m=round(d)))
            else:
                self.event(text("event.map_far_km", map=what, file=name, distance_km=d / 1000))

    def _track_links(self, now: float) -> None:
        states = {"ecu": self.ecu_state, "gnss": self._gnss_state, "crop": self._crop_reported}
        for link, state in states.items():
            lost = state in LOST_STATES[link]
            since = self._lost_since.get(link)
            if lost and since is None:
                self._lost_since[link] = now
                self.log_event(now, "link.lost", link=link, state=state)
            elif not lost and since is not None:
                del self._lost_since[link]
                lost_s = round(now - since, 3)
                self.log_event(now, "link.restored", link=link, state=state, lost_s=lost_s)

    def _track_faults(self, now: float) -> None:
        """The fault word as the ECU sends it; while it is not heard the word is not known."""
        diag = self.link.ecu.diag
        if not self.link.ecu_alive or diag is None or int(diag.faults) == self._faults:
            return
        was, word = self._faults, int(diag.faults)
        self._faults = word
        self.log_event(
            now,
            "fault.changed",
            faults=word,
            was=was,
            set=fault_names(word & ~was),
            cleared=fault_names(was & ~word),
        )

    # ---- the GNSS lag ---------------------------------------------------------------------------
    def _fixed_lag_ms(self) -> float | None:
        """[ecu] gnss_lag_ms when it is a number (a fixed lag), None for "auto"."""
        return self.cfg.ecu.overrides.get("gnss_lag_ms")

    def _lag_start_ms(self) -> int | None:
        """Where the ECU's learning starts: the lag learned so far in this session, else the
        one kept for this receiver's input (a fixed gnss_lag_ms overrides both)."""
        if self.lag_watch.learned_ms is not None:
            return self.lag_watch.learned_ms
        return self.lag_start.lag_ms if self.lag_start is not None else None

    def _lag_view(self) -> LagView | None:
        frame = self.link.ecu.lag
        if frame is None or not self.link.ecu_alive:
            return None
        return LagView.of(frame, self._fixed_lag_ms())

    def _track_lag(self, now: float) -> None:
        frame = self.link.ecu.lag
        if frame is None or not self.link.ecu_alive:
            return
        change = self.lag_watch.update(now, frame, self._fixed_lag_ms())
        self._renew_lag()
        if change is not None:
            self.log_event(now, "gnss_lag.changed", **change.detail())
            if change.tell():
                self.event(change.message())
            else:
                log.info("%s", change.message())
            if frame.learned_ms is not None:
                self._keep_lag(now, final=False)
        warning = self.lag_watch.warning(now)
        if warning is not None:
            log.warning("%s", warning)
            self.event(warning)

    def _renew_lag(self) -> None:
        """The lag learned so far becomes the start value an ECU back from a loss is pushed, as
        the session's start value was at open; a number in gnss_lag_ms stays the one pushed."""
        learned = self.lag_watch.learned_ms
        if self._fixed_lag_ms() is not None:
            self._lag_renewed_ms = None  # set to "auto" again later: renewed then
            return
        if learned is None or learned == self._lag_renewed_ms:
            return
        self.link.renew({GNSS_LAG_ID: float(min(max(learned, 0), MAX_LAG_MS))})
        self._lag_renewed_ms = learned

    def _on_params_again(self, params: Mapping[int, float], now: float) -> None:
        """The parameters are in force again in an ECU back from a loss: when they carried the
        lag learned so far and the ECU has reported no learned lag of its own since (it
        restarted), that lag is where its learning starts again: logged and told."""
        pushed = params.get(GNSS_LAG_ID)
        frame = self.link.ecu.lag
        learned = self._lag_renewed_ms
        if learned is None or pushed != learned or self._fixed_lag_ms() is not None:
            return
        if frame is not None and frame.learned_ms is not None:
            return  # it kept what it learned: nothing was restored
        start = self.lag_start
        self.log_event(
            now,
            "gnss_lag.restored",
            input=self.receiver.input,
            lag_ms=learned,
            start_ms=start.lag_ms if start is not None else None,
        )
        self.event(text("event.gnss_lag_restored", s=learned / 1000))

    def _on_receiver(self, now: float) -> None:
        """The receiver's identity settled: said in the log, and told when the lag pushed at
        start was kept for another receiver on this input."""
        rid = self.receiver.receiver
        start = self.lag_start
        same = start.receiver.same(rid) if start is not None else None
        self.log_event(
            now,
            "gnss_lag.receiver",
            input=rid.input,
            sentences=list(rid.sentences),
            versions=list(rid.versions),
            start_ms=start.lag_ms if start is not None else None,
            same_receiver=same,
        )
        if same is False:
            self.event(text("event.gnss_lag_other", input=rid.input))

    def _keep_lag(self, now: float, final: bool) -> None:
        """Keep the learned lag for this receiver (in the background while running); at the end
        of the session also the `gnss_lag.kept` event, saying what was kept."""
        rid = self.receiver.receiver
        learned = self.lag_watch.learned_ms
        if learned is not None and rid.known:
            self.lags.keep(rid, learned, wait=final)
        if final:
            self.lags.wait()
            self.log_event(
                now,
                "gnss_lag.kept",
                input=rid.input,
                sentences=list(rid.sentences),
                lag_ms=learned if rid.known else None,
                error=self.lags.error,
            )

    def _track_gnss_state(self, gnss_kmh: float | None, now: float) -> None:
        if gnss_kmh is not None:
            state = "ok"
        elif not self.gnss.connected:
            # Before the first attempt to open the port has failed, it is still "wait".
            state = "lost" if self._gnss_seen or self.gnss.last_error is not None else "wait"
        elif not self._gnss_seen:
            state = "wait"
        elif self.tracker.heard(now):
            state = "no fix"
        else:
            state = "lost"  # the port is open but the receiver fell silent
        if state != self._gnss_state:
            if self._gnss_state != "wait" or state != "ok":
                if state != "lost":
                    self.event(text("event.gnss", state=link_state(state)))
                elif self.gnss.connected:
                    self.event(text("event.gnss_silent", s=self.tracker.stale_s))
                else:
                    self.event(text("event.gnss_lost", why=_why(self.gnss)))
            self._gnss_state = state

    def _track_crop_state(self, now: float) -> None:
        n, fresh = self.cfg.crop.sensors, len(self.ndvi.sensors.fresh(now))
        heard = self.ndvi.sensors.counters["ok"] > 0
        if not self.crop.connected and (heard or self.crop.last_error is not None):
            state = "lost"
        elif fresh == n:
            state = "ok"
        elif fresh:
            state = f"{fresh}/{n}"
        else:
            state = "silent" if heard else "wait"
        if state != self._crop_state:
            self._crop_state, self._crop_since = state, now
        # A sensor a moment late (a 1 Hz logger against stale_s = 1 s) is shown, not announced:
        # an event once the state has held CROP_HOLD_S; a loss at once.
        held = state == "lost" or now - self._crop_since >= CROP_HOLD_S - 1e-9
        if state == self._crop_reported or not held:
            return
        self._crop_reported = state
        was_ok = self._crop_ok_once
        self._crop_ok_once |= state == "ok"
        # Sensors come up one by one at start: report changes once all were there, or a loss.
        if state == "lost":
            self.event(text("event.crop_lost", why=_why(self.crop)))
        elif was_ok:
            if state in ("ok", "silent"):
                self.event(text(f"event.crop_{state}"))
            else:
                self.event(text("event.crop_fresh", fresh=fresh, n=n))

    def _hint_unusable_input(self) -> None:
        """Lines that keep coming and never give what the terminal needs are a setting to fix
        (baud rate, the receiver's sentences, the column map): said once per input."""
        nmea, crop = self.nmea.counters, self.ndvi.sensors.counters
        if "gnss" not in self._hinted and not self._gnss_seen:
            lines = sum(v for k, v in nmea.items() if k != "resync")
            if lines >= HINT_LINES:
                self._hinted.add("gnss")
                hint = "event.gnss_no_speed" if nmea["ok"] else "event.gnss_no_decode"
                self.event(text(hint, lines=lines))
        if "crop" not in self._hinted and crop["ok"] == 0:
            bad = sum(v for k, v in crop.items() if k != "stale")
            if bad >= HINT_LINES:
                self._hinted.add("crop")
                self.event(
                    text("event.crop_unusable", lines=bad, last=self.ndvi.sensors.last_error)
                )

    def _snapshot(
        self,
        now: float,
        ndvi_sensors: float | None,
        ndvi: float | None,
        rates: tuple[float, float],
        **site: Any,
    ) -> Snapshot:
        """The loop's state now; `site`: the Snapshot fields of time, outlet and site."""
        live = self.link.ecu_alive
        # The ECU's last frames are history once it is not heard: nothing is shown from them.
        ecu = self.link.ecu if live else EcuView()
        pos = self.tracker.position
        ident = self.link.ecu.ident  # who the ECU is stays known while it is not heard
        return Snapshot(
            t_s=now - (self._t0 if self._t0 is not None else now),
            **ecu_values(ecu.status, ecu.diag, ecu.speeds, ecu.targets),
            gnss_kmh=self.link.command.gnss_kmh,
            ndvi_sensors=ndvi_sensors,
            ndvi=ndvi,
            rate_kg_ha=rates,
            ecu_live=live,
            ecu_link=self.ecu_state,
            ecu_where=self.link.where,
            ecu_ident=None if ident is None else ident_text(ident),
            ecu_can_health=None if ecu.can_health is None else health_text(ecu.can_health),
            ecu_protocol=(
                (ident.protocol_version, terminal_protocol())
                if ident is not None and ident_mismatch(ident)
                else None
            ),
            gnss_link=self._gnss_state,
            crop_link=self._crop_state,
            lat=pos.lat if pos else None,
            lon=pos.lon if pos else None,
            distance_m=self.ndvi.odometer.distance_m,
            counters=self._counters(),
            last_event=self._last_event,
            gnss_lag=self._lag_view(),
            **site,
        )

    def _counters(self) -> dict[str, int]:
        lc = self.link.counters
        # a sentence decoded without a malformed optional field (bad_field) is also "ok"
        nmea_other = ("ok", "resync", "bad_field")
        bad_nmea = sum(v for k, v in self.nmea.counters.items() if k not in nmea_other)
        crop = self.ndvi.sensors.counters
        out = {
            "nmea": self.nmea.counters["ok"],
            "nmea_bad": bad_nmea,
            "crop": crop["ok"],
            "crop_bad": sum(v for k, v in crop.items() if k not in ("ok", "stale")),
            "can_rx": lc.rx_frames,
            "can_bad": lc.rx_foreign + lc.rx_malformed + lc.rx_implausible,
            "cmd_tx": lc.tx_commands,
            "tx_err": lc.tx_errors,
        }
        if self.session is not None:
            out["log_err"] = self.session.errors
        if self.nmea.counters["bad_field"]:
            out["nmea_bad_field"] = self.nmea.counters["bad_field"]
        # The loop's own anomalies (no NDVI, CAN receive errors) only when they happen.
        out.update((k, v) for k, v in self.counters.items() if k != "events" and v)
        # Lines a flooding source lost (the oldest of its bounded queue), per source.
        out.update((f"{k}_dropped", v) for k, v in self.inbox.dropped.items() if v)
        return out

    # ---- events and the transmit tap ----------------------------------------------------------
    def _log_tx(self, msg: can.Message) -> None:
        if self.session is not None:
            self.session.raw("can_tx", self.clock(), (msg.arbitration_id, bytes(msg.data)))

    def _log_ident(self, ident: EcuIdent, t: float) -> None:
        self.log_event(
            t,
            "ecu.ident",
            target=ident.target,
            firmware=ident.firmware_version,
            protocol=ident.protocol_version,
            terminal_protocol=terminal_protocol(),
            transport=ident.transport,
            reset_cause=ident.reset_cause,
            clock_fallback=ident.clock_fallback,
        )

    def log_event(self, t: float, kind: str, **detail: Any) -> None:
        """One event to the session log: `kind` of topdress.log.model.EVENT_KINDS, `detail`
        plain JSON values (docs/log.md lists each kind's)."""
        if self.session is not None:
            self.session.event(LogEvent(t, kind, detail))

    def event(self, message: Text) -> None:
        """Something the operator is told (the console, the display's last event)."""
        self._last_event = message
        self.counters["events"] += 1
        log.info("%s", message)  # English in the program log
        if self._on_event is not None:
            self._on_event(message)


@dataclass
class _Opening:
    """The bus of a changed [can] section, from the moment it starts opening until in use."""

    port: CanPort
    cfg: TerminalConfig
    done: Callable[[str | None], None]
    next: CanLink | None = None  # the link given the parameters there while the old one works
    since: float = 0.0


def _why(source: LineSource) -> str:
    return f"{source.name}: {source.last_error or 'disconnected'}"


def _in_background(stop: Callable[[], None], name: str) -> None:
    """Stop a device the loop no longer uses without waiting for it (a reader thread leaving
    a blocking read, a bus shutting down)."""
    threading.Thread(target=stop, name=name, daemon=True).start()
