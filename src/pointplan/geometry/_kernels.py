"""Compiled (numba) kernels for the hottest collision test (oriented boxes against oriented
boxes) and for rays against boxes. The numpy versions in ``collision.py`` (``obb_overlap``)
and ``raycast.py`` (``box_slabs_reference``) compute the same and are what the tests compare
them with."""

from __future__ import annotations

import numba
import numpy as np


def _obb_row(ca, ra, ha, i, cb, rb, hb, out, first, rel, absr, t):  # type: ignore[no-untyped-def]
    """Separating-axis test of box ``i`` of A (centres ``ca (M, 3)``, rotations ``ra (M, 3,
    3)`` whose columns are the box axes, half sides ``ha (M, 3)``) against every box of B
    (``(K, ...)``): writes ``out (K,)`` (True where the closed boxes overlap) and returns
    whether any does; with ``first`` it stops at the first overlap (the rest of ``out`` is
    then not written). ``rel``, ``absr`` ``(3, 3)`` and ``t (3,)``: scratch."""
    anyhit = False
    for j in range(cb.shape[0]):
        # bounding-sphere prefilter
        d0 = cb[j, 0] - ca[i, 0]
        d1 = cb[j, 1] - ca[i, 1]
        d2 = cb[j, 2] - ca[i, 2]
        reach = np.sqrt(ha[i, 0] ** 2 + ha[i, 1] ** 2 + ha[i, 2] ** 2) + np.sqrt(
            hb[j, 0] ** 2 + hb[j, 1] ** 2 + hb[j, 2] ** 2
        )
        if d0 * d0 + d1 * d1 + d2 * d2 > reach * reach:
            out[j] = False
            continue
        for p in range(3):
            t[p] = ra[i, 0, p] * d0 + ra[i, 1, p] * d1 + ra[i, 2, p] * d2
            for q in range(3):
                s = 0.0
                for r in range(3):
                    s += ra[i, r, p] * rb[j, r, q]
                rel[p, q] = s
                absr[p, q] = abs(s) + 1e-9
        sep = False
        for p in range(3):  # A's face axes
            rb_ = hb[j, 0] * absr[p, 0] + hb[j, 1] * absr[p, 1] + hb[j, 2] * absr[p, 2]
            if abs(t[p]) > ha[i, p] + rb_:
                sep = True
                break
        if not sep:
            for q in range(3):  # B's face axes
                tb = t[0] * rel[0, q] + t[1] * rel[1, q] + t[2] * rel[2, q]
                ra_ = ha[i, 0] * absr[0, q] + ha[i, 1] * absr[1, q] + ha[i, 2] * absr[2, q]
                if abs(tb) > ra_ + hb[j, q]:
                    sep = True
                    break
        if not sep:
            for p in range(3):  # cross products of edges
                p1, p2 = (p + 1) % 3, (p + 2) % 3
                for q in range(3):
                    q1, q2 = (q + 1) % 3, (q + 2) % 3
                    lhs = abs(t[p2] * rel[p1, q] - t[p1] * rel[p2, q])
                    ra_ = ha[i, p1] * absr[p2, q] + ha[i, p2] * absr[p1, q]
                    rb_ = hb[j, q1] * absr[p, q2] + hb[j, q2] * absr[p, q1]
                    if lhs > ra_ + rb_:
                        sep = True
                        break
                if sep:
                    break
        out[j] = not sep
        if not sep:
            anyhit = True
            if first:
                return True
    return anyhit


_obb_row = numba.njit(cache=True, nogil=True, inline="always")(_obb_row)


def _obb_overlap_flat(ca, ra, ha, cb, rb, hb, out):  # type: ignore[no-untyped-def]
    """Separating-axis test (:func:`_obb_row`) of boxes A ``(B, M, ...)`` against boxes B
    ``(B, K, ...)`` (rotation columns are the box axes, ``h`` half sides); writes ``out
    (B, M, K)``."""
    nb, m, k = out.shape
    rel = np.empty((3, 3))
    absr = np.empty((3, 3))
    t = np.empty(3)
    for b in range(nb):
        cab, rab, hab, cbb, rbb, hbb, outb = ca[b], ra[b], ha[b], cb[b], rb[b], hb[b], out[b]
        for i in range(m):
            _obb_row(cab, rab, hab, i, cbb, rbb, hbb, outb[i], False, rel, absr, t)


_obb_overlap_flat = numba.njit(cache=True, nogil=True)(_obb_overlap_flat)


