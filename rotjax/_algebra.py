"""Quaternion algebra the class API needs: canonical sign, fractional powers, finite rotation
groups and reduction by them, and the sensitivity of Wahba's problem."""

from __future__ import annotations

import functools
import itertools

import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.typing import ArrayLike, DTypeLike

from ._numerics import (
    FULL,
    as_float,
    as_part,
    cast,
    check_shape,
    check_static,
    from_scalar_last,
    like_rank,
    matmul,
    public,
    stack,
    to_scalar_last,
    unstack,
    where,
)
from ._quaternion import quat_multiply, quat_normalize
from ._rotvec import quat_to_rotvec, rotvec_to_quat


def _canonical(q):
    """Sign flip making the first non-zero of `(w, x, y, z)` positive (scalar-last `q`)."""
    x, y, z, w = jnp.moveaxis(q, -1, 0)
    lead = where(w != 0, w, where(x != 0, x, where(y != 0, y, z)))
    return where((lead < 0)[..., None], -q, q)


def _svd_signed(M):
    """SVD `M = U diag(s) V^T` with the sign of `det` moved into `U[:, 2]` and `s[2]`.

    Then `U @ V^T` is in SO(3) and `s[2]` is negative when `det M < 0`.
    """
    U, s, Vt = jnp.linalg.svd(M)
    d = jnp.sign(jnp.linalg.det(matmul(U, Vt)))  # exactly +-1 up to rounding: U, V are orthogonal
    flip = jnp.stack([jnp.ones_like(d), jnp.ones_like(d), d], axis=-1)
    return U * flip[..., None, :], s * flip, Vt


@public
def quaternion_canonical(q: ArrayLike, scalar_first: bool = False) -> Array:
    """The one of `q` and `-q` whose first non-zero component of `(w, x, y, z)` is positive.

    Args:
        q: `(..., 4)` quaternion (not normalised).
        scalar_first: `q` (input and output) is `(w, x, y, z)`.

    Returns:
        `(..., 4)` `q` or `-q`: `w > 0`, or `w = 0` and `x > 0`, and so on; as
            scipy's `as_quat(canonical=True)`.

    Note:
        The sign is piecewise constant, so the gradient is that of `+-q`: finite everywhere.

    Examples:
        ```python
        import rotjax as rj

        print(rj.quaternion_canonical([0.0, 0.0, 0.6, -0.8]))  # w < 0: the sign flips
        # [-0.  -0.  -0.6  0.8]
        ```
    """
    (q,), dt = as_float(q)
    check_shape(q, (4,), "q")
    out = _canonical(to_scalar_last(q, scalar_first))
    return cast(from_scalar_last(out, scalar_first), dt)


@public
def quaternion_power(q: ArrayLike, n: ArrayLike, scalar_first: bool = False) -> Array:
    """Fractional power `q^n = exp(n log q)` of a rotation: the angle times `n`, same axis.

    Args:
        q: `(..., 4)` quaternion; need not be unit (zero gives NaN).
        n: `(...)` exponent; broadcasts against `q[..., 0]`. `n = -1` is the inverse,
            `n = 0` the identity, `n = 2` the rotation applied twice.
        scalar_first: `q` (input and output) is `(w, x, y, z)`.

    Returns:
        `(..., 4)` unit quaternion, the rotation by `n` times the angle of `q` in
            `[0, pi]` about its axis (scipy's `Rotation.__pow__`).

    Note:
        The logarithm and exponential have Taylor branches at the identity: values and
        gradients are exact there. At exactly 180 degrees the logarithm has a cut (the axis
        sign follows the vector part), so non-integer powers of a half turn pick one side.

    Examples:
        ```python
        import rotjax as rj

        q = rj.axis_angle_to_quaternion([0.0, 0.0, 1.0], 90.0, degrees=True)
        _, angle = rj.quaternion_to_axis_angle(rj.quaternion_power(q, 0.5), degrees=True)
        print(angle.round(4))
        # 45.0
        ```
    """
    (q, n), dt = as_float(q, n)
    check_shape(q, (4,), "q")
    q = to_scalar_last(q, scalar_first)
    v = quat_to_rotvec(q)
    # n times v's components (an array product would be read back by slices: see stack)
    n = as_part(like_rank(n, q[..., 0]))
    out = rotvec_to_quat(stack([n * x for x in unstack(v)]))
    return cast(from_scalar_last(out, scalar_first), dt)


