"""The rollout engine: a policy stepped toward the goal, one step loop for every caller.

The planners (:class:`~pointplan.planners.policy.PolicyPlanner`, the hybrid), the
evaluator, training validation, PPO and DAgger all roll policies out through
:class:`RolloutEngine`. Its options (:class:`RolloutOptions`) are the features of a
rollout, each written once in the step loop (:func:`_loop`):

- the greedy goal test: before every step (the start included) and where the rollout
  stops, is the straight edge to the goal certified free? Then the path ends at the goal;
- the stall test: stop when the last ``stall_steps`` steps took the robot less than
  ``stall_distance`` from where it was;
- the escape (:class:`Escape`): sampled actions, or the mean action toward a random
  subgoal, for a few steps where the robot is stuck;
- the crush rule: a moving obstacle that runs into the robot ends its rollout;
- the dodge (:class:`Dodge`): among moving obstacles, an action whose move would meet
  them where they are foreseen to be is replaced by a sampled one that does not;
- sampled attempts: when the mean-action rollout fails, roll out again from the start
  with sampled actions;
- the goal connection: a rollout that stops within the goal tolerance ends at the goal
  when the edge there is free.

How a step observes, acts and moves is a *stepper*, chosen by capability:

- :class:`_Lockstep`: any number of problems in lockstep through the batched
  environment core (any observer, moving obstacles; PyTorch network);
- :class:`_OneRobot`: one robot in a static scene, for observers that can observe one
  robot from a block of uniform draws (``Observer.one_robot``), with the network in
  numpy: the same draws and the same arithmetic as :class:`_Lockstep` with that one
  problem, without the batch machinery;
- the compiled form (:mod:`._policy_kernels`, ``_rollout``): the whole mean-action
  rollout of a translating ball among boxes in one call, for observers whose draws it
  reproduces (``Observer.compiled_points``). Where an escape starts it hands the state
  back to the step loop, which goes on with :class:`_OneRobot`.

``tests/test_policy_planner.py`` and ``tests/test_policy_kernels.py`` check that the
three give the same rollouts.
"""

from __future__ import annotations

import contextlib
import time
import zlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ..envs.core import BatchedCore, EnvConfig, goal_reached, q_free
from ..geometry.collision import CollisionWorld
from ..robots import ROBOTS, make_robot
from ..robots.base import Robot
from ..robots.point import Disc2D, Sphere3D
from ..scenes.scenarios import Scenario
from ..scenes.scene import Problem, Scene
from .base import PlanResult
from .edges import edge_free

if TYPE_CHECKING:
    from ..models.policy import Policy

ActFn = Callable[..., np.ndarray]
_F64 = np.dtype(np.float64)
#: the resolution of every certified edge to the goal (as Bi-RRT checks its edges)
GOAL_EDGE_RESOLUTION = 0.01
#: a screened escape's draw that moves the robot less than this is not looked ahead from
_MOVED = 1e-3


@dataclass(frozen=True)
class Escape:
    """Noise switched on where a rollout is stuck: after a step that left the robot less
    than ``still`` (geodesic distance) from where it was ``window`` steps before, the next
    ``steps`` actions are sampled as ``tanh(mean + noise * std * N(0, 1))``, then the mean
    action again (``steps = 0``: off). The cloned S-shape policies mostly fail by pressing
    against an obstacle with the same mean action until the horizon (``window = 1``: one
    step that did not move); the sphere's by dithering back and forth in one place, which
    a longer window sees. A few sampled steps free them within the one rollout.

    ``subgoal``: during an escape the policy is steered toward a configuration drawn
    uniformly in the scene's bounds instead of the goal (with ``noise = 0``, its mean
    action toward it): a goal-conditioned policy walks off in a random direction while
    avoiding obstacles, where noise alone jitters about the trap (randomised escape from
    a local minimum, as in potential-field planners).

    ``tries``: each sampled step of an escape draws this many actions and takes the one
    whose free motion goes furthest (each draw's motion checked, and counted; among moving
    obstacles, against where they are at the step's start, not where they will be). One
    draw is the plain escape.

    ``lookahead``: with several draws, each draw's free end is followed by the mean action
    for this many steps more (observed there, each move as far as it is free), and the draw
    whose lookahead ends furthest from where the robot is is taken (one whose lookahead
    arrives at the goal first); 0: each draw's own motion decides.

    ``backoff``: with several draws (one draw: no effect), where not one of them takes the
    robot anywhere (every move refused: the body wedged against a wall a fraction of a
    millimetre away, where each draw presses on), the step heads instead back toward the
    latest pose of the robot's own path more than ``backoff`` away (geodesic distance; the
    action toward it, shortened into the action box, and its move checked like any other);
    the next escape steps draw again from there. 0: off."""

    steps: int = 10
    noise: float = 2.0
    still: float = 0.01
    window: int = 1
    subgoal: bool = False
    tries: int = 1
    lookahead: int = 0
    backoff: float = 0.0

    def __post_init__(self) -> None:
        if int(self.steps) != self.steps or self.steps < 0:
            raise ValueError(f"escape steps must be an integer >= 0, not {self.steps}")
        if not np.isfinite(self.noise) or self.noise < 0:
            raise ValueError(f"escape noise must be a finite number >= 0, not {self.noise}")
        if not np.isfinite(self.still) or self.still < 0:
            raise ValueError(f"escape still must be a finite number >= 0, not {self.still}")
        if int(self.window) != self.window or self.window < 1:
            raise ValueError(f"escape window must be an integer >= 1, not {self.window}")
        if int(self.tries) != self.tries or self.tries < 1:
            raise ValueError(f"escape tries must be an integer >= 1, not {self.tries}")
        if int(self.lookahead) != self.lookahead or self.lookahead < 0:
            raise ValueError(f"escape lookahead must be an integer >= 0, not {self.lookahead}")
        if not np.isfinite(self.backoff) or self.backoff < 0:
            raise ValueError(f"escape backoff must be a finite number >= 0, not {self.backoff}")
        object.__setattr__(self, "steps", int(self.steps))  # 6.0 -> 6: they index paths
        object.__setattr__(self, "tries", int(self.tries))
        object.__setattr__(self, "lookahead", int(self.lookahead))
        object.__setattr__(self, "window", int(self.window))

    @property
    def on(self) -> bool:
        return self.steps > 0


