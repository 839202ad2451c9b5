"""Kinematics: angular velocity and the time derivatives of every representation.

Conventions (see the README's Conventions table):

* ``R`` is active, ``v_world = R @ v_body``; quaternions are scalar last and Hamilton.
* ``frame="body"``: the angular velocity in body axes, ``omega_body = vee(R.T @ dR/dt)``.
* ``frame="world"``: the angular velocity in world axes, ``omega_world = vee(dR/dt @ R.T)``
  (the Simscape seed's ``Omega = dR/dt R^T``). ``omega_world = R @ omega_body``.

Euler-angle rates are reduced to one closed form: the *intrinsic* sequence in the *body* frame.
With ``R = R_i(a0) R_j(a1) R_k(a2)``, each angle rate spins the body about its own rotation axis
carried into body axes, so

    omega_body = a0' R_k(a2)^T R_j(a1)^T e_i + a1' R_k(a2)^T e_j + a2' e_k
               = R_k(a2)^T M [a0', a1', a2'],   M = [u, e_j, e_k],  u = R_j(a1)^T e_i.

The other three cases map onto it exactly (derived here, checked against autodiff in the tests):

* extrinsic ``(i, j, k)`` with angles ``a`` is intrinsic ``(k, j, i)`` with the angles reversed;
* the world-frame velocity of ``R`` is minus the body-frame velocity of ``R^T``, and ``R^T`` is
  the intrinsic reversed sequence at the negated, reversed angles; the two sign flips cancel, so
  ``E_world(seq, a) = E_body(reversed seq, -reversed a) @ P`` with ``P`` the order reversal.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ._euler import is_proper, parse_seq
from ._numerics import (
    as_float,
    check_shape,
    from_scalar_last,
    hat,
    like_rank,
    matmul,
    matvec,
    public,
    to_scalar_last,
    vee,
)
from ._quaternion import _conjugate, _multiply, _normalize
from ._rotvec import _rotvec_to_quat

FRAMES = ("body", "world")
METHODS = ("exponential", "euler", "rk4")


def _check_frame(frame) -> None:
    if frame not in FRAMES:
        raise ValueError(f"frame must be one of {FRAMES}, got {frame!r}")


def _levi_civita(i: int, j: int, k: int) -> int:
    """``epsilon_ijk`` for distinct axis indices: +1 for a cyclic order of (x, y, z), else -1."""
    return (i - j) * (j - k) * (k - i) // 2


# --- Euler rate matrices ---------------------------------------------------------------------


def _reduce(seq: str, frame: str):
    """Map ``(seq, frame)`` to the intrinsic body-frame case.

    Returns:
        ``(axes, negate, reverse)``: the intrinsic axes to use, whether the angles are negated,
        and whether the angle order is reversed (the angles on input, the columns of ``E`` and
        the rows of ``E^-1`` on output).
    """
    axes, intrinsic = parse_seq(seq)
    _check_frame(frame)
    world = frame == "world"
    reverse = intrinsic == world  # intrinsic/world and extrinsic/body reverse the order
    return (axes[::-1] if reverse else axes), world, reverse


def _prep_angles(a, negate: bool, reverse: bool):
    if reverse:
        a = a[..., ::-1]
    return -a if negate else a


def _rotate_k_transposed(k: int, angle, v):
    """``R_k(angle)^T @ v`` on a list of three component arrays (``R_k``: about axis ``k``)."""
    p, r = (k + 1) % 3, (k + 2) % 3  # (k, p, r) is cyclic, R_k turns e_p towards e_r
    c, s = jnp.cos(angle), jnp.sin(angle)
    out = list(v)
    out[p] = c * v[p] + s * v[r]
    out[r] = c * v[r] - s * v[p]
    return out


def _middle_terms(axes, a1):
    """``(h, g, m, s)`` for the middle angle ``a1`` of intrinsic ``axes = (i, j, k)``.

    ``u = R_j(a1)^T e_i = cos(a1) e_i + s sin(a1) e_m`` with ``m`` the axis that is neither ``i``
    nor ``j`` and ``s = epsilon_ijm``. ``h`` is the distance to gimbal lock (``cos a1`` for
    Tait-Bryan, ``sin a1`` for proper sequences) and ``g = u . e_k`` the one off-diagonal entry of
    the Gram matrix ``M^T M = [[1, 0, g], [0, 1, 0], [g, 0, 1]]``; ``h^2 + g^2 = 1``.
    """
    i, j, k = axes
    m = 3 - i - j
    s = _levi_civita(i, j, m)
    c1, s1 = jnp.cos(a1), jnp.sin(a1)
    if i == k:  # proper Euler: u . e_k = u . e_i = cos(a1)
        return s1, c1, m, s
    return c1, s * s1, m, s  # Tait-Bryan: m == k, u . e_k = s sin(a1)


def _body_rate_matrix(axes, a):
    """``E`` with ``omega_body = E @ rates`` for the intrinsic sequence ``axes`` (closed form)."""
    i, j, k = axes
    m = 3 - i - j
    s = _levi_civita(i, j, m)
    a1, a2 = a[..., 1], a[..., 2]
    zero = jnp.zeros_like(a1)
    one = jnp.ones_like(a1)
    u = [zero, zero, zero]
    u[i] = jnp.cos(a1)
    u[m] = s * jnp.sin(a1)
    e_j = [zero, zero, zero]
    e_j[j] = one
    e_k = [zero, zero, zero]
    e_k[k] = one
    cols = (_rotate_k_transposed(k, a2, u), _rotate_k_transposed(k, a2, e_j), e_k)
    return jnp.stack([cols[c][r] for r in range(3) for c in range(3)], axis=-1).reshape(
        *a.shape[:-1], 3, 3
    )


def _rate_matrix(a, seq, frame):
    axes, negate, reverse = _reduce(seq, frame)
    E = _body_rate_matrix(axes, _prep_angles(a, negate, reverse))
    return E[..., ::-1] if reverse else E


def _inverse_rates(a, omega, seq, frame, damping):
    """Exact (``damping == 0``) or damped least-squares inverse of :func:`_rate_matrix`.

    With ``E = R_k(a2)^T M P`` (``P`` a permutation) and ``v = R_k(a2) omega``, the damped solution
    ``(E^T E + d^2 I)^-1 E^T omega = P^T (G + d^2 I)^-1 M^T v`` only needs the 2x2 block
    ``[[1 + d^2, g], [g, 1 + d^2]]`` of ``G = M^T M``. Its determinant is written
    ``h^2 + d^2 (2 + d^2)`` (``1 - g^2 = h^2``), so no cancellation happens near lock, and it is
    at least ``2 d^2`` everywhere.
    """
    axes, negate, reverse = _reduce(seq, frame)
    a = _prep_angles(a, negate, reverse)
    i, j, k = axes
    h, g, m, s = _middle_terms(axes, a[..., 1])
    v = _rotate_k_transposed(k, -a[..., 2], list(jnp.moveaxis(omega, -1, 0)))  # R_k(a2) omega
    # M [x0, x1, x2] = v:  Tait-Bryan  v_i = h x0,        v_k = g x0 + x2;
    #                      proper      s v_m = h x0,      v_i = g x0 + x2.
    A, B = (s * v[m], v[i]) if i == k else (v[i], v[k])
    damped = damping > 0
    # Exact closed form (1/cos or 1/sin of the middle angle). Double where: where the damped
    # branch is selected, h may be 0 and A / h would send NaN into its gradient.
    h_safe = jnp.where(damped, 1.0, h)
    x0_exact = A / h_safe
    x2_exact = B - g * x0_exact
    d2 = damping * damping
    den = jnp.where(damped, h * h + d2 * (2 + d2), 1.0)  # > 0 where used
    x0_damped = ((1 + d2) * h * A + d2 * g * B) / den
    x2_damped = ((h * h + d2) * B - g * h * A) / den
    x0 = jnp.where(damped, x0_damped, x0_exact)
    x1 = v[j] / (1 + d2)
    x2 = jnp.where(damped, x2_damped, x2_exact)
    out = jnp.stack([x0, x1, x2], axis=-1)
    return out[..., ::-1] if reverse else out


@public
def euler_rate_matrix(angles, seq: str, frame: str = "body"):
    """Matrix ``E`` that maps Euler-angle rates to angular velocity: ``omega = E @ rates``.

    Args:
        angles: ``(..., 3)`` Euler angles in radians, in the order of ``seq``; any values.
        seq: axis sequence: ``"XYZ"``-style intrinsic, ``"xyz"``-style extrinsic or digits
            ``"123"`` (intrinsic); see :func:`rotjax.euler_to_quaternion`.
        frame: ``"body"`` (``omega = vee(R.T @ dR/dt)``, components in body axes) or
            ``"world"`` (``omega = vee(dR/dt @ R.T)``, components in world axes).

    Returns:
        ``(..., 3, 3)`` matrix whose column ``n`` is the rotation axis of angle ``n`` expressed
        in ``frame``. For intrinsic ``"ZXZ"`` in the body frame this is Nikravesh's Eq. (A.3),
        for intrinsic ``"XYZ"`` the corrected Eq. (A.7).

    Note:
        ``E`` is smooth everywhere. Its determinant is ``+-cos(a1)`` for Tait-Bryan sequences and
        ``+-sin(a1)`` for proper Euler sequences (``a1`` the middle angle): it is singular at
        gimbal lock, where the first and third axes coincide.
    """
    (a,), dt = as_float(angles)
    check_shape(a, (3,), "angles")
    return _rate_matrix(a, seq, frame).astype(dt)


@public
def euler_rates_to_angular_velocity(angles, rates, seq: str, frame: str = "body"):
    """Angular velocity of a body whose Euler angles change at ``rates``.

    Args:
        angles: ``(..., 3)`` Euler angles in radians, in the order of ``seq``.
        rates: ``(..., 3)`` angle rates (rad per unit time); broadcasts against ``angles``.
        seq: axis sequence; see :func:`euler_rate_matrix`.
        frame: ``"body"`` (``omega = vee(R.T @ dR/dt)``, components in body axes) or
            ``"world"`` (``omega = vee(dR/dt @ R.T)``, components in world axes).

    Returns:
        ``(..., 3)`` angular velocity ``euler_rate_matrix(angles, seq, frame) @ rates``. Smooth
        and finite everywhere, gimbal lock included.
    """
    (a, r), dt = as_float(angles, rates)
    check_shape(a, (3,), "angles")
    check_shape(r, (3,), "rates")
    E = _rate_matrix(a, seq, frame)
    return matvec(E, r).astype(dt)


@public
def angular_velocity_to_euler_rates(angles, omega, seq: str, frame: str = "body", damping=0.0):
    """Euler-angle rates that produce the angular velocity ``omega``.

    Args:
        angles: ``(..., 3)`` Euler angles in radians, in the order of ``seq``.
        omega: ``(..., 3)`` angular velocity in ``frame``; broadcasts against ``angles``.
        seq: axis sequence; see :func:`euler_rate_matrix`.
        frame: ``"body"`` (``omega = vee(R.T @ dR/dt)``, components in body axes) or
            ``"world"`` (``omega = vee(dR/dt @ R.T)``, components in world axes).
        damping: ``(...)`` non-negative damping ``d``, traced (it may vary inside a compiled
            loop). ``0`` gives the exact inverse ``E^-1 @ omega`` in closed form (a ``1/cos`` of
            the middle angle for Tait-Bryan sequences, ``1/sin`` for proper ones, as Nikravesh
            Eqs. A.4 and A.8). ``d > 0`` gives the damped least-squares solution
            ``(E^T E + d^2 I)^-1 E^T omega``, which differs from the exact one by ``O(d^2)``
            away from lock.

    Returns:
        ``(..., 3)`` angle rates.

    Note:
        *At gimbal lock with* ``damping=0`` the rates do not exist (only the sum or difference
        of the outer rates is defined, and an ``omega`` with a component along the missing
        direction cannot be produced at all): the result is non-finite (``inf`` or ``nan``),
        and near lock it grows like ``1/euler_singularity``. With ``damping > 0`` the result is
        finite everywhere with finite gradients; at lock it is the minimum-norm least-squares
        solution shrunk by the damping. A common pattern is to switch on damping inside a jitted
        loop with ``jnp.where(euler_singularity(angles, seq) < tol, d, 0.0)``.
    """
    (a, w), dt = as_float(angles, omega)
    check_shape(a, (3,), "angles")
    check_shape(w, (3,), "omega")
    d = jnp.asarray(damping).astype(a.dtype)
    return _inverse_rates(a, w, seq, frame, d).astype(dt)


@public
def euler_singularity(angles, seq: str):
    """Distance to gimbal lock: ``|cos(a1)|`` (Tait-Bryan) or ``|sin(a1)|`` (proper Euler).

    Args:
        angles: ``(..., 3)`` Euler angles in radians, in the order of ``seq``.
        seq: axis sequence; see :func:`euler_rate_matrix`.

    Returns:
        ``(...)`` value in ``[0, 1]``: ``|det E|`` of :func:`euler_rate_matrix` in either frame;
        0 exactly at gimbal lock, 1 when the first and third axes are perpendicular. Branch-free,
        so it can drive a ``jnp.where`` inside ``jit`` or ``lax.scan``.
    """
    (a,), dt = as_float(angles)
    check_shape(a, (3,), "angles")
    axes, _ = parse_seq(seq)
    h, _, _, _ = _middle_terms(axes, a[..., 1])
    return jnp.abs(h).astype(dt)


# --- quaternion and matrix derivatives ---------------------------------------------------------


def _pure(omega):
    return jnp.concatenate([omega, jnp.zeros_like(omega[..., :1])], axis=-1)


def _quat_rate(q, omega, frame):
    # body: q' = q * (omega_b, 0) / 2;  world: q' = (omega_w, 0) * q / 2  (R(p q) = R(p) R(q)).
    # The Simscape seed's "q_v' = (q_s w - q_v x w) / 2" is the world-frame form.
    w = _pure(omega)
    return 0.5 * (_multiply(q, w) if frame == "body" else _multiply(w, q))


@public
def quaternion_derivative(q, omega, frame: str = "body", scalar_first: bool = False):
    """Time derivative of a quaternion rotating at angular velocity ``omega``.

    Args:
        q: ``(..., 4)`` quaternion, scalar last unless ``scalar_first``; need not be unit.
        omega: ``(..., 3)`` angular velocity in ``frame``; broadcasts against ``q``.
        frame: ``"body"`` (``q' = q * (omega, 0) / 2``) or ``"world"``
            (``q' = (omega, 0) * q / 2``), Hamilton products.
        scalar_first: ``q`` (and the result) are ``(w, x, y, z)``.

    Returns:
        ``(..., 4)`` ``dq/dt``, in the layout of ``q``. It is orthogonal to ``q``, so the norm of
        ``q`` is preserved; for a non-unit ``q`` it is the derivative of ``|q| q_unit(t)``.
        Bilinear in ``q`` and ``omega``: no singularity.
    """
    (q, w), dt = as_float(q, omega)
    check_shape(q, (4,), "q")
    check_shape(w, (3,), "omega")
    _check_frame(frame)
    qd = _quat_rate(to_scalar_last(q, scalar_first), w, frame)
    return from_scalar_last(qd, scalar_first).astype(dt)


@public
def quaternion_derivative_to_angular_velocity(
    q, q_dot, frame: str = "body", scalar_first: bool = False
):
    """Angular velocity from a quaternion and its time derivative.

    Args:
        q: ``(..., 4)`` quaternion; need not be unit (must be non-zero).
        q_dot: ``(..., 4)`` its time derivative, same layout; broadcasts against ``q``.
        frame: ``"body"`` (``omega = 2 vec(conj(q) * q') / |q|^2``) or ``"world"``
            (``omega = 2 vec(q' * conj(q)) / |q|^2``).
        scalar_first: quaternions are ``(w, x, y, z)``.

    Returns:
        ``(..., 3)`` angular velocity in ``frame``. A component of ``q_dot`` along ``q`` (a
        change of norm) lands in the scalar part and is ignored, so the result is exact for a
        quaternion of varying norm. The zero quaternion gives NaN.
    """
    (q, qd), dt = as_float(q, q_dot)
    check_shape(q, (4,), "q")
    check_shape(qd, (4,), "q_dot")
    _check_frame(frame)
    q = to_scalar_last(q, scalar_first)
    qd = to_scalar_last(qd, scalar_first)
    qc = _conjugate(q)
    prod = _multiply(qc, qd) if frame == "body" else _multiply(qd, qc)
    n2 = jnp.sum(q * q, axis=-1, keepdims=True)
    return (2 * prod[..., :3] / n2).astype(dt)


@public
def matrix_derivative_to_angular_velocity(R, R_dot, frame: str = "body"):
    """Angular velocity from a rotation matrix and its time derivative.

    Args:
        R: ``(..., 3, 3)`` active rotation matrix.
        R_dot: ``(..., 3, 3)`` its time derivative; broadcasts against ``R``.
        frame: ``"body"`` (``omega = vee(R.T @ R_dot)``) or ``"world"``
            (``omega = vee(R_dot @ R.T)``, the Simscape seed's ``Omega = dR/dt R^T``).

    Returns:
        ``(..., 3)`` angular velocity in ``frame``. ``vee`` reads the antisymmetric part, so a
        ``R_dot`` slightly off the tangent space is projected onto it. No singularity.
    """
    (R, Rd), dt = as_float(R, R_dot)
    check_shape(R, (3, 3), "R")
    check_shape(Rd, (3, 3), "R_dot")
    _check_frame(frame)
    Rt = jnp.swapaxes(R, -1, -2)
    return vee(matmul(Rt, Rd) if frame == "body" else matmul(Rd, Rt)).astype(dt)


@public
def angular_velocity_to_matrix_derivative(R, omega, frame: str = "body"):
    """Time derivative of a rotation matrix turning at angular velocity ``omega``.

    Args:
        R: ``(..., 3, 3)`` active rotation matrix.
        omega: ``(..., 3)`` angular velocity in ``frame``; broadcasts against ``R``.
        frame: ``"body"`` (``R_dot = R @ hat(omega)``) or ``"world"``
            (``R_dot = hat(omega) @ R``).

    Returns:
        ``(..., 3, 3)`` ``dR/dt``. Linear in ``omega``: no singularity.
    """
    (R, w), dt = as_float(R, omega)
    check_shape(R, (3, 3), "R")
    check_shape(w, (3,), "omega")
    _check_frame(frame)
    W = hat(w)
    return (matmul(R, W) if frame == "body" else matmul(W, R)).astype(dt)


# --- attitude propagation ----------------------------------------------------------------------


@public
def integrate_angular_velocity(
    q, omega, dt, frame: str = "body", method: str = "exponential", scalar_first: bool = False
):
    """One step of attitude propagation with the angular velocity held constant over the step.

    Args:
        q: ``(..., 4)`` orientation at the start of the step; need not be unit.
        omega: ``(..., 3)`` angular velocity in ``frame`` over the step (zero-order hold, as a
            gyro sample); broadcasts against ``q``.
        dt: ``(...)`` step length; broadcasts against ``q[..., 0]``. Any sign.
        frame: ``"body"`` (gyro axes, ``q_next = q * dq``) or ``"world"``
            (``q_next = dq * q``).
        method:

            * ``"exponential"`` (default): ``dq = exp(omega dt / 2)``, the exact step for a
              constant ``omega``. Its Taylor branch at ``omega = 0`` makes the gradient there
              exact.
            * ``"euler"``: ``q + dt q'``, renormalised. Because ``omega`` is constant over the
              step, the renormalised step turns about the exact axis by ``2 atan(|omega| dt / 2)``
              instead of ``|omega| dt``: local error ``O(dt^3)``, global ``O(dt^2)``.
            * ``"rk4"``: classical Runge-Kutta on ``q' = q * (omega, 0) / 2``, renormalised:
              local error ``O(dt^5)``, global ``O(dt^4)``.
        scalar_first: quaternions are ``(w, x, y, z)``.

    Returns:
        ``(..., 4)`` unit quaternion at the end of the step, in the layout of ``q``. No
        hemisphere is imposed, so a sequence of steps stays continuous.

    Note:
        The step is a pure function of its arrays, so it scans over a gyro log::

            step = lambda q, w: (integrate_angular_velocity(q, w, dt),) * 2
            q_end, q_traj = jax.lax.scan(step, q0, omegas)
    """
    (q, w), out_dt = as_float(q, omega)
    check_shape(q, (4,), "q")
    check_shape(w, (3,), "omega")
    _check_frame(frame)
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    h = like_rank(jnp.asarray(dt).astype(q.dtype)[..., None], q)
    q = to_scalar_last(q, scalar_first)
    if method == "exponential":
        dq = _rotvec_to_quat(w * h)
        q_next = _multiply(q, dq) if frame == "body" else _multiply(dq, q)
    elif method == "euler":
        q_next = q + h * _quat_rate(q, w, frame)
    else:

        def f(x):
            return _quat_rate(x, w, frame)

        k1 = f(q)
        k2 = f(q + h / 2 * k1)
        k3 = f(q + h / 2 * k2)
        k4 = f(q + h * k3)
        q_next = q + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return from_scalar_last(_normalize(q_next), scalar_first).astype(out_dt)


# --- continuous Euler angles -------------------------------------------------------------------


@public
def unwrap_euler(angles, seq: str, axis: int = 0):
    """Continuous Euler angles from a time series of principal-range ones.

    Args:
        angles: ``(..., T, ..., 3)`` Euler angles in radians, in the order of ``seq``, e.g. from
            :func:`rotjax.quaternion_to_euler`; the last axis holds the three angles.
        seq: axis sequence; see :func:`euler_rate_matrix`.
        axis: the time axis (any axis but the last).

    Returns:
        Array of the same shape: at each sample, among the two solution sets and all ``2 pi``
        shifts of each angle, the one nearest (sum of squared differences) to the previous
        output sample. Every output sample describes the same rotation as its input. The first
        sample is returned unchanged.

    Note:
        The second solution set is ``(a0 + pi, pi - a1, a2 + pi)`` for Tait-Bryan sequences and
        ``(a0 + pi, -a1, a2 + pi)`` for proper Euler sequences (the MapleSim seed's
        ``a1 +- pi`` and ``a1`` are wrong; see the tests). A middle angle that runs through
        the edge of its principal range therefore continues smoothly past it. Only the sum or
        difference of the outer angles is defined at exact gimbal lock; there the choice
        follows the previous sample, so the output stays continuous if the input sampling
        resolves the motion (steps well below ``pi / 2``). Implemented with ``lax.scan`` and
        no data-dependent branches.
    """
    (a,), dt = as_float(angles)
    check_shape(a, (3,), "angles")
    parse_seq(seq)  # a bad seq raises here, before any array work
    ndim = a.ndim
    if not isinstance(axis, int) or not -ndim <= axis < ndim or axis % ndim == ndim - 1:
        raise ValueError(
            f"axis must index a time axis of angles with shape {a.shape} other than the last "
            f"(the angle axis), got {axis!r}"
        )
    x = jnp.moveaxis(a, axis, 0)
    if x.shape[0] == 0:
        return a.astype(dt)
    two_pi = 2 * np.pi
    # Second solution set: R_i(a0 + pi) R_j(b) R_k(a2 + pi) = R_i(a0) R_j(a1) R_k(a2) needs
    # b = pi - a1 when i != k and b = -a1 when i == k (rotating by pi about e_i flips e_j).
    flip = np.array([1.0, -1.0, 1.0])
    offset = np.array([np.pi, 0.0 if is_proper(seq) else np.pi, np.pi])
    flip, offset = like_rank(flip, x[0]), like_rank(offset, x[0])

    def nearest(c, prev):
        return c + two_pi * jnp.round((prev - c) / two_pi)

    def step(prev, sample):
        c1 = nearest(sample, prev)
        c2 = nearest(offset + flip * sample, prev)
        d1 = jnp.sum((c1 - prev) ** 2, axis=-1, keepdims=True)
        d2 = jnp.sum((c2 - prev) ** 2, axis=-1, keepdims=True)
        out = jnp.where(d2 < d1, c2, c1)
        return out, out

    _, y = jax.lax.scan(step, x[0], x)
    return jnp.moveaxis(y, 0, axis).astype(dt)
