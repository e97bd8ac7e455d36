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

Encoding (`encoder`) takes the same layouts the other way for the frames the terminal sends
every 100 ms: each signal's own cantools conversion gives its raw value and its DBC range is
checked as cantools checks it (strict); anything the fast form does not take (a value out of
range, a missing or extra signal, a non-number) goes to cantools, which encodes it or raises.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
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
    raw_all: tuple[int, int]  # every raw value the signal's bits can hold

    @property
    def always_valid(self) -> bool:
        """No raw value can fail the check (no value table, the range spans every value)."""
        return self.choices is None and self.raw_lo <= self.raw_all[0] <= self.raw_all[1] <= (
            self.raw_hi
        )

    @property
    def ratio(self) -> tuple[int, int] | None:
        """(k, d) with physical = raw * k / d exactly, when the offset is 0 and the scale is
        k / d with d = 10**decimals: the value rounded to its resolution (as `physical`) is
        then the correctly rounded quotient of two integers. None otherwise."""
        d = 10**self.decimals
        k = round(self.scale * d)
        if self.offset != 0 or k <= 0 or abs(self.scale * d - k) > 1e-9 * k:
            return None
        return k, d

    def physical(self, raw: int) -> float:
        """The value that was sent, rounded to the signal's resolution."""
        return float(round(raw * self.scale + self.offset, self.decimals))

    def check(self, raw: int) -> float:
        """Physical value of a raw signal, or ProtocolError when outside its range or choices."""
        value = self.physical(raw)
        if self.choices is not None and raw not in self.choices:
            raise ProtocolError(f"{self.frame}.{self.name}: undefined value {raw}")
        if not self.raw_lo <= raw <= self.raw_hi:
            raise ProtocolError(
                f"{self.frame}.{self.name} = {value:g} outside {self.minimum:g}..{self.maximum:g}"
            )
        return value


@dataclass(frozen=True)
class FrameLayout:
    """Where each signal of a plain frame sits: raw = (payload >> shift) & mask, then
    two's complement for a signed one; and how its values are checked and scaled."""

    name: str
    length: int
    names: tuple[str, ...]
    fields: tuple[tuple[int, int], ...]  # (shift, mask) per signal, in DBC order
    sign_bits: tuple[int, ...]  # 1 << (length - 1) of a signed signal, 0 of an unsigned one
    checks: tuple[SignalCheck, ...]
    checked: tuple[int, ...]  # the signals a raw value can fail (the others need no check)
    ratios: tuple[tuple[int, int], ...] | None  # SignalCheck.ratio of every signal, if all have one
    _guards: tuple[tuple[int, int, int, frozenset[int] | None], ...] = field(
        init=False, repr=False, compare=False
    )
    _signed: bool = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # what SignalCheck.check accepts, as plain values: (index, raw_lo, raw_hi, choices) of
        # every checked signal; check itself runs only to raise a refused signal's error
        guards = tuple((i, c.raw_lo, c.raw_hi, c.choices) for i, c in enumerate(self.checks))
        object.__setattr__(self, "_guards", tuple(guards[i] for i in self.checked))
        object.__setattr__(self, "_signed", any(self.sign_bits))

    def decode(self, data: bytes) -> tuple[tuple[int, ...], tuple[float, ...]]:
        """Raw and physical values in DBC order; ProtocolError for a wrong length or as
        `values`."""
        if len(data) != self.length:
            raise ProtocolError(f"{self.name}: {len(data)} data bytes, expected {self.length}")
        raw = self.raw(data)
        return raw, self.values(raw)

    def raw(self, data: bytes) -> tuple[int, ...]:
        """Raw signal values in DBC order; the caller has checked the length."""
        x = int.from_bytes(data, "little")
        raw = tuple([(x >> s) & m for s, m in self.fields])
        if not self._signed:
            return raw
        return tuple([r - ((r & b) << 1) for r, b in zip(raw, self.sign_bits, strict=True)])

    def values(self, raw: tuple[int, ...]) -> tuple[float, ...]:
        """Physical values in DBC order; ProtocolError as SignalCheck.check for the first
        signal (in DBC order) outside its range or value table."""
        checks = self.checks
        for i, lo, hi, choices in self._guards:
            r = raw[i]
            if not lo <= r <= hi or (choices is not None and r not in choices):
                checks[i].check(r)
        ratios = self.ratios
        if ratios is None:
            return tuple([c.physical(r) for c, r in zip(checks, raw, strict=True)])
        return tuple([r * k / d for r, (k, d) in zip(raw, ratios, strict=True)])


