"""The field experiment's metrics, the look-ahead on a known NDVI step, the sensor geometry,
the wheel's edge time and the fused fields of table2."""

from __future__ import annotations

import math

import numpy as np
import pytest

from topdress.config import CropConfig
from topdress.crop.sensors import CompensatedNdvi
from topdress.errors import ConfigError
from topdress.protocol import SpeedMode
from topdress.sim import experiments as ex
from topdress.sim import fieldexp as fx
from topdress.sim.tractor import Drive
from topdress.sim.world import SimConfig, World

WIDTH = 3.6


def _rate(ndvi: float) -> float:
    return 100.0 if math.isfinite(ndvi) else math.nan


def _run(applied_per_m: dict[float, float], length_m: float = 30.0) -> fx.FieldRun:
    """A pass 0..length_m at 100 kg/ha prescribed; applied given as multiples per metre."""
    bm = 0.05
    per_bin = 100.0 * 1e-4 * WIDTH * bm
    n = round(length_m / bm)
    applied = {i: per_bin * applied_per_m.get(math.floor(i * bm), 1.0) for i in range(n)}
    ndvi = {i: 0.5 for i in range(n)}
    return fx.FieldRun(bm, applied, ndvi, [(0.0, length_m)], np.array([0.1, -0.1]))


def test_field_metrics_on_a_known_case() -> None:
    # first metre empty, metre 5 at 150 %, last two metres at 200 %, everything else exact
    m = fx.field_metrics([_run({0: 0.0, 5: 1.5, 28: 2.0, 29: 2.0})], _rate, WIDTH)
    assert m.metres == 30
    assert m.start_m == pytest.approx(1.0 - 0.5)  # 1 m missing, 0.5 m extra in the window
    assert m.stop_m == pytest.approx(2.0)
    errs = np.array([-100.0, 50.0, 100.0, 100.0] + [0.0] * 26)
    assert m.rate_rms_pct == pytest.approx(float(np.sqrt(np.mean(errs**2))))
    assert m.total_kg_err_pct == pytest.approx(100.0 * (30.0 - 1 + 0.5 + 2) / 30.0 - 100.0)
    assert m.speed_rms_kmh == pytest.approx(0.1)
    assert m.rate_rms_mid_pct == pytest.approx(
        0.0, abs=1e-9
    )  # every error lies in the start and stop windows


def test_stop_counts_what_lands_after_the_stop_point() -> None:
    run = _run({})
    extra = 100.0 * 1e-4 * WIDTH * 0.05 * 4  # 0.2 m worth of rate landing at the stop point
    run.applied[round(30.0 / 0.05)] = extra
    assert fx.field_metrics([run], _rate, WIDTH).stop_m == pytest.approx(0.2)


def test_stop_excess_of_a_constant_rate_run() -> None:
    bins = {i: 0.01 for i in range(400)}  # 20 m at 0.01 kg / 5 cm
    bins[399] += 0.02  # + 0.1 m of rate after the stop at 20 m
    assert ex.stop_excess_m(bins, 0.05, 20.0, 0.2) == pytest.approx(0.1)


def _sensors_line(sid: int, ndvi: float) -> str:
    nir = 0.42
    red = nir * (1 - ndvi) / (1 + ndvi)
    return f"{sid},{red:.5f},0.2,{nir:.5f},0.3,{ndvi:.5f}\r\n"


def _step_run(lookahead_s: float) -> list[tuple[float, float | None]]:
    """Drive at 3.6 km/h (1 m/s) over an NDVI step at 10 m, sensors 2 m ahead."""
    c = CompensatedNdvi(CropConfig(sensor_to_meter_m=2.0), lookahead_s)
    out = []
    for k in range(200):
        t = k * 0.1
        ndvi = 0.3 if t + 2.0 < 10.0 else 0.8  # what the sensors see (2 m ahead)
        for sid in range(1, 5):
            c.sensors.feed(t, _sensors_line(sid, ndvi))
        out.append((t, c.update(t, 3.6)))
    return out


def test_lookahead_moves_a_known_ndvi_step_earlier_by_speed_times_tau() -> None:
    def step_time(series: list[tuple[float, float | None]]) -> float:
        return next(t for t, v in series if v is not None and v > 0.5)

    plain = step_time(_step_run(0.0))
    ahead = step_time(_step_run(0.8))
    assert plain == pytest.approx(10.0, abs=0.11)  # the outlets reach the step at 10 m
    assert plain - ahead == pytest.approx(0.8, abs=0.11)  # 1 m/s x 0.8 s earlier


