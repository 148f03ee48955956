"""The paper's Table 3 / Table 4 cells for a 3D robot: the shipped policies and Bi-RRT on
the test problems of every 3D scene, with the paper's success beside ours.

    python scripts/table_policy3d.py --robot sphere3d --episodes 400            # run and print
    python scripts/table_policy3d.py --robot sphere3d --table-only              # print from the JSONs

Each cell is written to ``docs/data/policy3d/{robot}_{scene}_{planner}.json`` (the metrics
of ``pointplan eval``); ``--table-only`` reads them back. Policies come from the package
(``--checkpoint-global`` / ``--checkpoint-local`` evaluate other files). With
``--attempts K`` the policy planners retry failed rollouts with sampled actions
(``pointplan eval --attempts``); their cells are named ``policy-local-xK`` and skip the
moving scene, where a rollout cannot start over. With ``--escape K`` a rollout takes K
steps of the robot's escape wherever it is stuck (``pointplan eval --escape``): sampled
actions for the S-shape (cells ``policy-local-escK``), steps toward a random subgoal for
the sphere (cells ``policy-local-subK``), in every scene. With ``--dodge N`` the
rollouts among moving obstacles replace an action that would meet them where their last
step's motion carries them by the nearest of standing still and N sampled ones that does
not (``pointplan eval --dodge``; cells ``...-dodgeN`` in 3D-Dynamic). A robot whose
policies check their moves with a finer sub-step than the environments' 0.01
(``SUBSTEP_DEFAULTS``: the S-shape told its orientation, in Slot) gets cells named
``...-checkS`` (S the sub-step); one whose escape backs off where no draw moves
(``Escape.backoff``) gets ``...bB`` after its draws and lookahead. Without these the
policies plan with the mean action throughout, whatever the planner's default. Other
planner names (``birrt``, ``hybrid``: the robot's default policy, then Bi-RRT, 10 s a
query) are built by ``make_planner`` with their defaults.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

from pointplan.envs.core import EnvConfig
from pointplan.evaluation import evaluate
from pointplan.planners import make_planner
from pointplan.planners.rollout import DODGE_DEFAULT, DODGE_OFF, RolloutOptions
from pointplan.scenes.scenarios import make_scenario

#: the paper's success (%): Table 3 (trained on 3D-Boxes) and Table 4 (3D-Qureshi)
PAPER = {
    "sphere3d": {
        "global": {"boxes3d": 95.8, "synthetic3d": 91.3, "ycb3d": 91.2, "dynamic3d": 94.7, "qureshi3d": 100.0},
        "local": {"boxes3d": 99.3, "synthetic3d": 87.0, "ycb3d": 87.7, "dynamic3d": 95.8},
    },
    "sshape": {
        "global": {"boxes3d": 89.0, "synthetic3d": 85.3, "ycb3d": 88.7, "dynamic3d": 86.0},
        # Slot (section 4.4): a `local` policy trained on Slot itself (--checkpoint-local)
        # slot: the gate fixed at the wall's centre, its width random (the paper's reading);
        # slotclassic (our diagnostic: the same with one goal) shows the same 97.7
        "local": {
            "boxes3d": 97.0,
            "synthetic3d": 87.3,
            "ycb3d": 96.0,
            "dynamic3d": 79.7,
            "slot": 97.7,
            "slotclassic": 97.7,
        },
    },
    # the S-shape told its orientation (not the paper's observation), in the paper's Slot:
    # beside the paper's Slot number, which its `local` policy reached
    "sshape-oriented": {"global": {"slot": 97.7}, "local": {"slot": 97.7}},
}
#: scenes run and tabled though the paper has no number for them: the moving-gate Slot
#: (a harder variant of our own)
NO_PAPER = {"sshape": {"local": {"slotmoving"}}}
SCENES = ["boxes3d", "synthetic3d", "ycb3d", "dynamic3d", "qureshi3d"]
#: the table's scenes: Slot's cells are run only when asked (--scenes slot ...), with a Slot policy
TABLE_SCENES = [*SCENES, "slot", "slotmoving", "slotclassic"]
OUT = Path("docs/data/policy3d")


def cell_path(robot: str, scene: str, planner: str) -> Path:
    return OUT / f"{robot}_{scene}_{planner}.json"


def run(args: argparse.Namespace) -> None:
    for scene in args.scenes:
        scenario = make_scenario(scene, robot=args.robot)
        problems = scenario.problems("test", args.episodes, seed=0)
        for planner_name in args.planners:
            if planner_name.startswith("policy-"):
                obs = planner_name.split("-", 1)[1]
                extra = NO_PAPER.get(args.robot, {}).get(obs, set())
                if scene not in PAPER[args.robot].get(obs, {}) and scene not in extra:
                    continue
                if args.attempts > 1 and scenario.scene("test", 0).dynamic:
                    continue
                esc = RolloutOptions(escape=args.escape).escape_for(scenario.robot, args.escape_tries)
                if args.escape_lookahead is not None:
                    esc = replace(esc, lookahead=args.escape_lookahead)
                if args.escape_backoff is not None:
                    esc = replace(esc, backoff=args.escape_backoff)
                moving = scenario.scene("test", 0).dynamic
                dodge = replace(DODGE_DEFAULT, draws=args.dodge) if args.dodge and moving else DODGE_OFF
                planner = make_planner(
                    "policy",
                    scenario.robot,
                    checkpoint=getattr(args, f"checkpoint_{obs}"),
                    observation=obs,
                    scene=scene,
                    attempts=args.attempts,
                    escape=esc,
                    dodge=dodge,
                )
                if args.escape > 0:
                    kind = "sub" if esc.subgoal else "esc"
                    tries = f"t{esc.tries}" if esc.tries > 1 else ""
                    tries += f"l{esc.lookahead}" if esc.lookahead and esc.tries > 1 else ""
                    tries += f"b{esc.backoff:g}" if esc.backoff and esc.tries > 1 else ""
                    planner_name = f"{planner_name}-{kind}{args.escape}{tries}"
                if dodge.on:
                    planner_name = f"{planner_name}-dodge{dodge.draws}"
                if planner.env.substep != EnvConfig().substep:  # the robot's finer motion check
                    planner_name = f"{planner_name}-check{planner.env.substep:g}"
                if args.attempts > 1:
                    planner_name = f"{planner_name}-x{args.attempts}"
            else:
                planner = make_planner(planner_name, scenario.robot, seed=0)
            report = evaluate(planner, problems, scenario.robot, progress=not args.quiet)
            m = report.metrics()
            cell_path(args.robot, scene, planner_name).parent.mkdir(parents=True, exist_ok=True)
            cell_path(args.robot, scene, planner_name).write_text(
                json.dumps({**m, "env": scene, "robot": args.robot, "planner": planner_name, "seed": 0}, indent=2)
                + "\n"
            )
            print(f"{scene} {planner_name}: {100 * m['success_rate']:.1f}%", flush=True)


def table(robot: str) -> str:
    lines = [
        "| planner | scene | paper success | success | steps / nodes (mean) | collision checks (mean) | path length (mean) | time per problem (mean / median) |",
        "|---|---|---|---|---|---|---|---|",
    ]

    def order(
        name: str,
    ) -> tuple[str, int, int, int, float, int, int, str]:  # policy-OBS[-escK[tN[lL][bB]]|-subK][-dodgeD][-xK][-checkS]
        parts = name.split("-")[2:]
        kind = next((p[3:] for p in parts if p.startswith(("esc", "sub"))), "0")
        kind, _, back = kind.partition("b")
        esc, _, tries = kind.partition("t")
        tries, _, ahead = tries.partition("l")
        dodge = next((int(p[5:]) for p in parts if p.startswith("dodge")), 0)
        att = next((int(p[1:]) for p in parts if p.startswith("x")), 1)
        return name.split("-")[1], int(esc), int(tries or 1), int(ahead or 0), float(back or 0), dodge, att, name

    base = ("policy-global", "policy-local")
    tried = sorted({p.stem.split("_", 2)[2] for p in OUT.glob(f"{robot}_*_policy-*.json")} - set(base), key=order)
    for planner in (*base, *tried, "hybrid", "birrt"):
        for scene in TABLE_SCENES:
            p = cell_path(robot, scene, planner)
            if not p.exists():
                continue
            d = json.loads(p.read_text())
            obs = planner.split("-")[1] if planner.startswith("policy-") else None
            paper = PAPER[robot][obs].get(scene) if obs else None
            lines.append(
                f"| {planner} | {scene} | {'-' if paper is None else f'{paper:.1f}%'} | {100 * d['success_rate']:.1f}% | {d['nodes_mean']:.1f} | "
                f"{d['collision_checks_mean']:,.0f} | {d['path_length_mean']:.3f} | {1000 * d['time_mean_s']:.1f} / {1000 * d['time_median_s']:.1f} ms |"
            )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", default="sphere3d", choices=["sphere3d", "sshape", "sshape-oriented"])
    ap.add_argument("--episodes", type=int, default=400)
    ap.add_argument(
        "--scenes",
        nargs="+",
        default=SCENES,
        help="default: all but slot, slotmoving and slotclassic, which take a policy of their own (slotmoving: the shipped one; slot and slotclassic: --checkpoint-local)",
    )
    ap.add_argument("--planners", nargs="+", default=["policy-global", "policy-local", "birrt"])
    ap.add_argument("--checkpoint-global", help="policy on global points (default: the shipped one)")
    ap.add_argument(
        "--checkpoint-local",
        help="policy on ray-cast points (default: the shipped one, the moving-gate Slot's own in slotmoving)",
    )
    ap.add_argument(
        "--attempts",
        type=int,
        default=1,
        help="policy planners: rollouts per problem, the first with the mean action, the rest sampled (default: 1)",
    )
    ap.add_argument(
        "--escape",
        type=int,
        default=0,
        help="policy planners: where the robot is stuck, this many steps of the robot's escape (cells named policy-OBS-escK, or -subK where it heads for a subgoal; default: 0, the mean action throughout)",
    )
    ap.add_argument(
        "--escape-tries",
        type=int,
        default=None,
        help="policy planners: draws per escape step, the furthest free motion taken (default: the robot's; cells named -escKtN where N > 1)",
    )
    ap.add_argument(
        "--escape-lookahead",
        type=int,
        default=None,
        help="policy planners: each escape draw judged by this many steps of the mean action from its end (default: the robot's; cells named -escKtNlL where L > 0)",
    )
    ap.add_argument(
        "--escape-backoff",
        type=float,
        default=None,
        help="policy planners: where no escape draw moves the robot, back off along its path to a pose more than this far away (default: the robot's; cells named -escKtN...bB where B > 0)",
    )
    ap.add_argument(
        "--dodge",
        type=int,
        default=0,
        help="policy planners in 3D-Dynamic: draws of the dodge among moving obstacles (cells named -dodgeN; default: 0, none)",
    )
    ap.add_argument("--table-only", action="store_true")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args()
    if not args.table_only:
        run(args)
    print(table(args.robot))


if __name__ == "__main__":
    main()
