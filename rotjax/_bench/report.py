"""Reports of a benchmark run: the text table, the markdown tables, the plot, the README block.

Everything here reads the rows and meta of ``bench.json`` only, so the documentation can be
regenerated (``python -m rotjax bench report``) without measuring anything.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

COLUMNS = (
    "op",
    "impl",
    "method",
    "dtype",
    "mrot_s",
    "vs_copy",
    "vs_rotjax",
    "eager_us",
    "eager_vs_scipy",
    "compile_s",
    "grad_mrot_s",
    "grad_over_fwd",
    "err_max_eps",
    "err_median_eps",
    "err_by_set",
)
PEERS = ("jax.scipy", "jaxlie", "scipy-jax", "scipy")
PEER_LABELS = {
    "jax.scipy": "jax.scipy",
    "jaxlie": "jaxlie",
    "scipy-jax": "scipy on JAX",
    "scipy": "scipy on NumPy",
}
HEADLINE_OPS = (
    "matrix_to_quaternion",
    "quaternion_to_matrix",
    "quaternion_to_euler",
    "matrix_to_euler",
    "quaternion_to_rotvec",
    "rotvec_to_quaternion",
    "quaternion_apply",
)
README_START, README_END = "<!-- headline:start -->", "<!-- headline:end -->"
# Distinct per dtype, so that no two points of one contender share a marker.
MARKERS = {"float32": "o", "float64": "s", "bfloat16": "^", "float16": "v"}
# (file key, operation, accuracy set or None for the clean sets, title): one figure each.
PANELS = (
    ("m2q", "matrix_to_quaternion", None, "matrix to quaternion, clean sets"),
    ("m2q-noisy", "matrix_to_quaternion", "noisy_0.0001", "matrix to quaternion, noise 1e-4"),
    ("q2e", "quaternion_to_euler", None, "quaternion to Euler angles, backward error"),
)
# The plots are drawn at the width the docs show them (mkdocs-material's content column at a
# 1280-pixel window), so that their text is read at the size it is drawn.
PLOT_WIDTH_PX, PLOT_DPI = 690, 100
SPEED_RATIO = "rotjax speed ÷ {}"
SPEED_RATIO_NOTE = (
    "Speed ratios are rotjax's throughput divided by the other's (median of per-round ratios, "
    "jitted, contenders interleaved): above 1 rotjax is faster, below 1 slower (0.5x: half "
    "as fast)."
)


def finite_or_none(x):
    """JSON has no inf/NaN: an infinite error (a NaN result) is written as null."""
    x = float(x)
    return x if x == x and abs(x) != float("inf") else None


def load(path):
    """``(meta, rows)`` of a ``bench.json``."""
    data = json.loads(Path(path).read_text())
    return data["meta"], data["rows"]


def dumps(meta, rows) -> str:
    return json.dumps({"meta": meta, "rows": rows}, indent=1, allow_nan=False)


def later_runs(meta) -> list[dict]:
    """The notes of the runs whose rows were merged into this one (see :func:`merge`)."""
    later = meta.get("rows_from_a_later_run") or []
    return [later] if isinstance(later, dict) else list(later)


def merge(meta, rows, new_meta, new_rows, why=""):
    """``(meta, rows)`` with the operations of ``new_rows`` replaced by them, in the registry's
    order, and the later run noted in ``meta["rows_from_a_later_run"]``. The two runs must
    share the batch size and device; a run on another machine is noted with its machine."""
    from .cases import CASES

    for key in ("batch", "device"):
        if meta.get(key) != new_meta.get(key):
            raise ValueError(
                f"cannot merge a run of {key} {new_meta.get(key)!r} into one of {meta.get(key)!r}"
            )
    ops = {r["op"] for r in new_rows}
    measured = {(r["op"], r.get("dtype")) for r in new_rows}
    kept = [r for r in rows if (r["op"], r.get("dtype")) not in measured]
    order = {op: i for i, op in enumerate(CASES)}
    merged = sorted(kept + new_rows, key=lambda r: order.get(r["op"], len(order)))  # stable
    # An earlier note keeps an operation some of whose dtypes the new run left as they were.
    whole = ops - {r["op"] for r in kept}
    later = [{**e, "ops": [op for op in e["ops"] if op not in whole]} for e in later_runs(meta)]
    later = [e for e in later if e["ops"]]
    entry = {"ops": sorted(ops, key=order.get), "date": new_meta["date"]}
    if ops - whole:
        entry["dtypes"] = sorted({dt for _, dt in measured if dt is not None})
    entry.update(seconds=new_meta.get("seconds"), versions=new_meta.get("versions"))
    for key in ("malloc_env", "commit", "rounds", "accuracy_samples"):
        if key in new_meta:
            entry[key] = new_meta[key]
    if new_meta.get("machine") != meta.get("machine"):
        entry["machine"] = new_meta.get("machine")
    if why:
        entry["why"] = why
    return {**meta, "rows_from_a_later_run": later + [entry]}, merged


def contender(r) -> str:
    """``impl`` or ``impl:method``, with scipy named by the arrays it ran on: one label per
    contender."""
    return PEER_LABELS.get(r["impl"], r["impl"]) + (f":{r['method']}" if r["method"] else "")


def _fmt(v, spec):
    width = int(spec.split(".")[0]) if spec[0].isdigit() else 0
    if isinstance(v, str):
        return f"{v:>{width}}"
    return f"{'-':>{width}}" if v is None else format(v, spec)


def _max_eps(r):
    """The largest error, or "NaN" where some output was not finite (written as null)."""
    if r["err_max_eps"] is None and r["err_by_set"]:
        return "NaN"
    return r["err_max_eps"]


def _pct(r):
    return None if r["vs_copy"] is None else 100 * r["vs_copy"]


def _inv(v):
    return 1 / v if v else None


def speedup(r):
    """rotjax's default method's throughput divided by this row's (above 1: rotjax faster)."""
    return _inv(r["vs_rotjax"])


