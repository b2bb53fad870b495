"""Interlace flicker and the performance analyzer's cost (issue 27 items 2 and 7), on the default
course's completed scene (riders chased by the camera, objects, shadows; ``ScenePreview.frames``,
pipelined as in ``piste demo``).

1. **Flicker**: the video's frame-to-frame energy of the line-alternating component
   (:func:`piste.render.interlace.flicker`) for progressive frames, ``--interlace`` and
   ``--interlace --flicker-filter``.
2. **Trace cost**: ms a frame untraced, with CPU spans only, with GL_TIME_ELAPSED timer queries and
   with glFinish brackets (runs interleaved; medians), and each way's per-pass GPU medians.

Run: ``.venv/bin/python benchmarks/bench_trace.py [--quick] [--frames N] [--runs R] [--size W H]``
"""

from __future__ import annotations

import argparse
import collections
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # (see bench_frame.py)

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="8 frames, 2 runs")
    ap.add_argument("--frames", type=int, help="frames per configuration (default 30, quick 8)")
    ap.add_argument("--runs", type=int, help="interleaved runs of each trace mode (default 5, quick 2)")
    ap.add_argument("--size", type=int, nargs=2, default=(640, 448), metavar=("W", "H"))
    args = ap.parse_args(argv)
    n = args.frames or (8 if args.quick else 30)
    runs = args.runs or (2 if args.quick else 5)

    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.default_scene import build_default_scene
    from piste.pipeline.preview import ScenePreview
    from piste.render.interlace import field_times, flicker, interlace
    from piste.render.trace import NULL_TRACER, ChromeTracer, load_trace

    b = load_bundle(build_default_scene(0).path, verify=False, warm=True)
    p = ScenePreview(b, size=tuple(args.size))
    try:
        for k in range(3):  # warm-up
            p.render(None, k / 30)
        times = [k / 30 for k in range(n)]
        print(f"default course, completed scene, {n} frames at {args.size[0]}x{args.size[1]}, "
              f"{p.ctx.info.get('GL_RENDERER')}")
        prog = np.stack(list(p.frames(times)))
        raw = np.stack(list(interlace(p.frames(field_times(times, 30)))))
        filt = np.stack(list(interlace(p.frames(field_times(times, 30)), filtered=True)))
        print("flicker (line-alternating luma component, mean squared change frame to frame):")
        for name, v in (("progressive", prog), ("interlaced", raw), ("interlaced + flicker filter", filt)):
            print(f"  {name:<28} {flicker(v):8.2f}")
        with tempfile.TemporaryDirectory() as tmp:
            modes = {"untraced": lambda m: NULL_TRACER,
                     "CPU spans only": lambda m: ChromeTracer(Path(tmp) / f"{m}.json"),
                     "GL_TIME_ELAPSED": lambda m: ChromeTracer(Path(tmp) / f"{m}.json", ctx=p.ctx, gpu="query"),
                     "glFinish": lambda m: ChromeTracer(Path(tmp) / f"{m}.json", ctx=p.ctx, gpu="finish")}
            ms = collections.defaultdict(list)
            gpu = collections.defaultdict(lambda: collections.defaultdict(list))
            for r in range(runs):
                for m, make in modes.items():
                    tr = make(f"{m}{r}")
                    p.tracer = p.renderer.tracer = tr
                    t0 = time.perf_counter()
                    for _ in p.frames(times, read=True):
                        pass
                    ms[m].append((time.perf_counter() - t0) / n * 1e3)
                    path = tr.close()
                    if path is not None and tr.gpu_timing:
                        for e in load_trace(path)["traceEvents"]:
                            if e["ph"] == "X" and e["cat"] == "gpu":
                                gpu[m][e["name"]].append(e["dur"] / 1e3)
            p.tracer = p.renderer.tracer = NULL_TRACER
        print(f"trace cost (ms a frame, pipelined, median of {runs} interleaved runs [min-max]):")
        for m, v in ms.items():
            print(f"  {m:<28} {np.median(v):7.2f}  [{min(v):.2f}-{max(v):.2f}]")
        for m, passes in gpu.items():
            print(f"  GPU spans, {m:<17} " + ", ".join(f"{k} {np.median(v):.2f}" for k, v in passes.items()))
    finally:
        p.release()
    return 0


if __name__ == "__main__":
    sys.exit(main())
