"""Top eigenvector of symmetric 4x4 matrices, elementwise over the batch (no LAPACK).

One kernel serves every fitting problem of rotjax: the nearest rotation's quaternion of a 3x3
matrix (Bar-Itzhack 2000), Wahba's problem (Davenport's q-method) and the quaternion mean
(Markley et al. 2007) each reduce to the eigenvector of the largest eigenvalue of a symmetric
4x4 matrix.

* Every symmetric `K` is Davenport's `K(B)` of a 3x3 `B` (a linear bijection onto the
  traceless part; see `_k_to_b`) plus a multiple of `I`, and the top eigenvector of
  `K(B)` is the quaternion of `Q = U diag(1, 1, det(U V^T)) V^T` for the SVD
  `B = U S V^T`: the rotation that maximises `tr(Q^T B)`. Its other eigenvectors are
  `q (x) (v_j, 0)` (`Q` composed with a half turn about a right singular vector).
* Forward: one-sided (Hestenes) Jacobi on the 3x3 `B`, a fixed number of rotations, then `Q`
  from the two largest columns of `B V` and their cross product (no division by the smallest
  singular value; `det B < 0` and rank-deficient `B` included), and Shepperd's extraction.
  `B` is first scaled by an exact power of two, so the result does not depend on its scale.
  On the CPU the batch runs in cache-sized chunks (every intermediate stays in cache).
* Derivative: from the 3x3 problem, `dv = v (x) (w / 2, 0)` with `(tr(H) I - H) w =
  vee(Q^T dB - dB^T Q)`, `H = Q^T B`, written as a differentiable expression of `B` (see
  `_top_tangent`), so second derivatives are exact where the top eigenvalue is simple,
  including at ties among the lower ones (exact rotations, identical means).
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp

from ._elementary import rsqrt, rsqrt_shared
from ._numerics import (
    TIE_ULPS,
    cross3,
    dot3,
    eps,
    exponent_scale,
    max_abs,
    safe_div,
    select,
    shared_tangent,
    stack,
    stack_matrix,
    tangent_entries,
    unstack,
    unstack_matrix,
    where,
)
from ._quaternion import quat_multiply, quat_to_matrix
from ._shepperd import k4_columns, masks_once, select_column

# One-sided Jacobi converges quadratically (Hestenes 1958; Demmel & Veselic 1992). The sweep
# counts are the fewest that orthogonalise the columns to the rounding level for every matrix
# of large samples of noisy rotations and random Gaussian matrices, and over near-ties,
# det < 0, rank-deficient and graded inputs. With the sorting rotations one sweep fewer leaves
# about 1% of noisy rotations off by 1e2-1e4 eps. The last sweep leaves out the rotation of the
# two smaller columns: Q reads their plane only through u_b, whose error from their remaining
# (second-order) inner product is not divided by a gap, whereas the sweep's other rotations set
# the largest column, against which every gap is measured.
_SWEEPS = {jnp.dtype(jnp.float32): 4, jnp.dtype(jnp.float64): 5}
_PAIRS = ((0, 1), (0, 2), (1, 2))

# The most entries per batch element whose maximum pow2_scale takes elementwise.
UNROLL_MAX = 64
# Batch elements per chunk on the CPU: a chunk's Jacobi state (18 numbers a matrix, a few
# copies live at once) stays in the last-level cache between the rotations, and each chunk
# costs a fixed overhead (one call per loop of the kernel, about 60 loops), so the chunk is as
# large as that cache allows: 4.5 MiB of state, in either dtype.
_CHUNK = {jnp.dtype(jnp.float32): 2**16, jnp.dtype(jnp.float64): 2**15}


def _schedule(dtype):
    """The kernel's Jacobi rotations, in order, as column pairs (see `_SWEEPS`)."""
    return _PAIRS * (_SWEEPS[jnp.dtype(dtype)] - 1) + _PAIRS[:2]


