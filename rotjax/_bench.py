"""``python -m rotjax bench [--quick] [--out DIR]``: the speed/accuracy benchmark.

For every operation, method and dtype it measures, in one process and against the peers that
are importable (scipy ``Rotation``, ``jax.scipy.spatial.transform.Rotation``, jaxlie ``SO3``):

* jitted throughput on a batch (2^20 rotations; 2^16 with ``--quick``), as the median over
  interleaved rounds, and as a fraction of a *copy* kernel that reads and writes the same bytes
  (36 B in and 16 B out for a float32 matrix to quaternion) with one add per output value;
* the latency of one eager call on a single rotation, interleaved with scipy's;
* compile time (lowering plus XLA compilation);
* throughput of ``jit(grad(sum(f)))`` and its ratio to the forward pass (same rounds);
* max and median error in eps of the dtype against an mpmath reference on a subset of every
  adversarial set (uniform, near identity, near and exactly 180 degrees, largest-component ties,
  within 1e-12 of gimbal lock in all 24 sequences, noisy matrices with sigma 1e-8, 1e-4, 1e-2).

Errors: quaternions componentwise up to sign, against the mpmath quaternion of the rotation
nearest to the input matrix (the top eigenvector of the 4x4 ``K``, Bar-Itzhack 2000); Euler
angles as a backward error, the angle between the rotation of the returned angles (evaluated in
mpmath) and the input rotation; matrices and rotation vectors componentwise. The JAX
contenders' errors come from the executable whose throughput is reported (the sets padded to
its batch; XLA:CPU's code, and so its rounding, can depend on the batch size), except jaxlie's,
timed in its own layout and jitted apart for the sets, and the Euler sequences other than the
timed one.

``--quick`` (CI, and a first look): a batch of 2^16, three rounds, 8 rotations per set, two
sequences, four operations; bfloat16/float16 for matrix_to_quaternion only; gradients of
rotjax's default methods only; single-call latency of rotjax and scipy only (a JAX peer's first
eager call compiles op by op, which costs seconds).

Ratios are medians of per-round ratios, which cancel most of the drift of a noisy machine.
glibc returns large freed buffers to the system and maps fresh ones, so every call would pay
page faults for its output: the benchmark runs in a child process with
``MALLOC_MMAP_THRESHOLD_`` and ``MALLOC_TRIM_THRESHOLD_`` pinned, unless they are already set.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

_MALLOC_ENV = {"MALLOC_MMAP_THRESHOLD_": str(1 << 30), "MALLOC_TRIM_THRESHOLD_": str(1 << 30)}
LETTER_SEQS = [a + b + c for a in "xyz" for b in "xyz" for c in "xyz" if a != b and b != c]
SEQS = LETTER_SEQS + [s.upper() for s in LETTER_SEQS]
COLUMNS = (
    "op",
    "impl",
    "method",
    "dtype",
    "mrot_s",
    "vs_copy",
    "vs_rotjax",
    "eager_us",
    "eager_vs_scipy",
    "compile_s",
    "grad_mrot_s",
    "grad_over_fwd",
    "err_max_eps",
    "err_median_eps",
    "err_by_set",
)


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# --- inputs and mpmath references ------------------------------------------------------------


def _mp():
    import mpmath

    mpmath.mp.dps = 40
    return mpmath


def _quats(rng, n):
    import numpy as np

    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return q * np.where(q[:, 3:] < 0, -1.0, 1.0)


def _mp_quat_to_matrix(q):
    mp = _mp()
    x, y, z, w = (mp.mpf(float(c)) for c in q)
    s = 2 / (x * x + y * y + z * z + w * w)
    return [
        [1 - s * (y * y + z * z), s * (x * y - z * w), s * (x * z + y * w)],
        [s * (x * y + z * w), 1 - s * (x * x + z * z), s * (y * z - x * w)],
        [s * (x * z - y * w), s * (y * z + x * w), 1 - s * (x * x + y * y)],
    ]


def _mp_optimal_quaternion(R):
    """Quaternion of the rotation nearest to ``R`` (top eigenvector of K), w >= 0, in mpmath."""
    mp = _mp()
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


def _mp_euler_quaternion(angles, seq):
    """Scalar-last quaternion of Euler angles (any of the 24 sequences), in mpmath."""
    mp = _mp()
    from ._euler import parse_seq

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
        out = _mp_multiply(out, nxt)
    return out


def _mp_multiply(p, q):
    px, py, pz, pw = p
    qx, qy, qz, qw = q
    return [
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
        pw * qw - px * qx - py * qy - pz * qz,
    ]


def _mp_angle_between(p, q):
    """Angle between two (not necessarily unit) mpmath quaternions."""
    mp = _mp()
    x, y, z, w = _mp_multiply([-p[0], -p[1], -p[2], p[3]], q)
    return 2 * mp.atan2(mp.sqrt(x * x + y * y + z * z), abs(w))


def _quaternion_sets(rng, n):
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
        "uniform": _quats(rng, n),
        "near_identity": near_id,
        "near_180": near_pi,
        "exact_180": exact_pi,
        "ties": ties,
    }


def _gimbal_set(rng, per_seq, seqs, lo, hi):
    """``(seqs, quaternions)``: the middle angle at ``lo <= |distance to lock| <= hi``.

    Both lock values of every sequence are visited; ``lo = 0`` makes every other sample exact.
    """
    import numpy as np

    from ._euler import is_proper

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
            qs.append([float(c) for c in _mp_euler_quaternion(a, seq)])
    return seq_of, np.array(qs)


def _noisy(rng, n, sigma):
    R = _np_matrix(_quats(rng, n))
    return R + sigma * rng.normal(size=R.shape)


def _np_matrix(q):
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


# --- contenders ------------------------------------------------------------------------------


def _peers():
    """Importable peers, by name."""
    peers = {}
    try:
        from scipy.spatial.transform import Rotation

        peers["scipy"] = Rotation
    except ImportError:  # pragma: no cover - scipy is a bench extra
        pass
    try:
        from jax.scipy.spatial.transform import Rotation as JRotation

        peers["jax.scipy"] = JRotation
    except ImportError:  # pragma: no cover
        pass
    try:
        import jaxlie

        peers["jaxlie"] = jaxlie
    except ImportError:  # pragma: no cover
        pass
    return peers


def _integrator():
    try:
        from ._kinematics import integrate_angular_velocity
    except ImportError:  # the kinematics module is optional for the benchmark
        return None
    return integrate_angular_velocity


def _quaternion_reader_peers(peers, scipy_as: str, jaxlie_read):
    """Peer contenders for an operation that reads a scalar-last quaternion: scipy and jax.scipy
    through ``Rotation.from_quat(q).<scipy_as>()``, jaxlie through ``jaxlie_read(SO3(wxyz))``."""
    import jax
    import jax.numpy as jnp

    out = []
    if "jax.scipy" in peers:
        out.append(
            ("jax.scipy", "", lambda q: getattr(peers["jax.scipy"].from_quat(q), scipy_as)(), True)
        )
    if "jaxlie" in peers:
        SO3 = peers["jaxlie"].SO3
        out.append(
            ("jaxlie", "", lambda q: jax.vmap(lambda v: jaxlie_read(SO3(jnp.roll(v, 1))))(q), True)
        )
    if "scipy" in peers:
        out.append(("scipy", "", lambda q: getattr(peers["scipy"].from_quat(q), scipy_as)(), False))
    return out


def _contenders(op, peers):
    """``[(impl, method, batch_fn, jax_traceable)]`` for an operation.

    ``batch_fn`` maps the op's input batch to its output in the rotjax convention (scalar-last
    quaternions, angles in the order of the sequence); peers are adapted at the boundary.
    """
    import jax
    import jax.numpy as jnp

    import rotjax as rj

    seq = "xyz"  # throughput sequence (extrinsic roll-pitch-yaw, jaxlie's); accuracy: all 24
    out = []
    if op == "matrix_to_quaternion":
        for m in ("shepperd", "markley", "optimal"):
            out.append(("rotjax", m, lambda R, m=m: rj.matrix_to_quaternion(R, method=m), True))
        if "jax.scipy" in peers:
            JR = peers["jax.scipy"]
            out.append(("jax.scipy", "", lambda R: JR.from_matrix(R).as_quat(), True))
        if "jaxlie" in peers:
            SO3 = peers["jaxlie"].SO3
            out.append(
                ("jaxlie", "", lambda R: jnp.roll(jax.vmap(SO3.from_matrix)(R).wxyz, -1, -1), True)
            )
        if "scipy" in peers:
            out.append(("scipy", "", lambda R: peers["scipy"].from_matrix(R).as_quat(), False))
    elif op in ("quaternion_to_euler", "matrix_to_euler"):
        fn = getattr(rj, op)
        out.append(("rotjax", "", lambda x, s=seq: fn(x, s), True))
        if op == "quaternion_to_euler":
            if "jax.scipy" in peers:
                JR = peers["jax.scipy"]
                out.append(("jax.scipy", "", lambda q, s=seq: JR.from_quat(q).as_euler(s), True))
            if "jaxlie" in peers:
                SO3 = peers["jaxlie"].SO3

                def jl(q):  # roll, pitch, yaw are the extrinsic "xyz" angles
                    rpy = jax.vmap(lambda v: SO3(jnp.roll(v, 1)).as_rpy_radians())(q)
                    return jnp.stack([rpy.roll, rpy.pitch, rpy.yaw], axis=-1)

                out.append(("jaxlie", "", jl, True))
            if "scipy" in peers:
                R_ = peers["scipy"]
                out.append(("scipy", "", lambda q, s=seq: R_.from_quat(q).as_euler(s), False))
        elif "scipy" in peers:
            R_ = peers["scipy"]
            out.append(("scipy", "", lambda R, s=seq: R_.from_matrix(R).as_euler(s), False))
    elif op == "quaternion_to_matrix":
        out.append(("rotjax", "", lambda q: rj.quaternion_to_matrix(q), True))
        out += _quaternion_reader_peers(peers, "as_matrix", lambda r: r.as_matrix())
    elif op == "quaternion_to_rotvec":
        out.append(("rotjax", "", lambda q: rj.quaternion_to_rotvec(q), True))
        out += _quaternion_reader_peers(peers, "as_rotvec", lambda r: r.log())
    elif op == "rotvec_to_quaternion":
        out.append(("rotjax", "", lambda v: rj.rotvec_to_quaternion(v), True))
        if "jax.scipy" in peers:
            out.append(
                ("jax.scipy", "", lambda v: peers["jax.scipy"].from_rotvec(v).as_quat(), True)
            )
        if "jaxlie" in peers:
            SO3 = peers["jaxlie"].SO3
            out.append(("jaxlie", "", lambda v: jnp.roll(jax.vmap(SO3.exp)(v).wxyz, -1, -1), True))
        if "scipy" in peers:
            out.append(("scipy", "", lambda v: peers["scipy"].from_rotvec(v).as_quat(), False))
    elif op == "integrate_angular_velocity":
        integrate = _integrator()
        for m in ("euler", "rk4", "exponential"):
            out.append(
                (
                    "rotjax",
                    m,
                    lambda x, m=m: integrate(x[..., :4], x[..., 4:], 0.01, method=m),
                    True,
                )
            )
    return out


def _jaxlie_native(op, SO3):
    """``(fn, pre)``: jaxlie's call in its own layout (scalar-first quaternions, rpy tuples)
    and the conversion of rotjax's input to it, done once outside the timing. The adapters in
    :func:`_contenders` (reordering inside the call) are used only for the accuracy columns.
    """
    import jax
    import jax.numpy as jnp

    def first(q):
        return jnp.roll(q, 1, axis=-1)

    def same(x):
        return x

    return {
        "matrix_to_quaternion": (lambda R: jax.vmap(SO3.from_matrix)(R).wxyz, same),
        "quaternion_to_euler": (jax.vmap(lambda v: SO3(v).as_rpy_radians()), first),
        "quaternion_to_matrix": (jax.vmap(lambda v: SO3(v).as_matrix()), first),
        "quaternion_to_rotvec": (jax.vmap(lambda v: SO3(v).log()), first),
        "rotvec_to_quaternion": (lambda v: jax.vmap(SO3.exp)(v).wxyz, same),
    }.get(op)


# Input and output widths (floats per rotation) of each operation, for the copy kernel.
_WIDTHS = {
    "matrix_to_quaternion": (9, 4),
    "matrix_to_euler": (9, 3),
    "quaternion_to_euler": (4, 3),
    "quaternion_to_matrix": (4, 9),
    "quaternion_to_rotvec": (4, 3),
    "rotvec_to_quaternion": (3, 4),
    "integrate_angular_velocity": (7, 4),
}


def _copy_kernel(n_in: int, n_out: int):
    """Reads ``n_in`` and writes ``n_out`` floats per rotation, one add per output value."""
    import jax.numpy as jnp

    def f(x):
        x = x.reshape(x.shape[0], n_in)
        if n_in >= n_out:  # fold the extra inputs into the outputs so that every byte is read
            out = x[:, :n_out]
            for k in range(n_out, n_in, n_out):
                chunk = x[:, k : k + n_out]
                out = out + (chunk if chunk.shape[1] == n_out else chunk[:, :1])
            return out
        reps = -(-n_out // n_in)
        return jnp.concatenate([x + x[:, :1]] * reps, axis=1)[:, :n_out]

    return f


def _input_shape(op):
    return {9: (3, 3), 4: (4,), 3: (3,), 7: (7,)}[_WIDTHS[op][0]]


# --- timing ----------------------------------------------------------------------------------


def _timed(f, x):
    import jax

    t = time.perf_counter()
    jax.block_until_ready(f(x))
    return time.perf_counter() - t


def _throughput_group(entries, rounds, slow_s=1.0, slow_rounds=3):
    """Interleaved rounds over every contender; returns ``{key: {round: seconds}}``.

    ``entries``: ``{key: (callable, input)}``. The order is rotated every round so that no
    contender always runs right after the same neighbour. A contender slower than ``slow_s`` per
    call (an eigendecomposition per matrix, say) sits out after ``slow_rounds`` rounds; its
    ratios are then medians over the rounds it ran in.
    """
    keys = list(entries)
    times = {k: {} for k in keys}
    for r in range(rounds):
        order = keys[r % len(keys) :] + keys[: r % len(keys)]
        for k in order:
            if r >= slow_rounds and statistics.median(times[k].values()) > slow_s:
                continue
            f, x = entries[k]
            times[k][r] = _timed(f, x)
    return times


def _median_ratio(num, den):
    """Median over shared rounds of ``num / den`` (dicts round -> seconds, or two lists)."""
    if isinstance(num, dict):
        shared = sorted(set(num) & set(den))
        return statistics.median(num[r] / den[r] for r in shared)
    return statistics.median(a / b for a, b in zip(num, den, strict=True))


def _total(out):
    """Sum of every output leaf (jaxlie returns a named tuple of angles)."""
    import jax
    import jax.numpy as jnp

    return sum(jnp.sum(leaf) for leaf in jax.tree.leaves(out))


def _median_time(t):
    return statistics.median(t.values())


# --- accuracy --------------------------------------------------------------------------------


def _as_dtype(x, dtype):
    import jax.numpy as jnp
    import numpy as np

    return np.asarray(jnp.asarray(x, dtype=dtype)).astype(np.float64)  # cast in NumPy: no compile


def _quat_err(got, ref):
    """Componentwise error up to sign (q and -q are one rotation)."""
    import numpy as np

    got = np.asarray(got, np.float64)
    return np.minimum(np.abs(got - ref).max(-1), np.abs(got + ref).max(-1))


class _Accuracy:
    """Inputs and mpmath references on a subset of every set, built once per dtype."""

    def __init__(self, rng, n, per_seq, dtype, seqs):
        import jax.numpy as jnp
        import numpy as np

        self.dtype = dtype
        self.seqs = seqs
        self.eps = float(jnp.finfo(dtype).eps)
        self.qsets = {k: _as_dtype(v, dtype) for k, v in _quaternion_sets(rng, n).items()}
        # within 1e-12 of lock (half of them exact), and 1e-9..1e-7 away (scipy's threshold)
        self.gsets = {}
        for name, lo, hi in (("gimbal", 0.0, 1e-12), ("near_gimbal", 1e-9, 1e-7)):
            seq_of, qs = _gimbal_set(rng, per_seq, seqs, lo, hi)
            self.gsets[name] = (seq_of, _as_dtype(qs, dtype))
        self.msets = {k: _as_dtype(_np_matrix(v), dtype) for k, v in self.qsets.items()}
        self.msets["gimbal"] = _as_dtype(_np_matrix(self.gsets["gimbal"][1]), dtype)
        for sigma in (1e-8, 1e-4, 1e-2):
            self.msets[f"noisy_{sigma:g}"] = _as_dtype(_noisy(rng, n, sigma), dtype)
        mp_ = _mp()
        self.mq_ref = {
            k: np.array([[float(c) for c in _mp_optimal_quaternion(R)] for R in v])
            for k, v in self.msets.items()
        }
        # exact rotations of the (rounded) input quaternions, for the backward errors
        self.q_mp = {
            k: [[mp_.mpf(float(c)) for c in q] for q in v]
            for k, v in {**self.qsets, **{g: v[1] for g, v in self.gsets.items()}}.items()
        }

    def eps_of(self, err):
        return err / self.eps


def _euler_backward(acc, angles, q_mp, seqs):
    """Angle (rad) between the rotation of each returned angle triple and the input rotation."""
    out = []
    for a, q, seq in zip(angles, q_mp, seqs, strict=True):
        out.append(float(_mp_angle_between(_mp_euler_quaternion(a, seq), q)))
    return out


_BASIC_SETS = ("uniform", "near_identity", "near_180")


def _accuracy(op, fn, impl, acc: _Accuracy, jnp_dtype, compiled=None, batch=0):
    """``{set: errors in eps}`` of one contender.

    ``compiled``: the contender's executable from the throughput columns, for a batch of
    ``batch`` rotations in rotjax's layout; the sets are padded to that batch and run through
    it, which saves a compilation. Without it, traced contenders are jitted for the sets.
    """
    import jax
    import jax.numpy as jnp
    import numpy as np

    # Traced contenders run jitted, as in the throughput columns, and once on all sets together:
    # one compilation (or none) per contender and dtype instead of one per set (or, eagerly,
    # per op).
    f_jit = None if impl == "scipy" else jax.jit(fn)

    def run(x):
        if impl == "scipy":
            # A writable copy: scipy's compiled from_rotvec rejects a read-only buffer (such as
            # a view of a JAX array), which had cost its float64 row its error columns.
            return np.asarray(fn(np.array(x, np.float64 if acc.dtype == "float64" else np.float32)))
        # Padding, slicing and casts in NumPy: as JAX ops, each new shape would compile.
        x, m = np.asarray(x), len(x)
        if compiled is not None and m <= batch:
            pad = np.broadcast_to(x[:1], (batch - m, *x.shape[1:]))
            out = compiled(jnp.asarray(np.concatenate([x, pad]), dtype=jnp_dtype))
        else:
            out = f_jit(jnp.asarray(x, dtype=jnp_dtype))
        return np.asarray(out)[:m].astype(np.float64)

    def run_sets(sets):
        """``{name: output}`` of one call on the concatenation of ``{name: input}``."""
        out = run(np.concatenate(list(sets.values())))
        ends = np.cumsum([len(v) for v in sets.values()])
        return dict(zip(sets, np.split(out, ends[:-1]), strict=True))

    errs = {}
    if op == "matrix_to_quaternion":
        for k, got in run_sets(acc.msets).items():
            errs[k] = _quat_err(got, acc.mq_ref[k])
    elif op in ("quaternion_to_euler", "matrix_to_euler"):
        mp_ = _mp()
        names = _BASIC_SETS
        gnames = tuple(acc.gsets)
        rows_of = {g: {} for g in gnames}  # set -> seq -> row indices
        for g in gnames:
            for i, s in enumerate(acc.gsets[g][0]):
                rows_of[g].setdefault(s, []).append(i)
        seqs = ["xyz"] if impl == "jaxlie" else acc.seqs
        per = {k: [] for k in (*names, *gnames)}
        for s in seqs:  # one call per sequence on all sets together (one compilation)
            if op == "quaternion_to_euler":
                parts = [acc.qsets[k] for k in names]
                parts += [acc.gsets[g][1][rows_of[g][s]] for g in gnames]
                refs = [acc.q_mp[k] for k in names]
                refs += [[acc.q_mp[g][i] for i in rows_of[g][s]] for g in gnames]
            else:
                gm = {
                    g: _as_dtype(_np_matrix(acc.gsets[g][1][rows_of[g][s]]), acc.dtype)
                    for g in gnames
                }
                parts = [acc.msets[k] for k in names] + [gm[g] for g in gnames]
                qrefs = [acc.mq_ref[k] for k in names]
                qrefs += [[_mp_optimal_quaternion(R) for R in gm[g]] for g in gnames]
                refs = [[[mp_.mpf(float(c)) for c in q] for q in qr] for qr in qrefs]
            ang = _euler_call(fn, impl, np.concatenate(parts), s, jnp_dtype)
            start = 0
            for k, ref in zip((*names, *gnames), refs, strict=True):
                a = ang[start : start + len(ref)]
                start += len(ref)
                per[k] += [
                    float(_mp_angle_between(_mp_euler_quaternion(t, s), r))
                    for t, r in zip(a, ref, strict=True)
                ]
        errs = {k: np.array(v) for k, v in per.items()}
    elif op == "quaternion_to_matrix":
        for k, got in run_sets({k: acc.qsets[k] for k in _BASIC_SETS}).items():
            ref = np.array(
                [[[float(c) for c in row] for row in _mp_quat_to_matrix(q)] for q in acc.qsets[k]]
            )
            errs[k] = np.abs(got - ref).reshape(len(ref), -1).max(-1)
    elif op == "quaternion_to_rotvec":
        mp_ = _mp()
        for k, got in run_sets({k: acc.qsets[k] for k in _BASIC_SETS}).items():
            ref = []
            for q in acc.q_mp[k]:
                x, y, z, w = q if q[3] >= 0 else [-c for c in q]  # angle in [0, pi]
                n = mp_.sqrt(x * x + y * y + z * z)
                s = 2 * mp_.atan2(n, w) / n if n != 0 else mp_.mpf(2) / w
                ref.append([float(s * c) for c in (x, y, z)])
            errs[k] = np.abs(got - np.array(ref)).max(-1)
    elif op == "rotvec_to_quaternion":
        mp_ = _mp()
        vs = {
            k: _as_dtype(np.array([_rotvec_of(q) for q in acc.qsets[k]]), acc.dtype)
            for k in _BASIC_SETS
        }
        for k, got in run_sets(vs).items():
            ref = []
            for r in vs[k]:
                r = [mp_.mpf(float(c)) for c in r]
                t = mp_.sqrt(sum(c * c for c in r))
                k_ = mp_.sin(t / 2) / t if t != 0 else mp_.mpf(0.5)
                ref.append([float(k_ * c) for c in r] + [float(mp_.cos(t / 2))])
            errs[k] = _quat_err(got, np.array(ref))
    elif op == "integrate_angular_velocity":
        # One step of dt = 0.01 s, omega ~ N(0, I) rad/s (|omega dt| about 0.016 rad on average,
        # up to about 0.04), against the exact exponential step in mpmath.
        mp_ = _mp()
        q = acc.qsets["uniform"]
        rng = np.random.default_rng(7)
        om = _as_dtype(rng.normal(size=(len(q), 3)), acc.dtype)
        x = np.concatenate([q, om], axis=1)
        got = run(x)
        ref = []
        for qi, oi in zip(q, om, strict=True):
            o = [mp_.mpf(float(c)) * mp_.mpf(0.01) for c in oi]
            t = mp_.sqrt(sum(c * c for c in o))
            dq = [mp_.sin(t / 2) / t * c for c in o] + [mp_.cos(t / 2)]
            ref.append([float(c) for c in _mp_multiply([mp_.mpf(float(c)) for c in qi], dq)])
        errs["step_0.01"] = _quat_err(got, np.array(ref))
    return {k: acc.eps_of(np.asarray(v, np.float64)) for k, v in errs.items()}


def _rotvec_of(q):
    import numpy as np

    n = np.linalg.norm(q[:3])
    return q[:3] * (2 * np.arctan2(n, q[3]) / n if n > 0 else 2.0)


def _euler_call(fn, impl, x, seq, jnp_dtype):
    """Euler angles of ``x`` (quaternions or matrices) for ``seq``, as float64 numpy."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    import rotjax as rj

    quat = x.shape[-1] == 4
    if impl == "rotjax":
        f = rj.quaternion_to_euler if quat else rj.matrix_to_euler
        return np.asarray(f(jnp.asarray(x, dtype=jnp_dtype), seq)).astype(np.float64)
    if impl == "jax.scipy":
        from jax.scipy.spatial.transform import Rotation as JR

        def f(xj):
            r = JR.from_quat(xj) if quat else JR.from_matrix(xj)
            return r.as_euler(seq)

        return np.asarray(jax.jit(f)(jnp.asarray(x, dtype=jnp_dtype)), np.float64)
    if impl == "scipy":
        import warnings

        from scipy.spatial.transform import Rotation

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # scipy warns at gimbal lock
            r = Rotation.from_quat(x) if quat else Rotation.from_matrix(x)
            return r.as_euler(seq)
    # jaxlie: its one sequence, jitted (as timed; one compilation rather than one per op)
    return np.asarray(jax.jit(fn)(jnp.asarray(x, dtype=jnp_dtype)), np.float64)


