"""Every finite scale: functions that read a quaternion or a matrix as a rotation give the same
answer, to a few eps, for ``s q`` and ``s R`` as for ``q`` and ``R`` (float32 from 1e-30 to
1e30, float64 from 1e-300 to 1e300), with the same gradient up to the factor ``1 / s``; the
zero matrix and any non-finite component give NaN in their own batch element only; and the
Euler angles' gradients stay finite and right at every distance from gimbal lock."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import ORACLE_BATCH, SEQS, angle_diff, assert_close, random_quaternions
from scipy.spatial.transform import Rotation

import rotjax as rj
from rotjax._euler import _abcd_patterns, _layout

SCALES = {
    np.float32: [1e-30, 3e-20, 1e-10, 7e9, 1e20, 1e30],
    np.float64: [1e-300, 3e-160, 1e-80, 7e79, 1e160, 1e300],
}
CASES = [(dt, s) for dt, scales in SCALES.items() for s in scales]
IDS = [f"{np.dtype(dt).name}-{s:g}" for dt, s in CASES]


Q = np.concatenate([random_quaternions(6, seed=41), [[0.0, 0, 0, 1], [0.0, 0.6, 0.8, 0]]])
P = random_quaternions(8, seed=42)
R = Rotation.from_quat(Q).as_matrix()  # by scipy: nothing compiled at import
V = np.random.default_rng(43).normal(size=(8, 3))


def _integrate(q, method):
    return rj.integrate_angular_velocity(q, V.astype(q.dtype), 0.1, method=method)


QUATERNION_FUNCTIONS = {
    "quaternion_to_matrix": rj.quaternion_to_matrix,
    "quaternion_to_euler_ZXZ": lambda q: rj.quaternion_to_euler(q, "ZXZ"),
    "quaternion_to_euler_xyz": lambda q: rj.quaternion_to_euler(q, "xyz"),
    "quaternion_to_rotvec": rj.quaternion_to_rotvec,
    "quaternion_to_axis_angle": lambda q: jnp.concatenate(
        [a[..., None] if a.ndim == 1 else a for a in rj.quaternion_to_axis_angle(q)], axis=-1
    ),
    "rotation_angle": rj.rotation_angle,
    "angle_between": lambda q: rj.angle_between(P.astype(q.dtype), q),
    "quaternion_apply": lambda q: rj.quaternion_apply(q, V.astype(q.dtype)),
    "quaternion_normalize": rj.quaternion_normalize,
    "relative_rotation": lambda q: rj.relative_rotation(q, P.astype(q.dtype)),
    "quaternion_to_mrp": rj.quaternion_to_mrp,
    "slerp_from": lambda q: rj.slerp(q, P.astype(q.dtype), 0.3),
    "slerp_to": lambda q: rj.slerp(P.astype(q.dtype), q, 0.3),
    "quaternion_reduce": lambda q: rj.quaternion_reduce(q, left=P[:3].astype(q.dtype))[0],
    **{
        f"integrate_{m}": functools.partial(_integrate, method=m)
        for m in ("euler", "exponential", "rk4")
    },
    "integrate_samples": lambda q: jnp.moveaxis(
        rj.integrate_angular_velocity_samples(q, jnp.stack([V, -V, V]).astype(q.dtype), 0.1), 0, 1
    ),
}
# Functions linear in q: -q gives the negated output.
SIGNED = {"quaternion_normalize", "relative_rotation", "slerp_from", "quaternion_reduce"}
SIGNED |= {name for name in QUATERNION_FUNCTIONS if name.startswith("integrate")}
MATRIX_FUNCTIONS = {
    "matrix_to_quaternion_shepperd": rj.matrix_to_quaternion,
    "matrix_to_quaternion_markley": lambda m: rj.matrix_to_quaternion(m, method="markley"),
    "matrix_to_quaternion_optimal": lambda m: rj.matrix_to_quaternion(m, method="optimal"),
    "matrix_to_euler_ZXZ": lambda m: rj.matrix_to_euler(m, "ZXZ"),
    "matrix_to_euler_zyx": lambda m: rj.matrix_to_euler(m, "zyx"),
    "matrix_to_rotvec": rj.matrix_to_rotvec,
}


def _jit_all(fns):
    return {k: jax.jit(f) for k, f in fns.items()}


_QF, _MF = _jit_all(QUATERNION_FUNCTIONS), _jit_all(MATRIX_FUNCTIONS)


def _both_angle_args(q):
    """angle_between reads both arguments as rotations: scale the first one too."""
    return rj.angle_between(q, q[::-1])


def _assert_same(name, got, want, atol):
    """Euler angles compared modulo 2 pi (at 180 degrees, pi and -pi are one angle)."""
    if "euler" in name:
        got, want = angle_diff(got, want), np.zeros(np.shape(want))
    assert_close(got, want, atol=atol, err_msg=name)


@pytest.mark.parametrize(("dtype", "scale"), CASES, ids=IDS)
def test_quaternion_functions_are_scale_invariant(dtype, scale):
    q = Q.astype(dtype)
    eps = np.finfo(dtype).eps
    for name, f in _QF.items():
        _assert_same(name, f(q * dtype(scale)), f(q), 8 * eps)
        # -q is the same rotation (the last one, 180 degrees, where some outputs jump, left out)
        want = np.asarray(f(q))[:-1]
        want = -want if name in SIGNED else want
        got = np.asarray(f(q * dtype(-scale)))[:-1]
        _assert_same(name, got, want, 8 * eps)
    got = np.asarray(jax.jit(_both_angle_args)(q * dtype(scale)))
    assert_close(got, np.asarray(jax.jit(_both_angle_args)(q)), atol=8 * eps)


@pytest.mark.parametrize(("dtype", "scale"), CASES, ids=IDS)
def test_matrix_functions_are_scale_invariant(dtype, scale):
    m = R.astype(dtype)
    eps = np.finfo(dtype).eps
    for name, f in _MF.items():
        want = np.asarray(f(m))
        got = np.asarray(f(m * dtype(scale)))
        _assert_same(name, got, want, 8 * eps)
        if name.startswith("matrix_to_quaternion"):  # a unit quaternion, w >= 0
            assert_close(np.linalg.norm(got.astype(np.float64), axis=-1), 1.0, atol=4 * eps)


@pytest.mark.parametrize("dtype", list(SCALES))
def test_matrix_to_quaternion_is_a_unit_quaternion_for_any_nonzero_matrix(dtype):
    """Random matrices (not rotations) over the whole scale range, every method."""
    rng = np.random.default_rng(44)
    lo, hi = np.log10(SCALES[dtype][0]), np.log10(SCALES[dtype][-1])
    m = rng.normal(size=(16, 3, 3)) * 10.0 ** rng.uniform(lo, hi, size=(16, 1, 1))
    m = m.astype(dtype)
    for method in ("shepperd", "markley", "optimal"):
        q = np.asarray(rj.matrix_to_quaternion(m, method=method)).astype(np.float64)
        assert_close(np.linalg.norm(q, axis=-1), 1.0, atol=8 * np.finfo(dtype).eps)


GRAD_FUNCTIONS = {
    "quaternion_to_matrix": (rj.quaternion_to_matrix, False),
    "quaternion_to_euler": (lambda q: rj.quaternion_to_euler(q, "ZYX"), False),
    "quaternion_to_rotvec": (rj.quaternion_to_rotvec, False),
    "rotation_angle": (rj.rotation_angle, False),
    "matrix_to_quaternion": (rj.matrix_to_quaternion, True),
    "matrix_to_quaternion_markley": (
        lambda m: rj.matrix_to_quaternion(m, method="markley"),
        True,
    ),
    "matrix_to_euler": (lambda m: rj.matrix_to_euler(m, "ZYX"), True),
    "matrix_to_rotvec": (rj.matrix_to_rotvec, True),
}


@pytest.mark.parametrize("name", sorted(GRAD_FUNCTIONS))
def test_gradient_at_any_scale_is_the_unit_gradient_over_the_scale(name):
    """f(s x) = f(x), so grad f at s x is grad f at x divided by s: the power-of-two
    prescaling passes the derivative through (its own derivative is zero)."""
    f, is_matrix = GRAD_FUNCTIONS[name]
    x = (R if is_matrix else Q)[:4]
    rng = np.random.default_rng(45)
    w = jnp.asarray(rng.normal(size=jax.eval_shape(f, x).shape))  # f's output shape
    g = jax.jit(jax.grad(lambda v: jnp.sum(w * f(v))))
    g1 = np.asarray(g(jnp.asarray(x)))
    for s in (2.0**-900, 1e-200, 3.0, 1e200):
        assert_close(np.asarray(g(jnp.asarray(x * s))) * s, g1, atol=1e-13 * np.abs(g1).max())


# --- non-rotations: NaN, in their own batch element -------------------------------------------

BAD_MATRICES = {
    "zero": np.zeros((3, 3)),
    "inf": np.where(np.eye(3) > 0, np.inf, 0.0),
    "one_inf": np.eye(3) + np.where(np.arange(9).reshape(3, 3) == 5, np.inf, 0.0),
    "nan": np.full((3, 3), np.nan),
}


@pytest.mark.parametrize("bad", sorted(BAD_MATRICES))
@pytest.mark.parametrize("name", sorted(MATRIX_FUNCTIONS))
def test_matrix_functions_give_nan_for_non_rotations_in_their_own_element(name, bad):
    _assert_nan_in_its_own_element(_MF[name], R, BAD_MATRICES[bad])


def _assert_nan_in_its_own_element(f, good, bad):
    """``f`` of a batch with ``bad`` in place of element 2: NaN there, the others unchanged."""
    batch = good.copy()
    batch[2] = bad
    out = np.asarray(f(batch))
    assert np.all(np.isnan(out[2])), out[2]
    np.testing.assert_array_equal(np.delete(out, 2, axis=0), np.delete(f(good), 2, axis=0))


BAD_QUATERNIONS = {
    "zero": [0.0, 0, 0, 0],
    "inf_w": [0.0, 0, 0, np.inf],
    "inf_x": [np.inf, 0.1, 0.2, 0.9],
    "nan": [0.1, np.nan, 0.2, 0.9],
}


@pytest.mark.parametrize("bad", sorted(BAD_QUATERNIONS))
@pytest.mark.parametrize("name", sorted(QUATERNION_FUNCTIONS))
def test_quaternion_functions_give_nan_for_non_rotations_in_their_own_element(name, bad):
    _assert_nan_in_its_own_element(_QF[name], Q, BAD_QUATERNIONS[bad])


def test_tiny_vector_part_gives_its_axis_and_angle():
    """A vector part of 1e-160 next to w = 1 (float64), or 1e-30 (float32): the axis is its
    direction and the angle twice its norm, not the identity's (e_x, 0)."""
    for dtype, t in ((np.float64, 1e-160), (np.float32, 1e-30)):
        q = np.array([0.0, 0.6 * t, -0.8 * t, 1.0], dtype=dtype)
        axis, angle = rj.quaternion_to_axis_angle(q)
        assert_close(axis, [0.0, 0.6, -0.8], atol=2 * np.finfo(dtype).eps)
        assert_close(angle / t, 2.0, atol=4 * np.finfo(dtype).eps)
        assert_close(rj.quaternion_to_rotvec(q) / t, [0.0, 1.2, -1.6], atol=8 * np.finfo(dtype).eps)