def _pow2_factors(m):
    """Two exact powers of two per batch element, `(f0, f1)`, such that `m * f0 * f1` lies in
    `[1/2, 1)` for `m` the largest `|entry|` of each batch element; NaN where `m` is not
    finite. Applied one after the other (their product can overflow): `f0` brings `m` within
    `2^+-k` (`k` half the exponent range), `f1` is `exponent_scale` of the result, halved.
    `m` is a constant: `pow2_factors` stops the gradient before taking it."""
    dt = m.dtype
    k = float(2 ** (jnp.finfo(dt).nexp - 2))  # 2^k, 2^-k, and their products with 2^E stay normal
    big, small = jnp.asarray(2.0**k, dt), jnp.asarray(2.0**-k, dt)
    c = where(m > big, small, where(m < small, big, 1.0))
    mc = m * c
    s, _ = exponent_scale(mc)
    nan = select(jnp.isfinite(m), 1.0, jnp.nan, dt)
    return c * nan, 0.5 * where(mc > 0, s, 1.0) * nan


def pow2_factors(x, axes):
    """The factors `(f0, f1)` (each of the batch shape of `x`, without `axes`) by which
    `pow2_scale` multiplies `x`, for callers that apply them inside their own products:
    `(x * f0) * f1` is exact."""
    n = len(axes)
    if sorted(a % x.ndim for a in axes) != list(range(x.ndim - n, x.ndim)):
        raise ValueError(f"axes must be the trailing axes, got {axes} for shape {x.shape}")
    # The factors are constants (the derivative is x's times them): no tangent is traced.
    flat = jax.lax.stop_gradient(x).reshape(*x.shape[: x.ndim - n], -1)
    if flat.shape[-1] <= UNROLL_MAX:
        return entry_pow2_factors([flat[..., i] for i in range(flat.shape[-1])])
    return _pow2_factors(jnp.max(where(jnp.isnan(flat), jnp.inf, jnp.abs(flat)), axis=-1))


def entry_pow2_factors(entries):
    """:func:`pow2_factors` of batch elements given by their entries (per-rotation arrays):
    elementwise maxima, which fuse with their neighbours and keep NaN (a max reduction over a
    small axis is a loop of its own; with NaN made infinite first, a slow one)."""
    return _pow2_factors(max_abs(*(jax.lax.stop_gradient(x) for x in entries)))


def pow2_scale(x, axes):
    """`x` times an exact power of two per batch element, so that the largest `|entry|` over
    the trailing `axes` lies in `[1/2, 1)`; no rounding. Zero stays zero; a non-finite entry
    gives NaN over the whole element."""
    f0, f1 = (f.reshape(*f.shape, *(1,) * len(axes)) for f in pow2_factors(x, axes))
    return x * f0 * f1


def _rotation(app, aqq, apq):
    """`(c, s)` of a Jacobi rotation that zeroes `a_pq` of the symmetric 2x2
    `[[a_pp, a_pq], [a_pq, a_qq]]` and leaves the larger diagonal entry first: a sorting
    rotation, so that the columns end in decreasing order of norm.

    `t = tan(theta)` is the smaller root of `t^2 + 2 tau t - 1 = 0`, `tau = (a_qq - a_pp) /
    (2 a_pq)` (Golub & Van Loan 8.5.2), written `t = 2 a_pq / (d + sign(d) r)`, `d = a_qq -
    a_pp`, `r = sqrt(d^2 + 4 a_pq^2)`: it gives `a_pp' = a_pp - t a_pq`, larger than
    `a_qq'` where `d < 0`. Elsewhere the rotation is by `theta + pi/2`, `t = -(d + r) /
    (2 a_pq)`, which swaps the two results; `|t|` is capped at `1 / eps^2` (a swap to below
    the rounding level), which is also `t` for `a_pq = 0 < d`.

    Each choice is made inside the one quotient `t`, and `c` and `s` come from it: XLA
    recomputes cheap expressions in every loop that uses them, and a sign of `d` taken twice
    at `d ~ 0` (an exact rotation) could differ between the loops that update the two columns.
    `c = rsqrt_shared(1 + t^2)`: every later rotation reads it."""
    d = aqq - app
    r = jnp.sqrt(d * d + 4.0 * apq * apq)
    keep = d < 0
    num = where(keep, 2.0 * apq, -(d + r))
    den = where(keep, d - r, 2.0 * apq)
    zero = den == 0  # a_pq = 0 <= d: swap (0 = d = r: nothing to do)
    big = 1.0 / eps(app.dtype) ** 2  # c ~ eps^2: a swap to well below the rounding level
    swap = select(num == 0, 0.0, -big, num.dtype)
    t = where(zero, swap, num) / where(zero, 1.0, den)
    # a_pq tiny but not 0: t^2 must not overflow (c = s = 0)
    t = jnp.minimum(jnp.maximum(t, -big), big)
    c = rsqrt_shared(1.0 + t * t)
    return c, t * c


