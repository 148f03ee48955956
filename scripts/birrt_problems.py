"""Bi-RRT on chosen test problems of a scenario, one JSON line per problem (appended as each
finishes, so a long run can be split over processes and stopped at any time; a run
skips the problems its file holds already, so it resumes), and a summary of such files.

    python scripts/birrt_problems.py run --env slot --robot sshape --max-nodes 50000 \\
        --start 0 --stop 100 --every 2 --out runs/slot_even.jsonl
    python scripts/birrt_problems.py summary runs/slot_even.jsonl runs/slot_odd.jsonl

Problem ``i`` is test problem ``i`` (start and goal seed 0) planned by a fresh
``BiRRT(seed=i)``, so results do not depend on how the problems are split; success is the
evaluator's re-check of the path.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from pointplan.evaluation.evaluate import check_path, path_length
from pointplan.planners import make_planner
from pointplan.scenes.scenarios import make_scenario


def run(args: argparse.Namespace) -> None:
    sc = make_scenario(args.env, robot=args.robot)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    done = (
        {json.loads(line)["index"] for line in out.read_text().splitlines() if line.strip()} if out.exists() else set()
    )
    if done:
        print(f"{out}: {len(done)} problems done already, skipped", flush=True)
    for i in range(args.start, args.stop, args.every):
        if i in done:
            continue
        problem = sc.problem("test", i, seed=0)
        planner = make_planner("birrt", sc.robot, seed=i, max_nodes=args.max_nodes)
        t0 = time.perf_counter()
        res = planner.plan(problem)
        elapsed = time.perf_counter() - t0
        ok = bool(len(res.path) and check_path(sc.robot, problem, res.path))
        row = {
            "index": i,
            "success": ok,
            "claimed": bool(res.success),
            "nodes": int(res.nodes),
            "collision_checks": int(res.collision_checks),
            "path_length": path_length(sc.robot, res.path) if ok else None,
            "time_s": elapsed,
            "extra": {
                k: float(v) if isinstance(v, (int, float, np.floating)) else str(v)
                for k, v in problem.scene.__dict__.get("slot", {}).items()
                if k == "width"
            },
        }
        with out.open("a") as f:
            f.write(json.dumps(row) + "\n")
        print(f"problem {i}: success={ok} nodes={res.nodes} {elapsed:.1f} s", flush=True)


def summary(args: argparse.Namespace) -> None:
    rows = [json.loads(line) for p in args.files for line in Path(p).read_text().splitlines() if line.strip()]
    if not rows:
        raise SystemExit("no problems in these files")
    ok = [r for r in rows if r["success"]]
    nodes = [r["nodes"] for r in rows]
    print(f"problems {len(rows)} (indices {min(r['index'] for r in rows)}..{max(r['index'] for r in rows)})")
    print(f"success {100 * len(ok) / len(rows):.1f}% ({len(ok)}/{len(rows)})")
    print(f"nodes mean {np.mean(nodes):.0f} median {np.median(nodes):.0f}")
    print(f"collision checks mean {np.mean([r['collision_checks'] for r in rows]):.0f}")
    if ok:
        print(f"path length mean {np.mean([r['path_length'] for r in ok]):.3f}")
    print(
        f"time mean {np.mean([r['time_s'] for r in rows]):.1f} s, median {np.median([r['time_s'] for r in rows]):.1f} s"
    )
    print(f"claims disagree {sum(r['success'] != r['claimed'] for r in rows)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("run")
    p.add_argument("--env", required=True)
    p.add_argument("--robot")
    p.add_argument("--max-nodes", type=int, default=20000)
    p.add_argument("--start", type=int, default=0)
    p.add_argument("--stop", type=int, default=100)
    p.add_argument("--every", type=int, default=1)
    p.add_argument("--out", required=True)
    p.set_defaults(func=run)
    p = sub.add_parser("summary")
    p.add_argument("files", nargs="+")
    p.set_defaults(func=summary)
    args = ap.parse_args()
    args.func(args)


if __name__ == "__main__":
    main()
