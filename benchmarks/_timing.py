"""Shared timing for the benchmarks: every contender (piste and its peers) is timed the same way,
interleaved in one process (round 1: A, B, C; round 2: A, B, C; ...) so load from other processes
hits them alike, and reported as the median with the range (min-max) over the rounds.

``record(...)`` appends a summary row (goal / piste / peer / ratio) to the JSON-lines file named by
``PISTE_BENCH_OUT`` when set (``benchmarks/summary.py`` collects them into one table).
"""

from __future__ import annotations

import json
import os
import time

import numpy as np


def interleaved(fns: dict, rounds: int, warmup: int = 1, inner: int = 1) -> dict:
    """Seconds per call of each ``fns[name]()`` over ``rounds`` interleaved rounds: ``{name: (rounds,)
    array}``.  Each round times ``inner`` back-to-back calls (for calls too short to time alone)."""
    for _ in range(warmup):
        for fn in fns.values():
            fn()
    out = {k: [] for k in fns}
    for _ in range(rounds):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            for _ in range(inner):
                fn()
            out[name].append((time.perf_counter() - t0) / inner)
    return {k: np.asarray(v) for k, v in out.items()}


def stat(t) -> tuple[float, float, float]:
    """``(median, min, max)`` of an array of times."""
    t = np.asarray(t, dtype=np.float64)
    return float(np.median(t)), float(t.min()), float(t.max())


def ms(t) -> str:
    """``"1.23 ms [1.10-1.50]"``: the median and range of times in seconds."""
    m, lo, hi = stat(t)
    return f"{m * 1e3:.3f} ms [{lo * 1e3:.3f}-{hi * 1e3:.3f}]"


def fit_exponent(ns, ts) -> float:
    """The exponent ``k`` of a least-squares fit ``t ~ n^k`` (log-log)."""
    ns, ts = np.asarray(ns, dtype=np.float64), np.asarray(ts, dtype=np.float64)
    ok = (ns > 0) & (ts > 0)
    if ok.sum() < 2:
        return float("nan")
    return float(np.polyfit(np.log(ns[ok]), np.log(ts[ok]), 1)[0])


def copy_bandwidth(nbytes: int, rounds: int = 15) -> float:
    """This machine's numpy copy bandwidth in bytes/s for a buffer of ``nbytes`` (median of rounds)."""
    a = np.ones(max(int(nbytes) // 8, 1), dtype=np.float64)
    b = np.empty_like(a)
    t = interleaved({"copy": lambda: np.copyto(b, a)}, rounds, warmup=2, inner=5)["copy"]
    return a.nbytes / float(np.median(t))


def record(bench: str, what: str, goal: str, piste: str, peer: str = "", ratio: str = "", met: bool | None = None) -> None:
    """One row of the summary table (written when ``PISTE_BENCH_OUT`` names a file)."""
    path = os.environ.get("PISTE_BENCH_OUT")
    if not path:
        return
    row = {"bench": bench, "what": what, "goal": goal, "piste": piste, "peer": peer, "ratio": ratio,
           "met": None if met is None else bool(met)}
    with open(path, "a") as f:
        f.write(json.dumps(row) + "\n")
