"""The Snapshot of the terminal loop's state, built once per tick for the display and the log.

The desk's fields (topdress.terminal.desk.DeskView) are added to it by the loop.
"""

from __future__ import annotations

from typing import Any

from topdress.crop.sensors import CompensatedNdvi
from topdress.terminal.busswitch import BusSwitch
from topdress.terminal.ecuhealth import health_text
from topdress.terminal.ecuview import EcuView, ident_mismatch, ident_text, terminal_protocol
from topdress.terminal.gnssin import GnssIn
from topdress.terminal.gnsslag import LagKeeper
from topdress.terminal.inbox import Inbox
from topdress.terminal.journal import Journal
from topdress.terminal.linkwatch import LinkWatch
from topdress.terminal.proplink import with_ecu
from topdress.view.snapshot import LagView, Snapshot, ecu_values


class SnapshotBuilder:
    """Reads the loop's parts into a Snapshot."""

    def __init__(
        self,
        journal: Journal,
        inbox: Inbox,
        bus: BusSwitch,
        gnss: GnssIn,
        ndvi: CompensatedNdvi,
        watch: LinkWatch,
        lags: LagKeeper,
    ) -> None:
        self._journal = journal
        self._inbox = inbox
        self._bus = bus
        self._gnss = gnss
        self._ndvi = ndvi
        self._watch = watch
        self._lags = lags

    def build(
        self,
        t_s: float,
        ndvi_sensors: float | None,
        ndvi: float | None,
        rates: tuple[float, float],
        lag: LagView | None,
        **site: Any,
    ) -> Snapshot:
        """The loop's state `t_s` after it opened; `lag`: the GNSS lag as the ECU reports it;
        `site`: the Snapshot fields of time, outlet and site."""
        link = self._bus.link
        live = link.ecu_alive
        # The ECU's last frames are history once it is not heard: nothing is shown from them.
        ecu = link.ecu if live else EcuView()
        pos = self._gnss.tracker.position
        ident = link.ecu.ident  # who the ECU is stays known while it is not heard
        tc = self._bus.tc
        if tc is not None:  # an ISOBUS implement: its reports in the ECU's fields, and a
            # topdress ECU's own broadcasts where they say more (terminal.proplink)
            machine = with_ecu(tc.machine_values(link.command.gnss_kmh), ecu)
            live = tc.state == "ok"
        else:
            machine = ecu_values(ecu.status, ecu.diag, ecu.speeds, ecu.targets)
        return Snapshot(
            t_s=t_s,
            **machine,
            gnss_kmh=link.command.gnss_kmh,
            ndvi_sensors=ndvi_sensors,
            ndvi=ndvi,
            rate_kg_ha=rates,
            ecu_live=live,
            ecu_link=self._bus.ecu_state,
            ecu_where=link.where,
            ecu_ident=None if ident is None else ident_text(ident),
            ecu_can_health=None if ecu.can_health is None else health_text(ecu.can_health),
            ecu_protocol=(
                (ident.protocol_version, terminal_protocol())
                if ident is not None and ident_mismatch(ident)
                else None
            ),
            gnss_link=self._watch.gnss_state,
            crop_link=self._watch.crop_state,
            lat=pos.lat if pos else None,
            lon=pos.lon if pos else None,
            distance_m=self._ndvi.odometer.distance_m,
            counters=self.counters(),
            last_event=self._journal.last_event,
            gnss_lag=lag,
            isobus=None if tc is None else tc.view(self._ndvi.lookahead_s),
            **site,
        )

    def counters(self) -> dict[str, int]:
        tc = self._bus.tc
        lc = self._bus.link.counters if tc is None else tc.counters
        nmea = self._gnss.nmea.counters
        # a sentence decoded without a malformed optional field (bad_field) is also "ok"
        nmea_other = ("ok", "resync", "bad_field")
        bad_nmea = sum(v for k, v in nmea.items() if k not in nmea_other)
        crop = self._ndvi.sensors.counters
        out = {
            "nmea": nmea["ok"],
            "nmea_bad": bad_nmea,
            "crop": crop["ok"],
            "crop_bad": sum(v for k, v in crop.items() if k not in ("ok", "stale")),
            "can_rx": lc.rx_frames,  # the topdress ECU's link, or the ISOBUS TC's
            "can_bad": lc.rx_foreign + lc.rx_malformed + lc.rx_implausible,
            "cmd_tx": lc.tx_commands,
            "tx_err": lc.tx_errors,
        }
        session = self._journal.session
        if session is not None:
            out["log_err"] = session.errors
        if self._bus.prop is not None:  # the topdress ECU's private frames on the ISOBUS
            out.update(self._bus.prop.counter_view(self._bus.link.counters))
        if nmea["bad_field"]:
            out["nmea_bad_field"] = nmea["bad_field"]
        # The loop's own anomalies (no NDVI, CAN receive errors) only when they happen.
        out.update((k, v) for k, v in self._journal.counters.items() if k != "events" and v)
        # Lines a flooding source lost (the oldest of its bounded queue), per source.
        out.update((f"{k}_dropped", v) for k, v in self._inbox.dropped.items() if v)
        return out
