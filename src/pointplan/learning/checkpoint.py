"""Self-describing checkpoints.

A checkpoint is a ``torch.save`` dict holding the package version, the environment, robot
and observation it was trained on, the network and training configuration, the actor's
weights and, for resuming, the whole trainer state. ``load_checkpoint`` checks the format;
``check_compatible`` refuses an environment whose robot or observation differs.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import torch

FORMAT = "pointplan-checkpoint"
VERSION = 1


class CheckpointError(ValueError):
    """A checkpoint that cannot be used here."""


def to_dict(obj: Any) -> Any:
    """Dataclasses to plain dicts (recursively), for saving."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_dict(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, (list, tuple)):
        return [to_dict(x) for x in obj]
    return obj


def save_checkpoint(path: str | Path, payload: dict[str, Any]) -> None:
    from .. import __version__

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = {"format": FORMAT, "version": VERSION, "package_version": __version__}
    data.update(payload)
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(data, tmp)
    tmp.replace(path)


def load_checkpoint(path: str | Path, device: str = "cpu") -> dict[str, Any]:
    path = Path(path)
    if not path.exists():
        raise CheckpointError(f"{path}: no such checkpoint")
    try:
        data = torch.load(path, map_location=device, weights_only=False)
    except Exception as e:  # torch raises many kinds on a corrupt file
        raise CheckpointError(f"{path}: not a readable checkpoint ({type(e).__name__}: {e})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise CheckpointError(f"{path}: not a pointplan checkpoint")
    if int(data.get("version", -1)) > VERSION:
        raise CheckpointError(f"{path}: checkpoint version {data['version']} is newer than this pointplan understands ({VERSION})")
    return data


def check_compatible(data: dict[str, Any], robot: str, observation: str, obs_shape: tuple[int, ...], where: str = "checkpoint") -> None:
    """Refuse a checkpoint trained for another robot or observation."""
    if data["robot"] != robot:
        raise CheckpointError(f"{where} was trained for robot {data['robot']!r}, not {robot!r}")
    if data["observation"] != observation:
        raise CheckpointError(f"{where} was trained on {data['observation']!r} observations, this env gives {observation!r}")
    if tuple(data["obs_shape"]) != tuple(obs_shape):
        raise CheckpointError(f"{where} expects observations of shape {tuple(data['obs_shape'])}, this env gives {tuple(obs_shape)}")
