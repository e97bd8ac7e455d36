"""Operator-facing text in English and Simplified Chinese, from one catalogue.

Messages the terminal makes (why a speed source, an event, a calibration step, a command's
answer) are `Text` values: a catalogue key and the values that fill it. The console and the
display render them in the language in force (`render`); `str()` gives the English, for the
program log, the session log and scripts. The catalogue is plain data below the terminal and
the display, so the terminal's domain code can name its messages without any UI code.

The language is one process-wide setting (the display's language menu and the console read the
same one), switchable at run time: `set_language("zh")` bumps `version()`, which a page polls to
redraw its static text.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal, get_args

from topdress.i18n.catalogue import CATALOGUE

Language = Literal["en", "zh"]
LANGUAGES: tuple[Language, ...] = get_args(Language)
#: Each language named in itself, for the language menu.
LANGUAGE_NAMES: Mapping[Language, str] = {"en": "English", "zh": "简体中文"}

_lock = threading.Lock()
_current: Language = "en"
_version = 0


class UnknownLanguage(ValueError):
    """A language the catalogue does not have."""


def language() -> Language:
    """The language in force."""
    return _current


def version() -> int:
    """Bumped at every change of language (pages poll it to redraw)."""
    return _version


def parse_language(code: str) -> Language:
    """`code` as a Language; "zh-CN", "zh_Hans" and the like count as "zh"."""
    base = code.strip().lower().replace("_", "-").split("-")[0]
    for lang in LANGUAGES:
        if base == lang:
            return lang
    raise UnknownLanguage(f"unknown language {code!r}: one of {', '.join(LANGUAGES)}")


def set_language(code: str) -> Language:
    """Switch every page and the console to `code`; returns the language now in force."""
    global _current, _version
    lang = parse_language(code)
    with _lock:
        if lang != _current:
            _current = lang
            _version += 1
    return lang


def tr(key: str, lang: Language | None = None, **values: object) -> str:
    """The text of `key` in `lang` (default: the language in force), `{name}`s filled in.

    An unknown key is a programming error (KeyError); the catalogue test checks every key used
    in the display and console exists in both languages.
    """
    entry = CATALOGUE[key]
    text = entry[LANGUAGES.index(lang or _current)]
    return text.format(**values) if values else text


@dataclass(frozen=True, slots=True)
class Text:
    """A message as a catalogue key and its values (numbers, names, nested Texts); the values
    are formatted by the catalogue's `{name:spec}` so each language places them its own way."""

    key: str
    values: tuple[tuple[str, Any], ...] = ()

    def __str__(self) -> str:
        return render(self, "en")


def text(key: str, **values: Any) -> Text:
    """`Text(key, values)`; an unknown key fails when rendered (the catalogue test finds them)."""
    return Text(key, tuple(values.items()))


#: A value named by its SI unit (`kg`, `switch_kmh`, ...) whose template writes the unit as
#: `{NAME_unit}` is a quantity: the display may give it in other units (display/units.py);
#: otherwise `render` writes the SI unit's word here. The longest suffix is tried first.
SI_UNITS: Mapping[str, str] = {"kg_ha": "unit.kgha", "kmh": "unit.kmh", "kg": "unit.kg"}


def si_unit(name: str) -> str | None:
    """The SI unit a value's name ends in (`kg_ha`, `kmh`, `kg`), or None."""
    for unit in SI_UNITS:
        if name == unit or name.endswith("_" + unit):
            return unit
    return None


def quantities(message: Text) -> list[str]:
    """The values of `message` its template shows with their unit word (`{NAME_unit}`)."""
    template = "".join(CATALOGUE[message.key])
    return [k for k, _ in message.values if si_unit(k) and "{" + k + "_unit}" in template]


def render(message: Text | str | None, lang: Language | None = None) -> str:
    """A message in `lang` (default: the language in force); a plain string (a library's or the
    operating system's own words) as it is, None as empty."""
    if message is None:
        return ""
    if isinstance(message, str):
        return message
    values = {k: render(v, lang) if isinstance(v, Text) else v for k, v in message.values}
    for k in quantities(message):
        values.setdefault(k + "_unit", tr(SI_UNITS[si_unit(k) or ""], lang))
    return tr(message.key, lang, **values)


__all__ = [
    "LANGUAGES",
    "LANGUAGE_NAMES",
    "SI_UNITS",
    "Language",
    "Text",
    "UnknownLanguage",
    "language",
    "parse_language",
    "quantities",
    "render",
    "set_language",
    "si_unit",
    "text",
    "tr",
    "version",
]
