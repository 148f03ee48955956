"""Compiled (numba) SE(3) kernels on position + quaternion poses ``(x, y, z, qx, qy, qz, qw)``.

They compute what :class:`~pointplan.robots.sshape.SShape` computes through 4x4 matrices
(``lie.se3_exp`` / ``lie.relative_twist``) directly on quaternions, one pose at a time, so
that planners calling them with a handful of configurations do not pay numpy's per-call
overhead. The numpy path through 4x4 matrices (``SShape._integrate_numpy`` / ``_log_numpy``,
``NumpySShape``) is the reference they are tested against.

Conventions match :mod:`pointplan.geometry.lie`: twists are body-frame ``(v, w)``,
translation first; input quaternions are normalised; output quaternions have ``w >= 0``.
When the output ``w`` is exactly 0 (a half turn, where ``q`` and ``-q`` both qualify) the
component of largest magnitude (the first of equal ones) is made positive, which is what
``lie.matrix_to_quat`` and ``lie.so3_log`` pick when their own arithmetic gives exactly 0
there. Within round-off of a half turn the two paths may still pick opposite signs: the
poses are then the same, and ``log`` returns a twist of angle pi either way.
"""

from __future__ import annotations

import math

import numba
import numpy as np

#: below this angle the coefficients that divide by powers of it use Taylor series
_SMALL = 1e-4
#: below this angle the cancelling coefficients (t - sin t and 1 - (t/2) cot(t/2)) do
_CANCEL = 1e-2


def _half_turn_sign(x: float, y: float, z: float, w: float) -> float:
    """Sign (+-1) to apply to a quaternion so that ``w >= 0``; for ``w == 0`` the component
    of largest magnitude (the first of equal ones) becomes positive."""
    if w > 0.0:
        return 1.0
    if w < 0.0:
        return -1.0
    big = x
    if abs(y) > abs(big):
        big = y
    if abs(z) > abs(big):
        big = z
    return -1.0 if big < 0.0 else 1.0


def _pose_integrate_flat(q, v, out):  # type: ignore[no-untyped-def]
    """``out[i] = q[i] * exp(v[i])`` for poses ``q (N, 7)`` and body twists ``v (N, 6)``.

    Rotation: ``quat(q) * (w / t sin(t/2), cos(t/2))`` with ``t = |w|``. Translation:
    ``p + R(q) V(w) v`` with the SO(3) left Jacobian ``V = I + B [w] + C [w]^2``,
    ``B = (1 - cos t) / t^2``, ``C = (t - sin t) / t^3``."""
    for i in range(q.shape[0]):
        # the pose, quaternion normalised
        px, py, pz = q[i, 0], q[i, 1], q[i, 2]
        ax, ay, az, aw = q[i, 3], q[i, 4], q[i, 5], q[i, 6]
        n = math.sqrt(ax * ax + ay * ay + az * az + aw * aw)
        ax, ay, az, aw = ax / n, ay / n, az / n, aw / n
        vx, vy, vz = v[i, 0], v[i, 1], v[i, 2]
        wx, wy, wz = v[i, 3], v[i, 4], v[i, 5]
        t2 = wx * wx + wy * wy + wz * wz
        t = math.sqrt(t2)
        # s = sin(t/2) / t, c = cos(t/2), b = (1 - cos t) / t^2, cc = (t - sin t) / t^3
        if t < _SMALL:
            s = 0.5 - t2 / 48.0 + t2 * t2 / 3840.0
            c = 1.0 - t2 / 8.0 + t2 * t2 / 384.0
            b = 0.5 - t2 / 24.0 + t2 * t2 / 720.0
        else:
            sh = math.sin(0.5 * t)
            c = math.cos(0.5 * t)
            s = sh / t
            b = 2.0 * sh * sh / t2  # 1 - cos t without the cancellation
        if t < _CANCEL:
            cc = 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0 - t2 * t2 * t2 / 362880.0
        else:
            cc = (t - math.sin(t)) / (t2 * t)
        # u = V(w) v = v + b w x v + cc w x (w x v)
        kx = wy * vz - wz * vy
        ky = wz * vx - wx * vz
        kz = wx * vy - wy * vx
        ux = vx + b * kx + cc * (wy * kz - wz * ky)
        uy = vy + b * ky + cc * (wz * kx - wx * kz)
        uz = vz + b * kz + cc * (wx * ky - wy * kx)
        # p + R(a) u, with R(a) u = u + 2 aw (a x u) + 2 a x (a x u)
        tx = 2.0 * (ay * uz - az * uy)
        ty = 2.0 * (az * ux - ax * uz)
        tz = 2.0 * (ax * uy - ay * ux)
        out[i, 0] = px + ux + aw * tx + (ay * tz - az * ty)
        out[i, 1] = py + uy + aw * ty + (az * tx - ax * tz)
        out[i, 2] = pz + uz + aw * tz + (ax * ty - ay * tx)
        # a * d, d = (s w, c) the rotation increment
        dx, dy, dz = s * wx, s * wy, s * wz
        rx = aw * dx + c * ax + (ay * dz - az * dy)
        ry = aw * dy + c * ay + (az * dx - ax * dz)
        rz = aw * dz + c * az + (ax * dy - ay * dx)
        rw = aw * c - (ax * dx + ay * dy + az * dz)
        n = _half_turn_sign(rx, ry, rz, rw) / math.sqrt(rx * rx + ry * ry + rz * rz + rw * rw)
        out[i, 3] = rx * n
        out[i, 4] = ry * n
        out[i, 5] = rz * n
        out[i, 6] = rw * n


