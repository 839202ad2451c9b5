"""Rotation matrix -> quaternion: branch-free largest-component extraction and its refinements."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from ._eigen import nearest_quaternion
from ._numerics import (
    as_float,
    check_shape,
    from_scalar_last,
    public,
    rsqrt,
)

METHODS = ("shepperd", "markley", "optimal")


def _k4_columns(R):
    """The four columns of ``K = 4 q q^T + (trace-free noise terms)`` as polynomials in ``R``.

    For a rotation matrix ``R = R(q)`` (active, scalar-last ``q``) column ``i`` equals
    ``4 q_i q``; Baruh/Kamman Eqs. (2)-(8) transposed to the active convention. Each candidate is
    exact arithmetic on the entries of ``R`` (no division, no root), so the selection below is
    branch-free and every candidate stays finite.
    """
    r00, r01, r02 = R[..., 0, 0], R[..., 0, 1], R[..., 0, 2]
    r10, r11, r12 = R[..., 1, 0], R[..., 1, 1], R[..., 1, 2]
    r20, r21, r22 = R[..., 2, 0], R[..., 2, 1], R[..., 2, 2]
    # diagonal of K minus 1: 4x^2-1, 4y^2-1, 4z^2-1, 4w^2-1
    dx = r00 - r11 - r22
    dy = r11 - r00 - r22
    dz = r22 - r00 - r11
    dw = r00 + r11 + r22
    sxy, sxz, syz = r01 + r10, r02 + r20, r12 + r21
    ax, ay, az = r21 - r12, r02 - r20, r10 - r01
    cols = (
        (1.0 + dx, sxy, sxz, ax),
        (sxy, 1.0 + dy, syz, ay),
        (sxz, syz, 1.0 + dz, az),
        (ax, ay, az, 1.0 + dw),
    )
    return cols, (dx, dy, dz, dw)


def _positive_w(q):
    """Choose the ``w >= 0`` hemisphere (both signs are the same rotation)."""
    return jnp.where(q[..., 3:] < 0, -q, q)


def _select(masks, vals):
    """``vals[i]`` for the first true mask ``(use_x, use_y, use_z)``, else ``vals[3]``.

    Nested ``jnp.where`` fuses into the surrounding XLA loop; an argmax + gather was measured
    slower, and a one-hot product turns ``0 * inf`` into NaN.
    """
    use_x, use_y, use_z = masks
    v = jnp.where(use_z, vals[2], vals[3])
    v = jnp.where(use_y, vals[1], v)
    return jnp.where(use_x, vals[0], v)


def _selected_column(R):
    """The column of ``K`` with the largest diagonal entry, as four per-rotation arrays, and its
    squared norm: at least 1 for any finite ``R`` (the four diagonal entries of ``K`` sum to 4,
    so the largest is at least 1), hence no small divisor and :func:`rsqrt`'s domain."""
    cols, (dx, dy, dz, dw) = _k4_columns(R)
    masks = ((dx >= dy) & (dx >= dz) & (dx >= dw), (dy >= dz) & (dy >= dw), dz >= dw)
    c = [_select(masks, [col[i] for col in cols]) for i in range(4)]
    return c, sum(x * x for x in c)


def _hemisphere_scale(v, sq, root=rsqrt):
    """``1 / |v|`` (``sq = |v|^2 >= 1`` here: see :func:`_selected_column`), negated where
    ``w < 0``: ``v * scale`` is the unit quaternion with ``w >= 0``.

    ``root``: :func:`rsqrt` (default), which XLA fuses into the loop that writes the four
    components; ``lax.rsqrt`` in a derivative rule, where the scale feeds many consumers and XLA
    should compute it once rather than inside each (with the fused form, ``matrix_to_euler``'s
    ``jit(grad)`` fell from 0.44x to 0.08x of its forward pass in the benchmark, when its rule
    took the scale from here; an optimisation barrier on the fused form did not help).
    With ``jnp.sqrt`` it gives the signed norm instead (:func:`_signed_norm`).
    """
    s = root(sq)
    return jnp.where(v[3] < 0, -s, s)


def _stack_last(v, scale):
    """``(..., 4)`` from four per-rotation components times a per-rotation scale.

    Stacked on a leading axis and moved last: XLA:CPU emits one transposing loop (stacking on
    the last axis directly was 2.5x slower in float32, when the scale was ``lax.rsqrt``).
    """
    return jnp.moveaxis(jnp.stack(v, axis=0) * scale, 0, -1)


