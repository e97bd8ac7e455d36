"""The simulator: the plant models, the World with the C ECU core in the loop, the experiments."""

from topdress.sim.tractor import Drive, Segment, Tractor, TractorParams
from topdress.sim.world import SimConfig, StepOutput, Truth, World

__all__ = [
    "Drive",
    "Segment",
    "SimConfig",
    "StepOutput",
    "Tractor",
    "TractorParams",
    "Truth",
    "World",
]
