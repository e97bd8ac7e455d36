"""Who a control function on ISOBUS is, in the operator's language: what its NAME's function
code means (the catalogue's `isobus.fn.*`) and who made it (topdress.isobus.manufacturers).

The function codes are those of the ISOBUS public listing (ISO 11783-1, SAE J1939): 0..127
mean the same in every industry group; 128..254 mean something only with the industry group
and the device class (function 130 is the Task Controller in class 0 of agriculture, but the
product pressure of a fertilizer, class 5). Only the functions met on a farm's implement bus are
named; any other shows as its number.
"""

from __future__ import annotations

from topdress.i18n import tr
from topdress.isobus.manufacturers import manufacturer
from topdress.view.snapshot import ControlFunctionView, IsobusView

AG = 2  # industry group 2: agricultural and forestry equipment

#: function code (0..127, any industry group) -> its catalogue key's last part
GLOBAL_FUNCTIONS: dict[int, str] = {
    0: "engine",
    3: "transmission",
    6: "pto_rear",
    16: "steering",
    19: "instruments",
    23: "navigation",
    25: "niu",
    27: "pto_front",
    28: "gateway",
    29: "vt",
    30: "management",
    33: "monitor",
    34: "hydraulic_pump",
    37: "cab",
    38: "tire_pressure",
    54: "cellular",
    60: "cab_display",
    61: "file_server_printer",
    62: "diagnostic",
    66: "io",
    82: "file_server",
}

# (industry group, device class) -> {function code 128..254 -> its catalogue key's last part}
_CLASS_0 = {129: "service_tool", 130: "onboard_logger", 134: "ground_speed", 145: "inertial"}
_AG_0 = {
    128: "display",
    129: "operator_controls",
    130: "tc",
    131: "position",
    132: "machine",
    133: "foreign_object",
    134: "tecu",
    135: "scm",
    136: "dosing",
    137: "treatment",
    139: "logger",
    140: "decision",
    141: "lighting",
    142: "tim",
}
_TRACTOR = {
    129: "aux_valves",
    130: "rear_hitch",
    131: "front_hitch",
    132: "tractor_machine",
    134: "center_hitch",
}
_SEEDERS = {
    128: "seed_rate",
    129: "sections",
    131: "position",
    132: "seeder_machine",
    133: "flow",
    134: "level",
    135: "depth",
    136: "frame",
    137: "down_pressure",
}
_FERTILIZERS = {
    128: "fert_rate",
    129: "sections",
    130: "pressure",
    131: "position",
    132: "fert_machine",
    133: "flow",
    134: "level",
    135: "height_depth",
    136: "frame",
}
_SPRAYERS = {
    128: "spray_rate",
    129: "sections",
    130: "pressure",
    131: "position",
    132: "sprayer_machine",
    133: "flow",
    134: "level",
    135: "boom_height",
    136: "frame",
}
_SENSORS = {
    128: "feeler",
    129: "camera",
    130: "crop_scouting",
    131: "material_sensing",
    132: "imu",
    133: "flow",
    134: "level",
    135: "mass",
    137: "weather",
    138: "soil_scouting",
}
CLASS_FUNCTIONS: dict[tuple[int, int], dict[int, str]] = {
    (0, 0): _CLASS_0,
    (AG, 0): _AG_0,
    (AG, 1): _TRACTOR,
    (AG, 4): _SEEDERS,
    (AG, 5): _FERTILIZERS,
    (AG, 6): _SPRAYERS,
    (AG, 17): _SENSORS,
}


def function_key(industry_group: int, device_class: int, function: int) -> str | None:
    """The catalogue key naming a NAME's function; None for one not named here."""
    if function < 128:
        name = GLOBAL_FUNCTIONS.get(function)
    else:
        name = CLASS_FUNCTIONS.get((industry_group, device_class), {}).get(function)
    return None if name is None else f"isobus.fn.{name}"


def function_words(f: ControlFunctionView) -> str:
    """What the control function is, by its function code, in the language in force."""
    key = function_key(f.industry_group, f.device_class, f.function)
    return tr("isobus.what_unknown", function=f.function) if key is None else tr(key)


def what(f: ControlFunctionView, v: IsobusView) -> str:
    """The "what" column: this terminal's TC, the implement it serves, or the function."""
    if f.address == v.tc_address:
        return tr("isobus.what_self")
    if f.address == v.implement_address:
        return tr("isobus.what_served", function=function_words(f))
    return function_words(f)


def maker(code: int) -> str:
    """A manufacturer code as "name (code)", or the bare number for a code not in the list."""
    name = manufacturer(code)
    return str(code) if name is None else f"{name} ({code})"
