"""One table of ECU parameters (topdress.protocol.params): every parameter of the DBC has a
configuration key, a field on the display and a refusal mapping, and the speed modes have one
name everywhere."""

from __future__ import annotations

from typing import Any

import pytest

from topdress import protocol
from topdress.config import ECU_KEYS, SPEED_MODE_IDS, default_config, loads_config
from topdress.config_edit import section_values, validate_section
from topdress.ecu import Ecu, EcuParams
from topdress.protocol import SpeedMode, database
from topdress.terminal.desksettings import refused_key


def _dbc_param_ids() -> list[int]:
    """Every value of PcParamSet's multiplexer (ParamId), from the DBC through cantools."""
    msg = database().get_message_by_name("PcParamSet")
    mux = next(s for s in msg.signals if s.is_multiplexer)
    return list(range(int(mux.minimum), int(mux.maximum) + 1))


def _a_value(spec: protocol.ParamSpec) -> Any:
    """A value to set the parameter's configuration key to: the ECU's default for an [ecu]
    override, a mode the ECU does not start in, the default of [machine] and [speed] (always
    pushed)."""
    if spec.config_key == "speed.mode":
        return "fused"
    if spec.config_key == "speed.switch_compare":
        return "wheel"
    if spec.section == "ecu":
        return spec.default
    if spec.section == "lookahead":
        return 120
    return getattr(getattr(default_config(), spec.section), spec.name)


def test_the_table_covers_every_parameter_id_of_the_dbc() -> None:
    ids = _dbc_param_ids()
    assert ids == list(range(1, 40))
    assert [s.id for s in protocol.params()] == ids


@pytest.mark.parametrize("pid", _dbc_param_ids())
def test_every_parameter_has_a_key_a_field_and_a_refusal_mapping(pid: int) -> None:
    spec = protocol.param(pid)
    # The table is read from the DBC's text without cantools: it agrees with cantools' reading.
    sig = database().get_message_by_name("PcParamSet").get_signal_by_name(spec.signal)
    assert sig.multiplexer_ids == [pid]
    assert (spec.scale, spec.minimum, spec.maximum) == (sig.scale, sig.minimum, sig.maximum)
    assert spec.unit == (sig.unit or "")
    # the ECU's default is the C core's
    assert spec.default == EcuParams.defaults().get(spec.key)
    # the key: the configuration takes it, and then pushes this parameter with its value
    section, name = spec.section, spec.name
    value = _a_value(spec)
    cfg = validate_section(default_config(), section, {name: value})
    pushed = cfg.ecu_params()
    expected = SPEED_MODE_IDS[value] if name == "mode" else value
    if name == "switch_compare":
        expected = protocol.Compare(value).code
    assert pushed[pid] == pytest.approx(expected)
    # the field: the display's form of the section shows the key
    assert name in section_values(cfg, section)
    # the refusal: an ECU refusing this parameter is shown at that field
    error = f"{spec.signal} = {value}: refused by the ECU: out of range"
    assert refused_key(error, pushed, section) == spec.config_key
    assert refused_key("something else", pushed, section) == section


def test_ecu_keys_take_the_dbc_range_and_resolution() -> None:
    assert set(ECU_KEYS) == {s.name for s in protocol.params() if s.section == "ecu"}
    assert "fused_jerk_ms3" in ECU_KEYS and "meter_tau_ms" in ECU_KEYS
    with pytest.raises(Exception, match=r"ecu\.meter_tau_ms: 2001 is outside 0\.\.2000"):
        loads_config("[ecu]\nmeter_tau_ms = 2001\n")
    with pytest.raises(Exception, match=r"ecu\.wheel_stop_ms: must be an integer"):
        loads_config("[ecu]\nwheel_stop_ms = 20.5\n")
    with pytest.raises(Exception, match=r"machine\.width_m: 31\.0 is outside 0\.5\.\.30"):
        loads_config("[machine]\nwidth_m = 31.0\n")


@pytest.mark.parametrize("mode", list(SpeedMode))
def test_a_speed_mode_has_one_name_in_the_configuration_the_protocol_and_the_ecu(
    mode: SpeedMode,
) -> None:
    cfg = loads_config(f'[speed]\nmode = "{mode}"\n')
    assert SpeedMode(cfg.speed.mode) is mode
    # pushed to the C core and reported back by it in EcuDiag under the same name
    pid = protocol.param("speed.mode").id
    ecu = Ecu(EcuParams.defaults())
    ecu.rx(protocol.encode_param_set(pid, cfg.ecu_params()[pid]), 0)
    diags = []
    for k in range(1, 30):
        ecu.step_raw(k * 10_000, 0, 0, 0, 0, 0)
        diags += [d for d in map(protocol.decode, ecu.tx()) if isinstance(d, protocol.EcuDiag)]
    assert diags and all(d.mode is mode for d in diags)


def test_the_default_speed_mode_is_fused_and_each_mode_has_one_name() -> None:
    cfg = default_config()
    assert cfg.speed.mode == SpeedMode.FUSED == "fused"
    assert cfg.ecu_params()[protocol.param("speed.mode").id] == SpeedMode.FUSED.code == 3
    assert (
        list(SPEED_MODE_IDS) == [str(m) for m in SpeedMode] == ["paper", "wheel", "gnss", "fused"]
    )
