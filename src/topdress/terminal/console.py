"""Live status of the terminal in a console: plain ANSI on a TTY, a line per second otherwise.

No curses: on a TTY the block of lines is redrawn in place (cursor up, clear line); when stdout is
a pipe or a file, one compact line is printed per `line_period_s` so a log stays readable.
"""

from __future__ import annotations

from typing import TextIO

from topdress.terminal.app import Snapshot

#: Fault word bits of the ECU (ecu/include/td_common.h).
FAULT_NAMES = (
    "CMD_TIMEOUT",
    "GNSS_LOST",
    "WHEEL_ENCODER",
    "UPPER_BLOCKED",
    "LOWER_BLOCKED",
    "UPPER_FAN_LOW",
    "LOWER_FAN_LOW",
    "NO_SPEED",
    "GNSS_FROZEN",
)


def fault_names(word: int) -> list[str]:
    """Names of the bits set in an ECU fault word (unknown bits as BITn)."""
    names = [name for bit, name in enumerate(FAULT_NAMES) if word & (1 << bit)]
    names += [f"BIT{bit}" for bit in range(len(FAULT_NAMES), 16) if word & (1 << bit)]
    return names


def _num(value: float | None, fmt: str) -> str:
    return "--" if value is None else format(value, fmt)


def _col(value: float | None, fmt: str) -> str:
    """The value formatted, or "--" as wide, so the columns of the block stay put."""
    return _num(value, fmt).rjust(len(format(0.0, fmt)))


def _ecu_link(s: Snapshot, space: str = " ") -> str:
    # While waiting, where it listens: the first thing to check when the ECU never answers.
    waiting = s.ecu_link == "wait" and s.ecu_where
    return f"wait{space}({s.ecu_where})" if waiting else s.ecu_link


#: Every line of the block fits an 80-column screen (a cab PC's text console).
WIDTH = 80


def _fit(line: str, width: int = WIDTH) -> str:
    return line if len(line) <= width else line[: width - 3] + "..."


def _wrap(head: str, items: list[str], width: int = WIDTH) -> list[str]:
    """`head` then the items, as many per line as fit; continuation lines indented."""
    lines, line, fresh = [], head, True
    for item in items:
        if not fresh and len(line) + len(item) + 2 > width:
            lines.append(line)
            line, fresh = " " * len(head), True
        line += "  " + item
        fresh = False
    lines.append(line)
    return [_fit(x, width) for x in lines]


