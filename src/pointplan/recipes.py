"""Recipes: the commands that rebuild each checkpoint shipped in ``pointplan/data``.

A :class:`Recipe` is the ordered list of commands (``pointplan bc``, ``train``, ``ppo``,
``mpnet-train``, ``lsample-train``, resumes with changed flags, and
``python scripts/slot_expert.py demos`` for Slot) that produced one shipped file, with the
flags the docs (``docs/results/``, ``docs/notebook/``, ``checkpoints/README.md``) and the
checkpoint's own saved configuration record. Where the docs leave a step open, the
recipe's description says so and which choice was taken.

Steps are written with two kinds of placeholder: ``{root}``, the folder the recipe's runs
go to, and ``{FULL|SMOKE}``, a budget (steps, epochs, problems, episodes) at full size
and in a smoke run. A step's ``smoke`` arguments are added in smoke runs only (a smaller
warm-up, fewer environments). A smoke run goes through every stage in seconds; it checks
that the chain runs, not what it learns.

    python -m pointplan.recipes --list
    python -m pointplan.recipes narrow2d_policy --dry-run
    python -m pointplan.recipes narrow2d_policy --smoke --root /tmp/smoke
    python -m pointplan.recipes narrow2d_policy --root runs/recipes/narrow2d_policy

At the end the recipe's final checkpoint is copied to ``ROOT/<shipped file name>``.
"""

from __future__ import annotations

import argparse
import re
import shlex
import shutil
import subprocess
import sys
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from argparse import _SubParsersAction

#: ``{FULL|SMOKE}``: a budget at full size and in a smoke run
_BUDGET = re.compile(r"\{([^{}|]*)\|([^{}|]*)\}")
#: the repository's folder (``scripts/`` lives there, not in the installed package)
REPO = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Step:
    """One command of a recipe: ``argv`` starts with ``pointplan`` or ``python``; ``smoke``
    arguments are appended in smoke runs only; ``note`` says what the step is for."""

    argv: tuple[str, ...]
    note: str = ""
    smoke: tuple[str, ...] = ()

    def render(self, root: str | Path, smoke: bool = False) -> list[str]:
        """The command line with the placeholders filled in (arguments that come out
        empty are dropped)."""
        out = []
        for arg in (*self.argv, *self.smoke) if smoke else self.argv:
            arg = _BUDGET.sub(lambda m: m.group(2 if smoke else 1), arg).replace("{root}", str(root))
            if arg:
                out.append(arg)
        return out


@dataclass(frozen=True)
class Recipe:
    """The commands that rebuild the shipped checkpoint ``shipped`` (a file name in
    ``pointplan/data``). ``product`` lists where the final checkpoint lands, relative to the
    run root, first choice first (a resumed run that never beats its best writes no
    ``best.pt`` of its own, so the run it resumed holds the best one). ``cost`` is the
    full-size training cost as the docs give it."""

    name: str
    shipped: str
    title: str
    description: str
    steps: tuple[Step, ...]
    product: tuple[str, ...]
    cost: str = ""


def _step(command: str, note: str = "", smoke: str = "") -> Step:
    """A :class:`Step` from a command line written with spaces between its arguments."""
    return Step(tuple(command.split()), note, tuple(smoke.split()))


# the roadmap expert's demonstrations of the S-shape in 3D-Boxes (both shipped S-shape policies)
_ROADMAP_DEMOS = _step(
    "python scripts/roadmap_demos.py --problems {2000|2} --nodes {2000|100} --k 15 --lookahead --save-every 200 "
    "--out {root}/demos_roadmap.npz",
    "the roadmap expert's demonstrations of 2,000 training problems of 3D-Boxes (the problems pointplan bc would plan)",
)

_SSHAPE_PPO = "--lr 1e-4 --reward-collision -0.1 --action-cost 0 --lam 0.98 --entropy-coef 0.01 --select escape"
_PPO_SMOKE = "--num-envs 4 --rollout-steps 16 --value-warmup 1 --eval-every 64 --eval-episodes 2"


