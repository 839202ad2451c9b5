"""`RigidTransform`: scipy's rigid-transform API over rotjax's functions, as a pytree.

The class holds two arrays, the `(..., 4)` scalar-last quaternion of the rotation (any
non-zero norm, as `Rotation` holds it) and the `(..., 3)` translation, so that
`T v = R v + t`; every computation is one jitted function of those arrays, built on rotjax's
quaternion and rotation-vector functions.
"""

from __future__ import annotations

from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.typing import ArrayLike, DTypeLike

from ._elementary import rsqrt
from ._fitting import quaternion_mean
from ._matrix import matrix_to_quaternion
from ._numerics import (
    as_part,
    broadcast_batch,
    det3,
    jit,
    matvec,
    max_abs,
    public,
    stack,
    stack_matrix,
    to_scalar_last,
    unit_scale,
    unstack,
    unstack_matrix,
    where,
)
from ._quaternion import (
    quat_conjugate,
    quat_multiply,
    quat_normalize,
    quat_rescaled,
    quat_to_matrix,
    quat_turn,
)
from ._rotation import (
    BatchedPytree,
    Rotation,
    constructor_input,
    float_array,
    host_value,
    identity_quat,
)
from ._se3 import exp_parts, homogeneous, log_parts

# --- SE(3) exponential coordinates ------------------------------------------------------
#
# exp([phi, v]) = (exp(phi), Jl(phi) v) and its inverse, with the SO(3) left Jacobian and its
# inverse from rotjax._se3 (applied without forming the matrix), on the quaternion.


def _rotate(q, v, t=None):
    """``R(q) v`` (``+ t``) for a unit scalar-last ``q``, all of one batch shape. Sums and
    negations of results are taken on their components (see :func:`_pose_inv`): an array
    operation on a stacked result leaves an array that its readers slice."""
    v = unstack(v)
    out = [a + d for a, d in zip(v, quat_turn(unstack(q), v), strict=True)]
    return out if t is None else [a + b for a, b in zip(out, unstack(t), strict=True)]


def _pose_exp(xi):
    xi = unstack(xi)
    q, t = exp_parts(xi[:3], xi[3:])
    return stack(q), stack(t)


def _pose_log(q, t):
    return stack(log_parts(unstack(q), unstack(t)))


# --- jitted kernels ----------------------------------------------------------------------


@jit(static_argnames="normalize")
def _pose_from_matrix(m, normalize):
    # Rotation part: the nearest rotation (Frobenius norm), as Rotation.from_matrix; a 3x3
    # block with det <= 0 or a last row other than [0, 0, 0, 1] gives NaN (scipy raises, or
    # gives NaN for lazy arrays).
    # The entries read as unstack reads (a slice's transpose in reverse mode is a pad,
    # evaluated per element in a branch of its own).
    e = unstack_matrix(m)
    if normalize:
        ok = det3([*e[0:3], *e[4:7], *e[8:11]]) > 0
        ok = ok & (e[12] == 0) & (e[13] == 0) & (e[14] == 0) & (e[15] == 1)
        # The mask on the inputs (the projection of NaN is NaN): in reverse mode it then masks
        # the cotangent once, where it is written, rather than inside each loop of the
        # projection's derivative, which recomputed the determinant in each.
        e = [where(ok, x, jnp.nan) for x in e]
    r = stack_matrix([e[0:3], e[4:7], e[8:11]])
    t = stack([e[3], e[7], e[11]])
    if r.size == 0:  # an empty batch (the eigen kernel cannot reshape one)
        return jnp.zeros(r.shape[:-2] + (4,), r.dtype), t
    return matrix_to_quaternion(r, method="optimal" if normalize else "shepperd"), t


@jit
def _as_matrix(q, t):
    # NaN in the quaternion reaches the last row too (0 |w| is +0 or NaN), as in scipy.
    q = unstack(q)
    return homogeneous(q, unstack(t), 0 * jnp.abs(q[3]))


@jit
def _pose_compose(q1, t1, q2, t2):
    # Stored quaternions of any norm: q1 is normalised once, for the product and the rotated
    # translation; q2 only rescaled (as Rotation composes), so the product is of order 1, or
    # NaN where either is not a rotation.
    q1, t1, q2, t2 = broadcast_batch(q1, t1, q2, t2)
    u1 = quat_normalize(q1)
    return quat_multiply(u1, quat_rescaled(q2)), stack(_rotate(u1, t2, t1))


