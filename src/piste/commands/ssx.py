"""``piste ssx``: SSX Tricky levels (``.pbd`` with ``.ssh`` / ``_L.ssh`` beside it).

    piste ssx info LEVEL.pbd                       counts, bounds, textures, light-map pages
    piste ssx render LEVEL.pbd --out x.png [--lightmap modulate|ps2]
    piste ssx view LEVEL.pbd                       a window (or one off-screen frame without a display)
    piste ssx bake LEVEL.pbd [--lights L.toml | --scene S.toml] [--out NEW.pbd]
    piste ssx convert LEVEL.pbd --to npz|multitool|gltf --out PATH
    piste ssx make DIR [--rows R --cols C --name NAME]   a synthetic level (piste's own encoder)
    piste ssx make DIR --from NET.npz|NET.bpt|default  the level from any piste patch net (metres)
    piste ssx import PROJECT_DIR --out NEW.pbd     a Multitool project as a level (+ .ssh, _L.ssh)

``piste render LEVEL.pbd``, ``piste view LEVEL.pbd`` and ``piste bake LEVEL.pbd --format ssx-tricky``
run the same code.
"""

from __future__ import annotations

ACTIONS = ("info", "render", "view", "bake", "convert", "make", "import")


def add_arguments(parser) -> None:
    from piste.commands import _numbers as N

    parser.add_argument("action", choices=ACTIONS, help="what to do")
    parser.add_argument("level", help="LEVEL.pbd (make: the output folder; import: the Multitool project folder)")
    parser.add_argument("--out", help="render: PNG (default out/ssx.png); bake: the .pbd to write (default: the "
                                      "level itself, with NAME_L.ssh beside it); convert: the .npz or project folder")
    parser.add_argument("--lightmap", choices=("modulate", "ps2"), default="modulate", help="light-map mode")
    parser.add_argument("--size", nargs=2, type=N.SIZE, default=(640, 448), metavar=("W", "H"), help="image size")
    parser.add_argument("--eye", nargs=3, type=N.COORDINATE, metavar=("X", "Y", "Z"), help="camera position (metres)")
    parser.add_argument("--target", nargs=3, type=N.COORDINATE, metavar=("X", "Y", "Z"), help="camera target (metres)")
    parser.add_argument("--lights", metavar="TOML", help="bake: a lights file (default: the scene's or piste's)")
    parser.add_argument("--scene", metavar="TOML", help="bake: take the lights from this scene file")
    parser.add_argument("--no-shadows", action="store_true", help="bake: no shadow rays")
    parser.add_argument("--jobs", type=N.JOBS, default=1, help="bake: worker processes (0 = every core)")
    parser.add_argument("--to", choices=("npz", "multitool", "gltf"),
                        help="convert: a PatchNet .npz, a Multitool project folder, or glTF (.glb/.gltf: the "
                             "terrain with the level's textures and light map, as `piste export` writes it)")
    parser.add_argument("--rows", type=N.integer(1, 256), default=2, help="make: patch rows")
    parser.add_argument("--cols", type=N.integer(1, 256), default=3, help="make: patch columns")
    parser.add_argument("--name", default="SYNTH", help="make: the level's name")
    parser.add_argument("--from", dest="from_net", metavar="NET",
                        help="make: the patches of a saved PatchNet (.npz), a .bpt, or 'default' (the default "
                             "course) instead of a synthetic slope; placeholder textures and light maps (bake next)")
    parser.add_argument("--frames", type=N.FRAMES, help="view: quit after N frames")


def default_camera(net):
    """A camera looking at the whole level from the south-west, above."""
    import numpy as np

    from piste.world.camera import Camera

    lo, hi = net.bounds
    c = (lo + hi) / 2.0
    ext = float(np.linalg.norm(hi - lo))
    return Camera(c + np.array([-0.35, -0.6, 0.55]) * ext, c, fov_y=50.0, near=max(ext * 1e-3, 0.05), far=ext * 4.0)