def _unit_or(w, fallback):
    """`w / |w|`, or `fallback` where `|w|^2` is zero or below the normal range, whose
    reciprocal could overflow (NaN there for `fallback=None`)."""
    n = dot3(w, w)
    ok = n >= jnp.finfo(n.dtype).tiny  # NaN is not
    inv = rsqrt_shared(where(ok, n, 1.0))
    if fallback is None:
        fallback = [jnp.full_like(n, jnp.nan)] * 3
    return [where(ok, x * inv, f) for x, f in zip(w, fallback, strict=True)]


def _perpendicular(u):
    """A unit vector perpendicular to the unit `u`: `u x e_k` normalised, `e_k` the axis
    of `u`'s smallest component (so `|u x e_k|^2 >= 2/3`)."""
    a = [jnp.abs(x) for x in u]
    k0 = (a[0] <= a[1]) & (a[0] <= a[2])  # comparisons fuse; an argmin is a loop of its own
    k1 = ~k0 & (a[1] <= a[2])
    zero = jnp.zeros_like(u[0])
    p = [
        where(k0, zero, where(k1, -u[2], u[1])),
        where(k0, u[2], where(k1, zero, -u[0])),
        where(k0, -u[1], where(k1, u[0], zero)),
    ]
    inv = rsqrt_shared(dot3(p, p))
    return [x * inv for x in p]


