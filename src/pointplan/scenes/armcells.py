"""Arm cells: random workcells for an arm (tables, shelves, cabinets and cages), the
training ground of the learned arm policy.

Every workspace holds one piece of furniture around the arm's base, turned by a random yaw
and placed at a random distance, with random sizes and clutter; the kind is drawn from the
workspace's own random stream:

``table``
    a table top on four legs with 2-6 objects (boxes and upright cylinders) on it; one end
    of a problem has the hand above the top among the objects, or under the top;
``shelf``
    a bookcase facing the arm: 2-4 boards 0.22-0.38 m apart, side panels, sometimes a back
    panel, cylinders standing on the boards; one end has the hand in a compartment;
``cabinet``
    a box open toward the arm (floor, top, back and sides), its front fully open, closed
    below by a low wall, or crossed by 1-2 horizontal bars (a cage), sometimes an object
    inside; one end has the hand inside.

The other end of a problem is a free configuration whose hand is outside the furniture,
or (shelves, one time in three) in another compartment. Both ends are free for the arm
(obstacles and self-collision), drawn uniformly in joint space by rejection with their
hand in the target region; the sampler prefers pairs whose straight joint-space line is
blocked (up to ``problem_tries`` pairs). The sizes cover MotionBenchMaker's scenes without
copying them: MotionBenchMaker is the test set and nothing is trained on it.

Train, val and test workspaces come from disjoint streams (the seeding of the 3D
scenarios). The default arm is the Panda; any :class:`~pointplan.robots.arm.ArmRobot` works.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..geometry.shapes import Cylinder, Shape
from ..robots.arm import ArmRobot, make_arm
from ..robots.base import Robot
from .base import Scenario
from .cluttered import Frame, Region, yaw_matrix
from .mbm import JointSpaceScene
from .scene import Scene
from .scenes3d import workspace_rng

Array = NDArray[np.float64]

#: the furniture kinds, drawn uniformly
KINDS = ("table", "shelf", "cabinet")


@dataclass
class Cell:
    """A built cell: its ``kind``, obstacles, the regions where one end's hand goes, and
    the ``hull`` the other end's hand stays out of."""

    kind: str
    obstacles: list[Shape]
    inside: list[Region]
    hull: Region


def _frame(rng: np.random.Generator, near: tuple[float, float], floor: float) -> Frame:
    """A furniture frame facing the arm: local x points away from the base, the local
    origin is on the furniture's near face at distance ``near`` (drawn), height ``floor``."""
    yaw = float(rng.uniform(-math.pi, math.pi))
    rot = yaw_matrix(yaw)
    d = float(rng.uniform(*near))
    return Frame(rot @ np.array([d, 0.0, 0.0]) + np.array([0.0, 0.0, floor]), rot)


def _objects(
    frame: Frame, rng: np.random.Generator, n: int, area: tuple[float, float, float, float], z: float, top: float
) -> list[Shape]:
    """``n`` objects standing at local height ``z`` in ``area = (x0, x1, y0, y1)``: small
    boxes or upright cylinders, at most ``top - z`` tall."""
    out: list[Shape] = []
    room = max(top - z, 0.06)
    for _ in range(n):
        x, y = rng.uniform(area[0], area[1]), rng.uniform(area[2], area[3])
        h = float(rng.uniform(0.05, min(0.3, room - 0.01)))
        if rng.random() < 0.5:
            sx, sy = rng.uniform(0.04, 0.16, 2)
            out.append(
                frame.box([x - sx / 2, y - sy / 2, z], [x + sx / 2, y + sy / 2, z + h], float(rng.uniform(-1, 1)))
            )
        else:
            r = float(rng.uniform(0.02, 0.05))
            centre = frame.origin + frame.rotation @ np.array([x, y, z + h / 2])
            out.append(Cylinder(centre, r, h))
    return out


