"""Accuracy: the adversarial sets, their mpmath references, and the errors of a contender.

Errors are in eps of the dtype. Quaternions componentwise up to sign, against the mpmath
quaternion of the rotation nearest to the input matrix (the top eigenvector of the 4x4 ``K``,
Bar-Itzhack 2000); Euler angles as a backward error, the angle between the rotation of the
returned angles (evaluated in mpmath) and the input rotation; matrices and rotation vectors
componentwise. Every reference is computed at 40 digits on the exact values of the rounded
inputs.
"""

from __future__ import annotations


def mpmath40():
    import mpmath

    mpmath.mp.dps = 40
    return mpmath


def quats(rng, n):
    import numpy as np

    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return q * np.where(q[:, 3:] < 0, -1.0, 1.0)


def mp_quat_to_matrix(q):
    mp = mpmath40()
    return _mp_matrix(*(mp.mpf(float(c)) for c in q))


def _mp_matrix(x, y, z, w):
    s = 2 / (x * x + y * y + z * z + w * w)
    return [
        [1 - s * (y * y + z * z), s * (x * y - z * w), s * (x * z + y * w)],
        [s * (x * y + z * w), 1 - s * (x * x + z * z), s * (y * z - x * w)],
        [s * (x * z - y * w), s * (y * z + x * w), 1 - s * (x * x + y * y)],
    ]


def mp_optimal_quaternion(R):
    """Quaternion of the rotation nearest to ``R`` (top eigenvector of K), w >= 0, in mpmath."""
    mp = mpmath40()
    r = [[mp.mpf(float(R[i][j])) for j in range(3)] for i in range(3)]
    dx, dy = r[0][0] - r[1][1] - r[2][2], r[1][1] - r[0][0] - r[2][2]
    dz, dw = r[2][2] - r[0][0] - r[1][1], r[0][0] + r[1][1] + r[2][2]
    sxy, sxz, syz = r[0][1] + r[1][0], r[0][2] + r[2][0], r[1][2] + r[2][1]
    ax, ay, az = r[2][1] - r[1][2], r[0][2] - r[2][0], r[1][0] - r[0][1]
    K = mp.matrix(
        [
            [1 + dx, sxy, sxz, ax],
            [sxy, 1 + dy, syz, ay],
            [sxz, syz, 1 + dz, az],
            [ax, ay, az, 1 + dw],
        ]
    )
    E, Q = mp.eigsy(K)
    top = max(range(4), key=lambda i: E[i])
    q = [Q[i, top] for i in range(4)]
    return [-c for c in q] if q[3] < 0 else q


def mp_euler_quaternion(angles, seq):
    """Scalar-last quaternion of Euler angles (any of the 24 sequences), in mpmath."""
    mp = mpmath40()
    from .._euler import parse_seq

    axes, intrinsic = parse_seq(seq)

    def elem(ax, a):
        h = mp.mpf(float(a)) / 2
        c = [mp.mpf(0)] * 3 + [mp.cos(h)]
        c[ax] = mp.sin(h)
        return c

    qs = [elem(ax, a) for ax, a in zip(axes, angles, strict=True)]
    order = qs if intrinsic else qs[::-1]
    out = order[0]
    for nxt in order[1:]:
        out = mp_multiply(out, nxt)
    return out


def mp_multiply(p, q):
    px, py, pz, pw = p
    qx, qy, qz, qw = q
    return [
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
        pw * qw - px * qx - py * qy - pz * qz,
    ]


def mp_angle_between(p, q):
    """Angle between two (not necessarily unit) mpmath quaternions."""
    mp = mpmath40()
    x, y, z, w = mp_multiply([-p[0], -p[1], -p[2], p[3]], q)
    return 2 * mp.atan2(mp.sqrt(x * x + y * y + z * z), abs(w))


def quaternion_sets(rng, n):
    """Unit quaternions (float64, scalar last): the sets the quaternion inputs are drawn from."""
    import numpy as np

    def unit(v):
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    axes = unit(rng.normal(size=(n, 3)))
    small = 10.0 ** rng.uniform(-12, -3, size=(n, 1))
    near_id = unit(np.concatenate([axes * small, np.ones((n, 1))], axis=1))
    near_pi = unit(np.concatenate([axes, small * rng.choice([-1, 1], size=(n, 1))], axis=1))
    exact_pi = np.concatenate([axes, np.zeros((n, 1))], axis=1)
    # Two or more components of equal magnitude: the selection in Shepperd's method is a tie.
    ties = np.array([[0.5, 0.5, 0.5, 0.5], [0.5, -0.5, 0.5, 0.5], [0.5**0.5, 0.5**0.5, 0, 0]])
    ties = np.concatenate([ties, unit(rng.choice([-1.0, 1.0], size=(n, 4)))])[:n]
    ties = ties * np.where(ties[:, 3:] < 0, -1.0, 1.0)
    return {
        "uniform": quats(rng, n),
        "near_identity": near_id,
        "near_180": near_pi,
        "exact_180": exact_pi,
        "ties": ties,
    }


