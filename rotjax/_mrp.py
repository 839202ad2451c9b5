"""Modified Rodrigues parameters (MRP): `p = axis * tan(angle / 4)`."""

from __future__ import annotations

from jax import Array
from jax.typing import ArrayLike

from ._elementary import rsqrt
from ._numerics import (
    as_float,
    cast,
    check_shape,
    exponent_scale,
    from_scalar_last,
    public,
    select,
    stack,
    sum_squares,
    to_scalar_last,
    unstack,
    where,
)
from ._quaternion import scaled_vector_part


@public
def quaternion_to_mrp(q: ArrayLike, scalar_first: bool = False) -> Array:
    """Modified Rodrigues parameters of a quaternion, on the shorter side (`|p| <= 1`).

    Args:
        q: `(..., 4)` quaternion; need not be unit (zero gives NaN).
        scalar_first: `q` is `(w, x, y, z)`.

    Returns:
        `(..., 3)` MRP `v / (|q| + |w|)` with the sign of `w`: `axis * tan(angle / 4)`
            for the rotation angle in `[0, pi]`, as scipy's `as_mrp`.

    Note:
        The denominator is at least `|q|`, so the map is smooth away from `w = 0`. At
        exactly 180 degrees (`w = 0`) both `p` and `-p` (norm 1) describe the rotation;
        `w = 0` is taken as positive, and the gradient is that of that side (finite).

    Examples:
        ```python
        import rotjax as rj

        q = rj.axis_angle_to_quaternion([0.0, 0.0, 1.0], 90.0, degrees=True)
        print(rj.quaternion_to_mrp(q).round(6))  # tan(90 deg / 4)
        # [0.       0.       0.414214]
        ```
    """
    (q,), dt = as_float(q)
    check_shape(q, (4,), "q")
    # Any finite scale: |q|^2 stays in range; NaN for the zero quaternion or a non-finite one.
    return cast(quat_to_mrp(to_scalar_last(q, scalar_first)), dt)


def quat_to_mrp(q, bounded=False):
    """The MRP of a scalar-last quaternion of any finite non-zero norm. ``bounded``: see
    :func:`rotjax._quaternion._prescaled_parts`."""
    return scaled_vector_part(q, _mrp_scale, True, bounded)


def _mrp_scale(n2, w):
    """``k = sign(w) / (|q| + |w|)`` from ``n2 = |q|^2`` and ``w`` of a prescaled quaternion:
    the MRP is ``k q_v``."""
    s = select(w < 0, -1.0, 1.0, w.dtype)
    d = n2 * rsqrt(n2) + s * w  # |q| + |w|, at least |q| >= 1/2: rsqrt's domain when squared
    return s * rsqrt(d * d)


@public
def mrp_to_quaternion(mrp: ArrayLike, scalar_first: bool = False) -> Array:
    """Unit quaternion of modified Rodrigues parameters.

    Args:
        mrp: `(..., 3)` MRP `axis * tan(angle / 4)`, any norm (`p` and `-p / |p|^2` are
            the same rotation).
        scalar_first: return `(w, x, y, z)`.

    Returns:
        `(..., 4)` unit quaternion `(2 p, 1 - |p|^2) / (1 + |p|^2)` (`w >= 0` iff
            `|p| <= 1`).

    Note:
        Smooth everywhere, with no singular point: the denominator is at least 1.

    Examples:
        ```python
        import rotjax as rj

        print(rj.mrp_to_quaternion([0.0, 0.0, 1.0]).round(6))  # 180 deg about z
        # [0. 0. 1. 0.]
        ```
    """
    (p,), dt = as_float(mrp)
    check_shape(p, (3,), "mrp")
    p = unstack(p)
    # Beyond |p| = 1 the same rotation's other MRP, p' = -p / |p|^2 (|p'| < 1), gives
    # q(p) = -q(p'): |p|^2 could overflow (|p| > 1e154 in float64). p / |p|^2 is formed from
    # p scaled by a power of two s (exact): s^2 (s p) / |s p|^2, each factor in range.
    # Reciprocals by rsqrt (multiplications and additions: see its note; both arguments are
    # at least 1), so that the conversion stays one loop alone and composed.
    outer = sum_squares(p) > 1
    s, _ = exponent_scale(*p)
    u = [x * s for x in p]
    r = rsqrt(where(outer, sum_squares(u), 1.0))  # double where; |s p|^2 is in [1, 12)
    f = -s * (r * r)
    p = [where(outer, x * f, y) for x, y in zip(u, p, strict=True)]
    p2 = sum_squares(p)  # at most 1
    r = rsqrt(1 + p2)
    k = where(outer, -(r * r), r * r)
    q = [(2 * k) * x for x in p] + [(1 - p2) * k]
    return cast(from_scalar_last(stack(q), scalar_first), dt)