def build_table(rng: np.random.Generator) -> Cell:
    depth, width, thick = float(rng.uniform(0.5, 1.0)), float(rng.uniform(0.8, 1.8)), 0.04
    height = float(rng.uniform(-0.15, 0.4))
    f = _frame(rng, (0.15, 0.45), 0.0)
    hw = width / 2
    obstacles: list[Shape] = [f.box([0, -hw, height - thick], [depth, hw, height])]
    leg = 0.05
    for x in (0.0, depth - leg):
        for y in (-hw, hw - leg):
            obstacles.append(f.box([x, y, -1.0], [x + leg, y + leg, height - thick]))
    reach_x = min(depth, 0.55)
    area = (0.05, reach_x, -min(hw, 0.5) + 0.05, min(hw, 0.5) - 0.05)
    obstacles += _objects(f, rng, int(rng.integers(2, 7)), area, height, height + 0.3)
    above = f.region([0.05, area[2], height + 0.04], [reach_x, area[3], height + 0.3])
    under = f.region([0.1, area[2], max(height - 0.45, -0.6)], [reach_x, area[3], height - thick - 0.08])
    inside = [above, under] if height > -0.05 and rng.random() < 0.4 else [above]
    hull = f.region([0.0, -hw, -1.0], [depth, hw, height + 0.3])
    return Cell("table", obstacles, inside, hull)


def build_shelf(rng: np.random.Generator) -> Cell:
    depth, width, thick = float(rng.uniform(0.25, 0.45)), float(rng.uniform(0.6, 1.2)), 0.03
    f = _frame(rng, (0.35, 0.7), 0.0)
    hw = width / 2
    z = float(rng.uniform(-0.5, 0.1))
    boards, inside = [z], []
    obstacles: list[Shape] = []
    for _ in range(int(rng.integers(2, 5))):
        gap = float(rng.uniform(0.22, 0.38))
        inside.append(
            f.region([0.04, -hw + 0.08, boards[-1] + 0.05], [depth - 0.04, hw - 0.08, boards[-1] + gap - 0.05])
        )
        boards.append(boards[-1] + gap)
    for b in boards:
        obstacles.append(f.box([0, -hw, b - thick], [depth, hw, b]))
    top = boards[-1]
    for y in (-hw - thick, hw):
        obstacles.append(f.box([0, y, boards[0] - thick], [depth, y + thick, top]))
    if rng.random() < 0.5:
        obstacles.append(f.box([depth, -hw, boards[0] - thick], [depth + thick, hw, top]))
    for lo, hi in zip(boards[:-1], boards[1:]):
        obstacles += _objects(
            f, rng, int(rng.integers(0, 4)), (0.05, depth - 0.05, -hw + 0.05, hw - 0.05), lo, hi - 0.03
        )
    hull = f.region([0.0, -hw - thick, boards[0] - thick], [depth + thick, hw + thick, top])
    return Cell("shelf", obstacles, inside, hull)


def build_cabinet(rng: np.random.Generator) -> Cell:
    depth, width, height, t = (float(rng.uniform(*r)) for r in ((0.4, 0.7), (0.5, 0.8), (0.45, 0.9), (0.04, 0.04)))
    f = _frame(rng, (0.2, 0.45), float(rng.uniform(-0.55, 0.2)))
    hw = width / 2
    obstacles: list[Shape] = [
        f.box([0, -hw, -t], [depth, hw, 0]),  # floor
        f.box([0, -hw, height], [depth, hw, height + t]),  # top
        f.box([depth, -hw, 0], [depth + t, hw, height]),  # back
        f.box([0, -hw - t, -t], [depth, -hw, height + t]),  # sides
        f.box([0, hw, -t], [depth, hw + t, height + t]),
    ]
    front = rng.random()
    low = 0.0
    if front < 0.35:  # a low wall: the opening is above it
        low = float(rng.uniform(0.3, 0.6)) * height
        obstacles.append(f.box([-t, -hw, 0], [0, hw, low]))
    elif front < 0.7:  # a cage: horizontal bars across the opening
        for _ in range(int(rng.integers(1, 3))):
            zb = float(rng.uniform(0.2, 0.8)) * height
            obstacles.append(f.box([-t, -hw, zb - 0.02], [0, hw, zb + 0.02]))
    if rng.random() < 0.5:
        obstacles += _objects(f, rng, 1, (depth * 0.3, depth * 0.8, -hw + 0.1, hw - 0.1), 0.0, height * 0.5)
    inside = [f.region([0.08, -hw + 0.08, max(low, 0.0) * 0.5 + 0.06], [depth - 0.06, hw - 0.08, height - 0.06])]
    hull = f.region([-t, -hw - t, -t], [depth + t, hw + t, height + t])
    return Cell("cabinet", obstacles, inside, hull)


BUILDERS: dict[str, Callable[[np.random.Generator], Cell]] = {
    "table": build_table,
    "shelf": build_shelf,
    "cabinet": build_cabinet,
}


def cell_of(scene: Scene) -> Cell | None:
    """The cell a workspace was built from (``None`` for other scenes)."""
    return scene.__dict__.get("cell")


