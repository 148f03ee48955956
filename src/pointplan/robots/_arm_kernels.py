"""Compiled (numba) collision test of an arm's spheres: forward kinematics, the spheres
against boxes, spheres, cylinders and a point cloud (through its grid), and the
self-collision pairs, one configuration at a time with an early exit.
:meth:`pointplan.robots.arm.ArmRobot.collides` uses it for scenes made of those; the numpy
path (:class:`~pointplan.geometry.collision.CollisionWorld`) computes the same and is what
the tests compare it with."""

from __future__ import annotations

import numba
import numpy as np

from ..geometry._kernels import grid_nearest_bound, grid_point_within


def _frames(q, parent, rot0, pos0, axis, prismatic, base_rot, base_pos, rot, pos):  # type: ignore[no-untyped-def]
    """Joint frames of one configuration into ``rot (n, 3, 3)``, ``pos (n, 3)``."""
    n = q.shape[0]
    r0 = np.empty((3, 3))
    for j in range(n):
        a = parent[j]
        rp = base_rot if a < 0 else rot[a]
        pp = base_pos if a < 0 else pos[a]
        for i in range(3):
            for k in range(3):
                r0[i, k] = rp[i, 0] * rot0[j, 0, k] + rp[i, 1] * rot0[j, 1, k] + rp[i, 2] * rot0[j, 2, k]
            pos[j, i] = pp[i] + rp[i, 0] * pos0[j, 0] + rp[i, 1] * pos0[j, 1] + rp[i, 2] * pos0[j, 2]
        ax, ay, az = axis[j, 0], axis[j, 1], axis[j, 2]
        if prismatic[j]:
            for i in range(3):
                for k in range(3):
                    rot[j, i, k] = r0[i, k]
                pos[j, i] += (r0[i, 0] * ax + r0[i, 1] * ay + r0[i, 2] * az) * q[j]
        else:  # r0 @ Rodrigues(axis, q_j)
            s, c = np.sin(q[j]), np.cos(q[j])
            t = 1.0 - c
            m00, m01, m02 = c + t * ax * ax, t * ax * ay - s * az, t * ax * az + s * ay
            m10, m11, m12 = t * ax * ay + s * az, c + t * ay * ay, t * ay * az - s * ax
            m20, m21, m22 = t * ax * az - s * ay, t * ay * az + s * ax, c + t * az * az
            for i in range(3):
                rot[j, i, 0] = r0[i, 0] * m00 + r0[i, 1] * m10 + r0[i, 2] * m20
                rot[j, i, 1] = r0[i, 0] * m01 + r0[i, 1] * m11 + r0[i, 2] * m21
                rot[j, i, 2] = r0[i, 0] * m02 + r0[i, 1] * m12 + r0[i, 2] * m22


def _centers(rot, pos, base_rot, base_pos, s_joint, s_center, c):  # type: ignore[no-untyped-def]
    """World centres ``c (P, 3)`` of the spheres from the joint frames."""
    for p in range(s_joint.shape[0]):
        j = s_joint[p]
        rr = base_rot if j < 0 else rot[j]
        pp = base_pos if j < 0 else pos[j]
        for i in range(3):
            c[p, i] = pp[i] + rr[i, 0] * s_center[p, 0] + rr[i, 1] * s_center[p, 1] + rr[i, 2] * s_center[p, 2]


def _place(q, kin_i, kin_f, s_joint, s_center, rot, pos, c):  # type: ignore[no-untyped-def]
    """Joint frames (``rot``, ``pos``) and sphere centres ``c`` of configuration ``q`` from
    the arrays packed by :func:`pack_kinematics`."""
    n = q.shape[0]
    rot0 = kin_f[: 9 * n].reshape(n, 3, 3)
    pos0 = kin_f[9 * n : 12 * n].reshape(n, 3)
    axis = kin_f[12 * n : 15 * n].reshape(n, 3)
    base_rot = kin_f[15 * n : 15 * n + 9].reshape(3, 3)
    base_pos = kin_f[15 * n + 9 : 15 * n + 12]
    _frames(q, kin_i[0], rot0, pos0, axis, kin_i[1], base_rot, base_pos, rot, pos)
    _centers(rot, pos, base_rot, base_pos, s_joint, s_center, c)


