"""API contract: broadcasting, jit/vmap, dtypes, scalar_first, and bad input."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import BATCH_SHAPES, DTYPES, assert_close, assert_same_rotation, random_quaternions

import rotjax as rj

Q = random_quaternions(64, seed=21)
R = np.asarray(rj.quaternion_to_matrix(Q))
V = np.asarray(rj.quaternion_to_rotvec(Q))
A = np.asarray(rj.quaternion_to_euler(Q, "ZYX"))

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


@pytest.mark.parametrize("batch", BATCH_SHAPES, ids=str)
@pytest.mark.parametrize("name", sorted(UNARY))
def test_unary_batch_jit_vmap(name, batch):
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
    jax.tree.map(lambda o, j: assert_close(j, o, atol=1e-15), out, jax.jit(f)(xb))
    if batch:
        jax.tree.map(lambda o, v: assert_close(v, o, atol=1e-15), out, jax.vmap(f)(xb))


@pytest.mark.parametrize("batch", BATCH_SHAPES, ids=str)
@pytest.mark.parametrize("name", sorted(BINARY))
def test_binary_broadcasting(name, batch):
    f, x, y, ndx, ndy = BINARY[name]
    xb = _reshape(x, batch, ndx)
    y0 = y[:1].reshape(y.shape[1:])  # one unbatched second argument, broadcast
    out = np.asarray(f(xb, y0))
    n = int(np.prod(batch, dtype=int))
    ref = np.asarray(f(x[:n], np.broadcast_to(y0, (n, *y0.shape))))
    assert_close(out.reshape(n, *ref.shape[1:]), ref, atol=1e-15)
    if batch:
        yb = _reshape(y, batch, ndy)
        assert_close(jax.vmap(f)(xb, yb), f(xb, yb), atol=1e-15)


@pytest.mark.parametrize(
    "dtype", DTYPES + [np.float16, jnp.bfloat16], ids=lambda d: jnp.dtype(d).name
)
@pytest.mark.parametrize("name", sorted(UNARY))
def test_dtype_preserved(name, dtype):
    f, x, _ = UNARY[name]
    out = f(jnp.asarray(x[:4], dtype=dtype))
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
    for name, f in [
        ("quaternion_to_matrix", rj.quaternion_to_matrix),
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
    p, q = Q[:32], Q[32:]
    pq = rj.quaternion_multiply(p, q)
    assert_close(
        rj.quaternion_to_matrix(pq),
        rj.quaternion_to_matrix(p) @ rj.quaternion_to_matrix(q),
        atol=1e-15,
    )
    ident = rj.quaternion_multiply(3 * q, rj.quaternion_inverse(3 * q))
    assert_close(ident, np.broadcast_to([0, 0, 0, 1.0], ident.shape), atol=1e-15)
    v = V[:32]
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


# --- bad input --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "seq", ["xyx ", "XYx", "XXY", "xyy", "abc", "12", "1234", "313a", "113", "404", "", 123]
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


def _every_public(q, r, w, a):
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
        "integrate_angular_velocity_samples": (
            lambda q, w: rj.integrate_angular_velocity_samples(q, w[:4, None], 0.01),
            (q, w),
        ),
        "unwrap_quaternion": (rj.unwrap_quaternion, (q,)),
        "euler_accelerations_to_angular_acceleration": (
            lambda a, w: rj.euler_accelerations_to_angular_acceleration(a, w, w[::-1], "ZYX"),
            (a, w),
        ),
        "angular_acceleration_to_euler_accelerations": (
            lambda a, w: rj.angular_acceleration_to_euler_accelerations(
                a, w, w[::-1], "ZYX", damping=0.1
            ),
            (a, w),
        ),
        "partition_coordinates": (lambda r: rj.partition_coordinates(r[:, :2]).influence, (r,)),
        # the Rotation class and the functions it added
        "quaternion_to_mrp": (rj.quaternion_to_mrp, (q,)),
        "mrp_to_quaternion": (rj.mrp_to_quaternion, (w,)),
        "quaternion_canonical": (rj.quaternion_canonical, (q,)),
        "quaternion_power": (lambda q: rj.quaternion_power(q, 0.3), (q,)),
        "quaternion_reduce": (
            lambda q: rj.quaternion_reduce(q, rj.rotation_group("O", dtype=q.dtype))[0],
            (q,),
        ),
        "rotation_group": (lambda q: rj.rotation_group("I", dtype=q.dtype), (q,)),
        # orthonormal vector sets: the sensitivity is ill-conditioned where the singular values
        # of B are (1/zeta), which is the data's conditioning, not the function's precision
        "wahba_sensitivity": (
            lambda r: rj.wahba_sensitivity(r, np.broadcast_to(np.eye(3, dtype=r.dtype), r.shape)),
            (r,),
        ),
        "davenport_to_quaternion": (
            lambda a: rj.davenport_to_quaternion(np.eye(3, dtype=a.dtype)[[0, 2, 0]], a),
            (a,),
        ),
        "quaternion_to_davenport": (
            lambda q: rj.quaternion_to_davenport(q, np.asarray(_OBLIQUE, q.dtype)),
            (q,),
        ),
        "Rotation": (lambda q: rj.Rotation.from_quat(q).as_euler("XYZ"), (q,)),
        "Slerp": (
            lambda q: rj.Slerp(np.arange(8, dtype=q.dtype), rj.Rotation.from_quat(q[:8]))(
                np.asarray(2.5, q.dtype)
            ).as_matrix(),
            (q,),
        ),
        "RotationSpline": (
            lambda q: rj.RotationSpline(np.arange(8, dtype=q.dtype), rj.Rotation.from_quat(q[:8]))(
                np.linspace(0, 7, 15, dtype=q.dtype), 1
            ),
            (q,),
        ),
    }


# Davenport axes with the first and last 2 rad apart (consecutive ones orthogonal).
_OBLIQUE = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [np.cos(2.0), 0.0, np.sin(2.0)]]


def _float32(n):
    """The inputs of :func:`_every_public` for ``n`` random rotations (the first 64 are ``Q``),
    rounded to float32."""
    q = random_quaternions(n, seed=21)
    derived = rj.quaternion_to_matrix(q), rj.quaternion_to_rotvec(q)
    derived += (rj.quaternion_to_euler(q, "ZYX"),)
    return [np.asarray(x).astype(np.float32) for x in (q, *derived)]


EVERY_PUBLIC = _every_public(*_float32(8))
EVERY_PUBLIC_1024 = _every_public(*_float32(1024))


@pytest.mark.parametrize("name", sorted(EVERY_PUBLIC))
def test_float32_results_are_float32_and_within_8_eps_of_float64(name):
    """Each public function on 1024 random rotations in float32 returns float32, within 8
    float32 eps (relative to the largest output, or to 1) of the same call on the same values
    in float64. This would catch a lower precision anywhere inside (a TF32 or bfloat16 matrix
    product, a float16 constant, a float32-only cancellation); the largest measured on CPU is
    4.0 eps (``rotvec_to_matrix``), most are near 1. Extremes (tiny angles, 180 degrees,
    gimbal lock) are covered per function elsewhere and by the benchmark's sets."""
    f, args = EVERY_PUBLIC_1024[name]
    out32 = jax.tree.leaves(f(*args))
    out64 = jax.tree.leaves(f(*[np.asarray(x, np.float64) for x in args]))
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


