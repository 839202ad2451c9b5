"""MkDocs hook: the accuracy page's tables, from the test bounds below and docs/bench.json.

A page that contains ``<!-- accuracy-table -->`` or ``<!-- peers-accuracy-table -->`` gets the
table in its place, built from the benchmark's measured largest errors, so that the page and the
data cannot disagree. A missing or malformed docs/bench.json fails the build.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

# (operation, method, bound float64, bound float32, what is compared, the test that asserts it);
# the bounds are in eps of the dtype, as asserted by the tests named.
BOUNDS = [
    (
        "quaternion_to_matrix",
        "",
        3,
        3,
        "componentwise",
        "test_core_oracle.py::test_quaternion_matrix_accuracy_ulp",
    ),
    (
        "matrix_to_quaternion",
        "shepperd",
        2,
        2,
        "componentwise, against the exact quaternion",
        "test_bench.py::test_matrix_to_quaternion_within_bound",
    ),
    (
        "matrix_to_quaternion",
        "markley",
        2,
        2,
        "componentwise, against the exact quaternion",
        "test_bench.py::test_matrix_to_quaternion_within_bound",
    ),
    (
        "matrix_to_quaternion",
        "optimal",
        2,
        2,
        "componentwise, against the exact quaternion",
        "test_bench.py::test_matrix_to_quaternion_within_bound",
    ),
    (
        "quaternion_to_euler",
        "",
        5,
        7,
        "backward error: rotation of the angles against the input",
        "test_bench.py::test_euler_backward_error_every_set",
    ),
    (
        "matrix_to_euler",
        "",
        5,
        7,
        "backward error: rotation of the angles against the input",
        "test_bench.py::test_euler_backward_error_every_set",
    ),
    (
        "quaternion_to_rotvec",
        "",
        5,
        None,
        "componentwise",
        "test_bench.py::test_accuracy_pass_every_operation",
    ),
    (
        "rotvec_to_quaternion",
        "",
        5,
        None,
        "componentwise",
        "test_bench.py::test_accuracy_pass_every_operation",
    ),
    (
        "integrate_angular_velocity",
        "exponential",
        5,
        None,
        "componentwise, one step",
        "test_bench.py::test_accuracy_pass_every_operation",
    ),
    (
        "euler_to_matrix",
        "",
        5,
        5,
        "componentwise",
        "test_core_oracle.py::test_euler_to_matrix_accuracy_ulp",
    ),
]
PEERS = ["rotjax", "scipy", "scipy-jax", "jax.scipy", "jaxlie"]
BENCH = Path(__file__).resolve().parents[1] / "bench.json"


def _fmt(x) -> str:
    if x is None:
        return "-"
    if isinstance(x, float) and not math.isfinite(x):
        return "NaN output"
    if x >= 1e4:
        return f"{x:.1e}"
    return f"{x:.3g}"


def _measured(rows, op, method, dtype, impl="rotjax"):
    for r in rows:
        if (r["op"], r["impl"], r["dtype"]) == (op, impl, dtype) and (
            impl != "rotjax" or r["method"] == method
        ):
            v = r["err_max_eps"]
            sets = r.get("err_by_set") or {}
            if v is None and any(s["max"] is None for s in sets.values()):
                return float("inf")  # the benchmark writes no number where an output was NaN
            return v
    return None


def _bound(b) -> str:
    return "-" if b is None else str(b)


def _accuracy_table(rows) -> str:
    # Five columns that fit the 1280-pixel layout: the method under the operation, bound and
    # measured in one cell per dtype, and the test's file above its name (no name is split).
    out = [
        "| operation | compared | float64 bound / measured | float32 bound / measured "
        "| asserted by |",
        "|---|---|---:|---:|---|",
    ]
    for op, method, b64, b32, what, test in BOUNDS:
        m64 = _measured(rows, op, method, "float64")
        m32 = _measured(rows, op, method, "float32")
        where, name = test.split("::")
        out.append(
            f"| `{op}`{f'<br>{method}' if method else ''} | {what} | {_bound(b64)} / {_fmt(m64)} "
            f"| {_bound(b32)} / {_fmt(m32)} | `{where}`<br>`{name}` |"
        )
    return "\n".join(out)


def _peers_table(rows) -> str:
    ops = [
        op
        for op in dict.fromkeys(r["op"] for r in rows)
        if any(r["op"] == op and r["impl"] not in ("rotjax", "copy") for r in rows)
    ]
    out = ["| operation | dtype | " + " | ".join(PEERS) + " |", "|---|---|" + "---:|" * len(PEERS)]
    for op in ops:
        for dtype in ("float64", "float32"):
            default = next(
                (r["method"] for r in rows if (r["op"], r["impl"]) == (op, "rotjax")), ""
            )
            cells = [_fmt(_measured(rows, op, default, dtype, impl)) for impl in PEERS]
            out.append(f"| `{op}` | {dtype} | " + " | ".join(cells) + " |")
    return "\n".join(out)


def _meta_line(meta) -> str:
    machine = meta["machine"]
    batch = meta["batch"]
    line = (
        f"Measured: `docs/bench.json`, {meta['date'][:10]}, "
        f"{'quick' if meta.get('quick') else 'full'} run, batch {batch}"
        f"{f' (2^{batch.bit_length() - 1})' if batch & (batch - 1) == 0 else ''}; "
        f"{machine['cpu']}, {machine['cores']} cores, {machine['platform']}; "
        f"backend {meta['device'].split(':')[0]}, jax {meta['jax']}."
    )
    from rotjax._bench.report import later_runs

    for later in later_runs(meta):
        ops = ", ".join(f"`{op}`" for op in later["ops"])
        line += f" The rows for {ops} come from a later run ({later['date'][:10]})."
    return line


def on_page_markdown(markdown, page, config, files):
    markers = ("<!-- accuracy-table -->", "<!-- peers-accuracy-table -->", "<!-- bench-meta -->")
    if not any(m in markdown for m in markers):
        return markdown
    data = json.loads(BENCH.read_text())
    rows = data["rows"]
    markdown = markdown.replace(markers[0], _accuracy_table(rows))
    markdown = markdown.replace(markers[1], _peers_table(rows))
    return markdown.replace(markers[2], _meta_line(data["meta"]))