def _polar(B, nan_at_zero=True, summed=False):
    """Scalar-last unit quaternion (`w >= 0`, or `|w| <= 4 eps` and the largest component
    positive) of the rotation `Q` maximising `tr(Q^T B)` for `(..., 3, 3)` `B`, `Q`,
    and `(V, s)`: the right singular vectors `(..., 3, 3)`
    (columns) and the singular values `(..., 3)` of `B` scaled by `pow2_scale`, the
    last one negative where `det B < 0` (`Q^T B = V diag(s) V^T`). XLA drops the outputs a
    caller does not use. `B = 0` gives NaN, or with `nan_at_zero=False` some rotation.
    `summed`: `B` is a sum over a set (see `_top`), whose derivative reads `q` back.

    One-sided Jacobi: the columns of `W = B V` are rotated in pairs until orthogonal, the
    rotations accumulated in `V`; both are rows of one `(..., 6, 3)` state, so each rotation
    is one loop over it. The rotations sort the columns (`_rotation`), so the first two
    are the largest, and `Q = u_a v_a^T + u_b v_b^T + (u_a x u_b)(v_a x v_b)^T` from them,
    `u = w / |w|`: a rotation, whatever the sign of `det B`.
    """
    Bs = pow2_scale(B, (-2, -1))
    eye = jnp.broadcast_to(jnp.eye(3, dtype=B.dtype), Bs.shape)
    S = jnp.concatenate([Bs, eye], axis=-2)
    for p, q in _schedule(B.dtype):
        cols = [S[..., k] for k in range(3)]
        wp, wq = cols[p][..., :3], cols[q][..., :3]
        alpha, beta, gamma = (
            sum(x[..., i] * y[..., i] for i in range(3)) for x, y in ((wp, wp), (wq, wq), (wp, wq))
        )
        c, s = (x[..., None] for x in _rotation(alpha, beta, gamma))
        cols[p], cols[q] = c * cols[p] - s * cols[q], s * cols[p] + c * cols[q]
        S = jnp.stack(cols, axis=-1)
    (wa, wb, wc), (va, vb, _) = (
        [[S[..., i, j : j + 1] for i in rows] for j in range(3)] for rows in ((0, 1, 2), (3, 4, 5))
    )
    # The largest column is 0 only for B = 0: the scaled B has an entry of at least 1/2, and
    # the rotations keep its Frobenius norm.
    ua = _unit_or(wa, None if nan_at_zero else va)
    ub = _unit_or(wb, _perpendicular(ua))  # rank 1: any rotation taking v_a to u_a
    uc, vc = cross3(ua, ub), cross3(va, vb)
    q_entries = [
        [ua[i] * va[j] + ub[i] * vb[j] + uc[i] * vc[j] for j in range(3)] for i in range(3)
    ]
    Q = jnp.stack([jnp.concatenate(row, -1) for row in q_entries], -2)
    # Shepperd's extraction, as in matrix_to_quaternion: the column of K = 4 q q^T with the
    # largest diagonal (at least 1 for a rotation, so |c|^2 >= 4 is in rsqrt's domain),
    # normalised to w >= 0. Within rounding of 180 degrees (|w| <= 4 eps) the selected
    # component is positive instead, so that rounding of the input cannot flip the result.
    # Q's entries are rounded products, so the column is chosen once (masks_once): at a tie
    # (exact rotations at 90 degrees) choices made again in each loop mixed two columns.
    entries = [x for row in q_entries for x in row]
    c, n = select_column(*k4_columns(entries), pick=masks_once)
    flip = (c[3] < 0) & (c[3] * c[3] > (4 * eps(B.dtype)) ** 2 * n)
    inv = rsqrt(n)
    k = where(flip, -inv, inv)
    # Stacked by a select (`stack`): one vectorised loop, whereas a stack on a leading axis
    # and its transpose is a concatenate, whose four branches LLVM compiles separately, each
    # with its own copy of the extraction. The derivative of a sum over a set reads q's
    # components back in the loops of its tangent: XLA would compute them again in each of
    # those loops from the select, and reads them from memory after the transpose.
    if summed:
        q = jnp.moveaxis(jnp.stack([x[..., 0] for x in c], axis=0) * k[None, ..., 0], 0, -1)
    else:
        q = stack([x * k for x in c])
    s = jnp.concatenate([dot3(ua, wa), dot3(ub, wb), dot3(uc, wc)], axis=-1)
    return q, Q, (S[..., 3:, :], s)


def _by_chunks(fn, B):
    """`fn` over the `(..., 3, 3)` batch `B`; on the CPU in chunks of `_CHUNK` (padded
    with identities), elsewhere in one piece."""
    batch = B.shape[:-2]
    n = math.prod(batch)
    chunk = _CHUNK[jnp.dtype(B.dtype)]
    if n <= chunk:
        return fn(B)

    def chunked(B):
        flat = B.reshape(n, 3, 3)
        pad = -n % chunk
        if pad:
            flat = jnp.concatenate([flat, jnp.broadcast_to(jnp.eye(3, dtype=B.dtype), (pad, 3, 3))])
        out = jax.lax.map(fn, flat.reshape(-1, chunk, 3, 3))
        return jax.tree.map(
            lambda o: o.reshape(-1, *o.shape[2:])[:n].reshape(*batch, *o.shape[2:]), out
        )

    return jax.lax.platform_dependent(B, cpu=chunked, default=fn)


