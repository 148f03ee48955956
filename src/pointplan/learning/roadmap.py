"""A roadmap expert: demonstrations whose labels are a function of the state.

Bi-RRT's paths depend on its random tree (above all their first steps: shortcutting leaves
pieces of the tree's short random edges), so a policy cloned from it can see contradictory
labels. The roadmap expert gives every state one answer. Per
workspace it builds a probabilistic roadmap: free configurations drawn uniformly, each
joined to its ``k`` nearest (by the robot's geodesic distance) by the edges that
:func:`~pointplan.planners.edges.edge_free` certifies at the evaluator's resolution. For a
goal, one shortest-path search (Dijkstra, from the goal) then gives every roadmap node its
cost-to-go and the neighbour to move to next: thousands of consistently labelled states
from one search. A configuration off the roadmap (a problem's start) moves to the
neighbour, among its ``k`` nearest nodes and the goal, that minimises edge length plus
cost-to-go over the certified edges, which is again a function of the configuration.

Paths are never shortcut (a shortcut would make a state's label depend on where its path
started); they are only cut into policy steps (:func:`pointplan.learning.bc.resample_path`).
An option, ``ahead``, drops waypoints in a way that keeps one label per state: from each
configuration the expert moves to the furthest configuration along its roadmap path that
one certified edge reaches without lengthening the path (:func:`lookahead`), a function of
that configuration alone, so paths through it all continue alike.

Typical use::

    rm = build_roadmap(robot, problem.scene, 1000, 10, np.random.default_rng(0))
    tree = goal_tree(rm, robot, problem.scene, problem.goal, 10)
    path = start_path(tree, problem.start, 10)  # None: the start does not join the roadmap
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from ..planners.edges import edge_free
from ..robots.base import Robot
from ..scenes.base import Scenario
from ..scenes.scene import Problem, Scene
from .bc import _demo_index, resample_path

Array = NDArray[np.float64]
Index = NDArray[np.int64]

#: the resolution edges are certified at (the evaluator's)
RESOLUTION = 0.01


# ---------------------------------------------------------------------- nearest nodes
def _embed(robot: Robot, q: Array, flip: bool = False) -> Array:
    """Points whose Euclidean distance stands in for the geodesic one: the configuration
    itself for flat spaces; else the position and twice the unit quaternion (its chord is
    about half the rotation angle), negated with ``flip`` (``q`` and ``-q`` are one
    rotation)."""
    q = np.asarray(q, np.float64)
    if robot.euclidean:
        return q
    if q.shape[-1] != robot.dim + 4:
        raise ValueError(f"{robot.name}: the roadmap takes flat configurations or a position and a quaternion")
    quat = -q[..., robot.dim :] if flip else q[..., robot.dim :]
    return np.concatenate([q[..., : robot.dim], 2.0 * quat], -1)


def _index(robot: Robot, nodes: Array) -> Any:
    """A KD-tree over the nodes' embeddings (both quaternion signs for oriented robots, so
    that a node is found whichever sign a query's quaternion has)."""
    if robot.euclidean:
        return cKDTree(nodes)
    return cKDTree(np.concatenate([_embed(robot, nodes), _embed(robot, nodes, flip=True)]))


def _nearest(
    robot: Robot, index: Any, nodes: Array, q: Array, k: int, exclude: Index | None = None
) -> tuple[Index, Array]:
    """The ``k`` nodes nearest to each row of ``q`` ``(M, config_dim)`` by the geodesic
    distance: indices ``(M, k)`` and distances ``(M, k)``, nearest first (a distance of inf
    where there are fewer nodes). Candidates come from the KD-tree and are re-ranked by the
    exact distance; ``exclude`` names one node per row to leave out (the query itself)."""
    q = np.atleast_2d(np.asarray(q, np.float64))
    n = len(nodes)
    c = min(int(index.n), k + 1 if robot.euclidean else max(4 * k, 32))
    _, cand = index.query(_embed(robot, q), k=c)
    cand = np.sort(np.asarray(cand, np.int64).reshape(len(q), c) % n, axis=1)
    d = robot.distance(nodes[cand], q[:, None, :])
    dup = np.zeros(cand.shape, bool)
    dup[:, 1:] = cand[:, 1:] == cand[:, :-1]
    d[dup] = np.inf
    if exclude is not None:
        d[cand == np.asarray(exclude)[:, None]] = np.inf
    order = np.argsort(d, axis=1, kind="stable")[:, :k]
    return np.take_along_axis(cand, order, 1), np.take_along_axis(d, order, 1)


