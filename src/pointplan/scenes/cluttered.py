"""3D-Cluttered: furniture-like layouts of boxes at the robots' scale.

Every workspace is ``[-0.6, 0.6]^3`` (as in the other 3D scenarios) and holds one piece of
furniture built only of (oriented) :class:`~pointplan.geometry.shapes.Box` obstacles, so
that the compiled box kernels (collision, motion checks, ray casting) handle it. The kind
is drawn from the workspace's own random stream:

``shelves``
    a bookcase standing against a wall of the workspace: side panels, a back panel and
    boards whose gaps vary, one at least narrower than the S-shape is long (it must turn to
    pass), with small boxes on some boards;
``cage``
    a box-shaped frame of thin bars (posts and rails), floating in the workspace, with
    openings between the bars, one side always open enough for the S-shape;
``table``
    a table top on four legs, with boxes on it and on the floor under it;
``openbox``
    a container on the floor: a floor panel and four walls, open at the top, sometimes a
    window in one wall, sometimes boxes inside.

Problems: one end (start or goal, drawn at random) lies inside the furniture (a shelf
compartment, the cage, under the table, inside the container: the robot's position and
the centres of all its body parts), the other outside it (or, for shelves, in another
compartment), both free for the robot and at least ``min_goal_distance`` apart. The sampler prefers pairs whose straight line is blocked: it
draws up to ``problem_tries`` pairs and keeps the first blocked one (else the first pair).
Nothing guarantees that a problem is solvable beyond its ends being free.

Train, val and test workspaces are drawn from disjoint streams,
``SeedSequence([crc32("cluttered3d"), split key, index])``, the seeding of the other 3D
scenarios. The horizon is 80 steps; the default robot is the sphere (``sphere3d``), the
S-shape (``sshape``) works too.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..geometry.shapes import Box
from ..robots.base import Robot
from .scene import Scene
from .scenes3d import HALF_EXTENT, HIGH, LOW, Scenario3D

Array = NDArray[np.float64]
Bool = NDArray[np.bool_]

#: the layout kinds, in the order the builders are looked up
KINDS = ("shelves", "cage", "table", "openbox")


def yaw_matrix(yaw: float) -> Array:
    """The rotation by ``yaw`` radians about the world's z axis."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True, eq=False)
class Region:
    """Positions in an oriented box: ``center``, ``half`` sides and ``rotation`` (box to
    world), all in the world frame."""

    center: Array
    half: Array
    rotation: Array

    def sample(self, rng: np.random.Generator, n: int) -> Array:
        """``n`` positions uniform in the region, ``(n, 3)``."""
        local = rng.uniform(-self.half, self.half, (n, 3))
        return self.center + local @ self.rotation.T

    def contains(self, points: Array, margin: float = 0.0) -> Bool:
        """Which of ``points (n, 3)`` lie in the region grown by ``margin``."""
        local = (np.asarray(points, np.float64) - self.center) @ self.rotation
        return np.all(np.abs(local) <= self.half + margin, axis=-1)


@dataclass(frozen=True)
class Frame:
    """Where a piece of furniture stands: ``world = origin + rotation @ local``. Builders
    describe their boxes in the local frame (z up, the floor at local z = 0)."""

    origin: Array
    rotation: Array

    def box(self, low: Sequence[float] | Array, high: Sequence[float] | Array, yaw: float = 0.0) -> Box:
        """The box spanning ``low``-``high`` in the local frame (turned by ``yaw`` about its
        own vertical axis)."""
        lo, hi = np.asarray(low, np.float64), np.asarray(high, np.float64)
        return Box(self.origin + self.rotation @ ((lo + hi) / 2), hi - lo, self.rotation @ yaw_matrix(yaw))

    def region(self, low: Sequence[float] | Array, high: Sequence[float] | Array) -> Region:
        """The region spanning ``low``-``high`` in the local frame."""
        lo, hi = np.asarray(low, np.float64), np.asarray(high, np.float64)
        return Region(self.origin + self.rotation @ ((lo + hi) / 2), (hi - lo) / 2, self.rotation.copy())


