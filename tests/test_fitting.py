"""Attitude fitting and learning: losses, 6D/9D representations, Wahba, mean, slerp."""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import (
    BATCH_SHAPES,
    DTYPES,
    assert_close,
    assert_same_rotation,
    check_grads,
    fd_jacobian,
    random_quaternions,
    rev_jacobian,
    sweep,
    ulp,
)
from scipy.spatial.transform import Rotation, Slerp

import rotjax as rj

METHODS = ["svd", "q-method"]
# Each method's call, one function object per method: check_grads and rev_jacobian keep their
# programs per function object, so the tests of a method (and shape) share them.
ALIGN = {m: partial(rj.align_vectors, method=m) for m in METHODS}


def random_rotations(n, seed=0):
    """Matrices of random rotations, by scipy: no program per ``n`` compiled for test data."""
    return Rotation.from_quat(random_quaternions(n, seed)).as_matrix()


def wahba_problem(n, seed, noise=0.01):
    """Reference vectors ``a``, body vectors ``b = R0^T a + noise``, weights, and ``R0``."""
    rng = np.random.default_rng(seed)
    R0 = random_rotations(1, seed + 100)[0]
    a = rng.normal(size=(n, 3))
    b = a @ R0 + noise * rng.normal(size=(n, 3))
    w = rng.uniform(0.2, 2.0, size=n)
    return a, b, w, R0


def scipy_align(a, b, w=None):
    # scipy wants >= 2 pairs for a well-posed answer; our random problems always have them.
    return Rotation.align_vectors(a, b, weights=w)[0].as_quat()


# --- geodesic and chordal distances -------------------------------------------------------


@pytest.mark.parametrize("dtype", DTYPES)
def test_geodesic_matches_angle_between(dtype):
    p, q = random_quaternions(50, 1), random_quaternions(50, 2)
    Rp, Rq = np.asarray(rj.quaternion_to_matrix(p)), np.asarray(rj.quaternion_to_matrix(q))
    d = rj.geodesic_distance(Rp.astype(dtype), Rq.astype(dtype))
    assert d.dtype == dtype
    assert_close(d, rj.angle_between(p, q), atol=20 * ulp(dtype))


@pytest.mark.parametrize("angle", [1e-9, 1e-4, 1.0, np.pi - 1e-4, np.pi - 1e-7])
def test_geodesic_accurate_at_small_and_near_pi(angle):
    axis = np.array([2.0, -3.0, 6.0]) / 7
    R = rj.rotvec_to_matrix(angle * axis)
    d = rj.geodesic_distance(np.eye(3), R)
    assert_close(d, angle, atol=4 * ulp(np.float64))


# jitted: one program each, shared by the tests (eager differentiation dispatches many)
_geodesic_grad = jax.jit(jax.grad(rj.geodesic_distance, argnums=(0, 1)))


def test_geodesic_gradient_at_zero_is_finite_and_zero():
    R = random_rotations(1, 3)[0]
    g = _geodesic_grad(jnp.asarray(R), jnp.asarray(R))
    for gi in g:
        assert_close(gi, np.zeros((3, 3)), atol=0)


@jax.jit
def _geodesic_along(x, R1):
    """The distance from the identity to ``exp(x) R1``."""
    return rj.geodesic_distance(jnp.eye(3), rj.rotvec_to_matrix(x) @ R1)


_geodesic_along_grad = jax.jit(jax.grad(_geodesic_along))


@pytest.mark.parametrize("angle", [1e-4, 0.5, np.pi - 1e-3])
def test_geodesic_gradient_matches_fd(angle):
    # Differentiate along the rotation: d/dt distance(I, exp(t v) R1) at t = 0 is the unit
    # speed of the geodesic: +1 in the direction that lengthens it.
    v = np.array([0.3, -0.2, 0.9])
    R1 = rj.rotvec_to_matrix(angle * v / np.linalg.norm(v))

    def f(x):
        return _geodesic_along(x, R1)

    x0 = np.zeros(3)
    g = _geodesic_along_grad(x0, R1)
    assert_close(g, fd_jacobian(f, x0, h=1e-7), atol=2e-6)
    assert_close(np.linalg.norm(g), 1.0, atol=1e-6)


