"""The cab terminal as an ISOBUS Task Controller (ISO 11783-10 version 4, TC-BAS and TC-SC):
claims its address with a TC NAME (the C layer's claim), sends the TC status every 2 s, answers
the client's version and label requests, takes the device description (DDOP) over TP/ETP (the C
layer's transport), parses and maps it (bins with their rates, sections), activates it or refuses
it with the error named, then sets values and asks for measurements. Domain code: frames in,
frames out, time passed in; no UI, no I/O."""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

from topdress.errors import ProtocolError
from topdress.isobus.ddop import PoolObject, parse
from topdress.isobus.node import ClaimNode, Frame, TpEndpoint, split_id

PD_PGN = 0xCB00
TC_ADDRESS = 0xF7
STATUS_PERIOD_US = 2_000_000
CLIENT_TIMEOUT_US = 6_000_000  # three missed 2 s task messages (ISO 11783-10 client timeout)
MAX_POOL_BYTES = 65_536  # what the terminal keeps; a larger pool is refused for memory

# process-data commands (low nibble of byte 0)
TECH, DEVICE, REQUEST, VALUE, MEAS_TIME, SET_ACK, PDACK, TASK = 0, 1, 2, 3, 4, 10, 13, 15
# DDIs the mapping looks for
SETPOINT_MASS_HA, ACTUAL_MASS_HA = 6, 7
SETPOINT_WORK_STATE, ACTUAL_WORK_STATE = 289, 141
SETPOINT_CONDENSED, ACTUAL_CONDENSED = 290, 161
DET_BIN, DET_SECTION = 3, 4


def tc_name(identity: int, manufacturer_code: int = 1407) -> int:
    """A Task Controller's NAME: function 130 (TC), industry group 2, self-configurable."""
    if not 0 <= identity < 1 << 21 or not 0 <= manufacturer_code < 1 << 11:
        raise ProtocolError("TC NAME: identity 0..2^21-1, manufacturer 0..2047")
    return (
        identity
        | manufacturer_code << 21
        | 130 << 40  # function: task controller
        | 2 << 60  # industry group: agriculture
        | 1 << 63
    )


@dataclass(frozen=True)
class Device:
    """What the terminal learnt from a device's pool: where its rates and sections are."""

    designator: str
    bins: dict[int, set[int]]  # element number -> DDIs it carries
    sections: list[int]  # element numbers of the sections, in pool order
    condensed: dict[int, int]  # DDI 161/290 -> element number that carries it
    settable: frozenset[tuple[int, int]]  # (element, DDI) of the settable process data
    objects: int


def map_device(pool: bytes) -> Device:
    """Parses and maps a pool; ProtocolError names what is wrong (never another exception)."""
    if len(pool) > MAX_POOL_BYTES:
        raise ProtocolError(f"DDOP of {len(pool)} bytes over the {MAX_POOL_BYTES} kept")
    try:
        objs = parse(pool)
    except ValueError as exc:
        raise ProtocolError(f"DDOP malformed: {exc}") from None
    by_id: dict[int, PoolObject] = {}
    for o in objs:
        if o.object_id in by_id:
            raise ProtocolError(f"DDOP object id {o.object_id} used twice")
        by_id[o.object_id] = o
    dvcs = [o for o in objs if o.table == "DVC"]
    if len(dvcs) != 1:
        raise ProtocolError(f"DDOP has {len(dvcs)} device objects (DVC), 1 expected")
    bins: dict[int, set[int]] = {}
    sections: list[int] = []
    condensed: dict[int, int] = {}
    settable: set[tuple[int, int]] = set()
    for o in objs:
        if o.table != "DET":
            continue
        ddis = set()
        for child in o.fields["children"]:
            c = by_id.get(child)
            if c is None:
                raise ProtocolError(f"DDOP element {o.object_id} names missing object {child}")
            if c.table in ("DPD", "DPT"):
                ddis.add(int(c.fields["ddi"]))
            if c.table == "DPD" and c.fields["properties"] & 2:  # bit 1: settable
                settable.add((int(o.fields["element"]), int(c.fields["ddi"])))
        if o.fields["parent"] not in by_id:
            raise ProtocolError(f"DDOP element {o.object_id} has missing parent")
        element = int(o.fields["element"])
        if element > 4095:
            raise ProtocolError(f"DDOP element number {element} over 4095")
        if o.fields["type"] == DET_BIN and ddis & {SETPOINT_MASS_HA, ACTUAL_MASS_HA}:
            bins[element] = ddis
        if o.fields["type"] == DET_SECTION:
            sections.append(element)
        for ddi in (SETPOINT_CONDENSED, ACTUAL_CONDENSED):
            if ddi in ddis:
                condensed[ddi] = element
    return Device(
        str(dvcs[0].fields["designator"]), bins, sections, condensed, frozenset(settable), len(objs)
    )