def gimbal_set(rng, per_seq, seqs, lo, hi):
    """``(seqs, quaternions)``: the middle angle at ``lo <= |distance to lock| <= hi``.

    Both lock values of every sequence are visited; ``lo = 0`` makes every other sample exact.
    """
    import numpy as np

    from .._euler import is_proper

    seq_of, qs = [], []
    for seq in seqs:
        locks = (0.0, np.pi) if is_proper(seq) else (np.pi / 2, -np.pi / 2)
        for k in range(per_seq):
            lock = locks[(k // 2) % 2]
            dist = (
                0.0
                if (lo == 0 and k % 2 == 0)
                else 10 ** rng.uniform(np.log10(max(lo, 1e-16)), np.log10(hi))
            )
            mid = lock + dist * (1 if lock <= 0 else -1)  # stay inside the angle's range
            a = [rng.uniform(-np.pi, np.pi), mid, rng.uniform(-np.pi, np.pi)]
            seq_of.append(seq)
            qs.append([float(c) for c in mp_euler_quaternion(a, seq)])
    return seq_of, np.array(qs)


def noisy(rng, n, sigma):
    R = np_matrix(quats(rng, n))
    return R + sigma * rng.normal(size=R.shape)


def np_matrix(q):
    """Float64 rotation matrices of unit quaternions (numpy, for inputs only)."""
    import numpy as np

    x, y, z, w = q.T
    return np.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
            2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
            2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
        ],
        axis=-1,
    ).reshape(-1, 3, 3)  # fmt: skip


# --- accuracy --------------------------------------------------------------------------------


def as_dtype(x, dtype):
    import jax.numpy as jnp
    import numpy as np

    return np.asarray(jnp.asarray(x, dtype=dtype)).astype(np.float64)  # cast in NumPy: no compile


def quat_err(got, ref):
    """Componentwise error up to sign (q and -q are one rotation)."""
    import numpy as np

    got = np.asarray(got, np.float64)
    return np.minimum(np.abs(got - ref).max(-1), np.abs(got + ref).max(-1))


class Accuracy:
    """Inputs and mpmath references on a subset of every set, built once per dtype."""

    def __init__(self, rng, n, per_seq, dtype, seqs):
        import jax.numpy as jnp
        import numpy as np

        self.dtype = dtype
        self.seqs = seqs
        self.eps = float(jnp.finfo(dtype).eps)
        self.qsets = {k: as_dtype(v, dtype) for k, v in quaternion_sets(rng, n).items()}
        # within 1e-12 of lock (half of them exact), and 1e-9..1e-7 away (scipy's threshold)
        self.gsets = {}
        for name, lo, hi in (("gimbal", 0.0, 1e-12), ("near_gimbal", 1e-9, 1e-7)):
            seq_of, qs = gimbal_set(rng, per_seq, seqs, lo, hi)
            self.gsets[name] = (seq_of, as_dtype(qs, dtype))
        self.msets = {k: as_dtype(np_matrix(v), dtype) for k, v in self.qsets.items()}
        self.msets["gimbal"] = as_dtype(np_matrix(self.gsets["gimbal"][1]), dtype)
        for sigma in (1e-8, 1e-4, 1e-2):
            self.msets[f"noisy_{sigma:g}"] = as_dtype(noisy(rng, n, sigma), dtype)
        mp_ = mpmath40()
        self.mq_ref = {
            k: np.array([[float(c) for c in mp_optimal_quaternion(R)] for R in v])
            for k, v in self.msets.items()
        }
        # exact rotations of the (rounded) input quaternions, for the backward errors
        self.q_mp = {
            k: [[mp_.mpf(float(c)) for c in q] for q in v]
            for k, v in {**self.qsets, **{g: v[1] for g, v in self.gsets.items()}}.items()
        }

    def eps_of(self, err):
        return err / self.eps


BASIC_SETS = ("uniform", "near_identity", "near_180")


