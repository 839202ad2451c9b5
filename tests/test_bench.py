"""Correctness of the speed/accuracy trade-off points and of the benchmark itself (no timing).

The references are the ones the benchmark uses (``rotjax._bench``): mpmath at 40 digits on the
exact values of the (rounded) inputs.
"""

from __future__ import annotations

import json
import warnings

import jax
import jax.numpy as jnp
import mpmath as mp
import numpy as np
import pytest
from helpers import SEQS, ulp
from jax.test_util import check_grads

import rotjax as rj
from rotjax import _bench as B

CLEAN_SETS = ["uniform", "near_identity", "near_180", "exact_180", "ties"]
# Documented componentwise bounds in eps on rotation matrices (see matrix_to_quaternion).
M2Q_BOUND = {"shepperd": 2.0, "markley": 2.0, "optimal": 2.0}


@pytest.fixture(scope="module")
def qsets():
    return B._quaternion_sets(np.random.default_rng(5), 16)


def _mp_quaternions(q):
    return [[mp.mpf(float(c)) for c in row] for row in q]


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("set_name", CLEAN_SETS + ["gimbal"])
@pytest.mark.parametrize("method", ["shepperd", "markley", "optimal"])
def test_matrix_to_quaternion_within_bound(qsets, method, set_name, dtype):
    if set_name == "gimbal":
        _, q = B._gimbal_set(np.random.default_rng(1), 2, ["xyz", "ZXZ"], 0.0, 1e-12)
    else:
        q = qsets[set_name]
    R = np.asarray(jnp.asarray(B._np_matrix(q), dtype=dtype)).astype(np.float64)
    ref = np.array([[float(c) for c in B._mp_optimal_quaternion(r)] for r in R])
    got = rj.matrix_to_quaternion(jnp.asarray(R, dtype=dtype), method=method)
    assert got.dtype == dtype
    err = B._quat_err(np.asarray(got, np.float64), ref) / ulp(dtype)
    assert np.all(np.isfinite(err))
    assert err.max() <= M2Q_BOUND[method], f"{method} {set_name}: {err.max():.2f} eps"


def _backward_errors(angles, seq, q_ref):
    return np.array(
        [
            float(B._mp_angle_between(B._mp_euler_quaternion(a, seq), r))
            for a, r in zip(np.asarray(angles, np.float64), q_ref, strict=True)
        ]
    )


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("seq", SEQS)
def test_euler_backward_error_every_set(qsets, seq, dtype):
    """Backward error <= 5 eps (float64) / 7 eps (float32), exact and near gimbal lock too."""
    rng = np.random.default_rng(SEQS.index(seq))  # deterministic per sequence
    _, g_exact = B._gimbal_set(rng, 4, [seq], 0.0, 1e-12)
    _, g_near = B._gimbal_set(rng, 4, [seq], 1e-9, 1e-7)
    some = [qsets[k][:6] for k in ("uniform", "near_identity", "near_180")]
    q = np.concatenate([*some, g_exact, g_near])
    q = np.asarray(jnp.asarray(q, dtype=dtype)).astype(np.float64)
    bound = {np.float32: 7.0, np.float64: 5.0}[dtype] * ulp(dtype)
    ang = rj.quaternion_to_euler(jnp.asarray(q, dtype=dtype), seq)
    assert ang.dtype == dtype
    err = _backward_errors(ang, seq, _mp_quaternions(q))
    assert err.max() <= bound, f"quaternion_to_euler {seq}: {err.max() / ulp(dtype):.2f} eps"
    R = np.asarray(jnp.asarray(B._np_matrix(q), dtype=dtype)).astype(np.float64)
    ref = [B._mp_optimal_quaternion(r) for r in R]
    err = _backward_errors(rj.matrix_to_euler(jnp.asarray(R, dtype=dtype), seq), seq, ref)
    assert err.max() <= bound, f"matrix_to_euler {seq}: {err.max() / ulp(dtype):.2f} eps"


