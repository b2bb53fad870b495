"""Shared timing for the benchmarks: every contender (piste and its peers) is timed the same way,
interleaved in one process (round 1: A, B, C; round 2: B, C, A; ...: the order rotated) so load from
other processes hits them alike, and reported as the median with the range (min-max) over the rounds.
A contender may bring an untimed set-up per call (``(setup, call)``), so a peer's input is handed over
through its own API outside the timed region when only piste's compiled call is timed.

``record(...)`` appends a summary row (goal / piste / peer / ratio) to the JSON-lines file named by
``PISTE_BENCH_OUT`` when set (``benchmarks/summary.py`` collects them into one table).
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

_clock = time.perf_counter  # (tests substitute a fake clock)


def interleaved(fns: dict, rounds: int, warmup: int = 1, inner: int = 1, rotate: bool = True) -> dict:
    """Seconds per call of each contender over ``rounds`` interleaved rounds: ``{name: (rounds,) array}``.

    ``fns[name]`` is a callable (all of it timed) or a ``(setup, call)`` pair: ``setup()`` runs
    before every timed ``call()`` and is not timed (e.g. handing a peer this round's input through its
    own API, so only its compiled call is timed, as piste's is).  Each round times ``inner`` calls
    (for calls too short to time alone); with ``rotate`` round ``r`` starts at contender ``r mod k``
    (A B C, B C A, C A B, ...) so no contender always runs right after the same other one."""
    pairs = {k: (f if isinstance(f, tuple) else (None, f)) for k, f in fns.items()}
    names = list(pairs)
    for _ in range(warmup):
        for setup, fn in pairs.values():
            if setup is not None:
                setup()
            fn()
    out = {k: [] for k in names}
    clock = _clock
    for r in range(rounds):
        k0 = r % len(names) if rotate and names else 0
        for name in names[k0:] + names[:k0]:
            setup, fn = pairs[name]
            if setup is None:
                t0 = clock()
                for _ in range(inner):
                    fn()
                dt = clock() - t0
            else:
                dt = 0.0
                for _ in range(inner):
                    setup()
                    t0 = clock()
                    fn()
                    dt += clock() - t0
            out[name].append(dt / inner)
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
