"""Certified motion checks: the one motion validator of the environment and the planners.

A motion is a geodesic ``q0 * exp(s v)``, ``s`` in ``[0, 1]``, sampled at ``s_j = j / n``
(``j = 0..n``). Checking only the samples misses collisions between them (a disc of
radius ``r`` can cut ``r - sqrt(r^2 - (delta/2)^2)`` into a box corner between samples
``delta`` apart). Here each sample is checked with the robot's body *grown* so that the
grown bodies at the samples cover everything the body sweeps between them
(:meth:`Robot.grown_parts <pointplan.robots.base.Robot.grown_parts>` gives the growth per
robot; ``docs/design.md`` proves the covers). If no grown sample collides, no
configuration of the motion does, and none comes within :data:`CONTACT_MARGIN` of an
obstacle.

Grown samples certify the half sub-step on each side of them, so the start pose is checked
grown too. A start closer to an obstacle than its growth (a problem's start a hair from a
wall, or an obstacle that has moved next to the robot) is not stuck: the first sub-step is
then certified instead by the plain start together with sample 1 grown to cover the whole
first sub-step (a second, small query for those motions only).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from ..geometry.collision import CollisionWorld
    from .base import Robot

Array = NDArray[np.float64]
Bool = NDArray[np.bool_]
Int = NDArray[np.int64]

#: every checked body is grown by this much more: an accepted motion keeps at least this
#: clearance (the evaluator calls a clearance below 1e-6 a contact)
CONTACT_MARGIN = 1e-5
#: positions may leave the bounds by this much (round-off of the geodesic's end)
BOUNDS_EPS = 1e-12
#: slack on ``length / resolution`` before rounding up, so that an edge of exactly ``step``
#: gets the same number of intervals whatever the round-off of its length
GRID_SLACK = 1e-9


def intervals(length: Array, resolution: float) -> Int:
    """Sub-steps of a checked motion: ``max(1, ceil(length / resolution - GRID_SLACK))``."""
    return np.maximum(1, np.ceil(np.asarray(length) / resolution - GRID_SLACK).astype(np.int64))


@dataclass
class MotionCheck:
    """Outcome of :func:`check_motions` for a batch of motions ``(...)``."""

    #: ``k`` in ``[-1, n]``: the motion is certified free on ``[0, k / n]`` (``k = n``: all
    #: of it; ``k = -1``: not even the start pose)
    free: Int
    #: the motion was stopped by an obstacle (False when it was stopped by the bounds or
    #: not at all)
    collided: Bool
    #: configurations checked per motion
    checks: Int
    #: the samples ``q0 exp(s_j v)``: ``(..., J, config_dim)``, ``J = max(n) + 1``; past a
    #: motion's own ``n`` they repeat its end
    configs: Array


def _grown_collides(robot: Robot, world: CollisionWorld, q: Array, seg: Array, reach: float, margin: float, mask: Bool | None) -> Bool:
    """Collision of the bodies at ``q: (..., J, cdim)`` grown for motions by ``seg: (...,
    twist_dim)`` between samples (``reach`` as in ``Robot.grown_parts``) plus ``margin``.
    With a single-scene world only the entries where ``mask`` is true are computed."""
    radii, halfs = robot.grown_parts(seg, reach)
    radii = (radii + margin)[..., None, :]  # (..., 1, Ps): the same for every sample
    halfs = (halfs + margin)[..., None, :, :]
    if world.batch_shape != () or mask is None:
        return robot.collides(world, q, radii=radii, halfs=halfs)
    out = np.zeros(q.shape[:-1], dtype=bool)
    if mask.any():
        radii = np.broadcast_to(radii, q.shape[:-1] + radii.shape[-1:])[mask]
        halfs = np.broadcast_to(halfs, q.shape[:-1] + halfs.shape[-2:])[mask]
        out[mask] = robot.collides(world, q[mask], radii=radii, halfs=halfs)
    return out


def check_motions(
    robot: Robot,
    world: CollisionWorld,
    q0: Array,
    twist: Array,
    n: Int,
    low: Array | None = None,
    high: Array | None = None,
) -> MotionCheck:
    """Certify the motions ``q0 * exp(s twist)`` sampled in ``n`` sub-steps each.

    ``q0: (..., config_dim)``, ``twist: (..., twist_dim)``, ``n: (...)`` (at least 1);
    ``world`` is a single scene or stacked with ``batch_shape == (...)`` (then ``q0`` is
    ``(E, config_dim)``). ``low, high`` (broadcasting to ``(..., d)``), if given, bound the
    positions of the samples: a sample outside stops the motion without being a collision.
    """
    q0 = np.asarray(q0, np.float64)
    twist = np.asarray(twist, np.float64)
    n = np.maximum(np.asarray(n, np.int64), 1)
    lead = q0.shape[:-1]
    if n.shape != lead:
        n = np.broadcast_to(n, lead)
    nmax = int(n.max()) if n.size else 1
    j = np.arange(nmax + 1)
    valid = j <= n[..., None]  # (..., J)
    s = np.minimum(j / n[..., None], 1.0)
    qs = robot.integrate(q0[..., None, :], twist[..., None, :] * s[..., None])  # (..., J, cdim)
    seg = twist / n[..., None]
    ok = ~_grown_collides(robot, world, qs, seg, 0.5, CONTACT_MARGIN, valid)
    checks = n + 1
    retry = ~ok[..., 0]
    if retry.any():
        # the start is too close for its grown check: the plain start and sample 1 grown
        # over the whole first sub-step certify that sub-step instead
        pair = qs[..., :2, :]
        plain = ~_grown_collides(robot, world, pair[..., :1, :], seg, 0.0, CONTACT_MARGIN, retry[..., None])[..., 0]
        wide = ~_grown_collides(robot, world, pair[..., 1:, :], seg, 1.0, CONTACT_MARGIN, retry[..., None])[..., 0]
        ok[..., 0] |= retry & plain & wide
        checks = checks + 2 * retry
    out = np.zeros(ok.shape, dtype=bool)
    if low is not None and high is not None:
        pos = robot.positions(qs)
        lo = np.asarray(low, np.float64)[..., None, :]
        hi = np.asarray(high, np.float64)[..., None, :]
        out = np.any((pos < lo - BOUNDS_EPS) | (pos > hi + BOUNDS_EPS), axis=-1)
    stop = (~ok | out) & valid
    first = stop.argmax(-1)
    flat = first.reshape(-1)
    at_first = ~ok.reshape(-1, nmax + 1)[np.arange(flat.size), flat].reshape(first.shape)
    stopped = stop.reshape(-1, nmax + 1)[np.arange(flat.size), flat].reshape(first.shape)
    first = np.where(stopped, first, n + 1)
    hit = at_first
    return MotionCheck(free=first - 1, collided=stopped & hit, checks=checks, configs=qs)


def segments_free(robot: Robot, world: CollisionWorld, a: Array, b: Array, resolution: float, low: Array | None = None, high: Array | None = None) -> tuple[Bool, Int]:
    """Are the geodesics ``a[e] -> b[e]`` (``(E, config_dim)`` each) certified free (and
    inside the bounds)? Each is sampled in ``intervals(length, resolution)`` sub-steps.
    Returns ``(E,)`` booleans and the configurations checked per segment."""
    a = np.asarray(a, np.float64)
    v = robot.log(a, np.asarray(b, np.float64))
    m = intervals(np.linalg.norm(v, axis=-1), resolution)
    chk = check_motions(robot, world, a, v, m, low, high)
    return chk.free == m, chk.checks