@jit
def _pose_inv(q, t):
    qc = quat_conjugate(q)
    return qc, stack([-x for x in _rotate(qc, t)])


@jit(static_argnames="inverse")
def _pose_apply(q, t, v, inverse):
    batch = np.broadcast_shapes(q.shape[:-1], v.shape[:-1])
    if inverse:
        q, t = _pose_inv(q, t)
    if np.prod(q.shape[:-1]) < np.prod(v.shape[:-1]):
        # Fewer transforms than vectors: each matrix once, then 9 multiply-adds a vector.
        r = quat_to_matrix(q, bounded=True)
        r, t, v = jnp.broadcast_to(r, batch + (3, 3)), *broadcast_batch(t, v)
        return matvec(r, v) + t
    q, t, v = broadcast_batch(q, t, v)
    return stack(_rotate(q, v, t))


@jit
def _from_exp_coords(xi):
    return _pose_exp(xi)


@jit
def _as_exp_coords(q, t):
    return _pose_log(q, t)


@jit
def _pow(q, t, n):
    n = as_part(n)  # times the logarithm's components: see _rotate
    return _pose_exp(stack([n * x for x in unstack(_pose_log(q, t))]))


def _normalize_dq(real, dual):
    """scipy's dual-quaternion normalisation: unit real part, dual part orthogonal to it; a
    zero real part becomes the identity."""
    # Both parts scaled by one exact power of two first, so |real|^2 cannot overflow or
    # underflow (the result does not depend on that factor).
    big = max_abs(*jnp.moveaxis(real, -1, 0))
    zero = (big == 0)[..., None]
    scale = where(zero, jnp.ones_like(real[..., :1]), unit_scale(big)[..., None])
    real, dual = real * scale, dual * scale
    n2 = jnp.sum(real * real, axis=-1, keepdims=True)
    ident = jnp.zeros_like(real).at[..., 3].set(1)
    real = where(zero, ident, real)
    inv = rsqrt(where(zero, jnp.ones_like(n2), n2))  # double where; n2 in [1, 4)
    real, dual = real * inv, dual * inv
    return real, dual - jnp.sum(real * dual, axis=-1, keepdims=True) * real


@jit(static_argnames="scalar_first")
def _from_dual_quat(dq, scalar_first):
    real = to_scalar_last(dq[..., :4], scalar_first)
    dual = to_scalar_last(dq[..., 4:], scalar_first)
    real, dual = _normalize_dq(real, dual)
    return real, 2 * quat_multiply(dual, quat_conjugate(real))[..., :3]


@jit(static_argnames="scalar_first")
def _as_dual_quat(q, t, scalar_first):
    tq = jnp.concatenate([t, jnp.zeros_like(t[..., :1])], axis=-1)
    dual = 0.5 * quat_multiply(tq, q)
    if scalar_first:
        q, dual = jnp.roll(q, 1, axis=-1), jnp.roll(dual, 1, axis=-1)
    return jnp.concatenate([q, dual], axis=-1)


@jit
def _mean(q, t, w):
    """Means over the second-to-last axis: ``q`` ``(..., N, 4)``, ``t`` ``(..., N, 3)``,
    ``w`` ``(..., N)`` or ``None``; a negative weight gives NaN for its set."""
    if w is None:
        return quaternion_mean(q), jnp.mean(t, axis=-2)
    w = where(w < 0, jnp.nan, w)
    tm = jnp.sum(w[..., None] * t, axis=-2) / jnp.sum(w, axis=-1)[..., None]
    return quaternion_mean(q, w), tm


