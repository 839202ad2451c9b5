"""Shared test helpers: assertions, strategies that seek trouble, and the parameter lists."""

from __future__ import annotations

import hypothesis.extra.numpy as hnp
import jax.numpy as jnp
import numpy as np
from hypothesis import strategies as st

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
