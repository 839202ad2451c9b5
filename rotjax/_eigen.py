"""Top eigenvector of symmetric 4x4 matrices, elementwise over the batch (no LAPACK).

One kernel serves every fitting problem of rotjax: the nearest rotation's quaternion of a 3x3
matrix (Bar-Itzhack 2000), Wahba's problem (Davenport's q-method) and the quaternion mean
(Markley et al. 2007) each reduce to the eigenvector of the largest eigenvalue of a symmetric
4x4 matrix.

* Forward: a fixed number of cyclic Jacobi sweeps (Golub & Van Loan, Alg. 8.5.3, symmetric
  Schur rotations), written as per-matrix scalar expressions so that XLA fuses the whole
  kernel into one loop over the batch; then one power step with ``K - lambda_min I``, which
  scales the remaining error along each other eigenvector by
  ``(lambda_j - lambda_min) / (lambda_top - lambda_min) <= 1``. The matrix is first scaled by an
  exact power of two, so the result does not depend on the input's scale.
* Derivative: ``dv = (lambda_top I - K)^+ dK v``, written as a differentiable expression of
  ``K`` (see :func:`_top_jvp`), so second derivatives are exact where the top eigenvalue is
  simple, including at ties among the lower ones (exact rotations, identical means).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ._numerics import TIE_ULPS, eps, max_abs, safe_div

# Cyclic Jacobi converges quadratically for every symmetric matrix, repeated eigenvalues
# included (Schonhage 1964; Wilkinson 1962). The sweep counts are the fewest that bring the
# off-diagonal entries to the rounding level (a few eps of the largest entry) over random
# Gaussian matrices, near-ties down to relative gaps of 1e-9, +-1 pairs, graded spectra and
# near-rotations; one sweep fewer leaves 1e3-1e4 eps in each dtype.
_SWEEPS = {jnp.dtype(jnp.float32): 4, jnp.dtype(jnp.float64): 5}
_PAIRS = ((0, 1), (2, 3), (0, 2), (1, 3), (0, 3), (1, 2))


def pow2_scale(x, axes):
    """``x`` times an exact power of two per batch element, so that the largest ``|entry|`` over
    ``axes`` lies in ``[1/2, 1)``; no rounding. Zero stays zero; a non-finite entry gives NaN
    over the whole element."""
    m = jnp.max(jnp.abs(x), axis=axes, keepdims=True)
    finite = jnp.isfinite(m) & (m > 0)
    _, e = jnp.frexp(jnp.where(finite, m, 1.0))
    # Two factors: 2^-e alone overflows for subnormal m.
    h = e // 2
    one = jnp.ones((), x.dtype)
    y = x * jnp.ldexp(one, -h) * jnp.ldexp(one, h - e)
    return jnp.where(jnp.isfinite(m), y, jnp.nan)


def _mul(a, b):
    """``a * b`` where either may be a Python ``0.0`` or ``1.0`` (the initial eigenvectors): those
    are folded in Python so the first sweep does not multiply by constants."""
    if isinstance(a, float) or isinstance(b, float):
        if isinstance(b, float):
            a, b = b, a
        return 0.0 if a == 0.0 else b
    return a * b


def _lin(c, x, s, y):
    """``c x + s y`` with :func:`_mul`'s constant folding."""
    u, w = _mul(c, x), _mul(s, y)
    if isinstance(u, float):
        return w
    if isinstance(w, float):
        return u
    return u + w


def _rotation(app, aqq, apq):
    """``(t, c, s)`` of the Jacobi rotation that zeroes ``a_pq``: ``t = tan(theta)`` the smaller
    root of ``t^2 + 2 tau t - 1 = 0``, ``tau = (a_qq - a_pp) / (2 a_pq)`` (Golub & Van Loan
    8.5.2), written as ``t = 2 a_pq / (d + sign(d) sqrt(d^2 + 4 a_pq^2))``, ``d = a_qq - a_pp``,
    which needs no division by ``a_pq``. Both zero (underflowed squares included): ``t = 0``."""
    d = aqq - app
    r = jnp.sqrt(d * d + 4.0 * apq * apq)
    den = jnp.where(d < 0, d - r, d + r)
    zero = den == 0
    t = jnp.where(zero, 0.0, 2.0 * apq / jnp.where(zero, 1.0, den))  # double where
    c = jax.lax.rsqrt(1.0 + t * t)
    return t, c, t * c


