"""Lie calculus of SO(3) and SE(3): hat and vee, the Jacobians of the exponential map, and the
exponential, logarithm and adjoint of rigid transforms.

Tangent vectors of SE(3) are scipy's exponential coordinates `xi = [rotvec, v]` (rotation
first); transforms are `(..., 4, 4)` homogeneous matrices `[[R, t], [0, 1]]` acting on column
vectors. Every coefficient that is a ratio of vanishing quantities at the zero rotation
(`(t - sin t) / t^3` and its kind) is a power series in `t^2` below `t^2 = 1`, summed to
rounding for the dtype, and the closed form above it, where its cancellation costs at most a
few ulps: values and derivatives of every order are finite and accurate at 0, at `1e-300` and
up to pi.
"""

from __future__ import annotations

import functools
import math
from fractions import Fraction

import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from . import _numerics as nm
from ._elementary import rsqrt
from ._matrix import shepperd_parts
from ._numerics import (
    as_float,
    cast,
    check_shape,
    cross3,
    dot3,
    eps,
    public,
    stack,
    stack_matrix,
    sum_squares,
    unstack,
    unstack_matrix,
    where,
)
from ._quaternion import quat_to_matrix_parts, scaled_vector_parts
from ._rotvec import FEW, exp_coeffs, rotvec_scale

# --- power series in x = t^2 ------------------------------------------------------------------

# Below this t^2 a coefficient is its series; at and above it, its closed form.
_CUT = 1.0


def _bernoulli(n: int) -> list[Fraction]:
    """Bernoulli numbers ``B_0 .. B_n`` (``B_1 = -1/2``), exact."""
    b = [Fraction(1)]
    for m in range(1, n + 1):
        b.append(-sum(math.comb(m + 1, k) * b[k] for k in range(m)) / (m + 1))
    return b


_B = _bernoulli(40)
_N = 20  # terms generated; each dtype keeps as many as it needs at t^2 = _CUT

# (t - sin t) / t^3 = sum_k (-1)^k t^2k / (2k+3)!
_SERIES_B = [Fraction((-1) ** k, math.factorial(2 * k + 3)) for k in range(_N)]
# (t^2 + 2 cos t - 2) / (2 t^4) = sum_k (-1)^k t^2k / (2k+4)!
_SERIES_D = [Fraction((-1) ** k, math.factorial(2 * k + 4)) for k in range(_N)]
# (2t - 3 sin t + t cos t) / (2 t^5) = sum_k (-1)^k (k+1) t^2k / (2k+5)!
_SERIES_F = [Fraction((-1) ** k * (k + 1), math.factorial(2 * k + 5)) for k in range(_N)]
# (1 - (t/2) cot(t/2)) / t^2 = sum_k (-1)^k B_(2k+2) t^2k / (2k+2)!  (radius 2 pi)
_SERIES_E = [(-1) ** k * _B[2 * k + 2] / math.factorial(2 * k + 2) for k in range(_N)]


def _terms(series, dtype) -> list[float]:
    """The leading terms of ``series`` whose sum at ``t^2 = _CUT`` is its value to a sixteenth
    of an ulp (the first term left out, and every later one, is below that bound)."""
    bound = eps(dtype) / 16 * abs(series[0])
    n = next(
        i
        for i in range(len(series))
        if all(abs(series[j]) * _CUT**j < bound for j in range(i, len(series)))
    )
    return [float(c) for c in series[:n]]


def _series(x, series, closed):
    """A coefficient that is ``series`` in ``x = t^2`` below ``_CUT`` and ``closed(x)`` at and
    above it. Both branches see a harmless argument where they are not taken (double where), so
    neither sends inf or NaN into the derivatives."""
    small = x < _CUT
    xs = where(small, x, 0.0)
    out = 0.0
    for c in reversed(_terms(series, x.dtype)):  # Horner
        out = out * xs + c
    return where(small, out, closed(where(small, _CUT, x)))


def _recip(x):
    """``1 / x`` for ``x >= 1`` (the closed forms' ``t^2``): :func:`rotjax._elementary.rsqrt`
    squared, multiplications and additions only, so that a result built on it stays one loop
    (XLA writes a division read by several components in a loop of its own)."""
    r = rsqrt(x)
    y = r * r
    return y + y * (1 - x * y)  # a Newton step: to about half an ulp


