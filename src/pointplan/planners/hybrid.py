"""The policy first, a classical planner where it fails.

``HybridPlanner`` rolls the policy out (batch 1, :class:`~pointplan.planners.policy.PolicyPlanner`)
and keeps its path when it ends at the goal. Otherwise, when the horizon ends, when the
policy stalls (its last ``stall_steps`` steps took it less than ``stall_distance`` from
where it was: 10 steps and 0.035 by default), or when the last connection to the goal is
blocked, the fallback (Bi-RRT, or OMPL's RRTConnect with pointplan's certified motion
checks: ``hybrid-ompl``) plans from the last good configuration of the rollout to the
goal, within what is left of the query's ``time_limit``, and the two pieces make one path:

- after a stall or the horizon, the last good configuration is the one closest to the
  goal (the dithering after it is dropped from the path, not from the node count);
- after a blocked connection, it is the policy's last configuration (within the goal
  tolerance).

Every configuration of the rollout is collision-free (the environment's motion check stops
a move before it collides), so the joined path is free wherever its pieces are; the
evaluator checks it like every path. ``nodes`` = policy steps + Bi-RRT nodes,
``collision_checks`` = both planners' checks. ``info`` says what happened
(``policy_steps``, ``birrt_nodes`` (the fallback's nodes, whichever it is), ``policy_end``,
``repaired``, ``fallback``).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..robots.base import Robot
from ..scenes.scene import Problem
from .base import PlanResult
from .policy import PolicyPlanner

#: seconds of a hybrid query's budget kept back from its fallback's search for stopping and
#: joining the paths (at most 1% of the budget)
_WRAP_UP = 0.02


class HybridPlanner:
    """The policy, repaired by a classical planner where it fails or stalls.

    ``fallback``: any planner whose ``robot`` is the policy's (Bi-RRT, ``OMPLPlanner``);
    ``time_limit``: seconds for the whole query (``None``: the fallback's own limits). The
    fallback gets what the policy left of it, through its ``time_limit`` attribute."""

    name = "hybrid"

    def __init__(self, policy: PolicyPlanner, fallback: Any, time_limit: float | None = None) -> None:
        if policy.robot.name != fallback.robot.name:
            raise ValueError("the policy and the fallback plan for different robots")
        if time_limit is not None and not time_limit > 0:
            raise ValueError(f"time_limit must be positive seconds or None, not {time_limit}")
        self.policy = policy
        self.fallback = fallback
        self.time_limit = time_limit
        self.robot: Robot = policy.robot

    @property
    def birrt(self) -> Any:
        """The fallback planner (named for the default one)."""
        return self.fallback

    def __repr__(self) -> str:
        return f"HybridPlanner(stall_steps={self.policy.stall_steps}, horizon={self.policy.horizon}, fallback={self.fallback!r}, time_limit={self.time_limit})"

    def plan(self, problem: Problem) -> PlanResult:
        """The policy's rollout; where it does not reach the goal, the fallback planner from
        the pose of that rollout closest to the goal (the path kept up to there), within what
        is left of the query's time limit."""
        t0 = time.perf_counter()
        first = self.policy.plan(problem)
        end = first.info.get("end")
        info = {"policy_steps": first.nodes, "policy_end": end, "birrt_nodes": 0, "repaired": False}
        if end == "goal":
            first.info.update(info)
            first.time_s = time.perf_counter() - t0
            return first
        robot, path = self.robot, first.path
        if end == "near-goal":
            cut = len(path) - 1
        else:
            d = robot.distance(path, problem.goal[None])
            cut = int(np.flatnonzero(d <= d.min())[-1])  # the last of the closest ones
        sub = Problem(problem.scene, path[cut].copy(), problem.goal, tag=f"{problem.tag}/repair")
        if self.time_limit is not None:  # what the policy left of the query's budget, less the
            # time a search takes to stop and return (its last iteration, its trees)
            left = self.time_limit - (time.perf_counter() - t0)
            self.fallback.time_limit = max(left - min(_WRAP_UP, 0.01 * self.time_limit), 1e-3)
        second = self.fallback.plan(sub)
        nodes = first.nodes + second.nodes
        checks = first.collision_checks + second.collision_checks
        info.update(
            birrt_nodes=second.nodes,
            repaired=True,
            repaired_from=cut,
            fallback=getattr(self.fallback, "name", type(self.fallback).__name__),
        )
        dt = time.perf_counter() - t0
        if not second.success:
            return PlanResult.failure(robot.config_dim, nodes, checks, dt, info=info)
        full = np.concatenate([path[:cut], second.path])  # second.path starts at path[cut]
        return PlanResult(
            path=full, success=True, nodes=nodes, collision_checks=checks, time_s=dt, trees=second.trees, info=info
        )


__all__ = ["HybridPlanner"]
