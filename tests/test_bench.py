"""Correctness of the speed/accuracy trade-off points and of the benchmark itself (no timing).

The references are the ones the benchmark uses (``rotjax._bench.accuracy``): mpmath at 40
digits on the exact values of the (rounded) inputs.
"""

from __future__ import annotations

import os
import warnings

import jax
import jax.numpy as jnp
import mpmath as mp
import numpy as np
import pytest
from helpers import SEQS, check_grads, padded_call, sweep, ulp

import rotjax as rj
from rotjax._bench import accuracy as A
from rotjax._bench import cases as C
from rotjax._bench import cli
from rotjax._bench import report as R

CLEAN_SETS = ["uniform", "near_identity", "near_180", "exact_180", "ties"]
# Documented componentwise bounds in eps on rotation matrices (see matrix_to_quaternion).
M2Q_BOUND = {"shepperd": 2.0, "markley": 2.0, "optimal": 2.0}


@pytest.fixture(scope="module")
def qsets():
    return A.quaternion_sets(np.random.default_rng(5), 16)


def _mp_quaternions(q):
    return [[mp.mpf(float(c)) for c in row] for row in q]


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("set_name", sweep(CLEAN_SETS + ["gimbal"], fast=["gimbal"]))
@pytest.mark.parametrize("method", ["shepperd", "markley", "optimal"])
def test_matrix_to_quaternion_within_bound(qsets, method, set_name, dtype):
    if set_name == "gimbal":
        _, q = A.gimbal_set(np.random.default_rng(1), 2, ["xyz", "ZXZ"], 0.0, 1e-12)
    else:
        q = qsets[set_name]
    R = np.asarray(jnp.asarray(A.np_matrix(q), dtype=dtype)).astype(np.float64)
    ref = np.array([[float(c) for c in A.mp_optimal_quaternion(r)] for r in R])
    got = padded_call(rj.matrix_to_quaternion, R.astype(dtype), method=method)
    assert got.dtype == dtype
    err = A.quat_err(np.asarray(got, np.float64), ref) / ulp(dtype)
    assert np.all(np.isfinite(err))
    assert err.max() <= M2Q_BOUND[method], f"{method} {set_name}: {err.max():.2f} eps"


def _backward_errors(angles, seq, q_ref):
    return np.array(
        [
            float(A.mp_angle_between(A.mp_euler_quaternion(a, seq), r))
            for a, r in zip(np.asarray(angles, np.float64), q_ref, strict=True)
        ]
    )


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("seq", SEQS)
def test_euler_backward_error_every_set(qsets, seq, dtype):
    """Backward error <= 5 eps (float64) / 7 eps (float32), exact and near gimbal lock too."""
    rng = np.random.default_rng(SEQS.index(seq))  # deterministic per sequence
    _, g_exact = A.gimbal_set(rng, 4, [seq], 0.0, 1e-12)
    _, g_near = A.gimbal_set(rng, 4, [seq], 1e-9, 1e-7)
    some = [qsets[k][:6] for k in ("uniform", "near_identity", "near_180")]
    q = np.concatenate([*some, g_exact, g_near])
    q = np.asarray(jnp.asarray(q, dtype=dtype)).astype(np.float64)
    bound = {np.float32: 7.0, np.float64: 5.0}[dtype] * ulp(dtype)
    ang = padded_call(rj.quaternion_to_euler, q.astype(dtype), seq)
    assert ang.dtype == dtype
    err = _backward_errors(ang, seq, _mp_quaternions(q))
    assert err.max() <= bound, f"quaternion_to_euler {seq}: {err.max() / ulp(dtype):.2f} eps"
    R = np.asarray(jnp.asarray(A.np_matrix(q), dtype=dtype)).astype(np.float64)
    ref = [A.mp_optimal_quaternion(r) for r in R]
    m2e = padded_call(rj.matrix_to_euler, R.astype(dtype), seq)
    err = _backward_errors(m2e, seq, ref)
    assert err.max() <= bound, f"matrix_to_euler {seq}: {err.max() / ulp(dtype):.2f} eps"


