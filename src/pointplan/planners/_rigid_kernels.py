"""Compiled (numba) rollout of a free-flying body of boxes (the S-shape) among boxes, seeing
by ray casting (the ``local`` observation), with a PointNet actor: the whole rollout of
:meth:`RolloutEngine.plan <pointplan.planners.rollout.RolloutEngine.plan>` in one call,
escapes and sampled actions included. It computes what the step loop computes through the
batched core, one function per piece:

- the body among the boxes and its certified motions:
  :mod:`pointplan.robots._body_kernels` (``_body_hits``, ``_check_motion``);
- :func:`_move`, :func:`_edge_free`: ``q_free``'s move and the edge test of
  :func:`~pointplan.planners.edges.edge_free`, with the same counts of configurations
  checked;
- :func:`_observe`: :class:`~pointplan.observers.rays.LocalRays`' observation for one
  robot from its block of uniform draws (rays against the obstacle and wall boxes, the
  thinning grid, the random subset, the robot frame) as the network's input;
- the network: :func:`pointplan.planners._policy_kernels._network`.

``tests/test_rigid_kernels.py`` compares each piece with the numpy code it replaces and
whole rollouts with the step loop's.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..geometry._kernels import _ray_box_row
from ..robots._body_kernels import (
    _body_hits,
    _check_motion,
    _distance,
    _integrate,
    _log,
    _norm,
    _rotation,
    _scratch,
    motion_free,
)
from ..robots._cloud_kernels import _cloud_normal, _ray_cloud
from ._policy_kernels import (
    END_ESCAPE,
    END_GREEDY,
    END_HORIZON,
    END_STALLED,
    END_TOL,
    END_TOL_BLOCKED,
    END_TOL_GOAL,
    _network,
    _q_free,
    _segment_hits,
    _select,
    _workspace,
)
from ._policy_kernels import _edge_free as _ball_edge_free

#: as in pointplan.robots.motion and pointplan.planners.base (literals for the compiler)
_GRID_SLACK = 1e-9
_IN_BOUNDS_EPS = 1e-9
#: the rollout stopped within the goal tolerance exactly at the goal (nothing to connect)
END_AT_GOAL = 7
#: as ``rollout._MOVED``: a screened escape's draw that moves less is not looked ahead from
_MOVED = 1e-3

#: ``fparams`` of :func:`rollout_rigid`
(
    F_SUBSTEP,
    F_GOAL_TOL,
    F_STALL_DIST,
    F_RESOLUTION,
    F_S0,
    F_ESC_STILL,
    F_ESC_NOISE,
    F_NOISE,
    F_RANGE,
    F_SPACING,
    F_RADIUS,
    F_BACKOFF,
) = range(12)
#: ``iparams`` of :func:`rollout_rigid`
(
    I_HORIZON,
    I_STALL_STEPS,
    I_GREEDY,
    I_CONNECT,
    I_CLIP,
    I_N_POINTS,
    I_ACTION_DIM,
    I_ESC_WINDOW,
    I_ESC_STEPS,
    I_SAMPLED,
    I_ROBOT,
    I_HANDOVER,
    I_OBS,
    I_TRIES,
    I_LOOKAHEAD,
    I_AXES,
) = range(16)
#: ``I_ROBOT``: a translating ball, or a free-flying body of boxes
BALL, BODY = 0, 1
#: ``I_OBS``: what the robot sees: rays (``local``), or a subset of the scene's points (``global``)
RAYS, POINTS = 0, 1

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")


@_jit
def _move(q, tw, substep, clip_target, low, high, body, boxes, ws, new_q, scale):  # type: ignore[no-untyped-def]
    """``q_free`` for one robot: ``(collided, checks)``, the new configuration in ``new_q``."""
    poses, twists = ws[8], ws[9]
    if clip_target:
        target = poses[2]
        _integrate(q, tw, 1.0, target, ws[10])
        moved = False
        for a in range(3):
            c = min(max(target[a], low[a]), high[a])
            if c != target[a]:
                moved = True
                target[a] = c
        if moved:  # aim at the clipped target: slide along the border, never a longer step
            cap = 1.0
            for i in range(6):
                cap = max(cap, abs(tw[i]) / scale[i])
            _log(q, target, twists[0])
            tw = twists[0]
            size = 0.0
            for i in range(6):
                size = max(size, abs(tw[i]) / scale[i])
            if size > cap:
                f = cap / size
                for i in range(6):
                    tw[i] = tw[i] * f
    n = max(1, math.ceil(_norm(tw) / substep - _GRID_SLACK))
    k, collided, checks = _check_motion(q, tw, n, np.True_, low, high, body, boxes, ws, new_q)
    if k <= 0:
        for i in range(7):
            new_q[i] = q[i]
    return collided, checks


@_jit
def _edge_free(a, b, resolution, low, high, body, boxes, ws):  # type: ignore[no-untyped-def]
    """``edge_free(robot, world, a, b, resolution, low, high)``: ``(free, checks)``."""
    poses = ws[8]
    v = ws[9][2]
    _log(a, b, v)
    d = _norm(v)
    if d <= 1e-12:  # the configuration itself, plain and inside the bounds
        for p in range(3):
            if a[p] < low[p] - _IN_BOUNDS_EPS or a[p] > high[p] + _IN_BOUNDS_EPS:
                return False, 1
        return not _body_hits(a, body[1], body, boxes, ws), 1
    start = poses[3]
    _integrate(a, v, 0.0, start, ws[10])
    m = max(1, math.ceil(d / resolution - _GRID_SLACK))
    return motion_free(start, v, m, np.True_, low, high, body, boxes, ws)


# ------------------------------------------------------------------ the observation
@_jit
def _frame(kind, q, rot):  # type: ignore[no-untyped-def]
    """The robot's rotation: the identity for a ball, the pose's for a body."""
    if kind == BALL:
        for i in range(3):
            for j in range(3):
                rot[i, j] = 1.0 if i == j else 0.0
    else:
        _rotation(q, rot)


@_jit
def _cast(q, kind, rays, rboxes, low, high, max_range, hits, rot, scratch):  # type: ignore[no-untyped-def]
    """``LocalRays.cast`` for one robot: rays from the body (``rays``: body-frame origins
    and directions ``(R, 3)``) against the boxes ``rboxes`` (obstacles and wall slabs,
    with a validity flag each; with a cloud, also its grid, normals and indices:
    :func:`~pointplan.robots._cloud_kernels._ray_cloud`); writes ``hits (R, 7)``: point, normal, and 1.0 where the
    ray hit within range from an origin inside the bounds (else 0)."""
    bo, bd = rays
    box_c, box_r, box_h, valid = rboxes[0], rboxes[1], rboxes[2], rboxes[3]
    o, d, t0, t1, ax = scratch
    _frame(kind, q, rot)
    nr, nk = bo.shape[0], box_c.shape[0]
    for r in range(nr):
        for i in range(3):
            o[r, i] = rot[i, 0] * bo[r, 0] + rot[i, 1] * bo[r, 1] + rot[i, 2] * bo[r, 2] + q[i]
            d[r, i] = rot[i, 0] * bd[r, 0] + rot[i, 1] * bd[r, 1] + rot[i, 2] * bd[r, 2]
        dn = math.sqrt(d[r, 0] * d[r, 0] + d[r, 1] * d[r, 1] + d[r, 2] * d[r, 2])
        for i in range(3):
            d[r, i] = d[r, i] / dn
    for r in range(nr):
        _ray_box_row(o, d, r, box_c, box_r, box_h, t0, t1, ax)
        best, kb = np.inf, -1
        for k in range(nk):
            if valid[k] and t1[k] >= 0.0 and t0[k] <= t1[k]:
                tk = max(t0[k], 0.0)
                if tk < best:
                    best, kb = tk, k
        best, kc = _ray_cloud(rboxes, o[r], d[r], best, max_range)  # a nearer cloud point
        inside_bounds = True
        for i in range(3):
            if not (o[r, i] > low[i] and o[r, i] < high[i]):
                inside_bounds = False
        if (kb < 0 and kc < 0) or not best <= max_range or not inside_bounds:
            for i in range(7):
                hits[r, i] = 0.0
            continue
        n0, n1, n2 = -d[r, 0], -d[r, 1], -d[r, 2]
        if kc >= 0:  # the point's normal
            n0, n1, n2 = _cloud_normal(rboxes, kc)
        elif not t0[kb] < 0.0:  # entered through a face: its outward axis
            n0, n1, n2 = box_r[kb, 0, ax[kb]], box_r[kb, 1, ax[kb]], box_r[kb, 2, ax[kb]]
        nn = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        if nn > 0:
            n0, n1, n2 = n0 / nn, n1 / nn, n2 / nn
        else:
            n0, n1, n2 = -d[r, 0], -d[r, 1], -d[r, 2]
        if n0 * d[r, 0] + n1 * d[r, 1] + n2 * d[r, 2] > 0:
            n0, n1, n2 = -n0, -n1, -n2
        for i in range(3):
            hits[r, i] = o[r, i] + best * d[r, i]
        hits[r, 3], hits[r, 4], hits[r, 5], hits[r, 6] = n0, n1, n2, 1.0


@_jit
def _thin(hits, spacing, kept):  # type: ignore[no-untyped-def]
    """``thin_grid`` for one robot: the rays (in order) that are the first of their cell of
    ``spacing`` over (point, normal) among the hits; returns how many (in ``kept``)."""
    nr = hits.shape[0]
    keys = np.empty(nr, np.int64)
    which = np.empty(nr, np.int64)
    m = 0
    for r in range(nr):
        if hits[r, 6] == 0.0:
            continue
        key = np.int64(0)
        for i in range(6):
            c = np.int64(math.floor(hits[r, i] / spacing + 0.5)) + 128
            c = min(max(c, 0), 255)
            key |= c << np.int64(8 * i)
        keys[m] = key
        which[m] = r
        m += 1
    order = np.argsort(keys[:m], kind="mergesort")  # stable: the first ray of a cell leads
    first = np.zeros(nr, np.bool_)
    for i in range(m):
        if i == 0 or keys[order[i]] != keys[order[i - 1]]:
            first[which[order[i]]] = True
    count = 0
    for r in range(nr):
        if first[r]:
            kept[count] = r
            count += 1
    return count


@_jit
def _seen(obs, i, point, rot, q, s32):  # type: ignore[no-untyped-def]
    """Row ``i`` of the network's input: the world point and normal ``point[:6]`` in the
    robot's frame (``rot``, position ``q[:3]``), the position in steps (``/ s32``)."""
    for a in range(3):
        pb = rot[0, a] * (point[0] - q[0]) + rot[1, a] * (point[1] - q[1]) + rot[2, a] * (point[2] - q[2])
        nb = rot[0, a] * point[3] + rot[1, a] * point[4] + rot[2, a] * point[5]
        obs[i, a] = np.float32(pb) / s32
        obs[i, 3 + a] = np.float32(nb)


