"""``piste export SOURCE OUT.glb``: any source (a scene .toml, built first with the cache, a bundle
.piste, an SSX level .pbd) to glTF.  This module only parses: the glue from the runtime scene to
glTF (units, what is written) is :mod:`piste.pipeline.bundle_gltf`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import argparse

#: names that moved to :mod:`piste.pipeline.bundle_gltf` (still importable from here)
_MOVED = ("WHITE_LUX", "INFINITE_RANGE_MATCH", "terrain_levels", "bundle_parts", "export_bundle")


def __getattr__(name: str) -> Any:
    if name in _MOVED:
        from piste.pipeline import bundle_gltf

        return getattr(bundle_gltf, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from piste.commands import _numbers as N

    parser.add_argument("scene", help="a scene (.toml), a bundle (.piste) or an SSX level (.pbd)")
    parser.add_argument("out", help="output .glb (one file) or .gltf (JSON + .bin)")
    parser.add_argument("--level", default="4",
                        help="terrain tessellation: 4, 6 or 8 vertices per edge, or camera:NAME for the per-edge LOD "
                             "that camera sees (default: 4)")
    parser.add_argument("--instancing", choices=("ext", "nodes"), default="ext",
                        help="objects as EXT_mesh_gpu_instancing nodes (ext, default) or one plain node per instance")
    parser.add_argument("--no-base-texture", action="store_true", help="leave out the terrain's snow texture")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.add_argument("--riders", type=N.integer(0, 64), default=0, metavar="N",
                        help="stand N default riders on the terrain of a source without riders of its own (an SSX level)")
    parser.add_argument("--add-objects", type=N.integer(0, 10_000), default=0, metavar="N",
                        help="place N of the course's objects (trees, rocks, signs, rails) on the terrain of a source "
                             "without objects of its own (an SSX level, a tiled world)")


def run(args: argparse.Namespace) -> int:
    from piste.errors import ConfigError
    from piste.pipeline.bundle_gltf import export_bundle
    from piste.pipeline.open_scene import open_source, source_kind

    if source_kind(args.scene) == "tiles":
        raise ConfigError(f"{args.scene}: a tiled world is streamed tile by tile; export a scene, a bundle or an "
                          "SSX level (a whole world in one glTF file is not supported)")
    b = open_source(args.scene, quiet=args.quiet, riders=args.riders, objects=args.add_objects)
    r = export_bundle(b, args.out, level=args.level, instancing=args.instancing,
                      with_base_texture=not args.no_base_texture)
    print(f"wrote {', '.join(str(f) for f in r.files)} ({r.bytes / 1e6:.2f} MB): terrain {r.terrain_triangles:,} triangles, "
          f"{r.characters} riders ({r.animations} clips), {r.objects} objects"
          + (f" ({r.baked_objects} baked)" if r.baked_objects else "")
          + f", {r.lights} lights, {r.cameras} cameras")
    return 0