def pd_frame(cmd: int, element: int, ddi: int, value: int) -> bytes:
    """A process-data message's 8 bytes (element 0..4095, DDI 0..65535, value signed 32 bit)."""
    if not 0 <= element <= 4095 or not 0 <= ddi <= 0xFFFF or not -(2**31) <= value < 2**31:
        raise ProtocolError(f"process data out of range: element {element} DDI {ddi} {value}")
    head = bytes([cmd | (element & 0xF) << 4, element >> 4, ddi & 0xFF, ddi >> 8])
    return head + struct.pack("<i", value)


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


class TcServer:
    """One Task Controller on one bus; `step` takes the frames heard and returns those to send."""

    def __init__(self, name: int, preferred: int = TC_ADDRESS) -> None:
        self._claim = ClaimNode(name, preferred, (128, 247))
        self._tp: TpEndpoint | None = None
        self._out: list[Frame] = []
        self._next_status = 0
        self.client: Client | None = None
        self.errors: list[str] = []  # what went wrong, in words, oldest first
        self.ignored = 0  # frames not understood or from a client not served, counted
        self._refused: set[int] = set()

    @property
    def address(self) -> int | None:
        return self._claim.address

    def start(self, now_us: int) -> None:
        self._claim.start(now_us)

    def _send(self, da: int, data: bytes, prio: int = 5) -> None:
        sa = self.address
        if sa is not None:
            self._out.append(Frame(prio << 26 | PD_PGN << 8 | da << 8 | sa, data))

    def _error(self, what: str) -> None:
        self.errors.append(what)

    def set_value(self, element: int, ddi: int, value: int, ack: bool = True) -> None:
        """Set Value (and Acknowledge) to the client; ProtocolError before a pool is active, for
        an element and DDI its pool does not name settable, or a negative rate. A client need not
        check (AgIsoStack++'s acknowledges any value alike), so the TC does."""
        c = self._active_client()
        if c.device is None or (element, ddi) not in c.device.settable:
            raise ProtocolError(f"DDI {ddi} of element {element} is not settable in the DDOP")
        if ddi == SETPOINT_MASS_HA and value < 0:
            raise ProtocolError(f"rate {value} mg/m^2 below 0")
        self._send(c.address, pd_frame(SET_ACK if ack else VALUE, element, ddi, value))

    def measure_every(self, element: int, ddi: int, interval_ms: int) -> None:
        """Measurement command, time interval: the client reports the value every interval_ms."""
        c = self._active_client()
        self._send(c.address, pd_frame(MEAS_TIME, element, ddi, interval_ms))

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
            self._rx(f, now_us)
        self._claim.step(now_us)
        self._out[:0] = self._claim.tx()
        sa = self.address
        if sa is not None and (self._tp is None or self._tp.address != sa):
            self._tp = TpEndpoint(sa, MAX_POOL_BYTES + 1)  # claimed, or moved by a contest
        c = self.client
        if c is not None and not c.lost and now_us - c.last_heard_us > CLIENT_TIMEOUT_US:
            c.lost = True
            self._error(f"client {c.address:#x} silent for {CLIENT_TIMEOUT_US // 1000} ms")
        if sa is not None and now_us >= self._next_status:
            self._next_status = now_us + STATUS_PERIOD_US
            ca = c.address if c is not None and not c.lost else 0xFF
            self._send(0xFF, bytes([0xFE, 0xFF, 0xFF, 0xFF, 0, ca, 0, 0xFF]), prio=3)
        if self._tp is not None:
            self._tp.step(now_us)
            self._out += self._tp.tx()
        out, self._out = self._out, []
        return out

    def _rx(self, f: Frame, now_us: int) -> None:
        self._claim.rx(f.can_id, f.data, now_us)
        _, pgn, sa, da = split_id(f.can_id)
        me = self.address
        if me is None or da not in (me, 0xFF):
            return
        if pgn == 0xEA00 and f.data[:3] == b"\x0f\xfe\x00":  # request for the language command
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
            n = len(self._tp.received)
            self._tp.rx(f.can_id, f.data, now_us)
            if len(self._tp.received) > n:
                pgn_in, src, data = self._tp.received.pop()
                if pgn_in == PD_PGN:
                    self._message(src, data, now_us)
        elif pgn == PD_PGN:
            self._message(sa, f.data, now_us)

    def _client(self, sa: int, now_us: int) -> Client | None:
        """The client at sa; None (refused, reported once) while another one is served."""
        c = self.client
        if c is not None and c.address != sa and not c.lost:
            if sa not in self._refused:
                self._refused.add(sa)
                self._error(f"client {sa:#x} refused: the TC serves {c.address:#x}, one at a time")
            return None
        if c is None or c.address != sa or c.lost:
            c = self.client = Client(sa, now_us)
        c.last_heard_us = now_us
        return c

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
        if d[0] == 0x00:  # version request: version 4, options TC-BAS (bit 0) + TC-SC (bit 4)
            self._send(c.address, bytes([0x10, 4, 0xFF, 0x11, 0, 1, 16, 2]))
        elif d[0] == 0x10:  # the client's own version, answering ours
            c.version = bytes(d)
        else:
            self.ignored += 1

    def _device(self, c: Client, d: bytes) -> None:
        op = d[0] >> 4
        if op == 0:  # structure label request: none stored, the client sends its pool
            self._send(c.address, bytes([0x11]) + b"\xff" * 7)
        elif op == 2:  # localization label request
            self._send(c.address, bytes([0x31]) + b"\xff" * 7)
        elif op == 4:  # request object-pool transfer: room for it?
            (size,) = struct.unpack_from("<I", d, 1)
            room = size <= MAX_POOL_BYTES
            if not room:
                self._error(f"client {c.address:#x} offers a {size}-byte DDOP, too large")
            self._send(c.address, bytes([0x51, 0 if room else 1]) + b"\xff" * 6)
        elif op == 6:
            self._pool(c, d[1:])
        elif op == 8:  # activate
            self._activate(c)
        elif op == 0xA:  # delete pool
            c.pool, c.device, c.active = None, None, False
            self._send(c.address, bytes([0xB1, 0]) + b"\xff" * 6)
        else:
            self.ignored += 1

    def _pool(self, c: Client, pool: bytes) -> None:
        c.pool, c.device, c.active = pool, None, False
        try:
            c.device = map_device(pool)
            err = 0
        except ProtocolError as exc:
            self._error(str(exc))
            err = 1 if len(pool) > MAX_POOL_BYTES else 0  # a bad pool is refused at activation
        self._send(c.address, bytes([0x71, err]) + struct.pack("<I", len(pool)) + b"\xff\xff")

    def _activate(self, c: Client) -> None:
        if c.device is None:  # errors in the pool (bit 0), "other error" (bit 2)
            self._send(c.address, bytes([0x91, 1, 0xFF, 0xFF, 0xFF, 0xFF, 4, 0xFF]))
            self._error(f"client {c.address:#x}: activation refused, no valid DDOP")
            return
        c.active = True
        self._send(c.address, bytes([0x91, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0, 0xFF]))

    @staticmethod
    def _unpack(d: bytes) -> tuple[int, int, int]:
        element = d[0] >> 4 | d[1] << 4
        return element, d[2] | d[3] << 8, struct.unpack_from("<i", d, 4)[0]

    def _value(self, c: Client, d: bytes) -> None:
        element, ddi, value = self._unpack(d)
        c.values[(element, ddi)] = value
        c.heard[(element, ddi)] = c.heard.get((element, ddi), 0) + 1

    def _pdack(self, c: Client, d: bytes) -> None:
        # bytes 4.. are error codes and the command; AgIsoStack++ leaves 5..7 at 0xFF
        element, ddi, _ = self._unpack(d)
        c.pdacks.append((element, ddi, d[4]))
