"""Elementary functions written with multiplications, additions and selects only: ``rsqrt``,
``reciprocal``, ``sin_cos``, ``atan2`` and ``atan_ratio`` (``atan(t) / t``).

Why: XLA counts roots, divisions and transcendental functions as expensive, and will not
evaluate such a value inside each consumer that reads it more than once; it writes the value in
a loop of its own, which reads the input again. These forms fuse into the one loop of a
conversion, alone and composed. Each states its contract (the largest error against mpmath, in
ulp or eps of the dtype, over its domain; its derivative), which tests/test_numerics.py and the
accuracy tests check. The forms pay on XLA:CPU; on other backends ``rsqrt``, ``reciprocal``,
``sin_cos`` and ``atan2`` are XLA's own operations (``jax.lax.platform_dependent``), with the
same derivative rules. ``atan_ratio`` has no XLA counterpart and is the polynomial everywhere.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ._numerics import exponent_scale, select, signbit, sum_squares, where

# Newton's iteration for 1/sqrt(x): the integer type that reinterprets the float's bits, the
# magic constant of the initial guess (relative error at most 3.4%), and the number of steps
# (the error squares at each: 3.4e-2, 1.7e-3, 4.6e-6, 3.2e-11, 1.5e-21).
_RSQRT_START = {
    jnp.dtype(jnp.float32): (jnp.uint32, 0x5F375A86, 3),
    jnp.dtype(jnp.float64): (jnp.uint64, 0x5FE6EB50C7B537A9, 4),
}


@jax.custom_jvp
def rsqrt(x):
    """`1 / sqrt(x)` for positive, normal, finite float32 or float64 `x`, from
    multiplications and additions only.

    XLA counts `rsqrt`, `sqrt` and division as expensive and will not recompute them inside
    a consumer that reads each result more than once, so a per-rotation scale stacked into
    `(..., 4)` costs a loop of its own, which reads the input again. This form fuses. Initial
    guess from the bits of `x` (Lomont's constants), then Newton steps `y (3 - x y^2) / 2`,
    the last one written as a correction `y + y (1/2 - x y^2 / 2)` so that its rounding
    error is that of a small term: at most 0.63 eps in each dtype (checked against mpmath in
    the tests). Other backends run XLA's `rsqrt`: on a GPU, within 2 ulp in float32 (CUDA's
    `rsqrtf`; 1.0 eps measured on an H200) and 0.63 eps in float64. Outside the domain (zero,
    subnormal, infinite) the result is meaningless; NaN gives NaN.
    """
    return jax.lax.platform_dependent(x, cpu=_rsqrt_newton, default=jax.lax.rsqrt)


def rsqrt_or_zero(x):
    """`rsqrt(x)` for `x` in its domain, and 0 at `x = 0`, with a finite derivative (0) there
    too (double where)."""
    zero = x == 0
    return where(zero, 0.0, rsqrt(where(zero, 1.0, x)))


def rsqrt_shared(x):
    """`1 / sqrt(x)` as XLA's own `sqrt(1 / x)` (two roundings: within 1 ulp; JAX's derivative),
    for a value that many later operations read: XLA counts it expensive and computes it once,
    in a loop of its own, whereas it copies the cheap `rsqrt` above into every reader. In the
    eigen kernel's Jacobi sweeps each rotation's `c` feeds every later rotation, and the copies
    made `matrix_to_quaternion(method="optimal")` five times slower. (`lax.rsqrt` compiles to a
    slower loop on XLA:CPU.)"""
    return jnp.sqrt(1 / x)


def _rsqrt_newton(x):
    uint, magic, steps = _RSQRT_START[jnp.dtype(x.dtype)]
    bits = jax.lax.bitcast_convert_type(x, uint)
    # Unsigned, so that the shift is a logical one: x86 has no vector arithmetic shift of
    # 64-bit integers before AVX-512, and a signed one made the float64 loops scalar.
    half = jax.lax.shift_right_logical(bits, jnp.asarray(1, uint))
    y = jax.lax.bitcast_convert_type(jnp.asarray(magic, uint) - half, x.dtype)
    h = 0.5 * x
    for _ in range(steps - 1):
        y = y * (1.5 - h * y * y)
    return y + y * (0.5 - h * y * y)


@rsqrt.defjvp
def _rsqrt_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    y = rsqrt(x)
    return y, -0.5 * y * y * y * dx


# Newton's iteration for 1/x: the integer type of the float's bits, the magic constant of the
# initial guess (twice the exponent bias: exact for a power of two, relative error at most
# 12.5% otherwise) and the number of steps (the error squares at each: 1.6e-2, 2.4e-4,
# 5.9e-8, 3.5e-15, 1.2e-29).
_RECIPROCAL_START = {
    jnp.dtype(jnp.float32): (jnp.uint32, 0x7F000000, 4),
    jnp.dtype(jnp.float64): (jnp.uint64, 0x7FE0000000000000, 5),
}


@jax.custom_jvp
def reciprocal(x):
    """`1 / x` for positive, normal, finite float32 or float64 `x` whose reciprocal is normal,
    from multiplications and additions only: a division read by several slots of a stacked
    result is, for XLA, a loop of its own (see `rsqrt`); this fuses. Initial guess from the
    bits of `x`, then Newton steps written as corrections `y + y (1 - x y)`: within 1 ulp in
    each dtype (checked against mpmath in the tests), and exact where `x` is a power of two
    (the guess is exact and every correction is zero). Outside the domain the result is
    meaningless; NaN gives NaN."""
    return jax.lax.platform_dependent(x, cpu=_reciprocal_newton, default=lambda x: 1 / x)


def _reciprocal_newton(x):
    uint, magic, steps = _RECIPROCAL_START[jnp.dtype(x.dtype)]
    bits = jax.lax.bitcast_convert_type(x, uint)
    y = jax.lax.bitcast_convert_type(jnp.asarray(magic, uint) - bits, x.dtype)
    for _ in range(steps):
        y = y + y * (1 - x * y)
    return y


@reciprocal.defjvp
def _reciprocal_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    y = reciprocal(x)
    return y, -(y * y) * dx


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


def horner(coeffs, s):
    p = jnp.full_like(s, coeffs[0])
    for c in coeffs[1:]:
        p = p * s + c
    return p


def sin_cos(a):
    """`(sin a, cos a)` from multiplications, additions and selects: `a` reduced by the
    nearest multiple `j pi/2` (exact for `|a|` below 6e3 in float32 and 2e8 in float64), the
    polynomials above on the rest, and the quadrant `j mod 4` chosen by `jnp.where`. XLA fuses
    this into the loop of its consumers (it keeps `jnp.sin` and `jnp.cos`, expensive, in
    loops of their own when their result is read more than once)."""
    return jax.lax.platform_dependent(a, cpu=_sin_cos_poly, default=_sin_cos_xla)


def _sin_cos_xla(a):
    return jnp.sin(a), jnp.cos(a)


def _sin_cos_poly(a):
    size = jnp.dtype(a.dtype).itemsize
    j = jax.lax.round(a * (2 / np.pi), jax.lax.RoundingMethod.TO_NEAREST_EVEN)  # no nested jit
    p1, p2, p3 = _PIO2[size]
    r = ((a - j * p1) - j * p2) - j * p3
    s = r * r
    sin_r = r + r * (s * horner(_SIN_P[size], s))
    cos_r = (1 - 0.5 * s) + (s * s) * horner(_COS_Q[size], s)
    quadrant = j - 4 * jnp.floor(0.25 * j)  # 0, 1, 2, 3 (exact)
    odd = (quadrant == 1) | (quadrant == 3)
    sin_a = where(odd, cos_r, sin_r)
    cos_a = where(odd, sin_r, cos_r)
    sin_a = where(quadrant >= 2, -sin_a, sin_a)
    cos_a = where((quadrant == 1) | (quadrant == 2), -cos_a, cos_a)
    return sin_a, cos_a


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
def atan_ratio(u):
    """`atan(t) / t` for `u = t^2` in `[0, 1]`: the polynomial `_ATAN_RATIO`. Its derivative is
    that of the same polynomial, evaluated as one (a second Horner loop on the derivative's
    coefficients rather than JAX's transpose of the first, which is longer code)."""
    return horner(_ATAN_RATIO[jnp.dtype(u.dtype).itemsize], u)


@atan_ratio.defjvp
def _atan_ratio_jvp(primals, tangents):
    (u,), (du,) = primals, tangents
    coeffs = _ATAN_RATIO[jnp.dtype(u.dtype).itemsize]
    top = len(coeffs) - 1
    slope = horner([c * (top - i) for i, c in enumerate(coeffs[:-1])], u)
    return atan_ratio(u), slope * du


# --- a polynomial atan2 ----------------------------------------------------------------------
# XLA:CPU's atan2 dominated Euler extraction (three per rotation); this branch-free version
# fuses into the surrounding loop (see the performance page). It is within about 2 ulp of the
# correctly rounded value in both dtypes, which keeps the Euler backward error within its
# bounds (tests/test_core_oracle.py).
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
# pi/4 = hi + lo, hi with three trailing zero bits (Cody & Waite): k hi is exact for the octant
# index k in 0..4, so k pi/4 = k hi + k lo to about twice the dtype's precision.
_QUARTER_PI = {
    4: (0.785398006439209, 1.5695823663008923e-07),
    8: (0.7853981633974483, 3.061616997868383e-17),
}
_TAN_PI_8 = 0.41421356237309503


@jax.custom_jvp
def atan2(y, x):
    """`atan2(y, x)` for float32/float64, branch-free; 0 (not NaN) at `x = y = 0`.

    Signed zeros follow IEEE `atan2` except at the origin, which gives 0 with a zero
    derivative (the minimum-norm subgradient: the function has no limit there).
    """
    return jax.lax.platform_dependent(y, x, cpu=_atan2_poly, default=_atan2_xla)


def _atan2_xla(y, x):
    return where((x == 0) & (y == 0), jnp.zeros_like(x), jnp.arctan2(y, x))


def _atan2_poly(y, x):
    size = jnp.dtype(x.dtype).itemsize
    ax, ay = jnp.abs(x), jnp.abs(y)
    swap = ay > ax
    # where, not jnp.minimum/maximum: a NaN operand must reach the result.
    mn, mx = where(swap, ax, ay), where(swap, ay, ax)
    big = mn > _TAN_PI_8 * mx
    num = where(big, mn - mx, mn)
    den = where(big, mn + mx, mx)
    # A reciprocal and a product rather than one division (one more rounding, +0.1 ulp on
    # average): u is used several times below, and XLA:CPU materialises a division with several
    # uses in a loop of its own, while the product fuses (one pass over memory fewer).
    u = num * (1 / where(den == 0, 1, den))  # x = y = 0: u = 0
    s = u * u
    p = jnp.full_like(s, _ATAN_P[size][0])
    for c in _ATAN_P[size][1:]:
        p = p * s + c
    r = u + u * (s * p)
    xneg = signbit(x)
    k = select(big, 1, 0, x.dtype)  # the octant index, as a float (exact)
    k = where(swap, 2 - k, k)  # atan2 = pi/2 - (...) above the diagonal
    k = where(xneg, 4 - k, k)  # pi - (...) for x < 0
    sign = select(swap != xneg, -1, 1, x.dtype)
    hi, lo = _QUARTER_PI[size]
    a = k * hi + (k * lo + sign * r)
    a = where(signbit(y), -a, a)
    return where((ax == 0) & (ay == 0), jnp.zeros_like(a), a)


@atan2.defjvp
def _atan2_jvp(primals, tangents):
    # The exact derivative, (x dy - y dx) / (x^2 + y^2); 0 at the origin.
    # x and y are scaled by a power of two s first (exact), so that x^2 + y^2 cannot underflow:
    # it is s (xs dy - ys dx) / (xs^2 + ys^2), about 1 / |(x, y)| at any scale. The reciprocal
    # by rsqrt (xs^2 + ys^2 is in [1, 8) or 0): the rule then fuses into its consumers' loop.
    (y, x), (dy, dx) = primals, tangents
    xs, ys, s, _ = scaled_pair(x, y)
    r2 = xs * xs + ys * ys
    zero = r2 == 0
    r = rsqrt(where(zero, 1.0, r2))
    return atan2(y, x), (xs * dy - ys * dx) * where(zero, 0.0, s * (r * r))


def hypot(*xs):
    """`sqrt(sum x^2)` of a vector given by its components (per-element arrays), at any scale:
    scaled by a power of two first (exact), so that `(1e-160, 0)` gives `1e-160`, and the root
    as `m2 rsqrt(m2)`, which fuses with its readers (a root or a sum over a stacked axis is a
    loop of its own on XLA:CPU). Zero gives 0 with a zero gradient (the cone's minimum-norm
    subgradient; double where); an infinite or NaN component gives NaN.

    Derivative: `sum_i u_i dx_i`, `u` the unit vector of the scaled components (a rule, equal
    to JAX's derivative of this code): JAX's multiplies by the scale and by its inverse in
    turn, which underflows for the small components of a vector near the bottom of the normal
    range (a gradient of 0 for a component of `1e-38` in float32)."""
    return _hypot(tuple(xs))


def _hypot_parts(xs):
    s, inv = exponent_scale(*xs)
    ys = [x * s for x in xs]
    m2 = sum_squares(ys)  # at least eps^2 unless 0 or not finite: rsqrt's domain
    r = rsqrt_or_zero(m2)  # rsqrt(inf) is NaN
    # the outer where: the second derivative stays finite at 0, where the scaled tangents are
    # large (their squares may overflow)
    return ys, r, where(m2 == 0, 0.0, m2 * r) * inv


@jax.custom_jvp
def _hypot(xs):
    return _hypot_parts(xs)[2]


@_hypot.defjvp
def _hypot_jvp(primals, tangents):
    (xs,), (dxs,) = primals, tangents
    ys, r, n = _hypot_parts(xs)
    return n, sum((y * r) * dx for y, dx in zip(ys, dxs, strict=True))


def scaled_pair(u, v):
    """`(u s, v s, s, 1 / s)` for the power of two `s` (exact, no derivative) that brings the
    larger of `|u|`, `|v|` into `[1, 2)`: their squares then neither underflow nor
    overflow."""
    s, inv = exponent_scale(u, v)
    return u * s, v * s, s, inv
