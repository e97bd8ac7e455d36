"""NMEA 0183 sentences written: RMC, VTG, GGA with CRLF and checksums (the simulated receiver's),
and the quick RMC speed read of the simulated cab PC.

The terminal reads NMEA with topdress.gnss.nmea.NmeaDecoder; the cab PC of the experiments
reads only the speed of its own receiver's RMC, 25 times faster, and a test holds the two
readings equal on every line the simulator writes."""

from __future__ import annotations

import math
from functools import reduce
from operator import xor

from topdress.gnss.nmea import nmea_checksum

KNOTS_PER_MS = 3600.0 / 1852.0
TALKERS = ("GP", "BD", "GB", "GN", "GL", "GA")


def checksum(body: str) -> str:
    """XOR of the characters between '$' and '*', two upper-case hex digits."""
    if body.isascii():  # every line the simulator writes: the XOR of its bytes
        return f"{nmea_checksum(body.encode('ascii')):02X}"
    return f"{reduce(xor, map(ord, body), 0):02X}"


def sentence(body: str) -> str:
    """Wrap a sentence body (without '$') into a full line with checksum and CRLF."""
    return f"${body}*{checksum(body)}\r\n"


def _lat(lat_deg: float) -> tuple[str, str]:
    a = abs(lat_deg)
    d = int(a)
    return f"{d:02d}{(a - d) * 60.0:08.5f}", "N" if lat_deg >= 0 else "S"


def _lon(lon_deg: float) -> tuple[str, str]:
    a = abs(lon_deg)
    d = int(a)
    return f"{d:03d}{(a - d) * 60.0:08.5f}", "E" if lon_deg >= 0 else "W"


def _hms(t_utc_s: float) -> str:
    t = t_utc_s % 86400.0
    h = int(t // 3600)
    m = int(t % 3600 // 60)
    s = t - h * 3600 - m * 60
    return f"{h:02d}{m:02d}{s:05.2f}"


def rmc(
    talker: str,
    t_utc_s: float,
    valid: bool,
    lat_deg: float,
    lon_deg: float,
    speed_ms: float,
    course_deg: float,
    date_ddmmyy: str,
) -> str:
    """RMC: time, status A/V, position, speed over ground (knots), course, date, mode."""
    if not valid:
        return sentence(f"{talker}RMC,{_hms(t_utc_s)},V,,,,,,,{date_ddmmyy},,,N")
    la, ns = _lat(lat_deg)
    lo, ew = _lon(lon_deg)
    kn = speed_ms * KNOTS_PER_MS
    return sentence(
        f"{talker}RMC,{_hms(t_utc_s)},A,{la},{ns},{lo},{ew},{kn:.3f},{course_deg:.1f},"
        f"{date_ddmmyy},,,A"
    )


def vtg(talker: str, valid: bool, speed_ms: float, course_deg: float) -> str:
    """VTG: course true, speed in knots and km/h."""
    if not valid:
        return sentence(f"{talker}VTG,,T,,M,,N,,K,N")
    return sentence(
        f"{talker}VTG,{course_deg:.1f},T,,M,{speed_ms * KNOTS_PER_MS:.3f},N,"
        f"{speed_ms * 3.6:.3f},K,A"
    )


def gga(
    talker: str,
    t_utc_s: float,
    valid: bool,
    lat_deg: float,
    lon_deg: float,
    n_sats: int,
    hdop: float,
    alt_m: float,
) -> str:
    """GGA: fix quality 1 (single point) or 0 (no fix)."""
    if not valid:
        return sentence(f"{talker}GGA,{_hms(t_utc_s)},,,,,0,00,99.9,,M,,M,,")
    la, ns = _lat(lat_deg)
    lo, ew = _lon(lon_deg)
    return sentence(
        f"{talker}GGA,{_hms(t_utc_s)},{la},{ns},{lo},{ew},1,{n_sats:02d},{hdop:.1f},"
        f"{alt_m:.1f},M,0.0,M,,"
    )


def course_deg(vx_east: float, vy_north: float) -> float:
    """Course over ground, degrees clockwise from north, 0..360."""
    return math.degrees(math.atan2(vx_east, vy_north)) % 360.0


def parse_rmc_speed_kmh(line: str) -> float | None:
    """Speed of a valid RMC line in km/h, None for any other or an invalid line.

    A tiny checksum-verified reader for the simulated cab PC of the experiments; the
    terminal's full reader (NmeaDecoder) gives the same speed for every line written here.
    """
    s = line.strip()
    if len(s) < 10 or s[0] != "$" or s[-3] != "*" or s[3:6] != "RMC":
        return None
    body = s[1:-3]
    if checksum(body) != s[-2:].upper():
        return None
    f = body.split(",")
    if len(f) < 8 or f[2] != "A" or not f[7]:
        return None
    return float(f[7]) * 1.852
