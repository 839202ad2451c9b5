"""Shared test helpers: assertions, strategies that seek trouble, and the parameter lists."""

from __future__ import annotations

import hypothesis.extra.numpy as hnp
import jax.numpy as jnp
import numpy as np
from hypothesis import strategies as st

import rotjax as rj

LETTER_SEQS = [a + b + c for a in "xyz" for b in "xyz" for c in "xyz" if a != b and b != c]
SEQS = LETTER_SEQS + [s.upper() for s in LETTER_SEQS]  # 12 extrinsic + 12 intrinsic
DIGIT_SEQS = ["313", "123", "121", "232", "321"]
BATCH_SHAPES = [(), (1,), (3, 1, 2, 1)]
DTYPES = [np.float32, np.float64]


def is_proper(seq: str) -> bool:
    """Proper Euler (first axis = third axis) rather than Tait-Bryan."""
    return seq[0] == seq[2]


def lock_middles(seq: str) -> tuple[float, float]:
    """The two middle-angle values at which ``seq`` is in gimbal lock."""
    return (0.0, np.pi) if is_proper(seq) else (np.pi / 2, -np.pi / 2)


def ulp(dtype) -> float:
    return float(np.finfo(dtype).eps)


def assert_close(actual, desired, atol=0.0, rtol=0.0, err_msg=""):
    """``assert_allclose`` that also requires every value to be finite."""
    actual = np.asarray(actual)
    assert np.all(np.isfinite(actual)), f"non-finite values: {actual} {err_msg}"
    np.testing.assert_allclose(actual, np.asarray(desired), atol=atol, rtol=rtol, err_msg=err_msg)


def assert_same_rotation(q1, q2, atol, err_msg=""):
    """Quaternions equal up to sign (``q`` and ``-q`` are the same rotation)."""
    q1, q2 = np.asarray(q1, np.float64), np.asarray(q2, np.float64)
    assert np.all(np.isfinite(q1)), f"non-finite values: {q1} {err_msg}"
    d = np.minimum(np.abs(q1 - q2).max(axis=-1), np.abs(q1 + q2).max(axis=-1))
    assert np.all(d <= atol), f"max |q1 -+ q2| = {d.max():.3e} > {atol:.3e} {err_msg}"


def angle_diff(a, b):
    """Difference of angles wrapped to [-pi, pi]."""
    return np.angle(np.exp(1j * (np.asarray(a, np.float64) - np.asarray(b, np.float64))))


def random_quaternions(n: int, seed: int = 0) -> np.ndarray:
    """Uniformly distributed unit quaternions, scalar last."""
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def fd_jacobian(f, x, h=1e-6):
    """Central finite-difference Jacobian of ``f`` at ``x`` (float64), shape out + in."""
    x = np.asarray(x, np.float64)
    f0 = np.asarray(f(jnp.asarray(x)))
    jac = np.zeros(f0.shape + x.shape)
    for idx in np.ndindex(x.shape):
        e = np.zeros_like(x)
        e[idx] = h
        jac[(...,) + idx] = (
            np.asarray(f(jnp.asarray(x + e))) - np.asarray(f(jnp.asarray(x - e)))
        ) / (2 * h)
    return jac


# --- one call of every public function ------------------------------------------------------

# Functions whose input has a set or time axis before the trailing one (besides the batch).
SET_AXIS = ("quaternion_mean", "align_vectors", "align_vectors q-method", "unwrap_euler")


