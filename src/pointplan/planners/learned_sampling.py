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
from .base import Array, PlanResult
from .birrt import BiRRT, DrawSamples

if TYPE_CHECKING:
    import torch

    from ..models.cvae import CVAEConfig, LearnedSamplerNet

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


def load_sampler(checkpoint: str | Path, robot: Robot) -> tuple[CVAEConfig, LearnedSamplerNet, Array, Array, float]:
    """The network of a sampler checkpoint for ``robot`` (in eval mode), its settings, the
    bounds it normalises positions by (``low``, ``high``) and the spacing of the scene
    points it reads. Anything wrong with the file or its contents raises a one-line
    :class:`~pointplan.models.checkpoint.CheckpointError`."""
    import torch

    from ..config import from_dict
    from ..models.checkpoint import CheckpointError, check_finite_weights, check_weights, load_checkpoint, rebuilding
    from ..models.cvae import CVAEConfig, LearnedSamplerNet

    data = load_checkpoint(checkpoint)
    if data.get("kind") != CHECKPOINT_KIND:
        raise CheckpointError(
            f"{checkpoint}: not a learned-sampling network (train one with `pointplan lsample-train`)"
        )
    with rebuilding(checkpoint, "learned-sampling"):
        _check_sampler_fields(data, checkpoint, robot)
        config = from_dict(CVAEConfig, data["cvae"])
        _check_sampler_settings(config, checkpoint)
        with torch.device("meta"):  # the shapes of the weights, allocating nothing
            expected = LearnedSamplerNet(config, robot.dim).state_dict()
        check_weights(checkpoint, expected, data["weights"], "sampler network")
        check_finite_weights(checkpoint, data["weights"], "sampler network")
        net = LearnedSamplerNet(config, robot.dim)
        net.load_state_dict(data["weights"])
    low, high = np.asarray(data["low"], np.float64), np.asarray(data["high"], np.float64)
    return config, net.eval(), low, high, float(data["spacing"])


def _check_sampler_fields(data: dict[str, Any], path: str | Path, robot: Robot) -> None:
    """The fields of a sampler checkpoint that loading it reads, but the network's settings."""
    from ..models.checkpoint import CheckpointError, finite_number, short_repr

    for key in ("robot", "cvae", "weights", "low", "high", "spacing"):
        if key not in data:
            raise CheckpointError(f"{path}: not a learned-sampling network (it has no {key!r})")
    if not isinstance(data["robot"], str) or data["robot"] != robot.name:
        raise CheckpointError(f"{path} was trained for robot {short_repr(data['robot'])}, not {robot.name!r}")
    if not isinstance(data["cvae"], dict):
        raise CheckpointError(f"{path}: cvae must hold the network's settings, got {type(data['cvae']).__name__}")
    low, high = data["low"], data["high"]
    for bound in (low, high):
        if not isinstance(bound, (list, tuple)) or len(bound) != robot.dim or not all(map(finite_number, bound)):
            raise CheckpointError(f"{path}: low and high must be {robot.dim} numbers each, got {short_repr(bound)}")
    if not all(a < b for a, b in zip(low, high)):
        raise CheckpointError(f"{path}: low must be below high in every coordinate, got {low!r} and {high!r}")
    spacing = data["spacing"]
    if not finite_number(spacing) or spacing <= 0:
        raise CheckpointError(f"{path}: spacing must be a positive number, got {short_repr(spacing)}")


def _check_sampler_settings(config: CVAEConfig, path: str | Path) -> None:
    """A sampler network's settings: its sizes, positive scales and a known frame."""
    from ..models.checkpoint import CheckpointError, check_sizes, finite_number, short_repr

    check_sizes(path, config, ("latent", "width", "point_width"), ("layers", "point_layers"), "sampler network")
    for name in ("input_scale", "min_half"):
        value = getattr(config, name)
        if not finite_number(value) or value <= 0:
            raise CheckpointError(
                f"{path}: the sampler network's {name} must be a positive number, got {short_repr(value)}"
            )
    if config.frame not in ("world", "start-goal"):
        raise CheckpointError(
            f"{path}: the sampler network's frame must be 'world' or 'start-goal', got {short_repr(config.frame)}"
        )


class LearnedSampler:
    """The CVAE of a checkpoint as a Bi-RRT ``sampler``: ``sampler(problem)`` encodes the
    problem once and returns ``draw(rng, n)``, which draws ``n`` uniform targets and
    replaces each, with probability ``lam``, by a decoded sample (clipped into the bounds).
    ``drawn`` counts the network's samples of the last problem."""

    def __init__(self, checkpoint: str | Path, robot: Robot, lam: float) -> None:
        import torch

        if not 0.0 <= lam <= 1.0:
            raise ValueError(f"lam is a probability, got {lam}")
        if robot.config_dim != robot.dim:
            raise ValueError(f"learned sampling samples positions: robot {robot.name} has orientations")
        self.robot, self.lam, self.checkpoint = robot, float(lam), str(checkpoint)
        self.config, self.net, self.low, self.high, self.spacing = load_sampler(checkpoint, robot)
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
    "load_sampler",
    "shipped_sampler",
]
