"""Gradients: check_grads at generic points, and named regression tests at every singular point
(identity, 180 degrees, zero rotation vector, gimbal lock of every sequence)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import SEQS, angle_diff, assert_close, is_proper, random_quaternions
from jax.test_util import check_grads

import rotjax as rj
from rotjax._euler import parse_seq
from rotjax._numerics import hat

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


# Functions of a matrix are checked along tangent directions of SO(3) below: off SO(3) their
# derivative is defined by the rotation (see matrix_to_quaternion), not by ambient FD.


@pytest.mark.parametrize("name", sorted(GENERIC))
def test_check_grads_generic(name):
    f, x = GENERIC[name]
    check_grads(f, (x,), order=1, modes=("fwd", "rev"), atol=1e-6, rtol=1e-6)


@pytest.mark.parametrize("seq", SEQS)
def test_check_grads_euler_generic(seq):
    a = np.array([0.4, 1.1 if is_proper(seq) else 0.6, -2.0])
    check_grads(lambda x: rj.euler_to_matrix(x, seq), (a,), 1, modes=("fwd", "rev"))
    check_grads(lambda x: rj.euler_to_quaternion(x, seq), (a,), 1, modes=("fwd", "rev"))
    q = np.asarray(rj.euler_to_quaternion(a, seq))
    check_grads(lambda x: rj.quaternion_to_euler(x, seq), (q,), 1, modes=("fwd", "rev"))
    R = np.asarray(rj.euler_to_matrix(a, seq))
    for omega in OMEGAS:  # d angles along R omega^ equals the rate-map answer, by FD
        dR = R @ np.asarray(hat(omega))
        _, jvp = jax.jvp(
            lambda m: rj.matrix_to_euler(m, seq), (jnp.asarray(R),), (jnp.asarray(dR),)
        )
        h = 1e-6
        plus = rj.matrix_to_euler(R @ np.asarray(rj.rotvec_to_matrix(h * omega)), seq)
        minus = rj.matrix_to_euler(R @ np.asarray(rj.rotvec_to_matrix(-h * omega)), seq)
        fd = angle_diff(plus, minus) / (2 * h)
        assert_close(jvp, fd, atol=1e-7)


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
        np.testing.assert_array_equal(J[..., k], np.asarray(hat(jnp.eye(3)[k])))


@pytest.mark.parametrize("scale", [1e-9, 1e-5, 1e-2])
def test_exp_log_near_zero_match_finite_differences(scale):
    """Where the Taylor branch meets the closed form the derivatives agree with FD."""
    v = scale * np.array([0.3, -0.5, 0.8])
    check_grads(rj.rotvec_to_quaternion, (v,), 1, modes=("fwd", "rev"), eps=scale * 1e-3)
    check_grads(rj.rotvec_to_matrix, (v,), 1, modes=("fwd", "rev"), eps=scale * 1e-3)
    q = np.asarray(rj.rotvec_to_quaternion(v))
    check_grads(rj.quaternion_to_rotvec, (q,), 1, modes=("fwd", "rev"), eps=scale * 1e-3)


def test_quaternion_to_matrix_grads_at_identity_and_180():
    for q in [np.array([0.0, 0, 0, 1]), np.array([1.0, 0, 0, 0]), np.array([0.0, 0.6, 0.8, 0])]:
        check_grads(rj.quaternion_to_matrix, (q,), 2, modes=("fwd", "rev"))


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
        _, jvp = jax.jvp(f, (jnp.asarray(R),), (jnp.asarray(R @ np.asarray(hat(omega))),))
        q = np.asarray(f(R))
        # exact tangent identity dq = q (x) (omega/2, 0) for a unit q
        expected = np.asarray(rj.quaternion_multiply(q, np.array([*(omega / 2), 0.0])))
        assert_close(jvp, expected, atol=1e-9, err_msg=f"omega={omega}")
        assert_close(jvp, _aligned_fd(f, R, omega), atol=1e-7, err_msg=f"omega={omega}")
        g = jax.grad(lambda m: jnp.dot(f(m), jnp.asarray(expected)))(jnp.asarray(R))
        assert np.all(np.isfinite(g)) and np.abs(g).max() > 0


@pytest.mark.parametrize("name", sorted(SPECIAL_MATRICES))
def test_matrix_to_rotvec_tangent_derivative(name):
    """exp(log(R)) = R on SO(3), so the derivative of the composition along R omega^ returns
    R omega^; at the identity d log = omega exactly."""
    R = SPECIAL_MATRICES[name]
    for omega in OMEGAS:
        dR = R @ np.asarray(hat(omega))
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
    R = np.asarray(rj.euler_to_matrix(angles, seq))
    for s in (1.0, -1.0):
        moved = angles + np.array([-s * 0.3, 0.0, 0.3])
        if np.abs(np.asarray(rj.euler_to_matrix(moved, seq)) - R).max() < 1e-12:
            return s
    raise AssertionError("not at gimbal lock")


@pytest.mark.parametrize("mid_index", [0, 1], ids=["lock_a", "lock_b"])
@pytest.mark.parametrize("seq", SEQS)
def test_euler_gradient_rule_at_exact_lock(seq, mid_index):
    """Exactly at lock: the third angle is 0; its derivative and the middle angle's are 0; the
    first angle's derivative is that of the defined combination a0 + s a2 (finite
    differences of that smooth function through nearby non-locked points)."""
    q = _exact_lock_quaternion(seq, mid_index)
    ang = np.asarray(rj.quaternion_to_euler(q, seq))
    assert ang[2] == 0.0
    assert_close(rj.euler_to_matrix(ang, seq), rj.quaternion_to_matrix(q), atol=1e-15)
    s = _lock_combination_sign(seq, ang)
    J = np.asarray(jax.jacrev(lambda x: rj.quaternion_to_euler(x, seq))(jnp.asarray(q)))
    assert np.all(np.isfinite(J))
    np.testing.assert_array_equal(J[1:], 0.0)
    assert np.abs(J[0]).max() > 0.1  # not a silent zero

    def combo(x):
        a = np.asarray(rj.quaternion_to_euler(x, seq))
        return a[0] + s * a[2]

    h = 1e-7
    fd = np.array([angle_diff(combo(q + h * e), combo(q - h * e)) / (2 * h) for e in np.eye(4)])
    assert_close(J[0], fd, atol=1e-6)
    Jf = np.asarray(jax.jacfwd(lambda x: rj.quaternion_to_euler(x, seq))(jnp.asarray(q)))
    assert_close(Jf, J, atol=1e-15)


@pytest.mark.parametrize("seq", SEQS)
def test_euler_gradients_near_lock_are_true_derivatives(seq):
    """1e-9 from lock the angles are differentiable; the derivative of the round trip
    R -> angles -> R is the identity on tangent vectors (values ~1e9 cancel correctly)."""
    mid = 1e-9 if is_proper(seq) else np.pi / 2 - 1e-9
    R = np.asarray(rj.euler_to_matrix(np.array([0.4, mid, -1.3]), seq))
    for omega in OMEGAS:
        dR = R @ np.asarray(hat(omega))
        _, jvp = jax.jvp(
            lambda m: rj.euler_to_matrix(rj.matrix_to_euler(m, seq), seq),
            (jnp.asarray(R),),
            (jnp.asarray(dR),),
        )
        assert_close(jvp, dR, atol=1e-6 * max(1.0, 1.0))
    g = jax.grad(lambda m: jnp.sum(rj.matrix_to_euler(m, seq)))(jnp.asarray(R))
    assert np.all(np.isfinite(g))


@pytest.mark.parametrize("seq", ["XYZ", "ZXZ", "zyx", "yzy"])
def test_euler_to_matrix_grads_at_lock(seq):
    """The forward map is smooth everywhere, gimbal lock included."""
    for mid in (0.0, np.pi) if is_proper(seq) else (np.pi / 2, -np.pi / 2):
        a = np.array([0.3, mid, 0.5])
        check_grads(lambda x: rj.euler_to_matrix(x, seq), (a,), 1, modes=("fwd", "rev"))
        check_grads(lambda x: rj.euler_to_quaternion(x, seq), (a,), 1, modes=("fwd", "rev"))


def _power_step(R, q0):
    """The "markley" formula after its first step, written plainly (JAX differentiates it
    itself): one product with K, normalised to w >= 0."""
    from rotjax._matrix import _k4_columns

    cols, _ = _k4_columns(R)
    v = jnp.stack([sum(cols[i][c] * q0[..., i] for i in range(4)) for c in range(4)], axis=-1)
    v = v / jnp.linalg.norm(v, axis=-1, keepdims=True)
    return jnp.where(v[..., 3:] < 0, -v, v)


def _markley_by_autodiff(R):
    """The power step on the Shepperd quaternion with its own tangent rule: what the custom
    jvp of "markley" computes."""
    from rotjax._matrix import _shepperd

    return _power_step(R, _shepperd(R))


def _markley_plain(R):
    """The power step on the Shepperd column divided by its norm, no derivative rule anywhere:
    JAX's derivative of it is the true derivative of the quaternion that "markley" returns."""
    from rotjax._matrix import _selected_column

    c, sq = _selected_column(R)
    return _power_step(R, jnp.stack(c, axis=-1) / jnp.sqrt(sq)[..., None])


