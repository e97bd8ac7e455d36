"""Typed encode/decode of every frame of protocol/topdress.dbc, in physical units.

Decoding never returns a half-valid value: an unknown identifier, a wrong length, a raw value
outside the DBC range or an undefined enum value raises ProtocolError, as the C core rejects it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from typing import Any

import can
import cantools

from topdress.errors import ProtocolError
from topdress.protocol.dbc import message, snake, value_table
from topdress.protocol.layout import FrameLayout, checks, encoder, layout
from topdress.protocol.model import (
    DEFAULT_IDS,
    AckResult,
    CanFrame,
    Compare,
    Fault,
    FrameIds,
    Source,
    SpeedMode,
)
from topdress.protocol.params import ParamSpec, param

GNSS_NA_RAW = 0xFF  # PcCommand.GnssSpeed: "not available"
GNSS_MAX_KMH = 25.0  # raw 251..254 are out of range
NA_RAW_16 = 0xFFFF  # EcuDiag.Cv undefined, EcuSpeeds.GnssSpeedFine not valid
_RUN = next(k for k, v in value_table("PcCommand", "StartStop").items() if v == "Start")


def _words(frame: str, signal: str, sep: str = " ") -> tuple[str, ...]:
    """The names of a DBC value table in code order, in lower-case words: "BadValue" ->
    "bad value" (`sep` between the words)."""
    table = value_table(frame, signal)
    if list(table) != list(range(len(table))):
        raise ProtocolError(f"{frame}.{signal}: the codes are not 0..{len(table) - 1}")
    return tuple(snake(name).replace("_", sep) for name in table.values())


@dataclass(frozen=True)
class PcCommand:
    """PC -> ECU command (paper Table 1); gnss_kmh None = not available."""

    start: bool
    fan_rpm: float
    rate_upper_kg_ha: float
    rate_lower_kg_ha: float
    gnss_kmh: float | None


@dataclass(frozen=True)
class EcuStatus:
    """ECU -> PC status (paper Table 1)."""

    running: bool
    meter_rpm_upper: float
    meter_rpm_lower: float
    fan_rpm_upper: float
    fan_rpm_lower: float
    wheel_kmh: float


@dataclass(frozen=True)
class EcuDiag:
    """Speed source, CV (None = undefined), fault word, cumulative wheel pulses mod 2^24."""

    source: Source
    mode: SpeedMode
    gnss_valid: bool
    uniform: bool
    compare: Compare
    cv_pct: float | None
    faults: Fault
    wheel_pulses: int


@dataclass(frozen=True)
class EcuSpeeds:
    """Both speeds and the selected one at 0.01 km/h; gnss_kmh None = not valid."""

    wheel_kmh: float
    gnss_kmh: float | None
    selected_kmh: float
    rx_rejected: int


@dataclass(frozen=True)
class EcuTargets:
    """Target metering speeds and the PWM duties, %."""

    target_rpm_upper: float
    target_rpm_lower: float
    meter_duty_pct_upper: float
    meter_duty_pct_lower: float
    fan_duty_pct_upper: float
    fan_duty_pct_lower: float


@dataclass(frozen=True)
class PcParamSet:
    """Write one ECU parameter (physical value, units of td_params.h)."""

    param_id: int
    value: float

    @property
    def spec(self) -> ParamSpec:
        return param(self.param_id)


@dataclass(frozen=True)
class EcuParamAck:
    """Answer to PcParamSet: the result and the value now in force (raw DBC units)."""

    param_id: int
    result: AckResult
    raw: int

    @property
    def value(self) -> float | None:
        """The value in force in physical units; None for an unknown parameter id."""
        try:
            return param(self.param_id).from_raw(self.raw)
        except ProtocolError:
            return None


@dataclass(frozen=True)
class PcCalCommand:
    """Calibration command: catch test of one layer (action 1) or reset/abort (action 0)."""

    action: int
    layer: int  # 0 upper, 1 lower
    revolutions: float
    meter_rpm: float
    seq: int


#: EcuCalStatus.CalState and CalReason (DBC value tables).
CAL_STATES = _words("EcuCalStatus", "CalState")
CAL_REASONS = _words("EcuCalStatus", "CalReason")


@dataclass(frozen=True)
class EcuCalStatus:
    """Catch test state; revolutions counted on the meter encoder since the test began."""

    state: str  # CAL_STATES
    layer: int
    reason: str  # CAL_REASONS
    revolutions: float
    meter_rpm: float
    seq: int


@dataclass(frozen=True)
class PcGnssTime:
    """PC -> ECU: the GNSS speed (None = not available) with the age of its fix, ms, and the
    fix counter; the ECU applies each new `seq` once, at the fix's time of validity."""

    gnss_kmh: float | None
    age_ms: int
    seq: int