@_jit
def _observe(q, kind, u, rays, rboxes, low, high, max_range, spacing, s32, obs, ows):  # type: ignore[no-untyped-def]
    """The network's input for ``LocalRays.observe`` of one robot from the draws ``u`` (``R
    + n`` uniform numbers: the subset's keys, then the duplicates' draws): ``obs (n, 6)``
    float32, positions in steps (``/ s32``) and normals in the robot frame (all zero when
    nothing is seen). ``ows``: :func:`_obs_scratch`."""
    hits, kept, rot, scratch = ows
    _cast(q, kind, rays, rboxes, low, high, max_range, hits, rot, scratch)
    count = _thin(hits, spacing, kept)
    n, nr = obs.shape[0], hits.shape[0]
    if count == 0:
        for i in range(n):
            for j in range(6):
                obs[i, j] = 0.0
        return 0
    rank = np.argsort(u[:count])
    for i in range(n):
        pos = rank[i] if i < count else int(u[nr + i] * count)
        _seen(obs, i, hits[kept[pos]], rot, q, s32)
    return count


@_jit
def _observe_points(q, kind, u, pts, nrm, s32, obs, idx, rot):  # type: ignore[no-untyped-def]
    """The network's input for a point-set observation (``PointSetObserver.observe_one``)
    of one robot from the draws ``u`` (``max(P, 1) + n``): the drawn subset of the scene's
    points ``pts (P, 3)`` and normals, in the robot frame (``obs (n, 6)`` float32,
    positions in steps; all zero for a scene without points)."""
    count, n = pts.shape[0], obs.shape[0]
    if count == 0:
        for i in range(n):
            for j in range(6):
                obs[i, j] = 0.0
        return
    _select(u, count, n, idx)
    _frame(kind, q, rot)
    row = np.empty(6)
    for i in range(n):
        r = idx[i]
        for a in range(3):
            row[a], row[3 + a] = pts[r, a], nrm[r, a]
        _seen(obs, i, row, rot, q, s32)


