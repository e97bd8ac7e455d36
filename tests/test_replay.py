"""`topdress replay`: events through the ECU core, in virtual time.

The drive is synthesised: rest 2 s, +0.5 m/s^2 to 8 km/h, uniform until 30 s, -0.5 m/s^2 to
rest; wheel counts every 10 ms from eq. 1 inverted (pulses = distance / (2 pi r) * K, no slip),
RMC at 5 Hz with the true speed.
"""

from __future__ import annotations

import csv
import itertools
import math
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from topdress import protocol
from topdress.cli.main import main
from topdress.config import default_config, loads_config
from topdress.ecu import Ecu
from topdress.errors import ConfigError
from topdress.gnss.nmea import NmeaDecoder, make_sentence
from topdress.gnss.tracker import GnssSpeedTracker
from topdress.log.events import CanEvent, Event, NmeaEvent, WheelEvent, read_file, write
from topdress.log.export import session_events
from topdress.log.replay import (
    MAX_IDLE_S,
    ReplayRow,
    ReplayStats,
    ecu_params,
    replay,
    replay_stream,
)
from topdress.log.session import SessionLog, SessionReader

R_M, PPR = 0.0615, 500
V_MAX = 8.0 / 3.6
ACC = 0.5
T_ACC = V_MAX / ACC
T0 = 1000.0  # a monotonic clock does not start at zero


def truth(t: float) -> tuple[float, float]:
    """(speed m/s, distance m) at t seconds from the start of the drive."""
    x_acc = 0.5 * ACC * T_ACC**2
    if t < 2.0:
        return 0.0, 0.0
    if t < 2.0 + T_ACC:
        s = t - 2.0
        return ACC * s, 0.5 * ACC * s * s
    if t < 30.0:
        return V_MAX, x_acc + V_MAX * (t - 2.0 - T_ACC)
    x_uni = x_acc + V_MAX * (28.0 - T_ACC)
    if t < 30.0 + T_ACC:
        s = t - 30.0
        return V_MAX - ACC * s, x_uni + V_MAX * s - 0.5 * ACC * s * s
    return 0.0, x_uni + x_acc


def pulses(t: float) -> int:
    return math.floor(truth(t)[1] / (2 * math.pi * R_M) * PPR)


def rmc(v_ms: float) -> str:
    knots = v_ms * 3.6 / 1.852
    body = f"GPRMC,120000.00,A,4545.0000,N,12630.0000,E,{knots:.3f},90.0,211126,,,A"
    return make_sentence(body).decode().rstrip("\r\n")


def drive_events(seconds: float = 40.0, gnss_until: float = math.inf) -> list[Event]:
    events: list[Event] = []
    for k in range(round(seconds * 100)):
        t = k * 0.01
        if k % 20 == 0 and t < gnss_until:
            events.append(NmeaEvent(T0 + t, rmc(truth(t)[0])))
        events.append(WheelEvent(T0 + t, pulses(t)))
    return events


def eq1_kmh(f_hz: float) -> float:
    return 2 * math.pi * f_hz * R_M * 3.6 / PPR


def ecu_wheel_kmh(t: float) -> float:
    """What the ECU must report at an update at t: eq. 1 of the mean of 4 frequency samples,
    taken on a 125 ms grid rounded up to the 10 ms steps (windows of 130, 120, 130, 120 ms)."""
    edges = [t - 0.5, t - 0.37, t - 0.25, t - 0.12, t]
    freqs = [(pulses(b) - pulses(a)) / (b - a) for a, b in itertools.pairwise(edges)]
    return eq1_kmh(sum(freqs) / 4)


@pytest.fixture(scope="module")
def paper_rows() -> list[ReplayRow]:
    return replay(drive_events(), default_config(), "paper")


def test_a_row_at_every_wheel_update(paper_rows: list[ReplayRow]) -> None:
    # wheel_update_ms = 500: 40 s of events give 79 updates (0.5 .. 39.5 s).
    assert len(paper_rows) == 79
    assert [round(r.t - T0, 3) for r in paper_rows] == [round(0.5 * i, 3) for i in range(1, 80)]


