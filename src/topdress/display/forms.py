"""A form over one section of the configuration: its keys as the file names them.

Values are shown as the configuration in force holds them and read back with their types;
a refused value (ConfigError, or an error the terminal returns for a dotted key) is shown at
its field. The checks are the configuration's own (`topdress.config_edit`), never a copy.
"""

from __future__ import annotations

import json
import tomllib
from collections.abc import Callable, Iterable, Mapping
from typing import Any

import tomlkit
from nicegui import ui

from topdress.i18n import tr
from topdress.i18n.catalogue import CATALOGUE

#: Units from a key's suffix, as the configuration names its keys.
_UNITS = (
    ("_kg_ha", "unit.kgha"),
    ("_kmh", "unit.kmh"),
    ("_rpm", "unit.rpm"),
    ("_pct", "unit.pct"),
    ("_ms", "unit.ms"),
    ("_s", "unit.s"),
    ("_m", "unit.m"),
)

Widget = ui.input | ui.number | ui.switch | ui.select | ui.textarea


def unit_of(key: str) -> str:
    name = key.rsplit(".", 1)[-1]
    for suffix, unit in _UNITS:
        if name.endswith(suffix):
            return tr(unit)
    return ""


def label_of(key: str) -> str:
    """The key in words (from the catalogue where it has them) with its unit."""
    words = tr(f"key.{key}") if f"key.{key}" in CATALOGUE else key.rsplit(".", 1)[-1]
    unit = unit_of(key)
    return f"{words} ({unit})" if unit else words


def value_name(value: Any) -> str:
    """A setting's value in words where the catalogue names it (`linear`, `paper`), else as
    the file writes it (a port, a number)."""
    key = f"value.{value}"
    return tr(key) if isinstance(value, str) and key in CATALOGUE else str(value)


class SectionForm:
    """Inputs for `values` (a section as `settings.section_values` gives it)."""

    def __init__(
        self,
        section: str,
        values: Mapping[str, Any],
        keys: Iterable[str] | None = None,
        choices: Mapping[str, list[Any] | dict[Any, str]] | None = None,
        free_choice: Iterable[str] = (),
        on_change: Callable[[], None] | None = None,
        tables_as_text: Iterable[str] = (),
    ) -> None:
        self.section = section
        self.widgets: dict[str, Widget] = {}
        self._types: dict[str, type] = {}
        self._choices = choices or {}
        self._free = set(free_choice)
        # Tables of free names (the CAN adapter's options): `name = value` lines, TOML-typed.
        self._text_tables = set(tables_as_text)
        self._on_change = on_change
        with ui.grid(columns=2).classes("gap-x-4 gap-y-1 items-start w-full"):
            for key in keys if keys is not None else values:
                self._add(key, _get(values, key))

    def _add(self, key: str, value: Any) -> None:
        if key in self._text_tables:
            self._add_text_table(key, value)
            return
        if isinstance(value, Mapping):
            for sub, v in value.items():
                self._add(f"{key}.{sub}", v)
            return
        dotted = f"{self.section}.{key}"
        label = label_of(dotted)
        hook = self._on_change
        changed = (lambda _e: hook()) if hook is not None else None
        widget: Widget
        if key in self._choices:
            options = self._choices[key]
            if isinstance(options, list) and value not in options:
                options = [value, *options]
            if isinstance(options, list) and key not in self._free:
                options = {v: value_name(v) for v in options}  # the value by name
            widget = ui.select(
                options,
                value=value,
                label=label,
                new_value_mode="add-unique" if key in self._free else None,
                on_change=changed,
            )
        elif isinstance(value, bool):
            widget = ui.switch(label, value=value, on_change=changed)
        elif isinstance(value, int | float):
            widget = ui.number(label, value=value, on_change=changed)
            if isinstance(value, int):
                widget.props("step=1")
        elif isinstance(value, list):
            widget = ui.input(label, value=json.dumps(value), on_change=changed)
        else:
            widget = ui.input(label, value="" if value is None else str(value), on_change=changed)
        widget.classes("w-full").props("dense").mark(f"field_{dotted}")
        self.widgets[key] = widget
        self._types[key] = type(value)

    def _add_text_table(self, key: str, value: Mapping[str, Any]) -> None:
        dotted = f"{self.section}.{key}"
        hook = self._on_change
        widget = ui.textarea(
            label_of(dotted),
            value=tomlkit.dumps(dict(value)),
            on_change=(lambda _e: hook()) if hook is not None else None,
        )
        widget.classes("w-full font-mono").props("dense autogrow").mark(f"field_{dotted}")
        self.widgets[key] = widget
        self._types[key] = dict

    def text_errors(self) -> dict[str, str]:
        """Tables typed as text that are not `name = value` lines (dotted key -> reason)."""
        out: dict[str, str] = {}
        for key in self._text_tables & self.widgets.keys():
            try:
                tomllib.loads(str(self.widgets[key].value or ""))
            except tomllib.TOMLDecodeError as exc:
                out[f"{self.section}.{key}"] = f"not name = value lines: {exc}"
        return out

    def values(self) -> dict[str, Any]:
        """What the form holds, nested as the file nests it, each value in its key's type; a
        text that is not one (a number field left empty) is passed as it is, for the checks
        to name."""
        out: dict[str, Any] = {}
        for key, widget in self.widgets.items():
            raw = widget.value
            kind = self._types[key]
            value: Any = raw
            if kind is int and isinstance(raw, float) and raw.is_integer():
                value = int(raw)
            elif kind is list and isinstance(raw, str):
                try:
                    value = json.loads(raw)
                except ValueError:
                    value = raw
            elif kind is dict:
                try:
                    value = tomllib.loads(str(raw or ""))
                except tomllib.TOMLDecodeError:
                    value = raw  # text_errors() says why
            _put(out, key, value)
        return out

    def show_errors(self, errors: Mapping[str, str]) -> None:
        """Mark each field with its reason (dotted keys of this section); clear the others."""
        prefix = f"{self.section}."
        for key, widget in self.widgets.items():
            reason = errors.get(prefix + key)
            if reason is None and key in self._text_tables:  # a name inside the table
                inner = prefix + key + "."
                named = [
                    f"{k.removeprefix(inner)}: {r}"
                    for k, r in errors.items()
                    if k.startswith(inner)
                ]
                reason = "; ".join(named) or None
            widget.props.set_bool("error", reason is not None)
            widget.props.set_optional("error-message", reason)


def _get(values: Mapping[str, Any], dotted: str) -> Any:
    node: Any = values
    for part in dotted.split("."):
        node = node[part]
    return node


def _put(out: dict[str, Any], dotted: str, value: Any) -> None:
    *parents, last = dotted.split(".")
    node = out
    for part in parents:
        node = node.setdefault(part, {})
    node[last] = value
