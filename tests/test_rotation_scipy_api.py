"""Rotation's scipy API details a ported script depends on: tolerances that follow the dtype,
scipy's random streams, the newest scipy's constructors."""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation as SR

from rotjax import Rotation


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_approx_equal_default_follows_dtype(dtype):
    q = np.random.default_rng(20).normal(size=(1000, 4)).astype(dtype)
    r = Rotation.from_quat(q)
    assert bool(jnp.all(r.approx_equal(r)))
    # round trips through other representations, in the same precision
    assert bool(jnp.all(r.approx_equal(Rotation.from_matrix(r.as_matrix()))))
    assert bool(jnp.all(r.approx_equal(Rotation.from_rotvec(r.as_rotvec()))))
    # ... and still tells different rotations apart: a turn of 1e-3 rad is not equal
    turned = r * Rotation.from_rotvec(np.asarray([1e-3, 0, 0], dtype))
    assert not bool(jnp.any(r.approx_equal(turned)))
    atol = 1e-8 if dtype == jnp.float64 else 1e-8 * np.sqrt(2.0**-23 / 2.0**-52)
    just_in = r * Rotation.from_rotvec(np.asarray([0.5 * atol, 0, 0], np.float64).astype(dtype))
    if dtype == jnp.float64:
        assert bool(jnp.all(r.approx_equal(just_in)))
        just_out = r * Rotation.from_rotvec(np.asarray([2 * atol, 0, 0]))
        assert not bool(jnp.any(r.approx_equal(just_out)))
        # scipy's default, unchanged in float64
        np.testing.assert_array_equal(
            r.approx_equal(just_out), SR.from_quat(q).approx_equal(SR.from_quat(just_out.as_quat()))
        )


def test_approx_equal_default_with_degrees_warns_with_the_value():
    r = Rotation.from_quat(np.asarray([0.0, 0, 0, 1], np.float32))
    with pytest.warns(UserWarning, match="atol must be set.*0.000232"):
        assert bool(r.approx_equal(r, degrees=True))


def test_random_state_matches_scipy_legacy_stream():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        for seed in (0, 7):
            np.testing.assert_allclose(
                Rotation.random(4, random_state=seed).as_quat(),
                SR.random(4, random_state=seed).as_quat(),
                atol=1e-15,
            )
        # a RandomState is drawn from as it is (its state advances, as scipy's)
        a, b = np.random.RandomState(3), np.random.RandomState(3)
        for _ in range(2):
            np.testing.assert_allclose(
                Rotation.random(3, random_state=a).as_quat(),
                SR.random(3, random_state=b).as_quat(),
                atol=1e-15,
            )
        # a Generator given as random_state, and rng= (a seed for default_rng)
        np.testing.assert_allclose(
            Rotation.random(2, random_state=np.random.default_rng(5)).as_quat(),
            SR.random(2, random_state=np.random.default_rng(5)).as_quat(),
            atol=1e-15,
        )
    np.testing.assert_allclose(
        Rotation.random(3, rng=7).as_quat(), SR.random(3, rng=7).as_quat(), atol=1e-15
    )
    # neither: NumPy's global RandomState, as scipy
    np.random.seed(11)  # noqa: NPY002 (scipy draws from the global RandomState)
    ours = Rotation.random(2).as_quat()
    np.random.seed(11)  # noqa: NPY002 (scipy draws from the global RandomState)
    np.testing.assert_allclose(ours, SR.random(2).as_quat(), atol=1e-15)
    with pytest.raises(TypeError, match="multiple values"):
        Rotation.random(2, rng=1, random_state=1)
    # a JAX key in either place
    k = jax.random.key(1)
    np.testing.assert_array_equal(Rotation.random(k, 3).as_quat(), Rotation.random(3, k).as_quat())


def test_identity_and_random_shape_validation():
    assert Rotation.identity(shape=()).as_quat().shape == (4,)
    assert Rotation.identity(shape=5).as_quat().shape == (5, 4)
    assert Rotation.random(shape=(2, 3), rng=0).as_quat().shape == (2, 3, 4)
    np.testing.assert_array_equal(
        Rotation.identity(shape=(2, 2)).as_quat().reshape(-1, 4), np.tile([0.0, 0, 0, 1], (4, 1))
    )
    for f in (Rotation.identity, Rotation.random):
        with pytest.raises(ValueError, match="`shape` must be an int or a tuple of ints"):
            f(shape=2.5)
        with pytest.raises(ValueError, match="Only one of `num` or `shape`"):
            f(num=3, shape=(2, 2))
    with pytest.raises(TypeError, match="takes from 0 to 1 positional arguments"):
        Rotation.identity(3, 3)
    assert Rotation.identity(3, jnp.float32).as_quat().dtype == jnp.float32  # jax.scipy's form


@pytest.mark.parametrize("xp", [np, jnp])
def test_empty_batches_construct(xp):
    z3, z4 = xp.zeros((0, 3)), xp.zeros((0, 4))
    built = [
        Rotation.random(num=0),
        Rotation.identity(num=0),
        Rotation.random(num=3, rng=0)[[]],
        Rotation.from_quat(z4),
        Rotation.from_matrix(xp.zeros((0, 3, 3))),
        Rotation.from_matrix(xp.zeros((0, 3, 3)), assume_valid=True),
        Rotation.from_euler("xyz", z3),
        Rotation.from_rotvec(z3),
        Rotation.from_davenport(xp.eye(3), "extrinsic", z3),
        Rotation.from_mrp(z3),
    ]
    for r in built:
        assert len(r) == 0 and r.as_matrix().shape == (0, 3, 3)


@pytest.mark.slow
def test_constant_attitude_spline_has_exactly_zero_rates():
    from rotjax import RotationSpline

    @jax.jit  # the spline's construction and its three evaluations: one program
    def evaluate(rotvecs, t):
        spline = RotationSpline(jnp.arange(10.0), Rotation.from_rotvec(rotvecs))
        return spline(t, 1), spline(t, 2), spline(t).as_rotvec()

    rate, acceleration, rotvec = evaluate(np.ones((10, 3)), np.linspace(-1, 11))
    np.testing.assert_array_equal(rate, 0)
    np.testing.assert_array_equal(acceleration, 0)
    np.testing.assert_allclose(rotvec, 1, rtol=1e-15)
    # the keyframes' derivative is kept where they are equal (not a silent zero)
    q = Rotation.from_rotvec(np.ones((3, 3))).as_quat()
    spline_rate = lambda q: RotationSpline(jnp.arange(3.0), Rotation.from_quat(q))(0.5, 1)[0]  # noqa: E731
    g = jax.jit(jax.grad(spline_rate))(q)
    assert np.all(np.isfinite(g)) and np.any(g != 0)
