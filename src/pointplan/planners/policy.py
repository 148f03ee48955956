"""A learned policy as a planner: roll it out, one node per step.

``rollout_batch`` plays many problems at once through the batched environment core
(deterministic actions); ``PolicyPlanner`` wraps a trained :class:`~pointplan.models.policy.Policy`
behind the :class:`Planner` protocol. Nodes are policy steps; collision checks are the
sub-configurations ``q_free`` checked, plus those of the final connection to the goal.

``PolicyPlanner.plan`` (one problem, as a user calls it) does not go through the batched
core: it steps one robot with the environment's own pieces (the observer's draws, the
policy, ``q_free``), with the network in numpy when it is a PointNet
(:class:`~pointplan.models.policy.NumpyPointNetActor`) and otherwise PyTorch on one thread.
Its rollouts are those of ``rollout_batch`` with one problem. For a ball (disc, sphere)
among boxes the whole rollout is one compiled call (:mod:`._policy_kernels`, same
arithmetic; ``compiled=False`` keeps the Python path). With ``greedy_goal`` (the default)
``plan`` stops at the first configuration from which the straight edge to the goal is
certified free, and ends the path at the goal (``info["greedy_goal"]``), whatever the
observer, in static scenes (among moving obstacles it is off).

The environment stops a rollout anywhere within ``goal_tolerance`` of the goal. The
planner then tries the last step to the goal itself (the geodesic from the policy's last
configuration, checked like a Bi-RRT edge): when it is free the path ends at the goal
(``info["end"] == "goal"``), otherwise where the policy stopped (``"near-goal"``). A
rollout that does not get there ends with ``"horizon"`` (or ``"stalled"``, ``"crushed"``).
"""

from __future__ import annotations

import contextlib
import time
import zlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..envs.core import BatchedCore, EnvConfig, q_free
from ..geometry.shapes import Box
from ..observers.base import PointSetObserver
from ..robots.base import Robot
from ..robots.point import Disc2D, Sphere3D
from ..scenes.scenarios import Scenario
from ..scenes.scene import Problem, Scene
from .base import PlanResult
from .edges import edge_free

ActFn = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
_F64 = np.dtype(np.float64)


class _GivenProblems(Scenario):
    """A scenario that only plays the problems it is handed."""

    name = "given"

    def __init__(self, robot: Robot, horizon: int) -> None:
        self.robot = robot
        self.horizon = horizon

    def scene(self, split: str, index: int) -> Scene:
        raise RuntimeError("rollouts play given problems only")


def _free_move_end(robot: Robot, q: np.ndarray, twist: np.ndarray, low: np.ndarray, high: np.ndarray, clip_target: bool) -> np.ndarray:
    """Where ``q_free`` ends a move that nothing stops: ``q exp(twist)``, or with
    ``clip_target`` that end clipped into the bounds (reached along ``log(q, clipped)``)."""
    if isinstance(robot, (Disc2D, Sphere3D)):  # a translating ball: the same arithmetic, fewer calls
        end1 = q + twist
        if clip_target:
            clipped1 = np.clip(end1, low, high)
            if (clipped1 != end1).any():
                return q + (clipped1 - q)
        return end1
    end = robot.integrate(q[None], twist[None])
    if clip_target:
        clipped = robot.clip(end, low, high)
        if np.any(clipped != end):
            end = robot.integrate(q[None], robot.log(q[None], clipped))
    return end[0]


def connect_to_goal(robot: Robot, problem: Problem, result: PlanResult, resolution: float = 0.01, t: int | None = None) -> PlanResult:
    """End a successful rollout at the goal itself when the geodesic from its last
    configuration to the goal is free (checked like a Bi-RRT edge, at ``resolution``; in a
    scene whose obstacles move, against the obstacles at time ``t``, the step the
    connection would take). The checks are added to ``collision_checks``; the goal is not a
    node. Sets ``info["end"]`` (``goal``, ``near-goal``, or ``horizon`` for a failure that
    does not already say why) and ``info["goal_connection"]``."""
    t0 = time.perf_counter()
    info = result.info
    if not result.success or len(result.path) == 0:
        info.setdefault("end", "horizon")
        info["goal_connection"] = None
        return result
    last = result.path[-1]
    if float(robot.distance(last, problem.goal)) <= 0.0:
        info["end"], info["goal_connection"] = "goal", "free"
        return result
    scene = problem.scene
    world = scene.world_at(len(result.path) if t is None else t) if scene.dynamic else scene.world
    ok, checks = edge_free(robot, world, last, problem.goal, resolution, scene.low, scene.high)
    result.collision_checks += checks
    if ok:
        result.path = np.concatenate([result.path, np.asarray(problem.goal, np.float64)[None]])
    info["end"] = "goal" if ok else "near-goal"
    info["goal_connection"] = "free" if ok else "blocked"
    result.time_s += time.perf_counter() - t0
    return result


@contextlib.contextmanager
def torch_threads(n: int) -> Iterator[None]:
    """Run PyTorch on ``n`` threads inside the block (batch-1 inference on more threads
    only oversubscribes the cores), and restore the previous count after."""
    try:
        import torch
    except ImportError:  # pragma: no cover
        yield
        return
    before = torch.get_num_threads()
    if before != n:
        torch.set_num_threads(n)
    try:
        yield
    finally:
        if before != n:
            torch.set_num_threads(before)


