"""Numerical helpers shared by every module: dtype handling, shape checks, safe maths.

Everything here is private. The helpers follow two rules that the public functions rely on:

* thresholds are functions of the dtype (``_eps``), never fixed constants;
* any operation that is singular somewhere is guarded by the *double where* pattern: the
  dangerous operand is replaced by a harmless value before the operation, so that the branch not
  taken cannot send NaN (or inf) into the gradient;
* every matrix product (``dot_general``) asks for full precision (:data:`FULL`): on GPUs a
  float32 ``dot`` at JAX's default precision may run in TF32 (10-bit mantissa), and on TPUs in
  bfloat16 passes.
"""

from __future__ import annotations

import inspect

import jax
import jax.numpy as jnp
import numpy as np

# Dtypes that are computed in float32 and cast back (they have too few bits for the algorithms).
_LOW_PRECISION = (jnp.dtype(jnp.bfloat16), jnp.dtype(jnp.float16))


# Precision of every dot_general in rotjax. XLA:CPU computes float32 in full either way.
FULL = jax.lax.Precision.HIGHEST


def matmul(a, b):
    """``a @ b`` at full precision on every backend (see :data:`FULL`)."""
    return jnp.matmul(a, b, precision=FULL)


def matvec(a, x):
    """``a @ x`` for small ``(..., n, n)`` and ``(..., n)``, broadcasting: elementwise products
    and a sum, which XLA fuses into the surrounding loop (no ``dot``, so no precision setting
    and the same bits however the batch dimensions broadcast)."""
    return jnp.sum(a * x[..., None, :], axis=-1)


# Newton's iteration for 1/sqrt(x): the integer type that reinterprets the float's bits, the
# magic constant of the initial guess (relative error at most 3.4%), and the number of steps
# (the error squares at each: 3.4e-2, 1.7e-3, 4.6e-6, 3.2e-11, 1.5e-21).
_RSQRT_START = {
    jnp.dtype(jnp.float32): (jnp.int32, 0x5F375A86, 3),
    jnp.dtype(jnp.float64): (jnp.int64, 0x5FE6EB50C7B537A9, 4),
}


@jax.custom_jvp
def rsqrt(x):
    """``1 / sqrt(x)`` for positive, normal, finite float32 or float64 ``x``, from
    multiplications and additions only.

    XLA counts ``rsqrt``, ``sqrt`` and division as expensive and will not recompute them inside
    a consumer that reads each result more than once, so a per-rotation scale stacked into
    ``(..., 4)`` costs a loop of its own, which reads the input again. This form fuses. Initial
    guess from the bits of ``x`` (Lomont's constants), then Newton steps ``y (3 - x y^2) / 2``,
    the last one written as a correction ``y + y (1/2 - x y^2 / 2)`` so that its rounding
    error is that of a small term: at most 0.63 eps in each dtype, as for ``lax.rsqrt`` (2e6
    arguments against extended precision in an ad-hoc check; 8000 against mpmath in the
    tests). Outside the domain (zero, subnormal, infinite) the result is meaningless; NaN
    gives NaN.
    """
    int_type, magic, steps = _RSQRT_START[jnp.dtype(x.dtype)]
    bits = jax.lax.bitcast_convert_type(x, int_type)
    y = jax.lax.bitcast_convert_type(jnp.asarray(magic, int_type) - (bits >> 1), x.dtype)
    h = 0.5 * x
    for _ in range(steps - 1):
        y = y * (1.5 - h * y * y)
    return y + y * (0.5 - h * y * y)


@rsqrt.defjvp
def _rsqrt_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    y = rsqrt(x)
    return y, -0.5 * y * y * y * dx


def eps(dtype) -> float:
    """Machine epsilon of ``dtype`` as a Python float."""
    return float(np.finfo(dtype).eps)


def as_float(*xs):
    """Convert inputs to one floating compute dtype.

    Integers and bools are promoted to JAX's default float; float32 and float64 are preserved;
    bfloat16 and float16 are computed in float32.

    Returns:
        ``(arrays, out_dtype)``: the converted arrays (a tuple, one per input) and the dtype the
        results should be cast back to.
    """
    arrs = [jnp.asarray(x) for x in xs]
    dt = jnp.result_type(*arrs)
    if not jnp.issubdtype(dt, jnp.floating):
        dt = jnp.result_type(float)
    out_dtype = jnp.dtype(dt)
    compute = jnp.dtype(jnp.float32) if out_dtype in _LOW_PRECISION else out_dtype
    return tuple(a.astype(compute) for a in arrs), out_dtype


