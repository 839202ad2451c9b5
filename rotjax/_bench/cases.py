"""The operations and their contenders: ``CASES``, the one registry of the benchmark.

A contender maps the operation's input batch to its output in rotjax's convention (scalar-last
quaternions, angles in the order of the sequence); peers are adapted at the boundary. jaxlie is
timed in its own layout (``jaxlie``), the adapters serving only the accuracy columns.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from . import accuracy as A

SEQ = "xyz"  # throughput sequence (extrinsic roll-pitch-yaw, jaxlie's); accuracy: all 24


class Contender(NamedTuple):
    impl: str  # "rotjax", a peer's name ("scipy", "scipy-jax", "jax.scipy", "jaxlie")
    method: str  # rotjax's method=, or ""
    fn: Callable  # input batch -> output batch
    traceable: bool  # jitted and differentiated (False: called on NumPy arrays)


@dataclasses.dataclass(frozen=True)
class Case:
    """One row group of the benchmark.

    Attributes:
        op: the operation's name, as in the tables.
        input: the key of ``INPUTS`` that builds its input batch.
        contenders: ``peers -> [Contender]``; rotjax's first, its default method first of all.
        accuracy: ``Evaluator -> {set: absolute errors}`` (see ``accuracy``).
        quick: part of ``--quick``.
        low_precision: also measured in bfloat16 and float16 (``--quick``: only if ``quick``).
        grad: time ``jit(grad(sum(f)))`` too.
        jaxlie: ``SO3 -> (fn, pre)``: jaxlie's call in its own layout and the conversion of
            rotjax's input to it, done once outside the timing.
        eager: time one call on the batch's first element (False where that is not an input).
    """

    op: str
    input: str
    contenders: Callable
    accuracy: Callable
    quick: bool = False
    low_precision: bool = False
    grad: bool = True
    jaxlie: Callable | None = None
    eager: bool = True


# --- inputs: ``(rng, unit quaternions (n, 4) float64) -> float64 batch`` ------------------------


def _omega(rng, q):
    """A quaternion and an angular velocity (rad/s, N(0, I)) side by side: (n, 7)."""
    return np.concatenate([q, rng.normal(size=(len(q), 3))], axis=1)


# The fitting rows: one "rotation" of the batch is one problem of GROUP vector pairs or
# quaternions; the integrator's is one time step of a series of STEPS samples.
GROUP = 8
STEPS = 1024


def _vector_pairs(rng, q):
    """Problems of GROUP pairs ``(a_i, b_i)``, ``b_i = R a_i + noise``: two arrays (n, GROUP, 3),
    as a caller of ``align_vectors(a, b)`` holds them (slices of one interleaved array would be
    copied before the call)."""
    a = rng.normal(size=(len(q), GROUP, 3))
    b = np.einsum("nij,nkj->nki", A.np_matrix(q), a) + 0.01 * rng.normal(size=a.shape)
    return a, b


def _quaternion_groups(rng, q):
    """Groups of GROUP quaternions within about 0.1 rad of each other: (n, GROUP, 4)."""
    x = q[:, None, :] + 0.05 * rng.normal(size=(len(q), GROUP, 4))
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


INPUTS = {
    "quaternion": lambda rng, q: q,
    "matrix": lambda rng, q: A.np_matrix(q),
    "noisy_nined": lambda rng, q: (A.np_matrix(q) + 0.1 * rng.normal(size=(len(q), 3, 3))).reshape(
        -1, 9
    ),
    "rotvec": lambda rng, q: 0.7 * rng.normal(size=(len(q), 3)),
    "quaternion_omega": _omega,
    "vector_pairs": _vector_pairs,
    "quaternion_groups": _quaternion_groups,
    "omega": lambda rng, q: rng.normal(size=(len(q), 3)),
}


# --- contenders ------------------------------------------------------------------------------


def peers():
    """Importable peers, by name. ``"scipy-jax"`` is scipy's ``Rotation`` on JAX arrays, present
    when scipy was imported with ``SCIPY_ARRAY_API=1`` (the benchmark's child process sets it)
    and keeps a JAX array a JAX array; ``"scipy"`` is the same class on NumPy arrays."""
    out = {}
    try:
        from scipy.spatial.transform import Rotation

        out["scipy"] = Rotation
        if scipy_accepts_jax(Rotation):
            out["scipy-jax"] = Rotation
    except ImportError:  # pragma: no cover - scipy is a bench extra
        pass
    try:
        from jax.scipy.spatial.transform import Rotation as JRotation

        out["jax.scipy"] = JRotation
    except ImportError:  # pragma: no cover
        pass
    try:
        import jaxlie

        out["jaxlie"] = jaxlie
    except ImportError:  # pragma: no cover
        pass
    return out


def scipy_accepts_jax(Rotation) -> bool:
    """Whether ``Rotation`` computes on JAX arrays, under ``jax.jit`` (scipy >= 1.17 with
    ``SCIPY_ARRAY_API=1`` set before scipy was first imported); otherwise it converts them to
    NumPy, and a traced array fails the conversion."""
    import jax
    import jax.numpy as jnp

    try:
        out = jax.jit(lambda q: Rotation.from_quat(q).as_matrix())(jnp.eye(4)[3:])
    except Exception:  # noqa: BLE001 - any failure means: not on JAX arrays
        return False
    return isinstance(out, jax.Array)


def rotjax_fn(name, method="", *args):
    """rotjax's function ``name`` as a contender: ``f(x, *args, method=method)``."""
    import rotjax as rj

    fn = getattr(rj, name)
    kw = {"method": method} if method else {}
    return Contender("rotjax", method, lambda x: fn(x, *args, **kw), True)


def scipy_like(peers, build: str, read: str, *args):
    """jax.scipy, scipy on JAX arrays and scipy on NumPy arrays as
    ``Rotation.<build>(x).<read>(*args)``.

    scipy builds from a matrix with ``assume_valid=True``, as rotjax's conversions do not
    project either: its default projects by an SVD every matrix under ``jit``, and on NumPy
    arrays every matrix that is not orthogonal to within 1e-12 (every float32 matrix).
    """
    out = []
    for name, traceable in (("jax.scipy", True), ("scipy-jax", True), ("scipy", False)):
        if name in peers:
            R = peers[name]
            kw = {"assume_valid": True} if name != "jax.scipy" and build == "from_matrix" else {}
            out.append(
                Contender(
                    name,
                    "",
                    lambda x, R=R, kw=kw: getattr(getattr(R, build)(x, **kw), read)(*args),
                    traceable,
                )
            )
    return out


def jaxlie_reader(peers, read):
    """jaxlie on scalar-last quaternions: ``read(SO3(wxyz))`` per rotation."""
    if "jaxlie" not in peers:
        return []
    import jax
    import jax.numpy as jnp

    SO3 = peers["jaxlie"].SO3
    fn = jax.vmap(lambda v: read(SO3(jnp.roll(v, 1))))
    return [Contender("jaxlie", "", fn, True)]


def jaxlie_builder(peers, build: str):
    """jaxlie's ``SO3.<build>`` per rotation, returned as scalar-last quaternions."""
    if "jaxlie" not in peers:
        return []
    import jax
    import jax.numpy as jnp

    fn = getattr(peers["jaxlie"].SO3, build)
    return [Contender("jaxlie", "", lambda x: jnp.roll(jax.vmap(fn)(x).wxyz, -1, -1), True)]


def rotation_class(build: str, read: str, *args):
    """``rotjax.Rotation.<build>(x).<read>(*args)``: the class against its functions."""
    from .. import Rotation

    return Contender(
        "rotjax", "Rotation", lambda x: getattr(getattr(Rotation, build)(x), read)(*args), True
    )


def ordered(*groups):
    """rotjax first, in the order given, then jax.scipy, jaxlie, scipy on JAX, scipy (the
    tables' order)."""
    rank = {"rotjax": 0, "jax.scipy": 1, "jaxlie": 2, "scipy-jax": 3, "scipy": 4}
    return sorted((c for g in groups for c in g), key=lambda c: rank.get(c.impl, 5))


def _rpy(r):
    import jax.numpy as jnp

    rpy = r.as_rpy_radians()  # roll, pitch, yaw are the extrinsic "xyz" angles
    return jnp.stack([rpy.roll, rpy.pitch, rpy.yaw], axis=-1)


def _integrate(method):
    from .._kinematics import integrate_angular_velocity

    def f(x):
        return integrate_angular_velocity(x[..., :4], x[..., 4:], 0.01, method=method)

    return Contender("rotjax", method, f, True)


def _integrate_samples(method):
    from .._kinematics import integrate_angular_velocity_samples

    def f(x):  # (n, 3) -> STEPS samples of n / STEPS series, from the identity
        omega = x.reshape(STEPS, -1, 3)
        q0 = np.array([0.0, 0.0, 0.0, 1.0], x.dtype)
        q = integrate_angular_velocity_samples(q0, omega, 0.01, method=method)
        return q.reshape(-1, 4)

    return Contender("rotjax", method, f, True)


def _align(x, method="svd"):
    from .. import align_vectors

    a, b = x
    return align_vectors(a, b, method=method)


def _bare_svd_of_b(x):
    """A batched SVD of the problems' ``B = sum_i b_i a_i^T``: the LAPACK baseline."""
    import jax.numpy as jnp

    a, b = x
    return jnp.linalg.svd(jnp.einsum("...ki,...kj->...ij", a, b))


def _bare_svd_projection(x):
    """The special-orthogonal polar factor by a batched SVD: ``U diag(1, 1, det) V^T``."""
    import jax.numpy as jnp

    u, _, vt = jnp.linalg.svd(x.reshape(*x.shape[:-1], 3, 3))
    d = jnp.linalg.det(u @ vt)
    return (u * jnp.stack([jnp.ones_like(d), jnp.ones_like(d), d], axis=-1)[..., None, :]) @ vt


def _bare_eigh_mean(q):
    """The top eigenvector of ``sum_i q_i q_i^T`` by a batched ``eigh``: the LAPACK baseline."""
    import jax.numpy as jnp

    return jnp.linalg.eigh(jnp.einsum("...ki,...kj->...ij", q, q))[1][..., -1]


# --- jaxlie in its own layout: ``SO3 -> (fn, pre)`` ------------------------------------------


def _jaxlie_native(body, pre):
    def make(SO3):
        import jax

        return jax.vmap(lambda x: body(SO3, x)), pre

    return make


def _roll_first(q):
    import jax.numpy as jnp

    return jnp.roll(q, 1, axis=-1)


def _same(x):
    return x


# --- the registry ----------------------------------------------------------------------------

CASES = {
    c.op: c
    for c in [
        Case(
            "matrix_to_quaternion",
            "matrix",
            lambda p: ordered(
                [rotjax_fn("matrix_to_quaternion", m) for m in ("shepperd", "markley", "optimal")],
                scipy_like(p, "from_matrix", "as_quat"),
                jaxlie_builder(p, "from_matrix"),
            ),
            A.matrix_to_quaternion_errors,
            quick=True,
            low_precision=True,
            jaxlie=_jaxlie_native(lambda SO3, R: SO3.from_matrix(R).wxyz, _same),
        ),
        Case(
            "quaternion_to_euler",
            "quaternion",
            lambda p: ordered(
                [rotjax_fn("quaternion_to_euler", "", SEQ)],
                [rotation_class("from_quat", "as_euler", SEQ)],
                scipy_like(p, "from_quat", "as_euler", SEQ),
                jaxlie_reader(p, _rpy),
            ),
            A.quaternion_to_euler_errors,
            quick=True,
            low_precision=True,
            jaxlie=_jaxlie_native(lambda SO3, v: SO3(v).as_rpy_radians(), _roll_first),
        ),
        Case(
            "matrix_to_euler",
            "matrix",
            lambda p: ordered(
                [rotjax_fn("matrix_to_euler", "", SEQ)],
                [c for c in scipy_like(p, "from_matrix", "as_euler", SEQ) if c.impl != "jax.scipy"],
            ),
            A.matrix_to_euler_errors,
        ),
        Case(
            "quaternion_to_matrix",
            "quaternion",
            lambda p: ordered(
                [rotjax_fn("quaternion_to_matrix")],
                [rotation_class("from_quat", "as_matrix")],
                scipy_like(p, "from_quat", "as_matrix"),
                jaxlie_reader(p, lambda r: r.as_matrix()),
            ),
            A.quaternion_to_matrix_errors,
            quick=True,
            jaxlie=_jaxlie_native(lambda SO3, v: SO3(v).as_matrix(), _roll_first),
        ),
        Case(
            "quaternion_to_rotvec",
            "quaternion",
            lambda p: ordered(
                [rotjax_fn("quaternion_to_rotvec")],
                scipy_like(p, "from_quat", "as_rotvec"),
                jaxlie_reader(p, lambda r: r.log()),
            ),
            A.quaternion_to_rotvec_errors,
            jaxlie=_jaxlie_native(lambda SO3, v: SO3(v).log(), _roll_first),
        ),
        Case(
            "rotvec_to_quaternion",
            "rotvec",
            lambda p: ordered(
                [rotjax_fn("rotvec_to_quaternion")],
                [rotation_class("from_rotvec", "as_quat")],
                scipy_like(p, "from_rotvec", "as_quat"),
                jaxlie_builder(p, "exp"),
            ),
            A.rotvec_to_quaternion_errors,
            jaxlie=_jaxlie_native(lambda SO3, v: SO3.exp(v).wxyz, _same),
        ),
        Case(
            "integrate_angular_velocity",
            "quaternion_omega",
            lambda p: [_integrate(m) for m in ("euler", "rk4", "exponential")],
            A.integration_step_errors,
            quick=True,
            grad=False,
        ),
        Case(
            "integrate_angular_velocity_samples",
            "omega",
            lambda p: [_integrate_samples(m) for m in ("magnus4", "trapezoid", "hold")],
            A.no_errors,
            eager=False,
        ),
        Case(
            "nined_to_matrix",
            "noisy_nined",
            lambda p: [
                rotjax_fn("nined_to_matrix"),
                Contender("jnp.linalg", "svd", _bare_svd_projection, True),
            ],
            A.nined_to_matrix_errors,
        ),
        Case(
            "align_vectors",
            "vector_pairs",
            lambda p: [
                Contender("rotjax", "svd", _align, True),
                Contender("jnp.linalg", "svd of B", _bare_svd_of_b, True),
            ],
            A.no_errors,
        ),
        Case(
            "quaternion_mean",
            "quaternion_groups",
            lambda p: [
                rotjax_fn("quaternion_mean"),
                Contender("jnp.linalg", "eigh", _bare_eigh_mean, True),
            ],
            A.no_errors,
        ),
    ]
}
