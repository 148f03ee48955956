"""YCB objects (Calli et al., "The YCB object and model set", 2015) as obstacle meshes.

* :func:`find_ycb_objects` reads the dataset's own folder layout, as downloaded from the YCB
  site (``<root>/<id>_<name>/google_16k/textured.obj`` and friends).
* :func:`default_ycb_objects` returns the curated default set that ships without a download
  (see ``docs/guide/scenarios.md`` for where it comes from).
* :func:`load_object_mesh` turns a mesh file into a small, closed, centred
  :class:`~pointplan.geometry.shapes.Mesh` in metres (cached).
* :func:`place_mesh` scales, rotates and translates a mesh into the world.

Collision treats a mesh as a solid through a winding-number inside test
(:func:`pointplan.geometry.collision.mesh_contains`), whose cost grows with the number of
faces, and so does ray casting; hence the face budget of :func:`load_object_mesh`.
"""

from __future__ import annotations

import functools
import importlib.util
import logging
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..geometry.shapes import Mesh

if TYPE_CHECKING:
    import trimesh

log = logging.getLogger(__name__)

#: Per object folder, the mesh files looked for, best first: the Google scanner's 16k-face
#: mesh, then the Poisson and TSDF reconstructions of the Berkeley scans.
YCB_MESH_FILES: tuple[str, ...] = (
    "google_16k/textured.obj",
    "google_16k/nontextured.ply",
    "google_16k/nontextured.stl",
    "poisson/textured.ply",
    "poisson/nontextured.ply",
    "poisson/textured.obj",
    "tsdf/textured.obj",
    "tsdf/nontextured.ply",
)

#: The curated default set, in this order when present: boxes, cans, a bottle and a drill.
DEFAULT_YCB_OBJECTS: tuple[str, ...] = (
    "003_cracker_box",
    "004_sugar_box",
    "008_pudding_box",
    "009_gelatin_box",
    "002_master_chef_can",
    "005_tomato_soup_can",
    "007_tuna_fish_can",
    "010_potted_meat_can",
    "006_mustard_bottle",
    "035_power_drill",
)

#: A mesh whose longest side exceeds this many "metres" is taken to be in millimetres
#: (e.g. the BOP release of the YCB-Video models) and scaled by 1/1000.
MILLIMETRE_GUESS = 2.0


def find_ycb_objects(root: str | Path) -> dict[str, Path]:
    """Object name -> mesh file for a YCB download at ``root``.

    ``root`` holds one folder per object, named ``<id>_<name>`` (``003_cracker_box``), as the
    YCB site and its download scripts lay them out. Per object the first file of
    :data:`YCB_MESH_FILES` that exists is taken (``google_16k`` first, then ``poisson``, then
    ``tsdf``); folders with none of them are skipped. Raises ``FileNotFoundError`` if ``root``
    does not exist or holds no object, ``ValueError`` if it is not a directory.
    """
    root = Path(root).expanduser()
    if not root.exists():
        raise FileNotFoundError(f"YCB folder {str(root)!r} does not exist")
    if not root.is_dir():
        raise ValueError(f"YCB folder {str(root)!r} is not a directory")
    found: dict[str, Path] = {}
    for folder in sorted(p for p in root.iterdir() if p.is_dir()):
        for rel in YCB_MESH_FILES:
            path = folder / rel
            if path.is_file():
                found[folder.name] = path
                break
    if not found:
        raise FileNotFoundError(
            f"no YCB objects in {str(root)!r}: expected folders like <root>/003_cracker_box holding "
            "google_16k/textured.obj, poisson/textured.ply or tsdf/textured.obj"
        )
    return found


