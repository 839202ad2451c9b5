"""Kinematics: Euler rate maps, quaternion/matrix derivatives, integration, Euler unwrapping.

Every rate map is checked against autodiff of the core conversions (``jax.jvp`` of
``euler_to_matrix``), which share no code with the closed forms in ``_kinematics``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import (
    BATCH_SHAPES,
    DIGIT_SEQS,
    SEQS,
    assert_close,
    assert_same_rotation,
    fd_jacobian,
    is_proper,
    lock_middles,
    sweep,
)
from scipy.spatial.transform import Rotation

import rotjax as rj

FRAMES = ["body", "world"]
ALL_SEQS = SEQS + DIGIT_SEQS
METHODS = ["exponential", "euler", "rk4"]


def _rng(seed=0):
    return np.random.default_rng(seed)


def _omega_from_matrix_motion(R, R_dot, frame):
    """Angular velocity from ``R`` and ``dR/dt`` in plain numpy (independent of rotjax)."""
    R, R_dot = np.asarray(R), np.asarray(R_dot)
    Rt = np.swapaxes(R, -1, -2)
    W = Rt @ R_dot if frame == "body" else R_dot @ Rt
    return 0.5 * np.stack(
        [W[..., 2, 1] - W[..., 1, 2], W[..., 0, 2] - W[..., 2, 0], W[..., 1, 0] - W[..., 0, 1]],
        axis=-1,
    )


def _generic_angles(seq, n, seed=0, margin=0.2):
    """Angles of any size whose middle angle stays ``margin`` (in |cos| or |sin|) from lock."""
    a = _rng(seed).uniform(-4.0, 4.0, size=(n, 3))
    h = np.abs(np.sin(a[:, 1])) if is_proper(seq) else np.abs(np.cos(a[:, 1]))
    a[h < margin, 1] += 0.7  # moves |cos| or |sin| well away from 0 for these samples
    return a


def _lock_angles(seq, seed=0):
    """Angles exactly at both lock values of the middle angle (plus a 2 pi shifted copy)."""
    lo, hi = lock_middles(seq)
    a = _rng(seed).uniform(-np.pi, np.pi, size=(3, 3))
    a[:, 1] = [lo, hi, lo + 2 * np.pi]
    return a


# --- Euler rate maps: one report per sequence ---------------------------------------------------

_H = 1e-6  # central-difference step (float64)
_DAMPING = 0.1
_REPORTS: dict = {}


def _seq_report(seq):
    """Everything the per-sequence rate-map tests check, for both frames, as numpy arrays.

    It runs op by op (``jax.disable_jit``): the compiled primitive kernels are then shared by all
    24 sequences, whereas compiling one graph per sequence and check costs about ten times more.
    The compiled path is compared with this one in ``test_jit_matches_eager``.
    """
    if seq not in _REPORTS:
        with jax.disable_jit():
            _REPORTS[seq] = _compute_report(seq)
    return _REPORTS[seq]


def _compute_report(seq):
    rng = _rng(1)
    inp = {
        "a": rng.uniform(-4.0, 4.0, size=(32, 3)),  # any angles, beyond the ranges too
        "rates": rng.normal(size=(32, 3)),
        "w": rng.normal(size=(32, 3)),
        "a_gen": _generic_angles(seq, 32, seed=3, margin=0.3),
        "a_lock": _lock_angles(seq, seed=8),
        "w_lock": rng.normal(size=(3, 3)),
        "tangents": rng.normal(size=(3, 7)),
    }
    a, rates, w, a_gen = (jnp.asarray(inp[k]) for k in ("a", "rates", "w", "a_gen"))
    out = {"in": inp}
    R, R_dot = jax.jvp(lambda x: rj.euler_to_matrix(x, seq), (a,), (rates,))
    out["R"] = np.asarray(R)
    out["singularity"] = np.asarray(rj.euler_singularity(a, seq))
    out["singularity_lock"] = np.asarray(rj.euler_singularity(inp["a_lock"], seq))
    for frame in FRAMES:
        r = {"autodiff": _omega_from_matrix_motion(R, R_dot, frame)}
        r["E"] = np.asarray(rj.euler_rate_matrix(a, seq, frame=frame))
        r["omega"] = np.asarray(rj.euler_rates_to_angular_velocity(a, rates, seq, frame=frame))
        omega_gen = rj.euler_rates_to_angular_velocity(a_gen, rates, seq, frame=frame)
        r["rates_back"] = np.asarray(
            rj.angular_velocity_to_euler_rates(a_gen, omega_gen, seq, frame=frame)
        )
        rates_w = rj.angular_velocity_to_euler_rates(a_gen, w, seq, frame=frame)
        r["omega_back"] = np.asarray(
            rj.euler_rates_to_angular_velocity(a_gen, rates_w, seq, frame=frame)
        )
        r["damped_gen"] = [
            np.asarray(rj.angular_velocity_to_euler_rates(a_gen, w, seq, frame, damping=d))
            for d in (0.0, 1e-3, 2e-3)
        ]

        def f(x, frame=frame):
            return rj.angular_velocity_to_euler_rates(
                x[..., :3], x[..., 3:6], seq, frame=frame, damping=x[..., 6]
            )

        x = jnp.asarray(
            np.concatenate([inp["a_lock"], inp["w_lock"], np.full((3, 1), _DAMPING)], axis=-1)
        )
        t = jnp.asarray(inp["tangents"])
        r["E_lock"] = np.asarray(rj.euler_rate_matrix(inp["a_lock"], seq, frame=frame))
        # Directional derivatives at lock, forward and reverse mode, against central differences.
        y, jv = jax.jvp(f, (x,), (t,))
        r["damped_lock"], r["jvp"] = np.asarray(y), np.asarray(jv)
        r["jvp_fd"] = np.asarray((f(x + _H * t) - f(x - _H * t)) / (2 * _H))
        cot = t[:, :3]
        r["vjp"] = np.asarray(jax.vjp(f, x)[1](cot)[0])
        fd_rows = [
            np.asarray((f(x + _H * e[None]) - f(x - _H * e[None])) * cot) for e in jnp.eye(7)
        ]
        r["vjp_fd"] = np.stack([row.sum(-1) / (2 * _H) for row in fd_rows], axis=-1)
        out[frame] = r
    return out


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("seq", SEQS)
def test_rate_map_matches_autodiff(seq, frame):
    """omega from jax.jvp of R(angles(t)) equals E @ rates, for angles of any size."""
    rep = _seq_report(seq)
    r = rep[frame]
    assert_close(r["omega"], r["autodiff"], atol=1e-13)
    assert_close(np.einsum("nij,nj->ni", r["E"], rep["in"]["rates"]), r["autodiff"], atol=1e-13)


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("seq", SEQS)
def test_round_trips_away_from_lock(seq, frame):
    rep = _seq_report(seq)
    r = rep[frame]
    assert_close(r["rates_back"], rep["in"]["rates"], atol=1e-12)
    assert_close(r["omega_back"], rep["in"]["w"], atol=1e-12)


@pytest.mark.parametrize("seq", SEQS)
def test_frames_are_related_by_R(seq):
    """omega_world = R @ omega_body, so E_world = R @ E_body."""
    rep = _seq_report(seq)
    assert_close(rep["world"]["E"], rep["R"] @ rep["body"]["E"], atol=1e-14)


@pytest.mark.parametrize("seq", SEQS)
def test_euler_singularity_is_abs_det(seq):
    rep = _seq_report(seq)
    for frame in FRAMES:
        assert_close(rep["singularity"], np.abs(np.linalg.det(rep[frame]["E"])), atol=1e-14)
    assert_close(rep["singularity_lock"], 0.0, atol=1e-15)
    assert np.all(rep["singularity"] > 0)


def _damped_reference(E, omega, d):
    Et = np.swapaxes(E, -1, -2)
    return np.linalg.solve(Et @ E + d * d * np.eye(3), (Et @ omega[..., None]))[..., 0]


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("seq", SEQS)
def test_damped_inverse_exactly_at_lock(seq, frame):
    """Finite, equal to (E^T E + d^2 I)^-1 E^T omega, and with correct (finite) gradients in the
    angles, omega and the damping, exactly at both lock values of the middle angle."""
    rep = _seq_report(seq)
    r = rep[frame]
    ref = _damped_reference(r["E_lock"], rep["in"]["w_lock"], _DAMPING)
    assert_close(r["damped_lock"], ref, atol=1e-12)
    assert_close(r["jvp"], r["jvp_fd"], atol=1e-6)
    assert_close(r["vjp"], r["vjp_fd"], atol=1e-6)


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("seq", SEQS)
def test_damping_changes_answer_by_order_d2(seq, frame):
    exact, e1, e2 = _seq_report(seq)[frame]["damped_gen"]
    n1 = np.abs(e1 - exact).max(axis=-1)
    n2 = np.abs(e2 - exact).max(axis=-1)
    assert np.all(n1 > 0)
    np.testing.assert_allclose(n2 / n1, 4.0, rtol=1e-3)  # doubling d quadruples the change
    assert np.all(n1 < 100 * 1e-3**2 * np.abs(exact).max(axis=-1))


@pytest.mark.parametrize("seq", ["ZXZ", "zxz", "XYX", "yzy"])
def test_exact_inverse_at_lock_is_non_finite(seq):
    """Documented behaviour: with damping=0 the rates do not exist at lock (proper sequences at
    a middle angle of exactly 0, where sin is exactly 0)."""
    out = rj.angular_velocity_to_euler_rates(jnp.asarray([0.3, 0.0, -0.2]), jnp.ones(3), seq)
    assert not np.all(np.isfinite(np.asarray(out)))


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("digits", DIGIT_SEQS)
def test_digit_forms_equal_letter_forms(digits, frame):
    letters = "".join("XYZ"[int(c) - 1] for c in digits)
    rng = _rng(2)
    a, w = rng.uniform(-3, 3, size=(8, 3)), rng.normal(size=(8, 3))

    def all_maps(s):
        return (
            rj.euler_rate_matrix(a, s, frame=frame),
            rj.euler_rates_to_angular_velocity(a, w, s, frame=frame),
            rj.angular_velocity_to_euler_rates(a, w, s, frame=frame, damping=0.1),
            rj.angular_velocity_to_euler_rates(a, w, s, frame=frame),
            rj.euler_singularity(a, s),
        )

    with jax.disable_jit():
        for x, y in zip(all_maps(digits), all_maps(letters), strict=True):
            assert_close(x, y, atol=0)


@pytest.mark.parametrize("seq", ["ZXZ", "xyz", "YZX", "zyz"])
def test_jit_matches_eager(seq):
    a = jnp.asarray(_rng(3).uniform(-3, 3, size=(16, 3)))
    w = jnp.asarray(_rng(4).normal(size=(16, 3)))

    def fn(a, w):
        return [
            rj.euler_rate_matrix(a, seq, frame="world"),
            rj.angular_velocity_to_euler_rates(a, w, seq, frame="body", damping=0.05),
            rj.angular_velocity_to_euler_rates(a, w, seq, frame="world"),
        ]

    with jax.disable_jit():
        eager = fn(a, w)
    for x, y in zip(jax.jit(fn)(a, w), eager, strict=True):
        assert_close(x, y, atol=1e-13)


# --- Nikravesh, Appendix A (seed 002) --------------------------------------------------------


def _nikravesh(a):
    """Eqs. A.3/A.4 (z-x-z) and A.7/A.8 (x-y-z, Bryant) in body axes, as correct closed forms.

    A.3, A.4 and A.8 are correct as printed. A.7 is not: its (1, 1) entry reads
    ``cos(phi1) cos(phi3)`` where the derivation (the first axis carried into body axes,
    ``R_z(phi3)^T R_y(phi2)^T e_x``) gives ``cos(phi2) cos(phi3)``; with the printed entry A.8
    is not its inverse. ``printed_a7`` keeps the printed entry to show the test can tell.
    """
    p, t, s = a  # psi, theta, sigma for z-x-z; phi1, phi2, phi3 for x-y-z
    sin, cos = np.sin, np.cos
    a3 = np.array([[sin(t) * sin(s), cos(s), 0], [sin(t) * cos(s), -sin(s), 0], [cos(t), 0, 1]])
    a4 = np.array(
        [
            [sin(s), cos(s), 0],
            [cos(s) * sin(t), -sin(s) * sin(t), 0],
            [-sin(s) * cos(t), -cos(s) * cos(t), sin(t)],
        ]
    ) / sin(t)
    a7 = np.array([[cos(t) * cos(s), sin(s), 0], [-cos(t) * sin(s), cos(s), 0], [sin(t), 0, 1]])
    printed_a7 = a7.copy()
    printed_a7[0, 0] = cos(p) * cos(s)
    a8 = np.array(
        [
            [cos(s), -sin(s), 0],
            [sin(s) * cos(t), cos(s) * cos(t), 0],
            [-cos(s) * sin(t), sin(s) * sin(t), cos(t)],
        ]
    ) / cos(t)
    return a3, a4, a7, printed_a7, a8


@pytest.mark.parametrize("seed", range(4))
def test_nikravesh_seed_matrices(seed):
    a = _rng(seed).uniform(-3, 3, size=3)
    a3, a4, a7, printed_a7, a8 = _nikravesh(a)
    for seq in ("ZXZ", "313"):
        assert_close(rj.euler_rate_matrix(a, seq), a3, atol=1e-15)
        w = _rng(seed + 10).normal(size=3)
        assert_close(rj.angular_velocity_to_euler_rates(a, w, seq), a4 @ w, atol=1e-13)
    for seq in ("XYZ", "123"):
        E = np.asarray(rj.euler_rate_matrix(a, seq))
        assert_close(E, a7, atol=1e-15)
        assert np.abs(E - printed_a7).max() > 1e-3  # the printed A.7 is wrong
        w = _rng(seed + 20).normal(size=3)
        assert_close(rj.angular_velocity_to_euler_rates(a, w, seq), a8 @ w, atol=1e-13)
    assert_close(a4 @ a3, np.eye(3), atol=1e-12)
    assert_close(a8 @ a7, np.eye(3), atol=1e-12)


# --- damping inside compiled code ------------------------------------------------------------


def test_damping_traced_inside_jit_switch():
    """Switch damping on from euler_singularity inside a compiled function, near and at lock."""
    seq = "XYZ"

    @jax.jit
    def rates(a, w):
        d = jnp.where(rj.euler_singularity(a, seq) < 1e-2, 0.05, 0.0)
        return rj.angular_velocity_to_euler_rates(a, w, seq, damping=d)

    a = jnp.asarray([[0.2, np.pi / 2, 0.4], [0.2, 0.3, 0.4]])
    w = jnp.asarray([[0.3, -1.0, 2.0], [0.3, -1.0, 2.0]])
    out = rates(a, w)
    assert_close(out[1], rj.angular_velocity_to_euler_rates(a[1], w[1], seq), atol=1e-15)
    g = jax.grad(lambda x: rates(x, w).sum())(a)
    assert np.all(np.isfinite(np.asarray(g)))
    assert np.abs(np.asarray(out[0])).max() < 100


# --- quaternion and matrix derivatives ---------------------------------------------------------


def _quat_path(q0, omega, frame, t):
    """q(t) for constant omega, built from core conversions: q0 * exp(omega t) or exp * q0."""
    omega, t = jnp.asarray(omega), jnp.asarray(t)
    rank = max(omega.ndim, t.ndim)  # explicit rank promotion
    omega = omega.reshape((1,) * (rank - omega.ndim) + omega.shape)
    t = t.reshape((1,) * (rank - t.ndim) + t.shape)
    dq = rj.rotvec_to_quaternion(omega * t)
    return rj.quaternion_multiply(q0, dq) if frame == "body" else rj.quaternion_multiply(dq, q0)


@pytest.mark.parametrize("frame", FRAMES)
def test_quaternion_derivative(frame):
    rng = _rng(12)
    q = jnp.asarray(rng.normal(size=(16, 4)))  # deliberately not unit
    w = jnp.asarray(rng.normal(size=(16, 3)))
    qd = rj.quaternion_derivative(q, w, frame=frame)
    assert_close(np.sum(np.asarray(qd) * np.asarray(q), axis=-1), 0.0, atol=1e-14)
    assert_close(rj.quaternion_derivative_to_angular_velocity(q, qd, frame=frame), w, atol=1e-13)
    # A radial component (norm change) of q_dot does not change the angular velocity.
    qd_radial = qd + 0.37 * q
    assert_close(
        rj.quaternion_derivative_to_angular_velocity(q, qd_radial, frame=frame), w, atol=1e-13
    )
    # Finite differences of q(t) = q0 * exp(omega t) (body) or exp(omega t) * q0 (world).
    h = 1e-6
    fd = (_quat_path(q, w, frame, h) - _quat_path(q, w, frame, -h)) / (2 * h)
    assert_close(qd, fd, atol=1e-8)
    # Matches the matrix derivative: d/dt R(q(t)) = R hat(omega) (body) or hat(omega) R.
    R, R_dot = jax.jvp(rj.quaternion_to_matrix, (q,), (qd,))
    assert_close(rj.angular_velocity_to_matrix_derivative(R, w, frame=frame), R_dot, atol=1e-13)
    assert_close(rj.matrix_derivative_to_angular_velocity(R, R_dot, frame=frame), w, atol=1e-13)


@pytest.mark.parametrize("frame", FRAMES)
def test_quaternion_derivative_scalar_first(frame):
    rng = _rng(13)
    q = rng.normal(size=(5, 4))
    w = rng.normal(size=(5, 3))
    qd = np.asarray(rj.quaternion_derivative(q, w, frame=frame))
    qf = np.roll(q, 1, axis=-1)
    qdf = rj.quaternion_derivative(qf, w, frame=frame, scalar_first=True)
    assert_close(qdf, np.roll(qd, 1, axis=-1), atol=1e-15)
    back = rj.quaternion_derivative_to_angular_velocity(qf, qdf, frame=frame, scalar_first=True)
    assert_close(back, w, atol=1e-13)


@pytest.mark.parametrize("frame", FRAMES)
def test_matrix_derivative_of_euler_motion(frame):
    a = jnp.asarray(_rng(14).uniform(-3, 3, size=(8, 3)))
    rates = jnp.asarray(_rng(15).normal(size=(8, 3)))
    R, R_dot = jax.jvp(lambda x: rj.euler_to_matrix(x, "zyx"), (a,), (rates,))
    w = rj.matrix_derivative_to_angular_velocity(R, R_dot, frame=frame)
    assert_close(w, _omega_from_matrix_motion(R, R_dot, frame), atol=1e-14)
    assert_close(rj.angular_velocity_to_matrix_derivative(R, w, frame=frame), R_dot, atol=1e-13)


# --- integration ---------------------------------------------------------------------------------


@jax.jit
def _quat_path_jit(q0, omega, t):
    return _quat_path(q0, omega, "body", t), _quat_path(q0, omega, "world", t)


@jax.jit(static_argnames=("frame", "method"))
def _propagate(q0, omegas, dt, frame, method):
    def step(q, w):
        q = rj.integrate_angular_velocity(q, w, dt, frame=frame, method=method)
        return q, q

    return jax.lax.scan(step, q0, omegas)


@jax.jit(static_argnames=("frame", "method"))
def _propagate_constant(q0, omega, n, frame, method):
    """``n`` steps of length ``1 / n`` (``n`` traced: one compilation for every ``n``)."""
    dt = 1.0 / n

    def body(_, q):
        return rj.integrate_angular_velocity(q, omega, dt, frame=frame, method=method)

    return jax.lax.fori_loop(0, n, body, q0)


@pytest.mark.parametrize("frame", FRAMES)
def test_exponential_exact_for_constant_omega(frame):
    q0 = jnp.asarray(rj.quaternion_normalize(jnp.asarray([0.3, -0.2, 0.5, 0.8])))
    w = jnp.asarray([1.3, -2.1, 0.4])
    n, dt = 50, 0.07
    q_end, _ = _propagate(q0, jnp.broadcast_to(w, (n, 3)), dt, frame, "exponential")
    assert_same_rotation(q_end, _quat_path(q0, w, frame, n * dt), atol=1e-13)


@pytest.mark.parametrize("frame", FRAMES)
def test_scan_over_gyro_log(frame):
    """A time-varying gyro log: the scan equals the product of the per-sample exponentials."""
    ts = np.arange(64) * 0.01
    omegas = np.stack([np.sin(3 * ts), np.cos(2 * ts), 0.5 + ts], axis=-1)
    q0 = jnp.asarray([0.0, 0.0, 0.0, 1.0])
    q_end, traj = _propagate(q0, jnp.asarray(omegas), 0.01, frame, "exponential")
    # Reference: the product of exact per-sample rotations, in numpy (Rodrigues).
    R = np.eye(3)
    for w in omegas:
        th = np.linalg.norm(w) * 0.01
        n = w / np.linalg.norm(w)
        N = np.array([[0, -n[2], n[1]], [n[2], 0, -n[0]], [-n[1], n[0], 0]])
        K = np.eye(3) + np.sin(th) * N + (1 - np.cos(th)) * N @ N
        R = R @ K if frame == "body" else K @ R
    assert_close(rj.quaternion_to_matrix(q_end), R, atol=1e-13)
    assert traj.shape == (64, 4)
    assert_close(np.linalg.norm(traj, axis=-1), 1.0, atol=1e-14)


def _global_error(method, n, frame):
    q0 = jnp.asarray(rj.quaternion_normalize(jnp.asarray([0.1, 0.2, 0.3, 0.9])))
    w = jnp.asarray([1.0, -2.0, 0.7])
    q_end = _propagate_constant(q0, w, n, frame, method)
    return float(rj.angle_between(q_end, _quat_path(q0, w, frame, 1.0)))


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize(("method", "order"), [("euler", 2), ("rk4", 4)])
def test_integration_order_by_halving_dt(method, order, frame):
    """Global error over unit time shrinks by 2**order when dt halves.

    The renormalised Euler step is first order as an ODE step, but with omega held over the step
    it turns about the exact axis by 2 atan(|omega| dt / 2) = |omega| dt - O(dt^3): its attitude
    error is second order (the first-order norm drift is removed by the normalisation).
    """
    errs = np.array([_global_error(method, n, frame) for n in (16, 32, 64)])
    ratios = errs[:-1] / errs[1:]
    np.testing.assert_allclose(ratios, 2.0**order, rtol=0.03)


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize(("method", "order"), [("euler", 3), ("rk4", 5)])
def test_one_step_local_error_order(method, order, frame):
    q0 = jnp.asarray(rj.quaternion_normalize(jnp.asarray([0.4, -0.1, 0.2, 0.7])))
    w = jnp.asarray([0.9, 1.7, -1.1])
    dts = jnp.asarray([0.04, 0.02, 0.01])
    got = rj.integrate_angular_velocity(q0, w, dts, frame=frame, method=method)
    want = _quat_path(q0, w, frame, dts[:, None])
    errs = np.asarray(rj.angle_between(got, want))
    np.testing.assert_allclose(errs[:-1] / errs[1:], 2.0**order, rtol=0.03)


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("method", METHODS)
def test_integration_gradient_exact_at_zero_omega(method, frame):
    q0 = jnp.asarray([0.3, -0.4, 0.1, 0.85])  # not unit
    dt = 0.05

    def f(w):
        return rj.integrate_angular_velocity(q0, w, dt, frame=frame, method=method)

    zero = jnp.zeros(3)
    fd = fd_jacobian(f, zero, h=1e-5)
    # Analytic: d q_next / d omega at 0 is dt/2 * q0 * (e_n, 0) (body) or (e_n, 0) * q0 (world),
    # for the unit q0 (the output is normalised).
    qn = np.asarray(q0) / np.linalg.norm(q0)
    x, y, z, w = qn
    left = np.array([[w, -z, y], [z, w, -x], [-y, x, w], [-x, -y, -z]])  # q * (e_n, 0)
    right = np.array([[w, z, -y], [-z, w, x], [y, -x, w], [-x, -y, -z]])  # (e_n, 0) * q
    analytic = 0.5 * dt * (left if frame == "body" else right)
    for jac in jax.jit(lambda x: (jax.jacfwd(f)(x), jax.jacrev(f)(x)))(zero):
        assert_close(jac, analytic, atol=1e-15)
        assert_close(jac, fd, atol=1e-9)
    assert_close(f(zero), qn, atol=1e-15)


def test_integration_gradient_through_scan():
    """Gradient of a loss after a scanned gyro log (with zero samples in it) matches FD."""
    omegas = jnp.asarray(_rng(16).normal(size=(10, 3))).at[::3].set(0.0)
    q0 = jnp.asarray([0.0, 0.0, 0.0, 1.0])
    target = jnp.asarray([0.2, 0.1, -0.3, 0.9])

    @jax.jit
    def loss(w):
        q_end, _ = _propagate(q0, w, 0.1, "body", "exponential")
        return jnp.sum(q_end * target) ** 2

    g = jax.jit(jax.grad(loss))(omegas)
    assert_close(g, fd_jacobian(loss, omegas, h=1e-6), atol=1e-8)


# --- unwrapping -------------------------------------------------------------------------------


def _principal(angles, seq):
    """Principal-range angles of the same rotations, from scipy (an independent oracle)."""
    a = np.asarray(angles, np.float64)
    return Rotation.from_euler(seq, a.reshape(-1, 3)).as_euler(seq).reshape(a.shape)


@pytest.mark.parametrize("seq", SEQS)
def test_second_solution_set(seq):
    """(a0 + pi, pi - a1, a2 + pi) for Tait-Bryan, (a0 + pi, -a1, a2 + pi) for proper; the
    MapleSim seed's (a1 +- pi) and (a1 unchanged) are different rotations."""
    a = _rng(17).uniform(-3, 3, size=(16, 3))
    second = a + np.pi
    second[:, 1] = -a[:, 1] if is_proper(seq) else np.pi - a[:, 1]
    q1 = Rotation.from_euler(seq, a).as_quat()
    assert_same_rotation(Rotation.from_euler(seq, second).as_quat(), q1, atol=1e-14)
    maplesim = a + np.pi
    if is_proper(seq):
        maplesim[:, 1] = a[:, 1]
    q_m = Rotation.from_euler(seq, maplesim).as_quat()
    dist = np.minimum(np.abs(q_m - q1).max(-1), np.abs(q_m + q1).max(-1))
    assert np.all(dist > 1e-3)


