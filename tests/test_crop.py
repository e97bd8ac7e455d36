"""Crop sensor lines, averaging, staleness, and the sensor-to-meter distance compensation."""

from __future__ import annotations

import dataclasses
import math
import os
import random
import threading
import time

import pytest

from topdress.config import CropConfig, default_config, loads_config
from topdress.crop.sensors import (
    CompensatedNdvi,
    CropSensors,
    DistanceQueue,
    Odometer,
    parse_crop_line,
)
from topdress.devices.lines import SerialLineSource
from topdress.errors import ConfigError, SensorError

CFG = default_config().crop
COLUMNS = CFG.columns


def test_parse_the_documented_example() -> None:
    r = parse_crop_line(3.5, b"2,0.0412,0.2104,0.4419,0.3541,0.8295\r\n", COLUMNS, 4)
    assert (r.t, r.sensor_id, r.ndvi) == (3.5, 2, 0.8295)
    assert (r.red, r.red_edge, r.nir, r.ndre) == (0.0412, 0.2104, 0.4419, 0.3541)


def test_ndvi_computed_from_red_and_nir_when_the_field_is_empty() -> None:
    r = parse_crop_line(0.0, "2,0.0412,0.2104,0.4419,0.3541,", COLUMNS, 4)
    assert r.ndvi == pytest.approx((0.4419 - 0.0412) / (0.4419 + 0.0412))
    assert r.ndvi == pytest.approx(0.82943, abs=1e-5)


def test_custom_column_map_without_ndvi() -> None:
    cfg = loads_config("[crop.columns]\nsensor_id = 3\nred = 0\nnir = 1\n").crop
    r = parse_crop_line(0.0, "0.0500,0.4500,ignored,4", cfg.columns, cfg.sensors)
    assert r.sensor_id == 4
    assert r.ndvi == pytest.approx(0.8)
    assert r.red_edge is None


@pytest.mark.parametrize(
    ("line", "reason"),
    [
        (b"", "empty"),
        (b"\r\n", "empty"),
        (b"\x02\xff\xfe,0.1", "binary"),
        (b"2,0.0412,0.2104", "fields"),
        (b"2,0.0412,0.2104,0.4419,0.3541", "fields"),
        (b"ID,Red,RedEdge,NIR,NDRE,NDVI", "number"),
        (b"2,0.04x2,0.2104,0.4419,0.3541,0.8295", "number"),
        (b"2,nan,0.2104,0.4419,0.3541,0.8295", "number"),
        (b"0,0.0412,0.2104,0.4419,0.3541,0.8295", "sensor_id"),
        (b"5,0.0412,0.2104,0.4419,0.3541,0.8295", "sensor_id"),
        (b"1.5,0.0412,0.2104,0.4419,0.3541,0.8295", "sensor_id"),
        (b",0.0412,0.2104,0.4419,0.3541,0.8295", "sensor_id"),
        # forms int()/float() accept but no logger writes: refused, not read as 10, 1, 1.0
        (b"1_0,0.0412,0.2104,0.4419,0.3541,0.8295", "number"),
        (b"+1,0.0412,0.2104,0.4419,0.3541,0.8295", "number"),
        (b"1e0,0.0412,0.2104,0.4419,0.3541,0.8295", "number"),
        (b"2,4_1e-2,0.2104,0.4419,0.3541,0.8295", "number"),
        (b"2,0.0412,0.2104,0.4419,0.3541,+0.8295", "number"),
        (b"2,0.0412,0.2104,0.4419,0.3541,inf", "number"),
        (b"2,0.0412,0.2104,0.4419,0.3541,1" + b"0" * 400, "number"),
        (b"2,1.0412,0.2104,0.4419,0.3541,0.8295", "reflectance_range"),
        (b"2,0.0412,0.2104,-0.0001,0.3541,", "reflectance_range"),
        (b"2,0.0412,0.2104,0.4419,1.3541,0.8295", "index_range"),
        (b"2,0.0412,0.2104,0.4419,0.3541,-1.2", "index_range"),
        (b"2,,0.2104,0.4419,0.3541,", "ndvi_undefined"),
        (b"2,0.0000,0.2104,0.0000,0.3541,", "ndvi_undefined"),
    ],
)
def test_bad_lines_raise_a_sensor_error_with_the_reason(line: bytes, reason: str) -> None:
    with pytest.raises(SensorError) as info:
        parse_crop_line(0.0, line, COLUMNS, 4)
    assert str(info.value).startswith(reason + ":")


