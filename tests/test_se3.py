"""Lie calculus of SO(3) and SE(3): hat/vee, the Jacobians of the exponential map and their
inverses, se3_exp/se3_log and the adjoint.

Oracles: scipy's RigidTransform (exponential coordinates), scipy.linalg.expm, jax.jacfwd of
exp/log compositions (the Jacobians' defining relations), and mpmath's power series of the
exponential and of its Jacobians (sum ad^n / (n+1)!) at 50 digits, which are independent of
the closed forms and judge tiny angles, the series/closed-form switch and 180 degrees."""

import functools

import jax
import jax.numpy as jnp
import mpmath as mp
import numpy as np
import pytest
from helpers import assert_close, forward_hessian_rows, jacobian_rows, sweep
from scipy.linalg import expm
from scipy.spatial.transform import RigidTransform as SRigid

import rotjax as rj

RNG = np.random.default_rng(3535)
EPS = {np.float32: float(np.finfo(np.float32).eps), np.float64: float(np.finfo(np.float64).eps)}


def _unit(n, seed):
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# Angles: zero, tiny, around the series' cut at t = 1, generic, up to and at pi.
ANGLES = np.array(
    [0.0, 1e-300, 1e-150, 1e-20, 1e-8, 1e-4, 0.1, 0.5, 0.999, 1.0, 1.001, 1.7, 2.5, 3.0]
    + [np.pi - 1e-6, np.pi - 1e-12, np.pi]
)
AXES = _unit(len(ANGLES), 1)
ROTVECS = ANGLES[:, None] * AXES
XIS = np.concatenate([ROTVECS, RNG.normal(size=(len(ANGLES), 3)) * 2], axis=-1)


def _homogeneous(R, t):
    T = np.zeros((*np.shape(R)[:-2], 4, 4))
    T[..., :3, :3], T[..., :3, 3], T[..., 3, 3] = R, t, 1
    return T


# --- mpmath references (power series, 50 digits) ------------------------------------------

mp.mp.dps = 50


def _mp_hat(v):
    x, y, z = v
    return mp.matrix([[0, -z, y], [z, 0, -x], [-y, x, 0]])


def _mp_ad(xi):
    """ad of se(3) in the [rotation, translation] order: [[P, 0], [V, P]]."""
    P, V = _mp_hat(xi[:3]), _mp_hat(xi[3:])
    A = mp.zeros(6, 6)
    for i in range(3):
        for j in range(3):
            A[i, j] = A[i + 3, j + 3] = P[i, j]
            A[i + 3, j] = V[i, j]
    return A


def _mp_series(A, shift):
    """sum_n A^n / (n + shift)!, to 50 digits (|A| stays below 8 here)."""
    n = A.rows
    out, term = mp.zeros(n, n), mp.eye(n)
    for k in range(200):
        out += term / mp.factorial(k + shift)
        term = term * A
        if k > 20 and mp.mnorm(term, 1) / mp.factorial(k + shift) < mp.mpf(10) ** -60:
            break
    return out


def _mp_twist(xi):
    T = mp.zeros(4, 4)
    P = _mp_hat(xi[:3])
    for i in range(3):
        for j in range(3):
            T[i, j] = P[i, j]
        T[i, 3] = xi[3 + i]
    return T


def _np(m):
    return np.array(m.tolist(), dtype=float)


def _mp_vec(x):
    return [mp.mpf(float(v)) for v in x]


@functools.cache
def _mp_jacobian(group, sign, x):
    """The series sum (sign ad)^n / (n+1)! of se(3) or so(3) at the mpf coordinates ``x`` (a
    tuple): a Jacobian, computed once for it and its inverse."""
    A = _mp_ad(x) if group == "se3" else _mp_hat(x[:3])
    return _mp_series(A if sign > 0 else -A, 1)


