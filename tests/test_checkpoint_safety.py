"""Loading a checkpoint never runs code: checkpoints hold only data."""

from __future__ import annotations

import dataclasses
import os
import re
import subprocess
import sys
from collections import OrderedDict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

import pointplan
from pointplan.cli import main
from pointplan.envs.core import EnvConfig
from pointplan.learning.replay import EpisodeReplay
from pointplan.learning.sac import SAC, SACConfig
from pointplan.learning.train import TrainConfig, train
from pointplan.models.actor_critic import NetConfig
from pointplan.models.checkpoint import (
    FORMAT,
    VERSION,
    CheckpointError,
    find_non_plain,
    load_checkpoint,
    save_checkpoint,
    to_dict,
)
from pointplan.models.convert import convert_checkpoint
from pointplan.models.encoders import EncoderConfig
from pointplan.models.policy import Policy, shipped_checkpoint
from pointplan.robots import Disc2D

SMALL = NetConfig(
    EncoderConfig(width=32, layers=2), head_width=32, head_layers=2, critic_action="pooled", shared_encoder=True
)
SRC = Path(pointplan.__file__).resolve().parents[1]
REPO = Path(__file__).resolve().parents[1]


class Payload:
    """Unpickling this runs ``os.system(command)``."""

    def __init__(self, command: str) -> None:
        self.command = command

    def __reduce__(self) -> tuple[Any, tuple[str]]:
        return (os.system, (self.command,))


def _evil(tmp_path: Path) -> tuple[Path, Path]:
    """A file that looks like a pointplan checkpoint and writes ``pwned.txt`` when unpickled."""
    marker = tmp_path / "pwned.txt"
    path = tmp_path / "evil.pt"
    torch.save({"format": FORMAT, "version": 1, "robot": "disc2d", "x": Payload(f"echo PWNED > '{marker}'")}, path)
    return path, marker


def assert_same(a: Any, b: Any, at: str = "") -> None:
    """Exact equality: types, key order, tensor dtypes, shapes and bits, OrderedDict attributes."""
    assert type(a) is type(b), f"{at}: {type(a)} vs {type(b)}"
    if isinstance(a, torch.Tensor):
        assert (a.dtype, a.shape) == (b.dtype, b.shape), at
        assert torch.equal(a.reshape(-1).view(torch.uint8), b.reshape(-1).view(torch.uint8)), at
    elif isinstance(a, dict):
        assert list(a) == list(b), at
        for k in a:
            assert_same(a[k], b[k], f"{at}/{k}")
        if type(a) is OrderedDict:
            assert_same(dict(vars(a)), dict(vars(b)), f"{at}.__dict__")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), at
        for i, (x, y) in enumerate(zip(a, b)):
            assert_same(x, y, f"{at}[{i}]")
    else:
        assert a == b, f"{at}: {a!r} vs {b!r}"


def _one_line_error(match: str) -> Any:
    return pytest.raises(CheckpointError, match=match)


# ------------------------------------------------------------------ (1) a malicious file
def test_malicious_checkpoint_is_refused_without_running(tmp_path: Path) -> None:
    evil, marker = _evil(tmp_path)
    with _one_line_error("convert-checkpoint") as info:
        load_checkpoint(evil)
    msg = str(info.value)
    assert "\n" not in msg and "evil.pt" in msg and "system" in msg
    with pytest.raises(CheckpointError):
        Policy.from_checkpoint(evil)
    with pytest.raises(CheckpointError, match="trust_source"):
        convert_checkpoint(evil, tmp_path / "new.pt")
    assert not marker.exists()
    # the payload is live: converting the file on purpose (trusting it) runs it
    convert_checkpoint(evil, tmp_path / "new.pt", trust_source=True)
    assert marker.read_text().strip() == "PWNED"


def test_cli_eval_refuses_a_malicious_checkpoint(tmp_path: Path) -> None:
    evil, marker = _evil(tmp_path)
    env = {**os.environ, "PYTHONPATH": str(SRC), "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
    cmd = [
        sys.executable,
        "-m",
        "pointplan.cli",
        "eval",
        "--env",
        "narrow2d",
        "--planner",
        "policy",
        "--checkpoint",
        str(evil),
        "--episodes",
        "1",
        "--quiet",
    ]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env, cwd=tmp_path)
    assert res.returncode != 0
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert "Traceback" not in res.stderr and "convert-checkpoint" in lines[0] and str(evil) in lines[0]
    assert not marker.exists()


