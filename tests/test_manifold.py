"""rotjax.manifold: right perturbations on pytrees of rotations, rigid transforms and arrays,
the tangent-space gradient, and an optax optimiser stepping on the group."""

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
from helpers import assert_close, random_quaternions, sweep
from scipy.spatial.transform import RigidTransform as SRigid
from scipy.spatial.transform import Rotation as SRotation

import rotjax as rj
from rotjax import manifold

RNG = np.random.default_rng(35)
Q = random_quaternions(6, seed=35)
# by scipy: a rotjax call here would compile at collection, in every worker
XI = np.concatenate([SRotation.from_quat(Q[:4]).as_rotvec(), RNG.normal(size=(4, 3))], axis=-1)


def _params(dtype=np.float64):
    return {
        "rot": rj.Rotation.from_quat(Q.astype(dtype)),
        "pose": [rj.RigidTransform.from_exp_coords(XI[0].astype(dtype))],
        "poses": rj.RigidTransform.from_exp_coords(XI.reshape(2, 2, 6).astype(dtype)),
        "bias": jnp.arange(3, dtype=dtype),
    }


def _random_tangents(x, scale, seed):
    rng = np.random.default_rng(seed)
    zeros = manifold.zero_tangents(x)
    return jax.tree.map(lambda z: jnp.asarray(scale * rng.normal(size=z.shape), z.dtype), zeros)


@pytest.mark.parametrize("dtype", [np.float32, np.float64], ids=lambda d: d.__name__)
def test_zero_tangents_shapes_and_dtypes(dtype):
    z = manifold.zero_tangents(_params(dtype))
    shapes = jax.tree.map(lambda a: (a.shape, a.dtype), z)
    assert shapes == {
        "rot": ((6, 3), dtype),
        "pose": [((6,), dtype)],
        "poses": ((2, 2, 6), dtype),
        "bias": ((3,), dtype),
    }
    assert all(not np.any(a) for a in jax.tree.leaves(z))


def test_rplus_is_right_multiplication_by_exp():
    x = _params()
    d = _random_tangents(x, 0.7, 1)
    y = manifold.rplus(x, d)
    want = SRotation.from_quat(Q) * SRotation.from_rotvec(np.array(d["rot"]))
    assert_close(y["rot"].as_matrix(), want.as_matrix(), atol=1e-14)
    want = SRigid.from_exp_coords(XI.reshape(2, 2, 6)) * SRigid.from_exp_coords(
        np.array(d["poses"])
    )
    assert_close(y["poses"].as_matrix(), want.as_matrix(), atol=1e-13)
    want = SRigid.from_exp_coords(XI[0]) * SRigid.from_exp_coords(np.array(d["pose"][0]))
    assert_close(y["pose"][0].as_matrix(), want.as_matrix(), atol=1e-13)
    assert_close(y["bias"], np.arange(3) + np.array(d["bias"]), atol=0)


def _below_pi(w):
    """Rotation vectors scaled down to norm 3 where longer."""
    n = np.linalg.norm(w, axis=-1, keepdims=True)
    return w * np.minimum(1.0, 3.0 / np.maximum(n, 1e-300))


@pytest.mark.parametrize("scale", [1e-300, 1e-8, 0.5, 3.0])
def test_rminus_inverts_rplus(scale):
    """rminus(x, rplus(x, d)) == d while |d| < pi (beyond, the log wraps), and
    rplus(a, rminus(a, b)) == b for unrelated a and b."""
    x = _params()
    d = _random_tangents(x, scale, 2)
    d["rot"] = _below_pi(d["rot"])
    d["poses"] = d["poses"].at[..., :3].set(_below_pi(d["poses"][..., :3]))
    d["pose"][0] = d["pose"][0].at[:3].set(_below_pi(d["pose"][0][:3]))
    back = manifold.rminus(x, manifold.rplus(x, d))
    for got, want in zip(jax.tree.leaves(back), jax.tree.leaves(d), strict=True):
        assert_close(got, want, atol=2e-14 * max(1.0, scale), rtol=1e-12)
    b = manifold.rplus(x, _random_tangents(x, 2.0, 3))
    again = manifold.rplus(x, manifold.rminus(x, b))
    assert_close(again["rot"].as_matrix(), b["rot"].as_matrix(), atol=1e-14)
    assert_close(again["poses"].as_matrix(), b["poses"].as_matrix(), atol=1e-13)
    assert_close(again["bias"], b["bias"], atol=1e-15)


