"""Live status of the terminal in a console: plain ANSI on a TTY, a line per second otherwise.

No curses: on a TTY the block of lines is redrawn in place (cursor up, clear line); when stdout is
a pipe or a file, one compact line is printed per `line_period_s` so a log stays readable.

The block speaks the operator's language (topdress.i18n, the display's setting; each redraw reads
it, so a switch shows at the next one) and is measured in terminal columns, where a Chinese
character takes two. The compact line is for logs and scripts: its `key=value` words stay English.
"""

from __future__ import annotations

import unicodedata
from typing import TextIO

from topdress.i18n import Text, render, tr
from topdress.protocol import fault_names
from topdress.view.commands import ManualView
from topdress.view.links import fault_texts, link_text
from topdress.view.snapshot import AlarmView, Snapshot


def _num(value: float | None, fmt: str) -> str:
    return "--" if value is None else format(value, fmt)


def _col(value: float | None, fmt: str) -> str:
    """The value formatted, or "--" as wide, so the columns of the block stay put."""
    return _num(value, fmt).rjust(len(format(0.0, fmt)))


#: Every line of the block fits an 80-column screen (a cab PC's text console).
WIDTH = 80


def _cols(ch: str) -> int:
    # A Chinese character takes two columns of a terminal.
    return 2 if unicodedata.east_asian_width(ch) in "WF" else 1


def width(text: str) -> int:
    """Terminal columns `text` takes (wide East Asian characters count two)."""
    return sum(_cols(ch) for ch in text)


def _pad(text: str, cols: int) -> str:
    """`text` padded with spaces to `cols` columns (ljust by columns, not characters)."""
    return text + " " * (cols - width(text))


def _fit(line: str, cols: int = WIDTH) -> str:
    """`line` cut to `cols` columns, with "..." where it was cut."""
    if width(line) <= cols:
        return line
    used, out = 3, []
    for ch in line:
        if used + _cols(ch) > cols:
            break
        used += _cols(ch)
        out.append(ch)
    return "".join(out) + "..."