@_jit
def _obs_scratch(n_rays, n_boxes):  # type: ignore[no-untyped-def]
    """Scratch of :func:`_observe`: hits, kept rays, rotation, and the casting's rays and
    per-box rows."""
    return (
        np.empty((n_rays, 7)),
        np.empty(n_rays, np.int64),
        np.empty((3, 3)),
        (
            np.empty((n_rays, 3)),
            np.empty((n_rays, 3)),
            np.empty(max(n_boxes, 1)),
            np.empty(max(n_boxes, 1)),
            np.empty(max(n_boxes, 1), np.int8),
        ),
    )


# ------------------------------------------------------------------ one step's action
@_jit
def _act(  # type: ignore[no-untyped-def]
    q, goal, u, noise, sampled, rays, rboxes, pts, nrm, low, high, fparams, iparams, scale, wflat, layout, ows, nws
):
    """The action (float32 ``(action_dim,)``, a view into ``nws``) at ``q`` toward ``goal``
    for the draws ``u``: the observation, the goal input ``log(q^-1 goal) / scale``
    (``(goal - q) / scale`` for a ball; with ``I_AXES``, followed by the body's rotation
    matrix row by row: the world's axes in the body frame, the S-shape told its
    orientation), the network."""
    kind = iparams[I_ROBOT]
    h = nws[0]
    vec = nws[4]
    width, features = layout[0], layout[1]
    obs = ows[4]
    s32 = np.float32(fparams[F_S0])
    if iparams[I_OBS] == POINTS:
        _observe_points(q, kind, u, pts, nrm, s32, obs, ows[5], ows[2])
    else:
        _observe(q, kind, u, rays, rboxes, low, high, fparams[F_RANGE], fparams[F_SPACING], s32, obs, ows[:4])
    np.dot(obs, wflat[: features * width].reshape(features, width), h)
    b0 = wflat[features * width : features * width + width]
    for p in range(h.shape[0]):
        for o in range(width):
            h[p, o] += b0[o]
    z = vec[width + features + width :]
    gdim = scale.shape[0]
    if kind == BALL:
        for i in range(gdim):
            z[i] = np.float32((goal[i] - q[i]) / scale[i])
    else:
        g = np.empty(6)
        _log(q, goal, g)
        for i in range(gdim):
            z[i] = np.float32(g[i] / scale[i])
        if iparams[I_AXES] != 0:
            rot = np.empty((3, 3))
            _rotation(q, rot)
            for i in range(3):
                for j in range(3):
                    z[gdim + 3 * i + j] = np.float32(rot[i, j])
            gdim += 9
    return _network(nws, wflat, layout, gdim, iparams[I_ACTION_DIM], noise, sampled)