def test_geodesic_gradient_at_pi_is_finite():
    R = rj.rotvec_to_matrix(np.pi * np.array([0.0, 0.6, 0.8]))
    g = _geodesic_grad(jnp.eye(3), jnp.asarray(R))
    assert all(np.all(np.isfinite(gi)) for gi in g)


_chordal_grad = jax.jit(jax.grad(rj.chordal_distance))


@pytest.mark.parametrize("dtype", DTYPES)
def test_chordal_distance(dtype):
    p, q = random_quaternions(50, 4), random_quaternions(50, 5)
    Rp = np.asarray(rj.quaternion_to_matrix(p)).astype(dtype)
    Rq = np.asarray(rj.quaternion_to_matrix(q)).astype(dtype)
    d = rj.chordal_distance(Rp, Rq)
    assert d.dtype == dtype
    theta = np.asarray(rj.angle_between(p, q))
    assert_close(d, 2 * np.sqrt(2) * np.sin(theta / 2), atol=20 * ulp(dtype))
    g = _chordal_grad(Rp[0], Rp[0])
    assert_close(g, np.zeros((3, 3)), atol=0)


_geodesic_grad_b = jax.jit(jax.grad(rj.geodesic_distance, argnums=1))


@pytest.mark.parametrize("dtype", DTYPES)
def test_geodesic_keeps_angles_whose_squares_underflow(dtype):
    """A rotation by 1e-20 (float32) or 1e-160 (float64): the squared sine underflows, so the
    distance scales before it squares. Value and gradient (unit speed) as at any other small
    angle, not 0."""
    angle = 1e-20 if dtype == np.float32 else 1e-160
    eye = np.eye(3, dtype=dtype)
    R = eye.copy()
    R[0, 1], R[1, 0] = -angle, angle  # about z, to first order (exactly orthogonal in dtype)
    assert_close(rj.geodesic_distance(eye, R), angle, rtol=4 * ulp(dtype))
    want = np.zeros((3, 3))
    want[1, 0], want[0, 1] = 0.5, -0.5  # d(angle)/dR = (E10 - E01) / 2
    assert_close(_geodesic_grad_b(eye, R), want, atol=8 * ulp(dtype))


def _chordal_made(p, q):
    # matrices made in the program: read as their entries
    return rj.chordal_distance(rj.quaternion_to_matrix(p), rj.quaternion_to_matrix(q))


@jax.jit
def _chordal_both_ways(p, q):
    """chordal_distance and its gradient in ``p`` for matrices made in the program, and the same
    through matrices that chordal_distance receives as arguments (read as a stacked array)."""
    Rp, Rq = rj.quaternion_to_matrix(p), rj.quaternion_to_matrix(q)
    given = jax.vmap(rj.chordal_distance)(Rp, Rq)  # vmap's tracers: not the recorded arrays
    dRp = jax.grad(lambda R: jnp.sum(rj.chordal_distance(R, Rq)))(Rp)
    g_given = jax.vjp(rj.quaternion_to_matrix, p)[1](dRp)[0]
    made = _chordal_made(p, q)
    g_made = jax.grad(lambda p: jnp.sum(_chordal_made(p, q)))(p)
    return (made, g_made), (given, g_given)


@pytest.mark.parametrize("dtype", DTYPES)
def test_chordal_distance_of_made_matrices_equals_that_of_given_ones(dtype):
    p, q = random_quaternions(50, 6).astype(dtype), random_quaternions(50, 7).astype(dtype)
    (d, g), (d_ref, g_ref) = _chordal_both_ways(p, q)
    assert_close(d, d_ref, atol=8 * ulp(dtype))
    assert_close(g, g_ref, atol=32 * ulp(dtype))


