"""Self-describing checkpoints that hold only data.

A checkpoint is a ``torch.save`` dict holding the package version, the environment, robot
and observation it was trained on, the network and training configuration, the actor's
weights and, for resuming, the whole trainer state. Every value in it is plain data:
tensors, ``str``, ``int``, ``float``, ``bool``, ``None``, lists, tuples and dicts (module
and optimiser state dicts are ``OrderedDict``\\ s, also plain). ``save_checkpoint`` refuses
anything else, and ``load_checkpoint`` reads with ``torch.load(weights_only=True)``, which
rebuilds only such data and never calls code named in the file: policies are shared, and
unpickling a file can run anything.

Format version 2 is the data-only format. Version 1 files that are data only load as they
are; older files holding pickled objects are refused, naming ``pointplan convert-checkpoint``
(``pointplan.models.convert``), the one place that unpickles a file, on request.
``check_compatible`` refuses an environment whose robot or observation differs.
"""

from __future__ import annotations

import dataclasses
import math
import pickle
import re
import zipfile
from collections import OrderedDict
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import torch

FORMAT = "pointplan-checkpoint"
VERSION = 2
#: versions this code reads (1: the same keys, written before checkpoints were checked for
#: plain data; those that load with ``weights_only=True`` are data only)
READABLE_VERSIONS = (1, 2)
#: keys ``save_checkpoint`` writes itself
HEADER_KEYS = ("format", "version")

_SCALARS = (str, int, float, bool, type(None))
_KEYS = (str, int)
_TENSORS = (torch.Tensor, torch.nn.Parameter)
PLAIN_TYPES = "tensors, str, int, float, bool, None, lists, tuples and dicts"


class CheckpointError(ValueError):
    """A checkpoint that cannot be used here."""


def convert_hint(path: str | Path) -> str:
    return f"if you trust its source, convert it with `pointplan convert-checkpoint {path} NEW.pt`"


