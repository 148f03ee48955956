"""The inference policy: a trained actor plus what it needs to read observations.

Evaluation, the CLI and deployment use this class; none of them imports the trainer.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..config import from_dict
from ..robots import make_robot
from ..robots.base import Robot
from .actor_critic import LOG_STD_MAX, LOG_STD_MIN, Actor, NetConfig
from .checkpoint import CheckpointError, check_compatible, check_weights, load_checkpoint, rebuilding
from .inputs import goal_dim, goal_input, obs_input


class Policy:
    """Deterministic (mean) actions from observations, configurations and goals."""

    def __init__(self, actor: Actor, robot: Robot, meta: dict[str, Any], device: str = "cpu") -> None:
        self.actor = actor.eval()
        self.robot = robot
        self.meta = meta
        self.device = torch.device(device)
        #: the file it was loaded from (:meth:`from_checkpoint`), else None
        self.path: Path | None = None

    @property
    def observation(self) -> str:
        """The name of the observer the policy was trained on (``surface-normals``, ``local``, ...)."""
        return str(self.meta["observation"])

    @property
    def n_points(self) -> int:
        """Points per observation in training (64 for checkpoints that do not say)."""
        return int(self.meta.get("n_points", 64))

    @property
    def env(self) -> str:
        """The scenario the policy was trained in."""
        return str(self.meta["env"])

    @classmethod
    def from_checkpoint(cls, path: str | Path, device: str = "cpu") -> Policy:
        """The policy of a checkpoint. Anything wrong with the file or its contents raises
        a one-line :class:`~pointplan.models.checkpoint.CheckpointError`."""
        data = load_checkpoint(path, device)
        with rebuilding(path, "policy"):
            _check_policy_fields(data, path)
            robot = make_robot(data["robot"])
            net = from_dict(NetConfig, data["net"])
            shape = tuple(data["obs_shape"])
            with torch.device("meta"):  # the shapes of the weights, allocating nothing
                expected = Actor(shape, goal_dim(robot), robot.twist_dim, net).state_dict()
            check_weights(path, expected, data["actor"], "actor")
            actor = Actor(shape, goal_dim(robot), robot.twist_dim, net)
            actor.load_state_dict(data["actor"])  # a shared encoder's weights come with the actor
        actor.detach_encoder = False
        meta = {k: v for k, v in data.items() if k not in ("actor", "trainer")}
        policy = cls(actor.to(device), robot, meta, device)
        policy.path = Path(path)
        return policy

    def check_env(self, robot: Robot, observation: str, obs_shape: tuple[int, ...]) -> None:
        """Raise a clear error if the env differs from the one the policy was trained on."""
        check_compatible(self.meta, robot.name, observation, obs_shape, where="policy checkpoint")

    def __call__(self, obs: np.ndarray, q: np.ndarray, goal: np.ndarray, noise: np.ndarray | None = None) -> np.ndarray:
        """Actions ``(E, k)`` in [-1, 1] for observations ``(E, ...)``, configurations and
        goals: the mean action ``tanh(mean)``, or with ``noise`` (``(E, k)`` standard
        normal draws, possibly scaled) the sampled one ``tanh(mean + std * noise)``."""
        with torch.inference_mode():
            o = torch.as_tensor(obs_input(self.robot, obs), device=self.device)
            g = torch.as_tensor(goal_input(self.robot, q, goal), device=self.device)
            if noise is None:
                return self.actor.act(o, g).cpu().numpy()
            mean, log_std = self.actor(o, g)
            eps = torch.as_tensor(np.asarray(noise, np.float32), device=self.device)
            return torch.tanh(mean + log_std.exp() * eps).cpu().numpy()

    def fast_actor(self) -> NumpyPointNetActor | None:
        """The actor as numpy arrays (a snapshot of the current weights) when it is a
        PointNet actor on the CPU, else ``None``: see :class:`NumpyPointNetActor`."""
        if self.device.type != "cpu":
            return None
        return NumpyPointNetActor.from_actor(self.actor)


def _check_policy_fields(data: dict[str, Any], path: str | Path) -> None:
    """The fields of a policy checkpoint that rebuilding it and observing for it read."""
    for key in ("robot", "observation", "obs_shape", "net", "actor"):
        if key not in data:
            raise CheckpointError(f"{path}: not a policy checkpoint (it has no {key!r})")
    if not isinstance(data["robot"], str) or not isinstance(data["observation"], str):
        raise CheckpointError(f"{path}: its robot and observation must be names (strings)")
    shape = data["obs_shape"]
    if not isinstance(shape, (list, tuple)) or not shape or not all(type(x) is int and x > 0 for x in shape):
        raise CheckpointError(f"{path}: obs_shape must be a list of positive integers, got {shape!r}")
    if not isinstance(data["net"], dict):
        raise CheckpointError(f"{path}: net must hold the network's settings, got {type(data['net']).__name__}")
    n_points = data.get("n_points", 64)
    if type(n_points) is not int or n_points < 1:
        raise CheckpointError(f"{path}: n_points must be a positive integer, got {n_points!r}")


def _elu(x: np.ndarray) -> np.ndarray:
    """ELU in place, in three numpy calls: ``max(x, expm1(min(x, 0)))`` (for ``x > 0``
    the second term is 0, for ``x < 0`` it exceeds ``x``)."""
    neg = np.minimum(x, 0.0)
    np.expm1(neg, out=neg)
    return np.maximum(x, neg, out=x)


class NumpyPointNetActor:
    """The deterministic action ``tanh(mean)`` of a PointNet :class:`Actor`, in numpy.

    A planner asks for one action at a time; for a network this small (3 x 64 per point,
    3 x 64 head) PyTorch's per-operation overhead costs more than the arithmetic, and its
    default thread pool oversubscribes a busy machine. Here the same float32 arithmetic
    runs as a dozen numpy calls on weights copied once (agrees with the PyTorch actor to
    about 1e-6). ``obs_in: (..., N, F)`` and ``goal_in: (..., G)`` are the network inputs
    (:func:`obs_input`, :func:`goal_input`)."""

    def __init__(
        self,
        inp: tuple[np.ndarray, np.ndarray],
        hidden: list[tuple[np.ndarray, np.ndarray]],
        head: list[tuple[np.ndarray, np.ndarray]],
        action_dim: int,
    ) -> None:
        self.inp = inp
        self.hidden = hidden
        self.head = head
        self.action_dim = int(action_dim)

    @classmethod
    def from_actor(cls, actor: Actor) -> NumpyPointNetActor | None:
        """The numpy twin of ``actor``, or ``None`` if its architecture is not a PointNet
        encoder (no per-point extras) followed by a Linear/ELU head."""
        from torch import nn

        from .encoders import PointNetEncoder

        enc = actor.encoder
        if type(enc) is not PointNetEncoder or enc.extra or not isinstance(enc.act, nn.ELU) or enc.act.alpha != 1.0:
            return None
        mods = list(actor.head)
        linears = [m for m in mods[0::2] if isinstance(m, nn.Linear)]
        if (
            len(linears) != len(mods[0::2])
            or not all(isinstance(m, nn.ELU) and m.alpha == 1.0 for m in mods[1::2])
            or len(mods) % 2 != 1
        ):
            return None

        def wb(layer: nn.Linear) -> tuple[np.ndarray, np.ndarray]:
            w = layer.weight.detach().cpu().numpy().astype(np.float32).T.copy()
            return w, layer.bias.detach().cpu().numpy().astype(np.float32).copy()

        hidden = [m for m in enc.hidden if isinstance(m, nn.Linear)]
        if len(hidden) != len(enc.hidden):
            return None
        return cls(wb(enc.inp), [wb(m) for m in hidden], [wb(m) for m in linears], actor.action_dim)

    def __call__(self, obs_in: np.ndarray, goal_in: np.ndarray, noise: np.ndarray | None = None) -> np.ndarray:
        w, b = self.inp
        h = obs_in @ w
        h += b
        return self.from_first_layer(h, goal_in, noise)

    def from_first_layer(self, h: np.ndarray, goal_in: np.ndarray, noise: np.ndarray | None = None) -> np.ndarray:
        """The action from the first layer's pre-activations ``obs_in @ W + b``
        (``(..., N, width)`` float32, overwritten): a caller that can get them cheaper
        (a translating robot: a table per scene minus one row per step) skips the input
        layer. With ``noise`` (standard normal draws, possibly scaled, one per action
        component) the sampled action ``tanh(mean + std * noise)`` instead of
        ``tanh(mean)``."""
        h = _elu(h)
        last = len(self.hidden) - 1
        pooled = None
        for i, (w, b) in enumerate(self.hidden):
            y = h @ w
            if i < last:  # residual on the middle layers, plain on the last (max-pooled)
                y += b
                y += h
                h = _elu(y)
            else:  # max(y + b) = max(y) + b exactly (rounding is monotonic)
                pooled = np.maximum.reduce(y, axis=-2)
                pooled += b
        if pooled is None:
            pooled = np.maximum.reduce(h, axis=-2)
        z = np.concatenate([pooled, np.asarray(goal_in, np.float32)], -1)
        for i, (w, b) in enumerate(self.head):
            z = z @ w
            z += b
            if i < len(self.head) - 1:
                z = _elu(z)
        mean = z[..., : self.action_dim]
        if noise is None:
            return np.tanh(mean)
        log_std = np.clip(z[..., self.action_dim :], LOG_STD_MIN, LOG_STD_MAX)
        return np.tanh(mean + np.exp(log_std) * np.asarray(noise, np.float32))


#: trained policies that ship inside the package: (robot, observation) -> file in
#: ``pointplan/data``. The 3D ones were trained on 3D-Boxes and serve every 3D scene, as
#: in the paper.
SHIPPED: dict[tuple[str, str], str] = {
    ("disc2d", "surface-normals"): "narrow2d_policy.pt",
    ("sphere3d", "local"): "sphere3d_local_policy.pt",
    ("sphere3d", "global"): "sphere3d_global_policy.pt",
    ("sshape", "local"): "sshape_local_policy.pt",
    ("sshape", "global"): "sshape_global_policy.pt",
}
#: policies trained for one scene, taken there before the 3D-Boxes ones: (robot,
#: observation, scenario) -> file in ``pointplan/data``: the moving-gate Slot's, and the
#: paper's Slot's for the S-shape told its orientation (trained there; docs/results/slot.md).
SHIPPED_FOR_SCENE: dict[tuple[str, str, str], str] = {
    ("sshape", "local", "slotmoving"): "slotmoving_sshape_local_policy.pt",
    ("sshape-oriented", "local", "slot"): "slot_sshape_oriented_local_policy.pt",
}
#: the observation a robot's policy uses when none is asked for (the better of the two on
#: the validation problems where both ship; docs/results/README.md)
DEFAULT_OBSERVATION = {"disc2d": "surface-normals", "sphere3d": "global", "sshape": "local", "sshape-oriented": "local"}


def shipped_policies() -> list[tuple[str, str]]:
    """The (robot, observation) pairs a policy ships for."""
    from importlib.resources import files

    return [k for k, name in SHIPPED.items() if (files("pointplan") / "data" / name).is_file()]


def shipped_checkpoint(robot: str = "disc2d", observation: str | None = None, scene: str | None = None) -> Path:
    """The path of the policy shipped for ``robot`` and ``observation`` (see
    docs/results/README.md for how each was trained and what it scores). With ``scene`` (a
    scenario's name), the policy trained for that scene if one ships
    (:data:`SHIPPED_FOR_SCENE`), else the robot's."""
    from importlib.resources import files

    if scene is not None:
        for (r, o, sc), fname in SHIPPED_FOR_SCENE.items():
            if (
                r == robot
                and sc == scene
                and (observation is None or observation == o)
                and (files("pointplan") / "data" / fname).is_file()
            ):
                return Path(str(files("pointplan") / "data" / fname))
    if observation is None:  # the robot's usual observation, else any that ships for it
        have = [o for r, o in shipped_policies() if r == robot]
        default = DEFAULT_OBSERVATION.get(robot, "")
        observation = default if default in have or not have else have[0]
    name = SHIPPED.get((robot, observation))
    path = Path(str(files("pointplan") / "data" / name)) if name else None
    if path is None or not path.is_file():
        shipped = ", ".join(f"{r} with {o!r} points" for r, o in shipped_policies()) or "none"
        raise ValueError(
            f"no policy ships for robot {robot!r} with {observation!r} observations (shipped: {shipped}); pass --checkpoint PATH, or train one with `pointplan train`"
        )
    return path