def _sphere_hits(c, p, r, box_c, box_r, box_h, sph_c, sph_r, cyl_c, cyl_r, cyl_rad, cyl_half, cloud):  # type: ignore[no-untyped-def]
    """Does sphere ``p`` (centre ``c[p]``, radius ``r``) touch a box, sphere, cylinder or
    a point of the cloud (``cloud``: its grid and point radius, :func:`pack_cloud`)?"""
    pts, starts, origin, dims, params, pr = cloud
    if pts.shape[0] > 0 and grid_point_within(c[p, 0], c[p, 1], c[p, 2], r + pr, pts, starts, origin, dims, params):
        return True
    r2 = r * r
    for o in range(box_c.shape[0]):
        d2 = 0.0
        for k in range(3):
            u = (
                (c[p, 0] - box_c[o, 0]) * box_r[o, 0, k]
                + (c[p, 1] - box_c[o, 1]) * box_r[o, 1, k]
                + (c[p, 2] - box_c[o, 2]) * box_r[o, 2, k]
            )
            e = abs(u) - box_h[o, k]
            if e > 0.0:
                d2 += e * e
        if d2 <= r2:
            return True
    for o in range(sph_c.shape[0]):
        dx, dy, dz = c[p, 0] - sph_c[o, 0], c[p, 1] - sph_c[o, 1], c[p, 2] - sph_c[o, 2]
        rs = r + sph_r[o]
        if dx * dx + dy * dy + dz * dz <= rs * rs:
            return True
    for o in range(cyl_c.shape[0]):
        dx, dy, dz = c[p, 0] - cyl_c[o, 0], c[p, 1] - cyl_c[o, 1], c[p, 2] - cyl_c[o, 2]
        ux = dx * cyl_r[o, 0, 0] + dy * cyl_r[o, 1, 0] + dz * cyl_r[o, 2, 0]
        uy = dx * cyl_r[o, 0, 1] + dy * cyl_r[o, 1, 1] + dz * cyl_r[o, 2, 1]
        uz = dx * cyl_r[o, 0, 2] + dy * cyl_r[o, 1, 2] + dz * cyl_r[o, 2, 2]
        er = np.sqrt(ux * ux + uy * uy) - cyl_rad[o]
        ez = abs(uz) - cyl_half[o]
        if (er * er if er > 0.0 else 0.0) + (ez * ez if ez > 0.0 else 0.0) <= r2:
            return True
    return False


def _arm_collides(  # type: ignore[no-untyped-def]
    q,
    sizes,
    kin_i,
    kin_f,
    s_joint,
    s_center,
    pairs,
    box_c,
    box_r,
    box_h,
    sph_c,
    sph_r,
    cyl_c,
    cyl_r,
    cyl_rad,
    cyl_half,
    cloud,
    out,
):
    """``out[b]``: does configuration ``q[b]`` collide? ``sizes (B or 1, P + K)``: sphere
    radii then pair distances. ``kin_i``/``kin_f``: the kinematic arrays packed by
    :func:`pack_kinematics`."""
    nb, n = q.shape
    p_count = s_joint.shape[0]
    rot = np.empty((n, 3, 3))
    pos = np.empty((n, 3))
    c = np.empty((p_count, 3))
    for b in range(nb):
        _place(q[b], kin_i, kin_f, s_joint, s_center, rot, pos, c)
        sz = sizes[0] if sizes.shape[0] == 1 else sizes[b]
        hit = False
        for p in range(p_count):
            if _sphere_hits(c, p, sz[p], box_c, box_r, box_h, sph_c, sph_r, cyl_c, cyl_r, cyl_rad, cyl_half, cloud):
                hit = True
                break
        if not hit:
            for k in range(pairs.shape[0]):
                a, e = pairs[k, 0], pairs[k, 1]
                dx, dy, dz = c[a, 0] - c[e, 0], c[a, 1] - c[e, 1], c[a, 2] - c[e, 2]
                keep = sz[p_count + k]
                if dx * dx + dy * dy + dz * dz <= keep * keep:
                    hit = True
                    break
        out[b] = hit


