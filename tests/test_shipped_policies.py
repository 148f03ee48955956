"""The policies that ship in the package are found by (robot, observation) and plan."""

from __future__ import annotations

import pytest

from pointplan.evaluation import check_path
from pointplan.models.policy import shipped_checkpoint, shipped_policies
from pointplan.planners import make_planner
from pointplan.scenes.scenarios import make_scenario


def test_the_sphere_policy_ships_and_plans_without_a_path() -> None:
    assert ("sphere3d", "local") in shipped_policies()
    scenario = make_scenario("boxes3d", robot="sphere3d")
    planner = make_planner("policy", scenario.robot, observation="local")
    assert planner.policy.observation == "local" and planner.policy.n_points == 64
    # without an observation, the robot's shipped one is chosen
    assert make_planner("policy", scenario.robot).policy.observation == "local"
    problems = scenario.problems("test", 12, seed=0)
    solved = 0
    for p in problems:
        res = planner.plan(p)
        if res.success:
            assert check_path(scenario.robot, p, res.path)
            solved += 1
    assert solved >= 9  # 91% on the 400 test problems


def test_a_combination_that_does_not_ship_names_what_does() -> None:
    with pytest.raises(ValueError, match="no policy ships for robot 'sshape'.*sphere3d with 'local'"):
        shipped_checkpoint("sshape")
    with pytest.raises(ValueError, match="'global'"):
        make_planner("policy", make_scenario("boxes3d", robot="sphere3d").robot, observation="global")