@dataclass(frozen=True)
class EcuFused:
    """The ECU's fused speed estimate: speed, acceleration, learned slip (%), the last GNSS
    innovation (km/h), flags and the 1-sigma speed uncertainty (km/h, saturates at 1.55)."""

    speed_kmh: float
    accel_ms2: float
    slip_pct: float
    innovation_kmh: float
    slip_learning: bool
    edge_timing: bool
    gnss_fused: bool
    speed_std_kmh: float


@dataclass(frozen=True)
class EcuFusedAux:
    """Edge-timed wheel speed (no slip correction), the look-ahead speed that drives eq. 4,
    the learned metering drive slopes (r/min per unit duty) and the last GNSS delay (ms)."""

    wheel_edge_kmh: float
    lead_kmh: float
    drive_slope_upper: float
    drive_slope_lower: float
    gnss_delay_ms: int


LAG_NONE_RAW = 0xFFFF  # EcuGnssLag.LagLearned: not learned yet


@dataclass(frozen=True)
class EcuGnssLag:
    """The GNSS lag the ECU adds to every fix's age (ms), the one it learned from the wheel
    (ms, None until learned), the seconds of speed change behind it and how far the last change
    found it off (share of it, 0..1; 1 before any change settled), where
    the lag in use comes from (0 start value, 1 learned, 2 fixed, 3 a fixed lag overruled by
    the data) and whether GnssLagAuto is on."""

    in_use_ms: int
    learned_ms: int | None
    evidence_s: float
    fit: float
    state: int
    automatic: bool


#: EcuIdent's value tables (DBC): the target, the transport, the cause of the last reset.
TARGETS = _words("EcuIdent", "Target")
TRANSPORTS = _words("EcuIdent", "Transport", "-")
RESET_CAUSES = _words("EcuIdent", "ResetCause", "-")


@dataclass(frozen=True)
class EcuIdent:
    """Who the ECU is: target, firmware version, the protocol (DBC) version it was built with,
    its transport, the cause of its last reset, whether its clock fell back to the internal
    oscillator, and whether it runs on its firmware defaults (no parameter taken since
    power-up: it restarted)."""

    target: str  # TARGETS
    firmware: tuple[int, int, int]
    protocol: tuple[int, int]
    transport: str  # TRANSPORTS
    reset_cause: str  # RESET_CAUSES
    clock_fallback: bool
    on_defaults: bool = False

    @property
    def firmware_version(self) -> str:
        return ".".join(str(v) for v in self.firmware)

    @property
    def protocol_version(self) -> str:
        return f"{self.protocol[0]}.{self.protocol[1]}"


#: EcuCanHealth's bus states and EcuFaultRecord's registers and kinds (DBC value tables).
BUS_STATES = ("error-active", "error-passive", "bus-off")
FAULT_REGISTERS = ("CFSR", "HFSR", "MMFAR", "BFAR", "PC", "LR")
FAULT_KINDS = ("none", "hard fault", "crystal failure")


@dataclass(frozen=True)
class EcuCanHealth:
    """The firmware's CAN controller, once a second: its transmit and receive error counters
    (0..255), its state (BUS_STATES), the entries into error-passive and bus-off since it
    started and the receive FIFO overruns (each saturating at its field's maximum)."""

    tx_errors: int
    rx_errors: int
    bus_state: str  # BUS_STATES
    error_passive_count: int
    bus_off_count: int
    rx_overruns: int


@dataclass(frozen=True)
class EcuFaultRecord:
    """One register of what the firmware's fault handler kept across its reset: the register
    (FAULT_REGISTERS), the kind of fault (FAULT_KINDS) and its value."""

    register: str  # FAULT_REGISTERS
    kind: str  # FAULT_KINDS
    value: int


