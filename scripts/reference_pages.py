"""Write the reference pages from the code itself: ``docs/reference/cli.md`` from
``pointplan``'s argument parser (what ``pointplan COMMAND --help`` says) and
``docs/reference/api.md`` from the signatures and docstrings of the Python API.

    python scripts/reference_pages.py            # rewrite both pages
    python scripts/reference_pages.py --check    # exit 1, naming the page, if one is out of date
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import inspect
import math
import re
import sys
from pathlib import Path
from typing import Any

from pointplan.cli import build_parser

REFERENCE = Path(__file__).resolve().parents[1] / "docs" / "reference"
PAGES = {"cli": REFERENCE / "cli.md", "api": REFERENCE / "api.md"}


def _cell(text: str) -> str:
    """``text`` on one line of a Markdown table cell."""
    return " ".join(text.split()).replace("|", "\\|").replace("<", "&lt;")


def _help(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    """The action's help with ``%(default)s``-style fields filled in, by argparse itself."""
    return parser._get_formatter()._expand_help(action) if action.help else ""


def _names(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    """How the argument is written, as in ``--help``: ``--env ENV``, ``--quiet``,
    ``-o OUT, --out OUT``, ``--encoder-sharing {shared,separate}``, ``scene``."""
    return parser._get_formatter()._format_action_invocation(action)  # as --help writes it


def command_section(name: str, p: argparse.ArgumentParser) -> list[str]:
    lines = [f"## pointplan {name}", "", _cell(p.description or ""), ""]
    rows = []
    for action in p._actions:  # argparse has no public list of a parser's arguments
        if isinstance(action, argparse._HelpAction | argparse._VersionAction) or action.help == argparse.SUPPRESS:
            continue
        rows.append(f"| `{_names(p, action)}` | {_cell(_help(p, action))} |")
    if rows:
        lines += ["| argument | meaning |", "|---|---|", *rows, ""]
    if p.epilog:
        lines += [_cell(p.epilog), ""]
    return lines


def render_cli() -> str:
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
        "`python scripts/reference_pages.py` (a test fails when this page and the parser disagree);",
        "`pointplan COMMAND --help` prints the same, with a usage line. Worked examples: the",
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


# The Python API, section by section: (heading, what it is for, [(module, names)]).
API: list[tuple[str, str, list[tuple[str, list[str]]]]] = [
    (
        "Scenes and problems",
        "Workspaces, start/goal problems, the scenarios of the paper and your own scene files.",
        [
            ("pointplan.scenes", ["Scene", "Problem"]),
            ("pointplan.scenes.scenarios", ["make_scenario", "scenario_names", "Scenario"]),
            (
                "pointplan.scenes.io",
                ["load_scene", "save_scene", "load_points_scene", "load_depth_scene", "SceneFormatError"],
            ),
            ("pointplan.scenes.cameras", ["CameraModel", "camera_ring", "seen_by_cameras"]),
            ("pointplan.scenes.mbm", ["load_problem", "load_problems", "JointSpaceScene"]),
        ],
    ),
    (
        "Shapes and collision",
        "Obstacles and the batched, certified collision world built from them.",
        [("pointplan.geometry", ["Box", "Sphere", "Capsule", "Cylinder", "Mesh", "PointCloud", "CollisionWorld"])],
    ),
    (
        "Robots",
        "The rigid robots of the paper and arms from a URDF.",
        [
            ("pointplan.robots", ["make_robot", "Robot", "Disc2D", "Sphere3D", "SShape", "OrientedSShape"]),
            ("pointplan.robots.arm", ["load_arm", "ArmRobot"]),
        ],
    ),
    (
        "Observations",
        "What the robot sees of the obstacles: points with normals, rays, images.",
        [("pointplan.observers", ["make_observer", "Observer"])],
    ),
    (
        "Planners",
        "Every planner answers `plan(problem)` with a `PlanResult`.",
        [
            (
                "pointplan.planners",
                ["make_planner", "register_planner", "Planner", "PlanResult", "BiRRT", "StraightLine"],
            ),
            ("pointplan.planners.policy", ["PolicyPlanner"]),
            ("pointplan.planners.hybrid", ["HybridPlanner"]),
        ],
    ),
    (
        "Policies and training",
        "Trained policies, SAC + HER and behavioural cloning.",
        [
            ("pointplan.models.policy", ["Policy"]),
            ("pointplan.learning.train", ["TrainConfig", "train", "TrainResult"]),
            ("pointplan.learning.bc", ["BCConfig", "train_bc", "generate_demos"]),
            ("pointplan.models.actor_critic", ["NetConfig"]),
            ("pointplan.models.encoders", ["EncoderConfig"]),
        ],
    ),
    (
        "Environments",
        "Gymnasium environments (ids `pointplan/...`) for your own learning code.",
        [("pointplan.envs", ["make_env", "make_vector_env", "PlanningEnv", "PlanningVectorEnv", "EnvConfig"])],
    ),
    (
        "Evaluation and path checks",
        "Metrics of planners on problem sets, and the independent check of every path.",
        [
            ("pointplan.evaluation", ["evaluate", "EvalReport", "check_path", "PathCheck", "densify", "format_table"]),
            ("pointplan.evaluation.interpolation", ["check_linear_slerp", "for_linear_slerp"]),
        ],
    ),
    (
        "Many cores",
        "Ray workers on this machine or a cluster (`pip install 'pointplan[ray]'`).",
        [("pointplan.distributed", ["connect", "ScenarioProblems", "evaluate_parallel", "RayPool"])],
    ),
]

_ROLE = re.compile(r":[a-z]+:`(~?)([^`]+)`")


def _doc(obj: Any) -> str:
    """The object's own docstring as Markdown (not one inherited from a library, which
    would tie the page to that library's version, nor the text dataclasses make up for a
    class without one): ``code`` as `code`, Sphinx roles as code (``~`` keeps the last
    name)."""
    doc = inspect.cleandoc(obj.__doc__ or "")
    if dataclasses.is_dataclass(obj) and doc.startswith(f"{obj.__name__}("):
        doc = ""
    doc = _ROLE.sub(lambda m: f"`{m.group(2).rsplit('.', 1)[-1] if m.group(1) else m.group(2)}`", doc)
    return doc.replace("``", "`")


def _default(value: Any) -> str:
    """A default value as Python would spell it (``math.inf``, not ``inf``)."""
    if isinstance(value, float) and math.isnan(value):
        return "math.nan"
    if isinstance(value, float) and math.isinf(value):
        return "math.inf" if value > 0 else "-math.inf"
    return repr(value)


def _annotation(a: Any) -> str:
    """An annotation as written (a string under ``from __future__ import annotations``)."""
    return a if isinstance(a, str) else inspect.formatannotation(a)


def _signature(name: str, obj: Any) -> str | None:
    """``name(a: int = 1, ...)`` with the annotations as written, one parameter a line
    when long; None where there is no signature to show."""
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):
        return None
    parts = []
    for p in sig.parameters.values():
        text = p.name
        if p.kind is p.VAR_POSITIONAL:
            text = "*" + text
        elif p.kind is p.VAR_KEYWORD:
            text = "**" + text
        if p.annotation is not p.empty:
            text += f": {_annotation(p.annotation)}"
        if p.default is not p.empty:
            text += f" = {_default(p.default)}"
        parts.append(text)
    ret = sig.return_annotation
    tail = "" if ret is sig.empty or ret in ("None", None) else f" -> {_annotation(ret)}"
    one = f"{name}({', '.join(parts)}){tail}"
    if len(one) <= 88:
        return one
    return f"{name}(\n" + "".join(f"    {p},\n" for p in parts) + f"){tail}"