@pytest.mark.parametrize("seq", SEQS)
def test_euler_angles_keep_a_small_rotation_next_to_a_tiny_factor(seq):
    """Just off gimbal lock, a factor C of 2e-303 (float64) or 1e-36 (float32) next to a turn of
    2e-7 (2e-3) about the locked axis in A: a product of that small component of A with C
    underflows unless each factor is scaled by its own power of two, and the turn was lost."""
    for dtype, small, delta in ((np.float64, 1e-7, 2e-303), (np.float32, 1e-3, 1e-36)):
        pat = _abcd_patterns(seq)  # abcd = pat @ q
        q = (pat.T @ np.array([1.0, small, delta, 0.0]) / (pat[0] @ pat[0])).astype(dtype)
        qs = np.broadcast_to(q, (ORACLE_BATCH, 4))  # the oracle tests' batch
        back = rj.euler_to_matrix(rj.quaternion_to_euler(qs, seq), seq)
        want = rj.quaternion_to_matrix(qs)
        assert_close(back, want, atol=8 * np.finfo(dtype).eps, err_msg=f"{dtype} {seq}")


# --- gradients at every distance from gimbal lock ---------------------------------------------


def _near_lock(seq, delta, which):
    """A quaternion whose factors are A = (0, 0.75), C = (delta, 0) (``which = "C"``, near the
    lock where the middle angle is 0 / +pi/2), or A = (delta, 0), C = (0, 0.75): every component
    is exactly representable (a sum with at most one non-zero term), so the distance is
    ``delta`` exactly, down to the smallest subnormal. Returns ``(q, abcd)``."""
    big, small = (0.0, 0.75), (delta, 0.0)
    abcd = np.array([*big, *small] if which == "C" else [*small, *big])
    pat = _abcd_patterns(seq)  # abcd = pat @ q; pat pat^T = I (proper) or 2 I (Tait-Bryan)
    return pat.T @ abcd / (pat[0] @ pat[0]), abcd


