"""``piste build SCENE.toml``: pre-process a scene into one ``.piste`` bundle.

Validates the scene, fits or reads the terrain, bakes the light map, builds every character LOD
(palettes, batches, strips), compresses object vertices and bakes their colours, computes the
per-cell visibility sets, and writes the bundle atomically.  Steps whose inputs did not change come
from the cache (``.piste-cache/`` beside the scene), and the bundle comes out byte-identical.
A light-map bake that stops keeps its finished chunks in ``CACHE/bake-partial/`` (the same command
resumes from them); the failure says where they are and how much they hold, and
``piste build --clean SCENE [--cache DIR]`` removes them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import argparse

    from piste.pipeline.build import BuildResult


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from piste.commands import _numbers as N

    parser.add_argument("scene", help="scene description (.toml)")
    parser.add_argument("--out", metavar="BUNDLE", help="bundle to write (default: SCENE with suffix .piste)")
    parser.add_argument("--cache", metavar="DIR", help="step cache folder (default: .piste-cache beside the scene)")
    parser.add_argument("--no-cache", action="store_true", help="recompute every step, store nothing")
    parser.add_argument("--jobs", type=N.JOBS, default=1, help="light-map bake worker processes (default 1; 0 = every core)")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.add_argument("--clean", action="store_true",
                        help="remove the resumable chunks a stopped or failed bake left in CACHE/bake-partial, then exit")
    parser.add_argument("--dask", metavar="local", help="large worlds: build the tiles as Dask tasks on a LocalCluster "
                        "on 127.0.0.1 (implies a tiled build: terrain.tiles, default SCENE.tiles)")
    parser.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="large worlds: build the tiles on the Dask "
                        "scheduler at this address (the tiles folder must be on storage every worker sees)")
    parser.add_argument("--workers", type=N.WORKERS, default=None, help="--dask local: worker processes (default: cores)")


def run(args: argparse.Namespace) -> int:
    import sys

    from pathlib import Path

    from piste.errors import ConfigError
    from piste.formats.atomic import check_writable_folder
    from piste.pipeline.build import build_scene

    if args.clean:  # the scene need not load (it may be the broken input): only its folder is used
        from piste.lighting.baker import clean_partials
        from piste.pipeline.build import bake_partial_dir

        partial = bake_partial_dir(Path(args.scene).resolve(), args.cache)
        chunks, size = clean_partials(partial)
        print(f"removed {chunks} resumable chunks ({size:,} bytes) from {partial}" if size
              else f"no resumable chunks in {partial}")
        return 0
    if args.jobs < 0:
        raise ConfigError(f"--jobs must be >= 0, got {args.jobs}")
    from piste.world.scene_file import load_scene

    scene = load_scene(args.scene)
    # an unwritable output or cache is reported now, not after minutes of building
    check_writable_folder(Path(args.out).parent if args.out else Path(args.scene).resolve().parent)
    if args.cache and not args.no_cache:
        check_writable_folder(args.cache)
    if scene.terrain.tiles is not None or args.dask or args.scheduler:
        from piste.pipeline.dask_build import build_scene_tiles

        r = build_scene_tiles(scene, out=args.out, dask=args.dask, scheduler=args.scheduler, workers=args.workers,
                              progress=not args.quiet and sys.stderr.isatty())
        print(r.summary())
        return 0
    r = build_scene(scene, out=args.out, cache_dir=args.cache, progress=not args.quiet and sys.stderr.isatty(),
                    jobs=args.jobs, use_cache=not args.no_cache)
    print(format_result(r))
    return 0


def format_result(r: BuildResult) -> str:
    """A short human report of a :class:`piste.pipeline.build.BuildResult`."""
    lines = [f"built {r.path} ({r.bytes / 1e6:.2f} MB) in {r.seconds:.2f} s"]
    for name, s in r.steps.items():
        if s.get("key") == "none":
            continue
        state = "cached" if s.get("cached") else "built"
        lines.append(f"  {name:<17} {state:<7} {s['seconds'] * 1e3:9.1f} ms")
    rep = r.report
    lines.append(f"  {rep.get('patches', 0)} patches, {rep.get('riders', 0)} riders, {rep.get('objects', 0)} objects, "
                 f"{rep.get('lights', 0)} lights, cameras: {', '.join(rep.get('cameras', []))}")
    vis = rep.get("visibility")
    if vis:
        for where in ("track", "cameras"):
            v = vis.get(where)
            if v:
                lines.append(f"  visibility ({where}, {v['frames']} views): frustum alone draws {v['frustum_pct']:.1f}% "
                             f"of the patches, with the visibility sets {v['visible_pct']:.1f}% "
                             f"({v['saved_pct']:.1f}% fewer)")
    return "\n".join(lines)