def _sphere_clearances(c, radii, box_c, box_r, box_h, sph_c, sph_r, cyl_c, cyl_r, cyl_rad, cyl_half, clear):  # type: ignore[no-untyped-def]
    """``clear[p]``: distance from sphere ``p`` (centre ``c[p]``, radius ``radii[p]``) to the
    nearest primitive obstacle (``<= 0``: touching or inside; ``inf`` without obstacles)."""
    for p in range(c.shape[0]):
        best = np.inf
        for o in range(box_c.shape[0]):
            d2 = 0.0
            for k in range(3):
                u = (
                    (c[p, 0] - box_c[o, 0]) * box_r[o, 0, k]
                    + (c[p, 1] - box_c[o, 1]) * box_r[o, 1, k]
                    + (c[p, 2] - box_c[o, 2]) * box_r[o, 2, k]
                )
                e = abs(u) - box_h[o, k]
                if e > 0.0:
                    d2 += e * e
            best = min(best, d2)
        for o in range(cyl_c.shape[0]):
            dx, dy, dz = c[p, 0] - cyl_c[o, 0], c[p, 1] - cyl_c[o, 1], c[p, 2] - cyl_c[o, 2]
            ux = dx * cyl_r[o, 0, 0] + dy * cyl_r[o, 1, 0] + dz * cyl_r[o, 2, 0]
            uy = dx * cyl_r[o, 0, 1] + dy * cyl_r[o, 1, 1] + dz * cyl_r[o, 2, 1]
            uz = dx * cyl_r[o, 0, 2] + dy * cyl_r[o, 1, 2] + dz * cyl_r[o, 2, 2]
            er = np.sqrt(ux * ux + uy * uy) - cyl_rad[o]
            ez = abs(uz) - cyl_half[o]
            best = min(best, (er * er if er > 0.0 else 0.0) + (ez * ez if ez > 0.0 else 0.0))
        out = np.sqrt(best) - radii[p]
        for o in range(sph_c.shape[0]):
            dx, dy, dz = c[p, 0] - sph_c[o, 0], c[p, 1] - sph_c[o, 1], c[p, 2] - sph_c[o, 2]
            out = min(out, np.sqrt(dx * dx + dy * dy + dz * dz) - sph_r[o] - radii[p])
        clear[p] = out


def _cloud_step(c, radii, rate, margin, step, cloud):  # type: ignore[no-untyped-def]
    """The advancement step ``step`` (already bounded by the other obstacles and the
    segment's end) bounded by the cloud too, and whether a sphere is within ``margin`` of
    it. A sphere's search for its nearest point stops where that point could no longer
    shorten the step (``margin + step * rate`` plus the radii), so spheres in the open read
    a few cells (:func:`grid_nearest_bound`: past its cap it gives a lower bound, which
    leaves the step as it is)."""
    pts, starts, origin, dims, params, pr = cloud
    for p in range(c.shape[0]):
        reach = margin + step * rate[p] + pr + radii[p]
        # (searched a little past reach: a point at reach itself is found, not bounded)
        near = grid_nearest_bound(
            c[p, 0], c[p, 1], c[p, 2], reach * (1.0 + 1e-9) + 1e-12, pts, starts, origin, dims, params
        )
        if near > reach:  # nothing within reach: this sphere neither blocks nor shortens the step
            continue
        clear = near - pr - radii[p]
        if clear <= margin:
            return True, step
        if rate[p] > 0.0:
            step = min(step, (clear - margin) / rate[p])
    return False, step


