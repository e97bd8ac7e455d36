"""The package's layers (docs/architecture.md): imports run only down, no two modules import
each other, the loop, the screens and the simulator do not import one another. Every import is
counted: at the top of a module, inside a function, under TYPE_CHECKING."""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"

#: Top to bottom; a module may import its own layer's and the ones below.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("topdress.cli", "topdress.__main__"),
    ("topdress.display", "topdress.terminal", "topdress.sim"),
    ("topdress.office",),
    ("topdress.geo",),
    ("topdress.log",),
    ("topdress.crop", "topdress.devices", "topdress.config_edit"),
    ("topdress.config", "topdress.ecu", "topdress.isobus", "topdress.view", "topdress.outpath"),
    ("topdress.protocol", "topdress.gnss", "topdress.i18n", "topdress.errors", "topdress"),
)
#: Siblings of one layer that must not import one another.
APART = ("topdress.display", "topdress.terminal", "topdress.sim")


def _module(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _owner(module: str, names: tuple[str, ...]) -> str | None:
    """The longest of `names` that is `module` or a package holding it."""
    hits = [n for n in names if module == n or module.startswith(n + ".")]
    return max(hits, key=len) if hits else None


def _rank(module: str) -> tuple[int, str]:
    best: tuple[int, str] | None = None
    for rank, names in enumerate(LAYERS):
        owner = _owner(module, names)
        if owner is not None and (best is None or len(owner) > len(best[1])):
            best = (rank, owner)
    assert best is not None, f"{module} is on no layer: give it one in LAYERS and the docs"
    return best


def _imports() -> dict[str, set[str]]:
    """Module -> the topdress modules it imports (a name imported from a package counts as its
    submodule when there is one)."""
    files = {_module(p): p for p in (SRC / "topdress").rglob("*.py")}
    out: dict[str, set[str]] = {}
    for module, path in files.items():
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        found: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                found |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    base = ".".join(
                        [*package.split(".")[: len(package.split(".")) - node.level + 1], base]
                    ).rstrip(".")
                for a in node.names:
                    sub = f"{base}.{a.name}"
                    found.add(sub if sub in files else base)
        out[module] = {m for m in found if m == "topdress" or m.startswith("topdress.")}
    return out


def test_imports_run_only_down_the_layers() -> None:
    up = []
    for module, imported in sorted(_imports().items()):
        rank, owner = _rank(module)
        for other in sorted(imported):
            other_rank, other_owner = _rank(other)
            if other_rank < rank:
                up.append(f"{module} -> {other} (up from {owner} to {other_owner})")
            elif other_owner != owner and owner in APART and other_owner in APART:
                up.append(f"{module} -> {other} ({owner} and {other_owner} stay apart)")
    assert up == []


def test_no_two_modules_import_each_other() -> None:
    graph = _imports()
    circles = []
    state: dict[str, int] = {}  # 1 on the path, 2 done

    def visit(module: str, path: list[str]) -> None:
        state[module] = 1
        for other in sorted(graph.get(module, ())):
            if other == module or other == "topdress":
                continue
            if state.get(other) == 1:
                circles.append(" -> ".join([*path[path.index(other) :], other]))
            elif other not in state:
                visit(other, [*path, other])
        state[module] = 2

    for module in sorted(graph):
        if module not in state:
            visit(module, [module])
    assert circles == []


def test_every_module_is_on_a_layer_the_docs_name() -> None:
    docs = (SRC.parent / "docs" / "architecture.md").read_text(encoding="utf-8")
    for names in LAYERS:
        for name in names:
            if name.startswith("topdress."):
                short = name.removeprefix("topdress.").replace(".", "/")
                assert f"`{short}" in docs, f"docs/architecture.md does not place {name}"
    for module in _imports():
        _rank(module)
