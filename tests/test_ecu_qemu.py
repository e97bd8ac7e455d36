"""The firmware image in QEMU with the simulated machine in the loop (sim.qemu_ecu): it boots,
says who it is, takes the parameter push, meters the commanded rate, and its fail-safes fire.

One emulator run of 28 s of the machine's time serves every test: a working pass at 6.5 km/h,
the PC silent from 12 s to 14.5 s, then the upper metering wheel jams (18 s) and the ground-wheel
encoder dies (22 s). The firmware runs in lockstep with the simulator (each World step makes
exactly one firmware step at the World's time), so the run is the same on an idle or a loaded
host, as fast as the host allows. The same scenario runs on the in-process core (the World's
cffi ECU) as the reference: the firmware must do what the core does, step for step, within
what the HIL link's duty resolution (0.0001) changes in the plant.
"""

from __future__ import annotations

import io
import math
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from topdress import protocol
from topdress.cli.demo import run_demo
from topdress.cli.main import main
from topdress.ecu import EcuParams
from topdress.errors import ConfigError, DeviceError
from topdress.log.session import SessionReader
from topdress.log.summary import format_text, summarise
from topdress.protocol import Fault
from topdress.sim.actuators import MeterParams
from topdress.sim.qemu_ecu import (
    QemuEcu,
    QemuOptions,
    QemuSil,
    QemuWorld,
    ensure_image,
    qemu_missing,
)
from topdress.sim.sil import PcParams, Sil
from topdress.sim.tractor import Drive, Segment
from topdress.sim.wheel import WheelParams
from topdress.sim.world import SimConfig, World

REPO = Path(__file__).resolve().parents[1]
SILENT_S, RESUME_S, JAM_S, ENCODER_DEAD_S, END_S = 12.0, 14.5, 18.0, 22.0, 28.0
PUSH = (("working_width_m", 4.0), ("blocked_time_ms", 1000.0))

pytestmark = [
    pytest.mark.qemu,
    pytest.mark.skipif(qemu_missing() is not None, reason=str(qemu_missing())),
]


@dataclass
class Rec:
    """What the run saw, step by step."""

    t: list[float] = field(default_factory=list)
    duties: list[tuple[float, float, float, float]] = field(default_factory=list)
    meter_rpm: list[tuple[float, float]] = field(default_factory=list)
    ecu_meter_rpm: list[tuple[float, float]] = field(default_factory=list)
    target_rpm: list[tuple[float, float]] = field(default_factory=list)
    faults: list[Fault] = field(default_factory=list)
    selected_kmh: list[float] = field(default_factory=list)
    idents: list[protocol.EcuIdent] = field(default_factory=list)
    acks: list[protocol.EcuParamAck] = field(default_factory=list)
    last_command_t: float = 0.0
    timing: dict[str, float] = field(default_factory=dict)

    def first(self, after_s: float, cond: object) -> float | None:
        for t, ok in zip(self.t, cond, strict=True):  # type: ignore[call-overload]
            if t >= after_s and ok:
                return t
        return None


class RecWorld(QemuWorld):
    """QemuWorld that also keeps the firmware's EcuIdent frames (the cab PC skips them)."""

    idents: list[protocol.EcuIdent]

    def step_raw(self):  # type: ignore[no-untyped-def]
        out = super().step_raw()
        for fid, data in out[3]:
            if fid == protocol.DEFAULT_IDS.ident:
                ident = protocol.decode((fid, data))
                assert isinstance(ident, protocol.EcuIdent)
                self.idents.append(ident)
        return out


@pytest.fixture(scope="module")
def image() -> Path:
    if shutil.which("arm-none-eabi-gcc") is None:
        pytest.skip("arm-none-eabi-gcc is not installed (scripts/sysdeps.sh firmware)")
    subprocess.run(
        [
            "make",
            "--no-print-directory",
            "-s",
            "-f",
            "ecu/ports/stm32f4/firmware.mk",
            "VARIANT=qemu",
        ],
        cwd=REPO,
        check=True,
        capture_output=True,
    )
    return REPO / "build" / "fw-qemu" / "topdress-ecu-stm32f4.elf"


def _config() -> tuple[SimConfig, Drive, PcParams]:
    cfg = SimConfig(
        meter=(MeterParams(jammed_at_s=JAM_S), MeterParams()),
        wheel=WheelParams(encoder_dead_at_s=ENCODER_DEAD_S),
    )
    drive = Drive([Segment("stop", duration_s=1.0), Segment("straight", 6.5, length_m=1000.0)])
    return cfg, drive, PcParams(ecu_params=PUSH, rate_kg_ha=(150.0, 150.0))


