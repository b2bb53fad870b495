"""``piste view`` in a window vs the same frame off-screen (``bench_frame.py``'s way), interleaved.

One process, one GL context (the window's): each camera is drawn first into the window (render
straight into its framebuffer, overlay, swap) then off-screen into an RGBA8 target with read-back,
so load from other processes hits both alike.  Prints the median and range of each, fps and the
ratio window / off-screen, for the terrain alone and for the completed scene (riders, objects,
shadows, specular).  The issue's target: the window no more than 10 % slower.

Needs a display: ``xvfb-run -a -s "-screen 0 1024x768x24" .venv/bin/python benchmarks/bench_view.py``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def _stats(ms):
    a = np.asarray(ms, dtype=np.float64)
    return float(np.median(a)), float(a.min()), float(a.max())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="6 frames per configuration")
    ap.add_argument("--frames", type=int, default=20, help="frames per configuration (default 20)")
    ap.add_argument("--size", type=int, nargs=2, default=(640, 448))
    ap.add_argument("--no-overlay", action="store_true", help="window frames without the statistics overlay")
    args = ap.parse_args()
    frames = 6 if args.quick else args.frames

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
    window = pyglet.window.Window(w, h, caption="bench_view", config=config, vsync=False)
    ctx = moderngl.create_context()
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
    for i, cam in enumerate(cams):
        a = window_frame(tv, cam, 0.0)
        overlay.update(overlay_image(hist, "bench"))
        t0 = time.perf_counter()
        off.render(cam)  # bench_frame.py's frame: draw + glFinish + read-back
        b = (time.perf_counter() - t0) * 1e3
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
        a = window_frame(sv, None, t)
        t0 = time.perf_counter()
        so.render(t)
        b = (time.perf_counter() - t0) * 1e3
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
    print("(window: draw straight into the window's framebuffer + overlay + swap; off-screen: draw + glFinish + "
          "read-back, as bench_frame.py measures)")


if __name__ == "__main__":
    main()
