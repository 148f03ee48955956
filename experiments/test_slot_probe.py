"""experiments/slot_perception_probe.py: its count of the rays that cross Slot's opening,
checked against the ray caster (which knows nothing of the opening, only the boxes).
Run by hand (``python -m pytest experiments/test_slot_probe.py``); CI does not."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

from pointplan.geometry.raycast import cast_rays
from pointplan.observers import make_observer
from pointplan.scenes.scenarios import make_scenario

SCRIPT = Path(__file__).resolve().parent / "slot_perception_probe.py"


def _probe_module():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location("slot_perception_probe", SCRIPT)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_rays_through_the_opening_agree_with_the_ray_caster() -> None:
    probe = _probe_module()
    scen = make_scenario("slotmoving", "sshape")
    robot = scen.robot
    observer = make_observer("local", robot, max_range=2.0)
    rng = np.random.default_rng(3)
    low, high = scen.bounds
    low, high = low.copy(), high.copy()
    high[0] = -0.35  # the whole body (reach 0.29) in front of the wall
    n_through = n_checked = n_passed = 0
    for i in range(6):
        scene = scen.scene("train", i)
        center, ext = probe.slot_geometry(scene)
        q = robot.sample_free(scene.world, rng, 8, low, high)
        counted = probe.rays_through_opening(observer, q, center, ext)
        # the same rays, one by one: where they cross x = 0 and what the caster hits first
        rot, pos = robot.rotations(q), robot.positions(q)
        o = np.einsum("eij,rj->eri", rot, observer.body_origins) + pos[:, None, :]
        d = np.einsum("eij,rj->eri", rot, observer.body_dirs)
        observer.bind([scene] * len(q))
        hits = cast_rays(observer.stacked_world(None), o, d, 10.0)
        t_plane = -o[..., 0] / d[..., 0]
        crossing = (d[..., 0] > 0) & (t_plane <= observer.max_range)
        p = o + t_plane[..., None] * d
        in_opening = (np.abs(p[..., 1] - center[1]) < ext[1] / 2) & (np.abs(p[..., 2] - center[2]) < ext[2] / 2)
        assert np.array_equal(counted, (crossing & in_opening).sum(1))
        # a ray that crosses the mid-plane outside the opening but inside the workspace is
        # inside the wall there, so the caster must have hit something by then
        in_workspace = np.all(np.abs(p[..., 1:]) < 0.6, axis=-1)
        outside = crossing & ~in_opening & in_workspace
        assert np.all(hits.hit[outside]) and np.all(hits.distance[outside] <= t_plane[outside] + 1e-6)
        # a ray counted through the opening passes the mid-plane unless it grazes an inner
        # face of the opening (the wall is 0.04 thick)
        through = crossing & in_opening
        n_through += int(through.sum())
        n_passed += int(np.sum(~hits.hit[through] | (hits.distance[through] > t_plane[through])))
        n_checked += int(crossing.sum())
    assert n_checked > 500 and n_through >= 10
    assert n_passed >= 0.8 * n_through
