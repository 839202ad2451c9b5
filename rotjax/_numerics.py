"""Numerical helpers shared by every module: dtype handling, shape checks, safe maths.

Everything here is private. The helpers follow two rules that the public functions rely on:

* thresholds are functions of the dtype (`_eps`), never fixed constants;
* any operation that is singular somewhere is guarded by the *double where* pattern: the
  dangerous operand is replaced by a harmless value before the operation, so that the branch not
  taken cannot send NaN (or inf) into the gradient;
* every matrix product (`dot_general`) asks for full precision (`FULL`): on GPUs a
  float32 `dot` at JAX's default precision may run in TF32 (10-bit mantissa), and on TPUs in
  bfloat16 passes.
"""

from __future__ import annotations

import functools
import inspect
import weakref
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

# Dtypes that are computed in float32 and cast back (they have too few bits for the algorithms).
_LOW_PRECISION = (jnp.dtype(jnp.bfloat16), jnp.dtype(jnp.float16))


# Precision of every dot_general in rotjax. XLA:CPU computes float32 in full either way.
FULL = jax.lax.Precision.HIGHEST


def matmul(a, b):
    """`a @ b` at full precision on every backend (see `FULL`)."""
    return jnp.matmul(a, b, precision=FULL)


def matvec(a, x):
    """`a @ x` for small `(..., n, n)` and `(..., n)`, broadcasting: elementwise products
    and a sum, which XLA fuses into the surrounding loop (no `dot`, so no precision setting
    and the same bits however the batch dimensions broadcast)."""
    return jnp.sum(a * x[..., None, :], axis=-1)


def eps(dtype) -> float:
    """Machine epsilon of `dtype` as a Python float."""
    return float(np.finfo(dtype).eps)


def as_float(*xs):
    """Convert inputs to one floating compute dtype.

    Integers and bools are promoted to JAX's default float; float32 and float64 are preserved;
    bfloat16 and float16 are computed in float32.

    Returns:
        `(arrays, out_dtype)`: the converted arrays (a tuple, one per input) and the dtype the
            results should be cast back to.
    """
    arrs = [jnp.asarray(x) for x in xs]
    dt = jnp.result_type(*arrs)
    if not jnp.issubdtype(dt, jnp.floating):
        dt = jnp.result_type(float)
    out_dtype = jnp.dtype(dt)
    compute = jnp.dtype(jnp.float32) if out_dtype in _LOW_PRECISION else out_dtype
    return tuple(a.astype(compute) for a in arrs), out_dtype


def cast(x, dtype):
    """``x`` in ``dtype``: ``x`` itself where it has that dtype already (a conversion would be
    a new array, which :func:`unstack` would no longer recognise)."""
    return x if x.dtype == dtype else x.astype(dtype)


def check_shape(x, trailing: tuple[int, ...], name: str) -> None:
    """Raise `ValueError` at trace time unless `x.shape` ends with `trailing`.

    Args:
        x: the array, after `as_float`.
        trailing: the shape its last axes must have, e.g. `(3, 3)`.
        name: the argument's name, for the message.
    """
    n = len(trailing)
    if x.ndim < n or tuple(x.shape[x.ndim - n :]) != tuple(trailing):
        want = "(..., " + ", ".join(str(t) for t in trailing) + ")"
        raise ValueError(f"{name}: expected shape {want}, got {tuple(x.shape)}")


def like_rank(c, x, dtype=None):
    """`c` (an array or constant of trailing shape, e.g. `(4,)`) in `dtype` (default:
    `x`'s), with leading unit axes up to `x`'s rank: it broadcasts against `x` under
    `jax_numpy_rank_promotion="raise"` (an explicit, not an implicit, rank promotion)."""
    c = jnp.asarray(c, dtype=x.dtype if dtype is None else dtype)
    return c.reshape((1,) * (x.ndim - c.ndim) + c.shape)


def to_scalar_last(q, scalar_first: bool):
    """Reorder a quaternion to the internal scalar-last `(x, y, z, w)` layout."""
    return jnp.roll(q, -1, axis=-1) if scalar_first else q


