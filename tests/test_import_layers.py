"""No import circles, and imports point down the layers (docs/architecture.md).

The import graph of the four packages is read from the source with :mod:`ast` (nothing is
imported): every ``import`` and ``from ... import`` counts, at module level, inside a function
(a lazy import) or under ``if TYPE_CHECKING:``, because each is a dependency all the same; an
import inside a function only postpones a circle, it does not break it.

Layers (an import may point to its own package or to the packages listed):

    warpdem      the engine                       -> nothing of the applications
    calibration  experiments, measurement, ...    -> warpdem
    validation   diagnosis (top)                  -> calibration, warpdem
    pump         slurry-pump wear (top)           -> calibration, warpdem

``benchmarks``, ``examples``, ``scripts`` and ``tests`` sit above all four and none of the four
may import them. A cycle is a strongly connected component of more than one module (or a module
that imports itself); a package counts as its ``__init__`` module.
"""
from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("warpdem", "calibration", "validation", "pump")
#: package -> the packages its modules may import (besides third-party ones)
ALLOWED = {
    "warpdem": {"warpdem"},
    "calibration": {"calibration", "warpdem"},
    "validation": {"validation", "calibration", "warpdem"},
    "pump": {"pump", "calibration", "warpdem"},
}
#: first-party folders above the packages: never imported by them
ABOVE = ("benchmarks", "examples", "scripts", "tests")


@dataclass(frozen=True)
class Edge:
    source: str      # importing module
    target: str      # imported module (the longest first-party module the name reaches)
    line: int
    kind: str        # "top", "lazy" (inside a function) or "type" (under TYPE_CHECKING)

    def __str__(self) -> str:
        return f"{self.source} -> {self.target} (line {self.line}, {self.kind})"


def find_modules(root: Path, packages=PACKAGES) -> dict[str, tuple[Path, bool]]:
    """Dotted module name -> (file, is a package ``__init__``) for every .py file of ``packages``."""
    mods: dict[str, tuple[Path, bool]] = {}
    for pkg in packages:
        for f in sorted((root / pkg).rglob("*.py")):
            parts = list(f.relative_to(root).with_suffix("").parts)
            if "__pycache__" in parts:
                continue
            is_pkg = parts[-1] == "__init__"
            mods[".".join(parts[:-1] if is_pkg else parts)] = (f, is_pkg)
    return mods


def _kind(node: ast.AST, parents: dict[ast.AST, ast.AST]) -> str:
    kind = "top"
    p = parents.get(node)
    while p is not None:
        if isinstance(p, ast.If) and "TYPE_CHECKING" in ast.unparse(p.test):
            return "type"
        if isinstance(p, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            kind = "lazy"
        p = parents.get(p)
    return kind


def _resolve(name: str, mods) -> str | None:
    parts = name.split(".")
    while parts:
        if ".".join(parts) in mods:
            return ".".join(parts)
        parts.pop()
    return None


def import_edges(root: Path, packages=PACKAGES, above=ABOVE) -> tuple[dict, list[Edge], list[Edge]]:
    """(modules, edges between them, imports of a folder ``above`` the packages)."""
    mods = find_modules(root, packages)
    edges: list[Edge] = []
    upward: list[Edge] = []
    for name, (path, is_pkg) in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = name.split(".") if is_pkg else name.split(".")[:-1]
                    base = base[:len(base) - (node.level - 1)]
                    module = ".".join(base + ([node.module] if node.module else []))
                else:
                    module = node.module or ""
                # "from package import submodule" depends on the submodule itself
                targets = [f"{module}.{a.name}" if f"{module}.{a.name}" in mods else module for a in node.names]
            else:
                continue
            kind = _kind(node, parents)
            for t in targets:
                if t.split(".")[0] in above:
                    upward.append(Edge(name, t, node.lineno, kind))
                target = _resolve(t, mods)
                if target is not None:
                    edges.append(Edge(name, target, node.lineno, kind))
    return mods, list(dict.fromkeys(edges)), list(dict.fromkeys(upward))


def cycles(mods, edges: list[Edge]) -> list[list[str]]:
    """Strongly connected components of more than one module, and modules that import themselves
    (Tarjan, iterative)."""
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for e in edges:
        graph[e.source].add(e.target)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1 or v in graph[v]:
                    found.append(sorted(comp))
    return found


def layer_violations(edges: list[Edge], allowed=ALLOWED) -> list[Edge]:
    return [e for e in edges if e.target.split(".")[0] not in allowed[e.source.split(".")[0]]]


def describe_cycles(found: list[list[str]], edges: list[Edge]) -> str:
    out = []
    for comp in found:
        members = set(comp)
        out.append(f"cycle of {len(comp)} modules: {', '.join(comp)}")
        out += [f"    {e}" for e in edges if e.source in members and e.target in members]
    return "\n".join(out)


@pytest.fixture(scope="module")
def graph():
    return import_edges(ROOT)


def test_the_graph_is_read(graph):
    """The reader sees the packages and the three kinds of import (so that a pass means something)."""
    mods, edges, _ = graph
    assert {"warpdem", "calibration.experiments.common", "validation.diagnose", "pump.run"} <= set(mods)
    assert len(edges) > 300
    assert {e.kind for e in edges} == {"top", "lazy", "type"}
    pairs = {(e.source, e.target) for e in edges}
    assert ("calibration.experiments", "calibration.experiments.baffle") in pairs    # from .baffle import ...
    assert ("validation.report", "validation.diagnose") in pairs                     # under TYPE_CHECKING


def test_no_import_cycles(graph):
    mods, edges, _ = graph
    found = cycles(mods, edges)
    assert not found, ("import cycles (break each by moving the shared piece to the lower module; an import "
                       "inside a function or under TYPE_CHECKING still counts):\n" + describe_cycles(found, edges))


def test_imports_point_down_the_layers(graph):
    _, edges, upward = graph
    bad = layer_violations(edges)
    assert not bad, ("imports against the layers (docs/architecture.md):\n"
                     + "\n".join(f"    {e}" for e in bad))
    assert not upward, ("the packages import a folder above them:\n" + "\n".join(f"    {e}" for e in upward))


# ----------------------------------------------------------------------------- the checks can fail
def _write(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)


def test_a_lazy_or_type_only_circle_and_an_upward_import_are_found(tmp_path):
    _write(tmp_path, {
        "warpdem/__init__.py": "",
        "warpdem/a.py": "def f():\n    from calibration.x import g\n",          # upward, lazy
        "calibration/__init__.py": "from .x import g\n",
        "calibration/x.py": "def g():\n    from . import y\n",                   # x -> y, lazy
        "calibration/y.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .x import g\n",
        "calibration/z.py": "import warpdem.a\nimport tests.helpers\n",
        "validation/__init__.py": "",
        "pump/__init__.py": "from validation import thing\n",                     # top beside top
    })
    mods, edges, upward = import_edges(tmp_path)
    assert cycles(mods, edges) == [["calibration.x", "calibration.y"]]
    assert {(e.source, e.target, e.kind) for e in layer_violations(edges)} == {
        ("warpdem.a", "calibration.x", "lazy"), ("pump", "validation", "top")}
    assert [(e.source, e.target) for e in upward] == [("calibration.z", "tests.helpers")]
    assert ("calibration.z", "warpdem.a") in {(e.source, e.target) for e in edges}
