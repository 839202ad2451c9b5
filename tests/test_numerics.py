"""The private numerical kernels that the public functions' accuracy rests on."""

import jax
import jax.numpy as jnp
import mpmath as mp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import rotjax as rj
from rotjax._elementary import hypot, reciprocal, rsqrt
from rotjax._matrix import selected_column
from rotjax._numerics import exponent_scale, max_abs_bits, signbit, unit_scale, where

# Exponent ranges of normal numbers, and the documented accuracy of rsqrt: the Newton form's on
# the CPU, XLA's rsqrt elsewhere (a GPU's float32 rsqrt is within 2 ulp, CUDA's rsqrtf).
RANGE = {np.float32: (-37.5, 38.0), np.float64: (-307.5, 308.0)}
RSQRT_BOUND_EPS = 0.63
RSQRT_BOUND_EPS_XLA_FLOAT32 = 2.0


def _rsqrt_arguments(dtype, n, seed):
    rng = np.random.default_rng(seed)
    lo, hi = RANGE[dtype]
    dense = rng.uniform(1.0, 4.0, n)  # one period of the initial guess's error
    wide = 10.0 ** rng.uniform(lo, hi, n)
    return np.concatenate([dense, wide, [1.0, 2.0, 4.0]]).astype(dtype)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_rsqrt_is_within_its_documented_bound(dtype):
    x = _rsqrt_arguments(dtype, 4000, seed=7)
    got = np.asarray(jax.jit(rsqrt)(jnp.asarray(x)))
    assert got.dtype == dtype
    with mp.workdps(40):  # locally, as in tests/helpers.py
        err = [
            float(abs(mp.mpf(float(g)) * mp.sqrt(mp.mpf(float(a))) - 1))
            for g, a in zip(got, x, strict=True)
        ]
    eps = float(np.finfo(dtype).eps)
    xla_float32 = jax.default_backend() != "cpu" and dtype == np.float32
    bound = RSQRT_BOUND_EPS_XLA_FLOAT32 if xla_float32 else RSQRT_BOUND_EPS
    assert max(err) / eps <= bound, max(err) / eps


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_rsqrt_derivatives_and_nan(dtype):
    x = jnp.asarray([0.25, 1.0, 3.0, 1e6], dtype)
    g = jax.vmap(jax.grad(rsqrt))(x)
    want = -0.5 * np.asarray(x, np.float64) ** -1.5
    np.testing.assert_allclose(g, want, rtol=4 * np.finfo(dtype).eps)
    h = jax.grad(jax.grad(rsqrt))(jnp.asarray(4.0, dtype))
    np.testing.assert_allclose(h, 0.75 * 4.0**-2.5, rtol=8 * np.finfo(dtype).eps)
    assert np.isnan(rsqrt(jnp.asarray(np.nan, dtype)))


_hypot3 = jax.jit(lambda v: hypot(v[..., 0], v[..., 1], v[..., 2]))
_hypot3_grad = jax.jit(jax.vmap(jax.grad(lambda v: hypot(v[0], v[1], v[2]))))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_hypot_at_every_scale(dtype):
    """Within 2 eps of the true norm from the smallest normal to the largest finite scale
    (squares of either would underflow or overflow), gradient `v / |v|`; 0 with a zero gradient
    at the origin; NaN for an infinite or NaN component."""
    rng = np.random.default_rng(11)
    lo, hi = RANGE[dtype]
    v = rng.normal(size=(2000, 3)) * 10.0 ** rng.uniform(lo + 1, hi - 1, (2000, 1))
    v = v.astype(dtype)
    got = np.asarray(_hypot3(jnp.asarray(v)))
    with mp.workdps(40):
        err = [
            float(abs(mp.mpf(float(g)) / mp.sqrt(sum(mp.mpf(float(c)) ** 2 for c in x)) - 1))
            for g, x in zip(got, v, strict=True)
        ]
    assert max(err) <= 2 * np.finfo(dtype).eps, max(err) / np.finfo(dtype).eps
    g = np.asarray(_hypot3_grad(jnp.asarray(v)), np.float64)
    u = v / np.abs(v).max(axis=-1, keepdims=True)  # exact: the reference's squares stay finite
    want = u / np.linalg.norm(u.astype(np.float64), axis=-1, keepdims=True)
    np.testing.assert_allclose(g, want, atol=8 * np.finfo(dtype).eps)
    special = jnp.asarray([[0, 0, 0], [np.inf, 1, 0], [np.nan, 1, 0], [0, -np.inf, 0]], dtype)
    np.testing.assert_array_equal(_hypot3(special), [0, np.nan, np.nan, np.nan])
    np.testing.assert_array_equal(_hypot3_grad(special)[0], [0, 0, 0])


