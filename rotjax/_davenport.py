"""Davenport angles: rotations about three arbitrary axes, consecutive axes orthogonal."""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from ._euler import quat_to_euler
from ._matrix import quat_from_matrix
from ._numerics import (
    as_float,
    cast,
    check_shape,
    cross,
    from_scalar_last,
    public,
    to_scalar_last,
    where,
)
from ._quaternion import quat_conjugate, quat_multiply
from ._rotvec import rotvec_to_quat

ORDERS = {"e": True, "extrinsic": True, "i": False, "intrinsic": False}


def parse_order(order) -> bool:
    """`True` for extrinsic, `False` for intrinsic; ValueError otherwise."""
    if order not in ORDERS:
        raise ValueError(
            "order should be 'e'/'extrinsic' for extrinsic sequences or 'i'/'intrinsic' for "
            f"intrinsic sequences, got {order!r}"
        )
    return ORDERS[order]


@public(static=("extrinsic",))
def davenport_to_quaternion(
    axes: ArrayLike,
    angles: ArrayLike,
    extrinsic: bool = False,
    degrees: bool = False,
    scalar_first: bool = False,
) -> Array:
    """Quaternion of Davenport angles: rotations by `angles[k]` about `axes[k]`.

    Args:
        axes: `(..., K, 3)` rotation axes, `K` in 1..3; need not be unit (each is
            normalised). Consecutive axes must be orthogonal (`|dot| <= 1e-7` after
            normalisation, scipy's tolerance); otherwise the result is NaN.
        angles: `(..., K)` angles; broadcasts against `axes[..., 0]`.
        extrinsic: the axes are fixed (world) axes, `R = R_K ... R_1`; otherwise they rotate
            with the body (intrinsic), `R = R_1 ... R_K`.
        degrees: angles are in degrees.
        scalar_first: return `(w, x, y, z)`.

    Returns:
        `(..., 4)` unit quaternion (the product of the elementary quaternions, no hemisphere
            imposed, so the map is smooth in the angles and axes).

    Note:
        With the coordinate axes this is [`euler_to_quaternion`][rotjax.euler_to_quaternion]
        (intrinsic `"XYZ"` is `axes = eye(3)`). A zero axis gives NaN.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        axes = jnp.eye(3)  # the coordinate axes: intrinsic "XYZ" Euler angles
        q = rj.davenport_to_quaternion(axes, [10.0, 20.0, 30.0], degrees=True)
        print(q.round(6))
        # [0.127679 0.144878 0.268536 0.943714]
        print(rj.euler_to_quaternion([10.0, 20.0, 30.0], "XYZ", degrees=True).round(6))
        # [0.127679 0.144878 0.268536 0.943714]
        ```
    """
    (axes, angles), dt = as_float(axes, angles)
    check_shape(axes, (3,), "axes")
    if axes.ndim < 2 or not 1 <= axes.shape[-2] <= 3:
        raise ValueError(f"axes: expected shape (..., K, 3) with K in 1..3, got {axes.shape}")
    k = axes.shape[-2]
    if angles.ndim < 1 or angles.shape[-1] != k:
        raise ValueError(f"angles: expected shape (..., {k}) for {k} axes, got {angles.shape}")
    if degrees:
        angles = jnp.deg2rad(angles)
    unit = axes / jnp.sqrt(jnp.sum(axes * axes, axis=-1, keepdims=True))
    # Explicit broadcasting of the batch shapes (no implicit rank promotion).
    batch = jnp.broadcast_shapes(unit.shape[:-2], angles.shape[:-1])
    unit = jnp.broadcast_to(unit, batch + unit.shape[-2:])
    angles = jnp.broadcast_to(angles, batch + angles.shape[-1:])
    bad = jnp.any(jnp.abs(jnp.sum(unit[..., :-1, :] * unit[..., 1:, :], axis=-1)) > 1e-7, axis=-1)
    q = None
    for i in range(k):
        qi = rotvec_to_quat(angles[..., i, None] * unit[..., i, :])
        q = qi if q is None else (quat_multiply(qi, q) if extrinsic else quat_multiply(q, qi))
    q = where(bad[..., None], jnp.nan, q)
    return cast(from_scalar_last(q, scalar_first), dt)


