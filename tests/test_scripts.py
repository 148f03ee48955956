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


def test_the_cli_reference_page_is_current(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """docs/reference/cli.md is what scripts/cli_reference.py writes from the parser now, it
    has a section per command and a row per argument, and its check notices a stale page."""
    import argparse
    import importlib.util

    from pointplan.cli import build_parser

    spec = importlib.util.spec_from_file_location("cli_reference", SCRIPTS / "cli_reference.py")
    assert spec is not None and spec.loader is not None
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    assert tool.main(["--check"]) == 0, "docs/reference/cli.md is out of date: run python scripts/cli_reference.py"
    page = tool.PAGE.read_text(encoding="utf-8")
    for name, p in build_parser().commands.items():
        section = page.split(f"\n## pointplan {name}\n", 1)[1].split("\n## ", 1)[0]
        for action in p._actions:
            if not isinstance(action, argparse._HelpAction):
                assert f"| `{action.option_strings[0] if action.option_strings else action.dest}" in section, (
                    name,
                    action.dest,
                )
    stale = tmp_path / "cli.md"
    monkeypatch.setattr(tool, "PAGE", stale)
    assert tool.main(["--check"]) == 1  # no page
    stale.write_text(page.replace("| `--episodes EPISODES` |", "| `--episodes N` |", 1), encoding="utf-8")
    assert tool.main(["--check"]) == 1
    assert tool.main([]) == 0 and tool.main(["--check"]) == 0
