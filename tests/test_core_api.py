"""API contract: broadcasting, jit/vmap, dtypes, scalar_first, and bad input."""

import inspect
import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import (
    BATCH_SHAPES,
    DTYPES,
    NOT_BATCHWISE,
    SET_AXIS,
    assert_close,
    assert_same_rotation,
    check_grads,
    check_hessian,
    every_public,
    public_inputs,
    sweep,
)
from scipy.spatial.transform import Rotation as ScipyRotation

import rotjax as rj

Q, R, V, A = public_inputs(64, np.float64)  # by scipy, at import

# (function, positional inputs built from a flat batch of 64 rotations, trailing input ndims)
UNARY = {
    "quaternion_to_matrix": (rj.quaternion_to_matrix, Q, 1),
    "matrix_to_quaternion": (rj.matrix_to_quaternion, R, 2),
    "quaternion_to_rotvec": (rj.quaternion_to_rotvec, Q, 1),
    "rotvec_to_quaternion": (rj.rotvec_to_quaternion, V, 1),
    "rotvec_to_matrix": (rj.rotvec_to_matrix, V, 1),
    "matrix_to_rotvec": (rj.matrix_to_rotvec, R, 2),
    "quaternion_to_euler": (lambda x: rj.quaternion_to_euler(x, "ZYX"), Q, 1),
    "matrix_to_euler": (lambda x: rj.matrix_to_euler(x, "zxz"), R, 2),
    "euler_to_matrix": (lambda x: rj.euler_to_matrix(x, "ZYX"), A, 1),
    "euler_to_quaternion": (lambda x: rj.euler_to_quaternion(x, "313"), A, 1),
    "quaternion_normalize": (rj.quaternion_normalize, 3 * Q, 1),
    "quaternion_conjugate": (rj.quaternion_conjugate, Q, 1),
    "quaternion_inverse": (rj.quaternion_inverse, 2 * Q, 1),
    "rotation_angle": (rj.rotation_angle, Q, 1),
}
BINARY = {
    "quaternion_multiply": (rj.quaternion_multiply, Q, Q[::-1], 1, 1),
    "relative_rotation": (rj.relative_rotation, Q, Q[::-1], 1, 1),
    "angle_between": (rj.angle_between, Q, Q[::-1], 1, 1),
    "quaternion_apply": (rj.quaternion_apply, Q, V, 1, 1),
    "axis_angle_to_quaternion": (rj.axis_angle_to_quaternion, V, A[:, 0], 1, 0),
}


def _reshape(x, batch, trailing):
    n = int(np.prod(batch)) if batch else 1
    return x[:n].reshape(*batch, *x.shape[x.ndim - trailing :])


def _flat(out, batch):
    return jax.tree.map(
        lambda o: np.asarray(o).reshape(int(np.prod(batch, dtype=int)), *o.shape[len(batch) :]), out
    )


@pytest.mark.parametrize("batch", sweep(BATCH_SHAPES, fast=[(3, 1, 2, 1)]), ids=str)
@pytest.mark.parametrize("name", sorted(UNARY))
def test_unary_batch_jit_vmap(name, batch):
    """On a batch of any leading shape: the flat batch's values, and the same under jit and
    under vmap over the leading axis (jit and vmap traced into one program)."""
    f, x, nd = UNARY[name]
    xb = _reshape(x, batch, nd)
    out = f(xb)
    ref = f(x)  # the flat batch
    n = int(np.prod(batch, dtype=int))
    jax.tree.map(
        lambda o, r: assert_close(np.asarray(o).reshape(n, *r.shape[1:]), r[:n], atol=1e-15),
        out,
        ref,
    )
    jitted, vmapped = jax.jit(lambda x: (f(x), jax.vmap(f)(x) if batch else f(x)))(xb)
    jax.tree.map(lambda o, j: assert_close(j, o, atol=1e-15), out, jitted)
    jax.tree.map(lambda o, v: assert_close(v, o, atol=1e-15), out, vmapped)


