"""What the implement's ISOBUS node did, as session-log events: its address claimed (or lost),
the DDOP accepted or refused by the Task Controller, the rates and sections the TC set, the TC
lost. Compares the node's state between control periods; no I/O."""

from __future__ import annotations

from dataclasses import dataclass

from topdress.isobus.node import IsobusNode
from topdress.log.model import LogEvent


@dataclass
class _Seen:
    address: int | None = None
    tc_state: str = "no address"
    setting: tuple[float, float, int] = (0.0, 0.0, 0)
    alarm: bool = False


class IsobusWatch:
    """Call `events(t)` after each step of the node; it returns what changed since."""

    def __init__(self, node: IsobusNode) -> None:
        self.node = node
        self._seen = _Seen()

    def events(self, t: float) -> list[LogEvent]:
        n, seen, out = self.node, self._seen, []
        if n.address != seen.address:
            out.append(
                LogEvent(
                    t,
                    "isobus.claimed",
                    {"address": n.address, "name": f"{n.name:016X}", "state": n.claim_state},
                )
            )
            seen.address = n.address
        state = n.tc_state
        if state != seen.tc_state and state in ("connected", "refused"):
            out.append(
                LogEvent(
                    t,
                    "isobus.ddop",
                    {"accepted": state == "connected", "tc": n.tc_address, "code": n.refuse_code},
                )
            )
        seen.tc_state = state
        setting = (n.rate_kg_ha(0), n.rate_kg_ha(1), n.sections_on)
        if setting != seen.setting:
            out.append(
                LogEvent(
                    t,
                    "isobus.set",
                    {"upper_kg_ha": setting[0], "lower_kg_ha": setting[1], "sections": setting[2]},
                )
            )
            seen.setting = setting
        if n.alarm and not seen.alarm and state != "refused":
            out.append(LogEvent(t, "isobus.tc_lost", {"tc_state": state}))
        seen.alarm = n.alarm
        return out
