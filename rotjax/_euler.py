"""Euler angles in all 12 axis sequences, intrinsic and extrinsic."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.typing import ArrayLike

from ._elementary import atan2, rsqrt, rsqrt_or_zero, scaled_pair, sin_cos
from ._matrix import selected_column
from ._numerics import (
    as_float,
    cast,
    check_shape,
    exponent_scale_of_bits,
    float_bits,
    from_scalar_last,
    max_abs_bits,
    per_slot,
    public,
    select,
    spread,
    stack,
    stack_matrix,
    to_scalar_last,
    unstack,
    where,
)
from ._quaternion import quat_multiply
from ._shepperd import entries

_VALID = (
    "three axis letters with no two consecutive equal, all uppercase for intrinsic "
    "(rotating axes, e.g. 'ZXZ', 'XYZ') or all lowercase for extrinsic (fixed axes, e.g. "
    "'zxz', 'xyz'), or three digits 1-3 for intrinsic (e.g. '313', '123')"
)


@functools.cache
def parse_seq(seq) -> tuple[tuple[int, int, int], bool]:
    """Parse an Euler sequence string.

    Returns:
        `(axes, intrinsic)`: axis indices (0=x, 1=y, 2=z) in the order the angles are given,
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
    """Scalar-last quaternion of a rotation by `angle` about coordinate axis `axis`."""
    s, c = sin_cos(angle / 2)  # multiplications and additions: fuses into its consumers
    z = jnp.zeros_like(s)
    comps = [z, z, z, c]
    comps[axis] = s
    return stack(comps, unit=True)


def _euler_to_quat(a, seq):
    """The product of the three elementary quaternions; its readers in this trace that want its
    matrix get `_euler_to_matrix(a, seq)`, the product of the axis matrices (the same rotation,
    without the quaternion's products repeated in each entry)."""
    axes, intrinsic = parse_seq(seq)
    q0, q1, q2 = (_elementary(ax, angle) for ax, angle in zip(axes, unstack(a), strict=True))
    # intrinsic: R = R_0 R_1 R_2 (rotating axes); extrinsic: R = R_2 R_1 R_0 (fixed axes)
    q = (
        quat_multiply(quat_multiply(q0, q1), q2)
        if intrinsic
        else quat_multiply(quat_multiply(q2, q1), q0)
    )
    return stack(unstack(q), unit=True, matrix_form=functools.partial(_euler_to_matrix, a, seq))


def _axis_matrix(axis: int, angle):
    """Rows of the active rotation matrix by `angle` about coordinate axis `axis`, with
    Python's `0` and `1` for its constant entries (dropped from the products below)."""
    s, c = sin_cos(angle)
    i, j = (axis + 1) % 3, (axis + 2) % 3
    m = [[0, 0, 0], [0, 0, 0], [0, 0, 0]]
    m[axis][axis] = 1
    m[i][i], m[i][j], m[j][i], m[j][j] = c, -s, s, c
    return m


def _product(a, b):
    """3x3 product of rows of entries, where Python's `0` and `1` cost nothing."""

    def const(x, k):
        return isinstance(x, int) and x == k

    def mul(u, v):
        if const(u, 0) or const(v, 0):
            return 0
        return v if const(u, 1) else u if const(v, 1) else u * v

    def add(u, v):
        return v if const(u, 0) else u if const(v, 0) else u + v

    return [
        [
            add(add(mul(a[r][0], b[0][c]), mul(a[r][1], b[1][c])), mul(a[r][2], b[2][c]))
            for c in range(3)
        ]
        for r in range(3)
    ]


def _euler_to_matrix(a, seq):
    """The product of the three axis matrices (Nikravesh 1988, App. A: `A = D C B` for z-x-z),
    in the order of `seq`. Written with the sines and cosines of the angles themselves, not
    through the quaternion: each entry of a stacked result computes every entry (see
    ``stack``), and the quaternion's products and normalisation would be repeated nine times."""
    axes, intrinsic = parse_seq(seq)
    m0, m1, m2 = (_axis_matrix(ax, angle) for ax, angle in zip(axes, unstack(a), strict=True))
    R = _product(_product(m0, m1), m2) if intrinsic else _product(_product(m2, m1), m0)
    return stack_matrix(R)