@public
def normalize_dual_quaternion(dual_quat: ArrayLike, *, scalar_first: bool = False) -> Array:
    """Normalise dual quaternions (scipy's definition).

    A unit dual quaternion `r + eps d` has a unit real part `r` and a dual part `d` orthogonal
    to it. This divides both parts by `|r|` and then removes from `d` its component along `r`;
    a zero real part becomes the identity `[0, 0, 0, 1]` (scipy's rule), with the dual part
    kept.

    Args:
        dual_quat: `(..., 8)` dual quaternions `[real, dual]`, each part scalar last.
        scalar_first: each part is `[w, x, y, z]` (the result too).

    Returns:
        `(..., 8)` unit dual quaternions, in the input's layout and dtype.

    Examples:
        ```python
        import rotjax as rj

        print(rj.normalize_dual_quaternion([0.0, 0.0, 0.0, 2.0, 1.0, 0.0, 0.0, 1.0]))
        # [0.  0.  0.  1.  0.5 0.  0.  0. ]
        ```
    """
    dq = jnp.asarray(dual_quat)
    if dq.ndim < 1 or dq.shape[-1] != 8:
        raise ValueError(f"Expected `dual_quat` to have shape (..., 8), got {dq.shape}.")
    if not jnp.issubdtype(dq.dtype, jnp.floating):
        dq = dq.astype(float)
    real = to_scalar_last(dq[..., :4], scalar_first)
    dual = to_scalar_last(dq[..., 4:], scalar_first)
    real, dual = _normalize_dq(real, dual)
    if scalar_first:
        real, dual = jnp.roll(real, 1, axis=-1), jnp.roll(dual, 1, axis=-1)
    return jnp.concatenate([real, dual], axis=-1)


# --- the class ---------------------------------------------------------------------------


def _check_last(x, n, name):
    if x.ndim < 1 or x.shape[-1] != n:
        raise ValueError(f"Expected `{name}` to have shape (..., {n}), got {x.shape}.")


def _common(*arrays):
    """The arrays in one float dtype (NumPy's promotion, so float32 meets float64 explicitly
    even under strict dtype promotion)."""
    dt = np.result_type(*(a.dtype for a in arrays))
    return tuple(a.astype(dt) for a in arrays)


