"""Which of the screened escape's draws to take: the furthest free motion (the planner's
rule) against other rules, on Slot's thin openings (under 3 bar thicknesses) of the first
500 validation problems, the oriented S-shape's shipped `local` policy, one rollout each.

Rules (``--rules``): ``far`` the furthest free motion from where the robot is; ``goal`` the
draw whose free end is nearest the goal; ``x`` the most progress across the wall toward
the goal's side; ``value`` / ``value:L`` the draw whose end the PPO run's value network
rates highest (plus ``L`` times the normalised motion); ``mix`` / ``mixq`` half / a quarter
of the draws uniform in the action box instead of from the policy, then the furthest;
``lookgoal:D`` / ``lookfar:D`` the mean action followed for ``D`` steps from each draw's
free end (observed there, each step's motion free as far as it goes), then the draw whose
lookahead ends nearest the goal / furthest from where the robot is (an arrival wins);
``lookfarlow:D`` the same as ``lookfar:D`` with every second draw at a quarter of the noise.
The rules other than ``far`` replace the one-robot stepper's selection for this run only
(the compiled rollout is turned off so that every rule runs in the same Python loop):

    python experiments/escape_selection.py --tries 32 --rules far goal x value value:2 mix mixq
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tries", type=int, default=32)
    ap.add_argument("--rules", nargs="+", default=["far", "goal", "x"])
    ap.add_argument("--episodes", type=int, default=500, help="validation problems drawn (the thin ones are kept)")
    ap.add_argument(
        "--value", default="checkpoints/slot_oriented_local_ppo_last.pt", help="PPO state with the value network"
    )
    args = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    from pointplan.config import from_dict
    from pointplan.evaluation.evaluate import evaluate
    from pointplan.learning.ppo import ValueNetwork
    from pointplan.models.actor_critic import NetConfig
    from pointplan.models.inputs import goal_input, obs_input
    from pointplan.models.policy import Policy
    from pointplan.planners import rollout as R
    from pointplan.planners.policy import Escape, PolicyPlanner
    from pointplan.robots.sshape import BAR_THICKNESS
    from pointplan.scenes.scenarios import make_scenario

    policy = Policy.from_checkpoint("src/pointplan/data/slot_sshape_oriented_local_policy.pt")
    sc = make_scenario("slot", robot=policy.robot.name)
    robot = sc.robot
    problems = sc.problems("val", args.episodes, seed=0)
    thin = [p for p in problems if p.scene.__dict__["slot"]["width"] / BAR_THICKNESS < 3.0]
    value = None
    if any(r.startswith("value") for r in args.rules):
        ck = torch.load(args.value, map_location="cpu", weights_only=False)
        p0 = problems[0]
        gdim = goal_input(robot, p0.start[None], p0.goal[None]).shape[1]
        value = ValueNetwork(tuple(ck["obs_shape"]), gdim, from_dict(NetConfig, ck["net"]))
        value.load_state_dict(ck["ppo"]["value"])
        value.eval()
    rule, lam = "far", 0.0

    def select(self, obs, q, target):  # type: ignore[no-untyped-def]
        eng = self.engine
        cands = []
        for k in range(eng.escape.tries):
            uniform = (rule == "mix" and k % 2 == 1) or (rule == "mixq" and k % 4 == 3)
            if uniform:
                a = self.nrng.uniform(-1, 1, eng.action_dim).astype(np.float32)
            elif rule == "lookfarlow" and k % 2 == 1:
                a = eng._act(obs, q, target, 0.25 * self._noise(True))
            else:
                a = eng._act(obs, q, target, self._noise(True))
            q1, _, n = self._free_move(q[None], np.asarray(a, np.float32)[None])
            self.pending_checks += int(np.sum(n))
            cands.append((a, q1[0], float(np.asarray(robot.distance(q1, q[None]))[0])))
        d = np.array([c[2] for c in cands])
        if rule.startswith("look"):
            s = np.array([lookahead(self, c[1], target, int(lam), q) for c in cands])
            s = np.where(d < 1e-3, -np.inf, s)
            return cands[int(np.argmax(s))][0] if np.isfinite(s).any() else cands[int(np.argmax(d))][0]
        if rule in ("far", "mix", "mixq"):
            return cands[int(np.argmax(d))][0]
        if rule == "goal":
            s = -np.array([float(np.asarray(robot.distance(c[1][None], target[None]))[0]) for c in cands])
        elif rule == "x":
            s = np.array([(c[1][0] - q[0]) * np.sign(target[0] - q[0]) for c in cands])
        else:
            assert value is not None
            u = eng._uniforms(self.observer.draws_one())[: self.observer.draws_one()]
            o = np.stack([obs_input(robot, self.observer.observe_one(c[1], u=u)[None])[0] for c in cands])
            g = goal_input(robot, np.stack([c[1] for c in cands]), np.repeat(target[None], len(cands), 0))
            with torch.no_grad():
                v = value(torch.as_tensor(o, dtype=torch.float32), torch.as_tensor(g, dtype=torch.float32)).numpy()
            s = v + lam * d / max(d.max(), 1e-9)
        s = np.where(d < 1e-3, -np.inf, s)  # a draw that does not move is never taken
        return cands[int(np.argmax(s))][0] if np.isfinite(s).any() else cands[int(np.argmax(d))][0]

    def lookahead(self, q1, target, steps, q0):  # type: ignore[no-untyped-def]
        eng, qk = self.engine, q1.copy()
        for _ in range(steps):
            u = eng._uniforms(self.observer.draws_one())[: self.observer.draws_one()]
            a = eng._act(self.observer.observe_one(qk, u=u), qk, target, None)
            qn, _, n = self._free_move(qk[None], np.asarray(a, np.float32)[None])
            self.pending_checks += int(np.sum(n))
            qk = qn[0]
            if float(np.asarray(robot.distance(qk[None], target[None]))[0]) < 0.05:
                return np.inf
        if rule in ("lookfar", "lookfarlow"):
            return float(np.asarray(robot.distance(qk[None], q0[None]))[0])
        return -float(np.asarray(robot.distance(qk[None], target[None]))[0])

    R._OneRobot._furthest = select  # type: ignore[method-assign]
    for spec in args.rules:
        rule, _, l_text = spec.partition(":")
        lam = float(l_text) if l_text else 0.0
        planner = PolicyPlanner(
            policy, robot=robot, escape=Escape(steps=10, noise=2.0, still=0.01, tries=args.tries), compiled=False
        )
        t0 = time.perf_counter()
        report = evaluate(planner, thin, robot, progress=False)
        ok = sum(r.success for r in report.records)
        steps = np.mean([len(r.path) - 1 for r in report.records])
        print(
            f"{spec}, {args.tries} draws: {ok}/{len(thin)} thin openings solved, {steps:.1f} steps, {time.perf_counter() - t0:.0f} s",
            flush=True,
        )


if __name__ == "__main__":
    main()