def _lifted(u, v):
    """The pair times `2^k` (exact; `k` half the exponent range), where both are below
    `2^(2-k)`, and the inverse factor: their squares, and their products with components of
    order 1 down to eps, then stay normal."""
    k = 2 ** (jnp.finfo(u.dtype).nexp - 2)
    low = jnp.maximum(jnp.abs(u), jnp.abs(v)) < 2.0 ** (2 - k)
    f = select(low, 2.0**k, 1.0, u.dtype)
    return u * f, v * f, select(low, 2.0**-k, 1.0, u.dtype)


def _modulus(u, v, inv):
    """`|(u, v)| inv` for a lifted pair (`_lifted`): `m2 rsqrt(m2)`, whose root fuses with its
    readers; 0 at the origin. (At exact lock the product with `inv` may flush to 0: the
    angle it measures is below the normal range there.)"""
    m2 = u * u + v * v
    zero = m2 == 0  # double where: finite derivatives (0) at the origin, of any order
    return where(zero, 0.0, m2 * rsqrt(where(zero, 1.0, m2))) * inv


@functools.cache
def _algorithm_axes(seq):
    """`(i, j, k, sign)` of Bernardes & Viollet's algorithm for `seq`: the axes of the
    equivalent extrinsic sequence (an intrinsic sequence equals the reversed extrinsic one with
    the angles in reverse order), `k` the remaining axis for a proper Euler sequence, and
    `sign` +1 if `(i, j, k)` is an even permutation of `(x, y, z)`, else -1."""
    axes, intrinsic = parse_seq(seq)
    i, j, k = axes[::-1] if intrinsic else axes
    if i == k:
        k = 3 - i - j
    return i, j, k, (i - j) * (j - k) * (k - i) // 2


def _abcd(x, y, z, w, seq):
    """The two complex factors `A = a + ib` and `C = c + id` of Bernardes & Viollet's
    algorithm (before any scaling), linear in the quaternion's components: used for `q` and,
    in the derivative, for its tangent."""
    i, j, k, s = _algorithm_axes(seq)
    v = (x, y, z)
    if is_proper(seq):
        return w, v[i], v[j], s * v[k]
    return w - v[j], v[i] + s * v[k], v[j] + w, s * v[k] - v[i]


def is_proper(seq) -> bool:
    """Whether `seq` is a proper Euler sequence (first and third axes equal, e.g. `"ZXZ"`)
    rather than a Tait-Bryan one (three distinct axes); raises `ValueError` like
    `parse_seq` for an invalid `seq`."""
    axes, _ = parse_seq(seq)
    return axes[0] == axes[2]


@functools.cache
def _layout(seq):
    """Per output angle (in `seq`'s order): its name, factor and shift (see below)."""
    _, intrinsic = parse_seq(seq)
    proper = is_proper(seq)
    factor = {"first": 1.0, "mid": 2.0, "third": 1.0 if proper else float(_algorithm_axes(seq)[3])}
    shift = {"first": 0.0, "mid": 0.0 if proper else -np.pi / 2, "third": 0.0}
    order = ("third", "mid", "first") if intrinsic else ("first", "mid", "third")
    return order, tuple(factor[n] for n in order), tuple(shift[n] for n in order)


