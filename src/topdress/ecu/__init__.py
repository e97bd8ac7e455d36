"""The C ECU core inside Python (cffi, API mode): the same code as on the microcontroller."""

from topdress.ecu.core import Ecu, EcuCounters, EcuState, Outputs
from topdress.ecu.helpers import (
    Pid,
    cv_pct,
    meter_rate_kg_ha,
    meter_target_rpm,
    slip_measured_pct,
    slip_model_pct,
    slip_model_speed_kmh,
    speed_rule,
    wheel_speed_kmh,
)
from topdress.ecu.params import EcuParams

__all__ = [
    "Ecu",
    "EcuCounters",
    "EcuParams",
    "EcuState",
    "Outputs",
    "Pid",
    "cv_pct",
    "meter_rate_kg_ha",
    "meter_target_rpm",
    "slip_measured_pct",
    "slip_model_pct",
    "slip_model_speed_kmh",
    "speed_rule",
    "wheel_speed_kmh",
]