def _line(sensor: int, ndvi: float) -> bytes:
    return f"{sensor},0.0412,0.2104,0.4419,0.3541,{ndvi:.4f}\r\n".encode()


def test_mean_of_the_latest_fresh_reading_per_sensor() -> None:
    s = CropSensors(CFG)
    assert s.mean_ndvi(0.0) is None
    for sid, ndvi in ((1, 0.60), (2, 0.70), (3, 0.80), (4, 0.50), (1, 0.64)):
        assert s.feed(0.1, _line(sid, ndvi)) is not None
    assert s.mean_ndvi(0.2) == pytest.approx((0.64 + 0.70 + 0.80 + 0.50) / 4)
    assert s.counters == {"ok": 5}


def test_stale_sensor_is_left_out_and_counted_once() -> None:
    s = CropSensors(CFG)  # stale_s = 1.0
    s.feed(0.0, _line(1, 0.60))
    s.feed(0.5, _line(2, 0.70))
    assert s.mean_ndvi(1.0) == pytest.approx(0.65)
    assert s.mean_ndvi(1.2) == pytest.approx(0.70)  # sensor 1 silent for 1.2 s
    assert s.mean_ndvi(1.3) == pytest.approx(0.70)
    assert s.counters["stale"] == 1
    assert s.mean_ndvi(1.6) is None
    assert s.counters["stale"] == 2
    s.feed(1.7, _line(1, 0.62))  # back: fresh again
    assert s.mean_ndvi(1.8) == pytest.approx(0.62)
    assert [r.sensor_id for r in s.fresh(1.8)] == [1]


def test_out_of_range_ndvi_rejected_and_counted() -> None:
    cfg = dataclasses.replace(CFG, ndvi_min=0.2, ndvi_max=0.95)
    s = CropSensors(cfg)
    assert s.feed(0.0, _line(1, 0.15)) is None
    assert s.feed(0.0, _line(2, 0.97)) is None
    assert s.feed(0.0, b"9,0.0412,0.2104,0.4419,0.3541,0.8295") is None
    assert s.feed(0.0, _line(3, 0.55)) is not None
    assert s.counters == {"ndvi_range": 2, "sensor_id": 1, "ok": 1}
    assert s.last_error is not None and s.last_error.startswith("sensor_id:")
    assert s.mean_ndvi(0.1) == pytest.approx(0.55)  # rejected readings never enter the mean


def test_distance_queue_returns_the_ndvi_seen_offset_earlier() -> None:
    q = DistanceQueue(offset_m=2.0)
    for i in range(50):  # one reading every 0.1 m, NDVI rising with distance
        q.push(i * 0.1, 0.30 + i * 0.01)
    assert q.at(1.99) is None  # meters have not reached the first sensed spot
    assert q.at(2.0) == pytest.approx(0.30)
    assert q.at(3.05) == pytest.approx(0.40)  # spot 1.05 m: last sample at 1.0 m
    assert q.at(4.9) == pytest.approx(0.59)
    assert len(q) <= 21  # only what the meters still need is kept


def test_distance_queue_standing_still_and_backwards() -> None:
    q = DistanceQueue(offset_m=1.0)
    q.push(0.0, 0.5)
    q.push(5.0, 0.6)
    q.push(5.0, 0.7)  # standing: the latest view of the spot replaces the older
    q.push(4.0, 0.9)  # never happens with a speed >= 0; counted, ignored
    assert len(q) == 2
    assert q.counters["backwards"] == 1
    assert q.at(6.0) == pytest.approx(0.7)