def _continuous_trajectory(seq, n=400):
    """Outer angles that wrap several times, a middle angle that runs past its range edges."""
    t = np.linspace(0.0, 1.0, n)
    if is_proper(seq):
        mid = np.pi / 2 + 2.2 * np.sin(2 * np.pi * t)  # crosses 0 and pi
    else:
        mid = 0.2 + 2.0 * np.sin(2 * np.pi * t)  # crosses +pi/2 and -pi/2
    return np.stack([0.3 + 20.0 * t, mid, -0.5 - 23.0 * t + 3 * t * t], axis=-1)


def _two_trajectories(seq):
    """(T, 2, 3): the trajectory and its time reversal shifted to start in the principal range."""
    tr = _continuous_trajectory(seq)
    rev = tr[::-1].copy()
    rev -= rev[0] - _principal(rev[0], seq)  # same motion, first sample principal
    return np.stack([tr, rev], axis=1)


@pytest.mark.parametrize("seq", SEQS)
def test_unwrap_recovers_continuous_angles(seq):
    orig = _two_trajectories(seq)
    principal = _principal(orig, seq)
    assert np.abs(np.diff(principal, axis=0)).max() > np.pi  # the input does jump
    hi = np.pi if is_proper(seq) else np.pi / 2
    assert orig[..., 1].max() > hi and orig[..., 1].min() < hi - np.pi  # both edges crossed
    assert np.all(np.abs(orig[-1, :, [0, 2]] - orig[0, :, [0, 2]]) > 4 * np.pi)  # outer wraps
    assert_close(rj.unwrap_euler(principal, seq), orig, atol=1e-9)