def _bundled_sources() -> list[tuple[str, Path, str]]:
    """(description, folder, suffix) of the places that may hold the default meshes, in the
    order they are tried. None of them needs a download at run time."""
    sources = [("meshes bundled with pointplan", Path(__file__).with_name("ycb_meshes"), ".obj")]
    # MyoSuite 2.x (PyPI, Apache-2.0) ships MuJoCo models of ten YCB objects ("YCB_sim",
    # google_16k scans in metres). Located without importing the package.
    spec = importlib.util.find_spec("myosuite")
    for base in (spec.submodule_search_locations or []) if spec is not None else []:
        sources.append(("the 'myosuite' package (YCB_sim)", Path(base) / "simhive" / "YCB_sim" / "meshes", ".msh"))
    return sources


def default_ycb_objects() -> dict[str, Path]:
    """Object name -> mesh file of the curated default set (:data:`DEFAULT_YCB_OBJECTS`, the
    ones present), from the first source of :func:`_bundled_sources` that has any.

    Raises ``FileNotFoundError`` naming the places looked at when none has them; use
    :func:`find_ycb_objects` on a YCB download instead.
    """
    tried = []
    for what, folder, suffix in _bundled_sources():
        found = {
            name: folder / f"{name}{suffix}" for name in DEFAULT_YCB_OBJECTS if (folder / f"{name}{suffix}").is_file()
        }
        if found:
            return found
        tried.append(f"{what} ({folder})")
    raise FileNotFoundError(
        "no bundled YCB meshes found; looked in "
        + "; ".join(tried)
        + ". Pass find_ycb_objects('<your YCB download>') instead (see docs/guide/scenarios.md)"
    )


def load_object_mesh(path: str | Path, max_faces: int = 800) -> Mesh:
    """A YCB (or any) object mesh, ready to be an obstacle. Cached on ``(path, max_faces)``;
    the returned arrays are read-only, so place copies with :func:`place_mesh`.

    Steps: load with trimesh (``force='mesh'``: all parts of a scene merged; MuJoCo ``.msh``
    files are read directly); merge duplicate vertices and drop degenerate and repeated
    faces; millimetres to metres if the longest side exceeds :data:`MILLIMETRE_GUESS`;
    repair (below); if it has more than ``max_faces`` faces, quadric decimation
    (``fast_simplification``) to at most ``max_faces``; centre the bounding box on the
    origin.

    The result is always watertight (a closed, consistently oriented surface), which the
    inside test of collision checking needs. Repair removes the faces on non-manifold edges
    and dangling faces, fills the holes this and the scan left, and keeps the largest piece;
    if the mesh (or every decimation tried) is still open, the object is replaced by its
    convex hull with at most ``max_faces`` faces, which overestimates concave objects.
    """
    if int(max_faces) < 4:
        raise ValueError("max_faces must be at least 4 (a tetrahedron)")
    return _load_cached(str(Path(path).expanduser().resolve()), int(max_faces))


@functools.lru_cache(maxsize=256)
def _load_cached(path: str, max_faces: int) -> Mesh:
    import trimesh

    src = Path(path)
    if not src.is_file():
        raise FileNotFoundError(f"mesh file {path!r} does not exist")
    if src.suffix.lower() == ".msh":
        tm: trimesh.parent.Geometry = _read_mujoco_msh(src)
    else:
        try:
            tm = trimesh.load(path, force="mesh", process=False)
        except Exception as exc:  # trimesh raises many kinds of errors on bad files
            raise ValueError(f"cannot load mesh {path!r}: {exc}") from exc
    if not isinstance(tm, trimesh.Trimesh) or len(tm.faces) == 0:
        raise ValueError(f"mesh file {path!r} has no triangles")
    tm = _clean(trimesh.Trimesh(np.asarray(tm.vertices, np.float64), np.asarray(tm.faces, np.int64), process=False))
    if float(np.ptp(tm.vertices, axis=0).max()) > MILLIMETRE_GUESS:
        tm.apply_scale(1e-3)
    tm = _closed_within_budget(tm, max_faces, path)
    tm.apply_translation(-tm.bounds.mean(axis=0))
    mesh = Mesh(vertices=np.array(tm.vertices, np.float64), faces=np.array(tm.faces, np.int64), source=src)
    mesh.vertices.setflags(write=False)
    mesh.faces.setflags(write=False)
    return mesh