def _sphere(observation: str, rounds: int, stop: int, resume_at: int | None) -> tuple[Step, ...]:
    """Cloning, DAgger and SAC + HER for the sphere in 3D-Boxes; with ``resume_at`` the SAC
    run stops there and is resumed (into the same folder) to ``stop``."""
    env = f"--env boxes3d --robot sphere3d --observation {observation}"
    demos = "--demos {root}/demos_boxes3d_sphere_4k.npz"
    first = resume_at or stop
    steps = [
        _step(
            f"pointplan bc {env} --problems {{4000|6}} --epochs {{8|1}} --workers {{2|1}} {demos} --run-dir {{root}}/bc_{observation}",
            "behavioural cloning on 4,000 Bi-RRT solutions of 3D-Boxes training problems (the demonstrations file holds configurations only: "
            "the same file serves both observations and the sphere's MPNet)",
            "--eval-episodes 2",
        ),
        _step(
            f"pointplan bc {env} {demos} --init-actor {{root}}/bc_{observation}/bc.pt --dagger-rounds {rounds} --rollouts {{400|4}} "
            f"--run-dir {{root}}/dagger_sphere_{observation}",
            f"DAgger from the clone: {rounds} round{'s' if rounds > 1 else ''} of 400 rollouts, Bi-RRT labels at 4 states of every failed one",
            "--eval-episodes 2",
        ),
        _step(
            f"pointplan train {env} --steps {{{first}|48}} --updates-per-step 0.25 --eval-every {{10000|16}} --eval-episodes {{200|2}} "
            f"--init-actor {{root}}/dagger_sphere_{observation}/best.pt --init-alpha 0.05 --actor-delay 2000 --run-dir {{root}}/sac_sphere_{observation}",
            f"SAC + HER from the DAgger actor, the temperature starting at 0.05 and 2,000 critic-only updates first (given --steps 2000000, "
            f"stopped at {first:,}" + (")" if resume_at else ": the shipped step)"),
            "--warmup-steps 16",
        ),
    ]
    if resume_at:
        steps.append(
            _step(
                f"pointplan train --resume {{root}}/sac_sphere_{observation}/last.pt --steps {{{stop}|80}}",
                f"resumed into the same folder; its best.pt at {stop:,} steps is the shipped file (the original went on past it without a better validation)",
            )
        )
    return tuple(steps)