# ---------------------------------------------------------------------- the roadmap
@dataclass
class Roadmap:
    """A probabilistic roadmap of one workspace: free nodes and the certified edges
    between them."""

    #: node configurations ``(N, config_dim)``, all collision-free and inside the bounds
    nodes: Array
    #: ``(N, N)`` symmetric sparse matrix (CSR): the geodesic length of every certified
    #: edge (``robot.distance``); no entry where there is no edge
    graph: Any
    #: the nodes' KD-tree (see :func:`nearest_nodes`)
    index: Any
    #: candidate edges checked (each certified or rejected by ``edge_free``)
    checked: int
    #: configurations the edge checks evaluated
    checks: int
    #: seconds the build took
    build_time_s: float

    def __len__(self) -> int:
        return len(self.nodes)

    @property
    def edges(self) -> Index:
        """The certified edges ``(E, 2)``, each once (``i < j``)."""
        upper = sparse.triu(self.graph, k=1).tocoo()
        return np.stack([upper.row, upper.col], 1).astype(np.int64)


def nearest_nodes(roadmap: Roadmap, robot: Robot, q: Array, k: int) -> tuple[Index, Array]:
    """The ``k`` roadmap nodes nearest to each configuration of ``q`` ``(M, config_dim)``
    by the robot's geodesic distance: indices and distances ``(M, k)``, nearest first."""
    return _nearest(robot, roadmap.index, roadmap.nodes, q, k)


def build_roadmap(
    robot: Robot,
    scene: Scene,
    n_nodes: int,
    k: int,
    rng: np.random.Generator,
    max_edge: float | None = None,
    resolution: float = RESOLUTION,
) -> Roadmap:
    """A roadmap of ``scene``: ``n_nodes`` collision-free configurations drawn uniformly in
    the bounds, each joined to its ``k`` nearest nodes (geodesic distance) where the edge
    is certified free by :func:`~pointplan.planners.edges.edge_free` at ``resolution``.
    ``max_edge`` skips candidate edges longer than that (geodesic distance)."""
    if n_nodes < 2 or k < 1:
        raise ValueError(f"a roadmap needs n_nodes >= 2 and k >= 1, not {n_nodes} and {k}")
    t0 = time.perf_counter()
    nodes = robot.sample_free(scene.world, rng, n_nodes, scene.low, scene.high)
    index = _index(robot, nodes)
    nbr, dist = _nearest(robot, index, nodes, nodes, min(k, n_nodes - 1), exclude=np.arange(n_nodes))
    a = np.repeat(np.arange(n_nodes), nbr.shape[1])
    b, d = nbr.ravel(), dist.ravel()
    ok = np.isfinite(d) if max_edge is None else d <= max_edge
    a, b, d = a[ok], b[ok], d[ok]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    _, first = np.unique(lo * n_nodes + hi, return_index=True)
    lo, hi, d = lo[first], hi[first], d[first]
    free = np.zeros(len(lo), bool)
    checks = 0
    for e in range(len(lo)):
        free[e], used = edge_free(robot, scene, nodes[lo[e]], nodes[hi[e]], resolution)
        checks += used
    rows, cols, w = np.concatenate([lo[free], hi[free]]), np.concatenate([hi[free], lo[free]]), np.tile(d[free], 2)
    graph = sparse.csr_matrix((w, (rows, cols)), shape=(n_nodes, n_nodes))
    return Roadmap(nodes, graph, index, len(lo), checks, time.perf_counter() - t0)


# ---------------------------------------------------------------------- one goal
@dataclass
class GoalTree:
    """Shortest paths from every roadmap node to one goal (:func:`goal_tree`)."""

    roadmap: Roadmap
    robot: Robot
    scene: Scene
    #: the roadmap's nodes and, last, the goal: ``(N + 1, config_dim)``
    configs: Array
    #: cost-to-go (geodesic path length to the goal) of every configuration; inf where the
    #: goal cannot be reached; 0 at the goal
    cost: Array
    #: the configuration to move to next toward the goal (an index into ``configs``); -1
    #: at the goal and where it cannot be reached
    next: Index
    #: the roadmap nodes the goal is joined to by certified edges
    goal_edges: Index
    #: the resolution edges are certified at
    resolution: float = RESOLUTION
    #: lookahead targets found so far (:func:`lookahead`), by node
    jumps: dict[int, int] = field(default_factory=dict, repr=False)

    @property
    def goal(self) -> int:
        """The goal's index in ``configs``."""
        return len(self.configs) - 1

    @property
    def reachable(self) -> Index:
        """The roadmap nodes (not the goal) with a path to the goal."""
        return np.flatnonzero(np.isfinite(self.cost[:-1]))


