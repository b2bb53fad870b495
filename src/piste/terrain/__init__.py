"""Terrain: a curve net of bicubic Bézier patches with crack-free per-edge LOD.

Public API
----------
PatchNet            the net: control points (n, 4, 4, 3), corner UVs, light-map tiles, computed topology
tessellate          net + per-edge levels -> TerrainMesh (uniform and glue patches)
TerrainMesh         positions, normals, uv, uv_lightmap, uv_projected, indices (+ strips)
edge_levels         per-edge distance LOD (4, 6 or 8 vertices per edge)
stats               the talk's statistics table for a net and camera
fit_heightfield     least-squares C0 (or C1/C2) net from a height field
height_at           exact surface height at many (x, y)
ray_intersect       exact ray/net intersection (RayHits), PatchBVH reusable across calls
TileGrid, TileStore, fit_tile   tiled nets: per-tile fit with bit-identical tile edges, stored a tile at a time

The default course is :func:`piste.world.course.default_course` (the world layer builds on the
terrain, never the other way round).
"""

from typing import TYPE_CHECKING

from piste import _lazy_exports

# every name is imported when first asked for (PEP 562; tests/test_lazy_imports.py); ``stats`` and
# ``tessellate`` are also submodules' names and stay the functions (piste._LazyPackage)
__all__, __getattr__, __dir__ = _lazy_exports(__name__, {
    "net": ("PatchNet",),
    "tessellate": ("tessellate", "TerrainMesh", "get_shape", "decode_strips"),
    "lod": ("edge_levels", "visible_patches"),
    "stats": ("stats", "format_stats"),
    "bezier": ("BEZIER_M", "blend_tables", "evaluate", "eval_power_form"),
    "fit": ("fit_heightfield", "fit_error"),
    "query": ("height_at", "ray_intersect", "RayHits", "PatchBVH"),
    "heightfield": ("fit_control_points",),
    "tiles": ("TileGrid", "TileStore", "fit_tile"),
})

if TYPE_CHECKING:  # the same names, eagerly, for type checkers and the import graph
    from piste.terrain.bezier import BEZIER_M, blend_tables, evaluate, eval_power_form  # noqa: F401
    from piste.terrain.lod import edge_levels, visible_patches  # noqa: F401
    from piste.terrain.net import PatchNet  # noqa: F401
    from piste.terrain.stats import format_stats, stats  # noqa: F401
    from piste.terrain.tessellate import TerrainMesh, decode_strips, get_shape, tessellate  # noqa: F401
    from piste.terrain.fit import fit_error, fit_heightfield  # noqa: F401
    from piste.terrain.query import PatchBVH, RayHits, height_at, ray_intersect  # noqa: F401
    from piste.terrain.heightfield import fit_control_points  # noqa: F401
    from piste.terrain.tiles import TileGrid, TileStore, fit_tile  # noqa: F401