@public(static=("extrinsic",))
def quaternion_to_davenport(
    q: ArrayLike,
    axes: ArrayLike,
    extrinsic: bool = False,
    degrees: bool = False,
    scalar_first: bool = False,
) -> Array:
    """Davenport angles of a rotation about three axes (consecutive axes orthogonal).

    Reduced to Euler angles by a change of basis: with `B = [m1, m2, m1 x m2]` and `m3 =
    cos(l) m1 + sin(l) (m1 x m2)`, the rotation `R = R_m1(a) R_m2(b) R_m3(c)` satisfies
    `B^T R B Ry(-l) = Rx(a) Ry(b - l) Rx(c)`: the proper Euler sequence `"XYX"`.

    Args:
        q: `(..., 4)` quaternion; need not be unit.
        axes: `(..., 3, 3)` the three axes (rows; normalised here), `axes[0] . axes[1] = 0`
            and `axes[1] . axes[2] = 0`; batch shape broadcasts against `q`'s.
        extrinsic: the axes are fixed (world) axes; otherwise they rotate with the body.
        degrees: return degrees.
        scalar_first: `q` is `(w, x, y, z)`.

    Returns:
        `(..., 3)` angles as scipy's `as_davenport`: first and third in `[-pi, pi]`; the
            middle one in `[-l, pi - l]` where `l` in `[-pi, 0]` is the signed angle from
            the first to the last axis (of the intrinsic order) about the middle one, and in
            `[l - pi, l]` for `l` in `(0, pi]`. Coordinate axes give the Euler angles of
            [`quaternion_to_euler`][rotjax.quaternion_to_euler]. Axes that are not orthogonal
            (`|dot| > 1e-7`, scipy's tolerance) give NaN.

    Note:
        Inherits [`quaternion_to_euler`][rotjax.quaternion_to_euler]'s behaviour: no gimbal-lock
        threshold, the last angle (of the intrinsic order) 0 at exact lock, finite gradients there.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        axes = jnp.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # z, x, z
        q = rj.euler_to_quaternion([10.0, 20.0, 30.0], "ZXZ", degrees=True)
        print(rj.quaternion_to_davenport(q, axes, degrees=True).round(4))
        # [10. 20. 30.]
        ```
    """
    (q, axes), dt = as_float(q, axes)
    check_shape(q, (4,), "q")
    check_shape(axes, (3, 3), "axes")
    q = to_scalar_last(q, scalar_first)
    batch = jnp.broadcast_shapes(q.shape[:-1], axes.shape[:-2])
    q = jnp.broadcast_to(q, batch + (4,))
    m = jnp.broadcast_to(axes, batch + (3, 3))
    m = m / jnp.sqrt(jnp.sum(m * m, axis=-1, keepdims=True))
    if extrinsic:  # R = R_n3 R_n2 R_n1 is the intrinsic sequence n3, n2, n1
        m = m[..., ::-1, :]
    m1, m2, m3 = m[..., 0, :], m[..., 1, :], m[..., 2, :]
    bad = (jnp.abs(jnp.sum(m1 * m2, axis=-1)) > 1e-7) | (jnp.abs(jnp.sum(m2 * m3, axis=-1)) > 1e-7)
    c = cross(m1, m2)
    lam = jnp.arctan2(jnp.sum(m3 * c, axis=-1), jnp.sum(m3 * m1, axis=-1))
    # For l > 0 use -m2 (then l -> -l) and negate the middle angle at the end: scipy's ranges.
    flip = lam > 0
    m2 = where(flip[..., None], -m2, m2)
    c = where(flip[..., None], -c, c)
    lam = where(flip, -lam, lam)
    qb = quat_from_matrix(jnp.stack([m1, m2, c], axis=-1), "shepperd")  # columns: a rotation
    z = jnp.zeros_like(lam)
    qy = jnp.stack([z, jnp.sin(-lam / 2), z, jnp.cos(-lam / 2)], axis=-1)
    qp = quat_multiply(quat_multiply(quat_multiply(quat_conjugate(qb), q), qb), qy)
    ang = quat_to_euler(qp, "XYX")
    mid = ang[..., 1] + lam
    ang = jnp.stack([ang[..., 0], where(flip, -mid, mid), ang[..., 2]], axis=-1)
    if extrinsic:
        ang = ang[..., ::-1]
    ang = where(bad[..., None], jnp.nan, ang)
    if degrees:
        ang = jnp.rad2deg(ang)
    return cast(ang, dt)
