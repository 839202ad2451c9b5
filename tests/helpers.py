"""Shared test helpers: assertions, strategies that seek trouble, and the parameter lists."""

from __future__ import annotations

from functools import partial

import hypothesis.extra.numpy as hnp
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import strategies as st
from jax.test_util import check_jvp, check_vjp

import rotjax as rj

LETTER_SEQS = [a + b + c for a in "xyz" for b in "xyz" for c in "xyz" if a != b and b != c]
SEQS = LETTER_SEQS + [s.upper() for s in LETTER_SEQS]  # 12 extrinsic + 12 intrinsic
DIGIT_SEQS = ["313", "123", "121", "232", "321"]
# The sequences that a sweep over all of SEQS keeps in the default run; conftest.py marks the
# others slow. Tait-Bryan and proper, intrinsic and extrinsic, cyclic and anticyclic axis
# orders, two first axes.
FAST_SEQS = ["ZYX", "zxz"]
BATCH_SHAPES = [(), (1,), (3, 1, 2, 1)]
DTYPES = [np.float32, np.float64]


def sweep(values, fast, several=False):
    """Parameters for ``pytest.mark.parametrize`` over ``values`` (a list, or a dict's keys):
    those in ``fast`` run by default, the others are marked ``slow`` (CI runs them too).
    For sweeps whose every case compiles programs of its own (derivatives at each singular
    point, each method, each public function), so that the default run keeps a representative
    few. ``several``: each value is a tuple of several arguments."""
    values = list(values)
    missing = [v for v in fast if v not in values]
    if missing or not fast:
        raise ValueError(f"fast cases {missing} are not among {values}")
    slow = pytest.mark.slow
    return [v if v in fast else pytest.param(*(v if several else (v,)), marks=slow) for v in values]


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


# The batch of every oracle comparison (tests/test_core_oracle.py, test_bench.py, test_scale.py):
# one compiled program per function, Euler sequence, method and dtype, shared by those files.
ORACLE_BATCH = 640


def padded_call(f, x, *args, **kwargs):
    """``f(x, *args, **kwargs)`` on ``x`` padded to :data:`ORACLE_BATCH` rows (by repeating
    its first row), for ``x``'s rows only."""
    x = np.asarray(x)
    n = len(x)
    pad = np.broadcast_to(x[:1], (ORACLE_BATCH - n, *x.shape[1:]))
    return np.asarray(f(np.concatenate([x, pad]), *args, **kwargs))[:n]


def undecorated(kernel, *static, matrix=()):
    """The function a component kernel's wrapper computes, with the kernel's ``custom_jvp``
    removed: its arguments split into components by slicing (per-rotation arrays of shape
    ``(..., 1)``, as rotjax holds them; a matrix, index in ``matrix``, into its nine entries row
    by row), the results joined on the last axis (a stacked result as it is). JAX's derivative
    of this is the reference a hand-written rule must equal."""

    def split(i, x):
        if i in matrix:
            return tuple(x[..., r, c : c + 1] for r in range(3) for c in range(3))
        return tuple(x[..., k : k + 1] for k in range(x.shape[-1]))

    def fun(*xs):
        out = kernel.fun(*(split(i, x) for i, x in enumerate(xs)), *static)
        return out if isinstance(out, jax.Array) else jnp.concatenate(out, axis=-1)

    return fun


def jacobian_rows(f, x, *rows):
    """``jax.vmap(jax.jacfwd(f))(x, *rows)`` (the Jacobian in ``x`` only) for a batch-native
    ``f``, whose rows (the first axis of ``x`` and of each of ``rows``) are independent: one
    jitted jvp of ``f`` at the rows repeated once per component of a row of ``x``, with the
    basis directions as tangents; the inputs are built with NumPy, outside the program. The same
    numbers, several times faster to compile: a vmapped ``jacfwd`` broadcasts every row's values
    against the directions, and XLA:CPU's code for that spends seconds in LLVM's inliner.
    ``f`` may return a pytree; each leaf comes back as ``(n, *out, *row_shape)``."""
    x = np.asarray(x)
    n, inner = x.shape[0], x.shape[1:]
    d = int(np.prod(inner))
    basis = np.eye(d, dtype=x.dtype).reshape(d, *inner)
    reps = [np.repeat(np.asarray(r), d, axis=0) for r in (x, *rows)]
    e = np.tile(basis, (n,) + (1,) * len(inner))
    t = jax.jit(lambda e, a, *r: jax.jvp(lambda y: f(y, *r), (a,), (e,))[1])(e, *reps)

    def shape(y):
        y = np.asarray(y)
        out = y.shape[1:]
        return np.moveaxis(y.reshape(n, d, *out), 1, -1).reshape(n, *out, *inner)

    return jax.tree_util.tree_map(shape, t)


