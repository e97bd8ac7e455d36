"""Plant models against physics: wheel pulses, motor steady state, transport delay, NMEA."""

from __future__ import annotations

import math

import pynmeagps
import pytest

from topdress.gnss import sentences as nmea
from topdress.sim.actuators import Fan, FanParams, MeterMotor, MeterParams
from topdress.sim.field import CropSensor, CropSensorParams, Field, FieldParams
from topdress.sim.gnss import GnssParams, GnssReceiver
from topdress.sim.tractor import Drive, Tractor, TractorParams
from topdress.sim.transport import AirLine, AirLineParams
from topdress.sim.wheel import GroundWheel, WheelParams

DT = 0.01


@pytest.mark.parametrize("v_kmh", [3.5, 5.0, 6.5, 8.0])
def test_wheel_counts_follow_distance_and_eq5_slip(v_kmh: float) -> None:
    p = WheelParams(slip_sd_pct=0.0, bounce_sd=0.0)
    w = GroundWheel(p, seed=1)
    v = v_kmh / 3.6
    steps = int(40.0 / v / DT)
    for i in range(steps):
        w.step(i * DT, DT, v)
    dist = steps * DT * v
    slip = (0.167 * v_kmh**2 - 0.296 * v_kmh + 0.773) / 100.0
    expected = dist / (2 * math.pi * 0.0615) * 500 * (1 - slip)
    assert abs(w.count - expected) <= 1.0
    # eq. 3 on the simulated counts gives eq. 5 back
    measured = abs(2 * math.pi * 0.0615 * w.count / 500 - dist) / dist * 100
    assert measured == pytest.approx(slip * 100, abs=0.01)


def test_wheel_faults_stop_the_pulses() -> None:
    w = GroundWheel(WheelParams(encoder_dead_at_s=1.0), seed=2)
    for i in range(100):
        w.step(i * DT, DT, 1.5)
    at_fault = w.count
    assert at_fault == int(w.revolutions * 500)
    for i in range(100, 300):
        w.step(i * DT, DT, 1.5)
    assert w.revolutions > 3.0 * at_fault / 500
    assert w.count == at_fault
    assert GroundWheel(WheelParams(), 3).step(0.0, DT, 0.0) == 0


@pytest.mark.parametrize("duty", [0.2, 0.35, 0.6, 1.0, 1.7])
def test_meter_motor_steady_state_vs_duty(duty: float) -> None:
    p = MeterParams(load_ripple=0.0)
    m = MeterMotor(p, DT)
    for i in range(300):
        m.step(i * DT, DT, duty)
    expected = p.max_rpm * (min(duty, 1.0) - p.friction_duty - p.load_duty)
    assert m.rpm == pytest.approx(expected, rel=1e-3)
    assert m.steady_rpm(duty) == pytest.approx(expected)
    # encoder counts = revolutions * 6400
    assert m.count == int(m.revolutions * 6400)


def test_meter_static_friction_and_jam() -> None:
    p = MeterParams()
    m = MeterMotor(p, DT)
    for i in range(100):
        m.step(i * DT, DT, p.breakaway_duty + p.load_duty - 0.01)
    assert m.count == 0 and m.rpm == 0.0
    m = MeterMotor(MeterParams(jammed_at_s=0.5), DT)
    for i in range(100):
        m.step(i * DT, DT, 0.5)
    assert m.rpm == 0.0 and m.count > 0
    count = m.count
    m.step(1.01, DT, 1.0)
    assert m.count == count


def test_meter_time_constant() -> None:
    p = MeterParams(load_ripple=0.0)
    m = MeterMotor(p, DT)
    for i in range(round(p.tau_s / DT)):
        m.step(i * DT, DT, 0.5)
    assert m.rpm == pytest.approx(m.steady_rpm(0.5) * (1 - math.exp(-1)), rel=0.01)


def test_meter_load_ripple_averages_out() -> None:
    p = MeterParams(load_duty=0.05, load_ripple=0.8)
    m = MeterMotor(p, DT)
    for i in range(300):
        m.step(i * DT, DT, 0.5)
    rev0, rpms = m.revolutions, []
    for i in range(300, 900):
        m.step(i * DT, DT, 0.5)
        rpms.append(m.rpm)
    mean_rpm = (m.revolutions - rev0) / 6.0 * 60.0
    assert mean_rpm == pytest.approx(m.steady_rpm(0.5), rel=0.02)
    assert max(rpms) - min(rpms) > 0.3  # the flutes make the speed pulse


def test_fan_first_order_and_tach() -> None:
    f = Fan(FanParams(), DT)
    for i in range(800):
        f.step(i * DT, DT, 0.75)
    assert f.rpm == pytest.approx(3000.0, rel=1e-3)
    assert f.count == int(f.revolutions * 30)
    f2 = Fan(FanParams(belt_slip=0.2), DT)
    for i in range(800):
        f2.step(i * DT, DT, 0.75)
    assert f2.rpm == pytest.approx(2400.0, rel=1e-3)


