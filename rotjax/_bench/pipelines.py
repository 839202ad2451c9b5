"""Pipelines: chains of operations as users write them, through rotjax's functions, through its
``Rotation``/``RigidTransform`` objects, and through the peers' own APIs.

``python -m rotjax bench pipelines`` times each pipeline's jitted forward pass and its
``jit(grad)`` (of the sum of the outputs, with respect to the first input), interleaved in
shuffled rounds as the main benchmark does (``timing.throughput_group``), records the bytes the
compiled rotjax programs access per rotation against their inputs plus outputs, and the time to
trace, lower and compile each program (in this process, with no compilation cache). It writes a
JSON file that ``python -m rotjax bench report`` turns into ``_generated/pipelines.md``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from . import timing

DEFAULT_JSON = "docs/bench-pipelines.json"
SEQ = "xyz"  # jaxlie's roll-pitch-yaw


def pipeline_inputs(rng, n):
    """Unit quaternions, rotation vectors, rotation matrices, Euler angles, vectors and
    translations, float64 (``n`` of each)."""
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    R = np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )
    p = rng.normal(size=(n, 4))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    return {
        "q": q,
        "p": p,
        "rotvec": rng.uniform(-1.5, 1.5, size=(n, 3)),
        "R": R,
        "euler": rng.uniform(-1.5, 1.5, size=(n, 3)),
        "v": rng.normal(size=(n, 3)),
        "t": rng.normal(size=(n, 3)),
        "u": rng.normal(size=(n, 3)),
    }


def _wxyz(q):
    import jax.numpy as jnp

    return jnp.roll(q, 1, axis=-1)


def pipelines(peers):
    """``{name: (input keys, {contender: fn(*inputs)})}``; jaxlie's contenders take its own
    layout (scalar-first quaternions, converted once outside the timing: see ``_jaxlie_keys``)."""
    import jax
    import jax.numpy as jnp

    import rotjax as rj
    from rotjax import RigidTransform, Rotation

    jl = peers.get("jaxlie")
    JR = peers.get("jax.scipy")
    SR = peers.get("scipy-jax")
    SRT = None
    if SR is not None:
        from scipy.spatial.transform import RigidTransform as SRT

    def T(cls, R, q, t):
        return cls.from_components(t, R.from_quat(q))

    out = {
        "unit quaternion from a rotation vector": (
            ("rotvec",),
            {
                "rotjax functions": lambda v: rj.quaternion_normalize(rj.rotvec_to_quaternion(v)),
                "rotjax objects": lambda v: Rotation.from_rotvec(v).as_quat(),
                "jaxlie": jl and jax.vmap(lambda v: jl.SO3.exp(v).wxyz),
                "jax.scipy": JR and (lambda v: JR.from_rotvec(v).as_quat()),
                "scipy on JAX": SR and (lambda v: SR.from_rotvec(v).as_quat()),
            },
        ),
        "Euler angles from a matrix": (
            ("R",),
            {
                "rotjax functions": lambda m: rj.matrix_to_euler(m, SEQ),
                "rotjax objects": lambda m: Rotation.from_matrix(m, assume_valid=True).as_euler(
                    SEQ
                ),
                "jaxlie": jl
                and jax.vmap(lambda m: jnp.stack(jl.SO3.from_matrix(m).as_rpy_radians())),
                "jax.scipy": JR and (lambda m: JR.from_matrix(m).as_euler(SEQ)),
                "scipy on JAX": SR
                and (lambda m: SR.from_matrix(m, assume_valid=True).as_euler(SEQ)),
            },
        ),
        "gyro step q * exp(w)": (
            ("q", "rotvec"),
            {
                "rotjax functions": lambda q, w: rj.quaternion_normalize(
                    rj.quaternion_multiply(q, rj.rotvec_to_quaternion(w))
                ),
                "rotjax objects": lambda q, w: (
                    Rotation.from_quat(q) * Rotation.from_rotvec(w)
                ).as_quat(),
                "jaxlie": jl
                and jax.vmap(lambda q, w: (jl.SO3(q) @ jl.SO3.exp(w)).normalize().wxyz),
                "jax.scipy": JR and (lambda q, w: (JR.from_quat(q) * JR.from_rotvec(w)).as_quat()),
                "scipy on JAX": SR
                and (lambda q, w: (SR.from_quat(q) * SR.from_rotvec(w)).as_quat()),
            },
        ),
        "compose then apply": (
            ("p", "q", "v"),
            {
                "rotjax functions": lambda p, q, v: rj.quaternion_apply(
                    rj.quaternion_multiply(p, q), v
                ),
                "rotjax objects": lambda p, q, v: (
                    Rotation.from_quat(p) * Rotation.from_quat(q)
                ).apply(v),
                "jaxlie": jl and jax.vmap(lambda p, q, v: (jl.SO3(p) @ jl.SO3(q)).apply(v)),
                "jax.scipy": JR and (lambda p, q, v: (JR.from_quat(p) * JR.from_quat(q)).apply(v)),
                "scipy on JAX": SR
                and (lambda p, q, v: (SR.from_quat(p) * SR.from_quat(q)).apply(v)),
            },
        ),
        "relative angle |log(p^-1 q)|": (
            ("p", "q"),
            {
                "rotjax functions": rj.angle_between,
                "rotjax objects": lambda p, q: (
                    Rotation.from_quat(p).inv() * Rotation.from_quat(q)
                ).magnitude(),
                "jaxlie": jl
                and jax.vmap(lambda p, q: jnp.linalg.norm((jl.SO3(p).inverse() @ jl.SO3(q)).log())),
                "jax.scipy": JR
                and (lambda p, q: (JR.from_quat(p).inv() * JR.from_quat(q)).magnitude()),
                "scipy on JAX": SR
                and (lambda p, q: (SR.from_quat(p).inv() * SR.from_quat(q)).magnitude()),
            },
        ),
        "Euler angles then apply": (
            ("euler", "v"),
            {
                "rotjax functions": lambda e, v: rj.quaternion_apply(
                    rj.euler_to_quaternion(e, SEQ), v
                ),
                "rotjax objects": lambda e, v: Rotation.from_euler(SEQ, e).apply(v),
                "jaxlie": jl
                and jax.vmap(lambda e, v: jl.SO3.from_rpy_radians(e[0], e[1], e[2]).apply(v)),
                "jax.scipy": JR and (lambda e, v: JR.from_euler(SEQ, e).apply(v)),
                "scipy on JAX": SR and (lambda e, v: SR.from_euler(SEQ, e).apply(v)),
            },
        ),
        "pose compose then apply": (
            ("p", "t", "q", "u", "v"),
            {
                "rotjax functions": lambda p, t, q, u, v: (
                    rj.quaternion_apply(rj.quaternion_multiply(p, q), v)
                    + rj.quaternion_apply(p, u)
                    + t
                ),
                "rotjax objects": lambda p, t, q, u, v: (
                    T(RigidTransform, Rotation, p, t) * T(RigidTransform, Rotation, q, u)
                ).apply(v),
                "jaxlie": jl
                and jax.vmap(
                    lambda p, t, q, u, v: (
                        jl.SE3.from_rotation_and_translation(jl.SO3(p), t)
                        @ jl.SE3.from_rotation_and_translation(jl.SO3(q), u)
                    ).apply(v)
                ),
                "scipy on JAX": SRT
                and (lambda p, t, q, u, v: (T(SRT, SR, p, t) * T(SRT, SR, q, u)).apply(v)),
            },
        ),
        # The residual of pose graphs and SLAM. rotjax's functions have no pose type (a pose is
        # a RigidTransform, or a 4x4 matrix for se3_log), so this one has no function chain.
        "pose error log(a^-1 b)": (
            ("p", "t", "q", "u"),
            {
                "rotjax objects": lambda p, t, q, u: (
                    T(RigidTransform, Rotation, p, t).inv() * T(RigidTransform, Rotation, q, u)
                ).as_exp_coords(),
                "jaxlie": jl
                and jax.vmap(
                    lambda p, t, q, u: (
                        jl.SE3.from_rotation_and_translation(jl.SO3(p), t).inverse()
                        @ jl.SE3.from_rotation_and_translation(jl.SO3(q), u)
                    ).log()
                ),
                "scipy on JAX": SRT
                and (
                    lambda p, t, q, u: (T(SRT, SR, p, t).inv() * T(SRT, SR, q, u)).as_exp_coords()
                ),
            },
        ),
    }
    return {k: (keys, {c: f for c, f in fs.items() if f}) for k, (keys, fs) in out.items()}


_QUATERNION_KEYS = ("q", "p")


def contender_args(contender, keys, data):
    """The inputs of ``keys`` as the contender takes them: jaxlie's quaternions scalar first."""
    import jax.numpy as jnp

    out = []
    for k in keys:
        x = data[k]
        if contender == "jaxlie" and k in _QUATERNION_KEYS:
            x = jnp.roll(x, 1, axis=-1)
        out.append(x)
    return tuple(out)


