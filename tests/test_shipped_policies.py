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
    # without an observation, the robot's usual one (global points, as in the paper's Table 4)
    assert ("sphere3d", "global") in shipped_policies()
    glob = make_planner("policy", scenario.robot)
    assert glob.policy.observation == "global" and glob.policy.n_points == 256
    problems = scenario.problems("test", 12, seed=0)
    solved = 0
    for p in problems:
        res = planner.plan(p)
        if res.success:
            assert check_path(scenario.robot, p, res.path)
            solved += 1
    assert solved >= 9  # 91% on the 400 test problems


def test_the_sshape_policy_ships_and_its_paths_are_certified() -> None:
    """The S-shape's policies (global: cloned; local: cloned, then PPO; 35-40% of 3D-Boxes
    validation problems each with the mean action, 74.5 and 82.5% with the planner's escape) are
    found without a path, the local one by default; every path they claim passes the
    evaluator's check, and sampled retries solve at least what the first rollout solves."""
    assert ("sshape", "local") in shipped_policies() and ("sshape", "global") in shipped_policies()
    scenario = make_scenario("boxes3d", robot="sshape")
    assert make_planner("policy", scenario.robot, observation="global").policy.observation == "global"
    planner = make_planner("policy", scenario.robot)
    assert (
        planner.policy.observation == "local"
        and planner.policy.robot.name == "sshape"
        and planner.policy.n_points == 64
    )
    retry = make_planner("policy", scenario.robot, attempts=4)
    problems = scenario.problems("test", 12, seed=0)
    solved = solved_retry = 0
    for p in problems:
        a, b = planner.plan(p), retry.plan(p)
        for res in (a, b):
            if res.success:
                assert check_path(scenario.robot, p, res.path)
        solved += a.success
        solved_retry += b.success
        assert b.success or not a.success
    assert solved_retry >= solved and solved_retry >= 3


def test_a_combination_that_does_not_ship_names_what_does() -> None:
    with pytest.raises(ValueError, match="no policy ships for robot 'sshape' with 'local-near'.*sphere3d with 'local'"):
        shipped_checkpoint("sshape", "local-near")
    with pytest.raises(ValueError, match="'interior'"):
        make_planner("policy", make_scenario("boxes3d", robot="sphere3d").robot, observation="interior")


def test_slotmoving_takes_the_policy_trained_there_and_other_scenes_the_boxes_ones() -> None:
    """``scene="slotmoving"`` (the CLI passes ``--env``) selects the S-shape policy trained
    on the moving-gate Slot; other scenes (the paper's ``slot`` among them), other
    observations and other robots keep the 3D-Boxes policies."""
    from pointplan.models.checkpoint import load_checkpoint

    slot = shipped_checkpoint("sshape", None, "slotmoving")
    assert slot.name == "slotmoving_sshape_local_policy.pt" and slot.stat().st_size < 500_000
    meta = load_checkpoint(slot)
    assert (meta["env"], meta["robot"], meta["observation"]) == ("slotmoving", "sshape", "local")
    assert shipped_checkpoint("sshape", "local", "slotmoving") == slot
    assert shipped_checkpoint("sshape", "global", "slotmoving") == shipped_checkpoint("sshape", "global")
    assert shipped_checkpoint("sshape", None, "boxes3d") == shipped_checkpoint("sshape") != slot
    assert shipped_checkpoint("sshape", None, "slot") == shipped_checkpoint("sshape")
    assert shipped_checkpoint("sphere3d", None, "slotmoving") == shipped_checkpoint("sphere3d")
    robot = make_scenario("slotmoving").robot
    assert make_planner("policy", robot, scene="slotmoving").policy.meta["env"] == "slotmoving"
    assert make_planner("hybrid", robot, scene="slotmoving", max_nodes=10).policy.policy.meta["env"] == "slotmoving"
    assert make_planner("policy", robot, scene="boxes3d").policy.meta["env"] == "boxes3d"


def test_the_oriented_sshape_takes_its_slot_policy_and_its_paths_are_certified() -> None:
    """``sshape-oriented`` in ``slot`` takes the policy trained there (local points, told
    its orientation); elsewhere nothing ships for it and the error says what does. On 10
    validation problems its escape solves some, and every path it claims passes the
    evaluator's check."""
    from pointplan.models.checkpoint import load_checkpoint

    path = shipped_checkpoint("sshape-oriented", None, "slot")
    assert path.name == "slot_sshape_oriented_local_policy.pt" and path.stat().st_size < 500_000
    meta = load_checkpoint(path)
    assert (meta["env"], meta["robot"], meta["observation"]) == ("slot", "sshape-oriented", "local")
    assert shipped_checkpoint("sshape-oriented", "local", "slot") == path
    with pytest.raises(ValueError, match="no policy ships for robot 'sshape-oriented'"):
        shipped_checkpoint("sshape-oriented", None, "boxes3d")
    scenario = make_scenario("slot", robot="sshape-oriented")
    planner = make_planner("policy", scenario.robot, scene="slot")
    assert planner.policy.robot.name == "sshape-oriented" and planner.policy.n_points == 64
    from pointplan.planners.rollout import ESCAPE_DEFAULTS

    assert planner.escape == ESCAPE_DEFAULTS["sshape-oriented"]  # its own: 64 draws a step, chosen in Slot
    assert planner.escape.tries == 64 and ESCAPE_DEFAULTS["sshape"].tries == 8
    solved = 0
    for p in scenario.problems("val", 10, seed=0):
        res = planner.plan(p)
        if res.success:
            assert check_path(scenario.robot, p, res.path)
            solved += 1
    assert solved >= 5  # 80-87% of the validation problems
