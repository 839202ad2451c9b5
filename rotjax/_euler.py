"""Euler angles in all 12 axis sequences, intrinsic and extrinsic."""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np

from ._matrix import _from_matrix
from ._numerics import (
    as_float,
    check_shape,
    from_scalar_last,
    public,
    safe_atan2,
    safe_norm,
    to_scalar_last,
    wrap_angle,
)
from ._quaternion import _multiply, _to_matrix

_VALID = (
    "three axis letters with no two consecutive equal, all uppercase for intrinsic "
    "(rotating axes, e.g. 'ZXZ', 'XYZ') or all lowercase for extrinsic (fixed axes, e.g. "
    "'zxz', 'xyz'), or three digits 1-3 for intrinsic (e.g. '313', '123')"
)


@functools.cache
def parse_seq(seq) -> tuple[tuple[int, int, int], bool]:
    """Parse an Euler sequence string.

    Returns:
        ``(axes, intrinsic)``: axis indices (0=x, 1=y, 2=z) in the order the angles are given,
        and whether the rotations are about the rotating (body) axes.

    Raises:
        ValueError: for anything but the 24 letter forms and the 12 digit forms.
    """
    if not isinstance(seq, str) or len(seq) != 3:
        raise ValueError(f"invalid Euler sequence {seq!r}: expected {_VALID}")
    if set(seq) <= set("123"):
        axes, intrinsic = tuple(int(c) - 1 for c in seq), True
    elif set(seq) <= set("XYZ"):
        axes, intrinsic = tuple("XYZ".index(c) for c in seq), True
    elif set(seq) <= set("xyz"):
        axes, intrinsic = tuple("xyz".index(c) for c in seq), False
    else:
        raise ValueError(f"invalid Euler sequence {seq!r}: expected {_VALID}")
    if axes[0] == axes[1] or axes[1] == axes[2]:
        raise ValueError(
            f"invalid Euler sequence {seq!r}: consecutive axes must differ; expected {_VALID}"
        )
    return axes, intrinsic


def _prep_angles(angles, degrees):
    (a,), dt = as_float(angles)
    check_shape(a, (3,), "angles")
    if degrees:
        a = jnp.deg2rad(a)
    return a, dt


def _elementary(axis: int, angle):
    """Scalar-last quaternion of a rotation by ``angle`` about coordinate axis ``axis``."""
    half = angle / 2
    s, c = jnp.sin(half), jnp.cos(half)
    z = jnp.zeros_like(s)
    comps = [z, z, z, c]
    comps[axis] = s
    return jnp.stack(comps, axis=-1)


def _euler_to_quat(a, seq):
    axes, intrinsic = parse_seq(seq)
    q0, q1, q2 = (_elementary(ax, a[..., n]) for n, ax in enumerate(axes))
    # intrinsic: R = R_0 R_1 R_2 (rotating axes); extrinsic: R = R_2 R_1 R_0 (fixed axes)
    return _multiply(_multiply(q0, q1), q2) if intrinsic else _multiply(_multiply(q2, q1), q0)


def _quat_to_euler(q, seq):
    """Bernardes & Viollet 2022 (PLoS ONE 17(11): e0276302), Alg. 1, without a lock threshold.

    ``q`` is scalar last and of any non-zero norm (every step is a ratio inside atan2).
    """
    axes, intrinsic = parse_seq(seq)
    # The algorithm is stated for extrinsic sequences; an intrinsic sequence equals the reversed
    # extrinsic one with the angles in reverse order.
    i, j, k = axes[::-1] if intrinsic else axes
    proper = i == k
    if proper:
        k = 3 - i - j
    sign = (i - j) * (j - k) * (k - i) // 2  # +1 for an even permutation of (x, y, z), else -1
    if proper:
        a, b, c, d = q[..., 3], q[..., i], q[..., j], sign * q[..., k]
    else:
        a, b = q[..., 3] - q[..., j], q[..., i] + sign * q[..., k]
        c, d = q[..., j] + q[..., 3], sign * q[..., k] - q[..., i]
    ab = jnp.stack([a, b], axis=-1)
    cd = jnp.stack([c, d], axis=-1)
    mid = 2 * safe_atan2(safe_norm(cd), safe_norm(ab))
    half_sum = safe_atan2(b, a)
    half_diff = safe_atan2(d, c)
    first, third = half_sum - half_diff, half_sum + half_diff
    # Exactly at gimbal lock only one combination of the outer angles is defined. There the
    # angle that ends up *third* in the output is set to 0, as scipy does; this is an equality
    # test, not a threshold, so angles near lock keep the exact (threshold-free) formula.
    lock_sum = (c == 0) & (d == 0)  # middle angle at 0 (proper) / +pi/2 (Tait-Bryan)
    lock_diff = (a == 0) & (b == 0)  # middle angle at pi (proper) / -pi/2 (Tait-Bryan)
    if intrinsic:  # third output angle is `first` here (reversed below)
        third = jnp.where(lock_sum, 2 * half_sum, jnp.where(lock_diff, 2 * half_diff, third))
        first = jnp.where(lock_sum | lock_diff, 0.0, first)
    else:
        first = jnp.where(lock_sum, 2 * half_sum, jnp.where(lock_diff, -2 * half_diff, first))
        third = jnp.where(lock_sum | lock_diff, 0.0, third)
    if not proper:
        third = sign * third
        mid = mid - np.pi / 2
    out = (third, mid, first) if intrinsic else (first, mid, third)
    out = jnp.stack([wrap_angle(out[0]), out[1], wrap_angle(out[2])], axis=-1)
    # NaN for the zero quaternion rather than a valid-looking rotation.
    return jnp.where(jnp.sum(q * q, axis=-1, keepdims=True) == 0, jnp.nan, out)


