"""Write the command line's reference page, ``docs/reference/cli.md``, from ``pointplan``'s
own argument parser, so that the page says what ``pointplan COMMAND --help`` says.

    python scripts/cli_reference.py            # rewrite the page
    python scripts/cli_reference.py --check    # exit 1, naming the page, if it is out of date
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pointplan.cli import build_parser

PAGE = Path(__file__).resolve().parents[1] / "docs" / "reference" / "cli.md"


def _cell(text: str) -> str:
    """``text`` on one line of a Markdown table cell."""
    return " ".join(text.split()).replace("|", "\\|").replace("<", "&lt;")


def _help(action: argparse.Action, prog: str) -> str:
    """The action's help with argparse's ``%(default)s``-style fields filled in."""
    if not action.help:
        return ""
    params = {k: v for k, v in vars(action).items() if v is not argparse.SUPPRESS}
    params["prog"] = prog
    if params.get("choices") is not None:
        params["choices"] = ", ".join(str(c) for c in params["choices"])
    return action.help % params


def _names(action: argparse.Action) -> str:
    """How the option is written: ``--env ENV``, ``--quiet``, ``-o OUT, --out OUT``, ``scene``."""
    if not action.option_strings:
        return str(action.metavar or action.dest)
    if action.nargs == 0:
        return ", ".join(action.option_strings)
    metavar = action.metavar or action.dest.upper()
    if isinstance(metavar, tuple):
        metavar = " ".join(metavar)
    return ", ".join(f"{s} {metavar}" for s in action.option_strings)


def command_section(name: str, p: argparse.ArgumentParser) -> list[str]:
    lines = [f"## pointplan {name}", "", _cell(p.description or ""), ""]
    rows = []
    for action in p._actions:  # argparse has no public list of a parser's arguments
        if isinstance(action, argparse._HelpAction | argparse._VersionAction) or action.help == argparse.SUPPRESS:
            continue
        rows.append(f"| `{_names(action)}` | {_cell(_help(action, p.prog))} |")
    if rows:
        lines += ["| argument | meaning |", "|---|---|", *rows, ""]
    if p.epilog:
        lines += [_cell(p.epilog), ""]
    return lines


def render() -> str:
    parser = build_parser()
    commands: dict[str, argparse.ArgumentParser] = parser.commands  # type: ignore[attr-defined]
    helps = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help or "" for a in action._choices_actions}
    lines = [
        "# Command-line reference",
        "",
        "Every `pointplan` command and its arguments, generated from the program's own parser by",
        "`python scripts/cli_reference.py` (a test fails when this page and the parser disagree);",
        "`pointplan COMMAND --help` prints the same. Worked examples: the",
        "[planners](../guide/planners.md#the-command-line) and [training](../guide/training.md#commands)",
        "guides.",
        "",
        "| command | what it does |",
        "|---|---|",
    ]
    lines += [f"| [`{n}`](#pointplan-{n}) | {_cell(helps.get(n, ''))} |" for n in commands]
    lines.append("")
    for name, p in commands.items():
        lines += command_section(name, p)
    return "\n".join(lines).rstrip() + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--check", action="store_true", help="only check that the page is current (exit 1 if not)")
    args = ap.parse_args(argv)
    text = render()
    if args.check:
        if not PAGE.is_file() or PAGE.read_text(encoding="utf-8") != text:
            print(f"{PAGE} is out of date: run python scripts/cli_reference.py", file=sys.stderr)
            return 1
        return 0
    PAGE.write_text(text, encoding="utf-8")
    print(f"wrote {PAGE}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