def test_wheel_speed_is_eq1_of_the_replayed_pulses(paper_rows: list[ReplayRow]) -> None:
    for r in paper_rows:
        t = round(r.t - T0, 2)
        assert r.v_wheel_kmh == pytest.approx(ecu_wheel_kmh(t), abs=1e-3), f"t={t}"
    uniform = [r for r in paper_rows if 10.0 <= r.t - T0 <= 28.0]
    assert all(r.v_wheel_kmh == pytest.approx(8.0, abs=0.02) for r in uniform)


def test_paper_rule_picks_gnss_only_in_uniform_motion_above_6_kmh(
    paper_rows: list[ReplayRow],
) -> None:
    for r in paper_rows:
        assert r.v_gnss_kmh is not None
        rule = r.cv_pct is not None and r.cv_pct < 4.2 and r.v_gnss_kmh > 6.0
        assert r.source == ("gnss" if rule else "wheel"), f"t={r.t - T0}"
        assert r.v_kmh == pytest.approx(r.v_gnss_kmh if rule else r.v_wheel_kmh)
    by_t = {round(r.t - T0, 1): r for r in paper_rows}
    assert by_t[4.0].source == "wheel" and by_t[4.0].cv_pct is not None and by_t[4.0].cv_pct > 4.2
    assert all(by_t[t / 2].source == "gnss" for t in range(20, 58))
    assert by_t[33.0].source == "wheel"


def test_single_source_modes() -> None:
    events = drive_events()
    wheel = replay(events, default_config(), "wheel")
    gnss = replay(events, default_config(), "gnss")
    assert {r.source for r in wheel} == {"wheel"} and {r.source for r in gnss} == {"gnss"}
    assert all(r.v_kmh == r.v_wheel_kmh for r in wheel)
    assert all(r.v_kmh == r.v_gnss_kmh for r in gnss)
    # GNSS forwarded with 0.1 km/h resolution: 8.0 in the uniform phase.
    assert all(r.v_kmh == pytest.approx(8.0, abs=1e-6) for r in gnss if 10 <= r.t - T0 <= 28)


def test_config_moves_the_switch_speed() -> None:
    cfg = loads_config("[speed]\nswitch_speed_kmh = 8.5\n")
    rows = replay(drive_events(), cfg, "paper")
    assert {r.source for r in rows} == {"wheel"}  # 8.0 km/h never exceeds 8.5


def test_gnss_loss_falls_back_to_the_wheel() -> None:
    # RMC stops at 20 s; the tracker goes stale after gnss.stale_s = 2 s, the command then says
    # "not available" and the ECU drops GNSS at once.
    stats = ReplayStats()
    rows = replay(drive_events(gnss_until=20.0), default_config(), "paper", stats)
    by_t = {round(r.t - T0, 1): r for r in rows}
    assert by_t[19.5].source == "gnss" and by_t[19.5].v_gnss_kmh is not None
    assert all(by_t[t / 2].source == "wheel" for t in range(46, 60))
    assert all(by_t[t / 2].v_gnss_kmh is None for t in range(46, 60))
    assert stats.commands == 80 and stats.steps == 4000 and stats.nmea_rejected == 0


def test_wheel_counts_between_events_are_interpolated() -> None:
    # The same drive with wheel counts only every 100 ms (as a session export gives them).
    sparse = [
        e for e in drive_events() if not isinstance(e, WheelEvent) or round(e.t * 100) % 10 == 0
    ]
    dense_rows = replay(drive_events(), default_config(), "wheel")
    sparse_rows = replay(sparse, default_config(), "wheel")
    assert len(sparse_rows) == len(dense_rows)
    for a, b in zip(dense_rows, sparse_rows, strict=True):
        assert b.v_wheel_kmh == pytest.approx(a.v_wheel_kmh, abs=0.05)


