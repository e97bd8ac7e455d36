"""What the operator does: start, stop, pause, a manual rate; the commands that carry it.

Commands are frozen dataclasses posted to the terminal (`Terminal.post(command)` returns a
`concurrent.futures.Future[CommandResult]`); the control loop alone acts on them, so a display
or a console thread never touches the loop's state. `Operator` holds the run state and the
manual mode and turns the model's rates into the ones commanded.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from topdress.errors import TopdressError
from topdress.i18n import Text, text

#: Run states: the meters stopped (stop in every PcCommand), running, paused (start with zero
#: rates: the fans keep turning, the meters stand), or a calibration wizard at work.
STOPPED, RUNNING, PAUSED, CALIBRATING = "stopped", "running", "paused", "calibrating"
MANUAL_MODES = ("off", "fixed", "percent")
LAYERS = ("upper", "lower")
MAX_RATE_KG_HA = 600.0  # what PcCommand carries per layer
PERCENT_RANGE = (-100.0, 200.0)


class OperatorError(TopdressError):
    """A command that cannot be carried out now (the reason is the message: a Text, or the
    console's typed-command help, which stays in the words typed)."""

    def __init__(self, message: Text | str) -> None:
        super().__init__(message)
        self.text = message


# ---- commands ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Start:
    """Meters on (from paused: resume)."""


@dataclass(frozen=True)
class Stop:
    """Meters and fans off; always accepted, also ends a calibration."""


@dataclass(frozen=True)
class Pause:
    """Meters to zero, fans kept turning."""


@dataclass(frozen=True)
class SetManual:
    """`off`: the NDVI model; `fixed`: kg/ha per layer; `percent`: the model's rate +/- %."""

    mode: str
    upper_kg_ha: float = 0.0
    lower_kg_ha: float = 0.0
    percent: float = 0.0


@dataclass(frozen=True)
class AckAlarm:
    """Acknowledge one alarm by name, or every alarm (None)."""

    name: str | None = None


@dataclass(frozen=True)
class ResetCounter:
    which: str  # field | season


@dataclass(frozen=True)
class UndoReset:
    """Put back the counter as it was before its last reset (what was counted since is kept)."""

    which: str  # field | season


@dataclass(frozen=True)
class FillTank:
    """The product now in the tank (kg) and the level (kg) below which it is an alarm."""

    fill_kg: float
    alarm_kg: float = 0.0


@dataclass(frozen=True)
class StartCatchTest:
    layer: str  # upper | lower
    revolutions: float = 20.0
    meter_rpm: float = 20.0


@dataclass(frozen=True)
class FinishCatchTest:
    weighed_kg: float


@dataclass(frozen=True)
class StartWheelCal:
    distance_m: float = 40.0


@dataclass(frozen=True)
class FinishWheelCal:
    """End of the run; `distance_m` the distance measured on the ground if it differs from the
    one given at the start (the machine stopped short of the mark)."""

    distance_m: float | None = None


@dataclass(frozen=True)
class StartFanCheck:
    seconds: float | None = None  # None: operator.fan_check_s


@dataclass(frozen=True)
class StartLeadCal:
    """Look-ahead calibration (terminal/leadcal.py): meter start to product at the outlet.
    None: the meter speed is the catch test's default, the reaction time `operator`'s."""

    layer: str  # upper | lower
    trials: int = 3
    meter_rpm: float = 20.0
    reaction_ms: float | None = None
    run_s: float = 4.0


@dataclass(frozen=True)
class LeadSeen:
    """The operator saw product come out of the outlet."""


@dataclass(frozen=True)
class CloseCalibration:
    """Leave the wizard; apply=True saves its result (file and ECU) through the settings."""

    apply: bool = False


@dataclass(frozen=True)
class ApplySettings:
    """Validate, save (atomically, previous file kept as .bak) and apply one section."""

    section: str
    values: Mapping[str, Any]
    # The section's version (topdress.config_edit.section_version) the values were edited
    # from; another has been applied since: refused, nothing lost. None: not checked.
    base: str | None = None


@dataclass(frozen=True)
class TestDevice:
    device: str  # gnss | crop | can


@dataclass(frozen=True)
class DisplayState:
    """The operator display as the terminal's end sees it (posted on each change, never by a
    page): `state` starting | ok | down, `pages` the browser pages connected, `why` the reason
    it is down, `restarts` how often its process was started again."""

    state: str
    pages: int = 0
    why: str = ""
    restarts: int = 0


@dataclass(frozen=True)
class DisplayEvent:
    """Something the display reports for the session log (a wrong PIN, a lockout, a restart):
    `kind` one of the log's `display.*` kinds, `detail` plain values."""

    kind: str
    detail: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Help:
    """A typed line that is no command: answered with `text` (printed by the loop's thread)."""

    text: str


@dataclass(frozen=True)
class CommandResult:
    ok: bool
    message: Text | str = ""  # Text: rendered in the operator's language; str: a library's words
    errors: dict[str, str] = field(default_factory=dict)  # dotted key -> reason
    data: Any = None


# ---- state --------------------------------------------------------------------------------
@dataclass(frozen=True)
class ManualView:
    mode: str = "off"
    upper_kg_ha: float = 0.0
    lower_kg_ha: float = 0.0
    percent: float = 0.0

    def describe(self) -> Text:
        if self.mode == "fixed":
            return text("manual.fixed_is", upper=self.upper_kg_ha, lower=self.lower_kg_ha)
        if self.mode == "percent":
            return text("manual.percent_is", percent=self.percent)
        return text("manual.model_is")


def check_manual(cmd: SetManual) -> ManualView:
    """The manual mode a command asks for; OperatorError naming the value that is wrong."""
    if cmd.mode not in MANUAL_MODES:
        raise OperatorError(text("op.error.manual_mode", modes=", ".join(MANUAL_MODES)))
    if cmd.mode == "fixed":
        for name, v in (("upper_kg_ha", cmd.upper_kg_ha), ("lower_kg_ha", cmd.lower_kg_ha)):
            if not 0.0 <= v <= MAX_RATE_KG_HA:
                raise OperatorError(
                    text("op.error.rate_range", name=name, value=v, max=MAX_RATE_KG_HA)
                )
        return ManualView("fixed", float(cmd.upper_kg_ha), float(cmd.lower_kg_ha))
    if cmd.mode == "percent":
        lo, hi = PERCENT_RANGE
        if not lo <= cmd.percent <= hi:
            raise OperatorError(text("op.error.percent_range", value=cmd.percent, lo=lo, hi=hi))
        return ManualView("percent", percent=float(cmd.percent))
    return ManualView()


class Operator:
    """The run state and the manual mode; pure state, no I/O (the terminal logs the events)."""

    def __init__(self, autostart: bool) -> None:
        self.state = RUNNING if autostart else STOPPED
        self.manual = ManualView()

    @property
    def start_bit(self) -> bool:
        """What PcCommand's start says: running and paused both keep the ECU started."""
        return self.state in (RUNNING, PAUSED)

    def start(self) -> Text:
        if self.state == CALIBRATING:
            raise OperatorError(text("op.error.calibrating"))
        was, self.state = self.state, RUNNING
        return text("op.done.resumed" if was == PAUSED else "op.done.started")

    def stop(self) -> Text:
        self.state = STOPPED
        return text("op.done.stopped")

    def pause(self) -> Text:
        if self.state != RUNNING:
            raise OperatorError(text("op.error.pause", state=text(f"op.state.{self.state}")))
        self.state = PAUSED
        return text("op.done.paused")

    def set_manual(self, cmd: SetManual) -> Text:
        self.manual = check_manual(cmd)
        return text("op.done.rate", rate=self.manual.describe())

    def rates(self, model: tuple[float, float]) -> tuple[float, float]:
        """The rates to command per layer from the model's, under pause and manual mode."""
        if self.state != RUNNING:
            return (0.0, 0.0)
        m = self.manual
        if m.mode == "fixed":
            return (m.upper_kg_ha, m.lower_kg_ha)
        if m.mode == "percent":
            k = 1.0 + m.percent / 100.0
            return (min(model[0] * k, MAX_RATE_KG_HA), min(model[1] * k, MAX_RATE_KG_HA))
        return model


# ---- typed commands (the console) -------------------------------------------------------------
CONSOLE_HELP = (
    "commands: start | stop | pause | manual off | manual fixed UPPER LOWER\n"
    "          manual percent P | ack [NAME] | reset field|season | undo field|season\n"
    "          tank KG [ALARM_KG] | test gnss|crop|can\n"
    "          catch upper|lower [REV [RPM]] | weigh KG | wheel [M] | finish [M]\n"
    "          fan [S] | lead upper|lower [TRIALS [RPM]] | seen | close [apply]"
)


def _floats(args: list[str], n_min: int, n_max: int) -> list[float]:
    if not n_min <= len(args) <= n_max:
        raise OperatorError(CONSOLE_HELP)
    try:
        return [float(a) for a in args]
    except ValueError:
        raise OperatorError(f"not a number in {' '.join(args)!r}") from None


def parse_command(text: str) -> Any:
    """A command typed on the console (`CONSOLE_HELP`); OperatorError if it is not one."""
    words = text.split()
    if not words:
        raise OperatorError(CONSOLE_HELP)
    verb, args = words[0].lower(), words[1:]
    simple = {"start": Start, "stop": Stop, "pause": Pause}
    if verb in simple and not args:
        return simple[verb]()
    if verb == "manual" and args:
        mode, rest = args[0], args[1:]
        if mode == "off":
            return SetManual("off")
        if mode == "fixed":
            upper, lower = _floats(rest, 2, 2)
            return SetManual("fixed", upper_kg_ha=upper, lower_kg_ha=lower)
        if mode == "percent":
            return SetManual("percent", percent=_floats(rest, 1, 1)[0])
    if verb == "ack" and len(args) <= 1:
        return AckAlarm(args[0] if args else None)
    if verb == "reset" and len(args) == 1:
        return ResetCounter(args[0])
    if verb == "undo" and len(args) == 1:
        return UndoReset(args[0])
    if verb == "tank":
        return FillTank(*_floats(args, 1, 2))
    if verb == "catch" and args and args[0] in LAYERS:
        nums = _floats(args[1:], 0, 2)
        return StartCatchTest(args[0], *nums)
    if verb == "weigh":
        return FinishCatchTest(_floats(args, 1, 1)[0])
    if verb == "wheel":
        return StartWheelCal(*_floats(args, 0, 1))
    if verb == "finish":
        return FinishWheelCal(*_floats(args, 0, 1))
    if verb == "fan":
        return StartFanCheck(*_floats(args, 0, 1))
    if verb == "lead" and args and args[0] in LAYERS:
        nums = _floats(args[1:], 0, 2)
        if nums and not (nums[0].is_integer() and nums[0] >= 1):
            raise OperatorError(f"trials must be a whole number >= 1, not {args[1]!r}")
        return StartLeadCal(args[0], *[int(nums[0])] if nums else [], *nums[1:])
    if verb == "seen" and not args:
        return LeadSeen()
    if verb == "close" and args in ([], ["apply"]):
        return CloseCalibration(apply=bool(args))
    if verb == "test" and len(args) == 1:
        return TestDevice(args[0])
    raise OperatorError(CONSOLE_HELP)
