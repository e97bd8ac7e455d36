"""The Snapshot: what the control loop knows at one tick, and the view types inside it.

The one contract between the loop and everything that shows or records it: the console, the
display (in its own process) and the session log's state row all render from a Snapshot. It
depends on the protocol and the catalogue only, so a screen needs nothing of the loop.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from topdress import protocol
from topdress.i18n import Text, text
from topdress.view.commands import ManualView

TICK_S = 0.1  # the control tick, and the period of snapshots and state rows (10 Hz)


#: Snapshot.zone while the outlet's position is dead reckoned past its limit.
ZONE_UNKNOWN = "unknown"


@dataclass(frozen=True)
class AlarmView:
    name: str
    text: Text  # the alarm with its figures
    state: str  # active | acked | cleared
    since_s: float  # terminal time the alarm came


@dataclass(frozen=True)
class CounterView:
    area_ha: float = 0.0
    kg: tuple[float, float] = (0.0, 0.0)  # upper, lower
    work_s: float = 0.0  # time with a meter turning
    distance_m: float = 0.0  # distance worked
    since: str = ""  # ISO date and time of the last reset

    def add(self, area_ha: float, kg: tuple[float, float], dt_s: float, d_m: float) -> CounterView:
        return replace(
            self,
            area_ha=self.area_ha + area_ha,
            kg=(self.kg[0] + kg[0], self.kg[1] + kg[1]),
            work_s=self.work_s + dt_s,
            distance_m=self.distance_m + d_m,
        )


@dataclass(frozen=True)
class TankView:
    """The product in the tank: the fill the operator entered, what is left of it after what
    the meters applied since (both layers draw on it), and the level that raises an alarm.
    None: no fill entered since the terminal started."""

    fill_kg: float | None = None
    remaining_kg: float | None = None
    alarm_kg: float = 0.0


@dataclass(frozen=True)
class CalibrationView:
    kind: str  # catch | wheel | fan
    step: str  # running | weigh | drive | done | aborted
    text: Text
    progress: float = 0.0  # 0..1
    result: dict[str, float] = field(default_factory=dict)
    key: str = ""  # the configuration key the result would set ("" for the fan check)


@dataclass(frozen=True)
class DeviceLine:
    t_s: float
    raw: str
    decoded: str


#: Where the GNSS lag in use comes from (EcuGnssLag.LagState 0..3, docs/protocol.md).
LAG_STATES = ("start", "learned", "fixed", "overruled")


@dataclass(frozen=True)
class LagView:
    """The GNSS lag as the ECU reports it (EcuGnssLag): the one in use, the one learned from
    the wheel (None until learned), where the one in use comes from (LAG_STATES) and the
    configured fixed lag ([ecu] gnss_lag_ms; None for "auto")."""

    in_use_ms: int
    learned_ms: int | None
    state: str
    fixed_ms: float | None = None

    @classmethod
    def of(cls, frame: protocol.EcuGnssLag, fixed_ms: float | None) -> LagView:
        state = LAG_STATES[frame.state] if 0 <= frame.state < len(LAG_STATES) else "start"
        return cls(frame.in_use_ms, frame.learned_ms, state, fixed_ms)

    def text(self) -> Text:
        """One short text: "GNSS lag 0.95 s (learned)"."""
        s = self.in_use_ms / 1000
        if self.state == "overruled" and self.fixed_ms is not None:
            return text("lag.overruled", s=s, fixed=self.fixed_ms / 1000)
        return text(f"lag.{self.state}", s=s)


@dataclass(frozen=True)
class ControlFunctionView:
    """A control function heard claiming an address on ISOBUS, its NAME decoded (ISO 11783-5)."""

    address: int
    name: int  # the 64-bit NAME
    function: int  # 130 task controller, 29 virtual terminal, 128+ by device class
    device_class: int  # with industry group 2: 4 fertilizers, 5 sprayers, ...
    industry_group: int
    manufacturer_code: int
    identity_number: int


@dataclass(frozen=True)
class ProductView:
    """One product (a bin element of the implement's DDOP) and its rates: in kg/ha for a
    mass-per-area setpoint (DDI 6), in L/ha for volume per area (DDI 1)."""

    element: int
    setpoint_ddi: int  # 6 or 1
    unit: str  # kg/ha | L/ha
    setpoint: float  # what the terminal sent last
    actual: float | None = None  # what the implement reports (DDI 7 or 2); None: not yet
    total: float | None = None  # its total (DDI 81 kg, DDI 80 L); None: not reported


@dataclass(frozen=True)
class IsobusView:
    """The terminal as a Task Controller, and the implement it serves (can.implement isobus)."""

    tc_address: int | None = None  # None while claiming, or no address could be claimed
    state: str = "wait"  # wait (no implement with an active pool), ok, lost, refused
    implement_address: int | None = None
    implement: str = ""  # the DDOP's device designator
    products: tuple[ProductView, ...] = ()
    sections: tuple[bool, ...] = ()  # the implement's sections (DDI 161), on/off in pool order
    work_state: bool | None = None  # DDI 141; None: not reported
    setpoint_latency_ms: int | None = None  # DDI 142 in its DDOP (None: the [lookahead] times)
    actual_latency_ms: int | None = None  # DDI 143
    lookahead_s: float = 0.0  # the look-ahead in force
    functions: tuple[ControlFunctionView, ...] = ()  # every control function heard, by address
    problem: Text | str = ""  # the last thing wrong: a message (i18n.render), a library's words


@dataclass(frozen=True)
class Snapshot:
    """The loop's state at one tick: what the console and the display show and the session log's
    state row records (topdress.log.rows.state_row)."""

    t_s: float = 0.0
    running: bool = False
    source: str = "none"
    # The ECU's speeds (EcuSpeeds, else EcuStatus): the one it meters with, the wheel's, and
    # the GNSS speed it compares (None: it has none). The state row logs these same values.
    v_kmh: float = 0.0
    v_wheel_kmh: float = 0.0
    v_gnss_kmh: float | None = None
    cv_pct: float | None = None
    uniform: bool = False
    ndvi_sensors: float | None = None
    ndvi: float | None = None
    rate_kg_ha: tuple[float, float] = (0.0, 0.0)
    target_rpm: tuple[float, float] = (0.0, 0.0)
    meter_rpm: tuple[float, float] = (0.0, 0.0)
    fan_rpm: tuple[float, float] = (0.0, 0.0)
    faults: int = 0
    # Whether the ECU's values above (running .. faults) are live; while the ECU is not heard
    # they are unknown (source none, zeros, as in the state row) and shown as such.
    ecu_live: bool = False
    # The receiver's speed as the terminal sends it to the ECU (None: no fix, stale, lost):
    # known, and shown, while the ECU is not heard.
    gnss_kmh: float | None = None
    ecu_link: str = "wait"  # wait (parameters not all acknowledged yet), ok, lost
    ecu_where: str = ""  # the CAN interface:channel the terminal listens on
    ecu_ident: Text | None = None  # "stm32f4 firmware 0.1.0, protocol 1.1" (EcuIdent)
    ecu_protocol: tuple[str, str] | None = None  # (the ECU's, the terminal's) when they differ
    ecu_can_health: Text | None = None  # a firmware's CAN controller (EcuCanHealth)
    gnss_link: str = "wait"  # wait, ok, no fix, lost
    crop_link: str = "wait"  # wait, ok, "3/4" (fresh of configured), silent, lost
    lat: float | None = None
    lon: float | None = None
    distance_m: float = 0.0
    counters: dict[str, int] = field(default_factory=dict)
    last_event: Text | None = None
    # The operator's side (topdress.terminal.desk): run state, manual mode, alarms, counters.
    operator: str = "stopped"  # stopped, running, paused, calibrating
    manual: ManualView = field(default_factory=ManualView)
    rate_model_kg_ha: tuple[float, float] = (0.0, 0.0)  # the NDVI model's, before manual/pause
    # why the ECU meters on its source (CV and speed against thresholds); None: ECU not heard
    speed_why: Text | None = None
    alarms: tuple[AlarmView, ...] = ()
    count_field: CounterView = field(default_factory=CounterView)  # this field's counter
    count_season: CounterView = field(default_factory=CounterView)
    count_undo: tuple[str, ...] = ()  # counters reset since the start that can be put back
    tank: TankView = field(default_factory=TankView)
    calibration: CalibrationView | None = None
    settings_pending: bool = False
    settings_state: dict[str, str] = field(default_factory=dict)  # key -> pending/ok/refused..
    ndvi_per_sensor: tuple[float | None, ...] = ()  # sensor 1..n; None where not fresh
    cv_threshold_pct: float = 4.2  # the speed rule's thresholds in force
    switch_speed_kmh: float = 6.0
    applied_kg_ha: tuple[float, float] = (0.0, 0.0)  # from the measured metering speeds
    utc: tuple[float, str] | None = None  # (POSIX s, "gnss" | "system")
    heading_deg: float | None = None
    outlet_lat: float | None = None  # the meters' outlet (antenna + [machine] offsets)
    outlet_lon: float | None = None
    # field boundary: field, headland, outside; ZONE_UNKNOWN: the position dead reckoned past
    # gnss.dead_reckon_m (an estimate); None = no boundary
    zone: str | None = None
    prescription_kg_ha: float | None = None  # the prescription map's rate at the outlet
    gnss_lag: LagView | None = None  # the ECU's GNSS lag (None: no EcuGnssLag heard)
    # can.implement isobus: the Task Controller and its implement (None: the topdress ECU)
    isobus: IsobusView | None = None


def ecu_values(
    status: protocol.EcuStatus | None,
    diag: protocol.EcuDiag | None,
    speeds: protocol.EcuSpeeds | None,
    targets: protocol.EcuTargets | None,
) -> dict[str, Any]:
    """The Snapshot fields the ECU's frames give. A frame not received yet gives zeros (and
    source "none"); speeds come at 0.01 km/h from EcuSpeeds, else at 0.1 km/h from EcuStatus."""
    if speeds is not None:
        v_wheel, v_gnss, v = speeds.wheel_kmh, speeds.gnss_kmh, speeds.selected_kmh
    else:
        v_wheel = status.wheel_kmh if status is not None else 0.0
        v_gnss, v = None, v_wheel
    st, tg = status, targets
    return dict(
        running=st.running if st is not None else False,
        source=str(diag.source) if diag is not None else "none",
        v_kmh=v,
        v_wheel_kmh=v_wheel,
        v_gnss_kmh=v_gnss,
        cv_pct=diag.cv_pct if diag is not None else None,
        uniform=diag.uniform if diag is not None else False,
        target_rpm=(tg.target_rpm_upper, tg.target_rpm_lower) if tg else (0.0, 0.0),
        meter_rpm=(st.meter_rpm_upper, st.meter_rpm_lower) if st else (0.0, 0.0),
        fan_rpm=(st.fan_rpm_upper, st.fan_rpm_lower) if st else (0.0, 0.0),
        faults=int(diag.faults) if diag is not None else 0,
    )
