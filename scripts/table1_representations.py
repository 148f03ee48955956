"""The paper's Table 1 on 2D-Narrow: obstacle representations x learning method.

Five (observation, encoder) pairs, each learnt by behavioural cloning (BC) and by SAC + HER
from scratch (RL), under one budget per method that this machine can afford (the paper's:
BC on 1e6 expert steps for 200 epochs, RL for 1e6 environment steps). Every cell is
selected on the validation split (200 problems) and evaluated once on the 400 test
problems with ``pointplan eval``. One JSON per cell goes to ``--out``; ``--plot`` draws the
validation curves of all cells that are there, each with the paper's test result as a marker
on the right edge.

    python scripts/table1_representations.py --method bc                 # the five BC cells
    python scripts/table1_representations.py --method rl --cells surface-normals:pointnet
    python scripts/table1_representations.py --plot docs/img/table1_curves.png
    python scripts/table1_representations.py --table

Each cell writes ``OUT/CELL_METHOD.json``: the configuration, the validation curve, the
selected checkpoint's test metrics and the wall time. Run folders go to ``--runs``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch

CELLS = {
    "image:cnn": ("image", "cnn"),
    "interior:mlp": ("interior", "mlp"),
    "interior:pointnet": ("interior", "pointnet"),
    "surface:pointnet": ("surface", "pointnet"),
    "surface-normals:pointnet": ("surface-normals", "pointnet"),
}
#: the paper's Table 1 (success %, BC and RL)
PAPER = {
    "image:cnn": (64.5, 44.5),
    "interior:mlp": (42.0, 29.0),
    "interior:pointnet": (76.0, 83.0),
    "surface:pointnet": (85.0, 93.8),
    "surface-normals:pointnet": (86.5, 99.5),
}


def net_config(encoder: str, width: int) -> object:
    from pointplan.models.actor_critic import NetConfig
    from pointplan.models.encoders import EncoderConfig

    return NetConfig(
        EncoderConfig(encoder, width, 3), head_width=width, head_layers=3, critic_action="pooled", shared_encoder=True
    )


def validate(actor: torch.nn.Module, robot: object, env: object, problems: list, horizon: int) -> float:
    from pointplan.models.inputs import goal_input, obs_input
    from pointplan.planners.policy import rollout_batch

    device = next(actor.parameters()).device

    def act(o: np.ndarray, q: np.ndarray, g: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            obs = torch.as_tensor(obs_input(robot, o), dtype=torch.float32, device=device)  # type: ignore[arg-type]
            goal = torch.as_tensor(goal_input(robot, q, g), dtype=torch.float32, device=device)  # type: ignore[arg-type]
            return actor.act(obs, goal).cpu().numpy()  # type: ignore[operator]

    actor.eval()
    res = rollout_batch(act, robot, env, problems, horizon, seed=0)  # type: ignore[arg-type]
    actor.train()
    return float(np.mean([r.success for r in res]))


def test_eval(checkpoint: Path, episodes: int, json_path: Path, greedy: bool = True) -> dict:
    """The selected checkpoint on the test problems, once, through the CLI: the policy
    planner as it ships (``greedy``: it stops where the straight edge to the goal is
    certified free) or the plain rollout to the goal tolerance (the paper's protocol)."""
    cmd = ["pointplan", "eval", "--env", "narrow2d", "--planner", "policy", "--checkpoint", str(checkpoint)]
    cmd += ["--episodes", str(episodes), "--seed", "0", "--json", str(json_path)]
    cmd += [] if greedy else ["--no-greedy-goal"]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    data = json.loads(json_path.read_text())
    return data[0] if isinstance(data, list) else data


def patience_spent(curve: list[dict], patience: int) -> bool:
    """Whether the last ``patience`` epochs of a BC cell's validation ``curve`` brought no
    new best (the first epoch reaching the best counts); never with ``patience`` 0."""
    if patience <= 0 or not curve:
        return False
    best = max(c["val_success"] for c in curve)
    first = next(c["epochs"] for c in curve if c["val_success"] == best)
    return int(curve[-1]["epochs"]) - int(first) >= patience


def run_bc(cell: str, args: argparse.Namespace) -> dict:
    from pointplan.envs.core import EnvConfig
    from pointplan.learning.bc import (
        BCConfig,
        fit_actor,
        generate_demos,
        load_demos,
        observation_shape,
        observations_vary,
        observe_demos,
        policy_payload,
        save_demos,
        stored_obs_tensor,
    )
    from pointplan.models.actor_critic import Actor
    from pointplan.models.checkpoint import save_checkpoint, to_dict
    from pointplan.scenes.scenarios import make_scenario

    observation, encoder = CELLS[cell]
    scenario = make_scenario("narrow2d")
    robot = scenario.robot
    demos_file = Path(args.runs) / f"demos_narrow2d_{args.bc_problems}.npz"
    if demos_file.exists():
        demos = load_demos(demos_file, scenario)
    else:
        demos = generate_demos(scenario, args.bc_problems, seed=0, workers=args.workers)
        save_demos(demos_file, scenario, demos, "train", 0)
    cfg = BCConfig(
        observation=observation,
        n_points=args.points,
        n_problems=args.bc_problems,
        epochs=args.bc_epochs,
        net=net_config(encoder, args.width),  # type: ignore[arg-type]
    )
    env = EnvConfig(observation=observation, n_points=args.points)
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    shape = observation_shape(robot, env)
    actor = Actor(shape, robot.twist_dim, robot.twist_dim, cfg.net).to(args.device)
    opt = torch.optim.Adam(actor.parameters(), lr=cfg.lr)
    val = scenario.problems("val", args.val_episodes, seed=0)
    run_dir = Path(args.runs) / f"{cell.replace(':', '_')}_bc"
    run_dir.mkdir(parents=True, exist_ok=True)
    curve: list[dict] = []
    best, before, start = -1.0, 0.0, args.bc_eval_every
    state_file = run_dir / "state.pt"
    if state_file.exists() and not args.redo:  # a run stopped between two validations: resume
        state = torch.load(state_file, map_location="cpu", weights_only=True)
        if state["epochs_total"] == args.bc_epochs and state["eval_every"] == args.bc_eval_every:
            actor.load_state_dict(state["actor"])
            opt.load_state_dict(state["opt"])
            rng.bit_generator.state = state["rng"]
            torch.set_rng_state(state["torch_rng"])
            curve, best, before = list(state["curve"]), float(state["best"]), float(state["wall_time_s"])
            start = int(state["done"]) + args.bc_eval_every
            print(f"{cell} bc: resuming after {state['done']} epochs ({state_file})", file=sys.stderr)
    t0 = time.perf_counter() - before
    # observations that do not vary (the image) are computed once, not at every epoch:
    # the same values, and the same random stream (observing them draws nothing)
    fixed = None
    for done in range(start, args.bc_epochs + 1, args.bc_eval_every):
        if patience_spent(curve, args.bc_patience):
            print(f"{cell} bc: no better validation in {args.bc_patience} epochs, stopped", file=sys.stderr)
            break
        try:
            if fixed is None and not observations_vary(robot, env):
                fixed = stored_obs_tensor(robot, observe_demos(demos, robot, env, rng), args.device)
            fit_actor(
                actor,
                opt,
                demos,
                robot,
                env,
                args.bc_eval_every,
                cfg.batch_size,
                rng,
                cfg.refresh_every,
                progress=False,
                stored=fixed,
            )
            success = validate(actor, robot, env, val, scenario.horizon)
        except KeyboardInterrupt:  # Ctrl-C: the state of the last validation is what is kept
            kept = curve[-1]["epochs"] if curve else 0
            print(
                f"{cell} bc: interrupted; {state_file} keeps {kept} epochs, the same command continues", file=sys.stderr
            )
            return {"curve": curve, "interrupted": True}
        curve.append({"epochs": done, "val_success": success, "wall_time_s": time.perf_counter() - t0})
        print(f"{cell} bc: {done} epochs, val {success:.3f}", file=sys.stderr, flush=True)
        payload = policy_payload(cfg, robot.name, shape, actor, scenario.horizon)
        if success > best:
            best = success
            save_checkpoint(run_dir / "best.pt", {**payload, "bc_config": to_dict(cfg), "demo_steps": len(demos)})
        state = {
            "actor": actor.state_dict(),
            "opt": opt.state_dict(),
            "rng": rng.bit_generator.state,
            "torch_rng": torch.get_rng_state(),
            "curve": curve,
            "best": best,
            "done": done,
            "epochs_total": args.bc_epochs,
            "eval_every": args.bc_eval_every,
            "wall_time_s": time.perf_counter() - t0,
        }
        torch.save(state, state_file.with_suffix(".tmp"))
        state_file.with_suffix(".tmp").replace(state_file)
    test = test_eval(run_dir / "best.pt", args.test_episodes, run_dir / "test.json")
    rollout = test_eval(run_dir / "best.pt", args.test_episodes, run_dir / "test_rollout.json", greedy=False)
    return {
        "demo_problems": len(demos.problems),
        "demo_steps": len(demos),
        "curve": curve,
        "best_val": best,
        "test": test,
        "test_rollout": rollout,
    }


def run_rl(cell: str, args: argparse.Namespace) -> dict:
    from pointplan.learning.sac import SACConfig
    from pointplan.learning.train import TrainConfig, train

    observation, encoder = CELLS[cell]
    cfg = TrainConfig(
        env="narrow2d",
        observation=observation,
        n_points=args.points,
        total_steps=args.rl_steps,
        updates_per_step=args.rl_updates_per_step,
        eval_every=args.rl_eval_every,
        eval_episodes=args.val_episodes,
        net=net_config(encoder, args.width),  # type: ignore[arg-type]
        sac=SACConfig(),
        device=args.device,
    )
    run_dir = Path(args.runs) / f"{cell.replace(':', '_')}_rl"
    last = run_dir / "last.pt"
    res = train(cfg, run_dir, progress=not args.quiet, resume=last if last.exists() else None)
    curve = [
        {"env_steps": h["env_steps"], "val_success": h["val_success"], "wall_time_s": h["wall_time_s"]}
        for h in res.history
    ]
    old = Path(args.out) / f"{cell.replace(':', '_')}_rl.json"
    if old.exists() and last.exists():  # a resumed run: keep the curve of its earlier part
        before = [
            c
            for c in json.loads(old.read_text()).get("curve", [])
            if c["env_steps"] < (curve[0]["env_steps"] if curve else 1e18)
        ]
        curve = before + curve
    if res.interrupted:
        return {"curve": curve, "interrupted": True}
    test = test_eval(run_dir / "best.pt", args.test_episodes, run_dir / "test.json")
    rollout = test_eval(run_dir / "best.pt", args.test_episodes, run_dir / "test_rollout.json", greedy=False)
    # the curve's wall times add up over resumed sessions; the record's own ``wall_time_s`` is this process's
    return {
        "curve": curve,
        "best_val": res.best_success,
        "test": test,
        "test_rollout": rollout,
        "train_wall_time_s": curve[-1]["wall_time_s"] if curve else None,
    }


def plot(out_dir: Path, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, method, xkey, xlabel in (
        (axes[0], "bc", "epochs", "epochs of behavioural cloning"),
        (axes[1], "rl", "env_steps", "environment steps (SAC + HER)"),
    ):
        edge = matplotlib.transforms.blended_transform_factory(ax.transAxes, ax.transData)
        for k, cell in enumerate(CELLS):  # one colour per cell in both panels
            f = out_dir / f"{cell.replace(':', '_')}_{method}.json"
            if not f.exists():
                continue
            curve = json.loads(f.read_text())["curve"]
            if not curve:
                continue
            ax.plot(
                [c[xkey] for c in curve],
                [100 * c["val_success"] for c in curve],
                marker="o",
                ms=3,
                color=f"C{k}",
                label=cell.replace(":", " / "),
            )
            # the paper's test result for the cell, a marker on the right edge
            paper = PAPER[cell][0 if method == "bc" else 1]
            ax.plot([1.0], [paper], marker="<", ms=8, color=f"C{k}", clip_on=False, transform=edge)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("validation success (%)")
        ax.set_ylim(0, 100)
        ax.grid(alpha=0.3)
        ax.set_title({"bc": "behavioural cloning", "rl": "reinforcement learning"}[method])
        if not ax.lines:
            ax.text(0.5, 0.5, "not run yet", ha="center", va="center", transform=ax.transAxes, color="0.5")
    # one legend for both panels, below them, where it hides no curve (a cell has one colour)
    legend: dict[str, object] = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            legend.setdefault(label, handle)
    if legend:
        (paper_marker,) = axes[1].plot([], [], marker="<", ms=8, ls="none", color="0.4")
        legend["the paper's test result"] = paper_marker
        fig.legend(list(legend.values()), list(legend), loc="lower center", ncol=len(legend), fontsize=8)
    fig.suptitle("2D-Narrow: obstacle representation x learning method (200 validation problems)")
    fig.tight_layout(rect=(0, 0.06 if legend else 0, 1, 1))
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


def table(out_dir: Path) -> None:
    print(
        "| representation | encoder | paper BC | ours BC (rollout) | ours BC (planner) | paper RL | ours RL (rollout) | ours RL (planner) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for cell, (p_bc, p_rl) in PAPER.items():
        obs, enc = CELLS[cell]
        ours = []
        for method in ("bc", "rl"):
            f = out_dir / f"{cell.replace(':', '_')}_{method}.json"
            data = json.loads(f.read_text()) if f.exists() else {}
            for key in ("test_rollout", "test"):
                test = data.get(key)
                ours.append(f"{100 * test['success_rate']:.1f}%" if test else "-")
        print(f"| {obs} | {enc} | {p_bc}% | **{ours[0]}** | {ours[1]} | {p_rl}% | **{ours[2]}** | {ours[3]} |")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--method", choices=["bc", "rl"])
    ap.add_argument("--cells", nargs="*", default=list(CELLS), choices=list(CELLS))
    ap.add_argument("--points", type=int, default=128, help="points per observation (the paper: 128)")
    ap.add_argument("--width", type=int, default=64, help="layer width of encoders and heads")
    ap.add_argument(
        "--bc-problems", type=int, default=4000, help="Bi-RRT demonstration problems (shared by the BC cells)"
    )
    ap.add_argument("--bc-epochs", type=int, default=30)
    ap.add_argument("--bc-eval-every", type=int, default=5, help="epochs between validations")
    ap.add_argument(
        "--bc-patience",
        type=int,
        default=0,
        help="stop a BC cell after this many epochs without a better validation (0: run all --bc-epochs)",
    )
    ap.add_argument("--rl-steps", type=int, default=300_000, help="environment steps per RL cell")
    ap.add_argument("--rl-updates-per-step", type=float, default=0.25)
    ap.add_argument("--rl-eval-every", type=int, default=20_000)
    ap.add_argument("--val-episodes", type=int, default=200)
    ap.add_argument("--test-episodes", type=int, default=400)
    ap.add_argument("--workers", type=int, default=1, help="processes planning the demonstrations")
    ap.add_argument("--out", default="docs/data/table1")
    ap.add_argument("--runs", default="runs/table1")
    ap.add_argument("--plot", help="draw the validation curves of the cells in --out to this file")
    ap.add_argument("--table", action="store_true", help="print the Markdown table of the cells in --out")
    ap.add_argument("--redo", action="store_true", help="run cells whose result is in --out already")
    ap.add_argument("--quiet", action="store_true")
    ap.add_argument("--threads", type=int, default=1, help="PyTorch threads (1 when another job shares the cores)")
    ap.add_argument(
        "--device",
        default="cpu",
        help="where the networks train: cpu or cuda; the same run, resumable on either (default: %(default)s)",
    )
    args = ap.parse_args()
    out = Path(args.out)
    if args.method:
        torch.set_num_threads(max(1, args.threads))
        out.mkdir(parents=True, exist_ok=True)
        for cell in args.cells:
            done = out / f"{cell.replace(':', '_')}_{args.method}.json"
            if not args.redo and done.exists() and "test" in json.loads(done.read_text()):
                record = json.loads(done.read_text())
                best = Path(args.runs) / f"{cell.replace(':', '_')}_{args.method}" / "best.pt"
                if "test_rollout" not in record and best.exists():  # a cell run before the paper's protocol was added
                    record["test_rollout"] = test_eval(
                        best, args.test_episodes, best.parent / "test_rollout.json", greedy=False
                    )
                    done.write_text(json.dumps(record, indent=1))
                    print(
                        f"{cell} {args.method}: plain rollout on the test problems {record['test_rollout']['success_rate']:.3f}",
                        file=sys.stderr,
                    )
                print(f"{cell} {args.method}: done already ({done}; --redo to run it again)", file=sys.stderr)
                continue
            t0 = time.perf_counter()
            result = run_bc(cell, args) if args.method == "bc" else run_rl(cell, args)
            budget = (
                {"demo_problems": args.bc_problems, "epochs": args.bc_epochs, "patience": args.bc_patience}
                if args.method == "bc"
                else {"env_steps": args.rl_steps, "updates_per_step": args.rl_updates_per_step}
            )
            record = {
                "cell": cell,
                "method": args.method,
                "points": args.points,
                "width": args.width,
                **budget,
                **result,
                "wall_time_s": time.perf_counter() - t0,
            }
            if result.get("curve") or not result.get("interrupted"):  # nothing to keep before a first validation
                (out / f"{cell.replace(':', '_')}_{args.method}.json").write_text(json.dumps(record, indent=1))
            if result.get("interrupted"):
                print(f"{cell} {args.method}: interrupted", file=sys.stderr)
                break
            test = result.get("test")
            print(
                f"{cell} {args.method}: test success {test['success_rate']:.3f}"
                if test
                else f"{cell} {args.method}: interrupted",
                file=sys.stderr,
            )
    if args.plot:
        plot(out, args.plot)
    if args.table:
        table(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