@pytest.mark.parametrize("batch", sweep(BATCH_SHAPES, fast=BATCH_SHAPES[-1:]), ids=str)
@pytest.mark.parametrize("name", sorted(BINARY))
def test_binary_broadcasting(name, batch):
    f, x, y, ndx, ndy = BINARY[name]
    xb = _reshape(x, batch, ndx)
    y0 = y[:1].reshape(y.shape[1:])  # one unbatched second argument, broadcast
    out = np.asarray(f(xb, y0))
    n = int(np.prod(batch, dtype=int))
    ref = np.asarray(f(x, np.broadcast_to(y0, (len(x), *y0.shape))))[:n]  # the flat batch
    assert_close(out.reshape(n, *ref.shape[1:]), ref, atol=1e-15)
    if batch:
        yb = _reshape(y, batch, ndy)
        assert_close(jax.vmap(f)(xb, yb), f(xb, yb), atol=1e-15)


@pytest.mark.parametrize(
    "dtype", DTYPES + [np.float16, jnp.bfloat16], ids=lambda d: jnp.dtype(d).name
)
@pytest.mark.parametrize("name", sweep(sorted(UNARY), fast=sorted(UNARY)[::3]))
def test_dtype_preserved(name, dtype):
    f, x, _ = UNARY[name]
    out = f(jnp.asarray(x, dtype=dtype))  # the flat batch of test_unary_batch_jit_vmap
    for o in jax.tree.leaves(out):
        assert o.dtype == jnp.dtype(dtype)
        assert np.all(np.isfinite(np.asarray(o, np.float64)))


@pytest.mark.parametrize(
    "name", ["quaternion_to_matrix", "quaternion_to_euler", "rotvec_to_matrix"]
)
def test_integers_promote_to_float(name):
    f, x, _ = UNARY[name]
    x = np.zeros((2, x.shape[-1]), int)  # same trailing shape as the float input
    x[..., -1] = 1
    out = f(x)
    assert jnp.issubdtype(out.dtype, jnp.floating)


def test_scalar_first_everywhere():
    qf = np.roll(Q, 1, axis=-1)  # (w, x, y, z)
    # The matrix's program for scalar-first input is the scalar-last one but for the offsets of
    # its slices, which LLVM orders differently: it may contract the other product of an entry's
    # sum (x y + z w) into a fused multiply-add, one rounding apart.
    eps = np.finfo(np.float64).eps
    assert_close(
        rj.quaternion_to_matrix(qf, scalar_first=True), rj.quaternion_to_matrix(Q), atol=eps
    )
    for name, f in [
        ("quaternion_to_rotvec", rj.quaternion_to_rotvec),
        ("quaternion_to_euler", lambda q, **k: rj.quaternion_to_euler(q, "XYZ", **k)),
        ("rotation_angle", rj.rotation_angle),
        ("quaternion_to_axis_angle", rj.quaternion_to_axis_angle),
    ]:
        jax.tree.map(
            lambda a, b: assert_close(a, b, atol=0, err_msg=name), f(qf, scalar_first=True), f(Q)
        )
    for name, f in [
        ("quaternion_normalize", rj.quaternion_normalize),
        ("quaternion_conjugate", rj.quaternion_conjugate),
        ("quaternion_inverse", rj.quaternion_inverse),
    ]:
        assert_close(
            f(qf, scalar_first=True), np.roll(np.asarray(f(Q)), 1, -1), atol=0, err_msg=name
        )
    for name, f in [
        ("matrix_to_quaternion", lambda **k: rj.matrix_to_quaternion(R, **k)),
        ("rotvec_to_quaternion", lambda **k: rj.rotvec_to_quaternion(V, **k)),
        ("euler_to_quaternion", lambda **k: rj.euler_to_quaternion(A, "ZYX", **k)),
        ("axis_angle_to_quaternion", lambda **k: rj.axis_angle_to_quaternion(V, A[:, 0], **k)),
        (
            "quaternion_multiply",
            lambda **k: rj.quaternion_multiply(
                Q if not k else qf, Q[::-1] if not k else qf[::-1], **k
            ),
        ),
        (
            "relative_rotation",
            lambda **k: rj.relative_rotation(
                Q if not k else qf, Q[::-1] if not k else qf[::-1], **k
            ),
        ),
    ]:
        assert_close(f(scalar_first=True), np.roll(np.asarray(f()), 1, -1), atol=0, err_msg=name)
    assert_close(rj.quaternion_apply(qf, V, scalar_first=True), rj.quaternion_apply(Q, V), atol=0)
    assert_close(
        rj.angle_between(qf, qf[::-1], scalar_first=True), rj.angle_between(Q, Q[::-1]), atol=0
    )


