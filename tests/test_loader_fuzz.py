"""Seeded fuzzing of the loaders of a user's own data.

Valid sample files (a scene file, PLY in ASCII and binary, PCD, ``.npy`` and ``.xyz``
clouds, depth images as ``.npy`` and 16-bit PNG, the shipped policy, MPNet and
learned-sampling checkpoints) are mutated (bytes flipped, files cut short, bytes inserted or
repeated, headers, JSON documents and checkpoint contents edited) and fed to the public
loaders: :func:`~pointplan.scenes.io.load_scene`,
:func:`~pointplan.scenes.io.load_points_scene`, :func:`~pointplan.scenes.io.load_depth_scene`,
:meth:`~pointplan.models.policy.Policy.from_checkpoint` and the ``mpnet-nr`` and
``lsample-0.5`` planners (:func:`~pointplan.planners.make_planner`, as the CLI loads their
checkpoints). Each case must load or raise
the loader's own error (:class:`SceneFormatError`, :class:`CheckpointError`) with a
one-line message, within a time limit; anything else fails the test, listing the cases.
``pytest -s`` shows the counts.
"""

from __future__ import annotations

import copy
import json
import math
import re
import signal
import struct
import warnings
import zlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pointplan.models.checkpoint import CheckpointError
from pointplan.scenes.io import SceneFormatError, load_depth_scene, load_points_scene, load_scene

DATA = Path(__file__).resolve().parents[1] / "src" / "pointplan" / "data"
#: seconds one case may take
LIMIT_S = 5
INTR = (8.0, 8.0, 5.5, 3.5)
POSE = (0.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0)  # looking down the world's -z from z = 2

Mutation = tuple[bytes, str]


class Hang(Exception):
    """A case that ran past :data:`LIMIT_S`."""


@contextmanager
def time_limit(seconds: float) -> Iterator[None]:
    def alarm(signum: int, frame: Any) -> None:
        raise Hang(f"ran past {seconds} s")

    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


# ---------------------------------------------------------------------------- mutations
def byte_mutation(data: bytes, rng: np.random.Generator) -> Mutation:
    """One of: flip a few bytes, cut the file short, insert random bytes, repeat a chunk,
    zero a run."""
    b = bytearray(data)
    op = ("flip", "truncate", "insert", "repeat", "zero")[int(rng.integers(5))]
    n = len(b)
    if op == "flip":
        at = sorted(int(i) for i in rng.integers(0, n, int(rng.integers(1, 5))))
        for i in at:
            b[i] ^= int(rng.integers(1, 256))
        return bytes(b), f"flip bytes {at}"
    if op == "truncate":
        cut = int(rng.integers(0, n))
        return bytes(b[:cut]), f"cut at {cut} of {n}"
    if op == "insert":
        at, k = int(rng.integers(0, n + 1)), int(rng.integers(1, 17))
        return bytes(b[:at] + rng.integers(0, 256, k, dtype=np.uint8).tobytes() + b[at:]), f"insert {k} at {at}"
    at = int(rng.integers(0, n))
    k = int(rng.integers(1, 65))
    if op == "repeat":
        return bytes(b[: at + k] + b[at : at + k] + b[at + k :]), f"repeat {k} at {at}"
    b[at : at + k] = bytes(len(b[at : at + k]))
    return bytes(b), f"zero {k} at {at}"


NUMBERS: list[Any] = [0, -1, 1, 2, 3, 7, 0.5, -0.0, 1e-300, 1e308, -1e308, 10**400, 2**63, math.nan, math.inf]
VALUES: list[Any] = [*NUMBERS, None, True, False, "", "x", "box", "points", "cloud.npy", "depth.npy", "mesh.obj"]
VALUES += ["missing.ply", "/", "..", [], {}, [0, 0], [1, 2, 3], [1, 2, 3, 4], [[1]], {"x": 1}, [None] * 3, "é" * 3]


