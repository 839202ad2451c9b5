"""RigidTransform and normalize_dual_quaternion: scipy as the oracle, the pytree contract
(jit, vmap, scan, grad, one tree structure), derivatives at the singular points."""

from __future__ import annotations

import pickle

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import (
    assert_close,
    assert_same_rotation,
    check_grads,
    check_hessian,
    hessian_rows,
    jacobian_rows,
)
from hypothesis import example, given
from hypothesis import strategies as st
from scipy.spatial.transform import RigidTransform as SciTf
from scipy.spatial.transform import Rotation as SciRot
from scipy.spatial.transform._rigid_transform import normalize_dual_quaternion as sci_normalize

import rotjax as rj
from rotjax import RigidTransform as Tf

SHAPES = [(), (1,), (5,), (2, 3)]


def _data(shape, seed=0, scale=1.0):
    rng = np.random.default_rng(seed)
    return rng.normal(size=shape + (4,)), scale * rng.normal(size=shape + (3,))


def _pair(shape, seed=0, scale=1.0):
    """The same transforms in rotjax and scipy (scipy's classes take at most one batch axis
    in its Cython backend, so they are built flat and compared flat)."""
    q, t = _data(shape, seed, scale)
    ours = Tf.from_components(t, rj.Rotation.from_quat(q))
    theirs = SciTf.from_components(t.reshape(-1, 3), SciRot.from_quat(q.reshape(-1, 4)))
    return ours, theirs, q, t


def _flat(x, trailing):
    x = np.asarray(x)
    return x.reshape((-1,) + x.shape[x.ndim - trailing :])


def _last(dq, scalar_first):
    """Both parts of dual quaternions scalar last."""
    dq = np.asarray(dq)
    if not scalar_first:
        return dq
    return np.concatenate([np.roll(dq[..., :4], -1, -1), np.roll(dq[..., 4:], -1, -1)], -1)


def _dq_sign(dq):
    """Dual quaternions with the sign fixed by the real part's w (double cover)."""
    dq = np.asarray(dq)
    return dq * np.where(dq[..., 3:4] < 0, -1.0, 1.0)


# --- scipy as the oracle -----------------------------------------------------------------


@pytest.mark.parametrize("shape", SHAPES)
def test_conversions_match_scipy(shape):
    ours, theirs, q, t = _pair(shape, seed=1)
    assert ours.shape == shape and ours.single == (shape == ())
    assert_close(_flat(ours.as_matrix(), 2), theirs.as_matrix().reshape(-1, 4, 4), atol=1e-15)
    assert_close(_flat(ours.as_exp_coords(), 1), theirs.as_exp_coords().reshape(-1, 6), atol=2e-15)
    for sf in (False, True):
        mine = _last(_flat(ours.as_dual_quat(scalar_first=sf), 1), sf)
        ref = _last(theirs.as_dual_quat(scalar_first=sf).reshape(-1, 8), sf)
        assert_close(_dq_sign(mine), _dq_sign(ref), atol=1e-15)
    tt, rr = ours.as_components()
    assert_close(tt, t, atol=0)
    assert_same_rotation(rr.as_quat(), q / np.linalg.norm(q, axis=-1, keepdims=True), atol=1e-15)


