"""Software in the loop: the World's ECU and a simulated cab PC talk DBC frames over a
python-can bus (an in-process segment, sim.inproc), in virtual time, as the paper's machine
does over its USB-CAN link.

The cab PC reads the NMEA stream in its own program cycle (323 ms, as measured in the
paper), keeps the speed of the last valid RMC, and sends the PcCommand every 500 ms. It
records every EcuStatus period (100 ms) like the paper's CAN analyser.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import can
import numpy as np

from topdress import protocol
from topdress.config import CropConfig, LinearRateConfig
from topdress.crop.rate import LinearRate
from topdress.crop.sensors import CompensatedNdvi
from topdress.errors import EcuParamError, ProtocolError
from topdress.gnss.sentences import parse_rmc_speed_kmh
from topdress.sim.inproc import segment
from topdress.sim.world import World

_channels = itertools.count()

COLUMNS = (
    "t",
    "odometer_m",
    "v_true_kmh",
    "phase",
    "meter_rpm_upper",
    "meter_rpm_lower",
    "target_rpm_upper",
    "target_rpm_lower",
    "wheel_kmh",
    "gnss_kmh",
    "selected_kmh",
    "source",
    "cv_pct",
    "faults",
    "wheel_updates",
    "pc_gnss_kmh",
    "wheel_pulses",
)
PHASES = ("rest", "accel", "uniform", "decel", "turn", "run")


@dataclass(frozen=True)
class NdviRate:
    """The terminal's crop path run by the simulated PC: sensor lines -> distance queue (the
    sensors sensor_to_meter_m ahead, the look-ahead) -> linear rate model; each layer gets
    layer_share of the product rate."""

    crop: CropConfig = field(default_factory=CropConfig)
    rate: LinearRateConfig = field(default_factory=LinearRateConfig)
    lookahead_s: float = 0.0
    layer_share: float = 0.5

    def kg_ha(self, ndvi: float) -> float:
        """The rate of one layer for this NDVI (the prescription the metrics compare with)."""
        return LinearRate(self.rate).rate_kg_ha(ndvi) * self.layer_share


@dataclass(frozen=True)
class PcParams:
    """The cab PC of the experiments."""

    command_period_s: float = 0.5
    cycle_s: float = 0.323
    fan_rpm: float = 3000.0
    rate_kg_ha: tuple[float, float] = (180.0, 180.0)
    ecu_params: tuple[tuple[str, float], ...] = ()  # PcParamSet writes before the start
    start_at_s: float = 0.0
    gnss_time: bool = True  # send PcGnssTime (speed, fix age, seq) for every new RMC
    ndvi_rate: NdviRate | None = None  # None: the fixed rate_kg_ha
    # the terminal's `can.send_on_rate`: a changed rate goes out at the cycle that computed it
    send_on_rate: bool = False


@dataclass
class Record:
    """The CAN analyser's trace: one row per EcuStatus (100 ms), columns as COLUMNS."""

    rows: list[tuple[float, ...]] = field(default_factory=list)

    def arrays(self) -> dict[str, np.ndarray]:
        a = np.array(self.rows, dtype=float).reshape(-1, len(COLUMNS))
        return {name: a[:, i] for i, name in enumerate(COLUMNS)}


# The ECU frames the cab PC reads; the others (the fused estimate's, the catch test's) it
# lets pass undecoded, as a PC that does not show them would.
_PC_READS = frozenset(
    {
        protocol.DEFAULT_IDS.status,
        protocol.DEFAULT_IDS.diag,
        protocol.DEFAULT_IDS.speeds,
        protocol.DEFAULT_IDS.targets,
        protocol.DEFAULT_IDS.param_ack,
    }
)