def hessian_rows(f, x, *rows):
    """For a batch-native ``f`` returning one array: its value, forward-mode Jacobian,
    reverse-mode Jacobian and Hessian (in ``x`` only) at each row, as ``jax.vmap`` of ``f``,
    ``jax.jacfwd(f)``, ``jax.jacrev(f)`` and ``jax.hessian(f)`` (forward over reverse) give
    them, computed as :func:`jacobian_rows` computes a Jacobian: one jitted program, the JVP
    along the basis directions of ``f`` and of its VJP with the basis cotangents, at the rows
    repeated once per (output component, direction) pair. The same derivatives (to rounding:
    XLA simplifies the two programs differently), faster to compile (no vmap of a Jacobian).
    Shapes ``(n, *out)``, ``(n, *out, *row_shape)`` (twice) and ``(n, *out, *row_shape,
    *row_shape)``, the last axes the forward direction."""
    x = np.asarray(x)
    n, inner = x.shape[0], x.shape[1:]
    d = int(np.prod(inner))
    out = jax.eval_shape(f, x, *rows).shape[1:]
    m = int(np.prod(out))
    reps = [np.repeat(np.asarray(r), m * d, axis=0) for r in (x, *rows)]
    # row (i, o, j): cotangent e_o (an output component), tangent e_j (an input component)
    ct = np.tile(np.repeat(np.eye(m, dtype=x.dtype), d, axis=0), (n, 1)).reshape(-1, *out)
    e = np.tile(np.eye(d, dtype=x.dtype), (n * m, 1)).reshape(-1, *inner)

    @jax.jit
    def program(e, a, c, *r):
        def value_and_grad(y):
            value, vjp = jax.vjp(lambda y: f(y, *r), y)
            return value, vjp(c)[0]

        return jax.jvp(value_and_grad, (a,), (e,))

    (value, grad), (jvp, hess) = jax.tree_util.tree_map(
        np.asarray, program(e, *reps[:1], ct, *reps[1:])
    )
    value = value.reshape(n, m, d, *out)[:, 0, 0]
    jac_fwd = np.moveaxis(jvp.reshape(n, m, d, *out)[:, 0], 1, -1).reshape(n, *out, *inner)
    jac_rev = grad.reshape(n, m, d, *inner)[:, :, 0].reshape(n, *out, *inner)
    hess = np.moveaxis(hess.reshape(n, m, d, *inner), 2, -1).reshape(n, *out, *inner, *inner)
    return value, jac_fwd, jac_rev, hess


def check_hessian(f, x, h=1e-5, atol=1e-5, rtol=1e-5):
    """The first and second derivatives of a batch-native ``f`` (returning one array; its rows
    independent) at each row of the float64 ``x``, against central differences of step ``h``,
    from one jitted program (:func:`hessian_rows` at the rows and at each row moved by ``+-h``
    along each basis direction): the forward and the reverse Jacobian against differences of
    ``f``, and the Hessian (forward over reverse) against differences of the reverse Jacobian.
    The checks of ``check_grads(f, (x,), order=2)`` along every basis direction instead of a
    random one, at a fraction of its compile time (one program, where it compiles seven, each
    holding ``f`` again). Returns the Hessians, ``(n, *out, *row_shape, *row_shape)``."""
    x = np.asarray(x, np.float64)
    n, inner = x.shape[0], x.shape[1:]
    d = int(np.prod(inner))
    step = h * np.eye(d).reshape(1, d, *inner)
    moved = [(x[:, None] + sign * step).reshape(n * d, *inner) for sign in (1.0, -1.0)]
    value, jac_fwd, jac_rev, hess = hessian_rows(f, np.concatenate([x, *moved]))

    def central(y):  # (n, *out, *row_shape): differences along the basis directions, last
        up, down = (y[n + k * n * d : n + (k + 1) * n * d] for k in (0, 1))
        diff = ((up - down) / (2 * h)).reshape(n, d, *y.shape[1:])
        return np.moveaxis(diff, 1, -1).reshape(n, *y.shape[1:], *inner)

    close = partial(np.testing.assert_allclose, atol=atol, rtol=rtol)
    close(jac_fwd[:n], central(value), err_msg="forward Jacobian against differences")
    close(jac_rev[:n], jac_fwd[:n], err_msg="reverse Jacobian against the forward one")
    close(hess[:n], central(jac_rev), err_msg="Hessian against differences of the Jacobian")
    return hess[:n]


