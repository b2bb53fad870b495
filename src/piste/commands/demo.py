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
from typing import TYPE_CHECKING, Any

from piste.commands import _numbers as N

if TYPE_CHECKING:
    import argparse

    from piste.lighting.lights import Lights
    from piste.pipeline.bundle_objects import Bundle
    from piste.render.interlace import FlickerMeter
    from piste.world.scene import Scene

def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--size", nargs=2, type=N.SIZE, default=(640, 448), metavar=("W", "H"),
                        help="image size in pixels (default: 640 448, the PS2's)")
    parser.add_argument("--out", default="out/demo.png", help="PNG of the first frame (default: out/demo.png)")
    parser.add_argument("--frames", type=N.FRAMES, default=1, help="frames to render along the track (default: 1)")
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
                             "cached in $PISTE_CACHE_DIR, else $XDG_CACHE_HOME/piste or ~/.cache/piste), a "
                             "placeholder lit from the normals "
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
                             "specular; real-time frames at --fps from --start; see run_scene below); "
                             "terrain: the terrain fly-over only (default: full; debug views imply terrain)")
    parser.add_argument("--objects", choices=("dynamic", "baked", "points"), default="dynamic",
                        help="object lighting (full scene): 1 ambient + 3 directional per object (SSX), "
                             "pre-calculated RGBs, or dynamic point and spot lights")
    parser.add_argument("--object-lod", type=N.real(0.0, 64.0), default=None, metavar="PX",
                        help="full scene: objects' levels of detail, the simplification error an object may show "
                             "in pixels (0: full meshes; default: the scene's render.object_lod, 1)")
    parser.add_argument("--no-shadows", action="store_true", help="full scene without projected rider shadows")
    parser.add_argument("--no-specular", action="store_true", help="full scene without the riders' specular pass")
    parser.add_argument("--rider-model", action="append", default=[], metavar="FILE[:N]",
                        help="full scene: add N riders (default 2) of a skinned, animated glTF model to the pack "
                             "(repeatable: any number of different rider models)")


def demo_bundle(args: argparse.Namespace) -> tuple[Bundle, Any, str]:
    """The built (cached) default scene of ``args.seed`` and what ``--lighting`` draws with it:
    ``(bundle, lightmap for ScenePreview, lighting as printed)``."""
    import sys

    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.default_scene import build_default_scene

    result = build_default_scene(args.seed, progress=not args.no_progress and sys.stderr.isatty())
    bundle = load_bundle(result.path, verify=False, warm=True)  # just written or verified by the build's cache
    lightmap = {"baked": "bundle", "placeholder": "placeholder", "none": None}[args.lighting]
    return bundle, lightmap, args.lighting


def run(args: argparse.Namespace) -> int:
    import sys
    import time

    import numpy as np

    from piste.errors import ConfigError
    from piste.extras import require
    from piste.pipeline.preview import ScenePreview
    from piste.render import summarize
    from piste.render.context import save_png
    from piste.render.interlace import FlickerMeter, weave
    from piste.render.video import VideoWriter
    from piste.terrain import format_stats
    from piste.world.camera import track_camera

    w, h = args.size
    if args.video and (w % 2 or h % 2):
        raise ConfigError(f"--size {w} {h}: H.264 video needs an even width and height")
    if not (0.0 <= args.start <= 1.0 and 0.0 <= args.end <= 1.0):
        raise ConfigError(f"--start/--end must be fractions of the track in [0, 1], got {args.start}, {args.end}")
    if getattr(args, "flicker_filter", False) and not getattr(args, "interlace", False):
        raise ConfigError("--flicker-filter filters the fields of interlaced video: add --interlace")
    require("moderngl", "piste demo")  # before building: say at once that OpenGL is missing
    t0 = time.perf_counter()
    bundle, lightmap, lighting = demo_bundle(args)
    net, line = bundle.net, bundle.centerline
    if args.scene == "full" and args.debug is None:
        return run_scene(args, bundle, lightmap, lighting, t0)
    preview = ScenePreview(bundle, size=(w, h), lightmap=lightmap, lightmap_mode=args.lightmap, terrain_only=True,
                           lod_morph=_morph(args), aa=getattr(args, "aa", None),
                           supersample=getattr(args, "supersample", 1), trace=getattr(args, "trace", None),
                           dof=getattr(args, "dof", None))
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
    meter = FlickerMeter()
    inter, filt = getattr(args, "interlace", False), getattr(args, "flicker_filter", False)
    try:
        from tqdm import tqdm

        with VideoWriter(args.video, fps=args.fps) if args.video else contextlib.nullcontext() as video:
            bar = tqdm(ts, desc="rendering", unit="frame", disable=args.no_progress or args.frames < 2,
                       file=sys.stderr)
            for i, t in enumerate(bar):
                cam = track_camera(line, float(t), height=args.height, fov_y=args.fov)
                image = preview.render(cam, lod=lod_on, debug=args.debug)
                if inter:  # the odd lines: a second field half a frame on along the flight
                    half = 0.5 * float(ts[1] - ts[0]) if len(ts) > 1 else 0.0
                    cam2 = track_camera(line, float(t) + half, height=args.height, fov_y=args.fov)
                    image = weave(image, preview.render(cam2, lod=lod_on, debug=args.debug), filtered=filt)
                meter.add(image)
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
    _print_flicker(args, meter)
    print(f"  (set-up, not in the frame times: course, light map, GL context, shaders: {setup_s:.2f} s)")
    print(f"wrote {out}" + (f" and {args.video} ({len(frames)} frames at {args.fps} fps)" if args.video else ""))
    return 0


