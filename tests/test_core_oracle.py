"""Agreement with scipy (all 24 sequences) and accuracy in ulp against mpmath references."""

import itertools

import numpy as np
import pytest
from helpers import (
    DIGIT_SEQS,
    DTYPES,
    SEQS,
    angle_diff,
    assert_close,
    assert_same_rotation,
    is_proper,
    lock_middles,
    mp_euler_to_matrix,
    mp_matrix_to_quaternion,
    mp_max_diff,
    mp_quat_to_matrix,
    padded_call,
    random_quaternions,
)
from scipy.spatial.transform import Rotation

import rotjax as rj

EPS64 = np.finfo(np.float64).eps


def _normalise(q):
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def adversarial_sets(n=40, seed=0):
    """Unit quaternions that seek trouble: uniform, near the identity, near 180 degrees,
    exactly 180 degrees, and largest-component ties."""
    rng = np.random.default_rng(seed)
    near_id = _normalise(np.concatenate([1e-7 * rng.normal(size=(n, 3)), np.ones((n, 1))], 1))
    near_180 = _normalise(
        np.concatenate([rng.normal(size=(n, 3)), 1e-7 * rng.normal(size=(n, 1))], 1)
    )
    exact_180 = _normalise(np.concatenate([rng.normal(size=(n, 3)), np.zeros((n, 1))], 1))
    ties = np.array(list(itertools.product([0.5, -0.5], repeat=4)))  # all components equal
    ties2 = _normalise(np.array([[1, 1, 0, 0], [0, 1, 1, 0], [1, 0, 0, 1], [0, 1, 0, -1.0]]))
    return {
        "uniform": random_quaternions(n, seed),
        "near_identity": near_id,
        "near_180": near_180,
        "exact_180": exact_180,
        "ties": np.concatenate([ties, ties2]),
    }


SETS = adversarial_sets()


def near_lock_angles(seq, offset, n=30, seed=1):
    rng = np.random.default_rng(seed)
    outer = rng.uniform(-np.pi, np.pi, size=(n, 2))
    lo, hi = lock_middles(seq)
    mid = np.where(np.arange(n) % 2 == 0, lo, hi) + offset * rng.choice([-1, 1], size=n)
    if is_proper(seq):
        mid = np.abs(mid)  # stay in [0, pi] near 0; (pi + offset) is fine as well
    return np.stack([outer[:, 0], mid, outer[:, 1]], axis=-1)


# --- scipy as oracle -------------------------------------------------------------------------


@pytest.mark.parametrize("set_name", sorted(SETS))
def test_matrix_to_quaternion_matches_scipy(set_name):
    q = SETS[set_name]
    R = Rotation.from_quat(q).as_matrix()
    expected = Rotation.from_matrix(R).as_quat(canonical=False)
    ours = padded_call(rj.matrix_to_quaternion, R)
    assert np.all(ours[..., 3] >= 0)
    assert_same_rotation(ours, expected, atol=4 * EPS64)
    assert_close(padded_call(rj.quaternion_to_matrix, q), R, atol=4 * EPS64)


@pytest.mark.parametrize("seq", SEQS)
def test_euler_matches_scipy_generic(seq):
    q = random_quaternions(300, seed=2)
    angles = padded_call(rj.quaternion_to_euler, q, seq)
    expected = Rotation.from_quat(q).as_euler(seq)
    assert_close(angle_diff(angles, expected), 0, atol=1e-13)
    assert_close(
        padded_call(rj.matrix_to_euler, Rotation.from_quat(q).as_matrix(), seq), angles, atol=1e-13
    )
    # two float64 implementations, each within a few ulp of exact (see the mpmath tests)
    R_expected = Rotation.from_euler(seq, expected).as_matrix()
    assert_close(padded_call(rj.euler_to_matrix, expected, seq), R_expected, atol=10 * EPS64)
    assert_same_rotation(
        padded_call(rj.euler_to_quaternion, expected, seq),
        Rotation.from_euler(seq, expected).as_quat(),
        atol=4 * EPS64,
    )


@pytest.mark.parametrize("seq", SEQS)
def test_euler_ranges(seq):
    q = np.concatenate([random_quaternions(300, seed=4), *SETS.values()])
    a = padded_call(rj.quaternion_to_euler, q, seq)
    assert np.all(np.abs(a[:, [0, 2]]) <= np.pi)
    if is_proper(seq):
        assert np.all((a[:, 1] >= 0) & (a[:, 1] <= np.pi))
    else:
        assert np.all(np.abs(a[:, 1]) <= np.pi / 2)


