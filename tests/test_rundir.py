"""One run folder for every trainer: metrics, atomic checkpoints, resuming, Ctrl-C.

Each of the seven training commands is interrupted in a tiny configuration (Ctrl-C
raised from inside its loop, as a signal or as a ``KeyboardInterrupt``); it must save
``last.pt``, print one line naming the command that continues the run, show no
traceback, and that command must then finish the run."""

from __future__ import annotations

import csv
import re
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from pointplan.cli import main
from pointplan.learning.rundir import CtrlC, MetricsLog, RunDir, RunDirError, check_run_dir
from pointplan.models.checkpoint import load_checkpoint
from pointplan.models.policy import shipped_checkpoint

SMALL_NET = ["--width", "16", "--layers", "2"]


# ---------------------------------------------------------------------------- the pieces
def test_metrics_leave_out_missing_values_and_forget_rows_past_a_resumed_state(tmp_path: Path) -> None:
    log = MetricsLog(tmp_path)
    log.log({"epoch": 1, "loss": 0.5, "policy_loss": None})
    log.log({"epoch": 2, "loss": float("nan"), "policy_loss": 0.25})
    log.log({"epoch": 3, "loss": 0.125})
    with (tmp_path / "metrics.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [r["loss"] for r in rows] == ["0.5", "", "0.125"] and [r["policy_loss"] for r in rows] == ["", "0.25", ""]
    MetricsLog(tmp_path).drop_after(2)
    with (tmp_path / "metrics.csv").open() as f:
        assert [r["epoch"] for r in csv.DictReader(f)] == ["1", "2"]
    log.close()
    assert list((tmp_path / "tb").iterdir())  # TensorBoard events


def test_a_file_or_a_folder_under_a_file_is_refused(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("x")
    for bad in (tmp_path / "f", tmp_path / "f" / "run"):
        for create in (True, False):
            with pytest.raises(RunDirError, match="--run-dir"):
                check_run_dir(bad, create=create)
    assert not (tmp_path / "new").exists()
    check_run_dir(tmp_path / "new" / "run", create=False)  # checked, not made
    assert not (tmp_path / "new").exists()
    assert check_run_dir(tmp_path / "new" / "run").is_dir()


def test_ctrl_c_sets_a_flag_then_stops_and_no_interrupt_leaves_the_block() -> None:
    before = signal.getsignal(signal.SIGINT)
    with CtrlC() as stop:
        signal.raise_signal(signal.SIGINT)
        assert stop()  # the first: a request, the loop goes on to its next check
        signal.raise_signal(signal.SIGINT)  # the second: at once
        raise AssertionError("not reached")
    assert stop.requested
    with CtrlC() as stop2:
        raise KeyboardInterrupt  # raised inside the loop: the same
    assert stop2.requested
    assert signal.getsignal(signal.SIGINT) is before


def test_interrupted_saves_then_prints_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = RunDir(tmp_path / "my run", "pointplan bc")
    folder.interrupted("in epoch 3 of 9", lambda: folder.save("last.pt", {"x": 1}))
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and load_checkpoint(tmp_path / "my run" / "last.pt")["x"] == 1
    assert err.strip().endswith(f"continue with: pointplan bc --resume '{tmp_path / 'my run' / 'last.pt'}'")


# ---------------------------------------------------------------------------- Ctrl-C in each command
def _ctrl_c_after_rows(monkeypatch: pytest.MonkeyPatch, rows: int, raise_it: bool = False) -> None:
    """Ctrl-C once the trainer has logged ``rows`` metrics rows: SIGINT, or with
    ``raise_it`` a ``KeyboardInterrupt`` raised inside the loop."""
    real, calls = MetricsLog.log, []

    def log(self: MetricsLog, row: dict[str, Any]) -> None:
        real(self, row)
        calls.append(row)
        if len(calls) == rows:
            if raise_it:
                raise KeyboardInterrupt
            signal.raise_signal(signal.SIGINT)

    monkeypatch.setattr(MetricsLog, "log", log)


def _interrupted(capsys: pytest.CaptureFixture[str], code: int, run: Path, key: str) -> list[str]:
    """Checks an interrupted command's exit and output; returns the command that continues it."""
    out, err = capsys.readouterr()
    assert code == 130, err
    assert "Traceback" not in out + err
    lines = [x for x in err.splitlines() if x.startswith("interrupted")]
    assert len(lines) == 1, err
    assert key in load_checkpoint(run / "last.pt")
    command = lines[0].split("continue with: ", 1)[1]
    assert command.startswith("pointplan ") and f"--resume {run / 'last.pt'}" in command
    return shlex.split(command)[1:]


def test_ctrl_c_in_train(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    import pointplan.learning.train as train_mod

    learn = train_mod._learn

    def learn_then_ctrl_c(run, collected):  # type: ignore[no-untyped-def]
        learn(run, collected)
        if run.steps == 200:
            signal.raise_signal(signal.SIGINT)

    monkeypatch.setattr(train_mod, "_learn", learn_then_ctrl_c)
    run = tmp_path / "run"
    tiny = [
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
        *SMALL_NET,
    ]
    code = main(["train", "--quiet", "--steps", "400", "--eval-every", "400", *tiny, "--run-dir", str(run)])
    resume = _interrupted(capsys, code, run, "trainer")
    assert load_checkpoint(run / "last.pt")["trainer"]["steps"] == 200
    monkeypatch.setattr(train_mod, "_learn", learn)
    assert main([*resume, "--quiet"]) == 0
    assert load_checkpoint(run / "last.pt")["trainer"]["steps"] == 400
    assert "best validation success" in capsys.readouterr().out


def test_ctrl_c_in_ppo(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    _ctrl_c_after_rows(monkeypatch, 2)  # the starting policy's row, then the first validation's
    run = tmp_path / "run"
    tiny = [
        "--num-envs",
        "4",
        "--rollout-steps",
        "5",
        "--eval-every",
        "20",
        "--eval-episodes",
        "2",
        "--value-warmup",
        "1",
        "--quiet",
    ]
    code = main(
        ["ppo", "--init-actor", str(shipped_checkpoint("disc2d")), "--steps", "60", "--run-dir", str(run), *tiny]
    )
    resume = _interrupted(capsys, code, run, "ppo")
    assert load_checkpoint(run / "last.pt")["ppo"]["steps"] == 20
    monkeypatch.undo()
    assert main([*resume, "--quiet"]) == 0
    assert load_checkpoint(run / "last.pt")["ppo"]["steps"] == 60


def test_ctrl_c_in_bc(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    _ctrl_c_after_rows(monkeypatch, 2, raise_it=True)  # after the second epoch
    run = tmp_path / "run"
    tiny = [
        "--problems",
        "3",
        "--epochs",
        "4",
        "--n-points",
        "16",
        "--refresh-every",
        "0",
        "--eval-episodes",
        "3",
        *SMALL_NET,
        "--quiet",
    ]
    code = main(["bc", *tiny, "--run-dir", str(run)])
    resume = _interrupted(capsys, code, run, "bc_trainer")
    assert load_checkpoint(run / "last.pt")["bc_trainer"]["epochs"] == 2 and not (run / "bc.pt").exists()
    monkeypatch.undo()
    assert main([*resume, "--quiet"]) == 0
    assert load_checkpoint(run / "last.pt")["bc_trainer"]["epochs"] == 4
    line = capsys.readouterr().out
    assert "validation success" in line and "on 3 problems" in line and str(run / "bc.pt") in line
    with (run / "metrics.csv").open() as f:
        assert [r["epoch"] for r in csv.DictReader(f)] == ["1", "2", "3", "4"]


def test_ctrl_c_in_dagger(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    _ctrl_c_after_rows(monkeypatch, 1)  # after the first round
    run = tmp_path / "run"
    tiny = [
        "--problems",
        "4",
        "--epochs",
        "1",
        "--rollouts",
        "3",
        "--labels-per-failure",
        "1",
        "--epochs-per-round",
        "1",
        "--eval-episodes",
        "2",
    ]
    code = main(["bc", *tiny, "--n-points", "16", *SMALL_NET, "--dagger-rounds", "2", "--quiet", "--run-dir", str(run)])
    resume = _interrupted(capsys, code, run, "dagger")
    assert load_checkpoint(run / "last.pt")["dagger"]["round"] == 1
    monkeypatch.undo()
    assert main([*resume, "--quiet"]) == 0
    assert load_checkpoint(run / "last.pt")["dagger"]["round"] == 2


def test_ctrl_c_in_mpnet_train(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from pointplan.models.mpnet import MPNet

    _ctrl_c_after_rows(monkeypatch, 1)
    run = tmp_path / "run"
    tiny = [
        "--problems",
        "6",
        "--val-demo-problems",
        "2",
        "--val-problems",
        "2",
        "--test-problems",
        "0",
        "--epochs",
        "3",
        "--eval-every",
        "1",
    ]
    code = main(
        [
            "mpnet-train",
            *tiny,
            "--encoder-width",
            "8",
            "--width",
            "16",
            "--layers",
            "2",
            "--quiet",
            "--run-dir",
            str(run),
        ]
    )
    resume = _interrupted(capsys, code, run, "mpnet_trainer")
    assert load_checkpoint(run / "last.pt")["mpnet_trainer"]["epoch"] == 1
    MPNet.from_checkpoint(run / "last.pt")  # also a network the planner reads
    monkeypatch.undo()
    assert main([*resume, "--quiet"]) == 0
    assert load_checkpoint(run / "last.pt")["mpnet_trainer"]["epoch"] == 3
    assert "best validation success" in capsys.readouterr().out


def test_ctrl_c_in_lsample_train(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    _ctrl_c_after_rows(monkeypatch, 1, raise_it=True)
    run = tmp_path / "run"
    tiny = [
        "--problems",
        "4",
        "--val-problems",
        "2",
        "--plan-problems",
        "0",
        "--epochs",
        "3",
        "--width",
        "16",
        "--point-width",
        "16",
        "--quiet",
    ]
    code = main(["lsample-train", *tiny, "--run-dir", str(run)])
    resume = _interrupted(capsys, code, run, "lsample_trainer")
    assert load_checkpoint(run / "last.pt")["lsample_trainer"]["epoch"] == 1
    monkeypatch.undo()
    assert main([*resume, "--quiet"]) == 0
    assert load_checkpoint(run / "last.pt")["lsample_trainer"]["epoch"] == 3 and (run / "best.pt").is_file()


def test_ctrl_c_in_collision_classify(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    _ctrl_c_after_rows(monkeypatch, 1)
    run = tmp_path / "run"
    tiny = [
        "--train-scenes",
        "3",
        "--val-scenes",
        "2",
        "--test-scenes",
        "2",
        "--per-scene",
        "8",
        "--epochs",
        "2",
        "--width",
        "16",
        "--n-points",
        "16",
    ]
    code = main(
        ["collision-classify", "--observation", "surface,surface-normals", *tiny, "--quiet", "--run-dir", str(run)]
    )
    resume = _interrupted(capsys, code, run, "collision_trainer")
    state = load_checkpoint(run / "last.pt")["collision_trainer"]
    assert state["epoch"] == 1 and state["queue"] == ["surface-normals"]
    monkeypatch.undo()
    assert main([*resume, "--quiet"]) == 0  # the rest of the first observation, then the second
    assert (run / "surface.pt").is_file() and (run / "surface-normals.pt").is_file()


@pytest.mark.slow
def test_a_real_ctrl_c_stops_bc_in_its_loop_without_a_traceback(tmp_path: Path) -> None:
    run = tmp_path / "run"
    args = [
        "bc",
        "--problems",
        "3",
        "--epochs",
        "100000",
        "--n-points",
        "16",
        "--refresh-every",
        "0",
        *SMALL_NET,
        "--quiet",
        "--run-dir",
        str(run),
    ]
    proc = subprocess.Popen(
        [sys.executable, "-m", "pointplan", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        t0 = time.time()
        while not (run / "metrics.csv").exists() and time.time() - t0 < 120 and proc.poll() is None:
            time.sleep(0.2)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert "Traceback" not in err and f"continue with: pointplan bc --resume {run / 'last.pt'}" in err
    assert load_checkpoint(run / "last.pt")["bc_trainer"]["epochs"] >= 1


# ---------------------------------------------------------------------------- --run-dir checked first
COMMANDS = {
    "train": ["train", "--steps", "100"],
    "ppo": ["ppo", "--init-actor", "x.pt"],
    "bc": ["bc"],
    "dagger": ["bc", "--dagger-rounds", "1"],
    "mpnet-train": ["mpnet-train"],
    "lsample-train": ["lsample-train"],
    "collision-classify": ["collision-classify"],
}


@pytest.mark.parametrize("command", list(COMMANDS))
@pytest.mark.parametrize("under", [False, True])
def test_a_run_dir_that_cannot_be_used_is_one_line_before_any_work(
    command: str, under: bool, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import pointplan.learning.bc as bc
    import pointplan.learning.collision as collision
    import pointplan.learning.dagger as dagger
    import pointplan.learning.lsample as lsample
    import pointplan.learning.mpnet as mpnet
    import pointplan.learning.ppo as ppo
    import pointplan.learning.train as train

    def work(*a: object, **k: object) -> None:
        raise AssertionError("work started before --run-dir was checked")

    for mod, name in (
        (train, "train"),
        (ppo, "train_ppo"),
        (bc, "train_bc"),
        (bc, "generate_demos"),
        (dagger, "train_dagger"),
    ):
        monkeypatch.setattr(mod, name, work)
    for mod, name in (
        (mpnet, "train_mpnet"),
        (lsample, "train_lsample"),
        (collision, "make_data"),
        (collision, "train_classifier"),
    ):
        monkeypatch.setattr(mod, name, work)
    (tmp_path / "file").write_text("not a folder")
    run = tmp_path / "file" / "run" if under else tmp_path / "file"
    assert main([*COMMANDS[command], "--quiet", "--run-dir", str(run)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("pointplan: error: --run-dir") and "Traceback" not in err


# ---------------------------------------------------------------------------- no sentinels
def _no_sentinels(text: str) -> None:
    assert "-1.000" not in text and not re.search(r"\bnan\b", text, re.IGNORECASE), text


def test_train_without_a_validation_says_so(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import pointplan.learning.train as train_mod

    learn = train_mod._learn

    def learn_then_ctrl_c(run, collected):  # type: ignore[no-untyped-def]
        learn(run, collected)
        if run.steps == 200:
            signal.raise_signal(signal.SIGINT)

    monkeypatch.setattr(train_mod, "_learn", learn_then_ctrl_c)
    tiny = [
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
        *SMALL_NET,
    ]
    json_path = tmp_path / "s.json"
    assert (
        main(
            [
                "train",
                "--steps",
                "400",
                "--eval-every",
                "400",
                *tiny,
                "--run-dir",
                str(tmp_path / "run"),
                "--json",
                str(json_path),
            ]
        )
        == 130
    )
    out, err = capsys.readouterr()
    _no_sentinels(out + err)
    assert "no validation yet" in err
    assert '"best_success": null' in json_path.read_text()


def test_ppo_shows_no_missing_loss_and_stops_at_its_steps(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # the actor stays frozen (value warm-up) through every validation: no policy loss yet
    tiny = [
        "--num-envs",
        "4",
        "--rollout-steps",
        "10",
        "--eval-every",
        "20",
        "--eval-episodes",
        "2",
        "--value-warmup",
        "5",
    ]
    assert (
        main(
            [
                "ppo",
                "--init-actor",
                str(shipped_checkpoint("disc2d")),
                "--steps",
                "60",
                *tiny,
                "--run-dir",
                str(tmp_path),
            ]
        )
        == 0
    )
    out, err = capsys.readouterr()
    _no_sentinels(out + err)
    assert "value_loss=" in out and "policy_loss" not in out + err  # (the rows printed at each validation)
    assert "after 60 env steps," in out and load_checkpoint(tmp_path / "last.pt")["ppo"]["steps"] == 60
    with (tmp_path / "metrics.csv").open() as f:
        assert all("policy_loss" not in r for r in csv.DictReader(f))


def test_ppo_rounds_its_last_rollout_up_to_whole_steps_of_every_environment() -> None:
    from pointplan.learning.ppo import PPOConfig, PPORun

    def rollout(total: int, steps: int) -> int:
        return PPORun.next_rollout(
            SimpleNamespace(cfg=PPOConfig(num_envs=4, rollout_steps=10, total_steps=total), steps=steps)  # type: ignore[arg-type]
        )

    assert [rollout(100, s) for s in (0, 40, 80)] == [10, 10, 5]  # 80 + 4 x 5 = 100
    assert rollout(98, 80) == 5  # 18 left: 20, the multiple of 4 above
