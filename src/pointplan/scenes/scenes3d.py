"""3D scenarios: 3D-Boxes, 3D-Synthetic, 3D-YCB, 3D-Dynamic, Slot and 3D-Qureshi.

Every workspace is ``[-0.6, 0.6]^3`` and is drawn from its own random stream,
``SeedSequence([scenario key, split key, index])``: the train, val and test workspaces of a
scenario never share a stream. Each scenario works with the 3D sphere (``sphere3d``, 3 DoF)
and the S-shape (``sshape``, 6 DoF); the horizon is 80 steps.
"""

from __future__ import annotations

import math
import zlib
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..geometry.lie import random_rotations
from ..geometry.shapes import Box, Capsule, Cone, Cylinder, Shape, Sphere
from ..robots import make_robot
from ..robots.base import Robot
from ..robots.sshape import BAR_THICKNESS
from .base import Scenario
from .narrow2d import SPLIT_KEYS
from .scene import DynamicScene, Scene

Array = np.ndarray
HALF_EXTENT = 0.6
LOW = np.full(3, -HALF_EXTENT)
HIGH = np.full(3, HALF_EXTENT)


def workspace_rng(scenario: str, split: str, index: int) -> np.random.Generator:
    """The random stream of workspace ``index`` of ``split`` in ``scenario``."""
    if split not in SPLIT_KEYS:
        raise ValueError(f"unknown split {split!r}; use 'train', 'val' or 'test'")
    if index < 0:
        raise ValueError("workspace index must be >= 0")
    return np.random.default_rng(np.random.SeedSequence([zlib.crc32(scenario.encode()), SPLIT_KEYS[split], int(index)]))


@dataclass(frozen=True)
class BoxesConfig:
    """The 3D-Boxes layout (also used by 3D-Synthetic, 3D-YCB and 3D-Dynamic)."""

    min_obstacles: int = 3
    max_obstacles: int = 9
    #: full sides uniform in this range
    min_size: float = 0.15
    max_size: float = 0.5
    #: centres uniform in [-c, c]^3
    center_range: float = 0.45


class Scenario3D(Scenario):
    """Shared machinery: robot by name, bounds, a small cache of built workspaces."""

    name = "3d"
    horizon = 80
    default_robot = "sphere3d"

    def __init__(self, robot: str | Robot | None = None, config: BoxesConfig | None = None) -> None:
        robot = robot if robot is not None else self.default_robot
        self.robot = make_robot(robot) if isinstance(robot, str) else robot
        if self.robot.dim != 3:
            raise ValueError(
                f"{self.name} is a 3D scenario; robot {self.robot.name} is {self.robot.dim}D (use sphere3d or sshape)"
            )
        self.config = config or BoxesConfig()
        self._cache: OrderedDict[tuple[str, int], Scene] = OrderedDict()

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return LOW.copy(), HIGH.copy()

    def scene(self, split: str, index: int) -> Scene:
        key = (split, int(index))
        s = self._cache.get(key)
        if s is None:
            s = self.build(workspace_rng(self.stream_name, split, index), split)
            s.name = f"{self.name}/{split}/{index}"
            self._cache[key] = s
            if len(self._cache) > 512:  # keep recent workspaces (and their observation caches)
                self._cache.popitem(last=False)
        return s

    def build(self, rng: np.random.Generator, split: str) -> Scene:
        """A new workspace of ``split`` drawn from ``rng``."""
        raise NotImplementedError

    def _layout(self, rng: np.random.Generator) -> tuple[int, Array, Array, Array]:
        c = self.config
        n = int(rng.integers(c.min_obstacles, c.max_obstacles + 1))
        sizes = rng.uniform(c.min_size, c.max_size, (n, 3))
        centers = rng.uniform(-c.center_range, c.center_range, (n, 3))
        return n, sizes, centers, random_rotations(rng, n)


