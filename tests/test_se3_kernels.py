"""The compiled S-shape integrate / log (quaternion kernels) against the numpy reference
(4x4 matrices through ``lie``): random batches, angles near 0 and near pi, unnormalised
quaternions, the broadcasting patterns of the callers, exp/log round trips."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pointplan.geometry import lie
from pointplan.robots import SShape
from pointplan.robots.sshape import NumpySShape

TOL = 1e-10
ROBOT = SShape()
seeds = st.integers(0, 2**32 - 1)


# ============================================================================ helpers
def reference_integrate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    return SShape._integrate_numpy(q, v)


def reference_log(q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    return SShape._log_numpy(q0, q1)


def random_poses(rng: np.random.Generator, n: int) -> np.ndarray:
    """Positions in [-2, 2]^3 and quaternions of norms in [0.1, 10], either sign."""
    quat = rng.normal(size=(n, 4))
    quat *= rng.uniform(0.1, 10.0, (n, 1)) / np.linalg.norm(quat, axis=1, keepdims=True)
    return np.concatenate([rng.uniform(-2, 2, (n, 3)), quat], -1)


def twists_with_angles(rng: np.random.Generator, angles: np.ndarray) -> np.ndarray:
    """Random translations and rotation vectors of the given norms."""
    w = rng.normal(size=(len(angles), 3))
    w *= (angles / np.linalg.norm(w, axis=1))[:, None]
    return np.concatenate([rng.normal(size=(len(angles), 3)), w], -1)


def mixed_angles(rng: np.random.Generator, n: int, top: float = np.pi) -> np.ndarray:
    """Angles spread over the interesting ranges: 0, tiny, Taylor thresholds, generic, near pi."""
    pool = np.array([0.0, 1e-12, 1e-9, 1e-6, 9e-5, 1e-4, 1.1e-4, 5e-3, 1e-2, 1.1e-2, np.pi - 1e-3, np.pi - 1e-6])
    angles = rng.uniform(0.0, top, n)
    pick = rng.random(n) < 0.4
    angles[pick] = rng.choice(pool, pick.sum())
    return angles


def same_pose(a: np.ndarray, b: np.ndarray, atol: float = TOL) -> bool:
    """Equal positions and equal rotations (quaternions up to sign)."""
    qa = a[..., 3:] / np.linalg.norm(a[..., 3:], axis=-1, keepdims=True)
    qb = b[..., 3:] / np.linalg.norm(b[..., 3:], axis=-1, keepdims=True)
    dot = np.abs(np.sum(qa * qb, -1))
    return bool(np.allclose(a[..., :3], b[..., :3], atol=atol) and np.all(dot > 1 - atol))


def assert_integrate_matches(q: np.ndarray, v: np.ndarray) -> None:
    got = ROBOT.integrate(q, v)
    want = reference_integrate(q, v)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=0, atol=TOL)
    assert np.all(got[..., 6] >= 0)
    np.testing.assert_allclose(np.linalg.norm(got[..., 3:], axis=-1), 1.0, atol=1e-14)


def assert_log_matches(q0: np.ndarray, q1: np.ndarray) -> None:
    got = ROBOT.log(q0, q1)
    want = reference_log(q0, q1)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=0, atol=TOL)


# ============================================================================ random batches
@settings(max_examples=30, deadline=None)
@given(seeds, st.integers(1, 64))
def test_integrate_matches_reference(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    q = random_poses(rng, n)
    # rotation increments beyond pi too: exp is defined for any angle
    assert_integrate_matches(q, twists_with_angles(rng, mixed_angles(rng, n, top=3 * np.pi)))


@settings(max_examples=30, deadline=None)
@given(seeds, st.integers(1, 64))
def test_log_matches_reference(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    q0 = random_poses(rng, n)
    # q1 at a chosen relative angle (below pi: at exactly pi the axis sign is a tie)...
    q1 = reference_integrate(q0, twists_with_angles(rng, mixed_angles(rng, n)))
    q1[:, 3:] *= rng.choice([-1.0, 1.0], (n, 1)) * rng.uniform(0.1, 10.0, (n, 1))
    assert_log_matches(q0, q1)
    # ... and unrelated poses
    assert_log_matches(q0, random_poses(rng, n))


@settings(max_examples=20, deadline=None)
@given(seeds)
def test_exp_log_round_trip(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 32
    q0, q1 = random_poses(rng, n), random_poses(rng, n)
    assert same_pose(ROBOT.integrate(q0, ROBOT.log(q0, q1)), q1)
    # log(q, q exp(v)) = v for rotation angles below pi
    v = twists_with_angles(rng, mixed_angles(rng, n, top=np.pi - 1e-3))
    np.testing.assert_allclose(ROBOT.log(q0, ROBOT.integrate(q0, v)), v, rtol=0, atol=TOL)
    # geodesic interpolation stays on the way: halfway twice is the whole way
    half = ROBOT.integrate(q0, 0.5 * ROBOT.log(q0, q1))
    assert same_pose(ROBOT.integrate(half, ROBOT.log(half, q1)), q1)


# ============================================================================ edge cases
def test_identity_and_zero_twist() -> None:
    ident = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    np.testing.assert_array_equal(ROBOT.integrate(ident, np.zeros(6)), ident)
    np.testing.assert_array_equal(ROBOT.log(ident, ident), np.zeros(6))
    q = np.array([0.3, -1.0, 2.0, 0.1, -0.7, 0.2, -0.4])  # w < 0, unnormalised
    np.testing.assert_allclose(ROBOT.log(q, q), np.zeros(6), atol=1e-15)
    assert_integrate_matches(q, np.zeros(6))
    np.testing.assert_allclose(ROBOT.integrate(q, np.zeros(6))[3:], -q[3:] / np.linalg.norm(q[3:]), atol=1e-15)


@pytest.mark.parametrize("angle", [1e-12, 1e-9, 1e-7, 1e-4, 1e-2])
def test_tiny_rotations(angle: float) -> None:
    rng = np.random.default_rng(7)
    q = random_poses(rng, 50)
    v = twists_with_angles(rng, np.full(50, angle))
    assert_integrate_matches(q, v)
    q1 = reference_integrate(q, v)
    assert_log_matches(q, q1)
    np.testing.assert_allclose(ROBOT.log(q, q1), v, rtol=0, atol=TOL)


def test_near_half_turn() -> None:
    rng = np.random.default_rng(8)
    q = random_poses(rng, 200)
    for angle in (np.pi - 1e-3, np.pi - 1e-6, np.pi - 1e-9):
        v = twists_with_angles(rng, np.full(200, angle))
        assert_integrate_matches(q, v)
        q1 = reference_integrate(q, v)
        assert_log_matches(q, q1)


def test_exact_half_turn() -> None:
    """At exactly pi, ``w`` and ``-w`` are both logs: when the arithmetic gives an exact
    0 both paths make the largest axis component positive; otherwise round-off picks the
    sign (in either path), and the answers agree as poses."""
    ident = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    p = np.array([0.4, -0.2, 0.7])
    for axis in np.eye(3):
        for sign in (1.0, -1.0):
            # exact half turns about the axes, in both quaternion signs, in integrate and log
            q1 = np.concatenate([p, sign * axis, [0.0]])
            assert_log_matches(ident, q1)
            np.testing.assert_allclose(ROBOT.log(ident, q1)[3:], np.pi * axis, atol=1e-15)
            assert_integrate_matches(q1, np.zeros(6))
            assert_integrate_matches(ident, np.concatenate([p, sign * np.pi * axis]))
    # general axes: the same pose, an angle of pi, and a twist equal up to the axis sign
    rng = np.random.default_rng(9)
    q0 = random_poses(rng, 300)
    q1 = reference_integrate(q0, twists_with_angles(rng, np.full(300, np.pi)))
    got, want = ROBOT.log(q0, q1), reference_log(q0, q1)
    np.testing.assert_allclose(np.linalg.norm(got[:, 3:], axis=1), np.pi, atol=TOL)
    np.testing.assert_allclose(np.abs(got[:, 3:]), np.abs(want[:, 3:]), atol=TOL)
    assert same_pose(ROBOT.integrate(q0, got), q1)
    assert same_pose(reference_integrate(q0, got), reference_integrate(q0, want))


def test_unnormalised_quaternions() -> None:
    rng = np.random.default_rng(10)
    q = random_poses(rng, 100)
    for scale in (1e-6, 1e-3, 1e3, 1e6):
        qs = q.copy()
        qs[:, 3:] *= scale
        v = twists_with_angles(rng, mixed_angles(rng, 100))
        assert_integrate_matches(qs, v)
        assert_log_matches(qs, q[::-1] * np.array([1, 1, 1, scale, scale, scale, -scale]))


# ============================================================================ shapes
@pytest.mark.parametrize(
    ("q_shape", "v_shape"),
    [
        ((7,), (6,)),  # one pose, one twist
        ((7,), (5, 6)),  # interpolate / geodesic from one start
        ((1, 7), (5, 6)),  # march: q0[None] against the steps
        ((5, 7), (5, 6)),  # edge configurations
        ((4, 1, 7), (4, 3, 6)),  # env: each pose against its steps
        ((4, 3, 7), (4, 3, 6)),
        ((2, 4, 3, 7), (3, 6)),
        ((0, 7), (0, 6)),
        ((0, 7), (6,)),
    ],
)
def test_integrate_broadcasting(q_shape: tuple[int, ...], v_shape: tuple[int, ...]) -> None:
    rng = np.random.default_rng(11)
    q = random_poses(rng, int(np.prod(q_shape[:-1]))).reshape(q_shape)
    v = rng.normal(size=v_shape)
    assert_integrate_matches(q, v)
    # a broadcast (stride 0) view and plain lists work too
    n = 3
    view = np.broadcast_to(q.reshape(-1, 7)[:1], (n, 7)) if q.size else np.zeros((0, 7))
    assert_integrate_matches(view, rng.normal(size=(len(view), 6)))
    if q.size and v.size:  # (empty lists lose their shape)
        np.testing.assert_allclose(ROBOT.integrate(q.tolist(), v.tolist()), ROBOT.integrate(q, v), atol=0)


@pytest.mark.parametrize(
    ("a_shape", "b_shape"),
    [
        ((7,), (7,)),
        ((6, 7), (1, 7)),  # nearest node: all nodes against q[None]
        ((1, 7), (6, 7)),
        ((6, 7), (6, 7)),  # path segments
        ((7,), (6, 7)),
        ((3, 1, 7), (3, 4, 7)),
        ((0, 7), (1, 7)),
    ],
)
def test_log_broadcasting(a_shape: tuple[int, ...], b_shape: tuple[int, ...]) -> None:
    rng = np.random.default_rng(12)
    a = random_poses(rng, int(np.prod(a_shape[:-1]))).reshape(a_shape)
    b = random_poses(rng, int(np.prod(b_shape[:-1]))).reshape(b_shape)
    assert_log_matches(a, b)


def test_derived_operations_match() -> None:
    """distance / interpolate / goal_vector (built on log and integrate) agree with numpy."""
    rng = np.random.default_rng(13)
    q0, q1 = random_poses(rng, 20), random_poses(rng, 20)
    s = np.linspace(0.0, 1.0, 20)
    got = (ROBOT.distance(q0, q1), ROBOT.interpolate(q0, q1, s), ROBOT.interpolate(q0[0], q1[0], s))
    ref = NumpySShape()
    want = (ref.distance(q0, q1), ref.interpolate(q0, q1, s), ref.interpolate(q0[0], q1[0], s))
    for g, w in zip(got, want):
        np.testing.assert_allclose(g, w, rtol=0, atol=TOL)


def test_bad_shapes_raise() -> None:
    with pytest.raises(ValueError):
        ROBOT.integrate(np.zeros(6), np.zeros(6))
    with pytest.raises(ValueError):
        ROBOT.log(np.zeros((3, 7)), np.zeros((3, 6)))
    with pytest.raises(ValueError):
        ROBOT.log(np.zeros((3, 7)), np.zeros((2, 7)))


def test_reference_is_lie() -> None:
    """The reference really is the matrix computation (guards the helpers above)."""
    rng = np.random.default_rng(14)
    q, v = random_poses(rng, 5), rng.normal(size=(5, 6))
    t = SShape.to_matrix(q) @ lie.se3_exp(v)
    np.testing.assert_allclose(SShape.to_matrix(reference_integrate(q, v)), t, atol=1e-14)
