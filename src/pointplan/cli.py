"""The ``pointplan`` command."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn, cast

import numpy as np

if TYPE_CHECKING:  # the commands import what they run when they run
    from argparse import _SubParsersAction

    from .evaluation.evaluate import EpisodeRecord, EvalReport
    from .learning.collision import CollisionConfig
    from .learning.dagger import DaggerConfig
    from .learning.train import TrainConfig
    from .models.actor_critic import NetConfig
    from .parallel import WorkerPool
    from .planners.base import Planner
    from .robots.base import Robot
    from .scenes.base import Scenario
    from .scenes.io import CloudScenario
    from .scenes.scene import Problem, Scene


class CLIError(Exception):
    """A user-facing error: printed without a traceback."""


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser with its errors in two lines, the error first: ``pointplan plan:
    error: <message>`` and where the help is, instead of the whole usage (exit code 2)."""

    #: the subcommands' parsers by name (set by :func:`build_parser`)
    commands: dict[str, argparse.ArgumentParser]

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}\n(`{self.prog} -h` for help)\n")


def _int_at_least(text: str, low: int, what: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < low:
        raise argparse.ArgumentTypeError(f"must be {what}, got {value}")
    return value


def positive_int(text: str) -> int:
    """An argparse type: an integer of at least 1."""
    return _int_at_least(text, 1, "at least 1")


def _finite_float(text: str, zero: bool) -> float:
    """A finite number above 0 (or, with ``zero``, of at least 0), for argparse."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None
    if not (np.isfinite(value) and (value >= 0 if zero else value > 0)):
        raise argparse.ArgumentTypeError(f"must be a finite number {'of at least' if zero else 'above'} 0, got {text}")
    return value


def positive_float(text: str) -> float:
    """An argparse type: a finite number above 0."""
    return _finite_float(text, zero=False)


def non_negative_float(text: str) -> float:
    """An argparse type: a finite number of at least 0."""
    return _finite_float(text, zero=True)


#: Bi-RRT's node budget on the command line when --max-nodes is not given
DEFAULT_MAX_NODES = 20000


def non_negative_int(text: str) -> int:
    """An argparse type: an integer of at least 0."""
    return _int_at_least(text, 0, "0 or more")


# ---------------------------------------------------------------------------- helpers
def _numbers(text: str | None, what: str) -> np.ndarray | None:
    if text is None:
        return None
    try:
        return np.array([float(x) for x in text.replace(",", " ").split()], np.float64)
    except ValueError:
        raise CLIError(f"{what}: expected numbers separated by commas, got {text!r}") from None


def _given_problem(args: argparse.Namespace, scene: Scene, robot: Robot) -> list[Problem]:
    """The problem of --start/--goal (none if neither is given)."""
    from .scenes import Problem

    start, goal = _numbers(getattr(args, "start", None), "--start"), _numbers(getattr(args, "goal", None), "--goal")
    if start is None and goal is None:
        return []
    if start is None or goal is None:
        raise CLIError("give both --start and --goal (or neither, to draw problems)")
    qs = []
    for q, what in ((start, "--start"), (goal, "--goal")):
        if robot.config_dim == 7 and len(q) == 3:
            q = np.concatenate([q, [0.0, 0.0, 0.0, 1.0]])  # position only: the body upright
        if len(q) != robot.config_dim:
            raise CLIError(f"{what}: a configuration of {robot.name} has {robot.config_dim} numbers, got {len(q)}")
        if robot.config_dim == 7:
            q = np.concatenate([q[:3], q[3:] / np.linalg.norm(q[3:])])
        if np.any(q[: scene.dim] < scene.low) or np.any(q[: scene.dim] > scene.high):
            cloud = getattr(args, "points", None) or getattr(args, "depth", None)
            hint = "; --bounds sets them (low then high)" if cloud else " of the scene file"
            raise CLIError(
                f"{what}: position {q[: scene.dim].tolist()} lies outside the bounds {scene.low.tolist()} .. {scene.high.tolist()}{hint}"
            )
        qs.append(q)
    return [Problem(scene, qs[0], qs[1], tag=f"{scene.name}/given")]


#: the options that give the obstacles as data of one's own
_DATA_SOURCES = ("scene", "points", "depth")
#: the options that go with --depth
_DEPTH_OPTIONS = ("intrinsics", "camera_pose", "depth_scale")


def _data_source(args: argparse.Namespace) -> str | None:
    """Which of --scene, --points and --depth was given (one at most), else None."""
    given = [name for name in _DATA_SOURCES if getattr(args, name, None)]
    if len(given) > 1:
        raise CLIError(f"give one of --scene, --points and --depth, not {' and '.join('--' + g for g in given)}")
    if "depth" not in given:
        for name in _DEPTH_OPTIONS:
            if getattr(args, name, None) is not None:
                raise CLIError(f"--{name.replace('_', '-')} goes with --depth (a depth image)")
    return given[0] if given else None


def _depth_camera(args: argparse.Namespace) -> tuple[np.ndarray, np.ndarray | None, float | None]:
    """--intrinsics, --camera-pose and --depth-scale, checked."""
    intr = _numbers(getattr(args, "intrinsics", None), "--intrinsics")
    if intr is None:
        raise CLIError("--depth needs --intrinsics fx,fy,cx,cy (focal lengths and principal point, in pixels)")
    if len(intr) != 4:
        raise CLIError(f"--intrinsics: expected 4 numbers fx,fy,cx,cy, got {len(intr)}")
    if not (np.all(np.isfinite(intr)) and intr[0] > 0 and intr[1] > 0):
        raise CLIError(f"--intrinsics: fx and fy must be positive and all four finite, got {intr.tolist()}")
    pose = _numbers(getattr(args, "camera_pose", None), "--camera-pose")
    if pose is not None:
        if len(pose) != 7:
            raise CLIError(f"--camera-pose: expected 7 numbers x,y,z,qx,qy,qz,qw, got {len(pose)}")
        if not np.all(np.isfinite(pose)):
            raise CLIError(f"--camera-pose: expected finite numbers, got {pose.tolist()}")
        if not np.linalg.norm(pose[3:]) > 0:
            raise CLIError("--camera-pose: the quaternion qx,qy,qz,qw is zero")
    scale = getattr(args, "depth_scale", None)
    if scale is not None and not (math.isfinite(scale) and scale > 0):
        raise CLIError(f"--depth-scale: expected a positive number (metres per unit), got {scale}")
    return intr, pose, scale


def _cloud_scene(args: argparse.Namespace, source: str) -> Scene:
    """The scene of --points or --depth, in --bounds or around the cloud, --start and --goal."""
    from .robots import make_robot
    from .scenes.io import load_depth_scene, load_points_scene

    robot_arg = getattr(args, "robot", None)
    dim = make_robot(robot_arg).dim if robot_arg else None
    if source == "depth":
        if dim == 2:
            raise CLIError(f"--depth: a depth image is 3D but robot {robot_arg} is 2D")
        dim = 3
    bounds = _numbers(getattr(args, "bounds", None), "--bounds")
    if bounds is not None:
        if len(bounds) not in (4, 6):
            raise CLIError(f"--bounds: expected low then high (4 numbers in 2D, 6 in 3D), got {len(bounds)}")
        if dim is not None and len(bounds) != 2 * dim:
            what = "a depth image is 3D" if source == "depth" else f"{robot_arg} moves in {dim}D"
            raise CLIError(f"--bounds: {what}, got {len(bounds)} numbers")
        dim = len(bounds) // 2
    box = None if bounds is None or dim is None else (bounds[:dim], bounds[dim:])
    given = [
        q
        for q in (_numbers(getattr(args, "start", None), "--start"), _numbers(getattr(args, "goal", None), "--goal"))
        if q is not None
    ]
    if source == "depth":
        intr, pose, scale = _depth_camera(args)
        return load_depth_scene(args.depth, intr, pose, depth_scale=scale, bounds=box, include=given)
    return load_points_scene(args.points, dim=dim, bounds=box, include=given)


def _scenario(args: argparse.Namespace) -> Scenario:
    from .robots import make_robot
    from .scenes.scenarios import make_scenario

    source = _data_source(args)
    if source is not None:
        from .scenes.io import CloudScenario, load_scene

        if source == "scene":
            sf = load_scene(args.scene)
            scene, sf_robot, fixed = sf.scene, sf.robot, sf.problems
        else:
            scene, sf_robot, fixed = _cloud_scene(args, source), None, []
        robot_name = getattr(args, "robot", None) or sf_robot or ("disc2d" if scene.dim == 2 else "sphere3d")
        robot = make_robot(robot_name)
        if robot.dim != scene.dim:
            raise CLIError(f"robot {robot_name} is {robot.dim}D but the scene is {scene.dim}D")
        scenario = CloudScenario(scene, robot, fixed=_given_problem(args, scene, robot) or fixed)
        _warn_enclosed(scenario)
        return scenario
    try:
        return make_scenario(args.env, robot=getattr(args, "robot", None))
    except ValueError as e:
        raise CLIError(str(e)) from None


def _warn_enclosed(scenario: CloudScenario) -> None:
    """One line on stderr for each start or goal of the scenario's fixed problems that lies
    in a region its 2D point clouds enclose."""
    if scenario.enclosed is None:
        return
    for p in scenario.fixed:
        inside = scenario.enclosed.contains(scenario.robot.positions(np.stack([p.start, p.goal])))
        for name, q, hit in zip(("start", "goal"), (p.start, p.goal), inside):
            if hit:
                what = f"--{name}" if p.tag.endswith("/given") else f"{p.tag}: the {name}"
                pos = [round(float(x), 4) for x in scenario.robot.positions(q)]
                print(
                    f"pointplan: warning: {what} {pos} lies in a region the point cloud encloses (inside an obstacle's outline?)",
                    file=sys.stderr,
                )


#: planners that take --checkpoint
POLICY_PLANNERS = ("policy", "hybrid", "hybrid-ompl")
#: MPNet planners (their own checkpoints: `pointplan mpnet-train`)
MPNET_PLANNERS = ("mpnet-nr", "mpnet-hr")
#: learned-sampling planners: Bi-RRT with a CVAE's samples (their own checkpoints: `pointplan lsample-train`)
LSAMPLE_PLANNERS = ("learned-sampling", "lsample-0.5", "lsample-0.9")


def _check_checkpoint(args: argparse.Namespace, names: Sequence[str]) -> None:
    """--checkpoint needs a planner that runs a policy, an MPNet or a learned sampler (one
    kind only: one file cannot be two)."""
    if getattr(args, "no_greedy_goal", False) and "policy" not in [n.lower() for n in names]:
        raise CLIError(f"--no-greedy-goal is for --planner policy, not {', '.join(names)}")
    if getattr(args, "attempts", 1) > 1 and not any(n.lower() in POLICY_PLANNERS for n in names):
        raise CLIError(f"--attempts is for --planner policy or hybrid, not {', '.join(names)}")
    if getattr(args, "escape", None) is not None and not any(n.lower() in POLICY_PLANNERS for n in names):
        raise CLIError(f"--escape is for --planner policy or hybrid, not {', '.join(names)}")
    for flag in ("escape_tries", "escape_lookahead", "escape_backoff", "substep"):
        if getattr(args, flag, None) is not None and not any(n.lower() in POLICY_PLANNERS for n in names):
            raise CLIError(f"--{flag.replace('_', '-')} is for --planner policy or hybrid, not {', '.join(names)}")
    if getattr(args, "dodge", None) is not None and not any(n.lower() in POLICY_PLANNERS for n in names):
        raise CLIError(f"--dodge is for --planner policy or hybrid, not {', '.join(names)}")
    noise = getattr(args, "action_noise", 1.0)
    if not (math.isfinite(noise) and noise >= 0):
        raise CLIError(f"--action-noise must be a finite number >= 0, not {noise}")
    if not getattr(args, "checkpoint", None):
        return
    kinds = [
        kind
        for kind, members in (
            ("policy planners (policy, hybrid, hybrid-ompl)", POLICY_PLANNERS),
            ("MPNet planners (mpnet-nr, mpnet-hr)", MPNET_PLANNERS),
            ("learned-sampling planners (lsample-0.5, lsample-0.9, learned-sampling)", LSAMPLE_PLANNERS),
        )
        if any(n.lower() in members for n in names)
    ]
    if not kinds:
        raise CLIError(
            f"--checkpoint is for --planner policy, hybrid, mpnet-nr, mpnet-hr or a learned-sampling planner (lsample-0.5, lsample-0.9, learned-sampling); {', '.join(names)} takes no checkpoint"
        )
    if len(kinds) > 1:
        which = "both" if len(kinds) == 2 else "all three"
        raise CLIError(f"--checkpoint: give either {' or '.join(kinds)}, not {which}: each takes its own checkpoint")


def _policy_input(planner: Planner) -> tuple[str, int] | None:
    """The observation and point count the policy of ``planner`` sees (None without one)."""
    from .planners.hybrid import HybridPlanner
    from .planners.policy import PolicyPlanner

    if isinstance(planner, HybridPlanner):
        planner = planner.policy
    if not isinstance(planner, PolicyPlanner) or planner.env.observation is None:
        return None
    return str(planner.env.observation), int(planner.env.n_points or 0) or 64


def _say_shipped(name: str, planner: Planner, args: argparse.Namespace) -> None:
    """Where no --checkpoint was given, say which shipped policy ``planner`` runs and where
    it was trained (Slot has one of its own; the other 3D scenes share 3D-Boxes')."""
    from .planners.hybrid import HybridPlanner
    from .planners.policy import PolicyPlanner

    if getattr(args, "checkpoint", None) or getattr(args, "quiet", False):
        return
    if isinstance(planner, HybridPlanner):
        planner = planner.policy
    if isinstance(planner, PolicyPlanner) and planner.policy.path is not None:
        print(
            f"{name}: the shipped policy {planner.policy.path.name} (trained in {planner.policy.env}, {planner.policy.observation} observations)"
        )


def _planner(name: str, robot: Robot, args: argparse.Namespace, seed: int) -> Planner:
    from .planners import make_planner

    kwargs: dict[str, Any] = {}
    given_nodes = getattr(args, "max_nodes", None)
    nodes = given_nodes or DEFAULT_MAX_NODES
    time_limit = getattr(args, "time_limit", None)
    if name == "birrt":
        kwargs = {"max_nodes": nodes, "seed": seed, "time_limit": time_limit}
    elif name.lower() in LSAMPLE_PLANNERS:
        kwargs = {"max_nodes": nodes, "seed": seed, "checkpoint": getattr(args, "checkpoint", None)}
    elif name in POLICY_PLANNERS:
        kwargs = {
            "checkpoint": getattr(args, "checkpoint", None),
            "observation": getattr(args, "observation", None),
            "scene": getattr(args, "env", None),
        }
        if getattr(args, "no_greedy_goal", False) and name == "policy":
            kwargs["greedy_goal"] = False
        if getattr(args, "attempts", 1) > 1:
            kwargs.update(attempts=args.attempts, action_noise=args.action_noise)
        if getattr(args, "escape", None) is not None:
            kwargs["escape"] = args.escape
        tries, ahead = getattr(args, "escape_tries", None), getattr(args, "escape_lookahead", None)
        back = getattr(args, "escape_backoff", None)
        if tries is not None or ahead is not None or back is not None:
            from .planners.rollout import RolloutOptions

            esc = RolloutOptions(escape=getattr(args, "escape", None)).escape_for(robot, tries)
            esc = esc if ahead is None else dataclasses.replace(esc, lookahead=ahead)
            kwargs["escape"] = esc if back is None else dataclasses.replace(esc, backoff=back)
        if getattr(args, "substep", None) is not None:
            kwargs["substep"] = args.substep
        if getattr(args, "dodge", None) is not None:
            from .planners.rollout import DODGE_DEFAULT

            kwargs["dodge"] = dataclasses.replace(DODGE_DEFAULT, draws=args.dodge)
        if name == "hybrid":
            kwargs.update(max_nodes=given_nodes, seed=seed)
        if name in ("hybrid", "hybrid-ompl") and time_limit is not None:
            kwargs["time_limit"] = time_limit
    elif name in MPNET_PLANNERS:
        kwargs = {"checkpoint": getattr(args, "checkpoint", None), "seed": seed}
        if name == "mpnet-hr":
            kwargs["max_nodes"] = nodes
    elif name.lower().startswith("ompl:"):
        kwargs = {"time_limit": time_limit or 1.0}
        if getattr(args, "range", None):
            kwargs["range"] = args.range
    try:
        return make_planner(name, robot, **kwargs)
    except (ValueError, ImportError) as e:
        raise CLIError(str(e)) from None


def _write_json(path: str | None, payload: dict[str, Any]) -> None:
    if path:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_text(json.dumps(payload, indent=2) + "\n")
        print(f"wrote {path}")


#: what ``--env`` takes (:func:`pointplan.scenes.registry.scenario_names`, which the CLI's
#: tests hold this to; written out so that ``--help`` imports no scenario)
ENV_NAMES = (
    "narrow2d (2D-Narrow; variants narrow2d-ends, narrow2d-many, narrow2d-narrow, narrow2d-manynarrow), empty2d, "
    "boxes3d, synthetic3d, ycb3d, dynamic3d, qureshi3d, cluttered3d, slot (the paper's Slot), slotmoving, slotwide, "
    "slotclassic, armcells (an arm's random workcells), mbm-<scenario> (MotionBenchMaker: table_pick, "
    "table_under_pick, box, bookshelf_small, bookshelf_tall, bookshelf_thin, cage)"
)


def _add_common(
    p: argparse.ArgumentParser,
    planner_default: str = "birrt",
    seed_help: str = "problem-set seed, 0 or more (default: %(default)s)",
) -> None:
    p.add_argument(
        "--env",
        default="narrow2d",
        help=f"scenario: {ENV_NAMES} (default: narrow2d)",
    )
    p.add_argument("--scene", help="plan on a scene file (JSON, see docs/guide/scene-files.md) instead of --env")
    p.add_argument(
        "--robot",
        help="sphere3d, sshape or sshape-oriented (the S-shape told its orientation) for the 3D scenarios (default: sphere3d; sshape for slot), panda (default) or ur5 for mbm-* and armcells, or the robot of a scene file that names none",
    )
    p.add_argument(
        "--planner",
        default=planner_default,
        help="birrt, straight, policy, hybrid (the policy, then Bi-RRT where it fails), hybrid-ompl (the policy, then OMPL's RRTConnect; pip install 'pointplan[ompl]'), mpnet-nr, mpnet-hr (MPNet with neural or hybrid replanning), lsample-0.5 or lsample-0.9 (Bi-RRT drawing that fraction of its samples from a learned CVAE; learned-sampling is lsample-0.5) or ompl:NAME for an OMPL planner such as ompl:RRTConnect (pip install 'pointplan[ompl]') (default: %(default)s)",
    )
    p.add_argument(
        "--checkpoint",
        help="trained policy (a best.pt or last.pt) for --planner policy or hybrid, trained MPNet for mpnet-nr and mpnet-hr, or a sampler network from `pointplan lsample-train` for the lsample planners (default: the shipped policy for the robot and --observation, the shipped MPNet or the shipped sampler); an error with other planners",
    )
    p.add_argument(
        "--observation",
        help="what the robot observes (the policy's input; drawn by render and view): 2D surface, surface-normals, interior or image; 3D global or local (policy default: the one that ships for the robot)",
    )
    p.add_argument(
        "--max-nodes",
        type=positive_int,
        help=f"Bi-RRT node budget (mpnet-hr: per Bi-RRT call; also the lsample planners') (default: {DEFAULT_MAX_NODES:,}; hybrid: none, its --time-limit bounds it)",
    )
    p.add_argument(
        "--time-limit",
        type=positive_float,
        help="seconds per query: ompl:NAME (default: 1), hybrid and hybrid-ompl (default: 10, the whole query), birrt (default: none, --max-nodes bounds it)",
    )
    p.add_argument(
        "--range", type=float, help="longest edge of ompl:NAME planners that have one (default: 0.07, Bi-RRT's step)"
    )
    p.add_argument(
        "--no-greedy-goal",
        action="store_true",
        help="--planner policy: roll the policy out until it is within the goal tolerance, without stopping early where the straight edge to the goal is certified free (the paper's protocol; the default stops there)",
    )
    p.add_argument(
        "--attempts",
        type=positive_int,
        default=1,
        help="--planner policy or hybrid: when the policy's mean-action rollout fails, try again from the start up to this many times in all with sampled actions; steps, checks and time of every attempt are counted (default: %(default)s, the plain policy)",
    )
    p.add_argument(
        "--action-noise",
        type=float,
        default=1.0,
        help="the spread of the sampled attempts of --attempts, as a multiple of the policy's own (default: %(default)s)",
    )
    p.add_argument(
        "--escape",
        type=non_negative_int,
        help="--planner policy or hybrid: where the robot is stuck, this many steps of the robot's escape, then the mean action toward the goal again; 0 turns it off (default: 10 for the S-shape, which samples from twice the policy's spread after a step that did not move it, and for the sphere, which heads for a random subgoal after 6 steps that ended within 0.1 of where they started; both chosen on validation; 0 for the disc)",
    )
    p.add_argument(
        "--escape-tries",
        type=positive_int,
        help="--planner policy or hybrid: each sampled step of an escape draws this many actions and takes the one whose free motion goes furthest (default: the robot's, chosen on validation: 8 for the S-shape, 64 for the S-shape told its orientation; 1 is the plain escape)",
    )
    p.add_argument(
        "--escape-lookahead",
        type=non_negative_int,
        help="--planner policy or hybrid: judge each draw of a screened escape by where the mean action carries the robot in this many steps more from its end, the furthest taken; 0: by its own motion (default: the robot's)",
    )
    p.add_argument(
        "--escape-backoff",
        type=non_negative_float,
        help="--planner policy or hybrid: where not one draw of a screened escape step moves the robot, head back instead toward the latest pose of its path more than this far away (geodesic distance); 0: off (default: the robot's: 0.06 for the S-shape told its orientation, off for the others)",
    )
    p.add_argument(
        "--substep",
        type=positive_float,
        help="--planner policy or hybrid: the largest sub-step of the certified check of each move (geodesic distance); finer passes closer to obstacles, in more checks (default: the robot's: 0.005 for the S-shape told its orientation, 0.01, the environments', for the others)",
    )
    p.add_argument(
        "--dodge",
        type=non_negative_int,
        help="--planner policy or hybrid, among moving obstacles: an action whose move would meet them where their last step's motion carries them is replaced by the nearest of standing still and this many sampled actions that does not; 0 turns it off (default: 16, chosen on validation of 3D-Dynamic)",
    )
    p.add_argument("--seed", type=non_negative_int, default=0, help=seed_help)


# ---------------------------------------------------------------------------- commands
def _check_writable(path: str | None, option: str) -> None:
    """Refuse, in one line, an output file that cannot be written (a directory, a folder
    that cannot be made or written to), before any planning."""
    if not path:
        return
    target = Path(path)
    if target.is_dir():
        raise CLIError(f"{option} {path}: is a directory; give a file name")
    folder = target.absolute().parent
    while not folder.exists():  # folders still to make: their nearest existing ancestor decides
        folder = folder.parent
    if not folder.is_dir():
        raise CLIError(f"{option} {path}: cannot write there: {folder} is not a directory")
    if target.exists():
        ok = os.access(target, os.W_OK)
    else:
        try:  # a trial file in the folder: holds for root and on read-only file systems too
            with tempfile.NamedTemporaryFile(dir=folder, prefix=".pointplan-"):
                ok = True
        except OSError:
            ok = False
    if not ok:
        raise CLIError(f"{option} {path}: cannot write there (permission denied or a read-only file system)")


def cmd_eval(args: argparse.Namespace) -> int:
    from .evaluation import evaluate, format_table

    names = [n.strip() for n in args.planner.split(",")]
    _check_checkpoint(args, names)
    _check_writable(args.json, "--json")
    scenario = _scenario(args)
    problems = _test_problems(scenario, args, _eval_episodes(args, scenario))
    pool = _pool(args)
    results: dict[str, dict[str, Any]] = {}
    records: dict[str, list[dict[str, Any]]] = {}
    interrupted = None
    for name in names:
        planner = _planner(name, scenario.robot, args, args.seed)
        _say_shipped(name, planner, args)
        report = evaluate(planner, problems, scenario.robot, progress=not args.quiet, pool=pool)
        results[name] = report.metrics()
        records[name] = [r.to_json() for r in report.records]
        interrupted = report.interrupted
        if interrupted:
            break
    print(format_table(results))
    per_planner = {name: {**m, "problems": records[name]} for name, m in results.items()}
    payload: dict[str, Any] = dict(next(iter(per_planner.values()))) if len(results) == 1 else {"planners": per_planner}
    payload.update({"planner": names[0] if len(names) == 1 else names, "env": scenario.name, "seed": args.seed})
    if interrupted:
        payload["interrupted"] = {"finished": interrupted[0], "problems": interrupted[1]}
    _write_json(args.json, payload)
    return 130 if interrupted else 0


def _workers(args: argparse.Namespace) -> tuple[int | None, str | None] | None:
    """``(workers, address)`` when ``--workers`` / ``--address`` ask for Ray workers
    (checked: Ray must be installed to use them), else None."""
    from .distributed import RAY_MISSING, ray_available, wants_ray

    workers, address = getattr(args, "workers", None), getattr(args, "address", None)
    if not wants_ray(workers, address):
        return None
    if not ray_available():
        raise CLIError(RAY_MISSING)
    return workers, address


def _pool(args: argparse.Namespace) -> WorkerPool | None:
    """The Ray worker pool of ``--workers`` / ``--address`` for :func:`evaluate`, or None
    (one process)."""
    scale = _workers(args)
    if scale is None:
        return None
    from .distributed import RayPool

    return RayPool(*scale)


def _demo_pool(workers: int, address: str | None) -> WorkerPool | None:
    """Ray workers to plan demonstrations on when asked for and Ray is installed; None
    leaves it to the trainer (one process, or local processes without Ray)."""
    from .distributed import RayPool, ray_available, wants_ray

    if wants_ray(workers, address) and ray_available():
        return RayPool(workers if workers > 1 else None, address)
    return None


def _eval_episodes(args: argparse.Namespace, scenario: Scenario) -> int:
    """``eval``'s number of problems: ``--episodes``, else 400, or all of a fixed set's
    problems where it has fewer (a MotionBenchMaker scenario's 100)."""
    if args.episodes:
        return int(args.episodes)
    return min(400, getattr(scenario, "count", 400))


def _test_problems(scenario: Scenario, args: argparse.Namespace, n: int) -> Sequence[Problem]:
    """The first ``n`` test problems; on Ray workers a registered scenario's problems
    travel as their recipe and are rebuilt by the workers (the same problems)."""
    if (
        _workers(args)
        and not getattr(scenario, "fixed", None)
        and not any(getattr(args, name, None) for name in _DATA_SOURCES)
    ):
        from .distributed import ScenarioProblems

        return ScenarioProblems.of(scenario, "test", n, seed=args.seed)
    return scenario.problems("test", n, seed=args.seed)


def _render_arm(problem: Problem, robot: Robot, result: Any, args: argparse.Namespace) -> int:
    """``render`` for an arm: its spheres at the start, goal and along the path (PNG, GIF)."""
    from .robots.arm import ArmRobot
    from .viz.arm import render_arm_gif, render_arm_path

    assert isinstance(robot, ArmRobot)
    path = result.path if result is not None and len(result.path) else None
    render_arm_path(problem, robot, path, args.output, title=f"{robot.name}, {problem.tag}  ({args.planner})")
    print(f"wrote {args.output}")
    if args.gif:
        if path is None:
            raise CLIError("--gif needs a path: pick a planner that solves the problem")
        render_arm_gif(problem, robot, path, args.gif)
        print(f"wrote {args.gif}")
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    from .observers import world_observation

    _check_checkpoint(args, [args.planner])
    _check_writable(args.output, "-o/--output")
    _check_writable(args.gif, "--gif")
    scenario = _scenario(args)
    problem = scenario.problem("test", args.seed, seed=0)
    result = None
    if args.planner != "none":
        planner = _planner(args.planner, scenario.robot, args, args.seed)
        result = planner.plan(problem)
        print(f"{args.planner}: success={result.success} nodes={result.nodes} checks={result.collision_checks}")
        seen = _policy_input(planner)
        if seen is not None:  # draw what the policy saw
            args.observation = args.observation or seen[0]
            args.n_points = args.n_points or seen[1]
    robot = scenario.robot
    if getattr(robot, "urdf", None):
        return _render_arm(problem, robot, result, args)
    if robot.dim == 2:
        from .viz.plot2d import render_problem

        if args.gif:
            raise CLIError("--gif animates 3D scenes; for 2D use the PNG")
        render_problem(
            problem,
            args.output,
            robot,
            observer_name=args.observation or "surface-normals",
            n_points=args.n_points or 64,
            result=result,
            seed=args.seed,
        )
        print(f"wrote {args.output}")
        return 0
    from .evaluation.evaluate import timed_path
    from .viz.plot3d import render_problem_3d, render_rollout_gif

    observation = args.observation or "global"
    if observation not in ("global", "local", "local-near", "local-wide"):
        raise CLIError(
            f"3D scenes are observed as 'global', 'local', 'local-near' or 'local-wide', not {observation!r}"
        )
    path = result.path if result is not None and len(result.path) else None
    pts, nrm = world_observation(problem, robot, observation, args.n_points, problem.start, 0, args.seed)
    title = f"{problem.tag}  ({observation} observation)"
    render_problem_3d(
        problem,
        robot,
        path=path,
        points=pts,
        normals=nrm,
        output=args.output,
        title=title,
        obstacles=problem.scene.obstacles_at(0),
    )
    print(f"wrote {args.output}")
    if args.gif:
        if path is None:
            raise CLIError("--gif needs a path: pick a planner that solves the problem")
        timed = timed_path(robot, path)
        scene = problem.scene
        points_at = lambda t: world_observation(problem, robot, observation, args.n_points, timed[t], t, args.seed)[0]
        render_rollout_gif(
            problem,
            robot,
            timed,
            args.gif,
            obstacles_at=scene.obstacles_at if scene.dynamic else None,
            points_at=points_at,
        )
        print(f"wrote {args.gif} ({len(timed)} frames, one per time step)")
    return 0


def cmd_view(args: argparse.Namespace) -> int:
    import importlib.util

    from .viz.viewer import VIEWER_MISSING

    if importlib.util.find_spec("viser") is None:
        raise CLIError(VIEWER_MISSING)  # before any planning
    from .evaluation.evaluate import timed_path
    from .observers import world_observation
    from .viz.viewer import view_problem

    _check_checkpoint(args, [args.planner])
    scenario = _scenario(args)
    robot = scenario.robot
    if robot.dim != 3:
        raise CLIError("the viewer shows 3D scenes (--env boxes3d, slot, ...); for 2D use `pointplan render`")
    problem = scenario.problem("test", args.seed, seed=0)
    path = None
    if args.planner != "none":
        result = _planner(args.planner, robot, args, args.seed).plan(problem)
        print(f"{args.planner}: success={result.success} nodes={result.nodes} checks={result.collision_checks}")
        path = result.path if len(result.path) else None
    points_at = None
    if args.observation:
        timed = timed_path(robot, path) if path is not None else problem.start[None]

        def points_at(t: int) -> np.ndarray:
            return world_observation(problem, robot, args.observation, args.n_points, timed[t], t, args.seed)[0]

    view_problem(problem, robot, path=path, points_at=points_at, port=args.port, host=args.host)
    return 0


def cmd_plan(args: argparse.Namespace) -> int:
    from .evaluation import check_path, evaluate, format_table
    from .evaluation.evaluate import endpoint_fault

    _check_checkpoint(args, [args.planner])
    _check_writable(args.json, "--json")
    _check_writable(args.output, "-o/--output")
    scenario = _scenario(args)
    problems: Sequence[Problem] = getattr(scenario, "fixed", None) or _test_problems(scenario, args, args.episodes)
    if getattr(args, "start", None) and getattr(args, "goal", None):  # the one problem given
        fault = endpoint_fault(scenario.robot, problems[0])
        if fault:
            raise CLIError(f"the problem of --start and --goal cannot be solved: its {fault} with an obstacle")
    planner = _planner(args.planner, scenario.robot, args, args.seed)
    report = evaluate(planner, problems, scenario.robot, progress=not args.quiet, pool=_pool(args))
    print(format_table({args.planner: report.metrics()}))
    invalid = [r for r in report.records if r.invalid]
    for rec in invalid:
        print(f"{rec.tag or 'a problem'}: {rec.invalid}, cannot be solved")
    if args.output:
        _draw_plan(args, scenario.robot, problems[: len(report.records)], report.records, planner)
    if args.json:
        paths = _exported_paths(scenario.robot, problems, report.records, args.waypoints)
        out: dict[str, Any] = {
            "planner": args.planner,
            **_interpolation_note(scenario.robot, args.waypoints),
            "metrics": report.metrics(),
            "problems": paths,
        }
        if report.interrupted:
            out["interrupted"] = {"finished": report.interrupted[0], "problems": report.interrupted[1]}
        _write_json(args.json, out)
    if report.interrupted:
        return 130
    ok = all(check_path(scenario.robot, p, r.path) for p, r in zip(problems, report.records) if r.success)
    return 0 if ok else 1


def _interpolation_note(robot: Robot, waypoints: str) -> dict[str, str]:
    """What the written paths mean: how consecutive configurations are joined, and the
    configuration's layout."""
    if robot.euclidean:
        how = "linear: consecutive configurations are joined by straight lines in configuration space"
    elif waypoints == "linear-slerp":
        how = (
            "linear + slerp: position linearly, orientation by spherical linear interpolation (every edge is also "
            "free as a screw motion)"
        )
    else:
        how = "screw: q0 exp(s log(q0^-1 q1)), rotation and translation coupled (--waypoints linear-slerp for OMPL/MoveIt)"
    layout = "joint positions in the URDF's order" if getattr(robot, "urdf", None) else "x, y[, z]"
    if not robot.euclidean:
        layout = "x, y, z, qx, qy, qz, qw (quaternion scalar last, as ROS, OMPL and scipy)"
    return {"interpolation": how, "configuration": layout}


def _exported_paths(
    robot: Robot, problems: Sequence[Problem], records: Sequence[EpisodeRecord], waypoints: str
) -> list[dict[str, Any]]:
    """Per problem, the record with its path, split for linear + slerp when asked."""
    from .evaluation.interpolation import for_linear_slerp

    out = []
    for p, r in zip(problems, records, strict=False):
        path = np.asarray(r.path, np.float64)
        if waypoints == "linear-slerp" and r.success and len(path) > 1:
            try:
                path = for_linear_slerp(robot, p, path)
            except ValueError as e:
                raise CLIError(f"{r.tag or 'a problem'}: {e}") from None
        out.append({**r.to_json(), "path": path.tolist()})
    return out


def _draw_plan(
    args: argparse.Namespace,
    robot: Robot,
    problems: Sequence[Problem],
    records: Sequence[EpisodeRecord],
    planner: Planner,
) -> None:
    """The problems, their obstacles (point clouds as their points) and the paths of the
    evaluation's records: one problem alone (in 2D planned again, to draw Bi-RRT's trees),
    several in a grid."""
    Path(args.output).parent.mkdir(parents=True, exist_ok=True)
    verdicts = [f"{args.planner}, {'solved' if r.success else 'not solved'}" for r in records]
    if robot.dim == 2:
        from .viz.plot2d import render_grid, render_problem

        if len(problems) == 1:
            render_problem(problems[0], args.output, robot, result=planner.plan(problems[0]), seed=args.seed)
        else:
            render_grid(
                problems,
                records,
                args.output,
                robot,
                titles=[f"{p.tag.split('/', 1)[-1]}\n{v}" for p, v in zip(problems, verdicts)],
            )
    else:
        from .viz.plot3d import render_grid_3d, render_problem_3d

        paths = [np.asarray(r.path) if len(r.path) else None for r in records]
        if len(problems) == 1:
            title = f"{problems[0].tag}: {verdicts[0]}"
            render_problem_3d(
                problems[0],
                robot,
                path=paths[0],
                output=args.output,
                title=title,
                obstacles=problems[0].scene.obstacles_at(0),
            )
        else:
            render_grid_3d(
                problems,
                robot,
                paths,
                args.output,
                cols=min(3, len(problems)),
                titles=[f"{p.tag}: {v}" for p, v in zip(problems, verdicts)],
            )
    print(f"wrote {args.output} ({len(problems)} problem{'s' if len(problems) != 1 else ''})")


def cmd_demo(args: argparse.Namespace) -> int:
    from .evaluation import format_table
    from .evaluation.evaluate import EvalReport

    _check_writable(args.output, "-o/--output")
    scenario = _scenario(args)
    robot = scenario.robot
    if robot.dim == 3:
        _check_writable(str(Path(args.output).with_suffix(".gif")), "-o/--output (its GIF)")
    episodes = args.episodes or (400 if robot.dim == 2 else 100)
    print(f"{scenario.name} with {robot.name}: {episodes} test problems (workspaces never seen in training)")
    problems = scenario.problems("test", episodes, seed=0)
    planners = _demo_planners(args, scenario)
    reports = _demo_evaluate(planners, problems, robot, args.quiet)
    done = min(len(r.records) for r in reports.values())
    print(format_table({name: EvalReport(name, r.records[:done]).metrics() for name, r in reports.items()}))
    not_run = [name for name in planners if name not in reports]
    if not_run or any(r.interrupted for r in reports.values()):
        skipped = f" ({', '.join(not_run)} not run)" if not_run else ""
        print(
            f"interrupted: the table compares the first {done} of the {len(problems)} problems, which every planner above finished{skipped}; nothing drawn"
        )
        return 130
    try:
        _demo_figures(args, scenario, problems, reports)
    except KeyboardInterrupt:
        print("\ninterrupted while drawing", file=sys.stderr)
        return 130
    return 0


def _demo_planners(args: argparse.Namespace, scenario: Scenario) -> dict[str, Planner]:
    """The demo's planners: the policy (shipped, or --checkpoint), Bi-RRT and the straight line."""
    from .planners import make_planner

    robot = scenario.robot
    observation = args.observation if args.checkpoint is None else None
    try:
        policy = make_planner(
            "policy", robot, checkpoint=args.checkpoint or "shipped", observation=observation, scene=scenario.name
        )
    except ValueError as e:
        raise CLIError(str(e)) from None
    _say_shipped("policy", policy, args)
    return {
        "policy": policy,
        "birrt": make_planner("birrt", robot, seed=0, max_nodes=args.max_nodes or DEFAULT_MAX_NODES),
        "straight": make_planner("straight", robot),
    }


def _demo_evaluate(
    planners: dict[str, Planner], problems: Sequence[Problem], robot: Robot, quiet: bool
) -> dict[str, EvalReport]:
    """Each planner's report on ``problems``, one planner after the other; Ctrl-C stops them
    all (the planner it interrupted has the last report, holding the problems it finished)."""
    from .evaluation import evaluate

    reports: dict[str, EvalReport] = {}
    for name, planner in planners.items():
        reports[name] = evaluate(planner, problems, robot, progress=not quiet)
        if reports[name].interrupted:
            break
    return reports


def _demo_picks(records: Sequence[EpisodeRecord], n: int) -> list[int]:
    """The ``n`` problems the policy solved with the most steps (the ones it solved without
    a step, by the first goal test, only when there are no others), most steps first."""
    solved = [i for i, r in enumerate(records) if r.success]
    moved = [i for i in solved if records[i].nodes > 0]
    return sorted(moved or solved, key=lambda i: -int(records[i].nodes))[:n]


def _count(n: int, word: str) -> str:
    """``"1 step"``, ``"3 steps"``."""
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def _problem_name(problem: Problem) -> str:
    """``test problem 12`` for a problem tagged ``env/test/12/seed0``, else its tag."""
    parts = str(problem.tag).split("/")
    return f"{parts[1]} problem {parts[2]}" if len(parts) >= 3 else str(problem.tag)


def _demo_figures(
    args: argparse.Namespace, scenario: Scenario, problems: Sequence[Problem], reports: dict[str, EvalReport]
) -> None:
    """The policy's paths on the problems of :func:`_demo_picks` (in 3D Bi-RRT's below and
    a GIF), drawn from the evaluation's records."""
    records = reports["policy"].records
    picked = _demo_picks(records, args.figures)
    if not picked:
        print("the policy solved none of these problems: nothing to draw")
        return
    shown = [problems[i] for i in picked]
    policy = [records[i] for i in picked]
    robot = scenario.robot
    if robot.dim == 2:
        from .viz.plot2d import render_grid

        titles = [
            f"policy on {scenario.name}, {_problem_name(p)}\n{_count(r.nodes, 'step')}" for p, r in zip(shown, policy)
        ]
        render_grid(shown, policy, args.output, robot, titles=titles)
        print(f"wrote {args.output}")
        return
    _demo_figures_3d(args, robot, scenario.name, shown, policy, [reports["birrt"].records[i] for i in picked])


def _demo_figures_3d(
    args: argparse.Namespace,
    robot: Robot,
    env: str,
    shown: list[Problem],
    policy: list[EpisodeRecord],
    birrt: list[EpisodeRecord],
) -> None:
    """The policy's paths (top row) and Bi-RRT's (bottom row) on the same problems, and a
    GIF of the policy on the first one."""
    from .evaluation.evaluate import timed_path
    from .viz.plot3d import render_grid_3d, render_rollout_gif

    shown, policy, birrt = shown[:4], policy[:4], birrt[:4]
    names = [_problem_name(p) for p in shown]
    titles = [f"policy on {env}, {n}: {_count(r.nodes, 'step')}" for n, r in zip(names, policy)]
    titles += [f"Bi-RRT on {env}, {n}: {_count(r.nodes, 'node')}" for n, r in zip(names, birrt)]
    paths = [r.path for r in policy] + [r.path if r.success else None for r in birrt]
    render_grid_3d(shown + shown, robot, paths, args.output, cols=len(shown), titles=titles)
    print(f"wrote {args.output} (policy above, Bi-RRT below)")
    gif = str(Path(args.output).with_suffix(".gif"))
    scene = shown[0].scene
    render_rollout_gif(
        shown[0],
        robot,
        timed_path(robot, policy[0].path),
        gif,
        obstacles_at=scene.obstacles_at if scene.dynamic else None,
    )
    print(f"wrote {gif} (the policy on {shown[0].tag})")


def _net_config(args: argparse.Namespace) -> NetConfig:
    from .models.actor_critic import NetConfig
    from .models.encoders import EncoderConfig

    if args.paper:
        return NetConfig(
            EncoderConfig(args.encoder, 256, 3),
            head_width=256,
            head_layers=3,
            critic_action="points",
            shared_encoder=False,
        )
    shared = args.encoder_sharing == "shared"
    action = args.critic_action or ("pooled" if shared else "points")
    return NetConfig(
        EncoderConfig(args.encoder, args.width, args.layers),
        head_width=args.width,
        head_layers=args.layers,
        critic_action=action,
        shared_encoder=shared,
    )


#: train options derived from TrainConfig and SACConfig: flag -> field path
TRAIN_OPTIONS = {
    "steps": "total_steps",
    "num-envs": "num_envs",
    "warmup-steps": "warmup_steps",
    "updates-per-step": "updates_per_step",
    "eval-every": "eval_every",
    "eval-episodes": "eval_episodes",
    "target-success": "target_success",
    "init-actor": "init_actor",
    "retry-failures": "retry_failures",
    "mine-episodes": "mine_episodes",
    "pool-size": "pool_size",
    "pool-retries": "pool_retries",
    "action-cost": "action_cost",
    "demos": "demos",
    "demo-refresh": "demo_refresh",
    "demo-share": "demo_share",
    "bc-weight": "sac.bc_weight",
    "bc-q-filter": "sac.bc_q_filter",
    "bc-q-normalise": "sac.bc_q_normalise",
    "lr": "sac.lr",
    "batch-size": "sac.batch_size",
    "gamma": "sac.gamma",
    "tau": "sac.tau",
    "init-alpha": "sac.init_alpha",
    "target-entropy-scale": "sac.target_entropy_scale",
    "her-ratio": "sac.her_ratio",
    "buffer-size": "sac.buffer_size",
    "actor-delay": "sac.actor_delay",
    "policy-avg": "sac.policy_avg",
}


def _resume_config(args: argparse.Namespace) -> TrainConfig:
    """The configuration of the run ``--resume`` continues, with the options given on the
    command line replacing its own (the networks and the scenario cannot change)."""
    from .config import from_dict, given_options, replace_paths
    from .learning.train import TrainConfig
    from .models.checkpoint import load_checkpoint

    data = load_checkpoint(args.resume)
    if "trainer" not in data:
        kind = (
            "a behavioural-cloning policy (give it to --init-actor)"
            if "bc_config" in data or "dagger_config" in data
            else "a policy without the trainer's state"
        )
        raise CLIError(f"--resume {args.resume}: this is {kind}; resume from the run's last.pt")
    cfg = from_dict(TrainConfig, data["train_config"])
    done = int(data["trainer"]["steps"])
    cfg = replace_paths(cfg, {**given_options(args, TRAIN_OPTIONS), "device": args.device})
    if cfg.total_steps <= done:
        raise CLIError(
            f"--resume {args.resume}: the run has done {done} steps already; give --steps above {done} to continue it"
        )
    return cfg


def _run_folder(path: str | Path) -> str:
    """``--run-dir`` checked before any work (a file in the way, a folder that cannot be
    written: a one-line error); nothing is created yet."""
    from .learning.rundir import RunDirError, check_run_dir

    try:
        check_run_dir(path, create=False)
    except RunDirError as e:
        raise CLIError(str(e)) from None
    return str(path)


def _best_line(best: float | None) -> str:
    """``best validation success 0.850``, or ``no validation yet``."""
    from .learning.rundir import best_note

    return best_note(best)


def cmd_train(args: argparse.Namespace) -> int:
    from .config import given_options, replace_paths
    from .learning.train import TrainConfig, train

    if args.resume:
        cfg = _resume_config(args)
        run_dir = args.run_dir or str(Path(args.resume).parent)  # the run's own folder
    else:
        base = TrainConfig(**_learner_fields(args))
        cfg = replace_paths(base, given_options(args, TRAIN_OPTIONS))
        run_dir = args.run_dir or "runs/latest"
    _run_folder(run_dir)
    scale = _workers(args)
    rollouts = None
    if scale is not None:
        from .distributed.rollouts import ray_rollouts

        rollouts = ray_rollouts(*scale, sync_every=args.sync_every)
    res = train(
        cfg, run_dir, progress=not args.quiet, resume=args.resume, sync_every=args.sync_every, rollouts=rollouts
    )
    if not res.interrupted:  # (an interrupted run has said where it stopped and how to continue)
        print(
            f"{_best_line(res.best_success)} after {res.steps} env steps, {res.wall_time_s:.0f} s; checkpoints in {res.run_dir}"
        )
    summary = {
        "run_dir": str(res.run_dir),
        "best_success": res.best_success,
        "steps": res.steps,
        "wall_time_s": res.wall_time_s,
        "interrupted": res.interrupted,
    }
    _write_json(args.json, summary)
    return 130 if res.interrupted else 0


#: bc options derived from DaggerConfig and its BCConfig: flag -> field path
BC_OPTIONS = {
    "problems": "bc.n_problems",
    "epochs": "bc.epochs",
    "lr": "bc.lr",
    "batch-size": "bc.batch_size",
    "refresh-every": "bc.refresh_every",
    "spread-weight": "bc.spread_weight",
    "workers": "bc.workers",
    "demos": "bc.demos_file",
    "init-actor": "bc.init_actor",
    "rollouts": "rollouts",
    "labels-per-failure": "labels_per_failure",
    "epochs-per-round": "epochs_per_round",
    "eval-episodes": "eval_episodes",
    "expert-max-nodes": "max_nodes",
    "expert-attempts": "bc.expert_attempts",
    "expert-margin": "bc.expert_margin",
    "expert": "expert",
    "roadmap-nodes": "roadmap_nodes",
    "roadmap-k": "roadmap_k",
}


def cmd_bc(args: argparse.Namespace) -> int:
    from .config import given_options, replace_paths
    from .learning.bc import BCConfig, train_bc
    from .learning.dagger import DaggerConfig, train_dagger

    given = {**given_options(args, BC_OPTIONS), "bc.address": args.address}  # (the Ray cluster is this command's)
    if "max_nodes" in given:  # the expert's budget: DAgger's labels and the first demonstrations
        given["bc.expert_max_nodes"] = given["max_nodes"]
    cloning = False  # --resume of a cloning run (not DAgger)
    if args.resume:
        cfg, cloning = _bc_resume_config(args, given)
    else:
        bc = BCConfig(**_learner_fields(args))
        cfg = replace_paths(DaggerConfig(bc, rounds=args.dagger_rounds), given)
    run_dir = _run_folder(args.run_dir or (str(Path(args.resume).parent) if args.resume else "runs/latest"))
    pool = _demo_pool(cfg.bc.workers, cfg.bc.address)
    if (args.dagger_rounds or args.resume) and not cloning:
        summary = train_dagger(
            cfg,
            run_dir,
            progress=not args.quiet,
            init_actor=given.get("bc.init_actor"),  # (as given here: a resumed run keeps its own weights)
            resume=args.resume,
            pool=pool,
        )
    elif cfg.expert != "birrt" and not cloning:
        summary = _bc_own_expert(cfg, run_dir, not args.quiet)
    else:
        resume = args.resume if cloning else None
        summary = train_bc(
            cfg.bc, run_dir, progress=not args.quiet, pool=pool, resume=resume, eval_episodes=cfg.eval_episodes
        )
    if not summary.get("interrupted"):  # (an interrupted run has said where it stopped and how to continue)
        print(_bc_line(summary))
    _write_json(args.json, summary)
    return 130 if summary.get("interrupted") else 0


def _bc_resume_config(args: argparse.Namespace, given: dict[str, Any]) -> tuple[DaggerConfig, bool]:
    """The configuration of the run ``bc --resume`` continues (options given replace its
    own), and whether it is a cloning run (else DAgger)."""
    from .config import from_dict, replace_paths
    from .learning.bc import BCConfig
    from .learning.dagger import DaggerConfig
    from .models.checkpoint import load_checkpoint

    data = load_checkpoint(args.resume)
    if "bc_trainer" in data:
        if args.dagger_rounds:
            raise CLIError(
                f"--resume {args.resume}: a cloning run; finish it, then start DAgger from its bc.pt with --init-actor and --dagger-rounds"
            )
        # (the run's own unless given)
        episodes = int(data["bc_trainer"].get("eval_episodes") or DaggerConfig.eval_episodes)
        return replace_paths(DaggerConfig(from_dict(BCConfig, data["bc_config"]), eval_episodes=episodes), given), True
    if "dagger_config" not in data or "dagger" not in data:
        raise CLIError(
            f"--resume {args.resume}: not the trainer state of a `pointplan bc` run (cloning or DAgger); resume from the run's last.pt"
        )
    cfg = replace_paths(from_dict(DaggerConfig, data["dagger_config"]), given)
    if args.dagger_rounds:
        cfg = dataclasses.replace(cfg, rounds=args.dagger_rounds)
    return cfg, False


def _bc_own_expert(cfg: DaggerConfig, run_dir: str, progress: bool) -> dict[str, Any]:
    """Cloning from demonstrations of ``--expert`` (the slot threading or the roadmap
    expert; planned here in this process, kept in ``--demos`` or the run folder's
    ``demos.npz``)."""
    from .learning.bc import train_bc
    from .learning.dagger import first_demos
    from .learning.rundir import say_interrupted_early
    from .scenes.scenarios import make_scenario

    Path(run_dir).mkdir(parents=True, exist_ok=True)
    demos_file = Path(cfg.bc.demos_file or Path(run_dir) / "demos.npz")
    try:
        demos = first_demos(cfg, make_scenario(cfg.bc.env, robot=cfg.bc.robot), demos_file, progress)
    except KeyboardInterrupt:
        say_interrupted_early("planning the demonstrations")
        return {"run_dir": run_dir, "interrupted": True, "epochs": 0}
    bc = dataclasses.replace(cfg.bc, demos_file=str(demos_file))
    return train_bc(bc, run_dir, progress=progress, demos=demos, eval_episodes=cfg.eval_episodes)


def _bc_line(summary: dict[str, Any]) -> str:
    """One line for the summary of ``bc`` (cloning alone, or with DAgger)."""
    if "checkpoint" in summary:  # cloning alone
        val = summary.get("val_success")
        validation = (
            f"validation success {val:.3f} on {summary['val_problems']} problems"
            if val is not None
            else "no validation yet"
        )
        return (
            f"cloned {summary['demo_steps']} steps of {summary['demo_problems']} demonstrations, final loss {summary['final_loss']:.4f}, {validation}, "
            f"{summary['demo_time_s'] + summary['train_time_s']:.0f} s; checkpoint {summary['checkpoint']}"
        )
    return f"{_best_line(summary.get('best_success'))} with {summary['demo_steps']} demonstration steps, {summary['wall_time_s']:.0f} s; checkpoints in {summary['run_dir']}"


def _learner_fields(args: argparse.Namespace) -> dict[str, Any]:
    """The fields ``train`` and ``bc`` share: scenario, observation, seed, device, network."""
    return {
        "env": args.env,
        "robot": args.robot,
        "observation": _default_observation(args),
        "n_points": _default_points(args),
        "seed": args.seed,
        "device": args.device,
        "net": _net_config(args),
    }


def _default_observation(args: argparse.Namespace) -> str:
    from .scenes.scenarios import is_3d

    return str(args.observation or ("global" if is_3d(args.env) else "surface-normals"))


def _default_points(args: argparse.Namespace) -> int:
    return int(args.n_points or (256 if _default_observation(args) == "global" else 64))


#: collision-classify options derived from CollisionConfig: flag -> field path
COLLISION_OPTIONS = {
    "n-points": "n_points",
    "label": "label",
    "train-scenes": "train_scenes",
    "val-scenes": "val_scenes",
    "test-scenes": "test_scenes",
    "per-scene": "per_scene",
    "band": "band",
    "sampling": "sampling",
    "epochs": "epochs",
    "patience": "patience",
    "lr": "lr",
    "lr-end": "lr_end",
    "batch-size": "batch_size",
    "encoder": "encoder",
    "width": "width",
    "seed": "seed",
    "device": "device",
}


def cmd_collision_classify(args: argparse.Namespace) -> int:
    from .config import given_options, replace_paths
    from .learning.collision import OBSERVATIONS, CollisionConfig, make_data, train_classifier
    from .learning.rundir import say_interrupted_early

    if args.resume:
        base, names = _collision_resume_config(args)
    else:
        names = [n.strip() for n in args.observation.split(",") if n.strip()]
        unknown = [n for n in names if n not in OBSERVATIONS]
        if unknown or not names:
            raise CLIError(
                f"--observation: expected some of {', '.join(OBSERVATIONS)} (comma-separated), got {args.observation!r}"
            )
        base = replace_paths(CollisionConfig(observation=names[0]), given_options(args, COLLISION_OPTIONS))
    run_dir = Path(_run_folder(args.run_dir or (Path(args.resume).parent if args.resume else "runs/collision")))
    try:
        samples = make_data(base, progress=not args.quiet)  # the same samples for every representation
    except KeyboardInterrupt:
        say_interrupted_early("drawing the samples")
        return 130
    rows: dict[str, Any] = {}
    interrupted = False
    for i, name in enumerate(names):
        cfg = dataclasses.replace(base, observation=name)
        resume = args.resume if i == 0 else None
        res = train_classifier(
            cfg, run_dir, progress=not args.quiet, samples=samples, resume=resume, queue=names[i + 1 :]
        )
        if res.interrupted:  # (it has said where it stopped and how to continue)
            interrupted = True
            break
        t = res.test
        rows[name] = res.summary(cfg)
        print(
            f"{name:>16}: test accuracy {100 * t['accuracy']:.1f}% (near the boundary {100 * t['accuracy_near']:.1f}%, "
            f"away {100 * t['accuracy_far']:.1f}%), best epoch {res.best_epoch}, train {res.train_time_s:.0f} s"
        )
    if args.figure and not interrupted:
        from .viz.collision import render_collision_errors

        grid = render_collision_errors(run_dir, args.figure, names)
        for name, g in grid.items():
            rows[name]["figure_grid"] = g
        print(f"wrote {args.figure}")
    _write_json(args.json, {"run_dir": str(run_dir), "results": rows, "interrupted": interrupted})
    return 130 if interrupted else 0


def _collision_resume_config(args: argparse.Namespace) -> tuple[CollisionConfig, list[str]]:
    """The configuration of the classifier ``--resume`` continues (options given replace its
    own) and the observations to train: that one, then those the run had still to train."""
    from .config import from_dict, given_options, replace_paths
    from .learning.collision import CollisionConfig
    from .models.checkpoint import load_checkpoint

    data = load_checkpoint(args.resume)
    if "collision_trainer" not in data:
        raise CLIError(
            f"--resume {args.resume}: not the trainer state of a `pointplan collision-classify` run; resume from the run's last.pt"
        )
    cfg = replace_paths(from_dict(CollisionConfig, data["config"]), given_options(args, COLLISION_OPTIONS))
    return cfg, [cfg.observation, *data["collision_trainer"]["queue"]]


#: mpnet-train options derived from MPNetTrainConfig: flag -> field path
MPNET_OPTIONS = {
    "problems": "n_problems",
    "demos": "demos_file",
    "val-demo-problems": "val_demo_problems",
    "val-demos": "val_demos_file",
    "val-problems": "val_problems",
    "test-problems": "test_problems",
    "n-points": "n_points",
    "waypoint-step": "waypoint_step",
    "subgoal-prob": "subgoal_prob",
    "epochs": "epochs",
    "lr": "lr",
    "lr-end": "lr_end",
    "paths-per-batch": "paths_per_batch",
    "eval-every": "eval_every",
    "max-nodes": "max_nodes",
    "encoder-width": "net.encoder_width",
    "encoder-layers": "net.encoder_layers",
    "width": "net.width",
    "layers": "net.layers",
    "dropout": "net.dropout",
    "workers": "workers",
    "seed": "seed",
}


def cmd_mpnet_train(args: argparse.Namespace) -> int:
    from .config import from_dict, given_options, replace_paths
    from .learning.mpnet import MPNetTrainConfig, train_mpnet
    from .models.mpnet import check_translating

    if args.resume:
        from .models.checkpoint import load_checkpoint

        data = load_checkpoint(args.resume)
        if "mpnet_trainer" not in data:
            raise CLIError(
                f"--resume {args.resume}: not the trainer state of a `pointplan mpnet-train` run; resume from the run's last.pt"
            )
        cfg = replace_paths(from_dict(MPNetTrainConfig, data["train_config"]), given_options(args, MPNET_OPTIONS))
    else:
        try:
            check_translating(_scenario(args).robot)
        except ValueError as e:
            raise CLIError(f"mpnet-train: {e}") from None
        cfg = replace_paths(MPNetTrainConfig(env=args.env, robot=args.robot), given_options(args, MPNET_OPTIONS))
    run_dir = _run_folder(args.run_dir or (Path(args.resume).parent if args.resume else "runs/mpnet"))
    res = train_mpnet(cfg, run_dir, progress=not args.quiet, pool=_demo_pool(cfg.workers, None), resume=args.resume)
    if res.interrupted:  # (it has said where it stopped and how to continue)
        _write_json(
            args.json,
            {"run_dir": str(res.run_dir), "best_epoch": res.best_epoch, "best_val": res.best_val, "interrupted": True},
        )
        return 130
    print(
        f"{_best_line(res.best_val.get('val_success'))} at epoch {res.best_epoch} "
        f"(demonstrations {res.demo_time_s:.0f} s, training {res.train_time_s:.0f} s); checkpoints in {res.run_dir}"
    )
    for name, m in res.test.items():
        print(
            f"test {name}: success {100 * m['success_rate']:.1f}%, nodes {m['nodes_mean']:.1f}, "
            f"path length {m['path_length_mean']:.3f}, collision checks {m['collision_checks_mean']:.0f} ({m['episodes']} problems)"
        )
    _write_json(args.json, res.summary)
    return 0


#: lsample-train options derived from LSampleConfig: flag -> field path
LSAMPLE_OPTIONS = {
    "env": "env",
    "problems": "n_problems",
    "val-problems": "val_problems",
    "plan-problems": "plan_problems",
    "epochs": "epochs",
    "eval-every": "eval_every",
    "lr": "lr",
    "batch-problems": "batch_problems",
    "per-problem": "per_problem",
    "kl-weight": "kl_weight",
    "path-spacing": "path_spacing",
    "latent": "net.latent",
    "width": "net.width",
    "layers": "net.layers",
    "point-width": "net.point_width",
    "point-layers": "net.point_layers",
    "seed": "seed",
    "max-nodes": "max_nodes",
    "workers": "workers",
    "demos": "demos",
    "val-demos": "val_demos",
}


def cmd_lsample_train(args: argparse.Namespace) -> int:
    from .config import from_dict, given_options, replace_paths
    from .learning.lsample import LSampleConfig, train_lsample

    if args.resume:
        from .models.checkpoint import load_checkpoint

        data = load_checkpoint(args.resume)
        if "lsample_trainer" not in data:
            raise CLIError(
                f"--resume {args.resume}: not the trainer state of a `pointplan lsample-train` run; resume from the run's last.pt"
            )
        cfg = replace_paths(from_dict(LSampleConfig, data["lsample_config"]), given_options(args, LSAMPLE_OPTIONS))
    else:
        cfg = replace_paths(LSampleConfig(), given_options(args, LSAMPLE_OPTIONS))
    run_dir = _run_folder(args.run_dir or (Path(args.resume).parent if args.resume else "runs/lsample"))
    summary = train_lsample(
        cfg, run_dir, progress=not args.quiet, pool=_demo_pool(cfg.workers, None), resume=args.resume
    )
    if not summary["interrupted"]:  # (an interrupted run has said where it stopped and how to continue)
        best = summary["best_val_nodes_0.9"]
        print(
            f"trained on {summary['train_configs']} configurations of {summary['train_problems']} Bi-RRT solutions, {summary['epochs']} epochs, "
            f"{summary['train_time_s']:.0f} s (data {summary['data_time_s']:.0f} s); best epoch {summary['best_epoch']}"
            + (
                f" ({best:.1f} mean nodes at lambda 0.9 on validation problems)"
                if best is not None
                else " (no planning validation)"
            )
            + f"; checkpoints in {summary['run_dir']}"
        )
    _write_json(args.json, summary)
    return 130 if summary["interrupted"] else 0


#: ppo options derived from PPOConfig: flag -> field path
PPO_OPTIONS = {
    "init-actor": "init_actor",
    "env": "env",
    "steps": "total_steps",
    "num-envs": "num_envs",
    "rollout-steps": "rollout_steps",
    "epochs": "epochs",
    "minibatch": "minibatch",
    "lr": "lr",
    "value-lr": "value_lr",
    "clip": "clip",
    "target-kl": "target_kl",
    "gamma": "gamma",
    "lam": "lam",
    "entropy-coef": "entropy_coef",
    "value-warmup": "value_warmup",
    "action-cost": "action_cost",
    "reward-collision": "reward_collision",
    "eval-every": "eval_every",
    "eval-episodes": "eval_episodes",
    "eval-escape": "eval_escape",
    "select": "select",
    "greedy-goal": "greedy_goal",
    "start-demos": "start_demos",
    "start-share": "start_share",
    "start-back": "start_back",
    "start-back-step": "start_back_step",
    "start-band": "start_band",
    "start-frontier-share": "start_frontier_share",
    "start-advance": "start_advance",
    "start-min-episodes": "start_min_episodes",
    "seed": "seed",
    "device": "device",
}


def cmd_ppo(args: argparse.Namespace) -> int:
    from .config import from_dict, given_options, replace_paths
    from .learning.ppo import PPOConfig, train_ppo

    given = given_options(args, PPO_OPTIONS)
    if args.threads:
        import torch

        torch.set_num_threads(args.threads)
    if args.resume:
        from .models.checkpoint import load_checkpoint

        data = load_checkpoint(args.resume)
        if "ppo_config" not in data or "ppo" not in data:
            raise CLIError(f"--resume {args.resume}: not a PPO trainer state; resume from a PPO run's last.pt")
        cfg = replace_paths(from_dict(PPOConfig, data["ppo_config"]), given)
        run_dir = args.run_dir or str(Path(args.resume).parent)
    else:
        if not given.get("init_actor"):
            raise CLIError(
                "--init-actor is required: PPO fine-tunes a policy checkpoint (e.g. runs/bc/bc.pt from `pointplan bc`, or a shipped one)"
            )
        cfg = replace_paths(PPOConfig(), given)
        run_dir = args.run_dir or "runs/ppo"
    summary = train_ppo(cfg, _run_folder(run_dir), resume=args.resume, progress=not args.quiet)
    if not summary["interrupted"]:
        steps = summary["steps"]
        rounded = (
            f" (--steps {cfg.total_steps} rounded up to a multiple of --num-envs {cfg.num_envs})"
            if steps > cfg.total_steps
            else ""
        )
        print(
            f"{_best_line(summary['best_success'])} after {steps} env steps{rounded}, {summary['wall_time_s']:.0f} s; checkpoints in {summary['run_dir']}"
        )
    _write_json(args.json, summary)
    return 130 if summary["interrupted"] else 0


def cmd_convert_checkpoint(args: argparse.Namespace) -> int:
    from .models.checkpoint import VERSION
    from .models.convert import convert_checkpoint

    print(
        f"pointplan: warning: convert-checkpoint fully unpickles {args.old}, which runs any code stored in it; convert only files from a source you trust",
        file=sys.stderr,
    )
    notes = convert_checkpoint(args.old, args.new, trust_source=True)
    for note in notes:
        print(f"  converted {note}")
    print(f"wrote {args.new} (checkpoint version {VERSION}: data only)")
    return 0


def _add_net(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--env",
        default="narrow2d",
        help=f"scenario to train on: {ENV_NAMES} (default: %(default)s)",
    )
    p.add_argument(
        "--robot",
        help="sphere3d, sshape or sshape-oriented (the S-shape told its orientation) for the 3D scenarios (default: sphere3d; sshape for slot); panda or ur5 for armcells",
    )
    p.add_argument(
        "--observation", help="2D: surface, surface-normals (default), interior or image; 3D: global (default) or local"
    )
    p.add_argument("--n-points", type=positive_int, help="observed points (default: 256 for global, else 64)")
    p.add_argument(
        "--encoder",
        default="pointnet",
        help="pointnet, mlp or cnn (use cnn with --observation image) (default: %(default)s)",
    )
    p.add_argument(
        "--width", type=positive_int, default=64, help="layer width of encoder and head (default: %(default)s)"
    )
    p.add_argument(
        "--layers",
        type=positive_int,
        default=3,
        help="layers of the per-point encoder and of the head (default: %(default)s)",
    )
    p.add_argument(
        "--encoder-sharing",
        choices=["shared", "separate"],
        default="shared",
        help="one encoder for actor and critics, or one each",
    )
    p.add_argument(
        "--critic-action",
        choices=["points", "pooled"],
        help="where the critic sees the action (default: pooled if shared, else points)",
    )
    p.add_argument(
        "--paper", action="store_true", help="the paper's networks: 3 x 256, separate encoders, action on every point"
    )
    p.add_argument(
        "--seed",
        type=non_negative_int,
        default=0,
        help="seeds the problems, the networks and the validation set (default: %(default)s)",
    )
    p.add_argument("--device", default="cpu", help="cpu or cuda (default: %(default)s)")
    p.add_argument(
        "--run-dir", help="where checkpoints and logs go (default: runs/latest; with --resume the checkpoint's folder)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars")


def _add_scale(p: argparse.ArgumentParser, what: str = "problems are planned by") -> None:
    p.add_argument(
        "--workers",
        type=positive_int,
        default=None,
        help=f"{what} this many Ray workers on this machine (pip install 'pointplan[ray]'; default: one process); results equal a serial run's",
    )
    p.add_argument(
        "--address",
        help="an existing Ray cluster to run the workers on (e.g. auto, or ray://head:10001; see docs/guide/scaling.md)",
    )


CLAIMS_EPILOG = (
    "Every returned path is re-checked by the evaluator (exact clearance along each segment, docs/reference/design.md), and a "
    "problem counts as solved only if that check passes. 'claims disagree' (planner_claims_disagree in the JSON) counts the problems where the "
    "planner's own verdict (it says it solved the problem, or that it did not) differs from the check: a planner "
    "that claims a path the check finds in collision or short of the goal, or one that gives up on a path that "
    "is in fact valid. It should be 0; see docs/results/README.md. 'start/goal in collision' (invalid_problems) counts problems that "
    "cannot be solved as posed."
)


def _subparser(
    sub: _SubParsersAction[argparse.ArgumentParser], name: str, text: str, **kw: Any
) -> argparse.ArgumentParser:
    """A subcommand with ``text`` as both its one-line help and its description."""
    p: argparse.ArgumentParser = sub.add_parser(name, help=text, description=text[:1].upper() + text[1:] + ".", **kw)
    return p


def _add_eval_parser(sub: _SubParsersAction[argparse.ArgumentParser]) -> None:
    p = _subparser(
        sub, "eval", "run planners on a seeded set of test problems and print their metrics", epilog=CLAIMS_EPILOG
    )
    _add_common(p)
    p.add_argument(
        "--episodes",
        type=positive_int,
        help="number of test problems (default: 400, or all of an mbm-* scenario's problems, 100 each)",
    )
    p.add_argument("--json", help="write the metrics to this file")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_scale(p)
    p.set_defaults(func=cmd_eval)


def _add_render_parser(sub: _SubParsersAction[argparse.ArgumentParser]) -> None:
    p = _subparser(sub, "render", "draw a test problem, what the robot observes and a planner's path to a PNG")
    _add_common(
        p,
        seed_help="which test problem, by its index (0 or more), and the seed of the planner and of the drawn points (default: %(default)s)",
    )
    p.add_argument(
        "--n-points",
        type=positive_int,
        help="observed points drawn (default: the policy's with --planner policy or hybrid; else 64, 256 for global)",
    )
    p.add_argument("-o", "--output", default="render.png", help="PNG file (default: %(default)s)")
    p.add_argument("--gif", help="3D: also write an animation of the path, one frame per time step")
    p.set_defaults(func=cmd_render)


def _add_view_parser(sub: _SubParsersAction[argparse.ArgumentParser]) -> None:
    p = _subparser(
        sub, "view", "show a 3D test problem and a planner's path in the browser (pip install 'pointplan[viewer]')"
    )
    _add_common(
        p,
        seed_help="which test problem, by its index (0 or more), and the seed of the planner and of the drawn points (default: %(default)s)",
    )
    p.add_argument(
        "--n-points",
        type=positive_int,
        help="observed points shown with --observation (default: the observer's, 256 for global)",
    )
    p.add_argument("--port", type=int, default=8080, help="port to serve on (default: %(default)s)")
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to listen on; 0.0.0.0 to serve other machines (default: %(default)s)",
    )
    p.set_defaults(func=cmd_view)


def _add_plan_parser(sub: _SubParsersAction[argparse.ArgumentParser]) -> None:
    p = _subparser(
        sub,
        "plan",
        "plan the problems of a scene file, of a point cloud file or of a depth image (or test problems of --env)",
        epilog=CLAIMS_EPILOG,
    )
    _add_common(p)
    p.add_argument(
        "--points",
        help="plan among the points of a cloud file (.ply, .pcd, .npy, .xyz, .txt, .csv; normals estimated if it has none) instead of a scene file",
    )
    p.add_argument(
        "--depth",
        help="plan among the points of a depth image instead of a scene file: .npy (float, metres; or integers, see --depth-scale), .png (16-bit, millimetres) or .tif; pixels of depth 0, NaN or inf are dropped and normals come from the pixel grid, towards the camera; needs --intrinsics (and --camera-pose unless the camera is the world frame)",
    )
    p.add_argument(
        "--intrinsics",
        help="with --depth: the pinhole camera's fx,fy,cx,cy in pixels (focal lengths and principal point)",
    )
    p.add_argument(
        "--camera-pose",
        help="with --depth: the camera's pose in the world as x,y,z,qx,qy,qz,qw (position, then a quaternion); the camera looks along its +z with x to the right and y down in the image (the pinhole/OpenCV convention); write --camera-pose=-1,... when the first number is negative (default: the world frame)",
    )
    p.add_argument(
        "--depth-scale",
        type=float,
        help="with --depth: metres per unit of the image (default: 0.001, millimetres, for an integer image such as a 16-bit PNG; 1 for a float image)",
    )
    p.add_argument(
        "--bounds",
        help="with --points or --depth: the workspace as low then high, e.g. 0,0,1,1; write --bounds=-1,... when the first number is negative (default: the box of the cloud, --start and --goal (and --depth's camera) grown by 10%% of its largest side)",
    )
    p.add_argument(
        "--waypoints",
        choices=("as-planned", "linear-slerp"),
        default="as-planned",
        help="the paths written by --json: as planned (each edge free as the robot's own motion: a straight line for "
        "the disc, the sphere and arms, a screw motion for the S-shape), or linear-slerp (S-shape edges split until "
        "each is free also with its position interpolated linearly and its rotation by slerp, as OMPL's SE(3) space "
        "and MoveIt follow them) (default: %(default)s)",
    )
    p.add_argument("--start", help="plan this start (with --goal) instead of the scene's problems, e.g. 0.1,0.1")
    p.add_argument("--goal", help="the goal of --start, e.g. 0.9,0.9 (an S-shape takes x,y,z or x,y,z,qx,qy,qz,qw)")
    p.add_argument(
        "--episodes",
        type=positive_int,
        default=10,
        help="problems to draw when the scene file has none; in 2D, starts and goals in regions a point cloud encloses (inside a scanned outline) are drawn again, in 3D they are not checked (default: %(default)s)",
    )
    p.add_argument(
        "-o", "--output", help="draw the problems and their paths to this PNG (a grid when there are several)"
    )
    p.add_argument("--json", help="write metrics and paths to this file")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_scale(p)
    p.set_defaults(func=cmd_plan)


def _add_train_parser(sub: _SubParsersAction[argparse.ArgumentParser]) -> None:
    from .config import add_config_options
    from .learning.train import TrainConfig

    p = _subparser(
        sub,
        "train",
        "train a policy with SAC + HER (checkpoints best.pt and last.pt, metrics.csv and TensorBoard logs in --run-dir)",
    )
    _add_net(p)
    add_config_options(p, TrainConfig(), TRAIN_OPTIONS)
    p.add_argument(
        "--resume",
        help="continue a run from its last.pt (into the same folder unless --run-dir is given); options given replace the run's own",
    )
    p.add_argument(
        "--workers",
        type=positive_int,
        default=None,
        help="Ray rollout workers stepping the --num-envs environments (shared out among them) while this process learns (pip install 'pointplan[ray]'; default: one process)",
    )
    p.add_argument(
        "--address", help="an existing Ray cluster to run the rollout workers on (see docs/guide/scaling.md)"
    )
    p.add_argument(
        "--sync-every",
        type=positive_int,
        help="with --workers: learner updates between two broadcasts of the actor's weights (default: 16)",
    )
    p.add_argument("--json", help="also write the summary (best success, steps, time, run folder) to this JSON file")
    p.set_defaults(func=cmd_train)


def _add_bc_parser(sub: _SubParsersAction[argparse.ArgumentParser]) -> None:
    from .config import add_config_options
    from .learning.dagger import DaggerConfig

    p = _subparser(sub, "bc", "behavioural cloning from Bi-RRT demonstrations, optionally followed by DAgger rounds")
    _add_net(p)
    add_config_options(p, DaggerConfig(), BC_OPTIONS)
    p.add_argument(
        "--address", help="an existing Ray cluster to plan the demonstrations on (see docs/guide/scaling.md)"
    )
    p.add_argument(
        "--dagger-rounds",
        type=non_negative_int,
        default=0,
        help="DAgger rounds after cloning: the policy's failed rollouts labelled by Bi-RRT (default: 0, off)",
    )
    p.add_argument(
        "--resume",
        help="continue a cloning or DAgger run from its last.pt (DAgger: --dagger-rounds sets the new total); options given replace the run's own",
    )
    p.add_argument("--json", help="also write the summary to this JSON file")
    p.set_defaults(func=cmd_bc)


def _add_demo_parser(sub: _SubParsersAction[argparse.ArgumentParser]) -> None:
    p = _subparser(
        sub,
        "demo",
        "the shipped policy next to Bi-RRT and the straight line on test problems, with pictures",
        epilog=CLAIMS_EPILOG,
    )
    _add_common(p)
    p.add_argument("--episodes", type=positive_int, help="test problems (default: 400 in 2D, 100 in 3D)")
    p.add_argument("--figures", type=positive_int, default=8, help="problems drawn (default: %(default)s)")
    p.add_argument("-o", "--output", default="demo.png", help="figure (default: %(default)s)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_demo)


def _add_collision_parser(sub: _SubParsersAction[argparse.ArgumentParser]) -> None:
    from .config import add_config_options
    from .learning.collision import CollisionConfig

    p = _subparser(
        sub,
        "collision-classify",
        "the paper's collision classification (section 4.2): from the observation at a configuration and an action, predict whether the disc collides after the action (2D-Narrow)",
    )
    p.add_argument(
        "--observation",
        default="surface-normals",
        help="image (CNN), interior, surface or surface-normals (PointNet); several comma-separated train one after the other on the same samples (default: %(default)s)",
    )
    add_config_options(p, CollisionConfig(), COLLISION_OPTIONS)
    p.add_argument(
        "--run-dir",
        help="where the classifiers (<observation>.pt), summaries and test predictions go (default: runs/collision; with --resume the checkpoint's folder)",
    )
    p.add_argument(
        "--resume",
        help="continue an interrupted run from its last.pt, then the observations it had still to train; options given replace its own",
    )
    p.add_argument("--figure", help="draw where each classifier is wrong (a PNG) after training")
    p.add_argument("--json", help="write the results here")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_collision_classify)


def _add_mpnet_parser(sub: _SubParsersAction[argparse.ArgumentParser]) -> None:
    from .config import add_config_options
    from .learning.mpnet import MPNetTrainConfig

    p = _subparser(
        sub,
        "mpnet-train",
        "train MPNet (mpnet-nr, mpnet-hr) on Bi-RRT paths of training problems; model selection on validation problems, one test at the end (best.pt, last.pt, metrics.csv, summary.json in --run-dir)",
    )
    p.add_argument(
        "--env",
        default="narrow2d",
        help="scenario to train on: narrow2d (the disc) or a 3D scenario with the sphere, e.g. boxes3d (default: %(default)s)",
    )
    p.add_argument(
        "--robot",
        help="sphere3d for the 3D scenarios (the default there; MPNet plans translating robots only, not sshape)",
    )
    add_config_options(p, MPNetTrainConfig(), MPNET_OPTIONS)
    p.add_argument(
        "--run-dir", help="where checkpoints and logs go (default: runs/mpnet; with --resume the checkpoint's folder)"
    )
    p.add_argument(
        "--resume",
        help="continue a run from its last.pt (into the same folder unless --run-dir is given); options given replace the run's own",
    )
    p.add_argument("--json", help="also write the summary to this JSON file")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_mpnet_train)


