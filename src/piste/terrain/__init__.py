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
from piste.terrain.net import PatchNet

__all__ = ["PatchNet", "BEZIER_M", "blend_tables", "evaluate", "eval_power_form"]
