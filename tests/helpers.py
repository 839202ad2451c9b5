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
        jac[(...,) + idx] = (np.asarray(f(jnp.asarray(x + e))) - np.asarray(f(jnp.asarray(x - e)))) / (
            2 * h
        )
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
