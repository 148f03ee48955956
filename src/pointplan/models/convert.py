"""Converting an older checkpoint that holds pickled objects into a data-only one.

This is the only code in pointplan that fully unpickles a file (``torch.load`` with
``weights_only=False``), which runs whatever code the file names: it is reached only
through ``pointplan convert-checkpoint`` and needs ``trust_source=True``. Everything else
reads checkpoints with ``load_checkpoint`` (data only).
"""

from __future__ import annotations

import dataclasses
from collections import OrderedDict
from pathlib import Path, PurePath
from typing import Any

import numpy as np
import torch

from .checkpoint import FORMAT, HEADER_KEYS, PLAIN_TYPES, VERSION, CheckpointError, find_non_plain, save_checkpoint

_SCALARS = (str, int, float, bool, type(None))


def _fail(where: str, obj: Any) -> CheckpointError:
    t = type(obj)
    return CheckpointError(
        f"cannot convert {where or '/'}: a {t.__module__}.{t.__qualname__} has no plain-data form ({PLAIN_TYPES})"
    )


def _array(arr: np.ndarray, where: str, notes: list[str]) -> torch.Tensor:
    if arr.dtype.hasobject:
        raise _fail(where, arr)
    try:
        out = torch.from_numpy(np.array(arr, copy=True, order="C"))
    except TypeError:  # a dtype torch has no tensor for (strings, datetimes, ...)
        raise _fail(where, arr) from None
    notes.append(f"{where}: numpy array {arr.dtype} {arr.shape} -> tensor")
    return out


def _mapping(obj: dict[Any, Any], where: str, notes: list[str]) -> dict[Any, Any]:
    out: dict[Any, Any] = OrderedDict() if type(obj) is OrderedDict else {}
    for k, v in obj.items():
        key = k.item() if isinstance(k, np.generic) else k
        if type(key) not in (str, int):
            raise CheckpointError(f"cannot convert {where}/{k!r}: a key of type {type(k).__qualname__}")
        out[key] = to_plain(v, f"{where}/{key}", notes)
    if type(obj) is OrderedDict:  # a module state dict's _metadata
        for name, value in vars(obj).items():
            setattr(out, name, to_plain(value, f"{where}.{name}", notes))
    return out


def to_plain(obj: Any, where: str, notes: list[str]) -> Any:
    """``obj`` as plain data: dataclasses become dicts, numpy scalars Python numbers, numpy
    arrays tensors, paths strings, tensor subclasses tensors and tuple subclasses tuples.
    What changed is appended to ``notes``; anything else raises ``CheckpointError``."""
    t = type(obj)
    if t in _SCALARS or t is torch.Tensor:
        return obj
    if isinstance(obj, torch.Tensor):  # Parameter or another subclass
        return obj.detach().as_subclass(torch.Tensor)
    if isinstance(obj, np.generic):
        value = obj.item()
        if type(value) not in _SCALARS:
            raise _fail(where, obj)
        notes.append(f"{where}: numpy {obj.dtype} -> {type(value).__name__}")
        return value
    if isinstance(obj, np.ndarray):
        return _array(obj, where, notes)
    if isinstance(obj, PurePath):
        notes.append(f"{where}: path -> str")
        return str(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        notes.append(f"{where}: {t.__qualname__} -> dict")
        return {f.name: to_plain(getattr(obj, f.name), f"{where}/{f.name}", notes) for f in dataclasses.fields(obj)}
    if isinstance(obj, dict) and t in (dict, OrderedDict):
        return _mapping(obj, where, notes)
    if t is list:
        return [to_plain(v, f"{where}[{i}]", notes) for i, v in enumerate(obj)]
    if isinstance(obj, tuple):
        if t is not tuple:
            notes.append(f"{where}: {t.__qualname__} -> tuple")
        return tuple(to_plain(v, f"{where}[{i}]", notes) for i, v in enumerate(obj))
    raise _fail(where, obj)


def convert_checkpoint(src: str | Path, dst: str | Path, *, trust_source: bool = False) -> list[str]:
    """Unpickle ``src`` completely, which RUNS ANY CODE IT NAMES, and write its contents as a
    data-only checkpoint (format version 2) to ``dst``. Returns what was converted.

    ``trust_source=True`` is required: convert only files from a source you trust.
    """
    if trust_source is not True:
        raise CheckpointError(
            "convert_checkpoint unpickles the file, which can run code: pass trust_source=True only for a file you trust"
        )
    src = Path(src)
    if not src.is_file():
        raise CheckpointError(f"{src}: no such checkpoint")
    try:
        data = torch.load(src, map_location="cpu", weights_only=False)  # the one full unpickling, on request
    except Exception as e:  # torch raises many kinds on a corrupt file
        first = (str(e).strip().splitlines() or [""])[0]
        raise CheckpointError(f"{src}: not a readable checkpoint ({type(e).__name__}: {first})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise CheckpointError(f"{src}: not a pointplan checkpoint")
    version = data.get("version")
    if type(version) is int and version > VERSION:
        raise CheckpointError(
            f"{src}: checkpoint version {version} is newer than this pointplan understands ({VERSION})"
        )
    notes: list[str] = []
    try:
        payload = to_plain({k: v for k, v in data.items() if k not in HEADER_KEYS}, "", notes)
    except RecursionError:
        raise CheckpointError(f"{src}: cannot convert: its contents nest too deeply (or contain themselves)") from None
    bad = find_non_plain(payload)
    if bad is not None:  # to_plain returns only plain data; this guards against a slip there
        raise CheckpointError(f"cannot convert {bad}")
    save_checkpoint(dst, payload)
    return notes
