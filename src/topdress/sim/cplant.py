"""The bridge to the plant's C code (csrc/plant.c, compiled into topdress.ecu._core).

The devices' classes keep their parameters (fault knobs included) and their seeded random
streams in Python; their state lives in a C struct, stepped by the same arithmetic the Python
models had, so a seed gives the same numbers bit for bit. Random draws reach the C code in
blocks: `refill` hands over the stream's next N(0, 1) draws, used in the order drawn.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from topdress.ecu._core import ffi, lib

__all__ = ["ffi", "lib", "refill"]

_BLOCK: int = lib.TDSIM_GAUSS_BLOCK


def refill(gauss: Callable[[float, float], float], block: Any) -> None:
    """Give a used-up tdsim_gauss_t the next draws of `gauss` (a random.Random's gauss)."""
    if block.next < block.n:
        raise RuntimeError("a block of random draws refilled before it was used up")
    block.v[0:_BLOCK] = [gauss(0.0, 1.0) for _ in range(_BLOCK)]
    block.n = _BLOCK
    block.next = 0
