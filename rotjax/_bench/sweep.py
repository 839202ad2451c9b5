"""Batch sweep: each conversion and pipeline of rotjax against a copy kernel, batch by batch.

``python -m rotjax bench sweep`` times rotjax's jitted forward programs (every method of each
conversion of the benchmark, and each pipeline through the functions and through the objects)
at batches from ``2^16`` to ``2^26`` rotations, each next to a copy kernel that reads and
writes the same bytes (``timing.copy_kernel``), in interleaved rounds. At small batches an
accelerator is bound by launches and a CPU by its caches; the largest batch says what fraction
of the memory bandwidth a program reaches. The inputs are generated once (``2^20`` at most)
and tiled on the device. It writes a JSON file (``--json``); ``python -m rotjax bench report``
turns a ``bench-sweep{SUFFIX}.json`` beside its own ``--json`` file (``--suffix SUFFIX``) into
``_generated/sweep{SUFFIX}.md``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from . import timing

DEFAULT_JSON = "docs/bench-sweep.json"
LOG2_BATCHES = (16, 18, 20, 22, 24, 26)
_BASE_LOG2 = 20  # inputs generated on the host; larger batches repeat them on the device


def programs(found, ops=None):
    """``[(group, name, contender, input, fn)]``: rotjax's traceable contenders of each
    conversion (``cases.CASES``; ``input`` a key of ``cases.INPUTS``) and of each pipeline
    (``input`` its tuple of ``pipeline_inputs`` keys), restricted to the names in ``ops``."""
    from .cases import CASES
    from .pipelines import pipelines

    out = []
    for op, case in CASES.items():
        for c in case.contenders(found):
            if c.impl == "rotjax" and c.traceable:
                out.append(("conversion", op, c.label, case.input, c.fn))
    for name, (keys, contenders) in pipelines(found).items():
        for label, fn in contenders.items():
            if label.startswith("rotjax"):
                out.append(("pipeline", name, label, tuple(keys), fn))
    unknown = set(ops or ()) - {p[1] for p in out}
    if unknown:
        raise ValueError(f"unknown operations or pipelines {sorted(unknown)}")
    return [p for p in out if ops is None or p[1] in ops]


def _tiled(x, n):
    """``x`` (a batch-first array) repeated along the batch to ``n`` rotations."""
    import jax.numpy as jnp

    reps = -(-n // x.shape[0])
    return jnp.tile(x, (reps,) + (1,) * (x.ndim - 1))[:n] if reps > 1 else x[:n]


def _timed(fn, args, rounds, copies):
    """Throughput (Mrot/s) of ``jit(fn)`` on ``args`` and its ratio to a copy kernel of the
    same bytes (``copies``: compiled copy kernels, shared by programs that read and write
    alike), medians over interleaved rounds."""
    import jax

    n = jax.tree.leaves(args)[0].shape[0]
    n_in = sum(int(np.prod(a.shape[1:])) for a in jax.tree.leaves(args))
    out = jax.eval_shape(fn, *args)
    n_out = sum(int(np.prod(o.shape[1:])) for o in jax.tree.leaves(out))
    f = jax.jit(fn).lower(*args).compile()
    key = (n_out, str(jax.tree.map(lambda a: (a.shape, a.dtype), args)))  # n_in is in the shapes
    if key not in copies:
        copy = timing.copy_kernel(n_in, n_out)
        copies[key] = jax.jit(lambda *a: copy(a)).lower(*args).compile()
    entries = {"program": (lambda a: f(*a), args), "copy": (lambda a: copies[key](*a), args)}
    for g, a in entries.values():  # warm up (first-call allocations)
        timing.timed(g, a)
    times = timing.throughput_group(entries, rounds)
    return (
        n / timing.median_time(times["program"]) / 1e6,
        timing.median_ratio(times["copy"], times["program"]),
    )


def measure(
    log2_batches=LOG2_BATCHES,
    dtypes=("float32", "float64"),
    rounds=5,
    ops=None,
    seconds=None,
    log=print,
    save=None,
):
    """The rows ``{group, name, contender, dtype, log2_batch, mrot_s, vs_copy}``: throughput
    and its ratio to the copy kernel (median over interleaved rounds). ``seconds``: stop
    before a program once the run has taken that long; ``save(rows)`` after each program."""
    import jax
    import jax.numpy as jnp

    from .accuracy import quats
    from .cases import INPUTS, peers
    from .pipelines import contender_args, pipeline_inputs

    jax.config.update("jax_enable_x64", True)
    progs = programs(peers(), ops)
    base = 1 << min(max(log2_batches), _BASE_LOG2)
    rng = np.random.default_rng(2024)
    q = quats(rng, base)
    host = {}  # each kind of conversion input, made when a program first needs it
    pipeline_data = pipeline_inputs(rng, base)
    rows, copies, t0 = [], {}, time.perf_counter()
    for group, name, label, kind, fn in progs:
        for dt in dtypes:
            if seconds is not None and time.perf_counter() - t0 > seconds:
                log(f"[sweep] stopped after {seconds} s, before {name} {label} {dt}")
                return rows
            for log2 in log2_batches:
                n = 1 << log2

                def device(x, dt=dt, n=n):
                    return _tiled(jnp.asarray(x, dt), n)

                if group == "pipeline":
                    args = contender_args(label, kind, {k: device(pipeline_data[k]) for k in kind})
                else:
                    if kind not in host:
                        host[kind] = INPUTS[kind](np.random.default_rng(2025), q)
                    args = (jax.tree.map(device, host[kind]),)
                try:
                    mrot_s, vs_copy = _timed(fn, args, rounds, copies)
                except Exception as e:  # noqa: BLE001 - one program's failure ends no run
                    log(f"[sweep] {name} {label} {dt} 2^{log2}: not measured ({e!r:.200})")
                    continue
                finally:
                    del args
                rows.append(
                    {
                        "group": group,
                        "name": name,
                        "contender": label,
                        "dtype": dt,
                        "log2_batch": log2,
                        "mrot_s": mrot_s,
                        "vs_copy": vs_copy,
                    }
                )
            log(f"[sweep {time.perf_counter() - t0:6.1f}s] {name} {label} {dt}")
            if save is not None:
                save(rows)
    return rows


def markdown(doc) -> str:
    """One table per dtype: each program's throughput (Mrot/s) at each batch, and its
    fraction of the copy kernel at the largest."""
    meta, rows = doc["meta"], doc["rows"]
    log2s = sorted({r["log2_batch"] for r in rows})
    lines = []
    for dt in dict.fromkeys(r["dtype"] for r in rows):
        lines += [
            f"**{dt}**",
            "",
            "| program | rotjax | "
            + " | ".join(f"2^{k}" for k in log2s)
            + f" | % of copy at 2^{log2s[-1]} |",
            "|---|---|" + "--:|" * (len(log2s) + 1),
        ]
        mine = [r for r in rows if r["dtype"] == dt]
        for key in dict.fromkeys((r["name"], r["contender"]) for r in mine):
            by = {r["log2_batch"]: r for r in mine if (r["name"], r["contender"]) == key}
            cells = [f"{by[k]['mrot_s']:.1f}" if k in by else "" for k in log2s]
            top = by.get(log2s[-1])
            pct = f"{100 * top['vs_copy']:.0f}" if top else ""
            label = key[1].removeprefix("rotjax").strip() or "functions"
            lines.append(f"| {key[0]} | {label} | " + " | ".join(cells) + f" | {pct} |")
        lines.append("")
    lines.append(
        f"Throughput in Mrot/s of each jitted forward program, and its time against a copy "
        f"kernel that reads and writes the same bytes (100: as fast as the copy). "
        f"{meta['device']}, {meta['date']}, {meta['rounds']} rounds, rotjax {meta['commit']}, "
        f"JAX {meta['versions'].get('jax')}."
    )
    return "\n".join(lines) + "\n"


def generate(json_path, out_dir, suffix="", check=False) -> list[str]:
    """Write (or, with ``check``, compare) ``out_dir/_generated/sweep{suffix}.md``; the stale
    paths (none where ``json_path`` does not exist)."""
    from .pipelines import generated_table

    return generated_table(json_path, out_dir, f"sweep{suffix}.md", markdown, check)


def main(argv) -> int:
    p = argparse.ArgumentParser(prog="python -m rotjax bench sweep", description=__doc__)
    p.add_argument(
        "--log2-batches",
        default=",".join(map(str, LOG2_BATCHES)),
        help="comma-separated exponents N of the batches 2^N (default %(default)s)",
    )
    p.add_argument("--dtypes", default="float32,float64", help="default %(default)s")
    p.add_argument("--rounds", type=int, default=5, help="interleaved rounds (default 5)")
    p.add_argument("--ops", default=None, help="comma-separated conversions and pipelines")
    p.add_argument("--seconds", type=float, default=None, help="stop before a program after this")
    p.add_argument("--json", default=DEFAULT_JSON, help="output (default %(default)s)")
    args = p.parse_args(argv)
    import jax

    from .cli import commit_id, package_versions

    log2s = tuple(int(k) for k in args.log2_batches.split(","))
    ops = args.ops.split(",") if args.ops else None
    meta = {
        "date": time.strftime("%Y-%m-%d", time.gmtime()),
        "device": f"{jax.default_backend()}: {jax.devices()[0].device_kind}",
        "rounds": args.rounds,
        "commit": commit_id(),
        "versions": package_versions(),
    }
    path = Path(args.json)

    def save(rows):
        path.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1) + "\n")

    def log(msg):
        print(msg, file=sys.stderr, flush=True)

    rows = measure(log2s, args.dtypes.split(","), args.rounds, ops, args.seconds, log, save)
    save(rows)
    print(markdown({"meta": meta, "rows": rows}))
    return 0
