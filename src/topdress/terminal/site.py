"""The rate for where the outlet is: the NDVI model, a prescription map and a field boundary,
combined as configured."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from topdress.config import RateConfig, TerminalConfig
from topdress.crop.rate import RateModel, build_rate_model
from topdress.errors import MapError
from topdress.view.snapshot import ZONE_UNKNOWN

if TYPE_CHECKING:  # GDAL, shapely and PROJ cost ~60 MB: loaded only when a map is configured
    from topdress.geo.boundary import FieldBoundary
    from topdress.geo.prescription import RateMap


#: The zone while the position is dead reckoned past its limit.
UNKNOWN: Final = ZONE_UNKNOWN


@dataclass(frozen=True)
class SiteDecision:
    """The total product rate for where the outlet is, and why."""

    total_kg_ha: float
    zone: str | None = None  # field boundary zone; None without a boundary (or position)
    prescription_kg_ha: float | None = None  # the map's rate there; None outside or no map
    used_ndvi: bool = True  # the NDVI model set (or bounded) the rate


class SiteRate:
    """The NDVI model, a prescription map and a field boundary, combined as configured.

    - No map: the NDVI model's rate (0 without an NDVI).
    - `prescription.mode = "alone"`: the map's rate at the outlet; outside every zone, and
      while the outlet's position is not known, `prescription.outside_kg_ha`.
    - `prescription.mode = "bound"`: the NDVI model's rate, limited to the zone's min and
      max; the zone's rate while there is no NDVI; outside every zone `outside_kg_ha`.
    - Boundary: 0 (meters off) in the headland strip, outside the field, and before the
      first fix (it cannot be told to be inside).
    - Position lost (`lost`: dead reckoned past `gnss.dead_reckon_m`): zone "unknown", the
      rate `unknown_kg_ha`, or (< 0) the last one decided in the field. A position carried
      too far on an old heading (a turn) would switch the meters off inside the field: the
      boundary's switch-off never acts on it.
    """

    def __init__(
        self,
        model: RateModel,
        prescription: RateMap | None = None,
        boundary: FieldBoundary | None = None,
        mode: str = "alone",
        outside_kg_ha: float = 0.0,
        unknown_kg_ha: float = -1.0,
    ) -> None:
        self.model = model
        self.prescription = prescription
        self.boundary = boundary
        self.mode = mode
        self.outside_kg_ha = outside_kg_ha
        self.unknown_kg_ha = unknown_kg_ha
        self.last_field_kg_ha = 0.0  # the last rate decided with the outlet in the field

    def retune(self, rate: RateConfig) -> None:
        """A changed [rate] section: the NDVI model is built anew (the prescription and the
        boundary are read at start only)."""
        self.model = build_rate_model(rate)

    def decide(
        self,
        ndvi: float | None,
        outlet: tuple[float, float] | None,
        ahead: tuple[float, float] | None = None,
        lost: bool = False,
    ) -> SiteDecision:
        """`outlet`: where the outlets are (the boundary's zone); `ahead`: where they will be
        when the product commanded now lands (the look-ahead; the prescription is looked up
        there, as the NDVI is), None = at the outlet; `lost`: the position is dead reckoned
        past its limit."""
        if lost:
            rate = self.unknown_kg_ha if self.unknown_kg_ha >= 0.0 else self.last_field_kg_ha
            return SiteDecision(rate, UNKNOWN, None, used_ndvi=False)
        decision = self._decide(ndvi, outlet, ahead)
        if decision.zone == "field" or (decision.zone is None and outlet is not None):
            self.last_field_kg_ha = decision.total_kg_ha
        return decision

    def _decide(
        self,
        ndvi: float | None,
        outlet: tuple[float, float] | None,
        ahead: tuple[float, float] | None,
    ) -> SiteDecision:
        zone = None
        if self.boundary is not None:
            zone = self.boundary.zone(*outlet) if outlet is not None else None
            if zone != "field":
                return SiteDecision(0.0, zone, None, used_ndvi=False)
        if self.prescription is None:
            rate = self.model.rate_kg_ha(ndvi) if ndvi is not None else 0.0
            return SiteDecision(rate, zone)
        where = ahead if ahead is not None and outlet is not None else outlet
        hit = self.prescription.lookup(*where) if where is not None else None
        if hit is None:
            return SiteDecision(self.outside_kg_ha, zone, None, used_ndvi=False)
        if self.mode == "alone" or ndvi is None:
            return SiteDecision(hit.rate_kg_ha, zone, hit.rate_kg_ha, used_ndvi=False)
        rate = self.model.rate_kg_ha(ndvi)
        rate = min(max(rate, hit.min_kg_ha), hit.max_kg_ha)
        return SiteDecision(rate, zone, hit.rate_kg_ha)


@dataclass(frozen=True)
class Maps:
    """The prescription and the boundary the configuration names (None: none named)."""

    prescription: RateMap | None = None
    boundary: FieldBoundary | None = None

    def describe(self) -> list[str]:
        """One line per map: what was loaded (for `config check` and the start of `run`)."""
        out = []
        if self.prescription is not None:
            info = self.prescription.describe()
            out.append(f"prescription: {self.prescription.source}: {info.text()}")
        if self.boundary is not None:
            out.append(f"boundary: {self.boundary.source}: {self.boundary.describe()}")
        return out


@dataclass(frozen=True)
class OffMap:
    """The machine outside a map by more than the map's `outside_alarm_m`."""

    which: str  # "prescription" or "boundary"
    name: str  # the file's name
    distance_m: float  # from the outlet to the map
    limit_m: float


#: Back inside a map's limit only below this share of it: a position wandering about the
#: limit raises the alarm once, not at every crossing.
BACK_INSIDE: Final = 0.8


class MapGuard:
    """Where the machine is against the maps: how far it is from each (said at the first fix)
    and whether it is outside one by more than its limit (the wrong-field alarm).

    The prescription's distance is to its extent (the box around its zones: a map for another
    field is far from it; gaps between zones are not), the boundary's to its polygon."""

    def __init__(self, maps: Maps, prescription_m: float = 0.0, boundary_m: float = 0.0) -> None:
        self._parts: list[tuple[str, str, Callable[[float, float], float], float]] = []
        if maps.prescription is not None:
            info = maps.prescription.describe()  # once: a large map's extent costs a pass
            name = maps.prescription.source.name
            self._parts.append(("prescription", name, info.distance_m, prescription_m))
        if maps.boundary is not None:
            b = maps.boundary
            self._parts.append(("boundary", b.source.name, b.distance_m, boundary_m))
        self._outside: set[str] = set()

    def distances(self, lat: float, lon: float) -> list[tuple[str, str, float]]:
        """(which, file name, metres from (lat, lon); 0 inside) for each map."""
        return [(which, name, dist(lat, lon)) for which, name, dist, _ in self._parts]

    def outside(self, lat: float, lon: float) -> tuple[OffMap, ...]:
        """The maps (lat, lon) is outside of by more than their limit (a limit of 0: never)."""
        out = []
        for which, name, dist, limit in self._parts:
            if limit <= 0.0:
                continue
            d = dist(lat, lon)
            was = which in self._outside
            if d > limit or (was and d > limit * BACK_INSIDE):
                self._outside.add(which)
                out.append(OffMap(which, name, d, limit))
            else:
                self._outside.discard(which)
        return tuple(out)

    def forget(self) -> None:
        """The position is not known: nothing is judged (and the hysteresis starts afresh)."""
        self._outside.clear()


def load_maps(cfg: TerminalConfig, progress: Callable[[str], None] | None = None) -> Maps:
    """Loads the configured prescription and boundary files (MapError naming the key, the
    file and the feature). `run` and `config check` call it before anything is opened."""
    presc: RateMap | None = None
    boundary: FieldBoundary | None = None
    if cfg.prescription.path:
        from topdress.geo.prescription import load_prescription

        try:
            presc = load_prescription(cfg.prescription, progress)
        except MapError as exc:
            raise MapError(f"prescription.path: {exc}") from exc
    if cfg.boundary.path:
        from topdress.geo.boundary import load_boundary

        try:
            boundary = load_boundary(cfg.boundary)
        except MapError as exc:
            raise MapError(f"boundary.path: {exc}") from exc
    return Maps(presc, boundary)


def build_map_guard(cfg: TerminalConfig, maps: Maps) -> MapGuard:
    return MapGuard(maps, cfg.prescription.outside_alarm_m, cfg.boundary.outside_alarm_m)


def build_site_rate(cfg: TerminalConfig, model: RateModel, maps: Maps | None = None) -> SiteRate:
    """The site rate over `maps`, or over the configured files loaded now."""
    m = maps if maps is not None else load_maps(cfg)
    return SiteRate(
        model,
        m.prescription,
        m.boundary,
        cfg.prescription.mode,
        cfg.prescription.outside_kg_ha,
        cfg.gnss.unknown_kg_ha,
    )