def from_scalar_last(q, scalar_first: bool):
    """Reorder an internal scalar-last quaternion to the caller's layout."""
    return jnp.roll(q, 1, axis=-1) if scalar_first else q


def int_type(dtype):
    """The signed integer type of a float type's width: for its bits, and for an integer that
    selects among its values (a narrower or wider one keeps the selects out of the loop's
    vector lanes)."""
    return {2: jnp.int16, 4: jnp.int32, 8: jnp.int64}[jnp.dtype(dtype).itemsize]


def max_abs_bits(*xs):
    """The largest `|x|` over per-element float arrays, as the signed integer of its bits:
    for floats `>= 0` the integers' order is the floats' order, with NaN above infinity, so
    this is :func:`max_abs` exactly (a NaN operand gives a NaN's bits), but with integer
    maxima, one instruction each, where XLA:CPU lowers a float `maximum` with a NaN test (three).
    `|x|` is taken as a float, then reinterpreted: LLVM does not vectorise a loop that reads
    a component both as a float and, reinterpreted, as an integer (six times slower, measured
    in `quaternion_to_matrix`). For scale factors: no derivative flows through it."""
    ity = int_type(xs[0].dtype)
    bits = (jax.lax.bitcast_convert_type(jnp.abs(jax.lax.stop_gradient(x)), ity) for x in xs)
    return pairwise(jnp.maximum, bits)


def signbit(x):
    """`jnp.signbit(x)` of a float array (true for -0.0 and a negative NaN), from the sign of
    its bits read as a signed integer: one comparison, without `jnp.signbit`'s nested `jit`."""
    return jax.lax.bitcast_convert_type(x, int_type(x.dtype)) < 0


def float_bits(value, dtype):
    """The bits of the float `value` (not negative) in `dtype`, as a Python integer."""
    return int(np.asarray(value, dtype).view(np.dtype(int_type(dtype))))


def exponent_scale_of_bits(bits, dtype):
    """:func:`exponent_scale` of the magnitude bits :func:`max_abs_bits` returns, for a caller
    that reads those bits too."""
    info = jnp.finfo(dtype)
    ity = bits.dtype
    mant = info.nmant
    bias = (1 << (info.nexp - 1)) - 1
    field = bits & jnp.asarray(((1 << info.nexp) - 1) << mant, ity)
    field = jax.lax.clamp(
        jnp.asarray(1 << mant, ity), field, jnp.asarray((2 * bias - 1) << mant, ity)
    )
    s = jax.lax.bitcast_convert_type(jnp.asarray(2 * bias << mant, ity) - field, dtype)
    return s, jax.lax.bitcast_convert_type(field, dtype)


def _marked(bits, s, dtype):
    """`s`, NaN where the magnitude `bits` are those of zero, infinity or NaN."""
    return where((bits > 0) & (bits < float_bits(np.inf, dtype)), s, jnp.nan)


def exponent_scale(*xs, mark=False):
    """`(s, 1 / s)`, powers of two with `s max|x|` in `[1, 2)` over the per-element arrays `xs`
    (finite, normal).

    Read off the exponent field with integer arithmetic (:func:`max_abs_bits`), so both are
    exact and multiplying by them adds no rounding (a division or `jnp.frexp` would cost as
    much as the rest of a conversion and keep XLA from fusing the scaling into its consumers).
    The exponent is clamped so that both factors stay normal: where every `x` is zero or
    subnormal, `s = 2^(emax-1)` and `s max|x|` lies in `[eps, 1)`; where one is infinite or
    NaN, `s = 2^(emin)`, and it stays infinite or NaN; with `mark`, `s` is NaN there instead
    (not a rotation). The factor is piecewise constant: no derivative flows through it.
    """
    dt = xs[0].dtype
    bits = max_abs_bits(*xs)
    s, inv = exponent_scale_of_bits(bits, dt)
    return (_marked(bits, s, dt) if mark else s), inv


