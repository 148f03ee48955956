"""Compiled (numba) kernels of a translating ball (the disc, the sphere) among obstacle
primitives: the ball against boxes (:func:`_hits_boxes`) and against spheres, capsules,
cylinders and cones (:func:`_hits_prims`), each as ``collision.py`` computes it; the
certified motion check of :func:`pointplan.robots.motion.check_motions` for one motion
(:func:`_motion`: the grown samples, the start fallback, the bounds, stopping at the first
sample that decides it, with the numpy check's answer and count) or a batch
(:func:`check_motions_balls`), and ``march`` (:func:`march_balls`). The balls'
``check_motions`` and ``march_compiled`` take them in scenes of such primitives (no
meshes or point clouds); the policy planner's kernels (``planners/_policy_kernels.py``)
build on them, among boxes.

The obstacles travel as a tuple ``obs``: the boxes ``(centres, rotations, half sides)``,
or those and the other primitives ``(..., prims)`` with ``prims`` as
:meth:`pointplan.geometry.collision.CollisionWorld.ball_prims` packs them; the version of
:func:`_ball_hits` is chosen by the tuple's type when the caller is compiled (so a scene
of boxes runs the same code as before the other primitives were added). numba's cache
of the callers in other modules does not see edits here: delete their cache files
(``__pycache__/_shortcut_kernels.*``, ``planners/__pycache__/_policy_kernels.*``,
``planners/__pycache__/_rigid_kernels.*``) after changing this module.

Compiled callers pass constant flags as ``np.True_`` / ``np.False_``: numba types a
literal ``True`` as ``Literal[bool](True)`` and compiles the callee once more for it (and
once more for ``False``, and for an omitted default), where ``np.True_`` is a plain
``bool``. The same goes for integer constants (``np.int64(0)``, not ``0``) and for
read-only arrays (a type of their own).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import types
from numba.extending import overload

#: as in pointplan.robots.motion (literals for the compiler)
_CONTACT_MARGIN = 1e-5
_BOUNDS_EPS = 1e-12
_GRID_SLACK = 1e-9

_jit = numba.njit(cache=True, nogil=True)


@_jit
def _within(d2, r2, strict):  # type: ignore[no-untyped-def]
    return d2 < r2 if strict else d2 <= r2


@_jit
def _hits_boxes(p, r2, box_c, box_r, box_h, strict):  # type: ignore[no-untyped-def]
    """``any(sphere_box_sqdist(p, boxes) <= r2)``, written as collision.py computes it
    (``strict``: ``< r2``, an overlap, not a touch)."""
    d = p.shape[0]
    for k in range(box_c.shape[0]):
        out = 0.0
        for i in range(d):
            local = (p[0] - box_c[k, 0]) * box_r[k, 0, i]
            for j in range(1, d):
                local = local + (p[j] - box_c[k, j]) * box_r[k, j, i]
            ex = abs(local) - box_h[k, i]
            if ex < 0.0:
                ex = 0.0
            out += ex * ex
        if _within(out, r2, strict):
            return True
    return False


@_jit
def _dot(a, b, n):  # type: ignore[no-untyped-def]
    s = a[0] * b[0]
    for i in range(1, n):
        s += a[i] * b[i]
    return s


@_jit
def _segment2_sqdist(px, pz, ax, az, bx, bz):  # type: ignore[no-untyped-def]
    """collision._segment2_sqdist on floats."""
    ux, uz = bx - ax, bz - az
    t = ((px - ax) * ux + (pz - az) * uz) / max(ux * ux + uz * uz, 1e-18)
    t = min(max(t, 0.0), 1.0)
    dx, dz = px - ax - t * ux, pz - az - t * uz
    return dx * dx + dz * dz


@_jit
def _hits_prims(p, r, r2, prims, strict):  # type: ignore[no-untyped-def]
    """Does the ball at ``p`` of radius ``r`` (``r2 = r * r``) touch one of the spheres,
    capsules, cylinders or cones of ``prims`` (``CollisionWorld.ball_prims``)? The
    distances of ``CollisionWorld.spheres_collide``, computed in the same order; with
    ``strict``, only a distance below ``r`` counts (an overlap, not a touch)."""
    sph_c, sph_r, cap_a, cap_b, cap_r, cyl_c, cyl_r, cyl_rad, cyl_half, con_c, con_r, con_rad, con_half = prims
    d = p.shape[0]
    diff = np.empty(d)
    ab = np.empty(d)
    for k in range(sph_c.shape[0]):
        for i in range(d):
            diff[i] = p[i] - sph_c[k, i]
        rr = r + sph_r[k]
        if _within(_dot(diff, diff, d), rr * rr, strict):
            return True
    for k in range(cap_a.shape[0]):
        for i in range(d):
            ab[i] = cap_b[k, i] - cap_a[k, i]
            diff[i] = p[i] - cap_a[k, i]
        denom = max(_dot(ab, ab, d), 1e-18)
        t = min(max(_dot(diff, ab, d) / denom, 0.0), 1.0)
        for i in range(d):
            diff[i] = diff[i] - t * ab[i]
        rr = r + cap_r[k]
        if _within(_dot(diff, diff, d), rr * rr, strict):
            return True
    if d == 3:
        for k in range(cyl_c.shape[0] + con_c.shape[0]):
            cone = k >= cyl_c.shape[0]
            j = k - cyl_c.shape[0] if cone else k
            c, rot = (con_c, con_r) if cone else (cyl_c, cyl_r)
            l0 = (p[0] - c[j, 0]) * rot[j, 0, 0] + (p[1] - c[j, 1]) * rot[j, 1, 0] + (p[2] - c[j, 2]) * rot[j, 2, 0]
            l1 = (p[0] - c[j, 0]) * rot[j, 0, 1] + (p[1] - c[j, 1]) * rot[j, 1, 1] + (p[2] - c[j, 2]) * rot[j, 2, 1]
            z = (p[0] - c[j, 0]) * rot[j, 0, 2] + (p[1] - c[j, 1]) * rot[j, 1, 2] + (p[2] - c[j, 2]) * rot[j, 2, 2]
            rho = math.sqrt(l0 * l0 + l1 * l1)
            if not cone:
                dr = max(rho - cyl_rad[j], 0.0)
                dz = max(abs(z) - cyl_half[j], 0.0)
                if _within(dr * dr + dz * dz, r2, strict):
                    return True
                continue
            rad, h = con_rad[j], con_half[j]
            if z >= -h and z <= h and rho * 2.0 * h <= rad * (h - z) and _within(0.0, r2, strict):
                return True
            d_base = _segment2_sqdist(rho, z, 0.0, -h, rad, -h)
            d_side = _segment2_sqdist(rho, z, rad, -h, 0.0, h)
            if _within(min(d_base, d_side), r2, strict):
                return True
    return False


def _ball_hits(p, r, r2, obs, strict):  # type: ignore[no-untyped-def]
    """Does the ball at ``p`` of radius ``r`` (``r2 = r * r``) touch (``strict``: overlap)
    an obstacle of ``obs`` (boxes, or boxes and ``prims``)? Compiled callers only (the
    version is chosen by the tuple's type)."""
    raise NotImplementedError("_ball_hits is called from compiled code only")


@overload(_ball_hits, jit_options={"nogil": True})
def _ball_hits_impl(p, r, r2, obs, strict):  # type: ignore[no-untyped-def]
    if isinstance(obs, types.BaseTuple) and len(obs) == 4 and isinstance(obs[3], types.BaseTuple):

        def boxes_and_prims(p, r, r2, obs, strict):  # type: ignore[no-untyped-def]
            return _hits_boxes(p, r2, obs[0], obs[1], obs[2], strict) or _hits_prims(p, r, r2, obs[3], strict)

        return boxes_and_prims

    def boxes(p, r, r2, obs, strict):  # type: ignore[no-untyped-def]
        return _hits_boxes(p, r2, obs[0], obs[1], obs[2], strict)

    return boxes


def _obstacles(box_c, box_r, box_h, prims):  # type: ignore[no-untyped-def]
    """``obs`` of boxes and ``prims``: the boxes alone where ``prims`` is ``()``.
    Compiled callers only."""
    raise NotImplementedError("_obstacles is called from compiled code only")


@overload(_obstacles, jit_options={"nogil": True})
def _obstacles_impl(box_c, box_r, box_h, prims):  # type: ignore[no-untyped-def]
    if isinstance(prims, types.BaseTuple) and len(prims) == 0:

        def boxes(box_c, box_r, box_h, prims):  # type: ignore[no-untyped-def]
            return (box_c, box_r, box_h)

        return boxes

    def with_prims(box_c, box_r, box_h, prims):  # type: ignore[no-untyped-def]
        return (box_c, box_r, box_h, prims)

    return with_prims


@_jit
def _motion(q0, tw, n, radius, low, high, obs, fallback, end):  # type: ignore[no-untyped-def]
    """check_motions for one motion ``q0 + s tw`` in ``n`` sub-steps among the obstacles
    ``obs``: returns ``(free, collided, checks)`` and writes the last free sample (``q0``
    when ``free <= 0``) to ``end``."""
    d = q0.shape[0]
    seg2 = 0.0
    for i in range(d):
        si = tw[i] / n
        seg2 += si * si
    rg = np.sqrt(radius * radius + (0.5 * 0.5) * seg2) + _CONTACT_MARGIN
    r2g = rg * rg
    checks = n + 1
    cfg = np.empty(d)
    for i in range(d):
        end[i] = q0[i]
    for j in range(n + 1):
        s = min(j / n, 1.0)
        for i in range(d):
            cfg[i] = q0[i] + tw[i] * s
        bad = _ball_hits(cfg, rg, r2g, obs, np.False_)
        if j == 0 and bad and fallback:
            r0 = np.sqrt(radius * radius + (0.0 * 0.0) * seg2) + _CONTACT_MARGIN
            r1 = np.sqrt(radius * radius + (1.0 * 1.0) * seg2) + _CONTACT_MARGIN
            cfg1 = np.empty(d)
            s1 = min(1 / n, 1.0)
            for i in range(d):
                cfg1[i] = q0[i] + tw[i] * s1
            if not _ball_hits(cfg, r0, r0 * r0, obs, np.False_) and not _ball_hits(cfg1, r1, r1 * r1, obs, np.False_):
                bad = False
            checks += 2
        out = False
        for i in range(d):
            mid = (high[i] + low[i]) / 2
            half = (high[i] - low[i]) / 2 + _BOUNDS_EPS
            if abs(cfg[i] - mid) > half:
                out = True
        if bad or out:
            return j - 1, bad, checks
        for i in range(d):
            end[i] = cfg[i]
    return n, False, checks


@_jit
def check_motions_balls(q0, tw, n, fallback, low, high, radius, box_c, box_r, box_h, prims, stacked, configs, out):  # type: ignore[no-untyped-def]
    """:func:`_motion` for motions ``q0 (N, d)``, ``tw (N, d)`` in ``n (N,)`` sub-steps,
    ``fallback (N,)``, bounds ``low, high (N, d)``, against the boxes of one scene (``(1,
    K, ...)``) and its other primitives ``prims`` (``()``: none), or the boxes of scene
    ``i`` for motion ``i`` (``stacked``, ``prims = ()``): writes every sample
    ``configs (N, J, d)`` (past a motion's ``n`` its end) and ``out (N, 3)``: certified
    sub-steps, collided (0 or 1), checks."""
    nm, nj, d = configs.shape
    end = np.empty(d)
    for i in range(nm):
        s = i if stacked else 0
        obs = _obstacles(box_c[s], box_r[s], box_h[s], prims)
        k, hit, c = _motion(q0[i], tw[i], n[i], radius, low[i], high[i], obs, fallback[i], end)
        out[i, 0], out[i, 1], out[i, 2] = k, hit, c
        for j in range(nj):
            f = min(j / n[i], 1.0)
            for a in range(d):
                configs[i, j, a] = q0[i, a] + tw[i, a] * f


@_jit
def march_balls(q0, q1, v, step, resolution, max_steps, low, high, radius, box_c, box_r, box_h, prims):  # type: ignore[no-untyped-def]
    """``pointplan.planners.base.march`` of the segment ``q0 -> q1`` (``v = q1 - q0``) for a
    ball among boxes and the other primitives ``prims`` (``()``: none), edge by edge until the first blocked one: ``(nodes, reached,
    checks)`` as the numpy march gives them."""
    dim = q0.shape[0]
    d = 0.0
    for i in range(dim):
        d += v[i] * v[i]
    d = math.sqrt(d)
    if d <= 1e-12:
        return np.empty((0, dim)), True, 0
    total = max(1, math.ceil(d / step - _GRID_SLACK))
    n = total if max_steps < 0 else min(total, max_steps)
    if n <= 0:
        return np.empty((0, dim)), False, 0
    ends = np.empty(n + 1)
    for e in range(n + 1):
        ends[e] = min(e * (step / d), 1.0)
    if n == total:
        ends[n] = 1.0
    starts = np.empty((n + 1, dim))
    for e in range(n + 1):
        for i in range(dim):
            starts[e, i] = q0[i] + v[i] * ends[e]
    edge = np.empty(dim)
    end = np.empty(dim)
    obs = _obstacles(box_c, box_r, box_h, prims)
    checks, n_free = 0, n
    for e in range(n):
        frac = ends[e + 1] - ends[e]
        m = max(1, math.ceil(frac * d / resolution - _GRID_SLACK))
        for i in range(dim):
            edge[i] = v[i] * frac
        k, _, c = _motion(starts[e], edge, m, radius, low, high, obs, e == 0, end)
        checks += c
        if k < m:
            n_free = e
            break
    nodes = starts[1 : n_free + 1].copy()
    reached = n == total and n_free == n
    if reached:
        for i in range(dim):
            nodes[n_free - 1, i] = q1[i]
    return nodes, reached, checks
