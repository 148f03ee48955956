"""Can the S-shape see the slot? A perception probe for Slot.

Two measurements, on poses of the S-shape on the start side of Slot's wall (its frame
between ``--x-min`` and ``--x-max``, random orientation, free):

1. **Rays through the opening** (exact, no learning): how many of the ``local``
   observer's rays cross the wall's mid-plane inside the opening within the observer's
   range. A ray that does sees no hit there, so the opening shows in the observation only
   as such missing hits (and as hits on the opening's inner faces).
2. **Supervised probes**: a PointNet (the policy's encoder, smaller) trained to predict
   the opening's centre in the robot frame from the observation alone. The same probe is
   trained on the observations of the same poses in the same wall with the opening
   closed (``solid``): what it learns there comes from where the robot is, not from the
   opening. A probe on the real observations that does no better than on the closed
   wall has not found the opening in the points. For scale: the error of a predictor
   that knows the robot's pose exactly but not where the opening is (it answers the
   wall's centre, the mean of the openings' centres), and the probe's error at
   predicting the wall's centre itself.

3. **Which way the opening runs** (``--axis``): the same probe trained to point along the
   opening's long side in the robot frame (either sign), scored by the angle to it; the
   closed-wall control again says what can be guessed without the opening (in the wall's
   plane at random: 45 degrees on average).

``global-near`` (``--observations global-near``, this script only) is ``global`` drawn
from a pool 4x denser and only within ``--near-radius`` of the robot's frame: the same
256 points spent on the wall near the robot, where the opening's inner faces show.

Training workspaces and validation workspaces are disjoint (``train`` and ``val``
splits). Output: a JSON summary (``--json``) and a table on stdout.

    python experiments/slot_perception_probe.py --json docs/data/slot/perception_probe.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch
from torch import nn

from pointplan.geometry.shapes import Box
from pointplan.models.encoders import PointNetEncoder
from pointplan.observers import make_observer
from pointplan.scenes.scenarios import make_scenario
from pointplan.scenes.scene import Scene


def slot_geometry(scene) -> tuple[np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    """Centre and full extents (y, z) of the opening."""
    s = scene.__dict__["slot"]
    ext = np.zeros(3)
    ext[s["long_axis"]] = 0.4
    ext[3 - s["long_axis"]] = s["width"]
    return np.asarray(s["center"], float), ext


def closed(scene: Scene) -> Scene:
    """The same wall with the opening filled."""
    ext = scene.high - scene.low
    wall = Box(np.array([0.0, 0.0, 0.0]), np.array([0.04, ext[1], ext[2]]))
    return Scene([wall], scene.low, scene.high)


def rays_through_opening(observer, q: np.ndarray, center: np.ndarray, ext: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    """For each pose, the number of the observer's rays that cross x = 0 inside the
    opening within the observer's range."""
    rot = observer.robot.rotations(q)
    pos = observer.robot.positions(q)
    o = np.einsum("eij,rj->eri", rot, observer.body_origins) + pos[:, None, :]
    d = np.einsum("eij,rj->eri", rot, observer.body_dirs)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -o[..., 0] / d[..., 0]
    hit = o + t[..., None] * d
    inside = (np.abs(hit[..., 1] - center[1]) < ext[1] / 2) & (np.abs(hit[..., 2] - center[2]) < ext[2] / 2)
    ok = (t > 0) & (t <= observer.max_range) & inside & np.isfinite(t)
    return ok.sum(1)