def _k_to_b(K):
    """The `(..., 3, 3)` `B` with `davenport_k(B) = K - (tr K / 4) I` for the symmetric
    part of `(..., 4, 4)` `K` (the inverse of `davenport_k` on traceless matrices)."""

    e = unstack_matrix(K)  # a slice's transpose is a pad

    def k(i, j):
        return 0.5 * e[4 * i + j] + 0.5 * e[4 * j + i]

    t = 0.25 * (e[0] + e[5]) + 0.25 * (e[10] + e[15])
    diag = [0.5 * e[5 * i] + 0.5 * e[15] - t for i in range(3)]
    # davenport_k: K[i, j] = b_ij + b_ji (i, j < 3), K[:3, 3] = (b21 - b12, b02 - b20, b10 - b01)
    s01, s02, s12 = 0.5 * k(0, 1), 0.5 * k(0, 2), 0.5 * k(1, 2)
    a21, a02, a10 = 0.5 * k(0, 3), 0.5 * k(1, 3), 0.5 * k(2, 3)
    return stack_matrix(
        (
            (diag[0], s01 - a10, s02 + a02),
            (s01 + a10, diag[1], s12 - a21),
            (s02 - a02, s12 + a21, diag[2]),
        )
    )


def _check(K):
    if K.ndim < 2 or K.shape[-2:] != (4, 4):
        raise ValueError(f"K: expected shape (..., 4, 4), got {tuple(K.shape)}")


@jax.custom_jvp
def _top(B, q, aux):
    """`q`, the top eigenvector of `davenport_k(B)` computed by the caller with `aux`, the
    kernel's `(V, s)` for `B`, differentiated as that function of `B`. For a `B` summed over a
    set (the fitting problems): in reverse mode the cotangent of the stacked `B` is written
    once, in one loop, and the sum's transpose reads it (each entry's cotangent, left an
    expression, was computed again in a loop of its own per entry)."""
    del B, aux
    return q


@jax.custom_jvp
def _top_parts(b, q, aux):
    """`_top` on components: `b` the nine entries of `B` and `q` the four of the kernel's
    eigenvector (per-rotation arrays, see `rotjax._numerics.unstack`), returned with
    per-rotation tangents, which the caller's loop reads as they are. For a `B` read from memory
    (the conversions): a stacked tangent, read back by the caller, was transposed in reverse
    mode into a select and a reduction per component, each a loop that computed the whole
    incoming cotangent again."""
    del b, aux
    return tuple(q)


def _run(B, nan_at_zero=True, summed=False):
    """The kernel's `(q, Q, (V, s))` for `B` (`_polar`, by chunks), as constants: the
    derivative rules take `(V, s)` from this same run, so that a derivative needs no second
    one; where nothing is differentiated they are unused, and XLA drops them."""
    polar = functools.partial(_polar, nan_at_zero=nan_at_zero, summed=summed)
    # Stopped at the input: a caller's jvp then traces the kernel once, without tangents.
    return _by_chunks(polar, jax.lax.stop_gradient(B))


def _nearest(B, nan_at_zero=True, summed=False):
    """The kernel's top eigenvector of `davenport_k(B)`, differentiable (`_top_tangent`);
    `summed`: `B` is a sum over a set (see `_top`), else read from memory (`_top_parts`)."""
    q, _, aux = _run(B, nan_at_zero, summed)
    if summed:
        return _top(B, q, aux)
    return stack(_top_parts(tuple(unstack_matrix(B)), tuple(unstack(q)), aux), unit=True)


@jax.custom_jvp
def _top_matrix(b, q, aux, Q):
    """`Q`, the rotation of `_top_parts(b, q, aux)` computed by the kernel, differentiated as
    `quat_to_matrix` of it."""
    del b, q, aux
    return Q


@_top_matrix.defjvp
def _top_matrix_jvp(primals, tangents):
    (b, q, aux, _), (db, _, _, _) = primals, tangents

    def rotation(b):
        return quat_to_matrix(stack(_top_parts(b, q, aux)), bounded=True)

    return jax.jvp(rotation, (b,), (db,))