def eager_speedup(r):
    """scipy's single-call time divided by this row's (above 1: faster than scipy)."""
    return _inv(r["eager_vs_scipy"])


# (header, width, value, format) of the text table printed by a run
_TABLE = (
    ("Mrot/s", 8, lambda r: r["mrot_s"], ".1f"),
    ("%copy", 7, _pct, ".0f"),
    ("rotjax/this", 12, speedup, ".2f"),
    ("eager us", 9, lambda r: r["eager_us"], ".1f"),
    ("scipy/this", 11, eager_speedup, ".2f"),
    ("compile s", 10, lambda r: r["compile_s"], ".2f"),
    ("grad Mrot/s", 12, lambda r: r["grad_mrot_s"], ".1f"),
    ("grad/fwd", 9, lambda r: r["grad_over_fwd"], ".2f"),
    ("max eps", 10, _max_eps, ".3g"),
    ("med eps", 9, lambda r: r["err_median_eps"], ".3g"),
)


def table(rows) -> str:
    """The fixed-width text table printed by a run (rotjax/this: rotjax's default method's
    throughput over this row's; scipy/this: scipy's single-call time over this row's)."""
    head = f"{'operation':<35}{'impl':<11}{'method':<12}{'dtype':<9}"
    head += "".join(f"{h:>{w}}" for h, w, _, _ in _TABLE)
    lines = [head, "-" * len(head)]
    for r in rows:
        cells = "".join(_fmt(get(r), f"{w}{spec}") for _, w, get, spec in _TABLE)
        lines.append(f"{r['op']:<35}{r['impl']:<11}{r['method'] or '-':<12}{r['dtype']:<9}{cells}")
    return "\n".join(lines)


def _machine(m) -> str:
    return f"{m.get('cpu', '?')} ({m.get('cores', '?')} cores)"