def test_ecu_params_follow_the_config_and_the_mode() -> None:
    cfg = loads_config("[machine]\nwheel_radius_m = 0.1\n[speed]\nqueue_len = 3\ncv_window = 3\n")
    p = ecu_params(cfg, "gnss")
    assert p.wheel_radius_m == pytest.approx(0.1) and p.queue_len == 3 and p.cv_window == 3
    assert p.speed_mode == 2
    assert p.command_id == 0x0A5C6465


def test_replay_cli_is_deterministic_and_reports_bad_lines(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    events = tmp_path / "drive.ndjson"
    with events.open("w") as f:
        write(drive_events(20.0), f)
        f.write('{"t": 1020.0, "wheel_count": "many"}\n')
    outs = [tmp_path / "a.csv", tmp_path / "b.csv"]
    for out in outs:
        assert main(["replay", str(events), "--speed-mode", "paper", "--out", str(out)]) == 0
    captured = capsys.readouterr()
    assert f"{events}:2101: skipped" in captured.err
    assert "39 speed updates" in captured.out
    a, b = (p.read_bytes() for p in outs)
    assert a == b
    with outs[0].open() as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["t", "v_wheel_kmh", "v_gnss_kmh", "v_kmh", "source", "cv_pct"]
    assert rows[0]["cv_pct"] == ""  # queue not full yet
    assert rows[-1]["t"] == "1019.500" and rows[-1]["source"] == "gnss"
    assert rows[-1]["v_gnss_kmh"] == "8.000"


def test_events_out_of_file_order_replay_as_in_time_order() -> None:
    events = drive_events(10.0)
    # Swap neighbours with distinct times, as lines of two input threads can interleave.
    shuffled = list(events)
    for i in range(0, len(shuffled) - 3, 7):
        if shuffled[i].t != shuffled[i + 2].t:
            shuffled[i], shuffled[i + 2] = shuffled[i + 2], shuffled[i]
    assert shuffled != events
    assert replay(shuffled, default_config()) == replay(events, default_config())


def test_replay_cli_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(tmp_path / "none.ndjson"), "--out", str(tmp_path / "o.csv")]) == 2
    assert "cannot read events" in capsys.readouterr().err
    bad_cfg = tmp_path / "bad.toml"
    bad_cfg.write_text("[speed]\ncv_threshold_pct = 99\n")
    events = tmp_path / "e.ndjson"
    events.write_text("")
    argv = ["replay", str(events), "--config", str(bad_cfg), "--out", str(tmp_path / "o.csv")]
    assert main(argv) == 2
    assert "speed.cv_threshold_pct" in capsys.readouterr().err


def test_round_trip_log_export_replay(tmp_path: Path) -> None:
    """A live run (ECU core fed by the same inputs, the terminal's GNSS forwarding) is logged,
    exported and replayed: the replay gives the live speeds at every update."""
    cfg = default_config()
    ecu = Ecu(ecu_params(cfg, "paper"), now_us=-10_000 & 0xFFFFFFFF)
    decoder, tracker = NmeaDecoder(), GnssSpeedTracker(cfg.gnss.rmc_timeout_s, cfg.gnss.stale_s)
    live: list[ReplayRow] = []
    updates = 0
    with SessionLog.create(tmp_path, "") as log:
        for k in range(4000):
            # A port's loop: the ECU steps, then the terminal takes what came and commands.
            t, now_us = T0 + k * 0.01, k * 10_000
            ecu.step_raw(now_us, pulses(k * 0.01), 0, 0, 0, 0)
            for frame in ecu.tx_raw():
                log.raw("can_rx", t, frame)
            s = ecu.state
            if s.wheel_updates != updates:
                updates = s.wheel_updates
                live.append(ReplayRow(t, s.v_wheel_kmh, s.v_gnss_kmh, s.v_kmh, s.source, s.cv_pct))
            if k % 20 == 0:
                line = rmc(truth(k * 0.01)[0])
                log.raw("nmea", t, line)
                tracker.update(t, decoder.decode(line))
            if k % 50 == 0:
                msg = protocol.encode_command(True, 3000, 180, 180, tracker.current(t))
                log.raw("can_tx", t, (msg.arbitration_id, bytes(msg.data)))
                assert ecu.rx(msg, now_us) == 0
    assert log.dropped == 0 and log.errors == 0
    out = tmp_path / "events.ndjson"
    with SessionReader(log.path) as reader, out.open("w") as f:
        write(session_events(reader), f)
    read = read_file(out)
    assert read.bad == []
    # EcuDiag every 100 ms: 400 in 40 s, each giving a wheel_count.
    assert sum(isinstance(e, WheelEvent) for e in read.events) == 400
    replayed = replay(read.events, cfg, "paper")
    # The wheel count is known every 100 ms (not 10 ms) after the log: the first wheel_count
    # comes with the first EcuDiag, and counts in between are interpolated.
    assert len(replayed) == len(live)
    for a, b in zip(live, replayed, strict=True):
        assert b.t == pytest.approx(a.t, abs=1e-6)
        assert b.v_wheel_kmh == pytest.approx(a.v_wheel_kmh, abs=0.02)
        assert b.v_gnss_kmh == pytest.approx(a.v_gnss_kmh)
        assert b.source == a.source
        assert b.v_kmh == pytest.approx(a.v_kmh, abs=0.02)


