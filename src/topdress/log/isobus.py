"""What the implement's ISOBUS node did, as session-log events: its address claimed (or lost),
the DDOP accepted or refused by the Task Controller, the rates and sections the TC set, values
the node refused (out of range, unknown element or DDI), a transfer of the DDOP aborted, the TC
lost, the bus loaded to its limit (and back). Compares the node's state between control
periods; no I/O."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from topdress.isobus.node import IsobusNode
from topdress.log.model import LogEvent

BUS_FRAMES_PER_S: Final = 250_000 / 135  # 250 kbit/s, 29-bit 8-byte frames of ~135 bits
LOAD_HIGH: Final = 0.9  # a second of frames heard at 90 % of the bus or more: overloaded
LOAD_LOW: Final = 0.7  # below 70 % again: back to normal
LOAD_WINDOW_S: Final = 1.0


@dataclass
class _Seen:
    address: int | None = None
    claim_state: str = "idle"
    tc_state: str = "no address"
    setting: tuple[float, float, int] = (0.0, 0.0, 0)
    alarm: bool = False
    window_t: float | None = None
    window_frames: int = 0
    overloaded: bool = False
    refused: int = 0
    tp_send: str = "idle"


class IsobusWatch:
    """Call `events(t)` after each step of the node; it returns what changed since."""

    def __init__(self, node: IsobusNode) -> None:
        self.node = node
        self._seen = _Seen()

    def events(self, t: float) -> list[LogEvent]:
        n, seen, out = self.node, self._seen, []
        failed = n.claim_state == "cannot claim" != seen.claim_state
        seen.claim_state = n.claim_state
        if (n.address is not None and n.address != seen.address) or failed:
            # between losing an address and claiming the next the node has none for 250 ms:
            # one event for the move, naming the address taken from it
            detail = {"address": n.address, "name": f"{n.name:016X}", "state": n.claim_state}
            if seen.address is not None and n.address is not None:
                detail["moved"] = seen.address
            out.append(LogEvent(t, "isobus.claimed", detail))
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
        refused = n.counters["values_refused"]
        if refused != seen.refused:
            out.append(LogEvent(t, "isobus.value_refused", {"refused": refused - seen.refused,
                                                            "total": refused}))  # fmt: skip
            seen.refused = refused
        tp, reason = n.tp_send
        if tp != seen.tp_send and tp in ("aborted", "timeout"):
            out.append(LogEvent(t, "isobus.tp_aborted", {"state": tp, "reason": reason,
                                                         "tc_state": state}))  # fmt: skip
        seen.tp_send = tp
        out += self._load(t)
        return out

    def _load(self, t: float) -> list[LogEvent]:
        """The frames heard per second over windows of LOAD_WINDOW_S: an `isobus.bus_load`
        event when the bus is at its limit (the Task Controller's frames and ours then get
        through late or not at all) and when it is back."""
        seen, frames = self._seen, self.node.counters["rx_frames"]
        if seen.window_t is None:
            seen.window_t, seen.window_frames = t, frames
            return []
        span = t - seen.window_t
        if span < LOAD_WINDOW_S:
            return []
        load = (frames - seen.window_frames) / span / BUS_FRAMES_PER_S
        seen.window_t, seen.window_frames = t, frames
        if (load >= LOAD_HIGH) == seen.overloaded or LOAD_LOW < load < LOAD_HIGH:
            return []
        seen.overloaded = load >= LOAD_HIGH
        detail = {"overloaded": seen.overloaded, "load_pct": round(100.0 * load, 1)}
        return [LogEvent(t, "isobus.bus_load", detail)]