@pytest.mark.parametrize("seq", DIGIT_SEQS)
def test_digit_sequences_are_intrinsic(seq):
    letters = "".join("XYZ"[int(c) - 1] for c in seq)
    q = random_quaternions(20, seed=7)
    assert_close(
        padded_call(rj.quaternion_to_euler, q, seq),
        padded_call(rj.quaternion_to_euler, q, letters),
        atol=0,
    )
    a = padded_call(rj.quaternion_to_euler, q, seq)
    assert_close(
        padded_call(rj.euler_to_matrix, a, seq),
        Rotation.from_euler(letters, a).as_matrix(),
        atol=1e-15,
    )


EXACT_GRID = np.array(
    [q for q in itertools.product([-1, -0.5, 0, 0.5, 1], repeat=4) if any(q)], float
)


@pytest.mark.parametrize("seq", SEQS)
def test_exact_lock_grid_matches_scipy(seq):
    """624 quaternions with exact components, many of them exactly at gimbal lock: the angles
    equal scipy's (third angle 0 at lock) and reproduce the rotation."""
    a = padded_call(rj.quaternion_to_euler, EXACT_GRID, seq)
    assert_close(angle_diff(a, Rotation.from_quat(EXACT_GRID).as_euler(seq)), 0, atol=1e-15)
    assert_close(
        padded_call(rj.euler_to_matrix, a, seq),
        Rotation.from_quat(EXACT_GRID).as_matrix(),
        atol=1e-15,
    )


@pytest.mark.parametrize("offset", [0.0, 1e-12, 1e-9])
@pytest.mark.parametrize("seq", SEQS)
def test_near_lock_round_trip_to_few_ulp(seq, offset):
    """Within 1e-9 of gimbal lock (and at it) the returned angles reproduce the matrix to a few
    ulp, where scipy's 1e-7 threshold moves the rotation by up to ~1e9 eps."""
    R = padded_call(rj.euler_to_matrix, near_lock_angles(seq, offset), seq)
    back = padded_call(rj.euler_to_matrix, padded_call(rj.matrix_to_euler, R, seq), seq)
    err = np.abs(back - R).max()
    assert err <= 6 * EPS64, f"{err / EPS64:.1f} eps"
    if offset == 1e-9:  # the threshold costs scipy far more (this documents the comparison)
        scipy_back = Rotation.from_euler(seq, Rotation.from_matrix(R).as_euler(seq)).as_matrix()
        assert np.abs(scipy_back - R).max() > 1e5 * err


# --- accuracy in ulp against mpmath ----------------------------------------------------------

ACC_SETS = {k: v[:12] for k, v in SETS.items()}


@pytest.mark.parametrize("dtype", DTYPES, ids=lambda d: d.__name__)
@pytest.mark.parametrize("set_name", sorted(ACC_SETS))
def test_quaternion_matrix_accuracy_ulp(set_name, dtype):
    """quaternion_to_matrix within 3 ulp and matrix_to_quaternion within 2 ulp (componentwise)
    of the exact-arithmetic values, in float32 and float64."""
    eps = np.finfo(dtype).eps
    q = ACC_SETS[set_name].astype(dtype)
    R = padded_call(rj.quaternion_to_matrix, q)
    assert R.dtype == dtype
    err_m = max(mp_max_diff(R[i].tolist(), mp_quat_to_matrix(q[i])) for i in range(len(q)))
    assert err_m <= 3 * eps, f"{err_m / eps:.2f} ulp"
    q2 = padded_call(rj.matrix_to_quaternion, R)
    assert q2.dtype == dtype
    ref = np.array([mp_matrix_to_quaternion(R[i].astype(np.float64))[0] for i in range(len(q))])
    err_q = np.abs(q2 - ref).max()
    assert err_q <= 2 * eps, f"{err_q / eps:.2f} ulp"


@pytest.mark.parametrize("dtype", DTYPES, ids=lambda d: d.__name__)
@pytest.mark.parametrize("seq", SEQS)
def test_euler_backward_error_ulp(seq, dtype):
    """Backward error of quaternion_to_euler (rotation of the returned angles against the
    input, exact arithmetic): <= 5 ulp in float64, <= 7 ulp in float32, on uniform,
    near-identity, near-180 and exact/near gimbal-lock inputs."""
    eps = np.finfo(dtype).eps
    lock = padded_call(rj.euler_to_quaternion, near_lock_angles(seq, 1e-12, n=6), seq)
    q = np.concatenate([ACC_SETS["uniform"][:6], ACC_SETS["near_identity"][:3],
                        ACC_SETS["near_180"][:3], lock]).astype(dtype)  # fmt: skip
    a = padded_call(rj.quaternion_to_euler, q, seq)
    assert a.dtype == dtype
    err = max(
        mp_max_diff(mp_euler_to_matrix(a[i], seq), mp_quat_to_matrix(q[i])) for i in range(len(q))
    )
    assert err <= (5 if dtype == np.float64 else 7) * eps, f"{err / eps:.2f} ulp"