@dataclass
class Layout:
    """A built workspace: its ``kind``, its boxes, the regions ``inside`` the furniture
    where one end of a problem is drawn, and the ``hull`` the other end stays out of."""

    kind: str
    boxes: list[Box]
    inside: list[Region]
    hull: Region


@dataclass(frozen=True)
class ClutteredConfig:
    """Parameters of 3D-Cluttered shared by the layout kinds (the sizes of each kind are
    in its builder)."""

    #: the kinds drawn (uniformly) for the workspaces
    kinds: tuple[str, ...] = KINDS
    #: thickness of panels and boards (shelves, container walls)
    thickness: float = 0.03
    #: start and goal positions at least this far apart
    min_goal_distance: float = 0.4
    #: pairs drawn per problem; the first whose straight line is blocked is kept (else the first pair)
    problem_tries: int = 12
    #: an outside end keeps this far from the furniture's hull
    hull_margin: float = 0.02
    #: an inside end has the centres of all its body parts (the S-shape's five bars) in
    #: its region grown by this much
    part_margin: float = 0.03
    #: shelves: chance that both ends lie in two different compartments
    two_compartments: float = 0.3


def _place(rng: np.random.Generator, footprint: tuple[float, float], z0: float = -HALF_EXTENT) -> Frame:
    """A frame turned by a random yaw whose local floor is at world height ``z0``, placed
    so that the footprint ``(x, y)`` (full sides) stays roughly inside the workspace."""
    yaw = float(rng.uniform(-math.pi, math.pi))
    rot = yaw_matrix(yaw)
    c, s = abs(math.cos(yaw)), abs(math.sin(yaw))
    ex = (c * footprint[0] + s * footprint[1]) / 2  # half extents of the turned footprint
    ey = (s * footprint[0] + c * footprint[1]) / 2
    room = np.maximum(HALF_EXTENT - np.array([ex, ey]) - 0.05, 0.0)
    xy = rng.uniform(-room, room)
    return Frame(np.array([xy[0], xy[1], z0]), rot)


def _loose_boxes(
    frame: Frame,
    rng: np.random.Generator,
    n: int,
    area: tuple[float, float, float, float],
    z: float,
    max_height: float,
) -> list[Box]:
    """``n`` small boxes standing at local height ``z`` with centres in the local
    rectangle ``area = (x0, x1, y0, y1)``, each turned by a random yaw."""
    out = []
    for _ in range(n):
        size = np.array([rng.uniform(0.06, 0.16), rng.uniform(0.06, 0.16), rng.uniform(0.06, max_height)])
        x, y = rng.uniform(area[0], area[1]), rng.uniform(area[2], area[3])
        out.append(
            frame.box(
                [x - size[0] / 2, y - size[1] / 2, z],
                [x + size[0] / 2, y + size[1] / 2, z + size[2]],
                float(rng.uniform(-0.5, 0.5)),
            )
        )
    return out


def _shelf_gaps(rng: np.random.Generator) -> list[float]:
    """Board gaps of a bookcase, bottom up: one large (0.34-0.40, room for the S-shape),
    one narrower than the S-shape is long (0.20-0.28), sometimes a third (0.22-0.36)."""
    gaps = [float(rng.uniform(0.34, 0.40)), float(rng.uniform(0.20, 0.28))]
    if rng.random() < 0.6:
        gaps.append(float(rng.uniform(0.22, 0.36)))
    order = rng.permutation(len(gaps))
    return [gaps[i] for i in order]


