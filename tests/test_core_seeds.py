"""The seeds' worked examples and formulas, reproduced numerically (never transcribed)."""

import numpy as np
import pytest
from helpers import assert_close, assert_same_rotation, is_proper, random_quaternions

import rotjax as rj
from rotjax._demo import KAMMAN_AXIS, KAMMAN_DCM_350, KAMMAN_DCM_M250

# Kamman/Baruh printed values (6 digits), eps4 = scalar part. Example 2's eps3 is printed as
# +0.702130 in part (a); 6/7 sin(-125 deg) = -0.702130, so the printed sign is an error of the
# seed (part (c) agrees with the negative value).
KAMMAN = [
    (KAMMAN_DCM_350, 350.0, [0.024902, -0.037352, 0.074705, -0.996195], 10.0),
    (KAMMAN_DCM_M250, -250.0, [-0.234043, 0.351065, -0.702130, -0.573576], 110.0),
]


@pytest.mark.parametrize("dcm,deg,eps_printed,angle", KAMMAN, ids=["350deg", "-250deg"])
def test_kamman_examples(dcm, deg, eps_printed, angle):
    q_true = rj.axis_angle_to_quaternion(KAMMAN_AXIS, deg, degrees=True)
    # (a) the Euler parameters of the rotation, as printed
    assert_close(q_true, eps_printed, atol=1e-6)
    # (b) the printed direction-cosine matrix is the passive one: R_active.T
    assert_close(rj.quaternion_to_matrix(q_true).T, dcm, atol=1.5e-6)
    # (c) extraction from the printed DCM gives the negatives of (a), here with w >= 0
    q = rj.matrix_to_quaternion(dcm.T)
    assert float(q[3]) >= 0
    assert_close(q, -np.asarray(eps_printed), atol=2e-6)
    # (d) the angle of rotation, 10 and 110 degrees, and the axis up to sign
    axis, ang = rj.quaternion_to_axis_angle(q, degrees=True)
    assert_close(ang, angle, atol=2e-4)
    assert_close(np.abs(axis), np.abs(KAMMAN_AXIS), atol=2e-6)


def _nikravesh_A1(psi, theta, sigma):
    """Eq. A.1 (z-x-z Euler angles, A = D C B), checked against the product D C B below."""
    c, s = np.cos, np.sin
    return np.array(
        [
            [c(psi) * c(sigma) - s(psi) * c(theta) * s(sigma),
             -c(psi) * s(sigma) - s(psi) * c(theta) * c(sigma), s(psi) * s(theta)],
            [s(psi) * c(sigma) + c(psi) * c(theta) * s(sigma),
             -s(psi) * s(sigma) + c(psi) * c(theta) * c(sigma), -c(psi) * s(theta)],
            [s(theta) * s(sigma), s(theta) * c(sigma), c(theta)],
        ]
    )  # fmt: skip


def _nikravesh_A5(p1, p2, p3):
    """Eq. A.5 (Bryant angles x-y-z)."""
    c, s = np.cos, np.sin
    return np.array(
        [
            [c(p2) * c(p3), -c(p2) * s(p3), s(p2)],
            [c(p1) * s(p3) + s(p1) * s(p2) * c(p3), c(p1) * c(p3) - s(p1) * s(p2) * s(p3),
             -s(p1) * c(p2)],
            [s(p1) * s(p3) - c(p1) * s(p2) * c(p3), s(p1) * c(p3) + c(p1) * s(p2) * s(p3),
             c(p1) * c(p2)],
        ]
    )  # fmt: skip


def _rz(a):
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])


def _rx(a):
    return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])


def _ry(a):
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


ANGLES = np.random.default_rng(3).uniform([-3, 0.1, -3], [3, 3.0, 3], size=(20, 3))


@pytest.mark.parametrize("seq", ["ZXZ", "313"])
def test_nikravesh_A1_euler_matrix(seq):
    for psi, theta, sigma in ANGLES:
        dcb = _rz(psi) @ _rx(theta) @ _rz(sigma)
        assert_close(_nikravesh_A1(psi, theta, sigma), dcb, atol=1e-15)
        assert_close(rj.euler_to_matrix(np.array([psi, theta, sigma]), seq), dcb, atol=1e-15)


@pytest.mark.parametrize("seq", ["XYZ", "123"])
def test_nikravesh_A5_bryant_matrix(seq):
    for p1, p2, p3 in ANGLES - [0, 1.5, 0]:
        dcb = _rx(p1) @ _ry(p2) @ _rz(p3)
        assert_close(_nikravesh_A5(p1, p2, p3), dcb, atol=1e-15)
        assert_close(rj.euler_to_matrix(np.array([p1, p2, p3]), seq), dcb, atol=1e-15)


