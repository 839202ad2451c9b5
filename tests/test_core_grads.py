"""Gradients: check_grads at generic points, and named regression tests at every singular point
(identity, 180 degrees, zero rotation vector, gimbal lock of every sequence)."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import (
    SEQS,
    angle_diff,
    assert_close,
    check_grads,
    check_hessian,
    is_proper,
    random_quaternions,
    sweep,
    undecorated,
)
from jax.test_util import check_jvp, check_vjp

import rotjax as rj
from rotjax._euler import parse_seq
from rotjax._numerics import skew

Q = random_quaternions(3, seed=31)
OMEGAS = np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1], [0.3, -0.7, 0.2]])
GENERIC = {
    "quaternion_to_matrix": (rj.quaternion_to_matrix, Q[0]),
    "matrix_to_quaternion_optimal": (
        lambda R: rj.matrix_to_quaternion(R, method="optimal"),
        np.asarray(rj.quaternion_to_matrix(Q[1])),
    ),  # fmt: skip
    "rotvec_to_quaternion": (rj.rotvec_to_quaternion, np.array([0.3, -1.2, 0.7])),
    "quaternion_to_rotvec": (rj.quaternion_to_rotvec, Q[2]),
    "rotvec_to_matrix": (rj.rotvec_to_matrix, np.array([0.3, -1.2, 0.7])),
    "rotation_angle": (rj.rotation_angle, Q[0]),
    "angle_between": (lambda q: rj.angle_between(Q[1], q), Q[0]),
    "quaternion_apply": (lambda q: rj.quaternion_apply(q, np.array([1.0, 2.0, 3.0])), Q[0]),
    "quaternion_multiply": (lambda q: rj.quaternion_multiply(q, Q[1]), Q[0]),
    "relative_rotation": (lambda q: rj.relative_rotation(q, Q[1]), Q[0]),
    "quaternion_inverse": (rj.quaternion_inverse, Q[0]),
    "axis_angle_to_quaternion": (
        lambda a: rj.axis_angle_to_quaternion(a, 0.7),
        np.array([1.0, 2, 3]),
    ),
    "quaternion_to_axis_angle": (rj.quaternion_to_axis_angle, Q[2]),
}


MATRIX_FUNCTIONS = {
    "shepperd": rj.matrix_to_quaternion,
    "markley": lambda m: rj.matrix_to_quaternion(m, method="markley"),
    "optimal": lambda m: rj.matrix_to_quaternion(m, method="optimal"),
    "matrix_to_rotvec": rj.matrix_to_rotvec,
}


def _noisy_batch(seed):
    """A rotation, and rotations with Gaussian noise of sigma 1e-3 and 0.1: generic points, away
    from the switches between largest-component branches."""
    rng = np.random.default_rng(seed)
    R = np.asarray(rj.quaternion_to_matrix(rng.normal(size=(3, 4))))
    return R + np.array([0.0, 1e-3, 0.1])[:, None, None] * rng.normal(size=R.shape)


# check_grads keeps each function's jitted programs (helpers._check_programs): a check of the
# same function (MATRIX_FUNCTIONS', OFF_SPHERE's) at another point, order or test runs them.
_check_grads = check_grads


# --- Euler programs shared by the tests of a sequence ---------------------------------------
# (The tests parametrized over SEQS take the sequence with module scope: pytest runs the tests
# of one sequence one after another, so that xdist's workers split the sequences between them,
# not the tests of one sequence.)
# Each Euler test of a sequence calls one compiled program per public function: its values,
# jvp and vjp, at one point (a batch of one row), called row by row. Compiling these programs is
# most of such a test's time; once one test of a sequence has compiled them, its other tests and
# parameters run them as they are. One point, not a batch: XLA:CPU vectorises a batch's loop,
# and LLVM's vectorised code for a derivative program takes 2-2.5x as long to compile (the
# values are those of the batched program, to an ulp of fused multiply-adds).
_EULER_OUT = {
    "matrix_to_euler": (3,),
    "quaternion_to_euler": (3,),
    "quaternion_to_euler_of_parts": (3,),
    "euler_to_matrix": (3, 3),
    "euler_to_quaternion": (4,),
}


@functools.partial(jax.jit, static_argnums=0)
def _derivatives(f, x, dx, ct):
    """``f(x)``, its jvp along ``dx`` and its vjp of ``ct``: one program."""
    out, jv = jax.jvp(f, (x,), (dx,))
    return out, jv, jax.vjp(f, x)[1](ct)[0]


@functools.partial(jax.jit, static_argnums=(0, 1))
def _euler_derivatives(name, seq, x, dx, ct):
    fn = _OF_PARTS.get(name) or getattr(rj, name)
    return _derivatives(lambda v: fn(v, seq), x, dx, ct)


def _quaternion_to_euler_of_parts(q, seq):
    """quaternion_to_euler of the parts of an earlier operation (`stack` notes them), which its
    derivative rule takes as they are, rather than of slices of an array."""
    from rotjax._numerics import stack, unstack

    return rj.quaternion_to_euler(stack(unstack(q)), seq)


_OF_PARTS = {"quaternion_to_euler_of_parts": _quaternion_to_euler_of_parts}


def _euler(name, seq, x, dx=None, ct=None):
    """``rj.<name>(x, seq)`` for the rows of ``x`` (float64), through the shared program; with
    ``dx``, also its jvp along ``dx`` and its vjp of ``ct`` (0 if not given), row by row."""
    x = np.asarray(x, np.float64)
    values_only = dx is None
    dx = np.zeros_like(x) if values_only else np.asarray(dx, np.float64)
    ct = np.zeros((len(x), *_EULER_OUT[name])) if ct is None else np.asarray(ct, np.float64)
    parts = [
        [np.asarray(o) for o in _euler_derivatives(name, seq, *(a[i : i + 1] for a in (x, dx, ct)))]
        for i in range(len(x))
    ]
    out, jv, vj = (np.concatenate(p) for p in zip(*parts, strict=True))
    return out if values_only else (out, jv, vj)


def _check_grads_euler(name, seq, x, batch=False):
    """``check_grads(lambda v: rj.<name>(v, seq), (x,), 1, modes=("fwd", "rev"))`` at one point
    ``x`` (``batch``: at a batch of points, rows of ``x``): the same checks (JAX's check_jvp and
    check_vjp: their random directions, finite differences and tolerances), through the shared
    program."""
    x = np.asarray(x, np.float64)
    rows = (lambda v: v) if batch else (lambda v: v[None])
    first = (lambda v: v) if batch else (lambda v: v[0])

    def f(v):
        return first(_euler(name, seq, rows(v)))

    def f_jvp(primals, tangents):
        out, jv, _ = _euler(name, seq, rows(primals[0]), rows(tangents[0]))
        return first(out), first(jv)

    def f_vjp(v):
        def pull(ct):
            return (first(_euler(name, seq, rows(v), rows(np.zeros_like(v)), rows(ct))[2]),)

        return f(v), pull

    check_jvp(f, f_jvp, (x,))
    check_vjp(f, f_vjp, (x,))


@pytest.mark.parametrize("name", sweep(sorted(MATRIX_FUNCTIONS), fast=["shepperd"]))
def test_check_grads_matrix_functions_on_and_off_so3(name):
    """The derivative of the function computed, along every basis direction, to second order,
    in both modes: the Jacobians and the Hessian against finite differences (one program)."""
    check_hessian(MATRIX_FUNCTIONS[name], _noisy_batch(3))


# Order 2 is slow: matrix_to_euler's derivative is JAX's of the Shepperd column (checked to
# order 2 above), then quaternion_to_euler's rule, whose second derivatives are compared with
# JAX's of its code (test_euler_hand_written_derivative_equals_autodiff_of_its_formula).
@pytest.mark.parametrize("order", sweep([1, 2], fast=[1]))
@pytest.mark.parametrize("seq", sweep(["ZXZ", "xyz"], fast=["xyz"]))
def test_check_grads_matrix_to_euler_on_and_off_so3(seq, order):
    if order == 1:  # through the sequence's shared program
        _check_grads_euler("matrix_to_euler", seq, _noisy_batch(4), batch=True)
    else:
        check_hessian(lambda m: rj.matrix_to_euler(m, seq), _noisy_batch(4))


@pytest.mark.parametrize("seq", SEQS, scope="module")
def test_matrix_to_euler_derivative_on_and_off_so3_equals_finite_differences(seq):
    """Every sequence, cheaply (the sequence's shared programs): forward mode equals central
    differences along random 3x3 directions, and reverse mode is its transpose."""
    R = _noisy_batch(5)
    dR = np.random.default_rng(6).normal(size=R.shape)
    ct = np.random.default_rng(7).normal(size=(len(R), 3))
    _, jv, g = _euler("matrix_to_euler", seq, R, dR, ct)
    h = 1e-6
    plus, minus = np.split(
        _euler("matrix_to_euler", seq, np.concatenate([R + h * dR, R - h * dR])), 2
    )
    assert_close(jv, angle_diff(plus, minus) / (2 * h), atol=1e-6)
    assert_close(np.sum(g * dR), np.sum(ct * jv), rtol=1e-12)


def _symmetric_direction(R, seed):
    """``R @ S`` with ``S`` symmetric: a direction off SO(3) (scaling and shear of the body)."""
    S = np.random.default_rng(seed).normal(size=(3, 3))
    return R @ (S + S.T)


@pytest.mark.parametrize(
    "name", [*sorted(MATRIX_FUNCTIONS), "matrix_to_euler_ZXZ", "matrix_to_euler_xyz"]
)
def test_derivative_along_symmetric_directions_equals_finite_differences(name):
    """Along R @ S the function moves (except "optimal", whose nearest rotation stays R to first
    order, and "markley", within O(sigma^2) of it): the jvp is the central difference, not a
    projected surrogate (0)."""
    if name in MATRIX_FUNCTIONS:
        f = MATRIX_FUNCTIONS[name]

        def jvp_of(R, dR):
            return jax.jvp(f, (jnp.asarray(R),), (jnp.asarray(dR),))[1]
    else:  # matrix_to_euler: the sequence's shared program
        seq = name[-3:]

        def f(m):
            return _euler("matrix_to_euler", seq, m[None])[0]

        def jvp_of(R, dR):
            return _euler("matrix_to_euler", seq, R[None], dR[None])[1][0]

    for k, R in enumerate([np.asarray(rj.quaternion_to_matrix(q)) for q in Q] + [np.eye(3)]):
        dR = _symmetric_direction(R, k)
        jvp = jvp_of(R, dR)
        h = 1e-6
        fd = (np.asarray(f(R + h * dR)) - np.asarray(f(R - h * dR))) / (2 * h)
        assert_close(jvp, fd, atol=1e-7)
        if name not in ("optimal", "markley") and k < len(Q):  # at the identity, all stay put
            assert np.abs(fd).max() > 1e-3  # the function does move: 0 would be wrong


@pytest.mark.parametrize("name", sweep(sorted(GENERIC), fast=sorted(GENERIC)[::3]))
def test_check_grads_generic(name):
    f, x = GENERIC[name]
    _check_grads(f, (x,), order=1, modes=("fwd", "rev"), atol=1e-6, rtol=1e-6)


OFF_SPHERE = {
    "quaternion_to_rotvec": rj.quaternion_to_rotvec,
    "quaternion_to_mrp": rj.quaternion_to_mrp,
    "quaternion_to_euler": lambda q: rj.quaternion_to_euler(q, "ZYX"),
    "rotvec_to_quaternion": lambda q: rj.rotvec_to_quaternion(3 * q[..., :3]),  # past pi
    "quaternion_apply": lambda q: rj.quaternion_apply(
        q, jnp.stack([q[..., 1], 2.0 - q[..., 3], q[..., 0]], -1)
    ),
}


# Order 2 is slow: the default tier compares the rules' second derivatives with JAX's of the
# forward code (the *_hand_written_derivative_equals_autodiff_of_its_formula tests) and checks
# that the others' are finite (the *_derivatives_finite_* tests).
@pytest.mark.parametrize("order", sweep([1, 2], fast=[1]))
@pytest.mark.parametrize("name", sorted(OFF_SPHERE))
def test_check_grads_off_the_unit_sphere(name, order):
    """Quaternion conversions at quaternions of norm 0.3 and 4 (off the unit sphere, where the
    derivative, a rule's for quaternion_to_euler and rotvec_to_quaternion, must still be that
    of the code) and on it: first and second order, both modes (quaternion_apply in both
    arguments through one input)."""
    q = np.concatenate([Q[:2] * 0.3, Q[2:] * 4.0, Q[:1]])
    _check_grads(OFF_SPHERE[name], (q,), order=order, modes=("fwd", "rev"))


@pytest.mark.parametrize("seq", SEQS, scope="module")
def test_check_grads_euler_generic(seq):
    a = np.array([0.4, 1.1 if is_proper(seq) else 0.6, -2.0])
    _check_grads_euler("euler_to_matrix", seq, a)
    _check_grads_euler("euler_to_quaternion", seq, a)
    q = _euler("euler_to_quaternion", seq, a[None])[0]
    _check_grads_euler("quaternion_to_euler", seq, q)
    # d angles along R omega^ equals central differences along R exp(t omega^)
    R = _euler("euler_to_matrix", seq, a[None])[0]
    dR = R @ np.asarray(skew(OMEGAS))
    _, jvp, _ = _euler("matrix_to_euler", seq, np.broadcast_to(R, dR.shape), dR)
    h = 1e-6
    steps = np.asarray(rj.rotvec_to_matrix(np.concatenate([h * OMEGAS, -h * OMEGAS])))
    plus, minus = np.split(_euler("matrix_to_euler", seq, R @ steps), 2)
    assert_close(jvp, angle_diff(plus, minus) / (2 * h), atol=1e-7)


# --- exact derivatives at the identity / zero rotation vector --------------------------------


def test_rotvec_to_quaternion_jacobian_at_zero_is_half_identity():
    J = np.asarray(jax.jacfwd(rj.rotvec_to_quaternion)(jnp.zeros(3)))
    np.testing.assert_array_equal(J, np.vstack([0.5 * np.eye(3), np.zeros((1, 3))]))
    Jr = np.asarray(jax.jacrev(rj.rotvec_to_quaternion)(jnp.zeros(3)))
    np.testing.assert_array_equal(Jr, J)


def test_log_map_jacobian_at_identity_is_two_identity():
    J = np.asarray(jax.jacfwd(rj.quaternion_to_rotvec)(jnp.array([0.0, 0, 0, 1])))
    np.testing.assert_array_equal(J, np.hstack([2 * np.eye(3), np.zeros((3, 1))]))
    Jr = np.asarray(jax.jacrev(rj.quaternion_to_rotvec)(jnp.array([0.0, 0, 0, 1])))
    np.testing.assert_array_equal(Jr, J)


def test_rotvec_to_matrix_jacobian_at_zero_is_hat():
    J = np.asarray(jax.jacfwd(rj.rotvec_to_matrix)(jnp.zeros(3)))
    for k in range(3):
        np.testing.assert_array_equal(J[..., k], np.asarray(skew(jnp.eye(3)[k])))


@pytest.mark.parametrize("scale", [1e-9, 1e-5, 1e-2])
def test_exp_log_near_zero_match_finite_differences(scale):
    """Where the Taylor branch meets the closed form the derivatives agree with FD."""
    v = scale * np.array([0.3, -0.5, 0.8])
    _check_grads(rj.rotvec_to_quaternion, (v,), 1, modes=("fwd", "rev"), eps=scale * 1e-3)
    _check_grads(rj.rotvec_to_matrix, (v,), 1, modes=("fwd", "rev"), eps=scale * 1e-3)
    q = np.asarray(rj.rotvec_to_quaternion(v))
    _check_grads(rj.quaternion_to_rotvec, (q,), 1, modes=("fwd", "rev"), eps=scale * 1e-3)


def test_quaternion_to_matrix_grads_at_identity_and_180():
    for q in [np.array([0.0, 0, 0, 1]), np.array([1.0, 0, 0, 0]), np.array([0.0, 0.6, 0.8, 0])]:
        _check_grads(rj.quaternion_to_matrix, (q,), 2, modes=("fwd", "rev"))


# --- matrix -> quaternion on SO(3): tangent directions ---------------------------------------

SPECIAL_MATRICES = {
    "identity": np.eye(3),
    "180_x": np.diag([1.0, -1, -1]),
    "180_y": np.diag([-1.0, 1, -1]),
    "180_z": np.diag([-1.0, -1, 1]),
    "180_generic": np.asarray(rj.rotvec_to_matrix(np.pi * np.array([2.0, -3, 6]) / 7)),
    "tie_120": np.array([[0.0, 0, 1], [1, 0, 0], [0, 1, 0]]),  # all |q_i| = 1/2
    "generic": np.asarray(rj.quaternion_to_matrix(Q[1])),
}


def _aligned_fd(f, R, omega, h=1e-6):
    """Central difference of f(R exp(t omega^)) at t=0, each sample sign-aligned to f(R)."""
    f0 = np.asarray(f(R))
    out = []
    for t in (h, -h):
        ft = np.asarray(f(R @ np.asarray(rj.rotvec_to_matrix(t * omega))))
        out.append(ft if np.dot(ft, f0) >= 0 else -ft)
    return (out[0] - out[1]) / (2 * h)


@pytest.mark.parametrize("method", ["shepperd", "markley", "optimal"])
@pytest.mark.parametrize("name", sorted(SPECIAL_MATRICES))
def test_matrix_to_quaternion_tangent_derivative(name, method):
    R = SPECIAL_MATRICES[name]
    f = lambda m: rj.matrix_to_quaternion(m, method=method)  # noqa: E731
    for omega in OMEGAS:
        _, jvp = jax.jvp(f, (jnp.asarray(R),), (jnp.asarray(R @ np.asarray(skew(omega))),))
        q = np.asarray(f(R))
        # exact tangent identity dq = q (x) (omega/2, 0) for a unit q
        expected = np.asarray(rj.quaternion_multiply(q, np.array([*(omega / 2), 0.0])))
        assert_close(jvp, expected, atol=1e-9, err_msg=f"omega={omega}")
        assert_close(jvp, _aligned_fd(f, R, omega), atol=1e-7, err_msg=f"omega={omega}")
        g = jax.grad(lambda m: jnp.dot(f(m), jnp.asarray(expected)))(jnp.asarray(R))
        assert np.all(np.isfinite(g)) and np.abs(g).max() > 0


@pytest.mark.parametrize("method", ["shepperd", "markley"])
@pytest.mark.parametrize("name", sorted(set(SPECIAL_MATRICES) - {"tie_120"}))
def test_matrix_to_quaternion_ambient_derivative_at_special_matrices(name, method):
    """At the identity and at 180 degrees the true derivative exists in every 3x3 direction
    (the selected column is unique there): finite, and equal to central differences."""
    R = SPECIAL_MATRICES[name]
    f = lambda m: rj.matrix_to_quaternion(m, method=method)  # noqa: E731
    f0 = np.asarray(f(R))

    def branch(x):  # at 180 degrees (w = 0) the branch taken: samples sign-aligned to f(R)
        x = np.asarray(f(x))
        return x if np.dot(x, f0) >= 0 else -x

    for k in range(3):
        dR = np.random.default_rng(k).normal(size=(3, 3))
        _, jvp = jax.jvp(f, (jnp.asarray(R),), (jnp.asarray(dR),))
        h = 1e-6
        fd = (branch(R + h * dR) - branch(R - h * dR)) / (2 * h)
        assert_close(jvp, fd, atol=1e-7)


@pytest.mark.parametrize("name", sorted(SPECIAL_MATRICES))
def test_matrix_to_rotvec_tangent_derivative(name):
    """exp(log(R)) = R on SO(3), so the derivative of the composition along R omega^ returns
    R omega^; at the identity d log = omega exactly."""
    R = SPECIAL_MATRICES[name]
    for omega in OMEGAS:
        dR = R @ np.asarray(skew(omega))
        _, jvp = jax.jvp(
            lambda m: rj.rotvec_to_matrix(rj.matrix_to_rotvec(m)),
            (jnp.asarray(R),),
            (jnp.asarray(dR),),
        )
        assert_close(jvp, dR, atol=1e-12)
        if name == "identity":
            _, d = jax.jvp(rj.matrix_to_rotvec, (jnp.asarray(R),), (jnp.asarray(dR),))
            assert_close(d, omega, atol=1e-15)


@pytest.mark.parametrize(
    "q", [np.array([1.0, 0, 0, 0]), np.array([0.0, 0.6, 0.8, 0]), np.array([0.6, 0, 0.8, 1e-12])]
)
def test_log_map_derivative_at_180_is_the_branch_derivative(q):
    """At 180 degrees the log has a cut; the gradient is that of the w >= 0 branch, so
    exp(log(q)) reproduces dR exactly."""
    for dq in np.eye(4):
        _, lhs = jax.jvp(lambda x: rj.rotvec_to_matrix(rj.quaternion_to_rotvec(x)), (q,), (dq,))
        _, rhs = jax.jvp(rj.quaternion_to_matrix, (q,), (dq,))
        assert_close(lhs, rhs, atol=1e-10)


# --- angles: finite and correct at 0 ---------------------------------------------------------


def test_rotation_angle_gradient_at_identity_and_near_it():
    ident = jnp.array([0.0, 0, 0, 1])
    g = np.asarray(jax.grad(rj.rotation_angle)(ident))
    np.testing.assert_array_equal(g, np.zeros(4))  # cone minimum: minimum-norm subgradient
    g2 = np.asarray(jax.grad(lambda q: rj.rotation_angle(q) ** 2)(ident))
    np.testing.assert_array_equal(g2, np.zeros(4))  # smooth loss: true derivative 0
    for t in [1e-12, 1e-6]:
        q = np.array([np.sin(t / 2), 0, 0, np.cos(t / 2)])
        g = np.asarray(jax.grad(rj.rotation_angle)(q))
        assert_close(g, [2 * np.cos(t / 2), 0, 0, -2 * np.sin(t / 2)], atol=1e-12)  # not silently 0
        gb = np.asarray(jax.grad(lambda p: rj.angle_between(p, q))(jnp.array([0.0, 0, 0, 1])))
        assert_close(np.abs(gb[0]), 2 * np.cos(t / 2), atol=1e-12)


# --- Euler angles at and near gimbal lock ----------------------------------------------------


def _exact_lock_quaternion(seq, mid_index):
    """An exactly representable quaternion at gimbal lock: products of unnormalised elementary
    quaternions (tan(a/2) e_i, 1) with small dyadic entries."""
    axes, intrinsic = parse_seq(seq)
    lock_mid = [(0.0, 1.0), (1.0, 0.0)] if is_proper(seq) else [(1.0, 1.0), (-1.0, 1.0)]
    s, c = lock_mid[mid_index]  # unnormalised (sin, cos) of half the middle angle

    def elem(ax, s, c):
        e = np.zeros(4)
        e[ax], e[3] = s, c
        return e

    parts = [elem(axes[0], 0.5, 1.0), elem(axes[1], s, c), elem(axes[2], -0.25, 1.0)]
    mult = lambda p, q: np.asarray(rj.quaternion_multiply(p, q))  # noqa: E731
    return (
        mult(mult(parts[0], parts[1]), parts[2])
        if intrinsic
        else mult(mult(parts[2], parts[1]), parts[0])
    )


def _lock_combination_sign(seq, angles):
    """s such that only a0 + s * a2 is defined at this lock, found from the forward map."""
    moved = [angles + np.array([-s * 0.3, 0.0, 0.3]) for s in (1.0, -1.0)]
    R, *R_moved = _euler("euler_to_matrix", seq, np.stack([angles, *moved]))
    for s, Rs in zip((1.0, -1.0), R_moved, strict=True):
        if np.abs(Rs - R).max() < 1e-12:
            return s
    raise AssertionError("not at gimbal lock")


@pytest.mark.parametrize("mid_index", [0, 1], ids=["lock_a", "lock_b"])
@pytest.mark.parametrize("seq", SEQS, scope="module")
def test_euler_gradient_rule_at_exact_lock(seq, mid_index):
    """Exactly at lock: the third angle is 0; its derivative and the middle angle's are 0; the
    first angle's derivative is that of the defined combination a0 + s a2 (finite
    differences of that smooth function through nearby non-locked points). Both modes: the
    Jacobian's columns are jvps along the four unit vectors, its rows vjps of the three."""
    q = _exact_lock_quaternion(seq, mid_index)
    ang = _euler("quaternion_to_euler", seq, q[None])[0]
    assert ang[2] == 0.0
    assert_close(
        _euler("euler_to_matrix", seq, ang[None])[0], rj.quaternion_to_matrix(q), atol=1e-15
    )
    s = _lock_combination_sign(seq, ang)
    _, jv, vj = _euler("quaternion_to_euler", seq, np.tile(q, (4, 1)), np.eye(4), np.eye(4, 3))
    J, Jf = vj[:3], jv.T  # reverse mode, forward mode
    assert np.all(np.isfinite(J))
    np.testing.assert_array_equal(J[1:], 0.0)
    assert np.abs(J[0]).max() > 0.1  # not a silent zero

    h = 1e-7
    a = _euler("quaternion_to_euler", seq, np.concatenate([q + h * np.eye(4), q - h * np.eye(4)]))
    combo_plus, combo_minus = np.split(a[:, 0] + s * a[:, 2], 2)
    fd = angle_diff(combo_plus, combo_minus) / (2 * h)
    assert_close(J[0], fd, atol=1e-6)
    assert_close(Jf, J, atol=1e-15)


