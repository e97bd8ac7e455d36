"""docs/protocol.md and docs/ecu.md stay in step with the DBC and the core's defaults: every signal
and every parameter has its row, with the layout, resolution, range and default of today."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from topdress.ecu import EcuParams
from topdress.protocol import database, params

DOCS = Path(__file__).resolve().parents[1] / "docs"


def num(x: float) -> str:
    """A number as the docs write it: no exponent, no trailing zeros."""
    return f"{x:.6f}".rstrip("0").rstrip(".")


def where(sig: Any) -> str:
    """Bytes (and bits inside a byte) of a little-endian signal."""
    first, last = sig.start // 8, (sig.start + sig.length - 1) // 8
    if sig.start % 8 == 0 and sig.length % 8 == 0:
        return str(first) if first == last else f"{first}-{last}"
    lo, hi = sig.start % 8, (sig.start + sig.length - 1) % 8
    return f"{first}, bit {lo}" if lo == hi else f"{first}, bits {lo}-{hi}"


def signal_rows() -> list[str]:
    rows = []
    for msg in database().messages:
        for sig in msg.signals:
            if sig.multiplexer_ids:
                continue  # the parameters have their own table
            rows.append(
                f"| `{sig.name}` | {where(sig)} | {num(sig.scale)} | "
                f"{num(sig.minimum)}..{num(sig.maximum)} | {sig.unit or '-'} |"
            )
    return rows


def param_rows() -> list[str]:
    defaults = EcuParams.defaults()
    return [
        f"| {p.id} | `{p.signal}` | `{p.key}` | {p.unit or '-'} | "
        f"{num(p.minimum)}..{num(p.maximum)} | {num(p.scale)} | {num(defaults.get(p.id))} |"
        for p in params()
    ]


@pytest.mark.parametrize(("doc", "rows"), [("protocol.md", signal_rows), ("ecu.md", param_rows)])
def test_doc_tables_match_the_dbc_and_the_defaults(doc: str, rows: Any) -> None:
    lines = (DOCS / doc).read_text(encoding="utf-8").splitlines()
    missing = [r for r in rows() if not any(line.startswith(r) for line in lines)]
    assert not missing, f"docs/{doc} is out of date; rows expected:\n" + "\n".join(missing)


def test_protocol_doc_names_every_frame() -> None:
    text = (DOCS / "protocol.md").read_text(encoding="utf-8")
    for msg in database().messages:
        assert f"`{msg.name}` 0x{msg.frame_id:08X}" in text
