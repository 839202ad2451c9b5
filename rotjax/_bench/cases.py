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

    @property
    def label(self) -> str:
        """``impl`` and ``method``, as the compile-time and sweep tables name a contender."""
        return self.impl + (f" {self.method}" if self.method else "")


# Every operation in the first two; a case with ``low_precision`` in the other two as well.
DTYPES = ("float32", "float64", "bfloat16", "float16")


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
    "euler": lambda rng, q: A.euler_angles_of(q, SEQ),
    "quaternion_omega": _omega,
    # as a caller of quaternion_apply(q, v) holds them: two arrays (slices of one would be
    # copied before the call, and their cotangents padded back)
    "quaternion_vector": lambda rng, q: (q, rng.normal(size=(len(q), 3))),
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


def _scipy_peers(peers, call):
    """jax.scipy, scipy on JAX arrays and scipy on NumPy arrays, those in ``peers``, as
    contenders ``x -> call(name, Rotation, x)``."""
    return [
        Contender(name, "", lambda x, name=name, R=peers[name]: call(name, R, x), traceable)
        for name, traceable in (("jax.scipy", True), ("scipy-jax", True), ("scipy", False))
        if name in peers
    ]


def scipy_like(peers, build: str, read: str, *args):
    """jax.scipy, scipy on JAX arrays and scipy on NumPy arrays as
    ``Rotation.<build>(x).<read>(*args)``.

    scipy builds from a matrix with ``assume_valid=True``, as rotjax's conversions do not
    project either: its default projects by an SVD every matrix under ``jit``, and on NumPy
    arrays every matrix that is not orthogonal to within 1e-12 (every float32 matrix).
    """

    def call(name, R, x):
        kw = {"assume_valid": True} if name != "jax.scipy" and build == "from_matrix" else {}
        return getattr(getattr(R, build)(x, **kw), read)(*args)

    return _scipy_peers(peers, call)


def scipy_projecting(peers):
    """scipy on JAX arrays with its default ``from_matrix``, which projects every matrix onto
    SO(3) by an SVD under ``jit``: the peer of the projecting ``method="optimal"``."""
    if "scipy-jax" not in peers:
        return []
    R = peers["scipy-jax"]
    return [Contender("scipy-jax", "project", lambda x: R.from_matrix(x).as_quat(), True)]


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


def _jaxlie_exp_matrix(peers):
    """jaxlie's ``SO3.exp(v).as_matrix()`` per rotation."""
    if "jaxlie" not in peers:
        return []
    import jax

    SO3 = peers["jaxlie"].SO3
    return [Contender("jaxlie", "", jax.vmap(lambda v: SO3.exp(v).as_matrix()), True)]


def _jaxlie_rpy_matrix(peers):
    """jaxlie's ``SO3.from_rpy_radians(roll, pitch, yaw).as_matrix()`` per rotation (the
    extrinsic "xyz" angles)."""
    if "jaxlie" not in peers:
        return []
    import jax

    SO3 = peers["jaxlie"].SO3
    fn = jax.vmap(lambda a: SO3.from_rpy_radians(a[0], a[1], a[2]).as_matrix())
    return [Contender("jaxlie", "", fn, True)]


def _rotation_euler_matrix(x):
    from .. import Rotation

    return Rotation.from_euler(SEQ, x).as_matrix()


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
    from .._propagation import integrate_angular_velocity

    def f(x):
        return integrate_angular_velocity(x[..., :4], x[..., 4:], 0.01, method=method)

    return Contender("rotjax", method, f, True)


def _integrate_samples(method):
    from .._propagation import integrate_angular_velocity_samples

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


def _roll_quaternion_first(x):
    """``(q scalar last, v)`` to jaxlie's ``(wxyz, v)``."""
    import jax.numpy as jnp

    return jnp.roll(x[0], 1, axis=-1), x[1]


def _apply_contenders(p):
    """``R(q) v`` on ``(q, v)``: rotjax's function and class, jax.scipy, jaxlie, scipy."""
    import jax

    from .. import Rotation, quaternion_apply

    out = [
        Contender("rotjax", "", lambda x: quaternion_apply(*x), True),
        Contender("rotjax", "Rotation", lambda x: Rotation.from_quat(x[0]).apply(x[1]), True),
    ]
    out += _scipy_peers(p, lambda _, R, x: R.from_quat(x[0]).apply(x[1]))
    if "jaxlie" in p:
        SO3 = p["jaxlie"].SO3
        fn = jax.vmap(lambda x: _jaxlie_apply(SO3, x))
        out.append(Contender("jaxlie", "", lambda x: fn(_roll_quaternion_first(x)), True))
    return ordered(out)


