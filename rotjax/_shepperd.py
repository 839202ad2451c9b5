"""Shepperd's extraction of a quaternion from a rotation matrix, on per-rotation scalars.

Shared by the conversions (:mod:`rotjax._matrix`) and the eigen kernel (:mod:`rotjax._eigen`),
which builds on it and not the other way round. Every step is a per-rotation scalar expression
(no reduction over a stacked axis), so that XLA:CPU fuses a whole extraction into one loop.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ._numerics import sum_squares, unstack_matrix, where


def entries(R):
    """The nine entries of a ``(..., 3, 3)`` matrix, row by row, as per-rotation arrays."""
    return unstack_matrix(R)


def k4_columns(r, one=1.0):
    """The four columns of ``K = 4 q q^T + (trace-free noise terms)`` as polynomials in the nine
    entries ``r`` of ``R`` (row by row, see :func:`entries`).

    For a rotation matrix ``R = R(q)`` (active, scalar-last ``q``) column ``i`` equals
    ``4 q_i q``; Baruh/Kamman Eqs. (2)-(8) transposed to the active convention. Each candidate is
    exact arithmetic on the entries of ``R`` (no division, no root), so the selection below is
    branch-free and every candidate stays finite.

    ``one`` is the ``1 = |q|^2`` on the diagonal. For a scaled rotation ``t R(q)`` the columns
    are ``4 t q_i q`` with ``one = t``: passing an estimate of ``t`` (homogeneous of degree 1
    in ``R``) makes ``K`` homogeneous, so that every quaternion read from it is scale
    invariant. Replacing 1 by ``t`` adds ``(t - 1) I``, which changes no eigenvector.
    """
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = r
    # diagonal of K minus 1: 4x^2-1, 4y^2-1, 4z^2-1, 4w^2-1
    dx = r00 - r11 - r22
    dy = r11 - r00 - r22
    dz = r22 - r00 - r11
    dw = r00 + r11 + r22
    sxy, sxz, syz = r01 + r10, r02 + r20, r12 + r21
    ax, ay, az = r21 - r12, r02 - r20, r10 - r01
    cols = (
        (one + dx, sxy, sxz, ax),
        (sxy, one + dy, syz, ay),
        (sxz, syz, one + dz, az),
        (ax, ay, az, one + dw),
    )
    return cols, (dx, dy, dz, dw)


def select(masks, vals):
    """``vals[i]`` for the first true mask ``(use_x, use_y, use_z)``, else ``vals[3]``.

    Nested ``jnp.where`` fuses into the surrounding XLA loop (an argmax + gather does not), and
    unlike a one-hot product it cannot turn ``0 * inf`` into NaN.
    """
    use_x, use_y, use_z = masks
    v = where(use_z, vals[2], vals[3])
    v = where(use_y, vals[1], v)
    return where(use_x, vals[0], v)


def masks(diag):
    """``(use_x, use_y, use_z)`` for :func:`select`: the largest diagonal entry of ``K``.

    Comparisons fuse into every loop that reads the selected column, and each loop makes them
    again. That is safe where ``diag`` is exact arithmetic on the input (the conversions: the
    same bits in every loop); for computed entries use :func:`masks_once`."""
    dx, dy, dz, dw = diag
    return (dx >= dy) & (dx >= dz) & (dx >= dw), (dy >= dz) & (dy >= dw), dz >= dw


def masks_once(diag):
    """:func:`masks` from one argmax (the same first-largest choice), which XLA:CPU computes in
    a loop of its own. For a ``diag`` computed from rounded products: XLA recomputes such
    values in each loop that reads them, contracted into FMAs differently, and at a tie
    comparisons made again there can pick different columns for different components."""
    d = jnp.stack(diag, axis=-1)
    k = jax.lax.argmax(d, d.ndim - 1, jnp.int32)  # jnp.argmax's, without its nested jit
    return k == 0, k == 1, k == 2


def column(m, cols):
    """The column of ``cols`` that :func:`select` picks with the masks ``m`` (see
    :func:`masks`), as four per-rotation arrays."""
    return [select(m, [col[i] for col in cols]) for i in range(4)]


def select_column(cols, diag, pick=masks):
    """The column of ``K`` with the largest diagonal entry, as four per-rotation arrays, and its
    squared norm, at least ``t^2`` (the four diagonal entries of ``K`` sum to ``4 t``, so the
    largest is at least ``t``): no small divisor. ``pick``: :func:`masks` or
    :func:`masks_once`."""
    c = column(pick(diag), cols)
    return c, sum_squares(c)