def goal_tree(
    roadmap: Roadmap, robot: Robot, scene: Scene, goal: Array, k: int, resolution: float = RESOLUTION
) -> GoalTree:
    """Join ``goal`` to its ``k`` nearest roadmap nodes (certified edges) and search the
    roadmap from it (Dijkstra): every node's cost-to-go and next configuration toward the
    goal. The result is a function of the roadmap and the goal alone, so every state of
    every path it gives has one label."""
    goal = np.asarray(goal, np.float64)
    n = len(roadmap)
    nbr, dist = nearest_nodes(roadmap, robot, goal[None], k)
    nbr, dist = nbr[0][np.isfinite(dist[0])], dist[0][np.isfinite(dist[0])]
    free = np.array([edge_free(robot, scene, roadmap.nodes[j], goal, resolution)[0] for j in nbr], bool)
    nbr, dist = nbr[free], dist[free]
    g = roadmap.graph.tocoo()
    rows = np.concatenate([g.row, nbr, np.full(len(nbr), n)])
    cols = np.concatenate([g.col, np.full(len(nbr), n), nbr])
    graph = sparse.csr_matrix((np.concatenate([g.data, dist, dist]), (rows, cols)), shape=(n + 1, n + 1))
    cost, pred = csgraph.dijkstra(graph, directed=True, indices=n, return_predecessors=True)
    nxt = np.where(pred < 0, -1, pred).astype(np.int64)  # from the goal, i's predecessor is its next step
    configs = np.concatenate([roadmap.nodes, goal[None]])
    return GoalTree(roadmap, robot, scene, configs, np.asarray(cost, np.float64), nxt, nbr, resolution)


def _ahead(tree: GoalTree, q: Array, first: int, cost_q: float, max_ahead: int) -> int:
    """The furthest configuration along ``first``'s path to the goal that ``q`` (whose
    cost-to-go through ``first`` is ``cost_q``) reaches by one certified edge without
    lengthening the path: ancestors are tried in order up to the first blocked edge."""
    robot, best, j = tree.robot, first, first
    for _ in range(max_ahead):
        j = int(tree.next[j])
        if j < 0:
            break
        if not edge_free(robot, tree.scene, q, tree.configs[j], tree.resolution)[0]:
            break
        if float(robot.distance(q, tree.configs[j])) + tree.cost[j] <= cost_q + 1e-9:
            best = j
    return best


def lookahead(tree: GoalTree, i: int, max_ahead: int = 64) -> int:
    """Where the lookahead expert moves from node ``i``: the furthest configuration along
    ``i``'s roadmap path that one certified edge reaches without lengthening the path
    (``next[i]`` at least). A function of ``i`` alone (remembered in ``tree.jumps``), so
    paths that drop the waypoints in between still give every state one label."""
    if i not in tree.jumps:
        nxt = int(tree.next[i])
        if nxt < 0:
            raise ValueError(f"configuration {i} has no next step toward the goal")
        tree.jumps[i] = _ahead(tree, tree.configs[i], nxt, float(tree.cost[i]), max_ahead)
    return tree.jumps[i]


def path_to_goal(tree: GoalTree, i: int, ahead: bool = False) -> Array:
    """The configurations from ``configs[i]`` (a roadmap node, or the goal) along the
    roadmap to the goal, both included; with ``ahead``, from each configuration to its
    :func:`lookahead` target instead of its next node. Raises ``ValueError`` where the goal
    cannot be reached from ``i``."""
    if not np.isfinite(tree.cost[i]):
        raise ValueError(f"node {i} has no path to the goal")
    seq = [int(i)]
    while seq[-1] != tree.goal:
        seq.append(lookahead(tree, seq[-1]) if ahead else int(tree.next[seq[-1]]))
    return tree.configs[seq]