@pytest.mark.parametrize("seq", SEQS, scope="module")
def test_euler_gradients_near_lock_are_true_derivatives(seq):
    """1e-9 from lock the angles are differentiable; the derivative of the round trip
    R -> angles -> R is the identity on tangent vectors (values ~1e9 cancel correctly)."""
    mid = 1e-9 if is_proper(seq) else np.pi / 2 - 1e-9
    R = _euler("euler_to_matrix", seq, np.array([[0.4, mid, -1.3]]))[0]
    dR = R @ np.asarray(skew(OMEGAS))
    Rs = np.broadcast_to(R, dR.shape)
    # the chain rule through the two programs: d(euler_to_matrix)(angles; d angles)
    ang, dang, g = _euler("matrix_to_euler", seq, Rs, dR, np.ones((len(dR), 3)))
    _, jvp, _ = _euler("euler_to_matrix", seq, ang, dang)
    assert_close(jvp, dR, atol=1e-6)
    assert np.all(np.isfinite(g))


@pytest.mark.parametrize("seq", SEQS, scope="module")
def test_euler_to_matrix_grads_at_lock(seq):
    """The forward map is smooth everywhere, gimbal lock included."""
    for mid in (0.0, np.pi) if is_proper(seq) else (np.pi / 2, -np.pi / 2):
        a = np.array([0.3, mid, 0.5])
        _check_grads_euler("euler_to_matrix", seq, a)
        _check_grads_euler("euler_to_quaternion", seq, a)