_MP_FUNS = {  # reference exp, Jl, Jr and inverses of SE(3) and SO(3), of mpf coordinates
    "se3_exp": lambda x: _mp_series(_mp_twist(x), 0),
    "se3_left_jacobian": lambda x: _mp_jacobian("se3", 1, tuple(x)),
    "se3_right_jacobian": lambda x: _mp_jacobian("se3", -1, tuple(x)),
    "se3_left_jacobian_inverse": lambda x: mp.inverse(_mp_jacobian("se3", 1, tuple(x))),
    "se3_right_jacobian_inverse": lambda x: mp.inverse(_mp_jacobian("se3", -1, tuple(x))),
    "so3_left_jacobian": lambda x: _mp_jacobian("so3", 1, tuple(x[:3])),
    "so3_right_jacobian": lambda x: _mp_jacobian("so3", -1, tuple(x[:3])),
    "so3_left_jacobian_inverse": lambda x: mp.inverse(_mp_jacobian("so3", 1, tuple(x[:3]))),
    "so3_right_jacobian_inverse": lambda x: mp.inverse(_mp_jacobian("so3", -1, tuple(x[:3]))),
}
SE3_FUNS = [f for f in _MP_FUNS if f.startswith("se3")]
SO3_FUNS = [f for f in _MP_FUNS if f.startswith("so3")]


@functools.cache
def mp_refs(name, dtype):
    """``name``'s references at each of XIS, as float64 arrays; for float32 at the
    float32-rounded inputs (float32 rounds the angle, which moves the result). Computed when
    a test first asks (not at collection, in every worker)."""
    xis = XIS if dtype == np.float64 else XIS.astype(np.float32).astype(np.float64)
    return [_np(_MP_FUNS[name](_mp_vec(xi))) for xi in xis]


@pytest.mark.parametrize("dtype", [np.float32, np.float64], ids=lambda d: d.__name__)
@pytest.mark.parametrize("name", sweep(SE3_FUNS + SO3_FUNS, fast=(SE3_FUNS + SO3_FUNS)[::3]))
def test_against_mpmath_series(name, dtype):
    """Every angle of ANGLES (0, 1e-300, tiny, both sides of the series' cut at t = 1, up to
    pi): within 4 eps of the 50-digit series, relative to the largest entry (or 1). The
    inverses at pi are finite (only multiples of 2 pi are singular). The largest measured
    (float64) is below 2 eps."""
    x = XIS.astype(dtype)
    arg = x if name.startswith("se3") else x[:, :3]
    got = np.asarray(getattr(rj, name)(arg))
    assert got.dtype == dtype
    for i, want in enumerate(mp_refs(name, dtype)):
        err = np.abs(got[i] - want).max() / max(1.0, np.abs(want).max())
        assert np.isfinite(got[i]).all()
        assert err <= 4 * EPS[dtype], (name, ANGLES[i], err / EPS[dtype])


def test_se3_log_is_the_inverse_of_the_mpmath_exponential():
    """log(T) for T the exp of XIS rounded to float64: the 50-digit exp of the result is T to
    4 eps (a backward error: at pi the log's direction is ill-conditioned, its exp is not);
    below pi the log is also the original coordinates to 4 eps times the condition number
    1 / sin-like factor (|xi| eps / (pi - t) at worst, so a plain 64 eps off pi)."""
    T = np.stack(mp_refs("se3_exp", np.float64))
    logs = np.asarray(rj.se3_log(T))
    for i, xi in enumerate(logs):
        back = _np(_mp_series(_mp_twist(_mp_vec(xi)), 0))
        err = np.abs(back - T[i]).max() / max(1.0, np.abs(T[i]).max())
        assert err <= 4 * EPS[np.float64], (ANGLES[i], err / EPS[np.float64])
        if ANGLES[i] < 3.0:
            assert_close(xi, XIS[i], atol=64 * EPS[np.float64] * max(1, np.abs(XIS[i]).max()))


# --- scipy ---------------------------------------------------------------------------------


