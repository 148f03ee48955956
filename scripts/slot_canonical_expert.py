"""One threading of the slot for every Slot problem: demonstrations that agree.

Bi-RRT and the sweep (``slot_sweep_expert.py``) thread each slot their own way, and a
policy cloned from them averages the ways. Here one threading, the *template*, is planned
once by the guided sweep through a reference slot (centred, long along y, ``--width``
bars), simplified, and certified there. It then serves every slot at least that wide:

- a slot centred at ``c`` is the reference wall moved by ``c`` along the wall, so the
  template moved by ``c`` threads it;
- a slot long along z is the reference turned 90 degrees about x, so the template turned
  the same way threads it;
- a wider opening centred at the same place leaves a wall that is a subset of the
  narrower one's, so a path free in the narrow slot is free in the wide one.

The template's first pose is moved 0.3 back from the wall and its last 0.3 past it, so a
demonstration is: the start, straight to the first pose (Bi-RRT where that collides),
straight along x into the opening, the template, out along x, and straight (or Bi-RRT) to
the goal (``pointplan.planners.slot_threading``).
Every path is re-checked by the evaluator (``check_path``), nothing counts otherwise.

    python scripts/slot_canonical_expert.py template --width 2.15 --seed 2 --tries 3 --out src/pointplan/data/slot_threading.npz
    python scripts/slot_canonical_expert.py demos --save-demos runs/demos_slot_canonical.npz --problems 3000
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from slot_sweep_expert import simplify, sweep  # noqa: E402

from pointplan.evaluation.evaluate import check_path, timed_path  # noqa: E402
from pointplan.planners.base import path_length  # noqa: E402
from pointplan.planners.slot_threading import SlotThreading  # noqa: E402
from pointplan.robots.sshape import BAR_THICKNESS, SShape  # noqa: E402
from pointplan.scenes.scene import Problem  # noqa: E402
from pointplan.scenes.scenes3d import SlotScenario  # noqa: E402

#: how far before and past the wall (along x) the template's first and last poses are moved
BACK = 0.3


def reference(width_bars: float) -> Problem:
    """A problem in the reference slot (centred, long along y); its start and goal are
    placeholders, the template does not use them."""
    sc = SlotScenario("sshape")
    scene = sc.wall(width_bars * BAR_THICKNESS, np.zeros(3), 1)
    q = np.array([-0.4, 0, 0, 0, 0, 0, 1.0])
    return Problem(scene, q, q)


def make_template(args: argparse.Namespace) -> None:
    robot = SShape()
    problem = reference(args.width)
    rng = np.random.default_rng(args.seed)
    t0 = time.perf_counter()
    for attempt in range(args.tries):
        for order in args.orders:
            poses = sweep(robot, problem, order, args.ds, rng, args.verbose, args.min_clearance, args.guide)
            print(f"try {attempt}, led by {order}: {'found' if poses is not None else 'stuck'} ({time.perf_counter() - t0:.0f} s)", flush=True)
            if poses is None:
                continue
            raw = np.array(poses)
            ends = Problem(problem.scene, raw[0], raw[-1])
            # simplified for the body grown by --margin, so that the shortcuts keep that room
            path = simplify(robot.padded(args.margin) if args.margin > 0 else robot, ends, raw, args.seed)
            first, last = path[0].copy(), path[-1].copy()
            first[0] -= BACK
            last[0] += BACK
            full = np.concatenate([first[None], path, last[None]])
            ok = check_path(robot, Problem(problem.scene, full[0], full[-1]), full)
            print(
                f"  {len(path)} vertices, length {path_length(robot, path):.2f}, {len(timed_path(robot, full)) - 1} steps with the straight ends, certified: {bool(ok)} {ok.reason if not ok else ''}",
                flush=True,
            )
            if not ok:
                continue
            np.savez(args.out, poses=full, width_bars=args.width, order=order, seed=args.seed, clearance=float(ok.clearance))
            print(f"{args.out}: {len(full)} poses (clearance {ok.clearance:.4f})", flush=True)
            return
    raise SystemExit("no template found")


def demos(args: argparse.Namespace) -> None:
    """Demonstrations of Slot's training problems in ``pointplan bc --demos``'s format
    (problem ``_demo_index(seed, n, i)`` for ``i`` in ``first .. first + problems - 1``); the
    file is rewritten every ``--save-every`` solved problems and at the end, and a rerun skips
    the problems already in it."""
    from tqdm import tqdm

    from pointplan.learning.bc import _demo_index, demos_from_paths, load_demos, resample_path, save_demos
    from pointplan.scenes.scenarios import make_scenario

    sc = make_scenario(args.env, robot="sshape")
    robot = sc.robot
    expert = SlotThreading.load(robot, args.template, args.max_nodes, copies=args.copies)
    out = Path(args.save_demos)
    paths: list[tuple[int, np.ndarray]] = list(load_demos(out, sc).paths) if out.exists() else []
    done = {k for k, _ in paths}
    counts = {"solved": 0, "narrower than the template": 0, "failed": 0, "already": 0}
    new = 0
    bar = tqdm(range(args.first, args.first + args.problems), desc="canonical demos", unit="problem")
    try:
        for i in bar:
            index = _demo_index(args.seed, args.demo_n, i)
            if index in done:
                counts["already"] += 1
                continue
            p = sc.problem("train", index, seed=args.seed)
            if not expert.threads(p.scene.__dict__["slot"]):
                counts["narrower than the template"] += 1
                continue
            path = expert.plan(p, seed=index)
            ok = check_path(robot, p, path) if path is not None else None
            if path is None or not ok:
                counts["failed"] += 1
                if args.verbose:
                    print(f"problem {i}: {'no path' if ok is None else ok.reason}", file=sys.stderr)
                continue
            counts["solved"] += 1
            paths.append((index, resample_path(robot, path)))
            new += 1
            if new % args.save_every == 0:
                save_demos(out, sc, demos_from_paths(sc, "train", args.seed, paths), "train", args.seed)
            bar.set_postfix(solved=counts["solved"], failed=counts["failed"])
    except KeyboardInterrupt:
        print("interrupted: saving what was planned", file=sys.stderr)
    if new:
        save_demos(out, sc, demos_from_paths(sc, "train", args.seed, paths), "train", args.seed)
    print(f"{out}: {len(paths)} demonstrations; this run: {counts}", file=sys.stderr)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("template", help="plan the threading of the reference slot")
    t.add_argument("--width", type=float, default=2.05, help="the reference slot's width, in bars (0.036)")
    t.add_argument("--out", required=True)
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--orders", nargs="+", default=["A", "E"], choices=["A", "E"], help="which end bar leads, tried in turn")
    t.add_argument("--tries", type=int, default=2)
    t.add_argument("--ds", type=float, default=0.004)
    t.add_argument("--min-clearance", type=float, default=0.0015)
    t.add_argument("--guide", type=float, default=0.05)
    t.add_argument("--margin", type=float, default=0.0, help="simplify for the body grown by this much (keeps that clearance; ask --min-clearance above it)")
    t.add_argument("--verbose", action="store_true")
    d = sub.add_parser("demos", help="demonstrations of training problems from a template")
    d.add_argument("--template", help="a template file (default: the one shipped, pointplan/data/slot_threading.npz)")
    d.add_argument("--save-demos", required=True)
    d.add_argument("--env", default="slot", choices=["slot", "slotwide", "slotfixed", "slotclassic"])
    d.add_argument("--problems", type=int, default=3000)
    d.add_argument("--first", type=int, default=0)
    d.add_argument("--seed", type=int, default=0)
    d.add_argument("--demo-n", type=int, default=3000, help="the n of the demonstration indices (the same for every process filling one file)")
    d.add_argument("--max-nodes", type=int, default=5000, help="Bi-RRT nodes where a straight edge collides")
    d.add_argument("--save-every", type=int, default=100)
    d.add_argument("--copies", action="store_true", help="follow the template's symmetric copy turned least from the start (SlotThreading(copies=True))")
    d.add_argument("--verbose", action="store_true")
    args = ap.parse_args()
    if args.cmd == "template":
        make_template(args)
    else:
        demos(args)


if __name__ == "__main__":
    main()