def _add_lsample_parser(sub: _SubParsersAction[argparse.ArgumentParser]) -> None:
    from .config import add_config_options
    from .learning.lsample import LSampleConfig

    p = _subparser(
        sub,
        "lsample-train",
        "train the learned sampler of --planner lsample-0.5 / lsample-0.9 (Ichter et al. 2018): a conditional VAE on configurations of Bi-RRT solutions of training problems",
    )
    add_config_options(p, LSampleConfig(), LSAMPLE_OPTIONS)
    p.add_argument(
        "--run-dir",
        help="where best.pt, last.pt and metrics.csv go (default: runs/lsample; with --resume the checkpoint's folder)",
    )
    p.add_argument(
        "--resume",
        help="continue a run from its last.pt (into the same folder unless --run-dir is given); options given replace the run's own",
    )
    p.add_argument("--json", help="also write the summary to this JSON file")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_lsample_train)


def _add_ppo_parser(sub: _SubParsersAction[argparse.ArgumentParser]) -> None:
    from .config import add_config_options
    from .learning.ppo import PPOConfig

    p = _subparser(
        sub,
        "ppo",
        "fine-tune a policy (e.g. a cloned one) with PPO on its own sampled rollouts (checkpoints best.pt and last.pt, metrics.csv in --run-dir)",
    )
    add_config_options(p, PPOConfig(), PPO_OPTIONS)
    p.add_argument(
        "--resume",
        help="continue a run from its last.pt (into the same folder unless --run-dir is given); options given replace the run's own",
    )
    p.add_argument(
        "--run-dir", help="where checkpoints and logs go (default: runs/ppo; with --resume the checkpoint's folder)"
    )
    p.add_argument(
        "--threads",
        type=positive_int,
        help="PyTorch threads (default: PyTorch's; 1 per job when several share the cores)",
    )
    p.add_argument("--json", help="also write the summary to this JSON file")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_ppo)