# --- 6D ---------------------------------------------------------------------------------


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("shape", BATCH_SHAPES, ids=str)
def test_sixd_round_trip(dtype, shape):
    n = int(np.prod(shape))
    R = random_rotations(n, 6).reshape(*shape, 3, 3).astype(dtype)
    x = rj.matrix_to_sixd(R)
    assert x.shape == (*shape, 6) and x.dtype == dtype
    assert_close(rj.sixd_to_matrix(x), R, atol=10 * ulp(dtype))


def test_sixd_gram_schmidt_is_a_projection():
    x = np.random.default_rng(7).normal(size=(20, 6))
    R = np.asarray(rj.sixd_to_matrix(x))
    assert_close(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-14)
    assert_close(np.linalg.det(R), np.ones(20), atol=1e-14)
    # first column along a1; second in the plane of a1 and a2 on a2's side
    a1, a2 = x[:, :3], x[:, 3:]
    assert_close(R[:, :, 0], a1 / np.linalg.norm(a1, axis=-1, keepdims=True), atol=1e-15)
    assert_close(np.einsum("ni,ni->n", np.cross(a1, a2), R[:, :, 1]), np.zeros(20), atol=1e-12)
    assert np.all(np.einsum("ni,ni->n", a2, R[:, :, 1]) > 0)
    # idempotent: re-encoding a Gram-Schmidt output gives the same matrix
    assert_close(rj.sixd_to_matrix(rj.matrix_to_sixd(R)), R, atol=1e-14)


def test_sixd_check_grads():
    x = np.random.default_rng(8).normal(size=6)
    check_grads(rj.sixd_to_matrix, (x,), order=1, modes=("fwd", "rev"))


# --- 9D (SVD projection) --------------------------------------------------------------------

# Singular values of M = R1 @ diag(s) @ R2: ties make jnp.linalg.svd's own gradient NaN.
SPECTRA = {
    "generic": [3.0, 2.0, 0.5],
    "all_tied": [1.0, 1.0, 1.0],
    "top_tied": [2.0, 2.0, 0.5],
    "bottom_tied": [3.0, 1.0, 1.0],
    "negative_det": [3.0, 2.0, -0.5],
    "negative_det_top_tied": [2.0, 2.0, -0.5],
}


def spectral_matrix(s, seed):
    R1, R2 = random_rotations(2, seed)
    return R1 @ np.diag(s) @ R2


def numpy_projection(M):
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt))
    return U @ np.diag([1.0, 1.0, d]) @ Vt


@pytest.mark.parametrize("name", list(SPECTRA))
def test_nined_projection_value(name):
    M = spectral_matrix(SPECTRA[name], 9)
    R = np.asarray(rj.nined_to_matrix(M.reshape(9)))
    assert_close(R, numpy_projection(M), atol=1e-13)
    assert_close(R @ R.T, np.eye(3), atol=1e-14)
    assert_close(np.linalg.det(R), 1.0, atol=1e-14)


def _nined_jacobian(x):
    """``jax.jacobian(rj.nined_to_matrix)(x)``, by test_nined_check_grads' VJP program."""
    return rev_jacobian(rj.nined_to_matrix, (x,))[0]


@pytest.mark.parametrize("name", list(SPECTRA))
def test_nined_gradient_matches_fd_including_ties(name):
    M = spectral_matrix(SPECTRA[name], 10).reshape(9)
    J = _nined_jacobian(M)
    assert_close(J, fd_jacobian(rj.nined_to_matrix, M, h=1e-6), atol=1e-8)