def rollout_batch(
    act: ActFn,
    robot: Robot,
    env: EnvConfig,
    problems: Sequence[Problem],
    horizon: int,
    seed: int = 0,
    chunk: int = 100,
    connect_goal: bool = False,
    greedy_goal: bool = False,
    escape: Escape | None = None,
    noise: float = 0.0,
    noise_rng: np.random.Generator | None = None,
    crush_ends: bool = True,
) -> list[PlanResult]:
    """Roll ``act(obs, q, goal) -> actions`` out on every problem, ``chunk`` at a time.
    The time of a chunk is shared equally by its problems. With ``connect_goal`` each
    successful path ends at the goal when it can (:func:`connect_to_goal`). With
    ``greedy_goal`` (static scenes only) a problem stops at the first configuration, the
    start included, from which the straight edge to the goal is certified free
    (:func:`~pointplan.planners.edges.edge_free`, counted in its collision checks), and
    its path ends at the goal, as ``PolicyPlanner.plan`` does for point-set observers.

    ``noise > 0`` samples every action, ``act(obs, q, goal, noise=s * N(0, 1))`` with
    ``s = noise``; an ``escape`` (:class:`Escape`) samples the next ``escape.steps``
    actions of a problem with ``s = escape.noise`` wherever its robot ended a step less
    than ``escape.still`` from where it was ``escape.window`` steps before. Both need an ``act`` that takes ``noise`` (a
    :class:`~pointplan.models.policy.Policy` does) and draw from ``noise_rng`` (default:
    seeded by ``seed`` and the chunk).

    ``crush_ends=False`` is for comparisons only: a moving obstacle that runs into the
    robot no longer ends its rollout (the robot stays where it is until it can move
    again), so a success may have touched an obstacle; ``info["crushed"]`` counts the
    steps it was hit. The planner never plans so."""
    if greedy_goal and any(p.scene.dynamic for p in problems):
        raise ValueError("greedy_goal connects to the goal in static scenes only")
    escaping_on = escape is not None and escape.steps > 0
    sampled = escaping_on or noise > 0
    results: list[PlanResult] = []
    env = replace(env, horizon=horizon)
    for c0 in range(0, len(problems), chunk):
        probs = list(problems[c0 : c0 + chunk])
        n = len(probs)
        t0 = time.perf_counter()
        rng = np.random.default_rng(np.random.SeedSequence([seed, c0]))
        core = BatchedCore(_GivenProblems(robot, horizon), n, env)
        core.reset_envs(range(n), rng, probs)
        paths = np.zeros((horizon + 1, n, robot.config_dim))
        paths[0] = core.q
        length = np.ones(n, np.int64)
        checks = np.zeros(n, np.int64)
        active = np.ones(n, bool)
        success = np.zeros(n, bool)
        crushed = np.zeros(n, bool)
        hits = np.zeros(n, np.int64)
        at_goal = np.zeros(n, bool)
        nrng = noise_rng if noise_rng is not None else np.random.default_rng(np.random.SeedSequence([seed, c0, 0x6E6F6973]))
        left = np.zeros(n, np.int64)  # sampled steps of an escape still to come, per problem
        escapes = np.zeros(n, np.int64)
        subgoals = core.goal.copy()  # where an escape toward a subgoal heads, per problem
        toward_subgoal = escaping_on and escape is not None and escape.subgoal

        def try_goal(which: np.ndarray) -> None:
            for i in np.flatnonzero(which):
                sc = probs[i].scene
                ok, c = edge_free(robot, sc.world, core.q[i], probs[i].goal, 0.01, sc.low, sc.high)
                checks[i] += c
                if ok:
                    at_goal[i], success[i], active[i] = True, True, False

        for t in range(horizon):
            if greedy_goal:
                try_goal(active)
                if not active.any():
                    break
            obs = core.observe(rng)["observation"]  # (at each problem's own time step)
            if sampled:
                esc = left > 0
                scale = np.where(esc, escape.noise if escape is not None else 0.0, noise)
                draw = nrng.standard_normal((n, len(robot.action_scale)))
                goal_in = np.where(esc[:, None], subgoals, core.goal) if toward_subgoal else core.goal.copy()
                a = np.asarray(act(obs, core.q.copy(), goal_in, noise=scale[:, None] * draw), np.float32)  # type: ignore[call-arg]
                left[esc] -= 1
            else:
                a = np.asarray(act(obs, core.q.copy(), core.goal.copy()), np.float32)
            a[~active] = 0.0  # finished problems stand still
            _, term, _, info = core.step(a)
            paths[t + 1] = core.q
            if escape is not None and escaping_on and t + 1 >= escape.window:
                going_on = active & ~term & ~(info["crushed"] & crush_ends)  # not ended by this step
                stuck = going_on & (left == 0) & (np.asarray(robot.distance(core.q, paths[t + 1 - escape.window])) < escape.still)
                left[stuck] = escape.steps
                escapes += stuck
                if toward_subgoal:
                    for j in np.flatnonzero(stuck).tolist():
                        subgoals[j] = robot.sample_uniform(nrng, 1, probs[j].scene.low, probs[j].scene.high)[0]
            length += active
            checks += np.where(active, info["collision_checks"], 0)
            success |= term & active
            crushed |= info["crushed"] & active
            hits += info["crushed"] & active
            active &= ~(term | (info["crushed"] & crush_ends))  # a moving obstacle that hits the robot ends it
            if not active.any():
                break
        if greedy_goal:  # where the rollouts that did not arrive stopped
            try_goal(~success)
        dt = (time.perf_counter() - t0) / n
        for i in range(n):
            k = int(length[i])
            if at_goal[i]:
                path = np.concatenate([paths[:k, i], np.asarray(probs[i].goal, np.float64)[None]])
                res = PlanResult(path=path, success=True, nodes=k - 1, collision_checks=int(checks[i]), time_s=dt)
                res.info.update({"end": "goal", "goal_connection": "free", "greedy_goal": True})
                if escaping_on:
                    res.info["escapes"] = int(escapes[i])
                if not crush_ends:
                    res.info["crushed"] = int(hits[i])
                results.append(res)
                continue
            res = PlanResult(path=paths[:k, i].copy(), success=bool(success[i]), nodes=k - 1, collision_checks=int(checks[i]), time_s=dt)
            if crushed[i] and crush_ends:
                res.info["end"] = "crushed"
            if not crush_ends:
                res.info["crushed"] = int(hits[i])
            if escaping_on:
                res.info["escapes"] = int(escapes[i])
            if connect_goal:
                res = connect_to_goal(robot, probs[i], res, t=k)
            results.append(res)
    return results