class CabPc:
    """The PC side: NMEA in, PcCommand out every 500 ms, the ECU frames it reads decoded."""

    def __init__(self, p: PcParams) -> None:
        self.p = p
        self.gnss_kmh: float | None = None
        self._serial: list[tuple[float, str]] = []
        self._gnss_seq = 0
        nr = p.ndvi_rate
        self.ndvi = None if nr is None else CompensatedNdvi(nr.crop, nr.lookahead_s)
        self._next_cycle = p.cycle_s
        self._next_cmd = p.start_at_s
        self.next_poll_s = min(self._next_cycle, self._next_cmd)  # poll() has nothing before
        self.status: protocol.EcuStatus | None = None
        self.diag: protocol.EcuDiag | None = None
        self.speeds: protocol.EcuSpeeds | None = None
        self.targets: protocol.EcuTargets | None = None
        self.acks: list[protocol.EcuParamAck] = []
        self.rejected_frames = 0
        self.rate_kg_ha = p.rate_kg_ha
        self.start = True
        self.paused = False  # the operator's pause (headland turn): rate 0, fans kept running
        self._sent: tuple[bool, float, float] | None = None  # start and rates last sent

    def on_nmea(self, line: str, t: float = 0.0) -> None:
        """A line reaching the serial port at t (its arrival is all the PC knows of its age)."""
        self._serial.append((t, line))

    def on_crop(self, line: str, t: float) -> None:
        if self.ndvi is not None:
            self.ndvi.sensors.feed(t, line)

    def poll(self, t: float) -> list[can.Message]:
        """Run the program cycle and the command timer; the frames due now."""
        out: list[can.Message] = []
        if t + 1e-9 >= self._next_cycle:
            self._next_cycle += self.p.cycle_s
            rmc_t: float | None = None
            for t_line, line in self._serial:
                if line[3:6] == "RMC":
                    self.gnss_kmh = parse_rmc_speed_kmh(line)
                    rmc_t = t_line
            self._serial.clear()
            if rmc_t is not None and self.p.gnss_time:
                self._gnss_seq = (self._gnss_seq + 1) & 0xFF
                age_ms = min(10000, round((t - rmc_t) * 1000.0))
                kmh = None if self.gnss_kmh is None else min(self.gnss_kmh, 25.0)
                out.append(protocol.encode_gnss_time(kmh, age_ms, self._gnss_seq))
            self._update_rate(t)
            if self.p.send_on_rate and self._sent not in (None, self._command_values()):
                out.append(self._command())
        if t + 1e-9 >= self._next_cmd:
            self._next_cmd += self.p.command_period_s
            out.append(self._command())
        self.next_poll_s = min(self._next_cycle, self._next_cmd)
        return out

    def _command_values(self) -> tuple[bool, float, float]:
        up, lo = (0.0, 0.0) if self.paused else self.rate_kg_ha
        return (self.start, up, lo)

    def _command(self) -> can.Message:
        self._sent = start, up, lo = self._command_values()
        gnss = None if self.gnss_kmh is None else min(self.gnss_kmh, 25.0)
        return protocol.encode_command(start, self.p.fan_rpm, up, lo, gnss)

    def _update_rate(self, t: float) -> None:
        """The NDVI where the outlets are (or will be, with the look-ahead) -> the rate."""
        nr = self.p.ndvi_rate
        if self.ndvi is None or nr is None:
            return
        v = 0.0 if self.speeds is None else self.speeds.selected_kmh
        ndvi = self.ndvi.update(t, v)
        if ndvi is None:  # the outlets have not reached the first spot sensed yet
            ndvi = self.ndvi.sensors.mean_ndvi(t)
        if ndvi is not None:
            rate = min(nr.kg_ha(ndvi), 655.0)
            self.rate_kg_ha = (rate, rate)

    def on_frame(self, msg: can.Message) -> bool:
        """Decode one ECU frame; True if it was an EcuStatus. A frame of the protocol the PC
        does not read is skipped; anything else that does not decode is counted."""
        if msg.arbitration_id not in _PC_READS and protocol.is_known_id(msg.arbitration_id):
            return False
        try:
            f = protocol.decode(msg)
        except ProtocolError:
            self.rejected_frames += 1
            return False
        if isinstance(f, protocol.EcuStatus):
            self.status = f
            return True
        if isinstance(f, protocol.EcuDiag):
            self.diag = f
        elif isinstance(f, protocol.EcuSpeeds):
            self.speeds = f
        elif isinstance(f, protocol.EcuTargets):
            self.targets = f
        elif isinstance(f, protocol.EcuParamAck):
            self.acks.append(f)
        return False


