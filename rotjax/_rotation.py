"""`Rotation`: scipy's transform API over rotjax's functions, as a pytree.

The class holds one array, the `(..., 4)` scalar-last unit quaternion, and adds scipy's shape
bookkeeping and method names; every computation is one of rotjax's functions.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.typing import ArrayLike, DTypeLike

from ._algebra import (
    quaternion_canonical,
    quaternion_power,
    quaternion_reduce,
    rotation_group,
    wahba_sensitivity,
)
from ._davenport import davenport_to_quaternion, parse_order, quaternion_to_davenport
from ._elementary import atan2
from ._euler import euler_to_quaternion, parse_seq, quaternion_to_euler
from ._fitting import align_vectors as _align_vectors
from ._fitting import quaternion_mean
from ._matrix import matrix_to_quaternion, shepperd_column
from ._mrp import mrp_to_quaternion, quat_to_mrp
from ._numerics import (
    as_float,
    broadcast_batch,
    cast,
    check_array,
    check_static,
    cross,
    det3,
    from_part,
    jit,
    to_scalar_last,
    unstack_matrix,
    where,
)
from ._quaternion import (
    angle_between,
    quat_angle,
    quat_apply,
    quat_multiply,
    quat_normalize,
    quat_rescaled,
    quat_to_matrix,
    quaternion_apply,
    quaternion_conjugate,
    quaternion_multiply,
    quaternion_normalize,
)
from ._rotvec import quat_to_rotvec, rotvec_to_quaternion


def float_array(x, dtype=None):
    """`x` as a JAX float array (integers to the default float; float32/64 kept)."""
    check_array("input", x)
    x = jnp.asarray(x, dtype=dtype)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        x = x.astype(float)
    return x


def host_value(x) -> np.ndarray | None:
    """`x` as NumPy if it is a host value (NumPy array, Python number or list), else `None`.

    Value checks that scipy makes (negative weights, zero norms) are made only on such inputs:
    they cost no device transfer, and under `jit` the values are never inspected.
    """
    if isinstance(x, jax.Array):  # tracers are jax.Array instances too
        return None
    try:
        a = np.asarray(x)
    except (TypeError, ValueError):
        return None
    kind = a.dtype.kind  # dtype kinds, not issubdtype: this runs on every eager call
    if kind == "c":
        check_array("input", a)  # raises the TypeError for complex input
    return a if kind == "f" else a.astype(float) if kind in "biu" else None


def constructor_input(x):
    """A constructor's input: a host value stays in NumPy (in JAX's dtype for it) and goes to
    the device with the one jitted call that reads it, which costs less than a transfer of
    its own; anything else as a JAX float array."""
    host = host_value(x)
    if host is None:
        return float_array(x)
    return host.astype(jax.dtypes.canonicalize_dtype(host.dtype), copy=False)


@jit
def _from_matrix_checked(matrix):
    # scipy raises for det <= 0; a traced function cannot, so those rotations are NaN.
    q = matrix_to_quaternion(matrix, method="optimal")
    return where(det3(unstack_matrix(matrix)) > 0, q, jnp.nan)


@jit(static_argnames="scalar_first")
def _scalar_last(q, scalar_first):
    return to_scalar_last(float_array(q), scalar_first)


@jit(static_argnames=("rescale_p", "rescale_q"))
def _rotation_compose(p, q, rescale_p=True, rescale_q=True):
    # The stored quaternions need not be unit, nor is their product: the product of the
    # rescaled ones (exact powers of two) has a norm in [1, 16), which no reader depends on
    # (each normalises, or is homogeneous), so it is stored as it is. A unit quaternion (see
    # Rotation._unit) is not rescaled: the scaling is exact, so the readers' results are the
    # same bits either way.
    p, q = broadcast_batch(p, q, trailing=(1, 1))
    return quat_multiply(quat_rescaled(p) if rescale_p else p, quat_rescaled(q) if rescale_q else q)


@jit(static_argnames=("inverse", "bounded"))
def _rotation_apply(q, v, inverse, bounded):
    if inverse:
        q = quaternion_conjugate(q)
    (q, v), dt = as_float(*broadcast_batch(q, v, trailing=(1, 1)))
    return cast(quat_apply(q, v, bounded), dt)


@jit(static_argnames=("read", "bounded", "degrees"))
def _read(q, read, bounded, degrees=False):
    """``read(q, bounded)``, a reader of the stored quaternion (``quat_to_matrix``, ...), in
    its compute dtype; ``bounded``: the rotation's mark (the reader then skips its prescaling)."""
    (q,), dt = as_float(q)
    out = read(q, bounded)
    return cast(jnp.rad2deg(out) if degrees else out, dt)


def identity_quat(shape, dtype):
    return jnp.zeros((*shape, 4), dtype).at[..., 3].set(1)


def _batch_shape(shape) -> tuple[int, ...]:
    """scipy's ``shape`` argument (``None``, an int or a tuple of ints) as a tuple."""
    if shape is None:
        return ()
    if isinstance(shape, (int, np.integer)) and not isinstance(shape, bool):
        return (int(shape),)
    if isinstance(shape, (tuple, list)) and all(
        isinstance(n, (int, np.integer)) and not isinstance(n, bool) for n in shape
    ):
        return tuple(int(n) for n in shape)
    raise ValueError("`shape` must be an int or a tuple of ints")


def _is_key(x) -> bool:
    if isinstance(x, jax.Array):
        if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key):
            return True
        return x.dtype == jnp.uint32 and x.shape == (2,)
    return False


def _check_index(indexer, n: int):
    """scipy's IndexError for host indices out of range (JAX clamps them)."""
    if isinstance(indexer, (int, np.integer)) and not isinstance(indexer, bool):
        if not -n <= indexer < n:
            raise IndexError(f"index {indexer} is out of bounds for axis 0 with size {n}")
        return indexer
    if isinstance(indexer, (list, np.ndarray)):
        a = np.asarray(indexer)
        if a.size == 0 and a.dtype.kind == "f":  # [] selects nothing (NumPy reads it as float)
            a = a.astype(np.intp)
        if a.dtype.kind in "iu" and a.size and (a.min() < -n or a.max() >= n):
            raise IndexError(f"index out of bounds for axis 0 with size {n}")
        if a.dtype == bool and a.ndim >= 1 and a.shape[0] != n:
            raise IndexError(
                f"boolean index did not match indexed array along axis 0; size of axis is "
                f"{n} but size of corresponding boolean axis is {a.shape[0]}"
            )
        return a
    if isinstance(indexer, jax.Array) and not isinstance(indexer, jax.core.Tracer) and n == 0:
        if jnp.issubdtype(indexer.dtype, jnp.integer) and indexer.size:
            raise IndexError("cannot take from an empty array")
    return indexer