def _b_coeff(x, k, c):
    """``(t - sin t) / t^3`` for ``x = t^2``, given ``k = sin(t/2)/t`` and ``c = cos(t/2)``."""
    return _series(x, _SERIES_B, lambda xb: (1 - 2 * k * c) * _recip(xb))


# --- building blocks ----------------------------------------------------------------------


def _combo_rows(alpha, beta, gamma, p):
    """The rows (per-rotation entries) of ``alpha I + beta hat(p) + gamma p p^T`` from the
    components of ``p`` (every SO(3) Jacobian has this form, since
    ``hat(p)^2 = p p^T - |p|^2 I``)."""
    x, y, z = p
    return (
        (alpha + gamma * x * x, -beta * z + gamma * x * y, beta * y + gamma * x * z),
        (beta * z + gamma * y * x, alpha + gamma * y * y, -beta * x + gamma * y * z),
        (-beta * y + gamma * z * x, beta * x + gamma * z * y, alpha + gamma * z * z),
    )


def _combo(alpha, beta, gamma, p):
    """:func:`_combo_rows` as a ``(..., 3, 3)`` matrix."""
    return stack_matrix(_combo_rows(alpha, beta, gamma, p))


def _combo_apply(alpha, beta, gamma, p, u):
    """``(alpha I + beta hat(p) + gamma p p^T) @ u`` without forming the matrix, on the
    components of ``p`` and ``u`` (lists of three per-rotation arrays)."""
    (p0, p1, p2), (u0, u1, u2) = p, u
    gpu = gamma * (p0 * u0 + p1 * u1 + p2 * u2)
    cross = (p1 * u2 - p2 * u1, p2 * u0 - p0 * u2, p0 * u1 - p1 * u0)
    return [alpha * a + beta * b + gpu * c for a, b, c in zip(u, cross, p, strict=True)]


def _so3_coeffs(p):
    """``(x, k, c, a, b)`` of a rotation vector (its three components): ``x = t^2``,
    ``k = sin(t/2)/t``, ``c = cos(t/2)``, ``a = (1 - cos t)/t^2``, ``b = (t - sin t)/t^3``."""
    x = sum_squares(p)
    k, c = exp_coeffs(x)
    return x, k, c, 2 * k * k, _b_coeff(x, k, c)


def _inverse_coeffs(beta, p):
    """``(alpha, beta, gamma)`` of :func:`_combo` for the inverse SO(3) Jacobians of ``p``
    (its components): ``beta = -1/2`` for the left one, ``1/2`` for the right one."""
    g, e = _inv_coeffs(p)
    return g, jnp.full_like(g, beta), e


def _inv_coeffs(p):
    """``(g, e)`` of the inverse Jacobians of a rotation vector (its three components):
    ``g = (t/2) cot(t/2)`` and ``e = (1 - g) / t^2``."""
    x = sum_squares(p)
    k, c = exp_coeffs(x)
    g = c * (0.5 * _recip_k(k))
    return g, _series(x, _SERIES_E, lambda xb: (1 - g) * _recip(xb))


def _recip_k(k):
    """``1 / k`` for ``k = sin(t/2)/t`` (``1/pi <= k <= 1/2`` on ``[0, pi]``; 0 at ``t = 2 pi``,
    where the inverse Jacobians are singular)."""
    r = rsqrt(k * k)  # 1 / |k|
    y = (r * r) * k
    return y + y * (1 - k * y)  # a Newton step: to about half an ulp


def exp_parts(p, r):
    """``exp([p, r])`` on components: the unit quaternion ``(k p, c)`` of ``exp(p)`` (four
    parts) and ``t = Jl(p) r`` (three). The one SE(3) exponential: :func:`se3_exp` and
    ``RigidTransform.from_exp_coords``."""
    _, k, c, a, b = _so3_coeffs(p)
    return [k * x for x in p] + [c], _combo_apply(2 * k * c, a, b, p, r)


def log_parts(q, t):
    """``[p, Jl(p)^-1 t]`` with ``p = log(q)`` (angle in ``[0, pi]``) on components: ``q`` a
    quaternion of any non-zero norm (four parts), ``t`` three. The one SE(3) logarithm:
    :func:`se3_log` and ``RigidTransform.as_exp_coords``."""
    p = list(scaled_vector_parts(tuple(q), rotvec_scale, False))
    g, e = _inv_coeffs(p)
    return p + _combo_apply(g, -0.5 * jnp.ones_like(g), e, p, t)


