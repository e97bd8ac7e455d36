"""Words the display shows, in both languages: nothing left in English in Chinese."""

from __future__ import annotations

from dataclasses import replace

from topdress.config import default_config, loads_config
from topdress.i18n import render
from topdress.terminal.deskview import speed_why
from topdress.view.snapshot import Snapshot


def test_the_speed_mode_is_named_in_the_language_shown() -> None:
    snap = replace(Snapshot(), ecu_live=True, source="fused")
    why = speed_why(snap, default_config())  # the default mode: fused
    assert render(why, "zh") == "融合：速度模式 融合（卡尔曼）"
    assert render(why, "en") == "fused: speed mode fused (Kalman)"
    wheel = speed_why(replace(snap, source="wheel"), loads_config('[speed]\nmode = "wheel"\n'))
    assert render(wheel, "zh") == "地轮：速度模式 地轮"