def _factors(x, y, z, w, seq):
    """From the quaternion's components (arrays of any one shape): the power-of-two scale, the
    scaled factors `(a, b, c, d)`, the lock masks (see `_substitute`), and where the
    quaternion is zero or not finite."""
    _, intrinsic = parse_seq(seq)
    # Scale by a power of two (exact) so that the largest component is in [1, 2): the
    # products A conj(C) and A C below then cannot underflow, whatever the norm of q.
    # (Elementwise maxima, not jnp.max: XLA:CPU splits a reduction into loops of its own.
    # A piecewise-constant factor: no derivative flows through it, the angles are invariant.)
    big = max_abs_bits(x, y, z, w)
    scale, _ = exponent_scale_of_bits(big, x.dtype)
    # The scale is applied to a, b, c, d (linear in q; a power of two, so exactly as if applied
    # to q): XLA:CPU then fuses it instead of writing a scaled copy of q.
    a, b, c, d = (scale * t for t in _abcd(x, y, z, w, seq))
    # Exactly at gimbal lock only one combination of the outer angles is defined. There the
    # angle that ends up *third* in the output is set to 0, as scipy does; this is an equality
    # test (up to underflow), not a threshold, so angles near lock keep the exact formula. The
    # zero factor is replaced by (the conjugate of) the other one, which gives exactly that:
    # e.g. C := conj(A) turns arg(A conj(C)) into 2 arg(A) and arg(A C) into arg(|A|^2) = 0.
    # "Zero" means below 4x the smallest normal number: q is scaled so that the other factor
    # is at least 0.35, so every product with it stays normal (XLA:CPU flushes subnormals to
    # zero, which would otherwise leave atan2(0, 0) for a C of 1e-310). The rotation moves by
    # less than 1e-307 rad (float64) / 5e-38 rad (float32) against the exact formula.
    tiny = 4 * float(jnp.finfo(x.dtype).tiny)
    lock_sum = (jnp.abs(c) < tiny) & (jnp.abs(d) < tiny)  # mid 0 (proper) / +pi/2 (Tait-Bryan)
    lock_diff = (jnp.abs(a) < tiny) & (jnp.abs(b) < tiny)  # mid pi (proper) / -pi/2 (T-B)
    locks = (lock_sum, lock_diff, 1 if intrinsic else -1)  # extrinsic keeps `first`
    # NaN for the zero quaternion rather than a valid-looking rotation, and for a NaN or
    # infinite component (the power-of-two scaling would otherwise zero the finite ones).
    bad = (big == 0) | (big >= float_bits(np.inf, x.dtype))  # NaN's bits are above inf's
    return scale, (a, b, c, d), locks, bad


def _substitute(abcd, locks):
    """At exact lock, the zero factor replaced by (the conjugate of) the other (see above)."""
    a, b, c, d = abcd
    lock_sum, lock_diff, flip = locks
    c, d = where(lock_sum, a, c), where(lock_sum, flip * b, d)
    a, b = where(lock_diff, c, a), where(lock_diff, flip * d, b)
    return a, b, c, d


def quat_to_euler(q, seq):
    """Euler angles (output order) of a scalar-last quaternion of any non-zero norm."""
    return _quat_to_euler_stacked(tuple(unstack(q)), seq)


def _slots(x, values):
    """``(1, ..., 1, 3)`` constants (one per output angle), of ``x``'s rank and dtype."""
    return jnp.asarray(values, x.dtype).reshape((1,) * (x.ndim - 1) + (3,))


@functools.partial(jax.custom_jvp, nondiff_argnums=(1,))
def _quat_to_euler_stacked(q, seq):
    """Bernardes & Viollet 2022 (PLoS ONE 17(11): e0276302), Alg. 1, without a lock threshold,
    on the four components of ``q`` (scalar last, any non-zero norm: every step is a ratio
    inside atan2); the ``(..., 3)`` angles in output order.
    """
    # Each output element computes its angle from the whole quaternion, spread over the three
    # slots first (see `spread`): one vectorised loop and one atan2 per output element, of the
    # arguments selected for its slot, whether q is read from memory or computed by the
    # operation before.
    q = tuple(spread(x, 3) for x in q)
    _, (a, b, c, d), locks, bad = _factors(*q, seq)
    # With A = a + ib and C = c + id the outer angles are half_sum -+ half_diff =
    # arg(A) -+ arg(C) = arg(A conj(C)) and arg(A C): one atan2 each, already in [-pi, pi]
    # (no wrap), and one rounding less than subtracting two atan2 results (after the lock
    # substitution). The middle angle is 2 atan2(|C|, |A|) (before it).
    # A factor below 2^(2-k) (k half the exponent range) is multiplied by 2^k (exact; the angles
    # do not change): with only q scaled, the product of a small component of A and one of a
    # tiny C could underflow (b c = 1e-7 * 1e-303) and lose a turn that the others do not carry.
    la, lb, ia = _lifted(a, b)
    lc, ld, ic = _lifted(c, d)
    sa, sb, sc, sd = _substitute((la, lb, lc, ld), locks)
    mid_num, mid_den = _modulus(lc, ld, ic), _modulus(la, lb, ia)  # |C|, |A| (before it)
    num = {"first": sb * sc - sa * sd, "mid": mid_num, "third": sb * sc + sa * sd}
    den = {"first": sa * sc + sb * sd, "mid": mid_den, "third": sa * sc - sb * sd}
    order, factor, shift = _layout(seq)
    num, den = per_slot([num[n] for n in order]), per_slot([den[n] for n in order])
    out = atan2(num, den) * _slots(num, factor) + _slots(num, shift)
    # The substitution makes the zeroed (last) angle an atan2 of (x - x, ...), which a fused
    # multiply-add can leave at a rounding error instead of 0: it is set exactly.
    last = _slots(num, (0, 0, 1)) == 1
    out = where(last & (locks[0] | locks[1]), 0.0, out)
    return where(bad, jnp.nan, out)