def test_nikravesh_A2_matrix_to_euler_angles():
    """Eq. A.2 with sin(theta) > 0: theta = acos a33, psi = atan2(a13, -a23),
    sigma = atan2(a31, a32)."""
    for psi, theta, sigma in ANGLES:
        A = _nikravesh_A1(psi, theta, sigma)
        expected = [np.arctan2(A[0, 2], -A[1, 2]), np.arccos(A[2, 2]), np.arctan2(A[2, 0], A[2, 1])]
        assert_close(rj.matrix_to_euler(A, "ZXZ"), expected, atol=1e-12)


def test_nikravesh_A6_bryant_angles():
    """Eq. A.6 with cos(phi2) > 0: phi2 = asin a13, phi1 = atan2(-a23, a33),
    phi3 = atan2(-a12, a11)."""
    for p1, p2, p3 in ANGLES - [0, 1.5, 0]:
        A = _nikravesh_A5(p1, p2, p3)
        expected = [
            np.arctan2(-A[1, 2], A[2, 2]),
            np.arcsin(A[0, 2]),
            np.arctan2(-A[0, 1], A[0, 0]),
        ]
        assert_close(rj.matrix_to_euler(A, "XYZ"), expected, atol=1e-12)


def test_nikravesh_B1_B7_euler_parameters():
    """B.1-B.4 give (e0, e1, e2, e3) of z-x-z angles (e0 scalar); B.5-B.7 invert them."""
    for psi, theta, sigma in ANGLES:
        e0 = np.cos(theta / 2) * np.cos((psi + sigma) / 2)  # B.1
        e1 = np.sin(theta / 2) * np.cos((psi - sigma) / 2)  # B.2
        e2 = np.sin(theta / 2) * np.sin((psi - sigma) / 2)  # B.3
        e3 = np.cos(theta / 2) * np.sin((psi + sigma) / 2)  # B.4
        q = rj.euler_to_quaternion(np.array([psi, theta, sigma]), "ZXZ", scalar_first=True)
        assert_same_rotation(q, [e0, e1, e2, e3], atol=1e-15)
        # B.5-B.7, read off the matrix in terms of the parameters
        assert_close(np.cos(theta), 2 * (e0**2 + e3**2) - 1, atol=1e-15)  # B.5
        assert_close(np.cos(sigma), 2 * (e2 * e3 + e0 * e1) / np.sin(theta), atol=1e-12)  # B.6
        assert_close(np.cos(psi), -2 * (e2 * e3 - e0 * e1) / np.sin(theta), atol=1e-12)  # B.7
        ang = rj.quaternion_to_euler(np.array([e0, e1, e2, e3]), "313", scalar_first=True)
        assert_close(ang, [psi, theta, sigma], atol=1e-14)


def test_nikravesh_B11_lock():
    """At theta = 0 only psi + sigma is defined: sin(psi + sigma) = 2 e0 e3 (B.11)."""
    for total in np.linspace(-3, 3, 7):
        e0, e3 = np.cos(total / 2), np.sin(total / 2)
        ang = np.asarray(rj.quaternion_to_euler(np.array([e0, 0, 0, e3]), "ZXZ", scalar_first=True))
        assert ang[1] == 0 and ang[2] == 0
        assert_close(np.sin(ang[0] + ang[2]), 2 * e0 * e3, atol=1e-15)


SEQ_SAMPLE = ["XYZ", "ZYX", "ZXZ", "XZX", "xyz", "zyz", "yxz", "YXY"]


@pytest.mark.parametrize("seq", SEQ_SAMPLE)
def test_maplesim_alternate_solution_set(seq):
    """MapleSim's 'alternate solutions' (theta1 +- pi, theta2 +- pi, theta3 +- pi for
    Tait-Bryan) describe a *different* rotation; the true second set is
    (a + pi, pi - b, c + pi) for Tait-Bryan and (a + pi, -b, c + pi) for proper sequences."""
    q = random_quaternions(50, seed=11)
    a, b, c = np.moveaxis(np.asarray(rj.quaternion_to_euler(q, seq)), -1, 0)
    second = np.stack([a + np.pi, -b if is_proper(seq) else np.pi - b, c + np.pi], axis=-1)
    assert_close(rj.euler_to_matrix(second, seq), rj.quaternion_to_matrix(q), atol=2e-15)
    if not is_proper(seq):
        literal = np.stack([a + np.pi, b + np.pi, c + np.pi], axis=-1)  # as worded by the seed
        err = np.abs(np.asarray(rj.euler_to_matrix(literal, seq) - rj.quaternion_to_matrix(q)))
        assert err.max() > 0.5


def test_maplesim_relative_rotation():
    """The relative-angles sensor decomposes R_rel = R_a^T R_b (rotation from a to b)."""
    qa, qb = random_quaternions(2, seed=5)
    rel = rj.relative_rotation(qa, qb)
    Ra, Rb = rj.quaternion_to_matrix(qa), rj.quaternion_to_matrix(qb)
    assert_close(rj.quaternion_to_matrix(rel), Ra.T @ Rb, atol=1e-15)
    assert_close(
        rj.quaternion_to_euler(rel, "123"), rj.matrix_to_euler(Ra.T @ Rb, "123"), atol=1e-14
    )
