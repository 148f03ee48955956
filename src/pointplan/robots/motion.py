"""Certified motion checks: the one motion validator of the environment and the planners.

A motion is a geodesic ``q0 * exp(s v)``, ``s`` in ``[0, 1]``, sampled at ``s_j = j / n``
(``j = 0..n``). Checking only the samples misses collisions between them (a disc of
radius ``r`` can cut ``r - sqrt(r^2 - (delta/2)^2)`` into a box corner between samples
``delta`` apart). Here each sample is checked with the robot's body *grown* so that the
grown bodies at the samples cover everything the body sweeps between them
(:meth:`Robot.grown_parts <pointplan.robots.base.Robot.grown_parts>` gives the growth per
robot; ``docs/reference/design.md`` proves the covers). If no grown sample collides, no
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
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from ..geometry.collision import CollisionWorld

Array = NDArray[np.float64]
Bool = NDArray[np.bool_]
Int = NDArray[np.int64]


class Robot(Protocol):
    """What the checks use of a :class:`pointplan.robots.base.Robot` (which imports this
    module, so it is not imported here)."""

    def grown_parts(self, seg: Array, reach: float) -> tuple[Array, Array]: ...

    def collides(
        self, world: CollisionWorld, q: Array, radii: Array | None = None, halfs: Array | None = None
    ) -> Bool: ...

    def integrate(self, q: Array, v: Array) -> Array: ...

    def positions(self, q: Array) -> Array: ...

    def log(self, q0: Array, q1: Array) -> Array: ...

    def check_motions(
        self,
        world: CollisionWorld,
        q0: Array,
        twist: Array,
        n: Int,
        low: Array | None = None,
        high: Array | None = None,
        fallback: Bool | None = None,
    ) -> MotionCheck: ...


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


def _sizes(robot: Robot, seg: Array, reach: float) -> tuple[Array, Array]:
    """Grown part sizes plus the contact margin, with a sample axis: ``(..., 1, Ps)`` and
    ``(..., 1, Pb, d)``."""
    radii, halfs = robot.grown_parts(seg, reach)
    return (radii + CONTACT_MARGIN)[..., None, :], (halfs + CONTACT_MARGIN)[..., None, :, :]


def _collides(
    robot: Robot, world: CollisionWorld, q: Array, radii: Array, halfs: Array, mask: Bool | None = None
) -> Bool:
    """Collision of bodies of the given sizes at ``q: (..., J, cdim)``; with a single-scene
    world and a ``mask: (..., J)`` only the masked entries are computed."""
    if world.batch_shape != () or mask is None:
        return robot.collides(world, q, radii=radii, halfs=halfs)
    out = np.zeros(q.shape[:-1], dtype=bool)
    if mask.any():
        radii = np.broadcast_to(radii, q.shape[:-1] + radii.shape[-1:])[mask]
        halfs = np.broadcast_to(halfs, q.shape[:-1] + halfs.shape[-2:])[mask]
        out[mask] = robot.collides(world, q[mask], radii=radii, halfs=halfs)
    return out


def _start_fallback(robot: Robot, world: CollisionWorld, qs: Array, seg: Array, retry: Bool) -> Bool:
    """For motions whose grown start collides (``retry: (...)``): is the first sub-step
    certified by the plain start and sample 1 grown over the whole sub-step? ``(...)``."""
    r0, h0 = _sizes(robot, seg, 0.0)
    r1, h1 = _sizes(robot, seg, 1.0)
    radii = np.concatenate([r0, r1], -2)  # (..., 2, Ps)
    halfs = np.concatenate([h0, h1], -3)
    mask = np.broadcast_to(retry[..., None], retry.shape + (2,))
    return retry & ~_collides(robot, world, qs[..., :2, :], radii, halfs, mask).any(-1)


def check_motions(
    robot: Robot,
    world: CollisionWorld,
    q0: Array,
    twist: Array,
    n: Int,
    low: Array | None = None,
    high: Array | None = None,
    fallback: Bool | None = None,
) -> MotionCheck:
    """Certify the motions ``q0 * exp(s twist)`` sampled in ``n`` sub-steps each.

    ``q0: (..., config_dim)``, ``twist: (..., twist_dim)``, ``n: (...)`` (at least 1);
    ``world`` is a single scene or stacked with ``batch_shape == (...)`` (then ``q0`` is
    ``(E, config_dim)``). ``low, high`` (broadcasting to ``(..., d)``), if given, bound the
    positions of the samples: a sample outside stops the motion without being a collision.
    ``fallback: (...)`` says which motions may certify their first sub-step from a start
    too close for its grown check (default: all; a caller whose motion ``e`` starts where
    motion ``e - 1`` ends needs it for the first only).
    """
    q0 = np.asarray(q0, np.float64)
    twist = np.asarray(twist, np.float64)
    n = np.maximum(np.asarray(n, np.int64), 1)
    lead = q0.shape[:-1]
    if n.shape != lead:
        n = np.broadcast_to(n, lead)
    nmax = int(n.max()) if n.size else 1
    # samples past a motion's own n repeat its end (same configuration, same sizes, same
    # verdict), so they never stop a motion earlier than its end would: no mask needed
    s = np.minimum(np.arange(nmax + 1) / n[..., None], 1.0)  # (..., J)
    qs = robot.integrate(q0[..., None, :], twist[..., None, :] * s[..., None])  # (..., J, cdim)
    seg = twist / n[..., None]
    bad = _collides(robot, world, qs, *_sizes(robot, seg, 0.5))
    checks = n + 1
    retry = bad[..., 0].copy() if fallback is None else bad[..., 0] & fallback
    if retry.any():
        bad[..., 0] &= ~_start_fallback(robot, world, qs, seg, retry)
        checks = checks + 2 * retry
    stop = bad
    if low is not None and high is not None:
        mid, half = (np.asarray(high) + np.asarray(low)) / 2, (np.asarray(high) - np.asarray(low)) / 2 + BOUNDS_EPS
        stop = bad | np.any(np.abs(robot.positions(qs) - mid[..., None, :]) > half[..., None, :], axis=-1)
    if not stop.any():
        return MotionCheck(free=n.copy(), collided=np.zeros(lead, bool), checks=checks, configs=qs)
    first = stop.argmax(-1)
    at = (np.arange(first.size), first.reshape(-1))
    stopped = stop.reshape(-1, nmax + 1)[at].reshape(lead)
    hit = bad.reshape(-1, nmax + 1)[at].reshape(lead)
    return MotionCheck(free=np.where(stopped, first, n + 1) - 1, collided=stopped & hit, checks=checks, configs=qs)


@dataclass
class FlatMotions:
    """A batch of motions ``(...)`` laid out as the compiled checks read them: ``lead``
    (the batch shape), ``q0 (M, c)``, ``twist (M, t)``, ``n (M,)`` (at least 1),
    ``fallback (M,)``, bounds ``low, high (M, d)`` (bounds that stop nothing when none are
    given), and the arrays the kernel fills: every sample ``configs (M, J, c)`` and ``out
    (M, 3)`` (certified sub-steps, collided, checks)."""

    lead: tuple[int, ...]
    q0: Array
    twist: Array
    n: Int
    fallback: Bool
    low: Array
    high: Array
    configs: Array
    out: Int

    @classmethod
    def of(
        cls,
        q0: Array,
        twist: Array,
        n: Int,
        low: Array | None,
        high: Array | None,
        fallback: Bool | None,
        dim: int,
        twist_dim: int,
    ) -> FlatMotions:
        # contiguous and writable: a view that broadcasts nothing is read-only, and numba
        # compiles its kernels once more for read-only arrays (a type of their own)
        def f(a: np.ndarray) -> Any:
            return np.require(a, requirements=("C", "W"))

        q0 = np.asarray(q0, np.float64)
        lead, c = q0.shape[:-1], q0.shape[-1]
        m = int(np.prod(lead, dtype=np.int64))
        nf = f(np.maximum(np.broadcast_to(np.asarray(n, np.int64), lead), 1).reshape(m))
        if low is None or high is None:  # bounds that stop nothing
            low, high = np.full(dim, -1e300), np.full(dim, 1e300)
        return cls(
            lead,
            f(q0.reshape(m, c)),
            f(np.broadcast_to(np.asarray(twist, np.float64), lead + (twist_dim,)).reshape(m, twist_dim)),
            nf,
            np.ones(m, bool) if fallback is None else f(np.broadcast_to(fallback, lead).reshape(m)),
            f(np.broadcast_to(np.asarray(low, np.float64), lead + (dim,)).reshape(m, dim)),
            f(np.broadcast_to(np.asarray(high, np.float64), lead + (dim,)).reshape(m, dim)),
            np.empty((m, int(nf.max()) + 1 if m else 2, c)),
            np.empty((m, 3), np.int64),
        )

    def result(self) -> MotionCheck:
        """The :class:`MotionCheck` of the filled arrays, in the batch's shape."""
        out, lead = self.out, self.lead
        return MotionCheck(
            free=out[:, 0].reshape(lead),
            collided=out[:, 1].astype(bool).reshape(lead),
            checks=out[:, 2].reshape(lead),
            configs=self.configs.reshape(lead + self.configs.shape[1:]),
        )


def segments_free(
    robot: Robot,
    world: CollisionWorld,
    a: Array,
    b: Array,
    resolution: float,
    low: Array | None = None,
    high: Array | None = None,
) -> tuple[Bool, Int]:
    """Are the geodesics ``a[e] -> b[e]`` (``(E, config_dim)`` each) certified free (and
    inside the bounds)? Each is sampled in ``intervals(length, resolution)`` sub-steps.
    Returns ``(E,)`` booleans and the configurations checked per segment."""
    a = np.asarray(a, np.float64)
    v = robot.log(a, np.asarray(b, np.float64))
    m = intervals(np.linalg.norm(v, axis=-1), resolution)
    chk = robot.check_motions(world, a, v, m, low, high)  # the robot's own (compiled where it has one)
    return chk.free == m, chk.checks