def _exp_rule_matches_autodiff(rule, ref, seed, primal_ulps=0, batch=None):
    """The custom jvp of ``rule`` (a function of rotation vectors) and its transpose equal
    JAX's own derivatives of ``ref`` (its forward code): the zero vector, the Taylor branch and
    its edge, angles near and at pi, 2 pi and beyond, in both dtypes; Hessians at three points
    (``batch``: each repeated that many times, the first result taken). ``primal_ulps``: how far
    the two primals may differ (0: equal)."""
    rng = np.random.default_rng(seed)
    axes = rng.normal(size=(40, 3))
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    angles = np.concatenate(
        [[0.0, 1e-12, 1e-6, 3e-4, 1e-2, np.pi, 2 * np.pi, 7.5, 40.0], rng.uniform(0, 12, 31)]
    )
    jit = jax.jit
    for dtype, tol in ((jnp.float64, 1e-14), (jnp.float32, 2e-6)):
        v = jnp.asarray(axes * angles[:, None], dtype)
        dv = jnp.asarray(rng.normal(size=v.shape), dtype)
        out, jv = jit(lambda x, t: jax.jvp(rule, (x,), (t,)))(v, dv)
        out_ref, jv_ref = jit(lambda x, t: jax.jvp(ref, (x,), (t,)))(v, dv)
        if primal_ulps:
            assert_close(out, out_ref, atol=primal_ulps * float(jnp.finfo(dtype).eps))
        else:
            np.testing.assert_array_equal(out, out_ref)
        assert jv.dtype == dtype
        assert_close(jv, jv_ref, atol=tol)
        ct = jnp.asarray(rng.normal(size=out.shape), dtype)
        g = jit(jax.grad(lambda x: jnp.sum(ct * rule(x))))(v)
        g_ref = jit(jax.grad(lambda x: jnp.sum(ct * ref(x))))(v)
        assert np.all(np.isfinite(np.asarray(g)))
        assert_close(g, g_ref, atol=tol * (1 + float(jnp.abs(g_ref).max())))

    def point(fn):
        return fn if batch is None else lambda x: fn(jnp.broadcast_to(x, (batch, 3)))[0]

    hess, hess_ref = (jit(jax.hessian(point(fn))) for fn in (rule, ref))
    for x in (jnp.zeros(3), jnp.asarray(axes[0] * 1e-5), jnp.asarray(axes[1] * 2.0)):
        h, h_ref = hess(x), hess_ref(x)
        assert_close(h, h_ref, atol=1e-13 * (1 + float(jnp.abs(h_ref).max())))