def _noisy_rotations(sigma, n, seed):
    rng = np.random.default_rng(seed)
    R = np.asarray(rj.quaternion_to_matrix(rng.normal(size=(n, 4))))
    return jnp.asarray(R + sigma * rng.normal(size=R.shape)), jnp.asarray(rng.normal(size=R.shape))


def _median_deviation(f, R, dR):
    """Median over rotations of |df - df_true| / |df_true| along the ambient directions dR."""
    _, jv = jax.vmap(lambda m, d: jax.jvp(f, (m,), (d,)))(R, dR)
    _, ref = jax.vmap(lambda m, d: jax.jvp(_markley_plain, (m,), (d,)))(R, dR)
    return float(np.median(np.linalg.norm(jv - ref, axis=-1) / np.linalg.norm(ref, axis=-1)))


def test_markley_derivative_is_the_true_one_on_so3_in_every_direction():
    """At a rotation matrix K = 4 q q^T annihilates the Shepperd step's error in the power
    step's derivative, so the rule (Shepperd's tangent rule inside) equals the true derivative
    of the returned quaternion along every 3x3 direction, off SO(3) too."""
    R, dR = _noisy_rotations(0.0, 64, seed=5)
    special = np.stack(list(SPECIAL_MATRICES.values()))
    R = jnp.concatenate([R, jnp.asarray(special)])
    dR = jnp.concatenate([dR, jnp.asarray(np.random.default_rng(6).normal(size=special.shape))])
    f = lambda m: rj.matrix_to_quaternion(m, method="markley")  # noqa: E731
    _, jv = jax.jvp(f, (R,), (dR,))
    _, ref = jax.jvp(_markley_plain, (R,), (dR,))
    assert_close(jv, ref, atol=1e-12)


