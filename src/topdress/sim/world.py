"""The World: every plant device and the C ECU core, advanced together in virtual time."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from dataclasses import field as dc_field
from typing import Any

from topdress.config import TerminalConfig
from topdress.ecu import Ecu, EcuParams
from topdress.ecu.params import check
from topdress.protocol import CanFrame
from topdress.sim.actuators import Fan, FanParams, MeterMotor, MeterParams
from topdress.sim.cplant import ffi, lib, refill
from topdress.sim.field import CropSensor, CropSensorParams, Field, FieldParams
from topdress.sim.gnss import EARTH_R_M, GnssParams, GnssReceiver
from topdress.sim.tractor import Drive, Tractor, TractorParams
from topdress.sim.transport import AirLine, AirLineParams
from topdress.sim.wheel import GroundWheel, WheelParams

_U32 = 0xFFFFFFFF
_NO_MEMORY = -1000  # tdsim_world_step: an air line could not grow
_TX_SHIFT: int = lib.TDSIM_TX_SHIFT  # tdsim_world_step's result: frames to drain << this
_FLAGS = (1 << _TX_SHIFT) - 1  # and the flags below it
LAYERS = ("upper", "lower")


@dataclass(frozen=True)
class SimConfig:
    """Every model parameter of the simulated machine (defaults: docs/simulation.md)."""

    dt_s: float = 0.01
    tractor: TractorParams = dc_field(default_factory=TractorParams)
    gnss: GnssParams = dc_field(default_factory=GnssParams)
    wheel: WheelParams = dc_field(default_factory=WheelParams)
    meter: tuple[MeterParams, MeterParams] = (MeterParams(), MeterParams())
    fan: tuple[FanParams, FanParams] = (FanParams(), FanParams())
    airline: tuple[AirLineParams, AirLineParams] = (AirLineParams(), AirLineParams())
    field: FieldParams = dc_field(default_factory=FieldParams)
    crop: CropSensorParams = dc_field(default_factory=CropSensorParams)
    # the crop sensors across the track from the outlets' centre, m (right > 0)
    crop_offsets_m: tuple[float, ...] = (-1.35, -0.45, 0.45, 1.35)
    kg_per_rev: tuple[float, float] = (0.3, 0.3)  # true fertilizer per metering revolution
    ecu: EcuParams | None = None  # None: the ECU's defaults
    bin_m: float = 0.5  # resolution of the applied-fertilizer record along the track
    # where the crop sensors look: this far ahead of the outlets along the track (the
    # terminal's crop.sensor_to_meter_m says the same of the real machine); 0 = at the outlets
    crop_ahead_m: float = 2.0
    # the ECU port captures the time of the wheel's last encoder edge (False: counts only)
    wheel_edges: bool = True
    # loose patches (x, y, radius m) where the ground wheel slips loose_slip_pct (at least)
    loose_patches: tuple[tuple[float, float, float], ...] = ()
    loose_slip_pct: float = 15.0

    @classmethod
    def of_machine(cls, machine: TerminalConfig, **kw: Any) -> SimConfig:
        """The simulated machine with the geometry of a terminal's configuration, so the two
        agree by construction: `crop.sensors` sensors spread evenly across `machine.width_m`,
        `crop.sensor_to_meter_m` ahead of the outlets, the GNSS antenna where
        `machine.outlet_along_m` / `outlet_across_m` put it, the metering wheels' kg/rev as
        calibrated. `kw`: any other SimConfig field."""
        m, crop = machine.machine, machine.crop
        pitch = m.width_m / crop.sensors
        # to the micrometre: the defaults' offsets are then SimConfig's own, bit for bit
        offsets = tuple(round((i + 0.5) * pitch - m.width_m / 2, 6) for i in range(crop.sensors))
        gnss = kw.pop("gnss", GnssParams())
        return cls(
            crop_offsets_m=offsets,
            crop_ahead_m=crop.sensor_to_meter_m,
            gnss=replace(
                gnss, antenna_along_m=-m.outlet_along_m, antenna_across_m=-m.outlet_across_m
            ),
            kg_per_rev=(m.kg_per_rev_upper, m.kg_per_rev_lower),
            **kw,
        )


@dataclass(frozen=True)
class StepOutput:
    """What the devices put out during one step."""

    t_s: float
    nmea: list[str]
    crop: list[str]
    can: list[tuple[int, bytes]]


@dataclass(frozen=True)
class Truth:
    """Ground truth, for analysis (never seen by the ECU or the terminal)."""

    t_s: float
    x_m: float
    y_m: float
    lat_deg: float
    lon_deg: float
    heading_deg: float
    v_kmh: float
    odometer_m: float
    wheel_revolutions: float
    meter_rpm: tuple[float, float]
    fan_rpm: tuple[float, float]
    applied_kg: tuple[float, float]
    in_flight_kg: tuple[float, float]
    first_landing_m: tuple[float | None, float | None]  # odometer where fertilizer first landed
    ndvi: float  # true NDVI under the machine centre


class World:
    """A tractor with the topdresser in a field; step() advances one control period."""

    def __init__(self, cfg: SimConfig | None = None, seed: int = 0, drive: Drive | None = None):
        self.cfg = cfg = cfg or SimConfig()
        self.seed = seed
        dt = cfg.dt_s
        self.dt = dt
        self.tractor = Tractor(cfg.tractor, seed=seed * 7 + 1)
        self.drive = drive or Drive.paper_run(6.5)
        self.gnss = GnssReceiver(cfg.gnss, seed * 7 + 2)
        self.wheel = GroundWheel(cfg.wheel, seed * 7 + 3)
        self.meters = (MeterMotor(cfg.meter[0], dt), MeterMotor(cfg.meter[1], dt))
        self.fans = (Fan(cfg.fan[0], dt), Fan(cfg.fan[1], dt))
        self.airlines = (AirLine(cfg.airline[0]), AirLine(cfg.airline[1]))
        self.field = Field(cfg.field, seed * 7 + 4)
        self.sensors = [
            CropSensor(i + 1, off, cfg.crop, seed * 7 + 5, cfg.crop_ahead_m)
            for i, off in enumerate(cfg.crop_offsets_m)
        ]
        self.ecu = Ecu(cfg.ecu, now_us=0)
        self.t_s = 0.0
        self._step_n = 0
        self.first_landing_m: list[float | None] = [None, None]
        self.first_landing_t: list[float | None] = [None, None]
        self._applied: tuple[dict[int, float], dict[int, float]] = ({}, {})
        # mean true NDVI across the working width under the outlets, by bin (the spot's truth)
        self.ndvi_by_bin: dict[int, float] = {}
        self._crop_next = min(s.next_t for s in self.sensors)
        self._dt_us = round(dt * 1e6)
        # the continuous part of a step runs in C (csrc/plant.c, tdsim_world_step) on the
        # devices' structs; the flags it returns say what is left for Python. The devices are
        # the World's for good: it holds them so their structs live as long as it does.
        self._devices = (self.tractor, self.wheel, *self.meters, *self.fans, *self.airlines)
        ws = self._ws = ffi.new("tdsim_world_t *")
        ws.tractor, ws.wheel = self.tractor._s, self.wheel._s
        ws.meter = [m._s for m in self.meters]
        ws.fan = [f._s for f in self.fans]
        ws.line = [a._s for a in self.airlines]
        ws.dt_s, ws.kg_per_rev, ws.bin_m, ws.bin = dt, cfg.kg_per_rev, cfg.bin_m, -1
        ws.wheel_edges = cfg.wheel_edges
        self._patches = ffi.new("double[]", [v for patch in cfg.loose_patches for v in patch])
        ws.patches, ws.n_patches = self._patches, len(cfg.loose_patches)
        ws.loose_slip_pct, ws.loose_reach2 = cfg.loose_slip_pct, -1.0
        ws.land_bin, ws.done_bin = (-1, -1), (-1, -1)
        self._app = self.ecu._app
        self._step_fn = lib.tdsim_world_step
        self._tx_raw = self.ecu.tx_raw

    @property
    def now_us(self) -> int:
        return (self._step_n * self._dt_us) & _U32

    def deliver_can(self, frame: Any, now_us: int | None = None) -> int:
        """Hand a PC -> ECU frame (can.Message or (id, bytes)) to the ECU; its return code."""
        rc: int = self.ecu.rx(frame, self.now_us if now_us is None else now_us)
        return rc

    def step(self) -> StepOutput:
        """Advance one control period: plant under the last duties, then one ECU step."""
        return StepOutput(*self.step_raw())

    def step_raw(self) -> tuple[float, list[str], list[str], list[CanFrame]]:
        """step() as a plain tuple (t_s, nmea, crop, can): the simulator's inner loop."""
        dt = self.dt
        n = self._step_n + 1
        self._step_n = n
        t = n * dt
        self.t_s = t
        tr = self.tractor
        v_t, k = self.drive.command(tr, dt)
        rc = self._step_fn(self._ws, self._app, t, (n * self._dt_us) & _U32, v_t, k)
        if rc & _FLAGS or rc < 0:
            self._after_step(rc, t)
        gnss = self.gnss
        lines = gnss.step(t, tr.x, tr.y, tr.v, tr.heading) if t + 1e-9 >= gnss.next_due_s else []
        crop: list[str] = []
        if t + 1e-9 >= self._crop_next:
            x, y, h = tr.x, tr.y, tr.heading
            for s in self.sensors:
                line = s.step(t, self.field, x, y, h)
                if line is not None:
                    crop.append(line)
            self._crop_next = min(s.next_t for s in self.sensors)
        return t, lines, crop, self._tx_raw() if rc >> _TX_SHIFT else []

    def _after_step(self, rc: int, t: float) -> None:
        """What tdsim_world_step's flags leave to Python: errors, random draws, records."""
        if rc == _NO_MEMORY:
            raise MemoryError("air line: no memory for more parcels in flight")
        if rc < 0:
            check(rc, "Ecu.step")
        if rc & lib.TDSIM_REFILL_TRACTOR:
            refill(self.tractor._rng, self.tractor._s.gauss)
        if rc & lib.TDSIM_REFILL_WHEEL:
            refill(self.wheel._rng, self.wheel._s.gauss)
        if rc & lib.TDSIM_NEW_BIN:
            self._record_ndvi(self._ws.bin)
        if rc & lib.TDSIM_FIRST_LANDING:
            for i in (0, 1):
                if self.first_landing_m[i] is None and self._ws.landed_any[i]:
                    self.first_landing_m[i] = self.tractor.odometer
                    self.first_landing_t[i] = t
        if rc & lib.TDSIM_BIN_DONE:
            ws = self._ws
            for i in (0, 1):
                if ws.done_bin[i] >= 0:
                    self._applied[i][ws.done_bin[i]] = ws.done_kg[i]
                    ws.done_bin[i] = -1

    @property
    def applied_by_bin(self) -> tuple[dict[int, float], dict[int, float]]:
        """Fertilizer landed (kg) by record bin of the track (odometer // bin_m), per layer."""
        ws = self._ws
        for i in (0, 1):
            if ws.land_bin[i] >= 0:  # the bin the outlets are over, so far
                self._applied[i][ws.land_bin[i]] = ws.land_kg[i]
        return self._applied

    @property
    def _edge_us(self) -> int:
        """The capture timer's last edge (the ECU clock, us)."""
        e: int = self._ws.edge_us
        return e

    @property
    def _wheel_pos(self) -> float:
        """The encoder position (pulses, fractional) at the last step."""
        pos: float = self._ws.wheel_pos
        return pos

    def _loose(self, x: float, y: float) -> float:
        """The wheel's slip floor here (%): loose_slip_pct inside a loose patch, else 0.

        Which patch the wheel is in can only change after it has moved as far as the nearest
        patch edge: until then the last answer stands (the tractor moves a few cm a step)."""
        floor: float = lib.tdsim_world_loose(self._ws, x, y)
        return floor

    def _wheel_edge(self, now_us: int, count: int) -> int:
        """The capture timer: the time of the last whole pulse crossed in this step, by
        interpolating the wheel's position over the step (the previous edge if none)."""
        e: int = lib.tdsim_world_wheel_edge(self._ws, now_us, count)
        return e

    def _record_ndvi(self, b: int) -> None:
        tr = self.tractor
        c, s = math.cos(tr.heading), math.sin(tr.heading)
        offs = self.cfg.crop_offsets_m
        self.ndvi_by_bin[b] = sum(self.field.ndvi(tr.x + o * c, tr.y - o * s) for o in offs) / len(
            offs
        )

    def metered_kg(self, layer: int) -> float:
        """Fertilizer the layer's metering wheel has let out so far (true kg/rev): what a
        scale under the outlet shows after a catch test."""
        return self.meters[layer].revolutions * self.cfg.kg_per_rev[layer]

    def run(self, seconds: float) -> None:
        """Advance `seconds` of virtual time, discarding the outputs."""
        for _ in range(round(seconds / self.dt)):
            self.step()

    @property
    def truth(self) -> Truth:
        tr = self.tractor
        g = self.cfg.gnss
        lat = g.lat0_deg + math.degrees(tr.y / EARTH_R_M)
        lon = g.lon0_deg + math.degrees(tr.x / (EARTH_R_M * math.cos(math.radians(g.lat0_deg))))
        return Truth(
            t_s=self.t_s,
            x_m=tr.x,
            y_m=tr.y,
            lat_deg=lat,
            lon_deg=lon,
            heading_deg=math.degrees(tr.heading) % 360.0,
            v_kmh=tr.v * 3.6,
            odometer_m=tr.odometer,
            wheel_revolutions=self.wheel.revolutions,
            meter_rpm=(self.meters[0].rpm, self.meters[1].rpm),
            fan_rpm=(self.fans[0].rpm, self.fans[1].rpm),
            applied_kg=(self.airlines[0].landed_kg, self.airlines[1].landed_kg),
            in_flight_kg=(self.airlines[0].in_flight_kg, self.airlines[1].in_flight_kg),
            first_landing_m=(self.first_landing_m[0], self.first_landing_m[1]),
            ndvi=self.field.ndvi(tr.x, tr.y),
        )