class NearGlobal:
    """``global``'s surface points from a pool of ``pool_size``, ``n_points`` of those within
    ``radius`` of the robot's frame (duplicates where fewer; zeros where none), in the robot
    frame with their normals."""

    def __init__(self, robot, n_points: int = 256, pool_size: int = 16384, radius: float = 0.6) -> None:  # type: ignore[no-untyped-def]
        self.robot, self.n_points, self.radius = robot, n_points, radius
        self.inner = make_observer("global", robot, n_points=n_points, pool_size=pool_size)
        self.scenes: list[Scene] = []

    def bind(self, scenes: list[Scene]) -> None:
        self.scenes = list(scenes)

    def observe(self, q: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        out = np.zeros((len(q), self.n_points, 6), np.float32)
        pos = self.robot.positions(q)
        for e, scene in enumerate(self.scenes):
            p, n = self.inner.points_of(scene)
            idx = np.flatnonzero(np.linalg.norm(p - pos[e], axis=1) < self.radius)
            if len(idx) == 0:
                continue
            pick = rng.choice(idx, self.n_points, replace=len(idx) < self.n_points)
            pb, nb = self.robot.to_body_frame(q[e], p[pick], n[pick])
            out[e] = np.concatenate([pb, nb], -1)
        return out


def collect(split: str, n_scenes: int, per_scene: int, observation: str, args: argparse.Namespace, seed: int) -> dict[str, np.ndarray]:
    scen = make_scenario("slotmoving", "sshape")
    robot = scen.robot
    if observation == "global-near":
        observer = NearGlobal(robot, radius=args.near_radius)
    else:
        observer = make_observer(observation, robot, **json.loads(args.observer_args))
    rng = np.random.default_rng(seed)
    obs, obs_solid, target, base, width, xs, through, axis = [], [], [], [], [], [], [], []
    low, high = scen.bounds
    lo, hi = low.copy(), high.copy()
    lo[0], hi[0] = args.x_min, args.x_max
    for i in range(n_scenes):
        scene = scen.scene(split, i)
        center, ext = slot_geometry(scene)
        q = robot.sample_free(scene.world, rng, per_scene, lo, hi)
        observer.bind([scene] * len(q))
        o = observer.observe(q, rng)
        observer.bind([closed(scene)] * len(q))
        obs_solid.append(observer.observe(q, rng))
        c_body, _ = robot.to_body_frame(q, np.repeat(center[None, None], len(q), 0))
        w_body, _ = robot.to_body_frame(q, np.zeros((len(q), 1, 3)))  # the wall's centre
        long = np.zeros(3)
        long[scene.__dict__["slot"]["long_axis"]] = 1.0
        axis.append(np.einsum("eji,j->ei", robot.rotations(q), long))  # R^T e: the long side in the robot frame
        obs.append(o)
        target.append(c_body[:, 0])
        base.append(w_body[:, 0])
        width.append(np.full(len(q), scene.__dict__["slot"]["width"] / 0.036))
        xs.append(q[:, 0])
        if observation == "local":
            through.append(rays_through_opening(observer, q, center, ext))
    out = {
        "obs": np.concatenate(obs).astype(np.float32),
        "obs_solid": np.concatenate(obs_solid).astype(np.float32),
        "target": np.concatenate(target).astype(np.float32),
        "base": np.concatenate(base).astype(np.float32),
        "width_bars": np.concatenate(width),
        "x": np.concatenate(xs),
        "axis": np.concatenate(axis).astype(np.float32),
    }
    if through:
        out["through"] = np.concatenate(through)
    return out


class Probe(nn.Module):
    def __init__(self, features: int, width: int) -> None:
        super().__init__()
        self.enc = PointNetEncoder(features, width, 3)
        self.head = nn.Sequential(nn.Linear(width, width), nn.ELU(), nn.Linear(width, 3))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.enc(x))


def train_probe(tr: dict[str, np.ndarray], va: dict[str, np.ndarray], args: argparse.Namespace, obs_key: str, target_key: str) -> np.ndarray:
    """The probe's predictions of ``target_key`` on the validation observations; for
    ``axis``, a direction either way round (the loss takes the nearer sign)."""
    torch.manual_seed(0)
    scale = 0.4  # points and targets in units of 0.4, as the local observer's points are
    unsigned = target_key == "axis"
    xt = torch.from_numpy(tr[obs_key]).clone()
    xt[..., :3] /= scale
    yt = torch.from_numpy(tr[target_key]) / (1.0 if unsigned else scale)
    xv = torch.from_numpy(va[obs_key]).clone()
    xv[..., :3] /= scale
    model = Probe(xt.shape[-1], args.width)
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, args.epochs)
    n = len(xt)
    for epoch in range(args.epochs):
        perm = torch.randperm(n)
        model.train()
        tot = 0.0
        for b in range(0, n, 256):
            idx = perm[b : b + 256]
            pred = model(xt[idx])
            err = ((pred - yt[idx]) ** 2).sum(-1)
            if unsigned:
                err = torch.minimum(err, ((pred + yt[idx]) ** 2).sum(-1))
            loss = err.mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
            tot += loss.item() * len(idx)
        sched.step()
        if (epoch + 1) % 10 == 0:
            print(f"  epoch {epoch + 1}: train rms {np.sqrt(tot / n) * scale:.4f}", flush=True)
    model.eval()
    with torch.no_grad():
        pred = torch.cat([model(xv[b : b + 1024]) for b in range(0, len(xv), 1024)]).numpy()
    return pred if unsigned else pred * scale


