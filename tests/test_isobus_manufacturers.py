"""The manufacturer codes of a NAME as names (topdress.isobus.manufacturers) and the display's
words for a control function (topdress.display.isobus_names)."""

from __future__ import annotations

import pytest

from topdress import i18n
from topdress.display import isobus_names
from topdress.errors import ProtocolError
from topdress.i18n.catalogue import CATALOGUE
from topdress.isobus.manufacturers import MANUFACTURERS, manufacturer
from topdress.isobus.node import name_fields
from topdress.isobus.tcserver import tc_name
from topdress.view.snapshot import ControlFunctionView, IsobusView


@pytest.mark.parametrize(
    ("code", "name"),
    [
        (299, "Rauch"),  # fertilizer spreaders
        (98, "Mueller-Elektronik GmbH & Co"),
        (1407, "Open-Agriculture"),  # AgIsoStack++'s, and the topdress TC's NAME
        (674, "Yara International ASA"),  # the N-Sensor
        (1, None),  # a truck maker: not in the farm's table
        (0, None),  # reserved
        (2047, None),  # the highest an 11-bit field holds: not assigned
    ],
)
def test_known_and_unknown_codes(code: int, name: str | None) -> None:
    assert manufacturer(code) == name


def test_the_formerly_notes_are_left_out_of_the_name_in_use() -> None:
    assert "formerly Wachendorff" in MANUFACTURERS[171]
    assert manufacturer(171) == "Topcon Electronics GmbH & Co. KG"
    assert manufacturer(728) == "Streumaster"
    assert manufacturer(1208) == "Afflield Kft. (MachineryGuide)"  # not a former name: kept


@pytest.mark.parametrize("code", [-1, 2048, 65535])
def test_a_code_no_name_can_carry_is_refused(code: int) -> None:
    with pytest.raises(ProtocolError, match=rf"manufacturer code {code} outside 0..2047"):
        manufacturer(code)


def test_the_table_holds_11_bit_codes_and_names_only() -> None:
    assert len(MANUFACTURERS) > 200
    assert all(0 < code < 2048 for code in MANUFACTURERS)
    assert all(n == n.strip() and n for n in MANUFACTURERS.values())


def test_the_terminals_own_name_decodes_to_its_maker_and_function() -> None:
    f = name_fields(tc_name(200))
    assert isobus_names.maker(f["manufacturer_code"]) == "Open-Agriculture (1407)"
    key = isobus_names.function_key(f["industry_group"], f["device_class"], f["function"])
    assert key == "isobus.fn.tc"


def test_maker_shows_the_number_when_the_code_is_not_known() -> None:
    assert isobus_names.maker(299) == "Rauch (299)"
    assert isobus_names.maker(607) == "607"
    assert isobus_names.maker(0) == "0"


@pytest.mark.parametrize(
    ("group", "device_class", "function", "key"),
    [
        (2, 0, 130, "isobus.fn.tc"),
        (2, 5, 130, "isobus.fn.pressure"),  # the same code in a fertilizer: not a TC
        (2, 0, 134, "isobus.fn.tecu"),
        (2, 1, 130, "isobus.fn.rear_hitch"),
        (2, 5, 132, "isobus.fn.fert_machine"),
        (0, 0, 134, "isobus.fn.ground_speed"),
        (2, 9, 29, "isobus.fn.vt"),  # 0..127: any group and class
        (3, 4, 25, "isobus.fn.niu"),
        (2, 0, 138, None),  # "reserved" in the listing
        (2, 18, 132, None),  # a class not named here
        (2, 0, 255, None),
        (2, 0, 127, None),
    ],
)
def test_function_codes_by_group_and_class(
    group: int, device_class: int, function: int, key: str | None
) -> None:
    assert isobus_names.function_key(group, device_class, function) == key


def test_every_function_named_has_its_words_in_both_languages() -> None:
    names = set(isobus_names.GLOBAL_FUNCTIONS.values())
    for table in isobus_names.CLASS_FUNCTIONS.values():
        names |= set(table.values())
    assert {f"isobus.fn.{n}" for n in names} <= CATALOGUE.keys()
    assert all(0 <= code < 128 for code in isobus_names.GLOBAL_FUNCTIONS)
    for table in isobus_names.CLASS_FUNCTIONS.values():
        assert all(128 <= code < 255 for code in table)


def test_what_a_function_is_in_chinese() -> None:
    v = IsobusView(tc_address=247, implement_address=134)
    vt = ControlFunctionView(38, 0, 29, 0, 2, 98, 23)
    tc = ControlFunctionView(247, 0, 130, 0, 2, 1407, 200)
    spreader = ControlFunctionView(134, 0, 132, 5, 2, 299, 418)
    odd = ControlFunctionView(90, 0, 200, 5, 2, 0, 1)
    assert [isobus_names.what(f, v) for f in (vt, tc, spreader, odd)] == [
        "Virtual Terminal (in cab)",
        "task controller (this terminal)",
        "implement served: Fertilizers Machine Control",
        "function 200",
    ]
    i18n.set_language("zh")
    try:
        assert [isobus_names.what(f, v) for f in (vt, tc, spreader, odd)] == [
            "虚拟终端（驾驶室）",
            "任务控制器（本终端）",
            "所服务的机具：施肥机机器控制",
            "功能 200",
        ]
    finally:
        i18n.set_language("en")
