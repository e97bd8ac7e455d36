"""A field with a smooth spatial NDVI pattern, and the crop sensors reading it."""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

from topdress.sim.cplant import ffi, lib


@dataclass(frozen=True)
class FieldParams:
    """NDVI(x, y) = mean + a sum of smooth waves and patches, clipped to 0.15..0.92.

    Wavelengths of tens of metres, like the nitrogen stress patterns at V6-V8 corn.
    """

    ndvi_mean: float = 0.62
    wave_amp: float = 0.10
    wavelength_m: float = 45.0
    patches: int = 6
    patch_amp: float = 0.12
    patch_radius_m: float = 12.0
    size_m: float = 200.0
    nir_mean: float = 0.42


class Field:
    """The NDVI pattern of one field (seeded); ndvi() is computed in C (csrc/plant.c,
    tdsim_field_ndvi), the same arithmetic as the formula of FieldParams."""

    def __init__(self, p: FieldParams, seed: int) -> None:
        rng = random.Random(seed)
        self._phase = (rng.uniform(0, 2 * math.pi), rng.uniform(0, 2 * math.pi))
        self._patches = [
            (
                rng.uniform(0, p.size_m),
                rng.uniform(0, p.size_m),
                rng.uniform(-p.patch_amp, p.patch_amp),
            )
            for _ in range(p.patches)
        ]
        self._s = ffi.new("tdsim_field_t *")
        self._patch_arr = ffi.new("double[]", [v for patch in self._patches for v in patch])
        self._s.patches, self._s.n_patches = self._patch_arr, len(self._patches)
        self._s.phase0, self._s.phase1 = self._phase
        self.p = p
        self._ndvi = lib.tdsim_field_ndvi

    @property
    def p(self) -> FieldParams:
        return self._p

    @p.setter
    def p(self, p: FieldParams) -> None:
        self._p = p
        s = self._s
        s.ndvi_mean, s.wave_amp = p.ndvi_mean, p.wave_amp
        s.k = 2 * math.pi / p.wavelength_m
        s.two_r2 = 2 * (p.patch_radius_m * p.patch_radius_m)

    def ndvi(self, x: float, y: float) -> float:
        v: float = self._ndvi(self._s, x, y)
        return v


@dataclass(frozen=True)
class CropSensorParams:
    """An active canopy sensor (670/730/780 nm) as logged by the data logger."""

    period_s: float = 0.5
    refl_sd: float = 0.004  # reflectance noise per band
    dead_at_s: float = -1.0  # fault knob: sensor stops reporting; < 0 never
    garble_prob: float = 0.0  # fault knob: probability that a line is corrupted on the wire


class CropSensor:
    """Sensor `sensor_id` (1..4) mounted `offset_m` to the right of the machine centre and
    `ahead_m` ahead of the outlets (the tractor's x, y is the outlets' position)."""

    def __init__(
        self, sensor_id: int, offset_m: float, p: CropSensorParams, seed: int, ahead_m: float = 0.0
    ) -> None:
        self.sensor_id = sensor_id
        self.offset_m = offset_m
        self.p = p
        self._rng = random.Random(seed * 10 + sensor_id)
        # stagger the four sensors so their lines interleave as on the logger
        self.next_t = p.period_s * sensor_id / 4.0
        self.last_ndvi = 0.0
        self.ahead_m = ahead_m  # along-track distance ahead of the outlets (the reference point)

    def step(self, t: float, field: Field, x: float, y: float, heading: float) -> str | None:
        """Return a line when a reading is due."""
        if t + 1e-9 < self.next_t:
            return None
        self.next_t += self.p.period_s
        if 0.0 <= self.p.dead_at_s <= t:
            return None
        a = self.ahead_m
        sx = x + self.offset_m * math.cos(heading) + a * math.sin(heading)
        sy = y - self.offset_m * math.sin(heading) + a * math.cos(heading)
        true_ndvi = field.ndvi(sx, sy)
        g = self._rng.gauss
        sd = self.p.refl_sd
        nir = max(0.05, field.p.nir_mean + g(0.0, sd))
        red = max(0.001, nir * (1.0 - true_ndvi) / (1.0 + true_ndvi) + g(0.0, sd * 0.3))
        edge = max(0.001, nir * (0.55 - 0.25 * true_ndvi) + g(0.0, sd))
        ndvi = (nir - red) / (nir + red)
        ndre = (nir - edge) / (nir + edge)
        self.last_ndvi = ndvi
        line = f"{self.sensor_id},{red:.4f},{edge:.4f},{nir:.4f},{ndre:.4f},{ndvi:.4f}\r\n"
        if self.p.garble_prob > 0.0 and self._rng.random() < self.p.garble_prob:
            cut = self._rng.randrange(1, len(line) - 2)
            line = line[:cut] + "#" + line[cut + 1 :]
        return line
