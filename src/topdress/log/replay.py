"""Replay recorded raw inputs through the ECU core (the same C code as in the field).

Virtual time: the ECU steps every 10 ms from the first event's time; after each step every
event due by then is applied (the ECU sees its effect from the next step):
- `nmea`: through the terminal's NmeaDecoder and GnssSpeedTracker; the speed is forwarded in a
  PcCommand every `can.command_period_s` (and on each new fix with `can.send_on_gnss`), as
  the terminal does, carrying "not available" when the tracker has no fresh valid speed;
  and every new fix in a PcGnssTime with its age at that step (the sentence's recorded arrival
  to the step that forwards it), as the terminal sends it, so the `fused` mode applies the
  GNSS speed at its time of validity. The recorded PcGnssTime frames are not replayed: they
  are made again from the NMEA, like the commands' speed.
- `wheel_count`: the wheel encoder input, linearly interpolated between events (integer
  pulses, rounded down); held before the first and after the last. Between two events the
  wheel is taken to turn evenly, which is what a frequency input sees; events every 10 ms on
  the step grid make the input exact.
- `can` terminal->ECU PcCommand: its start flag, fan speed and rates are kept for the next
  commands (its GNSS speed is not: that comes from the NMEA). Other frames are ignored.
- `crop`: ignored (the speeds do not depend on it).
- `can` ECU->terminal EcuGnssLag: the last lag the ECU reported as learned is pushed as the
  start of this run's learning (`[ecu] gnss_lag_ms = "auto"`), as the terminal does with the
  lag it keeps per receiver; a configured number still fixes it.
Output: one row at every ECU speed update (wheel_updates increments).
A pause longer than MAX_IDLE_S between two events (two sessions in one file, a bogus time) is
cut to MAX_IDLE_S: every ECU timeout has run out by then, and stepping through hours (or 1e300 s)
of nothing at 10 ms would take that long. Rows keep the events' own times.
"""

from __future__ import annotations

import bisect
import csv
import logging
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Final, TextIO

from topdress import protocol
from topdress.config import SPEED_MODE_IDS, TerminalConfig
from topdress.ecu import Ecu, EcuParams, EcuState
from topdress.errors import ProtocolError
from topdress.gnss.nmea import NmeaDecoder
from topdress.gnss.tracker import GnssSpeedTracker
from topdress.log.events import CanEvent, CropEvent, Drop, Event, NmeaEvent, WheelEvent
from topdress.protocol.frames import GNSS_MAX_KMH
from topdress.protocol.model import SpeedMode

_log = logging.getLogger(__name__)

STEP_US: Final = 10_000
MAX_IDLE_S: Final = 60.0  # the longest ECU timeout is 30 s
_MAX_IDLE_US: Final = round(MAX_IDLE_S * 1e6)
COLUMNS: Final = ("t", "v_wheel_kmh", "v_gnss_kmh", "v_kmh", "source", "cv_pct")


@dataclass(frozen=True, slots=True)
class ReplayRow:
    t: float
    v_wheel_kmh: float
    v_gnss_kmh: float | None  # None: the ECU has no valid GNSS speed
    v_kmh: float
    source: str
    cv_pct: float | None  # None: undefined (queue not full yet)


@dataclass
class ReplayStats:
    steps: int = 0
    commands: int = 0
    gnss_times: int = 0  # PcGnssTime frames sent (one per new fix)
    nmea_rejected: int = 0
    bad_commands: int = 0  # recorded PcCommand frames that did not decode
    ecu_rx_refused: int = 0
    gaps_cut: int = 0  # pauses between events longer than MAX_IDLE_S, cut to it
    lag_start_ms: int | None = None  # the learned lag found in the recorded frames (None: none)
    lag_learned_ms: int | None = None  # the GNSS lag the ECU learned by the end (None: not)


@dataclass
class _Command:
    start: bool
    fan_rpm: float
    rate_upper_kg_ha: float = 0.0
    rate_lower_kg_ha: float = 0.0


