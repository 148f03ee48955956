"""The recipes that rebuild the shipped checkpoints: every command parses, every shipped
file has one recipe whose flags agree with the configuration the file carries, and two
recipes run end to end at smoke scale."""

from __future__ import annotations

import argparse
import importlib.util
import shlex
import subprocess
from pathlib import Path
from typing import Any

import pytest

from pointplan import cli, recipes
from pointplan.config import given_options
from pointplan.models.checkpoint import load_checkpoint
from pointplan.recipes import RECIPES, Recipe, Step

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "src" / "pointplan" / "data"

#: the options of each pointplan subcommand that map onto a saved configuration, and the
#: key of that configuration in a checkpoint
OPTIONS = {
    "train": (cli.TRAIN_OPTIONS, "train_config"),
    "ppo": (cli.PPO_OPTIONS, "ppo_config"),
    "mpnet-train": (cli.MPNET_OPTIONS, "train_config"),
    "lsample-train": (cli.LSAMPLE_OPTIONS, "lsample_config"),
}
#: settings that name files or where a run stops: the recipes differ there by design
#: (their own run folder; --steps stops at the shipped checkpoint's step)
NOT_COMPARED = {"total_steps", "init_actor", "demos", "demos_file", "val_demos", "val_demos_file", "start_demos"}
#: cloning steps whose result is kept in checkpoints/ (recipe, step index): file
CLONES = {
    ("sshape_local_policy", 1): "sshape_local_bc_roadmap.pt",
    ("sshape_global_policy", 1): "sshape_global_bc_roadmap.pt",
    ("slotmoving_sshape_local_policy", 1): "slotmoving_local_bc_threading.pt",
    ("slot_sshape_oriented_local_policy", 1): "slot_oriented_local_bc_threading.pt",
}


def _subparser(parser: argparse.ArgumentParser, name: str) -> argparse.ArgumentParser:
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    p: argparse.ArgumentParser = sub.choices[name]
    return p


