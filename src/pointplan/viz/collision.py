"""Where the collision classifiers are wrong (:mod:`pointplan.learning.collision`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..learning.collision import grid_predictions, load_classifier
from ..scenes.scenarios import make_scenario
from .plot2d import _draw_obstacles, _new_figure

#: panel titles of the four representations
TITLES = {
    "image": "(a) 64x64 image, CNN",
    "interior": "(b) interior points, PointNet",
    "surface": "(c) boundary points, PointNet",
    "surface-normals": "(d) boundary points + normals, PointNet",
}


def render_collision_errors(
    run_dir: str | Path,
    output: str | Path,
    observations: list[str],
    scene_index: int = 0,
    action: tuple[float, float] = (0.71, 0.71),
    resolution: int = 120,
    dpi: float = 110,
) -> dict[str, Any]:
    """Top row, one panel per classifier in ``run_dir``: test workspace ``scene_index``, a
    grid of free starts all taking ``action``, coloured by the exact label and marked
    where the classifier is wrong. Bottom: test accuracy against the end's clearance.
    Returns the grid accuracies."""
    run_dir = Path(run_dir)
    n = len(observations)
    fig = _new_figure((3.3 * n, 6.6), dpi)
    gs = fig.add_gridspec(2, n, height_ratios=[1.0, 0.75])
    out: dict[str, Any] = {}
    band = 0.02
    curves = []
    for j, name in enumerate(observations):
        model, cfg = load_classifier(run_dir / f"{name}.pt")
        band = cfg.band
        scene = make_scenario(cfg.env).scene("test", scene_index)
        g = grid_predictions(model, cfg, scene, np.array(action), resolution)
        ax = fig.add_subplot(gs[0, j])
        _draw_obstacles(ax, scene)
        q = np.asarray(g["q"], np.float64)
        truth, pred = np.asarray(g["truth"], bool), np.asarray(g["pred"], bool)
        wrong = truth != pred
        size = 6.0 * (100 / resolution) ** 2
        for mask, style in (
            (~wrong & truth, {"s": size, "c": "#f4a582", "lw": 0, "label": "collides (right)"}),
            (~wrong & ~truth, {"s": size, "c": "#d1e5f0", "lw": 0, "label": "free (right)"}),
            (wrong & truth, {"s": 3 * size, "c": "#b2182b", "marker": "x", "lw": 0.8, "label": "collides, said free"}),
            (wrong & ~truth, {"s": 3 * size, "c": "#2166ac", "marker": "+", "lw": 0.8, "label": "free, said collides"}),
        ):
            ax.scatter(q[mask, 0], q[mask, 1], **style)  # type: ignore[arg-type]
        ax.set_xlim(scene.low[0], scene.high[0])
        ax.set_ylim(scene.low[1], scene.high[1])
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        grid_acc = float(1.0 - wrong.mean())
        ax.set_title(
            f"{TITLES.get(name, name)}\ngrid: {int(wrong.sum())} wrong of {len(q)} ({100 * grid_acc:.1f}% right)",
            fontsize=8,
        )
        if j == 0:
            ax.legend(loc="lower left", fontsize=6, framealpha=0.9, markerscale=1.5)
        out[name] = {"grid_accuracy": grid_acc, "grid_wrong": int(wrong.sum()), "grid_points": int(len(q))}
        test_file = run_dir / f"{name}_test.npz"
        if test_file.exists():
            with np.load(test_file) as f:
                curves.append((name, f["end_clearance"], f["pred"]))
    ax = fig.add_subplot(gs[1, :])
    edges = np.linspace(-0.07, 0.07, 29)  # the outer bins take everything beyond
    for name, c, pred in curves:
        ok = pred == (c <= 0.0)
        which = np.clip(np.digitize(c, edges) - 1, 0, len(edges) - 2)
        acc = np.array([ok[which == k].mean() if np.any(which == k) else np.nan for k in range(len(edges) - 1)])
        mids = (edges[:-1] + edges[1:]) / 2
        ax.plot(mids, 100 * acc, marker="o", ms=3, label=TITLES.get(name, name))
    ax.axvline(0.0, color="k", lw=0.8)
    ax.axvspan(-band, band, color="0.9", zorder=0, label=f"near the boundary (|c| < {band})")
    ax.set_xlabel("clearance c of the disc at the end of the action (negative: overlaps an obstacle)", fontsize=8)
    ax.set_ylabel("test accuracy (%)", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7, loc="lower right")
    ax.grid(alpha=0.3)
    a = np.asarray(action, float)
    fig.suptitle(
        f"2D-Narrow collision classification: test workspace {scene_index}, every free start taking action {a.tolist()} (step {0.07 * np.linalg.norm(a):.3f})",
        fontsize=9,
    )
    Path(output).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(output)
    return out
