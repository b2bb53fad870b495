"""Run every benchmark and print one summary table: goal / piste / peer / ratio.

Each ``benchmarks/bench_*.py`` runs in its own process (``--quick`` unless ``--full``), its output
shown as it goes; the benchmarks that measure a goal append rows through ``_timing.record`` to a
file named by ``PISTE_BENCH_OUT``, collected here at the end.  Exit status 1 if a benchmark failed
(a missed goal is reported, not a failure: these are measurements, not tests).

Run: ``.venv/bin/python benchmarks/summary.py [--full] [--only terrain frame ...]`` (``make bench``)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="full runs (default: every benchmark with --quick)")
    ap.add_argument("--only", nargs="+", metavar="NAME", help="only these benchmarks (e.g. terrain frame skinning)")
    ap.add_argument("--quiet", action="store_true", help="hide the benchmarks' own output, print the table only")
    args = ap.parse_args(argv)
    benches = sorted(HERE.glob("bench_*.py"))
    if args.only:
        benches = [b for b in benches if b.stem.removeprefix("bench_") in args.only]
    failed = []
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "rows.jsonl"
        env = dict(os.environ, PISTE_BENCH_OUT=str(out))
        times = {}
        for b in benches:
            cmd = [sys.executable, str(b)] + ([] if args.full else ["--quick"])
            print(f"\n##### {b.name} {'' if args.full else '--quick'}", flush=True)
            t0 = time.perf_counter()
            res = subprocess.run(cmd, env=env, stdout=subprocess.PIPE if args.quiet else None,
                                 stderr=subprocess.STDOUT if args.quiet else None)
            times[b.stem] = time.perf_counter() - t0
            if res.returncode:
                failed.append(b.name)
                print(f"##### {b.name} failed (exit {res.returncode})")
        rows = [json.loads(line) for line in out.read_text().splitlines()] if out.exists() else []
    print("\n" + "=" * 30 + " summary (medians of interleaved runs; this machine, llvmpipe, no GPU) " + "=" * 30)
    head = ("bench", "what", "goal", "piste", "peer / before", "ratio", "goal met")
    table = [head] + [(r["bench"], r["what"], r["goal"], r["piste"], r["peer"], r["ratio"],
                       "" if r["met"] is None else ("yes" if r["met"] else "NO")) for r in rows]
    widths = [max(len(str(row[i])) for row in table) for i in range(len(head))]
    for k, row in enumerate(table):
        print("  ".join(str(c).ljust(w) for c, w in zip(row, widths)))
        if k == 0:
            print("  ".join("-" * w for w in widths))
    print(f"\nran {len(benches)} benchmarks in {sum(times.values()):.0f} s"
          + (f"; FAILED: {', '.join(failed)}" if failed else ""))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
