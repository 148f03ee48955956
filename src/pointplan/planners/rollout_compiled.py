"""The compiled forms of the rollout engine's one-robot rollout, each a whole rollout in
one numba call with the same greedy goal test, action, move and end tests as the step loop
of :mod:`pointplan.planners.rollout`, in the same arithmetic:

- :class:`CompiledBall`: a translating ball (the disc, the sphere) among boxes, seeing a
  uniform subset of the scene's points (:func:`._policy_kernels._rollout`);
- :class:`CompiledRays`: a free-flying body of boxes (the S-shape) among boxes, seeing by
  ray casting (``local``), escapes and sampled attempts included
  (:func:`._rigid_kernels.rollout_rigid`).

Most of a call's time beyond the network is not arithmetic but memory: a caller does
other work between plans, and every Python and numpy operation here then waits for code
and data the call has not touched for a while (measured: a plain ``np.empty`` or
``np.asarray`` takes 5-15 us in that state instead of 0.2). So this path does as few
operations as it can: the kernel's arguments are prepared once per engine and per scene
(the last scene's are kept), the kernel writes the whole path (the goal included) into
one array and returns plain integers, and the result's ``info`` comes from a per-end-code
table.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ..geometry.shapes import Box
from ..observers.rays import LocalRays, WideRays
from ..robots.point import Disc2D, Sphere3D
from ..robots.sshape import OrientedSShape
from ..scenes.scene import Problem, Scene
from . import _policy_kernels as K
from . import _rigid_kernels as RK
from .base import PlanResult

if TYPE_CHECKING:
    from ..envs.core import EnvConfig
    from ..robots.base import Robot


class EngineView(Protocol):
    """What the compiled rollout reads of its rollout engine."""

    fast: Any
    robot: Robot
    env: EnvConfig
    options: Any
    escape: Any
    horizon: int

    @property
    def observer(self) -> Any: ...

    def _uniforms(self, k: int) -> np.ndarray: ...


_F64 = np.dtype(np.float64)
#: ``info["end"]`` of the compiled rollouts' end codes (``_policy_kernels.END_*``, then
#: ``_rigid_kernels.END_AT_GOAL``)
END_NAMES = ("horizon", "stalled", "goal", "goal", "near-goal", "near-goal", "escape", "goal")


class CompiledBall:
    """The compiled rollout of one engine (see the module's docstring); made by :meth:`build`."""

    def __init__(
        self,
        engine: EngineView,
        weights: tuple[np.ndarray, np.ndarray],
        scale: np.ndarray,
        fparams: np.ndarray,
        iparams: np.ndarray,
    ) -> None:
        self.engine = engine
        self.args = (*weights, scale, fparams, iparams)
        self._scene: Scene | None = None
        self._scene_args: tuple[np.ndarray, ...] | None = None
        self._path_shape = (engine.horizon + 2, engine.robot.config_dim)
        self._end_entries = self._end_table()

    @classmethod
    def build(cls, engine: EngineView) -> CompiledBall | None:
        """The compiled rollout of ``engine``, or ``None`` where it does not apply (not a
        ball, not a PointNet in numpy, hidden layers of another width)."""
        fast, robot, env, opts, esc = engine.fast, engine.robot, engine.env, engine.options, engine.escape
        if fast is None or not isinstance(robot, (Disc2D, Sphere3D)):
            return None
        width = fast.inp[0].shape[1]
        if any(w.shape != (width, width) for w, _ in fast.hidden) or fast.head[0][0].shape[0] != width + robot.dim:
            return None
        fparams = np.zeros(7)
        fparams[[K.F_RADIUS, K.F_SUBSTEP, K.F_GOAL_TOL, K.F_STALL_DIST, K.F_RESOLUTION, K.F_S32, K.F_ESC_STILL]] = (
            robot.radius,
            env.substep,
            env.goal_tolerance,
            opts.stall_distance,
            0.01,  # the goal edge: as connect_to_goal checks it
            float(np.float32(robot.action_scale[0])),
            esc.still if esc.on else 0.0,
        )
        iparams = np.zeros(8, np.int64)
        iparams[
            [
                K.I_HORIZON,
                K.I_STALL_STEPS,
                K.I_GREEDY,
                K.I_CONNECT,
                K.I_CLIP,
                K.I_N_POINTS,
                K.I_ACTION_DIM,
                K.I_ESC_WINDOW,
            ]
        ] = [
            int(engine.horizon),
            int(opts.stall_steps or 0),
            int(opts.greedy_goal),
            int(opts.connect_goal),
            int(env.bounds == "clip"),
            int(engine.observer.n_points),
            int(fast.action_dim),
            int(esc.window) if esc.on else 0,  # the compiled rollout stops where an escape starts
        ]
        return cls(
            engine,
            K.pack_weights(fast.inp, fast.hidden, fast.head),
            np.ascontiguousarray(robot.action_scale, np.float64),
            fparams,
            iparams,
        )

    def rollout(
        self, problem: Problem, t0: float
    ) -> tuple[PlanResult | None, tuple[np.ndarray, int] | None, float | None]:
        """``(result, None, None)``: the whole rollout; ``(None, (path, checks), seconds)``:
        it stopped where an escape starts, and the step loop goes on from there; ``(None,
        None, None)``: the scene is not boxes only (or has no points)."""
        scene = problem.scene
        if scene is not self._scene:
            self._scene_args = self._scene_inputs(scene)
            self._scene = scene
        args = self._scene_args
        if args is None:
            return None, None, None
        start, goal = problem.start, problem.goal
        if start.dtype is not _F64 or goal.dtype is not _F64:
            start, goal = np.asarray(start, np.float64), np.asarray(goal, np.float64)
        path = np.empty(self._path_shape)
        t1 = time.perf_counter()
        end, rows, checks, _ = K._rollout(start, goal, *args, path)  # type: ignore[call-arg]
        t2 = time.perf_counter()
        if end == K.END_ESCAPE:
            return None, (path[:rows].copy(), int(checks)), t2 - t1
        success, to_goal, entries = self._end_entries[end]
        steps = rows - 1 - to_goal
        info = {
            "time_split": {
                "observe": 0.0,
                "network": 0.0,
                "motion": 0.0,
                "goal": 0.0,
                "compiled": t2 - t1,
                "steps": steps,
            },
            **entries,
        }
        return PlanResult(path[:rows], success, steps, checks, time.perf_counter() - t0, info=info), None, None

    def _scene_inputs(self, scene: Scene) -> tuple[Any, ...] | None:
        """The kernel's arguments after the start and the goal for ``scene`` (its bounds,
        boxes and other primitives, the observer's points, the engine's arguments, the
        random stream long enough for the scene), or ``None`` when the scene has obstacles
        other than boxes, spheres, capsules, cylinders and cones, or no points."""
        observer = self.engine.observer
        observer.set_scene(0, scene)
        world = scene.world
        if world.batch_shape != () or not world.primitives_only:
            return None
        pts, nrm = observer.points_one()
        if not len(pts):
            return None
        f = np.ascontiguousarray
        nrm = f(nrm, np.float64) if observer.with_normals else np.zeros((len(pts), 0))
        boxes = world.box_arrays()
        stream = self.engine._uniforms(self.engine.horizon * (max(len(pts), 1) + observer.n_points))
        return (scene.low, scene.high, *boxes, world.ball_prims(), f(pts, np.float64), nrm, *self.args, stream)

    def _end_table(self) -> tuple[tuple[bool, bool, dict[str, Any]], ...]:
        """Per end code: success, whether the path ends at the goal, and the ``info``
        entries of the result (those the step loop sets)."""
        rows = []
        opts = self.engine.options
        for end, name in enumerate(END_NAMES):
            to_goal = end in (K.END_GREEDY, K.END_TOL_GOAL)
            success = to_goal or end in (K.END_TOL_BLOCKED, K.END_TOL)
            entries: dict[str, Any] = {"end": name}
            if self.engine.escape.on:
                entries["escapes"] = 0  # (a rollout that escapes goes on in the step loop, which counts them)
            if end == K.END_GREEDY:
                entries["greedy_goal"] = True
            if to_goal or end == K.END_TOL_BLOCKED:
                entries["goal_connection"] = "free" if to_goal else "blocked"
            elif opts.connect_goal and not success:
                entries["goal_connection"] = None
            rows.append((success, to_goal, entries))
        return tuple(rows)


def _boxes_only(scene: Scene) -> bool:
    """Is every obstacle of the static scene a box (what the compiled rollouts check)?"""
    world = scene.world
    return (
        not scene.dynamic
        and world.batch_shape == ()
        and world.box_c.shape[0] == len(scene.obstacles)
        and all(type(o) is Box for o in scene.obstacles)
    )


class CompiledRays:
    """The compiled rollout of an engine whose robot is the sphere or a free-flying body of
    boxes (the S-shape) seeing rays (:class:`~pointplan.observers.rays.LocalRays`), or the
    S-shape seeing a subset of the scene's points (``global``): one call per attempt, in
    scenes of boxes, the same rollout as the one-robot step loop's. The mean action with its escape,
    or a sampled attempt; an escape toward a subgoal (the sphere's) is left to the step
    loop, which goes on from where it starts. Made by :meth:`build`."""

    def __init__(
        self,
        engine: EngineView,
        kind: int,
        body: tuple[np.ndarray, ...],
        rays: tuple[np.ndarray, ...] | None,
        axes: bool = False,
    ) -> None:
        self.engine = engine
        fast, robot = engine.fast, engine.robot
        self.kind, self.body = kind, body
        self.sees = RK.RAYS if rays is not None else RK.POINTS
        self.rays = rays if rays is not None else (np.zeros((0, 3)), np.zeros((0, 3)))
        self.weights = K.pack_weights(fast.inp, fast.hidden, fast.head)
        self.scale = np.ascontiguousarray(robot.action_scale, np.float64)
        self._scene: Scene | None = None
        self._scene_args: tuple[Any, ...] | None = None
        #: the goal input carries the world's axes in the body frame (``I_AXES``)
        self.axes = axes

    @classmethod
    def build(cls, engine: EngineView) -> CompiledRays | None:
        """The compiled rollout of ``engine``, or ``None`` where it does not apply (another
        robot or observer, a network of another shape)."""
        fast, robot, observer = engine.fast, engine.robot, engine.observer
        rays = type(observer) in (LocalRays, WideRays)
        points = bool(getattr(observer, "compiled_points", False)) and getattr(observer, "with_normals", False)
        if fast is None or not (rays or (points and not isinstance(robot, Sphere3D))):
            return None  # (the sphere seeing points has CompiledBall)
        f = np.ascontiguousarray
        parts = robot.parts
        if isinstance(robot, Sphere3D):
            kind, body = RK.BALL, (np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((6, 0)))
        elif (
            robot.dim == 3
            and robot.twist_dim == 6
            and robot.config_dim == 7
            and not len(parts.sphere_radii)
            and len(parts.box_halfs)
            and np.array_equal(parts.box_rotations, np.broadcast_to(np.eye(3), parts.box_rotations.shape))
        ):
            kind = RK.BODY
            body = (f(parts.box_centers, np.float64), f(parts.box_halfs, np.float64), f(robot._corner_velocity))
        else:
            return None
        width, adim = fast.inp[0].shape[1], robot.twist_dim
        # the goal input beside the twist: nothing, or the world's axes in the body frame
        axes = isinstance(robot, OrientedSShape) and kind == RK.BODY
        if robot.state_feature_dim != (9 if axes else 0):
            return None
        if (
            any(w.shape != (width, width) for w, _ in fast.hidden)
            or fast.head[0][0].shape[0] != width + adim + robot.state_feature_dim
            or fast.action_dim != adim
        ):
            return None
        if fast.inp[0].shape[0] != 6 or robot.dim != 3:
            return None
        seen = (f(observer.body_origins, np.float64), f(observer.body_dirs, np.float64)) if rays else None
        return cls(engine, kind, body, seen, axes)

    def _scene_inputs(self, scene: Scene) -> tuple[Any, ...] | None:
        """The obstacles of ``scene`` as the kernel takes them (its boxes; for the S-shape
        seeing points, also a point cloud's grid), the boxes rays hit (with the wall slabs)
        or the points the robot sees; ``None`` where the scene has other obstacles."""
        world, observer = scene.world, self.engine.observer
        clouds = self.kind == RK.BODY and not scene.dynamic
        if not (_boxes_only(scene) or (clouds and world.batch_shape == () and world.boxes_and_clouds_only)):
            return None
        f = np.ascontiguousarray
        boxes = world.box_arrays()
        if clouds:
            boxes = self.engine.robot._obstacles(world)  # type: ignore[attr-defined]  # (boxes and the cloud grid)
        empty = np.zeros((0, 3))
        if self.sees == RK.POINTS:
            observer.set_scene(0, scene)
            pts, nrm = (f(a, np.float64) for a in observer.points_one())
            rboxes: tuple[Any, ...] = (empty, np.zeros((0, 3, 3)), empty, np.zeros(0, bool))
        else:
            rw = observer.ray_world(scene)
            pts, nrm = empty, empty
            rboxes = (
                f(rw.box_c, np.float64),
                f(rw.box_r, np.float64),
                f(rw.box_h, np.float64),
                np.any(rw.box_h > 0, -1),
            )
            # (cells twice the point radius: a ray tests the points of the 27 cells around
            # each cell it crosses, few where they are small)
            ray_grid = rw.cloud_ray_grid(2.0 * float(rw.cloud_radius[0])) if clouds and rw.cloud_radius else None
            if ray_grid is not None:  # the rays hit the cloud's points too
                rboxes = (*rboxes, *ray_grid)
        return boxes, rboxes, pts, nrm, f(scene.low, np.float64), f(scene.high, np.float64)

    def _params(self, sampled: bool) -> tuple[np.ndarray, np.ndarray]:
        """The kernel's ``fparams`` and ``iparams`` for an attempt."""
        eng = self.engine
        opts, esc, env, observer = eng.options, eng.escape, eng.env, eng.observer
        fparams = np.zeros(12)
        fparams[[RK.F_SUBSTEP, RK.F_GOAL_TOL, RK.F_STALL_DIST, RK.F_RESOLUTION, RK.F_S0]] = (
            env.substep,
            env.goal_tolerance,
            opts.stall_distance,
            0.01,  # the goal edge: as GoalTester and connect_to_goal check it
            float(eng.robot.action_scale[0]),
        )
        fparams[[RK.F_ESC_STILL, RK.F_ESC_NOISE, RK.F_NOISE, RK.F_RANGE, RK.F_SPACING, RK.F_RADIUS]] = (
            esc.still,
            esc.noise,
            opts.action_noise if sampled else 0.0,
            getattr(observer, "max_range", 0.0),  # (rays only)
            observer.spacing,
            float(getattr(eng.robot, "radius", 0.0)),
        )
        fparams[RK.F_BACKOFF] = esc.backoff
        iparams = np.zeros(16, np.int64)
        iparams[:] = (
            eng.horizon,
            int(opts.stall_steps or 0),
            int(opts.greedy_goal),
            int(opts.connect_goal),
            int(env.bounds == "clip"),
            int(observer.n_points),
            eng.robot.twist_dim,
            esc.window,
            esc.steps if esc.on else 0,
            int(sampled),
            self.kind,
            int(esc.on and esc.subgoal),  # an escape toward a subgoal: the step loop's
            self.sees,
            esc.tries,
            esc.lookahead,
            int(self.axes),
        )
        return fparams, iparams

    def rollout(
        self, problem: Problem, nrng: np.random.Generator, sampled: bool, t0: float
    ) -> tuple[PlanResult | None, tuple[np.ndarray, int] | None, float | None]:
        """One attempt of ``RolloutEngine.plan`` (the mean action with the escape drawn
        from ``nrng``, or with ``sampled`` every action drawn from it): ``(result, None,
        None)``; ``(None, (path, checks), seconds)`` where an escape toward a subgoal
        starts (the step loop goes on from there); ``(None, None, None)`` where it does
        not apply (a scene not of boxes only; a sampled attempt with subgoal escapes)."""
        esc = self.engine.escape
        if sampled and esc.on and esc.subgoal:
            return None, None, None
        scene = problem.scene
        if scene is not self._scene:
            self._scene_args = self._scene_inputs(scene)
            self._scene = scene
        if self._scene_args is None:
            return None, None, None
        boxes, rboxes, pts, nrm, low, high = self._scene_args
        eng = self.engine
        horizon, adim = eng.horizon, eng.robot.twist_dim
        # the sampled steps' normal draws, in the order the step loop takes them
        noisy = sampled or (esc.on and not esc.subgoal)
        # (a screened escape takes ``tries`` rows a step)
        normals = nrng.standard_normal((horizon * max(1, esc.tries), adim)) if noisy else np.zeros((0, adim))
        fparams, iparams = self._params(sampled)
        start, goal = (np.ascontiguousarray(x, np.float64) for x in (problem.start, problem.goal))
        path = np.empty((horizon + 2, eng.robot.config_dim))
        blk = (max(len(pts), 1) if self.sees == RK.POINTS else len(self.rays[0])) + int(eng.observer.n_points)
        stream = eng._uniforms(horizon * blk)
        t1 = time.perf_counter()
        end, rows, checks, escapes = RK.rollout_rigid(
            start, goal, low, high, boxes, rboxes, pts, nrm, self.body, self.rays, *self.weights, self.scale, fparams,
            iparams, stream, normals, path,
        )  # fmt: skip
        t2 = time.perf_counter()
        if end == K.END_ESCAPE:
            return None, (path[:rows].copy(), int(checks)), t2 - t1
        return self._result(end, path[:rows], checks, escapes, t2 - t1, time.perf_counter() - t0), None, None

    def _result(self, end: int, path: np.ndarray, checks: int, escapes: int, dt: float, total: float) -> PlanResult:
        """The :class:`PlanResult` the step loop gives for a rollout that ended so."""
        opts = self.engine.options
        to_goal = end in (K.END_GREEDY, K.END_TOL_GOAL)
        success = to_goal or end in (K.END_TOL_BLOCKED, K.END_TOL, RK.END_AT_GOAL)
        info: dict[str, Any] = {"end": END_NAMES[end]}
        if end == K.END_GREEDY:
            info.update(goal_connection="free", greedy_goal=True)
        elif end in (K.END_TOL_GOAL, K.END_TOL_BLOCKED, RK.END_AT_GOAL):
            info["goal_connection"] = "blocked" if end == K.END_TOL_BLOCKED else "free"
        elif opts.connect_goal and not success:
            info["goal_connection"] = None
        if self.engine.escape.on:
            info["escapes"] = int(escapes)
        if not opts.crush_ends:
            info["crushed"] = 0
        steps = len(path) - 1 - int(to_goal)
        info["time_split"] = {
            "observe": 0.0,
            "network": 0.0,
            "motion": 0.0,
            "goal": 0.0,
            "compiled": dt,
            "steps": steps,
        }
        return PlanResult(path, success, steps, int(checks), total, info=info)


__all__ = ["END_NAMES", "CompiledBall", "CompiledRays"]
