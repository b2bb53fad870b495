"""Terrain: a curve net of bicubic Bézier patches with crack-free per-edge LOD.

Public API
----------
PatchNet            the net: control points (n, 4, 4, 3), corner UVs, light-map tiles, computed topology
tessellate          net + per-edge levels -> TerrainMesh (uniform and glue patches)
TerrainMesh         positions, normals, uv, uv_lightmap, uv_projected, indices (+ strips)
edge_levels         per-edge distance LOD (4, 6 or 8 vertices per edge)
stats               the talk's statistics table for a net and camera
default_course      the seeded default snowboard course
"""

from piste.terrain.bezier import BEZIER_M, blend_tables, evaluate, eval_power_form
from piste.terrain.lod import cull_boxes, edge_levels, look_at, perspective, visible_patches
from piste.terrain.net import PatchNet
from piste.terrain.stats import format_stats, stats
from piste.terrain.tessellate import TerrainMesh, decode_strips, get_shape, tessellate

__all__ = [
    "PatchNet", "TerrainMesh", "tessellate", "edge_levels", "visible_patches", "cull_boxes", "look_at",
    "perspective", "stats", "format_stats", "get_shape", "decode_strips",
    "BEZIER_M", "blend_tables", "evaluate", "eval_power_form",
]
