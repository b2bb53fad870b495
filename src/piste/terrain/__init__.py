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

from piste.terrain.bezier import BEZIER_M, blend_tables, evaluate, eval_power_form
from piste.terrain.lod import edge_levels, visible_patches
from piste.terrain.net import PatchNet
from piste.terrain.stats import format_stats, stats
from piste.terrain.tessellate import TerrainMesh, decode_strips, get_shape, tessellate
from piste.terrain.fit import fit_error, fit_heightfield
from piste.terrain.query import PatchBVH, RayHits, height_at, ray_intersect
from piste.terrain.tiles import TileGrid, TileStore, fit_tile

__all__ = [
    "PatchNet", "TerrainMesh", "tessellate", "edge_levels", "visible_patches", "stats", "format_stats",
    "get_shape", "decode_strips",
    "BEZIER_M", "blend_tables", "evaluate", "eval_power_form",
    "fit_heightfield", "fit_error", "height_at", "ray_intersect", "RayHits", "PatchBVH",
    "TileGrid", "TileStore", "fit_tile",
]
