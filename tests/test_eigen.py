"""The 4x4 top-eigenvector kernel: accuracy against mpmath, scale, bad input, derivatives."""

import jax
import jax.numpy as jnp
import mpmath
import numpy as np
import pytest
from jax.test_util import check_grads
from scipy.spatial.transform import Rotation

import rotjax as rj
from rotjax._eigen import top_eigenvector

mpmath.mp.dps = 40
_top = jax.jit(top_eigenvector)


def _mp_top(K):
    E, Q = mpmath.eigsy(mpmath.matrix(K.tolist()))
    k = max(range(4), key=lambda i: E[i])
    lam = sorted(float(e) for e in E)
    return np.array([float(Q[i, k]) for i in range(4)]), (lam[-1] - lam[-2]) / max(
        abs(x) for x in lam
    )


def _bar_itzhack(sigma, n, seed, flip=False):
    rng = np.random.default_rng(seed)
    M = Rotation.random(n, random_state=seed).as_matrix() + sigma * rng.standard_normal((n, 3, 3))
    if flip:
        M = M * np.array([1.0, 1.0, -1.0])
    from rotjax._eigen import davenport_k

    return np.asarray(davenport_k(jnp.asarray(M)))


def _cases():
    out = {f"sigma={s:g}": _bar_itzhack(s, 12, i) for i, s in enumerate([1e-8, 1e-4, 1e-2, 0.3, 1])}
    out["det<0"] = _bar_itzhack(0.3, 12, 7, flip=True)
    rng = np.random.default_rng(9)
    G = rng.standard_normal((12, 4, 4))
    out["gaussian"] = G + np.swapaxes(G, -1, -2)
    Q, _ = np.linalg.qr(rng.standard_normal((12, 4, 4)))
    lam = np.array([1 + 1e-6, 1.0, 0.3, -0.5])
    out["near-tie"] = np.einsum("nij,j,nkj->nik", Q, lam, Q)
    return out


CASES = _cases()


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("name", list(CASES))
def test_top_eigenvector_against_mpmath(name, dtype):
    K = CASES[name].astype(dtype)
    v = np.asarray(_top(jnp.asarray(K)), np.float64)
    e = np.finfo(dtype).eps
    for Ki, vi in zip(K, v, strict=True):
        ref, gap = _mp_top(Ki.astype(np.float64))
        err = np.abs(vi * np.sign(vi @ ref) - ref).max()
        # 2 eps where well separated; a few eps / relative gap in general.
        bound = 2 * e if gap > 0.1 else 8 * e / gap
        assert err <= bound, (name, err / e, gap)


@pytest.mark.parametrize(
    "dtype,scales", [(np.float32, [1e-30, 1e30]), (np.float64, [1e-300, 1e300])]
)
def test_optimal_scale_invariant(dtype, scales):
    R = jnp.asarray(Rotation.random(8, random_state=3).as_matrix(), dtype)
    q = rj.matrix_to_quaternion(R, method="optimal")
    for s in scales:
        qs = rj.matrix_to_quaternion(R * jnp.asarray(s, dtype), method="optimal")
        np.testing.assert_allclose(qs, q, atol=4 * np.finfo(dtype).eps)


def test_q_method_units():
    rng = np.random.default_rng(4)
    a = rng.standard_normal((5, 3))
    b = a @ Rotation.random(random_state=4).as_matrix() + 1e-3 * rng.standard_normal((5, 3))
    np.testing.assert_allclose(
        rj.align_vectors(5e-5 * a, b, method="q-method"), rj.align_vectors(a, b), atol=1e-15
    )


def test_bad_input_gives_nan():
    x = jnp.zeros((2, 9)).at[0, 4].set(jnp.inf)
    assert np.isnan(rj.nined_to_matrix(x)).all()  # inf in [0], the zero matrix in [1]
    assert np.isnan(rj.align_vectors(jnp.ones((3, 3)), jnp.ones((3, 3)), jnp.zeros(3))).all()
    assert np.isnan(rj.quaternion_mean(jnp.ones((3, 4)), jnp.zeros(3))).all()
    with pytest.raises(ValueError, match="empty"):
        rj.quaternion_mean(jnp.ones((0, 4)))


POINTS = {
    "identity": np.eye(3),
    "180 deg": np.diag([1.0, -1.0, -1.0]),
    "rotation": Rotation.from_rotvec([0.3, -1.0, 0.5]).as_matrix(),
    "noisy": Rotation.from_rotvec([0.3, -1.0, 0.5]).as_matrix()
    + 0.3 * np.random.default_rng(5).standard_normal((3, 3)),
}


@pytest.mark.parametrize("name", list(POINTS))
def test_second_derivatives(name):
    # Sign-free outputs (the matrix), so the w >= 0 choice at 180 degrees does not matter.
    M = POINTS[name]
    check_grads(rj.nined_to_matrix, (M.reshape(9),), order=2, modes=["fwd", "rev"])
    H = jax.hessian(lambda M: rj.matrix_to_quaternion(M, method="optimal"))(M)
    assert np.isfinite(H).all()


def test_mean_and_align_hessians_finite():
    q = jnp.tile(jnp.array([0.1, 0.2, 0.3, 0.9]), (3, 1))
    assert np.isfinite(jax.hessian(rj.quaternion_mean)(q)).all()
    check_grads(lambda q: rj.quaternion_mean(q), (q,), order=2, modes=["fwd", "rev"])
    a = jnp.eye(3)
    assert np.isfinite(jax.hessian(lambda a: rj.align_vectors(a, jnp.eye(3)))(a)).all()
