"""The ECU firmware in an emulator with the simulated machine in the loop.

QEMU's `netduinoplus2` machine is an STM32F405 without a CAN controller; the firmware finds
none at start and speaks SLCAN on USART1 instead (docs/firmware.md). QEMU puts that serial
port on a local TCP socket, and python-can's `slcan` interface talks to it as to a USB-CAN
dongle. Over the same link run the bus frames (the PC's commands, the ECU's status) and the HIL
frames of protocol/topdress_hil.dbc: the firmware sends the duties of every control step, the
simulator answers with the machine's counters at the next step's time.

`QemuWorld` is a drop-in World: the same plant, the same step(), but the control law is the
firmware's, on its own 10 ms tick in the emulator. The plant advances one World step (dt) per
firmware step, so the firmware's clock drives the simulation; the World's in-process core
still runs beside it on the same counters (it gets no commands, its outputs are not used).
"""

from __future__ import annotations

import math
import os
import shutil
import socket
import subprocess
import time
from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

import can
import cantools
from can.interfaces.slcan import slcanBus as SlcanBus

from topdress import protocol
from topdress.errors import DeviceError, EcuParamError
from topdress.protocol import CanFrame
from topdress.sim.sil import Sil
from topdress.sim.tractor import Drive
from topdress.sim.world import SimConfig, World

_U32 = 0xFFFFFFFF
IMAGE_NAME = "topdress-ecu-stm32f4.elf"
# the repository's build output (make firmware); an installed package names it by TOPDRESS_ECU_IMAGE
_REPO_IMAGE = Path(__file__).resolve().parents[3] / "build" / "fw" / IMAGE_NAME


def default_image() -> Path:
    """The firmware image: $TOPDRESS_ECU_IMAGE, else the repository's build/fw one."""
    env = os.environ.get("TOPDRESS_ECU_IMAGE")
    return Path(env) if env else _REPO_IMAGE


def qemu_missing() -> str | None:
    """Why the emulated ECU cannot run here, or None."""
    if shutil.which("qemu-system-arm") is None:
        return "qemu-system-arm is not installed (apt-get install qemu-system-arm)"
    return None


@cache
def hil_database() -> Any:
    """The HIL frames (protocol/topdress_hil.dbc, shipped in the package beside the bus DBC)."""
    text = (resources.files("topdress.protocol") / "topdress_hil.dbc").read_text(encoding="utf-8")
    return cantools.database.load_string(text, database_format="dbc")


@dataclass(frozen=True)
class QemuOptions:
    """How the emulator runs. icount_shift: None runs the guest on the host's clock (TCG);
    N makes every instruction 2**N ns of virtual time (-icount shift=N,sleep=on): timing by
    instruction count, the virtual clock still kept to real time while the guest sleeps."""

    image: Path = field(default_factory=default_image)
    qemu: str = "qemu-system-arm"
    icount_shift: int | None = None
    connect_timeout_s: float = 5.0


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


class QemuEcu:
    """The firmware image running in qemu-system-arm, its serial port an SLCAN CAN interface
    (`bus`, python-can). Use as a context manager; close() stops the emulator."""

    def __init__(self, opts: QemuOptions | None = None) -> None:
        self.opts = opts = opts or QemuOptions()
        if not opts.image.is_file():
            raise DeviceError(f"no firmware image at {opts.image} (make firmware)")
        if shutil.which(opts.qemu) is None:
            raise DeviceError(f"{opts.qemu} not found (apt-get install qemu-system-arm)")
        self.port = _free_port()
        cmd = [
            opts.qemu,
            "-M",
            "netduinoplus2",
            "-display",
            "none",
            "-monitor",
            "none",
            "-nodefaults",
            "-kernel",
            str(opts.image),
            # the guest starts when the link connects: nothing it says is lost
            "-serial",
            f"tcp:127.0.0.1:{self.port},server=on,wait=on",
        ]
        if opts.icount_shift is not None:
            cmd += ["-icount", f"shift={opts.icount_shift},sleep=on"]
        self.command = cmd
        self._proc = subprocess.Popen(
            cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
        )
        try:
            self.bus = self._connect()
        except BaseException:
            self._stop()
            raise

    def _connect(self) -> SlcanBus:
        deadline = time.monotonic() + self.opts.connect_timeout_s
        while True:
            if self._proc.poll() is not None:
                err = self._proc.stderr.read().decode(errors="replace") if self._proc.stderr else ""
                raise DeviceError(f"qemu-system-arm exited: {err.strip()}")
            try:
                bus = SlcanBus(
                    channel=f"socket://127.0.0.1:{self.port}",
                    sleep_after_open=0.0,
                    timeout=0.001,
                )
                break
            except can.CanError:
                if time.monotonic() > deadline:
                    raise DeviceError("qemu-system-arm: its serial port never listened") from None
                time.sleep(0.05)
        # the guest starts at the connection and its USART drops what comes before it is set
        # up: ask for its version until it answers, then open the channel again
        while bus.get_version(0.05) == (None, None):
            if time.monotonic() > deadline:
                bus.shutdown()
                raise DeviceError("the emulated ECU does not answer on its SLCAN link")
        bus.open()
        return bus

    def _stop(self) -> None:
        if self._proc.poll() is None:
            self._proc.terminate()
            try:
                self._proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
        if self._proc.stderr is not None:
            self._proc.stderr.close()

    def close(self) -> None:
        bus = getattr(self, "bus", None)
        if bus is not None:
            bus.shutdown()
        self._stop()

    def __enter__(self) -> QemuEcu:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass(frozen=True)
