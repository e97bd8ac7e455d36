"""The CAN protocol of topdress (protocol/topdress.dbc) with cantools: typed encode/decode.

The codes, fault bits and frame ids (topdress.protocol.model) and the table of ECU parameters
(topdress.protocol.params) load without cantools; the frames (encode, decode) and the database
load it, with python-can, on first use. A screen that only shows a Snapshot needs neither.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from topdress.protocol.model import (
    DEFAULT_IDS,
    FAULT_NAMES,
    LATCHED_FAULTS,
    AckResult,
    CanFrame,
    Compare,
    Fault,
    FrameIds,
    Source,
    SpeedMode,
    fault_names,
)
from topdress.protocol.params import ParamSpec, param, param_name, params

if TYPE_CHECKING:
    from topdress.protocol.dbc import database, dbc_text, protocol_version
    from topdress.protocol.frames import (
        BUS_STATES,
        CAL_REASONS,
        CAL_STATES,
        FAULT_KINDS,
        FAULT_REGISTERS,
        RESET_CAUSES,
        TARGETS,
        TRANSPORTS,
        EcuCalStatus,
        EcuCanHealth,
        EcuDiag,
        EcuFaultRecord,
        EcuFused,
        EcuFusedAux,
        EcuGnssLag,
        EcuIdent,
        EcuParamAck,
        EcuSpeeds,
        EcuStatus,
        EcuTargets,
        Frame,
        PcCalCommand,
        PcCommand,
        PcGnssTime,
        PcParamSet,
        decode,
        encode_cal_command,
        encode_command,
        encode_gnss_time,
        encode_param_set,
        is_known_id,
    )

# from dbc.py; the rest of __all__ not imported above is frames.py's
_FROM_DBC = ("database", "dbc_text", "protocol_version")


def __getattr__(name: str) -> Any:
    """The names of the frames and the database, imported on first use."""
    if name not in __all__:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    module = "topdress.protocol." + ("dbc" if name in _FROM_DBC else "frames")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


__all__ = [
    "BUS_STATES",
    "CAL_REASONS",
    "CAL_STATES",
    "DEFAULT_IDS",
    "FAULT_KINDS",
    "FAULT_NAMES",
    "FAULT_REGISTERS",
    "LATCHED_FAULTS",
    "RESET_CAUSES",
    "TARGETS",
    "TRANSPORTS",
    "AckResult",
    "CanFrame",
    "Compare",
    "EcuCalStatus",
    "EcuCanHealth",
    "EcuDiag",
    "EcuFaultRecord",
    "EcuFused",
    "EcuFusedAux",
    "EcuGnssLag",
    "EcuIdent",
    "EcuParamAck",
    "EcuSpeeds",
    "EcuStatus",
    "EcuTargets",
    "Fault",
    "Frame",
    "FrameIds",
    "ParamSpec",
    "PcCalCommand",
    "PcCommand",
    "PcGnssTime",
    "PcParamSet",
    "Source",
    "SpeedMode",
    "database",
    "dbc_text",
    "decode",
    "encode_cal_command",
    "encode_command",
    "encode_gnss_time",
    "encode_param_set",
    "fault_names",
    "is_known_id",
    "param",
    "param_name",
    "params",
    "protocol_version",
]
