"""The World with the C ECU core in the loop, and the cab PC over a virtual CAN bus."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from topdress import protocol
from topdress.errors import EcuParamError
from topdress.protocol import Fault, Source
from topdress.sim.gnss import GnssParams
from topdress.sim.sil import CabPc, PcParams, Sil
from topdress.sim.tractor import Drive
from topdress.sim.world import SimConfig, World


def test_world_outputs_nmea_crop_and_ecu_frames_at_their_rates() -> None:
    w = World(seed=3, drive=Drive.paper_run(5.0))
    nmea: list[str] = []
    crop: list[str] = []
    frames: list[tuple[int, bytes]] = []
    for _ in range(200):  # 2 s
        out = w.step()
        nmea += out.nmea
        crop += out.crop
        frames += out.can
    assert w.t_s == pytest.approx(2.0)
    assert len(nmea) == 3 * 8  # 5 Hz; the fixes of 1.8 and 2.0 s are inside the 0.3 s latency
    assert sorted({ln[3:6] for ln in nmea}) == ["GGA", "RMC", "VTG"]
    assert len(crop) == 4 * 4  # four sensors at 2 Hz
    assert sorted({int(ln.split(",")[0]) for ln in crop}) == [1, 2, 3, 4]
    status = [f for f in frames if f[0] == protocol.DEFAULT_IDS.status]
    assert len(status) == 20  # every 100 ms
    decoded = [protocol.decode(f) for f in frames]
    assert {type(d).__name__ for d in decoded} >= {"EcuStatus", "EcuDiag", "EcuSpeeds"}
    # no command yet: stopped, meters and fans at rest
    assert w.ecu.state.running is False and w.truth.fan_rpm == (0.0, 0.0)


def test_deliver_can_rejects_and_counts_bad_frames() -> None:
    w = World(seed=1)
    assert w.deliver_can((protocol.DEFAULT_IDS.command, b"\x0a\x00")) < 0
    assert w.deliver_can((0x123, bytes(8))) < 0
    good = protocol.encode_command(True, 3000.0, 180.0, 180.0, None)
    assert w.deliver_can(good) == 0
    c = w.ecu.counters
    assert c.rx_bad_length == 1 and c.rx_unknown_id == 1 and c.rx_ok == 1


def _paper_run(
    v_kmh: float, seed: int, cfg: SimConfig | None = None
) -> tuple[World, dict[str, np.ndarray]]:
    w = World(cfg, seed=seed, drive=Drive.paper_run(v_kmh))
    with Sil(w, PcParams()) as sil:
        sil.run_until_done()
        assert sil.record is not None
        return w, sil.record.arrays()


def test_applied_fertilizer_matches_rate_times_area() -> None:
    w, tr = _paper_run(8.0, seed=5)
    truth = w.truth
    assert truth.in_flight_kg == pytest.approx((0.0, 0.0), abs=1e-9)
    # 180 kg/ha over 3.6 m on the distance metered (from first landing to the stop)
    assert truth.first_landing_m[0] is not None
    metered_m = truth.odometer_m - truth.first_landing_m[0]
    expected = 180.0 * 3.6 * metered_m / 10_000.0
    assert truth.applied_kg[0] == pytest.approx(expected, rel=0.06)
    assert truth.applied_kg[1] == pytest.approx(expected, rel=0.06)
    # the bins along the track hold all of it
    assert sum(w.applied_by_bin[0].values()) == pytest.approx(truth.applied_kg[0])
    # uniform phase: meter speed = eq. 4 from the selected speed, within the PID's error
    uni = tr["phase"] == 2
    expected_rpm = 3.6 * 180.0 * tr["selected_kmh"][uni] / (600.0 * 0.3)
    assert np.median(np.abs(tr["meter_rpm_upper"][uni] - expected_rpm)) < 1.0


def test_uniform_speeds_seen_by_the_ecu_match_the_truth() -> None:
    w, tr = _paper_run(6.5, seed=2)
    uni = tr["phase"] == 2
    slip = w.wheel.slip_pct(6.5) / 100.0
    assert np.mean(tr["wheel_kmh"][uni]) == pytest.approx(6.5 * (1 - slip), abs=0.15)
    assert np.mean(tr["gnss_kmh"][uni]) == pytest.approx(6.5, abs=0.15)
    assert np.mean(tr["v_true_kmh"][uni]) == pytest.approx(6.5, abs=0.1)


def test_same_seed_same_run_other_seed_other_run() -> None:
    _, a = _paper_run(5.0, seed=11)
    _, b = _paper_run(5.0, seed=11)
    _, c = _paper_run(5.0, seed=12)
    assert np.array_equal(a["meter_rpm_upper"], b["meter_rpm_upper"])
    n = min(a["t"].size, c["t"].size)
    assert not np.array_equal(a["wheel_kmh"][:n], c["wheel_kmh"][:n])


def test_gnss_outage_falls_back_to_the_wheel_and_keeps_metering() -> None:
    cfg = SimConfig(gnss=dataclasses.replace(GnssParams(), outages=((15.0, 22.0),)))
    _, tr = _paper_run(8.0, seed=4, cfg=cfg)
    t = tr["t"]
    # without a valid RMC the PC sends 0xFF; the ECU flags GNSS_LOST and uses the wheel
    during = (t > 16.0) & (t < 22.0)
    assert np.all(tr["source"][during] == 0)  # wheel
    assert np.all(tr["faults"][during].astype(int) & int(Fault.GNSS_LOST))
    assert np.all(tr["meter_rpm_upper"][during] > 20.0)
    after = (t > 24.0) & (tr["phase"] == 2)
    assert np.any(tr["source"][after] == 1)  # GNSS again once uniform
    assert Source.GNSS.code == 1


def test_rejected_parameter_raises_with_its_name() -> None:
    w = World(seed=1)
    with pytest.raises(EcuParamError, match="CvWindow"):
        Sil(w, PcParams(ecu_params=(("CvWindow", 9.0),)))


@pytest.mark.parametrize("on_rate", [True, False])
def test_the_simulated_pc_sends_a_changed_rate_at_its_cycle_with_send_on_rate(
    on_rate: bool,
) -> None:
    pc = CabPc(PcParams(cycle_s=0.1, send_on_rate=on_rate))
    first = pc.poll(0.0)  # the command period's first frame
    assert [m.arbitration_id for m in first] == [protocol.DEFAULT_IDS.command]
    pc.rate_kg_ha = (200.0, 90.0)
    out = pc.poll(0.1)  # the next cycle, 0.4 s before the period's next frame
    cmds = [protocol.decode(m) for m in out if m.arbitration_id == protocol.DEFAULT_IDS.command]
    assert len(cmds) == (1 if on_rate else 0)
    if on_rate:
        assert isinstance(cmds[0], protocol.PcCommand)
        assert (cmds[0].rate_upper_kg_ha, cmds[0].rate_lower_kg_ha) == (200.0, 90.0)
    assert pc.poll(0.2) == []  # unchanged: nothing more until the period
    pc.paused = True  # the pause is a change of rate too (0, 0)
    assert len(pc.poll(0.3)) == (1 if on_rate else 0)
