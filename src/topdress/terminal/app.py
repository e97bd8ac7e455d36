"""The cab terminal: GNSS and crop lines in, the rate per layer out to the ECU, everything logged.

Sources (GNSS line source, crop line source, the CAN bus) run in their own reader threads and
put `(kind, t, payload)` on one queue; the control loop alone touches the state. It never waits
on a device, only on that queue, with a timeout that keeps its 10 Hz tick:

- an NMEA line: to the GNSS input (terminal.gnssin), which sends a new speed to the ECU;
- a crop line: parsed into the sensor table;
- a CAN frame, or news of the adapter: to the bus switcher (terminal.busswitch) and its link;
- an operator command: to the operator's desk (terminal.desk);
- every tick: the NDVI where the meters are now (sensor mean through the distance queue, driven
  by the ECU's selected speed), the rate per layer from the NDVI model and the maps, the next
  command (terminal.busswitch), the links' states (terminal.linkwatch), the GNSS lag
  (terminal.gnsslag), a fresh `Snapshot` for the display (terminal.snapbuild) with the desk's
  fields, and one state row to the session log.

The loop only dispatches and orders; each part owns its state and is handed the parts it works
with (the settings in force and the journal of events, terminal.journal, are shared by all).
What happens (operator actions, settings, alarms, links lost and back, the ECU's fault word,
calibration results, the GNSS lag the ECU learns) also goes to the session log as events, on
the same clock.

No device is opened on the loop's thread: the CAN adapter (`devices.can.CanPort`) and the serial
ports open, and reopen after a loss, in their own threads; a changed `[can]` section opens its bus
there too while the old one keeps working, and the link moves to it once it is open.
"""

from __future__ import annotations

import gc
import time
from collections import Counter
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import replace
from pathlib import Path
from typing import Any

import can

