"""The terminal's configuration: one TOML file, one frozen dataclass per section.

Every key has a default (see DEFAULT_TOML, which is also docs/config.md). Unknown keys, wrong
types and out-of-range values raise ConfigError naming the dotted key, so a bad file stops
start-up before any device is opened.
"""

from __future__ import annotations

import dataclasses
import hmac
import ipaddress
import math
import re
import stat
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from topdress.errors import ConfigError
from topdress.protocol.model import DEFAULT_IDS, Compare, SpeedMode
from topdress.protocol.params import ParamSpec, param, params

# Numeric fields carry metadata {"range": (lo, hi)}; str fields may carry {"choices": (...)}.
_T = TypeVar("_T")


def _num(default: _T, lo: float, hi: float) -> Any:
    return field(default=default, metadata={"range": (lo, hi)})


def _choice(default: str, *choices: str) -> Any:
    return field(default=default, metadata={"choices": choices})


def _param(config_key: str, default: _T) -> Any:
    """A key that is also an ECU parameter: its range is the DBC's (topdress.protocol.params)."""
    spec = param(config_key)
    return field(default=default, metadata={"range": (spec.minimum, spec.maximum)})


@dataclass(frozen=True)
class MachineConfig:
    width_m: float = _param("machine.width_m", 3.6)
    rows: int = _num(6, 1, 64)
    layers: int = _num(2, 1, 2)
    kg_per_rev_upper: float = _param("machine.kg_per_rev_upper", 0.3)
    kg_per_rev_lower: float = _param("machine.kg_per_rev_lower", 0.3)
    wheel_radius_m: float = _param("machine.wheel_radius_m", 0.0615)
    wheel_ppr: int = _param("machine.wheel_ppr", 500)
    fan_rpm: int = _num(3000, 0, 6000)
    # The meters' outlet from the GNSS antenna: forward along the track (behind < 0), and to
    # the right across it, m. The as-applied map, prescription and boundary use the outlet.
    outlet_along_m: float = _num(0.0, -50.0, 50.0)
    outlet_across_m: float = _num(0.0, -30.0, 30.0)


@dataclass(frozen=True)
class SpeedConfig:
    # fused = the fused estimate (the default: it learns the GNSS lag itself); paper = the
    # dual speed mode of the paper; wheel / gnss = one source only.
    mode: str = _choice(str(SpeedMode.FUSED), *map(str, SpeedMode))
    queue_len: int = _param("speed.queue_len", 5)
    cv_window: int = _param("speed.cv_window", 5)
    cv_threshold_pct: float = _param("speed.cv_threshold_pct", 4.2)
    switch_speed_kmh: float = _param("speed.switch_speed_kmh", 6.0)
    switch_compare: str = _choice(str(Compare.GNSS), *map(str, Compare))
    min_work_speed_kmh: float = _param("speed.min_work_speed_kmh", 0.5)


#: [ecu] keys: the ECU parameters of the table (topdress.protocol.params) that the [ecu]
#: section sets, by their td_params_t name; range and resolution the DBC's.
ECU_KEYS: dict[str, ParamSpec] = {p.name: p for p in params() if p.section == "ecu"}

# [ecu] keys that the terminal's own periods must agree with (see _check_timing).
ECU_TIMING = ("cmd_timeout_ms", "gnss_timeout_ms", "status_period_ms")
SPEED_MODE_IDS = {str(m): m.code for m in SpeedMode}  # td_speed_mode_t
SWITCH_COMPARE_IDS = {str(c): c.code for c in Compare}  # td_compare_t
# [ecu] gnss_lag_ms = "auto" (the default): the ECU learns the GNSS lag (GnssLagAuto 1); a
# number fixes it (GnssLagAuto 0, unless gnss_lag_auto is set too; the ECU still overrules a
# lag its data contradict).
GNSS_LAG_AUTO = "auto"


