"""The complete Python examples of README.md and the guide run as written and print what
the text says they print. (The guide's fragments, which need a user's own files or
variables of the text around them, are not here; their commands are parsed by
test_docs_commands.py.)"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import pytest

markdown_it = pytest.importorskip("markdown_it")

REPO = Path(__file__).resolve().parents[1]


def python_blocks(page: str) -> list[str]:
    tokens = markdown_it.MarkdownIt("commonmark").parse((REPO / page).read_text(encoding="utf-8"))
    return [t.content for t in tokens if t.type == "fence" and t.info.strip() == "python"]


def run_blocks(page: str, which: list[int], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Run blocks ``which`` of ``page`` one after the other in one namespace, in a fresh
    folder that has the repository's examples/; the lines each block printed."""
    (tmp_path / "examples").symlink_to(REPO / "examples")
    monkeypatch.chdir(tmp_path)
    blocks = python_blocks(page)
    namespace: dict[str, object] = {"__name__": "__docs__"}
    printed = []
    for i in which:
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            exec(compile(blocks[i], f"{page}, Python example {i + 1}", "exec"), namespace)
        printed.append(out.getvalue().strip())
    return printed


def test_readme_plans_the_wall_with_a_gap_as_its_comment_says(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    block = python_blocks("README.md")[0]
    comment = next(line for line in block.splitlines() if line.startswith("print(")).split("#", 1)[1]
    expected = comment.split(":")[0].strip()  # "True 10 (12, 2)"
    assert run_blocks("README.md", [0], tmp_path, monkeypatch) == [expected]


def test_scenarios_guide_examples(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    printed = run_blocks("docs/guide/scenarios.md", [0, 1], tmp_path, monkeypatch)
    assert printed[0] == "(64, 4) False False"


def test_planners_guide_evaluates_birrt(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (printed,) = run_blocks("docs/guide/planners.md", [0], tmp_path, monkeypatch)
    success, nodes = map(float, printed.split())
    assert success == 1.0 and nodes > 2


def test_scene_files_guide_loads_and_saves(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    run_blocks("docs/guide/scene-files.md", [0], tmp_path, monkeypatch)
    from pointplan.scenes.io import load_scene

    copy = load_scene(tmp_path / "copy.json")
    original = load_scene(REPO / "examples/scenes/narrow_example.json")
    assert len(copy.problems) == len(original.problems) and copy.robot == original.robot


@pytest.mark.slow
def test_arms_guide_plans_on_the_shelf_and_on_what_cameras_see(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("ompl")
    shelf, seen = run_blocks("docs/guide/arms.md", [0, 1], tmp_path, monkeypatch)
    assert shelf.startswith("True PathCheck(ok=True")
    # planned on the cameras' cloud; against the true scene it is either free or, as the
    # guide says it may be, through something no camera saw
    assert seen.startswith("True PathCheck(ok=True") or (
        seen.startswith("True PathCheck(ok=False") and "touches" in seen
    )


# the examples that are fragments: each with the names it takes from the text around it
FRAGMENTS = {
    ("docs/guide/arms.md", 1): {"make_planner", "check_path", "panda", "problem"},  # continues the first example
    ("docs/guide/planners.md", 1): {"problem", "problems"},
    ("docs/guide/planners.md", 2): {"robot", "problem", "result"},
    ("docs/guide/scenarios.md", 2): {"rotation", "translation"},
}


def free_names(code: str) -> set[str]:
    """Names ``code`` reads that it neither imports nor assigns nor defines (nor builtins)."""
    import ast
    import builtins

    bound, read = set(dir(builtins)), set()
    for node in ast.walk(ast.parse(code)):
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            bound |= {(alias.asname or alias.name).split(".")[0] for alias in node.names}
        elif isinstance(node, ast.Name):
            (bound if isinstance(node.ctx, ast.Store) else read).add(node.id)
        elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            bound.add(node.name)
        elif isinstance(node, ast.arg):
            bound.add(node.arg)
    return read - bound


def test_every_python_example_names_only_what_it_imports_or_defines() -> None:
    """A reader copies one example at a time: each Python block of README.md and the
    guide imports or defines every name it uses (the fragments above take the listed
    names from their text). Catches an example that forgot an import."""
    pages = ["README.md", *sorted(str(p.relative_to(REPO)) for p in (REPO / "docs/guide").glob("*.md"))]
    seen = set()
    for page in pages:
        for i, code in enumerate(python_blocks(page)):
            seen.add((page, i))
            allowed = FRAGMENTS.get((page, i), set())
            assert free_names(code) <= allowed, f"{page}, Python example {i + 1} uses {free_names(code) - allowed}"
    assert set(FRAGMENTS) <= seen, "a listed fragment is no longer there"
    assert free_names("from a import b\nprint(b, c)") == {"c"}
