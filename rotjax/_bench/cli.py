"""``python -m rotjax bench``: run the benchmark, or regenerate its reports from a JSON file."""

from __future__ import annotations

import argparse
import datetime
import os
import subprocess
import sys
import time
from pathlib import Path

from .cases import DTYPES

DEFAULT_OUT = "bench_out"
# With glibc's defaults, a buffer over 32 MiB (2^20 float32 matrices: 36 MiB) is mapped fresh and
# returned to the system on every call, so every call pays page faults for its output; users
# run so, and the published runs measure so. --pin-malloc keeps such buffers in the heap.
MALLOC_ENV = {"MALLOC_MMAP_THRESHOLD_": str(1 << 30), "MALLOC_TRIM_THRESHOLD_": str(1 << 30)}
# scipy's Rotation computes on JAX arrays (jitted) only with this set before scipy is imported.
SCIPY_ENV = {"SCIPY_ARRAY_API": "1"}


def rerun_with(want, argv):
    """``python -m rotjax bench *argv`` in a child process whose environment has ``want``
    (variables that glibc and scipy read once, at start-up), unless this one has them: its
    return code, or None (measure in this process)."""
    if all(os.environ.get(k) == v for k, v in want.items()):
        return None
    cmd = [sys.executable, "-m", "rotjax", "bench", *argv]
    return subprocess.call(cmd, env={**os.environ, **want})


RUN_HELP = """\
Measure every operation, method and dtype against the importable peers (scipy's Rotation on
NumPy arrays and, jitted, on JAX arrays; jax.scipy.spatial.transform.Rotation; jaxlie SO3):
jitted throughput (medians over interleaved
rounds), its fraction of a copy kernel that reads and writes the same bytes, single-call
latency, compile time, jit(grad) throughput, and the largest and median error in eps against
mpmath on adversarial sets (near identity, near and at 180 degrees, ties, gimbal lock, noisy
matrices). Writes bench.json, bench.txt and the plots (bench-*.png) into --out.

The measurement runs in a child process with SCIPY_ARRAY_API=1 (so that scipy accepts JAX
arrays) and glibc's default allocator settings, as users run (--pin-malloc: with its mmap and
trim thresholds at 1 GiB instead, which spares each call the page faults of a fresh output
buffer). The tables state which allocator a run used.

--quick: a batch of 2^16, three rounds, four operations, few accuracy samples. At that size
the data stays in cache, so the copy kernel is no bandwidth limit: the %copy column and the
copy rows are left out (they are reported for batches of 2^20 and more, see --log2-batch).
"""

REPORT_HELP = """\
Regenerate, without measuring, the files made from a bench.json: the plots OUT/bench-*.png,
OUT/_generated/bench_table.md (a table per operation), OUT/_generated/headline.md (rotjax
against the peers), OUT/_generated/machine.md (the machine paragraph), and the README block
between <!-- headline:start --> and <!-- headline:end --> when the README has those markers.
--check exits 1 if any of them is out of date (the markdown is compared exactly, the plots by
the digest of the data they were drawn from).
"""