def test_hypot_rule_equals_autodiff_of_its_code():
    """The rule is JAX's derivative of the forward code (away from the underflow it avoids),
    to first and second order, at generic points, a zero component and the origin."""
    from rotjax._elementary import _hypot_parts

    def code(v):
        return _hypot_parts(tuple(v))[2]

    def rule(v):
        return hypot(*v)

    rng = np.random.default_rng(3)
    vs = [rng.normal(size=3) * 10.0**k for k in (-5, 0, 7)] + [np.array([0.0, 2.0, -1.0])]
    d = rng.normal(size=3)
    def along(f):
        return lambda v: jax.jvp(f, (v,), (d,))[1]

    # one program per function and order, called at every point
    pairs = [(jax.jit(along(rule)), jax.jit(along(code)))]
    pairs.append((jax.jit(along(along(rule))), jax.jit(along(along(code)))))
    for v in [*vs, np.zeros(3)]:
        for order, (f, g) in enumerate(pairs, 1):
            a, b = f(jnp.asarray(v)), g(jnp.asarray(v))
            np.testing.assert_allclose(a, b, rtol=1e-14, atol=0, err_msg=f"{v} order {order}")


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_reciprocal_is_within_one_ulp_and_exact_on_powers_of_two(dtype):
    rng = np.random.default_rng(11)
    lo, hi = RANGE[dtype]
    dense = rng.uniform(1.0, 2.0, 4000)  # one period of the initial guess's error
    wide = 10.0 ** rng.uniform(lo, -lo, 4000)  # 1 / x normal too
    twos = 2.0 ** np.arange(-100, 101)
    x = np.concatenate([dense, wide, twos, np.nextafter(twos, 0), np.nextafter(twos, 4)])
    x = x.astype(dtype)
    got = np.asarray(jax.jit(reciprocal)(jnp.asarray(x)))
    assert got.dtype == dtype
    with mp.workdps(40):
        exact = [1 / mp.mpf(float(a)) for a in x]
        ulps = [float(abs(mp.mpf(float(g)) - e)) for g, e in zip(got, exact, strict=True)]
    spacing = np.spacing(np.asarray([float(e) for e in exact], dtype))
    assert max(np.asarray(ulps) / spacing.astype(np.float64)) <= 1.0
    np.testing.assert_array_equal(got[8000 : 8000 + twos.size], (1 / twos).astype(dtype))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_reciprocal_derivatives_and_nan(dtype):
    x = jnp.asarray([0.25, 1.0, 3.0, 1e6], dtype)
    g = jax.vmap(jax.grad(reciprocal))(x)
    np.testing.assert_allclose(g, -1 / np.asarray(x, np.float64) ** 2, rtol=4 * np.finfo(dtype).eps)
    h = jax.grad(jax.grad(reciprocal))(jnp.asarray(4.0, dtype))
    np.testing.assert_allclose(h, 2 / 4.0**3, rtol=8 * np.finfo(dtype).eps)
    assert np.isnan(reciprocal(jnp.asarray(np.nan, dtype)))


