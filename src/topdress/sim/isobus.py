"""The simulated machine with its ECU on ISOBUS: the node (ecu/isobus through cffi) takes the
Task Controller's rates and sections, and hands them to the control core each control period
as the core's own command, beside it behind the same port (the core stays as it is).

On the bus the core's own frames go as the node maps them (docs/isobus.md, "The private
frames on ISOBUS"): its broadcasts on Proprietary B from the claimed address, its answers on
Proprietary A to the TC; the terminal's frames reach the core only from the TC's address.

Ground speed: the core's command carries the true speed (a perfect GNSS) by default; with
`gnss_from_tc` it carries what the ISOBUS firmware gives it (ecu/ports/stm32f4/fw_isobus.c): the
terminal's last PcGnssTime from the TC's address while fresh (`gnss_timeout_ms`), else "not
available" (the core on its wheel). Once the terminal's PcGnssTime reaches the core, the
command's speed is no fused fix any more (the core takes a PC's fixes from PcGnssTime only,
docs/protocol.md); it still serves the paper's modes.

Sections: the meters run at the TC's rate times the share of the width switched on (row
shut-offs at the outlets close the rows switched off), and stop with every section off or no TC
(the node's fail-safe after the cab PC's command timeout).
"""

from __future__ import annotations

from topdress.errors import ProtocolError
from topdress.isobus.ddop import (
    DDI_ACTUAL_CONDENSED_1_16,
    DDI_ACTUAL_RATE,
    DDI_ACTUAL_WORK_STATE,
)
from topdress.isobus.node import Frame, IsobusNode
from topdress.isobus.workstate import condensed_value
from topdress.protocol.dbc import frame_ids
from topdress.protocol.frames import GNSS_MAX_KMH, PcGnssTime, decode, encode_command
from topdress.sim.world import StepOutput, World

ELEMENT_DEVICE, ELEMENT_BOOM, ELEMENT_BINS = 0, 2, (3, 4)
TC_STATUS_PERIOD_MS = 2000  # a TC proves itself alive only this often (ISO 11783-10)
KG_HA_PER_RPM_KG = 600.0  # kg/ha = rpm * kg/rev * 600 / (km/h * m)


def tc_timeout_ms(cmd_timeout_ms: int) -> int:
    """The node's TC timeout: the cab PC's command timeout counted from the first status
    message missed, so a TC that merely waits for its next status is never taken for lost."""
    return cmd_timeout_ms + TC_STATUS_PERIOD_MS


_GNSS_TIME_ID = frame_ids()["PcGnssTime"]


class IsobusMachine:
    """A World whose ECU is commanded over ISOBUS by a Task Controller."""

    def __init__(self, world: World, node: IsobusNode, width_m: float, sections: int,
                 fan_rpm: float = 3000.0, gnss_from_tc: bool = False) -> None:  # fmt: skip
        self.world = world
        self.gnss_from_tc = gnss_from_tc
        self._gnss: tuple[float | None, int] | None = None  # the TC's last speed, and when
        self.node = node
        self.width_m = width_m
        self.sections = sections
        self.fan_rpm = fan_rpm
        self.running = False
        self.actual_kg_ha = (0.0, 0.0)  # what the meters apply, as reported to the TC (DDI 7)
        self.out: StepOutput | None = None  # the World's last step: its NMEA and crop lines
        self._connected = False  # the node connected to its TC at the last step
        node.start(world.now_us)

    def rates_kg_ha(self) -> tuple[float, float]:
        """The rates the core is told: the TC's, times the share of the width switched on."""
        share = bin(self.node.sections_on).count("1") / self.sections
        return self.node.rate_kg_ha(0) * share, self.node.rate_kg_ha(1) * share

    def _take_gnss(self, frame: Frame, now_us: int) -> None:
        try:
            g = decode((frame.can_id, frame.data))
        except ProtocolError:
            return  # counted by the core, which got it too
        if isinstance(g, PcGnssTime):
            self._gnss = (g.gnss_kmh, now_us)

    def _gnss_kmh(self, now_us: int) -> float | None:
        """The GNSS speed the core's command carries."""
        if not self.gnss_from_tc:
            return min(self.world.truth.v_kmh, GNSS_MAX_KMH)
        timeout_us = self.world.ecu.params.gnss_timeout_ms * 1000
        if self._gnss is None or now_us - self._gnss[1] > timeout_us:
            return None
        kmh = self._gnss[0]
        return None if kmh is None or kmh > GNSS_MAX_KMH else kmh

    def step(self, frames_in: list[Frame]) -> list[Frame]:
        """One control period: the bus's frames to the node, the node's setpoints to the core,
        the plant and core one step, the actual values back to the node; the node's frames."""
        w, n = self.world, self.node
        now = w.now_us
        for f in frames_in:
            n.rx(f.can_id, f.data, now)
            core = n.prop_rx(f)
            if core is not None:
                w.deliver_can((core.can_id, core.data))
                if core.can_id == _GNSS_TIME_ID:
                    self._take_gnss(core, now)
        upper, lower = self.rates_kg_ha()
        self.running = upper > 0.0 or lower > 0.0
        w.deliver_can(encode_command(self.running, self.fan_rpm, upper, lower,
                                     self._gnss_kmh(now)))  # fmt: skip
        self.out = w.step()
        core_out = self.out.can
        truth = w.truth
        actual = [0.0, 0.0]
        for layer, element in enumerate(ELEMENT_BINS):
            rate = 0.0
            if truth.v_kmh > 0.5:
                rate = (truth.meter_rpm[layer] * w.cfg.kg_per_rev[layer] * KG_HA_PER_RPM_KG
                        / (truth.v_kmh * self.width_m))  # fmt: skip
            n.set_actual(element, DDI_ACTUAL_RATE, round(rate * 100))
            actual[layer] = rate
        self.actual_kg_ha = (actual[0], actual[1])
        n.set_actual(ELEMENT_DEVICE, DDI_ACTUAL_WORK_STATE, 1 if self.running else 0)
        on: list[bool | None] = [bool(n.sections_on >> i & 1) for i in range(self.sections)]
        n.set_actual(ELEMENT_BOOM, DDI_ACTUAL_CONDENSED_1_16, condensed_value(on))
        n.step(w.now_us, round(truth.odometer_m * 1000))
        connected = n.tc_state == "connected"
        if connected and not self._connected:
            w.ecu.announce()  # its EcuIdent went out before the claim, to no one: say it again
        self._connected = connected
        out = n.tx()
        for can_id, data in core_out:
            bus = n.prop_tx(Frame(can_id, data))
            if bus is not None:
                out.append(bus)
        return out
