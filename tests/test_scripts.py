"""Every tool in scripts/ answers ``--help``: it exits 0 and its help opens with what the
tool is for (the first paragraph of its docstring, its argparse description)."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"
TOOLS = sorted(SCRIPTS.glob("*.py"))


def _purpose(path: Path) -> str:
    """The first paragraph of the script's docstring, whitespace collapsed."""
    doc = ast.get_docstring(ast.parse(path.read_text()))
    assert doc, f"{path.name} has no docstring"
    return " ".join(doc.split("\n\n")[0].split())


def test_the_tools_are_found() -> None:
    assert len(TOOLS) >= 5 and (SCRIPTS / "table1_representations.py") in TOOLS


@pytest.mark.parametrize("path", TOOLS, ids=[p.stem for p in TOOLS])
def test_help_names_the_tools_purpose(path: Path) -> None:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MPLBACKEND": "Agg"}
    run = subprocess.run(
        [sys.executable, str(path), "--help"], capture_output=True, text=True, timeout=120, env=env, cwd=SCRIPTS.parent
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith("usage:"), run.stdout[:200]
    assert _purpose(path) in " ".join(run.stdout.split()), (
        f"{path.name}: the help does not give the docstring's first paragraph"
    )


def test_the_reference_pages_are_current(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """docs/reference/cli.md and api.md are what scripts/reference_pages.py writes from the
    parser and the code now: a section per command with a row per argument, a section per
    listed API object; and the check notices a stale or missing page."""
    import argparse
    import importlib.util

    from pointplan.cli import build_parser

    spec = importlib.util.spec_from_file_location("reference_pages", SCRIPTS / "reference_pages.py")
    assert spec is not None and spec.loader is not None
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    assert tool.main(["--check"]) == 0, "a reference page is out of date: run python scripts/reference_pages.py"
    cli = tool.PAGES["cli"].read_text(encoding="utf-8")
    for name, p in build_parser().commands.items():
        section = cli.split(f"\n## pointplan {name}\n", 1)[1].split("\n## ", 1)[0]
        for action in p._actions:
            if not isinstance(action, argparse._HelpAction):
                written = action.option_strings[0] if action.option_strings else action.dest
                assert f"| `{written}" in section, (name, written)
    api = tool.PAGES["api"].read_text(encoding="utf-8")
    listed = [(m, n) for _, _, groups in tool.API for m, names in groups for n in names]
    assert len(listed) > 40
    for module, name in listed:
        assert f"\n### {name}\n\n`{module}.{name}`" in api, (module, name)
    pages = {key: tmp_path / f"{key}.md" for key in tool.PAGES}
    monkeypatch.setattr(tool, "PAGES", pages)
    assert tool.main(["--check"]) == 1  # no pages
    assert tool.main([]) == 0 and tool.main(["--check"]) == 0
    pages["cli"].write_text(cli.replace("| `--episodes EPISODES` |", "| `--episodes N` |", 1), encoding="utf-8")
    assert tool.main(["--check"]) == 1
    tool.main([])
    pages["api"].write_text(api.replace("### BiRRT\n", "### RRT\n", 1), encoding="utf-8")
    assert tool.main(["--check"]) == 1
