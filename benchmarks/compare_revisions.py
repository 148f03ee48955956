"""Run one benchmark script from two revisions of pointplan, alternating, in one session,
and report the ratio of a column (current / base) line by line: on a shared, noisy machine
a ratio measured this way means more than two numbers measured at different times.

    python benchmarks/compare_revisions.py --base ba80ff4 --column 3 -- benchmarks/bench_env.py --quick
    python benchmarks/compare_revisions.py --base ba80ff4 --column 4 -- benchmarks/bench_env3d.py --seconds 1 --scenes boxes3d

The base revision is checked out in a temporary git worktree; both runs use the current
benchmark script (so the two measure the same thing), each importing its own tree's
``src`` first (``PYTHONPATH``). A line's key is its first ``--column`` tokens; its value
the token at ``--column`` (thousands separators and a trailing ``x`` are dropped).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def number(token: str) -> float | None:
    try:
        return float(token.replace(",", "").rstrip("x"))
    except ValueError:
        return None


def parse(text: str, column: int) -> dict[tuple[str, ...], float]:
    out = {}
    for line in text.splitlines():
        tokens = line.split()
        if len(tokens) > column and (v := number(tokens[column])) is not None:
            out[tuple(tokens[:column])] = v
    return out


def run(tree: Path, command: list[str]) -> str:
    env = {**os.environ, "PYTHONPATH": str(tree / "src")}
    res = subprocess.run([sys.executable, *command], cwd=ROOT, env=env, capture_output=True, text=True, check=True)
    return res.stdout


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base", required=True, help="git revision to compare with")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--column", type=int, default=3, help="0-based token index of the value to compare")
    ap.add_argument("command", nargs=argparse.REMAINDER, help="-- SCRIPT [ARGS...]")
    args = ap.parse_args()
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command:
        ap.error("give the benchmark after --")
    with tempfile.TemporaryDirectory() as tmp:
        base_tree = Path(tmp) / "base"
        subprocess.run(
            ["git", "worktree", "add", "--detach", str(base_tree), args.base], cwd=ROOT, check=True, capture_output=True
        )
        try:
            trees = {"current": ROOT, "base": base_tree}
            for tree in trees.values():  # warm-up: numba caches, imports
                run(tree, command)
            values: dict[str, list[dict[tuple[str, ...], float]]] = {"current": [], "base": []}
            for r in range(args.rounds):
                for name in ("current", "base") if r % 2 == 0 else ("base", "current"):
                    values[name].append(parse(run(trees[name], command), args.column))
                print(f"round {r + 1}/{args.rounds} done", file=sys.stderr)
        finally:
            subprocess.run(
                ["git", "worktree", "remove", "--force", str(base_tree)], cwd=ROOT, check=False, capture_output=True
            )
    keys = [k for k in values["current"][0] if all(k in v for v in values["current"] + values["base"])]
    print(f"{' '.join(command)}: median over {args.rounds} rounds, current vs {args.base}")
    for k in keys:
        cur = statistics.median(v[k] for v in values["current"])
        base = statistics.median(v[k] for v in values["base"])
        print(f"{' '.join(k):<40} {base:>12,.1f} {cur:>12,.1f} {cur / base:>7.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
