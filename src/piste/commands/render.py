"""``piste render SCENE --camera NAME --out image.png``: render a scene from one of its cameras.

``SCENE`` is a ``.toml`` scene (built first, with the cache) or a built ``.piste`` bundle.  With
``--frames N`` time advances ``1/fps`` a frame (riders animate, track cameras fly) and ``--video``
writes an H.264 MP4.
"""

from __future__ import annotations


def add_arguments(parser) -> None:
    from piste.commands import _numbers as N
    from piste.commands.demo import _positive, _size

    parser.add_argument("scene", help="a scene (.toml), a bundle (.piste) or a tiled world folder (.tiles: a flight "
                        "across it at --speed, tiles streamed)")
    parser.add_argument("--camera", help="scene camera to render from (default: the first; see --list)")
    parser.add_argument("--out", default="out/render.png", help="PNG of the first frame (default: out/render.png)")
    parser.add_argument("--size", nargs=2, type=_size, metavar=("W", "H"), help="image size (default: the scene's)")
    parser.add_argument("--frames", type=_positive, default=1, help="frames to render (default: 1)")
    parser.add_argument("--video", metavar="MP4", help="also write the frames as an H.264 MP4")
    parser.add_argument("--fps", type=N.FPS, default=30, help="frame rate (default: 30)")
    parser.add_argument("--list", action="store_true", help="list the scene's cameras and exit")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.add_argument("--speed", type=N.real(0.0, 100_000.0, lo_open=True), default=100.0,
                        help="tiled worlds: flight speed in m/s (default 100)")
    parser.add_argument("--budget", type=N.real(1.0, float(1 << 20)), default=256.0,
                        help="tiled worlds: streaming memory budget in MiB")


def load_or_build(scene, quiet: bool = True):
    """A loaded bundle for ``scene`` (see :func:`piste.pipeline.open_scene.load_or_build`)."""
    from piste.pipeline.open_scene import load_or_build as _load_or_build

    return _load_or_build(scene, quiet, warm=True)  # the renderer draws it next: resident blocks at load


def run(args) -> int:
    import sys

    if str(args.scene).lower().endswith(".pbd"):  # an SSX Tricky level: piste.commands.ssx
        from piste.commands.ssx import render_pbd

        print(f"wrote {render_pbd(args.scene, args.out, args.size or (640, 448))}")
        return 0
    from pathlib import Path

    from piste.errors import ConfigError
    from piste.formats.atomic import check_writable_folder
    from piste.pipeline.preview import render_frames

    if args.scene.rstrip("/").endswith(".tiles"):  # a tiled world: stream it (piste.render.streaming)
        from piste.render.streaming import render_flight_cli

        return render_flight_cli(args)
    b = load_or_build(args.scene, args.quiet)
    if args.list:
        for c in b.manifest.get("cameras", []):
            extra = f" track {c['track'][0]:.2f}..{c['track'][1]:.2f}" if c.get("track") else ""
            print(f"{c['name']:<20} from {c.get('source', 'scene'):<16} eye {[round(x, 2) for x in c['eye']]}{extra}")
        return 0
    size = tuple(args.size) if args.size else None
    if args.video:
        w, h = size or tuple(b.manifest.get("render", {}).get("size", (640, 448)))
        if w % 2 or h % 2:
            raise ConfigError(f"--size {w} {h}: H.264 video needs an even width and height")
    for out in (args.out, args.video):  # unwritable outputs are reported before rendering
        if out:
            check_writable_folder(Path(out).parent)
    if b.visibility is not None:  # cameras above the visibility band draw without the sets: say so
        from piste.pipeline.preview import camera_at
        from piste.pipeline.visibility import band_warnings

        cams = [camera_at(b, args.camera, i, args.frames) for i in range(args.frames)]
        for msg in band_warnings(b.net, b.visibility, cams, [f"{args.camera or 'camera'} frame {i}" for i in range(len(cams))])[:1]:
            print(f"warning: {msg}", file=sys.stderr)
    stats = render_frames(b, args.camera, args.frames, size=size, fps=args.fps, video=args.video, first_png=args.out,
                          progress=not args.quiet and sys.stderr.isatty() and args.frames > 1)
    if stats and "frustum_patches" in stats[0]:
        fr = sum(s["frustum_patches"] for s in stats) / len(stats)
        dr = sum(s["drawn_patches"] for s in stats) / len(stats)
        print(f"patches: frustum culling {fr:.0f}, with visibility {dr:.0f} of {len(b.net)} (mean over {len(stats)} frame(s))")
    print(f"wrote {args.out}" + (f" and {args.video} ({args.frames} frames at {args.fps} fps)" if args.video else ""))
    return 0
