"""Rotation, Slerp and RotationSpline as pytrees: one tree structure whatever built them, so
that they can be a scan carry, the two branches of a cond, or the operands of a tree_map."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import random_quaternions
from scipy.spatial.transform import Rotation as SR

import rotjax
from rotjax import Rotation, RotationSpline, Slerp

Q = random_quaternions(5, seed=11)  # (5, 4), not unit
V = np.random.default_rng(12).normal(size=(5, 3))
M = SR.from_quat(Q).as_matrix()


def _spline(r):
    return RotationSpline(np.arange(5.0), r)(np.array([0.5, 1.5, 2.5, 3.5, 3.9]))


# Every way of making a batch of 5 rotations: constructors, methods and operators.
BUILDERS = {
    "Rotation(q)": lambda: Rotation(Q),
    "Rotation(q, normalize=False)": lambda: Rotation(
        Q / np.linalg.norm(Q, axis=-1)[:, None], normalize=False
    ),
    "from_quat": lambda: Rotation.from_quat(Q),
    "from_quat_jax": lambda: Rotation.from_quat(jnp.asarray(Q)),
    "from_quat_scalar_first": lambda: Rotation.from_quat(Q, scalar_first=True),
    "from_matrix": lambda: Rotation.from_matrix(M),
    "from_matrix_valid": lambda: Rotation.from_matrix(M, assume_valid=True),
    "from_rotvec": lambda: Rotation.from_rotvec(V),
    "from_mrp": lambda: Rotation.from_mrp(V / 4),
    "from_euler": lambda: Rotation.from_euler("ZXZ", V),
    "from_euler_1": lambda: Rotation.from_euler("x", V[:, :1]),
    "from_davenport": lambda: Rotation.from_davenport(np.eye(3), "e", V),
    "identity": lambda: Rotation.identity(5),
    "random": lambda: Rotation.random(5, rng=0),
    "random_key": lambda: Rotation.random(jax.random.key(0), 5),
    "concatenate": lambda: Rotation.concatenate(
        [Rotation.from_quat(Q[:2]), Rotation.from_rotvec(V[2:])]
    ),
    "mul": lambda: Rotation.from_quat(Q) * Rotation.from_rotvec(V),
    "pow": lambda: Rotation.from_quat(Q) ** 0.5,
    "inv": lambda: Rotation.from_quat(Q).inv(),
    "getitem": lambda: Rotation.from_quat(np.concatenate([Q, Q]))[::2][:5],
    "mean_axis": lambda: Rotation.from_quat(np.stack([Q, Q[::-1]], 1)).mean(axis=1),
    "reduce": lambda: Rotation.from_quat(Q).reduce(Rotation.create_group("T")),
    "group": lambda: Rotation.create_group("C5"),
    "slerp": lambda: Slerp(np.arange(5.0), Rotation.from_quat(Q))(np.arange(5.0) * 0.9),
    "spline": lambda: _spline(Rotation.from_quat(Q)),
    "pickle": lambda: __import__("pickle").loads(__import__("pickle").dumps(Rotation(Q))),
}


def _setitem():
    r = Rotation.from_rotvec(V)
    r[1] = Rotation.from_quat(Q[0])
    return r


BUILDERS["setitem"] = _setitem


def test_tree_structure_is_the_same_for_every_builder():
    ref = jax.tree_util.tree_structure(Rotation.identity(5))
    for name, build in BUILDERS.items():
        # Traced, not run (structure and shape are fixed by tracing); pickling needs values.
        r = build() if name == "pickle" else jax.eval_shape(build)
        assert r.shape == (5,), name
        assert jax.tree_util.tree_structure(r) == ref, name
    # Singles and other batch shapes differ only in the leaf's shape, not in the structure.
    for build in (
        lambda: Rotation.from_quat(Q[0]),
        lambda: Rotation.align_vectors(V, V[::-1])[0],
        lambda: Rotation.from_quat(Q).mean(),
    ):
        assert jax.tree_util.tree_structure(jax.eval_shape(build)) == ref


@pytest.mark.parametrize(
    "start", ["from_quat", "from_quat_jax", "Rotation(q)", "from_matrix", "identity", "random"]
)
def test_scan_carry_from_any_constructor(start):
    # The loop every attitude filter writes: the carry starts from a user's quaternion (not
    # unit), each step composes a rotation from a rotation vector.
    r0 = BUILDERS[start]()[0]
    omegas = np.random.default_rng(13).normal(size=(20, 3)) * 0.1

    def body(r, w):
        r = r * Rotation.from_rotvec(w)
        return r, r.magnitude()

    final, mags = jax.lax.scan(body, r0, omegas)
    ref = SR.from_quat(np.asarray(r0.as_quat()))
    for w in omegas:
        ref = ref * SR.from_rotvec(w)
    np.testing.assert_allclose(final.as_matrix(), ref.as_matrix(), atol=1e-13)
    np.testing.assert_allclose(mags[-1], ref.magnitude(), atol=1e-13)
    # Of order 1 after every step, whatever the norm of the start: a product is formed from
    # the prescaled factors (largest component in [0.5, 2), the step's unit), so its norm lies
    # in [0.5, 4) and cannot drift towards overflow or underflow over a long loop.
    assert 0.5 <= np.linalg.norm(final._stored) < 4


def test_scan_carry_under_jit_with_float32():
    q0 = jnp.asarray(Q[0] * 3, jnp.float32)
    omegas = jnp.asarray(np.random.default_rng(14).normal(size=(50, 3)) * 0.05, jnp.float32)

    @jax.jit
    def run(q0, omegas):
        return jax.lax.scan(
            lambda r, w: (r * Rotation.from_rotvec(w), None), Rotation.from_quat(q0), omegas
        )[0]

    final = run(q0, omegas)
    assert final.as_quat().dtype == jnp.float32
    ref = SR.from_quat(Q[0])
    for w in np.asarray(omegas, np.float64):
        ref = ref * SR.from_rotvec(w)
    np.testing.assert_allclose(final.as_matrix(), ref.as_matrix(), atol=2e-5)


@pytest.mark.parametrize("pick", [True, False])
def test_cond_between_two_constructors(pick):
    def f(pick, q, v):
        return jax.lax.cond(pick, lambda: Rotation.from_quat(q), lambda: Rotation.from_rotvec(v))

    r = jax.jit(f)(pick, Q, V)
    ref = SR.from_quat(Q) if pick else SR.from_rotvec(V)
    np.testing.assert_allclose(r.as_matrix(), ref.as_matrix(), atol=1e-13)
    # jnp.where-style selection through tree_map, eagerly
    r2 = jax.tree.map(
        lambda a, b: jnp.where(pick, a, b), Rotation.from_quat(Q), Rotation.from_euler("xyz", V)
    )
    ref2 = SR.from_quat(Q) if pick else SR.from_euler("xyz", V)
    np.testing.assert_allclose(r2.as_matrix(), ref2.as_matrix(), atol=1e-13)


def test_tree_map_over_two_rotations():
    a, b = Rotation.from_quat(Q), Rotation.from_rotvec(V)
    # The leaves are quaternions of any norm: their sum is a rotation (of the summed quaternion).
    s = jax.tree.map(lambda x, y: x + y, a, b)
    qa = Q / np.linalg.norm(Q, axis=-1, keepdims=True)
    np.testing.assert_allclose(
        s.as_matrix(), SR.from_quat(Q + SR.from_rotvec(V).as_quat()).as_matrix(), atol=1e-13
    )
    # tree_map with the leaves in the other order, and over a list of rotations
    avg = jax.tree.map(lambda *xs: sum(xs) / len(xs), a, Rotation.from_quat(qa))
    np.testing.assert_allclose(avg.as_matrix(), SR.from_quat(Q).as_matrix(), atol=1e-13)


def test_user_quaternion_keeps_its_derivative():
    # The leaf is the user's quaternion: grad of a reader is that of the function on q, and
    # grad of as_quat that of the normalisation (scipy normalises in from_quat).
    q = jnp.asarray(Q[1] * 2.5)
    g = jax.grad(lambda q: Rotation.from_quat(q).as_euler("xyz")[1])(q)
    g_ref = jax.grad(lambda q: rotjax.quaternion_to_euler(q, "xyz")[1])(q)
    np.testing.assert_allclose(g, g_ref, atol=1e-15)
    J = jax.jacfwd(lambda q: Rotation.from_quat(q).as_quat())(q)
    J_ref = jax.jacfwd(rotjax.quaternion_normalize)(q)
    np.testing.assert_allclose(J, J_ref, atol=1e-15)
    # ... and through a composition, against the product of the normalised quaternions
    J = jax.jacfwd(lambda q: (Rotation.from_quat(q) * Rotation.from_rotvec(V[0])).as_quat())(q)
    J_ref = jax.jacfwd(
        lambda q: rotjax.quaternion_multiply(
            rotjax.quaternion_normalize(q), rotjax.rotvec_to_quaternion(V[0])
        )
    )(q)
    np.testing.assert_allclose(J, J_ref, atol=1e-14)


def test_compose_at_extreme_scales():
    for scale in (1e-200, 1e200):
        p, q = jnp.asarray(Q * scale), jnp.asarray(Q[::-1] * scale)
        r = Rotation.from_quat(p) * Rotation.from_quat(q)
        ref = SR.from_quat(Q) * SR.from_quat(Q[::-1])
        np.testing.assert_allclose(r.as_matrix(), ref.as_matrix(), atol=1e-13)


def test_slerp_and_spline_tree_structure():
    t = np.arange(5.0)
    keys = [BUILDERS[n]() for n in ("from_quat", "from_rotvec", "identity", "mul")]
    for cls in (Slerp, RotationSpline):
        # traced, not run: the structure is known without computing
        shapes = [jax.eval_shape(lambda k=k: cls(t, k)) for k in keys]
        structs = {jax.tree_util.tree_structure(x) for x in shapes}
        assert len(structs) == 1, cls
        # cond between two interpolators built from different constructors (one program, with
        # the second interpolator's value as the reference)
        out, ref = jax.jit(
            lambda p: (
                jax.lax.cond(p, lambda: cls(t, keys[0]), lambda: cls(t, keys[1]))(2.5).as_matrix(),
                cls(t, keys[1])(2.5).as_matrix(),
            )
        )(False)
        np.testing.assert_allclose(out, ref, atol=1e-13)


def test_slerp_with_traced_keyframe_times():
    r = Rotation.from_quat(Q)
    t = np.array([0.0, 0.5, 2.0, 2.5, 4.0])
    at = np.array([0.1, 1.0, 2.2, 3.9])
    ref = Slerp(t, r)(at)
    out = jax.jit(lambda t, q: Slerp(t, Rotation.from_quat(q))(at))(t, Q)
    np.testing.assert_allclose(out.as_matrix(), ref.as_matrix(), atol=1e-13)
    np.testing.assert_allclose(ref.as_matrix(), _scipy_slerp(t, at), atol=1e-13)
    # jax.scipy's form: concrete JAX times closed over by a jitted function
    tj = jnp.asarray(t)
    out = jax.jit(lambda q: Slerp.init(tj, Rotation.from_quat(q))(at))(Q)
    np.testing.assert_allclose(out.as_matrix(), ref.as_matrix(), atol=1e-13)
    # the keyframe times are differentiable
    g = jax.grad(lambda t: Slerp(t, r)(1.0).magnitude())(jnp.asarray(t))
    assert np.all(np.isfinite(g)) and np.any(g != 0)
    # concrete times still get scipy's range check
    with pytest.raises(ValueError, match="within the range"):
        Slerp(jnp.asarray(t), r)(np.array([5.0]))


def _scipy_slerp(t, at):
    from scipy.spatial.transform import Slerp as SSlerp

    return SSlerp(t, SR.from_quat(Q))(at).as_matrix()


class _Other:
    """A stand-in for a class that composes with Rotation from either side."""

    def __mul__(self, other):
        return "other*" + type(other).__name__

    def __rmul__(self, other):
        return type(other).__name__ + "*other"

    def __rpow__(self, other):
        return "pow"


def test_unknown_operands_defer_to_the_other_class():
    r = Rotation.from_quat(Q)
    assert r * _Other() == "Rotation*other"
    assert _Other() * r == "other*Rotation"
    with pytest.raises(TypeError):
        r * 2.0
    with pytest.raises(TypeError):
        r * np.eye(3)
