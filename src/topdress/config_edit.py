"""Settings changed while the terminal runs: checked as the file is, saved, then applied.

- `validate_section(cfg, section, values)` puts the changed values into the configuration and
  runs the very checks of `load_config` (ConfigError names the dotted key);
- `save_section(path, section, values)` writes only those values into the file with tomlkit,
  so the user's comments and layout stay, atomically (temporary file, then rename), the
  previous file kept as `FILE.bak`;
- applying (reopening a port or the CAN bus, pushing ECU parameters) is the terminal's, on its
  own loop (`ApplySettings`, see topdress.view.commands).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import tomlkit

from topdress.config import TerminalConfig, config_from_dict, read_config_text
from topdress.errors import ConfigError
from topdress.outpath import atomic_write

SECTIONS = tuple(f.name for f in dataclasses.fields(TerminalConfig))
#: What applying a changed section takes, beyond the file.
#: The keys a device is opened with: a change reopens it, and a failure to open is shown at the
#: keys changed (the old device stays).
DEVICE_KEYS: dict[str, tuple[str, ...]] = {
    "gnss": ("source", "port", "baud", "path", "replay_interval_s"),
    "crop": ("source", "port", "baud", "path", "replay_interval_s"),
    "can": ("interface", "channel", "bitrate", "options"),
}
#: Tables a form gives whole: a name left out of the new values is removed from the table.
WHOLE_TABLES = ("ids", "options")
# pushed to the ECU (meters stopped); [lookahead]'s meter and air-line times are ECU parameters
ECU_SECTIONS = ("machine", "speed", "ecu", "lookahead")
LIVE_SECTIONS = ("rate", "operator")  # taken at once by the loop
# saved; in force at the next start ([isobus] also with a new CAN bus: the TC link is made anew)
RESTART_SECTIONS = ("log", "display", "isobus")


def _plain(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    return value


def section_values(cfg: TerminalConfig, section: str) -> dict[str, Any]:
    """The values of one section as the TOML file writes them (nested tables as dicts)."""
    if section not in SECTIONS:
        raise ConfigError(section, f"no such section (known: {', '.join(SECTIONS)})")
    sec = getattr(cfg, section)
    if section == "ecu":
        return dict(sec.overrides)
    out: dict[str, Any] = {}
    for f in dataclasses.fields(sec):
        value = getattr(sec, f.name)
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            value = {g.name: _plain(getattr(value, g.name)) for g in dataclasses.fields(value)}
        out[f.name] = _plain(value)
    return out


def config_document(cfg: TerminalConfig) -> dict[str, Any]:
    return {name: section_values(cfg, name) for name in SECTIONS}


def _merge(base: dict[str, Any], changes: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in changes.items():
        if (
            isinstance(value, Mapping)
            and isinstance(out.get(key), dict)
            and key not in WHOLE_TABLES
        ):
            out[key] = _merge(out[key], value)
        else:
            out[key] = _plain(value)
    return out


def _flat(values: Mapping[str, Any], prefix: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in values.items():
        if isinstance(value, Mapping):
            out.update(_flat(value, f"{prefix}.{key}"))
        else:
            out[f"{prefix}.{key}"] = value
    return out


def section_version(cfg: TerminalConfig, section: str) -> str:
    """A short digest of one section's values: a form remembers the one it was filled from,
    and a change applied meanwhile (from another screen) makes it differ."""
    values = json.dumps(_plain(section_values(cfg, section)), sort_keys=True, default=str)
    return hashlib.sha256(values.encode()).hexdigest()[:12]


def changed_keys(
    old: TerminalConfig, new: TerminalConfig, section: str
) -> list[tuple[str, Any, Any]]:
    """(dotted key, old value, new value) for every value of `section` that differs; a key
    only one side has gives None on the other (an ECU override added or removed)."""
    a = _flat(section_values(old, section), section)
    b = _flat(section_values(new, section), section)
    return [(k, a.get(k), b.get(k)) for k in sorted(a.keys() | b.keys()) if a.get(k) != b.get(k)]


def validate_section(
    cfg: TerminalConfig, section: str, values: Mapping[str, Any]
) -> TerminalConfig:
    """The configuration with `values` put into `section`, checked as a file is checked."""
    doc = config_document(cfg)
    if section not in doc:
        raise ConfigError(section, f"no such section (known: {', '.join(SECTIONS)})")
    doc[section] = _merge(doc[section], values)
    return config_from_dict(doc)


def save_section(path: Path, section: str, values: Mapping[str, Any]) -> TerminalConfig:
    """Write `values` into `section` of the file at `path` (comments kept), atomically, the
    previous file kept as `path.bak`; returns the configuration the file now holds.

    The whole new file is checked before anything is written: ConfigError names the key."""
    text = read_config_text(path) if path.exists() else ""
    try:
        doc = tomlkit.parse(text)
    except tomlkit.exceptions.ParseError as exc:
        raise ConfigError(str(path), f"not valid TOML: {exc}") from exc
    table = doc.get(section)
    if table is None:
        table = tomlkit.table()
        doc[section] = table
    _merge_into(table, values)
    new_text = tomlkit.dumps(doc)
    cfg = config_from_dict(tomlkit.parse(new_text).unwrap())
    if path.exists():
        shutil.copy2(path, path.with_name(path.name + ".bak"))
    atomic_write(path, new_text)
    return cfg


def _merge_into(table: Any, values: Mapping[str, Any]) -> None:
    for key, value in values.items():
        if isinstance(value, Mapping) and key in table and isinstance(table[key], Mapping):
            if key in WHOLE_TABLES:  # removed names go; the kept ones keep their comments
                for gone in [k for k in table[key] if k not in value]:
                    del table[key][gone]
            _merge_into(table[key], value)
        else:
            table[key] = _plain(value)


def changed_device_keys(old: TerminalConfig, new: TerminalConfig, section: str) -> list[str]:
    """The dotted keys a device of `section` is opened with that differ between two
    configurations (none for a section without a device)."""
    before, after = getattr(old, section), getattr(new, section)
    return [
        f"{section}.{k}"
        for k in DEVICE_KEYS.get(section, ())
        if _plain(getattr(before, k)) != _plain(getattr(after, k))
    ]


def changed_ecu_params(old: TerminalConfig, new: TerminalConfig) -> dict[int, float]:
    """The ECU parameters whose value differs between two configurations (id -> new value)."""
    a, b = old.ecu_params(), new.ecu_params()
    return {k: v for k, v in b.items() if a.get(k) != v}