def _true_jacobian(seq, q, abcd):
    """The angles' derivatives with respect to q from the formulas (in float64 for the values
    that are representable): arg(A) -+ arg(C) and 2 atan2(|C|, |A|), chained through abcd."""
    a, b, c, d = abcd
    na, nc = np.hypot(a, b), np.hypot(c, d)  # one of them is 0.75, the other delta
    ua, ub, uc, ud = a / na, b / na, c / nc, d / nc  # unit directions: no underflowing square
    darg_a = np.array([-ub, ua, 0, 0]) / na
    darg_c = np.array([0, 0, -ud, uc]) / nc
    dmid = 2 * (na * np.array([0, 0, uc, ud]) - nc * np.array([ua, ub, 0, 0])) / (na**2 + nc**2)
    rows = {"first": darg_a - darg_c, "mid": dmid / 2, "third": darg_a + darg_c}
    order, factor, _ = _layout(seq)
    return np.stack([f * rows[n] for n, f in zip(order, factor, strict=True)]) @ _abcd_patterns(seq)


DISTANCES = {
    np.float64: [10.0**-k for k in (3, 20, 100, 150, 160, 200, 250, 300, 306)] + [1e-310, 5e-324],
    np.float32: [10.0**-k for k in (3, 10, 18, 20, 25, 30, 36)] + [1e-40, 1e-45],
}


