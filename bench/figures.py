"""The figures of `make bench` in one generated place: `python bench/figures.py SCRIPT` passes a
bench script's standard output through unchanged and records it in bench/figures.json, then
writes docs/figures.md from that file. Other docs link to docs/figures.md instead of copying
numbers, so a figure cannot go stale in one place while it is fresh in another
(tests/test_figures.py checks that no doc repeats one by hand).

A line `snake_name: number  (note)` is a figure; any other line (the tables some scripts print) is
kept as the script's text."""

from __future__ import annotations

import datetime as dt
import json
import os
import platform
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STORE = ROOT / "bench" / "figures.json"
DOC = ROOT / "docs" / "figures.md"
FIGURE = re.compile(r"^([a-z][a-z0-9]*_[a-z0-9_]+)(?: \([^)]*\))?: (-?[\d.]+)\s*(.*)$")


def parse(lines: list[str]) -> tuple[dict[str, dict[str, str]], list[str]]:
    figures: dict[str, dict[str, str]] = {}
    text: list[str] = []
    for line in lines:
        m = FIGURE.match(line)
        if m:
            if m.group(1) in figures:  # the second would hide the first in the table
                raise SystemExit(f"figures.py: the figure {m.group(1)} is printed twice")
            figures[m.group(1)] = {"value": m.group(2), "note": m.group(3).strip()}
        elif line.strip():
            text.append(line)
    return figures, text


def load() -> dict[str, dict[str, object]]:
    if STORE.exists():
        data: dict[str, dict[str, object]] = json.loads(STORE.read_text(encoding="utf-8"))
        return data
    return {}


def render(store: dict[str, dict[str, object]]) -> str:
    out = [
        "# Figures of the last `make bench`",
        "",
        "Written by `bench/figures.py` from `bench/figures.json` each time `make bench` runs:",
        "never edit it by hand. What each figure means and its target: [benchmarks.md]"
        "(benchmarks.md).",
    ]
    for script in sorted(store):
        entry = store[script]
        out += ["", f"## `bench/{script}`", "", f"Run {entry['when']} on {entry['machine']}.", ""]
        figures = entry["figures"]
        assert isinstance(figures, dict)
        if figures:
            out += ["| figure | value | note |", "|---|---|---|"]
            out += [f"| `{k}` | {v['value']} | {v['note']} |" for k, v in figures.items()]
        text = entry["text"]
        assert isinstance(text, list)
        if text:
            out += ["", *text]
    return "\n".join(out) + "\n"


def main() -> int:
    script = sys.argv[1]
    lines: list[str] = []
    for line in sys.stdin:
        sys.stdout.write(line)
        lines.append(line.rstrip("\n"))
    figures, text = parse(lines)
    store = load()
    store[script] = {
        "when": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": f"{platform.machine()}, {len(os.sched_getaffinity(0))} cores",
        "figures": figures,
        "text": text,
    }
    STORE.write_text(json.dumps(store, indent=1) + "\n", encoding="utf-8")
    DOC.write_text(render(load()), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