def test_degrees_option():
    assert_close(
        rj.euler_to_matrix(np.rad2deg(A), "ZYX", degrees=True),
        rj.euler_to_matrix(A, "ZYX"),
        atol=1e-15,
    )
    assert_close(rj.quaternion_to_euler(Q, "ZYX", degrees=True), np.rad2deg(A), atol=1e-12)
    assert_close(rj.matrix_to_euler(R, "ZYX", degrees=True), np.rad2deg(A), atol=1e-12)
    assert_close(
        rj.rotvec_to_quaternion(np.rad2deg(V), degrees=True), rj.rotvec_to_quaternion(V), atol=1e-15
    )
    assert_close(rj.quaternion_to_rotvec(Q, degrees=True), np.rad2deg(V), atol=1e-12)


def test_algebra_identities():
    """Identities between the functions, on pairs of the 64 rotations (at the batch shape of
    the other tests here, whose programs these calls share)."""
    p, q = Q, np.roll(Q, 32, axis=0)  # pairs (Q[i], Q[i + 32]) and (Q[i + 32], Q[i])
    pq = rj.quaternion_multiply(p, q)
    assert_close(
        rj.quaternion_to_matrix(pq),
        rj.quaternion_to_matrix(p) @ rj.quaternion_to_matrix(q),
        atol=1e-15,
    )
    ident = rj.quaternion_multiply(3 * q, rj.quaternion_inverse(3 * q))
    assert_close(ident, np.broadcast_to([0, 0, 0, 1.0], ident.shape), atol=1e-15)
    v = V
    assert_close(
        rj.quaternion_apply(2 * p, v),
        np.einsum("nij,nj->ni", rj.quaternion_to_matrix(p), v),
        atol=1e-14,
    )
    assert_close(rj.quaternion_normalize(5 * p), p, atol=1e-15)
    assert_close(rj.angle_between(p, -p), 0, atol=1e-15)
    assert_close(rj.angle_between(p, q), rj.rotation_angle(rj.relative_rotation(p, q)), atol=1e-14)
    assert_close(
        rj.rotation_angle(p), np.linalg.norm(rj.quaternion_to_rotvec(p), axis=-1), atol=1e-14
    )
    axis, angle = rj.quaternion_to_axis_angle(p)
    assert_same_rotation(rj.axis_angle_to_quaternion(axis, angle), p, atol=1e-15)


def test_non_unit_quaternions_are_normalised():
    for scale in [1e-150, 1e-3, 7.0, 1e150]:
        s = scale * Q
        assert_close(rj.quaternion_to_matrix(s), R, atol=1e-15)
        assert_close(rj.quaternion_to_euler(s, "XYZ"), rj.quaternion_to_euler(Q, "XYZ"), atol=1e-14)
        assert_close(rj.quaternion_to_rotvec(s), V, atol=1e-14)
        assert_close(rj.rotation_angle(s), rj.rotation_angle(Q), atol=1e-15)


def test_quaternions_with_exact_matrices_give_exact_entries():
    # 90 and 180 degrees about each axis, at unit, power-of-two and other norms: the entries
    # that cancel are exactly 0 (scipy's too) at any norm, the others exactly +-1 where
    # |q|^2 times its rounded reciprocal is 1 (here)
    axes = np.eye(3)
    q90 = np.concatenate([axes, np.ones((3, 1))], axis=-1)
    q180 = np.concatenate([axes, np.zeros((3, 1))], axis=-1)
    cases = [(np.concatenate([q90, -q90, q180]), [1.0, 0.5, 3.0, 2.0**-600, 2.0**600])]
    cases += [(q90 / np.sqrt(2), [1.0, 0.5, 2.0**-600])]  # unit, rounded
    for q, scales in cases:
        expected = np.round(ScipyRotation.from_quat(q).as_matrix())
        for scale, dtype in itertools.product(scales, (np.float32, np.float64)):
            if dtype == np.float32 and not 1e-30 < scale < 1e30:
                continue
            m = np.asarray(rj.quaternion_to_matrix((scale * q).astype(dtype)))
            np.testing.assert_array_equal(m, expected, err_msg=f"scale {scale}, {dtype}")
    q = cases[0][0]
    zero = np.round(ScipyRotation.from_quat(q).as_matrix()) == 0
    for scale in [7.0, 1e150]:
        np.testing.assert_array_equal(np.asarray(rj.quaternion_to_matrix(scale * q))[zero], 0.0)


