"""Draw 3D-Cluttered workspaces, one per layout kind (shelves, cage, table, open box), each with a start and a goal.

    python scripts/draw_cluttered.py --plan -o docs/img/cluttered3d.png  # the picture in docs/img
    python scripts/draw_cluttered.py --robot sphere3d --split val -o cluttered_val.png

For each kind it takes the first workspace of that kind in the split (test by default),
for shelves the first whose open front faces the viewer, and draws its first problem (seed 0) with pointplan's 3D renderer
(:func:`pointplan.viz.plot3d.render_grid_3d`). ``--plan`` also runs Bi-RRT and draws its
paths.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from pointplan.planners import make_planner
from pointplan.scenes.cluttered import KINDS, Cluttered3DScenario, Layout, layout_of
from pointplan.scenes.scene import Problem
from pointplan.viz.plot3d import render_grid_3d


def faces_viewer(layout: Layout, azim: float) -> bool:
    """Whether the furniture's local front (-y: the open side of shelves) turns toward a
    camera at azimuth ``azim`` (degrees)."""
    eye = np.array([math.cos(math.radians(azim)), math.sin(math.radians(azim)), 0.0])
    return bool(-layout.hull.rotation[:, 1] @ eye > 0.75)


def first_of_each_kind(scenario: Cluttered3DScenario, split: str, azim: float, limit: int = 300) -> list[Problem]:
    """The first problem of the first workspace of each kind in ``split`` (shelves: facing
    a camera at ``azim``), in the order of :data:`~pointplan.scenes.cluttered.KINDS`."""
    found: dict[str, Problem] = {}
    for i in range(limit):
        layout = layout_of(scenario.scene(split, i))
        if layout is None or layout.kind in found:
            continue
        if layout.kind != "shelves" or faces_viewer(layout, azim):
            found[layout.kind] = scenario.problem(split, i)
        if len(found) == len(KINDS):
            break
    return [found[k] for k in KINDS if k in found]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("-o", "--output", default="docs/img/cluttered3d.png", help="PNG to write")
    ap.add_argument("--robot", default="sshape", choices=["sshape", "sphere3d"], help="robot drawn at start and goal")
    ap.add_argument("--split", default="test", choices=["train", "val", "test"], help="split the workspaces come from")
    ap.add_argument("--plan", action="store_true", help="also plan with Bi-RRT and draw the paths")
    ap.add_argument("--azim", type=float, default=-60.0, help="view azimuth, degrees")
    ap.add_argument("--cols", type=int, default=2, help="workspaces per row")
    args = ap.parse_args()
    scenario = Cluttered3DScenario(robot=args.robot)
    problems = first_of_each_kind(scenario, args.split, args.azim)
    titles = [f"{layout_of(p.scene).kind}: {p.scene.name}" for p in problems]  # type: ignore[union-attr]
    paths = None
    if args.plan:
        planner = make_planner("birrt", scenario.robot, seed=0, max_nodes=20000)
        paths = [r.path if r.success else None for r in (planner.plan(p) for p in problems)]
    render_grid_3d(problems, scenario.robot, paths, output=args.output, cols=args.cols, titles=titles, azim=args.azim)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