def test_rminus_near_180_degrees():
    a = rj.Rotation.from_rotvec(np.array([0.3, -0.1, 0.2]))
    axis = np.array([1.0, 2.0, -2.0]) / 3
    for angle in (np.pi, np.pi - 1e-9, np.pi - 1e-4):
        b = a * rj.Rotation.from_rotvec(angle * axis)
        d = manifold.rminus(a, b)
        assert_close(np.linalg.norm(d), angle, atol=4e-15)
        assert_close(manifold.rplus(a, d).as_matrix(), b.as_matrix(), atol=4e-15)


TARGET = np.array([1.0, -1.0, 2.0])


def _loss(p):
    v, target = jnp.asarray([1.0, 2.0, 3.0]), TARGET
    out = jnp.sum(p["rot"].apply(v) @ target)
    out = out + jnp.sum(p["poses"].apply(v) ** 2) + jnp.sum(p["pose"][0].apply(-v) * target)
    return out + jnp.sum(jnp.sin(p["bias"]))


def test_grad_matches_directional_derivatives():
    """<grad, d> equals the central difference of f(rplus(x, h d)) for random directions d."""
    x = _params()
    g = jax.jit(manifold.grad(_loss))(x)
    assert jax.tree.structure(g) == jax.tree.structure(manifold.zero_tangents(x))
    h = 1e-5

    @jax.jit  # one program for every direction and step
    def step(s, d):
        return _loss(manifold.rplus(x, jax.tree.map(lambda t: s * h * t, d)))

    for seed in range(3):
        d = _random_tangents(x, 1.0, 10 + seed)
        fd = (step(1.0, d) - step(-1.0, d)) / (2 * h)
        dot = sum(
            jnp.sum(a * b) for a, b in zip(jax.tree.leaves(g), jax.tree.leaves(d), strict=True)
        )
        assert_close(dot, fd, rtol=1e-8)


def test_grad_is_the_body_frame_gradient():
    """f(R) = a . (R v): the tangent gradient is v x (R^T a); f(T) = a . (T p): rotation part
    p x (R^T a), translation part R^T a. At the identity and at 180 degrees too."""
    a, v = np.array([0.3, -2.0, 1.0]), np.array([1.5, 0.5, -1.0])
    # compiled once, for the three points
    rot_grad = jax.jit(manifold.grad(lambda r: jnp.dot(a, r.apply(v))))
    pose_grad = jax.jit(manifold.grad(lambda t: jnp.dot(a, t.apply(v))))
    for w in (np.zeros(3), np.array([np.pi, 0, 0]), np.array([0.4, 1.0, -0.2])):
        R = rj.Rotation.from_rotvec(w)
        g = rot_grad(R)
        Rm = np.asarray(R.as_matrix())
        assert_close(g, np.cross(v, Rm.T @ a), atol=1e-14)
        T = rj.RigidTransform.from_components(np.array([1.0, 2.0, 3.0]), R)
        g = pose_grad(T)
        assert_close(g, np.concatenate([np.cross(v, Rm.T @ a), Rm.T @ a]), atol=1e-14)


def test_argnums_tuple_value_and_has_aux():
    x = _params()
    s = jnp.asarray(2.0)

    def f(scale, p):
        return scale * _loss(p), {"aux": scale}

    def all_of_them(s, x):  # one compiled program
        return (
            manifold.value_and_grad(f, argnums=(0, 1), has_aux=True)(s, x),
            _loss(x),
            manifold.grad(_loss)(x),
            manifold.grad(f, argnums=1, has_aux=True)(s, x),
        )

    ((val, aux), (gs, gp)), loss, g1, (gp_only, aux1) = jax.jit(all_of_them)(s, x)
    assert_close(val, 2 * loss, rtol=1e-15)
    assert aux["aux"] == 2.0 and aux1["aux"] == 2.0
    assert_close(gs, loss, rtol=1e-15)
    for a, b in zip(jax.tree.leaves(gp), jax.tree.leaves(g1), strict=True):
        assert_close(a, 2 * b, rtol=1e-14, atol=1e-14)
    assert jax.tree.structure(gp_only) == jax.tree.structure(g1)
    # the Euclidean leaf's gradient is jax.grad's
    assert_close(g1["bias"], jnp.cos(x["bias"]), rtol=1e-15)