@pytest.mark.parametrize("seq", ["XZY", "yxy"])
def test_unwrap_time_axis(seq):
    orig = _two_trajectories(seq)
    principal = _principal(orig, seq)
    swapped = np.swapaxes(principal, 0, 1)
    assert_close(rj.unwrap_euler(swapped, seq, axis=1), np.swapaxes(orig, 0, 1), atol=1e-9)
    assert_close(rj.unwrap_euler(principal, seq, axis=-3), orig, atol=1e-9)


@pytest.mark.parametrize("seq", ["ZYX", "zxz"])
def test_unwrap_float32_and_same_rotations(seq):
    orig = _continuous_trajectory(seq, n=300)
    principal = _principal(orig, seq).astype(np.float32)
    out = rj.unwrap_euler(principal, seq)
    assert out.dtype == jnp.float32
    assert_close(out, orig, atol=2e-4)
    q_out = Rotation.from_euler(seq, np.asarray(out, np.float64)).as_quat()
    assert_same_rotation(q_out, Rotation.from_euler(seq, principal).as_quat(), atol=1e-5)


def test_unwrap_single_sample_and_empty():
    a = jnp.asarray([[0.1, 0.2, 0.3]])
    assert_close(rj.unwrap_euler(a, "XYZ"), a, atol=0)
    assert rj.unwrap_euler(jnp.zeros((0, 3)), "XYZ").shape == (0, 3)


