"""The inference policy: a trained actor plus what it needs to read observations.

Evaluation, the CLI and deployment use this class; none of them imports the trainer.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..learning.checkpoint import check_compatible, load_checkpoint
from ..robots import make_robot
from ..robots.base import Robot
from .actor_critic import Actor, NetConfig
from .encoders import EncoderConfig
from .inputs import goal_input, obs_input


def net_config_from_dict(d: dict[str, Any]) -> NetConfig:
    d = dict(d)
    d["encoder"] = EncoderConfig(**d["encoder"])
    return NetConfig(**d)


class Policy:
    """Deterministic (mean) actions from observations, configurations and goals."""

    def __init__(self, actor: Actor, robot: Robot, meta: dict[str, Any], device: str = "cpu") -> None:
        self.actor = actor.eval()
        self.robot = robot
        self.meta = meta
        self.device = torch.device(device)

    @property
    def observation(self) -> str:
        return str(self.meta["observation"])

    @property
    def n_points(self) -> int:
        return int(self.meta.get("n_points", 64))

    @property
    def env(self) -> str:
        return str(self.meta["env"])

    @classmethod
    def from_checkpoint(cls, path: str | Path, device: str = "cpu") -> Policy:
        data = load_checkpoint(path, device)
        robot = make_robot(data["robot"])
        net = net_config_from_dict(data["net"])
        actor = Actor(tuple(data["obs_shape"]), robot.twist_dim, robot.twist_dim, net)
        actor.load_state_dict(data["actor"])  # a shared encoder's weights come with the actor
        actor.detach_encoder = False
        meta = {k: v for k, v in data.items() if k not in ("actor", "trainer")}
        return cls(actor.to(device), robot, meta, device)

    def check_env(self, robot: Robot, observation: str, obs_shape: tuple[int, ...]) -> None:
        """Raise a clear error if the env differs from the one the policy was trained on."""
        check_compatible(self.meta, robot.name, observation, obs_shape, where="policy checkpoint")

    @torch.no_grad()
    def __call__(self, obs: np.ndarray, q: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Actions ``(E, k)`` in [-1, 1] for observations ``(E, ...)``, configurations and goals."""
        o = torch.as_tensor(obs_input(self.robot, obs), device=self.device)
        g = torch.as_tensor(goal_input(self.robot, q, goal), device=self.device)
        return self.actor.act(o, g).cpu().numpy()


#: trained policies that ship inside the package: (robot, observation) -> file in
#: ``pointplan/data``. The 3D ones were trained on 3D-Boxes and serve every 3D scene, as
#: in the paper.
SHIPPED: dict[tuple[str, str], str] = {
    ("disc2d", "surface-normals"): "narrow2d_policy.pt",
}
#: the observation a robot's policy uses when none is asked for
DEFAULT_OBSERVATION = {"disc2d": "surface-normals", "sphere3d": "global", "sshape": "local"}


def shipped_policies() -> list[tuple[str, str]]:
    """The (robot, observation) pairs a policy ships for."""
    from importlib.resources import files

    return [k for k, name in SHIPPED.items() if (files("pointplan") / "data" / name).is_file()]


def shipped_checkpoint(robot: str = "disc2d", observation: str | None = None) -> Path:
    """The path of the policy shipped for ``robot`` and ``observation`` (see
    docs/results.md for how each was trained and what it scores)."""
    from importlib.resources import files

    observation = observation or DEFAULT_OBSERVATION.get(robot, "")
    name = SHIPPED.get((robot, observation))
    path = Path(str(files("pointplan") / "data" / name)) if name else None
    if path is None or not path.is_file():
        have = ", ".join(f"{r} with {o!r} points" for r, o in shipped_policies()) or "none"
        raise ValueError(f"no policy ships for robot {robot!r} with {observation!r} observations (shipped: {have}); pass --checkpoint PATH, or train one with `pointplan train`")
    return path