def test_exp_map_hand_written_derivative_equals_autodiff_of_its_formula():
    """rotvec_to_quaternion's custom jvp (and its transpose, and second derivatives) equals
    JAX's own derivative of the forward code."""
    from rotjax._rotvec import _rotvec_to_quat_parts, rotvec_to_quat

    _exp_rule_matches_autodiff(rotvec_to_quat, undecorated(_rotvec_to_quat_parts), 29)


def test_exp_matrix_rule_equals_autodiff_of_its_forward():
    """rotvec_to_matrix's custom jvp (the derivative of the matrix of rotvec_to_quaternion)
    equals JAX's own derivative of its forward code: on the CPU the per-slot form, with XLA's
    root and divisions (a batch of eight for the Hessians: a few rotations take the
    per-rotation form). The primals are the same code compiled beside different tangent code:
    equal to an ulp."""
    from rotjax._rotvec import _exp_matrix

    _exp_rule_matches_autodiff(_exp_matrix, _exp_matrix.fun, 31, primal_ulps=2, batch=8)


@functools.partial(jax.jit, static_argnums=0)
def _vmap_grad(f, u):
    return jax.vmap(jax.grad(f))(u)


@pytest.mark.parametrize("which", ["rotvec", "mrp"])
def test_rotvec_derivatives_finite_at_any_scale(which):
    """quaternion_to_rotvec's and quaternion_to_mrp's derivatives (JAX's of their code) are
    finite, first and second: quaternions of norms 1e-20 to 1e20, identity and near it,
    180 degrees, both signs of w, and n = |w| (the switch between the two atan forms); NaN
    where q is zero or not finite."""
    f = {"rotvec": rj.quaternion_to_rotvec, "mrp": rj.quaternion_to_mrp}[which]
    rng = np.random.default_rng(23)
    special = [
        [0, 0, 0, 1.0], [0, 0, 0, -2.0], [1e-9, -2e-9, 0, 1], [1.0, 0, 0, 0], [0, 3, 4, 0],
        [0.6, 0, 0.8, 1.0], [-0.6, 0, 0.8, -1.0], [1e-12, 0, 0, -1], [1, 2, 2, 1e-9],
    ]  # fmt: skip
    q = np.concatenate([special, rng.normal(size=(24, 4))])
    q = jnp.asarray(q * np.exp(rng.uniform(-46, 46, size=(len(q), 1))))
    dq = jnp.asarray(rng.normal(size=q.shape)) * jnp.linalg.norm(q, axis=-1, keepdims=True)
    jit = jax.jit
    out, jv = jit(lambda x, t: jax.jvp(f, (x,), (t,)))(q, dq)
    assert np.all(np.isfinite(np.asarray(jv)))
    ct = jnp.asarray(rng.normal(size=out.shape))
    grad = jit(jax.grad(lambda x, c: jnp.sum(c * f(x))))
    assert np.all(np.isfinite(np.asarray(grad(q, ct))))
    hess = jit(jax.hessian(f))
    for x in (q[-1] / jnp.linalg.norm(q[-1]), q[2], q[3]):  # generic, near identity, 180 degrees
        assert np.all(np.isfinite(np.asarray(hess(x))))
    # no rotation (zero or not finite q, in the first rows): NaN derivative
    qb = q.at[:3].set(jnp.array([[0.0, 0, 0, 0], [np.inf, 0, 0, 1], [np.nan, 0, 0, 1]]))
    g = grad(qb, jnp.ones_like(ct))
    assert np.all(np.isnan(g[:3])) and not np.any(np.isnan(g[3:]))