def _left(p):
    """SO(3) left Jacobian of ``p`` (its components) as ``(alpha, beta, gamma)`` of
    :func:`_combo`."""
    x, k, c, a, b = _so3_coeffs(p)
    return 2 * k * c, a, b  # alpha = 1 - b t^2 = sin(t)/t


def _so3_jacobian(p, coeffs):
    """``_combo(*coeffs(parts), parts)`` for the components ``parts`` of ``p``."""
    parts = unstack(p)
    return _combo(*coeffs(parts), parts).reshape(*p.shape[:-1], 3, 3)


def _blocks(tl, bl, br, shape):
    """The ``(..., 6, 6)`` block lower-triangular matrix ``[[tl, 0], [bl, br]]`` of the rows
    (per-rotation entries) of three 3x3 blocks, for a batch of shape ``shape``. Up to ``FEW``
    rotations stacked row by row (``stack_matrix(concat=True)``), which XLA counts at fewer
    flops (see ``FEW``); a larger batch by a select, which XLA:CPU vectorises."""
    zero = jnp.zeros_like(tl[0][0])
    rows = [(*row, zero, zero, zero) for row in tl]
    rows += [(*u, *v) for u, v in zip(bl, br, strict=True)]
    return stack_matrix(rows, concat=math.prod(shape) <= FEW).reshape(*shape, 6, 6)


def _matmul_rows(A, B):
    """The product of two 3x3 matrices given by their rows of per-rotation entries."""
    return [
        [A[i][0] * B[0][j] + A[i][1] * B[1][j] + A[i][2] * B[2][j] for j in range(3)]
        for i in range(3)
    ]


def _hat_rows(v):
    x, y, z = v
    zero = jnp.zeros_like(x)
    return ((zero, -z, y), (z, zero, -x), (-y, x, zero))


def _q_rows(p, r):
    """The rows of the bottom-left block ``Q(p, r)`` of the SE(3) left Jacobian of
    ``xi = [p, r]`` (components). Barfoot's ``Q = 1/2 R + b (P R + R P + P R P)
    + d (P P R + R P P - 3 P R P) + f (P R P P + P P R P)``, with ``P = hat(p)``,
    ``R = hat(r)``, ``b = (t - sin t)/t^3``, ``d = (t^2 + 2 cos t - 2)/(2 t^4)`` and
    ``f = (2t - 3 sin t + t cos t)/(2 t^5)``, reduced by ``P R = r p^T - (p.r) I``,
    ``P R P = -(p.r) P`` and ``P P = p p^T - t^2 I`` to ``(1/2 - 2 d t^2) R + (3d - b)(p.r) P
    + b (r p^T + p r^T) + d (p w^T - w p^T) - 2 f (p.r) p p^T + 2 (f t^2 - b)(p.r) I``,
    ``w = p x r``: a few terms an entry instead of seven matrix products (the antisymmetric
    ones gathered into one hat)."""
    x, k, c, a, b = _so3_coeffs(p)
    d = _series(x, _SERIES_D, lambda xb: (1 - 4 * k * k) * (0.5 * _recip(xb)))
    # 2 - 3 sin t / t + cos t, with sin t / t = 2 k c and cos t = c^2 - (k t)^2.
    f = _series(
        x, _SERIES_F, lambda xb: (2 - 6 * k * c + c * c - k * k * xb) * (0.5 * _recip(xb * xb))
    )
    pr, w = dot3(p, r), cross3(p, r)
    s_i, e = 2 * (f * x - b) * pr, -2 * f * pr
    # The antisymmetric terms as one hat: p w^T - w p^T = hat(w x p).
    wp = cross3(w, p)
    s_r, s_p = 0.5 - 2 * d * x, (3 * d - b) * pr
    H = _hat_rows([s_r * rk + s_p * pk + d * wk for rk, pk, wk in zip(r, p, wp, strict=True)])

    def entry(i, j):
        out = b * (r[i] * p[j] + p[i] * r[j]) + e * p[i] * p[j]
        return out + s_i if i == j else out + H[i][j]

    return [[entry(i, j) for j in range(3)] for i in range(3)]


