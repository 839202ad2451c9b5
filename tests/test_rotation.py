"""rotjax.Rotation and Slerp against scipy's, and their behaviour as pytrees."""

import pickle

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import random_quaternions, sweep
from scipy.spatial.transform import Rotation as SR
from scipy.spatial.transform import Slerp as SSlerp

import rotjax
from rotjax import Rotation, Slerp

Q = random_quaternions(6, seed=3)  # (6, 4), not unit
V = np.random.default_rng(4).normal(size=(6, 3))


def same_rotation(q1, q2, atol):
    """Quaternions equal up to sign, rotation by rotation."""
    q1, q2 = np.asarray(q1), np.asarray(q2)
    d = np.minimum(np.abs(q1 - q2).max(axis=-1), np.abs(q1 + q2).max(axis=-1))
    np.testing.assert_array_less(d, atol)


RANK_SAFE = {
    "mul_broadcast": lambda: (Rotation.from_quat(Q) * Rotation.from_quat(Q[0])).as_quat(),
    "apply_broadcast": lambda: Rotation.from_quat(Q[:1]).apply(V),
    "apply_single": lambda: Rotation.from_quat(Q[0]).apply(V),
    "align_vectors_inf": lambda: Rotation.align_vectors(V, V[::-1], [np.inf] + [1.0] * 5)[1],
    "reduce": lambda: Rotation.from_quat(Q).reduce(Rotation.create_group("T")).as_quat(),
    "from_davenport": lambda: Rotation.from_davenport(np.eye(3), "e", V).as_quat(),
    "from_euler_1": lambda: Rotation.from_euler("x", V[:, :1]).as_quat(),
    "pow": lambda: (Rotation.from_quat(Q) ** 0.5).as_quat(),
}


@pytest.mark.parametrize("name", sorted(RANK_SAFE))
def test_class_broadcasting_under_rank_promotion_raise(name):
    # The class's own broadcasting is explicit. (The whole module can run under "raise" once
    # every core function is rank-promotion safe.)
    with jax.numpy_rank_promotion("raise"):
        assert np.all(np.isfinite(RANK_SAFE[name]()))


# --- conversions against scipy --------------------------------------------------------

AS = {
    "as_quat": lambda r: r.as_quat(),
    "as_quat_canonical_sf": lambda r: r.as_quat(canonical=True, scalar_first=True),
    "as_matrix": lambda r: r.as_matrix(),
    "as_rotvec_deg": lambda r: r.as_rotvec(degrees=True),
    "as_mrp": lambda r: r.as_mrp(),
    "as_euler_ZXZ": lambda r: r.as_euler("ZXZ"),
    "as_euler_xyz_deg": lambda r: r.as_euler("xyz", degrees=True),
    "magnitude": lambda r: r.magnitude(),
    "apply": lambda r: r.apply(V),
    "apply_inverse": lambda r: r.apply(V, inverse=True),
    "inv": lambda r: r.inv().as_matrix(),
    "pow_0.3": lambda r: (r**0.3).as_matrix(),
    "pow_-2": lambda r: (r**-2).as_matrix(),
    "mul": lambda r: (r * r[::-1]).as_matrix(),
    "mean": lambda r: r.mean().as_matrix(),
    "mean_weights": lambda r: r.mean(weights=np.arange(1.0, 7.0)).as_matrix(),
    "davenport": lambda r: r.as_davenport(np.eye(3)[[2, 0, 2]], "e"),
    "mean_axis": lambda r: type(r).from_quat(r.as_quat().reshape(2, 3, 4)).mean(axis=1).as_matrix(),
}


@pytest.mark.parametrize("name", sweep(sorted(AS), fast=sorted(AS)[::3]))
def test_methods_match_scipy(name):
    f = AS[name]
    np.testing.assert_allclose(f(Rotation.from_quat(Q)), f(SR.from_quat(Q)), atol=1e-13)


FROM = {
    "from_quat_sf": ("from_quat", (Q,), {"scalar_first": True}),
    "from_matrix": ("from_matrix", (SR.from_quat(Q).as_matrix() * 1.01,), {}),
    "from_matrix_valid": ("from_matrix", (SR.from_quat(Q).as_matrix(),), {"assume_valid": True}),
    "from_rotvec": ("from_rotvec", (V * 30,), {"degrees": True}),
    "from_mrp": ("from_mrp", (V,), {}),
    "from_euler_3": ("from_euler", ("zyz", V), {}),
    "from_euler_2": ("from_euler", ("XY", V[:, :2]), {}),
    "from_euler_1": ("from_euler", ("y", V[:, :1]), {"degrees": True}),
    "from_euler_1_scalar": ("from_euler", ("Z", 0.4), {}),
    "from_davenport": ("from_davenport", (np.eye(3)[[0, 2, 1]], "i", V), {}),
    "from_davenport_oblique": (
        "from_davenport",
        ([[1.0, 0, 0], [0, 1, 1], [1, 0, 0]], "extrinsic", V),
        {},
    ),
}