def _nodes(doc: Any, at: tuple[Any, ...] = ()) -> Iterator[tuple[tuple[Any, ...], Any]]:
    yield at, doc
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _nodes(v, (*at, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from _nodes(v, (*at, i))


def json_edit(doc: Any, rng: np.random.Generator) -> str:
    """Edit ``doc`` in place at a random node: replace, delete, add or repeat a value, or
    nest it deeply; returns what was done."""
    nodes = list(_nodes(doc))
    path, node = nodes[int(rng.integers(len(nodes)))]
    op = ("replace", "delete", "add", "repeat", "nest", "number")[int(rng.integers(6))]
    if not path:
        return "nothing (the root)"
    parent = doc
    for key in path[:-1]:
        parent = parent[key]
    key = path[-1]
    value = copy.deepcopy(VALUES[int(rng.integers(len(VALUES)))])
    if op == "delete":
        del parent[key]
    elif op == "add" and isinstance(node, dict):
        node[str(rng.choice(["extra", "type", "path", "depth", "k", "stride", "radius"]))] = value
    elif op == "add" and isinstance(node, list):
        node.insert(int(rng.integers(len(node) + 1)), value)
    elif op == "repeat" and isinstance(node, list) and node:
        node.extend(copy.deepcopy(node))
    elif op == "nest":
        parent[key] = [[[[[[node]]]]]] if rng.random() < 0.5 else {"x": node}
    elif op == "number" and isinstance(node, (int, float)) and not isinstance(node, bool):
        parent[key] = node * float(rng.choice([-1.0, 0.0, 1e-9, 1e9, math.nan, math.inf]))
    else:
        parent[key] = value
    return f"{op} at {'/'.join(map(str, path))}"


def npy_edit(data: bytes, rng: np.random.Generator) -> Mutation:
    """A ``.npy`` file with its header's shape, dtype or order rewritten."""
    end = data.index(b"\n") + 1
    header = data[10:end].decode("latin1")
    op = int(rng.integers(3))
    if op == 0:
        shape = tuple(int(x) for x in rng.choice([0, 1, 2, 3, 4, 6, 7, 100, 2**31, 2**40], int(rng.integers(0, 4))))
        header = re.sub(r"'shape': \([^)]*\)", f"'shape': {shape!r}", header)
        what = f"shape {shape}"
    elif op == 1:
        descr = str(rng.choice(["<i2", "<u2", "|O", "<c16", "|b1", "<U3", ">f4", "<f2", "|V8", "<M8[s]", "|S4"]))
        header = re.sub(r"'descr': '[^']*'", f"'descr': '{descr}'", header)
        what = f"dtype {descr}"
    else:
        header = header.replace("False", "True")
        what = "fortran order"
    body = header.rstrip("\n").encode("latin1") + b"\n"
    return data[:8] + struct.pack("<H", len(body)) + body + data[end:], what


def ply_edit(data: bytes, rng: np.random.Generator) -> Mutation:
    """A PLY file with its header's vertex count, a property or its format rewritten."""
    head, sep, body = data.partition(b"end_header\n")
    text = head.decode("ascii")
    op = int(rng.integers(3))
    if op == 0:
        count = int(rng.choice([0, 1, 2, 5, 39, 41, 10**6, 2**31, -1]))
        text = re.sub(r"element vertex \d+", f"element vertex {count}", text)
        what = f"vertex count {count}"
    elif op == 1:
        prop = str(rng.choice(["property list uchar float x", "property double x", "property char x", "property x"]))
        text = text.replace("property float x", prop, 1)
        what = prop
    else:
        fmt = str(rng.choice(["ascii", "binary_big_endian", "binary_little_endian", "binary"]))
        text = re.sub(r"format \S+", f"format {fmt}", text)
        what = f"format {fmt}"
    return text.encode("ascii") + sep + body, what


def text_edit(data: bytes, rng: np.random.Generator) -> Mutation:
    """A text file with a token replaced, a line dropped or a line added."""
    lines = data.decode("ascii").splitlines()
    i = int(rng.integers(len(lines)))
    op = int(rng.integers(3))
    if op == 0:
        tokens = lines[i].split()
        j = int(rng.integers(len(tokens))) if tokens else 0
        new = str(rng.choice(["nan", "inf", "-inf", "1e999", "-", "x", "0x10", "1,2", "", "1 2"]))
        tokens[j : j + 1] = [new]
        lines[i] = " ".join(tokens)
        what = f"token {j} of line {i} -> {new!r}"
    elif op == 1:
        del lines[i]
        what = f"drop line {i}"
    else:
        lines.insert(i, str(rng.choice(["1 2", "1 2 3 4 5", "# note", "", "a b c", "1 2 3 4 5 6 7"])))
        what = f"add a line at {i}"
    return ("\n".join(lines) + "\n").encode("ascii"), what


def png_edit(data: bytes, rng: np.random.Generator) -> Mutation:
    """A PNG with its width, height, bit depth or colour type rewritten (checksum redone)."""
    start = 8 + 8  # signature, IHDR length and type
    ihdr = bytearray(data[start : start + 13])
    op = int(rng.integers(3))
    if op == 0:
        w, h = (int(x) for x in rng.choice([0, 1, 9, 11, 12, 100, 2**16, 2**31 - 1], 2))
        ihdr[0:8] = struct.pack(">II", w, h)
        what = f"size {w} x {h}"
    elif op == 1:
        ihdr[8] = int(rng.choice([1, 2, 4, 8, 16, 32]))
        what = f"bit depth {ihdr[8]}"
    else:
        ihdr[9] = int(rng.choice([0, 2, 3, 4, 6, 7]))
        what = f"colour type {ihdr[9]}"
    crc = struct.pack(">I", zlib.crc32(b"IHDR" + bytes(ihdr)) & 0xFFFFFFFF)
    return data[:start] + bytes(ihdr) + crc + data[start + 17 :], what


# ---------------------------------------------------------------------------- sample files
def cloud(n: int = 40, seed: int = 0) -> np.ndarray:
    """Points on a box's surface (enough for the normal fit, few enough to be quick)."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(-0.3, 0.3, (n, 3))
    axis = rng.integers(0, 3, n)
    p[np.arange(n), axis] = np.sign(rng.standard_normal(n)) * 0.3
    return p


def ply_bytes(binary: bool) -> bytes:
    p = cloud().astype(np.float32)
    head = f"ply\nformat {'binary_little_endian' if binary else 'ascii'} 1.0\nelement vertex {len(p)}\n"
    head += "property float x\nproperty float y\nproperty float z\nend_header\n"
    body = p.tobytes() if binary else "".join(f"{x} {y} {z}\n" for x, y, z in p).encode("ascii")
    return head.encode("ascii") + body


def npy_bytes(array: np.ndarray, path: Path) -> bytes:
    np.save(path, array)
    return path.read_bytes()


def depth_image() -> np.ndarray:
    depth = np.full((8, 12), 1.5)
    depth[2:5, 3:7] = 1.2  # a block in front of the floor
    depth[0, 0] = 0.0
    return depth


def scene_doc() -> dict[str, Any]:
    return {
        "format": "pointplan-scene",
        "version": 1,
        "dim": 3,
        "name": "fuzz",
        "bounds": {"low": [-1, -1, -1], "high": [1, 1, 2]},
        "robot": "sphere3d",
        "obstacles": [
            {"type": "box", "center": [0.5, 0.5, 0.5], "size": [0.2, 0.3, 0.1], "quaternion": [0, 0, 0.3, 1]},
            {"type": "sphere", "center": [-0.5, 0.5, 0.0], "radius": 0.1},
            {"type": "capsule", "a": [0, 0, 0], "b": [0, 0.2, 0], "radius": 0.05},
            {"type": "cylinder", "center": [0, -0.5, 0], "radius": 0.1, "length": 0.4},
            {"type": "mesh", "path": "mesh.obj", "scale": 0.5, "position": [0, 0, 0.5]},
            {"type": "points", "path": "cloud.npy", "k": 6, "viewpoint": [0, 0, 2]},
            {
                "type": "points",
                "depth": "depth.npy",
                "intrinsics": dict(zip(("fx", "fy", "cx", "cy"), INTR)),
                "camera_pose": {"position": [0, 0, 2], "quaternion": [1, 0, 0, 0]},
                "depth_scale": 1.0,
                "stride": 1,
            },
        ],
        "problems": [{"start": [-0.8, -0.8, -0.8], "goal": [0.8, 0.8, 0.8], "tag": "p"}],
    }


MESH = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n"


# ---------------------------------------------------------------------------- the runner
def run_cases(
    name: str,
    path: Path,
    cases: Iterator[Mutation],
    loader: Callable[[Path], object],
    errors: tuple[type[BaseException], ...],
) -> int:
    """Feed each case to ``loader``; fail listing the cases that raised anything but
    ``errors`` with a one-line message, or ran past the time limit."""
    bad: list[str] = []
    n = loaded = 0
    for data, what in cases:
        n += 1
        path.write_bytes(data)
        try:
            with warnings.catch_warnings(), time_limit(LIMIT_S):
                warnings.simplefilter("ignore")
                loader(path)
            loaded += 1
        except errors as exc:
            message = str(exc)
            if not message.strip() or "\n" in message.strip():
                bad.append(f"{name} case {n} ({what}): {type(exc).__name__} not in one line: {message!r}")
        except Exception as exc:  # what the test is for
            bad.append(f"{name} case {n} ({what}): {type(exc).__name__}: {str(exc)[:200]}")
    print(f"fuzz {name}: {n} cases ({loaded} loaded), {len(bad)} tracebacks")
    assert not bad, f"{len(bad)} of {n} cases failed:\n" + "\n".join(bad[:30])
    return n


def byte_cases(data: bytes, n: int, seed: int, edit: Callable[..., Mutation] | None = None) -> Iterator[Mutation]:
    """``n`` mutations of ``data``: byte-level ones, and every third one ``edit`` if given."""
    rng = np.random.default_rng(seed)
    for i in range(n):
        if edit is not None and i % 3 == 0:
            yield edit(data, rng)
        else:
            yield byte_mutation(data, rng)


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    """The files a scene file refers to."""
    np.save(tmp_path / "cloud.npy", cloud(20))
    np.save(tmp_path / "depth.npy", depth_image())
    (tmp_path / "mesh.obj").write_text(MESH)
    return tmp_path


def test_scene_files(folder: Path) -> None:
    base = scene_doc()
    assert load_scene_ok(folder, base)
    rng = np.random.default_rng(1)

    def cases() -> Iterator[Mutation]:
        text = json.dumps(base, indent=1).encode()
        for i in range(800):
            if i % 4 == 3:
                yield byte_mutation(text, rng)
                continue
            doc = copy.deepcopy(base)
            done = [json_edit(doc, rng) for _ in range(int(rng.integers(1, 4)))]
            yield json.dumps(doc).encode(), "; ".join(done)

    run_cases("scene file", folder / "scene.json", cases(), load_scene, (SceneFormatError,))


def load_scene_ok(folder: Path, doc: dict[str, Any]) -> bool:
    (folder / "scene.json").write_text(json.dumps(doc))
    return len(load_scene(folder / "scene.json").scene.obstacles) == len(doc["obstacles"])


def point_sample(kind: str, folder: Path) -> tuple[bytes, Callable[..., Mutation] | None]:
    """A valid file of ``kind`` and the structured edit for it."""
    if kind.startswith("pcd"):
        pypcd4 = pytest.importorskip("pypcd4")
        ascii = kind.endswith("ascii")
        encoding = pypcd4.Encoding.ASCII if ascii else pypcd4.Encoding.BINARY
        pypcd4.PointCloud.from_xyz_points(cloud().astype(np.float32)).save(folder / "s.pcd", encoding=encoding)
        return (folder / "s.pcd").read_bytes(), text_edit if ascii else None  # an ASCII PCD is text throughout
    if kind.startswith("ply"):
        return ply_bytes(kind.endswith("binary")), ply_edit
    if kind == "npy":
        return npy_bytes(np.c_[cloud(), np.zeros((40, 3)) + [0, 0, 1]], folder / "s.npy"), npy_edit
    return "".join(f"{x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in cloud()).encode(), text_edit


@pytest.mark.parametrize("kind", ["ply-ascii", "ply-binary", "npy", "xyz", "pcd-binary", "pcd-ascii"])
def test_point_files(tmp_path: Path, kind: str) -> None:
    data, edit = point_sample(kind, tmp_path)
    path = tmp_path / f"fuzz.{kind.split('-')[0]}"
    path.write_bytes(data)
    assert len(load_points_scene(path).obstacles[0].points) == 40
    cases = byte_cases(data, 350, seed=zlib.crc32(kind.encode()), edit=edit)
    run_cases(kind, path, cases, load_points_scene, (SceneFormatError,))


@pytest.mark.parametrize("kind", ["npy", "png"])
def test_depth_images(tmp_path: Path, kind: str) -> None:
    depth = depth_image()
    if kind == "png":
        from PIL import Image

        Image.fromarray((depth * 1000).astype(np.uint16)).save(tmp_path / "s.png")
        data, edit = (tmp_path / "s.png").read_bytes(), png_edit
    else:
        data, edit = npy_bytes(depth, tmp_path / "s.npy"), npy_edit
    path = tmp_path / f"fuzz.{kind}"
    path.write_bytes(data)

    def load(p: Path) -> object:
        return load_depth_scene(p, INTR, POSE)

    assert len(load(path).obstacles[0].points) == depth.size - 1
    run_cases(f"depth {kind}", path, byte_cases(data, 400, seed=7 + len(kind), edit=edit), load, (SceneFormatError,))


POOL: list[Any] = [None, -1, 0, 3, 2.5, "x", "disc2d", "sshape", "global", [], {}, [64], [64, 4, 2], [1, 1]]
#: more values for the MPNet and sampler checkpoints: their other names, huge and
#: non-finite numbers, positions
MORE: list[Any] = [*POOL, "sphere3d", "surface-normals", "mpnet", "lsample-cvae", "world", "start-goal", True]
MORE += [1.0, 0.99, 10**9, 10**400, 2**63, 1e-300, math.nan, math.inf, -math.inf, ["0", "1"]]
MORE += [[0.5, 0.5], [0.0, 0.0, 0.0], [math.nan, 0.5], [[0.5, 0.5]], [1.0, 0.0]]


def weights_edit(weights: dict[str, Any], key: str, rng: np.random.Generator) -> str:
    """Replace a weight by one of another shape, of its shape in another dtype, or by non-finite values."""
    import torch

    dtypes = [torch.int64, torch.bool, torch.complex64, torch.float16, torch.float64, torch.uint8]
    op = int(rng.integers(3))
    w = weights[key]
    if op == 0 or not isinstance(w, torch.Tensor):
        shape = tuple(int(x) for x in rng.integers(0, 5, int(rng.integers(0, 3))))
        weights[key] = torch.zeros(shape)
        return f"zeros {shape}"
    if op == 1:
        dtype = dtypes[int(rng.integers(len(dtypes)))]
        weights[key] = torch.zeros(w.shape, dtype=dtype)
        return f"zeros {tuple(w.shape)} of {dtype}"
    weights[key] = torch.full(w.shape, float(rng.choice([math.nan, math.inf, 1e30])))
    return f"{tuple(w.shape)} of {weights[key].reshape(-1)[:1].item()}"


def checkpoint_edit(
    data: dict[str, Any], rng: np.random.Generator, parts: tuple[str, str] = ("net", "actor"), more: bool = False
) -> str:
    """Edit a loaded checkpoint in place: drop or replace a value at the top, in the
    network settings or among the weights (``parts``: their keys); ``more``: from a larger
    pool of values, and weights of other dtypes and non-finite ones too."""
    import torch

    where = str(rng.choice(["top", *parts]))
    target = data.get(where) if where != "top" else data
    if not isinstance(target, dict) or not target:  # gone in an earlier edit
        where, target = "top", data
    key = str(rng.choice(sorted(target)))
    op = int(rng.integers(3))
    if op == 0:
        del target[key]
        return f"delete {where}/{key}"
    if where == parts[1] and op == 1:
        if more:
            return f"{where}/{key} -> {weights_edit(target, key, rng)}"
        shape = tuple(int(x) for x in rng.integers(0, 5, int(rng.integers(0, 3))))
        target[key] = torch.zeros(shape)
        return f"{where}/{key} -> zeros {shape}"
    pool = MORE if more else POOL
    value = copy.deepcopy(pool[int(rng.integers(len(pool)))])
    target[key] = value
    return f"{where}/{key} -> {value!r}"


def checkpoint_cases(
    source: Path,
    path: Path,
    n: int,
    seed: int,
    parts: tuple[str, str] = ("net", "actor"),
    more: bool = False,
    edited: int = 3,
) -> Iterator[Mutation]:
    """``n`` mutations of the checkpoint ``source``: one in ``edited`` its contents edited
    (:func:`checkpoint_edit`, written to ``path``), the others its bytes."""
    import torch

    original = torch.load(source, weights_only=True)
    raw = source.read_bytes()
    rng = np.random.default_rng(seed)
    for i in range(n):
        if i % edited == 0:
            data = copy.deepcopy(original)
            what = "; ".join(checkpoint_edit(data, rng, parts, more) for _ in range(int(rng.integers(1, 3))))
            torch.save(data, path)
            yield path.read_bytes(), what
        else:
            yield byte_mutation(raw, rng)


def test_policy_checkpoints(tmp_path: Path) -> None:
    from pointplan.models.policy import Policy

    path = tmp_path / "fuzz.pt"
    cases = checkpoint_cases(DATA / "narrow2d_policy.pt", path, 450, seed=11)
    run_cases("policy checkpoint", path, cases, Policy.from_checkpoint, (CheckpointError,))


@pytest.mark.parametrize(
    ("planner", "source", "parts"),
    [
        ("mpnet-nr", "narrow2d_mpnet.pt", ("net", "model")),
        ("lsample-0.5", "narrow2d_lsample_cvae.pt", ("cvae", "weights")),
    ],
)
def test_mpnet_and_sampler_checkpoints(tmp_path: Path, planner: str, source: str, parts: tuple[str, str]) -> None:
    """Loaded as the CLI loads them: through the planner's factory, with a checkpoint."""
    from pointplan.planners import make_planner
    from pointplan.robots import Disc2D

    def load(p: Path) -> object:
        return make_planner(planner, Disc2D(), checkpoint=str(p))

    path = tmp_path / "fuzz.pt"
    load(DATA / source)
    cases = checkpoint_cases(DATA / source, path, 300, zlib.crc32(source.encode()), parts, more=True, edited=2)
    run_cases(f"{planner} checkpoint", path, cases, load, (CheckpointError,))


# ---------------------------------------------------------------------------- what the fuzz found
def test_a_pcd_header_problem_is_one_line(tmp_path: Path) -> None:
    pytest.importorskip("pypcd4")
    (tmp_path / "cut.pcd").write_bytes(b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\n")
    with pytest.raises(SceneFormatError) as e:
        load_points_scene(tmp_path / "cut.pcd")
    message = str(e.value)
    assert "\n" not in message and "cannot read PCD file 'cut.pcd': " in message and "Field required" in message


def test_an_empty_depth_image_of_a_huge_width_is_refused(tmp_path: Path) -> None:
    data = npy_bytes(np.zeros((0, 4)), tmp_path / "s.npy")
    head = data.decode("latin1").replace("(0, 4)", f"(0, {2**40})").encode("latin1")
    (tmp_path / "wide.npy").write_bytes(head)
    with pytest.raises(SceneFormatError, match="holds no valid pixel"):
        load_depth_scene(tmp_path / "wide.npy", INTR, POSE)


@pytest.mark.parametrize("stride", [10**400, 2**63, 12, 13])
def test_a_stride_longer_than_the_image_keeps_its_first_pixel(folder: Path, stride: int) -> None:
    np.save(folder / "depth.npy", np.full((8, 12), 1.5))
    doc = scene_doc()
    doc["obstacles"] = doc["obstacles"][-1:]
    doc["obstacles"][0]["stride"] = stride
    assert load_scene_ok(folder, doc)
    points = load_scene(folder / "scene.json").scene.obstacles[0].points
    assert len(points) == 1 and points[0, 2] == pytest.approx(0.5)  # 1.5 below the camera


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.pop("actor"), "not a policy checkpoint (it has no 'actor')"),
        (lambda d: d.update(obs_shape=[64, -4]), "obs_shape must be a list of positive integers"),
        (lambda d: d["net"].update(head_width=100_000), "the actor's weights do not match its settings"),
        (lambda d: d["net"].update(encoder="x"), "not a usable policy checkpoint (AttributeError"),
        (lambda d: d.update(robot="tank"), "not a usable policy checkpoint (ValueError: unknown robot 'tank'"),
    ],
)
def test_a_policy_checkpoint_with_bad_contents_is_refused_in_one_line(
    tmp_path: Path, edit: Callable[[dict[str, Any]], object], message: str
) -> None:
    import torch

    from pointplan.models.policy import Policy

    data = torch.load(DATA / "narrow2d_policy.pt", weights_only=True)
    edit(data)
    torch.save(data, tmp_path / "bad.pt")
    with pytest.raises(CheckpointError) as e:
        Policy.from_checkpoint(tmp_path / "bad.pt")
    assert message in str(e.value) and "\n" not in str(e.value)


