"""Property-based round trips (hypothesis), on strategies that seek trouble."""

import numpy as np
import pytest
from helpers import (
    SEQS,
    angle_diff,
    assert_close,
    assert_same_rotation,
    euler_angles,
    lock_middles,
    unit_quaternions,
)
from hypothesis import given, settings
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


@given(unit_quaternions(), st.sampled_from(SEQS))
@settings(max_examples=120)
def test_quaternion_euler_backward_error(q, seq):
    a = rj.quaternion_to_euler(q, seq)
    assert_close(rj.euler_to_matrix(a, seq), rj.quaternion_to_matrix(q), atol=6 * EPS)


@given(st.data(), st.sampled_from(SEQS))
@settings(max_examples=120)
def test_euler_round_trip_generic_and_near_lock(data, seq):
    a = data.draw(euler_angles(seq))
    R = rj.euler_to_matrix(a, seq)
    back = np.asarray(rj.matrix_to_euler(R, seq))
    assert_close(rj.euler_to_matrix(back, seq), R, atol=6 * EPS)
    dist = min(abs(a[1] - m) for m in lock_middles(seq))
    if dist > 1e-3:  # away from lock the angles themselves come back (mod 2 pi)
        assert_close(angle_diff(back, a), 0, atol=1e-11)


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
