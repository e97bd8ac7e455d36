"""`topdress demo` end to end in real time: the simulated machine on real pseudo-terminals (read
with pyserial) and a virtual CAN bus, the terminal in front of it, the session log behind it."""

from __future__ import annotations

import io
import math
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import can
import pytest
import serial
from can import Message

from topdress import protocol
from topdress.cli.demo import demo_config_toml, run_demo
from topdress.cli.main import main
from topdress.cli.run import EXIT_NO_ECU
from topdress.config import default_config, loads_config
from topdress.ecu import meter_target_rpm
from topdress.errors import ConfigError
from topdress.log.session import RawRecord, SessionReader
from topdress.protocol import AckResult
from topdress.sim.live import PtyPort


@pytest.mark.wallclock
def test_demo_runs_meters_at_eq4_targets_and_logs(tmp_path: Path) -> None:
    out = io.StringIO()
    assert run_demo(11.0, tmp_path, out=out) == 0
    text = out.getvalue()
    sessions = list(tmp_path.glob("*.sqlite"))
    assert len(sessions) == 1
    assert f"session log: {sessions[0]}" in text
    assert f"topdress log summary {sessions[0]}" in text
    m = default_config().machine
    with SessionReader(sessions[0]) as reader:
        rows = list(reader.states())
        counts = reader.raw_counts()
    # 10 Hz rows over 11 s of wall time (a loaded machine may lose a few ticks, never gain)
    assert 90 <= len(rows) <= 111
    # NMEA (RMC+VTG+GGA at 5 Hz) and four crop sensors at 2 Hz came through the ptys
    assert counts["nmea"] > 100 and counts["crop"] > 60
    assert counts["can_rx"] > 300 and counts["can_tx"] > 27  # 27 parameters, then commands
    moving = [r for r in rows if r.v_kmh > 2.0 and r.rate_kg_ha_upper > 0]
    assert len(moving) > 20, "the drive leaves the headland after 3 s"
    for r in moving:
        # eq. 4 with the speed the ECU selected and a rate the terminal commanded within the
        # last command period (the rate moves with the NDVI between a command and the row)
        rates = [q.rate_kg_ha_upper for q in rows if r.t - 0.6 <= q.t <= r.t]
        lo, hi = (
            meter_target_rpm(m.width_m, q, r.v_kmh, m.kg_per_rev_upper)
            for q in (min(rates), max(rates))
        )
        assert lo * 0.99 - 0.05 <= r.target_rpm_upper <= hi * 1.01 + 0.05
    # the metering motor follows its target once up to speed (last second of the run)
    tail = moving[-10:]
    err = sum(abs(r.meter_rpm_upper - r.target_rpm_upper) for r in tail) / len(tail)
    assert err < 0.15 * sum(r.target_rpm_upper for r in tail) / len(tail)
    assert any(r.ndvi is not None and 0.3 < r.ndvi < 0.95 for r in rows)


def test_run_with_an_invalid_config_names_the_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[can]\ncommand_period_s = 0\n")
    assert main(["run", "--config", str(cfg), "--duration", "1"]) == 2
    assert "can.command_period_s" in capsys.readouterr().err


