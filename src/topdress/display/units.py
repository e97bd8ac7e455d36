"""Units the display shows: metric (kg/ha, km/h, ha, kg, m) or US (lb/ac, mph, ac, lb, ft).

Display only: the terminal, the session log and the configuration stay SI whatever the screen
shows; a rate typed on the screen is converted back to kg/ha before it is sent.
"""

from __future__ import annotations

from dataclasses import dataclass

from topdress.i18n import Text, quantities, si_unit, tr

KG_PER_LB = 0.45359237
HA_PER_AC = 0.40468564224
KM_PER_MI = 1.609344
M_PER_FT = 0.3048
LB_AC_PER_KG_HA = HA_PER_AC / KG_PER_LB  # 0.8922
SYSTEMS = ("metric", "imperial")


@dataclass(frozen=True)
class Units:
    system: str = "metric"

    @property
    def imperial(self) -> bool:
        return self.system == "imperial"

    def rate(self, kg_ha: float) -> float:
        return kg_ha * LB_AC_PER_KG_HA if self.imperial else kg_ha

    def rate_to_kg_ha(self, shown: float) -> float:
        return shown / LB_AC_PER_KG_HA if self.imperial else shown

    def speed(self, kmh: float) -> float:
        return kmh / KM_PER_MI if self.imperial else kmh

    def area(self, ha: float) -> float:
        return ha / HA_PER_AC if self.imperial else ha

    def mass(self, kg: float) -> float:
        return kg / KG_PER_LB if self.imperial else kg

    def mass_to_kg(self, shown: float) -> float:
        return shown * KG_PER_LB if self.imperial else shown

    def length(self, m: float) -> float:
        return m / M_PER_FT if self.imperial else m

    @property
    def rate_unit(self) -> str:
        return tr("unit.lbac") if self.imperial else tr("unit.kgha")

    @property
    def speed_unit(self) -> str:
        return tr("unit.mph") if self.imperial else tr("unit.kmh")

    @property
    def area_unit(self) -> str:
        return tr("unit.ac") if self.imperial else tr("unit.ha")

    @property
    def mass_unit(self) -> str:
        return tr("unit.lb") if self.imperial else tr("unit.kg")

    @property
    def length_unit(self) -> str:
        return tr("unit.ft") if self.imperial else tr("unit.m")

    def shown(self, message: Text | str | None) -> Text | str | None:
        """`message` with its quantities (the values its template writes with their unit word,
        i18n.quantities) in these units and their unit words beside them."""
        if not isinstance(message, Text) or not self.imperial:
            return message
        convert = {
            "kg": (self.mass, self.mass_unit),
            "kmh": (self.speed, self.speed_unit),
            "kg_ha": (self.rate, self.rate_unit),
        }
        keys = set(quantities(message))
        values: list[tuple[str, object]] = []
        for k, v in message.values:
            unit = si_unit(k) if k in keys and isinstance(v, int | float) else None
            if unit is None:
                values.append((k, v))
            else:
                to, word = convert[unit]
                values += [(k, to(float(v))), (k + "_unit", word)]
        return Text(message.key, tuple(values))
