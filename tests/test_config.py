"""The terminal configuration: defaults, the documented file, and every kind of bad value."""

from __future__ import annotations

import os
import random
from collections import Counter
from pathlib import Path

import pytest

from topdress.cli.main import main
from topdress.config import (
    DEFAULT_TOML,
    MAX_CONFIG_BYTES,
    default_config,
    load_config,
    loads_config,
)
from topdress.errors import ConfigError

DOCS = Path(__file__).resolve().parents[1] / "docs" / "config.md"


def test_documented_default_file_equals_built_in_defaults() -> None:
    assert loads_config(DEFAULT_TOML) == default_config()
    assert loads_config("") == default_config()


def test_docs_show_the_default_file() -> None:
    assert DEFAULT_TOML.strip() in DOCS.read_text(encoding="utf-8")


def test_paper_values_are_the_defaults() -> None:
    cfg = default_config()
    assert cfg.machine.width_m == 3.6
    assert cfg.machine.rows == 6
    assert cfg.machine.wheel_radius_m == 0.0615
    assert cfg.machine.wheel_ppr == 500
    assert (cfg.speed.queue_len, cfg.speed.cv_window) == (5, 5)
    assert cfg.speed.cv_threshold_pct == 4.2
    assert cfg.speed.switch_speed_kmh == 6.0
    assert cfg.gnss.baud == 9600
    assert cfg.crop.baud == 38400
    assert cfg.crop.sensors == 4
    assert cfg.can.command_period_s == 0.5
    assert cfg.can.send_on_gnss is False
    assert cfg.can.ids["status"] == 0x185C6465
    assert cfg.can.ids["command"] == 0x0A5C6465


def test_load_from_file_with_sections(tmp_path: Path) -> None:
    path = tmp_path / "field7.toml"
    path.write_text(
        """
[machine]
width_m = 4.2
kg_per_rev_upper = 0.25
[speed]
mode = "gnss"
switch_compare = "wheel"
[ecu]
pid_kp = 0.05
cmd_timeout_ms = 2000
[crop.columns]
sensor_id = 0
red = 2
nir = 1
[rate]
model = "table"
split_upper = 0.3
[rate.table]
points = [[0.2, 500], [0.9, 100]]
[can]
interface = "udp_multicast"
channel = "239.74.163.2"
send_on_gnss = true
[can.ids]
command = 0x0A5C6466
""",
        encoding="utf-8",
    )
    cfg = load_config(path)
    assert cfg.machine.width_m == 4.2
    assert cfg.speed.mode == "gnss"
    assert cfg.crop.columns == {"sensor_id": 0, "red": 2, "nir": 1}
    assert cfg.rate.model == "table"
    assert cfg.rate.table.points == ((0.2, 500.0), (0.9, 100.0))
    assert cfg.can.ids["command"] == 0x0A5C6466
    assert cfg.can.ids["status"] == 0x185C6465  # untouched ids keep their defaults
    params = cfg.ecu_params()
    assert params[1] == 4.2
    assert params[2] == 0.25
    assert params[10] == 2  # GnssOnly
    assert params[11] == 1  # compare wheel
    assert params[12] == 0.05
    assert params[16] == 2000
    assert 13 not in params  # pid_ki not set by the user: not pushed


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("[machine]\nwidth = 3.6", "machine.width"),
        ("[machin]\nwidth_m = 3.6", "machin"),
        ("machine = 3", "machine"),
        ("[machine]\nwidth_m = 0.1", "machine.width_m"),
        ("[machine]\nwidth_m = 'wide'", "machine.width_m"),
        ("[machine]\nwheel_ppr = 500.5", "machine.wheel_ppr"),
        ("[machine]\nwheel_ppr = true", "machine.wheel_ppr"),
        ("[machine]\nwidth_m = nan", "machine.width_m"),
        ("[speed]\nmode = 'dual'", "speed.mode"),
        ("[speed]\nqueue_len = 3\ncv_window = 4", "speed.cv_window"),
        ("[speed]\nswitch_compare = 'both'", "speed.switch_compare"),
        ("[ecu]\npid_kq = 1.0", "ecu.pid_kq"),
        ("[ecu]\npid_kp = 11.0", "ecu.pid_kp"),
        ("[ecu]\ncmd_timeout_ms = 1500.0", "ecu.cmd_timeout_ms"),
        ("[gnss]\nbaud = 0", "gnss.baud"),
        ("[gnss]\nsource = 'file'", "gnss.path"),
        ("[gnss]\nsource = 'tcp'", "gnss.source"),
        ("[gnss]\nsource = 'stdin'\n[crop]\nsource = 'stdin'", "crop.source"),
        ("[crop]\nndvi_min = 0.9\nndvi_max = 0.2", "crop.ndvi_min"),
        ("[crop]\nstale_s = -1", "crop.stale_s"),
        ("[crop.columns]\nsensor_id = 0\nred = 1", "crop.columns"),
        ("[crop.columns]\nred = 1\nnir = 2", "crop.columns.sensor_id"),
        ("[crop.columns]\nsensor_id = 0\nndvi = 0", "crop.columns"),
        ("[crop.columns]\nsensor_id = 0\nevi = 3", "crop.columns.evi"),
        ("[rate]\nmodel = 'quadratic'", "rate.model"),
        ("[rate]\nsplit_upper = 1.5", "rate.split_upper"),
        ("[rate.linear]\nndvi_0 = 0.5\nndvi_1 = 0.5", "rate.linear.ndvi_1"),
        ("[rate.linear]\nmin_kg_ha = 500\nmax_kg_ha = 100", "rate.linear.min_kg_ha"),
        ("[rate.linear]\nslope = 2", "rate.linear.slope"),
        ("[rate.table]\npoints = [[0.5, 100]]", "rate.table.points"),
        ("[rate.table]\npoints = [[0.5, 100], [0.4, 50]]", "rate.table.points[1]"),
        ("[rate.table]\npoints = [[0.5, 100], [0.6]]", "rate.table.points[1]"),
        ("[rate.table]\npoints = [[0.5, 100], [0.6, -5]]", "rate.table.points[1]"),
        ("[rate.sufficiency]\nreference = 'strip'", "rate.sufficiency.reference"),
        ("[rate.sufficiency]\nn_fraction = 0", "rate.sufficiency.n_fraction"),
        ("[can]\ncommand_period_s = 0", "can.command_period_s"),
        ("[can]\nsend_on_gnss = 1", "can.send_on_gnss"),
        ("[can]\ninterface = ''", "can.interface"),
        ("[can.ids]\ncommand = 0x20000000", "can.ids.command"),
        ("[can.ids]\ncommand = 0x185C6465", "can.ids"),
        ("[can.ids]\nheartbeat = 1", "can.ids.heartbeat"),
        ("[display]\nrefresh_s = 0", "display.refresh_s"),
        ("[display]\nrefresh_s = 5.0", "display.refresh_s"),  # was taken, then cut to 0.5
        ("[log]\ndir = 5", "log.dir"),
        ("[crop]\nport = '/dev/ttyUSB0'", "crop.port"),  # gnss.port's default
        ("[can]\ninterface = 'slcan'\nchannel = '/dev/ttyUSB1'", "can.channel"),
        # periods against the ECU's timeouts (its defaults: 1500, 1200 and 100 ms)
        ("[can]\ncommand_period_s = 1.5\nsend_on_gnss = true", "can.command_period_s"),
        ("[ecu]\ncmd_timeout_ms = 400", "can.command_period_s"),
        ("[can]\ncommand_period_s = 1.2", "can.command_period_s"),
        ("[ecu]\ngnss_timeout_ms = 500", "can.command_period_s"),
        ("[ecu]\nstatus_period_ms = 300", "can.ecu_timeout_s"),
        ("[can]\necu_timeout_s = 0.15", "can.ecu_timeout_s"),
    ],
)
def test_bad_value_names_its_key(text: str, key: str) -> None:
    with pytest.raises(ConfigError) as info:
        loads_config(text)
    assert info.value.key == key
    assert str(info.value).startswith(f"{key}: ")