def test_a_long_pause_between_events_is_cut_not_stepped_through() -> None:
    # Two drives an hour apart in one file (two sessions pasted together): the hour of nothing
    # is replayed as MAX_IDLE_S; the rows keep the events' times.
    first = drive_events(40.0)
    last_count = pulses(40.0)
    second: list[Event] = [
        WheelEvent(e.t + 3600.0, e.wheel_count + last_count)
        if isinstance(e, WheelEvent)
        else NmeaEvent(e.t + 3600.0, e.nmea)
        for e in first
        if isinstance(e, WheelEvent | NmeaEvent)
    ]
    stats = ReplayStats()
    rows = replay(first + second, default_config(), "paper", stats)
    assert stats.gaps_cut == 1
    assert stats.steps == pytest.approx((40.0 + MAX_IDLE_S + 40.0) / 0.01, abs=2)
    assert all(r.t - T0 < 40.0 + MAX_IDLE_S or r.t - T0 > 3600.0 for r in rows)
    # the second drive replays as the first did: 8 km/h on GNSS in its uniform phase
    again = [r for r in rows if r.t - T0 > 3600.0]
    assert len(again) == pytest.approx(80, abs=1)
    uniform = [r for r in again if 10.0 <= r.t - T0 - 3600.0 <= 28.0]
    assert len(uniform) == 36
    for r in uniform:
        assert r.v_wheel_kmh == pytest.approx(8.0, abs=0.02) and r.source == "gnss"


def test_a_bogus_time_does_not_hang_the_replay() -> None:
    events = [*drive_events(5.0), WheelEvent(1e300, pulses(5.0))]
    stats = ReplayStats()
    rows = replay(events, default_config(), "wheel", stats)
    assert stats.gaps_cut == 1 and stats.steps < (5.0 + MAX_IDLE_S) / 0.01 + 2
    assert rows[-1].t < T0 + 5.0 + MAX_IDLE_S


def test_gnss_beyond_the_frame_is_forwarded_as_25_kmh_as_the_terminal_does() -> None:
    # 30 km/h (road transport): the terminal's CAN link clamps it to the frame's 25 km/h
    knots = 30.0 / 1.852
    line = make_sentence(f"GPRMC,120000.00,A,4545.0,N,12630.0,E,{knots:.3f},90.0,211126,,,A")
    events: list[Event] = [NmeaEvent(T0 + k * 0.2, line.decode().rstrip()) for k in range(20)]
    rows = replay(events, default_config(), "gnss")
    assert rows and all(r.v_gnss_kmh == pytest.approx(25.0) for r in rows[1:])