@pytest.mark.parametrize(
    "dtype", sweep([np.float32, np.float64], fast=[np.float64]), ids=lambda d: d.__name__
)
def test_grad_finite_at_the_identity_and_at_180_degrees(dtype):
    x = {
        "rot": rj.Rotation.from_rotvec(np.array([[0.0, 0, 0], [np.pi, 0, 0]], dtype)),
        "pose": rj.RigidTransform.from_exp_coords(
            np.array([[0.0, 0, 0, 1, 2, 3], [0, np.pi, 0, 1, 2, 3]], dtype)
        ),
    }

    def f(p):
        v = jnp.asarray([1.0, 2.0, 3.0], dtype)
        return jnp.sum(p["rot"].apply(v) ** 2 @ v) + jnp.sum(p["pose"].apply(v) @ v)

    def both(x):  # one program: the tangent gradient, and the Hessian at the zero tangent
        h = jax.hessian(lambda d: f(manifold.rplus(x, d)))(manifold.zero_tangents(x))
        return manifold.grad(f)(x), h

    g, h = jax.jit(both)(x)
    for leaf in jax.tree.leaves(g):
        assert leaf.dtype == dtype and np.all(np.isfinite(leaf))
    assert np.any(g["rot"]) and np.any(g["pose"])
    assert all(np.all(np.isfinite(leaf)) for leaf in jax.tree.leaves(h))


@pytest.mark.parametrize(
    ("make", "steps", "tol"),
    [
        (lambda: optax.sgd(0.4), 200, 1e-12),
        (lambda: optax.adam(optax.cosine_decay_schedule(0.1, 400, alpha=1e-9)), 400, 1e-6),
    ],
    ids=["sgd", "adam"],
)
def test_optax_fits_a_pose_on_the_group(make, steps, tol):
    """An optax optimiser updates the tangents and rplus applies them: the fitted pose of a
    noiseless point cloud is the true one (gradient descent converges linearly, to rounding;
    Adam to its last step size)."""
    rng = np.random.default_rng(7)
    true = SRigid.from_exp_coords(np.array([1.0, -2.0, 0.5, 0.3, 4.0, -1.0]))
    pts = rng.normal(size=(50, 3))
    obs = true.apply(pts)

    def loss(T):
        return jnp.mean(jnp.sum((T.apply(pts) - obs) ** 2, axis=-1))

    opt = make()
    T = rj.RigidTransform.identity(dtype=np.float64)
    state = opt.init(manifold.zero_tangents(T))

    def step(carry, _):
        T, state = carry
        g = manifold.grad(loss)(T)
        updates, state = opt.update(g, state)
        return (manifold.rplus(T, updates), state), loss(T)

    # optax's schedules and bias corrections mix its int32 step count with floats, which the
    # test suite's strict promotion rejects (rotjax's code is checked strict everywhere else).
    with jax.numpy_dtype_promotion("standard"):
        (T, state), losses = jax.jit(lambda c: jax.lax.scan(step, c, None, length=steps))(
            (T, state)
        )
    assert losses[0] > 10 and losses[-1] < 1e-3 * tol
    assert_close(T.as_matrix(), true.as_matrix(), atol=tol)


def test_rigid_transform_optional_at_import():
    # manifold handles arrays alone and rotations without touching RigidTransform's module
    x = {"a": jnp.ones(2), "r": rj.Rotation.identity()}
    assert_close(manifold.rplus(x, manifold.zero_tangents(x))["a"], np.ones(2), atol=0)


@pytest.mark.parametrize(
    "a, b, expected",
    [
        (rj.Rotation.identity(), rj.RigidTransform.identity(), "expected a Rotation"),
        (rj.RigidTransform.identity(), rj.Rotation.identity(), "expected a RigidTransform"),
        (jnp.zeros(3), rj.Rotation.identity(), "expected an array"),
        (rj.Rotation.identity(), jnp.zeros(3), "expected a Rotation"),
    ],
)
def test_mixed_types_are_a_type_error_naming_the_expected_one(a, b, expected):
    with pytest.raises(TypeError, match=expected):
        manifold.rminus({"x": a}, {"x": b})


def test_rplus_of_a_group_element_is_a_type_error():
    with pytest.raises(TypeError, match="expected a tangent array"):
        manifold.rplus(rj.Rotation.identity(), rj.Rotation.identity())
