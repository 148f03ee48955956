"""The Table 1 script: its stopping rule, records and plot, and its image cells' observations."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def table1():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location(
        "table1_representations", ROOT / "scripts" / "table1_representations.py"
    )
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _curve(vals: list[float]) -> list[dict]:
    return [{"epochs": i + 1, "val_success": v} for i, v in enumerate(vals)]


def test_patience_counts_from_the_first_epoch_reaching_the_best(table1) -> None:  # type: ignore[no-untyped-def]
    spent = table1.patience_spent
    curve = _curve([0.5, 0.7, 0.6, 0.7, 0.65, 0.6])  # best 0.7 first at epoch 2; 4 epochs since
    assert not spent(curve, 5)
    assert spent(curve, 4)
    assert spent(curve, 3)
    assert not spent(curve, 0)  # 0: the rule is off
    assert not spent([], 3)
    # a new best restarts the count
    assert not spent(_curve([0.5, 0.7, 0.6, 0.6, 0.6, 0.8]), 3)
    # every fifth epoch validated: the count is in epochs, not validations
    assert spent(
        [{"epochs": 5, "val_success": 0.8}, {"epochs": 10, "val_success": 0.7}, {"epochs": 15, "val_success": 0.7}], 10
    )
    assert not spent([{"epochs": 5, "val_success": 0.8}, {"epochs": 10, "val_success": 0.7}], 10)


@pytest.mark.parametrize("curve", [[], [{"epochs": 1, "val_success": 0.5, "wall_time_s": 1.0}]])
def test_an_interrupted_cell_keeps_a_record_only_after_a_validation(table1, tmp_path, monkeypatch, curve) -> None:  # type: ignore[no-untyped-def]
    monkeypatch.setattr(table1, "run_bc", lambda cell, args: {"curve": list(curve), "interrupted": True})
    argv = ["table1", "--method", "bc", "--cells", "surface:pointnet", "--out", str(tmp_path), "--runs", str(tmp_path)]
    monkeypatch.setattr("sys.argv", argv)
    table1.main()
    record = tmp_path / "surface_pointnet_bc.json"
    assert record.exists() == bool(curve)
    if curve:
        assert json.loads(record.read_text())["curve"] == curve


def test_the_plot_marks_the_papers_result_of_each_drawn_cell(table1, tmp_path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curve = [{"env_steps": 20000, "val_success": 0.3}, {"env_steps": 40000, "val_success": 0.4}]
    (tmp_path / "interior_mlp_rl.json").write_text(json.dumps({"curve": curve}))
    figures = []
    monkeypatch.setattr(plt.Figure, "savefig", lambda self, *a, **k: figures.append(self))
    table1.plot(tmp_path, str(tmp_path / "curves.png"))
    rl = figures[0].axes[1]
    markers = [line for line in rl.lines if line.get_marker() == "<" and len(line.get_ydata()) == 1]
    assert [float(m.get_ydata()[0]) for m in markers] == [table1.PAPER["interior:mlp"][1]]
    assert not [line for line in figures[0].axes[0].lines if line.get_marker() == "<" and len(line.get_ydata())]


def test_the_image_cell_rasterises_its_demonstrations_once(table1, tmp_path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """A BC cell validates after every epoch, each a separate fit; the occupancy images do
    not vary, so they are observed once for all the epochs (point subsets are drawn anew)."""
    from pointplan.learning import bc as bc_mod

    real = bc_mod.observe_demos
    calls: list[str | None] = []

    def counted(demos, robot, env, rng, *a, **k):  # type: ignore[no-untyped-def]
        calls.append(env.observation)
        return real(demos, robot, env, rng, *a, **k)

    monkeypatch.setattr(bc_mod, "observe_demos", counted)
    monkeypatch.setattr(table1, "validate", lambda *a, **k: 0.5)
    monkeypatch.setattr(table1, "test_eval", lambda *a, **k: {"success_rate": 0.5})
    for cell, once in (("image:cnn", True), ("surface:pointnet", False)):
        calls.clear()
        argv = ["table1", "--method", "bc", "--cells", cell, "--bc-problems", "3", "--bc-epochs", "3"]
        argv += ["--bc-eval-every", "1", "--width", "16", "--out", str(tmp_path), "--runs", str(tmp_path), "--quiet"]
        monkeypatch.setattr("sys.argv", argv)
        table1.main()
        name = cell.split(":")[0]
        assert calls == ([name] if once else [name] * 3), cell
        assert len(json.loads((tmp_path / f"{cell.replace(':', '_')}_bc.json").read_text())["curve"]) == 3