def _script_parser(path: Path) -> argparse.ArgumentParser:
    spec = importlib.util.spec_from_file_location(f"recipe_script_{path.stem}", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    p: argparse.ArgumentParser = module.parser()
    return p


def _parse(argv: list[str]) -> argparse.Namespace:
    """Parse a recipe's command line as its command would, refusing abbreviated options."""
    if argv[0] == "pointplan":
        parser, rest = cli.build_parser(), argv[1:]
        sub = _subparser(parser, rest[0])
    else:
        assert argv[0] == "python", argv
        parser, rest = _script_parser(ROOT / argv[1]), argv[2:]
        has_commands = any(isinstance(a, argparse._SubParsersAction) for a in parser._actions)
        sub = _subparser(parser, rest[0]) if has_commands else parser
    known = {o for a in sub._actions for o in a.option_strings}
    for arg in rest:
        if arg.startswith("--"):
            assert arg in known, f"{shlex.join(argv)}: {arg} is not an option of {argv[0]} {rest[0]}"
    try:
        return parser.parse_args(rest)
    except SystemExit as e:
        raise AssertionError(f"{shlex.join(argv)} does not parse") from e


def _get(config: dict[str, Any], path: str) -> Any:
    for key in path.split("."):
        config = config[key]
    return config


def _agree(a: Any, b: Any) -> bool:
    if isinstance(a, float) or isinstance(b, float):
        return a == pytest.approx(b, rel=1e-9)
    return bool(a == b)


def test_every_shipped_file_has_one_recipe() -> None:
    shipped = sorted(p.name for p in DATA.glob("*.pt"))
    named = sorted(r.shipped for r in RECIPES.values())
    assert named == shipped
    for name, r in RECIPES.items():
        assert r.name == name and r.steps and r.product and r.cost


@pytest.mark.parametrize("smoke", [False, True])
@pytest.mark.parametrize("name", sorted(RECIPES))
def test_dry_run_prints_commands_that_parse(
    name: str, smoke: bool, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert recipes.run(name, tmp_path / "r", smoke=smoke, dry_run=True) == 0
    out = capsys.readouterr().out
    lines = [shlex.split(line) for line in out.splitlines() if line and not line.startswith("#")]
    assert len(lines) == len(RECIPES[name].steps)
    assert not (tmp_path / "r").exists()  # a dry run writes nothing
    for argv in lines:
        assert not any("{" in a or "|" in a for a in argv), argv
        assert all(str(tmp_path / "r") in a for a in argv if a.endswith((".pt", ".npz"))), argv
        _parse(argv)
        if argv[0] == "python":
            assert (ROOT / argv[1]).is_file()


@pytest.mark.parametrize("name", sorted(RECIPES))
def test_flags_agree_with_the_saved_configurations(name: str) -> None:
    """The options the steps give (accumulated over resumes) are what the shipped file's
    configuration says, the last run stops at its step (or epoch count), and the cloning
    steps kept in checkpoints/ agree with theirs."""
    r = RECIPES[name]
    shipped = load_checkpoint(DATA / r.shipped)
    given: dict[str, Any] = {}
    last: tuple[str, dict[str, Any]] | None = None
    last_clone: argparse.Namespace | None = None
    for i, argv in enumerate(recipes.commands(r, "runs/x")):
        args = _parse(argv)
        last_clone = args if argv[:2] == ["pointplan", "bc"] else last_clone
        if (name, i) in CLONES:
            clone = load_checkpoint(ROOT / "checkpoints" / CLONES[(name, i)])
            for path, value in given_options(args, cli.BC_OPTIONS).items():
                if path.startswith("bc.") and path != "bc.demos_file":
                    assert _agree(value, clone["bc_config"][path[3:]]), (argv, path)
            assert clone["net"]["shared_encoder"] == (args.encoder_sharing == "shared")
            assert clone["observation"] == args.observation
        if argv[0] == "pointplan" and argv[1] in OPTIONS:
            options, _ = OPTIONS[argv[1]]
            step = given_options(args, options)
            given.update(step)
            last = (argv[1], step)
            for key in ("env", "robot", "observation"):  # (a resumed run keeps its own)
                if (
                    not getattr(args, "resume", None)
                    and getattr(args, key, None)
                    and key in shipped[OPTIONS[argv[1]][1]]
                ):
                    assert shipped[OPTIONS[argv[1]][1]][key] == getattr(args, key), (argv, key)
    if last is None:  # a recipe that ends with a clone ships the clone itself
        assert last_clone is not None, name
        for path, value in given_options(last_clone, cli.BC_OPTIONS).items():
            if path.startswith("bc.") and path != "bc.demos_file":
                assert _agree(value, shipped["bc_config"][path[3:]]), (name, path)
        assert shipped["observation"] == last_clone.observation and shipped["env"] == last_clone.env
        assert shipped["net"]["shared_encoder"] == (last_clone.encoder_sharing == "shared")
        return
    command, final = last
    config = shipped[OPTIONS[command][1]]
    for path, value in given.items():
        if path not in NOT_COMPARED:
            assert _agree(value, _get(config, path)), (name, path, value, _get(config, path))
    if command in ("train", "ppo"):
        assert final["total_steps"] == shipped["env_steps"]
    else:
        assert final["epochs"] == config["epochs"]


def _fake_run(codes: list[int], calls: list[list[str]]) -> Any:
    def run(argv: list[str], *a: Any, **kw: Any) -> subprocess.CompletedProcess[bytes]:
        calls.append(argv)
        return subprocess.CompletedProcess(argv, codes[len(calls) - 1])

    return run


def test_run_stops_at_the_first_failure(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    steps = tuple(Step(("pointplan", "eval", "--episodes", "{400|1}", "--json", f"{{root}}/{k}.json")) for k in "abc")
    monkeypatch.setitem(RECIPES, "fake", Recipe("fake", "fake.pt", "a test", "three steps", steps, ("b.json",)))
    calls: list[list[str]] = []
    monkeypatch.setattr(recipes.subprocess, "run", _fake_run([0, 3, 0], calls))
    assert recipes.run("fake", tmp_path, smoke=True) == 3
    assert len(calls) == 2 and calls[0][1:4] == ["-m", "pointplan", "eval"] and "1" in calls[0]
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        len(err) == 1
        and err[0].startswith("recipe fake: step 2 of 3 failed with exit code 3")
        and "--from-step 2" in err[0]
    )
    # continued from step 2; the product (the first of the candidates that exists) is copied
    calls.clear()
    monkeypatch.setattr(recipes.subprocess, "run", _fake_run([0, 0], calls))
    (tmp_path / "b.json").write_text("{}")
    assert recipes.run("fake", tmp_path, from_step=2) == 0
    assert len(calls) == 2 and (tmp_path / "fake.pt").read_text() == "{}"


def test_list_and_the_subcommand(capsys: pytest.CaptureFixture[str]) -> None:
    assert recipes.main(["--list"]) == 0
    out = capsys.readouterr().out
    for r in RECIPES.values():
        assert r.name in out and r.shipped in out
    parser = argparse.ArgumentParser(prog="pointplan")
    recipes.add_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["recipe", "narrow2d_mpnet", "--dry-run", "--smoke"])
    assert args.func(args) == 0
    assert "pointplan mpnet-train --problems 8" in capsys.readouterr().out
    assert recipes.main(["no_such_recipe"]) == 2


def _smoke(name: str, root: Path) -> Path:
    """Run recipe ``name`` at smoke scale; its checkpoint is the shipped file's kind: the
    same scenario, robot, observation and network."""
    assert recipes.run(name, root, smoke=True) == 0
    out = root / RECIPES[name].shipped
    built, shipped = load_checkpoint(out), load_checkpoint(DATA / RECIPES[name].shipped)
    for key in (
        "kind",
        "env",
        "robot",
        "observation",
        "n_points",
        "obs_shape",
        "net",
        "cvae",
        "point_features",
        "horizon",
    ):
        assert built.get(key) == shipped.get(key), key
    return out


def test_smoke_narrow2d_lsample_cvae(tmp_path: Path) -> None:
    """The cheapest 2D recipe end to end; the CVAE loader takes its network."""
    from pointplan.planners.learned_sampling import LearnedSampler
    from pointplan.robots.point import Disc2D

    path = _smoke("narrow2d_lsample_cvae", tmp_path)
    assert LearnedSampler(path, Disc2D(), 0.5).config.latent == 2


@pytest.mark.slow
def test_smoke_sphere3d_local_policy(tmp_path: Path) -> None:
    """A 3D recipe end to end (cloning, DAgger, SAC + HER); the policy loader takes it."""
    from pointplan.models.policy import Policy

    path = _smoke("sphere3d_local_policy", tmp_path)
    policy = Policy.from_checkpoint(path)
    assert (policy.robot.name, policy.observation, policy.env) == ("sphere3d", "local", "boxes3d")