def _jaxlie_apply(SO3, x):
    return SO3(x[0]) @ x[1]


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
                scipy_projecting(p),
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
            "rotvec_to_matrix",
            "rotvec",
            lambda p: ordered(
                [rotjax_fn("rotvec_to_matrix")],
                [rotation_class("from_rotvec", "as_matrix")],
                scipy_like(p, "from_rotvec", "as_matrix"),
                _jaxlie_exp_matrix(p),
            ),
            A.rotvec_to_matrix_errors,
            jaxlie=_jaxlie_native(lambda SO3, v: SO3.exp(v).as_matrix(), _same),
        ),
        Case(
            "euler_to_matrix",
            "euler",
            lambda p: ordered(
                [rotjax_fn("euler_to_matrix", "", SEQ)],
                [Contender("rotjax", "Rotation", _rotation_euler_matrix, True)],
                _scipy_peers(p, lambda name, R, x: R.from_euler(SEQ, x).as_matrix()),
                _jaxlie_rpy_matrix(p),
            ),
            lambda ev: A.euler_to_matrix_errors(ev, SEQ),
            jaxlie=_jaxlie_native(
                lambda SO3, a: SO3.from_rpy_radians(a[0], a[1], a[2]).as_matrix(), _same
            ),
        ),
        Case(
            "quaternion_apply",
            "quaternion_vector",
            _apply_contenders,
            A.quaternion_apply_errors,
            jaxlie=_jaxlie_native(_jaxlie_apply, _roll_quaternion_first),
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


# --- SE(3) and SO(3) Lie calculus ------------------------------------------------------------
# Exponential coordinates are rotjax's and scipy's [rotvec, v]; jaxlie's tangents are [v, rotvec]
# and its parameters [wxyz, xyz]: the adapters reorder at the boundary.


def _rotvecs(q):
    """Rotation vectors (angle in [0, pi]) of unit quaternions (n, 4), float64."""
    q = q * np.where(q[:, 3:] < 0, -1.0, 1.0)
    n = np.linalg.norm(q[:, :3], axis=-1, keepdims=True)
    safe = np.where(n > 0, n, 1.0)
    return q[:, :3] * np.where(n > 0, 2 * np.arctan2(n, q[:, 3:]) / safe, 2.0)


def _transforms(q, t):
    T = np.zeros((len(q), 4, 4))
    T[:, :3, :3], T[:, :3, 3], T[:, 3, 3] = A.np_matrix(q), t, 1.0
    return T


INPUTS.update(
    {
        # [rotvec, v]: uniform rotations (angles in [0, pi]), translations N(0, I)
        "exp_coords": lambda rng, q: np.concatenate(
            [_rotvecs(q), rng.normal(size=(len(q), 3))], axis=1
        ),
        "transform": lambda rng, q: _transforms(q, rng.normal(size=(len(q), 3))),
        # [quaternion, translation, point]: (n, 10)
        "pose_point": lambda rng, q: np.concatenate([q, rng.normal(size=(len(q), 6))], axis=1),
        # (quaternion, translation), two arrays as a caller holds them (slices of one array
        # would be padded back in reverse mode)
        "pose": lambda rng, q: (q, rng.normal(size=(len(q), 3))),
    }
)


def _rigid(x):
    """rotjax's RigidTransform of a (n, 10) [quaternion, translation, point] batch."""
    from .. import RigidTransform, Rotation

    return RigidTransform.from_components(x[..., 4:7], Rotation.from_quat(x[..., :4]))


def _scipy_rigid(peers):
    """scipy's ``RigidTransform`` (on NumPy arrays, and on JAX arrays where ``"scipy-jax"`` is
    among the peers), or None."""
    if "scipy" not in peers:
        return None
    from scipy.spatial.transform import RigidTransform

    return RigidTransform


def _se3_contenders(p, op, build, read, jaxlie_call):
    """rotjax's function ``op`` and its ``RigidTransform.<build>(x).<read>()``, jaxlie's
    ``jaxlie_call(SE3, x)`` per transform, and scipy's ``RigidTransform.<build>(x).<read>()``."""
    from .. import RigidTransform

    def via(cls):
        return lambda x: getattr(getattr(cls, build)(x), read)()

    out = [rotjax_fn(op), Contender("rotjax", "RigidTransform", via(RigidTransform), True)]
    if "jaxlie" in p:
        import jax

        SE3 = p["jaxlie"].SE3
        out.append(Contender("jaxlie", "", jax.vmap(lambda x: jaxlie_call(SE3, x)), True))
    S = _scipy_rigid(p)
    if S is not None:
        # On JAX arrays under jit (its from_matrix projects by an SVD, as rotjax's does), and
        # on NumPy arrays.
        if "scipy-jax" in p:
            out.append(Contender("scipy-jax", "", via(S), True))
        out.append(Contender("scipy", "", via(S), False))
    return ordered(out)


def _se3_exp_contenders(p):
    import jax.numpy as jnp

    return _se3_contenders(
        p,
        "se3_exp",
        "from_exp_coords",
        "as_matrix",
        lambda SE3, x: SE3.exp(jnp.roll(x, 3)).as_matrix(),
    )


def _se3_log_contenders(p):
    import jax.numpy as jnp

    return _se3_contenders(
        p,
        "se3_log",
        "from_matrix",
        "as_exp_coords",
        lambda SE3, T: jnp.roll(SE3.from_matrix(T).log(), 3),
    )


def _rigid_apply_contenders(p):
    out = [Contender("rotjax", "RigidTransform", lambda x: _rigid(x).apply(x[..., 7:]), True)]
    if "jaxlie" in p:
        import jax
        import jax.numpy as jnp

        jl = p["jaxlie"]

        def one(x):
            T = jl.SE3.from_rotation_and_translation(jl.SO3(jnp.roll(x[:4], 1)), x[4:7])
            return T.apply(x[7:])

        out.append(Contender("jaxlie", "", jax.vmap(one), True))
    S = _scipy_rigid(p)
    if S is not None:
        from scipy.spatial.transform import Rotation

        def scipy_apply(x):
            return S.from_components(x[..., 4:7], Rotation.from_quat(x[..., :4])).apply(x[..., 7:])

        if "scipy-jax" in p:
            out.append(Contender("scipy-jax", "", scipy_apply, True))
        out.append(Contender("scipy", "", scipy_apply, False))
    return ordered(out)


def _so3_jr_contenders(p):
    out = [rotjax_fn("so3_right_jacobian")]
    if "jaxlie" in p:
        import jax
        from jaxlie._so3 import _SO3_jac_left  # jaxlie's own (private) left Jacobian

        SO3 = p["jaxlie"].SO3
        fn = jax.vmap(lambda w: _SO3_jac_left(-w, SO3.exp(-w).as_matrix()))
        out.append(Contender("jaxlie", "jac_left(-w)", fn, True))
    return out


def _jlog_rotjax(q):
    from .. import quaternion_to_rotvec, so3_right_jacobian_inverse

    return so3_right_jacobian_inverse(quaternion_to_rotvec(q))


def _jlog_contenders(p):
    out = [Contender("rotjax", "Jr^-1(log q)", _jlog_rotjax, True)]
    if "jaxlie" in p:
        import jax
        import jax.numpy as jnp

        SO3 = p["jaxlie"].SO3
        out.append(
            Contender("jaxlie", "jlog", jax.vmap(lambda q: SO3(jnp.roll(q, 1)).jlog()), True)
        )
    return out


def _se3_jlog_rotjax(x):
    from .. import RigidTransform, Rotation, se3_right_jacobian_inverse

    T = RigidTransform.from_components(x[1], Rotation.from_quat(x[0]))
    return se3_right_jacobian_inverse(T.as_exp_coords())


def _wxyz_xyz(x):
    """``(q scalar last, t)`` to jaxlie's ``(n, 7)`` ``wxyz_xyz``."""
    import jax.numpy as jnp

    return jnp.concatenate(_roll_quaternion_first(x), axis=-1)


def _se3_jlog_contenders(p):
    out = [Contender("rotjax", "Jr^-1(log T)", _se3_jlog_rotjax, True)]
    if "jaxlie" in p:
        import jax
        import jax.numpy as jnp

        SE3 = p["jaxlie"].SE3
        perm = jnp.array([3, 4, 5, 0, 1, 2])  # jaxlie's [v, omega] order to [omega, v]

        def one(x):
            return SE3(x).jlog()[perm][:, perm]

        # timed on its own layout, without the permutation (the case's jaxlie form)
        out.append(Contender("jaxlie", "jlog", lambda x: jax.vmap(one)(_wxyz_xyz(x)), True))
    return out


def _jaxlie_se3(body, pre):
    """jaxlie's SE3 in its own layout (the registry hands over SO3; SE3 is its neighbour)."""

    def make(_SO3):
        import jax
        import jaxlie

        return jax.vmap(lambda x: body(jaxlie.SE3, x)), pre

    return make


def _wxyz_xyz_point(x):
    import jax.numpy as jnp

    return jnp.concatenate([jnp.roll(x[..., :4], 1, axis=-1), x[..., 4:]], axis=-1)


def _roll3(x):
    import jax.numpy as jnp

    return jnp.roll(x, 3, axis=-1)


# mpmath references (80 digits where a closed form cancels at tiny angles)


def _mp_lie():
    import mpmath

    return mpmath


def _mp_hat(w):
    mp = _mp_lie()
    x, y, z = w
    return mp.matrix([[0, -z, y], [z, 0, -x], [-y, x, 0]])


def _mp_so3(w, kind):
    """exp, Jl, Jr or Jr^-1 of a rotation vector (float list), at 80 digits."""
    mp = _mp_lie()
    with mp.workdps(80):
        w = [mp.mpf(float(c)) for c in w]
        K = _mp_hat(w)
        t = mp.sqrt(sum(c * c for c in w))
        K2 = K * K
        if t == 0:
            a, b, e = mp.mpf(1) / 2, mp.mpf(1) / 6, mp.mpf(1) / 12
        else:
            a, b = (1 - mp.cos(t)) / t**2, (t - mp.sin(t)) / t**3
            e = (1 - t / 2 * mp.cot(t / 2)) / t**2
        eye = mp.eye(3)
        if kind == "exp":
            out = eye + (mp.sin(t) / t if t else 1) * K + a * K2
        elif kind == "jl":
            out = eye + a * K + b * K2
        elif kind == "jr":
            out = eye - a * K + b * K2
        else:  # jr_inv
            out = eye + K / 2 + e * K2
        return np.array([[float(out[i, j]) for j in range(3)] for i in range(3)])


def _lie_sets(ev, cols):
    """The basic quaternion sets as rotation vectors (rounded to the dtype), with ``cols - 3``
    extra N(0, I) columns (translations, points), fixed per set."""
    acc = ev.acc
    rng = np.random.default_rng(35)
    out = {}
    for k in A.BASIC_SETS:
        w = _rotvecs(acc.qsets[k])
        extra = rng.normal(size=(len(w), cols - 3))
        out[k] = A.as_dtype(np.concatenate([w, extra], axis=1), acc.dtype)
    return out


def se3_exp_errors(ev):
    """Componentwise, against the 80-digit exp of the (rounded) coordinates."""
    sets = _lie_sets(ev, 6)
    errs = {}
    for k, got in ev.run_sets(sets).items():
        ref = []
        for x in sets[k]:
            R, V = _mp_so3(x[:3], "exp"), _mp_so3(x[:3], "jl")
            ref.append(_transforms_one(R, V @ x[3:]))
        errs[k] = np.abs(got - np.array(ref)).reshape(len(ref), -1).max(-1)
    return errs


def _transforms_one(R, t):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def se3_log_errors(ev):
    """Backward error: the 80-digit exp of the returned coordinates against the input matrix
    (near 180 degrees the direction of the log is ill-conditioned; its exp is not)."""
    sets = {}
    for k, x in _lie_sets(ev, 6).items():
        sets[k] = A.as_dtype(
            np.stack([_transforms_one(_mp_so3(r[:3], "exp"), r[3:]) for r in x]), ev.acc.dtype
        )
    errs = {}
    for k, got in ev.run_sets(sets).items():
        back = np.stack(
            [_transforms_one(_mp_so3(g[:3], "exp"), _mp_so3(g[:3], "jl") @ g[3:]) for g in got]
        )
        errs[k] = np.abs(back - sets[k]).reshape(len(got), -1).max(-1)
    return errs


def rigid_apply_errors(ev):
    """Componentwise, against R(q) v + t of the (rounded) inputs at 40 digits."""
    acc = ev.acc
    rng = np.random.default_rng(36)
    sets = {
        k: A.as_dtype(
            np.concatenate([acc.qsets[k], rng.normal(size=(len(acc.qsets[k]), 6))], 1), acc.dtype
        )
        for k in A.BASIC_SETS
    }
    errs = {}
    for k, got in ev.run_sets(sets).items():
        ref = []
        for x in sets[k]:
            R = A.mp_quat_to_matrix(x[:4])
            ref.append(
                [float(sum(R[i][j] * x[7 + j] for j in range(3)) + x[4 + i]) for i in range(3)]
            )
        errs[k] = np.abs(got - np.array(ref)).max(-1)
    return errs


def _mp_se3_jr_inv(w, t):
    """Jr^-1 of the SE(3) coordinates ``[w, Jl(w)^-1 t]`` of ``(exp(w), t)`` (float lists), at
    80 digits: the inverse of ``Jl(-xi) = sum_n ad(-xi)^n / (n + 1)!``, ``ad = [[W, 0], [V, W]]``
    for ``W = hat(w)``, ``V = hat(v)`` (independent of rotjax's closed forms)."""
    mp = _mp_lie()
    with mp.workdps(80):
        wm = [mp.mpf(float(c)) for c in w]
        K = _mp_hat(wm)
        th = mp.sqrt(sum(c * c for c in wm))
        a, b = ((1 - mp.cos(th)) / th**2, (th - mp.sin(th)) / th**3) if th else (0.5, 1 / 6.0)
        v = mp.lu_solve(mp.eye(3) + a * K + b * K * K, mp.matrix([float(c) for c in t]))
        V = _mp_hat([v[0], v[1], v[2]])
        ad = mp.zeros(6, 6)
        for i in range(3):
            for j in range(3):
                ad[i, j], ad[i + 3, j + 3], ad[i + 3, j] = -K[i, j], -K[i, j], -V[i, j]
        J, term = mp.zeros(6, 6), mp.eye(6)
        for n in range(60):  # |ad| <= pi + |v|: the terms fall below 1e-40
            J += term / mp.factorial(n + 1)
            term = term * ad
        out = mp.inverse(J)
        return np.array([[float(out[i, j]) for j in range(6)] for i in range(6)])


def se3_jlog_errors(ev):
    """Componentwise, against Jr^-1 of the log (angle in [0, pi]) of the (rounded) pose."""
    acc = ev.acc
    rng = np.random.default_rng(37)
    sets = {
        k: (acc.qsets[k], A.as_dtype(rng.normal(size=(len(acc.qsets[k]), 3)), acc.dtype))
        for k in A.BASIC_SETS
    }
    errs = {}
    for k, got in ev.run_sets(sets).items():
        qs, ts = sets[k]
        ref = np.stack([_mp_se3_jr_inv(w, t) for w, t in zip(_mp_rotvecs(qs), ts, strict=True)])
        errs[k] = np.abs(got - ref).reshape(len(got), -1).max(-1)
    return errs


def so3_right_jacobian_errors(ev):
    sets = {k: v[:, :3] for k, v in _lie_sets(ev, 3).items()}
    return {
        k: np.abs(got - np.stack([_mp_so3(w, "jr") for w in sets[k]])).reshape(len(got), -1).max(-1)
        for k, got in ev.run_sets(sets).items()
    }


def jlog_errors(ev):
    """Componentwise, against Jr^-1 of the log (angle in [0, pi]) of the (rounded) quaternion."""
    acc = ev.acc
    sets = {k: acc.qsets[k] for k in A.BASIC_SETS}
    return {
        k: np.abs(got - np.stack([_mp_so3(w, "jr_inv") for w in _mp_rotvecs(sets[k])]))
        .reshape(len(got), -1)
        .max(-1)
        for k, got in ev.run_sets(sets).items()
    }


def _mp_rotvecs(qs):
    """Rotation vectors (angle in [0, pi]) of quaternions, at 40 digits, as float lists."""
    mp = A.mpmath40()
    out = []
    for q in qs:
        x, y, z, w = (mp.mpf(float(c)) for c in q)
        if w < 0:
            x, y, z, w = -x, -y, -z, -w
        n = mp.sqrt(x * x + y * y + z * z)
        s = 2 * mp.atan2(n, w) / n if n != 0 else 2 / w
        out.append([float(s * c) for c in (x, y, z)])
    return out


CASES.update(
    {
        c.op: c
        for c in [
            Case(
                "se3_exp",
                "exp_coords",
                _se3_exp_contenders,
                se3_exp_errors,
                jaxlie=_jaxlie_se3(lambda SE3, x: SE3.exp(x).wxyz_xyz, _roll3),
            ),
            Case(
                "se3_log",
                "transform",
                _se3_log_contenders,
                se3_log_errors,
                jaxlie=_jaxlie_se3(lambda SE3, T: SE3.from_matrix(T).log(), _same),
            ),
            Case(
                "rigid_apply",
                "pose_point",
                _rigid_apply_contenders,
                rigid_apply_errors,
                jaxlie=_jaxlie_se3(lambda SE3, x: SE3(x[:7]).apply(x[7:]), _wxyz_xyz_point),
            ),
            Case("so3_right_jacobian", "rotvec", _so3_jr_contenders, so3_right_jacobian_errors),
            Case("so3_jlog", "quaternion", _jlog_contenders, jlog_errors),
            Case(
                "se3_jlog",
                "pose",
                _se3_jlog_contenders,
                se3_jlog_errors,
                jaxlie=_jaxlie_se3(lambda SE3, x: SE3(x).jlog(), _wxyz_xyz),
            ),
        ]
    }
)