def test_the_gnss_lag_is_learned_and_a_recorded_one_starts_the_learning() -> None:
    # this drive's receiver reports the speed of its fix at once: the lag learned is ~0
    stats = ReplayStats()
    replay(drive_events(), default_config(), "fused", stats)
    assert stats.lag_start_ms is None
    assert stats.lag_learned_ms is not None and stats.lag_learned_ms <= 150
    # a recorded session's EcuGnssLag (learned 800 ms, LagState 1, LagAuto) starts the next run
    frame = bytes([0x20, 0x03, 0x20, 0x03, 30, 5, 0x05, 0])
    recorded = CanEvent(T0 + 0.5, protocol.DEFAULT_IDS.gnss_lag, frame, "rx")
    assert protocol.decode((protocol.DEFAULT_IDS.gnss_lag, frame)) == protocol.EcuGnssLag(
        800, 800, 3.0, 0.05, 1, True
    )
    stats = ReplayStats()
    replay([*drive_events(seconds=3.0), recorded], default_config(), "fused", stats)
    assert stats.lag_start_ms == 800
    p = ecu_params(default_config(), "fused", stats.lag_start_ms)
    assert (p.gnss_lag_ms, p.gnss_lag_auto) == (800, 1)
    # a configured lag is fixed: the recorded one does not replace it
    fixed = ecu_params(loads_config("[ecu]\ngnss_lag_ms = 1300\n"), "fused", 800)
    assert (fixed.gnss_lag_ms, fixed.gnss_lag_auto) == (1300, 0)
    with pytest.raises(ConfigError, match=r"ecu\.gnss_lag_ms"):
        loads_config('[ecu]\ngnss_lag_ms = "soon"\n')


def test_the_step_loops_wheel_walker_gives_what_the_search_gives() -> None:
    # repeated times, a count that goes back, steps before the first and after the last event
    from topdress.log.replay import _WheelInput

    w = _WheelInput([30_000, 50_000, 50_000, 90_000, 200_000], [7, 9, 20, 15, 400])
    walk = w.walker()
    times = range(0, 260_000, 10_000)
    assert [walk(t) for t in times] == [w.at(t) for t in times]
    assert [walk(t) for t in (0, 60_000, 250_000)] != [7, 7, 7]


def test_replay_streams_a_file_in_two_passes_with_the_rows_of_a_whole_read(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`topdress replay` goes through the file twice (the survey, then the run), holding no
    list of its events, and writes what a replay of all events read at once gives."""
    events = drive_events(20.0)
    passes: list[int] = []
    streamed = list(replay_stream(source_of(events, passes), default_config(), "paper"))
    assert streamed == replay(events, default_config(), "paper") and len(streamed) > 30
    assert passes == [len(events), len(events)]
    # out of time order: sorted once in memory, then the same rows
    swapped = [events[0], events[2], events[1], *events[3:]]
    assert swapped[1].t > swapped[2].t
    passes.clear()
    assert list(replay_stream(source_of(swapped, passes), default_config(), "paper")) == streamed
    assert passes == [len(events), len(events)]  # the survey, then one read to sort
    # the command over a file with a malformed line: said once, the rows as above
    path = tmp_path / "e.ndjson"
    with path.open("w") as f:
        write(events[:100], f)
        f.write("{not json\n")
        write(events[100:], f)
    out = tmp_path / "r.csv"
    assert main(["replay", str(path), "--speed-mode", "paper", "--out", str(out)]) == 0
    captured = capsys.readouterr()
    assert captured.err.count("e.ndjson:101: skipped") == 1
    assert f"{len(streamed)} speed updates from {len(events)} events" in captured.out
    with out.open() as f:
        assert [float(r["t"]) for r in csv.DictReader(f)] == pytest.approx(
            [r.t for r in streamed], abs=1e-3
        )


def source_of(events: list[Event], passes: list[int]) -> Callable[[], Iterator[Event]]:
    def source() -> Iterator[Event]:
        passes.append(0)
        for e in events:
            passes[-1] += 1
            yield e

    return source
