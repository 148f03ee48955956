"""A privileged expert for Slot: one threading of the slot, placed on every slot.

Demonstrations from Bi-RRT thread each slot in their own way, and a policy cloned from them
averages the ways (``docs/notebook/slot.md``). This expert always threads the same way. Its
*template* is a path through a reference slot (centred, long along y, ``width_bars`` bar
thicknesses wide), planned once by :func:`template_candidates` (the guided sweep of
:mod:`pointplan.planners.slot_sweep`, simplified; ``scripts/slot_expert.py template``
certifies it and writes it with :func:`save_template`) and shipped as
``data/slot_threading.npz``. It serves every slot at least that wide:

- a slot centred elsewhere is the reference wall moved along itself: move the template;
- a slot long along z is the reference turned 90 degrees about x: turn the template;
- a wider opening at the same centre leaves less wall: a path free in the narrow slot is
  free in the wide one.

A path from a configuration ``q`` (the problem's start, or a state a policy reached, for
DAgger) is: a certified straight edge from ``q`` to the last template pose in the opening
it reaches, or else to the template's first pose (0.3 before the wall; Bi-RRT where the
straight edge collides), the template on from there, and a straight edge (or Bi-RRT) to
the goal. The expert reads the slot's width, centre and long axis from the scene: it is for
demonstrations, not a planner for unknown scenes.

With ``copies=True`` the expert also uses the template's symmetric copies. The wall with its
opening is unchanged by a half turn about the wall's normal through the opening's centre,
and by a half turn about the opening's long or short axis, which swaps the wall's sides:
so the template turned about the normal threads the slot, and so does the template run
backwards and turned about either axis in the wall. Of the four, the expert takes the one
whose approach pose is turned least from the robot (from the start side), or whose nearest
pose is (once the robot is at the wall), so that the approach asks for less turning.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Sequence
from importlib import resources
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..robots.base import Robot
from ..robots.sshape import BAR_THICKNESS, SShape
from ..scenes.scene import Problem
from ..scenes.scenes3d import SlotScenario
from .birrt import BiRRT
from .edges import edge_free

#: the turn that takes a slot long along y to one long along z (90 degrees about x)
TURN = Rotation.from_euler("x", 90, degrees=True)
#: the half turns that leave the reference wall and its opening where they are, each with
#: whether the template runs backwards under it (a turn about y or z swaps the wall's sides)
SYMMETRIES = (
    (Rotation.identity(), False),
    (Rotation.from_euler("x", 180, degrees=True), False),
    (Rotation.from_euler("y", 180, degrees=True), True),
    (Rotation.from_euler("z", 180, degrees=True), True),
)
#: metres of distance that weigh as much as a radian of turn, when the nearest pose is sought
METRES_PER_RADIAN = 0.1
#: how far before and past the wall (along x) a template's first and last poses are moved
BACK = 0.3


def _turn_angle(qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    """Angles (radians) between unit quaternions ``(..., 4)``, either sign."""
    d = np.abs(np.sum(np.asarray(qa) * np.asarray(qb), -1))
    return 2.0 * np.arccos(np.clip(d, 0.0, 1.0))


def symmetric_copy(template: np.ndarray, k: int) -> np.ndarray:
    """Copy ``k`` (0-3, :data:`SYMMETRIES`) of a template in the reference slot."""
    rot, backwards = SYMMETRIES[k]
    out = np.asarray(template, np.float64).copy()
    if backwards:
        out = out[::-1].copy()
    out[:, :3] = rot.apply(out[:, :3])
    out[:, 3:] = (rot * Rotation.from_quat(out[:, 3:])).as_quat()
    return out


class SlotThreading:
    """The expert of one template (``(N, 7)`` poses in the reference slot, the first before
    the wall, the last past it)."""

    def __init__(
        self, robot: Robot, template: np.ndarray, width_bars: float, max_nodes: int = 2000, copies: bool = False
    ) -> None:
        template = np.asarray(template, np.float64)
        if template.ndim != 2 or template.shape[1] != robot.config_dim or len(template) < 2:
            raise ValueError(f"a template is (N >= 2, {robot.config_dim}) poses, not {template.shape}")
        self.robot, self.template, self.width_bars, self.max_nodes = robot, template, float(width_bars), int(max_nodes)
        self.copies = bool(copies)

    @classmethod
    def load(
        cls, robot: Robot, path: str | Path | None = None, max_nodes: int = 2000, copies: bool = False
    ) -> SlotThreading:
        """The template in ``path`` (``np.savez`` with ``poses`` and ``width_bars``), by
        default the one shipped in the package."""
        if path is None:
            with resources.as_file(resources.files("pointplan") / "data" / "slot_threading.npz") as f:
                return cls.load(robot, f, max_nodes, copies)
        with np.load(Path(path)) as z:
            return cls(robot, np.array(z["poses"]), float(z["width_bars"]), max_nodes, copies)

    def threads(self, slot: dict) -> bool:
        """Is the slot at least as wide as the template's?"""
        return float(slot["width"]) / BAR_THICKNESS >= self.width_bars - 1e-9

    def place(self, slot: dict, copy: int = 0) -> np.ndarray:
        """The template (or its symmetric copy ``copy``, 0-3) moved (and turned) onto
        ``slot`` (the scene's ``slot`` entry)."""
        out = symmetric_copy(self.template, copy) if copy else self.template.copy()
        if int(slot["long_axis"]) == 2:
            out[:, :3] = TURN.apply(out[:, :3])
            out[:, 3:] = (TURN * Rotation.from_quat(out[:, 3:])).as_quat()
        out[:, 1:3] += np.asarray(slot["center"], np.float64)[1:3]
        return out

    def choose(self, slot: dict, q: np.ndarray) -> np.ndarray:
        """The placed template to follow from ``q``: the template itself, or with ``copies``
        the copy turned least from ``q`` at its approach pose (``q`` before the approach
        pose along x) or at its nearest pose (distance plus turn, ``q`` at the wall)."""
        if not self.copies:
            return self.place(slot)
        q = np.asarray(q, np.float64)
        placed = [self.place(slot, k) for k in range(len(SYMMETRIES))]
        if q[0] <= placed[0][0, 0]:
            cost = [float(_turn_angle(q[3:], t[0, 3:])) for t in placed]
        else:
            cost = [
                float(
                    np.min(np.linalg.norm(t[:, :3] - q[:3], axis=1) / METRES_PER_RADIAN + _turn_angle(q[3:], t[:, 3:]))
                )
                for t in placed
            ]
        return placed[int(np.argmin(cost))]

    def _connect(self, problem: Problem, a: np.ndarray, b: np.ndarray, seed: int) -> np.ndarray | None:
        if edge_free(self.robot, problem, a, b)[0]:
            return np.array([a, b])
        r = BiRRT(self.robot, seed=seed, max_nodes=self.max_nodes).plan(Problem(problem.scene, a, b))
        return np.asarray(r.path) if r.success else None

    def plan(self, problem: Problem, start: np.ndarray | None = None, seed: int = 0) -> np.ndarray | None:
        """A path from ``start`` (default: the problem's) to the problem's goal that threads
        the slot the template's way, or ``None`` (a slot narrower than the template, or no
        way found to join it). The path is not re-checked here: its edges are certified by
        :func:`edge_free` and Bi-RRT; the evaluator's ``check_path`` is the independent check."""
        slot = problem.scene.__dict__.get("slot")
        if slot is None:
            raise ValueError("the slot threading expert needs a Slot scene (its scene has no 'slot' entry)")
        if not self.threads(slot):
            return None
        q = np.asarray(problem.start if start is None else start, np.float64)
        t = self.choose(slot, q)
        goal = np.asarray(problem.goal, np.float64)
        # already past the wall: straight to the goal if that is free
        if edge_free(self.robot, problem, q, goal)[0]:
            return np.array([q, goal])
        head, rest = None, t[1:]
        for k in range(len(t) - 1, 0, -1):  # the last template pose a straight edge reaches
            # the first pose in the opening only from nearer than the approach pose: from
            # farther, the approach (pose 0, then straight along x) is the canonical way in
            near = k > 1 or np.linalg.norm(q[:3] - t[1, :3]) <= np.linalg.norm(t[0, :3] - t[1, :3])
            if near and edge_free(self.robot, problem, q, t[k])[0]:
                head, rest = np.array([q, t[k]]), t[k + 1 :]
                break
        if head is None:
            head = self._connect(problem, q, t[0], seed)
            if head is None:
                return None
        tail = self._connect(problem, t[-1], goal, seed + 1)
        if tail is None:
            return None
        return np.concatenate([head, rest, tail[1:]])