def nearest_rotation(B):
    """The rotation matrix `R` maximising `tr(R^T B)` for a `(..., 3, 3)` `B` (the
    special-orthogonal polar factor), as the kernel forms it; differentiated as the matrix of
    `nearest_quaternion`. NaN where `B` is zero or not finite."""
    q, Q, aux = _run(B)
    return _top_matrix(tuple(unstack_matrix(B)), tuple(unstack(q)), aux, Q)


def top_eigenvector(K):
    """Unit eigenvector `(..., 4)` of the largest eigenvalue of the symmetric part of a
    `(..., 4, 4)` `K`.

    The last component is `>= 0` (within `4 eps` of 0 the largest component is positive
    instead, so that rounding does not flip the sign). Where the top eigenvalue is simple the
    result is accurate to a few eps divided by the relative gap to the next one, at any finite
    scale of `K`; a non-finite entry gives NaN; a multiple of `I` gives a unit vector (every
    vector is an eigenvector).

    Derivative: exact while the top eigenvalue is simple, and differentiable again (second
    derivatives exact there). At a tie with the top eigenvalue the component of the derivative
    along the tied eigenspace, where the answer is not unique, is 0.
    """
    _check(K)
    return _nearest(_k_to_b(K), nan_at_zero=False, summed=True)


def _top_tangent(b_e, db_e, v, aux, summed=False):
    """The tangent (components) of the top eigenvector `v` (`(..., 4)`) from the entries of `B`
    and of its tangent, both scaled by the kernel's power of two, and the kernel's
    `aux = (V, s)`. `summed`: `B` is a sum over a set (see `_top`)."""
    # The rotation Q = R(v) maximises tr(Q^T B), so H = Q^T B is symmetric for every B. Moving B
    # by dB moves Q to Q (I + [w]x), and keeping H symmetric gives
    #     (tr(H) I - H) w = vee(Q^T dB - dB^T Q),      dv = v (x) (w / 2, 0).
    # tr(H) I - H = V diag(g) V^T, g_j = s_k + s_l from the kernel's signed singular values s:
    # half the gaps from the top eigenvalue of K(B), which are its only gap terms (lower ties,
    # as at exact rotations or identical inputs to a mean, leave it invertible). Its inverse is
    # evaluated as 2 Y - Y A Y with Y = V diag(1/g) V^T (constant): the same value, and its
    # derivative in B is that of A^{-1}. With v differentiable (this rule, recursively), the
    # expression is an exact identity in B, so its derivative is the second derivative of v. A
    # gap below TIE_ULPS eps |K| is a tie: Y is 0 along it. B is scaled by the kernel's exact
    # power of two (v does not depend on the scale).
    V, s = aux
    # Entries read by unstack (a slice's transpose is a pad, which XLA:CPU evaluates per
    # element in a branch of its own: minutes to compile at second order)
    q_e, v_e = (unstack_matrix(X) for X in (quat_to_matrix(v, bounded=True), V))

    def qt(x, i, j):
        """`(Q^T X)_ij` from the entries `x` of `X` as a sum of per-element terms: XLA:CPU
        compiles a reduction over a small trailing axis (`jnp.sum`, `einsum`) to a slow kernel
        of its own."""
        return sum(q_e[3 * k + i] * x[3 * k + j] for k in range(3))

    H = [[qt(b_e, i, j) for j in range(3)] for i in range(3)]
    tr = H[0][0] + H[1][1] + H[2][2]
    # vee(Q^T dB - dB^T Q)
    r = [qt(db_e, j, k) - qt(db_e, k, j) for j, k in ((2, 1), (0, 2), (1, 0))]
    s0, s1, s2 = unstack(s)
    top = s0 + s1 + s2
    gaps = [s1 + s2, s0 + s2, s0 + s1]
    tol = 0.5 * TIE_ULPS * eps(tr.dtype) * max_abs(top, *(top - 2.0 * g for g in gaps))
    inv_g = [safe_div(1.0, g, tol) for g in gaps]
    v_cols = [[v_e[3 * i + j] for i in range(3)] for j in range(3)]

    def Y(x):
        c = [inv_g[j] * dot3(v_cols[j], x) for j in range(3)]
        return [sum(c[j] * v_cols[j][i] for j in range(3)) for i in range(3)]

    def A(x):  # tr(H) I - (H + H^T) / 2
        return [
            tr * x[i] - sum(0.5 * (H[i][k] + H[k][i]) * x[k] for k in range(3)) for i in range(3)
        ]

    # For a sum over a set, every later step reads r: written once (shared_tangent), its
    # cotangent is computed once in reverse mode, rather than again in the loop of each of B's
    # entries. For a matrix read from memory it only adds a loop.
    y = Y(shared_tangent(r) if summed else r)
    half_w = [y[i] - 0.5 * z for i, z in enumerate(Y(A(y)))]  # (2 y - Y A y) / 2
    return tuple(unstack(quat_multiply(v, stack([*half_w, jnp.zeros_like(tr)]))))