def allocator(meta) -> str:
    """Which malloc settings the run measured with (glibc reads them at start-up)."""
    env = {k: v for k, v in (meta.get("malloc_env") or {}).items() if v is not None}
    if not env:
        return "glibc's default malloc settings"
    if set(env.values()) == {str(1 << 30)}:
        return "glibc malloc with mmap and trim thresholds pinned at 1 GiB"
    return "glibc malloc with " + ", ".join(f"{k}={v}" for k, v in sorted(env.items()))


def _device(meta) -> str:
    kind, _, name = (meta.get("device") or "?").partition(": ")
    return "CPU" if kind == "cpu" else (name or kind)


def _batch(meta) -> str:
    batch = meta.get("batch")
    return f"2^{batch.bit_length() - 1}" if batch and batch & (batch - 1) == 0 else str(batch)


def _run_of(meta, ops):
    """``(date, machine, allocator)`` of the run that measured ``ops`` (a merged run or the
    main one)."""
    date, machine, alloc = meta.get("date"), meta.get("machine", {}), allocator(meta)
    for later in later_runs(meta):
        if set(ops) & set(later["ops"]):
            date, machine = later["date"], later.get("machine") or machine
            alloc = allocator(later) if "malloc_env" in later else alloc
    return date, machine, alloc


def caption(meta, ops) -> str:
    """One line under each generated table: machine, device, dates, batch and allocator of the
    runs that measured ``ops``."""
    runs = [_run_of(meta, [op]) for op in ops] or [_run_of(meta, [])]
    dates = sorted({d[:10] for d, _, _ in runs})
    machines = list(dict.fromkeys(_machine(m) for _, m, _ in runs))
    allocs = list(dict.fromkeys(a for _, _, a in runs))
    when = dates[0] if len(dates) == 1 else f"{dates[0]} to {dates[-1]}"
    quick = ", --quick" if meta.get("quick") else ""
    return (
        f"*{' and '.join(machines)}, {_device(meta)}; measured {when}; batch {_batch(meta)}"
        f"{quick}; {' and '.join(allocs)}.*"
    )


def provenance(meta) -> str:
    """The machine paragraph: machine, device, date, versions, batch, allocator and run time,
    and the runs whose rows were merged in."""
    m = meta.get("machine", {})
    versions = meta.get("versions") or {"jax": meta.get("jax")}
    vs = ", ".join(f"{k} {v}" for k, v in versions.items() if v)
    secs = meta.get("seconds")
    took = f"; the run took {secs / 60:.0f} min" if secs else ""
    line = (
        f"Machine: {_machine(m)}, {m.get('platform', '')}; device {meta.get('device')}; "
        f"date {meta.get('date')}{took}; {vs}"
        + (f" (commit {meta['commit']})" if meta.get("commit") else "")
        + f"; batch {_batch(meta)}"
        + ("; --quick" if meta.get("quick") else "")
        + (f"; {meta['rounds']} interleaved rounds" if meta.get("rounds") else "")
        + (
            f"; {meta['accuracy_samples']} accuracy samples per set"
            if meta.get("accuracy_samples")
            else ""
        )
        + (
            " (a full run's defaults are 21 and 96)"
            if not meta.get("quick")
            and (meta.get("rounds"), meta.get("accuracy_samples")) not in ((21, 96), (None, None))
            else ""
        )
        + f"; {allocator(meta)}."
    )
    if meta.get("grad_not_timed"):
        line += f" jit(grad) not timed for {', '.join(meta['grad_not_timed'])}."
    for later in later_runs(meta):
        on = f" on {_machine(later['machine'])}" if later.get("machine") else ""
        alloc = f", {allocator(later)}" if "malloc_env" in later else ""
        dts = f" ({', '.join(later['dtypes'])})" if later.get("dtypes") else ""
        line += f" Rows of {', '.join(later['ops'])}{dts} from a run of {later['date']}{on}{alloc}."
    return line


