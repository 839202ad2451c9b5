"""Timing: interleaved rounds over the contenders of one group, medians of per-round ratios.

Every contender of an operation and dtype (and the copy kernel, and the gradients) runs once
per round, in an order shuffled every round; ratios are medians over rounds of per-round
ratios, which cancel most of the drift of a shared or throttled machine.
"""

from __future__ import annotations

import random
import statistics
import time

# The copy kernel is a bandwidth limit only on batches that do not fit in cache: on smaller
# batches (--quick) the "%copy" column and the copy row are left out.
MIN_COPY_BATCH = 1 << 20


def copy_kernel(n_in: int, n_out: int):
    """Reads ``n_in`` and writes ``n_out`` floats per rotation, one add per output value; the
    input is an array or a tuple of arrays (joined per rotation)."""
    import jax
    import jax.numpy as jnp

    def f(x):
        leaves = jax.tree.leaves(x)
        x = jnp.concatenate([v.reshape(v.shape[0], -1) for v in leaves], axis=1)
        if n_in >= n_out:  # fold the extra inputs into the outputs so that every byte is read
            out = x[:, :n_out]
            for k in range(n_out, n_in, n_out):
                chunk = x[:, k : k + n_out]
                out = out + jnp.pad(chunk, ((0, 0), (0, n_out - chunk.shape[1])))
            return out
        reps = -(-n_out // n_in)
        return jnp.concatenate([x + x[:, :1]] * reps, axis=1)[:, :n_out]

    return f


def timed(f, x):
    import jax

    t = time.perf_counter()
    jax.block_until_ready(f(x))
    return time.perf_counter() - t


def throughput_group(entries, rounds, slow_s=1.0, slow_rounds=7, seed=0):
    """Interleaved rounds over every contender; returns ``{key: {round: seconds}}``.

    ``entries``: ``{key: (callable, input)}``. The order is shuffled every round (seeded), so
    that no contender always runs right after the same neighbour: a call's time depends on
    what ran before it (the allocator's state after a large gradient buffer was freed, say),
    and a fixed or merely rotated order would charge that to the same contender every round.
    A contender slower than ``slow_s`` per call (an eigendecomposition per matrix, say) sits
    out after ``slow_rounds`` rounds; its ratios are then medians over the rounds it ran in:
    seven by default, which take about as long as a burst of a shared machine (10-20 s), so
    that one burst rarely decides the median.
    """
    keys = list(entries)
    times = {k: {} for k in keys}
    shuffle = random.Random(seed).shuffle
    for r in range(rounds):
        order = keys[:]
        shuffle(order)
        for k in order:
            if r >= slow_rounds and statistics.median(times[k].values()) > slow_s:
                continue
            f, x = entries[k]
            times[k][r] = timed(f, x)
    return times


def median_ratio(num, den):
    """Median over shared rounds of ``num / den`` (dicts round -> seconds, or two lists)."""
    if isinstance(num, dict):
        shared = sorted(set(num) & set(den))
        return statistics.median(num[r] / den[r] for r in shared)
    return statistics.median(a / b for a, b in zip(num, den, strict=True))


def total(out):
    """Sum of every output leaf (jaxlie returns a named tuple of angles)."""
    import jax
    import jax.numpy as jnp

    return sum(jnp.sum(leaf) for leaf in jax.tree.leaves(out))


def median_time(t):
    return statistics.median(t.values())


def eager(fn, x1, scipy_fn, x1_np, reps):
    """Median single-call latency (us) and its median per-round ratio to scipy's."""
    ts, ss = [], []
    for _ in range(reps):
        ts.append(timed(fn, x1))
        if scipy_fn is not None:
            ss.append(timed(scipy_fn, x1_np))
    med = statistics.median(ts) * 1e6
    return med, (median_ratio(ts, ss) if ss else None)