def every_public(q, r, w, a):
    """One call of every public function (name -> (function, inputs)), built from ``n``
    quaternions ``q``, their matrices ``r``, rotation vectors ``w`` and ZYX angles ``a``."""
    n = len(q)
    # quaternions near q[0], of both signs and not unit: a mean that is well conditioned (the
    # mean of uniformly random rotations is not: its 4x4 scatter matrix has close eigenvalues)
    cluster = (q[0] + q / 5) * np.where(np.arange(n) % 2 == 0, 1, -1).astype(q.dtype)[:, None]
    return {
        "quaternion_to_matrix": (rj.quaternion_to_matrix, (q,)),
        "matrix_to_quaternion": (lambda r: rj.matrix_to_quaternion(r, method="optimal"), (r,)),
        "quaternion_to_rotvec": (rj.quaternion_to_rotvec, (q,)),
        "rotvec_to_quaternion": (rj.rotvec_to_quaternion, (w,)),
        "rotvec_to_matrix": (rj.rotvec_to_matrix, (w,)),
        "matrix_to_rotvec": (rj.matrix_to_rotvec, (r,)),
        "quaternion_to_axis_angle": (lambda q: rj.quaternion_to_axis_angle(q)[0], (q,)),
        "axis_angle_to_quaternion": (rj.axis_angle_to_quaternion, (w, a[:, 0])),
        "quaternion_to_euler": (lambda q: rj.quaternion_to_euler(q, "ZYX"), (q,)),
        "matrix_to_euler": (lambda r: rj.matrix_to_euler(r, "zxz"), (r,)),
        "euler_to_matrix": (lambda a: rj.euler_to_matrix(a, "ZYX"), (a,)),
        "euler_to_quaternion": (lambda a: rj.euler_to_quaternion(a, "313"), (a,)),
        "quaternion_normalize": (rj.quaternion_normalize, (q,)),
        "quaternion_conjugate": (rj.quaternion_conjugate, (q,)),
        "quaternion_inverse": (rj.quaternion_inverse, (q,)),
        "quaternion_multiply": (rj.quaternion_multiply, (q, q[::-1])),
        "quaternion_apply": (rj.quaternion_apply, (q, w)),
        "relative_rotation": (rj.relative_rotation, (q, q[::-1])),
        "rotation_angle": (rj.rotation_angle, (q,)),
        "angle_between": (rj.angle_between, (q, q[::-1])),
        "slerp": (lambda p, q: rj.slerp(p, q, 0.3), (q, q[::-1])),
        "quaternion_mean": (rj.quaternion_mean, (cluster,)),
        "align_vectors": (rj.align_vectors, (w, a)),
        "align_vectors q-method": (lambda a, b: rj.align_vectors(a, b, method="q-method"), (w, a)),
        "chordal_distance": (rj.chordal_distance, (r, r[::-1])),
        "geodesic_distance": (rj.geodesic_distance, (r, r[::-1])),
        "matrix_to_sixd": (rj.matrix_to_sixd, (r,)),
        "sixd_to_matrix": (lambda x: rj.sixd_to_matrix(x), (r[:, :2].reshape(n, 6),)),
        "nined_to_matrix": (rj.nined_to_matrix, (r.reshape(n, 9),)),
        "euler_rate_matrix": (lambda a: rj.euler_rate_matrix(a, "ZXZ", frame="world"), (a,)),
        "euler_rates_to_angular_velocity": (
            lambda a, w: rj.euler_rates_to_angular_velocity(a, w, "ZYX"),
            (a, w),
        ),
        "angular_velocity_to_euler_rates": (
            lambda a, w: rj.angular_velocity_to_euler_rates(a, w, "ZYX", damping=0.1),
            (a, w),
        ),
        "euler_singularity": (lambda a: rj.euler_singularity(a, "XYZ"), (a,)),
        "unwrap_euler": (lambda a: rj.unwrap_euler(a, "ZYX"), (a,)),
        "quaternion_derivative": (rj.quaternion_derivative, (q, w)),
        "quaternion_derivative_to_angular_velocity": (
            rj.quaternion_derivative_to_angular_velocity,
            (q, q[::-1]),
        ),
        "matrix_derivative_to_angular_velocity": (
            lambda r, d: rj.matrix_derivative_to_angular_velocity(r, d, frame="world"),
            (r, r[::-1]),
        ),
        "angular_velocity_to_matrix_derivative": (rj.angular_velocity_to_matrix_derivative, (r, w)),
        "integrate_angular_velocity": (
            lambda q, w: rj.integrate_angular_velocity(q, w, 0.01, method="rk4"),
            (q, w),
        ),
    }


def public_inputs(n, dtype):
    """The inputs of :func:`every_public` for ``n`` random rotations (seed 21), in ``dtype``:
    quaternions, their matrices, rotation vectors and ZYX angles."""
    q = random_quaternions(n, seed=21)
    derived = rj.quaternion_to_matrix(q), rj.quaternion_to_rotvec(q)
    derived += (rj.quaternion_to_euler(q, "ZYX"),)
    return [np.asarray(x).astype(dtype) for x in (q, *derived)]


# --- hypothesis strategies -----------------------------------------------------------------

finite = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)