def _dot_generals(f, args):
    """The ``dot_general`` lines of the StableHLO of ``f`` and of its reverse-mode gradient."""

    def loss(*a):
        return sum(jnp.sum(o) for o in jax.tree.leaves(f(*a)))

    grad = jax.grad(loss, argnums=tuple(range(len(args))))
    lines = []
    for g in (f, grad):
        text = jax.jit(g).lower(*args).as_text()
        lines += [ln.strip() for ln in text.splitlines() if "dot_general" in ln]
    return lines


@pytest.mark.parametrize("name", sorted(EVERY_PUBLIC))
def test_matrix_products_ask_for_full_precision(name):
    # On GPUs a float32 dot at JAX's default precision may run in TF32 (about 1e-3 relative
    # error; seen on an H100 as 1e5 eps in quaternion_mean); on TPUs in bfloat16 passes. XLA:CPU
    # ignores the setting, so this checks the program rather than the numbers.
    f, args = EVERY_PUBLIC[name]
    bad = [ln for ln in _dot_generals(f, args) if "HIGHEST" not in ln]
    assert not bad, "\n".join(bad)


def test_precision_check_sees_matrix_products():
    # The check above is not vacuous: these functions do contain matrix products.
    for name in ("quaternion_mean", "align_vectors", "nined_to_matrix", "geodesic_distance"):
        f, args = EVERY_PUBLIC[name]
        assert _dot_generals(f, args), name
