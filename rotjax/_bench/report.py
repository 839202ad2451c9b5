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
PEERS = ("jax.scipy", "jaxlie", "scipy")
HEADLINE_OPS = (
    "matrix_to_quaternion",
    "quaternion_to_matrix",
    "quaternion_to_euler",
    "matrix_to_euler",
    "quaternion_to_rotvec",
    "rotvec_to_quaternion",
)
README_START, README_END = "<!-- headline:start -->", "<!-- headline:end -->"
# Distinct per dtype, so that no two points of one contender share a marker.
MARKERS = {"float32": "o", "float64": "s", "bfloat16": "^", "float16": "v"}
PANELS = (
    ("matrix_to_quaternion", None, "matrix to quaternion, clean sets"),
    ("matrix_to_quaternion", "noisy_0.0001", "matrix to quaternion, noise 1e-4 (vs optimal)"),
    ("quaternion_to_euler", None, "quaternion to Euler, backward error"),
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
    kept = [r for r in rows if r["op"] not in ops]
    order = {op: i for i, op in enumerate(CASES)}
    merged = sorted(kept + new_rows, key=lambda r: order.get(r["op"], len(order)))  # stable
    later = [{**e, "ops": [op for op in e["ops"] if op not in ops]} for e in later_runs(meta)]
    later = [e for e in later if e["ops"]]
    entry = {"ops": sorted(ops, key=order.get), "date": new_meta["date"]}
    entry.update(seconds=new_meta.get("seconds"), versions=new_meta.get("versions"))
    if new_meta.get("machine") != meta.get("machine"):
        entry["machine"] = new_meta.get("machine")
    if why:
        entry["why"] = why
    return {**meta, "rows_from_a_later_run": later + [entry]}, merged


def contender(r) -> str:
    """``impl`` or ``impl:method``: one label per contender."""
    return r["impl"] + (f":{r['method']}" if r["method"] else "")


def _fmt(v, spec):
    width = int(spec.split(".")[0]) if spec[0].isdigit() else 0
    return f"{'-':>{width}}" if v is None else format(v, spec)


def _pct(r):
    return None if r["vs_copy"] is None else 100 * r["vs_copy"]


# (header, width, value, format) of the table columns
_TABLE = (
    ("Mrot/s", 8, lambda r: r["mrot_s"], ".1f"),
    ("%copy", 7, _pct, ".0f"),
    ("x rotjax", 9, lambda r: r["vs_rotjax"], ".2f"),
    ("eager us", 9, lambda r: r["eager_us"], ".1f"),
    ("x scipy", 8, lambda r: r["eager_vs_scipy"], ".2f"),
    ("compile s", 10, lambda r: r["compile_s"], ".2f"),
    ("grad Mrot/s", 12, lambda r: r["grad_mrot_s"], ".1f"),
    ("grad/fwd", 9, lambda r: r["grad_over_fwd"], ".2f"),
    ("max eps", 10, lambda r: r["err_max_eps"], ".3g"),
    ("med eps", 9, lambda r: r["err_median_eps"], ".3g"),
)


def table(rows) -> str:
    """The fixed-width text table printed by a run."""
    head = f"{'operation':<35}{'impl':<11}{'method':<12}{'dtype':<9}"
    head += "".join(f"{h:>{w}}" for h, w, _, _ in _TABLE)
    lines = [head, "-" * len(head)]
    for r in rows:
        cells = "".join(_fmt(get(r), f"{w}{spec}") for _, w, get, spec in _TABLE)
        lines.append(f"{r['op']:<35}{r['impl']:<11}{r['method'] or '-':<12}{r['dtype']:<9}{cells}")
    return "\n".join(lines)


def _machine(m) -> str:
    return f"{m.get('cpu', '?')} ({m.get('cores', '?')} cores)"


def provenance(meta) -> str:
    """One line: machine, device, date, versions and batch of a run."""
    m = meta.get("machine", {})
    versions = meta.get("versions") or {"jax": meta.get("jax")}
    vs = ", ".join(f"{k} {v}" for k, v in versions.items() if v)
    batch = meta.get("batch")
    size = f"2^{batch.bit_length() - 1}" if batch and batch & (batch - 1) == 0 else str(batch)
    line = (
        f"Machine: {_machine(m)}, device {meta.get('device')}"
        f"; date {meta.get('date')}; {vs}; batch {size}"
        + ("; --quick" if meta.get("quick") else "")
        + "."
    )
    for later in later_runs(meta):
        on = f" on {_machine(later['machine'])}" if later.get("machine") else ""
        line += f" Rows of {', '.join(later['ops'])} from a run of {later['date']}{on}."
    return line


def markdown_table(meta, rows) -> str:
    """Every row, as a markdown table, under the provenance line."""
    head = ["operation", "contender", "dtype"] + [h for h, _, _, _ in _TABLE]
    out = [provenance(meta), "", "| " + " | ".join(head) + " |"]
    out.append("|" + "|".join([":--"] * 3 + ["--:"] * len(_TABLE)) + "|")
    for r in rows:
        cells = [_fmt(get(r), spec) for _, _, get, spec in _TABLE]
        out.append("| " + " | ".join([r["op"], contender(r), r["dtype"], *cells]) + " |")
    return "\n".join(out) + "\n"


def _num(v):
    """Three significant digits, without an exponent up to 10^7."""
    return f"{v:,.0f}" if abs(v) >= 100 else f"{v:.3g}"


def _eps(r):
    """The largest error; "NaN" where some output was not finite (written as null)."""
    if r["err_max_eps"] is not None:
        return f"{r['err_max_eps']:.2g} eps"
    return "NaN output" if r["err_by_set"] else "-"


def headline(meta, rows, dtype="float64") -> str:
    """rotjax's default method against each peer, one line per conversion, in ``dtype``."""
    by = {}
    for r in rows:
        if r["dtype"] == dtype and r["impl"] != "copy":
            by.setdefault((r["op"], r["impl"]), r)  # rotjax's first row: its default method
    out = [
        f"Throughput of rotjax ({dtype}, batch of {meta.get('batch')}, jitted) and how many "
        "times faster it is than each peer; largest error over the adversarial sets, in eps.",
        "",
        "| conversion | rotjax | " + " | ".join(PEERS) + " |",
        "|:--|--:|" + "--:|" * len(PEERS),
    ]
    for op in HEADLINE_OPS:
        own = by.get((op, "rotjax"))
        if own is None:
            continue
        cells = [f"{_num(own['mrot_s'])} Mrot/s, {_eps(own)}"]
        for p in PEERS:
            r = by.get((op, p))
            if r is None or not r["vs_rotjax"]:
                cells.append("-")
            else:
                cells.append(f"{_num(1 / r['vs_rotjax'])}x, {_eps(r)}")
        out.append(f"| {op} | " + " | ".join(cells) + " |")
    out += ["", provenance(meta)]
    return "\n".join(out) + "\n"


def digest(meta, rows) -> str:
    """What the plot was drawn from, the data and this module's code (stored in the PNG and
    compared by ``--check``, since pixels can differ between matplotlib versions)."""
    h = hashlib.sha256(dumps(meta, rows).encode())
    h.update(Path(__file__).read_bytes())
    return h.hexdigest()[:16]


def figure(meta, rows):
    """Throughput against largest error, one panel per entry of ``PANELS``.

    Colour: the contender; marker: the dtype; the two legends name each once, so no label is
    drawn on the points.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    names = sorted({contender(r) for r in rows if r["impl"] != "copy"})
    cmap = plt.get_cmap("tab10" if len(names) <= 10 else "tab20")
    colour = {name: cmap(i % cmap.N) for i, name in enumerate(names)}
    fig, axes = plt.subplots(1, len(PANELS), figsize=(5.2 * len(PANELS), 4.8), squeeze=False)
    used = set()
    for ax, (op, set_name, title) in zip(axes[0], PANELS, strict=True):
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
                s=42,
                edgecolors="black",
                linewidths=0.4,
            )
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("throughput (million rotations/s, higher is better)")
        ax.set_ylabel("largest error (eps of the dtype, lower is better)")
        ax.set_title(title, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
    shown = sorted({n for n, _ in used})
    dtypes = [d for d in MARKERS if any(d == dt for _, dt in used)]
    by_colour = [Line2D([], [], ls="", marker="o", color=colour[n], label=n) for n in shown]
    by_marker = [
        Line2D([], [], ls="", marker=MARKERS[d], color="white", mec="black", label=d)
        for d in dtypes
    ]
    kw = {"loc": "lower center", "fontsize": 8, "title_fontsize": 8, "frameon": False}
    fig.legend(handles=by_colour, title="contender (colour)", ncol=4, bbox_to_anchor=(0.4, 0), **kw)
    fig.legend(handles=by_marker, title="dtype (marker)", ncol=4, bbox_to_anchor=(0.8, 0), **kw)
    m = meta.get("machine", {})
    title = (
        f"rotjax benchmark on {m.get('cpu', '?')} ({meta.get('device')}), {meta.get('date')}, "
        f"jax {meta.get('jax')}, batch {meta.get('batch')}"
    )
    for later in later_runs(meta):
        if later.get("machine"):
            title += f"\n{', '.join(later['ops'])}: {later['date']} on {_machine(later['machine'])}"
    fig.suptitle(title, fontsize=11)
    fig.tight_layout(rect=(0, 0.13, 1, 1))
    return fig


def write_plot(meta, rows, path: Path) -> bool:
    """The figure as a PNG carrying the digest of its data; False without matplotlib."""
    try:
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    fig = figure(meta, rows)
    fig.savefig(path, dpi=110, metadata={"Software": None, "Source": digest(meta, rows)})
    plt.close(fig)
    return True


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

    Writes ``out_dir/bench{suffix}.png``, ``out_dir/_generated/bench_table{suffix}.md``,
    ``out_dir/_generated/headline{suffix}.md``, and the README block between
    ``README_START`` and ``README_END`` when ``readme`` has them. Returns the paths that are
    (with ``check``: would be) changed.
    """
    meta, rows = load(json_path)
    out_dir = Path(out_dir)
    gen = out_dir / "_generated"
    head = headline(meta, rows)
    texts = {
        gen / f"bench_table{suffix}.md": markdown_table(meta, rows),
        gen / f"headline{suffix}.md": head,
    }
    if readme is not None and Path(readme).exists():
        new = readme_block(Path(readme).read_text(), head)
        if new is not None:
            texts[Path(readme)] = new
    stale = [str(p) for p, t in texts.items() if not p.exists() or p.read_text() != t]
    png = out_dir / f"bench{suffix}.png"
    png_stale = not png.exists() or plot_digest(png) != digest(meta, rows)
    if png_stale:
        stale.append(str(png))
    if check:
        return stale
    gen.mkdir(parents=True, exist_ok=True)
    for p, t in texts.items():
        if str(p) in stale:
            p.write_text(t)
    if png_stale:
        write_plot(meta, rows, png)
    return stale