@dataclass
class _WheelInput:
    """Cumulative wheel pulses at any step time, from the wheel_count events."""

    times_us: list[int] = field(default_factory=list)
    counts: list[int] = field(default_factory=list)

    def at(self, t_us: int) -> int:
        if not self.counts:
            return 0
        i = bisect.bisect_right(self.times_us, t_us)
        if i == 0:
            return self.counts[0]
        if i == len(self.counts):
            return self.counts[-1]
        t0, t1 = self.times_us[i - 1], self.times_us[i]
        c0, c1 = self.counts[i - 1], self.counts[i]
        return c0 + (c1 - c0) * (t_us - t0) // (t1 - t0)

    def walker(self) -> Callable[[int], int]:
        """`at` for times that never go back (the step loop): the segment is followed along
        instead of searched for at every step. Same values as `at`."""
        times, counts = self.times_us, self.counts
        if len(counts) < 2:
            return self.at
        last = len(counts) - 1
        i = 0  # times[i] <= t < times[i + 1] once t reaches times[0]

        def at(t_us: int) -> int:
            nonlocal i
            if t_us < times[0]:
                return counts[0]
            while i < last and times[i + 1] <= t_us:
                i += 1
            if i == last:
                return counts[-1]
            t0 = times[i]
            return counts[i] + (counts[i + 1] - counts[i]) * (t_us - t0) // (times[i + 1] - t0)

        return at


def ecu_params(cfg: TerminalConfig, speed_mode: str, lag_start_ms: int | None = None) -> EcuParams:
    """The parameters the terminal would push at start, with the replay's speed mode (and
    the GNSS lag to start learning from, as the terminal keeps it per receiver)."""
    pushed = cfg.ecu_params(lag_start_ms)
    pushed[protocol.param("speed_mode").id] = SPEED_MODE_IDS[speed_mode]
    base = EcuParams.defaults()
    kg = list(base.kg_per_rev)
    changes: dict[str, float | int] = {}
    for pid, value in pushed.items():
        spec = protocol.param(pid)
        if spec.index is not None:
            kg[spec.index] = float(value)
        else:
            changes[spec.field] = int(value) if spec.integer else float(value)
    ids = cfg.can.ids
    return base.replace(
        **changes,
        kg_per_rev=(kg[0], kg[1]),
        status_id=ids["status"],
        command_id=ids["command"],
    ).validate()


def kept(ids: protocol.FrameIds = protocol.DEFAULT_IDS) -> tuple[Callable[[Event], bool], Drop]:
    """What replay acts on, for a session's frame ids: NMEA, wheel counts, frames to the ECU
    and the ECU's learned GNSS lag; crop lines and the ECU's other frames are ignored, so a
    reader need not keep them (a 12 h day: 70 % of them). As a test of an event, and as the
    lines a reader drops without building an event."""

    def needed(event: Event) -> bool:
        if isinstance(event, CanEvent) and event.dir == "rx":
            return event.can_id == ids.gnss_lag
        return not isinstance(event, CropEvent)

    return needed, Drop(crop=True, can_rx=True, rx_kept=frozenset({ids.gnss_lag}))


#: What replay keeps with the default frame ids.
needed, DROP = kept()


def _learned(e: CanEvent, ids: protocol.FrameIds) -> int | None:
    try:
        frame = protocol.decode((e.can_id, e.data), ids)
    except ProtocolError:
        return None
    return frame.learned_ms if isinstance(frame, protocol.EcuGnssLag) else None


def _us(t: float, t0: float) -> int:
    return round((t - t0) * 1e6)


#: The events again from the start, each time it is called (replay goes through them twice).
Source = Callable[[], Iterable[Event]]