def _jacobi(a, sweeps):
    """Cyclic Jacobi on the symmetric 4x4 given as a dict ``{(i, j): array}`` (``i <= j``).

    Returns the diagonal (eigenvalues, unordered) and the eigenvector columns ``V[j][i]``
    (component ``i`` of eigenvector ``j``), as per-matrix arrays.
    """
    a = dict(a)
    V = [[1.0 if i == j else 0.0 for i in range(4)] for j in range(4)]

    def get(i, j):
        return a[(min(i, j), max(i, j))]

    def put(i, j, x):
        a[(min(i, j), max(i, j))] = x

    for _ in range(sweeps):
        for p, q in _PAIRS:
            t, c, s = _rotation(a[(p, p)], a[(q, q)], a[(p, q)])
            apq = a[(p, q)]
            a[(p, p)] = a[(p, p)] - t * apq
            a[(q, q)] = a[(q, q)] + t * apq
            a[(p, q)] = jnp.zeros_like(apq)
            for r in range(4):
                if r in (p, q):
                    continue
                arp, arq = get(r, p), get(r, q)
                put(r, p, c * arp - s * arq)
                put(r, q, s * arp + c * arq)
            vp, vq = V[p], V[q]
            V[p] = [_lin(c, x, -s, y) for x, y in zip(vp, vq, strict=True)]
            V[q] = [_lin(s, x, c, y) for x, y in zip(vp, vq, strict=True)]
    lam = [a[(i, i)] for i in range(4)]
    return lam, V


def _entries(K):
    return {(i, j): K[..., i, j] for i in range(4) for j in range(i, 4)}


def _argmax_select(lam, vals):
    """``vals[k]`` for the first ``k`` with the largest ``lam[k]`` (nested ``where``)."""
    l0, l1, l2, l3 = lam
    m0 = (l0 >= l1) & (l0 >= l2) & (l0 >= l3)
    m1 = (l1 >= l2) & (l1 >= l3)
    m2 = l2 >= l3
    out = []
    for i in range(len(vals[0])):
        x = jnp.where(m2, vals[2][i], vals[3][i])
        x = jnp.where(m1, vals[1][i], x)
        out.append(jnp.where(m0, vals[0][i], x))
    return out


def _check(K):
    if K.ndim < 2 or K.shape[-2:] != (4, 4):
        raise ValueError(f"K: expected shape (..., 4, 4), got {tuple(K.shape)}")


def eigh4(K):
    """Eigenvalues ``(..., 4)`` (unordered) and eigenvectors ``(..., 4, 4)`` (columns) of the
    symmetric ``K``, read from its upper triangle, by Jacobi sweeps on ``K`` scaled by a power
    of two (the eigenvalues are scaled back). A non-finite entry gives NaN. No derivative rule:
    see :func:`top_eigenvector`."""
    _check(K)
    Ks = pow2_scale(K, (-2, -1))
    lam, V = _jacobi(_entries(Ks), _SWEEPS[jnp.dtype(K.dtype)])
    # Scale back: the ratio K / Ks, exact, from one nonzero entry's exponent.
    m = jnp.max(jnp.abs(K), axis=(-2, -1))
    ms = jnp.max(jnp.abs(Ks), axis=(-2, -1))
    ratio = jnp.where(ms > 0, m / jnp.where(ms > 0, ms, 1.0), 0.0)
    return jnp.stack(lam, axis=-1) * ratio[..., None], jnp.stack(
        [jnp.stack(v, axis=-1) for v in V], axis=-1
    )


def _top_forward(K):
    """Unit top eigenvector (components), the scaled ``K``'s entries and its eigenvalues."""
    Ks = pow2_scale(K, (-2, -1))
    a = _entries(Ks)
    lam, V = _jacobi(a, _SWEEPS[jnp.dtype(K.dtype)])
    v = _argmax_select(lam, V)
    # One power step with K - lambda_min I (all its eigenvalues >= 0, the top one the largest).
    lmin = jnp.minimum(jnp.minimum(lam[0], lam[1]), jnp.minimum(lam[2], lam[3]))
    w = [sum(a[(min(i, j), max(i, j))] * v[j] for j in range(4)) - lmin * v[i] for i in range(4)]
    sq = sum(x * x for x in w)
    ok = sq > 0  # 0 only where K is a multiple of I: keep the Jacobi vector
    inv = jax.lax.rsqrt(jnp.where(ok, sq, 1.0))
    return [jnp.where(ok, x * inv, y) for x, y in zip(w, v, strict=True)]


@jax.custom_jvp
def top_eigenvector(K):
    """Unit eigenvector ``(..., 4)`` of the largest eigenvalue of a symmetric ``(..., 4, 4)``
    ``K`` (its upper triangle is read; the derivative symmetrises ``dK``).

    The sign is arbitrary. Where the top eigenvalue is simple the result is accurate to a few
    eps divided by the relative gap to the next one, at any finite scale of ``K``; a non-finite
    entry gives NaN; the zero matrix gives a unit vector (every vector is an eigenvector).

    Derivative: exact while the top eigenvalue is simple, and differentiable again (second
    derivatives exact there). At a tie with the top eigenvalue the component of the derivative
    along the tied eigenspace, where the answer is not unique, is 0.
    """
    _check(K)
    return jnp.stack(_top_forward(K), axis=-1)


def top_eigenpair(K):
    """``(lambda, v)``: the top eigenvector (:func:`top_eigenvector`) and its Rayleigh quotient
    ``v^T K v``, shapes ``(...,)`` and ``(..., 4)``."""
    v = top_eigenvector(K)
    return _dot(v, _mv(K, v))[..., 0], v


# The derivative rule's small products are sums of per-element terms, not ``jnp.sum`` over a
# trailing axis of 4 (``_numerics.matvec``): XLA:CPU compiles each such reduction to a kernel of
# its own, a slow one in float64.