def _arm_advance(  # type: ignore[no-untyped-def]
    q0, twist, kin_i, kin_f, s_joint, s_center, pairs, radii, keep, w_sphere, w_pair,
    box_c, box_r, box_h, sph_c, sph_r, cyl_c, cyl_r, cyl_rad, cyl_half, cloud, margin, max_iter, out_s, out_n,
):  # fmt: skip
    """Conservative advancement along the joint-space segments ``q0[e] + s twist[e]``:
    from ``s = 0``, step by the least ``(clearance - margin) / rate`` over the spheres (rate:
    ``w_sphere @ |twist|``, the most a centre moves per unit ``s``) and over the
    self-collision pairs (``w_pair @ |twist|``, the most their distance changes), until
    ``s = 1``, a clearance is at most ``margin`` or ``max_iter[e]`` configurations have
    been evaluated (then the segment is certified only as far as it got). ``out_s[e]``: the fraction certified
    free (1: all of it; -1: the start itself is not); ``out_n[e]``: configurations evaluated."""
    ne, n = q0.shape
    p_count = s_joint.shape[0]
    pts = cloud[0]
    rot = np.empty((n, 3, 3))
    pos = np.empty((n, 3))
    c = np.empty((p_count, 3))
    clear = np.empty(p_count)
    q = np.empty(n)
    rate = np.empty(p_count)
    prate = np.empty(pairs.shape[0])
    for e in range(ne):
        for p in range(p_count):
            rate[p] = 0.0
            for j in range(n):
                rate[p] += w_sphere[p, j] * abs(twist[e, j])
        for k in range(pairs.shape[0]):
            prate[k] = 0.0
            for j in range(n):
                prate[k] += w_pair[k, j] * abs(twist[e, j])
        s = 0.0
        it = 0
        done = False
        while it < max_iter[e]:
            it += 1
            for j in range(n):
                q[j] = q0[e, j] + s * twist[e, j]
            _place(q, kin_i, kin_f, s_joint, s_center, rot, pos, c)
            _sphere_clearances(c, radii, box_c, box_r, box_h, sph_c, sph_r, cyl_c, cyl_r, cyl_rad, cyl_half, clear)
            step = np.inf
            blocked = False
            for p in range(p_count):
                if clear[p] <= margin:
                    blocked = True
                    break
                if rate[p] > 0.0:
                    step = min(step, (clear[p] - margin) / rate[p])
            if not blocked:
                for k in range(pairs.shape[0]):
                    a, b = pairs[k, 0], pairs[k, 1]
                    dx, dy, dz = c[a, 0] - c[b, 0], c[a, 1] - c[b, 1], c[a, 2] - c[b, 2]
                    gap = np.sqrt(dx * dx + dy * dy + dz * dz) - keep[k]
                    if gap <= margin:
                        blocked = True
                        break
                    if prate[k] > 0.0:
                        step = min(step, (gap - margin) / prate[k])
            if not blocked and pts.shape[0] > 0:
                blocked, step = _cloud_step(c, radii, rate, margin, min(step, 1.0 - s), cloud)
            if blocked:
                break
            if s + step >= 1.0:
                done = True
                break
            s += step
        out_n[e] = it
        if done:
            out_s[e] = 1.0
        elif s == 0.0 and it == 1:
            out_s[e] = -1.0
        else:
            out_s[e] = s


_frames = numba.njit(cache=True, nogil=True)(_frames)
_centers = numba.njit(cache=True, nogil=True)(_centers)
_place = numba.njit(cache=True, nogil=True)(_place)
_sphere_hits = numba.njit(cache=True, nogil=True)(_sphere_hits)
_sphere_clearances = numba.njit(cache=True, nogil=True)(_sphere_clearances)
_cloud_step = numba.njit(cache=True, nogil=True)(_cloud_step)
_arm_advance = numba.njit(cache=True, nogil=True)(_arm_advance)
_arm_collides = numba.njit(cache=True, nogil=True)(_arm_collides)


def pack_cloud(grid, point_radius):  # type: ignore[no-untyped-def]
    """A scene's cloud as the kernels take it: its grid (``CollisionWorld.cloud_grid``:
    points, row starts, origin, cells per axis, parameters) and its point radius; an empty
    one for ``grid=None`` (no cloud)."""
    if grid is None:
        return (np.zeros((0, 3)), np.zeros(1, np.int64), np.zeros(3), np.zeros(3, np.int64), np.ones(4), 0.0)
    pts, starts, origin, dims, params, _ = grid
    return (pts, starts, origin, np.asarray(dims, np.int64), params, float(point_radius))


def pack_kinematics(parent, prismatic, rot0, pos0, axis, base_rot, base_pos):  # type: ignore[no-untyped-def]
    """The kinematic arrays as one int and one float array (the kernel's arguments)."""
    kin_i = np.stack([np.asarray(parent, np.int64), np.asarray(prismatic, np.int64)])
    kin_f = np.concatenate(
        [np.ravel(rot0), np.ravel(pos0), np.ravel(axis), np.ravel(base_rot), np.ravel(base_pos)]
    ).astype(np.float64)
    return kin_i, kin_f