# --- jit / vmap / broadcasting / dtypes --------------------------------------------------------


def _all_public(a, w, q, R):
    """Every kinematics function on one set of inputs, as a dict of outputs."""
    seq = "ZYX"
    return {
        "E": rj.euler_rate_matrix(a, seq, frame="world"),
        "w": rj.euler_rates_to_angular_velocity(a, w, seq),
        "r": rj.angular_velocity_to_euler_rates(a, w, seq, frame="world"),
        "rd": rj.angular_velocity_to_euler_rates(a, w, seq, damping=0.1),
        "s": rj.euler_singularity(a, seq),
        "qd": rj.quaternion_derivative(q, w, frame="world"),
        "wq": rj.quaternion_derivative_to_angular_velocity(q, rj.quaternion_derivative(q, w)),
        "Rd": rj.angular_velocity_to_matrix_derivative(R, w),
        "wR": rj.matrix_derivative_to_angular_velocity(R, R @ R),
        "q1": rj.integrate_angular_velocity(q, w, 0.1, method="rk4"),
        "q2": rj.integrate_angular_velocity(q, w, 0.1, frame="world"),
        "al": rj.euler_accelerations_to_angular_acceleration(a, w, a, seq, frame="world"),
        "aa": rj.angular_acceleration_to_euler_accelerations(a, w, a, seq, damping=0.1),
        "q3": rj.integrate_angular_velocity(q, w, 0.1, method="euler"),
    }