class Boxes3DScenario(Scenario3D):
    """3D-Boxes: 3 to 9 boxes, full sides uniform in [0.15, 0.5], centres uniform in
    [-0.45, 0.45]^3, uniformly random orientations (boxes may overlap)."""

    name = "boxes3d"

    def build(self, rng: np.random.Generator, split: str) -> Scene:
        n, sizes, centers, rots = self._layout(rng)
        return Scene([Box(centers[i], sizes[i], rots[i]) for i in range(n)], LOW, HIGH)


def synthetic_shape(kind: str, size: Array, center: Array, rotation: Array) -> Shape:
    """A shape of ``kind`` filling roughly the box of full sides ``size``: the radius is half
    the mean of the first two sides (a capsule's at most a quarter of the third, so that it
    keeps a straight part), the length along the axis the third side."""
    radius = float(size[0] + size[1]) / 4.0
    length = float(size[2])
    if kind == "sphere":
        return Sphere(center, float(np.mean(size)) / 2.0)
    if kind == "cylinder":
        return Cylinder(center, radius, length, rotation)
    if kind == "cone":
        return Cone(center, radius, length, rotation)
    if kind == "capsule":
        radius = min(radius, length / 4.0)
        seg = (length - 2.0 * radius) / 2.0
        axis = rotation[:, 2]
        return Capsule(center - seg * axis, center + seg * axis, radius)
    raise ValueError(f"unknown synthetic shape {kind!r}")


class Synthetic3DScenario(Scenario3D):
    """3D-Synthetic: the 3D-Boxes layout filled with shapes a box-trained policy never saw:
    capsules, cylinders, spheres and cones (kind drawn uniformly per obstacle)."""

    name = "synthetic3d"
    KINDS = ("capsule", "cylinder", "sphere", "cone")

    def build(self, rng: np.random.Generator, split: str) -> Scene:
        n, sizes, centers, rots = self._layout(rng)
        kinds = rng.integers(0, len(self.KINDS), n)
        return Scene(
            [synthetic_shape(self.KINDS[k], sizes[i], centers[i], rots[i]) for i, k in enumerate(kinds)], LOW, HIGH
        )


class YCB3DScenario(Scenario3D):
    """3D-YCB: the 3D-Boxes layout filled with real object meshes (YCB objects), each
    scaled so that its longest side is uniform in [0.15, 0.5] like a box's side.

    ``objects`` maps names to mesh files; by default the set that ships with the package's
    dependencies (see ``docs/guide/scenarios.md``); pass ``find_ycb_objects(root)`` to use a YCB download.
    """

    name = "ycb3d"

    def __init__(
        self,
        robot: str | Robot | None = None,
        config: BoxesConfig | None = None,
        objects: dict[str, str | Path] | None = None,
        max_faces: int = 800,
    ) -> None:
        super().__init__(robot, config)
        from . import ycb

        self.objects = dict(objects) if objects is not None else ycb.default_ycb_objects()
        if not self.objects:
            raise ValueError("3D-YCB needs at least one object mesh")
        self.names = sorted(self.objects)
        self.max_faces = int(max_faces)

    def build(self, rng: np.random.Generator, split: str) -> Scene:
        from . import ycb

        n, sizes, centers, rots = self._layout(rng)
        picks = rng.integers(0, len(self.names), n)
        shapes: list[Shape] = []
        for i, k in enumerate(picks):
            mesh = ycb.load_object_mesh(self.objects[self.names[k]], max_faces=self.max_faces)
            extent = float(np.ptp(mesh.vertices, axis=0).max())
            target = float(rng.uniform(self.config.min_size, self.config.max_size))
            shapes.append(ycb.place_mesh(mesh, rots[i], centers[i], scale=target / extent))
        return Scene(shapes, LOW, HIGH)