def test_toml_syntax_error_names_the_file(tmp_path: Path) -> None:
    path = tmp_path / "broken.toml"
    path.write_text("[machine\nwidth_m = 3.6\n", encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert info.value.key == str(path)
    assert "not valid TOML" in str(info.value)


def test_missing_file_names_the_file(tmp_path: Path) -> None:
    path = tmp_path / "absent.toml"
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert info.value.key == str(path)


def test_integers_accepted_for_float_keys() -> None:
    cfg = loads_config("[machine]\nwidth_m = 4\n")
    assert cfg.machine.width_m == 4.0
    assert isinstance(cfg.machine.width_m, float)


def test_periods_that_agree_with_the_ecu_timeouts_are_accepted() -> None:
    # GNSS sent on each fix: a command period up to the command timeout is fine
    cfg = loads_config("[can]\ncommand_period_s = 1.4\nsend_on_gnss = true")
    assert cfg.can.command_period_s == 1.4
    cfg = loads_config("[ecu]\nstatus_period_ms = 250\ngnss_timeout_ms = 600")
    assert cfg.ecu.overrides == {"status_period_ms": 250, "gnss_timeout_ms": 600}


def test_one_port_per_device_but_files_may_be_shared() -> None:
    text = "[gnss]\nsource = 'file'\npath = 'a.log'\n[crop]\nport = '/dev/ttyUSB0'\n"
    assert loads_config(text).crop.port == "/dev/ttyUSB0"  # gnss reads a file, not the port
    cfg = loads_config("[can]\ninterface = 'slcan'\nchannel = '/dev/ttyACM0'\n")
    assert cfg.can.channel == "/dev/ttyACM0"


def test_a_file_with_a_byte_order_mark_loads(tmp_path: Path) -> None:
    path = tmp_path / "notepad.toml"
    path.write_bytes("\ufeff[machine]\nwidth_m = 4.2\n".encode())
    assert load_config(path).machine.width_m == 4.2


# ---- hostile files: errors name the key, never a traceback ----------------------------------

_HUGE = "1" + "0" * 400  # an integer no float holds: float() and isfinite() raise OverflowError


@pytest.mark.parametrize(
    ("text", "key"),
    [
        (f"[machine]\nwidth_m = {_HUGE}\n", "machine.width_m"),
        (f"[machine]\nwheel_ppr = {_HUGE}\n", "machine.wheel_ppr"),
        (f"[ecu]\npid_kp = {_HUGE}\n", "ecu.pid_kp"),
        (f"[crop.columns]\nsensor_id = {_HUGE}\nndvi = 1\n", "crop.columns.sensor_id"),
        (f"[can.ids]\ncommand = {_HUGE}\n", "can.ids.command"),
        (
            f'[rate]\nmodel = "table"\n[rate.table]\npoints = [[0.1, {_HUGE}], [0.5, 3.0]]\n',
            "rate.table.points[0]",
        ),
        (f"[machine]\nwidth_m = -{_HUGE}\n", "machine.width_m"),
    ],
)
def test_overflowing_integers_name_the_key(text: str, key: str) -> None:
    with pytest.raises(ConfigError) as err:
        loads_config(text)
    assert err.value.key == key
    assert "400 digits" in str(err.value) or "401 digits" in str(err.value)


def test_integer_over_the_digit_limit_names_the_key() -> None:
    # tomllib raises ValueError (Python's 4,300-digit limit on int parsing), with no key
    text = "[gnss]\nbaud = 9600\n\n[machine]\nrows = 6\nwidth_m = 1" + "0" * 5000 + "\n"
    with pytest.raises(ConfigError) as err:
        loads_config(text)
    assert err.value.key == "machine.width_m"
    assert "too long" in str(err.value)


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("[speed]\nqueue_len = " + "[" * 100_000 + "]" * 100_000 + "\n", "speed.queue_len"),
        ("x = " + "{a = " * 50_000 + "}" * 50_000 + "\n", "x"),
    ],
)
def test_nesting_100000_deep_names_the_key(text: str, key: str) -> None:
    with pytest.raises(ConfigError) as err:
        loads_config(text)
    assert err.value.key == key
    assert "nested too deep" in str(err.value)


