"""Time to first result: trace, lowering and compile time of each conversion of the benchmark and
each pipeline, forward and ``jit(grad)``, for rotjax and its peers.

``python -m rotjax bench compile`` runs every program in a fresh Python process with JAX's
compilation cache off, so nothing traced or compiled before (by another contender, another
program or an earlier run) is reused. The process first compiles one trivial program, so that
the backend's start-up is not counted against whichever program comes first; then it traces,
lowers and compiles the forward program, and then its ``jit(grad)`` (of the sum of the
outputs), on a batch of ``BATCH`` rotations. It writes a JSON file that ``python -m rotjax bench
report`` turns into ``_generated/compile.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

DEFAULT_JSON = "docs/bench-compile.json"
BATCH = 1024


def targets(found) -> list[tuple[str, str, str]]:
    """``(group, name, contender)`` of every traceable program: the benchmark's conversions
    (``cases.CASES``) and the pipelines (``pipelines.pipelines``)."""
    from .cases import CASES
    from .pipelines import pipelines

    out = []
    for op, case in CASES.items():
        out += [("conversion", op, c.label) for c in case.contenders(found) if c.traceable]
    for name, (_, contenders) in pipelines(found).items():
        out += [("pipeline", name, c) for c in contenders]
    return out


def _program(found, group, name, contender, dtype):
    """``(f, args, with_grad)`` of one target, inputs of ``BATCH`` rotations in ``dtype``."""
    import jax
    import jax.numpy as jnp

    rng = np.random.default_rng(0)
    if group == "pipeline":
        from .pipelines import contender_args, pipeline_inputs, pipelines

        keys, contenders = pipelines(found)[name]
        data = {k: jnp.asarray(v, dtype) for k, v in pipeline_inputs(rng, BATCH).items()}
        return contenders[contender], contender_args(contender, keys, data), True
    from .cases import CASES, INPUTS

    case = CASES[name]
    (c,) = [c for c in case.contenders(found) if c.label == contender]
    q = rng.normal(size=(BATCH, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    x = jax.tree.map(lambda v: jnp.asarray(v, dtype), INPUTS[case.input](rng, q))
    f = c.fn
    if c.impl == "jaxlie" and case.jaxlie is not None:
        f, pre = case.jaxlie(found["jaxlie"].SO3)
        x = pre(x)
    return f, (x,), case.grad


def _seconds(f, args) -> dict:
    """Wall seconds of each step, and the CPU seconds of all three (``cpu_s``: what the
    tables show, robust to other work on a shared machine)."""
    import jax

    c0, t0 = time.process_time(), time.perf_counter()
    traced = jax.jit(f).trace(*args)
    t1 = time.perf_counter()
    lowered = traced.lower()
    t2 = time.perf_counter()
    lowered.compile()
    t3, c3 = time.perf_counter(), time.process_time()
    return {
        "trace_s": t1 - t0,
        "lower_s": t2 - t1,
        "compile_s": t3 - t2,
        "total_s": t3 - t0,
        "cpu_s": c3 - c0,
    }


def child(group, name, contender, dtype) -> dict:
    """Measure one target in this (fresh) process."""
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    jax.config.update("jax_enable_compilation_cache", False)
    from .cases import peers
    from .timing import total

    found = peers()
    f, args, with_grad = _program(found, group, name, contender, dtype)
    jax.jit(jnp.sin).lower(jnp.zeros(3, dtype)).compile()  # the backend's start-up
    row = {"group": group, "name": name, "contender": contender, "dtype": dtype}
    row["forward"] = _seconds(f, args)
    if with_grad:
        row["grad"] = _seconds(jax.grad(lambda *a: total(f(*a))), args)
    return row


def _median_row(samples: list[dict]) -> dict:
    """One row from repeated measurements of a target: each time its median over the runs."""
    row = {k: v for k, v in samples[0].items() if k not in ("forward", "grad")}
    for mode in ("forward", "grad"):
        if mode in samples[0]:
            times = samples[0][mode]
            row[mode] = {k: float(np.median([r[mode][k] for r in samples])) for k in times}
    row["repeats"] = len(samples)
    return row


def measure(dtypes=("float32", "float64"), only=None, log=print, save=None, repeat=3) -> list[dict]:
    """Every target, each in a new process (``SCIPY_ARRAY_API=1``, no compilation cache),
    ``repeat`` times, the contenders of a program taking turns (a noisy machine then slows
    them alike), and the median kept; ``save(rows)`` after each program."""
    from .cases import peers

    env = {k: v for k, v in os.environ.items() if not k.startswith("JAX_COMPILATION_CACHE")}
    env.update(SCIPY_ARRAY_API="1", JAX_ENABLE_COMPILATION_CACHE="false")
    rows = []
    todo = [t for t in targets(peers()) if only is None or only in t[1]]
    programs = list(dict.fromkeys((group, name) for group, name, _ in todo))
    for i, (group, name) in enumerate(programs):
        contenders = [c for g, n, c in todo if (g, n) == (group, name)]
        for dt in dtypes:
            samples = {c: [] for c in contenders}
            for _ in range(repeat):
                for contender in contenders:
                    arg = json.dumps([group, name, contender, dt])
                    cmd = [sys.executable, "-m", "rotjax", "bench", "compile", "--child", arg]
                    done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
                    if done.returncode != 0:
                        log(f"[compile] {name} {contender} {dt}: failed\n{done.stderr[-800:]}")
                        continue
                    samples[contender].append(json.loads(done.stdout.strip().splitlines()[-1]))
            rows += [_median_row(v) for v in samples.values() if v]
            if save is not None:
                save(rows)
            log(f"[compile {i + 1}/{len(programs)}] {name} {dt}")
    return rows


def merged(old: dict, new: dict) -> dict:
    """``old``'s rows with those measured again in ``new`` replaced (same group, program,
    contender and dtype); each row keeps the date and commit of the run that measured it."""
    key = lambda r: (r["group"], r["name"], r["contender"], r["dtype"])  # noqa: E731
    stamp = {k: new["meta"][k] for k in ("date", "commit")}
    fresh = {key(r): {**r, **stamp} for r in new["rows"]}
    rows = [fresh.pop(key(r), r) for r in old["rows"]] + list(fresh.values())
    for r in rows:
        for k in ("date", "commit"):
            r.setdefault(k, old["meta"][k])
    return {"meta": new["meta"], "rows": rows}


# --- report ------------------------------------------------------------------------------------


# The projecting rotjax programs compare with the peers that project too (scipy's default
# from_matrix, an SVD per matrix under jit), not with an extraction; the "vs jaxlie" column
# still gives the extraction's.
PROJECTING = {
    ("matrix_to_quaternion", "rotjax optimal"): ("scipy-jax project",),
    ("se3_log", "rotjax RigidTransform"): ("scipy-jax",),
}


def _best_peer(rows, mode, mine=None):
    """The peer row of ``rows`` that compiles fastest in ``mode``; for the rotjax row ``mine``,
    among its projecting peers if it projects (``PROJECTING``)."""
    allowed = mine and PROJECTING.get((mine["name"], mine["contender"]))
    peers = [
        r
        for r in rows
        if not r["contender"].startswith("rotjax")
        and mode in r
        and (not allowed or r["contender"] in allowed)
    ]
    return min(peers, key=lambda r: r[mode]["cpu_s"], default=None)


def markdown(doc) -> str:
    """One table per group: each rotjax program's trace + lower + compile CPU seconds, forward and
    ``jit(grad)``, against the fastest peer's and jaxlie's."""
    meta, rows = doc["meta"], doc["rows"]
    out = []
    for group, title in (("conversion", "Conversions"), ("pipeline", "Pipelines")):
        out += [
            f"**{title}**",
            "",
            "| program | dtype | rotjax | s | fastest peer | s | ratio | vs jaxlie | grad s "
            "| peer grad s | grad ratio |",
            "|---|---|---|--:|---|--:|--:|--:|--:|--:|--:|",
        ]
        mine = [r for r in rows if r["group"] == group]
        for name in dict.fromkeys(r["name"] for r in mine):
            for dt in dict.fromkeys(r["dtype"] for r in mine):
                sel = [r for r in mine if r["name"] == name and r["dtype"] == dt]
                jaxlie = next((r for r in sel if r["contender"] == "jaxlie"), None)
                for r in (r for r in sel if r["contender"].startswith("rotjax")):
                    best, best_g = _best_peer(sel, "forward", r), _best_peer(sel, "grad", r)
                    s = r["forward"]["cpu_s"]
                    g = r.get("grad", {}).get("cpu_s")
                    pg = best_g["grad"]["cpu_s"] if best_g else None
                    cells = [
                        name,
                        dt,
                        r["contender"].removeprefix("rotjax").strip() or "functions",
                        f"{s:.2f}",
                        best["contender"] if best else "",
                        f"{best['forward']['cpu_s']:.2f}" if best else "",
                        f"{s / best['forward']['cpu_s']:.2f}" if best else "",
                        f"{s / jaxlie['forward']['cpu_s']:.2f}" if jaxlie else "",
                        f"{g:.2f}" if g is not None else "",
                        f"{pg:.2f}" if pg is not None else "",
                        f"{g / pg:.2f}" if g is not None and pg else "",
                    ]
                    out.append("| " + " | ".join(cells) + " |")
        out.append("")
    out.append(
        f"Trace + lower + compile CPU seconds of each program in a fresh process without a "
        f"compilation cache, {BATCH} rotations; ratio: rotjax ÷ the fastest peer (below 1: "
        f"rotjax compiles faster); for the programs that project onto SO(3) (`optimal`, "
        f"`RigidTransform.from_matrix`), the fastest peer that projects too. "
        f"{meta['cpu']}, {_dates(meta, rows)}, JAX {meta['jax']}."
    )
    return "\n".join(out) + "\n"


def _dates(meta, rows) -> str:
    """The day, or the first and last days, on which the rows were measured."""
    days = sorted({r.get("date", meta["date"])[:10] for r in rows})
    return days[0] if len(days) == 1 else f"measured {days[0]} to {days[-1]}"


def generate(json_path, out_dir, check=False) -> list[str]:
    """Write (or, with ``check``, compare) ``out_dir/_generated/compile.md``; the stale paths."""
    from .pipelines import generated_table

    return generated_table(json_path, out_dir, "compile.md", markdown, check)


def _meta() -> dict:
    import datetime
    import platform

    import jax

    from .cli import commit_id

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            cpu = next(line.split(":", 1)[1].strip() for line in fh if "model name" in line)
    except (OSError, StopIteration):
        pass
    return {
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "cpu": f"{cpu}, {os.cpu_count()} cores",
        "jax": jax.__version__,
        "commit": commit_id(),
        "batch": BATCH,
    }


def main(argv) -> int:
    p = argparse.ArgumentParser(prog="python -m rotjax bench compile", description=__doc__)
    p.add_argument("--json", default=DEFAULT_JSON, help=f"output (default {DEFAULT_JSON})")
    p.add_argument("--only", help="only the programs whose name contains this")
    p.add_argument("--dtypes", default="float32,float64")
    p.add_argument("--repeat", type=int, default=3, help="fresh processes per target (median)")
    p.add_argument(
        "--merge",
        action="store_true",
        help="replace the measured rows in --json and keep the others (with their dates)",
    )
    p.add_argument("--child", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        print(json.dumps(child(*json.loads(args.child))))
        return 0
    from .cli import SCIPY_ENV, rerun_with

    rc = rerun_with(SCIPY_ENV, ["compile", *argv])  # the targets include scipy on JAX arrays
    if rc is not None:
        return rc
    meta = _meta()

    old = json.loads(Path(args.json).read_text()) if args.merge else None

    def save(rows):  # after each program: an interrupted run keeps what it measured
        doc = {"meta": meta, "rows": rows}
        doc = merged(old, doc) if old is not None else doc
        Path(args.json).write_text(json.dumps(doc, indent=1) + "\n")
        return doc

    dtypes = tuple(args.dtypes.split(","))
    rows = measure(dtypes, args.only, lambda s: print(s, flush=True), save, args.repeat)
    print(markdown(save(rows)))
    return 0
