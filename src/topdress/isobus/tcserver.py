"""The cab terminal as an ISOBUS Task Controller (ISO 11783-10 version 4, TC-BAS, TC-GEO with
position-based control, TC-SC): claims its address with a TC NAME (the C layer's claim), sends
the TC status every 2 s, answers the client's version and label requests (with the labels of a
pool kept from an earlier connection, see `poolstore`), takes the device description (DDOP)
over TP/ETP (the C layer's transport), parses and maps it (`devicemap`), activates it or
refuses it with the error named, then sets values (acknowledges awaited) and asks for
measurements by time, distance, threshold or change as the pool offers them. Faults (a second
client, a second TC, a flood, nonsense process data, a client gone or re-addressed) are counted
and said once in `errors`, never raised. Domain code: frames in, frames out, time passed in;
no UI."""

from __future__ import annotations

import logging
import struct
from collections import Counter
from dataclasses import dataclass, field

from topdress.errors import ProtocolError
from topdress.i18n import Text, text
from topdress.isobus.devicemap import (
    ACTUAL_CONDENSED,
    ACTUAL_MASS_HA,
    ACTUAL_WORK_STATE,
    MAX_POOL_BYTES,
    SETPOINT_CONDENSED,
    SETPOINT_MASS_HA,
    SETPOINT_VOLUME_HA,
    SETPOINT_WORK_STATE,
    TRIG_CHANGE,
    TRIG_DISTANCE,
    TRIG_THRESHOLD,
    TRIG_TIME,
    Device,
    map_device,
)
from topdress.isobus.node import ClaimNode, Frame, TpEndpoint, name_fields, name_of, split_id
from topdress.isobus.poolstore import PoolStore
from topdress.isobus.workstate import condensed_states, condensed_value

__all__ = [
    "ACTUAL_CONDENSED",
    "ACTUAL_MASS_HA",
    "ACTUAL_WORK_STATE",
    "RESTART_QUIET_US",
    "SETPOINT_CONDENSED",
    "SETPOINT_MASS_HA",
    "SETPOINT_WORK_STATE",
    "Client",
    "Device",
    "TcServer",
    "is_tc",
    "map_device",
    "pd_frame",
    "pdack_texts",
    "tc_name",
]  # fmt: skip

_log = logging.getLogger(__name__)

PD_PGN = 0xCB00
ACK_PGN = 0xE800
CLAIM_PGN = 0xEE00
REQUEST_PGN = 0xEA00
TC_ADDRESS = 0xF7
TC_FUNCTION = 130
STATUS_PERIOD_US = 2_000_000
CLIENT_TIMEOUT_US = 6_000_000  # three missed 2 s task messages (ISO 11783-10 client timeout)
# silent this long, a TC started anew is lost to every client (6 s) and its next status is
# a new TC to them
RESTART_QUIET_US = CLIENT_TIMEOUT_US + STATUS_PERIOD_US
PDACK_TIMEOUT_US = 1_000_000  # a Set Value and Acknowledge unanswered this long is reported
FLOOD_PER_S = 200  # process-data messages a second from one address; more are dropped
KEEP_PDACKS = 256  # the last acknowledges kept per client
KEEP_ERRORS = 200  # the last error lines kept
KEEP_SAID = 1024  # faults said once; past this many kinds, further new ones are only counted

# process-data commands (low nibble of byte 0)
TECH, DEVICE, REQUEST, VALUE, MEAS_TIME, MEAS_DISTANCE = 0, 1, 2, 3, 4, 5
MEAS_MIN, MEAS_MAX, MEAS_CHANGE, SET_ACK, PDACK, STATUS, TASK = 6, 7, 8, 10, 13, 14, 15
# the server's version message: version 4, options TC-BAS (bit 0), TC-GEO with position-based
# control (bit 2: the terminal sends each position's rate, from its maps and crop sensors) and
# TC-SC (bit 4); 1 boom, 16 sections, 2 position-based control channels (the two products, the
# upper and lower layers' rates)
VERSION = 4
SERVER_OPTIONS = 0x15
BOOMS, SECTIONS, GEO_CHANNELS = 1, 16, 2
# the client's options byte (its version message, byte 4)
OPTION_NAMES = (
    "documentation", "TC-GEO without position-based control", "TC-GEO with position-based "
    "control", "peer control", "implement section control",
)  # fmt: skip