def test_device_files_fifo_and_directories_are_refused(tmp_path: Path) -> None:
    fifo = tmp_path / "config.fifo"
    os.mkfifo(fifo)  # opening it to read would block until a writer came
    for path in (Path("/dev/zero"), Path("/dev/urandom"), fifo, tmp_path):
        with pytest.raises(ConfigError) as err:
            load_config(path)
        assert err.value.key == str(path)
        assert "not a regular file" in str(err.value)


def test_a_file_over_1_mib_is_refused_and_one_at_the_limit_is_read(tmp_path: Path) -> None:
    big = tmp_path / "big.toml"
    comment = "# " + "x" * 98 + "\n"  # 101 bytes a line
    body = "[machine]\nwidth_m = 3.0\n"
    pad = MAX_CONFIG_BYTES - len(body)
    big.write_text(body + comment * (pad // len(comment)) + "#" * (pad % len(comment) - 1) + "\n")
    assert big.stat().st_size == MAX_CONFIG_BYTES
    assert load_config(big).machine.width_m == 3.0
    with big.open("a") as f:
        f.write("#")
    with pytest.raises(ConfigError) as err:
        load_config(big)
    assert "over 1048576 bytes" in str(err.value)


def test_cli_refuses_dev_zero_with_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", "--config", "/dev/zero", "--duration", "1"]) == 2
    err = capsys.readouterr().err
    assert "/dev/zero" in err and "not a regular file" in err and "Traceback" not in err


def test_mutated_configuration_files_give_config_error_only() -> None:
    # Deterministic mutations of the documented file: each is loaded or refused with a
    # ConfigError naming a key; nothing else may escape (2,000 files, about a second).
    rng = random.Random(8)
    base = DEFAULT_TOML
    alphabet = '[]{}=."\n#,-+_0123456789eEinfa \t'
    outcomes: Counter[str] = Counter()
    for _ in range(2000):
        text = list(base)
        for _ in range(rng.randint(1, 6)):
            i = rng.randrange(len(text))
            op = rng.random()
            if op < 0.4:
                text[i] = rng.choice(alphabet)
            elif op < 0.7:
                del text[i]
            else:
                text.insert(i, rng.choice(["0" * rng.randint(1, 500), "[" * 60, "1e999"]))
        try:
            loads_config("".join(text))
            outcomes["ok"] += 1
        except ConfigError as exc:
            assert exc.key, exc
            outcomes["refused"] += 1
    assert outcomes["refused"] > 500 and outcomes["ok"] > 50
