"""Operator-facing text in English and Simplified Chinese, from one catalogue.

The language is one process-wide setting (the display's language menu and the console read the
same one), switchable at run time: `set_language("zh")` bumps `version()`, which a page polls to
redraw its static text.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from typing import Literal, get_args

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


__all__ = [
    "LANGUAGES",
    "LANGUAGE_NAMES",
    "Language",
    "UnknownLanguage",
    "language",
    "parse_language",
    "set_language",
    "tr",
    "version",
]