def test_nined_check_grads():
    M = spectral_matrix(SPECTRA["generic"], 11).reshape(9)
    check_grads(rj.nined_to_matrix, (M,), order=1, modes=("fwd", "rev"))


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("shape", BATCH_SHAPES, ids=str)
def test_nined_round_trip_of_rotations(dtype, shape):
    n = int(np.prod(shape))
    R = random_rotations(n, 12).reshape(*shape, 3, 3).astype(dtype)
    out = rj.nined_to_matrix(R.reshape(*shape, 9))
    assert out.shape == (*shape, 3, 3) and out.dtype == dtype
    assert_close(out, R, atol=20 * ulp(dtype))
    # at a rotation (all singular values tied) the gradient is finite and is the projection
    # onto the tangent space: tangent directions pass, normal (symmetric) ones are removed.
    assert np.all(np.isfinite(_nined_weighted_grad(R.reshape(*shape, 9)[(0,) * len(shape)])))


@jax.jit
@jax.grad
def _nined_weighted_grad(x):
    """Gradient of a weighted sum of squares of ``nined_to_matrix``: one program per dtype."""
    return jnp.sum(rj.nined_to_matrix(x) ** 2 * jnp.arange(9, dtype=x.dtype).reshape(3, 3))


def test_nined_gradient_finite_when_projection_not_unique():
    # rank 1: every rotation about one axis is equally near
    M = np.outer([1.0, 2.0, 0.5], [0.3, -1.0, 0.2]).reshape(9)
    J = _nined_jacobian(M)
    assert np.all(np.isfinite(J)) and np.abs(J).max() > 0


# --- Wahba's problem --------------------------------------------------------------------------


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("weighted", [False, True])
@pytest.mark.parametrize("seed", range(4))
def test_align_matches_scipy(method, weighted, seed):
    a, b, w, _ = wahba_problem(8, seed, noise=0.2)
    w = w if weighted else None
    q = rj.align_vectors(a, b, w, method=method)
    assert q[3] >= 0
    assert_same_rotation(q, scipy_align(a, b, w), atol=1e-13)


@pytest.mark.parametrize("dtype", DTYPES)
def test_svd_and_q_method_agree(dtype):
    rng = np.random.default_rng(13)
    R0 = random_rotations(64, 14)
    a = rng.normal(size=(64, 5, 3))
    b = np.einsum("bni,bij->bnj", a, R0) + 0.3 * rng.normal(size=(64, 5, 3))
    w = rng.uniform(0.1, 3.0, size=(64, 5))
    args = (a.astype(dtype), b.astype(dtype), w.astype(dtype))
    q_svd = rj.align_vectors(*args, method="svd")
    q_dav = rj.align_vectors(*args, method="q-method")
    assert q_svd.dtype == dtype and q_dav.dtype == dtype
    assert_same_rotation(q_svd, q_dav, atol=200 * ulp(dtype))


def _align_vmapped(a, b, w, method):
    """``align_vectors`` mapped over the rows by ``jax.vmap``, called eagerly as before."""
    return jax.vmap(ALIGN[method])(a, b, w)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("shape", BATCH_SHAPES, ids=str)
def test_align_broadcasts_like_vmap(method, shape):
    # the 6 rows of the largest shape; the smaller shapes take the first (one vmapped program
    # per method, at 6 rows)
    n = int(np.prod(shape))
    rng = np.random.default_rng(15)
    a = rng.normal(size=(6, 4, 3))
    b = rng.normal(size=(6, 4, 3))
    w = rng.uniform(0.5, 1.5, size=(6, 4))
    looped = np.asarray(_align_vmapped(a, b, w, method))[:n]
    a, b, w = a[:n], b[:n], w[:n]
    batched = rj.align_vectors(
        a.reshape(*shape, 4, 3), b.reshape(*shape, 4, 3), w.reshape(*shape, 4), method=method
    )
    assert batched.shape == (*shape, 4)
    assert_close(batched.reshape(n, 4), looped, atol=1e-13)


