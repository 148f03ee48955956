"""Calls per second of the S-shape's ``integrate`` and ``log``: compiled quaternion kernels
versus the numpy path through 4x4 matrices.

    python benchmarks/bench_se3.py            # N = 1, 16, 256 configurations per call
    python benchmarks/bench_se3.py --quick    # shorter timings
    python benchmarks/bench_se3.py --birrt    # also S-shape Bi-RRT in Slot, both paths

Planners call these with a few configurations at a time (Bi-RRT: one nearest-node query
or one march per call), where numpy's per-call overhead dominates. The inputs are shaped
like the planner's: ``integrate(q0[None], v)`` (one start, N steps) and
``log(nodes, q[None])`` (N nodes against one sample).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

from pointplan.robots import SShape
from pointplan.robots.sshape import NumpySShape


def calls_per_second(fn: Callable[[], object], budget: float) -> float:
    """Repeat ``fn`` in growing batches until ``budget`` seconds have been spent."""
    fn()  # warm-up (compilation, caches)
    calls, spent, batch = 0, 0.0, 1
    while spent < budget:
        t = time.perf_counter()
        for _ in range(batch):
            fn()
        spent += time.perf_counter() - t
        calls += batch
        batch *= 2
    return calls / spent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="0.1 s per measurement instead of 0.5 s")
    parser.add_argument(
        "--birrt", action="store_true", help="also time Bi-RRT (3,000 nodes) on Slot test problems 1-3 with each path"
    )
    args = parser.parse_args()
    budget = 0.1 if args.quick else 0.5
    robot, reference = SShape(), NumpySShape()
    rng = np.random.default_rng(0)
    print(f"{'op':<10}{'N':>5}{'compiled /s':>14}{'numpy /s':>12}{'ratio':>8}")
    for n in (1, 16, 256):
        nodes = np.concatenate([rng.uniform(-1, 1, (n, 3)), robot.sample_orientation(rng, n)], -1)
        q = nodes[0]
        v = rng.normal(size=(n, 6)) * robot.action_scale
        cases: dict[str, Callable[[SShape], object]] = {
            "integrate": lambda r, q=q, v=v: r.integrate(q[None], v),
            "log": lambda r, q=q, nodes=nodes: r.log(nodes, q[None]),
        }
        for op, fn in cases.items():
            compiled = calls_per_second(lambda fn=fn: fn(robot), budget)
            plain = calls_per_second(lambda fn=fn: fn(reference), budget)
            print(f"{op:<10}{n:>5}{compiled:>14,.0f}{plain:>12,.0f}{compiled / plain:>7.1f}x")
    if args.birrt:
        birrt_speed()


def birrt_speed() -> None:
    """Bi-RRT with the S-shape in Slot on each path: time, and whether the results match."""
    from pointplan.planners.birrt import BiRRT
    from pointplan.scenes.scenarios import make_scenario

    scenario = make_scenario("slotmoving", robot="sshape")
    print(f"\n{'Slot test problem':<18}{'numpy s':>9}{'compiled s':>12}{'ratio':>8}{'nodes':>7}  same result")
    for i in (1, 2, 3):
        problem = scenario.problem("test", i)
        runs = {}
        for compiled in (False, True):
            robot = SShape() if compiled else NumpySShape()
            t = time.perf_counter()
            res = BiRRT(robot, max_nodes=3000, seed=1).plan(problem)
            runs[compiled] = (time.perf_counter() - t, res)
        (t_np, a), (t_c, b) = runs[False], runs[True]
        same = (a.success, a.nodes, a.collision_checks, len(a.path)) == (
            b.success,
            b.nodes,
            b.collision_checks,
            len(b.path),
        ) and np.allclose(a.path, b.path, atol=1e-9)
        print(f"{i:<18}{t_np:>9.2f}{t_c:>12.2f}{t_np / t_c:>7.2f}x{b.nodes:>7}  {same}")


if __name__ == "__main__":
    main()
