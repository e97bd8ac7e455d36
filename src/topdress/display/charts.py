"""ECharts options for the live charts (last minute): speeds with the source, metering speeds."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from topdress.display.units import Units
from topdress.i18n import tr
from topdress.protocol.model import Source
from topdress.view.snapshot import Snapshot

#: Every n-th snapshot of the history is charted (2.5 Hz of the loop's 10): over a minute the
#: curves look the same, and the page update (and the browser's redraw) is a quarter as large.
CHART_EVERY = 4

SOURCE_COLOURS = {"gnss": "#1565c0", "wheel": "#ef6c00", "none": "#9e9e9e", "fused": "#6a1b9a"}


@dataclass(frozen=True)
class Ink:
    """A chart's colours on its card: words (4.5:1 or more), axis lines and curves (3:1)."""

    text: str
    axis: str
    split: str
    sources: Mapping[str, str]
    selected: str
    meters: tuple[str, str, str, str]  # target upper, lower; measured upper, lower


DAY = Ink(
    "#333333", "#616161", "#e0e0e0", SOURCE_COLOURS, "#2e7d32",
    ("#90caf9", "#ffcc80", "#1565c0", "#ef6c00"),
)  # fmt: skip
# ECharts' own grey words are 3:1 on the night card (#1d1d1d), its dark curves 2.6:1
NIGHT = Ink(
    "#e0e0e0", "#bdbdbd", "#3a3a3a",
    {"gnss": "#64b5f6", "wheel": "#ffb74d", "none": "#9e9e9e", "fused": "#ce93d8"}, "#81c784",
    ("#90caf9", "#ffcc80", "#42a5f5", "#ffa726"),
)  # fmt: skip

# the sources a band is drawn for: a sensor (or both) feeds the speed
_SENSED = frozenset(str(s) for s in Source if s is not Source.NONE)


def _series(name: str, points: list[list[float | None]], colour: str) -> dict[str, Any]:
    return {
        "name": name,
        "type": "line",
        "showSymbol": False,
        "animation": False,
        "data": points,
        "lineStyle": {"color": colour},
        "itemStyle": {"color": colour},
        "connectNulls": False,
    }


def _axes(y_name: str, t_start: float, t_end: float, window_s: float, ink: Ink) -> dict[str, Any]:
    words = {"color": ink.text}
    lines = {
        "axisLine": {"lineStyle": {"color": ink.axis}},
        "axisTick": {"lineStyle": {"color": ink.axis}},
        "splitLine": {"lineStyle": {"color": ink.split}},
        "nameTextStyle": words,
    }
    return {
        "animation": False,
        "textStyle": words,
        "grid": {"left": 50, "right": 24, "top": 40, "bottom": 28},
        "legend": {"top": 0, "left": 60, "textStyle": words},
        "tooltip": {"trigger": "axis"},
        "xAxis": {
            "type": "value",
            "min": round(max(t_start, t_end - window_s), 1),
            "max": round(t_end, 1),
            "name": tr("unit.s"),
            "axisLabel": {"formatter": "{value}", **words},
            **lines,
        },
        "yAxis": {
            "type": "value",
            "name": y_name,
            "min": 0,
            "nameLocation": "middle",
            "nameGap": 32,
            "axisLabel": words,
            **lines,
        },
    }


def sampled(history: list[Snapshot]) -> list[Snapshot]:
    """Every CHART_EVERY-th snapshot, ending with the latest."""
    return history[(len(history) - 1) % CHART_EVERY :: CHART_EVERY] if history else []


def speed_options(
    history: list[Snapshot],
    window_s: float = 60.0,
    units: Units | None = None,
    night: bool = False,
) -> dict[str, Any]:
    """Wheel, GNSS and selected speed (km/h, or mph in imperial `units`) against time, with
    bands naming the source the ECU metered on; in the night colours when `night`."""
    u = units or Units()
    ink = NIGHT if night else DAY
    history = sampled(history)
    t_end = history[-1].t_s if history else 0.0
    wheel, gnss, selected, marks = [], [], [], []
    for s in history:
        t = round(s.t_s, 2)
        wheel.append([t, round(u.speed(s.v_wheel_kmh), 2) if s.ecu_live else None])
        gnss.append([t, None if s.gnss_kmh is None else round(u.speed(s.gnss_kmh), 2)])
        selected.append([t, round(u.speed(s.v_kmh), 2) if s.ecu_live else None])
        marks.append(s.source if s.ecu_live else "none")
    opts = _axes(u.speed_unit, history[0].t_s if history else 0.0, t_end, window_s, ink)
    sel = _series(tr("chart.selected"), selected, ink.selected)
    # Bands under the selected speed say which source drove it.
    sel["markArea"] = {"silent": True, "data": _source_bands(history, marks, ink)}
    sel["lineStyle"] = {"color": ink.selected, "width": 3}
    opts["series"] = [
        _series(tr("chart.wheel"), wheel, ink.sources["wheel"]),
        _series(tr("chart.gnss"), gnss, ink.sources["gnss"]),
        sel,
    ]
    return opts


def _source_bands(
    history: list[Snapshot], marks: list[str], ink: Ink
) -> list[list[dict[str, Any]]]:
    bands: list[list[dict[str, Any]]] = []
    start = 0
    for i in range(1, len(marks) + 1):
        if i == len(marks) or marks[i] != marks[start]:
            src = marks[start]
            if src in _SENSED:
                bands.append(
                    [
                        {
                            "xAxis": round(history[start].t_s, 2),
                            "name": tr(f"source.{src}"),
                            "itemStyle": {"color": ink.sources[src], "opacity": 0.08},
                            "label": {"position": "insideTop", "color": ink.sources[src]},
                        },
                        {"xAxis": round(history[i - 1].t_s, 2)},
                    ]
                )
            start = i
    return bands


def meter_options(
    history: list[Snapshot], window_s: float = 60.0, night: bool = False
) -> dict[str, Any]:
    """Target and measured metering speed (r/min) of each layer against time."""
    ink = NIGHT if night else DAY
    history = sampled(history)
    t_end = history[-1].t_s if history else 0.0
    cols: list[list[list[float | None]]] = [[], [], [], []]
    for s in history:
        t = round(s.t_s, 2)
        values = (*s.target_rpm, *s.meter_rpm)
        for col, v in zip(cols, values, strict=True):
            col.append([t, round(v, 2) if s.ecu_live else None])
    opts = _axes(tr("unit.rpm"), history[0].t_s if history else 0.0, t_end, window_s, ink)
    names = ("chart.target_upper", "chart.target_lower", "chart.meter_upper", "chart.meter_lower")
    opts["series"] = [
        _series(tr(n), col, colour) for n, col, colour in zip(names, cols, ink.meters, strict=True)
    ]
    for series in opts["series"][:2]:
        series["lineStyle"]["type"] = "dashed"
    return opts
