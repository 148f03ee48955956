"""MotionBenchMaker problems for arms (Chamzas et al., RA-L 2022), as shipped with VAMP.

Each problem is a MoveIt planning scene (``sceneNNNN.yaml``: boxes and cylinders with poses
in the robot's base frame) and a motion plan request (``requestNNNN.yaml``: the start joint
state and the goal as joint constraints). The package ships the problems of the Panda and
the UR5 (``data/robots/<arm>/mbm_problems.tar.bz2``, 7 scenarios x 100; Apache 2.0, see
``data/robots/LICENSE-vamp-Apache-2.0.txt``) and reads them straight from the archive.
They are test data: nothing in the package trains on them.
"""

from __future__ import annotations

import tarfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..geometry.shapes import Box, Cylinder, Shape, Sphere
from ..robots.arm import ARMS, ArmRobot, arm_data, make_arm
from .base import Scenario
from .scene import Problem, Scene

Array = NDArray[np.float64]

#: the seven scenarios, in MotionBenchMaker's order
SCENARIOS = ("table_pick", "table_under_pick", "box", "bookshelf_small", "bookshelf_tall", "bookshelf_thin", "cage")


@dataclass(eq=False)
class JointSpaceScene(Scene):
    """Obstacles in the 3D workspace of an arm; ``low``/``high`` are the joint limits (the
    box the planners sample in and the motion checks bound), ``workspace_low``/``high`` the
    region of the workspace the scene covers (what a camera or an observation crops to)."""

    workspace_low: Array = field(default_factory=lambda: np.full(3, -1.0))
    workspace_high: Array = field(default_factory=lambda: np.full(3, 1.0))

    @property
    def dim(self) -> int:
        """3: the arm's workspace (its configurations live in joint space)."""
        return 3


def _rotation(quat: Sequence[float]) -> Array:
    """Rotation matrix of a quaternion ``(x, y, z, w)`` (ROS order), normalised."""
    x, y, z, w = np.asarray(quat, np.float64) / np.linalg.norm(quat)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def scene_shapes(scene: dict[str, Any]) -> list[Shape]:
    """The obstacles of a MoveIt ``PlanningScene`` (parsed YAML): boxes, cylinders and
    spheres with their poses (an object's own pose, when given, composes with its
    primitives' poses)."""
    out: list[Shape] = []
    for obj in (scene.get("world") or {}).get("collision_objects") or []:
        op = obj.get("pose") or {}
        orot, opos = (
            _rotation(op.get("orientation", (0, 0, 0, 1))),
            np.asarray(op.get("position", (0, 0, 0)), np.float64),
        )
        for prim, pose in zip(obj.get("primitives") or [], obj.get("primitive_poses") or [], strict=True):
            rot = orot @ _rotation(pose.get("orientation", (0, 0, 0, 1)))
            pos = opos + orot @ np.asarray(pose["position"], np.float64)
            kind, dims = prim["type"], np.asarray(prim["dimensions"], np.float64)
            if kind == "box":
                out.append(Box(pos, dims, rot))
            elif kind == "cylinder":  # MoveIt: (height, radius), axis z
                out.append(Cylinder(pos, float(dims[1]), float(dims[0]), rot))
            elif kind == "sphere":
                out.append(Sphere(pos, float(dims[0])))
            else:
                raise ValueError(
                    f"object {obj.get('id', '?')}: primitive {kind!r} is not supported (box, cylinder, sphere)"
                )
    return out


def request_start_goal(request: dict[str, Any], joint_names: Sequence[str]) -> tuple[Array, Array]:
    """The start joint state and the goal joint constraints of a MoveIt
    ``MotionPlanRequest`` (parsed YAML), in the order of ``joint_names``."""
    js = request["start_state"]["joint_state"]
    start_by = dict(zip(js["name"], js["position"], strict=True))
    goal_by = {c["joint_name"]: c["position"] for c in request["goal_constraints"][0]["joint_constraints"]}
    missing = [n for n in joint_names if n not in start_by or n not in goal_by]
    if missing:
        raise ValueError(f"the request does not give joint {missing[0]} in both its start and its goal")
    return np.array([start_by[n] for n in joint_names], np.float64), np.array(
        [goal_by[n] for n in joint_names], np.float64
    )


@cache
def _archive(arm: str) -> dict[str, bytes]:
    """Every file of an arm's problem archive: ``<scenario>_<arm>/<file>`` -> contents."""
    with resources.as_file(arm_data(arm) / "mbm_problems.tar.bz2") as path, tarfile.open(path, "r:bz2") as tar:
        out = {}
        for member in tar.getmembers():
            if member.isfile():
                f = tar.extractfile(member)
                assert f is not None
                out[member.name.split("/", 1)[1]] = f.read()
        return out