# --- bad input --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "seq", ["xyx ", "XYx", "XXY", "xyy", "abc", "12", "1234", "313a", "113", "404", ""]
)
def test_bad_sequence_raises_listing_valid_forms(seq):
    with pytest.raises(ValueError, match="uppercase for intrinsic") as info:
        rj.euler_to_matrix(A, seq)
    assert "313" in str(info.value)
    with pytest.raises(ValueError, match="invalid Euler sequence"):
        rj.quaternion_to_euler(Q, seq)


@pytest.mark.parametrize(
    "f,x,expected",
    [
        (rj.quaternion_to_matrix, np.zeros((5, 3)), r"\(\.\.\., 4\), got \(5, 3\)"),
        (rj.matrix_to_quaternion, np.zeros((5, 3, 4)), r"\(\.\.\., 3, 3\), got \(5, 3, 4\)"),
        (rj.rotvec_to_matrix, np.zeros((4,)), r"\(\.\.\., 3\), got \(4,\)"),
        (lambda x: rj.euler_to_matrix(x, "XYZ"), np.zeros((2, 2)), r"\(\.\.\., 3\), got \(2, 2\)"),
        (lambda x: rj.matrix_to_euler(x, "XYZ"), np.zeros((3,)), r"\(\.\.\., 3, 3\), got \(3,\)"),
        (
            lambda x: rj.quaternion_apply(x, np.zeros(4)),
            np.zeros(4),
            r"v: expected shape \(\.\.\., 3\)",
        ),
    ],
)
def test_wrong_shape_raises_with_both_shapes(f, x, expected):
    with pytest.raises(ValueError, match=expected):
        f(x)
    with pytest.raises(ValueError, match=expected):
        jax.jit(f)(x)


def test_bad_method_raises():
    with pytest.raises(ValueError, match="shepperd"):
        rj.matrix_to_quaternion(R, method="fast")


def test_nan_stays_in_its_batch_element():
    q = Q[:8].copy()
    q[3, 1] = np.nan
    for f in [rj.quaternion_to_matrix, rj.quaternion_to_rotvec, rj.rotation_angle,
              lambda x: rj.quaternion_to_euler(x, "ZXZ")]:  # fmt: skip
        out = np.asarray(f(q)).reshape(8, -1)
        assert np.all(np.isnan(out[3])) and np.all(np.isfinite(np.delete(out, 3, 0)))
    Rn = R[:8].copy()
    Rn[5, 2, 2] = np.nan
    for f in [rj.matrix_to_quaternion, rj.matrix_to_rotvec, lambda x: rj.matrix_to_euler(x, "XYZ")]:
        out = np.asarray(f(Rn)).reshape(8, -1)
        assert np.any(np.isnan(out[5])) and np.all(np.isfinite(np.delete(out, 5, 0)))


def test_zero_quaternion_gives_nan():
    z = np.zeros(4)
    for f in [
        rj.quaternion_to_matrix,
        rj.quaternion_to_rotvec,
        rj.rotation_angle,
        rj.quaternion_normalize,
        lambda x: rj.quaternion_to_euler(x, "XYZ"),
        lambda x: rj.quaternion_to_euler(x, "ZXZ"),
        lambda x: rj.quaternion_apply(x, np.ones(3)),
    ]:
        assert np.all(np.isnan(np.asarray(f(z))))
    axis, angle = rj.quaternion_to_axis_angle(z)
    assert np.all(np.isnan(axis)) and np.isnan(angle)