class BatchedPytree:
    """The batch bookkeeping shared by `Rotation` and `RigidTransform`: the object is its
    leaves (`_LEAVES`, arrays with the batch axes first and one trailing axis each), the first
    batch axis is scipy's sequence, and a single element (no batch axes) has no length, is not
    iterable and not subscriptable. A subclass defines `_LEAVES`, `_NOUN` and `_raw(*leaves)`;
    its first leaf `_stored` is the quaternion of the rotation (scalar last, any non-zero norm),
    read normalised as `_quat`. `_bounded`, a mark outside the tree that every constructor
    sets: `_stored` is of order 1 or NaN (see `Rotation`), and `_quat` skips the prescaling."""

    __slots__ = ("_bounded",)
    _NOUN = "element"
    _LEAVES: tuple[str, ...] = ()

    def _leaves(self):
        return tuple(getattr(self, name) for name in self._LEAVES)

    @property
    def _quat(self):
        """The unit quaternion of the rotation, scalar last."""
        return _read(self._stored, quat_normalize, self._bounded)

    def _exponent(self, n, modulus):
        """scipy's ``__pow__`` exponent: a scalar (or one-element array), broadcast to the
        batch shape in the stored dtype."""
        if modulus is not None:
            raise NotImplementedError("modulus not supported")
        e = jnp.asarray(n)
        if e.shape == (1,):
            e = e[0]
        if e.ndim != 0:
            raise ValueError("Array exponent must be a scalar")
        return jnp.broadcast_to(e.astype(self._stored.dtype), self.shape)

    # --- pytree and pickling ---------------------------------------------------------------

    def tree_flatten(self):
        return self._leaves(), None

    @classmethod
    def tree_unflatten(cls, aux, children):
        return cls._raw(*children)

    def __getstate__(self):
        # The leaves as they are (a JAX array pickles itself): a pickler that swaps arrays for
        # placeholders, as pickle-based flatteners of jitted arguments do, must see them, and
        # a traced one must not be converted.
        return tuple(self._leaves())

    def __setstate__(self, state):
        for name, x in zip(self._LEAVES, state, strict=True):
            setattr(self, name, jnp.asarray(x))
        self._bounded = False

    # --- shape and sequence ------------------------------------------------------------------

    @property
    def single(self) -> bool:
        """Whether this is a single element (no batch axes)."""
        return self._leaves()[0].ndim == 1

    @property
    def shape(self) -> tuple[int, ...]:
        """The batch shape (`()` for a single element)."""
        return tuple(self._leaves()[0].shape[:-1])

    def __len__(self) -> int:
        """Length of the first batch axis. Raises TypeError for a single element."""
        if self.single:
            raise TypeError(f"Single {self._NOUN} has no len().")
        return self.shape[0]

    def __bool__(self) -> bool:
        return True

    def __iter__(self):
        if self.single:
            raise TypeError(f"Single {self._NOUN} is not iterable.")
        return (self[i] for i in range(len(self)))

    def _index(self, indexer):
        """The index of every leaf: ``indexer`` over the batch axes, all of the last axis."""
        if self.single:
            raise TypeError(f"Single {self._NOUN} is not subscriptable.")
        if not isinstance(indexer, tuple):
            indexer = (_check_index(indexer, self.shape[0]),)
        if any(i is Ellipsis for i in indexer):
            return indexer + (slice(None),)
        return indexer + (Ellipsis,)

    def __getitem__(self, indexer):
        """The elements selected by `indexer` over the batch axes (as NumPy indexing)."""
        idx = self._index(indexer)
        return self._raw(*(x[idx] for x in self._leaves()))

    def __setitem__(self, indexer, value):
        """Replace the selected elements by `value` (an object of the same class).

        JAX arrays are immutable: this builds new arrays (`.at[...].set`) and rebinds this
        object's leaves to them. Other references to the old arrays, and copies of this object
        made before (e.g. a pytree flattened earlier), are unchanged.
        """
        idx = self._index(indexer)
        if not isinstance(value, type(self)):
            raise TypeError(f"value must be a {type(self).__name__} object")
        for name, old, new in zip(self._LEAVES, self._leaves(), value._leaves(), strict=True):
            old = jnp.asarray(old)
            setattr(self, name, old.at[idx].set(jnp.asarray(new, old.dtype)))
        self._bounded = self._bounded and value._bounded

    def __repr__(self) -> str:
        head = f"{type(self).__name__}.from_matrix("
        m = self.as_matrix()  # under a trace, the tracer's repr (no values to show)
        m = repr(m if isinstance(m, jax.core.Tracer) else np.asarray(m)).splitlines()
        m[1:] = [" " * len(head) + line for line in m[1:]]
        return head + "\n".join(m) + ")"


