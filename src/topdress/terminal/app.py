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
calibration results) also goes to the session log as events (`log_event`), on the same clock.

GNSS lost (port vanished, no valid fix, stale speed) is forwarded as "not available", so the
ECU falls back to the wheel.
"""

from __future__ import annotations

import gc
import logging
import threading
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
from topdress.devices.lines import LineSource, open_line_source
from topdress.geo.outlet import OutletTracker
from topdress.gnss.nmea import NmeaDecoder
from topdress.gnss.tracker import GnssSpeedTracker
from topdress.gnss.utc import UtcClock
from topdress.i18n import Text, text
from topdress.log.model import LogEvent
from topdress.log.rows import state_row
from topdress.log.session import SessionLog
from topdress.protocol import EcuIdent, fault_names, protocol_version
from topdress.terminal import signals
from topdress.terminal.canlink import CanLink, EcuView, ident_mismatch, ident_text
from topdress.terminal.desk import OperatorDesk
from topdress.terminal.inbox import Inbox
from topdress.terminal.site import Maps, build_site_rate
from topdress.view.commands import RUNNING, CommandResult
from topdress.view.links import link_state
from topdress.view.snapshot import TICK_S, Snapshot, ecu_values

log = logging.getLogger(__name__)

CROP_HOLD_S = 0.5  # a crop sensor state must hold this long to be an event
#: The states of each link that are a loss (an event when entered, another when left).
LOST_STATES = {"ecu": ("lost",), "gnss": ("lost", "no fix"), "crop": ("lost", "silent")}
HINT_LINES = 20  # unusable lines in a row from one input before the operator is told why
_CAN_POLL_S = 0.1  # how long the CAN reader blocks in recv() before checking for stop


class Terminal:
    """The terminal's control loop over its three sources and the session log."""

    def __init__(
        self,
        cfg: TerminalConfig,
        gnss: LineSource,
        crop: LineSource,
        bus: can.BusABC,
        session: SessionLog | None = None,
        clock: Callable[[], float] = time.monotonic,
        start: bool = True,
        on_event: Callable[[Text], None] | None = None,
        config_path: Path | None = None,
        maps: Maps | None = None,
    ) -> None:
        """`start`: the meters start at once (headless); else at the operator's Start.
        `config_path`: where settings changed while running are saved (None: not saved).
        `maps`: the prescription and boundary loaded already (None: loaded here)."""
        self.cfg = cfg
        self.gnss = gnss
        self.crop = crop
        self.session = session
        self.clock = clock
        self._on_event = on_event
        self.inbox = Inbox()
        self.link = CanLink(
            bus,
            cfg.can,
            fan_rpm=cfg.machine.fan_rpm,
            on_tx=self._log_tx,
            on_event=self.event,
            on_ident=self._log_ident,
        )
        self.nmea = NmeaDecoder()
        self.tracker = GnssSpeedTracker(cfg.gnss.rmc_timeout_s, cfg.gnss.stale_s)
        self.ndvi = CompensatedNdvi(cfg.crop, cfg.lookahead.total_s)
        # The prescription map and boundary files (`run` reads them before any device opens).
        self.site = build_site_rate(cfg, build_rate_model(cfg.rate), maps)
        self.utc = UtcClock()
        self.outlet = OutletTracker(cfg.machine.outlet_along_m, cfg.machine.outlet_across_m)
        self.counters: Counter[str] = Counter()
        self.snapshot = Snapshot()
        self._t0: float | None = None
        self._gnss_state = "wait"
        self._gnss_seen = False
        self._crop_state = self._crop_reported = "wait"
        self._crop_since = 0.0
        self._can_failing = False
        self._hinted: set[str] = set()
        self._crop_ok_once = False
        self._last_event: Text | None = None
        self._lost_since: dict[str, float] = {}  # link -> when it was lost
        self._faults = 0  # the ECU's fault word as last heard
        self._stop = threading.Event()
        self._can_thread: threading.Thread | None = None
        self.desk = OperatorDesk(self, start, config_path)

    @property
    def bus(self) -> can.BusABC:
        """The CAN bus in use (a changed [can] section moves the link to another)."""
        return self.link.bus

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
        """Open the device of a changed [gnss], [crop] or [can] section in place of the one in
        use; DeviceError when it cannot be opened (the old one stays)."""
        if section == "can":
            self.link.reopen(new.can, new.ecu_params(), now)
            return
        kind = "nmea" if section == "gnss" else "crop"
        source = open_line_source(new.gnss if section == "gnss" else new.crop)
        if section == "gnss":
            self.gnss.stop()
            self.gnss = source
        else:
            self.crop.stop()
            self.crop = source
        source.start(lambda t, line: self.inbox.put((kind, t, line)))

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
        """Start the line sources and the parameter push. `run` also starts the CAN reader;
        a caller driving `handle`/`tick` itself (virtual time) hands CAN frames in directly."""
        now = self.clock()
        self._t0 = now
        self.gnss.start(lambda t, line: self.inbox.put(("nmea", t, line)))
        self.crop.start(lambda t, line: self.inbox.put(("crop", t, line)))
        self.link.begin(self.cfg.ecu_params(), now)
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
        self._stop.set()
        self.gnss.stop()
        self.crop.stop()
        if self._can_thread is not None:
            self._can_thread.join(timeout=2.0)
        if self.session is not None:
            self.session.close()

    def _can_reader(self) -> None:
        while not self._stop.is_set():
            try:
                msg = self.link.bus.recv(timeout=_CAN_POLL_S)
            except (can.CanError, OSError) as exc:
                self.inbox.put(("can_error", self.clock(), str(exc)))
                self._stop.wait(0.5)
                continue
            if msg is not None:
                self.inbox.put(("can", self.clock(), msg))

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
            self._can_thread = threading.Thread(target=self._can_reader, name="can-rx", daemon=True)
            self._can_thread.start()
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
            if not self._can_failing:  # once per failure spell (the reader retries every 0.5 s)
                self._can_failing = True
                self.event(text("event.can_rx_error", error=str(payload)))
        self.link.poll(t)

    def _on_nmea(self, t: float, line: bytes) -> None:
        if self.session is not None:
            self.session.raw("nmea", t, line.decode("latin-1"))
        fix = self.nmea.decode(line)
        if not fix.ok:
            return
        if fix.fix_valid:
            self.utc.on_fix(t, fix.utc)
            self.outlet.on_fix(
                fix.lat, fix.lon, fix.course_deg, fix.speed_kmh, self.ndvi.odometer.distance_m
            )
        if self.tracker.update(t, fix) is not None:
            self._gnss_seen = True
            self.link.set_gnss(self.tracker.current(t, self.gnss.connected), t)
            self.link.send_gnss_time(self.tracker.current(t, self.gnss.connected), 0.0)

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
        self.snapshot = replace(snap, **vars(self.desk.after_tick(now, snap)))
        if self.session is not None:
            self.session.state(state_row(now, self.snapshot))

    def _track_links(self, now: float) -> None:
        states = {"ecu": self.link.state, "gnss": self._gnss_state, "crop": self._crop_reported}
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
            ecu_link=self.link.state,
            ecu_where=self.link.where,
            ecu_ident=None if ident is None else ident_text(ident),
            ecu_protocol=(
                (ident.protocol_version, "{}.{}".format(*protocol_version()))
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
            terminal_protocol="{}.{}".format(*protocol_version()),
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


def _why(source: LineSource) -> str:
    return f"{source.name}: {source.last_error or 'disconnected'}"
