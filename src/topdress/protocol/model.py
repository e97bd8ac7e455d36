"""Values shared by the protocol and the ECU binding: sources, modes, fault bits, frame ids.

The integer codes are the ones of ecu/include/td_common.h and of the DBC value tables;
tests check both.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum, IntFlag, StrEnum

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


_SOURCE_CODES = (Source.WHEEL, Source.GNSS, Source.NONE, Source.FUSED)
_MODE_CODES = (SpeedMode.PAPER, SpeedMode.WHEEL_ONLY, SpeedMode.GNSS_ONLY, SpeedMode.FUSED)
_COMPARE_CODES = (Compare.GNSS, Compare.WHEEL)


class Fault(IntFlag):
    """The ECU fault word (TD_FAULT_* of td_common.h; EcuDiag.FaultWord)."""

    CMD_TIMEOUT = 1 << 0
    GNSS_LOST = 1 << 1
    WHEEL_ENCODER = 1 << 2
    UPPER_BLOCKED = 1 << 3
    LOWER_BLOCKED = 1 << 4
    UPPER_FAN_LOW = 1 << 5
    LOWER_FAN_LOW = 1 << 6
    NO_SPEED = 1 << 7
    GNSS_FROZEN = 1 << 8


#: The fault word's bits by name, lowest first (ecu/include/td_common.h).
FAULT_NAMES: tuple[str, ...] = tuple(str(f.name) for f in Fault)


def fault_names(word: int) -> list[str]:
    """Names of the bits set in a fault word (16 bits, EcuDiag.FaultWord), lowest first; a bit
    this software does not know as BITn."""
    names = [name for bit, name in enumerate(FAULT_NAMES) if word & (1 << bit)]
    names += [f"BIT{bit}" for bit in range(len(FAULT_NAMES), 16) if word & (1 << bit)]
    return names


# Cleared only by a stop command (operator acknowledgement).
LATCHED_FAULTS = Fault.WHEEL_ENCODER | Fault.UPPER_BLOCKED | Fault.LOWER_BLOCKED


class AckResult(IntEnum):
    """EcuParamAck.AckResult."""

    OK = 0
    UNKNOWN_PARAM = 1
    OUT_OF_RANGE = 2
    BUSY = 3
    INCONSISTENT = 4
    BAD_FRAME = 5


@dataclass(frozen=True)
class FrameIds:
    """29-bit identifiers of every frame; the defaults are the DBC's (the paper's two first)."""

    status: int = 0x185C6465
    command: int = 0x0A5C6465
    diag: int = 0x185D6465
    speeds: int = 0x185E6465
    targets: int = 0x185F6465
    param_set: int = 0x0A606465
    param_ack: int = 0x18616465
    cal_command: int = 0x0A646465
    cal_status: int = 0x18656465
    gnss_time: int = 0x0A626465
    fused: int = 0x18636465
    fused_aux: int = 0x18666465
    gnss_lag: int = 0x18696465
    ident: int = 0x18676465
    can_health: int = 0x186A6465
    fault_record: int = 0x186B6465


DEFAULT_IDS = FrameIds()