def replay(
    events: Sequence[Event],
    cfg: TerminalConfig,
    speed_mode: str = SpeedMode.FUSED,
    stats: ReplayStats | None = None,
) -> list[ReplayRow]:
    """Run `events` through a fresh ECU core; rows at each speed update. Events are taken in
    time order (a stable sort: equal times keep their order)."""
    return list(replay_stream(lambda: events, cfg, speed_mode, stats))


def replay_stream(
    source: Source,
    cfg: TerminalConfig,
    speed_mode: str = SpeedMode.FUSED,
    stats: ReplayStats | None = None,
) -> Iterator[ReplayRow]:
    """`replay` of events in time order that are read twice and never held: a first pass
    finds the start, the pauses to cut, the wheel counts and the ECU's learned lag; the second
    runs the ECU and yields each row as it is made. A long day's events read from a file this
    way cost the wheel counts' memory, not the events'. Events out of time order are sorted
    (a stable sort: equal times keep their order), in memory."""
    stats = stats or ReplayStats()
    ids = protocol.FrameIds(**cfg.can.ids)
    survey = _Survey(source(), ids)
    if not survey.ordered:  # not as an export writes them: sorted (stable), in memory
        ordered = sorted(source(), key=lambda e: e.t)
        source = lambda: ordered  # noqa: E731
        survey = _Survey(ordered, ids)
    if survey.t0 is None:
        return
    stats.gaps_cut += survey.gaps
    replayer = _Replayer(survey, cfg, speed_mode, stats)
    yield from replayer.run(source())


class _Clock:
    """The events' times on the replay clock: each pause longer than MAX_IDLE_S cut to it,
    times never going back; `cuts`: (replay time, offset to the events' clock from there on)."""

    def __init__(self, t0: float) -> None:
        self.t0 = t0
        self.cuts: list[tuple[float, float]] = [(t0, 0.0)]
        self.gaps = 0
        self._offset = 0.0
        self._prev = t0  # the last event's own time
        self._last: float | None = None  # the last event's replay time

    @property
    def t_in(self) -> float:
        """The own time of the last event taken."""
        return self._prev

    @property
    def last(self) -> float:
        """The replay time of the last event taken."""
        return self._last if self._last is not None else self.t0

    def take(self, t: float) -> float:
        """The replay time of the next event, whose own time is `t`."""
        if t - self._prev > MAX_IDLE_S:
            # Whole steps cut, so the events keep their place on the 10 ms grid.
            self._offset += (_us(t, self._prev) - _MAX_IDLE_US) // STEP_US * STEP_US / 1e6
            last = self._last if self._last is not None else t
            self.cuts.append((max(t - self._offset, last), self._offset))
            self.gaps += 1
        at = max(t - self._offset, self._last) if self._last is not None else t
        self._last, self._prev = at, t
        return at


class _Survey:
    """The first pass: where the events start and end on the replay clock, the wheel input,
    and the last GNSS lag the ECU reported as learned (None: none)."""

    def __init__(self, events: Iterable[Event], ids: protocol.FrameIds) -> None:
        self.t0: float | None = None
        self.end: float = 0.0
        self.wheel = _WheelInput()
        self.learned_ms: int | None = None
        self.gaps = 0
        self.ordered = True  # the events' own times never go back
        clock: _Clock | None = None
        times, counts = self.wheel.times_us, self.wheel.counts
        lag_data: bytes | None = None  # the ECU repeats its lag report: decoded when it changes
        for e in events:
            if clock is None:
                clock = _Clock(e.t)
                self.t0 = e.t
            self.ordered &= e.t >= clock.t_in
            t = clock.take(e.t)
            if isinstance(e, WheelEvent):
                times.append(_us(t, clock.t0))
                counts.append(e.wheel_count)
            elif (
                isinstance(e, CanEvent)
                and e.dir != "tx"
                and e.can_id == ids.gnss_lag
                and e.data != lag_data
            ):
                lag_data = e.data
                learned = _learned(e, ids)
                self.learned_ms = learned if learned is not None else self.learned_ms
        if clock is not None:
            self.end, self.gaps = clock.last, clock.gaps