@pytest.mark.parametrize("name", sweep(sorted(FROM), fast=sorted(FROM)[::3]))
def test_constructors_match_scipy(name):
    meth, args, kw = FROM[name]
    r, s = getattr(Rotation, meth)(*args, **kw), getattr(SR, meth)(*args, **kw)
    assert r.shape == s.shape and r.single == s.single
    same_rotation(r.as_quat(), s.as_quat(), 1e-13)


def test_random_and_identity_match_scipy():
    np.testing.assert_allclose(Rotation.random(3, rng=7).as_quat(), SR.random(3, rng=7).as_quat())
    assert Rotation.random(jax.random.key(0), 5).shape == (5,)  # jax.scipy's signature
    assert Rotation.random(shape=(2, 3), rng=1).shape == (2, 3)
    r = Rotation.identity(4, jnp.float32)
    assert r.as_quat().dtype == jnp.float32 and r.shape == (4,)
    np.testing.assert_array_equal(Rotation.identity().as_matrix(), np.eye(3))


def test_align_vectors_matches_scipy():
    rng = np.random.default_rng(5)
    a, b = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    w = rng.uniform(0.5, 2, 5)
    r, rssd, sens = Rotation.align_vectors(a, b, w, return_sensitivity=True)
    s, srssd, ssens = SR.align_vectors(a, b, w, return_sensitivity=True)
    same_rotation(r.as_quat(), s.as_quat(), 1e-13)
    np.testing.assert_allclose(rssd, srssd, rtol=1e-12)
    np.testing.assert_allclose(sens, ssens, atol=1e-13)
    w[2] = np.inf  # primary vector
    same_rotation(
        Rotation.align_vectors(a, b, w)[0].as_quat(), SR.align_vectors(a, b, w)[0].as_quat(), 1e-12
    )
    # a single pair: the smallest rotation, also for antiparallel vectors
    for bb in (b[0], -a[0]):
        r1 = Rotation.align_vectors(a[0], bb)[0]
        np.testing.assert_allclose(r1.apply(bb / np.linalg.norm(bb)), a[0] / np.linalg.norm(a[0]))


def test_reduce_and_groups_match_scipy():
    left, right = SR.create_group("O"), SR.create_group("D3")
    r = SR.from_quat(Q).reduce(left, right, return_indices=True)
    mine = Rotation.from_quat(Q).reduce(
        Rotation.create_group("O"), Rotation.create_group("D3"), return_indices=True
    )
    # scipy's group elements are in another order: compare the reduced rotations' angles,
    # which are the minimum over the groups and so independent of the order.
    np.testing.assert_allclose(mine[0].magnitude(), r[0].magnitude(), atol=1e-13)
    for g, n in (("C5", 5), ("D4", 8), ("T", 12), ("O", 24), ("I", 60)):
        m = Rotation.create_group(g).as_matrix()
        assert m.shape == (n, 3, 3)
        # closed under composition: every product is an element
        prod = np.einsum("aij,bjk->abik", m, m).reshape(-1, 1, 9)
        assert np.abs(prod - np.asarray(m).reshape(1, -1, 9)).max(-1).min(-1).max() < 1e-12


def test_slerp_matches_scipy():
    t = np.array([0.0, 1.0, 2.5, 3.0, 5.0, 6.0])
    ti = np.linspace(0, 6, 13)
    mine = Slerp(t, Rotation.from_quat(Q))(ti)
    same_rotation(mine.as_quat(), SSlerp(t, SR.from_quat(Q))(ti).as_quat(), 1e-13)
    assert Slerp.init(t, Rotation.from_quat(Q))(2.0).single
    # under jit, construction and call together
    f = jax.jit(lambda t, r, x: Slerp(t, r)(x).as_matrix())
    np.testing.assert_allclose(f(t, Rotation.from_quat(Q), ti), mine.as_matrix(), atol=1e-14)


# --- pytree behaviour ------------------------------------------------------------------


