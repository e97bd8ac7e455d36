"""The ECU's ISOBUS layer (ecu/isobus, C) through cffi: the whole node, and its address claim
and transport protocol on their own, so the terminal and the tests run the very C the ECU runs.

Times are the port's microsecond counter (modulo 2^32), as in the C headers.
"""

from __future__ import annotations

from dataclasses import dataclass

from topdress.errors import ProtocolError
from topdress.isobus._isobus import ffi, lib

TC_STATES = (
    "no address", "waiting for a TC", "version", "language", "structure label",
    "localization label", "pool size", "pool transfer", "activation", "connected", "refused",
)  # fmt: skip
CLAIM_STATES = ("idle", "claiming", "claimed", "cannot claim")
MG_M2_PER_KG_HA = 100.0


@dataclass(frozen=True)
class Frame:
    """An extended CAN frame: 29-bit id and payload."""

    can_id: int
    data: bytes


def _frame(can_id: int, data: bytes) -> object:
    if len(data) > 8:
        raise ProtocolError(f"a classic CAN frame has at most 8 bytes, got {len(data)}")
    f = ffi.new("td_can_frame_t *")
    f.id = can_id & 0x1FFFFFFF
    f.extended = 1
    f.dlc = len(data)
    ffi.memmove(f.data, data, len(data))
    return f


def _drain(pop: object, owner: object) -> list[Frame]:
    out: list[Frame] = []
    f = ffi.new("td_can_frame_t *")
    while pop(owner, f):  # type: ignore[operator]
        out.append(Frame(f.id, bytes(ffi.buffer(f.data, f.dlc))))
    return out


def topdress_name(manufacturer_code: int, uid: bytes) -> int:
    """The implement's NAME (industry group 2, fertilizers, rate control) from a board UID."""
    n = ffi.new("td_ibname_t *")
    if lib.td_ibname_topdress(manufacturer_code, uid, len(uid), n) != lib.TD_IB_OK:
        raise ProtocolError(f"manufacturer code {manufacturer_code} outside 0..2047 or no UID")
    out = ffi.new("uint64_t *")
    lib.td_ibname_encode(n, out)
    return int(out[0])


def name_of(**fields: int) -> int:
    """A NAME from its ISO 11783-5 fields (those of `name_fields`; the others 0), encoded by
    the C layer; ProtocolError for a field out of its range."""
    n = ffi.new("td_ibname_t *")
    for key, value in fields.items():
        setattr(n, key, value)
    out = ffi.new("uint64_t *")
    if lib.td_ibname_encode(n, out) != lib.TD_IB_OK:
        raise ProtocolError(f"NAME fields out of range: {fields}")
    return int(out[0])


def name_fields(name: int) -> dict[str, int]:
    """The fields of a NAME, by their ISO 11783-5 names."""
    n = ffi.new("td_ibname_t *")
    lib.td_ibname_decode(name, n)
    keys = (
        "identity_number", "manufacturer_code", "ecu_instance", "function_instance", "function",
        "device_class", "device_class_instance", "industry_group", "self_configurable",
    )  # fmt: skip
    return {k: int(getattr(n, k)) for k in keys}


def _one(f: object) -> Frame:
    return Frame(int(f.id), bytes(ffi.buffer(f.data, f.dlc)))  # type: ignore[attr-defined]


def to_bus(frame: Frame, by_ecu: bool, sa: int, da: int | None = None) -> Frame | None:
    """A frame of the paper's bus (its fixed identifier) sent by the ECU or the terminal, as it
    goes on an ISOBUS from `sa` (to `da` for Proprietary A): protocol/topdress.dbc's IsobusPgn.
    None when the frame has no ISOBUS form (the PcCommand: the Task Controller sets the rates)
    or no address to go from or to."""
    out = ffi.new("td_can_frame_t *")
    side = lib.TD_PROP_ECU if by_ecu else lib.TD_PROP_TERMINAL
    peer = lib.TD_IB_ADDR_NULL if da is None else da
    if lib.td_prop_to_bus(_frame(frame.can_id, frame.data), side, sa, peer, out) != lib.TD_IB_OK:
        return None
    return _one(out)