class _Replayer:
    """The terminal's side (GNSS forwarding, commands) and the ECU, on the 10 ms grid."""

    def __init__(
        self, survey: _Survey, cfg: TerminalConfig, speed_mode: str, stats: ReplayStats
    ) -> None:
        assert survey.t0 is not None
        self.cfg = cfg
        self.stats = stats
        self.t0 = survey.t0
        self.clock = _Clock(self.t0)
        self.ids = protocol.FrameIds(**cfg.can.ids)
        if self.ids == protocol.DEFAULT_IDS:  # its decoders are found without hashing the ids
            self.ids = protocol.DEFAULT_IDS
        # The lag learned in the recorded session is where this run's learning starts (the
        # terminal would have pushed it for the next session with the same receiver).
        self.lag_start_ms = survey.learned_ms
        stats.lag_start_ms = self.lag_start_ms
        # Initialised one period before its first step, as a port's ECU is.
        params = ecu_params(cfg, speed_mode, self.lag_start_ms)
        self.ecu = Ecu(params, now_us=-STEP_US & 0xFFFFFFFF)
        self.wheel = survey.wheel
        self.end_us = _us(survey.end, self.t0)
        self.decoder = NmeaDecoder()
        self.tracker = GnssSpeedTracker(cfg.gnss.rmc_timeout_s, cfg.gnss.stale_s)
        self.command = _Command(start=True, fan_rpm=float(cfg.machine.fan_rpm))
        self.command_data: bytes | None = None  # the last PcCommand decoded (most repeat it)
        self.period_us = round(cfg.can.command_period_s * 1e6)
        self.last_cmd_us: int | None = None
        self.gnss_seq = 0
        self.fix_us = 0  # replay time of the last sentence that gave a new speed

    def _event_t(self, now_us: int) -> float:
        """The events' clock at replay time `now_us` (the cuts read so far reach past it)."""
        t = self.t0 + now_us / 1e6
        cuts = self.clock.cuts
        i = bisect.bisect_right(cuts, t, key=lambda c: c[0]) - 1
        return t + cuts[max(i, 0)][1]

    def run(self, events: Iterable[Event]) -> Iterator[ReplayRow]:
        # Each period: the ECU steps on the counters of that instant, then the terminal takes
        # the inputs that arrived by then and sends its command, which the ECU acts on from
        # its next step (the order of a port's main loop and of the simulator).
        ecu = self.ecu
        step, discard = ecu.step_raw, ecu.tx_discard
        updates = ecu.wheel_updates
        wheel = self.wheel.walker()
        # One event ahead: its time on the replay clock is read (and a pause before it cut)
        # before the steps reach it.
        ahead = iter(events)
        clock, t0 = self.clock, self.t0
        nxt = next(ahead, None)
        next_due = _us(clock.take(nxt.t), t0) if nxt is not None else 0
        end_us = self.end_us
        now_us = 0
        steps = 0
        while now_us <= end_us:
            step(now_us, wheel(now_us), 0, 0, 0, 0)
            discard()  # the ECU's frames are not needed here; keep its queue free
            steps += 1
            # The whole state (a dataclass of 30 fields) only at a speed update, every 50 steps
            if ecu.wheel_updates != updates:
                state = ecu.state
                updates = state.wheel_updates
                yield _row(self._event_t(now_us), state)
            new_fix = False
            while nxt is not None and next_due <= now_us:
                if self._take(nxt):
                    new_fix = True
                    self.fix_us = next_due
                nxt = next(ahead, None)
                if nxt is not None:
                    next_due = _us(clock.take(nxt.t), t0)
            if new_fix:
                self._send_gnss_time(now_us)
            due = self.last_cmd_us is None or now_us - self.last_cmd_us >= self.period_us
            if due or (new_fix and self.cfg.can.send_on_gnss):
                self._send_command(now_us)
            now_us += STEP_US
        self.stats.steps += steps
        self.stats.lag_learned_ms = self.ecu.state.lag_learned_ms

    def _take(self, e: Event) -> bool:
        """Apply one event; True when it gave a new GNSS speed sample."""
        if isinstance(e, NmeaEvent):
            fix = self.decoder.decode(e.nmea)
            if not fix.ok:
                self.stats.nmea_rejected += 1
            return self.tracker.update(e.t, fix) is not None
        if (
            isinstance(e, CanEvent)
            and e.dir != "rx"
            and e.can_id == self.ids.command
            and e.data != self.command_data
            and _take_command(self.command, e, self.ids, self.stats)
        ):
            self.command_data = e.data
        return False

    def _send_gnss_time(self, now_us: int) -> None:
        gnss = _forwardable(self.tracker.current(self._event_t(now_us)))
        self.gnss_seq = (self.gnss_seq + 1) & 0xFF
        age_ms = min(round((now_us - self.fix_us) / 1000), 10000)
        msg = protocol.encode_gnss_time(gnss, age_ms, self.gnss_seq, ids=self.ids)
        if self.ecu.rx(msg, now_us) < 0:
            self.stats.ecu_rx_refused += 1
        self.stats.gnss_times += 1

    def _send_command(self, now_us: int) -> None:
        c = self.command
        gnss = _forwardable(self.tracker.current(self._event_t(now_us)))
        msg = protocol.encode_command(
            c.start, c.fan_rpm, c.rate_upper_kg_ha, c.rate_lower_kg_ha, gnss, ids=self.ids
        )
        if self.ecu.rx(msg, now_us) < 0:
            self.stats.ecu_rx_refused += 1
        self.stats.commands += 1
        self.last_cmd_us = now_us