Frame = (
    PcCommand
    | EcuStatus
    | EcuDiag
    | EcuSpeeds
    | EcuTargets
    | PcParamSet
    | EcuParamAck
    | PcCalCommand
    | EcuCalStatus
    | PcGnssTime
    | EcuFused
    | EcuFusedAux
    | EcuGnssLag
    | EcuIdent
    | EcuCanHealth
    | EcuFaultRecord
)


def _frame_parts(frame: can.Message | CanFrame) -> tuple[int, bytes]:
    if isinstance(frame, can.Message):
        if frame.is_remote_frame or frame.is_error_frame:
            raise ProtocolError(f"CAN id 0x{frame.arbitration_id:08X}: remote or error frame")
        return frame.arbitration_id, bytes(frame.data)
    frame_id, data = frame
    return frame_id, bytes(data)


def _decode_raw(name: str, data: bytes) -> dict[str, int]:
    """Raw signal values of frame `name`, every one checked against the DBC."""
    lay = layout(name)
    if lay is not None:
        if len(data) != lay.length:
            raise ProtocolError(f"{name}: {len(data)} data bytes, expected {lay.length}")
        return dict(zip(lay.names, lay.raw(data), strict=True))
    msg = message(name)
    if len(data) != msg.length:
        raise ProtocolError(f"{name}: {len(data)} data bytes, expected {msg.length}")
    try:
        raw: dict[str, int] = msg.decode(data, decode_choices=False, scaling=False)
    except cantools.database.DecodeError as exc:  # an undefined multiplexer id
        raise ProtocolError(f"{name}: {exc}") from None
    return raw


@cache
def _plain(name: str, *signals: str) -> FrameLayout:
    """The layout of plain frame `name`, whose signals are `signals` in DBC order: the
    decoders below unpack them by position, so a DBC that moves a signal stops them here."""
    lay = layout(name)
    if lay is None or lay.names != signals:
        raise ProtocolError(f"{name}: the DBC's signals are not {', '.join(signals)}")
    return lay


def _check(name: str, signal: str, raw: int) -> float:
    """Physical value of a raw signal, or ProtocolError when outside its range or choices."""
    return checks()[(name, signal)].check(raw)


def _decode_command(data: bytes) -> PcCommand:
    raw = _decode_raw("PcCommand", data)
    g = raw["GnssSpeed"]
    if GNSS_MAX_KMH / 0.1 < g < GNSS_NA_RAW:
        raise ProtocolError(f"PcCommand.GnssSpeed raw {g} is out of range (0..250, 255 = n/a)")
    return PcCommand(
        start=_check("PcCommand", "StartStop", raw["StartStop"]) == _RUN,
        fan_rpm=_check("PcCommand", "FanSpeed", raw["FanSpeed"]),
        rate_upper_kg_ha=_check("PcCommand", "UpperRate", raw["UpperRate"]),
        rate_lower_kg_ha=_check("PcCommand", "LowerRate", raw["LowerRate"]),
        gnss_kmh=None if g == GNSS_NA_RAW else _check("PcCommand", "GnssSpeed", g),
    )


def _decode_status(data: bytes) -> EcuStatus:
    _, v = _plain(
        "EcuStatus",
        "RunState",
        "UpperMeterSpeed",
        "LowerMeterSpeed",
        "UpperFanSpeed",
        "LowerFanSpeed",
        "WheelSpeed",
    ).decode(data)
    return EcuStatus(v[0] == _RUN, v[1], v[2], v[3], v[4], v[5])


def _decode_diag(data: bytes) -> EcuDiag:
    (source, mode, gnss_valid, uniform, compare, cv, faults, pulses), v = _plain(
        "EcuDiag",
        "SpeedSource",
        "SpeedMode",
        "GnssValid",
        "Uniform",
        "SwitchCompare",
        "Cv",
        "FaultWord",
        "WheelPulses",
    ).decode(data)
    return EcuDiag(
        source=Source.from_code(source),
        mode=SpeedMode.from_code(mode),
        gnss_valid=bool(gnss_valid),
        uniform=bool(uniform),
        compare=Compare.from_code(compare),
        cv_pct=None if cv == NA_RAW_16 else v[5],
        faults=Fault(faults),
        wheel_pulses=pulses,
    )


