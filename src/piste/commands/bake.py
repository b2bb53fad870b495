"""``piste bake``: bake per-patch light maps (with terrain shadows) into an atlas.

Writes ``lightmap.png`` (half-bright 8-bit RGB, 128 = 1.0), ``lightmap.npz`` (float32 atlas,
``rects`` = each patch's ``lightmap_rect``) and ``manifest.json`` into ``--out``, each atomically.
Finished chunks are kept in ``OUT/.partial/`` until the bake completes, so an interrupted bake
started again resumes where it stopped and ends with the same bytes.  A bake that fails says where
its chunks are and how much they hold; ``piste bake --clean [--out DIR]`` removes them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from piste.commands import _numbers as N

    parser.add_argument("net", nargs="?", help="a .bpt or .npz patch net (default: the default course)")
    parser.add_argument("--lights", metavar="TOML", help="lights file (default: the default course's lights)")
    parser.add_argument("--res", type=N.integer(8, 16), default=8, choices=(8, 16), help="texels per patch side (default 8)")
    parser.add_argument("--out", metavar="DIR", default="out/lightmap", help="output folder (default out/lightmap)")
    parser.add_argument("--jobs", type=N.JOBS, default=0, help="worker processes (default 0 = every core)")
    parser.add_argument("--no-shadows", action="store_true", help="skip shadow rays (unshadowed lighting)")
    parser.add_argument("--bounces", type=N.integer(0, 16), default=0, metavar="N",
                        help="diffuse inter-reflections with sky light (the ambient lights become a sky the terrain "
                             "occludes); 0 = direct light only, as before (default 0)")
    parser.add_argument("--sun-radius", type=N.real(0.0, 10.0), default=0.0, metavar="DEG",
                        help="angular radius of the sun in degrees for soft shadows (the real sun: 0.27); "
                             "default 0 = a hard sun, the light maps as before")
    parser.add_argument("--tracer", choices=("exact", "embree"), default="exact",
                        help="--bounces' gather rays: on the exact patches (default) or through Embree on a "
                             "tessellation (the 'bench' extra's embreex; faster, slightly different light)")
    parser.add_argument("--chunk-size", type=N.integer(1, 1 << 20), default=64, help="patches per chunk (unit of resuming)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--clean", action="store_true",
                        help="remove the resumable chunks a stopped or failed bake left in OUT/.partial, then exit")
    parser.add_argument("--format", choices=("piste", "ssx-tricky"), default="piste",
                        help="piste: an atlas in --out; ssx-tricky: NET is a .pbd, writes NAME_L.ssh beside it the "
                             "game's way and updates the patches' light-map tiles (see `piste ssx --help`)")
    parser.add_argument("--scene", metavar="TOML", help="ssx-tricky: take the lights from this scene file")


def run(args: argparse.Namespace) -> int:
    import shutil
    import sys
    import time
    from pathlib import Path

    from piste.errors import ConfigError, PisteError
    from piste.formats.atomic import check_writable_folder
    from piste.lighting import bake_lightmap, default_lights, load_lights, write_lightmap
    from piste.lighting.baker import clean_partials, kept_chunks_error
    from piste.pipeline.open_scene import load_net

    if args.clean:
        partial = Path(args.out) / ".partial"
        chunks, size = clean_partials(partial)
        print(f"removed {chunks} resumable chunks ({size:,} bytes) from {partial}" if size
              else f"no resumable chunks in {partial}")
        return 0
    if args.format == "ssx-tricky" or str(args.net or "").lower().endswith(".pbd"):
        from piste.pipeline.build import scene_lights
        from piste.pipeline.ssx_level import bake_file
        from piste.world.scene_file import load_scene

        if args.net is None:
            raise ConfigError("--format ssx-tricky needs a level: piste bake LEVEL.pbd --format ssx-tricky")
        if args.bounces or args.sun_radius or args.tracer != "exact":
            raise ConfigError("--bounces, --sun-radius and --tracer are for piste light maps, not --format ssx-tricky")
        out = args.out if str(args.out).lower().endswith(".pbd") else None
        lights = load_lights(args.lights) if args.lights else scene_lights(load_scene(args.scene)) if args.scene else None
        report = bake_file(args.net, lights, out, not args.no_shadows, args.jobs)
        if not args.quiet:
            print(report.summary())
        return 0
    if args.jobs < 0:
        raise ConfigError(f"--jobs must be >= 0, got {args.jobs}")
    if args.tracer != "exact" and not args.bounces:
        raise ConfigError(f"--tracer {args.tracer} chooses the gather rays of --bounces: give --bounces N (N >= 1) too")
    if args.chunk_size < 1:
        raise ConfigError(f"--chunk-size must be >= 1, got {args.chunk_size}")
    out = check_writable_folder(args.out)  # before the bake, not after it
    net = load_net(args.net)
    lights = load_lights(args.lights) if args.lights else default_lights()
    partial = out / ".partial"
    t0 = time.perf_counter()
    lm = bake_lightmap(
        net,
        lights,
        res=args.res,
        shadows=not args.no_shadows,
        jobs=args.jobs,
        chunk_size=args.chunk_size,
        partial_dir=partial,
        progress=not args.quiet and sys.stderr.isatty(),
        bounces=args.bounces,
        sun_radius=args.sun_radius,
        tracer=args.tracer,
    )
    try:
        paths = write_lightmap(lm, out)
    except (PisteError, OSError) as exc:  # a full disk: say where the finished bake's chunks are
        err = kept_chunks_error(exc, partial)
        if err is exc:
            raise
        raise err from exc
    shutil.rmtree(partial / lm.manifest["key"], ignore_errors=True)
    try:
        partial.rmdir()
    except OSError:
        pass
    dt = time.perf_counter() - t0
    m = lm.manifest
    st = m.get("stats", {})
    resumed = getattr(lm, "resumed_chunks", 0)
    print(
        f"baked {m['patches']} patches at {m['res']}x{m['res']} ({m['samples']:,} samples, "
        f"{st.get('rays', 0):,} shadow rays, {st.get('rays_occluded', 0):,} occluded) in {dt:.2f} s "
        f"({m['samples'] / max(dt, 1e-9):,.0f} samples/s)" + (f", {resumed} chunks resumed" if resumed else "")
    )
    if "gi" in m:
        gi = m["gi"]
        print(", ".join(([f"{gi['bounces']} bounces ({st.get('gather_rays', 0):,} gather rays, "
                          f"{st.get('gather_escaped', 0):,} to the sky)"] if "bounces" in gi else [])
                        + ([f"sun radius {gi['sun_radius']:g} deg (up to {gi['sun_rays']} rays per sample)"]
                           if "sun_radius" in gi else [])))
    print(f"atlas {m['atlas_size'][0]}x{m['atlas_size'][1]}: {paths['png']}, {paths['npz']}, {paths['manifest']}")
    return 0
