"""The 4x4 top-eigenvector kernel: accuracy against mpmath, scale, bad input, derivatives."""

import functools

import jax
import jax.numpy as jnp
import mpmath
import numpy as np
import pytest
from helpers import check_hessian, hessian_rows, sweep
from scipy.spatial.transform import Rotation

import rotjax as rj
from rotjax._eigen import _CHUNK, _polar, davenport_k, pow2_scale, top_eigenvector

mpmath.mp.dps = 40
_top = jax.jit(top_eigenvector)
_polar_jit = jax.jit(_polar)  # one program per shape and dtype, shared by the tests
# jitted: one program per shape and dtype (eager, each operation compiles one)
_davenport_k = jax.jit(davenport_k)
_scaled_k = jax.jit(lambda B: davenport_k(pow2_scale(B, (-2, -1))))
_pow2_scale = jax.jit(lambda B: pow2_scale(B, (-2, -1)))


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
    return np.asarray(_davenport_k(M))  # one program per shape (eager: one per operation)


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
    R = Rotation.random(8, random_state=3).as_matrix().astype(dtype)
    q = rj.matrix_to_quaternion(R, method="optimal")
    for s in scales:
        qs = rj.matrix_to_quaternion(R * dtype(s), method="optimal")  # NumPy: no eager op
        np.testing.assert_allclose(qs, q, atol=4 * np.finfo(dtype).eps)


def test_q_method_units():
    rng = np.random.default_rng(4)
    a = rng.standard_normal((5, 3))
    b = a @ Rotation.random(random_state=4).as_matrix() + 1e-3 * rng.standard_normal((5, 3))
    np.testing.assert_allclose(
        rj.align_vectors(5e-5 * a, b, method="q-method"), rj.align_vectors(a, b), atol=1e-15
    )


def test_bad_input_gives_nan():
    x = np.zeros((2, 9))
    x[0, 4] = np.inf
    assert np.isnan(rj.nined_to_matrix(x)).all()  # inf in [0], the zero matrix in [1]
    assert np.isnan(rj.align_vectors(np.ones((3, 3)), np.ones((3, 3)), np.zeros(3))).all()
    assert np.isnan(rj.quaternion_mean(np.ones((3, 4)), np.zeros(3))).all()
    # in a batch run in chunks (padded: not a whole number of chunks), the NaN stays in its own
    # element; the batch of test_chunked_batches_agree_with_one_piece's float64 public call,
    # whose program this shares
    chunk = _CHUNK[np.dtype(np.float64)]
    B = np.broadcast_to(np.eye(3), (2 * chunk + 4, 3, 3)).copy()
    assert len(B) % chunk
    B[5], B[chunk + 1, 1, 2] = 0.0, np.inf
    bad = np.zeros(len(B), bool)
    bad[[5, chunk + 1]] = True
    for f in (
        lambda B: rj.matrix_to_quaternion(B, method="optimal"),
        lambda B: rj.nined_to_matrix(B.reshape(-1, 9)),
    ):
        out = np.asarray(f(B)).reshape(len(B), -1)  # each one compiled program
        assert np.isnan(out[bad]).all() and np.isfinite(out[~bad]).all()
    with pytest.raises(ValueError, match="empty"):
        rj.quaternion_mean(np.ones((0, 4)))


# Special points of the nearest-rotation kernel, stacked as one batch: one set of programs.
POINTS = np.stack(
    [
        np.eye(3),  # identity
        np.diag([1.0, -1.0, -1.0]),  # 180 degrees
        Rotation.from_rotvec([0.3, -1.0, 0.5]).as_matrix(),  # a rotation
        Rotation.from_rotvec([0.3, -1.0, 0.5]).as_matrix()
        + 0.3 * np.random.default_rng(5).standard_normal((3, 3)),  # noisy
    ]
)