def _decode_speeds(data: bytes) -> EcuSpeeds:
    raw, v = _plain(
        "EcuSpeeds", "WheelSpeedFine", "GnssSpeedFine", "SelectedSpeed", "RxRejected"
    ).decode(data)
    return EcuSpeeds(v[0], None if raw[1] == NA_RAW_16 else v[1], v[2], raw[3])


def _decode_targets(data: bytes) -> EcuTargets:
    _, v = _plain(
        "EcuTargets",
        "UpperTargetSpeed",
        "LowerTargetSpeed",
        "UpperDuty",
        "LowerDuty",
        "UpperFanDuty",
        "LowerFanDuty",
    ).decode(data)
    return EcuTargets(v[0], v[1], v[2], v[3], v[4], v[5])


def _decode_param_set(data: bytes) -> PcParamSet:
    raw = _decode_raw("PcParamSet", data)
    spec = param(raw["ParamId"])
    return PcParamSet(spec.id, _check("PcParamSet", spec.signal, raw[spec.signal]))


def _decode_param_ack(data: bytes) -> EcuParamAck:
    raw = _decode_raw("EcuParamAck", data)
    try:
        result = AckResult(raw["AckResult"])
    except ValueError:
        raise ProtocolError(f"EcuParamAck.AckResult: undefined value {raw['AckResult']}") from None
    return EcuParamAck(raw["AckParamId"], result, raw["AckRaw"])


def _decode_cal_command(data: bytes) -> PcCalCommand:
    raw = _decode_raw("PcCalCommand", data)
    return PcCalCommand(
        action=int(_check("PcCalCommand", "CalAction", raw["CalAction"])),
        layer=int(_check("PcCalCommand", "CalLayer", raw["CalLayer"])),
        revolutions=raw["CalRevolutions"] * 0.1,
        meter_rpm=raw["CalMeterSpeed"] * 0.01,
        seq=raw["CalSeq"],
    )


def _decode_cal_status(data: bytes) -> EcuCalStatus:
    raw = _decode_raw("EcuCalStatus", data)
    state = int(_check("EcuCalStatus", "CalState", raw["CalState"]))
    reason = int(_check("EcuCalStatus", "CalReason", raw["CalReason"]))
    return EcuCalStatus(
        state=CAL_STATES[state],
        layer=int(_check("EcuCalStatus", "CalLayer", raw["CalLayer"])),
        reason=CAL_REASONS[reason],
        revolutions=raw["CalRevolutions"] * 0.001,
        meter_rpm=raw["CalMeterSpeed"] * 0.01,
        seq=raw["CalSeq"],
    )


def encode_cal_command(
    action: int,
    layer: int = 0,
    revolutions: float = 0.0,
    meter_rpm: float = 0.0,
    seq: int = 0,
    *,
    ids: FrameIds = DEFAULT_IDS,
) -> can.Message:
    """PcCalCommand: action 1 = catch test of `layer` (standing, stopped), 2 = the look-ahead
    test (the same run, with the fans of a started machine running), 0 = reset/abort;
    range-checked."""
    signals = {
        "CalAction": action,
        "CalLayer": layer,
        "CalRevolutions": float(revolutions),
        "CalMeterSpeed": float(meter_rpm),
        "CalSeq": seq % 256,
    }
    return _message(ids.cal_command, _encode("PcCalCommand", signals))


def _decode_gnss_time(data: bytes) -> PcGnssTime:
    raw = _decode_raw("PcGnssTime", data)
    g = raw["GnssSpeedPrecise"]
    if GNSS_MAX_KMH / 0.01 < g < NA_RAW_16:
        raise ProtocolError(
            f"PcGnssTime.GnssSpeedPrecise raw {g} is out of range (0..2500, 65535 = n/a)"
        )
    age = _check("PcGnssTime", "GnssFixAge", raw["GnssFixAge"])
    return PcGnssTime(
        gnss_kmh=None if g == NA_RAW_16 else _check("PcGnssTime", "GnssSpeedPrecise", g),
        age_ms=int(age),
        seq=raw["GnssSeq"],
    )


