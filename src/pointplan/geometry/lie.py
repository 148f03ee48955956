"""Batched Lie-group operations on SO(2), SE(2), SO(3) and SE(3).

Every function accepts arrays with arbitrary leading batch dimensions. Poses are
homogeneous matrices (``(..., 3, 3)`` for SE(2), ``(..., 4, 4)`` for SE(3)); twists are
body-frame velocity vectors ordered translation first: ``(vx, vy, w)`` for SE(2) and
``(vx, vy, vz, wx, wy, wz)`` for SE(3). Quaternions are ``(x, y, z, w)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

_EPS = 1e-8


def hat3(w: Array) -> Array:
    """Skew-symmetric matrices of vectors ``w: (..., 3) -> (..., 3, 3)``."""
    w = np.asarray(w, dtype=np.float64)
    out = np.zeros(w.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -w[..., 2], w[..., 1]
    out[..., 1, 0], out[..., 1, 2] = w[..., 2], -w[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -w[..., 1], w[..., 0]
    return out


def _so3_coeffs(theta: Array) -> tuple[Array, Array, Array]:
    """A = sin(t)/t, B = (1-cos t)/t^2, C = (t - sin t)/t^3 with Taylor series near 0."""
    t2 = theta * theta
    small = theta < 1e-4
    ts = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - t2 / 6.0, np.sin(ts) / ts)
    b = np.where(small, 0.5 - t2 / 24.0, (1.0 - np.cos(ts)) / (ts * ts))
    c = np.where(small, 1.0 / 6.0 - t2 / 120.0, (ts - np.sin(ts)) / (ts**3))
    return a, b, c


def so3_exp(w: Array) -> Array:
    """Rotation matrices ``(..., 3, 3)`` from rotation vectors ``w: (..., 3)``."""
    w = np.asarray(w, dtype=np.float64)
    theta = np.linalg.norm(w, axis=-1)
    a, b, _ = _so3_coeffs(theta)
    k = hat3(w)
    eye = np.broadcast_to(np.eye(3), k.shape)
    return eye + a[..., None, None] * k + b[..., None, None] * (k @ k)


def so3_log(r: Array) -> Array:
    """Rotation vectors ``(..., 3)`` (angle in [0, pi]) from rotation matrices."""
    r = np.asarray(r, dtype=np.float64)
    cos = (np.trace(r, axis1=-2, axis2=-1) - 1.0) / 2.0
    vee = np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]], -1)
    # arctan2 keeps full precision at both ends, where arccos of the trace does not
    theta = np.arctan2(np.linalg.norm(vee, axis=-1) / 2.0, cos)
    small = theta < 1e-4
    near_pi = theta > np.pi - 1e-3
    sin = np.sin(theta)
    scale = np.where(small, 0.5 + theta**2 / 12.0, theta / (2.0 * np.where(small, 1.0, sin) + _EPS * small))
    w = scale[..., None] * vee
    if np.any(near_pi):
        # Near pi the antisymmetric part vanishes; read the axis from the symmetric part.
        rp = r[near_pi]
        th = theta[near_pi]
        bmat = (rp + np.swapaxes(rp, -1, -2)) / 2.0 - np.cos(th)[..., None, None] * np.eye(3)
        diag = np.clip(np.diagonal(bmat, axis1=-2, axis2=-1), 0.0, None)
        i = np.argmax(diag, axis=-1)
        col = np.take_along_axis(bmat, i[:, None, None].repeat(3, axis=1), axis=2)[..., 0]
        axis = col / np.linalg.norm(col, axis=-1, keepdims=True)
        v = vee[near_pi]
        sign = np.where(np.sum(axis * v, axis=-1) < 0, -1.0, 1.0)
        w[near_pi] = axis * (sign * th)[..., None]
    return w


def so3_left_jacobian(w: Array) -> Array:
    """V(w) such that the translation of exp((v, w)) is ``V(w) v``."""
    theta = np.linalg.norm(w, axis=-1)
    _, b, c = _so3_coeffs(theta)
    k = hat3(w)
    eye = np.broadcast_to(np.eye(3), k.shape)
    return eye + b[..., None, None] * k + c[..., None, None] * (k @ k)


def so3_left_jacobian_inv(w: Array) -> Array:
    """Inverse of :func:`so3_left_jacobian`."""
    theta = np.linalg.norm(w, axis=-1)
    small = theta < 1e-4
    ts = np.where(small, 1.0, theta)
    half = ts / 2.0
    d = np.where(small, 1.0 / 12.0 + theta**2 / 720.0, (1.0 - half * np.cos(half) / np.sin(half)) / (ts * ts))
    k = hat3(w)
    eye = np.broadcast_to(np.eye(3), k.shape)
    return eye - 0.5 * k + d[..., None, None] * (k @ k)


def se3_exp(xi: Array) -> Array:
    """SE(3) matrices ``(..., 4, 4)`` from body twists ``xi: (..., 6)`` (v, w)."""
    xi = np.asarray(xi, dtype=np.float64)
    v, w = xi[..., :3], xi[..., 3:]
    out = np.zeros(xi.shape[:-1] + (4, 4))
    out[..., :3, :3] = so3_exp(w)
    out[..., :3, 3] = np.einsum("...ij,...j->...i", so3_left_jacobian(w), v)
    out[..., 3, 3] = 1.0
    return out


def se3_log(t: Array) -> Array:
    """Body twists ``(..., 6)`` from SE(3) matrices."""
    t = np.asarray(t, dtype=np.float64)
    w = so3_log(t[..., :3, :3])
    v = np.einsum("...ij,...j->...i", so3_left_jacobian_inv(w), t[..., :3, 3])
    return np.concatenate([v, w], -1)


def se3_inv(t: Array) -> Array:
    """Inverse of SE(3) matrices."""
    t = np.asarray(t, dtype=np.float64)
    out = np.zeros_like(t)
    rt = np.swapaxes(t[..., :3, :3], -1, -2)
    out[..., :3, :3] = rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", rt, t[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def so2_exp(theta: Array) -> Array:
    """2x2 rotation matrices from angles ``(...,)``."""
    theta = np.asarray(theta, dtype=np.float64)
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def so2_log(r: Array) -> Array:
    """Angles in (-pi, pi] from 2x2 rotation matrices."""
    r = np.asarray(r, dtype=np.float64)
    return np.arctan2(r[..., 1, 0], r[..., 0, 0])


def se2_exp(xi: Array) -> Array:
    """SE(2) matrices ``(..., 3, 3)`` from body twists ``xi: (..., 3)`` (vx, vy, w)."""
    xi = np.asarray(xi, dtype=np.float64)
    v, th = xi[..., :2], xi[..., 2]
    small = np.abs(th) < 1e-6
    ts = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th**2 / 6.0, np.sin(ts) / ts)
    b = np.where(small, th / 2.0, 2.0 * np.sin(ts / 2.0) ** 2 / ts)  # (1 - cos) / th without the cancellation
    vmat = np.stack([np.stack([a, -b], -1), np.stack([b, a], -1)], -2)
    out = np.zeros(xi.shape[:-1] + (3, 3))
    out[..., :2, :2] = so2_exp(th)
    out[..., :2, 2] = np.einsum("...ij,...j->...i", vmat, v)
    out[..., 2, 2] = 1.0
    return out


def se2_log(t: Array) -> Array:
    """Body twists ``(..., 3)`` from SE(2) matrices."""
    t = np.asarray(t, dtype=np.float64)
    th = so2_log(t[..., :2, :2])
    small = np.abs(th) < 1e-6
    ts = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th**2 / 6.0, np.sin(ts) / ts)
    b = np.where(small, th / 2.0, 2.0 * np.sin(ts / 2.0) ** 2 / ts)  # (1 - cos) / th without the cancellation
    det = a * a + b * b
    vinv = np.stack([np.stack([a, b], -1), np.stack([-b, a], -1)], -2) / det[..., None, None]
    v = np.einsum("...ij,...j->...i", vinv, t[..., :2, 2])
    return np.concatenate([v, th[..., None]], -1)


def se_inv(t: Array) -> Array:
    """Inverse of SE(2) or SE(3) homogeneous matrices."""
    t = np.asarray(t, dtype=np.float64)
    n = t.shape[-1] - 1
    out = np.zeros_like(t)
    rt = np.swapaxes(t[..., :n, :n], -1, -2)
    out[..., :n, :n] = rt
    out[..., :n, n] = -np.einsum("...ij,...j->...i", rt, t[..., :n, n])
    out[..., n, n] = 1.0
    return out


def se_exp(xi: Array) -> Array:
    """SE(2) or SE(3) exponential, chosen by the twist length (3 or 6)."""
    return se2_exp(xi) if np.shape(xi)[-1] == 3 else se3_exp(xi)


def se_log(t: Array) -> Array:
    """SE(2) or SE(3) logarithm, chosen by the matrix size."""
    return se2_log(t) if np.shape(t)[-1] == 3 else se3_log(t)


def relative_twist(t0: Array, t1: Array) -> Array:
    """Body twist ``log(T0^-1 T1)`` that carries T0 onto T1 in unit time."""
    return se_log(se_inv(t0) @ t1)


def geodesic(t0: Array, t1: Array, s: Array) -> Array:
    """Points ``T0 exp(s log(T0^-1 T1))`` along the geodesic; ``s`` broadcasts on the batch."""
    xi = relative_twist(t0, t1)
    s = np.asarray(s, dtype=np.float64)
    return t0 @ se_exp(xi * s[..., None])


def geodesic_distance(t0: Array, t1: Array) -> Array:
    """``||log(T0^-1 T1)||``: metres and radians weighted one to one."""
    return np.linalg.norm(relative_twist(t0, t1), axis=-1)


def quat_to_matrix(q: Array) -> Array:
    """Rotation matrices from quaternions ``(..., 4)`` (x, y, z, w); normalises first."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    out = np.empty(q.shape[:-1] + (3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)
    out[..., 1, 0], out[..., 1, 1], out[..., 1, 2] = 2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)
    out[..., 2, 0], out[..., 2, 1], out[..., 2, 2] = 2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)
    return out