@given(arrays(np.float64, (3, 3), elements=st.floats(-1e300, 1e300)))
def test_selected_column_norm_is_in_rsqrt_domain_for_any_finite_matrix(R):
    """rsqrt's domain in matrix_to_quaternion: after the power-of-two prescaling the selected
    column's squared norm is at least t^2 >= 1/12 and bounded, at any scale; NaN for zero.
    XLA flushes subnormals to zero, so a matrix of subnormal entries only is the zero matrix."""
    _, sq = selected_column(jnp.asarray(R))
    sq = np.asarray(sq).item()  # one rotation's per-rotation array, (1,)
    if not np.any(np.abs(R) >= np.finfo(np.float64).tiny):
        assert np.isnan(sq)
    else:
        assert 1 / 12 <= sq <= 400.0


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_exponent_scale_is_exact_and_clamped(dtype):
    info = np.finfo(dtype)
    rng = np.random.default_rng(3)
    e = rng.integers(info.minexp, info.maxexp - 1, 64)
    x = (rng.uniform(1, 2, 64) * 2.0**e).astype(dtype)
    x = np.concatenate([x, [info.tiny, info.max, 1.0, 0.5, 1.9999]]).astype(dtype)
    s, inv = (np.asarray(v) for v in exponent_scale(jnp.asarray(x)))
    assert np.all((np.abs(x * s) >= 1) & (np.abs(x * s) < 2) | (x == info.max)), x * s
    np.testing.assert_array_equal(s.astype(np.float64) * inv.astype(np.float64), 1.0)
    np.testing.assert_array_equal(np.frexp(s)[0], 0.5)  # powers of two: the product is exact
    odd = jnp.asarray([0.0, info.smallest_subnormal, np.inf, np.nan], dtype)
    s, inv = (np.asarray(v) for v in exponent_scale(odd))
    assert np.all(np.isfinite(s) & (s > 0) & np.isfinite(inv) & (inv > 0))
    assert np.isinf(np.asarray(odd)[2] * s[2])


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_scale_factors_of_several_components(dtype):
    """The factors of four components read off the bits of their largest magnitude: the same
    as of that magnitude as a float, for signed values, zeros, subnormals, infinities and NaN;
    ``unit_scale`` is 1 in ``[0.5, 2)`` and, with ``mark``, NaN where every component is zero
    or one is not finite (a non-rotation)."""
    info = np.finfo(dtype)
    special = [0.0, -0.0, info.smallest_subnormal, -info.tiny, 0.5, -1.9999, 2.0, info.max,
               -np.inf, np.nan, 3e-3, -7.0]  # fmt: skip
    rng = np.random.default_rng(5)
    x = rng.choice(np.asarray(special, dtype), size=(4, 512))
    x[:, :64] = 0.0  # whole quaternions of zeros
    x[:, 64:128] *= rng.uniform(0.5, 1.0, (4, 64)).astype(dtype)
    parts = [jnp.asarray(c) for c in x]
    big = np.max(np.abs(x), axis=0)  # NaN where a component is
    got = np.asarray(max_abs_bits(*parts)).view(dtype)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(big))
    np.testing.assert_array_equal(got[~np.isnan(big)], big[~np.isnan(big)])
    for a, b in zip(exponent_scale(*parts), exponent_scale(jnp.asarray(big)), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    s = np.asarray(unit_scale(*parts, mark=True))
    bad = (big == 0) | ~np.isfinite(big)
    assert np.isnan(s[bad]).all() and np.isfinite(s[~bad]).all()
    unit = (big >= 0.5) & (big < 2)
    np.testing.assert_array_equal(s[unit], 1.0)
    np.testing.assert_array_equal(np.asarray(unit_scale(*parts))[~bad], s[~bad])


def test_other_backends_use_xla_operations():
    """Lowered for a GPU (no GPU needed to lower), ``rsqrt``, ``reciprocal``, ``sin_cos`` and
    ``atan2`` are XLA's own operations; lowered for the CPU, the polynomial forms (no such
    operation)."""
    from jax import export

    def f(q, v):
        return rj.quaternion_to_euler(q, "ZYX"), rj.rotvec_to_quaternion(v)

    args = (jax.ShapeDtypeStruct((8, 4), jnp.float32), jax.ShapeDtypeStruct((8, 3), jnp.float32))
    ops = ("rsqrt", "atan2", "sine", "cosine")
    for platform, present in (("cuda", True), ("cpu", False)):
        text = export.export(jax.jit(f), platforms=[platform])(*args).mlir_module()
        for op in ops:
            assert (f"stablehlo.{op}" in text) == present, (platform, op)
        text = export.export(jax.jit(reciprocal), platforms=[platform])(args[0]).mlir_module()
        assert ("stablehlo.divide" in text) == present, (platform, "reciprocal")


_F32 = jnp.arange(6, dtype=jnp.float32).reshape(2, 3) - 2.5
_WHERE_ARGS = {
    "arrays": (_F32 > 0, _F32, -_F32),
    "number and array": (_F32 > 0, 0.0, _F32),
    "array and int": (_F32 > 0, _F32, 1),
    "broadcast condition": (jnp.array([True, False, True]), _F32, 2.0 * _F32),
    "broadcast value": (_F32 > 0, jnp.ones((3,), jnp.float32), _F32),
    "non-bool condition": (jnp.arange(3), _F32, 0.0),
}


@pytest.mark.parametrize("name", list(_WHERE_ARGS))
def test_where_is_jnp_where_without_a_nested_jit(name):
    args = _WHERE_ARGS[name]
    got, want = where(*args), jnp.where(*args)
    assert (got.dtype, got.shape, got.weak_type) == (want.dtype, want.shape, want.weak_type)
    np.testing.assert_array_equal(got, want)
    text = jax.jit(lambda c: where(c, *args[1:])).lower(args[0]).as_text()
    assert text.count("func.func") == 1


def test_where_of_two_numbers_asks_for_their_type():
    with pytest.raises(TypeError, match="select"):
        where(_F32 > 0, 1.0, 0.0)


@pytest.mark.parametrize("dtype", [jnp.bfloat16, jnp.float16, jnp.float32, jnp.float64])
def test_signbit_is_jnp_signbit(dtype):
    x = jnp.asarray([0.0, -0.0, 1.5, -1.5, jnp.inf, -jnp.inf, jnp.nan, -jnp.nan, 1e-40], dtype)
    np.testing.assert_array_equal(signbit(x), jnp.signbit(x))