#: the escape a robot's policies plan with when none is given (by the robot's name, else
#: its body's), chosen on validation problems (docs: "Escaping a stall"): the S-shape
#: presses against an obstacle, so one still step starts ten sampled ones, each the
#: furthest-moving of eight draws (one rollout; 200 validation problems of 3D-Boxes, `local`
#: 88.5 / 94.5 / 95.0 / 95.5% with 1 / 4 / 8 / 16 draws, `global` 86.0 / 92.0 / 94.0% with
#: 1 / 4 / 8; 64 draws gained 0.2-1.8 points on 500 for three times the time, so eight
#: stay); the S-shape told its orientation, whose policy threads Slot's openings, takes 64
#: (twice 500 validation problems of Slot: 90.8 and 92.4% with 8, 94.8 and 95.0% with 64);
#: both S-shapes judge each draw by three steps of lookahead (500 validation problems of
#: 3D-Boxes, twice: `local` 94.4 / 95.8 -> 97.4 / 97.0%, `global` 92.8 -> 97.0% once; Slot
#: twice: 94.8 / 95.0 -> 95.8 / 96.6%; 3D-Dynamic, 200: 93.0 -> 95.5%, 88.5 -> 89.0%); the
#: oriented S-shape, wedged in Slot's thinnest openings where every draw is refused, backs
#: off along its path (twice 500 validation problems of Slot with sub-steps of 0.005: 97.2 /
#: 96.8% without, 98.2 / 97.4% backing off 0.03, 98.0 / 97.8% backing off 0.06);
#: the sphere dithers in one place, so six steps that
#: end within 0.1 of where they started start ten toward a random subgoal; the Panda, like
#: the S-shape, presses against what blocks it (its cloned policy on 40 validation cells of
#: ``armcells``: 4 solved without an escape, 20 with this one, 10 with the subgoal's), each
#: step the furthest-moving of eight draws (its tuned policy on 200 validation cells: 53.0%
#: with one draw, 65.5% with eight); the UR5 takes the Panda's (its policy: 23.5 -> 34.0%).
#: Robots not named here plan without.
ESCAPE_DEFAULTS: dict[str, Escape] = {
    "sshape": Escape(steps=10, noise=2.0, still=0.01, tries=8, lookahead=3),
    "sshape-oriented": Escape(steps=10, noise=2.0, still=0.01, tries=64, lookahead=3, backoff=0.06),
    "panda": Escape(steps=10, noise=2.0, still=0.01, tries=8),
    "ur5": Escape(steps=10, noise=2.0, still=0.01, tries=8),
    "sphere3d": Escape(steps=10, noise=0.0, still=0.1, window=6, subgoal=True),
}
ESCAPE_OFF = Escape(steps=0)

#: the largest sub-step of a checked move (geodesic distance) a robot's policies plan with
#: when no environment is given, where it differs from the environments' 0.01 (by the
#: robot's name): the check grows the body by half a sub-step's sweep, so a finer one
#: certifies moves that pass closer to an obstacle. The S-shape told its orientation
#: threads Slot's openings with 1-2 mm to spare: with 0.005, twice 500 validation problems
#: of Slot 95.8 / 96.6% -> 97.2 / 96.8% (openings under 3 bars: 63 -> 69 of 80), at about
#: the same time; the plain S-shape in 3D-Boxes gains nothing (500: 97.6 -> 97.0%) and keeps 0.01
SUBSTEP_DEFAULTS: dict[str, float] = {"sshape-oriented": 0.005}


def default_substep(robot: Robot | str) -> float | None:
    """The robot's planning sub-step (:data:`SUBSTEP_DEFAULTS`, by its name), or ``None``
    (the environment's default)."""
    return SUBSTEP_DEFAULTS.get(robot if isinstance(robot, str) else robot.name)


@dataclass(frozen=True)
class Dodge:
    """Keeping out of moving obstacles' way. A policy sees the obstacles as they are; one
    that is moving may run into the robot within the next steps (which ends the rollout).
    Before each step among moving obstacles, the chosen action (the mean, or the escape's)
    is screened against where the obstacles are foreseen to be
    (:meth:`~pointplan.scenes.scene.Scene.predicted_world`: their motion over the last
    step carried on): its move must be free of them at the step's end, and where it ends
    must stay free of them for ``lookahead`` steps more. An action that fails is replaced
    by the one nearest to it (in action space) that passes, among standing still and
    ``draws`` sampled actions ``tanh(mean + noise * std * N(0, 1))``; where none passes,
    it stays. Static scenes: nothing to do. ``draws = 0``: off."""

    draws: int = 16
    noise: float = 1.0
    lookahead: int = 3

    def __post_init__(self) -> None:
        for name in ("draws", "lookahead"):
            v = getattr(self, name)
            if int(v) != v or v < 0:
                raise ValueError(f"dodge {name} must be an integer >= 0, not {v}")
            object.__setattr__(self, name, int(v))
        if not np.isfinite(self.noise) or self.noise < 0:
            raise ValueError(f"dodge noise must be a finite number >= 0, not {self.noise}")

    @property
    def on(self) -> bool:
        return self.draws > 0


#: the dodge every robot's rollouts take among moving obstacles when none is given, chosen
#: on validation problems of 3D-Dynamic (docs: "Keeping out of the boxes' way"): the
#: S-shape's `local` policy with its escape solves 55.5 / 83.0 / 90.0 / 93.0 / 93.0% of 200
#: with no dodge / a look ahead of 1 / 2 / 3 / 4 steps (16 draws, noise 1), and 62.8 / 91.6
#: / 93.8% of another 500 with none / 2 / 3; 8 or 32 draws, noise 0.5, 1.5 or 2 no better
DODGE_DEFAULT = Dodge()
DODGE_OFF = Dodge(draws=0)


def default_escape(robot: Robot | str) -> Escape | None:
    """The robot's default escape (:data:`ESCAPE_DEFAULTS`: by its name, else by its
    body's name; a name is looked up as the robot registered under it), or ``None``."""
    if isinstance(robot, str):
        if robot in ESCAPE_DEFAULTS or robot not in ROBOTS:
            return ESCAPE_DEFAULTS.get(robot)
        robot = make_robot(robot)
    return ESCAPE_DEFAULTS.get(robot.name, ESCAPE_DEFAULTS.get(robot.body))