# --- finite rotation groups ------------------------------------------------------------


_GROUP_AXES = {"X": 0, "Y": 1, "Z": 2}


def _cyclic(n: int, axis: int) -> np.ndarray:
    t = np.pi * np.arange(n) / n  # half angles of the rotations by 2 pi k / n
    q = np.zeros((n, 4))
    q[:, axis] = np.sin(t)
    q[:, 3] = np.cos(t)
    return q


def _dihedral(n: int, axis: int) -> np.ndarray:
    # C_n plus the n half turns about axes perpendicular to `axis`, spaced pi / n apart,
    # starting at the next coordinate axis after `axis`.
    t = np.pi * np.arange(n) / n
    u, v = (axis + 1) % 3, (axis + 2) % 3
    flips = np.zeros((n, 4))
    flips[:, u] = np.cos(t)
    flips[:, v] = np.sin(t)
    return np.concatenate([_cyclic(n, axis), flips])


def _signed_permutations(base, even_only: bool) -> np.ndarray:
    """Distinct quaternions from permutations of `base` with all sign choices, one of each
    +-q pair."""
    out = set()
    for perm in itertools.permutations(range(4)):
        inversions = sum(perm[i] > perm[j] for i in range(4) for j in range(i + 1, 4))
        if even_only and inversions % 2:
            continue
        for signs in itertools.product((1, -1), repeat=4):
            q = tuple(float(s * base[p]) for s, p in zip(signs, perm, strict=True))
            first = next(c for c in q if c != 0)
            out.add(q if first > 0 else tuple(-c for c in q))
    return np.array(sorted(out))


def _polyhedral(name: str) -> np.ndarray:
    units = _signed_permutations((1.0, 0.0, 0.0, 0.0), False)  # the 4 half turns and identity
    halves = _signed_permutations((0.5, 0.5, 0.5, 0.5), False)  # the 8 third turns
    tetra = np.concatenate([units, halves])  # 12
    if name == "T":
        return tetra
    if name == "O":
        r = 0.5**0.5
        return np.concatenate([tetra, _signed_permutations((r, r, 0.0, 0.0), False)])  # 24
    phi = (1 + 5**0.5) / 2
    # The 120 icosians: the 24 Hurwitz units and the even permutations of
    # (+-phi, +-1, +-1/phi, 0) / 2 (Conway & Smith, "On Quaternions and Octonions", ch. 4).
    return np.concatenate([tetra, _signed_permutations((phi / 2, 0.5, 0.5 / phi, 0.0), True)])  # 60


def _group(group: str, axis: str) -> np.ndarray:
    if not isinstance(group, str):
        raise ValueError(f"`group` argument must be a string, got {group!r}")
    if not isinstance(axis, str) or axis not in _GROUP_AXES:
        raise ValueError(f"`axis` must be one of 'X', 'Y', 'Z', got {axis!r}")
    return _group_cached(group, axis)


@functools.cache
def _group_cached(group: str, axis: str) -> np.ndarray:
    names = "`group` must be one of 'I', 'O', 'T', 'Dn', 'Cn'"
    kind, order = group[:1].upper(), group[1:]
    if kind in "CD" and len(group) > 1:
        if not order.isdigit():
            raise ValueError(f"{names} (n a positive integer), got {group!r}")
        if int(order) < 1:
            raise ValueError(f"Group order must be positive, got {group!r}")
        n = int(order)
        q = _cyclic(n, _GROUP_AXES[axis]) if kind == "C" else _dihedral(n, _GROUP_AXES[axis])
    elif group.upper() in ("T", "O", "I"):
        q = _polyhedral(group.upper())
    else:
        raise ValueError(f"{names} (n a positive integer), got {group!r}")
    return q