def from_bus(frame: Frame, by_ecu: bool, peer: int, my_address: int) -> Frame | None:
    """An ISOBUS frame as the paper's-bus frame of the ECU or the terminal it carries, when it
    comes from `peer` (to `my_address` for Proprietary A); None for other traffic. A private
    frame from another address raises ProtocolError (to be counted, never acted on)."""
    out = ffi.new("td_can_frame_t *")
    side = lib.TD_PROP_ECU if by_ecu else lib.TD_PROP_TERMINAL
    rc = lib.td_prop_from_bus(_frame(frame.can_id, frame.data), side, peer, my_address, out)
    if rc == lib.TD_IB_E_SOURCE:
        _, pgn, sa, _ = split_id(frame.can_id)
        raise ProtocolError(f"PGN {pgn:#x} from address {sa:#x}, not from {peer:#x}: ignored")
    return _one(out) if rc == 1 else None


def split_id(can_id: int) -> tuple[int, int, int, int]:
    """(priority, PGN, source, destination) of a 29-bit identifier."""
    i = lib.td_ib_id_unpack(can_id)
    return int(i.priority), int(i.pgn), int(i.sa), int(i.da)


class IsobusNode:
    """The implement's ISOBUS node: address claim, TP/ETP and the Task Controller client."""

    def __init__(
        self,
        name: int,
        preferred: int = 0x84,
        fallback: tuple[int, int] = (0x80, 0x87),
        tc_timeout_ms: int = 1000,
    ) -> None:
        self._n = ffi.new("td_isob_t *")
        rc = lib.td_isob_init(self._n, name, preferred, fallback[0], fallback[1],
                              tc_timeout_ms * 1000)  # fmt: skip
        if rc != lib.TD_IB_OK:
            raise ProtocolError(
                f"ISOBUS node: preferred address {preferred:#x} or range {fallback} invalid"
            )
        self.name = name

    def start(self, now_us: int) -> None:
        lib.td_isob_start(self._n, now_us & 0xFFFFFFFF)

    def rx(self, can_id: int, data: bytes, now_us: int) -> int:
        """One received frame; a negative code when malformed (counted in rx_errors)."""
        return int(lib.td_isob_rx(self._n, _frame(can_id, data), now_us & 0xFFFFFFFF))

    def step(self, now_us: int, distance_mm: int) -> None:
        lib.td_isob_step(self._n, now_us & 0xFFFFFFFF, distance_mm & 0xFFFFFFFF)

    def tx(self) -> list[Frame]:
        return _drain(lib.td_isob_tx, self._n)

    def prop_rx(self, frame: Frame) -> Frame | None:
        """The terminal's frame for the control core (its fixed identifier) when `frame` is one
        from our TC's address; None otherwise (from another address: counted in
        `counters["prop_wrong_source"]`)."""
        out = ffi.new("td_can_frame_t *")
        rc = lib.td_isob_prop_rx(self._n, _frame(frame.can_id, frame.data), out)
        return _one(out) if rc == 1 else None

    def prop_tx(self, frame: Frame) -> Frame | None:
        """The control core's frame as it goes on the ISOBUS from our address; None when it has
        no ISOBUS form or no address yet (nothing is sent)."""
        out = ffi.new("td_can_frame_t *")
        if lib.td_isob_prop_tx(self._n, _frame(frame.can_id, frame.data), out) != lib.TD_IB_OK:
            return None
        return _one(out)

    def set_actual(self, element: int, ddi: int, value: int) -> None:
        if lib.td_tc_set_actual(ffi.addressof(self._n.tc), element, ddi, value) != lib.TD_IB_OK:
            raise ProtocolError(f"the DDOP has no measured DDI {ddi} on element {element}")

    @property
    def address(self) -> int | None:
        a = int(lib.td_claim_address(ffi.addressof(self._n.claim)))
        return None if a == lib.TD_IB_ADDR_NULL else a

    @property
    def claim_state(self) -> str:
        return CLAIM_STATES[int(self._n.claim.state)]

    @property
    def tc_state(self) -> str:
        return TC_STATES[int(self._n.tc.state)]

    @property
    def tc_address(self) -> int | None:
        a = int(self._n.tc.tc_addr)
        return None if a == lib.TD_IB_ADDR_NULL else a

    @property
    def alarm(self) -> bool:
        return bool(self._n.tc.alarm)

    @property
    def tp_send(self) -> tuple[str, int]:
        """The state of the node's last TP/ETP send (idle, busy, done, aborted, timeout) and
        the abort reason it got (ISO 11783-3; 0: none)."""
        tx = self._n.tp.tx
        return ("idle", "busy", "done", "aborted", "timeout")[int(tx.state)], int(tx.abort_reason)

    @property
    def refuse_code(self) -> int:
        return int(self._n.tc.refuse_code)

    def rate_kg_ha(self, layer: int) -> float:
        """The rate the TC set for layer 0 (upper) or 1 (lower); 0 unless connected."""
        return float(lib.td_tc_rate_mg_m2(ffi.addressof(self._n.tc), layer)) / MG_M2_PER_KG_HA

    @property
    def sections_on(self) -> int:
        return int(lib.td_tc_sections_on(ffi.addressof(self._n.tc)))

    @property
    def counters(self) -> dict[str, int]:
        tc, tp = self._n.tc, self._n.tp
        return {
            "rx_frames": int(self._n.rx_frames), "rx_errors": int(self._n.rx_errors),
            "prop_rx": int(self._n.prop_rx),
            "prop_wrong_source": int(self._n.prop_wrong_source),
            "tp_done": int(tp.rx_done), "tp_aborts": int(tp.rx_aborts),
            "pdacks": int(tc.pdacks_sent), "values_set": int(tc.values_set),
            "values_refused": int(tc.values_refused), "connects": int(tc.connects),
            "tx_dropped": int(self._n.q.dropped),
            "contests_won": int(self._n.claim.contests_won),
            "contests_lost": int(self._n.claim.contests_lost),
        }  # fmt: skip