@dataclass(frozen=True)
class EcuConfig:
    # Only the keys the user wrote; the ECU keeps its own defaults for the rest.
    overrides: Mapping[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class GnssConfig:
    source: str = _choice("serial", "serial", "file", "stdin")
    port: str = "/dev/ttyUSB0"
    baud: int = _num(9600, 300, 921600)
    path: str = ""
    replay_interval_s: float = _num(0.1, 0.0, 10.0)  # pause between lines of a replayed file
    # VTG speed is forwarded only when no valid RMC came for this long.
    rmc_timeout_s: float = _num(1.5, 0.1, 60.0)
    # A GNSS speed older than this is not forwarded (the ECU gets "not available").
    stale_s: float = _num(2.0, 0.1, 60.0)
    # Without fixes the outlet is dead reckoned along the last heading by the wheel's distance
    # for this far, m; past it the position is unknown: no boundary switch-off, an alarm, and
    # the rate below (a fix's normal age is ~1.5 s, 3 m at 8 km/h, inside it).
    dead_reckon_m: float = _num(10.0, 0.0, 500.0)
    # The rate while the position is unknown, kg/ha; -1: the last rate metered in the field.
    unknown_kg_ha: float = _num(-1.0, -1.0, 1200.0)


CROP_COLUMN_NAMES = ("sensor_id", "red", "red_edge", "nir", "ndre", "ndvi")


@dataclass(frozen=True)
class CropConfig:
    source: str = _choice("serial", "serial", "file", "stdin")
    port: str = "/dev/ttyUSB1"
    baud: int = _num(38400, 300, 921600)
    path: str = ""
    replay_interval_s: float = _num(0.025, 0.0, 10.0)
    sensors: int = _num(4, 1, 16)
    columns: Mapping[str, int] = field(
        default_factory=lambda: {name: i for i, name in enumerate(CROP_COLUMN_NAMES)}
    )
    ndvi_min: float = _num(0.0, -1.0, 1.0)
    ndvi_max: float = _num(1.0, -1.0, 1.0)
    stale_s: float = _num(1.0, 0.05, 60.0)
    sensor_to_meter_m: float = _num(2.0, 0.0, 50.0)


@dataclass(frozen=True)
class LinearRateConfig:
    # Two points of the line NDVI -> product rate; clamped to [min_kg_ha, max_kg_ha].
    ndvi_0: float = _num(0.3, -1.0, 1.0)
    rate_0_kg_ha: float = _num(450.0, 0.0, 1200.0)
    ndvi_1: float = _num(0.8, -1.0, 1.0)
    rate_1_kg_ha: float = _num(150.0, 0.0, 1200.0)
    min_kg_ha: float = _num(0.0, 0.0, 1200.0)
    max_kg_ha: float = _num(600.0, 0.0, 1200.0)


@dataclass(frozen=True)
class TableRateConfig:
    # (NDVI, kg/ha) points, NDVI strictly increasing; held constant beyond the ends.
    points: tuple[tuple[float, float], ...] = ((0.3, 450.0), (0.5, 350.0), (0.8, 150.0))


@dataclass(frozen=True)
class SufficiencyRateConfig:
    reference: str = _choice("virtual", "virtual", "nrich")
    ndvi_ref: float = _num(0.85, 0.05, 1.0)  # N-rich strip NDVI (reference = "nrich")
    percentile: float = _num(95.0, 50.0, 100.0)  # virtual reference percentile
    min_samples: int = _num(50, 1, 1_000_000)  # before that, fallback_kg_ha is applied
    fallback_kg_ha: float = _num(300.0, 0.0, 1200.0)
    mz_opt_n_kg_ha: float = _num(200.0, 0.0, 500.0)
    n_pre_kg_ha: float = _num(50.0, 0.0, 500.0)
    n_credits_kg_ha: float = _num(0.0, 0.0, 500.0)
    delta_si: float = _num(0.3, 0.01, 1.0)
    max_n_kg_ha: float = _num(200.0, 0.0, 500.0)
    n_fraction: float = _num(0.46, 0.01, 1.0)  # urea


@dataclass(frozen=True)
class RateConfig:
    model: str = _choice("linear", "linear", "table", "sufficiency")
    split_upper: float = _num(0.5, 0.0, 1.0)
    linear: LinearRateConfig = field(default_factory=LinearRateConfig)
    table: TableRateConfig = field(default_factory=TableRateConfig)
    sufficiency: SufficiencyRateConfig = field(default_factory=SufficiencyRateConfig)


#: The frames whose identifiers `[can.ids]` may set (the others keep the DBC's).
CONFIGURABLE_IDS = (
    "status",
    "command",
    "diag",
    "speeds",
    "targets",
    "param_set",
    "param_ack",
    "cal_command",
    "cal_status",
)


@dataclass(frozen=True)
class CanConfig:
    interface: str = "virtual"
    channel: str = "topdress"
    bitrate: int = _num(250000, 10000, 1000000)
    command_period_s: float = _num(0.5, 0.02, 10.0)
    send_on_gnss: bool = False
    send_on_rate: bool = False
    ecu_timeout_s: float = _num(0.5, 0.05, 60.0)
    # what meters on this bus: the topdress ECU (protocol/topdress.dbc), or any ISOBUS
    # implement, with the terminal as its Task Controller ([isobus], docs/isobus.md)
    implement: str = _choice("topdress", "topdress", "isobus")
    # the DBC's identifiers of the frames a [can.ids] table may move
    ids: Mapping[str, int] = field(
        default_factory=lambda: {k: getattr(DEFAULT_IDS, k) for k in CONFIGURABLE_IDS}
    )
    # The adapter's own options, passed to python-can as keyword arguments (slcan's
    # tty_baudrate, pcan's fd, ...): [can.options] in the file.
    options: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class LogConfig:
    dir: str = "topdress-sessions"
    # free space on the log's disk below which the log_low_space alarm is raised, MiB (at
    # start and after every commit); 0 = no margin, only a full disk is an alarm
    min_free_mib: float = _num(50.0, 0.0, 1_000_000.0)


@dataclass(frozen=True)
class PrescriptionConfig:
    # A prescription map: GeoPackage, Shapefile or GeoJSON polygons, or an ISOXML
    # TASKDATA.XML with a grid (types 1 and 2). "" = none.
    path: str = ""
    layer: str = ""  # layer of a multi-layer file ("" = the first)
    attribute: str = "rate"  # the polygons' rate attribute
    units: str = _choice("kg/ha", "kg/ha", "lb/ac", "t/ha")
    # alone: the map's rate; bound: the NDVI model's rate within the zone's min and max
    mode: str = _choice("alone", "alone", "bound")
    min_attribute: str = "min_rate"  # bound mode: the zone's limits (same units)
    max_attribute: str = "max_rate"
    outside_kg_ha: float = _num(0.0, 0.0, 1200.0)  # outside every zone, and with no position
    # metering farther than this outside the map's extent is the wrong-field alarm; 0 = off
    outside_alarm_m: float = _num(50.0, 0.0, 100_000.0)


@dataclass(frozen=True)
class BoundaryConfig:
    # The field boundary: polygons (same formats) or an ISOXML TASKDATA.XML partfield. "" = none.
    path: str = ""
    layer: str = ""
    headland_m: float = _num(0.0, 0.0, 200.0)  # strip inside the boundary with the meters off
    # metering farther than this outside the boundary is the wrong-field alarm; 0 = off
    outside_alarm_m: float = _num(50.0, 0.0, 100_000.0)


@dataclass(frozen=True)
class LookaheadConfig:
    # tau = command_ms + meter_ms + airline_ms: the terminal takes the rate where the outlets
    # will be tau from now (docs/experiments.md measures each part). meter_ms and airline_ms
    # also go to the ECU (LeadMeter, LeadAirLine), whose target speed looks ahead by them.
    command_ms: int = _num(0, 0, 5000)
    meter_ms: int = _param("lookahead.meter_ms", 0)
    airline_ms: int = _param("lookahead.airline_ms", 0)
    # the ECU's speed look-ahead while the speed falls (slowing, the stop: LeadStop); 0 = the
    # same as rising (meter_ms + airline_ms). Not part of the rate's tau.
    stop_ms: int = _param("lookahead.stop_ms", 0)

    @property
    def total_s(self) -> float:
        return (self.command_ms + self.meter_ms + self.airline_ms) / 1000.0


@dataclass(frozen=True)
class DisplayConfig:
    refresh_s: float = _num(0.5, 0.2, 2.0)  # console redraw period on a TTY
    enabled: bool = True  # serve the operator display (web page)
    host: str = "127.0.0.1"  # any other address needs a pin
    port: int = _num(8080, 1, 65535)
    pin: str = ""  # 4..12 digits; required to operate from another address; never logged
    language: str = _choice("en", "en", "zh")
    # Host names the display answers to besides IP addresses and localhost (DNS rebinding).
    allowed_hosts: tuple[str, ...] = ()
    # Reverse proxies (addresses or networks) whose X-Forwarded-For is believed.
    trusted_proxies: tuple[str, ...] = ()
    # A file holding the token the cab's kiosk browser opens the display with (created, mode
    # 0600, when missing); set: only that browser operates without the PIN.
    kiosk_token_file: str = ""
    # The local user the cab's kiosk browser runs as: its direct loopback connections operate
    # without the PIN, recognised by the kernel's socket table (no secret anywhere).
    kiosk_user: str = ""
    # Metering with no operator display (its process down, or no page since one was open) for
    # longer than this pauses the meters; 0: never (the alarm only).
    lost_pause_s: float = _num(10.0, 0.0, 600.0)


#: Addresses that only the cab PC itself reaches: the display needs no PIN there.
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")


def check_pin(display: DisplayConfig, given: str) -> bool:
    """Whether `given` is the display PIN, compared in constant time; True when none is set."""
    if not display.pin:
        return True
    return hmac.compare_digest(display.pin.encode("utf-8"), given.encode("utf-8"))


@dataclass(frozen=True)
class OperatorConfig:
    autostart: bool = False  # meters run at once, without the operator's start (headless use)
    off_rate_pct: float = _num(10.0, 1.0, 100.0)  # metering speed this far off its target...
    off_rate_s: float = _num(5.0, 0.5, 120.0)  # ...for longer than this is an alarm
    fan_check_s: float = _num(10.0, 2.0, 120.0)  # how long the fan check runs the fans
    # The look-ahead calibration takes this off each "seen" press (0 with a flow sensor).
    reaction_ms: float = _num(200.0, 0.0, 1000.0)
    counters_file: str = "counters.json"  # field and season counters, relative to log.dir


@dataclass(frozen=True)
class IsobusConfig:
    # The terminal as an ISOBUS Task Controller (can.implement = "isobus", docs/isobus.md).
    tc_address: int = _num(0xF7, 128, 247)  # the address it claims first (247: the TC's)
    tc_identity: int = _num(1, 0, (1 << 21) - 1)  # its NAME's identity number (one per cab)
    # a product set in volume per area (DDI 1, a liquid): kg/ha to L/ha by this density
    density_kg_l: float = _num(1.0, 0.1, 5.0)
    # Section control (TC-SC, geo.sectionctl): each section off over ground already covered
    # and outside the field boundary; false = all sections with the rate.
    section_control: bool = True
    overlap_pct: float = _num(50.0, 0.0, 99.0)  # a section goes off above this % done/outside
    section_look_m: float = _num(1.0, 0.1, 20.0)  # length of ground each section looks at
    # earlier sessions of the same field (same [boundary] path) started within this many
    # hours before this one: their as-applied swaths count as covered; 0 = none
    coverage_hours: float = _num(24.0, 0.0, 8760.0)
    # The topdress ECU's NAME manufacturer code (its firmware's FW_ISOBUS_MANUFACTURER): an
    # implement with it, the ECU's NAME function and a DDOP named "topdress" is spoken to in
    # the ECU's private frames on Proprietary A/B (parameters, calibrations, its broadcasts).
    ecu_manufacturer: int = _num(0, 0, 2047)


@dataclass(frozen=True)
class OfficeConfig:
    # The farm office's database (docs/office.md): a PostgreSQL URL ("" = no office; the cab
    # works alone). The cab sends its sessions there by itself, off the control loop.
    url: str = ""
    interval_s: float = _num(300.0, 10.0, 86_400.0)  # between two syncs
    machine: str = ""  # this machine's id in the office ("" = the host's name)
    farm: str = ""  # the farm the office database belongs to ("" = not checked)
    product: str = "fertilizer"  # what the machine spreads, as the office's swaths name it


@dataclass(frozen=True)
class TerminalConfig:
    machine: MachineConfig = field(default_factory=MachineConfig)
    speed: SpeedConfig = field(default_factory=SpeedConfig)
    ecu: EcuConfig = field(default_factory=EcuConfig)
    gnss: GnssConfig = field(default_factory=GnssConfig)
    crop: CropConfig = field(default_factory=CropConfig)
    rate: RateConfig = field(default_factory=RateConfig)
    can: CanConfig = field(default_factory=CanConfig)
    log: LogConfig = field(default_factory=LogConfig)
    display: DisplayConfig = field(default_factory=DisplayConfig)
    operator: OperatorConfig = field(default_factory=OperatorConfig)
    prescription: PrescriptionConfig = field(default_factory=PrescriptionConfig)
    boundary: BoundaryConfig = field(default_factory=BoundaryConfig)
    lookahead: LookaheadConfig = field(default_factory=LookaheadConfig)
    office: OfficeConfig = field(default_factory=OfficeConfig)
    isobus: IsobusConfig = field(default_factory=IsobusConfig)

    def ecu_params(self, lag_start_ms: int | None = None) -> dict[int, float]:
        """PcParamSet id -> physical value of every parameter to push at start, by the table
        of topdress.protocol.params.

        Machine and speed parameters are always pushed (the terminal's file is the truth
        for them); the look-ahead's once set; of [ecu], only the keys the user set. The GNSS
        lag: a number fixes it; "auto" (the default) lets the ECU learn it, starting from
        `lag_start_ms` (the lag learned with this receiver before) when given.
        """
        out: dict[int, float] = {}
        for spec in params():
            value = self._param_value(spec, lag_start_ms)
            if value is not None:
                out[spec.id] = value
        return out

    def _param_value(self, spec: ParamSpec, lag_start_ms: int | None) -> float | None:
        """The value of one ECU parameter to push, None when the ECU keeps its own."""
        section, key = spec.section, spec.name
        if section == "ecu":
            overrides = self.ecu.overrides
            if key == "gnss_lag_auto" and key not in overrides:
                return 0 if "gnss_lag_ms" in overrides else 1
            if key == "gnss_lag_ms" and key not in overrides and lag_start_ms is not None:
                return float(min(max(round(lag_start_ms), 0), 3000))
            return overrides.get(key)
        if section == "lookahead":
            la = self.lookahead
            # LeadMeter and LeadAirLine go together once either is set; LeadStop when set
            # (0 = the same as rising, the ECU's default).
            pushed = la.stop_ms if key == "stop_ms" else la.meter_ms or la.airline_ms
            ms: int = getattr(la, key)
            return ms if pushed else None
        value = getattr(getattr(self, section), key)
        if key == "mode":
            return SPEED_MODE_IDS[value]
        if key == "switch_compare":
            return SWITCH_COMPARE_IDS[value]
        number: float = value
        return number


_PIN_LINE = re.compile(r'(?m)^(\s*pin\s*=\s*)("(?:[^"\\]|\\.)*"|\'[^\']*\'|[^#\s]+)')


def redacted_text(text: str) -> str:
    """The configuration text with the display PIN's value replaced, for the session log."""
    return _PIN_LINE.sub(lambda m: m.group(1) + '"***"', text)


def default_config() -> TerminalConfig:
    return TerminalConfig()


MAX_CONFIG_BYTES = 1 << 20  # a configuration file is a few kB; anything over 1 MiB is not one


def read_config_text(path: str | Path) -> str:
    """The file's text; a byte order mark (some Windows editors write one) is dropped.

    Only a regular file of at most MAX_CONFIG_BYTES is read: /dev/zero, /dev/urandom or a FIFO
    given as the configuration would otherwise be read forever (or block on open)."""
    path = Path(path)
    info = path.stat()  # follows links; never blocks, unlike opening a FIFO
    if not stat.S_ISREG(info.st_mode):
        raise ConfigError(str(path), "is not a regular file (a device, FIFO or directory)")
    with path.open("rb") as f:
        data = f.read(MAX_CONFIG_BYTES + 1)
    if len(data) > MAX_CONFIG_BYTES:
        raise ConfigError(str(path), f"is over {MAX_CONFIG_BYTES} bytes: not a configuration")
    return data.decode("utf-8-sig")


def load_config(path: str | Path) -> TerminalConfig:
    """Read and validate a TOML file; any problem raises ConfigError."""
    try:
        text = read_config_text(path)
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(str(path), f"cannot read the configuration file: {exc}") from exc
    return loads_config(text, source=str(path))


def loads_config(text: str, source: str = "<config>") -> TerminalConfig:
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(source, f"not valid TOML: {exc}") from exc
    except ValueError as exc:  # an integer over Python's 4,300-digit conversion limit
        raise ConfigError(_key_at(text, _has_long_digits), f"number too long: {exc}") from exc
    except RecursionError:
        raise ConfigError(_key_at(text, _is_deep), "arrays or tables nested too deep") from None
    return config_from_dict(doc)


def config_from_dict(doc: Mapping[str, Any]) -> TerminalConfig:
    """Validate a parsed TOML document (the same checks as a file); ConfigError names the key."""
    sections = {f.name: f for f in dataclasses.fields(TerminalConfig)}
    _reject_unknown(doc, sections, "")
    built: dict[str, Any] = {}
    for name, table in doc.items():
        table = _table(table, name)
        if name == "ecu":
            built[name] = _ecu(table)
        elif name == "rate":
            built[name] = _rate(table)
        else:
            built[name] = _section(sections[name].type, table, name)
    cfg = TerminalConfig(**built)
    _cross_check(cfg)
    return cfg


# ---- parsing helpers ----------------------------------------------------------------------


def _table(value: Any, key: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise ConfigError(key, "must be a table (a [section])")
    return value


def _reject_unknown(table: Mapping[str, Any], known: Mapping[str, Any], prefix: str) -> None:
    for key in table:
        if key not in known:
            dotted = f"{prefix}{key}"
            raise ConfigError(dotted, f"unknown key (known: {', '.join(sorted(known))})")


def _section(cls: Any, table: dict[str, Any], prefix: str) -> Any:
    if isinstance(cls, str):  # postponed annotations: resolve the section class by name
        cls = globals()[cls]
    fields = {f.name: f for f in dataclasses.fields(cls)}
    _reject_unknown(table, fields, f"{prefix}.")
    values: dict[str, Any] = {}
    for key, raw in table.items():
        f = fields[key]
        values[key] = _value(f, raw, f"{prefix}.{key}")
    return cls(**values)


def _value(f: dataclasses.Field[Any], raw: Any, key: str) -> Any:
    if f.name == "columns":
        return _columns(raw, key)
    if f.name == "ids":
        return _can_ids(raw, key)
    if f.name == "options":
        return _can_options(raw, key)
    default = f.default
    if isinstance(default, tuple):
        if not isinstance(raw, list) or not all(isinstance(x, str) for x in raw):
            raise ConfigError(key, f"must be a list of strings, not {raw!r}")
        return tuple(raw)
    if isinstance(default, bool):
        if not isinstance(raw, bool):
            raise ConfigError(key, f"must be true or false, not {raw!r}")
        return raw
    if isinstance(default, str):
        if not isinstance(raw, str):
            shown = "a number" if key == "display.pin" else repr(raw)  # the PIN is never shown
            raise ConfigError(key, f"must be a string, not {shown}")
        choices = f.metadata.get("choices")
        if choices and raw not in choices:
            raise ConfigError(key, f"must be one of {', '.join(choices)}, not {raw!r}")
        return raw
    lo, hi = f.metadata["range"]
    return _number(raw, key, lo, hi, integer=isinstance(default, int))


def _number(raw: Any, key: str, lo: float, hi: float, integer: bool) -> Any:
    if isinstance(raw, bool) or not isinstance(raw, int | float):
        raise ConfigError(key, f"must be a number, not {raw!r}")
    if integer and not isinstance(raw, int):
        raise ConfigError(key, f"must be an integer, not {raw!r}")
    # Range first: an int compares exactly with any float, while isfinite() or float() of an
    # int of 400 digits raises OverflowError.
    if (isinstance(raw, float) and not math.isfinite(raw)) or not lo <= raw <= hi:
        raise ConfigError(key, f"{_short(raw)} is outside {lo:g}..{hi:g}")
    return raw if integer else float(raw)


def _short(raw: int | float) -> str:
    if isinstance(raw, int) and abs(raw).bit_length() > 64:  # do not echo 400 digits
        return f"an integer of {len(str(abs(raw)))} digits"
    return repr(raw)


# ---- locating the key of an error tomllib reports without one -------------------------------

_LONG_DIGITS = re.compile(r"[0-9_]{4000,}")
_HEADER = re.compile(r"^\s*\[\[?\s*([^\]]+?)\s*\]")
_ASSIGN = re.compile(r"^\s*([^=\s]+)\s*=")


def _has_long_digits(line: str) -> bool:
    return _LONG_DIGITS.search(line) is not None


def _is_deep(line: str) -> bool:
    return line.count("[") + line.count("{") > 100


def _key_at(text: str, bad: Callable[[str], bool]) -> str:
    """The dotted key of the first line that `bad` flags, from the [section] above it."""
    section = ""
    key = "<config>"
    for line in text.splitlines():
        assign = _ASSIGN.match(line)
        if assign is not None:
            key = f"{section}.{assign.group(1)}" if section else assign.group(1)
        if bad(line):
            return key
        if assign is None and (header := _HEADER.match(line)) is not None:
            section = header.group(1).strip()
    return key


def _columns(raw: Any, key: str) -> dict[str, int]:
    table = _table(raw, key)
    _reject_unknown(table, dict.fromkeys(CROP_COLUMN_NAMES), f"{key}.")
    cols = {name: _number(v, f"{key}.{name}", 0, 63, integer=True) for name, v in table.items()}
    if "sensor_id" not in cols:
        raise ConfigError(f"{key}.sensor_id", "the sensor id column is required")
    if "ndvi" not in cols and not {"red", "nir"} <= cols.keys():
        raise ConfigError(key, "needs an ndvi column, or red and nir columns to compute NDVI")
    if len(set(cols.values())) != len(cols):
        raise ConfigError(key, "two names map to the same column")
    return cols


def _can_ids(raw: Any, key: str) -> dict[str, int]:
    table = _table(raw, key)
    _reject_unknown(table, dict.fromkeys(CONFIGURABLE_IDS), f"{key}.")
    ids = dict(CanConfig().ids)
    for name, v in table.items():
        ids[name] = _number(v, f"{key}.{name}", 0, 0x1FFFFFFF, integer=True)
    if len(set(ids.values())) != len(ids):
        raise ConfigError(key, "two frames share one identifier")
    return ids


def _can_options(raw: Any, key: str) -> dict[str, Any]:
    table = _table(raw, key)
    for name, value in table.items():
        if not name.isidentifier():
            raise ConfigError(f"{key}.{name}", "must be a python-can keyword argument name")
        if name in ("interface", "channel", "bitrate"):
            raise ConfigError(f"{key}.{name}", f"is set by can.{name}")
        if not isinstance(value, bool | int | float | str):
            raise ConfigError(
                f"{key}.{name}", f"must be a string, number or boolean, not {value!r}"
            )
    return dict(table)


def _ecu(table: dict[str, Any]) -> EcuConfig:
    _reject_unknown(table, ECU_KEYS, "ecu.")
    overrides: dict[str, float] = {}
    for name, raw in table.items():
        if name == "gnss_lag_ms" and raw == GNSS_LAG_AUTO:
            continue  # the default: the ECU learns the lag
        spec = ECU_KEYS[name]
        overrides[name] = _number(raw, f"ecu.{name}", spec.minimum, spec.maximum, spec.integer)
    return EcuConfig(overrides=overrides)


def _rate(table: dict[str, Any]) -> RateConfig:
    subs = {
        "linear": LinearRateConfig,
        "table": TableRateConfig,
        "sufficiency": SufficiencyRateConfig,
    }
    flat = {k: v for k, v in table.items() if k not in subs}
    base: RateConfig = _section(RateConfig, flat, "rate")
    built: dict[str, Any] = {}
    for name, cls in subs.items():
        if name not in table:
            continue
        sub = _table(table[name], f"rate.{name}")
        if name == "table":
            built[name] = TableRateConfig(points=_points(sub))
        else:
            built[name] = _section(cls, sub, f"rate.{name}")
    return dataclasses.replace(base, **built)


def _points(table: dict[str, Any]) -> tuple[tuple[float, float], ...]:
    _reject_unknown(table, {"points": None}, "rate.table.")
    raw = table.get("points", [])
    key = "rate.table.points"
    if not isinstance(raw, list) or len(raw) < 2:
        raise ConfigError(key, "needs at least two [ndvi, kg_ha] points")
    points: list[tuple[float, float]] = []
    for i, p in enumerate(raw):
        if not isinstance(p, list) or len(p) != 2:
            raise ConfigError(f"{key}[{i}]", f"must be [ndvi, kg_ha], not {p!r}")
        ndvi = _number(p[0], f"{key}[{i}]", -1.0, 1.0, integer=False)
        rate = _number(p[1], f"{key}[{i}]", 0.0, 1200.0, integer=False)
        if points and ndvi <= points[-1][0]:
            raise ConfigError(f"{key}[{i}]", "NDVI values must increase strictly")
        points.append((ndvi, rate))
    return tuple(points)


def _cross_check(cfg: TerminalConfig) -> None:
    if cfg.speed.cv_window > cfg.speed.queue_len:
        raise ConfigError("speed.cv_window", "must not exceed speed.queue_len")
    if cfg.crop.ndvi_min >= cfg.crop.ndvi_max:
        raise ConfigError("crop.ndvi_min", "must be below crop.ndvi_max")
    for section, src in (("gnss", cfg.gnss), ("crop", cfg.crop)):
        if src.source == "file" and not src.path:
            raise ConfigError(f"{section}.path", "is required when source = 'file'")
        if src.source == "serial" and not src.port:
            raise ConfigError(f"{section}.port", "is required when source = 'serial'")
    if cfg.gnss.source == "stdin" and cfg.crop.source == "stdin":
        raise ConfigError("crop.source", "gnss already reads stdin")
    # Two readers of one serial port would each get part of the bytes, and both garble.
    ports = {
        f"{name}.port": src.port
        for name, src in (("gnss", cfg.gnss), ("crop", cfg.crop))
        if src.source == "serial"
    }
    if cfg.can.interface == "slcan":
        ports["can.channel"] = cfg.can.channel
    seen: dict[str, str] = {}
    for key, port in ports.items():
        if port in seen:
            raise ConfigError(key, f"{port} is {seen[port]} too: one device per port")
        seen[port] = key
    lin = cfg.rate.linear
    if lin.ndvi_0 == lin.ndvi_1:
        raise ConfigError("rate.linear.ndvi_1", "must differ from rate.linear.ndvi_0")
    if lin.min_kg_ha > lin.max_kg_ha:
        raise ConfigError("rate.linear.min_kg_ha", "must not exceed rate.linear.max_kg_ha")
    if not cfg.can.interface:
        raise ConfigError("can.interface", "must name a python-can interface")
    _check_display(cfg.display)
    _check_timing(cfg)


def _check_display(d: DisplayConfig) -> None:
    if not d.host:
        raise ConfigError("display.host", "must be an address to listen on")
    if d.pin and not (d.pin.isdigit() and d.pin.isascii() and 4 <= len(d.pin) <= 12):
        raise ConfigError("display.pin", "must be 4 to 12 digits")
    if d.host not in LOCAL_HOSTS and not d.pin:
        # Anyone on the network could start the meters or change a setting.
        raise ConfigError("display.pin", f"is required when display.host is {d.host!r}")
    for name in d.allowed_hosts:
        if not _HOST_NAME.fullmatch(name):
            raise ConfigError("display.allowed_hosts", f"{name!r} is not a host name")
    for proxy in d.trusted_proxies:
        try:
            ipaddress.ip_network(proxy, strict=False)
        except ValueError:
            raise ConfigError(
                "display.trusted_proxies", f"{proxy!r} is not an address or network"
            ) from None


_HOST_NAME = re.compile(
    r"(?=.{1,253}$)[A-Za-z0-9]([A-Za-z0-9-]{0,62}[A-Za-z0-9])?"
    r"(\.[A-Za-z0-9]([A-Za-z0-9-]{0,62}[A-Za-z0-9])?)*\.?"
)


def _check_timing(cfg: TerminalConfig) -> None:
    """The terminal's periods against the ECU's timeouts ([ecu] or the ECU's defaults): a
    mismatch would stop the meters or drop the ECU between two frames, every time."""
    ms = {k: cfg.ecu.overrides.get(k, ECU_KEYS[k].default) for k in ECU_TIMING}
    can = cfg.can
    if can.command_period_s * 1000 >= ms["cmd_timeout_ms"]:
        raise ConfigError(
            "can.command_period_s",
            f"must be shorter than the ECU's command timeout (ecu.cmd_timeout_ms = "
            f"{ms['cmd_timeout_ms']:g} ms), or the meters stop between two commands",
        )
    if not can.send_on_gnss and can.command_period_s * 1000 >= ms["gnss_timeout_ms"]:
        raise ConfigError(
            "can.command_period_s",
            f"must be shorter than the ECU's GNSS timeout (ecu.gnss_timeout_ms = "
            f"{ms['gnss_timeout_ms']:g} ms), or the GNSS speed goes stale between two commands; "
            "or set can.send_on_gnss = true",
        )
    if can.ecu_timeout_s * 1000 < 2 * ms["status_period_ms"]:
        raise ConfigError(
            "can.ecu_timeout_s",
            f"must be at least two ECU status periods (ecu.status_period_ms = "
            f"{ms['status_period_ms']:g} ms), or the ECU is reported lost between its frames",
        )


def _ids_toml() -> str:
    """The [can.ids] lines of the default file: the DBC's identifiers."""
    notes = {"cal_command": "   # calibration (catch test) command and its status"}
    return "".join(
        f"{k} = 0x{getattr(DEFAULT_IDS, k):08X}{notes.get(k, '')}\n" for k in CONFIGURABLE_IDS
    )


_IDS_TOML = _ids_toml()
DEFAULT_TOML = (
    """\
# topdress terminal configuration. Every key is optional; shown here with its default.

[machine]
width_m = 3.6              # working width, m (6 rows x 0.60 m)
rows = 6                   # for the record only: width_m is what the rate works with
layers = 2                 # fertilizer layers (upper, lower), each with its meter and fan
kg_per_rev_upper = 0.3     # fertilizer per metering-wheel revolution, kg/rev
kg_per_rev_lower = 0.3
wheel_radius_m = 0.0615    # ground wheel, 12.3 cm diameter
wheel_ppr = 500            # ground-wheel encoder pulses per revolution
fan_rpm = 3000             # fan target sent in every command frame, rpm
outlet_along_m = 0.0       # meters' outlet from the GNSS antenna: forward (behind < 0), m
outlet_across_m = 0.0      # and to the right (left < 0), m

[speed]
mode = "fused"             # fused (estimate from both) | paper (dual rule) | wheel | gnss
queue_len = 5              # N, wheel-speed queue length
cv_window = 5              # n, last speeds of the queue used for the CV
cv_threshold_pct = 4.2     # CV below this = uniform motion
switch_speed_kmh = 6.0     # V_Grmax: GNSS used above this speed in uniform motion
switch_compare = "gnss"    # which speed is compared with switch_speed_kmh: gnss | wheel
min_work_speed_kmh = 0.5   # below this the meters stop

[ecu]
# ECU parameters by their td_params_t name; only the keys set here are pushed, the ECU
# keeps its defaults for the others. Keys: pid_kp pid_ki pid_kd pid_kff cmd_timeout_ms
# gnss_timeout_ms wheel_update_ms wheel_samples meter_counts_per_rev fan_min_rpm fan_ppr
# enc_fault_gnss_kmh enc_fault_time_ms blocked_time_ms status_period_ms slip_comp gnss_lag_ms
# fused_jerk_ms3 fused_gnss_std_kmh fused_wheel_noise_pct wheel_stop_ms drive_adapt
# meter_tau_ms gnss_lag_auto
# pid_kp = 0.02
gnss_lag_ms = "auto"       # GNSS lag: auto = learned on the machine (kept per receiver), or ms

[gnss]
source = "serial"          # serial | file | stdin
port = "/dev/ttyUSB0"
baud = 9600
path = ""                  # NMEA file when source = "file"
replay_interval_s = 0.1    # pause between the lines of that file (0 = as fast as read)
rmc_timeout_s = 1.5        # VTG speed used only when no RMC came for this long
stale_s = 2.0              # a GNSS speed older than this is sent as "not available"
dead_reckon_m = 10.0       # without fixes the outlet is carried this far, then "unknown"
unknown_kg_ha = -1.0       # rate while the position is unknown; -1 = the last in the field

[crop]
source = "serial"          # serial | file | stdin
port = "/dev/ttyUSB1"
baud = 38400
path = ""                  # sensor line file when source = "file"
replay_interval_s = 0.025  # 4 sensors at 10 Hz
sensors = 4                # sensor ids 1..sensors; their mean NDVI drives the rate
ndvi_min = 0.0             # NDVI outside [ndvi_min, ndvi_max] is rejected
ndvi_max = 1.0
stale_s = 1.0              # a sensor silent for longer is left out of the mean
sensor_to_meter_m = 2.0    # along-track distance from the sensors to the meter outlets

[crop.columns]             # field index (0-based) of each value in a sensor line
sensor_id = 0
red = 1
red_edge = 2
nir = 3
ndre = 4
ndvi = 5

[rate]
model = "linear"           # linear | table | sufficiency
split_upper = 0.5          # fraction of the total rate given to the upper layer

[rate.linear]              # product kg/ha through two points, clamped
ndvi_0 = 0.3
rate_0_kg_ha = 450.0
ndvi_1 = 0.8
rate_1_kg_ha = 150.0
min_kg_ha = 0.0
max_kg_ha = 600.0

[rate.table]               # [NDVI, product kg/ha], NDVI increasing; constant beyond the ends
points = [[0.3, 450.0], [0.5, 350.0], [0.8, 150.0]]

[rate.sufficiency]         # Holland-Schepers sufficiency index, N in kg N/ha
reference = "virtual"      # virtual (percentile of NDVI seen) | nrich (N-rich strip)
ndvi_ref = 0.85            # N-rich strip NDVI, used when reference = "nrich"
percentile = 95.0
min_samples = 50           # virtual reference needs this many readings; until then:
fallback_kg_ha = 300.0     # product rate applied until the virtual reference exists
mz_opt_n_kg_ha = 200.0     # economic optimum N for the management zone
n_pre_kg_ha = 50.0         # N applied before the crop sensing
n_credits_kg_ha = 0.0      # N credits (previous crop, manure, ...)
delta_si = 0.3             # 1 - SI of unfertilized crop
max_n_kg_ha = 200.0
n_fraction = 0.46          # N fraction of the product (urea 0.46)

[can]
# python-can interface: socketcan (can0 on Linux), slcan, pcan, kvaser, udp_multicast...
# "virtual" is the simulator's in-process bus: no real ECU can answer there.
interface = "virtual"
channel = "topdress"
bitrate = 250000
command_period_s = 0.5     # command frame period
send_on_gnss = false       # also send a command at once on each new GNSS speed
send_on_rate = false       # also send it at once when a rate changes (at most every 100 ms)
ecu_timeout_s = 0.5        # no ECU status for this long = ECU lost
implement = "topdress"     # topdress (its ECU) | isobus (any ISOBUS implement; see [isobus])

[can.ids]
"""
    + _IDS_TOML
    + """
[can.options]              # the adapter's own python-can options, e.g. for slcan:
# tty_baudrate = 115200

[log]
dir = "topdress-sessions"  # one SQLite file per session
min_free_mib = 50          # free space on the log's disk below this: an alarm, MiB

[display]
refresh_s = 0.5            # live status redrawn every 0.2..2 s on a terminal (1 line/s to a pipe)
enabled = true             # serve the operator display in a browser
host = "127.0.0.1"         # only this PC; any other address (0.0.0.0) needs a pin
port = 8080
pin = ""                   # 4..12 digits: needed to operate (start, stop, settings) from afar
language = "en"            # en | zh
allowed_hosts = []         # names it answers to besides IP addresses and localhost
trusted_proxies = []       # proxies whose X-Forwarded-For is believed, e.g. ["127.0.0.1"]
kiosk_token_file = ""      # the cab's browser opens /?kiosk=<the file's token>: no PIN for it only
kiosk_user = ""            # or: the cab's browser runs as this local user, no token needed
lost_pause_s = 10.0        # no operator display this long while metering: pause (0: alarm only)

[operator]
autostart = false          # true: the meters start at once, without the operator (headless)
off_rate_pct = 10.0        # a metering speed this far off its target...
off_rate_s = 5.0           # ...for longer than this raises the off-rate alarm
fan_check_s = 10.0         # how long the fan check runs the fans
reaction_ms = 200.0        # look-ahead calibration: the operator's reaction, taken off each press
counters_file = "counters.json"  # field and season counters, in log.dir

[prescription]             # a prescription map as rate source (see docs/maps.md)
path = ""                  # .gpkg, .shp, .geojson polygons or ISOXML TASKDATA.XML; "" = none
layer = ""                 # layer of a multi-layer file ("" = the first)
attribute = "rate"         # the polygons' rate attribute
units = "kg/ha"            # of that attribute: kg/ha | lb/ac | t/ha (ISOXML: from its DDI)
mode = "alone"             # alone (the map's rate) | bound (NDVI model within the zone's min/max)
min_attribute = "min_rate" # bound mode: the zone's limits
max_attribute = "max_rate"
outside_kg_ha = 0.0        # outside every zone, and while the position is not known
outside_alarm_m = 50.0     # metering farther than this outside the map: wrong-field alarm; 0 = off

[boundary]                 # the field boundary: meters off outside it and in the headland
path = ""                  # .gpkg, .shp, .geojson polygons or ISOXML TASKDATA.XML
layer = ""
headland_m = 0.0           # headland strip inside the boundary, m
outside_alarm_m = 50.0     # metering farther than this outside it: wrong-field alarm; 0 = off

[lookahead]
command_ms = 0             # the terminal's command path (program cycle + command period)
meter_ms = 0               # meter response; also the ECU's LeadMeter
airline_ms = 0             # air-line transport; also the ECU's LeadAirLine
stop_ms = 0                # the ECU's look-ahead while the speed falls (LeadStop); 0 = as rising

[office]                   # the farm office's database (docs/office.md); url = "" works alone
url = ""                   # e.g. "postgresql://cab@office.lan/topdress" (passwords: ~/.pgpass)
interval_s = 300.0         # between two syncs of the log directory (a thread of its own)
machine = ""               # this machine's id in the office; "" = the host's name
farm = ""                  # refuse an office database of another farm; "" = not checked
product = "fertilizer"     # what the machine spreads, as the office's swaths name it

[isobus]                   # can.implement = "isobus": the terminal is the Task Controller
tc_address = 247           # the address claimed first (0xF7); 128..247 if it is taken
tc_identity = 1            # the TC NAME's identity number: different in each cab on one bus
density_kg_l = 1.0         # volume-per-area products (DDI 1): kg/ha -> L/ha by this density
section_control = true     # sections off over ground covered and outside the boundary
overlap_pct = 50.0         # a section goes off when more of its ground ahead is done/outside
section_look_m = 1.0       # the strip of ground each section looks at, m (past its delay)
coverage_hours = 24.0      # sessions of the same field this recent count as covered; 0 = none
ecu_manufacturer = 0       # the topdress ECU's NAME manufacturer code (FW_ISOBUS_MANUFACTURER)
"""
)