def _inputs(shape, dtype=np.float64, seed=18):
    rng = _rng(seed)
    a = rng.uniform(-3, 3, size=(*shape, 3)).astype(dtype)
    w = rng.normal(size=(*shape, 3)).astype(dtype)
    q = rng.normal(size=(*shape, 4)).astype(dtype)
    # the matrices of the (normalised) quaternions, by scipy: no program compiled
    R = Rotation.from_quat(q.reshape(-1, 4).astype(np.float64)).as_matrix()
    return a, w, q, R.reshape(*shape, 3, 3).astype(dtype)


@pytest.mark.parametrize("shape", sweep(BATCH_SHAPES, fast=[(3, 1, 2, 1)]), ids=str)
def test_batch_vmap_agree(shape):
    """Batched inputs and vmap over the first axis agree (run op by op; the compiled path is
    checked in test_jit_batched_agrees, single samples in test_broadcasting_between_arguments).
    Op by op on purpose: the primitives compiled here are the ones test_jit_batched_agrees'
    reference runs (same shape), where a compiled program of each would cost more."""
    a, w, q, R = _inputs((4, *shape))
    with jax.disable_jit():
        batched = _all_public(a, w, q, R)
        mapped = jax.vmap(_all_public)(a, w, q, R)
    for k, v in batched.items():
        assert v.shape[: 1 + len(shape)] == (4, *shape), k
        assert_close(mapped[k], v, atol=1e-13, err_msg=k)


def test_jit_batched_agrees():
    a, w, q, R = _inputs((4, *BATCH_SHAPES[-1]))
    with jax.disable_jit():
        ref = _all_public(a, w, q, R)
    jitted = jax.jit(_all_public)(a, w, q, R)
    for k, v in ref.items():
        assert_close(jitted[k], v, atol=1e-13, err_msg=k)


def test_broadcasting_between_arguments():
    a, w, q, R = _inputs((3, 1))
    _, w2, _, _ = _inputs((1, 5), seed=19)
    d = np.array([0.0, 0.1, 0.2, 0.0, 0.5])  # per-sample damping broadcasts too
    dts = np.array([0.1, 0.2, 0.3])[:, None]

    def fn(a, w2, q, d, dts):
        return (
            rj.euler_rates_to_angular_velocity(a, w2, "XZX"),
            rj.euler_rates_to_angular_velocity(
                jnp.broadcast_to(a, (3, 5, 3)), jnp.broadcast_to(w2, (3, 5, 3)), "XZX"
            ),
            rj.angular_velocity_to_euler_rates(a, w2, "XZX", damping=d),
            rj.angular_velocity_to_euler_rates(a[1, 0], w2[0, 2], "XZX", damping=0.2),
            rj.quaternion_derivative(q, w2),
            rj.integrate_angular_velocity(q, w2, dts),
            rj.integrate_angular_velocity(q[2, 0], w2[0, 1], 0.3),
        )

    outs = jax.jit(fn)(a, w2, q, d, dts)
    out, full, damped, one, qd, qn, qn_one = (np.asarray(x) for x in outs)
    assert out.shape == (3, 5, 3)
    assert_close(out, full, atol=0)
    assert_close(damped[1, 2], one, atol=1e-15)
    assert qd.shape == (3, 5, 4)
    assert qn.shape == (3, 5, 4)
    assert_close(qn[2, 1], qn_one, atol=1e-15)


def test_float32_preserved_and_accurate():
    a, w, q, R = _inputs((4,), dtype=np.float32)
    out32 = jax.jit(_all_public)(a, w, q, R)
    with jax.disable_jit():
        out64 = _all_public(*(x.astype(np.float64) for x in (a, w, q, R)))
    for k, v in out32.items():
        assert v.dtype == jnp.float32, k
        scale = max(1.0, float(np.abs(np.asarray(out64[k])).max()))
        assert_close(v, out64[k], atol=2e-5 * scale, err_msg=k)