@pytest.mark.parametrize("dtype", [np.float32, np.float64], ids=lambda d: d.__name__)
def test_exp_and_log_match_scipy_rigid_transform(dtype):
    xi = np.concatenate([RNG.normal(size=(500, 3)), RNG.normal(size=(500, 3)) * 3], axis=-1)
    xi = np.concatenate([xi, XIS])
    xi = xi.astype(dtype).astype(np.float64)  # the values both see
    T = np.asarray(rj.se3_exp(xi.astype(dtype)))
    want = SRigid.from_exp_coords(xi).as_matrix()
    eps = EPS[dtype]
    assert T.dtype == dtype
    assert_close(T, want, atol=8 * eps * max(1, np.abs(want).max()))
    # logs of scipy's transforms, away from pi (where both rotation vectors are right)
    T64 = want[np.linalg.norm(xi[:, :3], axis=-1) < 3.0]
    got = np.asarray(rj.se3_log(T64.astype(dtype)), np.float64)
    ref = SRigid.from_matrix(T64.astype(dtype).astype(np.float64)).as_exp_coords()
    assert_close(got, ref, atol=64 * eps * max(1, np.abs(ref).max()))


def test_exp_is_the_matrix_exponential_of_hat():
    xi = np.concatenate([RNG.normal(size=(20, 6)), XIS])
    want = np.stack([expm(m) for m in np.asarray(rj.hat(xi))])
    assert_close(rj.se3_exp(xi), want, atol=1e-14 * np.abs(want).max())


# --- hat, vee, adjoint ----------------------------------------------------------------------


def test_hat_and_vee():
    v, u = RNG.normal(size=(2, 5, 3))
    H = np.asarray(rj.hat(v))
    assert H.shape == (5, 3, 3)
    assert_close(np.einsum("nij,nj->ni", H, u), np.cross(v, u), atol=1e-15)
    assert_close(rj.vee(H), v, atol=0)
    sym = RNG.normal(size=(5, 3, 3))
    assert_close(rj.vee(H + sym + np.swapaxes(sym, -1, -2)), v, atol=1e-15)
    xi = RNG.normal(size=(5, 6))
    W = np.asarray(rj.hat(xi))
    assert W.shape == (5, 4, 4)
    assert_close(W[:, :3, :3], rj.hat(xi[:, :3]), atol=0)
    assert_close(W[:, :3, 3], xi[:, 3:], atol=0)
    assert not np.any(W[:, 3])
    assert_close(rj.vee(W), xi, atol=0)
    assert rj.hat(v.astype(np.float32)).dtype == np.float32
    assert rj.vee(W.astype(np.float32)).dtype == np.float32
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\) or \(\.\.\., 6\)"):
        rj.hat(np.zeros(4))
    with pytest.raises(ValueError, match=r"\(\.\.\., 3, 3\) or \(\.\.\., 4, 4\)"):
        rj.vee(np.zeros((3, 4)))


def test_adjoint():
    """exp(Ad_T xi) = T exp(xi) T^-1, Ad of a product is the product of Ads, and Ad maps a
    right perturbation to a left one: T exp(d) = exp(Ad_T d) T."""
    T = SRigid.from_exp_coords(RNG.normal(size=(10, 6)) * 2).as_matrix()
    T2 = SRigid.from_exp_coords(RNG.normal(size=(10, 6))).as_matrix()
    xi = RNG.normal(size=(10, 6))
    Ad = np.asarray(rj.se3_adjoint(T))
    lhs = rj.se3_exp(np.einsum("nij,nj->ni", Ad, xi))
    rhs = T @ np.asarray(rj.se3_exp(xi)) @ np.linalg.inv(T)
    assert_close(lhs, rhs, atol=1e-13)
    assert_close(rj.se3_adjoint(T @ T2), Ad @ np.asarray(rj.se3_adjoint(T2)), atol=1e-13)
    # Jl(xi) = Ad(exp(xi)) Jr(xi), and the same for SO(3) with R
    x = np.concatenate([XIS, xi])
    E = rj.se3_exp(x)
    assert_close(
        rj.se3_left_jacobian(x), rj.se3_adjoint(E) @ rj.se3_right_jacobian(x), atol=4e-15 * 8
    )
    assert_close(
        rj.so3_left_jacobian(x[:, :3]),
        np.asarray(E)[:, :3, :3] @ np.asarray(rj.so3_right_jacobian(x[:, :3])),
        atol=2e-15,
    )