@_jit
def _r_move(kind, q, tw, substep, clip_target, low, high, radius, body, boxes, ws, new_q, scale):  # type: ignore[no-untyped-def]
    """``q_free`` of one step of the ball or the body: ``(collided, checks)``."""
    if kind == BALL:
        return _q_free(q, tw, radius, low, high, (boxes[0], boxes[1], boxes[2]), substep, clip_target, new_q)
    return _move(q, tw, substep, clip_target, low, high, body, boxes, ws, new_q, scale)


@_jit
def _r_goal_free(kind, q, goal, resolution, low, high, radius, body, boxes, ws, quick):  # type: ignore[no-untyped-def]
    """The edge to the goal as ``GoalTester`` (``quick``: a ball's quick test first, its
    checks counted) or ``connect_to_goal`` checks it: ``(free, checks)``."""
    if kind == BODY:
        return _edge_free(q, goal, resolution, low, high, body, boxes, ws)
    checks = 0
    if quick:
        hit, c = _segment_hits(q, goal, radius * (1.0 - 1e-9), resolution, (boxes[0], boxes[1], boxes[2]))
        checks += c
        if hit:
            return False, checks
    ok, c = _ball_edge_free(q, goal, radius, resolution, low, high, (boxes[0], boxes[1], boxes[2]))
    return ok, checks + c


@_jit
def _r_distance(kind, a, b, tmp):  # type: ignore[no-untyped-def]
    if kind == BODY:
        return _distance(a, b, tmp)
    s = 0.0
    for i in range(a.shape[0]):
        s += (b[i] - a[i]) ** 2
    return math.sqrt(s)


