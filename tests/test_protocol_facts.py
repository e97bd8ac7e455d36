"""One source for the protocol's facts: the DBC files. Frame identifiers, the value tables the
code uses (sources, modes, compare, acknowledgements, calibration and lag states, EcuIdent's
names) and the table of ECU parameters are read from protocol/*.dbc by the Python package and
generated from it for the C core (ecu/src/gen/td_dbc.h, scripts/gen_proto.py). These tests fail
when a hand-written copy appears again in the sources (tests and docs may state values: they
are checked against the DBC elsewhere)."""

from __future__ import annotations

import re
from pathlib import Path

import cantools
import pytest

from topdress import protocol
from topdress.protocol import Fault, Source, SpeedMode
from topdress.protocol.dbc import frame_ids, value_table

REPO = Path(__file__).resolve().parents[1]
DBCS = [REPO / "protocol" / "topdress.dbc", REPO / "protocol" / "topdress_hil.dbc"]


def _sources() -> list[Path]:
    """The project's own source files: Python, C and the scripts; generated files, tests and
    vendored code left out."""
    roots = [REPO / "src" / "topdress", REPO / "ecu", REPO / "bench", REPO / "scripts"]
    out = []
    for root in roots:
        for path in root.rglob("*"):
            if path.suffix not in (".py", ".c", ".h") or not path.is_file():
                continue
            parts = set(path.relative_to(REPO).parts)
            if parts & {"gen", "tests", "vendor", "build", "__pycache__"}:
                continue
            out.append(path)
    return sorted(out)


def _ids() -> dict[int, str]:
    out = {}
    for dbc in DBCS:
        for msg in cantools.database.load_file(str(dbc)).messages:
            out[msg.frame_id] = msg.name
    return out


def test_the_sources_are_found() -> None:
    names = {p.name for p in _sources()}
    assert {"td_params.c", "td_proto.h", "model.py", "app.py", "gen_proto.py"} <= names
    assert "td_dbc.h" not in names and "td_can.h" not in names


def test_no_frame_identifier_is_written_by_hand() -> None:
    ids = _ids()
    assert len(ids) >= 19  # the bus's frames and the HIL link's
    found = []
    for path in _sources():
        text = path.read_text(encoding="utf-8", errors="replace")
        for m in re.finditer(r"\b0[xX]([0-9A-Fa-f]{7,8})[uU]?\b|\b(\d{9,10})\b", text):
            value = int(m[1], 16) if m[1] else int(m[2])
            if value & 0x1FFFFFFF in ids and value >= 0x100000:
                found.append(f"{path.relative_to(REPO)}: {m[0]} ({ids[value & 0x1FFFFFFF]})")
    assert not found, "frame ids written by hand (take them from the DBC):\n" + "\n".join(found)


_C_TABLES = re.compile(
    r"#define\s+TD_(?:ID|RUN)_\w+\s+0x|#define\s+TD_PARAM_COUNT\s+\d"
    r"|#define\s+TD_FAULT_\w+\s+\(?\s*1u?\s*<<"
    r"|typedef\s+enum\s*\{\s*TD_(?:SRC|MODE|CMP|ACK|CAL|CAL_R|LAG|TARGET|TRANSPORT|RESET)_\w+\s*="
    r"|offsetof\(td_params_t,\s*(?!field\))\w+"
)


def test_no_c_header_or_table_restates_the_generated_one() -> None:
    found = []
    for path in _sources():
        if path.suffix not in (".c", ".h"):
            continue
        text = path.read_text(encoding="utf-8", errors="replace")
        found += [f"{path.relative_to(REPO)}: {m[0]}" for m in _C_TABLES.finditer(text)]
    assert not found, "C copies of td_dbc.h (include it instead):\n" + "\n".join(found)


# Three or more of the names of one value table, and only those, in one tuple or list.
_TABLES = {
    "speed modes": {str(m) for m in SpeedMode},
    "speed sources": {str(s) for s in Source},
    "reset causes": set(protocol.RESET_CAUSES),
    "transports": set(protocol.TRANSPORTS),
}