def test_lookahead_never_reaches_beyond_the_sensors() -> None:
    c = CompensatedNdvi(CropConfig(sensor_to_meter_m=0.5), 5.0)
    for sid in range(1, 5):
        c.sensors.feed(0.0, _sensors_line(sid, 0.6))
    assert c.update(0.0, 10.0) == pytest.approx(0.6, abs=1e-3)
    assert c.update(1.0, 10.0) == pytest.approx(0.6, abs=1e-3)


def test_crop_sensors_look_sensor_to_meter_m_ahead_of_the_outlets() -> None:
    w = World(SimConfig(crop_ahead_m=2.0), seed=3, drive=Drive.paper_run(6.5))
    s = w.sensors[0]
    # heading north (0): the sensor sees the spot 2 m north of the outlets, offset to the side
    line = s.step(s.next_t, w.field, 10.0, 20.0, 0.0)
    assert line is not None
    seen = float(line.split(",")[5])
    assert seen == pytest.approx(w.field.ndvi(10.0 + s.offset_m, 22.0), abs=0.03)
    assert s.ahead_m == 2.0


def test_wheel_edge_time_lies_inside_the_step_of_the_last_pulse() -> None:
    w = World(SimConfig(), seed=1, drive=Drive.paper_run(6.5, hold_m=5.0, wait_s=0.5))
    prev_count, seen = 0, 0
    for _ in range(400):
        w.step()
        count = int(w.wheel.revolutions * w.wheel.p.ppr)
        if count > prev_count:
            assert w.now_us - 10_000 <= w._edge_us <= w.now_us
            seen += 1
        prev_count = count
    assert seen > 100


def test_loose_patch_slips_the_wheel_15_pct() -> None:
    cfg = SimConfig(loose_patches=((0.0, 50.0, 100.0),), wheel_edges=False)
    w = World(cfg, seed=2, drive=Drive.paper_run(3.5, hold_m=20.0, wait_s=0.5))
    w.run(20.0)
    turned = w.wheel.revolutions * 2 * math.pi * w.wheel.p.radius_m
    assert turned / w.tractor.odometer == pytest.approx(0.85, abs=0.02)


def test_table2_rows_gain_the_fused_start_and_stop() -> None:
    rows = ex.table2(ex.Lab(), (8.0,), reps=1, fused=ex.FUSED)
    r = rows[0]
    assert r.fused_delay_m < r.dual_delay_m < r.gnss_delay_m
    assert abs(r.fused_stop_m) < r.dual_stop_m < r.gnss_stop_m
    run = ex.Lab().paper_run(8.0, 0, SpeedMode.FUSED, settings=ex.FUSED)
    assert run.trace["source"].max() == 3.0  # index 3 = fused decodes in the trace


def test_short_field_fused_beats_the_paper() -> None:
    plan = fx.FieldPlan(passes=2, length_m=50.0)
    res = fx.field_experiment(fx.FieldSetup(plan=plan), [0], ("paper", "fused"))
    paper, fused = res["paper"], res["fused"]
    assert fused.rate_rms_pct < paper.rate_rms_pct
    assert fused.start_m < paper.start_m
    assert abs(fused.total_kg_err_pct) < abs(paper.total_kg_err_pct)
    assert fused.speed_rms_kmh < paper.speed_rms_kmh


def test_fused_mode_in_the_configuration_and_the_replay() -> None:
    from topdress.config import default_config, loads_config
    from topdress.log.replay import ecu_params

    cfg = loads_config(
        '[speed]\nmode = "fused"\n[lookahead]\nmeter_ms = 200\nairline_ms = 400\nstop_ms = 900\n'
        "[ecu]\ngnss_lag_ms = 1300\n"
    )
    pushed = cfg.ecu_params()
    assert pushed[10] == 3 and pushed[30] == 200 and pushed[31] == 400 and pushed[29] == 1300
    assert pushed[38] == 900  # LeadStop
    assert cfg.lookahead.total_s == pytest.approx(0.6)  # the stop lead is not the rate's tau
    off = default_config().ecu_params()
    assert 30 not in off and 38 not in off  # look-ahead off: the paper's behaviour
    with pytest.raises(ConfigError):
        loads_config("[lookahead]\nstop_ms = 5001\n")
    assert int(ecu_params(default_config(), "fused").speed_mode) == 3
