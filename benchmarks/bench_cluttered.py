"""3D-Cluttered: the policy, the hybrid, OMPL's RRTConnect and Bi-RRT taking turns on the
same test problems, for the sphere and the S-shape.

Per robot (its shipped default policy: the sphere's ``global``, the S-shape's ``local``),
the first ``--problems`` test problems of ``cluttered3d`` (seed ``--seed``) are planned by
every planner in turn (the order rotates from problem to problem, so that a busy machine
slows them alike), one thread, ``planner.plan(problem)``: the policy alone (one rollout,
its escape), the hybrid (the policy, then Bi-RRT, ``--hybrid-limit`` seconds for the whole
query), OMPL's RRTConnect with pointplan's certified motion checks (``--ompl-limit``
seconds) and Bi-RRT (its 10,000-node budget). Every returned path is re-checked by the
evaluator (:func:`pointplan.evaluation.check_path`); only accepted paths count as solved.

One JSON line per problem goes to ``--out`` as it is measured (an existing file is resumed;
Ctrl-C keeps what was done); the summary says, per robot, what each planner solved, its
median, mean and largest time, and which problems OMPL solved that the hybrid did not.

    python benchmarks/bench_cluttered.py --problems 100 --out docs/data/cluttered/bench.jsonl
    python benchmarks/bench_cluttered.py --summary docs/data/cluttered/bench.jsonl
"""

from __future__ import annotations

import argparse
import gc
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

PLANNERS = ("policy", "hybrid", "ompl:RRTConnect", "birrt")


def run(args: argparse.Namespace) -> None:
    import torch

    from pointplan.evaluation import check_path
    from pointplan.planners import make_planner
    from pointplan.scenes.cluttered import layout_of
    from pointplan.scenes.scenarios import make_scenario

    torch.set_num_threads(1)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    done = set()
    if out.exists():
        done = {(r["robot"], r["tag"]) for r in map(json.loads, out.read_text().splitlines()) if r}
    with out.open("a") as f:
        for robot_name in args.robots.split(","):
            sc = make_scenario("cluttered3d", robot=robot_name)
            robot = sc.robot
            built = {
                "policy": make_planner("policy", robot),
                "hybrid": make_planner("hybrid", robot, time_limit=args.hybrid_limit),
                "ompl:RRTConnect": make_planner("ompl:RRTConnect", robot, time_limit=args.ompl_limit),
                "birrt": make_planner("birrt", robot),
            }
            for k, p in enumerate(sc.problems("test", args.problems, seed=args.seed)):
                if (robot_name, p.tag) in done:
                    continue
                layout = layout_of(p.scene)
                row: dict[str, Any] = {"robot": robot_name, "tag": p.tag, "kind": layout.kind if layout else None}
                for name in PLANNERS[k % len(PLANNERS) :] + PLANNERS[: k % len(PLANNERS)]:
                    gc.collect()
                    t = time.perf_counter()
                    res = built[name].plan(p)
                    dt = time.perf_counter() - t
                    ok = bool(res.success) and bool(check_path(robot, p, res.path))
                    row[name] = {"claimed": bool(res.success), "ok": ok, "time_s": dt, "nodes": int(res.nodes)}
                f.write(json.dumps(row) + "\n")
                f.flush()
                print(robot_name, p.tag, row["kind"], {n: (row[n]["ok"], round(row[n]["time_s"], 3)) for n in PLANNERS})


def summary(path: Path) -> None:
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    for robot in sorted({r["robot"] for r in rows}):
        rs = [r for r in rows if r["robot"] == robot]
        print(f"\n{robot}: {len(rs)} test problems of cluttered3d")
        print("| planner | solved | median s | mean s | largest s |")
        print("|---|---|---|---|---|")
        for n in PLANNERS:
            t = np.array([r[n]["time_s"] for r in rs])
            solved = sum(r[n]["ok"] for r in rs)
            print(f"| {n} | {solved}/{len(rs)} | {np.median(t):.3f} | {t.mean():.3f} | {t.max():.2f} |")
        missed = [r["tag"] for r in rs if r["ompl:RRTConnect"]["ok"] and not r["hybrid"]["ok"]]
        print(f"solved by OMPL, not by the hybrid: {len(missed)} {' '.join(missed)}")
        kinds = sorted({r["kind"] for r in rs if r["kind"]})
        print("policy alone by kind: " + ", ".join(
            f"{k} {sum(r['policy']['ok'] for r in rs if r['kind'] == k)}/{sum(r['kind'] == k for r in rs)}" for k in kinds
        ))  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", default="sphere3d,sshape", help="(default: %(default)s)")
    ap.add_argument("--problems", type=int, default=100, help="test problems per robot (default: %(default)s)")
    ap.add_argument("--seed", type=int, default=2026, help="problem seed (default: %(default)s)")
    ap.add_argument("--hybrid-limit", type=float, default=10.0, help="hybrid: seconds a query (default: %(default)s)")
    ap.add_argument("--ompl-limit", type=float, default=5.0, help="OMPL: seconds a query (default: %(default)s)")
    ap.add_argument("--out", default="cluttered.jsonl", help="one JSON line per problem (default: %(default)s)")
    ap.add_argument("--summary", help="print the summary of an existing output file and stop")
    args = ap.parse_args()
    if args.summary:
        summary(Path(args.summary))
        return
    try:
        run(args)
    except KeyboardInterrupt:
        print("interrupted: the problems measured so far are in", args.out)
    summary(Path(args.out))


if __name__ == "__main__":
    main()