def _bytes_ratio(f, args):
    """Bytes the compiled program accesses over what its inputs and outputs hold."""
    import jax

    compiled = jax.jit(f).lower(*args).compile()
    cost = compiled.cost_analysis()
    cost = cost[0] if isinstance(cost, (list, tuple)) else cost
    outs = jax.eval_shape(f, *args)
    io = sum(a.nbytes for a in args) + sum(o.size * o.dtype.itemsize for o in jax.tree.leaves(outs))
    return cost["bytes accessed"] / io


def _compile_seconds(f, args):
    """Trace, lower and compile of a new jit of ``f`` (no compilation cache)."""
    import jax

    t = time.perf_counter()
    jax.jit(f).lower(*args).compile()
    return time.perf_counter() - t


def _grad(f):
    import jax

    return jax.grad(lambda *a: timing.total(f(*a)))


def measure(log2_batch=18, rounds=9, dtypes=("float32", "float64"), seed=0):
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    from .cases import peers as find_peers

    found = find_peers()
    rng = np.random.default_rng(seed)
    raw = pipeline_inputs(rng, 1 << log2_batch)
    rows = []
    for name, (keys, contenders) in pipelines(found).items():
        for dt in dtypes:
            data = {k: jnp.asarray(v, dt) for k, v in raw.items()}
            entries, compile_s, byte_ratio = {}, {}, {}
            for c, f in contenders.items():
                args = contender_args(c, keys, data)
                g = _grad(f)
                compile_s[c] = (_compile_seconds(f, args), _compile_seconds(g, args))
                if c.startswith("rotjax"):
                    byte_ratio[c] = (_bytes_ratio(f, args), _bytes_ratio(g, args))
                jf, jg = jax.jit(f), jax.jit(g)
                jax.block_until_ready(jf(*args))
                jax.block_until_ready(jg(*args))
                entries[(c, "forward")] = (lambda a, jf=jf: jf(*a), args)
                entries[(c, "grad")] = (lambda a, jg=jg: jg(*a), args)
            times = timing.throughput_group(entries, rounds, seed=seed)
            ref = times[("rotjax objects", "forward")]
            ref_g = times[("rotjax objects", "grad")]
            for c in contenders:
                rows.append(
                    {
                        "pipeline": name,
                        "dtype": dt,
                        "contender": c,
                        "ns_per_rot": timing.median_time(times[(c, "forward")])
                        / (1 << log2_batch)
                        * 1e9,
                        "grad_ns_per_rot": timing.median_time(times[(c, "grad")])
                        / (1 << log2_batch)
                        * 1e9,
                        # rotjax objects' speed / this contender's (above 1: rotjax faster)
                        "speedup": timing.median_ratio(times[(c, "forward")], ref),
                        "grad_speedup": timing.median_ratio(times[(c, "grad")], ref_g),
                        "compile_s": compile_s[c][0],
                        "grad_compile_s": compile_s[c][1],
                        "bytes_ratio": byte_ratio.get(c, (None, None))[0],
                        "grad_bytes_ratio": byte_ratio.get(c, (None, None))[1],
                    }
                )
            print(f"{name} {dt}: done", file=sys.stderr, flush=True)
    return rows