def _print_flicker(args: argparse.Namespace, meter: FlickerMeter) -> None:
    """The video's flicker (:func:`piste.render.interlace.flicker`), with how it was drawn."""
    if meter.value is None:
        return
    inter, filt = getattr(args, "interlace", False), getattr(args, "flicker_filter", False)
    how = ("interlaced, flicker filter" if filt else "interlaced") if inter else "progressive"
    print(f"flicker ({how}; line-alternating luma component's mean squared change frame to frame, "
          f"{meter.pairs} frame pairs): {meter.value:.2f}")


def _occlusion(args: argparse.Namespace) -> bool | None:
    """``--occlusion on|off`` as the runtime's ``occlusion`` (None: the scene file's ``[render] occlusion``)."""
    return None if getattr(args, "occlusion", None) is None else args.occlusion == "on"


def _morph(args: argparse.Namespace) -> bool | None:
    """``--lod-morph on|off`` as the runtime's ``lod_morph`` (None: the scene file's ``[lod] morph``)."""
    return None if getattr(args, "lod_morph", None) is None else args.lod_morph == "on"


def _objects_table(scene: Scene, lights: Lights) -> list[str]:
    from piste.world.objects import lighting_report

    objs = scene.objects
    st = objs.stats()
    lines = ["Objects (compressed: 16-bit positions + UVs, octahedral 8-bit normals, uint16 indices):",
             f"  {'kind':<6} {'instances':>9} {'triangles':>9} {'vertices':>8} {'bytes/vertex':>12} {'mesh bytes':>10} "
             f"{'as float':>9}"]
    for k, s in st.items():
        lines.append(f"  {k:<6} {s['instances']:>9} {s['triangles']:>9} {s['vertices']:>8} {s['vertex_bytes']:>12} "
                     f"{s['bytes']:>10} {s['bytes_float']:>9}")
    rep = lighting_report(objs, lights)
    lines.append("  lighting options vs the full lighting equation per vertex (all lights):")
    names = {"dynamic": "1 ambient + 3 directional (SSX)", "baked": "pre-calculated RGB8 per vertex",
             "points": "dynamic point + spot lights"}
    for k, r in rep.items():
        lines.append(f"    {names[k]:<34} {r['bytes']:>8} bytes   mean error {r['mean_error']:.4f}   "
                     f"max error {r['max_error']:.3f}")
    return lines