@_jit
def _r_log(kind, a, b, out):  # type: ignore[no-untyped-def]
    """The twist from ``a`` to ``b`` into ``out`` (the body's ``log(a^-1 b)``; the ball's
    ``b - a``)."""
    if kind == BODY:
        _log(a, b, out)
        return
    for i in range(a.shape[0]):
        out[i] = b[i] - a[i]


@_jit
def _back_off(kind, path, t, backoff, scale, tmp, best):  # type: ignore[no-untyped-def]
    """The escape's back-off: ``best`` = the action from ``path[t]`` toward the latest of
    ``path[:t]`` more than ``backoff`` away, shortened into the action box (as
    ``rollout._back_off``); ``best`` untouched where none is that far."""
    q = path[t]
    for j in range(t - 1, -1, -1):
        if _r_distance(kind, path[j], q, tmp) > backoff:
            _r_log(kind, q, path[j], tmp)
            big = 1.0
            for i in range(best.shape[0]):
                big = max(big, abs(tmp[i] / scale[i]))
            for i in range(best.shape[0]):
                best[i] = np.float32(tmp[i] / scale[i] / big)
            return


@_jit
def _finish(kind, end, path, t, goal, greedy, connect, resolution, low, high, radius, body, boxes, ws):  # type: ignore[no-untyped-def]
    """The end of a rollout that stopped at ``path[t]`` with code ``end``: the goal test
    there (``greedy``), the edge to the goal from within the tolerance (``connect``), the
    goal appended where the path ends there. Returns ``(end, rows, checks)``."""
    checks = 0
    if greedy and end in (END_HORIZON, END_STALLED):  # the goal from where the rollout stopped
        ok, c = _r_goal_free(kind, path[t], goal, resolution, low, high, radius, body, boxes, ws, np.True_)
        checks += c
        if ok:
            end = END_GREEDY
    if end == END_TOL and connect:
        if _r_distance(kind, path[t], goal, ws[9][0]) <= 0.0:
            end = END_AT_GOAL
        else:
            ok, c = _r_goal_free(kind, path[t], goal, resolution, low, high, radius, body, boxes, ws, np.False_)
            checks += c
            end = END_TOL_GOAL if ok else END_TOL_BLOCKED
    rows = t + 1
    if end in (END_GREEDY, END_TOL_GOAL):
        for i in range(goal.shape[0]):
            path[rows, i] = goal[i]
        rows += 1
    return end, rows, checks


@_jit
def _furthest(  # type: ignore[no-untyped-def]
    q, goal, u, u0, noise, normals, drawn, sd, rays, rboxes, pts, nrm, low, high, boxes, body, fparams, iparams, scale,
    wflat, layout, ows, nws, ws, tw, cand, tmp, best,
):  # fmt: skip
    """The screened escape's step: ``I_TRIES`` actions drawn from ``normals`` (from row
    ``drawn``, scaled by ``sd``), each moved from ``q`` into ``cand`` as far as it is
    free, then (``I_LOOKAHEAD`` steps) followed by the mean action (:func:`_ahead`); the
    one that went furthest is left in ``best`` (the first of equals). Returns the motion
    checks of all the draws, the next row of ``normals`` and how far the best went."""
    kind, adim, radius = iparams[I_ROBOT], iparams[I_ACTION_DIM], fparams[F_RADIUS]
    far, checks = -1.0, 0
    drew = np.empty(adim, np.float32)
    for _ in range(iparams[I_TRIES]):
        for i in range(adim):
            noise[i] = np.float32(sd * normals[drawn, i])
        drawn += 1
        a = _act(
            q, goal, u, noise, np.True_, rays, rboxes, pts, nrm, low, high, fparams, iparams, scale, wflat, layout, ows, nws
        )  # fmt: skip
        for i in range(adim):
            drew[i] = a[i]  # (``a`` is the network's scratch, which the lookahead reuses)
            tw[i] = np.float64(min(max(a[i], np.float32(-1.0)), np.float32(1.0))) * scale[i]
        _, c = _r_move(
            kind, q, tw, fparams[F_SUBSTEP], iparams[I_CLIP] != 0, low, high, radius, body, boxes, ws, cand, scale
        )
        checks += c
        d = _r_distance(kind, cand, q, tmp)
        if iparams[I_LOOKAHEAD] > 0 and d >= _MOVED:
            d, c = _ahead(
                q, cand, goal, u0, noise, rays, rboxes, pts, nrm, low, high, boxes, body, fparams, iparams, scale,
                wflat, layout, ows, nws, ws, tw, tmp,
            )  # fmt: skip
            checks += c
        if d > far:
            far = d
            for i in range(adim):
                best[i] = drew[i]
    return checks, drawn, far


