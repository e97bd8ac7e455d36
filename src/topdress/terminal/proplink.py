"""The topdress ECU's private frames on an ISOBUS (`[can] implement = "isobus"`).

When the implement the Task Controller (terminal.tclink) serves is a topdress ECU, the terminal
speaks its private frames to it as on the paper's own bus, from the TC's address: the parameter
push with its acknowledges (terminal.parampush), the calibrations (terminal.calibration), the
GNSS speed with the fix's age (PcGnssTime), and the ECU's broadcasts (status, diagnostics,
speeds, faults, identity, GNSS lag) into the same Snapshot fields. One `CanLink` (isobus mode)
does all of it; `PropLink` is the `bus` it sends on and the filter of what it hears: each frame
goes on the proprietary PGN protocol/topdress.dbc's IsobusPgn gives it (topdress.isobus.node's
`to_bus`/`from_bus`, the C layer's table), PcParamSet and PcCalCommand on Proprietary A/A2 to
the ECU's address, PcGnssTime on Proprietary B.

A topdress ECU is recognised by what it says of itself, all of it: its NAME (the one
`td_ibname_topdress` makes: industry group 2, device class 5 fertilizers, function 128
Fertilize Rate Control, and the manufacturer code `[isobus] ecu_manufacturer`, the firmware's
FW_ISOBUS_MANUFACTURER) and its DDOP's device designator "topdress". Proprietary PGNs mean what
their sender's manufacturer says they mean, so the manufacturer code is the one thing that
makes the frames ours; the function and the DDOP keep another product of the same maker (or a
code left at 0 on both sides) out. Any other implement gets no proprietary frame.

Frames carrying a private PGN from any address but the ECU's (or Proprietary A to the TC from
elsewhere) are ignored and counted (`wrong_source`); without a topdress ECU served they are
other implements' traffic and not looked at. The ECU is its address and its NAME: once
another node claims that address (implements often prefer the same one), nothing goes to it
and nothing from it is taken until the same ECU is served again.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import can

from topdress.errors import DeviceError, ProtocolError
from topdress.i18n import Text, text
from topdress.isobus.node import Frame, from_bus, name_fields, split_id, to_bus
from topdress.isobus.tcserver import Client
from topdress.terminal.ecuview import EcuView, LinkCounters
from topdress.view.snapshot import ecu_values

DESIGNATOR = "topdress"  # the DDOP's device designator (isobus.ddop.build)
# The NAME fields td_ibname_topdress sets (docs/isobus.md, "The NAME")
INDUSTRY_GROUP, DEVICE_CLASS, FUNCTION = 2, 5, 128


class Sender(Protocol):
    """The CAN port (python-can's `send`)."""

    def send(self, msg: can.Message, timeout: float | None = None) -> None: ...


class Served(Protocol):
    """What the link needs of the Task Controller: its address, the client it serves, the NAME
    at each address (from the address claims heard) and its counters (`activations`: each pool
    activated)."""

    @property
    def address(self) -> int | None: ...

    @property
    def client(self) -> Client | None: ...

    @property
    def names(self) -> Mapping[int, int]: ...

    @property
    def counters(self) -> Mapping[str, int]: ...


def not_topdress(name: int | None, designator: str, manufacturer: int) -> Text | None:
    """Why an implement with this NAME and DDOP designator is not a topdress ECU (None: it is)."""
    if name is None:
        return text("prop.why.no_name")
    f = name_fields(name)
    if f["manufacturer_code"] != manufacturer:
        return text("prop.why.manufacturer", theirs=f["manufacturer_code"], ours=manufacturer)
    ours = (INDUSTRY_GROUP, DEVICE_CLASS, FUNCTION)
    theirs = (f["industry_group"], f["device_class"], f["function"])
    if theirs != ours:
        group, device_class, function = theirs
        return text("prop.why.name", group=group, device_class=device_class, function=function)
    if designator != DESIGNATOR:
        return text("prop.why.ddop", theirs=designator, ours=DESIGNATOR)
    return None


@dataclass
class PropCounters:
    """The private frames on the ISOBUS."""

    rx: int = 0  # from the ECU served, handed to the link
    wrong_source: int = 0  # a private PGN from another address: ignored
    tx: int = 0  # sent to the ECU
    tx_refused: int = 0  # no topdress ECU served or no TC address: not sent


class PropLink:
    """The `bus` of the topdress ECU's CanLink on an ISOBUS, and the filter of what it hears.

    `watch()` on each frame and tick follows the client the TC serves; `peer` is the ECU's
    address while a topdress ECU is served (None otherwise: none served, or the one served
    displaced); `on_tx` is told each frame as it goes on the bus."""

    def __init__(
        self,
        port: Sender,
        tc: Served,
        manufacturer: int,
        on_tx: Callable[[can.Message], None] | None = None,
        say: Callable[[Text], None] | None = None,
    ) -> None:
        self._port = port
        self._tc = tc
        self.manufacturer = manufacturer
        self._on_tx = on_tx
        self._say = say
        self.counters = PropCounters()
        self.peer: int | None = None
        self._name: int | None = None  # the NAME of the topdress ECU recognised last
        self.why: Text | None = None  # why the implement served is not a topdress ECU
        self.recognised = False  # a topdress ECU was served once (its parameters pushed)
        self._judged: tuple[int, int | None, str] | None = None  # address, NAME, designator
        self._activations = 0  # the TC's, when the topdress ECU was last judged or heard of

    # ---- who is served ----------------------------------------------------------------------
    def watch(self) -> str | None:
        """The client the TC serves, judged once per address, NAME and DDOP: `first` when a
        topdress ECU has just been recognised for the first time (its parameters are to be
        pushed), `again` when the topdress ECU served has activated its pool again (it
        connected again: it may have restarted), else None."""
        c = self._tc.client
        if c is None or (self.peer is not None and not self.serving):
            # Served by another TC, or another node claimed its address: served again once
            # back. One only lost keeps its address while its NAME holds it: its frames are
            # its own, and its first status after the loss ends the loss at once.
            self.peer = None
        if c is None or not c.active or c.lost or c.device is None:
            return None
        activations = self._tc.counters.get("activations", 0)
        key = (c.address, c.name, c.device.designator)
        if key == self._judged:
            back = self.peer is None and self.why is None  # the topdress ECU, served again
            again = back or (self.serving and activations > self._activations)
            self._activations = activations
            if back:
                self.peer = c.address
            return "again" if again else None
        self._judged = key
        self._activations = activations
        why = not_topdress(c.name, c.device.designator, self.manufacturer)
        if why is not None:
            self.peer, self.why = None, why
            self._tell(text("prop.not_topdress", address=c.address, why=why))
            return None
        was, self.recognised = self.recognised, True
        self.peer, self.why, self._name = c.address, None, c.name
        self._tell(text("prop.topdress", address=c.address))
        return "again" if was else "first"

    @property
    def serving(self) -> bool:
        """A topdress ECU is the implement served, and its NAME still holds its address."""
        return self.peer is not None and self._tc.names.get(self.peer) == self._name

    def _tell(self, what: Text) -> None:
        if self._say is not None:
            self._say(what)

    # ---- sending (the CanLink's bus) --------------------------------------------------------
    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """One of the paper's frames, to the ECU served on its proprietary PGN from the TC's
        address. DeviceError when it cannot go (no topdress ECU, no TC address, no ISOBUS
        form): the link counts it as a frame not sent."""
        me, peer = self._tc.address, self.peer
        bus = None
        if me is not None and peer is not None and self.serving:
            bus = to_bus(Frame(msg.arbitration_id, bytes(msg.data)), False, me, peer)
        if bus is None:
            self.counters.tx_refused += 1
            raise DeviceError("no topdress ECU served on the ISOBUS for this frame")
        out = can.Message(arbitration_id=bus.can_id, data=bus.data, is_extended_id=True)
        self._port.send(out, timeout=timeout)
        self.counters.tx += 1
        if self._on_tx is not None:
            self._on_tx(out)

    # ---- receiving --------------------------------------------------------------------------
    def take(self, msg: can.Message) -> can.Message | None:
        """A frame of the bus: the paper's frame it carries when it is the ECU's, from the ECU
        served to the TC (or to all); None for anything else (a private PGN from another
        address counted in `wrong_source`)."""
        me, peer = self._tc.address, self.peer
        if peer is None or me is None or not msg.is_extended_id or msg.is_error_frame:
            return None
        if not self.serving:  # another node claimed its address: not the ECU's frames
            return None
        if msg.is_remote_frame or split_id(msg.arbitration_id)[2] == me:
            return None  # our own echo (udp_multicast), or nothing with data
        try:
            f = from_bus(Frame(msg.arbitration_id, bytes(msg.data)), True, peer, me)
        except ProtocolError:
            self.counters.wrong_source += 1
            return None
        if f is None:
            return None
        self.counters.rx += 1
        return can.Message(
            arbitration_id=f.can_id, data=f.data, is_extended_id=True, timestamp=msg.timestamp
        )

    def counter_view(self, link: LinkCounters) -> dict[str, int]:
        """For the Snapshot's counters, those that are not 0; `link`: the ECU link's, whose
        malformed and implausible frames (from the ECU's address) are `prop_bad`."""
        c = self.counters
        named = {
            "prop_rx": c.rx,
            "prop_tx": c.tx,
            "prop_wrong_source": c.wrong_source,
            "prop_bad": link.rx_malformed + link.rx_implausible,
            "prop_tx_refused": c.tx_refused,
        }
        return {k: v for k, v in named.items() if v}


def with_ecu(machine: dict[str, Any], ecu: EcuView) -> dict[str, Any]:
    """The Snapshot's machine fields of an ISOBUS implement (`TcLink.machine_values`) with what a
    topdress ECU's own broadcasts say, as on its private bus: its speeds and their source, CV,
    fans, meters and targets, fault word and running, where those frames have come (the TC
    gives rates and work state only)."""
    if ecu.status is None:
        return machine
    out = dict(machine)
    mine = ecu_values(ecu.status, ecu.diag, ecu.speeds, ecu.targets)
    keys = ["running", "meter_rpm", "fan_rpm", "v_wheel_kmh"]
    if ecu.speeds is not None:
        keys += ["v_kmh", "v_gnss_kmh"]
    if ecu.diag is not None:
        keys += ["source", "cv_pct", "uniform", "faults"]
    if ecu.targets is not None:
        keys.append("target_rpm")
    out.update((k, mine[k]) for k in keys)
    return out