class Evaluator:
    """One contender on the accuracy sets: ``run(x)`` and ``run_sets({name: x})`` return float64.

    ``compiled``: the contender's executable from the throughput columns, for a batch of
    ``batch`` rotations in rotjax's layout; the sets are padded to that batch and run through
    it, which saves a compilation (and XLA:CPU's code, so its rounding, can depend on the batch
    size). Without it, traced contenders are jitted once for all sets together.
    """

    def __init__(self, fn, impl, acc, jnp_dtype, compiled=None, batch=0):
        import jax

        self.fn, self.impl, self.acc, self.jnp_dtype = fn, impl, acc, jnp_dtype
        self.compiled, self.batch = compiled, batch
        self.f_jit = None if impl == "scipy" else jax.jit(fn)

    def run(self, x):
        """The contender on ``x``, an array or a tuple of arrays (the rows first in each)."""
        import jax
        import jax.numpy as jnp
        import numpy as np

        if self.impl == "scipy":
            # A writable copy: scipy's compiled from_rotvec rejects a read-only buffer.
            dt = np.float64 if self.acc.dtype == "float64" else np.float32
            return np.asarray(self.fn(jax.tree.map(lambda v: np.array(v, dt), x)))
        # Padding, slicing and casts in NumPy: as JAX ops, each new shape would compile.
        x = jax.tree.map(np.asarray, x)
        m = len(jax.tree.leaves(x)[0])
        padded = self.compiled is not None and m <= self.batch
        if padded:
            x = jax.tree.map(
                lambda v: np.concatenate(
                    [v, np.broadcast_to(v[:1], (self.batch - m, *v.shape[1:]))]
                ),
                x,
            )
        x = jax.tree.map(lambda v: jnp.asarray(v, dtype=self.jnp_dtype), x)
        out = self.compiled(x) if padded else self.f_jit(x)
        return np.asarray(out)[:m].astype(np.float64)

    def run_sets(self, sets):
        """``{name: output}`` of one call on the concatenation of ``{name: input}``."""
        import jax
        import numpy as np

        joined = jax.tree.map(lambda *vs: np.concatenate(vs), *sets.values())
        out = self.run(joined)
        ends = np.cumsum([len(jax.tree.leaves(v)[0]) for v in sets.values()])
        return dict(zip(sets, np.split(out, ends[:-1]), strict=True))


def errors(case, fn, impl, acc: Accuracy, jnp_dtype, compiled=None, batch=0):
    """``{set: errors in eps of the dtype}`` of one contender of ``case`` (see Evaluator)."""
    import numpy as np

    errs = case.accuracy(Evaluator(fn, impl, acc, jnp_dtype, compiled, batch))
    return {k: acc.eps_of(np.asarray(v, np.float64)) for k, v in errs.items()}


# --- error functions, one per kind of output: ``(Evaluator) -> {set: absolute errors}`` ------


def matrix_to_quaternion_errors(ev):
    """Componentwise, up to sign, against the quaternion of the nearest rotation (every set)."""
    acc = ev.acc
    return {k: quat_err(got, acc.mq_ref[k]) for k, got in ev.run_sets(acc.msets).items()}


def euler_errors(ev, quat):
    """Backward error: the angle between the rotation of the returned angles (in mpmath) and
    the input rotation, on the basic sets and both gimbal sets, every sequence of the run.

    ``quat``: the contender reads quaternions (else matrices)."""
    import numpy as np

    mp_ = mpmath40()
    acc = ev.acc
    names = BASIC_SETS
    gnames = tuple(acc.gsets)
    rows_of = {g: {} for g in gnames}  # set -> seq -> row indices
    for g in gnames:
        for i, s in enumerate(acc.gsets[g][0]):
            rows_of[g].setdefault(s, []).append(i)
    seqs = ["xyz"] if ev.impl == "jaxlie" else acc.seqs
    per = {k: [] for k in (*names, *gnames)}
    for s in seqs:  # one call per sequence on all sets together (one compilation)
        if quat:
            parts = [acc.qsets[k] for k in names]
            parts += [acc.gsets[g][1][rows_of[g][s]] for g in gnames]
            refs = [acc.q_mp[k] for k in names]
            refs += [[acc.q_mp[g][i] for i in rows_of[g][s]] for g in gnames]
        else:
            gm = {g: as_dtype(np_matrix(acc.gsets[g][1][rows_of[g][s]]), acc.dtype) for g in gnames}
            parts = [acc.msets[k] for k in names] + [gm[g] for g in gnames]
            qrefs = [acc.mq_ref[k] for k in names]
            qrefs += [[mp_optimal_quaternion(R) for R in gm[g]] for g in gnames]
            refs = [[[mp_.mpf(float(c)) for c in q] for q in qr] for qr in qrefs]
        ang = euler_call(ev.fn, ev.impl, np.concatenate(parts), s, ev.jnp_dtype)
        start = 0
        for k, ref in zip((*names, *gnames), refs, strict=True):
            a = ang[start : start + len(ref)]
            start += len(ref)
            per[k] += [
                float(mp_angle_between(mp_euler_quaternion(t, s), r))
                for t, r in zip(a, ref, strict=True)
            ]
    return {k: np.array(v) for k, v in per.items()}


