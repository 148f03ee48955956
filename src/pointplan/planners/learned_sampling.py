"""Learned sampling (Ichter, Harrison and Pavone, ICRA 2018) on Bi-RRT.

Bi-RRT (:class:`~pointplan.planners.birrt.BiRRT`, unchanged: the same extend, connect,
certified edges, shortcutting and node count) draws each extend target from a conditional
VAE's decoder with probability ``lam`` (latent from the prior ``N(0, I)``, conditioned on
the problem: the scene's boundary points with normals, the start and the goal) and
uniformly in the bounds otherwise. The network is :mod:`pointplan.models.cvae`; it is
trained by ``pointplan lsample-train`` (:mod:`pointplan.learning.lsample`) on
configurations of Bi-RRT solutions of training problems.

With ``lam = 0`` no network runs and the generator is consumed exactly as plain Bi-RRT
consumes it, so the planner returns what ``BiRRT`` with the same seed returns.
Registered as ``learned-sampling`` (option ``lam``), ``lsample-0.5`` and ``lsample-0.9``;
without a ``checkpoint`` the one shipped for the robot is used.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..robots.base import Robot
from ..scenes.scene import Problem
from .base import PlanResult
from .birrt import BiRRT, DrawSamples

if TYPE_CHECKING:
    import torch

    #: the network's condition for a problem, with the problem's normalised start and goal
    Condition = tuple[torch.Tensor, torch.Tensor, torch.Tensor]

#: the sampler networks that ship, by robot name (files in ``pointplan/data``)
SHIPPED_SAMPLERS = {"disc2d": "narrow2d_lsample_cvae.pt"}
#: the ``kind`` a sampler checkpoint carries
CHECKPOINT_KIND = "lsample-cvae"


def shipped_sampler(robot: str = "disc2d") -> Path:
    """The path of the sampler network shipped for ``robot`` (docs/results/README.md says how it
    was trained and what it scores)."""
    from importlib.resources import files

    name = SHIPPED_SAMPLERS.get(robot)
    path = Path(str(files("pointplan") / "data" / name)) if name else None
    if path is None or not path.is_file():
        have = ", ".join(sorted(SHIPPED_SAMPLERS)) or "none"
        raise ValueError(
            f"no learned sampler ships for robot {robot!r} (shipped: {have}); pass checkpoint=PATH, or train one with `pointplan lsample-train`"
        )
    return path


class LearnedSampler:
    """The CVAE of a checkpoint as a Bi-RRT ``sampler``: ``sampler(problem)`` encodes the
    problem once and returns ``draw(rng, n)``, which draws ``n`` uniform targets and
    replaces each, with probability ``lam``, by a decoded sample (clipped into the bounds).
    ``drawn`` counts the network's samples of the last problem."""

    def __init__(self, checkpoint: str | Path, robot: Robot, lam: float) -> None:
        import torch

        from ..config import from_dict
        from ..models.checkpoint import CheckpointError, load_checkpoint
        from ..models.cvae import CVAEConfig, LearnedSamplerNet

        if not 0.0 <= lam <= 1.0:
            raise ValueError(f"lam is a probability, got {lam}")
        if robot.config_dim != robot.dim:
            raise ValueError(f"learned sampling samples positions: robot {robot.name} has orientations")
        data = load_checkpoint(checkpoint)
        if data.get("kind") != CHECKPOINT_KIND:
            raise CheckpointError(
                f"{checkpoint}: not a learned-sampling network (train one with `pointplan lsample-train`)"
            )
        if data["robot"] != robot.name:
            raise CheckpointError(f"{checkpoint} was trained for robot {data['robot']!r}, not {robot.name!r}")
        self.robot, self.lam, self.checkpoint = robot, float(lam), str(checkpoint)
        self.config = from_dict(CVAEConfig, data["cvae"])
        self.net = LearnedSamplerNet(self.config, robot.dim)
        self.net.load_state_dict(data["weights"])
        self.net.eval()
        self.low = np.asarray(data["low"], np.float64)
        self.high = np.asarray(data["high"], np.float64)
        self.spacing = float(data["spacing"])
        self.drawn = 0
        self._torch = torch

    def condition(self, problem: Problem) -> Condition:
        """The network's condition for ``problem`` (a ``(1, c_dim)`` tensor) and its
        normalised start and goal."""
        from ..models.cvae import normalise, scene_cloud

        torch = self._torch
        cloud = scene_cloud(problem.scene, self.spacing)
        ends = normalise(np.stack([problem.start, problem.goal]), self.low, self.high)
        t = torch.from_numpy
        start, goal = t(ends[:1].astype(np.float32)), t(ends[1:].astype(np.float32))
        with torch.no_grad():
            return self.net.condition(t(cloud[None].astype(np.float32)), start, goal), start, goal

    def decode(self, cond: Condition, z: np.ndarray) -> np.ndarray:
        """Configurations decoded from latents ``z: (k, latent)`` under the condition
        :meth:`condition` gave."""
        from ..models.cvae import denormalise

        c, start, goal = cond
        with self._torch.no_grad():
            y = self.net.cvae.sample(c, self._torch.from_numpy(z.astype(np.float32)))
            x = self.net.from_target(y, start, goal)
        return denormalise(x.double().numpy(), self.low, self.high)

    def __call__(self, problem: Problem) -> DrawSamples:
        from .policy import torch_threads

        robot, scene, lam = self.robot, problem.scene, self.lam
        low, high = scene.low, scene.high
        self.drawn = 0
        if lam <= 0.0:  # plain Bi-RRT's draws, nothing else taken from the generator
            return lambda rng, n: robot.sample_uniform(rng, n, low, high)
        with torch_threads(1):
            c = self.condition(problem)

        def draw(rng: np.random.Generator, n: int) -> np.ndarray:
            u = robot.sample_uniform(rng, n, low, high)
            learned = rng.random(n) < lam
            k = int(learned.sum())
            if k:
                z = rng.standard_normal((k, self.config.latent))
                with torch_threads(1):
                    u[learned] = np.clip(self.decode(c, z), low, high)
                self.drawn += k
            return u

        return draw


