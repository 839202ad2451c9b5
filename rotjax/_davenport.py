"""Davenport angles: rotations about three arbitrary axes, consecutive axes orthogonal."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from ._numerics import as_float, check_shape, from_scalar_last
from ._quaternion import _multiply
from ._rotvec import _rotvec_to_quat

ORDERS = {"e": True, "extrinsic": True, "i": False, "intrinsic": False}


def parse_order(order) -> bool:
    """``True`` for extrinsic, ``False`` for intrinsic; ValueError otherwise."""
    if order not in ORDERS:
        raise ValueError(
            "order should be 'e'/'extrinsic' for extrinsic sequences or 'i'/'intrinsic' for "
            f"intrinsic sequences, got {order!r}"
        )
    return ORDERS[order]


# ``extrinsic`` selects code, so it is static too (``public`` knows only the shared names).
@functools.partial(jax.jit, static_argnames=("extrinsic", "degrees", "scalar_first"))
def davenport_to_quaternion(
    axes, angles, extrinsic: bool = False, degrees: bool = False, scalar_first: bool = False
):
    """Quaternion of Davenport angles: rotations by ``angles[k]`` about ``axes[k]``.

    Args:
        axes: ``(..., K, 3)`` rotation axes, ``K`` in 1..3; need not be unit (each is
            normalised). scipy requires consecutive axes to be orthogonal for the inverse map;
            this composition does not.
        angles: ``(..., K)`` angles; broadcasts against ``axes[..., 0]``.
        extrinsic: the axes are fixed (world) axes, ``R = R_K ... R_1``; otherwise they rotate
            with the body (intrinsic), ``R = R_1 ... R_K``.
        degrees: angles are in degrees.
        scalar_first: return ``(w, x, y, z)``.

    Returns:
        ``(..., 4)`` unit quaternion (the product of the elementary quaternions, no hemisphere
        imposed, so the map is smooth in the angles and axes).

    Note:
        With the coordinate axes this is :func:`euler_to_quaternion` (intrinsic ``"XYZ"`` is
        ``axes = eye(3)``). A zero axis gives NaN.
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
    q = None
    for i in range(k):
        qi = _rotvec_to_quat(angles[..., i, None] * unit[..., i, :])
        q = qi if q is None else (_multiply(qi, q) if extrinsic else _multiply(q, qi))
    return from_scalar_last(q, scalar_first).astype(dt)