def quaternion_to_euler_errors(ev):
    return euler_errors(ev, quat=True)


def matrix_to_euler_errors(ev):
    return euler_errors(ev, quat=False)


def quaternion_to_matrix_errors(ev):
    """Componentwise, against the matrix of the (rounded) input quaternion."""
    import numpy as np

    acc, errs = ev.acc, {}
    for k, got in ev.run_sets({k: acc.qsets[k] for k in BASIC_SETS}).items():
        ref = np.array(
            [[[float(c) for c in row] for row in mp_quat_to_matrix(q)] for q in acc.qsets[k]]
        )
        errs[k] = np.abs(got - ref).reshape(len(ref), -1).max(-1)
    return errs


def quaternion_apply_errors(ev):
    """Componentwise, against ``R(q) v`` of the (rounded) input quaternion and vector, for
    vectors ``v ~ N(0, I)``."""
    import numpy as np

    acc, rng = ev.acc, np.random.default_rng(11)
    sets = {
        k: (acc.qsets[k], as_dtype(rng.normal(size=(len(acc.qsets[k]), 3)), acc.dtype))
        for k in BASIC_SETS
    }
    errs = {}
    for k, got in ev.run_sets(sets).items():
        ref = []
        for q, v in zip(*sets[k], strict=True):
            m = mp_quat_to_matrix(q)
            ref.append([float(sum(r * float(c) for r, c in zip(row, v, strict=True))) for row in m])
        errs[k] = np.abs(got - np.array(ref)).max(-1)
    return errs


def nined_to_matrix_errors(ev):
    """Componentwise, against the matrix of the nearest rotation (the matrix sets)."""
    acc = ev.acc
    got = ev.run_sets({k: v.reshape(len(v), 9) for k, v in acc.msets.items()})
    return {
        k: abs(v - np_matrix(acc.mq_ref[k])).reshape(len(v), -1).max(-1) for k, v in got.items()
    }


def no_errors(ev):
    """No accuracy columns: these rows time a fitting problem or a series, whose accuracy the
    test suite checks against mpmath and closed-form motions."""
    return {}


def quaternion_to_rotvec_errors(ev):
    """Componentwise, against the rotation vector of angle in [0, pi]."""
    import numpy as np

    mp_ = mpmath40()
    acc, errs = ev.acc, {}
    for k, got in ev.run_sets({k: acc.qsets[k] for k in BASIC_SETS}).items():
        ref = []
        for q in acc.q_mp[k]:
            x, y, z, w = q if q[3] >= 0 else [-c for c in q]
            n = mp_.sqrt(x * x + y * y + z * z)
            s = 2 * mp_.atan2(n, w) / n if n != 0 else mp_.mpf(2) / w
            ref.append([float(s * c) for c in (x, y, z)])
        errs[k] = np.abs(got - np.array(ref)).max(-1)
    return errs


def _rotvec_sets(acc):
    """The rotation vectors of the basic sets, rounded to the dtype, and their exact (40-digit)
    scalar-last quaternions."""
    import numpy as np

    mp_ = mpmath40()
    vs = {
        k: as_dtype(np.array([rotvec_of(q) for q in acc.qsets[k]]), acc.dtype) for k in BASIC_SETS
    }
    exact = {}
    for k, v in vs.items():
        exact[k] = []
        for r in v:
            r = [mp_.mpf(float(c)) for c in r]
            t = mp_.sqrt(sum(c * c for c in r))
            k_ = mp_.sin(t / 2) / t if t != 0 else mp_.mpf(0.5)
            exact[k].append([k_ * c for c in r] + [mp_.cos(t / 2)])
    return vs, exact


def rotvec_to_quaternion_errors(ev):
    """Componentwise, up to sign, against the quaternion of the (rounded) rotation vector."""
    import numpy as np

    vs, exact = _rotvec_sets(ev.acc)
    return {
        k: quat_err(got, np.array([[float(c) for c in q] for q in exact[k]]))
        for k, got in ev.run_sets(vs).items()
    }


