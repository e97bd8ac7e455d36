"""The ECU firmware in an emulator with the simulated machine in the loop.

QEMU's `netduinoplus2` machine is an STM32F405 without a CAN controller; the firmware finds
none at start and speaks SLCAN on USART1 instead (docs/firmware.md). QEMU puts that serial
port on a local TCP socket, and python-can's `slcan` interface talks to it as to a USB-CAN
dongle. Over the same link run the bus frames (the PC's commands, the ECU's status) and the HIL
frames of protocol/topdress_hil.dbc: the firmware sends the duties of every control step, the
simulator answers with the machine's counters at the next step's time.

`QemuWorld` is a drop-in World: the same plant, the same step(), but the control law is the
firmware's. In lockstep (the default) the simulator drives the firmware's step: each World step
sends the step's time (HilClock) and the counters at that time, the firmware makes exactly one
control step at that time and answers with its bus frames, its duties and HilStep, and only
then does the World go on. The firmware then steps on the simulator's clock as the in-process
core does, however fast or loaded the host is: runs are deterministic. Free-running
(`lockstep=False`) leaves the firmware on its own 10 ms SysTick in the emulator, on the host's
clock, the plant answering each of its steps (the way to see the emulator's real-time jitter).
The World's in-process core still runs beside it on the same counters (it gets no commands,
its outputs are not used).
"""

from __future__ import annotations

import math
import os
import select
import shutil
import socket
import subprocess
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
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
# the repository's emulator build (`make -f ecu/ports/stm32f4/firmware.mk VARIANT=qemu`: SLCAN
# and HIL on USART1, no clock set-up); an installed package names it by TOPDRESS_ECU_IMAGE
_REPO = Path(__file__).resolve().parents[3]
_REPO_IMAGE = _REPO / "build" / "fw-qemu" / IMAGE_NAME


def default_image() -> Path:
    """The firmware image: $TOPDRESS_ECU_IMAGE, else the repository's build/fw one."""
    env = os.environ.get("TOPDRESS_ECU_IMAGE")
    return Path(env) if env else _REPO_IMAGE


_FIRMWARE_MK = _REPO / "ecu" / "ports" / "stm32f4" / "firmware.mk"


def ensure_image(image: Path | None = None) -> Path:
    """The firmware image to boot, built first by the rules of `make firmware` when it is the
    repository's and the toolchain is here (make rebuilds only what changed). DeviceError, saying
    what to do, when there is none to boot."""
    image = image or default_image()
    repo_build = image == _REPO_IMAGE and _FIRMWARE_MK.is_file()
    if repo_build and shutil.which("arm-none-eabi-gcc") is not None:
        done = subprocess.run(
            [
                "make",
                "--no-print-directory",
                "-s",
                "-f",
                str(_FIRMWARE_MK.relative_to(_REPO)),
                "VARIANT=qemu",
            ],
            cwd=_REPO,
            capture_output=True,
            text=True,
            check=False,
        )
        if done.returncode != 0:
            raise DeviceError(f"make firmware failed:\n{done.stderr.strip()}")
    if not image.is_file():
        how = (
            "run `make firmware` (it installs arm-none-eabi-gcc as root, builds the emulator image)"
            if repo_build
            else "set TOPDRESS_ECU_IMAGE to an emulator build (VARIANT=qemu) of the firmware"
        )
        raise DeviceError(f"no firmware image at {image}: {how}")
    return image


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


def _socket_of(bus: SlcanBus) -> socket.socket:
    """The TCP socket under pyserial's `socket://` port (private there, ours to tune)."""
    sock: socket.socket = getattr(bus.serialPortOrig, "_socket")  # noqa: B009
    return sock


