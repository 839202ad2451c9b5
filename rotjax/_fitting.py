"""Rotations inside optimisation and learning loops: losses, continuous representations,
Wahba's problem, averaging and interpolation.

The 9D projection, Wahba's problem and the mean are each the top eigenvector of a symmetric 4x4
matrix, computed by `top_eigenvector` (a one-sided Jacobi SVD of the
equivalent 3x3 matrix, elementwise over the batch; exact first and second derivatives where
the top eigenvalue is simple, finite at ties).
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike

from ._eigen import (
    UNROLL_MAX,
    nearest_quaternion,
    nearest_rotation,
    pow2_factors,
    pow2_scale,
    top_eigenvector,
)
from ._elementary import atan2, hypot, rsqrt
from ._numerics import (
    FULL,
    as_float,
    as_part,
    broadcast_batch,
    cast,
    check_shape,
    cross3,
    dot3,
    exponent_scale,
    from_part,
    from_scalar_last,
    public,
    recorded,
    safe_norm,
    stack,
    stack_matrix,
    to_scalar_last,
    unstack,
    unstack_matrix,
    where,
)
from ._quaternion import quat_conjugate, quat_multiply, quat_normalize
from ._rotvec import quat_to_rotvec, rotvec_to_quat

ALIGN_METHODS = ("svd", "q-method")


def _einsum_outer(x, y):
    return jnp.einsum("...ni,...nj->...ij", x, y, precision=FULL)


def _scaled(v, factors):
    """`v` times each factor in turn (exact for powers of two; their product could overflow)."""
    for f in factors:
        v = v * f
    return v


def _sum_outer(x, y, fx, fy):
    """`sum_n (x_n fx)(y_n fy)^T` `(..., p, r)` for `(..., N, p)` and `(..., N, r)`;
    `fx`, `fy` are tuples of constant per-batch-element factors (powers of two from
    `pow2_factors`, or empty), applied inside the products so that they can neither
    underflow nor overflow.

    For a few vectors, a sum of broadcast outer products: one loop over the batch that reads
    the inputs once (XLA:CPU runs a batched `dot` of such small matrices several times
    slower, and scaled copies of the inputs would be written and read again); for many, an
    `einsum`. JAX differentiates this code."""
    if not _unrolled(x, y):
        return _einsum_outer(*_scaled_operands(x, y, fx, fy))
    xs, ys = _scaled_operands(*_broadcast_batch(x, y, fx, fy))
    n, p, r = xs.shape[-2], xs.shape[-1], ys.shape[-1]
    xe, ye = unstack_matrix(xs), unstack_matrix(ys)  # a slice's transpose is a pad
    return stack_matrix(
        [[sum(xe[k * p + i] * ye[k * r + j] for k in range(n)) for j in range(r)] for i in range(p)]
    )


def _unrolled(x, y):
    return x.shape[-2] * max(x.shape[-1], y.shape[-1]) <= UNROLL_MAX


def _broadcast_batch(x, y, fx, fy):
    """`x`, `y` (`(..., n, k)`) and their per-matrix factors broadcast to one batch shape."""
    x, y, *f = broadcast_batch(x, y, *fx, *fy, trailing=(2, 2) + (0,) * (len(fx) + len(fy)))
    return x, y, f[: len(fx)], f[len(fx) :]


def _scaled_operands(x, y, fx, fy):
    return (_scaled(v, [f[..., None, None] for f in fs]) for v, fs in ((x, fx), (y, fy)))


# --- losses --------------------------------------------------------------------------------


def _prep_pair(R_a, R_b):
    (R_a, R_b), dt = as_float(R_a, R_b)
    check_shape(R_a, (3, 3), "R_a")
    check_shape(R_b, (3, 3), "R_b")
    return R_a, R_b, dt


@public
def geodesic_distance(R_a: ArrayLike, R_b: ArrayLike) -> Array:
    """Angle of the rotation taking `R_a` to `R_b`: `atan2(|vee(M)|, (tr M - 1) / 2)`.

    Here `M = R_a^T R_b`; `|vee(M)| = sin(theta)` comes from the antisymmetric part and
    `(tr M - 1) / 2 = cos(theta)` from the trace.

    Args:
        R_a: `(..., 3, 3)` rotation matrix.
        R_b: `(..., 3, 3)` rotation matrix; broadcasts against `R_a`.

    Returns:
        `(...,)` angle in radians, in `[0, pi]`. Equal to [`angle_between`][rotjax.angle_between] of
            the corresponding quaternions.

    Note:
        The atan2 form keeps absolute accuracy of about 1 ulp at 0 and at pi, where
        `acos((tr M - 1) / 2)` loses half the digits and has an infinite derivative at 0.
        The distance is a cone at `R_a = R_b`: no derivative exists there, and the gradient
        returned is 0, the minimum-norm subgradient (finite; at any nonzero angle it is the true
        derivative, of unit size along the geodesic). Likewise at exactly pi, where the sine
        term vanishes, the gradient is 0 (a ridge). For a smooth loss use the squared distance.
        Inputs are assumed orthogonal; for other matrices this is a smooth function of their
        entries, but not a distance. An infinite or NaN component gives NaN.

    Examples:
        ```python
        import rotjax as rj

        R_a = rj.rotvec_to_matrix([0.0, 0.0, 0.2])
        R_b = rj.rotvec_to_matrix([0.0, 0.0, 0.5])
        print(rj.geodesic_distance(R_a, R_b).round(6))
        # 0.3
        ```
    """
    R_a, R_b, dt = _prep_pair(R_a, R_b)
    a, b = unstack_matrix(R_a), unstack_matrix(R_b)
    # The trace and the axial vector of M = R_a^T R_b from the entries (M_ij = sum_k a_ki b_kj):
    # no matrix product or stacked axial vector, which XLA:CPU computes in loops of their own.
    m = [[sum(a[3 * k + i] * b[3 * k + j] for k in range(3)) for j in range(3)] for i in range(3)]
    c = 0.5 * (m[0][0] + m[1][1] + m[2][2] - 1)
    s = hypot(*[0.5 * (m[2][1] - m[1][2]), 0.5 * (m[0][2] - m[2][0]), 0.5 * (m[1][0] - m[0][1])])
    # atan2 of an infinite sine is a finite pi/2: an infinite component gives NaN instead.
    return cast(from_part(where(jnp.isfinite(s) & jnp.isfinite(c), atan2(s, c), jnp.nan)), dt)


@public
def chordal_distance(R_a: ArrayLike, R_b: ArrayLike) -> Array:
    """Frobenius norm `||R_a - R_b||_F`, equal to `2 sqrt(2) sin(theta / 2)`.

    Args:
        R_a: `(..., 3, 3)` matrix.
        R_b: `(..., 3, 3)` matrix; broadcasts against `R_a`.

    Returns:
        `(...,)` distance, in `[0, 2 sqrt(2)]` for rotation matrices.

    Note:
        Cheaper than [`geodesic_distance`][rotjax.geodesic_distance] and monotone in the angle, but
        flat near pi (its derivative in `theta` goes to 0 there). At `R_a = R_b` it is a cone; the
        gradient returned there is 0, finite. Its square is smooth everywhere.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        R_b = rj.rotvec_to_matrix([0.0, 0.0, jnp.pi])  # half turn
        print(rj.chordal_distance(jnp.eye(3), R_b).round(6), (2 * jnp.sqrt(2.0)).round(6))
        # 2.828427 2.828427
        ```
    """
    R_a, R_b, dt = _prep_pair(R_a, R_b)
    if recorded(R_a, matrix=True) or recorded(R_b, matrix=True):
        # A matrix made in this trace: on its entries, in the loop of the operation before.
        a, b = unstack_matrix(R_a), unstack_matrix(R_b)
        return cast(from_part(hypot(*[x - y for x, y in zip(a, b, strict=True)])), dt)
    # Matrices read from memory: on the stacked difference, whose gradient is elementwise over
    # the (3, 3) entries, which XLA:CPU vectorises (written entry by entry, a scalar nest).
    D = R_a - R_b
    return cast(safe_norm(D.reshape(*D.shape[:-2], 9)), dt)


# --- continuous representations ----------------------------------------------------------


@public
def sixd_to_matrix(x: ArrayLike) -> Array:
    """Continuous 6D representation to a rotation matrix (Zhou et al. 2019), by Gram-Schmidt.

    Args:
        x: `(..., 6)`: `x[..., :3]` is read as the first column of the matrix and
            `x[..., 3:]` as (a vector in the plane of) the second column. Neither need be unit
            or orthogonal.

    Returns:
        `(..., 3, 3)` rotation matrix with columns `b1 = a1 / |a1|`,
            `b2 = normalise(a2 - (b1 . a2) b1)` and `b3 = b1 x b2`.

    Note:
        Defined and smooth wherever `a1 != 0` and `a2` is not parallel to `a1`. It returns
        NaN where `a1` or `a2` is zero, where `a2`'s residual after removing its `a1` part
        rounds to exactly zero, and for an infinite or NaN component: no rotation is closer
        than any other. (`a2` parallel to `a1` up to rounding leaves a residual of rounding
        errors, whose direction the second column then follows.) The two halves are prescaled
        by exact powers of two, so any finite non-zero scale of either gives the same matrix
        (float32 from 1e-30 to 1e30, float64 from 1e-300 to 1e300), with finite gradients.
        The map is surjective and continuous, unlike quaternions or Euler angles read as
        network outputs, which is why it regresses better.

    Examples:
        ```python
        import rotjax as rj

        R = rj.sixd_to_matrix([2.0, 0.0, 0.0, 1.0, 1.0, 0.0])  # neither unit nor orthogonal
        print(R.round(6))
        # [[1. 0. 0.]
        #  [0. 1. 0.]
        #  [0. 0. 1.]]
        ```
    """
    (x,), dt = as_float(x)
    check_shape(x, (6,), "x")
    x = unstack(x)
    b1 = _unit(x[:3])
    a2 = _direction_scaled(x[3:])
    dot = dot3(b1, a2)
    b2 = _unit([a - dot * b for a, b in zip(a2, b1, strict=True)])
    b3 = cross3(b1, b2)
    return cast(stack_matrix([[b1[i], b2[i], b3[i]] for i in range(3)]), dt)


def _direction_scaled(v, mark=False):
    """The components of `v` times the exact power of two that brings the largest into
    `[1, 2)`: their squares and products then neither overflow nor underflow. Used for
    directions, which do not depend on the factor (it carries no derivative). `mark`: NaN for
    a zero, infinite or NaN `v`."""
    s, _ = exponent_scale(*v, mark=mark)
    return [x * s for x in v]


def _unit(v):
    """`v / |v|` for three components at any finite non-zero scale; NaN for a zero, infinite
    or NaN `v`."""
    v = _direction_scaled(v, mark=True)
    inv = rsqrt(dot3(v, v))  # in [1, 12) after the scaling: rsqrt's domain
    return [x * inv for x in v]


@public
def matrix_to_sixd(R: ArrayLike) -> Array:
    """Rotation matrix to the 6D representation: its first two columns, concatenated.

    Args:
        R: `(..., 3, 3)` rotation matrix.

    Returns:
        `(..., 6)`: `(R[..., :, 0], R[..., :, 1])`. `sixd_to_matrix` inverts it on SO(3).

    Examples:
        ```python
        import rotjax as rj

        R = rj.rotvec_to_matrix([0.0, 0.0, 90.0], degrees=True)
        print(rj.matrix_to_sixd(R).round(6))
        # [-0.  1.  0. -1. -0.  0.]
        ```
    """
    (R,), dt = as_float(R)
    check_shape(R, (3, 3), "R")
    return cast(jnp.concatenate([R[..., :, 0], R[..., :, 1]], axis=-1), dt)


@public
def nined_to_matrix(x: ArrayLike) -> Array:
    """Nearest rotation matrix to an arbitrary 3x3 (Levinson et al. 2020), without an SVD.

    Args:
        x: `(..., 9)` entries of a 3x3 matrix `M` in row-major order (a network output);
            pass `M.reshape(*M.shape[:-2], 9)` to project a matrix. Any finite scale
            (float32 1e-30..1e30, float64 1e-300..1e300; the result does not depend on it).

    Returns:
        `(..., 3, 3)` the special-orthogonal polar factor of `M`: the rotation `R`
            minimising `||R - M||_F`, i.e. `U diag(1, 1, det(U V^T)) V^T` for the SVD
            `M = U diag(s) V^T` (`det M < 0` included). For `M` already a rotation, `R = M`.
            Computed as the rotation of the top eigenvector of Bar-Itzhack's symmetric 4x4 `K(M)`
            (Bar-Itzhack 2000), whose eigenvalue gap is `2 (s'_2 + s'_3)` (`s'` the singular
            values with `det(U V^T)` moved into `s'_3`).

    Note:
        Gradients and Hessians are exact wherever the projection is unique (`s'_2 + s'_3 > 0`),
        including every exact rotation and isotropic noise, where singular values tie. The
        projection is not unique for `rank(M) <= 1` or for `det M < 0` with `s_2 = s_3`:
        the gradient there is finite, with zero component along the undetermined rotation.
        The zero matrix and non-finite entries give NaN.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        M = jnp.array([[1.0, 0.1, 0.0], [-0.1, 1.0, 0.0], [0.0, 0.0, 2.0]])  # not a rotation
        R = rj.nined_to_matrix(M.reshape(9))
        print(jnp.allclose(R @ R.T, jnp.eye(3), atol=1e-6), jnp.linalg.det(R).round(6))
        # True 1.0
        ```
    """
    (x,), dt = as_float(x)
    check_shape(x, (9,), "x")
    return cast(nearest_rotation(x.reshape(*x.shape[:-1], 3, 3)), dt)


# --- Wahba's problem --------------------------------------------------------------------


@public
def align_vectors(
    a: ArrayLike,
    b: ArrayLike,
    weights: ArrayLike | None = None,
    method: str = "svd",
    scalar_first: bool = False,
) -> Array:
    """Rotation that best maps the vectors `b` onto `a` (Wahba's problem).

    Finds the `R` minimising `sum_i w_i |a_i - R b_i|^2`, as `scipy`'s
    `Rotation.align_vectors(a, b, weights)`: `b` are in the body frame, `a` in the
    reference frame, and `a_i ~ R @ b_i`. Equivalently `R` maximises `tr(R^T B)` with the
    attitude profile matrix `B = sum_i w_i a_i b_i^T`.

    Args:
        a: `(..., N, 3)` vectors in the reference frame.
        b: `(..., N, 3)` the same vectors in the body frame; broadcasts against `a`.
        weights: `(..., N)` non-negative weights; `None` for all ones.
        method: `"svd"` or `"q-method"`, kept for compatibility: both are computed the
            same way, as the top eigenvector of Davenport's symmetric 4x4 `K(B)` (Davenport's
            q-method), which maximises `tr(R^T B)` exactly as the SVD solution
            `U diag(1, 1, det(U V^T)) V^T` of `B` does (Markley 1988), without an SVD.
        scalar_first: return `(w, x, y, z)`.

    Returns:
        `(..., 4)` unit quaternion of `R`, with `w >= 0` (`|w| <= 4 eps` at 180 degrees,
            as in [`matrix_to_quaternion`][rotjax.matrix_to_quaternion]). NaN where all weights
            (or all vectors) are zero, or an entry is not finite. The result does not depend on
            the scale of `a`, `b` or the weights (e.g. magnetometer data in tesla or
            microtesla).

    Raises:
        ValueError: for shapes other than `(..., N, 3)` or an unknown `method`.

    Note:
        Where the solution is unique (two or more non-parallel vectors with positive weight)
        gradients and Hessians are exact, including noise-free data, where singular values of
        `B` tie: the eigenvalue gap of `K` is `2 (s_2 + s_3) > 0`.

        With a single vector pair (or all vectors parallel) any rotation about `a` composed
        with the optimum is optimal too, and one of them is returned. The gradient is then
        finite: its component along the undetermined rotation about `a` is zero, and the rest,
        which moves `R b` to follow `a`, is exact. Functions of `R b` therefore have exact
        gradients there.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        q_true = rj.rotvec_to_quaternion([0.1, -0.2, 0.3])
        b = jnp.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])  # body frame
        a = rj.quaternion_apply(q_true, b)  # the same vectors in the reference frame
        q = rj.align_vectors(a, b)
        print(rj.angle_between(q, q_true) < 1e-6)
        # True
        ```
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
        a = a * pow2_scale(weights, (-1,))[..., None]
    # Each set of vectors scaled by a power of two (exact) inside the products, so that B
    # neither underflows nor overflows; the rotation does not depend on these scales.
    B = _sum_outer(a, b, pow2_factors(a, (-2, -1)), pow2_factors(b, (-2, -1)))
    q = nearest_quaternion(B, summed=True)
    return cast(from_scalar_last(q, scalar_first), dt)  # w >= 0


