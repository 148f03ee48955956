"""Planners: Bi-RRT (RRT-Connect), the straight line, the learned policy, the hybrid
(policy, then Bi-RRT), MPNet (``mpnet-nr``, ``mpnet-hr``), learned sampling (Bi-RRT with a
CVAE's samples: ``learned-sampling``, ``lsample-0.5``, ``lsample-0.9``), OMPL's planners
(``ompl:NAME``, optional), and a registry to build them by name."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..robots.base import Robot
from .base import Planner, PlanResult, march, path_length
from .birrt import BiRRT
from .straight import StraightLine

if TYPE_CHECKING:
    from ..models.mpnet import MPNet
    from .rollout import Dodge, Escape

#: name -> factory ``(robot, **kw) -> Planner``; add planners with :func:`register_planner`
PLANNERS: dict[str, Callable[..., Planner]] = {"birrt": BiRRT, "straight": StraightLine}


def _policy_factory(
    robot: Robot, checkpoint: str | None = None, observation: str | None = None, scene: str | None = None, **kw: Any
) -> Planner:
    """The policy planner: ``checkpoint`` (a path), or the policy that ships for ``robot``
    and ``observation`` (the one trained for ``scene``, a scenario's name, if one ships)."""
    from .policy import PolicyPlanner

    if not checkpoint or checkpoint == "shipped":
        from ..models.policy import shipped_checkpoint

        checkpoint = str(shipped_checkpoint(robot.name, observation, scene))
    planner = PolicyPlanner(checkpoint, robot=robot, **kw)
    if observation is not None and planner.policy.observation != observation:
        raise ValueError(
            f"the policy {checkpoint} was trained on {planner.policy.observation!r} observations, not {observation!r}"
        )
    return planner


PLANNERS["policy"] = _policy_factory


def _hybrid_factory(
    robot: Robot,
    checkpoint: str | None = None,
    observation: str | None = None,
    scene: str | None = None,
    max_nodes: int | None = None,
    seed: int = 0,
    stall_steps: int | None = 10,
    stall_distance: float = 0.035,
    attempts: int = 1,
    action_noise: float = 1.0,
    escape: Escape | int | None = None,
    dodge: Dodge | None = None,
    fallback: str = "birrt",
    time_limit: float | None = 10.0,
    horizon: int | None = None,
    substep: float | None = None,
    **kw: Any,
) -> Planner:
    """The policy (``checkpoint`` or the shipped one, for ``scene`` if one ships), stopped when it stalls (moved less
    than ``stall_distance`` over ``stall_steps`` steps) or at its ``horizon`` (default: the policy's own), then the
    ``fallback`` from its configuration closest to the goal: ``birrt`` (``max_nodes``,
    ``seed``, other keywords) or ``ompl:NAME`` (OMPL's planner with pointplan's certified
    motion checks; other keywords go to :class:`~pointplan.planners.ompl.OMPLPlanner`).
    ``time_limit``: seconds for the whole query (10 by default; the Bi-RRT fallback then
    has no node budget unless ``max_nodes`` is given; ``None``: Bi-RRT's 10,000 nodes). ``attempts``, ``action_noise``,
    ``escape``, ``dodge``, ``substep``: the policy's sampled retries, stall escapes, dodge among moving
    obstacles and motion check (:class:`PolicyPlanner`)."""
    from .hybrid import HybridPlanner

    policy = _policy_factory(
        robot,
        checkpoint=checkpoint,
        observation=observation,
        scene=scene,
        stall_steps=stall_steps,
        stall_distance=stall_distance,
        attempts=attempts,
        action_noise=action_noise,
        escape=escape,
        dodge=dodge,
        horizon=horizon,
        substep=substep,
    )
    if fallback.lower() == "birrt":
        if max_nodes is None and time_limit is None:
            max_nodes = 10000
        back: Any = BiRRT(robot, max_nodes=max_nodes, seed=seed, time_limit=time_limit, **kw)
    elif fallback.lower().startswith("ompl:"):
        from .ompl import make_ompl_planner

        back = make_ompl_planner(robot, fallback[5:], time_limit=time_limit or 10.0, **kw)
    else:
        raise ValueError(f"the hybrid's fallback is 'birrt' or 'ompl:NAME', not {fallback!r}")
    return HybridPlanner(policy, back, time_limit=time_limit)  # type: ignore[arg-type]


def _hybrid_ompl_factory(robot: Robot, **kw: Any) -> Planner:
    """The hybrid with OMPL's RRTConnect (pointplan's certified motion checks) as its
    fallback, 10 s a query unless ``time_limit`` says otherwise (``pip install 'pointplan[ompl]'``)."""
    kw.setdefault("time_limit", 10.0)
    planner = _hybrid_factory(robot, fallback="ompl:RRTConnect", **kw)
    planner.name = "hybrid-ompl"  # type: ignore[misc]
    return planner


PLANNERS["hybrid"] = _hybrid_factory
PLANNERS["hybrid-ompl"] = _hybrid_ompl_factory


def _mpnet_factory(hybrid: bool) -> Callable[..., Planner]:
    def make(robot: Robot, checkpoint: str | Path | MPNet | None = None, **kw: Any) -> Planner:
        """MPNet (``checkpoint``: a path or a loaded ``MPNet``; default: the one that ships
        for ``robot``, ``disc2d`` or ``sphere3d``; a ValueError for other robots); keywords go to :class:`~pointplan.planners.mpnet.MPNetPlanner`
        (``seed``, ``max_nodes`` of the hybrid's Bi-RRT, ``replan_iters``, ...)."""
        from .mpnet import MPNetPlanner

        if checkpoint is None or (isinstance(checkpoint, str) and checkpoint in ("", "shipped")):
            from ..models.mpnet import shipped_mpnet

            checkpoint = shipped_mpnet(robot.name)
        return MPNetPlanner(checkpoint, robot=robot, hybrid=hybrid, **kw)

    make.__name__ = f"_mpnet_{'hr' if hybrid else 'nr'}_factory"
    return make


#: MPNet with neural replanning, and with Bi-RRT where neural replanning fails
PLANNERS["mpnet-nr"] = _mpnet_factory(False)
PLANNERS["mpnet-hr"] = _mpnet_factory(True)


def _learned_sampling_factory(robot: Robot, lam: float = 0.5, checkpoint: str | None = None, **kw: Any) -> Planner:
    """Learned sampling (Ichter et al. 2018): Bi-RRT drawing a fraction ``lam`` of its
    targets from a CVAE (``checkpoint`` or the one shipped for ``robot``); other keywords
    are Bi-RRT's (``max_nodes``, ``seed``, ...)."""
    from .learned_sampling import learned_sampling_factory

    return learned_sampling_factory(robot, lam=lam, checkpoint=checkpoint, **kw)


def _lsample(lam: float) -> Callable[..., Planner]:
    def factory(robot: Robot, **kw: Any) -> Planner:
        return _learned_sampling_factory(robot, lam=lam, **kw)

    factory.__doc__ = f"Learned sampling with lam = {lam} (see ``learned-sampling``)."
    return factory


PLANNERS["learned-sampling"] = _learned_sampling_factory
PLANNERS["lsample-0.5"] = _lsample(0.5)
PLANNERS["lsample-0.9"] = _lsample(0.9)


def register_planner(name: str, factory: Callable[..., Planner]) -> None:
    """Make ``factory(robot, **kw)`` available to :func:`make_planner` as ``name``."""
    PLANNERS[name.lower()] = factory


def make_planner(name: str, robot: Robot, **kw: Any) -> Planner:
    """A planner by name (``birrt``, ``straight``, ``policy`` with ``checkpoint=``,
    ``hybrid``, ``mpnet-nr``, ``mpnet-hr`` (``checkpoint=`` or the shipped one), ``learned-sampling`` with ``lam=``
    (or ``lsample-0.5``, ``lsample-0.9``; ``checkpoint=`` or the shipped one), ``ompl:NAME`` for any OMPL geometric planner such as ``ompl:RRTConnect``,
    or any registered one). ``ompl:`` planners raise ``ImportError`` naming
    ``pip install 'pointplan[ompl]'`` when the optional ``ompl`` package is missing."""
    key = name.strip().lower()
    for k, v in robot.planner_defaults(key).items():  # e.g. an arm's longer joint-space steps
        kw.setdefault(k, v)
    if key.startswith("ompl:"):
        from .ompl import make_ompl_planner

        return make_ompl_planner(robot, name.strip()[5:], **kw)
    try:
        factory = PLANNERS[key]
    except KeyError:
        raise ValueError(
            f"unknown planner {name!r}; known: {', '.join(sorted(PLANNERS))}, ompl:NAME (e.g. ompl:RRTConnect)"
        ) from None
    return factory(robot, **kw)


__all__ = [
    "PLANNERS",
    "BiRRT",
    "PlanResult",
    "Planner",
    "StraightLine",
    "make_planner",
    "march",
    "path_length",
    "register_planner",
]