def _decode_fused(data: bytes) -> EcuFused:
    raw, v = _plain(
        "EcuFused",
        "FusedSpeed",
        "FusedAccel",
        "LearnedSlip",
        "GnssInnovation",
        "SlipLearning",
        "EdgeTiming",
        "GnssFused",
        "SpeedStd",
    ).decode(data)
    return EcuFused(
        speed_kmh=v[0],
        accel_ms2=v[1],
        slip_pct=v[2],
        innovation_kmh=v[3],
        slip_learning=bool(raw[4]),
        edge_timing=bool(raw[5]),
        gnss_fused=bool(raw[6]),
        speed_std_kmh=v[7],
    )


def _decode_fused_aux(data: bytes) -> EcuFusedAux:
    raw, v = _plain(
        "EcuFusedAux",
        "WheelEdgeSpeed",
        "LeadSpeed",
        "UpperDriveSlope",
        "LowerDriveSlope",
        "GnssDelay",
    ).decode(data)
    return EcuFusedAux(v[0], v[1], v[2], v[3], raw[4])


def _decode_gnss_lag(data: bytes) -> EcuGnssLag:
    raw, v = _plain(
        "EcuGnssLag", "LagInUse", "LagLearned", "LagEvidence", "LagFit", "LagState", "LagAuto"
    ).decode(data)
    learned = raw[1]
    return EcuGnssLag(
        in_use_ms=raw[0],
        learned_ms=None if learned == LAG_NONE_RAW else learned,
        evidence_s=v[2],
        fit=raw[3] / 100,
        state=raw[4],
        automatic=bool(raw[5]),
    )


def _decode_ident(data: bytes) -> EcuIdent:
    raw, _ = _plain(
        "EcuIdent",
        "Target",
        "FirmwareMajor",
        "FirmwareMinor",
        "FirmwarePatch",
        "ProtocolMajor",
        "ProtocolMinor",
        "Transport",
        "ResetCause",
        "ClockFallback",
        "OnDefaults",
    ).decode(data)
    return EcuIdent(
        target=TARGETS[raw[0]],
        firmware=(raw[1], raw[2], raw[3]),
        protocol=(raw[4], raw[5]),
        transport=TRANSPORTS[raw[6]],
        reset_cause=RESET_CAUSES[raw[7]],
        clock_fallback=bool(raw[8]),
        on_defaults=bool(raw[9]),
    )


def _decode_can_health(data: bytes) -> EcuCanHealth:
    raw, _ = _plain(
        "EcuCanHealth",
        "TxErrors",
        "RxErrors",
        "BusState",
        "ErrorPassiveCount",
        "BusOffCount",
        "RxOverruns",
    ).decode(data)
    if raw[2] >= len(BUS_STATES):
        raise ProtocolError(f"EcuCanHealth: BusState {raw[2]} is not a state")
    return EcuCanHealth(raw[0], raw[1], BUS_STATES[raw[2]], raw[3], raw[4], raw[5])


def _decode_fault_record(data: bytes) -> EcuFaultRecord:
    raw, _ = _plain("EcuFaultRecord", "RegisterId", "Kind", "Value").decode(data)
    if raw[0] >= len(FAULT_REGISTERS) or raw[1] >= len(FAULT_KINDS):
        raise ProtocolError(f"EcuFaultRecord: register {raw[0]}, kind {raw[1]} out of range")
    return EcuFaultRecord(FAULT_REGISTERS[raw[0]], FAULT_KINDS[raw[1]], raw[2])


def is_known_id(frame_id: int, ids: FrameIds = DEFAULT_IDS) -> bool:
    """True for the identifier of a frame of the protocol (to tell malformed from foreign)."""
    return frame_id in (
        ids.command,
        ids.status,
        ids.diag,
        ids.speeds,
        ids.targets,
        ids.param_set,
        ids.param_ack,
        ids.cal_command,
        ids.cal_status,
        ids.gnss_time,
        ids.fused,
        ids.fused_aux,
        ids.gnss_lag,
        ids.ident,
        ids.can_health,
        ids.fault_record,
    )


def decode(frame: can.Message | CanFrame, ids: FrameIds = DEFAULT_IDS) -> Frame:
    """Decode any frame of the protocol; ProtocolError if it is not one, or not a valid one."""
    frame_id, data = _frame_parts(frame)
    # FrameIds hashes all its fields: look the default table up without hashing it
    table = _DEFAULT_DECODERS if ids is DEFAULT_IDS else _decoders(ids)
    try:
        decoder = table[frame_id]
    except KeyError:
        raise ProtocolError(f"unknown CAN id 0x{frame_id:08X}") from None
    return decoder(data)


