"""The scene file format: obstacles, bounds, an optional robot and planning problems in JSON.

A scene file looks like this (2D; see ``docs/guide/scene-files.md`` for every field)::

    {
      "format": "pointplan-scene",
      "version": 1,
      "dim": 2,
      "bounds": {"low": [0, 0], "high": [1, 1]},
      "robot": "disc2d",
      "obstacles": [
        {"type": "box", "center": [0.5, 0.5], "size": [0.2, 0.1], "angle": 0.3},
        {"type": "sphere", "center": [0.2, 0.8], "radius": 0.05}
      ],
      "problems": [{"start": [0.1, 0.1], "goal": [0.9, 0.9]}]
    }

Units are metres and radians. Boxes take *full* side lengths; rotations are an angle (2D)
or a quaternion ``[x, y, z, w]`` (3D). Mesh and point-cloud obstacles point to files given
relative to the JSON file.

Every problem with the input raises :class:`SceneFormatError`, whose message names the
file and the field, e.g. ``scene.json: obstacles[2].size: expected 3 positive numbers,
got [1, -2]``.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
from numpy.typing import NDArray

from ..geometry import lie
from ..geometry.clouds import (
    DEFAULT_K,
    DEPTH_FILE_SUFFIXES,
    POINT_FILE_SUFFIXES,
    CloudError,
    camera_pose,
    check_normals,
    estimate_normals,
    one_line,
    read_depth_cloud,
    read_point_file,
)
from ..geometry.shapes import Box, Capsule, Cylinder, Mesh, PointCloud, Shape, Sphere
from ..robots.base import Robot
from .base import FixedScenario
from .scene import Problem, Scene

Array = NDArray[np.float64]

FORMAT = "pointplan-scene"
VERSION = 1

#: robots a scene file may name: workspace dimension and configuration length
ROBOT_DIMS: dict[str, tuple[int, int]] = {
    "disc2d": (2, 2),
    "sphere3d": (3, 3),
    "sshape": (3, 7),
    "sshape-oriented": (3, 7),
}

OBSTACLE_TYPES = ("box", "sphere", "capsule", "cylinder", "mesh", "points")
_DEPTH_FIELDS = ("intrinsics", "camera_pose", "depth_scale", "stride")
_POINTS_FIELDS = ("type", "path", "depth", "k", "viewpoint", *_DEPTH_FIELDS)

_TOP_FIELDS = ("format", "version", "dim", "bounds", "robot", "obstacles", "problems", "name")
_PROBLEM_FIELDS = ("start", "goal", "tag")


class SceneFormatError(ValueError):
    """A scene file that cannot be read. ``file`` and ``field`` (e.g. ``obstacles[2].size``)
    say where; the message reads ``<file>: <field>: <what is wrong>``."""

    def __init__(self, file: str, field: str, detail: str) -> None:
        self.file = file
        self.field = field
        self.detail = detail
        super().__init__(f"{file}: {field}: {detail}" if field else f"{file}: {detail}")


@dataclass
class SceneFile:
    """The contents of a scene file."""

    scene: Scene
    problems: list[Problem] = field(default_factory=list)
    #: robot name (``disc2d``, ``sphere3d``, ``sshape``) or ``None`` if the file names none
    robot: str | None = None


# ============================================================================ reading
def _show(value: Any, limit: int = 60) -> str:
    """A short JSON rendering of an offending value for error messages."""
    try:
        text = json.dumps(value, allow_nan=True)
    except (TypeError, ValueError):
        text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _kind(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, dict):
        return "an object"
    return type(value).__name__


def _is_number(x: Any) -> bool:
    if not isinstance(x, (int, float)) or isinstance(x, bool):
        return False
    try:
        return math.isfinite(x)
    except OverflowError:  # an integer too large for a float
        return False


def _count(n: int, word: str) -> str:
    """``1 point``, ``3 points``."""
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def _join(prefix: str, key: str | int) -> str:
    if isinstance(key, int):
        return f"{prefix}[{key}]"
    return f"{prefix}.{key}" if prefix else key


class _Reader:
    """Validating reader of one parsed document; ``file`` is used in messages, ``base`` to
    resolve mesh and point files."""

    def __init__(self, file: str, base: Path) -> None:
        self.file = file
        self.base = base

    def fail(self, where: str, detail: str) -> NoReturn:
        raise SceneFormatError(self.file, where, detail)

    # ------------------------------------------------------------------ primitives
    def obj(self, value: Any, where: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            self.fail(where, f"expected an object, got {_kind(value)} {_show(value)}")
        return value

    def get(self, obj: dict[str, Any], key: str, where: str) -> Any:
        if key not in obj:
            self.fail(_join(where, key), "missing required field")
        return obj[key]

    def only(self, obj: dict[str, Any], allowed: Sequence[str], where: str, what: str) -> None:
        for key in obj:
            if key not in allowed:
                self.fail(
                    _join(where, key) if isinstance(key, str) else where,
                    f"unknown field for {what} (allowed: {', '.join(allowed)})",
                )

    def number(self, value: Any, where: str, positive: bool = False) -> float:
        ok = _is_number(value) and (not positive or value > 0)
        if not ok:
            want = "a positive number" if positive else "a finite number"
            self.fail(where, f"expected {want}, got {_show(value)}")
        return float(value)

    def vector(self, value: Any, where: str, n: int, positive: bool = False, nonzero: bool = False) -> Array:
        ok = (
            isinstance(value, list)
            and len(value) == n
            and all(_is_number(x) for x in value)
            and (not positive or all(x > 0 for x in value))
        )
        if not ok:
            adj = "positive numbers" if positive else "numbers"
            self.fail(where, f"expected {n} {adj}, got {_show(value)}")
        v = np.array(value, dtype=np.float64)
        if nonzero and not np.linalg.norm(v) > 0:
            self.fail(where, f"expected {n} numbers, not all zero, got {_show(value)}")
        return v

    def quaternion(self, value: Any, where: str) -> Array:
        """A rotation matrix from ``[x, y, z, w]`` (normalised here)."""
        return lie.quat_to_matrix(self.vector(value, where, 4, nonzero=True))

    def file_path(self, value: Any, where: str, suffixes: Sequence[str] | None = None) -> Path:
        if not isinstance(value, str) or not value:
            self.fail(where, f"expected a file name (a string), got {_show(value)}")
        path = Path(value)
        if not path.is_absolute():
            path = self.base / path
        if suffixes is not None and path.suffix.lower() not in suffixes:
            self.fail(
                where,
                f"unsupported file type {path.suffix or '(none)'!r} of {value!r}; use one of {', '.join(suffixes)}",
            )
        if not path.is_file():
            self.fail(where, f"file not found: {value!r} (looked for {os.path.abspath(path)})")
        return path

    # ------------------------------------------------------------------ document
    def document(self, doc: Any) -> SceneFile:
        doc = self.obj(doc, "(top level)")
        fmt = self.get(doc, "format", "")
        if fmt != FORMAT:
            self.fail("format", f"expected {FORMAT!r}, got {_show(fmt)}: is this a pointplan scene file?")
        version = self.get(doc, "version", "")
        if not isinstance(version, int) or isinstance(version, bool):
            self.fail("version", f"expected an integer, got {_show(version)}")
        if version != VERSION:
            self.fail("version", f"unsupported version {version}; this pointplan reads version {VERSION}")
        self.only(doc, _TOP_FIELDS, "", "a scene file")
        dim = self.get(doc, "dim", "")
        if dim not in (2, 3) or isinstance(dim, bool) or not isinstance(dim, int):
            self.fail("dim", f"expected 2 or 3, got {_show(dim)}")
        bounds = self.obj(self.get(doc, "bounds", ""), "bounds")
        self.only(bounds, ("low", "high"), "bounds", "bounds")
        low = self.vector(self.get(bounds, "low", "bounds"), "bounds.low", dim)
        high = self.vector(self.get(bounds, "high", "bounds"), "bounds.high", dim)
        if np.any(high <= low):
            self.fail(
                "bounds.high",
                f"must exceed bounds.low in every axis, got low {_show(low.tolist())}, high {_show(high.tolist())}",
            )

        robot = doc.get("robot")
        if robot is not None:
            if not isinstance(robot, str) or robot not in ROBOT_DIMS:
                self.fail("robot", f"unknown robot {_show(robot)}; known: {', '.join(ROBOT_DIMS)}")
            if ROBOT_DIMS[robot][0] != dim:
                self.fail("robot", f"{robot} is a {ROBOT_DIMS[robot][0]}D robot but the scene is {dim}D")

        name = doc.get("name", "")
        if not isinstance(name, str):
            self.fail("name", f"expected a string, got {_show(name)}")

        obstacles = self.get(doc, "obstacles", "")
        if not isinstance(obstacles, list):
            self.fail("obstacles", f"expected a list, got {_kind(obstacles)} {_show(obstacles)}")
        shapes = [self.obstacle(o, f"obstacles[{i}]", dim) for i, o in enumerate(obstacles)]
        scene = Scene(obstacles=shapes, low=low, high=high, name=name or Path(self.file).stem)

        problems_doc = doc.get("problems", [])
        if not isinstance(problems_doc, list):
            self.fail("problems", f"expected a list, got {_kind(problems_doc)} {_show(problems_doc)}")
        problems = self.problems(problems_doc, scene, robot)
        return SceneFile(scene=scene, problems=problems, robot=robot)

    # ------------------------------------------------------------------ obstacles
    def obstacle(self, entry: Any, where: str, dim: int) -> Shape:
        entry = self.obj(entry, where)
        kind = self.get(entry, "type", where)
        if not isinstance(kind, str) or kind not in OBSTACLE_TYPES:
            self.fail(_join(where, "type"), f"unknown obstacle type {_show(kind)}; known: {', '.join(OBSTACLE_TYPES)}")
        if kind in ("cylinder", "mesh") and dim != 3:
            self.fail(_join(where, "type"), f"{kind} obstacles need a 3D scene (dim is {dim})")
        at = lambda key: _join(where, key)
        need = lambda key: self.get(entry, key, where)

        if kind == "box":
            rot_key = "angle" if dim == 2 else "quaternion"
            self.only(entry, ("type", "center", "size", rot_key), where, f"a {dim}D box")
            center = self.vector(need("center"), at("center"), dim)
            size = self.vector(need("size"), at("size"), dim, positive=True)
            if dim == 2:
                rot = lie.so2_exp(np.asarray(self.number(entry.get("angle", 0.0), at("angle"))))
            else:
                rot = self.quaternion(entry["quaternion"], at("quaternion")) if "quaternion" in entry else np.eye(3)
            return Box(center=center, size=size, rotation=rot)
        if kind == "sphere":
            self.only(entry, ("type", "center", "radius"), where, "a sphere")
            return Sphere(
                center=self.vector(need("center"), at("center"), dim),
                radius=self.number(need("radius"), at("radius"), positive=True),
            )
        if kind == "capsule":
            self.only(entry, ("type", "a", "b", "radius"), where, "a capsule")
            return Capsule(
                a=self.vector(need("a"), at("a"), dim),
                b=self.vector(need("b"), at("b"), dim),
                radius=self.number(need("radius"), at("radius"), positive=True),
            )
        if kind == "cylinder":
            self.only(entry, ("type", "center", "radius", "length", "quaternion"), where, "a cylinder")
            center = self.vector(need("center"), at("center"), 3)
            radius = self.number(need("radius"), at("radius"), positive=True)
            length = self.number(need("length"), at("length"), positive=True)
            rot = self.quaternion(entry["quaternion"], at("quaternion")) if "quaternion" in entry else np.eye(3)
            return Cylinder(center=center, radius=radius, length=length, rotation=rot)
        if kind == "mesh":
            self.only(entry, ("type", "path", "scale", "position", "quaternion"), where, "a mesh")
            path = self.file_path(need("path"), at("path"))
            scale = np.ones(3)
            if "scale" in entry:
                s = entry["scale"]
                scale = (
                    np.full(3, self.number(s, at("scale"), positive=True))
                    if not isinstance(s, list)
                    else self.vector(s, at("scale"), 3, positive=True)
                )
            pos = self.vector(entry["position"], at("position"), 3) if "position" in entry else np.zeros(3)
            rot = self.quaternion(entry["quaternion"], at("quaternion")) if "quaternion" in entry else np.eye(3)
            vertices, faces = self.mesh_file(path, at("path"))
            return Mesh(vertices=(vertices * scale) @ rot.T + pos, faces=faces, source=path)
        return self.points_obstacle(entry, where, dim)

    def points_obstacle(self, entry: dict[str, Any], where: str, dim: int) -> PointCloud:
        """A ``points`` obstacle: a point file (normals read or estimated) or a depth image
        (normals from its pixel grid)."""
        at = lambda key: _join(where, key)
        self.only(entry, _POINTS_FIELDS, where, "a point cloud")
        has_path, has_depth = "path" in entry, "depth" in entry
        if has_path == has_depth:
            self.fail(where, "a points obstacle needs exactly one of 'path' (a point file) and 'depth' (a depth image)")
        for key in _DEPTH_FIELDS if not has_depth else ("k",):
            if key in entry:
                what = (
                    "a depth image ('depth')"
                    if not has_depth
                    else "a point file ('path'): a depth image's normals come from its pixel grid"
                )
                self.fail(at(key), f"only for {what}")
        k = DEFAULT_K
        if "k" in entry:
            k = entry["k"]
            if not isinstance(k, int) or isinstance(k, bool) or k < 3:
                self.fail(at("k"), f"expected an integer of at least 3 (neighbours of the normal fit), got {_show(k)}")
        viewpoint = self.vector(entry["viewpoint"], at("viewpoint"), dim) if "viewpoint" in entry else None

        if has_depth:
            return self.depth_obstacle(entry, where, dim, viewpoint)
        path = self.file_path(entry["path"], at("path"), POINT_FILE_SUFFIXES)
        try:
            points, normals = read_point_file(path)
        except CloudError as exc:
            self.fail(at("path"), str(exc))
        points, normals = self.fit_dimension(points, normals, path.name, at("path"), dim)
        try:
            if normals is None:
                if len(points) < dim + 1:
                    self.fail(
                        at("path"),
                        f"{path.name!r} holds {_count(len(points), 'point')}: too few to estimate normals (give normals in the file)",
                    )
                normals = estimate_normals(points, k=k, viewpoint=viewpoint)
            else:
                normals = check_normals(normals, path.name)
        except CloudError as exc:
            self.fail(at("path"), str(exc))
        return PointCloud(points=points, normals=normals, source=path)

    def fit_dimension(
        self, points: Array, normals: Array | None, name: str, where: str, dim: int
    ) -> tuple[Array, Array | None]:
        """Points (and normals) with ``dim`` columns: a 2D scene takes flat 3D clouds (z = 0)."""
        c = points.shape[1]
        if c == dim:
            return points, normals
        if dim == 2 and c == 3:
            if np.any(points[:, 2] != 0.0):
                self.fail(
                    where,
                    f"points file {name!r} holds 3D points (z is not 0 everywhere) but the scene is 2D; a 2D cloud has z = 0",
                )
            if normals is not None and np.any(
                np.abs(normals[:, 2]) > 1e-6 * np.maximum(np.linalg.norm(normals, axis=1), 1e-300)
            ):
                self.fail(where, f"points file {name!r}: normals of a 2D cloud must lie in the plane (normal z = 0)")
            return points[:, :2], None if normals is None else normals[:, :2]
        self.fail(where, f"points file {name!r} holds {c}D points but the scene is {dim}D")

    def depth_obstacle(self, entry: dict[str, Any], where: str, dim: int, viewpoint: Array | None) -> PointCloud:
        """A ``points`` obstacle of a depth image: normals towards the camera, or towards
        ``viewpoint`` when one is given."""
        at = lambda key: _join(where, key)
        if dim != 3:
            self.fail(at("depth"), f"depth images need a 3D scene (dim is {dim})")
        path = self.file_path(entry["depth"], at("depth"), DEPTH_FILE_SUFFIXES)
        points, normals = self.depth_cloud(entry, path, where)
        if viewpoint is not None:
            away = np.einsum("pi,pi->p", normals, viewpoint - points) < 0
            normals = np.where(away[:, None], -normals, normals)
        return PointCloud(points=points, normals=normals, source=path)

    def depth_cloud(self, entry: dict[str, Any], path: Path, where: str) -> tuple[Array, Array]:
        """World points and normals of a depth-image obstacle."""
        at = lambda key: _join(where, key)
        intr = self.obj(self.get(entry, "intrinsics", where), at("intrinsics"))
        self.only(intr, ("fx", "fy", "cx", "cy"), at("intrinsics"), "intrinsics")
        fx, fy = (
            self.number(self.get(intr, key, at("intrinsics")), _join(at("intrinsics"), key), positive=True)
            for key in ("fx", "fy")
        )
        cx, cy = (
            self.number(self.get(intr, key, at("intrinsics")), _join(at("intrinsics"), key)) for key in ("cx", "cy")
        )
        pose = np.eye(4)
        if "camera_pose" in entry:
            cam = self.obj(entry["camera_pose"], at("camera_pose"))
            self.only(cam, ("position", "quaternion"), at("camera_pose"), "a camera pose")
            if "position" in cam:
                pose[:3, 3] = self.vector(cam["position"], _join(at("camera_pose"), "position"), 3)
            if "quaternion" in cam:
                pose[:3, :3] = self.quaternion(cam["quaternion"], _join(at("camera_pose"), "quaternion"))
        scale = self.number(entry["depth_scale"], at("depth_scale"), positive=True) if "depth_scale" in entry else None
        stride = entry.get("stride", 1)
        if not isinstance(stride, int) or isinstance(stride, bool) or stride < 1:
            self.fail(at("stride"), f"expected a positive integer, got {_show(stride)}")
        try:
            return read_depth_cloud(path, (fx, fy, cx, cy), pose, depth_scale=scale, stride=stride)
        except CloudError as exc:
            self.fail(at("depth"), str(exc))

    def mesh_file(self, path: Path, where: str) -> tuple[Array, NDArray[np.int64]]:
        try:
            import trimesh
        except ImportError:  # pragma: no cover - trimesh is installed with the test extras
            self.fail(where, "mesh obstacles need the 'trimesh' package (pip install trimesh)")
        try:
            mesh = trimesh.load(str(path), force="mesh", process=False)
        except Exception as exc:  # trimesh raises many kinds of errors on bad files
            self.fail(where, f"cannot load mesh {path.name!r}: {one_line(exc)}")
        vertices = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), np.float64)
        faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), np.int64)
        if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
            self.fail(where, f"mesh {path.name!r} contains no triangles")
        if not np.all(np.isfinite(vertices)) or faces.min() < 0 or faces.max() >= len(vertices):
            self.fail(where, f"mesh {path.name!r} has invalid vertices or faces")
        return vertices, faces

    # ------------------------------------------------------------------ problems
    def problems(self, entries: list[Any], scene: Scene, robot: str | None) -> list[Problem]:
        dim = scene.dim
        # the configuration length: the robot's, or (no robot named) whatever the first
        # start holds among the lengths of the robots of this dimension
        n_config = ROBOT_DIMS[robot][1] if robot is not None else None
        allowed = sorted({c for d, c in ROBOT_DIMS.values() if d == dim})
        out: list[Problem] = []
        for i, entry in enumerate(entries):
            where = f"problems[{i}]"
            entry = self.obj(entry, where)
            self.only(entry, _PROBLEM_FIELDS, where, "a problem")
            tag = entry.get("tag", f"{scene.name}/{i}")
            if not isinstance(tag, str):
                self.fail(_join(where, "tag"), f"expected a string, got {_show(tag)}")
            q = {}
            for key in ("start", "goal"):
                at = _join(where, key)
                value = self.get(entry, key, where)
                if n_config is None:
                    if not (isinstance(value, list) and len(value) in allowed):
                        names = " or ".join(str(a) for a in allowed)
                        self.fail(
                            at, f"expected {names} numbers (a configuration of a {dim}D robot), got {_show(value)}"
                        )
                    n_config = len(value)
                q[key] = self.configuration(self.vector(value, at, n_config), at, scene)
            out.append(Problem(scene=scene, start=q["start"], goal=q["goal"], tag=tag))
        return out

    def configuration(self, q: Array, where: str, scene: Scene) -> Array:
        dim = scene.dim
        pos = q[:dim]
        if np.any(pos < scene.low) or np.any(pos > scene.high):
            self.fail(
                where,
                f"position {_show(pos.tolist())} lies outside the bounds {_show(scene.low.tolist())} .. {_show(scene.high.tolist())}",
            )
        if len(q) > dim:  # (x, y, z, qx, qy, qz, qw)
            norm = np.linalg.norm(q[dim:])
            if not norm > 1e-9:
                self.fail(where, f"orientation quaternion {_show(q[dim:].tolist())} is zero")
            q = np.concatenate([pos, q[dim:] / norm])
        return q


def load_scene(path: str | os.PathLike[str]) -> SceneFile:
    """Read a scene file. Raises :class:`SceneFormatError` naming the file and the field for
    any malformed or unsupported input."""
    path = Path(path)
    name = str(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise SceneFormatError(name, "", f"cannot read file: {exc.strerror or exc}") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise SceneFormatError(name, "", f"not UTF-8 text (byte {exc.start})") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise SceneFormatError(name, "", f"invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}") from None
    except RecursionError:
        raise SceneFormatError(name, "", "invalid JSON: nested too deeply") from None
    return _Reader(name, path.parent).document(doc)


def load_points_scene(
    path: str | os.PathLike[str],
    dim: int | None = None,
    bounds: tuple[Sequence[float] | np.ndarray, Sequence[float] | np.ndarray] | None = None,
    pad: float = 0.1,
    k: int = DEFAULT_K,
    viewpoint: Sequence[float] | None = None,
    include: Sequence[Sequence[float] | np.ndarray] = (),
) -> Scene:
    """A scene made of one point file (``.ply``, ``.pcd``, ``.npy``, ``.xyz``, ...), as a
    ``points`` obstacle of a scene file would read it (normals estimated when the file has
    none).

    ``dim`` defaults to 2 for a cloud of 2 columns or a flat one (z = 0 everywhere), else
    3. ``bounds`` is ``(low, high)``; without it the bounding box of the cloud and of the
    positions in ``include`` (the first ``dim`` numbers of each, e.g. a start and a goal)
    is grown by ``pad`` times its largest side on every side. Errors are
    :class:`SceneFormatError` naming the file.
    """
    path = Path(path)
    name = str(path)
    reader = _Reader(name, path.parent)
    if not path.is_file():
        raise SceneFormatError(name, "", "file not found")
    if dim is None:
        try:
            points, _ = read_point_file(path)
        except CloudError as exc:
            raise SceneFormatError(name, "", str(exc)) from None
        dim = 2 if points.shape[1] == 2 or (points.shape[1] == 3 and np.all(points[:, 2] == 0.0)) else 3
    entry: dict[str, Any] = {"type": "points", "path": str(path.resolve()), "k": int(k)}
    if viewpoint is not None:
        entry["viewpoint"] = [float(x) for x in viewpoint]
    cloud = reader.points_obstacle(entry, "", dim)
    return _cloud_scene(cloud, name, bounds, pad, include)


def load_depth_scene(
    path: str | os.PathLike[str],
    intrinsics: Sequence[float] | np.ndarray,
    pose: Sequence[float] | np.ndarray | None = None,
    depth_scale: float | None = None,
    bounds: tuple[Sequence[float] | np.ndarray, Sequence[float] | np.ndarray] | None = None,
    pad: float = 0.1,
    include: Sequence[Sequence[float] | np.ndarray] = (),
    stride: int = 1,
) -> Scene:
    """A 3D scene made of the points of one depth image (``.png``, ``.tif``, ``.npy``),
    with normals from its pixel grid: see
    :func:`~pointplan.geometry.clouds.read_depth_cloud` for ``intrinsics`` (``fx, fy, cx,
    cy``), ``pose`` (the camera in the world: ``x, y, z, qx, qy, qz, qw`` or a 4 x 4
    matrix), ``depth_scale`` and ``stride``.

    Without ``bounds`` (``(low, high)``) the workspace is the box around the points, the
    camera and the positions in ``include``, grown by ``pad`` times its largest side.
    Errors are :class:`SceneFormatError` naming the file.
    """
    path = Path(path)
    name = str(path)
    if not path.is_file():
        raise SceneFormatError(name, "", "file not found")
    try:
        camera = np.zeros(3) if pose is None else camera_pose(pose)[:3, 3]
        points, normals = read_depth_cloud(path, intrinsics, pose, depth_scale=depth_scale, stride=stride)
    except CloudError as exc:
        raise SceneFormatError(name, "", str(exc)) from None
    cloud = PointCloud(points=points, normals=normals, source=path)
    return _cloud_scene(cloud, name, bounds, pad, [*include, camera])


def _cloud_scene(
    cloud: PointCloud,
    name: str,
    bounds: tuple[Sequence[float] | np.ndarray, Sequence[float] | np.ndarray] | None,
    pad: float,
    include: Sequence[Sequence[float] | np.ndarray],
) -> Scene:
    """A scene of one cloud in ``bounds``, or in the padded box of the cloud and ``include``."""
    dim = cloud.points.shape[1]
    if bounds is None:
        extra = [np.asarray(q, np.float64).reshape(-1)[:dim] for q in include if np.asarray(q).size >= dim]
        box = np.concatenate([cloud.points, np.reshape(extra, (-1, dim))])
        lo, hi = box.min(0), box.max(0)
        margin = pad * max(float(np.max(hi - lo)), 1e-3)
        low, high = lo - margin, hi + margin
    else:
        low, high = (np.asarray(b, np.float64).reshape(-1) for b in bounds)
        if low.shape != (dim,) or high.shape != (dim,) or np.any(high <= low):
            raise SceneFormatError(
                name,
                "bounds",
                f"expected {dim} numbers low and high with low < high, got {low.tolist()} and {high.tolist()}",
            )
    return Scene(obstacles=[cloud], low=low, high=high, name=Path(name).stem)


# ============================================================================ enclosed regions
class EnclosedRegions:
    """Where the points of a 2D cloud wall free space in (the inside of an obstacle scanned
    as its outline, say).

    The points are rasterised on a grid over the bounds with cells of twice their typical
    spacing (the median nearest-neighbour distance; at most 2048 cells a side), free cells
    are flood-filled (4-connected) from the bounds' border, and the free cells the fill does
    not reach are enclosed. A position in a cell holding points is judged from the side of
    the nearest point it lies on: at 1.5 cells from that point, away from it through the
    position (or, where that lands among points too, by the nearest free cell around it)."""

    def __init__(self, points: Array, low: Array, high: Array, cell: float | None = None) -> None:
        from scipy import ndimage

        self.low, self.high = np.asarray(low, np.float64), np.asarray(high, np.float64)
        p = np.asarray(points, np.float64)
        p = p[np.all((p >= self.low) & (p <= self.high), axis=1)]
        if cell is None:
            cell = 2.0 * _typical_spacing(p)
        self.cell = max(float(cell), float(np.max(self.high - self.low)) / 2048, 1e-9)
        shape = tuple(int(n) for n in np.maximum(np.ceil((self.high - self.low) / self.cell), 1).astype(int))
        self.wall = np.zeros(shape, dtype=bool)
        if len(p):
            self.wall[tuple(self._index(p).T)] = True
        labels, _ = ndimage.label(~self.wall)
        edge = np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]])
        self.enclosed = (labels > 0) & ~np.isin(labels, edge[edge > 0])
        self._points = p

    def _index(self, pos: Array) -> NDArray[np.int64]:
        idx = np.floor((pos - self.low) / self.cell).astype(np.int64)
        return np.clip(idx, 0, np.array(self.wall.shape) - 1)

    @property
    def any(self) -> bool:
        """Does the cloud enclose any free cell?"""
        return bool(self.enclosed.any())

    def contains(self, positions: Array) -> NDArray[np.bool_]:
        """Whether each position ``(N, 2)`` lies in an enclosed region."""
        pos = np.asarray(positions, np.float64).reshape(-1, 2)
        out = np.zeros(len(pos), dtype=bool)
        inside = np.all((pos >= self.low) & (pos <= self.high), axis=1)
        idx = self._index(pos)
        out[inside] = self.enclosed[idx[inside, 0], idx[inside, 1]]
        on_wall = np.flatnonzero(inside & self.wall[idx[:, 0], idx[:, 1]])
        if len(on_wall):
            from scipy.spatial import cKDTree

            dist, near = cKDTree(self._points).query(pos[on_wall])
            for k, d, j in zip(on_wall, dist, near):
                probe = (
                    self._points[j] + (pos[k] - self._points[j]) / max(d, 1e-12) * 1.5 * self.cell if d > 0 else pos[k]
                )
                cell = self._index(probe)
                free = bool(np.all((probe >= self.low) & (probe <= self.high))) and not self.wall[cell[0], cell[1]]
                out[k] = bool(self.enclosed[cell[0], cell[1]]) if free else self._nearest_free(pos[k], idx[k])
        return out

    def _nearest_free(self, pos: Array, idx: NDArray[np.int64]) -> bool:
        """The verdict of the free cell nearest ``pos`` among the 3 x 3 cells around its own
        (enclosed when all of them hold points)."""
        best, verdict = np.inf, True
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                i, j = int(idx[0]) + di, int(idx[1]) + dj
                if not (0 <= i < self.wall.shape[0] and 0 <= j < self.wall.shape[1]) or self.wall[i, j]:
                    continue
                d = float(np.linalg.norm(self.low + (np.array([i, j]) + 0.5) * self.cell - pos))
                if d < best:
                    best, verdict = d, bool(self.enclosed[i, j])
        return verdict


def _typical_spacing(points: Array) -> float:
    """The median nearest-neighbour distance of ``points`` (0 for fewer than 2)."""
    from scipy.spatial import cKDTree

    if len(points) < 2:
        return 0.0
    dist, _ = cKDTree(points).query(points, k=2)
    return float(np.median(dist[:, 1]))


def enclosed_regions(scene: Scene) -> EnclosedRegions | None:
    """The regions the point clouds of a 2D ``scene`` enclose, or None (a 3D scene, or one
    without point clouds: 3D clouds are not checked)."""
    clouds = [s.points for s in scene.obstacles if isinstance(s, PointCloud)]
    if scene.dim != 2 or not clouds:
        return None
    return EnclosedRegions(np.concatenate(clouds), scene.low, scene.high)


class CloudScenario(FixedScenario):
    """:class:`FixedScenario` whose drawn starts and goals also avoid the regions the
    scene's 2D point clouds enclose (see :class:`EnclosedRegions`)."""

    #: redraws of an enclosed start or goal before giving up
    MAX_REDRAWS = 1000

    def __init__(self, scene: Scene, robot: Robot, horizon: int = 50, fixed: Sequence[Problem] = ()) -> None:
        super().__init__(scene, robot, horizon, fixed)
        regions = enclosed_regions(scene)
        self.enclosed = regions if regions is not None and regions.any else None

    def sample_problem(self, scene: Scene, rng: np.random.Generator) -> tuple[Array, Array]:
        q = self.robot.sample_free(scene.world, rng, 2, scene.low, scene.high)
        if self.enclosed is None:
            return q[0], q[1]
        for _ in range(self.MAX_REDRAWS):
            bad = self.enclosed.contains(self.robot.positions(q))
            if not bad.any():
                return q[0], q[1]
            q[bad] = self.robot.sample_free(scene.world, rng, int(bad.sum()), scene.low, scene.high)
        raise RuntimeError(
            f"{scene.name}: no free place found outside the regions the point cloud encloses; give bounds inside its outer walls, or the start and goal"
        )