# --- validation -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "call",
    [
        lambda: rj.euler_rate_matrix(np.zeros(3), "XYY"),
        lambda: rj.euler_rate_matrix(np.zeros(3), "xYz"),
        lambda: rj.euler_rate_matrix(np.zeros(3), "XYZ", frame="inertial"),
        lambda: rj.euler_rate_matrix(np.zeros(4), "XYZ"),
        lambda: rj.euler_rates_to_angular_velocity(np.zeros(3), np.zeros(2), "XYZ"),
        lambda: rj.angular_velocity_to_euler_rates(np.zeros(3), np.zeros(3), "XYZ", frame="x"),
        lambda: rj.angular_velocity_to_euler_rates(np.zeros(3), np.zeros(4), "XYZ"),
        lambda: rj.euler_singularity(np.zeros(3), "ABC"),
        lambda: rj.quaternion_derivative(np.zeros(4), np.zeros(3), frame="spatial"),
        lambda: rj.quaternion_derivative(np.zeros(3), np.zeros(3)),
        lambda: rj.quaternion_derivative_to_angular_velocity(np.zeros(4), np.zeros(3)),
        lambda: rj.matrix_derivative_to_angular_velocity(np.eye(3), np.eye(3), frame="Body"),
        lambda: rj.angular_velocity_to_matrix_derivative(np.eye(3), np.zeros(4)),
        lambda: rj.integrate_angular_velocity(np.zeros(4), np.zeros(3), 0.1, method="rk2"),
        lambda: rj.integrate_angular_velocity(np.zeros(4), np.zeros(3), 0.1, frame="fixed"),
        lambda: rj.integrate_angular_velocity(np.zeros(3), np.zeros(3), 0.1),
        lambda: rj.unwrap_euler(np.zeros((5, 3)), "XYZ", axis=1),
        lambda: rj.unwrap_euler(np.zeros((5, 3)), "XYZ", axis=-1),
        lambda: rj.unwrap_euler(np.zeros((5, 3)), "XYZ", axis=2),
        lambda: rj.unwrap_euler(np.zeros((5, 2)), "XYZ"),
        lambda: rj.unwrap_euler(np.zeros((5, 3)), "XXZ"),
    ],
)
def test_invalid_arguments_raise(call):
    with pytest.raises(ValueError):
        call()


def test_frame_error_lists_valid_values():
    with pytest.raises(ValueError, match="body.*world"):
        rj.euler_rate_matrix(np.zeros(3), "XYZ", frame="inertial")
    with pytest.raises(ValueError, match="exponential.*euler.*rk4"):
        rj.integrate_angular_velocity(np.zeros(4), np.zeros(3), 0.1, method="rk2")


# --- attitude from sampled angular velocity -----------------------------------------------------

SAMPLE_METHODS = ["hold", "trapezoid", "magnus4"]
_MOTION_SEQ = "ZYX"  # intrinsic: R = R_z(a0) R_y(a1) R_x(a2)


def _motion(t, frame):
    """A tumbling motion known in closed form: intrinsic ZYX angles that are smooth functions of
    time. Returns the attitudes (scalar last, from scipy) and the angular velocity in ``frame``
    from the angle rates, in plain numpy (columns of E: R_x^T R_y^T e_z, R_x^T e_y, e_x)."""
    t = np.asarray(t, np.float64)
    a = np.stack([np.sin(1.3 * t) + 0.4 * t, 0.5 + 0.3 * np.cos(2 * t), 1.7 * t - 0.2 * t**2], -1)
    ad = np.stack([1.3 * np.cos(1.3 * t) + 0.4, -0.6 * np.sin(2 * t), 1.7 - 0.4 * t], -1)
    rot = Rotation.from_euler(_MOTION_SEQ, a)
    c1, s1, c2, s2 = np.cos(a[:, 1]), np.sin(a[:, 1]), np.cos(a[:, 2]), np.sin(a[:, 2])
    col0 = np.stack([-s1, c1 * s2, c1 * c2], -1)  # R_x(a2)^T R_y(a1)^T e_z
    col1 = np.stack([0 * c2, c2, -s2], -1)  # R_x(a2)^T e_y
    w = ad[:, :1] * col0 + ad[:, 1:2] * col1 + ad[:, 2:] * np.array([1.0, 0.0, 0.0])
    if frame == "world":
        w = np.einsum("nij,nj->ni", rot.as_matrix(), w)
    return rot.as_quat(), w


def _chordal(q, q_ref):
    """Largest ``min |q -+ q_ref|`` over samples (about half the angle error, no acos)."""
    q, q_ref = np.asarray(q, np.float64), np.asarray(q_ref)
    return np.minimum(np.abs(q - q_ref).max(-1), np.abs(q + q_ref).max(-1)).max()


def test_motion_angular_velocity_matches_scipy():
    """The test motion's closed-form angular velocity agrees with differences of scipy's
    attitudes (so the order tests below measure the integrators, not the motion)."""
    t, h = np.linspace(0.0, 2.0, 9), 1e-6
    for frame in FRAMES:
        _, w = _motion(t, frame)
        r0, r1 = (
            Rotation.from_quat(_motion(t - h, frame)[0]),
            Rotation.from_quat(_motion(t + h, frame)[0]),
        )
        d = (r0.inv() * r1) if frame == "body" else (r1 * r0.inv())
        np.testing.assert_allclose(d.as_rotvec() / (2 * h), w, atol=1e-8)


@jax.jit(static_argnames=("frame", "method"))
def _samples_jit(q0, w, dt, frame, method):
    return rj.integrate_angular_velocity_samples(q0, w, dt, frame, method)


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize(
    ("method", "order"),
    [
        pytest.param("hold", 1, marks=pytest.mark.slow),
        pytest.param("trapezoid", 2, marks=pytest.mark.slow),
        ("magnus4", 4),
    ],
)
def test_sample_integration_orders(method, order, frame):
    """The largest attitude error over [0, 2] shrinks by 2**order when the sample interval
    halves (observed orders 1, 2, 4, each within 0.25: the sample with the largest error moves
    as dt halves, so the ratios wobble by up to 0.16 for magnus4)."""
    errs = []
    for steps in (16, 32, 64):
        # One log length for every interval (one compiled program): 65 samples of the motion
        # (defined beyond t = 2), of which the first steps + 1 cover [0, 2].
        dt = 2.0 / steps
        q_true, w = _motion(dt * np.arange(65), frame)
        q = _samples_jit(q_true[0], w, np.float64(dt), frame, method)
        errs.append(_chordal(np.asarray(q)[: steps + 1], q_true[: steps + 1]))
    observed = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(np.abs(observed - order) < 0.25), observed