from topdress.config import TerminalConfig
from topdress.crop.rate import RateModel, build_rate_model, split_layers
from topdress.crop.sensors import CompensatedNdvi
from topdress.devices.can import CanPort
from topdress.devices.lines import LineSource
from topdress.gnss.nmea import NmeaDecoder
from topdress.gnss.tracker import GnssSpeedTracker
from topdress.i18n import Text
from topdress.log.rows import state_row
from topdress.log.session import SessionLog
from topdress.terminal import signals
from topdress.terminal.busswitch import BusSwitch
from topdress.terminal.canlink import CanLink
from topdress.terminal.desk import DeskParts, OperatorDesk
from topdress.terminal.gnssin import GnssIn
from topdress.terminal.gnsslag import LagKeeper
from topdress.terminal.inbox import Inbox
from topdress.terminal.journal import Journal, Settings
from topdress.terminal.lines import Lines
from topdress.terminal.linkwatch import LinkWatch
from topdress.terminal.site import Maps, build_map_guard, build_site_rate
from topdress.terminal.snapbuild import SnapshotBuilder
from topdress.view.commands import CommandResult
from topdress.view.snapshot import TICK_S, Snapshot


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
        self.clock = clock
        self.settings = Settings(cfg)
        self.journal = Journal(session, clock, on_event)
        self.inbox = Inbox()
        self.lines = Lines(gnss, crop, self.inbox)
        where = session.path.parent if session is not None else None
        # The GNSS lag: kept per receiver beside the session logs (in memory without a log).
        self.lags = LagKeeper(self.settings, self.journal, where)
        self.can = BusSwitch(
            bus,
            self.settings,
            self.journal,
            self.inbox,
            self.lags.start_ms,
            lambda params, now: self.lags.again(params, now, self.can.link),
        )
        self.ndvi = CompensatedNdvi(cfg.crop, cfg.lookahead.total_s)
        # The prescription map and boundary files (`run` reads them before any device opens).
        self.site = build_site_rate(cfg, build_rate_model(cfg.rate), maps)
        # How far the machine is from each map: said at the first fix, an alarm when too far.
        guard = build_map_guard(cfg, Maps(self.site.prescription, self.site.boundary))
        self.gnss_in = GnssIn(self.settings, self.journal, self.lines, guard, self.lags)
        self.watch = LinkWatch(
            self.settings, self.journal, self.lines, self.gnss_in, self.ndvi, self.can
        )
        self.picture = SnapshotBuilder(
            self.journal, self.inbox, self.can, self.gnss_in, self.ndvi, self.watch, self.lags
        )
        self.settings.on_change(self._take)
        parts = DeskParts(self.settings, self.journal, self.inbox, self.lines, self.can, self.ndvi)
        self.desk = OperatorDesk(parts, start, config_path)
        self.snapshot = Snapshot()
        self._t0: float | None = None
        self._sc_at: tuple[float, float] | None = None  # the outlet section control last saw

    # ---- the parts, as the loop's callers know them --------------------------------------------
    @property
    def cfg(self) -> TerminalConfig:
        """The configuration in force."""
        return self.settings.cfg

    @property
    def session(self) -> SessionLog | None:
        return self.journal.session

    @property
    def counters(self) -> Counter[str]:
        """The loop's own anomalies (no NDVI, CAN receive errors, GNSS speeds not sent)."""
        return self.journal.counters

    @property
    def link(self) -> CanLink:
        """The CAN link in use."""
        return self.can.link

    @property
    def port(self) -> CanPort:
        """The CAN port in use."""
        return self.can.port

    @property
    def bus(self) -> can.BusABC | None:
        """The python-can bus in use (a changed [can] section moves the link to another; None
        while the adapter is being opened again)."""
        return self.can.port.bus

    @property
    def gnss(self) -> LineSource:
        return self.lines.gnss

    @property
    def crop(self) -> LineSource:
        return self.lines.crop

    @property
    def nmea(self) -> NmeaDecoder:
        return self.gnss_in.nmea

    @property
    def tracker(self) -> GnssSpeedTracker:
        return self.gnss_in.tracker

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

    def _lookahead_s(self) -> float:
        """The look-ahead: `[lookahead]`'s command, meter and air-line times; with an ISOBUS
        implement that gives its setpoint latency (DDI 142), the command time and that."""
        la = self.cfg.lookahead
        tc = self.can.tc
        own = tc.setpoint_latency_s() if tc is not None else None
        if own is None:
            return la.total_s
        return min(la.command_ms / 1000.0 + own, 5.0)

    def _take(self, section: str, new: TerminalConfig) -> None:
        """A changed section, for the loop's own parts (the others registered their own)."""
        if section in ("crop", "lookahead"):
            self.ndvi.retune(new.crop, self._lookahead_s())
        elif section == "rate":
            self.site.retune(new.rate)
        elif section == "gnss":
            self.site.unknown_kg_ha = new.gnss.unknown_kg_ha

    # ---- life cycle ---------------------------------------------------------------------------
    def open(self) -> None:
        """Start the line sources and the parameter push. `run` also starts the CAN port's
        reader; a caller driving `handle`/`tick` itself (virtual time) hands CAN frames in
        directly."""
        now = self.clock()
        self._t0 = now
        self.lines.start()
        self.can.begin(now)
        self.lags.opened(now)
        self.desk.open(now)

    def close(self) -> None:
        """Stop the ECU (a stop command), the readers, and the log; a stop signal arriving
        meanwhile is held until the log is closed (see topdress.terminal.signals)."""
        with signals.deferred():
            self._close()

    def _close(self) -> None:
        self.desk.close()
        self.can.stop_implement(self.clock())
        self.lines.stop()
        self.can.close()
        self.lags.keep(self.clock(), final=True)
        if self.session is not None:
            self.session.close()

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
            self.can.start()
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
            command = self.link.command
            self.gnss_in.on_line(t, payload, self.link, self.ndvi.odometer.distance_m)
            if self.link.command is not command:  # a new GNSS speed
                self.can.on_gnss(t)
        elif kind == "crop":
            self.journal.raw("crop", t, payload.decode("latin-1"))
            reading = self.ndvi.sensors.feed(t, payload)
            if reading is not None:
                self.model.observe(reading.ndvi)
        else:
            self.can.take(kind, t, payload)
        self.link.poll(t)

    # ---- the tick -----------------------------------------------------------------------------
    def tick(self, now: float) -> None:
        """10 Hz: NDVI at the meters, GNSS, rates, command, links, snapshot, state row."""
        link = self.link
        ecu = link.ecu
        v_sel = ecu.speeds.selected_kmh if ecu.speeds is not None and link.ecu_alive else 0.0
        tc = self.can.tc
        if tc is not None:
            # An ISOBUS implement meters on the ground speed it is given; the NDVI queue moves
            # with the GNSS speed, and the look-ahead is the implement's own delay (DDI 142)
            # where its DDOP gives one.
            v_sel = link.command.gnss_kmh or 0.0
            self.ndvi.lookahead_s = self._lookahead_s()
        ndvi_sensors = self.ndvi.sensors.mean_ndvi(now)
        ndvi_meters = self.ndvi.update(now, v_sel)
        # Before the meters reach the first spot sensed, the nearest information is the sensors'.
        ndvi = ndvi_meters if ndvi_meters is not None else ndvi_sensors
        # The boundary at the outlet; the prescription where the outlet will be when the
        # product commanded now lands (speed x the look-ahead, as the NDVI); the NDVI model.
        ahead_m = max(v_sel, 0.0) / 3.6 * self.ndvi.lookahead_s
        at = self.gnss_in.tick(now, link, self.ndvi.odometer.distance_m, ahead_m)
        outlet, target = at.outlet, at.target
        if tc is not None and outlet is not None and outlet.heading_deg is not None:
            here = (outlet.lat, outlet.lon)
            if here != self._sc_at:  # a new position: section control (terminal.tclink)
                self._sc_at = here
                tc.on_position(*here, outlet.heading_deg, v_sel, self.site.boundary, now)
        site = self.site.decide(
            ndvi,
            (outlet.lat, outlet.lon) if outlet is not None else None,
            (target.lat, target.lon) if target is not None else None,
            lost=at.lost,
        )
        if ndvi is None and site.used_ndvi:
            self.counters["no_ndvi_ticks"] += 1
        # The state row's outlet is where what the machine reports was metered: an ISOBUS
        # implement's reports are its DDI 143 old (terminal.tclink).
        mapped = None if outlet is None else (outlet.lat, outlet.lon)
        if tc is not None and mapped is not None:
            mapped = tc.reported_where(now, *mapped)
        cfg = self.cfg
        rates = split_layers(site.total_kg_ha, cfg.rate.split_upper, cfg.machine.layers)
        # No command goes out before the parameters are in force anyway; while they are pushed
        # again (ECU back), a stop here would stop a running ECU for a command period.
        # The operator's state (stopped, paused, manual, a calibration) decides what goes out.
        command = self.desk.rates((rates.upper_kg_ha, rates.lower_kg_ha))
        self.can.poll(now, command)
        # Before the desk's alarms: a link lost is logged ahead of the alarm it raises.
        self.watch.tick(now, at.gnss_kmh)
        lag = self.lags.track(now, self.link)
        snap = self.picture.build(
            now - (self._t0 if self._t0 is not None else now),
            ndvi_sensors,
            ndvi,
            (command[2], command[3]),
            lag,
            utc=self.gnss_in.utc.now(now),
            heading_deg=outlet.heading_deg if outlet is not None else None,
            outlet_lat=mapped[0] if mapped is not None else None,
            outlet_lon=mapped[1] if mapped is not None else None,
            zone=site.zone,
            prescription_kg_ha=site.prescription_kg_ha,
        )
        self.snapshot = replace(snap, **vars(self.desk.after_tick(now, snap, at.off_map)))
        if self.session is not None:
            self.session.state(state_row(now, self.snapshot))