def entry(tree: GoalTree, q: Array, k: int) -> int | None:
    """Where a configuration ``q`` off the roadmap joins it: among its ``k`` nearest nodes
    and the goal, the one that minimises edge length plus cost-to-go over the edges
    certified free (tried in that order, so only the edges up to the first certified one
    are checked). Returns its index in ``tree.configs``, or ``None`` if none is joined."""
    robot, q = tree.robot, np.asarray(q, np.float64)
    nbr, dist = nearest_nodes(tree.roadmap, robot, q[None], k)
    cand = np.concatenate([nbr[0], [tree.goal]])
    total = np.concatenate([dist[0], robot.distance(q, tree.configs[-1])[None]]) + tree.cost[cand]
    for j in np.argsort(total, kind="stable"):
        if not np.isfinite(total[j]):
            break
        if edge_free(robot, tree.scene, q, tree.configs[cand[j]], tree.resolution)[0]:
            return int(cand[j])
    return None


def start_path(tree: GoalTree, q: Array, k: int, ahead: bool = False, max_ahead: int = 64) -> Array | None:
    """The expert's path from a configuration ``q`` off the roadmap to the goal: ``q``,
    then the roadmap from its :func:`entry` (with ``ahead``: from ``q`` to the furthest
    configuration along that path one certified edge reaches without lengthening it, then
    :func:`lookahead` steps); ``None`` where ``q`` does not join the roadmap."""
    j = entry(tree, q, k)
    if j is None:
        return None
    q = np.asarray(q, np.float64)
    if ahead:
        j = _ahead(tree, q, j, float(tree.robot.distance(q, tree.configs[j])) + tree.cost[j], max_ahead)
    return np.concatenate([q[None], path_to_goal(tree, j, ahead)])


# ---------------------------------------------------------------------- demonstrations
@dataclass
class ProblemPaths:
    """The roadmap expert's paths for one problem, in policy steps."""

    #: the path from the problem's own start (``None``: the start did not join the roadmap,
    #: or the goal did not)
    start: Array | None
    #: paths from roadmap nodes drawn among those that reach the goal
    nodes: list[Array]
    #: the roadmap and its search (for measurements)
    tree: GoalTree

    @property
    def paths(self) -> list[Array]:
        """Every path: the start's first (if any), then the nodes'."""
        return ([self.start] if self.start is not None else []) + self.nodes


def roadmap_paths(
    robot: Robot,
    roadmap: Roadmap,
    problem: Problem,
    m: int,
    k: int,
    rng: np.random.Generator,
    ahead: bool = False,
) -> ProblemPaths:
    """Paths to ``problem``'s goal through ``roadmap``, each resampled into policy steps
    (:func:`~pointplan.learning.bc.resample_path`): from ``m`` roadmap nodes drawn without
    replacement among those that reach the goal (all of them when fewer), and from the
    problem's own start (joined to its ``k`` nearest nodes or the goal, :func:`entry`).
    ``ahead``: the lookahead expert's paths (:func:`lookahead`) instead of the roadmap's
    every node."""
    tree = goal_tree(roadmap, robot, problem.scene, problem.goal, k)
    raw = start_path(tree, problem.start, k, ahead)
    reach = tree.reachable
    chosen = rng.choice(reach, size=min(m, len(reach)), replace=False) if len(reach) else np.zeros(0, np.int64)
    return ProblemPaths(
        resample_path(robot, raw) if raw is not None else None,
        [resample_path(robot, path_to_goal(tree, int(i), ahead)) for i in chosen],
        tree,
    )


def demo_problem_indices(seed: int, n_problems: int) -> list[int]:
    """The training problems ``pointplan bc --problems n_problems --seed seed`` plans its
    Bi-RRT demonstrations from (the same problems, so the experts can be compared)."""
    return [_demo_index(seed, n_problems, i) for i in range(n_problems)]


def problem_paths(
    scenario: Scenario,
    split: str,
    seed: int,
    index: int,
    n_nodes: int,
    k: int,
    paths_per_problem: int,
    rng_seed: int,
    ahead: bool = False,
) -> ProblemPaths:
    """The roadmap expert's paths of problem ``index`` of ``split`` (problem seed
    ``seed``, see :func:`roadmap_paths`): a roadmap of its workspace drawn from
    ``(rng_seed, index)``, so a problem's paths do not depend on which other problems are
    planned or in what order."""
    p = scenario.problem(split, index, seed=seed)
    rng = np.random.default_rng([int(rng_seed), int(index)])
    rm = build_roadmap(scenario.robot, p.scene, n_nodes, k, rng)
    return roadmap_paths(scenario.robot, rm, p, paths_per_problem, k, rng, ahead)