@public
def euler_to_quaternion(angles, seq: str, degrees: bool = False, scalar_first: bool = False):
    """Quaternion of Euler angles.

    Args:
        angles: ``(..., 3)`` angles, in the order of ``seq``; any values (no range is required).
        seq: ``"XYZ"``-style intrinsic (rotating axes), ``"xyz"``-style extrinsic (fixed axes),
            or digits ``"123"``/``"313"`` (intrinsic). Intrinsic ``"XYZ"`` (Bryant angles) is
            ``R = Rx(a0) @ Ry(a1) @ Rz(a2)``; extrinsic ``"xyz"`` is
            ``R = Rz(a2) @ Ry(a1) @ Rx(a0)``.
        degrees: angles are in degrees.
        scalar_first: return ``(w, x, y, z)``.

    Returns:
        ``(..., 4)`` unit quaternion (product of the three elementary quaternions; no hemisphere
        is imposed, so the map is smooth in the angles).

    Raises:
        ValueError: for an invalid ``seq``, or if ``angles`` is not ``(..., 3)``.
    """
    a, dt = _prep_angles(angles, degrees)
    return from_scalar_last(_euler_to_quat(a, seq), scalar_first).astype(dt)


@public
def euler_to_matrix(angles, seq: str, degrees: bool = False):
    """Rotation matrix of Euler angles.

    Args:
        angles: ``(..., 3)`` angles in the order of ``seq``.
        seq: axis sequence; see :func:`euler_to_quaternion`.
        degrees: angles are in degrees.

    Returns:
        ``(..., 3, 3)`` active rotation matrix, e.g. ``Rz(a0) @ Rx(a1) @ Rz(a2)`` for ``"ZXZ"``
        (Nikravesh's ``A = D C B``, Eq. A.1).
    """
    a, dt = _prep_angles(angles, degrees)
    return _to_matrix(_euler_to_quat(a, seq)).astype(dt)


@public
def quaternion_to_euler(q, seq: str, degrees: bool = False, scalar_first: bool = False):
    """Euler angles of a quaternion (Bernardes & Viollet 2022, with no lock threshold).

    Args:
        q: ``(..., 4)`` quaternion; need not be unit (zero gives NaN).
        seq: axis sequence; see :func:`euler_to_quaternion`.
        degrees: return degrees.
        scalar_first: ``q`` is ``(w, x, y, z)``.

    Returns:
        ``(..., 3)`` angles as scipy's ``as_euler``: first and third in ``[-pi, pi]``; middle in
        ``[0, pi]`` for proper Euler sequences (first axis = third axis) and in
        ``[-pi/2, pi/2]`` for Tait-Bryan sequences.

    Note:
        Every angle is an atan2 of exact polynomial expressions in ``q``: no ``asin``/``acos``
        and no gimbal-lock threshold, so the angles reproduce the rotation to a few eps
        everywhere, at and near gimbal lock included (scipy switches formula at a 1e-7
        threshold, which moves the rotation by up to ~2e-7 rad).

        *At exact gimbal lock* (middle angle 0 or pi for proper sequences, +-pi/2 for
        Tait-Bryan) only the sum or difference of the outer angles is defined. The third angle
        is then returned as 0 and the first carries the whole rotation, like scipy.

        *Gradient rule.* Near lock the gradient is the true derivative (it grows like
        1/distance). Exactly at lock the gradient is that of the branch that fixes the third
        angle at 0: the first angle gets the derivative of the defined sum/difference, the third
        angle gets 0, and the middle angle, which sits at a kink (the edge of its range), gets
        0 (the minimum-norm subgradient). All are finite.
    """
    (q,), dt = as_float(q)
    check_shape(q, (4,), "q")
    parse_seq(seq)
    ang = _quat_to_euler(to_scalar_last(q, scalar_first), seq)
    if degrees:
        ang = jnp.rad2deg(ang)
    return ang.astype(dt)


@public
def matrix_to_euler(R, seq: str, degrees: bool = False):
    """Euler angles of a rotation matrix (via the branch-free quaternion, no ``asin``/``acos``).

    Args:
        R: ``(..., 3, 3)`` active rotation matrix.
        seq: axis sequence; see :func:`euler_to_quaternion`.
        degrees: return degrees.

    Returns:
        ``(..., 3)`` angles in scipy's ranges; see :func:`quaternion_to_euler` for the ranges,
        the behaviour at gimbal lock and the gradient rule.
    """
    (R,), dt = as_float(R)
    check_shape(R, (3, 3), "R")
    parse_seq(seq)
    ang = _quat_to_euler(_from_matrix(R, "shepperd"), seq)
    if degrees:
        ang = jnp.rad2deg(ang)
    return ang.astype(dt)
