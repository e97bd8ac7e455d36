"""Values shared by the protocol and the ECU binding: sources, modes, fault bits, frame ids.

The integer codes and the frame identifiers are the DBC's (its value tables and frames, read
by topdress.protocol.dbc), as the C core's are (its generated header, ecu/src/gen/td_dbc.h):
here each member only names the DBC value it is; adding a value to the DBC without a member
(or the reverse) fails at import.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum, IntEnum, IntFlag, StrEnum
from typing import TypeVar

from topdress.errors import ProtocolError
from topdress.protocol.dbc import bit_names, frame_ids, snake, value_table

E = TypeVar("E", bound=Enum)


def dbc_codes(
    cls: type[E], frame: str, signal: str, names: dict[str, str] | None = None
) -> tuple[E, ...]:
    """The members of `cls` in the order of the codes of the DBC's value table of
    `frame.signal` (codes 0..n-1): each DBC value is the member of its name in upper snake case
    ("WheelOnly" -> WHEEL_ONLY), or of the name `names` gives it."""
    table = value_table(frame, signal)
    if list(table) != list(range(len(table))):
        raise ProtocolError(f"{frame}.{signal}: the codes are not 0..{len(table) - 1}")
    members = []
    for name in table.values():
        key = (names or {}).get(name, snake(name).upper())
        if key not in cls.__members__:
            raise ProtocolError(f"{frame}.{signal} value {name!r} has no {cls.__name__}.{key}")
        members.append(cls[key])
    if set(members) != set(cls):
        raise ProtocolError(f"{cls.__name__} has members the DBC's {frame}.{signal} has not")
    return tuple(members)


# A CAN frame as plain values: (arbitration_id, data). The fast path of the binding uses it.
CanFrame = tuple[int, bytes]


class Source(StrEnum):
    """Speed source in use (td_source_t; EcuDiag.SpeedSource). FUSED: the fused estimate fed by
    both sensors (in the fused mode WHEEL or GNSS name the one sensor still feeding it)."""

    WHEEL = "wheel"
    GNSS = "gnss"
    NONE = "none"
    FUSED = "fused"

    @property
    def code(self) -> int:
        return _SOURCE_CODES.index(self)

    @classmethod
    def from_code(cls, code: int) -> Source:
        return _SOURCE_CODES[code]


class SpeedMode(StrEnum):
    """Speed mode (td_speed_mode_t; parameter SpeedMode). PAPER is the paper's dual rule
    (TD_MODE_DUAL, the DBC's "Dual"), FUSED the Kalman estimate over both sensors
    (docs/speed.md). The values are the names the configuration and the command line take."""

    PAPER = "paper"
    WHEEL_ONLY = "wheel"
    GNSS_ONLY = "gnss"
    FUSED = "fused"

    @property
    def code(self) -> int:
        return _MODE_CODES.index(self)

    @classmethod
    def from_code(cls, code: int) -> SpeedMode:
        return _MODE_CODES[code]


class Compare(StrEnum):
    """Which speed the dual rule compares with the switch speed (td_compare_t)."""

    GNSS = "gnss"
    WHEEL = "wheel"

    @property
    def code(self) -> int:
        return _COMPARE_CODES.index(self)

    @classmethod
    def from_code(cls, code: int) -> Compare:
        return _COMPARE_CODES[code]


_SOURCE_CODES = dbc_codes(Source, "EcuDiag", "SpeedSource")
# the paper's rule is the DBC's (and the C core's) "Dual"
_MODE_CODES = dbc_codes(SpeedMode, "EcuDiag", "SpeedMode", {"Dual": "PAPER"})
_COMPARE_CODES = dbc_codes(Compare, "EcuDiag", "SwitchCompare")


_FAULT_BITS = {
    snake(name).upper(): 1 << bit for bit, name in enumerate(bit_names("EcuDiag", "FaultWord"))
}


class Fault(IntFlag):
    """The ECU fault word (EcuDiag.FaultWord; the DBC names its bits, lowest first, as the C
    core's TD_FAULT_* are generated from; what each means: ecu/include/td_common.h)."""

    CMD_TIMEOUT = _FAULT_BITS["CMD_TIMEOUT"]
    GNSS_LOST = _FAULT_BITS["GNSS_LOST"]
    WHEEL_ENCODER = _FAULT_BITS["WHEEL_ENCODER"]
    UPPER_BLOCKED = _FAULT_BITS["UPPER_BLOCKED"]
    LOWER_BLOCKED = _FAULT_BITS["LOWER_BLOCKED"]
    UPPER_FAN_LOW = _FAULT_BITS["UPPER_FAN_LOW"]
    LOWER_FAN_LOW = _FAULT_BITS["LOWER_FAN_LOW"]
    NO_SPEED = _FAULT_BITS["NO_SPEED"]
    GNSS_FROZEN = _FAULT_BITS["GNSS_FROZEN"]


if set(_FAULT_BITS) != set(Fault.__members__):
    raise ProtocolError("the DBC's EcuDiag.FaultWord bits are not Fault's members")

#: The fault word's bits by name, lowest first (the DBC's order).
FAULT_NAMES: tuple[str, ...] = tuple(str(f.name) for f in Fault)


def fault_names(word: int) -> list[str]:
    """Names of the bits set in a fault word (16 bits, EcuDiag.FaultWord), lowest first; a bit
    this software does not know as BITn."""
    names = [name for bit, name in enumerate(FAULT_NAMES) if word & (1 << bit)]
    names += [f"BIT{bit}" for bit in range(len(FAULT_NAMES), 16) if word & (1 << bit)]
    return names


# Cleared only by a stop command (operator acknowledgement).
LATCHED_FAULTS = Fault.WHEEL_ENCODER | Fault.UPPER_BLOCKED | Fault.LOWER_BLOCKED


_ACK = {snake(name).upper(): code for code, name in value_table("EcuParamAck", "AckResult").items()}


class AckResult(IntEnum):
    """EcuParamAck.AckResult (codes: the DBC's value table)."""

    OK = _ACK["OK"]
    UNKNOWN_PARAM = _ACK["UNKNOWN_PARAM"]
    OUT_OF_RANGE = _ACK["OUT_OF_RANGE"]
    BUSY = _ACK["BUSY"]
    INCONSISTENT = _ACK["INCONSISTENT"]
    BAD_FRAME = _ACK["BAD_FRAME"]


dbc_codes(AckResult, "EcuParamAck", "AckResult")  # every DBC value has its member, and back

_IDS = frame_ids()


@dataclass(frozen=True)
class FrameIds:
    """29-bit identifiers of every frame; the defaults are the DBC's (the paper's two first)."""

    status: int = _IDS["EcuStatus"]
    command: int = _IDS["PcCommand"]
    diag: int = _IDS["EcuDiag"]
    speeds: int = _IDS["EcuSpeeds"]
    targets: int = _IDS["EcuTargets"]
    param_set: int = _IDS["PcParamSet"]
    param_ack: int = _IDS["EcuParamAck"]
    cal_command: int = _IDS["PcCalCommand"]
    cal_status: int = _IDS["EcuCalStatus"]
    gnss_time: int = _IDS["PcGnssTime"]
    fused: int = _IDS["EcuFused"]
    fused_aux: int = _IDS["EcuFusedAux"]
    gnss_lag: int = _IDS["EcuGnssLag"]
    ident: int = _IDS["EcuIdent"]
    can_health: int = _IDS["EcuCanHealth"]
    fault_record: int = _IDS["EcuFaultRecord"]


DEFAULT_IDS = FrameIds()
