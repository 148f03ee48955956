"""No module of ``src/pointplan`` imports from a layer above its own.

Layers, bottom up: config (dataclass helpers), geometry, robots, scenes/models, observers, envs, planners,
learning/evaluation/distributed, viz, cli. Packages on one layer may import each other;
imports inside functions count too.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pointplan

LAYERS = [
    ("config",),
    ("geometry",),
    ("robots",),
    ("scenes", "models"),
    ("observers",),
    ("envs",),
    ("planners",),
    ("learning", "evaluation", "distributed"),
    ("viz",),
    ("cli", "__main__"),
]
RANK = {name: i for i, names in enumerate(LAYERS) for name in names}
#: deliberate exceptions, each with its reason
ALLOWED = {
    ("envs/planning_env.py", "pointplan.viz.plot2d"): "Gymnasium's render() hook draws the workspace; imported only when rendering",
}
ROOT = Path(pointplan.__file__).parent


def _imports(path: Path) -> list[tuple[str, int]]:
    """The ``pointplan`` modules (or names) ``path`` imports, with their line numbers."""
    rel = path.relative_to(ROOT)
    parts = ["pointplan", *rel.with_suffix("").parts]
    package = parts[:-1]  # an __init__'s package is its own folder too: parts[:-1] drops "__init__"
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found += [(a.name, node.lineno) for a in node.names if a.name.split(".")[0] == "pointplan"]
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            target = base + (node.module.split(".") if node.module else [])
            if target[:1] != ["pointplan"]:
                continue
            if len(target) == 1:  # from pointplan import x
                found += [(f"pointplan.{a.name}", node.lineno) for a in node.names]
            else:
                found.append((".".join(target), node.lineno))
    return found


def _layer_of(path: Path) -> str:
    rel = path.relative_to(ROOT)
    return rel.parts[0] if len(rel.parts) > 1 else rel.stem


def test_every_package_has_a_layer():
    packages = {p.name for p in ROOT.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    assert packages <= set(RANK), packages - set(RANK)


def test_no_module_imports_from_a_layer_above():
    upward = []
    for path in sorted(ROOT.rglob("*.py")):
        layer = _layer_of(path)
        if layer == "__init__":  # the package root registers the environments
            continue
        for target, line in _imports(path):
            name = target.split(".")[1]
            if name == "__version__" or (str(path.relative_to(ROOT)), target) in ALLOWED:
                continue
            assert name in RANK, f"{path.relative_to(ROOT)}:{line} imports {target}, which has no layer"
            if RANK[name] > RANK[layer]:
                upward.append(f"{path.relative_to(ROOT)}:{line} ({layer}) imports {target}")
    assert not upward, "\n".join(upward)


def test_the_check_sees_an_upward_import(tmp_path, monkeypatch):
    fake = ROOT / "geometry" / "_layering_probe.py"
    monkeypatch.setattr(Path, "read_text", lambda self, *a, **k: "from ..planners import birrt\n" if self == fake else Path.read_bytes(self).decode())
    assert _imports(fake) == [("pointplan.planners", 1)]
