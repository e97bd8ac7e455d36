"""Set-up from nothing and the settings' file side: `config init|check`, `--version`, the
[display] and [operator] keys, the PIN, saving a section, typed commands, `sim ecu`."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from topdress import __version__, protocol
from topdress import config_edit as settings
from topdress.cli.config import can_interfaces, init_text
from topdress.cli.main import main
from topdress.config import (
    DEFAULT_TOML,
    DisplayConfig,
    check_pin,
    default_config,
    load_config,
    loads_config,
    redacted_text,
)
from topdress.crop.rate import rate_curve
from topdress.devices import ports
from topdress.errors import ConfigError, ProtocolError
from topdress.terminal.calibration import CalibrationError, kg_per_rev, wheel_result
from topdress.view import commands as op


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out == f"topdress {__version__}\n"


def test_config_init_fills_in_this_machines_ports_and_says_what_virtual_is() -> None:
    text = init_text(["/dev/ttyUSB0", "/dev/ttyUSB3", "/dev/ttyACM0"], ["can1", "vcan0"])
    cfg = loads_config(text)
    assert (cfg.gnss.port, cfg.crop.port) == ("/dev/ttyUSB0", "/dev/ttyUSB3")
    assert (cfg.can.interface, cfg.can.channel) == ("socketcan", "can1")
    assert "# Serial ports found on this machine: /dev/ttyUSB0, /dev/ttyUSB3, /dev/ttyACM0" in text
    assert "# working width, m (6 rows x 0.60 m)" in text  # the default file's comments stay
    bare = init_text([], [])
    cfg = loads_config(bare)
    assert cfg.can.interface == "virtual" and cfg.gnss.port == "/dev/ttyUSB0"
    assert "No SocketCAN interface found" in bare and "simulator" in bare
    assert "No serial port found" in bare


def test_can_interfaces_are_the_kernels_can_links(tmp_path: Path) -> None:
    for name, kind in (("eth0", "1"), ("can0", "280"), ("vcan1", "280"), ("lo", "772")):
        (tmp_path / name).mkdir()
        (tmp_path / name / "type").write_text(kind + "\n")
    (tmp_path / "broken").mkdir()  # no type file: skipped
    assert can_interfaces(tmp_path) == ["can0", "vcan1"]
    assert can_interfaces(tmp_path / "missing") == []


def test_config_init_and_check_from_the_command_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "new" / "terminal.toml"
    assert main(["config", "init", str(path)]) == 0
    out = capsys.readouterr().out
    assert f"wrote {path}" in out
    load_config(path)
    assert main(["config", "init", str(path)]) == 2  # never over an existing file
    assert "exists already (use --force" in capsys.readouterr().err
    assert main(["config", "check", str(path)]) == 0
    out = capsys.readouterr().out
    assert f"{path}: ok" in out and "display: http://127.0.0.1:8080" in out
    path.write_text("[speed]\ncv_window = 9\nqueue_len = 5\n")
    assert main(["config", "check", str(path)]) == 2
    assert "speed.cv_window: must not exceed speed.queue_len" in capsys.readouterr().err


def test_run_on_the_virtual_bus_warns_that_no_ecu_can_answer(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = tmp_path / "t.toml"
    cfg.write_text(
        '[gnss]\nport = "/dev/nonexistent-gnss"\n[crop]\nport = "/dev/nonexistent-crop"\n'
        f'[can]\nchannel = "test-setup-virtual"\n[log]\ndir = "{tmp_path}"\n'
    )
    assert main(["run", "--config", str(cfg), "--duration", "0.5"]) == 3
    out = capsys.readouterr().out
    assert 'warning: can.interface = "virtual" is the simulator\'s in-process bus' in out
    assert "meters stopped until the operator starts them (type start, or the display)" in out


@pytest.mark.parametrize(
    ("host", "pin", "error"),
    [
        ("127.0.0.1", "", None),
        ("::1", "", None),
        ("0.0.0.0", "", "display.pin: is required when display.host is '0.0.0.0'"),
        ("0.0.0.0", "4711", None),
        ("192.168.1.20", "123", "display.pin: must be 4 to 12 digits"),
        ("192.168.1.20", "12ab", "display.pin: must be 4 to 12 digits"),
        ("192.168.1.20", "1234567890123", "display.pin: must be 4 to 12 digits"),
        ("", "", "display.host: must be an address to listen on"),
    ],
)
def test_display_host_and_pin(host: str, pin: str, error: str | None) -> None:
    text = f'[display]\nhost = "{host}"\npin = "{pin}"\n'
    if error is None:
        cfg = loads_config(text)
        assert (cfg.display.host, cfg.display.pin, cfg.display.port) == (host, pin, 8080)
    else:
        with pytest.raises(ConfigError, match=re.escape(error)):
            loads_config(text)


def test_display_keys_are_checked_and_the_pin_never_shown() -> None:
    with pytest.raises(ConfigError, match=re.escape("display.port: 0 is outside 1..65535")):
        loads_config("[display]\nport = 0\n")
    with pytest.raises(ConfigError, match=re.escape("display.language: must be one of en, zh")):
        loads_config('[display]\nlanguage = "fr"\n')
    with pytest.raises(ConfigError) as exc:
        loads_config('[display]\nhost = "0.0.0.0"\npin = 987654\n')
    assert "987654" not in str(exc.value)
    text = '[display]\nhost = "0.0.0.0"\npin = "987654"   # the cab\'s PIN\n'
    red = redacted_text(text)
    assert "987654" not in red and 'pin = "***"' in red and "# the cab's PIN" in red
    assert redacted_text(DEFAULT_TOML) == DEFAULT_TOML.replace('pin = ""', 'pin = "***"')


def test_check_pin() -> None:
    assert check_pin(DisplayConfig(), "anything")  # no PIN set: nothing to check
    d = DisplayConfig(host="0.0.0.0", pin="4711")
    assert check_pin(d, "4711")
    assert not check_pin(d, "4712") and not check_pin(d, "") and not check_pin(d, "47110")
    assert not check_pin(d, "４７１１")  # full-width digits are not the PIN


def test_operator_keys() -> None:
    cfg = loads_config("[operator]\nautostart = true\noff_rate_pct = 15\n")
    assert cfg.operator.autostart and cfg.operator.off_rate_pct == 15.0
    with pytest.raises(
        ConfigError, match=re.escape("operator.off_rate_s: 0.1 is outside 0.5..120")
    ):
        loads_config("[operator]\noff_rate_s = 0.1\n")


def test_validate_section_names_the_key_and_keeps_the_rest() -> None:
    cfg = default_config()
    new = settings.validate_section(cfg, "speed", {"cv_threshold_pct": 3.5})
    assert new.speed.cv_threshold_pct == 3.5 and new.machine == cfg.machine
    with pytest.raises(ConfigError) as exc:
        settings.validate_section(cfg, "speed", {"cv_window": 6})
    assert exc.value.key == "speed.cv_window"
    with pytest.raises(ConfigError) as exc:
        settings.validate_section(cfg, "gnss", {"port": "/dev/ttyUSB1"})  # the crop's port
    # the check names the second of the two keys, saying which the first is
    assert str(exc.value) == "crop.port: /dev/ttyUSB1 is gnss.port too: one device per port"
    with pytest.raises(ConfigError) as exc:
        settings.validate_section(cfg, "rate", {"linear": {"ndvi_1": 0.3}})
    assert exc.value.key == "rate.linear.ndvi_1"
    new = settings.validate_section(cfg, "rate", {"table": {"points": [[0.2, 400], [0.9, 100]]}})
    assert new.rate.table.points == ((0.2, 400.0), (0.9, 100.0))
    new = settings.validate_section(cfg, "ecu", {"pid_kp": 0.05})
    assert settings.changed_ecu_params(cfg, new) == {12: 0.05}
    assert (
        protocol.param(12).config_key == "ecu.pid_kp"
        and protocol.param(9).config_key == "speed.switch_speed_kmh"
    )
    with pytest.raises(ConfigError, match="no such section"):
        settings.validate_section(cfg, "radio", {})
    assert settings.section_values(cfg, "can")["ids"]["cal_status"] == 0x18656465


def test_save_section_keeps_comments_and_a_backup(tmp_path: Path) -> None:
    path = tmp_path / "t.toml"
    original = "# my machine\n[machine]\nwidth_m = 3.0   # measured\n\n[gnss]\nbaud = 4800\n"
    path.write_text(original)
    cfg = settings.save_section(path, "gnss", {"baud": 9600, "port": "/dev/ttyS4"})
    assert cfg.gnss.baud == 9600 and cfg.machine.width_m == 3.0
    text = path.read_text()
    assert "# my machine" in text and "width_m = 3.0   # measured" in text
    assert 'port = "/dev/ttyS4"' in text
    assert (tmp_path / "t.toml.bak").read_text() == original
    # a value the checks refuse: nothing written, the file and its backup as they were
    with pytest.raises(ConfigError, match=re.escape("gnss.baud")):
        settings.save_section(path, "gnss", {"baud": 1})
    assert path.read_text() == text and (tmp_path / "t.toml.bak").read_text() == original
    settings.save_section(path, "rate", {"linear": {"ndvi_0": 0.25}})
    assert load_config(path).rate.linear.ndvi_0 == 0.25
    assert not list(tmp_path.glob(".*.tmp"))


def test_can_options_are_given_whole_and_checked_by_name(tmp_path: Path) -> None:
    path = tmp_path / "t.toml"
    path.write_text(
        '[can]\ninterface = "slcan"\nchannel = "/dev/ttyACM0"\n\n'
        "[can.options]\ntty_baudrate = 115200   # the adapter's serial speed\n"
        "sleep_after_open = 2\n"
    )
    cfg = load_config(path)
    assert settings.section_values(cfg, "can")["options"] == {
        "tty_baudrate": 115200,
        "sleep_after_open": 2,
    }
    # a name left out is removed, the kept one keeps its comment, a new one is added
    new = settings.save_section(path, "can", {"options": {"tty_baudrate": 921600, "rtscts": True}})
    assert dict(new.can.options) == {"tty_baudrate": 921600, "rtscts": True}
    text = path.read_text()
    assert "sleep_after_open" not in text and "# the adapter's serial speed" in text
    assert settings.validate_section(new, "can", {"options": {}}).can.options == {}
    with pytest.raises(ConfigError) as exc:
        settings.validate_section(new, "can", {"options": {"bitrate": 250000}})
    assert str(exc.value) == "can.options.bitrate: is set by can.bitrate"
    with pytest.raises(ConfigError) as exc:
        settings.validate_section(new, "can", {"options": {"tty-baud": 1}})
    assert exc.value.key == "can.options.tty-baud"
    # which keys a device is opened with, as changed between two configurations
    moved = settings.validate_section(new, "can", {"channel": "/dev/ttyACM1", "bitrate": 500000})
    assert settings.changed_device_keys(new, moved, "can") == ["can.channel", "can.bitrate"]
    assert settings.changed_device_keys(new, new, "can") == []
    assert settings.changed_device_keys(new, moved, "rate") == []


def test_rate_curve_is_the_model_over_ndvi() -> None:
    curve = rate_curve(default_config().rate, n=11)
    assert len(curve) == 11 and curve[0][0] == 0.0 and curve[-1][0] == 1.0
    got = dict(curve)
    assert got[0.3] == pytest.approx(450.0) and got[0.8] == pytest.approx(150.0)
    assert got[0.5] == pytest.approx(330.0)  # on the line between the two points
    assert got[0.0] == pytest.approx(600.0) and got[1.0] == pytest.approx(30.0)  # clamped


def test_serial_ports_listed_by_device(monkeypatch: pytest.MonkeyPatch) -> None:
    fake = [
        SimpleNamespace(device="/dev/ttyUSB1", description="FT232R", hwid="USB VID:PID=0403:6001"),
        SimpleNamespace(device="/dev/ttyS0", description=None, hwid=None),
    ]
    monkeypatch.setattr(ports.list_ports, "comports", lambda: fake)
    assert ports.list_serial_ports() == [
        ports.SerialPortInfo("/dev/ttyS0", "", ""),
        ports.SerialPortInfo("/dev/ttyUSB1", "FT232R", "USB VID:PID=0403:6001"),
    ]


@pytest.mark.parametrize(
    ("text", "command"),
    [
        ("start", op.Start()),
        (" STOP \n", op.Stop()),
        ("pause", op.Pause()),
        ("manual fixed 200 150.5", op.SetManual("fixed", 200.0, 150.5)),
        ("manual percent -15", op.SetManual("percent", percent=-15.0)),
        ("manual off", op.SetManual("off")),
        ("ack", op.AckAlarm(None)),
        ("ack fan_low_upper", op.AckAlarm("fan_low_upper")),
        ("reset season", op.ResetCounter("season")),
        ("catch lower", op.StartCatchTest("lower")),
        ("catch upper 30 25", op.StartCatchTest("upper", 30.0, 25.0)),
        ("weigh 6.02", op.FinishCatchTest(6.02)),
        ("wheel", op.StartWheelCal()),
        ("finish 39.6", op.FinishWheelCal(39.6)),
        ("fan 5", op.StartFanCheck(5.0)),
        ("close apply", op.CloseCalibration(apply=True)),
        ("test can", op.TestDevice("can")),
    ],
)
def test_typed_commands(text: str, command: object) -> None:
    assert op.parse_command(text) == command


@pytest.mark.parametrize(
    "text", ["", "go", "start now", "manual fixed 200", "weigh lots", "catch middle", "close it"]
)
def test_typed_nonsense_gets_the_help(text: str) -> None:
    with pytest.raises(op.OperatorError, match=r"commands: start \| stop|not a number"):
        op.parse_command(text)


def test_manual_mode_bounds_and_the_rates_in_each_state() -> None:
    o = op.Operator(autostart=False)
    assert o.rates((120.0, 80.0)) == (0.0, 0.0) and not o.start_bit
    o.start()
    assert o.rates((120.0, 80.0)) == (120.0, 80.0) and o.start_bit
    o.set_manual(op.SetManual("percent", percent=-100.0))
    assert o.rates((120.0, 80.0)) == (0.0, 0.0)
    o.set_manual(op.SetManual("percent", percent=200.0))
    assert o.rates((250.0, 80.0)) == (600.0, 240.0)  # capped at what the frame carries
    for bad in (
        op.SetManual("percent", percent=-100.1),
        op.SetManual("fixed", upper_kg_ha=-1.0),
        op.SetManual("fixed", lower_kg_ha=600.01),
        op.SetManual("auto"),
    ):
        with pytest.raises(op.OperatorError):
            o.set_manual(bad)
    assert o.manual.mode == "percent"
    o.pause()
    assert o.rates((120.0, 80.0)) == (0.0, 0.0) and o.start_bit  # fans stay on
    o.stop()
    assert not o.start_bit


def test_calibration_arithmetic() -> None:
    assert kg_per_rev(6.0, 20.0) == pytest.approx(0.3)
    for kg, rev in ((0.0, 20.0), (-1.0, 20.0), (float("nan"), 20.0), (6.0, 0.0)):
        with pytest.raises(CalibrationError):
            kg_per_rev(kg, rev)
    # the paper's wheel: 12.3 cm, 500 pulses; 51 750 pulses = 103.5 rev over a 40 m tape
    r = wheel_result(51_750, 500, 40.0, 0.0615, 40.8)
    assert r.revolutions == pytest.approx(103.5)
    assert r.radius_m == pytest.approx(40.0 / (2 * 3.141592653589793 * 103.5))
    # eq. 3 in the C core (float): 2 pi 0.0615 103.5 = 39.9937 m against 40 m and 40.8 m
    assert r.slip_pct == pytest.approx(0.01489, abs=2e-4)
    assert r.slip_gnss_pct == pytest.approx(1.9754, abs=2e-4)
    assert wheel_result(500, 500, 40.0, 0.0615, None).slip_gnss_pct is None
    with pytest.raises(CalibrationError):
        wheel_result(0, 500, 40.0, 0.0615, 40.0)


def test_calibration_frames_round_trip_and_range() -> None:
    msg = protocol.encode_cal_command(1, 1, 12.5, 20.0, 300)
    assert msg.arbitration_id == 0x0A646465
    assert protocol.decode(msg) == protocol.PcCalCommand(1, 1, 12.5, 20.0, 44)
    with pytest.raises(ProtocolError):
        protocol.encode_cal_command(3, 0, 1.0, 1.0)  # no such action (2: the look-ahead test)
    with pytest.raises(ProtocolError):
        protocol.encode_cal_command(1, 0, 7000.0, 1.0)  # more revolutions than the frame
    status = bytes([0x12, 0, 0x10, 0x27, 0, 0xD0, 0x07, 9])  # lower, running, 10.000 rev
    got = protocol.decode((0x18656465, status))
    assert got == protocol.EcuCalStatus("done", 1, "none", 10.0, 20.0, 9)
    with pytest.raises(ProtocolError, match="CalReason"):
        protocol.decode((0x18656465, bytes([0x02, 8, 0, 0, 0, 0, 0, 0])))


def _udp_or_skip(group: str) -> None:
    import can

    try:
        a = can.Bus(interface="udp_multicast", channel=group, fd=False)
    except OSError as exc:
        pytest.skip(f"udp_multicast CAN unavailable here: {exc}")
    a.shutdown()


@pytest.mark.wallclock
def test_sim_ecu_alone_on_a_bus_answers_a_real_terminal_and_says_what_to_weigh(
    tmp_path: Path,
) -> None:
    """`topdress sim ecu` in its own process; this one is the cab PC reading the ptys it named."""
    from topdress.devices.can import open_bus
    from topdress.devices.lines import open_line_source
    from topdress.terminal.app import Terminal

    group = f"239.74.{os.getpid() % 250}.{7 + os.getpid() % 200}"
    _udp_or_skip(group)
    # A port of its own: a socket on the default port hears every group joined on this host
    # (Linux), so another udp_multicast run on the machine would talk to this ECU.
    udp_port = 20000 + (os.getpid() * 7919) % 20000
    child = subprocess.Popen(
        [
            *(sys.executable, "-m", "topdress.cli", "sim", "ecu"),
            *("--can", f"udp_multicast:{group}", "--option", f"port={udp_port}"),
            *("--drive", "stand", "--duration", "9"),
        ],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    assert child.stdout is not None
    lines = []
    for line in child.stdout:
        lines.append(line)
        if line.startswith("Ctrl-C"):
            break
    head = "".join(lines)
    snippet = head.split("a terminal reaches it with:\n")[1].split("Ctrl-C")[0]
    cfg = loads_config(snippet)
    assert cfg.can.interface == "udp_multicast" and cfg.can.channel == group
    assert cfg.can.options == {"port": udp_port}
    term = Terminal(
        cfg,
        open_line_source(cfg.gnss),
        open_line_source(cfg.crop),
        open_bus(cfg.can),
        start=False,
    )
    runner = threading.Thread(target=term.run, kwargs={"duration_s": 8.0})
    runner.start()
    rest: list[str] = []
    reader = threading.Thread(target=lambda: rest.extend(child.stdout or []), daemon=True)
    reader.start()
    try:
        deadline = time.monotonic() + 8.0
        while not (term.link.ready and term.link.ecu_alive) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert term.link.ready
        res = term.post(op.StartCatchTest("upper", revolutions=2.0, meter_rpm=30.0)).result(2.0)
        assert res.ok, res.message
        # the operator reads the scale (the simulated machine says what it shows)
        deadline = time.monotonic() + 8.0
        weighed = None
        while weighed is None and time.monotonic() < deadline:
            time.sleep(0.1)
            weighed = re.search(
                r"catch test done: the upper meter let out ([0-9.]+) kg", "".join(rest)
            )
        assert weighed, ("".join(rest), term.snapshot.calibration)
        cal = term.snapshot.calibration
        assert cal is not None and cal.step == "weigh", cal
        assert term.snapshot.gnss_link == "ok" and term.snapshot.crop_link == "ok"
        res = term.post(op.FinishCatchTest(float(weighed.group(1)))).result(2.0)
        assert res.ok, res.message
        cal = term.snapshot.calibration
        time.sleep(0.3)
        cal = term.snapshot.calibration
        assert cal is not None
        # the simulated machine lets out 0.3 kg per revolution
        assert cal.result["kg_per_rev"] == pytest.approx(0.3, rel=0.01)
        assert 2.0 <= cal.result["revolutions"] < 2.15  # with the coast after the stop
    finally:
        runner.join()
        child.wait(timeout=30)
    assert child.returncode == 0


def test_can_adapter_options_reach_python_can() -> None:
    import can

    from topdress.devices.can import open_bus

    cfg = loads_config(
        '[can]\nchannel = "test-setup-options"\n[can.options]\nreceive_own_messages = true\n'
    )
    assert cfg.can.options == {"receive_own_messages": True}
    bus = open_bus(cfg.can)
    try:
        bus.send(can.Message(arbitration_id=0x123, data=b"\x01", is_extended_id=False))
        echo = bus.recv(timeout=1.0)  # only with the option: a virtual bus echoes its own frames
        assert echo is not None and echo.arbitration_id == 0x123
    finally:
        bus.shutdown()
    assert loads_config(
        '[can]\ninterface = "slcan"\nchannel = "/dev/ttyACM0"\n[can.options]\n'
        "tty_baudrate = 115200\n"
    ).can.options == {"tty_baudrate": 115200}
    for bad, key in (
        ("bitrate = 500000", "can.options.bitrate"),
        ("x = [1, 2]", "can.options.x"),
        ('"not a name" = 1', "can.options.not a name"),
    ):
        with pytest.raises(ConfigError) as exc:
            loads_config(f"[can.options]\n{bad}\n")
        assert exc.value.key == key
    new = settings.validate_section(default_config(), "can", {"options": {"tty_baudrate": 57600}})
    assert new.can.options == {"tty_baudrate": 57600}


def test_sim_ecu_options_become_the_terminals_can_options() -> None:
    from topdress.cli.sim import parse_options, terminal_snippet

    opts = parse_options(["port=43200", "tty_baudrate=115200", "fd=false", "name=left rack"])
    text = terminal_snippet("/dev/pts/3", "/dev/pts/4", "udp_multicast", "239.0.0.9", opts)
    cfg = loads_config(text)
    assert cfg.can.options == {
        "port": 43200,
        "tty_baudrate": 115200,
        "fd": False,
        "name": "left rack",
    }
    assert (cfg.gnss.port, cfg.crop.port) == ("/dev/pts/3", "/dev/pts/4")
    with pytest.raises(ConfigError, match="KEY=VALUE"):
        parse_options(["port"])