@functools.cache
def _abcd_patterns(seq):
    """`(4, 4)`: row `t` holds the coefficients of `(a, b, c, d)[t]` on `(x, y, z, w)`."""
    return np.array(_abcd(*np.eye(4), seq), dtype=float)


def _euler_jacobian(comps, seq):
    """The three angles' derivatives (in output order) with respect to the quaternion's four
    components: ``J[k][i]``, per-rotation arrays, such that ``d angle_k = sum_i J[k][i] dq_i``.

    `comps` are the quaternion's four components (per-rotation arrays, any norm).

    The outer angles are arg(A) -+ arg(C), with derivatives Im(conj(A) dA) / |A|^2 and
    Im(conj(C) dC) / |C|^2 (after the lock substitution); the middle one is
    2 atan2(|C|, |A|), with derivative 2 (|A| d|C| - |C| d|A|) / (|A|^2 + |C|^2) and
    d|C| = C.dC / |C|, taken as 0 where C = 0 (at lock the middle angle sits at the edge of its
    range, a kink: the minimum-norm subgradient, as a root's). Near lock one factor is tiny:
    each is scaled by its own power of two before it is squared (`scaled_pair`), so the
    derivatives, about 1 / distance, stay right down to the lock threshold rather than
    dividing by an underflowed |C|^2.

    No division or root (XLA computes such an expensive value, read by a broadcast, in a loop
    of its own): every entry is per-rotation arithmetic, which the rule's transpose computes
    once per rotation in the one loop that writes the cotangent.
    """
    scale, (a, b, c, d), locks, bad = _factors(*comps, seq)
    va, vb, sa, ka = scaled_pair(a, b)  # the factors before the substitution, for the middle
    vc, vd, sc, kc = scaled_pair(c, d)

    # Reciprocals and roots by rsqrt (multiplications and additions: see its note): each sum
    # of squares below is at least 1 (a scaled pair, or q scaled by _factors), so every
    # derivative is computed once per rotation in the loop that writes the cotangent.
    m2a, m2c = va * va + vb * vb, vc * vc + vd * vd
    ia, ic = rsqrt_or_zero(m2a), rsqrt_or_zero(m2c)  # 1 / |(u, v)| of the scaled pairs
    lock_sum, lock_diff, flip = locks
    pa, pc = scale * sa * ia * ia, scale * sc * ic * ic  # 1 / |A|^2, 1 / |C|^2 (scaled)
    na, nc = m2a * ia * ka, m2c * ic * kc  # |A|, |C|
    yt = rsqrt(a * a + b * b + c * c + d * d)
    t = scale * yt * yt
    order, factor, _ = _layout(seq)
    locked = lock_sum | lock_diff
    zero = jnp.zeros_like(va)
    jac = [[], [], []]
    for ea, eb, ec, ed in _abcd_patterns(seq).T:  # d(a, b, c, d) / dq_i: 0 or +-1
        # Im and Re of conj(A) dA and conj(C) dC, from the scaled pairs
        im_a, re_a = _combine(((eb, va), (-ea, vb)), zero), _combine(((ea, va), (eb, vb)), zero)
        im_c, re_c = _combine(((ed, vc), (-ec, vd)), zero), _combine(((ec, vc), (ed, vd)), zero)
        # A lock replaces the zero factor by (the conjugate of) the other (see _substitute):
        # only A or C can be zero, as |A|^2 + |C|^2 >= 1.
        j_a = where(lock_diff, flip * im_c * pc, im_a * pa)
        j_c = where(lock_sum, flip * im_a * pa, im_c * pc)
        j_mid = (na * (ic * re_c) - nc * (ia * re_a)) * t
        parts = {"first": j_a - j_c, "mid": j_mid, "third": j_a + j_c}
        parts = [f * parts[n] if f != 1 else parts[n] for n, f in zip(order, factor, strict=True)]
        # The angle set to 0 at lock: the substitution already makes its J cancel exactly,
        # unless a fused multiply-add rounds the two halves differently (as in the forward).
        parts[2] = where(locked, 0.0, parts[2])
        for k in range(3):
            jac[k].append(where(bad, 0.0, parts[k]))
    return jac