@pytest.mark.parametrize("dtype", DTYPES, ids=lambda d: d.__name__)
@pytest.mark.parametrize("seq", SEQS)
def test_euler_to_matrix_accuracy_ulp(seq, dtype):
    """euler_to_matrix within 5 ulp of the exact product of elementary rotations."""
    eps = np.finfo(dtype).eps
    a = np.random.default_rng(9).uniform(-4, 4, size=(10, 3)).astype(dtype)
    R = padded_call(rj.euler_to_matrix, a, seq)
    assert R.dtype == dtype
    err = max(mp_max_diff(R[i].tolist(), mp_euler_to_matrix(a[i], seq)) for i in range(len(a)))
    assert err <= 5 * eps, f"{err / eps:.2f} ulp"


@pytest.mark.parametrize("dtype", DTYPES, ids=lambda d: d.__name__)
def test_rotvec_round_trips(dtype):
    eps = np.finfo(dtype).eps
    rng = np.random.default_rng(8)
    axis = _normalise(rng.normal(size=(200, 3)))
    angle = np.concatenate(
        [rng.uniform(0, np.pi, 194), [0, 1e-30, 1e-12, 1e-6, np.pi, np.pi - 1e-9]]
    )
    v = (axis * angle[:, None]).astype(dtype)
    back = np.asarray(rj.quaternion_to_rotvec(rj.rotvec_to_quaternion(v)))
    # at exactly pi both v and -v are valid
    ok = np.minimum(np.abs(back - v).max(-1), np.abs(back + v).max(-1))
    assert ok.max() <= 8 * eps * np.pi, f"{ok.max() / eps:.1f} eps"
    R = np.asarray(rj.rotvec_to_matrix(v))
    assert_close(R, Rotation.from_rotvec(v.astype(np.float64)).as_matrix(), atol=4 * eps)
    back_m = np.asarray(rj.matrix_to_rotvec(R))
    ok = np.minimum(np.abs(back_m - v).max(-1), np.abs(back_m + v).max(-1))
    tol = 8 * eps * np.pi if dtype == np.float64 else 16 * eps * np.pi
    # near pi the axis is determined to sqrt(eps) from a rounded matrix: judge the rotation
    assert_close(rj.rotvec_to_matrix(back_m), R, atol=6 * eps)
    assert ok[angle < 3].max() <= tol


def test_rotvec_tiny_and_huge_angles():
    tiny = np.array([1e-200, -2e-200, 3e-200])
    assert_close(rj.rotvec_to_quaternion(tiny), [*(tiny / 2), 1.0], rtol=1e-15)
    assert_close(rj.quaternion_to_rotvec(np.array([*(tiny / 2), 1.0])), tiny, rtol=1e-15)
    for turns in [1e3, 1e6]:
        theta = 2 * np.pi * turns + 0.5  # huge angle = 0.5 rad modulo full turns
        v = np.array([0.0, 0.0, theta])
        want = Rotation.from_rotvec([0, 0, 0.5]).as_matrix()
        assert_close(rj.rotvec_to_matrix(v), want, atol=1e-15 * theta)
        # a batch (rotvec_to_matrix's per-slot form on the CPU), tiny vectors among them
        batch = np.concatenate([np.tile(v, (6, 1)), np.tile(tiny, (2, 1))])
        R = np.asarray(rj.rotvec_to_matrix(batch))
        assert_close(R[:6], np.broadcast_to(want, (6, 3, 3)), atol=1e-15 * theta)
        assert_close(R[6:], np.broadcast_to(np.eye(3), (2, 3, 3)), atol=1e-15)
        assert_close(
            rj.quaternion_to_rotvec(rj.rotvec_to_quaternion(v)), [0, 0, 0.5], atol=1e-15 * theta
        )


def test_angles_accurate_near_zero():
    """atan2 forms keep relative accuracy where acos would return 0."""
    for t in [1e-5, 1e-10, 1e-20]:
        q = np.array([np.sin(t / 2), 0, 0, np.cos(t / 2)])
        assert_close(rj.rotation_angle(q), t, rtol=1e-15)
        assert_close(rj.angle_between(np.array([0, 0, 0, 1.0]), q), t, rtol=1e-15)