@pytest.mark.wallclock
def test_run_without_an_ecu_waits_for_it_for_the_whole_run_and_exits_3(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = tmp_path / "t.toml"
    cfg.write_text(
        '[gnss]\nport = "/dev/nonexistent-gnss"\n[crop]\nport = "/dev/nonexistent-crop"\n'
        f'[can]\nchannel = "test-demo-no-ecu"\n[log]\ndir = "{tmp_path}"\n'
    )
    # the implement never hitched: no error, the wait shown, then "nothing was metered"
    assert main(["run", "--config", str(cfg), "--duration", "2"]) == EXIT_NO_ECU == 3
    out, err = capsys.readouterr()
    assert err == ""
    assert (
        "ECU wait: WorkingWidth unacknowledged after 4 tries on CAN virtual:test-demo-no-ecu;"
        " still trying (is the ECU powered, on this bus?)"
    ) in out
    assert "ecu=wait(virtual:test-demo-no-ecu)" in out  # the status line says where it listens
    assert "v=--km/h src=--" in out and "ecu=ok" not in out
    assert "the ECU never acknowledged its parameters on CAN virtual:test-demo-no-ecu" in out
    # the ports that cannot be opened are named, with the reason
    assert "GNSS lost (serial:/dev/nonexistent-gnss: [Errno 2] could not open port" in out
    assert "crop sensors lost (serial:/dev/nonexistent-crop: [Errno 2] could not open port" in out
    (session,) = tmp_path.glob("*.sqlite")
    assert f"session log: {session}" in out
    with SessionReader(session) as reader:
        rows = list(reader.states())
        sent = [_decoded(r) for r in reader.raw() if r.kind == "can_tx"]
    # the tries of the first parameter, over and over; no command (no stop either)
    assert len(sent) >= 4 and set(sent) == {protocol.PcParamSet(1, 3.6)}
    # GNSS and crop ports missing: nothing is invented while it waited
    assert rows and all(r.v_gnss_kmh is None and r.source == "none" for r in rows)


def _decoded(record: RawRecord) -> protocol.Frame:
    assert record.can_id is not None and record.data is not None
    return protocol.decode((record.can_id, record.data))


class _NarrowFirmwareEcu(threading.Thread):
    """An ECU whose firmware takes at most 5000 encoder pulses per revolution (the terminal's
    file allows 10000): it refuses more as out of range, acknowledges everything else."""

    def __init__(self, channel: str) -> None:
        super().__init__(daemon=True)
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.stop = threading.Event()
        self.ack = protocol.database().get_message_by_name("EcuParamAck")

    def run(self) -> None:
        while not self.stop.is_set():
            msg = self.bus.recv(timeout=0.01)
            if msg is None or msg.arbitration_id != protocol.DEFAULT_IDS.param_set:
                continue
            frame = protocol.decode(msg)
            assert isinstance(frame, protocol.PcParamSet)
            spec = frame.spec
            refused = spec.signal == "WheelPulsesPerRev" and frame.value > 5000
            signals = {
                "AckParamId": spec.id,
                "AckResult": int(AckResult.OUT_OF_RANGE if refused else AckResult.OK),
                "AckRaw": 5000 if refused else spec.to_raw(frame.value),
            }
            data = self.ack.encode(signals)
            self.bus.send(Message(arbitration_id=protocol.DEFAULT_IDS.param_ack, data=data))


def test_run_with_a_parameter_the_ecu_refuses_fails_naming_it_and_keeps_the_log(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = tmp_path / "t.toml"
    cfg.write_text(
        '[gnss]\nport = "/dev/nonexistent-gnss"\n[crop]\nport = "/dev/nonexistent-crop"\n'
        f'[machine]\nwheel_ppr = 8000\n[can]\nchannel = "test-demo-refused"\n'
        f'[log]\ndir = "{tmp_path}"\n'
    )
    ecu = _NarrowFirmwareEcu("test-demo-refused")
    ecu.start()
    try:
        assert main(["run", "--config", str(cfg), "--duration", "30"]) == 2
    finally:
        ecu.stop.set()
        ecu.join()
        ecu.bus.shutdown()
    out, err = capsys.readouterr()
    assert "ECU parameter WheelPulsesPerRev = 8000: refused by the ECU: out of range" in err
    (session,) = tmp_path.glob("*.sqlite")
    assert f"session log: {session}" in out
    with SessionReader(session) as reader:
        sent = [_decoded(r) for r in reader.raw() if r.kind == "can_tx"]
    # the parameters up to the refused one, in order (one may be sent again when its
    # acknowledge is late on a loaded machine); no command
    ids = [f.param_id for f in sent if isinstance(f, protocol.PcParamSet)]
    assert list(dict.fromkeys(ids)) == [1, 2, 3, 4, 5] and ids == sorted(ids)
    assert all(isinstance(f, protocol.PcParamSet) for f in sent)


def test_demo_duration_must_be_positive(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["demo", "--duration", "-3"])
    assert "must be > 0" in capsys.readouterr().err


def test_pty_nobody_reads_drops_and_counts_instead_of_blocking() -> None:
    port = PtyPort()
    try:
        line = b"$GNRMC,000000.00,V,,,,,,,210526,,,N*5F\r\n"
        dropped = sum(port.write(line) for _ in range(20_000))  # ~840 kB, far over the buffer
        assert 0 < dropped < 20_000 * len(line)
        # what did fit is there, intact, for a reader that comes late
        with open(port.path, "rb", buffering=0) as reader:
            assert reader.read(len(line)) == line
    finally:
        port.close()


@pytest.mark.parametrize(
    ("section", "named"),
    [
        ('[can]\ninterface = "no_such_interface"\n', "'no_such_interface'"),
        ('[crop]\nsource = "file"\npath = "/nonexistent/crop.txt"\n', "/nonexistent/crop.txt"),
    ],
)
def test_run_with_a_device_that_cannot_open_names_it_and_leaves_no_session(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], section: str, named: str
) -> None:
    cfg = tmp_path / "t.toml"
    cfg.write_text(f'[log]\ndir = "{tmp_path / "logs"}"\n' + section)
    assert main(["run", "--config", str(cfg), "--duration", "1"]) == 2
    assert named in capsys.readouterr().err
    assert not list(tmp_path.glob("logs/*"))


@pytest.mark.wallclock
def test_sigterm_stops_the_demo_cleanly(tmp_path: Path) -> None:
    # A service stop or the cab PC shutting down: the same clean end as Ctrl-C.
    proc = subprocess.Popen(
        [sys.executable, "-m", "topdress.cli", "demo", "--duration", "60", "--out", str(tmp_path)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    assert proc.stdout is not None
    lines = [proc.stdout.readline()]  # the banner, events, then a status line per second
    while lines[-1] and not lines[-1].startswith("t=1."):
        lines.append(proc.stdout.readline())
    assert lines[-1], "the demo ended before its second status line"
    proc.send_signal(signal.SIGTERM)
    out = "".join(lines) + proc.stdout.read()
    assert proc.wait(timeout=30) == 0
    assert "stopped by SIGTERM" in out
    (session,) = tmp_path.glob("*.sqlite")
    assert f"session log: {session}" in out
    with SessionReader(session) as reader:
        assert "closed_utc" in reader.meta and reader.meta["lost"] == "0"


class _PulledAdapter(can.BusABC):  # type: ignore[misc]
    """A serial CAN adapter (slcan) pulled out: pyserial's errors come through python-can."""

    def __init__(self) -> None:
        super().__init__(channel="pulled")

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        raise serial.SerialException("Could not configure port: (5, 'Input/output error')")

    def _recv_internal(self, timeout: float | None) -> tuple[None, bool]:
        raise can.CanOperationError("Could not read from serial device")

    def shutdown(self) -> None:
        super().shutdown()
        raise can.CanOperationError("Could not write to serial device")


def test_run_with_the_can_adapter_pulled_fails_cleanly(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("topdress.cli.demo.open_bus", lambda cfg: _PulledAdapter())
    cfg = tmp_path / "t.toml"
    cfg.write_text(f'[gnss]\nport = "/dev/nonexistent"\n[log]\ndir = "{tmp_path}"\n')
    # no traceback: the adapter is given up at its first error (pyserial's: it is gone) and
    # opened again (here the configuration's virtual bus, where no ECU answers: it waits)
    assert main(["run", "--config", str(cfg), "--duration", "1.5"]) == EXIT_NO_ECU
    out, err = capsys.readouterr()
    assert err == ""
    assert out.count("CAN send failed: Could not configure port") == 1
    assert out.count("CAN adapter lost (virtual:topdress: Could not configure port") == 1
    assert out.count("CAN adapter virtual:topdress open again after") == 1
    assert "ECU wait: WorkingWidth unacknowledged after 4 tries" in out
    assert "session log:" in out


def test_demo_config_keeps_any_log_directory() -> None:
    odd = Path('runs "north" field\\2026')
    cfg = loads_config(demo_config_toml("/dev/pts/7", "/dev/pts/8", "ch", odd))
    assert cfg.log.dir == str(odd) and cfg.gnss.port == "/dev/pts/7"


def test_demo_without_pseudo_terminals_fails_naming_them(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    def no_ptys(*args: object) -> None:
        raise OSError(2, "out of pty devices")

    monkeypatch.setattr("topdress.cli.demo.LiveMachine", no_ptys)
    assert main(["demo", "--duration", "1", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "cannot make the simulated machine's pseudo-terminals" in err
    assert "out of pty devices" in err


def test_demo_log_directory_with_an_emoji_works(tmp_path: Path) -> None:
    # The path went into the embedded TOML as a JSON surrogate pair, which TOML refuses.
    out_dir = tmp_path / "feld 🚜"
    assert run_demo(1.0, out_dir, out=io.StringIO()) == 0
    assert len(list(out_dir.glob("*.sqlite"))) == 1
    assert "🚜" in (out_dir / "topdress-demo.toml").read_text(encoding="utf-8")


def test_demo_log_directory_with_a_non_utf8_byte_is_a_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = os.fsdecode(os.fsencode(str(tmp_path)) + b"/bad\xff")
    assert main(["demo", "--duration", "1", "--out", bad]) == 2
    err = capsys.readouterr().err
    assert "not UTF-8" in err and "Traceback" not in err and "RuntimeError" not in err


@pytest.mark.wallclock
def test_demo_with_a_users_file_runs_its_settings_on_its_machines_geometry(
    tmp_path: Path,
) -> None:
    """`topdress demo --config FILE`: the terminal runs with the user's file (its devices
    replaced by the simulation's), and the simulated machine has the file's geometry: two crop
    sensors 3.0 m ahead, a 3 m width, the antenna 2 m ahead of the outlets."""
    user = tmp_path / "mine.toml"
    user.write_text(
        "# my machine\n[machine]\nwidth_m = 3.0\noutlet_along_m = -2.0\n"
        '[crop]\nsensors = 2\nsensor_to_meter_m = 3.0\nport = "/dev/ttyUSB7"\n'
        '[can]\ninterface = "socketcan"\nchannel = "can9"\n[can.options]\nfd = false\n'
        "[rate.linear]\nrate_0_kg_ha = 500.0\n",
        encoding="utf-8",
    )
    out = tmp_path / "out"
    args = ["demo", "--config", str(user), "--duration", "6", "--out", str(out), "--start"]
    assert main([*args, "--no-display"]) == 0
    demo_file = out / "topdress-demo.toml"
    cfg = loads_config(demo_file.read_text(encoding="utf-8"))
    assert "# my machine" in demo_file.read_text(encoding="utf-8")  # the user's file, kept
    assert (cfg.machine.width_m, cfg.machine.outlet_along_m) == (3.0, -2.0)
    assert (cfg.crop.sensors, cfg.crop.sensor_to_meter_m) == (2, 3.0)
    assert cfg.rate.linear.rate_0_kg_ha == 500.0
    assert cfg.crop.port.startswith("/dev/pts/")  # the simulation's, not /dev/ttyUSB7
    assert (cfg.can.interface, cfg.can.options, cfg.log.dir) == ("virtual", {}, str(out))
    assert user.read_text(encoding="utf-8").startswith("# my machine\n[machine]")  # untouched
    (session,) = out.glob("*.sqlite")
    with SessionReader(session) as reader:
        crop = [r.line or "" for r in reader.raw() if r.kind == "crop"]
        assert reader.count("state") > 30
    # the simulated machine has two sensors: ids 1 and 2, no line the terminal refuses
    ids = {line.split(",")[0] for line in crop}
    assert crop and ids == {"1", "2"}, ids


def test_the_simulated_machine_takes_the_configurations_geometry() -> None:
    from topdress.sim.gnss import EARTH_R_M
    from topdress.sim.world import SimConfig, World

    cfg = loads_config(
        "[machine]\nwidth_m = 6.0\noutlet_along_m = -2.5\noutlet_across_m = 0.5\n"
        "[crop]\nsensors = 3\nsensor_to_meter_m = 4.0\n"
    )
    sim = SimConfig.of_machine(cfg)
    assert sim.crop_offsets_m == (-2.0, 0.0, 2.0)
    assert sim.crop_ahead_m == 4.0  # the terminal's crop.sensor_to_meter_m
    assert (sim.gnss.antenna_along_m, sim.gnss.antenna_across_m) == (2.5, -0.5)
    # the defaults are the simulator's own machine, bit for bit
    assert SimConfig.of_machine(default_config()) == SimConfig()

    # the receiver reports the antenna, 2.5 m ahead of the outlets and 0.5 m to their left:
    # the same drive (same seed, same noise) with the antenna over the outlets, beside it
    def fix(sim: SimConfig) -> tuple[float, float, float]:
        world = World(sim, seed=1)
        world.run(10.0)
        f = world.gnss.last_fix
        assert f is not None and f.valid and f.speed_ms > 1.0
        return f.lat_deg, f.lon_deg, world.tractor.heading

    lat0, lon0, heading = fix(SimConfig())
    lat1, lon1, _ = fix(sim)
    north_m = math.radians(lat1 - lat0) * EARTH_R_M
    east_m = math.radians(lon1 - lon0) * EARTH_R_M * math.cos(math.radians(lat0))
    along = north_m * math.cos(heading) + east_m * math.sin(heading)
    right = east_m * math.cos(heading) - north_m * math.sin(heading)
    assert (along, right) == pytest.approx((2.5, -0.5), abs=0.01)


def _make_demo_argv(duration_s: int) -> list[str]:
    """The command `make demo` runs (from `make -n`), without the program's path."""
    root = Path(__file__).resolve().parents[1]
    dry = subprocess.run(
        ["make", "-n", "-W", ".venv/.installed-stamp", "-o", ".venv/.installed-stamp", "demo",
         f"DURATION={duration_s}"],
        cwd=root, capture_output=True, text=True, check=True,
    ).stdout  # fmt: skip
    (line,) = [ln for ln in dry.splitlines() if "topdress demo" in ln]
    words = line.split()
    return words[words.index("demo") :]


def _kg_applied(text: str) -> float:
    (line,) = [ln for ln in text.splitlines() if ln.startswith("simulated machine:")]
    return float(line.split(" kg applied")[0].rsplit(" ", 1)[1])


@pytest.mark.wallclock
def test_make_demo_starts_the_meters_and_reports_the_kg_applied(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """The README's main command shows the main job: the meters run without anybody pressing
    Start, and the end says how much was applied; `topdress demo` alone still waits."""
    argv = _make_demo_argv(10)
    assert "--start" in argv
    assert main([*argv, "--out", str(tmp_path / "made"), "--no-display"]) == 0
    made = capfd.readouterr().out
    assert _kg_applied(made) > 0.05  # 3 s of headland, then 8 km/h at ~140 kg/ha on 3.6 m
    assert "meters stopped until the operator starts them" not in made

    assert main(["demo", "--duration", "4", "--out", str(tmp_path / "plain"), "--no-display"]) == 0
    plain = capfd.readouterr().out
    assert "meters stopped until the operator starts them" in plain
    assert _kg_applied(plain) == 0.0


@pytest.mark.wallclock
def test_the_log_disks_free_space_margin_is_a_setting(tmp_path: Path) -> None:
    """`[log] min_free_mib`: a margin larger than the disk's free space is the log_low_space
    alarm from the start (the margin was fixed at 50 MiB in the code)."""
    user = tmp_path / "mine.toml"
    user.write_text("[log]\nmin_free_mib = 1000000\n", encoding="utf-8")  # ~1 TB
    out = tmp_path / "out"
    args = ["demo", "--config", str(user), "--duration", "3", "--out", str(out), "--start"]
    assert main([*args, "--no-display"]) == 0
    (session,) = out.glob("*.sqlite")
    with SessionReader(session) as reader:
        raised = [e.detail.get("name") for e in reader.events() if e.kind == "alarm.raised"]
    assert "log_low_space" in raised
    with pytest.raises(ConfigError, match=r"log\.min_free_mib"):
        loads_config("[log]\nmin_free_mib = -1\n")