def obb_overlap_compiled(ca, ra, ha, cb, rb, hb):  # type: ignore[no-untyped-def]
    """``(..., M, K)`` overlap of boxes ``(..., M, ...)`` and ``(..., K, ...)`` (same batch)."""
    batch = ca.shape[:-2]
    m, k = ca.shape[-2], cb.shape[-2]
    nb = int(np.prod(batch)) if batch else 1
    out = np.empty((nb, m, k), dtype=np.bool_)
    f = np.ascontiguousarray
    _obb_overlap_flat(
        f(ca.reshape(nb, m, 3), dtype=np.float64),
        f(ra.reshape(nb, m, 3, 3), dtype=np.float64),
        f(ha.reshape(nb, m, 3), dtype=np.float64),
        f(cb.reshape(nb, k, 3), dtype=np.float64),
        f(rb.reshape(nb, k, 3, 3), dtype=np.float64),
        f(hb.reshape(nb, k, 3), dtype=np.float64),
        out,
    )
    return out.reshape(batch + (m, k))


def _ray_box_row(o, d, r, c, rot, h, t0, t1, axis):  # type: ignore[no-untyped-def]
    """Slab test of ray ``r`` of ``o, d: (R, 3)`` against every box ``c (K, 3)``, ``rot (K,
    3, 3)`` (columns = box axes), half sides ``h (K, 3)``. Writes the entry and exit
    parameters ``t0, t1 (K,)`` (``inf, -inf`` for a miss) and the entry axis (the first of
    the axes whose slab is entered last). A ray parallel to a slab is inside it when its
    origin is in the closed slab."""
    inf = np.inf
    for k in range(c.shape[0]):
        lo_max = -inf
        hi_min = inf
        ax = 0
        for i in range(3):
            # local coordinates: column i of the rotation
            ol = (
                (o[r, 0] - c[k, 0]) * rot[k, 0, i]
                + (o[r, 1] - c[k, 1]) * rot[k, 1, i]
                + (o[r, 2] - c[k, 2]) * rot[k, 2, i]
            )
            dl = d[r, 0] * rot[k, 0, i] + d[r, 1] * rot[k, 1, i] + d[r, 2] * rot[k, 2, i]
            hh = h[k, i]
            if dl == 0.0:
                if -hh <= ol <= hh:
                    lo, hi = -inf, inf
                else:
                    lo, hi = inf, -inf
            else:
                ta = (-hh - ol) / dl
                tb = (hh - ol) / dl
                lo, hi = (ta, tb) if ta <= tb else (tb, ta)
            if i == 0 or lo > lo_max:
                ax = i
                lo_max = lo
            hi_min = min(hi_min, hi)
        if lo_max > hi_min:
            t0[k] = inf
            t1[k] = -inf
        else:
            t0[k] = lo_max
            t1[k] = hi_min
        axis[k] = ax


_ray_box_row = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")(_ray_box_row)


def _ray_box_flat(o, d, c, rot, h, t0, t1, axis):  # type: ignore[no-untyped-def]
    """:func:`_ray_box_row` for rays ``o, d: (B, R, 3)`` against boxes ``c (B, K, 3)``,
    ``rot (B, K, 3, 3)``, ``h (B, K, 3)``: writes ``t0, t1, axis (B, R, K)``."""
    nb, nr, nk = t0.shape
    for b in range(nb):
        ob, db, cb, rotb, hb, t0b, t1b, axb = o[b], d[b], c[b], rot[b], h[b], t0[b], t1[b], axis[b]
        for r in range(nr):
            _ray_box_row(ob, db, r, cb, rotb, hb, t0b[r], t1b[r], axb[r])


_ray_box_flat = numba.njit(cache=True, nogil=True, error_model="numpy")(_ray_box_flat)


def ray_box_compiled(o, d, c, rot, h):  # type: ignore[no-untyped-def]
    """Entry/exit parameters and entry axis ``(B, R, K)`` of rays against boxes."""
    nb, nr = o.shape[:2]
    nk = c.shape[1]
    t0 = np.empty((nb, nr, nk))
    t1 = np.empty((nb, nr, nk))
    axis = np.empty((nb, nr, nk), np.int8)
    f = np.ascontiguousarray
    _ray_box_flat(
        f(o, dtype=np.float64),
        f(np.broadcast_to(d, o.shape), dtype=np.float64),
        f(c, dtype=np.float64),
        f(rot, dtype=np.float64),
        f(h, dtype=np.float64),
        t0,
        t1,
        axis,
    )
    return t0, t1, axis


def _winding_numbers(points, tri, out):  # type: ignore[no-untyped-def]
    """Generalised winding number of the triangles ``tri (F, 3, 3)`` at ``points (N, 3)``:
    the sum of their solid angles (Van Oosterom & Strackee) over 4 pi; writes ``out (N,)``.
    ``collision.mesh_winding_reference`` computes the same with numpy."""
    for n in range(points.shape[0]):
        px, py, pz = points[n, 0], points[n, 1], points[n, 2]
        total = 0.0
        for f in range(tri.shape[0]):
            ax, ay, az = tri[f, 0, 0] - px, tri[f, 0, 1] - py, tri[f, 0, 2] - pz
            bx, by, bz = tri[f, 1, 0] - px, tri[f, 1, 1] - py, tri[f, 1, 2] - pz
            cx, cy, cz = tri[f, 2, 0] - px, tri[f, 2, 1] - py, tri[f, 2, 2] - pz
            la = np.sqrt(ax * ax + ay * ay + az * az)
            lb = np.sqrt(bx * bx + by * by + bz * bz)
            lc = np.sqrt(cx * cx + cy * cy + cz * cz)
            num = ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
            den = (
                la * lb * lc
                + (ax * bx + ay * by + az * bz) * lc
                + (ax * cx + ay * cy + az * cz) * lb
                + (bx * cx + by * cy + bz * cz) * la
            )
            total += np.arctan2(num, den)
        out[n] = total / (2.0 * np.pi)