def check_shape(x, trailing: tuple[int, ...], name: str) -> None:
    """Raise ``ValueError`` at trace time unless ``x.shape`` ends with ``trailing``."""
    n = len(trailing)
    if x.ndim < n or tuple(x.shape[x.ndim - n :]) != tuple(trailing):
        want = "(..., " + ", ".join(str(t) for t in trailing) + ")"
        raise ValueError(f"{name}: expected shape {want}, got {tuple(x.shape)}")


def to_scalar_last(q, scalar_first: bool):
    """Reorder a quaternion to the internal scalar-last ``(x, y, z, w)`` layout."""
    return jnp.roll(q, -1, axis=-1) if scalar_first else q


def from_scalar_last(q, scalar_first: bool):
    """Reorder an internal scalar-last quaternion to the caller's layout."""
    return jnp.roll(q, 1, axis=-1) if scalar_first else q


def safe_norm(x, axis=-1):
    """Euclidean norm with a finite gradient (zero) at the origin.

    The norm is a cone at 0, where no derivative exists; the returned gradient there is the
    minimum-norm subgradient, 0. Everywhere else it is the true derivative.
    """
    sq = jnp.sum(x * x, axis=axis)
    zero = sq == 0
    return jnp.where(zero, 0.0, jnp.sqrt(jnp.where(zero, 1.0, sq)))  # double where


def safe_atan2(y, x):
    """``atan2`` whose gradient is finite (zero) at ``y = x = 0``, where it returns 0."""
    zero = (x == 0) & (y == 0)
    return jnp.where(zero, 0.0, jnp.arctan2(jnp.where(zero, 0.0, y), jnp.where(zero, 1.0, x)))


def cross(a, b):
    """Cross product over the last axis (broadcasting)."""
    a0, a1, a2 = jnp.moveaxis(a, -1, 0)
    b0, b1, b2 = jnp.moveaxis(b, -1, 0)
    return jnp.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def hat(v):
    """Skew-symmetric matrix ``[v]x`` with ``hat(v) @ u == cross(v, u)``; shape ``(..., 3, 3)``."""
    x, y, z = jnp.moveaxis(v, -1, 0)
    o = jnp.zeros_like(x)
    rows = ((o, -z, y), (z, o, -x), (-y, x, o))
    # Nested stacks, not a flat stack of nine: XLA:CPU then writes the matrix in one loop.
    return jnp.stack([jnp.stack(r, axis=-1) for r in rows], axis=-2)


def vee(m):
    """Inverse of :func:`hat` on the antisymmetric part of ``m``: ``(..., 3, 3) -> (..., 3)``."""
    return 0.5 * jnp.stack(
        [m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]],
        axis=-1,
    )


# Keyword arguments that select code paths: always static under jit.
STATIC_ARGS = ("seq", "degrees", "scalar_first", "method", "frame", "axis")


def public(fun):
    """Jit-wrap a public function, with the configuration arguments it takes made static.

    Parsing and validation of those arguments then happens once, in Python, at trace time:
    errors are raised eagerly and cost nothing on later calls.
    """
    params = inspect.signature(fun).parameters
    # ``seq`` is static wherever it appears; the other names only as keyword options with a
    # default (so an array argument that happens to be called ``axis`` stays traced).
    static = [
        n
        for n, p in params.items()
        if n in STATIC_ARGS and (n == "seq" or p.default is not inspect.Parameter.empty)
    ]
    return jax.jit(fun, static_argnames=static)


# A gap below ``TIE_ULPS * eps * scale`` is a tie in exact arithmetic: LAPACK resolves the
# eigenvalues and singular values of these small matrices to a few ulps of the largest one.
TIE_ULPS = 64.0


def safe_div(num, den, tol):
    """``num / den`` where ``|den| > tol``, else 0 (double where: the gradient stays finite)."""
    small = jnp.abs(den) <= tol
    return jnp.where(small, 0.0, num / jnp.where(small, 1.0, den))