def unit_scale(*xs, mark=False):
    """A power of two `s` (exact) that brings the largest `|x|` over `xs` into `[0.5, 2)`:
    1 where it is there already (unit quaternions, rotation matrices: their results are the
    same bits as unscaled), else that of :func:`exponent_scale`, so that squares and products
    of the scaled values can neither overflow nor underflow. `mark`: NaN instead where every
    `x` is zero or one is infinite or NaN (not a rotation). Piecewise constant: no derivative
    flows through it (the functions scaled by it do not depend on the scale)."""
    dt = xs[0].dtype
    bits = max_abs_bits(*xs)
    s, _ = exponent_scale_of_bits(bits, dt)
    s = where((bits >= float_bits(0.5, dt)) & (bits < float_bits(2.0, dt)), jnp.ones_like(s), s)
    return _marked(bits, s, dt) if mark else s


def where(condition, x, y):
    """`jnp.where(condition, x, y)`, written as one `lax.select`: `jnp.where` is a nested `jit`
    (its array conversions and broadcasts too), which adds a function to the program at every
    call, hundreds in a conversion's gradient, for JAX to trace and lower and XLA to inline.
    The same promotion (a Python number takes the array's type) and broadcasting; for two
    numbers, :func:`select` (which names the type)."""
    if not any(isinstance(v, (jax.Array, np.ndarray)) for v in (x, y)):
        raise TypeError("where: x or y must be an array; for two numbers use select")
    dt = jnp.result_type(x, y)
    shape = jnp.broadcast_shapes(*(np.shape(v) for v in (condition, x, y)))

    def operand(v, dtype):
        if not isinstance(v, (jax.Array, np.ndarray)):
            return jax.lax.full(shape, v, dtype)
        v = jax.lax.convert_element_type(v, dtype) if v.dtype != dtype else v
        if v.shape == shape:
            return v
        return jax.lax.broadcast_in_dim(v, shape, tuple(range(len(shape) - v.ndim, len(shape))))

    if jnp.result_type(condition) != jnp.bool_:
        condition = jnp.asarray(condition) != 0
    return jax.lax.select(operand(condition, jnp.bool_), operand(x, dt), operand(y, dt))


def select(cond, a, b, dtype):
    """`jnp.where(cond, a, b)` for Python numbers `a` and `b`, as an array of `dtype`.
    On two Python numbers `jnp.where` makes an array of the default type, float64 with x64 on,
    which a float32 program would then compute and convert in every loop that reads it."""
    return where(cond, np.asarray(a, dtype), np.asarray(b, dtype))


def pairwise(op, xs):
    """``op`` folded over the per-element arrays ``xs`` as a balanced tree: the dependency chain
    is ``log2(n)`` operations long, not ``n - 1``, which lets the CPU overlap more of a
    vectorised loop's iterations (nine entries of a matrix: 4 steps instead of 8)."""
    xs = list(xs)
    while len(xs) > 1:
        xs = [op(*xs[i : i + 2]) if i + 1 < len(xs) else xs[i] for i in range(0, len(xs), 2)]
    return xs[0]


def sum_squares(xs):
    """``sum(x * x for x in xs)`` over per-element arrays (the components of a vector, the
    entries of a matrix), added in a balanced tree (see :func:`pairwise`)."""
    return pairwise(jnp.add, (x * x for x in xs))


# Trace-time record of stacked results: `stack` notes the parts of each traced array it returns,
# and `unstack` of that very array returns them rather than reading the array back. A chain of
# rotjax operations then passes per-rotation expressions from one to the next, and XLA fuses the
# whole chain into one loop whatever the layout of the intermediate results (XLA does not see
# through a stacked array read back by slices: it writes it out, or recomputes it per slice).
# unstack(stack(parts)) == parts exactly, so values and derivatives are those of the code.
# A stacked unit quaternion (a conversion's, a normalisation's) is marked so: its readers skip
# the prescaling, which is exactly 1 for it (see rotjax._quaternion._prescaled_parts). A
# quaternion whose maker has a direct form of its matrix carries it (see noted_matrix_form).
class _Record(NamedTuple):
    ref: weakref.ref  # the traced array (its id may be reused once it is gone)
    parts: tuple
    matrix: bool  # by stack_matrix
    unit: bool  # a unit quaternion (see noted_unit)
    matrix_form: object = None  # a function of no argument: this quaternion's rotation matrix


_PARTS: dict[int, _Record] = {}


