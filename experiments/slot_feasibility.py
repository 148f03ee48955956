"""Which Slot widths can the S-shape pass at all? A necessary condition, searched with coal.

Start and goal of a Slot problem have the whole S-shape on either side of the wall, so on
any collision-free path every point of the body crosses the wall's mid-plane x = 0 at some
moment, inside the slot. For a point ``c`` of the body (a corner of its centreline, where
two bars meet) this script searches the configurations with ``c`` in the slot's opening at
x = 0 (5 degrees of freedom: the rotation and where ``c`` is in the opening) for the one
with the largest clearance to the wall: the smallest signed distance, computed by coal,
between the S-shape's five boxes and the wall's boxes. If no such configuration is free
for some corner, no path passes that slot width.

The search is a local maximisation (Nelder-Mead on the rotation vector and the opening
coordinates) from many random starts; a negative best clearance is therefore evidence,
not proof, that the width is impassable. Every positive best is re-checked with
pointplan's own collision test of the robot in a Slot scene of that width.

    python experiments/slot_feasibility.py --widths 2 2.5 3 3.5 4 --starts 200 --json docs/data/slot/feasibility.json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import coal
import numpy as np
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

from pointplan.geometry.shapes import Box
from pointplan.robots.sshape import BAR_THICKNESS, S_CORNERS, SShape
from pointplan.scenes.scene import Scene
from pointplan.scenes.scenes3d import HALF_EXTENT, HIGH, LOW, SlotConfig

#: the centreline's interior corners (where two bars meet), named by their bars
CORNERS = {"A-B": S_CORNERS[1], "B-C": S_CORNERS[2], "C-D": S_CORNERS[3], "D-E": S_CORNERS[4]}


def wall_boxes(width: float, cfg: SlotConfig) -> list[Box]:
    """The Slot wall (x = 0) with a slot of ``width`` along z and ``cfg.slot_length`` along
    y, centred at the origin, as the scene builds it."""
    e, t = HALF_EXTENT, cfg.wall_thickness
    lo, hi = np.array([0.0, -cfg.slot_length / 2, -width / 2]), np.array([0.0, cfg.slot_length / 2, width / 2])
    boxes = []
    for a, b in ((-e, lo[1]), (hi[1], e)):
        boxes.append(Box(np.array([0.0, (a + b) / 2, 0.0]), np.array([t, b - a, 2 * e])))
    for a, b in ((-e, lo[2]), (hi[2], e)):
        boxes.append(Box(np.array([0.0, 0.0, (a + b) / 2]), np.array([t, hi[1] - lo[1], b - a])))
    return boxes


class Clearance:
    """Signed distance (coal) between the S-shape at a pose and the wall's boxes."""

    def __init__(self, robot: SShape, wall: list[Box]) -> None:
        parts = robot.parts
        self.bars = [(coal.Box(*(2 * h)), c, r) for c, r, h in zip(parts.box_centers, parts.box_rotations, parts.box_halfs, strict=True)]
        self.wall = [(coal.Box(*b.size), coal.Transform3s(np.eye(3), np.asarray(b.center, np.float64))) for b in wall]
        self.req = coal.DistanceRequest()
        self.req.enable_signed_distance = True

    def __call__(self, rot: np.ndarray, pos: np.ndarray) -> float:
        best = np.inf
        for shape, c, r in self.bars:
            tf = coal.Transform3s(rot @ r, rot @ c + pos)
            for wshape, wtf in self.wall:
                res = coal.DistanceResult()
                best = min(best, coal.distance(shape, tf, wshape, wtf, self.req, res))
        return float(best)


def search(clear: Clearance, corner: np.ndarray, width: float, length: float, starts: int, rng: np.random.Generator) -> tuple[float, np.ndarray]:
    """The largest clearance found over poses with ``corner`` (body frame) at x = 0 in the
    opening; returns it and the pose ``(x, y, z, qx, qy, qz, qw)``."""
    half = np.array([length / 2, width / 2])

    def pose(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rot = Rotation.from_rotvec(v[:3]).as_matrix()
        yz = half * np.tanh(v[3:5])  # the corner stays in the opening
        world = np.array([0.0, yz[0], yz[1]])
        return rot, world - rot @ corner

    def cost(v: np.ndarray) -> float:
        return -clear(*pose(v))

    best, best_v = -np.inf, None
    for _ in range(starts):
        v0 = np.concatenate([Rotation.random(random_state=rng).as_rotvec(), rng.normal(0, 0.5, 2)])
        r = minimize(cost, v0, method="Nelder-Mead", options={"xatol": 1e-5, "fatol": 1e-7, "maxiter": 1500})
        if -r.fun > best:
            best, best_v = -r.fun, r.x
    assert best_v is not None
    rot, pos = pose(best_v)
    return best, np.concatenate([pos, Rotation.from_matrix(rot).as_quat()])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--widths", type=float, nargs="+", default=[2, 2.5, 3, 3.5, 4], help="slot widths in bar thicknesses (0.036)")
    ap.add_argument("--corners", nargs="+", default=list(CORNERS), choices=list(CORNERS))
    ap.add_argument("--starts", type=int, default=100, help="random starts of the local search per (width, corner)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", help="write the results here")
    args = ap.parse_args()
    robot, cfg = SShape(), SlotConfig()
    rng = np.random.default_rng(args.seed)
    rows = []
    for wb in args.widths:
        width = wb * BAR_THICKNESS
        wall = wall_boxes(width, cfg)
        clear = Clearance(robot, wall)
        scene = Scene(wall, LOW, HIGH)
        for name in args.corners:
            t0 = time.perf_counter()
            best, q = search(clear, CORNERS[name], width, cfg.slot_length, args.starts, rng)
            free = not bool(np.asarray(robot.collides(scene.world, q[None]))[0])
            rows.append(
                {"width_bars": wb, "corner": name, "best_clearance": best, "pose": q.tolist(), "pointplan_free": free, "seconds": time.perf_counter() - t0}
            )
            print(
                f"width {wb:4.2f} bars ({width:.3f}), corner {name}: best clearance {best:+.4f}  (pointplan: {'free' if free else 'collides'}; {rows[-1]['seconds']:.0f} s)",
                file=sys.stderr,
            )
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({"command": " ".join(sys.argv), "starts": args.starts, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
