"""The terminal's link to an ISOBUS implement (`[can] implement = "isobus"`): the terminal is its
Task Controller (topdress.isobus.tcserver, on the C ISOBUS layer) on the CAN port in use.

`TcLink` is what `CanLink` is for the topdress ECU: the loop hands it every frame (`on_frame`)
and, at each tick, the command its desk decided (`poll`); it never reads a clock and never
blocks (the port sends from its own thread). Once a client's pool (DDOP) is active it

- sends the rate of each product the pool describes, to its setpoint DDI: mass per area (DDI 6,
  mg/m^2) or volume per area (DDI 1, mm^3/m^2, through `[isobus] density_kg_l`); the first
  product takes the upper layer's rate, the second the lower's, a single one both; on a change
  (acknowledged) and again every SETPOINT_REFRESH_S (a client that restarted gets it);
- switches the work state (DDI 289), section control (160) and the sections (290) with the
  operator's start and the site's rate; with `[isobus] section_control` each section is also
  off over ground already covered (what the implement reported working, DDI 161) and outside
  the field boundary (geo.sectionctl, decided at each new outlet position: `on_position`);
  with no boundary and nothing covered yet, all sections go with the rate; the ground earlier
  sessions of the field covered (`[isobus] coverage_hours`) is read in a thread at start and
  counts as covered; each switch of the sections commanded is an `isobus.sections` event;
- asks for the actual rates (DDI 7/2), the work state (141), the sections (161) every
  MEASURE_MS and the totals (DDI 81/80) every TOTAL_MS;
- reads the implement's delays from its pool (DDI 142, 143): 142 sets the look-ahead, 143
  puts its reports (the as-applied position, the ground covered) where the outlet was then;
- keeps who is on the bus: every address claim heard, its NAME decoded.

What goes wrong (a pool refused, the client silent, a value refused) becomes an event in the
session log (English) and the operator's words (catalogue messages, topdress.i18n); `problem`
and `state` feed the alarms.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any, Protocol

import can
from pyproj import CRS

from topdress.errors import DeviceError, ProtocolError
from topdress.geo.asapplied import Cover, utm_crs
from topdress.geo.boundary import FieldBoundary
from topdress.geo.sectionctl import (
    EarlierCoverage,
    SectionControl,
    earlier_coverage,
    sections_from_device,
)
from topdress.i18n import Text, text
from topdress.isobus.devicemap import TRIG_CHANGE, TRIG_TIME
from topdress.isobus.node import Frame, name_fields, split_id
from topdress.isobus.tcserver import RESTART_QUIET_US, Client, Device, TcServer, tc_name
from topdress.isobus.workstate import SECTIONS_PER_DDI, condensed_states, condensed_value
from topdress.terminal.ecuview import LinkCounters
from topdress.terminal.journal import Journal, Settings
from topdress.view.snapshot import ControlFunctionView, IsobusView, ProductView

MEASURE_MS = 200  # actual rates, work state and sections: 5 Hz, every other tick
TOTAL_MS = 1000
SETPOINT_REFRESH_S = 1.0
CLAIM_S = 1.0  # an address claim takes 250 ms; none after this long is a loss
TRACK_S = 10.0  # the outlet positions kept: the longest actual-value delay (DDI 143) applied
ADDRESS_CLAIM_PGN = 0xEE00
# DDIs (ISO 11783-11)
SETPOINT_VOLUME_HA, ACTUAL_VOLUME_HA = 1, 2
SETPOINT_MASS_HA, ACTUAL_MASS_HA = 6, 7
TOTAL_VOLUME_L, TOTAL_MASS_KG = 80, 81
ACTUAL_WORK_STATE, SETPOINT_WORK_STATE = 141, 289
SETPOINT_LATENCY, ACTUAL_LATENCY = 142, 143
SECTION_CONTROL_STATE = 160
ACTUAL_CONDENSED, SETPOINT_CONDENSED = 161, 290
PER_HA = 100  # kg/ha -> mg/m^2, and L/ha -> mm^3/m^2
KG_HA_PER_RPM_KG = 600.0  # eq. 4: kg/ha = rpm x kg/rev x 600 / (km/h x m)
# why a section the TC commands is off, beside section control's "covered" and "outside":
# the operator stopped, the rate is zero, or the ECU's parameters are not all in force yet
OPERATOR, RATE_ZERO, PARAMS = "operator", "rate_zero", "params"


class Sender(Protocol):
    """What the link sends on: the CAN port (or a bus in tests)."""

    def send(self, msg: can.Message, timeout: float | None = None) -> None: ...


@dataclass(frozen=True)
class Product:
    """A bin of the pool with a settable rate."""

    element: int
    setpoint_ddi: int  # 6 mass, 1 volume per area
    actual_ddi: int
    total_ddi: int | None  # 81 or 80 where the bin carries it

    @property
    def unit(self) -> str:
        return "kg/ha" if self.setpoint_ddi == SETPOINT_MASS_HA else "L/ha"


def known_ddis(d: Device) -> dict[int, set[int]]:
    """Per element, the DDIs a mapped device is known to carry (its bins, settable and
    condensed process data), for a pool the TC did not get the bytes of."""
    ddis: dict[int, set[int]] = {e: set(v) for e, v in d.bins.items()}
    for element, ddi in d.settable:
        ddis.setdefault(element, set()).add(ddi)
    for ddi, element in d.condensed.items():
        ddis.setdefault(element, set()).add(ddi)
    return ddis


def pool_ddis(d: Device) -> tuple[dict[int, set[int]], dict[int, int]]:
    """Per element, the DDIs its objects carry (its process data and properties, as the
    device's mapping read them from the pool); and the delays (142, 143) wherever the pool
    gives them (an implement names one delay for the machine)."""
    ddis: dict[int, set[int]] = {}
    for element, ddi in (*d.triggers, *d.properties):
        ddis.setdefault(element, set()).add(ddi)
    fixed: dict[int, int] = {}
    for (_, ddi), value in d.properties.items():
        if ddi in (SETPOINT_LATENCY, ACTUAL_LATENCY):
            fixed.setdefault(ddi, value)
    return ddis, fixed


class TcLink:
    """The Task Controller on the CAN port and the one implement it serves."""

    def __init__(
        self,
        port: Sender,
        settings: Settings,
        journal: Journal,
        on_tx: Callable[[can.Message], None] | None = None,
    ) -> None:
        self._port = port
        self._journal = journal
        self._on_tx = on_tx
        self._settings = settings
        # [isobus] as it was when the link was made: a change is saved and in force at the
        # next start (or the next [can] change), never half-taken by a link already serving
        self._cfg = cfg = settings.cfg.isobus
        self.name = tc_name(cfg.tc_identity)
        self.server = TcServer(self.name, cfg.tc_address)
        self.counters = LinkCounters()
        self._t0: float | None = None
        self._quiet_us = 0  # the server's status held back at its start (`carry`)
        self.names: dict[int, int] = {}  # address -> NAME of every claim heard
        self._told = 0  # the server's `told` count up to which its messages were told here
        self._served: tuple[int, Device] | None = None  # the client and pool set up
        self.products: tuple[Product, ...] = ()
        self.sections = 0
        self._ddis: dict[int, set[int]] = {}
        self.latency_ms: dict[int, int] = {}
        self._sent: dict[tuple[int, int], tuple[int, float]] = {}  # value and time, by var
        self.setpoints: tuple[float, ...] = ()  # per product, in its unit
        self.problem: Text | str = ""  # the last thing wrong (a message, or a library's words)
        self.refused = False  # the last pool offered could not be activated
        self.refusal = ""  # why
        self._was: str = "wait"
        self._failing = False
        self._claimed: int | None = None  # the address told
        self._no_address_since: float | None = None
        self._said_no_address = False
        self.connected_once = False  # a client's pool was active once
        self._functions_key: object = None
        self._functions_view: tuple[ControlFunctionView, ...] = ()
        self._sc: SectionControl | None = None  # the implement's section control, once placed
        self.section_on: tuple[bool, ...] | None = None  # what it decided last (None: all)
        self.section_why: tuple[str, ...] = ()  # why each one off is off ("covered", "outside")
        self._logged_sections: tuple[bool, ...] | None = None  # the last logged
        # the UTM zone section control works in: the boundary's, else the first position's
        self._zone: CRS | None = None
        # the field's earlier sessions, read off the loop once the zone is known
        self._earlier: Future[EarlierCoverage] | None = None
        self._earlier_due = (
            self._cfg.section_control
            and self._cfg.coverage_hours > 0.0
            and self._journal.session is not None
        )
        self._covered_before: EarlierCoverage | None = None  # for each SectionControl
        self._carried: tuple[Cover, CRS] | None = None  # covered on the bus before ([can])
        self._track: deque[tuple[float, float, float, float]] = deque()  # t, lat, lon, heading

    def _read_earlier(self, zone: CRS) -> None:
        """The ground earlier sessions of this field covered (`[isobus] coverage_hours`), read
        from the session logs and made into tiles in `zone` in a thread of its own (whole
        sessions: seconds for a long day); the loop takes it once it is there
        (`_take_earlier`)."""
        session = self._journal.session
        self._earlier_due = False
        if session is None:
            return
        hours = self._cfg.coverage_hours
        fut: Future[EarlierCoverage] = Future()
        self._earlier = fut

        def read() -> None:
            try:
                fut.set_result(earlier_coverage(session.path, hours, zone))
            except Exception as exc:  # said by the loop; never a traceback in a thread
                fut.set_exception(exc)

        threading.Thread(target=read, name="tc-coverage", daemon=True).start()

    def carry(self, old: TcLink) -> None:
        """Takes over from the TC link of the bus before (a [can] change makes the link anew).
        The implement it served, if the new bus is the same, knows nothing of the change:
        this TC keeps its status back past the client timeout, so that the implement takes
        it for lost and connects again (else it would go on at its last rate, never set
        again). And this session's ground: the old section control's coverage, the zone,
        the earlier sessions' ground or their reading under way; taken by this link's
        section control once placed."""
        c = old._client()
        if c is not None:  # on the same bus it would go on taking this TC for the old one
            self._quiet_us = RESTART_QUIET_US
            self._say(text("tc.link.restarted", client=c.address, s=RESTART_QUIET_US // 10**6))
        self._zone = old._zone
        if self._earlier_due:  # this link's [isobus] counts earlier sessions too
            self._earlier, self._earlier_due = old._earlier, old._earlier_due
            self._covered_before = old._covered_before
        if old._sc is not None:
            cover, crs = old._sc.ground()
            self._carried = None if crs is None else (cover, crs)
        else:
            self._carried = old._carried

    def _seed(self, sc: SectionControl) -> None:
        """The earlier sessions' ground into a section control: their tiles, made in the
        reading thread in its zone (taking them: a few ms here, never a projection)."""
        got = self._covered_before
        if got is not None and got.cover is not None and got.crs is not None:
            self._give(sc, got.cover, got.crs)

    def _give(self, sc: SectionControl, cover: Cover, crs: CRS) -> None:
        if not sc.add_cover(cover, crs):  # both in self._zone: not met
            why = f"tiles in {crs.to_string()}, section control in {sc.crs}"
            self._tell(text("tc.link.coverage_error", why=why))

    @property
    def section_control(self) -> SectionControl | None:
        """The served implement's section control, once placed (its coverage, its decisions)."""
        return self._sc

    @property
    def coverage_read(self) -> bool:
        """The earlier sessions' coverage was taken (or there is none to read)."""
        return not self._earlier_due and self._earlier is None

    def _take_earlier(self) -> None:
        fut = self._earlier
        if fut is None or not fut.done():
            return
        self._earlier = None
        now = self._journal.clock()
        try:
            got = fut.result()
        except Exception as exc:  # the logs unreadable as a whole: coverage starts empty
            self._tell(text("tc.link.coverage_error", why=str(exc)))
            return
        self._covered_before = got
        if self._sc is not None:
            self._seed(self._sc)
        self._journal.log_event(
            now,
            "isobus.coverage",
            sessions=list(got.sessions),
            swaths=len(got.swaths),
            skipped=list(got.skipped),
            zone=got.crs.to_string() if got.crs is not None else None,
        )
        # files that could not be read are in that event only: told at every start they would
        # keep a damaged or foreign file of the log directory on the operator's screen
        if got.sessions:
            self._say(text("tc.link.coverage", n=len(got.sessions), swaths=len(got.swaths)))

    # ---- time and frames --------------------------------------------------------------------
    def _us(self, now: float) -> int:
        if self._t0 is None:
            self._t0 = now
            self.server.start(1, self._quiet_us)
        return round((now - self._t0) * 1e6) + 1

    def on_frame(self, msg: can.Message, now: float) -> None:
        """One frame of the bus: every frame goes to the TC (it keeps only what is its own)."""
        self.counters.rx_frames += 1
        if not msg.is_extended_id or msg.is_error_frame or msg.is_remote_frame:
            self.counters.rx_foreign += 1
            return
        data = bytes(msg.data)
        _, pgn, sa, _ = split_id(msg.arbitration_id)
        if sa == self.server.address and pgn != ADDRESS_CLAIM_PGN:
            # our own frame (udp_multicast echoes it) or a usurper's: only a claim of our
            # address matters (the C claim defends it)
            return
        if pgn == ADDRESS_CLAIM_PGN and len(data) == 8:
            name = int.from_bytes(data, "little")
            # a NAME claims one address: where it was before, it is no more (cannot claim: none)
            self.names = {a: n for a, n in self.names.items() if n != name}
            if sa < 0xFE:
                self.names[sa] = name
        self._step(now, [Frame(msg.arbitration_id, data)])

    def _step(self, now: float, frames: list[Frame]) -> None:
        try:
            out = self.server.step(self._us(now), frames)
        except ProtocolError as exc:  # a frame the C layer refuses: counted, never raised
            self.counters.rx_malformed += 1
            self._tell(text("tc.link.frame_refused", why=str(exc)))
            return
        for f in out:
            self._send(can.Message(arbitration_id=f.can_id, data=f.data, is_extended_id=True))
        self._watch_address(now)
        server = self.server
        new = min(server.told - self._told, len(server.messages))
        self._told = server.told
        for what in server.messages[len(server.messages) - new :]:
            self._tell(what)

    def _send(self, msg: can.Message) -> None:
        try:
            self._port.send(msg, timeout=0.01)
        except DeviceError:
            self.counters.tx_errors += 1  # no adapter open: its loss is an event of its own
            return
        except (can.CanError, OSError) as exc:
            self.counters.tx_errors += 1
            if not self._failing:
                self._failing = True
                self._tell(text("tc.link.send_failed", why=str(exc)))
            return
        self._failing = False
        if self._on_tx is not None:
            self._on_tx(msg)

    def _tell(self, what: Text | str) -> None:
        """Something wrong: to the operator (in the language in force), the session log (in
        English), and `problem`."""
        self.problem = what
        self._journal.event(text("event.isobus", what=what))
        self._journal.log_event(self._journal.clock(), "isobus.problem", what=str(what))

    def _watch_address(self, now: float) -> None:
        """The TC's address: claimed, taken by a control function with a higher-priority NAME
        (another TC on the bus: the TC claims a fallback address, which takes CLAIM_S), or
        none left (no address for longer than that)."""
        address, was = self.server.address, self._claimed
        if address is None:
            if self._no_address_since is None:
                self._no_address_since = now
            elif now - self._no_address_since > CLAIM_S and not self._said_no_address:
                self._said_no_address = True
                self._tell(text("tc.link.no_address"))
            return
        self._no_address_since = None
        self._said_no_address = False
        if address == was:
            return
        self._claimed = address
        if was is None:
            self._say(text("tc.link.at", address=address))
        else:
            self._tell(text("tc.link.moved", old=was, new=address))

    def _say(self, what: Text) -> None:
        self._journal.event(text("event.isobus", what=what))

    # ---- the tick ---------------------------------------------------------------------------
    def poll(self, now: float, command: tuple[bool, float, float, float], held: str = "") -> None:
        """The tick's turn: the TC's own work, then the command (start, fan, upper and lower
        kg/ha) as setpoints to the implement served; `held`: why the command is a stop the
        operator did not give (PARAMS), for the session log ("": it is the operator's)."""
        self._step(now, [])
        c = self._client()
        self._watch_state(now, c)
        if c is None or c.device is None:
            return
        if self._served is None or self._served[0] != c.address or self._served[1] is not c.device:
            self._connect(c, now)
        self._command(c, now, command, held)
        self._step(now, [])  # what was set goes out this tick

    def _client(self) -> Client | None:
        c = self.server.client
        return c if c is not None and c.active and not c.lost else None

    @property
    def state(self) -> str:
        """ok (a client's pool is active), lost (it went silent), refused (its pool could not
        be activated), wait (none yet)."""
        c = self.server.client
        if c is not None and c.active and not c.lost:
            return "ok"
        if c is not None and c.lost and c.device is not None:
            return "lost"
        return "refused" if self.refused else "wait"

    def _watch_state(self, now: float, c: Client | None) -> None:
        sc = self.server.client
        if sc is not None and sc.device is None and sc.pool is not None and not self.refused:
            self.refused = True  # its pool failed to parse or map: the TC refuses to activate
            self.refusal = sc.pool_error  # what is wrong with it, for the operator's alarm
        elif sc is not None and sc.active:
            self.refused = False
        state = self.state
        if state == self._was:
            return
        j = self._journal
        if state == "ok" and sc is not None and sc.device is not None:
            j.log_event(now, "isobus.connected", address=sc.address, device=sc.device.designator)
        elif state == "lost":  # logged as the ECU link's loss (terminal.linkwatch)
            self._served = None  # a client back is set up again
        elif state == "refused":
            j.log_event(now, "isobus.refused", why=self.refusal)
        self._was = state

    def _connect(self, c: Client, now: float) -> None:
        """A pool newly active: its products, sections, delays; the measurements asked for."""
        assert c.device is not None
        self._served = (c.address, c.device)
        self._logged_sections = None  # each connection's first sections are logged
        self.connected_once = True
        self._sent.clear()
        if self._sc is not None and self._sc.sections != sections_from_device(c.device):
            self._sc = None  # another implement: its own sections and coverage
        self.section_on = None
        if c.pool is not None:
            self._ddis, self.latency_ms = pool_ddis(c.device)
        else:  # a pool the TC had stored: what its mapping kept (no delays)
            self._ddis, self.latency_ms = known_ddis(c.device), {}
        settable = c.device.settable
        products = []
        for element in sorted(self._ddis):
            ddis = self._ddis[element]
            if (element, SETPOINT_MASS_HA) in settable:
                total = TOTAL_MASS_KG if TOTAL_MASS_KG in ddis else None
                products.append(Product(element, SETPOINT_MASS_HA, ACTUAL_MASS_HA, total))
            elif (element, SETPOINT_VOLUME_HA) in settable:
                total = TOTAL_VOLUME_L if TOTAL_VOLUME_L in ddis else None
                products.append(Product(element, SETPOINT_VOLUME_HA, ACTUAL_VOLUME_HA, total))
        self.products = tuple(products)
        self.setpoints = tuple(0.0 for _ in products)
        self.sections = len(c.device.sections)
        for p in products:
            self._measure(p.element, p.actual_ddi, MEASURE_MS)
            if p.total_ddi is not None:
                self._measure(p.element, p.total_ddi, TOTAL_MS)
        for ddi in (ACTUAL_WORK_STATE, ACTUAL_CONDENSED):
            for element in self._carrying(ddi):
                self._measure(element, ddi, MEASURE_MS)
        units: Text = text("tc.link.none")
        for i, p in enumerate(products):
            one = text("tc.link.product", unit=p.unit, element=p.element)
            units = one if i == 0 else text("tc.and", a=units, b=one)
        self._say(
            text("tc.link.implement", device=c.device.designator, address=c.address,
                 n=len(products), units=units, sections=self.sections)
        )  # fmt: skip
        if not products:
            self._tell(text("tc.link.no_rate", device=c.device.designator))
        self._journal.log_event(
            now,
            "isobus.implement",
            address=c.address,
            device=c.device.designator,
            name=f"{self.names.get(c.address, 0):016X}",
            products=[f"{p.element}:{p.unit}" for p in products],
            sections=self.sections,
            setpoint_latency_ms=self.latency_ms.get(SETPOINT_LATENCY),
            actual_latency_ms=self.latency_ms.get(ACTUAL_LATENCY),
        )

    def _carrying(self, ddi: int) -> list[int]:
        return [e for e, ddis in sorted(self._ddis.items()) if ddi in ddis]

    def _measure(self, element: int, ddi: int, ms: int) -> None:
        """Ask for `ddi` every `ms`, or on change where the pool offers no time trigger for it
        (a measurement command the pool does not offer is refused by the server)."""
        c = self.server.client
        device = None if c is None else c.device
        if device is None or ddi not in self._ddis.get(element, ()):
            return
        if device.measured(element, ddi, TRIG_TIME):
            self.server.measure_every(element, ddi, ms)
        elif device.measured(element, ddi, TRIG_CHANGE):
            self.server.measure_on_change(element, ddi)

    def _command(
        self, c: Client, now: float, command: tuple[bool, float, float, float], held: str = ""
    ) -> None:
        start, _, upper, lower = command
        layers = (upper, lower)
        n = len(self.products)
        rates = [0.0] * n
        if start and n == 1:
            rates[0] = upper + lower
        elif start:
            rates[: min(n, 2)] = layers[: min(n, 2)]
        density = self._cfg.density_kg_l
        self.setpoints = tuple(
            r if p.setpoint_ddi == SETPOINT_MASS_HA else r / density
            for p, r in zip(self.products, rates, strict=True)
        )
        working = start and any(r > 0.0 for r in rates)
        assert c.device is not None
        for p, value in zip(self.products, self.setpoints, strict=True):
            self._set(c, now, p.element, p.setpoint_ddi, round(value * PER_HA))
        for element in self._carrying(SECTION_CONTROL_STATE):
            self._set(c, now, element, SECTION_CONTROL_STATE, 1)  # automatic: the TC switches
        for element in self._carrying(SETPOINT_WORK_STATE):
            self._set(c, now, element, SETPOINT_WORK_STATE, int(working))
        chosen = self.section_on
        n = min(self.sections, SECTIONS_PER_DDI)  # sections 17 and up are not switched
        on: list[bool | None] = [working and (chosen is None or chosen[i]) for i in range(n)]
        for element in self._carrying(SETPOINT_CONDENSED):
            self._set(c, now, element, SETPOINT_CONDENSED, condensed_value(on))
        if self._carrying(SETPOINT_CONDENSED):
            why = held or (OPERATOR if not start else RATE_ZERO if not working else "")
            self._log_sections(now, on, why)

    def _log_sections(self, now: float, on: list[bool | None], all_off: str) -> None:
        """The sections the TC commands, and why each one off is off, to the session log when
        one switches (`isobus.sections`): the operator stopped, the rate is zero, or section
        control put it off (covered, outside the field), or the topdress ECU's parameters are
        not all in force yet (the stop held)."""
        decided = self.section_why if self.section_on is not None else ()
        reasons = tuple(
            "" if o else all_off or (decided[i] if i < len(decided) else "")
            for i, o in enumerate(on)
        )
        state = tuple(bool(o) for o in on)
        if state == self._logged_sections:  # a reason alone changing is no new decision
            return
        self._logged_sections = state
        self._journal.log_event(now, "isobus.sections", on=list(state), why=list(reasons))

    def on_position(
        self,
        lat: float,
        lon: float,
        heading_deg: float,
        speed_kmh: float,
        boundary: FieldBoundary | None,
        now: float,
    ) -> None:
        """A new outlet position (the device reference point) at `now`: the ground the
        sections the implement reports working passed since the last one is covered (where
        the machine was its DDI 143 ago: what it reports now is what was then), then each
        section's setpoint is decided for the ground just ahead of it, past its delay (DDI
        142)."""
        track = self._track
        track.append((now, lat, lon, heading_deg))
        while track and track[0][0] < now - TRACK_S:
            track.popleft()
        if self._zone is None:  # the earlier sessions' tiles are made in the zone worked in
            self._zone = boundary.crs if boundary is not None else utm_crs(lat, lon)
            if self._earlier_due:
                self._read_earlier(self._zone)
        c = self._client()
        if not self._cfg.section_control or c is None or c.device is None:
            self.section_on = None
            return
        if self._sc is None:
            sections = sections_from_device(c.device)
            if not sections or any(s.width_m <= 0.0 for s in sections):
                return  # a pool without section widths: all sections with the rate
            cfg = self._cfg
            self._sc = SectionControl(
                sections,
                boundary,
                off_pct=cfg.overlap_pct,
                look_m=cfg.section_look_m,
                crs=self._zone,
            )
            if self._covered_before is not None:
                self._seed(self._sc)
            if self._carried is not None:  # this session's, from the bus before
                self._give(self._sc, *self._carried)
        self._take_earlier()
        reported = self._sections()
        if reported:
            was = self._where(now - self.actual_latency_s())
            self._sc.cover(*(was or (lat, lon, heading_deg)), list(reported))
        lead_m = max(speed_kmh, 0.0) / 3.6 * self.latency_ms.get(SETPOINT_LATENCY, 0) / 1000
        self.section_on = tuple(self._sc.decide(lat, lon, heading_deg, lead_m))
        self.section_why = self._sc.why

    def actual_latency_s(self) -> float:
        """The implement's actual-value delay (DDI 143: from the physical value to its report),
        0 when its pool gives none; at most TRACK_S."""
        ms = self.latency_ms.get(ACTUAL_LATENCY) if self.state == "ok" else None
        return 0.0 if ms is None else min(max(ms, 0) / 1000.0, TRACK_S)

    def _where(self, t: float) -> tuple[float, float, float] | None:
        """Where the outlet was at `t` (lat, lon, heading), between the two positions around it;
        the oldest kept when `t` is before them; None before any."""
        later: tuple[float, float, float, float] | None = None
        for t0, lat, lon, heading in reversed(self._track):  # the newest first: t is near
            if t0 <= t:
                if later is None or later[0] <= t0:
                    return lat, lon, heading
                f = (t - t0) / (later[0] - t0)
                return (lat + f * (later[1] - lat), lon + f * (later[2] - lon),
                        heading if f < 0.5 else later[3])  # fmt: skip
            later = (t0, lat, lon, heading)
        return None if later is None else later[1:]

    def reported_where(self, now: float, lat: float, lon: float) -> tuple[float, float]:
        """Where the implement's reports at `now` belong (the as-applied map's point): the outlet
        its DDI 143 ago; the outlet now (`lat`, `lon`) without a delay."""
        delay = self.actual_latency_s()
        was = self._where(now - delay) if delay > 0.0 else None
        return (lat, lon) if was is None else (was[0], was[1])

    def _set(self, c: Client, now: float, element: int, ddi: int, value: int) -> None:
        """Set a value on a change (acknowledged) or after SETPOINT_REFRESH_S (not)."""
        assert c.device is not None
        if (element, ddi) not in c.device.settable:
            return
        last = self._sent.get((element, ddi))
        if last is not None and last[0] == value and now - last[1] < SETPOINT_REFRESH_S:
            return
        try:
            self.server.set_value(element, ddi, value, ack=last is None or last[0] != value)
        except ProtocolError as exc:  # out of the DDI's range: said once per value
            if last is None or last[0] != value:
                self._tell(str(exc))
            self._sent[(element, ddi)] = (value, now)
            return
        self.counters.tx_commands += 1
        self._sent[(element, ddi)] = (value, now)

    def send_now(self, now: float) -> None:
        """The rates in force to the implement at once, off the tick (a new GNSS fix with
        `send_on_gnss`: the setpoints leave within the fix's handling, as PcCommand does)."""
        c = self._client()
        if c is None or self._served is None or self._served[1] is not c.device:
            return  # no client, or its pool not set up yet (the next tick does)
        for p, value in zip(self.products, self.setpoints, strict=True):
            v = round(value * PER_HA)
            try:
                self.server.set_value(p.element, p.setpoint_ddi, v, ack=False)
            except ProtocolError:
                continue  # told when it was decided (`_set`)
            self.counters.tx_commands += 1
            self._sent[(p.element, p.setpoint_ddi)] = (v, now)
        self._step(now, [])

    def send_stop(self, now: float) -> None:
        """The terminal closes: every rate 0 and the work state off, sent now; the totals the
        implement reported last go to the session log (`isobus.totals`)."""
        c = self._client()
        if c is not None and c.device is not None:
            self._command(c, now, (False, 0.0, 0.0, 0.0))
            self._step(now, [])
        reported = [p for p in self.view(0.0).products if p.total is not None]
        if reported:
            self._journal.log_event(
                now,
                "isobus.totals",
                elements=[p.element for p in reported],
                totals=[p.total for p in reported],
                units=["kg" if p.setpoint_ddi == SETPOINT_MASS_HA else "L" for p in reported],
            )

    # ---- what the implement reports ---------------------------------------------------------
    def _value(self, element: int, ddi: int) -> int | None:
        c = self.server.client
        return None if c is None else c.values.get((element, ddi))

    def view(self, lookahead_s: float) -> IsobusView:
        c = self.server.client
        products = []
        for p, sp in zip(self.products, self.setpoints, strict=True):
            actual = self._value(p.element, p.actual_ddi)
            total = None if p.total_ddi is None else self._value(p.element, p.total_ddi)
            products.append(
                ProductView(
                    p.element,
                    p.setpoint_ddi,
                    p.unit,
                    sp,
                    None if actual is None else actual / PER_HA,
                    None if total is None else float(total),
                )
            )
        return IsobusView(
            tc_address=self.server.address,
            state=self.state,
            implement_address=None if c is None else c.address,
            implement="" if c is None or c.device is None else c.device.designator,
            products=tuple(products),
            sections=self._sections(),
            work_state=self._work_state(),
            setpoint_latency_ms=self.latency_ms.get(SETPOINT_LATENCY),
            actual_latency_ms=self.latency_ms.get(ACTUAL_LATENCY),
            lookahead_s=lookahead_s,
            functions=self._functions(),
            problem=self.refusal if self.state == "refused" else self.problem,
        )

    def _sections(self) -> tuple[bool, ...]:
        for element in self._carrying(ACTUAL_CONDENSED):
            v = self._value(element, ACTUAL_CONDENSED)
            if v is not None:
                return tuple(s is True for s in condensed_states(v, self.sections))
        return ()

    def _work_state(self) -> bool | None:
        for element in self._carrying(ACTUAL_WORK_STATE):
            v = self._value(element, ACTUAL_WORK_STATE)
            if v is not None:
                return v == 1
        return None

    def _functions(self) -> tuple[ControlFunctionView, ...]:
        """Every control function heard, NAMEs decoded (again only when one changed)."""
        names = dict(self.names)
        if self.server.address is not None:  # its own claim is not heard back
            names[self.server.address] = self.name
        key = tuple(sorted(names.items()))
        if key != self._functions_key:
            self._functions_key = key
            self._functions_view = tuple(_decode(a, n) for a, n in key)
        return self._functions_view

    def setpoint_latency_s(self) -> float | None:
        """The implement's own delay from setpoint to product applied (DDI 142), if it gives one."""
        ms = self.latency_ms.get(SETPOINT_LATENCY) if self.state == "ok" else None
        return None if ms is None else max(ms, 0) / 1000.0

    def machine_values(self, gnss_kmh: float | None) -> dict[str, Any]:
        """The Snapshot's machine fields (those the ECU's frames give for the topdress ECU):
        the speed is the GNSS's; the actual and set rates become the metering speeds they mean
        for `[machine]` (eq. 4, kg/rev and width), so the counters, the off-rate alarm, the state
        row, the summary and the as-applied maps read the implement as they read the ECU."""
        live = self.state == "ok"
        v = gnss_kmh if gnss_kmh is not None and live else 0.0
        actual = [0.0, 0.0]
        target = [0.0, 0.0]
        density = self._cfg.density_kg_l
        for i, (p, sp) in enumerate(zip(self.products[:2], self.setpoints, strict=False)):
            k = 1.0 if p.setpoint_ddi == SETPOINT_MASS_HA else density
            a = self._value(p.element, p.actual_ddi)
            actual[i] = 0.0 if a is None else a / PER_HA * k
            target[i] = sp * k
        m = self._settings.cfg.machine
        kg_rev = (m.kg_per_rev_upper, m.kg_per_rev_lower)
        per = v * m.width_m / KG_HA_PER_RPM_KG
        work = self._work_state()
        return dict(
            running=live and (work if work is not None else any(a > 0 for a in actual)),
            source="gnss" if live else "none",
            v_kmh=v,
            v_wheel_kmh=0.0,
            v_gnss_kmh=gnss_kmh if live else None,
            cv_pct=None,
            uniform=False,
            target_rpm=(target[0] * per / kg_rev[0], target[1] * per / kg_rev[1]),
            meter_rpm=(actual[0] * per / kg_rev[0], actual[1] * per / kg_rev[1]),
            fan_rpm=(0.0, 0.0),
            faults=0,
        )


def _decode(address: int, name: int) -> ControlFunctionView:
    """A NAME's fields; what its function means is the display's to say (display/isobus_names)."""
    f = name_fields(name)
    return ControlFunctionView(
        address,
        name,
        f["function"],
        f["device_class"],
        f["industry_group"],
        f["manufacturer_code"],
        f["identity_number"],
    )