def test_distance_queue_carries_missing_ndvi_and_is_bounded() -> None:
    q = DistanceQueue(offset_m=0.5, max_len=3)
    for i in range(5):
        q.push(float(i), None if i == 3 else 0.5)
    assert q.counters["overflow"] == 2
    assert q.at(3.6) is None  # the sensors saw nothing at 3 m
    with pytest.raises(ConfigError):
        DistanceQueue(-1.0)


def test_odometer_integrates_the_selected_speed() -> None:
    odo = Odometer()
    assert odo.advance(0.0, 7.2) == 0.0
    assert odo.advance(1.0, 7.2) == pytest.approx(2.0)  # 7.2 km/h = 2 m/s
    assert odo.advance(1.5, 0.0) == pytest.approx(3.0)
    assert odo.advance(9.0, 3.6) == pytest.approx(3.0)  # stood still
    assert odo.advance(8.0, 3.6) == pytest.approx(3.0)  # time going back adds nothing
    assert odo.advance(10.0, -1.0) == pytest.approx(4.0)
    assert odo.advance(11.0, 0.0) == pytest.approx(4.0)  # negative speed counts as zero


def test_compensation_applies_a_step_when_the_meters_reach_it() -> None:
    cfg = CropConfig(sensor_to_meter_m=2.0)
    comp = CompensatedNdvi(cfg)
    applied: list[tuple[float, float | None]] = []
    # 7.2 km/h = 2 m/s; 10 Hz ticks; the canopy changes from NDVI 0.5 to 0.8 at t = 3 s
    # (6 m). The meters are 2 m behind: they must apply 0.8 from t = 4 s on.
    for k in range(80):
        t = k * 0.1
        ndvi = 0.5 if t < 3.0 - 1e-9 else 0.8
        for sid in range(1, 5):
            comp.sensors.feed(t, _line(sid, ndvi))
        applied.append((t, comp.update(t, 7.2)))
    first = {round(t, 1): v for t, v in applied}
    assert first[0.9] is None  # meters not yet where the first reading was taken
    assert first[1.0] == pytest.approx(0.5)
    assert first[3.9] == pytest.approx(0.5)
    assert first[4.0] == pytest.approx(0.8)
    assert first[7.9] == pytest.approx(0.8)


def test_crop_lines_over_a_pseudo_terminal() -> None:
    master, slave = os.openpty()
    sensors = CropSensors(CFG)
    done = threading.Event()

    times: list[float] = []

    def sink(t: float, line: bytes) -> None:
        times.append(t)
        sensors.feed(t, line)
        if sum(sensors.counters.values()) == 5:
            done.set()

    src = SerialLineSource(os.ttyname(slave), CFG.baud)
    src.start(sink)
    try:
        deadline = time.monotonic() + 5.0
        while not src.connected:  # bytes written before the port is open are flushed by it
            assert time.monotonic() < deadline
            time.sleep(0.01)
        lines = b"".join(_line(sid, 0.5 + 0.1 * sid) for sid in range(1, 5))
        os.write(master, lines + b"7,0.0412,0.2104,0.4419,0.3541,0.8295\r\n")
        assert done.wait(5.0)
    finally:
        src.stop()
        os.close(master)
        os.close(slave)
    assert sensors.counters == {"ok": 4, "sensor_id": 1}
    assert sensors.mean_ndvi(times[-1]) == pytest.approx((0.6 + 0.7 + 0.8 + 0.9) / 4)


def test_mutated_crop_lines_give_a_reading_or_a_sensor_error() -> None:
    rng = random.Random(12)
    cols = default_config().crop.columns
    base = "2,0.0412,0.2104,0.4419,0.3541,0.8295"
    readings = errors = 0
    for _ in range(20_000):
        line = list(base)
        for _ in range(rng.randint(1, 3)):
            i = rng.randrange(len(line))
            line[i] = rng.choice("0123456789.,-+_eEinfa ")
        try:
            r = parse_crop_line(0.0, "".join(line), cols, 4)
        except SensorError:
            errors += 1
            continue
        readings += 1
        assert 1 <= r.sensor_id <= 4 and math.isfinite(r.ndvi) and -1.0 <= r.ndvi <= 1.0
    assert readings > 1000 and errors > 1000