def _combine(terms, zero):
    """`sum(c x)` over `(c, x)` for Python numbers `c`: zero terms left out, `+-1` unmultiplied
    (`zero` where every `c` is 0)."""
    out = None
    for c, x in terms:
        if c != 0:
            x = x if c == 1 else -x if c == -1 else c * x
            out = x if out is None else out + x
    return zero if out is None else out


@_quat_to_euler_stacked.defjvp
def _quat_to_euler_stacked_jvp(seq, primals, tangents):
    # The exact derivative of the code above (see _euler_jacobian).
    (q,), (dq,) = primals, tangents
    rows = [sum(j * x for j, x in zip(row, dq, strict=True)) for row in _euler_jacobian(q, seq)]
    return _quat_to_euler_stacked(q, seq), jnp.concatenate(rows, axis=-1)


def _matrix_to_euler(R, seq):
    """quaternion_to_euler's extraction of the Shepperd column of ``R``: the angles do not
    depend on the quaternion's norm or sign, so the column needs no normalisation (NaN for a
    non-rotation, through its diagonal)."""
    c, _ = selected_column(tuple(entries(R)))
    return _quat_to_euler_stacked(tuple(c), seq)


@public
def euler_to_quaternion(
    angles: ArrayLike, seq: str, degrees: bool = False, scalar_first: bool = False
) -> Array:
    """Quaternion of Euler angles.

    Args:
        angles: `(..., 3)` angles, in the order of `seq`; any values (no range is required).
        seq: `"XYZ"`-style intrinsic (rotating axes), `"xyz"`-style extrinsic (fixed axes),
            or digits `"123"`/`"313"` (intrinsic). Intrinsic `"XYZ"` (Bryant angles) is
            `R = Rx(a0) @ Ry(a1) @ Rz(a2)`; extrinsic `"xyz"` is
            `R = Rz(a2) @ Ry(a1) @ Rx(a0)`.
        degrees: angles are in degrees.
        scalar_first: return `(w, x, y, z)`.

    Returns:
        `(..., 4)` unit quaternion (product of the three elementary quaternions; no hemisphere
            is imposed, so the map is smooth in the angles).

    Raises:
        ValueError: for an invalid `seq`, or if `angles` is not `(..., 3)`.

    Examples:
        ```python
        import rotjax as rj

        q = rj.euler_to_quaternion([90.0, 0.0, 0.0], "ZYX", degrees=True)  # yaw 90 deg
        print(q.round(6))
        # [0.       0.       0.707107 0.707107]
        ```
    """
    a, dt = _prep_angles(angles, degrees)
    return cast(from_scalar_last(_euler_to_quat(a, seq), scalar_first), dt)


@public
def euler_to_matrix(angles: ArrayLike, seq: str, degrees: bool = False) -> Array:
    """Rotation matrix of Euler angles.

    Args:
        angles: `(..., 3)` angles in the order of `seq`.
        seq: axis sequence; see [`euler_to_quaternion`][rotjax.euler_to_quaternion].
        degrees: angles are in degrees.

    Returns:
        `(..., 3, 3)` active rotation matrix, e.g. `Rz(a0) @ Rx(a1) @ Rz(a2)` for `"ZXZ"`
            (Nikravesh's `A = D C B`, Eq. A.1).

    Examples:
        ```python
        import rotjax as rj

        print(rj.euler_to_matrix([90.0, 90.0, 0.0], "ZXZ", degrees=True).round(6))
        # [[0. 0. 1.]
        #  [1. 0. 0.]
        #  [0. 1. 0.]]
        ```
    """
    a, dt = _prep_angles(angles, degrees)
    return cast(_euler_to_matrix(a, seq), dt)


