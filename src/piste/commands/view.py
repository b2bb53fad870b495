"""``piste view``: the fast in-game preview of the completed scene in a window.

Without SCENE: the default course with its six riders, objects, projected shadows, specular, the
light map and the sky (``--terrain-only`` for the terrain alone); the camera flies free from
``--start`` along the track, or chases a rider (``--follow N``; F toggles).  With SCENE (a
``.toml`` or ``.piste``): the scene's bundle, rebuilt and reloaded when its files change (see
:mod:`piste.pipeline.live`).  Keys: see :data:`piste.render.window.HELP`.

Scripted runs: ``--frames N`` / ``--exit-after S`` quit by themselves, ``--state FILE`` writes the
camera, frames and riders drawn as JSON on exit, ``--benchmark N`` renders N frames along a fixed
path (the track for ``--terrain-only``, chasing rider 0 otherwise) and prints fps.

Without a display it says so and renders one frame off-screen instead (``--out``).
"""

from __future__ import annotations

import sys


def add_arguments(parser) -> None:
    from piste.commands.demo import _positive, _size
    from piste.pipeline.live import add_scene_arguments

    parser.add_argument("--size", nargs=2, type=_size, default=(960, 672), metavar=("W", "H"),
                        help="window size (default: 960 672)")
    parser.add_argument("--seed", type=int, default=0, help="course seed (default: 0)")
    parser.add_argument("--start", type=float, default=0.1, help="start along the track, 0..1 (default: 0.1)")
    parser.add_argument("--lightmap", choices=("modulate", "ps2"), default="modulate", help="light-map mode (M toggles)")
    parser.add_argument("--lighting", choices=("baked", "placeholder", "none"), default="baked",
                        help="light-map atlas (see `piste demo --help`)")
    parser.add_argument("--debug", choices=("lod",), help="start in the LOD view (L toggles)")
    parser.add_argument("--terrain-only", action="store_true", help="the terrain alone (no riders, objects, shadows)")
    parser.add_argument("--rider-model", action="append", default=[], metavar="FILE[:N]",
                        help="add N riders (default 2) of a skinned, animated glTF model to the default course "
                             "(repeatable: any number of different rider models)")
    parser.add_argument("--face", choices=("morph", "null_bones", "off"), default="morph",
                        help="riders' faces: morph targets, their null-bone fit, or the neutral face (default: morph)")
    parser.add_argument("--follow", type=int, metavar="N", help="start chasing rider N (F toggles, N next rider)")
    parser.add_argument("--no-overlay", action="store_true", help="start without the statistics overlay (H toggles)")
    parser.add_argument("--frames", type=_positive, help="quit after N frames (for scripted runs)")
    parser.add_argument("--exit-after", type=float, metavar="S", help="quit after S seconds (for scripted runs)")
    parser.add_argument("--state", metavar="FILE", help="write the camera, frames and riders drawn as JSON on exit")
    parser.add_argument("--benchmark", type=_positive, metavar="N",
                        help="render N frames along a fixed path without input and print fps (needs a display)")
    parser.add_argument("--out", default="out/view.png",
                        help="screenshot on quit with --frames, or the headless fallback's image (default: out/view.png)")
    add_scene_arguments(parser)


def _course_view_factory(args, net, line, atlas):
    """``ctx -> view`` for the default course (terrain only or the whole scene)."""
    from piste.render.window import SceneView, TerrainView
    from piste.world.course import TRACK_HALF_WIDTH

    def make(ctx):
        if args.terrain_only:
            from piste.render.frame import TerrainRenderer

            return TerrainView(TerrainRenderer(net, size=tuple(args.size), ctx=ctx, lightmap=atlas, track=line,
                                               track_half_width=TRACK_HALF_WIDTH))
        return SceneView(_scene_renderer(args, net, line, atlas, ctx))

    return make


def _scene_renderer(args, net, line, atlas, ctx=None):
    import numpy as np

    from piste.lighting.lights import default_lights
    from piste.pipeline.preview import rider_casts
    from piste.render.scene_renderer import SceneRenderer
    from piste.world.course import TRACK_HALF_WIDTH
    from piste.world.objects import place_objects
    from piste.world.scene import Scene

    lights = default_lights()
    objs = place_objects(net, line, lights, seed=args.seed, track_half_width=TRACK_HALF_WIDTH)
    length = float(np.linalg.norm(np.diff(line[:, :2], axis=0), axis=1).sum())
    start = min(max(float(args.start), 0.0) * length, max(length - 120.0, 0.0))
    scene = Scene(net, line, lights, objects=objs, start=start)
    casts = [Scene(net, line, lights, model=m, pack=pack, start=start) for m, pack in rider_casts(args.rider_model)]
    face = getattr(args, "face", "morph")
    return SceneRenderer(scene, size=tuple(args.size), ctx=ctx, lightmap=atlas, casts=casts,
                         face=None if face == "off" else face)


def run(args) -> int:
    if str(getattr(args, "scene", None) or "").lower().endswith(".pbd"):  # an SSX Tricky level
        from piste.commands.ssx import view_pbd

        args.level = args.scene
        return view_pbd(args)
    if str(getattr(args, "scene", None) or "").rstrip("/").endswith(".tiles"):  # a tiled world: streamed
        from piste.render.streaming import view_tiles

        return view_tiles(args)
    if getattr(args, "scene", None):
        from piste.pipeline.live import run_view

        return run_view(args)
    from piste.commands.demo import lightmap_for
    from piste.render.window import HELP, ViewOptions, has_display, print_benchmark, run_window
    from piste.world.camera import track_camera
    from piste.world.course import default_course, track_centerline

    net = default_course(args.seed)
    line = track_centerline(args.seed)
    net, atlas, _ = lightmap_for(net, args.lighting)
    w, h = args.size
    cam = track_camera(line, args.start, aspect=w / h)
    if not has_display():
        from piste.render import TerrainRenderer, save_png
        from piste.world.course import TRACK_HALF_WIDTH

        print("piste view: no display (DISPLAY / WAYLAND_DISPLAY unset), so no window; rendering one frame "
              f"off-screen to {args.out} instead (run under a desktop or `xvfb-run piste view`)", file=sys.stderr)
        if args.terrain_only:
            r = TerrainRenderer(net, size=(w, h), lightmap=atlas, track=line, track_half_width=TRACK_HALF_WIDTH)
            try:
                image = r.render(cam, lightmap_mode=args.lightmap, debug=args.debug).image
            finally:
                r.release()
        else:
            r = _scene_renderer(args, net, line, atlas)
            try:
                image = r.render(0.0, camera=None if args.follow is not None else cam, lightmap_mode=args.lightmap,
                                 debug=args.debug).image
            finally:
                r.release()
        print(f"wrote {save_png(args.out, image[..., :3])}")
        return 0
    opts = ViewOptions(lightmap_mode=args.lightmap, debug=args.debug, follow=args.follow,
                       overlay=not args.no_overlay)
    make = _course_view_factory(args, net, line, atlas)
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