def rotvec_to_matrix_errors(ev):
    """Componentwise, against the matrix of the (rounded) rotation vector."""
    import numpy as np

    vs, exact = _rotvec_sets(ev.acc)
    errs = {}
    for k, got in ev.run_sets(vs).items():
        ref = np.array([[[float(c) for c in row] for row in _mp_matrix(*q)] for q in exact[k]])
        errs[k] = np.abs(got - ref).reshape(len(ref), -1).max(-1)
    return errs


def euler_angles_of(q, seq):
    """Float64 Euler angles of unit quaternions (scipy, for inputs only)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat(q).as_euler(seq)


def euler_to_matrix_errors(ev, seq):
    """Componentwise, against the product of the axis rotations of the (rounded) angles."""
    import numpy as np

    mp_ = mpmath40()
    acc, errs = ev.acc, {}
    sets = {k: as_dtype(euler_angles_of(acc.qsets[k], seq), acc.dtype) for k in BASIC_SETS}
    axes = ["xyz".index(c) for c in seq.lower()]
    for k, got in ev.run_sets(sets).items():
        ref = []
        for a in sets[k]:
            m = mp_.eye(3)
            for ax, angle in zip(axes, a, strict=True):
                c, s = mp_.cos(mp_.mpf(float(angle))), mp_.sin(mp_.mpf(float(angle)))
                e = mp_.eye(3)
                i, j = (ax + 1) % 3, (ax + 2) % 3
                e[i, i], e[i, j], e[j, i], e[j, j] = c, -s, s, c
                m = m * e if seq.isupper() else e * m  # intrinsic: R0 R1 R2; extrinsic: R2 R1 R0
            ref.append([[float(m[r, c]) for c in range(3)] for r in range(3)])
        errs[k] = np.abs(got - np.array(ref)).reshape(len(ref), -1).max(-1)
    return errs


def integration_step_errors(ev):
    """One step of dt = 0.01 s, omega ~ N(0, I) rad/s, against the exact exponential step."""
    import numpy as np

    mp_ = mpmath40()
    acc = ev.acc
    q = acc.qsets["uniform"]
    om = as_dtype(np.random.default_rng(7).normal(size=(len(q), 3)), acc.dtype)
    got = ev.run(np.concatenate([q, om], axis=1))
    ref = []
    for qi, oi in zip(q, om, strict=True):
        o = [mp_.mpf(float(c)) * mp_.mpf(0.01) for c in oi]
        t = mp_.sqrt(sum(c * c for c in o))
        dq = [mp_.sin(t / 2) / t * c for c in o] + [mp_.cos(t / 2)]
        ref.append([float(c) for c in mp_multiply([mp_.mpf(float(c)) for c in qi], dq)])
    return {"step_0.01": quat_err(got, np.array(ref))}


def rotvec_of(q):
    import numpy as np

    n = np.linalg.norm(q[:3])
    return q[:3] * (2 * np.arctan2(n, q[3]) / n if n > 0 else 2.0)


def euler_call(fn, impl, x, seq, jnp_dtype):
    """Euler angles of ``x`` (quaternions or matrices) for ``seq``, as float64 numpy."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    import rotjax as rj

    quat = x.shape[-1] == 4
    if impl == "rotjax":
        f = rj.quaternion_to_euler if quat else rj.matrix_to_euler
        return np.asarray(f(jnp.asarray(x, dtype=jnp_dtype), seq)).astype(np.float64)
    if impl in ("jax.scipy", "scipy-jax"):
        if impl == "jax.scipy":
            from jax.scipy.spatial.transform import Rotation as JR

            kw = {}
        else:  # scipy on JAX arrays, as timed (see cases.scipy_like)
            from scipy.spatial.transform import Rotation as JR

            kw = {"assume_valid": True}

        def f(xj):
            r = JR.from_quat(xj) if quat else JR.from_matrix(xj, **kw)
            return r.as_euler(seq)

        return np.asarray(jax.jit(f)(jnp.asarray(x, dtype=jnp_dtype)), np.float64)
    if impl == "scipy":
        import warnings

        from scipy.spatial.transform import Rotation

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # scipy warns at gimbal lock
            r = Rotation.from_quat(x) if quat else Rotation.from_matrix(x, assume_valid=True)
            return r.as_euler(seq)
    # jaxlie: its one sequence, jitted (as timed; one compilation rather than one per op)
    return np.asarray(jax.jit(fn)(jnp.asarray(x, dtype=jnp_dtype)), np.float64)