class FwStep:
    """One control step of the firmware as its HIL frames tell it."""

    time_us: int  # on the firmware's microsecond clock
    seq: int
    late_inputs: int  # steps so far without fresh counters, mod 256
    cost_us: int  # how long the step (receive + core) took on the emulated chip
    duties: tuple[float, float, float, float]  # meter upper, lower, fan upper, lower


@dataclass
class StepTiming:
    """The firmware's step intervals (its own clock) and costs, for the jitter figures."""

    intervals_us: list[int] = field(default_factory=list)
    costs_us: list[int] = field(default_factory=list)
    late_inputs: int = 0

    def summary(self) -> dict[str, float]:
        """Mean, standard deviation, extremes and 99th percentile of the step interval, us."""
        iv = sorted(self.intervals_us)
        if not iv:
            return {}
        n = len(iv)
        mean = sum(iv) / n
        sd = math.sqrt(sum((x - mean) ** 2 for x in iv) / max(1, n - 1))
        return {
            "steps": float(n),
            "mean_us": mean,
            "sd_us": sd,
            "min_us": float(iv[0]),
            "max_us": float(iv[-1]),
            "p99_us": float(iv[min(n - 1, math.ceil(0.99 * n) - 1)]),
            "late_inputs": float(self.late_inputs),
            "max_cost_us": float(max(self.costs_us, default=0)),
        }


class HilLink:
    """The simulator's end of the HIL link: the firmware's steps in, the counters out, bus
    frames both ways."""

    def __init__(self, bus: can.BusABC) -> None:
        self.bus = bus
        db = hil_database()
        self._actuators = db.get_message_by_name("HilActuators")
        self._step = db.get_message_by_name("HilStep")
        self._edge = db.get_message_by_name("HilWheelEdge")
        self._sensors = db.get_message_by_name("HilSensors")
        self._duties: tuple[int, tuple[float, float, float, float]] | None = None
        self.frames: list[CanFrame] = []  # bus frames from the firmware, not yet taken
        self.steps_seen = 0
        self._last_late = 0

    def wait_step(self, timeout_s: float) -> FwStep:
        """The firmware's next step; bus frames arriving meanwhile are kept in `frames`."""
        deadline = time.monotonic() + timeout_s
        while True:
            left = deadline - time.monotonic()
            msg = self.bus.recv(timeout=max(0.0, left)) if left > 0 else None
            if msg is None:
                raise DeviceError(f"the emulated ECU made no control step for {timeout_s:g} s")
            fid = msg.arbitration_id
            if fid == self._actuators.frame_id:
                d = self._actuators.decode(bytes(msg.data))
                self._duties = (
                    int(d["HilSeq"]),
                    (
                        float(d["HilUpperMeterDuty"]),
                        float(d["HilLowerMeterDuty"]),
                        float(d["HilUpperFanDuty"]),
                        float(d["HilLowerFanDuty"]),
                    ),
                )
            elif fid == self._step.frame_id:
                s = self._step.decode(bytes(msg.data))
                seq = int(s["HilSeq"])
                if self._duties is None or self._duties[0] != seq:
                    continue  # its duties were lost (a link opened mid-step): the next one
                self.steps_seen += 1
                return FwStep(
                    time_us=int(s["HilStepTime"]),
                    seq=seq,
                    late_inputs=int(s["HilLateInputs"]),
                    cost_us=int(s["HilStepCost"]),
                    duties=self._duties[1],
                )
            else:
                self.frames.append((fid, bytes(msg.data)))

    def send_counters(
        self,
        edge_us: int,
        edge_valid: bool,
        wheel: int,
        meters: tuple[int, int],
        fans: tuple[int, int],
        seq: int,
    ) -> None:
        """HilWheelEdge, then HilSensors: the hardware's narrow counters, wrapping."""
        edge = self._edge.encode(
            {
                "HilEdgeTime": edge_us & _U32,
                "HilEdgeCount": wheel & 0xFFFF,
                "HilSeq": seq & 0xFF,
                "HilEdgeValid": int(edge_valid),
            }
        )
        sensors = self._sensors.encode(
            {
                "HilWheelCount": wheel & 0xFFFF,
                "HilUpperMeterCount": meters[0] & 0xFFFF,
                "HilLowerMeterCount": meters[1] & 0xFFFF,
                "HilUpperFanCount": fans[0] & 0xFF,
                "HilLowerFanCount": fans[1] & 0xFF,
            }
        )
        for fid, data in ((self._edge.frame_id, edge), (self._sensors.frame_id, sensors)):
            self.bus.send(can.Message(arbitration_id=fid, data=data, is_extended_id=True))

    def send(self, frame: can.Message | CanFrame) -> None:
        """A bus frame to the firmware (it takes it at its next step)."""
        if not isinstance(frame, can.Message):
            frame = can.Message(arbitration_id=frame[0], data=frame[1], is_extended_id=True)
        self.bus.send(frame)

    def take_frames(self) -> list[CanFrame]:
        out, self.frames = self.frames, []
        return out