class ArmCellsScenario(Scenario):
    """Random arm workcells (see the module's description): ``robot`` is an arm by name
    (``panda`` by default, ``ur5``) or an :class:`~pointplan.robots.arm.ArmRobot`."""

    name = "armcells"
    horizon = 150
    #: pairs drawn per problem before one whose straight line is free is accepted
    problem_tries = 6
    #: joint-space draws per batch of the rejection sampler, and batches per end
    batch, tries = 2048, 12

    def __init__(self, robot: str | Robot | None = None, kinds: tuple[str, ...] = KINDS) -> None:
        robot = robot if robot is not None else "panda"
        arm = make_arm(robot) if isinstance(robot, str) else robot
        if not isinstance(arm, ArmRobot):
            raise ValueError(f"armcells is for arms (panda, ur5, or a loaded URDF), not {getattr(arm, 'name', arm)!r}")
        unknown = set(kinds) - set(BUILDERS)
        if unknown or not kinds:
            raise ValueError(f"unknown cell kinds {sorted(unknown)}; use some of {', '.join(KINDS)}")
        self.robot: ArmRobot = arm
        self.kinds = tuple(kinds)
        self._cache: OrderedDict[tuple[str, int], Scene] = OrderedDict()

    @property
    def bounds(self) -> tuple[Array, Array]:
        return self.robot.lower.copy(), self.robot.upper.copy()

    def scene(self, split: str, index: int) -> Scene:
        key = (split, int(index))
        s = self._cache.get(key)
        if s is None:
            rng = workspace_rng(self.stream_name, split, index)
            kind = self.kinds[int(rng.integers(0, len(self.kinds)))]
            cell = BUILDERS[kind](rng)
            s = JointSpaceScene(cell.obstacles, self.robot.lower.copy(), self.robot.upper.copy())
            s.name = f"{self.name}/{split}/{index}"
            s.__dict__["cell"] = cell
            self._cache[key] = s
            if len(self._cache) > 512:
                self._cache.popitem(last=False)
        return s

    def hand(self, q: Array) -> Array:
        """The hand's position (the centre of the arm's last sphere) at ``q: (..., n)``."""
        return self.robot.sphere_centers(q)[..., -1, :]

    def free_with_hand(
        self, scene: Scene, rng: np.random.Generator, keep: Callable[[Array], np.ndarray]
    ) -> Array | None:
        """A free configuration, uniform in joint space, whose hand satisfies ``keep``
        (a test on positions ``(B, 3)``); ``None`` when ``tries`` batches found none."""
        arm = self.robot
        for _ in range(self.tries):
            q = arm.sample_uniform(rng, self.batch, arm.lower, arm.upper)
            q = q[keep(self.hand(q))]
            if len(q):
                q = q[~arm.collides(scene.world, q)]
            if len(q):
                return q[0]
        return None

    def sample_problem(self, scene: Scene, rng: np.random.Generator) -> tuple[Array, Array]:
        cell = cell_of(scene)
        if cell is None:
            return super().sample_problem(scene, rng)
        pair = self.first_blocked_pair(
            lambda: self._draw_pair(scene, cell, rng),
            lambda a, b: self.straight_free(scene, a, b),
            self.problem_tries,
        )
        return pair if pair is not None else super().sample_problem(scene, rng)

    def _draw_pair(self, scene: Scene, cell: Cell, rng: np.random.Generator) -> tuple[Array, Array] | None:
        regions = [cell.inside[i] for i in rng.permutation(len(cell.inside))]
        a = self.free_with_hand(scene, rng, regions[0].contains)
        if a is None:
            return None
        if len(regions) > 1 and cell.kind == "shelf" and rng.random() < 1 / 3:
            b = self.free_with_hand(scene, rng, regions[1].contains)
        else:
            b = self.free_with_hand(scene, rng, lambda p: ~cell.hull.contains(p, 0.05) & (p[:, 2] > -0.3))
        if b is None:
            return None
        return (a, b) if rng.random() < 0.5 else (b, a)

    def straight_free(self, scene: Scene, a: Array, b: Array) -> bool:
        """Is the straight joint-space line ``a -> b`` free (the arm's certified check)?"""
        n = np.array([max(1, int(math.ceil(float(np.linalg.norm(b - a)) / 0.05)))])
        chk = self.robot.check_motions(scene.world, a[None], (b - a)[None], n, scene.low, scene.high)
        return not bool(chk.collided[0])