def tc_name(identity: int, manufacturer_code: int = 1407, function_instance: int = 0) -> int:
    """A Task Controller's NAME: function 130 (TC), industry group 2, self-configurable;
    function instance 0 is TC number 1."""
    if not 0 <= identity < 1 << 21 or not 0 <= manufacturer_code < 1 << 11:
        raise ProtocolError("TC NAME: identity 0..2^21-1, manufacturer 0..2047")
    if not 0 <= function_instance < 32:
        raise ProtocolError("TC NAME: function instance 0..31")
    return name_of(
        identity_number=identity,
        manufacturer_code=manufacturer_code,
        function_instance=function_instance,
        function=TC_FUNCTION,
        industry_group=2,  # agriculture
        self_configurable=1,
    )


def is_tc(name: int) -> bool:
    """A Task Controller's NAME: function 130 is the TC in device class 0 (non-specific) of
    industry group 2; in another device class (5, fertilizers) the same code is not a TC."""
    f = name_fields(name)
    return f["function"] == TC_FUNCTION and f["device_class"] == 0 and f["industry_group"] == 2


def pd_frame(cmd: int, element: int, ddi: int, value: int) -> bytes:
    """A process-data message's 8 bytes (element 0..4095, DDI 0..65535, value signed 32 bit)."""
    if not 0 <= element <= 4095 or not 0 <= ddi <= 0xFFFF or not -(2**31) <= value < 2**31:
        raise ProtocolError(f"process data out of range: element {element} DDI {ddi} {value}")
    head = bytes([cmd | (element & 0xF) << 4, element >> 4, ddi & 0xFF, ddi >> 8])
    return head + struct.pack("<i", value)


def pdack_texts(code: int) -> list[Text]:
    """A PDACK's error byte as messages, one per bit set (ISO 11783-10's eight: `tc.pdack.0`
    "process data command not supported" to `tc.pdack.7` "value outside the operational
    range"); 0 and 0xFF (AgIsoStack++ fills the byte with 0xFF: no code given) are no error."""
    if code in (0, 0xFF):
        return []
    return [text(f"tc.pdack.{bit}") for bit in range(8) if code >> bit & 1]


@dataclass
class Client:
    """The one working set the TC serves, as far as it has got."""

    address: int
    last_heard_us: int
    version: bytes | None = None
    pool: bytes | None = None
    device: Device | None = None
    active: bool = False
    lost: bool = False
    values: dict[tuple[int, int], int] = field(default_factory=dict)  # the last, by (element, DDI)
    heard: dict[tuple[int, int], int] = field(default_factory=dict)  # how many values came
    pdacks: list[tuple[int, int, int]] = field(default_factory=list)  # element, DDI, errors
    name: int | None = None  # its NAME, from its address claim
    from_store: bool = False  # the pool is the one kept from an earlier connection
    awaiting: dict[tuple[int, int], int] = field(default_factory=dict)  # acks due, by sent time
    pool_error: str = ""  # why its last pool could not be mapped ("" when it could)
    unanswered: int = 0  # acknowledges missed in this silence (said at the first)
    missed: set[tuple[int, int]] = field(default_factory=set)  # the values they were of

    @property
    def options(self) -> int:
        """The options byte of its version message (0 before it came)."""
        return self.version[3] if self.version is not None and len(self.version) > 3 else 0

    @property
    def option_names(self) -> list[str]:
        return [w for bit, w in enumerate(OPTION_NAMES) if self.options >> bit & 1]

    @property
    def geo(self) -> bool:
        """It says it does TC-GEO (with or without position-based control)."""
        return bool(self.options & 0x06)

    @property
    def section_control(self) -> bool:
        return bool(self.options & 0x10)