def to_dict(obj: Any) -> Any:
    """Dataclasses to plain dicts (recursively), for saving."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_dict(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, (list, tuple)):
        return [to_dict(x) for x in obj]
    return obj


def _type_name(obj: Any) -> str:
    t = type(obj)
    return t.__qualname__ if t.__module__ == "builtins" else f"{t.__module__}.{t.__qualname__}"


def find_non_plain(obj: Any, where: str = "") -> str | None:
    """The first value in ``obj`` that is not plain data, as ``"key/path (type)"``, or None.

    Types are matched exactly: a numpy ``float64`` (a ``float`` subclass) or a named tuple is
    not plain, since pickling it names a class. An ``OrderedDict``'s attributes (a module
    state dict's ``_metadata``) are checked too; a container inside itself is refused.
    """
    stack: list[tuple[Any, str, frozenset[int]]] = [(obj, where, frozenset())]
    while stack:
        x, at, seen = stack.pop()
        t = type(x)
        if t in _SCALARS or t in _TENSORS:
            continue
        if t not in (dict, OrderedDict, list, tuple):
            return f"{at or '/'} ({_type_name(x)})"
        if id(x) in seen:
            return f"{at or '/'} (contains itself)"
        inner = seen | {id(x)}
        if t is list or t is tuple:
            stack.extend((v, f"{at}[{i}]", inner) for i, v in enumerate(x))
            continue
        for k, v in x.items():
            if type(k) not in _KEYS:
                return f"{at}/{k!r} (a key of type {_type_name(k)})"
            stack.append((v, f"{at}/{k}", inner))
        if t is OrderedDict and vars(x):
            stack.append((dict(vars(x)), f"{at}.__dict__", inner))
    return None


def save_checkpoint(path: str | Path, payload: dict[str, Any]) -> None:
    """Write ``payload`` (plus format, version and package version) to ``path`` atomically.

    Raises ``CheckpointError`` if a value is not plain data (see ``find_non_plain``): convert
    dataclasses with ``to_dict``, numpy scalars with ``.item()`` and numpy arrays with
    ``torch.from_numpy``.
    """
    from .._version import __version__

    clash = [k for k in HEADER_KEYS if k in payload]
    if clash:
        raise CheckpointError(f"checkpoint payload may not set {', '.join(clash)}: save_checkpoint writes them")
    bad = find_non_plain(payload)
    if bad is not None:
        raise CheckpointError(f"cannot save {bad}: a checkpoint holds only {PLAIN_TYPES}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data: dict[str, Any] = {"format": FORMAT, "version": VERSION, "package_version": __version__}
    data.update(payload)
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(data, tmp)
    tmp.replace(path)


def first_line(e: BaseException) -> str:
    """``Type: message`` in one line (a first line ending in a colon takes the next along)."""
    lines = [line.strip() for line in str(e).strip().splitlines() if line.strip()]
    text = lines[0] if lines else ""
    if text.endswith(":") and len(lines) > 1:
        text = f"{text} {lines[1]}"
    return f"{type(e).__name__}: {text}".rstrip(": ")


@contextmanager
def rebuilding(path: str | Path, what: str) -> Iterator[None]:
    """Turn what goes wrong while rebuilding ``what`` (``"policy"``, ...) from a loaded
    checkpoint's contents (a missing key, a value of the wrong type, weights that do not fit
    the network) into one-line ``CheckpointError``\\ s naming ``path``."""
    try:
        yield
    except CheckpointError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError, IndexError, RuntimeError) as e:
        raise CheckpointError(f"{path}: not a usable {what} checkpoint ({first_line(e)})") from None


def check_weights(path: str | Path, expected: dict[str, Any], weights: Any, what: str = "network") -> None:
    """Refuse ``weights`` (a state dict read from ``path``) unless it holds exactly the
    tensors of ``expected`` (another state dict, e.g. of a network built on the ``meta``
    device, which allocates nothing) with their shapes."""
    if not isinstance(weights, dict):
        raise CheckpointError(f"{path}: the {what}'s weights are {_type_name(weights)}, not a state dict")
    missing = [k for k in expected if k not in weights]
    extra = [k for k in weights if k not in expected]
    if missing or extra:
        which = f"missing {missing[0]!r}" if missing else f"unexpected {extra[0]!r}"
        raise CheckpointError(f"{path}: the {what}'s weights do not match its settings ({which})")
    for k, v in expected.items():
        w = weights[k]
        if not isinstance(w, torch.Tensor) or tuple(w.shape) != tuple(v.shape):
            got = tuple(w.shape) if isinstance(w, torch.Tensor) else _type_name(w)
            raise CheckpointError(
                f"{path}: the {what}'s weights do not match its settings ({k}: {got}, expected {tuple(v.shape)})"
            )


#: the widest layer and the most layers a checkpoint's network settings may ask for
#: (:func:`check_sizes`, before anything is built)
MAX_WIDTH = 1 << 16
MAX_LAYERS = 256


def short_repr(value: Any, limit: int = 60) -> str:
    """``repr(value)``, cut to ``limit`` characters (for messages about a file's contents)."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def finite_number(value: Any) -> bool:
    """Whether ``value`` is an ``int`` or ``float`` (not a ``bool``) that is finite as a float."""
    if type(value) not in (int, float):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:  # an int too large for a float
        return False


def check_sizes(path: str | Path, settings: Any, widths: tuple[str, ...], counts: tuple[str, ...], what: str) -> None:
    """Refuse network ``settings`` (a dataclass read from ``path``) unless its fields
    ``widths`` are integers from 1 to :data:`MAX_WIDTH` and its fields ``counts`` (of
    layers) integers from 0 to :data:`MAX_LAYERS`: checked before a network is built, even
    on the ``meta`` device, which would still make a module per layer."""
    for names, low, high in ((widths, 1, MAX_WIDTH), (counts, 0, MAX_LAYERS)):
        for name in names:
            value = getattr(settings, name)
            if type(value) is not int or not low <= value <= high:
                raise CheckpointError(
                    f"{path}: the {what}'s {name} must be an integer from {low} to {high}, got {short_repr(value)}"
                )


def check_finite_weights(path: str | Path, weights: dict[str, Any], what: str = "network") -> None:
    """Refuse weights (tensors, already checked by :func:`check_weights`) that are not
    floating point numbers, or not finite."""
    for k, w in weights.items():
        if not w.is_floating_point():
            raise CheckpointError(f"{path}: the {what}'s weight {k} holds {w.dtype} values, not floating point numbers")
        if not bool(torch.isfinite(w).all()):
            raise CheckpointError(f"{path}: the {what}'s weight {k} holds values that are not finite (nan or inf)")


def _read_data_only(path: Path, device: str) -> Any:
    """``torch.load(weights_only=True)`` with one-line ``CheckpointError``\\ s."""
    if not zipfile.is_zipfile(path):  # torch.save writes zip archives; nothing else is tried
        raise CheckpointError(
            f"{path}: not a pointplan checkpoint (not a PyTorch zip archive: another kind of file, or truncated)"
        )
    try:
        return torch.load(path, map_location=device, weights_only=True)
    except pickle.UnpicklingError as e:
        if "weights only load failed" not in str(e).lower():
            raise CheckpointError(f"{path}: not a readable checkpoint ({first_line(e)})") from None
        found = re.search(r"GLOBAL ([\w.]+)", str(e))
        what = f" ({found.group(1)})" if found else ""
        raise CheckpointError(
            f"{path}: refused: it holds pickled Python objects{what}, which could run code when loaded; {convert_hint(path)}"
        ) from None
    except Exception as e:  # torch raises many kinds on a corrupt file
        raise CheckpointError(f"{path}: not a readable checkpoint ({first_line(e)})") from None


def load_checkpoint(path: str | Path, device: str = "cpu") -> dict[str, Any]:
    """Read a checkpoint without unpickling objects; check its format, version and contents."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: no such checkpoint")
    data = _read_data_only(path, device)
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise CheckpointError(f"{path}: not a pointplan checkpoint")
    version = data.get("version")
    if type(version) is not int or version < min(READABLE_VERSIONS):
        raise CheckpointError(f"{path}: unknown checkpoint version {version!r}")
    if version > VERSION:
        raise CheckpointError(
            f"{path}: checkpoint version {version} is newer than this pointplan understands ({VERSION})"
        )
    bad = find_non_plain(data)
    if bad is not None:  # possible only if someone allow-listed more types for torch.load
        raise CheckpointError(f"{path}: refused: {bad} is not plain data; {convert_hint(path)}")
    return data


def check_compatible(
    data: dict[str, Any], robot: str, observation: str, obs_shape: tuple[int, ...], where: str = "checkpoint"
) -> None:
    """Refuse a checkpoint trained for another robot or observation."""
    if data["robot"] != robot:
        raise CheckpointError(f"{where} was trained for robot {data['robot']!r}, not {robot!r}")
    if data["observation"] != observation:
        raise CheckpointError(
            f"{where} was trained on {data['observation']!r} observations, this env gives {observation!r}"
        )
    if tuple(data["obs_shape"]) != tuple(obs_shape):
        raise CheckpointError(
            f"{where} expects observations of shape {tuple(data['obs_shape'])}, this env gives {tuple(obs_shape)}"
        )
