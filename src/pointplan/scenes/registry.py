"""The scenarios by name: :func:`make_scenario` and the names it knows.

It imports every scenario module and none of them imports it.
"""

from __future__ import annotations

from collections.abc import Callable

from ..robots.base import Robot
from .armcells import ArmCellsScenario
from .base import Scenario
from .cluttered import Cluttered3DScenario
from .mbm import MBM_SCENARIOS
from .mbm import SCENARIOS as MBM_NAMES
from .narrow2d_variants import VARIANT_NAMES, VARIANT_SCENARIOS
from .scenes2d import Empty2DScenario, Narrow2DScenario
from .scenes3d import SCENARIOS_3D as _SCENES3D_MODULE

#: the 3D scenarios of the sphere and the S-shape (scenes3d's and the cluttered layouts)
SCENARIOS_3D: dict[str, Callable[..., Scenario]] = {**_SCENES3D_MODULE, "cluttered3d": Cluttered3DScenario}

#: the arms' own scenarios (MotionBenchMaker's are ``mbm-<scenario>``)
ARM_SCENARIOS: dict[str, Callable[..., Scenario]] = {"armcells": ArmCellsScenario}

#: the 2D scenarios: 2D-Narrow, its variants (narrow2d-ends, -many, -narrow, -manynarrow), the empty square
SCENARIOS: dict[str, type[Scenario]] = {"narrow2d": Narrow2DScenario, "empty2d": Empty2DScenario, **VARIANT_SCENARIOS}


def scenario_names() -> list[str]:
    """Every name :func:`make_scenario` knows, as users type it (``narrow2d-ends``; the
    spellings :func:`scenario_key` maps to the same key, ``narrow2dends``, work too)."""
    return (
        [VARIANT_NAMES.get(k, k) for k in SCENARIOS]
        + list(SCENARIOS_3D)
        + list(ARM_SCENARIOS)
        + [f"mbm-{s}" for s in MBM_NAMES]
    )


def scenario_key(name: str) -> str:
    """The registry key of a scenario name or Gymnasium id (``pointplan/Boxes3D-v0`` ->
    ``boxes3d``)."""
    return name.lower().split("/")[-1].removesuffix("-v0").replace("-", "").replace("_", "")


def is_3d(name: str) -> bool:
    """Whether ``name`` is one of the 3D scenarios (an arm's included)."""
    key = scenario_key(name)
    return key in SCENARIOS_3D or key in MBM_SCENARIOS or key in ARM_SCENARIOS


def make_scenario(name: str, robot: str | Robot | None = None, **kwargs: object) -> Scenario:
    """A scenario by name: ``narrow2d``, ``empty2d`` (2D disc); ``boxes3d``, ``synthetic3d``,
    ``ycb3d``, ``dynamic3d``, ``slot``, ``qureshi3d`` (``robot``: ``sphere3d`` or ``sshape``);
    ``mbm-<scenario>`` (MotionBenchMaker; ``robot``: ``panda`` or ``ur5``), ``armcells``
    (random arm workcells, training ground of the arm policy; ``robot``: an arm).
    Also accepts Gymnasium ids such as ``pointplan/Boxes3D-v0``."""
    key = scenario_key(name)
    if key in MBM_SCENARIOS:
        return MBM_SCENARIOS[key](robot=robot)  # type: ignore[no-any-return]
    if key in ARM_SCENARIOS:
        return ARM_SCENARIOS[key](robot=robot, **kwargs)
    if key in SCENARIOS_3D:
        return SCENARIOS_3D[key](robot=robot, **kwargs)
    if key in SCENARIOS:
        if robot is not None:
            from ..robots import make_robot

            r = make_robot(robot) if isinstance(robot, str) else robot
            if r.dim != 2:
                raise ValueError(f"{name} is a 2D scenario; robot {r.name} is {r.dim}D")
            return SCENARIOS[key](robot=r, **kwargs)  # type: ignore[call-arg]
        return SCENARIOS[key](**kwargs)
    raise ValueError(f"unknown environment {name!r}; known: {', '.join(scenario_names())}")
