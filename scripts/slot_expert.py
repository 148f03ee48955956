"""Slot's privileged experts: build the threading template, plan demonstrations with it,
or plan chosen Slot problems with the sweep expert.

- ``template``: the slot threading template (:mod:`pointplan.planners.slot_threading`):
  the guided sweep through a reference slot, simplified, certified by the evaluator's
  ``check_path``; the first certified one is written. The defaults rebuild the shipped
  ``src/pointplan/data/slot_threading.npz`` (about 1.5-3.5 minutes on one core):

      python scripts/slot_expert.py template --out src/pointplan/data/slot_threading.npz

- ``demos``: the threading expert's demonstrations of training problems, in the file format
  of ``pointplan bc --demos`` and ``pointplan ppo --start-demos`` (the problems
  ``pointplan bc`` would plan; each path certified by ``check_path``; a rerun skips the
  problems already in the file):

      python scripts/slot_expert.py demos --save-demos runs/demos_slot_canonical.npz --problems 3000

- ``sweep``: the sweep expert (:mod:`pointplan.planners.slot_sweep`) on Slot problems of
  chosen widths, one line per problem (solved means certified by ``check_path``):

      python scripts/slot_expert.py sweep --problems 6 --min-bars 2 --max-bars 4 --seed 5
      python scripts/slot_expert.py sweep --problems 12 --first 100 --guide 0.05
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def demo_index(seed: int, n_problems: int, i: int) -> int:
    """The training problem of demonstration ``i`` of ``n_problems``: the problems
    ``pointplan bc`` plans its demonstrations from (far from those the RL trainer draws
    first; ``pointplan.learning.bc`` keeps this rule private)."""
    return 1_000_000 + seed * n_problems + i


def make_template(args: argparse.Namespace) -> None:
    from pointplan.evaluation.evaluate import check_path, timed_path
    from pointplan.planners.base import path_length
    from pointplan.planners.slot_threading import reference_problem, save_template, template_candidates
    from pointplan.robots.sshape import SShape
    from pointplan.scenes.scene import Problem

    robot = SShape()
    scene = reference_problem(args.width).scene
    found = template_candidates(
        args.width, args.seed, args.tries, args.orders, args.ds, args.min_clearance, args.guide, args.margin, log=log
    )
    for order, poses in found:
        ok = check_path(robot, Problem(scene, poses[0], poses[-1]), poses)
        print(
            f"  {len(poses) - 2} vertices, length {path_length(robot, poses[1:-1]):.2f}, {len(timed_path(robot, poses)) - 1} steps with the straight ends, "
            f"certified: {bool(ok)} {ok.reason if not ok else ''}",
            flush=True,
        )
        if ok:
            save_template(args.out, poses, args.width, order, args.seed, ok.clearance)
            print(f"{args.out}: {len(poses)} poses (clearance {ok.clearance:.4f})", flush=True)
            return
    raise SystemExit("no template found")


def demos(args: argparse.Namespace) -> None:
    """Demonstrations of training problems ``demo_index(seed, demo_n, i)`` for ``i`` in
    ``first .. first + problems - 1``; the file is rewritten every ``--save-every`` solved
    problems and at the end."""
    from pointplan.evaluation.evaluate import check_path
    from pointplan.learning.bc import demos_from_paths, load_demos, resample_path, save_demos
    from pointplan.planners.slot_threading import SlotThreading
    from pointplan.progress import progress_bar
    from pointplan.robots.sshape import BAR_THICKNESS
    from pointplan.scenes.scenarios import make_scenario

    sc = make_scenario(args.env, robot="sshape")
    robot = sc.robot
    expert = SlotThreading.load(robot, args.template, args.max_nodes, copies=args.copies)
    out = Path(args.save_demos)
    paths: list[tuple[int, np.ndarray]] = list(load_demos(out, sc).paths) if out.exists() else []
    done = {k for k, _ in paths}
    counts = {"solved": 0, "narrower than the template": 0, "wider than --max-bars": 0, "failed": 0, "already": 0}
    new = 0
    bar = progress_bar(
        range(args.first, args.first + args.problems), desc="threading demos", unit="problem", disable=args.quiet
    )
    try:
        for i in bar:
            index = demo_index(args.seed, args.demo_n, i)
            if index in done:
                counts["already"] += 1
                continue
            p = sc.problem("train", index, seed=args.seed)
            if not expert.threads(p.scene.__dict__["slot"]):
                counts["narrower than the template"] += 1
                continue
            if args.max_bars and p.scene.__dict__["slot"]["width"] / BAR_THICKNESS > args.max_bars:
                counts["wider than --max-bars"] += 1
                continue
            path = expert.plan(p, seed=index)
            ok = check_path(robot, p, path) if path is not None else None
            if path is None or not ok:
                counts["failed"] += 1
                if args.verbose:
                    log(f"problem {i}: {'no path' if ok is None else ok.reason}")
                continue
            counts["solved"] += 1
            paths.append((index, resample_path(robot, path)))
            new += 1
            if new % args.save_every == 0:
                save_demos(out, sc, demos_from_paths(sc, "train", args.seed, paths), "train", args.seed)
            bar.set_postfix(solved=counts["solved"], failed=counts["failed"], refresh=False)
    except KeyboardInterrupt:
        log("interrupted: saving what was planned")
    if new:
        save_demos(out, sc, demos_from_paths(sc, "train", args.seed, paths), "train", args.seed)
    log(f"{out}: {len(paths)} demonstrations; this run: {counts}")


def sweep_problems(args: argparse.Namespace) -> None:
    from pointplan.evaluation.evaluate import check_path, timed_path
    from pointplan.planners.slot_sweep import plan
    from pointplan.robots.sshape import BAR_THICKNESS
    from pointplan.scenes.scenes3d import SlotConfig, SlotMovingScenario

    sc = SlotMovingScenario(config=SlotConfig(min_width_bars=args.min_bars, max_width_bars=args.max_bars))
    robot = sc.robot
    chosen = range(args.problems) if args.only is None else [i for i in range(args.problems) if i in args.only]
    solved = 0
    for i in chosen:
        p = sc.problem(args.split, args.first + i, seed=args.seed)
        t = time.perf_counter()
        path, info = plan(
            robot,
            p,
            args.ds,
            i,
            args.max_nodes,
            log if args.verbose else None,
            args.min_clearance,
            args.tries,
            args.guide,
        )
        good = path is not None and bool(check_path(robot, p, path))
        if path is not None:
            info["steps"] = len(timed_path(robot, path)) - 1
        solved += good
        wb = p.scene.__dict__["slot"]["width"] / BAR_THICKNESS
        print(f"sweep: width {wb:.2f} bars, solved {good}, {time.perf_counter() - t:.1f} s, {info}", flush=True)
    print(f"sweep: {solved}/{len(chosen)} solved")


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="slot_expert.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = ap.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("template", help="plan and certify the threading template of the reference slot")
    t.add_argument("--out", required=True, help="the template file (np.savez)")
    t.add_argument(
        "--width",
        type=float,
        default=2.15,
        help="the reference slot's width, in bars of 0.036 (default: %(default)s, the shipped template's)",
    )
    t.add_argument("--seed", type=int, default=2, help="seed of the sweeps' random stream (default: %(default)s)")
    t.add_argument(
        "--orders", nargs="+", default=["A", "E"], choices=["A", "E"], help="which end bar leads, tried in turn"
    )
    t.add_argument("--tries", type=int, default=3, help="rounds of --orders (default: %(default)s)")
    t.add_argument("--ds", type=float, default=0.004, help="arc length between sweep poses (default: %(default)s)")
    t.add_argument(
        "--min-clearance",
        type=float,
        default=0.0015,
        help="clearance (coal) every sweep pose must have (default: %(default)s)",
    )
    t.add_argument(
        "--guide",
        type=float,
        default=0.05,
        help="pull toward free poses of the next bend (0: off; default: %(default)s)",
    )
    t.add_argument(
        "--margin",
        type=float,
        default=0.0,
        help="simplify for the body grown by this much (keeps that clearance; ask --min-clearance above it)",
    )
    d = sub.add_parser("demos", help="the threading expert's demonstrations of training problems")
    d.add_argument("--save-demos", required=True, help="the demonstrations file (read first: its problems are skipped)")
    d.add_argument("--template", help="a template file (default: the shipped one, pointplan/data/slot_threading.npz)")
    d.add_argument("--env", default="slot", choices=["slot", "slotmoving", "slotwide", "slotclassic"])
    d.add_argument("--problems", type=int, default=3000)
    d.add_argument("--first", type=int, default=0)
    d.add_argument("--seed", type=int, default=0)
    d.add_argument(
        "--demo-n",
        type=int,
        default=3000,
        help="the n of the demonstration indices (the same for every process filling one file)",
    )
    d.add_argument("--max-nodes", type=int, default=5000, help="Bi-RRT nodes where a straight edge collides")
    d.add_argument(
        "--max-bars",
        type=float,
        default=0.0,
        help="only slots at most this many bars wide (0: every width; more thin-slot demonstrations)",
    )
    d.add_argument("--save-every", type=int, default=100)
    d.add_argument(
        "--copies",
        action="store_true",
        help="follow the template's symmetric copy turned least from the start (SlotThreading(copies=True))",
    )
    d.add_argument("--verbose", action="store_true", help="say why a problem failed")
    d.add_argument("--quiet", action="store_true", help="no progress bar")
    s = sub.add_parser("sweep", help="plan Slot problems with the sweep expert")
    s.add_argument("--problems", type=int, default=6)
    s.add_argument("--min-bars", type=float, default=2.0)
    s.add_argument("--max-bars", type=float, default=4.0)
    s.add_argument("--seed", type=int, default=5, help="problem seed")
    s.add_argument("--split", default="train")
    s.add_argument(
        "--first",
        type=int,
        default=0,
        help="the first workspace index (problems are workspaces first .. first + problems - 1)",
    )
    s.add_argument("--ds", type=float, default=0.004, help="arc length between sweep poses")
    s.add_argument("--max-nodes", type=int, default=5000, help="Bi-RRT nodes for each end")
    s.add_argument("--min-clearance", type=float, default=0.0015, help="clearance (coal) every sweep pose must have")
    s.add_argument(
        "--guide",
        type=float,
        default=0.0,
        help="pull toward free poses of the next bend found beforehand (weight; 0: off)",
    )
    s.add_argument(
        "--tries", type=int, default=1, help="rounds of the two sweeps (A first, E first), each from a new first pose"
    )
    s.add_argument("--only", type=int, nargs="*", help="plan only these of the problems (0-based)")
    s.add_argument("--verbose", action="store_true", help="say why a sweep gave up")
    return ap


def main(argv: list[str] | None = None) -> None:
    args = parser().parse_args(argv)
    if args.cmd == "template":
        make_template(args)
    elif args.cmd == "demos":
        demos(args)
    else:
        sweep_problems(args)


if __name__ == "__main__":
    main()