def rotation_group(
    group: str, axis: str = "Z", dtype: DTypeLike | None = None, scalar_first: bool = False
) -> Array:
    """Quaternions of a finite subgroup of SO(3).

    Args:
        group: `"Cn"` (cyclic: `n` rotations about `axis`), `"Dn"` (dihedral: `C_n`
            and `n` half turns about axes perpendicular to `axis`), `"T"` (tetrahedral,
            12), `"O"` (octahedral, 24) or `"I"` (icosahedral, 60). `n` is a positive
            integer.
        axis: `"X"`, `"Y"` or `"Z"`: the principal axis of `Cn` and `Dn`.
        dtype: float dtype of the result; JAX's default float if `None`.
        scalar_first: return `(w, x, y, z)`.

    Returns:
        `(N, 4)` unit quaternions, one per group element, the identity first for `Cn` and
            `Dn`. Computed in float64 with NumPy, then cast.

    Raises:
        ValueError: for an unknown group or axis.

    Examples:
        ```python
        import rotjax as rj

        print(rj.rotation_group("O").shape, rj.rotation_group("D3").shape)
        # (24, 4) (6, 4)
        print(rj.rotation_group("C4").round(6))
        # [[ 0.        0.        0.        1.      ]
        #  [ 0.        0.        0.707107  0.707107]
        #  [ 0.        0.        1.        0.      ]
        #  [ 0.        0.        0.707107 -0.707107]]
        ```
    """
    if dtype is not None and not jnp.issubdtype(dtype, jnp.floating):
        raise TypeError(f"dtype must be real (a floating dtype), got {jnp.dtype(dtype)}")
    scalar_first = check_static("scalar_first", scalar_first)
    q = jnp.asarray(_group(group, axis), dtype=dtype if dtype is not None else float)
    return from_scalar_last(q, scalar_first)


@public
def quaternion_reduce(
    q: ArrayLike,
    left: ArrayLike | None = None,
    right: ArrayLike | None = None,
    scalar_first: bool = False,
) -> tuple[Array, Array, Array]:
    """Reduce rotations by groups: `l * q * r` with `l`, `r` from the groups chosen to
    make the rotation angle smallest (scipy's `Rotation.reduce`).

    Args:
        q: `(..., 4)` quaternions; need not be unit.
        left: `(L, 4)` quaternions of the left group, or `None` (identity only).
        right: `(M, 4)` quaternions of the right group, or `None`.
        scalar_first: quaternions (input and output) are `(w, x, y, z)`.

    Returns:
        reduced: `(..., 4)` unit quaternions `l * q * r`.
        left_index: `(...)` integer index of the chosen `l` in `left` (0 if `left` is
            `None`).
        right_index: `(...)` integer index of the chosen `r` in `right` (0 if `right` is
            `None`).

    Note:
        The smallest angle is the largest `|w|`; ties go to the lowest flat index
        `left_index * M + right_index`. The choice is piecewise constant, so the gradient is
        that of the chosen product (finite).

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        group = rj.rotation_group("C4")  # quarter turns about z
        q = rj.axis_angle_to_quaternion([0.0, 0.0, 1.0], 100.0, degrees=True)
        reduced, left_index, right_index = rj.quaternion_reduce(q, left=group)
        print(jnp.rad2deg(rj.rotation_angle(reduced)).round(4), left_index)
        # 10.0 3
        ```
    """
    arrays = [x for x in (q, left, right) if x is not None]
    conv, dt = as_float(*arrays)
    q = quat_normalize(to_scalar_last(conv[0], scalar_first))
    check_shape(q, (4,), "q")
    rest = list(conv[1:])
    one = jnp.asarray([[0.0, 0.0, 0.0, 1.0]], dtype=q.dtype)
    groups = []
    for g, name in ((left, "left"), (right, "right")):
        if g is None:
            groups.append(one)
            continue
        g = rest.pop(0)
        if g.ndim != 2:
            raise ValueError(f"{name}: expected shape (N, 4), got {tuple(g.shape)}")
        check_shape(g, (4,), name)
        groups.append(to_scalar_last(g, scalar_first))
    lg, rg = groups
    L, M = lg.shape[0], rg.shape[0]
    # All products l_i * q * r_j, shape (..., L, M, 4).
    batch = q.shape[:-1]
    qr = quat_multiply(  # (..., M, 4); broadcasting made explicit (no rank promotion)
        jnp.broadcast_to(q[..., None, :], batch + (M, 4)), jnp.broadcast_to(rg, batch + (M, 4))
    )
    prod = quat_multiply(  # (..., L, M, 4)
        jnp.broadcast_to(lg[:, None, :], batch + (L, M, 4)),
        jnp.broadcast_to(qr[..., None, :, :], batch + (L, M, 4)),
    )
    flat = jnp.reshape(prod, prod.shape[:-3] + (L * M, 4))
    best = jnp.argmax(jnp.abs(flat[..., 3]), axis=-1)
    out = jnp.take_along_axis(flat, best[..., None, None], axis=-2)[..., 0, :]
    return from_scalar_last(out, scalar_first).astype(dt), best // M, best % M


