"""Rotations inside optimisation and learning loops: losses, continuous representations,
Wahba's problem, averaging and interpolation.

Two private helpers carry the differentiation work and are shared by several functions:

* ``_project`` is the special-orthogonal projection of a 3x3 matrix by SVD, with a closed-form
  JVP that never touches the derivatives of ``U`` and ``V`` separately (those have
  ``1 / (s_i^2 - s_j^2)`` terms and are NaN whenever singular values tie, e.g. at the identity);
* ``top_eigenvector`` is the eigenvector of the largest eigenvalue of a symmetric 4x4 matrix, with
  a JVP whose ``1 / (lambda_max - lambda_j)`` terms are safe-divided.

Both set to zero the component of the derivative that has no finite value: the direction in
which the solution is not unique. Everywhere else they are the exact derivative.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ._matrix import _from_matrix, _k4_columns, _positive_w
from ._numerics import (
    FULL,
    TIE_ULPS,
    as_float,
    check_shape,
    cross,
    eps,
    from_scalar_last,
    like_rank,
    matmul,
    public,
    safe_atan2,
    safe_div,
    safe_norm,
    to_scalar_last,
    top_eigenvector,
    vee,
)
from ._quaternion import _conjugate, _multiply, _normalize
from ._rotvec import _quat_to_rotvec, _rotvec_to_quat

ALIGN_METHODS = ("svd", "q-method")


def _mT(x):
    return jnp.swapaxes(x, -1, -2)


# --- special-orthogonal projection (SVD) --------------------------------------------------


def _svd_signed(M):
    """SVD ``M = U diag(s) V^T`` with the sign of ``det`` moved into ``U[:, 2]`` and ``s[2]``.

    Then ``U @ V^T`` is in SO(3) and ``s[2]`` is negative when ``det M < 0``.
    """
    U, s, Vt = jnp.linalg.svd(M)
    d = jnp.sign(jnp.linalg.det(matmul(U, Vt)))  # exactly +-1 up to rounding: U, V are orthogonal
    flip = jnp.stack([jnp.ones_like(d), jnp.ones_like(d), d], axis=-1)
    return U * flip[..., None, :], s * flip, Vt


@jax.custom_jvp
def _project(M):
    """Rotation nearest to ``M`` in the Frobenius norm: ``U diag(1, 1, det(U V^T)) V^T``."""
    U, _, Vt = _svd_signed(M)
    return matmul(U, Vt)


@_project.defjvp
def _project_jvp(primals, tangents):
    # Polar decomposition M = R H with H = V diag(s') V^T symmetric (s' = signed values).
    # Differentiating, R^T dM = Omega H + dH with Omega = R^T dR antisymmetric. In the V basis,
    # P = U^T dM V = W S' + Y (W = V^T Omega V antisymmetric, Y symmetric), so that
    # P - P^T = W S' + S' W, i.e. W_ij = (P_ij - P_ji) / (s'_i + s'_j), and dR = U W V^T.
    # The denominators vanish only where the projection is not unique: rank(M) <= 1, or
    # det M < 0 with s_2 = s_3 (then s'_2 + s'_3 = s_2 - s_3). There W_ij is set to 0.
    (M,), (dM,) = primals, tangents
    U, s, Vt = _svd_signed(M)
    P = matmul(matmul(_mT(U), dM), _mT(Vt))
    den = s[..., :, None] + s[..., None, :]
    tol = TIE_ULPS * eps(M.dtype) * jnp.abs(s[..., :1, None])
    W = safe_div(P - _mT(P), den, tol)
    return matmul(U, Vt), matmul(matmul(U, W), Vt)


# --- top eigenvector of a symmetric 4x4 matrix ------------------------------------------


def _davenport(B):
    """Davenport's symmetric 4x4 ``K`` (plus the identity) for the attitude profile ``B``.

    The matrix-to-quaternion ``K`` of :mod:`rotjax._matrix` is linear in its argument plus the
    identity, and satisfies ``q^T K(R(p)) q = 4 (q.p)^2 = tr(R(q)^T R(p)) + 1`` for unit ``q``,
    ``p``. Since rotation matrices span all 3x3 matrices, ``q^T K(B) q = tr(R(q)^T B) + 1`` for
    every ``B``: its top eigenvector maximises Wahba's gain (Davenport's q-method). The added
    identity does not change the eigenvectors.
    """
    cols, _ = _k4_columns(B)
    return jnp.stack([jnp.stack(c, axis=-1) for c in cols], axis=-1)


# --- losses --------------------------------------------------------------------------------


def _prep_pair(R_a, R_b):
    (R_a, R_b), dt = as_float(R_a, R_b)
    check_shape(R_a, (3, 3), "R_a")
    check_shape(R_b, (3, 3), "R_b")
    return R_a, R_b, dt


@public
def geodesic_distance(R_a, R_b):
    """Angle of the rotation taking ``R_a`` to ``R_b``: ``atan2(|vee(M)|, (tr M - 1) / 2)``.

    Here ``M = R_a^T R_b``; ``|vee(M)| = sin(theta)`` comes from the antisymmetric part and
    ``(tr M - 1) / 2 = cos(theta)`` from the trace.

    Args:
        R_a: ``(..., 3, 3)`` rotation matrix.
        R_b: ``(..., 3, 3)`` rotation matrix; broadcasts against ``R_a``.

    Returns:
        ``(...,)`` angle in radians, in ``[0, pi]``. Equal to :func:`angle_between` of the
        corresponding quaternions.

    Note:
        The atan2 form keeps absolute accuracy of about 1 ulp at 0 and at pi, where
        ``acos((tr M - 1) / 2)`` loses half the digits and has an infinite derivative at 0.
        The distance is a cone at ``R_a = R_b``: no derivative exists there, and the gradient
        returned is 0, the minimum-norm subgradient (finite; at any nonzero angle it is the true
        derivative, of unit size along the geodesic). Likewise at exactly pi, where the sine
        term vanishes, the gradient is 0 (a ridge). For a smooth loss use the squared distance.
        Inputs are assumed orthogonal; for other matrices this is a smooth function of their
        entries, but not a distance. An infinite or NaN component gives NaN.
    """
    R_a, R_b, dt = _prep_pair(R_a, R_b)
    M = matmul(_mT(R_a), R_b)
    c = 0.5 * (jnp.trace(M, axis1=-2, axis2=-1) - 1)
    s = safe_norm(vee(M))
    # atan2 of an infinite sine is a finite pi/2: an infinite component gives NaN instead.
    return jnp.where(jnp.isfinite(s) & jnp.isfinite(c), safe_atan2(s, c), jnp.nan).astype(dt)


@public
def chordal_distance(R_a, R_b):
    """Frobenius norm ``||R_a - R_b||_F``, equal to ``2 sqrt(2) sin(theta / 2)``.

    Args:
        R_a: ``(..., 3, 3)`` matrix.
        R_b: ``(..., 3, 3)`` matrix; broadcasts against ``R_a``.

    Returns:
        ``(...,)`` distance, in ``[0, 2 sqrt(2)]`` for rotation matrices.

    Note:
        Cheaper than :func:`geodesic_distance` and monotone in the angle, but flat near pi
        (its derivative in ``theta`` goes to 0 there). At ``R_a = R_b`` it is a cone; the
        gradient returned there is 0, finite. Its square is smooth everywhere.
    """
    R_a, R_b, dt = _prep_pair(R_a, R_b)
    D = R_a - R_b
    return safe_norm(D.reshape(*D.shape[:-2], 9)).astype(dt)


# --- continuous representations ----------------------------------------------------------


@public
def sixd_to_matrix(x):
    """Continuous 6D representation to a rotation matrix (Zhou et al. 2019), by Gram-Schmidt.

    Args:
        x: ``(..., 6)``: ``x[..., :3]`` is read as the first column of the matrix and
            ``x[..., 3:]`` as (a vector in the plane of) the second column. Neither need be unit
            or orthogonal.

    Returns:
        ``(..., 3, 3)`` rotation matrix with columns ``b1 = a1 / |a1|``,
        ``b2 = normalise(a2 - (b1 . a2) b1)`` and ``b3 = b1 x b2``.

    Note:
        Defined and smooth wherever ``a1 != 0`` and ``a2`` is not parallel to ``a1``; there it
        is undefined and returns NaN on purpose (no rotation is closer than any other), as
        for an infinite or NaN component. The two halves are prescaled by exact powers of
        two, so any finite non-zero scale of either gives the same matrix (float32 from 1e-30
        to 1e30, float64 from 1e-300 to 1e300), with finite gradients.
        The map is surjective and continuous, unlike quaternions or Euler angles read as
        network outputs, which is why it regresses better.
    """
    (x,), dt = as_float(x)
    check_shape(x, (6,), "x")
    a1, a2 = _pow2_prescale(x[..., :3]), _pow2_prescale(x[..., 3:])
    b1 = a1 / jnp.sqrt(jnp.sum(a1 * a1, axis=-1, keepdims=True))
    u2 = _pow2_prescale(a2 - jnp.sum(b1 * a2, axis=-1, keepdims=True) * b1)
    b2 = u2 / jnp.sqrt(jnp.sum(u2 * u2, axis=-1, keepdims=True))
    return jnp.stack([b1, b2, cross(b1, b2)], axis=-1).astype(dt)


def _pow2_prescale(v):
    """``v`` (``(..., 3)``) times the power of two that brings its largest component into
    ``[1/2, 1)``: exact (no rounding, unless a much smaller component becomes subnormal, which
    is below eps relative to the largest), so its square norm neither overflows nor underflows.

    Applied to vectors that are only used through their direction (``b = v / |v|`` is
    homogeneous of degree 0 in ``v``), the scale's own derivative contributes nothing
    (``b'(v) v = 0``): it is held constant. Zero, infinite and NaN vectors are left as they
    are (and give NaN downstream, as they must)."""
    big = jax.lax.stop_gradient(jnp.max(jnp.abs(v), axis=-1, keepdims=True))
    finite = jnp.isfinite(big) & (big > 0)
    _, e = jnp.frexp(jnp.where(finite, big, 1.0))
    # 2^-e in two factors: one alone would overflow for a subnormal ``big`` in float32.
    half = -e // 2
    one = jnp.ones((), v.dtype)
    return v * jnp.ldexp(one, half) * jnp.ldexp(one, -e - half)


@public
def matrix_to_sixd(R):
    """Rotation matrix to the 6D representation: its first two columns, concatenated.

    Args:
        R: ``(..., 3, 3)`` rotation matrix.

    Returns:
        ``(..., 6)``: ``(R[..., :, 0], R[..., :, 1])``. ``sixd_to_matrix`` inverts it on SO(3).
    """
    (R,), dt = as_float(R)
    check_shape(R, (3, 3), "R")
    return jnp.concatenate([R[..., :, 0], R[..., :, 1]], axis=-1).astype(dt)


@public
def nined_to_matrix(x):
    """Nearest rotation matrix to an arbitrary 3x3, by SVD (Levinson et al. 2020).

    Args:
        x: ``(..., 9)`` entries of a 3x3 matrix ``M`` in row-major order (a network output);
            pass ``M.reshape(*M.shape[:-2], 9)`` to project a matrix.

    Returns:
        ``(..., 3, 3)`` the rotation ``R = U diag(1, 1, det(U V^T)) V^T`` minimising
        ``||R - M||_F``, where ``M = U diag(s) V^T``. For ``M`` already a rotation, ``R = M``.

    Note:
        Differentiated in closed form, not through ``U`` and ``V``: with ``s'`` the singular
        values after moving ``det(U V^T)`` into ``s'_3``,
        ``dR = U W V^T`` with ``W_ij = (P_ij - P_ji) / (s'_i + s'_j)``, ``P = U^T dM V``. So
        ties ``s_i = s_j`` (the identity, any rotation, isotropic noise) are harmless: the
        gradient there is exact. The denominators vanish only where the projection itself is
        not unique, ``rank(M) <= 1`` or ``det M < 0`` with ``s_2 = s_3``; they are safe-divided
        (the term is set to 0 when ``|s'_i + s'_j| <= 64 eps s_1``), so the gradient is finite
        and has no component along the undetermined rotation.
    """
    (x,), dt = as_float(x)
    check_shape(x, (9,), "x")
    return _project(x.reshape(*x.shape[:-1], 3, 3)).astype(dt)


# --- Wahba's problem --------------------------------------------------------------------


@public
def align_vectors(a, b, weights=None, method: str = "svd", scalar_first: bool = False):
    """Rotation that best maps the vectors ``b`` onto ``a`` (Wahba's problem).

    Finds the ``R`` minimising ``sum_i w_i |a_i - R b_i|^2``, as ``scipy``'s
    ``Rotation.align_vectors(a, b, weights)``: ``b`` are in the body frame, ``a`` in the
    reference frame, and ``a_i ~ R @ b_i``. Equivalently ``R`` maximises ``tr(R^T B)`` with the
    attitude profile matrix ``B = sum_i w_i a_i b_i^T``.

    Args:
        a: ``(..., N, 3)`` vectors in the reference frame.
        b: ``(..., N, 3)`` the same vectors in the body frame; broadcasts against ``a``.
        weights: ``(..., N)`` non-negative weights; ``None`` for all ones.
        method: ``"svd"`` (Kabsch/Markley 1988: ``R = U diag(1, 1, det(U V^T)) V^T`` from the
            SVD of ``B``, then the quaternion) or ``"q-method"`` (Davenport: the top eigenvector
            of the symmetric 4x4 ``K(B)``). Both give the same rotation up to rounding.
        scalar_first: return ``(w, x, y, z)``.

    Returns:
        ``(..., 4)`` unit quaternion of ``R``, with ``w >= 0``.

    Raises:
        ValueError: for shapes other than ``(..., N, 3)`` or an unknown ``method``.

    Note:
        Where the solution is unique and the problem well posed (two or more non-parallel
        vectors), both methods are differentiable and their gradients are exact, including
        noise-free data, where singular values of ``B`` may tie (see :func:`nined_to_matrix`)
        but the eigenvalue gap of ``K`` is ``2 (s_2 + s_3) > 0``.

        With a single vector pair (or all vectors parallel) any rotation about ``a`` composed
        with the optimum is optimal too; the one returned is whichever the decomposition picks.
        The gradient is then finite: its component along the undetermined rotation about ``a``
        is zero, and the rest, which moves ``R b`` to follow ``a``, is exact. Functions of
        ``R b`` therefore have exact gradients there.
    """
    if method not in ALIGN_METHODS:
        raise ValueError(f"method must be one of {ALIGN_METHODS}, got {method!r}")
    if weights is None:
        (a, b), dt = as_float(a, b)
    else:
        (a, b, weights), dt = as_float(a, b, weights)
    for x, name in ((a, "a"), (b, "b")):
        check_shape(x, (3,), name)
        if x.ndim < 2:
            raise ValueError(f"{name}: expected shape (..., N, 3), got {tuple(x.shape)}")
    if a.shape[-2] != b.shape[-2]:
        raise ValueError(
            f"a and b must hold the same number N of vectors, got {a.shape}, {b.shape}"
        )
    if weights is not None:
        if weights.ndim < 1 or weights.shape[-1] != a.shape[-2]:
            raise ValueError(f"weights: expected shape (..., {a.shape[-2]}), got {weights.shape}")
        a = a * weights[..., None]
    B = jnp.einsum("...ni,...nj->...ij", a, b, precision=FULL)
    if method == "svd":
        q = _from_matrix(_project(B), "shepperd")
    else:
        q = top_eigenvector(_davenport(B))
    return from_scalar_last(_positive_w(q), scalar_first).astype(dt)


# --- averaging and interpolation ---------------------------------------------------------


@public
def quaternion_mean(q, weights=None, scalar_first: bool = False):
    """Weighted average rotation (Markley et al. 2007).

    The unit quaternion maximising ``sum_i w_i (q . q_i)^2``: the top eigenvector of
    ``sum_i w_i q_i q_i^T``. It minimises the weighted sum of squared chordal distances
    ``||R(q) - R(q_i)||_F^2``.

    Args:
        q: ``(..., N, 4)`` quaternions; need not be unit (each is normalised first) and the
            sign of each is irrelevant.
        weights: ``(..., N)`` non-negative weights; ``None`` for all ones.
        scalar_first: quaternions (input and output) are ``(w, x, y, z)``.

    Returns:
        ``(..., 4)`` unit quaternion with ``w >= 0``.

    Note:
        For rotations about one axis by angles ``t_i`` the mean is the rotation by the circular
        mean ``atan2(sum w_i sin t_i, sum w_i cos t_i)``. The mean is undefined when the top
        eigenvalue is repeated (e.g. two rotations 180 degrees apart with equal weights); the
        gradient is then finite, with zero component within the tied eigenspace.
    """
    if weights is None:
        (q,), dt = as_float(q)
    else:
        (q, weights), dt = as_float(q, weights)
    check_shape(q, (4,), "q")
    if q.ndim < 2:
        raise ValueError(f"q: expected shape (..., N, 4), got {tuple(q.shape)}")
    q = _normalize(to_scalar_last(q, scalar_first))
    if weights is not None and (weights.ndim < 1 or weights.shape[-1] != q.shape[-2]):
        raise ValueError(f"weights: expected shape (..., {q.shape[-2]}), got {weights.shape}")
    qw = q if weights is None else q * weights[..., None]
    M = jnp.einsum("...ni,...nj->...ij", qw, q, precision=FULL)
    return from_scalar_last(_positive_w(top_eigenvector(M)), scalar_first).astype(dt)


@public
def slerp(p, q, t, scalar_first: bool = False):
    """Spherical linear interpolation along the shorter arc: ``p * (p^-1 q)^t``.

    Args:
        p: ``(..., 4)`` start quaternion; need not be unit.
        q: ``(..., 4)`` end quaternion; need not be unit; broadcasts against ``p``.
        t: ``(...)`` interpolation parameter (0 gives ``p``, 1 gives ``q``; values outside
            ``[0, 1]`` extrapolate); broadcasts against ``p[..., 0]``.
        scalar_first: quaternions are ``(w, x, y, z)``.

    Returns:
        ``(..., 4)`` unit quaternion. The angle from ``p`` grows as ``t`` times the angle
        between ``p`` and ``q``: constant angular speed. At ``t = 0`` it is ``p / |p|``; at
        ``t = 1`` it is ``q / |q|`` or its negative (the same rotation).

    Note:
        Written as the exponential of ``t`` times the logarithm of the relative rotation, both
        with Taylor branches, so there is no ``sin(theta) / sin(theta)`` 0/0 as ``p -> q``:
        values and gradients are exact there. ``q`` and ``-q`` are the same rotation and give
        the same path, so ``p = -q`` is a constant path. When the relative rotation is exactly
        180 degrees, both arcs are equally short and the one chosen follows the sign of the
        relative quaternion's vector part (the logarithm has a cut there).
    """
    (p, q, t), dt = as_float(p, q, t)
    check_shape(p, (4,), "p")
    check_shape(q, (4,), "q")
    check_shape(t, (), "t")
    p = _normalize(to_scalar_last(p, scalar_first))
    q = to_scalar_last(q, scalar_first)
    rel = _quat_to_rotvec(_multiply(_conjugate(p), q))  # angle in [0, pi]: the shorter arc
    out = _multiply(p, _rotvec_to_quat(like_rank(t[..., None], rel) * rel))
    return from_scalar_last(out, scalar_first).astype(dt)