def test_airline_transport_delay_and_mass() -> None:
    p = AirLineParams(release_rev=0.05)
    line = AirLine(p)
    delay = p.drop_s + p.line_length_m / p.air_speed_ms
    assert line.delay_s(3000.0) == pytest.approx(delay)
    assert line.delay_s(600.0) == math.inf
    first = None
    for i in range(1, 200):
        t = i * DT
        d_rev = 0.01 if t <= 0.5 else 0.0
        if line.step(t, d_rev, 0.3, 3000.0) > 0 and first is None:
            first = t
    # the first flute releases after 0.05 rev (5-6 steps), then travels `delay`
    assert first is not None
    assert 0.05 + delay - 1e-9 <= first <= 0.06 + delay + DT + 1e-9
    assert line.landed_kg == pytest.approx((0.5 - 0.05) * 0.3, rel=1e-6)
    assert line.in_flight_kg == pytest.approx(0.0, abs=1e-12)


def test_nmea_sentences_parse_back_with_checksums() -> None:
    p = GnssParams(talker="BD", speed_sd_ms=0.0, pos_sd_m=0.0, filter_tau_s=0.2, latency_s=0.1)
    rx = GnssReceiver(p, seed=4)
    lines: list[str] = []
    for i in range(1, 400):
        lines += rx.step(i * DT, 0.0, 1.5 * i * DT, 1.5, 0.0)
    assert len(lines) == 3 * 20 - 3  # 5 Hz fixes, the last still inside the latency
    for line in lines:
        assert line.endswith("\r\n")
        msg = pynmeagps.NMEAReader.parse(line.encode(), validate=pynmeagps.VALCKSUM)
        assert msg.talker == "BD"
    rmc = pynmeagps.NMEAReader.parse(lines[-3].encode(), validate=pynmeagps.VALCKSUM)
    assert rmc.msgID == "RMC" and rmc.status == "A"
    assert rmc.spd * 1.852 == pytest.approx(5.4, abs=0.01)
    assert nmea.parse_rmc_speed_kmh(lines[-3]) == pytest.approx(5.4, abs=0.01)
    vtg = pynmeagps.NMEAReader.parse(lines[-2].encode(), validate=pynmeagps.VALCKSUM)
    assert vtg.sogk == pytest.approx(5.4, abs=0.01)
    gga = pynmeagps.NMEAReader.parse(lines[-1].encode(), validate=pynmeagps.VALCKSUM)
    assert gga.quality == 1
    # the position moves north: 1.5 m/s for ~3.9 s
    assert (gga.lat - 43.8853) * math.pi / 180 * 6_371_000 == pytest.approx(5.7, abs=0.4)


def test_nmea_bad_checksum_and_outage() -> None:
    good = nmea.rmc("GP", 3600.0, True, 43.9, 125.3, 2.0, 90.0, "150626")
    bad = good[:20] + ("1" if good[20] != "1" else "2") + good[21:]
    assert nmea.parse_rmc_speed_kmh(good) == pytest.approx(7.2, abs=0.01)
    assert nmea.parse_rmc_speed_kmh(bad) is None
    rx = GnssReceiver(GnssParams(outages=((0.0, 10.0),)), seed=5)
    lines = [ln for i in range(1, 100) for ln in rx.step(i * DT, 0.0, 0.0, 0.0, 0.0)]
    assert lines and all(nmea.parse_rmc_speed_kmh(ln) is None for ln in lines)
    msg = pynmeagps.NMEAReader.parse(lines[0].encode(), validate=pynmeagps.VALCKSUM)
    assert msg.status == "V"
    with pytest.raises(ValueError):
        GnssReceiver(GnssParams(talker="XX"), 0)


def test_gnss_static_hold_reports_zero_until_threshold() -> None:
    p = GnssParams(speed_sd_ms=0.0, pos_sd_m=0.0, hold_ms=0.4, filter_tau_s=0.35)
    rx = GnssReceiver(p, seed=6)
    speeds: list[tuple[float, float]] = []
    v = 0.0
    for i in range(1, 600):
        t = i * DT
        v = min(1.0, 0.2 * t)  # ramp at 0.2 m/s^2
        for ln in rx.step(t, 0.0, 0.0, v, 0.0):
            s = nmea.parse_rmc_speed_kmh(ln)
            if s is not None:
                speeds.append((t, s / 3.6))
    first = next(t for t, s in speeds if s > 0)
    # true speed passes 0.4 m/s at 2.0 s; the filter and latency add to that
    assert 2.1 < first < 3.5
    assert all(s == 0.0 for t, s in speeds if t < first)
    assert next(s for t, s in speeds if t == first) >= p.hold_ms


