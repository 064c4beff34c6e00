"""docs/architecture.md's import layers hold in the code: every module of the package is in one
layer, imports only from its own layer or earlier ones, and the imports have no cycle."""

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "tdct_jax"


def _module(path: Path) -> str:
    """A module's name in the package, a subpackage's modules under its own name (``ik``)."""
    parts = path.relative_to(PACKAGE).with_suffix("").parts
    return parts[0] if len(parts) > 1 else parts[0]


def _imports() -> dict[str, set[str]]:
    """Each module (or subpackage) -> the package's modules it imports (relative imports)."""
    modules = {_module(p) for p in PACKAGE.rglob("*.py")}
    graph = {m: set() for m in modules}
    for path in PACKAGE.rglob("*.py"):
        me, depth = _module(path), len(path.relative_to(PACKAGE).parts) - 1
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ImportFrom) or not node.level:
                continue
            up = node.level - 1 - depth  # levels above the package root: none
            assert up <= 0, f"{path}: import above the package"
            names = node.module.split(".") if node.module else []
            if node.level - 1 < depth and me != "__init__":  # inside a subpackage, e.g. from .problem import
                continue
            # ``from . import name``: the module of that name, else a name of the package's __init__
            targets = [names[0]] if names else [a.name if a.name in modules else "__init__" for a in node.names]
            graph[me] |= {t for t in targets if t in modules and t != me}
    return graph


def _layers() -> list[list[str]]:
    """The numbered layers of docs/architecture.md's "What depends on what"."""
    text = (ROOT / "docs" / "architecture.md").read_text()
    section = text.split("## What depends on what", 1)[1].split("\n## ", 1)[0]
    return [re.findall(r"`([\w_]+)`", line) for line in section.splitlines() if re.match(r"^\d+\. ", line)]


def test_every_module_is_in_one_layer():
    layers = _layers()
    named = [m for layer in layers for m in layer]
    assert len(named) == len(set(named)), "a module is named in two layers"
    assert set(named) == set(_imports()), (
        f"in the code, not the layers: {set(_imports()) - set(named)}; in the layers only: {set(named) - set(_imports())}"
    )


def test_no_module_imports_from_a_later_layer():
    rank = {m: i for i, layer in enumerate(_layers()) for m in layer}
    upward = [f"{m} ({rank[m] + 1}) imports {d} ({rank[d] + 1})" for m, ds in _imports().items() for d in ds if rank[d] > rank[m]]
    assert not upward, upward


def test_imports_have_no_cycle():
    graph, done, path = _imports(), set(), []

    def visit(m):
        assert m not in path, "import cycle: " + " -> ".join(path[path.index(m) :] + [m])
        if m in done:
            return
        path.append(m)
        for d in sorted(graph[m]):
            visit(d)
        path.pop()
        done.add(m)

    for m in sorted(graph):
        visit(m)
