"""``piste render SOURCE --camera NAME --out image.png``: render any source from one of its cameras.

``SOURCE`` is a ``.toml`` scene (built first, with the cache), a built ``.piste`` bundle, an SSX
Tricky level (``.pbd`` with its ``.ssh`` / ``_L.ssh``) or a tiled world (``.tiles``, streamed):
each opened by :func:`piste.pipeline.open_scene.open_source` and drawn by the one runtime
(:class:`piste.pipeline.preview.ScenePreview`; tiled worlds by :mod:`piste.render.streaming`).
``--eye X Y Z --target X Y Z`` gives a camera of your own for any source.  With ``--frames N`` time
advances ``1/fps`` a frame (riders animate, track cameras fly) and ``--video`` writes an H.264 MP4.
This module only parses.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import argparse

    from piste.pipeline.bundle_objects import Bundle


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from piste.commands import _numbers as N

    parser.add_argument("scene", help="a scene (.toml), a bundle (.piste), an SSX level (.pbd) or a tiled world folder "
                        "(.tiles: a flight across it at --speed, tiles streamed)")
    parser.add_argument("--camera", help="scene camera to render from (default: the first; see --list)")
    parser.add_argument("--out", default="out/render.png", help="PNG of the first frame (default: out/render.png)")
    parser.add_argument("--size", nargs=2, type=N.SIZE, metavar=("W", "H"), help="image size (default: the scene's)")
    parser.add_argument("--frames", type=N.FRAMES, default=1, help="frames to render (default: 1)")
    parser.add_argument("--video", metavar="MP4", help="also write the frames as an H.264 MP4")
    parser.add_argument("--fps", type=N.FPS, default=30, help="frame rate (default: 30)")
    parser.add_argument("--list", action="store_true", help="list the scene's cameras and exit")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.add_argument("--speed", type=N.real(0.0, 100_000.0, lo_open=True), default=100.0,
                        help="tiled worlds: flight speed in m/s (default 100)")
    parser.add_argument("--budget", type=N.real(1.0, float(1 << 20)), default=256.0,
                        help="tiled worlds: streaming memory budget in MiB")
    parser.add_argument("--eye", nargs=3, type=N.COORDINATE, metavar=("X", "Y", "Z"),
                        help="a camera of your own: its position in metres (with --target; any source)")
    parser.add_argument("--target", nargs=3, type=N.COORDINATE, metavar=("X", "Y", "Z"),
                        help="the point --eye looks at (metres)")
    parser.add_argument("--fov", type=N.FOV, default=50.0, help="--eye's vertical field of view in degrees (default 50)")
    parser.add_argument("--riders", type=N.integer(0, 64), default=0, metavar="N",
                        help="stand N default riders on the terrain of a source without riders of its own (an SSX "
                             "level); drawn with their shadows by the same runtime as a scene's. With --track: the "
                             "pack riding the track has N riders (1..64, default 6)")
    parser.add_argument("--track", nargs=4, type=N.COORDINATE, metavar=("X0", "Y0", "X1", "Y1"),
                        help="tiled worlds: a pack of riders (six, or --riders N) rides a straight track from "
                             "(X0, Y0) to (X1, Y1) metres across the tiles, the camera chasing rider 0 (unless "
                             "--eye/--camera)")
    parser.add_argument("--add-objects", type=N.integer(0, 10_000), default=0, metavar="N",
                        help="place N of the course's objects (trees, rocks, signs, rails) on the terrain of a source "
                             "without objects of its own (an SSX level, a tiled world)")


def load_or_build(scene: str | os.PathLike[str], quiet: bool = True) -> Bundle:
    """The runtime scene of ``scene`` with its terrain warming (the old name, for scripts and tests:
    :func:`piste.pipeline.open_scene.open_source`)."""
    from piste.pipeline.open_scene import open_source

    return open_source(scene, quiet=quiet, warm=True)


def _morph(args: argparse.Namespace) -> bool | None:
    return None if getattr(args, "lod_morph", None) is None else args.lod_morph == "on"


def _occlusion(args: argparse.Namespace) -> bool | None:
    """``--occlusion on|off`` as the runtime's ``occlusion`` (None: the scene file's ``[render] occlusion``)."""
    return None if getattr(args, "occlusion", None) is None else args.occlusion == "on"


def run(args: argparse.Namespace) -> int:
    import sys
    from pathlib import Path

    from piste.errors import ConfigError
    from piste.formats.atomic import check_writable_folder
    from piste.pipeline.open_scene import eye_camera, open_source, source_kind
    from piste.pipeline.preview import camera_at, render_frames

    kind = source_kind(args.scene)
    cam = eye_camera(args.eye, args.target, args.fov)
    if cam is not None and args.camera:
        raise ConfigError("--camera names a scene camera; --eye/--target give one: use one or the other")
    size = tuple(args.size) if args.size else None
    track = getattr(args, "track", None)
    if track is not None and kind != "tiles":
        raise ConfigError(f"--track needs a tiled world (.tiles), got a {kind}")
    b = open_source(args.scene, quiet=args.quiet, warm=True, riders=args.riders, objects=args.add_objects,
                    budget_mb=args.budget, track=track)
    if args.list:
        for c in b.manifest.get("cameras", []):
            extra = f" track {c['track'][0]:.2f}..{c['track'][1]:.2f}" if c.get("track") else ""
            print(f"{c['name']:<20} from {c.get('source', 'scene'):<16} eye {[round(x, 2) for x in c['eye']]}{extra}")
        return 0
    if args.video:
        w, h = size or tuple(b.manifest.get("render", {}).get("size", (640, 448)))
        if w % 2 or h % 2:
            raise ConfigError(f"--size {w} {h}: H.264 video needs an even width and height")
    if getattr(args, "flicker_filter", False) and not getattr(args, "interlace", False):
        raise ConfigError("--flicker-filter filters the fields of interlaced video: add --interlace")
    for out in (args.out, args.video, getattr(args, "trace", None)):  # unwritable outputs are reported before rendering
        if out:
            check_writable_folder(Path(out).parent)
    flight = kind == "tiles" and cam is None and not args.camera and track is None  # a tiled world: fly across it
    if flight:
        from piste.pipeline.tiles_source import flight_cameras

        cam = flight_cameras(b, args.frames, args.fps, args.speed)
    if b.visibility is not None:  # cameras above the visibility band draw without the sets: say so
        from piste.pipeline.visibility import band_warnings

        cams = [cam if cam is not None else camera_at(b, args.camera, i, args.frames) for i in range(args.frames)]
        for msg in band_warnings(b.net, b.visibility, cams, [f"{args.camera or 'camera'} frame {i}" for i in range(len(cams))])[:1]:
            print(f"warning: {msg}", file=sys.stderr)
    stats = render_frames(b, cam if cam is not None else args.camera, args.frames, size=size, fps=args.fps, video=args.video,
                          first_png=args.out, progress=not args.quiet and sys.stderr.isatty() and args.frames > 1,
                          lod_morph=_morph(args), aa=getattr(args, "aa", None),
                          supersample=getattr(args, "supersample", 1), trace=getattr(args, "trace", None),
                          dof=getattr(args, "dof", None), soft_shadows=getattr(args, "soft_shadows", None), occlusion=_occlusion(args),
                          interlace=getattr(args, "interlace", False),
                          flicker_filter=getattr(args, "flicker_filter", False))
    if kind == "tiles":
        import numpy as np

        ms = np.array([st["ms"] for st in stats])
        how = f"flying at {args.speed:g} m/s" if flight else \
            "chasing rider 0 along the track" if track is not None and cam is None and not args.camera else \
            f"from {args.camera or 'the camera'}"
        print(f"wrote {args.out}" + (f" and {args.video}" if args.video else "") +
              f": {len(stats)} frame(s) {how}, median {np.median(ms):.1f} ms (max {ms.max():.1f}), resident "
              f"{max(st['resident_bytes'] for st in stats) / 2**20:.1f} MiB of {args.budget:g}, last frame "
              f"{stats[-1]['near_tiles']} near + {stats[-1]['far_tiles']} far tiles")
        return 0
    if stats and "frustum_patches" in stats[0]:
        fr = sum(s["frustum_patches"] for s in stats) / len(stats)
        dr = sum(s["drawn_patches"] for s in stats) / len(stats)
        print(f"patches: frustum culling {fr:.0f}, with visibility {dr:.0f} of {len(b.net)} (mean over {len(stats)} frame(s))")
    print(f"wrote {args.out}" + (f" and {args.video} ({args.frames} frames at {args.fps} fps)" if args.video else ""))
    return 0
