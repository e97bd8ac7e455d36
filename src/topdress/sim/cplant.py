"""The bridge to the plant's C code (csrc/plant.c, compiled into topdress.ecu._core).

The devices' classes keep their parameters (fault knobs included) and their seeded random
streams in Python; their state lives in a C struct, stepped by the same arithmetic the Python
models had, so a seed gives the same numbers bit for bit. A stream's random() draws reach
the C code in blocks (`attach`, `refill`) and become the normal draws random.gauss would give.
"""

from __future__ import annotations

import random
from typing import Any

from topdress.ecu._core import ffi, lib

__all__ = ["attach", "ffi", "lib", "refill"]

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
