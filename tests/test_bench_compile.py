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
    assert sum(g == "pipeline" for g, _ in names) == 7
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