def _note(out, parts, matrix=False, unit=False, matrix_form=None) -> None:
    if isinstance(out, jax.core.Tracer):
        key = id(out)
        ref = weakref.ref(out, lambda _, key=key: _PARTS.pop(key, None))
        _PARTS[key] = _Record(ref, tuple(parts), matrix, unit, matrix_form)


def _record(x, matrix):
    """What :func:`stack` (or, ``matrix``, :func:`stack_matrix`) recorded for ``x`` in this
    trace, or None."""
    hit = _PARTS.get(id(x))
    return hit if hit is not None and hit.ref() is x and hit.matrix == matrix else None


def _parts(x, matrix):
    """The parts recorded for ``x`` (see :func:`_record`), or None."""
    hit = _record(x, matrix)
    return None if hit is None else list(hit.parts)


def recorded(x, matrix=False) -> bool:
    """Whether ``x`` is a result of :func:`stack` (``matrix``: :func:`stack_matrix`) in this
    trace, whose parts :func:`unstack` (:func:`unstack_matrix`) returns."""
    return _parts(x, matrix) is not None


def noted_unit(x) -> bool:
    """Whether ``x`` is a result of ``stack(parts, unit=True)`` in this trace: a quaternion of
    unit norm to rounding, or NaN."""
    hit = _record(x, False)
    return hit is not None and hit.unit


def noted_matrix_form(q):
    """The function of no argument that ``stack(parts, matrix_form=...)`` noted for the
    quaternion ``q`` in this trace (its rotation matrix, computed from what made ``q``), or
    None."""
    hit = _record(q, False)
    return None if hit is None else hit.matrix_form


def unstack(x):
    """The components of ``x`` along its last axis, as per-rotation arrays: the one way rotjax
    reads a stacked array. For an array that :func:`stack` returned in the same trace, the parts
    it was given; else slices ``x[..., i:i+1]``. Per-rotation arrays keep that unit axis
    (``(..., 1)``): a squeeze after each slice counts, for XLA's fusion, once more per reader of
    the slice, and a slice read by a long chain was then copied in a loop of its own."""
    parts = _parts(x, False)
    return parts if parts is not None else list(_read(x))


@jax.custom_jvp
def _read(x):
    """The components of ``x`` (last axis) by slices; their tangents by :func:`components`
    (the same linear map), whose transpose in reverse mode writes the cotangent of ``x`` as
    :func:`stack` writes, in one vectorised loop (that of slices is a sum of pads)."""
    return tuple(x[..., i : i + 1] for i in range(x.shape[-1]))


@_read.defjvp
def _read_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    return _read(x), tuple(_components(dx))


def as_part(x):
    """A per-rotation scalar argument (``(...)``, broadcasting against the batch) as the
    per-rotation arrays of rotjax hold it, ``(..., 1)`` (see :func:`unstack`); a 0-d one
    as it is."""
    return x[..., None] if jnp.ndim(x) else x


def from_part(x):
    """A per-rotation array as rotjax returns a per-rotation scalar, ``(...)``: the inverse of
    :func:`as_part` (a reshape of the result alone, after every reader of the parts)."""
    return x[..., 0]


def _part_shape(parts):
    """The common shape of per-rotation arrays (each ``(..., 1)``, or a constant)."""
    shape = jnp.broadcast_shapes(*(jnp.shape(p) for p in parts))
    if not shape or shape[-1] != 1:
        raise AssertionError(f"per-rotation arrays end in a unit axis, got {shape}")
    return shape


def stack(parts, unit=False, matrix_form=None):
    """``(..., k)`` from ``k`` per-rotation arrays (each ``(..., 1)``, or a constant): the one
    way rotjax writes a stacked array (see :func:`unstack`). ``unit``: the parts are those of a
    unit quaternion (to rounding) or NaN, noted for :func:`noted_unit`; ``matrix_form``: noted
    for :func:`noted_matrix_form`.

    Written as a select on the last axis among the broadcast parts: each output element
    computes every part, so XLA:CPU's loop computes the shared per-rotation factors once and is
    vectorised (a concatenate computes each part in a branch of its own, which LLVM neither
    merges nor vectorises), and no transpose is left for the layout pass to turn into a copy
    when the result is one of several outputs. A root, a division or a transcendental function
    read by several slots is computed in a loop of its own: stack its arguments instead and
    apply it to the stacked array, or ``spread`` the inputs (as quaternion_to_euler), or use the
    fusible forms of ``_elementary``."""
    shape = _part_shape(parts)
    out = _select_stack(tuple(jnp.broadcast_to(p, shape) for p in parts))
    _note(out, parts, unit=unit, matrix_form=matrix_form)
    return out