def test_scipy_loses_accuracy_near_gimbal_lock():
    """What the benchmark's peer rows show: scipy's lock threshold costs ~1e8-1e9 eps."""
    from scipy.spatial.transform import Rotation

    seq_of, q = A.gimbal_set(np.random.default_rng(3), 8, ["xyz", "ZXZ"], 1e-9, 1e-7)
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
    R = A.noisy(np.random.default_rng(11), 48, sigma)
    ref = np.array([[float(c) for c in A.mp_optimal_quaternion(r)] for r in R])
    err = {
        m: A.quat_err(padded_call(rj.matrix_to_quaternion, R, method=m), ref)
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
        R_low = jnp.asarray(A.np_matrix(q), dtype=dtype)
        q_low = jnp.asarray(q, dtype=dtype)
    R = np.asarray(R_low.astype(jnp.float64))
    got = rj.matrix_to_quaternion(R_low)
    assert got.dtype == dtype
    ref = np.array([[float(c) for c in A.mp_optimal_quaternion(r)] for r in R])
    # components in [-1, 1]: one rounding to the output dtype, at most half an eps
    assert A.quat_err(np.asarray(got.astype(jnp.float64)), ref).max() <= 0.5 * eps * (1 + 1e-3)
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


@pytest.mark.slow  # compiles every contender of two operations, and their gradients
def test_quick_benchmark_writes_json(tmp_path):
    """The CI mode runs end to end (two operations here, to keep the test short); its batch
    stays in cache, so no copy baseline is reported."""
    rc = cli.main(
        ["--quick", "--out", str(tmp_path), "--ops", "matrix_to_quaternion,quaternion_to_euler"]
    )
    assert rc == 0
    meta, rows = R.load(tmp_path / "bench.json")
    assert meta["quick"] is True and meta["batch"] == 1 << 16
    assert meta["device"].startswith(jax.default_backend() + ": ")
    # glibc's default malloc settings unless the caller's environment sets them (--pin-malloc)
    assert meta["malloc_env"] == {k: os.environ.get(k) for k in cli.MALLOC_ENV}
    assert meta["versions"]["jax"] == jax.__version__
    assert meta["rounds"] == 3 and meta["accuracy_samples"] == 8 and "commit" in meta
    assert rows and all(set(r) == set(R.COLUMNS) for r in rows)
    m2q = [r for r in rows if r["op"] == "matrix_to_quaternion" and r["dtype"] == "float32"]
    assert {r["method"] for r in m2q if r["impl"] == "rotjax"} == {"shepperd", "markley", "optimal"}
    assert not any(r["impl"] == "copy" or r["vs_copy"] is not None for r in rows)
    for r in rows:
        assert r["mrot_s"] > 0
        if r["impl"] in ("rotjax", "scipy-jax"):
            assert r["err_max_eps"] is not None and r["err_by_set"]
    # scipy on JAX arrays is a peer of every conversion, in both dtypes, next to scipy on NumPy
    for op in ("matrix_to_quaternion", "quaternion_to_euler"):
        for dt in ("float32", "float64"):
            impls = {r["impl"] for r in rows if r["op"] == op and r["dtype"] == dt}
            assert {"scipy-jax", "scipy", "jax.scipy", "jaxlie"} <= impls, (op, dt)
    assert (tmp_path / "bench.txt").read_text().startswith("operation")
    assert not (tmp_path / "bench.partial.json").exists()  # written per operation, then removed
    assert [p.name for p in sorted(tmp_path.glob("bench-*.png"))] == [
        "bench-m2q-noisy.png",
        "bench-m2q.png",
        "bench-q2e.png",
    ]
    for png in tmp_path.glob("bench-*.png"):
        assert R.plot_digest(png) == R.digest(meta, rows)


_SCIPY_ON_JAX = """
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
from rotjax._bench import cases as C
import rotjax as rj
peers = C.peers()
print("scipy-jax" in peers)
if "scipy-jax" in peers:
    x = jnp.asarray(np.random.default_rng(0).normal(size=(64, 4)), jnp.float32)
    for c in C.CASES["quaternion_to_matrix"].contenders(peers):
        if c.impl == "scipy-jax":
            text = jax.jit(c.fn).lower(x).as_text()
            out = jax.jit(c.fn)(x)
            err = float(jnp.abs(out - rj.quaternion_to_matrix(x)).max())
            print(out.dtype, "callback" in text, err)
"""


@pytest.mark.slow  # a subprocess importing scipy and JAX
@pytest.mark.parametrize("flag", ["1", None])
def test_scipy_on_jax_is_a_jitted_peer_only_with_the_array_api(flag):
    """With SCIPY_ARRAY_API=1 scipy's Rotation is a peer on JAX arrays: traced by jax.jit into
    one XLA program (no host callback), keeping float32, with rotjax's results; without it,
    scipy converts to NumPy, and the peer is left out rather than timed on NumPy."""
    import subprocess
    import sys
    from pathlib import Path

    env = {k: v for k, v in os.environ.items() if k != "SCIPY_ARRAY_API"}
    if flag:
        env["SCIPY_ARRAY_API"] = flag
    root = Path(__file__).resolve().parent.parent
    env["PYTHONPATH"] = os.pathsep.join([str(root), env.get("PYTHONPATH", "")])
    res = subprocess.run(
        [sys.executable, "-c", _SCIPY_ON_JAX], env=env, capture_output=True, text=True, check=True
    )
    lines = res.stdout.split("\n")
    if not flag:
        assert lines[0] == "False"
        return
    assert lines[0] == "True"
    dtype, callback, err = lines[1].split()
    assert dtype == "float32" and callback == "False" and float(err) < 1e-6


@pytest.mark.slow  # a batch of 2^20 in several rounds
def test_copy_baseline_at_a_bandwidth_bound_batch(tmp_path):
    """At 2^20 rotations (past the caches) quaternion_to_matrix, which writes 9 floats per
    rotation, runs at a sane fraction of the copy kernel that moves the same bytes: a copy
    kernel doing more or less than a copy moves this ratio out of range. A quick run's three
    rounds can all be slowed by other work on the machine (the tests run in parallel), so up
    to three runs: one must be in range, which a wrong copy kernel never is."""
    missed = []
    for attempt in range(3):
        out = tmp_path / str(attempt)
        args = ["--quick", "--out", str(out), "--ops", "quaternion_to_matrix"]
        assert cli.main([*args, "--log2-batch", "20"]) == 0
        _, rows = R.load(out / "bench.json")
        copy = [r for r in rows if r["impl"] == "copy"]
        assert {r["dtype"] for r in copy} == {"float32", "float64"}
        bad = [r for r in rows if r["impl"] == "rotjax" and not 0.05 <= r["vs_copy"] <= 1.5]
        if not bad:
            return
        missed.append([(r["method"], r["dtype"], r["vs_copy"]) for r in bad])
    pytest.fail(f"vs_copy out of [0.05, 1.5] in three runs: {missed}")


def test_interleaved_rounds_vary_each_contenders_predecessor(monkeypatch):
    """Every contender runs once per round, and not always right after the same one: a call's
    time depends on what ran before it (a large buffer just freed), which a fixed or rotated
    order would charge to the same contender every round."""
    from rotjax._bench import timing as T

    calls = []
    monkeypatch.setattr(T, "timed", lambda f, x: calls.append(f) or 1e-3)
    keys = [f"c{i}" for i in range(14)]
    times = T.throughput_group({k: (k, None) for k in keys}, rounds=9)
    assert all(sorted(times[k]) == list(range(9)) for k in keys)
    before = {k: {calls[i - 1] for i in range(1, len(calls)) if calls[i] == k} for k in keys}
    assert all(len(b) >= 3 for b in before.values()), before


def test_copy_kernel_reads_every_input_and_writes_the_output_width():
    from rotjax._bench.timing import copy_kernel

    for n_in, n_out in ((9, 4), (4, 9), (4, 3), (3, 4), (7, 4)):
        x = jnp.zeros((5, n_in))
        out = copy_kernel(n_in, n_out)(x)
        assert out.shape == (5, n_out)

        # every input value reaches some output (the Jacobian jitted whole: one program)
        def first_row(v, n_in=n_in, n_out=n_out):
            return copy_kernel(n_in, n_out)(v)[0]

        jac = jax.jit(jax.jacrev(first_row))(x)
        assert np.all(np.abs(np.asarray(jac[:, 0])).sum(0) > 0), (n_in, n_out)


def _synthetic(dtypes=("float32", "float64", "bfloat16", "float16")):
    """A small bench.json: two operations, rotjax (two methods), two peers and the copy row."""
    rows = []
    for op in ("matrix_to_quaternion", "quaternion_to_euler"):
        for dt in dtypes:
            for k, (impl, method) in enumerate(
                [("rotjax", "shepperd"), ("rotjax", "markley"), ("jaxlie", ""), ("scipy", "")]
            ):
                r = dict.fromkeys(R.COLUMNS)
                r.update(op=op, impl=impl, method=method, dtype=dt, mrot_s=100.0 / (k + 1))
                r.update(vs_copy=0.5 / (k + 1), vs_rotjax=1.0 / (k + 1))
                r.update(err_max_eps=0.5 + k, err_median_eps=0.25)
                r["err_by_set"] = {"uniform": {"max": 0.5 + k, "median": 0.25}}
                r["err_by_set"]["noisy_0.0001"] = {"max": 10.0**k, "median": 1.0}
                rows.append(r)
            c = dict.fromkeys(R.COLUMNS)
            c.update(op=op, impl="copy", method="limit", dtype=dt, mrot_s=200.0, vs_copy=1.0)
            rows.append(c)
    meta = {"date": "2000-01-01T00:00:00+00:00", "machine": {"cpu": "TestCPU", "cores": 2}}
    meta.update(device="cpu: cpu", jax="0.0", batch=1 << 20, quick=False)
    meta["versions"] = {"jax": "0.0", "numpy": "0.1"}
    return meta, rows


def test_report_generates_and_checks(tmp_path):
    meta, rows = _synthetic()
    src = tmp_path / "bench.json"
    src.write_text(R.dumps(meta, rows))
    readme = tmp_path / "README.md"
    readme.write_text(f"intro\n{R.README_START}\nold\n{R.README_END}\nrest\n")
    out = tmp_path / "docs"
    argv = ["report", "--json", str(src), "--out", str(out), "--readme", str(readme)]
    assert cli.main([*argv, "--check"]) == 1  # nothing written yet
    assert cli.main(argv) == 0
    assert cli.main([*argv, "--check"]) == 0
    head = (out / "_generated" / "headline.md").read_text()
    # rotjax's speed over each peer's (3x: jaxlie ran at a third of rotjax's speed), both dtypes
    assert "| rotjax ÷ jaxlie | rotjax ÷ scipy on NumPy |" in head and "above 1 rotjax" in head
    for dt in ("float32", "float64"):  # a table per dtype, of six columns at most
        assert f"| {dt} conversion | rotjax Mrot/s | rotjax ÷ jaxlie |" in head
    assert head.count("| matrix_to_quaternion | 100 | 3x | 4x |") == 2
    assert head.count("| matrix_to_quaternion | 0.5 | 2.5 | 3.5 |") == 2  # errors in eps
    assert "TestCPU" in head and "2000-01-01" in head and "glibc's default malloc" in head
    machine = (out / "_generated" / "machine.md").read_text()
    assert machine.count("TestCPU") == 1 and "numpy 0.1" in machine and "malloc" in machine
    table = (out / "_generated" / "bench_table.md").read_text()
    assert table.count("### ") == 2  # a section per operation
    assert table.count("TestCPU") == 2 and table.count("2000-01-01") == 2  # a caption each
    main = [ln for ln in table.split("\n") if ln.startswith("| ")]
    folded = [ln for ln in table.split("\n") if ln.startswith("    | ")]
    assert len(main) == len(rows) + 2  # header and one line per row, per operation
    assert len(folded) == len([r for r in rows if r["impl"] != "copy"]) + 2  # no copy rows
    assert max(ln.strip().count(" | ") + 1 for ln in main + folded) == 6  # columns per table
    assert "| jaxlie | float32 | 33.3 | 3.00 |" in table  # rotjax speed ÷ this
    text = readme.read_text()
    assert text.startswith("intro\n") and text.endswith(f"{R.README_END}\nrest\n")
    assert "old" not in text and head in text
    # a changed JSON makes every generated file stale, and only --check leaves them so
    next(r for r in rows if r["dtype"] == "float64")["mrot_s"] = 1.0  # a headline cell
    src.write_text(R.dumps(meta, rows))
    assert set(R.generate(src, out, readme, check=True)) == {
        str(out / "_generated" / "bench_table.md"),
        str(out / "_generated" / "headline.md"),
        str(readme),
        *(str(out / f"bench-{p[0]}.png") for p in R.PANELS),
    }
    assert cli.main([*argv, "--check"]) == 1
    assert cli.main(argv) == 0 and cli.main([*argv, "--check"]) == 0


def test_readme_without_markers_is_left_alone(tmp_path):
    assert R.readme_block("no markers here\n", "block") is None


@pytest.mark.parametrize("panel", R.PANELS, ids=[p[0] for p in R.PANELS])
def test_plot_labels_unique_and_markers_per_dtype(panel):
    """One figure per panel, drawn at the width the docs show it, with legible text."""
    meta, rows = _synthetic()
    fig = R.figure(meta, rows, panel)
    try:
        assert round(fig.get_figwidth() * fig.dpi) == R.PLOT_WIDTH_PX
        labels = [t.get_text() for leg in fig.legends for t in leg.get_texts()]
        assert len(labels) == len(set(labels))
        assert {"float32", "float64", "bfloat16", "float16"} <= set(labels)
        assert {"rotjax:shepperd", "rotjax:markley", "jaxlie", "scipy on NumPy"} <= set(labels)
        assert len(set(R.MARKERS.values())) == len(R.MARKERS)
        assert min(t.get_fontsize() for leg in fig.legends for t in leg.get_texts()) >= 9
        for ax in fig.axes:
            assert not ax.texts  # no labels drawn on the points
            assert "(" in ax.get_xlabel() and "(" in ax.get_ylabel()  # units
            assert ax.xaxis.label.get_fontsize() >= 9 and ax.yaxis.label.get_fontsize() >= 9
        assert "TestCPU" in fig._suptitle.get_text() and "2000-01-01" in fig._suptitle.get_text()
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)