# The mean's matrix is formed by elementwise sums up to 16 quaternions, by an einsum beyond:
# both sides of the switch.
@pytest.mark.parametrize("n", [2, 16, 17, 300])
def test_align_and_mean_any_number_of_vectors(n):
    a, b, w, _ = wahba_problem(n, 40 + n, noise=0.2)
    assert_same_rotation(rj.align_vectors(a, b, w), scipy_align(a, b, w), atol=1e-13)
    q = random_quaternions(n, 41 + n)
    want = Rotation.from_quat(q).mean(w).as_quat()
    assert_same_rotation(rj.quaternion_mean(q, w), want, 1e-12)


@pytest.mark.parametrize("n", [5, 30])
def test_mean_broadcasts_shared_quaternions_against_batched_weights(n):
    q = random_quaternions(n, 42)
    w = np.random.default_rng(43).uniform(0.1, 1.0, size=(4, n))
    batched = np.asarray(rj.quaternion_mean(q, w))
    assert batched.shape == (4, 4)
    for k in range(4):
        assert_close(batched[k], rj.quaternion_mean(q, w[k]), atol=1e-14)


@pytest.mark.parametrize("n", sweep([8, 30], fast=[8]))
@pytest.mark.parametrize("scale", [1.0, 1e-170])
def test_sum_outer_applies_the_factors_inside_the_products(n, scale):
    # At 1e-170 the products of x and y underflow unless the factors are applied inside them:
    # the sum of scaled outer products (unrolled for 8 vectors, an einsum for 30) is that of
    # the scaled inputs, of order 1.
    from rotjax._eigen import pow2_factors
    from rotjax._fitting import _sum_outer

    rng = np.random.default_rng(44)
    u, v = (rng.normal(size=(3, n, 4)) for _ in range(2))
    factors = scale != 1.0

    @jax.jit  # one program per case (eager, each operation was one)
    def case(u, v):
        x, y = u * scale, v * scale
        fx = pow2_factors(x, (-2, -1)) if factors else ()
        fy = pow2_factors(y, (-2, -1)) if factors else ()
        naive = jnp.max(jnp.abs(jnp.einsum("...ni,...nj->...ij", x, y)))
        return _sum_outer(x, y, fx, fy), fx, fy, naive

    got, fx, fy, naive = case(u, v)
    if factors:
        assert float(naive) == 0
    xs, ys = (np.asarray(w) * scale for w in (u, v))
    for f in fx:  # each factor in turn (exact; their product could overflow)
        xs = xs * np.asarray(f)[:, None, None]
    for f in fy:
        ys = ys * np.asarray(f)[:, None, None]
    want = np.einsum("...ni,...nj->...ij", xs, ys)
    assert float(np.min(np.abs(np.asarray(got)))) > 1e-6
    assert_close(got, want, atol=1e-14 * np.abs(want).max())


def test_sum_outer_broadcasts_shared_vectors_against_a_batch():
    # Shared quaternions against batched weights (quaternion_mean): x has a batch axis, y none.
    from rotjax._fitting import _sum_outer

    rng = np.random.default_rng(45)
    x = jnp.asarray(rng.normal(size=(4, 8, 4)))
    y = jnp.asarray(rng.normal(size=(8, 4)))
    got = jax.jit(lambda x, y: _sum_outer(x, y, (), ()))(x, y)
    assert got.shape == (4, 4, 4)
    assert_close(got, np.einsum("bni,nj->bij", np.asarray(x), np.asarray(y)), atol=1e-14)


@pytest.mark.parametrize("method", METHODS)
def test_align_zero_weight_drops_a_pair(method):
    a, b, w, _ = wahba_problem(6, 16, noise=0.3)
    w[2] = 0.0
    keep = np.arange(6) != 2
    q_all = rj.align_vectors(a, b, w, method=method)
    q_drop = rj.align_vectors(a[keep], b[keep], w[keep], method=method)
    assert_close(q_all, q_drop, atol=1e-12)


