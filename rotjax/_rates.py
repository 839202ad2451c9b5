"""Angular velocity and acceleration against the time derivatives of every representation.

Conventions (see the README's Conventions table):

* `R` is active, `v_world = R @ v_body`; quaternions are scalar last and Hamilton.
* `frame="body"`: the angular velocity in body axes, `omega_body = vee(R.T @ dR/dt)`.
* `frame="world"`: the angular velocity in world axes, `omega_world = vee(dR/dt @ R.T)`
  (the spatial angular-velocity tensor `Omega = dR/dt R^T`, Nikravesh 1988).
  `omega_world = R @ omega_body`.

Euler-angle rates are reduced to one closed form: the *intrinsic* sequence in the *body* frame.
With `R = R_i(a0) R_j(a1) R_k(a2)`, each angle rate spins the body about its own rotation axis
carried into body axes, so

    omega_body = a0' R_k(a2)^T R_j(a1)^T e_i + a1' R_k(a2)^T e_j + a2' e_k
               = R_k(a2)^T M [a0', a1', a2'],   M = [u, e_j, e_k],  u = R_j(a1)^T e_i.

The other three cases map onto it exactly (derived here, checked against autodiff in the tests):

* extrinsic `(i, j, k)` with angles `a` is intrinsic `(k, j, i)` with the angles reversed;
* the world-frame velocity of `R` is minus the body-frame velocity of `R^T`, and `R^T` is
  the intrinsic reversed sequence at the negated, reversed angles; the two sign flips cancel, so
  `E_world(seq, a) = E_body(reversed seq, -reversed a) @ P` with `P` the order reversal.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from ._elementary import reciprocal, sin_cos
from ._euler import parse_seq
from ._numerics import (
    as_float,
    as_part,
    axial,
    cast,
    check_shape,
    cross3,
    from_part,
    from_scalar_last,
    matmul,
    public,
    skew,
    stack,
    stack_matrix,
    sum_squares,
    to_scalar_last,
    unit_scale,
    unstack,
    where,
)
from ._quaternion import quat_conjugate, quat_multiply

FRAMES = ("body", "world")


def check_frame(frame) -> None:
    if frame not in FRAMES:
        raise ValueError(f"frame must be one of {FRAMES}, got {frame!r}")


def _levi_civita(i: int, j: int, k: int) -> int:
    """`epsilon_ijk` for distinct axis indices: +1 for a cyclic order of (x, y, z), else -1."""
    return (i - j) * (j - k) * (k - i) // 2


# --- Euler rate matrices ---------------------------------------------------------------------


def _reduce(seq: str, frame: str):
    """Map `(seq, frame)` to the intrinsic body-frame case.

    Returns:
        `(axes, negate, reverse)`: the intrinsic axes to use, whether the angles are negated,
            and whether the angle order is reversed (the angles on input, the columns of `E` and
            the rows of `E^-1` on output).
    """
    axes, intrinsic = parse_seq(seq)
    check_frame(frame)
    world = frame == "world"
    reverse = intrinsic == world  # intrinsic/world and extrinsic/body reverse the order
    return (axes[::-1] if reverse else axes), world, reverse


def _rate_angles(a, negate: bool, reverse: bool):
    """The three angles of `a` (per-rotation arrays) in the intrinsic body-frame case."""
    parts = unstack(a)[::-1] if reverse else unstack(a)
    return [-x for x in parts] if negate else parts


def _rotate_k_transposed(k: int, angle, v):
    """`R_k(angle)^T @ v` on a list of three component arrays (`R_k`: about axis `k`)."""
    p, r = (k + 1) % 3, (k + 2) % 3  # (k, p, r) is cyclic, R_k turns e_p towards e_r
    s, c = sin_cos(angle)
    out = list(v)
    out[p] = c * v[p] + s * v[r]
    out[r] = c * v[r] - s * v[p]
    return out


def _middle_terms(axes, a1):
    """`(h, g, m, s)` for the middle angle `a1` of intrinsic `axes = (i, j, k)`.

    `u = R_j(a1)^T e_i = cos(a1) e_i + s sin(a1) e_m` with `m` the axis that is neither `i`
    nor `j` and `s = epsilon_ijm`. `h` is the distance to gimbal lock (`cos a1` for
    Tait-Bryan, `sin a1` for proper sequences) and `g = u . e_k` the one off-diagonal entry of
    the Gram matrix `M^T M = [[1, 0, g], [0, 1, 0], [g, 0, 1]]`; `h^2 + g^2 = 1`.
    """
    i, j, k = axes
    m = 3 - i - j
    s = _levi_civita(i, j, m)
    s1, c1 = sin_cos(a1)
    if i == k:  # proper Euler: u . e_k = u . e_i = cos(a1)
        return s1, c1, m, s
    return c1, s * s1, m, s  # Tait-Bryan: m == k, u . e_k = s sin(a1)


def _body_rate_columns(axes, a):
    """The columns of `E` (`omega_body = E @ rates`) for the intrinsic sequence `axes` and
    its angles `a` (per-rotation arrays), each three per-rotation arrays (closed form)."""
    i, j, k = axes
    m = 3 - i - j
    s = _levi_civita(i, j, m)
    _, a1, a2 = a
    zero = jnp.zeros_like(a1)
    one = jnp.ones_like(a1)
    sin1, cos1 = sin_cos(a1)
    u = [zero, zero, zero]
    u[i] = cos1
    u[m] = s * sin1
    e_j = [zero, zero, zero]
    e_j[j] = one
    e_k = [zero, zero, zero]
    e_k[k] = one
    return [_rotate_k_transposed(k, a2, u), _rotate_k_transposed(k, a2, e_j), e_k]


# The rate matrix and the functions of it work on its columns and on components (per-rotation
# arrays): a stacked matrix or vector read back by slices is copied slice by slice by XLA.


def _rate_columns(a, seq, frame):
    """The columns of `E` (in the angle order of `seq`), each three per-rotation arrays."""
    axes, negate, reverse = _reduce(seq, frame)
    cols = _body_rate_columns(axes, _rate_angles(a, negate, reverse))
    return cols[::-1] if reverse else cols


def _apply_columns(cols, x):
    """`E @ x` from the columns of `E` and the components of `x`."""
    return [sum(c[i] * xc for c, xc in zip(cols, x, strict=True)) for i in range(3)]


def _inverse_rates(a, omega, seq, frame, damping):
    """Exact (`damping == 0`) or damped least-squares inverse of the rate matrix (`_rate_columns`).

    With `E = R_k(a2)^T M P` (`P` a permutation) and `v = R_k(a2) omega`, the damped solution
    `(E^T E + d^2 I)^-1 E^T omega = P^T (G + d^2 I)^-1 M^T v` only needs the 2x2 block
    `[[1 + d^2, g], [g, 1 + d^2]]` of `G = M^T M`. Its determinant is written
    `h^2 + d^2 (2 + d^2)` (`1 - g^2 = h^2`), so no cancellation happens near lock, and it is
    at least `2 d^2` everywhere.
    """
    axes, negate, reverse = _reduce(seq, frame)
    i, j, k = axes
    _, a1, a2 = _rate_angles(a, negate, reverse)
    h, g, m, s = _middle_terms(axes, a1)
    v = _rotate_k_transposed(k, -a2, unstack(omega))  # R_k(a2) omega
    # M [x0, x1, x2] = v:  Tait-Bryan  v_i = h x0,        v_k = g x0 + x2;
    #                      proper      s v_m = h x0,      v_i = g x0 + x2.
    A, B = (s * v[m], v[i]) if i == k else (v[i], v[k])
    damped = damping > 0
    # Exact closed form (1/cos or 1/sin of the middle angle). Double where: where the damped
    # branch is selected, h may be 0 and A / h would send NaN into its gradient.
    h_safe = where(damped, 1.0, h)
    x0_exact = A / h_safe
    x2_exact = B - g * x0_exact
    d2 = damping * damping
    den = where(damped, h * h + d2 * (2 + d2), 1.0)  # > 0 where used
    x0_damped = ((1 + d2) * h * A + d2 * g * B) / den
    x2_damped = ((h * h + d2) * B - g * h * A) / den
    x0 = where(damped, x0_damped, x0_exact)
    x1 = v[j] / (1 + d2)
    x2 = where(damped, x2_damped, x2_exact)
    return stack([x2, x1, x0] if reverse else [x0, x1, x2])


@public
def euler_rate_matrix(angles: ArrayLike, seq: str, frame: str = "body") -> Array:
    """Matrix `E` that maps Euler-angle rates to angular velocity: `omega = E @ rates`.

    Args:
        angles: `(..., 3)` Euler angles in radians, in the order of `seq`; any values.
        seq: axis sequence: `"XYZ"`-style intrinsic, `"xyz"`-style extrinsic or digits
            `"123"` (intrinsic); see [`euler_to_quaternion`][rotjax.euler_to_quaternion].
        frame: `"body"` (`omega = vee(R.T @ dR/dt)`, components in body axes) or
            `"world"` (`omega = vee(dR/dt @ R.T)`, components in world axes).

    Returns:
        `(..., 3, 3)` matrix whose column `n` is the rotation axis of angle `n` expressed
            in `frame`. For intrinsic `"ZXZ"` in the body frame this is Nikravesh's Eq. (A.3),
            for intrinsic `"XYZ"` the corrected Eq. (A.7).

    Note:
        `E` is smooth everywhere. Its determinant is `+-cos(a1)` for Tait-Bryan sequences and
        `+-sin(a1)` for proper Euler sequences (`a1` the middle angle): it is singular at
        gimbal lock, where the first and third axes coincide.

    Examples:
        ```python
        import rotjax as rj

        E = rj.euler_rate_matrix([0.0, 0.0, 0.0], "ZYX")  # yaw, pitch, roll at zero
        print(E)
        # [[-0.  0.  1.]
        #  [ 0.  1.  0.]
        #  [ 1.  0.  0.]]
        ```
    """
    (a,), dt = as_float(angles)
    check_shape(a, (3,), "angles")
    cols = _rate_columns(a, seq, frame)
    return cast(stack_matrix([[c[r] for c in cols] for r in range(3)]), dt)


@public
def euler_rates_to_angular_velocity(
    angles: ArrayLike, rates: ArrayLike, seq: str, frame: str = "body"
) -> Array:
    """Angular velocity of a body whose Euler angles change at `rates`.

    Args:
        angles: `(..., 3)` Euler angles in radians, in the order of `seq`.
        rates: `(..., 3)` angle rates (rad per unit time); broadcasts against `angles`.
        seq: axis sequence; see [`euler_rate_matrix`][rotjax.euler_rate_matrix].
        frame: `"body"` (`omega = vee(R.T @ dR/dt)`, components in body axes) or
            `"world"` (`omega = vee(dR/dt @ R.T)`, components in world axes).

    Returns:
        `(..., 3)` angular velocity `euler_rate_matrix(angles, seq, frame) @ rates`. Smooth
            and finite everywhere, gimbal lock included.

    Examples:
        ```python
        import rotjax as rj

        omega = rj.euler_rates_to_angular_velocity([0.3, 0.2, 0.1], [0.0, 0.0, 1.0], "ZYX")
        print(omega.round(6))  # the roll rate turns the body about its own x axis
        # [1. 0. 0.]
        ```
    """
    (a, r), dt = as_float(angles, rates)
    check_shape(a, (3,), "angles")
    check_shape(r, (3,), "rates")
    return cast(stack(_apply_columns(_rate_columns(a, seq, frame), unstack(r))), dt)


@public
def angular_velocity_to_euler_rates(
    angles: ArrayLike, omega: ArrayLike, seq: str, frame: str = "body", damping: ArrayLike = 0.0
) -> Array:
    """Euler-angle rates that produce the angular velocity `omega`.

    Args:
        angles: `(..., 3)` Euler angles in radians, in the order of `seq`.
        omega: `(..., 3)` angular velocity in `frame`; broadcasts against `angles`.
        seq: axis sequence; see [`euler_rate_matrix`][rotjax.euler_rate_matrix].
        frame: `"body"` (`omega = vee(R.T @ dR/dt)`, components in body axes) or
            `"world"` (`omega = vee(dR/dt @ R.T)`, components in world axes).
        damping: `(...)` non-negative damping `d`, traced (it may vary inside a compiled
            loop). `0` gives the exact inverse `E^-1 @ omega` in closed form (a `1/cos` of
            the middle angle for Tait-Bryan sequences, `1/sin` for proper ones, as Nikravesh
            Eqs. A.4 and A.8). `d > 0` gives the damped least-squares solution
            `(E^T E + d^2 I)^-1 E^T omega`, which differs from the exact one by `O(d^2)`
            away from lock.

    Returns:
        `(..., 3)` angle rates.

    Note:
        *At gimbal lock with* `damping=0` the rates do not exist (only the sum or difference
        of the outer rates is defined, and an `omega` with a component along the missing
        direction cannot be produced at all): the result is non-finite (`inf` or `nan`),
        and near lock it grows like `1/euler_singularity`. With `damping > 0` the result is
        finite everywhere with finite gradients; at lock it is the minimum-norm least-squares
        solution shrunk by the damping. A common pattern is to switch on damping inside a jitted
        loop with `jnp.where(euler_singularity(angles, seq) < tol, d, 0.0)`.

    Examples:
        ```python
        import rotjax as rj

        angles = [0.3, 0.2, 0.1]
        omega = rj.euler_rates_to_angular_velocity(angles, [0.5, -0.2, 1.0], "ZYX")
        print(rj.angular_velocity_to_euler_rates(angles, omega, "ZYX").round(6))
        # [ 0.5 -0.2  1. ]
        ```
    """
    (a, w), dt = as_float(angles, omega)
    check_shape(a, (3,), "angles")
    check_shape(w, (3,), "omega")
    d = as_part(jnp.asarray(damping).astype(a.dtype))
    return cast(_inverse_rates(a, w, seq, frame, d), dt)


@public
def euler_singularity(angles: ArrayLike, seq: str) -> Array:
    """Distance to gimbal lock: `|cos(a1)|` (Tait-Bryan) or `|sin(a1)|` (proper Euler).

    Args:
        angles: `(..., 3)` Euler angles in radians, in the order of `seq`.
        seq: axis sequence; see [`euler_rate_matrix`][rotjax.euler_rate_matrix].

    Returns:
        `(...)` value in `[0, 1]`: `|det E|` of [`euler_rate_matrix`][rotjax.euler_rate_matrix] in
            either frame; 0 exactly at gimbal lock, 1 when the first and third axes are
            perpendicular. Branch-free, so it can drive a `jnp.where` inside `jit` or `lax.scan`.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        print(rj.euler_singularity([0.0, jnp.pi / 2, 0.0], "ZYX").round(6))  # pitch 90 deg: lock
        # 0.0
        print(rj.euler_singularity([0.0, 0.0, 0.0], "ZYX"))
        # 1.0
        ```
    """
    (a,), dt = as_float(angles)
    check_shape(a, (3,), "angles")
    axes, _ = parse_seq(seq)
    h, _, _, _ = _middle_terms(axes, unstack(a)[1])
    return cast(from_part(jnp.abs(h)), dt)


# --- quaternion and matrix derivatives ---------------------------------------------------------


def _pure(omega):
    return jnp.concatenate([omega, jnp.zeros_like(omega[..., :1])], axis=-1)


def quat_rate(q, omega, frame):
    # body: q' = q * (omega_b, 0) / 2;  world: q' = (omega_w, 0) * q / 2  (R(p q) = R(p) R(q)).
    # "q_v' = (q_s w - q_v x w) / 2" (Markley & Crassidis 2014) is the world-frame form.
    w = _pure(omega)
    product = quat_multiply(q, w) if frame == "body" else quat_multiply(w, q)
    return stack([0.5 * x for x in unstack(product)])  # its parts, for a reader (see stack)


@public
def quaternion_derivative(
    q: ArrayLike, omega: ArrayLike, frame: str = "body", scalar_first: bool = False
) -> Array:
    """Time derivative of a quaternion rotating at angular velocity `omega`.

    Args:
        q: `(..., 4)` quaternion, scalar last unless `scalar_first`; need not be unit.
        omega: `(..., 3)` angular velocity in `frame`; broadcasts against `q`.
        frame: `"body"` (`q' = q * (omega, 0) / 2`) or `"world"`
            (`q' = (omega, 0) * q / 2`), Hamilton products.
        scalar_first: `q` (and the result) are `(w, x, y, z)`.

    Returns:
        `(..., 4)` `dq/dt`, in the layout of `q`. It is orthogonal to `q`, so the norm of
            `q` is preserved; for a non-unit `q` it is the derivative of `|q| q_unit(t)`.
            Bilinear in `q` and `omega`: no singularity.

    Examples:
        ```python
        import rotjax as rj

        q = [0.0, 0.0, 0.0, 1.0]
        print(rj.quaternion_derivative(q, [0.0, 0.0, 2.0]))  # 2 rad/s about z
        # [0. 0. 1. 0.]
        ```
    """
    (q, w), dt = as_float(q, omega)
    check_shape(q, (4,), "q")
    check_shape(w, (3,), "omega")
    check_frame(frame)
    qd = quat_rate(to_scalar_last(q, scalar_first), w, frame)
    return cast(from_scalar_last(qd, scalar_first), dt)


@public
def quaternion_derivative_to_angular_velocity(
    q: ArrayLike, q_dot: ArrayLike, frame: str = "body", scalar_first: bool = False
) -> Array:
    """Angular velocity from a quaternion and its time derivative.

    Args:
        q: `(..., 4)` quaternion; need not be unit (must be non-zero).
        q_dot: `(..., 4)` its time derivative, same layout; broadcasts against `q`.
        frame: `"body"` (`omega = 2 vec(conj(q) * q') / |q|^2`) or `"world"`
            (`omega = 2 vec(q' * conj(q)) / |q|^2`).
        scalar_first: quaternions are `(w, x, y, z)`.

    Returns:
        `(..., 3)` angular velocity in `frame`. A component of `q_dot` along `q` (a
            change of norm) lands in the scalar part and is ignored, so the result is exact for a
            quaternion of varying norm. The zero quaternion gives NaN.

    Examples:
        ```python
        import rotjax as rj

        q = rj.rotvec_to_quaternion([0.1, 0.2, 0.3])
        q_dot = rj.quaternion_derivative(q, [1.0, -2.0, 0.5])
        print(rj.quaternion_derivative_to_angular_velocity(q, q_dot).round(6))
        # [ 1.  -2.   0.5]
        ```
    """
    (q, qd), dt = as_float(q, q_dot)
    check_shape(q, (4,), "q")
    check_shape(qd, (4,), "q_dot")
    check_frame(frame)
    q = to_scalar_last(q, scalar_first)
    qd = to_scalar_last(qd, scalar_first)
    # omega is homogeneous of degree 0 in (q, q_dot): both scaled by the power of two that
    # brings q's largest component into [0.5, 2) (exact; 1 for a unit q), so that |q|^2 can
    # neither underflow nor overflow.
    # On components, the reciprocal of |q|^2 (in [1/4, 16)) by multiplications: a division
    # read by the three components, or a stacked intermediate read back, is a loop of its own.
    # NaN for the zero quaternion or a non-finite component (through the scale's mark).
    qp, qdp = unstack(q), unstack(qd)
    s = unit_scale(*qp, mark=True)
    qp, qdp = [x * s for x in qp], [x * s for x in qdp]
    qc, qd = quat_conjugate(stack(qp)), stack(qdp)
    prod = unstack(quat_multiply(qc, qd) if frame == "body" else quat_multiply(qd, qc))
    r = 2 * reciprocal(sum_squares(qp))
    return cast(stack([c * r for c in prod[:3]]), dt)


@public
def matrix_derivative_to_angular_velocity(
    R: ArrayLike, R_dot: ArrayLike, frame: str = "body"
) -> Array:
    """Angular velocity from a rotation matrix and its time derivative.

    Args:
        R: `(..., 3, 3)` active rotation matrix.
        R_dot: `(..., 3, 3)` its time derivative; broadcasts against `R`.
        frame: `"body"` (`omega = vee(R.T @ R_dot)`) or `"world"`
            (`omega = vee(R_dot @ R.T)`, the spatial angular-velocity tensor `Omega = dR/dt R^T`).

    Returns:
        `(..., 3)` angular velocity in `frame`. `vee` reads the antisymmetric part, so a
            `R_dot` slightly off the tangent space is projected onto it. No singularity.

    Examples:
        ```python
        import rotjax as rj

        R = rj.rotvec_to_matrix([0.1, 0.2, 0.3])
        R_dot = rj.angular_velocity_to_matrix_derivative(R, [1.0, -2.0, 0.5])
        print(rj.matrix_derivative_to_angular_velocity(R, R_dot).round(6))
        # [ 1.  -2.   0.5]
        ```
    """
    (R, Rd), dt = as_float(R, R_dot)
    check_shape(R, (3, 3), "R")
    check_shape(Rd, (3, 3), "R_dot")
    check_frame(frame)
    Rt = jnp.swapaxes(R, -1, -2)
    return cast(axial(matmul(Rt, Rd) if frame == "body" else matmul(Rd, Rt)), dt)


@public
def angular_velocity_to_matrix_derivative(
    R: ArrayLike, omega: ArrayLike, frame: str = "body"
) -> Array:
    """Time derivative of a rotation matrix turning at angular velocity `omega`.

    Args:
        R: `(..., 3, 3)` active rotation matrix.
        omega: `(..., 3)` angular velocity in `frame`; broadcasts against `R`.
        frame: `"body"` (`R_dot = R @ hat(omega)`) or `"world"`
            (`R_dot = hat(omega) @ R`).

    Returns:
        `(..., 3, 3)` `dR/dt`. Linear in `omega`: no singularity.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        print(rj.angular_velocity_to_matrix_derivative(jnp.eye(3), [0.0, 0.0, 1.0]))
        # [[ 0. -1.  0.]
        #  [ 1.  0.  0.]
        #  [ 0.  0.  0.]]
        ```
    """
    (R, w), dt = as_float(R, omega)
    check_shape(R, (3, 3), "R")
    check_shape(w, (3,), "omega")
    check_frame(frame)
    W = skew(w)
    return cast((matmul(R, W) if frame == "body" else matmul(W, R)), dt)


# --- Euler-angle accelerations -----------------------------------------------------------------


def _rate_derivative_terms(c, r, seq):
    """`(dE/dt) @ rates` from the columns `c_n` of `E` (either frame) and the rates `r`, as
    components (per-rotation arrays).

    Write `R` as the product of its three elementary rotations, outermost first (angle order
    for an intrinsic `seq`, reversed for an extrinsic one). A column belonging to an inner
    factor turns with the angular velocity of the factors outside it, so
    `dc_inner/dt = sum_outer a_outer' c_outer x c_inner` in both frames (in the body frame the
    outer factors turn the inner axes the opposite way, as seen from the body, and the cross
    product order makes up for it). Hence
    `(dE/dt) a' = sum_{outer < inner} a_outer' a_inner' (c_outer x c_inner)`: for angle order
    `(0, 1, 2)` the pairs `(0, 1), (0, 2), (1, 2)` with sign `+1` (intrinsic) or `-1`
    (extrinsic, where the outer factor of each pair is the later angle).
    """
    _, intrinsic = parse_seq(seq)
    sign = 1.0 if intrinsic else -1.0
    pairs = [(r[m] * r[n], cross3(c[m], c[n])) for m, n in ((0, 1), (0, 2), (1, 2))]
    return [sign * sum(w * x[i] for w, x in pairs) for i in range(3)]


@public
def euler_accelerations_to_angular_acceleration(
    angles: ArrayLike, rates: ArrayLike, accelerations: ArrayLike, seq: str, frame: str = "body"
) -> Array:
    """Angular acceleration of a body whose Euler angles move with the given rates and
    accelerations.

    Args:
        angles: `(..., 3)` Euler angles in radians, in the order of `seq`.
        rates: `(..., 3)` angle rates (rad per unit time).
        accelerations: `(..., 3)` angle accelerations (rad per unit time squared). The three
            arrays broadcast against each other.
        seq: axis sequence; see [`euler_rate_matrix`][rotjax.euler_rate_matrix].
        frame: `"body"`: `alpha = d/dt omega_body`, components in body axes; `"world"`:
            `alpha = d/dt omega_world`, components in world axes. The two are related by
            `alpha_world = R @ alpha_body` (the term `dR/dt @ omega_body` vanishes, as
            `omega x omega = 0`).

    Returns:
        `(..., 3)` `alpha = E(a) @ a'' + (dE/dt) @ a'`, with `E` the
            [`euler_rate_matrix`][rotjax.euler_rate_matrix] and `(dE/dt) a'` in closed form: the sum
            over the pairs of elementary rotations of `outer rate * inner rate * (c_outer x
            c_inner)` (`c` the columns of `E`). Smooth and finite everywhere, gimbal lock included.

    Examples:
        ```python
        import rotjax as rj

        alpha = rj.euler_accelerations_to_angular_acceleration(
            [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0], "ZYX"
        )
        print(alpha.round(6))  # constant yaw rate at zero pitch and roll: no acceleration
        # [0. 0. 0.]
        ```
    """
    (a, r, acc), dt = as_float(angles, rates, accelerations)
    check_shape(a, (3,), "angles")
    check_shape(r, (3,), "rates")
    check_shape(acc, (3,), "accelerations")
    cols, rates = _rate_columns(a, seq, frame), unstack(r)
    terms = _rate_derivative_terms(cols, rates, seq)
    out = [x + y for x, y in zip(_apply_columns(cols, unstack(acc)), terms, strict=True)]
    return cast(stack(out), dt)


@public
def angular_acceleration_to_euler_accelerations(
    angles: ArrayLike,
    rates: ArrayLike,
    alpha: ArrayLike,
    seq: str,
    frame: str = "body",
    damping: ArrayLike = 0.0,
) -> Array:
    """Euler-angle accelerations that produce the angular acceleration `alpha`.

    Args:
        angles: `(..., 3)` Euler angles in radians, in the order of `seq`.
        rates: `(..., 3)` angle rates (rad per unit time).
        alpha: `(..., 3)` angular acceleration in `frame` (see
            [`euler_accelerations_to_angular_acceleration`][rotjax.euler_accelerations_to_angular_acceleration]).
            The three arrays broadcast.
        seq: axis sequence; see [`euler_rate_matrix`][rotjax.euler_rate_matrix].
        frame: `"body"` or `"world"`.
        damping: `(...)` non-negative damping `d`, traced, as in
            [`angular_velocity_to_euler_rates`][rotjax.angular_velocity_to_euler_rates]: `0` gives
            the exact `E^-1 (alpha - (dE/dt) a')`, `d > 0` the damped least-squares solution of `E
            a'' = alpha - (dE/dt) a'`.

    Returns:
        `(..., 3)` angle accelerations (rad per unit time squared).

    Note:
        *At gimbal lock with* `damping=0` the result is non-finite, and near lock it grows
        like `1/euler_singularity` (for the part of `alpha` the angles cannot follow).
        With `damping > 0` it is finite everywhere, with finite gradients.

    Examples:
        ```python
        import rotjax as rj

        angles, rates = [0.3, 0.2, 0.1], [0.5, -0.2, 1.0]
        acc = [0.1, 0.2, 0.3]
        alpha = rj.euler_accelerations_to_angular_acceleration(angles, rates, acc, "ZYX")
        print(rj.angular_acceleration_to_euler_accelerations(angles, rates, alpha, "ZYX").round(6))
        # [0.1 0.2 0.3]
        ```
    """
    (a, r, al), dt = as_float(angles, rates, alpha)
    check_shape(a, (3,), "angles")
    check_shape(r, (3,), "rates")
    check_shape(al, (3,), "alpha")
    d = as_part(jnp.asarray(damping).astype(a.dtype))
    terms = _rate_derivative_terms(_rate_columns(a, seq, frame), unstack(r), seq)
    rhs = stack([x - y for x, y in zip(unstack(al), terms, strict=True)])
    return cast(_inverse_rates(a, rhs, seq, frame, d), dt)