@pytest.mark.parametrize("frame", FRAMES)
def test_trapezoid_commutator_term(frame):
    """One step with omega linear in time, against a fine-grained fourth-order solution: the
    commutator (coning) term is 1.7e-3 here, so a missing or mis-signed term fails."""
    a, b, h = np.array([1.0, 0.0, 0.0]), np.array([0.0, 2.0, 0.0]), 0.1
    q0 = np.array([0.1, 0.2, -0.3, 0.9])
    coarse = rj.integrate_angular_velocity_samples(q0, np.stack([a, b]), h, frame, "trapezoid")
    s = np.linspace(0.0, 1.0, 201)[:, None]
    fine = rj.integrate_angular_velocity_samples(q0, (1 - s) * a + s * b, h / 200, frame)
    assert _chordal(coarse[-1], fine[-1]) < 2e-5


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("method", SAMPLE_METHODS)
def test_samples_constant_omega_exact(method, frame):
    """For a constant angular velocity every method is the exact exponential."""
    q0 = rj.quaternion_normalize(jnp.asarray([0.3, -0.2, 0.5, 0.8]))
    w = jnp.asarray([1.3, -2.1, 0.4])
    ts = 0.07 * np.arange(9)
    ws = jnp.broadcast_to(w, (9, 3))
    q = rj.integrate_angular_velocity_samples(q0, ws, 0.07, frame, method)
    want = _quat_path(jnp.broadcast_to(q0, (9, 4)), ws, frame, ts[:, None])
    assert_same_rotation(q, want, atol=1e-14)


@pytest.mark.parametrize("frame", FRAMES)
def test_hold_equals_exponential_steps(frame):
    """ "hold" is the existing one-step exponential integrator, applied sample by sample."""
    w = jnp.asarray(_rng(21).normal(size=(12, 3)))
    q0 = jnp.asarray([0.2, 0.0, -0.1, 0.7])  # not unit
    got = rj.integrate_angular_velocity_samples(q0, w, 0.05, frame, "hold")
    _, traj = _propagate(rj.quaternion_normalize(q0), w[:-1], 0.05, frame, "exponential")
    assert_close(got[0], np.asarray(q0) / np.linalg.norm(q0), atol=1e-15)
    assert_close(got[1:], traj, atol=1e-14)


@pytest.mark.slow
def test_samples_gradient_at_zero_and_generic():
    """Forward and reverse derivatives match finite differences at omega = 0 (the exp map's
    Taylor branch) and at a generic log, for every method (and the world frame once)."""
    q0 = jnp.asarray([0.3, -0.4, 0.1, 0.85])

    @jax.jit
    def f(w):
        return jnp.stack(
            [
                rj.integrate_angular_velocity_samples(q0, w, 0.1, frame, method)[-1]
                for method, frame in [(m, "body") for m in SAMPLE_METHODS] + [("magnus4", "world")]
            ]
        )

    jacs = jax.jit(lambda x: (jax.jacfwd(f)(x), jax.jacrev(f)(x)))
    for w in (jnp.zeros((5, 3)), jnp.asarray(_rng(22).normal(size=(5, 3)))):
        jf, jr = jacs(w)
        fd = fd_jacobian(f, w, h=1e-6)
        assert_close(jf, fd, atol=1e-9)
        assert_close(jr, jf, atol=1e-15)
        assert np.all(np.abs(jf).max(axis=(1, 2, 3)) > 1e-3)  # not silently zero


def test_samples_batch_vmap_scalar_first_float32():
    """Batch dims after time broadcast against q0, vmap over them agrees, per-element dt
    broadcasts, scalar_first round-trips, float32 stays float32, strict rank promotion."""
    rng = _rng(23)
    w = rng.normal(size=(7, 3, 2, 3))
    q0 = rng.normal(size=(2, 4))
    dts = np.array([0.05, 0.1])
    with jax.numpy_rank_promotion("raise"):
        q = rj.integrate_angular_velocity_samples(q0, w, dts)
        assert q.shape == (7, 3, 2, 4)
        one = rj.integrate_angular_velocity_samples(q0[1], w[:, 2, 1], 0.1)
        assert_close(q[:, 2, 1], one, atol=1e-14)
        mapped = jax.vmap(
            lambda qq, ww, d: rj.integrate_angular_velocity_samples(qq, ww, d),
            in_axes=(0, 2, 0),
            out_axes=2,
        )(q0, w, dts)
        assert_close(mapped, q, atol=1e-14)
        sf = rj.integrate_angular_velocity_samples(np.roll(q0, 1, -1), w, dts, scalar_first=True)
        assert_close(np.roll(sf, -1, -1), q, atol=1e-15)
        q32 = rj.integrate_angular_velocity_samples(
            q0.astype(np.float32), w.astype(np.float32), 0.1
        )
    assert q32.dtype == jnp.float32
    q64 = rj.integrate_angular_velocity_samples(q0, w, 0.1)
    assert_close(q32, q64, atol=2e-6)


@pytest.mark.parametrize("n", [1, 2, 3])
def test_samples_short_logs(n):
    """One sample returns q0; two or three samples still give unit attitudes (magnus4 then
    interpolates through all of them)."""
    w = _rng(24).normal(size=(n, 3))
    q = rj.integrate_angular_velocity_samples(np.array([0.0, 0.0, 0.0, 2.0]), w, 0.1)
    assert q.shape == (n, 4)
    assert_close(q[0], [0.0, 0.0, 0.0, 1.0], atol=0)
    assert_close(np.linalg.norm(q, axis=-1), 1.0, atol=1e-15)


@pytest.mark.parametrize(("method", "first_nan"), [("hold", 4), ("trapezoid", 3), ("magnus4", 1)])
def test_samples_nan_and_zero_q0(method, first_nan):
    """A NaN sample reaches the attitudes from the first step that reads it onwards (hold:
    step 3; trapezoid: step 2; magnus4: every step whose stencil holds it, from step 0) and
    stays in its own batch element; the zero q0 gives NaN."""
    w = _rng(25).normal(size=(8, 2, 3))
    w[3, 0, 1] = np.nan
    q0 = np.array([0.0, 0.0, 0.0, 1.0])
    q = np.asarray(rj.integrate_angular_velocity_samples(q0, w, 0.1, method=method))
    assert np.all(np.isfinite(q[:, 1])) and np.all(np.isfinite(q[:first_nan, 0]))
    assert np.all(np.isnan(q[first_nan:, 0]))
    z = rj.integrate_angular_velocity_samples(np.zeros(4), w[:, 1], 0.1, method=method)
    assert np.all(np.isnan(z))


# --- Euler accelerations ------------------------------------------------------------------------


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("seq", ALL_SEQS)
def test_euler_accelerations_match_jvp_and_invert(seq, frame):
    """alpha = d/dt omega along a(t): jax.jvp of the rate map with tangents (a', a''); the
    inverse recovers a'' away from lock."""
    rng = _rng(26)
    a = _generic_angles(seq, 6, seed=26)
    r, acc = rng.normal(size=(2, 6, 3))
    with jax.disable_jit():  # op by op: the primitives compile once for all 58 cases
        _, want = jax.jvp(
            lambda x, y: rj.euler_rates_to_angular_velocity(x, y, seq, frame), (a, r), (r, acc)
        )
        alpha = rj.euler_accelerations_to_angular_acceleration(a, r, acc, seq, frame)
        back = rj.angular_acceleration_to_euler_accelerations(a, r, alpha, seq, frame)
    assert_close(alpha, want, atol=4e-15 * np.abs(want).max())
    assert_close(back, acc, atol=1e-12)


