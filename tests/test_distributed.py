"""Ray workers give the serial results: evaluation, demonstrations, a worker that dies.

One local Ray instance (2 CPUs) serves the whole module; it is skipped without Ray."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from pointplan.cli import main
from pointplan.evaluation import evaluate
from pointplan.planners import BiRRT
from pointplan.scenes.scenarios import make_scenario

# Ray starts worker processes; the module's tests share one local cluster, on one test worker
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("ray")]

ray = pytest.importorskip("ray")

N = 10


@pytest.fixture(scope="module")
def ray_local() -> object:
    from pointplan.distributed import connect

    started = not ray.is_initialized()
    connect(workers=2)
    # classes of this module travel by value (the workers cannot import tests/)
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    yield ray
    ray.cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
    if started:
        ray.shutdown()


def _untimed(d: dict) -> dict:
    return {k: _untimed(v) if isinstance(v, dict) else v for k, v in d.items() if not k.startswith("time")}


def test_cli_eval_and_plan_on_workers_equal_serial_runs(ray_local: object, tmp_path: Path) -> None:
    common = ["--env", "narrow2d", "--planner", "birrt", "--episodes", str(N), "--quiet"]
    assert main(["eval", *common, "--json", str(tmp_path / "s.json")]) == 0
    assert main(["eval", *common, "--workers", "2", "--json", str(tmp_path / "p.json")]) == 0
    serial, parallel = (json.loads((tmp_path / f).read_text()) for f in ("s.json", "p.json"))
    assert _untimed(serial) == _untimed(parallel)
    assert serial["success_rate"] == 1.0
    # plan writes every path: the same ones
    assert main(["plan", *common, "--json", str(tmp_path / "ps.json")]) == 0
    assert main(["plan", *common, "--workers", "2", "--json", str(tmp_path / "pp.json")]) == 0
    ps, pp = (json.loads((tmp_path / f).read_text()) for f in ("ps.json", "pp.json"))
    assert ps["problems"] == pp["problems"] and _untimed(ps["metrics"]) == _untimed(pp["metrics"])


def test_evaluate_on_workers_keeps_the_call_numbering(ray_local: object) -> None:
    scenario = make_scenario("narrow2d")
    problems = scenario.problems("test", 6, seed=1)
    a, b = BiRRT(scenario.robot, seed=5), BiRRT(scenario.robot, seed=5)
    a.plan(problems[0]), b.plan(problems[0])  # both have made one call already
    serial = evaluate(a, problems, scenario.robot, progress=False)
    parallel = evaluate(b, problems, scenario.robot, progress=False, workers=2)
    assert b.calls == a.calls == 7
    for x, y in zip(serial.records, parallel.records, strict=True):
        assert (x.tag, x.success, x.nodes, x.collision_checks) == (y.tag, y.success, y.nodes, y.collision_checks)
        assert np.array_equal(x.path, y.path)
    assert _untimed(serial.metrics()) == _untimed(parallel.metrics())


class _DiesOnce(BiRRT):
    """Bi-RRT whose worker process dies the first time it meets problem 3."""

    marker = ""

    def plan(self, problem):  # type: ignore[no-untyped-def]
        if self.calls == 3 and not os.path.exists(self.marker):
            Path(self.marker).write_text("died")
            os._exit(1)
        return super().plan(problem)


def test_a_worker_that_dies_is_replaced_and_its_problems_rerun(ray_local: object, tmp_path: Path) -> None:
    scenario = make_scenario("narrow2d")
    problems = scenario.problems("test", 6)
    dying = _DiesOnce(scenario.robot)
    dying.marker = str(tmp_path / "died")
    parallel = evaluate(dying, problems, scenario.robot, progress=False, workers=2)
    serial = evaluate(BiRRT(scenario.robot), problems, scenario.robot, progress=False)
    assert (tmp_path / "died").exists()
    assert [r.nodes for r in parallel.records] == [r.nodes for r in serial.records]
    assert all(np.array_equal(x.path, y.path) for x, y in zip(serial.records, parallel.records))


def test_ctrl_c_keeps_what_finished(ray_local: object) -> None:
    from pointplan.distributed import Interrupted, map_ordered

    def stop(pos: int, value: int) -> None:
        raise KeyboardInterrupt

    with pytest.raises(Interrupted) as e:
        map_ordered(abs, list(range(-40, 0)), workers=2, chunksize=1, on_result=stop)
    assert 1 <= len(e.value.results) < 40 and all(v == abs(-40 + i) for i, v in e.value.results.items())


def test_demonstrations_on_workers_equal_serial_ones(ray_local: object) -> None:
    from pointplan.distributed import RayPool
    from pointplan.learning.bc import demo_pool, generate_demos

    assert isinstance(demo_pool(2), RayPool)
    scenario = make_scenario("narrow2d")
    serial = generate_demos(scenario, 8, seed=2, progress=False)
    parallel = generate_demos(scenario, 8, seed=2, progress=False, workers=2)
    assert [k for k, _ in serial.paths] == [k for k, _ in parallel.paths]
    for a, b in ((serial.q, parallel.q), (serial.action, parallel.action), (serial.goal, parallel.goal)):
        assert np.array_equal(a, b)


def test_training_with_rollout_workers(ray_local: object, tmp_path: Path) -> None:
    from pointplan.learning.train import TrainConfig, train
    from pointplan.models.actor_critic import NetConfig
    from pointplan.models.encoders import EncoderConfig

    net = NetConfig(
        EncoderConfig(width=16, layers=2), head_width=16, head_layers=2, critic_action="pooled", shared_encoder=True
    )
    cfg = TrainConfig(
        env="empty2d",
        total_steps=600,
        num_envs=4,
        warmup_steps=200,
        eval_every=300,
        eval_episodes=10,
        updates_per_step=0.05,
        net=net,
    )
    res = train(cfg, tmp_path / "run", progress=False, workers=2, sync_every=2)
    assert res.steps >= 600 and not res.interrupted
    assert (tmp_path / "run" / "last.pt").exists() and len(res.history) == 2
    # the learner takes updates_per_step updates per transition it receives (once the
    # buffer holds a batch, as in the serial trainer)
    assert 0 < res.history[-1]["updates"] <= 0.05 * (res.steps - 200) + 1


def test_without_ray_workers_say_how_to_install_it(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import pointplan.distributed as dist

    monkeypatch.setattr(dist, "ray_available", lambda: False)
    assert main(["eval", "--episodes", "2", "--workers", "2", "--quiet"]) == 2
    assert "pip install 'pointplan[ray]'" in capsys.readouterr().err
    assert main(["eval", "--episodes", "2", "--quiet"]) == 0  # one process: as before


def test_a_rollout_worker_that_dies_is_replaced(ray_local: object) -> None:
    from pointplan.distributed.rollouts import RayRollouts
    from pointplan.learning.sac import SAC
    from pointplan.learning.train import TrainConfig
    from pointplan.models.actor_critic import NetConfig
    from pointplan.models.encoders import EncoderConfig

    net = NetConfig(
        EncoderConfig(width=8, layers=1), head_width=8, head_layers=1, critic_action="pooled", shared_encoder=True
    )
    cfg = TrainConfig(env="empty2d", num_envs=2, net=net)
    rollouts = RayRollouts(cfg, workers=1, address=None, steps_per_call=60)
    try:
        from pointplan.envs.core import EnvConfig

        scenario = make_scenario("empty2d")
        agent = SAC(
            scenario.robot,
            EnvConfig(observation=cfg.observation, n_points=cfg.n_points),
            (cfg.n_points, 4),
            net,
            cfg.sac,
        )
        rollouts.sync(agent.actor, 0)
        episodes, success, steps = rollouts.next_chunk(random_actions=False)
        # 2 environments, 60 steps each: every one ended an episode (the horizon is 50)
        assert (
            steps == 120 and len(episodes) >= 2 and all(len(e) == 8 and len(e[0]) == len(e[2]) <= 50 for e in episodes)
        )
        ray.kill(rollouts.workers[0])  # (its next chunk was already asked for)
        total = sum(rollouts.next_chunk(random_actions=True)[2] for _ in range(2))
        assert total == 240 and rollouts.replaced == 1
    finally:
        rollouts.close()
