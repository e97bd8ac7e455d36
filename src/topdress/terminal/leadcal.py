"""Look-ahead calibration on the machine: from the meter's start to product at the outlet.

The look-ahead (docs/speed.md) needs two times of the real machine: `lookahead.meter_ms`, the
meter's response (command to the meter turning at half its set speed), and
`lookahead.airline_ms`, the product's way from the meter to the outlet (the drop, the air line).
The simulator knows both; a machine is measured, standing, with this wizard:

1. Standing, the fans run at their working speed (a start command with zero rates: the machine
   stands, so the ECU meters nothing), and once they are above the ECU's minimum the ECU turns
   one layer's meter for `run_s` seconds (PcCalCommand action 2, the look-ahead test, td_cal.c).
   The terminal sends the command and timestamps it.
2. The ECU's EcuCalStatus (every status period) carries the revolutions the meter has turned
   since the test began (0.001 rev, counted on its encoder: a position, not a filtered speed).
   Once the meter runs steadily at R r/min, it is behind a meter that had jumped to R at the
   command by exactly its effective delay: meter time = (t - t_cmd) - revolutions(t) / R, with
   R from the last two reports. That is the delay of the product's flow out of the meter, the
   number the look-ahead needs, whatever the shape of the meter's rise.
3. The operator, at the outlet, presses "seen" when product comes out (a helper with a radio,
   or the operator watching a transparent outlet hose). The press minus the operator's
   reaction time (`operator.reaction_ms`, 200 ms by default; 0 with a flow sensor or a video)
   minus the moment the meter started turning (the last report before any revolution, or the
   command) -> the air-line time: the fall, the line, every granule delayed alike.
4. After `trials` runs (a pause between them, so the line empties) the medians are proposed;
   closing with apply saves both keys (file and ECU) through the settings, nothing else.

A trial whose press comes before the meter turned, or not within `SEEN_WINDOW_S`, is refused
and repeated: it says nothing about the machine. The start of the meter's turn is known only
to the report period (100 ms): it is taken as the last report with no revolution (or the
command), so the air-line time reads long by up to the time the meter takes to start; the
median of several trials is the answer (docs/speed.md, "Look-ahead").
"""

from __future__ import annotations

import statistics
from dataclasses import dataclass

import can

from topdress import protocol
from topdress.i18n import text
from topdress.protocol import FrameIds
from topdress.terminal.calibration import (
    CAL_ANSWER_S,
    LAYER_INDEX,
    CalCommand,
    CalibrationError,
    CalInputs,
)
from topdress.view.snapshot import CalibrationView

STEADY_S = 0.4  # the meter delay is read from reports at least this long after the command
PAUSE_S = 3.0  # between trials: the air line empties
SEEN_WINDOW_S = 10.0  # a press later than this after the command is no measurement
MAX_TRIALS = 10
LEAD_TEST = 2  # PcCalCommand.CalAction: the meter run with the fans of a started machine


@dataclass(frozen=True)
class LeadTrial:
    meter_s: float  # command -> meter at half its set speed
    airline_s: float  # meter at half speed -> product at the outlet (reaction removed)


def trial(
    t_cmd: float,
    reports: list[tuple[float, float]],
    t_seen: float,
    reaction_s: float,
    need_steady: bool = True,
) -> LeadTrial:
    """One trial's two times from the command time, the (arrival time, revolutions) reports
    of the meter under test, and the press; CalibrationError when they cannot give them
    (`need_steady` False: check the press only, the meter time is 0)."""
    seen = t_seen - reaction_s
    if t_seen - t_cmd > SEEN_WINDOW_S:
        raise CalibrationError(text("lead.error.late", s=t_seen - t_cmd))
    turning = [(t, rev) for t, rev in reports if rev > 0.0]
    if not turning:
        raise CalibrationError(text("lead.error.not_turned"))
    still = [t for t, rev in reports if rev <= 0.0 and t < turning[0][0]]
    t_start = max([t_cmd, *still])
    if seen <= t_start:
        raise CalibrationError(text("lead.error.early"))
    if not need_steady:
        return LeadTrial(meter_s=0.0, airline_s=seen - t_start)
    steady = [(t, rev) for t, rev in turning if t - t_cmd >= STEADY_S]
    if len(steady) < 2:
        raise CalibrationError(text("lead.error.short"))
    (t0, rev0), (t1, rev1) = steady[-2], steady[-1]
    rev_per_s = (rev1 - rev0) / (t1 - t0)
    if not rev_per_s > 0.0:
        raise CalibrationError(text("lead.error.unsteady"))
    return LeadTrial(meter_s=(t1 - t_cmd) - rev1 / rev_per_s, airline_s=seen - t_start)


