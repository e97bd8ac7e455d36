"""The docs name only constants the code has: an upper-case name in backticks in docs/*.md is
defined somewhere in the C or Python sources (a renamed or removed constant leaves a stale
explanation behind)."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCES = [
    *ROOT.glob("ecu/**/*.[ch]"),
    *ROOT.glob("src/topdress/**/*.py"),
    *ROOT.glob("src/topdress/**/*.c"),
    *ROOT.glob("bench/*.py"),
    *ROOT.glob("scripts/*"),
    *ROOT.glob("protocol/*.dbc"),
    ROOT / "Makefile",
    *ROOT.glob("ecu/**/*.mk"),
]


def test_every_constant_a_doc_names_exists() -> None:
    code = "\n".join(
        p.read_text(encoding="utf-8", errors="replace") for p in SOURCES if p.is_file()
    )
    words = set(re.findall(r"\b[A-Z][A-Z0-9_]+\b", code))
    missing = []
    for doc in sorted((ROOT / "docs").glob("*.md")):
        for name in sorted(
            set(re.findall(r"`([A-Z][A-Z0-9]*_[A-Z0-9_]+)`", doc.read_text("utf-8")))
        ):
            if name not in words:
                missing.append(f"{doc.name}: {name}")
    assert not missing, "constants the code no longer has:\n" + "\n".join(missing)
