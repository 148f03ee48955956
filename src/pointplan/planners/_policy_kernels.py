"""Compiled (numba) kernels of the batch-1 policy planner (:mod:`pointplan.planners.policy`)
for a translating ball (the 2D disc, the 3D sphere) among boxes.

- :func:`ball_segment_hits_boxes_count`: a quick *necessary* test for the certified edge
  check: does the plain ball (no growth, a hair smaller) overlap a box at some sample of
  the segment? Then the segment is certainly not free (a certified edge has no
  configuration touching an obstacle), and the certified check may be skipped.
- :func:`ball_motion`: the certified motion check of
  :func:`pointplan.robots.motion.check_motions` for one motion of a ball among boxes
  (grown samples, the start fallback, the bounds), written out on floats: the same
  arithmetic in the same order, so the same verdict and the same counts.
- :func:`pointnet_action`: the deterministic action of a PointNet actor from the folded
  first layer (the drawn points' input-layer rows minus one row for the position, see
  ``PolicyPlanner._lean_step``)
  and the observation's draws: the same as
  :meth:`pointplan.models.policy.NumpyPointNetActor.from_first_layer` up to float32
  round-off (the ELU's exponential is a polynomial here, relative error about 1e-7).
- :func:`rollout_ball`: a whole rollout of ``PolicyPlanner.plan`` (greedy goal test, action,
  ``q_free``'s move, the end tests) in one call.

``tests/test_policy_kernels.py`` compares each with the numpy/PyTorch code it replaces.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np

from ..robots._ball_kernels import _ball_hits, _motion, _obstacles

#: as in pointplan.robots.motion (repeated as a literal for the compiler)
_GRID_SLACK = 1e-9
#: as in pointplan.models.actor_critic
_LOG_STD_MIN, _LOG_STD_MAX = -20.0, 2.0

#: rollout ends (``rollout_ball``'s code); ``END_ESCAPE``: the robot is stuck by the
#: escape's test (``I_ESC_WINDOW`` > 0), and the rollout is handed back to Python there
END_HORIZON, END_STALLED, END_GREEDY, END_TOL_GOAL, END_TOL_BLOCKED, END_TOL, END_ESCAPE = 0, 1, 2, 3, 4, 5, 6

_jit = numba.njit(cache=True, nogil=True)
_jit_fast = numba.njit(cache=True, nogil=True, fastmath=True)


# ------------------------------------------------------------------ collision tests
@_jit
def _segment_hits(a, b, radius, spacing, obs):  # type: ignore[no-untyped-def]
    d = a.shape[0]
    length2 = 0.0
    for i in range(d):
        length2 += (b[i] - a[i]) ** 2
    n = int(np.ceil(np.sqrt(length2) / spacing))
    if n < 1:
        n = 1
    r2 = radius * radius
    p = np.empty(d)
    for j in range(n + 1):
        s = j / n
        for i in range(d):
            p[i] = a[i] + s * (b[i] - a[i])
        if _ball_hits(p, radius, r2, obs, np.True_):  # an overlap, not a touch
            return True, j + 1
    return False, n + 1


def ball_segment_hits_boxes_count(
    a: np.ndarray,
    b: np.ndarray,
    radius: float,
    spacing: float,
    box_c: np.ndarray,
    box_r: np.ndarray,
    box_h: np.ndarray,
    prims: tuple[np.ndarray, ...] = (),
) -> tuple[bool, int]:
    """Does a ball of ``radius`` centred at one of the points ``a + (j / n) (b - a)``,
    ``n = ceil(|b - a| / spacing)``, overlap (distance below ``radius``) one of the boxes
    ``box_c: (K, d)``, ``box_r: (K, d, d)`` (columns are the box axes), ``box_h: (K, d)``
    (half sides), or one of the other primitives ``prims``
    (``CollisionWorld.ball_prims``)? Returns the answer and the number of sample points
    tested (up to the first hit)."""
    obs = (box_c, box_r, box_h, prims) if prims else (box_c, box_r, box_h)
    hit, n = _segment_hits(a, b, float(radius), float(spacing), obs)
    return bool(hit), int(n)


def ball_motion(
    q0: np.ndarray,
    twist: np.ndarray,
    n: int,
    radius: float,
    low: np.ndarray,
    high: np.ndarray,
    box_c: np.ndarray,
    box_r: np.ndarray,
    box_h: np.ndarray,
    fallback: bool = True,
) -> tuple[int, bool, int, np.ndarray]:
    """``check_motions`` of one motion of a ball among boxes: ``(free, collided, checks,
    last free configuration)``."""
    end = np.empty_like(q0)
    free, hit, checks = _motion(q0, twist, int(n), float(radius), low, high, (box_c, box_r, box_h), bool(fallback), end)
    return int(free), bool(hit), int(checks), end


@_jit
def _intervals(length, resolution):  # type: ignore[no-untyped-def]
    k = int(np.ceil(length / resolution - _GRID_SLACK))
    return k if k > 1 else 1


@_jit
def _norm(v):  # type: ignore[no-untyped-def]
    s = 0.0
    for i in range(v.shape[0]):
        s += v[i] * v[i]
    return np.sqrt(s)


@_jit
def _q_free(q, tw, radius, low, high, obs, substep, clip_target, new_q):  # type: ignore[no-untyped-def]
    """``pointplan.envs.core.q_free`` for one move: writes the end to ``new_q``, returns
    ``(collided, checks)``."""
    d = q.shape[0]
    v = tw.copy()
    if clip_target:
        moved = False
        for i in range(d):
            target = q[i] + tw[i]
            c = min(max(target, low[i]), high[i])
            if c != target:
                moved = True
        if moved:
            for i in range(d):
                target = q[i] + tw[i]
                v[i] = min(max(target, low[i]), high[i]) - q[i]
    n = _intervals(_norm(v), substep)
    free, hit, checks = _motion(q, v, n, radius, low, high, obs, np.True_, new_q)
    return hit, checks


@_jit
def _edge_free(a, b, radius, resolution, low, high, obs):  # type: ignore[no-untyped-def]
    """``pointplan.planners.edges.edge_free`` for a ball among the obstacles ``obs`` (boxes,
    or boxes and the other primitives): ``(free, checks)``."""
    d = a.shape[0]
    v = np.empty(d)
    for i in range(d):
        v[i] = b[i] - a[i]
    length = _norm(v)
    end = np.empty(d)
    if length <= 1e-12:  # check_free of the configuration itself (plain ball, bounds)
        if _ball_hits(a, radius, radius * radius, obs, np.False_):
            return False, 1
        for i in range(d):
            if not (a[i] >= low[i] - 1e-9 and a[i] <= high[i] + 1e-9):  # in_bounds' eps
                return False, 1
        return True, 1
    m = _intervals(length, resolution)
    free, hit, checks = _motion(a, v, m, radius, low, high, obs, np.True_, end)
    return free == m, checks


def ball_edge_free(
    a: np.ndarray,
    b: np.ndarray,
    radius: float,
    resolution: float,
    low: np.ndarray,
    high: np.ndarray,
    box_c: np.ndarray,
    box_r: np.ndarray,
    box_h: np.ndarray,
) -> tuple[bool, int]:
    """``edge_free`` of a ball among boxes (see :func:`_edge_free`)."""
    ok, n = _edge_free(a, b, float(radius), float(resolution), low, high, (box_c, box_r, box_h))
    return bool(ok), int(n)


# ------------------------------------------------------------------ the network
#: the ELU's scratch length: it works through its vector in blocks of this many (the scratch
#: stays in the L1 cache; a whole ``(n_points, width)`` scratch would be 32 KB more memory
#: to bring in per call)
_ELU_BLOCK = 256


@_jit_fast
def _elu(flat, tmp, ki):  # type: ignore[no-untyped-def]
    """ELU in place of a float32 vector (``tmp``, ``ki``: float32, int32 scratch of
    ``_ELU_BLOCK``): ``v`` for ``v > 0``, else ``exp(v) - 1`` with ``exp`` as ``2^k p(r)``
    (Cephes' expf polynomial; relative error about 1e-7), in loops the compiler
    vectorises."""
    size = flat.shape[0]
    scale = ki.view(np.float32)
    for c0 in range(0, size, _ELU_BLOCK):
        c1 = min(size, c0 + _ELU_BLOCK)
        for i in range(c0, c1):
            v = min(flat[i], np.float32(0.0))
            v = max(v, np.float32(-87.0))
            k = np.floor(v * np.float32(1.4426950408889634) + np.float32(0.5))
            r = v - k * np.float32(0.693359375) - k * np.float32(-2.12194440e-4)
            p = np.float32(1.9875691500e-4)
            p = p * r + np.float32(1.3981999507e-3)
            p = p * r + np.float32(8.3334519073e-3)
            p = p * r + np.float32(4.1665795894e-2)
            p = p * r + np.float32(1.6666665459e-1)
            p = p * r + np.float32(5.0000001201e-1)
            tmp[i - c0] = p * r * r + r + np.float32(1.0)
            ki[i - c0] = (np.int32(k) + np.int32(127)) << np.int32(23)
        for i in range(c0, c1):
            e = tmp[i - c0] * scale[i - c0] - np.float32(1.0)
            flat[i] = flat[i] if flat[i] > np.float32(0.0) else e


@_jit_fast
def _elu_bias(x, b, tmp, ki):  # type: ignore[no-untyped-def]
    """ELU of ``x + b`` in place (``x: (N, W)`` float32, C-contiguous, ``b: (W,)``)."""
    n, width = x.shape
    for p in range(n):
        for o in range(width):
            x[p, o] += b[o]
    _elu(x.reshape(-1), tmp, ki)


@_jit
def _select(u, count, n_points, idx):  # type: ignore[no-untyped-def]
    """The drawn points: ``argsort(u[:m])[:n]`` as a set (the network max-pools, so the
    order does not matter), padded with ``(u[m + count : m + n] * count)`` when the scene
    has fewer points than ``n``. The set is the points whose key is at most the ``n``-th
    smallest (the keys are uniform doubles: no ties)."""
    m = count if count > 1 else 1
    k = min(n_points, m)
    if k == m:
        for i in range(m):
            idx[i] = i
    else:
        keys = u[:m]
        thr = np.partition(keys, k - 1)[k - 1]
        j = 0
        for i in range(m):
            if keys[i] <= thr and j < k:
                idx[j] = i
                j += 1
    if count < n_points:
        for i in range(count, n_points):
            idx[i] = int(u[m + i] * count)


def pack_weights(
    inp: tuple[np.ndarray, np.ndarray],
    hidden: list[tuple[np.ndarray, np.ndarray]],
    head: list[tuple[np.ndarray, np.ndarray]],
) -> tuple[np.ndarray, np.ndarray]:
    """A PointNet actor's weights (``NumpyPointNetActor``'s ``inp``, ``hidden``, ``head``;
    ``W`` as ``(in, out)``) as one float32 array and its layout: ``[width, features,
    n_hidden, n_head, then per head layer its input and output widths]``, the arrays in
    the order input W, b, hidden Ws, hidden bs, head (W, b) pairs. Hidden layers are
    ``width x width``; the residual ones (all but the last) are stored as ``W + I``
    (``h W + h = h (W + I)``, one product)."""
    w0, b0 = inp
    features, width = w0.shape
    eye = np.eye(width, dtype=np.float32)
    hid = [w + eye if i < len(hidden) - 1 else w for i, (w, _) in enumerate(hidden)]
    parts = [w0.ravel(), b0.ravel()] + [w.ravel() for w in hid] + [b.ravel() for _, b in hidden]
    layout = [width, features, len(hidden), len(head)]
    for w, b in head:
        parts += [w.ravel(), b.ravel()]
        layout += [w.shape[0], w.shape[1]]
    return np.ascontiguousarray(np.concatenate(parts), np.float32), np.asarray(layout, np.int64)


@_jit
def _workspace(n_points, layout, d):  # type: ignore[no-untyped-def]
    """The scratch arrays of :func:`_action`, allocated once per rollout (not per step):
    ``(h, y)``: ``(n_points, width)`` float32 activations; ``(tmp, ki)``: the ELU's
    float32 and int32 scratch; ``vec``: float32 room for the small vectors (the position
    row and the point's features, then the head's input row and two ping-pong rows)."""
    width, features = layout[0], layout[1]
    head = width + d
    for li in range(layout[3]):  # each head layer's input and output rows
        head = max(head, layout[4 + 2 * li], layout[5 + 2 * li])
    h = np.empty((n_points, width), np.float32)
    y = np.empty((n_points, width), np.float32)
    tmp, ki = np.empty(_ELU_BLOCK, np.float32), np.empty(_ELU_BLOCK, np.int32)
    vec = np.empty(width + features + 3 * head, np.float32)
    return h, y, tmp, ki, vec


@_jit_fast
def _first_layer(q, idx, pts, nrm, s32, wflat, layout, h, vec):  # type: ignore[no-untyped-def]
    """The input layer's pre-activations of the drawn points ``idx`` seen from ``q``,
    folded (see ``PolicyPlanner._lean_step``): ``[f32(pts / s), f32(nrm)] @ W + b`` of
    each drawn point minus the row ``f32(q / s) @ W[:d]``, with the products summed in the
    same order as the per-scene table of ``PolicyPlanner._fold`` (into ``h``; ``vec``:
    scratch of ``width + features``). Computed for the drawn points only: a rollout of a
    few steps sees fewer points than a scene has, and no table has to be written."""
    width, features = layout[0], layout[1]
    d = q.shape[0]
    e = nrm.shape[1]
    row = vec[:width]
    x = vec[width : width + features]
    for o in range(width):
        row[o] = 0.0
    for i in range(d):
        qi = np.float32(q[i] / s32)
        for o in range(width):
            row[o] += qi * wflat[i * width + o]
    for p in range(h.shape[0]):
        src = idx[p]
        for i in range(d):
            x[i] = np.float32(pts[src, i] / s32)
        for j in range(e):
            x[d + j] = np.float32(nrm[src, j])
        for o in range(width):
            h[p, o] = wflat[features * width + o]
        for i in range(features):
            xi = x[i]
            for o in range(width):
                h[p, o] += xi * wflat[i * width + o]
        for o in range(width):
            h[p, o] -= row[o]


@_jit_fast
def _dense_row(z, w, b, out):  # type: ignore[no-untyped-def]
    """``out = z @ w + b`` for one row ``z: (k,)``, ``w: (k, m)``, into ``out`` (no
    allocation). The product goes through BLAS as a ``1 x k`` matrix, as ``np.dot`` of
    the row did before: a loop here sums in another order and moves the actions by about
    1e-6."""
    m = out.shape[0]
    np.dot(z.reshape(1, z.shape[0]), w, out.reshape(1, m))
    for o in range(m):
        out[o] += b[o]


@_jit_fast
def _network(ws, wflat, layout, gdim, action_dim, noise, sampled):  # type: ignore[no-untyped-def]
    """The actor's action (float32, a view into ``ws``) from the input layer's
    pre-activations in ``h`` (the first array of ``ws``, bias included; overwritten) and
    the goal input in the head's input row (``vec[2 width + features:][: gdim]``, written
    by the caller): ELU, the hidden layers (residual, the last max-pooled), the head on
    ``[pooled, goal input]``, then ``tanh(mean)``, or with ``sampled`` ``tanh(mean +
    exp(clip(log_std)) * noise)`` (``noise``: float32, one per action component).
    ``ws``: :func:`_workspace` (nothing is allocated here)."""
    h, y, tmp, ki, vec = ws
    n = h.shape[0]
    width, features, n_hidden, n_head = layout[0], layout[1], layout[2], layout[3]
    _elu(h.reshape(-1), tmp, ki)  # (the first layer's bias is in h already)
    off_w = features * width + width
    off_b = off_w + n_hidden * width * width
    rows = vec[width + features :]  # the head's input and output rows
    head = rows.shape[0] // 3
    pooled = rows[:width]
    if n_hidden == 0:
        for o in range(width):
            pooled[o] = h[0, o]
        for p in range(1, n):
            for o in range(width):
                pooled[o] = max(pooled[o], h[p, o])
    for li in range(n_hidden):
        w = wflat[off_w + li * width * width : off_w + (li + 1) * width * width].reshape(width, width)
        b = wflat[off_b + li * width : off_b + (li + 1) * width]
        np.dot(h, w, y)
        if li < n_hidden - 1:  # residual: w is W + I, so y = h W + h
            _elu_bias(y, b, tmp, ki)
            h, y = y, h
        else:  # the last one max-pooled: max(y + b) = max(y) + b
            for o in range(width):
                pooled[o] = y[0, o]
            for p in range(1, n):
                for o in range(width):
                    pooled[o] = max(pooled[o], y[p, o])
            for o in range(width):
                pooled[o] += b[o]
    off = off_b + n_hidden * width
    src, dst = 0, head
    for li in range(n_head):
        k_in, k_out = layout[4 + 2 * li], layout[5 + 2 * li]
        w = wflat[off : off + k_in * k_out].reshape(k_in, k_out)
        off += k_in * k_out
        b = wflat[off : off + k_out]
        off += k_out
        out = rows[dst : dst + k_out]
        _dense_row(rows[src : src + k_in], w, b, out)
        if li < n_head - 1:
            _elu(out, tmp, ki)
        src, dst = dst, (head if dst != head else 2 * head)
    a = rows[src : src + action_dim]
    if sampled:
        for i in range(action_dim):
            log_std = min(max(rows[src + action_dim + i], np.float32(_LOG_STD_MIN)), np.float32(_LOG_STD_MAX))
            a[i] = np.tanh(a[i] + np.exp(log_std) * noise[i])
    else:
        for i in range(action_dim):
            a[i] = np.tanh(a[i])
    return a


@_jit_fast
def _action(q, goal, idx, pts, nrm, s32, wflat, layout, scale, action_dim, ws):  # type: ignore[no-untyped-def]
    """The actor's mean action (float32, a view into ``ws``) for the drawn points ``idx``
    of a translating ball: the folded first layer (:func:`_first_layer`), the goal input
    ``(goal - q) / scale``, then :func:`_network`."""
    h, y, tmp, ki, vec = ws
    d = q.shape[0]
    width, features = layout[0], layout[1]
    _first_layer(q, idx, pts, nrm, s32, wflat, layout, h, vec)
    z = vec[width + features + width :]
    for i in range(d):
        z[i] = np.float32((goal[i] - q[i]) / scale[i])
    return _network(ws, wflat, layout, d, action_dim, vec[:0], np.False_)


def pointnet_action(
    q: np.ndarray,
    goal: np.ndarray,
    u: np.ndarray,
    n_points: int,
    pts: np.ndarray,
    nrm: np.ndarray,
    s32: float,
    wflat: np.ndarray,
    layout: np.ndarray,
    scale: np.ndarray,
    action_dim: int,
) -> np.ndarray:
    """One action of the folded PointNet actor (:func:`_select`, :func:`_action`) for the
    scene's points ``pts`` (world frame), normals ``nrm`` (``(count, 0)`` without) and the
    draws ``u``."""
    idx = np.empty(n_points, np.int64)
    _select(u, len(pts), n_points, idx)
    ws = _workspace(n_points, layout, len(q))
    return _action(q, goal, idx, pts, nrm, float(s32), wflat, layout, scale, int(action_dim), ws).copy()


# ------------------------------------------------------------------ a whole rollout
@_jit_fast
def _clip_twist(a, scale, tw):  # type: ignore[no-untyped-def]
    for i in range(tw.shape[0]):
        ai = min(max(a[i], np.float32(-1.0)), np.float32(1.0))
        tw[i] = np.float64(ai) * scale[i]


#: ``fparams`` of :func:`_rollout`
F_RADIUS, F_SUBSTEP, F_GOAL_TOL, F_STALL_DIST, F_RESOLUTION, F_S32, F_ESC_STILL = range(7)
#: ``iparams`` of :func:`_rollout`
I_HORIZON, I_STALL_STEPS, I_GREEDY, I_CONNECT, I_CLIP, I_N_POINTS, I_ACTION_DIM, I_ESC_WINDOW = range(8)


@_jit
def _rollout(  # type: ignore[no-untyped-def]
    q0, goal, low, high, box_c, box_r, box_h, prims, pts, nrm, wflat, layout, scale, fparams, iparams, stream, path
):
    """A rollout of ``PolicyPlanner.plan`` (see :func:`rollout_ball`): writes the path to
    ``path`` (``horizon + 2`` rows: the policy's configurations, then the goal when the
    path ends there) and returns ``(end code, rows of path, checks, certified goal
    edges)`` (plain integers: nothing to unpack from an array afterwards)."""
    radius, substep, goal_tol = fparams[F_RADIUS], fparams[F_SUBSTEP], fparams[F_GOAL_TOL]
    stall_dist, resolution, s32 = fparams[F_STALL_DIST], fparams[F_RESOLUTION], fparams[F_S32]
    horizon, stall_steps = iparams[I_HORIZON], iparams[I_STALL_STEPS]
    n_points, action_dim = iparams[I_N_POINTS], iparams[I_ACTION_DIM]
    esc_window, esc_still = iparams[I_ESC_WINDOW], fparams[F_ESC_STILL]
    greedy, connect, clip_target = iparams[I_GREEDY] != 0, iparams[I_CONNECT] != 0, iparams[I_CLIP] != 0
    d = q0.shape[0]
    count = pts.shape[0]
    m = count if count > 1 else 1
    blk = m + n_points
    idx = np.empty(n_points, np.int64)
    ws = _workspace(n_points, layout, d)
    tw = np.empty(d)
    new_q = np.empty(d)
    filt_r = radius * (1.0 - 1e-9)
    obs = _obstacles(box_c, box_r, box_h, prims)
    for i in range(d):
        path[0, i] = q0[i]
    checks = 0
    certified = 0
    t = 0
    end = END_HORIZON
    while True:
        q = path[t]
        if greedy:  # is the straight edge to the goal free from here?
            hit, c = _segment_hits(q, goal, filt_r, resolution, obs)
            checks += c
            if not hit:
                ok, c = _edge_free(q, goal, radius, resolution, low, high, obs)
                checks += c
                certified += 1
                if ok:
                    end = END_GREEDY
                    break
        if t >= horizon or end == END_STALLED:
            break
        _select(stream[t * blk : (t + 1) * blk], count, n_points, idx)
        a = _action(q, goal, idx, pts, nrm, s32, wflat, layout, scale, action_dim, ws)
        _clip_twist(a, scale, tw)
        hit, c = _q_free(q, tw, radius, low, high, obs, substep, clip_target, new_q)
        checks += c
        t += 1
        for i in range(d):
            path[t, i] = new_q[i]
        dist = 0.0
        for i in range(d):
            dist += (new_q[i] - goal[i]) ** 2
        if np.sqrt(dist) < goal_tol and not hit:
            end = END_TOL
            if connect:
                ok, c = _edge_free(new_q, goal, radius, resolution, low, high, obs)
                checks += c
                end = END_TOL_GOAL if ok else END_TOL_BLOCKED
            break
        if stall_steps > 0 and t >= stall_steps:
            back = 0.0
            for i in range(d):
                back += (new_q[i] - path[t - stall_steps, i]) ** 2
            if np.sqrt(back) < stall_dist:
                end = END_STALLED  # the goal is still tried from here (greedy)
                if not greedy:
                    break
        if end != END_STALLED and esc_window > 0 and t >= esc_window:  # stuck: an escape starts here
            back = 0.0
            for i in range(d):
                back += (new_q[i] - path[t - esc_window, i]) ** 2
            if np.sqrt(back) < esc_still:
                end = END_ESCAPE
                break
    rows = t + 1
    if end in (END_GREEDY, END_TOL_GOAL):  # the path ends at the goal
        for i in range(d):
            path[rows, i] = goal[i]
        rows += 1
    return end, rows, checks, certified


def rollout_ball(
    q0: np.ndarray,
    goal: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    boxes: tuple[Any, ...],
    pts: np.ndarray,
    nrm: np.ndarray,
    weights: tuple[np.ndarray, np.ndarray],
    scale: np.ndarray,
    fparams: np.ndarray,
    iparams: np.ndarray,
    stream: np.ndarray,
) -> tuple[int, np.ndarray, int, int]:
    """A rollout of ``PolicyPlanner.plan`` for a ball among boxes, one call: at each
    configuration (the start included), with ``greedy``, the straight edge to the goal
    (the quick test, then the certified check of ``edge_free``; stop at the goal when it
    is free); the action of the network for the step's draws from ``stream``; the move as
    ``q_free`` makes it; stop within the goal tolerance (then, with ``connect``, the edge
    to the goal, as ``connect_to_goal``), at the horizon or stalled, or (``I_ESC_WINDOW``
    > 0) where the robot ended a step less than ``F_ESC_STILL`` from where it was
    ``I_ESC_WINDOW`` steps before (``END_ESCAPE``: the path so far, for the caller to go
    on from, as the escape of ``PolicyPlanner`` starts there).

    ``boxes``: ``(centres, rotations, half sides)``, or those and the other primitives
    (``CollisionWorld.ball_prims``); ``pts``, ``nrm``: the observer's
    points of the scene and their normals (``(count, 0)`` without); ``weights``: :func:`pack_weights`;
    ``fparams``, ``iparams``: the ``F_*``, ``I_*`` entries. Returns ``(end code, the path
    (the policy's configurations, start first, then the goal when it ends there),
    collision checks, certified goal-edge checks made)``. (``PolicyPlanner`` calls
    :func:`_rollout` directly, with its arguments prepared once.)"""
    path = np.empty((int(iparams[I_HORIZON]) + 2, len(q0)))
    obs = boxes if len(boxes) == 4 else (*boxes, ())
    end, rows, checks, certified = _rollout(  # type: ignore[call-arg]
        q0, goal, low, high, *obs, pts, nrm, *weights, scale, fparams, iparams, stream, path
    )
    return int(end), path[:rows], int(checks), int(certified)