def test_import_does_no_jax_work():
    """Importing rotjax must not initialise a JAX backend: a user may still choose the platform
    or other start-up options after ``import rotjax``."""
    import subprocess
    import sys

    code = (
        "import jax\n"
        "from jax._src import xla_bridge\n"
        "import rotjax\n"
        "assert not xla_bridge._backends, 'importing rotjax initialised a JAX backend'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


EVERY_PUBLIC = every_public(*public_inputs(8, np.float32))
EVERY_PUBLIC_1024 = every_public(*public_inputs(1024, np.float32))
# The functions of the default run's precision and NaN checks: the same, so that the float64
# programs, at one batch shape, are shared.
PRECISION_FAST = sorted(EVERY_PUBLIC)[::8]


def _float64(args):
    return [np.asarray(x, np.float64) for x in args]


@pytest.mark.parametrize("name", sweep(sorted(EVERY_PUBLIC), fast=PRECISION_FAST))
def test_float32_results_are_float32_and_within_8_eps_of_float64(name):
    """Each public function on 1024 random rotations in float32 returns float32, within 8
    float32 eps (relative to the largest output, or to 1) of the same call on the same values
    in float64. This would catch a lower precision anywhere inside (a TF32 or bfloat16 matrix
    product, a float16 constant, a float32-only cancellation); the largest measured on CPU is
    4.0 eps (``rotvec_to_matrix``), most are near 1. Extremes (tiny angles, 180 degrees,
    gimbal lock) are covered per function elsewhere and by the benchmark's sets."""
    f, args = EVERY_PUBLIC_1024[name]
    out32 = jax.tree.leaves(f(*args))
    out64 = jax.tree.leaves(f(*_float64(args)))
    eps = np.finfo(np.float32).eps
    for lo, hi in zip(out32, out64, strict=True):
        assert lo.dtype == jnp.float32 and hi.dtype == jnp.float64, (lo.dtype, hi.dtype)
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi)
        assert np.all(np.isfinite(lo))
        err = np.max(np.abs(lo - hi)) / max(1.0, np.max(np.abs(hi))) / eps
        assert err <= 8, f"{name}: {err:.1f} float32 eps"


def test_every_public_function_is_listed_for_the_precision_check():
    public = {n for n in dir(rj) if not n.startswith("_") and callable(getattr(rj, n))}
    listed = {n.split()[0] for n in EVERY_PUBLIC}
    assert public == listed, (public - listed, listed - public)


def _value_and_sum_gradient(f):
    """``f``'s outputs and the gradient of the sum of all their elements (by one VJP)."""

    def both(*a):
        out, vjp = jax.vjp(f, *a)
        return out, vjp(jax.tree.map(jnp.ones_like, out))

    return both


def _dot_generals(f, args):
    """The ``dot_general`` lines of the StableHLO of ``f`` and of its reverse-mode gradient (of
    the sum of its outputs, in every argument): one program that returns both (one trace and
    lowering, where ``f`` and its gradient were two). Its lines hold those of each: the values
    are returned (no forward product is dropped) and the gradient is the same VJP."""
    text = jax.jit(_value_and_sum_gradient(f)).lower(*args).as_text()
    return [ln.strip() for ln in text.splitlines() if "dot_general" in ln]


@pytest.mark.parametrize("name", sweep(sorted(EVERY_PUBLIC), fast=sorted(EVERY_PUBLIC)[1::4]))
def test_matrix_products_ask_for_full_precision(name):
    # On GPUs a float32 dot at JAX's default precision may run in TF32 (about 1e-3 relative
    # error; seen on an H100 as 1e5 eps in quaternion_mean); on TPUs in bfloat16 passes. XLA:CPU
    # ignores the setting, so this checks the program rather than the numbers.
    f, args = EVERY_PUBLIC[name]
    bad = [ln for ln in _dot_generals(f, args) if "HIGHEST" not in ln]
    assert not bad, "\n".join(bad)


def test_precision_check_sees_matrix_products():
    # The check above is not vacuous: these functions do contain matrix products.
    for name in ("wahba_sensitivity", "matrix_derivative_to_angular_velocity"):
        f, args = EVERY_PUBLIC[name]
        assert _dot_generals(f, args), name


_MANY = np.random.default_rng(6).normal(size=(3, 30, 4)).astype(np.float32)


