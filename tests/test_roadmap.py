"""The roadmap expert (pointplan.learning.roadmap): certified edges, a consistent
shortest-path search, paths the evaluator accepts, demonstrations that round-trip, and
labels that are a function of the state."""

from __future__ import annotations

import numpy as np
import pytest

from pointplan.evaluation.evaluate import check_path
from pointplan.learning.bc import demos_from_paths, load_demos, save_demos
from pointplan.learning.roadmap import (
    Roadmap,
    build_roadmap,
    entry,
    goal_tree,
    lookahead,
    path_to_goal,
    roadmap_demos,
    roadmap_paths,
    start_path,
)
from pointplan.planners.base import path_length
from pointplan.planners.edges import edge_free
from pointplan.scenes.scenarios import make_scenario
from pointplan.scenes.scene import Problem

NODES, K = 300, 8
#: a training problem of 3D-Boxes whose start and goal join a 300-node roadmap
INDEX = 1_000_000


@pytest.fixture(scope="module")
def setup() -> tuple[object, Problem, Roadmap]:
    sc = make_scenario("boxes3d", robot="sshape")
    p = sc.problem("train", INDEX, seed=0)
    rm = build_roadmap(sc.robot, p.scene, NODES, K, np.random.default_rng(0))
    return sc, p, rm


def test_the_roadmap_edges_are_certified(setup: tuple) -> None:
    sc, p, rm = setup
    robot = sc.robot
    assert rm.nodes.shape == (NODES, 7) and not robot.collides(p.scene.world, rm.nodes).any()
    edges = rm.edges
    assert len(edges) > NODES  # a connected-looking graph, not a handful of edges
    g = rm.graph.toarray()
    assert np.allclose(g, g.T)
    sample = edges[np.random.default_rng(1).choice(len(edges), 40, replace=False)]
    for a, b in sample:
        assert np.isclose(g[a, b], robot.distance(rm.nodes[a], rm.nodes[b]))
        assert edge_free(robot, p.scene, rm.nodes[a], rm.nodes[b])[0]
        assert edge_free(robot, p.scene, rm.nodes[b], rm.nodes[a])[0]
        dense = robot.interpolate(rm.nodes[a], rm.nodes[b], np.linspace(0.0, 1.0, 200))
        assert not robot.collides(p.scene.world, dense).any()


def test_cost_to_go_is_consistent(setup: tuple) -> None:
    sc, p, rm = setup
    tree = goal_tree(rm, sc.robot, p.scene, p.goal, K)
    reach = tree.reachable
    assert len(reach) > NODES // 2
    assert tree.cost[tree.goal] == 0 and tree.next[tree.goal] == -1
    nxt = tree.next[reach]
    assert (nxt >= 0).all()
    # the edge to the next configuration: the roadmap's, or the one to the goal
    edge = np.where(
        nxt == tree.goal,
        sc.robot.distance(tree.configs[reach], tree.configs[-1]),
        np.asarray(rm.graph[reach, np.minimum(nxt, NODES - 1)]).ravel(),
    )
    assert np.allclose(tree.cost[reach], edge + tree.cost[nxt])
    assert np.isin(reach[nxt == tree.goal], tree.goal_edges).all()
    unreached = np.setdiff1d(np.arange(NODES), reach)
    assert (tree.next[unreached] == -1).all() and np.isinf(tree.cost[unreached]).all()


def test_paths_reach_the_goal_and_pass_the_evaluator(setup: tuple) -> None:
    sc, p, rm = setup
    robot = sc.robot
    pp = roadmap_paths(robot, rm, p, 3, K, np.random.default_rng(2))
    assert pp.start is not None and len(pp.nodes) == 3
    assert check_path(robot, p, pp.start)
    for path in pp.nodes:
        assert np.allclose(path[-1], p.goal)
        # one action a step
        assert (np.abs(robot.log(path[:-1], path[1:])) <= robot.action_scale + 1e-9).all()
        assert check_path(robot, Problem(p.scene, path[0], p.goal), path)
    raw = path_to_goal(pp.tree, int(pp.tree.reachable[0]))
    assert np.allclose(raw[-1], p.goal)


def test_labels_are_a_function_of_the_state(setup: tuple) -> None:
    sc, p, rm = setup
    robot = sc.robot
    a = roadmap_paths(robot, rm, p, 2, K, np.random.default_rng(3))
    b = roadmap_paths(robot, rm, p, 2, K, np.random.default_rng(4))
    assert a.start is not None and b.start is not None
    assert np.array_equal(a.start, b.start)
    tree = a.tree
    # a node's path goes on as its next node's own path: one answer per state
    i = int(tree.reachable[0])
    here, there = path_to_goal(tree, i), path_to_goal(tree, int(tree.next[i]))
    assert np.array_equal(here[1:], there)
    # a roadmap node entering from off the roadmap is its own successor's path
    j = entry(tree, p.start, K)
    path = start_path(tree, p.start, K)
    assert j is not None and path is not None and np.array_equal(path[1:], path_to_goal(tree, j))


