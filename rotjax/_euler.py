"""Euler angles in all 12 axis sequences, intrinsic and extrinsic."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ._matrix import _from_matrix
from ._numerics import (
    as_float,
    check_shape,
    from_scalar_last,
    public,
    to_scalar_last,
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


# --- a polynomial atan2 ----------------------------------------------------------------------
# XLA:CPU's atan2 runs at about 10 M/s per core and dominated Euler extraction (three per
# rotation). This branch-free version is measured 10x faster (``python -m rotjax bench``);
# on 20,000 random pairs spanning six decades it is within 1.7 ulp (float32) / 2.0 ulp
# (float64) of the correctly rounded value (XLA's: 1.2 / 1.0), which keeps the Euler backward
# error within its bounds (tests/test_core_oracle.py, the benchmark's error columns).
#
# Reduction: t = min(|x|, |y|) / max(|x|, |y|) in [0, 1]; above tan(pi/8) it is mapped to
# u = (t - 1) / (t + 1) (one division either way), so |u| <= tan(pi/8) and
# atan2 = k pi/4 +- atan(u) for an octant k in 0..4, with k pi/4 split into hi + lo parts so the
# reconstruction adds no more than the final rounding.
# atan(u) = u + u s P(s), s = u^2: P is a Chebyshev fit (mpmath.chebyfit at 50 digits) of
# (atan(u)/u - 1)/s on [0, tan^2(pi/8)], degree 5 for float32 and 11 for float64; max error
# relative to atan(u): 9e-11 and 2e-19, far below half an eps.
_ATAN_P = {
    4: (
        0.050481385120797445, -0.08624676145249494, 0.11071365021884794, -0.14284151193628614,
        0.19999977258688387, -0.333333332792548,
    ),
    8: (
        0.016285756855221028, -0.034570561981427744, 0.04551593220626549, -0.05230454270650244,
        0.05878928997834775, -0.06666424885738255, 0.07692296375032143, -0.09090908753500877,
        0.11111111105155447, -0.14285714285659828, 0.19999999999999804, -0.3333333333333333,
    ),
}  # fmt: skip
_QUARTER_PI = {  # (hi, lo) of k pi/4, k = 0..4, rounded to float32 / float64
    4: (
        (0.0, 0.7853981852531433, 1.5707963705062866, 2.356194496154785, 3.1415927410125732),
        (0.0, -2.1855694143368964e-08, -4.371138828673793e-08, -5.962440319251527e-09,
         -8.742277657347586e-08),
    ),
    8: (
        (0.0, 0.7853981633974483, 1.5707963267948966, 2.356194490192345, 3.141592653589793),
        (0.0, 3.061616997868383e-17, 6.123233995736766e-17, 9.184850993605148e-17,
         1.2246467991473532e-16),
    ),
}  # fmt: skip
_TAN_PI_8 = 0.41421356237309503


@jax.custom_jvp
def _atan2(y, x):
    """``atan2(y, x)`` for float32/float64, branch-free; 0 (not NaN) at ``x = y = 0``.

    Signed zeros follow IEEE ``atan2`` except at the origin, which gives 0 like
    :func:`rotjax._numerics.safe_atan2`.
    """
    size = jnp.dtype(x.dtype).itemsize
    ax, ay = jnp.abs(x), jnp.abs(y)
    swap = ay > ax
    # where, not jnp.minimum/maximum: a NaN operand must reach the result.
    mn, mx = jnp.where(swap, ax, ay), jnp.where(swap, ay, ax)
    big = mn > _TAN_PI_8 * mx
    num = jnp.where(big, mn - mx, mn)
    den = jnp.where(big, mn + mx, mx)
    # A reciprocal and a product rather than one division (one more rounding, +0.1 ulp on
    # average): u is used several times below, and XLA:CPU materialises a division with several
    # uses in a loop of its own, while the product fuses (one pass over memory fewer).
    u = num * (1 / jnp.where(den == 0, 1, den))  # x = y = 0: u = 0
    s = u * u
    p = jnp.full_like(s, _ATAN_P[size][0])
    for c in _ATAN_P[size][1:]:
        p = p * s + c
    r = u + u * (s * p)
    xneg = jnp.signbit(x)
    k = jnp.where(big, 1, 0)
    k = jnp.where(swap, 2 - k, k)  # atan2 = pi/2 - (...) above the diagonal
    k = jnp.where(xneg, 4 - k, k)  # pi - (...) for x < 0
    sign = jnp.where(swap != xneg, -1, 1).astype(x.dtype)
    hi, lo = _QUARTER_PI[size]

    def octant(vals):
        v = jnp.where(k == 1, vals[1], vals[0])
        v = jnp.where(k == 2, vals[2], v)
        v = jnp.where(k == 3, vals[3], v)
        return jnp.where(k == 4, vals[4], v).astype(x.dtype)

    a = octant(hi) + (octant(lo) + sign * r)
    a = jnp.where(jnp.signbit(y), -a, a)
    return jnp.where((ax == 0) & (ay == 0), jnp.zeros_like(a), a)


@_atan2.defjvp
def _atan2_jvp(primals, tangents):
    # The exact derivative, (x dy - y dx) / (x^2 + y^2); 0 at the origin, as safe_atan2.
    (y, x), (dy, dx) = primals, tangents
    r2 = x * x + y * y
    return _atan2(y, x), (x * dy - y * dx) / jnp.where(r2 == 0, 1, r2)


def _euler_to_quat(a, seq):
    axes, intrinsic = parse_seq(seq)
    q0, q1, q2 = (_elementary(ax, a[..., n]) for n, ax in enumerate(axes))
    # intrinsic: R = R_0 R_1 R_2 (rotating axes); extrinsic: R = R_2 R_1 R_0 (fixed axes)
    return _multiply(_multiply(q0, q1), q2) if intrinsic else _multiply(_multiply(q2, q1), q0)


def _inv_pow2(x):
    """``2^-e`` for the exponent ``e`` of ``x`` (``x = m 2^e``, ``1 <= m < 2``), exactly.

    Integer arithmetic on the exponent field rather than ``1 / 2^e`` or ``jnp.frexp`` (a
    division or frexp costs as much as the rest of the Euler extraction, and keeps XLA from
    fusing the scaling into its consumers). Meaningful for normal ``x`` with ``e < emax``; the
    caller returns NaN where the scaled values would not be (zero, subnormal, infinite, NaN).
    """
    info = jnp.finfo(x.dtype)
    ity = {4: jnp.uint32, 8: jnp.uint64}[jnp.dtype(x.dtype).itemsize]
    mant = info.nmant
    bias = (1 << (info.nexp - 1)) - 1
    exp_mask = ((1 << info.nexp) - 1) << mant
    field = jax.lax.bitcast_convert_type(x, ity) & jnp.asarray(exp_mask, dtype=ity)
    return jax.lax.bitcast_convert_type(jnp.asarray(2 * bias << mant, dtype=ity) - field, x.dtype)


def _hypot(u, v):
    """``sqrt(u^2 + v^2)`` with a finite (zero) gradient at the origin (double where).

    Written on the two scalars rather than as ``safe_norm`` of a stacked pair: XLA:CPU turns
    that reduction into separate loops.
    """
    sq = u * u + v * v
    zero = sq == 0
    return jnp.where(zero, 0.0, jnp.sqrt(jnp.where(zero, 1.0, sq)))


def _quat_to_euler(q, seq):
    """Bernardes & Viollet 2022 (PLoS ONE 17(11): e0276302), Alg. 1, without a lock threshold.

    ``q`` is scalar last and of any non-zero norm (every step is a ratio inside atan2).
    """
    axes, intrinsic = parse_seq(seq)
    # Scale by a power of two (exact) so that the largest component is in [1, 2): the
    # products A conj(C) and A C below then cannot underflow, whatever the norm of q.
    # (Elementwise maxima, not jnp.max: XLA:CPU splits a reduction into loops of its own.)
    q_in = q
    aq = [jnp.abs(q[..., n]) for n in range(4)]
    big = jnp.maximum(jnp.maximum(aq[0], aq[1]), jnp.maximum(aq[2], aq[3]))
    # (A piecewise-constant factor: no derivative flows through it, the angles are invariant.)
    scale = _inv_pow2(jax.lax.stop_gradient(big))
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
    # The scale is applied to a, b, c, d (linear in q; a power of two, so exactly as if applied
    # to q): XLA:CPU then fuses it instead of writing a scaled copy of q.
    a, b, c, d = (scale * t for t in (a, b, c, d))
    hyp_cd, hyp_ab = _hypot(c, d), _hypot(a, b)
    # With A = a + ib and C = c + id the outer angles are half_sum -+ half_diff =
    # arg(A) -+ arg(C) = arg(A conj(C)) and arg(A C): one atan2 each, already in [-pi, pi]
    # (no wrap), and one rounding less than subtracting two atan2 results.
    # Exactly at gimbal lock only one combination of the outer angles is defined. There the
    # angle that ends up *third* in the output is set to 0, as scipy does; this is an equality
    # test (up to underflow), not a threshold, so angles near lock keep the exact formula. The
    # zero factor is replaced by (the conjugate of) the other one, which gives exactly that:
    # e.g. C := conj(A) turns arg(A conj(C)) into 2 arg(A) and arg(A C) into arg(|A|^2) = 0.
    # "Zero" means below 4x the smallest normal number: q is scaled so that the other factor
    # is at least 0.35, so every product with it stays normal (XLA:CPU flushes subnormals to
    # zero, which would otherwise leave atan2(0, 0) for a C of 1e-310). The rotation moves by
    # less than 1e-307 rad (float64) / 5e-38 rad (float32) against the exact formula.
    tiny = 4 * float(jnp.finfo(q.dtype).tiny)
    lock_sum = (jnp.abs(c) < tiny) & (jnp.abs(d) < tiny)  # mid 0 (proper) / +pi/2 (Tait-Bryan)
    lock_diff = (jnp.abs(a) < tiny) & (jnp.abs(b) < tiny)  # mid pi (proper) / -pi/2 (T-B)
    flip = 1 if intrinsic else -1  # extrinsic keeps `first`, intrinsic keeps `third`
    c, d = jnp.where(lock_sum, a, c), jnp.where(lock_sum, flip * b, d)
    a, b = jnp.where(lock_diff, c, a), jnp.where(lock_diff, flip * d, b)
    # The three atan2 are evaluated as one, on (..., 3) arrays in the output order: the result
    # is then written by one elementwise loop (stacking three separate results and moving the
    # axis last made XLA:CPU emit a transposing loop that LLVM did not vectorize in float64).
    num = {"first": b * c - a * d, "mid": hyp_cd, "third": b * c + a * d}
    den = {"first": a * c + b * d, "mid": hyp_ab, "third": a * c - b * d}
    order = ("third", "mid", "first") if intrinsic else ("first", "mid", "third")
    ang = _atan2(
        jnp.stack([num[n] for n in order], axis=-1), jnp.stack([den[n] for n in order], axis=-1)
    )
    factor = {"first": 1.0, "mid": 2.0, "third": 1.0 if proper else float(sign)}
    shift = {"first": 0.0, "mid": 0.0 if proper else -np.pi / 2, "third": 0.0}
    out = ang * np.array([factor[n] for n in order], dtype=ang.dtype) + np.array(
        [shift[n] for n in order], dtype=ang.dtype
    )
    # The substitution makes the zeroed angle (the last in the output: `first` of an intrinsic
    # sequence, `third` of an extrinsic one) an atan2 of (x - x, ...), which a fused
    # multiply-add can leave at a rounding error instead of 0: set it exactly.
    out = jnp.where((lock_sum | lock_diff)[..., None] & np.array([False, False, True]), 0.0, out)
    # NaN for the zero quaternion rather than a valid-looking rotation, and for a NaN or
    # infinite component (the power-of-two scaling would otherwise zero the finite ones).
    x, y, z, w = (q_in[..., n] for n in range(4))
    n2 = x * x + y * y + z * z + w * w  # a scalar sum, not jnp.sum: see _hypot
    return jnp.where(((n2 == 0) | ~jnp.isfinite(n2))[..., None], jnp.nan, out)


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
        threshold, which moves the rotation by up to ~2e-7 rad). The atan2 is a branch-free
        polynomial within about 1 ulp of the correctly rounded value, with the exact
        derivative.

        *At exact gimbal lock* (middle angle 0 or pi for proper sequences, +-pi/2 for
        Tait-Bryan; "exact" up to underflow: within 1e-307 rad in float64, 5e-38 rad in
        float32) only the sum or difference of the outer angles is defined. The third angle
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