@jax.tree_util.register_pytree_node_class
class RigidTransform(BatchedPytree):
    """Rigid transforms (rotation and translation) in 3 dimensions, scipy's API on JAX arrays.

    `T v = R v + t`: a rotation `R` followed by a translation `t`; as a matrix
    `[[R, t], [0, 1]]` acting on `[v, 1]`. `p * q` applies `q` first.

    A `RigidTransform` is a pytree of two leaves, the `(..., 4)` quaternion of `R` (scalar last, any
    non-zero norm, as a `Rotation` holds it) and the `(..., 3)` translation, with no other data:
    every constructor gives the same tree structure, `jax.jit` takes and returns it, `jax.vmap` maps
    over its batch axes, `lax.scan` carries it and `jax.grad` differentiates through every method. A
    transform with `(4,)` and `(3,)` leaves is *single* (no `len`, no indexing); otherwise `shape`
    is the batch shape. float32 and float64 are kept.

    Exponential coordinates are scipy's `[rotation vector, v]` (rotation first):
    `exp([phi, v]) = (exp(phi), J(phi) v)` with `J` the left Jacobian of SO(3). Their
    derivatives are exact at zero rotation and finite up to and at 180 degrees.

    Values scipy rejects (a matrix whose last row is not `[0, 0, 0, 1]` or whose rotation block
    has `det <= 0`, negative weights) raise `ValueError` when they arrive as NumPy arrays, lists
    or numbers; as JAX arrays, and always under `jit`, they give NaN for the affected
    transforms.

    Args:
        matrix: `(..., 4, 4)` homogeneous transformation matrices (as
            [`from_matrix`][rotjax.RigidTransform.from_matrix]).
        normalize: replace each rotation block by the nearest rotation and check the matrix;
            `False` takes the rotation block as a rotation matrix unchecked.
        copy: accepted for scipy compatibility (JAX arrays are immutable).

    Examples:
        ```python
        import jax
        import jax.numpy as jnp
        import rotjax as rj

        R = rj.Rotation.from_rotvec(jnp.array([0.0, 0.0, jnp.pi / 2]))
        T = rj.RigidTransform.from_components(jnp.array([1.0, 0.0, 0.0]), R)
        print(T.apply(jnp.array([1.0, 0.0, 0.0])).round(3))  # rotate, then translate
        # [1. 1. 0.]
        print(jax.jit(lambda T: T.inv() * T)(T).as_exp_coords().round(3))  # a pytree under jit
        # [ 0.  0. -0.  0.  0.  0.]
        ```
    """

    # The leaves: the rotation's quaternion (any non-zero norm, as Rotation stores it) and
    # the translation; the methods read the unit ``_quat``, so a normalisation happens where a
    # value is read (fused into that program), not where one is stored.
    __slots__ = ("_stored", "_translation")
    _LEAVES = ("_stored", "_translation")
    _NOUN = "transform"

    def __init__(self, matrix: ArrayLike, normalize: bool = True, copy: bool = True):
        del copy  # JAX arrays are immutable: there is nothing to copy
        m = constructor_input(matrix)
        if m.ndim < 2 or m.shape[-2:] != (4, 4):
            raise ValueError(f"Expected `matrix` to have shape (..., 4, 4), got {m.shape}.")
        if normalize and isinstance(m, np.ndarray):
            bad = np.any(m[..., 3, :] != np.array([0.0, 0.0, 0.0, 1.0]), axis=-1)
            if np.any(bad):
                idx = tuple(int(i[0]) for i in np.nonzero(bad)) if bad.ndim else ()
                raise ValueError(
                    f"Expected last row of transformation matrix {idx} to be exactly "
                    f"[0, 0, 0, 1], got {m[idx + (3, Ellipsis)]}"
                )
            if m.size and np.any(np.linalg.det(m[..., :3, :3]) <= 0):
                raise ValueError("Non-positive determinant (left-handed or null coordinate frame)")
        self._stored, self._translation = _pose_from_matrix(m, normalize=bool(normalize))
        self._bounded = False

    @classmethod
    def _raw(cls, quat, translation, bounded=False) -> RigidTransform:
        """A transform holding a quaternion (any non-zero norm) and a translation as they are
        (no check); `bounded`: the quaternion is of order 1 or NaN (a product of rescaled or
        unit ones: see `Rotation._raw`), which the readers need not prescale."""
        tf = object.__new__(cls)
        tf._stored = quat
        tf._translation = translation
        tf._bounded = bounded
        return tf

    # --- parts -----------------------------------------------------------------------------

    @property
    def rotation(self) -> Rotation:
        """The rotation part, a [`Rotation`][rotjax.Rotation] of shape `shape`."""
        return Rotation._raw(self._stored, bounded=self._bounded)

    @property
    def translation(self) -> Array:
        """The translation part, `(..., 3)`."""
        return self._translation

    # --- constructors --------------------------------------------------------------------

    @staticmethod
    def from_matrix(matrix: ArrayLike) -> RigidTransform:
        """From `(..., 4, 4)` homogeneous transformation matrices `[[R, t], [0, 1]]`.

        Each rotation block is replaced by the nearest rotation matrix (Frobenius norm, as
        `Rotation.from_matrix`). A block with `det <= 0` or a last row other than `[0, 0, 0, 1]`
        raises `ValueError` for NumPy input and gives NaN for JAX input.

        Args:
            matrix: `(..., 4, 4)` homogeneous transformation matrices.

        Returns:
            The transforms, of batch shape `matrix.shape[:-2]`.

        Examples:
            ```python
            import jax.numpy as jnp
            import rotjax as rj

            T = rj.RigidTransform.from_matrix(jnp.eye(4).at[:3, 3].set(jnp.array([1.0, 2.0, 3.0])))
            print(T.translation, T.single)
            # [1. 2. 3.] True
            ```
        """
        return RigidTransform(matrix)

    @staticmethod
    def from_rotation(rotation: Rotation) -> RigidTransform:
        """A pure rotation (zero translation) from a [`Rotation`][rotjax.Rotation].

        Args:
            rotation: the rotations; their shape is the transforms' batch shape.

        Returns:
            The transforms `[[R, 0], [0, 1]]`.

        Examples:
            ```python
            import jax.numpy as jnp
            import rotjax as rj

            R = rj.Rotation.from_rotvec(jnp.array([0.0, 0.0, jnp.pi / 2]))
            print(rj.RigidTransform.from_rotation(R).as_matrix().round(3))
            # [[-0. -1.  0.  0.]
            #  [ 1. -0.  0.  0.]
            #  [ 0.  0.  1.  0.]
            #  [ 0.  0.  0.  1.]]
            ```
        """
        if not isinstance(rotation, Rotation):
            raise TypeError(
                f"Expected `rotation` to be a `Rotation` instance, got {type(rotation)}."
            )
        q = rotation._stored
        return RigidTransform._raw(q, jnp.zeros(q.shape[:-1] + (3,), q.dtype))

    @staticmethod
    def from_translation(translation: ArrayLike) -> RigidTransform:
        """A pure translation from `(..., 3)` vectors.

        Args:
            translation: `(..., 3)` translations; their batch shape is the transforms'.

        Returns:
            The transforms `[[I, t], [0, 1]]`.

        Examples:
            ```python
            import rotjax as rj

            T = rj.RigidTransform.from_translation([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
            print(T.shape, T.apply([1.0, 1.0, 1.0]))
            # (2,) [[2. 1. 1.]
            #  [1. 3. 1.]]
            ```
        """
        t = float_array(translation)
        _check_last(t, 3, "translation")
        return RigidTransform._raw(identity_quat(t.shape[:-1], t.dtype), t)

    @staticmethod
    def from_components(translation: ArrayLike, rotation: Rotation) -> RigidTransform:
        """Rotation followed by translation: `T v = rotation.apply(v) + translation`.

        Args:
            translation: `(..., 3)` translations.
            rotation: a [`Rotation`][rotjax.Rotation]; its batch shape broadcasts with the
                translation's.

        Returns:
            The transforms `[[R, t], [0, 1]]`, of the broadcast batch shape.

        Examples:
            ```python
            import jax.numpy as jnp
            import rotjax as rj

            R = rj.Rotation.from_rotvec(jnp.array([0.0, 0.0, jnp.pi / 2]))
            T = rj.RigidTransform.from_components(jnp.array([1.0, 0.0, 0.0]), R)
            print(T.apply(jnp.array([1.0, 0.0, 0.0])).round(3))
            # [1. 1. 0.]
            ```
        """
        if not isinstance(rotation, Rotation):
            raise TypeError(
                f"Expected `rotation` to be a `Rotation` instance, got {type(rotation)}."
            )
        t = float_array(translation)
        _check_last(t, 3, "translation")
        q, t = _common(rotation._stored, t)
        try:
            q, t = broadcast_batch(q, t)
        except ValueError:
            raise ValueError(
                f"Cannot broadcast {rotation.shape} rotations to {t.shape[:-1]} translations."
            ) from None
        return RigidTransform._raw(q, t)

    @staticmethod
    def from_exp_coords(exp_coords: ArrayLike) -> RigidTransform:
        """From exponential coordinates `[phi, v]`, `(..., 6)`, rotation vector first.

        `exp([phi, v])` is the rotation `exp(phi)` with translation `J(phi) v`, `J` the left
        Jacobian of SO(3) (scipy's and Lynch and Park's convention): the transform reached at time
        1 by the constant twist `[phi, v]` in the body frame.

        Args:
            exp_coords: `(..., 6)` exponential coordinates `[phi, v]`.

        Returns:
            The transforms, of batch shape `exp_coords.shape[:-1]`.

        Examples:
            ```python
            import jax.numpy as jnp
            import rotjax as rj

            # a quarter turn about z while moving 1 along x
            T = rj.RigidTransform.from_exp_coords(jnp.array([0.0, 0.0, jnp.pi / 2, 1.0, 0.0, 0.0]))
            print(T.translation.round(3))
            # [0.637 0.637 0.   ]
            ```
        """
        xi = constructor_input(exp_coords)
        _check_last(xi, 6, "exp_coords")
        return RigidTransform._raw(*_from_exp_coords(xi))

    @staticmethod
    def from_dual_quat(dual_quat: ArrayLike, *, scalar_first: bool = False) -> RigidTransform:
        """From `(..., 8)` unit dual quaternions `[real, dual]`.

        The input is normalised first (see
        [`normalize_dual_quaternion`][rotjax.normalize_dual_quaternion]): a zero real part is the
        identity rotation, as in scipy.

        Args:
            dual_quat: `(..., 8)` real part (the rotation's quaternion) then dual part, each
                scalar last.
            scalar_first: each part is `[w, x, y, z]`.

        Returns:
            The transforms, of batch shape `dual_quat.shape[:-1]`.

        Examples:
            ```python
            import rotjax as rj

            # identity rotation, dual part t q / 2 for t = [2, 0, 0]
            T = rj.RigidTransform.from_dual_quat([0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0])
            print(T.translation)
            # [2. 0. 0.]
            ```
        """
        dq = constructor_input(dual_quat)
        _check_last(dq, 8, "dual_quat")
        return RigidTransform._raw(*_from_dual_quat(dq, scalar_first=bool(scalar_first)))

    @staticmethod
    def identity(
        num: int | None = None,
        *,
        shape: int | tuple[int, ...] | None = None,
        dtype: DTypeLike | None = None,
    ) -> RigidTransform:
        """The identity transform.

        Args:
            num: number of transforms (`None`: a single one).
            shape: batch shape, instead of `num`.
            dtype: float dtype; JAX's default float if `None`.

        Returns:
            Identity transforms of batch shape `(num,)`, `shape`, or `()`.

        Examples:
            ```python
            import rotjax as rj

            print(rj.RigidTransform.identity().single)
            # True
            print(rj.RigidTransform.identity(shape=(2, 3)).shape)
            # (2, 3)
            ```
        """
        if num is not None and shape is not None:
            raise ValueError("Only one of `num` and `shape` can be specified.")
        if num is not None:
            shape = (num,)
        elif shape is None:
            shape = ()
        elif isinstance(shape, (int, np.integer)):
            shape = (int(shape),)
        elif not isinstance(shape, tuple):
            raise ValueError("`shape` must be an int or a tuple of ints or None.")
        dt = float if dtype is None else dtype
        return RigidTransform._raw(identity_quat(shape, dt), jnp.zeros((*shape, 3), dt))

    @staticmethod
    def concatenate(transforms: RigidTransform | Sequence[RigidTransform]) -> RigidTransform:
        """Concatenate transforms along the first batch axis (single ones count as one).

        Args:
            transforms: a `RigidTransform`, or a sequence of them.

        Returns:
            One batch of transforms.

        Examples:
            ```python
            import rotjax as rj

            T = rj.RigidTransform.concatenate(
                [rj.RigidTransform.identity(), rj.RigidTransform.identity(2)]
            )
            print(T.shape)
            # (3,)
            ```
        """
        if isinstance(transforms, RigidTransform):
            return RigidTransform._raw(transforms._stored, transforms._translation)
        transforms = list(transforms)
        if not all(isinstance(x, RigidTransform) for x in transforms):
            raise TypeError("input must contain RigidTransform objects only")
        q = _common(*(jnp.atleast_2d(x._stored) for x in transforms))
        t = _common(*(jnp.atleast_2d(x._translation) for x in transforms))
        return RigidTransform._raw(jnp.concatenate(q), jnp.concatenate(t))

    # --- conversions ---------------------------------------------------------------------

    def as_matrix(self) -> Array:
        """Homogeneous transformation matrices `[[R, t], [0, 1]]`.

        Returns:
            `(..., 4, 4)` matrices acting on column vectors `[v, 1]`.

        Examples:
            ```python
            import rotjax as rj

            print(rj.RigidTransform.from_translation([1.0, 2.0, 3.0]).as_matrix())
            # [[1. 0. 0. 1.]
            #  [0. 1. 0. 2.]
            #  [0. 0. 1. 3.]
            #  [0. 0. 0. 1.]]
            ```
        """
        return _as_matrix(self._quat, self._translation)

    def as_components(self) -> tuple[Array, Rotation]:
        """The translation and the rotation.

        Returns:
            translation: `(..., 3)` translations `t`.
            rotation: the rotations `R`, a [`Rotation`][rotjax.Rotation] of shape `shape`.

        Examples:
            ```python
            import jax.numpy as jnp
            import rotjax as rj

            R = rj.Rotation.from_rotvec(jnp.array([0.0, 0.0, 0.5]))
            t, R2 = rj.RigidTransform.from_components(jnp.array([1.0, 2.0, 3.0]), R).as_components()
            print(t, R2.as_rotvec().round(3))
            # [1. 2. 3.] [0.  0.  0.5]
            ```
        """
        return self.translation, self.rotation

    def as_exp_coords(self) -> Array:
        """Exponential coordinates `[phi, v]`: the rotation vector `phi` (angle in `[0, pi]`) and
        `v = J(phi)^-1 t`.

        Returns:
            `(..., 6)` exponential coordinates, rotation vector first (inverse of
                [`from_exp_coords`][rotjax.RigidTransform.from_exp_coords]).

        Examples:
            ```python
            import jax.numpy as jnp
            import rotjax as rj

            xi = jnp.array([0.0, 0.0, 0.5, 1.0, 0.0, 0.0])
            print(rj.RigidTransform.from_exp_coords(xi).as_exp_coords().round(3))
            # [ 0.   0.   0.5  1.  -0.   0. ]
            ```
        """
        return _as_exp_coords(self._quat, self._translation)

    def as_dual_quat(self, *, scalar_first: bool = False) -> Array:
        """Unit dual quaternions `[q, t q / 2]`.

        Args:
            scalar_first: each part is `[w, x, y, z]`.

        Returns:
            `(..., 8)` dual quaternions, each part scalar last unless `scalar_first`; `q` is the
                stored quaternion, of either sign.

        Examples:
            ```python
            import rotjax as rj

            print(rj.RigidTransform.from_translation([2.0, 0.0, 0.0]).as_dual_quat())
            # [0. 0. 0. 1. 1. 0. 0. 0.]
            ```
        """
        return _as_dual_quat(self._quat, self._translation, scalar_first=bool(scalar_first))

    # --- algebra -------------------------------------------------------------------------

    @staticmethod
    def _operand(other):
        if isinstance(other, RigidTransform):
            return other
        if isinstance(other, Rotation):
            return RigidTransform.from_rotation(other)
        return None

    def _compose(self, other: RigidTransform) -> RigidTransform:
        try:
            np.broadcast_shapes(self.shape, other.shape)
        except ValueError:
            raise ValueError(
                f"Cannot broadcast {self.shape} transforms in first to {other.shape} "
                "transforms in second object."
            ) from None
        q1, t1, q2, t2 = _common(self._stored, self._translation, other._stored, other._translation)
        return RigidTransform._raw(*_pose_compose(q1, t1, q2, t2), bounded=True)

    def __mul__(self, other: RigidTransform | Rotation) -> RigidTransform:
        """Composition `self * other`: `other` applied first; batch shapes broadcast.

        `other` may be a [`Rotation`][rotjax.Rotation] (a transform with zero translation); so may
        the left operand (`Rotation * RigidTransform`).

        Args:
            other: the transform applied first.

        Returns:
            The composed transforms, `(self * other).apply(v) == self.apply(other.apply(v))`.

        Examples:
            ```python
            import jax.numpy as jnp
            import rotjax as rj

            R = rj.Rotation.from_rotvec(jnp.array([0.0, 0.0, jnp.pi / 2]))
            T = rj.RigidTransform.from_translation(jnp.array([1.0, 0.0, 0.0]))
            print((T * R).apply(jnp.array([1.0, 0.0, 0.0])).round(3))  # rotate, then translate
            # [1. 1. 0.]
            print((R * T).apply(jnp.array([1.0, 0.0, 0.0])).round(3))  # translate, then rotate
            # [0. 2. 0.]
            ```
        """
        other = self._operand(other)
        if other is None:
            return NotImplemented
        return self._compose(other)

    def __rmul__(self, other):
        other = self._operand(other)
        if other is None:
            return NotImplemented
        return other._compose(self)

    def __pow__(self, n: ArrayLike, modulus: None = None) -> RigidTransform:
        """Fractional power `exp(n log T)`: `n` times the screw motion of `T`.

        `T ** 0` is the identity exactly, `T ** -1` the inverse to rounding.

        Args:
            n: `()` or `(1,)` exponent.
            modulus: not supported (scipy's signature); must be `None`.

        Returns:
            The transforms `exp(n log T)`, of the batch shape of `T`.

        Examples:
            ```python
            import jax.numpy as jnp
            import rotjax as rj

            T = rj.RigidTransform.from_exp_coords(jnp.array([0.0, 0.0, 1.0, 2.0, 0.0, 0.0]))
            print((T ** 0.5).as_exp_coords().round(3))  # half the screw motion
            # [ 0.   0.   0.5  1.  -0.   0. ]
            ```
        """
        e = self._exponent(n, modulus)
        return RigidTransform._raw(*_pow(self._quat, self._translation, e))

    def inv(self) -> RigidTransform:
        """The inverse transforms: `R^T` and `-R^T t`.

        Returns:
            The inverses, of the same batch shape.

        Examples:
            ```python
            import rotjax as rj

            print(rj.RigidTransform.from_translation([1.0, 2.0, 3.0]).inv().translation)
            # [-1. -2. -3.]
            ```
        """
        return RigidTransform._raw(*_pose_inv(self._quat, self._translation))

    def apply(self, vector: ArrayLike, inverse: bool = False) -> Array:
        """Transform vectors: `R v + t` (`R^T (v - t)` with `inverse`).

        Args:
            vector: `(..., 3)` vectors; batch shapes broadcast with the transforms'.
            inverse: apply the inverse transform.

        Returns:
            `(..., 3)` vectors, in the transform's dtype.

        Examples:
            ```python
            import rotjax as rj

            T = rj.RigidTransform.from_translation([1.0, 2.0, 3.0])
            print(T.apply([1.0, 1.0, 1.0]), T.apply([1.0, 1.0, 1.0], inverse=True))
            # [2. 3. 4.] [ 0. -1. -2.]
            ```
        """
        dtype = self._stored.dtype
        host = host_value(vector)
        v = host.astype(dtype) if host is not None else float_array(vector, dtype)
        if v.ndim < 1 or v.shape[-1] != 3:
            raise ValueError(f"Expected vector to have shape (..., 3), got {v.shape}.")
        try:
            np.broadcast_shapes(self.shape, v.shape[:-1])
        except ValueError:
            raise ValueError(
                f"operands could not be broadcast together: {self.shape} transforms and "
                f"{v.shape[:-1]} vectors"
            ) from None
        return _pose_apply(self._quat, self._translation, v, inverse=bool(inverse))

    def mean(
        self, weights: ArrayLike | None = None, axis: int | tuple[int, ...] | None = None
    ) -> RigidTransform:
        """Weighted mean: the mean rotation (as `Rotation.mean`) and the weighted mean of the
        translations.

        Args:
            weights: `shape` non-negative weights; `None` for equal weights.
            axis: batch axis or axes to reduce; `None` for all.

        Returns:
            The mean transforms, of the batch shape without the reduced axes.

        Examples:
            ```python
            import rotjax as rj

            T = rj.RigidTransform.from_translation([[0.0, 0.0, 0.0], [2.0, 4.0, 0.0]])
            print(T.mean().translation, T.mean(weights=[3.0, 1.0]).translation)
            # [1. 2. 0.] [0.5 1.  0. ]
            ```
        """
        q, t = self._quat, self._translation
        if self.single:
            q, t = q[None], t[None]
        nb = q.ndim - 1
        if q.shape[0] == 0:
            raise ValueError("Mean of an empty rotation set is undefined.")
        if axis is None:
            axes = tuple(range(nb))
        elif isinstance(axis, (int, np.integer)):
            axes = (int(axis),)
        elif isinstance(axis, tuple):
            axes = axis
        else:
            raise ValueError("`axis` must be None, int, or tuple of ints.")
        if axes and (min(axes) < -nb or max(axes) > nb - 1):
            raise ValueError(f"axis {axis} is out of bounds for transform with shape {self.shape}.")
        axes = tuple(sorted({a % nb for a in axes}))
        keep = tuple(i for i in range(nb) if i not in axes)
        out = [q.shape[i] for i in keep]
        w = None
        if weights is not None:
            host = host_value(weights)
            if host is not None and np.any(host < 0):
                raise ValueError("`weights` must be non-negative.")
            w = float_array(weights, q.dtype)
            if w.shape != self.shape:
                raise ValueError(
                    f"Expected `weights` to match transform shape, got shape {w.shape} for "
                    f"{self.shape} transformations."
                )
            w = jnp.reshape(jnp.transpose(jnp.atleast_1d(w), keep + axes), out + [-1])
        qt = jnp.reshape(jnp.transpose(q, keep + axes + (nb,)), out + [-1, 4])
        tt = jnp.reshape(jnp.transpose(t, keep + axes + (nb,)), out + [-1, 3])
        return RigidTransform._raw(*_mean(qt, tt, w))


__all__ = ["RigidTransform", "normalize_dual_quaternion"]
