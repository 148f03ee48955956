"""Smoke tests of the command line with tiny budgets."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from pointplan.cli import main

ROOT = Path(__file__).resolve().parents[1]


def test_eval_writes_metrics(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "m.json"
    assert main(["eval", "--env", "narrow2d", "--planner", "birrt", "--episodes", "5", "--seed", "0", "--json", str(out), "--quiet"]) == 0
    m = json.loads(out.read_text())
    for key in ("success_rate", "nodes_mean", "collision_checks_mean", "path_length_mean", "time_mean_s", "episodes"):
        assert key in m
    assert m["episodes"] == 5
    assert m["success_rate"] == 1.0
    assert "birrt" in capsys.readouterr().out


def test_eval_two_planners(tmp_path: Path) -> None:
    out = tmp_path / "m.json"
    assert main(["eval", "--planner", "birrt,straight", "--episodes", "3", "--json", str(out), "--quiet"]) == 0
    m = json.loads(out.read_text())
    assert set(m["planners"]) == {"birrt", "straight"}


def test_render_writes_png(tmp_path: Path) -> None:
    out = tmp_path / "fig.png"
    assert main(["render", "--env", "narrow2d", "--seed", "3", "--planner", "birrt", "-o", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plan_on_scene_file(tmp_path: Path) -> None:
    scene = ROOT / "examples" / "scenes" / "narrow_example.json"
    out = tmp_path / "paths.json"
    png = tmp_path / "plan.png"
    assert main(["plan", "--scene", str(scene), "--json", str(out), "-o", str(png), "--quiet"]) == 0
    data = json.loads(out.read_text())
    assert data["metrics"]["success_rate"] == 1.0
    assert all(len(p["path"]) >= 2 for p in data["problems"])
    assert png.exists()


def test_bad_inputs_give_clear_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["eval", "--env", "nowhere", "--episodes", "1", "--quiet"]) == 2
    assert "unknown environment" in capsys.readouterr().err
    assert main(["eval", "--planner", "magic", "--episodes", "1", "--quiet"]) == 2
    assert "magic" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "pointplan-scene", "version": 1, "dim": 2}')
    assert main(["plan", "--scene", str(bad), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "bad.json" in err and "Traceback" not in err


def test_module_entry_point() -> None:
    res = subprocess.run([sys.executable, "-m", "pointplan", "--version"], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0 and "pointplan" in res.stdout