def _camera(args, net):
    import numpy as np

    from piste.errors import ConfigError
    from piste.world.camera import Camera

    if args.eye is None and args.target is None:
        return default_camera(net)
    if args.eye is None or args.target is None:
        raise ConfigError("--eye and --target go together")
    d = float(np.linalg.norm(np.subtract(args.eye, args.target)))
    return Camera(np.array(args.eye), np.array(args.target), fov_y=50.0, near=0.1, far=max(d * 20.0, 1000.0))


def _pbd_path(p):
    from pathlib import Path

    from piste.errors import ConfigError

    path = Path(p)
    if path.suffix.lower() != ".pbd":
        raise ConfigError(f"{p}: expected an SSX Tricky level (.pbd)")
    return path


def render_pbd(level_path, out, size=(640, 448), lightmap_mode="modulate", camera=None) -> str:
    """Render ``level_path`` to ``out`` (PNG); returns the path written."""
    from piste.pipeline.ssx_level import load_level
    from piste.render.context import save_png
    from piste.render.ssx_pass import render_level

    level = load_level(_pbd_path(level_path))
    cam = camera if camera is not None else default_camera(level.net)
    img = render_level(level, cam, size=tuple(size), lightmap_mode=lightmap_mode)
    return str(save_png(out, img))


def bake_pbd(level_path, out=None, lights_path=None, scene_path=None, shadows=True, jobs=1, quiet=False) -> int:
    """``piste ssx bake``: bake ``NAME_L.ssh`` the game's way and update the patches' light-map tiles."""
    import time

    from piste.lighting.lights import default_lights, load_lights
    from piste.pipeline.ssx_level import bake_level, load_level, write_baked

    t0 = time.perf_counter()
    level = load_level(_pbd_path(level_path))
    if lights_path:
        lights = load_lights(lights_path)
    elif scene_path:
        from piste.pipeline.build import scene_lights
        from piste.world.scene_file import load_scene

        lights = scene_lights(load_scene(scene_path))
    else:
        lights = default_lights()
    baked = bake_level(level, lights, shadows=shadows, jobs=jobs)
    pbd, lssh = write_baked(level, baked, out)
    st = baked.stats
    if not quiet:
        print(f"baked {len(level.pbd)} patches into {len(baked.pages)} light-map page(s) "
              f"({st.get('rays', 0):,} shadow rays, {st.get('rays_occluded', 0):,} occluded) in "
              f"{time.perf_counter() - t0:.2f} s: {lssh}, {pbd}")
    return 0