def build_shelves(rng: np.random.Generator, config: ClutteredConfig) -> Layout:
    """A bookcase, its back against a wall of the workspace: width 0.6-0.9, depth
    0.34-0.44, two or three compartments (see :func:`_shelf_gaps`) above a plinth, boards
    ``config.thickness`` thick, 0-2 small boxes on each board. Every compartment is an
    inside region (the S-shape fits in the narrow ones only lying down, so the sampler
    rarely finds it a place there)."""
    t = config.thickness
    width, depth = float(rng.uniform(0.6, 0.9)), float(rng.uniform(0.34, 0.44))
    plinth = float(rng.uniform(0.0, 0.12))
    gaps = _shelf_gaps(rng)
    height = plinth + sum(gaps) + (len(gaps) + 1) * t
    # back to a wall: turn by a quarter turn (and a little), push to the wall
    yaw = float(rng.integers(0, 4)) * math.pi / 2 + float(rng.uniform(-0.15, 0.15))
    rot = yaw_matrix(yaw)
    back = HALF_EXTENT - depth / 2 - 0.03
    shift = float(rng.uniform(-1, 1)) * max(HALF_EXTENT - width / 2 - 0.05, 0.0)
    frame = Frame(rot @ np.array([shift, back, 0.0]) + np.array([0.0, 0.0, -HALF_EXTENT]), rot)
    w, d = width / 2, depth / 2
    boxes = [
        frame.box([-w, d - t, 0.0], [w, d, height]),  # back panel
        frame.box([-w, -d, 0.0], [-w + t, d - t, height]),  # side panels
        frame.box([w - t, -d, 0.0], [w, d - t, height]),
    ]
    inside = []
    z = plinth
    for i in range(len(gaps) + 1):
        boxes.append(frame.box([-w + t, -d, z], [w - t, d - t, z + t]))  # board
        if i == len(gaps):
            break
        top = z + t + gaps[i]
        n_objects = int(rng.integers(0, 3))
        area = (-w + t + 0.08, w - t - 0.08, -d + 0.08, d - t - 0.08)
        boxes += _loose_boxes(frame, rng, n_objects, area, z + t, min(0.16, gaps[i] - 0.1))
        inside.append(frame.region([-w + t + 0.04, -d + 0.02, z + t + 0.01], [w - t - 0.04, d - t - 0.06, top - 0.01]))
        z = top
    hull = frame.region([-w, -d, 0.0], [w, d + 0.2, height])
    return Layout("shelves", boxes, inside, hull)


def _bar_positions(rng: np.random.Generator, side: float, bar: float, max_inner: int) -> list[float]:
    """Centres of the bars across one side of a cage, in ``[-side/2, side/2]``: the two
    edge bars and 0 to ``max_inner`` evenly spread inner bars (jittered)."""
    edge = side / 2 - bar / 2
    n = int(rng.integers(0, max_inner + 1))
    inner = [-edge + (k + 1) * 2 * edge / (n + 1) + float(rng.uniform(-0.03, 0.03)) for k in range(n)]
    return [-edge, *inner, edge]


def build_cage(rng: np.random.Generator, config: ClutteredConfig) -> Layout:
    """A floating cage of bars 0.025-0.04 thick, sides 0.5-0.7: posts at the corners and
    rails along the top and bottom edges; each of the four walls gets 0-2 inner posts, the
    roof and the bottom 0-2 inner bars, and a rail may run round the middle. One wall (the
    door) keeps no inner posts, and the middle rail (only in cages 0.62 tall or more) leaves
    openings 0.25+ high, so the S-shape can get in by turning."""
    size = rng.uniform(0.5, 0.7, 3)
    bar = float(rng.uniform(0.025, 0.04))
    frame = _place(rng, (float(size[0]), float(size[1])), z0=0.0)
    zc = float(rng.uniform(-1, 1)) * (HALF_EXTENT - size[2] / 2 - 0.02)
    frame = Frame(frame.origin + np.array([0.0, 0.0, zc]), frame.rotation)
    h = size / 2
    boxes: list[Box] = []

    def bar_along(axis: int, at: tuple[float, float]) -> Box:
        lo, hi = np.empty(3), np.empty(3)
        others = [a for a in range(3) if a != axis]
        lo[axis], hi[axis] = -h[axis], h[axis]
        for a, c in zip(others, at):
            lo[a], hi[a] = c - bar / 2, c + bar / 2
        return frame.box(lo, hi)

    ex, ey, ez = (h - bar / 2).tolist()
    door = int(rng.integers(0, 4))  # wall 0: -x, 1: +x, 2: -y, 3: +y
    for sx in (-ex, ex):  # posts, and rails along x and y at the top and bottom
        for sy in (-ey, ey):
            boxes.append(bar_along(2, (sx, sy)))
    for sz in (-ez, ez):
        boxes += [bar_along(0, (sy, sz)) for sy in (-ey, ey)] + [bar_along(1, (sx, sz)) for sx in (-ex, ex)]
    for wall in range(4):  # inner posts of the walls
        axis, sign = (1, 0) if wall < 2 else (0, 1)  # the axis the wall spans, and its normal
        normal_at = (ex if sign == 0 else ey) * (1 if wall % 2 else -1)
        inner = _bar_positions(rng, float(size[axis]), bar, 0 if wall == door else 2)[1:-1]
        for c in inner:
            at = (normal_at, c) if axis == 1 else (c, normal_at)
            boxes.append(bar_along(2, at))
    for sz in (-ez, ez):  # inner bars of the roof and the bottom
        for c in _bar_positions(rng, float(size[1]), bar, 2)[1:-1]:
            boxes.append(bar_along(0, (c, sz)))
    if size[2] >= 0.62 and rng.random() < 0.5:  # a rail round the middle
        zm = float(rng.uniform(-0.03, 0.03))
        boxes += [bar_along(0, (sy, zm)) for sy in (-ey, ey)] + [bar_along(1, (sx, zm)) for sx in (-ex, ex)]
    m = bar + 0.03
    inside = [frame.region(-h + m, h - m)]
    return Layout("cage", boxes, inside, frame.region(-h, h))


