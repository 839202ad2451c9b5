"""Rotation vectors and axis-angle pairs (exponential and logarithm maps)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.typing import ArrayLike

from ._matrix import _from_matrix
from ._numerics import (
    as_float,
    cast,
    check_shape,
    eps,
    exponent_scale,
    from_scalar_last,
    hat,
    like_rank,
    matmul,
    public,
    rsqrt,
    safe_norm,
    select,
    stack,
    to_scalar_last,
    unstack,
)
from ._quaternion import _angle, _prescaled, _scaled_vector_part


def _small(x2):
    """Below this squared argument the Taylor branch is exact to rounding (dtype dependent)."""
    return x2 < eps(x2.dtype) ** 0.5


# pi/2 in three parts (Cody & Waite): the first two have few enough bits that their products
# with the quadrant count j are exact (j < 2^12 in float32, 2^27 in float64), the third is the
# rounded rest.
_PIO2 = {
    4: (1.57080078125, -4.453584551811218e-06, -8.705515752716053e-10),
    8: (1.5707963407039642, -1.3909067675399456e-08, 6.123233995736766e-17),
}
# sin(r) = r + r s P(s) and cos(r) = 1 - s/2 + s^2 Q(s), s = r^2 <= (pi/4)^2: Chebyshev fits
# (mpmath.chebyfit, 50 digits) of (sin(r)/r - 1)/s and (cos(r) - 1 + s/2)/s^2, highest power
# first; the error of sin and cos is below 0.1 eps (float32: 1.2e-8, 7.6e-10; float64: 1.3e-17,
# 4.9e-19).
_SIN_P = {
    4: (-0.00019587890880412386, 0.008332748270629749, -0.1666666466231438),
    8: (
        1.5918129294866608e-10, -2.5051131845003624e-08, 2.755731610255244e-06,
        -0.00019841269836758574, 0.008333333333330948, -0.16666666666666666,
    ),
}  # fmt: skip
_COS_Q = {
    4: (2.4547942085071572e-05, -0.0013888303035894866, 0.04166666465950221),
    8: (
        -1.1382632425521717e-11, 2.08761462684032e-09, -2.7557317271729793e-07,
        2.480158729876569e-05, -0.0013888888888887398, 0.041666666666666664,
    ),
}  # fmt: skip


def _horner(coeffs, s):
    p = jnp.full_like(s, coeffs[0])
    for c in coeffs[1:]:
        p = p * s + c
    return p


def _sin_cos(a):
    """`(sin a, cos a)` from multiplications, additions and selects: `a` reduced by the
    nearest multiple `j pi/2` (exact for `|a|` below 6e3 in float32 and 2e8 in float64), the
    polynomials above on the rest, and the quadrant `j mod 4` chosen by `jnp.where`. XLA fuses
    this into the loop of its consumers (it keeps `jnp.sin` and `jnp.cos`, expensive, in
    loops of their own when their result is read more than once)."""
    size = jnp.dtype(a.dtype).itemsize
    j = jnp.round(a * (2 / np.pi))
    p1, p2, p3 = _PIO2[size]
    r = ((a - j * p1) - j * p2) - j * p3
    s = r * r
    sin_r = r + r * (s * _horner(_SIN_P[size], s))
    cos_r = (1 - 0.5 * s) + (s * s) * _horner(_COS_Q[size], s)
    quadrant = j - 4 * jnp.floor(0.25 * j)  # 0, 1, 2, 3 (exact)
    odd = (quadrant == 1) | (quadrant == 3)
    sin_a = jnp.where(odd, cos_r, sin_r)
    cos_a = jnp.where(odd, sin_r, cos_r)
    sin_a = jnp.where(quadrant >= 2, -sin_a, sin_a)
    cos_a = jnp.where((quadrant == 1) | (quadrant == 2), -cos_a, cos_a)
    return sin_a, cos_a


def _exp_coeffs(theta2):
    """`sin(t/2)/t` and `cos(t/2)` for `t = sqrt(theta2)`, smooth at 0 (double where).

    Multiplications, additions and selects only (`rsqrt`, `_sin_cos`), so that a conversion
    built on them is one fused loop."""
    small = _small(theta2)
    safe = jnp.where(small, 1.0, theta2)  # any non-zero value keeps the gradient finite
    inv_t = rsqrt(safe)
    t = safe * inv_t
    t = t + (0.5 * inv_t) * (safe - t * t)  # one Newton step for sqrt: t to about 0.5 ulp
    sin_h, cos_h = _sin_cos(0.5 * t)
    k = jnp.where(small, 0.5 - theta2 / 48 + theta2 * theta2 / 3840, sin_h * inv_t)
    c = jnp.where(small, 1 - theta2 / 8 + theta2 * theta2 / 384, cos_h)
    return k, c


def _rotvec_to_quat(v):
    """`(k v, c)` with `k, c = _exp_coeffs(|v|^2)`: the exponential map, scalar last."""
    return stack(_rotvec_to_quat_parts(tuple(unstack(v))))


@jax.custom_jvp
def _rotvec_to_quat_parts(v):
    x, y, z = v
    k, c = _exp_coeffs(x * x + y * y + z * z)
    return k * x, k * y, k * z, c


@_rotvec_to_quat_parts.defjvp
def _rotvec_to_quat_parts_jvp(primals, tangents):
    # JAX's derivative of the code above, grouped: d(k v) = k dv + v dk and dc, with
    # dk = 2 k' (v . dv), dc = 2 c' (v . dv) and k', c' JAX's derivatives of _exp_coeffs,
    # computed once per rotation (JAX's own transpose of the code above was a scalar loop in
    # float64: a function outlined per component).
    (v,), ((dx, dy, dz),) = primals, tangents
    x, y, z = v
    t2 = x * x + y * y + z * z
    (k, c), (dk2, dc2) = jax.jvp(_exp_coeffs, (t2,), (2 * jnp.ones_like(t2),))
    vd = x * dx + y * dy + z * dz
    dk = dk2 * vd
    out = (k * dx + x * dk, k * dy + y * dk, k * dz + z * dk, dc2 * vd)
    return (k * x, k * y, k * z, c), out


# f(u) = atan(sqrt(u)) / sqrt(u) on [0, 1]: Chebyshev fits (mpmath.chebyfit at 40 digits) of
# degree 9 for float32 and 20 for float64, highest power first; max error 2.8e-9 and 5.4e-18.
_ATAN_RATIO = {
    4: (
        -0.0017011700640685973, 0.010487649254949306, -0.030351864785781172, 0.05708955593030619,
        -0.08349724968301601, 0.10932341501303093, -0.14260016082820906, 0.19998075281148714,
        -0.3333327629198255, 0.9999999971605454,
    ),
    8: (
        1.2631178430477426e-05, -0.00014617088163625013, 0.0008033604181626027,
        -0.0028047655531701315, 0.007038646202989813, -0.013674139288399478,
        0.021740213830758134, -0.02970071773623423, 0.03651081352721035, -0.042125723963855326,
        0.04719723992321112, -0.052527255573225747, 0.05880342002401543, -0.06666371187721098,
        0.0769227555520563, -0.09090906605656898, 0.11111110982087126, -0.14285714281592693,
        0.19999999999929946, -0.3333333333333286, 1.0,
    ),
}  # fmt: skip


@jax.custom_jvp
def _atan_ratio(u):
    """`atan(t) / t` for `u = t^2` in `[0, 1]`: the polynomial `_ATAN_RATIO`. Its derivative is
    that of the same polynomial, evaluated as one (a second Horner loop on the derivative's
    coefficients rather than JAX's transpose of the first, which is longer code)."""
    return _horner(_ATAN_RATIO[jnp.dtype(u.dtype).itemsize], u)


@_atan_ratio.defjvp
def _atan_ratio_jvp(primals, tangents):
    (u,), (du,) = primals, tangents
    coeffs = _ATAN_RATIO[jnp.dtype(u.dtype).itemsize]
    top = len(coeffs) - 1
    slope = _horner([c * (top - i) for i, c in enumerate(coeffs[:-1])], u)
    return _atan_ratio(u), slope * du


def _rotvec_scale(n2, w):
    """`k = 2 atan2(n, |w|) / n` (sign of `w` included, so that the angle is in [0, pi]) from
    `n^2 = |q_v|^2` and `w` of a prescaled quaternion: the rotation vector is `k q_v`.

    Without a root of ``n``, an atan2 or a division: with ``m`` the larger and ``l`` the
    smaller of ``n``, ``|w|`` (``m^2 >= 1/8`` after the prescaling: rsqrt's domain) and
    ``u = l^2 / m^2``, ``atan(l / m) = (l / m) f(u)`` with the polynomial ``f`` above; it is
    the angle's half where ``n <= |w|``, else its complement to ``pi/2``. Smooth in ``n^2`` at
    the identity (``d rotvec / d q_v = 2 I`` for a unit ``q``).
    """
    sign = select(w < 0, -1.0, 1.0, w.dtype)  # w >= 0 gives the angle in [0, pi]
    aw = sign * w
    w2 = aw * aw
    near = n2 <= w2
    inv_m = rsqrt(jnp.where(near, w2, n2))
    u = jnp.where(near, n2, w2) * (inv_m * inv_m)
    f = _atan_ratio(u)
    half = jnp.where(near, f, 0.5 * np.pi - aw * inv_m * f)  # atan2(n, |w|) * m / m
    return (2 * sign) * inv_m * half


def _quat_to_rotvec(q):
    """Logarithm map of a scalar-last quaternion of any finite non-zero norm; angle in
    [0, pi] (see `_rotvec_scale`): one vectorised loop, forward and reverse."""
    return _scaled_vector_part(q, _rotvec_scale, False)


@public
def rotvec_to_quaternion(
    rotvec: ArrayLike, degrees: bool = False, scalar_first: bool = False
) -> Array:
    """Exponential map: rotation vector `theta * axis` to a unit quaternion.

    Args:
        rotvec: `(..., 3)` rotation vector; its norm is the angle (any size) and its direction
            the axis (right-hand rule).
        degrees: the norm of `rotvec` is in degrees.
        scalar_first: return `(w, x, y, z)`.

    Returns:
        `(..., 4)` unit quaternion `(sin(t/2) axis, cos(t/2))`. `w` is negative for angles
            above pi; no hemisphere is imposed, so the map is smooth everywhere.

    Note:
        Smooth at the zero vector, where a Taylor branch (double where) gives the exact
        derivative `d q_v / d rotvec = I / 2`.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        print(rj.rotvec_to_quaternion([0.0, 0.0, jnp.pi / 2]).round(6))  # 90 deg about z
        # [0.       0.       0.707107 0.707107]
        print(rj.rotvec_to_quaternion([0.0, 0.0, 90.0], degrees=True, scalar_first=True).round(6))
        # [0.707107 0.       0.       0.707107]
        ```
    """
    (v,), dt = as_float(rotvec)
    check_shape(v, (3,), "rotvec")
    if degrees:
        v = jnp.deg2rad(v)
    return cast(from_scalar_last(_rotvec_to_quat(v), scalar_first), dt)


@public
def quaternion_to_rotvec(q: ArrayLike, degrees: bool = False, scalar_first: bool = False) -> Array:
    """Logarithm map: unit quaternion to the rotation vector of angle in `[0, pi]`.

    Args:
        q: `(..., 4)` quaternion; need not be unit (zero gives NaN).
        degrees: return the vector with its norm in degrees.
        scalar_first: `q` is `(w, x, y, z)`.

    Returns:
        `(..., 3)` rotation vector with norm in `[0, pi]` (or `[0, 180]`).

    Note:
        Uses `2 atan2(|q_v|, |w|) / |q_v|` with a Taylor branch near the identity, so the
        derivative there is exact: `d rotvec / d q_v = 2 I` for a unit `q`. At exactly
        180 degrees both `v` and `-v` are valid; the one from the sign of `q_v` after
        choosing `w >= 0` is returned, and the map jumps there (it must: the log has a cut).

    Examples:
        ```python
        import rotjax as rj

        print(rj.quaternion_to_rotvec([0.0, 0.0, 0.70710678, 0.70710678], degrees=True))
        # [ 0.  0. 90.]
        print(rj.quaternion_to_rotvec([0.0, 0.0, 0.0, 1.0]))  # identity: exactly zero
        # [0. 0. 0.]
        ```
    """
    (q,), dt = as_float(q)
    check_shape(q, (4,), "q")
    v = _quat_to_rotvec(to_scalar_last(q, scalar_first))
    if degrees:
        v = jnp.rad2deg(v)
    return cast(v, dt)


@public
def rotvec_to_matrix(rotvec: ArrayLike, degrees: bool = False) -> Array:
    """Rodrigues formula: rotation vector to an active rotation matrix.

    Args:
        rotvec: `(..., 3)` rotation vector (angle = norm, any size).
        degrees: the norm is in degrees.

    Returns:
        `(..., 3, 3)` rotation matrix `I + sin(t)/t K + (1 - cos t)/t^2 K^2` with
            `K = hat(rotvec)`.

    Note:
        `(1 - cos t)` is evaluated as `2 sin^2(t/2)` (no cancellation), and both coefficients
        have Taylor branches at 0, so values and gradients are exact at the zero vector.

    Examples:
        ```python
        import rotjax as rj

        print(rj.rotvec_to_matrix([90.0, 0.0, 0.0], degrees=True).round(6))
        # [[ 1.  0.  0.]
        #  [ 0. -0. -1.]
        #  [ 0.  1. -0.]]
        ```
    """
    (v,), dt = as_float(rotvec)
    check_shape(v, (3,), "rotvec")
    if degrees:
        v = jnp.deg2rad(v)
    k, c = _exp_coeffs(jnp.sum(v * v, axis=-1))
    # sin(t)/t = 2 k c and (1 - cos t)/t^2 = 2 k^2, both smooth in theta^2.
    a = (2 * k * c)[..., None, None]
    b = (2 * k * k)[..., None, None]
    K = hat(v)
    eye = like_rank(jnp.eye(3, dtype=v.dtype), K)
    return cast((eye + a * K + b * matmul(K, K)), dt)


@public
def matrix_to_rotvec(R: ArrayLike, degrees: bool = False) -> Array:
    """Logarithm of a rotation matrix, via the branch-free quaternion extraction.

    Args:
        R: `(..., 3, 3)` active rotation matrix.
        degrees: return the norm in degrees.

    Returns:
        `(..., 3)` rotation vector with norm in `[0, pi]`.

    Note:
        Going through [`matrix_to_quaternion`][rotjax.matrix_to_quaternion] keeps full
        accuracy at 180 degrees, where `acos((trace - 1) / 2)` formulas lose half the digits
        and the axis from the antisymmetric part vanishes. Scale invariant and NaN for
        non-rotations like it, and the gradient is the derivative of the function computed,
        off SO(3) too.

    Examples:
        ```python
        import rotjax as rj

        R = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]  # 90 deg about z
        print(rj.matrix_to_rotvec(R, degrees=True))
        # [ 0.  0. 90.]
        ```
    """
    (R,), dt = as_float(R)
    check_shape(R, (3, 3), "R")
    v = _quat_to_rotvec(_from_matrix(R, "shepperd"))
    if degrees:
        v = jnp.rad2deg(v)
    return cast(v, dt)


@public
def axis_angle_to_quaternion(
    axis: ArrayLike, angle: ArrayLike, degrees: bool = False, scalar_first: bool = False
) -> Array:
    """Quaternion of a rotation by `angle` about `axis`.

    Args:
        axis: `(..., 3)` rotation axis; need not be unit (the zero axis gives NaN).
        angle: `(...)` angle (right-hand rule); broadcasts against `axis[..., 0]`.
        degrees: `angle` is in degrees.
        scalar_first: return `(w, x, y, z)`.

    Returns:
        `(..., 4)` unit quaternion `(sin(angle/2) n, cos(angle/2))`, `n = axis / |axis|`.

    Examples:
        ```python
        import rotjax as rj

        print(rj.axis_angle_to_quaternion([0.0, 0.0, 2.0], 90.0, degrees=True).round(6))
        # [0.       0.       0.707107 0.707107]
        ```
    """
    (axis, angle), dt = as_float(axis, angle)
    check_shape(axis, (3,), "axis")
    if degrees:
        angle = jnp.deg2rad(angle)
    batch = jnp.broadcast_shapes(axis.shape[:-1], angle.shape)
    n = jnp.broadcast_to(axis / jnp.sqrt(jnp.sum(axis * axis, axis=-1, keepdims=True)), (*batch, 3))
    half = jnp.broadcast_to(angle, batch)[..., None] / 2
    q = jnp.concatenate([jnp.sin(half) * n, jnp.cos(half)], axis=-1)
    return cast(from_scalar_last(q, scalar_first), dt)


@public
def quaternion_to_axis_angle(
    q: ArrayLike, degrees: bool = False, scalar_first: bool = False
) -> tuple[Array, Array]:
    """Axis and angle of a quaternion, with the angle in `[0, pi]`.

    Args:
        q: `(..., 4)` quaternion; need not be unit (zero gives NaN).
        degrees: return the angle in degrees.
        scalar_first: `q` is `(w, x, y, z)`.

    Returns:
        axis: `(..., 3)` unit axis.
        angle: `(...)` angle in `[0, pi]` (or `[0, 180]` with `degrees`).

    Note:
        At the identity the axis is undefined; `(1, 0, 0)` is returned, with a zero gradient
        (finite, by the double where). A tiny but non-zero vector part (`1e-160` next to
        `w = 1`) gives its own direction: it is scaled by a power of two before its norm is
        taken. Any finite non-zero scale of `q` gives the same result. The angle uses atan2
        (see [`rotation_angle`][rotjax.rotation_angle]).

    Examples:
        ```python
        import rotjax as rj

        axis, angle = rj.quaternion_to_axis_angle([0.0, 0.0, -1.0, 1.0], degrees=True)
        print(axis, angle)
        # [ 0.  0. -1.] 90.0
        ```
    """
    (q,), dt = as_float(q)
    check_shape(q, (4,), "q")
    q = _prescaled(to_scalar_last(q, scalar_first))
    q = jnp.where(q[..., 3:] < 0, -q, q)
    qv = q[..., :3]
    # The vector part scaled on its own (a power of two), so that a tiny one (1e-160 next to
    # w = 1) still gives its direction rather than underflowing to the identity's.
    s, _ = exponent_scale(jax.lax.stop_gradient(jnp.max(jnp.abs(qv), axis=-1)))
    qv = qv * s[..., None]
    n = safe_norm(qv)
    ident = (n == 0)[..., None]
    e_x = jnp.asarray([1.0, 0.0, 0.0], dtype=q.dtype)
    axis = jnp.where(ident, e_x, qv / jnp.where(ident, 1.0, n[..., None]))
    angle = _angle(q)
    # NaN (not a valid-looking identity) for the zero quaternion or a non-finite component.
    axis = jnp.where(jnp.isnan(angle)[..., None], jnp.nan, axis)
    if degrees:
        angle = jnp.rad2deg(angle)
    return cast(axis, dt), cast(angle, dt)
