"""Scenarios: a robot, a family of workspaces, and how problems are drawn in them.

The names most code imports, gathered from the modules that define them: the interface
(:mod:`.base`), the 2D scenarios (:mod:`.scenes2d`) and the registry (:mod:`.registry`).
"""

from __future__ import annotations

from .base import FixedScenario, Scenario
from .registry import SCENARIOS, is_3d, make_scenario, scenario_key, scenario_names
from .scenes2d import Empty2DScenario, Narrow2DScenario

__all__ = [
    "SCENARIOS",
    "Empty2DScenario",
    "FixedScenario",
    "Narrow2DScenario",
    "Scenario",
    "is_3d",
    "make_scenario",
    "scenario_key",
    "scenario_names",
]