def matrix_to_quat(r: Array) -> Array:
    """Quaternions (x, y, z, w) with w >= 0 from rotation matrices."""
    r = np.asarray(r, dtype=np.float64)
    tr = np.trace(r, axis1=-2, axis2=-1)
    cand = np.stack(
        [
            1 + 2 * r[..., 0, 0] - tr,
            1 + 2 * r[..., 1, 1] - tr,
            1 + 2 * r[..., 2, 2] - tr,
            1 + tr,
        ],
        -1,
    )
    i = np.argmax(cand, axis=-1)
    out = np.empty(r.shape[:-2] + (4,))
    s = np.sqrt(np.maximum(np.take_along_axis(cand, i[..., None], -1)[..., 0], 1e-12))
    # Four cases, written with masks so the function stays batched.
    m = i == 3
    out[m, 3] = s[m] / 2
    out[m, 0] = (r[m, 2, 1] - r[m, 1, 2]) / (2 * s[m])
    out[m, 1] = (r[m, 0, 2] - r[m, 2, 0]) / (2 * s[m])
    out[m, 2] = (r[m, 1, 0] - r[m, 0, 1]) / (2 * s[m])
    m = i == 0
    out[m, 0] = s[m] / 2
    out[m, 3] = (r[m, 2, 1] - r[m, 1, 2]) / (2 * s[m])
    out[m, 1] = (r[m, 0, 1] + r[m, 1, 0]) / (2 * s[m])
    out[m, 2] = (r[m, 0, 2] + r[m, 2, 0]) / (2 * s[m])
    m = i == 1
    out[m, 1] = s[m] / 2
    out[m, 3] = (r[m, 0, 2] - r[m, 2, 0]) / (2 * s[m])
    out[m, 0] = (r[m, 0, 1] + r[m, 1, 0]) / (2 * s[m])
    out[m, 2] = (r[m, 1, 2] + r[m, 2, 1]) / (2 * s[m])
    m = i == 2
    out[m, 2] = s[m] / 2
    out[m, 3] = (r[m, 1, 0] - r[m, 0, 1]) / (2 * s[m])
    out[m, 0] = (r[m, 0, 2] + r[m, 2, 0]) / (2 * s[m])
    out[m, 1] = (r[m, 1, 2] + r[m, 2, 1]) / (2 * s[m])
    out = out / np.linalg.norm(out, axis=-1, keepdims=True)
    return np.where(out[..., 3:4] < 0, -out, out)


def random_rotations(rng: np.random.Generator, n: int) -> Array:
    """``n`` rotation matrices drawn uniformly (Haar measure) from SO(3)."""
    q = rng.normal(size=(n, 4))
    return quat_to_matrix(q)