def place_mesh(mesh: Mesh, rotation: np.ndarray, translation: np.ndarray, scale: float = 1.0) -> Mesh:
    """``mesh`` scaled by ``scale`` about its origin, then rotated by ``rotation: (3, 3)`` and
    moved by ``translation: (3,)``: vertex ``v`` goes to ``R (scale v) + t``."""
    rot = np.asarray(rotation, np.float64)
    t = np.asarray(translation, np.float64).reshape(-1)
    if rot.shape != (3, 3):
        raise ValueError(f"rotation must be 3x3, got shape {rot.shape}")
    if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0:
        raise ValueError("rotation must be a proper rotation matrix (orthonormal, det +1)")
    if t.shape != (3,):
        raise ValueError(f"translation must have 3 numbers, got {t.shape[0]}")
    if not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"scale must be positive, got {scale}")
    vertices = (float(scale) * mesh.vertices) @ rot.T + t
    return Mesh(vertices=vertices, faces=np.array(mesh.faces, np.int64), source=mesh.source)


# --------------------------------------------------------------------------- internals


def _read_mujoco_msh(path: Path) -> trimesh.Trimesh:
    """MuJoCo's legacy binary mesh: int32 counts (vertices, normals, texcoords, faces), then
    float32 vertices (3 each), normals (3), texcoords (2) and int32 faces (3)."""
    import trimesh

    data = path.read_bytes()
    if len(data) < 16:
        raise ValueError(f"{str(path)!r} is too short for a MuJoCo .msh file")
    nv, nn, nt, nf = (int(x) for x in np.frombuffer(data, np.int32, 4))
    size = 16 + 12 * nv + 12 * nn + 8 * nt + 12 * nf
    if min(nv, nn, nt, nf) < 0 or size != len(data):
        raise ValueError(f"{str(path)!r} is not a MuJoCo .msh file (sizes do not add up)")
    vertices = np.frombuffer(data, np.float32, 3 * nv, 16).reshape(-1, 3)
    faces = np.frombuffer(data, np.int32, 3 * nf, 16 + 12 * nv + 12 * nn + 8 * nt).reshape(-1, 3)
    if len(faces) and (faces.min() < 0 or faces.max() >= nv):
        raise ValueError(f"{str(path)!r} has face indices out of range")
    return trimesh.Trimesh(vertices.astype(np.float64), faces.astype(np.int64), process=False)


def _clean(tm: trimesh.Trimesh) -> trimesh.Trimesh:
    """Merge duplicate vertices, drop degenerate and repeated faces and unused vertices."""
    import trimesh

    tm = trimesh.Trimesh(tm.vertices, tm.faces, process=True)  # merges equal vertices
    tm.update_faces(tm.nondegenerate_faces())
    tm.update_faces(tm.unique_faces())
    tm.remove_unreferenced_vertices()
    return tm


def _edge_use(tm: trimesh.Trimesh) -> np.ndarray:
    """``(F, 3)``: how many faces share each edge of each face."""
    import trimesh

    _, inverse = trimesh.grouping.unique_rows(tm.edges_sorted)
    return np.bincount(inverse)[inverse].reshape(-1, 3)


def _repair(tm: trimesh.Trimesh, rounds: int = 6) -> trimesh.Trimesh:
    """Try to close ``tm``: drop faces on non-manifold edges and dangling faces, fill holes;
    keep the largest piece; orient the faces outwards."""
    import trimesh

    tm = _clean(tm)
    for _ in range(rounds):
        if tm.is_watertight or len(tm.faces) < 4:
            break
        use = _edge_use(tm)
        tm.update_faces(~(use > 2).any(axis=1))
        for _ in range(3):
            use = _edge_use(tm)
            dangling = (use == 1).sum(axis=1) >= 2
            if not dangling.any():
                break
            tm.update_faces(~dangling)
        tm.remove_unreferenced_vertices()
        trimesh.repair.fill_holes(tm)
        tm = _clean(tm)
    if len(tm.faces) and tm.body_count > 1:
        parts = tm.split(only_watertight=False)
        closed = [p for p in parts if p.is_watertight]
        tm = max(closed, key=lambda p: abs(p.volume)) if closed else max(parts, key=lambda p: p.area)
    if len(tm.faces):
        trimesh.repair.fix_normals(tm)
    return tm