@dataclass(frozen=True)
class RolloutOptions:
    """What a rollout does besides stepping the policy (see the module's docstring).

    ``escape``: an :class:`Escape`; a number of steps (the robot's own kind of escape,
    :data:`ESCAPE_DEFAULTS`, that long; 0: off); ``None``: the robot's default.
    ``noise``: sample every action of the rollout, ``tanh(mean + noise * std * N(0, 1))``
    (0: the mean action). ``attempts``, ``action_noise``: after a failed rollout, up to
    ``attempts - 1`` more from the start with actions sampled at ``action_noise``, seeded
    by ``seed``, the attempt and the problem (static scenes only). ``draws``: the action
    of a step is the mean over this many observations (one robot, static scenes).
    ``compiled``: use the compiled rollout where it applies. ``crush_ends=False`` is for
    comparisons only: a moving obstacle that runs into the robot no longer ends its
    rollout (a success may then have touched an obstacle; ``info["crushed"]`` counts the
    steps it was hit). ``dodge``: a :class:`Dodge` for moving obstacles (``None``: the
    default, :data:`DODGE_DEFAULT`; :data:`DODGE_OFF`: none)."""

    horizon: int | None = None
    greedy_goal: bool = True
    connect_goal: bool = True
    escape: Escape | int | None = None
    stall_steps: int | None = None
    stall_distance: float = 0.035
    noise: float = 0.0
    attempts: int = 1
    action_noise: float = 1.0
    draws: int = 1
    seed: int = 0
    compiled: bool = True
    crush_ends: bool = True
    dodge: Dodge | None = None
    #: problems stepped together by :meth:`RolloutEngine.run`
    chunk: int = field(default=100, metadata={"min": 1})

    def __post_init__(self) -> None:
        if int(self.attempts) != self.attempts or self.attempts < 1:
            raise ValueError(f"attempts must be an integer >= 1, not {self.attempts}")
        for name in ("action_noise", "noise", "stall_distance"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise ValueError(f"{name} must be a finite number >= 0, not {v}")
        if int(self.draws) != self.draws or self.draws < 1:
            raise ValueError(f"draws must be an integer >= 1, not {self.draws}")
        if self.stall_steps is not None and (int(self.stall_steps) != self.stall_steps or self.stall_steps < 1):
            raise ValueError(f"stall_steps must be an integer >= 1 or None, not {self.stall_steps}")
        if self.horizon is not None and (int(self.horizon) != self.horizon or self.horizon < 1):
            raise ValueError(f"horizon must be an integer >= 1 or None, not {self.horizon}")
        if isinstance(self.escape, (int, float)) and not isinstance(self.escape, bool):
            Escape(steps=self.escape)  # validates the number of steps
        if int(self.chunk) < 1:
            raise ValueError(f"chunk must be >= 1, not {self.chunk}")
        if self.dodge is not None and not isinstance(self.dodge, Dodge):
            raise TypeError(f"dodge must be a Dodge or None, not {type(self.dodge).__name__}")

    def escape_for(self, robot: Robot | str, tries: int | None = None) -> Escape:
        """The escape this rollout uses for ``robot`` (a robot, or a robot's name: its own
        default, else its body's; ``tries``: with that many draws per escape step instead of
        its own)."""
        default = default_escape(robot)
        if self.escape is None:
            esc = default or ESCAPE_OFF
        elif isinstance(self.escape, Escape):
            esc = self.escape
        else:
            esc = replace(default or Escape(), steps=self.escape)
        return esc if tries is None else replace(esc, tries=tries)


class _GivenProblems(Scenario):
    """A scenario that only plays the problems it is handed."""

    name = "given"

    def __init__(self, robot: Robot, horizon: int) -> None:
        self.robot = robot
        self.horizon = horizon

    def scene(self, split: str, index: int) -> Scene:
        raise RuntimeError("rollouts play given problems only")


def connect_to_goal(
    robot: Robot, problem: Problem, result: PlanResult, resolution: float = GOAL_EDGE_RESOLUTION, t: int | None = None
) -> PlanResult:
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


class GoalTester:
    """Is the straight edge from a configuration to the goal free? The certified answer is
    :func:`~pointplan.planners.edges.edge_free` at :data:`GOAL_EDGE_RESOLUTION` (the check
    of :func:`connect_to_goal`). For a translating ball among boxes, spheres, capsules,
    cylinders and cones a quick test comes first: the plain ball (a hair smaller) at the
    samples of the edge; if it overlaps an obstacle the edge is certainly not free, and the certified check is skipped (it would say
    the same: a certified edge has no configuration touching an obstacle).
    ``tests/test_policy_kernels.py`` checks that implication."""

    def __init__(self, robot: Robot, scene: Scene, goal: np.ndarray, resolution: float = GOAL_EDGE_RESOLUTION) -> None:
        self.robot, self.scene, self.goal, self.resolution = robot, scene, goal, resolution
        self.boxes: tuple[Any, ...] | None = None
        world = scene.world  # (a moving scene's at time 0, as below)
        if isinstance(robot, (Disc2D, Sphere3D)) and world.batch_shape == () and world.primitives_only:
            self.boxes = (*world.box_arrays(), world.ball_prims())
        self.radius = float(getattr(robot, "radius", 0.0)) * (1.0 - 1e-9)

    def free(self, q: np.ndarray, certify: bool = True) -> tuple[bool, int]:
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


# ---------------------------------------------------------------- the step loop
class _State:
    """The rollouts of ``n`` robots: their paths and counters, the escapes under way."""

    def __init__(self, q0: np.ndarray, goal: np.ndarray, horizon: int, greedy: np.ndarray) -> None:
        n, d = q0.shape
        self.paths = np.zeros((horizon + 1, n, d))
        self.paths[0] = q0
        self.q = q0
        self.goal = goal
        self.greedy = greedy
        self.t = 0
        self.length = np.ones(n, np.int64)
        self.checks = np.zeros(n, np.int64)
        self.active = np.ones(n, bool)
        self.success = np.zeros(n, bool)
        self.at_goal = np.zeros(n, bool)
        self.crushed = np.zeros(n, bool)
        self.stalled = np.zeros(n, bool)
        self.hits = np.zeros(n, np.int64)
        self.left = np.zeros(n, np.int64)  # sampled steps of an escape still to come
        self.escapes = np.zeros(n, np.int64)
        self.subgoals = goal.copy()  # where an escape toward a subgoal heads

    @classmethod
    def resumed(cls, path: np.ndarray, goal: np.ndarray, horizon: int, greedy: bool, checks: int) -> _State:
        """One robot's rollout taken over after ``len(path) - 1`` steps (from the compiled one)."""
        st = cls(path[:1].copy(), goal[None].copy(), horizon, np.array([greedy]))
        k = len(path)
        st.paths[:k, 0] = path
        st.q = path[-1][None].copy()
        st.t = k - 1
        st.length[0] = k
        st.checks[0] = checks
        return st


class _Stepper:
    """How a step observes, acts and moves; the loop does the rest."""

    robot: Robot

    def actions(self, st: _State, t: int, escaping: np.ndarray, target: np.ndarray) -> np.ndarray:
        """The actions ``(n, action_dim)`` of step ``t`` (toward ``target``; sampled where
        ``escaping``)."""
        raise NotImplementedError

    def move(self, a: np.ndarray, st: _State) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Apply the actions: ``(configurations, within the goal tolerance and free,
        crushed by a moving obstacle, configurations checked)``."""
        raise NotImplementedError

    def goal_free(self, i: int, q: np.ndarray) -> tuple[bool, int]:
        """Is the straight edge from ``q`` to robot ``i``'s goal certified free?"""
        raise NotImplementedError

    def subgoal(self, i: int) -> np.ndarray:
        """A subgoal for robot ``i``'s escape, drawn uniformly in its scene's bounds."""
        raise NotImplementedError


def _try_goal(sp: _Stepper, st: _State, which: np.ndarray) -> None:
    for i in np.flatnonzero(which & st.greedy):
        ok, c = sp.goal_free(int(i), st.q[i])
        st.checks[i] += c
        if ok:
            st.at_goal[i], st.success[i], st.active[i] = True, True, False


def _back_off(robot: Robot, past: np.ndarray, q: np.ndarray, backoff: float) -> np.ndarray | None:
    """The escape's back-off (:class:`Escape`): the action from ``q`` toward the latest of
    the poses ``past`` (the robot's path so far, oldest first) more than ``backoff`` away,
    shortened into the action box; ``None`` where none is that far."""
    far = np.flatnonzero(np.asarray(robot.distance(past, np.broadcast_to(q, past.shape))) > backoff)
    if not len(far):
        return None
    a = np.asarray(robot.log(q[None], past[far[-1]][None]), np.float64)[0] / robot.action_scale
    return (a / max(1.0, float(np.max(np.abs(a))))).astype(np.float32)


def _loop(sp: _Stepper, st: _State, horizon: int, opts: RolloutOptions, esc: Escape) -> None:
    """Step every active robot of ``st`` until it arrives, stalls, is crushed or the
    horizon ends; the greedy goal test before each step and where a rollout stopped."""
    robot = sp.robot
    toward_subgoal = esc.on and esc.subgoal
    stall = opts.stall_steps
    for t in range(st.t, horizon):
        _try_goal(sp, st, st.active)
        if not st.active.any():
            break
        escaping = (st.left > 0) & st.active  # a rollout that ended mid-escape draws no more
        target = np.where(escaping[:, None], st.subgoals, st.goal) if toward_subgoal else st.goal
        a = sp.actions(st, t, escaping, target)
        st.left[escaping] -= 1
        a[~st.active] = 0.0  # finished rollouts stand still
        q, term, crushed, checks = sp.move(a, st)
        st.q = q
        st.paths[t + 1] = q
        st.t = t + 1
        act = st.active
        st.length += act
        st.checks += np.where(act, checks, 0)
        st.success |= term & act
        st.crushed |= crushed & act
        st.hits += crushed & act
        ended = term | (crushed & opts.crush_ends)  # a moving obstacle that hits the robot ends it
        going = act & ~ended
        if stall is not None and t + 1 >= stall:
            stalled = going & (np.asarray(robot.distance(q, st.paths[t + 1 - stall])) < opts.stall_distance)
            st.stalled |= stalled
            going &= ~stalled
            ended = ended | stalled
        if esc.on and t + 1 >= esc.window:
            stuck = going & (st.left == 0) & (np.asarray(robot.distance(q, st.paths[t + 1 - esc.window])) < esc.still)
            st.left[stuck] = esc.steps
            st.escapes += stuck
            if toward_subgoal:
                for j in np.flatnonzero(stuck).tolist():
                    st.subgoals[j] = sp.subgoal(j)
        st.active &= ~ended
        if not st.active.any():
            break
    _try_goal(sp, st, ~st.success)  # where the rollouts that did not arrive stopped


def _results(
    st: _State, problems: Sequence[Problem], robot: Robot, opts: RolloutOptions, esc: Escape, dt: float
) -> list[PlanResult]:
    """One :class:`PlanResult` per robot of a finished loop (``dt`` seconds each)."""
    out = []
    for i, p in enumerate(problems):
        k = int(st.length[i])
        if st.at_goal[i]:
            path = np.concatenate([st.paths[:k, i], np.asarray(p.goal, np.float64)[None]])
            res = PlanResult(path=path, success=True, nodes=k - 1, collision_checks=int(st.checks[i]), time_s=dt)
            res.info.update({"end": "goal", "goal_connection": "free", "greedy_goal": True})
        else:
            res = PlanResult(
                path=st.paths[:k, i].copy(),
                success=bool(st.success[i]),
                nodes=k - 1,
                collision_checks=int(st.checks[i]),
                time_s=dt,
            )
            if st.crushed[i] and opts.crush_ends:
                res.info["end"] = "crushed"
            elif st.stalled[i]:
                res.info["end"] = "stalled"
            if opts.connect_goal:
                res = connect_to_goal(robot, p, res, t=k)
            else:
                res.info.setdefault("end", "near-goal" if res.success else "horizon")
        if esc.on:
            res.info["escapes"] = int(st.escapes[i])
        if not opts.crush_ends:
            res.info["crushed"] = int(st.hits[i])
        out.append(res)
    return out


# ---------------------------------------------------------------- steppers
class _Rows:
    """A few environments of a lockstep batch taken apart (the screened escape's robots):
    their own observer, their obstacles as they are at their time steps, and their
    workspace bounds."""

    def __init__(self, core: BatchedCore, idx: np.ndarray) -> None:
        self.t = core.t[idx].copy()
        self.observer, self.world = core.rows(idx, self.t)
        self.low, self.high = core.low[idx], core.high[idx]


class _Lockstep(_Stepper):
    """Problems in lockstep through the batched environment core; ``act(obs, q, goal)``
    (with ``noise=`` when actions are sampled). The observations are drawn from ``rng``;
    where actions are sampled (``noise > 0`` or an escape), a block of normal draws comes
    from ``nrng`` at every step."""

    def __init__(
        self,
        act: ActFn,
        robot: Robot,
        env: EnvConfig,
        problems: Sequence[Problem],
        rng: np.random.Generator,
        nrng: np.random.Generator,
        noise: float,
        esc: Escape,
        dodge: Dodge = DODGE_OFF,
    ) -> None:
        self.act, self.robot, self.problems = act, robot, problems
        self.core = BatchedCore(_GivenProblems(robot, int(env.horizon or 0)), len(problems), env)
        self.core.reset_envs(range(len(problems)), rng, problems)
        self.rng, self.nrng, self.noise, self.esc = rng, nrng, noise, esc
        self.pending_checks: Any = 0  # motion checks of the screened escape's draws, counted with the step
        self.sampled = esc.on or noise > 0
        self._testers: dict[int, GoalTester] = {}
        self.moving = np.array([p.scene.dynamic for p in problems])
        self.dodge = dodge if self.moving.any() else DODGE_OFF
        self.look_rng = np.random.default_rng(zlib.crc32(b"lookahead"))  # the lookahead's observations

    def actions(self, st: _State, t: int, escaping: np.ndarray, target: np.ndarray) -> np.ndarray:
        core = self.core
        obs = core.observe(self.rng)["observation"]  # (at each problem's own time step)
        if not self.sampled:
            a = np.asarray(self.act(obs, core.q.copy(), core.goal.copy()), np.float32)
        else:
            scale = np.where(escaping, self.esc.noise, self.noise)
            draw = self.nrng.standard_normal((len(self.problems), len(self.robot.action_scale)))
            a = np.asarray(self.act(obs, core.q.copy(), target.copy(), noise=scale[:, None] * draw), np.float32)
            if self.esc.tries > 1 and escaping.any():
                a = self._furthest(obs, target, escaping, a, st.paths[: t + 1])
        if self.dodge.on:
            a = self._dodge(obs, target, st.active & self.moving, a)
        return a

    def _clear(self, a: np.ndarray, ends: Any, later: list[Any]) -> tuple[np.ndarray, np.ndarray]:
        """Whether each action's move is free among the obstacles foreseen at the step's
        end (``ends``) and its end pose among those foreseen after (``later``); the checks."""
        core = self.core
        tw = np.clip(a.astype(np.float64), -1.0, 1.0) * self.robot.action_scale
        q1, collided, n = q_free(
            self.robot, ends, core.q, tw, core.low, core.high, core.config.substep, core.config.bounds == "clip"
        )
        ok = ~np.asarray(collided, bool)
        for w in later:
            ok &= ~self.robot.collides(w, q1[:, None])[:, 0]
        return ok, np.asarray(n) + len(later)

    def _dodge(self, obs: np.ndarray, target: np.ndarray, moving: np.ndarray, a: np.ndarray) -> np.ndarray:
        """The :class:`Dodge` for the robots ``moving``: actions ``a`` kept where they pass
        the screen, else replaced by the nearest of standing still and the sampled draws
        that does."""
        core, d = self.core, self.dodge
        scenes = [p.scene for p in self.problems]

        def foreseen(k: int) -> Any:  # each problem at its own time, k steps ahead
            return CollisionWorld.stack([s.predicted_world(int(t), int(t) + k) for s, t in zip(scenes, core.t)])

        ends, later = foreseen(1), [foreseen(1 + h) for h in range(1, d.lookahead + 1)]
        ok, n = self._clear(a, ends, later)
        checks = np.where(moving, n, 0)
        bad = moving & ~ok
        if bad.any():
            best, gap = a.copy(), np.full(len(a), np.inf)
            q0, draws = core.q.copy(), [np.zeros_like(a)]
            for _ in range(d.draws):
                noise = d.noise * self.nrng.standard_normal(a.shape)
                draws.append(np.asarray(self.act(obs, q0.copy(), target.copy(), noise=noise), np.float32))
            for b in draws:
                ok, n = self._clear(b, ends, later)
                checks += np.where(bad, n, 0)
                dist = np.linalg.norm(b - a, axis=-1)
                take = bad & ok & (dist < gap)
                best[take], gap[take] = b[take], dist[take]
            a = best
        self.pending_checks = self.pending_checks + checks
        return a

    def _free_move(self, a: np.ndarray, q: np.ndarray, rows: _Rows) -> tuple[np.ndarray, np.ndarray]:
        """Where actions ``a`` would take the robots ``rows`` from ``q``, as far as each is
        free among the obstacles as they are now (what the robot's sensors show: no look at
        where moving ones will be); the motion checks of each."""
        config = self.core.config
        tw = np.clip(a.astype(np.float64), -1.0, 1.0) * self.robot.action_scale
        q1, _, n = q_free(
            self.robot, rows.world, q, tw, rows.low, rows.high, config.substep, clip_target=config.bounds == "clip"
        )
        return q1, np.asarray(n)

    def _furthest(
        self,
        obs: np.ndarray,
        target: np.ndarray,
        escaping: np.ndarray,
        a: np.ndarray,
        paths: np.ndarray | None = None,
    ) -> np.ndarray:
        """The screened escape for the robots ``escaping``: of ``tries`` draws (``a`` the
        first), each takes the one whose free motion goes furthest; where none moves, the
        back-off along its path (``paths``: ``(steps so far + 1, n, dof)``; :class:`Escape`;
        ``None``: no back-off).
        Only the escaping environments are drawn for, moved and observed (apart from the
        batch)."""
        idx = np.flatnonzero(escaping)
        if len(idx) == 0:
            return a
        rows = _Rows(self.core, idx)
        q0, tg, ob = self.core.q[idx].copy(), target[idx].copy(), obs[idx]
        best = a[idx].copy()
        q1, checks = self._free_move(best, q0, rows)
        far, ahead = self._score(q1, q0, tg, rows)
        checks = checks + ahead
        for _ in range(self.esc.tries - 1):
            draw = self.esc.noise * self.nrng.standard_normal(best.shape)
            b = np.asarray(self.act(ob, q0.copy(), tg.copy(), noise=draw), np.float32)
            q1, n = self._free_move(b, q0, rows)
            d, ahead = self._score(q1, q0, tg, rows)
            better = d > far
            best[better], far[better] = b[better], d[better]
            checks = checks + n + ahead
        if self.esc.backoff > 0 and paths is not None:
            for j in np.flatnonzero(far < _MOVED).tolist():
                back = _back_off(self.robot, paths[:, idx[j]], q0[j], self.esc.backoff)
                if back is not None:
                    best[j] = back
        a[idx] = best
        counted = np.zeros(len(a), np.int64)
        counted[idx] = checks
        self.pending_checks = self.pending_checks + counted
        return a

    def _score(
        self, q1: np.ndarray, q0: np.ndarray, target: np.ndarray, rows: _Rows
    ) -> tuple[np.ndarray, np.ndarray | int]:
        """How far each draw that ends at ``q1`` takes its robot from ``q0`` (the
        environments ``rows``): its own motion, or with a lookahead (:class:`Escape`) where
        the mean action then carries it (infinite where it arrives at ``target``); and the
        lookahead's motion checks."""
        robot = self.robot
        d = np.asarray(robot.distance(q1, q0), np.float64)
        look = d >= _MOVED
        if not self.esc.lookahead or not look.any():
            return d, 0
        qk, arrived, checks = q1.copy(), np.zeros(len(q1), bool), np.zeros(len(q1), np.int64)
        for _ in range(self.esc.lookahead):
            obs = rows.observer.observe(qk, self.look_rng, rows.t)
            qk, n = self._free_move(np.asarray(self.act(obs, qk.copy(), target.copy())), qk, rows)
            checks += np.where(look, n, 0)
            arrived |= goal_reached(robot, self.core.config, qk, target, np.zeros(len(qk), bool))
        ahead = np.where(arrived, np.inf, np.asarray(robot.distance(qk, q0), np.float64))
        return np.where(look, ahead, d), checks

    def move(self, a: np.ndarray, st: _State) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        _, term, _, info = self.core.step(a)
        checks, self.pending_checks = info["collision_checks"] + self.pending_checks, 0
        return self.core.q.copy(), term, info["crushed"], checks

    def goal_free(self, i: int, q: np.ndarray) -> tuple[bool, int]:
        if i not in self._testers:
            p = self.problems[i]
            self._testers[i] = GoalTester(self.robot, p.scene, np.asarray(p.goal, np.float64))
        return self._testers[i].free(q)

    def subgoal(self, i: int) -> np.ndarray:
        sc = self.problems[i].scene
        return self.robot.sample_uniform(self.nrng, 1, sc.low, sc.high)[0]


@dataclass
class _Timing:
    """Seconds of a one-robot rollout spent observing, in the network, checking motions
    and testing the goal edge."""

    observe: float = 0.0
    network: float = 0.0
    motion: float = 0.0
    goal: float = 0.0

    def split(self, steps: int) -> dict[str, float]:
        return {
            "observe": self.observe,
            "network": self.network,
            "motion": self.motion,
            "goal": self.goal,
            "steps": steps,
        }


class _OneRobot(_Stepper):
    """One robot in a static scene, observed with ``observe_one`` from the block of
    uniform numbers :class:`_Lockstep` would draw for it, the network in numpy where it
    can (and, for a translating ball seeing points, without building the observation:
    :meth:`RolloutEngine._lean_step`). Normal draws come from ``nrng`` only where an
    action is sampled: at an escape's steps, and at every step of a sampled attempt."""

    def __init__(
        self, engine: RolloutEngine, problem: Problem, nrng: np.random.Generator | None, sampled: bool
    ) -> None:
        self.engine, self.robot, self.problem = engine, engine.robot, problem
        self.scene = problem.scene
        self.goal = np.asarray(problem.goal, np.float64)
        self.nrng, self.sampled = nrng, sampled
        self.observer = engine.observer
        self.observer.set_scene(0, self.scene)
        self.lean = None if sampled else engine._lean_step()
        self.tester = GoalTester(self.robot, self.scene, self.goal)
        self.scale = np.asarray(self.robot.action_scale, np.float64)
        self.clip_target = engine.env.bounds == "clip"
        self.timing = _Timing()
        self.pending_checks = 0  # motion checks of the screened escape's draws, counted with the next step

    def _noise(self, escaping: bool) -> np.ndarray | None:
        eng = self.engine
        if escaping:
            assert self.nrng is not None
            return eng.escape.noise * self.nrng.standard_normal(eng.action_dim)
        if self.sampled:
            assert self.nrng is not None
            return eng.options.action_noise * self.nrng.standard_normal(eng.action_dim)
        return None

    def actions(self, st: _State, t: int, escaping: np.ndarray, target: np.ndarray) -> np.ndarray:
        eng, observer, q = self.engine, self.observer, st.q[0]
        per_step, k = observer.draws_one(), eng.options.draws
        blk = per_step * k
        u = eng._uniforms((t + 1) * blk)[t * blk : (t + 1) * blk]
        esc = bool(escaping[0])
        ta = time.perf_counter()
        tb = ta  # observing and acting interleaved are timed as network
        if self.lean is not None and not esc:  # observation and network in one
            lean = self.lean
            a = (
                lean(q, self.goal, u)
                if k == 1
                else np.mean([lean(q, self.goal, u[j * per_step : (j + 1) * per_step]) for j in range(k)], 0)
            )
        elif k == 1:
            obs = observer.observe_one(q, u=u)
            tb = time.perf_counter()
            if esc and eng.escape.tries > 1:
                a = self._furthest(obs, q, target[0], st.paths[: t + 1, 0])
            else:
                a = eng._act(obs, q, target[0], self._noise(esc))
        else:
            a = np.mean(
                [
                    eng._act(
                        observer.observe_one(q, u=u[j * per_step : (j + 1) * per_step]), q, target[0], self._noise(esc)
                    )
                    for j in range(k)
                ],
                0,
            )
        tc = time.perf_counter()
        self.timing.observe += tb - ta
        self.timing.network += tc - tb
        return np.asarray(a, np.float32)[None]

    def _free_move(self, q: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Where action ``a`` takes the robot from ``q`` (``(1, dof)``), as far as it is free."""
        sc = self.scene
        tw = np.clip(a.astype(np.float64), -1.0, 1.0) * self.scale
        return q_free(
            self.robot,
            sc.world,
            q,
            tw,
            sc.low[None],
            sc.high[None],
            self.engine.env.substep,
            clip_target=self.clip_target,
        )

    def _furthest(
        self, obs: np.ndarray, q: np.ndarray, target: np.ndarray, past: np.ndarray | None = None
    ) -> np.ndarray:
        """The screened escape's step: of ``tries`` sampled actions, the one whose free
        motion from ``q`` goes furthest, or whose lookahead does; where none moves, the
        back-off along the path so far ``past`` (:class:`Escape`; ``None``: none); the
        motion checks are counted with the step's."""
        eng = self.engine
        tc = time.perf_counter()
        best, far = None, -np.inf
        for _ in range(eng.escape.tries):
            a = eng._act(obs, q, target, self._noise(True))
            d = self._score(a, q, target)
            if d > far:
                best, far = a, d
        if eng.escape.backoff > 0 and far < _MOVED and past is not None:
            back = _back_off(self.robot, past, q, eng.escape.backoff)
            best = best if back is None else back
        self.timing.motion += time.perf_counter() - tc
        assert best is not None
        return best

    def _score(self, a: np.ndarray, q: np.ndarray, target: np.ndarray) -> float:
        """How far one escape draw ``a`` takes the robot from ``q``: its free motion, or
        its lookahead's (:class:`Escape`); its motion checks are counted with the step's."""
        q1, _, n = self._free_move(q[None], np.asarray(a, np.float32)[None])
        self.pending_checks += int(np.sum(n))
        d = float(np.asarray(self.robot.distance(q1, q[None]))[0])
        if self.engine.escape.lookahead and d >= _MOVED:
            d = self._ahead(q1[0], q, target)
        return d

    def _ahead(self, q1: np.ndarray, q: np.ndarray, target: np.ndarray) -> float:
        """How far from ``q`` the mean action carries the robot in the escape's lookahead
        from ``q1`` (infinite where it arrives at ``target``)."""
        eng, observer = self.engine, self.observer
        u = eng._uniforms(observer.draws_one())[: observer.draws_one()]
        qk = q1[None]
        for _ in range(eng.escape.lookahead):
            a = eng._act(observer.observe_one(qk[0], u=u), qk[0], target, None)
            qk, _, n = self._free_move(qk, np.asarray(a, np.float32)[None])
            self.pending_checks += int(np.sum(n))
            if goal_reached(self.robot, eng.env, qk, target[None], np.zeros(1, bool))[0]:
                return np.inf
        return float(np.asarray(self.robot.distance(qk, q[None]))[0])

    def move(self, a: np.ndarray, st: _State) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        tc = time.perf_counter()
        q, collided, n = self._free_move(st.q, a)
        arrived = goal_reached(self.robot, self.engine.env, q, self.goal[None], collided)
        self.timing.motion += time.perf_counter() - tc
        n, self.pending_checks = n + self.pending_checks, 0
        return q, arrived, np.zeros(1, bool), n

    def goal_free(self, i: int, q: np.ndarray) -> tuple[bool, int]:
        tg = time.perf_counter()
        out = self.tester.free(q)
        self.timing.goal += time.perf_counter() - tg
        return out

    def subgoal(self, i: int) -> np.ndarray:
        assert self.nrng is not None
        return self.robot.sample_uniform(self.nrng, 1, self.scene.low, self.scene.high)[0]


# ---------------------------------------------------------------- the engine
class RolloutEngine:
    """Rolls a policy out on problems (see the module's docstring).

    ``act``: a :class:`~pointplan.models.policy.Policy` (then the one-robot rollout and
    the compiled one are available), or any ``act(obs, q, goal, noise=None) -> actions``
    on batches. ``observer_wrapper``: a function ``observer -> observer`` applied to the
    one-robot observer (noisy or occluded points, static scenes only)."""

    def __init__(
        self,
        act: Policy | ActFn,
        robot: Robot,
        env: EnvConfig,
        options: RolloutOptions | None = None,
        observer_wrapper: Callable[[Any], Any] | None = None,
    ) -> None:
        from ..models.policy import Policy

        self.options = options or RolloutOptions()
        self.act = act
        self.policy = act if isinstance(act, Policy) else None
        self.robot = robot
        meta_horizon = self.policy.meta.get("horizon") if self.policy is not None else None
        self.horizon = int(self.options.horizon or meta_horizon or 50)
        self.env = replace(env, horizon=self.horizon)
        self.escape = self.options.escape_for(robot)
        self.dodge = DODGE_DEFAULT if self.options.dodge is None else self.options.dodge
        self.observer_wrapper = observer_wrapper
        self.action_dim = len(robot.action_scale)
        #: the network as numpy arrays (weights as of now), or None: PyTorch on one thread
        self.fast = self.policy.fast_actor() if self.policy is not None else None
        self._observer: Any = None
        self._compiled: Any = None
        self._compiled_rays: Any = None
        self._stream_rng: np.random.Generator | None = None
        self._stream = np.empty(0)

    # -------------------------------------------------------------- many problems
    def run(
        self,
        problems: Sequence[Problem],
        noise_rng: np.random.Generator | None = None,
        options: RolloutOptions | None = None,
    ) -> list[PlanResult]:
        """Roll out every problem, ``options.chunk`` at a time in lockstep (the time of a
        chunk is shared equally by its problems); the greedy goal test in static scenes.
        Actions are sampled where ``options.noise > 0`` and during escapes, from
        ``noise_rng`` (default: seeded by the seed and the chunk). ``options``: these
        instead of the engine's (same horizon and escape)."""
        opts, results = options or self.options, []
        act = self.act
        for c0 in range(0, len(problems), opts.chunk):
            probs = list(problems[c0 : c0 + opts.chunk])
            t0 = time.perf_counter()
            rng = np.random.default_rng(np.random.SeedSequence([opts.seed, c0]))
            nrng = (
                noise_rng
                if noise_rng is not None
                else np.random.default_rng(np.random.SeedSequence([opts.seed, c0, 0x6E6F6973]))
            )
            dodge = self.dodge if opts.dodge is None else opts.dodge
            sp = _Lockstep(act, self.robot, self.env, probs, rng, nrng, opts.noise, self.escape, dodge)
            greedy = np.array([opts.greedy_goal and not p.scene.dynamic for p in probs])
            st = _State(sp.core.q.copy(), sp.core.goal.copy(), self.horizon, greedy)
            _loop(sp, st, self.horizon, opts, self.escape)
            results += _results(st, probs, self.robot, opts, self.escape, (time.perf_counter() - t0) / len(probs))
        return results

    # -------------------------------------------------------------- one problem
    def plan(self, problem: Problem) -> PlanResult:
        """One problem as a planner plans it: the mean-action rollout, then (``attempts``)
        sampled ones from the start until one succeeds. The draws are seeded by the seed,
        the attempt and the problem's start and goal, so a problem gets the same
        rollouts in any order."""
        opts = self.options
        if opts.attempts > 1 and problem.scene.dynamic:
            raise ValueError(
                "attempts > 1 plans static scenes only: a rollout among moving obstacles cannot start over"
            )
        if problem.scene.dynamic and (self.observer_wrapper is not None or opts.draws > 1):
            raise ValueError("observer_wrapper and draws > 1 plan static scenes only")
        if np.shape(problem.start) != (self.robot.config_dim,):
            raise ValueError(f"problem {problem.tag or ''} does not fit robot {self.robot.name}")
        key = zlib.crc32(
            np.ascontiguousarray(problem.start, np.float64).tobytes()
            + np.ascontiguousarray(problem.goal, np.float64).tobytes()
        )
        first = self._attempt(
            problem, np.random.default_rng(np.random.SeedSequence([opts.seed, 0, key, 0x657363])), sampled=False
        )
        if first.success or opts.attempts == 1:
            return first
        tried = [first]
        for k in range(1, opts.attempts):
            tried.append(
                self._attempt(problem, np.random.default_rng(np.random.SeedSequence([opts.seed, k, key])), sampled=True)
            )
            if tried[-1].success:
                break
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

    @property
    def observer(self) -> Any:
        """The one-robot observer (the environment's, wrapped with ``observer_wrapper``)."""
        if self._observer is None:
            probe = BatchedCore(_GivenProblems(self.robot, self.horizon), 1, self.env)
            obs = probe.observer
            self._observer = obs if self.observer_wrapper is None else self.observer_wrapper(obs)
        return self._observer

    def one_robot(self) -> bool:
        """Can a static problem go through the one-robot stepper? (A policy and an observer
        that observes one robot from a block of uniform draws.)"""
        return self.policy is not None and bool(getattr(self.observer, "one_robot", False))

    def _attempt(self, problem: Problem, nrng: np.random.Generator, sampled: bool) -> PlanResult:
        """One rollout of ``problem``: the mean action (``sampled=False``: ``nrng`` draws
        the escapes) or sampled actions (``nrng`` draws them all)."""
        opts = self.options
        if problem.scene.dynamic or not self.one_robot():
            lock = replace(opts, noise=opts.action_noise if sampled else 0.0)
            with torch_threads(1):
                return self.run([problem], noise_rng=nrng, options=lock)[0]
        t0 = time.perf_counter()
        rays = self.compiled_rays()
        compiled = self.compiled() if not sampled else None
        st, t_compiled = None, None
        if rays is not None or compiled is not None:
            if rays is not None:
                res, handover, t_compiled = rays.rollout(problem, nrng, sampled, t0)
            else:
                assert compiled is not None
                res, handover, t_compiled = compiled.rollout(problem, t0)
            if res is not None:
                return res
            if handover is not None:
                st = _State.resumed(
                    handover[0], np.asarray(problem.goal, np.float64), self.horizon, opts.greedy_goal, handover[1]
                )
        sp = _OneRobot(self, problem, nrng, sampled)
        if st is None:
            st = _State(
                np.asarray(problem.start, np.float64)[None].copy(),
                sp.goal[None].copy(),
                self.horizon,
                np.array([opts.greedy_goal]),
            )
        else:  # the compiled rollout stopped where an escape starts
            st.left[0], st.escapes[0] = self.escape.steps, 1
            if self.escape.subgoal:
                st.subgoals[0] = sp.subgoal(0)
        with torch_threads(1) if self.fast is None else contextlib.nullcontext():
            _loop(sp, st, self.horizon, opts, self.escape)
        res = _results(st, [problem], self.robot, opts, self.escape, 0.0)[0]
        res.info["time_split"] = sp.timing.split(res.nodes)
        if t_compiled is not None:
            res.info["time_split"]["compiled"] = t_compiled
        res.time_s = time.perf_counter() - t0
        return res

    def compiled(self) -> Any:
        """The compiled rollout (:class:`~pointplan.planners.rollout_compiled.CompiledBall`)
        when it applies to this policy, robot and observer; else ``None``."""
        if self._compiled is None:
            from .rollout_compiled import CompiledBall

            ok = self.options.compiled and self.options.draws == 1 and self.observer_wrapper is None
            ok = ok and self.one_robot() and bool(getattr(self.observer, "compiled_points", False))
            self._compiled = (ok and CompiledBall.build(self)) or False
        return self._compiled or None

    def compiled_rays(self) -> Any:
        """The compiled ray-casting rollout
        (:class:`~pointplan.planners.rollout_compiled.CompiledRays`) when it applies to
        this policy, robot and observer; else ``None``."""
        if self._compiled_rays is None:
            from .rollout_compiled import CompiledRays

            ok = self.options.compiled and self.options.draws == 1 and self.observer_wrapper is None
            self._compiled_rays = (ok and self.policy is not None and CompiledRays.build(self)) or False
        return self._compiled_rays or None

    def _act(self, obs: np.ndarray, q: np.ndarray, goal: np.ndarray, noise: np.ndarray | None) -> np.ndarray:
        from ..models.inputs import goal_input, obs_input

        if self.fast is not None:
            return self.fast(obs_input(self.robot, obs[None])[0], goal_input(self.robot, q, goal), noise)
        assert self.policy is not None
        return self.policy(obs[None], q[None], goal[None], None if noise is None else noise[None])[0]

    def _uniforms(self, k: int) -> np.ndarray:
        """The first ``k`` numbers of the stream :meth:`run` draws its first chunk's
        observations from (seed ``(seed, 0)``): the same for every problem, so drawn once
        and kept."""
        if self._stream_rng is None:
            self._stream_rng = np.random.default_rng(np.random.SeedSequence([self.options.seed, 0]))
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
        robot, observer, fast = self.robot, self.observer, self.fast
        if fast is None or not isinstance(robot, (Disc2D, Sphere3D)) or not getattr(observer, "compiled_points", False):
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

    def _lean_step(self) -> Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None:
        """For a robot that only translates, seeing points, with the numpy network:
        ``(q, goal, u) -> action`` for the observation ``observe_one(q, u=u)``, without
        building the observation. The body frame is a translation, so the input layer's
        pre-activations are a per-scene table (:meth:`_fold`) minus one row
        (``q / scale @ W``), gathered for the drawn points: the same arithmetic up to
        float32 round-off (about 1e-7). ``None`` otherwise."""
        fold = self._fold()
        if fold is None:
            return None
        fast, n = self.fast, self.observer.n_points
        assert fast is not None
        table, w_pos, s32, count = fold
        m = max(count, 1)
        scale = self.robot.action_scale

        def step(q: np.ndarray, goal: np.ndarray, u: np.ndarray) -> np.ndarray:
            idx = np.argsort(u[:m])[:n]
            if count < n:
                idx = np.concatenate([idx, (u[m + count : m + n] * count).astype(np.int64)])
            h = table[idx]
            h -= (q / s32).astype(np.float32) @ w_pos
            return fast.from_first_layer(h, ((goal - q) / scale).astype(np.float32))

        return step


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
    dodge: Dodge | None = None,
) -> list[PlanResult]:
    """:meth:`RolloutEngine.run` with the plain rollout's defaults: the mean action to
    the horizon or the goal tolerance, no goal connection, no greedy goal test, no escape,
    no dodge (training validation, DAgger and PPO call this). ``greedy_goal`` raises a ValueError
    when a scene has moving obstacles."""
    if greedy_goal and any(p.scene.dynamic for p in problems):
        raise ValueError("greedy_goal connects to the goal in static scenes only")
    opts = RolloutOptions(
        horizon=horizon,
        greedy_goal=greedy_goal,
        connect_goal=connect_goal,
        escape=escape if escape is not None else ESCAPE_OFF,
        noise=noise,
        seed=seed,
        crush_ends=crush_ends,
        dodge=dodge if dodge is not None else DODGE_OFF,
        chunk=chunk,
    )
    return RolloutEngine(act, robot, env, opts).run(problems, noise_rng=noise_rng)


__all__ = [
    "DODGE_DEFAULT",
    "DODGE_OFF",
    "Dodge",
    "ESCAPE_DEFAULTS",
    "default_escape",
    "ESCAPE_OFF",
    "Escape",
    "GoalTester",
    "RolloutEngine",
    "RolloutOptions",
    "connect_to_goal",
    "rollout_batch",
    "torch_threads",
]
