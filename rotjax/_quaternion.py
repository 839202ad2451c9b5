"""Quaternion algebra and the quaternion -> matrix map.

Internally every quaternion is scalar last, `(x, y, z, w)`; `scalar_first=True` reorders at the
boundary. Functions that interpret a quaternion as a rotation normalise it, at any finite non-zero
scale (an exact power-of-two prescaling, `quat_prescaled`); the algebraic functions (product,
conjugate) do not, because kinematics needs them on non-unit quaternions.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from ._elementary import atan2, hypot, reciprocal, rsqrt
from ._numerics import (
    as_float,
    cast,
    check_shape,
    exponent_scale,
    from_part,
    from_scalar_last,
    noted_matrix_form,
    noted_unit,
    public,
    recorded,
    stack,
    stack_matrix,
    sum_squares,
    to_scalar_last,
    unit_scale,
    unstack,
    where,
)


def _prep(q, scalar_first, name="q"):
    (q,), dt = as_float(q)
    check_shape(q, (4,), name)
    return to_scalar_last(q, scalar_first), dt


def _prep2(p, q, scalar_first, names=("p", "q")):
    """Two quaternions in one common compute dtype, scalar last."""
    (p, q), dt = as_float(p, q)
    check_shape(p, (4,), names[0])
    check_shape(q, (4,), names[1])
    return to_scalar_last(p, scalar_first), to_scalar_last(q, scalar_first), dt


def _prescaled_parts(q, bounded=False):
    """The four components of ``q`` (per-rotation arrays) times a power of two ``s`` that brings
    the largest into ``[0.5, 2)`` (exact; 1 for a unit quaternion), so that squared norms and
    products neither overflow nor underflow, and ``s``. ``s`` is NaN where ``q`` is zero or a
    component is infinite or NaN (not a rotation): the NaN is put into the scale, which XLA
    applies inside the loop that reads ``q``, rather than into a copy of ``q``.

    ``bounded``: ``q`` is of order 1 (a unit quaternion, a product of :func:`quat_rescaled`
    ones) or NaN where it is not a rotation, and is returned as it is (``s = 1``); so is a
    unit quaternion computed in this trace (:func:`rotjax._numerics.noted_unit`), for which
    ``s`` is exactly 1."""
    return _prescale(unstack(q), bounded or noted_unit(q))


def _prescale(parts, bounded=False):
    """:func:`_prescaled_parts` of a quaternion given by its four components."""
    if bounded:
        return list(parts), jnp.ones_like(parts[0])
    s = unit_scale(*parts, mark=True)
    return [x * s for x in parts], s


def quat_rescaled(q):
    """``q`` times the exact power of two that brings its largest ``|component|`` into
    ``[1, 2)``, NaN where ``q`` is not a rotation (zero or not finite): for a product whose
    result is stored, not read (a composition), so that a chain of them neither overflows nor
    underflows. A product of such factors and unit ones has a norm in ``[1, 16)`` or is NaN:
    its readers need no prescaling (``bounded``)."""
    parts = unstack(q)
    s, _ = exponent_scale(*parts, mark=True)
    return stack([x * s for x in parts])


def quat_prescaled(q):
    """:func:`_prescaled_parts` stacked: ``q`` scaled, NaN where it is not a rotation. A
    function of the rotation gives the same result for ``q`` and for this."""
    return stack(_prescaled_parts(q)[0])


def scaled_vector_part(q, scale, with_w, bounded=False):
    """``k q_v`` with ``k = scale(n2, w)`` a per-rotation function of the prescaled quaternion
    (see :func:`_prescaled_parts`), ``n2 = |q_v|^2`` (``|q|^2`` with ``with_w``): the
    logarithm map and the MRP. ``bounded``: see :func:`_prescaled_parts`."""
    p, _ = _prescaled_parts(q, bounded)
    return stack(scaled_vector_parts(tuple(p), scale, with_w, bounded=True))


def scaled_vector_parts(q, scale, with_w, bounded=False):
    """:func:`scaled_vector_part` on the four components of ``q``: the three components of
    ``k q_v``. JAX differentiates this code."""
    (x, y, z, w), _ = _prescale(q, bounded)  # NaN for the zero quaternion or a non-finite one
    n2 = x * x + y * y + z * z + (w * w if with_w else 0)
    k = scale(n2, w)
    return k * x, k * y, k * z


def quat_multiply(p, q):
    """Hamilton product of scalar-last quaternions (no normalisation); noted unit (see
    :func:`rotjax._numerics.noted_unit`) where both factors are."""
    px, py, pz, pw = unstack(p)
    qx, qy, qz, qw = unstack(q)
    return stack(
        [
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
            pw * qw - px * qx - py * qy - pz * qz,
        ],
        unit=noted_unit(p) and noted_unit(q),
    )


def quat_conjugate(q):
    x, y, z, w = unstack(q)
    return stack([-x, -y, -z, w], unit=noted_unit(q))


def quat_normalize(q, bounded=False):
    """`q / |q|` for `q` at any finite scale (`quat_prescaled` first); NaN for the zero
    quaternion (0/0, on purpose: it is not a rotation) and for a non-finite component.
    ``bounded``: see :func:`_prescaled_parts`."""
    p, _ = _prescaled_parts(q, bounded)
    r = rsqrt(sum_squares(p))
    return stack([x * r for x in p], unit=True)


def quat_renormalize(q):
    """`q / |q|` for `q` of order 1, computed from unit or prescaled quaternions (a step of
    an integrator, a product): no scaling, whose cost would be that of the step. The squared
    norm is a sum of four squares: XLA:CPU runs a reduction over the last axis as a loop of its
    own."""
    p = unstack(q)
    r = rsqrt(sum_squares(p))
    return stack([x * r for x in p], unit=True)


def quat_to_matrix(q, bounded=False):
    """Rotation matrix of a scalar-last quaternion of any finite non-zero norm (NaN for zero
    or a non-finite component). ``bounded``: see :func:`_prescaled_parts`. A quaternion made
    in this trace by a maker with a direct form of its matrix (the exponential map's, the Euler
    angles') gets that form (:func:`rotjax._numerics.noted_matrix_form`)."""
    direct = noted_matrix_form(q)
    if direct is not None:
        return direct()
    return quat_to_matrix_parts(*_prescaled_parts(q, bounded)[0], computed=recorded(q))


def quat_to_matrix_parts(x, y, z, w, computed=False):
    """Rotation matrix of a quaternion given by its components (per-rotation arrays), stacked
    row by row (see :func:`rotjax._numerics.stack_matrix`).

    Read from memory, the components make each entry a short expression: the entries of
    :func:`_matrix_entries`, stacked by a concatenate, which computes each in a loop branch
    of its own. ``computed``: the components are expressions of this program (a quaternion
    stacked in this trace, such as ``Rotation.from_euler``'s), which that branch would compute
    again for each entry, one rotation at a time (30 times slower); the entries are then
    stacked by a select, each computing every entry, with ``1 / |q|^2`` as
    :func:`~rotjax._elementary.reciprocal` (a division would be a loop of its own)."""
    e = _matrix_entries(x, y, z, w, computed)
    return stack_matrix([e[0:3], e[3:6], e[6:9]], concat=not computed)


@functools.partial(jax.custom_jvp, nondiff_argnums=(4,))
def _matrix_entries(x, y, z, w, fused):
    """Rotation matrix of a quaternion given by its components (per-rotation arrays), of
    non-zero norm, squared norm a normal number: the homogeneous form, quadratic in ``q``, then
    one division by ``|q|^2`` (Markley & Crassidis 2014, Ch. 2, for any norm). An entry
    whose terms cancel is exactly zero (``z = w``: ``w^2 - z^2``), not ``1 - 2 z^2 / |q|^2``
    rounded; an entry equal to ``+-|q|^2`` is exactly ``+-1`` where ``|q|^2`` times its rounded
    reciprocal rounds to 1, as for every power-of-two norm (the prescaled unit quaternions)."""
    return homogeneous_matrix(x, y, z, w, reciprocal if fused else lambda n2: 1 / n2)


@_matrix_entries.defjvp
def _matrix_entries_jvp(fused, primals, tangents):
    # The derivative of the same form, with 1 / |q|^2 as rsqrt(|q|^2)^2 (the same to an ulp):
    # multiplications only, which XLA:CPU fuses into one loop in reverse mode as well (a
    # division there split the gradient into six loops).
    def form(*q):
        return homogeneous_matrix(*q, reciprocal if fused else lambda n2: jnp.square(rsqrt(n2)))

    return _matrix_entries(*primals, fused), jax.jvp(form, primals, tangents)[1]


def homogeneous_matrix(x, y, z, w, reciprocal):
    xx, yy, zz, ww = x * x, y * y, z * z, w * w
    r = reciprocal((xx + yy) + (zz + ww))
    t = 2 * r
    xy, xz, yz = x * y, x * z, y * z
    xw, yw, zw = x * w, y * w, z * w
    rows = (
        (((ww + xx) - (yy + zz)) * r, (xy - zw) * t, (xz + yw) * t),
        ((xy + zw) * t, ((ww + yy) - (xx + zz)) * r, (yz - xw) * t),
        ((xz - yw) * t, (yz + xw) * t, ((ww + zz) - (xx + yy)) * r),
    )
    return tuple(e for row in rows for e in row)


def quat_angle(q, bounded=False):
    """Rotation angle in [0, pi] of a scalar-last quaternion of any finite norm (NaN for zero
    or a non-finite component). ``bounded``: see :func:`_prescaled_parts`."""
    # |w|, n of order 1: atan2's derivative is finite
    (x, y, z, w), _ = _prescaled_parts(q, bounded)
    w = jnp.abs(w)
    # |q_v| scaled on its own, so that 1e-160 stays 1e-160 (atan2 is a ratio, scale-free)
    n = hypot(x, y, z)
    # NaN for the zero quaternion: atan2(0, 0) = 0 would pass for the identity; and for an
    # infinite component, where atan2 would return a finite angle.
    bad = ((n == 0) & (w == 0)) | ~jnp.isfinite(n + w)
    return where(bad, jnp.nan, 2 * atan2(n, w))


@public
def quaternion_to_matrix(q: ArrayLike, scalar_first: bool = False) -> Array:
    """Rotation matrix of a quaternion.

    Args:
        q: `(..., 4)` quaternion, scalar last `(x, y, z, w)` unless `scalar_first`; need not
            be unit (it is normalised; any finite non-zero scale gives the same matrix, to a
            few eps: 1e-30 to 1e30 in float32, 1e-300 to 1e300 in float64; zero, infinite or
            NaN components give NaN).
        scalar_first: read `q` as `(w, x, y, z)`.

    Returns:
        `(..., 3, 3)` active rotation matrix `R` with `v_world = R @ v_body`. `q` and
            `-q` give the same matrix.

    Examples:
        ```python
        import rotjax as rj

        q = [0.0, 0.0, 0.6, 0.8]  # about z by 2 atan(0.6 / 0.8) = 73.7 deg
        print(rj.quaternion_to_matrix(q).round(6))
        # [[ 0.28 -0.96  0.  ]
        #  [ 0.96  0.28  0.  ]
        #  [ 0.    0.    1.  ]]
        ```
    """
    q, dt = _prep(q, scalar_first)
    return cast(quat_to_matrix(q), dt)


@public
def quaternion_multiply(p: ArrayLike, q: ArrayLike, scalar_first: bool = False) -> Array:
    """Hamilton product `p * q`, so that `R(p * q) = R(p) @ R(q)`.

    Args:
        p: `(..., 4)` quaternion (layout as `scalar_first`).
        q: `(..., 4)` quaternion; broadcasts against `p`.
        scalar_first: quaternions are `(w, x, y, z)`.

    Returns:
        `(..., 4)` the raw product. It is not normalised: its norm is `|p| |q|`, which keeps
            the product bilinear (kinematics relies on that).

    Examples:
        ```python
        import rotjax as rj

        x90 = [0.70710678, 0.0, 0.0, 0.70710678]  # 90 deg about x
        z90 = [0.0, 0.0, 0.70710678, 0.70710678]  # 90 deg about z
        print(rj.quaternion_multiply(z90, x90).round(6))  # x90 first, then z90
        # [0.5 0.5 0.5 0.5]
        ```
    """
    p, q, dt = _prep2(p, q, scalar_first)
    return cast(from_scalar_last(quat_multiply(p, q), scalar_first), dt)


@public
def quaternion_conjugate(q: ArrayLike, scalar_first: bool = False) -> Array:
    """Conjugate `(-x, -y, -z, w)`: the inverse rotation, with the same norm.

    Args:
        q: `(..., 4)` quaternion.
        scalar_first: `q` is `(w, x, y, z)`.

    Returns:
        `(..., 4)` conjugate, in the same layout.

    Examples:
        ```python
        import rotjax as rj

        print(rj.quaternion_conjugate([1.0, 2.0, 3.0, 4.0]))
        # [-1. -2. -3.  4.]
        ```
    """
    q, dt = _prep(q, scalar_first)
    return cast(from_scalar_last(quat_conjugate(q), scalar_first), dt)


@public
def quaternion_inverse(q: ArrayLike, scalar_first: bool = False) -> Array:
    """Multiplicative inverse `conj(q) / |q|^2`, so that `q * inverse(q) = (0, 0, 0, 1)`.

    Args:
        q: `(..., 4)` non-zero quaternion (the zero quaternion gives NaN).
        scalar_first: `q` is `(w, x, y, z)`.

    Returns:
        `(..., 4)` inverse, in the same layout.

    Examples:
        ```python
        import rotjax as rj

        q = [0.0, 0.0, 1.2, 1.6]  # norm 2
        print(rj.quaternion_inverse(q))
        # [-0.  -0.  -0.3  0.4]
        print(rj.quaternion_multiply(q, rj.quaternion_inverse(q)).round(6))
        # [0. 0. 0. 1.]
        ```
    """
    q, dt = _prep(q, scalar_first)
    (x, y, z, w), s = _prescaled_parts(q)  # conj(q) / |q|^2 = s conj(s q) / |s q|^2
    r = rsqrt(x * x + y * y + z * z + w * w)
    k = s * r * r
    return cast(from_scalar_last(stack([-x * k, -y * k, -z * k, w * k]), scalar_first), dt)


@public
def quaternion_normalize(q: ArrayLike, scalar_first: bool = False) -> Array:
    """Unit quaternion `q / |q|`; the sign is kept (no hemisphere is imposed).

    Args:
        q: `(..., 4)` quaternion. The zero quaternion gives NaN, on purpose.
        scalar_first: `q` is `(w, x, y, z)`.

    Returns:
        `(..., 4)` unit quaternion, in the same layout.

    Examples:
        ```python
        import rotjax as rj

        print(rj.quaternion_normalize([0.0, 0.0, 3.0, 4.0]))
        # [0.  0.  0.6 0.8]
        ```
    """
    q, dt = _prep(q, scalar_first)
    return cast(from_scalar_last(quat_normalize(q), scalar_first), dt)


@public
def quaternion_apply(q: ArrayLike, v: ArrayLike, scalar_first: bool = False) -> Array:
    """Rotate vectors: `R(q) @ v`.

    Args:
        q: `(..., 4)` quaternion; need not be unit.
        v: `(..., 3)` vectors; broadcasts against `q`.
        scalar_first: `q` is `(w, x, y, z)`.

    Returns:
        `(..., 3)` rotated vectors.

    Examples:
        ```python
        import rotjax as rj

        z90 = [0.0, 0.0, 0.70710678, 0.70710678]  # 90 deg about z
        print(rj.quaternion_apply(z90, [1.0, 0.0, 0.0]).round(6))
        # [-0.  1.  0.]
        ```
    """
    (q, v), dt = as_float(q, v)
    check_shape(q, (4,), "q")
    check_shape(v, (3,), "v")
    return cast(quat_apply(to_scalar_last(q, scalar_first), v), dt)


def quat_turn(p, v):
    """``R(p) v - v`` for a unit quaternion ``p`` (four per-rotation arrays, scalar last) and
    ``v`` (three): ``w t + p_v x t`` with ``t = 2 p_v x v``. A polynomial, quadratic in ``p``
    and linear in ``v``, for any ``p``."""
    x, y, z, w = p
    a, b, c = v
    t0, t1, t2 = 2 * (y * c - z * b), 2 * (z * a - x * c), 2 * (x * b - y * a)
    return [w * t0 + (y * t2 - z * t1), w * t1 + (z * t0 - x * t2), w * t2 + (x * t1 - y * t0)]


def quat_apply(q, v, bounded=False):
    """``R(q) v`` for a scalar-last ``q`` of any finite non-zero norm (see quaternion_apply).
    ``bounded``: see :func:`_prescaled_parts`."""
    p, _ = _prescaled_parts(q, bounded)
    return stack(_apply_parts(tuple(p), tuple(unstack(v)), bounded=True))


def _apply_parts(q, v, bounded=False):
    p, _ = _prescale(q, bounded)
    r = rsqrt(sum_squares(p))  # the unit quaternion, on per-rotation scalars
    d = quat_turn([x * r for x in p], v)
    return tuple(a + b for a, b in zip(v, d, strict=True))


@public
def relative_rotation(q_a: ArrayLike, q_b: ArrayLike, scalar_first: bool = False) -> Array:
    """Rotation from frame `a` to frame `b`: `q_rel = conj(q_a) * q_b`, normalised.

    With `R_a`, `R_b` the orientations of the two frames in a common (world) frame, the
    result is `R_rel = R_a.T @ R_b`: the orientation of `b` expressed in `a`, so that
    `R_b = R_a @ R_rel` and `v_a = R_rel @ v_b`. This is the matrix the MapleSim
    relative-angle sensors decompose into Euler angles.

    Args:
        q_a: `(..., 4)` orientation of frame `a`; need not be unit.
        q_b: `(..., 4)` orientation of frame `b`; broadcasts against `q_a`.
        scalar_first: quaternions are `(w, x, y, z)`.

    Returns:
        `(..., 4)` unit quaternion of the relative rotation (sign as produced by the product).

    Examples:
        ```python
        import rotjax as rj

        q_a = rj.axis_angle_to_quaternion([0.0, 0.0, 1.0], 30.0, degrees=True)
        q_b = rj.axis_angle_to_quaternion([0.0, 0.0, 1.0], 75.0, degrees=True)
        _, angle = rj.quaternion_to_axis_angle(rj.relative_rotation(q_a, q_b), degrees=True)
        print(angle.round(4))
        # 45.0
        ```
    """
    qa, qb, dt = _prep2(q_a, q_b, scalar_first, ("q_a", "q_b"))
    rel = quat_renormalize(quat_multiply(quat_conjugate(quat_prescaled(qa)), quat_prescaled(qb)))
    return cast(from_scalar_last(rel, scalar_first), dt)


@public
def rotation_angle(q: ArrayLike, scalar_first: bool = False) -> Array:
    """Rotation angle `2 atan2(|q_v|, |w|)` in `[0, pi]`.

    Args:
        q: `(..., 4)` quaternion; need not be unit.
        scalar_first: `q` is `(w, x, y, z)`.

    Returns:
        `(...,)` angle in radians, in `[0, pi]`; `q` and `-q` give the same angle.

    Note:
        atan2 keeps full relative accuracy near 0 and near pi, where `2 acos(w)` loses half the
        digits. Any finite non-zero scale of `q` gives the same angle; zero, infinite or NaN
        components give NaN. At the identity the angle has a cone-shaped minimum and no
        derivative; the gradient returned there is 0 (the minimum-norm subgradient), finite. Use
        the squared angle as a smooth loss.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        print(rj.rotation_angle([0.0, 0.0, 1.0, 1.0]) / jnp.pi)  # 90 deg; need not be unit
        # 0.5
        ```
    """
    q, dt = _prep(q, scalar_first)
    return cast(from_part(quat_angle(q)), dt)


@public
def angle_between(p: ArrayLike, q: ArrayLike, scalar_first: bool = False) -> Array:
    """Geodesic distance between two rotations: the angle of `conj(p) * q`, in `[0, pi]`.

    Args:
        p: `(..., 4)` quaternion; need not be unit.
        q: `(..., 4)` quaternion; broadcasts against `p`.
        scalar_first: quaternions are `(w, x, y, z)`.

    Returns:
        `(...,)` angle in radians in `[0, pi]`; invariant to the sign of `p` and of `q`.

    Note:
        Computed with atan2, so it is accurate at 0 and the gradient there is finite (0, the
        minimum of the cone). See [`rotation_angle`][rotjax.rotation_angle].

    Examples:
        ```python
        import rotjax as rj

        p = rj.rotvec_to_quaternion([0.1, 0.0, 0.0])
        q = rj.rotvec_to_quaternion([0.4, 0.0, 0.0])
        print(rj.angle_between(p, q).round(6), rj.angle_between(p, -q).round(6))  # q or -q
        # 0.3 0.3
        ```
    """
    p, q, dt = _prep2(p, q, scalar_first)
    # prescaled factors (NaN where not a rotation): their product is of order 1, or NaN
    rel = quat_multiply(quat_conjugate(quat_prescaled(p)), quat_prescaled(q))
    return cast(from_part(quat_angle(rel, bounded=True)), dt)
