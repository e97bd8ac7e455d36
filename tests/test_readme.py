"""The README and the docs index stay true: every command the README shows parses as written,
every make target it names exists, every document in docs/ is listed, and the licence that
pyproject.toml declares is in the repository."""

from __future__ import annotations

import re
import shlex
import tomllib
from pathlib import Path

import pytest

from topdress.cli.main import build_parser

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def _readme_commands() -> list[str]:
    """The `topdress …` lines of the README's code blocks, without their comments; a word
    `a|b|c` stands for any one of them, so each alternative makes a line of its own."""
    blocks = re.findall(r"```sh\n(.*?)```", README, flags=re.S)
    lines = [ln.split("#", 1)[0].strip() for b in blocks for ln in b.splitlines()]
    out: list[str] = []
    for line in (ln for ln in lines if ln.startswith("topdress ")):
        words = line.split()
        alts = [i for i, w in enumerate(words) if "|" in w]
        if not alts:
            out.append(line)
        for i in alts:
            out += [" ".join([*words[:i], a, *words[i + 1 :]]) for a in words[i].split("|")]
    return out


def test_the_readme_shows_commands() -> None:
    assert len(_readme_commands()) >= 10


@pytest.mark.parametrize("line", _readme_commands())
def test_every_readme_command_parses_as_written(line: str) -> None:
    words = [w.split("|", 1)[0] for w in shlex.split(line)[1:]]
    try:
        args = build_parser().parse_args(words)
    except SystemExit as exc:  # argparse's way of refusing a command line
        pytest.fail(f"README: `{line}` does not parse (exit {exc.code})")
    assert callable(args.func)


def test_every_log_export_line_asks_for_an_output() -> None:
    """`topdress log export SESSION` alone writes nothing ("nothing to do"): the README never
    shows it without an output option."""
    exports = [ln for ln in _readme_commands() if ln.startswith("topdress log export")]
    assert exports
    for line in exports:
        assert re.search(r"--(out|events|csv|log-events|config|can) ", line), line


def test_every_make_target_the_readme_names_exists() -> None:
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    targets = set(re.findall(r"^([a-z][a-z0-9-]*):", makefile, flags=re.M))
    named = set(re.findall(r"\bmake (?:[A-Z]+=\S+ )?([a-z][a-z0-9-]*)", README))
    assert {"demo", "test", "check"} <= named
    assert named <= targets, named - targets


def test_the_docs_index_lists_every_document() -> None:
    index = (ROOT / "docs" / "README.md").read_text(encoding="utf-8")
    listed = set(re.findall(r"\]\(([\w.-]+\.md)\)", index))
    docs = {p.name for p in (ROOT / "docs").glob("*.md")} - {"README.md"}
    assert docs <= listed, f"not in docs/README.md: {sorted(docs - listed)}"


def test_the_declared_licence_is_in_the_repository() -> None:
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert meta["license"]["text"] == "MIT"
    text = (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert text.startswith("MIT License")
    assert "Permission is hereby granted, free of charge" in text