def _meta(log2_batch, rounds):
    import jax

    from .cli import commit_id, package_versions

    try:
        cpu = next(
            line.split(":", 1)[1].strip()
            for line in Path("/proc/cpuinfo").read_text().splitlines()
            if line.startswith("model name")
        )
    except (OSError, StopIteration):
        cpu = platform.processor() or platform.machine()
    return {
        "date": datetime.date.today().isoformat(),
        "machine": f"{cpu}, {os.cpu_count()} cores",
        "device": str(jax.devices()[0].device_kind),
        "batch": 1 << log2_batch,
        "rounds": rounds,
        "commit": commit_id(),
        "versions": package_versions(),
    }


def _fmt(v, spec):
    return "" if v is None else format(v, spec)


def markdown(doc) -> str:
    """One table per pipeline: contenders' speed against rotjax's objects, forward and
    ``jit(grad)``, bytes over inputs plus outputs, compile seconds."""
    meta, rows = doc["meta"], doc["rows"]
    lines = []
    for name in dict.fromkeys(r["pipeline"] for r in rows):
        lines += [
            f"**{name}**",
            "",
            "| contender | dtype | ns/rot | rotjax objects' speed ÷ this | grad ns/rot "
            "| grad: rotjax objects ÷ this | bytes ÷ I/O | grad bytes ÷ I/O | compile s "
            "| grad compile s |",
            "|---|---|--:|--:|--:|--:|--:|--:|--:|--:|",
        ]
        for r in rows:
            if r["pipeline"] != name:
                continue
            lines.append(
                f"| {r['contender']} | {r['dtype']} | {_fmt(r['ns_per_rot'], '.2f')} "
                f"| {_fmt(r['speedup'], '.2f')} | {_fmt(r['grad_ns_per_rot'], '.2f')} "
                f"| {_fmt(r['grad_speedup'], '.2f')} | {_fmt(r['bytes_ratio'], '.2f')} "
                f"| {_fmt(r['grad_bytes_ratio'], '.2f')} | {_fmt(r['compile_s'], '.2f')} "
                f"| {_fmt(r['grad_compile_s'], '.2f')} |"
            )
        lines.append("")
    lines.append(
        f"Measured {meta['date']} on {meta['machine']} ({meta['device']}), batch "
        f"{meta['batch']:,}, {meta['rounds']} rounds, rotjax {meta['commit']}, jax "
        f"{meta['versions'].get('jax')}. Compile: trace, lower and compile of a new `jax.jit` "
        "in the measuring process, no compilation cache."
    )
    return "\n".join(lines) + "\n"