def _md_table(head, align, lines) -> list[str]:
    return [
        "| " + " | ".join(head) + " |",
        "|" + "|".join(":--" if a == "l" else "--:" for a in align) + "|",
        *("| " + " | ".join(cells) + " |" for cells in lines),
    ]


# (header, value, format) of the per-operation tables: the main one, and the one in the fold.
# Six columns: what fits the docs' content column (690 px), and a fold, without scrolling.
_MAIN = (
    ("Mrot/s", lambda r: r["mrot_s"], ".1f"),
    (SPEED_RATIO.format("this"), speedup, ".2f"),
    ("grad ÷ forward speed", lambda r: r["grad_over_fwd"], ".2f"),
    ("max eps", _max_eps, ".3g"),
)
_MORE = (
    ("% of copy", _pct, ".0f"),
    ("eager µs", lambda r: r["eager_us"], ".1f"),
    ("scipy ÷ this, eager time", eager_speedup, ".2f"),
    ("compile s", lambda r: r["compile_s"], ".2f"),
)


def _by_op(rows):
    ops = {}
    for r in rows:
        ops.setdefault(r["op"], []).append(r)
    return ops


def markdown_table(meta, rows) -> str:
    """One section per operation: a table of the main columns, its caption, and the other
    columns in a fold (at most 7 columns each, to fit the docs' content width)."""
    out = []
    for op, rs in _by_op(rows).items():
        out += [f"### {op}", "", caption(meta, [op]), ""]
        for cols, indent in ((_MAIN, ""), (_MORE, "    ")):
            head = ["contender", "dtype", *(h for h, _, _ in cols)]
            lines = [
                [contender(r), r["dtype"], *(_fmt(get(r), spec) for _, get, spec in cols)]
                for r in rs
                if cols is _MAIN or r["impl"] != "copy"
            ]
            if indent:
                out += ['??? note "Bandwidth, single-call latency, compile time"', ""]
            out += [indent + line for line in _md_table(head, "ll" + "r" * len(cols), lines)]
            out.append("")
    return "\n".join(out)


def _num(v):
    """Three significant digits, without an exponent up to 10^7."""
    return f"{v:,.0f}" if abs(v) >= 100 else f"{v:.3g}"


def _eps(r):
    """The largest error in eps; "NaN" where some output was not finite (written as null)."""
    if r["err_max_eps"] is not None:
        return f"{r['err_max_eps']:.2g}"
    return "NaN" if r["err_by_set"] else "-"


def headline(meta, rows) -> str:
    """rotjax's default method against each peer, per conversion and dtype: a speed table and
    an accuracy table, each with its caption."""
    by = {}
    for r in rows:
        if r["dtype"] in ("float32", "float64") and r["impl"] != "copy":
            by.setdefault((r["op"], r["dtype"], r["impl"]), r)  # rotjax's default method first
    peers = [p for p in PEERS if any(k[2] == p for k in by)]
    keys = [(op, dt) for op in HEADLINE_OPS for dt in ("float32", "float64")]
    keys = [k for k in keys if (*k, "rotjax") in by]
    align = "l" + "r" * (1 + len(peers))
    labels = [PEER_LABELS.get(p, p) for p in peers]
    out = [
        "Speed: rotjax's throughput in millions of rotations per second, and the speed ratio "
        "to each peer. " + SPEED_RATIO_NOTE,
        "",
    ]
    acc_out = [
        "Accuracy: the largest error over the adversarial sets, in eps of the dtype (lower is "
        "better; NaN: some output was NaN).",
        "",
    ]
    for dt in ("float32", "float64"):
        speed, acc = [], []
        for op, _ in [k for k in keys if k[1] == dt]:
            own = by[(op, dt, "rotjax")]
            others = [by.get((op, dt, p)) for p in peers]
            speed.append(
                [op, _num(own["mrot_s"])]
                + [f"{_num(speedup(r))}x" if r and speedup(r) else "-" for r in others]
            )
            acc.append([op, _eps(own)] + [_eps(r) if r else "-" for r in others])
        if not speed:
            continue
        head = [f"{dt} conversion", "rotjax Mrot/s", *(f"rotjax ÷ {p}" for p in labels)]
        out += [*_md_table(head, align, speed), ""]
        acc_out += [*_md_table([f"{dt} conversion", "rotjax", *labels], align, acc), ""]
    out += [caption(meta, sorted({op for op, _ in keys}, key=HEADLINE_OPS.index)), ""]
    out += acc_out
    return "\n".join(out)


