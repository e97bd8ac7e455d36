"""A simulated Table 2 drive, run live with the terminal's GNSS forwarding, recorded as events
and replayed: the replay reproduces the live speed trace at every ECU speed update."""

from __future__ import annotations

from pathlib import Path

import pytest

from topdress import protocol
from topdress.config import default_config
from topdress.gnss.nmea import NmeaDecoder
from topdress.gnss.tracker import GnssSpeedTracker
from topdress.log.events import CanEvent, Event, NmeaEvent, WheelEvent, read_file, write
from topdress.log.replay import ReplayRow, ReplayStats, ecu_params, replay
from topdress.sim.tractor import Drive
from topdress.sim.world import SimConfig, World


def live_run(
    target_kmh: float, seed: int, mode: str = "paper"
) -> tuple[list[ReplayRow], list[Event]]:
    """The terminal's forwarding done by hand: a PcCommand every 500 ms and, for every new
    fix, a PcGnssTime of age 0 (as the terminal sends it the moment the sentence arrives).
    The wheel port counts only: a recorded session has the counts, not the edge times."""
    cfg = default_config()
    sim = SimConfig(ecu=ecu_params(cfg, mode), wheel_edges=False)
    world = World(sim, seed, Drive.paper_run(target_kmh))
    decoder = NmeaDecoder()
    tracker = GnssSpeedTracker(cfg.gnss.rmc_timeout_s, cfg.gnss.stale_s)
    rows: list[ReplayRow] = []
    events: list[Event] = []
    updates = 0
    seq = 0
    for n in range(4500):
        out = world.step()
        t = out.t_s
        s = world.ecu.state
        if s.wheel_updates != updates:
            updates = s.wheel_updates
            gnss = s.v_gnss_kmh if s.gnss_valid else None
            rows.append(ReplayRow(t, s.v_wheel_kmh, gnss, s.v_kmh, str(s.source), s.cv_pct))
        events.append(WheelEvent(t, world.wheel.count))
        for line in out.nmea:
            events.append(NmeaEvent(t, line))
            if tracker.update(t, decoder.decode(line)) is not None:
                seq += 1
                fix = protocol.encode_gnss_time(tracker.current(t), 0, seq & 0xFF)
                assert world.deliver_can(fix) == 0
        if n % 50 == 0:  # the terminal's 500 ms command period
            msg = protocol.encode_command(True, 3000, 180, 180, tracker.current(t))
            events.append(CanEvent(t, msg.arbitration_id, bytes(msg.data), "tx"))
            assert world.deliver_can(msg) == 0
    return rows, events


@pytest.mark.parametrize(("target_kmh", "seed"), [(6.5, 1), (8.0, 2)])
def test_replay_of_a_simulated_table2_drive_reproduces_its_speed_trace(
    tmp_path: Path, target_kmh: float, seed: int
) -> None:
    live, events = live_run(target_kmh, seed)
    path = tmp_path / "drive.ndjson"
    with path.open("w") as f:
        write(events, f)
    read = read_file(path)
    assert read.bad == [] and read.events == events
    replayed = replay(read.events, default_config(), "paper")
    assert len(replayed) == len(live) == 89
    for a, b in zip(live, replayed, strict=True):
        assert b.t == pytest.approx(a.t, abs=1e-6)
        assert (b.v_wheel_kmh, b.v_gnss_kmh, b.v_kmh, b.source, b.cv_pct) == (
            a.v_wheel_kmh,
            a.v_gnss_kmh,
            a.v_kmh,
            a.source,
            a.cv_pct,
        ), f"t={a.t}"
    # It is a dual-mode drive: wheel while accelerating, GNSS in the uniform phase, wheel again.
    sources = [r.source for r in live]
    first_gnss = sources.index("gnss")
    last_gnss = len(sources) - 1 - sources[::-1].index("gnss")
    assert set(sources[:first_gnss]) == {"wheel"} and set(sources[last_gnss + 1 :]) == {"wheel"}
    assert all(r.v_gnss_kmh is not None and r.v_gnss_kmh > 6.0 for r in live if r.source == "gnss")


def test_replay_in_the_fused_mode_applies_each_fix_once_at_its_time(tmp_path: Path) -> None:
    """The fused estimate takes each fix from PcGnssTime once, with its age: the replay makes
    those frames again from the recorded NMEA and reproduces the live fused trace exactly."""
    live, events = live_run(8.0, 3, "fused")
    stats = ReplayStats()
    replayed = replay(events, default_config(), "fused", stats)
    assert len(replayed) == len(live) > 80
    for a, b in zip(live, replayed, strict=True):
        assert (b.t, b.v_wheel_kmh, b.v_gnss_kmh, b.v_kmh, b.source) == pytest.approx(
            (a.t, a.v_wheel_kmh, a.v_gnss_kmh, a.v_kmh, a.source), abs=1e-6
        ), f"t={a.t}"
    fixes = sum(1 for e in events if isinstance(e, NmeaEvent) and e.nmea[3:6] == "RMC")
    assert stats.gnss_times == fixes  # one PcGnssTime per new RMC, none for the GGA
    assert {r.source for r in live if r.v_kmh > 1.0} == {"fused"}
