"""Rotation vectors and axis-angle pairs (exponential and logarithm maps)."""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.typing import ArrayLike

from ._elementary import atan_ratio, rsqrt, sin_cos
from ._matrix import quat_from_matrix
from ._numerics import (
    as_float,
    as_part,
    cast,
    check_shape,
    eps,
    exponent_scale,
    from_part,
    from_scalar_last,
    noted_matrix,
    per_slot,
    public,
    select,
    spread,
    stack,
    sum_squares,
    to_scalar_last,
    unstack,
    unstack_matrix,
    where,
)
from ._quaternion import (
    homogeneous_matrix,
    quat_angle,
    quat_prescaled,
    quat_to_matrix_parts,
    scaled_vector_part,
)


def _small(x2):
    """Below this squared argument the Taylor branch is exact to rounding (dtype dependent)."""
    return x2 < eps(x2.dtype) ** 0.5


def exp_coeffs(theta2, roots=False):
    """`sin(t/2)/t` and `cos(t/2)` for `t = sqrt(theta2)`, smooth at 0 (double where).

    Multiplications, additions and selects only (`rsqrt`, `sin_cos`), so that a conversion
    built on them is one fused loop. `roots`: XLA's square root and division instead, for code
    computed per output slot (see `_exp_matrix_slots`)."""
    small = _small(theta2)
    safe = where(small, 1.0, theta2)  # any non-zero value keeps the gradient finite
    if roots:
        t = jnp.sqrt(safe)
        sin_h, cos_h = sin_cos(0.5 * t)
        k_big = sin_h / t
    else:
        inv_t = rsqrt(safe)
        t = safe * inv_t
        t = t + (0.5 * inv_t) * (safe - t * t)  # one Newton step for sqrt: t to about 0.5 ulp
        sin_h, cos_h = sin_cos(0.5 * t)
        k_big = sin_h * inv_t
    k = where(small, 0.5 - theta2 / 48 + theta2 * theta2 / 3840, k_big)
    c = where(small, 1 - theta2 / 8 + theta2 * theta2 / 384, cos_h)
    return k, c


def rotvec_to_quat(v):
    """`(k v, c)` with `k, c = exp_coeffs(|v|^2)`: the exponential map, scalar last. Its
    readers in this trace that want its matrix get `rotvec_matrix(v)`."""
    parts = _rotvec_to_quat_parts(tuple(unstack(v)))
    return stack(parts, unit=True, matrix_form=functools.partial(rotvec_matrix, v))


def _exp_matrix_parts(v):
    """The matrix of `exp(v)` from per-rotation arrays: that of `rotvec_to_quat`'s quaternion
    (`quat_to_matrix` of it), stacked by a select (`stack_matrix`)."""
    return quat_to_matrix_parts(*_rotvec_to_quat_parts(tuple(unstack(v))), computed=True)


def _exp_matrix_slots(v):
    """`_exp_matrix_parts` computed per output slot: each of the nine entries of the
    `(..., 3, 3)` result from the whole rotation vector (`spread`), with XLA's square root and
    divisions. XLA:CPU fuses this into one loop nest per rotation (a root or a division read by
    the nine slots of a stacked result would be a loop of its own, which reads the input again)
    and LLVM computes the shared terms once per rotation, where the multiplication-only forms
    of `_elementary` are longer chains; the nest itself is scalar, as for any `(..., 3, 3)`
    result. Within a few eps of `_exp_matrix_parts`: the tests check both forms against scipy
    in float64, at any angle (a batch takes this form, a single vector the other)."""
    x, y, z = (spread(c, 9) for c in unstack(v))
    k, c = exp_coeffs(x * x + y * y + z * z, roots=True)
    out = per_slot(homogeneous_matrix(k * x, k * y, k * z, c, lambda n2: 1 / n2))
    return out.reshape(*out.shape[:-1], 3, 3)


# XLA:CPU runs a program that it estimates at fewer than 1000 flops on the calling thread, any
# other on a worker thread (a thread switch for each call). It counts the
# per-slot form's shared terms nine times (about 1100 flops a rotation, against about 250 for
# the per-rotation form), so up to this many rotations keep the per-rotation form.
FEW = 4


@jax.custom_jvp
def _exp_matrix(v):
    """The matrix of `exp(v)`: on the CPU `_exp_matrix_slots` (but for `FEW` rotations or
    fewer), elsewhere `_exp_matrix_parts`. Differentiated as `_exp_matrix_parts` (the same
    function): JAX's derivative of the per-slot code computes a `(3, 3)` cotangent per
    intermediate and sums it over the slots, far slower under `jit(grad)`."""
    if math.prod(v.shape[:-1]) <= FEW:
        return _exp_matrix_parts(v)
    return jax.lax.platform_dependent(v, cpu=_exp_matrix_slots, default=_exp_matrix_parts)


@_exp_matrix.defjvp
def _exp_matrix_jvp(primals, tangents):
    (v,), (dv,) = primals, tangents
    return _exp_matrix(v), jax.jvp(_exp_matrix_parts, (v,), (dv,))[1]


