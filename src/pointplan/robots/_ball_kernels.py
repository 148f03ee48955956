"""Compiled (numba) kernels of a translating ball (the disc, the sphere) among obstacle
boxes: the ball against the boxes (:func:`_hits_boxes`, as ``collision.py`` computes it),
the certified motion check of :func:`pointplan.robots.motion.check_motions` for one motion
(:func:`_motion`: the grown samples, the start fallback, the bounds, stopping at the first
sample that decides it, with the numpy check's answer and count) or a batch
(:func:`check_motions_balls`), and ``march`` (:func:`march_balls`). The balls'
``check_motions`` and ``march_compiled`` take them in scenes of boxes; the policy
planner's kernels (``planners/_policy_kernels.py``) build on them.
"""

from __future__ import annotations

import math

import numba
import numpy as np

#: as in pointplan.robots.motion (literals for the compiler)
_CONTACT_MARGIN = 1e-5
_BOUNDS_EPS = 1e-12
_GRID_SLACK = 1e-9

_jit = numba.njit(cache=True, nogil=True)


@_jit
def _hits_boxes(p, r2, box_c, box_r, box_h):  # type: ignore[no-untyped-def]
    """``any(sphere_box_sqdist(p, boxes) <= r2)``, written as collision.py computes it."""
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
        if out <= r2:
            return True
    return False


@_jit
def _motion(q0, tw, n, radius, low, high, box_c, box_r, box_h, fallback, end):  # type: ignore[no-untyped-def]
    """check_motions for one motion ``q0 + s tw`` in ``n`` sub-steps: returns ``(free,
    collided, checks)`` and writes the last free sample (``q0`` when ``free <= 0``) to
    ``end``."""
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
        bad = _hits_boxes(cfg, r2g, box_c, box_r, box_h)
        if j == 0 and bad and fallback:
            r0 = np.sqrt(radius * radius + (0.0 * 0.0) * seg2) + _CONTACT_MARGIN
            r1 = np.sqrt(radius * radius + (1.0 * 1.0) * seg2) + _CONTACT_MARGIN
            cfg1 = np.empty(d)
            s1 = min(1 / n, 1.0)
            for i in range(d):
                cfg1[i] = q0[i] + tw[i] * s1
            if not _hits_boxes(cfg, r0 * r0, box_c, box_r, box_h) and not _hits_boxes(
                cfg1, r1 * r1, box_c, box_r, box_h
            ):
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
def check_motions_balls(q0, tw, n, fallback, low, high, radius, box_c, box_r, box_h, stacked, configs, out):  # type: ignore[no-untyped-def]
    """:func:`_motion` for motions ``q0 (N, d)``, ``tw (N, d)`` in ``n (N,)`` sub-steps,
    ``fallback (N,)``, bounds ``low, high (N, d)``, against the boxes of one scene (``(1,
    K, ...)``) or of scene ``i`` for motion ``i`` (``stacked``): writes every sample
    ``configs (N, J, d)`` (past a motion's ``n`` its end) and ``out (N, 3)``: certified
    sub-steps, collided (0 or 1), checks."""
    nm, nj, d = configs.shape
    end = np.empty(d)
    for i in range(nm):
        s = i if stacked else 0
        k, hit, c = _motion(q0[i], tw[i], n[i], radius, low[i], high[i], box_c[s], box_r[s], box_h[s], fallback[i], end)
        out[i, 0], out[i, 1], out[i, 2] = k, hit, c
        for j in range(nj):
            f = min(j / n[i], 1.0)
            for a in range(d):
                configs[i, j, a] = q0[i, a] + tw[i, a] * f


@_jit
def march_balls(q0, q1, v, step, resolution, max_steps, low, high, radius, box_c, box_r, box_h):  # type: ignore[no-untyped-def]
    """``pointplan.planners.base.march`` of the segment ``q0 -> q1`` (``v = q1 - q0``) for a
    ball among boxes, edge by edge until the first blocked one: ``(nodes, reached,
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
    checks, n_free = 0, n
    for e in range(n):
        frac = ends[e + 1] - ends[e]
        m = max(1, math.ceil(frac * d / resolution - _GRID_SLACK))
        for i in range(dim):
            edge[i] = v[i] * frac
        k, _, c = _motion(starts[e], edge, m, radius, low, high, box_c, box_r, box_h, e == 0, end)
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
