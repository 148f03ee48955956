"""Arms on MotionBenchMaker: Bi-RRT and OMPL's RRTConnect (or any planners, the learned arm
policy and its hybrid included) taking turns on the same problems.

For an arm (``panda`` or ``ur5``), every problem of the chosen scenarios is planned by each
planner in turn (the order rotates from problem to problem, so that a busy machine slows
them alike), one thread, ``planner.plan(problem)``, both with pointplan's certified
joint-space motion check. Every returned path is re-checked by the evaluator
(:func:`pointplan.evaluation.check_path`: pinocchio and coal, conservative advancement,
independent of the planners' check); only accepted paths count as solved. Problems whose
start or goal collides for the arm's sphere model (conservative by construction) are
listed and left out of the rates.

One JSON line per problem goes to ``--out`` as it is measured (Ctrl-C keeps what was done);
the summary per scenario is printed at the end (or from an existing file with ``--summary``).

With ``--cameras N`` the planners see the scene only as ``N`` simulated depth cameras do
(:mod:`pointplan.scenes.cameras`: one merged point cloud, what no camera sees missing):
they plan against the cloud, and the evaluator certifies the path against the true
obstacles. Problems whose start or goal collides with the cloud are listed apart.

    python benchmarks/bench_mbm.py --arm panda --out mbm_panda.jsonl
    python benchmarks/bench_mbm.py --summary mbm_panda.jsonl
    python benchmarks/bench_mbm.py --arm panda --problems 10 --cameras 2 --out mbm_panda_cameras.jsonl
    python benchmarks/bench_mbm.py --planners policy,hybrid,ompl:RRTConnect --checkpoint bc.pt --out mbm_policy.jsonl

``policy@N`` (and ``hybrid@N``) is the learned planner with N draws per escape step instead
of the arm's default (``--planners policy,policy@1`` compares the screened escape with the
plain one in one run).
"""

from __future__ import annotations

import argparse
import gc
import json
import time
from pathlib import Path
from typing import Any

import numpy as np


def run(args: argparse.Namespace) -> None:
    from pointplan.evaluation import check_path
    from pointplan.planners.base import path_length
    from pointplan.scenes.mbm import SCENARIOS, load_problem, make_arm, problem_count

    robot = make_arm(args.arm)
    camera = None
    if args.cameras:
        from pointplan.scenes.cameras import CameraModel, camera_ring, seen_by_cameras
        from pointplan.scenes.scene import Problem

        w, h = (int(x) for x in args.camera_size.lower().split("x"))
        camera = CameraModel(w, h, args.focal)
    names = args.planners.split(",")
    planners = {n: _planner(n, robot, args) for n in names}
    scenarios = SCENARIOS if args.scenarios == "all" else tuple(args.scenarios.split(","))
    out = Path(args.out)
    done = set()
    if out.exists():  # resume: skip the problems already measured
        done = {json.loads(line)["tag"] for line in out.read_text().splitlines() if line.strip()}
    k = 0
    with out.open("a") as f:
        for scenario in scenarios:
            count = min(problem_count(args.arm, scenario), args.problems or 10**9)
            for i in range(1, count + 1):
                p = load_problem(args.arm, scenario, i)
                if p.tag in done:
                    continue
                row: dict[str, Any] = {"tag": p.tag, "scenario": scenario}
                row["valid"] = not bool(robot.collides(p.scene.world, np.stack([p.start, p.goal])).any())
                seen = p
                if camera is not None and row["valid"]:
                    t = time.perf_counter()
                    scene = seen_by_cameras(p.scene, camera_ring(p.scene, args.cameras, args.distance), camera)
                    seen = Problem(scene, p.start, p.goal, tag=p.tag)
                    cloud = scene.obstacles[0]
                    row["cameras"] = {
                        "n": args.cameras,
                        "size": args.camera_size,
                        "focal": args.focal,
                        "distance": args.distance,
                        "points": len(cloud.points),
                        "point_radius": cloud.point_radius(),
                        "render_s": time.perf_counter() - t,
                    }
                    row["valid_cloud"] = not bool(robot.collides(scene.world, np.stack([p.start, p.goal])).any())
                order = names[k % len(names) :] + names[: k % len(names)]
                k += 1
                for name in order if row["valid"] and row.get("valid_cloud", True) else []:
                    gc.collect()
                    t = time.perf_counter()
                    res = planners[name].plan(seen)
                    dt = time.perf_counter() - t
                    ok = bool(res.success) and bool(check_path(robot, p, res.path, tolerance=1e-6))
                    row[name] = {
                        "claimed": bool(res.success),
                        "ok": ok,
                        "time_s": dt,
                        "checks": int(res.collision_checks),
                        "nodes": int(res.nodes),
                        "length": path_length(robot, res.path) if ok else None,
                    }
                    if "policy_steps" in res.info:  # the hybrid: how far the policy went alone
                        row[name]["policy_steps"] = int(res.info["policy_steps"])
                        row[name]["repaired"] = bool(res.info["repaired"])
                f.write(json.dumps(row) + "\n")
                f.flush()
                print(p.tag, {n: (row[n]["ok"], round(row[n]["time_s"], 3)) for n in names if n in row}, flush=True)