@pytest.mark.slow  # compiles the kernel's second-derivative programs
def test_second_derivatives():
    """At the identity, 180 degrees, a rotation and a noisy matrix: ``nined_to_matrix``'s first
    and second derivatives match finite differences (one program for the four points), and the
    full Hessian of the optimal ``matrix_to_quaternion`` is finite (sign-free matrix outputs, so
    the ``w >= 0`` choice at 180 degrees does not matter)."""
    check_hessian(rj.nined_to_matrix, POINTS.reshape(len(POINTS), 9))
    assert np.isfinite(_optimal_hessians()).all()


def _optimal(M):
    return rj.matrix_to_quaternion(M, method="optimal")


@functools.cache
def _optimal_hessians():
    """The Hessians of the optimal ``matrix_to_quaternion`` at the four points, ``(4, 4, 3, 3,
    3, 3)``: ``jax.vmap(jax.hessian(f))`` to rounding (forward over reverse), by
    ``helpers.hessian_rows``' one jitted program (no vmapped ``jacfwd(jacrev)``, slow to
    compile), computed once for the four cases."""
    return hessian_rows(_optimal, POINTS)[3]


@pytest.mark.slow
def test_mean_and_align_hessians_finite():
    """The full Hessians of ``quaternion_mean`` at identical quaternions (ties among the lower
    eigenvalues) and of ``align_vectors`` at orthonormal pairs are finite; the mean's first and
    second derivatives match finite differences there."""
    q = np.tile(np.array([0.1, 0.2, 0.3, 0.9]), (3, 1))
    # jax.hessian's (forward over reverse) Hessians, to rounding, by one jitted program each
    # (helpers.hessian_rows; a leading axis of one row), not a vmapped jacfwd(jacrev); the
    # mean's against differences of its Jacobian in the same program (helpers.check_hessian)
    hess = check_hessian(rj.quaternion_mean, q[None])[0]
    assert hess.shape == (4, 3, 4, 3, 4) and np.isfinite(hess).all()
    a = np.eye(3)
    hess = hessian_rows(lambda a: rj.align_vectors(a, np.eye(3)), a[None])[3][0]
    assert hess.shape == (4, 3, 3, 3, 3) and np.isfinite(hess).all()


def _spectral(lam, seed, n=12):
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.standard_normal((n, 4, 4)))
    return np.einsum("nij,j,nkj->nik", Q, np.asarray(lam, np.float64), Q)


def _from_b(B):
    return np.asarray(_davenport_k(np.asarray(B, np.float64)))


_RNG = np.random.default_rng(21)
_R = Rotation.random(12, random_state=21).as_matrix()
# Inputs where the top eigenvalue ties or nearly ties, or where B is rank deficient: the
# answer is any vector of the (near-)tied space, so the test is the residual, not the vector.
TIES = {
    "triple near-tie (B ~ -R)": _from_b(-_R + 1e-7 * _RNG.standard_normal((12, 3, 3))),
    "exact triple tie (B = -I)": _from_b(-np.broadcast_to(np.eye(3), (12, 3, 3))),
    "rank 1": _from_b(np.einsum("ni,nj->nij", *_RNG.standard_normal((2, 12, 3)))),
    "rank 2": _from_b(_R * np.array([1.0, 0.5, 0.0])),
    "graded": _from_b(np.einsum("nij,j,nkj->nik", _R, [1.0, 1e-6, 1e-12], _R[::-1])),
    "double tie": _spectral([2.0, 2.0, 0.5, -1.0], 22),
    "near-tie 1e-12": _spectral([1.0 + 1e-12, 1.0, 0.3, -0.5], 23),
    "multiple of I": np.broadcast_to(3.0 * np.eye(4), (12, 4, 4)).copy(),
    "zero": np.zeros((12, 4, 4)),
}


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("name", list(CASES) + list(TIES))
def test_top_eigenvector_residual(name, dtype):
    """A unit vector with residual |K v - (v.K v) v| within a few eps |K|, and a Rayleigh
    quotient within a few eps |K| of the top eigenvalue: backward stable, ties included."""
    K = {**CASES, **TIES}[name].astype(dtype)
    v = np.asarray(_top(jnp.asarray(K)), np.float64)
    K = K.astype(np.float64)
    e = np.finfo(dtype).eps
    norm = np.maximum(np.abs(K).max(axis=(-2, -1)), np.finfo(np.float64).tiny)
    assert np.allclose(np.linalg.norm(v, axis=-1), 1.0, atol=4 * e)
    Kv = np.einsum("nij,nj->ni", K, v)
    rho = np.einsum("ni,ni->n", v, Kv)
    assert (np.linalg.norm(Kv - rho[:, None] * v, axis=-1) <= 16 * e * norm).all(), name
    assert (np.linalg.eigvalsh(K)[:, -1] - rho <= 16 * e * norm).all(), name


