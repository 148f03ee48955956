"""Point clouds from files and depth images, and normals estimated for clouds that have none.

* :func:`read_point_file` reads points (and normals when the file has them) from ``.ply``
  (trimesh's PLY reader), ``.pcd`` (the ``pypcd4`` package, ``pip install
  'pointplan[pcd]'``), ``.npy`` (NumPy) and whitespace or comma separated text (``.xyz``,
  ``.txt``, ``.csv``).
* :func:`estimate_normals` fits a plane (a line in 2D) to each point's ``k`` nearest
  neighbours (principal component analysis, all points in one batched eigen-decomposition)
  and orients the normal towards a viewpoint or away from the obstacle's interior.
* :func:`depth_to_cloud` turns a depth image, pinhole intrinsics and the camera's pose
  into world points with normals from the pixel grid; :func:`read_depth_cloud` does it
  for a file (``.npy``, a 16-bit PNG or a TIFF).

Problems with the input raise :class:`CloudError`; the scene reader turns it into a
:class:`~pointplan.scenes.io.SceneFormatError` naming the scene file and the field.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

#: file types :func:`read_point_file` reads
POINT_FILE_SUFFIXES = (".ply", ".pcd", ".npy", ".xyz", ".txt", ".csv")
#: neighbours of the plane fit (``k``) by default
DEFAULT_K = 16
#: weight of the surface variation against the distance to the plane (in neighbour spacings)
#: when a point picks the best neighbouring fit (see :func:`pca_normals`)
SHARP_VARIATION_WEIGHT = 10.0
#: depth image files :func:`read_depth_image` reads
DEPTH_FILE_SUFFIXES = (".png", ".npy", ".tif", ".tiff")
#: metres per unit of an integer depth image (a 16-bit PNG holds millimetres) by default
INTEGER_DEPTH_SCALE = 0.001
#: largest depth change between neighbouring pixels of one surface, relative to the depth
#: (:func:`depth_to_cloud`'s normals)
MAX_DEPTH_JUMP = 0.05
PCD_MISSING = "reading .pcd files needs the 'pypcd4' package: pip install 'pointplan[pcd]'"


class CloudError(ValueError):
    """A point file or depth image that cannot be used (the message says why)."""


# ============================================================================ files
def one_line(exc: BaseException) -> str:
    """What went wrong in one line: the first line of the exception's message, or, for a
    validation error listing problems (pydantic's, as pypcd4 raises for a bad header),
    the first three of them as ``field: problem``."""
    errors = getattr(exc, "errors", None)
    if callable(errors):
        try:
            found = [f"{'.'.join(str(x) for x in e['loc'])}: {e['msg']}" for e in errors()]
        except Exception:  # not a list of pydantic's problems after all
            found = []
        if found:
            more = f" (and {len(found) - 3} more)" if len(found) > 3 else ""
            return "; ".join(found[:3]) + more
    lines = str(exc).strip().splitlines()
    return lines[0].strip() if lines else type(exc).__name__


def read_point_file(path: str | Path) -> tuple[Array, Array | None]:
    """``(points (P, c), normals (P, c) or None)`` from a point file, as float64.

    ``c`` is the number of coordinates in the file: 3 for PLY and PCD; for NumPy and text
    files the columns are either the coordinates alone or the coordinates followed by as
    many normal components (an even count is read as points with normals: 4 columns are
    ``x y nx ny``, 6 are ``x y z nx ny nz``; 2 and 3 columns are points only).
    Normals are returned as stored (not normalised, not checked).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".ply":
        points, normals = _read_ply(path)
    elif suffix == ".pcd":
        points, normals = _read_pcd(path)
    elif suffix in (".npy", ".xyz", ".txt", ".csv"):
        points, normals = _read_table(path)
    else:
        raise CloudError(
            f"unsupported file type {suffix or '(none)'!r} of {path.name!r}; use one of {', '.join(POINT_FILE_SUFFIXES)}"
        )
    if len(points) == 0:
        raise CloudError(f"points file {path.name!r} holds no points")
    if not np.all(np.isfinite(points)):
        raise CloudError(f"points file {path.name!r} contains NaN or infinite coordinates")
    return points, normals


def _read_ply(path: Path) -> tuple[Array, Array | None]:
    from trimesh.exchange.ply import load_ply

    try:
        with open(path, "rb") as f:
            kwargs = load_ply(f)
    except Exception as exc:  # trimesh raises many kinds of errors on bad files
        raise CloudError(f"cannot read PLY file {path.name!r}: {one_line(exc)}") from None
    vertices = kwargs.get("vertices")
    if vertices is None or len(vertices) == 0:
        raw = kwargs.get("metadata", {}).get("_ply_raw", {})
        if isinstance(raw, dict) and "vertex" in raw:
            raise CloudError(f"PLY file {path.name!r} holds no points (its vertex element has 0 vertices)")
        raise CloudError(f"PLY file {path.name!r} has no vertex element")
    normals = kwargs.get("vertex_normals")  # trimesh fills it from nx, ny, nz when present
    try:
        points = np.asarray(vertices, np.float64).reshape(len(vertices), -1)
        if normals is not None:
            normals = np.asarray(normals, np.float64).reshape(points.shape)
    except (TypeError, ValueError) as exc:
        raise CloudError(f"cannot read PLY file {path.name!r}: {one_line(exc)}") from None
    return points, normals


def _read_pcd(path: Path) -> tuple[Array, Array | None]:
    try:
        from pypcd4 import PointCloud as PCDCloud
    except ImportError:
        raise CloudError(PCD_MISSING) from None
    try:
        cloud = PCDCloud.from_path(path)
        fields = tuple(cloud.fields)
        if not all(f in fields for f in ("x", "y", "z")):
            raise CloudError(f"PCD file {path.name!r} has no x, y, z fields (fields: {', '.join(fields)})")
        points = np.asarray(cloud.numpy(("x", "y", "z")), np.float64)
        names = ("normal_x", "normal_y", "normal_z")
        normals = np.asarray(cloud.numpy(names), np.float64) if all(n in fields for n in names) else None
    except CloudError:
        raise
    except Exception as exc:
        raise CloudError(f"cannot read PCD file {path.name!r}: {one_line(exc)}") from None
    return points.reshape(-1, 3), None if normals is None else normals.reshape(-1, 3)


def _read_table(path: Path) -> tuple[Array, Array | None]:
    try:
        if path.suffix.lower() == ".npy":
            data = np.load(path, allow_pickle=False)
        else:
            delimiter = "," if path.suffix.lower() == ".csv" else None
            data = np.loadtxt(path, dtype=np.float64, delimiter=delimiter, comments="#", ndmin=2)
    except Exception as exc:
        raise CloudError(f"cannot read points file {path.name!r}: {one_line(exc)}") from None
    data = np.asarray(data)
    if not np.issubdtype(data.dtype, np.number):
        raise CloudError(f"points file {path.name!r} does not hold numbers (dtype {data.dtype})")
    data = data.astype(np.float64)
    if data.ndim != 2 or data.shape[1] not in (2, 3, 4, 6) or data.shape[0] == 0:
        raise CloudError(
            f"points file {path.name!r}: expected an array (P, 2) or (P, 3) of points, or (P, 4) or (P, 6) of points and normals, got shape {data.shape}"
        )
    c = data.shape[1]
    if c in (4, 6):
        return data[:, : c // 2], data[:, c // 2 :]
    return data, None


def check_normals(normals: Array, name: str) -> Array:
    """Unit normals, or :class:`CloudError` naming ``name`` if one is zero, NaN or infinite."""
    n = np.asarray(normals, np.float64)
    norm = np.linalg.norm(n, axis=1)
    bad = ~np.isfinite(norm) | ~(norm > 1e-12)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        what = "NaN or infinite" if not np.isfinite(norm[i]) else "zero"
        raise CloudError(
            f"points file {name!r}: {int(bad.sum())} of {len(n)} normals are degenerate (the first, of point {i}, "
            f"is {what}); give a non-zero normal for every point, or leave the normals out to have them estimated"
        )
    return n / norm[:, None]


# ============================================================================ normals
def _knn(points: Array, k: int) -> tuple[Array, NDArray[np.int64]]:
    from scipy.spatial import cKDTree

    k = max(1, min(int(k), len(points)))
    dist, idx = cKDTree(points).query(points, k=k)
    return dist.reshape(len(points), k), idx.reshape(len(points), k)


def _pca(p: Array, idx: NDArray[np.int64]) -> tuple[Array, Array, Array]:
    """Per neighbourhood ``idx`` (P, m): centroid, unit direction of least spread and
    surface variation (smallest eigenvalue over their sum: 0 on a flat patch)."""
    nb = p[idx]  # (P, m, d)
    centroid = nb.mean(axis=1)
    nb = nb - centroid[:, None, :]
    cov = np.einsum("pki,pkj->pij", nb, nb)
    vals, vecs = np.linalg.eigh(cov)  # eigenvalues ascending
    n = vecs[:, :, 0]
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    variation = vals[:, 0] / np.maximum(vals.sum(axis=1), 1e-300)
    return centroid, n, np.clip(variation, 0.0, None)


def pca_normals(points: Array, k: int = DEFAULT_K, sharp: bool = True) -> Array:
    """Unoriented unit normals from the ``k`` nearest neighbours of each point (PCA, one
    batched eigen-decomposition).

    A plain fit to the point's own neighbourhood bends its normal near edges and corners,
    where the neighbourhood spans two faces. With ``sharp``, each point instead takes the
    fit, among those of its ``k`` neighbours' neighbourhoods, that is flattest and passes
    closest to it (the smallest surface variation plus distance to the fitted plane in
    units of the neighbour spacing): near an edge that is a neighbourhood lying on the
    point's own face."""
    p = np.asarray(points, np.float64)
    dist, idx = _knn(p, k)
    centroid, n, variation = _pca(p, idx)
    if not sharp or idx.shape[1] < 3:
        return n
    spacing = np.maximum(dist[:, 1:].mean(axis=1), 1e-12)  # (P,)
    residual = np.abs(np.einsum("pki,pki->pk", n[idx], p[:, None, :] - centroid[idx]))
    score = variation[idx] * SHARP_VARIATION_WEIGHT + residual / spacing[:, None]
    best = np.take_along_axis(idx, np.argmin(score, axis=1)[:, None], axis=1)[:, 0]
    return n[best]


def _clusters(idx: NDArray[np.int64]) -> NDArray[np.int64]:
    """Connected components of the (symmetrised) nearest-neighbour graph."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    p, k = idx.shape
    rows = np.repeat(np.arange(p), k)
    graph = coo_matrix((np.ones(p * k), (rows, idx.reshape(-1))), shape=(p, p))
    _, labels = connected_components(graph, directed=False)
    return labels


def estimate_normals(
    points: Array,
    k: int = DEFAULT_K,
    viewpoint: Array | None = None,
    scales: tuple[int, ...] = (4, 16),
    ambiguity: float = 0.1,
) -> Array:
    """Unit normals of a cloud sampled on obstacle surfaces (``(P, d)``, ``d`` = 2 or 3).

    Each normal is the direction of least spread of the point's ``k`` nearest neighbours
    (PCA), then oriented:

    * with ``viewpoint`` (a ``(d,)`` point, e.g. the camera of a scan): towards it;
    * without: away from the obstacle's interior, estimated as the centroid of a larger
      neighbourhood. The ``scales`` are tried in order (``k * s`` neighbours each), and the
      first whose centroid lies clearly off the point's tangent plane (by more than
      ``ambiguity`` times the neighbourhood's radius) decides; if none does, the centroid
      of the point's cluster (connected component of the neighbour graph) decides. The
      small scales follow thin walls and concave unions; the cluster centroid settles the
      middle of large flat faces of convex objects.
    """
    p = np.asarray(points, np.float64)
    if p.ndim != 2 or p.shape[1] not in (2, 3):
        raise ValueError(f"points must be a (P, 2) or (P, 3) array, got shape {p.shape}")
    if len(p) < p.shape[1]:
        raise CloudError(f"cannot estimate normals from {len(p)} point{'' if len(p) == 1 else 's'}")
    n = pca_normals(p, k)
    if viewpoint is not None:
        v = np.asarray(viewpoint, np.float64).reshape(-1)
        sign = np.sign(np.einsum("pi,pi->p", n, v - p))
        return n * np.where(sign < 0, -1.0, 1.0)[:, None]

    big = max(k * s for s in scales) if scales else k
    dist, idx = _knn(p, max(big, k))
    labels = _clusters(idx[:, : max(2, min(k, idx.shape[1]))])
    off = np.zeros(len(p))
    decided = np.zeros(len(p), dtype=bool)
    for s in scales:
        m = max(1, min(k * s, idx.shape[1]))
        nbr = idx[:, :m]
        same = (labels[nbr] == labels[:, None]).astype(np.float64)  # only the point's own obstacle
        count = same.sum(axis=1)
        centroid = np.einsum("pm,pmi->pi", same, p[nbr]) / count[:, None]
        radius = np.sqrt(np.einsum("pm,pm->p", same, dist[:, :m] ** 2) / count)
        o = np.einsum("pi,pi->p", n, p - centroid)
        clear = ~decided & (np.abs(o) > ambiguity * radius)
        off[clear] = o[clear]
        decided |= clear
    if not decided.all():
        counts = np.bincount(labels)
        sums = np.zeros((len(counts), p.shape[1]))
        np.add.at(sums, labels, p)
        centroid = (sums / counts[:, None])[labels]
        o = np.einsum("pi,pi->p", n, p - centroid)
        off[~decided] = o[~decided]
    n = n * np.where(off < 0, -1.0, 1.0)[:, None]
    return _agree(p, n, idx[:, : max(2, min(k, idx.shape[1]))], dist[:, : max(2, min(k, idx.shape[1]))])


def _agree(p: Array, n: Array, idx: NDArray[np.int64], dist: Array, rounds: int = 3) -> Array:
    """Flip normals that disagree with most neighbours on the same face: neighbours close
    to the point's tangent plane (within half a spacing) whose normals are nearly parallel
    vote with the sign of the dot product. Walls seen from both sides do not vote against
    each other, as the far side lies off the tangent plane."""
    spacing = np.maximum(dist[:, 1:].mean(axis=1), 1e-12)
    for _ in range(rounds):
        dots = np.einsum("pi,pki->pk", n, n[idx])
        planar = np.abs(np.einsum("pi,pki->pk", n, p[idx] - p[:, None, :])) < 0.5 * spacing[:, None]
        vote = np.where(planar & (np.abs(dots) > 0.7), np.sign(dots), 0.0).sum(axis=1)
        flip = vote < 0
        if not flip.any():
            break
        n = np.where(flip[:, None], -n, n)
    return n


# ============================================================================ depth images
def _read_depth_raw(path: Path) -> NDArray[Any]:
    """The depth image in ``path`` as stored (its own dtype), checked to be ``(H, W)`` numbers."""
    if path.suffix.lower() not in DEPTH_FILE_SUFFIXES:
        raise CloudError(
            f"unsupported depth image type {path.suffix or '(none)'!r} of {path.name!r}; use one of {', '.join(DEPTH_FILE_SUFFIXES)}"
        )
    try:
        if path.suffix.lower() == ".npy":
            depth = np.load(path, allow_pickle=False)
        else:
            from PIL import Image

            with Image.open(path) as im:
                depth = np.asarray(im)
    except Exception as exc:  # Pillow and NumPy raise many kinds of errors on bad files
        raise CloudError(f"cannot read depth image {path.name!r}: {one_line(exc)}") from None
    depth = np.asarray(depth)
    if depth.ndim != 2 or not (np.issubdtype(depth.dtype, np.integer) or np.issubdtype(depth.dtype, np.floating)):
        raise CloudError(
            f"depth image {path.name!r}: expected one channel of numbers (H, W), got shape {depth.shape} of {depth.dtype}"
        )
    return depth


def read_depth_image(path: str | Path) -> Array:
    """A depth image ``(H, W)`` as float64 in the file's units: ``.npy`` or an image file
    (16-bit PNG, as depth cameras write them, or TIFF; read with Pillow)."""
    return _read_depth_raw(Path(path)).astype(np.float64)


def default_depth_scale(depth: NDArray[Any]) -> float:
    """Metres per depth unit when none is given: :data:`INTEGER_DEPTH_SCALE` (millimetres)
    for an integer image such as a 16-bit PNG, 1 (metres) for a floating-point one."""
    return INTEGER_DEPTH_SCALE if np.issubdtype(np.asarray(depth).dtype, np.integer) else 1.0


def camera_intrinsics(intrinsics: Sequence[float] | Array) -> tuple[float, float, float, float]:
    """``(fx, fy, cx, cy)`` checked: four finite numbers, the focal lengths positive."""
    k = np.asarray(intrinsics, np.float64).reshape(-1)
    if k.shape != (4,) or not np.all(np.isfinite(k)) or not (k[0] > 0 and k[1] > 0):
        raise CloudError(
            f"intrinsics: expected 4 finite numbers fx, fy, cx, cy with fx, fy > 0, got {np.round(k, 6).tolist()}"
        )
    return float(k[0]), float(k[1]), float(k[2]), float(k[3])


def camera_pose(pose: Sequence[float] | Array) -> Array:
    """A 4 x 4 camera-to-world transform from one (checked to be rigid) or from 7 numbers
    ``x, y, z, qx, qy, qz, qw`` (the camera's position and orientation in the world; the
    quaternion is normalised)."""
    from .lie import quat_to_matrix

    p = np.asarray(pose, np.float64)
    if p.shape == (4, 4):
        rot = p[:3, :3]
        rigid = np.allclose(rot @ rot.T, np.eye(3), atol=1e-6) and np.linalg.det(rot) > 0
        if not np.all(np.isfinite(p)) or not rigid or not np.allclose(p[3], [0, 0, 0, 1]):
            raise CloudError("camera pose: a 4 x 4 matrix must be a rigid transform (rotation and translation)")
        return p.copy()
    p = p.reshape(-1)
    if p.shape != (7,) or not np.all(np.isfinite(p)):
        raise CloudError(f"camera pose: expected 7 finite numbers x, y, z, qx, qy, qz, qw, got {p.size}")
    if not np.linalg.norm(p[3:]) > 1e-12:
        raise CloudError("camera pose: the quaternion qx, qy, qz, qw is zero")
    out = np.eye(4)
    out[:3, :3] = quat_to_matrix(p[3:])
    out[:3, 3] = p[:3]
    return out


def _back_project(z: Array, fx: float, fy: float, cx: float, cy: float) -> Array:
    """Camera-frame points ``(H, W, 3)`` of depths ``z`` (metres, NaN where invalid)."""
    h, w = z.shape
    u = np.arange(w, dtype=np.float64)[None, :]
    v = np.arange(h, dtype=np.float64)[:, None]
    return np.stack([(u - cx) * z / fx, (v - cy) * z / fy, z], axis=-1)


def depth_to_points(
    depth: Array,
    fx: float,
    fy: float,
    cx: float,
    cy: float,
    pose: Array | None = None,
    depth_scale: float = 1.0,
) -> Array:
    """World points ``(P, 3)`` of a depth image ``(H, W)`` seen by a pinhole camera (the
    points of :func:`depth_to_cloud`, without normals).

    Pixel ``(u, v)`` (column, row) with depth ``z = depth[v, u] * depth_scale`` is the point
    ``((u - cx) z / fx, (v - cy) z / fy, z)`` of the camera frame (x right, y down, z along
    the optical axis, as OpenCV has it). ``pose`` (a 4 x 4 camera-to-world transform) takes
    it to the world. Pixels with zero, negative or non-finite depth (no return) are dropped.
    """
    d = np.asarray(depth, np.float64)
    if d.ndim != 2:
        raise ValueError(f"depth must be an (H, W) image, got shape {d.shape}")
    with np.errstate(invalid="ignore", over="ignore"):
        z = d * float(depth_scale)
    valid = np.isfinite(z) & (z > 0)
    pts = _back_project(np.where(valid, z, np.nan), fx, fy, cx, cy)[valid]
    if pose is not None:
        t = np.asarray(pose, np.float64).reshape(4, 4)
        pts = pts @ t[:3, :3].T + t[:3, 3]
    return pts


def _grid_step(p: Array, z: Array, axis: int, max_jump: float) -> Array:
    """Per pixel, the step ``(H, W, 3)`` from the previous to the next pixel along ``axis``
    (0: down a column, 1: along a row) on the same surface: of the steps to the neighbour
    before and after, the shorter of those whose depth changes by at most ``max_jump``
    times the nearer depth (NaN where neither does: an edge or a lone pixel)."""
    pm, zm = np.moveaxis(p, axis, 0), np.moveaxis(z, axis, 0)
    step = pm[1:] - pm[:-1]
    with np.errstate(invalid="ignore"):
        same = np.abs(zm[1:] - zm[:-1]) <= max_jump * np.fmin(zm[1:], zm[:-1])
    step[~same] = np.nan
    after, before = np.full_like(pm, np.nan), np.full_like(pm, np.nan)
    after[:-1], before[1:] = step, step
    la, lb = np.linalg.norm(after, axis=-1), np.linalg.norm(before, axis=-1)
    with np.errstate(invalid="ignore"):
        use_before = ~(la <= lb) & np.isfinite(lb)
    return np.moveaxis(np.where(use_before[..., None], before, after), 0, axis)


def depth_to_cloud(
    depth: Array,
    intrinsics: Sequence[float] | Array,
    pose: Sequence[float] | Array | None = None,
    depth_scale: float = 1.0,
    max_jump: float = MAX_DEPTH_JUMP,
) -> tuple[Array, Array]:
    """World points ``(P, 3)`` and unit normals ``(P, 3)`` of a depth image ``(H, W)``.

    ``intrinsics`` are ``fx, fy, cx, cy`` of the pinhole camera, in pixels; ``pose`` is
    where the camera is in the world (see :func:`camera_pose`: a 4 x 4 camera-to-world
    matrix or ``x, y, z, qx, qy, qz, qw``; default: the world frame). The camera looks
    along its +z with x right and y down (OpenCV's convention): pixel ``(u, v)`` (column,
    row) with depth ``z = depth[v, u] * depth_scale`` is the point ``((u - cx) z / fx,
    (v - cy) z / fy, z)`` of the camera frame. Pixels of zero, negative or non-finite
    depth (no return) are dropped; the others come row by row.

    Normals come from the image grid: the cross product of the steps to the neighbouring
    pixels along the row and down the column (each the shorter of the steps before and
    after that stays on the surface: depth changing by at most ``max_jump`` times the
    depth), oriented towards the camera. A pixel without such a neighbour in one of the
    two directions (a lone pixel, a line one pixel thin) takes the direction back along
    its ray.
    """
    fx, fy, cx, cy = camera_intrinsics(intrinsics)
    d = np.asarray(depth)
    if d.ndim != 2 or not (np.issubdtype(d.dtype, np.integer) or np.issubdtype(d.dtype, np.floating)):
        raise CloudError(f"depth: expected an (H, W) image of numbers, got shape {d.shape} of {d.dtype}")
    scale = float(depth_scale)
    if not (math.isfinite(scale) and scale > 0):
        raise CloudError(f"depth scale: expected a positive number (metres per unit), got {depth_scale}")
    with np.errstate(invalid="ignore", over="ignore"):
        z = d.astype(np.float64) * scale
    valid = np.isfinite(z) & (z > 0)
    if not valid.any():
        return np.zeros((0, 3)), np.zeros((0, 3))
    z = np.where(valid, z, np.nan)
    p = _back_project(z, fx, fy, cx, cy)
    with np.errstate(invalid="ignore", over="ignore"):
        du, dv = _grid_step(p, z, 1, max_jump), _grid_step(p, z, 0, max_jump)
        n = np.cross(du[valid], dv[valid])
        pts = p[valid]
        size = np.linalg.norm(n, axis=1)
        good = np.isfinite(size) & (
            size > 1e-12 * np.linalg.norm(du[valid], axis=1) * np.linalg.norm(dv[valid], axis=1)
        )
        ray = -pts / np.linalg.norm(pts, axis=1, keepdims=True)
        n = np.where(good[:, None], n / np.where(good, size, 1.0)[:, None], ray)
        n = np.where((np.einsum("pi,pi->p", n, pts) > 0)[:, None], -n, n)  # the camera is at the origin
    if pose is not None:
        t = camera_pose(pose)
        pts, n = pts @ t[:3, :3].T + t[:3, 3], n @ t[:3, :3].T
    return pts, n


def read_depth_cloud(
    path: str | Path,
    intrinsics: Sequence[float] | Array,
    pose: Sequence[float] | Array | None = None,
    depth_scale: float | None = None,
    stride: int = 1,
) -> tuple[Array, Array]:
    """Points and normals (see :func:`depth_to_cloud`) of the depth image in ``path``
    (``.png``, ``.tif``, ``.tiff`` or ``.npy``).

    ``depth_scale`` is metres per unit of the file; by default 0.001 (millimetres) for an
    integer image such as a 16-bit PNG and 1 (metres) for a floating-point one. ``stride``
    keeps every ``stride``-th pixel in each direction (the intrinsics scaled to match).
    Raises :class:`CloudError` when the file cannot be read or has no valid pixel.
    """
    path = Path(path)
    depth = _read_depth_raw(path)
    scale = default_depth_scale(depth) if depth_scale is None else depth_scale
    stride = min(int(stride), max(depth.shape, default=1))  # a longer stride keeps the same pixels
    if stride > 1:
        fx, fy, cx, cy = camera_intrinsics(intrinsics)
        depth = depth[::stride, ::stride]
        intrinsics = (fx / stride, fy / stride, cx / stride, cy / stride)
    points, normals = depth_to_cloud(depth, intrinsics, pose, scale)
    if len(points) == 0:
        raise CloudError(
            f"depth image {path.name!r} holds no valid pixel (every depth is 0, negative, NaN or infinite)"
        )
    return points, normals