def test_atan_ratio_rule_equals_autodiff_of_its_formula():
    """The rotation vector's polynomial atan(sqrt(u)) / sqrt(u): its rule equals JAX's
    derivative of its code on [0, 1], in both dtypes."""
    from rotjax._elementary import atan_ratio

    u = jnp.linspace(0.0, 1.0, 257)
    for dtype, tol in ((jnp.float64, 1e-15), (jnp.float32, 1e-6)):
        d = _vmap_grad(atan_ratio, u.astype(dtype))
        d_ref = _vmap_grad(atan_ratio.fun, u.astype(dtype))
        assert d.dtype == dtype
        assert_close(d, d_ref, atol=tol)


@pytest.mark.parametrize("method", ["shepperd", "markley", "optimal"])
def test_matrix_to_quaternion_float32_derivatives_stay_float32(method):
    """The derivatives keep the input dtype, in both modes (a float64 constant inside a rule
    or the code would otherwise promote the tangent and JAX would reject it)."""
    R = jnp.asarray(rj.quaternion_to_matrix(np.array([0.3, -0.5, 0.2, 0.78])), dtype=jnp.float32)
    f = lambda m: rj.matrix_to_quaternion(m, method=method)  # noqa: E731
    ones = jnp.ones(4, jnp.float32)
    _, jv, g = _derivatives(f, R, jnp.ones_like(R), ones)  # jvp and vjp, one program
    assert jv.dtype == jnp.float32 and g.dtype == jnp.float32
    assert np.all(np.isfinite(np.asarray(g)))
    g64 = jax.grad(lambda m: jnp.sum(f(m)))(R.astype(jnp.float64))
    assert_close(g, g64, atol=1e-5)


