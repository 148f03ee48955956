"""How a Slot policy is turned when it fails to reach the insertion pose: by about 90
degrees about the wall's normal (it took the opening's long side for its short one), or
otherwise.

Each rollout starts on a demonstration of the slot threading expert, ``--back`` steps
before its goal (the reverse curriculum's starts, ``pointplan ppo --start-demos``), and is
run by the planner (mean action, its greedy goal test). A rollout that is not solved is
taken at its state nearest (in position) to the template's insertion pose on that slot;
the world-frame turn from the insertion pose to it is sorted by its angle and by its axis
(within 30 degrees of the wall's normal, x, or not).

    python experiments/slot_turn_errors.py src/pointplan/data/slotmoving_sshape_local_policy.pt --demos runs/demos_slot_canonical.npz --back 32 40 48 56
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import torch


def classify(angle_deg: float, axis: np.ndarray) -> str:
    """``aligned`` (under 30 degrees), ``normal-90`` / ``normal-180`` (about 90 / 180 degrees
    about an axis within 30 degrees of x), else ``other``."""
    if angle_deg < 30:
        return "aligned"
    about_x = abs(float(axis[0])) >= np.cos(np.radians(30))
    if about_x and 60 <= angle_deg <= 120:
        return "normal-90"
    if about_x and angle_deg > 150:
        return "normal-180"
    return "other"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint")
    ap.add_argument("--demos", required=True)
    ap.add_argument("--env", default="slotmoving", choices=["slot", "slotmoving", "slotwide", "slotclassic"])
    ap.add_argument("--back", nargs="+", type=int, default=[32, 40, 48, 56])
    ap.add_argument("--paths", type=int, default=100, help="the last this many demonstrations of the file")
    ap.add_argument("--json")
    args = ap.parse_args()
    torch.set_num_threads(1)
    from scipy.spatial.transform import Rotation
    from tqdm import tqdm

    from pointplan.learning.bc import load_demos
    from pointplan.models.policy import Policy
    from pointplan.planners.policy import PolicyPlanner
    from pointplan.planners.slot_threading import SlotThreading
    from pointplan.scenes.scenarios import make_scenario
    from pointplan.scenes.scene import Problem

    policy = Policy.from_checkpoint(args.checkpoint)
    sc = make_scenario(args.env, robot="sshape")
    expert = SlotThreading.load(sc.robot)
    planner = PolicyPlanner(policy, robot=sc.robot, attempts=1, escape=0)
    demos = load_demos(args.demos, sc)
    by_index: dict[int, Problem] = {}
    for k, _ in demos.paths:
        by_index.setdefault(k, demos.problems[len(by_index)])
    paths = [(by_index[k], p) for k, p in demos.paths][-args.paths :]
    out: dict[str, dict[str, int]] = {}
    for back in args.back:
        counts = {"solved": 0, "aligned": 0, "normal-90": 0, "normal-180": 0, "other": 0}
        for problem, demo in tqdm(paths, desc=f"{back} steps back", unit="rollout"):
            start = demo[max(0, len(demo) - 1 - back)]
            p = Problem(problem.scene, start, problem.goal, problem.tag)
            r = planner.plan(p)
            if r.success:
                counts["solved"] += 1
                continue
            t1 = expert.place(problem.scene.__dict__["slot"])[1]
            path = np.asarray(r.path)
            q = path[int(np.linalg.norm(path[:, :3] - t1[:3], axis=1).argmin())]
            turn = Rotation.from_quat(q[3:]) * Rotation.from_quat(t1[3:]).inv()  # world frame
            rv = turn.as_rotvec()
            angle = float(np.degrees(np.linalg.norm(rv)))
            counts[classify(angle, rv / max(np.linalg.norm(rv), 1e-12))] += 1
        out[str(back)] = counts
        print(back, counts, flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"checkpoint": args.checkpoint, "demos": args.demos, "env": args.env, "paths": len(paths), "by_back": out}, f, indent=1)


if __name__ == "__main__":
    main()