def _run(sil: Sil, world: World, r: Rec) -> None:
    r.acks = list(sil.pc.acks)
    while world.t_s < END_S:
        pc = sil.pc
        if SILENT_S <= world.t_s < RESUME_S and math.isfinite(pc.next_poll_s):
            # the PC falls silent: its cycle and command timer do not come due ...
            pc._next_cycle = pc._next_cmd = pc.next_poll_s = math.inf
        elif world.t_s >= RESUME_S and not math.isfinite(pc.next_poll_s):
            # ... until it is back
            pc._next_cycle = pc._next_cmd = pc.next_poll_s = world.t_s
        next_cmd = pc._next_cmd
        sil.step()
        if pc._next_cmd != next_cmd and world.t_s <= SILENT_S:
            r.last_command_t = world.t_s
        tg, dg, sp, st = pc.targets, pc.diag, pc.speeds, pc.status
        r.t.append(world.t_s)
        r.duties.append(world.duties if isinstance(world, QemuWorld) else _duties(world))
        r.meter_rpm.append(world.truth.meter_rpm)
        r.ecu_meter_rpm.append((st.meter_rpm_upper, st.meter_rpm_lower) if st else (0.0, 0.0))
        r.target_rpm.append((tg.target_rpm_upper, tg.target_rpm_lower) if tg else (0.0, 0.0))
        r.faults.append(dg.faults if dg else Fault(0))
        r.selected_kmh.append(sp.selected_kmh if sp else 0.0)


def _duties(world: World) -> tuple[float, float, float, float]:
    s = world.ecu.state
    return (*s.meter_duty, *s.fan_duty)


@pytest.fixture(scope="module")
def ref() -> Rec:
    """The in-process core in the same scenario."""
    cfg, drive, pc = _config()
    r = Rec()
    world = World(cfg, seed=3, drive=drive)
    with Sil(world, pc, record=False) as sil:
        _run(sil, world, r)
    return r


@pytest.fixture(scope="module")
def rec(image: Path) -> Rec:
    cfg, drive, pc = _config()
    r = Rec()
    with QemuEcu(QemuOptions(image=image)) as ecu:
        world = RecWorld(ecu, cfg, seed=3, drive=drive)
        world.idents = r.idents
        with QemuSil(world, pc, record=False) as sil:
            _run(sil, world, r)
        r.timing = world.timing.summary()
    return r


def test_boots_and_says_who_it_is(rec: Rec) -> None:
    assert rec.idents, "no EcuIdent from the firmware"
    ident = rec.idents[0]
    assert ident.target == "stm32f4" and ident.transport == "slcan-hil"
    assert ident.protocol_version == "1.1" and ident.firmware_version == "0.1.0"
    assert not ident.clock_fallback  # the emulator's clock is taken as the board's 168 MHz
    assert ident.reset_cause == "unknown"  # the emulator has no reset flags


def test_takes_the_parameter_push(rec: Rec) -> None:
    assert [(a.param_id, a.result) for a in rec.acks] == [
        (protocol.param(k).id, protocol.AckResult.OK) for k, _ in PUSH
    ]
    assert [a.value for a in rec.acks] == [pytest.approx(v) for _, v in PUSH]


def test_steps_in_lockstep_with_the_simulator(rec: Rec, ref: Rec) -> None:
    tm = rec.timing
    # every firmware step at the World's time, none without fresh counters
    assert tm["steps"] == round(END_S / 0.01) - 1  # intervals between the steps made
    assert tm["min_us"] == tm["max_us"] == 10_000
    assert tm["late_inputs"] == 0
    # the firmware's duties are the in-process core's, step for step
    assert rec.t == ref.t
    pairs = zip(rec.duties, ref.duties, strict=True)
    worst = max(abs(a - b) for fw, core in pairs for a, b in zip(fw, core, strict=True))
    assert worst < 0.01


def _window(rec: Rec, lo: float, hi: float) -> list[int]:
    return [i for i, t in enumerate(rec.t) if lo <= t < hi]


def test_meters_the_commanded_rate_in_steady_state(rec: Rec) -> None:
    idx = _window(rec, 6.0, SILENT_S)
    kg_per_rev = EcuParams.defaults().kg_per_rev

    def mean(values: list[tuple[float, float]], layer: int) -> float:
        return sum(values[i][layer] for i in idx) / len(idx)

    v = sum(rec.selected_kmh[i] for i in idx) / len(idx)
    for layer in (0, 1):
        target = mean(rec.target_rpm, layer)
        # eq. 4 with the pushed working width: rpm = W x rate x v / (600 x kg/rev)
        assert target == pytest.approx(4.0 * 150.0 * v / (600.0 * kg_per_rev[layer]), rel=0.01)
        # the firmware holds its target, as the in-process core does (test_ecu_app.py) ...
        assert mean(rec.ecu_meter_rpm, layer) == pytest.approx(target, rel=0.02)
        # ... and measures the simulated meter right
        assert mean(rec.meter_rpm, layer) == pytest.approx(mean(rec.ecu_meter_rpm, layer), rel=0.02)
    assert not any(rec.faults[i] & ~Fault.GNSS_LOST for i in idx)