def reference_problem(width_bars: float) -> Problem:
    """A problem in the reference slot (centred, long along y, ``width_bars`` bar
    thicknesses wide); its start and goal are placeholders, a template does not use them."""
    scene = SlotScenario("sshape").wall(width_bars * BAR_THICKNESS, np.zeros(3), 1)
    q = np.array([-0.4, 0, 0, 0, 0, 0, 1.0])
    return Problem(scene, q, q)


def template_candidates(
    width_bars: float,
    seed: int = 0,
    tries: int = 2,
    orders: Sequence[str] = ("A", "E"),
    ds: float = 0.004,
    min_clearance: float = 0.0015,
    guide: float = 0.05,
    margin: float = 0.0,
    log: Callable[[str], None] | None = None,
) -> Iterator[tuple[str, np.ndarray]]:
    """Templates for the reference slot of ``width_bars``, in the order they are found: for
    each of ``tries`` rounds and each leading bar of ``orders``, the guided sweep through the
    slot (:func:`pointplan.planners.slot_sweep.sweep`; one random stream, seeded by
    ``seed``, for them all), simplified for the body grown by ``margin`` (so that the
    shortcuts keep that room), its first pose moved :data:`BACK` before the wall and its
    last :data:`BACK` past it. Yields ``(leading bar, (N, 7) poses)``; the next is planned
    only when asked for. They are not certified here: the caller checks each in
    :func:`reference_problem` (the evaluator's ``check_path``) and keeps the first that
    passes. ``log`` gets a line per sweep and why a sweep gave up."""
    from .slot_sweep import simplify, sweep

    robot = SShape()
    problem = reference_problem(width_bars)
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    for attempt in range(tries):
        for order in orders:
            poses = sweep(robot, problem, order, ds, rng, log, min_clearance, guide)
            if log is not None:
                log(
                    f"try {attempt}, led by {order}: {'found' if poses is not None else 'stuck'} ({time.perf_counter() - t0:.0f} s)"
                )
            if poses is None:
                continue
            raw = np.array(poses)
            ends = Problem(problem.scene, raw[0], raw[-1])
            path = simplify(robot.padded(margin) if margin > 0 else robot, ends, raw, seed)
            first, last = path[0].copy(), path[-1].copy()
            first[0] -= BACK
            last[0] += BACK
            yield order, np.concatenate([first[None], path, last[None]])


def save_template(
    path: str | Path, poses: np.ndarray, width_bars: float, order: str, seed: int, clearance: float
) -> None:
    """Write a template as :meth:`SlotThreading.load` reads it (``np.savez``: ``poses`` and
    ``width_bars``, with the leading bar, the seed and the certified clearance it was made
    with)."""
    np.savez(
        path,
        poses=np.asarray(poses, np.float64),
        width_bars=float(width_bars),
        order=str(order),
        seed=int(seed),
        clearance=float(clearance),
    )
