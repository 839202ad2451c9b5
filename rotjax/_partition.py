"""Coordinate partitioning of a constraint Jacobian (Nikravesh, App. C).

For `m` constraints `Phi(q) = 0` on `n` coordinates, L-U factorisation with full pivoting
of the `m x n` Jacobian `Phi_q` picks `m` well-conditioned columns as the dependent
(basic) coordinates `u` and leaves the other `n - m` as the independent (nonbasic) ones
`v`. With the rows and columns permuted, `P Phi_q Q = L [U1 U2]`, so
`Phi_u = L U1` and `Phi_v = L U2` (Eqs. C.1, C.2) and the influence-coefficient matrix is

    H = -U1^-1 U2 = -Phi_u^-1 Phi_v                                     (Eqs. C.3, C.4)

(`L` cancels). Differentiating `Phi(q) = 0` gives `Phi_u du + Phi_v dv = 0`, hence
`du = H dv` (C.5) and `u_dot = H v_dot` (C.6).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from ._numerics import as_float, eps, public, where


class Partition(NamedTuple):
    """Result of [`partition_coordinates`][rotjax.partition_coordinates] (all arrays share the batch
    shape `...`).

    Attributes:
        dependent: `(..., m)` integer column indices of the dependent coordinates `u`, in
            pivot order.
        independent: `(..., n - m)` integer column indices of the independent coordinates
            `v`, in the order of the columns of `influence`.
        influence: `(..., m, n - m)` `H = -Phi_u^-1 Phi_v`, so that `du = H dv` and
            `u_dot = H v_dot`.
        rank: `(...)` integer number of pivots above the tolerance.
    """

    dependent: jax.Array
    independent: jax.Array
    influence: jax.Array
    rank: jax.Array


def _swap(x, i, j, axis):
    """Swap entries `i` (static) and `j` (`(...)`, traced) of `x` along `axis`."""
    size = x.shape[axis]
    idx = jnp.arange(size).reshape((1,) * j.ndim + (size,))
    jj = j[..., None]
    perm = where(idx == i, jj, where(idx == jj, i, idx))  # (..., size)
    if axis == -2:
        return jnp.take_along_axis(x, perm[..., :, None], axis=-2)
    if x.ndim == perm.ndim:
        return jnp.take_along_axis(x, perm, axis=-1)
    return jnp.take_along_axis(x, perm[..., None, :], axis=-1)


def _eliminate(A, rows, cols):
    """Gaussian elimination with full pivoting on `(..., m, n)` `A` (unrolled, static `m`).

    Returns the upper-trapezoidal factor `U` (the eliminated part below the diagonal is
    zeroed), the row and column permutations and the pivots `U[p, p]`.
    """
    m, n = A.shape[-2:]
    lead = (1,) * (A.ndim - 2)
    r_idx = jnp.arange(m).reshape(lead + (m, 1))
    c_idx = jnp.arange(n).reshape(lead + (1, n))
    pivots = []
    for p in range(m):
        # Largest |entry| of the remaining submatrix A[p:, p:] (first one on ties).
        score = where((r_idx >= p) & (c_idx >= p), jnp.abs(A), -1.0)
        flat = jnp.argmax(score.reshape(*A.shape[:-2], m * n), axis=-1)
        r, c = flat // n, flat % n
        A = _swap(_swap(A, p, r, -2), p, c, -1)
        rows = _swap(rows, p, r, -1)
        cols = _swap(cols, p, c, -1)
        piv = A[..., p, p]
        # Double where: a zero pivot (a rank-deficient remainder) must not send inf or NaN
        # into the values or the gradient; its multipliers are then 0.
        zero = piv == 0
        mult = A[..., p + 1 :, p] / where(zero, 1.0, piv)[..., None]
        mult = where(zero[..., None], 0.0, mult)
        below = A[..., p + 1 :, :] - mult[..., :, None] * A[..., p : p + 1, :]
        below = below.at[..., :, p].set(0.0)
        A = jnp.concatenate([A[..., : p + 1, :], below], axis=-2)
        pivots.append(piv)
    return A, rows, cols, jnp.stack(pivots, axis=-1)


@public
def partition_coordinates(jacobian: ArrayLike, tol: float | None = None) -> Partition:
    """Split coordinates into dependent and independent ones by L-U with full pivoting.

    Args:
        jacobian: `(..., m, n)` constraint Jacobian `Phi_q` with `m <= n` (rows:
            constraints; columns: coordinates).
        tol: pivot tolerance, a scalar or `(...)`; `None` (default) uses
            `max(m, n) * eps * max|Phi_q|` per batch element (`eps` of the dtype).

    Returns:
        A `Partition` named tuple `(dependent, independent, influence, rank)`:
            `dependent` `(..., m)` column indices of `u` (in pivot order), `independent`
            `(..., n - m)` those of `v`, `influence` `(..., m, n - m)`
            `H = -Phi_u^-1 Phi_v` (Nikravesh Eq. C.4) with `du = H dv` and `u_dot = H v_dot`
            (C.5, C.6), and `rank` `(...)` the number of leading pivots whose magnitude
            exceeds `tol`. Each pivot is the largest remaining entry, so the first dependent
            coordinate is the column of the largest `|Phi_q|` entry: for the Euler-parameter
            constraint `2 e^T` it is the largest `|e_i|`.

    Note:
        *Rank-deficient Jacobians* (`rank = r < m`): full pivoting moves the `m - r`
        redundant constraints to the bottom, as in the appendix. Then only `dependent[:r]`
        are determined by the constraints; `dependent[r:]` are free, like `independent`.
        `influence[..., :r, :]` gives `du[:r] = H[:r] dv` for motions that keep
        `dependent[r:]` fixed, and `influence[..., r:, :]` is NaN (no `H` exists). A NaN
        in the Jacobian gives NaN influence in its batch element. The tie-break among equal
        magnitudes is the first in row-major order. Gradients of `influence` are those of
        the factorisation computed (the pivot order is piecewise constant).

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        # One constraint x + 2 y - z = 0 on three coordinates (x, y, z).
        part = rj.partition_coordinates(jnp.array([[1.0, 2.0, -1.0]]))
        print(part.dependent, part.independent, part.rank)
        # [1] [0 2] 1
        ```
    """
    (A,), dt = as_float(jacobian)
    if A.ndim < 2:
        raise ValueError(f"jacobian: expected shape (..., m, n), got {tuple(A.shape)}")
    m, n = A.shape[-2:]
    if m > n:
        raise ValueError(f"jacobian: expected m <= n (constraints <= coordinates), got {(m, n)}")
    batch = A.shape[:-2]
    rows = jnp.broadcast_to(jnp.arange(m), batch + (m,))
    cols = jnp.broadcast_to(jnp.arange(n), batch + (n,))
    U, rows, cols, piv = _eliminate(A, rows, cols) if m else (A, rows, cols, A[..., :0, 0])
    if tol is None:
        big = jnp.max(jnp.abs(A), axis=(-2, -1)) if m else jnp.zeros(batch, A.dtype)
        limit = max(m, n) * eps(A.dtype) * big
    else:
        limit = jnp.broadcast_to(jnp.asarray(tol).astype(A.dtype), batch)
    above = jnp.abs(piv) > limit[..., None]
    rank = jnp.sum(jnp.cumprod(above.astype(jnp.int32), axis=-1), axis=-1)
    keep = (
        jnp.arange(m).reshape((1,) * len(batch) + (m,)) < rank[..., None]
    )  # (..., m): leading pivots within the rank
    # H = -U1^-1 U2 by back substitution, with the rows beyond the rank replaced by identity
    # rows and a zero right-hand side (those dependent coordinates held fixed), then set NaN.
    eye = jnp.eye(m, dtype=A.dtype).reshape((1,) * len(batch) + (m, m))
    U1 = where(keep[..., :, None], U[..., :, :m], eye)
    U2 = where(keep[..., :, None], U[..., :, m:], 0.0)
    H = -jax.lax.linalg.triangular_solve(U1, U2, left_side=True, lower=False)
    H = where(keep[..., :, None], H, jnp.nan)
    H = where(jnp.any(jnp.isnan(A), axis=(-2, -1))[..., None, None], jnp.nan, H)
    return Partition(cols[..., :m], cols[..., m:], H.astype(dt), rank)
