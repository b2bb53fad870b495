"""``piste view``: the fast in-game preview of the completed scene in a window.

Without SCENE: the built-in default scene (:mod:`piste.pipeline.default_scene`, built once and
cached, the one ``piste demo`` draws) through the runtime
(:class:`piste.pipeline.preview.ScenePreview` drawing into the window,
:class:`piste.pipeline.live.PreviewView`): the default course with its six riders, objects,
projected shadows, specular, the light map and the sky (``--terrain-only`` for the terrain alone); the camera flies free from
``--start`` along the track, or chases a rider (``--follow N``; F toggles).  With SCENE (a
``.toml`` or ``.piste``): the scene's bundle, rebuilt and reloaded when its files change (see
:mod:`piste.pipeline.live`).  An SSX level (``.pbd``) or a tiled world (``.tiles``) is opened by
:func:`piste.pipeline.open_scene.open_source` and drawn by the same runtime (``--riders N`` stands
default riders on it).  Keys: see :data:`piste.render.window.HELP`.  This module only parses.

Scripted runs: ``--frames N`` / ``--exit-after S`` quit by themselves, ``--state FILE`` writes the
camera, frames and riders drawn as JSON on exit, ``--benchmark N`` renders N frames along a fixed
path (the track for ``--terrain-only``, chasing rider 0 otherwise) and prints fps.

Without a display it says so and renders one frame off-screen instead (``--out``).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import argparse

    import moderngl

    from piste.pipeline.bundle_objects import Bundle
    from piste.pipeline.live import LiveScene, LiveView, PreviewView
    from piste.pipeline.preview import ScenePreview
    from piste.world.camera import Camera


def print_benchmark(st: dict, what: str, size: Sequence[int]) -> float:
    """Print the fps of a ``run_window(benchmark=N)`` state (``st["frame_ms"]``: the frame times in
    ms); returns the median fps."""
    import numpy as np

    ms = np.asarray(st["frame_ms"], dtype=np.float64)
    med = float(np.median(ms))
    print(f"piste view --benchmark {len(ms)} ({what}, {size[0]}x{size[1]}, window, swap included): "
          f"median {med:.1f} ms = {1e3 / med:.1f} fps (frames {ms.min():.1f}..{ms.max():.1f} ms; "
          f"mean {1e3 / ms.mean():.1f} fps)")
    return 1e3 / med


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from piste.commands import _numbers as N

    parser.add_argument("--size", nargs=2, type=N.SIZE, default=(960, 672), metavar=("W", "H"),
                        help="window size (default: 960 672)")
    parser.add_argument("--seed", type=N.SEED, default=0, help="course seed (default: 0)")
    parser.add_argument("--start", type=N.FRACTION, default=0.1, help="start along the track, 0..1 (default: 0.1)")
    parser.add_argument("--lightmap", choices=("modulate", "ps2"), default="modulate", help="light-map mode (M toggles)")
    parser.add_argument("--lighting", choices=("baked", "placeholder", "none"), default="baked",
                        help="light-map atlas (see `piste demo --help`)")
    parser.add_argument("--debug", choices=("lod",), help="start in the LOD view (L toggles)")
    parser.add_argument("--terrain-only", action="store_true", help="the terrain alone (no riders, objects, shadows)")
    parser.add_argument("--rider-model", action="append", default=[], metavar="FILE[:N]",
                        help="add N riders (default 2) of a skinned, animated glTF model to the default course "
                             "(repeatable: any number of different rider models)")
    parser.add_argument("--face", choices=("morph", "null_bones", "off"),
                        help="riders' faces: morph targets, their null-bone fit, or the neutral face (default: the "
                             "scene file's [render] face, else morph)")
    parser.add_argument("--follow", type=N.integer(0, 10_000), metavar="N",
                        help="start chasing rider N (F toggles, N next rider)")
    parser.add_argument("--no-overlay", action="store_true", help="start without the statistics overlay (H toggles)")
    parser.add_argument("--frames", type=N.FRAMES, help="quit after N frames (for scripted runs)")
    parser.add_argument("--exit-after", type=N.SECONDS, metavar="S", help="quit after S seconds (for scripted runs)")
    parser.add_argument("--state", metavar="FILE", help="write the camera, frames and riders drawn as JSON on exit")
    parser.add_argument("--benchmark", type=N.FRAMES, metavar="N",
                        help="render N frames along a fixed path without input and print fps (needs a display)")
    parser.add_argument("--out", default="out/view.png",
                        help="screenshot on quit with --frames, or the headless fallback's image (default: out/view.png)")
    parser.add_argument("scene", nargs="?", help="a scene (.toml) or bundle (.piste) to preview live (rebuilt and "
                                                 "reloaded when its files change), an SSX level (.pbd) or a tiled "
                                                 "world (.tiles)")
    parser.add_argument("--headless", action="store_true",
                        help="with SCENE: no window; render a frame to --out (a folder) at start and per change")
    parser.add_argument("--camera", help="with SCENE: the scene camera (default: the first)")
    parser.add_argument("--watch-seconds", type=N.SECONDS, help="with SCENE: stop watching after this many seconds")
    parser.add_argument("--eye", nargs=3, type=N.COORDINATE, metavar=("X", "Y", "Z"),
                        help="with an SSX level or a tiled world: start at this position in metres (with --target)")
    parser.add_argument("--target", nargs=3, type=N.COORDINATE, metavar=("X", "Y", "Z"),
                        help="the point --eye looks at (metres)")
    parser.add_argument("--riders", type=N.integer(0, 64), default=0, metavar="N",
                        help="with an SSX level or a tiled world: stand N default riders on its terrain (with "
                             "--track: the pack riding the track has N riders, 1..64, default 6)")
    parser.add_argument("--add-objects", type=N.integer(0, 10_000), default=0, metavar="N",
                        help="place N of the course's objects (trees, rocks, signs, rails) on the terrain of a source "
                             "without objects of its own (an SSX level, a tiled world)")
    parser.add_argument("--budget", type=N.real(1.0, float(1 << 20)), default=256.0,
                        help="tiled worlds: streaming memory budget in MiB")
    parser.add_argument("--track", nargs=4, type=N.COORDINATE, metavar=("X0", "Y0", "X1", "Y1"),
                        help="tiled worlds: a pack of riders (six, or --riders N) rides a straight track from "
                             "(X0, Y0) to (X1, Y1) metres across the tiles (F: chase rider 0)")


def course_preview(args: argparse.Namespace, bundle: Bundle, ctx: moderngl.Context | None = None) -> ScenePreview:
    """The runtime (:class:`piste.pipeline.preview.ScenePreview`) of the built default scene
    ``bundle`` with the view's flags: the terrain alone or the whole scene, the pack from
    ``--start``, ``--rider-model`` casts, ``--lighting``, ``--face``."""
    import numpy as np

    from piste.pipeline.preview import PACK_TRACK_AHEAD, ScenePreview, rider_casts

    lightmap = {"baked": "bundle", "placeholder": "placeholder", "none": None}[args.lighting]
    line = bundle.centerline
    length = float(np.linalg.norm(np.diff(line[:, :2], axis=0), axis=1).sum())
    start = min(max(float(args.start), 0.0), max(length - PACK_TRACK_AHEAD, 0.0) / length)  # the pack: 120 m ahead
    return ScenePreview(bundle, size=tuple(args.size), ctx=ctx, lightmap=lightmap, object_lighting="dynamic",
                        lightmap_mode=args.lightmap, terrain_only=args.terrain_only, start=start,
                        casts=rider_casts(args.rider_model), face=args.face, lod_morph=_morph(args),
                        aa=getattr(args, "aa", None), trace=getattr(args, "trace", None), dof=getattr(args, "dof", None),
                        **_quality(args))


def _morph(args: argparse.Namespace) -> bool | None:
    return None if getattr(args, "lod_morph", None) is None else args.lod_morph == "on"


def _quality(args: argparse.Namespace) -> dict[str, Any]:
    """``--soft-shadows`` and ``--occlusion on|off`` as the runtime's ``soft_shadows`` / ``occlusion``
    (None: the scene file's ``[render]`` keys)."""
    occ = getattr(args, "occlusion", None)
    return {"soft_shadows": getattr(args, "soft_shadows", None), "occlusion": None if occ is None else occ == "on"}


def _view_scene(args: argparse.Namespace) -> int:
    """``piste view SCENE``: a scene file or bundle, previewed live (:mod:`piste.pipeline.live`)."""
    from pathlib import Path

    from piste.pipeline.live import LiveScene, run_headless, run_window
    from piste.pipeline.preview import camera_at
    from piste.render.window import HELP, ViewOptions, has_display

    size = tuple(args.size) if getattr(args, "size", None) else None
    kw = {"face": args.face, "lod_morph": _morph(args), "aa": getattr(args, "aa", None), "dof": getattr(args, "dof", None),
          "trace": getattr(args, "trace", None), **_quality(args)}
    if args.headless or not has_display():
        live = LiveScene(args.scene, size=size, camera=args.camera, **kw)
        try:
            out = Path(args.out)
            if out.suffix.lower() == ".png":  # view's own default is a PNG path: use a folder beside it
                out = out.with_suffix("")
            if not args.headless:
                print("piste view: no display, so previewing headless into " + str(out), file=sys.stderr)
            files = run_headless(live, out, frames=args.frames, seconds=args.watch_seconds)
            print(f"{len(files)} frame(s) in {out}")
            return 0
        finally:
            live.release()
    path = Path(args.scene)

    def factory(ctx: moderngl.Context) -> LiveScene:
        return LiveScene(path, size=size, camera=args.camera, ctx=ctx, **kw)

    def start_camera(view: LiveView) -> Camera:
        return camera_at(view.live.bundle, args.camera)

    size = size or (640, 448)
    opts = ViewOptions(lightmap_mode=args.lightmap, debug=args.debug, follow=args.follow,
                       overlay=not args.no_overlay)
    seconds = args.exit_after if args.exit_after is not None else args.watch_seconds
    if args.benchmark:
        st = run_window(factory, start_camera, size=size, opts=opts, benchmark=args.benchmark)
        print_benchmark(st, f"{path.name}, " + ("chasing rider 0" if st.get("follow_used") else "scene camera"), size)
        return 0
    print(f"piste view: {HELP}", file=sys.stderr)
    st = run_window(factory, start_camera, size=size, caption=f"piste view {path.name}", opts=opts, frames=args.frames,
                    exit_after=seconds, screenshot=args.out if (args.frames or seconds) else None, state=args.state)
    print(f"{st['frames']} frames")
    return 0


def _view_source(args: argparse.Namespace, kind: str) -> int:
    """``piste view LEVEL.pbd`` or ``WORLD.tiles`` (a source that is not watched): opened by
    :func:`piste.pipeline.open_scene.open_source` and drawn by the runtime in the window (or one
    frame off-screen to ``--out`` without a display).  A tiled world starts at its flight
    (``--benchmark``: along it at 100 m/s); in the window its tiles load while far stand-ins show."""
    from piste.pipeline.live import PreviewView
    from piste.pipeline.open_scene import eye_camera, open_source
    from piste.pipeline.preview import ScenePreview, camera_at
    from piste.render import save_png
    from piste.render.window import ViewOptions, has_display, run_window

    track = getattr(args, "track", None)
    if track is not None and kind != "tiles":
        from piste.errors import ConfigError

        raise ConfigError(f"--track needs a tiled world (.tiles), got a {kind}")
    bundle = open_source(args.scene, warm=True, riders=args.riders, objects=args.add_objects, budget_mb=args.budget,
                         track=track)
    size = tuple(args.size)
    kw = {"lightmap_mode": args.lightmap, "face": args.face, "lod_morph": _morph(args), "aa": getattr(args, "aa", None),
          "dof": getattr(args, "dof", None),
          "trace": getattr(args, "trace", None), **_quality(args)}
    cam = eye_camera(args.eye, args.target) or camera_at(bundle, args.camera)
    if not has_display():
        print("piste view: no display (DISPLAY / WAYLAND_DISPLAY unset), so no window; rendering one frame "
              f"off-screen to {args.out} instead (run under a desktop or `xvfb-run piste view`)", file=sys.stderr)
        p = ScenePreview(bundle, size=size, **kw)
        try:  # (riders on a --track: the chase camera, unless --eye/--camera)
            chase = track is not None and args.eye is None and not args.camera
            image = p.render(None if chase else cam, 0.0, debug=args.debug)
        finally:
            p.release()
        print(f"wrote {save_png(args.out, image)}")
        return 0
    opts = ViewOptions(lightmap_mode=args.lightmap, debug=args.debug, follow=args.follow, overlay=not args.no_overlay)

    def make(ctx: moderngl.Context) -> PreviewView:
        return PreviewView(ScenePreview(bundle, size=size, ctx=ctx, stream_wait=False, **kw))

    if args.benchmark:
        path = None
        if kind == "tiles":
            from piste.pipeline.tiles_source import flight_cameras

            flight = flight_cameras(bundle, args.benchmark + 5)
            path = lambda i: flight[min(max(i - 5, 0), len(flight) - 1)]  # noqa: E731
        st = run_window(make, cam, size=size, opts=opts, benchmark=args.benchmark, benchmark_camera=path)
        print_benchmark(st, f"{bundle.name}" + (", flying at 100 m/s" if kind == "tiles" else ""), size)
        return 0
    st = run_window(make, cam, size=size,
                    caption=f"piste view {bundle.name}", opts=opts, frames=args.frames, exit_after=args.exit_after,
                    screenshot=args.out if (args.frames or args.exit_after) else None, state=args.state)
    print(f"{st['frames']} frames")
    return 0


def run(args: argparse.Namespace) -> int:
    if args.scene:
        from piste.pipeline.open_scene import source_kind

        kind = source_kind(args.scene)
        if kind in ("scene", "bundle"):  # watched and rebuilt live
            return _view_scene(args)
        return _view_source(args, kind)
    from piste.extras import require
    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.default_scene import build_default_scene
    from piste.pipeline.live import PreviewView
    from piste.render.window import HELP, ViewOptions, has_display, run_window
    from piste.world.camera import track_camera

    require("moderngl", "piste view")
    # the default course is the built default scene (cached; the one `piste demo` draws) + the runtime
    result = build_default_scene(args.seed, progress=sys.stderr.isatty())
    bundle = load_bundle(result.path, verify=False, warm=True)  # just written or verified by the build's cache
    line = bundle.centerline
    w, h = args.size
    cam = track_camera(line, args.start, aspect=w / h)
    if not has_display():
        from piste.render import save_png

        print("piste view: no display (DISPLAY / WAYLAND_DISPLAY unset), so no window; rendering one frame "
              f"off-screen to {args.out} instead (run under a desktop or `xvfb-run piste view`)", file=sys.stderr)
        p = course_preview(args, bundle)
        try:
            if p.scene is not None and args.follow is not None:
                p.scene.follow = int(args.follow) % len(p.scene.riders)
            image = p.render(None if (p.follow and args.follow is not None) else cam, 0.0, debug=args.debug)
        finally:
            p.release()
        print(f"wrote {save_png(args.out, image)}")
        return 0
    opts = ViewOptions(lightmap_mode=args.lightmap, debug=args.debug, follow=args.follow,
                       overlay=not args.no_overlay)

    def make(ctx: moderngl.Context) -> PreviewView:
        return PreviewView(course_preview(args, bundle, ctx))
    if args.benchmark:
        cams = None
        if args.terrain_only:
            import numpy as np

            path = [track_camera(line, f, aspect=w / h) for f in np.linspace(0.1, 0.9, args.benchmark + 5)]
            cams = lambda i: path[i]  # noqa: E731
        st = run_window(make, cam, size=(w, h), opts=opts, benchmark=args.benchmark, benchmark_camera=cams)
        print_benchmark(st, "terrain only" if args.terrain_only else "full scene, chasing rider 0", (w, h))
        return 0
    print(f"piste view: {HELP}", file=sys.stderr)
    st = run_window(make, cam, size=(w, h), opts=opts, frames=args.frames, exit_after=args.exit_after,
                    screenshot=args.out if (args.frames or args.exit_after) else None, state=args.state)
    print(f"{st['frames']} frames" + (f"; wrote {args.out}" if (args.frames or args.exit_after) else ""))
    return 0