MATRIX_SEQS = ("ZXZ", "xyz", "yzy", "ZYX")  # matrix_to_euler, and float32: a few sequences


@pytest.mark.parametrize("seq", SEQS)
def test_euler_gradients_near_lock_at_every_distance(seq):
    """quaternion_to_euler's and matrix_to_euler's Jacobians are finite at every distance, down
    to the smallest subnormal; above the lock threshold (4x the smallest normal number) the
    quaternion one is the true derivative, about 1 / distance."""
    with_matrix = seq in MATRIX_SEQS
    for dtype, deltas in DISTANCES.items():
        if dtype == np.float32 and not with_matrix:
            continue  # the same code in both dtypes: float32 on a few sequences
        tiny = 4 * float(np.finfo(dtype).tiny)
        for which in ("A", "C"):
            pairs = [_near_lock(seq, dl, which) for dl in deltas]
            qs = jnp.asarray(np.array([p[0] for p in pairs]), dtype=dtype)
            jq = np.asarray(_jac_q(qs, seq))
            assert np.all(np.isfinite(jq)), (dtype, which)
            if with_matrix:
                jm = np.asarray(_jac_r(rj.quaternion_to_matrix(qs), seq))
                assert np.all(np.isfinite(jm)), (dtype, which)
                assert np.abs(jm[:-2]).max() > 1 / (8 * deltas[-3]), (dtype, which)
            for (q, abcd), j, dl in zip(pairs, jq, deltas, strict=True):
                if dl > tiny:
                    want = _true_jacobian(seq, q, abcd)
                    err = np.abs(j - want).max() / np.abs(want).max()
                    assert err < 16 * np.finfo(dtype).eps, (dtype, which, dl, err)


# The Jacobians, as vmap(jacfwd) and vmap(jacrev) give them, by one-point programs called
# along each basis direction (forward) or cotangent (reverse): a batch's vectorised loop takes
# LLVM twice as long to compile.
@functools.partial(jax.jit, static_argnums=2)
def _jvp_q(q, e, seq):
    return jax.jvp(lambda x: rj.quaternion_to_euler(x, seq), (q,), (e,))[1]


@functools.partial(jax.jit, static_argnums=2)
def _vjp_r(m, c, seq):
    return jax.vjp(lambda x: rj.matrix_to_euler(x, seq), m)[1](c)[0]


def _jac_q(qs, seq):
    """``(n, 3, 4)``: forward mode, column by column."""
    qs = np.asarray(qs)  # rows by NumPy: indexing a JAX array compiles a program
    eye = np.eye(4, dtype=qs.dtype)
    return np.array([np.stack([_jvp_q(q, e, seq) for e in eye], axis=-1) for q in qs])


