"""The bridge to the plant's C code (csrc/plant.c, compiled into topdress.ecu._core).

The devices' classes keep their parameters (fault knobs included) and their seeded random
streams in Python; their state lives in a C struct, stepped by the same arithmetic the Python
models had, so a seed gives the same numbers bit for bit. A stream's random() draws reach
the C code in blocks (`attach`, `refill`) and become the normal draws random.gauss would give.
"""

from __future__ import annotations

import random
from operator import attrgetter
from typing import Any, Generic, TypeVar, overload

from topdress.ecu._core import ffi, lib

__all__ = ["CField", "attach", "ffi", "lib", "refill"]

_BLOCK: int = lib.TDSIM_UNIFORM_BLOCK


def attach(rng: random.Random, block: Any) -> None:
    """Make tdsim_gauss_t `block` the rest of rng's gauss stream: the second value of a pair
    that rng.gauss keeps for its next call (the pure-Python random.gauss holds it in
    `gauss_next`) moves over, then the block is filled."""
    state = vars(rng)
    kept = state.get("gauss_next")
    if kept is not None:
        block.kept, block.has_kept = kept, 1
        state["gauss_next"] = None
    block.n = block.next = 0
    refill(rng, block)


def refill(rng: random.Random, block: Any) -> None:
    """Top tdsim_gauss_t `block` up with rng's next random() draws, after those still unused."""
    left = list(block.u[block.next : block.n])
    r = rng.random
    block.u[0:_BLOCK] = left + [r() for _ in range(_BLOCK - len(left))]
    block.n = _BLOCK
    block.next = 0


T = TypeVar("T")


class CField(Generic[T]):
    """A device's attribute that lives in its C struct, `self._s.<field>`: read, and written
    only if `writable` (the others are the C step's to change)."""

    def __init__(self, field: str, doc: str = "", writable: bool = False) -> None:
        self._field = field
        self._read = attrgetter("_s." + field)  # C-level: the simulator reads these every step
        self._writable = writable
        self.__doc__ = doc

    def __set_name__(self, owner: type, name: str) -> None:
        self._name = name

    @overload
    def __get__(self, obj: None, owner: type | None = None) -> CField[T]: ...
    @overload
    def __get__(self, obj: object, owner: type | None = None) -> T: ...
    def __get__(self, obj: object | None, owner: type | None = None) -> CField[T] | T:
        if obj is None:
            return self
        value: T = self._read(obj)
        return value

    def __set__(self, obj: object, value: T) -> None:
        if not self._writable:
            raise AttributeError(f"{self._name} is set by the plant's C step")
        setattr(obj._s, self._field, value)  # type: ignore[attr-defined]
