"""Alarms the operator acknowledges: off-rate, blocked meter, fan low, an input lost, a
map the machine is far outside of (the wrong field).

Each alarm follows the usual annunciator sequence: it comes `active` (unacknowledged); the
operator acknowledges it (`acked`, still active); when its condition ends it leaves the list if
acknowledged, or stays as `cleared` until acknowledged, so a short fault is never missed. The
conditions come from the terminal's own state and the ECU's fault word, evaluated every tick.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from topdress.i18n import Text, text
from topdress.protocol import Fault
from topdress.terminal.site import OffMap
from topdress.view.links import link_state
from topdress.view.snapshot import AlarmView

ACTIVE, ACKED, CLEARED = "active", "acked", "cleared"
#: Metering speed targets below this are not judged off-rate (a meter just starting or stopping).
MIN_TARGET_RPM = 1.0
#: A link not ok with the meters on is an alarm once it lasts this long (one starting up, or
#: a sensor missing one line, gets this long first).
LINK_GRACE_S = 3.0


@dataclass(frozen=True)
class AlarmInputs:
    """What the alarms are judged on, from one tick."""

    metering: bool  # the operator has the meters running and the ECU is live
    target_rpm: tuple[float, float]
    meter_rpm: tuple[float, float]
    faults: int
    gnss_link: str
    crop_link: str
    ecu_link: str
    ecu_protocol: tuple[str, str] | None = None  # (the ECU's, the terminal's) when they differ
    # The session log's health (topdress.log.session.LogHealth): a log that cannot be
    # written is an alarm, not only a line on the console
    log_health: str = "ok"
    log_free_mb: float = 0.0
    log_min_free_mb: float = 0.0
    log_error: str = ""
    # The maps the outlet is farther outside of than their limit (topdress.terminal.site)
    off_map: tuple[OffMap, ...] = ()
    display_down: bool = False  # the display process is not serving (terminal/surface.py)
    display_lost: bool = False  # the operator has had no display for display.lost_pause_s
    # The operator has the meters on (running or paused), whatever the ECU answers: a link
    # that is not ok then is an alarm, not only a lost one.
    operating: bool = False
    tank_low: Text | None = None  # the tank below its alarm level (the text with its figures)
    position_lost: bool = False  # the outlet dead reckoned past its limit (site.UNKNOWN)
    # An ISOBUS implement (None: the topdress ECU): its link's state (terminal.tclink: ok,
    # lost, refused, wait), its DDOP's designator and the last problem in words
    isobus: tuple[str, str, Text | str] | None = None
    ecu_refused: Text | None = None  # a parameter the ECU on an ISOBUS refused (the text)


@dataclass
class _Alarm:
    text: Text
    since_s: float
    active: bool = True
    acked: bool = False


_LAYERS = ("upper", "lower")
_BLOCKED = (Fault.UPPER_BLOCKED, Fault.LOWER_BLOCKED)
_FAN_LOW = (Fault.UPPER_FAN_LOW, Fault.LOWER_FAN_LOW)


class AlarmBook:
    """The alarms of one run. `update` once per tick; returns the new alarms (name, text)."""

    def __init__(self, off_rate_pct: float, off_rate_s: float) -> None:
        self.off_rate_pct = off_rate_pct
        self.off_rate_s = off_rate_s
        self._alarms: dict[str, _Alarm] = {}
        self._off_since: list[float | None] = [None, None]
        self._link_since: dict[str, float] = {}

    def retune(self, off_rate_pct: float, off_rate_s: float) -> None:
        """A changed [operator] section: the off-rate limits taken at the next tick."""
        self.off_rate_pct = off_rate_pct
        self.off_rate_s = off_rate_s

    def update(self, t_s: float, x: AlarmInputs) -> list[tuple[str, Text]]:
        conditions = dict(self._conditions(t_s, x))
        new: list[tuple[str, Text]] = []
        for name, what in conditions.items():
            a = self._alarms.get(name)
            if a is None or not a.active:
                self._alarms[name] = _Alarm(what, t_s)
                new.append((name, what))
        for name, a in list(self._alarms.items()):
            if a.active and name not in conditions:
                a.active = False
                if a.acked:
                    del self._alarms[name]
        return new

    def _conditions(self, t_s: float, x: AlarmInputs) -> Iterator[tuple[str, Text]]:
        for i, layer in enumerate(_LAYERS):
            if self._off_rate(i, t_s, x):
                yield (
                    f"off_rate_{layer}",
                    text(
                        f"alarm.text.off_rate_{layer}",
                        rpm=x.meter_rpm[i],
                        target=x.target_rpm[i],
                        pct=self.off_rate_pct,
                        s=self.off_rate_s,
                    ),
                )
            if x.faults & _BLOCKED[i]:
                yield f"blocked_{layer}", text(f"alarm.text.blocked_{layer}")
            if x.faults & _FAN_LOW[i]:
                yield f"fan_low_{layer}", text(f"alarm.text.fan_low_{layer}")
        if x.gnss_link == "lost":
            yield "gnss_lost", text("alarm.gnss_lost")
        if x.crop_link in ("lost", "silent"):
            yield "crop_lost", text("alarm.text.crop_lost", state=link_state(x.crop_link))
        if x.isobus is not None:
            state, device, problem = x.isobus
            if state == "lost":  # the implement's own alarm, in place of the ECU's
                yield "implement_lost", text("alarm.text.implement_lost", device=device)
            elif state == "refused":
                yield "ddop_refused", text("alarm.text.ddop_refused", why=problem)
        elif x.ecu_link == "lost":
            yield "ecu_lost", text("alarm.ecu_lost")
        if x.ecu_refused is not None:
            yield "ecu_param_refused", x.ecu_refused
        if x.metering:  # the wrong field matters only while product goes out
            for o in x.off_map:
                yield (
                    f"wrong_field_{o.which}",
                    text(
                        f"alarm.text.wrong_field_{o.which}",
                        file=o.name,
                        distance_m=round(o.distance_m),
                        limit_m=o.limit_m,
                    ),
                )
        if x.ecu_protocol is not None:
            ecu, terminal = x.ecu_protocol
            yield "ecu_protocol", text("alarm.text.ecu_protocol", ecu=ecu, terminal=terminal)
        if x.log_health == "low_space":
            free, margin = x.log_free_mb, x.log_min_free_mb
            yield "log_low_space", text("alarm.text.log_low_space", free_mb=free, min_mb=margin)
        elif x.log_health == "disk_full":
            yield "log_disk_full", text("alarm.text.log_disk_full")
        elif x.log_health == "write_failing":
            yield "log_write_failing", text("alarm.text.log_write_failing", error=x.log_error)
        if x.display_down:
            yield "display_down", text("alarm.display_down")
        if x.display_lost:
            yield "display_lost", text("alarm.display_lost")
        # Waiting (a CAN channel changed), no fix, sensors partly fresh: with the meters on,
        # never silent once it lasts LINK_GRACE_S (a link starting up gets that long).
        for kind, state, lost in (
            ("ecu", x.ecu_link, ("lost",)),
            ("gnss", x.gnss_link, ("lost",)),
            ("crop", x.crop_link, ("lost", "silent")),
        ):
            bad = x.operating and state != "ok" and state not in lost
            since = self._link_since.get(kind)
            if not bad:
                self._link_since.pop(kind, None)
            elif since is None:
                self._link_since[kind] = t_s
            elif t_s - since >= LINK_GRACE_S - 1e-9:
                yield (
                    f"{kind}_link",
                    text(
                        "alarm.text.link",
                        link=text(f"link_name.{kind}"),
                        state=link_state(state),
                    ),
                )
        if x.tank_low is not None:
            yield "tank_low", x.tank_low
        if x.position_lost and x.operating:
            yield "position_unknown", text("alarm.position_unknown")

    def _off_rate(self, i: int, t_s: float, x: AlarmInputs) -> bool:
        target = x.target_rpm[i]
        off = (
            x.metering
            and target >= MIN_TARGET_RPM
            and abs(x.meter_rpm[i] - target) * 100.0 > self.off_rate_pct * target
        )
        if not off:
            self._off_since[i] = None
            return False
        since = self._off_since[i]
        if since is None:
            self._off_since[i] = t_s
            return False
        return t_s - since > self.off_rate_s - 1e-9

    def ack(self, name: str | None) -> list[str]:
        """Acknowledge one alarm (or all); returns the names of those acknowledged now."""
        names = list(self._alarms) if name is None else [name] if name in self._alarms else []
        acked = []
        for key in names:
            a = self._alarms[key]
            if a.acked:
                continue
            acked.append(key)
            a.acked = True
            if not a.active:
                del self._alarms[key]
        return acked

    def known(self, name: str) -> bool:
        return name in self._alarms

    def views(self) -> tuple[AlarmView, ...]:
        out = []
        for name, a in self._alarms.items():
            state = (ACKED if a.acked else ACTIVE) if a.active else CLEARED
            out.append(AlarmView(name, a.text, state, a.since_s))
        return tuple(out)
