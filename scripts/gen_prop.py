"""Generate ecu/isobus/src/gen/td_prop_gen.h from protocol/topdress.dbc: where each frame of the
paper's bus goes on an ISOBUS (the message's IsobusPgn attribute), for the ECU's ISOBUS layer.

    .venv/bin/python scripts/gen_prop.py [OUTPUT_DIR]

tests/test_isobus_prop.py holds the committed header to a fresh run.
"""

from __future__ import annotations

import sys
from pathlib import Path

import cantools

REPO = Path(__file__).resolve().parents[1]
DBC = REPO / "protocol" / "topdress.dbc"
HEADER = "td_prop_gen.h"
ATTRIBUTE = "IsobusPgn"


def rows(db: cantools.database.Database) -> list[tuple[str, int, int, int, bool]]:
    """(frame, fixed identifier, ISOBUS PGN, priority, sent by the ECU) of every frame that has
    an ISOBUS PGN, in the DBC's order."""
    out = []
    for msg in db.messages:
        attrs = msg.dbc.attributes if msg.dbc is not None else {}
        pgn = int(attrs[ATTRIBUTE].value) if ATTRIBUTE in attrs else 0
        if pgn == 0:
            continue
        by_ecu = msg.senders == ["ECU"]
        if not by_ecu and msg.senders != ["PC"]:
            raise SystemExit(f"{msg.name} in {DBC}: one sender, ECU or PC, expected")
        out.append((msg.name, msg.frame_id, pgn, (msg.frame_id >> 26) & 7, by_ecu))
    keys = [(pgn, by_ecu) for _, _, pgn, _, by_ecu in out]
    if len(set(keys)) != len(keys):
        raise SystemExit(f"two frames of one sender share an {ATTRIBUTE} in {DBC}")
    return out


def generate(db: cantools.database.Database) -> str:
    table = rows(db)
    out = [
        "/* Generated from protocol/topdress.dbc by scripts/gen_prop.py: never edit by hand. */",
        "#ifndef TD_PROP_GEN_H",
        "#define TD_PROP_GEN_H",
        "",
        "/* The frames of the paper's bus on an ISOBUS: X(frame, fixed 29-bit identifier, ISOBUS",
        " * PGN, priority, 1 sent by the ECU / 0 by the terminal). */",
        f"#define TD_PROP_COUNT {len(table)}u",
        "#define TD_PROP_TABLE(X) \\",
    ]
    for name, ident, pgn, prio, by_ecu in table:
        out.append(f"    X({name}, 0x{ident:08X}u, 0x{pgn:05X}u, {prio}u, {int(by_ecu)}u) \\")
    out += ["    /* end */", "", "#endif"]
    return "\n".join(out) + "\n"


def main() -> None:
    out_dir = Path(sys.argv[1]) if len(sys.argv) > 1 else REPO / "ecu" / "isobus" / "src" / "gen"
    db = cantools.database.load_file(str(DBC))
    assert isinstance(db, cantools.database.can.Database)
    (out_dir / HEADER).write_text(generate(db), encoding="utf-8")


if __name__ == "__main__":
    main()
