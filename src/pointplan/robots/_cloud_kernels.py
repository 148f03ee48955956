"""Compiled (numba) test of oriented boxes against a point cloud sorted into a uniform grid
(:meth:`CollisionWorld.cloud_grid <pointplan.geometry.collision.CollisionWorld.cloud_grid>`):
the answer of :func:`pointplan.geometry.collision.boxes_contain_cloud_points` (does a
cloud point, a sphere of the cloud's point radius, touch the closed box?) computed with
the same arithmetic on the points of the cells near the box only.

:func:`box_hits_cloud` takes the cells the box's bounding box (grown by the point radius,
with a slack for round-off) covers: none of them holds a point (the grid's prefix sums
say so in eight reads) for most boxes in free space; otherwise it goes through them
column by column (a column's cells are consecutive rows: an empty one is one read),
skips each cell whose cube is separated from the grown box along one of the box's axes,
and tests the points of the others exactly as the numpy function does (``local_i = sum_j (p_j - c_j) R_ji``, the excess over the half sides
squared and summed in axis order, a hit when at most the radius squared), so the answer is
the brute force's. The S-shape's compiled checks (:mod:`._body_kernels`) take a scene's
obstacles as ``(box centres, rotations, half sides)`` or, with a cloud, ``(..., grid)``;
:func:`_cloud_hits` tests a body's boxes against the grid of the second kind and is
``False`` for the first (chosen when the caller is compiled). numba's cache of those
callers does not see edits here: delete their cache files (``__pycache__/_body_kernels.*``,
``_shortcut_kernels.*``, ``planners/__pycache__/_rigid_kernels.*`` ``.nbi``/``.nbc``)
after changing this module.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import types
from numba.extending import overload

from ..geometry.raycast import sphere_entry

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")


@_jit
def _cell_range(ca, e, o, inv, n):  # type: ignore[no-untyped-def]
    """The cells ``[lo, hi]`` (within ``[0, n - 1]``; empty where ``lo > hi``) along one
    axis holding the points in ``[ca - e, ca + e]``: a point's cell is ``floor((x - o) *
    inv)``, which never decreases with ``x``."""
    lo = (ca - e - o) * inv
    hi = (ca + e - o) * inv
    if not (hi >= 0.0 and lo < n):  # (also a NaN)
        return 0, -1
    return math.floor(max(lo, 0.0)), math.floor(min(hi, n - 1.0))


@_jit
def _point_hits(pts, t, c, rot, h, m2):  # type: ignore[no-untyped-def]
    """Is point ``t`` within ``sqrt(m2)`` of the box (``boxes_contain_cloud_points``'
    arithmetic, in its order)?"""
    d0 = pts[t, 0] - c[0]
    d1 = pts[t, 1] - c[1]
    d2 = pts[t, 2] - c[2]
    acc = 0.0
    for i in range(3):
        local = d0 * rot[0, i] + d1 * rot[1, i]
        local = local + d2 * rot[2, i]
        ex = abs(local) - h[i]
        if ex > 0.0:
            acc += ex * ex
            if acc > m2:
                return False
    return acc <= m2


@_jit
def _count(cum, n1, n2, x0, x1, y0, y1, z0, z1):  # type: ignore[no-untyped-def]
    """The points in the cells ``[x0, x1] x [y0, y1] x [z0, z1]`` from the grid's prefix
    sums ``cum``: the points in the cells below ``(i, j, k)`` at ``(i * (n1 + 1) + j) *
    (n2 + 1) + k``."""
    a, b = n1 + 1, n2 + 1
    i0, i1, j0, j1 = x0 * a, (x1 + 1) * a, y0, y1 + 1
    k0, k1 = z0, z1 + 1
    return (
        cum[(i1 + j1) * b + k1] - cum[(i1 + j1) * b + k0] - cum[(i1 + j0) * b + k1] + cum[(i1 + j0) * b + k0]
        - cum[(i0 + j1) * b + k1] + cum[(i0 + j1) * b + k0] + cum[(i0 + j0) * b + k1] - cum[(i0 + j0) * b + k0]
    )  # fmt: skip


@_jit
def _narrow(b, s, t, za, zb, cell):  # type: ignore[no-untyped-def]
    """The cells ``iz`` of ``[za, zb]`` where ``|b + iz s| <= t`` may hold, widened by one
    cell for round-off (each is still tested); unchanged where ``s`` is too small to
    divide by safely."""
    if abs(s) < 1e-6 * cell:
        return za, zb
    lo, hi = (-t - b) / s, (t - b) / s
    if s < 0.0:
        lo, hi = hi, lo
    lo = max(lo, za - 2.0)
    hi = min(hi, zb + 2.0)
    return max(za, math.ceil(lo) - 1), min(zb, math.floor(hi) + 1)


@_jit
def box_hits_cloud(c, rot, h, grid):  # type: ignore[no-untyped-def]
    """Does a point of the cloud ``grid`` (its point radius included) touch the box of
    centre ``c (3,)``, rotation ``rot (3, 3)`` (columns: the box's axes) and half sides
    ``h (3,)``?"""
    pts, starts, origin, dims, params, cum = grid
    inv, cell, margin, slack = params[0], params[1], params[2], params[3]
    m2 = margin * margin
    half = 0.5 * cell
    # the bounding box of the box grown by the radius; the cells it covers
    e0 = (abs(rot[0, 0]) * h[0] + abs(rot[0, 1]) * h[1] + abs(rot[0, 2]) * h[2] + margin) * (1.0 + 1e-9) + slack
    e1 = (abs(rot[1, 0]) * h[0] + abs(rot[1, 1]) * h[1] + abs(rot[1, 2]) * h[2] + margin) * (1.0 + 1e-9) + slack
    e2 = (abs(rot[2, 0]) * h[0] + abs(rot[2, 1]) * h[1] + abs(rot[2, 2]) * h[2] + margin) * (1.0 + 1e-9) + slack
    x0, x1 = _cell_range(c[0], e0, origin[0], inv, dims[0])
    y0, y1 = _cell_range(c[1], e1, origin[1], inv, dims[1])
    z0, z1 = _cell_range(c[2], e2, origin[2], inv, dims[2])
    n1, n2 = dims[1], dims[2]
    if x0 > x1 or y0 > y1 or z0 > z1 or _count(cum, n1, n2, x0, x1, y0, y1, z0, z1) == 0:
        return False
    # a cell's points lie within half a cell (per world axis) of its centre: along box axis
    # i they are then within half * sum_a |R_ai| of the centre's coordinate
    t0 = (h[0] + margin + half * (abs(rot[0, 0]) + abs(rot[1, 0]) + abs(rot[2, 0]))) * (1.0 + 1e-9) + slack
    t1 = (h[1] + margin + half * (abs(rot[0, 1]) + abs(rot[1, 1]) + abs(rot[2, 1]))) * (1.0 + 1e-9) + slack
    t2 = (h[2] + margin + half * (abs(rot[0, 2]) + abs(rot[1, 2]) + abs(rot[2, 2]))) * (1.0 + 1e-9) + slack
    s0, s1, s2 = cell * rot[2, 0], cell * rot[2, 1], cell * rot[2, 2]  # a cell up in z, in box axes
    dz = origin[2] + half - c[2]
    for ix in range(x0, x1 + 1):
        dx = origin[0] + (ix + 0.5) * cell - c[0]
        for iy in range(y0, y1 + 1):
            row = (ix * n1 + iy) * n2
            if starts[row + z1 + 1] == starts[row + z0]:
                continue  # no point in the column's cells
            dy = origin[1] + (iy + 0.5) * cell - c[1]
            b0 = dx * rot[0, 0] + dy * rot[1, 0] + dz * rot[2, 0]
            b1 = dx * rot[0, 1] + dy * rot[1, 1] + dz * rot[2, 1]
            b2 = dx * rot[0, 2] + dy * rot[1, 2] + dz * rot[2, 2]
            za, zb = _narrow(b0, s0, t0, z0, z1, cell)
            za, zb = _narrow(b1, s1, t1, za, zb, cell)
            za, zb = _narrow(b2, s2, t2, za, zb, cell)
            for iz in range(za, zb + 1):
                if abs(b0 + iz * s0) > t0 or abs(b1 + iz * s1) > t1 or abs(b2 + iz * s2) > t2:
                    continue
                for t in range(starts[row + iz], starts[row + iz + 1]):
                    if _point_hits(pts, t, c, rot, h, m2):
                        return True
    return False


@_jit
def boxes_hit_cloud(c, rot, h, grid, out):  # type: ignore[no-untyped-def]
    """:func:`box_hits_cloud` for boxes ``c (M, 3)``, ``rot (M, 3, 3)``, ``h (M, 3)`` into
    ``out (M,)``."""
    for i in range(c.shape[0]):
        out[i] = box_hits_cloud(c[i], rot[i], h[i], grid)


@_jit
def ray_hits_cloud(o, d, grid, oid, limit, bound):  # type: ignore[no-untyped-def]
    """The first of the cloud's spheres (the grid's points, its point radius) that the ray
    from ``o (3,)`` along the unit ``d (3,)`` enters, if closer than ``limit``: ``(t, its
    row in the grid's order)``, else ``(limit, -1)``; found for every ``t`` up to
    ``bound`` (further hits may be missed). The answer of
    :func:`pointplan.geometry.raycast._first_cloud_hits` with the same arithmetic, ties
    going to the lowest index in the cloud (``oid``: the rows' indices there).

    The cells the ray passes through are walked in order (Amanatides and Woo's traversal,
    from ``o``), each with the block of cells within ``k`` cells of it, ``k`` the point
    radius in cells rounded up: a sphere the ray enters at ``t_e`` holds the ray's point
    at ``t* = max(t_p, 0)`` (``t_p`` the centre's projection, ``t_e >= t* - radius``),
    whose cell is within ``k`` cells of the centre's, so the walk stops at the first cell
    entered past the best hit (or ``bound``) plus the radius."""
    origin, dims, params = grid[2], grid[3], grid[4]
    inv, r = params[0], params[2]
    n0, n1, n2 = dims[0], dims[1], dims[2]
    k = int(math.floor(r * inv + 1e-6)) + 1
    slack = 1e-9 * (1.0 + abs(bound))
    d0, d1, d2 = d[0], d[1], d[2]
    c0, c1, c2 = (o[0] - origin[0]) * inv, (o[1] - origin[1]) * inv, (o[2] - origin[2]) * inv
    i0, i1, i2 = math.floor(c0), math.floor(c1), math.floor(c2)
    s0, t0, e0 = _axis_walk(c0, i0, d0 * inv)
    s1, t1, e1 = _axis_walk(c1, i1, d1 * inv)
    s2, t2, e2 = _axis_walk(c2, i2, d2 * inv)
    # past ``far`` the ray is more than k cells outside the grid along some axis, for good
    far = min(_axis_exit(c0, d0 * inv, n0, k), _axis_exit(c1, d1 * inv, n1, k), _axis_exit(c2, d2 * inv, n2, k))
    best, which = limit, np.int64(-1)  # (not the literal -1: one compiled _block_hits)
    entry = 0.0
    # the first cell's whole block, then after each step only the block's new face (the
    # blocks of the cells walked so far are then all tested, each cell about once)
    lo0, hi0, lo1, hi1, lo2, hi2 = i0 - k, i0 + k, i1 - k, i1 + k, i2 - k, i2 + k
    while entry <= far and entry - r <= min(best, bound) + slack:
        best, which = _block_hits(o, d, grid, oid, lo0, hi0, lo1, hi1, lo2, hi2, best, which)
        # the next cell along the ray: across the nearest cell wall
        if t0 <= t1 and t0 <= t2:
            entry, i0, t0 = t0, i0 + s0, t0 + e0
            lo0 = hi0 = i0 + s0 * k
            lo1, hi1, lo2, hi2 = i1 - k, i1 + k, i2 - k, i2 + k
        elif t1 <= t2:
            entry, i1, t1 = t1, i1 + s1, t1 + e1
            lo1 = hi1 = i1 + s1 * k
            lo0, hi0, lo2, hi2 = i0 - k, i0 + k, i2 - k, i2 + k
        else:
            entry, i2, t2 = t2, i2 + s2, t2 + e2
            lo2 = hi2 = i2 + s2 * k
            lo0, hi0, lo1, hi1 = i0 - k, i0 + k, i1 - k, i1 + k
        if not entry < np.inf:
            break
    return best, which


@_jit
def _block_hits(o, d, grid, oid, x0, x1, y0, y1, z0, z1, best, which):  # type: ignore[no-untyped-def]
    """:func:`ray_hits_cloud`'s test of the points in the cells ``[x0, x1] x [y0, y1] x
    [z0, z1]`` (clipped to the grid): the nearer ``(best, which)``."""
    starts, dims, r, cum = grid[1], grid[3], grid[4][2], grid[5]
    n0, n1, n2 = dims[0], dims[1], dims[2]
    x0, x1, y0, y1, z0, z1 = max(x0, 0), min(x1, n0 - 1), max(y0, 0), min(y1, n1 - 1), max(z0, 0), min(z1, n2 - 1)
    if x0 > x1 or y0 > y1 or z0 > z1 or _count(cum, n1, n2, x0, x1, y0, y1, z0, z1) == 0:
        return best, which
    for a in range(x0, x1 + 1):
        for b in range(y0, y1 + 1):
            row = (a * n1 + b) * n2
            for t in range(starts[row + z0], starts[row + z1 + 1]):
                te = sphere_entry(grid[0], t, o, d, r, best)
                if te < 0.0:
                    continue
                if te < best or (te == best and which >= 0 and oid[t] < oid[which]):
                    best, which = te, t
    return best, which


@_jit
def _axis_walk(c, i, v):  # type: ignore[no-untyped-def]
    """One axis of the traversal: the step, the ray's distance to the first cell wall it
    crosses and between walls, for the coordinate ``c`` in cells (in cell ``i``) moving by
    ``v`` cells per unit of distance."""
    if v > 0.0:
        return 1, (i + 1.0 - c) / v, 1.0 / v
    if v < 0.0:
        return -1, (i - c) / v, -1.0 / v
    return 0, np.inf, np.inf


@_jit
def _axis_exit(c, v, n, k):  # type: ignore[no-untyped-def]
    """The distance along the ray past which its coordinate ``c`` (in cells, moving by
    ``v`` per unit of distance) is outside ``[-k, n + k]`` for good (``-1``: always is)."""
    if v > 0.0:
        return (n + k - c) / v
    if v < 0.0:
        return (-k - c) / v
    return np.inf if -k <= c <= n + k else -1.0


def _ray_cloud(rboxes, o, d, limit, bound):  # type: ignore[no-untyped-def]
    """:func:`ray_hits_cloud` against the cloud of the ray-casting obstacles ``rboxes``
    (``(box centres, rotations, half sides, valid)``: no cloud, ``(limit, -1)``; ``(...,
    grid, normals in the grid's order, indices in the cloud)``). Compiled callers only."""
    raise NotImplementedError("_ray_cloud is called from compiled code only")


@overload(_ray_cloud, jit_options={"nogil": True, "error_model": "numpy"})
def _ray_cloud_impl(rboxes, o, d, limit, bound):  # type: ignore[no-untyped-def]
    if isinstance(rboxes, types.BaseTuple) and len(rboxes) == 7:

        def with_cloud(rboxes, o, d, limit, bound):  # type: ignore[no-untyped-def]
            return ray_hits_cloud(o, d, rboxes[4], rboxes[6], limit, bound)

        return with_cloud

    def without(rboxes, o, d, limit, bound):  # type: ignore[no-untyped-def]
        return limit, -1

    return without


def _cloud_normal(rboxes, row):  # type: ignore[no-untyped-def]
    """The normal of the cloud point in ``row`` (the grid's order) of the ray-casting
    obstacles ``rboxes`` with a cloud (see :func:`_ray_cloud`). Compiled callers only."""
    raise NotImplementedError("_cloud_normal is called from compiled code only")


@overload(_cloud_normal, jit_options={"nogil": True, "error_model": "numpy"})
def _cloud_normal_impl(rboxes, row):  # type: ignore[no-untyped-def]
    if isinstance(rboxes, types.BaseTuple) and len(rboxes) == 7:

        def with_cloud(rboxes, row):  # type: ignore[no-untyped-def]
            nrm = rboxes[5]
            return nrm[row, 0], nrm[row, 1], nrm[row, 2]

        return with_cloud

    def without(rboxes, row):  # type: ignore[no-untyped-def]
        return 0.0, 0.0, 0.0

    return without


def boxes_contain_cloud_points_compiled(
    grid: tuple[np.ndarray, ...], c: np.ndarray, rot: np.ndarray, h: np.ndarray
) -> np.ndarray:
    """``boxes_contain_cloud_points(tree, c, rot, h, margin)`` through the compiled grid of
    the same cloud and margin: boxes ``(..., 3)``, ``(..., 3, 3)``, ``(..., 3)``; returns
    ``(...)``."""
    f = np.ascontiguousarray
    shape = np.shape(c)[:-1]
    out = np.zeros(shape, np.bool_).reshape(-1)
    boxes_hit_cloud(
        f(np.reshape(c, (-1, 3)), np.float64),
        f(np.reshape(rot, (-1, 3, 3)), np.float64),
        f(np.reshape(np.broadcast_to(h, np.shape(c)), (-1, 3)), np.float64),
        grid,
        out,
    )
    return out.reshape(shape)


def _cloud_hits(obstacles, bc, br, halfs):  # type: ignore[no-untyped-def]
    """Does a point of the obstacles' cloud grid touch one of the boxes ``bc (P, 3)``, ``br
    (P, 3, 3)``, ``halfs (P, 3)``? ``obstacles``: ``(centres, rotations, half sides)`` (no
    cloud: ``False``) or ``(centres, rotations, half sides, grid)``. Compiled callers only
    (the version is chosen by the obstacles' type)."""
    raise NotImplementedError("_cloud_hits is called from compiled code only")


@overload(_cloud_hits, jit_options={"nogil": True, "error_model": "numpy"})
def _cloud_hits_impl(obstacles, bc, br, halfs):  # type: ignore[no-untyped-def]
    if isinstance(obstacles, types.BaseTuple) and len(obstacles) == 4:

        def with_grid(obstacles, bc, br, halfs):  # type: ignore[no-untyped-def]
            grid = obstacles[3]
            for p in range(bc.shape[0]):  # noqa: SIM110 (a loop, for the compiler)
                if box_hits_cloud(bc[p], br[p], halfs[p], grid):
                    return True
            return False

        return with_grid

    def without(obstacles, bc, br, halfs):  # type: ignore[no-untyped-def]
        return False

    return without