def _mv(A, x):
    """``A @ x`` for ``(..., 4, 4)`` and ``(..., 4)``."""
    return jnp.stack([sum(A[..., i, k] * x[..., k] for k in range(4)) for i in range(4)], -1)


def _mtv(A, x):
    """``A^T @ x``."""
    return _mv(jnp.swapaxes(A, -1, -2), x)


def _dot(x, y):
    """``x . y`` over the last axis of 4 (``keepdims``)."""
    return sum(x[..., k] * y[..., k] for k in range(4))[..., None]


def _max(x):
    """Largest entry over the last axis of 4 (``keepdims``)."""
    return jnp.maximum(jnp.maximum(x[..., 0], x[..., 1]), jnp.maximum(x[..., 2], x[..., 3]))[
        ..., None
    ]


@top_eigenvector.defjvp
def _top_jvp(primals, tangents):
    # dv = (lambda I - K)^+ dK v = M^{-1} (I - v v^T) dK v, with M = lambda I - K + c v v^T
    # (invertible where lambda is simple; M^{-1} v = v / c, so the v v^T term cancels).
    # M^{-1} is evaluated as 2 X - X M X with X = M^{-1} from the eigendecomposition under
    # stop_gradient: the same value, and its derivative in K is that of M^{-1}. With v and
    # lambda = v^T K v themselves differentiable (this rule, recursively), the expression is an
    # exact identity in K, so its derivative is the second derivative of v. Its only gap
    # terms are to the top eigenvalue: lower ties (exact rotations, identical inputs to a mean)
    # do not appear. A gap to the top below TIE_ULPS eps |K| is a tie: X is 0 there.
    (K,), (dK,) = primals, tangents
    dK = 0.5 * (dK + jnp.swapaxes(dK, -1, -2))
    lam_all, V = jax.lax.stop_gradient(eigh4(K))
    lam, v = top_eigenpair(K)
    top = _max(lam_all)
    scale = max_abs(*jnp.moveaxis(lam_all, -1, 0))[..., None]
    c = jnp.where(scale > 0, scale, 1.0)
    tol = TIE_ULPS * eps(K.dtype) * scale
    gap = top - lam_all
    vs = jax.lax.stop_gradient(v)
    # X's eigenvalues: 1/c along v, 1/gap_j along the others; the Jacobi column nearest v has
    # gap 0 and is replaced by v's own term.
    own = jnp.abs(_mtv(V, vs))
    is_top = own >= _max(own)
    inv_mu = jnp.where(is_top, 0.0, safe_div(1.0, gap, tol))

    def X(x):
        return _mv(V, inv_mu * _mtv(V, x)) + vs * _dot(vs, x) / c

    def M(x):
        return lam[..., None] * x - _mv(K, x) + c * v * _dot(v, x)

    Kv = _mv(dK, v)
    w = Kv - v * _dot(v, Kv)
    y = X(w)
    return v, 2.0 * y - X(M(y))


def davenport_k(B):
    """Davenport's symmetric ``(..., 4, 4)`` ``K`` (scalar-last quaternions) of a ``(..., 3, 3)``
    ``B``: ``q^T K q = tr(R(q)^T B)`` for unit ``q`` (active ``R``). Linear in ``B``.

    For ``B`` the attitude profile ``sum_i w_i a_i b_i^T`` its top eigenvector solves Wahba's
    problem (Davenport's q-method; Markley & Crassidis 2014, Sec. 5.5.3); for ``B`` any 3x3
    matrix it is the quaternion of the rotation nearest to ``B`` in the Frobenius norm, since
    ``||R - B||^2 = 3 + ||B||^2 - 2 tr(R^T B)`` (Bar-Itzhack 2000).
    """
    b = [[B[..., i, j] for j in range(3)] for i in range(3)]
    tr = b[0][0] + b[1][1] + b[2][2]
    sxy, sxz, syz = b[0][1] + b[1][0], b[0][2] + b[2][0], b[1][2] + b[2][1]
    ax, ay, az = b[2][1] - b[1][2], b[0][2] - b[2][0], b[1][0] - b[0][1]
    rows = (
        (2 * b[0][0] - tr, sxy, sxz, ax),
        (sxy, 2 * b[1][1] - tr, syz, ay),
        (sxz, syz, 2 * b[2][2] - tr, az),
        (ax, ay, az, tr),
    )
    return jnp.stack([jnp.stack(r, axis=-1) for r in rows], axis=-2)


def nearest_quaternion(B):
    """Scalar-last unit quaternion ``(..., 4)`` (sign arbitrary) of the rotation ``R`` maximising
    ``tr(R^T B)`` for a ``(..., 3, 3)`` ``B``: the nearest rotation to ``B``, ``det B < 0``
    included. NaN where ``B`` is zero or not finite. Independent of the scale of ``B``."""
    v = top_eigenvector(davenport_k(pow2_scale(B, (-2, -1))))
    zero = jnp.all(B == 0, axis=(-2, -1))[..., None]
    return jnp.where(zero, jnp.nan, v)