def _se3_jacobian(xi, sign, inverse):
    """The SE(3) left Jacobian of ``sign * xi`` (``sign = -1``: the right one), or its inverse,
    on the components of ``xi``."""
    parts = unstack(xi)
    if sign < 0:
        parts = [-x for x in parts]
    p, r = parts[:3], parts[3:]
    Q = _q_rows(p, r)
    if inverse:
        J = _combo_rows(*_inverse_coeffs(-0.5, p), p)
        Q = [[-x for x in row] for row in _matmul_rows(_matmul_rows(J, Q), J)]
    else:
        J = _combo_rows(*_left(p), p)
    return _blocks(J, Q, J, xi.shape[:-1])


# --- public functions ---------------------------------------------------------------------


@public
def hat(v: ArrayLike) -> Array:
    """The matrix of a tangent vector: `so(3)` for 3-vectors, `se(3)` for 6-vectors.

    Args:
        v: `(..., 3)` vector `w`, or `(..., 6)` exponential coordinates `[w, v]` (rotation
            first).

    Returns:
        `(..., 3, 3)` skew-symmetric `[w]x` with `hat(w) @ u == cross(w, u)`, or `(..., 4, 4)`
            twist `[[hat(w), v], [0, 0]]`, whose matrix exponential is
            [`se3_exp`][rotjax.se3_exp].

    Examples:
        ```python
        import rotjax as rj

        print(rj.hat([1.0, 2.0, 3.0]))
        # [[ 0. -3.  2.]
        #  [ 3.  0. -1.]
        #  [-2.  1.  0.]]
        print(rj.hat([0.0, 0.0, 1.0, 4.0, 5.0, 6.0]))
        # [[ 0. -1.  0.  4.]
        #  [ 1.  0. -0.  5.]
        #  [-0.  0.  0.  6.]
        #  [ 0.  0.  0.  0.]]
        ```
    """
    (v,), dt = as_float(v)
    if v.ndim < 1 or v.shape[-1] not in (3, 6):
        raise ValueError(f"v: expected shape (..., 3) or (..., 6), got {tuple(v.shape)}")
    if v.shape[-1] == 3:
        return cast(nm.skew(v), dt)
    top = jnp.concatenate([nm.skew(v[..., :3]), v[..., 3:, None]], axis=-1)
    out = jnp.concatenate([top, jnp.zeros_like(top[..., :1, :])], axis=-2)
    return cast(out, dt)


@public
def vee(M: ArrayLike) -> Array:
    """Inverse of [`hat`][rotjax.hat]: the vector of an `so(3)` or `se(3)` matrix.

    Args:
        M: `(..., 3, 3)` matrix, or `(..., 4, 4)` twist `[[W, v], [*, *]]`.

    Returns:
        `(..., 3)` vector of the antisymmetric part, `(M - M^T) / 2` (so `vee(hat(w)) == w`
            and a symmetric part is ignored), or `(..., 6)` `[vee(W), v]`; the bottom row of a
            4x4 matrix is not read.

    Examples:
        ```python
        import rotjax as rj

        print(rj.vee(rj.hat([1.0, 2.0, 3.0])))
        # [1. 2. 3.]
        print(rj.vee(rj.hat([0.0, 0.0, 1.0, 4.0, 5.0, 6.0])))
        # [0. 0. 1. 4. 5. 6.]
        ```
    """
    (M,), dt = as_float(M)
    if M.ndim < 2 or M.shape[-2:] not in ((3, 3), (4, 4)):
        raise ValueError(f"M: expected shape (..., 3, 3) or (..., 4, 4), got {tuple(M.shape)}")
    w = nm.axial(M[..., :3, :3])
    if M.shape[-1] == 4:
        w = jnp.concatenate([w, M[..., :3, 3]], axis=-1)
    return cast(w, dt)


@public
def so3_left_jacobian(rotvec: ArrayLike) -> Array:
    """Left Jacobian of the SO(3) exponential: `exp(p + d) = exp(Jl(p) d) exp(p)` to first order
    in `d`.

    Args:
        rotvec: `(..., 3)` rotation vector `p` (any angle).

    Returns:
        `(..., 3, 3)` `Jl = I + (1 - cos t)/t^2 P + (t - sin t)/t^3 P^2`, `P = hat(p)`,
            `t = |p|`. It is also the matrix `V` that maps `v` to the translation in
            [`se3_exp`][rotjax.se3_exp], and `Jl(p) = R(p) Jr(p)`.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        print(rj.so3_left_jacobian([0.0, 0.0, jnp.pi / 2]).round(3))
        # [[ 0.637 -0.637  0.   ]
        #  [ 0.637  0.637  0.   ]
        #  [ 0.     0.     1.   ]]
        ```
    """
    (p,), dt = as_float(rotvec)
    check_shape(p, (3,), "rotvec")
    return cast(_so3_jacobian(p, _left), dt)


