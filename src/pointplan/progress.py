"""Progress bars that suit a terminal, a notebook and a log file alike.

Every long job of pointplan (training, evaluation, demonstrations) shows a tqdm bar made
by :func:`progress_bar`. On a terminal it redraws in place; in Jupyter it is a widget.
When its stream is a file or a pipe (``nohup pointplan train ... > train.log``), a bar
redrawn in place would pile up as carriage returns on one line that grows all run long, so
there the bar writes its state as a plain line instead, at most once every
:data:`LOG_INTERVAL` seconds (``POINTPLAN_PROGRESS_INTERVAL`` sets another), and its final
state when it closes.
"""

from __future__ import annotations

import os
import re
import sys
from collections.abc import Iterable
from typing import IO, Any

#: seconds between two lines of a bar written to a file or a pipe
LOG_INTERVAL = 60.0
#: terminal control sequences (tqdm moves the cursor for stacked bars)
_CONTROL = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")


def _is_terminal(stream: Any) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or a closed file
        return False


def _in_notebook(stream: Any) -> bool:
    return type(stream).__module__.split(".")[0] == "ipykernel"


def log_interval() -> float:
    """Seconds between two lines of a bar in a log: ``POINTPLAN_PROGRESS_INTERVAL`` if set
    (a number of seconds), else :data:`LOG_INTERVAL`."""
    value = os.environ.get("POINTPLAN_PROGRESS_INTERVAL", "")
    if not value:
        return LOG_INTERVAL
    try:
        seconds = float(value)
    except ValueError:
        raise ValueError(f"POINTPLAN_PROGRESS_INTERVAL={value!r}: expected a number of seconds") from None
    if not seconds >= 0:
        raise ValueError(f"POINTPLAN_PROGRESS_INTERVAL={value!r}: expected a number of seconds, 0 or more")
    return seconds


class LogLines:
    """A text stream for tqdm that writes each state of the bar as a line of its own.

    tqdm redraws a bar by writing ``"\\r"`` and the new state, and clears it for a message
    by writing ``"\\r"``, spaces and ``"\\r"``. Here every stretch of text between carriage
    returns and newlines that is not blank becomes one line, with trailing spaces and
    terminal control sequences removed; blank stretches, and a line equal to the one before
    it, are dropped."""

    def __init__(self, stream: IO[str]) -> None:
        self.stream = stream
        self._last = ""

    def write(self, text: str) -> int:
        out = []
        for part in _CONTROL.sub("", text).replace("\r", "\n").split("\n"):
            line = part.rstrip()
            if line and line != self._last:
                out.append(f"{line}\n")
                self._last = line
        if out:
            self.stream.write("".join(out))
        return len(text)

    def flush(self) -> None:
        self.stream.flush()

    def isatty(self) -> bool:
        return False

    def __getattr__(self, name: str) -> Any:  # encoding, fileno, ... of the stream
        if name.startswith("__") or "stream" not in self.__dict__:  # (copy, pickle)
            raise AttributeError(name)
        return getattr(self.stream, name)


def progress_bar(iterable: Iterable[Any] | None = None, **kwargs: Any) -> Any:
    """A ``tqdm`` bar over ``iterable`` (or a manual one with ``total=...``), writing to
    ``file`` (standard error by default); other keyword arguments go to ``tqdm``. On a
    terminal or in a notebook it is the usual bar. On a file or a pipe it writes a line at
    most every :func:`log_interval` seconds (unless ``mininterval`` is given). Update the
    postfix with ``set_postfix(..., refresh=False)``, so that it shows at the bar's next
    line rather than forcing one."""
    stream = kwargs.pop("file", None) or sys.stderr
    if _in_notebook(stream):
        from tqdm.auto import tqdm as auto_tqdm

        return auto_tqdm(iterable, file=stream, **kwargs)
    from tqdm import tqdm

    if _is_terminal(stream):
        return tqdm(iterable, file=stream, **kwargs)
    interval = kwargs.pop("mininterval", None)
    interval = log_interval() if interval is None else float(interval)
    kwargs.pop("dynamic_ncols", None)  # a file has no width to follow
    # miniters=1: every update looks at the clock, and tqdm's monitor thread (which redraws
    # a bar with a larger miniters after maxinterval, showing its last count again) keeps away
    kwargs.setdefault("miniters", 1)
    return tqdm(iterable, file=LogLines(stream), mininterval=interval, **kwargs)
