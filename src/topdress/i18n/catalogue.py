"""Every operator-facing string: key -> (English, 简体中文).

One place for both languages, so a string cannot exist in one only (tests/test_i18n.py checks
both are there with the same `{placeholders}`, and that every key the display uses exists).
Units are the SI/agronomic ones in both languages (km/h, kg/ha, r/min) as the paper prints them.
"""

from __future__ import annotations

from typing import Final

CATALOGUE: Final[dict[str, tuple[str, str]]] = {
    # ---- units
    "unit.kmh": ("km/h", "km/h"),
    "unit.kgha": ("kg/ha", "kg/ha"),
    "unit.rpm": ("r/min", "r/min"),
    "unit.s": ("s", "秒"),
    "unit.m": ("m", "m"),
    "unit.ha": ("ha", "ha"),
    "unit.kg": ("kg", "kg"),
    "unit.pct": ("%", "%"),
    # ---- screens
    "screen.main": ("Main", "主界面"),
    "screen.communication": ("Communication", "通信设置"),
    "screen.control": ("Control", "控制设置"),
    "screen.calibration": ("Calibration", "标定"),
    # ---- main screen
    "main.speed": ("Speed", "作业速度"),
    "main.selected": ("selected", "采用"),
    "main.wheel": ("wheel", "地轮"),
    "main.gnss": ("GNSS", "GNSS"),
    "main.source": ("source", "速度来源"),
    "main.why": ("CV {cv} % · {motion}", "变异系数 {cv} % · {motion}"),
    "main.uniform": ("uniform motion", "匀速"),
    "main.varying": ("accelerating or decelerating", "加速或减速"),
    "main.ndvi": ("NDVI", "NDVI"),
    "main.ndvi_sensors": ("sensors (mean)", "传感器均值"),
    "main.ndvi_meters": ("at the meters", "排肥器处"),
    "main.crop_sensors": ("crop sensors", "作物传感器"),
    "main.metering": ("Metering", "排肥"),
    "main.upper": ("upper", "上层"),
    "main.lower": ("lower", "下层"),
    "main.rate_set": ("rate set", "设定施肥量"),
    "main.target": ("target", "目标转速"),
    "main.measured": ("measured", "实测转速"),
    "main.fans": ("fans", "风机"),
    "main.links": ("Links", "连接状态"),
    "main.faults": ("faults", "故障"),
    # ---- sources, links, faults
    "source.gnss": ("GNSS", "GNSS"),
    "source.wheel": ("wheel", "地轮"),
    "source.fused": ("fused", "融合"),
    "source.none": ("none", "无"),
    "link_name.ecu": ("ECU", "控制器"),
    "link_name.gnss": ("GNSS", "GNSS"),
    "link_name.crop": ("crop sensors", "作物传感器"),
    "link.ok": ("ok", "正常"),
    "link.wait": ("waiting", "等待"),
    "link.lost": ("lost", "丢失"),
    "link.no_fix": ("no fix", "未定位"),
    "link.silent": ("silent", "无数据"),
    "link.partial": ("{fresh} fresh", "{fresh} 有效"),
    "fault.none": ("none", "无"),
    "fault.CMD_TIMEOUT": ("no command from the terminal", "未收到终端指令"),
    "fault.GNSS_LOST": ("GNSS speed lost", "GNSS 速度丢失"),
    "fault.WHEEL_ENCODER": ("ground-wheel encoder failed", "地轮编码器故障"),
    "fault.UPPER_BLOCKED": ("upper meter blocked", "上层排肥器堵转"),
    "fault.LOWER_BLOCKED": ("lower meter blocked", "下层排肥器堵转"),
    "fault.UPPER_FAN_LOW": ("upper fan too slow", "上层风机转速低"),
    "fault.LOWER_FAN_LOW": ("lower fan too slow", "下层风机转速低"),
    "fault.NO_SPEED": ("no speed at all", "无速度信号"),
    "fault.GNSS_FROZEN": ("GNSS speed frozen", "GNSS 速度冻结"),
    # ---- charts and map
    "chart.speed_title": ("Speed, last minute", "速度（最近 1 分钟）"),
    "chart.meter_title": ("Metering speed, last minute", "排肥转速（最近 1 分钟）"),
    "chart.selected": ("selected", "采用"),
    "chart.wheel": ("wheel", "地轮"),
    "chart.gnss": ("GNSS", "GNSS"),
    "chart.target_upper": ("target upper", "上层目标"),
    "chart.target_lower": ("target lower", "下层目标"),
    "chart.meter_upper": ("measured upper", "上层实测"),
    "chart.meter_lower": ("measured lower", "下层实测"),
    "map.title": ("Map", "作业地图"),
    "map.legend": (
        "swath coloured by rate, blue 0 … red {max} {unit}",
        "幅宽按施肥量着色：蓝 0 … 红 {max} {unit}",
    ),
}