RECIPES: dict[str, Recipe] = {
    r.name: r
    for r in (
        Recipe(
            name="narrow2d_policy",
            shipped="narrow2d_policy.pt",
            title="the disc's PointNet policy in 2D-Narrow: behavioural cloning, then SAC + HER resumed with new flags",
            description=(
                "Five stages (docs/results/2d-narrow.md, 'How the shipped policy was trained'): cloning 5,000 Bi-RRT solutions; SAC + HER from the clone; "
                "from 490,000 steps a smaller step size (1e-4), 0.5 updates per step and 400 validation problems; from 630,000 a running average of "
                "the actor (3e-5) with step size 5e-5 and 1,000 validation problems; from 930,000 retries of failed problems (share 0.5, 4,000 "
                "problems mined per validation) with step size 1e-4 and 2,000 validation problems. The shipped file is the best by validation at "
                "1,200,000 steps (its train_config: lr 1e-4, updates 0.5, policy_avg 3e-5, retry_failures 0.5, mine_episodes 4000, eval_episodes "
                "2000, init_alpha 0.05, actor_delay 2000). The first SAC run ran its 400,000 steps; the later ones were given a larger --steps (1,000,000, "
                "1,000,000, 900,000, 1,200,000, 1,600,000, 1,600,000) and stopped by hand; here --steps is where each was stopped, so every resume starts where the "
                "original one did (the replay buffer is not saved and refills at every resume, as it did). Left open by the docs: the run to "
                "630,000 was resumed once more from its own last.pt at a step they do not give (here it runs in one go), and the stops at 785,000 "
                "and 1,110,000 were by hand (here the run ends at the first multiple of its 16 environments past them). Of the two runs in "
                "parallel at stages 4 and 5, these are the ones the shipped file descends from (lr 5e-5; share 0.5 with lr 1e-4). The last run "
                "went on to 1,390,000 steps without a better validation (checkpoints/narrow2d_bcsac_retry_1390k_last.pt)."
            ),
            steps=(
                _step(
                    "pointplan bc --env narrow2d --problems {5000|8} --epochs {40|1} --run-dir {root}/bc",
                    "stage 1: behavioural cloning on Bi-RRT solutions of 5,000 training problems, 40 epochs",
                    "--eval-episodes 2",
                ),
                _step(
                    "pointplan train --env narrow2d --steps {400000|48} --num-envs 16 --updates-per-step 0.25 --eval-every {10000|16} "
                    "--eval-episodes {100|2} --init-actor {root}/bc/bc.pt --init-alpha 0.05 --actor-delay 2000 --run-dir {root}/bcsac",
                    "stage 2: SAC + HER from the clone, the temperature starting at 0.05 and 2,000 critic-only updates first",
                    "--warmup-steps 16",
                ),
                _step(
                    "pointplan train --resume {root}/bcsac/last.pt --steps {490000|64} --run-dir {root}/bcsac2",
                    "stage 2, resumed once (given --steps 1000000, stopped at 490,000)",
                ),
                _step(
                    "pointplan train --resume {root}/bcsac2/last.pt --steps {630000|80} --updates-per-step 0.5 --lr 1e-4 --eval-episodes {400|3} "
                    "--run-dir {root}/cont",
                    "stage 3: a smaller step size, more updates, 400 validation problems (given --steps 1000000; the 630,000-step state went on)",
                ),
                _step(
                    "pointplan train --resume {root}/cont/last.pt --steps {785000|96} --eval-episodes {1000|4} --policy-avg 3e-5 --lr 5e-5 "
                    "--updates-per-step 0.5 --run-dir {root}/avg2",
                    "stage 4: policy averaging, 1,000 validation problems (given --steps 900000, stopped at 785,000)",
                ),
                _step(
                    "pointplan train --resume {root}/avg2/last.pt --steps {930000|112} --run-dir {root}/avg3",
                    "stage 4, resumed alone (given --steps 1200000, stopped at 930,000)",
                ),
                _step(
                    "pointplan train --resume {root}/avg3/last.pt --steps {1110000|128} --retry-failures 0.5 --lr 1e-4 --mine-episodes {4000|4} "
                    "--eval-episodes {2000|5} --run-dir {root}/retryB",
                    "stage 5: retrying failed problems, 2,000 validation problems (given --steps 1600000, stopped at 1,110,000)",
                ),
                _step(
                    "pointplan train --resume {root}/retryB/last.pt --steps {1200000|144} --run-dir {root}/retryB2",
                    "stage 5, resumed alone (given --steps 1600000): its best.pt at 1,200,000 steps is the shipped file",
                ),
            ),
            product=("retryB2/best.pt", "retryB/best.pt"),
            cost="about 4.7 hours of wall time to 1,200,000 steps (284 minutes, cloning included; partly two runs sharing 2 cores)",
        ),
        Recipe(
            name="sphere3d_local_policy",
            shipped="sphere3d_local_policy.pt",
            title="the sphere's local policy (64 ray-cast points) in 3D-Boxes: cloning, DAgger, then SAC + HER",
            description=(
                "Cloning on 4,000 Bi-RRT solutions of 3D-Boxes (8 epochs), two DAgger rounds, then SAC + HER (docs/results/3d-sphere.md, 'How the "
                "policies were trained'; checkpoints/README.md). The shipped file is the SAC run's best by validation at 140,000 steps (92.5% of 200 "
                "validation problems). The DAgger command is not in the docs: its metrics (docs/data/sphere3d_training/local_bc_dagger_metrics.csv: "
                "612 and 608 labels, 4 per failed rollout of 400) match --dagger-rounds 2 with the defaults --rollouts 400 and --labels-per-failure 4, "
                "and the SAC run's init_actor (in the shipped file's train_config) is the DAgger run's best.pt, not bc.pt as the docs' command says. "
                "The SAC run was given --steps 2000000 and stopped at 140,000; continued from there (lr 1e-4 and 0.5 updates per step, from 170,000 "
                "also retries 0.25 and policy averaging 1e-4) it did not do better up to 210,000 steps (checkpoints/sphere3d_local_sac_210k_last.pt)."
            ),
            steps=_sphere("local", rounds=2, stop=140_000, resume_at=None),
            product=("sac_sphere_local/best.pt",),
            cost="about 84 minutes on 2 shared cores (17 for the demonstrations, cloning and DAgger; 140,000 SAC steps)",
        ),
        Recipe(
            name="sphere3d_global_policy",
            shipped="sphere3d_global_policy.pt",
            title="the sphere's global policy (256 surface points) in 3D-Boxes: cloning, DAgger, then SAC + HER",
            description=(
                "As the local one (docs/results/3d-sphere.md), with --observation global. The shipped file is the SAC run's best by validation at "
                "80,000 steps (93.5% of 200 validation problems). Its DAgger metrics (docs/data/sphere3d_training/global_bc_dagger_metrics.csv) record "
                "one round of 400 rollouts (640 labels), so --dagger-rounds 1 here; the docs' 'two DAgger rounds' are the local run's. The SAC run "
                "(given --steps 2000000) was stopped at 40,000 steps and resumed from that trainer state; it was stopped at 99,104 steps (92.0% at "
                "90,000: checkpoints/sphere3d_global_sac_99k_last.pt). The demonstrations file may have been the local run's; it is the same file "
                "(the same problems, seed and planner)."
            ),
            steps=_sphere("global", rounds=1, stop=80_000, resume_at=40_000),
            product=("sac_sphere_global/best.pt",),
            cost="about 2 h 20 min on shared cores (about 23 minutes of demonstrations, cloning and DAgger; 80,000 SAC steps in 7,076 s)",
        ),
        Recipe(
            name="sshape_local_policy",
            shipped="sshape_local_policy.pt",
            title="the S-shape's local policy in 3D-Boxes: the roadmap expert's demonstrations, cloned with its spread, then PPO",
            description=(
                "The roadmap expert (pointplan.learning.roadmap: one roadmap of 2,000 nodes per training workspace, one shortest-path "
                "search from the goal, so every state has one label) demonstrates 2,000 training problems: 1,046,922 steps, 72 minutes of "
                "one core. The clone with its spread (10 epochs, separate encoders: checkpoints/sshape_local_bc_roadmap.pt; it was run as "
                "4 epochs, then resumed to 10), then PPO with the settings of the earlier shipped policy (run 7). The shipped file is the "
                "PPO run's best by validation with the escape, at 665,600 steps (docs/notebook/sshape.md, 'Cloning the roadmap expert'); "
                "the run (ppo_config: --steps 20000000) went on to 1,111,040 steps without a better validation "
                "(checkpoints/sshape3d_local_roadmap_ppo_last.pt). Here --steps stops it at the shipped step."
            ),
            steps=(
                _ROADMAP_DEMOS,
                _step(
                    "pointplan bc --env boxes3d --robot sshape --observation local --encoder-sharing separate --epochs {10|1} "
                    "--spread-weight 1 --demos {root}/demos_roadmap.npz --run-dir {root}/bc_roadmap_local",
                    "the clone with its spread: 10 epochs on the million steps",
                    "--eval-episodes 2",
                ),
                _step(
                    f"pointplan ppo --init-actor {{root}}/bc_roadmap_local/bc.pt {_SSHAPE_PPO} --steps {{665600|128}} --threads 1 "
                    "--run-dir {root}/ppo_roadmap_local",
                    "PPO: -0.1 a step, +20 on arrival, no collision penalty or action cost, lambda 0.98, entropy 0.01, best.pt by the escape",
                    _PPO_SMOKE,
                ),
            ),
            product=("ppo_roadmap_local/best.pt",),
            cost="about 2.6 hours of one core: demonstrations 72 minutes, cloning 48, PPO 21 (validation included)",
        ),
        Recipe(
            name="sshape_global_policy",
            shipped="sshape_global_policy.pt",
            title="the S-shape's global policy in 3D-Boxes: the roadmap expert's demonstrations, cloned with its spread",
            description=(
                "The local policy's demonstrations (the roadmap expert: 1,046,922 steps of 2,000 training problems, 72 minutes of one "
                "core), the global clone with its spread (5 epochs, separate encoders, 256 surface points; 51 minutes of a shared core). "
                "Chosen on validation with the escape: 86.0% of 200 problems in scripts/attempts_success.py, against 83.5% for the policy it "
                "replaces (the Bi-RRT clone + PPO run 8, shipped from 2026-12-02 to 2026-12-05). PPO from it (run 25, the local "
                "policy's settings) fell to 84-85.5% in 153,600 steps and was stopped (checkpoints/sshape3d_global_roadmap_ppo_last.pt), "
                "so the clone itself ships (docs/notebook/sshape.md, 'A global clone of the roadmap expert')."
            ),
            steps=(
                _ROADMAP_DEMOS,
                _step(
                    "pointplan bc --env boxes3d --robot sshape --observation global --encoder-sharing separate --epochs {5|1} "
                    "--spread-weight 1 --demos {root}/demos_roadmap.npz --run-dir {root}/bc_roadmap_global",
                    "the global clone with its spread: 5 epochs on the million steps",
                    "--eval-episodes 2",
                ),
            ),
            product=("bc_roadmap_global/bc.pt",),
            cost="about 2.1 hours of one core: demonstrations 72 minutes, cloning 51 (observing a million states of 256 points included)",
        ),
        Recipe(
            name="slotmoving_sshape_local_policy",
            shipped="slotmoving_sshape_local_policy.pt",
            title="the S-shape's local policy in the moving-gate Slot (slotmoving): the threading expert's demonstrations, cloning, then PPO on a reverse curriculum",
            description=(
                "The slot threading expert's demonstrations of 3,000 moving-gate Slot training problems (2,927 threaded: scripts/slot_expert.py demos with the "
                "shipped template), the local clone with its spread (40 epochs, separate encoders: checkpoints/slotmoving_local_bc_threading.pt), then PPO "
                "with the reverse curriculum and the greedy goal test (docs/guide/training.md, 'A reverse curriculum'; docs/notebook/slot.md; "
                "checkpoints/README.md). The shipped file is the curriculum's best by validation with the escape, at 307,200 steps. The clone's "
                "command (--problems 2927, as its bc_config says) is the one of the earlier learning guide (git show 9dc8483^:docs/learning.md); "
                "the current docs give its settings in words. The curriculum run (ppo_config: --steps 20000000) went on to 860,160 steps without a "
                "better validation; its branch with --lr 3e-5 from 307,200 steps is checkpoints/slotmoving_local_ppo_curriculum_last.pt. Here --steps "
                "stops it at the shipped step. The scene was named slot then (slotmoving since the paper's reading, the fixed gate, took the name); "
                "its problems are the same."
            ),
            steps=(
                _step(
                    "python scripts/slot_expert.py demos --env slotmoving --save-demos {root}/demos_slot_canonical.npz --problems {3000|6}",
                    "the threading expert's demonstrations of 3,000 moving-gate Slot training problems (slots narrower than the template are left out)",
                ),
                _step(
                    "pointplan bc --env slotmoving --robot sshape --observation local --encoder-sharing separate --problems 2927 --epochs {40|1} "
                    "--spread-weight 1 --demos {root}/demos_slot_canonical.npz --run-dir {root}/canon/bc_local",
                    "the clone with its spread: 40 epochs",
                    "--eval-episodes 2",
                ),
                _step(
                    "pointplan ppo --init-actor {root}/canon/bc_local/bc.pt --start-demos {root}/demos_slot_canonical.npz --greedy-goal --lr 1e-4 "
                    "--reward-collision -0.1 --action-cost 0 --lam 0.98 --entropy-coef 0 --select escape --eval-every {102400|64} "
                    "--eval-episodes {100|2} --steps {307200|128} --threads 1 --run-dir {root}/rc/g_ent0",
                    "PPO on the reverse curriculum: episodes start on the demonstrations, near their goal first",
                    "--num-envs 4 --rollout-steps 16 --value-warmup 1",
                ),
            ),
            product=("rc/g_ent0/best.pt",),
            cost="about 1 hour: demonstrations about 4 minutes, cloning 32, the curriculum 25 (307,200 steps, one core)",
        ),
        Recipe(
            name="slot_sshape_oriented_local_policy",
            shipped="slot_sshape_oriented_local_policy.pt",
            title="the S-shape told its orientation (sshape-oriented), local policy in the paper's Slot: the threading expert's demonstrations, cloning, then PPO on a reverse curriculum",
            description=(
                "The slot threading expert's demonstrations of 3,000 Slot training problems (the gate fixed at the wall's centre; 2,914 threaded), "
                "the local clone of the S-shape told its orientation (the world's axes in the body frame beside the goal; 20 epochs, separate "
                "encoders, the spread fitted: checkpoints/slot_oriented_local_bc_threading.pt), then PPO with the reverse curriculum and the "
                "greedy goal test, the settings of the moving-gate Slot's recipe (docs/results/slot.md; docs/notebook/slot.md). The shipped file "
                "is the curriculum's best by its own validation with the escape; the run went on to 1e6 steps, then was resumed to 2e6 "
                "(--resume with --steps 2000000). Here --steps stops it at the shipped step."
            ),
            steps=(
                _step(
                    "python scripts/slot_expert.py demos --env slot --save-demos {root}/demos_slot.npz --problems {3000|6}",
                    "the threading expert's demonstrations of 3,000 Slot training problems (slots narrower than the template are left out)",
                ),
                _step(
                    "pointplan bc --env slot --robot sshape-oriented --observation local --encoder-sharing separate --epochs {20|1} "
                    "--spread-weight 1 --demos {root}/demos_slot.npz --eval-episodes {200|2} --run-dir {root}/bc_local",
                    "the clone with its spread: 20 epochs",
                ),
                _step(
                    "pointplan ppo --init-actor {root}/bc_local/bc.pt --start-demos {root}/demos_slot.npz --greedy-goal --lr 1e-4 "
                    "--reward-collision -0.1 --action-cost 0 --lam 0.98 --entropy-coef 0 --select escape --eval-every {102400|64} "
                    "--eval-episodes {100|2} --steps {1230400|128} --threads 1 --run-dir {root}/rc_local",
                    "PPO on the reverse curriculum: episodes start on the demonstrations, near their goal first",
                    "--num-envs 4 --rollout-steps 16 --value-warmup 1",
                ),
            ),
            product=("rc_local/best.pt",),
            cost="about 47 minutes of one core (beside another job): demonstrations 5 minutes, cloning 10, the curriculum 32 (1,230,400 steps)",
        ),
        Recipe(
            name="narrow2d_mpnet",
            shipped="narrow2d_mpnet.pt",
            title="MPNet's networks for the disc in 2D-Narrow",
            description=(
                "The shipped run, F2 (docs/results/baselines-mpnet-lsample.md, 'How the MPNet networks were trained'): Bi-RRT paths of 10,000 "
                "training problems and 500 validation problems (planned by the command into the two files when they do not exist), 80 epochs, "
                "mpnet-nr planning 200 validation problems every 10 epochs, no test at the end. best.pt is epoch 80 (96.5% of the validation "
                "problems). The docs ran it with OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 MKL_NUM_THREADS=1 nice -n 10, which changes the time only."
            ),
            steps=(
                _step(
                    "pointplan mpnet-train --problems {10000|8} --demos {root}/demos_train_10000.npz --val-demo-problems {500|4} "
                    "--val-demos {root}/demos_val_500.npz --epochs {80|2} --eval-every {10|1} --val-problems {200|2} --test-problems 0 "
                    "--run-dir {root}/mpnet",
                    "demonstrations, then 80 epochs; the epoch with the best validation success (then loss) is best.pt",
                ),
            ),
            product=("mpnet/best.pt",),
            cost="about 20 minutes: 346 s to plan the 10,000 demonstrations, 859 s of training (one process)",
        ),
        Recipe(
            name="boxes3d_sphere_mpnet",
            shipped="boxes3d_sphere_mpnet.pt",
            title="MPNet's networks for the sphere, trained in 3D-Boxes",
            description=(
                "Run 1 of docs/results/baselines-mpnet-lsample.md ('MPNet in 3D: the sphere'): Bi-RRT paths of 4,000 training problems (3,999 "
                "solved) and of 200 validation problems, 50 epochs, validation every 5; best.pt is epoch 30 (70.5% of 200 validation problems). "
                "Its training file was the sphere's cloning file (demos_boxes3d_sphere_4k.npz, written by pointplan bc); mpnet-train plans the same "
                "problems with the same function, seed and node budget when the file does not exist, so the recipe lets it. Run 2 (12,000 problems, "
                "30 epochs) tied on validation and was not shipped."
            ),
            steps=(
                _step(
                    "pointplan mpnet-train --env boxes3d --robot sphere3d --problems {4000|6} --demos {root}/demos_boxes3d_sphere_4k.npz "
                    "--val-demo-problems {200|4} --val-demos {root}/mpnet3d/demos_val_boxes3d_sphere_200.npz --val-problems {200|2} --test-problems 0 "
                    "--epochs {50|2} --eval-every {5|1} --workers {2|1} --run-dir {root}/mpnet3d/train",
                    "demonstrations, then 50 epochs; the epoch with the best validation success (then loss) is best.pt",
                ),
            ),
            product=("mpnet3d/train/best.pt",),
            cost="885 s of training (50 epochs, one process on a loaded machine), after planning the demonstrations (not timed on their own)",
        ),
        Recipe(
            name="narrow2d_lsample_cvae",
            shipped="narrow2d_lsample_cvae.pt",
            title="the learned sampler's conditional VAE for the disc in 2D-Narrow",
            description=(
                "Run K of docs/results/baselines-mpnet-lsample.md ('How the learned sampler was trained'): Bi-RRT solutions of 4,000 training and "
                "500 validation problems (planned into the two files when they do not exist, with the function and seed the docs used), the "
                "problem's frame, latent size 2, KL weight 3e-3, 80 epochs, planning 200 validation problems every 20 epochs; best.pt is epoch 80 "
                "(the fewest mean nodes at lambda 0.9)."
            ),
            steps=(
                _step(
                    "pointplan lsample-train --demos {root}/demos_train_4k.npz --val-demos {root}/demos_val_500.npz --epochs {80|2} "
                    "--eval-every {20|1} --batch-problems 32 --per-problem 16 --latent 2 --kl-weight 3e-3 --run-dir {root}/lsampleK",
                    "demonstrations, then 80 epochs; the epoch with the fewest nodes at lambda 0.9 is best.pt",
                    "--problems 8 --val-problems 4 --plan-problems 2",
                ),
            ),
            product=("lsampleK/best.pt",),
            cost="about 14 minutes: 4 minutes to plan the two demonstration files, 615 s of training (one process)",
        ),
    )
}