def forward_hessian_rows(f, x, *rows):
    """For a batch-native ``f`` returning one array: its Jacobian and its forward-over-forward
    second derivative (in ``x`` only) at each row, as ``jax.vmap`` of ``jax.jacfwd(f)`` and
    ``jax.jacfwd(jax.jacfwd(f))`` give them: one jitted JVP of a JVP, along every pair of
    basis directions, at the rows repeated once per pair (as :func:`jacobian_rows`; equal to
    the vmapped ``jacfwd`` to rounding). Shapes
    ``(n, *out, *row_shape)`` and ``(n, *out, *row_shape, *row_shape)``, the last axes the
    outer direction."""
    x = np.asarray(x)
    n, inner = x.shape[0], x.shape[1:]
    d = int(np.prod(inner))
    basis = np.eye(d, dtype=x.dtype)
    reps = [np.repeat(np.asarray(r), d * d, axis=0) for r in (x, *rows)]
    # row (i, j, k): inner direction e_j, outer direction e_k
    e_in = np.tile(np.repeat(basis, d, axis=0), (n, 1)).reshape(-1, *inner)
    e_out = np.tile(basis, (n * d, 1)).reshape(-1, *inner)

    def program(e_in, e_out, a, *r):
        def jvp(y):
            return jax.jvp(lambda y: f(y, *r), (y,), (e_in,))[1]

        return jax.jvp(jvp, (a,), (e_out,))

    # Compiled without XLA's elementwise fusion: this program is all elementwise operations on
    # the rows, which XLA:CPU fuses into loops that recompute each shared subexpression once per
    # use (se3_log of se3_exp: 0.5 s a row to run); unfused it runs in microseconds. The same
    # operations, in the same order.
    args = (e_in, e_out, *reps)
    compiled = jax.jit(program).lower(*args).compile({"xla_disable_hlo_passes": "fusion"})
    jac, hess = (np.asarray(t) for t in compiled(*args))
    out = jac.shape[1:]
    jac = np.moveaxis(jac.reshape(n, d, d, *out)[:, :, 0], 1, -1).reshape(n, *out, *inner)
    hess = np.moveaxis(hess.reshape(n, d, d, *out), (1, 2), (-2, -1))
    return jac, hess.reshape(n, *out, *inner, *inner)


_CHECK_PROGRAMS: dict = {}


def _check_programs(f, path):
    """The function that :func:`check_grads` checks after the steps ``path`` ("fwd": its jvp,
    "rev": its vjp of its own output) from ``f``, and its value, jvp and vjp, each jitted: kept
    per ``f`` (the function object itself is the key, and is kept with them, so that a fresh
    lambda never finds another's programs), so that a check of the same ``f`` at another point
    of the same shapes, at another order or by another test runs them as they are, without
    tracing them again. The value of a step is its parent's programs: after "fwd" the parent's
    jitted jvp (the same program), after "rev" the parent's vjp applied to the parent's value
    (the same function, by two programs already compiled, where a program of its own would
    compile the parent's vjp again)."""
    key = (f, path)
    if key in _CHECK_PROGRAMS:
        return _CHECK_PROGRAMS[key]
    if not path:
        g, fj = f, jax.jit(f)
    else:
        parent, parent_fj, parent_jvp, parent_pull = _check_programs(f, path[:-1])
        if path[-1] == "fwd":
            g, fj = partial(jax.jvp, parent), parent_jvp
        else:

            def g(*a):
                out, vjp = jax.vjp(parent, *a)
                return vjp(out)

            def fj(*a):
                return parent_pull(a, parent_fj(*a))

    pull = jax.jit(lambda a, ct: jax.vjp(g, *a)[1](ct))
    programs = g, fj, jax.jit(partial(jax.jvp, g)), pull
    _CHECK_PROGRAMS[key] = programs
    return programs


