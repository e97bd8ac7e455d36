"""Fast decoding of the protocol's plain frames: bit layouts and range checks taken from the
cantools database once, at first use.

cantools decodes a frame through a generic bit-unpacker and a dictionary per call; the
simulated cab PC decodes four frames every 100 ms and the terminal as many, so the layouts
are compiled here into one shift-and-mask per signal over the payload read as one
little-endian integer. The DBC stays the only description of the frames: nothing here names
a bit position. A frame that does not fit the fast form (multiplexed, big-endian or float
signals) has no layout and is decoded by cantools.

The range check of a signal is reduced to the interval of raw values that pass it, found once
by bisection on the same check, so a decoded frame is accepted or refused exactly as before.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from typing import Any

from topdress.errors import ProtocolError
from topdress.protocol.dbc import database, message
from topdress.protocol.params import decimals


@dataclass(frozen=True)
class SignalCheck:
    """A signal's scaling and the raw values its DBC range and value table accept."""

    frame: str
    name: str
    scale: float
    offset: float
    decimals: int
    minimum: float
    maximum: float
    choices: frozenset[int] | None
    raw_lo: int  # raw values in raw_lo..raw_hi are inside minimum..maximum (+- scale / 2)
    raw_hi: int

    def physical(self, raw: int) -> float:
        """The value that was sent, rounded to the signal's resolution."""
        return float(round(raw * self.scale + self.offset, self.decimals))

    def check(self, raw: int) -> float:
        """Physical value of a raw signal, or ProtocolError when outside its range or choices."""
        value = float(round(raw * self.scale + self.offset, self.decimals))
        if self.choices is not None and raw not in self.choices:
            raise ProtocolError(f"{self.frame}.{self.name}: undefined value {raw}")
        if not self.raw_lo <= raw <= self.raw_hi:
            raise ProtocolError(
                f"{self.frame}.{self.name} = {value:g} outside "
                f"{self.minimum:g}..{self.maximum:g}"
            )
        return value


@dataclass(frozen=True)
class FrameLayout:
    """Where each signal of a plain frame sits: raw = (payload >> shift) & mask, then
    two's complement for a signed one."""

    name: str
    length: int
    names: tuple[str, ...]
    fields: tuple[tuple[int, int], ...]  # (shift, mask) per signal, in DBC order
    sign_bits: tuple[int, ...]  # 1 << (length - 1) of a signed signal, 0 of an unsigned one
    checks: tuple[SignalCheck, ...]

    def raw(self, data: bytes) -> tuple[int, ...]:
        """Raw signal values in DBC order; the caller has checked the length."""
        x = int.from_bytes(data, "little")
        raw = tuple([(x >> s) & m for s, m in self.fields])
        if not any(self.sign_bits):
            return raw
        return tuple([r - ((r & b) << 1) for r, b in zip(raw, self.sign_bits, strict=True)])

    def values(self, raw: tuple[int, ...]) -> tuple[float, ...]:
        """Physical values in DBC order, each checked as SignalCheck.check does."""
        return tuple([c.check(r) for c, r in zip(self.checks, raw, strict=True)])


def _raw_bounds(sig: Any, accepts: Callable[[int], bool]) -> tuple[int, int]:
    """The first and last raw value `accepts` (monotone scaling: the accepted values are one
    interval); an empty interval (lo > hi) when none is."""
    lo_all = -(1 << (sig.length - 1)) if sig.is_signed else 0
    hi_all = (1 << (sig.length - 1)) - 1 if sig.is_signed else (1 << sig.length) - 1
    # a raw value inside the range: the one nearest the middle of minimum..maximum
    mid = round(((sig.minimum + sig.maximum) / 2 - sig.offset) / sig.scale)
    mid = min(hi_all, max(lo_all, mid))
    if not accepts(mid):
        return 1, 0
    a, b = lo_all, mid  # first accepted in a..b
    while a < b:
        m = (a + b) // 2
        a, b = (a, m) if accepts(m) else (m + 1, b)
    lo = a
    a, b = mid, hi_all  # last accepted in a..b
    while a < b:
        m = (a + b + 1) // 2
        a, b = (m, b) if accepts(m) else (a, m - 1)
    return lo, a


def signal_check(frame: str, sig: Any) -> SignalCheck:
    """The compiled check of one cantools signal."""
    dec = decimals(sig.scale)
    tol = sig.scale / 2

    def accepts(raw: int) -> bool:
        value = float(round(raw * sig.scale + sig.offset, dec))
        return bool(sig.minimum - tol <= value <= sig.maximum + tol)

    if sig.scale <= 0:
        raise ProtocolError(f"{frame}.{sig.name}: scale {sig.scale} is not positive")
    lo, hi = _raw_bounds(sig, accepts)
    choices = None if sig.choices is None else frozenset(int(k) for k in sig.choices)
    return SignalCheck(
        frame, sig.name, sig.scale, sig.offset, dec, sig.minimum, sig.maximum, choices, lo, hi
    )


def _compile(msg: Any) -> FrameLayout | None:
    if msg.is_multiplexed():
        return None
    sigs = msg.signals
    if any(s.byte_order != "little_endian" or s.is_float for s in sigs):
        return None
    return FrameLayout(
        name=msg.name,
        length=msg.length,
        names=tuple(s.name for s in sigs),
        fields=tuple((s.start, (1 << s.length) - 1) for s in sigs),
        sign_bits=tuple(1 << (s.length - 1) if s.is_signed else 0 for s in sigs),
        checks=tuple(signal_check(msg.name, s) for s in sigs),
    )


@cache
def layouts() -> dict[str, FrameLayout | None]:
    """Frame name -> its layout (None: decoded by cantools), for every frame of the DBC."""
    return {m.name: _compile(m) for m in database().messages}


@cache
def checks() -> dict[tuple[str, str], SignalCheck]:
    """(frame, signal) -> the compiled check, for every signal of the DBC."""
    return {
        (m.name, s.name): signal_check(m.name, s) for m in database().messages for s in m.signals
    }


def layout(name: str) -> FrameLayout | None:
    """The layout of frame `name` (None for one cantools decodes); ProtocolError if unknown."""
    table = layouts()
    if name not in table:
        message(name)  # raises the protocol's error for an unknown name
    return table[name]