def roadmap_demos(
    scenario: Scenario,
    split: str,
    seed: int,
    problem_indices: Sequence[int],
    n_nodes: int,
    k: int,
    paths_per_problem: int,
    rng_seed: int = 0,
    ahead: bool = False,
    on_problem: Callable[[int, ProblemPaths], None] | None = None,
) -> list[tuple[int, Array]]:
    """Demonstrations of the problems ``problem_indices`` of ``split`` by the roadmap
    expert (:func:`problem_paths`): ``[(problem index, path in steps), ...]``, the list
    :func:`~pointplan.learning.bc.demos_from_paths` and
    :func:`~pointplan.learning.bc.save_demos` take (with the same ``split`` and ``seed``).
    Per problem: the path from its start, then ``paths_per_problem`` paths from roadmap
    nodes. ``on_problem(index, paths)`` is called after each problem."""
    out: list[tuple[int, Array]] = []
    for index in problem_indices:
        pp = problem_paths(scenario, split, seed, int(index), n_nodes, k, paths_per_problem, rng_seed, ahead)
        out.extend((int(index), path) for path in pp.paths if len(path) > 1)
        if on_problem is not None:
            on_problem(int(index), pp)
    return out


def label_states(
    scenario: Scenario,
    split: str,
    seed: int,
    index: int,
    states: Sequence[Array],
    n_nodes: int,
    k: int,
    rng_seed: int = 0,
    ahead: bool = True,
) -> list[Array]:
    """The roadmap expert's paths, in policy steps, from configurations ``states`` (for
    example those a policy visited) to the goal of problem ``index`` of ``split``: the
    workspace's roadmap is drawn as :func:`problem_paths` draws it (from ``(rng_seed,
    index)``), searched once from the goal, and every state joins it by
    :func:`start_path`. States that do not join the roadmap (or whose goal does not) are
    left out, so the list may be shorter than ``states``."""
    p = scenario.problem(split, index, seed=seed)
    rng = np.random.default_rng([int(rng_seed), int(index)])
    rm = build_roadmap(scenario.robot, p.scene, n_nodes, k, rng)
    tree = goal_tree(rm, scenario.robot, p.scene, p.goal, k)
    out = []
    for q in states:
        raw = start_path(tree, q, k, ahead)
        if raw is not None and len(raw) > 1:
            out.append(resample_path(scenario.robot, raw))
    return out


# ---------------------------------------------------------------------- measurement
def _unit(v: Array) -> Array | None:
    norm = float(np.linalg.norm(v))
    return v / norm if norm > 0 else None


def first_direction(robot: Robot, path: Array | None) -> Array | None:
    """The unit twist of a path's first step after resampling into policy steps (``None``
    for no path or a path of one configuration)."""
    if path is None or len(path) < 2:
        return None
    steps = resample_path(robot, path)
    return _unit(robot.log(steps[0], steps[1]))


def heading(robot: Robot, path: Array | None, at: float = 0.5) -> Array | None:
    """The unit twist from a path's start to its configuration at arc length ``at`` (the
    end if the path is shorter): where the path heads, whatever its first short pieces
    do (``None`` for no path or a path of one configuration)."""
    if path is None or len(path) < 2:
        return None
    steps = resample_path(robot, path)
    arc = np.concatenate([[0.0], np.cumsum(robot.distance(steps[:-1], steps[1:]))])
    j = min(int(np.searchsorted(arc, at)), len(steps) - 1)
    return _unit(robot.log(steps[0], steps[j]))


#: the pairs of expert paths :func:`label_consistency` compares (indices into the paths
#: of :func:`_consistency_paths`)
_PAIRS = {
    "roadmap": (0, 1),
    "lookahead": (2, 3),
    "birrt": (4, 5),
    "roadmap_vs_birrt": (0, 4),
    "lookahead_vs_birrt": (2, 4),
}