@public
def quaternion_to_euler(
    q: ArrayLike, seq: str, degrees: bool = False, scalar_first: bool = False
) -> Array:
    """Euler angles of a quaternion (Bernardes & Viollet 2022, with no lock threshold).

    Args:
        q: `(..., 4)` quaternion; need not be unit (zero gives NaN).
        seq: axis sequence; see [`euler_to_quaternion`][rotjax.euler_to_quaternion].
        degrees: return degrees.
        scalar_first: `q` is `(w, x, y, z)`.

    Returns:
        `(..., 3)` angles as scipy's `as_euler`: first and third in `[-pi, pi]`; middle in
            `[0, pi]` for proper Euler sequences (first axis = third axis) and in
            `[-pi/2, pi/2]` for Tait-Bryan sequences.

    Note:
        Every angle is an atan2 of exact polynomial expressions in `q`: no `asin`/`acos`
        and no gimbal-lock threshold, so the angles reproduce the rotation to a few eps
        everywhere, at and near gimbal lock included (scipy switches formula at a 1e-7
        threshold, which moves the rotation by up to ~2e-7 rad). The atan2 is a branch-free
        polynomial within about 1 ulp of the correctly rounded value, with the exact
        derivative.

        *At exact gimbal lock* (middle angle 0 or pi for proper sequences, +-pi/2 for
        Tait-Bryan; "exact" up to underflow: within 1e-307 rad in float64, 5e-38 rad in
        float32) only the sum or difference of the outer angles is defined. The third angle
        is then returned as 0 and the first carries the whole rotation, like scipy.

        *Scale.* `q` need not be unit: any finite non-zero scale gives the same angles (an
        exact power-of-two prescaling); zero, infinite or NaN components give NaN.

        *Gradient rule.* Near lock the gradient is the true derivative (it grows like
        1/distance), finite at every distance down to the lock threshold (each factor is
        scaled by its own power of two before it is squared). Exactly at lock the gradient is
        that of the branch that fixes the third angle at 0: the first angle gets the derivative
        of the defined sum/difference, the third angle gets 0, and the middle angle, which sits
        at a kink (the edge of its range), gets 0 (the minimum-norm subgradient). All are
        finite.

    Examples:
        ```python
        import rotjax as rj

        q = rj.euler_to_quaternion([30.0, 20.0, 10.0], "ZYX", degrees=True)
        print(rj.quaternion_to_euler(q, "ZYX", degrees=True).round(4))
        # [30. 20. 10.]
        print(rj.quaternion_to_euler(q, "xyz", degrees=True).round(4))  # extrinsic, reversed
        # [10. 20. 30.]
        ```
    """
    (q,), dt = as_float(q)
    check_shape(q, (4,), "q")
    parse_seq(seq)
    ang = quat_to_euler(to_scalar_last(q, scalar_first), seq)
    if degrees:
        ang = jnp.rad2deg(ang)
    return cast(ang, dt)


@public
def matrix_to_euler(R: ArrayLike, seq: str, degrees: bool = False) -> Array:
    """Euler angles of a rotation matrix (via the branch-free quaternion, no `asin`/`acos`).

    Args:
        R: `(..., 3, 3)` active rotation matrix.
        seq: axis sequence; see [`euler_to_quaternion`][rotjax.euler_to_quaternion].
        degrees: return degrees.

    Returns:
        `(..., 3)` angles in scipy's ranges; see [`quaternion_to_euler`][rotjax.quaternion_to_euler]
            for the ranges, the behaviour at gimbal lock and the gradient rule.

    Note:
        Computed as [`quaternion_to_euler`][rotjax.quaternion_to_euler] of
        [`matrix_to_quaternion`][rotjax.matrix_to_quaternion]'s `"shepperd"` quaternion: scale
        invariant (any `s R`, `s > 0`, from 1e-30 to 1e30 in float32, 1e-300 to 1e300 in float64),
        NaN for the zero matrix or a non-finite entry. The gradient is the derivative of the
        function computed, in every 3x3 direction, on and off SO(3) (see
        [`matrix_to_quaternion`][rotjax.matrix_to_quaternion]), with the gimbal-lock rule of
        [`quaternion_to_euler`][rotjax.quaternion_to_euler].

    Examples:
        ```python
        import rotjax as rj

        R = rj.euler_to_matrix([0.3, 1.1, -0.7], "313")  # Nikravesh's z-x-z angles
        print(rj.matrix_to_euler(R, "313").round(6))
        # [ 0.3  1.1 -0.7]
        ```
    """
    (R,), dt = as_float(R)
    check_shape(R, (3, 3), "R")
    parse_seq(seq)
    ang = _matrix_to_euler(R, seq)
    if degrees:
        ang = jnp.rad2deg(ang)
    return cast(ang, dt)