def build_table(rng: np.random.Generator, config: ClutteredConfig) -> Layout:
    """A table: a top 0.6-0.9 by 0.45-0.7, 0.04 thick, its underside 0.38-0.55 above the
    floor, on four legs 0.04-0.06 square; 1-3 boxes stand on the top and 0-2 on the floor
    under it. The space under the top, between the legs, is the inside region."""
    length, width = float(rng.uniform(0.6, 0.9)), float(rng.uniform(0.45, 0.7))
    under, top_t = float(rng.uniform(0.38, 0.55)), 0.04
    leg = float(rng.uniform(0.04, 0.06))
    frame = _place(rng, (length, width))
    a, b = length / 2, width / 2
    boxes = [frame.box([-a, -b, under], [a, b, under + top_t])]
    inset = 0.03
    for sx in (-1, 1):
        for sy in (-1, 1):
            x0 = sx * (a - inset) - (leg if sx > 0 else 0.0)
            y0 = sy * (b - inset) - (leg if sy > 0 else 0.0)
            boxes.append(frame.box([x0, y0, 0.0], [x0 + leg, y0 + leg, under]))
    on_top = int(rng.integers(1, 4))
    boxes += _loose_boxes(frame, rng, on_top, (-a + 0.1, a - 0.1, -b + 0.1, b - 0.1), under + top_t, 0.28)
    below = int(rng.integers(0, 3))
    boxes += _loose_boxes(frame, rng, below, (-a + 0.15, a - 0.15, -b + 0.15, b - 0.15), 0.0, under - 0.2)
    inside = [frame.region([-a + 0.06, -b + 0.06, 0.04], [a - 0.06, b - 0.06, under - 0.04])]
    hull = frame.region([-a, -b, 0.0], [a, b, under + top_t])
    return Layout("table", boxes, inside, hull)


def _wall_with_window(
    frame: Frame, x: tuple[float, float], y: tuple[float, float], z: tuple[float, float], window: tuple[float, ...]
) -> list[Box]:
    """A wall spanning local x-range ``x`` (its length), ``y`` (thickness) and ``z``, with a
    window ``(x0, x1, z0, z1)`` cut out: four boxes around the opening."""
    x0, x1, z0, z1 = window
    return [
        frame.box([x[0], y[0], z[0]], [x0, y[1], z[1]]),
        frame.box([x1, y[0], z[0]], [x[1], y[1], z[1]]),
        frame.box([x0, y[0], z[0]], [x1, y[1], z0]),
        frame.box([x0, y[0], z1], [x1, y[1], z[1]]),
    ]