@public
def so3_right_jacobian(rotvec: ArrayLike) -> Array:
    """Right Jacobian of the SO(3) exponential: `exp(p + d) = exp(p) exp(Jr(p) d)` to first order
    in `d`.

    Args:
        rotvec: `(..., 3)` rotation vector `p` (any angle).

    Returns:
        `(..., 3, 3)` `Jr = Jl(-p) = Jl(p)^T = I - (1 - cos t)/t^2 P + (t - sin t)/t^3 P^2`.
            In the body frame, the angular velocity of `exp(p(s))` is `Jr(p) dp/ds`.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        p = jnp.array([0.0, 0.0, jnp.pi / 2])
        print(rj.so3_right_jacobian(p).round(3))
        # [[ 0.637  0.637  0.   ]
        #  [-0.637  0.637  0.   ]
        #  [ 0.     0.     1.   ]]
        print(jnp.allclose(rj.so3_right_jacobian(p), rj.so3_left_jacobian(p).T))
        # True
        ```
    """
    (p,), dt = as_float(rotvec)
    check_shape(p, (3,), "rotvec")

    def coeffs(parts):
        alpha, a, b = _left(parts)
        return alpha, -a, b

    return cast(_so3_jacobian(p, coeffs), dt)


@public
def so3_left_jacobian_inverse(rotvec: ArrayLike) -> Array:
    """Inverse of [`so3_left_jacobian`][rotjax.so3_left_jacobian].

    Args:
        rotvec: `(..., 3)` rotation vector `p`; the inverse exists for angles other than
            non-zero multiples of 2 pi (the logarithm's angles, `[0, pi]`, are all fine).

    Returns:
        `(..., 3, 3)` `Jl^-1 = I - P/2 + (1 - (t/2) cot(t/2))/t^2 P^2`: the derivative of
            `log(exp(d) exp(p))` in `d` at 0.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        p = jnp.array([0.3, -0.2, 1.0])
        J = rj.so3_left_jacobian(p)
        print(jnp.allclose(rj.so3_left_jacobian_inverse(p) @ J, jnp.eye(3), atol=1e-6))
        # True
        ```
    """
    (p,), dt = as_float(rotvec)
    check_shape(p, (3,), "rotvec")
    return cast(_so3_jacobian(p, functools.partial(_inverse_coeffs, -0.5)), dt)


@public
def so3_right_jacobian_inverse(rotvec: ArrayLike) -> Array:
    """Inverse of [`so3_right_jacobian`][rotjax.so3_right_jacobian].

    Args:
        rotvec: `(..., 3)` rotation vector `p` (angle not a non-zero multiple of 2 pi).

    Returns:
        `(..., 3, 3)` `Jr^-1 = I + P/2 + (1 - (t/2) cot(t/2))/t^2 P^2`: the derivative of
            `log(exp(p) exp(d))` in `d` at 0.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        p = jnp.array([0.3, -0.2, 1.0])
        J = rj.so3_right_jacobian(p)
        print(jnp.allclose(rj.so3_right_jacobian_inverse(p) @ J, jnp.eye(3), atol=1e-6))
        # True
        ```
    """
    (p,), dt = as_float(rotvec)
    check_shape(p, (3,), "rotvec")
    return cast(_so3_jacobian(p, functools.partial(_inverse_coeffs, 0.5)), dt)


def homogeneous(q, t, zero=None):
    """``[[R(q), t], [0, 1]]`` from the components of a unit quaternion ``q`` and of ``t``;
    ``zero``: the bottom row's zeros (default exact zeros)."""
    e = unstack_matrix(quat_to_matrix_parts(*q))
    zero = jnp.zeros_like(t[0]) if zero is None else zero
    rows = [e[3 * i : 3 * i + 3] + [t[i]] for i in range(3)] + [[zero, zero, zero, zero + 1]]
    return stack_matrix(rows)