def test_allocator_is_named():
    assert R.allocator({"malloc_env": dict.fromkeys(cli.MALLOC_ENV)}) == (
        "glibc's default malloc settings"
    )
    assert "pinned at 1 GiB" in R.allocator({"malloc_env": cli.MALLOC_ENV})
    other = {"malloc_env": {"MALLOC_TRIM_THRESHOLD_": "7"}}
    assert "MALLOC_TRIM_THRESHOLD_=7" in R.allocator(other)


def test_committed_docs_are_generated_from_bench_json():
    """docs/_generated/*.md and docs/bench-*.png are current with docs/bench.json, and the
    GPU page's with docs/bench-h100.json."""
    from pathlib import Path

    docs = Path(__file__).resolve().parent.parent / "docs"
    assert R.generate(docs / "bench.json", docs, check=True) == []
    assert R.generate(docs / "bench-h100.json", docs, suffix="-h100", check=True) == []


def test_unknown_operation_is_rejected(tmp_path):
    with pytest.raises(SystemExit):
        cli.main(["--quick", "--out", str(tmp_path), "--ops", "matrix_to_quaternion,nope"])
    assert not (tmp_path / "bench.json").exists()


ALL_OPS = [
    ("matrix_to_quaternion", "shepperd"),
    ("quaternion_to_euler", ""),
    ("matrix_to_euler", ""),
    ("quaternion_to_matrix", ""),
    ("quaternion_to_rotvec", ""),
    ("rotvec_to_quaternion", ""),
    ("quaternion_apply", ""),
    ("integrate_angular_velocity", "exponential"),
]


