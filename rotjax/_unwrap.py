"""Continuous time series: Euler angles and quaternion signs without jumps."""

from __future__ import annotations

import operator

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.typing import ArrayLike

from ._euler import is_proper, parse_seq
from ._numerics import (
    as_float,
    cast,
    check_shape,
    like_rank,
    public,
    where,
)

# --- continuous Euler angles -------------------------------------------------------------------


@public
def unwrap_euler(angles: ArrayLike, seq: str, axis: int = 0) -> Array:
    """Continuous Euler angles from a time series of principal-range ones.

    Args:
        angles: `(..., T, ..., 3)` Euler angles in radians, in the order of `seq`, e.g. from
            [`quaternion_to_euler`][rotjax.quaternion_to_euler]; the last axis holds the three
            angles.
        seq: axis sequence; see [`euler_rate_matrix`][rotjax.euler_rate_matrix].
        axis: the time axis (any integer-like value, any axis but the last).

    Returns:
        Array of the same shape: at each sample, among the two solution sets and all `2 pi`
            shifts of each angle, the one nearest (sum of squared differences) to the previous
            output sample. Every output sample describes the same rotation as its input. The first
            sample is returned unchanged. A sample with a NaN or infinite angle is returned as it
            is and skipped: the next finite sample is unwrapped against the last finite output.

    Note:
        The second solution set is `(a0 + pi, pi - a1, a2 + pi)` for Tait-Bryan sequences and
        `(a0 + pi, -a1, a2 + pi)` for proper Euler sequences (checked against
        `euler_to_quaternion` in the tests). A middle angle that runs through
        the edge of its principal range therefore continues smoothly past it. Only the sum or
        difference of the outer angles is defined at exact gimbal lock; there the choice
        follows the previous sample, so the output stays continuous if the input sampling
        resolves the motion (steps well below `pi / 2`). Implemented with `lax.scan` and
        no data-dependent branches.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        yaw = jnp.deg2rad(jnp.array([170.0, 179.0, -172.0]))  # crosses +-180 deg
        angles = jnp.stack([yaw, jnp.zeros(3), jnp.zeros(3)], axis=-1)
        print(jnp.rad2deg(rj.unwrap_euler(angles, "ZYX")[:, 0]).round(1))
        # [170. 179. 188.]
        ```
    """
    (a,), dt = as_float(angles)
    check_shape(a, (3,), "angles")
    parse_seq(seq)  # a bad seq raises here, before any array work
    axis = _time_axis(axis, a.ndim, "angles", a.shape)
    x = jnp.moveaxis(a, axis, 0)
    if x.shape[0] == 0:
        return cast(a, dt)
    two_pi = 2 * np.pi
    # Second solution set: R_i(a0 + pi) R_j(b) R_k(a2 + pi) = R_i(a0) R_j(a1) R_k(a2) needs
    # b = pi - a1 when i != k and b = -a1 when i == k (rotating by pi about e_i flips e_j).
    flip = np.array([1.0, -1.0, 1.0])
    offset = np.array([np.pi, 0.0 if is_proper(seq) else np.pi, np.pi])
    flip, offset = like_rank(flip, x[0]), like_rank(offset, x[0])

    def nearest(c, prev):
        return c + two_pi * jnp.round((prev - c) / two_pi)

    def step(carry, sample):
        prev, seen = carry
        # A non-finite sample is returned as it is and leaves the reference untouched: the next
        # finite sample is unwrapped against the last finite output (or passed through unchanged
        # if none came before). Double where: `prev` is made finite before the arithmetic.
        ok = jnp.all(jnp.isfinite(sample), axis=-1, keepdims=True)
        ref = where(seen, prev, 0.0)
        s = where(ok, sample, 0.0)
        c1 = nearest(s, ref)
        c2 = nearest(offset + flip * s, ref)
        d1 = jnp.sum((c1 - ref) ** 2, axis=-1, keepdims=True)
        d2 = jnp.sum((c2 - ref) ** 2, axis=-1, keepdims=True)
        out = where(seen, where(d2 < d1, c2, c1), s)
        out = where(ok, out, sample)
        return (where(ok, out, prev), seen | ok), out

    seen0 = jnp.zeros(x.shape[1:-1] + (1,), dtype=bool)
    _, y = jax.lax.scan(step, (jnp.zeros_like(x[0]), seen0), x)
    return cast(jnp.moveaxis(y, 0, axis), dt)


