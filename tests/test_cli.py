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


# ---------------------------------------------------------------------------- train options and --resume
@pytest.fixture
def captured_train(monkeypatch: pytest.MonkeyPatch) -> dict[str, object]:
    """Replace the training loop by a recorder of what the command asked for."""
    import pointplan.learning.train as train_mod

    seen: dict[str, object] = {}

    def fake_train(cfg, run_dir, **kw):  # type: ignore[no-untyped-def]
        seen.update(cfg=cfg, run_dir=Path(run_dir), **kw)
        return train_mod.TrainResult(run_dir=Path(run_dir), best_success=0.5, steps=cfg.total_steps, wall_time_s=1.0, history=[])

    monkeypatch.setattr(train_mod, "train", fake_train)
    return seen


def _saved_run(tmp_path: Path, steps: int = 1000, **cfg_over: object) -> Path:
    from dataclasses import replace

    from pointplan.learning.train import TrainConfig
    from pointplan.models.checkpoint import save_checkpoint, to_dict

    cfg = replace(TrainConfig(total_steps=2000), **cfg_over)
    run = tmp_path / "run"
    base = {
        "env": "narrow2d",
        "robot": "disc2d",
        "observation": "surface-normals",
        "n_points": 64,
        "obs_shape": [64, 4],
        "net": to_dict(cfg.net),
        "train_config": to_dict(cfg),
        "actor": {},
    }
    save_checkpoint(run / "last.pt", {**base, "trainer": {"steps": steps}})
    save_checkpoint(run / "best.pt", base)
    save_checkpoint(run / "bc.pt", {**base, "bc_config": {}})
    return run


def test_train_options_and_defaults_come_from_the_config_dataclasses(captured_train: dict[str, object], capsys: pytest.CaptureFixture[str]) -> None:
    from pointplan.learning.sac import SACConfig
    from pointplan.learning.train import TrainConfig

    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for flag, default in (
        ("--steps", TrainConfig.total_steps),
        ("--lr", SACConfig.lr),
        ("--pool-size", TrainConfig.pool_size),
        ("--pool-retries", TrainConfig.pool_retries),
        ("--init-alpha", SACConfig.init_alpha),
    ):
        assert flag in text and f"(default: {default})" in text
    assert main(["train", "--quiet", "--init-alpha", "0.5", "--pool-size", "7", "--steps", "300"]) == 0
    cfg = captured_train["cfg"]
    assert cfg.sac.init_alpha == 0.5 and cfg.pool_size == 7 and cfg.total_steps == 300  # type: ignore[attr-defined]
    assert cfg.sac.lr == SACConfig.lr and cfg.eval_every == TrainConfig.eval_every  # type: ignore[attr-defined]


def test_resume_takes_every_option_and_stays_in_its_folder(tmp_path: Path, captured_train: dict[str, object]) -> None:
    run = _saved_run(tmp_path)
    args = [
        "train",
        "--quiet",
        "--resume",
        str(run / "last.pt"),
        "--steps",
        "5000",
        "--init-alpha",
        "0.3",
        "--actor-delay",
        "9",
        "--pool-size",
        "11",
        "--pool-retries",
        "2",
    ]
    assert main(args) == 0
    cfg = captured_train["cfg"]
    assert (cfg.sac.init_alpha, cfg.sac.actor_delay, cfg.pool_size, cfg.pool_retries, cfg.total_steps) == (0.3, 9, 11, 2, 5000)  # type: ignore[attr-defined]
    assert captured_train["run_dir"] == run  # not a second folder


def test_resume_from_a_policy_checkpoint_says_what_to_do(tmp_path: Path, captured_train: dict[str, object], capsys: pytest.CaptureFixture[str]) -> None:
    run = _saved_run(tmp_path)
    assert main(["train", "--quiet", "--resume", str(run / "best.pt"), "--steps", "5000"]) == 2
    err = capsys.readouterr().err
    assert "best.pt" in err and "last.pt" in err and "KeyError" not in err
    assert main(["train", "--quiet", "--resume", str(run / "bc.pt"), "--steps", "5000"]) == 2
    assert "--init-actor" in capsys.readouterr().err
    assert not captured_train


def test_resume_with_steps_already_done_is_an_error(tmp_path: Path, captured_train: dict[str, object], capsys: pytest.CaptureFixture[str]) -> None:
    run = _saved_run(tmp_path, steps=1000)
    assert main(["train", "--quiet", "--resume", str(run / "last.pt"), "--steps", "800"]) == 2
    assert "done 1000 steps" in capsys.readouterr().err and not captured_train


# ---------------------------------------------------------------------------- Ctrl-C and the progress bar
TINY_TRAIN = ["--num-envs", "4", "--eval-episodes", "2", "--warmup-steps", "100", "--batch-size", "16", "--buffer-size", "2000"]


def test_ctrl_c_in_train_saves_the_trainer_state_and_exits_130(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    import signal

    import pointplan.learning.train as train_mod
    from pointplan.models.checkpoint import load_checkpoint

    learn = train_mod._learn

    def learn_then_ctrl_c(run, collected):  # type: ignore[no-untyped-def]
        learn(run, collected)
        if run.steps == 200:
            signal.raise_signal(signal.SIGINT)

    monkeypatch.setattr(train_mod, "_learn", learn_then_ctrl_c)
    run = tmp_path / "run"
    assert main(["train", "--quiet", "--steps", "2000", "--eval-every", "1000", *TINY_TRAIN, "--run-dir", str(run)]) == 130
    err = capsys.readouterr().err
    assert f"interrupted at step 200: trainer state saved to {run / 'last.pt'}" in err and "Traceback" not in err
    assert load_checkpoint(run / "last.pt")["trainer"]["steps"] == 200


def test_ctrl_c_in_eval_keeps_the_finished_problems(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    import pointplan.evaluation  # noqa: F401

    ev = sys.modules["pointplan.evaluation.evaluate"]  # (the package's `evaluate` is the function)
    real, calls = ev.plan_and_check, []

    def plan_then_ctrl_c(*a, **k):  # type: ignore[no-untyped-def]
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(ev, "plan_and_check", plan_then_ctrl_c)
    out = tmp_path / "partial.json"
    assert main(["eval", "--planner", "straight", "--episodes", "10", "--json", str(out), "--quiet"]) == 130
    captured = capsys.readouterr()
    assert "kept the 2 of 10 problems" in captured.err and "Traceback" not in captured.err
    assert f"wrote {out}" in captured.out
    data = json.loads(out.read_text())
    assert data["interrupted"] == {"finished": 2, "problems": 10} and data["episodes"] == 2


def test_training_progress_bar_stops_at_its_total(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["train", "--steps", "302", "--eval-every", "302", *TINY_TRAIN, "--run-dir", str(tmp_path)]) == 0
    err = capsys.readouterr().err
    assert "302/302" in err and "304/302" not in err