def generated_table(json_path, out_dir, name, markdown, check=False) -> list[str]:
    """Write (or, with ``check``, compare) ``out_dir/_generated/name`` as ``markdown(doc)`` of the
    JSON file ``json_path``, if that exists; the stale paths."""
    path = Path(json_path)
    if not path.exists():
        return []
    text = markdown(json.loads(path.read_text()))
    target = Path(out_dir) / "_generated" / name
    if target.exists() and target.read_text() == text:
        return []
    if not check:
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(text)
    return [str(target)]


def generate(json_path, out_dir, check=False) -> list[str]:
    """Write (or, with ``check``, compare) ``out_dir/_generated/pipelines.md``; the stale paths."""
    return generated_table(json_path, out_dir, "pipelines.md", markdown, check)


def main(argv) -> int:
    p = argparse.ArgumentParser(prog="python -m rotjax bench pipelines", description=__doc__)
    p.add_argument("--log2-batch", type=int, default=18, help="batch of 2^N (default 18)")
    p.add_argument("--rounds", type=int, default=9)
    p.add_argument("--json", default=DEFAULT_JSON, help=f"output (default {DEFAULT_JSON})")
    args = p.parse_args(argv)
    from .cli import SCIPY_ENV, rerun_with

    rc = rerun_with(SCIPY_ENV, ["pipelines", *argv])  # scipy on JAX arrays
    if rc is not None:
        return rc
    rows = measure(args.log2_batch, args.rounds)
    doc = {"meta": _meta(args.log2_batch, args.rounds), "rows": rows}
    Path(args.json).write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.json}", file=sys.stderr)
    print(markdown(doc))
    return 0


__all__ = ["main", "generate", "markdown", "measure", "pipelines", "statistics"]