# --- the defining relations, by jax.jacfwd ---------------------------------------------------

# points where the Jacobians are checked by their definitions (angles below pi: the log's cut)
DEF_XIS = np.concatenate([XIS[ANGLES < 3.1], RNG.normal(size=(4, 6))])


def _inv(T):
    R, t = T[..., :3, :3], T[..., :3, 3]
    Rt = jnp.swapaxes(R, -1, -2)
    top = jnp.concatenate([Rt, -(Rt @ t[..., None])], axis=-1)
    return jnp.concatenate([top, T[..., 3:, :]], axis=-2)


def _defining(d, x):
    """log(exp(x)^-1 exp(x + d)), log(exp(x + d) exp(x)^-1), log(exp(x) exp(d)) and
    log(exp(d) exp(x)), batched: their Jacobians in d at 0 are the right, left, right inverse
    and left inverse Jacobians at x."""
    E = rj.se3_exp(x)
    return (
        rj.se3_log(_inv(E) @ rj.se3_exp(x + d)),
        rj.se3_log(rj.se3_exp(x + d) @ _inv(E)),
        rj.se3_log(E @ rj.se3_exp(d)),
        rj.se3_log(rj.se3_exp(d) @ E),
    )


def test_se3_jacobians_by_their_definitions():
    got = jacobian_rows(_defining, np.zeros_like(DEF_XIS), DEF_XIS)
    names = ("right_jacobian", "left_jacobian", "right_jacobian_inverse", "left_jacobian_inverse")
    for name, J in zip(names, got, strict=True):
        want = np.asarray(getattr(rj, "se3_" + name)(DEF_XIS))
        err = np.abs(np.asarray(J) - want).max(axis=(1, 2)) / np.maximum(
            1, np.abs(want).max(axis=(1, 2))
        )
        assert err.max() <= 64 * EPS[np.float64], (name, err / EPS[np.float64])


def test_so3_jacobians_by_their_definitions():
    def defining(d, p):
        R = rj.rotvec_to_matrix(p)
        Rt = jnp.swapaxes(R, -1, -2)
        return (
            rj.matrix_to_rotvec(Rt @ rj.rotvec_to_matrix(p + d)),
            rj.matrix_to_rotvec(rj.rotvec_to_matrix(p + d) @ Rt),
            rj.matrix_to_rotvec(R @ rj.rotvec_to_matrix(d)),
            rj.matrix_to_rotvec(rj.rotvec_to_matrix(d) @ R),
        )

    p = DEF_XIS[:, :3]
    got = jacobian_rows(defining, np.zeros_like(p), p)
    names = ("right_jacobian", "left_jacobian", "right_jacobian_inverse", "left_jacobian_inverse")
    for name, J in zip(names, got, strict=True):
        want = np.asarray(getattr(rj, "so3_" + name)(p))
        assert_close(J, want, atol=64 * EPS[np.float64], err_msg=name)


def test_inverses_are_inverses():
    x = np.concatenate([XIS, RNG.normal(size=(20, 6)) * 2])
    for grp, n in (("se3", 6), ("so3", 3)):
        arg = x if grp == "se3" else x[:, :3]
        for side in ("left", "right"):
            J = np.asarray(getattr(rj, f"{grp}_{side}_jacobian")(arg))
            Ji = np.asarray(getattr(rj, f"{grp}_{side}_jacobian_inverse")(arg))
            assert_close(Ji @ J, np.broadcast_to(np.eye(n), J.shape), atol=1e-13)


# --- derivatives: finite and exact at 0, 1e-300 and up to pi --------------------------------

SPECIAL = np.concatenate(
    [
        np.zeros((1, 6)),
        np.full((1, 6), 1e-300),
        np.concatenate([1e-300 * _unit(1, 5), RNG.normal(size=(1, 3))], -1),
        XIS[ANGLES >= 3.0],
    ]
)


