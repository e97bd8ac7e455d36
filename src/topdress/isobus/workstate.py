"""Condensed work states (ISO 11783-11 DDI 161 actual / 290 setpoint, sections 1-16): two bits a
section, section 1 in the lowest bits; 00 off, 01 on, 10 error (actual) or "leave as is"
(setpoint), 11 not installed or "leave as is". Values travel as signed 32-bit process data."""

from __future__ import annotations

from topdress.errors import ProtocolError

SECTIONS_PER_DDI = 16


def condensed_value(states: list[bool | None]) -> int:
    """The setpoint value for sections 1..n (True on, False off, None leave as is); the sections
    beyond n are 11 (not installed)."""
    if len(states) > SECTIONS_PER_DDI:
        raise ProtocolError(f"{len(states)} sections: one condensed DDI carries 16")
    raw = 0
    for i in range(SECTIONS_PER_DDI):
        s = states[i] if i < len(states) else None
        raw |= (3 if s is None else int(s)) << 2 * i
    return raw - (1 << 32) if raw >= 1 << 31 else raw


def condensed_states(value: int, sections: int) -> list[bool | None]:
    """Sections 1..n of a condensed value: True on, False off, None error or not installed."""
    raw = value & 0xFFFFFFFF
    out: list[bool | None] = []
    for i in range(min(sections, SECTIONS_PER_DDI)):
        bits = raw >> 2 * i & 3
        out.append(None if bits > 1 else bits == 1)
    return out
