"""The Table 1 script's stopping rule for its behavioural-cloning cells."""

from __future__ import annotations

import importlib.util
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