def _jac_r(rs, seq):
    """``(n, 3, 3, 3)``: reverse mode, row by row."""
    rs = np.asarray(rs)
    eye = np.eye(3, dtype=rs.dtype)
    return np.array([np.stack([_vjp_r(m, c, seq) for c in eye]) for m in rs])


@pytest.mark.parametrize("dtype", list(SCALES))
def test_quaternion_mean_is_scale_invariant(dtype):
    """Each quaternion of a set at its own scale, over the whole range: the mean of the
    unit-scale set, with and without weights."""
    rng = np.random.default_rng(47)
    q = rj.quaternion_multiply(Q[:1], random_quaternions(5, seed=48) * [0.1, 0.1, 0.1, 1.0])
    q = np.asarray(q).astype(dtype)
    w = rng.uniform(0.5, 2.0, size=5).astype(dtype)
    eps = np.finfo(dtype).eps
    for s in SCALES[dtype]:
        scales = (s * 10.0 ** rng.uniform(-3, 3, size=(5, 1))).astype(dtype)
        for weights in (None, w):
            want = np.asarray(rj.quaternion_mean(q, weights))
            got = np.asarray(rj.quaternion_mean(q * scales, weights))
            assert_close(got, want, atol=8 * eps, err_msg=f"scale {s:g}")


@pytest.mark.parametrize("bad", sorted(BAD_QUATERNIONS))
def test_quaternion_mean_gives_nan_for_a_non_rotation_in_its_own_set(bad):
    sets = np.stack([Q[:4], Q[4:], Q[2:6], Q[1:5]])
    bad_set = sets[2].copy()
    bad_set[1] = BAD_QUATERNIONS[bad]
    _assert_nan_in_its_own_element(jax.jit(rj.quaternion_mean), sets, bad_set)


# --- the residue: the last readers of |q|^2 and |p|^2 ------------------------------------------


@pytest.mark.parametrize(("dtype", "scale"), CASES, ids=IDS)
def test_angular_velocity_from_a_quaternion_derivative_is_scale_invariant(dtype, scale):
    """omega(s q, s q') = omega(q, q'): |q|^2 of 1e-60 (float32) underflowed to 0 and gave NaN
    or inf; of 1e60, inf and 0."""
    q = Q.astype(dtype)
    q_dot = np.random.default_rng(46).normal(size=Q.shape).astype(dtype)
    eps = np.finfo(dtype).eps
    for frame in ("body", "world"):
        want = np.asarray(rj.quaternion_derivative_to_angular_velocity(q, q_dot, frame=frame))
        got = rj.quaternion_derivative_to_angular_velocity(
            q * dtype(scale), q_dot * dtype(scale), frame=frame
        )
        assert_close(got, want, atol=8 * eps * np.abs(want).max(), err_msg=frame)


@pytest.mark.parametrize(("dtype", "scale"), CASES, ids=IDS)
def test_quaternion_inverse_at_any_scale(dtype, scale):
    """inverse(s q) = inverse(q) / s: |s q|^2 must neither underflow nor overflow."""
    q = Q.astype(dtype)
    want = np.asarray(rj.quaternion_inverse(q))
    got = np.asarray(rj.quaternion_inverse(q * dtype(scale))).astype(np.float64) * scale
    assert_close(got, want, atol=4 * np.finfo(dtype).eps)