@_top.defjvp
def _top_jvp(primals, tangents):
    (B, qe, aux), (dB, _, _) = primals, tangents
    Bs, dBs = jax.jvp(lambda b: pow2_scale(b, (-2, -1)), (B,), (dB,))  # a constant factor
    v = _top(B, qe, aux)  # v, not the constant q: its derivative is the next order's
    return v, stack(_top_tangent(unstack_matrix(Bs), tangent_entries(dBs), v, aux, summed=True))


@_top_parts.defjvp
def _top_parts_jvp(primals, tangents):
    (b, qe, aux), (db, _, _) = primals, tangents
    f0, f1 = entry_pow2_factors(b)  # pow2_scale's factors (constants)
    bs, dbs = ([(x * f0) * f1 for x in e] for e in (b, db))
    v = _top_parts(b, qe, aux)
    return v, _top_tangent(bs, dbs, stack(v), aux)


def davenport_k(B):
    """Davenport's symmetric `(..., 4, 4)` `K` (scalar-last quaternions) of a `(..., 3, 3)`
    `B`: `q^T K q = tr(R(q)^T B)` for unit `q` (active `R`). Linear in `B`.

    For `B` the attitude profile `sum_i w_i a_i b_i^T` its top eigenvector solves Wahba's
    problem (Davenport's q-method; Markley & Crassidis 2014, Sec. 5.5.3); for `B` any 3x3
    matrix it is the quaternion of the rotation nearest to `B` in the Frobenius norm, since
    `||R - B||^2 = 3 + ||B||^2 - 2 tr(R^T B)` (Bar-Itzhack 2000).
    """
    e = unstack_matrix(B)
    b = [e[3 * i : 3 * i + 3] for i in range(3)]
    tr = b[0][0] + b[1][1] + b[2][2]
    sxy, sxz, syz = b[0][1] + b[1][0], b[0][2] + b[2][0], b[1][2] + b[2][1]
    ax, ay, az = b[2][1] - b[1][2], b[0][2] - b[2][0], b[1][0] - b[0][1]
    return stack_matrix(
        (
            (2 * b[0][0] - tr, sxy, sxz, ax),
            (sxy, 2 * b[1][1] - tr, syz, ay),
            (sxz, syz, 2 * b[2][2] - tr, az),
            (ax, ay, az, tr),
        )
    )


def nearest_quaternion(B, summed=False):
    """Scalar-last unit quaternion `(..., 4)`, `w >= 0` (see `top_eigenvector` for
    `|w| <= 4 eps`), of the rotation `R` maximising
    `tr(R^T B)` for a `(..., 3, 3)` `B`: the nearest rotation to `B`, `det B < 0`
    included. NaN where `B` is zero or not finite. Independent of the scale of `B`.
    `summed`: `B` is a sum over a set (Wahba's attitude profile; see `_top`)."""
    return _nearest(B, summed=summed)
