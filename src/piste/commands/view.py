"""``piste view``: fly over the default course in a window; the LOD follows the camera live.

Without a display it says so and renders one frame off-screen instead (``--out``).
"""

from __future__ import annotations


def add_arguments(parser) -> None:
    from piste.commands.demo import _positive, _size

    parser.add_argument("--size", nargs=2, type=_size, default=(960, 672), metavar=("W", "H"),
                        help="window size (default: 960 672)")
    parser.add_argument("--seed", type=int, default=0, help="course seed (default: 0)")
    parser.add_argument("--start", type=float, default=0.1, help="start along the track, 0..1 (default: 0.1)")
    parser.add_argument("--lightmap", choices=("modulate", "ps2"), default="modulate", help="light-map mode (M toggles)")
    parser.add_argument("--lighting", choices=("baked", "placeholder", "none"), default="baked",
                        help="light-map atlas (see `piste demo --help`)")
    parser.add_argument("--debug", choices=("lod",), help="start in the LOD view (L toggles)")
    parser.add_argument("--frames", type=_positive, help="quit after N frames (for scripted runs)")
    parser.add_argument("--out", default="out/view.png",
                        help="screenshot on quit with --frames, or the headless fallback's image (default: out/view.png)")


def run(args) -> int:
    import sys

    from piste.render.window import has_display, run_window
    from piste.world.camera import track_camera
    from piste.world.course import TRACK_HALF_WIDTH, default_course, track_centerline

    from piste.commands.demo import lightmap_for

    net = default_course(args.seed)
    line = track_centerline(args.seed)
    net, atlas, _ = lightmap_for(net, args.lighting)
    w, h = args.size
    cam = track_camera(line, args.start, aspect=w / h)
    if not has_display():
        from piste.render import TerrainRenderer, save_png

        print("piste view: no display (DISPLAY / WAYLAND_DISPLAY unset), so no window; rendering one frame "
              f"off-screen to {args.out} instead (run under a desktop or `xvfb-run piste view`)", file=sys.stderr)
        r = TerrainRenderer(net, size=(w, h), lightmap=atlas, track=line, track_half_width=TRACK_HALF_WIDTH)
        try:
            frame = r.render(cam, lightmap_mode=args.lightmap, debug=args.debug)
        finally:
            r.release()
        print(f"wrote {save_png(args.out, frame.image[..., :3])}")
        return 0
    print("piste view: W/S/A/D fly, Q/E down/up, Shift fast, arrows or mouse drag look, "
          "L LOD view, M light-map mode, O LOD on/off, P screenshot, Esc quit", file=sys.stderr)
    n = run_window(net, cam, size=(w, h), lightmap=atlas, track=line, track_half_width=TRACK_HALF_WIDTH, lightmap_mode=args.lightmap,
                   debug=args.debug, frames=args.frames, screenshot=args.out if args.frames else None)
    print(f"{n} frames" + (f"; wrote {args.out}" if args.frames else ""))
    return 0


# --- the live scene preview (issue 7, piste.pipeline.live): `piste view SCENE [--headless --out DIR]`
# rebuilds a scene (.toml) when its files change and reloads it; without SCENE, the course fly-over above.
_add_course_arguments, _run_course = add_arguments, run


def add_arguments(parser) -> None:  # noqa: F811
    _add_course_arguments(parser)
    from piste.pipeline.live import add_scene_arguments

    add_scene_arguments(parser)


def run(args) -> int:  # noqa: F811
    if getattr(args, "scene", None):
        from piste.pipeline.live import run_view

        return run_view(args)
    return _run_course(args)