@_jit
def _ahead(  # type: ignore[no-untyped-def]
    q, q1, goal, u0, noise, rays, rboxes, pts, nrm, low, high, boxes, body, fparams, iparams, scale, wflat, layout,
    ows, nws, ws, tw, tmp,
):  # fmt: skip
    """The escape's lookahead from a draw's free end ``q1``: ``I_LOOKAHEAD`` steps of the
    mean action, observed from the draws ``u0`` (the stream's first block, as the step loop
    does), each moved as far as it is free. Returns how far from ``q`` it ended (infinite
    where it came within the goal tolerance) and its motion checks."""
    kind, adim, radius = iparams[I_ROBOT], iparams[I_ACTION_DIM], fparams[F_RADIUS]
    qk, qn = q1.copy(), np.empty_like(q1)
    checks = 0
    for _ in range(iparams[I_LOOKAHEAD]):
        a = _act(
            qk, goal, u0, noise, np.False_, rays, rboxes, pts, nrm, low, high, fparams, iparams, scale, wflat, layout, ows, nws
        )  # fmt: skip
        for i in range(adim):
            tw[i] = np.float64(min(max(a[i], np.float32(-1.0)), np.float32(1.0))) * scale[i]
        _, c = _r_move(
            kind, qk, tw, fparams[F_SUBSTEP], iparams[I_CLIP] != 0, low, high, radius, body, boxes, ws, qn, scale
        )
        checks += c
        for i in range(qk.shape[0]):
            qk[i] = qn[i]
        if _r_distance(kind, qk, goal, tmp) < fparams[F_GOAL_TOL]:
            return np.inf, checks
    return _r_distance(kind, qk, q, tmp), checks


