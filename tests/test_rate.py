"""NDVI -> rate models with worked numbers, the virtual reference and the layer split."""

from __future__ import annotations

import math

import numpy as np
import pytest

from topdress.config import (
    LinearRateConfig,
    SufficiencyRateConfig,
    TableRateConfig,
    loads_config,
)
from topdress.crop.rate import (
    LinearRate,
    SufficiencyRate,
    TableRate,
    VirtualReference,
    build_rate_model,
    split_layers,
)


def test_linear_through_two_points_with_clamps() -> None:
    m = LinearRate(LinearRateConfig())  # (0.3, 450) -> (0.8, 150), clamp 0..600
    assert m.rate_kg_ha(0.3) == pytest.approx(450.0)
    assert m.rate_kg_ha(0.8) == pytest.approx(150.0)
    assert m.rate_kg_ha(0.55) == pytest.approx(300.0)
    assert m.rate_kg_ha(0.05) == pytest.approx(600.0)  # 600 on the line, at the clamp
    assert m.rate_kg_ha(0.0) == pytest.approx(600.0)  # 630 on the line, clamped
    assert m.rate_kg_ha(1.0) == pytest.approx(30.0)
    clamped = LinearRate(LinearRateConfig(min_kg_ha=100.0, max_kg_ha=400.0))
    assert clamped.rate_kg_ha(0.9) == pytest.approx(100.0)
    assert clamped.rate_kg_ha(0.2) == pytest.approx(400.0)


def test_table_interpolates_and_holds_the_ends() -> None:
    m = TableRate(TableRateConfig(points=((0.3, 450.0), (0.5, 350.0), (0.8, 150.0))))
    assert m.rate_kg_ha(0.1) == pytest.approx(450.0)
    assert m.rate_kg_ha(0.4) == pytest.approx(400.0)
    assert m.rate_kg_ha(0.5) == pytest.approx(350.0)
    assert m.rate_kg_ha(0.65) == pytest.approx(250.0)
    assert m.rate_kg_ha(0.95) == pytest.approx(150.0)


@pytest.mark.parametrize(
    ("ndvi", "si", "n_kg_ha"),
    [
        (0.85, 1.0, 0.0),  # as green as the N-rich strip: no N
        (0.90, 0.90 / 0.85, 0.0),  # greener than the reference: none
        (0.765, 0.9, 150.0 * math.sqrt(0.1 / 0.3)),  # 86.60 kg N/ha
        (0.595, 0.7, 150.0),  # SI = 1 - delta_SI: the full (MZ_opt - N_pre)
        (0.51, 0.6, 150.0 * math.sqrt(0.4 / 0.3)),  # 173.21
        (0.34, 0.4, 200.0),  # 212.13 clamped to max_n
    ],
)
def test_holland_schepers_with_an_n_rich_strip(ndvi: float, si: float, n_kg_ha: float) -> None:
    m = SufficiencyRate(SufficiencyRateConfig(reference="nrich", ndvi_ref=0.85))
    assert m.sufficiency_index(ndvi) == pytest.approx(si)
    assert m.n_rate_kg_ha(ndvi) == pytest.approx(n_kg_ha)
    assert m.rate_kg_ha(ndvi) == pytest.approx(n_kg_ha / 0.46)  # as urea


def test_holland_schepers_worked_example_in_product() -> None:
    m = SufficiencyRate(SufficiencyRateConfig(reference="nrich", ndvi_ref=0.85))
    assert m.rate_kg_ha(0.765) == pytest.approx(188.27, abs=0.01)  # 86.60 N / 0.46 urea
    credits = SufficiencyRate(
        SufficiencyRateConfig(reference="nrich", ndvi_ref=0.85, n_credits_kg_ha=30.0)
    )
    assert credits.n_rate_kg_ha(0.595) == pytest.approx(120.0)
    covered = SufficiencyRate(SufficiencyRateConfig(reference="nrich", n_pre_kg_ha=250.0))
    assert covered.n_rate_kg_ha(0.5) == 0.0  # pre-plant N already above the optimum


def test_virtual_reference_percentile_matches_numpy() -> None:
    rng = np.random.default_rng(3)
    values = np.clip(rng.normal(0.70, 0.08, 5000), -1.0, 1.0)
    ref = VirtualReference(95.0)
    assert ref.value() is None
    for v in values:
        ref.observe(float(v))
    ref.observe(float("nan"))  # ignored
    assert ref.n == 5000
    assert ref.value() == pytest.approx(float(np.percentile(values, 95)), abs=0.0015)


def test_virtual_reference_model_waits_for_min_samples() -> None:
    cfg = SufficiencyRateConfig(reference="virtual", percentile=95.0, min_samples=20)
    m = SufficiencyRate(cfg)
    for i in range(19):
        m.observe(0.60 + 0.01 * i)  # 0.60 .. 0.78
    assert m.reference() is None
    assert m.rate_kg_ha(0.6) == pytest.approx(300.0)  # fallback until the reference exists
    m.observe(0.79)
    ref = m.reference()
    assert ref == pytest.approx(0.7805, abs=0.001)  # 19th of 20 values (rank 95 %)
    assert m.n_rate_kg_ha(0.79) == 0.0
    expected_n = 150.0 * math.sqrt((1.0 - 0.6 / ref) / 0.3)
    assert m.rate_kg_ha(0.6) == pytest.approx(expected_n / 0.46)


def test_nrich_model_ignores_observations() -> None:
    m = SufficiencyRate(SufficiencyRateConfig(reference="nrich", ndvi_ref=0.8))
    for _ in range(100):
        m.observe(0.95)
    assert m.reference() == 0.8


def test_build_rate_model_from_config() -> None:
    cfg = loads_config(
        '[rate]\nmodel = "sufficiency"\n[rate.sufficiency]\nreference = "nrich"\nndvi_ref = 0.85\n'
    )
    assert build_rate_model(cfg.rate).rate_kg_ha(0.595) == pytest.approx(150.0 / 0.46)
    table = loads_config('[rate]\nmodel = "table"\n[rate.table]\npoints = [[0.2, 400], [0.6, 0]]')
    assert build_rate_model(table.rate).rate_kg_ha(0.5) == pytest.approx(100.0)
    assert build_rate_model(loads_config("").rate).rate_kg_ha(0.55) == pytest.approx(300.0)


def test_split_between_layers() -> None:
    r = split_layers(300.0, 0.5)
    assert (r.upper_kg_ha, r.lower_kg_ha, r.limited) == (150.0, 150.0, False)
    r = split_layers(400.0, 0.3)
    assert r.upper_kg_ha == pytest.approx(120.0)
    assert r.lower_kg_ha == pytest.approx(280.0)
    assert r.total_kg_ha == pytest.approx(400.0)
    one = split_layers(250.0, 0.3, layers=1)
    assert (one.upper_kg_ha, one.lower_kg_ha) == (250.0, 0.0)
    big = split_layers(1000.0, 0.5)
    assert (big.upper_kg_ha, big.lower_kg_ha, big.limited) == (500.0, 500.0, False)
    over = split_layers(1000.0, 0.8)
    assert (over.upper_kg_ha, over.lower_kg_ha, over.limited) == (600.0, 200.0, True)
    assert split_layers(-5.0, 0.5).total_kg_ha == 0.0