@cache
def _decoders(ids: FrameIds) -> dict[int, Callable[[bytes], Frame]]:
    return {
        ids.command: _decode_command,
        ids.status: _decode_status,
        ids.diag: _decode_diag,
        ids.speeds: _decode_speeds,
        ids.targets: _decode_targets,
        ids.param_set: _decode_param_set,
        ids.param_ack: _decode_param_ack,
        ids.cal_command: _decode_cal_command,
        ids.cal_status: _decode_cal_status,
        ids.gnss_time: _decode_gnss_time,
        ids.fused: _decode_fused,
        ids.fused_aux: _decode_fused_aux,
        ids.gnss_lag: _decode_gnss_lag,
        ids.ident: _decode_ident,
        ids.can_health: _decode_can_health,
        ids.fault_record: _decode_fault_record,
    }


_DEFAULT_DECODERS = _decoders(DEFAULT_IDS)


def _message(frame_id: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=frame_id, data=data, is_extended_id=True)


def _encode(name: str, signals: dict[str, Any]) -> bytes:
    for key, value in signals.items():
        if isinstance(value, float) and not math.isfinite(value):
            raise ProtocolError(f"{name}.{key}: {value} is not a number")
    fast = encoder(name)
    if fast is not None and (payload := fast(signals)) is not None:
        return payload
    try:
        data: bytes = message(name).encode(signals, strict=True)
    except (cantools.database.EncodeError, OverflowError) as exc:
        raise ProtocolError(f"{name}: {exc}") from None
    return data


def encode_command(
    start: bool,
    fan_rpm: float,
    rate_upper_kg_ha: float,
    rate_lower_kg_ha: float,
    gnss_kmh: float | None,
    *,
    ids: FrameIds = DEFAULT_IDS,
) -> can.Message:
    """The paper's command frame; gnss_kmh None (no valid GNSS speed) is sent as 0xFF."""
    if gnss_kmh is not None and not 0.0 <= gnss_kmh <= GNSS_MAX_KMH:
        raise ProtocolError(f"PcCommand.GnssSpeed = {gnss_kmh} outside 0..{GNSS_MAX_KMH:g} km/h")
    signals = {
        "StartStop": _RUN if start else 0,
        "FanSpeed": float(fan_rpm),
        "UpperRate": float(rate_upper_kg_ha),
        "LowerRate": float(rate_lower_kg_ha),
        "GnssSpeed": GNSS_NA_RAW * 0.1 if gnss_kmh is None else float(gnss_kmh),
    }
    return _message(ids.command, _encode("PcCommand", signals))


def encode_gnss_time(
    gnss_kmh: float | None, age_ms: int, seq: int, *, ids: FrameIds = DEFAULT_IDS
) -> can.Message:
    """PcGnssTime: the GNSS speed at 0.01 km/h (None = not available), the time from its fix
    (as the PC knows it: the arrival of its sentence) to now in ms (0..10000), and the fix
    counter mod 256 (a new value for every new fix; a repeated one is not applied again)."""
    if gnss_kmh is not None and not 0.0 <= gnss_kmh <= GNSS_MAX_KMH:
        raise ProtocolError(f"PcGnssTime.GnssSpeedPrecise = {gnss_kmh} outside 0..25 km/h")
    signals = {
        "GnssSpeedPrecise": NA_RAW_16 * 0.01 if gnss_kmh is None else float(gnss_kmh),
        "GnssFixAge": int(age_ms),
        "GnssSeq": int(seq) & 0xFF,
    }
    return _message(ids.gnss_time, _encode("PcGnssTime", signals))


def encode_param_set(key: int | str, value: float, *, ids: FrameIds = DEFAULT_IDS) -> can.Message:
    """PcParamSet for one parameter by id, DBC name or EcuParams name; range-checked."""
    spec = param(key)
    spec.check(value)
    data = _encode("PcParamSet", {"ParamId": spec.id, spec.signal: float(value)})
    return _message(ids.param_set, data)