@pytest.mark.parametrize(
    "name",
    sweep(
        ["se3_exp", "se3_log", "se3_adjoint", *SE3_FUNS[1:], *SO3_FUNS, "hat", "vee"],
        fast=["se3_log", "se3_adjoint", "hat", "vee"],
    ),
)
def test_first_and_second_derivatives_are_finite_at_singular_points(name):
    f = getattr(rj, name)
    if name in ("se3_log", "se3_adjoint"):
        args = np.asarray(rj.se3_exp(SPECIAL))
    elif name == "vee":
        args = np.asarray(rj.hat(SPECIAL[:, :3]))
    else:
        args = SPECIAL if name.startswith("se3") else SPECIAL[:, :3]

    def total(a):  # a weighted sum of each point's outputs, summed over the points
        y = f(a)
        return jnp.sum(y * jnp.arange(1.0, 1 + y[0].size).reshape(1, *y.shape[1:]))

    # One compiled program for the Jacobian of f and the Hessian of total (forward over the
    # reverse gradient), at every point of the batch.
    J, H = jacobian_rows(lambda a: (f(a), jax.grad(total)(a)), args)
    assert np.isfinite(J).all() and np.isfinite(H).all(), name
    assert np.any(J[0]) and np.any(J[1])


ROUND_TRIP_XIS = np.concatenate([SPECIAL[:3], DEF_XIS, XIS[ANGLES == np.pi - 1e-6]])


def _round_trip(v):
    return rj.se3_log(rj.se3_exp(v))


def test_log_of_exp_has_identity_derivative():
    """d log(exp(x)) / dx = I at 0, 1e-300, tiny, at the series' cut and up to pi - 1e-6:
    exercises the first derivatives of every coefficient, through both branches and their
    switch."""
    J = jacobian_rows(_round_trip, ROUND_TRIP_XIS)
    assert_close(J, np.broadcast_to(np.eye(6), J.shape), atol=1e-9)
    small = np.linalg.norm(ROUND_TRIP_XIS[:, :3], axis=-1) < 3
    assert_close(J[small], np.broadcast_to(np.eye(6), J[small].shape), atol=64 * EPS[np.float64])


@pytest.mark.slow
def test_log_of_exp_has_identity_derivative_and_zero_second_derivative():
    """d log(exp(x)) / dx = I and d^2 = 0 at the same points: the second derivatives of every
    coefficient, through both branches and their switch."""
    x = ROUND_TRIP_XIS
    # one program: the first and (forward over forward) second derivatives
    J, H = forward_hessian_rows(_round_trip, x)
    assert_close(J, np.broadcast_to(np.eye(6), J.shape), atol=1e-9)
    small = np.linalg.norm(x[:, :3], axis=-1) < 3
    assert_close(J[small], np.broadcast_to(np.eye(6), J[small].shape), atol=64 * EPS[np.float64])
    assert_close(H[small], np.zeros(H[small].shape), atol=1e-11)


def test_derivatives_at_zero_are_exact():
    """At 0: d exp(xi) = hat(d xi); d Jl(p)[., .] / dp = hat(.)/2, d Jr = -hat/2, and the
    second derivative of Jl at 0 is that of the series, (P^2)/6's."""
    D = np.asarray(jax.jit(jax.jacfwd(rj.se3_exp))(jnp.zeros(6)))
    for i in range(6):
        assert_close(D[..., i], rj.hat(np.eye(6)[i]), atol=0)

    def derivatives(p):
        def jl(p):  # reverse mode, differentiated again as jax.hessian does; forward as aux
            return jax.jacrev(rj.so3_left_jacobian)(p), jax.jacfwd(rj.so3_left_jacobian)(p)

        H, dJl = jax.jacfwd(jl, has_aux=True)(p)
        return dJl, jax.jacfwd(rj.so3_right_jacobian)(p), H

    # one program, at both points
    p0 = jnp.asarray(np.stack([np.zeros(3), np.full(3, 1e-300)]))
    dJls, dJrs, Hs = (np.asarray(a) for a in jax.jit(jax.vmap(derivatives))(p0))
    e = np.eye(3)
    E = [np.asarray(rj.hat(e[i])) for i in range(3)]
    for dJl, dJr, H in zip(dJls, dJrs, Hs, strict=True):
        for i in range(3):
            # (at 1e-300 the exact derivative differs from that at 0 by O(1e-300))
            assert_close(dJl[..., i], E[i] / 2, atol=1e-299)
            assert_close(dJr[..., i], -E[i] / 2, atol=1e-299)
        for i in range(3):
            for j in range(3):
                assert_close(H[..., i, j], (E[i] @ E[j] + E[j] @ E[i]) / 6, atol=1e-16)


