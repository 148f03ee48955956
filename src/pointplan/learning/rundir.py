"""The folder of a training run, shared by every trainer.

A run folder holds ``metrics.csv`` (one row per logged step; a column that appears later
is added to the earlier rows, empty), TensorBoard scalars under ``tb/``, and checkpoints
written atomically (a temporary file, then ``os.replace``): ``last.pt``, the trainer state
a run resumes from, and the trainer's best or final model.

Ctrl-C while a trainer's loop runs (:meth:`RunDir.ctrl_c`) sets a flag the loop checks
between steps; a second Ctrl-C, or a ``KeyboardInterrupt`` raised inside the loop, leaves
the loop at once. Either way the trainer then saves ``last.pt`` through
:meth:`RunDir.interrupted`, which prints one line: where the state is and the command that
continues the run.
"""

from __future__ import annotations

import csv
import json
import math
import os
import shlex
import signal
import sys
import tempfile
import threading
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import torch

from ..models.checkpoint import CheckpointError, load_checkpoint, save_checkpoint

#: the trainer state a run resumes from
LAST = "last.pt"


class RunDirError(ValueError):
    """A run folder that cannot be used: a file is in the way, or it cannot be written."""


def check_run_dir(path: str | Path, create: bool = True) -> Path:
    """Check that the folder ``path`` can hold a run, creating it (with its parents) when
    ``create``; raises :class:`RunDirError` with a one-line reason otherwise. Without
    ``create`` nothing is written: the folder, or the nearest of its parents that exists,
    must be a folder this process may write in."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise RunDirError(f"--run-dir {p}: a file of that name exists; give a folder")
    if not create:
        near = next((a for a in (p, *p.parents) if a.exists()), Path("."))
        if not near.is_dir():
            raise RunDirError(f"--run-dir {p}: cannot create it, {near} is a file")
        if not os.access(near, os.W_OK | os.X_OK):
            raise RunDirError(f"--run-dir {p}: cannot write in {near} (permission denied)")
        return p
    try:
        p.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=p):
            pass
    except OSError as e:
        raise RunDirError(f"--run-dir {p}: cannot write there ({e.strerror or e})") from None
    return p


def atomic_write(path: Path, write: Callable[[Path], object]) -> None:
    """``write(tmp)`` to a temporary file next to ``path``, then move it over ``path``."""
    tmp = path.parent / f".{path.name}.{os.getpid()}.tmp"
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _scalar(v: Any) -> Any:
    """A plain number or string (numpy scalars and 0-d tensors unwrapped)."""
    return v.item() if hasattr(v, "item") and not isinstance(v, (str, bytes)) else v


class MetricsLog:
    """``metrics.csv`` (or ``name``) and TensorBoard scalars (under ``tb_dir``) of a run.

    The step of a row is its ``step_key`` value (default: the row's first key). Values that
    are ``None`` or not finite are left out (an empty cell, no scalar)."""

    def __init__(
        self, run_dir: str | Path, step_key: str | None = None, name: str = "metrics.csv", tb_dir: str = "tb"
    ) -> None:
        self.run_dir = Path(run_dir)
        self.path = self.run_dir / name
        self.step_key = step_key
        self.tb_dir = tb_dir
        self.tb: Any = None

    def _writer(self) -> Any:
        if self.tb is None:
            try:
                from torch.utils.tensorboard import SummaryWriter

                self.tb = SummaryWriter(str(self.run_dir / self.tb_dir))
            except Exception:  # tensorboard unusable here: the CSV only
                self.tb = False
        return self.tb or None

    def _read(self, rows: bool = True) -> tuple[list[str], list[dict[str, str]]]:
        """The CSV's header and (with ``rows``) its rows."""
        if not self.path.exists():
            return [], []
        with self.path.open(newline="") as f:
            reader = csv.DictReader(f)
            return list(reader.fieldnames or []), list(reader) if rows else []

    def _rewrite(self, keys: list[str], rows: Sequence[Mapping[str, Any]]) -> None:
        def write(tmp: Path) -> None:
            with tmp.open("w", newline="") as f:
                w = csv.DictWriter(f, fieldnames=keys, extrasaction="ignore", restval="")
                w.writeheader()
                w.writerows(rows)

        atomic_write(self.path, write)

    def log(self, row: Mapping[str, Any]) -> None:
        """Append ``row`` to the CSV (rewritten with every column when it brings new ones)
        and its numbers to TensorBoard."""
        clean = {k: _scalar(v) for k, v in row.items() if v is not None}
        clean = {k: v for k, v in clean.items() if not (isinstance(v, float) and not math.isfinite(v))}
        header, _ = self._read(rows=False)
        if header and set(clean) <= set(header):
            with self.path.open("a", newline="") as f:
                csv.DictWriter(f, fieldnames=header, extrasaction="ignore", restval="").writerow(clean)
        else:
            self._rewrite(header + [k for k in clean if k not in header], [*self._read()[1], clean])
        self._scalars(clean)

    def _scalars(self, row: dict[str, Any]) -> None:
        key = self.step_key or next(iter(row), None)
        tb = self._writer()
        if tb is None or key is None or key not in row:
            return
        for k, v in row.items():
            if k != key and isinstance(v, (int, float)) and not isinstance(v, bool):
                tb.add_scalar(k, v, int(row[key]))
        tb.flush()

    def drop_after(self, step: float) -> None:
        """Forget the CSV rows past ``step`` (logged after the state a run resumes from was
        saved), so that the resumed run does not log those steps twice."""
        header, old = self._read()
        key = self.step_key or (header[0] if header else None)
        if key is None:
            return
        keep = [r for r in old if not r.get(key) or float(r[key]) <= step]
        if len(keep) < len(old):
            self._rewrite(header, keep)

    def close(self) -> None:
        if self.tb:
            self.tb.close()
            self.tb = None


class CtrlC:
    """Ctrl-C (SIGINT) sets ``requested`` for the loop to check; a second one raises
    ``KeyboardInterrupt``. A ``KeyboardInterrupt`` that leaves the block sets ``requested``
    too and goes no further. The handler is installed only in the main thread and when
    ``enabled``."""

    def __init__(self, enabled: bool = True) -> None:
        self.enabled = enabled and threading.current_thread() is threading.main_thread()
        self.requested = False
        self._old: Any = None

    def __enter__(self) -> CtrlC:
        if self.enabled:
            self._old = signal.signal(signal.SIGINT, self._on_sigint)
        return self

    def _on_sigint(self, signum: int, frame: Any) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True

    def __call__(self) -> bool:
        return self.requested

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: Any) -> bool:
        if self.enabled:
            signal.signal(signal.SIGINT, self._old)
        if exc_type is not None and issubclass(exc_type, KeyboardInterrupt):
            self.requested = True
            return True
        return False