class QemuWorld(World):
    """A World whose control law is the firmware's in the emulator (see the module's doc)."""

    def __init__(
        self,
        ecu: QemuEcu,
        cfg: SimConfig | None = None,
        seed: int = 0,
        drive: Drive | None = None,
        step_timeout_s: float = 2.0,
    ) -> None:
        super().__init__(cfg, seed, drive)
        self.qemu = ecu
        self.link = HilLink(ecu.bus)
        self.step_timeout_s = step_timeout_s
        self.timing = StepTiming()
        self.last_step: FwStep | None = None
        self.duties: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)

    def deliver_can(self, frame: Any, now_us: int | None = None) -> int:
        """A PC -> ECU frame over the link; the firmware says what it made of it in its own
        frames (EcuSpeeds.RxRejected), so this always returns 0."""
        self.link.send(frame)
        return 0

    def step_raw(self) -> tuple[float, list[str], list[str], list[CanFrame]]:
        """The firmware's next step (its duties), the plant over one dt with them, and the
        counters for the firmware's step after: (t_s, nmea, crop, ECU frames)."""
        st = self.link.wait_step(self.step_timeout_s)
        last = self.last_step
        if last is not None:
            self.timing.intervals_us.append((st.time_us - last.time_us) & _U32)
            self.timing.costs_us.append(st.cost_us)
            self.timing.late_inputs += (st.late_inputs - last.late_inputs) & 0xFF  # mod 256
        self.last_step = st
        self.duties = st.duties
        self._ws.duty = list(st.duties)
        t, nmea, crop, _ = super().step_raw()  # the in-process core's frames are not the ECU's
        # the plant is now at the firmware's next step: its time on the firmware's clock
        fw_next = st.time_us + self._dt_us
        wheel = int(self.wheel._s.count)
        edge_fw = (fw_next - ((self.now_us - self._edge_us) & _U32)) & _U32
        self.link.send_counters(
            edge_fw,
            self.cfg.wheel_edges and wheel > 0,
            wheel,
            (int(self.meters[0]._s.count), int(self.meters[1]._s.count)),
            (int(self.fans[0]._s.count), int(self.fans[1]._s.count)),
            st.seq,
        )
        return t, nmea, crop, self.link.take_frames()


class QemuSil(Sil):
    """Software in the loop against the emulated firmware: a Sil whose World is a QemuWorld.
    A parameter's acknowledgement comes at the firmware's next step, not within the step that
    sent it, so the push waits for it (up to ack_steps steps)."""

    ack_steps = 50

    def _push_params(self) -> None:
        pc = self.pc
        pc.start = False
        for key, value in pc.p.ecu_params:
            before = len(pc.acks)
            self.pc_bus.send(protocol.encode_param_set(key, value))
            self._pending_to_ecu += 1
            for _ in range(self.ack_steps):
                self.step()
                if len(pc.acks) > before:
                    break
            ack = pc.acks[-1] if len(pc.acks) > before else None
            if ack is None or ack.result != protocol.AckResult.OK:
                result = "no answer" if ack is None else ack.result.name
                raise EcuParamError(key, value, f"refused by the ECU: {result}")
        pc.start = True