def _time_axis(axis, ndim: int, name: str, shape) -> int:
    """Validate a static time axis (any integer-like value, not the component axis)."""
    try:
        ax = operator.index(axis)
    except TypeError:
        ax = None
    if ax is None or isinstance(axis, bool) or not -ndim <= ax < ndim or ax % ndim == ndim - 1:
        raise ValueError(
            f"axis must be an integer indexing a time axis of {name} with shape {tuple(shape)} "
            f"other than the last, got {axis!r}"
        )
    return ax % ndim


# --- quaternion sign continuity ----------------------------------------------------------------


@public
def unwrap_quaternion(q: ArrayLike, axis: int = 0, scalar_first: bool = False) -> Array:
    """Quaternion time series with consecutive samples in the same hemisphere.

    Args:
        q: `(..., T, ..., 4)` quaternions; need not be unit. The last axis holds the
            components.
        axis: the time axis (any integer-like value, any axis but the last).
        scalar_first: quaternions are `(w, x, y, z)` (the layout is kept).

    Returns:
        Array of the same shape, each sample `q_k` or `-q_k` (the same rotation), such that
            `q_k . q_{k+1} >= 0` between consecutive finite samples. The first finite sample
            keeps its sign. A dot product of exactly 0 keeps the sign.

    Note:
        Samples with a NaN or infinite component are returned unchanged and skipped: the sign
        of the next finite sample is chosen against the last finite sample before it, so a bad
        sample neither flips nor poisons the rest of the series. Implemented with a cumulative
        maximum (the last finite index) and a cumulative parity of sign changes: no sequential
        loop.

    Examples:
        ```python
        import rotjax as rj

        q = [[0.0, 0.0, 0.6, 0.8], [0.0, 0.0, -0.7, -0.71], [0.0, 0.0, 0.8, 0.6]]
        print(rj.unwrap_quaternion(q))  # the middle sample flips to the same hemisphere
        # [[ 0.    0.    0.6   0.8 ]
        #  [-0.   -0.    0.7   0.71]
        #  [ 0.    0.    0.8   0.6 ]]
        ```
    """
    (x,), dt = as_float(q)
    check_shape(x, (4,), "q")
    axis = _time_axis(axis, x.ndim, "q", x.shape)
    x = jnp.moveaxis(x, axis, 0)
    n = x.shape[0]
    if n == 0:
        return cast(jnp.moveaxis(x, 0, axis), dt)
    ok = jnp.all(jnp.isfinite(x), axis=-1)  # (T, ...)
    idx = jnp.arange(n).reshape((n,) + (1,) * (ok.ndim - 1))
    # Prefix operations as associative scans (log-depth passes over the series), which XLA:CPU
    # runs faster than its cumulative-reduction lowering of cummax and cumprod.
    last = jax.lax.associative_scan(jax.lax.max, where(ok, idx, -1), axis=0)  # last finite <= k
    prev = jnp.concatenate([jnp.full_like(last[:1], -1), last[:-1]], axis=0)  # < k
    ref = jnp.take_along_axis(x, jnp.maximum(prev, 0)[..., None], axis=0)
    dot = jnp.sum(where(ok[..., None], x, 0.0) * where(prev[..., None] >= 0, ref, 0.0), -1)
    # the parity of the sign changes up to k (a cumulative product of +-1)
    odd = jax.lax.associative_scan(jax.lax.ne, dot < 0, axis=0)
    out = where(ok[..., None] & odd[..., None], -x, x)  # bad samples as given
    return cast(jnp.moveaxis(out, 0, axis), dt)