def _wrap(head: str, items: list[str], cols: int = WIDTH) -> list[str]:
    """`head` then the items, as many per line as fit; continuation lines indented."""
    lines, line, fresh = [], head, True
    indent = " " * min(width(head), cols // 2)
    for item in items:
        if not fresh and width(line) + width(item) + 2 > cols:
            lines.append(line)
            line, fresh = indent, True
        line += "  " + item
        fresh = False
    lines.append(line)
    return [_fit(x, cols) for x in lines]


def _label(key: str) -> str:
    """A label of the block from the catalogue, padded so the values after it line up."""
    return _pad(tr(key), max(8, width(tr(key)) + 1))


def _head(key: str) -> str:
    """A label before wrapped items (which start two columns after it)."""
    return _pad(tr(key), 6)


def _ecu_link(s: Snapshot) -> str:
    # While waiting, where it listens: the first thing to check when the ECU never answers.
    waiting = s.ecu_link == "wait" and s.ecu_where
    return f"{link_text('wait')} ({s.ecu_where})" if waiting else link_text(s.ecu_link)


def _hm(seconds: float) -> str:
    m = int(seconds // 60)
    return f"{m // 60}h{m % 60:02d}"


def _manual(m: ManualView) -> str:
    if m.mode == "fixed":
        return tr(
            "manual.shown_fixed",
            upper=f"{m.upper_kg_ha:.1f}",
            lower=f"{m.lower_kg_ha:.1f}",
            unit=tr("unit.kgha"),
        )
    if m.mode == "percent":
        return tr("manual.shown_percent", percent=f"{m.percent:+.0f}")
    return tr("manual.off")


def _alarm(a: AlarmView) -> str:
    state = "" if a.state == "active" else f" ({tr(f'alarm.state.{a.state}')})"
    return tr(f"alarm.{a.name}") + state


def _source_lines(s: Snapshot) -> list[str]:
    """Why the ECU meters on its source, and the GNSS lag it uses ("GNSS lag 0.95 s (learned)",
    while the ECU says) after it, or on a line of its own when both do not fit."""
    source = f"{_label('main.source')}{render(s.speed_why) or '--'}"
    if not s.ecu_live or s.gnss_lag is None:
        return [source]
    lag = render(s.gnss_lag.text())
    if width(source) + 2 + width(lag) <= WIDTH:
        return [f"{source}  {lag}"]
    return [source, f"{' ' * width(_label('main.source'))}{lag}"]


def _operator_lines(s: Snapshot) -> list[str]:
    lines = [
        f"{_label('con.operator')}{_pad(tr(f'op.state.{s.operator}'), 16)}"
        f"  {tr('con.rate')} {_manual(s.manual)}",
        *_source_lines(s),
    ]
    if s.alarms:
        lines += _wrap(_head("con.alarms"), [_alarm(a) for a in s.alarms])
    else:
        lines.append(f"{_label('con.alarms')}{tr('alarm.none')}")
    f, z = s.count_field, s.count_season
    lines.append(
        f"{_label('count.field')}{f.area_ha:7.3f} ha {f.kg[0]:7.1f} /{f.kg[1]:7.1f} kg"
        f" {_hm(f.work_s)}   {tr('count.season')} {z.area_ha:7.2f} ha"
        f" {z.kg[0] + z.kg[1]:7.0f} kg {_hm(z.work_s)}"
    )
    if s.calibration is not None:
        c = s.calibration
        lines.append(
            f"{_label('con.calib')}{tr(f'cal.{c.kind}')} {tr(f'cal.step.{c.step}')}"
            f" {c.progress * 100:3.0f} %: {render(c.text)}"
        )
    return lines


def _status(s: Snapshot, running: str) -> str:
    """The first line: time, links, run state; in columns while they fit, else packed (the
    program's name left out) so the run state at the end stays on the screen."""
    links = (
        (tr("link_name.ecu"), _ecu_link(s), 5),
        ("GNSS", link_text(s.gnss_link), 7),
        (tr("con.crop"), link_text(s.crop_link), 6),
    )
    for packed in (False, True):
        line = f"{'' if packed else 'topdress '}{s.t_s:7.1f} {tr('unit.s')}"
        for name, state, cols in links:
            line += f"  {name} {state if packed else _pad(state, cols)}"
        line += f"  {running}"
        if width(line) <= WIDTH:
            break
    return line


def render_lines(s: Snapshot) -> list[str]:
    """The full status block in the language in force (topdress.i18n), each line at most WIDTH
    terminal columns. The ECU's values are "--" while it is not heard."""
    live = s.ecu_live

    def col(value: float, fmt: str) -> str:
        return _col(value if live else None, fmt)

    faults = (fault_texts(s.faults) or [tr("fault.none")]) if live else ["--"]
    uniform = tr("con.uniform" if s.uniform else "con.varying") if live else "--"
    running = tr("op.state.running" if s.running else "op.state.stopped") if live else "--"
    source = tr(f"source.{s.source}") if live else "--"
    head = [
        _status(s, running),
        f"{_label('con.speed')}{col(s.v_kmh, '5.2f')} km/h {tr('con.from')} {_pad(source, 5)}"
        f" {tr('main.wheel')} {col(s.v_wheel_kmh, '5.2f')}"
        f"  GNSS {_col(s.gnss_kmh, '5.2f')} km/h  CV {_col(s.cv_pct if live else None, '.2f')} %"
        f" ({uniform})",
        f"NDVI    {tr('con.sensors')} {_col(s.ndvi_sensors, '.3f')}"
        f"  {tr('con.at_meters')} {_col(s.ndvi, '.3f')}"
        f"   {tr('con.rate')} {tr('main.upper')} {s.rate_kg_ha[0]:6.1f}"
        f"  {tr('main.lower')} {s.rate_kg_ha[1]:6.1f} kg/ha",
        f"{_label('con.meters')}{tr('main.target')} {col(s.target_rpm[0], '6.2f')}"
        f" / {col(s.target_rpm[1], '6.2f')} r/min"
        f"   {tr('con.actual')} {col(s.meter_rpm[0], '6.2f')}"
        f" / {col(s.meter_rpm[1], '6.2f')} r/min",
    ]
    fans = _wrap(
        f"{_label('main.fans')}{col(s.fan_rpm[0], '5.0f')} / {col(s.fan_rpm[1], '5.0f')} rpm"
        f"   {tr('main.faults')}:",
        faults,
    )
    counts = _wrap(_head("con.counts"), [f"{k} {v}" for k, v in s.counters.items()])
    last = [f"{_label('con.last')}{render(s.last_event) or '-'}"]
    return [_fit(x) for x in head + fans + _operator_lines(s) + counts + last]


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
        f" ecu={_ecu_where(s)} gnss={s.gnss_link} crop={s.crop_link}"
        f" op={s.operator} rate={s.manual.mode} alarms={len(s.alarms)} lag={_lag_word(s)}"
    )


def _lag_word(s: Snapshot) -> str:
    lag = s.gnss_lag
    if not s.ecu_live or lag is None:
        return "--"
    return f"{lag.in_use_ms / 1000:.2f}s/{lag.state}"


def _ecu_where(s: Snapshot) -> str:
    return f"wait({s.ecu_where})" if s.ecu_link == "wait" and s.ecu_where else s.ecu_link


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

    def message(self, message: Text | str) -> None:
        """A line that stays (an event): printed above the live block, in the language in
        force."""
        text = render(message)
        if self._tty and self._drawn:
            self._stream.write(f"\x1b[{self._drawn}F\x1b[J")
            self._drawn = 0
        self._stream.write(text + "\n")
        self._stream.flush()
