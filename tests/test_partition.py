"""Coordinate partitioning by L-U with full pivoting (Nikravesh App. C), checked against the
defining equations: Phi_u H + Phi_v = 0 (C.4) and u_dot = H v_dot for a velocity that
satisfies the constraints (C.6)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_close, check_grads, sweep

import rotjax as rj


def _rng(seed=0):
    return np.random.default_rng(seed)


def _columns(J, idx):
    return np.take_along_axis(np.asarray(J), np.asarray(idx)[..., None, :], axis=-1)


def _check_partition(J, part, n_dep, atol):
    """C.4 on the leading ``n_dep`` rows, the index sets, and C.6 on a velocity in the null
    space of J (built from v_dot with the surplus dependent coordinates held still)."""
    J = np.asarray(J, np.float64)
    m, n = J.shape[-2:]
    dep, ind = np.asarray(part.dependent), np.asarray(part.independent)
    np.testing.assert_array_equal(
        np.sort(np.concatenate([dep, ind], -1), -1), np.arange(n) + 0 * J[..., 0, :].astype(int)
    )
    H = np.asarray(part.influence, np.float64)[..., :n_dep, :]
    Ju, Jv = _columns(J, dep[..., :n_dep]), _columns(J, ind)
    # C.4: Phi_u H = -Phi_v (on the independent rows of the factorisation, all rows of J).
    assert_close(Ju @ H, -Jv, atol=atol * max(1.0, np.abs(H).max(initial=0.0)))
    # C.6: u_dot = H v_dot gives Phi_q q_dot = 0.
    v_dot = _rng(1).normal(size=ind.shape)
    q_dot = np.zeros(J.shape[:-2] + (n,))
    np.put_along_axis(q_dot, ind, v_dot, axis=-1)
    np.put_along_axis(q_dot, dep[..., :n_dep], np.einsum("...ij,...j->...i", H, v_dot), axis=-1)
    assert_close(np.einsum("...ij,...j->...i", J, q_dot), 0.0, atol=atol * 10)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize(
    ("m", "n"), sweep([(1, 4), (3, 7), (4, 4), (5, 6)], fast=[(3, 7)], several=True)
)
def test_full_rank_random(m, n, dtype):
    J = _rng(m * n).normal(size=(6, m, n)).astype(dtype)
    with jax.numpy_rank_promotion("raise"):
        part = rj.partition_coordinates(J)
    assert part.influence.dtype == dtype and part.influence.shape == (6, m, n - m)
    assert part.dependent.shape == (6, m) and part.independent.shape == (6, n - m)
    np.testing.assert_array_equal(part.rank, m)
    _check_partition(J, part, m, atol=30 * np.finfo(dtype).eps)
    # The first pivot is the largest |entry|: its column is the first dependent coordinate.
    flat = np.abs(J).reshape(6, -1).argmax(-1)
    np.testing.assert_array_equal(part.dependent[:, 0], flat % n)
    # Against numpy's solve on the chosen columns (Eq. C.4 directly).
    want = -np.linalg.solve(
        _columns(J, part.dependent).astype(np.float64), _columns(J, part.independent)
    )
    assert_close(
        part.influence, want, atol=100 * np.finfo(dtype).eps * max(1, np.abs(want).max(initial=0.0))
    )


def test_full_pivoting_beats_partial():
    """A pivot chosen by magnitude over the whole remainder: with a tiny leading entry the
    dependent coordinates avoid it."""
    J = np.array([[1e-12, 1.0, 0.0], [1.0, 1.0, 0.0]])
    part = rj.partition_coordinates(J)
    assert set(np.asarray(part.dependent).tolist()) == {0, 1}
    assert part.dependent[0] in (0, 1)
    _check_partition(J, part, 2, atol=1e-15)


def test_euler_parameter_constraint():
    """Phi = e.e - 1 has the Jacobian 2 e^T: the dependent parameter is the largest |e_i| (the
    same choice as the largest-component extraction), and H = -e_v / e_u."""
    e = _rng(2).normal(size=(50, 4))
    e /= np.linalg.norm(e, axis=-1, keepdims=True)
    part = rj.partition_coordinates(2 * e[:, None, :])
    big = np.abs(e).argmax(-1)
    np.testing.assert_array_equal(part.dependent[:, 0], big)
    eu = np.take_along_axis(e, big[:, None], -1)
    ev = _columns(e[:, None, :], part.independent)[:, 0]
    assert_close(part.influence[:, 0], -ev / eu, atol=1e-15)
    _check_partition(2 * e[:, None, :], part, 1, atol=1e-15)
    # |H| <= 1 entrywise: the best-conditioned choice.
    assert np.abs(np.asarray(part.influence)).max() <= 1.0


def _two_link_chain(th1, th2, length=2.0):
    """Two planar links, q = (x1, y1, th1, x2, y2, th2) at the centres of mass: link 1 pinned
    to the ground at its left end, link 2 joined to the right end of link 1 (revolute)."""
    c1, s1, c2, s2 = np.cos(th1), np.sin(th1), np.cos(th2), np.sin(th2)
    half = length / 2
    q = np.array(
        [half * c1, half * s1, th1, 2 * half * c1 + half * c2, 2 * half * s1 + half * s2, th2]
    )
    # Phi = [x1 - h c1, y1 - h s1, x1 + h c1 - x2 + h c2, y1 + h s1 - y2 + h s2]
    J = np.array(
        [
            [1, 0, half * s1, 0, 0, 0],
            [0, 1, -half * c1, 0, 0, 0],
            [1, 0, -half * s1, -1, 0, -half * s2],
            [0, 1, half * c1, 0, -1, half * c2],
        ]
    )
    return q, J


def test_two_link_chain_velocities():
    """Velocities of the chain from the two joint rates are reproduced from the independent
    coordinates' rates (Eq. C.6)."""
    th1, th2, w1, w2, h = 0.7, -0.4, 1.3, -0.8, 1.0
    q, J = _two_link_chain(th1, th2)
    q_dot = np.array(
        [
            -h * np.sin(th1) * w1,
            h * np.cos(th1) * w1,
            w1,
            -2 * h * np.sin(th1) * w1 - h * np.sin(th2) * w2,
            2 * h * np.cos(th1) * w1 + h * np.cos(th2) * w2,
            w2,
        ]
    )
    assert_close(J @ q_dot, 0.0, atol=1e-15)
    part = rj.partition_coordinates(J)
    assert int(part.rank) == 4
    u_dot = np.asarray(part.influence) @ q_dot[np.asarray(part.independent)]
    assert_close(u_dot, q_dot[np.asarray(part.dependent)], atol=1e-14)
    _check_partition(J, part, 4, atol=1e-15)