@jax.custom_jvp
def _shepperd(R):
    """Shepperd extraction, scalar last, ``w >= 0``: the selected column of ``K`` over its norm.

    Written for XLA:CPU, measured with ``python -m rotjax bench``: every step is a per-rotation
    scalar expression (no reduction over a stacked axis); the four components are selected
    first and the scale ``rsqrt(|c|^2)`` is computed from them (not from the norms of all four
    columns); the components are stacked on a leading axis and moved to the end
    (:func:`_stack_last`). With the scale from :func:`rsqrt` (multiplications and additions
    only) XLA emits a single transposing loop: the matrix is read once. With ``lax.rsqrt``,
    which XLA will not recompute for each of the four components, it emitted a loop for the
    scale and a second one that read the matrix again (full benchmark runs: 53% / 34% of the
    copy kernel's rate in float32 / float64, against 76-94% / 48-79% over nine runs with one
    loop).
    """
    c, sq = _selected_column(R)
    # The norm of the selected column (not 2 sqrt of its diagonal entry, which is cheaper but
    # gives a non-unit result for a non-orthogonal R).
    return _stack_last(c, _hemisphere_scale(c, sq))


def _signed_norm(c, sq):
    """``sqrt(sq)`` (``sq = |c|^2``) with the sign of ``c[3]``: ``c / n`` is the unit quaternion
    with ``w >= 0`` (for the selected column, the Shepperd quaternion; up to rounding, ``c``
    times :func:`_hemisphere_scale`, the same sign rule with the reciprocal root)."""
    return _hemisphere_scale(c, sq, jnp.sqrt)


def _shepperd_tangent(R, dR):
    """The selected column ``c``, its squared norm, and the four components of the Shepperd
    quaternion's tangent ``dq`` (per-rotation arrays) for a tangent ``dR``.

    Tangent-space rule: with dR = R hat(v) on SO(3), dq = 1/2 q (x) (v, 0), v = vee(R^T dR).
    Off the tangent space, dR is projected onto it through R^T: at a rotation matrix this is
    the derivative of the nearest-rotation quaternion ("optimal").

    The code is arranged for reverse mode, where JAX transposes it (measured: jit(grad) went
    from 12 XLA loops to 2):

    * dR enters only through :func:`_rotation_tangent`;
    * v is divided by the signed column norm last (:func:`_divide_split`), so in the transpose
      the cotangent of v ends in a division, which XLA does not recompute inside each of the
      nine consumers, and is written interleaved in one pass.
    """
    c, sq = _selected_column(R)
    n = 4.0 * _signed_norm(c, sq)  # q = c / (n / 4); the 1/2 of v and of dq folded in
    vx, vy, vz = _divide_split(_rotation_tangent(R, dR), n)
    x, y, z, w = c
    dq = [
        w * vx + y * vz - z * vy,
        w * vy + z * vx - x * vz,
        w * vz + x * vy - y * vx,
        -(x * vx + y * vy + z * vz),
    ]
    return c, sq, dq


def _divide_split(parts, n):
    """``[p / n for p in parts]`` (per-rotation arrays), arranged for reverse mode.

    The parts are stacked on the last axis, divided by ``n`` stacked alike, and split again
    with ``jnp.split``. JAX transposes a split into a concatenation, so the cotangents of the
    parts are written as one interleaved ``(..., k)`` array, one rotation after another, in a
    single pass over ``R``; the division makes XLA materialise it rather than recompute it in
    each consumer. Unstacking by indexing (``v[..., i]`` or ``v[i]``) transposes into padding
    instead, and XLA:CPU then wrote a planar ``(k, ...)`` array, one pass over ``R`` per part
    (``jit(grad)`` of ``"shepperd"`` over its forward pass, float32 / float64, in the benchmark:
    0.21-0.29x / 0.21-0.26x over five runs before, 0.24-0.34x / 0.27-0.29x over four after;
    side by side in an ad-hoc interleaved timing, 0.27x -> 0.40x in float32).
    """
    return [t[..., 0] for t in jnp.split(_divide_stacked(parts, n), len(parts), axis=-1)]


def _divide_stacked(parts, n):
    """``(..., k)``: the parts (per-rotation arrays) stacked last and divided by ``n`` stacked
    alike. XLA:CPU keeps the division (a divisor broadcast from ``(..., 1)`` was turned into a
    multiplication by its reciprocal), so the quotients are the same bits as ``p / n``."""
    return jnp.stack(parts, axis=-1) / jnp.stack([n] * len(parts), axis=-1)