@pytest.mark.parametrize("method", METHODS)
def test_align_scalar_first(method):
    a, b, w, _ = wahba_problem(5, 17)
    q = rj.align_vectors(a, b, w, method=method)
    assert_close(rj.align_vectors(a, b, w, method=method, scalar_first=True), np.roll(q, 1), atol=0)


@pytest.mark.parametrize("method", METHODS)
def test_align_check_grads(method):
    a, b, w, _ = wahba_problem(6, 18, noise=0.3)
    check_grads(ALIGN[method], (a, b, w), order=1, modes=("fwd", "rev"))


def _single_pair(method):
    def f(a, b):
        q = rj.align_vectors(a, b, method=method)
        return q, rj.quaternion_apply(q, b[0])

    return f


_SINGLE_PAIR = {m: _single_pair(m) for m in METHODS}


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("dtype", sweep(DTYPES, fast=[np.float64]))
def test_align_single_pair(method, dtype):
    """One pair: R is unique only up to a rotation about a, but R b = |b| a / |a| is unique.

    The quaternion's own gradient is finite (zero along the undetermined rotation), and the
    gradient of R b is exact.
    """
    rng = np.random.default_rng(19)
    a, b = rng.normal(size=(1, 3)).astype(dtype), rng.normal(size=(1, 3)).astype(dtype)
    f = _SINGLE_PAIR[method]
    q, Rb = f(a, b)
    na, nb = np.linalg.norm(a.astype(np.float64)), np.linalg.norm(b.astype(np.float64))
    u = a[0].astype(np.float64) / na
    assert_close(np.asarray(Rb, np.float64) / nb, u, atol=20 * ulp(dtype))
    (Jq_a, Jq_b), (Ja, Jb) = rev_jacobian(f, (a, b))  # one program (eager: many)
    assert all(np.all(np.isfinite(j)) for j in (Jq_a, Jq_b))
    tol = 1e-8 if dtype == np.float64 else 1e-3
    assert_close(Ja[:, 0, :], nb / na * (np.eye(3) - np.outer(u, u)), atol=tol)
    if dtype == np.float64:
        assert_close(Ja, fd_jacobian(lambda a: f(a, b)[1], a), atol=1e-8)
        assert_close(Jb, fd_jacobian(lambda b: f(a, b)[1], b), atol=1e-8)


NOISE_FREE_SETS = {
    # three orthogonal pairs of +-axes: B = 2 R0, all singular values tied
    "isotropic": np.concatenate([np.eye(3), -np.eye(3)]),
    "two_vectors": np.array([[1.0, 0.2, -0.1], [0.1, 1.0, 0.5]]),
    "generic": np.random.default_rng(21).normal(size=(6, 3)),
}


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", list(NOISE_FREE_SETS))
def test_align_noise_free(method, name):
    """Exact data: the rotation is recovered to rounding and its gradient is exact."""
    R0 = random_rotations(1, 22)[0]
    a = NOISE_FREE_SETS[name]
    b = a @ R0  # b_i = R0^T a_i
    q = rj.align_vectors(a, b, method=method)
    assert_close(rj.quaternion_to_matrix(q), R0, atol=1e-14)

    def f(a):
        return rj.align_vectors(a, b, method=method)

    # one VJP program per method and shape, shared by the sets of a shape
    J = rev_jacobian(ALIGN[method], (a, b))[0]
    assert_close(J, fd_jacobian(f, a, h=1e-6), atol=1e-8)


@pytest.mark.parametrize(
    ("a_shape", "b_shape", "w_shape"),
    [((3,), (3,), None), ((4, 2), (4, 2), None), ((4, 3), (5, 3), None), ((4, 3), (4, 3), (3,))],
)
def test_align_bad_shapes(a_shape, b_shape, w_shape):
    w = None if w_shape is None else np.ones(w_shape)
    with pytest.raises(ValueError, match="expected|same number"):
        rj.align_vectors(np.ones(a_shape), np.ones(b_shape), w)