def _row(t: float, state: EcuState) -> ReplayRow:
    return ReplayRow(
        t=t,
        v_wheel_kmh=state.v_wheel_kmh,
        v_gnss_kmh=state.v_gnss_kmh if state.gnss_valid else None,
        v_kmh=state.v_kmh,
        source=str(state.source),
        cv_pct=state.cv_pct,
    )


def _forwardable(kmh: float | None) -> float | None:
    # As the terminal's CAN link: PcCommand carries 0..25 km/h, a faster reading is sent as 25.
    return None if kmh is None else min(max(kmh, 0.0), GNSS_MAX_KMH)


def _take_command(
    command: _Command, e: CanEvent, ids: protocol.FrameIds, stats: ReplayStats
) -> bool:
    """Keep the command's start flag, fan speed and rates; False when it did not decode."""
    try:
        decoded = protocol.decode((e.can_id, e.data), ids)
    except ProtocolError as exc:
        stats.bad_commands += 1
        _log.warning("recorded PcCommand at t=%r not decoded: %s", e.t, exc)
        return False
    assert isinstance(decoded, protocol.PcCommand)
    command.start = decoded.start
    command.fan_rpm = decoded.fan_rpm
    command.rate_upper_kg_ha = decoded.rate_upper_kg_ha
    command.rate_lower_kg_ha = decoded.rate_lower_kg_ha
    return True


def _fmt(value: float | None) -> str:
    return "" if value is None else f"{value:.3f}"


def write_csv(rows: Iterable[ReplayRow], out: TextIO) -> int:
    """Columns t,v_wheel_kmh,v_gnss_kmh,v_kmh,source,cv_pct; empty = not available. Returns
    how many rows were written (they may come as they are made)."""
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(COLUMNS)
    n = 0
    for r in rows:
        n += 1
        writer.writerow(
            (
                f"{r.t:.3f}",
                _fmt(r.v_wheel_kmh),
                _fmt(r.v_gnss_kmh),
                _fmt(r.v_kmh),
                r.source,
                _fmt(r.cv_pct),
            )
        )
    return n