class _SocketSlcan(SlcanBus):
    """python-can's slcan interface on the emulator's TCP socket, reading what has arrived at
    once instead of a byte per system call (a step's lines are ~300 bytes, every 10 ms of
    simulated time)."""

    def _read(self, timeout: float | None) -> str | None:
        sock = _socket_of(self)
        buf: bytearray = self._buffer
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            ends = [i for i in (buf.find(self._OK), buf.find(self._ERROR)) if i >= 0]
            if ends:
                end = min(ends) + 1
                line = buf[:end].decode()
                del buf[:end]
                return line
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            ready, _, _ = select.select([sock], [], [], left)
            if not ready:
                return None
            chunk = sock.recv(65536)
            if not chunk:
                raise can.CanOperationError("the emulator closed its serial port")
            buf.extend(chunk)


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
            # nodelay: a step's few short lines go at once, not after the peer's delayed ACK
            f"tcp:127.0.0.1:{self.port},server=on,wait=on,nodelay=on",
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

    def _connect(self) -> _SocketSlcan:
        deadline = time.monotonic() + self.opts.connect_timeout_s
        while True:
            if self._proc.poll() is not None:
                err = self._proc.stderr.read().decode(errors="replace") if self._proc.stderr else ""
                raise DeviceError(f"qemu-system-arm exited: {err.strip()}")
            try:
                bus = _SocketSlcan(
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
        # pyserial's socket leaves Nagle on: the lines of a step would wait ~40 ms for an ACK
        _socket_of(bus).setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
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


def _stats(values: list[int] | list[float], prefix: str) -> dict[str, float]:
    v = sorted(values)
    n = len(v)
    mean = sum(v) / n
    sd = math.sqrt(sum((x - mean) ** 2 for x in v) / max(1, n - 1))
    return {
        f"{prefix}mean_us": mean,
        f"{prefix}sd_us": sd,
        f"{prefix}min_us": float(v[0]),
        f"{prefix}max_us": float(v[-1]),
        f"{prefix}p99_us": float(v[min(n - 1, math.ceil(0.99 * n) - 1)]),
    }


@dataclass
class StepTiming:
    """The firmware's step intervals (its own clock), its step costs, and the host time each
    World step took (in lockstep: the round trip to the emulator and back), for the figures."""

    intervals_us: list[int] = field(default_factory=list)
    costs_us: list[int] = field(default_factory=list)
    host_us: list[float] = field(default_factory=list)
    late_inputs: int = 0

    def summary(self) -> dict[str, float]:
        """Step interval on the firmware's clock (mean_us, sd_us, min_us, max_us, p99_us; in
        lockstep the simulator's dt by construction), host time per World step (host_*_us),
        late steps and the longest step cost."""
        if not self.intervals_us:
            return {}
        out = {"steps": float(len(self.intervals_us)), **_stats(self.intervals_us, "")}
        if self.host_us:
            out.update(_stats(self.host_us, "host_"))
            out["host_total_s"] = sum(self.host_us) / 1e6
        out["late_inputs"] = float(self.late_inputs)
        out["max_cost_us"] = float(max(self.costs_us, default=0))
        return out


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
        self._clock = db.get_message_by_name("HilClock")
        self._duties: tuple[int, tuple[float, float, float, float]] | None = None
        self.frames: list[CanFrame] = []  # bus frames from the firmware, not yet taken
        self._last_late = 0

    def wait_step(self, timeout_s: float, seq: int | None = None) -> FwStep:
        """The firmware's next step (in lockstep the one numbered `seq`); bus frames arriving
        meanwhile are kept in `frames`."""
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
                got = int(s["HilSeq"])
                if self._duties is None or self._duties[0] != got:
                    continue  # its duties were lost (a link opened mid-step): the next one
                if seq is not None and got != seq:
                    raise DeviceError(f"the emulated ECU answered step {got}, not step {seq}")
                return FwStep(
                    time_us=int(s["HilStepTime"]),
                    seq=got,
                    late_inputs=int(s["HilLateInputs"]),
                    cost_us=int(s["HilStepCost"]),
                    duties=self._duties[1],
                )
            else:
                self.frames.append((fid, bytes(msg.data)))

    def send_clock(self, time_us: int, seq: int, free_run: bool = False) -> None:
        """HilClock: the time of the step the counters that follow are for (the first one
        also chooses the firmware's tick: lockstep, or its own with `free_run`)."""
        data = self._clock.encode(
            {"HilClockTime": time_us & _U32, "HilSeq": seq & 0xFF, "HilFreeRun": int(free_run)}
        )
        fid = self._clock.frame_id
        self.bus.send(can.Message(arbitration_id=fid, data=data, is_extended_id=True))

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
        lockstep: bool = True,
    ) -> None:
        super().__init__(cfg, seed, drive)
        self.qemu = ecu
        self.link = HilLink(ecu.bus)
        self.step_timeout_s = step_timeout_s
        self.lockstep = lockstep
        self.timing = StepTiming()
        self.last_step: FwStep | None = None
        self.duties: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
        # the first HIL frame chooses the firmware's tick; in lockstep its core starts again at
        # the World's time 0, as the in-process core does
        self.link.send_clock(self.now_us, 0, free_run=not lockstep)

    def deliver_can(self, frame: Any, now_us: int | None = None) -> int:
        """A PC -> ECU frame over the link (and to the in-process core beside, so that its
        parameters, `world.ecu.params`, are the firmware's); the firmware says what it made of
        it in its own frames (EcuSpeeds.RxRejected), so this always returns 0."""
        self.link.send(frame)
        super().deliver_can(frame, now_us)
        return 0

    def step_raw(self) -> tuple[float, list[str], list[str], list[CanFrame]]:
        """One World step with the firmware's control step: (t_s, nmea, crop, ECU frames)."""
        t0 = time.perf_counter()
        out = self._lockstep() if self.lockstep else self._free_running()
        self.timing.host_us.append((time.perf_counter() - t0) * 1e6)
        return out

    def _take(self, st: FwStep) -> None:
        last = self.last_step
        if last is not None:
            self.timing.intervals_us.append((st.time_us - last.time_us) & _U32)
            self.timing.costs_us.append(st.cost_us)
            self.timing.late_inputs += (st.late_inputs - last.late_inputs) & 0xFF  # mod 256
        self.last_step = st
        self.duties = st.duties
        self._ws.duty = list(st.duties)

    def _counters(self, edge_us: int, seq: int) -> None:
        wheel = int(self.wheel._s.count)
        self.link.send_counters(
            edge_us,
            self.cfg.wheel_edges,
            wheel,
            (int(self.meters[0]._s.count), int(self.meters[1]._s.count)),
            (int(self.fans[0]._s.count), int(self.fans[1]._s.count)),
            seq,
        )

    def _lockstep(self) -> tuple[float, list[str], list[str], list[CanFrame]]:
        """The plant over one dt under the firmware's last duties, then the firmware's step at
        the World's time on the counters there, as World.step_raw does with its own core."""
        t, nmea, crop, _ = super().step_raw()  # the in-process core's frames are not the ECU's
        seq = self._step_n & 0xFF
        self.link.send_clock(self.now_us, seq)
        self._counters(self._edge_us, seq)
        self._take(self.link.wait_step(self.step_timeout_s, seq))
        return t, nmea, crop, self.link.take_frames()

    def _free_running(self) -> tuple[float, list[str], list[str], list[CanFrame]]:
        """The firmware's next step on its own tick (its duties), the plant over one dt with
        them, and the counters for the firmware's step after."""
        st = self.link.wait_step(self.step_timeout_s)
        self._take(st)
        t, nmea, crop, _ = super().step_raw()
        # the plant is now at the firmware's next step: its time on the firmware's clock
        fw_next = st.time_us + self._dt_us
        self._counters((fw_next - ((self.now_us - self._edge_us) & _U32)) & _U32, st.seq)
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


def qemu_machine(
    image: Path,
) -> Callable[[SimConfig, int, Drive], AbstractContextManager[QemuWorld]]:
    """A `topdress.sim.experiments.Machine`: each run on a freshly booted firmware image, in
    lockstep with its World."""

    @contextmanager
    def machine(cfg: SimConfig, seed: int, drive: Drive) -> Iterator[QemuWorld]:
        with QemuEcu(QemuOptions(image=image)) as ecu:
            yield QemuWorld(ecu, cfg, seed=seed, drive=drive)

    return machine