@public
def wahba_sensitivity(a: ArrayLike, b: ArrayLike, weights: ArrayLike | None = None) -> Array:
    """Sensitivity matrix of Wahba's problem (Markley & Crassidis 2014, Sec. 5.5.4).

    The covariance of the attitude error (rotation vector, reference frame) of
    [`align_vectors`][rotjax.align_vectors]' solution for measurement noise of unit variance per
    weight, up to the factor the noise variance. This is scipy's `align_vectors(...,
    return_sensitivity=True)` matrix: `mean(w) / zeta * (kappa I + B B^T)` with `B = sum w_i a_i
    b_i^T` and the signed singular values `s` of `B`, `zeta = (s1 + s2)(s2 + s3)(s3 + s1)`, `kappa =
    s1 s2 + s2 s3 + s3 s1`.

    Args:
        a: `(..., N, 3)` reference-frame vectors.
        b: `(..., N, 3)` body-frame vectors.
        weights: `(..., N)` non-negative weights; `None` for all ones.

    Returns:
        `(..., 3, 3)` symmetric matrix.

    Note:
        `zeta = 0` (all vectors parallel: the rotation about them is unobservable) gives
        inf/NaN, as the covariance is unbounded.

    Examples:
        ```python
        import jax.numpy as jnp
        import rotjax as rj

        a = jnp.eye(3)  # three orthogonal directions, observed without rotation
        print(rj.wahba_sensitivity(a, a).round(6))
        # [[0.5 0.  0. ]
        #  [0.  0.5 0. ]
        #  [0.  0.  0.5]]
        ```
    """
    if weights is None:
        (a, b), dt = as_float(a, b)
        weights = jnp.ones(a.shape[:-1], a.dtype)
    else:
        (a, b, weights), dt = as_float(a, b, weights)
    check_shape(a, (3,), "a")
    check_shape(b, (3,), "b")
    B = jnp.einsum("...n,...ni,...nj->...ij", weights, a, b, precision=FULL)
    _, s, _ = _svd_signed(B)
    s1, s2, s3 = jnp.moveaxis(s, -1, 0)
    zeta = (s1 + s2) * (s2 + s3) * (s3 + s1)
    kappa = s1 * s2 + s2 * s3 + s3 * s1
    BBt = jnp.einsum("...ij,...kj->...ik", B, B, precision=FULL)
    eye = jnp.eye(3, dtype=B.dtype)
    scale = (jnp.mean(weights, axis=-1) / zeta)[..., None, None]
    return cast((scale * (kappa[..., None, None] * like_rank(eye, BBt) + BBt)), dt)