def test_exact_rotations_under_jit():
    """Exact rotations tie every singular value of B: the kernel's choices (which column is
    smallest, which column of K is largest) must agree across the loops XLA compiles."""
    Q = Rotation.random(512, random_state=31).as_quat()
    Q[:4] = [[0, 0, 0, 1], [1, 0, 0, 0], [0, 1, 0, 0], [1 / np.sqrt(2), 1 / np.sqrt(2), 0, 0]]
    R = Rotation.from_quat(Q).as_matrix()
    for dtype in (np.float32, np.float64):
        q = jax.jit(lambda R: rj.matrix_to_quaternion(R, method="optimal"))(R.astype(dtype))
        dots = np.abs(np.sum(np.asarray(q, np.float64) * Q, axis=-1))
        assert np.abs(dots - 1).max() <= 4 * np.finfo(dtype).eps


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("chunks", sweep([(2, 5), (2, 0)], fast=[(2, 5)]))
def test_chunked_batches_agree_with_one_piece(chunks, dtype):
    """Large batches run in chunks on the CPU (padded where the batch is not a multiple; the
    chunk size depends on the dtype): the same vectors as the kernel applied in one piece, in
    every batch element (up to rounding, which near-ties among random matrices amplify)."""
    from rotjax._eigen import _by_chunks

    whole_chunks, extra = chunks
    n = whole_chunks * _CHUNK[np.dtype(dtype)] + extra
    tol = 1e-12 if dtype == np.float64 else 1e-5  # on 1 - |cos|: angles of 1e-6 and 3e-3
    rng = np.random.default_rng(n)
    B = rng.standard_normal((n, 3, 3)).astype(dtype)  # NumPy: no eager operations below
    chunked, _, (vc, _) = jax.jit(lambda B: _by_chunks(_polar, B))(B)
    whole, _, (vw, _) = _polar_jit(B)
    chunked, vc, whole, vw = (np.asarray(x) for x in (chunked, vc, whole, vw))
    assert chunked.shape == (n, 4) and vc.shape == (n, 3, 3)
    assert np.abs(np.abs(np.sum(chunked * whole, axis=-1)) - 1).max() <= tol
    assert np.abs(np.abs(np.sum(vc * vw, axis=-2)) - 1).max() <= tol  # columns, up to sign
    # a batch of two leading axes through the public function: the same per element
    m = n // 2 * 2
    q = np.asarray(rj.matrix_to_quaternion(B[:m].reshape(2, -1, 3, 3), method="optimal"))
    assert q.shape == (2, m // 2, 4)
    flat = np.asarray(rj.matrix_to_quaternion(B[:m], method="optimal"))
    assert np.abs(np.abs(np.sum(q.reshape(m, 4) * flat, axis=-1)) - 1).max() <= tol


@pytest.mark.parametrize("name", ["gaussian", "sigma=0.3", "det<0", "near-tie"])
def test_the_rules_decomposition(name):
    """The derivative rule's decomposition, from one kernel run on the ``B`` of ``K``: the right
    singular vectors ``V`` are orthonormal and diagonalise ``H = Q^T B`` (prescaled) with the
    signed singular values ``s``, so that ``tr(H) I - H = V diag(s_k + s_l) V^T``; ``sum(s)`` is
    the top eigenvalue of ``K(B)`` and the gaps ``s_k + s_l`` to it are not negative."""
    from rotjax._eigen import _k_to_b

    B = jax.jit(_k_to_b)(CASES[name])
    _, Q, (V, s) = _polar_jit(B)
    Bs = np.asarray(_pow2_scale(B))
    Q, V, s = np.asarray(Q), np.asarray(V), np.asarray(s)
    H = np.swapaxes(Q, -1, -2) @ Bs
    scale = np.abs(Bs).max()
    np.testing.assert_allclose(
        np.swapaxes(V, -1, -2) @ V, np.broadcast_to(np.eye(3), V.shape), atol=1e-14
    )
    np.testing.assert_allclose(H @ V, V * s[:, None, :], atol=1e-13 * scale)
    lam = np.linalg.eigvalsh(np.asarray(_davenport_k(Bs)))
    np.testing.assert_allclose(s.sum(-1), lam[:, -1], atol=1e-13 * scale)
    gaps = s.sum(-1, keepdims=True) - s
    assert (gaps >= -1e-13 * scale).all()


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_nearest_rotation_is_the_matrix_of_nearest_quaternion(dtype):
    """``nined_to_matrix`` returns the kernel's rotation ``Q`` itself, differentiated as the
    matrix of the kernel's quaternion: the two agree to rounding (ties, rank deficiency and
    ``det < 0`` included), and so do their derivatives."""
    from rotjax._eigen import nearest_quaternion, nearest_rotation
    from rotjax._quaternion import quat_to_matrix

    rng = np.random.default_rng(41)
    R = Rotation.random(64, random_state=41).as_matrix()
    B = np.concatenate(
        [
            R + 0.3 * rng.standard_normal((64, 3, 3)),
            -R,  # a triple tie
            R * np.array([1.0, 1.0, -1.0]),  # det < 0
            R * np.array([1.0, 0.5, 0.0]),  # rank 2
            np.einsum("ni,nj->nij", *rng.standard_normal((2, 64, 3))),  # rank 1
            rng.standard_normal((64, 3, 3)),
        ]
    ).astype(dtype)

    def via_q(B):
        return quat_to_matrix(nearest_quaternion(B), bounded=True)  # unit: as _eigen reads it

    # both in one program, and both tangents in one: the kernel's run is shared within each
    Q, Qq = jax.jit(lambda B: (nearest_rotation(B), via_q(B)))(B)
    assert (
        np.abs(np.asarray(Q, np.float64) - np.asarray(Qq, np.float64)).max()
        <= 8 * np.finfo(dtype).eps
    )
    if dtype == np.float64:
        dB = rng.standard_normal(B.shape)
        t, tq = jax.jit(
            lambda B, dB: tuple(jax.jvp(f, (B,), (dB,))[1] for f in (nearest_rotation, via_q))
        )(B, dB)
        assert np.array_equal(np.asarray(t), np.asarray(tq))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_optimal_half_turns_stable_under_rounding(dtype):
    """At 180 degrees the sign of ``w`` is rounding noise: ``"optimal"`` gives ``w`` within
    rounding of 0 and the largest component positive, whatever the rounding of the input (here:
    scalings that are not powers of two, and a transposed rounding)."""
    axes = np.array([[0.0, 0.6, 0.8], [1.0, 0.0, 0.0], [2.0, -3.0, 6.0], [1.0, 1.0, 1.0]])
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    R = (2 * np.einsum("ni,nj->nij", axes, axes) - np.eye(3)).astype(dtype)
    e = np.finfo(dtype).eps
    f = jax.jit(lambda R: rj.matrix_to_quaternion(R, method="optimal"))
    want = np.where(axes[np.arange(4), np.abs(axes).argmax(-1)][:, None] < 0, -axes, axes)
    for M in (R, R * dtype(1e-30), R * dtype(3.0), R * dtype(0.7), np.swapaxes(R, -1, -2)):
        q = np.asarray(f(M), np.float64)
        assert (np.abs(q[:, 3]) <= 4 * e).all()
        assert np.abs(q[:, :3] - want).max() <= 8 * e


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_kernel_singular_values_give_the_eigenvalues(dtype):
    """The derivative rule takes the eigenvalues of ``K`` from the kernel's signed singular
    values ``s`` of the prescaled ``B``: ``sum(s)`` and ``sum(s) - 2 (s_k + s_l)``."""
    rng = np.random.default_rng(43)
    R = Rotation.random(48, random_state=43).as_matrix()
    B = np.concatenate(
        [
            rng.standard_normal((48, 3, 3)),
            R * np.array([1.0, 1.0, -1.0]),  # det < 0
            R * np.array([1.0, 0.5, 0.0]),  # rank 2
            -R,  # a triple tie
            1e-20 * (R + 0.1 * rng.standard_normal((48, 3, 3))),
        ]
    ).astype(dtype)
    _, _, (_, s) = _polar_jit(B)
    s = np.asarray(s, np.float64)
    t = s.sum(-1, keepdims=True)
    lam = np.sort(np.concatenate([t, t - 2 * (t - s)], -1), -1)
    K = np.asarray(_scaled_k(B), np.float64)
    ref = np.linalg.eigvalsh(K)
    assert np.abs(lam - ref).max() <= 16 * np.finfo(dtype).eps * np.abs(ref).max()


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_jacobi_rotation_with_a_tiny_off_diagonal(dtype):
    """Equal column norms and an off-diagonal entry far below the rounding level (rotations at
    gimbal lock, in a batch) ask for a swap with ``|tan theta|`` beyond the square root of the
    largest float: the rotation must stay a rotation (``c`` and ``s`` not both 0)."""
    from rotjax._eigen import _rotation

    tiny = np.finfo(dtype).tiny
    app = np.array([1.0, 1.0, 1.0, 1.0, 2.0], dtype)
    aqq = np.array([1.0 + 4 * np.finfo(dtype).eps, 1.0, 2.0, 1.0, 1.0], dtype)
    apq = np.array([1e3 * tiny, 1e3 * tiny, 0.0, 0.0, 1e3 * tiny], dtype)
    c, s = (np.asarray(x, np.float64) for x in jax.jit(_rotation)(app, aqq, apq))
    assert np.allclose(c * c + s * s, 1.0, atol=4 * np.finfo(dtype).eps)
    # the larger diagonal entry ends first: a swap where a_qq > a_pp
    alpha = c * c * app - 2 * c * s * apq + s * s * aqq
    beta = s * s * app + 2 * c * s * apq + c * c * aqq
    assert (alpha >= beta * (1 - 4 * np.finfo(dtype).eps)).all()


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_exact_rotations_with_ties_in_a_batch(dtype):
    """The benchmark's gimbal-lock and tied rotations (every sequence): exact to a few eps in a
    batch, where XLA:CPU's loops round differently from a single matrix, and with the quaternion
    turned back into a matrix in the same program. The Shepperd column is chosen at a tie of
    diagonal entries there, and a choice made again in each loop that reads it (rounded
    differently) mixed two columns into an orthogonal quaternion."""
    from rotjax._bench import accuracy as A
    from rotjax._bench.runner import SEQS

    acc = A.Accuracy(np.random.default_rng(99), 96, 8, dtype, SEQS)
    names = ("gimbal", "ties", "exact_180")
    sets = [np.asarray(acc.msets[name]) for name in names]
    M = np.concatenate(sets)  # one batch: one program per function
    ends = np.cumsum([len(m) for m in sets])
    for f in (
        lambda R: rj.quaternion_to_matrix(rj.matrix_to_quaternion(R, method="optimal")),
        lambda R: rj.nined_to_matrix(R.reshape(-1, 9)),
    ):
        err = np.abs(np.asarray(jax.jit(f)(M), np.float64) - M.astype(np.float64)).max(axis=(1, 2))
        for name, part in zip(names, np.split(err, ends[:-1]), strict=True):
            assert part.max() <= 8 * np.finfo(dtype).eps, name


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize(
    ("scale", "noise"),
    sweep(
        [(1.1, 0.05), (1.0, 0.01), (1.0, 0.3), (-1.0, 0.3), (1.0, 1.0)],
        fast=[(-1.0, 0.3)],
        several=True,
    ),
)
def test_kernel_converges_on_many_noisy_matrices(scale, noise, dtype):
    """The fixed rotation schedule converges for every matrix of a large sample, not only on
    average: a backward-stable top eigenvector of K (residual within a few eps |K|) for 20000
    noisy rotations (scale -1: det < 0); a sweep fewer, or a last sweep without the rotations of
    the largest column, leaves thousands of them off by 1e2-1e4 eps."""
    R = Rotation.random(20000, random_state=47).as_matrix()
    B = (scale * R + noise * np.random.default_rng(47).standard_normal(R.shape)).astype(dtype)
    v = np.asarray(_polar_jit(B)[0], np.float64)
    K = np.asarray(_scaled_k(B), np.float64)
    Kv = np.einsum("nij,nj->ni", K, v)
    rho = np.einsum("ni,ni->n", v, Kv)
    res = np.linalg.norm(Kv - rho[:, None] * v, axis=-1) / np.abs(K).max(axis=(-2, -1))
    assert res.max() <= 16 * np.finfo(dtype).eps


@pytest.mark.slow
def test_rules_equal_jax_derivative_of_the_kernel_code():
    """The derivative rules of ``nearest_quaternion`` and ``nearest_rotation`` equal JAX's own
    derivative of the forward code (the Jacobi sweeps, the rotation from the columns and the
    extraction, differentiated by autodiff), first and second order, off ties: noisy
    rotations, ``det < 0``, random and scaled matrices."""
    from rotjax._eigen import _polar, nearest_quaternion, nearest_rotation

    rng = np.random.default_rng(53)
    R = Rotation.random(4, random_state=53).as_matrix()
    Bs = [
        R[0] + 0.3 * rng.standard_normal((3, 3)),
        R[1] * np.array([1.0, 1.0, -1.0]) + 0.1 * rng.standard_normal((3, 3)),
        rng.standard_normal((3, 3)),
        1e-5 * (R[3] + 0.1 * rng.standard_normal((3, 3))),
    ]
    d1, d2 = np.stack([rng.standard_normal((2, 3, 3)) for _ in Bs], axis=1)  # per B: d1, d2

    # the four matrices as one batch (the derivatives are per matrix): one eager pass
    B, d1, d2 = map(jnp.asarray, (np.stack(Bs), d1, d2))

    def t_and_h(f):
        """The first and second directional derivatives of ``f`` at ``B``."""
        return jax.jvp(lambda b: jax.jvp(f, (b,), (d1,))[1], (B,), (d2,))

    for rule, code in (
        (nearest_quaternion, lambda b: _polar(b)[0]),
        (nearest_rotation, lambda b: _polar(b)[1]),
    ):
        (t, h), (t_code, h_code) = t_and_h(rule), t_and_h(code)
        # per matrix B
        t, h, t_code, h_code = (np.asarray(x).reshape(len(Bs), -1) for x in (t, h, t_code, h_code))
        assert (np.abs(t - t_code).max(-1) <= 1e-12 * np.abs(t_code).max(-1)).all()
        assert (np.abs(h - h_code).max(-1) <= 1e-10 * np.abs(h_code).max(-1)).all()