def default_root(name: str) -> Path:
    """Where a recipe's runs go unless told: ``runs/recipes/NAME``."""
    return Path("runs") / "recipes" / name


def shipped_path(recipe: Recipe) -> Path:
    """The shipped file a recipe rebuilds (in the installed package's ``data`` folder)."""
    from importlib.resources import files

    return Path(str(files("pointplan") / "data" / recipe.shipped))


def commands(recipe: Recipe, root: str | Path, smoke: bool = False) -> list[list[str]]:
    """The recipe's command lines, as written (``pointplan ...``, ``python scripts/...``)."""
    return [s.render(root, smoke) for s in recipe.steps]


def _executable(argv: list[str]) -> list[str]:
    """The command to run for a written command line: this Python for ``pointplan`` and
    ``python``, scripts found in the repository."""
    if argv[0] == "pointplan":
        return [sys.executable, "-m", "pointplan", *argv[1:]]
    if argv[0] == "python":
        script = REPO / argv[1]
        if not script.is_file():
            raise FileNotFoundError(f"{argv[1]} is not in {REPO}: run this recipe from a checkout of the repository")
        return [sys.executable, str(script), *argv[2:]]
    raise ValueError(f"a recipe step runs pointplan or python, not {argv[0]!r}")


def _say(message: str) -> None:
    print(message, flush=True)