def spread(x, k):
    """``(..., k)``: the per-rotation array ``x`` (``(..., 1)``) in each of ``k`` slots, for
    a kernel that computes each output element from the whole input (as a ``stack`` does, but
    with every step after the spread done per slot).

    A select on the slot index that never picks its zero: XLA moves a plain broadcast past the
    element-wise operations after it, back to per-rotation values that every slot reads, and
    computes such a value in a loop of its own when it is too long to copy into each reader
    (quaternion_to_euler's power-of-two scale was)."""
    col = jax.lax.broadcasted_iota(jnp.int32, (*jnp.shape(x)[:-1], k), jnp.ndim(x) - 1)
    return where(col == k, jnp.zeros((), x.dtype), x)


def per_slot(parts):
    """``(..., k)`` with slot ``i`` taken from ``parts[i]``, each already ``(..., k)`` (computed
    per slot after :func:`spread`): the counterpart of :func:`stack` for such parts."""
    col = jax.lax.broadcasted_iota(jnp.int32, parts[0].shape, parts[0].ndim - 1)
    out = parts[-1]
    for i in range(len(parts) - 2, -1, -1):
        out = where(col == i, parts[i], out)
    return out


@jax.custom_jvp
def _select_stack(parts):
    shape = (*parts[0].shape[:-1], len(parts))
    return per_slot([jnp.broadcast_to(p, shape) for p in parts])


@_select_stack.defjvp
def _select_stack_jvp(primals, tangents):
    # The same linear map, written as a concatenate: its transpose (reverse mode) reads each
    # part's cotangent by a slice, which XLA fuses into the loop that uses it (the select's
    # transpose is a sum over the last axis per part, each a loop of its own).
    (parts,), (dparts,) = primals, tangents
    return _select_stack(parts), jnp.concatenate(dparts, axis=-1)


def stack_matrix(rows, concat=False):
    """``(..., m, n)`` from ``m`` rows of ``n`` per-rotation arrays; :func:`unstack_matrix`
    reads its entries back.

    Written as :func:`stack` writes (a select among the entries, each output element computing
    every entry), which keeps entries that share long per-rotation expressions (the SO(3)
    Jacobians' coefficients, the SE(3) exponential's) in one fast loop. ``concat``: the rows
    stacked on the last axis, then the rows on the one before, which XLA:CPU vectorises for
    entries that are short expressions (a quaternion's matrix) but evaluates part by part,
    repeating shared expressions (fifteen times slower for ``so3_right_jacobian_inverse`` in
    float64)."""
    entries = [x for row in rows for x in row]
    if concat:
        shape = _part_shape(entries)
        rows = [[jnp.broadcast_to(x, shape) for x in row] for row in rows]
        out = jnp.stack([jnp.concatenate(row, axis=-1) for row in rows], axis=-2)
    else:
        flat = stack(entries)
        out = flat.reshape(*flat.shape[:-1], len(rows), len(rows[0]))
    _note(out, entries, matrix=True)
    return out


def noted_matrix(out, entries):
    """``out``, a ``(..., m, n)`` matrix computed otherwise (per slot), noted as the stack of
    ``entries`` (its per-rotation entries, row by row): a reader in this trace
    (:func:`unstack_matrix`) takes those, as from :func:`stack_matrix`."""
    _note(out, entries, matrix=True)
    return out


def unstack_matrix(R):
    """The entries of a ``(..., m, n)`` matrix, row by row, as per-rotation arrays (see
    :func:`unstack`)."""
    parts = _parts(R, True)
    return parts if parts is not None else list(_read(_flat(R)))


def tangent_entries(x):
    """The entries of a tangent ``(..., m, n)`` inside a hand-written derivative rule, row by
    row, as per-rotation arrays (:func:`_components`: in reverse mode the transpose of
    :func:`unstack_matrix`'s slices, applied to a tangent there, is a pad per entry)."""
    return _components(_flat(x))