def test_jit_vmap_scan_grad_pickle():
    r = Rotation.from_quat(Q.reshape(2, 3, 4))
    out = jax.jit(lambda r: r.inv() * r)(r)
    assert isinstance(out, Rotation) and out.shape == (2, 3)
    np.testing.assert_allclose(out.magnitude(), 0, atol=1e-7)
    m = jax.vmap(lambda r: r.as_matrix())(r)
    np.testing.assert_allclose(m, r.as_matrix())

    step = Rotation.from_rotvec(jnp.asarray([0.0, 0.0, 0.1]))
    final, _ = jax.lax.scan(lambda c, _: (c * step, None), Rotation.identity(), None, length=10)
    np.testing.assert_allclose(final.as_rotvec(), [0, 0, 1.0], atol=1e-14)

    # gradient through the class equals the gradient through the functions, at the identity
    def loss_cls(v):
        return jnp.sum(Rotation.from_rotvec(v).apply(jnp.asarray([1.0, 2.0, 3.0])) ** 2 * v[0])

    def loss_fun(v):
        q = rotjax.rotvec_to_quaternion(v)
        return jnp.sum(rotjax.quaternion_apply(q, jnp.asarray([1.0, 2.0, 3.0])) ** 2 * v[0])

    for v in (jnp.zeros(3), jnp.asarray([0.3, -0.2, 0.1])):
        g = jax.grad(loss_cls)(v)
        assert np.all(np.isfinite(g))
        np.testing.assert_allclose(g, jax.grad(loss_fun)(v), atol=1e-15)
    # the magnitude's gradient at pi and the Euler gradient at gimbal lock are finite
    g = jax.grad(lambda q: Rotation.from_quat(q).as_euler("XYZ")[0])(
        jnp.asarray([0.5, 0.5, 0.5, 0.5])
    )
    assert np.all(np.isfinite(g))

    back = pickle.loads(pickle.dumps(r))
    np.testing.assert_array_equal(back.as_quat(), r.as_quat())


class _SwapArrays(pickle.Pickler):
    """Pickles with every JAX array (a tracer too) swapped for a placeholder, as pickle-based
    flatteners of jitted arguments do (array-api-extra's ``jax_autojit``, which scipy's JAX
    tests wrap methods with)."""

    def __init__(self, file, found):
        super().__init__(file)
        self.found = found

    def persistent_id(self, obj):
        if isinstance(obj, (jax.Array, jax.core.Tracer)):
            self.found.append(obj)
            return len(self.found) - 1
        return None


class _RestoreArrays(pickle.Unpickler):
    def __init__(self, file, found):
        super().__init__(file)
        self.found = found

    def persistent_load(self, pid):
        return self.found[pid]


@pytest.mark.parametrize("cls", ["Rotation", "RigidTransform"])
def test_repr_and_pickling_of_a_traced_object(cls):
    """Under jit, repr (and print) of a Rotation or RigidTransform shows the tracer, as scipy's
    does, and pickling hands its leaves over as they are: a traced object goes through a
    pickler that swaps arrays for placeholders and comes back with the same tracers."""
    import io

    make = {
        "Rotation": Rotation.from_quat,
        "RigidTransform": lambda q: rotjax.RigidTransform.from_rotation(Rotation.from_quat(q)),
    }[cls]
    q = jnp.asarray([0.1, -0.2, 0.3, 0.9])
    texts = []

    def through_pickle(q):
        obj = make(q)
        texts.append(repr(obj))
        found, buf = [], io.BytesIO()
        _SwapArrays(buf, found).dump(obj)
        assert found and all(isinstance(x, jax.core.Tracer) for x in found)
        buf.seek(0)
        return _RestoreArrays(buf, found).load().as_matrix()

    out = jax.jit(through_pickle)(q)
    np.testing.assert_allclose(out, make(q).as_matrix(), atol=1e-15)
    assert texts[0].startswith(f"{cls}.from_matrix(") and "Tracer" in texts[0], texts[0]
    assert "Tracer" not in repr(make(q))  # outside a trace: the values


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_dtype_preserved(dtype):
    r = Rotation.from_quat(Q.astype(dtype))  # NumPy input keeps its float dtype too
    outs = [r.as_matrix(), r.as_euler("zyx"), r.apply(V), r.as_mrp(), (r * r).as_quat()]
    assert all(o.dtype == dtype for o in outs)