def test_scipy_loses_accuracy_near_gimbal_lock():
    """What the benchmark's peer rows show: scipy's lock threshold costs ~1e8-1e9 eps."""
    from scipy.spatial.transform import Rotation

    seq_of, q = B._gimbal_set(np.random.default_rng(3), 8, ["xyz", "ZXZ"], 1e-9, 1e-7)
    worst_scipy, worst_ours = 0.0, 0.0
    for seq in ("xyz", "ZXZ"):
        idx = [i for i, s in enumerate(seq_of) if s == seq]
        ref = _mp_quaternions(q[idx])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            theirs = Rotation.from_quat(q[idx]).as_euler(seq)
        worst_scipy = max(worst_scipy, _backward_errors(theirs, seq, ref).max())
        worst_ours = max(
            worst_ours, _backward_errors(rj.quaternion_to_euler(q[idx], seq), seq, ref).max()
        )
    assert worst_ours <= 5 * ulp(np.float64)
    assert worst_scipy > 1e6 * ulp(np.float64)


@pytest.mark.parametrize("sigma", [1e-8, 1e-4, 1e-2])
def test_noisy_matrices_ordering(sigma):
    """Error against the optimal quaternion: optimal <= markley <= shepperd, over a batch."""
    R = B._noisy(np.random.default_rng(11), 48, sigma)
    ref = np.array([[float(c) for c in B._mp_optimal_quaternion(r)] for r in R])
    err = {
        m: B._quat_err(np.asarray(rj.matrix_to_quaternion(R, method=m)), ref)
        for m in ("shepperd", "markley", "optimal")
    }
    med = {m: np.median(e) for m, e in err.items()}
    assert med["optimal"] <= med["markley"] <= med["shepperd"], med
    assert err["optimal"].max() <= 2 * ulp(np.float64)
    # Markley's power step leaves O(sigma^2) of the O(sigma) Shepperd error.
    assert np.mean(err["markley"] <= err["shepperd"]) >= 0.9
    assert med["markley"] <= 10 * sigma**2 + 4 * ulp(np.float64)


@pytest.mark.parametrize("dtype", [jnp.bfloat16, jnp.float16])
def test_low_precision_inputs(qsets, dtype):
    """bfloat16/float16 are computed in float32 and returned in the input dtype."""
    eps = float(jnp.finfo(dtype).eps)
    q = np.concatenate([qsets[k] for k in CLEAN_SETS])
    with np.errstate(under="ignore"):  # near-identity entries flush to zero in float16
        R_low = jnp.asarray(B._np_matrix(q), dtype=dtype)
        q_low = jnp.asarray(q, dtype=dtype)
    R = np.asarray(R_low.astype(jnp.float64))
    got = rj.matrix_to_quaternion(R_low)
    assert got.dtype == dtype
    ref = np.array([[float(c) for c in B._mp_optimal_quaternion(r)] for r in R])
    # components in [-1, 1]: one rounding to the output dtype, at most half an eps
    assert B._quat_err(np.asarray(got.astype(jnp.float64)), ref).max() <= 0.5 * eps * (1 + 1e-3)
    ang = rj.quaternion_to_euler(q_low, "ZYX")
    assert ang.dtype == dtype
    err = _backward_errors(
        ang.astype(jnp.float64), "ZYX", _mp_quaternions(q_low.astype(jnp.float64))
    )
    # each of three angles up to pi is rounded once: at most 3 * pi/2 eps of rotation
    assert err.max() <= 3 * np.pi / 2 * eps


def _tangent_fd(R, w, h=1e-6):
    """Central difference of matrix_to_quaternion along R exp(t hat(w)), signs aligned."""
    q0 = np.asarray(rj.matrix_to_quaternion(R))

    def q(t):
        v = np.asarray(rj.matrix_to_quaternion(R @ np.asarray(rj.rotvec_to_matrix(t * w))))
        return v if v @ q0 >= 0 else -v

    return (q(h) - q(-h)) / (2 * h)


@pytest.mark.parametrize(
    "name, R",
    [
        ("generic", np.asarray(rj.quaternion_to_matrix(np.array([0.3, -0.5, 0.2, 0.78])))),
        ("identity", np.eye(3)),
        ("exact_180", np.diag([1.0, -1.0, -1.0])),
        ("tie", np.asarray(rj.quaternion_to_matrix(np.array([0.5, 0.5, 0.5, 0.5])))),
        ("gimbal_xyz", np.asarray(rj.euler_to_matrix(np.array([0.3, np.pi / 2, -1.0]), "xyz"))),
    ],
)
def test_shepperd_derivative_matches_finite_differences_on_so3(name, R):
    """The tangent-space rule is the true derivative along every direction that stays on SO(3)."""
    for w in np.eye(3) + 0.3:
        hat = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
        _, jv = jax.jvp(rj.matrix_to_quaternion, (jnp.asarray(R),), (jnp.asarray(R @ hat),))
        q0 = np.asarray(rj.matrix_to_quaternion(R))
        fd = _tangent_fd(R, w)
        np.testing.assert_allclose(np.asarray(jv), fd, atol=1e-8, err_msg=name)
        # and the rule is tangent to the unit sphere
        assert abs(q0 @ np.asarray(jv)) < 1e-14