@pytest.mark.parametrize("dtype", list(SCALES))
def test_mrp_to_quaternion_of_any_norm(dtype):
    """(2 p, 1 - |p|^2) / (1 + |p|^2) for |p| up to the largest scale (|p|^2 overflowed beyond
    1e154 in float64, 1e19 in float32, and gave NaN), against mpmath."""
    mp = pytest.importorskip("mpmath")
    mp.mp.dps = 40
    axis = np.array([0.48, -0.6, 0.64])
    for s in [0.3, 1.0, 7.0, *SCALES[dtype]]:
        p = (axis * s).astype(dtype)
        pm = [mp.mpf(float(x)) for x in p]
        p2 = sum(x * x for x in pm)
        want = [float(2 * x / (1 + p2)) for x in pm] + [float((1 - p2) / (1 + p2))]
        got = np.asarray(rj.mrp_to_quaternion(p)).astype(np.float64)
        assert_close(got, want, atol=4 * np.finfo(dtype).eps, err_msg=f"|p| = {s:g}")


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_rotation_products_at_any_scale(dtype):
    """A Rotation keeps the quaternion it was given (any norm) and stores products unnormalised:
    a product of factors at the ends of the range, and a chain of such products (whose norms
    multiply), neither overflows nor underflows, and reads as the product of the unit ones."""
    eps = np.finfo(dtype).eps
    p, q, v = Q.astype(dtype), P.astype(dtype), V.astype(dtype)
    want = rj.Rotation.from_quat(p) * rj.Rotation.from_quat(q)
    for s, t in ((SCALES[dtype][-1], SCALES[dtype][-1]), (SCALES[dtype][0], SCALES[dtype][0]),
                 (SCALES[dtype][0], SCALES[dtype][-1])):  # fmt: skip
        got = rj.Rotation.from_quat(p * dtype(s)) * rj.Rotation.from_quat(q * dtype(t))
        assert_close(got.as_matrix(), want.as_matrix(), atol=8 * eps, err_msg=f"{s} {t}")
        assert_close(got.apply(v), want.apply(v), atol=8 * eps * np.abs(v).max())
    chain, unit = rj.Rotation.from_quat(p * dtype(SCALES[dtype][-1])), rj.Rotation.from_quat(p)
    for _ in range(6):
        chain, unit = chain * chain, unit * unit  # norms s^2, s^4, ..., s^64
    assert_close(chain.as_quat(canonical=True), unit.as_quat(canonical=True), atol=64 * eps)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_unchecked_matrix_rotations_at_any_scale(dtype):
    """``Rotation.from_matrix(assume_valid=True)`` stores the Shepperd column unnormalised: its
    readers give the unit quaternion, the matrix and the Euler angles of ``R`` for ``s R`` at
    every scale, NaN for the zero matrix, and a chain of 64 products of such factors (not
    marked unit, so rescaled) reads as the chain of the unit ones."""
    eps = np.finfo(dtype).eps
    m, v = R.astype(dtype), V.astype(dtype)
    want = rj.Rotation.from_quat(rj.matrix_to_quaternion(m))
    for s in SCALES[dtype]:
        got = rj.Rotation.from_matrix(m * dtype(s), assume_valid=True)
        assert_close(got.as_quat(), rj.matrix_to_quaternion(m), atol=4 * eps, err_msg=s)
        assert_close(got.as_matrix(), m, atol=8 * eps, err_msg=s)
        assert_close(got.as_euler("ZXZ"), rj.matrix_to_euler(m, "ZXZ"), atol=64 * eps)
        assert_close(got.apply(v), want.apply(v), atol=8 * eps * np.abs(v).max())
    nan = rj.Rotation.from_matrix(np.stack([m[0], 0 * m[1]]), assume_valid=True).as_quat()
    assert np.isfinite(nan[0]).all() and np.isnan(nan[1]).all()
    chain = unit = rj.Rotation.from_matrix(m * dtype(SCALES[dtype][-1]), assume_valid=True)
    unit = rj.Rotation.from_quat(unit.as_quat())
    for _ in range(6):
        chain, unit = chain * chain, unit * unit
    assert_close(chain.as_quat(canonical=True), unit.as_quat(canonical=True), atol=64 * eps)


@pytest.mark.parametrize(("dtype", "scale"), CASES, ids=IDS)
def test_axis_angle_to_quaternion_with_an_axis_of_any_norm(dtype, scale):
    """The axis need not be unit: s axis gives the quaternion of the unit axis (|axis|^2
    overflowed beyond 1e19 in float32 and gave the identity's vector part, and underflowed
    below 1e-19 and gave inf); the zero axis gives NaN in its own element."""
    axis, angle = V.astype(dtype), np.linspace(-3.0, 3.0, len(V)).astype(dtype)
    want = np.asarray(rj.axis_angle_to_quaternion(axis, angle))
    got = np.asarray(rj.axis_angle_to_quaternion(axis * dtype(scale), angle))
    assert_close(got, want, atol=4 * np.finfo(dtype).eps)
    zero = np.asarray(rj.axis_angle_to_quaternion(np.concatenate([axis[:1] * 0, axis]), 1.0))
    assert np.all(np.isnan(zero[0])) and np.all(np.isfinite(zero[1:]))
