"""The fast tier stays fast: a test module that drives Chromium or QEMU carries the mark that
keeps it out of `make check` (pyproject.toml declares the marks)."""

from __future__ import annotations

from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
NEEDS = {"missing_browser(": "pytest.mark.browser", "qemu_missing(": "pytest.mark.qemu"}


@pytest.mark.parametrize("probe", sorted(NEEDS))
def test_modules_that_need_a_browser_or_qemu_are_marked(probe: str) -> None:
    mods = [p for p in TESTS.glob("test_*.py") if p.name != Path(__file__).name]
    users = [p for p in mods if probe in p.read_text(encoding="utf-8")]
    assert users, probe
    unmarked = [p.name for p in users if NEEDS[probe] not in p.read_text(encoding="utf-8")]
    assert not unmarked, f"{NEEDS[probe]} missing in {unmarked}"