def _euler_test_quaternions(seq):
    """Random quaternions of norms from 1e-20 to 1e20, points 1e-9 from both locks, both exact
    locks, and 180-degree rotations about each axis."""
    rng = np.random.default_rng(17)
    qs = list(rng.normal(size=(12, 4)) * np.exp(rng.uniform(-46, 46, size=(12, 1))))
    mids = (1e-9, np.pi - 1e-9) if is_proper(seq) else (np.pi / 2 - 1e-9, 1e-9 - np.pi / 2)
    qs += list(_euler("euler_to_quaternion", seq, [[0.4, mid, -1.3] for mid in mids]))
    qs += [_exact_lock_quaternion(seq, i) for i in (0, 1)]
    qs += list(np.hstack([np.eye(3), np.zeros((3, 1))]))
    return np.array(qs)


def _assert_rule_equals_autodiff(rule, ref, x, dx, ct, min_same=None):
    """The custom jvp of a public function and its transpose (``rule``: its values, jvp along
    ``dx`` and vjp of ``ct``, row by row) equal JAX's own derivatives of ``ref``, the same code
    without the rule (its jvp and vjp: one program), row by row, relative to each row's size.

    ``min_same``: None, the two primals must be equal; else the rows whose primals differ by
    more than 1e-12 rad are left out, at most ``1 - min_same`` of them (JAX's jvp of the forward
    code rounds its primal differently, by an ulp or so; where that moves a point across a lock
    test, it differentiates another branch). Returns the rule's primal."""
    out, jv, gr = rule
    # row by row, as the rule's rows (`_euler`): the same compiled code for both
    rows = [_derivatives(ref, *(a[i : i + 1] for a in (x, dx, ct))) for i in range(len(x))]
    out_ref, jv_ref, gr_ref = (np.concatenate(r) for r in zip(*rows, strict=True))
    if min_same is None:
        np.testing.assert_array_equal(out, out_ref)
        same = np.ones(out.shape[:-1], bool)
    else:
        same = np.abs(angle_diff(out, out_ref)).max(axis=-1) < 1e-12
        assert same.mean() > min_same, same
    scale = 1 + np.abs(jv_ref).max(axis=-1, keepdims=True)
    assert_close((jv / scale)[same], (jv_ref / scale)[same], atol=1e-14)
    assert np.all(np.isfinite(gr))
    row_axes = tuple(range(out.ndim - 1, x.ndim))
    scale = np.abs(gr_ref).max(axis=row_axes, keepdims=True)
    assert_close((gr / scale)[same], (gr_ref / scale)[same], atol=1e-14)
    return out


