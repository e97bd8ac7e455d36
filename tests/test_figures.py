"""Figures cannot go stale: `make bench` writes them to bench/figures.json and docs/figures.md
(bench/figures.py), and no other document repeats one by hand. A doc that wants a figure
links to docs/figures.md; targets, and figures of code that no longer exists (the "before" of
a change), may stand in the text."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [
    *(p for p in (ROOT / "docs").glob("*.md") if p.name != "figures.md"),
    ROOT / "README.md",
    *ROOT.glob("ecu/**/README.md"),
]


def _figures_module():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location("bench_figures", ROOT / "bench" / "figures.py")
    assert spec and spec.loader
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


FIGURES = _figures_module()


def _figures() -> dict[str, str]:
    store = FIGURES.load()
    return {k: v["value"] for entry in store.values() for k, v in entry["figures"].items()}


def _spellings(value: str) -> list[str]:
    """16236 is also written 16,236."""
    whole, _, frac = value.partition(".")
    if whole.isdigit() and len(whole) > 3:
        grouped = f"{int(whole):,}" + (f".{frac}" if frac else "")
        return [value, grouped]
    return [value]


def _distinctive(name: str, value: str) -> bool:
    """Sizes in bytes and instruction counts are exact: one of four or more digits is not written
    by chance, so it is a copy wherever it stands. Any other figure varies from run to run and is
    a copy when it stands beside its name."""
    digits = re.sub(r"\D", "", value).lstrip("0")
    exact = name.endswith("_bytes") or name.startswith("instructions_")
    return exact and len(digits) >= 4


def _found(spelling: str, text: str) -> bool:
    return re.search(rf"(?<![\d.,]){re.escape(spelling)}(?![\d]|[.,]\d)", text) is not None


def test_the_figures_file_was_written_by_make_bench() -> None:
    figures = _figures()
    assert "instructions_per_step" in figures and "fw_flash_bytes" in figures


def test_docs_figures_md_is_what_the_store_renders() -> None:
    assert (ROOT / "docs" / "figures.md").read_text(encoding="utf-8") == FIGURES.render(
        FIGURES.load()
    )


def test_no_doc_repeats_a_bench_figure_by_hand() -> None:
    copies: list[str] = []
    for name, value in _figures().items():
        for doc in DOCS:
            text = doc.read_text(encoding="utf-8")
            for n, line in enumerate(text.splitlines(), 1):
                near = name in line
                if any(_found(s, line) for s in _spellings(value)) and (
                    near or _distinctive(name, value)
                ):
                    copies.append(f"{doc.relative_to(ROOT)}:{n}: {name} = {value}")
    assert not copies, "figures copied by hand (link to docs/figures.md):\n" + "\n".join(copies)


def test_the_check_finds_a_copied_figure() -> None:
    assert _found("16,236", "text 16,236 B, 148 B left")
    assert not _found("16,236", "text 116,2361 B")
    assert _spellings("27384") == ["27384", "27,384"]
    assert _distinctive("td_app_t_bytes", "1704")
    assert not _distinctive("sim_realtime_ratio", "1013")


def test_a_figure_printed_twice_is_refused() -> None:
    figures, _ = FIGURES.parse(["can_a_s (one): 1.0", "can_b_s: 2"])
    assert figures == {
        "can_a_s": {"value": "1.0", "note": ""},
        "can_b_s": {"value": "2", "note": ""},
    }
    with pytest.raises(SystemExit, match="can_a_s is printed twice"):
        FIGURES.parse(["can_a_s (one): 1.0", "can_a_s (two): 2.0"])