class LearnedSamplingPlanner(BiRRT):
    """Bi-RRT whose extend targets come from a :class:`LearnedSampler` with probability
    ``lam``. Other keywords are Bi-RRT's. ``info`` of a result has ``lambda`` and
    ``learned_samples`` (network samples drawn, used or not)."""

    def __init__(
        self, robot: Robot, lam: float = 0.5, checkpoint: str | Path | None = None, name: str | None = None, **kw: Any
    ) -> None:
        if not checkpoint or checkpoint == "shipped":
            checkpoint = shipped_sampler(robot.name)
        self.learned = LearnedSampler(checkpoint, robot, lam)
        super().__init__(robot, sampler=self.learned, **kw)
        self.lam = float(lam)
        self.name = name or f"lsample-{lam:g}"

    def __repr__(self) -> str:
        return f"LearnedSamplingPlanner(lam={self.lam}, checkpoint={self.learned.checkpoint!r}, {super().__repr__()})"

    def plan(self, problem: Problem) -> PlanResult:
        result = super().plan(problem)
        result.info.update({"lambda": self.lam, "learned_samples": self.learned.drawn})
        return result


def learned_sampling_factory(
    robot: Robot, lam: float = 0.5, checkpoint: str | None = None, **kw: Any
) -> LearnedSamplingPlanner:
    """``learned-sampling``: Bi-RRT with a fraction ``lam`` of learned samples; the
    network of ``checkpoint`` or the one shipped for ``robot``."""
    return LearnedSamplingPlanner(robot, lam=lam, checkpoint=checkpoint, **kw)


__all__ = [
    "CHECKPOINT_KIND",
    "SHIPPED_SAMPLERS",
    "LearnedSampler",
    "LearnedSamplingPlanner",
    "learned_sampling_factory",
    "shipped_sampler",
]