def test_shapes_indexing_setitem():
    r = Rotation.from_quat(Q.reshape(2, 3, 4))
    assert r.shape == (2, 3) and len(r) == 2 and r[1].shape == (3,) and r[1, 2].single
    assert r[..., 0].shape == (2,) and r[:, None].shape == (2, 1, 3)
    assert [x.shape for x in r] == [(3,), (3,)]
    # apply broadcasts the batch shapes explicitly, also under rank-promotion "raise"
    assert r.apply(V[:3]).shape == (2, 3, 3) and r[0, 0].apply(V).shape == (6, 3)
    assert (r * r[0, 0]).shape == (2, 3)
    single = r[0, 0]
    for op in (len, lambda s: s[0], iter):
        with pytest.raises(TypeError):
            op(single)
    r2 = Rotation.from_quat(Q)
    old = r2.as_quat()
    r2[1:3] = Rotation.identity(2)
    np.testing.assert_array_equal(r2.as_quat()[1:3], [[0, 0, 0, 1]] * 2)
    np.testing.assert_array_equal(r2.as_quat()[0], old[0])
    c = Rotation.concatenate([r2[0], r2[1:4]])
    assert c.shape == (4,)
    assert repr(Rotation.identity()).startswith("Rotation.from_matrix(")


ZERO_FIRST = np.array([[0.0], [1], [1], [1], [1], [1]])  # V * ZERO_FIRST: V[0] zeroed
ERRORS = {
    "quat_shape": (ValueError, lambda: Rotation.from_quat(np.ones(3))),
    "zero_quat": (ValueError, lambda: Rotation.from_quat(np.zeros(4))),
    "matrix_shape": (ValueError, lambda: Rotation.from_matrix(np.eye(2))),
    "det_negative": (ValueError, lambda: Rotation.from_matrix(-np.eye(3))),
    "euler_seq": (ValueError, lambda: Rotation.from_euler("xyzx", [1, 2, 3, 4])),
    "euler_mixed": (ValueError, lambda: Rotation.from_euler("xY", [1, 2])),
    "euler_repeat": (ValueError, lambda: Rotation.from_euler("xx", [1, 2])),
    "euler_angles": (ValueError, lambda: Rotation.from_euler("xyz", [1, 2])),
    "as_euler_seq": (ValueError, lambda: Rotation.identity().as_euler("xy")),
    "weights_negative": (ValueError, lambda: Rotation.align_vectors(V, V, -np.ones(6))),
    "two_infinite": (ValueError, lambda: Rotation.align_vectors(V, V, [np.inf] * 2 + [1] * 4)),
    "sensitivity_one_pair": (
        ValueError,
        lambda: Rotation.align_vectors(V[0], V[0], return_sensitivity=True),
    ),
    "mul_shapes": (ValueError, lambda: Rotation.from_quat(Q) * Rotation.from_quat(Q[:2])),
    "pow_array": (ValueError, lambda: Rotation.identity() ** np.ones(2)),
    "mean_axis": (ValueError, lambda: Rotation.from_quat(Q).mean(axis=1)),
    "davenport_order": (ValueError, lambda: Rotation.from_davenport(np.eye(3), "x", [1, 2, 3])),
    "davenport_axes": (
        ValueError,
        lambda: Rotation.from_davenport([[1, 0, 0], [1, 1, 0]], "e", [1, 2]),
    ),
    "group": (ValueError, lambda: Rotation.create_group("Q")),
    "slerp_range": (ValueError, lambda: Slerp([0, 1], Rotation.from_quat(Q[:2]))(2.0)),
    "slerp_order": (ValueError, lambda: Slerp([1, 0], Rotation.from_quat(Q[:2]))),
    "setitem_type": (TypeError, lambda: Rotation.from_quat(Q).__setitem__(0, 1)),
    "zero_primary_one_pair": (ValueError, lambda: Rotation.align_vectors([0, 0, 0], V[0])),
    "zero_primary_b": (ValueError, lambda: Rotation.align_vectors(V[:1], np.zeros((1, 3)))),
    "zero_primary_inf": (
        ValueError,
        lambda: Rotation.align_vectors(V * ZERO_FIRST, V, [np.inf] + [1.0] * 5),
    ),
}


@pytest.mark.parametrize("name", sorted(ERRORS))
def test_errors(name):
    exc, f = ERRORS[name]
    with pytest.raises(exc):
        f()


def test_zero_primary_vector_message_and_nan_for_jax_arrays():
    with pytest.raises(ValueError, match="Cannot align zero length primary vectors"):
        Rotation.align_vectors(np.zeros((1, 3)), V[:1])
    # a zero vector that is not primary is no error: it has no weight in the fit
    Rotation.align_vectors(V * ZERO_FIRST, V)
    r, rssd = Rotation.align_vectors(jnp.zeros((1, 3)), jnp.asarray(V[:1]))
    assert np.all(np.isnan(r.as_quat())) and np.isnan(rssd)


