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
    # why the ECU meters on its speed source (the paper's rule)
    "why.mode": ("{source}: speed mode {mode}", "{source}：速度模式 {mode}"),
    "why.none": ("none: no usable speed", "无：没有可用的速度"),
    "why.encoder_fault": ("GNSS: wheel encoder fault", "GNSS：地轮编码器故障"),
    "why.gnss_frozen": (
        "wheel: GNSS speed frozen while the wheel stands",
        "地轮：地轮静止时 GNSS 速度冻结",
    ),
    "why.no_gnss": ("{source}: no valid GNSS speed", "{source}：无有效 GNSS 速度"),
    # the GNSS lag in use and where it comes from (EcuGnssLag)
    "main.lag": ("lag {s:.2f} s", "滞后 {s:.2f} 秒"),
    "lag.start": ("GNSS lag {s:.2f} s (learning)", "GNSS 滞后 {s:.2f} 秒（学习中）"),
    "lag.learned": ("GNSS lag {s:.2f} s (learned)", "GNSS 滞后 {s:.2f} 秒（已学习）"),
    "lag.fixed": ("GNSS lag {s:.2f} s (fixed)", "GNSS 滞后 {s:.2f} 秒（固定）"),
    "lag.overruled": (
        "GNSS lag {s:.2f} s (learned, not the set {fixed:.2f} s)",
        "GNSS 滞后 {s:.2f} 秒（已学习，非设定的 {fixed:.2f} 秒）",
    ),
    "why.cv": ("CV {cv:.2f} %", "变异系数 {cv:.2f} %"),
    "why.cv_none": ("CV --", "变异系数 --"),
    "why.gnss": (
        "GNSS: {cv} < {threshold:g} %, "
        "{compare} {kmh:.1f} {kmh_unit} > {switch_kmh:.3g} {switch_kmh_unit}",
        "GNSS：{cv} < {threshold:g} %，"
        "{compare} {kmh:.1f} {kmh_unit} > {switch_kmh:.3g} {switch_kmh_unit}",
    ),
    "why.not_uniform": (
        "wheel: {cv} ≥ {threshold:g} % (not uniform)",
        "地轮：{cv} ≥ {threshold:g} %（非匀速）",
    ),
    "why.slow": (
        "wheel: {compare} {kmh:.1f} {kmh_unit} ≤ {switch_kmh:.3g} {switch_kmh_unit}",
        "地轮：{compare} {kmh:.1f} {kmh_unit} ≤ {switch_kmh:.3g} {switch_kmh_unit}",
    ),
    "link_name.ecu": ("ECU", "控制器"),
    "link_name.gnss": ("GNSS", "GNSS"),
    "link_name.crop": ("crop sensors", "作物传感器"),
    "link.ok": ("ok", "正常"),
    "link.wait": ("waiting", "等待"),
    "link.lost": ("lost", "丢失"),
    "link.no_fix": ("no fix", "未定位"),
    "link.silent": ("silent", "无数据"),
    "link.refused": ("refused", "被拒绝"),
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
    # ---- the terminal's console (labels of its status block, padded to 8 columns there)
    "con.refused": ("refused: {message}", "被拒绝：{message}"),
    "con.speed": ("speed", "速度"),
    "con.from": ("from", "来自"),
    "con.uniform": ("uniform", "匀速"),
    "con.varying": ("varying", "变速"),
    "con.sensors": ("sensors", "传感器"),
    "con.at_meters": ("at meters", "排肥器处"),
    "con.rate": ("rate", "施肥量"),
    "con.meters": ("meters", "排肥器"),
    "con.actual": ("actual", "实测"),
    "con.operator": ("operator", "作业"),
    "con.alarms": ("alarms", "报警"),
    "con.calib": ("calib", "标定"),
    "con.counts": ("counts", "计数"),
    "con.last": ("last", "最近"),
    "con.crop": ("CROP", "作物"),
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
        "swath coloured by the rate applied, blue 0 … red {max} {unit}",
        "幅宽按实际施肥量着色：蓝 0 … 红 {max} {unit}",
    ),
    # ---- operating
    "op.start": ("Start", "开始"),
    "op.stop": ("Stop", "停止"),
    "op.pause": ("Pause", "暂停"),
    "op.state.stopped": ("STOPPED", "已停止"),
    "op.state.running": ("RUNNING", "作业中"),
    "op.state.paused": ("PAUSED (fans on)", "暂停（风机运转）"),
    "op.state.calibrating": ("CALIBRATING", "标定中"),
    "manual.title": ("Manual rate", "手动施肥量"),
    "manual.off": ("NDVI model", "NDVI 模型"),
    "manual.fixed": ("fixed kg/ha", "固定施肥量"),
    "manual.percent": ("± % on the planned rate", "计划施肥量 ± %"),
    "manual.shown_fixed": ("MANUAL {upper} / {lower} {unit}", "手动 {upper} / {lower} {unit}"),
    "manual.fixed_is": (
        "manual {upper:.1f}/{lower:.1f} kg/ha",
        "手动 {upper:.1f}/{lower:.1f} kg/ha",
    ),
    "manual.percent_is": (
        "manual {percent:+.0f} % on the planned rate",
        "手动 计划施肥量 {percent:+.0f} %",
    ),
    "manual.model_is": ("model", "模型"),
    # ---- answers to the operator's commands
    "op.done.started": ("started", "已开始"),
    "op.done.resumed": ("resumed", "已继续"),
    "op.done.stopped": ("stopped", "已停止"),
    "op.done.paused": ("paused: meters stopped, fans kept", "已暂停：排肥器停止，风机保持"),
    "op.done.rate": ("rate: {rate}", "施肥量：{rate}"),
    "op.done.acked": ("{n} acknowledged", "已确认 {n} 项"),
    "op.done.reset": ("{which} counter reset", "{which}统计已清零"),
    "op.done.cal_closed": ("calibration closed, nothing changed", "标定已关闭，未做更改"),
    "op.done.test": ("{device} on {where}: {n} recent", "{device}（{where}）：最近 {n} 条"),
    "op.done.saved": (", saved to {path}", "，已保存到 {path}"),
    "op.done.not_saved": (" (not saved: no configuration file)", "（未保存：无配置文件）"),
    "op.done.later": (" (in force at the next start)", "（下次启动时生效）"),
    "op.done.settings": (
        "settings [{section}] applied{saved}{later}",
        "设置 [{section}] 已应用{saved}{later}",
    ),
    "op.done.pushing": ("pushing to the ECU", "正在发送到控制器"),
    "op.error.manual_mode": ("manual mode must be one of {modes}", "手动模式必须为 {modes} 之一"),
    "op.error.rate_range": (
        "{name}: {value:g} is outside 0..{max:g} kg/ha",
        "{name}：{value:g} 超出 0..{max:g} kg/ha",
    ),
    "op.error.percent_range": (
        "percent: {value:g} is outside {lo:g}..{hi:g} %",
        "百分比：{value:g} 超出 {lo:g}..{hi:g} %",
    ),
    "op.error.calibrating": ("a calibration is running: close it first", "正在标定：请先关闭标定"),
    "op.error.pause": (
        "only running meters can be paused (now {state})",
        "只有作业中才能暂停（当前：{state}）",
    ),
    "op.error.no_alarm": ("no alarm {name!r}", "没有报警 {name!r}"),
    "op.error.no_cal": ("no {cal} open", "未打开{cal}"),
    "op.error.stop_first": ("stop the meters first (now {state})", "请先停止排肥（当前：{state}）"),
    "op.error.ecu_for_cal": (
        "the ECU is {state}: calibration needs it",
        "控制器{state}：标定需要控制器",
    ),
    # whether the ISOBUS implement served is a topdress ECU, and why not (terminal/proplink.py)
    "prop.topdress": (
        "implement at 0x{address:02X} is a topdress ECU: its private frames",
        "地址 0x{address:02X} 的机具是 topdress 控制器：使用其专有帧",
    ),
    "prop.not_topdress": (
        "implement at 0x{address:02X} is not a topdress ECU ({why})",
        "地址 0x{address:02X} 的机具不是 topdress 控制器（{why}）",
    ),
    "prop.why.no_name": ("no NAME heard from it", "未收到其 NAME"),
    "prop.why.manufacturer": (
        "its NAME's manufacturer is {theirs}, not {ours}",
        "其 NAME 的制造商代码为 {theirs}，而非 {ours}",
    ),
    "prop.why.name": (
        "its NAME is of industry group {group}, device class {device_class}, function {function}",
        "其 NAME 为行业组 {group}、设备类 {device_class}、功能 {function}",
    ),
    "prop.why.ddop": ("its DDOP is '{theirs}', not '{ours}'", "其 DDOP 为“{theirs}”，而非“{ours}”"),
    "prop.why.none_served": ("none served", "未服务任何机具"),
    # calibrations on an ISOBUS (terminal/proplink.py): only with a topdress ECU served
    "op.error.cal_isobus_not_topdress": (
        "calibration needs the topdress ECU; the ISOBUS implement is not one ({why})",
        "标定需要topdress控制器；该ISOBUS机具不是（{why}）",
    ),
    "op.error.cal_isobus_fans": (
        "the fan check and the look-ahead calibration need the fans started by the terminal's "
        "command, which an ISOBUS does not carry: run them on the ECU's own bus",
        "风机检查和前视标定需要终端命令启动风机，ISOBUS不传送该命令：请在控制器自己的总线上进行",
    ),
    "op.error.no_device": (
        "no device {device!r} (gnss, crop, can)",
        "没有设备 {device!r}（gnss、crop、can）",
    ),
    "op.error.settings_busy": (
        "settings are being applied: wait for the ECU's answer or the new CAN bus",
        "正在应用设置：请等待控制器应答或新的 CAN 总线",
    ),
    "op.error.save": ("cannot save {path}: {error}", "无法保存 {path}：{error}"),
    "op.error.not_saved": (
        "applied in the ECU, not saved: {error}",
        "已应用到控制器，但未保存：{error}",
    ),
    "op.error.ecu_stopped": (
        "the ECU takes [{section}] only with the meters stopped (now {state})",
        "控制器只在排肥停止时接受 [{section}]（当前：{state}）",
    ),
    "op.error.ecu_params": (
        "the ECU is {state}: its parameters cannot be changed",
        "控制器{state}：无法修改其参数",
    ),
    # ---- events (the console's lines, the display's last event, the log)
    "event.operator": ("operator: {what}", "操作：{what}"),
    "event.calibration": ("calibration: {what}", "标定：{what}"),
    "event.alarm": ("alarm: {alarm}", "报警：{alarm}"),
    "event.map_inside": (
        "{map}: {file}: the machine is on it",
        "{map}：{file}：机具位于图内",
    ),
    "event.map_far_m": (
        "{map}: {file}: {distance_m} m from the machine",
        "{map}：{file}：距机具 {distance_m} 米",
    ),
    "event.map_far_km": (
        "{map}: {file}: {distance_km:.1f} km from the machine",
        "{map}：{file}：距机具 {distance_km:.1f} 公里",
    ),
    "map.prescription": ("prescription", "处方图"),
    "map.boundary": ("boundary", "地块边界"),
    "event.display_lost": (
        "no operator display for {s:.0f} s",
        "已 {s:.0f} 秒无操作显示",
    ),
    "event.display_lost_paused": (
        "no operator display for {s:.0f} s: meters paused (start resumes)",
        "已 {s:.0f} 秒无操作显示：排肥已暂停（启动可恢复）",
    ),
    "event.pin_lockout": (
        "display: {failures} wrong PINs from {address}: locked out for {lockout_s:.0f} s",
        "显示：来自 {address} 的 PIN 码错误 {failures} 次：锁定 {lockout_s:.0f} 秒",
    ),
    "event.settings_refused": (
        "settings [{section}] refused: {error}",
        "设置 [{section}] 被拒绝：{error}",
    ),
    "event.can_rx_error": ("CAN receive error: {error}", "CAN 接收错误：{error}"),
    "event.can_tx_failed": ("CAN send failed: {error}", "CAN 发送失败：{error}"),
    "event.can_tx_again": ("CAN send works again", "CAN 发送已恢复"),
    "event.can_adapter_lost": (
        "CAN adapter lost ({why}): opening it again",
        "CAN 适配器丢失（{why}）：正在重新打开",
    ),
    "event.can_new_bus_silent": (
        "no ECU took its parameters on {where} within {s:.0f} s: the bus in use stays "
        "(check the bitrate and the wiring)",
        "{where} 上 {s:.0f} 秒内没有控制器接受参数：继续使用当前总线（请检查波特率和接线）",
    ),
    "event.can_adapter_back": (
        "CAN adapter {where} open again after {s:.1f} s",
        "CAN 适配器 {where} 已重新打开（中断 {s:.1f} 秒）",
    ),
    "event.ecu_ready": (
        "ECU ready: every parameter acknowledged, {s:.1f} s after start",
        "控制器就绪：所有参数已确认，启动后 {s:.1f} 秒",
    ),
    "event.ecu_back": ("ECU back", "控制器已恢复"),
    "event.ecu_reconnected": (
        "ECU connected to the Task Controller again: its parameters are sent again",
        "控制器重新连接任务控制器：重新发送参数",
    ),
    "event.ecu_restarted": (
        "ECU restarted on its defaults: its parameters are sent again",
        "控制器已重启并使用默认参数：重新发送参数",
    ),
    "event.ecu_ident": ("ECU: {ecu} ({transport})", "控制器：{ecu}（{transport}）"),
    "event.ecu_protocol": (
        "warning: the ECU speaks protocol {ecu}, this terminal {terminal}: frames may be "
        "misread; update the ECU's firmware or the terminal",
        "警告：控制器协议版本 {ecu}，本终端 {terminal}：报文可能被误读；请更新控制器固件或终端",
    ),
    "view.ecu_ident": (
        "{target} firmware {firmware}, protocol {protocol}",
        "{target} 固件 {firmware}，协议 {protocol}",
    ),
    "view.ecu_can_health": (
        "CAN {state}, errors tx {tec} rx {rec}, error-passive {passive}x, bus-off {bus_off}x",
        "CAN {state}，错误计数 发送 {tec} 接收 {rec}，被动错误 {passive} 次，总线关闭 {bus_off} 次",
    ),
    "event.ecu_can_health": ("ECU CAN controller: {health}", "控制器 CAN：{health}"),
    "event.ecu_fault_record": (
        "ECU reset after a {kind}; it kept {registers} (find the PC in the firmware's map file)",
        "控制器因{kind}复位；保留的寄存器 {registers}（在固件的 map 文件中查找 PC）",
    ),
    "event.ecu_crystal_failure": (
        "ECU crystal failure before this start: it ran on its internal oscillator, off the bus "
        "with its outputs off (check the crystal and its load capacitors)",
        "控制器本次启动前晶振故障：曾以内部振荡器运行，未上总线且输出关闭（请检查晶振及其负载电容）",
    ),
    "event.ecu_lost": ("ECU lost: no status for {s:.1f} s", "控制器丢失：{s:.1f} 秒无状态帧"),
    "event.ecu_wait_silent": (
        "ECU wait: {name} unacknowledged after {tries} tries on CAN {where}; still trying (is "
        "the ECU powered, on this bus?)",
        "等待控制器：参数 {name} 在 CAN {where} 上发送 {tries} 次未确认；继续重试（控制器是否通电、"
        "是否在此总线上？）",
    ),
    "event.ecu_wait_deaf": (
        "ECU wait: {name} unacknowledged after {tries} tries on CAN {where}; the ECU sends "
        "status but does not answer (check [can.ids]); still trying",
        "等待控制器：参数 {name} 在 CAN {where} 上发送 {tries} 次未确认；控制器发送状态帧但不应答"
        "（请检查 [can.ids]）；继续重试",
    ),
    "event.ecu_wait_deaf_isobus": (
        "ECU wait: {name} unacknowledged after {tries} tries on the ISOBUS ({where}); the ECU "
        "sends status but does not answer the Task Controller; still trying",
        "等待控制器：参数 {name} 在ISOBUS（{where}）上发送 {tries} 次未确认；"
        "控制器发送状态帧但不应答任务控制器；继续重试",
    ),
    "event.udp_multicast": (
        "warning: CAN over udp_multicast: any host on this network can read and inject frames "
        "(no authentication); use it only on a private network or this machine",
        "警告：CAN 经 udp_multicast 传输：本网络上任何主机都能读取和注入报文（无认证）；"
        "仅在专用网络或本机使用",
    ),
    "event.gnss": ("GNSS {state}", "GNSS：{state}"),
    "event.gnss_silent": (
        "GNSS lost (no speed sentence for {s:g} s)",
        "GNSS 丢失（{s:g} 秒无速度语句）",
    ),
    "event.gnss_lost": ("GNSS lost ({why})", "GNSS 丢失（{why}）"),
    "event.gnss_no_speed": (
        "GNSS: {lines} lines, none with a speed: the receiver must send RMC (or VTG)",
        "GNSS：{lines} 行，均无速度：接收机须输出 RMC（或 VTG）",
    ),
    "event.gnss_no_decode": (
        "GNSS: {lines} lines, none with a speed: none decodes, check gnss.baud",
        "GNSS：{lines} 行，均无速度：无法解码，请检查 gnss.baud",
    ),
    "event.crop_lost": ("crop sensors lost ({why})", "作物传感器丢失（{why}）"),
    "event.crop_ok": ("crop sensors ok", "作物传感器正常"),
    "event.crop_silent": (
        "crop sensors silent: no NDVI, rate 0",
        "作物传感器无数据：无 NDVI，施肥量为 0",
    ),
    "event.crop_fresh": (
        "crop sensors: {fresh} of {n} fresh",
        "作物传感器：{n} 个中 {fresh} 个有效",
    ),
    "event.crop_unusable": (
        "crop sensors: {lines} lines, none usable (last: {last}): check crop.baud and "
        "[crop.columns]",
        "作物传感器：{lines} 行，均不可用（最后一条：{last}）：请检查 crop.baud 和 [crop.columns]",
    ),
    "event.counters_error": ("counters: {error}", "作业统计：{error}"),
    "event.gnss_lag_learned": ("GNSS lag learned: {s:.2f} s", "GNSS 滞后已学习：{s:.2f} 秒"),
    "event.gnss_lag_moved": (
        "GNSS lag learned: {s:.2f} s (was {was:.2f} s)",
        "GNSS 滞后已学习：{s:.2f} 秒（原为 {was:.2f} 秒）",
    ),
    "event.gnss_lag_overruled": (
        "warning: the configured gnss_lag_ms ({fixed:.2f} s) contradicts the data; the learned "
        "lag ({s:.2f} s) is used",
        "警告：配置的 gnss_lag_ms（{fixed:.2f} 秒）与数据矛盾；采用学习到的滞后（{s:.2f} 秒）",
    ),
    "event.gnss_lag_fixed": (
        "GNSS lag: the configured {fixed:.2f} s is in use (it agrees with the data)",
        "GNSS 滞后：采用配置的 {fixed:.2f} 秒（与数据一致）",
    ),
    "event.gnss_lag_start": (
        "GNSS lag: learning from {s:.2f} s",
        "GNSS 滞后：从 {s:.2f} 秒开始学习",
    ),
    "event.gnss_lag_other": (
        "GNSS receiver on {input} is not the one whose lag was kept: its lag is learned at the "
        "first start",
        "{input} 上的 GNSS 接收机不是所保存滞后的那台：首次起步时学习其滞后",
    ),
    "event.gnss_lag_restored": (
        "GNSS lag: the ECU restarted; it learns again from the {s:.2f} s learned in this session",
        "GNSS 滞后：ECU 已重启；从本次作业已学到的 {s:.2f} 秒重新开始学习",
    ),
    "event.gnss_lag_store": ("GNSS lag file: {error}", "GNSS 滞后文件：{error}"),
    # on the model's or the prescription's rate, whichever is in force: "planned"
    "manual.shown_percent": ("MANUAL {percent} % of plan", "手动 计划 {percent} %"),
    "main.rate_model": ("model rate", "模型施肥量"),
    "main.rate_applied": ("rate applied", "实际施肥量"),
    "alarm.title": ("Alarms", "报警"),
    "alarm.ack": ("Acknowledge", "确认"),
    "alarm.ack_all": ("acknowledge all", "全部确认"),
    "alarm.none": ("no alarm", "无报警"),
    "alarm.state.active": ("active", "未确认"),
    "alarm.state.acked": ("acknowledged", "已确认"),
    "alarm.state.cleared": ("gone, not acknowledged", "已消除，未确认"),
    "alarm.off_rate_upper": ("upper meter off rate", "上层排肥转速偏离目标"),
    "alarm.off_rate_lower": ("lower meter off rate", "下层排肥转速偏离目标"),
    "alarm.blocked_upper": ("upper meter blocked", "上层排肥器堵转"),
    "alarm.blocked_lower": ("lower meter blocked", "下层排肥器堵转"),
    "alarm.fan_low_upper": ("upper fan low", "上层风机转速低"),
    "alarm.fan_low_lower": ("lower fan low", "下层风机转速低"),
    "alarm.gnss_lost": ("GNSS lost: metering on the ground wheel", "GNSS 丢失：按地轮速度排肥"),
    "alarm.position_unknown": (
        "position unknown (no GNSS fix): boundary and map not applied",
        "位置未知（无 GNSS 定位）：不按边界和处方图施肥",
    ),
    "alarm.crop_lost": ("crop sensors lost: no NDVI", "作物传感器丢失：无 NDVI"),
    "alarm.ecu_lost": ("ECU lost: no status frames", "控制器丢失：无状态帧"),
    "alarm.implement_lost": ("ISOBUS implement lost", "ISOBUS 机具丢失"),
    "alarm.text.implement_lost": (
        "ISOBUS implement {device} lost: silent, no rate reaches it",
        "ISOBUS 机具 {device} 丢失：无响应，施肥量无法下发",
    ),
    "alarm.ddop_refused": ("implement's DDOP refused", "机具描述（DDOP）被拒绝"),
    "alarm.text.ddop_refused": (
        "the implement's DDOP was refused: {why}",
        "机具描述（DDOP）被拒绝：{why}",
    ),
    # a parameter the topdress ECU on an ISOBUS refused (terminal/busswitch.py), and why
    "alarm.ecu_param_refused": ("ECU parameter refused", "控制器拒绝参数"),
    "alarm.text.ecu_param_refused": (
        "the ECU refused its parameter {param} = {value:g} ({why}): "
        "the implement is held at rate 0",
        "控制器拒绝参数 {param} = {value:g}（{why}）：机具施肥量保持为 0",
    ),
    "ecu.ack.unknown_param": ("not a parameter it knows", "控制器不认识此参数"),
    "ecu.ack.out_of_range": ("out of range", "超出范围"),
    "ecu.ack.inconsistent": ("inconsistent with its other parameters", "与其他参数不一致"),
    "ecu.ack.bad_frame": ("bad frame", "帧格式错误"),
    "event.isobus": ("ISOBUS: {what}", "ISOBUS：{what}"),
    # what the terminal's Task Controller says (isobus/tcserver.py, terminal/tclink.py)
    "tc.frame_refused": ("frame {id:08X} refused: {why}", "帧 {id:08X} 被拒绝：{why}"),
    "tc.silent": ("client {client:#x} silent for {ms} ms", "客户端 {client:#x} 已 {ms} ms 无响应"),
    "tc.no_ack": (
        "client {client:#x} did not acknowledge DDI {ddi} of element {element} within {ms} ms",
        "客户端 {client:#x} 未在 {ms} ms 内确认元素 {element} 的 DDI {ddi}",
    ),
    "tc.ack_again": (
        "client {client:#x} acknowledges again ({n} acknowledges were missing)",
        "客户端 {client:#x} 恢复确认（此前缺少 {n} 次确认）",
    ),
    "tc.displaced": (
        "client {client:#x}'s address taken by NAME {name:016X}: client dropped",
        "客户端 {client:#x} 的地址被 NAME {name:016X} 占用：已断开该客户端",
    ),
    "tc.moved": (
        "client NAME {name:016X} moved from {old:#x} to {new:#x}: it must connect again",
        "客户端 NAME {name:016X} 从 {old:#x} 移至 {new:#x}：须重新连接",
    ),
    "tc.other_tc": (
        "another Task Controller at {address:#x}",
        "总线上另有任务控制器，地址 {address:#x}",
    ),
    "tc.other_tc_number": (
        "another Task Controller at {address:#x}, TC number {number}",
        "总线上另有任务控制器，地址 {address:#x}，任务控制器编号 {number}",
    ),
    "tc.elsewhere": (
        "client {client:#x} works with the Task Controller at {tc:#x}",
        "客户端 {client:#x} 已与地址 {tc:#x} 的任务控制器连接",
    ),
    "tc.flood": (
        "address {address:#x} floods the TC (over {n} process-data messages a second): the "
        "excess dropped",
        "地址 {address:#x} 向任务控制器发送过多（每秒超过 {n} 条过程数据）：超出部分已丢弃",
    ),
    "tc.second_client": (
        "client {client:#x} refused: the TC serves {served:#x}, one at a time",
        "客户端 {client:#x} 被拒绝：任务控制器正在服务 {served:#x}，每次只服务一个",
    ),
    "tc.pool_too_large": (
        "client {client:#x} offers a {size}-byte DDOP, too large",
        "客户端 {client:#x} 提供的 DDOP 为 {size} 字节，过大",
    ),
    "tc.stored_corrupt": (
        "client {client:#x}: {why}; its pool is asked for again",
        "客户端 {client:#x}：{why}；已重新请求其对象池",
    ),
    "tc.pool_bad": ("client {client:#x}: {why}", "客户端 {client:#x}：{why}"),
    "tc.activation_refused": (
        "client {client:#x}: activation refused, no valid DDOP",
        "客户端 {client:#x}：激活被拒绝，没有有效的 DDOP",
    ),
    "tc.not_kept": (
        "DDOP of client {client:#x} not kept: {why}",
        "客户端 {client:#x} 的 DDOP 未能保存：{why}",
    ),
    "tc.unknown_value": (
        "client {client:#x} reports DDI {ddi} of element {element}, which its DDOP does not have",
        "客户端 {client:#x} 报告了元素 {element} 的 DDI {ddi}，其 DDOP 中没有该项",
    ),
    "tc.pdack_refused": (
        "client {client:#x} refused DDI {ddi} of element {element}: {why}",
        "客户端 {client:#x} 拒绝了元素 {element} 的 DDI {ddi}：{why}",
    ),
    "tc.and": ("{a}, {b}", "{a}，{b}"),
    "tc.pdack.0": ("process data command not supported", "不支持该过程数据命令"),
    "tc.pdack.1": ("invalid element number", "元素编号无效"),
    "tc.pdack.2": ("DDI not supported by the element", "该元素不支持此 DDI"),
    "tc.pdack.3": ("trigger method not supported", "不支持该触发方式"),
    "tc.pdack.4": ("process data not settable", "过程数据不可设置"),
    "tc.pdack.5": ("invalid or unsupported interval or threshold", "间隔或阈值无效或不受支持"),
    "tc.pdack.6": ("value does not conform to the DDI definition", "数值不符合 DDI 定义"),
    "tc.pdack.7": ("value outside the operational range", "数值超出工作范围"),
    "tc.link.frame_refused": ("ISOBUS frame refused: {why}", "ISOBUS 帧被拒绝：{why}"),
    "tc.link.send_failed": ("ISOBUS send failed: {why}", "ISOBUS 发送失败：{why}"),
    "tc.link.no_address": (
        "the Task Controller has no address: every one it tried was taken",
        "任务控制器没有地址：尝试过的地址均已被占用",
    ),
    "tc.link.at": ("Task Controller at address 0x{address:02X}", "任务控制器地址 0x{address:02X}"),
    "tc.link.moved": (
        "Task Controller moved from 0x{old:02X} to 0x{new:02X}: another took it",
        "任务控制器从 0x{old:02X} 移至 0x{new:02X}：原地址被其他设备占用",
    ),
    "tc.link.implement": (
        "implement {device} at 0x{address:02X}: DDOP active, {n} products in {units}, "
        "{sections} sections",
        "机具 {device}（0x{address:02X}）：DDOP 已激活，{n} 种物料（{units}），{sections} 个作业段",
    ),
    "tc.link.product": ("{unit} (element {element})", "{unit}（元素 {element}）"),
    "tc.link.none": ("none", "无"),
    "tc.link.no_rate": (
        "{device}: its DDOP has no settable rate (DDI 6 or 1)",
        "{device}：其 DDOP 没有可设置的施肥量（DDI 6 或 1）",
    ),
    "tc.link.coverage": (
        "section control: ground covered earlier taken from {n} session log(s) of this field "
        "({swaths} swaths)",
        "分段控制：已计入本地块之前 {n} 次作业的覆盖区域（{swaths} 条幅带）",
    ),
    "tc.link.restarted": (
        "Task Controller started anew on the new bus: silent {s} s, so that the implement "
        "at {client:#x} takes it for a new one and connects again",
        "任务控制器已在新总线上重新启动：静默 {s} 秒，"
        "使地址 {client:#x} 的机具将其视为新的任务控制器并重新连接",
    ),
    "tc.link.coverage_error": (
        "earlier sessions' coverage not read: {why}",
        "未能读取之前作业的覆盖区域：{why}",
    ),
    "alarm.wrong_field_prescription": (
        "far outside the prescription map: wrong field?",
        "远离处方图：地块错误？",
    ),
    "alarm.wrong_field_boundary": (
        "far outside the field boundary: wrong field?",
        "远离地块边界：地块错误？",
    ),
    "alarm.text.wrong_field_prescription": (
        "metering {distance_m} m outside the prescription map {file} (limit {limit_m:g} m): "
        "wrong field or wrong map? The rate outside the map is applied",
        "排肥位置在处方图 {file} 之外 {distance_m} 米（限值 {limit_m:g} 米）："
        "地块或处方图是否选错？当前按图外施肥量排肥",
    ),
    "alarm.text.wrong_field_boundary": (
        "metering {distance_m} m outside the field boundary {file} (limit {limit_m:g} m): "
        "wrong field or wrong boundary? The meters are off outside it",
        "排肥位置在地块边界 {file} 之外 {distance_m} 米（限值 {limit_m:g} 米）："
        "地块或边界文件是否选错？边界外排肥器已关闭",
    ),
    "alarm.ecu_protocol": ("ECU protocol version differs", "控制器协议版本不一致"),
    "alarm.text.ecu_protocol": (
        "the ECU speaks protocol {ecu}, this terminal {terminal}",
        "控制器协议版本 {ecu}，本终端 {terminal}",
    ),
    "alarm.log_low_space": ("log disk almost full", "记录磁盘将满"),
    "alarm.log_disk_full": ("log disk full", "记录磁盘已满"),
    "alarm.log_write_failing": ("session log not written", "作业记录无法写入"),
    "alarm.text.log_low_space": (
        "log disk almost full: {free_mb:.0f} MB free (margin {min_mb:.0f} MB)",
        "记录磁盘将满：剩余 {free_mb:.0f} MB（下限 {min_mb:.0f} MB）",
    ),
    "alarm.text.log_disk_full": (
        "log disk full: this session is not being recorded (metering goes on)",
        "记录磁盘已满：本次作业未被记录（排肥继续）",
    ),
    "alarm.text.log_write_failing": (
        "session log cannot be written: {error} (metering goes on)",
        "作业记录无法写入：{error}（排肥继续）",
    ),
    "alarm.display_down": (
        "operator display down: restarting it",
        "操作显示已停止：正在重新启动",
    ),
    "alarm.display_lost": (
        "no operator display: Stop only on the console",
        "无操作显示：只能在控制台停止",
    ),
    "alarm.ecu_link": ("ECU not ok, meters on", "排肥时控制器异常"),
    "alarm.gnss_link": ("GNSS not ok, meters on", "排肥时 GNSS 异常"),
    "alarm.crop_link": ("crop sensors not ok, meters on", "排肥时作物传感器异常"),
    "alarm.tank_low": ("tank low", "料箱肥量低"),
    "alarm.text.off_rate_upper": (
        "upper meter off rate: {rpm:.1f} r/min for {target:.1f} (more than {pct:g} % for {s:g} s)",
        "上层排肥转速偏离：{rpm:.1f} r/min，目标 {target:.1f}（偏差超过 {pct:g} % 达 {s:g} 秒）",
    ),
    "alarm.text.off_rate_lower": (
        "lower meter off rate: {rpm:.1f} r/min for {target:.1f} (more than {pct:g} % for {s:g} s)",
        "下层排肥转速偏离：{rpm:.1f} r/min，目标 {target:.1f}（偏差超过 {pct:g} % 达 {s:g} 秒）",
    ),
    "alarm.text.blocked_upper": (
        "upper meter blocked (stopped by the ECU)",
        "上层排肥器堵转（控制器已停机）",
    ),
    "alarm.text.blocked_lower": (
        "lower meter blocked (stopped by the ECU)",
        "下层排肥器堵转（控制器已停机）",
    ),
    "alarm.text.fan_low_upper": (
        "upper fan low: the upper meter is held",
        "上层风机转速低：上层排肥器暂停",
    ),
    "alarm.text.fan_low_lower": (
        "lower fan low: the lower meter is held",
        "下层风机转速低：下层排肥器暂停",
    ),
    "alarm.text.crop_lost": (
        "crop sensors {state}: no NDVI, rate 0 (unless manual)",
        "作物传感器{state}：无 NDVI，施肥量为 0（手动模式除外）",
    ),
    "count.title": ("Counters", "作业统计"),
    "count.field": ("field", "本地块"),
    "count.season": ("season", "本季"),
    "count.area": ("area", "面积"),
    "count.kg_upper": ("upper layer", "上层肥量"),
    "count.kg_lower": ("lower layer", "下层肥量"),
    "count.time": ("work time", "作业时间"),
    "count.distance": ("distance", "作业距离"),
    # ---- commands, PIN
    "action.apply": ("Apply", "应用"),
    "action.cancel": ("Cancel", "取消"),
    "action.save_apply": ("Save and apply", "保存并应用"),
    "action.refused": ("refused", "被拒绝"),
    "action.timeout": ("no answer from the terminal", "终端无应答"),
    "action.view_only": ("this display only shows", "此显示仅供查看"),
    "pin.title": ("PIN needed to operate", "操作需要 PIN 码"),
    "pin.label": ("PIN", "PIN 码"),
    "pin.ok": ("Unlock", "解锁"),
    "pin.wrong": ("wrong PIN", "PIN 码错误"),
    "pin.locked": (
        "too many wrong PINs: try again in {s:.0f} s",
        "PIN 码错误次数过多：请 {s:.0f} 秒后再试",
    ),
    "stale.title": (
        "No connection to the terminal — the values are stale",
        "与终端的连接已断开 — 显示的数值已过时",
    ),
    "stale.body": (
        "Nothing on this page is live. Stop the meters at the terminal's console or with the "
        "machine's stop switch. The page reconnects by itself.",
        "本页数值均非实时。请在终端控制台或用机器的停止开关停止排肥。页面会自动重新连接。",
    ),
    # ---- settings
    "settings.refused_here": ("refused: see the field marked", "被拒绝：见标红的字段"),
    "settings.sending": ("applying …", "正在应用 …"),
    "comm.gnss": ("GNSS receiver (NMEA)", "GNSS 接收机（NMEA）"),
    "comm.crop": ("Crop sensors (logger)", "作物传感器（数据记录仪）"),
    "comm.can": ("CAN (ECU)", "CAN（控制器）"),
    "comm.state": ("state", "状态"),
    "comm.ecu": ("ECU: {ecu}", "控制器：{ecu}"),
    "comm.test": ("Test: last lines", "测试：最近数据"),
    "comm.raw": ("received", "原始数据"),
    "comm.decoded": ("decoded", "解析结果"),
    # the terminal as an ISOBUS Task Controller (can.implement isobus)
    "comm.isobus": ("ISOBUS (Task Controller)", "ISOBUS（任务控制器）"),
    "isobus.tc": (
        "task controller at address {address}: {state}",
        "任务控制器地址 {address}：{state}",
    ),
    "isobus.no_implement": ("no implement connected", "未连接机具"),
    "isobus.implement": ("implement {name} at address {address}", "机具 {name}，地址 {address}"),
    "isobus.work_True": ("working", "作业中"),
    "isobus.work_False": ("not working", "未作业"),
    "isobus.element": ("product", "物料"),
    "isobus.unit": ("unit", "单位"),
    "isobus.setpoint": ("setpoint", "设定值"),
    "isobus.actual": ("actual", "实际值"),
    "isobus.total": ("total", "累计"),
    "isobus.sections": (
        "sections {marks} ({on} of {n} on)",
        "作业段 {marks}（{n} 段中 {on} 段开）",
    ),
    "isobus.timing": (
        "look-ahead {lookahead} s · implement's delays: setpoint {setpoint} ms, actual {actual} ms",
        "前视 {lookahead} 秒 · 机具延迟：设定 {setpoint} ms，实际 {actual} ms",
    ),
    "isobus.functions": ("Control functions heard", "总线上的控制功能"),
    "isobus.address": ("address", "地址"),
    "isobus.name": ("NAME", "NAME"),
    "isobus.what": ("what", "说明"),
    "isobus.decoded": (
        "function {function}, class {device_class}, group {group}, "
        "manufacturer {manufacturer}, identity {identity}",
        "功能 {function}，设备类 {device_class}，行业组 {group}，"
        "制造商 {manufacturer}，标识号 {identity}",
    ),
    # who a control function is (its NAME's function, display/isobus_names.py); the English is
    # after the ISOBUS public listing's function names (ISO 11783-1, SAE J1939)
    "isobus.what_self": ("task controller (this terminal)", "任务控制器（本终端）"),
    "isobus.what_served": ("implement served: {function}", "所服务的机具：{function}"),
    "isobus.what_unknown": ("function {function}", "功能 {function}"),
    "isobus.fn.engine": ("Engine", "发动机"),
    "isobus.fn.transmission": ("Transmission", "变速箱"),
    "isobus.fn.pto_rear": ("Power TakeOff (Main or Rear)", "动力输出轴（主/后）"),
    "isobus.fn.steering": ("Steering Controller", "转向控制器"),
    "isobus.fn.instruments": ("Instrument Cluster", "组合仪表"),
    "isobus.fn.navigation": ("Vehicle Navigation", "车辆导航"),
    "isobus.fn.niu": ("Network Interconnect ECU", "网络互联控制单元"),
    "isobus.fn.pto_front": ("Power TakeOff (Secondary or Front)", "动力输出轴（副/前）"),
    "isobus.fn.gateway": ("Off Vehicle Gateway", "车外网关"),
    "isobus.fn.vt": ("Virtual Terminal (in cab)", "虚拟终端（驾驶室）"),
    "isobus.fn.management": ("Management Computer", "管理计算机"),
    "isobus.fn.monitor": ("System Monitor", "系统监视器"),
    "isobus.fn.hydraulic_pump": ("Hydraulic Pump Controller", "液压泵控制器"),
    "isobus.fn.cab": ("Cab Controller", "驾驶室控制器"),
    "isobus.fn.tire_pressure": ("Tire Pressure Control", "轮胎气压控制"),
    "isobus.fn.cellular": ("Communications Unit, Cellular", "通信单元（蜂窝网络）"),
    "isobus.fn.cab_display": ("Cab Display", "驾驶室显示器"),
    "isobus.fn.file_server_printer": ("File Server / Printer", "文件服务器/打印机"),
    "isobus.fn.diagnostic": ("On-Board Diagnostic Unit", "车载诊断单元"),
    "isobus.fn.io": ("I/O Controller", "输入/输出控制器"),
    "isobus.fn.file_server": ("File Server", "文件服务器"),
    "isobus.fn.service_tool": ("Off-board diagnostic-service tool", "车外诊断服务工具"),
    "isobus.fn.onboard_logger": ("On-board data logger", "车载数据记录仪"),
    "isobus.fn.ground_speed": ("Ground based speed sensor", "对地速度传感器"),
    "isobus.fn.inertial": ("Inertial Sensor", "惯性传感器"),
    "isobus.fn.display": ("Non Virtual Terminal Display", "非虚拟终端显示器"),
    "isobus.fn.operator_controls": ("Operator Controls - Machine Specific", "操作控制（机器专用）"),
    "isobus.fn.tc": ("Task Controller (Mapping Computer)", "任务控制器（作业图计算机）"),
    "isobus.fn.position": ("Position Control", "位置控制"),
    "isobus.fn.machine": ("Machine Control", "机器控制"),
    "isobus.fn.foreign_object": ("Foreign Object Detection", "异物检测"),
    "isobus.fn.tecu": ("Tractor ECU", "拖拉机控制单元"),
    "isobus.fn.scm": ("Sequence Control Master", "顺序控制主控"),
    "isobus.fn.dosing": ("Product Dosing", "物料定量"),
    "isobus.fn.treatment": ("Product Treatment", "物料处理"),
    "isobus.fn.logger": ("Data Logger", "数据记录仪"),
    "isobus.fn.decision": ("Decision Support", "决策支持"),
    "isobus.fn.lighting": ("Lighting Controller", "照明控制器"),
    "isobus.fn.tim": ("TIM Server", "TIM 服务器"),
    "isobus.fn.aux_valves": ("Auxiliary Valve Control", "辅助阀控制"),
    "isobus.fn.rear_hitch": ("Rear Hitch Control", "后悬挂控制"),
    "isobus.fn.front_hitch": ("Front Hitch Control", "前悬挂控制"),
    "isobus.fn.tractor_machine": ("Tractor Machine Control", "拖拉机机器控制"),
    "isobus.fn.center_hitch": ("Center Hitch Control", "中间悬挂控制"),
    "isobus.fn.seed_rate": ("Seed Rate Control", "播种量控制"),
    "isobus.fn.sections": ("Section On/Off Control", "作业段开关控制"),
    "isobus.fn.seeder_machine": ("Planters/Seeders Machine Control", "播种机机器控制"),
    "isobus.fn.flow": ("Product Flow", "物料流量"),
    "isobus.fn.level": ("Product Level", "物料料位"),
    "isobus.fn.depth": ("Depth Control", "深度控制"),
    "isobus.fn.frame": ("Frame Control", "机架控制"),
    "isobus.fn.down_pressure": ("Down Pressure", "下压力"),
    "isobus.fn.fert_rate": ("Fertilize Rate Control", "施肥量控制"),
    "isobus.fn.pressure": ("Product Pressure", "物料压力"),
    "isobus.fn.fert_machine": ("Fertilizers Machine Control", "施肥机机器控制"),
    "isobus.fn.height_depth": ("Height/Depth Control", "高度/深度控制"),
    "isobus.fn.spray_rate": ("Spray Rate Control", "喷施量控制"),
    "isobus.fn.sprayer_machine": ("Sprayers Machine Control", "喷雾机机器控制"),
    "isobus.fn.boom_height": ("Boom Height Control", "喷杆高度控制"),
    "isobus.fn.feeler": ("Guidance Feeler", "导向触杆"),
    "isobus.fn.camera": ("Camera System", "摄像系统"),
    "isobus.fn.crop_scouting": ("Crop Scouting", "作物监测"),
    "isobus.fn.material_sensing": ("Material Properties Sensing", "物料特性检测"),
    "isobus.fn.imu": ("Inertial Measurement Unit (IMU)", "惯性测量单元（IMU）"),
    "isobus.fn.mass": ("Product Mass", "物料质量"),
    "isobus.fn.weather": ("Weather Instruments", "气象仪器"),
    "isobus.fn.soil_scouting": ("Soil Scouting", "土壤监测"),
    "main.implement": ("{name}: {state}", "{name}：{state}"),
    "control.rate": ("Fertilization model", "施肥模型"),
    "control.curve": ("Rate against NDVI", "施肥量-NDVI 曲线"),
    "control.total_rate": ("total kg/ha", "总施肥量 kg/ha"),
    "control.point": (
        "operating point: NDVI {ndvi} → {rate} {unit}",
        "当前工作点：NDVI {ndvi} → {rate} {unit}",
    ),
    "control.speed": ("Speed measurement", "测速模式"),
    "control.ecu": ("ECU: PID and protection", "控制器：PID 与保护"),
    "control.ecu_note": (
        "sent to the ECU with the meters stopped; applied once it acknowledges",
        "需在排肥停止时发送；控制器确认后生效",
    ),
    "control.pending": ("waiting for the ECU's acknowledgement …", "等待控制器确认 …"),
    "key.gnss.port": ("serial port", "串口"),
    "key.gnss.baud": ("baud", "波特率"),
    "key.gnss.stale_s": ("speed lost after", "速度超时"),
    "key.crop.port": ("serial port", "串口"),
    "key.crop.baud": ("baud", "波特率"),
    "key.crop.sensors": ("sensors", "传感器数量"),
    "key.crop.sensor_to_meter_m": ("sensors ahead of the meters", "传感器至排肥器距离"),
    "key.can.interface": ("interface", "接口类型"),
    "key.can.channel": ("channel", "通道"),
    "key.can.bitrate": ("bitrate", "波特率"),
    "key.can.command_period_s": ("command period", "指令周期"),
    "key.can.send_on_gnss": ("command on each GNSS speed", "每次 GNSS 速度即发送指令"),
    "key.can.send_on_rate": ("command on each rate change", "速率变化即发送指令"),
    "key.can.options": (
        "adapter options (name = value, one per line)",
        "适配器选项（每行一项：名称 = 值）",
    ),
    "key.rate.model": ("model", "模型"),
    "key.rate.split_upper": ("upper layer share", "上层比例"),
    "key.speed.mode": ("speed mode", "测速模式"),
    "key.speed.queue_len": ("wheel queue length N", "地轮速度队列长度 N"),
    "key.speed.cv_threshold_pct": ("CV threshold", "变异系数阈值"),
    "key.speed.switch_speed_kmh": ("switch speed", "切换速度"),
    "key.speed.switch_compare": ("speed compared", "比较速度"),
    "key.ecu.pid_kp": ("PID Kp", "PID 比例 Kp"),
    "key.ecu.pid_ki": ("PID Ki", "PID 积分 Ki"),
    "key.ecu.pid_kd": ("PID Kd", "PID 微分 Kd"),
    "key.ecu.pid_kff": ("feed-forward", "前馈系数"),
    "key.ecu.fan_min_rpm": ("fan minimum", "风机最低转速"),
    "key.ecu.blocked_time_ms": ("blocked after", "堵转判定时间"),
    # ---- calibration
    "cal.catch": ("Metering catch test", "排肥器标定（接肥试验）"),
    "cal.catch_how": (
        "Machine standing, meters stopped: the ECU turns one meter the set revolutions; "
        "weigh what was caught and enter it.",
        "机具静止、排肥停止：控制器使排肥器转动设定圈数；称量接到的肥料并输入。",
    ),
    "cal.wheel": ("Ground-wheel distance", "地轮距离标定"),
    "cal.wheel_how": (
        "Start, drive the measured distance (40 m), finish: pulses give the radius, GNSS the slip.",
        "开始后行驶已测距离（40 m）再结束：由脉冲数得有效半径，由 GNSS 得滑移率。",
    ),
    "cal.fan": ("Fan check", "风机检查"),
    "cal.fan_how": (
        "Machine standing: the fans run to their speed, the meters stay off.",
        "机具静止：风机升至设定转速，排肥器不转。",
    ),
    "cal.lead": ("Look-ahead: meter to outlet", "前瞻时间：排肥器到出肥口"),
    "cal.lead_how": (
        "Machine standing, fans on: the ECU runs one meter; press Seen the moment product "
        "comes out of the outlet. Three trials give the meter and air-line times.",
        "机具静止、风机运转：控制器使一个排肥器转动；出肥口一出肥即按“看到”。"
        "三次试验得出排肥器与气力输送时间。",
    ),
    "cal.trials": ("trials", "试验次数"),
    "cal.seen": ("Seen at the outlet", "看到出肥"),
    "cal.result.meter_ms": ("meter time ms", "排肥器响应 ms"),
    "cal.result.airline_ms": ("air-line time ms", "气力输送时间 ms"),
    "cal.result.meter_spread_ms": ("meter spread ms", "排肥器时间极差 ms"),
    "cal.result.airline_spread_ms": ("air-line spread ms", "输送时间极差 ms"),
    "cal.result.trials": ("trials", "试验次数"),
    "cal.start": ("Start", "开始"),
    "cal.revolutions": ("revolutions", "转数"),
    "cal.meter_speed": ("meter speed", "排肥转速"),
    "cal.distance": ("distance", "距离"),
    "cal.now": ("Wizard", "标定向导"),
    "cal.none": ("no calibration running", "无进行中的标定"),
    "cal.weighed": ("weighed", "称重"),
    "cal.finish": ("Enter weight", "输入重量"),
    "cal.finish_drive": ("Distance driven", "已行驶到终点"),
    "cal.apply": ("Apply to {setting}", "应用到 {setting}"),
    "cal.close": ("Close, change nothing", "关闭，不做更改"),
    "cal.step.running": ("running", "进行中"),
    "cal.step.weigh": ("weigh and enter kg", "称重并输入 kg"),
    "cal.step.drive": ("drive the distance", "行驶标定距离"),
    "cal.step.done": ("done", "完成"),
    "cal.step.aborted": ("aborted", "已中止"),
    "cal.text.catch_running": (
        "{layer} meter: {rev:g} revolutions at {rpm:g} r/min",
        "{layer}排肥器：以 {rpm:g} r/min 转 {rev:g} 圈",
    ),
    "cal.text.catch_weigh": (
        "{layer} meter: {rev:.3f} revolutions; weigh what was caught and enter kg",
        "{layer}排肥器：已转 {rev:.3f} 圈；请称量接到的肥料并输入 kg",
    ),
    "cal.text.catch_aborted": (
        "catch test aborted by the ECU: {reason}",
        "接肥试验被控制器中止：{reason}",
    ),
    "cal.text.no_answer": (
        "the ECU does not answer the calibration command (firmware too old?)",
        "控制器未响应标定指令（固件版本过旧？）",
    ),
    "cal.text.catch_done": (
        "{layer}: {kg_per_rev:.4f} kg/rev ({kg:g} kg over {rev:.3f} rev)",
        "{layer}：{kg_per_rev:.4f} kg/转（{rev:.3f} 转共 {kg:g} kg）",
    ),
    "cal.text.wheel_drive": (
        "drive {distance:g} m (measured on the ground), then finish",
        "行驶 {distance:g} m（地面实测距离）后点击结束",
    ),
    "cal.text.wheel_done": (
        "radius {radius_mm:.1f} mm ({rev:.2f} rev), GNSS {gnss_m:.1f} m, slip {slip:.1f} %",
        "半径 {radius_mm:.1f} mm（{rev:.2f} 转），GNSS {gnss_m:.1f} m，滑移率 {slip:.1f} %",
    ),
    "cal.text.wheel_done_no_gnss": (
        "radius {radius_mm:.1f} mm ({rev:.2f} rev), no GNSS distance (GNSS lost meanwhile)",
        "半径 {radius_mm:.1f} mm（{rev:.2f} 转），无 GNSS 距离（期间 GNSS 丢失）",
    ),
    "cal.text.fan_running": (
        "fans to {rpm:g} r/min for {s:g} s, meters off",
        "风机升至 {rpm:g} r/min 运行 {s:g} 秒，排肥器关闭",
    ),
    "cal.text.fan_no_ecu": (
        "fan check aborted: the ECU is not heard",
        "风机检查中止：收不到控制器",
    ),
    "cal.text.fan_moves": ("fan check aborted: the machine moves", "风机检查中止：机器在移动"),
    "cal.text.fan_ok": ("{layer} {rpm:.0f} r/min ok", "{layer} {rpm:.0f} r/min 正常"),
    "cal.text.fan_low": ("{layer} {rpm:.0f} r/min LOW", "{layer} {rpm:.0f} r/min 偏低"),
    "cal.text.fan_done": (
        "fans (target {target:g}, min {min:g} r/min): {upper}, {lower}",
        "风机（目标 {target:g}，最低 {min:g} r/min）：{upper}，{lower}",
    ),
    "cal.error.not_weighing": (
        "the catch test is {step}, not waiting for a weight",
        "接肥试验{step}，不在等待输入重量",
    ),
    "cal.error.wheel_step": ("the wheel calibration is {step}", "地轮标定{step}"),
    "cal.error.distance": (
        "distance must be > 0 m, not {distance:g}",
        "距离必须 > 0 m，而不是 {distance:g}",
    ),
    "cal.error.distance_range": (
        "distance must be 1..1000 m, not {distance:g}",
        "距离必须在 1..1000 m 之间，而不是 {distance:g}",
    ),
    "lead.text.trial": (
        "trial {n} of {trials}: {layer} meter at {rpm:g} r/min; press seen when product comes "
        "out of the outlet",
        "第 {n}/{trials} 次试验：{layer}排肥器 {rpm:g} r/min；看到出肥口出肥时按“看到出肥”",
    ),
    "lead.text.no_ecu": (
        "look-ahead calibration aborted: the ECU is not heard",
        "前瞻标定中止：收不到控制器",
    ),
    "lead.text.fans": ("fans spinning up ({rpm:.0f} r/min)", "风机加速中（{rpm:.0f} r/min）"),
    "lead.text.aborted": (
        "look-ahead calibration aborted by the ECU: {reason}",
        "前瞻标定被控制器中止：{reason}",
    ),
    "lead.text.no_press": (
        "no press within {s:g} s: the trial is repeated",
        "{s:g} 秒内未按键：重做本次试验",
    ),
    "lead.text.seen": ("seen; timing the meter", "已看到出肥；正在测排肥器时间"),
    "lead.text.done": (
        "meter {meter:.0f} ms (spread {meter_spread:.0f}), air line {air:.0f} ms (spread "
        "{air_spread:.0f}) over {trials} trials",
        "排肥器 {meter:.0f} ms（极差 {meter_spread:.0f}），气力输送 {air:.0f} ms（极差 "
        "{air_spread:.0f}），共 {trials} 次试验",
    ),
    "lead.error.late": (
        "seen {s:.1f} s after the start: too late",
        "开始后 {s:.1f} 秒才看到：太晚",
    ),
    "lead.error.not_turned": (
        "the meter has not turned yet: press when product comes out",
        "排肥器尚未转动：出肥时再按",
    ),
    "lead.error.early": (
        "seen before the meter turned (less the reaction time): press when product comes out "
        "of the outlet",
        "排肥器转动前（扣除反应时间）就按了：出肥口出肥时再按",
    ),
    "lead.error.short": (
        "the meter has not run long enough to time it: wait a moment",
        "排肥器运行时间不足以计时：请稍候",
    ),
    "lead.error.unsteady": (
        "the meter does not turn steadily: no meter time",
        "排肥器转速不稳：无法得到排肥器时间",
    ),
    "lead.error.trials": (
        "trials must be 1..{max}, not {trials}",
        "试验次数必须为 1..{max}，而不是 {trials}",
    ),
    "lead.error.reaction": (
        "reaction time must be 0..1000 ms, not {ms:g}",
        "反应时间必须为 0..1000 ms，而不是 {ms:g}",
    ),
    "lead.error.run": (
        "run time must be 1..30 s, not {s:g}",
        "运行时间必须为 1..30 秒，而不是 {s:g}",
    ),
    "lead.error.no_trial": (
        "no trial running: wait for the meter to start",
        "没有进行中的试验：请等待排肥器启动",
    ),
    "lead.error.already": ("already seen: the meter is being timed", "已按过：正在测排肥器时间"),
    "cal.error.no_revolutions": (
        "the meter did not turn: no revolutions counted",
        "排肥器未转动：未计到转数",
    ),
    "cal.error.weight": (
        "weighed mass must be > 0 kg, not {kg:g}",
        "称重质量必须 > 0 kg，而不是 {kg:g}",
    ),
    "cal.error.no_pulses": (
        "the ground wheel did not turn: no pulses counted",
        "地轮未转动：未计到脉冲",
    ),
    "cal.error.layer": (
        "layer must be upper or lower, not {layer!r}",
        "层必须为 upper 或 lower，而不是 {layer!r}",
    ),
    "cal.result.kg_per_rev": ("kg per revolution", "每转排肥量 kg"),
    "cal.result.weighed_kg": ("weighed kg", "称重 kg"),
    "cal.result.revolutions": ("revolutions", "转数"),
    "cal.result.pulses": ("pulses", "脉冲数"),
    "cal.result.radius_m": ("effective radius m", "有效半径 m"),
    "cal.result.slip_pct": ("slip %", "滑移率 %"),
    "cal.result.gnss_distance_m": ("GNSS distance m", "GNSS 距离 m"),
    "cal.result.slip_gnss_pct": ("slip against GNSS %", "相对 GNSS 滑移率 %"),
    "cal.result.upper_rpm": ("upper fan r/min", "上层风机 r/min"),
    "cal.result.lower_rpm": ("lower fan r/min", "下层风机 r/min"),
    "unit.ms": ("ms", "ms"),
    # ---- the cab layout: header, units, night, tank, area, panels
    "unit.mph": ("mph", "mph"),
    "unit.lbac": ("lb/ac", "lb/ac"),
    "unit.ac": ("ac", "英亩"),
    "unit.lb": ("lb", "磅"),
    "unit.ft": ("ft", "英尺"),
    "unit.lha": ("L/ha", "L/ha"),
    "unit.l": ("L", "L"),
    "view.night": ("Night mode", "夜间模式"),
    "view.day": ("Day mode", "日间模式"),
    "view.imperial": ("Units: lb/ac, mph", "单位：lb/ac、mph"),
    "view.metric": ("Units: kg/ha, km/h", "单位：kg/ha、km/h"),
    "alarm.more": ("(+{n} more)", "（另有 {n} 项）"),
    "alarm.text.link": ("{link} {state} while the meters are on", "排肥时{link}{state}"),
    "alarm.text.tank_low": (
        "tank low: {kg:.0f} {kg_unit} left",
        "料箱肥量低：剩余 {kg:.0f} {kg_unit}",
    ),
    "main.rate_target": ("target", "目标"),
    "main.prescription": ("prescription {rate} {unit}", "处方 {rate} {unit}"),
    "zone.field": ("in the field", "田块内"),
    "zone.headland": ("headland: meters off", "地头：停止排肥"),
    "zone.outside": ("outside the field", "田块外"),
    "zone.unknown": ("position unknown: last rate kept", "位置未知：保持上次施肥量"),
    "main.tank_none": ("tank: no fill entered", "料箱：未输入装料量"),
    "main.tank_left": ("tank {kg} {unit} left", "料箱剩余 {kg} {unit}"),
    "main.covers": ("enough for {area} {unit}", "可施 {area} {unit}"),
    "main.area_done": ("done {area} {unit}", "已作业 {area} {unit}"),
    "main.area_left": ("left {area} {unit}", "剩余 {area} {unit}"),
    "tab.charts": ("Charts", "曲线"),
    "tab.crop": ("NDVI, links", "NDVI 与连接"),
    "tank.fill": ("tank filled to", "料箱装料"),
    "tank.alarm": ("alarm below", "报警下限"),
    "tank.set": ("Set tank", "设置料箱"),
    "count.reset": ("Reset", "清零"),
    "count.undo": ("Undo reset", "撤销清零"),
    "count.reset_ask": (
        "Reset the {which} counter? {area} and {kg} go to 0 (the reset can be undone while "
        "the terminal runs).",
        "清零{which}统计？{area}、{kg} 将归零（终端运行期间可撤销）。",
    ),
    "manual.in_force": ("in force: {what}", "当前生效：{what}"),
    "manual.clipped": ("limited to {max}", "已限制为 {max}"),
    "cal.last": ("last result: {what}", "上次结果：{what}"),
    "settings.reload": ("Reload", "重新加载"),
    "settings.stop_apply": ("Stop the meters and apply", "停止排肥并应用"),
    "settings.link_cut_ask": (
        "Applying [can] reopens the CAN link: the ECU is not heard for a moment. Stop the "
        "meters and apply?",
        "应用 [can] 会重新打开 CAN 连接，控制器会短暂失联。停止排肥并应用？",
    ),
    "op.error.no_undo": ("no reset of the {which} counter to undo", "没有可撤销的 {which} 清零"),
    "op.done.undo": ("{which} counter put back", "{which}统计已恢复"),
    "op.error.tank": (
        "tank: the fill must be > 0 kg and the alarm level below it (fill {fill:g}, alarm "
        "{alarm:g})",
        "料箱：装料量必须 > 0 kg 且报警下限低于装料量（装料 {fill:g}，下限 {alarm:g}）",
    ),
    "op.done.tank": (
        "tank: {kg:g} kg, alarm below {alarm:g} kg",
        "料箱：{kg:g} kg，低于 {alarm:g} kg 报警",
    ),
    "op.error.stale": (
        "[{section}] was changed from another screen meanwhile: reload to see the values in "
        "force, then change them again",
        "[{section}] 已在其他画面修改：请重新加载查看当前值后再修改",
    ),
    # values a setting takes, by name
    "value.linear": ("linear", "线性"),
    "value.table": ("table", "查表"),
    "value.sufficiency": ("sufficiency index", "充足指数"),
    "value.paper": ("paper's dual rule", "论文双速规则"),
    "value.wheel": ("ground wheel", "地轮"),
    "value.gnss": ("GNSS", "GNSS"),
    "value.fused": ("fused (Kalman)", "融合（卡尔曼）"),
    # keys of the settings screens that had no words yet
    "key.crop.columns.sensor_id": ("column: sensor number", "列：传感器编号"),
    "key.crop.columns.red": ("column: red", "列：红光"),
    "key.crop.columns.red_edge": ("column: red edge", "列：红边"),
    "key.crop.columns.nir": ("column: near infrared", "列：近红外"),
    "key.crop.columns.ndre": ("column: NDRE", "列：NDRE"),
    "key.crop.columns.ndvi": ("column: NDVI", "列：NDVI"),
    "key.rate.linear.ndvi_0": ("first point: NDVI", "第一点 NDVI"),
    "key.rate.linear.rate_0_kg_ha": ("first point: rate", "第一点施肥量"),
    "key.rate.linear.ndvi_1": ("second point: NDVI", "第二点 NDVI"),
    "key.rate.linear.rate_1_kg_ha": ("second point: rate", "第二点施肥量"),
    "key.rate.linear.min_kg_ha": ("lowest rate", "最低施肥量"),
    "key.rate.linear.max_kg_ha": ("highest rate", "最高施肥量"),
    "key.rate.table.points": ("table: [NDVI, kg/ha] points", "查表：[NDVI, kg/ha] 点"),
    "key.speed.cv_window": ("CV window (fixes)", "变异系数窗口（定位数）"),
    "key.speed.min_work_speed_kmh": ("lowest working speed", "最低作业速度"),
}