class RunDir:
    """A run's folder: metrics, atomic checkpoints, resuming and Ctrl-C.

    ``command`` is the command that trains into it (``pointplan bc``): the line printed on
    Ctrl-C names ``<command> --resume <folder>/last.pt``."""

    def __init__(self, path: str | Path, command: str, metrics: str = "metrics.csv", tb_dir: str = "tb") -> None:
        self.path = check_run_dir(path)
        self.command = command
        self.metrics = MetricsLog(self.path, name=metrics, tb_dir=tb_dir)

    @property
    def last(self) -> Path:
        return self.path / LAST

    def log(self, row: Mapping[str, Any]) -> None:
        self.metrics.log(row)

    def save(self, name: str, payload: dict[str, Any]) -> Path:
        """A data-only checkpoint ``name`` (:func:`~pointplan.models.checkpoint.save_checkpoint`, atomic)."""
        save_checkpoint(self.path / name, payload)
        return self.path / name

    def save_torch(self, name: str, obj: Any) -> Path:
        """``torch.save(obj)`` to ``name``, atomically."""
        atomic_write(self.path / name, lambda tmp: torch.save(obj, tmp))
        return self.path / name

    def write_json(self, name: str, data: Any) -> Path:
        """``data`` as indented JSON in ``name``, atomically."""
        text = json.dumps(data, indent=2) + "\n"
        atomic_write(self.path / name, lambda tmp: tmp.write_text(text))
        return self.path / name

    def resume_command(self) -> str:
        return f"{self.command} --resume {shlex.quote(str(self.last))}"

    def ctrl_c(self, enabled: bool = True) -> CtrlC:
        return CtrlC(enabled)

    def interrupted(self, where: str, save: Callable[[], Any], note: str = "") -> None:
        """Save the trainer state (``save`` writes ``last.pt``; Ctrl-C is ignored meanwhile),
        then print one line: where it went and the command that continues the run."""
        main = threading.current_thread() is threading.main_thread()
        old = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
        try:
            save()
        finally:
            if main:
                signal.signal(signal.SIGINT, old)
        extra = f" ({note})" if note else ""
        print(
            f"interrupted {where}: trainer state saved to {self.last}{extra}; continue with: {self.resume_command()}",
            file=sys.stderr,
            flush=True,
        )

    def close(self) -> None:
        self.metrics.close()


