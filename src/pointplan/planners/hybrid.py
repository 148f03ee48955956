"""The policy first, Bi-RRT where it fails.

``HybridPlanner`` rolls the policy out (batch 1, :class:`~pointplan.planners.policy.PolicyPlanner`)
and keeps its path when it ends at the goal. Otherwise, when the horizon ends, when the
policy stalls (its last ``stall_steps`` steps took it less than ``stall_distance`` from
where it was: 10 steps and 0.035 by default), or when the last connection to the goal is
blocked, Bi-RRT plans from the last
good configuration of the rollout to the goal, and the two pieces make one path:

- after a stall or the horizon, the last good configuration is the one closest to the
  goal (the dithering after it is dropped from the path, not from the node count);
- after a blocked connection, it is the policy's last configuration (within the goal
  tolerance).

Every configuration of the rollout is collision-free (the environment's motion check stops
a move before it collides), so the joined path is free wherever its pieces are; the
evaluator checks it like every path. ``nodes`` = policy steps + Bi-RRT nodes,
``collision_checks`` = both planners' checks. ``info`` says what happened
(``policy_steps``, ``birrt_nodes``, ``policy_end``, ``repaired``).
"""

from __future__ import annotations

import time

import numpy as np

from ..robots.base import Robot
from ..scenes.scene import Problem
from .base import PlanResult
from .birrt import BiRRT
from .policy import PolicyPlanner


class HybridPlanner:
    """The policy, repaired by Bi-RRT where it fails or stalls."""

    name = "hybrid"

    def __init__(self, policy: PolicyPlanner, birrt: BiRRT) -> None:
        if policy.robot.name != birrt.robot.name:
            raise ValueError("the policy and Bi-RRT plan for different robots")
        self.policy = policy
        self.birrt = birrt
        self.robot: Robot = policy.robot

    def __repr__(self) -> str:
        return f"HybridPlanner(stall_steps={self.policy.stall_steps}, horizon={self.policy.horizon}, birrt={self.birrt!r})"

    def plan(self, problem: Problem) -> PlanResult:
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
        second = self.birrt.plan(sub)
        nodes = first.nodes + second.nodes
        checks = first.collision_checks + second.collision_checks
        info.update(birrt_nodes=second.nodes, repaired=True, repaired_from=cut)
        dt = time.perf_counter() - t0
        if not second.success:
            return PlanResult.failure(robot.config_dim, nodes, checks, dt, info=info)
        full = np.concatenate([path[:cut], second.path])  # second.path starts at path[cut]
        return PlanResult(path=full, success=True, nodes=nodes, collision_checks=checks, time_s=dt, trees=second.trees, info=info)


__all__ = ["HybridPlanner"]