def check_grads(f, args, order, modes=("fwd", "rev"), atol=None, rtol=None, eps=None):
    """``jax.test_util.check_grads`` with each program jitted: the same checks (the same random
    directions, finite differences, tolerances and assertions, by JAX's ``check_jvp`` and
    ``check_vjp``), but ``f``, its JVP and its VJP at each order are each one jitted program
    (the finite differences call the jitted ``f``), where the eager version dispatches the
    derivatives of its parts one by one, each a program of its own. The programs are kept per
    ``f`` (:func:`_check_programs`): pass the same function object (``rj.nined_to_matrix``, a
    module-level lambda) to check it at several points without tracing again."""
    eps = eps or 1e-4  # check_grads' default step

    def check(path, args, order, err_msg):
        _, fj, jvp, pull = _check_programs(f, path)
        if "fwd" in modes:
            msg = f"JVP of {err_msg}" if err_msg else "JVP"
            check_jvp(fj, jvp, args, atol, rtol, eps, msg)
            if order > 1:
                check((*path, "fwd"), (args, args), order - 1, msg)
        if "rev" in modes:
            msg = f"VJP of {err_msg}" if err_msg else "VJP"
            check_vjp(fj, lambda *a: (fj(*a), partial(pull, a)), args, atol, rtol, eps, msg)
            if order > 1:
                check((*path, "rev"), args, order - 1, msg)

    check((), tuple(args), order, "")


def rev_jacobian(f, args):
    """The Jacobians of ``f(*args)`` (each output leaf, in each argument), by reverse mode: the
    jitted VJP of ``f`` that :func:`check_grads` keeps for ``f`` (the same program,
    compiled once, where ``f`` is checked at these shapes too), applied to each basis cotangent
    in turn. The numbers of ``jax.jacobian(f, argnums=range(len(args)))``, without its
    vmapped VJP (one more program, slow to compile). Leaves ``(*out, *arg)`` per output leaf,
    a tuple over the arguments."""
    _, fj, _, pull = _check_programs(f, ())
    out = fj(*args)
    leaves, tree = jax.tree.flatten(out)
    leaves = [np.asarray(o) for o in leaves]
    jac = []
    for k, o in enumerate(leaves):
        rows = []
        for idx in np.ndindex(o.shape):
            ct = [np.zeros_like(x) for x in leaves]
            ct[k][idx] = 1
            rows.append([np.asarray(g) for g in pull(tuple(args), jax.tree.unflatten(tree, ct))])
        jac.append(
            tuple(
                np.stack([r[i] for r in rows]).reshape(*o.shape, *np.shape(args[i]))
                for i in range(len(args))
            )
        )
    return jax.tree.unflatten(tree, jac)


# --- one call of every public function ------------------------------------------------------

# Functions whose input has a set or time axis before the trailing one (besides the batch).
SET_AXIS = (
    "quaternion_mean",
    "align_vectors",
    "align_vectors q-method",
    "unwrap_euler",
    "unwrap_quaternion",
)
# Calls whose inputs are not mapped over a leading batch as a whole: keyframes (Slerp,
# RotationSpline), a time axis before the batch (the sampled integrator), a constant group.
# Their batching is tested with them (tests/test_rotation.py, tests/test_kinematics.py).
NOT_BATCHWISE = ("Slerp", "RotationSpline", "integrate_angular_velocity_samples", "rotation_group")


# Oblique Davenport axes (the third axis is not perpendicular to the second's plane's normal).
_OBLIQUE = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [np.cos(2.0), 0.0, np.sin(2.0)]]