@pytest.mark.parametrize("seq", SEQS, scope="module")
def test_matrix_to_euler_derivatives_finite_at_any_scale(seq):
    """matrix_to_euler's derivatives (JAX's of the Shepperd column, then quaternion_to_euler's
    rule), both modes, are finite: the matrices of quaternions of any norm, near and exactly at
    lock and at 180 degrees, scaled by 1e-20 to 1e20, with noise, and random matrices; the
    shared program's angles are the forward's."""
    rng = np.random.default_rng(23)
    R = np.asarray(rj.quaternion_to_matrix(_euler_test_quaternions(seq)))
    R = np.concatenate([R, R + 1e-3 * rng.normal(size=R.shape), rng.normal(size=(6, 3, 3))])
    R = R * np.exp(rng.uniform(-46, 46, size=(len(R), 1, 1)))
    dR = rng.normal(size=R.shape) * np.abs(R).max(axis=(-2, -1), keepdims=True)
    ct = rng.normal(size=(len(R), 3))
    out, jv, gr = _euler("matrix_to_euler", seq, R, dR, ct)
    assert np.all(np.isfinite(jv)) and np.all(np.isfinite(gr))
    assert_close(angle_diff(out, rj.matrix_to_euler(R, seq)), 0, atol=1e-15)  # the forward's