def test_align_vectors_batched_input_names_both_shapes():
    with pytest.raises(ValueError, match="Expected inputs `a` and `b` to have shape"):
        Rotation.align_vectors(V[None], V[None])


def test_values_under_jit_give_nan():
    nan_q = jax.jit(lambda q: Rotation.from_quat(q).as_quat())(jnp.zeros((2, 4)).at[0, 3].set(1))
    assert np.all(np.isfinite(nan_q[0])) and np.all(np.isnan(nan_q[1]))
    m = jnp.stack([jnp.eye(3), -jnp.eye(3)])
    q = jax.jit(lambda m: Rotation.from_matrix(m).as_quat())(m)
    assert np.all(np.isfinite(q[0])) and np.all(np.isnan(q[1]))


def test_jax_scipy_snippet_runs_unchanged():
    # Code written for jax.scipy.spatial.transform, with only the import swapped.
    from jax.scipy.spatial import transform as jst

    def script(R, S):
        r = R.from_euler("xyz", jnp.asarray([[0.1, 0.2, 0.3], [0.4, -0.2, 1.0]]))
        s = S.init(jnp.asarray([0.0, 1.0]), r)
        out = jax.jit(lambda x: s(x).apply(jnp.asarray([1.0, 0.0, 0.0])))(jnp.asarray(0.25))
        return (
            out,
            R.identity(dtype=jnp.float32).as_quat(),  # jax.scipy: num must be None
            R.concatenate([r, r]).as_rotvec(),
            jax.vmap(lambda q: R.from_quat(q).apply(jnp.asarray([0.0, 1.0, 0.0])))(r.as_quat()),
            r.magnitude(),
            (r[0] * r[1].inv()).as_matrix(),
        )

    ours = script(Rotation, Slerp)  # under the suite's rank promotion "raise"
    with jax.numpy_rank_promotion("allow"):  # the oracle: jax.scipy's Slerp promotes ranks
        # one compiled program (jax.scipy's methods op by op would compile one program each)
        theirs = jax.jit(lambda: script(jst.Rotation, jst.Slerp))()
    for a, b in zip(ours, theirs, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-12)


# --- the new functions and RotationSpline -------------------------------------------------


def test_as_davenport_oblique_axes_match_scipy():
    axes = np.array([[1.0, 0, 0], [0, 1, 0], [np.cos(2.0), 0, np.sin(2.0)]])
    rot = SR.from_quat(Q)
    for order in ("e", "i"):
        np.testing.assert_allclose(
            Rotation.from_quat(Q).as_davenport(axes, order),
            rot.as_davenport(axes, order),
            atol=1e-13,
        )


def test_rotation_spline_matches_scipy():
    from scipy.spatial.transform import RotationSpline as SSpline

    t = np.array([0.0, 1.0, 2.5, 3.0, 5.0, 6.0])
    ti = np.linspace(-0.5, 6.5, 15)
    mine, ref = rotjax.RotationSpline(t, Rotation.from_quat(Q)), SSpline(t, SR.from_quat(Q))
    same_rotation(mine(ti).as_quat(), ref(ti).as_quat(), 1e-12)
    np.testing.assert_allclose(mine(ti, 1), ref(ti, 1), atol=1e-12)
    np.testing.assert_allclose(mine(ti, 2), ref(ti, 2), atol=1e-11)


SINGULAR_QUATS = {
    "identity": [0.0, 0.0, 0.0, 1.0],
    "half_turn": [0.0, 0.6, 0.8, 0.0],
    "generic": [0.1, -0.3, 0.2, 0.9],
}


@pytest.mark.parametrize("name", sorted(SINGULAR_QUATS))
def test_new_functions_gradients_finite_and_true(name):
    q = jnp.asarray(SINGULAR_QUATS[name])
    dq = jnp.asarray([0.3, -0.2, 0.5, 0.1])
    h = 1e-6

    def check(f, x, dx, side=None):
        _, jvp = jax.jvp(f, (x,), (dx,))
        assert np.all(np.isfinite(jvp))
        # one-sided at the 180-degree cut (the side that keeps w >= 0), central elsewhere
        fd = (f(x + h * dx) - f(x)) / h if side else (f(x + h * dx) - f(x - h * dx)) / (2 * h)
        np.testing.assert_allclose(jvp, fd, atol=1e-6)

    side = name == "half_turn"
    check(rotjax.quaternion_to_mrp, q, dq, side)
    check(lambda n: rotjax.quaternion_power(q, n), jnp.asarray(1.0), jnp.asarray(1.0), side)
    check(lambda x: rotjax.quaternion_power(x, jnp.asarray(0.4)), q, dq, side)
    check(rotjax.mrp_to_quaternion, q[:3], dq[:3])


