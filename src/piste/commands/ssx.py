"""``piste ssx``: SSX Tricky levels (``.pbd`` with ``.ssh`` / ``_L.ssh`` beside it), as subcommands.

    piste ssx info LEVEL.pbd                       counts, bounds, textures, light-map pages
    piste ssx render LEVEL.pbd [--out x.png] [--lightmap modulate|ps2] [--eye X Y Z --target X Y Z]
    piste ssx view LEVEL.pbd                       a window (or one off-screen frame without a display)
    piste ssx bake LEVEL.pbd [--lights L.toml | --scene S.toml] [--out NEW.pbd]
    piste ssx convert LEVEL.pbd --to npz|multitool|gltf --out PATH
    piste ssx make DIR [--rows R --cols C --name NAME]   a synthetic level (piste's own encoder)
    piste ssx make DIR --from NET.npz|NET.bpt|default  the level from any piste patch net (metres)
    piste ssx import PROJECT_DIR --out NEW.pbd     a Multitool project as a level (+ .ssh, _L.ssh)

``piste render LEVEL.pbd``, ``piste view LEVEL.pbd`` and ``piste bake LEVEL.pbd --format ssx-tricky``
open the same levels.  The command only parses: the work is in :mod:`piste.pipeline.ssx_level`,
:mod:`piste.formats.ssx`; ``render`` and ``view`` draw through the one runtime
(:func:`piste.pipeline.open_scene.open_source` + :class:`piste.pipeline.preview.ScenePreview`),
the same path as ``piste render|view LEVEL.pbd``.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import argparse

    import moderngl

    from piste.pipeline.live import PreviewView
    from piste.world.camera import Camera

def add_arguments(parser: argparse.ArgumentParser) -> None:
    from piste.commands import _numbers as N

    sub = parser.add_subparsers(dest="ssx_command", metavar="ACTION")
    sub.required = True

    def level(p: argparse.ArgumentParser, help: str = "an SSX Tricky level (.pbd; its .ssh and _L.ssh beside it)") -> None:
        p.add_argument("level", metavar="LEVEL.pbd", help=help)

    def look(p: argparse.ArgumentParser, default_out: str) -> None:
        p.add_argument("--out", default=default_out, help=f"PNG to write (default {default_out})")
        p.add_argument("--lightmap", choices=("modulate", "ps2"), default="modulate",
                       help="light-map mode: modulate (base x light) or ps2 (the stored Cs/As blended as the GS does)")
        p.add_argument("--size", nargs=2, type=N.SIZE, default=(640, 448), metavar=("W", "H"), help="image size")

    level(sub.add_parser("info", help="counts, bounds, textures and light-map pages"))
    r = sub.add_parser("render", help="render one frame to a PNG")
    level(r)
    look(r, "out/ssx.png")
    r.add_argument("--eye", nargs=3, type=N.COORDINATE, metavar=("X", "Y", "Z"), help="camera position (metres)")
    r.add_argument("--target", nargs=3, type=N.COORDINATE, metavar=("X", "Y", "Z"), help="camera target (metres)")
    v = sub.add_parser("view", help="the level in a window (M toggles the light-map mode)")
    level(v)
    look(v, "out/ssx_view.png")
    v.add_argument("--frames", type=N.FRAMES, help="quit after N frames (and save the last to --out)")
    b = sub.add_parser("bake", help="bake NAME_L.ssh the game's way and update the patches' light-map tiles")
    level(b)
    b.add_argument("--out", help="the .pbd to write (default: the level itself, with NAME_L.ssh beside it)")
    b.add_argument("--lights", metavar="TOML", help="a lights file (default: the scene's or piste's)")
    b.add_argument("--scene", metavar="TOML", help="take the lights from this scene file")
    b.add_argument("--no-shadows", action="store_true", help="no shadow rays")
    b.add_argument("--jobs", type=N.JOBS, default=1, help="worker processes (0 = every core)")
    b.add_argument("--quiet", action="store_true", help="print nothing")
    c = sub.add_parser("convert", help="the level as a PatchNet .npz, a Multitool project or glTF")
    level(c)
    c.add_argument("--to", choices=("npz", "multitool", "gltf"), required=True,
                   help="npz: the welded PatchNet (metres); multitool: a Multitool project folder (Patches, Lights, "
                        "Instances, Splines .json, Textures/, Lightmaps/); gltf (.glb/.gltf): "
                        "the terrain with the level's textures and light map, as `piste export` writes it")
    c.add_argument("--out", required=True, help="the .npz, project folder or .glb/.gltf to write")
    m = sub.add_parser("make", help="a level from piste's own encoder (a synthetic slope or any piste patch net)")
    m.add_argument("level", metavar="DIR", help="the folder to write NAME.pbd, NAME.ssh and NAME_L.ssh into")
    m.add_argument("--rows", type=N.integer(1, 256), default=2, help="patch rows")
    m.add_argument("--cols", type=N.integer(1, 256), default=3, help="patch columns")
    m.add_argument("--name", default="SYNTH", help="the level's name")
    m.add_argument("--from", dest="from_net", metavar="NET",
                   help="the patches of a saved PatchNet (.npz), a .bpt, or 'default' (the default course) instead "
                        "of a synthetic slope; placeholder textures and light maps (bake next)")
    i = sub.add_parser("import", help="a Multitool project as a level (.pbd, and .ssh / _L.ssh when it has them); "
                                      "notes on stderr name what the new level lacks")
    i.add_argument("level", metavar="PROJECT_DIR", help="the Multitool project folder (or its Patches.json)")
    i.add_argument("--out", required=True, help="the new level's .pbd")


def render_pbd(level: str | os.PathLike[str], out: str | os.PathLike[str], size: tuple[int, int] = (640, 448),
               lightmap_mode: str = "modulate", camera: Camera | None = None) -> str:
    """Render ``level`` (a ``.pbd`` path) to ``out`` (PNG) through the one runtime, as ``piste
    render LEVEL.pbd`` does (:func:`piste.pipeline.open_scene.open_source` +
    :func:`piste.pipeline.preview.render_frames`); ``camera``: a
    :class:`~piste.world.camera.Camera` (default: the level's own, from the south-west, above).
    Returns the path written."""
    from piste.pipeline.open_scene import open_source
    from piste.pipeline.preview import render_frames
    from piste.pipeline.ssx_level import level_path

    bundle = open_source(level_path(level), warm=True)  # (a non-.pbd: "expected an SSX Tricky level")
    render_frames(bundle, camera, 1, size=tuple(size), first_png=out, lightmap_mode=lightmap_mode)
    return str(out)


def run(args: argparse.Namespace) -> int:
    import sys
    from pathlib import Path

    cmd = args.ssx_command
    if cmd == "make":
        from piste.pipeline.ssx_synth import make_level

        net = None
        if args.from_net:
            from piste.pipeline.open_scene import load_net as _load_net

            net = _load_net(None if args.from_net == "default" else args.from_net)
        path = make_level(net=net, rows=args.rows, cols=args.cols, jitter=0.0 if net is not None else 0.02,
                          n_textures=1 if net is not None else 3).write(Path(args.level), args.name)
        print(f"wrote {path} and {path.stem}.ssh, {path.stem}_L.ssh beside it")
        return 0
    if cmd == "import":
        from piste.errors import ConfigError
        from piste.formats.ssx.multitool import read_project
        from piste.formats.ssx.pbd import write_pbd
        from piste.formats.ssx.ssh import write_ssh

        if not str(args.out).lower().endswith(".pbd"):
            raise ConfigError(f"--out {args.out}: expected the new level's .pbd")
        out = Path(args.out)
        project = read_project(args.level)
        pbd, textures, lightmaps = project.to_level()
        for note in project.notes:
            print(f"piste ssx import: note: {note}", file=sys.stderr)
        write_pbd(pbd, out)
        wrote = [f"{out} ({len(pbd)} patches)"]
        if textures is not None:
            write_ssh(textures, out.with_name(f"{out.stem}.ssh"))
            wrote.append(f"{out.stem}.ssh ({len(textures)} textures)")
        if lightmaps is not None:
            write_ssh(lightmaps, out.with_name(f"{out.stem}_L.ssh"))
            wrote.append(f"{out.stem}_L.ssh ({len(lightmaps)} pages)")
        print("wrote " + ", ".join(wrote))
        return 0
    if cmd == "bake":
        from piste.lighting.lights import load_lights
        from piste.pipeline.build import scene_lights
        from piste.pipeline.ssx_level import bake_file
        from piste.world.scene_file import load_scene

        lights = load_lights(args.lights) if args.lights else scene_lights(load_scene(args.scene)) if args.scene else None
        report = bake_file(args.level, lights, args.out, not args.no_shadows, args.jobs)
        if not args.quiet:
            print(report.summary())
        return 0
    from piste.pipeline.ssx_level import level_path, load_level

    if cmd == "info":
        level = load_level(level_path(args.level))
        p = level.pbd
        lo, hi = level.net.bounds
        print(f"{level.path.name}: platform {p.platform}, {len(p)} patches "
              f"({int(p.trick_only.sum())} trick-only), {len(level.net.shared_edges)} shared edges after welding")
        print(f"bounds (m): {[round(float(x), 2) for x in lo]} .. {[round(float(x), 2) for x in hi]}")
        print(f"textures: {level.info['textures']} ({level.info['textures_file']}), light-map pages: "
              f"{level.info['lightmap_pages']} ({level.info['lightmaps_file']})")
        print("counts: " + ", ".join(f"{k} {v}" for k, v in p.counts.items() if v))
        return 0
    if cmd == "render":
        from piste.pipeline.open_scene import eye_camera

        camera = eye_camera(args.eye, args.target)
        print(f"wrote {render_pbd(args.level, args.out, args.size, args.lightmap, camera)}")
        return 0
    if cmd == "view":
        return view_pbd(args)
    # convert
    if args.to == "gltf":
        return gltf_pbd(args.level, args.out)
    level = load_level(level_path(args.level))
    if args.to == "npz":
        from piste.pipeline.ssx_level import pbd_to_net

        pbd_to_net(level.pbd).save(args.out)
    else:
        from piste.formats.ssx.multitool import write_project

        write_project(args.out, level.pbd, level.textures, level.lightmaps)
    print(f"wrote {args.out}")
    return 0


def view_pbd(args: argparse.Namespace) -> int:
    """A level in a window, drawn by the one runtime as ``piste view LEVEL.pbd`` draws it
    (:class:`piste.pipeline.preview.ScenePreview` in :class:`piste.pipeline.live.PreviewView`);
    without a display, one off-screen frame to ``--out``."""
    import sys

    from piste.pipeline.live import PreviewView
    from piste.pipeline.open_scene import open_source
    from piste.pipeline.preview import ScenePreview, camera_at
    from piste.render.window import ViewOptions, has_display, run_window

    out = args.out or "out/ssx_view.png"
    size = tuple(args.size)
    if not has_display():
        print("piste view: no display (DISPLAY / WAYLAND_DISPLAY unset), so no window; rendering one frame "
              f"off-screen to {out} instead (run under a desktop or `xvfb-run piste view`)", file=sys.stderr)
        print(f"wrote {render_pbd(args.level, out, size, args.lightmap)}")
        return 0
    from piste.pipeline.ssx_level import level_path

    bundle = open_source(level_path(args.level), warm=True)

    def make_view(ctx: moderngl.Context) -> PreviewView:
        return PreviewView(ScenePreview(bundle, size=size, ctx=ctx, stream_wait=False, lightmap_mode=args.lightmap))

    run_window(make_view, camera_at(bundle), size=size, caption=f"piste view {bundle.path.name}",
               opts=ViewOptions(lightmap_mode=args.lightmap), frames=args.frames,
               screenshot=out if args.frames else None)
    return 0


def gltf_pbd(level_path: str | os.PathLike[str], out: str | os.PathLike[str]) -> int:
    """The level as glTF: a scene ``terrain = { ssx_pbd = LEVEL }`` built in a temporary folder (no
    files beside the level) and exported like ``piste export``."""
    import json
    import tempfile
    from pathlib import Path

    from piste.pipeline.bundle_gltf import export_bundle
    from piste.pipeline import load_bundle
    from piste.pipeline.build import build_scene
    from piste.pipeline.ssx_level import level_path as _level_path
    from piste.world.scene_file import loads_scene

    level = _level_path(level_path).resolve()
    # the scene exists only in memory, as if beside the level (its path relative to that folder)
    scene = loads_scene(f"name = {json.dumps(level.stem)}\nterrain = {{ ssx_pbd = {json.dumps(level.name)} }}\n",
                        level.parent / f"{level.stem}.toml")
    with tempfile.TemporaryDirectory() as d:
        r = build_scene(scene, out=Path(d) / f"{level.stem}.piste", use_cache=False)
        report = export_bundle(load_bundle(r.path), out)
    print(f"wrote {out} ({report.bytes / 1e6:.2f} MB): terrain {report.terrain_triangles:,} triangles with the "
          "level's textures and light map")
    return 0