def axis_degrees(pred: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Angles (degrees) between predicted and true directions, either sign."""
    c = np.abs(np.sum(pred * axis, -1)) / np.maximum(np.linalg.norm(pred, axis=-1), 1e-9)
    return np.degrees(np.arccos(np.clip(c, 0.0, 1.0)))


def rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(a**2, -1)))) if len(a) else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--train-scenes", type=int, default=2000)
    ap.add_argument("--val-scenes", type=int, default=300)
    ap.add_argument("--per-scene", type=int, default=8)
    ap.add_argument("--x-min", type=float, default=-0.55, help="the frame's x range of the poses (the wall is at x = 0)")
    ap.add_argument("--x-max", type=float, default=-0.1)
    ap.add_argument("--observations", nargs="+", default=["local", "global"])
    ap.add_argument("--observer-args", default="{}", help="keyword arguments of the observers, as JSON (e.g. '{\"max_range\": 2.0}')")
    ap.add_argument("--near-radius", type=float, default=0.6, help="global-near: points within this distance of the robot's frame")
    ap.add_argument("--axis", action="store_true", help="also probe which way the opening's long side runs")
    ap.add_argument("--epochs", type=int, default=40)
    ap.add_argument("--width", type=int, default=128)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--json")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    summary: dict[str, object] = {"args": vars(args)}
    bins = [(2, 4), (4, 6), (6, 8.01)]
    for obs_name in args.observations:
        t0 = time.perf_counter()
        tr = collect("train", args.train_scenes, args.per_scene, obs_name, args, 1)
        va = collect("val", args.val_scenes, args.per_scene, obs_name, args, 2)
        print(f"{obs_name}: {len(tr['obs'])} training and {len(va['obs'])} validation observations ({time.perf_counter() - t0:.0f} s)", flush=True)
        errs = {}
        for name, obs_key, target_key in (("opening", "obs", "target"), ("closed", "obs_solid", "target"), ("wall_centre", "obs", "base")):
            print(f" probe {name}", flush=True)
            errs[name] = train_probe(tr, va, args, obs_key, target_key) - va[target_key]
        errs["pose_known"] = va["base"] - va["target"]
        axis_deg = {}
        if args.axis:
            for name, obs_key in (("opening", "obs"), ("closed", "obs_solid")):
                print(f" probe axis, {name}", flush=True)
                axis_deg[name] = axis_degrees(train_probe(tr, va, args, obs_key, "axis"), va["axis"])
        near = va["x"] > (args.x_min + args.x_max) / 2
        row: dict[str, object] = {"rms": {k: rms(e) for k, e in errs.items()}, "by_width": {}}
        for lo_b, hi_b in bins:
            m = (va["width_bars"] >= lo_b) & (va["width_bars"] < hi_b)
            row["by_width"][f"{lo_b}-{int(hi_b)}"] = {"n": int(m.sum()), **{k: rms(e[m]) for k, e in errs.items()}}  # type: ignore[index]
        if axis_deg:
            row["axis_degrees_mean"] = {k: float(v.mean()) for k, v in axis_deg.items()}
            row["axis_within_30_degrees"] = {k: float(np.mean(v < 30)) for k, v in axis_deg.items()}
            row["axis_degrees_by_width"] = {
                f"{a}-{int(b)}": {k: float(v[(va["width_bars"] >= a) & (va["width_bars"] < b)].mean()) for k, v in axis_deg.items()} for a, b in bins
            }
        row["near_half"] = {k: rms(e[near]) for k, e in errs.items()}
        row["far_half"] = {k: rms(e[~near]) for k, e in errs.items()}
        if "through" in va:
            th = va["through"]
            row["rays_through_opening"] = {
                "mean": float(th.mean()),
                "share_zero": float(np.mean(th == 0)),
                "by_width_share_zero": {f"{a}-{int(b)}": float(np.mean(th[(va["width_bars"] >= a) & (va["width_bars"] < b)] == 0)) for a, b in bins},
                "near_half_share_zero": float(np.mean(th[near] == 0)),
                "far_half_share_zero": float(np.mean(th[~near] == 0)),
            }
        summary[obs_name] = row
        print(json.dumps({obs_name: row}, indent=1), flush=True)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(summary, indent=1) + "\n")


if __name__ == "__main__":
    main()