# what the emulated firmware may add to a fail-safe's time: the duties' resolution on the HIL
# link moves the plant by a hair, which may move a threshold crossing by a few steps
SLACK_S = 0.05


def _fault_time(r: Rec, after_s: float, bit: Fault) -> float:
    t = r.first(after_s, [bool(f & bit) for f in r.faults])
    assert t is not None, f"{bit.name} never set"
    return t


def test_jammed_meter_is_latched_and_stopped(rec: Rec, ref: Rec) -> None:
    up = Fault.UPPER_BLOCKED
    t_ref = _fault_time(ref, JAM_S, up)
    t_fault = _fault_time(rec, JAM_S, up)
    assert t_ref - JAM_S < 3.0  # the core: blocked_time_ms (1 s) after the duty rose to 0.3
    assert abs(t_fault - t_ref) <= SLACK_S
    # latched: the upper meter stays off, the lower one goes on metering
    idx = _window(rec, t_fault + 0.5, ENCODER_DEAD_S)
    assert all(rec.duties[i][0] == 0.0 for i in idx)
    assert all(bool(rec.faults[i] & up) for i in idx)
    assert sum(rec.duties[i][1] for i in idx) / len(idx) > 0.2


def test_dead_wheel_encoder_falls_back_to_gnss(rec: Rec, ref: Rec) -> None:
    t_ref = _fault_time(ref, ENCODER_DEAD_S, Fault.WHEEL_ENCODER)
    t_fault = _fault_time(rec, ENCODER_DEAD_S, Fault.WHEEL_ENCODER)
    assert abs(t_fault - t_ref) <= SLACK_S
    idx = _window(rec, t_fault + 1.5, END_S)
    assert all(rec.duties[i][1] > 0.1 for i in idx)  # metering again, on the GNSS speed
    assert sum(rec.selected_kmh[i] for i in idx) / len(idx) == pytest.approx(6.5, abs=0.3)


def test_command_loss_stops_the_meters_within_the_timeout(rec: Rec, ref: Rec) -> None:
    timeout_s = EcuParams.defaults().cmd_timeout_ms / 1000.0
    for r in (ref, rec):
        t_stop = r.first(SILENT_S, [d[1] == 0.0 for d in r.duties])
        assert t_stop is not None
        # both stop them at the first step past the timeout
        assert r.last_command_t + timeout_s <= t_stop <= r.last_command_t + timeout_s + 0.011
        assert _fault_time(r, SILENT_S, Fault.CMD_TIMEOUT) <= t_stop + 0.1  # a status period
        assert r.meter_rpm[r.t.index(t_stop) + 100][1] < 0.5  # the plant's meter has run down
        # the PC back: metering again (the fault clears with the first command)
        assert max(d[1] for d in r.duties[r.t.index(t_stop) : r.t.index(JAM_S)]) > 0.1


def test_the_demo_runs_the_terminal_against_the_firmware(image: Path, tmp_path: Path) -> None:
    out = io.StringIO()
    assert run_demo(10.0, tmp_path, out=out, ecu="qemu") == 0
    text = out.getvalue()
    # the terminal says who answers on its bus, as it would of a real ECU
    assert "ECU: stm32f4 firmware 0.1.0, protocol 1.1 (slcan-hil)" in text.splitlines()
    (session,) = tmp_path.glob("*.sqlite")
    with SessionReader(session) as reader:
        s = summarise(reader)
    assert s.ecu is not None and s.ecu["target"] == "stm32f4"
    assert (
        "ECU              stm32f4 firmware 0.1.0, protocol 1.1 (slcan-hil, last reset: unknown)"
        in (format_text(s).splitlines())
    )
    # the drive leaves the headland after 3 s: the firmware meters what the terminal asks
    assert s.layers["upper"].applied_kg > 0.1
    assert abs(s.layers["upper"].rate_error_pct or 100.0) < 15.0


def test_no_image_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(DeviceError, match=r"no firmware image at .*: set TOPDRESS_ECU_IMAGE"):
        ensure_image(tmp_path / "topdress-ecu-stm32f4.elf")
    with pytest.raises(ConfigError, match="--ecu: 'stm32': one of host, qemu"):
        run_demo(1.0, tmp_path, ecu="stm32")
    # the firmware runs Table 2's experiment only: another is refused before any run
    assert main(["experiment", "cv", "--ecu", "qemu", "--out", str(tmp_path)]) == 2
    assert not list(tmp_path.iterdir())