def digest(meta, rows) -> str:
    """What the plot was drawn from, the data and this module's code (stored in the PNG and
    compared by ``--check``, since pixels can differ between matplotlib versions)."""
    h = hashlib.sha256(dumps(meta, rows).encode())
    h.update(Path(__file__).read_bytes())
    return h.hexdigest()[:16]


def panels(rows):
    """The entries of ``PANELS`` that ``rows`` have points for."""
    return [p for p in PANELS if any(r["op"] == p[1] and r["err_by_set"] for r in rows)]


def _log_axis(axis):
    """A log scale labelled with plain numbers (0.2, 1, 50): at 1, 2 and 5 times the powers of
    ten where the data span less than two decades, at the powers of ten otherwise."""
    import math

    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    axis.axes.set_xscale("log") if axis is axis.axes.xaxis else axis.axes.set_yscale("log")
    axis.axes.autoscale_view()
    lo, hi = sorted(axis.get_view_interval())
    few = math.log10(hi / lo) < 2
    axis.set_major_locator(LogLocator(10, subs=(1, 2, 5) if few else (1,)))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(NullFormatter())


def figure(meta, rows, panel):
    """Throughput against largest error for one entry of ``PANELS``, drawn at the width the
    docs show it (``PLOT_WIDTH_PX``).

    Colour: the contender; marker: the dtype; the two legends, beside the axes, name each
    once, so no label is drawn on the points.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    _, op, set_name, title = panel
    # One colour per contender across every plot: assigned over all the plotted operations.
    plotted = {p[1] for p in panels(rows)}
    names = sorted({contender(r) for r in rows if r["op"] in plotted and r["impl"] != "copy"})
    cmap = plt.get_cmap("tab10" if len(names) <= 10 else "tab20")
    colour = {name: cmap(i % cmap.N) for i, name in enumerate(names)}
    width = PLOT_WIDTH_PX / PLOT_DPI
    fig = plt.figure(figsize=(width, 0.62 * width), dpi=PLOT_DPI)
    ax = fig.add_axes((0.11, 0.14, 0.55, 0.72))
    used = set()
    for r in rows:
        if r["op"] != op or r["impl"] == "copy" or not r["err_by_set"]:
            continue
        err = (
            r["err_max_eps"]
            if set_name is None
            else (r["err_by_set"].get(set_name) or {}).get("max")
        )
        if err is None or r["mrot_s"] is None:
            continue
        name = contender(r)
        used.add((name, r["dtype"]))
        ax.scatter(
            r["mrot_s"],
            max(err, 1e-2),  # an exact result (0 eps) drawn at the bottom of the log scale
            marker=MARKERS[r["dtype"]],
            color=colour[name],
            s=48,
            edgecolors="black",
            linewidths=0.5,
        )
    ax.margins(0.1)  # room for the markers at the ends: none clipped at the axes
    for axis in (ax.xaxis, ax.yaxis):
        _log_axis(axis)
    ax.set_xlabel("throughput (million rotations/s, higher is better)", fontsize=9)
    ax.set_ylabel("largest error (eps, lower is better)", fontsize=9)
    ax.tick_params(which="both", labelsize=9)
    ax.set_title(title, fontsize=11)
    ax.grid(True, which="both", alpha=0.3)
    shown = sorted({n for n, _ in used})
    dtypes = [d for d in MARKERS if any(d == dt for _, dt in used)]
    by_colour = [
        Line2D([], [], ls="", marker="o", ms=7, color=colour[n], mec="black", mew=0.5, label=n)
        for n in shown
    ]
    by_marker = [
        Line2D([], [], ls="", marker=MARKERS[d], ms=7, color="white", mec="black", label=d)
        for d in dtypes
    ]
    kw = {"loc": "upper left", "fontsize": 9, "title_fontsize": 9, "frameon": False}
    fig.legend(handles=by_colour, title="contender (colour)", bbox_to_anchor=(0.68, 0.87), **kw)
    y = 0.87 - 0.058 * (len(shown) + 1.6)
    fig.legend(handles=by_marker, title="dtype (marker)", bbox_to_anchor=(0.68, y), **kw)
    date, m, _ = _run_of(meta, [op])
    fig.suptitle(
        f"{_machine(m)}, {_device(meta)}, {date[:10]}, batch {_batch(meta)}",
        fontsize=9,
        x=0.02,
        ha="left",
        y=0.985,
        color="0.3",
    )
    return fig


def plot_path(out_dir, panel, suffix="") -> Path:
    return Path(out_dir) / f"bench-{panel[0]}{suffix}.png"


def write_plots(meta, rows, out_dir, suffix="") -> list[Path]:
    """One PNG per panel (see :func:`panels`), each carrying the digest of its data; none
    without matplotlib."""
    try:
        import matplotlib.pyplot as plt
    except ImportError:
        return []
    paths = []
    for panel in panels(rows):
        fig = figure(meta, rows, panel)
        path = plot_path(out_dir, panel, suffix)
        fig.savefig(path, dpi=PLOT_DPI, metadata={"Software": None, "Source": digest(meta, rows)})
        plt.close(fig)
        paths.append(path)
    return paths


def plot_digest(path: Path):
    """The digest stored in a PNG written by :func:`write_plot`, or None."""
    from PIL import Image

    with Image.open(path) as im:
        return im.text.get("Source")


def readme_block(text: str, block: str):
    """``text`` with the headline block replaced, or None when it has no markers."""
    i, j = text.find(README_START), text.find(README_END)
    if i < 0 or j < i:
        return None
    return text[: i + len(README_START)] + "\n" + block + text[j:]


def generate(json_path, out_dir, readme=None, suffix="", check=False) -> list[str]:
    """Write (or, with ``check``, compare) the files generated from ``json_path``.

    Writes ``out_dir/bench-<panel>{suffix}.png`` (one per panel),
    ``out_dir/_generated/bench_table{suffix}.md`` (one table per operation),
    ``out_dir/_generated/headline{suffix}.md``, ``out_dir/_generated/machine{suffix}.md`` (the
    machine paragraph), and the README block between ``README_START`` and ``README_END`` when
    ``readme`` has them. Returns the paths that are (with ``check``: would be) changed.
    """
    meta, rows = load(json_path)
    out_dir = Path(out_dir)
    gen = out_dir / "_generated"
    head = headline(meta, rows)
    texts = {
        gen / f"bench_table{suffix}.md": markdown_table(meta, rows),
        gen / f"headline{suffix}.md": head,
        gen / f"machine{suffix}.md": provenance(meta) + "\n",
    }
    if readme is not None and Path(readme).exists():
        new = readme_block(Path(readme).read_text(), head)
        if new is not None:
            texts[Path(readme)] = new
    stale = [str(p) for p, t in texts.items() if not p.exists() or p.read_text() != t]
    pngs = [plot_path(out_dir, p, suffix) for p in panels(rows)]
    png_stale = [p for p in pngs if not p.exists() or plot_digest(p) != digest(meta, rows)]
    stale += [str(p) for p in png_stale]
    if check:
        return stale
    gen.mkdir(parents=True, exist_ok=True)
    for p, t in texts.items():
        if str(p) in stale:
            p.write_text(t)
    if png_stale:
        write_plots(meta, rows, out_dir, suffix)
    return stale
