"""The device test on the operator's desk: the last lines or frames of each device, as they
came in and as the terminal reads them."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import Any

from topdress import protocol
from topdress.config import TerminalConfig
from topdress.crop.sensors import parse_crop_line
from topdress.errors import ProtocolError, SensorError
from topdress.gnss.nmea import NmeaDecoder
from topdress.i18n import text
from topdress.terminal.busswitch import BusSwitch
from topdress.terminal.journal import Settings
from topdress.terminal.lines import Lines
from topdress.view import commands as op
from topdress.view.snapshot import DeviceLine

DEVICE_LINES = 20  # lines or frames kept per device for the "test" view
_DEVICE = {"nmea": "gnss", "crop": "crop", "can": "can"}  # inbox kind -> device


class DeviceTest:
    """The last DEVICE_LINES inputs of each device, kept for the operator's device test."""

    def __init__(self, settings: Settings, lines: Lines, can: BusSwitch) -> None:
        self._settings = settings
        self._sources = lines
        self._can = can
        self._lines: dict[str, deque[tuple[float, Any]]] = {
            k: deque(maxlen=DEVICE_LINES) for k in _DEVICE.values()
        }

    def record(self, kind: str, t: float, payload: Any) -> None:
        """One input of the loop's inbox (those of no device are not kept)."""
        key = _DEVICE.get(kind)
        if key is not None:
            self._lines[key].append((t, payload))

    def test(self, device: str, t0: float) -> op.CommandResult:
        """The lines kept for `device`, decoded, their times since `t0`."""
        if device not in self._lines:
            return op.CommandResult(False, text("op.error.no_device", device=device))
        decode: Callable[[Any], tuple[str, str]] = {
            "gnss": _decode_nmea(NmeaDecoder()),
            "crop": _decode_crop(self._settings.cfg),
            "can": _decode_can(self._can.link.ids),
        }[device]
        lines = [DeviceLine(t - t0, *decode(p)) for t, p in self._lines[device]]
        where = {
            "gnss": self._sources.gnss.name,
            "crop": self._sources.crop.name,
            "can": self._can.link.where,
        }[device]
        return op.CommandResult(
            True, text("op.done.test", device=device, where=where, n=len(lines)), data=lines
        )


def _decode_nmea(dec: NmeaDecoder) -> Callable[[Any], tuple[str, str]]:
    def f(line: Any) -> tuple[str, str]:
        fix = dec.decode(line)
        raw = bytes(line).decode("latin-1").rstrip()
        if not fix.ok:
            return raw, f"not usable: {fix.error}"
        parts = [f"{fix.talker}{fix.type}", "fix" if fix.fix_valid else "no fix"]
        if fix.speed_kmh is not None:
            parts.append(f"{fix.speed_kmh:.2f} km/h")
        if fix.lat is not None and fix.lon is not None:
            parts.append(f"{fix.lat:.6f},{fix.lon:.6f}")
        return raw, " ".join(parts)

    return f


def _decode_crop(cfg: TerminalConfig) -> Callable[[Any], tuple[str, str]]:
    def f(line: Any) -> tuple[str, str]:
        raw = bytes(line).decode("latin-1").rstrip()
        try:
            r = parse_crop_line(0.0, line, cfg.crop.columns, cfg.crop.sensors)
        except SensorError as exc:
            return raw, f"not usable: {exc}"
        return raw, f"sensor {r.sensor_id} NDVI {r.ndvi:.3f}"

    return f


def _decode_can(ids: protocol.FrameIds) -> Callable[[Any], tuple[str, str]]:
    def f(msg: Any) -> tuple[str, str]:
        raw = f"{msg.arbitration_id:08X} {bytes(msg.data).hex(' ')}"
        try:
            return raw, repr(protocol.decode(msg, ids))
        except ProtocolError as exc:
            return raw, f"not ours or malformed: {exc}"

    return f