# ============================================================================ writing
def _floats(a: Array) -> list[float]:
    return [float(x) for x in np.asarray(a, np.float64).reshape(-1)]


def _is_rotation(r: Array) -> bool:
    n = r.shape[0]
    return bool(np.allclose(r @ r.T, np.eye(n), atol=1e-9) and np.linalg.det(r) > 0)


def _write_obj(path: Path, mesh: Mesh) -> None:
    """Wavefront OBJ with exact (shortest round-trip) coordinates."""
    lines = ["# pointplan mesh obstacle (world frame)"]
    lines += [" ".join(["v", *(repr(float(x)) for x in v)]) for v in mesh.vertices]
    lines += [" ".join(["f", *(str(int(i) + 1) for i in f)]) for f in mesh.faces]
    path.write_text("\n".join(lines) + "\n")


def _obstacle_doc(shape: Shape, index: int, json_path: Path, dim: int) -> dict[str, Any]:
    where = f"obstacles[{index}]"
    if shape.dim != dim:
        raise SceneFormatError(str(json_path), where, f"{type(shape).__name__} is {shape.dim}D in a {dim}D scene")
    if isinstance(shape, Box):
        out: dict[str, Any] = {"type": "box", "center": _floats(shape.center), "size": _floats(shape.size)}
        rot = shape.rotation
        if not _is_rotation(rot):
            raise SceneFormatError(str(json_path), where, "box rotation is not a proper rotation matrix")
        if not np.array_equal(rot, np.eye(dim)):
            if dim == 2:
                out["angle"] = float(lie.so2_log(rot))
            else:
                out["quaternion"] = _floats(lie.matrix_to_quat(rot))
        return out
    if isinstance(shape, Sphere):
        return {"type": "sphere", "center": _floats(shape.center), "radius": float(shape.radius)}
    if isinstance(shape, Capsule):
        return {"type": "capsule", "a": _floats(shape.a), "b": _floats(shape.b), "radius": float(shape.radius)}
    if isinstance(shape, Cylinder):
        out = {
            "type": "cylinder",
            "center": _floats(shape.center),
            "radius": float(shape.radius),
            "length": float(shape.length),
        }
        if not _is_rotation(shape.rotation):
            raise SceneFormatError(str(json_path), where, "cylinder rotation is not a proper rotation matrix")
        if not np.array_equal(shape.rotation, np.eye(3)):
            out["quaternion"] = _floats(lie.matrix_to_quat(shape.rotation))
        return out
    if isinstance(shape, Mesh):
        name = f"{json_path.stem}.mesh{index}.obj"
        _write_obj(json_path.parent / name, shape)
        return {"type": "mesh", "path": name}
    if isinstance(shape, PointCloud):
        name = f"{json_path.stem}.points{index}.npy"
        np.save(json_path.parent / name, np.concatenate([shape.points, shape.normals], 1).astype(np.float64))
        return {"type": "points", "path": name}
    raise SceneFormatError(str(json_path), where, f"cannot save obstacles of type {type(shape).__name__}")