def build_open_box(rng: np.random.Generator, config: ClutteredConfig) -> Layout:
    """A container on the floor, open at the top: inside 0.5-0.7 by 0.5-0.7, walls
    0.3-0.45 high and ``config.thickness`` thick on a floor panel; half of them have a
    window 0.22-0.32 wide in one wall, and 0-2 small boxes stand inside. The inside is
    the region (reaching up to the rim) where one end of a problem lies."""
    t = config.thickness
    lx, ly = rng.uniform(0.5, 0.7, 2)
    wall_h = float(rng.uniform(0.3, 0.45))
    frame = _place(rng, (float(lx) + 2 * t, float(ly) + 2 * t))
    a, b = float(lx) / 2, float(ly) / 2
    boxes = [frame.box([-a - t, -b - t, 0.0], [a + t, b + t, t])]  # floor panel
    walls = [  # (x-range, y-range) of the -y and +y walls, then the -x and +x walls
        ((-a - t, a + t), (-b - t, -b)),
        ((-a - t, a + t), (b, b + t)),
    ]
    slotted = int(rng.integers(0, 2)) if rng.random() < 0.5 else -1
    z = (t, t + wall_h)
    for i, (xr, yr) in enumerate(walls):
        if i == slotted:
            ww = float(rng.uniform(0.22, 0.32))
            xc = float(rng.uniform(-a + ww / 2 + 0.03, a - ww / 2 - 0.03))
            z0 = t + float(rng.uniform(0.02, 0.06))
            z1 = min(t + wall_h - 0.03, z0 + float(rng.uniform(0.2, 0.3)))
            boxes += _wall_with_window(frame, xr, yr, z, (xc - ww / 2, xc + ww / 2, z0, z1))
        else:
            boxes.append(frame.box([xr[0], yr[0], z[0]], [xr[1], yr[1], z[1]]))
    boxes.append(frame.box([-a - t, -b, z[0]], [-a, b, z[1]]))
    boxes.append(frame.box([a, -b, z[0]], [a + t, b, z[1]]))
    boxes += _loose_boxes(frame, rng, int(rng.integers(0, 3)), (-a + 0.1, a - 0.1, -b + 0.1, b - 0.1), t, 0.15)
    inside = [frame.region([-a + 0.03, -b + 0.03, t + 0.04], [a - 0.03, b - 0.03, t + wall_h - 0.02])]
    hull = frame.region([-a - t, -b - t, 0.0], [a + t, b + t, t + wall_h])
    return Layout("openbox", boxes, inside, hull)


#: kind -> builder ``(rng, config) -> Layout``
BUILDERS: dict[str, Callable[[np.random.Generator, ClutteredConfig], Layout]] = {
    "shelves": build_shelves,
    "cage": build_cage,
    "table": build_table,
    "openbox": build_open_box,
}


def layout_of(scene: Scene) -> Layout | None:
    """The layout a 3D-Cluttered workspace was built from (``None`` for other scenes)."""
    layout = scene.__dict__.get("layout")
    return layout if isinstance(layout, Layout) else None