@pytest.mark.parametrize(
    ("f", "args"),
    [(rj.quaternion_mean, (_MANY[0],)), (rj.align_vectors, (_MANY[1, :, :3], _MANY[2, :, :3]))],
    ids=["quaternion_mean", "align_vectors"],
)
def test_matrix_products_of_many_vectors_ask_for_full_precision(f, args):
    # For a few vectors these form their matrix as sums of products (no matrix product, so the
    # check above sees none); for many, with an einsum, which must ask for full precision too.
    lines = _dot_generals(f, args)
    assert lines
    assert all("HIGHEST" in ln for ln in lines), "\n".join(lines)


# --- shapes and arguments, for every public function -----------------------------------------

EVERY_PUBLIC_64 = every_public(*public_inputs(64, np.float64))


def _batched(name, args, batch):
    """``args`` (flat batches of 64) reshaped to the leading shape ``batch`` (plus a set axis of
    3 for the functions that take one)."""
    lead = batch + ((3,) if name in SET_AXIS else ())
    n = int(np.prod(lead, dtype=int))
    return [np.asarray(x)[:n].reshape((*lead, *np.shape(x)[1:])) for x in args]


BATCHWISE = sorted(n for n in EVERY_PUBLIC_64 if n not in NOT_BATCHWISE)


@pytest.mark.parametrize("batch", sweep([(), (1,), (2,), (3, 1, 2)], fast=[(3, 1, 2)]), ids=str)
@pytest.mark.parametrize("name", BATCHWISE)
def test_no_implicit_rank_promotion(name, batch):
    """Forward (every batch shape) and gradient (the widest) trace under
    ``jax_numpy_rank_promotion="raise"`` (no internal ``(4,)`` constant broadcast against a
    batch), and the output keeps the batch shape. Tracing is enough to raise, so nothing is
    compiled."""
    f, args = EVERY_PUBLIC_64[name]
    xs = _batched(name, args, batch)
    with jax.numpy_rank_promotion("raise"):
        if len(batch) == 3:  # the outputs and the gradient of their sum, in one trace
            out, grads = jax.eval_shape(_value_and_sum_gradient(f), *xs)
            assert [g.shape for g in grads] == [x.shape for x in xs]
        else:
            out = jax.eval_shape(f, *xs)
    for o in jax.tree.leaves(out):
        assert o.shape[: len(batch)] == batch, (o.shape, batch)


MULTI_ARG = sorted(n for n in BATCHWISE if len(EVERY_PUBLIC_64[n][1]) > 1)


@pytest.mark.parametrize("arg", [1, 0])
@pytest.mark.parametrize("name", MULTI_ARG)
def test_leading_shapes_that_do_not_broadcast_raise_naming_both(name, arg):
    f, args = EVERY_PUBLIC_64[name]
    xs = _batched(name, args, (2,))
    xs[arg] = _batched(name, [args[arg]], (3,))[0]
    with pytest.raises(ValueError, match=r"do not broadcast: .*\(2,.*\(3,|\(3,.*\(2,"):
        f(*xs)


def _call_with(name, **options):
    """Call the public function ``name`` on its inputs with keyword ``options`` (its other
    static arguments as in :func:`every_public`'s call, or defaults)."""
    fun = getattr(rj, name)
    _, args = EVERY_PUBLIC_64[name]
    params = inspect.signature(fun).parameters
    if "seq" in params and "seq" not in options:
        options["seq"] = "ZYX"
    args = _CALL_ARGS.get(name, lambda a: a)(args)
    return fun(*args, **options)


# Positional arguments of the functions whose ``every_public`` call adds some of its own.
_CALL_ARGS = {
    "slerp": lambda a: (*a, 0.3),
    "quaternion_power": lambda a: (*a, 0.3),
    "integrate_angular_velocity": lambda a: (*a, 0.01),
    "integrate_angular_velocity_samples": lambda a: (a[0], a[1][:4, None], 0.01),
    "euler_accelerations_to_angular_acceleration": lambda a: (*a, a[1][..., ::-1]),
    "angular_acceleration_to_euler_accelerations": lambda a: (*a, a[1][..., ::-1]),
    "davenport_to_quaternion": lambda a: (np.eye(3)[[0, 2, 0]], *a),
    "quaternion_to_davenport": lambda a: (*a, np.eye(3)[[0, 2, 0]]),
}


