"""Progress bars: redrawn in place on a terminal, a line at a time in a log."""

from __future__ import annotations

import io

import pytest

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