def test_new_functions_round_trips():
    q = jnp.asarray(Q)
    same_rotation(
        rotjax.mrp_to_quaternion(rotjax.quaternion_to_mrp(q)),
        q / np.linalg.norm(Q, axis=-1, keepdims=True),
        1e-15,
    )
    c = rotjax.quaternion_canonical(
        jnp.asarray([[0.0, -1.0, 0, 0], [0, 0, 0, -1.0], [1, 0, 0, -2]])
    )
    np.testing.assert_array_equal(c, [[0, 1, 0, 0], [0, 0, 0, 1], [-1, 0, 0, 2]])
    axes = np.array([[0.0, 0, 2], [1, 0, 0], [0, 0, 1]])
    ang = rotjax.quaternion_to_davenport(q, axes, extrinsic=True)
    same_rotation(
        rotjax.davenport_to_quaternion(axes, ang, extrinsic=True),
        q / np.linalg.norm(Q, axis=-1, keepdims=True),
        1e-14,
    )


def test_jit_class_compiles_to_the_functions_program():
    # Under jit the class adds no work: the same operations, flops and bytes as the functions.
    import re

    def ops(f, *args):
        c = f.lower(*args).compile()
        ca = c.cost_analysis()
        ca = ca[0] if isinstance(ca, list) else ca
        text = re.sub(r", metadata=\{[^}]*\}", "", c.as_text())
        found = sorted(re.findall(r"= \S+\[[^\]]*\][^ ]* (\w+)\(", text))
        return found, ca.get("flops"), ca.get("bytes accessed")

    q, v = jnp.asarray(Q), jnp.asarray(V)
    cls = jax.jit(lambda q, v: (Rotation.from_quat(q) * Rotation.from_quat(q[::-1])).apply(v))
    # A product of the stored quaternions (any norm, rescaled by powers of two), stored as is
    # and read without a prescaling (of order 1, or NaN).
    from rotjax._quaternion import quat_apply, quat_multiply, quat_normalize, quat_rescaled

    fun = jax.jit(
        lambda q, v: quat_apply(quat_multiply(quat_rescaled(q), quat_rescaled(q[::-1])), v, True)
    )
    assert ops(cls, q, v) == ops(fun, q, v)
    # The readers take the quaternion as given (any norm): one conversion, no normalisation.
    pairs = [
        (
            lambda q: Rotation.from_quat(q).as_euler("xyz"),
            lambda q: rotjax.quaternion_to_euler(q, "xyz"),
        ),
        (lambda q: Rotation.from_quat(q).as_matrix(), rotjax.quaternion_to_matrix),
        (
            lambda q: Rotation.from_quat(q).inv().as_rotvec(),
            lambda q: rotjax.quaternion_to_rotvec(rotjax.quaternion_conjugate(q)),
        ),
        (lambda q: Rotation.from_quat(q).apply(V), lambda q: rotjax.quaternion_apply(q, V)),
        # as_quat normalises the stored quaternion, whatever built it; one that a conversion
        # built (marked unit) without the prescaling
        (
            lambda q: Rotation.from_rotvec(q[:, :3]).as_quat(),
            lambda q: quat_normalize(rotjax.rotvec_to_quaternion(q[:, :3]), True),
        ),
        (lambda q: Rotation.from_quat(q).as_quat(), rotjax.quaternion_normalize),
    ]
    for cls, fun in pairs:
        assert ops(jax.jit(cls), q) == ops(jax.jit(fun), q)