def optimizer_and_random_state(opt: torch.optim.Optimizer, rng: Any) -> dict[str, Any]:
    """The optimiser's state and both random generators' (numpy ``rng`` and PyTorch's), for a trainer state."""
    return {"optimizer": opt.state_dict(), "rng": rng.bit_generator.state, "torch_rng": torch.get_rng_state()}


def restore_optimizer_and_random_state(t: Mapping[str, Any], opt: torch.optim.Optimizer, rng: Any) -> None:
    """Put back what :func:`optimizer_and_random_state` saved."""
    opt.load_state_dict(t["optimizer"])
    rng.bit_generator.state = t["rng"]
    torch.set_rng_state(t["torch_rng"])


def epoch_range(done: int, total: int, resume: object, desc: str, progress: bool) -> Any:
    """The epochs ``done + 1 .. total`` still to run (with a progress bar when ``progress``);
    a ValueError naming ``resume`` when none is left."""
    if done >= total:
        raise ValueError(f"{resume}: the run has done its {done} epochs; give --epochs above that to continue it")
    epochs: Any = range(done + 1, total + 1)
    if progress:
        from ..progress import progress_bar

        epochs = progress_bar(epochs, desc=desc, unit="epoch", total=total, initial=done)
    return epochs


def say_interrupted_early(what: str) -> None:
    """The line for Ctrl-C before training started (nothing to save)."""
    print(f"interrupted while {what}: nothing trained yet, nothing saved", file=sys.stderr, flush=True)


def load_trainer_state(path: str | Path, key: str, command: str, device: str = "cpu") -> dict[str, Any]:
    """The checkpoint at ``path`` if it holds the trainer state ``key`` of ``command``'s
    runs; a :class:`~pointplan.models.checkpoint.CheckpointError` naming what to give otherwise."""
    state = load_checkpoint(path, device)
    if key not in state:
        raise CheckpointError(f"{path}: not the trainer state of a `{command}` run; resume from that run's {LAST}")
    return state


def best_or_none(best: float) -> float | None:
    """A best validation score kept as a negative number until the first validation: None then."""
    return best if best >= 0 else None


def best_note(best: float | None, what: str = "validation success") -> str:
    """What a run's validation has found so far, in words."""
    return f"best {what} {best:.3f}" if best is not None else "no validation yet"


__all__ = [
    "LAST",
    "CtrlC",
    "MetricsLog",
    "RunDir",
    "RunDirError",
    "atomic_write",
    "best_note",
    "best_or_none",
    "check_run_dir",
    "load_trainer_state",
]