class LeadCal:
    """Meter start to product at the outlet, `trials` times; proposes lookahead.meter_ms and
    lookahead.airline_ms (the medians)."""

    kind = "lead"
    key = "lookahead"  # the section: both of its times (`values()`)

    def __init__(
        self,
        layer: str,
        meter_rpm: float,
        trials: int,
        reaction_ms: float,
        run_s: float,
        fan_rpm: float,
        fan_min_rpm: float,
        seq: int,
        ids: FrameIds,
    ) -> None:
        if layer not in LAYER_INDEX:
            raise CalibrationError(text("cal.error.layer", layer=layer))
        if not 1 <= trials <= MAX_TRIALS:
            raise CalibrationError(text("lead.error.trials", max=MAX_TRIALS, trials=trials))
        if not 0.0 <= reaction_ms <= 1000.0:
            raise CalibrationError(text("lead.error.reaction", ms=reaction_ms))
        if not 1.0 <= run_s <= 30.0:
            raise CalibrationError(text("lead.error.run", s=run_s))
        self.layer = layer
        self.command = CalCommand(start=True, fan_rpm=fan_rpm)  # fans on, rates 0
        self.fan_min_rpm = fan_min_rpm
        self._fans_up = False
        self.meter_rpm = meter_rpm
        self.trials = trials
        self.reaction_s = reaction_ms / 1000.0
        self.revolutions = meter_rpm / 60.0 * run_s
        self.ids = ids
        self.seq = seq % 256
        # Range-checked before anything is sent (ProtocolError naming the signal).
        self._msg(1)
        self.done: list[LeadTrial] = []
        self.result: dict[str, float] = {}
        self.step = "running"
        self.text = text("cal.step.running")
        self._begin(None)

    # ---- one trial --------------------------------------------------------------------------
    def _msg(self, mode: int) -> can.Message:
        layer = LAYER_INDEX[self.layer]
        rev, rpm = (self.revolutions, self.meter_rpm) if mode else (0.0, 0.0)
        mode = LEAD_TEST if mode else 0
        return protocol.encode_cal_command(mode, layer, rev, rpm, self.seq, ids=self.ids)

    def _begin(self, now: float | None) -> None:
        self._t_cmd: float | None = None
        self._tries = 0
        self._answered = False
        self._reports: list[tuple[float, float]] = []
        self._t_seen: float | None = None
        self._pause_until = now
        n = len(self.done) + 1
        self.text = text(
            "lead.text.trial",
            n=n,
            trials=self.trials,
            layer=text(f"main.{self.layer}"),
            rpm=self.meter_rpm,
        )

    def tick(self, now: float, x: CalInputs) -> list[can.Message]:
        if self.step != "running":
            return []
        if not x.ecu_live:
            self.step, self.text = "aborted", text("lead.text.no_ecu")
            self.command = CalCommand()
            return []
        if not self._fans_up:
            if x.fan_rpm[LAYER_INDEX[self.layer]] < self.fan_min_rpm:
                self.text = text("lead.text.fans", rpm=x.fan_rpm[LAYER_INDEX[self.layer]])
                return []
            self._fans_up = True
            self._begin(None)
        if self._pause_until is not None:
            if now < self._pause_until:
                return []
            self._pause_until = None
            self.seq = (self.seq + 1) % 256  # a new test at the ECU
        out: list[can.Message] = []
        st = x.cal_status
        if st is not None and st.seq == self.seq and st.state != "idle":
            self._answered = True
            if st.state == "aborted":
                self.step = "aborted"
                self.command = CalCommand()
                self.text = text("lead.text.aborted", reason=st.reason)
                return []
            t_st = x.cal_t if x.cal_t is not None else now
            new = not self._reports or t_st > self._reports[-1][0]
            if new and st.state == "running":  # the coast after the run is no steady turn
                self._reports.append((t_st, st.revolutions))
        if not self._answered:
            if self._t_cmd is None or now - self._t_cmd >= CAL_ANSWER_S - 1e-9:
                if self._tries >= 3:
                    self.step = "aborted"
                    self.command = CalCommand()
                    self.text = text("cal.text.no_answer")
                    return []
                self._tries += 1
                self._t_cmd = now  # a retry: the first was lost, the clock starts again
                out.append(self._msg(1))
        elif self._t_seen is not None:
            stop = self._end_trial(now)
            if stop is not None:
                return stop
        if self._t_seen is None and self._t_cmd is not None and now - self._t_cmd > SEEN_WINDOW_S:
            self.text = text("lead.text.no_press", s=SEEN_WINDOW_S)
            out.append(self._msg(0))
            self._begin(now + PAUSE_S)
        return out

    def seen(self, now: float) -> None:
        """The operator saw product at the outlet. The trial ends once the meter has run
        steadily long enough to time it (`tick`); a press that cannot be a sighting is refused."""
        if self.step != "running" or self._t_cmd is None or self._pause_until is not None:
            raise CalibrationError(text("lead.error.no_trial"))
        if self._t_seen is not None:
            raise CalibrationError(text("lead.error.already"))
        trial(self._t_cmd, self._reports, now, self.reaction_s, need_steady=False)
        self._t_seen = now
        self.text = text("lead.text.seen")

    def _end_trial(self, now: float) -> list[can.Message] | None:
        assert self._t_cmd is not None and self._t_seen is not None
        try:
            result = trial(self._t_cmd, self._reports, self._t_seen, self.reaction_s)
        except CalibrationError:
            return None  # not yet enough steady reports
        self.done.append(result)
        if len(self.done) >= self.trials:
            self._conclude()
        else:
            self._begin(now + PAUSE_S)
        return [self._msg(0)]

    def _conclude(self) -> None:
        meter = [t.meter_s * 1000.0 for t in self.done]
        air = [t.airline_s * 1000.0 for t in self.done]
        self.result = {
            "meter_ms": statistics.median(meter),
            "airline_ms": statistics.median(air),
            "meter_spread_ms": max(meter) - min(meter),
            "airline_spread_ms": max(air) - min(air),
            "trials": float(len(self.done)),
        }
        self.step = "done"
        self.command = CalCommand()  # fans off again
        r = self.result
        self.text = text(
            "lead.text.done",
            meter=r["meter_ms"],
            meter_spread=r["meter_spread_ms"],
            air=r["airline_ms"],
            air_spread=r["airline_spread_ms"],
            trials=len(self.done),
        )

    def close(self) -> list[can.Message]:
        return [self._msg(0)]

    def view(self) -> CalibrationView:
        progress = len(self.done) / self.trials
        return CalibrationView(
            self.kind, self.step, self.text, progress, dict(self.result), self.key
        )

    def value(self) -> float | None:
        return self.result.get("meter_ms")

    def values(self) -> dict[str, int]:
        """Both keys' values once done (whole ms, as the configuration and the ECU take them)."""
        if self.step != "done":
            return {}
        return {
            "meter_ms": round(self.result["meter_ms"]),
            "airline_ms": round(self.result["airline_ms"]),
        }