def _flat(R):
    return R.reshape(*R.shape[:-2], R.shape[-2] * R.shape[-1])


def _components(x):
    """The components of ``x`` (last axis) as per-rotation arrays, read as sums against one-hot
    rows: for a hand-written rule's tangent, whose transpose (reverse mode) then writes each
    cotangent component by a select on the last axis, in one loop that XLA:CPU vectorises
    (slices transpose to pads, and a leading axis to a transposing copy of its own)."""
    k = x.shape[-1]
    col = jax.lax.broadcasted_iota(jnp.int32, (1,) * (x.ndim - 1) + (k,), x.ndim - 1)
    return [jnp.sum(where(col == i, x, 0.0), axis=-1, keepdims=True) for i in range(k)]


def shared_tangent(parts):
    """The per-rotation tangent ``parts`` of a hand-written rule, stacked and read back by
    :func:`_components`: the same values, but in reverse mode their cotangents are written once,
    as one array in one loop, for every later reader. Left as expressions, a cotangent that
    several outputs read was computed again in each output's loop (XLA:CPU does not fuse
    several outputs into one loop)."""
    return _components(jnp.concatenate(jnp.broadcast_arrays(*parts), axis=-1))


def max_abs(*xs):
    """Elementwise largest `|x|` over per-element arrays (`jnp.maximum`, not `jnp.max`
    over a stacked axis: XLA:CPU splits a reduction into loops of its own), in a balanced tree
    (see :func:`pairwise`). A NaN operand gives NaN."""
    return pairwise(jnp.maximum, (jnp.abs(x) for x in xs))


def safe_norm(x, axis=-1):
    """Euclidean norm with a finite gradient (zero) at the origin.

    The norm is a cone at 0, where no derivative exists; the returned gradient there is the
    minimum-norm subgradient, 0. Everywhere else it is the true derivative.
    """
    sq = jnp.sum(x * x, axis=axis)
    zero = sq == 0
    return where(zero, 0.0, jnp.sqrt(where(zero, 1.0, sq)))  # double where


def cross(a, b):
    """Cross product over the last axis (broadcasting)."""
    a0, a1, a2 = jnp.moveaxis(a, -1, 0)
    b0, b1, b2 = jnp.moveaxis(b, -1, 0)
    return jnp.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def dot3(x, y):
    """The dot product of two 3-vectors given by their components (per-rotation arrays)."""
    return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]


def cross3(x, y):
    """The cross product of two 3-vectors given by their components, as components (the
    stacked :func:`cross` reads and writes a trailing axis)."""
    return [x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]]


def det3(e):
    """The determinant of a 3x3 matrix from its nine entries (row by row, per-rotation arrays,
    as :func:`unstack_matrix` reads them), without a sum over a stacked axis (a loop of its own
    on XLA:CPU)."""
    return dot3(e[0:3], cross3(e[3:6], e[6:9]))


def skew(v):
    """Skew-symmetric matrix `[v]x` with `skew(v) @ u == cross(v, u)`; shape `(..., 3, 3)`."""
    x, y, z = unstack(v)
    o = jnp.zeros_like(x)
    rows = ((o, -z, y), (z, o, -x), (-y, x, o))
    return stack_matrix(rows)


def axial(m):
    """Axial vector of the antisymmetric part of `m` (the inverse of `skew`): `(..., 3)`."""
    return 0.5 * jnp.stack(
        [m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]],
        axis=-1,
    )


# Keyword arguments that select code paths: always static under jit.
STATIC_ARGS = ("seq", "degrees", "scalar_first", "method", "frame", "axis")

# Trailing (non-batch) rank of each array argument, by the name the public functions give it:
# `(..., 4)` quaternions, `(..., 3, 3)` matrices, `(..., 3)` and `(..., 6)` vectors,
# `(...)` per-rotation scalars. A set or time axis counts as batch (`weights` is
# `(..., N)` against `(..., N, 3)` vectors).
_TRAILING_RANK = {
    **dict.fromkeys(("p", "q", "q_a", "q_b", "q_dot"), 1),
    **dict.fromkeys(("R", "R_a", "R_b", "R_dot"), 2),
    **dict.fromkeys(("omega", "v", "rotvec", "axis", "angles", "rates", "a", "b", "x"), 1),
    **dict.fromkeys(("angle", "t", "dt", "weights", "damping"), 0),
}