def every_public(q, r, w, a):
    """One call of every public function (name -> (function, inputs)), built from ``n``
    quaternions ``q``, their matrices ``r``, rotation vectors ``w`` and ZYX angles ``a``."""
    n = len(q)
    # quaternions near q[0], of both signs and not unit: a mean that is well conditioned (the
    # mean of uniformly random rotations is not: its 4x4 scatter matrix has close eigenvalues)
    cluster = (q[0] + q / 5) * np.where(np.arange(n) % 2 == 0, 1, -1).astype(q.dtype)[:, None]
    # SE(3): exponential coordinates [rotvec, v] and homogeneous transforms [[R, t], [0, 1]]
    xi = np.concatenate([w, a], axis=-1)
    T = np.zeros((*np.shape(r)[:-2], 4, 4), np.asarray(r).dtype)
    T[..., :3, :3], T[..., :3, 3], T[..., 3, 3] = r, a, 1
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
            lambda a, w: rj.euler_accelerations_to_angular_acceleration(a, w, w[..., ::-1], "ZYX"),
            (a, w),
        ),
        "angular_acceleration_to_euler_accelerations": (
            lambda a, w: rj.angular_acceleration_to_euler_accelerations(
                a, w, w[..., ::-1], "ZYX", damping=0.1
            ),
            (a, w),
        ),
        "partition_coordinates": (
            lambda r: rj.partition_coordinates(r[..., :2, :]).influence,
            (r,),
        ),
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
        # Lie calculus of SO(3) and SE(3)
        "hat": (rj.hat, (w,)),
        "vee": (rj.vee, (r,)),
        "so3_left_jacobian": (rj.so3_left_jacobian, (w,)),
        "so3_right_jacobian": (rj.so3_right_jacobian, (w,)),
        "so3_left_jacobian_inverse": (rj.so3_left_jacobian_inverse, (w,)),
        "so3_right_jacobian_inverse": (rj.so3_right_jacobian_inverse, (w,)),
        "se3_exp": (rj.se3_exp, (xi,)),
        "se3_log": (rj.se3_log, (T,)),
        "se3_adjoint": (rj.se3_adjoint, (T,)),
        "se3_left_jacobian": (rj.se3_left_jacobian, (xi,)),
        "se3_right_jacobian": (rj.se3_right_jacobian, (xi,)),
        "se3_left_jacobian_inverse": (rj.se3_left_jacobian_inverse, (xi,)),
        "se3_right_jacobian_inverse": (rj.se3_right_jacobian_inverse, (xi,)),
        "RigidTransform": (
            lambda xi: rj.RigidTransform.from_exp_coords(xi).apply(xi[..., 3:]),
            (xi,),
        ),
        # dual quaternions [real, dual], the dual part not orthogonal to the real one
        "normalize_dual_quaternion": (
            lambda q: rj.normalize_dual_quaternion(jnp.concatenate([q, q[..., ::-1]], axis=-1)),
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


def public_inputs(n, dtype):
    """The inputs of :func:`every_public` for ``n`` random rotations (seed 21), in ``dtype``:
    quaternions, their matrices, rotation vectors and ZYX angles (by scipy: no program is
    compiled when a test module builds them at import)."""
    from scipy.spatial.transform import Rotation

    q = random_quaternions(n, seed=21)
    rot = Rotation.from_quat(q)
    derived = rot.as_matrix(), rot.as_rotvec(), rot.as_euler("ZYX")
    return [np.asarray(x).astype(dtype) for x in (q, *derived)]


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


# --- trouble-seeking batches (fuzzing) ---------------------------------------------------------

# Input scales every function must handle today, as exponents of two: about 1e-10..1e10 in
# float64 and 1e-6..1e6 in float32. (The full finite range is tested per function elsewhere.)
SCALE_EXP = {np.float32: 20, np.float64: 33}
QUAT_KINDS = ("generic", "identity", "near_identity", "half_turn", "near_half_turn", "tie",
              "lock", "near_lock", "tiny_vector")  # fmt: skip


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def trouble_quaternions(kinds, rng, seq="ZYX", tiny_exp=(-150, -20)):
    """Unit quaternions (float64, scalar last), one per entry of ``kinds`` (see
    :data:`QUAT_KINDS`): exactly at and near the identity and 180 degrees, component ties
    (equal magnitudes, as where the largest-component branch switches), exactly at and within
    1e-9 (relative) of gimbal lock of ``seq``, and vector parts of ``10^tiny_exp``."""
    n = len(kinds)
    q = _unit(rng.normal(size=(n, 4)))
    tiny = 10.0 ** rng.uniform(-12, -5, size=(n, 1))
    for i, kind in enumerate(kinds):
        if kind == "identity":
            q[i] = [0, 0, 0, 1]
        elif kind == "near_identity":
            q[i] = _unit(np.append(tiny[i] * q[i, :3], 1.0))
        elif kind == "half_turn":
            q[i] = np.append(_unit(q[i, :3]), 0.0)
        elif kind == "near_half_turn":
            q[i] = _unit(np.append(q[i, :3], tiny[i]))
        elif kind == "tie":
            signs = rng.choice([-1.0, 1.0], size=4)
            mask = rng.permutation([1.0, 1.0, 1.0, 0.0] if rng.random() < 0.5 else [1.0] * 4)
            q[i] = _unit(signs * np.where(mask > 0, 1.0, rng.uniform(0.1, 0.9)))
        elif kind in ("lock", "near_lock"):
            a = rng.uniform(-np.pi, np.pi, size=3)
            a[1] = lock_middles(seq)[rng.integers(2)]
            if kind == "near_lock":
                a[1] += tiny[i, 0] * 1e-4 * rng.choice([-1.0, 1.0])
            q[i] = mp_euler_quaternion(a, seq)
        elif kind == "tiny_vector":
            q[i] = _unit(np.append(10.0 ** rng.uniform(*tiny_exp) * q[i, :3], 1.0))
    return q


def mp_euler_quaternion(angles, seq):
    """Scalar-last quaternion of Euler angles by Hamilton products of elementary quaternions
    in float64 numpy (an independent construction, not rotjax's)."""
    from rotjax._euler import parse_seq

    axes, intrinsic = parse_seq(seq)
    qs = []
    for ax, a in zip(axes, angles, strict=True):
        e = np.zeros(4)
        e[ax], e[3] = np.sin(a / 2), np.cos(a / 2)
        qs.append(e)
    if not intrinsic:
        qs = qs[::-1]
    out = qs[0]
    for e in qs[1:]:
        out = _hamilton(out, e)
    return out


def _hamilton(p, q):
    (px, py, pz, pw), (qx, qy, qz, qw) = p, q
    return np.array(
        [
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
            pw * qw - px * qx - py * qy - pz * qz,
        ]
    )


@st.composite
def trouble_batches(draw, dtype, n=64):
    """A batch of ``n`` troubled rotations in ``dtype``, as the four inputs of
    :func:`every_public`: quaternions (not unit: random power-of-two-and-odd scales over
    :data:`SCALE_EXP`, random signs), their matrices with noise of up to 1e-3 (not orthogonal)
    and scaled, rotation vectors (angles at and near 0 and pi) and ZYX angles (some at and
    near gimbal lock); plus the unit quaternions in float64 for reference."""
    kinds = draw(st.lists(st.sampled_from(QUAT_KINDS), min_size=n, max_size=n))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    # vector parts whose square is still a normal number
    unit = trouble_quaternions(
        kinds, rng, tiny_exp=(-18, -6) if dtype == np.float32 else (-150, -20)
    )
    k = SCALE_EXP[dtype]
    scale = 2.0 ** rng.integers(-k, k + 1, size=(n, 1)) * rng.uniform(0.5, 1.5, size=(n, 1))
    q = unit * scale * rng.choice([-1.0, 1.0], size=(n, 1))
    R = np.asarray(rj.quaternion_to_matrix(unit))
    noise = rng.normal(size=(n, 3, 3)) * 10.0 ** rng.uniform(-16, -3, size=(n, 1, 1))
    R_noisy = (R + noise * (rng.random((n, 1, 1)) < 0.5)) * scale[:, :, None]
    w = np.asarray(rj.quaternion_to_rotvec(unit))
    a = np.asarray(rj.quaternion_to_euler(unit, "ZYX"))
    return [x.astype(dtype) for x in (q, R_noisy, w, a)], unit
