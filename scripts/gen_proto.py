"""Generate ecu/src/gen/td_dbc.h from protocol/topdress.dbc: the protocol's facts for the C core.

    .venv/bin/python scripts/gen_proto.py [OUTPUT_DIR]     (scripts/gen_codec.sh runs it)

Frame identifiers (TD_ID_<FRAME>), the value tables the core uses as C enums, and the table of
ECU parameters (TD_PARAM_TABLE: id, td_params_t field from the signal's TdField attribute,
storage, resolution, raw range): the C core writes none of them by hand. The Python side reads
the same DBC (topdress.protocol); tests/test_protocol_codec.py holds the committed header to a
fresh run, tests/test_protocol_facts.py keeps hand-written copies out.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import cantools

REPO = Path(__file__).resolve().parents[1]
DBC = REPO / "protocol" / "topdress.dbc"
HEADER = "td_dbc.h"

#: The value tables the core uses: (frame, signal) -> (C type, member prefix). Only how the C
#: names are spelled is here; the values and their names are the DBC's.
ENUMS = {
    ("EcuDiag", "SpeedSource"): ("td_source_t", "TD_SRC"),
    ("EcuDiag", "SpeedMode"): ("td_speed_mode_t", "TD_MODE"),
    ("EcuDiag", "SwitchCompare"): ("td_compare_t", "TD_CMP"),
    ("EcuParamAck", "AckResult"): ("td_ack_result_t", "TD_ACK"),
    ("EcuCalStatus", "CalState"): ("td_cal_state_t", "TD_CAL"),
    ("EcuCalStatus", "CalReason"): ("td_cal_reason_t", "TD_CAL_R"),
    ("EcuGnssLag", "LagState"): ("td_lag_state_t", "TD_LAG"),
    ("EcuIdent", "Target"): ("td_target_t", "TD_TARGET"),
    ("EcuIdent", "Transport"): ("td_transport_t", "TD_TRANSPORT"),
    ("EcuIdent", "ResetCause"): ("td_reset_cause_t", "TD_RESET"),
}
#: Value tables the core uses as plain constants (the paper's bytes): (frame, signal) -> prefix.
CONSTANTS = {("EcuStatus", "RunState"): "TD_RUN"}
#: Bit words whose bits the DBC names, lowest first, in the signal's TdBits attribute.
BITS = {("EcuDiag", "FaultWord"): "TD_FAULT"}
FIELD_ATTRIBUTE = "TdField"
_TYPES = {"F32": "TD_PF32", "U8": "TD_PU8", "U16": "TD_PU16"}


def upper(name: str) -> str:
    """ "WheelOnly" -> "WHEEL_ONLY", "Stm32f4" -> "STM32F4"."""
    return re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name).upper()


def _choices(db: cantools.database.Database, frame: str, signal: str) -> dict[int, str]:
    sig = db.get_message_by_name(frame).get_signal_by_name(signal)
    if not sig.choices:
        raise SystemExit(f"{frame}.{signal} has no value table in {DBC}")
    return {int(k): str(v) for k, v in sorted(sig.choices.items())}


def _bits(db: cantools.database.Database, frame: str, signal: str) -> list[str]:
    sig = db.get_message_by_name(frame).get_signal_by_name(signal)
    attrs = sig.dbc.attributes if sig.dbc is not None else {}
    if "TdBits" not in attrs:
        raise SystemExit(f"{frame}.{signal} has no TdBits attribute in {DBC}")
    return str(attrs["TdBits"].value).split()


def _storage(scale: float, raw_max: int) -> str:
    """How td_params_t holds a parameter: a float unless it counts in whole units (checked
    against the struct's field sizes by TD_PARAM_TABLE's users)."""
    if scale != 1:
        return "F32"
    return "U8" if raw_max <= 0xFF else "U16"


def generate(db: cantools.database.Database) -> str:
    out = [
        "/* Generated from protocol/topdress.dbc by scripts/gen_proto.py: never edit by hand. */",
        "#ifndef TD_DBC_H",
        "#define TD_DBC_H",
        "",
        "/* Frame identifiers (29-bit). */",
    ]
    for msg in db.messages:
        out.append(f"#define TD_ID_{upper(msg.name)} 0x{msg.frame_id:08X}u")
    out.append("/* Every frame's identifier: X(TD_ID_<FRAME>). */")
    out.append("#define TD_FRAME_IDS(X) \\")
    out += [f"    X(TD_ID_{upper(msg.name)}) \\" for msg in db.messages]
    out.append("    /* end */")
    for (frame, signal), prefix in CONSTANTS.items():
        out += ["", f"/* {frame}.{signal} */"]
        for code, name in _choices(db, frame, signal).items():
            out.append(f"#define {prefix}_{upper(name)} 0x{code:02X}u")
    for (frame, signal), prefix in BITS.items():
        out += ["", f"/* {frame}.{signal}: one bit each, lowest first */"]
        for bit, name in enumerate(_bits(db, frame, signal)):
            out.append(f"#define {prefix}_{upper(name)} (1u << {bit})")
    for (frame, signal), (ctype, prefix) in ENUMS.items():
        members = ", ".join(
            f"{prefix}_{upper(name)} = {code}" for code, name in _choices(db, frame, signal).items()
        )
        out += ["", f"/** {frame}.{signal} */", f"typedef enum {{ {members} }} {ctype};"]
    out += _params(db)
    out += ["", "#endif"]
    return "\n".join(out) + "\n"


def _params(db: cantools.database.Database) -> list[str]:
    msg = db.get_message_by_name("PcParamSet")
    rows = []
    for sig in msg.signals:
        if not sig.multiplexer_ids:
            continue
        (pid,) = sig.multiplexer_ids
        attrs = sig.dbc.attributes if sig.dbc is not None else {}
        if FIELD_ATTRIBUTE not in attrs:
            raise SystemExit(f"PcParamSet.{sig.name} has no {FIELD_ATTRIBUTE} attribute in {DBC}")
        field = str(attrs[FIELD_ATTRIBUTE].value)
        scale = float(sig.scale)
        raw_min, raw_max = round(sig.minimum / scale), round(sig.maximum / scale)
        storage = _TYPES[_storage(scale, raw_max)]
        rows.append((pid, sig.name, field, storage, scale, raw_min, raw_max))
    rows.sort()
    if [r[0] for r in rows] != list(range(1, len(rows) + 1)):
        raise SystemExit(f"PcParamSet's ids in {DBC} are not 1..{len(rows)}")
    out = [
        "",
        "/* PcParamSet: one row a parameter, id order: X(id, signal, td_params_t field, storage,",
        " * resolution, raw minimum, raw maximum). */",
        f"#define TD_PARAM_COUNT {len(rows)}u",
        "#define TD_PARAM_TABLE(X) \\",
    ]
    for pid, name, field, storage, scale, lo, hi in rows:
        out.append(f"    X({pid}, {name}, {field}, {storage}, {scale!r}f, {lo}u, {hi}u) \\")
    out.append("    /* end */")
    return out


def main() -> None:
    out_dir = Path(sys.argv[1]) if len(sys.argv) > 1 else REPO / "ecu" / "src" / "gen"
    db = cantools.database.load_file(str(DBC))
    (out_dir / HEADER).write_text(generate(db), encoding="utf-8")
    print(f"generated {out_dir / HEADER}")


if __name__ == "__main__":
    main()