def run(
    name: str, root: str | Path | None = None, smoke: bool = False, dry_run: bool = False, from_step: int = 1
) -> int:
    """Run recipe ``name``'s steps in order (from step ``from_step``, counted from 1) with
    its runs under ``root``, then copy the final checkpoint to ``root/<shipped name>``.
    ``smoke`` swaps the budgets for tiny ones; ``dry_run`` prints the commands instead.
    Returns 0, or the failed step's exit code after one line saying which step failed."""
    if name not in RECIPES:
        print(f"recipe: no recipe {name!r}; known: {', '.join(RECIPES)}", file=sys.stderr)
        return 2
    recipe = RECIPES[name]
    root = Path(root) if root is not None else default_root(name)
    lines = commands(recipe, root, smoke)
    if not 1 <= from_step <= len(lines):
        print(f"recipe {name}: --from-step {from_step} is not one of its steps 1-{len(lines)}", file=sys.stderr)
        return 2
    final = root / recipe.shipped
    if dry_run:
        _say(f"# {recipe.name}: rebuilds {recipe.shipped}{' (smoke scale)' if smoke else ''}; full size: {recipe.cost}")
        _say(
            textwrap.fill(recipe.description, 100, initial_indent="# ", subsequent_indent="# ", break_on_hyphens=False)
        )
        for i, (step, argv) in enumerate(zip(recipe.steps, lines), 1):
            if i >= from_step:
                _say(f"# {i}. {step.note}" if step.note else f"# {i}.")
                _say(shlex.join(argv))
        _say(
            f"# then: cp {root / recipe.product[0]} {final}"
            + (f" (else {', '.join(str(root / p) for p in recipe.product[1:])})" if len(recipe.product) > 1 else "")
        )
        return 0
    root.mkdir(parents=True, exist_ok=True)
    for i, argv in enumerate(lines, 1):
        if i < from_step:
            continue
        _say(f"recipe {name} [{i}/{len(lines)}]: {shlex.join(argv)}")
        try:
            code = subprocess.run(_executable(argv)).returncode
        except (OSError, ValueError) as e:
            print(f"recipe {name}: step {i} of {len(lines)} could not start: {e}", file=sys.stderr)
            return 2
        if code != 0:
            print(
                f"recipe {name}: step {i} of {len(lines)} failed with exit code {code}: {shlex.join(argv)} (fix it, then continue with --from-step {i})",
                file=sys.stderr,
            )
            return code
    product = next((root / p for p in recipe.product if (root / p).is_file()), None)
    if product is None:
        print(
            f"recipe {name}: its steps finished but left none of {', '.join(str(root / p) for p in recipe.product)}",
            file=sys.stderr,
        )
        return 1
    shutil.copyfile(product, final)
    _say(f"recipe {name}: {final} (from {product}){'; a smoke run, its weights are not for use' if smoke else ''}")
    return 0


