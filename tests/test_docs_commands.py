"""The commands the documentation gives still parse: every ``pointplan ...`` and ``python
scripts|benchmarks|experiments/X.py ...`` line in a code block of README.md, docs/,
checkpoints/ and experiments/ is handed to its own argument parser (nothing runs: parsing
stops the program), so a renamed option, a removed choice or a retired script shows up
here rather than in a user's terminal.
"""

from __future__ import annotations

import argparse
import io
import runpy
import shlex
import sys
from pathlib import Path

import pytest

from test_docs_links import PAGES, REPO  # the same pages

markdown_it = pytest.importorskip("markdown_it")

SCRIPT_DIRS = ("scripts/", "benchmarks/", "experiments/")


def _split_commands(line: str) -> list[list[str]]:
    """The shell words of each command in ``line`` (``&&``, ``;`` and ``|`` separate
    commands; leading ``VAR=value``, ``nice -n N``, ``time`` and ``timeout N`` go)."""
    try:
        lexer = shlex.shlex(line, posix=True, punctuation_chars=";&|")
        lexer.whitespace_split = True
        lexer.commenters = "#"
        words = list(lexer)
    except ValueError:  # an unbalanced quote: not a command line
        return []
    out: list[list[str]] = [[]]
    for w in words:
        if w in (";", "&&", "||", "|", "&"):
            out.append([])
        else:
            out[-1].append(w)
    cleaned = []
    for cmd in out:
        while cmd and ("=" in cmd[0] and not cmd[0].startswith("-") or cmd[0] in ("time", "nice", "timeout", "-n")):
            if cmd[0] == "nice" and len(cmd) > 2 and cmd[1] == "-n":
                cmd = cmd[3:]
            elif cmd[0] == "timeout" and len(cmd) > 1:
                cmd = cmd[2:]
            else:
                cmd = cmd[1:]
        if cmd:
            cleaned.append(cmd)
    return cleaned


def commands(page: Path) -> list[list[str]]:
    """The ``pointplan`` and ``python <script>`` commands in the page's code blocks."""
    out = []
    for tok in markdown_it.MarkdownIt("commonmark").parse(page.read_text(encoding="utf-8")):
        if tok.type not in ("fence", "code_block") or tok.info.strip() not in ("", "bash", "sh", "shell", "console"):
            continue
        text = tok.content.replace("\\\n", " ")
        for line in text.splitlines():
            line = line.strip().removeprefix("$ ")
            for cmd in _split_commands(line):
                if cmd[0] == "pointplan":
                    out.append(cmd)
                elif cmd[0] in ("python", "python3") and len(cmd) > 1 and cmd[1].startswith(SCRIPT_DIRS):
                    out.append(cmd[1:])
    return out


class _Parsed(Exception):
    pass


def parse_error(cmd: list[str], monkeypatch: pytest.MonkeyPatch) -> str | None:
    """None where ``cmd`` parses, else argparse's message."""
    original = argparse.ArgumentParser.parse_args

    def parse_then_stop(self, args=None, namespace=None):  # type: ignore[no-untyped-def]
        original(self, args, namespace)
        raise _Parsed

    with monkeypatch.context() as m:
        m.setattr(argparse.ArgumentParser, "parse_args", parse_then_stop)
        stderr = io.StringIO()
        m.setattr(sys, "stderr", stderr)
        try:
            if cmd[0] == "pointplan":  # as pointplan.cli.main parses, without running
                from pointplan.cli import build_parser

                parser = build_parser()
                args, extra = parser.parse_known_args(cmd[1:])
                if extra:
                    parser.commands.get(args.command, parser).error(f"unrecognized arguments: {' '.join(extra)}")
                raise _Parsed
            else:
                script = REPO / cmd[0]
                if not script.is_file():
                    return f"{cmd[0]}: no such script"
                m.setattr(sys, "argv", cmd)
                m.syspath_prepend(str(script.parent))
                runpy.run_path(str(script), run_name="__main__")
        except _Parsed:
            return None
        except SystemExit as e:
            message = " ".join(stderr.getvalue().split())
            return message[message.find("error:") :] if "error:" in message else message or f"exit {e.code}"
    return "the program ran past its argument parsing without parsing"


def test_commands_are_found_and_split() -> None:
    assert _split_commands("OMP_NUM_THREADS=1 nice -n 10 pointplan eval --env x && echo ok  # note") == [
        ["pointplan", "eval", "--env", "x"],
        ["echo", "ok"],
    ]
    assert _split_commands("pip install -e . && pointplan demo") == [
        ["pip", "install", "-e", "."],
        ["pointplan", "demo"],
    ]
    found = [c for p in PAGES for c in commands(p)]
    assert sum(c[0] == "pointplan" for c in found) > 20
    assert sum(c[0].startswith("scripts/") for c in found) > 10


def test_a_bad_option_is_caught(monkeypatch: pytest.MonkeyPatch) -> None:
    assert parse_error(["pointplan", "eval", "--env", "narrow2d"], monkeypatch) is None
    assert "unrecognized arguments" in str(parse_error(["pointplan", "eval", "--no-such-option"], monkeypatch))
    assert "invalid choice" in str(parse_error(["pointplan", "no-such-command"], monkeypatch))
    assert parse_error(["scripts/no_such_script.py"], monkeypatch) == "scripts/no_such_script.py: no such script"


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(REPO)) for p in PAGES])
def test_documented_commands_parse(page: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    bad = [f"{shlex.join(c)}\n    -> {err}" for c in commands(page) if (err := parse_error(c, monkeypatch))]
    assert not bad, "\n".join(bad)
