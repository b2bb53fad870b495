"""``piste demo``: render the default course from a camera flying down the track.

Writes ``out/demo.png`` (the first frame); with ``--frames N --video out/demo.mp4`` also an MP4 of
the flight.  Prints the talk's statistics table over the frames shown and the frame times.

The demo is ``piste build`` of the built-in default scene (:mod:`piste.pipeline.default_scene`:
the course of ``--seed``, its lights and baked light map, the six riders following the track and
the objects placed along it; built once into the piste cache folder, then loaded) followed by the runtime that ``piste render`` uses
(:class:`piste.pipeline.preview.ScenePreview`): one place where a frame is made.
"""

from __future__ import annotations

import contextlib

from piste.commands import _numbers as N

#: argparse types (kept under these names for the commands that import them from here)
_size = N.SIZE
_positive = N.FRAMES


def add_arguments(parser) -> None:
    parser.add_argument("--size", nargs=2, type=_size, default=(640, 448), metavar=("W", "H"),
                        help="image size in pixels (default: 640 448, the PS2's)")
    parser.add_argument("--out", default="out/demo.png", help="PNG of the first frame (default: out/demo.png)")
    parser.add_argument("--frames", type=_positive, default=1, help="frames to render along the track (default: 1)")
    parser.add_argument("--video", metavar="MP4", help="also write the frames as an H.264 MP4 (e.g. out/demo.mp4)")
    parser.add_argument("--fps", type=N.FPS, default=30, help="video frame rate (default: 30)")
    parser.add_argument("--start", type=N.FRACTION, default=0.12, help="camera start along the track, 0..1 (default: 0.12)")
    parser.add_argument("--end", type=N.FRACTION, default=0.45, help="camera end along the track, 0..1 (default: 0.45)")
    parser.add_argument("--lod", choices=("on", "off"), default="on",
                        help="per-edge LOD (off: every patch 8x8, for comparison)")
    parser.add_argument("--lightmap", choices=("modulate", "ps2"), default="modulate",
                        help="light-map mode: one pass Cd x CL, or the PS2's two-pass (Cd - Cs) x As blend")
    parser.add_argument("--lighting", choices=("baked", "placeholder", "none"), default="baked",
                        help="light-map atlas: baked with terrain shadows (piste.lighting; baked once, ~2 s, then "
                             "cached in $PISTE_CACHE_DIR or ~/.cache/piste), a placeholder lit from the normals "
                             "without shadows, or none")
    parser.add_argument("--debug", choices=("lod", "wire", "base", "lightmap"),
                        help="debug view: lod = patches coloured by tessellation (4x4 green, 6x6 yellow, 8x8 red, "
                             "glue blue) with wireframe; wire = wireframe over the lit terrain; base / lightmap = one texture")
    parser.add_argument("--seed", type=N.SEED, default=0, help="course seed (default: 0)")
    parser.add_argument("--fov", type=N.FOV, default=60.0, help="vertical field of view in degrees (default: 60)")
    parser.add_argument("--height", type=N.real(0.0, 100_000.0, lo_open=True), default=12.0,
                        help="camera height above the track in metres (default: 12)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--scene", choices=("full", "terrain"), default="full",
                        help="full: the completed scene (six riders chased by the camera, objects, projected shadows, "
                             "specular; real-time frames at --fps from --start; see piste.commands.demo_scene); "
                             "terrain: the terrain fly-over only (default: full; debug views imply terrain)")
    parser.add_argument("--objects", choices=("dynamic", "baked", "points"), default="dynamic",
                        help="object lighting (full scene): 1 ambient + 3 directional per object (SSX), "
                             "pre-calculated RGBs, or dynamic point and spot lights")
    parser.add_argument("--object-lod", type=N.real(0.0, 1000.0), default=None, metavar="PX",
                        help="full scene: objects' levels of detail, the simplification error an object may show "
                             "in pixels (0: full meshes; default: the scene's render.object_lod, 0.5)")
    parser.add_argument("--no-shadows", action="store_true", help="full scene without projected rider shadows")
    parser.add_argument("--no-specular", action="store_true", help="full scene without the riders' specular pass")
    parser.add_argument("--rider-model", action="append", default=[], metavar="FILE[:N]",
                        help="full scene: add N riders (default 2) of a skinned, animated glTF model to the pack "
                             "(repeatable: any number of different rider models)")


def lightmap_for(net, lighting: str):
    """The atlas for ``--lighting``: returns ``(net, atlas or "placeholder" or None, what was used)``."""
    if lighting == "none":
        return net, None, "none"
    if lighting == "placeholder":
        return net, "placeholder", "placeholder"
    import sys

    from piste.lighting.baker import load_or_bake_default_lightmap

    try:
        lm = load_or_bake_default_lightmap(net)
    except Exception as exc:  # the demo must still render: say so and fall back
        print(f"warning: no baked light map ({type(exc).__name__}: {exc}); using the placeholder lighting",
              file=sys.stderr)
        return net, "placeholder", "placeholder (bake failed)"
    return lm.apply(net), lm.atlas, "baked"


