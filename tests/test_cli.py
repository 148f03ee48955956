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
    assert (
        main(
            [
                "eval",
                "--env",
                "narrow2d",
                "--planner",
                "birrt",
                "--episodes",
                "5",
                "--seed",
                "0",
                "--json",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
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
        return train_mod.TrainResult(
            run_dir=Path(run_dir), best_success=0.5, steps=cfg.total_steps, wall_time_s=1.0, history=[]
        )

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


def test_train_options_and_defaults_come_from_the_config_dataclasses(
    captured_train: dict[str, object], capsys: pytest.CaptureFixture[str]
) -> None:
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
    assert (cfg.sac.init_alpha, cfg.sac.actor_delay, cfg.pool_size, cfg.pool_retries, cfg.total_steps) == (  # type: ignore[attr-defined]
        0.3,
        9,
        11,
        2,
        5000,
    )
    assert captured_train["run_dir"] == run  # not a second folder


def test_resume_from_a_policy_checkpoint_says_what_to_do(
    tmp_path: Path, captured_train: dict[str, object], capsys: pytest.CaptureFixture[str]
) -> None:
    run = _saved_run(tmp_path)
    assert main(["train", "--quiet", "--resume", str(run / "best.pt"), "--steps", "5000"]) == 2
    err = capsys.readouterr().err
    assert "best.pt" in err and "last.pt" in err and "KeyError" not in err
    assert main(["train", "--quiet", "--resume", str(run / "bc.pt"), "--steps", "5000"]) == 2
    assert "--init-actor" in capsys.readouterr().err
    assert not captured_train


def test_resume_with_steps_already_done_is_an_error(
    tmp_path: Path, captured_train: dict[str, object], capsys: pytest.CaptureFixture[str]
) -> None:
    run = _saved_run(tmp_path, steps=1000)
    assert main(["train", "--quiet", "--resume", str(run / "last.pt"), "--steps", "800"]) == 2
    assert "done 1000 steps" in capsys.readouterr().err and not captured_train


# ---------------------------------------------------------------------------- Ctrl-C and the progress bar
TINY_TRAIN = [
    "--num-envs",
    "4",
    "--eval-episodes",
    "2",
    "--warmup-steps",
    "100",
    "--batch-size",
    "16",
    "--buffer-size",
    "2000",
]


def test_ctrl_c_in_train_saves_the_trainer_state_and_exits_130(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
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
    assert (
        main(["train", "--quiet", "--steps", "2000", "--eval-every", "1000", *TINY_TRAIN, "--run-dir", str(run)]) == 130
    )
    err = capsys.readouterr().err
    assert f"interrupted at step 200: trainer state saved to {run / 'last.pt'}" in err and "Traceback" not in err
    assert load_checkpoint(run / "last.pt")["trainer"]["steps"] == 200


def test_ctrl_c_in_eval_keeps_the_finished_problems(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
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


# ---------------------------------------------------------------------------- option checks and messages
@pytest.mark.parametrize(
    ("args", "option", "why"),
    [
        (["eval", "--episodes", "0"], "--episodes", "at least 1"),
        (["eval", "--episodes", "-3"], "--episodes", "at least 1"),
        (["eval", "--max-nodes", "-5"], "--max-nodes", "at least 1"),
        (["eval", "--seed", "-1"], "--seed", "0 or more"),
        (["plan", "--episodes", "0"], "--episodes", "at least 1"),
        (["train", "--num-envs", "0"], "--num-envs", None),
    ],
)
def test_bad_counts_are_refused_naming_the_option(
    args: list[str], option: str, why: str | None, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as e:
        main([*args, "--quiet"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {option}" in err and (why is None or why in err)


def _scene_file(tmp_path: Path, problems: list[dict[str, object]]) -> Path:
    doc = {
        "format": "pointplan-scene",
        "version": 1,
        "dim": 2,
        "name": "wall",
        "bounds": {"low": [0.0, 0.0], "high": [1.0, 1.0]},
        "robot": "disc2d",
        "obstacles": [{"type": "box", "center": [0.5, 0.4], "size": [0.1, 0.8]}],
        "problems": problems,
    }
    path = tmp_path / "wall.json"
    path.write_text(json.dumps(doc))
    return path


def test_a_start_or_goal_in_collision_is_reported(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scene = _scene_file(
        tmp_path,
        [
            {"start": [0.2, 0.3], "goal": [0.8, 0.3], "tag": "fine"},
            {"start": [0.5, 0.3], "goal": [0.8, 0.3], "tag": "inside"},
        ],
    )
    out = tmp_path / "out.json"
    main(["plan", "--scene", str(scene), "--json", str(out), "--quiet"])
    text = capsys.readouterr().out
    assert "start/goal in collision" in text and "inside: start in collision" in text
    data = json.loads(out.read_text())
    assert data["metrics"]["invalid_problems"] == 1
    assert [p["invalid"] for p in data["problems"]] == ["", "start in collision"]
    # one problem given on the command line: an error
    assert main(["plan", "--scene", str(scene), "--start", "0.2,0.3", "--goal", "0.5,0.5", "--quiet"]) == 2
    assert "goal in collision" in capsys.readouterr().err


def test_checkpoint_with_a_planner_that_takes_none_is_an_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["eval", "--planner", "birrt", "--checkpoint", "x.pt", "--episodes", "1", "--quiet"]) == 2
    assert (
        "--checkpoint is for --planner policy, hybrid, mpnet-nr, mpnet-hr or a learned-sampling planner"
        in capsys.readouterr().err
    )


def test_eval_json_names_the_planner(tmp_path: Path) -> None:
    out = tmp_path / "m.json"
    assert main(["eval", "--planner", "straight", "--episodes", "2", "--json", str(out), "--quiet"]) == 0
    assert json.loads(out.read_text())["planner"] == "straight"


def test_plan_draws_every_problem(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import pointplan.viz.plot2d as plot2d

    drawn: list[int] = []
    monkeypatch.setattr(plot2d, "render_grid", lambda problems, *a, **k: drawn.append(len(problems)))
    scene = ROOT / "examples" / "scenes" / "narrow_example.json"
    assert main(["plan", "--scene", str(scene), "-o", str(tmp_path / "p.png"), "--quiet"]) == 0
    assert drawn == [2] and "(2 problems)" in capsys.readouterr().out


def test_render_draws_the_points_the_policy_sees(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import pointplan
    import pointplan.viz.plot2d as plot2d
    from pointplan.models.checkpoint import load_checkpoint, save_checkpoint

    data = load_checkpoint(Path(pointplan.__file__).parent / "data" / "narrow2d_policy.pt")
    data = {k: v for k, v in data.items() if k not in ("format", "version")}
    data.update(n_points=32, obs_shape=[32, 4])  # PointNet takes any number of points
    save_checkpoint(tmp_path / "p32.pt", data)
    seen: dict[str, object] = {}
    monkeypatch.setattr(plot2d, "render_problem", lambda *a, **k: seen.update(k))
    assert (
        main(["render", "--planner", "policy", "--checkpoint", str(tmp_path / "p32.pt"), "-o", str(tmp_path / "r.png")])
        == 0
    )
    assert seen["n_points"] == 32 and seen["observer_name"] == "surface-normals"


def test_train_and_bc_print_one_line_and_write_json_on_request(
    tmp_path: Path, captured_train: dict[str, object], capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "t.json"
    assert main(["train", "--quiet", "--steps", "300", "--json", str(out)]) == 0
    lines = [x for x in capsys.readouterr().out.splitlines() if not x.startswith("wrote")]
    assert len(lines) == 1 and lines[0].startswith("best validation success")
    assert json.loads(out.read_text())["steps"] == 300
    from pointplan.cli import _bc_line

    line = _bc_line(
        {
            "checkpoint": "r/bc.pt",
            "demo_steps": 10,
            "demo_problems": 2,
            "demo_time_s": 1.0,
            "train_time_s": 2.0,
            "final_loss": 0.5,
        }
    )
    assert "\n" not in line and "r/bc.pt" in line


def test_subcommands_have_descriptions_and_options_have_help(capsys: pytest.CaptureFixture[str]) -> None:
    from pointplan.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, type(parser._subparsers._group_actions[0])))  # type: ignore[union-attr]
    for name, p in sub.choices.items():
        assert p.description, name
        for action in p._actions:
            if action.option_strings and action.dest != "help":
                assert action.help, f"{name} {action.option_strings}"
    with pytest.raises(SystemExit):
        main(["eval", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "claims disagree" in text and "re-checked" in text
    with pytest.raises(SystemExit):
        main(["eval", "--help"])
    assert "shipped policy" in " ".join(capsys.readouterr().out.split())


def test_bc_options_come_from_the_config_dataclasses(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import pointplan.learning.bc as bc_mod
    import pointplan.learning.dagger as dagger_mod

    seen: dict[str, object] = {}
    summary = {"run_dir": "r", "best_success": 0.5, "demo_steps": 3, "wall_time_s": 1.0}
    monkeypatch.setattr(
        dagger_mod, "train_dagger", lambda cfg, run_dir, **kw: seen.update(cfg=cfg, run_dir=run_dir) or summary
    )
    monkeypatch.setattr(
        bc_mod,
        "train_bc",
        lambda cfg, run_dir, **kw: (
            seen.update(bc=cfg)
            or {
                **summary,
                "checkpoint": "r/bc.pt",
                "demo_problems": 1,
                "demo_time_s": 0.0,
                "train_time_s": 0.0,
                "final_loss": 0.1,
            }
        ),
    )
    assert (
        main(
            [
                "bc",
                "--quiet",
                "--problems",
                "5",
                "--epochs",
                "2",
                "--rollouts",
                "7",
                "--dagger-rounds",
                "1",
                "--expert-max-nodes",
                "99",
            ]
        )
        == 0
    )
    cfg = seen["cfg"]
    assert (cfg.bc.n_problems, cfg.bc.epochs, cfg.rollouts, cfg.rounds, cfg.max_nodes) == (5, 2, 7, 1, 99)  # type: ignore[attr-defined]
    assert main(["bc", "--quiet", "--lr", "0.01"]) == 0
    assert seen["bc"].lr == 0.01 and seen["bc"].n_problems == 2000  # type: ignore[attr-defined]
    assert "r/bc.pt" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["bc", "--epochs", "0"])
    assert "argument --epochs" in capsys.readouterr().err


def test_eval_without_the_greedy_goal_test(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--no-greedy-goal``: the shipped policy rolls out to the goal tolerance, so its paths
    take more steps than with the early stop where the straight edge to the goal is free;
    other planners refuse the flag."""
    steps = {}
    for flag in ([], ["--no-greedy-goal"]):
        out = tmp_path / f"m{len(flag)}.json"
        assert main(["eval", "--planner", "policy", "--episodes", "20", "--json", str(out), "--quiet", *flag]) == 0
        m = json.loads(out.read_text())
        assert m["success_rate"] >= 0.9
        steps[bool(flag)] = m["nodes_mean_solved"]
    assert steps[True] > steps[False] + 2  # (measured on 50 problems: 11.9 against 6.9)
    assert main(["eval", "--planner", "birrt", "--episodes", "2", "--no-greedy-goal", "--quiet"]) == 2
    assert "--no-greedy-goal" in capsys.readouterr().err


def test_eval_escape_flag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--escape`` reaches the policy planner (the S-shape's cloned policy pins itself
    against obstacles; sampled steps after a stall change its rollouts); other planners
    and negative counts are refused."""
    runs = {}
    for k in (0, 10):
        out = tmp_path / f"esc{k}.json"
        args = [
            "eval",
            "--env",
            "boxes3d",
            "--robot",
            "sshape",
            "--observation",
            "local",
            "--planner",
            "policy",
            "--episodes",
            "8",
        ]
        assert main([*args, "--escape", str(k), "--json", str(out), "--quiet"]) == 0
        runs[k] = json.loads(out.read_text())
    assert runs[10]["success_rate"] >= runs[0]["success_rate"]
    assert runs[10]["nodes_mean"] != runs[0]["nodes_mean"]
    assert main(["eval", "--planner", "birrt", "--episodes", "2", "--escape", "3", "--quiet"]) == 2
    assert "--escape" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["eval", "--planner", "policy", "--episodes", "2", "--escape", "-1", "--quiet"])
    # --escape-tries reaches the escape: one draw a step is the plain escape, a different rollout
    out = tmp_path / "tries1.json"
    assert main([*args, "--escape", "10", "--escape-tries", "1", "--json", str(out), "--quiet"]) == 0
    assert json.loads(out.read_text())["collision_checks_mean"] != runs[10]["collision_checks_mean"]
    assert main(["eval", "--planner", "birrt", "--episodes", "2", "--escape-tries", "3", "--quiet"]) == 2
    assert "--escape-tries" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["eval", "--planner", "policy", "--episodes", "2", "--escape-tries", "0", "--quiet"])
    # --escape-lookahead too: another lookahead than the default's, a different rollout
    from pointplan.planners.rollout import ESCAPE_DEFAULTS

    other = "0" if ESCAPE_DEFAULTS["sshape"].lookahead else "3"
    out = tmp_path / "look.json"
    assert main([*args, "--escape", "10", "--escape-lookahead", other, "--json", str(out), "--quiet"]) == 0
    assert json.loads(out.read_text())["collision_checks_mean"] != runs[10]["collision_checks_mean"]
    assert main(["eval", "--planner", "birrt", "--episodes", "2", "--escape-lookahead", "3", "--quiet"]) == 2
    assert "--escape-lookahead" in capsys.readouterr().err


def test_eval_substep_flag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--substep`` reaches the policy planner's motion check (finer: more checks for the
    same rollouts' moves) and the hybrid's policy; other planners are refused."""
    from pointplan.planners import make_planner
    from pointplan.robots import make_robot

    args = ["eval", "--env", "boxes3d", "--robot", "sshape", "--observation", "local", "--planner", "policy"]
    runs = {}
    for name, extra in (("default", []), ("fine", ["--substep", "0.0025"])):
        out = tmp_path / f"{name}.json"
        assert main([*args, "--episodes", "6", *extra, "--json", str(out), "--quiet"]) == 0
        runs[name] = json.loads(out.read_text())
    assert runs["fine"]["collision_checks_mean"] > runs["default"]["collision_checks_mean"]
    assert main(["eval", "--planner", "birrt", "--episodes", "2", "--substep", "0.005", "--quiet"]) == 2
    assert "--substep" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([*args, "--episodes", "2", "--substep", "0", "--quiet"])
    hybrid = make_planner("hybrid", make_robot("sshape"), observation="local", substep=0.005)
    assert hybrid.policy.env.substep == 0.005  # type: ignore[attr-defined]


def test_eval_escape_backoff_flag(capsys: pytest.CaptureFixture[str]) -> None:
    """``--escape-backoff`` reaches the policy planner's escape (the rest of it the robot's
    default); other planners, and a negative distance, are refused."""
    from pointplan.cli import _planner, build_parser
    from pointplan.planners.rollout import ESCAPE_DEFAULTS
    from pointplan.robots import make_robot

    base = ["eval", "--env", "boxes3d", "--robot", "sshape", "--observation", "local", "--planner", "policy"]
    args = build_parser().parse_args([*base, "--escape-backoff", "0.05"])
    esc = _planner("policy", make_robot("sshape"), args, 0).escape  # type: ignore[attr-defined]
    assert esc.backoff == 0.05 and esc.tries == ESCAPE_DEFAULTS["sshape"].tries
    args = build_parser().parse_args(base)
    assert _planner("policy", make_robot("sshape"), args, 0).escape == ESCAPE_DEFAULTS["sshape"]  # type: ignore[attr-defined]
    assert main(["eval", "--planner", "birrt", "--episodes", "2", "--escape-backoff", "0.03", "--quiet"]) == 2
    assert "--escape-backoff" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([*base, "--episodes", "2", "--escape-backoff", "-1", "--quiet"])


def test_eval_dodge_flag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--dodge`` reaches the policy planner among moving obstacles (on by default, 0: off);
    other planners are refused."""
    args = ["eval", "--env", "dynamic3d", "--robot", "sshape", "--observation", "local", "--planner", "policy"]
    runs = {}
    for k in (0, 16):
        out = tmp_path / f"dodge{k}.json"
        assert main([*args, "--episodes", "12", "--dodge", str(k), "--json", str(out), "--quiet"]) == 0
        runs[k] = json.loads(out.read_text())
    default = tmp_path / "default.json"
    assert main([*args, "--episodes", "12", "--json", str(default), "--quiet"]) == 0
    assert json.loads(default.read_text())["collision_checks_mean"] == runs[16]["collision_checks_mean"]
    assert runs[16]["collision_checks_mean"] > runs[0]["collision_checks_mean"]  # the screen's checks count
    assert runs[16]["success_rate"] >= runs[0]["success_rate"]
    assert main(["eval", "--planner", "birrt", "--episodes", "2", "--dodge", "3", "--quiet"]) == 2
    assert "--dodge" in capsys.readouterr().err


def test_eval_attempts_flag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--attempts`` reaches the policy planner; other planners and bad noise are refused."""
    out = tmp_path / "m.json"
    assert (
        main(["eval", "--planner", "policy", "--episodes", "10", "--attempts", "3", "--json", str(out), "--quiet"]) == 0
    )
    assert json.loads(out.read_text())["success_rate"] >= 0.9
    assert main(["eval", "--planner", "birrt", "--episodes", "2", "--attempts", "2", "--quiet"]) == 2
    assert "--attempts" in capsys.readouterr().err
    assert (
        main(["eval", "--planner", "policy", "--episodes", "2", "--attempts", "2", "--action-noise", "-1", "--quiet"])
        == 2
    )
    assert "--action-noise" in capsys.readouterr().err
    assert (
        main(
            [
                "eval",
                "--env",
                "dynamic3d",
                "--robot",
                "sphere3d",
                "--observation",
                "local",
                "--planner",
                "policy",
                "--episodes",
                "2",
                "--attempts",
                "2",
                "--quiet",
            ]
        )
        == 2
    )
    assert "static scenes" in capsys.readouterr().err


def test_eval_says_which_shipped_policy_it_runs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Without --checkpoint, eval names the shipped policy: the moving-gate Slot's own there, 3D-Boxes' in
    the other 3D scenes; with --checkpoint or --quiet it says nothing of the kind."""
    out = tmp_path / "m.json"
    assert main(["eval", "--env", "slotmoving", "--planner", "policy", "--episodes", "1", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "the shipped policy slotmoving_sshape_local_policy.pt (trained in slotmoving, local observations)" in text
    assert (
        main(
            [
                "eval",
                "--env",
                "boxes3d",
                "--robot",
                "sshape",
                "--planner",
                "policy",
                "--episodes",
                "1",
                "--json",
                str(out),
            ]
        )
        == 0
    )
    assert "the shipped policy sshape_local_policy.pt (trained in boxes3d" in capsys.readouterr().out
    assert (
        main(
            [
                "eval",
                "--env",
                "boxes3d",
                "--robot",
                "sshape",
                "--planner",
                "policy",
                "--episodes",
                "1",
                "--quiet",
                "--json",
                str(out),
            ]
        )
        == 0
    )
    assert "shipped policy" not in capsys.readouterr().out


def test_env_help_names_every_scenario() -> None:
    """``--env``'s help, written out so that ``--help`` imports no scenario, names every
    scenario ``make_scenario`` knows (MotionBenchMaker's by their scenario names)."""
    from pointplan.cli import ENV_NAMES, build_parser
    from pointplan.scenes.registry import scenario_names

    words = set(ENV_NAMES.replace(",", " ").replace("(", " ").replace(")", " ").split())
    for name in scenario_names():
        assert name.removeprefix("mbm-") in words, name
    help_text = " ".join(build_parser().commands["eval"].format_help().split())
    assert "mbm-<scenario>" in help_text and "slotclassic" in help_text