_winding_numbers = numba.njit(cache=True, nogil=True)(_winding_numbers)


def winding_numbers_compiled(points, tri):  # type: ignore[no-untyped-def]
    """Winding numbers ``(N,)`` of the closed triangle soup ``tri (F, 3, 3)`` at ``points (N, 3)``."""
    out = np.empty(len(points))
    _winding_numbers(np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(tri, dtype=np.float64), out)
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _grid_cube(x, y, z, e, origin, dims, inv, lo, hi):  # type: ignore[no-untyped-def]
    """The cells ``[lo, hi]`` (per axis, clipped to the grid) of the cube ``(x, y, z) +- e``;
    False where it misses the grid (a point's cell is ``floor((p - origin) * inv)``)."""
    for a in range(3):
        v = x if a == 0 else (y if a == 1 else z)
        x0 = (v - e - origin[a]) * inv
        x1 = (v + e - origin[a]) * inv
        if not (x1 >= 0.0 and x0 < dims[a]):  # (also a NaN)
            return False
        lo[a] = np.int64(np.floor(max(x0, 0.0)))
        hi[a] = np.int64(np.floor(min(x1, dims[a] - 1.0)))
    return True


@numba.njit(cache=True, nogil=True, error_model="numpy")
def grid_point_within(x, y, z, reach, pts, starts, origin, dims, params):  # type: ignore[no-untyped-def]
    """Is some point of the grid (``collision.cloud_grid_arrays``: points, row starts,
    origin, cells per axis, ``params`` with ``1 / cell`` first and the round-off slack
    fourth) within ``reach`` of ``(x, y, z)``: ``sqrt(sum((p - c)^2)) <= reach`` (the k-d
    tree's test)? Only the cells the cube ``+- (reach + slack)`` covers are read."""
    lo = np.empty(3, np.int64)
    hi = np.empty(3, np.int64)
    if not _grid_cube(x, y, z, reach + params[3], origin, dims, params[0], lo, hi):
        return False
    n1, n2 = dims[1], dims[2]
    for i in range(lo[0], hi[0] + 1):
        for j in range(lo[1], hi[1] + 1):
            row = (i * n1 + j) * n2
            for q in range(starts[row + lo[2]], starts[row + hi[2] + 1]):
                d0, d1, d2 = pts[q, 0] - x, pts[q, 1] - y, pts[q, 2] - z
                if np.sqrt(d0 * d0 + d1 * d1 + d2 * d2) <= reach:
                    return True
    return False


@numba.njit(cache=True, nogil=True, error_model="numpy")
def grid_nearest_bound(x, y, z, cap, pts, starts, origin, dims, params):  # type: ignore[no-untyped-def]
    """The distance from ``(x, y, z)`` to the nearest point of the grid (see
    :func:`grid_point_within`) where it is at most ``cap``, else a lower bound of it that is
    at least ``cap`` (no point lies within it). Searches cubes of growing half side (two
    cells, doubled up to ``cap``): a point found within the half side is the nearest, since
    every point that near lies in the cube."""
    if pts.shape[0] == 0:
        return np.inf
    lo = np.empty(3, np.int64)
    hi = np.empty(3, np.int64)
    n1, n2 = dims[1], dims[2]
    lim = min(2.0 * params[1], cap)
    while True:
        best = np.inf
        if _grid_cube(x, y, z, lim + params[3], origin, dims, params[0], lo, hi):
            for i in range(lo[0], hi[0] + 1):
                for j in range(lo[1], hi[1] + 1):
                    row = (i * n1 + j) * n2
                    for q in range(starts[row + lo[2]], starts[row + hi[2] + 1]):
                        d0, d1, d2 = pts[q, 0] - x, pts[q, 1] - y, pts[q, 2] - z
                        best = min(best, np.sqrt(d0 * d0 + d1 * d1 + d2 * d2))
        if best <= lim:
            return best
        if lim >= cap:
            return lim
        lim = min(2.0 * lim, cap)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def spheres_hit_cloud_compiled(c, reach, pts, starts, origin, dims, params, out):  # type: ignore[no-untyped-def]
    """``out[m]``: is some point of the cloud's grid within ``reach[m]`` of ``c[m]``
    (``(M, 3)``; :func:`grid_point_within`)?"""
    for m in range(c.shape[0]):
        out[m] = grid_point_within(c[m, 0], c[m, 1], c[m, 2], reach[m], pts, starts, origin, dims, params)
    return out