def _consistency_paths(
    robot: Robot,
    p: Problem,
    i: int,
    n_nodes: int,
    k: int,
    roadmap_seeds: Sequence[int],
    birrt_seeds: Sequence[int],
    max_nodes: int,
) -> list[Array | None]:
    """The experts' raw paths from a problem's start: the roadmap's, the lookahead's (one
    per roadmap seed) and Bi-RRT's (one per planner seed); ``None`` for a failure."""
    from ..planners.birrt import BiRRT

    plain, ahead = [], []
    for s in roadmap_seeds:
        tree = goal_tree(
            build_roadmap(robot, p.scene, n_nodes, k, np.random.default_rng([int(s), i])), robot, p.scene, p.goal, k
        )
        plain.append(start_path(tree, p.start, k))
        ahead.append(start_path(tree, p.start, k, ahead=True))
    rrt = []
    for s in birrt_seeds:
        res = BiRRT(robot, max_nodes=max_nodes, seed=int(s)).plan(p)
        rrt.append(res.path if res.success else None)
    return plain + ahead + rrt


def _cosines(robot: Robot, paths: list[Array | None], at: float) -> dict[str, tuple[float, float]]:
    """Per pair of :data:`_PAIRS`: the cosines of the first steps and of the headings (nan
    where a path is missing)."""
    first = [first_direction(robot, x) for x in paths]
    head = [heading(robot, x, at) for x in paths]
    cos = lambda u, v: float(u @ v) if u is not None and v is not None else float("nan")
    return {key: (cos(first[a], first[b]), cos(head[a], head[b])) for key, (a, b) in _PAIRS.items()}


def _cosine_summary(cos: list[float]) -> dict[str, float]:
    """Median cosine and the share of pairs pointing apart (cosine below 0)."""
    c = np.asarray([x for x in cos if np.isfinite(x)], np.float64)
    return {
        "pairs": float(len(c)),
        "median_cos": float(np.median(c)) if len(c) else float("nan"),
        "share_below_0": float(np.mean(c < 0)) if len(c) else float("nan"),
    }


def label_consistency(
    scenario: Scenario,
    n_problems: int,
    n_nodes: int = 1000,
    k: int = 10,
    roadmap_seeds: tuple[int, int] = (1, 2),
    birrt_seeds: tuple[int, int] = (1, 2),
    split: str = "val",
    seed: int = 0,
    max_nodes: int = 20000,
    heading_at: float = 0.5,
    progress: bool = False,
) -> dict[str, Any]:
    """How far an expert's move from a problem's start depends on its randomness, over
    the first ``n_problems`` problems of ``split``: the roadmap expert with two roadmaps
    (``roadmap_seeds``; ``roadmap``: every node, ``lookahead``: :func:`lookahead` steps),
    Bi-RRT (``max_nodes``, shortcut) with two planner seeds (``birrt``), and the first
    roadmap against the first Bi-RRT. Per pair, the cosine between the first-step
    directions (:func:`first_direction`) and between the headings (:func:`heading` at arc
    length ``heading_at``). Returns per pair ``{"first": summary, "heading": summary}``
    with ``pairs`` (problems both runs solved), ``median_cos`` and ``share_below_0``, and
    in ``per_problem`` every problem's cosines (nan where a run failed)."""
    robot = scenario.robot
    idx: Any = range(n_problems)
    if progress:
        from ..progress import progress_bar

        idx = progress_bar(idx, desc="label consistency", unit="problem")
    per: dict[str, list[tuple[float, float]]] = {key: [] for key in _PAIRS}
    for i in idx:
        p = scenario.problem(split, i, seed=seed)
        paths = _consistency_paths(robot, p, i, n_nodes, k, roadmap_seeds, birrt_seeds, max_nodes)
        for key, c in _cosines(robot, paths, heading_at).items():
            per[key].append(c)
    out: dict[str, Any] = {
        key: {"first": _cosine_summary([c[0] for c in v]), "heading": _cosine_summary([c[1] for c in v])}
        for key, v in per.items()
    }
    out["problems"] = n_problems
    out["per_problem"] = per
    return out


__all__ = [
    "GoalTree",
    "ProblemPaths",
    "Roadmap",
    "build_roadmap",
    "demo_problem_indices",
    "entry",
    "first_direction",
    "goal_tree",
    "heading",
    "label_consistency",
    "lookahead",
    "nearest_nodes",
    "path_to_goal",
    "problem_paths",
    "roadmap_demos",
    "roadmap_paths",
    "start_path",
]