# ------------------------------------------------------------------ (2) damaged and foreign files
def test_truncated_text_and_foreign_files_get_clear_errors(tmp_path: Path) -> None:
    good = tmp_path / "good.pt"
    save_checkpoint(good, {"actor": OrderedDict(w=torch.ones(3))})
    assert load_checkpoint(good)["version"] == VERSION
    data = good.read_bytes()
    cases = {
        "truncated.pt": (data[: len(data) // 2], "truncated"),
        "empty.pt": (b"", "truncated"),
        "notes.txt": (b"these are not the weights you are looking for\n", "not a pointplan checkpoint"),
    }
    for name, (content, match) in cases.items():
        (tmp_path / name).write_bytes(content)
        with _one_line_error(match) as info:
            load_checkpoint(tmp_path / name)
        assert name in str(info.value) and "\n" not in str(info.value)
    torch.save({"weights": torch.zeros(2)}, tmp_path / "other.pt")  # a torch file, not ours
    with _one_line_error("not a pointplan checkpoint"):
        load_checkpoint(tmp_path / "other.pt")
    with _one_line_error("no such checkpoint"):
        load_checkpoint(tmp_path / "missing.pt")
    for version in (0, "2", VERSION + 1):
        torch.save({"format": FORMAT, "version": version}, tmp_path / "v.pt")
        with _one_line_error("version"):
            load_checkpoint(tmp_path / "v.pt")


@dataclasses.dataclass
class _Config:
    width: int = 3


@pytest.mark.parametrize(
    ("value", "where"),
    [
        (np.zeros(3), "numpy.ndarray"),
        (np.float64(0.5), "numpy.float64"),
        (_Config(), "_Config"),
        (Path("runs/x"), "Path"),
        ({1, 2}, "set"),
        (torch.Size([64, 4]), "torch.Size"),
        (b"bytes", "bytes"),
        ({(1, 2): 3}, "key of type tuple"),
        (object(), "object"),
    ],
)
def test_save_refuses_what_is_not_plain_data(tmp_path: Path, value: Any, where: str) -> None:
    with _one_line_error(re.escape(where)) as info:
        save_checkpoint(tmp_path / "c.pt", {"train_config": {"net": [1, value]}})
    assert "train_config/net[1]" in str(info.value)
    assert not (tmp_path / "c.pt").exists()


def test_save_refuses_cycles_and_header_keys(tmp_path: Path) -> None:
    loop: list[Any] = [1]
    loop.append(loop)
    with _one_line_error("contains itself"):
        save_checkpoint(tmp_path / "c.pt", {"x": loop})
    with _one_line_error("version"):
        save_checkpoint(tmp_path / "c.pt", {"version": 1})
    shared = torch.ones(2)
    save_checkpoint(tmp_path / "c.pt", {"a": [shared, shared], "cfg": to_dict(SMALL)})  # shared values are fine
    assert load_checkpoint(tmp_path / "c.pt")["cfg"] == dataclasses.asdict(SMALL)


# ------------------------------------------------------------------ (3) exact round trip of the trainer state
def test_trainer_checkpoint_round_trip_is_bit_exact(tmp_path: Path) -> None:
    cfg = TrainConfig(
        env="empty2d",
        num_envs=4,
        total_steps=400,
        warmup_steps=100,
        eval_every=200,
        eval_episodes=5,
        net=SMALL,
        sac=SACConfig(batch_size=32, policy_avg=0.01),
    )
    train(cfg, tmp_path / "a", progress=False)
    state = load_checkpoint(tmp_path / "a" / "last.pt")
    assert find_non_plain(state) is None and state["version"] == VERSION
    trainer = state["trainer"]
    assert type(trainer["torch_rng"]) is torch.Tensor and trainer["rng"]["bit_generator"] == "PCG64"
    save_checkpoint(tmp_path / "again.pt", {k: v for k, v in state.items() if k not in ("format", "version")})
    assert_same(load_checkpoint(tmp_path / "again.pt"), state)
    # the state restores exactly: a fresh agent loaded from it gives the same state back
    agent = SAC(Disc2D(), EnvConfig(), tuple(state["obs_shape"]), SMALL, cfg.sac)
    agent.load_state_dict(trainer["agent"])
    assert_same(agent.state_dict(), trainer["agent"])
    rng = np.random.default_rng(123)
    rng.bit_generator.state = trainer["rng"]
    assert rng.bit_generator.state == trainer["rng"]


def _random_buffer(rng: np.random.Generator) -> EpisodeReplay:
    buf = EpisodeReplay(1000, (64, 4), 2, 2)
    for _ in range(6):
        t = 20
        obs = rng.normal(size=(t + 1, 64, 4)).astype(np.float32)
        q = np.cumsum(rng.normal(scale=0.02, size=(t + 1, 2)), axis=0) + 0.5
        action = rng.uniform(-1, 1, (t, 2)).astype(np.float32)
        buf.add_episode(
            obs[:-1],
            obs[1:],
            q[:-1],
            q[1:],
            np.repeat(q[-1:], t, 0),
            action,
            np.linalg.norm(action, axis=1),
            np.zeros(t, bool),
        )
    return buf


def _updates(agent: SAC, buf: EpisodeReplay, rng: np.random.Generator, n: int) -> list[dict[str, float]]:
    return [agent.update(buf.sample(32, rng)) for _ in range(n)]


def test_resumed_updates_match_uninterrupted_ones(tmp_path: Path) -> None:
    """Save mid-run, keep going; then load into a fresh agent and repeat: same losses, same weights."""
    sac_cfg = SACConfig(batch_size=32, policy_avg=0.05)
    rng = np.random.default_rng(0)
    buf = _random_buffer(rng)
    torch.manual_seed(0)
    agent = SAC(Disc2D(), EnvConfig(), (64, 4), SMALL, sac_cfg)
    _updates(agent, buf, rng, 4)
    save_checkpoint(
        tmp_path / "mid.pt",
        {"trainer": {"agent": agent.state_dict(), "rng": rng.bit_generator.state, "torch_rng": torch.get_rng_state()}},
    )
    losses = _updates(agent, buf, rng, 4)

    torch.manual_seed(1)  # another initialisation and other random streams, all overwritten below
    resumed = SAC(Disc2D(), EnvConfig(), (64, 4), SMALL, sac_cfg)
    rng2 = np.random.default_rng(1)
    trainer = load_checkpoint(tmp_path / "mid.pt")["trainer"]
    resumed.load_state_dict(trainer["agent"])
    rng2.bit_generator.state = trainer["rng"]
    torch.set_rng_state(trainer["torch_rng"])
    assert _updates(resumed, buf, rng2, 4) == losses
    assert_same(resumed.state_dict(), agent.state_dict())
    assert rng2.bit_generator.state == rng.bit_generator.state


# ------------------------------------------------------------------ (4) converting older files
def test_version_1_data_only_file_loads_and_converts(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    payload = {
        "package_version": "0.0.9",
        "robot": "disc2d",
        "obs_shape": [64, 4],
        "actor": OrderedDict(w=torch.arange(4.0)),
        "trainer": {"rng": {"state": {"state": 2**100}}},
    }
    torch.save({"format": FORMAT, "version": 1, **payload}, tmp_path / "v1.pt")
    assert load_checkpoint(tmp_path / "v1.pt")["version"] == 1  # pure data: accepted as it is
    assert main(["convert-checkpoint", str(tmp_path / "v1.pt"), str(tmp_path / "v2.pt")]) == 0
    out = capsys.readouterr()
    assert "unpickles" in out.err and "trust" in out.err and "v2.pt" in out.out
    assert_same(load_checkpoint(tmp_path / "v2.pt"), {"format": FORMAT, "version": VERSION, **payload})


def test_old_file_with_objects_is_refused_then_converted(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    old = tmp_path / "old.pt"
    torch.save(
        {
            "format": FORMAT,
            "version": 1,
            "net": SMALL,
            "obs_shape": np.array([64, 4]),
            "val_success": np.float64(0.75),
            "init": Path("runs/bc.pt"),
            "actor": {"w": torch.nn.Parameter(torch.ones(2))},
        },
        old,
    )
    with _one_line_error(re.escape(f"pointplan convert-checkpoint {old} NEW.pt")) as info:
        load_checkpoint(old)
    assert "\n" not in str(info.value)
    assert main(["convert-checkpoint", str(old), str(tmp_path / "new.pt")]) == 0
    out = capsys.readouterr()
    assert "warning" in out.err and "trust" in out.err
    assert "/net: NetConfig -> dict" in out.out and "/val_success: numpy float64 -> float" in out.out
    new = load_checkpoint(tmp_path / "new.pt")
    assert new["version"] == VERSION and find_non_plain(new) is None
    assert new["net"] == dataclasses.asdict(SMALL) and new["val_success"] == 0.75 and new["init"] == "runs/bc.pt"
    assert new["obs_shape"].tolist() == [64, 4] and type(new["actor"]["w"]) is torch.Tensor


def test_convert_refuses_what_has_no_plain_form(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    torch.save({"format": FORMAT, "version": 1, "tags": {"a", "b"}}, tmp_path / "set.pt")
    assert main(["convert-checkpoint", str(tmp_path / "set.pt"), str(tmp_path / "new.pt")]) == 2
    assert "/tags" in capsys.readouterr().err and not (tmp_path / "new.pt").exists()
    torch.save({"weights": torch.zeros(1)}, tmp_path / "other.pt")
    assert main(["convert-checkpoint", str(tmp_path / "other.pt"), str(tmp_path / "new.pt")]) == 2
    assert "not a pointplan checkpoint" in capsys.readouterr().err


# ------------------------------------------------------------------ the files in the repository
@pytest.mark.parametrize(
    "path", [shipped_checkpoint("disc2d"), REPO / "checkpoints" / "narrow2d_bcsac_retry_1390k_last.pt"]
)
def test_committed_checkpoints_are_version_2_data_only(path: Path) -> None:
    if not path.exists():
        pytest.skip(f"{path} is not in this checkout")
    data = load_checkpoint(path)
    assert data["version"] == 2 and find_non_plain(data) is None


def test_only_the_conversion_unpickles() -> None:
    """No code under src/ may unpickle a file, except the explicit conversion."""
    risky = re.compile(
        r"weights_only\s*=\s*False|allow_pickle\s*=\s*True|pickle\.loads?\(|torch\.jit\.load|dill|joblib"
    )
    hits = {}
    for py in sorted((SRC / "pointplan").rglob("*.py")):
        found = [line.strip() for line in py.read_text().splitlines() if risky.search(line)]
        if found:
            hits[py.relative_to(SRC).as_posix()] = found
    assert list(hits) == ["pointplan/models/convert.py"], hits
    assert all("weights_only=False" in line for line in hits["pointplan/models/convert.py"])


# ------------------------------------------------------------------ the MPNet and sampler loaders
def _shipped_and_loader(kind: str) -> tuple[Path, Any]:
    """The shipped checkpoint of ``kind`` and the loader the planners use for it."""
    from pointplan.models.mpnet import MPNet, shipped_mpnet
    from pointplan.planners.learned_sampling import LearnedSampler, shipped_sampler

    if kind == "mpnet":
        return shipped_mpnet("disc2d"), MPNet.from_checkpoint
    return shipped_sampler("disc2d"), lambda path: LearnedSampler(path, Disc2D(), 0.5)


@pytest.mark.parametrize(
    ("kind", "weights", "name", "what"),
    [
        ("mpnet", "model", "pnet.3.weight", "the MPNet's weights"),
        ("sampler", "weights", "cvae.decoder.2.weight", "the sampler network's weights"),
    ],
)
def test_mpnet_and_sampler_checkpoints_with_wrong_weights_are_refused_in_one_line(
    tmp_path: Path, kind: str, weights: str, name: str, what: str
) -> None:
    shipped, load = _shipped_and_loader(kind)
    load(shipped)  # the shipped one loads
    data = load_checkpoint(shipped)
    missing = {**data, weights: {k: v for k, v in data[weights].items() if k != name}}
    wrong = {**data, weights: {**data[weights], name: torch.zeros(3, 5)}}
    for label, payload, expected in (
        ("missing.pt", missing, f"{what} do not match its settings (missing {name!r})"),
        ("wrong.pt", wrong, f"{what} do not match its settings ({name}: (3, 5), expected "),
    ):
        path = tmp_path / label
        save_checkpoint(path, {k: v for k, v in payload.items() if k not in ("format", "version")})
        with _one_line_error("do not match its settings") as info:
            load(path)
        message = str(info.value)
        assert "\n" not in message and message.startswith(f"{path}: ") and expected in message, message