@pytest.mark.parametrize("seq", SEQS, scope="module")
def test_euler_hand_written_derivative_equals_autodiff_of_its_formula(seq):
    """quaternion_to_euler's custom jvp (and its transpose) equals JAX's own derivative of the
    forward code, everywhere: generic points of any norm, near and exactly at lock (where the
    forward code's selects define the gradient rule), 180 degrees; second derivatives too."""
    from rotjax._euler import _quat_to_euler_stacked, quat_to_euler

    ref = undecorated(_quat_to_euler_stacked, seq)

    q = _euler_test_quaternions(seq)
    rng = np.random.default_rng(5)
    dq = rng.normal(size=q.shape) * np.linalg.norm(q, axis=-1, keepdims=True)
    ct = rng.normal(size=(len(q), 3))
    rule = _euler("quaternion_to_euler", seq, q, dq, ct)
    _assert_rule_equals_autodiff(rule, ref, q, dq, ct)
    # the rule's form for the parts of an earlier operation (matrix_to_euler's, a chain's)
    rule = _euler("quaternion_to_euler_of_parts", seq, q, dq, ct)
    _assert_rule_equals_autodiff(rule, ref, q, dq, ct)
    # second derivatives at a generic point and at exact lock: the rule's forward over reverse
    # (as jax.hessian), the reference's forward over forward (as jacfwd of jacfwd), each one
    # program at one point called along each basis direction and cotangent (a vmapped
    # Jacobian's batch would compile 2x slower)
    f = functools.partial(quat_to_euler, seq=seq)
    hvp = jax.jit(lambda x, e, c: jax.jvp(lambda y: jax.vjp(f, y)[1](c)[0], (x,), (e,))[1])
    ffd = jax.jit(lambda x, e, d: jax.jvp(lambda y: jax.jvp(ref, (y,), (e,))[1], (x,), (d,))[1])
    eye4, eye3 = np.eye(4), np.eye(3)
    for x in (q[0] / np.linalg.norm(q[0]), q[-4]):
        # [output, inner direction, outer direction]
        h = np.array([[hvp(x, e, c) for e in eye4] for c in eye3]).swapaxes(1, 2)
        h_ref = np.moveaxis(np.array([[ffd(x, e, d) for d in eye4] for e in eye4]), -1, 0)
        assert_close(h, h_ref, atol=1e-13 * (1 + np.abs(h_ref).max()))


def test_euler_derivative_of_zero_and_nonfinite_quaternions():
    """No rotation, no derivative: the angles are NaN and the derivative is 0 (not NaN, so one
    bad row does not poison a batch's gradient), as JAX's derivative of the forward code."""
    q = jnp.array([[0.0, 0, 0, 0], [np.inf, 0, 0, 1], [np.nan, 0, 0, 1], [0.1, 0.2, 0.3, 0.9]])
    g = jax.grad(lambda x: jnp.sum(jnp.nan_to_num(rj.quaternion_to_euler(x, "ZYX"))))(q)
    np.testing.assert_array_equal(g[:3], 0.0)
    assert np.abs(np.asarray(g[3])).min() > 0.01


@pytest.mark.parametrize("fn", ["quaternion_to_euler", "matrix_to_euler"])
def test_euler_float32_derivatives_stay_float32(fn):
    q = np.array([0.3, -0.5, 0.2, 0.78])
    x = q if fn == "quaternion_to_euler" else np.asarray(rj.quaternion_to_matrix(q))
    f = lambda v: getattr(rj, fn)(v, "zxz")  # noqa: E731
    x32 = jnp.asarray(x, dtype=jnp.float32)
    ones = jnp.ones(3, jnp.float32)
    _, jv, g = _derivatives(f, x32, jnp.ones_like(x32), ones)  # jvp and vjp, one program
    assert jv.dtype == jnp.float32 and g.dtype == jnp.float32
    g64 = _euler(fn, "zxz", x[None], np.zeros_like(x)[None], np.ones((1, 3)))[2][0]  # shared
    assert_close(g, g64, atol=1e-5)


_F32_PROGRAMS = {
    "quaternion_to_matrix": (rj.quaternion_to_matrix, "q"),
    "matrix_to_quaternion": (rj.matrix_to_quaternion, "R"),
    "optimal": (lambda m: rj.matrix_to_quaternion(m, method="optimal"), "R"),
    "markley": (lambda m: rj.matrix_to_quaternion(m, method="markley"), "R"),
    "quaternion_to_rotvec": (rj.quaternion_to_rotvec, "q"),
    "rotvec_to_quaternion": (rj.rotvec_to_quaternion, "v"),
    "quaternion_to_euler": (lambda q: rj.quaternion_to_euler(q, "ZYX"), "q"),
    "matrix_to_euler": (lambda m: rj.matrix_to_euler(m, "zxz"), "R"),
    "euler_to_quaternion": (lambda a: rj.euler_to_quaternion(a, "ZYX"), "v"),
    "quaternion_to_mrp": (rj.quaternion_to_mrp, "q"),
    "mrp_to_quaternion": (rj.mrp_to_quaternion, "v"),
    "nined_to_matrix": (lambda m: rj.nined_to_matrix(m.reshape(-1, 9)), "R"),
    "align_vectors": (lambda m: rj.align_vectors(m, m[..., ::-1, :]), "R"),
    "quaternion_mean": (lambda q: rj.quaternion_mean(q.reshape(4, 4, 4)), "q"),
    "unwrap_quaternion": (rj.unwrap_quaternion, "q"),
}


@pytest.mark.parametrize("name", sweep(_F32_PROGRAMS, fast=list(_F32_PROGRAMS)[::3]))
def test_float32_programs_hold_no_float64_array(name):
    """With x64 on, a float32 call compiles to float32 arithmetic, forward and jit(grad): a
    float64 array (e.g. ``jnp.where`` on two Python numbers) would be computed and converted in
    every loop that reads it."""
    f, kind = _F32_PROGRAMS[name]
    q = jnp.asarray(np.random.default_rng(5).normal(size=(16, 4)), jnp.float32)
    x = {"q": q, "R": rj.quaternion_to_matrix(q), "v": q[:, :3]}[kind]
    for g in (jax.jit(f), jax.jit(jax.grad(lambda x: jnp.sum(f(x))))):
        hlo = g.lower(x).compile().as_text()
        assert "f64[" not in hlo, [line for line in hlo.splitlines() if "f64[" in line][:3]
