"""The states of the terminal's links (ECU, GNSS, crop sensors) as messages."""

from __future__ import annotations

from topdress.i18n import Text, text


def link_state(state: str) -> Text:
    """A link state: "ok", "wait", "lost", "no fix", "silent", or "3/4" (crop sensors fresh)."""
    if "/" in state:
        return text("link.partial", fresh=state)
    return text(f"link.{state.replace(' ', '_')}")