# --- shapes, dtypes, errors -------------------------------------------------------------


@pytest.mark.parametrize("batch", [(), (2,), (2, 3)], ids=str)
def test_batch_shapes_and_dtypes(batch):
    """Output shapes and dtypes of every function at each batch shape, float32 in, float32
    out (integers promote to the default float). Traced, not run: shapes and dtypes are fixed
    by tracing."""

    def out(name, x):
        return jax.eval_shape(getattr(rj, name), x)

    xi = jax.ShapeDtypeStruct((*batch, 6), np.float32)
    T = out("se3_exp", xi)
    assert (T.shape, T.dtype) == ((*batch, 4, 4), np.float32)
    log = out("se3_log", T)
    assert (log.shape, log.dtype) == ((*batch, 6), np.float32)
    assert out("se3_adjoint", T).shape == (*batch, 6, 6)
    for name in SE3_FUNS[1:]:
        assert (out(name, xi).shape, out(name, xi).dtype) == ((*batch, 6, 6), np.float32)
    p = jax.ShapeDtypeStruct((*batch, 3), np.float32)
    for name in SO3_FUNS:
        assert out(name, p).shape == (*batch, 3, 3)
    assert rj.se3_exp(np.zeros(6, int)).dtype == np.float64


def test_wrong_shapes_raise():
    with pytest.raises(ValueError, match=r"xi: expected shape \(\.\.\., 6\)"):
        rj.se3_exp(np.zeros(3))
    with pytest.raises(ValueError, match=r"T: expected shape \(\.\.\., 4, 4\)"):
        rj.se3_log(np.eye(3))
    with pytest.raises(ValueError, match=r"rotvec: expected shape \(\.\.\., 3\)"):
        rj.so3_left_jacobian(np.zeros(6))


def test_nan_stays_in_its_element():
    xi = RNG.normal(size=(3, 6))
    xi[1, 2] = np.nan
    out = np.asarray(rj.se3_exp(xi))
    assert np.isnan(out[1]).any() and np.isfinite(out[[0, 2]]).all()
    T = np.array(rj.se3_exp(RNG.normal(size=(3, 6))))
    T[1, 0, 0] = np.nan
    out = np.asarray(rj.se3_log(T))
    assert np.isnan(out[1]).all() and np.isfinite(out[[0, 2]]).all()


# --- the benchmark's accuracy rows ----------------------------------------------------------


@pytest.mark.parametrize(
    "op", ["se3_exp", "se3_log", "rigid_apply", "so3_right_jacobian", "so3_jlog"]
)
def test_benchmark_accuracy_rows(op):
    """The benchmark's accuracy pass for these rows runs, reports every basic set, and finds
    rotjax within 5 float64 eps of its mpmath references (near 0 and near 180 degrees too)."""
    from rotjax._bench import accuracy as A
    from rotjax._bench import cases as C

    acc = A.Accuracy(np.random.default_rng(4), 4, 1, "float64", ["xyz"])
    case = C.CASES[op]
    fn = next(c.fn for c in case.contenders({}) if c.impl == "rotjax")
    errs = A.errors(case, fn, "rotjax", acc, jnp.float64)
    assert set(errs) == set(A.BASIC_SETS)
    for k, e in errs.items():
        assert len(e) == 4 and np.all(np.isfinite(e)), (op, k)
        assert e.max() <= 5.0, (op, k, e.max())