def _lsample(path: Path) -> object:
    from pointplan.planners.learned_sampling import LearnedSampler
    from pointplan.robots import Disc2D

    return LearnedSampler(path, Disc2D(), 0.5)


def _mpnet(path: Path) -> object:
    from pointplan.models.mpnet import MPNet

    return MPNet.from_checkpoint(path)


@pytest.mark.parametrize(
    ("load", "source", "edit", "message"),
    [
        (_mpnet, "narrow2d_mpnet.pt", lambda d: d.pop("robot"), "not an MPNet checkpoint (it has no 'robot')"),
        (_mpnet, "narrow2d_mpnet.pt", lambda d: d["net"].update(width="x"), "width must be an integer from 1 to"),
        (_mpnet, "narrow2d_mpnet.pt", lambda d: d["net"].update(layers=2**63), "layers must be an integer from 0 to"),
        (_mpnet, "narrow2d_mpnet.pt", lambda d: d["net"].update(dropout=1.0), "dropout must be a number from 0"),
        (_mpnet, "narrow2d_mpnet.pt", lambda d: d["net"].update(foo=1), "(ValueError: unknown MPNetNetConfig settings"),
        (_mpnet, "narrow2d_mpnet.pt", lambda d: d.update(center=[[0.5, 0.5]]), "center must be 2 numbers"),
        (_mpnet, "narrow2d_mpnet.pt", lambda d: d.update(step=math.nan), "step must be a positive number"),
        (_mpnet, "narrow2d_mpnet.pt", lambda d: d.update(observation=-1), "its observation must be"),
        (_mpnet, "narrow2d_mpnet.pt", lambda d: d.update(robot="sshape"), "MPNet plans translating robots only"),
        (_mpnet, "narrow2d_mpnet.pt", lambda d: d.update(point_features=3), "point_features must be 4"),
        (_mpnet, "narrow2d_mpnet.pt", lambda d: d["model"]["pnet.9.bias"].fill_(math.nan), "not finite"),
        (_lsample, "narrow2d_lsample_cvae.pt", lambda d: d.update(weights=1.0), "weights are float, not a state dict"),
        (_lsample, "narrow2d_lsample_cvae.pt", lambda d: d["cvae"].update(frame=[0]), "frame must be 'world' or"),
        (_lsample, "narrow2d_lsample_cvae.pt", lambda d: d["cvae"].update(min_half=[1]), "min_half must be a positive"),
        (_lsample, "narrow2d_lsample_cvae.pt", lambda d: d.update(high=0.99), "low and high must be 2 numbers each"),
        (_lsample, "narrow2d_lsample_cvae.pt", lambda d: d.update(low=[1.0, 0.0]), "low must be below high"),
        (_lsample, "narrow2d_lsample_cvae.pt", lambda d: d.pop("spacing"), "it has no 'spacing'"),
        (_lsample, "narrow2d_lsample_cvae.pt", lambda d: d.update(robot=[1, 1]), "was trained for robot [1, 1]"),
        (
            _lsample,
            "narrow2d_lsample_cvae.pt",
            lambda d: d["weights"].update({"cvae.decoder.4.bias": d["weights"]["cvae.decoder.4.bias"].long()}),
            "cvae.decoder.4.bias holds torch.int64 values, not floating point numbers",
        ),
    ],
)
def test_an_mpnet_or_sampler_checkpoint_with_bad_contents_is_refused_in_one_line(
    tmp_path: Path, load: Callable[[Path], object], source: str, edit: Callable[[dict[str, Any]], object], message: str
) -> None:
    import torch

    data = torch.load(DATA / source, weights_only=True)
    edit(data)
    torch.save(data, tmp_path / "bad.pt")
    with pytest.raises(CheckpointError) as e:
        load(tmp_path / "bad.pt")
    assert message in str(e.value) and "\n" not in str(e.value) and "bad.pt" in str(e.value)
