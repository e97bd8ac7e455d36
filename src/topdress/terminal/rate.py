"""NDVI -> fertilizer rate models (kg/ha of product end to end) and the split between layers.

Models share one small interface (RateModel): `rate_kg_ha(ndvi)` gives the total product
rate for an NDVI, `observe(ndvi)` shows the model every NDVI the sensors see (only the virtual
reference of the sufficiency model learns from it). `build_rate_model(cfg.rate)` picks the one
the configuration names. `SiteRate` combines it with a prescription map and a field boundary.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from topdress.config import (
    LinearRateConfig,
    RateConfig,
    SufficiencyRateConfig,
    TableRateConfig,
    TerminalConfig,
)
from topdress.errors import MapError

if TYPE_CHECKING:  # GDAL, shapely and PROJ cost ~60 MB: loaded only when a map is configured
    from topdress.geo.boundary import FieldBoundary
    from topdress.geo.prescription import RateMap

# Largest rate one layer's command field carries (PcCommand UpperRate/LowerRate, 0.01 kg/ha).
MAX_LAYER_KG_HA = 600.0


class RateModel(Protocol):
    def rate_kg_ha(self, ndvi: float) -> float: ...

    def observe(self, ndvi: float) -> None: ...


class LinearRate:
    """The line through (ndvi_0, rate_0) and (ndvi_1, rate_1), clamped to [min, max]."""

    def __init__(self, cfg: LinearRateConfig) -> None:
        self.cfg = cfg
        self.slope = (cfg.rate_1_kg_ha - cfg.rate_0_kg_ha) / (cfg.ndvi_1 - cfg.ndvi_0)

    def rate_kg_ha(self, ndvi: float) -> float:
        c = self.cfg
        rate = c.rate_0_kg_ha + self.slope * (ndvi - c.ndvi_0)
        return min(max(rate, c.min_kg_ha), c.max_kg_ha)

    def observe(self, ndvi: float) -> None:
        del ndvi  # a fixed line learns nothing


class TableRate:
    """Piecewise-linear between (NDVI, kg/ha) points, constant beyond the first and last."""

    def __init__(self, cfg: TableRateConfig) -> None:
        self.ndvi = np.array([p[0] for p in cfg.points])
        self.rate = np.array([p[1] for p in cfg.points])

    def rate_kg_ha(self, ndvi: float) -> float:
        return float(np.interp(ndvi, self.ndvi, self.rate))

    def observe(self, ndvi: float) -> None:
        del ndvi


class VirtualReference:
    """A percentile of every NDVI seen so far, in constant memory: a histogram of 0.001-wide
    bins over -1..1 (the answer is within half a bin, 0.0005, of the exact percentile)."""

    BIN = 0.001

    def __init__(self, percentile: float) -> None:
        self.percentile = percentile
        self.counts = np.zeros(round(2.0 / self.BIN), dtype=np.int64)
        self.n = 0

    def observe(self, ndvi: float) -> None:
        if not math.isfinite(ndvi):
            return
        i = min(max(int((ndvi + 1.0) / self.BIN), 0), len(self.counts) - 1)
        self.counts[i] += 1
        self.n += 1

    def value(self) -> float | None:
        if self.n == 0:
            return None
        rank = self.percentile / 100.0 * self.n
        i = int(np.searchsorted(np.cumsum(self.counts), max(rank, 1.0)))
        return -1.0 + (i + 0.5) * self.BIN


class SufficiencyRate:
    """Holland & Schepers (2010) sufficiency-index model.

    SI = NDVI / NDVI_ref, the reference being an N-rich strip (`ndvi_ref`) or the virtual
    reference (a percentile of the NDVI seen so far, once `min_samples` are seen). Nitrogen:
    N = (MZ_opt - N_pre - N_credits) * sqrt((1 - SI) / delta_SI), clamped to [0, max_n];
    SI >= 1 gives 0. Product = N / n_fraction. Until a reference exists, fallback_kg_ha.
    """

    def __init__(self, cfg: SufficiencyRateConfig) -> None:
        self.cfg = cfg
        self.virtual = VirtualReference(cfg.percentile) if cfg.reference == "virtual" else None

    def reference(self) -> float | None:
        if self.virtual is None:
            return self.cfg.ndvi_ref
        if self.virtual.n < self.cfg.min_samples:
            return None
        ref = self.virtual.value()
        return ref if ref is not None and ref > 0.0 else None

    def sufficiency_index(self, ndvi: float) -> float | None:
        ref = self.reference()
        return None if ref is None else ndvi / ref

    def n_rate_kg_ha(self, ndvi: float) -> float | None:
        si = self.sufficiency_index(ndvi)
        if si is None:
            return None
        if si >= 1.0:
            return 0.0
        c = self.cfg
        need = max(c.mz_opt_n_kg_ha - c.n_pre_kg_ha - c.n_credits_kg_ha, 0.0)
        return min(need * math.sqrt((1.0 - si) / c.delta_si), c.max_n_kg_ha)

    def rate_kg_ha(self, ndvi: float) -> float:
        n = self.n_rate_kg_ha(ndvi)
        return self.cfg.fallback_kg_ha if n is None else n / self.cfg.n_fraction

    def observe(self, ndvi: float) -> None:
        if self.virtual is not None:
            self.virtual.observe(ndvi)


def build_rate_model(cfg: RateConfig) -> RateModel:
    if cfg.model == "linear":
        return LinearRate(cfg.linear)
    if cfg.model == "table":
        return TableRate(cfg.table)
    return SufficiencyRate(cfg.sufficiency)


@dataclass(frozen=True)
class LayerRates:
    """Product rate of each layer, kg/ha. `limited` is True when a layer was cut to the
    largest rate its command field carries (MAX_LAYER_KG_HA)."""

    upper_kg_ha: float
    lower_kg_ha: float
    limited: bool = False

    @property
    def total_kg_ha(self) -> float:
        return self.upper_kg_ha + self.lower_kg_ha


def split_layers(total_kg_ha: float, split_upper: float, layers: int = 2) -> LayerRates:
    """`split_upper` of the total to the upper layer, the rest to the lower; a one-layer
    machine puts everything in the upper layer."""
    total = max(total_kg_ha, 0.0)
    upper = total if layers == 1 else total * split_upper
    lower = total - upper
    limited = upper > MAX_LAYER_KG_HA or lower > MAX_LAYER_KG_HA
    return LayerRates(min(upper, MAX_LAYER_KG_HA), min(lower, MAX_LAYER_KG_HA), limited)


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
    - Boundary: 0 (meters off) in the headland strip, outside the field, and while the
      position is not known (it cannot be told to be inside).
    """

    def __init__(
        self,
        model: RateModel,
        prescription: RateMap | None = None,
        boundary: FieldBoundary | None = None,
        mode: str = "alone",
        outside_kg_ha: float = 0.0,
    ) -> None:
        self.model = model
        self.prescription = prescription
        self.boundary = boundary
        self.mode = mode
        self.outside_kg_ha = outside_kg_ha

    def decide(
        self,
        ndvi: float | None,
        outlet: tuple[float, float] | None,
        ahead: tuple[float, float] | None = None,
    ) -> SiteDecision:
        """`outlet`: where the outlets are (the boundary's zone); `ahead`: where they will be
        when the product commanded now lands (the look-ahead; the prescription is looked up
        there, as the NDVI is), None = at the outlet."""
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


def build_site_rate(cfg: TerminalConfig, model: RateModel, maps: Maps | None = None) -> SiteRate:
    """The site rate over `maps`, or over the configured files loaded now."""
    m = maps if maps is not None else load_maps(cfg)
    return SiteRate(
        model, m.prescription, m.boundary, cfg.prescription.mode, cfg.prescription.outside_kg_ha
    )