def _report(argv) -> int:
    from . import report

    p = argparse.ArgumentParser(
        prog="python -m rotjax bench report",
        description=REPORT_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--json", default="docs/bench.json", help="input (default: docs/bench.json)")
    p.add_argument("--out", default="docs", help="output directory (default: docs)")
    p.add_argument("--readme", default="README.md", help="README whose headline block is rewritten")
    p.add_argument("--suffix", default="", help="appended to the output names, e.g. -h100")
    p.add_argument("--check", action="store_true", help="only check that the files are current")
    args = p.parse_args(argv)
    readme = args.readme if not args.suffix else None  # the README shows the main run only
    stale = report.generate(args.json, args.out, readme, args.suffix, check=args.check)
    from . import sweep

    sweep_json = Path(args.json).with_name(f"bench-sweep{args.suffix}.json")
    stale += sweep.generate(sweep_json, args.out, args.suffix, check=args.check)
    if not args.suffix:  # the pipelines' and compile times' tables, from their own files
        from . import compile_time, pipelines

        for mod in (pipelines, compile_time):
            other = str(Path(args.json).with_name(Path(mod.DEFAULT_JSON).name))
            stale += mod.generate(other, args.out, check=args.check)
    for path in stale:
        print(f"{'out of date' if args.check else 'wrote'}: {path}", file=sys.stderr)
    return 1 if args.check and stale else 0


def package_versions():
    import importlib.metadata as md
    import platform

    out = {"python": platform.python_version()}
    for name in ("rotjax", "jax", "jaxlib", "numpy", "scipy", "jaxlie", "mpmath"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            if name == "rotjax":
                from .. import __version__

                out[name] = __version__
    return out


def commit_id():
    """The git commit of the measured rotjax ("+changes" where its files differ from it), or
    None outside a git checkout."""
    root = Path(__file__).resolve().parents[2]

    def git(*args):
        return subprocess.run(
            ["git", "-C", str(root), *args], capture_output=True, text=True, check=True
        ).stdout.strip()

    try:
        changed = git("status", "--porcelain", "--", "rotjax")
        return git("rev-parse", "--short=12", "HEAD") + ("+changes" if changed else "")
    except (OSError, subprocess.CalledProcessError):
        return None


def _json_rows(rows):
    """Strict JSON: an infinite error (a NaN result) is written as null."""
    from . import report

    out = []
    for r in rows:
        r = dict(r)
        for k in ("err_max_eps", "err_median_eps"):
            if r[k] is not None:
                r[k] = report.finite_or_none(r[k])
        out.append(r)
    return out


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[2:] if argv is None else argv)
    if argv and argv[0] == "report":
        return _report(argv[1:])
    if argv and argv[0] == "pipelines":
        from . import pipelines

        return pipelines.main(argv[1:])
    if argv and argv[0] == "compile":
        from . import compile_time

        return compile_time.main(argv[1:])
    if argv and argv[0] == "sweep":
        from . import sweep

        return sweep.main(argv[1:])
    p = argparse.ArgumentParser(
        prog="python -m rotjax bench",
        description=RUN_HELP,
        epilog="python -m rotjax bench report --help: regenerate the docs from a JSON file. "
        "python -m rotjax bench pipelines --help: the pipelines' benchmark. "
        "python -m rotjax bench compile --help: trace, lowering and compile times. "
        "python -m rotjax bench sweep --help: throughput against a copy kernel, batch by batch.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--quick", action="store_true", help="small batch and subsets (CI)")
    p.add_argument(
        "--out",
        default=DEFAULT_OUT,
        help=f"output directory, created if missing (default: ./{DEFAULT_OUT}, git-ignored)",
    )
    p.add_argument("--ops", default=None, help="comma-separated subset of operations")
    p.add_argument(
        "--log2-batch", type=int, default=None, help="batch of 2^N rotations (default 20; 16 quick)"
    )
    p.add_argument(
        "--merge-into",
        default=None,
        metavar="JSON",
        help="also replace the measured operations' rows in this bench.json (a full run of the "
        "same batch), noting the run's date, then regenerate reports with 'bench report'",
    )
    p.add_argument(
        "--why", default="", help="with --merge-into: why these rows were measured again"
    )
    p.add_argument(
        "--rounds", type=int, default=None, help="interleaved timing rounds (default 21; 3 quick)"
    )
    p.add_argument(
        "--accuracy-samples",
        type=int,
        default=None,
        help="inputs per accuracy set (default 96; 8 quick); the edge cases of the gimbal-lock "
        "sets are kept whatever the number",
    )
    p.add_argument(
        "--skip-grad",
        default="",
        metavar="CONTENDERS",
        help="comma-separated contenders (impl:method, e.g. rotjax:markley) whose jit(grad) is "
        "not timed, noted in bench.json",
    )
    p.add_argument(
        "--dtypes",
        default=None,
        help=f"comma-separated subset of {','.join(DTYPES)} (default: float32 and float64, and "
        "the low-precision ones where an operation has them); --merge-into keeps the other "
        "dtypes' rows",
    )
    p.add_argument(
        "--pin-malloc",
        action="store_true",
        help="glibc's mmap and trim thresholds at 1 GiB (default: glibc's defaults, as users run)",
    )
    args = p.parse_args(argv)
    from .cases import CASES

    unknown = sorted(set(args.ops.split(",") if args.ops else ()) - set(CASES))
    if unknown:
        p.error(f"unknown operations {unknown}; expected some of {sorted(CASES)}")
    dtypes = args.dtypes.split(",") if args.dtypes else None
    if dtypes is not None and not set(dtypes) <= set(DTYPES):
        p.error(f"unknown dtypes {sorted(set(dtypes) - set(DTYPES))}; expected some of {DTYPES}")
    rc = rerun_with({**SCIPY_ENV, **(MALLOC_ENV if args.pin_malloc else {})}, argv)
    if rc is not None:
        return rc
    from . import report
    from .runner import log, machine, run, settings

    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    import jax

    t0 = time.perf_counter()
    ops = args.ops.split(",") if args.ops else None
    skip_grad = [c for c in args.skip_grad.split(",") if c]

    def make_meta():
        return {
            "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "machine": machine(),
            "device": f"{jax.default_backend()}: {jax.devices()[0].device_kind}",
            "jax": jax.__version__,
            "versions": package_versions(),
            "commit": commit_id(),
            "quick": args.quick,
            "batch": 1
            << (args.log2_batch if args.log2_batch is not None else (16 if args.quick else 20)),
            "malloc_env": {k: os.environ.get(k) for k in MALLOC_ENV},
            **settings(args.quick, args.rounds, args.accuracy_samples),
            "grad_not_timed": skip_grad,
            **({"dtypes": dtypes} if dtypes else {}),
            "seconds": round(time.perf_counter() - t0, 1),
            "columns": list(report.COLUMNS),
        }

    def partial(rows):  # the operations measured so far, should the run be cut short
        (out_dir / "bench.partial.json").write_text(report.dumps(make_meta(), _json_rows(rows)))

    rows = run(
        args.quick,
        ops,
        args.log2_batch,
        args.rounds,
        args.accuracy_samples,
        partial,
        skip_grad,
        dtypes,
    )
    meta = make_meta()
    text = report.table(rows)  # before the JSON conversion: an infinite error prints as inf
    rows = _json_rows(rows)
    (out_dir / "bench.json").write_text(report.dumps(meta, rows))
    (out_dir / "bench.partial.json").unlink(missing_ok=True)
    if args.merge_into:
        path = Path(args.merge_into)
        merged = report.merge(*report.load(path), meta, rows, args.why)
        path.write_text(report.dumps(*merged))
        log(f"[bench] merged {sorted({r['op'] for r in rows})} into {path}")
    (out_dir / "bench.txt").write_text(text + "\n")
    print(text)
    for path in report.write_plots(meta, rows, out_dir):
        log(f"[bench] wrote {path}")
    log(f"[bench] wrote {out_dir / 'bench.json'} in {meta['seconds']} s")
    return 0