def _hm(seconds: float) -> str:
    m = int(seconds // 60)
    return f"{m // 60}h{m % 60:02d}"


def _operator_lines(s: Snapshot) -> list[str]:
    lines = [
        f"operator {s.operator:<11}  rate {s.manual.describe()}",
        f"source  {s.speed_why}",
    ]
    if s.alarms:
        lines += _wrap(
            "alarms",
            [a.name + ("" if a.state == "active" else f" ({a.state})") for a in s.alarms],
        )
    else:
        lines.append("alarms  none")
    f, z = s.count_field, s.count_season
    lines.append(
        f"field   {f.area_ha:7.3f} ha {f.kg[0]:7.1f} /{f.kg[1]:7.1f} kg {_hm(f.work_s)}"
        f"   season {z.area_ha:7.2f} ha {z.kg[0] + z.kg[1]:7.0f} kg {_hm(z.work_s)}"
    )
    if s.calibration is not None:
        c = s.calibration
        lines.append(f"calib   {c.kind} {c.step} {c.progress * 100:3.0f} %: {c.text}")
    return lines


def render_lines(s: Snapshot) -> list[str]:
    """The full status block, each line at most WIDTH columns. The ECU's values are "--"
    while it is not heard."""
    live = s.ecu_live

    def col(value: float, fmt: str) -> str:
        return _col(value if live else None, fmt)

    faults = (", ".join(fault_names(s.faults)) or "none") if live else "--"
    uniform = ("uniform" if s.uniform else "varying") if live else "--"
    running = ("RUNNING" if s.running else "stopped") if live else "--"
    head = [
        f"topdress {s.t_s:7.1f} s  ECU {_ecu_link(s):<5}  GNSS {s.gnss_link:<7}"
        f"  CROP {s.crop_link:<6}  {running}",
        f"speed   {col(s.v_kmh, '5.2f')} km/h from {s.source if live else '--':<5}"
        f" wheel {col(s.v_wheel_kmh, '5.2f')}"
        f"  GNSS {_col(s.v_gnss_kmh, '5.2f')} km/h  CV {_col(s.cv_pct if live else None, '.2f')} %"
        f" ({uniform})",
        f"NDVI    sensors {_col(s.ndvi_sensors, '.3f')}  at meters {_col(s.ndvi, '.3f')}"
        f"   rate upper {s.rate_kg_ha[0]:6.1f}  lower {s.rate_kg_ha[1]:6.1f} kg/ha",
        f"meters  target {col(s.target_rpm[0], '6.2f')} / {col(s.target_rpm[1], '6.2f')} r/min"
        f"   actual {col(s.meter_rpm[0], '6.2f')} / {col(s.meter_rpm[1], '6.2f')} r/min",
        f"fans    {col(s.fan_rpm[0], '5.0f')} / {col(s.fan_rpm[1], '5.0f')} rpm   faults: {faults}",
    ]
    counts = _wrap("counts", [f"{k} {v}" for k, v in s.counters.items()])
    last = [f"last    {s.last_event or '-'}"]
    return [_fit(x) for x in head + _operator_lines(s)] + counts + [_fit(x) for x in last]


def render_line(s: Snapshot) -> str:
    """One compact line, for a log or a pipe. The ECU's values are "--" while it is not heard."""
    live = s.ecu_live

    def num(value: float | None, fmt: str) -> str:
        return _num(value if live else None, fmt)

    faults = (",".join(fault_names(s.faults)) or "-") if live else "--"
    return (
        f"t={s.t_s:.1f}s v={num(s.v_kmh, '.2f')}km/h src={s.source if live else '--'}"
        f" cv={num(s.cv_pct, '.2f')}%"
        f" ndvi={_num(s.ndvi, '.3f')} rate={s.rate_kg_ha[0]:.1f}/{s.rate_kg_ha[1]:.1f}kg/ha"
        f" target={num(s.target_rpm[0], '.2f')}/{num(s.target_rpm[1], '.2f')}"
        f" meter={num(s.meter_rpm[0], '.2f')}/{num(s.meter_rpm[1], '.2f')}r/min"
        f" fan={num(s.fan_rpm[0], '.0f')}/{num(s.fan_rpm[1], '.0f')}rpm faults={faults}"
        f" ecu={_ecu_link(s, space='')} gnss={s.gnss_link} crop={s.crop_link}"
        f" op={s.operator} rate={s.manual.mode} alarms={len(s.alarms)}"
    )


class Console:
    """Draws snapshots at most every `period_s` (TTY) or `line_period_s` (not a TTY)."""

    def __init__(
        self,
        stream: TextIO,
        tty: bool | None = None,
        period_s: float = 0.3,
        line_period_s: float = 1.0,
    ) -> None:
        self._stream = stream
        self._tty = stream.isatty() if tty is None else tty
        self._period_s = period_s if self._tty else line_period_s
        self._last_t: float | None = None
        self._drawn = 0

    def update(self, snapshot: Snapshot, now: float) -> bool:
        """Draw if due; returns whether it drew."""
        if self._last_t is not None and now < self._last_t + self._period_s - 1e-3:
            return False
        # On a grid, so a 10 Hz caller gets exactly one line per second, not one per 1.1 s.
        last = self._last_t
        self._last_t = (
            now if last is None or now - last > 2 * self._period_s else last + self._period_s
        )
        self.draw(snapshot)
        return True

    def draw(self, snapshot: Snapshot) -> None:
        if not self._tty:
            self._stream.write(render_line(snapshot) + "\n")
        else:
            lines = render_lines(snapshot)
            # Back to the first line of the previous block, then overwrite each line.
            up = f"\x1b[{self._drawn}F" if self._drawn else ""
            self._stream.write(up + "".join(f"\x1b[2K{line}\n" for line in lines))
            self._drawn = len(lines)
        self._stream.flush()

    def message(self, text: str) -> None:
        """A line that stays (an event): printed above the live block."""
        if self._tty and self._drawn:
            self._stream.write(f"\x1b[{self._drawn}F\x1b[J")
            self._drawn = 0
        self._stream.write(text + "\n")
        self._stream.flush()