class Dynamic3DScenario(Scenario3D):
    """3D-Dynamic: 3D-Boxes whose boxes move between two placements drawn from the same
    layout (centre and orientation), there and back over ``period`` steps (default: the
    horizon, so the second placement is reached at half the horizon and the first again
    at its end)."""

    name = "dynamic3d"

    def __init__(
        self, robot: str | Robot | None = None, config: BoxesConfig | None = None, period: int | None = None
    ) -> None:
        super().__init__(robot, config)
        if period is not None and period < 1:
            raise ValueError(f"period must be a positive number of steps, not {period}")
        self.period = int(period) if period is not None else self.horizon

    def build(self, rng: np.random.Generator, split: str) -> Scene:
        n, sizes, centers, rots = self._layout(rng)
        c = self.config
        targets_c = rng.uniform(-c.center_range, c.center_range, (n, 3))
        targets_r = random_rotations(rng, n)
        return DynamicScene(
            [Box(centers[i], sizes[i], rots[i]) for i in range(n)],
            [Box(targets_c[i], sizes[i], targets_r[i]) for i in range(n)],
            LOW,
            HIGH,
            period=self.period,
        )

    def sample_problem(self, scene: Scene, rng: np.random.Generator) -> tuple[Array, Array]:
        """Start free at time 0; goal free at every time step of an episode (it can be
        reached whenever the robot gets there)."""
        start = self.robot.sample_free(scene.world_at(0), rng, 1, scene.low, scene.high)[0]
        worlds = [scene.world_at(t) for t in range(self.horizon + 1)]
        for _ in range(1000):
            cand = self.robot.sample_free(scene.world_at(0), rng, 16, scene.low, scene.high)
            ok = np.ones(len(cand), dtype=bool)
            for w in worlds:
                ok &= ~self.robot.collides(w, cand)
                if not ok.any():
                    break
            if ok.any():
                return start, cand[int(np.argmax(ok))]
        raise RuntimeError(f"no goal stays free in {scene.name}")


@dataclass(frozen=True)
class SlotConfig:
    """The Slot scene: a wall across x = 0 with a slot through it."""

    #: slot width in units of the S-shape's bar thickness (0.036)
    min_width_bars: float = 2.0
    max_width_bars: float = 8.0
    slot_length: float = 0.4
    wall_thickness: float = 0.04
    #: the slot's centre is uniform in [-c, c] along the wall's two axes
    center_range: float = 0.15
    #: the axes its long side may lie along (1: y, 2: z), drawn uniformly
    long_axes: tuple[int, ...] = (1, 2)
    #: start and goal positions are this far from the wall at least (along x): more than the
    #: S-shape's reach from its frame (0.29), so its whole body is on its side
    side_gap: float = 0.3