def test_rank_deficient():
    """A redundant constraint (sum of two others): rank m - 1, the last influence row is NaN,
    and the leading rows hold Eq. C.4 with the surplus dependent coordinate held fixed."""
    J = _rng(3).normal(size=(3, 6))
    Jr = np.concatenate([J, J[:1] + J[2:3]], axis=0)
    part = rj.partition_coordinates(Jr)
    assert int(part.rank) == 3
    H = np.asarray(part.influence)
    assert np.all(np.isnan(H[3])) and np.all(np.isfinite(H[:3]))
    _check_partition(Jr, part, 3, atol=1e-14)
    zero = rj.partition_coordinates(np.zeros((2, 5)))
    assert int(zero.rank) == 0 and np.all(np.isnan(zero.influence))
    # A tolerance above the second pivot cuts the rank.
    scaled = np.diag([1.0, 1e-6]) @ J[:2]
    assert int(rj.partition_coordinates(scaled).rank) == 2
    assert int(rj.partition_coordinates(scaled, tol=1e-3).rank) == 1


def test_nan_stays_local_and_vmap_jit():
    J = _rng(4).normal(size=(3, 2, 5))
    J[1, 0, 3] = np.nan
    part = rj.partition_coordinates(J)
    assert np.all(np.isnan(part.influence[1]))
    assert np.all(np.isfinite(part.influence[np.array([0, 2])]))
    mapped = jax.vmap(rj.partition_coordinates)(J)
    for a, b in zip(mapped, part, strict=True):
        np.testing.assert_array_equal(a, b)
    one = rj.partition_coordinates(J[2])
    for a, b in zip(one, part, strict=True):
        np.testing.assert_array_equal(a, b[2])


def test_gradient_matches_finite_differences():
    """Away from pivot changes the influence matrix is a smooth function of the Jacobian."""
    J = jnp.asarray(_rng(5).normal(size=(2, 5)))
    check_grads(
        lambda x: rj.partition_coordinates(x).influence, (J,), order=1, modes=("fwd", "rev")
    )
    g = jax.grad(lambda x: jnp.sum(rj.partition_coordinates(x).influence[:1]))(
        jnp.zeros((2, 5)).at[0, 0].set(1.0)
    )
    assert np.all(np.isfinite(g))  # rank 1: finite gradients, NaN rows excluded


@pytest.mark.parametrize(
    "bad", [np.zeros((3, 2)), np.zeros(4), np.zeros((2, 3, 2))], ids=["m>n", "1-D", "batch m>n"]
)
def test_invalid_shapes_raise(bad):
    with pytest.raises(ValueError, match="jacobian"):
        rj.partition_coordinates(bad)
