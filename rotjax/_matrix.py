"""Rotation matrix -> quaternion: branch-free largest-component extraction and its refinements."""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from ._eigen import nearest_quaternion
from ._elementary import rsqrt
from ._numerics import (
    as_float,
    cast,
    check_shape,
    exponent_scale,
    from_scalar_last,
    public,
    stack,
    sum_squares,
    where,
)
from ._shepperd import entries, k4_columns, select_column

METHODS = ("shepperd", "markley", "optimal")


def _prescaled_matrix(R):
    """The nine entries of ``R`` (row by row) times a power of two ``s`` that brings the largest
    into ``[1, 2)`` (exact), so that no product below overflows or
    underflows; their squared Frobenius norm; whether ``R`` is a candidate rotation (not zero,
    every entry finite); and ``s``. Per-rotation scalars: XLA:CPU applies the scale inside the
    one loop that reads ``R`` (a scaled copy of ``R`` would be a loop of its own)."""
    r = list(R) if isinstance(R, (list, tuple)) else entries(R)  # or the entries already
    # Always the power of two, also for a rotation matrix (s = 1 or 2 there): every step below
    # is exact under it, and one less select keeps XLA:CPU's per-rotation scale function small
    # enough to be inlined into the vectorised loop in float64 too.
    s, _ = exponent_scale(*r)
    r = [x * s for x in r]
    f2 = sum_squares(r)
    return r, f2, (f2 > 0) & (f2 < jnp.inf), s


def _homogeneous_k(R):
    """The columns and diagonal of the homogeneous ``K`` (see
    :func:`rotjax._shepperd.k4_columns`) of the prescaled ``R``, with ``t = |R|_F / sqrt(3)``
    (1 for a rotation matrix, ``s`` for ``s`` times one) on the diagonal, and the scalars of
    ``t``: ``h = |r|^2 / 3``, ``y = rsqrt(h)`` (``t = h y``) and the power of two ``s``. ``t``
    is NaN for a zero or non-finite ``R``, and so is every column
    :func:`rotjax._shepperd.select_column` returns (the NaN is put into the scale, not into a
    copy of ``R``)."""
    r, f2, ok, s = _prescaled_matrix(R)
    h = f2 / 3  # in [1/12, 12] after the prescaling: rsqrt's domain
    y = rsqrt(h)
    cols, diag = k4_columns(r, where(ok, h * y, jnp.nan))
    return cols, diag, (h, y, s)


def selected_column(R):
    """:func:`rotjax._shepperd.select_column` of the prescaled, homogeneous ``K`` of ``R``."""
    cols, diag, _ = _homogeneous_k(R)
    return select_column(cols, diag)


def shepperd_column(R):
    """The selected column of :func:`selected_column`, sign-flipped to ``w >= 0`` and not
    normalised: the quaternion of ``R`` at a norm between ``2 t`` and ``4 t`` for a rotation
    (``t`` of order 1 after the prescaling), for a ``Rotation`` (which stores a quaternion at
    any norm and whose readers prescale) or any consumer that does not need a unit quaternion.
    NaN for a non-rotation, as the column."""
    c, _ = selected_column(R)
    return stack([where(c[3] < 0, -x, x) for x in c])


def _hemisphere_scale(v, sq):
    """``1 / |v|`` (``sq = |v|^2``, away from 0: see :func:`rotjax._shepperd.select_column`),
    negated where ``w < 0``: ``v * scale`` is the unit quaternion with ``w >= 0``. :func:`rsqrt`
    (multiplications and additions only) fuses into the loop that writes the components."""
    s = rsqrt(sq)
    return where(v[3] < 0, -s, s)


def _shepperd(R):
    """The quaternion of :func:`shepperd_parts`, stacked."""
    return stack(shepperd_parts(tuple(entries(R))), unit=True)


def shepperd_parts(R):
    """Shepperd extraction, scalar last, `w >= 0`: the selected column of `K` over its norm.

    Written for XLA:CPU: every step is a per-rotation scalar expression (no reduction over a
    stacked axis); the four components are selected first and the scale `rsqrt(|c|^2)` is
    computed from them; with `rsqrt` (multiplications and additions only) XLA emits a
    single transposing loop that reads the matrix once. JAX differentiates this code: every
    operation has a finite derivative wherever it is reached (the divisor is at least ``t^2``),
    and at a switch of the selected column it is the derivative of the branch taken.
    """
    c, sq = selected_column(R)
    # The norm of the selected column (not 2 sqrt of its diagonal entry, which is cheaper but
    # gives a non-unit result for a non-orthogonal R).
    z = _hemisphere_scale(c, sq)
    return tuple(x * z for x in c)


def _k_times(cols, p):
    """`K p` for the symmetric `K` given by its columns, on per-rotation components."""
    return [sum(cols[i][c] * p[i] for i in range(4)) for c in range(4)]