def run(args) -> int:
    import sys
    from pathlib import Path

    from piste.errors import ConfigError

    if args.action == "make":
        from piste.formats.ssx.synth import make_level

        if args.rows < 1 or args.cols < 1:
            raise ConfigError("--rows and --cols must be >= 1")
        net = None
        if args.from_net:
            from piste.pipeline.open_scene import load_net as _load_net

            net = _load_net(None if args.from_net == "default" else args.from_net)
        path = make_level(net=net, rows=args.rows, cols=args.cols, jitter=0.0 if net is not None else 0.02,
                          n_textures=1 if net is not None else 3).write(Path(args.level), args.name)
        print(f"wrote {path} and {path.stem}.ssh, {path.stem}_L.ssh beside it")
        return 0
    if args.action == "import":
        from piste.formats.ssx.multitool import read_project
        from piste.formats.ssx.pbd import write_pbd
        from piste.formats.ssx.ssh import write_ssh

        if not args.out or not str(args.out).lower().endswith(".pbd"):
            raise ConfigError("import needs --out NEW.pbd")
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
    if args.action == "info":
        from piste.pipeline.ssx_level import load_level

        level = load_level(_pbd_path(args.level))
        p = level.pbd
        lo, hi = level.net.bounds
        print(f"{level.path.name}: platform {p.platform}, {len(p)} patches "
              f"({int(p.trick_only.sum())} trick-only), {len(level.net.shared_edges)} shared edges after welding")
        print(f"bounds (m): {[round(float(x), 2) for x in lo]} .. {[round(float(x), 2) for x in hi]}")
        print(f"textures: {level.info['textures']} ({level.info['textures_file']}), light-map pages: "
              f"{level.info['lightmap_pages']} ({level.info['lightmaps_file']})")
        print("counts: " + ", ".join(f"{k} {v}" for k, v in p.counts.items() if v))
        return 0
    if args.action == "render":
        out = args.out or "out/ssx.png"
        from piste.pipeline.ssx_level import load_level

        level_net = load_level(_pbd_path(args.level)).net
        print(f"wrote {render_pbd(args.level, out, args.size, args.lightmap, _camera(args, level_net))}")
        return 0
    if args.action == "view":
        return view_pbd(args)
    if args.action == "bake":
        return bake_pbd(args.level, args.out, args.lights, args.scene, not args.no_shadows, args.jobs)
    if args.action == "convert":
        if args.to is None or args.out is None:
            raise ConfigError("convert needs --to npz|multitool|gltf and --out PATH")
        if args.to == "gltf":
            return gltf_pbd(args.level, args.out)
        from piste.pipeline.ssx_level import load_level

        level = load_level(_pbd_path(args.level))
        if args.to == "npz":
            level.pbd.to_net().save(args.out)
        else:
            from piste.formats.ssx.multitool import write_project

            write_project(args.out, level.pbd, level.textures, level.lightmaps)
        print(f"wrote {args.out}")
        return 0
    raise ConfigError(f"unknown action {args.action!r}")


def view_pbd(args) -> int:
    """A level in a window; without a display, one off-screen frame to ``--out``."""
    import sys

    from piste.render.window import has_display

    out = args.out or "out/ssx_view.png"
    if not has_display():
        print("piste view: no display (DISPLAY / WAYLAND_DISPLAY unset), so no window; rendering one frame "
              f"off-screen to {out} instead (run under a desktop or `xvfb-run piste view`)", file=sys.stderr)
        print(f"wrote {render_pbd(args.level, out, args.size, args.lightmap)}")
        return 0
    from piste.pipeline.ssx_level import load_level
    from piste.render.ssx_pass import LevelView, level_renderer
    from piste.render.window import ViewOptions, run_window

    level = load_level(_pbd_path(args.level))

    def make_view(ctx):
        return LevelView(level_renderer(level, tuple(args.size), ctx=ctx))

    run_window(make_view, default_camera(level.net), size=tuple(args.size), caption=f"piste view {level.path.name}",
               opts=ViewOptions(lightmap_mode=args.lightmap), frames=args.frames,
               screenshot=out if args.frames else None)
    return 0


def gltf_pbd(level_path, out) -> int:
    """The level as glTF: a scene ``terrain = { ssx_pbd = LEVEL }`` built in a temporary folder (no
    files beside the level) and exported like ``piste export``."""
    import json
    import tempfile
    from pathlib import Path

    from piste.commands.export import export_bundle
    from piste.pipeline import load_bundle
    from piste.pipeline.build import build_scene

    from piste.world.scene_file import loads_scene

    level = _pbd_path(level_path).resolve()
    # the scene exists only in memory, as if beside the level (its path relative to that folder)
    scene = loads_scene(f"name = {json.dumps(level.stem)}\nterrain = {{ ssx_pbd = {json.dumps(level.name)} }}\n",
                        level.parent / f"{level.stem}.toml")
    with tempfile.TemporaryDirectory() as d:
        r = build_scene(scene, out=Path(d) / f"{level.stem}.piste", use_cache=False)
        report = export_bundle(load_bundle(r.path), out)
    print(f"wrote {out} ({report.bytes / 1e6:.2f} MB): terrain {report.terrain_triangles:,} triangles with the "
          "level's textures and light map")
    return 0