@pytest.mark.parametrize("sigma", [1e-6, 1e-3])
def test_markley_derivative_off_so3_is_within_sigma_of_the_true_one(sigma):
    """Off SO(3) the rule is first-order accurate: its median relative deviation from the true
    derivative of the returned quaternion is about 0.45 sigma (measured), against about 2 sigma
    for Shepperd's rule, the cheaper alternative."""
    R, dR = _noisy_rotations(sigma, 400, seed=7)
    markley = _median_deviation(lambda m: rj.matrix_to_quaternion(m, method="markley"), R, dR)
    shepperd = _median_deviation(rj.matrix_to_quaternion, R, dR)
    assert markley <= 0.6 * sigma, markley / sigma
    assert shepperd >= 1.5 * sigma, shepperd / sigma


@pytest.mark.parametrize("sigma", [0.0, 1e-6, 1e-2, 0.2])
def test_markley_hand_written_derivative_equals_autodiff_of_its_formula(sigma):
    """Off SO(3) as well, the custom jvp (and its transpose, reverse mode) equals JAX's
    derivative of the formula with the Shepperd step's tangent rule inside (not the true
    derivative off SO(3): see the test above)."""
    rng = np.random.default_rng(11)
    base = np.stack(
        [SPECIAL_MATRICES[k] for k in sorted(SPECIAL_MATRICES)]
        + [np.asarray(rj.quaternion_to_matrix(q)) for q in rng.normal(size=(8, 4))]
    )
    R = jnp.asarray(base + sigma * rng.normal(size=base.shape))
    dR = jnp.asarray(rng.normal(size=base.shape))
    f = lambda m: rj.matrix_to_quaternion(m, method="markley")  # noqa: E731
    q, jv = jax.jvp(f, (R,), (dR,))
    q_ref, jv_ref = jax.jvp(_markley_by_autodiff, (R,), (dR,))
    assert_close(q, q_ref, atol=1e-15)
    assert_close(jv, jv_ref, atol=1e-12 * (1 + float(jnp.abs(jv_ref).max())))
    w = jnp.asarray(rng.normal(size=q.shape))
    g = jax.grad(lambda m: jnp.sum(w * f(m)))(R)
    g_ref = jax.grad(lambda m: jnp.sum(w * _markley_by_autodiff(m)))(R)
    assert_close(g, g_ref, atol=1e-12 * (1 + float(jnp.abs(g_ref).max())))


@pytest.mark.parametrize("method", ["shepperd", "markley", "optimal"])
def test_matrix_to_quaternion_float32_derivatives_stay_float32(method):
    """The hand-written derivatives keep the input dtype, in both modes (a float64 constant
    inside a rule would otherwise promote the tangent and JAX would reject it)."""
    R = jnp.asarray(rj.quaternion_to_matrix(np.array([0.3, -0.5, 0.2, 0.78])), dtype=jnp.float32)
    f = lambda m: rj.matrix_to_quaternion(m, method=method)  # noqa: E731
    _, jv = jax.jvp(f, (R,), (jnp.ones_like(R),))
    g = jax.grad(lambda m: jnp.sum(f(m)))(R)
    assert jv.dtype == jnp.float32 and g.dtype == jnp.float32
    assert np.all(np.isfinite(np.asarray(g)))
    g64 = jax.grad(lambda m: jnp.sum(f(m)))(R.astype(jnp.float64))
    assert_close(g, g64, atol=1e-5)