def _raw_all(sig: Any) -> tuple[int, int]:
    """The lowest and highest raw value of a signal's bits."""
    if sig.is_signed:
        return -(1 << (sig.length - 1)), (1 << (sig.length - 1)) - 1
    return 0, (1 << sig.length) - 1


def _raw_bounds(sig: Any, accepts: Callable[[int], bool]) -> tuple[int, int]:
    """The first and last raw value `accepts` (monotone scaling: the accepted values are one
    interval); an empty interval (lo > hi) when none is."""
    lo_all, hi_all = _raw_all(sig)
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


def is_enumeration(sig: Any) -> bool:
    """A signal whose value table lists every value it takes (RunState, SpeedMode). A quantity
    (a signal with a unit) may name special values in its table, such as 0xFFFF "not
    available" of a speed: its other values are numbers within its range."""
    return sig.choices is not None and not sig.unit


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
    choices = None if not is_enumeration(sig) else frozenset(int(k) for k in sig.choices)
    return SignalCheck(
        frame,
        sig.name,
        sig.scale,
        sig.offset,
        dec,
        sig.minimum,
        sig.maximum,
        choices,
        lo,
        hi,
        _raw_all(sig),
    )


def _compile(msg: Any) -> FrameLayout | None:
    if msg.is_multiplexed():
        return None
    sigs = msg.signals
    if any(s.byte_order != "little_endian" or s.is_float for s in sigs):
        return None
    checks = tuple(signal_check(msg.name, s) for s in sigs)
    ratios = tuple(c.ratio for c in checks)
    exact = tuple(r for r in ratios if r is not None)
    return FrameLayout(
        name=msg.name,
        length=msg.length,
        names=tuple(s.name for s in sigs),
        fields=tuple((s.start, (1 << s.length) - 1) for s in sigs),
        sign_bits=tuple(1 << (s.length - 1) if s.is_signed else 0 for s in sigs),
        checks=checks,
        checked=tuple(i for i, c in enumerate(checks) if not c.always_valid),
        ratios=exact if len(exact) == len(ratios) else None,
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


#: A compiled encoder: physical values by signal name -> the payload, or None when the values
#: need cantools (to encode them or to raise its error).
Encoder = Callable[[Mapping[str, Any]], bytes | None]


@cache
def encoder(name: str) -> Encoder | None:
    """The compiled encoder of frame `name`; None for a frame without a layout."""
    lay = layout(name)
    if lay is None:
        return None
    msg = message(name)
    plan = tuple(
        (
            sig.name,
            sig.conversion,
            shift,
            mask,
            # cantools' strict range check: the DBC range widened by a millionth of the scale
            -math.inf if sig.minimum is None else sig.minimum - abs(sig.conversion.scale) * 1e-6,
            math.inf if sig.maximum is None else sig.maximum + abs(sig.conversion.scale) * 1e-6,
            sig.conversion.choices or None,
            check.raw_all,
        )
        for sig, (shift, mask), check in zip(msg.signals, lay.fields, lay.checks, strict=True)
    )
    length = lay.length

    def encode(values: Mapping[str, Any]) -> bytes | None:
        if len(values) != len(plan):
            return None
        x = 0
        for sig_name, conv, shift, mask, lo, hi, choices, (raw_lo, raw_hi) in plan:
            value = values.get(sig_name)
            if value is None or type(value) not in (int, float):  # bool, str: cantools
                return None
            raw = conv.numeric_scaled_to_raw(value)
            in_table = choices is not None and raw in choices
            if not (in_table or lo <= value <= hi) or not raw_lo <= raw <= raw_hi:
                return None
            x |= (raw & mask) << shift
        return x.to_bytes(length, "little")

    return encode