# --- averaging and interpolation ---------------------------------------------------------


@public
def quaternion_mean(
    q: ArrayLike, weights: ArrayLike | None = None, scalar_first: bool = False
) -> Array:
    """Weighted average rotation (Markley et al. 2007).

    The unit quaternion maximising `sum_i w_i (q . q_i)^2`: the top eigenvector of
    `sum_i w_i q_i q_i^T`. It minimises the weighted sum of squared chordal distances
    `||R(q) - R(q_i)||_F^2`.

    Args:
        q: `(..., N, 4)` quaternions; need not be unit (each is normalised first, at any
            finite scale) and the sign of each is irrelevant.
        weights: `(..., N)` non-negative weights; `None` for all ones.
        scalar_first: quaternions (input and output) are `(w, x, y, z)`.

    Returns:
        `(..., 4)` unit quaternion with `w >= 0` (`|w| <= 4 eps` at 180 degrees, as in
            `matrix_to_quaternion`).

    Raises:
        ValueError: for an empty set (`N = 0`) or mismatched shapes.

    Note:
        For rotations about one axis by angles `t_i` the mean is the rotation by the circular
        mean `atan2(sum w_i sin t_i, sum w_i cos t_i)`. All-zero weights give NaN. Gradients
        and Hessians are exact where the top eigenvalue is simple, identical inputs included.
        The mean is undefined when the top eigenvalue is repeated (e.g. two rotations 180
        degrees apart with equal weights); the gradient is then finite, with zero component
        within the tied eigenspace.

    Examples:
        ```python
        import rotjax as rj

        q = rj.rotvec_to_quaternion([[0.0, 0.0, 0.1], [0.0, 0.0, 0.3]])
        mean = rj.quaternion_mean(q)
        print(rj.quaternion_to_rotvec(mean).round(6))
        # [-0.  -0.   0.2]
        ```
    """
    if weights is None:
        (q,), dt = as_float(q)
    else:
        (q, weights), dt = as_float(q, weights)
    check_shape(q, (4,), "q")
    if q.ndim < 2:
        raise ValueError(f"q: expected shape (..., N, 4), got {tuple(q.shape)}")
    if q.shape[-2] == 0:
        raise ValueError("q: the mean of an empty set (N = 0) is undefined")
    q = quat_normalize(to_scalar_last(q, scalar_first))
    if weights is not None and (weights.ndim < 1 or weights.shape[-1] != q.shape[-2]):
        raise ValueError(f"weights: expected shape (..., {q.shape[-2]}), got {weights.shape}")
    qw = q if weights is None else q * pow2_scale(weights, (-1,))[..., None]
    M = _sum_outer(qw, q, (), ())
    v = top_eigenvector(M)
    if weights is not None:
        v = where(jnp.all(weights == 0, axis=-1, keepdims=True), jnp.nan, v)
    return cast(from_scalar_last(v, scalar_first), dt)  # w >= 0