PUBLIC_PARAMS = {
    n: inspect.signature(getattr(rj, n)).parameters
    for n in dir(rj)
    if not n.startswith("_") and callable(getattr(rj, n))
}


def _takers(option):
    return sorted(n for n, p in PUBLIC_PARAMS.items() if option in p)


@pytest.mark.parametrize("seq", [["x", "y", "z"], ("Z", "Y", "X"), None, b"ZYX", 123], ids=repr)
@pytest.mark.parametrize("name", _takers("seq"))
def test_seq_not_a_string_is_a_type_error(name, seq):
    with pytest.raises(TypeError, match=r"seq must be a str"):
        _call_with(name, seq=seq)


@pytest.mark.parametrize("value", ["yes", 1, None, 0.0], ids=repr)
@pytest.mark.parametrize("option", ["degrees", "scalar_first"])
def test_flags_must_be_bool(option, value):
    for name in _takers(option):
        with pytest.raises(TypeError, match=rf"{option} must be a bool"):
            _call_with(name, **{option: value})


def test_numpy_bools_are_accepted_as_flags():
    out = rj.quaternion_to_euler(Q, "ZYX", degrees=np.bool_(True), scalar_first=np.False_)
    assert_close(out, np.rad2deg(A), rtol=1e-13, atol=1e-12)


@pytest.mark.parametrize("option", ["method", "frame"])
def test_unknown_method_or_frame_lists_the_valid_ones(option):
    valid = {"method": None, "frame": ("body", "world")}[option]
    for name in _takers(option):
        default = PUBLIC_PARAMS[name][option].default
        with pytest.raises(ValueError, match=rf"{option}.*{default!r}.*'nope'") as info:
            _call_with(name, **{option: "nope"})
        for v in valid or ():
            assert repr(v) in str(info.value), (name, str(info.value))
        with pytest.raises(TypeError, match=rf"{option} must be a str"):
            _call_with(name, **{option: 1})


@pytest.mark.parametrize("axis", [np.int64(1), np.int32(-2), 1], ids=repr)
def test_integer_like_axis_is_accepted(axis):
    a = np.stack([A[:5], A[5:10]])  # (2, 5, 3): time on axis 1
    want = rj.unwrap_euler(np.swapaxes(a, 0, 1), "ZYX", axis=0)
    assert_close(rj.unwrap_euler(a, "ZYX", axis=axis), np.swapaxes(want, 0, 1), atol=0)


@pytest.mark.parametrize("axis", [1.0, "0", True, None], ids=repr)
def test_non_integer_axis_is_a_type_error(axis):
    with pytest.raises(TypeError, match="axis must be an int"):
        rj.unwrap_euler(A[:5], "ZYX", axis=axis)


@pytest.mark.parametrize("arg", [0, 1])
@pytest.mark.parametrize("name", sorted(EVERY_PUBLIC_64))
def test_complex_input_is_a_type_error(name, arg):
    f, args = EVERY_PUBLIC_64[name]
    if arg >= len(args):
        arg = 0
    xs = list(args)
    xs[arg] = xs[arg] + 0j
    with pytest.raises(TypeError, match="must be real"):
        f(*xs)
    with pytest.raises(TypeError, match="must be real"):
        jax.jit(f)(*xs)