@jax.tree_util.register_pytree_node_class
class Rotation(BatchedPytree):
    """Rotations in 3 dimensions, scipy's `Rotation` API on one JAX array.

    A `Rotation` holds a `(..., 4)` quaternion `[x, y, z, w]` (scalar last), the only
    leaf of the pytree: `jax.jit` can take and return it, `jax.vmap` maps over its
    leading (batch) axes, `jax.grad` differentiates through its methods and `lax.scan`
    carries it. A 1-D quaternion is a *single* rotation (`single` is `True`; no `len`, no
    indexing); `(..., 4)` holds a batch of shape `shape`. float32 and float64 are kept.

    Every method is one of rotjax's functions (`as_euler` is
    [`quaternion_to_euler`][rotjax.quaternion_to_euler], `apply` is
    [`quaternion_apply`][rotjax.quaternion_apply], ...), with their accuracy and their
    gradients at the identity, at 180 degrees and at gimbal lock.

    Conventions (scipy's): `as_matrix()` is the active matrix, `v_world = R @ v_body`;
    `p * q` applies `q` first; Euler `"XYZ"` is intrinsic, `"xyz"` extrinsic.

    Values scipy rejects (zero-norm quaternions, matrices with `det <= 0`, negative weights,
    interpolation times out of range) raise `ValueError` only when they arrive as NumPy arrays
    or Python numbers; as JAX arrays, and always under `jit`, they are not inspected and the
    result is NaN for the affected rotations.

    Args:
        quat: `(..., 4)` quaternion(s); need not be unit.
        normalize: normalise `quat` (set `False` only for unit quaternions).
        copy: accepted for scipy compatibility (JAX arrays are immutable).
        scalar_first: `quat` is `[w, x, y, z]`.

    Examples:
        ```python
        import jax
        import jax.numpy as jnp
        from rotjax import Rotation

        r = Rotation.from_euler("z", 90.0, degrees=True)
        print(r.apply([1.0, 0.0, 0.0]).round(6))
        # [-0.  1.  0.]

        @jax.jit
        def yaw(r):  # a Rotation goes in and out of jit, vmap and grad
            return r.as_euler("ZYX")[..., 0]

        batch = Rotation.from_rotvec(jnp.array([[0.0, 0.0, 0.1], [0.0, 0.0, 0.2]]))
        print(yaw(batch).round(6))
        # [0.1 0.2]
        ```
    """

    # The leaf is the quaternion as given (scalar last), of any non-zero norm: the readers
    # (as_matrix, as_euler, apply, ...) accept any norm, so from_quat(q).as_euler(seq) compiles
    # to exactly quaternion_to_euler(q, seq); as_quat and the methods that need a unit
    # quaternion read the normalised ``_quat``. Nothing else is stored: the tree structure is
    # the same for every constructor, method and operator (a scan carry, both branches of a
    # cond), and the value alone decides the result. Two marks outside the tree (so lost, and
    # False, once the object is flattened) save work only. ``_unit``: the constructor stored a
    # unit quaternion (to rounding), which a product need not rescale (``_rotation_compose``).
    # ``_bounded``: the quaternion is of order 1, or NaN where it is not a rotation (a unit
    # one, a product, Shepperd's column), which the readers need not prescale.
    __slots__ = ("_stored", "_unit")
    _LEAVES = ("_stored",)
    _NOUN = "rotation"
    # NumPy's operators defer to ours (``array * r`` is not an object-array product), and ours
    # return NotImplemented for unknown operands, so another class's reflected operator runs.
    __array_ufunc__ = None

    def __init__(
        self, quat: ArrayLike, normalize: bool = True, copy: bool = True, scalar_first: bool = False
    ):
        del copy  # JAX arrays are immutable: there is nothing to copy
        normalize = check_static("normalize", normalize)
        scalar_first = check_static("scalar_first", scalar_first)
        q = constructor_input(quat)
        if q.ndim < 1 or q.shape[-1] != 4:
            raise ValueError(f"Expected `quat` to have shape (..., 4), got {q.shape}.")
        host = isinstance(q, np.ndarray)
        # (a single quaternion is checked in Python: a NumPy reduction here slowed the
        # jitted call that follows by more than its own cost)
        if host and normalize and not (any(q.tolist()) if q.ndim == 1 else q.any(-1).all()):
            raise ValueError("Found zero norm quaternions in `quat`.")
        # No device work here (a host array is kept as it is); scalar-first input is reordered.
        if scalar_first:
            q = _scalar_last(q, scalar_first)
        self._stored = q
        self._unit = self._bounded = False

    @classmethod
    def _raw(cls, quat, unit=False, bounded=False):
        """A rotation holding the quaternion `quat` (any non-zero norm) as it is; `unit`: it
        is a unit quaternion to rounding (or NaN), as computed by a conversion; `bounded`: it
        is of order 1 or NaN (a unit one included)."""
        r = object.__new__(cls)
        r._stored = quat
        r._unit = unit
        r._bounded = unit or bounded
        return r

    def __setstate__(self, state):
        super().__setstate__(state)
        self._unit = False

    def __getitem__(self, indexer):
        r = super().__getitem__(indexer)
        r._unit, r._bounded = self._unit, self._bounded
        return r

    def __setitem__(self, indexer, value):
        super().__setitem__(indexer, value)
        self._unit = self._unit and value._unit

    # --- shape ---------------------------------------------------------------------------

    @property
    def quat(self) -> Array:
        """The stored `(..., 4)` unit quaternion, scalar last (jax.scipy's field)."""
        return self._quat

    # --- constructors --------------------------------------------------------------------

    @staticmethod
    def from_quat(quat: ArrayLike, *, scalar_first: bool = False) -> Rotation:
        """From quaternion(s).

        Args:
            quat: `(..., 4)` quaternion(s) `[x, y, z, w]`; need not be unit (they are
                normalised; zero gives NaN, or ValueError for NumPy input).
            scalar_first: `quat` is `[w, x, y, z]`.

        Returns:
            The rotation(s), of batch shape `quat.shape[:-1]`.

        Examples:
            ```python
            from rotjax import Rotation

            r = Rotation.from_quat([0.0, 0.0, 1.0, 1.0])  # normalised: 90 deg about z
            print(r.as_quat().round(6))
            # [0.       0.       0.707107 0.707107]
            ```
        """
        return Rotation(quat, scalar_first=scalar_first)

    @staticmethod
    def from_matrix(matrix: ArrayLike, *, assume_valid: bool = False) -> Rotation:
        """From rotation matrices.

        Args:
            matrix: `(..., 3, 3)` active matrices (`v_world = R @ v_body`). Unless
                `assume_valid`, each is replaced by the nearest rotation matrix (Frobenius
                norm; [`matrix_to_quaternion`][rotjax.matrix_to_quaternion] with
                `method="optimal"`) and a matrix with `det <= 0` gives NaN (ValueError for NumPy
                input).
            assume_valid: the matrices are rotations: use the cheaper `"shepperd"` method,
                with no check.

        Returns:
            The rotation(s), of batch shape `matrix.shape[:-2]`.

        Examples:
            ```python
            from rotjax import Rotation

            r = Rotation.from_matrix([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
            print(r.as_rotvec(degrees=True).round(4))
            # [ 0.  0. 90.]
            ```
        """
        m = constructor_input(matrix)
        if m.ndim < 2 or m.shape[-2:] != (3, 3):
            raise ValueError(f"Expected `matrix` to have shape (..., 3, 3), got {m.shape}")
        if m.size == 0:  # an empty batch (the nearest-rotation solver needs an element)
            return Rotation._raw(jnp.zeros(m.shape[:-2] + (4,), m.dtype))
        if assume_valid:  # not normalised: the readers prescale (and as_euler needs no norm)
            return Rotation._raw(shepperd_column(m), bounded=True)
        if isinstance(m, np.ndarray) and np.any(np.linalg.det(m) <= 0):
            raise ValueError("Non-positive determinant (left-handed or null coordinate frame)")
        return Rotation._raw(_from_matrix_checked(m), unit=True)

    @staticmethod
    def from_rotvec(rotvec: ArrayLike, degrees: bool = False) -> Rotation:
        """From rotation vectors `angle * axis`.

        Args:
            rotvec: `(..., 3)` rotation vectors (radians, or degrees with `degrees`).
            degrees: the norms are in degrees.

        Returns:
            The rotation(s), of batch shape `rotvec.shape[:-1]`.

        Examples:
            ```python
            from rotjax import Rotation

            r = Rotation.from_rotvec([[0.0, 0.0, 90.0], [180.0, 0.0, 0.0]], degrees=True)
            print(r.shape, r.magnitude().round(6))
            # (2,) [1.570796 3.141592]
            ```
        """
        v = constructor_input(rotvec)
        if v.ndim < 1 or v.shape[-1] != 3:
            raise ValueError(f"Expected `rot_vec` to have shape (..., 3), got {v.shape}")
        return Rotation._raw(rotvec_to_quaternion(v, degrees=degrees), unit=True)

    @staticmethod
    def from_mrp(mrp: ArrayLike) -> Rotation:
        """From modified Rodrigues parameters `axis * tan(angle / 4)`.

        Args:
            mrp: `(..., 3)` modified Rodrigues parameters, any norm.

        Returns:
            The rotation(s), of batch shape `mrp.shape[:-1]`.

        Examples:
            ```python
            from rotjax import Rotation

            r = Rotation.from_mrp([0.0, 0.0, 1.0])  # tan(180 deg / 4) = 1: a half turn about z
            print(r.as_matrix().round(6))
            # [[-1.  0.  0.]
            #  [ 0. -1.  0.]
            #  [ 0.  0.  1.]]
            ```
        """
        p = constructor_input(mrp)
        if p.ndim < 1 or p.shape[-1] != 3:
            raise ValueError(f"Expected `mrp` to have shape (..., 3), got {p.shape}")
        return Rotation._raw(mrp_to_quaternion(p), unit=True)

    @staticmethod
    def from_euler(seq: str, angles: ArrayLike, degrees: bool = False) -> Rotation:
        """From Euler angles about 1 to 3 axes.

        Args:
            seq: 1 to 3 axis letters, uppercase for intrinsic (rotating axes, `"ZXZ"`),
                lowercase for extrinsic (fixed axes, `"xyz"`); or three digits (`"313"`,
                intrinsic). Consecutive axes must differ.
            angles: `(..., len(seq))` angles; a scalar for one axis. A 1-D array of length
                `len(seq)` is a single rotation.
            degrees: angles are in degrees.

        Returns:
            The rotation(s), of batch shape `angles.shape[:-1]`.

        Examples:
            ```python
            from rotjax import Rotation

            r = Rotation.from_euler("ZYX", [90.0, 0.0, 45.0], degrees=True)  # yaw, pitch, roll
            print(r.as_euler("ZYX", degrees=True).round(4))
            # [90.  0. 45.]
            ```
        """
        if not isinstance(seq, str) or not 1 <= len(seq) <= 3:
            raise ValueError(
                "Expected axis specification to be a non-empty string of up to 3 "
                f"characters, got {seq!r}"
            )
        a = constructor_input(angles)
        if a.ndim == 0:
            a = a[None]
        k = len(seq)
        if a.shape[-1] != k:
            raise ValueError(
                "Expected last dimension of `angles` to match number of sequence axes "
                f"specified, got {a.shape[-1]}."
            )
        if k < 3:
            if not (set(seq) <= set("xyz") or set(seq) <= set("XYZ")):
                raise ValueError(
                    f"Expected axes from `seq` to be from ['x', 'y', 'z'] or ['X', 'Y', 'Z'], "
                    f"got {seq!r}"
                )
            if k == 2 and seq[0] == seq[1]:
                raise ValueError(f"Expected consecutive axes to be different, got {seq!r}")
            # Pad to three axes with zero angles: the extra elementary rotations are exactly
            # the identity, so the product is that of the given axes.
            base = "xyz" if seq.islower() else "XYZ"
            while len(seq) < 3:
                seq += next(c for c in base if c != seq[-1])
            a = jnp.concatenate([a, jnp.zeros(a.shape[:-1] + (3 - k,), a.dtype)], axis=-1)
        else:
            parse_seq(seq)
        return Rotation._raw(euler_to_quaternion(a, seq, degrees=degrees), unit=True)

    @staticmethod
    def from_davenport(
        axes: ArrayLike, order: str, angles: ArrayLike, degrees: bool = False
    ) -> Rotation:
        """From Davenport angles: rotations about 1 to 3 given axes.

        Args:
            axes: `(K, 3)` or `(3,)` axes (normalised here), `K` in 1..3; consecutive
                axes must be orthogonal.
            order: `"e"`/`"extrinsic"` (fixed axes) or `"i"`/`"intrinsic"`.
            angles: `(..., K)` angles (a scalar for one axis).
            degrees: angles are in degrees.

        Returns:
            The rotation(s), of batch shape `angles.shape[:-1]`.

        Examples:
            ```python
            from rotjax import Rotation

            axes = [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]  # about z, then about the new x
            r = Rotation.from_davenport(axes, "intrinsic", [90.0, 30.0], degrees=True)
            print(r.as_euler("ZXY", degrees=True).round(4))
            # [90. 30.  0.]
            ```
        """
        extrinsic = parse_order(order)
        ax = float_array(axes)
        if ax.shape[-1] != 3:
            raise ValueError("Axes must be vectors of length 3.")
        if ax.ndim == 1:
            ax = ax[None]
        if not 1 <= ax.shape[-2] <= 3:
            raise ValueError(f"Expected up to 3 axes, got {ax.shape[-2]}")
        host = host_value(axes)
        if host is not None:
            h = np.atleast_2d(host)
            h = h / np.linalg.norm(h, axis=-1, keepdims=True)
            if np.any(np.abs(np.sum(h[..., :-1, :] * h[..., 1:, :], axis=-1)) > 1e-7):
                raise ValueError("Consecutive axes must be orthogonal.")
        a = float_array(angles, ax.dtype)
        if a.ndim == 0:
            a = a[None]
        if a.shape[-1] != ax.shape[-2]:
            raise ValueError(
                f"Expected `angles` to match number of axes, got {a.shape} angles and "
                f"{ax.shape} axes."
            )
        q = davenport_to_quaternion(ax, a, extrinsic=extrinsic, degrees=degrees)
        return Rotation._raw(q, unit=True)

    @staticmethod
    def identity(
        num: int | None = None,
        dtype: DTypeLike | None = None,
        *,
        shape: int | tuple[int, ...] | None = None,
    ) -> Rotation:
        """The identity rotation.

        Args:
            num: number of rotations (`None`: a single rotation).
            dtype: float dtype (jax.scipy's second argument); JAX's default float if `None`.
            shape: batch shape, instead of `num`.

        Returns:
            The identity: a single rotation, or a batch of shape `(num,)` or `shape`.

        Examples:
            ```python
            from rotjax import Rotation

            print(Rotation.identity().as_quat(), Rotation.identity(shape=(2, 3)).shape)
            # [0. 0. 0. 1.] (2, 3)
            ```
        """
        if dtype is not None:
            try:
                floating = jnp.issubdtype(dtype, jnp.floating)
            except TypeError:
                floating = False
            if not floating:
                raise TypeError(
                    "identity() takes from 0 to 1 positional arguments (a second one is "
                    f"jax.scipy's float dtype), got {dtype!r}"
                )
        if num is not None and shape is not None:
            raise ValueError("Only one of `num` or `shape` can be specified.")
        if num is not None:
            shape = (num,)
        shape = _batch_shape(shape)
        return Rotation._raw(identity_quat(shape, dtype if dtype is not None else float), unit=True)

    @staticmethod
    def random(
        num: int | Array | None = None,
        rng: np.random.Generator | int | Array | None = None,
        *,
        shape: int | tuple[int, ...] | None = None,
        random_state: np.random.Generator | int | None = None,
    ) -> Rotation:
        """Uniformly distributed random rotations.

        Args:
            num: number of rotations (`None`: a single one). A JAX PRNG key here is taken as
                jax.scipy's `random(key, num)`.
            rng: a `numpy.random.Generator`, a seed for `numpy.random.default_rng`, or a
                JAX PRNG key. With NumPy, the samples equal scipy's for the same generator.
            shape: batch shape, instead of `num`.
            random_state: scipy's former name of `rng`, with its legacy meaning: a seed
                seeds a `numpy.random.RandomState`, which is used as it is; so is a
                `RandomState` or a `Generator`. With neither `rng` nor
                `random_state`, NumPy's global `RandomState` draws (as scipy's).

        Returns:
            The random rotations: a single one, or a batch of shape `(num,)` or `shape`.

        Examples:
            ```python
            import jax
            from rotjax import Rotation

            r = Rotation.random(1000, rng=jax.random.key(0))
            print(r.shape, bool((r.magnitude() <= 3.1416).all()))
            # (1000,) True
            ```
        """
        if rng is not None and random_state is not None:
            raise TypeError(
                "random() got multiple values for argument now known as `rng`. Specify one "
                "of `rng` or `random_state`."
            )
        legacy = rng is None  # scipy's check_random_state: a seed seeds a RandomState
        if legacy:
            rng = random_state
        if _is_key(num):
            num, rng = rng, num
        if num is not None and shape is not None:
            raise ValueError("Only one of `num` or `shape` can be specified.")
        size = (num,) if num is not None else _batch_shape(shape)
        if _is_key(rng):
            sample = jax.random.normal(rng, (*size, 4), dtype=float)
        else:
            if isinstance(rng, (np.random.Generator, np.random.RandomState)):
                gen = rng
            elif legacy:
                gen = np.random.mtrand._rand if rng is None else np.random.RandomState(rng)
            else:
                gen = np.random.default_rng(rng)
            sample = gen.normal(size=(*size, 4))
        return Rotation(sample)

    @staticmethod
    def concatenate(rotations: Rotation | Sequence[Rotation]) -> Rotation:
        """Concatenate rotations along the first batch axis (single ones count as one).

        Args:
            rotations: a `Rotation` or a sequence of them.

        Returns:
            One `Rotation` holding them all, of batch shape `(N, ...)`.

        Examples:
            ```python
            from rotjax import Rotation

            both = Rotation.concatenate([Rotation.identity(), Rotation.random(3, rng=0)])
            print(both.shape)
            # (4,)
            ```
        """
        # The stored quaternions as they are (each keeps its norm), like indexing.
        if isinstance(rotations, Rotation):
            return Rotation._raw(jnp.asarray(rotations._stored))
        rotations = list(rotations)
        if not all(isinstance(r, Rotation) for r in rotations):
            raise TypeError("input must contain Rotation objects only")
        return Rotation._raw(jnp.concatenate([jnp.atleast_2d(r._stored) for r in rotations]))

    @classmethod
    def create_group(cls, group: str, axis: str = "Z") -> Rotation:
        """A finite rotation group: `"Cn"`, `"Dn"`, `"T"`, `"O"` or `"I"`.

        See [`rotation_group`][rotjax.rotation_group].

        Args:
            group: the group's name, `"Cn"` and `"Dn"` with a positive integer `n`.
            axis: `"X"`, `"Y"` or `"Z"`: the principal axis of `Cn` and `Dn`.

        Returns:
            The group's elements, of batch shape `(order,)`.

        Examples:
            ```python
            from rotjax import Rotation

            print(len(Rotation.create_group("I")), len(Rotation.create_group("D6", axis="X")))
            # 60 12
            ```
        """
        return cls._raw(rotation_group(group, axis), unit=True)

    @staticmethod
    def align_vectors(
        a: ArrayLike,
        b: ArrayLike,
        weights: ArrayLike | None = None,
        return_sensitivity: bool = False,
    ) -> tuple[Rotation, Array] | tuple[Rotation, Array, Array]:
        """Rotation that best maps vectors `b` onto `a` (Wahba's problem).

        Minimises `sum_i w_i |a_i - R b_i|^2` ([`align_vectors`][rotjax.align_vectors]). One
        infinite weight (or a single vector pair) makes that pair primary: it is aligned exactly
        (the smallest rotation taking `b_i` to `a_i`), and the rotation about `a_i` minimises
        the secondary pairs' loss (scipy's rule).

        Args:
            a: `(N, 3)` or `(3,)` vectors in the reference frame.
            b: `(N, 3)` or `(3,)` the same vectors in the body frame.
            weights: `(N,)` non-negative weights (at most one infinite); `None` for ones.
            return_sensitivity: also return the sensitivity matrix
                ([`wahba_sensitivity`][rotjax.wahba_sensitivity]); not defined with an
                infinite weight or one pair.

        Returns:
            rotation (Rotation): the single best rotation.
            rssd (Array): `()` the root of the weighted sum of squared distances
                `|a_i - R b_i|` (infinite weights counting as 0).
            sensitivity (Array): `(3, 3)` sensitivity matrix, only with `return_sensitivity`.

        Examples:
            ```python
            import jax.numpy as jnp
            from rotjax import Rotation

            b = jnp.eye(3)
            a = Rotation.from_euler("z", 30.0, degrees=True).apply(b)
            r, rssd = Rotation.align_vectors(a, b)
            print(r.as_euler("ZYX", degrees=True).round(4), rssd.round(6))
            # [30.  0.  0.] 0.0
            ```
        """
        a_in, b_in = float_array(a), float_array(b)
        dt = jnp.result_type(a_in.dtype, b_in.dtype)
        a2, b2 = jnp.atleast_2d(a_in.astype(dt)), jnp.atleast_2d(b_in.astype(dt))
        for x, x0, name in ((a2, a_in, "a"), (b2, b_in, "b")):
            if x.shape[-1] != 3:
                raise ValueError(
                    f"Expected input `{name}` to have shape (3,) or (N, 3), got {x0.shape}"
                )
        if a2.shape != b2.shape:
            raise ValueError(
                "Expected inputs `a` and `b` to have same shapes, got "
                f"{a_in.shape} and {b_in.shape} respectively."
            )
        if a2.ndim > 2:  # no broadcasting, as scipy
            raise ValueError(
                "Expected inputs `a` and `b` to have shape (3,) or (N, 3), got "
                f"{a_in.shape} and {b_in.shape} respectively."
            )
        n = a2.shape[0]
        if weights is None:
            w = jnp.ones(n, dt)
        else:
            w = float_array(weights, dt)
            if w.ndim != 1:
                raise ValueError(f"Expected `weights` to be 1 dimensional, got shape {w.shape}.")
            if n > 1 and w.shape[0] != n:
                raise ValueError(
                    "Expected `weights` to have number of values equal to number of input "
                    f"vectors, got {w.shape[0]} values and {n} vectors."
                )
            host = host_value(weights)
            if host is not None:
                if np.any(host < 0):
                    raise ValueError("`weights` may not contain negative values")
                if np.sum(np.isinf(host)) > 1:
                    raise ValueError("Only one infinite weight is allowed")
                if return_sensitivity and (n == 1 or np.any(np.isinf(host))):
                    raise ValueError(
                        "Cannot return sensitivity matrix with an infinite weight or one "
                        "vector pair"
                    )
        if return_sensitivity and n == 1:
            raise ValueError(
                "Cannot return sensitivity matrix with an infinite weight or one vector pair"
            )
        # The primary pair (one pair, or the one with an infinite weight) is aligned exactly:
        # a zero vector there is an error, as in scipy, on host input (NaN for JAX arrays).
        host_w = None if weights is None else host_value(weights)
        primary = 0 if n == 1 else None
        if host_w is not None and n > 1 and np.sum(np.isinf(host_w)) == 1:
            primary = int(np.argmax(np.isinf(host_w)))
        for x in (a, b) if primary is not None else ():
            host = host_value(x)
            if host is not None and not np.any(np.atleast_2d(host)[primary]):
                raise ValueError("Cannot align zero length primary vectors")
        q, rssd = _align_primary(a2, b2, w)
        rot = Rotation._raw(q)
        if return_sensitivity:
            return rot, rssd, wahba_sensitivity(a2, b2, w)
        return rot, rssd

    # --- conversions ---------------------------------------------------------------------

    def as_quat(self, canonical: bool = False, *, scalar_first: bool = False) -> Array:
        """The unit quaternion(s).

        Args:
            canonical: pick the sign with `w > 0` (and, where `w = 0`, the first non-zero
                of `x, y, z` positive); otherwise the stored sign.
            scalar_first: return `[w, x, y, z]`.

        Returns:
            `(..., 4)` unit quaternions, scalar last unless `scalar_first`.

        Examples:
            ```python
            from rotjax import Rotation

            r = Rotation.from_quat([0.0, 0.0, -0.6, -0.8])
            print(r.as_quat(), r.as_quat(canonical=True))
            # [ 0.   0.  -0.6 -0.8] [-0.  -0.   0.6  0.8]
            ```
        """
        q = quaternion_canonical(self._quat) if canonical else self._quat
        return to_scalar_last(q, False) if not scalar_first else jnp.roll(q, 1, axis=-1)

    def as_matrix(self) -> Array:
        """Active rotation matrices (`v_world = R @ v_body`).

        Returns:
            `(..., 3, 3)` rotation matrices.

        Examples:
            ```python
            from rotjax import Rotation

            print(Rotation.from_euler("x", 90.0, degrees=True).as_matrix().round(6))
            # [[ 1.  0.  0.]
            #  [ 0. -0. -1.]
            #  [ 0.  1. -0.]]
            ```
        """
        return _read(self._stored, quat_to_matrix, self._bounded)

    def as_rotvec(self, degrees: bool = False) -> Array:
        """Rotation vectors `angle * axis` with the angle in `[0, pi]`.

        Args:
            degrees: return the norm in degrees.

        Returns:
            `(..., 3)` rotation vectors.

        Examples:
            ```python
            from rotjax import Rotation

            print(Rotation.from_euler("y", -30.0, degrees=True).as_rotvec(degrees=True).round(4))
            # [  0. -30.   0.]
            ```
        """
        return _read(self._stored, quat_to_rotvec, self._bounded, degrees=degrees)

    def as_mrp(self) -> Array:
        """Modified Rodrigues parameters `axis * tan(angle / 4)`, norm at most 1.

        Returns:
            `(..., 3)` modified Rodrigues parameters.

        Examples:
            ```python
            from rotjax import Rotation

            print(Rotation.from_euler("z", 90.0, degrees=True).as_mrp().round(6))  # tan(22.5 deg)
            # [0.       0.       0.414214]
            ```
        """
        return _read(self._stored, quat_to_mrp, self._bounded)

    def as_euler(
        self, seq: str, degrees: bool = False, *, suppress_warnings: bool = False
    ) -> Array:
        """Euler angles in scipy's ranges (see [`quaternion_to_euler`][rotjax.quaternion_to_euler]).

        Args:
            seq: three axes, `"XYZ"`-style intrinsic, `"xyz"`-style extrinsic, or digits.
            degrees: return degrees.
            suppress_warnings: accepted for scipy compatibility: rotjax has no gimbal-lock
                threshold and never warns (at exact lock the third angle is 0, as scipy).

        Returns:
            `(..., 3)` angles in the order of `seq`.

        Examples:
            ```python
            from rotjax import Rotation

            r = Rotation.from_euler("ZYX", [30.0, 20.0, 10.0], degrees=True)
            print(r.as_euler("ZYX", degrees=True).round(4))
            # [30. 20. 10.]
            ```
        """
        del suppress_warnings
        if not isinstance(seq, str) or len(seq) != 3:
            raise ValueError(f"Expected 3 axes, got {seq!r}.")
        parse_seq(seq)
        return quaternion_to_euler(self._stored, seq, degrees=degrees)

    def as_davenport(
        self,
        axes: ArrayLike,
        order: str,
        degrees: bool = False,
        *,
        suppress_warnings: bool = False,
    ) -> Array:
        """Davenport angles about three axes, consecutive ones orthogonal.

        Args:
            axes: `(..., 3, 3)` the axes as rows; batch shape broadcasts with `shape`.
            order: `"e"`/`"extrinsic"` or `"i"`/`"intrinsic"`.
            degrees: return degrees.
            suppress_warnings: accepted for scipy compatibility (no gimbal-lock warning).

        Returns:
            `(..., 3)` angles in scipy's ranges (see
                [`quaternion_to_davenport`][rotjax.quaternion_to_davenport]).

        Examples:
            ```python
            from rotjax import Rotation

            axes = [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]  # z, x, z
            r = Rotation.from_euler("ZXZ", [10.0, 20.0, 30.0], degrees=True)
            print(r.as_davenport(axes, "intrinsic", degrees=True).round(4))
            # [10. 20. 30.]
            ```
        """
        del suppress_warnings
        extrinsic = parse_order(order)
        ax = float_array(axes, self._stored.dtype)
        if ax.ndim < 2 or ax.shape[-2] != 3:
            raise ValueError(f"Expected 3 axes, got {ax.shape}.")
        if ax.shape[-1] != 3:
            raise ValueError("Axes must be vectors of length 3.")
        try:
            np.broadcast_shapes(ax.shape[:-2], self.shape)
        except ValueError:
            raise ValueError(
                f"Expected `axes` to match number of rotations, got {ax.shape} axes and "
                f"{self._stored.shape} rotations."
            ) from None
        host = host_value(axes)
        if host is not None:
            h = host / np.linalg.norm(host, axis=-1, keepdims=True)
            if np.any(np.abs(np.sum(h[..., :-1, :] * h[..., 1:, :], axis=-1)) > 1e-7):
                raise ValueError("Consecutive axes must be orthogonal.")
        return quaternion_to_davenport(self._stored, ax, extrinsic=extrinsic, degrees=degrees)

    # --- algebra -------------------------------------------------------------------------

    def __mul__(self, other: Rotation) -> Rotation:
        """Composition `self * other`: `other` applied first; batch shapes broadcast.

        Args:
            other: the rotation(s) applied first.

        Returns:
            The composed rotation(s).

        Examples:
            ```python
            from rotjax import Rotation

            x90 = Rotation.from_euler("x", 90.0, degrees=True)
            z90 = Rotation.from_euler("z", 90.0, degrees=True)
            print((z90 * x90).apply([0.0, 1.0, 0.0]).round(6))  # y -> z, then z stays
            # [-0.  0.  1.]
            ```
        """
        if not isinstance(other, Rotation):
            return NotImplemented
        # The shapes are checked here, so that the error is scipy's ValueError.
        np_shapes = (self.shape, other.shape)
        try:
            np.broadcast_shapes(*np_shapes)
        except ValueError:
            raise ValueError(
                f"Cannot broadcast {np_shapes[0]} rotations in first to {np_shapes[1]} "
                "rotations in second object."
            ) from None
        stored = _rotation_compose(
            self._stored, other._stored, rescale_p=not self._unit, rescale_q=not other._unit
        )
        return Rotation._raw(stored, unit=self._unit and other._unit, bounded=True)

    def __pow__(self, n: ArrayLike, modulus: None = None) -> Rotation:
        """Fractional power: `n` times the rotation angle about the same axis.

        See [`quaternion_power`][rotjax.quaternion_power]. `r ** 1` is `r` up to the
        quaternion's sign (`w >= 0`), `r ** 0` the identity exactly.

        Args:
            n: the exponent, a scalar (an array of shape `()` or `(1,)`).
            modulus: not supported (scipy's signature).

        Returns:
            The rotation(s) by `n` times the angle.

        Examples:
            ```python
            from rotjax import Rotation

            r = Rotation.from_euler("z", 90.0, degrees=True)
            print((r ** 0.5).as_euler("ZYX", degrees=True).round(4))
            # [45.  0.  0.]
            ```
        """
        e = self._exponent(n, modulus)
        return Rotation._raw(quaternion_power(self._quat, e), unit=True)

    def inv(self) -> Rotation:
        """The inverse rotation(s).

        Returns:
            The inverse, of the same shape.

        Examples:
            ```python
            from rotjax import Rotation

            r = Rotation.from_rotvec([0.1, 0.2, 0.3])
            print((r * r.inv()).magnitude().round(6))
            # 0.0
            ```
        """
        conj = quaternion_conjugate(self._stored)
        return Rotation._raw(conj, unit=self._unit, bounded=self._bounded)

    def apply(self, vectors: ArrayLike, inverse: bool = False) -> Array:
        """Rotate vectors: `R @ v` (`R.T @ v` with `inverse`).

        Args:
            vectors: `(..., 3)` vectors; batch shapes broadcast with the rotations'.
            inverse: apply the inverse rotation.

        Returns:
            `(..., 3)` rotated vectors, in the rotation's dtype.

        Examples:
            ```python
            from rotjax import Rotation

            r = Rotation.from_euler("z", 90.0, degrees=True)
            print(r.apply([1.0, 0.0, 0.0]).round(6),
                  r.apply([1.0, 0.0, 0.0], inverse=True).round(6))
            # [-0.  1.  0.] [-0. -1.  0.]
            ```
        """
        host = host_value(vectors)
        dtype = self._stored.dtype
        v = host.astype(dtype) if host is not None else float_array(vectors, dtype)
        if v.ndim < 1 or v.shape[-1] != 3:
            raise ValueError(f"Expected input of shape (..., 3), got {v.shape}.")
        try:
            np.broadcast_shapes(self.shape, v.shape[:-1])
        except ValueError:
            raise ValueError(
                f"Cannot broadcast {self.shape} rotations to {v.shape[:-1]} vectors."
            ) from None
        return _rotation_apply(self._stored, v, inverse=inverse, bounded=self._bounded)

    def magnitude(self) -> Array:
        """Rotation angles in `[0, pi]`.

        Returns:
            `(...)` angles in radians, of shape `shape`.

        Examples:
            ```python
            from rotjax import Rotation

            print(Rotation.from_rotvec([[0.0, 0.0, 0.5], [3.0, 0.0, 0.0]]).magnitude().round(6))
            # [0.5 3. ]
            ```
        """
        return _read(self._stored, lambda q, b: from_part(quat_angle(q, b)), self._bounded)

    def approx_equal(
        self, other: Rotation, atol: ArrayLike | None = None, degrees: bool = False
    ) -> Array:
        """Whether the angle between the rotations is below `atol`.

        Args:
            other: rotations whose batch shape broadcasts with `shape`.
            atol: the angle (radians, or degrees with `degrees`). Default: scipy's 1e-8 rad
                in float64, scaled with the square root of the machine epsilon in lower
                precision (`1e-8 * sqrt(eps / eps_float64)`: about 2.3e-4 rad in float32),
                so that a rotation compares equal to itself and to its round trips.
            degrees: `atol` is in degrees.

        Returns:
            `(...)` booleans, one per rotation pair.

        Examples:
            ```python
            from rotjax import Rotation

            r = Rotation.from_euler("z", 90.0, degrees=True)
            s = Rotation.from_euler("z", 90.5, degrees=True)
            print(r.approx_equal(s, atol=1.0, degrees=True), r.approx_equal(s))
            # True False
            ```
        """
        if atol is None:
            dt = jnp.result_type(self._stored.dtype, other._stored.dtype)
            atol = 1e-8 * float(np.sqrt(jnp.finfo(dt).eps / np.finfo(np.float64).eps))
            if degrees:
                warnings.warn(
                    f"atol must be set to use the degrees flag, defaulting to {atol:.3g} radians.",
                    stacklevel=2,
                )
        elif degrees:
            atol = np.deg2rad(atol)
        p, q = broadcast_batch(
            self._quat,
            other._quat,
            trailing=(1, 1),
            what="Expected broadcastable shapes in both rotations, got",
        )
        return angle_between(p, q) < atol

    def mean(
        self, weights: ArrayLike | None = None, axis: int | tuple[int, ...] | None = None
    ) -> Rotation:
        """Weighted mean rotation (Markley et al. 2007;
        [`quaternion_mean`][rotjax.quaternion_mean]).

        Args:
            weights: non-negative weights broadcastable to `shape`; `None` for ones.
            axis: batch axis or axes to reduce; `None` for all.

        Returns:
            The mean rotation(s), with the reduced axes removed.

        Examples:
            ```python
            from rotjax import Rotation

            r = Rotation.from_euler("z", [[10.0], [20.0], [30.0]], degrees=True)
            print(r.mean().as_euler("ZYX", degrees=True).round(2))
            # [20.  0.  0.]
            ```
        """
        q = jnp.atleast_2d(self._quat)
        nb = q.ndim - 1
        if q.shape[0] == 0:
            raise ValueError("Mean of an empty rotation set is undefined.")
        axes = tuple(range(nb)) if axis is None else ((axis,) if isinstance(axis, int) else axis)
        if not isinstance(axes, tuple):
            raise ValueError("`axis` must be None, int, or tuple of ints.")
        if axes and (min(axes) < -nb or max(axes) > nb - 1):
            raise ValueError(f"axis {axis} is out of bounds for rotation with shape {self.shape}.")
        axes = tuple(sorted({a % nb for a in axes}))
        keep = tuple(i for i in range(nb) if i not in axes)
        if weights is None:
            w = None
        else:
            host = host_value(weights)
            if host is not None and np.any(host < 0):
                raise ValueError("`weights` must be non-negative.")
            w = float_array(weights, q.dtype)
            try:
                w = jnp.broadcast_to(w, q.shape[:-1])
            except ValueError:
                raise ValueError(
                    "Expected `weights` to be broadcastable to rotation shape, got shape "
                    f"{w.shape} for {q.shape[:-1]} rotations."
                ) from None
            w = where(w < 0, jnp.nan, w)
            w = jnp.reshape(jnp.transpose(w, keep + axes), [q.shape[i] for i in keep] + [-1])
        qt = jnp.transpose(q, keep + axes + (nb,))
        qt = jnp.reshape(qt, [q.shape[i] for i in keep] + [-1, 4])
        return Rotation._raw(quaternion_mean(qt, w), unit=True)

    def reduce(
        self,
        left: Rotation | None = None,
        right: Rotation | None = None,
        return_indices: bool = False,
    ) -> Rotation | tuple[Rotation, Array | None, Array | None]:
        """Reduce by groups: `l * self * r` with the smallest angle.

        See [`quaternion_reduce`][rotjax.quaternion_reduce].

        Args:
            left: a `Rotation` holding the left group, or `None`.
            right: a `Rotation` holding the right group, or `None`.
            return_indices: also return the indices of the chosen `l` and `r` (`None`
                for an absent group).

        Returns:
            The reduced rotation(s); with `return_indices`, the tuple `(reduced, left_index,
                right_index)` with `(...)` integer indices or `None`.

        Examples:
            ```python
            from rotjax import Rotation

            group = Rotation.create_group("C4")  # quarter turns about z
            r = Rotation.from_euler("z", 100.0, degrees=True)
            print(r.reduce(left=group).magnitude().round(6))  # 10 deg, in radians
            # 0.174533
            ```
        """
        if left is None and right is None:
            reduced, li, ri = self, None, None
        else:
            lq = None if left is None else jnp.atleast_2d(left._quat)
            rq = None if right is None else jnp.atleast_2d(right._quat)
            q, li, ri = quaternion_reduce(self._quat, lq, rq)
            reduced = Rotation._raw(q)
            li = None if left is None else li
            ri = None if right is None else ri
        if return_indices:
            return reduced, li, ri
        return reduced