@_jit
def rollout_rigid(  # type: ignore[no-untyped-def]
    q0,
    goal,
    low,
    high,
    boxes,
    rboxes,
    pts,
    nrm,
    body,
    rays,
    wflat,
    layout,
    scale,
    fparams,
    iparams,
    stream,
    normals,
    path,
):
    """One attempt of ``RolloutEngine.plan`` for the sphere seeing rays or the S-shape
    seeing rays or points (``I_ROBOT``, ``I_OBS``), as the one-robot step loop makes it: at each configuration
    (the start included), with ``I_GREEDY``, the certified edge to the goal (stop at the
    goal when free); the action for the step's draws (``stream``: ``R + n`` uniform
    numbers a step), sampled where the attempt is (``I_SAMPLED``, scaled by ``F_NOISE``)
    and during an escape (scaled by ``F_ESC_NOISE``), each sampled step taking the next
    row of ``normals``; ``q_free``'s move; stop within the goal tolerance, stalled or at
    the horizon; an escape of ``I_ESC_STEPS`` sampled steps after a step that ended less
    than ``F_ESC_STILL`` from where the robot was ``I_ESC_WINDOW`` steps before (with
    ``I_HANDOVER``, stop there instead: ``END_ESCAPE``, for the step loop to go on). Then
    the goal test where it stopped and, with ``I_CONNECT``, the edge to the goal from
    within the tolerance.

    ``boxes``: the obstacle boxes ``(centres, rotations, half sides)``; ``rboxes``: the
    boxes rays hit (obstacles and wall slabs) and a validity flag each; ``body``:
    ``(centres, half sides, corner map)`` of the S-shape's boxes (unused for the ball,
    whose radius is ``F_RADIUS``); ``rays``: body-frame ray origins and directions;
    ``pts``, ``nrm``: the scene's points and normals where the robot sees a subset of
    them (``I_OBS``: then ``max(P, 1) + n`` uniform numbers a step). Writes
    the path to ``path`` (``horizon + 2`` rows) and returns ``(end code, rows, checks,
    escapes)``."""
    kind, horizon, stall_steps = iparams[I_ROBOT], iparams[I_HORIZON], iparams[I_STALL_STEPS]
    greedy, connect, clip_target = iparams[I_GREEDY] != 0, iparams[I_CONNECT] != 0, iparams[I_CLIP] != 0
    esc_window, esc_steps, sampled = iparams[I_ESC_WINDOW], iparams[I_ESC_STEPS], iparams[I_SAMPLED] != 0
    substep, goal_tol, resolution = fparams[F_SUBSTEP], fparams[F_GOAL_TOL], fparams[F_RESOLUTION]
    n_points, adim, radius = iparams[I_N_POINTS], iparams[I_ACTION_DIM], fparams[F_RADIUS]
    nr = rays[0].shape[0]
    blk = (max(pts.shape[0], 1) if iparams[I_OBS] == POINTS else nr) + n_points
    ws = _scratch(body[0].shape[0], boxes[0].shape[0])
    o4 = _obs_scratch(nr, rboxes[0].shape[0])
    ows = (o4[0], o4[1], o4[2], o4[3], np.empty((n_points, 6), np.float32), np.empty(n_points, np.int64))
    nws = _workspace(n_points, layout, adim)
    noise = np.zeros(adim, np.float32)
    best = np.empty(adim, np.float32)  # the step's action
    tw = np.empty(adim)
    tmp = np.empty(6)
    for i in range(q0.shape[0]):
        path[0, i] = q0[i]
    checks, escapes, left, t, drawn = 0, 0, 0, np.int64(0), np.int64(0)  # (not literals: _ball_kernels says why)
    end = END_HORIZON
    while t < horizon:
        q = path[t]
        if greedy:
            ok, c = _r_goal_free(kind, q, goal, resolution, low, high, radius, body, boxes, ws, np.True_)
            checks += c
            if ok:
                end = END_GREEDY
                break
        escaping = left > 0
        noisy = escaping or sampled
        u = stream[t * blk : (t + 1) * blk]
        if escaping and iparams[I_TRIES] > 1:
            c, drawn, far = _furthest(
                q, goal, u, stream[:blk], noise, normals, drawn, fparams[F_ESC_NOISE], rays, rboxes, pts, nrm, low, high,
                boxes, body, fparams, iparams, scale, wflat, layout, ows, nws, ws, tw, path[t + 1], tmp, best,
            )  # fmt: skip
            checks += c
            if fparams[F_BACKOFF] > 0 and far < _MOVED:  # not one draw moves: back off along the path
                _back_off(kind, path, t, fparams[F_BACKOFF], scale, tmp, best)
        else:
            if noisy:
                sd = fparams[F_ESC_NOISE] if escaping else fparams[F_NOISE]
                for i in range(adim):
                    noise[i] = np.float32(sd * normals[drawn, i])
                drawn += 1
            res = _act(
                q, goal, u, noise, noisy, rays, rboxes, pts, nrm, low, high, fparams, iparams, scale, wflat, layout, ows, nws
            )  # fmt: skip
            for i in range(adim):
                best[i] = res[i]
        a = best
        if escaping:
            left -= 1
        for i in range(adim):
            tw[i] = np.float64(min(max(a[i], np.float32(-1.0)), np.float32(1.0))) * scale[i]
        collided, c = _r_move(kind, q, tw, substep, clip_target, low, high, radius, body, boxes, ws, path[t + 1], scale)
        checks += c
        t += 1
        new_q = path[t]
        if not collided and _r_distance(kind, new_q, goal, tmp) < goal_tol:
            end = END_TOL
            break
        back = t - stall_steps
        if stall_steps > 0 and back >= 0 and _r_distance(kind, new_q, path[back], tmp) < fparams[F_STALL_DIST]:
            end = END_STALLED
            break
        still = esc_steps > 0 and t >= esc_window and left == 0
        if still and _r_distance(kind, new_q, path[t - esc_window], tmp) < fparams[F_ESC_STILL]:
            if iparams[I_HANDOVER] != 0:  # the step loop goes on from here
                return END_ESCAPE, t + 1, checks, escapes
            left = esc_steps
            escapes += 1
    end, rows, c = _finish(kind, end, path, t, goal, greedy, connect, resolution, low, high, radius, body, boxes, ws)
    checks += c
    return end, rows, checks, escapes


__all__ = ["END_AT_GOAL", "rollout_rigid"]