def test_tractor_paper_run_holds_40_m() -> None:
    tr = Tractor(TractorParams(ripple_sd=0.0))
    drive = Drive.paper_run(6.5)
    hold_start = decel_start = None
    while not drive.finished and tr.t < 120:
        v_t, k = drive.command(tr, DT)
        tr.step(DT, v_t, k)
        if hold_start is None and tr.v >= 0.995 * 6.5 / 3.6:
            hold_start = tr.odometer
        if hold_start is not None and decel_start is None and tr.a < 0:
            decel_start = tr.odometer
    assert drive.finished and tr.v == 0.0
    assert hold_start is not None and decel_start is not None
    assert decel_start - hold_start == pytest.approx(40.0, abs=0.05)
    assert tr.y == pytest.approx(tr.odometer)


@pytest.mark.parametrize(
    ("target_kmh", "accel_ms2"),
    # the same 3.5 m run-up for every target: (v/3.6)^2 / 7; 12 km/h capped at 0.8 m/s^2
    [(3.5, 0.1350), (8.0, 0.7055), (12.0, 0.8)],
)
def test_tractor_launch_acceleration_grows_with_the_square_of_the_target(
    target_kmh: float, accel_ms2: float
) -> None:
    tr = Tractor(TractorParams(ripple_sd=0.0))
    accel = []
    for _ in range(300):
        tr.step(DT, target_kmh / 3.6, 0.0)
        accel.append(tr.a)
    assert max(accel) == pytest.approx(accel_ms2, rel=1e-3)
    # the clutch engages over 0.3 s: half the acceleration after 0.15 s, all of it at 0.3 s
    assert accel[14] == pytest.approx(accel_ms2 / 2, rel=1e-3)
    assert accel[29] == pytest.approx(accel_ms2, rel=1e-3)


def test_field_passes_turn_back() -> None:
    tr = Tractor(TractorParams(ripple_sd=0.0))
    drive = Drive.field_passes(2, 30.0, 8.0)
    vmax = 0.0
    while not drive.finished and tr.t < 200:
        v_t, k = drive.command(tr, DT)
        tr.step(DT, v_t, k)
        vmax = max(vmax, tr.v)
    assert drive.finished
    assert vmax == pytest.approx(8.0 / 3.6, rel=0.02)
    # back where it started, one working width to the side, heading south
    assert tr.x == pytest.approx(3.6, abs=0.2)
    assert tr.y == pytest.approx(0.0, abs=0.6)
    assert math.cos(tr.heading) == pytest.approx(-1.0, abs=1e-3)


def test_crop_sensor_lines_match_the_field() -> None:
    f = Field(FieldParams(), seed=7)
    sensors = [CropSensor(i, -1.8 + 1.2 * (i - 1), CropSensorParams(), 7) for i in range(1, 5)]
    got: dict[int, list[float]] = {1: [], 2: [], 3: [], 4: []}
    for i in range(1, 501):
        for s in sensors:
            line = s.step(i * DT, f, 10.0, 20.0, 0.0)
            if line is None:
                continue
            assert line.endswith("\r\n")
            sid, red, edge, nir, ndre, ndvi = line.strip().split(",")
            assert float(ndvi) == pytest.approx(
                (float(nir) - float(red)) / (float(nir) + float(red)), abs=2e-3
            )
            assert -1 <= float(ndre) <= 1 and 0 <= float(edge) <= 1
            got[int(sid)].append(float(ndvi))
    for i, s in enumerate(sensors, start=1):
        assert len(got[i]) == 10
        truth = f.ndvi(10.0 + s.offset_m, 20.0)
        assert sum(got[i]) / 10 == pytest.approx(truth, abs=0.02)


def test_the_cab_pcs_quick_rmc_read_is_the_terminals_decoder() -> None:
    """The simulated receiver's lines through the cab PC's quick speed read and the terminal's
    NmeaDecoder: the same speed (None where the decoder has no valid fix), to the bit."""
    from topdress.gnss.nmea import NmeaDecoder

    decoder = NmeaDecoder()
    outage = GnssParams(outages=((30.0, 40.0),), talker="GP")
    rmc = 0
    for params in (GnssParams(), outage):
        rx = GnssReceiver(params, seed=8)
        for i in range(1, 6000):
            t = i * DT
            v = min(3.0, 0.3 * t)
            for line in rx.step(t, 0.0, v * t, v, 0.3):
                fix = decoder.decode(line)
                if fix.type != "RMC":
                    continue
                rmc += 1
                want = fix.speed_kmh if fix.fix_valid else None
                assert nmea.parse_rmc_speed_kmh(line) == want
    assert rmc > 500
