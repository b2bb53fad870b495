"""``piste view`` in a window vs the same frame off-screen (``bench_frame.py``'s way), interleaved.

One process, one GL context (the window's): each camera is drawn into the window (render straight
into its framebuffer, overlay, swap) and off-screen into an RGBA8 target with read-back, the order
alternating from one camera to the next, so load from other processes hits both alike.  Prints the median and range of each, fps and the
ratio window / off-screen, for the terrain alone and for the completed scene (riders, objects,
shadows, specular).  The issue's target: the window no more than 10 % slower.

Needs a display: ``xvfb-run -a -s "-screen 0 1024x768x24" .venv/bin/python benchmarks/bench_view.py``
(``benchmarks/summary.py`` / ``make bench`` start it that way when there is no display and Xvfb is
installed); without one it says so, records the row as skipped and exits 0.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _timing import record  # noqa: E402


def _stats(ms):
    a = np.asarray(ms, dtype=np.float64)
    return float(np.median(a)), float(a.min()), float(a.max())


def _skip(reason: str) -> int:
    print(f"bench_view skipped: {reason} (run it under Xvfb: xvfb-run -a -s \"-screen 0 1024x768x24\" "
          f".venv/bin/python benchmarks/bench_view.py; make bench does when Xvfb is installed)")
    record("view", "window vs off-screen frame", "<= 1.10x", "", f"skipped: {reason}", "")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="6 frames per configuration")
    ap.add_argument("--frames", type=int, default=20, help="frames per configuration (default 20)")
    ap.add_argument("--size", type=int, nargs=2, default=(640, 448))
    ap.add_argument("--no-overlay", action="store_true", help="window frames without the statistics overlay")
    args = ap.parse_args(argv)
    frames = 6 if args.quick else args.frames
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return _skip("no display (DISPLAY is not set)")

    import moderngl
    import pyglet

    pyglet.options["debug_gl"] = False
    from piste.render import TerrainRenderer
    from piste.render.overlay import OverlayPass, StatsHistory, overlay_image
    from piste.render.scene_renderer import SceneRenderer
    from piste.render.window import SceneView, TerrainView, ViewOptions
    from piste.world.camera import track_camera
    from piste.world.course import TRACK_HALF_WIDTH
    from piste.world.scene import Scene

    w, h = args.size
    config = pyglet.gl.Config(major_version=3, minor_version=3, forward_compatible=True, depth_size=24,
                              double_buffer=True)
    try:
        window = pyglet.window.Window(w, h, caption="bench_view", config=config, vsync=False)
        ctx = moderngl.create_context()
    except Exception as exc:  # noqa: BLE001 - no usable display / GL: reported, not a crash
        return _skip(f"no window: {type(exc).__name__}: {' '.join(str(exc).split())}")
    print(f"GL: {ctx.info['GL_RENDERER']}, {w}x{h}, {frames} frames per configuration, interleaved")
    scene = Scene.default(0)
    net, line = scene.net, scene.line
    opts = ViewOptions()
    overlay = OverlayPass(ctx)
    hist = StatsHistory(120)
    cams = [track_camera(line, f, aspect=w / h) for f in np.linspace(0.1, 0.9, frames + 2)]

    def window_frame(view, cam, t):
        window.dispatch_events()
        t0 = time.perf_counter()
        vf = view.draw(cam, t, opts)
        if not args.no_overlay:
            overlay.draw((w, h))
        window.flip()
        ms = (time.perf_counter() - t0) * 1e3
        hist.add(vf.terrain, ms, vf.extra)
        return ms

    results = {}
    # ---- terrain alone
    tv = TerrainView(TerrainRenderer(net, size=(w, h), ctx=ctx, track=line, track_half_width=TRACK_HALF_WIDTH))
    tv.attach(ctx)
    off = TerrainRenderer(net, size=(w, h), ctx=ctx, track=line, track_half_width=TRACK_HALF_WIDTH)
    win_ms, off_ms = [], []
    def offscreen(fn):
        t0 = time.perf_counter()
        fn()
        return (time.perf_counter() - t0) * 1e3

    for i, cam in enumerate(cams):
        if i % 2 == 0:  # the order alternates
            a = window_frame(tv, cam, 0.0)
            b = offscreen(lambda cam=cam: off.render(cam))  # bench_frame.py's frame: draw + glFinish + read-back
        else:
            b = offscreen(lambda cam=cam: off.render(cam))
            a = window_frame(tv, cam, 0.0)
        overlay.update(overlay_image(hist, "bench"))
        if i >= 2:  # warm-up
            win_ms.append(a)
            off_ms.append(b)
    results["terrain only"] = (win_ms, off_ms)
    tv.release()
    off.release()
    # ---- the completed scene, chasing rider 0 (t = i / 30 s)
    sv = SceneView(SceneRenderer(scene, size=(w, h), ctx=ctx))
    sv.attach(ctx)
    so = SceneRenderer(scene, size=(w, h), ctx=ctx)
    opts.follow = 0
    win_ms, off_ms = [], []
    for i in range(frames + 2):
        t = i / 30.0
        if i % 2 == 0:
            a = window_frame(sv, None, t)
            b = offscreen(lambda t=t: so.render(t))
        else:
            b = offscreen(lambda t=t: so.render(t))
            a = window_frame(sv, None, t)
        if i >= 2:
            win_ms.append(a)
            off_ms.append(b)
    results["full scene"] = (win_ms, off_ms)
    sv.release()
    so.release()
    overlay.release()
    window.close()

    print()
    print(f"{'configuration':16s} {'window ms (median [min-max])':>32s} {'fps':>6s} {'off-screen ms':>28s} {'fps':>6s} "
          f"{'window/off-screen':>18s}")
    for name, (wm, om) in results.items():
        a, b = _stats(wm), _stats(om)
        print(f"{name:16s} {a[0]:12.1f} [{a[1]:6.1f}-{a[2]:6.1f}] {1e3 / a[0]:6.1f} {b[0]:12.1f} [{b[1]:6.1f}-{b[2]:6.1f}] "
              f"{1e3 / b[0]:6.1f} {a[0] / b[0]:17.2f}x")
        record("view", f"window vs off-screen, {name}, {w}x{h}, {ctx.info['GL_RENDERER'][:24]}", "<= 1.10x",
               f"{a[0]:.1f} ms", f"off-screen {b[0]:.1f} ms", f"{a[0] / b[0]:.2f}x", a[0] / b[0] <= 1.10)
    print("(window: draw straight into the window's framebuffer + overlay + swap; off-screen: draw + glFinish + "
          "read-back, as bench_frame.py measures)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