@st.composite
def unit_quaternions(draw):
    """Generic, near-identity (1e-7 scale) and near-180-degree unit quaternions."""
    v = draw(hnp.arrays(np.float64, 4, elements=finite))
    kind = draw(st.sampled_from(["generic", "near_identity", "near_180"]))
    if kind == "near_identity":
        v = np.array([*(1e-7 * v[:3]), 1.0])
    elif kind == "near_180":
        v = np.array([*v[:3], 1e-7 * v[3]])
        if np.linalg.norm(v[:3]) < 1e-3:
            v[:3] = [1.0, 0.0, 0.0]
    n = np.linalg.norm(v)
    if n < 1e-3:
        v, n = np.array([0.0, 0.0, 0.0, 1.0]), 1.0
    return v / n


@st.composite
def euler_angles(draw, seq):
    """Angles for ``seq``: generic, or with the middle angle within 1e-6 of gimbal lock."""
    a0 = draw(st.floats(-np.pi, np.pi))
    a2 = draw(st.floats(-np.pi, np.pi))
    near_lock = draw(st.booleans())
    if near_lock:
        mid = draw(st.sampled_from(lock_middles(seq))) + draw(st.floats(-1e-6, 1e-6))
    else:
        lo, hi = (0.0, np.pi) if is_proper(seq) else (-np.pi / 2, np.pi / 2)
        mid = draw(st.floats(lo, hi))
    return np.array([a0, mid, a2])


# --- high-precision references (mpmath) ----------------------------------------------------


def mp_quat_to_matrix(q, dps=40):
    """Rotation matrix of a (normalised) scalar-last quaternion, in mpmath; returns float64
    rows of mpf values as a nested list."""
    import mpmath as mp

    with mp.workdps(dps):
        x, y, z, w = (mp.mpf(float(c)) for c in q)
        n = x * x + y * y + z * z + w * w
        s = 2 / n
        return [
            [1 - s * (y * y + z * z), s * (x * y - z * w), s * (x * z + y * w)],
            [s * (x * y + z * w), 1 - s * (x * x + z * z), s * (y * z - x * w)],
            [s * (x * z - y * w), s * (y * z + x * w), 1 - s * (x * x + y * y)],
        ]


def mp_euler_to_matrix(angles, seq, dps=40):
    """Product of elementary rotation matrices in mpmath, for any sequence string."""
    import mpmath as mp

    from rotjax._euler import parse_seq

    axes, intrinsic = parse_seq(seq)
    with mp.workdps(dps):
        mats = []
        for ax, a in zip(axes, angles, strict=True):
            c, s = mp.cos(mp.mpf(float(a))), mp.sin(mp.mpf(float(a)))
            m = mp.eye(3)
            i, j = [(1, 2), (2, 0), (0, 1)][ax]
            m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
            mats.append(m)
        out = mats[0] * mats[1] * mats[2] if intrinsic else mats[2] * mats[1] * mats[0]
        return [[out[r, k] for k in range(3)] for r in range(3)]


def mp_max_diff(a, b, dps=40):
    """Max |a - b| over nested 3x3 lists of mpf / floats, as a float."""
    import mpmath as mp

    with mp.workdps(dps):
        return float(
            max(abs(mp.mpf(a[r][k]) - mp.mpf(b[r][k])) for r in range(3) for k in range(3))
        )


def mp_matrix_to_quaternion(R, dps=40):
    """Quaternion (w >= 0) of the exact input matrix by the normalised largest column of K,
    evaluated in mpmath (the exact-arithmetic value of the float algorithm's formula)."""
    import mpmath as mp

    with mp.workdps(dps):
        r = [[mp.mpf(float(R[i][j])) for j in range(3)] for i in range(3)]
        cols = [
            [
                1 + r[0][0] - r[1][1] - r[2][2],
                r[0][1] + r[1][0],
                r[0][2] + r[2][0],
                r[2][1] - r[1][2],
            ],
            [
                r[0][1] + r[1][0],
                1 - r[0][0] + r[1][1] - r[2][2],
                r[1][2] + r[2][1],
                r[0][2] - r[2][0],
            ],
            [
                r[0][2] + r[2][0],
                r[1][2] + r[2][1],
                1 - r[0][0] - r[1][1] + r[2][2],
                r[1][0] - r[0][1],
            ],
            [
                r[2][1] - r[1][2],
                r[0][2] - r[2][0],
                r[1][0] - r[0][1],
                1 + r[0][0] + r[1][1] + r[2][2],
            ],
        ]
        best = max(range(4), key=lambda i: cols[i][i])
        v = cols[best]
        n = mp.sqrt(sum(c * c for c in v))
        q = [c / n for c in v]
        if q[3] < 0:
            q = [-c for c in q]
        return [float(c) for c in q], q