def rotvec_matrix(v):
    """`(..., 3, 3)` matrix of `exp(v)` for the stacked rotation vectors `v` (`_exp_matrix`),
    noted with the per-rotation entries of `_exp_matrix_parts`: a reader in this trace takes
    those, so a chain stays one loop, and XLA drops whichever form is not read."""
    entries = unstack_matrix(_exp_matrix_parts(v))
    return noted_matrix(_exp_matrix(v), entries)


@jax.custom_jvp
def _rotvec_to_quat_parts(v):
    x, y, z = v
    k, c = exp_coeffs(x * x + y * y + z * z)
    return k * x, k * y, k * z, c


@_rotvec_to_quat_parts.defjvp
def _rotvec_to_quat_parts_jvp(primals, tangents):
    # JAX's derivative of the code above, grouped: d(k v) = k dv + v dk and dc, with
    # dk = 2 k' (v . dv), dc = 2 c' (v . dv) and k', c' JAX's derivatives of exp_coeffs,
    # computed once per rotation (JAX's own transpose of the code above was a scalar loop in
    # float64: a function outlined per component).
    (v,), ((dx, dy, dz),) = primals, tangents
    x, y, z = v
    t2 = x * x + y * y + z * z
    (k, c), (dk2, dc2) = jax.jvp(exp_coeffs, (t2,), (2 * jnp.ones_like(t2),))
    vd = x * dx + y * dy + z * dz
    dk = dk2 * vd
    out = (k * dx + x * dk, k * dy + y * dk, k * dz + z * dk, dc2 * vd)
    return (k * x, k * y, k * z, c), out


def rotvec_scale(n2, w):
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
    inv_m = rsqrt(where(near, w2, n2))
    u = where(near, n2, w2) * (inv_m * inv_m)
    f = atan_ratio(u)
    half = where(near, f, 0.5 * np.pi - aw * inv_m * f)  # atan2(n, |w|) * m / m
    return (2 * sign) * inv_m * half


def quat_to_rotvec(q, bounded=False):
    """Logarithm map of a scalar-last quaternion of any finite non-zero norm; angle in
    [0, pi] (see `rotvec_scale`): one vectorised loop, forward and reverse. ``bounded``: see
    :func:`rotjax._quaternion._prescaled_parts`."""
    return scaled_vector_part(q, rotvec_scale, False, bounded)


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
    return cast(from_scalar_last(rotvec_to_quat(v), scalar_first), dt)


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
    v = quat_to_rotvec(to_scalar_last(q, scalar_first))
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
        Computed as the matrix of the unit quaternion `(sin(t/2) v / t, cos(t/2))`: no
        cancellation in `1 - cos t`, and the quaternion's coefficients have Taylor branches at
        0, so values and gradients are exact at the zero vector.

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
    return cast(rotvec_matrix(v), dt)


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
    v = quat_to_rotvec(quat_from_matrix(R, "shepperd"))
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
    batch = (*jnp.broadcast_shapes(axis.shape[:-1], angle.shape), 1)
    # The axis scaled by a power of two first, so that its norm can neither overflow nor
    # underflow; a zero, infinite or NaN axis gives NaN. The half angle's sine and cosine as
    # for the Euler and rotation-vector conversions (`sin_cos`): one loop.
    a = [jnp.broadcast_to(x, batch) for x in unstack(axis)]
    scale, _ = exponent_scale(*a, mark=True)
    a = [x * scale for x in a]
    sin_h, cos_h = sin_cos(0.5 * jnp.broadcast_to(as_part(angle), batch))
    k = sin_h * rsqrt(sum_squares(a))  # the sum is in [1, 12) or NaN: rsqrt's domain
    q = stack([x * k for x in a] + [where(jnp.isnan(scale), jnp.nan, cos_h)], unit=True)
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
    q = quat_prescaled(to_scalar_last(q, scalar_first))
    x, y, z, w = unstack(q)
    # The axis of the hemisphere w >= 0, from the vector part scaled on its own (a power of
    # two), so that a tiny one (1e-160 next to w = 1) still gives its direction rather than
    # underflowing to the identity's.
    s, _ = exponent_scale(x, y, z)
    s = where(w < 0, -s, s)
    v = [c * s for c in (x, y, z)]
    m2 = sum_squares(v)  # at least 1 (or eps^2 for a subnormal part) unless 0: rsqrt's domain
    ident = m2 == 0
    inv = rsqrt(where(ident, 1.0, m2))
    angle = from_part(quat_angle(q))
    # NaN (not a valid-looking identity) for the zero quaternion or a non-finite component, as
    # the angle, but from the components' bits: the angle's atan2 (a division), read by both
    # outputs, would be computed in a loop of its own.
    nan = jnp.isnan(exponent_scale(x, y, z, w, mark=True)[0])
    axis = [where(ident, e, c * inv) for c, e in zip(v, (1.0, 0.0, 0.0), strict=True)]
    axis = stack([where(nan, jnp.nan, c) for c in axis])
    if degrees:
        angle = jnp.rad2deg(angle)
    return cast(axis, dt), cast(angle, dt)