def test_shepperd_gradients_fwd_and_rev_through_rotvec():
    def f(v):
        return rj.matrix_to_quaternion(rj.rotvec_to_matrix(v))

    for v in (np.array([0.3, -0.2, 0.9]), np.array([1e-9, 0.0, 2e-9]), np.array([0.0, 3.0, 0.1])):
        check_grads(f, (v,), order=1, modes=("fwd", "rev"))
        jac = np.asarray(jax.jacrev(f)(v))
        np.testing.assert_allclose(jac, np.asarray(jax.jacfwd(f)(v)), atol=1e-14)


def test_quick_benchmark_writes_json(tmp_path):
    """The CI mode runs end to end (two operations here, to keep the test short)."""
    rc = B.main(
        ["--quick", "--out", str(tmp_path), "--ops", "matrix_to_quaternion,quaternion_to_euler"]
    )
    assert rc == 0
    data = json.loads((tmp_path / "bench.json").read_text())
    assert data["meta"]["quick"] is True
    assert data["meta"]["device"].startswith(jax.default_backend() + ": ")
    assert data["meta"]["malloc_env"]["MALLOC_MMAP_THRESHOLD_"] is not None
    rows = data["rows"]
    assert rows and all(set(r) == set(B.COLUMNS) for r in rows)
    m2q = [r for r in rows if r["op"] == "matrix_to_quaternion" and r["dtype"] == "float32"]
    assert {r["method"] for r in m2q if r["impl"] == "rotjax"} == {"shepperd", "markley", "optimal"}
    assert any(r["impl"] == "copy" for r in m2q)
    for r in rows:
        assert r["mrot_s"] > 0
        if r["impl"] == "rotjax":
            assert r["err_max_eps"] is not None and r["err_by_set"]
    assert (tmp_path / "bench.txt").read_text().startswith("operation")
    assert (tmp_path / "bench.png").exists()


ALL_OPS = [
    ("matrix_to_quaternion", "shepperd"),
    ("quaternion_to_euler", ""),
    ("matrix_to_euler", ""),
    ("quaternion_to_matrix", ""),
    ("quaternion_to_rotvec", ""),
    ("rotvec_to_quaternion", ""),
    ("integrate_angular_velocity", "exponential"),
]


@pytest.fixture(scope="module")
def small_accuracy():
    return B._Accuracy(np.random.default_rng(4), 4, 1, "float64", ["xyz", "ZXZ"])


@pytest.mark.parametrize(("op", "method"), ALL_OPS)
def test_accuracy_pass_every_operation(small_accuracy, op, method):
    """The benchmark's accuracy pass on each operation, both ways it runs a JAX contender:
    through the throughput executable (sets padded to its batch) and jitted for the sets. Both
    must report every set, finite, within the documented float64 bounds (at most 5 eps)."""
    fn = next(f for impl, m, f, _ in B._contenders(op, {}) if impl == "rotjax" and m == method)
    batch = 256  # larger than the sets together (at most 34 rows here)
    shape = B._input_shape(op)
    q = B._quats(np.random.default_rng(0), batch)
    x = {
        (4,): q,
        (3, 3): B._np_matrix(q),
        (3,): 0.7 * q[:, :3],
        (7,): np.concatenate([q, q[:, :3]], axis=1),
    }[shape]
    compiled = jax.jit(fn).lower(jnp.asarray(x)).compile()
    padded = B._accuracy(op, fn, "rotjax", small_accuracy, jnp.float64, compiled, batch)
    apart = B._accuracy(op, fn, "rotjax", small_accuracy, jnp.float64)
    assert padded.keys() == apart.keys() and padded
    for k in padded:
        assert len(padded[k]) == len(apart[k]) > 0
        for errs in (padded[k], apart[k]):
            assert np.all(np.isfinite(errs)), (op, k)
            if not k.startswith("noisy"):  # noisy matrices: Shepperd's O(sigma), by design
                assert errs.max() <= 5.0, (op, k, errs.max())
