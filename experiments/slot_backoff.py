"""Backing off where every escape draw is refused, in Slot: the oriented S-shape's shipped
`local` policy through the planner (its default escape and motion check, the numpy
one-robot rollout), with one change: at an escape step whose best draw does not move the
robot (every draw refused: the body wedged 0.1-0.5 mm from a wall), the action is instead
the one that heads back to the latest pose of its path more than ``--back`` away (a
geodesic move, checked like any other). ``--back 0``: the planner as it is.
``--problems frozen``: the 24 validation problems (of twice 500) that end frozen in an
opening; ``all``: the 500 of ``--seed``.

    python experiments/slot_backoff.py --problems frozen --back 0 0.03 0.1
    python experiments/slot_backoff.py --problems all --seed 0 --back 0 0.03
"""

from __future__ import annotations

import argparse
import time

import numpy as np

#: the validation problems whose rollouts end frozen in an opening (experiments/slot_failure_ends.py)
FROZEN = {
    0: [32, 119, 181, 182, 188, 222, 306, 343, 387, 489, 428],
    1: [32, 181, 182, 188, 216, 222, 343, 387, 407, 422, 487, 47, 325],
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--problems", choices=["frozen", "all"], default="frozen")
    ap.add_argument("--seed", type=int, default=0, help="with --problems all: which draw of 500 validation problems")
    ap.add_argument("--back", type=float, nargs="+", default=[0.0, 0.03])
    args = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    from pointplan.evaluation.evaluate import evaluate
    from pointplan.models.policy import Policy
    from pointplan.planners import rollout as R
    from pointplan.planners.policy import PolicyPlanner
    from pointplan.scenes.scenarios import make_scenario

    policy = Policy.from_checkpoint("src/pointplan/data/slot_sshape_oriented_local_policy.pt")
    sc = make_scenario("slot", robot=policy.robot.name)
    robot = sc.robot
    if args.problems == "frozen":
        problems = [sc.problems("val", 500, seed=s)[i] for s, ii in FROZEN.items() for i in ii]
    else:
        problems = sc.problems("val", 500, seed=args.seed)
    setting = {"back": 0.0, "backoffs": 0}
    actions, furthest = R._OneRobot.actions, R._OneRobot._furthest

    def remember(self, st, t, escaping, target):  # type: ignore[no-untyped-def]
        self._path_so_far = st.paths[: t + 1, 0]
        return actions(self, st, t, escaping, target)

    def back_off(self, obs, q, target):  # type: ignore[no-untyped-def]
        best = furthest(self, obs, q, target)
        if setting["back"] <= 0:
            return best
        q1, _, _ = self._free_move(q[None], np.asarray(best, np.float32)[None])
        if float(robot.distance(q1, q[None])[0]) >= R._MOVED:
            return best
        past = self._path_so_far
        away = np.flatnonzero(robot.distance(past, np.broadcast_to(q, past.shape)) > setting["back"])
        if not len(away):
            return best
        a = robot.log(q[None], past[away[-1]][None])[0] / self.scale
        setting["backoffs"] += 1
        return (a / max(1.0, float(np.max(np.abs(a))))).astype(np.float32)

    R._OneRobot.actions, R._OneRobot._furthest = remember, back_off  # type: ignore[method-assign]
    for back in args.back:
        setting.update(back=back, backoffs=0)
        t0 = time.perf_counter()
        report = evaluate(PolicyPlanner(policy, robot=robot, compiled=False), problems, robot, progress=False)
        solved = sum(bool(r.success) for r in report.records)
        print(
            f"back {back}: {solved} of {len(problems)} ({args.problems}"
            + (f", seed {args.seed}" if args.problems == "all" else "")
            + f"), {setting['backoffs']} back-offs, {report.metrics()['planner_claims_disagree']} claims disagree, "
            f"{time.perf_counter() - t0:.0f} s",
            flush=True,
        )


if __name__ == "__main__":
    main()
