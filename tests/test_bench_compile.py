"""The compile-time benchmark (``python -m rotjax bench compile``): its targets, its table, and
one real measurement in a fresh process."""

import json
import subprocess
import sys

import pytest

from rotjax._bench import compile_time as C
from rotjax._bench.cases import CASES, peers


def _row(group, name, contender, dtype, fwd, grad=None):
    row = {"group": group, "name": name, "contender": contender, "dtype": dtype}
    row["forward"] = {"cpu_s": fwd}
    if grad is not None:
        row["grad"] = {"cpu_s": grad}
    return row


def test_targets_cover_every_conversion_and_pipeline():
    found = peers()
    got = C.targets(found)
    names = {(g, n) for g, n, _ in got}
    assert {("conversion", op) for op in CASES} <= names
    assert sum(g == "pipeline" for g, _ in names) == 8
    rotjax = [t for t in got if t[2].startswith("rotjax")]
    assert len({t[1] for t in rotjax}) == len({t[1] for t in got})  # rotjax in every group


def test_table_ratios_against_fastest_peer_and_jaxlie(tmp_path):
    rows = [
        _row("conversion", "quaternion_to_matrix", "rotjax", "float32", 0.3, 0.6),
        _row("conversion", "quaternion_to_matrix", "jaxlie", "float32", 0.6, 1.2),
        _row("conversion", "quaternion_to_matrix", "jax.scipy", "float32", 0.4, 1.5),
    ]
    doc = {"meta": {"cpu": "cpu", "date": "2026-01-01T00:00", "jax": "0"}, "rows": rows}
    md = C.markdown(doc)
    line = next(x for x in md.splitlines() if x.startswith("| quaternion_to_matrix"))
    cells = [c.strip() for c in line.strip("|").split("|")]
    # fastest peer forward: jax.scipy 0.4 (0.3 / 0.4); vs jaxlie 0.3 / 0.6; grad: 0.6 / 1.2
    assert cells[2:] == ["functions", "0.30", "jax.scipy", "0.40", "0.75", "0.50"] + [
        "0.60",
        "1.20",
        "0.50",
    ]
    path = tmp_path / "bench-compile.json"
    path.write_text(json.dumps(doc))
    assert C.generate(path, tmp_path, check=True) == [str(tmp_path / "_generated/compile.md")]
    C.generate(path, tmp_path)
    assert C.generate(path, tmp_path, check=True) == []


def test_projecting_programs_compare_with_projecting_peers():
    """The optimal conversion's ratio is to scipy's projecting from_matrix, not to jaxlie's
    faster extraction; the other methods' to the fastest peer of all."""
    m2q = "matrix_to_quaternion"
    rows = [
        _row("conversion", m2q, "rotjax shepperd", "float32", 0.1, 0.2),
        _row("conversion", m2q, "rotjax optimal", "float32", 0.8, 1.6),
        _row("conversion", m2q, "jaxlie", "float32", 0.2, 0.4),
        _row("conversion", m2q, "scipy-jax project", "float32", 0.5, 2.0),
    ]
    doc = {"meta": {"cpu": "cpu", "date": "2026-01-01T00:00", "jax": "0"}, "rows": rows}
    lines = [x for x in C.markdown(doc).splitlines() if x.startswith("| " + m2q)]
    cells = [[c.strip() for c in x.strip("|").split("|")] for x in lines]
    assert cells[0][2:8] == ["shepperd", "0.10", "jaxlie", "0.20", "0.50", "0.50"]
    assert cells[1][2:8] == ["optimal", "0.80", "scipy-jax project", "0.50", "1.60", "4.00"]
    assert cells[1][8:] == ["1.60", "2.00", "0.80"]


def test_repeats_keep_the_median_and_merging_keeps_other_rows():
    """Repeated runs of a target give their median; a merge replaces the rows measured again,
    keeps the others, and the table's footer gives the days the rows were measured."""
    runs = [_row("conversion", "q", "rotjax", "float32", t, 2 * t) for t in (0.5, 0.1, 0.3)]
    row = C._median_row(runs)
    assert row["forward"]["cpu_s"] == 0.3 and row["grad"]["cpu_s"] == 0.6
    assert row["repeats"] == 3
    old_meta = {"cpu": "cpu", "date": "2026-01-01T00:00", "jax": "0", "commit": "a"}
    old = {
        "meta": old_meta,
        "rows": [
            _row("conversion", "q", "rotjax", "float32", 0.9),
            _row("conversion", "q", "jaxlie", "float32", 0.2),
        ],
    }
    new = {"meta": {**old_meta, "date": "2026-02-03T00:00", "commit": "b"}, "rows": [row]}
    doc = C.merged(old, new)
    assert [(r["contender"], r["forward"]["cpu_s"], r["commit"]) for r in doc["rows"]] == [
        ("rotjax", 0.3, "b"),
        ("jaxlie", 0.2, "a"),
    ]
    assert "measured 2026-01-01 to 2026-02-03" in C.markdown(doc)


def test_targets_include_scipy_on_jax_arrays():
    """scipy's projecting from_matrix beside "optimal", its RigidTransform in the SE(3) rows."""
    from scipy.spatial.transform import Rotation

    got = C.targets({**peers(), "scipy-jax": Rotation})
    assert ("conversion", "matrix_to_quaternion", "scipy-jax project") in got
    for op in ("se3_exp", "se3_log", "rigid_apply"):
        assert ("conversion", op, "scipy-jax") in got


def test_measures_where_scipy_takes_jax_arrays(monkeypatch):
    """Without SCIPY_ARRAY_API=1 (which scipy reads once, on import) the command runs itself
    again with it, so that its targets include scipy on JAX arrays."""
    from rotjax._bench import cli

    calls = []
    monkeypatch.delenv("SCIPY_ARRAY_API", raising=False)
    monkeypatch.setattr(cli.subprocess, "call", lambda cmd, env: calls.append((cmd, env)) or 0)
    monkeypatch.setattr(C, "measure", lambda *a, **k: pytest.fail("measured without scipy on JAX"))
    assert C.main(["--only", "se3_log"]) == 0
    ((cmd, env),) = calls
    assert cmd[-4:] == ["bench", "compile", "--only", "se3_log"]
    assert env["SCIPY_ARRAY_API"] == "1"


@pytest.mark.slow  # a fresh Python process that imports JAX and compiles
def test_child_measures_one_program_in_a_fresh_process():
    arg = json.dumps(["conversion", "quaternion_to_matrix", "rotjax", "float32"])
    cmd = [sys.executable, "-m", "rotjax", "bench", "compile", "--child", arg]
    out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout
    row = json.loads(out.strip().splitlines()[-1])
    for mode in ("forward", "grad"):
        t = row[mode]
        assert 0 < t["trace_s"] and 0 < t["lower_s"] and 0 < t["compile_s"]
        assert t["total_s"] == pytest.approx(t["trace_s"] + t["lower_s"] + t["compile_s"])
        assert t["cpu_s"] > 0
