"""The one catalogue: both languages for every string, and every string the UI uses exists."""

from __future__ import annotations

import re
import string
from collections.abc import Iterator
from pathlib import Path

import pytest

from topdress import i18n
from topdress.i18n import UnknownLanguage, parse_language, render, set_language, text, tr
from topdress.i18n.catalogue import CATALOGUE

SRC = Path(__file__).resolve().parents[1] / "src" / "topdress"


@pytest.fixture(autouse=True)
def english() -> Iterator[None]:
    set_language("en")
    yield
    set_language("en")


def _fields(text: str) -> set[str]:
    return {name for _, name, _, _ in string.Formatter().parse(text) if name}


def test_every_entry_has_both_languages_with_the_same_placeholders() -> None:
    for key, (en, zh) in CATALOGUE.items():
        assert en.strip() and zh.strip(), key
        assert _fields(en) == _fields(zh), key


def test_chinese_entries_are_translated() -> None:
    # Identical texts are allowed only where the term is the same in both (units, acronyms).
    same = {k for k, (en, zh) in CATALOGUE.items() if en == zh}
    assert all(
        k.startswith("unit.") or re.fullmatch(r"[A-Za-z0-9/ ]+", CATALOGUE[k][0]) for k in same
    )
    assert len(same) < len(CATALOGUE) / 4


def test_every_key_used_in_the_code_is_in_the_catalogue() -> None:
    used: set[str] = set()
    for path in SRC.rglob("*.py"):
        used |= set(
            re.findall(r"""\b(?:tr|text)\(\s*["']([a-z_]+\.[A-Za-z0-9_.]+)["']""", path.read_text())
        )
    assert len(used) > 150, "tr() and text() calls not found"
    missing = sorted(k for k in used if k not in CATALOGUE)
    assert missing == []


def test_the_terminals_messages_are_keyed_with_their_values() -> None:
    why = text(
        "why.gnss",
        cv=text("why.cv", cv=2.514),
        threshold=4.2,
        compare=text("source.wheel"),
        kmh=7.96,
        switch_kmh=6.0,
    )
    # str() is the English of the program log; render() follows the language in force
    assert str(why) == "GNSS: CV 2.51 % < 4.2 %, wheel 8.0 km/h > 6 km/h"
    set_language("zh")
    assert render(why) == "GNSS：变异系数 2.51 % < 4.2 %，地轮 8.0 km/h > 6 km/h"
    assert str(why) == "GNSS: CV 2.51 % < 4.2 %, wheel 8.0 km/h > 6 km/h"  # the log stays English
    assert render(why, "en") == str(why)
    # a library's or the system's own words pass as they are; nothing is empty
    assert render("[Errno 2] No such file") == "[Errno 2] No such file" and render(None) == ""
    assert render(text("event.gnss_lost", why="serial:/dev/ttyUSB0: gone")) == (
        "GNSS 丢失（serial:/dev/ttyUSB0: gone）"
    )
    # values, not sentences: equal messages compare equal (the console prints each once)
    assert text("event.ecu_lost", s=1.0) == text("event.ecu_lost", s=1.0)
    with pytest.raises(KeyError):
        render(text("event.no_such_event"))


def test_keys_built_at_run_time_exist() -> None:
    from topdress.protocol import FAULT_NAMES

    for name in FAULT_NAMES:
        assert f"fault.{name}" in CATALOGUE
    for state in ("ok", "wait", "lost", "no_fix", "silent"):
        assert f"link.{state}" in CATALOGUE
    for source in ("gnss", "wheel", "none"):
        assert f"source.{source}" in CATALOGUE
    # the console's: operator states, alarms and calibrations by their names
    for state in ("stopped", "running", "paused", "calibrating"):
        assert f"op.state.{state}" in CATALOGUE
    for alarm in ("gnss_lost", "crop_lost", "ecu_lost"):
        assert f"alarm.{alarm}" in CATALOGUE
    for kind in ("off_rate", "blocked", "fan_low"):
        assert f"alarm.{kind}_upper" in CATALOGUE and f"alarm.{kind}_lower" in CATALOGUE
    for state in ("active", "acked", "cleared"):
        assert f"alarm.state.{state}" in CATALOGUE
    for cal in ("catch", "wheel", "fan", "step.running", "step.weigh", "step.drive", "step.done"):
        assert f"cal.{cal}" in CATALOGUE
    assert "cal.step.aborted" in CATALOGUE
    # the terminal's messages by their parts
    for layer in ("upper", "lower"):
        assert f"main.{layer}" in CATALOGUE
        for kind in ("off_rate", "blocked", "fan_low"):
            assert f"alarm.text.{kind}_{layer}" in CATALOGUE
    for state in ("ok", "wait", "lost", "no_fix"):  # GNSS states, "no fix" as no_fix
        assert f"link.{state}" in CATALOGUE
    for name in ("resumed", "started", "stopped", "paused"):
        assert f"op.done.{name}" in CATALOGUE
    for end in ("ok", "low"):
        assert f"cal.text.fan_{end}" in CATALOGUE
    for state in ("ok", "silent"):
        assert f"event.crop_{state}" in CATALOGUE
    for which in ("field", "season"):
        assert f"count.{which}" in CATALOGUE


def test_switching_the_language() -> None:
    v = i18n.version()
    assert tr("screen.control") == "Control"
    assert set_language("zh-CN") == "zh"
    assert i18n.version() == v + 1
    assert tr("screen.control") == "控制设置"
    assert tr("screen.control", "en") == "Control"
    assert tr("link.partial", fresh="3/4") == "3/4 有效"
    set_language("zh")  # no change, no redraw
    assert i18n.version() == v + 1


@pytest.mark.parametrize("code", ["fr", "", "english"])
def test_unknown_languages_are_refused(code: str) -> None:
    with pytest.raises(UnknownLanguage, match="en, zh"):
        parse_language(code)
    assert i18n.language() == "en"