def _markley(R):
    """Shepperd's quaternion refined by one power-iteration step with `K`, `w >= 0`.

    `K = 4 q q^T` (+ noise) has eigenvalues 4, 0, 0, 0 for a rotation, so one product removes
    the O(sigma) error of the selected column and leaves O(sigma^2). Per-rotation scalar
    expressions throughout, as in `_shepperd` (the Shepperd quaternion is not stacked
    and unstacked in between: that cost a transposing loop).
    """
    cols, diag, _ = _homogeneous_k(R)
    c, _ = select_column(cols, diag)
    # The product of the column as it is: its norm (2t to 4t) keeps K c of order t, and the
    # hemisphere is chosen once, on K c.
    v = _k_times(cols, c)
    k = _hemisphere_scale(v, sum_squares(v))
    return stack([x * k for x in v], unit=True)


def quat_from_matrix(R, method: str):
    if method == "shepperd":
        return _shepperd(R)
    if method == "markley":
        return _markley(R)
    if method == "optimal":
        return nearest_quaternion(R)  # Bar-Itzhack 2000, w >= 0; see rotjax._eigen
    raise ValueError(f"method must be one of {METHODS}, got {method!r}")


@public
def matrix_to_quaternion(
    R: ArrayLike, method: str = "shepperd", scalar_first: bool = False
) -> Array:
    """Quaternion of a rotation matrix, with `w >= 0`.

    Args:
        R: `(..., 3, 3)` active rotation matrix (`v_world = R @ v_body`). A passive
            direction-cosine matrix, as in Kamman's notes, must be transposed first.
        method: how to treat matrices that are not exactly orthogonal:

            * `"shepperd"` (default): branch-free largest-component extraction (Shepperd 1978;
              Baruh/Kamman Eqs. 5-8; Markley 2008). The column of `K = 4 q q^T` with the
              largest diagonal is selected with nested `jnp.where` and normalised once. Exact
              to about 1 eps for rotation matrices; error O(sigma) for noise sigma.
            * `"markley"`: the Shepperd column followed by one power-iteration step with `K`.
              About 30 more flops; brings noisy matrices to within O(sigma^2) of optimal.
            * `"optimal"`: the quaternion of the nearest rotation (Bar-Itzhack 2000): the top
              eigenvector of the symmetric 4x4 `K` by rotjax's elementwise eigen kernel
              (a one-sided Jacobi SVD of `R`, fixed sweeps; no LAPACK). Any input, `det < 0`
              included. Slowest: see the performance page.
        scalar_first: return `(w, x, y, z)`.

    Returns:
        `(..., 4)` unit quaternion with `w >= 0` (at exactly 180 degrees, `w = 0` and the
            sign is that of the selected component; with `"optimal"`, wherever `|w| <= 4 eps`,
            so that the rounding of the input does not flip the sign).

    Note:
        *Scale.* `K` is built homogeneous (its diagonal `1 = |q|^2` replaced by
        `t = |R|_F / sqrt(3)`, which adds `(t - 1) I` and changes no eigenvector), and
        `R` is scaled by the exact power of two that brings its largest entry into `[1, 2)`,
        which adds no rounding: every method gives the same unit quaternion, to a few eps, for `s R`
        as for `R`, for any `s > 0` from 1e-30 to 1e30 (float32) or 1e-300 to 1e300
        (float64). The zero matrix, or any infinite or NaN
        entry, gives NaN (in that batch element only).

        *Singular points.* No sqrt or division is applied to a small number: the selected
        column has squared norm at least `t^2`, so every method is finite and differentiable
        at the identity and at every 180-degree rotation.

        *Gradients.* `jax.grad` and `jax.jvp` give the derivative of the function computed,
        in every 3x3 direction, on and off SO(3): a perturbation `R @ S` with `S`
        symmetric (scaling, shear) moves `"shepperd"` and `"markley"` as it moves their
        formulas. Where the selected column switches (off SO(3) the result jumps there), it
        is the derivative of the branch taken. For the derivative of "the rotation nearest
        to this matrix", which ignores such perturbations to first order, use `"optimal"`: its
        gradient is that of the top eigenvector, finite while the top eigenvalue is simple
        (always, for matrices near a rotation).

    Examples:
        ```python
        import rotjax as rj

        R = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]  # 90 deg about z
        print(rj.matrix_to_quaternion(R).round(6))
        # [0.       0.       0.707107 0.707107]
        print(rj.matrix_to_quaternion(R, scalar_first=True).round(6))
        # [0.707107 0.       0.       0.707107]
        ```
    """
    (R,), dt = as_float(R)
    check_shape(R, (3, 3), "R")
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    return cast(from_scalar_last(quat_from_matrix(R, method), scalar_first), dt)