class TcServer:
    """One Task Controller on one bus; `step` takes the frames heard and returns those to send.
    With a `store`, pools are kept per client NAME and offered back by their labels."""

    def __init__(
        self, name: int, preferred: int = TC_ADDRESS, store: PoolStore | None = None
    ) -> None:
        self.name = name
        self._claim = ClaimNode(name, preferred, (128, 247))
        self._tp: TpEndpoint | None = None
        self._out: list[Frame] = []
        self._next_status = 0
        self._quiet_until = 0  # a TC started anew: no client taken before (`start`)
        self._ask: list[Frame] = []  # the request for address claim, sent with the first step
        self.store = store
        self.client: Client | None = None
        self.errors: list[str] = []  # what went wrong, in words, oldest first (the last 200)
        self.messages: list[Text] = []  # the same as catalogue messages (topdress.i18n)
        self.told = 0  # faults said since the start (`messages` keeps the last 200)
        self.ignored = 0  # frames not understood or from a client not served, counted
        self.counters: Counter[str] = Counter()
        self.names: dict[int, int] = {}  # address -> NAME, from the address claims heard
        self.other_tcs: dict[int, int | None] = {}  # address -> NAME of another TC heard
        self._said: set[str] = set()  # faults said once
        self._refused: set[int] = set()
        self._nacked: dict[int, int] = {}  # address -> when it was last NACKed
        self._flood: dict[int, tuple[int, int]] = {}  # address -> (second, messages in it)

    @property
    def address(self) -> int | None:
        return self._claim.address

    @property
    def alarms(self) -> list[str]:
        """What the operator must act on now (empty when all is well)."""
        out = []
        if self._claim.state == "cannot claim":
            out.append("the TC found no free address: no client can reach it")
        mine = name_fields(self.name)["function_instance"]
        for sa, n in sorted(self.other_tcs.items()):
            if n is None:
                out.append(f"another Task Controller at {sa:#x} (its number not known)")
            elif name_fields(n)["function_instance"] == mine:
                out.append(f"another Task Controller number {mine + 1} at {sa:#x}")
        c = self.client
        if c is not None and c.active and c.lost:
            out.append(f"the implement at {c.address:#x} stopped answering")
        return out

    def start(self, now_us: int, quiet_us: int = 0) -> None:
        """Claims its address; its status goes out from `now_us + quiet_us` (a TC started anew
        beside clients that took the one before for itself: silent past their timeout, they
        take it for lost and connect again, as to a TC that booted). It asks every node to
        claim its address again (from the null address, before its own claim), so that it
        knows the NAMEs of those that claimed before it was on the bus."""
        self._ask = [Frame(6 << 26 | REQUEST_PGN << 8 | 0xFF << 8 | 0xFE, b"\x00\xee\x00")]
        self._claim.start(now_us)
        self._next_status = self._quiet_until = now_us + quiet_us

    def _send(self, da: int, data: bytes, prio: int = 5) -> None:
        sa = self.address
        if sa is not None:
            self._out.append(Frame(prio << 26 | PD_PGN << 8 | da << 8 | sa, data))

    def _error(self, what: Text, key: str | None = None) -> None:
        """Records a fault (once per `key`, when given): its English in `errors` and the
        program log, the message itself (for the operator's language) in `messages`."""
        if key is not None:
            if key in self._said:
                return
            if len(self._said) >= KEEP_SAID:  # a client inventing new faults without end
                self.counters["errors_suppressed"] += 1
                return
            self._said.add(key)
        self.errors.append(str(what))
        del self.errors[:-KEEP_ERRORS]
        self.messages.append(what)
        del self.messages[:-KEEP_ERRORS]
        self.told += 1
        _log.warning("TC: %s", what)

    def set_value(self, element: int, ddi: int, value: int, ack: bool = True) -> None:
        """Set Value (and Acknowledge) to the client; ProtocolError before a pool is active, for
        an element and DDI its pool does not name settable, or a negative rate. A client need not
        check (AgIsoStack++'s acknowledges any value alike), so the TC does."""
        c = self._active_client()
        if c.device is None or (element, ddi) not in c.device.settable:
            raise ProtocolError(f"DDI {ddi} of element {element} is not settable in the DDOP")
        if ddi in (SETPOINT_MASS_HA, SETPOINT_VOLUME_HA) and value < 0:
            raise ProtocolError(f"rate {value} below 0")
        self._send(c.address, pd_frame(SET_ACK if ack else VALUE, element, ddi, value),
                   prio=3 if ack else 5)  # fmt: skip
        if ack:
            c.awaiting.setdefault((element, ddi), -1)  # stamped with the next step's time
        self.counters["values_set"] += 1

    def set_sections(self, states: list[bool | None], ack: bool = True) -> None:
        """The sections' setpoint work states (section 1 first; None leaves one as it is) as the
        condensed setpoint (DDI 290) on the element the pool carries it on."""
        c = self._active_client()
        element = None if c.device is None else c.device.condensed.get(SETPOINT_CONDENSED)
        if element is None:
            raise ProtocolError("the DDOP has no setpoint condensed work state (DDI 290)")
        if c.device is not None and len(states) > len(c.device.sections):
            raise ProtocolError(f"{len(states)} section states for {len(c.device.sections)} "
                                "sections")  # fmt: skip
        self.set_value(element, SETPOINT_CONDENSED, condensed_value(states), ack)

    def sections_working(self) -> list[bool | None] | None:
        """The sections' actual work states as the client last reported them (DDI 161), section
        1 first; None before any report."""
        c = self.client
        if c is None or c.device is None or ACTUAL_CONDENSED not in c.device.condensed:
            return None
        value = c.values.get((c.device.condensed[ACTUAL_CONDENSED], ACTUAL_CONDENSED))
        return None if value is None else condensed_states(value, len(c.device.sections))

    def _measure(self, cmd: int, trigger: int, element: int, ddi: int, value: int) -> None:
        c = self._active_client()
        if c.device is None or not c.device.measured(element, ddi, trigger):
            what = {TRIG_TIME: "time", TRIG_DISTANCE: "distance", TRIG_THRESHOLD: "threshold",
                    TRIG_CHANGE: "on-change"}[trigger]  # fmt: skip
            raise ProtocolError(
                f"the DDOP offers no {what} trigger for DDI {ddi} of element {element}"
            )
        self._send(c.address, pd_frame(cmd, element, ddi, value))
        self.counters["measurements_asked"] += 1

    def measure_every(self, element: int, ddi: int, interval_ms: int) -> None:
        """Measurement command, time interval: the client reports the value every interval_ms
        (0 stops it)."""
        if interval_ms < 0:
            raise ProtocolError(f"measurement interval {interval_ms} ms below 0")
        self._measure(MEAS_TIME, TRIG_TIME, element, ddi, interval_ms)

    def measure_distance(self, element: int, ddi: int, distance_mm: int) -> None:
        """Measurement command, distance interval: a report every distance_mm driven."""
        if distance_mm < 0:
            raise ProtocolError(f"measurement distance {distance_mm} mm below 0")
        self._measure(MEAS_DISTANCE, TRIG_DISTANCE, element, ddi, distance_mm)

    def measure_threshold(
        self, element: int, ddi: int, minimum: int | None = None, maximum: int | None = None
    ) -> None:
        """Measurement commands, thresholds: a report while the value is below `minimum`
        (minimum within threshold) or above `maximum`; at least one of them."""
        if minimum is None and maximum is None:
            raise ProtocolError("a threshold measurement needs a minimum or a maximum")
        if minimum is not None and maximum is not None and minimum > maximum:
            raise ProtocolError(f"threshold minimum {minimum} above maximum {maximum}")
        if minimum is not None:
            self._measure(MEAS_MIN, TRIG_THRESHOLD, element, ddi, minimum)
        if maximum is not None:
            self._measure(MEAS_MAX, TRIG_THRESHOLD, element, ddi, maximum)

    def measure_on_change(self, element: int, ddi: int, threshold: int = 1) -> None:
        """Measurement command, change threshold: a report whenever the value moved this much."""
        if threshold < 1:
            raise ProtocolError(f"change threshold {threshold} below 1")
        self._measure(MEAS_CHANGE, TRIG_CHANGE, element, ddi, threshold)

    def request_value(self, element: int, ddi: int) -> None:
        c = self._active_client()
        self._send(c.address, pd_frame(REQUEST, element, ddi, 0))

    def _active_client(self) -> Client:
        c = self.client
        if c is None or not c.active or c.lost:
            raise ProtocolError("the TC has no client with an active pool")
        return c

    def step(self, now_us: int, frames_in: list[Frame]) -> list[Frame]:
        for f in frames_in:
            try:
                self._rx(f, now_us)
            except ProtocolError as exc:  # a frame the C layer refused: said, counted, dropped
                self.counters["bad_frames"] += 1
                self._error(text("tc.frame_refused", id=f.can_id, why=str(exc)), key="bad_frame")
        self._claim.step(now_us)
        self._out[:0] = self._ask + self._claim.tx()  # the request before its own claim
        self._ask = []
        sa = self.address
        if sa is not None and (self._tp is None or self._tp.address != sa):
            self._tp = TpEndpoint(sa, MAX_POOL_BYTES + 1)  # claimed, or moved by a contest
        c = self.client
        if c is not None and not c.lost:
            if now_us - c.last_heard_us > CLIENT_TIMEOUT_US:
                c.lost = True
                self.counters["clients_lost"] += 1
                self._error(text("tc.silent", client=c.address, ms=CLIENT_TIMEOUT_US // 1000))
            self._acks_due(c, now_us)
        if sa is not None and now_us >= self._next_status:
            self._next_status = now_us + STATUS_PERIOD_US
            ca = c.address if c is not None and not c.lost else 0xFF
            self._send(0xFF, bytes([0xFE, 0xFF, 0xFF, 0xFF, 0, ca, 0, 0xFF]), prio=3)
        if self._tp is not None:
            self._tp.step(now_us)
            self._out += self._tp.tx()
        out, self._out = self._out, []
        return out

    def _acks_due(self, c: Client, now_us: int) -> None:
        for key, sent in list(c.awaiting.items()):
            if sent < 0:
                c.awaiting[key] = now_us
            elif now_us - sent > PDACK_TIMEOUT_US:
                del c.awaiting[key]
                self.counters["pdacks_missing"] += 1
                c.unanswered += 1
                c.missed.add(key)
                if c.unanswered == 1:  # once per silence: the rest are counted
                    self._error(text("tc.no_ack", client=c.address, ddi=key[1], element=key[0],
                                     ms=PDACK_TIMEOUT_US // 1000))  # fmt: skip

    def _rx(self, f: Frame, now_us: int) -> None:
        self._claim.rx(f.can_id, f.data, now_us)
        _, pgn, sa, da = split_id(f.can_id)
        if pgn == CLAIM_PGN and len(f.data) == 8:
            self._claimed(sa, int.from_bytes(f.data, "little"))
            return
        me = self.address
        if pgn == PD_PGN and da == 0xFF and sa != me and f.data[:1] and f.data[0] & 0x0F == STATUS:
            self._other_tc(sa, self.names.get(sa))
            return
        if me is None or da not in (me, 0xFF):
            c = self.client
            if pgn == PD_PGN and da in self.other_tcs and c is not None and c.address == sa:
                self._elsewhere(c, da)
            return
        if now_us < self._quiet_until:
            return  # started anew: a client still talking to the TC before, until it lost it
        if pgn == REQUEST_PGN and f.data[:3] == b"\x0f\xfe\x00":  # request for the language command
            self._out.append(Frame(6 << 26 | 0xFE0F << 8 | me, b"en\x50\x00\x00\x00\xff\xff"))
            return
        if pgn == 0xFE0D:  # working-set master: a client announces itself; ask its version
            c = self._client(sa, now_us)
            if c is not None and c.version is None:
                self._send(sa, bytes([0x00]) + b"\xff" * 7)
            return
        if da != me:
            return
        if pgn in (0xEC00, 0xEB00, 0xC800, 0xC700) and self._tp is not None:
            c = self.client
            if c is not None and c.address == sa and not c.lost:
                c.last_heard_us = now_us  # a slow pool transfer is a client still there
            n = len(self._tp.received)
            self._tp.rx(f.can_id, f.data, now_us)
            self._out += self._tp.tx()  # the end-of-message ack goes before any answer to it
            if len(self._tp.received) > n:
                pgn_in, src, data = self._tp.received.pop()
                if pgn_in == PD_PGN:
                    self._message(src, data, now_us)
        elif pgn == PD_PGN:
            if self._flooding(sa, now_us):
                return
            self._message(sa, f.data, now_us)

    def _claimed(self, sa: int, name: int) -> None:
        """An address claim heard: who is where; a second TC; the served client re-addressed."""
        old = self.names.get(sa)
        self.names[sa] = name
        if sa == self.address or sa == 0xFE:
            self.other_tcs.pop(sa, None)  # that one lost the address to us, or gave it up
            return
        if is_tc(name) and name != self.name:
            self._other_tc(sa, name)
        elif sa in self.other_tcs and old is not None and old != name:
            del self.other_tcs[sa]  # that address went to a node that is no TC
        c = self.client
        if c is None or c.lost:
            return
        if sa == c.address and c.name is not None and name != c.name:
            c.lost = True
            self.counters["clients_displaced"] += 1
            self._error(text("tc.displaced", client=sa, name=name))
        elif sa != c.address and c.name == name:
            c.lost = True
            self.counters["clients_displaced"] += 1
            self._error(text("tc.moved", name=name, old=c.address, new=sa))

    def _other_tc(self, sa: int, name: int | None) -> None:
        if sa in self.other_tcs and self.other_tcs[sa] == name:
            return
        for a in [a for a, n in self.other_tcs.items() if name is not None and n == name]:
            del self.other_tcs[a]  # the same TC moved (an address contest)
        self.other_tcs[sa] = name
        key = f"tc:{sa}" if name is None else f"tc:{name}"
        if key in self._said:
            return
        self.counters["other_tcs"] += 1
        if name is None:
            self._error(text("tc.other_tc", address=sa), key=key)
        else:
            number = name_fields(name)["function_instance"] + 1
            self._error(text("tc.other_tc_number", address=sa, number=number), key=key)

    def _elsewhere(self, c: Client, tc: int) -> None:
        """The client talks to another TC (two on the bus, and it chose that one): let it go
        rather than wait for it and call it lost."""
        self.client = None
        self.counters["clients_to_other_tc"] += 1
        self._error(
            text("tc.elsewhere", client=c.address, tc=tc), key=f"elsewhere:{c.address}:{tc}"
        )

    def _flooding(self, sa: int, now_us: int) -> bool:
        second = now_us // 1_000_000
        was, n = self._flood.get(sa, (second, 0))
        n = n + 1 if was == second else 1
        self._flood[sa] = (second, n)
        if n <= FLOOD_PER_S:
            return False
        self.counters["flood_dropped"] += 1
        self._error(text("tc.flood", address=sa, n=FLOOD_PER_S), key=f"flood:{sa}")
        return True

    def _client(self, sa: int, now_us: int) -> Client | None:
        """The client at sa; None (refused, reported once, NACKed) while another is served."""
        c = self.client
        if c is not None and c.address != sa and not c.lost:
            if sa not in self._refused:
                self._refused.add(sa)
                self._error(text("tc.second_client", client=sa, served=c.address))
            self.counters["refused_frames"] += 1
            self._nack(sa, now_us)
            return None
        if c is None or c.address != sa or c.lost:
            c = self.client = Client(sa, now_us, name=self.names.get(sa))
            self._refused.discard(sa)
        c.last_heard_us = now_us
        return c

    def _nack(self, sa: int, now_us: int) -> None:
        """A negative acknowledgement of process data, at most once a second per address."""
        me = self.address
        if me is None or now_us - self._nacked.get(sa, -(10**12)) < 1_000_000:
            return
        self._nacked[sa] = now_us
        data = bytes([1, 0xFF, 0xFF, 0xFF, sa]) + PD_PGN.to_bytes(3, "little")
        self._out.append(Frame(6 << 26 | ACK_PGN << 8 | sa << 8 | me, data))

    def _message(self, sa: int, d: bytes, now_us: int) -> None:
        c = self._client(sa, now_us) if len(d) >= 8 else None
        if c is None:
            self.ignored += 1
            return
        cmd = d[0] & 0x0F
        if cmd == TECH:
            self._technical(c, d)
        elif cmd == TASK:
            pass  # the working set's task message: heard, nothing to answer
        elif cmd == DEVICE:
            self._device(c, d)
        elif cmd == VALUE:
            self._value(c, d)
        elif cmd == PDACK:
            self._pdack(c, d)
        else:
            self.ignored += 1

    def _technical(self, c: Client, d: bytes) -> None:
        if d[0] == 0x00:  # version request
            self._send(c.address, bytes([0x10, VERSION, 0xFF, SERVER_OPTIONS, 0, BOOMS, SECTIONS,
                                         GEO_CHANNELS]))  # fmt: skip
            if c.version is None:  # ours came too early for it (AgIsoStack++): ask again
                self._send(c.address, bytes([0x00]) + b"\xff" * 7)
        elif d[0] == 0x10:  # the client's own version, answering ours
            c.version = bytes(d)
            _log.info("TC: client %#x version %d, options %s%s", c.address, d[1],
                      ", ".join(c.option_names) or "none",
                      " (TC-GEO: position-based)" if c.geo else "")  # fmt: skip
        else:
            self.ignored += 1

    def _device(self, c: Client, d: bytes) -> None:
        op = d[0] >> 4
        if op == 0:  # structure label request: the stored pool's, or none (7 x 0xFF)
            label = self._stored(c)
            self._send(c.address, bytes([0x11]) + (label or b"\xff" * 7))
        elif op == 2:  # localization label request
            ok = c.from_store and c.device is not None
            label = c.device.localization_label if ok and c.device is not None else None
            self._send(c.address, bytes([0x31]) + (label or b"\xff" * 7))
        elif op == 4:  # request object-pool transfer: room for it?
            (size,) = struct.unpack_from("<I", d, 1)
            room = size <= MAX_POOL_BYTES
            if not room:
                self.counters["pools_refused"] += 1
                self._error(text("tc.pool_too_large", client=c.address, size=size))
            self._send(c.address, bytes([0x51, 0 if room else 1]) + b"\xff" * 6)
        elif op == 6:
            self._pool(c, d[1:])
        elif op == 8:  # activate
            self._activate(c)
        elif op == 0xA:  # delete pool
            c.pool, c.device, c.active, c.from_store = None, None, False, False
            if self.store is not None and c.name is not None:
                self.store.delete(c.name)
            self._send(c.address, bytes([0xB1, 0]) + b"\xff" * 6)
        else:
            self.ignored += 1

    def _stored(self, c: Client) -> bytes | None:
        """The structure label of the pool kept for this client's NAME, the pool taken as the
        client's until it uploads another; None when none is kept or it does not read back."""
        if self.store is None or c.name is None:
            return None
        try:
            pool = self.store.load(c.name)
            if pool is None:
                return None
            device = map_device(pool)
        except ProtocolError as exc:
            self.store.discard(c.name)
            self.counters["stored_pools_corrupt"] += 1
            self._error(text("tc.stored_corrupt", client=c.address, why=str(exc)))
            return None
        c.pool, c.device, c.active, c.from_store = pool, device, False, True
        self.counters["stored_pools_offered"] += 1
        return device.structure_label

    def _pool(self, c: Client, pool: bytes) -> None:
        c.pool, c.device, c.active, c.from_store = pool, None, False, False
        c.pool_error = ""
        try:
            c.device = map_device(pool)
            err = 0
        except ProtocolError as exc:
            c.pool_error = str(exc)
            self.counters["pools_refused"] += 1
            self._error(text("tc.pool_bad", client=c.address, why=str(exc)))
            err = 1 if len(pool) > MAX_POOL_BYTES else 0  # a bad pool is refused at activation
        self._send(c.address, bytes([0x71, err]) + struct.pack("<I", len(pool)) + b"\xff\xff")

    def _activate(self, c: Client) -> None:
        if c.device is None or c.pool is None:  # errors in the pool (bit 0), "other error" (bit 2)
            self._send(c.address, bytes([0x91, 1, 0xFF, 0xFF, 0xFF, 0xFF, 4, 0xFF]))
            self._error(text("tc.activation_refused", client=c.address))
            return
        c.active = True
        self.counters["activations"] += 1
        self._send(c.address, bytes([0x91, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0, 0xFF]))
        if c.from_store:
            self.counters["uploads_saved"] += 1
        elif self.store is not None and c.name is not None:
            try:
                self.store.save(c.name, c.pool, c.device.structure_label,
                                c.device.localization_label)  # fmt: skip
            except OSError as exc:
                self.counters["store_errors"] += 1
                self._error(text("tc.not_kept", client=c.address, why=str(exc)), key="store")

    @staticmethod
    def _unpack(d: bytes) -> tuple[int, int, int]:
        element = d[0] >> 4 | d[1] << 4
        return element, d[2] | d[3] << 8, struct.unpack_from("<i", d, 4)[0]

    def _value(self, c: Client, d: bytes) -> None:
        element, ddi, value = self._unpack(d)
        dev = c.device
        if (
            dev is not None
            and (element, ddi) not in dev.triggers
            and ((element, ddi) not in dev.properties)
        ):
            # not process data of its pool: counted and said once, not taken for a measurement
            self.counters["unknown_values"] += 1
            self._error(text("tc.unknown_value", client=c.address, ddi=ddi, element=element),
                        key=f"unknown:{element}:{ddi}")  # fmt: skip
            return
        c.values[(element, ddi)] = value
        c.heard[(element, ddi)] = c.heard.get((element, ddi), 0) + 1

    def _pdack(self, c: Client, d: bytes) -> None:
        # byte 4: error bits; byte 5: the command acknowledged (AgIsoStack++: both 0xFF)
        element, ddi, _ = self._unpack(d)
        c.pdacks.append((element, ddi, d[4]))
        del c.pdacks[:-KEEP_PDACKS]
        c.awaiting.pop((element, ddi), None)
        # the silence ends when a value it missed is acknowledged: a client that acknowledges
        # others but never this one would otherwise say "missed" and "again" at each change
        if (element, ddi) in c.missed:
            self._error(text("tc.ack_again", client=c.address, n=c.unanswered))
            c.unanswered = 0
            c.missed.clear()
        words = pdack_texts(d[4])
        if words:
            self.counters["pdack_errors"] += 1
            why = words[0]
            for w in words[1:]:
                why = text("tc.and", a=why, b=w)
            self._error(text("tc.pdack_refused", client=c.address, ddi=ddi, element=element,
                             why=why))  # fmt: skip
        else:
            self.counters["pdacks_ok"] += 1