def test_align_vectors_infinite_weight_near_180_degrees():
    """The primary pair's smallest rotation is computed from ``a + b`` (no cancellation in
    ``1 + a.b``): for exact data whose primary pair is within 1e-4 rad of antiparallel, the
    infinite-weight answer is the true rotation to rounding."""
    rng = np.random.default_rng(5)
    worst = 0.0
    for _ in range(40):
        b0 = rng.normal(size=3)
        b0 /= np.linalg.norm(b0)
        # pi about an axis perpendicular to b0, then a small tilt: a0 = R b0 is nearly -b0
        axis = np.cross(b0, rng.normal(size=3))
        half = rotjax.rotvec_to_quaternion(np.pi * axis / np.linalg.norm(axis))
        tilt = rotjax.rotvec_to_quaternion(1e-4 * rng.normal(size=3))
        R = np.asarray(rotjax.quaternion_to_matrix(rotjax.quaternion_multiply(tilt, half)))
        b = np.stack([b0, rng.normal(size=3)])
        a = b @ R.T
        r_inf, _ = Rotation.align_vectors(a, b, weights=[np.inf, 1.0])
        worst = max(worst, np.abs(np.asarray(r_inf.as_matrix()) - R).max())
    assert worst < 1e-14, worst


# Constructors that mark their quaternion as unit (Rotation._unit), so that a product does not
# rescale it; on inputs far from unit size, at 180 degrees and at the identity.
# (from_matrix with assume_valid stores the unnormalised Shepperd column: not marked.)
_ANGLES = np.array([[0.0, 0.0, 0.0], [1e-20, 0.0, 0.0], [0.3, -2.0, 1.0], [np.pi, 0, 0],
                    [4e3, -1e2, 7.0], [1e-3, 2.5, -3.1]])  # fmt: skip
_UNIT_BUILT = {
    "from_rotvec": lambda x: Rotation.from_rotvec(x),
    "from_euler": lambda x: Rotation.from_euler("ZXZ", x),
    "from_mrp": lambda x: Rotation.from_mrp(x * np.array([1e15, 1.0, 1e-15])[:, None].repeat(2, 0)),
    "from_matrix projected": lambda x: Rotation.from_matrix(
        np.asarray(rotjax.rotvec_to_matrix(x)) + 1e-3 * np.cos(np.arange(9)).reshape(3, 3)
    ),
    "from_davenport": lambda x: Rotation.from_davenport(np.eye(3), "e", x),
    "pow": lambda x: Rotation.from_quat(np.c_[x, np.ones(len(x))] * 1e30) ** 0.3,
    "mean": lambda x: Rotation.from_rotvec(np.stack([x, 0.5 * x], 1)).mean(axis=1),
    "identity": lambda x: Rotation.identity(len(x), dtype=x.dtype),
    "create_group": lambda x: Rotation.create_group("C6"),  # float64 whatever x is
    "product": lambda x: Rotation.from_rotvec(x) * Rotation.from_euler("xyz", x[::-1]),
    "inv": lambda x: Rotation.from_rotvec(x).inv(),
    "getitem": lambda x: Rotation.from_rotvec(np.stack([x, -x], 1))[:, 1],
    "Slerp": lambda x: Slerp([0.0, 1.0], Rotation.from_rotvec(x[2:4]))(
        np.linspace(0.0, 1.0, len(x)).astype(x.dtype)
    ),
    "RotationSpline": lambda x: rotjax.RotationSpline(
        np.arange(len(x), dtype=x.dtype), Rotation.from_rotvec(x)
    )(np.linspace(0.0, len(x) - 1.0, len(x)).astype(x.dtype)),
}


def _flattened(r):
    """The same rotation, as jit, vmap and grad see it: the flag is not in the tree."""
    return jax.tree.unflatten(*jax.tree.flatten(r)[::-1])


def _reads(v):
    return (
        lambda p: p.as_quat(),
        lambda p: p.as_matrix(),
        lambda p: p.magnitude(),
        lambda p: p.apply(v[: len(p)].astype(p.as_quat().dtype)),
        lambda p: p.as_rotvec(),
    )


def _raw_rotations(x):
    return Rotation.from_quat((np.c_[x, np.ones(len(x))] * 1e15).astype(x.dtype))  # not unit


def _assert_same_bits(a, b, v, what):
    for read in _reads(v):
        np.testing.assert_array_equal(
            read(a * b), read(_flattened(a) * _flattened(b)), err_msg=what
        )


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_unit_marked_rotations_store_unit_quaternions(dtype):
    """The flag only skips work: every constructor that sets it stores a quaternion of norm 1
    to rounding; and each reader gives the same bits for a product with and without the
    rescaling of its factors (exact powers of two): here for one constructor, for every one in
    the slow tier (below)."""
    x = _ANGLES.astype(dtype)
    for name, build in _UNIT_BUILT.items():
        r = build(x)
        assert r._unit and not _flattened(r)._unit, name
        n = np.linalg.norm(np.asarray(r._stored, np.float64), axis=-1)
        np.testing.assert_array_less(np.abs(n - 1), 8 * np.finfo(dtype).eps, err_msg=name)
    r, raw = Rotation.from_rotvec(x), _raw_rotations(x)
    _assert_same_bits(r, raw, V.astype(dtype), "from_rotvec * raw")


