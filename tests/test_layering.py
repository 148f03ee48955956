"""The import structure of ``src/pointplan``: layered subpackages, and no import cycles.

Every top-level subpackage and module has a layer of its own (:data:`LAYERS`, bottom up);
a module imports only from its own layer or the layers below. The package root
(``__init__.py``) sits near the top: it wires the subpackages together (the Gymnasium ids,
the renderer of the environments, the default worker back end).

Every ``import`` statement counts: at module level, inside functions, and under
``if TYPE_CHECKING:``. Importing ``pointplan.a.b`` also loads the package ``pointplan.a``,
so that is an edge too (except into the importer's own packages).
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Mapping
from functools import cache
from pathlib import Path

import pointplan

ROOT = Path(pointplan.__file__).parent
#: the package root's layer name
TOP = "pointplan"

#: bottom up; each name is a subpackage or module directly under src/pointplan
LAYERS = [
    "config",  # dataclass helpers
    "progress",  # progress bars for terminals, notebooks and logs
    "_version",
    "parallel",  # the interfaces of worker pools and rollout sources
    "geometry",
    "robots",
    "scenes",
    "models",
    "observers",
    "envs",
    "planners",
    "evaluation",
    "learning",
    "distributed",  # Ray: takes evaluation and learning to workers
    "viz",
    TOP,
    "recipes",  # the commands that rebuild the shipped checkpoints (runs pointplan in subprocesses)
    "cli",
    "__main__",
]
RANK = {name: i for i, name in enumerate(LAYERS)}

#: module -> {imported module: line of the first such import}
Graph = dict[str, dict[str, int]]


@cache
def _module_files() -> dict[str, tuple[Path, bool]]:
    """Every module of the package: dotted name -> (file, is a package)."""
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        is_package = parts[-1] == "__init__"
        out[".".join((TOP, *(parts[:-1] if is_package else parts)))] = (path, is_package)
    return out


def _known(name: str, modules: Iterable[str]) -> str | None:
    """The longest prefix of ``name`` that is a module of the package."""
    known = set(modules)
    parts = name.split(".")
    while parts:
        if ".".join(parts) in known:
            return ".".join(parts)
        parts.pop()
    return None


def imports_of(module: str, source: str, is_package: bool, modules: Iterable[str]) -> list[tuple[str, int]]:
    """The package's modules that ``source`` (module ``module``) loads, with line numbers:
    every import statement wherever it is, plus the packages an import loads on the way."""
    modules = set(modules)
    package = module if is_package else module.rpartition(".")[0]
    ancestors = {".".join(module.split(".")[:i]) for i in range(1, module.count(".") + 1)} | (
        {module} if is_package else set()
    )
    found: list[tuple[str, int]] = []

    def add(name: str, line: int) -> None:
        target = _known(name, modules)
        if target is None:
            return
        parts = target.split(".")
        for i in range(1, len(parts)):  # the packages that loading ``target`` loads first
            parent = ".".join(parts[:i])
            if parent in modules and parent not in ancestors:
                found.append((parent, line))
        found.append((target, line))

    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == TOP:
                    add(alias.name, node.lineno)
        elif isinstance(node, ast.ImportFrom):
            base = package.split(".")[: len(package.split(".")) - node.level + 1] if node.level else []
            target = ".".join(base + (node.module.split(".") if node.module else []))
            if target.split(".")[0] != TOP:
                continue
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                add(sub if sub in modules else target, node.lineno)
    return sorted(((t, line) for t, line in found if t != module), key=lambda x: x[1])


def import_graph() -> Graph:
    """The import graph of every module of the package."""
    files = _module_files()
    graph: Graph = {}
    for name, (path, is_package) in files.items():
        edges: dict[str, int] = {}
        for target, line in imports_of(name, path.read_text(), is_package, files):
            edges.setdefault(target, line)
        graph[name] = edges
    return graph


def layer_of(module: str) -> str:
    """The top-level subpackage or module ``module`` belongs to."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else TOP


def _path_of(module: str) -> str:
    path, _ = _module_files().get(module, (None, False))
    return str(path.relative_to(ROOT)) if path else module


def upward_imports(graph: Graph, rank: Mapping[str, int]) -> list[str]:
    """Imports from a layer above the importer's."""
    out = []
    for module, edges in graph.items():
        for target, line in edges.items():
            low, high = layer_of(module), layer_of(target)
            if rank[high] > rank[low]:
                out.append(f"{_path_of(module)}:{line} ({low}) imports {target} ({high})")
    return out