@public
def se3_exp(xi: ArrayLike) -> Array:
    """Exponential map of SE(3): exponential coordinates to a 4x4 rigid transform.

    Args:
        xi: `(..., 6)` exponential coordinates `[p, v]`, scipy's order (rotation vector
            first), so that `se3_exp(xi)` is `RigidTransform.from_exp_coords(xi).as_matrix()`
            and the matrix exponential of `hat(xi)`.

    Returns:
        `(..., 4, 4)` `[[R, t], [0, 1]]` with `R = exp(hat(p))` and `t = Jl(p) v`
            ([`so3_left_jacobian`][rotjax.so3_left_jacobian]).

    Note:
        Exact derivatives of every order at `p = 0` (the coefficients are series in `|p|^2`
        there, see the module notes).

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        # a quarter turn about z while moving 1 along x: a screw motion
        T = rj.se3_exp(jnp.array([0.0, 0.0, jnp.pi / 2, 1.0, 0.0, 0.0]))
        print(T.round(3))
        # [[-0.    -1.     0.     0.637]
        #  [ 1.    -0.     0.     0.637]
        #  [ 0.     0.     1.     0.   ]
        #  [ 0.     0.     0.     1.   ]]
        ```
    """
    (xi,), dt = as_float(xi)
    check_shape(xi, (6,), "xi")
    xi = unstack(xi)
    return cast(homogeneous(*exp_parts(xi[:3], xi[3:])), dt)


@public
def se3_log(T: ArrayLike) -> Array:
    """Logarithm map of SE(3): a 4x4 rigid transform to its exponential coordinates.

    Args:
        T: `(..., 4, 4)` homogeneous transform `[[R, t], [0, 1]]` (the bottom row is not
            read).

    Returns:
        `(..., 6)` `[p, v]` with `p` the rotation vector of `R` (angle in `[0, pi]`) and
            `v = Jl(p)^-1 t`, so that `se3_exp(se3_log(T)) == T` to rounding, at and near 180
            degrees too.

    Note:
        `p` is [`matrix_to_rotvec`][rotjax.matrix_to_rotvec]'s (through the quaternion, exact
        near 180 degrees); the derivatives are finite everywhere and exact at the identity. At
        exactly 180 degrees the log jumps between `p` and `-p` (the cut of the map).

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        xi = jnp.array([0.0, 0.0, jnp.pi / 2, 1.0, 0.0, 0.0])
        print(rj.se3_log(rj.se3_exp(xi)).round(6))
        # [ 0.        0.        1.570796  1.       -0.        0.      ]
        ```
    """
    (T,), dt = as_float(T)
    check_shape(T, (4, 4), "T")
    e = unstack_matrix(T)  # T read once: R's nine entries and t's three
    q = shepperd_parts(tuple(e[4 * i + j] for i in range(3) for j in range(3)))
    return cast(stack(log_parts(q, [e[3], e[7], e[11]])), dt)


@public
def se3_adjoint(T: ArrayLike) -> Array:
    """Adjoint matrix of a rigid transform, in the `[rotation, translation]` order.

    Args:
        T: `(..., 4, 4)` homogeneous transform `[[R, t], [0, 1]]`.

    Returns:
        `(..., 6, 6)` `Ad_T = [[R, 0], [hat(t) R, R]]`, with
            `se3_exp(Ad_T @ xi) == T @ se3_exp(xi) @ inv(T)`. A covariance `S` of a right
            perturbation `T exp(d)` is `Ad_T S Ad_T^T` as a left one, `exp(d') T`.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        T = rj.se3_exp(jnp.array([0.1, 0.2, 0.3, 1.0, 2.0, 3.0]))
        xi = jnp.array([0.3, -0.1, 0.2, 0.5, 0.0, -0.4])
        lhs = rj.se3_exp(rj.se3_adjoint(T) @ xi)
        print(jnp.allclose(lhs, T @ rj.se3_exp(xi) @ jnp.linalg.inv(T), atol=1e-5))
        # True
        ```
    """
    (T,), dt = as_float(T)
    check_shape(T, (4, 4), "T")
    e = unstack_matrix(T)
    R, t = [e[4 * i : 4 * i + 3] for i in range(3)], [e[4 * i + 3] for i in range(3)]
    # hat(t) R, column by column: t x (column j of R)
    tR = [cross3(t, [row[j] for row in R]) for j in range(3)]
    return cast(_blocks(R, [[col[i] for col in tR] for i in range(3)], R, T.shape[:-2]), dt)