@dataclass(frozen=True)
class Escape:
    """Noise switched on where a rollout is stuck: after a step that left the robot less
    than ``still`` (geodesic distance) from where it was ``window`` steps before, the next
    ``steps`` actions are sampled as ``tanh(mean + noise * std * N(0, 1))``, then the mean
    action again (``steps = 0``: off). The cloned S-shape policies mostly fail by pressing
    against an obstacle with the same mean action until the horizon (``window = 1``: one
    step that did not move); the sphere's by dithering back and forth in one place, which
    a longer window sees. A few sampled steps free them within the one rollout
    (``docs/learning.md``, "Escaping a stall").

    ``subgoal``: during an escape the policy is steered toward a configuration drawn
    uniformly in the scene's bounds instead of the goal (with ``noise = 0``, its mean
    action toward it): a goal-conditioned policy walks off in a random direction while
    avoiding obstacles, where noise alone jitters about the trap (randomised escape from
    a local minimum, as in potential-field planners)."""

    steps: int = 10
    noise: float = 2.0
    still: float = 0.01
    window: int = 1
    subgoal: bool = False

    def __post_init__(self) -> None:
        if int(self.steps) != self.steps or self.steps < 0:
            raise ValueError(f"escape steps must be an integer >= 0, not {self.steps}")
        if not np.isfinite(self.noise) or self.noise < 0:
            raise ValueError(f"escape noise must be a finite number >= 0, not {self.noise}")
        if not np.isfinite(self.still) or self.still < 0:
            raise ValueError(f"escape still must be a finite number >= 0, not {self.still}")
        if int(self.window) != self.window or self.window < 1:
            raise ValueError(f"escape window must be an integer >= 1, not {self.window}")
        object.__setattr__(self, "steps", int(self.steps))  # 6.0 -> 6: they index paths
        object.__setattr__(self, "window", int(self.window))


#: the escape a robot's policies plan with when none is given, chosen on validation
#: problems (``scripts/stall_escape.py``; docs/learning.md, "Escaping a stall"): the
#: S-shape presses against an obstacle, so one still step starts ten sampled ones; the
#: sphere dithers in one place, so six steps that end within 0.1 of where they started
#: start ten toward a random subgoal. Robots not named here plan without.
ESCAPE_DEFAULTS: dict[str, Escape] = {
    "sshape": Escape(steps=10, noise=2.0, still=0.01),
    "sphere3d": Escape(steps=10, noise=0.0, still=0.1, window=6, subgoal=True),
}


#: ``info["end"]`` of the compiled rollout's end codes (``_policy_kernels.END_*``)
_END_NAMES = ("horizon", "stalled", "goal", "goal", "near-goal", "near-goal", "escape")
#: the end code of a compiled rollout that stopped where an escape starts (``END_ESCAPE``)
_K_END_ESCAPE = _END_NAMES.index("escape")


class _GoalTester:
    """Is the straight edge from a configuration to the goal free? The certified answer is
    :func:`~pointplan.planners.edges.edge_free` at resolution 0.01 (the check of
    :func:`connect_to_goal`). For a translating ball among boxes a quick test comes first:
    the plain ball (a hair smaller) at the samples of the edge; if it overlaps a box the
    edge is certainly not free, and the certified check is skipped (it would say the
    same: a certified edge has no configuration touching an obstacle).
    ``tests/test_policy_kernels.py`` checks that implication."""

    def __init__(self, robot: Robot, scene: Scene, goal: np.ndarray, resolution: float = 0.01) -> None:
        self.robot, self.scene, self.goal, self.resolution = robot, scene, goal, resolution
        world = scene.world
        self.boxes: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        if isinstance(robot, (Disc2D, Sphere3D)) and world.batch_shape == () and all(type(o) is Box for o in scene.obstacles):
            if world.box_c.shape[0] == len(scene.obstacles):
                f = np.ascontiguousarray
                self.boxes = (f(world.box_c, np.float64), f(world.box_r, np.float64), f(world.box_h, np.float64))
        self.radius = float(getattr(robot, "radius", 0.0)) * (1.0 - 1e-9)

    def free(self, q: np.ndarray, certify: bool) -> tuple[bool, int]:
        """``(answer, configurations checked)``: with ``certify`` the certified answer;
        without, ``False`` only where the quick test rules the edge out (otherwise
        ``True``: maybe free)."""
        checks = 0
        if self.boxes is not None:
            from ._policy_kernels import ball_segment_hits_boxes_count

            hit, checks = ball_segment_hits_boxes_count(q, self.goal, self.radius, self.resolution, *self.boxes)
            if hit:
                return False, checks
        if not certify:
            return True, checks
        ok, n = edge_free(self.robot, self.scene.world, q, self.goal, self.resolution, self.scene.low, self.scene.high)
        return ok, checks + n


@dataclass
class _Rollout:
    """One robot's rollout in :meth:`PolicyPlanner._rollout_one`: where it is, its path
    and counters, and the time spent observing, in the network and checking motions."""

    q: np.ndarray
    path: list[np.ndarray]
    t: int = 0
    checks: int = 0
    success: bool = False
    end: str = "horizon"
    t_obs: float = 0.0
    t_net: float = 0.0
    t_motion: float = 0.0
    t_goal: float = 0.0
    #: the certified edge from ``q`` to the goal was found free (greedy goal connection)
    at_goal: bool = False
    #: sampled steps of an escape (:class:`Escape`) still to come, and escapes so far
    escape_left: int = 0
    escapes: int = 0
    #: where the current escape heads (``Escape.subgoal``; ``None``: the goal)
    subgoal: np.ndarray | None = None