@pytest.fixture(scope="module")
def small_accuracy():
    return A.Accuracy(np.random.default_rng(4), 4, 1, "float64", ["xyz", "ZXZ"])


@pytest.mark.parametrize(("op", "method"), ALL_OPS)
def test_accuracy_pass_every_operation(small_accuracy, op, method):
    """The benchmark's accuracy pass on each operation, both ways it runs a JAX contender:
    through the throughput executable (sets padded to its batch) and jitted for the sets. Both
    must report every set, finite, within the documented float64 bounds (at most 5 eps)."""
    case = C.CASES[op]
    fn = next(c.fn for c in case.contenders({}) if c.impl == "rotjax" and c.method == method)
    batch = 256  # larger than the sets together (at most 34 rows here)
    rng = np.random.default_rng(0)
    x = C.INPUTS[case.input](rng, A.quats(rng, batch))
    compiled = jax.jit(fn).lower(jax.tree.map(jnp.asarray, x)).compile()
    padded = A.errors(case, fn, "rotjax", small_accuracy, jnp.float64, compiled, batch)
    apart = A.errors(case, fn, "rotjax", small_accuracy, jnp.float64)
    assert padded.keys() == apart.keys() and padded
    for k in padded:
        assert len(padded[k]) == len(apart[k]) > 0
        for errs in (padded[k], apart[k]):
            assert np.all(np.isfinite(errs)), (op, k)
            if not k.startswith("noisy"):  # noisy matrices: Shepperd's O(sigma), by design
                assert errs.max() <= 5.0, (op, k, errs.max())