def _dumps(value: Any, indent: int = 0) -> str:
    """JSON with objects and lists of objects indented and number lists on one line."""
    pad, inner = "  " * indent, "  " * (indent + 1)
    if isinstance(value, dict):
        if not value:
            return "{}"
        flat = all(
            not isinstance(v, (dict, list)) or (isinstance(v, list) and all(not isinstance(x, (dict, list)) for x in v))
            for v in value.values()
        )
        if flat and indent >= 2:
            return "{" + ", ".join(f"{json.dumps(k)}: {_dumps(v)}" for k, v in value.items()) + "}"
        items = [f"{inner}{json.dumps(k)}: {_dumps(v, indent + 1)}" for k, v in value.items()]
        return "{\n" + ",\n".join(items) + "\n" + pad + "}"
    if isinstance(value, list):
        if not value:
            return "[]"
        if all(not isinstance(x, (dict, list)) for x in value):
            return "[" + ", ".join(_dumps(x) for x in value) + "]"
        return "[\n" + ",\n".join(inner + _dumps(x, indent + 1) for x in value) + "\n" + pad + "]"
    return json.dumps(value, allow_nan=False)


def save_scene(
    path: str | os.PathLike[str],
    scene: Scene,
    problems: Sequence[Problem] = (),
    robot: str | Robot | None = None,
) -> None:
    """Write ``scene`` (and problems) as a scene file that :func:`load_scene` reads back.

    ``robot`` is a robot name or a :class:`~pointplan.robots.base.Robot`. Mesh and point
    obstacles are written next to the JSON file as ``<stem>.mesh<i>.obj`` and
    ``<stem>.points<i>.npy`` (world frame). The document is validated before the JSON file
    is written: a scene that could not be loaded back raises :class:`SceneFormatError`.
    """
    path = Path(path)
    name = robot if robot is None or isinstance(robot, str) else getattr(robot, "name", None)
    if robot is not None and name not in ROBOT_DIMS:
        raise SceneFormatError(str(path), "robot", f"unknown robot {robot!r}; known: {', '.join(ROBOT_DIMS)}")
    dim = scene.dim
    doc: dict[str, Any] = {"format": FORMAT, "version": VERSION, "dim": dim}
    if scene.name:
        doc["name"] = scene.name
    doc["bounds"] = {"low": _floats(scene.low), "high": _floats(scene.high)}
    if name is not None:
        doc["robot"] = name
    doc["obstacles"] = [_obstacle_doc(s, i, path, dim) for i, s in enumerate(scene.obstacles)]
    probs = []
    for p in problems:
        entry: dict[str, Any] = {"start": _floats(p.start), "goal": _floats(p.goal)}
        if p.tag:
            entry["tag"] = p.tag
        probs.append(entry)
    doc["problems"] = probs
    # validate exactly as the reader will (this also catches NaN and bad problems)
    try:
        text = _dumps(doc) + "\n"
    except ValueError as exc:
        raise SceneFormatError(str(path), "", f"cannot write non-finite numbers: {exc}") from None
    _Reader(str(path), path.parent).document(json.loads(text))
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