def strongly_connected(graph: Mapping[str, Iterable[str]]) -> list[list[str]]:
    """The strongly connected components of ``graph`` with more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def a_cycle(graph: Mapping[str, Iterable[str]], component: list[str]) -> list[str]:
    """One cycle through ``component``'s first node, inside the component: ``[a, b, ..., a]``."""
    start, inside = component[0], set(component)
    came_from: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt = []
        for v in frontier:
            for w in sorted(graph.get(v, ())):
                if w not in inside or w in came_from:
                    continue
                came_from[w] = v
                if w == start:
                    path = [start]
                    while path[-1] != start or len(path) == 1:
                        path.append(came_from[path[-1]])
                    return path[::-1]
                nxt.append(w)
        frontier = nxt
    raise AssertionError(f"{component} is not strongly connected")


def describe_cycles(graph: Graph) -> list[str]:
    """Each cycle of the module graph, ``module:line`` of every import along it."""
    out = []
    for comp in strongly_connected(graph):
        cycle = a_cycle(graph, comp)
        steps = " -> ".join(f"{a}:{graph[a][b]}" for a, b in zip(cycle, cycle[1:]))
        out.append(f"{steps} -> {cycle[-1]}  [cycle among {', '.join(comp)}]")
    return out


def layer_graph(graph: Graph) -> dict[str, dict[str, str]]:
    """Subpackage -> {subpackage it imports: one such import, ``module:line -> target``}."""
    out: dict[str, dict[str, str]] = {}
    for module, edges in graph.items():
        for target, line in edges.items():
            a, b = layer_of(module), layer_of(target)
            if a != b:
                out.setdefault(a, {}).setdefault(b, f"{_path_of(module)}:{line} -> {target}")
    return out


# ---------------------------------------------------------------------------- the checks
def test_every_top_level_name_has_a_layer() -> None:
    names = {layer_of(m) for m in _module_files()}
    assert len(LAYERS) == len(RANK), "a name is on two layers"
    assert names == set(LAYERS), (
        f"without a layer: {sorted(names - set(LAYERS))}; layers of nothing: {sorted(set(LAYERS) - names)}"
    )


def test_no_module_imports_from_a_layer_above() -> None:
    upward = upward_imports(import_graph(), RANK)
    assert not upward, "imports from a layer above:\n" + "\n".join(upward)


def test_no_import_cycles() -> None:
    cycles = describe_cycles(import_graph())
    assert not cycles, "import cycles:\n" + "\n".join(cycles)


def test_no_cycles_between_subpackages() -> None:
    between = layer_graph(import_graph())
    cycles = []
    for comp in strongly_connected(between):
        cycle = a_cycle(between, comp)
        cycles.append(" -> ".join(cycle) + "\n" + "\n".join(f"    {between[a][b]}" for a, b in zip(cycle, cycle[1:])))
    assert not cycles, "cycles between subpackages:\n" + "\n".join(cycles)


# ---------------------------------------------------------------------------- the checks checked
MODULES = {"pointplan", "pointplan.a", "pointplan.a.x", "pointplan.a.y", "pointplan.b", "pointplan.b.z"}


def test_every_kind_of_import_is_seen() -> None:
    source = """
from typing import TYPE_CHECKING
import numpy
from . import y
from .y import thing
from ..b import z
import pointplan.b.z
if TYPE_CHECKING:
    from pointplan.b import Name

def f():
    from .. import __version__
    from ..b.z import other
"""
    found = imports_of("pointplan.a.x", source, False, MODULES)
    assert found == [
        ("pointplan.a.y", 4),
        ("pointplan.a.y", 5),
        ("pointplan.b", 6),
        ("pointplan.b.z", 6),
        ("pointplan.b", 7),
        ("pointplan.b.z", 7),
        ("pointplan.b", 9),
        ("pointplan", 12),
        ("pointplan.b", 13),
        ("pointplan.b.z", 13),
    ]
    # in a package's __init__, ``.`` is the package itself
    assert imports_of("pointplan.a", "from .x import f\nfrom . import y\n", True, MODULES) == [
        ("pointplan.a.x", 1),
        ("pointplan.a.y", 2),
    ]


def test_the_checks_see_an_upward_import_and_cycles() -> None:
    graph: Graph = {
        "pointplan.a.x": {"pointplan.b.z": 3},
        "pointplan.b.z": {"pointplan.a.y": 7},
        "pointplan.a.y": {"pointplan.a.x": 9},
    }
    assert upward_imports(graph, {"a": 0, "b": 1}) == ["pointplan.a.x:3 (a) imports pointplan.b.z (b)"]
    (cycle,) = describe_cycles(graph)
    assert cycle.startswith("pointplan.a.x:3 -> pointplan.b.z:7 -> pointplan.a.y:9 -> pointplan.a.x ")
    assert strongly_connected(layer_graph(graph)) == [["a", "b"]]
    # two modules of one subpackage importing each other
    assert strongly_connected({"pointplan.a.x": {"pointplan.a.y": 1}, "pointplan.a.y": {"pointplan.a.x": 2}}) == [
        ["pointplan.a.x", "pointplan.a.y"]
    ]
    assert not strongly_connected({"pointplan.a.x": {"pointplan.a.y": 1}, "pointplan.a.y": {}})