@pytest.mark.parametrize("bad", sweep([np.nan, np.inf, -np.inf], fast=[np.nan]), ids=str)
@pytest.mark.parametrize(
    "name", sweep(BATCHWISE, fast=[n for n in PRECISION_FAST if n in BATCHWISE])
)
def test_nan_and_inf_stay_in_their_batch_element(name, bad):
    """NaN or infinite values in batch element 1 (of the 1024 of the float32 precision check's
    float64 call, whose program this shares; of 4 sets for the functions of a set) leave every
    other element bit-identical to the clean call; element 1's output is not all finite (a bad
    input must not give a valid-looking result)."""
    if name in SET_AXIS:
        f, args = EVERY_PUBLIC_64[name]
        xs = _batched(name, args, (4,))
    else:
        f, args = EVERY_PUBLIC_1024[name]
        xs = _float64(args)
    if name == "unwrap_euler":  # batch first, time second (locality in time: test_kinematics)
        f = lambda a: rj.unwrap_euler(a, "ZYX", axis=1)  # noqa: E731
    if name == "unwrap_quaternion":
        f = lambda q: rj.unwrap_quaternion(q, axis=1)  # noqa: E731
    clean = jax.tree.leaves(f(*xs))
    for arg in range(len(xs)):
        ys = [x.copy() for x in xs]
        ys[arg][1] = bad  # the whole element: no map can ignore it
        out = jax.tree.leaves(f(*ys))
        for o, c in zip(out, clean, strict=True):
            o, c = np.asarray(o), np.asarray(c)
            keep = np.arange(len(c)) != 1
            np.testing.assert_array_equal(o[keep], c[keep], err_msg=f"{name}, argument {arg}")
        assert not all(np.all(np.isfinite(np.asarray(o)[1])) for o in out), (name, arg, out)


# --- sixd_to_matrix at every finite scale ------------------------------------------------------

# from scipy's matrices, so that the data do not change with rotjax's own rounding
_R16 = ScipyRotation.from_quat(np.asarray(Q[:16], np.float64)).as_matrix()
SIXD = np.concatenate([_R16[:, :, 0], _R16[:, :, 1] + 0.3 * _R16[:, :, 2]], axis=-1)  # a2 not unit


@pytest.mark.parametrize(
    "dtype,exps",
    [(np.float32, [-30, -20, -5, 0, 7, 20, 30]), (np.float64, [-300, -155, 0, 160, 300])],
)
def test_sixd_to_matrix_is_scale_invariant_with_finite_gradients(dtype, exps):
    """Each half of the 6D vector scaled by 10^k (independently) gives the same matrix within
    2 eps, and the gradient scales as 1/10^k (the map is homogeneous of degree 0 in each
    half), finite. Before the power-of-two prescaling, float32 gave zeros at 1e20 and NaN at
    1e-20."""
    eps = np.finfo(dtype).eps
    x = SIXD.astype(dtype)
    ref = np.asarray(rj.sixd_to_matrix(x), np.float64)
    rng = np.random.default_rng(3)
    w = rng.normal(size=ref.shape).astype(dtype)  # a random linear functional of the output
    grad = jax.jit(jax.grad(lambda x: jnp.sum(rj.sixd_to_matrix(x) * w)))
    g_ref = np.asarray(grad(x), np.float64)
    for k1 in exps:
        for k2 in (exps[0], 0, exps[-1]):
            s = np.array([10.0**k1] * 3 + [10.0**k2] * 3)
            xs = (x.astype(np.float64) * s).astype(dtype)
            out = np.asarray(rj.sixd_to_matrix(xs), np.float64)
            assert np.abs(out - ref).max() <= 2 * eps, (k1, k2, np.abs(out - ref).max() / eps)
            g = np.asarray(grad(xs), np.float64) * s
            assert np.all(np.isfinite(g)), (k1, k2)
            assert np.abs(g - g_ref).max() <= 64 * eps * np.abs(g_ref).max(), (k1, k2)


def test_sixd_to_matrix_gradient_is_the_derivative():
    check_grads(rj.sixd_to_matrix, (SIXD[:4],), order=1, modes=["fwd", "rev"])
    check_grads(rj.sixd_to_matrix, (1e-200 * SIXD[:4],), order=1, eps=1e-206)


@pytest.mark.slow  # second order: JAX's derivative of the code (no rule), against differences
def test_sixd_to_matrix_second_derivative():
    check_hessian(rj.sixd_to_matrix, SIXD[:4])


@pytest.mark.parametrize("bad", [0.0, np.inf, np.nan], ids=str)
def test_sixd_to_matrix_nan_for_no_rotation(bad):
    x = SIXD[:2].copy()
    x[0, :3] = bad
    out = np.asarray(rj.sixd_to_matrix(x))
    assert np.all(np.isnan(out[0])) and np.all(np.isfinite(out[1]))
