"""Compiled (numba) kernels of a free-flying body made of boxes (the S-shape) among
obstacle boxes: the body's boxes at a pose, grown for a motion as
:meth:`Robot.grown_parts <pointplan.robots.base.Robot.grown_parts>` grows them
(:func:`_grow`), against the obstacles by the separating-axis test of
:func:`pointplan.geometry._kernels._obb_row` (:func:`_body_hits`), and the certified motion
check of :func:`pointplan.robots.motion.check_motions` (grown samples, the start fallback,
the bounds) for one motion (:func:`_check_motion`, which stops at the first sample that
decides it: the answer and the count of configurations are those of the numpy check, which
computes every sample) or a batch (:func:`check_motions_boxes`). The obstacles are boxes
``(centres, rotations, half sides)``, or those and a point cloud's grid (``(..., grid)``,
:mod:`._cloud_kernels`; :func:`check_motions_cloud`): the same kernels test both.
``SShape.check_motions`` (and ``collides``, ``march_compiled``, ``shortcut_compiled``)
takes them in scenes of boxes and in one scene of boxes and a cloud;
``tests/test_rigid_kernels.py`` and ``tests/test_cloud_kernels.py`` compare them with the
numpy check (``NumpySShape``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..geometry._kernels import _obb_row
from ..geometry._se3_kernels import _pose_integrate_flat, _pose_log_flat
from ._cloud_kernels import _cloud_hits

#: as in pointplan.robots.motion (literals for the compiler)
_CONTACT_MARGIN = 1e-5
_BOUNDS_EPS = 1e-12

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")


# ------------------------------------------------------------------ poses
@_jit
def _rotation(q, rot):  # type: ignore[no-untyped-def]
    """``lie.quat_to_matrix`` of the pose ``q (7,)`` into ``rot (3, 3)``."""
    x, y, z, w = q[3], q[4], q[5], q[6]
    n = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    rot[0, 0], rot[0, 1], rot[0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)
    rot[1, 0], rot[1, 1], rot[1, 2] = 2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)
    rot[2, 0], rot[2, 1], rot[2, 2] = 2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)


@_jit
def _integrate(q, v, s, out, vs):  # type: ignore[no-untyped-def]
    """``out = q * exp(s v)`` for one pose and one twist (``vs``: scratch ``(1, 6)``)."""
    for i in range(6):
        vs[0, i] = v[i] * s
    _pose_integrate_flat(q.reshape(1, 7), vs, out.reshape(1, 7))


@_jit
def _log(q0, q1, out):  # type: ignore[no-untyped-def]
    """``out = log(q0^-1 q1)`` (body twist ``(6,)``)."""
    _pose_log_flat(q0.reshape(1, 7), q1.reshape(1, 7), out.reshape(1, 6))


@_jit
def _norm(v):  # type: ignore[no-untyped-def]
    s = 0.0
    for i in range(v.shape[0]):
        s += v[i] * v[i]
    return math.sqrt(s)


@_jit
def _distance(q0, q1, tw):  # type: ignore[no-untyped-def]
    """The geodesic distance ``|log(q0^-1 q1)|`` (``tw``: scratch ``(6,)``)."""
    _log(q0, q1, tw)
    return _norm(tw)


# ------------------------------------------------------------------ the body among boxes
@_jit
def _grow(seg, reach, halfs0, cv, out):  # type: ignore[no-untyped-def]
    """Half sides of the body's boxes grown for the sub-step twist ``seg`` (``Robot.grown_parts``)
    plus the contact margin, into ``out (P, 3)``; ``cv (6, P * 8 * 3)``: the twist's
    map to the corners' velocities in each box's axes (``Robot._corner_velocity``)."""
    wn = math.sqrt(seg[3] * seg[3] + seg[4] * seg[4] + seg[5] * seg[5])
    c2 = (0.5 * reach * reach) * wn
    for p in range(halfs0.shape[0]):
        g0 = g1 = g2 = -np.inf
        for k in range(8):
            base = (p * 8 + k) * 3
            l0 = l1 = l2 = 0.0
            for i in range(6):
                l0 += seg[i] * cv[i, base]
                l1 += seg[i] * cv[i, base + 1]
                l2 += seg[i] * cv[i, base + 2]
            extra = c2 * math.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
            g0 = max(g0, reach * abs(l0) + extra)
            g1 = max(g1, reach * abs(l1) + extra)
            g2 = max(g2, reach * abs(l2) + extra)
        out[p, 0] = halfs0[p, 0] + g0 + _CONTACT_MARGIN
        out[p, 1] = halfs0[p, 1] + g1 + _CONTACT_MARGIN
        out[p, 2] = halfs0[p, 2] + g2 + _CONTACT_MARGIN


@_jit
def _body_hits(q, halfs, body, boxes, ws):  # type: ignore[no-untyped-def]
    """Does the body at ``q`` with box half sides ``halfs (P, 3)`` overlap an obstacle?
    ``body``: ``(centres (P, 3), half sides, corner map)``, the boxes axis-aligned in the
    body frame; ``boxes``: the obstacle boxes ``(centres, rotations, half sides)``, or
    those and a point cloud's grid (:mod:`._cloud_kernels`: a point, a sphere of the
    cloud's point radius, touching a body box is a hit, as in
    ``CollisionWorld.boxes_collide``); ``ws``: :func:`_scratch`."""
    c0 = body[0]
    box_c, box_r, box_h = boxes[0], boxes[1], boxes[2]
    rot, bc, br, row, rel, absr, t = ws[0], ws[1], ws[2], ws[3], ws[4], ws[5], ws[6]
    if box_c.shape[0] == 0 and len(boxes) == 3:
        return False
    _rotation(q, rot)
    for p in range(c0.shape[0]):
        for a in range(3):
            bc[p, a] = rot[a, 0] * c0[p, 0] + rot[a, 1] * c0[p, 1] + rot[a, 2] * c0[p, 2] + q[a]
            for b in range(3):
                br[p, a, b] = rot[a, b]
    if box_c.shape[0]:
        for p in range(c0.shape[0]):
            if _obb_row(bc, br, halfs, p, box_c, box_r, box_h, row, True, rel, absr, t):
                return True
    return _cloud_hits(boxes, bc, br, halfs)


@_jit
def bodies_hit(q, halfs, body, boxes, out):  # type: ignore[no-untyped-def]
    """:func:`_body_hits` of the poses ``q (M, 7)`` with box half sides ``halfs (M, P, 3)``
    into ``out (M,)`` (``Robot.collides``)."""
    ws = _scratch(body[0].shape[0], boxes[0].shape[0])
    for i in range(q.shape[0]):
        out[i] = _body_hits(q[i], halfs[i], body, boxes, ws)


@_jit
def _scratch(n_parts, n_boxes):  # type: ignore[no-untyped-def]
    """The scratch arrays of :func:`_body_hits` and the motion checks, allocated once per
    rollout: rotation, box centres and rotations, a row of overlaps, the separating-axis
    scratch, three sets of grown half sides, four poses, three twists and the scratch of
    :func:`_integrate`."""
    return (
        np.empty((3, 3)),
        np.empty((n_parts, 3)),
        np.empty((n_parts, 3, 3)),
        np.empty(max(n_boxes, 1), np.bool_),
        np.empty((3, 3)),
        np.empty((3, 3)),
        np.empty(3),
        np.empty((3, n_parts, 3)),
        np.empty((4, 7)),
        np.empty((3, 6)),
        np.empty((1, 6)),
    )


@_jit
def _out_of_bounds(q, low, high):  # type: ignore[no-untyped-def]
    for a in range(3):
        mid = (high[a] + low[a]) / 2
        half = (high[a] - low[a]) / 2 + _BOUNDS_EPS
        if abs(q[a] - mid) > half:
            return True
    return False


@_jit
def _check_motion(q0, tw, n, fallback, low, high, body, boxes, ws, last):  # type: ignore[no-untyped-def]
    """``check_motions`` for one motion ``q0 exp(s tw)`` in ``n`` sub-steps: returns ``(k,
    collided, checks)`` (certified free on ``[0, k / n]``) and leaves the configuration
    at ``k / n`` in ``last`` (when ``k >= 0``)."""
    grown, poses, vs = ws[7], ws[8], ws[10]
    bad, checks = _start(q0, tw, n, fallback, body, boxes, ws)
    qj = poses[0]
    for j in range(n + 1):
        if j > 0:
            _integrate(q0, tw, min(j / n, 1.0), qj, vs)
            bad = _body_hits(qj, grown[0], body, boxes, ws)
        if bad or _out_of_bounds(qj, low, high):
            return j - 1, bad, checks
        for i in range(7):
            last[i] = qj[i]
    return n, False, checks


@_jit
def _start(q0, tw, n, fallback, body, boxes, ws):  # type: ignore[no-untyped-def]
    """The start of a motion in ``n`` sub-steps: the sizes grown for its sub-steps (into
    ``ws[7][0]``), the start pose (into ``ws[8][0]``) and whether its grown check fails,
    after, with ``fallback``, the plain start and sample 1 grown over the whole first
    sub-step (``check_motions``' start fallback): ``(bad, checks)``, the checks of the
    whole motion (``n + 1``, and 2 more where the fallback ran)."""
    halfs0, cv = body[1], body[2]
    grown, poses, twists, vs = ws[7], ws[8], ws[9], ws[10]
    seg = twists[1]
    for i in range(6):
        seg[i] = tw[i] / n
    _grow(seg, 0.5, halfs0, cv, grown[0])
    checks = n + 1
    q0s = poses[0]
    _integrate(q0, tw, 0.0, q0s, vs)
    bad = _body_hits(q0s, grown[0], body, boxes, ws)
    if bad and fallback:  # the start too close for its grown check
        checks += 2
        _grow(seg, 0.0, halfs0, cv, grown[1])
        _grow(seg, 1.0, halfs0, cv, grown[2])
        q1 = poses[1]
        _integrate(q0, tw, min(1 / n, 1.0), q1, vs)
        bad = _body_hits(q0s, grown[1], body, boxes, ws) or _body_hits(q1, grown[2], body, boxes, ws)
    return bad, checks


@_jit
def motion_free(q0, tw, n, fallback, low, high, body, boxes, ws):  # type: ignore[no-untyped-def]
    """Is the whole motion certified free (:func:`_check_motion`'s ``k == n``)? Returns
    ``(free, checks)`` with the same count. Only the answer matters here, not where the
    motion stops, so the samples are checked coarse to fine (the start first, for its
    fallback; then ``n / 2``-spaced ones, then the midpoints between them, and so on): a
    blocked motion is usually found after a few samples wherever its obstacle lies."""
    grown, poses, vs = ws[7], ws[8], ws[10]
    bad, checks = _start(q0, tw, n, fallback, body, boxes, ws)
    qj = poses[0]
    if bad or _out_of_bounds(qj, low, high):
        return False, checks
    top = 1
    while top * 2 <= n:
        top *= 2
    stride, step = top, top  # first j = top; then the odd multiples of each smaller stride
    while stride >= 1:
        for j in range(stride, n + 1, step):
            _integrate(q0, tw, min(j / n, 1.0), qj, vs)
            if _out_of_bounds(qj, low, high) or _body_hits(qj, grown[0], body, boxes, ws):
                return False, checks
        stride //= 2
        step = 2 * stride
    return True, checks


@_jit
def check_motions_boxes(q0, tw, n, fallback, low, high, body, box_c, box_r, box_h, stacked, configs, out):  # type: ignore[no-untyped-def]
    """:func:`_check_motion` for motions ``q0 (N, 7)``, ``tw (N, 6)`` in ``n (N,)`` sub-steps,
    ``fallback (N,)``, bounds ``low, high (N, 3)``, against the boxes of one scene (``(1,
    K, ...)``) or of scene ``i`` for motion ``i`` (``stacked``). Writes every sample
    ``configs (N, J, 7)`` (past a motion's own ``n`` its end, as the numpy check lays
    them out) and ``out (N, 3)``: certified sub-steps, collided (0 or 1), checks."""
    ws = _scratch(body[0].shape[0], box_c.shape[1])
    last = np.empty(7)
    for i in range(configs.shape[0]):
        s = i if stacked else 0
        _check_one(i, q0, tw, n, fallback, low, high, body, (box_c[s], box_r[s], box_h[s]), ws, last, configs, out)


@_jit
def check_motions_cloud(q0, tw, n, fallback, low, high, body, obstacles, configs, out):  # type: ignore[no-untyped-def]
    """:func:`check_motions_boxes` in one scene whose obstacles are boxes and a point
    cloud: ``obstacles`` = ``(centres, rotations, half sides, grid)`` (:func:`_body_hits`)."""
    ws = _scratch(body[0].shape[0], obstacles[0].shape[0])
    last = np.empty(7)
    for i in range(configs.shape[0]):
        _check_one(i, q0, tw, n, fallback, low, high, body, obstacles, ws, last, configs, out)


@_jit
def _check_one(i, q0, tw, n, fallback, low, high, body, boxes, ws, last, configs, out):  # type: ignore[no-untyped-def]
    """Motion ``i`` of :func:`check_motions_boxes`: its row of ``out`` and its samples."""
    k, hit, c = _check_motion(q0[i], tw[i], n[i], fallback[i], low[i], high[i], body, boxes, ws, last)
    out[i, 0], out[i, 1], out[i, 2] = k, hit, c
    for j in range(configs.shape[1]):
        _integrate(q0[i], tw[i], min(j / n[i], 1.0), configs[i, j], ws[10])


_GRID_SLACK = 1e-9


@_jit
def march_boxes(q0, q1, v, step, resolution, max_steps, low, high, body, boxes):  # type: ignore[no-untyped-def]
    """``pointplan.planners.base.march`` of the geodesic ``q0 -> q1`` (twist ``v``) in
    edges of length ``step`` (the last one shorter), each certified by
    :func:`_check_motion` in ``intervals(length, resolution)`` sub-steps, up to
    ``max_steps`` edges (``-1``: all), edge by edge until the first blocked one (the numpy
    march checks them all at once and counts the same; an edge is kept whole or not at
    all, so each is checked by :func:`motion_free`). Returns ``(nodes, reached,
    checks)``: the ends of the free edges ``(n_free, 7)`` (the last one ``q1`` itself when
    reached)."""
    d = _norm(v)
    if d <= 1e-12:
        return np.empty((0, 7)), True, 0
    total = max(1, math.ceil(d / step - _GRID_SLACK))
    n = total if max_steps < 0 else min(total, max_steps)
    if n <= 0:
        return np.empty((0, 7)), False, 0
    ends = np.empty(n + 1)
    for e in range(n + 1):
        ends[e] = min(e * (step / d), 1.0)
    if n == total:
        ends[n] = 1.0
    ws = _scratch(body[0].shape[0], boxes[0].shape[0])
    starts = np.empty((n + 1, 7))
    for e in range(n + 1):
        _integrate(q0, v, ends[e], starts[e], ws[10])
    edge = np.empty(6)
    checks, n_free = 0, n
    for e in range(n):
        frac = ends[e + 1] - ends[e]
        m = max(1, math.ceil(frac * d / resolution - _GRID_SLACK))
        for i in range(6):
            edge[i] = v[i] * frac
        ok, c = motion_free(starts[e], edge, m, e == 0, low, high, body, boxes, ws)
        checks += c
        if not ok:
            n_free = e
            break
    nodes = starts[1 : n_free + 1].copy()
    reached = n == total and n_free == n
    if reached:
        for i in range(7):
            nodes[n_free - 1, i] = q1[i]
    return nodes, reached, checks


@_jit
def nearest_pose(nodes, q):  # type: ignore[no-untyped-def]
    """The row of ``nodes (n, 7)`` nearest to the pose ``q`` by ``|log(node^-1 q)|`` (the
    first of equals) and the twist from it to ``q``."""
    best, at = np.inf, -1
    tw = np.empty(6)
    out = np.empty(6)
    for i in range(nodes.shape[0]):
        _log(nodes[i], q, tw)
        s = 0.0
        for j in range(6):
            s += tw[j] * tw[j]
        if s < best:
            best, at = s, i
            for j in range(6):
                out[j] = tw[j]
    return at, out