def _planner(name: str, robot: Any, args: argparse.Namespace) -> Any:
    """A planner by name; the learned ones (``policy``, ``hybrid``, ``hybrid-ompl``) take
    ``--checkpoint``, and the policy alone has no time limit (its horizon ends it).
    ``policy@N``, ``hybrid@N``: with N draws per escape step instead of the arm's default."""
    from pointplan.planners import make_planner
    from pointplan.planners.rollout import RolloutOptions

    base, _, tries = name.partition("@")
    kw: dict[str, Any] = {}
    if tries:
        if not (base == "policy" or base.startswith("hybrid")) or not tries.isdigit() or int(tries) < 1:
            raise SystemExit(f"{name!r}: only the policy and the hybrids take @N (N draws per escape step, N >= 1)")
        kw["escape"] = RolloutOptions().escape_for(robot, int(tries))
    if base == "policy":
        return make_planner(base, robot, checkpoint=args.checkpoint, **kw)
    if base.startswith("hybrid"):
        return make_planner(base, robot, checkpoint=args.checkpoint, time_limit=args.time_limit, **kw)
    return make_planner(name, robot, time_limit=args.time_limit)


def summary(path: Path) -> None:
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    names = sorted({k for r in rows for k, v in r.items() if isinstance(v, dict) and k != "cameras"})
    by: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        by.setdefault(r["scenario"], []).append(r)
    by["all"] = rows
    print("| scenario | problems (valid) | " + " | ".join(f"{n}: solved, median / mean s" for n in names) + " |")
    print("|---|---|" + "---|" * len(names))
    for sc, rs in by.items():
        valid = [r for r in rs if r["valid"] and r.get("valid_cloud", True)]
        cells = []
        for n in names:
            got = [r[n] for r in valid if n in r]
            t = np.array([g["time_s"] for g in got])
            solved = sum(g["ok"] for g in got)
            cells.append(f"{solved}/{len(got)}, {np.median(t):.3f} / {t.mean():.3f}" if len(got) else "-")
        print(f"| {sc} | {len(rs)} ({len(valid)}) | " + " | ".join(cells) + " |")
    for n in names:
        if "ompl:RRTConnect" in names and n != "ompl:RRTConnect":
            both = [r for r in rows if r["valid"] and n in r and "ompl:RRTConnect" in r]
            ratio = np.median([r[n]["time_s"] for r in both]) / np.median(
                [r["ompl:RRTConnect"]["time_s"] for r in both]
            )
            print(f"{n}: median time / OMPL's median time = {ratio:.2f}")
    for n in names:
        hyb = [r[n] for r in rows if r["valid"] and n in r and "policy_steps" in r[n]]
        if hyb:
            alone = [h for h in hyb if h["ok"] and not h["repaired"]]
            print(
                f"{n}: solved by the policy alone {len(alone)}/{len(hyb)}; fallback used on {sum(h['repaired'] for h in hyb)}; "
                f"policy steps median {np.median([h['policy_steps'] for h in hyb]):.0f}, nodes median {np.median([h['nodes'] for h in hyb]):.0f}"
            )
    bad = [r["tag"] for r in rows if not r["valid"]]
    print(f"left out (start or goal collides for the sphere model): {len(bad)} {' '.join(bad)}")
    blind = [r["tag"] for r in rows if r["valid"] and not r.get("valid_cloud", True)]
    if any("cameras" in r for r in rows):
        cams = [r["cameras"] for r in rows if "cameras" in r]
        print(
            f"cameras: {cams[0]['n']} of {cams[0]['size']} pixels; cloud points median {np.median([c['points'] for c in cams]):.0f}, "
            f"point radius median {1000 * np.median([c['point_radius'] for c in cams]):.1f} mm; "
            f"left out (start or goal collides with the cloud): {len(blind)} {' '.join(blind)}"
        )
        for n in names:
            wrong = [r["tag"] for r in rows if n in r and r[n]["claimed"] and not r[n]["ok"]]
            print(f"{n}: paths planned on the cloud that touch the true obstacles: {len(wrong)} {' '.join(wrong)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--arm", default="panda", help="panda or ur5 (default: %(default)s)")
    ap.add_argument("--scenarios", default="all", help="comma-separated, or all (default)")
    ap.add_argument("--problems", type=int, default=0, help="first N problems per scenario (default: all)")
    ap.add_argument("--planners", default="birrt,ompl:RRTConnect", help="(default: %(default)s)")
    ap.add_argument("--time-limit", type=float, default=30.0, help="seconds per query (default: %(default)s)")
    ap.add_argument(
        "--checkpoint", help="the arm policy of the planners policy, hybrid and hybrid-ompl (a bc.pt or ppo.pt)"
    )
    ap.add_argument("--out", default="mbm.jsonl", help="one JSON line per problem, appended (default: %(default)s)")
    ap.add_argument("--summary", help="print the summary of an existing output file and stop")
    ap.add_argument(
        "--cameras", type=int, default=0, help="plan on what N simulated depth cameras see (default: 0, off)"
    )
    ap.add_argument("--camera-size", default="640x480", help="the cameras' image, WxH pixels (default: %(default)s)")
    ap.add_argument(
        "--focal", type=float, default=550.0, help="the cameras' focal length, pixels (default: %(default)s)"
    )
    ap.add_argument(
        "--distance",
        type=float,
        default=1.5,
        help="the cameras' distance to the obstacles' centre, m (default: %(default)s)",
    )
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
