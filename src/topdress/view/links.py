"""The states of the terminal's links (ECU, GNSS, crop sensors) and the ECU's fault word, in
words."""

from __future__ import annotations

from topdress.i18n import Text, render, text, tr
from topdress.protocol import fault_names


def link_state(state: str) -> Text:
    """A link state: "ok", "wait", "lost", "no fix", "silent", or "3/4" (crop sensors fresh)."""
    if "/" in state:
        return text("link.partial", fresh=state)
    return text(f"link.{state.replace(' ', '_')}")


def link_text(state: str) -> str:
    """A link state in words, in the language in force (topdress.view.links)."""
    return render(link_state(state))


def fault_texts(word: int) -> list[str]:
    """The bits of a fault word in the catalogue's words (unknown bits as BITn)."""
    return [n if n.startswith("BIT") else tr(f"fault.{n}") for n in fault_names(word)]