@pytest.mark.parametrize("table", sorted(_TABLES))
def test_no_python_source_lists_a_value_table_by_hand(table: str) -> None:
    names = _TABLES[table]
    literal = re.compile(r"[(\[]\s*((?:\"[\w -]+\"\s*,\s*){2,}\"[\w -]+\"\s*,?\s*)[)\]]")
    found = []
    for path in _sources():
        if path.suffix != ".py":
            continue
        text = path.read_text(encoding="utf-8")
        for m in literal.finditer(text):
            items = set(re.findall(r"\"([\w -]+)\"", m[1]))
            if len(items & names) >= 3 and items <= names | {"none"}:
                found.append(f"{path.relative_to(REPO)}: {m[0]}")
    assert not found, f"the {table} written by hand (take them from the enum):\n" + "\n".join(found)


def test_no_python_source_numbers_the_fault_bits_by_hand() -> None:
    bit = re.compile(rf"\b(?:{'|'.join(f.name or '' for f in Fault)})\s*=\s*(?:1\s*<<|0x|\d)")
    found = []
    for path in _sources():
        if path.suffix == ".py":
            text = path.read_text(encoding="utf-8")
            found += [f"{path.relative_to(REPO)}: {m[0]}" for m in bit.finditer(text)]
    assert not found, "fault bits numbered by hand (the DBC's TdBits):\n" + "\n".join(found)


def test_no_python_source_maps_a_parameter_to_its_field_by_hand() -> None:
    signals = "|".join(spec.signal for spec in protocol.params())
    pair = re.compile(rf"\"(?:{signals})\"\s*:\s*\(\s*\"[a-z_]+\"")  # a field, not a `section.key`
    found = []
    for path in _sources():
        if path.suffix == ".py":
            text = path.read_text(encoding="utf-8")
            found += [f"{path.relative_to(REPO)}: {m[0]}" for m in pair.finditer(text)]
    assert not found, "PcParamSet fields written by hand (the DBC's TdField):\n" + "\n".join(found)


def test_the_guards_catch_a_copy() -> None:
    """The patterns above find what they are for (so a test that passes says something)."""
    assert _C_TABLES.search("#define TD_ID_ECU_STATUS 0x185C6465u")
    assert _C_TABLES.search("typedef enum { TD_MODE_DUAL = 0, TD_MODE_FUSED = 3 } td_speed_mode_t;")
    assert _C_TABLES.search("{ (uint16_t)offsetof(td_params_t, working_width_m), F32 }")
    assert not _C_TABLES.search("{ (uint16_t)offsetof(td_params_t, field), (uint8_t)(type) }")
    assert _C_TABLES.search("#define TD_FAULT_GNSS_LOST (1u << 1)   /**< GNSS speed missing */")
    assert not _C_TABLES.search("#define TD_FAULT_LATCHED_MASK (TD_FAULT_WHEEL_ENCODER | x)")


def test_python_reads_what_the_dbc_says() -> None:
    db = cantools.database.load_file(str(DBCS[0]))
    assert frame_ids() == {m.name: m.frame_id for m in db.messages}
    ids = protocol.DEFAULT_IDS
    assert (ids.status, ids.command, ids.ident) == (
        frame_ids()["EcuStatus"],
        frame_ids()["PcCommand"],
        frame_ids()["EcuIdent"],
    )
    diag = db.get_message_by_name("EcuDiag")
    for signal, enum in (("SpeedMode", SpeedMode), ("SpeedSource", Source)):
        choices = {int(k): str(v) for k, v in diag.get_signal_by_name(signal).choices.items()}
        assert value_table("EcuDiag", signal) == choices
        assert [m.code for m in enum] == sorted(m.code for m in enum)
        assert len(list(enum)) == len(choices)
    assert SpeedMode.PAPER.code == 0 and value_table("EcuDiag", "SpeedMode")[0] == "Dual"
    word = diag.get_signal_by_name("FaultWord")
    assert word.dbc is not None
    assert [f.name for f in Fault] == [
        re.sub(r"(?<=[a-z])(?=[A-Z])", "_", n).upper()
        for n in word.dbc.attributes["TdBits"].value.split()
    ]
    for spec in protocol.params():
        sig = db.get_message_by_name("PcParamSet").get_signal_by_name(spec.signal)
        assert sig.dbc is not None and sig.dbc.attributes["TdField"].value == spec.key