def demo_bundle(args):
    """The built (cached) default scene of ``args.seed`` and what ``--lighting`` draws with it:
    ``(bundle, lightmap for ScenePreview, lighting as printed)``."""
    import sys

    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.default_scene import build_default_scene

    result = build_default_scene(args.seed, progress=not args.no_progress and sys.stderr.isatty())
    bundle = load_bundle(result.path, verify=False, warm=True)  # just written or verified by the build's cache
    lightmap = {"baked": "bundle", "placeholder": "placeholder", "none": None}[args.lighting]
    return bundle, lightmap, args.lighting


def run(args) -> int:
    import sys
    import time

    import numpy as np

    from piste.errors import ConfigError
    from piste.extras import require
    from piste.pipeline.preview import ScenePreview
    from piste.render import summarize
    from piste.render.context import save_png
    from piste.render.video import VideoWriter
    from piste.terrain import format_stats
    from piste.world.camera import track_camera

    w, h = args.size
    if args.video and (w % 2 or h % 2):
        raise ConfigError(f"--size {w} {h}: H.264 video needs an even width and height")
    if not (0.0 <= args.start <= 1.0 and 0.0 <= args.end <= 1.0):
        raise ConfigError(f"--start/--end must be fractions of the track in [0, 1], got {args.start}, {args.end}")
    require("moderngl", "piste demo")  # before building: say at once that OpenGL is missing
    t0 = time.perf_counter()
    bundle, lightmap, lighting = demo_bundle(args)
    net, line = bundle.net, bundle.centerline
    if args.scene == "full" and args.debug is None:
        from piste.commands.demo_scene import run_scene

        return run_scene(args, bundle, lightmap, lighting, t0)
    preview = ScenePreview(bundle, size=(w, h), lightmap=lightmap, lightmap_mode=args.lightmap, terrain_only=True)
    lod_on = args.lod == "on"
    # warm-up (not timed): compiled kernels, the terrain's resident vertex blocks, shaders, GL buffers
    from piste._jit import warm_up
    from piste.terrain.resident import resident_fits, resident_terrain

    warm_up()
    if resident_fits(net):
        resident_terrain(net)
    for _ in range(3):
        preview.render(track_camera(line, args.start, height=args.height, fov_y=args.fov), lod=lod_on,
                       debug=args.debug, read=False)
    setup_s = time.perf_counter() - t0
    ts = np.linspace(args.start, args.end, args.frames) if args.frames > 1 else np.array([args.start])
    frames = []
    try:
        from tqdm import tqdm

        with VideoWriter(args.video, fps=args.fps) if args.video else contextlib.nullcontext() as video:
            bar = tqdm(ts, desc="rendering", unit="frame", disable=args.no_progress or args.frames < 2,
                       file=sys.stderr)
            for i, t in enumerate(bar):
                cam = track_camera(line, float(t), height=args.height, fov_y=args.fov)
                image = preview.render(cam, lod=lod_on, debug=args.debug)
                if i == 0:
                    out = save_png(args.out, image)
                if video is not None:
                    video.append(image)
                frame = preview.frame
                frame.image = None  # keep memory flat over long flights
                frames.append(frame)
        timed = list(frames)
        while len(timed) < 5:  # time at least five frames (medians below); the extra ones are not written
            preview.render(track_camera(line, float(ts[-1]), height=args.height, fov_y=args.fov), lod=lod_on,
                           debug=args.debug)
            preview.frame.image = None
            timed.append(preview.frame)
    finally:
        preview.release()
    med = {k: float(np.median([f.timings[k] for f in timed])) for k in timed[0].timings}
    s = summarize(frames)
    lod = "on" if args.lod == "on" else "off (all 8x8)"
    title = (f"Terrain statistics: {net.name}, {len(frames)} frame(s) at {w}x{h}, LOD {lod}, "
             f"light map {args.lightmap}, lighting {lighting}" + (f", debug {args.debug}" if args.debug else ""))
    print(format_stats(s, title=title))
    print()
    print(f"frame times (median over {len(timed)} warmed-up frame(s), llvmpipe/EGL):")
    print(f"  LOD + cull + tessellation  {med['lod'] + med['cull'] + med['tessellate']:7.2f} ms"
          f"  (LOD {med['lod']:.2f}, cull {med['cull']:.2f}, tessellate / index list {med['tessellate']:.2f})")
    print(f"  upload                     {med['upload']:7.2f} ms")
    print(f"  CPU side                   {med['cpu']:7.2f} ms")
    print(f"  draw (GL + finish)         {med['draw']:7.2f} ms")
    print(f"  read back                  {med['readback']:7.2f} ms")
    print(f"  frame                      {med['total']:7.2f} ms = {1e3 / med['total']:.1f} fps")
    print(f"  (set-up, not in the frame times: course, light map, GL context, shaders: {setup_s:.2f} s)")
    print(f"wrote {out}" + (f" and {args.video} ({len(frames)} frames at {args.fps} fps)" if args.video else ""))
    return 0