def test_align_bad_method():
    with pytest.raises(ValueError, match="method"):
        rj.align_vectors(np.ones((2, 3)), np.ones((2, 3)), method="triad")


# --- mean ------------------------------------------------------------------------------------


@pytest.mark.parametrize("flip", range(5))
def test_mean_invariant_to_sign_flips(flip):
    rng = np.random.default_rng(23)
    q = random_quaternions(5, 24) * rng.uniform(0.5, 2.0, size=(5, 1))  # not unit, on purpose
    w = rng.uniform(0.1, 1.0, size=5)
    q_flip = q.copy()
    q_flip[flip] *= -1
    m = rj.quaternion_mean(q, w)
    assert m[3] >= 0
    assert_close(rj.quaternion_mean(q_flip, w), m, atol=1e-14)


@pytest.mark.parametrize("dtype", DTYPES)
def test_mean_about_one_axis_is_circular_mean(dtype):
    # rotations about one axis: the mean angle is atan2(sum w sin t, sum w cos t)
    axis = np.array([2.0, -3.0, 6.0]) / 7
    t = np.array([0.1, 0.5, -0.3, 1.2])
    w = np.array([1.0, 2.0, 0.5, 0.25])
    q = rj.rotvec_to_quaternion((t[:, None] * axis).astype(dtype))
    want = np.arctan2(np.sum(w * np.sin(t)), np.sum(w * np.cos(t)))
    m = rj.quaternion_mean(q, w.astype(dtype))
    assert m.dtype == dtype
    assert_same_rotation(m, rj.rotvec_to_quaternion(want * axis), atol=20 * ulp(dtype))


def test_mean_matches_scipy():
    q = random_quaternions(10, 25)
    w = np.random.default_rng(26).uniform(0.1, 1.0, 10)
    assert_same_rotation(rj.quaternion_mean(q, w), Rotation.from_quat(q).mean(w).as_quat(), 1e-12)


def test_mean_batched_and_scalar_first():
    q = random_quaternions(12, 27).reshape(3, 4, 4)
    m = rj.quaternion_mean(q)
    assert m.shape == (3, 4)
    assert_close(m, jax.vmap(rj.quaternion_mean)(q), atol=1e-14)
    assert_close(rj.quaternion_mean(np.roll(q, 1, -1), scalar_first=True), np.roll(m, 1, -1), 1e-14)


def test_mean_gradients():
    q = random_quaternions(4, 28)
    w = np.array([1.0, 0.5, 2.0, 0.7])
    check_grads(rj.quaternion_mean, (q, w), order=1, modes=("fwd", "rev"))


def test_mean_jacobian_finite_where_not_unique():
    # two rotations 180 degrees apart with equal weights: the mean is not unique
    q2 = np.array([[0.0, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0, 0.0]])
    J = rev_jacobian(rj.quaternion_mean, (q2,))[0]
    assert J.shape == (4, 2, 4)
    assert np.all(np.isfinite(J))


def test_mean_bad_shapes():
    with pytest.raises(ValueError, match="expected"):
        rj.quaternion_mean(np.ones(4))
    with pytest.raises(ValueError, match="expected"):
        rj.quaternion_mean(np.ones((3, 4)), np.ones(2))


# --- slerp -----------------------------------------------------------------------------------


@pytest.mark.parametrize("dtype", DTYPES)
def test_slerp_endpoints_and_scipy(dtype):
    p, q = random_quaternions(20, 29), random_quaternions(20, 30)
    p, q = p.astype(dtype), q.astype(dtype)
    tol = 20 * ulp(dtype)
    s0 = rj.slerp(p, q, np.zeros(20, dtype))
    assert s0.dtype == dtype
    assert_close(s0, p, atol=tol)
    assert_same_rotation(rj.slerp(p, q, np.ones(20, dtype)), q, atol=tol)
    t = np.linspace(0, 1, 20).astype(dtype)
    want = [
        Slerp([0, 1], Rotation.from_quat([pi, qi]))(ti).as_quat()
        for pi, qi, ti in zip(p, q, t, strict=True)
    ]
    assert_same_rotation(rj.slerp(p, q, t), np.array(want), atol=50 * tol)