def test_merge_replaces_the_measured_operations_and_notes_the_run():
    from rotjax._bench.cases import CASES

    ops = list(CASES)[:3]
    meta = {"batch": 8, "device": "cpu: cpu", "date": "d0"}
    rows = [{"op": op, "impl": "rotjax", "v": 0} for op in ops]
    new_meta = {"batch": 8, "device": "cpu: cpu", "date": "d1", "seconds": 1.0}
    merged_meta, merged = R.merge(meta, rows, new_meta, [{"op": ops[1], "impl": "rotjax", "v": 1}])
    assert [(r["op"], r["v"]) for r in merged] == [(ops[0], 0), (ops[1], 1), (ops[2], 0)]
    assert merged_meta["rows_from_a_later_run"][-1]["ops"] == [ops[1]]
    assert ops[1] in R.provenance(merged_meta) and "d1" in R.provenance(merged_meta)
    # measuring the same operation again replaces the earlier note
    again, _ = R.merge(merged_meta, merged, {**new_meta, "date": "d2"}, [{"op": ops[1], "v": 2}])
    assert [e["date"] for e in R.later_runs(again)] == ["d2"]
    with pytest.raises(ValueError, match="batch"):
        R.merge(meta, rows, {**new_meta, "batch": 16}, rows)
    # a run of some dtypes replaces those rows only, and its note names them
    typed = [{"op": op, "impl": "rotjax", "dtype": dt, "v": 0} for op in ops for dt in "ab"]
    part_meta, part = R.merge(meta, typed, new_meta, [{"op": ops[0], "dtype": "b", "v": 1}])
    assert [(r["op"], r["dtype"], r["v"]) for r in part][:2] == [(ops[0], "a", 0), (ops[0], "b", 1)]
    assert len(part) == len(typed)
    assert f"Rows of {ops[0]} (b) from a run of d1" in R.provenance(part_meta)
    # ... and the next run of all of them drops the partial note
    full_meta, _ = R.merge(part_meta, part, {**new_meta, "date": "d2"}, typed[:2])
    assert [(e["date"], e.get("dtypes")) for e in R.later_runs(full_meta)] == [("d2", None)]
    # a run on another machine says so
    other = {**new_meta, "machine": {"cpu": "Other CPU", "cores": 2}}
    elsewhere, _ = R.merge({**meta, "machine": {"cpu": "CPU", "cores": 2}}, rows, other, rows[:1])
    assert "from a run of d1 on Other CPU (2 cores)" in R.provenance(elsewhere)
    # each merged run keeps its own allocator, in the machine paragraph and its tables' captions
    pinned = {**other, "malloc_env": dict(cli.MALLOC_ENV), "date": "2000-01-02"}
    mixed, _ = R.merge({**meta, "date": "2000-01-01"}, rows, pinned, rows[:1])
    assert "pinned at 1 GiB" in R.provenance(mixed)
    assert "pinned at 1 GiB" in R.caption(mixed, [ops[0]])
    assert "glibc's default malloc" in R.caption(mixed, [ops[1]])