def run_scene(args: argparse.Namespace, bundle: Bundle, lightmap: Any, lighting: str, t0: float) -> int:
    """``piste demo --scene full`` (the default): the completed real-time scene.

    Six riders playing their clips down the default course, the camera chasing the first; trees,
    signs, rocks and rails; projected rider shadows; per-vertex lit riders and objects with the
    specular pass.  Frames are real time: frame ``i`` is ``t = i / fps`` seconds after rider 0 was at
    ``--start`` (a fraction of the track).  Prints the terrain table (the talk's statistics), the
    characters (bones, palette sizes per LOD, batches), the objects (instances, compressed bytes,
    lighting memory vs error), shadow patches per frame and the frame-time breakdown.

    The full scene on the built default course ``bundle`` (see :func:`run`):
    the six riders following the track and the course's objects are the default scene file's
    ``[pack]`` and ``[auto_objects]``, made and drawn by the runtime of ``piste render``
    (:class:`piste.pipeline.preview.ScenePreview`); ``--start`` moves the pack."""
    import sys
    import time

    import numpy as np

    from piste.pipeline.preview import ScenePreview, rider_casts  # --rider-model: other models beside the pack
    from piste.render import summarize
    from piste.render.context import save_png
    from piste.render.scene_renderer import summarize_scene
    from piste.render.interlace import FlickerMeter, field_times, interlace
    from piste.render.video import VideoWriter
    from piste.terrain import format_stats

    w, h = args.size
    net, lights = bundle.net, bundle.lights
    preview = ScenePreview(bundle, size=(w, h), lightmap=lightmap, object_lighting=args.objects,
                           shadows=not args.no_shadows, specular=not args.no_specular, lightmap_mode=args.lightmap,
                           start=args.start, casts=rider_casts(args.rider_model),
                           object_lod=getattr(args, "object_lod", None), lod_morph=_morph(args),
                           aa=getattr(args, "aa", None), supersample=getattr(args, "supersample", 1),
                           trace=getattr(args, "trace", None), dof=getattr(args, "dof", None),
                           soft_shadows=getattr(args, "soft_shadows", None), occlusion=_occlusion(args))
    scene, renderer = preview.scene, preview.renderer
    lod_on = args.lod == "on"
    from piste._jit import warm_up
    from piste.terrain.resident import resident_fits, resident_terrain

    warm_up()  # the compiled kernels and the terrain's resident vertex blocks, before anything is timed
    if resident_fits(net):
        resident_terrain(net)
    for k in range(3):  # warm-up frames (not timed, not written): shaders, GL buffers, caches
        preview.render(None, k / args.fps, lod=lod_on, read=False)
    setup_s = time.perf_counter() - t0
    images = []
    meter = FlickerMeter()
    times = [i / args.fps for i in range(args.frames)]
    inter, filt = getattr(args, "interlace", False), getattr(args, "flicker_filter", False)
    try:
        from tqdm import tqdm

        with VideoWriter(args.video, fps=args.fps) if args.video else contextlib.nullcontext() as video:
            bar = tqdm(total=args.frames, desc="rendering", unit="frame",
                       disable=args.no_progress or args.frames < 2, file=sys.stderr)
            t_loop = time.perf_counter()
            # pipelined: each frame's CPU side runs while the GL draws the one before
            # --interlace: two fields a frame, half a frame apart, woven (the frame's stats: its second field's)
            stream = interlace(preview.frames(field_times(times, args.fps), lod=lod_on), filt) \
                if inter else preview.frames(times, lod=lod_on)
            for i, image in enumerate(stream):
                bar.update(1)
                meter.add(image)
                if i == 0:
                    out = save_png(args.out, image)
                if video is not None:
                    video.append(image)
                im = preview.frame
                im.image = None
                im.terrain.image = None
                images.append(im)
            bar.close()
            loop_s = time.perf_counter() - t_loop
        timed = list(images)
        while len(timed) < 5:  # time at least five frames (medians below); the extra ones are not written
            preview.render(None, len(timed) / args.fps, lod=lod_on)
            im = preview.frame
            im.image = im.terrain.image = None
            timed.append(im)
    finally:
        preview.release()
    med = {f"{k}_ms": float(np.median([im.timings[k] for im in timed])) for k in timed[0].timings}
    med["fps"] = 1e3 / med["total_ms"] if med["total_ms"] > 0 else float("inf")
    s = summarize([im.terrain for im in images])
    sc = summarize_scene(images)
    lod = "on" if lod_on else "off (all 8x8)"
    print(format_stats(s, title=(f"Terrain statistics: {net.name}, {len(images)} frame(s) at {w}x{h}, LOD {lod}, "
                                 f"light map {args.lightmap}, lighting {lighting}")))
    print()
    print(f"Characters: {len(scene.riders)} riders, clips {', '.join(scene.riders.clips)}; blended-matrix palettes "
          f"skinned on the CPU (see piste.render.character_pass)")
    print(f"  {'LOD':<7} {'triangles':>9} {'vertices':>8} {'bones':>5} {'weight step':>11} {'palette matrices':>16} "
          f"{'batches':>7}")
    for c in scene.character_stats():
        print(f"  {c['lod']:<7} {c['triangles']:>9} {c['vertices']:>8} {c['bones']:>5} {c['step']:>11.2f} "
              f"{c['palette']:>16} {c['batches']:>7}")
    lods = np.array([im.scene.rider_lod for im in images])
    print(f"  riders per LOD (mean over frames): high {np.mean(lods == 0) * 6:.1f}, medium {np.mean(lods == 1) * 6:.1f}, "
          f"low {np.mean(lods == 2) * 6:.1f};  rider triangles per frame {sc['rider_triangles']:.0f} "
          f"(+ specular pass)")
    print()
    for line_ in _objects_table(scene, lights):
        print(line_)
    ob = renderer.objects
    levels = ", ".join(f"{n}" for n in ob.lod_counts) if ob is not None else "-"
    print(f"  drawn per frame (frustum-culled, lighting '{args.objects}'): {sc['objects_drawn']:.0f} objects, "
          f"{sc['object_triangles']:.0f} triangles; last frame's objects per LOD level {levels} "
          f"(error <= {ob.lod_pixels if ob is not None else 0:g} px)")
    print()
    print(f"Projected shadows: {len(scene.riders)} low-LOD riders ({scene.lods[-1].n_triangles} triangles each) into "
          f"{renderer.shadows.tile if renderer.shadows else 0}x{renderer.shadows.tile if renderer.shadows else 0} tiles;"
          f" extra pass on the patches each shadow frustum touches:")
    print(f"  shadow patches per frame: {sc['shadow_patches']:.1f} (max {sc['shadow_patches_max']}; "
          f"{sc['shadow_patches_union']:.1f} distinct), {sc['shadow_triangles']:.0f} triangles, "
          f"vs {sc['terrain_patches']:.0f} terrain patches drawn")
    print()
    print(f"frame times (median over {len(timed)} warmed-up frame(s), llvmpipe/EGL):")
    rows = [
        ("animation (clips, rider matrices, camera)", "animation_ms"),
        ("character LOD + skinning (palettes)", "lod_skinning_ms"),
        ("light choice (1 + 3 per rider)", "lights_ms"),
        ("object culling", "objects_ms"),
        ("terrain LOD", "terrain_lod_ms"),
        ("terrain culling", "terrain_cull_ms"),
        ("tessellation", "tessellate_ms"),
        ("shadow frusta + patch culling", "shadow_cull_ms"),
    ]
    for label, key in rows:
        print(f"  {label:<42} {med[key]:7.2f} ms")
    print(f"  {'LOD + cull + tessellation (terrain)':<42} {med['terrain_lod_ms'] + med['terrain_cull_ms'] + med['tessellate_ms']:7.2f} ms")
    print(f"  {'CPU side':<42} {med['cpu_ms']:7.2f} ms")
    print(f"  {'upload':<42} {med['upload_ms']:7.2f} ms")
    print(f"  {'draw terrain (GL issue)':<42} {med['terrain_draw_ms']:7.2f} ms")
    print(f"  {'draw shadows, objects, riders, specular + wait':<42} {med['scene_draw_ms']:7.2f} ms")
    print(f"  {'read back':<42} {med['readback_ms']:7.2f} ms")
    print(f"  {'frame':<42} {med['total_ms']:7.2f} ms = {med['fps']:.1f} fps")
    if len(images) >= 2:
        print(f"  {'pipelined loop (wall time / frames)':<42} {1e3 * loop_s / len(images):7.2f} ms = "
              f"{len(images) / loop_s:.1f} fps  ({len(images)} frames, PNG/video writing included)")
    print(f"  (set-up, not in the frame times: course, light map, riders, objects, GL context, shaders: {setup_s:.2f} s)")
    _print_flicker(args, meter)
    print(f"wrote {out}" + (f" and {args.video} ({len(images)} frames at {args.fps} fps)" if args.video else ""))
    return 0