class SlotMovingScenario(Scenario3D):
    """Slot with a moving gate (a harder variant of our own): a wall spanning the workspace
    at x = 0 with one slot, its width drawn between 2 and 8 bar thicknesses, its centre
    uniform in [-0.15, 0.15] along the wall's two axes, its long side along y or z; start
    on the x < 0 side, goal on the x > 0 side, each at least 0.3 from the wall. The default
    robot is the S-shape. (Named ``slot`` before the paper's reading took that name: its
    problems are drawn from that name's streams, so they are the ones measured then.)"""

    name = "slotmoving"
    stream: str | None = "slot"
    default_robot = "sshape"

    def __init__(self, robot: str | Robot | None = None, config: SlotConfig | None = None) -> None:
        super().__init__(robot)
        self.slot = config or SlotConfig()

    def build(self, rng: np.random.Generator, split: str) -> Scene:
        c = self.slot
        width = float(rng.uniform(c.min_width_bars, c.max_width_bars)) * BAR_THICKNESS
        long_axis = int(rng.integers(1, 3))  # 1: slot long along y, 2: along z
        if tuple(c.long_axes) != (1, 2):
            long_axis = int(c.long_axes[(long_axis - 1) % len(c.long_axes)])
        mid = np.zeros(3)
        mid[1:] = rng.uniform(-c.center_range, c.center_range, 2)
        return self.wall(width, mid, long_axis)

    def wall(self, width: float, mid: Array, long_axis: int) -> Scene:
        """The scene of a slot ``width`` wide (metres) centred at ``mid`` (its x is ignored),
        long along y (``long_axis`` 1) or z (2)."""
        if long_axis not in (1, 2):
            raise ValueError(f"long_axis must be 1 (y) or 2 (z), not {long_axis}")
        c = self.slot
        ext = np.zeros(3)
        ext[long_axis] = c.slot_length
        ext[3 - long_axis] = width
        mid = np.array([0.0, float(mid[1]), float(mid[2])])
        e, t = HALF_EXTENT, c.wall_thickness
        boxes = []
        lo, hi = mid - ext / 2, mid + ext / 2
        # wall = four boxes around the opening: below/above along y, then left/right along z
        for a, b in ((-e, lo[1]), (hi[1], e)):
            boxes.append(Box(np.array([0.0, (a + b) / 2, 0.0]), np.array([t, b - a, 2 * e])))
        for a, b in ((-e, lo[2]), (hi[2], e)):
            boxes.append(Box(np.array([0.0, mid[1], (a + b) / 2]), np.array([t, hi[1] - lo[1], b - a])))
        scene = Scene(boxes, LOW, HIGH)
        scene.__dict__["slot"] = {"width": float(width), "center": mid, "long_axis": long_axis}
        return scene

    def sample_problem(self, scene: Scene, rng: np.random.Generator) -> tuple[Array, Array]:
        g = self.slot.side_gap
        low_a, high_a = LOW.copy(), HIGH.copy()
        high_a[0] = -g
        low_b, high_b = LOW.copy(), HIGH.copy()
        low_b[0] = g
        start = self.robot.sample_free(scene.world, rng, 1, low_a, high_a)[0]
        goal = self.robot.sample_free(scene.world, rng, 1, low_b, high_b)[0]
        return start, goal


class SlotWideScenario(SlotMovingScenario):
    """The moving-gate Slot with wide slots only (4-8 bar thicknesses): a curriculum stage for training,
    where Bi-RRT solves 94-100% of problems in a few seconds (it solves none of the
    slots under 3 bars with 50,000 nodes). Its workspaces are drawn from their own stream,
    not Slot's."""

    name = "slotwide"
    stream = None  # its own name's

    def __init__(self, robot: str | Robot | None = None, config: SlotConfig | None = None) -> None:
        super().__init__(robot, config or SlotConfig(min_width_bars=4.0))


class SlotScenario(SlotMovingScenario):
    """Slot, the paper's reading: the wall at x = 0 with its opening always centred and
    long along y, only its width varying (2-8 bar thicknesses), as in the classic problem
    the paper takes Slot from; start on the x < 0 side, goal anywhere on the x > 0 side
    (0.3 from the wall at least). (Named ``slotfixed`` before it became ``slot``: its
    problems are drawn from that name's streams.)"""

    name = "slot"
    stream: str | None = "slotfixed"

    def __init__(self, robot: str | Robot | None = None, config: SlotConfig | None = None) -> None:
        super().__init__(robot, config or SlotConfig(center_range=0.0, long_axes=(1,)))


#: the goal of ``slotclassic``: the last pose of the shipped threading template
#: (``pointplan/data/slot_threading.npz``) in the centred slot long along y, 0.45 past the
#: wall (position, then the quaternion x, y, z, w)
SLOT_CLASSIC_GOAL = np.array([0.474, 0.005, 0.076, 0.005, -0.702, 0.712, 0.005])


