"""Progress bars: redrawn in place on a terminal, a line at a time in a log."""

from __future__ import annotations

import copy
import io
import re
import time

import pytest
import tqdm

from pointplan.evaluation import evaluate
from pointplan.planners import StraightLine
from pointplan.progress import LOG_INTERVAL, LogLines, log_interval, progress_bar
from pointplan.robots import Disc2D
from pointplan.scenes.scenarios import Narrow2DScenario


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_log_lines_turns_redraws_into_lines() -> None:
    out = io.StringIO()
    log = LogLines(out)
    # what tqdm writes: a state, another state over it, a clear, a message, the last state
    for text in ("\rbar  0%   ", "\rbar 50%   ", "\r          \r", "a message", "\n", "\rbar 100%", "\n"):
        assert log.write(text) == len(text)
    assert out.getvalue() == "bar  0%\nbar 50%\na message\nbar 100%\n"
    # a second bar's cursor movements are not written; a copy still writes to the stream
    log.write("\x1b[A\rbar2 10%\x1b[A")
    copy.copy(log).write("copied\n")
    assert out.getvalue().endswith("bar 100%\nbar2 10%\ncopied\n")


@pytest.mark.parametrize("manual", [False, True])
def test_lines_during_a_run_are_current_and_spaced(manual: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """A bar over a run of about 1.2 s (over an iterable, or updated by hand with the
    postfix set first), with a line every 0.2 s: lines during the run, each with its own
    count and the postfix of that count, none repeating an earlier count, at most one per
    interval."""
    monkeypatch.setenv("POINTPLAN_PROGRESS_INTERVAL", "0.2")
    # tqdm's monitor thread, which redraws bars that have not been drawn for a while, woken
    # every 0.05 s rather than every 10 s (a fresh one, as a bar starts it when there is none)
    if tqdm.tqdm.monitor is not None:
        tqdm.tqdm.monitor.exit()
        tqdm.tqdm.monitor = None
    monkeypatch.setattr(tqdm.tqdm, "monitor_interval", 0.05)
    out = io.StringIO()
    t0 = time.perf_counter()
    if manual:
        bar = progress_bar(total=60, file=out)
        for i in range(60):
            time.sleep(0.02)
            bar.set_postfix(done=i + 1, refresh=False)
            bar.update()
    else:
        bar = progress_bar(range(60), file=out)
        for i in bar:
            time.sleep(0.02)
            bar.set_postfix(done=i + 1, refresh=False)
    elapsed = time.perf_counter() - t0
    bar.close()
    lines = out.getvalue().splitlines()
    counts = [int(re.search(r"(\d+)/60", line).group(1)) for line in lines]  # type: ignore[union-attr]
    assert counts[0] == 0 and counts[-1] == 60
    assert len(lines) >= 4  # lines in the middle of the run, not only the first and the last
    assert len(lines) <= 2 + elapsed / 0.2 + 1
    if counts[-2] == 60:  # closing writes the last state again, with its final time
        counts = counts[:-1]
    assert all(a < b for a, b in zip(counts[:-1], counts[1:])), counts
    for line, n in zip(lines[1:], counts[1:]):
        assert f"done={n}" in line, line


def test_a_log_gets_a_line_per_interval_not_per_update(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("POINTPLAN_PROGRESS_INTERVAL", raising=False)
    out = io.StringIO()
    bar = progress_bar(range(5000), file=out, desc="work", unit="item")
    for i in bar:
        bar.set_postfix(done=i + 1, refresh=False)
    bar.close()
    text = out.getvalue()
    lines = text.splitlines()
    assert "\r" not in text
    # the first state and the last one: the loop takes far less than LOG_INTERVAL
    assert len(lines) == 2, lines
    assert "0/5000" in lines[0]
    assert "5000/5000" in lines[-1] and "done=5000" in lines[-1]


def test_interval_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("POINTPLAN_PROGRESS_INTERVAL", "0")
    assert log_interval() == 0.0
    out = io.StringIO()
    bar = progress_bar(range(4), file=out, miniters=1)
    for _ in bar:
        pass
    bar.close()
    states = [line.split("|")[-1].split()[0] for line in out.getvalue().splitlines()]
    # a line per update; closing writes the last state once more (its rate has changed)
    assert states[:5] == ["0/4", "1/4", "2/4", "3/4", "4/4"] and set(states[5:]) <= {"4/4"}
    monkeypatch.setenv("POINTPLAN_PROGRESS_INTERVAL", "soon")
    with pytest.raises(ValueError, match="POINTPLAN_PROGRESS_INTERVAL='soon'"):
        log_interval()
    monkeypatch.setenv("POINTPLAN_PROGRESS_INTERVAL", "-1")
    with pytest.raises(ValueError, match="0 or more"):
        log_interval()
    monkeypatch.delenv("POINTPLAN_PROGRESS_INTERVAL")
    assert log_interval() == LOG_INTERVAL


def test_a_terminal_gets_the_usual_bar() -> None:
    out = Terminal()
    bar = progress_bar(range(3), file=out, mininterval=0)
    for _ in bar:
        pass
    bar.close()
    text = out.getvalue()
    assert text.count("\r") >= 4  # redrawn in place: the first state and one per item
    assert text.rstrip("\n").rpartition("\r")[2].lstrip().startswith("100%")


def test_evaluate_writes_a_short_log(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """An evaluation with its bar on (standard error is not a terminal under pytest):
    the bar's first and last states, not one redraw per problem."""
    monkeypatch.delenv("POINTPLAN_PROGRESS_INTERVAL", raising=False)
    robot = Disc2D()
    problems = Narrow2DScenario().problems("test", 60, seed=1)
    report = evaluate(StraightLine(robot), problems, robot, progress=True)
    assert len(report.records) == 60
    success = report.metrics()["success_rate"]
    err = capsys.readouterr().err
    lines = err.splitlines()
    assert "\r" not in err
    assert len(lines) == 2, lines
    assert "60/60" in lines[-1] and f"success={success:.1%}" in lines[-1]
