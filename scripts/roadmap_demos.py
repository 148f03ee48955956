"""Demonstrations from the roadmap expert (pointplan.learning.roadmap): one roadmap per
training workspace, one shortest-path search from the goal, every state labelled with one
answer.

The file is in the format of ``pointplan bc --demos`` (the same problems ``pointplan bc
--problems N --seed S`` would plan with Bi-RRT; env and robot must match the run's):

    python scripts/roadmap_demos.py --env boxes3d --robot sshape --problems 200 --seed 0 \\
        --nodes 1000 --k 10 --paths-per-problem 20 --out runs/demos_roadmap.npz
    pointplan bc --env boxes3d --robot sshape --demos runs/demos_roadmap.npz ...

Per problem: the path from its own start (where it joins the roadmap) and
``--paths-per-problem`` paths from roadmap nodes that reach the goal, cut into policy
steps, never shortcut (``--lookahead`` drops waypoints only where every state keeps one
label). Ctrl-C writes what was built so far. ``--consistency N`` measures,
on N validation problems, how far the move from the start (the first step, and the heading
to the point 0.5 along the path) depends on the expert's randomness (two roadmaps, two
Bi-RRT seeds):

    python scripts/roadmap_demos.py --consistency 40
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def build(args: argparse.Namespace) -> None:
    """Build and write the demonstrations; Ctrl-C keeps the problems done."""
    from pointplan.learning.bc import demos_from_paths, save_demos
    from pointplan.learning.roadmap import demo_problem_indices, problem_paths
    from pointplan.progress import progress_bar
    from pointplan.scenes.scenarios import make_scenario

    sc = make_scenario(args.env, robot=args.robot)
    indices = demo_problem_indices(args.seed, args.problems)
    paths: list[tuple[int, np.ndarray]] = []
    stats: dict[str, list[float]] = {"build_s": [], "start": [], "goal": [], "reach": []}
    t0 = time.perf_counter()
    bar = progress_bar(indices, desc="roadmap demos", unit="problem", disable=args.quiet)
    try:
        for n, index in enumerate(bar, 1):
            pp = problem_paths(
                sc, args.split, args.seed, index, args.nodes, args.k, args.paths_per_problem, args.rng_seed
            )
            paths.extend((index, p) for p in pp.paths if len(p) > 1)
            stats["build_s"].append(pp.tree.roadmap.build_time_s)
            stats["start"].append(pp.start is not None)
            stats["goal"].append(len(pp.tree.goal_edges) > 0)
            stats["reach"].append(len(pp.tree.reachable) / len(pp.tree.roadmap))
            bar.set_postfix(
                start=f"{np.mean(stats['start']):.2f}", steps=sum(len(p) - 1 for _, p in paths), refresh=False
            )
            if args.save_every and n % args.save_every == 0 and paths:
                save_demos(args.out, sc, demos_from_paths(sc, args.split, args.seed, paths), args.split, args.seed)
    except KeyboardInterrupt:
        log(f"\ninterrupted: writing the {len(stats['start'])} of {len(indices)} problems done")
    finally:
        bar.close()
    if not paths:
        raise SystemExit("no demonstration was built")
    save_demos(args.out, sc, demos_from_paths(sc, args.split, args.seed, paths), args.split, args.seed)
    report(args, paths, stats, time.perf_counter() - t0)


def report(
    args: argparse.Namespace, paths: list[tuple[int, np.ndarray]], stats: dict[str, list[float]], wall: float
) -> None:
    """One summary of a build."""
    steps = sum(len(p) - 1 for _, p in paths)
    states = np.concatenate([p[:-1] for _, p in paths])
    unique = len(np.unique(np.round(states, 9), axis=0))
    b = np.asarray(stats["build_s"])
    print(
        f"{args.out}: {len(paths)} paths, {steps} steps ({unique / max(steps, 1):.0%} distinct states) from "
        f"{len(b)} problems; {os.path.getsize(args.out) / 1e6:.1f} MB, {wall:.0f} s\n"
        f"  roadmap build per workspace ({args.nodes} nodes, k={args.k}): mean {b.mean():.2f} s, max {b.max():.2f} s\n"
        f"  goal joined the roadmap: {np.mean(stats['goal']):.1%}; start reaches the goal: {np.mean(stats['start']):.1%}; "
        f"nodes reaching the goal: {np.mean(stats['reach']):.1%} on average",
        flush=True,
    )


def consistency(args: argparse.Namespace) -> None:
    """Print the label-consistency measurement."""
    from pointplan.learning.roadmap import label_consistency
    from pointplan.scenes.scenarios import make_scenario

    sc = make_scenario(args.env, robot=args.robot)
    t0 = time.perf_counter()
    res = label_consistency(
        sc,
        args.consistency,
        args.nodes,
        args.k,
        seed=args.seed,
        max_nodes=args.birrt_max_nodes,
        progress=not args.quiet,
    )
    print(
        f"label consistency on {args.consistency} {args.env} val problems, roadmaps of {args.nodes} nodes, k={args.k}, "
        f"Bi-RRT {args.birrt_max_nodes} nodes ({time.perf_counter() - t0:.0f} s); "
        f"median cosine / share below 0 / problems both solved:"
    )
    names = {
        "roadmap": "roadmap, two roadmaps",
        "lookahead": "roadmap with lookahead, two roadmaps",
        "birrt": "Bi-RRT, seeds 1 and 2",
        "roadmap_vs_birrt": "roadmap vs Bi-RRT",
        "lookahead_vs_birrt": "lookahead vs Bi-RRT",
    }
    for key, name in names.items():
        cells = [
            f"{what} {r['median_cos']:.2f} / {r['share_below_0']:.0%} / {int(r['pairs'])}"
            for what, r in (("first step", res[key]["first"]), ("heading", res[key]["heading"]))
        ]
        print(f"  {name}: {'; '.join(cells)}")


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="roadmap_demos.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--env", default="boxes3d", help="scenario (default: %(default)s)")
    ap.add_argument("--robot", default="sshape", help="robot (default: %(default)s)")
    ap.add_argument("--problems", type=int, default=200, help="training problems (default: %(default)s)")
    ap.add_argument("--split", default="train", help="split of the problems (default: %(default)s)")
    ap.add_argument("--seed", type=int, default=0, help="problem seed, as pointplan bc --seed (default: %(default)s)")
    ap.add_argument("--nodes", type=int, default=1000, help="roadmap nodes per workspace (default: %(default)s)")
    ap.add_argument("--k", type=int, default=10, help="nearest nodes each node is joined to (default: %(default)s)")
    ap.add_argument(
        "--paths-per-problem", type=int, default=20, help="paths from roadmap nodes per problem (default: %(default)s)"
    )
    ap.add_argument(
        "--lookahead",
        action="store_true",
        help="from each state move to the furthest point of its roadmap path one certified edge reaches (still one label per state)",
    )
    ap.add_argument("--rng-seed", type=int, default=0, help="seed of the roadmaps (default: %(default)s)")
    ap.add_argument("--out", help="the demonstrations file (.npz, pointplan bc --demos); overwritten")
    ap.add_argument("--save-every", type=int, default=50, help="rewrite --out every this many problems (0: at the end)")
    ap.add_argument("--consistency", type=int, metavar="N", help="measure label consistency on N validation problems")
    ap.add_argument(
        "--birrt-max-nodes",
        type=int,
        default=20000,
        help="Bi-RRT's node budget in --consistency (default: %(default)s)",
    )
    ap.add_argument("--quiet", action="store_true", help="no progress bars")
    return ap


def main() -> None:
    args = parser().parse_args()
    if args.out is None and not args.consistency:
        parser().error("give --out (demonstrations) or --consistency N (a measurement), or both")
    if args.out is not None:
        build(args)
    if args.consistency:
        consistency(args)


if __name__ == "__main__":
    main()
