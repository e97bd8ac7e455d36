"""The firmware's own diagnostics on the bus: the CAN controller's health (EcuCanHealth, once a
second) and what its fault handler kept across a fault reset (EcuFaultRecord, one register a
second). The texts the communication screen shows and the events the terminal logs."""

from __future__ import annotations

from dataclasses import dataclass, field

from topdress import protocol
from topdress.i18n import Text, text


def health_text(h: protocol.EcuCanHealth) -> Text:
    """ "CAN error-active, errors tx 0 rx 0, error-passive 0x, bus-off 0x" for the screen."""
    return text(
        "view.ecu_can_health",
        state=h.bus_state,
        tec=h.tx_errors,
        rec=h.rx_errors,
        passive=h.error_passive_count,
        bus_off=h.bus_off_count,
    )


def health_event(before: protocol.EcuCanHealth | None, now: protocol.EcuCanHealth) -> Text | None:
    """An event when the controller's state changes or it went bus-off or error-passive again
    since the last frame (a bus-off recovered within the second shows only in the count)."""
    if before is None:
        return None if now.bus_state == "error-active" else health_text(now)
    if (
        now.bus_state != before.bus_state
        or now.bus_off_count != before.bus_off_count
        or now.error_passive_count != before.error_passive_count
    ):
        return text("event.ecu_can_health", health=health_text(now))
    return None


@dataclass
class FaultRecord:
    """The registers of one EcuFaultRecord round, said once when all six are in."""

    values: dict[str, int] = field(default_factory=dict)
    kind: str = "none"
    said: bool = False

    def take(self, rec: protocol.EcuFaultRecord) -> Text | None:
        if rec.kind != self.kind or self.values.get(rec.register, rec.value) != rec.value:
            self.values, self.kind, self.said = {}, rec.kind, False  # another fault
        self.values[rec.register] = rec.value
        if not self.said and rec.kind == "crystal failure":  # no registers to wait for
            self.said = True
            return text("event.ecu_crystal_failure")
        if self.said or len(self.values) < len(protocol.FAULT_REGISTERS):
            return None
        self.said = True
        regs = " ".join(f"{r} 0x{self.values[r]:08X}" for r in protocol.FAULT_REGISTERS)
        return text("event.ecu_fault_record", kind=self.kind, registers=regs)