def test_demos_round_trip(setup: tuple, tmp_path: object) -> None:
    sc, _, _ = setup
    paths = roadmap_demos(sc, "train", 0, [INDEX], 200, K, 2, rng_seed=5)
    assert {k for k, _ in paths} == {INDEX} and len(paths) == 3
    demos = demos_from_paths(sc, "train", 0, paths)
    f = tmp_path / "demos.npz"  # type: ignore[operator]
    save_demos(f, sc, demos, "train", 0)
    back = load_demos(f, sc)
    assert len(back) == len(demos) == sum(len(x) - 1 for _, x in paths)
    assert np.array_equal(back.q, demos.q) and np.array_equal(back.action, demos.action)
    assert np.allclose(back.goal, sc.problem("train", INDEX, seed=0).goal)
    # the same call gives the same demonstrations
    again = roadmap_demos(sc, "train", 0, [INDEX], 200, K, 2, rng_seed=5)
    assert all(np.array_equal(x, y) for (_, x), (_, y) in zip(paths, again))


@pytest.mark.parametrize("robot", ["sshape", "sphere3d"])
def test_nearest_nodes_are_the_geodesic_nearest(robot: str) -> None:
    from pointplan.learning.roadmap import nearest_nodes

    sc = make_scenario("boxes3d", robot=robot)
    p = sc.problem("train", INDEX, seed=0)
    rm = build_roadmap(sc.robot, p.scene, 200, 6, np.random.default_rng(6))
    q = sc.robot.sample_uniform(np.random.default_rng(7), 50, p.scene.low, p.scene.high)
    idx, dist = nearest_nodes(rm, sc.robot, q, 6)
    brute = sc.robot.distance(rm.nodes[None], q[:, None])
    assert np.allclose(dist, np.sort(brute, axis=1)[:, :6])
    assert np.allclose(np.take_along_axis(brute, idx, 1), dist)


def test_lookahead_paths_keep_one_label_per_state(setup: tuple) -> None:
    sc, p, rm = setup
    robot = sc.robot
    a = roadmap_paths(robot, rm, p, 3, K, np.random.default_rng(8), ahead=True)
    assert a.start is not None and check_path(robot, p, a.start)
    for path in a.nodes:
        assert check_path(robot, Problem(p.scene, path[0], p.goal), path)
    tree = a.tree
    plain_len, ahead_len = [], []
    for i in tree.reachable[:20]:
        here = path_to_goal(tree, int(i), ahead=True)
        j = lookahead(tree, int(i))
        # the node's path goes on as its lookahead target's own path
        assert np.array_equal(here[1:], path_to_goal(tree, j, ahead=True))
        # the target lies on the node's roadmap path, at least one node on
        assert any(np.array_equal(tree.configs[j], c) for c in path_to_goal(tree, int(i))[1:])
        plain_len.append(path_length(robot, path_to_goal(tree, int(i))))
        ahead_len.append(path_length(robot, here))
    assert (np.array(ahead_len) <= np.array(plain_len) + 1e-6).all()
    # a new search of the same roadmap gives the same lookahead paths
    b = roadmap_paths(robot, rm, p, 3, K, np.random.default_rng(9), ahead=True)
    assert b.start is not None and np.array_equal(a.start, b.start)


def test_state_labels_are_certified_and_a_function_of_the_state() -> None:
    """``label_states`` (DAgger's roadmap expert): a state's label is its path to the goal
    in policy steps, accepted by the evaluator, and the same whichever other states are
    labelled with it (one roadmap per workspace, drawn from the problem's index)."""
    from pointplan.learning.roadmap import label_states

    sc = make_scenario("boxes3d", robot="sshape")
    p = sc.problem("train", INDEX, seed=0)
    robot = sc.robot
    states = list(robot.sample_free(p.scene.world, np.random.default_rng(11), 4, p.scene.low, p.scene.high))
    states.insert(0, p.start)
    both = label_states(sc, "train", 0, INDEX, states, NODES, K, rng_seed=3)
    assert len(both) >= 3  # most free states of this workspace join a 300-node roadmap
    for path in both:
        assert check_path(robot, Problem(p.scene, path[0], p.goal), path)
        steps = robot.log(path[:-1], path[1:]) / robot.action_scale
        assert np.abs(steps).max() <= 1 + 1e-9
    alone = label_states(sc, "train", 0, INDEX, [p.start], NODES, K, rng_seed=3)
    assert len(alone) == 1 and np.allclose(alone[0][0], p.start)
    assert np.array_equal(alone[0], both[0])
    # another roadmap (seed) may label the same state differently, but still certified
    other = label_states(sc, "train", 0, INDEX, [p.start], NODES, K, rng_seed=4)
    assert len(other) == 1 and check_path(robot, p, other[0])