@public
def slerp(p: ArrayLike, q: ArrayLike, t: ArrayLike, scalar_first: bool = False) -> Array:
    """Spherical linear interpolation along the shorter arc: `p * (p^-1 q)^t`.

    Args:
        p: `(..., 4)` start quaternion; need not be unit.
        q: `(..., 4)` end quaternion; need not be unit; broadcasts against `p`.
        t: `(...)` interpolation parameter (0 gives `p`, 1 gives `q`; values outside
            `[0, 1]` extrapolate); broadcasts against `p[..., 0]`.
        scalar_first: quaternions are `(w, x, y, z)`.

    Returns:
        `(..., 4)` unit quaternion. The angle from `p` grows as `t` times the angle
            between `p` and `q`: constant angular speed. At `t = 0` it is `p / |p|`; at
            `t = 1` it is `q / |q|` or its negative (the same rotation).

    Note:
        Written as the exponential of `t` times the logarithm of the relative rotation, both
        with Taylor branches, so there is no `sin(theta) / sin(theta)` 0/0 as `p -> q`:
        values and gradients are exact there. `q` and `-q` are the same rotation and give
        the same path, so `p = -q` is a constant path. When the relative rotation is exactly
        180 degrees, both arcs are equally short and the one chosen follows the sign of the
        relative quaternion's vector part (the logarithm has a cut there).

    Examples:
        ```python
        import rotjax as rj

        p = rj.rotvec_to_quaternion([0.0, 0.0, 0.0])
        q = rj.rotvec_to_quaternion([0.0, 0.0, 1.0])
        print(rj.quaternion_to_rotvec(rj.slerp(p, q, 0.25)).round(6))
        # [0.   0.   0.25]
        ```
    """
    (p, q, t), dt = as_float(p, q, t)
    check_shape(p, (4,), "p")
    check_shape(q, (4,), "q")
    check_shape(t, (), "t")
    p = quat_normalize(to_scalar_last(p, scalar_first))
    q = to_scalar_last(q, scalar_first)
    rel = quat_to_rotvec(quat_multiply(quat_conjugate(p), q))  # angle in [0, pi]: the shorter arc
    # t times the parts of rel (read as they are: a stacked product would be read by slices)
    t = as_part(t)
    out = quat_multiply(p, rotvec_to_quat(stack([t * x for x in unstack(rel)])))
    return cast(from_scalar_last(out, scalar_first), dt)