# --- the benchmark ---------------------------------------------------------------------------


def _finite_or_none(x):
    """JSON has no inf/NaN: infinite errors are written as null with the count kept apart."""
    x = float(x)
    return x if x == x and abs(x) != float("inf") else None


def _fmt(v, spec):
    width = int(spec.split(".")[0])
    return f"{'-':>{width}}" if v is None else format(v, spec)


def _table(rows):
    head = (
        f"{'operation':<27}{'impl':<10}{'method':<12}{'dtype':<9}{'Mrot/s':>8}{'%copy':>7}"
        f"{'x rotjax':>9}{'eager us':>9}{'x scipy':>8}{'compile s':>10}{'grad Mrot/s':>12}"
        f"{'grad/fwd':>9}{'max eps':>10}{'med eps':>9}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        pct = None if r["vs_copy"] is None else 100 * r["vs_copy"]
        lines.append(
            f"{r['op']:<27}{r['impl']:<10}{r['method'] or '-':<12}{r['dtype']:<9}"
            f"{_fmt(r['mrot_s'], '8.1f')}{_fmt(pct, '7.0f')}{_fmt(r['vs_rotjax'], '9.2f')}"
            f"{_fmt(r['eager_us'], '9.1f')}{_fmt(r['eager_vs_scipy'], '8.2f')}"
            f"{_fmt(r['compile_s'], '10.2f')}{_fmt(r['grad_mrot_s'], '12.1f')}"
            f"{_fmt(r['grad_over_fwd'], '9.2f')}{_fmt(r['err_max_eps'], '10.3g')}"
            f"{_fmt(r['err_median_eps'], '9.3g')}"
        )
    return "\n".join(lines)


def _eager(fn, x1, scipy_fn, x1_np, reps):
    """Median single-call latency (us) and its median per-round ratio to scipy's."""
    ts, ss = [], []
    for _ in range(reps):
        ts.append(_timed(fn, x1))
        if scipy_fn is not None:
            ss.append(_timed(scipy_fn, x1_np))
    med = statistics.median(ts) * 1e6
    return med, (_median_ratio(ts, ss) if ss else None)


def run(quick: bool, out_dir: Path, ops=None) -> list[dict]:
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    peers = _peers()
    n = 1 << (16 if quick else 20)
    rounds = 3 if quick else 21  # medians of per-round ratios: enough rounds to outvote bursts
    n_acc = 8 if quick else 96
    per_seq = 4 if quick else 8
    # Accuracy of Euler extraction: every sequence in a full run, one of each kind in --quick.
    seqs = ["xyz", "ZXZ"] if quick else SEQS
    eager_reps = 10 if quick else 100
    rng = np.random.default_rng(2024)
    q_batch = _quats(rng, n)
    inputs64 = {
        (4,): q_batch,
        (3, 3): _np_matrix(q_batch),
        (3,): np.array(0.7 * rng.normal(size=(n, 3))),
        (7,): np.concatenate([q_batch, rng.normal(size=(n, 3))], axis=1),
    }
    quick_ops = [
        "matrix_to_quaternion",
        "quaternion_to_euler",
        "quaternion_to_matrix",
        "integrate_angular_velocity",
    ]
    ops = (
        ops or quick_ops
        if quick
        else ops
        or [
            "matrix_to_quaternion",
            "quaternion_to_euler",
            "matrix_to_euler",
            "quaternion_to_matrix",
            "quaternion_to_rotvec",
            "rotvec_to_quaternion",
            "integrate_angular_velocity",
        ]
    )
    if _integrator() is None and "integrate_angular_velocity" in ops:
        _log("[bench] rotjax._kinematics not available: skipping integrate_angular_velocity")
        ops = [o for o in ops if o != "integrate_angular_velocity"]
    dtypes = ["float32", "float64"]
    # Also measured in bfloat16 and float16 (--quick: one op, which keeps that path exercised).
    low = {"matrix_to_quaternion"} if quick else {"matrix_to_quaternion", "quaternion_to_euler"}
    rows = []
    acc_cache = {}
    t_start = time.perf_counter()
    for op in ops:
        for dt in dtypes + (["bfloat16", "float16"] if op in low else []):
            _log(f"[bench {time.perf_counter() - t_start:6.1f}s] {op} {dt}")
            jdt = jnp.dtype(dt)
            shape = _input_shape(op)
            x_np = inputs64[shape].astype(np.float64 if dt == "float64" else np.float32)
            x_jax = jnp.asarray(inputs64[shape], dtype=jdt)
            x1 = np.array(x_jax[0])
            cont = _contenders(op, peers)
            if dt in ("bfloat16", "float16"):
                cont = [c for c in cont if c[0] == "rotjax" and not (quick and c[1] != cont[0][1])]
            entries, grads, compile_s = {}, {}, {}
            for impl, method, fn, traceable in cont:
                key = (impl, method)
                if not traceable:
                    entries[key] = (fn, x_np)
                    continue
                x_in, f_timed = x_jax, fn
                native = _jaxlie_native(op, peers["jaxlie"].SO3) if impl == "jaxlie" else None
                if native is not None:
                    f_timed, x_in = native[0], native[1](x_jax)
                jf = jax.jit(f_timed)
                t0 = time.perf_counter()
                try:
                    compiled = jf.lower(x_in).compile()
                except Exception as e:  # a peer without this dtype: leave it out of the group
                    _log(f"[bench]   {impl} {method}: not measured ({type(e).__name__})")
                    continue
                compile_s[key] = time.perf_counter() - t0
                entries[key] = (compiled, x_in)
                # --quick differentiates only rotjax's default method (compiling is the cost)
                want_grad = not quick or (impl == "rotjax" and method == cont[0][1])
                if (
                    want_grad
                    and dt in ("float32", "float64")
                    and op != "integrate_angular_velocity"
                ):
                    try:
                        g = jax.jit(jax.grad(lambda x, f=f_timed: _total(f(x))))
                        grads[key] = (g.lower(x_in).compile(), x_in)
                    except Exception as e:  # noqa: BLE001 - a peer that cannot be differentiated
                        _log(f"[bench]   {impl} {method}: no grad ({type(e).__name__})")
            copy_key = ("copy", "")
            entries[copy_key] = (jax.jit(_copy_kernel(*_WIDTHS[op])).lower(x_jax).compile(), x_jax)
            for key, g in grads.items():
                entries[("grad",) + key] = g
            for f, x in entries.values():  # warm up (first-call allocations)
                _timed(f, x)
            times = _throughput_group(entries, rounds)
            ref_key = next(k for k in entries if k[0] == "rotjax")
            scipy_eager = None
            for impl, _method, fn, _ in cont:
                if impl == "scipy":
                    scipy_eager = fn
            if dt not in acc_cache:
                _log(f"[bench {time.perf_counter() - t_start:6.1f}s]   mpmath references ({dt})")
                acc_cache[dt] = _Accuracy(np.random.default_rng(99), n_acc, per_seq, dt, seqs)
            acc = acc_cache[dt]
            for impl, method, fn, traceable in cont:
                key = (impl, method)
                if key not in entries:
                    continue
                t = times[key]
                row = dict.fromkeys(COLUMNS)
                row.update(op=op, impl=impl, method=method, dtype=dt)
                row["mrot_s"] = n / _median_time(t) / 1e6
                row["vs_copy"] = _median_ratio(times[copy_key], t)
                row["vs_rotjax"] = _median_ratio(times[ref_key], t)
                row["compile_s"] = compile_s.get(key)
                if ("grad",) + key in times:
                    tg = times[("grad",) + key]
                    row["grad_mrot_s"] = n / _median_time(tg) / 1e6
                    row["grad_over_fwd"] = _median_ratio(t, tg)
                # --quick times single calls of rotjax and scipy only: the JAX peers' first
                # eager call compiles op by op (seconds), and the targets compare with scipy.
                if dt in ("float32", "float64") and not (quick and impl in ("jax.scipy", "jaxlie")):
                    # One rotation, unbatched (jaxlie's adapters vmap, so they get a batch of 1).
                    # rotjax's public functions jit-wrap themselves; jax.scipy runs op by op.
                    x1_np = np.array(x1, np.float64 if dt == "float64" else np.float32)
                    x1_in = x1_np[None] if impl == "jaxlie" else x1_np
                    _timed(fn, x1_in)  # the first call compiles: not part of the latency
                    row["eager_us"], row["eager_vs_scipy"] = _eager(
                        fn, x1_in, scipy_eager, x1_np, eager_reps
                    )
                try:
                    # jaxlie's executable takes its own layout: it is jitted apart.
                    reuse = impl != "jaxlie" and key in entries and traceable
                    errs = _accuracy(op, fn, impl, acc, jdt, entries[key][0] if reuse else None, n)
                except Exception as e:  # noqa: BLE001 - report, do not hide
                    _log(f"[bench]   {impl} {method}: accuracy failed ({type(e).__name__}: {e})")
                    errs = {}
                # A non-finite result (NaN from an asin of a value just above 1, say) counts as
                # an infinite error, so it shows instead of vanishing from the maximum.
                errs = {k: np.where(np.isfinite(v), v, np.inf) for k, v in errs.items()}
                row["err_by_set"] = {
                    k: {"max": _finite_or_none(np.max(v)), "median": _finite_or_none(np.median(v))}
                    for k, v in errs.items()
                }
                clean = {k: v for k, v in errs.items() if not k.startswith("noisy")}
                if clean:
                    allv = np.concatenate(list(clean.values()))
                    row["err_max_eps"] = float(np.max(allv))
                    row["err_median_eps"] = float(np.median(allv))
                rows.append(row)
            copy_row = dict.fromkeys(COLUMNS)
            copy_row.update(op=op, impl="copy", method="limit", dtype=dt)
            copy_row["mrot_s"] = n / _median_time(times[copy_key]) / 1e6
            copy_row["vs_copy"] = 1.0
            copy_row["vs_rotjax"] = _median_ratio(times[ref_key], times[copy_key])
            rows.append(copy_row)
    return rows


def _machine():
    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return {"cpu": model, "cores": os.cpu_count(), "platform": platform.platform()}


def _plot(rows, path: Path) -> bool:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    panels = [
        ("matrix_to_quaternion", None, "matrix -> quaternion (clean sets)"),
        ("matrix_to_quaternion", "noisy_0.0001", "matrix -> quaternion (noise 1e-4, vs optimal)"),
        ("quaternion_to_euler", None, "quaternion -> Euler (backward error, all sets)"),
    ]
    fig, axes = plt.subplots(1, len(panels), figsize=(5 * len(panels), 4.2))
    markers = {"float32": "o", "float64": "s", "bfloat16": "^", "float16": "v"}
    for ax, (op, set_name, title) in zip(axes, panels, strict=True):
        for r in rows:
            if r["op"] != op or r["impl"] == "copy" or not r["err_by_set"]:
                continue
            if set_name is None:
                err = r["err_max_eps"]
            else:
                err = (r["err_by_set"].get(set_name) or {}).get("max")
            if err is None or r["mrot_s"] is None:
                continue
            label = r["impl"] + (f":{r['method']}" if r["method"] else "")
            ax.scatter(r["mrot_s"], max(err, 1e-2), marker=markers[r["dtype"]], s=40)
            ax.annotate(f"{label} {r['dtype'][-2:]}", (r["mrot_s"], max(err, 1e-2)), fontsize=7)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("throughput, Mrot/s (higher is better)")
        ax.set_ylabel("max error, eps of the dtype (lower is better)")
        ax.set_title(title, fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m rotjax bench", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--quick", action="store_true", help="small batch and subsets (CI)")
    parser.add_argument("--out", default="bench_out", help="directory for bench.json and bench.png")
    parser.add_argument("--ops", default=None, help="comma-separated subset of operations")
    args = parser.parse_args(argv)
    if any(os.environ.get(k) != v for k, v in _MALLOC_ENV.items()):
        # glibc reads these once, at start-up: run the measurement in a child that has them.
        env = {**os.environ, **_MALLOC_ENV}
        cmd = [
            sys.executable,
            "-m",
            "rotjax",
            "bench",
            *(argv if argv is not None else sys.argv[2:]),
        ]
        return subprocess.call(cmd, env=env)
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    import jax

    t0 = time.perf_counter()
    rows = run(args.quick, out_dir, args.ops.split(",") if args.ops else None)
    meta = {
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "machine": _machine(),
        "device": f"{jax.default_backend()}: {jax.devices()[0].device_kind}",
        "jax": jax.__version__,
        "quick": args.quick,
        "batch": 1 << (16 if args.quick else 20),
        "malloc_env": {k: os.environ.get(k) for k in _MALLOC_ENV},
        "seconds": None,
        "columns": list(COLUMNS),
    }
    meta["seconds"] = round(time.perf_counter() - t0, 1)
    table = _table(rows)  # before the JSON conversion: an infinite error prints as inf
    for r in rows:  # strict JSON: an infinite error (a NaN result) is written as null
        for k in ("err_max_eps", "err_median_eps"):
            if r[k] is not None:
                r[k] = _finite_or_none(r[k])
    text = json.dumps({"meta": meta, "rows": rows}, indent=1, allow_nan=False)
    (out_dir / "bench.json").write_text(text)
    (out_dir / "bench.txt").write_text(table + "\n")
    print(table)
    if _plot(rows, out_dir / "bench.png"):
        _log(f"[bench] wrote {out_dir / 'bench.png'}")
    _log(f"[bench] wrote {out_dir / 'bench.json'} in {meta['seconds']} s")
    return 0