@pytest.mark.parametrize("seq", ["XYZ", "zyx", "ZXZ", "yzy", "313"])
def test_angular_acceleration_frames_related_by_R(seq):
    rng = _rng(27)
    a, r, acc = rng.normal(size=(3, 5, 3))
    ab = rj.euler_accelerations_to_angular_acceleration(a, r, acc, seq, "body")
    aw = rj.euler_accelerations_to_angular_acceleration(a, r, acc, seq, "world")
    R = rj.euler_to_matrix(a, seq)
    assert_close(aw, np.einsum("nij,nj->ni", R, ab), atol=1e-14)


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("seq", sweep(["XYZ", "zxy", "ZXZ", "xzx", "121"], fast=["XYZ", "xzx"]))
def test_damped_euler_accelerations_at_lock(seq, frame):
    """At exact lock the damped inverse and its gradients are finite (and not all zero); the
    exact inverse is not finite there."""
    a = _lock_angles(seq, seed=28)
    r, alpha = _rng(28).normal(size=(2, 3, 3))

    def f(a, r, al):
        return rj.angular_acceleration_to_euler_accelerations(a, r, al, seq, frame, damping=0.1)

    with jax.disable_jit():  # op by op: compiled primitives are shared between the cases
        out = f(a, r, alpha)
        grads = jax.jacrev(lambda *x: jnp.sum(f(*x)), argnums=(0, 1, 2))(a, r, alpha)
        exact = np.asarray(rj.angular_acceleration_to_euler_accelerations(a, r, alpha, seq, frame))
    assert np.all(np.isfinite(out))
    for g in grads:
        assert np.all(np.isfinite(g)) and np.abs(g).max() > 0
    # Non-finite, or ~1/eps where the lock angle pi/2 is not exact in floating point.
    assert not np.all(np.isfinite(exact)) or np.abs(exact).max() > 1e12


# --- quaternion sign continuity -----------------------------------------------------------------


def _smooth_series(n, batch=(), seed=29):
    """A slowly turning quaternion series (steps of about 0.2 rad) and random sign flips."""
    rng = _rng(seed)
    w = 0.2 * rng.normal(size=(n, *batch, 3))
    q = np.asarray(
        rj.integrate_angular_velocity_samples(rng.normal(size=(*batch, 4)), w, 1.0, "body", "hold")
    )
    flips = rng.choice([-1.0, 1.0], size=(n, *batch, 1))
    return q, flips


@pytest.mark.parametrize("axis", [0, np.int64(1), -2])
def test_unwrap_quaternion_restores_continuity(axis):
    q, flips = _smooth_series(20, (3,))
    x = q * flips
    ax = int(axis) % 3
    out = rj.unwrap_quaternion(np.moveaxis(x, 0, ax), axis=axis)
    out = np.moveaxis(np.asarray(out), ax, 0)
    assert_close(out, q * flips[:1], atol=0)  # the first sample's sign is kept
    sf = rj.unwrap_quaternion(np.roll(x, 1, -1), scalar_first=True)
    assert_close(np.roll(sf, -1, -1), out, atol=0)


def test_unwrap_quaternion_nan_stays_local():
    """A NaN or inf sample is returned as is; the next finite sample is unwrapped against the
    last finite one, so the rest of the series is what it would be without the bad sample."""
    q, flips = _smooth_series(12, (2,), seed=30)
    x = q * flips
    if np.dot(x[0, 0], x[1, 0]) > 0:  # the bad samples come after a flip: -1 is carried
        x[1:, 0] *= -1
    if np.dot(x[3, 0], x[6, 0]) > 0:  # make the sample after the gap need a flip
        x[6:, 0] *= -1
    bad = x.copy()
    bad[4, 0, 2] = np.inf
    bad[5, 0] = np.nan
    bad[0, 1] = np.nan  # a bad first sample: the first finite one keeps its sign
    out = np.asarray(rj.unwrap_quaternion(bad))
    keep0 = np.r_[0:4, 6:12]
    ref0 = np.asarray(rj.unwrap_quaternion(x[keep0, 0]))
    ref1 = np.asarray(rj.unwrap_quaternion(x[1:, 1]))
    assert_close(out[keep0, 0], ref0, atol=0)
    assert_close(out[1:, 1], ref1, atol=0)
    np.testing.assert_array_equal(out[4:6, 0], bad[4:6, 0])
    assert np.isnan(out[0, 1]).all()


def test_unwrap_quaternion_ties_and_gradient():
    """A dot product of exactly 0 keeps the sign; the gradient is the sign pattern."""
    q = jnp.asarray([[0.0, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0, 0.0], [-1.0, 0.0, 0.0, 0.1]])
    out = rj.unwrap_quaternion(q)
    assert_close(out, q * jnp.asarray([[1.0], [1.0], [-1.0]]), atol=0)
    g = jax.grad(lambda x: jnp.sum(rj.unwrap_quaternion(x)))(q)
    assert_close(g, np.array([[1.0], [1.0], [-1.0]]) * np.ones(4), atol=0)


def test_unwrap_euler_nan_stays_local():
    """One NaN sample of unwrap_euler no longer poisons the samples after it."""
    seq = "ZYX"
    true = np.cumsum(_rng(31).normal(size=(15, 2, 3)) * 0.4, axis=0)
    wrapped = _principal(true, seq)
    bad = wrapped.copy()
    bad[6, 0, 1] = np.nan
    out = np.asarray(rj.unwrap_euler(bad, seq, axis=np.int64(0)))
    keep = np.r_[0:6, 7:15]
    assert_close(out[keep, 0], rj.unwrap_euler(wrapped[keep, 0], seq), atol=0)
    assert_close(out[:, 1], rj.unwrap_euler(wrapped[:, 1], seq), atol=0)
    np.testing.assert_array_equal(out[6, 0], bad[6, 0])


@pytest.mark.parametrize(
    "call",
    [
        lambda: rj.unwrap_quaternion(np.zeros((5, 4)), axis=1),
        lambda: rj.unwrap_quaternion(np.zeros((5, 3))),
        lambda: rj.integrate_angular_velocity_samples(np.zeros(4), np.zeros((5, 3)), 0.1, "x"),
        lambda: rj.integrate_angular_velocity_samples(np.zeros(4), np.zeros(3), 0.1),
        lambda: rj.integrate_angular_velocity_samples(
            np.zeros(4), np.zeros((5, 3)), 0.1, method="rk4"
        ),
        lambda: rj.euler_accelerations_to_angular_acceleration(
            np.zeros(3), np.zeros(3), np.zeros(2), "XYZ"
        ),
        lambda: rj.angular_acceleration_to_euler_accelerations(
            np.zeros(3), np.zeros(3), np.zeros(3), "XYZ", frame="inertial"
        ),
    ],
)
def test_new_invalid_arguments_raise(call):
    with pytest.raises(ValueError):
        call()


def test_non_integer_axis_is_a_type_error():
    with pytest.raises(TypeError, match="axis must be an int"):
        rj.unwrap_quaternion(np.zeros((5, 4)), axis=1.0)
