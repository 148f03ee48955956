"""A user's own data through the command line: capsules observed, hollow outlines, bounds
around a given start and goal, output paths, a missing Ray cluster, Ctrl-C in the demo
and what the demo draws."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pointplan.cli import main
from pointplan.geometry.collision import point_segment_sqdist
from pointplan.geometry.sampling import area_weighted_points, interior_points, surface_points
from pointplan.geometry.shapes import Box, Capsule
from pointplan.robots import make_robot
from pointplan.scenes import Problem, Scene
from pointplan.scenes.io import CloudScenario, EnclosedRegions, load_points_scene


def _outline(low: list[float], high: list[float], spacing: float = 0.01) -> np.ndarray:
    """Points on the four edges of the rectangle ``low .. high``, about ``spacing`` apart."""
    xs = np.arange(low[0], high[0] + spacing / 2, spacing)
    ys = np.arange(low[1], high[1] + spacing / 2, spacing)
    return np.concatenate(
        [np.stack([xs, np.full_like(xs, low[1])], 1), np.stack([xs, np.full_like(xs, high[1])], 1)]
        + [np.stack([np.full_like(ys, low[0]), ys], 1), np.stack([np.full_like(ys, high[0]), ys], 1)]
    )


BOXES = [([0.2, 0.2], [0.5, 0.8]), ([0.6, 0.3], [0.9, 0.6])]


def _inside_a_box(p: np.ndarray) -> bool:
    return any(bool(np.all((p > np.array(lo)) & (p < np.array(hi)))) for lo, hi in BOXES)


@pytest.fixture
def outlines(tmp_path: Path) -> Path:
    path = tmp_path / "outlines.npy"
    np.save(path, np.concatenate([_outline(lo, hi) for lo, hi in BOXES]))
    return path


# ---------------------------------------------------------------------------- capsules
@pytest.mark.parametrize(
    "cap",
    [
        Capsule([0.7, 0.2], [0.9, 0.4], 0.03),
        Capsule([0.5, 0.5], [0.5, 0.5], 0.05),
        Capsule([0.0, 0.1, 0.2], [0.3, -0.2, 0.6], 0.05),
    ],
    ids=["2d", "2d-point", "3d"],
)
def test_capsule_surface_points_lie_on_the_boundary_with_outward_normals(cap: Capsule) -> None:
    p, n = surface_points([cap], 0.01)
    dist = np.sqrt(point_segment_sqdist(p, cap.a[None], cap.b[None])[:, 0])
    assert len(p) > 20 and np.allclose(dist, cap.radius, atol=1e-12)
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    outward = np.sqrt(point_segment_sqdist(p + 1e-3 * n, cap.a[None], cap.b[None])[:, 0])
    assert np.all(outward > dist + 0.9e-3)
    # about `spacing` apart: no point far from its neighbour, the whole outline covered
    gaps = np.sort(np.linalg.norm(p[:, None] - p[None], axis=2), axis=1)[:, 1]
    assert gaps.max() < 0.02
    assert len(interior_points([cap], 0.01, p.min(0) - 0.01, p.max(0) + 0.01)) > 0


def test_capsule_area_weighted_points_lie_on_its_tessellation() -> None:
    cap = Capsule([0.0, 0.0, 0.0], [0.0, 0.4, 0.0], 0.05)
    p, n, owner = area_weighted_points([cap], 2000, np.random.default_rng(0))
    dist = np.sqrt(point_segment_sqdist(p, cap.a[None], cap.b[None])[:, 0])
    assert len(p) == 2000 and np.all(owner == 0) and np.all(np.abs(dist - cap.radius) < 0.01 * cap.radius)
    outward = np.sqrt(point_segment_sqdist(p + 1e-3 * n, cap.a[None], cap.b[None])[:, 0])
    assert np.all(outward > dist)


def test_a_capsule_hides_the_surface_points_inside_it() -> None:
    box = Box([0.5, 0.5], [0.2, 0.2])
    cap = Capsule([0.5, 0.3], [0.5, 0.7], 0.05)
    p, _ = surface_points([box, cap], 0.01)
    dist = np.sqrt(point_segment_sqdist(p, cap.a[None], cap.b[None])[:, 0])
    assert np.all(dist > cap.radius - 1e-9)
    assert np.all(np.any(np.abs(np.abs(p - box.center) - box.half) < 1e-9, axis=1) | (np.abs(dist - cap.radius) < 1e-9))


def _docs_scene(tmp_path: Path) -> Path:
    """The complete 2D example of docs/guide/scene-files.md (box, sphere, capsule, cloud)."""
    (tmp_path / "clouds").mkdir()
    y = np.arange(0.45, 0.75, 0.01)
    np.save(tmp_path / "clouds" / "wall2d.npy", np.stack([np.full_like(y, 0.3), y], 1))
    doc = {
        "format": "pointplan-scene",
        "version": 1,
        "dim": 2,
        "name": "two-rooms",
        "bounds": {"low": [0.0, 0.0], "high": [1.0, 1.0]},
        "robot": "disc2d",
        "obstacles": [
            {"type": "box", "center": [0.5, 0.25], "size": [0.1, 0.5]},
            {"type": "box", "center": [0.5, 0.85], "size": [0.1, 0.3], "angle": 0.2},
            {"type": "sphere", "center": [0.2, 0.7], "radius": 0.08},
            {"type": "capsule", "a": [0.7, 0.2], "b": [0.9, 0.4], "radius": 0.03},
            {"type": "points", "path": "clouds/wall2d.npy"},
        ],
        "problems": [
            {"start": [0.1, 0.1], "goal": [0.9, 0.9]},
            {"start": [0.2, 0.4], "goal": [0.8, 0.6], "tag": "through-the-door"},
        ],
    }
    path = tmp_path / "two-rooms.json"
    path.write_text(json.dumps(doc))
    return path


def test_policy_and_render_on_the_documented_2d_scene_with_a_capsule(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = _docs_scene(tmp_path)
    out = tmp_path / "plan.json"
    assert main(["plan", "--scene", str(scene), "--planner", "policy", "--json", str(out), "--quiet"]) in (0, 1)
    assert len(json.loads(out.read_text())["problems"]) == 2
    png = tmp_path / "render.png"
    assert main(["render", "--scene", str(scene), "--planner", "none", "-o", str(png)]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert "Traceback" not in capsys.readouterr().err


# ---------------------------------------------------------------------------- hollow outlines
def test_enclosed_regions_of_outlines() -> None:
    cloud = np.concatenate([_outline(lo, hi) for lo, hi in BOXES])
    regions = EnclosedRegions(cloud, np.array([0.0, 0.0]), np.array([1.0, 1.0]))
    inside = np.array([[0.3, 0.5], [0.75, 0.45], [0.205, 0.5], [0.895, 0.35]])
    outside = np.array([[0.1, 0.1], [0.55, 0.5], [0.195, 0.5], [0.95, 0.95], [0.75, 0.2], [2.0, 2.0]])
    assert regions.any
    assert regions.contains(inside).all() and not regions.contains(outside).any()
    # an open outline (one side missing) encloses nothing
    open_box = _outline(*BOXES[0])
    open_box = open_box[~((np.abs(open_box[:, 0] - 0.5) < 1e-9) & (open_box[:, 1] > 0.3) & (open_box[:, 1] < 0.7))]
    assert not EnclosedRegions(open_box, np.array([0.0, 0.0]), np.array([1.0, 1.0])).any


def test_drawn_problems_avoid_the_inside_of_outlines(outlines: Path, tmp_path: Path) -> None:
    scene = load_points_scene(outlines)
    problems = CloudScenario(scene, make_robot("disc2d")).problems("test", 40)
    assert not any(_inside_a_box(q) for p in problems for q in (p.start, p.goal))
    out = tmp_path / "o.json"
    assert main(
        ["plan", "--points", str(outlines), "--planner", "straight", "--episodes", "4", "--json", str(out), "--quiet"]
    ) in (0, 1)
    recs = json.loads(out.read_text())["problems"]
    assert len(recs) == 4 and not any(_inside_a_box(np.array(r[k])) for r in recs for k in ("start", "goal"))


def test_a_given_start_inside_an_outline_is_warned_about(outlines: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(
        [
            "plan",
            "--points",
            str(outlines),
            "--planner",
            "straight",
            "--start",
            "0.3,0.5",
            "--goal",
            "0.95,0.9",
            "--quiet",
        ]
    ) in (0, 1)
    err = capsys.readouterr().err
    warnings = [line for line in err.splitlines() if "warning" in line]
    assert len(warnings) == 1 and "--start [0.3, 0.5] lies in a region the point cloud encloses" in warnings[0]
    assert (
        main(
            [
                "plan",
                "--points",
                str(outlines),
                "--planner",
                "straight",
                "--start",
                "0.1,0.1",
                "--goal",
                "0.95,0.9",
                "--quiet",
            ]
        )
        == 0
    )
    assert "warning" not in capsys.readouterr().err


# ---------------------------------------------------------------------------- automatic bounds
def test_automatic_bounds_hold_the_given_start_and_goal(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    y = np.arange(0.0, 1.0, 0.01)
    wall = tmp_path / "wall.npy"
    np.save(wall, np.stack([np.full_like(y, 0.5), y], 1))
    out = tmp_path / "o.json"
    args = ["plan", "--points", str(wall), "--start", "0.1,0.1", "--goal", "0.9,0.1", "--json", str(out), "--quiet"]
    assert main(args) == 0
    assert json.loads(out.read_text())["metrics"]["success_rate"] == 1.0
    scene = load_points_scene(wall, include=[[0.1, 0.1], [0.9, 0.1]])
    assert np.all(scene.low < [0.1, 0.0]) and np.all(scene.high > [0.9, 0.99])
    # bounds given that leave out the start: the message says that --bounds sets them
    assert (
        main(
            [
                "plan",
                "--points",
                str(wall),
                "--bounds",
                "0.3,0,0.7,1",
                "--start",
                "0.1,0.1",
                "--goal",
                "0.6,0.1",
                "--quiet",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "lies outside the bounds" in err and "--bounds sets them" in err


# ---------------------------------------------------------------------------- output paths
def _no_planning(monkeypatch: pytest.MonkeyPatch) -> None:
    import pointplan.evaluation  # noqa: F401

    def refuse(*a: Any, **k: Any) -> Any:
        raise AssertionError("planned before checking the output path")

    monkeypatch.setattr(sys.modules["pointplan.evaluation.evaluate"], "plan_and_check", refuse)


@pytest.mark.parametrize(
    "command",
    [
        ["eval", "--planner", "straight", "--episodes", "2", "--json", "{dir}"],
        ["plan", "--planner", "straight", "--episodes", "2", "--json", "{file}/m.json"],
        ["plan", "--planner", "straight", "--episodes", "2", "-o", "{dir}"],
        ["render", "--planner", "straight", "-o", "{file}/sub/r.png"],
        ["demo", "--episodes", "2", "-o", "{dir}"],
    ],
    ids=["eval-json-dir", "plan-json-under-file", "plan-png-dir", "render-under-file", "demo-dir"],
)
def test_unwritable_outputs_are_refused_before_planning(
    command: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    _no_planning(monkeypatch)
    (tmp_path / "a_file").write_text("x")
    args = [a.format(dir=tmp_path, file=tmp_path / "a_file") for a in command]
    assert main([*args, "--quiet"] if command[0] != "render" else args) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("pointplan: error: ") and "\n" not in err and "Traceback" not in err
    assert "is a directory" in err or "not a directory" in err


def test_an_output_in_a_folder_still_to_make_is_fine(tmp_path: Path) -> None:
    out = tmp_path / "new" / "deeper" / "m.json"
    assert main(["eval", "--planner", "straight", "--episodes", "2", "--json", str(out), "--quiet"]) == 0
    assert out.exists()


# ---------------------------------------------------------------------------- Ray cluster
def test_no_ray_cluster_at_the_address_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    ray = pytest.importorskip("ray")

    def no_cluster(*a: Any, **k: Any) -> None:
        raise ConnectionError("Could not find any running Ray instance.")

    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    monkeypatch.setattr(ray, "init", no_cluster)
    code = main(
        ["train", "--workers", "4", "--address", "auto", "--steps", "1000", "--run-dir", str(tmp_path), "--quiet"]
    )
    err = capsys.readouterr().err.strip()
    assert (
        code == 2
        and err == "pointplan: error: no Ray cluster at auto: start one with `ray start --head`, or leave out --address"
    )
    assert main(["eval", "--address", "ray://head:10001", "--episodes", "2", "--quiet"]) == 2
    assert "no Ray cluster at ray://head:10001" in capsys.readouterr().err


# ---------------------------------------------------------------------------- the demo
def test_ctrl_c_stops_the_whole_demo(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import pointplan.evaluation  # noqa: F401

    ev = sys.modules["pointplan.evaluation.evaluate"]
    real, calls = ev.plan_and_check, []

    def ctrl_c_in_birrt(*a: Any, **k: Any) -> Any:
        calls.append(1)
        if len(calls) == 6 + 4:  # all 6 problems of the policy, then 3 of Bi-RRT
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(ev, "plan_and_check", ctrl_c_in_birrt)
    png = tmp_path / "demo.png"
    assert main(["demo", "--episodes", "6", "-o", str(png), "--quiet"]) == 130
    out = capsys.readouterr().out
    assert len(calls) == 10 and not png.exists()  # the straight line never ran, nothing drawn
    episodes = next(line for line in out.splitlines() if line.startswith("episodes"))
    assert episodes.split() == ["episodes", "3", "3"] and "straight" not in out.split("metric")[1].splitlines()[0]
    assert "interrupted: the table compares the first 3 of the 6 problems" in out and "straight not run" in out


def test_demo_picks_problems_where_the_policy_moved() -> None:
    from pointplan.cli import _demo_picks

    class Rec:
        def __init__(self, success: bool, nodes: int) -> None:
            self.success, self.nodes = success, nodes

    records = [Rec(True, 0), Rec(True, 5), Rec(False, 40), Rec(True, 0), Rec(True, 12), Rec(True, 3)]
    assert _demo_picks(records, 2) == [4, 1]
    assert _demo_picks(records, 8) == [4, 1, 5]
    assert _demo_picks([Rec(True, 0), Rec(False, 3)], 4) == [0]  # only trivial ones: those


def test_demo_draws_the_policy_moving_with_named_titles(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import pointplan.viz.plot2d as plot2d

    drawn: dict[str, Any] = {}
    monkeypatch.setattr(
        plot2d,
        "render_grid",
        lambda problems, results, out, robot, titles=None, **k: drawn.update(results=results, titles=titles),
    )
    assert main(["demo", "--episodes", "12", "--figures", "4", "-o", str(tmp_path / "d.png"), "--quiet"]) == 0
    assert len(drawn["titles"]) == 4 and all(r.nodes > 0 and r.success for r in drawn["results"])
    assert [r.nodes for r in drawn["results"]] == sorted((r.nodes for r in drawn["results"]), reverse=True)
    assert all(
        t.startswith("policy on narrow2d, test problem ")
        and t.endswith(f"\n{r.nodes} step" + ("s" if r.nodes != 1 else ""))
        for t, r in zip(drawn["titles"], drawn["results"])
    )


def test_3d_demo_draws_the_policy_moving_with_named_titles(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import pointplan.viz.plot3d as plot3d

    drawn: dict[str, Any] = {}
    monkeypatch.setattr(
        plot3d,
        "render_grid_3d",
        lambda problems, robot, paths, out, cols=3, titles=None, **k: drawn.update(titles=titles),
    )
    monkeypatch.setattr(plot3d, "render_rollout_gif", lambda *a, **k: None)
    assert main(["demo", "--env", "boxes3d", "--episodes", "12", "-o", str(tmp_path / "d.png"), "--quiet"]) == 0
    titles = drawn["titles"]
    policy, birrt = titles[: len(titles) // 2], titles[len(titles) // 2 :]
    assert policy and all(
        t.startswith("policy on boxes3d, test problem ") and not t.endswith(": 0 steps") for t in policy
    )
    assert all(t.startswith("Bi-RRT on boxes3d, test problem ") for t in birrt)


def test_the_robot_is_drawn_at_its_size_above_the_markers() -> None:
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    from pointplan.viz.plot2d import draw_problem

    robot = make_robot("disc2d")
    problem = Problem(
        Scene([Box([0.5, 0.5], [0.1, 0.1])], low=np.zeros(2), high=np.ones(2)),
        np.array([0.1, 0.1]),
        np.array([0.9, 0.8]),
    )
    ax = Figure().subplots()
    draw_problem(ax, problem, robot)
    marker_z = max(line.get_zorder() for line in ax.lines if len(line.get_xdata()))
    for q in (problem.start, problem.goal):
        bodies = [
            p for p in ax.patches if isinstance(p, Circle) and np.allclose(p.center, q) and np.isclose(p.radius, 0.01)
        ]
        assert bodies and all(b.get_zorder() > marker_z and b.get_edgecolor()[3] == 1.0 for b in bodies)
    assert "disc2d, radius 0.01" in ax.get_legend_handles_labels()[1]


def test_the_sphere_is_outlined_at_its_radius_in_3d() -> None:
    from pointplan.viz.plot3d import render_problem_3d

    robot = make_robot("sphere3d")
    scene = Scene([Box([0.0, 0.0, 0.0], [0.2, 0.2, 0.2])], low=-np.ones(3), high=np.ones(3))
    problem = Problem(scene, np.array([-0.5, -0.5, -0.5]), np.array([0.5, 0.6, 0.4]))
    fig = render_problem_3d(problem, robot)
    ax = fig.axes[0]
    for q in (problem.start, problem.goal):
        rings = [
            line
            for line in ax.lines
            if len(line.get_data_3d()[0]) > 10
            and np.allclose(np.linalg.norm(np.stack(line.get_data_3d(), 1) - q, axis=1), 0.03)
        ]
        assert len(rings) == 1
    assert "sphere3d, radius 0.03" in [t.get_text() for t in fig.legends[0].get_texts()]


def test_eval_json_records_carry_start_and_goal(tmp_path: Path) -> None:
    from pointplan.scenes.scenarios import make_scenario

    out = tmp_path / "m.json"
    assert main(["eval", "--planner", "straight", "--episodes", "3", "--json", str(out), "--quiet"]) == 0
    recs = json.loads(out.read_text())["problems"]
    expected = make_scenario("narrow2d").problems("test", 3, seed=0)
    assert [r["tag"] for r in recs] == [p.tag for p in expected]
    for r, p in zip(recs, expected):
        assert np.allclose(r["start"], p.start) and np.allclose(r["goal"], p.goal)
    assert main(["eval", "--planner", "straight,birrt", "--episodes", "2", "--json", str(out), "--quiet"]) == 0
    both = json.loads(out.read_text())["planners"]
    assert all(len(both[n]["problems"]) == 2 and "start" in both[n]["problems"][0] for n in ("straight", "birrt"))


# ---------------------------------------------------------------------------- messages
def test_an_empty_ply_holds_no_points(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    header = "ply\nformat {}\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    for fmt in ("ascii 1.0", "binary_little_endian 1.0"):
        (tmp_path / "empty.ply").write_text(header.format(fmt))
        assert main(["plan", "--points", str(tmp_path / "empty.ply"), "--quiet"]) == 2
        err = capsys.readouterr().err
        assert (
            "'empty.ply' holds no points (its vertex element has 0 vertices)" in err and "no vertex element" not in err
        )
    (tmp_path / "faces.ply").write_text(
        "ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n"
    )
    assert main(["plan", "--points", str(tmp_path / "faces.ply"), "--quiet"]) == 2
    assert "'faces.ply' has no vertex element" in capsys.readouterr().err


@pytest.mark.parametrize(("n", "said"), [(1, "holds 1 point:"), (2, "holds 2 points:")])
def test_too_few_points_are_counted_in_good_english(
    tmp_path: Path, n: int, said: str, capsys: pytest.CaptureFixture[str]
) -> None:
    np.save(tmp_path / "few.npy", np.arange(3.0 * n).reshape(n, 3) + 1.0)
    assert main(["plan", "--points", str(tmp_path / "few.npy"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert said in err and "too few to estimate normals" in err


def test_unknown_environments_list_the_names_as_typed(capsys: pytest.CaptureFixture[str]) -> None:
    from pointplan.scenes.scenarios import make_scenario, scenario_names

    assert main(["eval", "--env", "narrow3d", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "narrow2d-ends, narrow2d-many, narrow2d-narrow, narrow2d-manynarrow" in err and "narrow2dends" not in err
    for name in scenario_names():  # every listed name is accepted as listed
        if not name.startswith("mbm-"):
            assert make_scenario(name).name.replace("-", "") == name.replace("-", "")
    assert make_scenario("narrow2dends").name == make_scenario("narrow2d_ends").name == "narrow2d-ends"


@pytest.mark.parametrize(
    ("argv", "prog", "message"),
    [
        (["plan", "--episodes", "0"], "pointplan plan", "argument --episodes: must be at least 1, got 0"),
        (["eval", "--bogus"], "pointplan eval", "unrecognized arguments: --bogus"),
        (["plan", "--start"], "pointplan plan", "argument --start: expected one argument"),
        (["nope"], "pointplan", "argument command: invalid choice: 'nope'"),
        ([], "pointplan", "the following arguments are required: command"),
    ],
)
def test_argument_errors_come_first_with_a_hint_not_the_usage(
    argv: list[str], prog: str, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith(f"{prog}: error: ") and message in err[0], err
    assert err[1:] == [f"(`{prog} -h` for help)"] and "usage:" not in " ".join(err)