def problem_count(arm: str, scenario: str) -> int:
    """How many problems a scenario has for an arm."""
    return sum(1 for k in _archive(arm) if k.startswith(f"{scenario}_{arm}/request"))


def load_problem(arm: str, scenario: str, index: int) -> Problem:
    """Problem ``index`` (1-based, as in the files' names) of ``scenario`` for ``arm``."""
    import yaml

    if scenario not in SCENARIOS:
        raise ValueError(f"unknown MotionBenchMaker scenario {scenario!r}; known: {', '.join(SCENARIOS)}")
    files = _archive(arm)
    key = f"{scenario}_{arm}/{{}}{index:04d}.yaml"
    if key.format("scene") not in files:
        raise ValueError(f"{scenario} has no problem {index} for {arm} (1..{problem_count(arm, scenario)})")
    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # (libyaml's: ten times faster)
    scene_yaml = yaml.load(files[key.format("scene")], Loader=loader)  # noqa: S506 (a safe loader)
    request = yaml.load(files[key.format("request")], Loader=loader)  # noqa: S506
    robot = make_arm(arm)
    start, goal = request_start_goal(request, robot.model.joint_names)
    ws = request.get("workspace_parameters") or {}
    scene = JointSpaceScene(
        scene_shapes(scene_yaml),
        robot.lower,
        robot.upper,
        name=f"mbm-{scenario}",
        workspace_low=np.asarray(ws.get("min_corner", (-1, -1, -1)), np.float64),
        workspace_high=np.asarray(ws.get("max_corner", (1, 1, 1)), np.float64),
    )
    return Problem(scene, start, goal, tag=f"mbm-{scenario}/{arm}/{index:04d}")


def load_problems(arm: str, scenario: str, indices: Sequence[int] | None = None) -> list[Problem]:
    """Problems of a scenario for an arm (all of them by default)."""
    idx = range(1, problem_count(arm, scenario) + 1) if indices is None else indices
    return [load_problem(arm, scenario, int(i)) for i in idx]


class MBMScenario(Scenario):
    """A MotionBenchMaker scenario as a :class:`Scenario` (``mbm-box``, ...): its 100
    problems, in order, for ``robot`` (``panda`` by default, ``ur5``, or an arm of the same
    name). Test data only: the ``train`` split is refused; seeds do not change problems."""

    horizon = 200
    #: the problems are fixed files (workers load them, nothing is drawn)
    fixed = True

    def __init__(self, scenario: str, robot: str | ArmRobot | None = None) -> None:
        if scenario not in SCENARIOS:
            raise ValueError(f"unknown MotionBenchMaker scenario {scenario!r}; known: {', '.join(SCENARIOS)}")
        name = robot if isinstance(robot, str) else getattr(robot, "name", "panda")
        if name not in ARMS:
            raise ValueError(f"MotionBenchMaker problems ship for the arms {', '.join(ARMS)}, not {name!r}")
        self.scenario, self.arm = scenario, str(name)
        self.name = f"mbm-{scenario}"
        self.arm_robot = robot if isinstance(robot, ArmRobot) else make_arm(self.arm)
        self.robot = self.arm_robot

    def problem(self, split: str, index: int, seed: int = 0) -> Problem:
        if split != "test":
            raise ValueError("MotionBenchMaker problems are test data: only the test split exists")
        return load_problem(self.arm, self.scenario, index + 1)

    def scene(self, split: str, index: int) -> Scene:
        return self.problem(split, index).scene

    @property
    def count(self) -> int:
        """How many problems the scenario has for the arm (100 in MotionBenchMaker)."""
        return problem_count(self.arm, self.scenario)

    def problems(self, split: str, n: int, seed: int = 0) -> list[Problem]:
        if n > self.count:
            raise ValueError(f"{self.name} has {self.count} problems for {self.arm}, not {n}")
        return [self.problem(split, i) for i in range(n)]

    @property
    def bounds(self) -> tuple[Array, Array]:
        return self.arm_robot.lower.copy(), self.arm_robot.upper.copy()


def mbm_scenario_factory(scenario: str) -> Any:
    """``make(robot=None) -> MBMScenario`` for the registry."""

    def make(robot: str | ArmRobot | None = None) -> MBMScenario:
        return MBMScenario(scenario, robot)

    return make


#: registry keys (``mbm-bookshelf_small`` -> ``mbmbookshelfsmall``) -> factories
MBM_SCENARIOS = {"mbm" + s.replace("_", ""): mbm_scenario_factory(s) for s in SCENARIOS}