def _is_solid(tm: trimesh.Trimesh, max_faces: int, like: trimesh.Trimesh) -> bool:
    """Closed, within budget, and still the object ``like`` (bounding box within 15%, and
    volume within 30% when ``like`` is a closed volume): repair may keep the wrong piece."""
    if not (4 <= len(tm.faces) <= max_faces and tm.is_watertight and tm.is_volume):
        return False
    if not np.allclose(tm.extents, like.extents, rtol=0.15, atol=1e-9):
        return False
    return not like.is_volume or abs(tm.volume / like.volume - 1.0) <= 0.3


def _closed_within_budget(tm: trimesh.Trimesh, max_faces: int, path: str) -> trimesh.Trimesh:
    """Watertight, at most ``max_faces`` faces: repair, decimate, or the convex hull."""
    import trimesh

    original = tm
    tm = _repair(tm)
    if not np.allclose(tm.extents, original.extents, rtol=0.15, atol=1e-9):
        tm = original  # repair threw away most of the object; decimate the raw mesh
    if _is_solid(tm, max_faces, original):
        return tm
    if len(tm.faces) > max_faces:
        try:
            # fast_simplification is what trimesh's quadric decimation wraps
            from fast_simplification import simplify
        except ImportError:
            log.warning("fast_simplification is not installed: %s replaced by its convex hull", path)
        else:
            # decimation can pinch the surface; a few budgets and aggressions usually work
            for fraction in (1.0, 0.9, 0.8, 0.7):
                for aggression in (7, 3):
                    count = max(4, int(max_faces * fraction))
                    vertices, faces = simplify(
                        np.asarray(tm.vertices, np.float64),
                        np.asarray(tm.faces, np.int32),
                        target_count=count,
                        agg=aggression,
                    )
                    small = _repair(trimesh.Trimesh(vertices, faces, process=False))
                    if _is_solid(small, max_faces, tm):
                        return small
    log.info("%s: no watertight mesh within %d faces, using its convex hull", path, max_faces)
    return _hull_within_budget(tm, max_faces)


def _hull_within_budget(tm: trimesh.Trimesh, max_faces: int) -> trimesh.Trimesh:
    """Convex hull with at most ``max_faces`` faces: a hull of ``V`` points has at most
    ``2 V - 4`` faces, so hull a subset of at most ``max_faces / 2 + 2`` hull vertices."""
    import trimesh

    hull = tm.convex_hull
    keep = max_faces // 2 + 2
    while len(hull.faces) > max_faces:
        points = hull.vertices
        if len(points) > keep:  # farthest-point subset keeps the overall shape
            chosen = [int(np.argmax(np.linalg.norm(points - points.mean(axis=0), axis=1)))]
            dist = np.linalg.norm(points - points[chosen[0]], axis=1)
            while len(chosen) < keep:
                chosen.append(int(np.argmax(dist)))
                dist = np.minimum(dist, np.linalg.norm(points - points[chosen[-1]], axis=1))
            points = points[chosen]
        hull = trimesh.convex.convex_hull(points)
        keep = max(4, keep - 1)
    trimesh.repair.fix_normals(hull)
    return hull


__all__ = [
    "DEFAULT_YCB_OBJECTS",
    "YCB_MESH_FILES",
    "default_ycb_objects",
    "find_ycb_objects",
    "load_object_mesh",
    "place_mesh",
]