class SlotClassicScenario(SlotScenario):
    """``slot`` with one goal for every problem (:data:`SLOT_CLASSIC_GOAL`, past the
    wall; its position for the sphere): only the start and the slot's width vary. A diagnostic, not the paper's Slot: the
    goal's relative pose, which the policy is given, then tells it exactly where the opening
    is and which way it runs, so what a policy fails at here is not seeing the opening. Its
    workspaces are drawn from their own stream."""

    name = "slotclassic"
    stream = None  # its own name's

    def sample_problem(self, scene: Scene, rng: np.random.Generator) -> tuple[Array, Array]:
        start, _ = super().sample_problem(scene, rng)
        goal = SLOT_CLASSIC_GOAL.copy()
        goal[3:] /= np.linalg.norm(goal[3:])
        goal = goal[: self.robot.config_dim]  # the sphere: the position alone
        if self.robot.collides(scene.world, goal[None])[0]:
            raise RuntimeError("slotclassic's goal collides: the wall or the robot changed")
        return start, goal


#: 3D-Qureshi obstacle centres and sizes (full sides), after the "complex 3D" environments
#: of Qureshi et al. (MPNet): ten axis-aligned blocks in a cube, here scaled to [-0.6, 0.6]^3.
QURESHI_CENTERS = np.array(
    [
        [-0.36, -0.36, -0.3],
        [0.0, -0.36, 0.24],
        [0.36, -0.3, -0.12],
        [-0.36, 0.0, 0.3],
        [-0.06, 0.0, -0.3],
        [0.33, 0.06, 0.27],
        [-0.3, 0.36, -0.15],
        [0.06, 0.36, 0.0],
        [0.39, 0.39, -0.36],
        [0.0, 0.0, 0.39],
    ]
)
QURESHI_SIZES = np.array(
    [
        [0.15, 0.15, 0.45],
        [0.3, 0.15, 0.15],
        [0.15, 0.3, 0.3],
        [0.24, 0.24, 0.24],
        [0.45, 0.15, 0.15],
        [0.15, 0.45, 0.15],
        [0.3, 0.3, 0.15],
        [0.15, 0.15, 0.3],
        [0.21, 0.3, 0.21],
        [0.36, 0.15, 0.24],
    ]
)


def unrank_permutation(rank: int, n: int) -> list[int]:
    """The permutation of ``range(n)`` with lexicographic rank ``rank`` (Lehmer code)."""
    items, out = list(range(n)), []
    for k in range(n, 0, -1):
        f = math.factorial(k - 1)
        i, rank = divmod(rank, f)
        out.append(items.pop(i))
    return out


class Qureshi3DScenario(Scenario3D):
    """3D-Qureshi: ten axis-aligned boxes at fixed centres; each workspace assigns the ten
    sizes to the centres by a permutation of its own. There are only 10! permutations, so
    the splits own disjoint sets of them: ranks 0 (mod 10) are test, 1 (mod 10) val, the
    rest train."""

    name = "qureshi3d"
    SPLIT_RESIDUES = {"test": (0,), "val": (1,), "train": tuple(range(2, 10))}

    def build(self, rng: np.random.Generator, split: str) -> Scene:
        n = len(QURESHI_SIZES)
        residues = self.SPLIT_RESIDUES[split]
        block = int(rng.integers(0, math.factorial(n) // 10))
        rank = 10 * block + residues[int(rng.integers(0, len(residues)))]
        perm = unrank_permutation(rank, n)
        return Scene([Box(c, QURESHI_SIZES[p]) for c, p in zip(QURESHI_CENTERS, perm)], LOW, HIGH)


SCENARIOS_3D: dict[str, Callable[..., Scenario]] = {
    "boxes3d": Boxes3DScenario,
    "synthetic3d": Synthetic3DScenario,
    "ycb3d": YCB3DScenario,
    "dynamic3d": Dynamic3DScenario,
    "slot": SlotScenario,
    "slotmoving": SlotMovingScenario,
    "slotwide": SlotWideScenario,
    "slotclassic": SlotClassicScenario,
    "qureshi3d": Qureshi3DScenario,
}