class Cluttered3DScenario(Scenario3D):
    """3D-Cluttered: one piece of furniture per workspace (shelves, a cage, a table or an
    open box, see the module docstring), only boxes; problems from inside the furniture
    to outside it (either way round), preferably with a blocked straight line.

    ``robot``: ``sphere3d`` (default) or ``sshape``, by name or as a robot;
    ``config``: a :class:`ClutteredConfig`."""

    name = "cluttered3d"

    def __init__(self, robot: str | Robot | None = None, config: ClutteredConfig | None = None) -> None:
        super().__init__(robot)
        self.layouts = config or ClutteredConfig()
        unknown = set(self.layouts.kinds) - set(BUILDERS)
        if unknown or not self.layouts.kinds:
            raise ValueError(f"unknown layout kinds {sorted(unknown)}; use some of {', '.join(KINDS)}")

    def build(self, rng: np.random.Generator, split: str) -> Scene:
        """A new workspace drawn from ``rng``: the kind, then its layout (``layout_of(scene)``)."""
        kind = self.layouts.kinds[int(rng.integers(0, len(self.layouts.kinds)))]
        layout = BUILDERS[kind](rng, self.layouts)
        scene = Scene(layout.boxes, LOW, HIGH)
        scene.__dict__["layout"] = layout
        return scene

    def sample_problem(self, scene: Scene, rng: np.random.Generator) -> tuple[Array, Array]:
        """A free start and goal, one inside the furniture and one outside (or, for
        shelves, sometimes in two compartments), at least ``min_goal_distance`` apart;
        the first of ``problem_tries`` pairs whose straight line is blocked, else the
        first pair drawn. Scenes without a layout: uniform, as any scenario."""
        layout = layout_of(scene)
        if layout is None:
            return super().sample_problem(scene, rng)
        pair = self.first_blocked_pair(
            lambda: self._draw_pair(scene, layout, rng),
            lambda a, b: self.straight_free(scene, a, b),
            self.layouts.problem_tries,
        )
        return pair if pair is not None else super().sample_problem(scene, rng)

    def _draw_pair(self, scene: Scene, layout: Layout, rng: np.random.Generator) -> tuple[Array, Array] | None:
        inside = [layout.inside[i] for i in rng.permutation(len(layout.inside))]
        a = self.free_in(scene, inside, rng)
        if a is None:
            return None
        if len(inside) > 1 and rng.random() < self.layouts.two_compartments:
            b = self.free_in(scene, [r for r in inside if not r.contains(a[None, :3])[0]], rng)
        else:
            b = self.free_outside(scene, layout.hull, rng)
        if b is None or np.linalg.norm(a[:3] - b[:3]) < self.layouts.min_goal_distance:
            return None
        return (a, b) if rng.random() < 0.5 else (b, a)

    def _free(self, scene: Scene, pos: Array, rng: np.random.Generator, within: Region | None = None) -> Array | None:
        """The first free configuration at positions ``pos`` (in the bounds), random
        orientations, with the centres of all its body parts ``within`` a region (grown by
        ``part_margin``) if one is given; ``None`` if there is none."""
        pos = pos[np.all((pos >= scene.low) & (pos <= scene.high), axis=1)]
        if not len(pos):
            return None
        q = np.concatenate([pos, self.robot.sample_orientation(rng, len(pos))], axis=1)
        ok: Bool = np.ones(len(q), dtype=bool)
        if within is not None:
            sc, bc, _, _ = self.robot.world_parts(q)
            centres = np.concatenate([sc, bc], axis=1).reshape(-1, 3)
            ok = np.all(within.contains(centres, self.layouts.part_margin).reshape(len(q), -1), axis=1)
        if ok.any():
            ok[ok] = ~self.robot.collides(scene.world, q[ok])
        return q[int(np.argmax(ok))] if ok.any() else None

    def free_in(
        self, scene: Scene, regions: Sequence[Region], rng: np.random.Generator, tries: int = 64, batch: int = 32
    ) -> Array | None:
        """A free configuration whose position and body part centres lie in one of
        ``regions`` (tried in turn), or ``None`` when ``tries`` batches of ``batch`` draws
        found none."""
        if not regions:
            return None
        for k in range(tries):
            region = regions[k % len(regions)]
            q = self._free(scene, region.sample(rng, batch), rng, within=region)
            if q is not None:
                return q
        return None

    def free_outside(
        self, scene: Scene, hull: Region, rng: np.random.Generator, tries: int = 64, batch: int = 32
    ) -> Array | None:
        """A free configuration whose position lies in the bounds, off ``hull`` (grown by
        ``hull_margin``)."""
        for _ in range(tries):
            pos = rng.uniform(scene.low, scene.high, (batch, 3))
            q = self._free(scene, pos[~hull.contains(pos, self.layouts.hull_margin)], rng)
            if q is not None:
                return q
        return None

    def straight_free(self, scene: Scene, a: Array, b: Array, resolution: float = 0.02) -> bool:
        """Is the geodesic ``a -> b`` free of obstacles and inside the bounds, checked at
        ``resolution`` steps (a quick test for the sampler; planners certify their own)?"""
        n = max(2, int(math.ceil(float(self.robot.distance(a, b)) / resolution)) + 1)
        q = self.robot.interpolate(a, b, np.linspace(0.0, 1.0, n))
        pos = q[:, :3]
        if np.any(pos < scene.low - 1e-9) or np.any(pos > scene.high + 1e-9):
            return False
        return not bool(self.robot.collides(scene.world, q).any())