def _euler_test_quaternions(seq):
    """Random quaternions of norms from 1e-20 to 1e20, points 1e-9 from both locks, both exact
    locks, and 180-degree rotations about each axis."""
    rng = np.random.default_rng(17)
    qs = list(rng.normal(size=(12, 4)) * np.exp(rng.uniform(-46, 46, size=(12, 1))))
    for mid in (1e-9, np.pi - 1e-9) if is_proper(seq) else (np.pi / 2 - 1e-9, 1e-9 - np.pi / 2):
        qs.append(np.asarray(rj.euler_to_quaternion(np.array([0.4, mid, -1.3]), seq)))
    qs += [_exact_lock_quaternion(seq, i) for i in (0, 1)]
    qs += list(np.hstack([np.eye(3), np.zeros((3, 1))]))
    return jnp.asarray(np.array(qs))


def _assert_rule_equals_autodiff(f, seq, x, dx, rng):
    """The custom jvp of ``f(x, seq)`` (a jax.custom_jvp) and its transpose equal JAX's own
    derivatives of the undecorated code ``f.fun``, row by row, relative to each row's size."""
    g = lambda v: f(v, seq)  # noqa: E731
    g_ref = lambda v: f.fun(v, seq)  # noqa: E731
    out, jv = jax.jvp(g, (x,), (dx,))
    out_ref, jv_ref = jax.jvp(g_ref, (x,), (dx,))
    np.testing.assert_array_equal(out, out_ref)
    scale = 1 + np.abs(np.asarray(jv_ref)).max(axis=-1, keepdims=True)
    assert_close(jv / scale, jv_ref / scale, atol=1e-14)
    ct = jnp.asarray(rng.normal(size=out.shape))
    gr = jax.grad(lambda v: jnp.sum(ct * g(v)))(x)
    gr_ref = jax.grad(lambda v: jnp.sum(ct * g_ref(v)))(x)
    assert np.all(np.isfinite(np.asarray(gr)))
    row_axes = tuple(range(out.ndim - 1, x.ndim))
    scale = np.abs(np.asarray(gr_ref)).max(axis=row_axes, keepdims=True)
    assert_close(gr / scale, gr_ref / scale, atol=1e-14)


@pytest.mark.parametrize("seq", SEQS)
def test_euler_hand_written_derivative_equals_autodiff_of_its_formula(seq):
    """quaternion_to_euler's custom jvp (and its transpose) equals JAX's own derivative of the
    forward code, everywhere: generic points of any norm, near and exactly at lock (where the
    forward code's selects define the gradient rule), 180 degrees; second derivatives too."""
    from rotjax._euler import _quat_to_euler

    q = _euler_test_quaternions(seq)
    rng = np.random.default_rng(5)
    dq = jnp.asarray(rng.normal(size=q.shape)) * jnp.linalg.norm(q, axis=-1, keepdims=True)
    _assert_rule_equals_autodiff(_quat_to_euler, seq, q, dq, rng)
    f, f_ref = _quat_to_euler, _quat_to_euler.fun
    for x in (q[0] / jnp.linalg.norm(q[0]), q[-4]):  # second derivatives: generic, exact lock
        h = jax.hessian(lambda x: f(x, seq))(x)
        h_ref = jax.hessian(lambda x: f_ref(x, seq))(x)
        assert_close(h, h_ref, atol=1e-13 * (1 + float(jnp.abs(h_ref).max())))


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
    _, jv = jax.jvp(f, (x32,), (jnp.ones_like(x32),))
    g = jax.grad(lambda v: jnp.sum(f(v)))(x32)
    assert jv.dtype == jnp.float32 and g.dtype == jnp.float32
    assert_close(g, jax.grad(lambda v: jnp.sum(f(v)))(jnp.asarray(x)), atol=1e-5)


@pytest.mark.parametrize("seq", SEQS)
def test_matrix_to_euler_derivative_equals_chain_rule(seq):
    """matrix_to_euler's custom jvp (taken with respect to the rotation tangent directly)
    equals JAX's chain rule through the Shepperd quaternion and quaternion_to_euler's own
    rule, in both modes, on rotation matrices (generic, near and at lock, 180 degrees) and
    off SO(3) (noise sigma 1e-3, where both use the tangent-space projection)."""
    from rotjax._euler import _matrix_to_euler

    q = _euler_test_quaternions(seq)
    R = np.asarray(rj.quaternion_to_matrix(q))
    rng = np.random.default_rng(8)
    R = jnp.asarray(np.concatenate([R, R[:6] + 1e-3 * rng.normal(size=R[:6].shape)]))
    _assert_rule_equals_autodiff(
        _matrix_to_euler, seq, R, jnp.asarray(rng.normal(size=R.shape)), rng
    )