class PolicyPlanner:
    """Plan by rolling out a trained policy (deterministic mean actions).

    ``stall_steps``, ``stall_distance``: stop a rollout early when the robot's last
    ``stall_steps`` steps took it less than ``stall_distance`` from where it was (it
    dithers in place; ``info["end"] == "stalled"``). Off by default; the hybrid planner
    uses 10 steps and half a step (0.035), under which none of 1,000 validation rollouts of
    the shipped policy that succeed would have stopped. ``connect_goal``: end successful
    paths at the goal when the last edge is free (default). ``info["time_split"]`` of a
    ``plan`` result has the seconds spent observing, in the network and in motion checks.

    ``observer_wrapper``: a function ``observer -> observer`` applied to the observer of
    ``plan`` (e.g. :func:`pointplan.observers.perturb.perturbation`: noisy, dropped or
    occluded points, farthest-point subsets); static scenes only. ``draws``: the action at
    each step is the mean of the actions for ``draws`` independent random point subsets
    (``draws`` network passes per step; 1, the default, is the plain policy).

    ``attempts``: when the mean-action rollout fails, roll out again from the start up to
    ``attempts - 1`` more times with sampled actions ``tanh(mean + action_noise * std *
    noise)`` (the policy's own spread at ``action_noise = 1``), and return the first
    success. The steps, motion checks and time of all attempts are counted in the result
    (``info["attempts"]``: how many ran); a failure returns the attempt that ended
    closest to the goal. The draws are seeded by ``seed``, the attempt and the problem's
    start and goal, so a problem gets the same attempts in any order. Static scenes only
    (a rollout in a moving scene cannot start over).

    ``escape`` (an :class:`Escape`, or its number of steps with the rest of the robot's
    default): where the robot is stuck, take the next few actions from a wider spread or
    toward a random subgoal, then go back to the mean action toward the goal; within the
    one rollout, so in moving scenes too (``info["escapes"]``: how many times). ``None``:
    the robot's default (:data:`ESCAPE_DEFAULTS`: the S-shape, whose cloned policies pin
    themselves against obstacles, samples wider; the sphere, whose policies dither in one
    place, heads for a subgoal; off for the disc, where validation showed no change).
    With an escape the compiled rollout runs up to where the first escape starts and the
    numpy one-robot rollout goes on from there (the same steps as the numpy rollout from
    the start: no escape has drawn anything before).

    A PointNet actor is copied to numpy when the planner is made (later changes to the
    policy's weights are not seen; make a new planner). Scenes with moving obstacles and
    image observations go through ``rollout_batch`` (PyTorch on one thread), which runs to
    the horizon: no stall test there.
    """

    name = "policy"

    def __init__(
        self,
        policy: object,
        robot: Robot | None = None,
        horizon: int | None = None,
        env: EnvConfig | None = None,
        stall_steps: int | None = None,
        stall_distance: float = 0.035,
        connect_goal: bool = True,
        seed: int = 0,
        observer_wrapper: Callable[[Any], Any] | None = None,
        draws: int = 1,
        greedy_goal: bool = True,
        compiled: bool = True,
        attempts: int = 1,
        action_noise: float = 1.0,
        escape: Escape | int | None = None,
    ) -> None:
        from ..models.policy import Policy

        if isinstance(policy, (str, Path)):
            policy = Policy.from_checkpoint(policy)
        assert isinstance(policy, Policy)
        self.policy = policy
        self.robot = robot or policy.robot
        if self.robot.name != policy.robot.name:
            raise ValueError(f"the policy was trained for robot {policy.robot.name!r}, not {self.robot.name!r}")
        self.env = env or EnvConfig(observation=policy.observation, n_points=policy.n_points)
        if self.env.observation != policy.observation:
            raise ValueError(f"the policy was trained on {policy.observation!r} observations, not {self.env.observation!r}")
        self.horizon = int(horizon or policy.meta.get("horizon") or 50)
        self.stall_steps = None if stall_steps is None else int(stall_steps)
        self.stall_distance = float(stall_distance)
        self.connect_goal = bool(connect_goal)
        self.seed = int(seed)
        self.observer_wrapper = observer_wrapper
        self.draws = max(1, int(draws))
        self.greedy_goal = bool(greedy_goal)
        self.compiled = bool(compiled)
        if int(attempts) < 1:
            raise ValueError(f"attempts must be >= 1, not {attempts}")
        if not np.isfinite(action_noise) or action_noise < 0:
            raise ValueError(f"action_noise must be a finite number >= 0, not {action_noise}")
        self.attempts = int(attempts)
        self.action_noise = float(action_noise)
        if escape is None:
            escape = ESCAPE_DEFAULTS.get(self.robot.name, Escape(steps=0))
        elif not isinstance(escape, Escape):  # a number of steps: the robot's own kind of escape
            escape = replace(ESCAPE_DEFAULTS.get(self.robot.name, Escape()), steps=escape)
        self.escape: Escape = escape
        #: the draws of the escapes of the rollout being planned (seeded per problem)
        self._escape_rng: np.random.Generator | None = None
        #: the action noise of the attempt being rolled out (None: the mean action)
        self._noise_rng: np.random.Generator | None = None
        #: the network as numpy arrays (weights as of now), or None: PyTorch on one thread
        self.fast = policy.fast_actor()
        self._net: tuple[Any, ...] | None = self._kernel_weights() if self.compiled else None
        self._observer: Any = None
        #: the compiled rollout's planner arguments (weights, scale, parameters), set with
        #: the observer when the compiled rollout applies to it; else None
        self._kernel_args: tuple[Any, ...] | None = None
        #: the compiled rollout's scene arguments of the last scene planned in (a scene is
        #: usually planned in many times; ``None``: the compiled rollout does not apply)
        self._kernel_scene: Scene | None = None
        self._kernel_scene_args: tuple[np.ndarray, ...] | None = None
        self._kernel: Callable[..., tuple[int, int, int, int]] | None = None
        self._end_entries = self._end_table()
        self._path_shape = (self.horizon + 2, self.robot.config_dim)  # the compiled rollout's path buffer
        self._stream_rng: np.random.Generator | None = None
        self._stream = np.empty(0)

    def plan(self, problem: Problem) -> PlanResult:
        if self.attempts > 1 and problem.scene.dynamic:
            raise ValueError("attempts > 1 plans static scenes only: a rollout among moving obstacles cannot start over")
        key = zlib.crc32(np.ascontiguousarray(problem.start, np.float64).tobytes() + np.ascontiguousarray(problem.goal, np.float64).tobytes())
        try:
            self._escape_rng = np.random.default_rng(np.random.SeedSequence([self.seed, 0, key, 0x657363]))
            res = self._plan_mean(problem)
        finally:
            self._escape_rng = None
        if res.success or self.attempts == 1:
            return res
        tried = [res]
        try:
            for k in range(1, self.attempts):
                self._noise_rng = np.random.default_rng(np.random.SeedSequence([self.seed, k, key]))
                self._escape_rng = self._noise_rng
                tried.append(self._plan_sampled(problem))
                if tried[-1].success:
                    break
        finally:
            self._noise_rng = None
            self._escape_rng = None
        last = tried[-1]
        pick = last if last.success else min(tried, key=lambda r: float(self.robot.distance(r.path[-1], problem.goal)))
        out = PlanResult(
            path=pick.path,
            success=pick.success,
            nodes=sum(r.nodes for r in tried),
            collision_checks=sum(r.collision_checks for r in tried),
            time_s=sum(r.time_s for r in tried),
        )
        out.info.update(pick.info)
        out.info["attempts"] = len(tried)
        out.info["attempt_steps"] = [int(r.nodes) for r in tried]
        return out

    def _plan_sampled(self, problem: Problem) -> PlanResult:
        """One rollout with sampled actions (``self._noise_rng`` set)."""
        if self._observer is None:
            self._make_observer()
        if isinstance(self._observer, PointSetObserver) and type(self._observer).observe is PointSetObserver.observe:
            return self._rollout_one(problem)
        rng = self._noise_rng
        assert rng is not None
        with torch_threads(1):
            greedy = self.greedy_goal and not problem.scene.dynamic
            return rollout_batch(
                self.policy,
                self.robot,
                self.env,
                [problem],
                self.horizon,
                self.seed,
                connect_goal=self.connect_goal,
                greedy_goal=greedy,
                escape=self.escape,
                noise=self.action_noise,
                noise_rng=rng,
            )[0]

    def _plan_mean(self, problem: Problem) -> PlanResult:
        """The mean-action rollout."""
        if problem.scene.dynamic:
            if self.observer_wrapper is not None or self.draws > 1:
                raise ValueError("observer_wrapper and draws > 1 plan static scenes only")
            return self._plan_batched(problem)
        if self._observer is None:
            self._make_observer()
        if self._kernel_args is not None:
            res = self._rollout_compiled(problem)
            if res is not None:
                return res
        if not isinstance(self._observer, PointSetObserver) or type(self._observer).observe is not PointSetObserver.observe:
            return self._plan_batched(problem)
        return self._rollout_one(problem)

    def _make_observer(self) -> None:
        """The observer of ``plan`` (the environment's, wrapped with ``observer_wrapper``)
        and, when the compiled rollout applies (one draw per step of the plain point
        observer, the network in numpy, a ball robot), its planner arguments."""
        from . import _policy_kernels as K

        probe = BatchedCore(_GivenProblems(self.robot, self.horizon), 1, replace(self.env, horizon=self.horizon))
        observer = probe.observer if self.observer_wrapper is None else self.observer_wrapper(probe.observer)
        self._observer = observer
        plain = (
            isinstance(observer, PointSetObserver)
            and type(observer).observe is PointSetObserver.observe
            and type(observer).observe_one is PointSetObserver.observe_one
        )
        if self._net is not None and self.draws == 1 and self.observer_wrapper is None and plain:
            (wflat, layout), scale, fparams, iparams = self._net
            iparams[K.I_N_POINTS] = self._observer.n_points  # the observer's (the env may leave it to the observer)
            self._kernel_args = (wflat, layout, scale, fparams, iparams)
            self._kernel = K._rollout

    def _plan_batched(self, problem: Problem) -> PlanResult:
        """The rollout through the batched core (observers without the one-robot path, such
        as the ray-cast one, and moving scenes; the greedy goal connection in static
        scenes only: among moving obstacles an edge free now may not be free later)."""
        greedy = self.greedy_goal and not problem.scene.dynamic
        with torch_threads(1):
            res = rollout_batch(
                self.policy,
                self.robot,
                self.env,
                [problem],
                self.horizon,
                self.seed,
                connect_goal=self.connect_goal,
                greedy_goal=greedy,
                escape=self.escape,
                noise_rng=self._escape_rng,
            )[0]
        return res

    def _act(self, obs: np.ndarray, q: np.ndarray, goal: np.ndarray, escaping: bool = False) -> np.ndarray:
        from ..models.inputs import goal_input, obs_input

        noise = None
        if escaping:
            assert self._escape_rng is not None
            noise = self.escape.noise * self._escape_rng.standard_normal(self.policy.actor.action_dim)
        elif self._noise_rng is not None:
            noise = self.action_noise * self._noise_rng.standard_normal(self.policy.actor.action_dim)
        if self.fast is not None:
            return self.fast(obs_input(self.robot, obs[None])[0], goal_input(self.robot, q, goal), noise)
        return self.policy(obs[None], q[None], goal[None], None if noise is None else noise[None])[0]

    def _uniforms(self, k: int) -> np.ndarray:
        """The first ``k`` numbers of the stream ``rollout_batch`` draws its observations
        from (seed ``(seed, 0)``): the same for every problem, so drawn once and kept."""
        if self._stream_rng is None:
            self._stream_rng = np.random.default_rng(np.random.SeedSequence([self.seed, 0]))
            self._stream = np.empty(0)
        if len(self._stream) < k:
            more = max(k - len(self._stream), 8192)
            self._stream = np.concatenate([self._stream, self._stream_rng.random(more)])
        return self._stream

    def _fold(self) -> tuple[np.ndarray, np.ndarray, np.float32, int] | None:
        """For a robot that only translates, seeing points, with the numpy network: the
        per-scene table of the input layer's pre-activations (``points / scale @ W +
        normals @ W + b``), the rows of ``W`` that multiply the position, the scale as
        float32 and the number of points; ``None`` otherwise."""
        robot, observer, fast = self.robot, self._observer, self.fast
        if fast is None or not isinstance(robot, (Disc2D, Sphere3D)) or type(observer).observe_one is not PointSetObserver.observe_one:
            return None
        pts, nrm = observer.points_one()
        count = len(pts)
        if count == 0:
            return None
        w, b = fast.inp
        x = (pts / robot.action_scale[0]).astype(np.float32)
        if observer.with_normals:
            x = np.concatenate([x, nrm.astype(np.float32)], 1)
        table = x @ w + b  # (count, width)
        return table, np.ascontiguousarray(w[: robot.dim]), np.float32(robot.action_scale[0]), count

    def _lean_step(
        self, fold: tuple[np.ndarray, np.ndarray, np.float32, int] | None = None
    ) -> Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None:
        """For a robot that only translates, seeing points, with the numpy network:
        ``(q, goal, u) -> action`` for the observation ``observe_one(q, u=u)``, without
        building the observation. The body frame is a translation, so the input layer's
        pre-activations are a per-scene table (:meth:`_fold`) minus one row
        (``q / scale @ W``), gathered for the drawn points: the same arithmetic up to
        float32 round-off (about 1e-7). ``None`` otherwise, and while actions are sampled
        (an attempt after the first: they go through :meth:`_act`)."""
        if self._noise_rng is not None:
            return None
        fold = fold or self._fold()
        if fold is None:
            return None
        fast, robot, n = self.fast, self.robot, self._observer.n_points
        assert fast is not None
        table, w_pos, s32, count = fold
        m = max(count, 1)
        scale = robot.action_scale

        def step(q: np.ndarray, goal: np.ndarray, u: np.ndarray) -> np.ndarray:
            idx = np.argsort(u[:m])[:n]
            if count < n:
                idx = np.concatenate([idx, (u[m + count : m + n] * count).astype(np.int64)])
            h = table[idx]
            h -= (q / s32).astype(np.float32) @ w_pos
            return fast.from_first_layer(h, ((goal - q) / scale).astype(np.float32))

        return step

    def _kernel_weights(self) -> tuple[Any, ...] | None:
        """What :func:`~._policy_kernels.rollout_ball` needs of the planner (the packed
        weights, the action scale, the float and int parameters), or ``None`` when the
        compiled rollout does not apply (not a ball, not a PointNet in numpy, hidden
        layers of another width)."""
        from . import _policy_kernels as K

        fast, robot, env = self.fast, self.robot, self.env
        if fast is None or not isinstance(robot, (Disc2D, Sphere3D)):
            return None
        width = fast.inp[0].shape[1]
        if any(w.shape != (width, width) for w, _ in fast.hidden) or fast.head[0][0].shape[0] != width + robot.dim:
            return None
        escaping = self.escape.steps > 0
        fparams = np.zeros(7)
        fparams[[K.F_RADIUS, K.F_SUBSTEP, K.F_GOAL_TOL, K.F_STALL_DIST, K.F_RESOLUTION, K.F_S32, K.F_ESC_STILL]] = (
            robot.radius,
            env.substep,
            env.goal_tolerance,
            self.stall_distance,
            0.01,  # the goal edge: as connect_to_goal checks it
            float(np.float32(robot.action_scale[0])),
            self.escape.still if escaping else 0.0,
        )
        iparams = np.zeros(8, np.int64)
        iparams[[K.I_HORIZON, K.I_STALL_STEPS, K.I_GREEDY, K.I_CONNECT, K.I_CLIP, K.I_N_POINTS, K.I_ACTION_DIM, K.I_ESC_WINDOW]] = [
            int(self.horizon),
            int(self.stall_steps or 0),
            int(self.greedy_goal),
            int(self.connect_goal),
            int(env.bounds == "clip"),
            int(env.n_points or 0),
            int(fast.action_dim),
            int(self.escape.window) if escaping else 0,  # the compiled rollout stops where an escape starts
        ]
        return K.pack_weights(fast.inp, fast.hidden, fast.head), np.ascontiguousarray(robot.action_scale, np.float64), fparams, iparams

    def _scene_inputs(self, scene: Scene) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray]] | None:
        """For the compiled rollout: the observer's points of the scene (the observer must be
        bound to it), their normals (``(count, 0)`` without) and the scene's boxes; ``None``
        when the scene has obstacles other than boxes or no points."""
        world = scene.world
        obstacles = scene.obstacles
        if world.batch_shape != () or world.box_c.shape[0] != len(obstacles) or not all(type(o) is Box for o in obstacles):
            return None
        pts, nrm = self._observer.points_one()
        if not len(pts):
            return None
        f = np.ascontiguousarray
        nrm = f(nrm, np.float64) if self._observer.with_normals else np.zeros((len(pts), 0))
        return f(pts, np.float64), nrm, (f(world.box_c, np.float64), f(world.box_r, np.float64), f(world.box_h, np.float64))

    def _rollout_compiled(self, problem: Problem) -> PlanResult | None:
        """``_rollout_one`` in one compiled call (:func:`~._policy_kernels._rollout`) for a
        ball among boxes; ``None`` when the scene is not boxes only (or has no points).

        Most of a call's time beyond the network is not arithmetic but memory: a caller
        does other work between plans, and every Python and numpy operation here then
        waits for code and data the call has not touched for a while (measured: a plain
        ``np.empty`` or ``np.asarray`` takes 5-15 us in that state instead of 0.2). So
        this path does as few operations as it can: the kernel's arguments are prepared
        once per planner and per scene (the last scene's are kept), the kernel writes the
        whole path (the goal included) into one array and returns plain integers, and the
        result's ``info`` comes from a per-end-code table."""
        t0 = time.perf_counter()
        scene = problem.scene
        if scene is not self._kernel_scene:
            self._kernel_scene_args = self._kernel_scene_inputs(scene)
            self._kernel_scene = scene
        args = self._kernel_scene_args
        if args is None:
            return None
        start, goal = problem.start, problem.goal
        if start.dtype is not _F64 or goal.dtype is not _F64:
            start, goal = np.asarray(start, np.float64), np.asarray(goal, np.float64)
        if start.shape != self._path_shape[1:]:
            raise ValueError(f"problem {problem.tag or ''} does not fit robot {self.robot.name}")
        path = np.empty(self._path_shape)
        assert self._kernel is not None
        t1 = time.perf_counter()
        end, rows, checks, _ = self._kernel(start, goal, *args, path)
        t2 = time.perf_counter()
        if end == _K_END_ESCAPE:  # stuck: the escape and the rest of the rollout go on in Python
            r = _Rollout(q=path[rows - 1].copy(), path=list(path[:rows].copy()), t=rows - 1, checks=checks)
            self._start_escape(r, scene)
            return self._rollout_one(problem, r, t0, t2 - t1)
        success, to_goal, entries = self._end_entries[end]
        steps = rows - 1 - to_goal
        info = {"time_split": {"observe": 0.0, "network": 0.0, "motion": 0.0, "goal": 0.0, "compiled": t2 - t1, "steps": steps}, **entries}
        return PlanResult(path[:rows], success, steps, checks, time.perf_counter() - t0, info=info)

    def _kernel_scene_inputs(self, scene: Scene) -> tuple[np.ndarray, ...] | None:
        """The compiled rollout's arguments after the start and the goal, for ``scene``
        (its bounds and boxes, the observer's points, the planner's arguments, the random
        stream long enough for the scene), or ``None`` when it does not apply."""
        assert self._kernel_args is not None
        self._observer.set_scene(0, scene)
        inputs = self._scene_inputs(scene)
        if inputs is None:
            return None
        pts, nrm, boxes = inputs
        stream = self._uniforms(self.horizon * (max(len(pts), 1) + self._observer.n_points))
        return (scene.low, scene.high, *boxes, pts, nrm, *self._kernel_args, stream)

    def _end_table(self) -> tuple[tuple[bool, bool, dict[str, Any]], ...]:
        """Per end code of the compiled rollout (``_policy_kernels.END_*``): success, whether
        the path ends at the goal, and the ``info`` entries of the result (those
        ``_rollout_one`` sets)."""
        from . import _policy_kernels as K

        rows = []
        for end, name in enumerate(_END_NAMES):
            to_goal = end in (K.END_GREEDY, K.END_TOL_GOAL)
            success = to_goal or end in (K.END_TOL_BLOCKED, K.END_TOL)
            entries: dict[str, Any] = {"end": name}
            if self.escape.steps > 0:
                entries["escapes"] = 0  # (a rollout that escapes goes on in numpy, which counts them)
            if end == K.END_GREEDY:
                entries["greedy_goal"] = True
            if to_goal or end == K.END_TOL_BLOCKED:
                entries["goal_connection"] = "free" if to_goal else "blocked"
            elif self.connect_goal and not success:
                entries["goal_connection"] = None
            rows.append((success, to_goal, entries))
        return tuple(rows)

    def _goal_tester(self, scene: Scene, goal: np.ndarray) -> _GoalTester:
        return _GoalTester(self.robot, scene, goal)

    def _start_escape(self, r: _Rollout, scene: Scene) -> None:
        """``r`` is stuck (the escape's test): its next ``escape.steps`` steps escape."""
        r.escape_left = self.escape.steps
        r.escapes += 1
        if self.escape.subgoal:
            assert self._escape_rng is not None
            r.subgoal = self.robot.sample_uniform(self._escape_rng, 1, scene.low, scene.high)[0]

    def _rollout_one(self, problem: Problem, resume: _Rollout | None = None, t0: float | None = None, t_compiled: float = 0.0) -> PlanResult:
        """One robot stepped as the environment steps it: the same observation draws as
        ``rollout_batch`` with this one problem and the same ``q_free``, without the batch.

        The motion checks are batched along the rollout: the policy runs ahead assuming
        each move ends at its (bounds-clipped) target, as a free move does; then one
        ``q_free`` call checks all those moves. Up to the first move that ``q_free`` ends
        elsewhere (a collision, a bound) the rollout is exactly the sequential one; from
        there it continues from where ``q_free`` put the robot, with the same draws. So
        the result is the sequential rollout's, at one motion-check call per run ahead
        instead of one per step.

        With ``greedy_goal`` the rollout stops at the first configuration it reaches (the
        start included) from which the straight edge to the goal is certified free
        (:class:`_GoalTester`); up to there it is the rollout without.

        ``resume``: go on from this rollout (the compiled one's, where an escape started;
        ``t0`` its start time, ``t_compiled`` its seconds in the kernel)."""
        t0 = time.perf_counter() if t0 is None else t0
        robot, scene = self.robot, problem.scene
        if problem.start.shape != (robot.config_dim,):
            raise ValueError(f"problem {problem.tag or ''} does not fit robot {robot.name}")
        self._observer.set_scene(0, scene)
        lean = self._lean_step()
        goal = np.asarray(problem.goal, np.float64)
        q = np.asarray(problem.start, np.float64).copy()
        r = _Rollout(q=q, path=[q]) if resume is None else resume
        tester = self._goal_tester(scene, goal) if self.greedy_goal else None
        ctx = torch_threads(1) if self.fast is None else contextlib.nullcontext()
        with ctx:
            while r.t < self.horizon and not r.success and r.end == "horizon":
                qs, twists, dists = self._run_ahead(r, scene, goal, lean, tester)
                if r.at_goal:
                    break
                self._keep_agreeing(r, scene, goal, qs, twists, dists)
            if tester is not None and not r.success and not r.at_goal:  # where the rollout stopped
                tg = time.perf_counter()
                r.at_goal, checks = tester.free(r.q, certify=True)
                r.checks += checks
                r.t_goal += time.perf_counter() - tg
        steps = len(r.path) - 1
        path = np.stack(r.path + [goal]) if r.at_goal else np.stack(r.path)
        res = PlanResult(path=path, success=r.success or r.at_goal, nodes=steps, collision_checks=r.checks, time_s=time.perf_counter() - t0)
        res.info["time_split"] = {"observe": r.t_obs, "network": r.t_net, "motion": r.t_motion, "goal": r.t_goal, "steps": steps}
        if resume is not None:
            res.info["time_split"]["compiled"] = t_compiled
        if self.escape.steps > 0:
            res.info["escapes"] = r.escapes
        if r.at_goal:
            res.info["end"], res.info["goal_connection"], res.info["greedy_goal"] = "goal", "free", True
            return res
        if not r.success:
            res.info["end"] = r.end
        if self.connect_goal:
            res = connect_to_goal(robot, problem, res)
        else:
            res.info.setdefault("end", "near-goal" if r.success else r.end)
        return res

    def _run_ahead(
        self, r: _Rollout, scene: Scene, goal: np.ndarray, lean: Any, tester: _GoalTester | None = None
    ) -> tuple[list[np.ndarray], list[np.ndarray], list[float]]:
        """Steps of the policy from ``(r.q, r.t)``, every move assumed free: the
        configurations (``r.q`` first), the twists and the distances to the goal.

        With a goal ``tester``: at ``r.q`` the edge to the goal is checked (certified; when
        free, ``r.at_goal`` is set and nothing is returned); at a configuration ahead that
        passes the tester's quick test the run ahead stops there (the next run, from there
        once ``q_free`` has confirmed the moves, certifies the edge)."""
        robot, observer, stall, stall_r = self.robot, self._observer, self.stall_steps, self.stall_distance
        per_step, tol, k_draws = observer.draws_one(), self.env.goal_tolerance, self.draws
        blk = per_step * k_draws
        clip_target = self.env.bounds == "clip"
        scale = np.asarray(robot.action_scale, np.float64)
        qs: list[np.ndarray] = [r.q]
        twists: list[np.ndarray] = []
        dists: list[float] = []
        qq, t = r.q, r.t
        left = r.escape_left
        for s in range(t, self.horizon):
            if tester is not None:
                tg = time.perf_counter()
                maybe, checks = tester.free(qq, certify=s == t)
                if s == t or not maybe:  # a quick pass ahead is done again when the run gets there
                    r.checks += checks
                r.t_goal += time.perf_counter() - tg
                if maybe:
                    if s == t:
                        r.at_goal = True
                        return qs, twists, dists
                    break  # confirm the moves up to here first
            u = self._uniforms((s + 1) * blk)[s * blk : (s + 1) * blk]
            escaping = left > 0
            left -= escaping
            ta = time.perf_counter()
            if lean is not None and not escaping:  # observation and network in one (timed as network)
                tb = ta
                a = lean(qq, goal, u) if k_draws == 1 else np.mean([lean(qq, goal, u[j * per_step : (j + 1) * per_step]) for j in range(k_draws)], 0)
            elif k_draws == 1:
                obs = observer.observe_one(qq, u=u)
                tb = time.perf_counter()
                a = self._act(obs, qq, r.subgoal if escaping and r.subgoal is not None else goal, escaping)
            else:  # observing and acting interleaved: timed as network
                tb = ta
                toward = r.subgoal if escaping and r.subgoal is not None else goal
                a = np.mean([self._act(observer.observe_one(qq, u=u[j * per_step : (j + 1) * per_step]), qq, toward, escaping) for j in range(k_draws)], 0)
            tc = time.perf_counter()
            tw = np.clip(a, -1.0, 1.0) * scale  # float64, as the env computes it
            qq = _free_move_end(robot, qq, tw, scene.low, scene.high, clip_target)
            r.t_obs += tb - ta
            r.t_net += tc - tb
            r.t_motion += time.perf_counter() - tc
            twists.append(tw)
            qs.append(qq)
            d = float(robot.distance(qq, goal))
            dists.append(d)
            if d < tol:
                break
            if stall is not None and s + 1 >= stall:
                back = s + 1 - stall  # the step ``stall`` steps before this one
                if float(robot.distance(qq, qs[back - t] if back >= t else r.path[back])) < stall_r:
                    break
        return qs, twists, dists

    def _keep_agreeing(self, r: _Rollout, scene: Scene, goal: np.ndarray, qs: list[np.ndarray], twists: list[np.ndarray], dists: list[float]) -> None:
        """Check every move of the run ahead in one ``q_free`` call; advance ``r`` by the
        moves up to the first that ends elsewhere (or the end of the episode)."""
        robot, env, stall, stall_r = self.robot, self.env, self.stall_steps, self.stall_distance
        tc = time.perf_counter()
        k = len(twists)
        low, high = np.repeat(scene.low[None], k, 0), np.repeat(scene.high[None], k, 0)
        new_q, collided, n = q_free(robot, scene.world, np.stack(qs[:-1]), np.stack(twists), low, high, env.substep, clip_target=env.bounds == "clip")
        r.t_motion += time.perf_counter() - tc
        esc = self.escape
        for j in range(k):
            r.q = new_q[j]
            r.path.append(r.q)
            r.escape_left = max(r.escape_left - 1, 0)
            r.checks += int(n[j])
            r.t += 1
            agrees = not collided[j] and np.array_equal(r.q, qs[j + 1])
            d = dists[j] if agrees else float(robot.distance(r.q, goal))
            if d < env.goal_tolerance and not collided[j]:
                r.success = True
                return
            if stall is not None and r.t >= stall and float(robot.distance(r.q, r.path[r.t - stall])) < stall_r:
                r.end = "stalled"
                return
            if esc.steps > 0 and r.escape_left == 0 and r.t >= esc.window and float(robot.distance(r.q, r.path[r.t - esc.window])) < esc.still:
                self._start_escape(r, scene)  # stuck: the next steps escape (run ahead again)
                return
            if not agrees:
                return  # the run ahead went elsewhere from here: run again from r.q

    def plan_many(self, problems: Sequence[Problem]) -> list[PlanResult]:
        """All problems at once (much faster than one by one; one by one with an
        ``observer_wrapper``, ``draws > 1`` or ``attempts > 1``)."""
        if self.observer_wrapper is not None or self.draws > 1 or self.attempts > 1:
            return [self.plan(p) for p in problems]
        return rollout_batch(self.policy, self.robot, self.env, problems, self.horizon, self.seed, connect_goal=self.connect_goal, escape=self.escape)