@public
def se3_left_jacobian(xi: ArrayLike) -> Array:
    """Left Jacobian of the SE(3) exponential: `exp(xi + d) = exp(Jl(xi) d) exp(xi)` to first
    order in `d`.

    Args:
        xi: `(..., 6)` exponential coordinates `[p, v]` (rotation first).

    Returns:
        `(..., 6, 6)` `[[Jl(p), 0], [Q(p, v), Jl(p)]]` in the same order, with `Jl(p)` the
            SO(3) left Jacobian and `Q` the coupling block of Barfoot's *State Estimation for
            Robotics* (his `[v, p]` order swapped): with `P = hat(p)`, `V = hat(v)` and
            `t = |p|`, `Q = V/2 + (t - sin t)/t^3 (PV + VP + PVP)
            + (t^2 + 2 cos t - 2)/(2 t^4) (PPV + VPP - 3 PVP)
            + (2t - 3 sin t + t cos t)/(2 t^5) (PVPP + PPVP)`.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        # at zero rotation: [[I, 0], [hat(v) / 2, I]]
        J = rj.se3_left_jacobian(jnp.array([0.0, 0.0, 0.0, 2.0, 0.0, 0.0]))
        print(J[3:, :3])
        # [[ 0.  0.  0.]
        #  [ 0.  0. -1.]
        #  [ 0.  1.  0.]]
        ```
    """
    (xi,), dt = as_float(xi)
    check_shape(xi, (6,), "xi")
    return cast(_se3_jacobian(xi, 1, False), dt)


@public
def se3_right_jacobian(xi: ArrayLike) -> Array:
    """Right Jacobian of the SE(3) exponential: `exp(xi + d) = exp(xi) exp(Jr(xi) d)` to first
    order in `d`.

    Args:
        xi: `(..., 6)` exponential coordinates `[p, v]` (rotation first).

    Returns:
        `(..., 6, 6)` `Jr(xi) = Jl(-xi)`.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        xi = jnp.array([0.1, 0.2, 0.3, 1.0, 2.0, 3.0])
        print(jnp.allclose(rj.se3_right_jacobian(xi), rj.se3_left_jacobian(-xi)))
        # True
        ```
    """
    (xi,), dt = as_float(xi)
    check_shape(xi, (6,), "xi")
    return cast(_se3_jacobian(xi, -1, False), dt)


@public
def se3_left_jacobian_inverse(xi: ArrayLike) -> Array:
    """Inverse of [`se3_left_jacobian`][rotjax.se3_left_jacobian]: the derivative of
    `log(exp(d) exp(xi))` in `d` at 0.

    Args:
        xi: `(..., 6)` exponential coordinates `[p, v]`; rotation angle not a non-zero
            multiple of 2 pi.

    Returns:
        `(..., 6, 6)` `[[Jl^-1, 0], [-Jl^-1 Q Jl^-1, Jl^-1]]`.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        xi = jnp.array([0.1, 0.2, 0.3, 1.0, 2.0, 3.0])
        J, Ji = rj.se3_left_jacobian(xi), rj.se3_left_jacobian_inverse(xi)
        print(jnp.allclose(Ji @ J, jnp.eye(6), atol=1e-5))
        # True
        ```
    """
    (xi,), dt = as_float(xi)
    check_shape(xi, (6,), "xi")
    return cast(_se3_jacobian(xi, 1, True), dt)


@public
def se3_right_jacobian_inverse(xi: ArrayLike) -> Array:
    """Inverse of [`se3_right_jacobian`][rotjax.se3_right_jacobian]: the derivative of
    `log(exp(xi) exp(d))` in `d` at 0.

    Args:
        xi: `(..., 6)` exponential coordinates `[p, v]`; rotation angle not a non-zero
            multiple of 2 pi.

    Returns:
        `(..., 6, 6)` `Jr(xi)^-1 = Jl(-xi)^-1`.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        xi = jnp.array([0.1, 0.2, 0.3, 1.0, 2.0, 3.0])
        J, Ji = rj.se3_right_jacobian(xi), rj.se3_right_jacobian_inverse(xi)
        print(jnp.allclose(Ji @ J, jnp.eye(6), atol=1e-5))
        # True
        ```
    """
    (xi,), dt = as_float(xi)
    check_shape(xi, (6,), "xi")
    return cast(_se3_jacobian(xi, -1, True), dt)
