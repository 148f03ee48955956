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