@jit
def _align_primary(a, b, w):
    """`align_vectors` with scipy's infinite-weight rule; `(N, 3)`, `(N, 3)`, `(N,)`."""
    n = a.shape[0]
    inf = jnp.isinf(w) | (n == 1)
    bad = (jnp.sum(jnp.isinf(w)) > 1) | jnp.any(w < 0)
    w_fin = where(inf, 0.0, w)
    # Least squares over all pairs (used when no weight is infinite).
    q_svd = _align_vectors(a, b, where(jnp.isinf(w), 1.0, w))
    # The primary pair, aligned exactly by the smallest rotation.
    k = jnp.argmax(inf)
    ap, bp = a[k], b[k]
    ap = ap / jnp.sqrt(jnp.sum(ap * ap))
    bp = bp / jnp.sqrt(jnp.sum(bp * bp))
    # q = (b x a, 1 + a.b), from s = a + b: 1 + a.b = |s|^2 / 2 and b x a = b x s, both
    # accurate to a few eps relative even near 180 degrees, where 1 + a.b cancels.
    sv = ap + bp
    c = 0.5 * jnp.sum(sv * sv)
    # Antiparallel: any axis perpendicular to a serves; the coordinate axis least aligned with
    # a gives a well-conditioned cross product.
    e = jnp.eye(3, dtype=a.dtype)[jnp.argmin(jnp.abs(ap))]
    anti = c < jnp.finfo(a.dtype).tiny
    vec = where(anti, cross(ap, e), cross(bp, sv))
    q_pri = quaternion_normalize(jnp.concatenate([vec, where(anti, 0.0, c)[None]]))
    # The rotation about a_p that best aligns the secondary pairs (scipy's 2-D problem).
    cs = quaternion_apply(jnp.broadcast_to(q_pri, (n, 4)), b)
    apn = ap[None, :]
    sin = jnp.sum(cross(cs, a) * apn, axis=-1)
    cos = jnp.sum(cs * a, axis=-1) - jnp.sum(cs * apn, axis=-1) * jnp.sum(a * apn, axis=-1)
    phi = atan2(jnp.sum(w_fin * sin), jnp.sum(w_fin * cos))
    q_fix = quaternion_multiply(rotvec_to_quaternion(phi * ap), q_pri)
    q = where(jnp.any(inf), q_fix, q_svd)
    q = where(bad, jnp.nan, q)
    d = a - quaternion_apply(jnp.broadcast_to(q, (n, 4)), b)
    # A single finite-weight pair keeps its weight in the residual (scipy's rule).
    w_res = w if n == 1 else w_fin
    w_res = where(jnp.isinf(w_res), 0.0, w_res)
    ss = jnp.sum(w_res * jnp.sum(d * d, axis=-1))
    pos = ss > 0
    rssd = where(pos, jnp.sqrt(where(pos, ss, 1.0)), 0.0)  # cone at 0: gradient 0 there
    rssd = where(jnp.isnan(ss), jnp.nan, rssd)
    return q, rssd
