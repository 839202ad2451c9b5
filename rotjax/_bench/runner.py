"""The measurement loop: one group of interleaved rounds per operation and dtype."""

from __future__ import annotations

import math
import os
import platform
import sys
import time

from . import accuracy as A
from . import cases as C
from . import report as R
from . import timing as T

LETTER_SEQS = [a + b + c for a in "xyz" for b in "xyz" for c in "xyz" if a != b and b != c]
SEQS = LETTER_SEQS + [s.upper() for s in LETTER_SEQS]


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def settings(quick: bool, rounds=None, accuracy_samples=None) -> dict:
    """Rounds of the timing groups and accuracy samples per set (the defaults of a full or a
    quick run where not given)."""
    return {
        "rounds": rounds or (3 if quick else 21),  # medians of per-round ratios: outvote bursts
        "accuracy_samples": accuracy_samples or (8 if quick else 96),
    }


def run(
    quick: bool,
    ops=None,
    log2_batch=None,
    rounds=None,
    accuracy_samples=None,
    done=None,
    skip_grad=(),
    dtypes=None,
) -> list[dict]:
    """The rows of the benchmark (see ``report.COLUMNS``) for ``ops`` (default: every case,
    or the quick ones), on a batch of ``2**log2_batch`` rotations, in ``rounds`` interleaved
    rounds, with ``accuracy_samples`` inputs per accuracy set (see :func:`settings`).
    ``done(rows)``, if given, is called with the rows so far after each operation;
    ``skip_grad``: contenders (``impl:method`` labels) whose ``jit(grad)`` is not timed;
    ``dtypes``: measure only these of each operation's dtypes."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    found = C.peers()
    n = 1 << (log2_batch if log2_batch is not None else (16 if quick else 20))
    with_copy = n >= T.MIN_COPY_BATCH
    conf = settings(quick, rounds, accuracy_samples)
    rounds, n_acc = conf["rounds"], conf["accuracy_samples"]
    per_seq = 4 if quick else 8
    # Accuracy of Euler extraction: all 24 sequences; --quick: one of each kind.
    seqs = ["xyz", "ZXZ"] if quick else SEQS
    eager_reps = 10 if quick else 100
    rng = np.random.default_rng(2024)
    q_batch = A.quats(rng, n)
    if not ops:
        ops = [op for op, case in C.CASES.items() if case.quick or not quick]
    unknown = sorted(set(ops) - set(C.CASES))
    if unknown:
        raise ValueError(f"unknown operations {unknown}; expected some of {sorted(C.CASES)}")
    # bfloat16 and float16 too where a case asks (--quick: the first such case only)
    low = [op for op in ops if C.CASES[op].low_precision][: 1 if quick else None]
    rows = []
    acc_cache = {}
    t_start = time.perf_counter()
    for op in ops:
        case = C.CASES[op]
        x64 = C.INPUTS[case.input](np.random.default_rng(2025), q_batch)
        op_dtypes = C.DTYPES if op in low else C.DTYPES[:2]
        for dt in [dt for dt in op_dtypes if dtypes is None or dt in dtypes]:
            log(f"[bench {time.perf_counter() - t_start:6.1f}s] {op} {dt}")
            jdt = jnp.dtype(dt)
            np_dt = np.float64 if dt == "float64" else np.float32
            # An input is an array or a tuple of arrays (the batch first in each).
            x_np = jax.tree.map(lambda v, t=np_dt: v.astype(t), x64)
            x_jax = jax.tree.map(lambda v, t=jdt: jnp.asarray(v, dtype=t), x64)
            x1 = jax.tree.map(lambda v: np.array(v[0]), x_jax)
            cont = case.contenders(found)
            if dt in ("bfloat16", "float16"):
                cont = [c for c in cont if c.impl == "rotjax" and not (quick and c != cont[0])]
            entries, grads, compile_s = {}, {}, {}
            for impl, method, fn, traceable in cont:
                key = (impl, method)
                if not traceable:
                    entries[key] = (fn, x_np)
                    continue
                x_in, f_timed = x_jax, fn
                if impl == "jaxlie" and case.jaxlie is not None:
                    f_timed, pre = case.jaxlie(found["jaxlie"].SO3)
                    x_in = pre(x_jax)
                jf = jax.jit(f_timed)
                t0 = time.perf_counter()
                try:
                    compiled = jf.lower(x_in).compile()
                except Exception as e:  # a peer without this dtype: leave it out of the group
                    log(f"[bench]   {impl} {method}: not measured ({type(e).__name__})")
                    continue
                compile_s[key] = time.perf_counter() - t0
                entries[key] = (compiled, x_in)
                # --quick differentiates only rotjax's default method (compiling is the cost)
                want_grad = not quick or (impl == "rotjax" and method == cont[0][1])
                want_grad = want_grad and f"{impl}:{method}".rstrip(":") not in skip_grad
                if want_grad and case.grad and dt in ("float32", "float64"):
                    try:
                        g = jax.jit(jax.grad(lambda x, f=f_timed: T.total(f(x))))
                        grads[key] = (g.lower(x_in).compile(), x_in)
                    except Exception as e:  # noqa: BLE001 - a peer that cannot be differentiated
                        log(f"[bench]   {impl} {method}: no grad ({type(e).__name__})")
            copy_key = ("copy", "")
            if with_copy:
                n_out = sum(
                    math.prod(leaf.shape[1:])
                    for leaf in jax.tree.leaves(jax.eval_shape(cont[0].fn, x_jax))
                )
                n_in = sum(math.prod(leaf.shape[1:]) for leaf in jax.tree.leaves(x_jax))
                kernel = T.copy_kernel(n_in, n_out)
                entries[copy_key] = (jax.jit(kernel).lower(x_jax).compile(), x_jax)
            for key, g in grads.items():
                entries[("grad",) + key] = g
            for f, x in entries.values():  # warm up (first-call allocations)
                T.timed(f, x)
            times = T.throughput_group(entries, rounds)
            ref_key = next(k for k in entries if k[0] == "rotjax")
            scipy_eager = None
            for c in cont:
                if c.impl == "scipy":
                    scipy_eager = c.fn
            if dt not in acc_cache:
                log(f"[bench {time.perf_counter() - t_start:6.1f}s]   mpmath references ({dt})")
                acc_cache[dt] = A.Accuracy(np.random.default_rng(99), n_acc, per_seq, dt, seqs)
            acc = acc_cache[dt]
            for impl, method, fn, traceable in cont:
                key = (impl, method)
                if key not in entries:
                    continue
                t = times[key]
                row = dict.fromkeys(R.COLUMNS)
                row.update(op=op, impl=impl, method=method, dtype=dt)
                row["mrot_s"] = n / T.median_time(t) / 1e6
                if with_copy:
                    row["vs_copy"] = T.median_ratio(times[copy_key], t)
                row["vs_rotjax"] = T.median_ratio(times[ref_key], t)
                row["compile_s"] = compile_s.get(key)
                if ("grad",) + key in times:
                    tg = times[("grad",) + key]
                    row["grad_mrot_s"] = n / T.median_time(tg) / 1e6
                    row["grad_over_fwd"] = T.median_ratio(t, tg)
                # Single calls of rotjax, jaxlie and scipy on NumPy (--quick: rotjax and scipy):
                # jax.scipy and scipy on JAX arrays run op by op, so that their first eager
                # call compiles dozens of programs and each later one takes milliseconds (on a
                # loaded 2-core machine, half of a group's time); the targets compare with scipy.
                if (
                    case.eager
                    and dt in ("float32", "float64")
                    and impl not in ("jax.scipy", "scipy-jax")
                    and not (quick and impl == "jaxlie")
                ):
                    # One rotation, unbatched (jaxlie's adapters vmap, so they get a batch of 1).
                    # rotjax's public functions jit-wrap themselves.
                    x1_np = jax.tree.map(lambda v, t=np_dt: np.array(v, t), x1)
                    x1_in = jax.tree.map(lambda v: v[None], x1_np) if impl == "jaxlie" else x1_np
                    T.timed(fn, x1_in)  # the first call compiles: not part of the latency
                    row["eager_us"], row["eager_vs_scipy"] = T.eager(
                        fn, x1_in, scipy_eager, x1_np, eager_reps
                    )
                try:
                    # jaxlie's executable takes its own layout: it is jitted apart.
                    reuse = impl != "jaxlie" and key in entries and traceable
                    compiled = entries[key][0] if reuse else None
                    errs = A.errors(case, fn, impl, acc, jdt, compiled, n)
                except Exception as e:  # noqa: BLE001 - report, do not hide
                    log(f"[bench]   {impl} {method}: accuracy failed ({type(e).__name__}: {e})")
                    errs = {}
                # A non-finite result (NaN from an asin of a value just above 1, say) counts as
                # an infinite error, so it shows instead of vanishing from the maximum.
                errs = {k: np.where(np.isfinite(v), v, np.inf) for k, v in errs.items()}
                row["err_by_set"] = {
                    k: {
                        "max": R.finite_or_none(np.max(v)),
                        "median": R.finite_or_none(np.median(v)),
                    }
                    for k, v in errs.items()
                }
                clean = {k: v for k, v in errs.items() if not k.startswith("noisy")}
                if clean:
                    allv = np.concatenate(list(clean.values()))
                    row["err_max_eps"] = float(np.max(allv))
                    row["err_median_eps"] = float(np.median(allv))
                rows.append(row)
            if not with_copy:
                continue
            copy_row = dict.fromkeys(R.COLUMNS)
            copy_row.update(op=op, impl="copy", method="limit", dtype=dt)
            copy_row["mrot_s"] = n / T.median_time(times[copy_key]) / 1e6
            copy_row["vs_copy"] = 1.0
            copy_row["vs_rotjax"] = T.median_ratio(times[ref_key], times[copy_key])
            rows.append(copy_row)
        if done is not None:
            done(rows)
    return rows


def machine():
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
