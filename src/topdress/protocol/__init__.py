"""The CAN protocol of topdress (protocol/topdress.dbc) with cantools: typed encode/decode."""

from topdress.protocol.dbc import database, dbc_text
from topdress.protocol.frames import (
    EcuDiag,
    EcuParamAck,
    EcuSpeeds,
    EcuStatus,
    EcuTargets,
    Frame,
    PcCommand,
    PcParamSet,
    decode,
    encode_command,
    encode_param_set,
    is_known_id,
)
from topdress.protocol.model import (
    DEFAULT_IDS,
    LATCHED_FAULTS,
    AckResult,
    CanFrame,
    Compare,
    Fault,
    FrameIds,
    Source,
    SpeedMode,
)
from topdress.protocol.params import ParamSpec, param, param_name, params

__all__ = [
    "DEFAULT_IDS",
    "LATCHED_FAULTS",
    "AckResult",
    "CanFrame",
    "Compare",
    "EcuDiag",
    "EcuParamAck",
    "EcuSpeeds",
    "EcuStatus",
    "EcuTargets",
    "Fault",
    "Frame",
    "FrameIds",
    "ParamSpec",
    "PcCommand",
    "PcParamSet",
    "Source",
    "SpeedMode",
    "database",
    "dbc_text",
    "decode",
    "encode_command",
    "encode_param_set",
    "is_known_id",
    "param",
    "param_name",
    "params",
]