def _rotation_tangent(R, dR):
    """``2 vee(R^T dR)`` (three per-rotation arrays) for a rotation matrix ``R``: twice the
    body-frame angular velocity of ``dR`` (exact for ``dR = R hat(v)``; off the tangent space,
    its projection onto it). Computed as ``sum_k dR_k x R_k`` over the rows ``k``; ``dR``
    enters only through elementwise products with three (..., 3, 3) arrays built from ``R``,
    whose transpose (reverse mode) is one elementwise loop that writes the cotangent of ``R``.
    """
    r0, r1, r2 = R[..., 0], R[..., 1], R[..., 2]  # columns of R
    o = jnp.zeros_like(r0)
    rows = (  # (dR_k x R_k)_a = sum_j A_a[k, j] dR[k, j]
        jnp.stack([o, r2, -r1], axis=-1),
        jnp.stack([-r2, o, r0], axis=-1),
        jnp.stack([r1, -r0, o], axis=-1),
    )
    return [jnp.sum(a * dR, axis=(-2, -1)) for a in rows]


@jax.custom_jvp
def _shepperd_divided(R):
    """The Shepperd quaternion as the selected column divided by its signed norm (stacked, see
    :func:`_divide_stacked`), for ``matrix_to_euler``; its derivative rule uses the same bits
    through :func:`_divide_split`. Same tangent rule as :func:`_shepperd`."""
    c, sq = _selected_column(R)
    return _divide_stacked(c, _signed_norm(c, sq))


def _define_shepperd_jvp(f):
    def jvp(primals, tangents):
        (R,), (dR,) = primals, tangents
        _, _, dq = _shepperd_tangent(R, dR)
        return f(R), jnp.stack(dq, axis=-1)

    f.defjvp(jvp)


_define_shepperd_jvp(_shepperd)
_define_shepperd_jvp(_shepperd_divided)


def _dk_pattern():
    """``S[c, a]`` (3x3) with ``(dK p)_c = sum_kj (sum_a p_a S[c, a])[k, j] dR[k, j]``, read off
    :func:`_k4_columns` (``K`` is affine in ``R``) by evaluating it, in NumPy, on unit
    matrices."""
    out = np.zeros((4, 4, 3, 3))
    for k in range(3):
        for j in range(3):
            e = np.zeros((3, 3))
            e[k, j] = 1.0
            cols, _ = _k4_columns(e)
            out[:, :, k, j] = (np.array(cols) - np.eye(4)).T  # dK/dR[k, j]; symmetric
    return out


_DK_PATTERN = _dk_pattern()


def _k_times(cols, p):
    """``K p`` for the symmetric ``K`` given by its columns, on per-rotation components."""
    return [sum(cols[i][c] * p[i] for i in range(4)) for c in range(4)]


@jax.custom_jvp
def _markley(R):
    """Shepperd's quaternion refined by one power-iteration step with ``K``, ``w >= 0``.

    ``K = 4 q q^T`` (+ noise) has eigenvalues 4, 0, 0, 0 for a rotation, so one product removes
    the O(sigma) error of the selected column and leaves O(sigma^2). Per-rotation scalar
    expressions throughout, as in :func:`_shepperd` (the Shepperd quaternion is not stacked
    and unstacked in between: that cost a transposing loop).
    """
    c, sq = _selected_column(R)
    s0 = _hemisphere_scale(c, sq)
    cols, _ = _k4_columns(R)
    v = _k_times(cols, [x * s0 for x in c])
    return _stack_last(v, _hemisphere_scale(v, sum(x * x for x in v)))