def listing() -> str:
    """One paragraph per recipe: its name, what it rebuilds, its steps and full-size cost."""
    out = []
    for r in RECIPES.values():
        n = len(r.steps)
        out.append(
            f"{r.name}\n  rebuilds src/pointplan/data/{r.shipped}: {r.title}\n  {n} step{'s' if n > 1 else ''}; full size: {r.cost or 'not given in the docs'}"
        )
    return "\n".join(out)


def _add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("name", nargs="?", help="the recipe (--list shows them)")
    p.add_argument("--list", action="store_true", help="list the recipes, what each rebuilds and its full-size cost")
    p.add_argument("--root", help="folder for the recipe's runs and the rebuilt file (default: runs/recipes/NAME)")
    p.add_argument("--dry-run", action="store_true", help="print the commands instead of running them")
    p.add_argument(
        "--smoke", action="store_true", help="tiny budgets (steps, epochs, problems, episodes): every stage in seconds"
    )
    p.add_argument(
        "--from-step",
        type=int,
        default=1,
        help="start at this step (counted from 1), e.g. after a failure (default: %(default)s)",
    )
    p.set_defaults(func=_command)


def _command(args: argparse.Namespace) -> int:
    if args.list:
        _say(listing())
        return 0
    if not args.name:
        print("recipe: name a recipe, or --list", file=sys.stderr)
        return 2
    return run(args.name, args.root, smoke=args.smoke, dry_run=args.dry_run, from_step=args.from_step)


def add_parser(sub: _SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    """Register the ``recipe`` subcommand on ``sub`` (an argparse subparsers object)."""
    text = (
        "rebuild a shipped checkpoint from nothing with the commands that trained it (list, dry-run, smoke-run or run)"
    )
    p: argparse.ArgumentParser = sub.add_parser("recipe", help=text, description=text[:1].upper() + text[1:] + ".")
    _add_arguments(p)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m pointplan.recipes NAME [--dry-run | --smoke] [--root DIR]``."""
    p = argparse.ArgumentParser(
        prog="python -m pointplan.recipes", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    _add_arguments(p)
    args = p.parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    raise SystemExit(main())
