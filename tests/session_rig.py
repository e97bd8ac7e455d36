"""A small session as the terminal writes it (raw NMEA, crop, CAN both ways incl. EcuDiag with
the wheel pulses, 10 Hz state rows with positions and UTC, events), for the damage tests."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

from topdress import protocol
from topdress.gnss import sentences as nmea
from topdress.log.model import LogEvent, StateRow
from topdress.log.session import SessionLog
from topdress.protocol.frames import _encode

CONFIG = "[machine]\nwidth_m = 3.6\n"
LAT0, LON0 = 43.8853, 125.3245
UTC0 = 1_780_000_000.0  # 2026-05-28


def fill(log: SessionLog, seconds: float = 20.0, t0: float = 100.0, commits: bool = False) -> None:
    """`seconds` of a 8 km/h drive heading east: 10 Hz NMEA, state and ECU frames, 2 Hz
    commands, a crop line, and start/stop events; `commits`: one commit per second of it (as
    the terminal's writer does), not as few as the queue allows."""
    ids = protocol.DEFAULT_IDS
    v = 8.0 / 3.6
    log.event(LogEvent(t0, "operator.start", {"was": "stopped"}))
    for i in range(round(seconds * 10)):
        t = t0 + i * 0.1
        x = v * i * 0.1
        lat = LAT0
        lon = LON0 + x / (111_320.0 * math.cos(math.radians(LAT0)))
        log.raw(
            "nmea", t, nmea.rmc("GP", UTC0 % 86400 + i * 0.1, True, lat, lon, v, 90.0, "280526")
        )
        log.raw("crop", t + 0.01, "2,0.0412,0.2104,0.4419,0.3541,0.8295")
        pulses = (i * 36) % (1 << 24)
        diag = _encode(
            "EcuDiag",
            {
                "SpeedSource": 1,
                "SpeedMode": 0,
                "GnssValid": 1,
                "Uniform": 1,
                "SwitchCompare": 0,
                "Cv": 1.2,
                "FaultWord": 0,
                "WheelPulses": pulses,
            },
        )
        log.raw("can_rx", t + 0.02, (ids.diag, diag))
        if i % 5 == 0:
            msg = protocol.encode_command(True, 3000, 150.0, 120.0, 8.0)
            log.raw("can_tx", t + 0.03, (msg.arbitration_id, bytes(msg.data)))
        log.state(
            StateRow(
                t,
                lat,
                lon,
                8.0,
                8.0,
                8.0,
                "gnss",
                1.2,
                0.8,
                150.0,
                120.0,
                20.0,
                16.0,
                20.0,
                16.0,
                3000.0,
                3000.0,
                0,
                utc=UTC0 + i * 0.1,
                utc_source="gnss",
                heading_deg=90.0,
                outlet_lat=lat,
                outlet_lon=lon,
                zone=None,
                prescription_kg_ha=None,
            )
        )
        if commits and i % 10 == 9:
            log.sync()
    log.event(LogEvent(t0 + seconds, "operator.stop", {"was": "running"}))


def closed_session(directory: Path, seconds: float = 20.0) -> Path:
    with SessionLog.create(directory, CONFIG, name="field") as log:
        fill(log, seconds)
    return log.path


def live_copy(directory: Path, into: Path, seconds: float = 20.0) -> Path:
    """A copy of a session still being written: the file and its -wal as they are."""
    log = SessionLog.create(directory, CONFIG, name="live")
    fill(log, seconds, commits=True)
    assert log.sync()
    into.mkdir(parents=True, exist_ok=True)
    copy = into / log.path.name
    shutil.copyfile(log.path, copy)
    shutil.copyfile(log.path.with_name(log.path.name + "-wal"), copy.with_name(copy.name + "-wal"))
    log.close()
    return copy