class Sil:
    """World + cab PC over an in-process CAN segment; step() advances one control period."""

    def __init__(self, world: World, pc: PcParams | None = None, record: bool = True) -> None:
        self.world = world
        self.pc = CabPc(pc or PcParams())
        channel = f"topdress-sil-{next(_channels)}"
        self.ecu_bus, self.pc_bus = segment(channel)
        self.record: Record | None = Record() if record else None
        self.nmea_lines = 0
        self.crop_lines = 0
        self._pending_to_ecu = 0
        try:
            self._push_params()
        except EcuParamError:
            self.close()
            raise

    def close(self) -> None:
        self.ecu_bus.shutdown()
        self.pc_bus.shutdown()

    def __enter__(self) -> Sil:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _push_params(self) -> None:
        """Write the PC's parameters while the ECU is stopped, each acknowledged; the PC
        commands stop meanwhile (the ECU refuses parameters while running)."""
        self.pc.start = False
        for key, value in self.pc.p.ecu_params:
            self.pc_bus.send(protocol.encode_param_set(key, value))
            self._pending_to_ecu += 1
            self.step()
            ack = self.pc.acks[-1] if self.pc.acks else None
            if ack is None or ack.result != protocol.AckResult.OK:
                result = "no answer" if ack is None else ack.result.name
                raise EcuParamError(key, value, f"refused by the ECU: {result}")
        self.pc.start = True

    def step(self) -> None:
        w = self.world
        if self._pending_to_ecu:
            now = w.now_us
            while (msg := self.ecu_bus.recv(0)) is not None:
                w.deliver_can(msg, now)
            self._pending_to_ecu = 0
        t, nmea, crop, frames = w.step_raw()
        pc = self.pc
        if nmea:
            self.nmea_lines += len(nmea)
            for line in nmea:
                pc.on_nmea(line, t)
        if crop:
            self.crop_lines += len(crop)
            if pc.ndvi is not None:
                for line in crop:
                    pc.on_crop(line, t)
        if frames:
            for fid, data in frames:
                self.ecu_bus.send(can.Message(arbitration_id=fid, data=data, is_extended_id=True))
            status = False
            while (msg := self.pc_bus.recv(0)) is not None:
                status |= pc.on_frame(msg)
            if status and self.record is not None:
                self._record(t)
        if t + 1e-9 >= pc.next_poll_s:  # the PC's cycle or command timer is due
            for msg in pc.poll(t):
                self.pc_bus.send(msg)
                self._pending_to_ecu += 1

    def _record(self, t: float) -> None:
        pc = self.pc
        st, dg, sp, tg = pc.status, pc.diag, pc.speeds, pc.targets
        if st is None or dg is None or sp is None or tg is None or self.record is None:
            return
        w = self.world
        tr = w.tractor
        self.record.rows.append(
            (
                t,
                tr.odometer,
                tr.v * 3.6,
                float(PHASES.index(w.drive.phase(tr.v))),
                st.meter_rpm_upper,
                st.meter_rpm_lower,
                tg.target_rpm_upper,
                tg.target_rpm_lower,
                sp.wheel_kmh,
                math.nan if sp.gnss_kmh is None else sp.gnss_kmh,
                sp.selected_kmh,
                float(protocol.Source(dg.source).code),
                math.nan if dg.cv_pct is None else dg.cv_pct,
                float(int(dg.faults)),
                float(w.ecu.wheel_updates),
                math.nan if pc.gnss_kmh is None else pc.gnss_kmh,
                float(dg.wheel_pulses),
            )
        )

    def run_until_done(self, max_s: float = 600.0) -> None:
        """Step until the Drive is finished (or max_s)."""
        w = self.world
        n = round(max_s / w.dt)
        for _ in range(n):
            self.step()
            if w.drive.finished:
                return