def _add_convert_parser(sub: _SubParsersAction[argparse.ArgumentParser]) -> None:
    p = _subparser(
        sub,
        "convert-checkpoint",
        "rewrite an older checkpoint holding pickled objects as a data-only one (unpickles OLD: trusted files only)",
    )
    p.add_argument("old", help="the checkpoint to convert; it is fully unpickled, which can run code")
    p.add_argument("new", help="where the data-only checkpoint goes")
    p.set_defaults(func=cmd_convert_checkpoint)


def build_parser() -> ArgumentParser:
    from . import __version__

    parser = ArgumentParser(prog="pointplan", description="Neural motion planning from point clouds.")
    parser.add_argument("--version", action="version", version=f"pointplan {__version__}")
    sub = cast("_SubParsersAction[argparse.ArgumentParser]", parser.add_subparsers(dest="command", required=True))
    for add in (
        _add_eval_parser,
        _add_render_parser,
        _add_view_parser,
        _add_plan_parser,
        _add_train_parser,
        _add_bc_parser,
        _add_demo_parser,
        _add_collision_parser,
        _add_mpnet_parser,
        _add_lsample_parser,
        _add_ppo_parser,
        _add_convert_parser,
    ):
        add(sub)
    from .recipes import add_parser as add_recipe_parser

    add_recipe_parser(sub)
    parser.commands = dict(sub.choices)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:  # named by the subcommand, whose options they are not
        parser.commands.get(args.command, parser).error(f"unrecognized arguments: {' '.join(extra)}")
    t0 = time.perf_counter()
    try:
        code = int(args.func(args))
    except CLIError as e:
        print(f"pointplan: error: {e}", file=sys.stderr)
        return 2
    except (ValueError, FileNotFoundError, RuntimeError) as e:
        # scene-file and argument problems come with messages meant for the user
        print(f"pointplan: error: {e}", file=sys.stderr)
        return 2
    if getattr(args, "quiet", False) is False:
        print(f"({time.perf_counter() - t0:.1f} s)")
    return code


if __name__ == "__main__":
    raise SystemExit(main())