def test_slerp_constant_angular_speed_and_short_way():
    p = random_quaternions(1, 31)[0]
    q = -random_quaternions(1, 32)[0]  # sign chosen so that p . q < 0 : the long way is wrong
    if p @ q > 0:
        q = -q
    theta = float(rj.angle_between(p, q))
    t = np.linspace(0.0, 1.0, 11)
    path = rj.slerp(p, q, t)
    assert_close(rj.angle_between(p, path), t * theta, atol=1e-14)
    assert_close(rj.angle_between(path, q), (1 - t) * theta, atol=1e-14)
    # equal steps: each consecutive pair is theta / 10 apart
    assert_close(rj.angle_between(path[:-1], path[1:]), np.full(10, theta / 10), atol=1e-14)


def _slerp_jacobian(p, q, t):
    """``jax.jacobian(rj.slerp, argnums=(0, 1, 2))``: one VJP program, shared by the tests and
    by test_slerp_t_broadcasts' check_grads of ``rj.slerp`` (eager: many)."""
    return rev_jacobian(rj.slerp, (p, q, t))


@pytest.mark.parametrize("gap", [0.0, 1e-12, 1e-7])
def test_slerp_stable_as_p_approaches_q(gap):
    p = random_quaternions(1, 33)[0]
    q = np.asarray(rj.quaternion_multiply(p, rj.rotvec_to_quaternion([gap, -gap, 0.5 * gap])))
    out = rj.slerp(p, q, 0.3)
    theta = float(rj.angle_between(p, q))
    assert_close(rj.angle_between(p, out), 0.3 * theta, atol=1e-15)
    assert_close(rj.angle_between(out, q), 0.7 * theta, atol=1e-15)
    Jp, Jq, _ = _slerp_jacobian(p, q, 0.3)
    assert_close(Jp, fd_jacobian(lambda x: rj.slerp(x, q, 0.3), p), atol=1e-8)
    assert_close(Jq, fd_jacobian(lambda x: rj.slerp(p, x, 0.3), q), atol=1e-8)


def test_slerp_antipodal_is_constant_path():
    p = random_quaternions(1, 34)[0]
    t = np.linspace(-0.5, 1.5, 9)
    path = rj.slerp(p, -p, t)
    assert_close(path, np.broadcast_to(p, (9, 4)), atol=1e-15)
    J = _slerp_jacobian(p, -p, 0.4)
    assert all(np.all(np.isfinite(j)) for j in J)


def test_slerp_t_broadcasts():
    p, q = random_quaternions(2, 35)
    t = np.linspace(0, 1, 7).reshape(7, 1)
    out = rj.slerp(p, np.stack([q, p]), t)
    assert out.shape == (7, 2, 4)
    assert_close(out[:, 1], np.broadcast_to(p, (7, 4)), atol=1e-15)
    check_grads(rj.slerp, (p, q, 0.3), order=1, modes=("fwd", "rev"))


# --- shapes ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("fun", "args"),
    [
        (rj.geodesic_distance, (np.eye(3), np.ones((3, 4)))),
        (rj.chordal_distance, (np.ones((2, 3)), np.eye(3))),
        (rj.sixd_to_matrix, (np.ones(5),)),
        (rj.matrix_to_sixd, (np.ones((3, 2)),)),
        (rj.nined_to_matrix, (np.eye(3),)),
        (rj.slerp, (np.ones(3), np.ones(4), 0.5)),
    ],
    ids=lambda x: getattr(x, "__name__", ""),
)
def test_bad_shapes_raise(fun, args):
    with pytest.raises(ValueError, match="expected shape"):
        fun(*args)