def broadcast_batch(*arrays, trailing=1, what="Cannot broadcast the batch shapes"):
    """The arrays broadcast explicitly to one batch shape (all but each array's `trailing`
    core axes: an int for all, or one per array), so that rank promotion is never implicit;
    an array that has it already is returned as it is. `ValueError` (`what` and the shapes)
    where the batch shapes do not broadcast."""
    if isinstance(trailing, int):
        trailing = (trailing,) * len(arrays)
    lead = [a.shape[: a.ndim - t] for a, t in zip(arrays, trailing, strict=True)]
    try:
        shape = np.broadcast_shapes(*lead)
    except ValueError:
        raise ValueError(f"{what} {', '.join(map(str, lead))}") from None
    return tuple(
        a if s == shape else jnp.broadcast_to(a, shape + a.shape[a.ndim - t :])
        for a, s, t in zip(arrays, lead, trailing, strict=True)
    )


def _broadcast_batches(arrays: dict) -> None:
    """Check that the batch shapes of the array arguments in `arrays` (name -> array, updated
    in place) broadcast, else raise `ValueError` naming both arguments and shapes (rather
    than a shape error from deep inside JAX); then give them leading unit axes up to a common
    batch rank, so that batches of different ranks broadcast with the explicit rank promotion
    that `jax_numpy_rank_promotion="raise"` allows. Trailing shapes are checked later, by
    `check_shape` in the function."""
    lead = {
        n: jnp.shape(x)[: jnp.ndim(x) - _TRAILING_RANK[n]]
        for n, x in arrays.items()
        if n in _TRAILING_RANK and x is not None and jnp.ndim(x) >= _TRAILING_RANK[n]
    }
    names = list(lead)
    for i, n in enumerate(names):
        for m in names[:i]:
            try:
                np.broadcast_shapes(lead[m], lead[n])
            except ValueError:
                raise ValueError(
                    f"leading (batch) shapes do not broadcast: {m} has {lead[m]} (shape "
                    f"{jnp.shape(arrays[m])}) and {n} has {lead[n]} "
                    f"(shape {jnp.shape(arrays[n])}); expected batch shapes that broadcast"
                ) from None
    rank = max((len(s) for s in lead.values()), default=0)
    for n, s in lead.items():
        if len(s) < rank:
            x = jnp.asarray(arrays[n])
            arrays[n] = x.reshape((1,) * (rank - len(s)) + x.shape)


def check_static(name: str, value):
    """Validate one configuration argument's type (its value is checked by the function that
    reads it, which knows the valid choices) and return it in canonical form."""
    if name in ("degrees", "scalar_first", "extrinsic", "normalize"):
        if not isinstance(value, (bool, np.bool_)):
            raise TypeError(f"{name} must be a bool, got {type(value).__name__} {value!r}")
        return bool(value)
    if name == "axis":
        # Any integer-like value (a NumPy integer included), but not a bool.
        if isinstance(value, (bool, np.bool_)) or not hasattr(value, "__index__"):
            raise TypeError(f"axis must be an int, got {type(value).__name__} {value!r}")
        return int(value.__index__())
    if not isinstance(value, str):  # seq, method, frame
        raise TypeError(f"{name} must be a str, got {type(value).__name__} {value!r}")
    return value


def check_array(name: str, value) -> None:
    """Reject complex input, whose imaginary part would otherwise be dropped silently."""
    if value is not None and jnp.iscomplexobj(value):
        raise TypeError(f"{name} must be real (float or integer), got complex {value.dtype}")


def _traced(tree) -> bool:
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree.leaves(tree))


try:  # JAX's own test of a jit trace on the stack (its trace state has no public reader)
    from jax._src.core import unsafe_am_i_under_a_jit as _under_jit
except ImportError:  # pragma: no cover - older or newer JAX: inline under any trace
    _under_jit = None