class ClaimNode:
    """J1939-81 address claim alone (td_claim.h)."""

    def __init__(self, name: int, preferred: int, fallback: tuple[int, int]) -> None:
        self._c = ffi.new("td_claim_t *")
        self._q = ffi.new("td_ib_txq_t *")
        lib.td_ib_txq_init(self._q)
        if lib.td_claim_init(self._c, name, preferred, fallback[0], fallback[1]) != lib.TD_IB_OK:
            raise ProtocolError(f"address claim: {preferred:#x} or range {fallback} invalid")

    def start(self, now_us: int) -> None:
        lib.td_claim_start(self._c, now_us & 0xFFFFFFFF, self._q)

    def rx(self, can_id: int, data: bytes, now_us: int) -> int:
        return int(lib.td_claim_rx(self._c, _frame(can_id, data), now_us & 0xFFFFFFFF, self._q))

    def step(self, now_us: int) -> None:
        lib.td_claim_step(self._c, now_us & 0xFFFFFFFF)

    def tx(self) -> list[Frame]:
        return _drain(lib.td_ib_txq_pop, self._q)

    @property
    def address(self) -> int | None:
        a = int(lib.td_claim_address(self._c))
        return None if a == lib.TD_IB_ADDR_NULL else a

    @property
    def state(self) -> str:
        return CLAIM_STATES[int(self._c.state)]


class TpEndpoint:
    """TP (BAM, CMDT) and ETP alone (td_tp.h), for one address."""

    def __init__(self, address: int, capacity: int = 4096) -> None:
        self.address = address
        self._tp = ffi.new("td_tp_t *")
        self._q = ffi.new("td_ib_txq_t *")
        self._conn = ffi.new("uint8_t[]", capacity)
        self._bam = ffi.new("uint8_t[]", 1785)
        self._sending = ffi.new("uint8_t[]", 1)
        lib.td_ib_txq_init(self._q)
        lib.td_tp_init(self._tp, self._conn, capacity, self._bam, 1785)
        self.received: list[tuple[int, int, bytes]] = []  # (pgn, source, data)

    def send(self, pgn: int, da: int, data: bytes, now_us: int) -> None:
        self._sending = ffi.new("uint8_t[]", data)  # kept alive until the send ends
        rc = lib.td_tp_send(self._tp, pgn, self.address, da, self._sending, len(data),
                            now_us & 0xFFFFFFFF, self._q)  # fmt: skip
        if rc != lib.TD_IB_OK:
            raise ProtocolError(f"transport send of {len(data)} bytes refused ({rc})")

    def rx(self, can_id: int, data: bytes, now_us: int) -> None:
        if lib.td_tp_rx(self._tp, _frame(can_id, data), self.address, now_us & 0xFFFFFFFF,
                        self._q) == 1:  # fmt: skip
            m = self._tp.msg
            self.received.append((int(m.pgn), int(m.sa), bytes(ffi.buffer(m.data, m.len))))

    def step(self, now_us: int) -> None:
        lib.td_tp_step(self._tp, now_us & 0xFFFFFFFF, self._q)

    def cancel(self) -> None:
        lib.td_tp_cancel(self._tp, self._q)

    def tx(self) -> list[Frame]:
        return _drain(lib.td_ib_txq_pop, self._q)

    @property
    def send_state(self) -> str:
        return ("idle", "busy", "done", "aborted", "timeout")[int(self._tp.tx.state)]

    @property
    def abort_reason(self) -> int:
        return int(self._tp.tx.abort_reason)

    @property
    def rx_aborts(self) -> int:
        return int(self._tp.rx_aborts)