def _documented(cls: type, name: str, member: Any) -> Any:
    """``member``, or where it has no docstring the nearest one of pointplan's own base
    classes that documents ``name`` (``BiRRT.plan``: ``Planner.plan``'s)."""
    if member.__doc__:
        return member
    for base in cls.__mro__[1:]:
        found = vars(base).get(name)
        found = found.fget if isinstance(found, property) else found
        if found is not None and found.__doc__ and base.__module__.startswith("pointplan."):
            return found
    return member


def _members(cls: type) -> list[tuple[str, Any]]:
    """The public methods and properties a class defines itself, in source order."""
    out = []
    for name, value in vars(cls).items():
        if name.startswith("_"):
            continue
        if isinstance(value, staticmethod | classmethod):
            value = value.__func__
        if inspect.isfunction(value) or isinstance(value, property):
            out.append((name, value))
    return out


def _object_section(module: str, name: str) -> list[str]:
    obj = getattr(importlib.import_module(module), name)
    kind = "class" if inspect.isclass(obj) else "function"
    lines = [f"### {name}", "", f"`{module}.{name}` ({kind})", ""]
    # exceptions and protocols (structural types, never constructed) have no signature to show
    protocol = inspect.isclass(obj) and getattr(obj, "_is_protocol", False)
    sig = None if protocol or (inspect.isclass(obj) and issubclass(obj, BaseException)) else _signature(name, obj)
    if sig:
        lines += ["```python", sig, "```", ""]
    if _doc(obj):
        lines += [_doc(obj), ""]
    if inspect.isclass(obj):
        members = _members(obj)
        if members:
            lines += ["| member | what it does |", "|---|---|"]
            for mname, member in members:
                label = f"`{mname}`" if isinstance(member, property) else f"`{mname}()`"
                summary = _doc(_documented(obj, mname, member.fget if isinstance(member, property) else member))
                summary = summary.split("\n\n")[0]
                lines.append(f"| {label} | {_cell(summary)} |")
            lines.append("")
    return lines


def render_api() -> str:
    lines = [
        "# Python API reference",
        "",
        "The classes and functions a user of pointplan calls, by task, with their signatures and",
        "docstrings, generated from the code by `python scripts/reference_pages.py` (a test fails",
        "when this page and the code disagree). Worked examples: the [guides](../../README.md#documentation).",
        "",
    ]
    lines += [f"- [{title}](#{title.lower().replace(' ', '-')}): {what}" for title, what, _ in API]
    lines.append("")
    for title, what, groups in API:
        lines += [f"## {title}", "", what, ""]
        for module, names in groups:
            for name in names:
                lines += _object_section(module, name)
    return "\n".join(lines).rstrip() + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--check", action="store_true", help="only check that the pages are current (exit 1 if not)")
    args = ap.parse_args(argv)
    stale = []
    for key, text in (("cli", render_cli()), ("api", render_api())):
        page = PAGES[key]
        if args.check:
            if not page.is_file() or page.read_text(encoding="utf-8") != text:
                stale.append(page)
        else:
            page.write_text(text, encoding="utf-8")
            print(f"wrote {page}")
    for page in stale:
        print(f"{page} is out of date: run python scripts/reference_pages.py", file=sys.stderr)
    return 1 if stale else 0


if __name__ == "__main__":
    raise SystemExit(main())