def _staged(tree) -> bool:
    """Whether a call with these arguments is being staged into a caller's jitted program: its
    arguments are tracers and a jit trace is on the stack (eager ``vmap`` or ``grad`` is not)."""
    return _traced(tree) and (_under_jit is None or _under_jit())


def jit(fun=None, *, static_argnames=()):
    """``jax.jit``, except inside a caller's jit (under its grad or vmap too), where the function
    is inlined: the caller's program holds no nested jit per call (less to trace and compile)
    and :func:`unstack` sees the stacked results of this call. Eager ``vmap``/``grad`` call the
    jitted function, as one compiled program."""
    if fun is None:
        return functools.partial(jit, static_argnames=static_argnames)
    jitted = jax.jit(fun, static_argnames=static_argnames)

    @functools.wraps(fun)
    def call(*args, **kwargs):
        if _staged((args, kwargs)):
            return fun(*args, **kwargs)
        return jitted(*args, **kwargs)

    return call


def public(fun=None, *, static=(), time_leading=()):
    """Jit-wrap a public function, with the configuration arguments it takes made static.

    `static`: further argument names to make static (flags of that function alone, such as
    `extrinsic`). `time_leading`: array arguments whose first axis is time, before the
    batch axes (a gyro log); the function broadcasts them itself, so they take no part in the
    batch-shape check below.

    Parsing and validation of those arguments then happens once, in Python, at trace time:
    errors are raised eagerly and cost nothing on later calls. Before the function body runs,

    * `seq`, `method` and `frame` must be `str`, `degrees` and `scalar_first`
      `bool` (or a NumPy bool) and `axis` an integer (a NumPy integer included); otherwise
      `TypeError`. Unknown values raise `ValueError` in the function, listing the valid
      ones;
    * complex arrays raise `TypeError`;
    * the array arguments' batch shapes must broadcast (`ValueError` naming both), and get
      leading unit axes up to a common rank (`_broadcast_batches`).

    A static argument that cannot be hashed (`seq` as a list) fails in `jax.jit` before
    any of this; the wrapper then runs the same checks to raise the clear error instead.
    """
    if fun is None:
        return functools.partial(public, static=static, time_leading=time_leading)
    sig = inspect.signature(fun)
    params = sig.parameters
    # `seq` is static wherever it appears; the other names only as keyword options with a
    # default (so an array argument that happens to be called `axis` stays traced).
    static = [
        n
        for n, p in params.items()
        if (n in STATIC_ARGS and (n == "seq" or p.default is not inspect.Parameter.empty))
        or n in static
    ]

    def validated(*args, **kwargs):
        bound = sig.bind(*args, **kwargs)
        for name, value in bound.arguments.items():
            if name in static:
                bound.arguments[name] = check_static(name, value)
            else:
                check_array(name, value)
        return bound

    arrays = [n for n in params if n not in static]

    @functools.wraps(fun)
    def traced(*args, **kwargs):
        bound = validated(*args, **kwargs)
        # A list or tuple argument arrives as a pytree of scalars: one array again.
        given = {
            n: jnp.asarray(v) if isinstance(v, (list, tuple)) else v
            for n, v in bound.arguments.items()
            if n in arrays and n not in time_leading
        }
        _broadcast_batches(given)
        bound.arguments.update(given)
        return fun(*bound.args, **bound.kwargs)

    jitted = jit(traced, static_argnames=static)

    @functools.wraps(fun)
    def call(*args, **kwargs):
        try:
            return jitted(*args, **kwargs)
        except (TypeError, ValueError):
            # jax.jit rejects an unhashable static argument before the checks run: run them
            # (the clear error naming the argument); any other error is raised as it was.
            validated(*args, **kwargs)
            raise

    return call


# A gap below `TIE_ULPS * eps * scale` is a tie in exact arithmetic: LAPACK resolves the
# eigenvalues and singular values of these small matrices to a few ulps of the largest one.
TIE_ULPS = 64.0


def safe_div(num, den, tol):
    """`num / den` where `|den| > tol`, else 0 (double where: the gradient stays finite)."""
    small = jnp.abs(den) <= tol
    return where(small, 0.0, num / where(small, 1.0, den))
