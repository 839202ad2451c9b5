"""The batch sweep (``python -m rotjax bench sweep``): its programs, a small real run, and its
table."""

import json

import pytest

from rotjax._bench import cli
from rotjax._bench import sweep as S
from rotjax._bench.cases import CASES, peers


def test_programs_cover_every_conversion_method_and_pipeline():
    found = peers()
    progs = S.programs(found)
    conversions = {(n, c) for g, n, c, _, _ in progs if g == "conversion"}
    assert {n for n, _ in conversions} == set(CASES)
    m2q = {c for n, c in conversions if n == "matrix_to_quaternion"}
    assert m2q == {"rotjax shepperd", "rotjax markley", "rotjax optimal"}
    pipes = [(n, c) for g, n, c, _, _ in progs if g == "pipeline"]
    assert len(pipes) == 15 and {c for _, c in pipes} == {"rotjax functions", "rotjax objects"}
    with pytest.raises(ValueError, match="unknown operations or pipelines"):
        S.programs(found, ["no_such_operation"])


def test_small_sweep_measures_against_the_copy_kernel(tmp_path):
    """A real run at two small batches, one conversion and one pipeline, both dtypes; the
    table has a column per batch and the copy fraction at the largest."""
    path = tmp_path / "bench-sweep.json"
    rc = cli.main(
        [
            "sweep",
            "--log2-batches",
            "6,8",
            "--rounds",
            "2",
            "--ops",
            "quaternion_to_matrix,compose then apply",
            "--json",
            str(path),
        ]
    )
    assert rc == 0
    doc = json.loads(path.read_text())
    rows = doc["rows"]
    keys = {(r["name"], r["contender"], r["dtype"], r["log2_batch"]) for r in rows}
    # two contenders each (the functions, the objects), two dtypes, two batches
    assert len(keys) == len(rows) == 4 * 2 * 2
    assert all(r["mrot_s"] > 0 and r["vs_copy"] > 0 for r in rows)
    assert doc["meta"]["device"].startswith("cpu")
    md = S.markdown(doc)
    assert "| 2^6 | 2^8 | % of copy at 2^8 |" in md
    line = next(x for x in md.splitlines() if x.startswith("| compose then apply | objects"))
    assert len(line.strip("|").split("|")) == 5
    assert S.generate(path, tmp_path, "-x", check=True) == [str(tmp_path / "_generated/sweep-x.md")]
    S.generate(path, tmp_path, "-x")
    assert S.generate(path, tmp_path, "-x", check=True) == []
    assert S.generate(tmp_path / "missing.json", tmp_path) == []


def test_a_program_that_fails_at_one_batch_ends_no_run():
    """The gyro-log integration reshapes its batch into 1024 steps: at 2^6 it cannot run. It is
    logged and left out; the program after it is measured."""
    logged = []
    rows = S.measure(
        (6,),
        ("float32",),
        1,
        ["integrate_angular_velocity_samples", "quaternion_to_matrix"],
        log=logged.append,
    )
    assert {r["name"] for r in rows} == {"quaternion_to_matrix"} and len(rows) == 2
    assert (
        sum("integrate_angular_velocity_samples" in m and "not measured" in m for m in logged) == 3
    )