def test_unit_marked_products_have_true_gradients():
    """Products that skip the rescaling are differentiated by JAX like any other code: the
    derivative (forward and reverse, jitted) matches finite differences through a marked
    factor at a generic point, at the zero rotation vector and at 180 degrees, with a raw
    factor off the unit sphere, through the readers that skip the prescaling of a product; and
    equals the gradient with no marks (both factors rescaled, the product prescaled)."""
    from helpers import check_grads

    v = jnp.asarray(V[:3])
    q = jnp.asarray(Q[:3] * 3.0)  # norms about 3: off SO(3)

    def read(r):
        parts = [r.apply(v), r.as_quat(), r.as_rotvec(), r.as_mrp(), r.magnitude()[:, None]]
        return jnp.concatenate(parts + [r.as_matrix().reshape(-1, 9)], axis=-1)

    def f(a, q):
        return read(Rotation.from_rotvec(a) * Rotation.from_quat(q))

    def f_rescaled(a, q):
        return read(_flattened(_flattened(Rotation.from_rotvec(a)) * Rotation.from_quat(q)))

    a = jnp.array([[0.3, -0.2, 0.5], [0.0, 0.0, 0.0], [np.pi, 0.0, 0.0]])
    check_grads(f, (a, q), order=1)
    g = jax.jit(jax.grad(lambda a, q: jnp.sum(f(a, q) ** 2), argnums=(0, 1)))(a, q)
    g_ref = jax.jit(jax.grad(lambda a, q: jnp.sum(f_rescaled(a, q) ** 2), argnums=(0, 1)))(a, q)
    for x, y in zip(g, g_ref, strict=True):
        assert np.all(np.isfinite(x))
        np.testing.assert_allclose(x, y, rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_products_of_non_rotations_read_nan(dtype):
    """A product is read without a prescaling (``Rotation._bounded``): a zero, infinite or NaN
    factor, raw or converted, on either side, makes its element NaN in every reader, after an
    inverse and a further product too, and leaves the other elements alone."""
    good = Q[:4].astype(dtype)
    bad = good.copy()
    bad[1], bad[2, 0], bad[3, 2] = 0.0, np.inf, np.nan
    raw_good, raw_bad = Rotation.from_quat(jnp.asarray(good)), Rotation.from_quat(jnp.asarray(bad))
    conv_bad = Rotation.from_rotvec(jnp.asarray(bad[:, :3]))  # NaN where bad[:, :3] is not finite
    v = V[:4].astype(dtype)
    readers = {
        "as_quat": lambda r: r.as_quat(),
        "as_matrix": lambda r: r.as_matrix().reshape(-1, 9),
        "apply": lambda r: r.apply(v),
        "magnitude": lambda r: r.magnitude()[:, None],
        "as_rotvec": lambda r: r.as_rotvec(),
        "as_mrp": lambda r: r.as_mrp(),
        "as_euler": lambda r: r.as_euler("ZYX"),
    }
    products = {
        "raw bad * raw": raw_bad * raw_good,
        "raw * raw bad": raw_good * raw_bad,
        "converted * raw bad": Rotation.from_euler("xyz", v) * raw_bad,
        "converted bad * raw": conv_bad * raw_good,
    }
    for name, r in products.items():
        assert r._bounded, name
        for s in (r, r.inv(), r * r):
            for what, read in readers.items():
                out = np.asarray(read(s))
                bad_rows = [1, 2, 3] if "converted bad" not in name else [2, 3]
                assert np.isfinite(out[0]).all(), (name, what)
                assert np.isnan(out[bad_rows]).all(), (name, what, out)


@pytest.mark.slow
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_unit_marked_products_read_the_same_bits(dtype):
    """Every constructor that sets the flag: products with itself and with a raw rotation, on
    either side, read the same with and without the flag."""
    x = _ANGLES.astype(dtype)
    raw = _raw_rotations(x)
    for name, build in _UNIT_BUILT.items():
        r = build(x)
        k = len(r)
        pairs = [(r, r[::-1])]
        if r._stored.dtype == dtype:
            pairs += [(r, raw[:k]), (raw[:k], r)]
        for a, b in pairs:
            _assert_same_bits(a, b, V.astype(dtype), name)
