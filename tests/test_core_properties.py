"""Property-based round trips (hypothesis), on strategies that seek trouble."""

import jax
import numpy as np
import pytest
from helpers import (
    SEQS,
    angle_diff,
    assert_close,
    assert_same_rotation,
    is_proper,
    lock_middles,
    unit_quaternions,
)
from hypothesis import given
from hypothesis import strategies as st

import rotjax as rj

EPS = np.finfo(np.float64).eps


@given(unit_quaternions())
def test_quaternion_matrix_round_trip(q):
    R = rj.quaternion_to_matrix(q)
    assert_same_rotation(rj.matrix_to_quaternion(R), q, atol=4 * EPS)
    # R itself is within 3 ulp per entry (mpmath tests); the product adds up to ~3 more roundings
    assert_close(np.asarray(R) @ np.asarray(R).T, np.eye(3), atol=8 * EPS)
    assert float(rj.matrix_to_quaternion(R)[3]) >= 0


@given(unit_quaternions())
def test_quaternion_rotvec_round_trip(q):
    v = rj.quaternion_to_rotvec(q)
    assert float(np.linalg.norm(v)) <= np.pi + 4 * EPS
    assert_same_rotation(rj.rotvec_to_quaternion(v), q, atol=8 * EPS)
    assert_close(rj.rotvec_to_matrix(v), rj.quaternion_to_matrix(q), atol=8 * EPS)


# Every sequence (conftest.py marks those outside helpers.FAST_SEQS slow), each on one batch:
# one compiled program per function and sequence, rather than one draw per example.
quaternion_to_euler = jax.jit(rj.quaternion_to_euler, static_argnums=1)
euler_to_matrix = jax.jit(rj.euler_to_matrix, static_argnums=1)
matrix_to_euler = jax.jit(rj.matrix_to_euler, static_argnums=1)


def _trouble_quaternions(n, seed):
    """Unit quaternions as ``unit_quaternions`` draws them: generic, near the identity (vector
    part 1e-7) and near 180 degrees (scalar part 1e-7), and the identity and half turns."""
    rng = np.random.default_rng(seed)
    v = rng.uniform(-1, 1, size=(n, 4))
    kind = np.arange(n) % 3
    v[kind == 1, :3] *= 1e-7
    v[kind == 1, 3] = 1.0
    v[kind == 2, 3] *= 1e-7
    v[:4] = [[0, 0, 0, 1.0], [1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0]]
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _trouble_angles(seq, n, seed):
    """Angles as ``euler_angles`` draws them: generic, or the middle angle within 1e-6 of
    either lock value (exactly at it for some); first and third angles over [-pi, pi]."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(-np.pi, np.pi, size=(n, 3))
    lo, hi = (0.0, np.pi) if is_proper(seq) else (-np.pi / 2, np.pi / 2)
    a[:, 1] = rng.uniform(lo, hi, size=n)
    near = np.arange(n) % 2 == 1
    offset = rng.uniform(-1e-6, 1e-6, size=n) * (np.arange(n) % 4 != 1)  # some exactly at lock
    a[near, 1] = np.array(lock_middles(seq))[rng.integers(2, size=n)][near] + offset[near]
    a[:2, 0], a[:2, 2] = np.pi, -np.pi
    return a


@pytest.mark.parametrize("seq", SEQS)
def test_quaternion_euler_backward_error(seq):
    q = _trouble_quaternions(120, seed=1)
    a = quaternion_to_euler(q, seq)
    assert_close(euler_to_matrix(a, seq), rj.quaternion_to_matrix(q), atol=6 * EPS)


@pytest.mark.parametrize("seq", SEQS)
def test_euler_round_trip_generic_and_near_lock(seq):
    a = _trouble_angles(seq, 120, seed=2)
    R = euler_to_matrix(a, seq)
    back = np.asarray(matrix_to_euler(R, seq))
    assert_close(euler_to_matrix(back, seq), R, atol=6 * EPS)
    dist = np.min(np.abs(a[:, 1:2] - np.array(lock_middles(seq))), axis=-1)
    far = dist > 1e-3  # away from lock the angles themselves come back (mod 2 pi)
    assert far.sum() > 20
    assert_close(angle_diff(back[far], a[far]), 0, atol=1e-11)


@pytest.mark.parametrize("seq", ["XYZ", "zxz"])
@given(q=unit_quaternions(), scale=st.floats(1e-100, 1e100))
def test_scale_invariance(seq, q, scale):
    a_scaled = rj.quaternion_to_euler(scale * q, seq)
    a = rj.quaternion_to_euler(q, seq)
    # the same rotation to a few ulp; the angles themselves agree except within rounding of
    # gimbal lock, where scaling can make the lock exact (then the third angle becomes 0)
    assert_close(rj.euler_to_matrix(a_scaled, seq), rj.quaternion_to_matrix(q), atol=6 * EPS)
    if float(rj.euler_singularity(a, seq)) > 1e-6:
        assert_close(angle_diff(a_scaled, a), 0, atol=1e-13)  # -pi and pi are the same angle
    # two computed matrices, each within ~3 ulp of exact
    assert_close(rj.quaternion_to_matrix(scale * q), rj.quaternion_to_matrix(q), atol=6 * EPS)


@given(unit_quaternions(), unit_quaternions())
def test_composition_and_angle(p, q):
    pq = rj.quaternion_multiply(p, q)
    assert_close(
        rj.quaternion_to_matrix(pq),
        np.asarray(rj.quaternion_to_matrix(p)) @ np.asarray(rj.quaternion_to_matrix(q)),
        atol=8 * EPS,
    )
    ang = float(rj.angle_between(p, q))
    assert 0 <= ang <= np.pi
    assert_close(ang, float(rj.angle_between(q, p)), atol=8 * EPS)
    assert_close(ang, float(rj.angle_between(-p, q)), atol=0)