@_markley.defjvp
def _markley_jvp(primals, tangents):
    # The exact derivative of the formula with the Shepperd step's tangent-space rule inside
    # (the true derivative on SO(3); off it, within O(sigma) of it: see matrix_to_quaternion),
    # written by hand so that reverse mode compiles to few loops (the benchmark's jit(grad)
    # over forward went from 0.11x to 0.33x in float32, against JAX's own transposition of
    # the forward code):
    # dv = K(R) dq0 + dK q0, where dK q0 = sum_kj M_c[k, j](q0) dR[k, j] (M_c read off K's
    # columns, linear in R); then q = v / |v| gives dq = (I - q q^T) dv / |v|. As in
    # _shepperd_tangent, dR enters through elementwise products only, and dv is divided by the
    # signed norm (a division that XLA does not recompute inside each consumer).
    (R,), (dR,) = primals, tangents
    c, sq, dq0 = _shepperd_tangent(R, dR)
    # lax.rsqrt (see _hemisphere_scale): q0 may differ from the forward pass's by an ulp, which
    # this well-conditioned derivative does not notice (equal to autodiff to 1e-12, tested).
    s0 = _hemisphere_scale(c, sq, lax.rsqrt)
    cols, _ = _k4_columns(R)
    px, py, pz, pw = (x * s0 for x in c)
    v = _k_times(cols, [px, py, pz, pw])
    n = _signed_norm(v, sum(x * x for x in v))

    # M_c = sum_a p_a S[c, a]: a broadcast against constant sign patterns, which XLA fuses
    # into the loop that consumes it (stacking the entries made it materialise them).
    p = (px, py, pz, pw)
    pat = _DK_PATTERN.astype(R.dtype)
    m = [sum(p[a][..., None, None] * pat[c, a] for a in range(4)) for c in range(4)]
    dk = _k_times(cols, dq0)
    w = _divide_split([dk[c] + jnp.sum(m[c] * dR, axis=(-2, -1)) for c in range(4)], n)
    inv = 1 / n
    q = [x * inv for x in v]
    qw = sum(q[c] * w[c] for c in range(4))
    return _markley(R), jnp.stack([w[c] - q[c] * qw for c in range(4)], axis=-1)


def _from_matrix(R, method: str):
    if method == "shepperd":
        return _shepperd(R)
    if method == "markley":
        return _markley(R)
    if method == "optimal":
        return _positive_w(nearest_quaternion(R))  # Bar-Itzhack 2000; see rotjax._eigen
    raise ValueError(f"method must be one of {METHODS}, got {method!r}")


@public
def matrix_to_quaternion(R, method: str = "shepperd", scalar_first: bool = False):
    """Quaternion of a rotation matrix, with ``w >= 0``.

    Args:
        R: ``(..., 3, 3)`` active rotation matrix (``v_world = R @ v_body``). A passive
            direction-cosine matrix, as in Kamman's notes, must be transposed first.
        method: how to treat matrices that are not exactly orthogonal:

            * ``"shepperd"`` (default): branch-free largest-component extraction (Shepperd 1978;
              Baruh/Kamman Eqs. 5-8; Markley 2008). The column of ``K = 4 q q^T`` with the
              largest diagonal is selected with nested ``jnp.where`` and normalised once. Exact
              to about 1 eps for rotation matrices; error O(sigma) for noise sigma.
            * ``"markley"``: the Shepperd column followed by one power-iteration step with ``K``.
              About 35 more flops; brings noisy matrices to within O(sigma^2) of optimal.
            * ``"optimal"``: the quaternion of the nearest rotation (Bar-Itzhack 2000): the top
              eigenvector of the symmetric 4x4 ``K`` by ``jnp.linalg.eigh``, then one power
              step with ``K``, which removes the eigensolver's own rounding error. Slowest.
        scalar_first: return ``(w, x, y, z)``.

    Returns:
        ``(..., 4)`` unit quaternion with ``w >= 0`` (at exactly 180 degrees, ``w = 0`` and the
        sign is that of the selected component).

    Note:
        No sqrt or division is applied to a small number: the selected column has norm at least
        1 for a rotation matrix, so every method is finite and differentiable everywhere,
        including the identity and every 180-degree rotation.

        *Gradients.* For ``"shepperd"`` the derivative is the tangent-space rule
        ``dq = 1/2 q (x) (v, 0)`` with ``v = vee(R^T dR)`` (a ``jax.custom_jvp``): exact for
        every perturbation that stays on SO(3), and for a perturbation off SO(3) it keeps only
        its component along the tangent space, which at a rotation matrix equals the derivative
        of the ``"optimal"`` quaternion. So the gradient of a loss with respect to a free 3x3
        matrix is not that of the raw Shepperd formula (which would also react to scaling and
        shear); compose with an explicit projection if that is what you need. For
        ``"markley"`` the gradient is the exact derivative of the power step applied to the
        Shepperd quaternion (with the rule above for the latter). At a rotation matrix this is
        the true derivative of the returned quaternion along every direction, off SO(3) too
        (there ``K = 4 q q^T`` annihilates the Shepperd step's share); for a matrix with noise
        sigma it deviates from the true derivative by O(sigma): a median 0.45 sigma (relative,
        random directions), against 2 sigma for the rule above, which would be the cheaper
        choice. For
        ``"optimal"`` the gradient is that of the top eigenvector (the power step does not
        change it), finite while the top eigenvalue is simple (always, for matrices near a
        rotation).
    """
    (R,), dt = as_float(R)
    check_shape(R, (3, 3), "R")
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    return from_scalar_last(_from_matrix(R, method), scalar_first).astype(dt)
