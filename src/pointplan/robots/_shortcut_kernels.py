"""Compiled (numba) path shortcutting of Bi-RRT (:meth:`pointplan.planners.birrt.BiRRT.shortcut`)
for the robots with compiled motion checks among boxes: a translating ball
(:mod:`._ball_kernels`, ``kind = 0``) and a free-flying body of boxes
(:mod:`._body_kernels`, ``kind = 1``). The same shortcuts in the same order from the
same draws (``u``: the uniform numbers the Python loop draws, two per iteration, scaled
by the path's length as ``rng.uniform(0, length, 2)`` scales them), the same
certification of each new stretch (``segments_free``: every piece checked, all counted)
and so the same path and counts; ``tests/test_rigid_kernels.py`` and
``tests/test_policy_kernels.py`` compare them.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ._ball_kernels import _motion, _obstacles
from ._body_kernels import _check_motion, _integrate, _log, _scratch
from ._body_kernels import _norm as _length

_GRID_SLACK = 1e-9

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")


@_jit
def _geo_integrate(kind, q, v, s, out, vs):  # type: ignore[no-untyped-def]
    """``out = q exp(s v)``: a translation (``kind = 0``) or a pose (``kind = 1``)."""
    if kind == 0:
        for a in range(q.shape[0]):
            out[a] = q[a] + v[a] * s
    else:
        _integrate(q, v, s, out, vs)


@_jit
def _geo_log(kind, a, b, out):  # type: ignore[no-untyped-def]
    if kind == 0:
        for i in range(a.shape[0]):
            out[i] = b[i] - a[i]
    else:
        _log(a, b, out)


@_jit
def _segments_free(kind, verts, k, resolution, low, high, radius, body, boxes, prims, ws):  # type: ignore[no-untyped-def]
    """``segments_free`` of the ``k - 1`` geodesics ``verts[e] -> verts[e + 1]``:
    ``(all free, configurations checked)`` (every segment checked and counted)."""
    tdim = 6 if kind == 1 else verts.shape[1]
    v = np.empty(tdim)
    last = np.empty(verts.shape[1])
    ok, checks = True, 0
    for e in range(k - 1):
        _geo_log(kind, verts[e], verts[e + 1], v)
        m = max(1, math.ceil(_length(v) / resolution - _GRID_SLACK))
        if kind == 0:
            obs = _obstacles(boxes[0], boxes[1], boxes[2], prims)
            free, _, c = _motion(verts[e], v, m, radius, low, high, obs, np.True_, last)
        else:
            free, _, c = _check_motion(verts[e], v, m, np.True_, low, high, body, boxes, ws, last)
        checks += c
        ok = ok and free == m
    return ok, checks


@_jit
def _locate(cum, x, n_seg):  # type: ignore[no-untyped-def]
    """``min(searchsorted(cum, x, "right") - 1, n_seg - 1)``: the segment holding arc length ``x``."""
    i = np.searchsorted(cum[: n_seg + 1], x, side="right") - 1
    return min(i, n_seg - 1)


@_jit
def shortcut_path(kind, path0, tw0, u, resolution, low, high, radius, body, boxes, prims):  # type: ignore[no-untyped-def]
    """``BiRRT.shortcut`` on ``path0 (L, c)`` with its segments' twists ``tw0 (L - 1, t)``,
    ``len(u) // 2`` iterations: returns ``(path, checks)``. ``boxes``: the obstacles as
    the robot's motion check takes them; ``prims``: the ball's other primitives
    (``CollisionWorld.ball_prims``; ``()``: none, and always for the body)."""
    iters = u.shape[0] // 2
    c, t = path0.shape[1], tw0.shape[1]
    cap = path0.shape[0] + iters + 2
    path, tw = np.empty((cap, c)), np.empty((cap, t))
    n = path0.shape[0]
    path[:n], tw[: n - 1] = path0, tw0
    seg, cum = np.empty(cap), np.empty(cap + 1)
    verts, pair, vs = np.empty((4, c)), np.empty((2, c)), np.empty((1, 6))
    dv = np.empty(t)
    ws = _scratch(body[0].shape[0], boxes[0].shape[0])
    checks = 0
    for it in range(iters):
        if n < 3:
            break
        cum[0] = 0.0
        for e in range(n - 1):
            seg[e] = _length(tw[e])
            cum[e + 1] = cum[e] + seg[e]
        a, b = cum[n - 1] * u[2 * it], cum[n - 1] * u[2 * it + 1]
        lo, hi = min(a, b), max(a, b)
        i, j = _locate(cum, lo, n - 1), _locate(cum, hi, n - 1)
        if i == j:
            continue  # both on one segment: already a geodesic
        fa = (lo - cum[i]) / seg[i] if seg[i] > 0 else 0.0
        fb = (hi - cum[j]) / seg[j] if seg[j] > 0 else 1.0
        _geo_integrate(kind, path[i], tw[i], fa, pair[0], vs)
        _geo_integrate(kind, path[j], tw[j], fb, pair[1], vs)
        _geo_log(kind, pair[0], pair[1], dv)
        if _length(dv) >= hi - lo - 1e-12:
            continue
        k = 0
        verts[k] = path[i]
        k += 1
        if lo - cum[i] > 1e-9:
            verts[k] = pair[0]
            k += 1
        if cum[j + 1] - hi > 1e-9:
            verts[k] = pair[1]
            k += 1
        verts[k] = path[j + 1]
        k += 1
        ok, used = _segments_free(kind, verts, k, resolution, low, high, radius, body, boxes, prims, ws)
        checks += used
        if not ok:
            continue
        tail = n - (j + 2)
        new_n = i + k + tail
        path[i + k : new_n] = path[j + 2 : n].copy()
        tw[i + k - 1 : new_n - 1] = tw[j + 1 : n - 1].copy()
        path[i : i + k] = verts[:k]
        for e in range(k - 1):
            _geo_log(kind, verts[e], verts[e + 1], tw[i + e])
        n = new_n
    return path[:n].copy(), checks