def _pose_log_flat(q0, q1, out):  # type: ignore[no-untyped-def]
    """``out[i] = log(q0[i]^-1 q1[i])`` (body twist, angle in [0, pi]) for poses ``(N, 7)``.

    Rotation: ``r = conj(a) b`` of the normalised quaternions taken with ``w >= 0``, then
    ``w = 2 atan2(|r_v|, r_w) r_v / |r_v|``. Translation: ``V(w)^-1 R(a)^T (p1 - p0)`` with
    ``V^-1 = I - [w] / 2 + D [w]^2``, ``D = (1 - (t/2) cot(t/2)) / t^2``."""
    for i in range(q0.shape[0]):
        ax, ay, az, aw = q0[i, 3], q0[i, 4], q0[i, 5], q0[i, 6]
        n = math.sqrt(ax * ax + ay * ay + az * az + aw * aw)
        ax, ay, az, aw = ax / n, ay / n, az / n, aw / n
        bx, by, bz, bw = q1[i, 3], q1[i, 4], q1[i, 5], q1[i, 6]
        n = math.sqrt(bx * bx + by * by + bz * bz + bw * bw)
        bx, by, bz, bw = bx / n, by / n, bz / n, bw / n
        # the relative rotation conj(a) * b
        rx = aw * bx - bw * ax - (ay * bz - az * by)
        ry = aw * by - bw * ay - (az * bx - ax * bz)
        rz = aw * bz - bw * az - (ax * by - ay * bx)
        rw = aw * bw + ax * bx + ay * by + az * bz
        sign = _half_turn_sign(rx, ry, rz, rw)
        rx, ry, rz, rw = sign * rx, sign * ry, sign * rz, sign * rw
        # rotation vector; rw >= 0 so the angle is in [0, pi]
        sv = math.sqrt(rx * rx + ry * ry + rz * rz)
        if sv < _SMALL:
            # 2 atan(r) / sv with r = sv / rw (rw is about 1 here)
            r2 = sv * sv / (rw * rw)
            scale = 2.0 / rw * (1.0 - r2 / 3.0 + r2 * r2 / 5.0)
        else:
            scale = 2.0 * math.atan2(sv, rw) / sv
        wx, wy, wz = scale * rx, scale * ry, scale * rz
        t2 = wx * wx + wy * wy + wz * wz
        # D(t); (t/2) cot(t/2) = (t/2) rw / sv since (sv, rw) ~ (sin, cos)(t/2)
        if t2 < _CANCEL * _CANCEL:
            d = 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0 + t2 * t2 * t2 / 1209600.0
        else:
            d = (1.0 - 0.5 * math.sqrt(t2) * rw / sv) / t2
        # p = R(a)^T (p1 - p0) = u - 2 aw (a x u) + 2 a x (a x u)
        ux = q1[i, 0] - q0[i, 0]
        uy = q1[i, 1] - q0[i, 1]
        uz = q1[i, 2] - q0[i, 2]
        tx = 2.0 * (ay * uz - az * uy)
        ty = 2.0 * (az * ux - ax * uz)
        tz = 2.0 * (ax * uy - ay * ux)
        px = ux - aw * tx + (ay * tz - az * ty)
        py = uy - aw * ty + (az * tx - ax * tz)
        pz = uz - aw * tz + (ax * ty - ay * tx)
        # v = p - (w x p) / 2 + d w x (w x p)
        kx = wy * pz - wz * py
        ky = wz * px - wx * pz
        kz = wx * py - wy * px
        out[i, 0] = px - 0.5 * kx + d * (wy * kz - wz * ky)
        out[i, 1] = py - 0.5 * ky + d * (wz * kx - wx * kz)
        out[i, 2] = pz - 0.5 * kz + d * (wx * ky - wy * kx)
        out[i, 3] = wx
        out[i, 4] = wy
        out[i, 5] = wz


# error_model="numpy": a zero quaternion gives nan (as the numpy path does), not an exception
_jit = numba.njit(cache=True, nogil=True, error_model="numpy")
_half_turn_sign = _jit(_half_turn_sign)
_pose_integrate_flat = _jit(_pose_integrate_flat)
_pose_log_flat = _jit(_pose_log_flat)


def pose_integrate_compiled(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``q * exp(v)`` for C-contiguous float64 poses ``(N, 7)`` and twists ``(N, 6)``."""
    out = np.empty((q.shape[0], 7))
    _pose_integrate_flat(q, v, out)
    return out


def pose_log_compiled(q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """``log(q0^-1 q1)`` for C-contiguous float64 poses ``(N, 7)``; twists ``(N, 6)``."""
    out = np.empty((q0.shape[0], 6))
    _pose_log_flat(q0, q1, out)
    return out