def _mp_exp_translation(xi, dps=40):
    """`V(w) v` of the SE(3) exponential of `(w, v)` in mpmath: `V = I + b W + c W^2` with
    `b = (1 - cos t) / t^2`, `c = (t - sin t) / t^3` (at `t = 0`: 1/2 and 1/6)."""
    import mpmath as mp

    with mp.workdps(dps):
        w = [mp.mpf(float(x)) for x in xi[:3]]
        v = mp.matrix([mp.mpf(float(x)) for x in xi[3:]])
        t = mp.sqrt(sum(x * x for x in w))
        b = (1 - mp.cos(t)) / t**2 if t else mp.mpf(1) / 2
        c = (t - mp.sin(t)) / t**3 if t else mp.mpf(1) / 6
        W = mp.matrix([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
        out = (mp.eye(3) + b * W + c * W * W) * v
        return np.array([float(x) for x in out])


@given(
    xi=st.lists(st.floats(-10, 10), min_size=6, max_size=6),
    scale=st.sampled_from([1e-9, 1e-4, 0.05, 0.1, 0.2, 1.0]),
)
@example(xi=[0.0, 9.6875, 3.0, 0.0, 0.0, 1.0], scale=1e-4)  # scipy's translation: 7e-11 off
def test_exp_coords_match_scipy(xi, scale):
    """Both maps against scipy, at tiny rotation angles, near the series cut (angle 1) and
    past pi. The translation of the exponential is judged by mpmath: scipy's closed form of
    `(1 - cos t) / t^2` loses digits at small angles (7e-11 relative at an angle of 1e-3)."""
    xi = np.asarray(xi)
    xi[:3] *= scale
    m = np.asarray(Tf.from_exp_coords(xi).as_matrix())
    ref = SciTf.from_exp_coords(xi).as_matrix()
    ref[:3, 3] = _mp_exp_translation(xi)
    assert_close(m, ref, atol=1e-14 * (1 + np.abs(xi).max()))
    m_ref = SciTf.from_exp_coords(xi)
    assert_close(
        Tf.from_matrix(m_ref.as_matrix()).as_exp_coords(),
        m_ref.as_exp_coords(),
        atol=1e-13 * (1 + np.abs(xi).max()),
    )


@pytest.mark.parametrize("shape", SHAPES)
def test_operations_match_scipy(shape):
    ours, theirs, _, _ = _pair(shape, seed=2)
    other, theirs2, _, _ = _pair(shape, seed=3)
    flat = lambda tf: _flat(tf.as_matrix(), 2)  # noqa: E731
    assert_close(flat(ours * other), (theirs * theirs2).as_matrix().reshape(-1, 4, 4), atol=1e-14)
    assert_close(flat(ours.inv()), theirs.inv().as_matrix().reshape(-1, 4, 4), atol=1e-14)
    v = np.random.default_rng(4).normal(size=shape + (3,))
    for inverse in (False, True):
        assert_close(
            _flat(ours.apply(v, inverse=inverse), 1),
            theirs.apply(v.reshape(-1, 3), inverse=inverse).reshape(-1, 3),
            atol=1e-14,
        )
    # One transform applied to many vectors (the matrix path) and many to one.
    many = np.random.default_rng(5).normal(size=(7, 3))
    one = ours if ours.single else ours[(0,) * len(shape)]
    one_s = theirs if ours.single else theirs[0]
    for inverse in (False, True):
        assert_close(
            one.apply(many, inverse=inverse), one_s.apply(many, inverse=inverse), atol=1e-14
        )
        assert_close(
            _flat(ours.apply(many[0], inverse=inverse), 1),
            theirs.apply(many[0], inverse=inverse).reshape(-1, 3),
            atol=1e-14,
        )
    for n in (0, 1, -1, 2, 0.5, -1.5, 3.7):
        # scipy's definition of the power (its Array API backend): exp(n log T).
        ref = SciTf.from_exp_coords(n * theirs.as_exp_coords())
        assert_close(flat(ours**n), ref.as_matrix().reshape(-1, 4, 4), atol=1e-13)
    assert_close(ours.mean().as_matrix(), theirs.mean().as_matrix(), atol=1e-14)


def test_power_special_cases_and_traced_exponent():
    ours, _, _, _ = _pair((4,), seed=6)
    assert_close((ours**0).as_matrix(), np.broadcast_to(np.eye(4), (4, 4, 4)), atol=0)
    assert_close((ours**1).as_matrix(), ours.as_matrix(), atol=1e-14)
    assert_close((ours**-1).as_matrix(), ours.inv().as_matrix(), atol=1e-14)
    f = jax.jit(lambda tf, n: (tf**n).as_matrix())
    assert_close(f(ours, 2.0), (ours * ours).as_matrix(), atol=1e-14)
    assert_close(f(ours, jnp.array([0.5])), (ours**0.5).as_matrix(), atol=1e-15)
    with pytest.raises(ValueError, match="scalar"):
        ours ** jnp.ones(2)


@pytest.mark.parametrize("axis", [None, 0, 1, (0, 1), -1])
def test_mean_matches_scipy(axis):
    q, t = _data((3, 4), seed=7)
    w = np.random.default_rng(8).random((3, 4))
    ours = Tf.from_components(t, rj.Rotation.from_quat(q))
    theirs = SciTf.from_components(t, SciRot.from_quat(q))
    for weights in (None, w):
        got = ours.mean(weights=weights, axis=axis)
        ref = theirs.mean(weights=weights, axis=axis)
        assert got.shape == ref.shape
        assert_close(got.translation, ref.translation, atol=1e-14)
        assert_same_rotation(got.rotation.as_quat(), ref.rotation.as_quat(), atol=1e-13)
    with pytest.raises(ValueError, match="non-negative"):
        ours.mean(weights=-w)
    with pytest.raises(ValueError, match="Expected `weights` to"):
        ours.mean(weights=w[0])
    # JAX weights: a negative one gives NaN in its own set only.
    bad = jnp.asarray(w).at[1, 2].set(-1.0)
    got = np.asarray(ours.mean(weights=bad, axis=1).as_matrix())
    assert np.isnan(got[1]).all() and np.isfinite(got[[0, 2]]).all()


@given(
    dq=st.lists(st.floats(-3, 3), min_size=8, max_size=8),
    scalar_first=st.booleans(),
)
def test_dual_quat_matches_scipy(dq, scalar_first):
    dq = np.asarray(dq)
    ref = sci_normalize(_last(dq, scalar_first))
    got = _last(rj.normalize_dual_quaternion(dq, scalar_first=scalar_first), scalar_first)
    real = _last(dq, scalar_first)[:4]
    tiny = np.finfo(np.float64).tiny
    if tiny <= np.abs(real).max() and np.sum(real * real) < tiny:
        # scipy's |real|^2 underflows and it returns the identity; rotjax prescales, so its
        # real part is the direction of the given one. (A real part of subnormal numbers only
        # is zero to XLA on the CPU, which flushes subnormals: scipy's identity, as below.)
        unit = real / np.abs(real).max()
        assert_close(got[:4], unit / np.linalg.norm(unit), atol=1e-15)
        return
    # Rounding at the scale of the dual part divided by |real| (before its component along the
    # real part is removed), however small |real|; a zero real part divides by 1.
    n = np.linalg.norm(real) if np.abs(real).max() >= tiny else 1.0
    assert_close(got, ref, atol=1e-14 * (1 + np.abs(dq).max() / n))
    if np.linalg.norm(dq[:4]) > 1e-3:
        tf = Tf.from_dual_quat(dq, scalar_first=scalar_first)
        assert_close(
            tf.as_matrix(),
            SciTf.from_dual_quat(dq, scalar_first=scalar_first).as_matrix(),
            atol=1e-13 * (1 + np.abs(dq[4:]).max() / np.linalg.norm(dq[:4])),
        )


def test_from_matrix_validation():
    m = np.eye(4)
    m[:3, :3] *= 2  # scaled: the nearest rotation is the identity
    assert_close(Tf.from_matrix(m).as_matrix(), np.eye(4), atol=1e-15)
    bad_row = np.eye(4)
    bad_row[3, 0] = 1.0
    with pytest.raises(ValueError, match="last row of transformation matrix"):
        Tf.from_matrix(bad_row)
    left = np.diag([-1.0, 1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="Non-positive determinant"):
        Tf(left, normalize=True)
    with pytest.raises(ValueError, match="Expected `matrix` to have shape"):
        Tf.from_matrix(np.eye(3))
    # JAX input: NaN in the bad transform only (its whole matrix, last row included).
    stack = jnp.stack([jnp.eye(4), jnp.asarray(bad_row), jnp.asarray(left), jnp.eye(4)])
    out = np.asarray(Tf.from_matrix(stack).as_matrix())
    assert np.isnan(out[1]).all() and np.isnan(out[2, :3, :3]).all()
    assert np.isnan(out[2, 3]).all()
    assert_close(out[[0, 3]], np.broadcast_to(np.eye(4), (2, 4, 4)), atol=0)


def test_rotation_on_either_side():
    ours, theirs, _, _ = _pair((3,), seed=9)
    q = np.random.default_rng(10).normal(size=(3, 4))
    r, r_s = rj.Rotation.from_quat(q), SciRot.from_quat(q)
    r_tf = SciTf.from_rotation(r_s)
    left = r * ours
    right = ours * r
    assert isinstance(left, Tf) and isinstance(right, Tf)
    assert_close(left.as_matrix(), (r_tf * theirs).as_matrix(), atol=1e-14)
    assert_close(right.as_matrix(), (theirs * r_tf).as_matrix(), atol=1e-14)
    with pytest.raises(TypeError):
        ours * 2.0
    with pytest.raises(ValueError, match="Cannot broadcast"):
        ours * Tf.identity(2)


# --- scipy's container behaviour ----------------------------------------------------------


def test_shapes_indexing_setitem_iter():
    tf = Tf.from_translation(np.arange(12.0).reshape(4, 3))
    assert len(tf) == 4 and tf.shape == (4,) and not tf.single
    assert tf[1].single and tf[1:3].shape == (2,) and tf[[True, False, True, False]].shape == (2,)
    assert tf[np.array([3, 0])].shape == (2,)
    assert_close(tf[-1].translation, [9.0, 10, 11], atol=0)
    assert [x.translation.tolist() for x in tf][2] == [6.0, 7.0, 8.0]
    with pytest.raises(IndexError):
        tf[4]
    with pytest.raises(IndexError):
        tf[[0, 7]]
    single = Tf.identity()
    for bad in (lambda: single[0], lambda: len(single), lambda: iter(single)):
        with pytest.raises(TypeError):
            bad()
    before = jax.tree_util.tree_leaves(tf)
    tf[1:3] = Tf.from_translation([[1.0, 1, 1], [2, 2, 2]])
    tf[0] = Tf.from_rotation(rj.Rotation.from_rotvec([0.0, 0.0, 1.0]))
    assert_close(tf.translation, [[0.0, 0, 0], [1, 1, 1], [2, 2, 2], [9, 10, 11]], atol=0)
    assert_close(tf[0].rotation.as_rotvec(), [0.0, 0.0, 1.0], atol=1e-15)
    assert_close(before[1], np.arange(12.0).reshape(4, 3), atol=0)  # the old leaf is intact
    with pytest.raises(TypeError, match="value must be a RigidTransform"):
        tf[0] = np.eye(4)
    grid = Tf.identity(shape=(2, 3))
    assert grid.shape == (2, 3) and grid[1, 2].single and grid[:, 0].shape == (2,)
    assert grid[..., 1].shape == (2,)


def test_empty_and_concatenate():
    empty = Tf.from_matrix(np.empty((0, 4, 4)))
    assert len(empty) == 0 and empty.as_exp_coords().shape == (0, 6)
    assert empty.apply(np.zeros(3)).shape == (0, 3)
    assert len(empty * Tf.identity()) == 0 and len(empty**0.5) == 0
    with pytest.raises(IndexError):
        empty[0]
    a = Tf.from_translation([1.0, 0, 0])
    both = Tf.concatenate([a, Tf.identity(2), empty])
    assert both.shape == (3,)
    assert_close(both.translation, [[1.0, 0, 0], [0, 0, 0], [0, 0, 0]], atol=0)
    assert Tf.concatenate(a).single
    with pytest.raises(TypeError, match="RigidTransform objects only"):
        Tf.concatenate([a, np.eye(4)])


def test_identity_arguments():
    assert Tf.identity().single and Tf.identity(3).shape == (3,)
    assert Tf.identity(shape=4).shape == (4,)
    assert Tf.identity(dtype=jnp.float32).as_matrix().dtype == jnp.float32
    with pytest.raises(ValueError, match="Only one of"):
        Tf.identity(2, shape=(2,))
    with pytest.raises(ValueError, match="`shape` must be"):
        Tf.identity(shape="x")
    with pytest.raises(TypeError):
        Tf.identity(None, (2,))


def test_pickle_and_repr():
    ours, _, _, _ = _pair((2,), seed=11)
    back = pickle.loads(pickle.dumps(ours))
    assert_close(back.as_matrix(), ours.as_matrix(), atol=0)
    assert repr(Tf.identity()) == repr(SciTf.identity())
    assert repr(Tf.identity(2)) == repr(SciTf.identity(2))


def test_dtype_kept():
    q, t = _data((3,), seed=12)
    tf = Tf.from_components(t.astype(np.float32), rj.Rotation.from_quat(q.astype(np.float32)))
    for out in (
        tf.as_matrix(),
        tf.as_exp_coords(),
        tf.as_dual_quat(),
        tf.apply(np.ones(3)),
        (tf * tf).as_matrix(),
        (tf**0.5).as_matrix(),
        tf.mean().as_matrix(),
        tf.inv().translation,
    ):
        assert out.dtype == jnp.float32
    assert Tf.from_translation([1, 2, 3]).translation.dtype == jnp.float64


# --- pytree contract ----------------------------------------------------------------------


def test_one_tree_structure_for_every_constructor():
    q, t = _data((2,), seed=13)
    r = rj.Rotation.from_quat(q)
    m = np.asarray(Tf.from_components(t, r).as_matrix())
    builders = [
        lambda: Tf(m),
        lambda: Tf(m, normalize=False),
        lambda: Tf.from_matrix(jnp.asarray(m)),
        lambda: Tf.from_rotation(r),
        lambda: Tf.from_rotation(rj.Rotation.from_matrix(m[:, :3, :3])),
        lambda: Tf.from_translation(t),
        lambda: Tf.from_components(t, r),
        lambda: Tf.from_exp_coords(np.ones((2, 6))),
        lambda: Tf.from_dual_quat(np.ones((2, 8))),
        lambda: Tf.identity(2),
        lambda: Tf.concatenate([Tf.identity(), Tf.identity()]),
        lambda: Tf.identity(2) * Tf.identity(2),
        lambda: r * Tf.identity(2),
        lambda: Tf.identity(2) ** 0.5,
        lambda: Tf.identity(2).inv(),
        lambda: Tf.identity(shape=(2, 2)).mean(axis=0),
        lambda: Tf.identity(5)[[0, 1]],
        lambda: jax.jit(lambda x: x)(Tf.identity(2)),
    ]
    # Traced, not run (structure and shapes are fixed by tracing); pickling needs values.
    made = [jax.eval_shape(b) for b in builders]
    made.append(pickle.loads(pickle.dumps(Tf.identity(2))))
    ref = jax.tree_util.tree_structure(made[0])
    for tf in made:
        assert jax.tree_util.tree_structure(tf) == ref
        assert [x.shape for x in jax.tree_util.tree_leaves(tf)] == [(2, 4), (2, 3)]


def test_jit_vmap_scan():
    ours, _, _, _ = _pair((6,), seed=14)
    out = jax.jit(lambda tf: tf * tf)(ours)
    assert isinstance(out, Tf)
    assert_close(out.as_matrix(), (ours * ours).as_matrix(), atol=1e-15)
    v = np.random.default_rng(15).normal(size=(6, 3))
    mapped = jax.vmap(lambda tf, x: tf.apply(x))(ours, v)
    assert_close(mapped, ours.apply(v), atol=1e-15)
    made = jax.vmap(Tf.from_exp_coords)(jnp.asarray(ours.as_exp_coords()))
    assert isinstance(made, Tf) and made.shape == (6,)
    assert_close(made.as_matrix(), ours.as_matrix(), atol=1e-14)

    def step(carry, tf):
        return carry * tf, carry.translation

    final, trail = jax.lax.scan(step, Tf.identity(), ours)
    expect = Tf.identity()
    for tf in ours:
        expect = expect * tf
    assert_close(final.as_matrix(), expect.as_matrix(), atol=1e-14)
    assert trail.shape == (6, 3)


def test_grad_flows_through_methods():
    """jax.grad of a pose-fitting loss through from_exp_coords, *, inv and apply, against
    central differences."""
    rng = np.random.default_rng(16)
    pts = rng.normal(size=(5, 3))
    target = Tf.from_exp_coords(rng.normal(size=6))

    def loss(xi):
        tf = Tf.from_exp_coords(xi)
        d = (target.inv() * tf).apply(pts) - pts
        return jnp.sum(d * d)

    x0 = rng.normal(size=6)
    g = np.asarray(jax.grad(loss)(jnp.asarray(x0)))
    h = 1e-6
    fd = [(loss(x0 + h * e) - loss(x0 - h * e)) / (2 * h) for e in np.eye(6)]
    assert_close(g, fd, rtol=1e-6, atol=1e-7)


# --- derivatives at the singular points -----------------------------------------------------

AXIS = np.array([0.36, -0.48, 0.8])
SINGULAR = {
    "zero": np.zeros(3),
    "tiny": 1e-300 * AXIS,
    "small": 1e-9 * AXIS,
    "threshold": 1.0 * AXIS,  # |AXIS| = 1: the series cut t^2 = 1
    "pi": np.pi * AXIS,
    "x_pi": np.array([np.pi, 0.0, 0.0]),
    "two_pi": 2 * np.pi * AXIS,
}


def _at(wheres):
    """The poses of SINGULAR's rotation vectors at ``wheres``, with one translation, stacked."""
    w = np.stack([SINGULAR[k] for k in wheres])
    return jnp.asarray(np.concatenate([w, np.broadcast_to([0.3, -1.2, 2.0], w.shape)], -1))


def _pose_matrix(x):
    return Tf.from_exp_coords(x).as_matrix()


def _pose_log(x):
    return Tf.from_exp_coords(x).as_exp_coords()


# Slow: second-order programs of the pose (test_se3 checks the same coordinates'
# functions at their singular points by default).
@pytest.mark.slow
def test_exp_derivatives_finite_and_right():
    """At every point of SINGULAR (0, 1e-300, tiny, the series cut, pi, two pi): first and
    second derivatives of the pose matrix agree with finite differences (helpers.check_hessian
    on the batch of all points: its elementwise tolerances judge each point's rows), the
    Jacobian and the Hessian of a sum of cubes are finite."""
    xi = _at(SINGULAR)
    check_hessian(_pose_matrix, xi, atol=1e-6, rtol=1e-6)
    # one program: the Jacobian and jax.hessian's forward-over-reverse Hessian (of each
    # point's sum of cubes: the sum over the points separates)
    cubes = jax.grad(lambda x: jnp.sum(_pose_matrix(x) ** 3))
    jac, hess = jacobian_rows(lambda x: (_pose_matrix(x), cubes(x)), xi)
    assert np.all(np.isfinite(np.asarray(jac)))
    assert np.all(np.isfinite(np.asarray(hess)))


@pytest.mark.slow  # as test_exp_derivatives_finite_and_right
def test_log_derivatives_finite_and_exact():
    """log(exp(xi)) = xi for angles up to pi (0, 1e-300, tiny, the series cut, pi, x pi): its
    Jacobian is the identity, exactly at 0 and at 180 degrees too (the derivative of the
    formula computed), by forward and by reverse mode; its second derivative is finite, and
    zero away from the series cut; away from pi (where finite differences cross the log's cut)
    the Jacobians and the Hessian against finite differences at those points."""
    wheres = ["zero", "tiny", "small", "threshold", "pi", "x_pi"]
    xi = _at(wheres)

    # one program: the value, both Jacobians and jax.hessian's forward-over-reverse Hessian
    value, fwd, back, second = hessian_rows(_pose_log, xi)
    assert_close(value, xi, atol=1e-15 * 4)
    eye = np.broadcast_to(np.eye(6), (len(wheres), 6, 6))
    assert_close(fwd, eye, atol=4e-15)
    assert_close(back, eye, atol=4e-15)
    second = np.asarray(second)
    assert np.all(np.isfinite(second))
    for where, s in zip(wheres, second, strict=True):
        if where != "threshold":
            assert_close(s, np.zeros((6, 6, 6)), atol=2e-14, err_msg=where)
    away = _at([w for w in wheres if "pi" not in w])
    check_hessian(_pose_log, away, atol=1e-6, rtol=1e-6)


def test_derivative_at_identity_is_the_hat_map():
    f = lambda x: Tf.from_exp_coords(x).as_matrix()  # noqa: E731
    jac = np.asarray(jax.jacfwd(f)(jnp.zeros(6)))
    for i in range(6):
        e = np.zeros(6)
        e[i] = 1
        expect = np.zeros((4, 4))
        expect[:3, :3] = np.asarray(rj._numerics.skew(jnp.asarray(e[:3])))
        expect[:3, 3] = e[3:]
        assert_close(jac[..., i], expect, atol=0)


def test_grad_of_as_exp_coords_wrt_the_transform_at_identity_and_pi():
    """d log(T exp(d)) / dd at d = 0 is the inverse right Jacobian: the identity at T = I and
    finite at a half turn."""

    def right(tf):
        return lambda d: (tf * Tf.from_exp_coords(d)).as_exp_coords()

    jac = np.asarray(jax.jacfwd(right(Tf.identity()))(jnp.zeros(6)))
    assert_close(jac, np.eye(6), atol=0)
    half = Tf.from_exp_coords(np.concatenate([np.pi * AXIS, [1.0, 2.0, 3.0]]))
    jac = np.asarray(jax.jacfwd(right(half))(jnp.zeros(6)))
    assert np.all(np.isfinite(jac))
    # Central differences agree in directions that keep the angle below pi.
    h = 1e-7
    f = right(half)
    for i in range(3, 6):
        e = np.zeros(6)
        e[i] = h
        fd = (np.asarray(f(e)) - np.asarray(f(-e))) / (2 * h)
        assert_close(jac[:, i], fd, atol=1e-6)


def test_dual_quat_normalization_gradient_at_zero_real_part():
    g = jax.jacfwd(lambda d: rj.normalize_dual_quaternion(d))(jnp.zeros(8))
    assert np.all(np.isfinite(np.asarray(g)))


@pytest.mark.parametrize("scale", [1e-200, 1e-30, 1e30, 1e200])
def test_dual_quat_normalization_at_any_scale(scale):
    """Both parts scaled alike describe the same transform: |real|^2 must not overflow or
    underflow (it did, unscaled, beyond 1e+-154)."""
    dq = np.random.default_rng(17).normal(size=(4, 8))
    ref = sci_normalize(dq)
    assert_close(rj.normalize_dual_quaternion(dq * scale), ref, atol=1e-15)
    assert_close(
        Tf.from_dual_quat(dq * scale).as_matrix(), SciTf.from_dual_quat(dq).as_matrix(), atol=1e-14
    )


def _projected_log(m):
    return Tf.from_matrix(m).as_exp_coords()


def _projected_log_of_top(top):
    """``_projected_log`` of ``[[top], [0, 0, 0, 1]]``: every other last row gives NaN, so the
    finite differences move the top 3x4 block only."""
    row = jnp.broadcast_to(jnp.array([0.0, 0.0, 0.0, 1.0], top.dtype), (*top.shape[:-2], 1, 4))
    return _projected_log(jnp.concatenate([top, row], axis=-2))


def test_projecting_from_matrix_gradient_is_the_derivative():
    """The derivative of ``from_matrix(T).as_exp_coords()`` (the projection onto SO(3), then
    the logarithm) in every direction of the top 3x4 block, against finite differences, forward
    and reverse, in one batch: on SO(3) (a generic pose, the identity, a half turn) and off it
    (a noisy block, and a scaled one). An element with a last row other than [0, 0, 0, 1] is
    NaN, and its gradient 0, not NaN, without touching the others."""
    rng = np.random.default_rng(7)
    R = rj.rotvec_to_matrix(np.array([[0.3, -0.5, 0.9], [0.0, 0.0, 0.0], [0.0, 0.0, 3.0]]))
    blocks = np.concatenate(
        [np.asarray(R), np.asarray(R[:1]) + 0.05 * rng.normal(size=(1, 3, 3)), 2.5 * R[:1]]
    )
    m = np.zeros((len(blocks), 4, 4))
    m[:, :3, :3] = blocks
    m[:, :3, 3] = rng.normal(size=(len(blocks), 3))
    m[:, 3, 3] = 1.0
    top = jnp.asarray(m[:, :3])
    check_grads(_projected_log_of_top, (top,), order=1, modes=("fwd", "rev"), atol=1e-6)
    bad = m.copy()
    bad[0, 3, 0] = 1.0
    out = np.asarray(_projected_log(jnp.asarray(bad)))
    grad = np.asarray(jax.grad(lambda x: jnp.sum(_projected_log(x)[1:]))(jnp.asarray(bad)))
    assert np.all(np.isnan(out[0])) and np.all(np.isfinite(out[1:]))
    assert np.all(np.isfinite(grad)) and np.all(grad[0] == 0) and np.any(grad[1:] != 0)
