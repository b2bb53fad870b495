"""Streaming a tiled world at run time: tiles paged in and out by camera distance under a fixed
memory budget, loaded by a background thread, with coarse far-field stand-ins so the horizon never
shows holes.

Levels of a tile
----------------
Every level is drawn like the course's terrain (``terrain.frag.glsl``, modulate): the base snow
texture times the tile's light map, a texture of its baked texels welded across patches
(:func:`light_grid`, sampled bilinearly like the course's atlas), fogged per vertex as a bundle of
the same terrain is.  The geometry differs by level:

* **far** (resident for every tile): the tile's patch-corner grid from the build (``lit/*.npz``
  ``far_positions``; one vertex a patch corner) at corner strides 1, 2, 4 and 8.  Corners are exact
  surface points and bit-identical between neighbouring tiles, so far tiles meet without cracks.
* **middle** (paged): every patch evaluated 3 samples a side (``MID_SAMPLES``).
* **near** (paged): every patch evaluated ``max(res, 4)`` samples a side (``NEAR_SAMPLES``).

A tile's level follows its error on screen: the build measures how far each tile's patches leave
the corner grid and the middle level (``far_error``, :func:`piste.pipeline.tiled_build.far_errors`);
a tile is drawn at the coarsest level whose error projects to at most ``pixel_error`` pixels
(``FAR_PIXEL_ERROR``), nearest tiles first under the budget (and near within ``near_radius``).
Within a tile the level follows each patch's error, as on the course (:mod:`piste.terrain.lod`'s
per-patch errors, :func:`patch_level_errors`).  Near and middle meshes geomorph per vertex: each
vertex carries its heights on the middle level and on the corner grid and the largest errors of the
patches around it (:func:`vertex_errors`), and is drawn corner grid -> middle -> its own by those
errors on screen, fully on the coarser level where they fit ``pixel_error`` pixels, so nothing pops
where a tile or a patch changes level.  A near or middle tile is drawn by patch: patches out of the
frustum (or the visibility sets) are left out, patches all of whose vertices are fully on the
corner grid (:func:`patch_corner_errors` under ``pixel_error`` at the patch's box) come from the
tile's corner grid, the rest from the mesh, each mesh's runs of patches in one indirect multi-draw
(:func:`patch_runs`, patches in :func:`patch_order`); a mesh patch beside a corner-grid patch is
glued to its edge (:func:`glue_indices`: the side's inner vertices collapsed onto its corners, as
the course's glue patches zip to a flat neighbour), so they share the edge, not a T-junction.

A far tile is drawn by block of ``FAR_BLOCK`` x ``FAR_BLOCK`` patches, each at the coarsest stride
whose error fits the renderer's ``pixel_error`` pixels at the block (``FAR_PIXEL_ERROR`` by default;
:meth:`TileCache.block_strides`, :attr:`StreamingRenderer.far_pixel_error`), blocks
out of the frustum left out; where a block meets a coarser one (in its tile or across the border of
another far tile) it draws its zipper to it, a fan from the coarser side's vertices over its own
edge that fills the gap between the two exactly (:func:`far_mesh`, :func:`block_runs`).  Near,
middle and full-corner-grid tiles draw through the build's visibility sets of the tile under the
eye, which say what eyes over it see of its own patches and of its eight neighbours'
(:class:`TileSets`), while every tile of theirs in view is drawn at a level their occluders were
lowered to (:meth:`TileCache.sets_hold`).  Tiles are drawn with back faces culled.

Where a near tile meets a far one, the near tile's border follows the patch edge curves and the
far tile's border their chords.  Both lie in the same vertical plane (patch edges are straight in
x, y), so every tile gets a **skirt**: a strip hanging ``zmax - zmin + 1`` metres down from its
border (the curve and its chord both lie inside the tile's height range), facing out of it.
Whichever border is higher, its skirt closes the gap, seen from the lower side; skirts are hidden
under the terrain everywhere else.

Paging
------
:class:`TileCache` (no OpenGL; testable alone) keeps every far tile within the view distance
(loaded up front at corner strides 1, 2, 4 and 8 with its light map) and chooses the paged
levels (:meth:`TileCache.update`) while their bytes fit ``budget_bytes``; a loader thread builds
the meshes, the renderer uploads finished ones and releases evicted ones.  ``resident_bytes``
(far + paged meshes and light maps, the CPU copies; the GPU holds the same arrays) never exceeds
the budget.

Scene objects (a world built with object rules, :mod:`piste.pipeline.tile_objects`) page by their
own distance, not with the terrain's level: a tile's objects are resident while the tallest of them
would stand at least ``OBJECT_MIN_PIXELS`` tall at the tile's nearest point (and before the fog has
swallowed them and the far plane cut them off), so trees do not stop where the terrain switches to
far stand-ins; the object pass draws the far ones at the coarsest level of their LOD chains
(:mod:`piste.world.object_lod`: their error is far below a pixel there).  Their bytes (what the
cache reads and what the object set and pass derive per instance, :func:`object_instance_bytes`)
count in ``resident_bytes`` and the budget: terrain and objects are reserved together, nearest tile
first, a tile's mesh before its objects.

:class:`StreamingRenderer` draws a frame: far tiles not covered by a resident near tile, near
tiles, frustum-culled per tile, fogged like the course (and faded out over the last fifth of
the far plane), the sky gradient behind.
:class:`StreamingTerrain` is the same renderer as the runtime's terrain (the interface of
:class:`piste.render.frame.TerrainRenderer`): ``piste render|view WORLD.tiles`` draw through
:class:`piste.pipeline.preview.ScenePreview` with riders, objects and shadows like any scene
(:mod:`piste.pipeline.tiles_source`).  :func:`fly_path` is a straight flight across the world.
"""

from __future__ import annotations

import functools
import logging
import math
import queue
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from piste.errors import ConfigError, FormatError
from piste.render.block_errors import block_stride_errors, corner_stride_errors
from piste.render.context import Offscreen, create_context, save_png
from piste.render.frame import DEFAULT_FOG_DENSITY, FOG_REFERENCE_SIZE, Frame
from piste.render.sky_pass import HORIZON, SkyPass
from piste.render.terrain_mode import TerrainMode
from piste.render.textures import mipmapped_texture, snow_texture
from piste.render.video import VideoWriter
from piste.terrain.bezier import evaluate, grid_params
from piste.terrain.cull import patch_tree
from piste.terrain.lod import FLAT_LEVEL, patch_error_table
from piste.terrain.net import PatchNet
from piste.terrain.tessellate import tessellate
from piste.terrain.tiles import (MAX_TILE_OBJECTS, TileError, TileGrid, TileStore, read_tile_objects, tile_entries,
                                 triangulated_heights)
from piste.transforms import frustum_planes
from piste.world.camera import Camera
from piste.world.objects import OBJECT_KINDS, make_mesh

if TYPE_CHECKING:
    import os

    import numpy.typing as npt

    from piste.terrain.tessellate import TerrainMesh

__all__ = ["TileCache", "StreamingRenderer", "StreamingTerrain", "TileMesh", "near_mesh", "far_mesh", "mesh_bytes", "fly_path",
           "render_flight", "TileSets", "light_grid", "stride_errors", "chord_error", "visible_indices", "world_fog_density",
           "object_instance_bytes", "object_kind_heights", "OBJECT_MIN_PIXELS", "patch_order", "patch_level_errors",
           "vertex_errors", "glue_indices", "far_blocks", "block_runs", "patch_runs", "entry_runs", "FAR_BLOCK",
           "LOD_REFERENCE_LINES", "command_indices", "window_net"]

_log = logging.getLogger(__name__)

SKY = (0.80, 0.86, 0.93)
#: corner strides of the far levels (every tile keeps all of them: 1 + 1/4 + 1/16 + 1/64 of the grid)
FAR_STRIDES = (1, 2, 4, 8)

#: patches a side of the blocks a far tile draws each at its own stride (the coarsest stride's cell)
FAR_BLOCK = FAR_STRIDES[-1]
#: far levels are chosen so that a level's height error (against the full corner grid) stays
#: under this many pixels on screen
FAR_PIXEL_ERROR = 3.0
#: pixel errors are counted in pixels of a frame at least this many lines tall (the PS2's): a smaller
#: target gets the same error as an angle, as the course's LOD thresholds are angles
#: (:data:`piste.terrain.lod.FLAT_ERROR`: 0.5 px at 640 x 448), a taller one ``pixel_error`` of its own pixels
LOD_REFERENCE_LINES = 448
#: near meshes evaluate every patch at least this many samples a side (the course's LOD beyond 180 m)
NEAR_SAMPLES = 4
#: samples a patch side of the middle level: evaluated patches (a centre and edge midpoints: a
#: quarter of the corner grid's chord error) for tiles too far for near meshes but whose
#: corner grid would show, about a sixth of a near mesh's bytes at res 8
MID_SAMPLES = 3
#: a tile's scene objects stay paged in while its tallest one would be at least this many pixels
#: tall at the tile's nearest point (:meth:`TileCache.object_distances`)
OBJECT_MIN_PIXELS = 1.5
#: ... and while the fog leaves at least this fraction of an object's own colour (1 grey level)
OBJECT_FOG_FLOOR = 1.0 / 255.0

# The tiles are drawn like the course's terrain (terrain.frag.glsl, modulate mode): the base
# texture (repeated once a patch) times the light map, fogged per vertex.  A heightfield patch is
# linear in x and y, so both texture coordinates are affine in the world position: per tile,
# base uv = (p.xy - origin) / patch size and the light texel = (p.xy - origin) / patch size
# (res - 1) + 0.5 in the tile's welded light grid (:func:`light_grid`): near and far levels of a
# tile sample the same light, bilinearly like the course's atlas.
_VERT = """#version 330
uniform mat4 u_vp;
uniform vec3 u_eye;
uniform vec4 u_fog;        // rgb, density per metre
uniform vec2 u_fade;       // linear fade to the fog colour between these distances (metres)
uniform vec2 u_origin;     // the tile's (x0, y0)
uniform vec2 u_patch;      // 1 / patch size (x, y)
uniform vec4 u_light_uv;   // (res - 1) / width, (res - 1) / height, 0.5 / width, 0.5 / height
uniform float u_morph;     // geomorph: 1 the mesh's own heights, 0 its coarser level's (in_target)
uniform float u_verr;      // > 0: the geomorph per vertex instead, by the vertex's errors (pixels a metre of error at 1 m over the limit)
in vec3 in_pos;
in float in_target;        // the next coarser level's height here (a near mesh: the middle level's; a middle one: the corner grid's)
in float in_corner;        // the corner grid's height here
in vec2 in_err;            // the corner grid's and the middle level's errors (metres) of the patches around the vertex
out vec2 v_uv;
out vec2 v_uvl;
out float v_fog;
void main() {
    float z = in_target + u_morph * (in_pos.z - in_target);
    if (u_verr > 0.0) {  // each level's error in pixels at this vertex (its corner-grid position), over the limit
        float dc = max(distance(vec3(in_pos.xy, in_corner), u_eye), 1e-6);
        float m1 = clamp(in_err.x * u_verr / dc - 1.0, 0.0, 1.0);  // corner grid -> middle level
        float m2 = clamp(in_err.y * u_verr / dc - 1.0, 0.0, 1.0);  // middle level -> the mesh's own
        float hm = in_corner + m1 * (in_target - in_corner);
        z = hm + m2 * (in_pos.z - hm);
    }
    vec3 p = vec3(in_pos.xy, z);
    gl_Position = u_vp * vec4(p, 1.0);
    vec2 q = (p.xy - u_origin) * u_patch;   // patch units from the tile's corner
    v_uv = q;
    v_uvl = q * u_light_uv.xy + u_light_uv.zw;
    float d = distance(p, u_eye);
    float f = u_fog.a > 0.0 ? 1.0 - exp(-u_fog.a * d) : 0.0;
    v_fog = max(f, clamp((d - u_fade.x) / max(u_fade.y - u_fade.x, 1.0), 0.0, 1.0));
}
"""
_FRAG = """#version 330
uniform sampler2D u_base;
uniform sampler2D u_light;
uniform vec4 u_fog;
in vec2 v_uv;
in vec2 v_uvl;
in float v_fog;
out vec4 f_color;
void main() {
    vec3 c = texture(u_base, v_uv).rgb * texture(u_light, v_uvl).rgb * (255.0 / 128.0);  // half-bright texels
    f_color = vec4(mix(c, u_fog.rgb, v_fog), 1.0);
}
"""


@dataclass
class TileMesh:
    """A tile's triangles: positions ``(k, 3)`` float32, colours ``(k, 3)`` uint8 (half-bright),
    indices ``(t, 3)`` uint32; ``patch_triangles``: the first ``n * patch_triangles`` triangles
    are patch-major (the ``j``-th patch of :func:`patch_order`'s at ``[j pt, (j+1) pt)``, the skirts
    after them; 0: not ordered);
    ``targets`` ``(k,)`` float32 or None: each vertex's height on the next coarser level (geomorph);
    with them (near and middle meshes, :func:`near_mesh`) ``corner`` ``(k,)`` float32: its height on the
    corner grid, ``errors`` ``(k, 2)`` float32: the largest corner-grid and middle-level errors
    (metres) of the patches around it (what its per-vertex geomorph follows: :func:`vertex_errors`)."""

    positions: np.ndarray
    colors: np.ndarray
    indices: np.ndarray
    patch_triangles: int = 0
    targets: np.ndarray | None = None
    corner: np.ndarray | None = None
    errors: np.ndarray | None = None
    #: a far mesh's blocks (:func:`far_mesh`), or None
    blocks: dict | None = None
    #: the triangles of the mesh drawn whole (the first ``whole``: a far mesh's cells and tile skirts,
    #: its block skirts and zippers after them); None: all
    whole: int | None = None

    @property
    def whole_triangles(self) -> int:
        """Triangles of the mesh drawn whole (:attr:`whole`)."""
        return len(self.indices) if self.whole is None else int(self.whole)

    @property
    def nbytes(self) -> int:
        extra = sum(a.nbytes for a in (self.targets, self.corner, self.errors) if a is not None)
        return self.positions.nbytes + self.colors.nbytes + self.indices.nbytes + extra


def _grid_triangles(rows: int, cols: int, offset: int = 0) -> np.ndarray:
    """Two triangles a cell of a ``rows x cols`` vertex grid (row-major), ``(2 (r-1)(c-1), 3)``."""
    r, c = np.mgrid[0:rows - 1, 0:cols - 1]
    a = (r * cols + c).ravel() + offset
    return np.concatenate([np.stack([a, a + 1, a + cols + 1], 1), np.stack([a, a + cols + 1, a + cols], 1)])


def _skirt(border: np.ndarray, colors: np.ndarray, depth: float, offset: int):
    """A strip hanging ``depth`` down from a border polyline ``(m, 3)``: vertices, colours, triangles."""
    low = border.copy()
    low[:, 2] -= depth
    m = len(border)
    i = np.arange(m - 1) + offset
    tris = np.concatenate([np.stack([i, i + 1, i + m + 1], 1), np.stack([i, i + m + 1, i + m], 1)])
    return np.concatenate([border, low]), np.concatenate([colors, colors]), tris


def _with_skirts(pos: np.ndarray, rgb: np.ndarray, tris: np.ndarray, sides: list, depth: float) -> TileMesh:
    """``pos (k, 3)``, ``rgb (k, 3)`` plus a skirt under each border polyline (index arrays in ``sides``)."""
    ps, cs, ts = [pos], [rgb], [tris]
    n = len(pos)
    for idx in sides:
        p, c, t = _skirt(pos[idx], rgb[idx], depth, n)
        ps.append(p)
        cs.append(c)
        ts.append(t)
        n += len(p)
    return TileMesh(np.concatenate(ps).astype(np.float32), np.concatenate(cs).astype(np.uint8),
                    np.concatenate(ts).astype(np.uint32))


def _border_sides(idx: np.ndarray) -> list:
    """The four border polylines of a ``(rows, cols)`` grid of vertex indices (row = y, column = x),
    each ordered so that its skirt (:func:`_skirt`) faces out of the tile (counter-clockwise seen
    from outside): the frames draw with back faces culled, and a gap at a tile border shows only
    from the side of the lower border, where the higher one's skirt hangs facing it."""
    return [idx[0][::-1], idx[:, -1][::-1], idx[-1], idx[:, 0]]


@functools.lru_cache(maxsize=64)
def patch_order(ny: int, nx: int) -> np.ndarray:
    """The order patch-major meshes (:func:`near_mesh`, :func:`far_mesh` at stride 1) hold the
    patches of a ``(ny, nx)`` tile in, and far meshes their blocks: Z (Morton) order of (row,
    column), so that a region of patches chosen by distance or by the frustum is few runs of
    consecutive patches (:func:`patch_runs`: one indirect draw command a run).  ``(n,)`` int64 patch
    ids (``row * nx + col``) in mesh order, read-only."""

    def spread(v: np.ndarray) -> np.ndarray:  # the bits of v (< 2^16) to the even bits
        v = v.astype(np.uint64)
        for shift, mask in ((8, 0x00FF00FF), (4, 0x0F0F0F0F), (2, 0x33333333), (1, 0x55555555)):
            v = (v | (v << np.uint64(shift))) & np.uint64(mask)
        return v

    py, px = np.mgrid[0:int(ny), 0:int(nx)]
    out = np.argsort((spread(py) << np.uint64(1) | spread(px)).reshape(-1), kind="stable")
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=64)
def _patch_rank(ny: int, nx: int) -> np.ndarray:
    """Where each patch (row-major id) comes in :func:`patch_order`: ``(n,)`` int64, read-only."""
    order = patch_order(ny, nx)
    rank = np.empty(ny * nx, np.int64)
    rank[order] = np.arange(ny * nx)
    rank.flags.writeable = False
    return rank


def _stride_index(n: int, stride: int) -> np.ndarray:
    """``0, stride, 2 stride, ...`` and always the last of ``n``."""
    i = np.arange(0, n, stride)
    return i if i[-1] == n - 1 else np.append(i, n - 1)


def far_mesh(lit: dict, depth: float, stride: int = 1) -> TileMesh:
    """The far stand-in of a tile: its corner grid ``(ny+1, nx+1)`` (every ``stride``-th corner, the
    border rows always kept) plus skirts.  At stride 1 (a cell a patch) the triangles are
    patch-major (``patch_triangles`` 2: visibility sets cull it per patch like a near mesh); at
    coarser strides block-major.

    Blocks of ``FAR_BLOCK`` x ``FAR_BLOCK`` patches are drawn each at its own stride
    (:meth:`TileCache.block_strides`): every block side has a zipper to each coarser stride (the fan
    from the coarse side's vertices over this side's: it fills the gap between the two exactly,
    drawn two-sided), and the sides on the tile's border a skirt (hanging ``depth``, facing out of
    the tile) for neighbours that are not far blocks (:func:`block_runs`).  The patches (stride 1)
    and blocks are in :func:`patch_order`.  ``blocks`` (first triangle and triangles of each entry):
    ``{"cell_first", "cell_count": (nb,)`` each block's cells (coarser strides), ``"block_order"``
    the blocks in mesh order, ``"skirt_first", "skirt_count": (nb, 4)`` each block side's skirt
    (sides south, east, north, west; block ``row * bx + col``), ``"skirt_order" (4 nb,)`` the
    sides in mesh order (side by side, along the tile: its border is four runs)}``."""
    g = np.asarray(lit["far_positions"], dtype=np.float64)
    c = np.asarray(lit["far_colors"])
    rows0, cols0 = g.shape[:2]
    ri, ci = _stride_index(rows0, stride), _stride_index(cols0, stride)
    g, c = g[ri][:, ci], c[ri][:, ci]
    rows, cols = g.shape[:2]
    idx = np.arange(rows * cols).reshape(rows, cols)
    tris = _grid_triangles(rows, cols)
    cells = (rows - 1) * (cols - 1)
    by, bx = -(-(rows0 - 1) // FAR_BLOCK), -(-(cols0 - 1) // FAR_BLOCK)
    nb = by * bx
    cell_block = ((ri[:-1] // FAR_BLOCK)[:, None] * bx + (ci[:-1] // FAR_BLOCK)[None, :]).ravel()
    border = patch_order(by, bx)  # the blocks in mesh order
    if stride == 1:  # cell k's two triangles are k and k + cells: together, in patch order
        tris = tris.reshape(2, cells, 3).transpose(1, 0, 2)[patch_order(rows - 1, cols - 1)].reshape(-1, 3)
    else:  # block by block
        rank = np.empty(nb, np.int64)
        rank[border] = np.arange(nb)
        tris = tris[np.argsort(rank[np.concatenate([cell_block, cell_block])], kind="stable")]
    ccount = 2 * np.bincount(cell_block, minlength=nb)
    cfirst = np.empty(nb, np.int64)
    cfirst[border] = np.concatenate([[0], np.cumsum(ccount[border])[:-1]])
    # the block lines (every FAR_BLOCK-th corner and the last) among the strided rows and columns
    lr = np.nonzero((ri % FAR_BLOCK == 0) | (ri == rows0 - 1))[0]
    lc = np.nonzero((ci % FAR_BLOCK == 0) | (ci == cols0 - 1))[0]
    n = rows * cols
    low_r = n + np.arange(2 * cols).reshape(2, cols)  # a lowered copy of each border vertex: rows 0 and last
    low_c = n + 2 * cols + np.arange(2 * rows).reshape(2, rows)  # columns 0 and last
    pos = np.concatenate([g.reshape(-1, 3), g[[0, -1]].reshape(-1, 3), g[:, [0, -1]].transpose(1, 0, 2).reshape(-1, 3)])
    pos[n:, 2] -= depth
    col = np.concatenate([c.reshape(-1, 3), c[[0, -1]].reshape(-1, 3), c[:, [0, -1]].transpose(1, 0, 2).reshape(-1, 3)])
    segs, keys = [], []

    def strip(top, low, key, forward: bool) -> None:  # the segments of polylines (k, m) top and low
        ta, tb, la, lb = top[:, :-1], top[:, 1:], low[:, :-1], low[:, 1:]
        if not forward:
            ta, tb, la, lb = tb, ta, lb, la
        segs.append(np.stack([np.stack([ta, tb, lb], -1), np.stack([ta, lb, la], -1)], -2).reshape(-1, 2, 3))
        keys.append(key.reshape(-1))

    bcol = (ci[:-1] // FAR_BLOCK)[None, :]  # the block column of each segment along a row line
    brow = (ri[:-1] // FAR_BLOCK)[None, :]
    # skirts under the tile's border only (inside a tile, blocks meet blocks: zippers)
    strip(idx[[0]], low_r[[0]], bcol * 4 + 0, False)  # the south side of the first row of blocks
    strip(idx[[-1]], low_r[[1]], ((by - 1) * bx + bcol) * 4 + 2, True)  # the north side of the last
    strip(idx[:, [0]].T, low_c[[0]], (brow * bx) * 4 + 3, True)  # the west side of the first column
    strip(idx[:, [-1]].T, low_c[[1]], (brow * bx + bx - 1) * 4 + 1, False)  # the east side of the last
    seg, key = np.concatenate(segs), np.concatenate(keys)
    # the skirts side by side, each side's blocks along it (rows for south and north, columns for
    # east and west): a tile's border is four runs
    entry = np.arange(nb * 4)
    br, bc, side = entry // 4 // bx, entry // 4 % bx, entry % 4
    along = np.where(side % 2 == 0, br * bx + bc, bc * by + br)
    inner = ~(((side == 0) & (br == 0)) | ((side == 2) & (br == by - 1)) | ((side == 1) & (bc == bx - 1))
              | ((side == 3) & (bc == 0)))  # the tile's border first: a whole tile is its cells and border skirts
    sorder = np.argsort(inner * 4 * nb + side * nb + along, kind="stable")  # the (block, side) entries in mesh order
    srank = np.empty(nb * 4, np.int64)
    srank[sorder] = entry
    seg = seg[np.argsort(srank[key], kind="stable")].reshape(-1, 3)
    count = 2 * np.bincount(key, minlength=nb * 4)
    sfirst = np.empty(nb * 4, np.int64)
    sfirst[sorder] = 2 * cells + np.concatenate([[0], np.cumsum(count[sorder])[:-1]])
    # zippers: where a block side meets a coarser block (stride k), the fan from each of the coarse
    # side's vertices over this side's vertices up to the next one (drawn two-sided): it fills the
    # gap between the two in their vertical plane exactly, with this mesh's own edge vertices
    zips, zkeys = [], []
    for kidx, k in enumerate(FAR_STRIDES):
        if k <= stride:
            continue
        for line, corner, last, along, nlines, side_lo, side_hi in (
                (idx[lr], ci, cols0 - 1, bcol[0], len(lr), 0, 2), (idx[:, lc].T, ri, rows0 - 1, brow[0], len(lc), 3, 1)):
            coarse = (corner % k == 0) | (corner == last)
            a = np.maximum.accumulate(np.where(coarse, np.arange(len(corner)), 0))
            ps = np.nonzero(~coarse[:-1])[0]  # the segments that do not start at a coarse vertex
            if not len(ps):
                continue
            fan = np.stack([line[:, a[ps]], line[:, ps], line[:, ps + 1]], -1)  # (lines, s, 3)
            ln = np.arange(nlines)[:, None]
            blk_lo = (ln * bx + along[ps][None, :]) if side_lo != 3 else (along[ps][None, :] * bx + ln)
            blk_hi = ((ln - 1) * bx + along[ps][None, :]) if side_lo != 3 else (along[ps][None, :] * bx + ln - 1)
            for blk, side, ok in ((blk_lo, side_lo, ln < nlines - 1), (blk_hi, side_hi, ln > 0)):
                sel = np.broadcast_to(ok, blk.shape)
                zips.append(fan[sel])
                zkeys.append(((blk[sel] * 4 + side) * 4 + kidx))
    zip_tris = np.concatenate(zips).reshape(-1, 3) if zips else np.zeros((0, 3), np.int64)
    zkey = np.concatenate(zkeys) if zkeys else np.zeros(0, np.int64)
    zorder = np.argsort(zkey, kind="stable")
    zip_tris = zip_tris[zorder]
    zcount = np.bincount(zkey, minlength=nb * 16)
    zfirst = 2 * cells + len(seg) + np.concatenate([[0], np.cumsum(zcount)[:-1]])
    mesh = TileMesh(pos.astype(np.float32), col.astype(np.uint8),
                    np.concatenate([tris, seg, zip_tris]).astype(np.uint32))
    mesh.patch_triangles = 2 if stride == 1 else 0
    mesh.whole = 2 * cells + int(count[~inner].sum())
    mesh.blocks = {"cell_first": cfirst, "cell_count": ccount, "block_order": border,
                   "skirt_first": sfirst.reshape(-1, 4), "skirt_count": count.reshape(-1, 4), "skirt_order": sorder,
                   "zip_first": zfirst.reshape(-1, 4, 4), "zip_count": zcount.reshape(-1, 4, 4)}
    return mesh


def light_grid(texels: np.ndarray, grid_shape: tuple) -> np.ndarray:
    """A tile's light map welded into one image: ``texels (n, res, res, 3)`` uint8 (patch
    ``row * nx + col``, ``[patch, j (v), i (u)]``) -> ``(ny (res-1) + 1, nx (res-1) + 1, 3)`` uint8,
    row = y.  Neighbouring patches' border texels are equal (the bake welds them), so bilinear
    sampling of this image at ``(x - x0) / patch (res - 1) + 0.5`` texels is the course's atlas
    sampled at the same surface point."""
    t = np.asarray(texels)
    n, res = t.shape[:2]
    ny, nx = grid_shape
    if n != ny * nx:
        raise ValueError(f"light_grid: {n} patches for a {ny} x {nx} tile")
    r = res - 1
    out = np.empty((ny * r + 1, nx * r + 1, 3), np.uint8)
    t = t.reshape(ny, nx, res, res, 3)
    for j in range(res):  # a shared texel takes the value of the last patch written
        for i in range(res):
            out[j:j + ny * r:r, i:i + nx * r:r] = t[:, :, j, i]
    return out


def stride_errors(far_positions: np.ndarray) -> dict:
    """Height error of each far level: ``{stride: metres}``, the largest vertical distance between
    the full corner grid ``(ny+1, nx+1, 3)`` and the level's grid interpolated bilinearly."""
    return {k: float(e.max()) for k, e in stride_error_grids(far_positions).items()}


def stride_error_grids(far_positions: np.ndarray) -> dict:
    """:func:`stride_errors` at every corner: ``{stride: (ny+1, nx+1) float64 metres}``."""
    g = np.asarray(far_positions, dtype=np.float64)[..., 2]
    out = {}
    for k in FAR_STRIDES:
        ri, ci = _stride_index(g.shape[0], k), _stride_index(g.shape[1], k)
        b = _lerp_matrix(g.shape[0], ri) @ g[ri][:, ci] @ _lerp_matrix(g.shape[1], ci).T  # (rows, cols)
        out[k] = np.abs(b - g)
    return out


def _lerp_matrix(n: int, at: np.ndarray) -> np.ndarray:
    """``(n, len(at))``: linear interpolation at ``0 .. n-1`` between the samples at the sorted
    indices ``at`` (``np.interp``'s, as one matrix)."""
    x = np.arange(n, dtype=np.float64)
    j = np.clip(np.searchsorted(at, x, side="right") - 1, 0, max(len(at) - 2, 0))
    w = np.zeros((n, len(at)))
    if len(at) == 1:
        w[:, 0] = 1.0
        return w
    f = np.clip((x - at[j]) / (at[j + 1] - at[j]), 0.0, 1.0)
    w[np.arange(n), j] = 1.0 - f
    w[np.arange(n), j + 1] += f
    return w


def _block_reduce(grid: np.ndarray, op) -> np.ndarray:
    """``op`` (np.minimum or np.maximum) over the corners of each far block (:data:`FAR_BLOCK`
    patches a side, both border lines included) of a corner grid ``(ny+1, nx+1)``: ``(by, bx)``."""
    out = np.asarray(grid)
    for axis in (0, 1):
        n = out.shape[axis]
        s = np.arange(0, n - 1, FAR_BLOCK)
        e = np.minimum(s + FAR_BLOCK, n - 1)
        out = op(op.reduceat(out, s, axis=axis), np.take(out, e, axis=axis))
    return out


def far_blocks(far_positions: np.ndarray, depth: float) -> dict:
    """The far blocks of a tile (:func:`far_mesh`, :data:`FAR_BLOCK` patches a side) from its corner
    grid ``(ny+1, nx+1, 3)``: ``lo, hi (nb, 3)`` their boxes (skirts included, ``depth`` metres
    below) and ``patches (nb,)``, block ``row * bx + col``.  Their stride errors are measured apart
    (:func:`piste.render.block_errors.corner_stride_errors` at load,
    :func:`piste.render.block_errors.block_stride_errors` by the loader: :class:`TileCache`)."""
    g = np.asarray(far_positions, dtype=np.float64)
    z = g[..., 2]
    rows, cols = z.shape
    rs, cs = np.arange(0, rows - 1, FAR_BLOCK), np.arange(0, cols - 1, FAR_BLOCK)
    re, ce = np.minimum(rs + FAR_BLOCK, rows - 1), np.minimum(cs + FAR_BLOCK, cols - 1)
    x0, x1 = g[0, cs, 0][None, :], g[0, ce, 0][None, :]
    y0, y1 = g[rs, 0, 1][:, None], g[re, 0, 1][:, None]
    shape = (len(rs), len(cs))
    lo = np.stack([np.broadcast_to(x0, shape), np.broadcast_to(y0, shape), _block_reduce(z, np.minimum) - depth], -1)
    hi = np.stack([np.broadcast_to(x1, shape), np.broadcast_to(y1, shape), _block_reduce(z, np.maximum)], -1)
    return {"lo": lo.reshape(-1, 3), "hi": hi.reshape(-1, 3), "patches": ((re - rs)[:, None] * (ce - cs)[None, :]).reshape(-1)}


def chord_error(far_positions: np.ndarray) -> float:
    """An estimate of how far a tile's patches leave the chords of its corner grid ``(ny+1, nx+1,
    3)``: a quarter of the largest second difference of the corner heights along x or y (a
    parabola through three corners leaves its chords by an eighth of it: twice that for safety),
    metres.  Tiles where this would show on screen are drawn near (evaluated patches)."""
    z = np.asarray(far_positions, dtype=np.float64)[..., 2]
    m = 0.0
    if z.shape[0] >= 3:
        m = max(m, float(np.abs(z[2:] - 2.0 * z[1:-1] + z[:-2]).max()))
    if z.shape[1] >= 3:
        m = max(m, float(np.abs(z[:, 2:] - 2.0 * z[:, 1:-1] + z[:, :-2]).max()))
    return m / 4.0


def _bilinear(img: np.ndarray, y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``img (h, w, c)`` at fractional pixel rows ``y (rows,)`` and columns ``x (cols,)``:
    ``(rows, cols, c)`` float64."""
    h, w = img.shape[:2]
    y0 = np.clip(np.floor(y).astype(int), 0, h - 2) if h > 1 else np.zeros(len(y), int)
    x0 = np.clip(np.floor(x).astype(int), 0, w - 2) if w > 1 else np.zeros(len(x), int)
    fy = (y - y0)[:, None, None] if h > 1 else np.zeros((len(y), 1, 1))
    fx = (x - x0)[None, :, None] if w > 1 else np.zeros((1, len(x), 1))
    y1, x1 = np.minimum(y0 + 1, h - 1), np.minimum(x0 + 1, w - 1)
    a = img.astype(np.float64)
    top = a[y0][:, x0] * (1 - fx) + a[y0][:, x1] * fx
    bot = a[y1][:, x0] * (1 - fx) + a[y1][:, x1] * fx
    return top * (1 - fy) + bot * fy


class _Patches:
    """Control points ``(n, 4, 4, 3)`` as the net :func:`piste.terrain.lod.patch_error_table` reads."""

    def __init__(self, control_points: np.ndarray):
        self.control_points = control_points

    def __len__(self) -> int:
        return len(self.control_points)


def patch_level_errors(control_points: np.ndarray) -> np.ndarray:
    """Per patch ``(n, 4, 4, 3)``, how far the surface leaves its corner quad and its middle-level
    mesh (3 samples a side), both split along the (0, 0)-(1, 1) diagonal as the streamed meshes
    are: ``(n, 2)`` float64 metres (:func:`piste.terrain.lod.patch_error_table`, the course's
    per-patch LOD errors; on a height field the distance at the same ``(u, v)`` is vertical)."""
    cp = np.asarray(control_points, dtype=np.float64)
    return patch_error_table(_Patches(cp), (FLAT_LEVEL, MID_SAMPLES)) if len(cp) else np.zeros((0, 2))


def vertex_errors(patch_errors: np.ndarray, grid_shape: tuple, r: int) -> np.ndarray:
    """Per vertex of a welded tile grid of ``r`` cells a patch side (``(ny r + 1, nx r + 1)``), the
    largest of ``patch_errors (ny nx, c)`` over the (up to four) patches it belongs to: ``(ny r + 1,
    nx r + 1, c)``.  A vertex on a patch edge carries the same values in both patches, so its
    geomorph is the same whichever patch draws it (no cracks inside a tile)."""
    ny, nx = (int(x) for x in grid_shape)
    e = np.asarray(patch_errors).reshape(ny, nx, -1)
    j, i = np.arange(ny * r + 1), np.arange(nx * r + 1)
    a0, a1 = np.clip((j - 1) // r, 0, ny - 1), np.clip(j // r, 0, ny - 1)
    b0, b1 = np.clip((i - 1) // r, 0, nx - 1), np.clip(i // r, 0, nx - 1)
    return np.maximum(np.maximum(e[a0][:, b0], e[a0][:, b1]), np.maximum(e[a1][:, b0], e[a1][:, b1]))


def near_mesh(fit: dict, lit: dict, grid_shape: tuple, depth: float, samples: int | None = None,
              max_errors: tuple[float, float] | None = None) -> TileMesh:
    """The near mesh of a tile: every patch evaluated on a ``samples x samples`` parameter grid
    (default: its ``res x res`` light-map grid), welded into one ``(ny (samples-1) + 1, nx
    (samples-1) + 1)`` vertex grid (patches share their edge vertices: no cracks inside a tile by
    construction), coloured by its light map (bilinear between texels), plus skirts.

    Each vertex carries its heights on the coarser levels (``targets``: the middle level's, or the
    corner grid's for a middle mesh; ``corner``: the corner grid's) and the patches' errors around
    it (``errors``: :func:`patch_level_errors` through :func:`vertex_errors`, at most
    ``max_errors``: the tile's corner-grid and middle-level errors, what its level is chosen by), so
    it is drawn between the levels by its own error on screen.

    ``grid_shape``: ``(ny, nx)`` patches of the tile (patch ``row * nx + col``).
    """
    texels = np.asarray(lit["texels"])  # (n, res, res, 3), [patch, j (v), i (u)]
    n, res = texels.shape[:2]
    m = int(samples) if samples is not None else res
    if m < 2:
        raise ValueError(f"near_mesh: samples must be >= 2, got {m}")
    cp = np.asarray(fit["control_points"])
    u, v = grid_params(m)
    pos = evaluate(cp, u, v, normals=False)  # (n, m*m, 3)
    ny, nx = grid_shape
    r = m - 1
    rows, cols = ny * r + 1, nx * r + 1
    gp = np.empty((rows, cols, 3))
    pos = pos.reshape(ny, nx, m, m, 3)
    # geomorph targets: the next coarser level's surface above each vertex (the middle level's for
    # a near mesh, the corner grid's for a middle one): drawn fully morphed, a mesh is that level
    coarse = 3 if m > 3 else 2
    cu, cv = grid_params(coarse)
    zc = evaluate(cp, cu, cv, normals=False)[..., 2].reshape(-1, coarse, coarse)
    lin = np.linspace(0.0, 1.0, m)
    tz = triangulated_heights(zc, lin).reshape(ny, nx, m, m)
    cz = triangulated_heights(zc[:, ::coarse - 1, ::coarse - 1], lin).reshape(ny, nx, m, m)  # the corner quad's
    gt = np.empty((rows, cols))
    gz = np.empty((rows, cols))
    for j in range(m):  # scatter: a shared vertex takes the value of the last patch written
        for i in range(m):
            gp[j:j + ny * r:r, i:i + nx * r:r] = pos[:, :, j, i]
            gt[j:j + ny * r:r, i:i + nx * r:r] = tz[:, :, j, i]
            gz[j:j + ny * r:r, i:i + nx * r:r] = cz[:, :, j, i]
    light = light_grid(texels, grid_shape)  # (ny (res-1) + 1, nx (res-1) + 1, 3)
    k = (res - 1) / r  # light texels a vertex step
    gc = np.clip(np.rint(_bilinear(light, np.arange(rows) * k, np.arange(cols) * k)), 0, 255).astype(np.uint8)
    idx = np.arange(rows * cols).reshape(rows, cols)
    sides = _border_sides(idx)
    cr, cc = np.mgrid[0:rows - 1, 0:cols - 1]
    cell_patch = ((cr // r) * nx + cc // r).ravel()
    rank = np.empty(ny * nx, np.int64)
    rank[patch_order(ny, nx)] = np.arange(ny * nx)
    order = np.argsort(rank[np.concatenate([cell_patch, cell_patch])], kind="stable")  # patch-major, in patch_order
    mesh = _with_skirts(gp.reshape(-1, 3), gc.reshape(-1, 3), _grid_triangles(rows, cols)[order], sides, depth)
    mesh.patch_triangles = 2 * r * r
    # per patch: the corner grid's error (at least the middle level's: where the corner grid fits,
    # so does the middle level) and the error of the level under this mesh (a middle mesh: the corner grid)
    pe = patch_level_errors(cp)
    if max_errors is not None:
        pe = np.minimum(pe, np.asarray(max_errors, dtype=np.float64)[None, :])
    pe[:, 0] = np.maximum(pe[:, 0], pe[:, 1])
    if m <= 3:
        pe[:, 1] = pe[:, 0]
    ge = vertex_errors(pe, grid_shape, r).reshape(-1, 2)

    def skirted(a: np.ndarray, down: float) -> np.ndarray:  # a value a vertex, the skirts' after the grid's
        return np.concatenate([a] + [np.concatenate([a[i], a[i] - down]) for i in sides]).astype(np.float32)

    gt[::r, ::r] = gz[::r, ::r] = gp[::r, ::r, 2]  # patch corners: every level's the same, to the bit
    mesh.targets = skirted(gt.reshape(-1), depth)
    mesh.corner = skirted(gz.reshape(-1), depth)
    mesh.errors = skirted(ge, 0.0)
    return mesh


def visible_indices(mesh: TileMesh, visible: np.ndarray, order: np.ndarray) -> np.ndarray:
    """The triangles of a patch-major ``mesh`` (:func:`near_mesh`, patches in ``order``:
    :func:`patch_order`) whose patch is ``visible (n,) bool``, and every skirt triangle: ``(t', 3)``
    uint32."""
    pt = mesh.patch_triangles
    n = len(visible)
    tri = mesh.indices
    keep = np.zeros(len(tri), bool)
    keep[:mesh.whole_triangles] = True  # (a far mesh's block skirts and zippers are drawn by block)
    keep[:n * pt] = np.repeat(np.asarray(visible, bool)[order], pt)
    return np.ascontiguousarray(tri[keep])


def glue_indices(mesh: TileMesh, grid_shape: tuple, glued: np.ndarray) -> np.ndarray:
    """The triangles of the patches of a patch-major ``mesh`` (:func:`near_mesh`) of a ``(ny, nx)``
    tile with sides ``glued (n, 4) bool`` (south, east, north, west), where a side meets a patch
    drawn from the corner grid: each such side's inner vertices collapsed onto its nearer corner
    (as the course's glue patches zip their strips to a flat neighbour's straight edge), so the side
    is the corner grid's edge itself, shared vertex for vertex, not a T-junction (whose rasterized
    pinholes no strip under it closes); the patch's vertices there are fully morphed onto the
    corner grid, so the surface does not move.  ``(t, 3)`` uint32, degenerate triangles left out:
    the patches with a glued side, in :func:`patch_order`."""
    ny, nx = (int(x) for x in grid_shape)
    pt = int(mesh.patch_triangles)
    r = int(round(np.sqrt(pt / 2.0)))
    cols = nx * r + 1
    g = np.asarray(glued, bool).reshape(ny * nx, 4)
    order, rank = patch_order(ny, nx), _patch_rank(ny, nx)
    p = order[g[order].any(1)]  # (k,) the patches with a glued side, in mesh order
    if not len(p):
        return np.zeros((0, 3), np.uint32)
    tri = np.asarray(mesh.indices)[(rank[p] * pt)[:, None] + np.arange(pt)].astype(np.int64)  # (k, pt, 3)
    row, col = tri // cols, tri % cols
    r0, c0 = ((p // nx) * r)[:, None, None], ((p % nx) * r)[:, None, None]
    gs = g[p][:, None, None, :]
    snap_c = np.where(2 * (col - c0) < r, c0, c0 + r)  # along a south or north side: to the nearer corner
    snap_r = np.where(2 * (row - r0) < r, r0, r0 + r)
    on = ((row == r0) & gs[..., 0]) | ((row == r0 + r) & gs[..., 2])
    col = np.where(on, snap_c, col)
    on = ((col == c0 + r) & gs[..., 1]) | ((col == c0) & gs[..., 3])
    row = np.where(on, snap_r, row)
    out = (row * cols + col).reshape(-1, 3)
    keep = (out[:, 0] != out[:, 1]) & (out[:, 1] != out[:, 2]) & (out[:, 0] != out[:, 2])
    return np.ascontiguousarray(out[keep], dtype=np.uint32)


def patch_boxes(mesh: TileMesh, grid_shape: tuple) -> tuple[np.ndarray, np.ndarray] | None:
    """The box of each patch's triangles of a patch-major ``mesh`` (:func:`near_mesh`, or
    :func:`far_mesh` at stride 1) of a ``(ny, nx)`` tile: ``(centre (n, 3), half extent (n, 3))``
    float64, from the mesh's own float32 vertices (a triangle lies in the box of its vertices; with
    geomorph targets a vertex is drawn between its height and its target, both inside), padded by a
    centimetre; None for a mesh that is not patch-major."""
    pt = int(mesh.patch_triangles)
    if not pt:
        return None
    ny, nx = (int(x) for x in grid_shape)
    r = int(round(np.sqrt(pt / 2.0)))  # cells a patch side (2 r^2 triangles a patch)
    rows, cols = ny * r + 1, nx * r + 1
    if 2 * r * r != pt or len(mesh.positions) < rows * cols:
        raise ValueError(f"patch_boxes: a mesh of {len(mesh.positions)} vertices and {pt} triangles a patch is not "
                         f"the grid of a {ny} x {nx} tile")
    g = mesh.positions[:rows * cols].reshape(rows, cols, 3)
    lo = _patch_reduce(g, (ny, nx), r, np.minimum)
    hi = _patch_reduce(g, (ny, nx), r, np.maximum)
    for a in (mesh.targets, mesh.corner):  # heights a vertex may be drawn at too
        if a is not None:
            z = a[:rows * cols].reshape(rows, cols)
            np.minimum(lo[..., 2], _patch_reduce(z, (ny, nx), r, np.minimum), out=lo[..., 2])
            np.maximum(hi[..., 2], _patch_reduce(z, (ny, nx), r, np.maximum), out=hi[..., 2])
    lo64, hi64 = lo.reshape(-1, 3).astype(np.float64), hi.reshape(-1, 3).astype(np.float64)
    return 0.5 * (lo64 + hi64), 0.5 * (hi64 - lo64) + 0.01


def _patch_reduce(grid: np.ndarray, grid_shape: tuple, r: int, op) -> np.ndarray:
    """``op`` (np.minimum or np.maximum) over each patch's vertices of a welded ``grid (ny r + 1,
    nx r + 1, ...)``: ``(ny, nx, ...)``."""
    ny, nx = grid_shape
    out = grid[0:ny * r:r, 0:nx * r:r].copy()
    for j in range(r + 1):  # patch (py, px)'s vertices: rows py r .. py r + r, columns likewise
        for i in range(r + 1):
            op(out, grid[j:j + ny * r:r, i:i + nx * r:r], out=out)
    return out


def patch_corner_errors(mesh: TileMesh, grid_shape: tuple) -> np.ndarray | None:
    """The largest corner-grid error (:attr:`TileMesh.errors` column 0) over each patch's vertices of
    a patch-major ``mesh`` with errors, ``(n,)`` float64 (None without them): where ``pixel_error``
    pixels of it fit at the patch's box, every vertex of the patch is drawn fully morphed onto the
    corner grid, so the patch may be drawn from the corner grid instead."""
    if mesh.errors is None or not mesh.patch_triangles:
        return None
    ny, nx = (int(x) for x in grid_shape)
    r = int(round(np.sqrt(int(mesh.patch_triangles) / 2.0)))
    rows, cols = ny * r + 1, nx * r + 1
    e = np.asarray(mesh.errors)[:rows * cols, 0].reshape(rows, cols)
    return _patch_reduce(e, (ny, nx), r, np.maximum).reshape(-1).astype(np.float64)


def _pad1(a: np.ndarray) -> np.ndarray:
    """``a (h, w)`` with a border of zeros (False) one wide: ``(h + 2, w + 2)`` (``np.pad(a, 1)``
    without its per-call overhead, which the per-frame tile loops pay many times)."""
    a = np.asarray(a)
    out = np.zeros((a.shape[0] + 2, a.shape[1] + 2), a.dtype)
    out[1:-1, 1:-1] = a
    return out


def entry_runs(mask: np.ndarray, first: np.ndarray, count: np.ndarray) -> np.ndarray:
    """Indirect draw commands ``(k, 5)`` uint32 (count, instances, first index, base vertex, base
    instance: ``glMultiDrawElementsIndirect``'s) drawing the entries ``mask (m,) bool`` of an index
    buffer whose entry ``j`` is the triangles ``[first[j], first[j] + count[j])``, entries in buffer
    order and back to back: one command a run of consecutive entries."""
    m = np.asarray(mask, bool)
    first, count = np.asarray(first, np.int64), np.asarray(count, np.int64)
    d = np.diff(np.concatenate([[False], m, [False]]).astype(np.int8))
    start, end = np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]
    n = (first[end - 1] + count[end - 1] - first[start]) * 3
    keep = n > 0
    out = np.zeros((int(keep.sum()), 5), np.uint32)
    out[:, 0], out[:, 1], out[:, 2] = n[keep], 1, first[start][keep] * 3
    return out


def command_indices(indices: np.ndarray, commands: np.ndarray) -> np.ndarray:
    """The vertex indices ``(m,)`` uint32 that indirect draw commands ``commands (k, 5)`` uint32
    (:func:`entry_runs`': count, instances, first index, base vertex, base instance) draw from the
    index buffer ``indices (t, 3)`` uint32, in command order, base vertices added: what one
    ``glDrawElements`` draws instead of the ``k`` draws of a multi-draw."""
    c = np.asarray(commands, np.int64).reshape(-1, 5)
    flat = np.asarray(indices).reshape(-1)
    cnt = c[:, 0] * (c[:, 1] > 0)
    total = int(cnt.sum())
    if total == 0:
        return np.zeros(0, np.uint32)
    if (c[:, 2] + cnt > len(flat))[cnt > 0].any():
        raise ValueError(f"draw commands reach index {int((c[:, 2] + cnt).max())} of a buffer of {len(flat)}")
    at = np.arange(total, dtype=np.int64) + np.repeat(c[:, 2] - (np.cumsum(cnt) - cnt), cnt)
    out = flat[at]
    if c[:, 3].any():
        out = out + np.repeat(c[:, 3], cnt)
    return out.astype(np.uint32, copy=False)


def patch_runs(inside: np.ndarray, patch_triangles: int, total_triangles: int, skirts: bool = True,
               order: np.ndarray | None = None) -> np.ndarray:
    """Indirect draw commands ``(k, 5)`` uint32 (:func:`entry_runs`) drawing the patches ``inside
    (n,) bool`` of a patch-major index buffer of ``total_triangles`` (the ``j``-th patch of ``order``,
    :func:`patch_order`, default patch ``j``: triangles ``[j pt, (j+1) pt)``, the skirts after the
    ``n`` patches', drawn with ``skirts``): one command a run of consecutive patches."""
    m = np.asarray(inside, bool)
    if order is not None:
        m = m[order]
    n, pt = len(m), int(patch_triangles)
    # (entry_runs of equal entries back to back: a run's first patch and its length)
    d = np.diff(np.concatenate([[False], m, [False]]).astype(np.int8))
    start, end = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    out = np.zeros((len(start) if pt > 0 else 0, 5), np.uint32)
    if len(out):
        out[:, 0], out[:, 1], out[:, 2] = (end - start) * pt * 3, 1, start * pt * 3
    rest = int(total_triangles) - n * pt
    if skirts and rest > 0:
        out = np.concatenate([out, np.array([[rest * 3, 1, n * pt * 3, 0, 0]], np.uint32)])
    return out


def block_runs(mesh: TileMesh, grid_shape: tuple, strides: np.ndarray, drawn: np.ndarray, stride: int,
               border: tuple | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Indirect draw commands ``(k, 5)`` uint32 (:func:`entry_runs`) drawing, of far ``mesh`` at
    ``stride`` (:func:`far_mesh`) of a ``(ny, nx)``-patch tile, the blocks ``drawn (nb,) bool`` whose
    stride (``strides (nb,) int``, block ``row * bx + col``) is ``stride``: their cells, and the
    joins of their sides: against a coarser block (within the tile, or across its border:
    ``border``, the strides of the neighbouring tiles' blocks along its south, east, north and west
    sides, ``(bx,), (by,), (bx,), (by,)``) the side's zipper to it (a finer block zips to this one,
    blocks of one stride share their corners), against anything else (0 in ``border``: a neighbour
    not drawn by blocks, or none; None: all 0) the side's skirt (a far mesh has them under the tile's
    border).  ``(cells and skirts, zippers)``: the zippers are drawn two-sided."""
    ny, nx = (int(x) for x in grid_shape)
    by, bx = -(-ny // FAR_BLOCK), -(-nx // FAR_BLOCK)
    st = np.asarray(strides).reshape(by, bx)
    sel = (np.asarray(drawn, bool) & (np.asarray(strides) == stride)).reshape(by, bx)
    pad = _pad1(st)  # 0: beyond the tile's border (no stride)
    if border is not None:
        pad[0, 1:-1], pad[1:-1, -1], pad[-1, 1:-1], pad[1:-1, 0] = border
    other = np.stack([pad[:-2, 1:-1], pad[1:-1, 2:], pad[2:, 1:-1], pad[1:-1, :-2]], -1)  # south, east, north, west
    skirt = (sel[..., None] & (other == 0)).reshape(-1)  # against what is not a far block: a skirt
    blk = mesh.blocks
    assert blk is not None
    if stride == 1:  # patch-major cells: the patches of the blocks
        py, px = np.arange(ny) // FAR_BLOCK, np.arange(nx) // FAR_BLOCK
        cells = patch_runs(sel[py][:, px].reshape(-1), 2, 2 * ny * nx, skirts=False, order=patch_order(ny, nx))
    else:
        bo = blk["block_order"]
        cells = entry_runs(sel.reshape(-1)[bo], blk["cell_first"][bo], blk["cell_count"][bo])
    return np.concatenate([cells, skirt_runs(mesh, skirt)]), zip_runs(mesh, sel.reshape(-1), other, stride)


def zip_runs(mesh: TileMesh, blocks: np.ndarray, other: np.ndarray, stride: int) -> np.ndarray:
    """Indirect draw commands ``(k, 5)`` uint32 (:func:`entry_runs`) drawing the zippers of far
    ``mesh`` (at ``stride``, :func:`far_mesh`) of the blocks ``blocks (nb,) bool`` to their
    neighbours coarser than ``stride``: ``other (nb, 4)`` the neighbours' strides (sides south, east,
    north, west; a finer or equal one, or 0: none)."""
    blk = mesh.blocks
    assert blk is not None
    zmask = np.zeros((len(blk["zip_count"]) * 4, len(FAR_STRIDES)), bool)
    o = np.asarray(other).reshape(-1)
    up = np.asarray(blocks, bool).repeat(4) & (o > stride)
    zmask[np.nonzero(up)[0], np.searchsorted(FAR_STRIDES, o[up])] = True
    return entry_runs(zmask.reshape(-1), blk["zip_first"].reshape(-1), blk["zip_count"].reshape(-1))


def skirt_runs(mesh: TileMesh, mask: np.ndarray) -> np.ndarray:
    """Indirect draw commands ``(k, 5)`` uint32 (:func:`entry_runs`) drawing the block-side skirts
    ``mask (4 nb,) bool`` (block ``b``'s side ``s`` at ``4 b + s``) of far ``mesh``."""
    blk = mesh.blocks
    assert blk is not None
    so = blk["skirt_order"]
    return entry_runs(np.asarray(mask, bool)[so], blk["skirt_first"].reshape(-1)[so], blk["skirt_count"].reshape(-1)[so])


def mesh_bytes(rows: int, cols: int, morph: bool = False) -> int:
    """Bytes of a grid mesh of ``rows x cols`` vertices with skirts (positions, colours, indices;
    with ``morph`` the geomorph heights and errors of a near or middle mesh)."""
    border = 2 * (rows + cols)
    verts = rows * cols + 2 * border
    tris = 2 * (rows - 1) * (cols - 1) + 2 * (border - 4)
    return verts * (31 if morph else 15) + tris * 12


@functools.lru_cache(maxsize=1)
def _kind_meshes() -> tuple:
    """``(heights (kinds,) float64, vertices (kinds,) int64)``: each object kind's mesh height (its
    extent along its own up axis, model units) and vertex count."""
    meshes = [make_mesh(k) for k in OBJECT_KINDS]
    h = np.array([float(np.ptp(np.asarray(m.positions)[:, 2])) for m in meshes])
    v = np.array([len(m.positions) for m in meshes], dtype=np.int64)
    return h, v


def object_kind_heights() -> np.ndarray:
    """Each object kind's mesh height ``(kinds,)`` float64 (model units, in the order of
    :data:`piste.world.objects.OBJECT_KINDS`)."""
    return _kind_meshes()[0].copy()


def object_instance_bytes() -> np.ndarray:
    """The bytes one paged-in object instance of each kind holds on the CPU, ``(kinds,)`` int64
    (the GPU holds copies of the instance rows as it does of the tile meshes):

    * the cache's copy as read: kind (int64) and matrix (4 x 4 float64): 136;
    * the object set's group (:meth:`piste.render.object_pass.ObjectGroups.part`) and the set's
      concatenation of its groups, each: kind, matrix, normal matrix (3 x 3 float64), bounding
      centre (3 float64) and radius, vertex lights (3 directions, 3 colours, an ambient, float32):
      324, twice;
    * the object pass's instance rows (16 x 4 float32) of the group and of the whole set, and their
      packed attributes (13 x 4 float32): 720;
    * baked vertex colours (3 uint8 a vertex), the group's and the set's: 6 a vertex of the kind.
    """
    read = 8 + 16 * 8
    group = 8 + 16 * 8 + 9 * 8 + 3 * 8 + 8 + (9 + 9 + 3) * 4
    rows = 2 * 16 * 4 * 4 + 13 * 4 * 4
    return read + 2 * group + rows + 6 * _kind_meshes()[1]


@dataclass
class TileSets:
    """A tile's visibility sets at run time (what :class:`piste.pipeline.visibility.Visibility`
    wrote: ``origin (2,)``, ``cell`` metres, ``shape (rows, cols)``, ``patch_bits (cells, ceil(n/8))``
    uint8 little bit order, ``n`` patches, ``ground_min (cells,)`` or None, ``band`` metres;
    ``tiles`` ``{(ty, tx): (first bit, patches)}``: whose patches the bits are, the tile's own and,
    in worlds built since the sets cover the 3 x 3 neighbourhood, its neighbours')."""

    origin: np.ndarray
    cell: float
    shape: tuple
    patch_bits: np.ndarray
    n: int
    ground_min: np.ndarray | None
    band: float
    tiles: dict | None = None
    #: samples a patch side of the meshes the occluders were lowered to (the build's ``levels``:
    #: the sets hold while every tile of theirs in view is drawn at one of them); None: sets of the
    #: tile's own patches with only the tile as occluder (worlds built before), always used
    levels: tuple | None = None
    #: ``(levels - 1, cells, ceil(n/8))`` uint8: the patches seen from eyes up to each lower sampled
    #: height (``heights``, sorted; the top level is ``patch_bits``), or None
    level_bits: np.ndarray | None = None
    heights: tuple = ()

    def visible_tile(self, t: tuple[int, int], eye: npt.ArrayLike) -> np.ndarray | None:
        """``(n_t,) bool`` patches of tile ``t`` an eye ``(3,)`` over this set's tile may see
        (:meth:`visible`), or None: ``t`` is not in the sets, or the eye is outside the grid or above
        the band (draw all)."""
        span = (self.tiles or {}).get(tuple(t))
        if span is None:
            return None
        key = tuple(float(x) for x in np.asarray(eye, dtype=np.float64).reshape(-1)[:3])
        got = self.__dict__.get("_last")
        if got is None or got[0] != key:  # one union of cells a frame, whatever the tiles drawn
            got = self.__dict__["_last"] = (key, self.visible(eye))
        bits = got[1]
        return None if bits is None else bits[span[0]:span[0] + span[1]]

    def visible(self, eye: npt.ArrayLike) -> np.ndarray | None:
        """``(n,) bool`` patches an eye ``(3,)`` over the tile may see, or None (outside the grid,
        or above the band over its cell: draw all).  The sets were sampled at five eye points a
        cell (its corners and centre) and an eye between them can see a little more, so this is
        the union of the sets of the eye's cell and its neighbours (at the band's top)."""
        e = np.asarray(eye, dtype=np.float64).reshape(-1)
        rows, cols = self.shape
        ij = np.floor((e[:2] - self.origin) / self.cell)
        if not (0 <= ij[0] < cols and 0 <= ij[1] < rows):
            return None
        q0, r0 = int(ij[0]), int(ij[1])
        if self.ground_min is not None and e[2] > self.ground_min[r0 * cols + q0] + self.band:
            return None
        cells = [r * cols + q for r in range(max(r0 - 1, 0), min(r0 + 2, rows))
                 for q in range(max(q0 - 1, 0), min(q0 + 2, cols))]
        if self.level_bits is not None and self.ground_min is not None and len(self.level_bits):
            # the sets of the lowest sampled height at or above the eye's over its cell's lowest ground
            k = int(np.searchsorted(np.asarray(self.heights, dtype=np.float64),
                                    e[2] - self.ground_min[r0 * cols + q0] - 1e-9))
            level = self.level_bits[k] if k < len(self.level_bits) else self.patch_bits
            bits = np.bitwise_or.reduce(level[cells], axis=0)
        else:
            bits = np.bitwise_or.reduce(self.patch_bits[cells], axis=0)
        return np.unpackbits(bits, count=self.n, bitorder="little").astype(bool)


class TileCache:
    """Which tiles are resident, at which level, under ``budget_bytes`` (see the module docstring).

    Parameters
    ----------
    root : a tiled world folder (``piste build`` with ``terrain.tiles``)
    budget_bytes : the most bytes of tile meshes held at once
    near_radius : metres (from the eye to a tile's rectangle) within which tiles get near meshes
        (default 0.3 tile: the eye's tile and the ones whose border is close; the near mesh has
        2 (near_samples - 1)^2 triangles a patch, the middle level 8, the far levels 2 / stride^2;
        with a camera, tiles further out get near or middle meshes where the far grid would show:
        :meth:`update`)
    view_distance : far tiles beyond this are not loaded (default: the whole world)
    near_samples : samples a patch side of the near meshes (default max(res, ``NEAR_SAMPLES``))
    object_distance : with :attr:`load_objects`, metres (from the eye to a tile's box) within which a
        tile's scene objects are paged in, whatever its terrain level; None (default): each tile's
        own distance from the camera (:meth:`object_distances`: its tallest object at least
        ``OBJECT_MIN_PIXELS`` tall, short of the fog's end and the far plane)
    """

    def __init__(self, root, budget_bytes: int = 256 << 20, near_radius: float | None = None,
                 view_distance: float | None = None, near_samples: int | None = None,
                 object_distance: float | None = None):
        self.store = TileStore(root)
        self.index = self.store.read_index()  # schema-checked (piste.terrain.tiles.check_index)
        self.grid = self.store.grid()
        g = self.grid
        if "res" not in self.index:
            raise FormatError(self.store.index_path, "expected res (light-map texels a patch side): not a built "
                                                     "tiled world", field="res")
        entries = tile_entries(self.index, g, self.store.index_path)  # keys, patches, finite bounds checked
        self.budget = int(budget_bytes)
        s = g.samples_per_patch
        tile_size = g.tile_patches * s * max(g.spacing)
        self.near_radius = float(near_radius) if near_radius is not None else 0.3 * tile_size
        self.view_distance = view_distance
        self.res = int(self.index["res"])
        #: samples a patch side of the near meshes (evaluated patches; the light comes from the
        #: tile's light-map texture whatever the count)
        self.near_samples = max(self.res, NEAR_SAMPLES) if near_samples is None else int(near_samples)
        if self.near_samples < 2:
            raise ConfigError(f"near_samples must be >= 2, got {self.near_samples}")
        self._lock = threading.Lock()
        self.near: dict = {}
        #: resident near tiles' visibility sets (:meth:`_read_vis`; None: built without)
        self.vis: dict = {}
        #: resident tiles' samples a patch side (``near_samples``, or ``MID_SAMPLES``: the middle level)
        self.near_level: dict = {}
        #: page the scene objects of tiles (``lit`` members ``objects_kind``, ``objects_matrix``):
        #: :attr:`objects` ``{tile: (kind (k,) int64, matrix (k, 4, 4))}``, paged in and out by
        #: their own distance (``object_distance``, :meth:`object_distances`), whatever the tile's
        #: terrain level (a tile whose objects do not read back keeps its terrain and draws no objects)
        self.load_objects = False
        self.objects: dict = {}
        if object_distance is not None and not (float(object_distance) >= 0.0):
            raise ConfigError(f"object distance must be >= 0 metres, got {object_distance}")
        self.object_distance = None if object_distance is None else float(object_distance)
        #: per tile with objects: how many of each kind ``(kinds,)`` int64 (from the build's members'
        #: headers; a tile without objects is not listed), the tallest one's height (metres) and
        #: the bytes they hold paged in (:func:`object_instance_bytes`)
        self.object_counts: dict = {}
        self.object_height: dict = {}
        self.object_bytes: dict = {}
        self._objects_wanted: set = set()
        self._objects_pending: set = set()
        self._objects_bad: set = set()  # tiles whose objects did not read back (not asked again)
        self.far: dict = {}
        self.bounds: dict = {t: e["bounds"] for t, e in entries.items()}
        self.patches: dict = {t: e["patches"] for t, e in entries.items()}
        #: tiles that could not be read: ``{(ty, tx): TileError}`` (not drawn; the others are)
        self.bad: dict = {}
        self._wanted: dict = {}  # tile -> samples a patch side of the mesh it should have
        # the bytes of a tile's near mesh, estimated exactly from its patch count
        self._near_estimate = {t: self._near_bytes(self.patches[t], t) for t in self.bounds}
        #: the tiles in a fixed order, their boxes ``(n, 3)`` (skirts included below)
        self.tiles = sorted(self.bounds)
        self.lo = np.array([self.bounds[t][0] for t in self.tiles])
        self.hi = np.array([self.bounds[t][1] for t in self.tiles])
        self.lo[:, 2] -= [self._depth(t) for t in self.tiles]
        self._far_bytes = 0
        self.far_lod_distance = 0.5 * tile_size
        #: per tile: its welded light map ``(rows, cols, 3)`` uint8 (:func:`light_grid`, near and
        #: far levels sample it) and each far level's height error ``{stride: metres}``
        self.light: dict = {}
        self.far_error: dict = {}
        #: per tile: how far its surface leaves the far grid's chords and the middle level's (metres:
        #: the build's ``far_error`` member, :func:`piste.pipeline.tiled_build.far_errors`; for
        #: worlds built without it, :func:`chord_error` and a quarter of it)
        self.chord_error: dict = {}
        self.mid_error: dict = {}
        #: per tile: its far blocks' boxes (:func:`far_blocks`) and ``"err" (nb, 3)`` each coarser
        #: stride's error over each block, a bound: the corner grids'
        #: distance plus the tile's chord error until the loader measures it against the tile's patches
        #: (:func:`piste.render.block_errors.block_stride_errors`, :attr:`exact_errors`)
        self.blocks: dict = {}
        for t in sorted(self.bounds):
            try:
                lit = self._read("lit", t, None)  # every member (the far field, texels, far_error, sets)
                for k in ("far_positions", "far_colors", "texels"):
                    if k not in lit:
                        raise TileError(self.store.path("lit", *t), t, f"has no {k}", field=k)
                if "far_error" in lit and (lit["far_error"] < 0).any():
                    raise TileError(self.store.path("lit", *t), t, "expected errors >= 0 metres", field="far_error")
            except TileError as exc:  # drawn as a hole; the other tiles are drawn
                self._bad_tile(t, exc)
                continue
            py0, py1, px0, px1 = self.grid.patch_range(*t)
            self.far[t] = {k: far_mesh(lit, self._depth(t), k) for k in FAR_STRIDES}
            self.light[t] = light_grid(lit["texels"], (py1 - py0, px1 - px0))
            self.far_error[t] = stride_errors(lit["far_positions"])
            if "far_error" in lit:  # measured by the build (tiled_build.far_errors)
                self.chord_error[t], self.mid_error[t] = (float(x) for x in lit["far_error"])
            else:  # a world built before it: estimated from the corner grid
                self.chord_error[t] = chord_error(lit["far_positions"])
                self.mid_error[t] = self.chord_error[t] / 4.0
            self.blocks[t] = far_blocks(lit["far_positions"], self._depth(t))
            # the stride choice's errors: until the loader measures them against the tile's patches
            # (:meth:`_load_block_errors`), the exact distance between the corner grid's triangulations
            # plus the tile's chord error (a bound by the triangle inequality)
            self.blocks[t]["err"] = (corner_stride_errors(lit["far_positions"][..., 2], FAR_BLOCK, FAR_STRIDES[1:])
                                     + self.chord_error[t])
            self._far_bytes += sum(m.nbytes for m in self.far[t].values()) + self.light[t].nbytes
            self._note_objects(t, lit)
        if self.bad:  # only tiles with a far stand-in are drawn
            keep = [i for i, t in enumerate(self.tiles) if t not in self.bad]
            self.tiles = [self.tiles[i] for i in keep]
            self.lo, self.hi = self.lo[keep].reshape(-1, 3), self.hi[keep].reshape(-1, 3)
        # per tile of :attr:`tiles`, as arrays (what every frame compares with its distances):
        # chord and middle errors (n,) and each coarser far level's error on top of the chords
        # (n, len(FAR_STRIDES) - 1), metres
        self._chord = np.array([self.chord_error.get(t, 0.0) for t in self.tiles], dtype=np.float64)
        self._mid = np.array([self.mid_error.get(t, 0.0) for t in self.tiles], dtype=np.float64)
        # (each stride's largest block error: the tile's far level bounds its blocks' strides from below)
        self._stride_err = np.array([self.blocks[t]["err"].max(0) for t in self.tiles],
                                    dtype=np.float64).reshape(-1, len(FAR_STRIDES) - 1)
        # the far blocks of every tile of :attr:`tiles`, concatenated: tile i's at [block_start[i], block_start[i+1])
        nb = [len(self.blocks[t]["patches"]) for t in self.tiles]
        self.block_start = np.concatenate([[0], np.cumsum(nb)]).astype(np.int64)
        self.tile_index = {t: i for i, t in enumerate(self.tiles)}
        self._blk = {k: np.concatenate([self.blocks[t][k] for t in self.tiles]) if self.tiles else
                     np.zeros((0, 3) if k != "patches" else 0) for k in ("lo", "hi", "err", "patches")}
        #: tiles whose block errors the loader has measured against their patches
        #: (:func:`piste.render.block_errors.block_stride_errors`), and those queued for it
        self.exact_errors: set = set()
        self._errors_pending: set = set()
        if self._far_bytes > self.budget:
            raise ConfigError(f"streaming budget {self.budget / 2**20:.1f} MiB is below the far field's "
                              f"{self._far_bytes / 2**20:.1f} MiB: raise it")
        self._queue: queue.PriorityQueue = queue.PriorityQueue()
        self._pending: set = set()
        self.loaded_count = 0
        self.errors: list = []
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="piste-tile-loader", daemon=True)
        self._thread.start()

    # ---------------------------------------------------------------- sizes
    def _note_objects(self, t, lit: dict) -> None:
        """Remember how many objects tile ``t``'s ``lit`` members hold, their tallest height and
        bytes (the members are checked when they page in: :func:`read_tile_objects`)."""
        kind, mat = lit.get("objects_kind"), lit.get("objects_matrix")
        if kind is None and mat is None:
            return
        k = np.asarray(kind if kind is not None else np.zeros(0, np.int64))
        if kind is not None and mat is not None and k.ndim == 1 and len(k) == 0:
            return  # none placed on this tile
        n = len(OBJECT_KINDS)
        ok = (mat is not None and k.ndim == 1 and k.dtype.kind in "iu" and len(k) <= MAX_TILE_OBJECTS
              and bool(((k >= 0) & (k < n)).all()))
        # (members that will not read back: one instance's worth, so they are asked for, warned and dropped)
        counts = np.bincount(k.astype(np.int64), minlength=n)[:n] if ok else np.array([1] + [0] * (n - 1))
        heights, _ = _kind_meshes()
        h = 0.0
        if ok and mat is not None and np.shape(mat) == (len(k), 4, 4) and np.asarray(mat).dtype.kind in "fiu":
            with np.errstate(all="ignore"):
                up = heights[k.astype(np.int64)] * np.linalg.norm(np.asarray(mat, dtype=np.float64)[:, :3, 2], axis=1)
            up = up[np.isfinite(up)]
            h = float(up.max()) if len(up) else 0.0
        if not h > 0.0:  # members that will not read back (warned when they page in): as tall as a mesh
            h = float(heights.max())
        self.object_counts[t] = counts.astype(np.int64)
        self.object_height[t] = min(h, 1e4)
        self.object_bytes[t] = int((counts * object_instance_bytes()).sum())

    def _near_bytes(self, n: int, t, samples: int | None = None) -> int:
        py0, py1, px0, px1 = self.grid.patch_range(*t)
        r = (self.near_samples if samples is None else samples) - 1
        return mesh_bytes((py1 - py0) * r + 1, (px1 - px0) * r + 1, morph=True)

    def _depth(self, t) -> float:
        b = self.bounds[t]
        return float(b[1, 2] - b[0, 2]) + 1.0

    @property
    def resident_bytes(self) -> int:
        """Bytes resident now: the far field, the paged meshes and the paged objects
        (:attr:`object_bytes` of the tiles in :attr:`objects`)."""
        with self._lock:
            return (self._far_bytes + sum(m.nbytes for m in self.near.values())
                    + sum(self.object_bytes.get(t, 0) for t in self.objects))

    # ---------------------------------------------------------------- loading
    def _expect(self, t) -> dict:
        """The shapes and dtype kinds a tile's members must have (from the grid and ``res``)."""
        py0, py1, px0, px1 = self.grid.patch_range(*t)
        ny, nx, r = py1 - py0, px1 - px0, self.res
        return {"control_points": ((ny * nx, 4, 4, 3), "fiu"), "texels": ((ny * nx, r, r, 3), "u"),
                "far_positions": ((ny + 1, nx + 1, 3), "fiu"), "far_colors": ((ny + 1, nx + 1, 3), "u"),
                "far_error": ((2,), "f")}

    def _read(self, product: str, t, names) -> dict:
        """Members ``names`` of tile ``t``'s ``product`` file, every header checked before a byte is
        allocated and every file opened below the world's folder without following links
        (:meth:`piste.terrain.tiles.TileStore.read`): a bad tile is a TileError naming it."""
        a = self.store.read(product, *t, names=names, expect=self._expect(t))
        for k in ("texels", "far_colors"):  # uint8 colours (a wider unsigned type would wrap)
            if k in a and a[k].dtype != np.uint8:
                raise TileError(self.store.path(product, *t), t, f"expected uint8 colours, got {a[k].dtype}", field=k)
        return a

    def _read_vis(self, t):
        """Tile ``t``'s visibility sets (the build's ``vis_*`` members of its lit file, written by
        :class:`piste.pipeline.visibility.Visibility`: which of its patches eyes over each of its
        cells see), a :class:`TileSets`; None when the world was built without them.  Sets that do
        not fit the tile are a TileError naming the file and the member."""
        if not float(self.index.get("cell", 0.0) or 0.0) > 0.0:
            return None
        import json

        path = self.store.path("lit", *t)
        a = self.store.read("lit", *t, expect=self._expect(t))
        if "vis_meta" not in a:
            return None
        try:
            meta = json.loads(str(a["vis_meta"]))
            shape = tuple(int(x) for x in meta["shape"])
            n, cell = int(meta["n_patches"]), float(meta["cell"])
            origin = np.asarray(meta["origin"], dtype=np.float64).reshape(2)
            band = max((float(h) for h in meta.get("eye_heights", ())), default=0.0)
            listed = [(int(y), int(x), int(k)) for y, x, k in meta["tiles"]] if "tiles" in meta else [(*t, n)]
            heights = tuple(sorted(float(h) for h in meta.get("eye_heights", ())))
            levels = tuple(int(m) for m in meta["levels"]) if "levels" in meta else None
        except (ValueError, TypeError, KeyError) as exc:
            raise TileError(path, t, f"unreadable visibility metadata ({str(exc)[:80]})", field="vis_meta") from None
        tiles, first = {}, 0
        for y, x, k in listed:  # the tiles whose patches the bits are, in bit order
            if self.patches.get((y, x)) != k or (y, x) in tiles or max(abs(y - t[0]), abs(x - t[1])) > 1:
                raise TileError(path, t, f"visibility sets list tile ({y}, {x}) with {k} patches: expected this tile "
                                         "and its neighbours, each once with its patch count", field="vis_meta")
            tiles[(y, x)] = (first, k)
            first += k
        cells = int(np.prod(shape)) if len(shape) == 2 else 0
        if n != first or t not in tiles or cells < 1 or not (cell > 0 and np.isfinite(cell)) \
                or not np.isfinite(origin).all():
            raise TileError(path, t, f"visibility sets for {n} patches in {cells} cells of {cell} m, expected "
                                     f"{first} patches (this tile's {self.patches[t]} among them) in at least one "
                                     "cell", field="vis_meta")
        pb = a.get("vis_patch_bits")
        if pb is None or pb.dtype != np.uint8 or pb.shape != (cells, (n + 7) // 8):
            raise TileError(path, t, f"expected ({cells}, {(n + 7) // 8}) uint8 patch bits, got "
                                     f"{None if pb is None else (pb.shape, str(pb.dtype))}", field="vis_patch_bits")
        gm = a.get("vis_ground_min")
        if gm is not None and (gm.shape != (cells,) or gm.dtype.kind != "f" or not np.isfinite(gm).all()):
            raise TileError(path, t, f"expected ({cells},) finite ground heights, got {gm.shape} {gm.dtype}",
                            field="vis_ground_min")
        lb = a.get("vis_level_bits")
        if lb is not None and (lb.dtype != np.uint8 or lb.ndim != 3 or lb.shape[1:] != pb.shape
                               or not 0 < lb.shape[0] < max(len(heights), 1)):
            raise TileError(path, t, f"expected (levels < {len(heights)}, {cells}, {(n + 7) // 8}) uint8 level bits, got "
                                     f"{lb.shape} {lb.dtype}", field="vis_level_bits")
        return TileSets(origin, cell, shape, pb, n, None if gm is None else gm.astype(np.float64), band, tiles, levels,
                        lb, heights)

    def _read_objects(self, t):
        """Tile ``t``'s scene objects ``(kind, matrix)`` (:func:`piste.terrain.tiles.read_tile_objects`),
        None when they do not read back (warned; the tile's terrain is still drawn)."""
        try:
            return read_tile_objects(self.store, self.grid, t[0], t[1], len(OBJECT_KINDS))
        except TileError as exc:
            _log.warning("%s (the tile's objects are not drawn)", exc)
            return None

    def resident_objects(self) -> dict:
        """``{tile: (kind (k,) int64, matrix (k, 4, 4) float64)}``: the objects paged in (their tile
        within its object distance, :meth:`update`, whatever its terrain level), empty without
        :attr:`load_objects`."""
        with self._lock:
            return dict(self.objects)

    def sets_hold(self, eye: npt.ArrayLike, drawn: dict) -> bool:
        """Whether the sets of the tile under ``eye`` may cull this frame: every tile of theirs among
        ``drawn`` (``{tile: level}``, :meth:`draw_list`'s) is drawn at a level their occluders were
        lowered to (:attr:`TileSets.levels`: a coarser mesh sags below the surface and may show what
        the surface hides).  True without such sets (nothing to check, or sets of an older build)."""
        e = np.asarray(eye, dtype=np.float64).reshape(-1)
        under = self.grid.tile_of(float(e[0]), float(e[1]))
        with self._lock:
            vis = self.vis.get(under) if under in self.near else None
            samples = dict(self.near_level)
        if vis is None or vis.levels is None:
            return True
        for t, level in drawn.items():
            if t in vis.tiles:
                m = samples.get(t) if level in ("near", "mid") else (2 if level == "far1" else None)
                if m not in vis.levels:
                    return False
        return True

    def visible_patches(self, t: tuple[int, int], eye: npt.ArrayLike) -> np.ndarray | None:
        """``(n,) bool`` patches of tile ``t`` seen from ``eye``, by the sets of the resident tile under
        the eye (:meth:`TileSets.visible_tile`: its own patches and its neighbours'), None: draw them
        all (no sets there, ``t`` not in them, the eye outside their grid or above their band)."""
        e = np.asarray(eye, dtype=np.float64).reshape(-1)
        under = self.grid.tile_of(float(e[0]), float(e[1]))
        with self._lock:
            vis = self.vis.get(under) if under in self.near else None
        return None if vis is None else vis.visible_tile(t, e)

    def _bad_tile(self, t, exc: TileError) -> None:
        """Remember a tile that cannot be read; the first one is a warning, the rest debug lines."""
        with self._lock:
            first = not self.bad
            self.bad[t] = exc
            self._wanted.pop(t, None)
        (_log.warning if first else _log.debug)(
            "%s (the tile is not drawn; the other tiles are%s)", exc,
            "" if not first else ": further bad tiles are logged at debug level")

    def _run(self) -> None:
        while not self._stop:
            try:
                _, what, t = self._queue.get(timeout=0.05)  # what: 0 a tile's mesh, 1 its objects
            except queue.Empty:
                continue
            if t is None:
                break
            try:
                if what == 1:
                    self._load_objects(t)
                    continue
                if what == 2:
                    self._load_block_errors(t)
                    continue
                with self._lock:
                    samples = self._wanted.get(t)
                if samples is not None:
                    py0, py1, px0, px1 = self.grid.patch_range(*t)
                    mesh = near_mesh(self._read("fit", t, ("control_points",)), self._read("lit", t, ("texels",)),
                                     (py1 - py0, px1 - px0), self._depth(t), samples,
                                     max_errors=(self.chord_error[t], self.mid_error[t]))
                    vis = self._read_vis(t)
                    with self._lock:
                        if self._wanted.get(t) == samples:  # still wanted and still fits: the budget was reserved
                            self.vis[t] = vis
                            self.near[t] = mesh
                            self.near_level[t] = samples
                            self.loaded_count += 1
            except TileError as exc:  # a bad tile: warned, left out; the others are drawn
                self._bad_tile(t, exc)
            except Exception as exc:  # reported by wait_idle / the renderer
                self.errors.append(exc)
            finally:
                with self._lock:
                    (self._objects_pending if what == 1 else self._errors_pending if what == 2
                     else self._pending).discard(t)
                self._queue.task_done()

    def _load_block_errors(self, t) -> None:
        """Measure tile ``t``'s far blocks' stride errors against its fitted patches (the loader
        thread: :func:`piste.render.block_errors.block_stride_errors`, exact on a lattice of 9 points
        a patch side plus a curvature margin) and use them in place of the first bound (the corner
        grids' distance plus the tile's chord error); a fit that does not read back keeps the first."""
        i = self.tile_index.get(t)
        if i is None or t in self.bad:
            return
        py0, py1, px0, px1 = self.grid.patch_range(*t)
        try:
            cp = self._read("fit", t, ("control_points",))["control_points"]
            corner_z = self._read("lit", t, ("far_positions",))["far_positions"][..., 2]
        except TileError as exc:  # the first bound stays (a near mesh of the tile will report it)
            _log.debug("%s (block errors kept from the corner grid)", exc)
            return
        err = block_stride_errors(cp, corner_z, (py1 - py0, px1 - px0), FAR_BLOCK, FAR_STRIDES[1:])
        s, e = int(self.block_start[i]), int(self.block_start[i + 1])
        with self._lock:
            self.blocks[t]["err"] = err
            self._blk["err"][s:e] = err
            cols = self.__dict__.get("_blk_cols")
            if cols is not None:
                cols[1][2][:, s:e] = err.T
            self._stride_err[i] = err.max(0)
            self.exact_errors.add(t)

    def _load_objects(self, t) -> None:
        """Read tile ``t``'s objects (the loader thread) and keep them while still wanted (their
        bytes were reserved); objects that do not read back are warned once and not asked again."""
        with self._lock:
            if t not in self._objects_wanted:
                return
        objs = self._read_objects(t)
        with self._lock:
            if objs is None:
                self._objects_bad.add(t)
            elif t in self._objects_wanted:
                self.objects[t] = objs

    def distance(self, eye: npt.ArrayLike, t: tuple[int, int]) -> float:
        """Metres from ``eye`` (x, y) to tile ``t``'s rectangle."""
        b = self.bounds[t]
        dx = max(b[0, 0] - eye[0], 0.0, eye[0] - b[1, 0])
        dy = max(b[0, 1] - eye[1], 0.0, eye[1] - b[1, 1])
        return float(np.hypot(dx, dy))

    def distances(self, eye: npt.ArrayLike) -> np.ndarray:
        """:meth:`distance` to every tile of :attr:`tiles` at once, ``(n,)`` float64."""
        eye = np.asarray(eye, dtype=np.float64)[:2]
        d = np.maximum(np.maximum(self.lo[:, :2] - eye, eye - self.hi[:, :2]), 0.0)
        return np.hypot(d[:, 0], d[:, 1])

    def object_distances(self, eye: npt.ArrayLike, pixel_scale: float | None = None, far: float | None = None,
                         fog_density: float | None = None) -> np.ndarray:
        """How far from the eye each tile of :attr:`tiles` keeps its objects paged in, ``(n,)``
        metres (compared with the distance from the eye ``(3,)`` to the tile's box): ``object_distance``
        when one was given; else the distance at which the tile's tallest object
        (:attr:`object_height`) is ``OBJECT_MIN_PIXELS`` tall at ``pixel_scale`` pixels a radian
        (without one: ``near_radius``), at most where fog of ``fog_density`` per metre leaves
        ``OBJECT_FOG_FLOOR`` of its colour and at most ``far`` (the far plane)."""
        n = len(self.tiles)
        if self.object_distance is not None:
            return np.full(n, self.object_distance)
        if pixel_scale is None:
            out = np.full(n, self.near_radius)
        else:
            h = np.array([self.object_height.get(t, 0.0) for t in self.tiles])
            out = h * float(pixel_scale) / OBJECT_MIN_PIXELS
        if fog_density is not None and float(fog_density) > 0.0:
            out = np.minimum(out, -np.log(OBJECT_FOG_FLOOR) / float(fog_density))
        if far is not None and np.isfinite(far):
            out = np.minimum(out, float(far))
        return out

    def update(self, eye: npt.ArrayLike, pixel_scale: float | None = None, pixel_error: float = FAR_PIXEL_ERROR,
               far: float | None = None, fog_density: float | None = None, object_scale: float | None = None) -> None:
        """Choose the paged meshes for ``eye``: nearest tiles first, while the budget allows, get
        near meshes (``near_samples`` a patch side) within ``near_radius`` and, with
        ``pixel_scale`` (pixels a radian), wherever the middle level's error (:attr:`mid_error`)
        would show as more than ``pixel_error`` pixels; the
        middle level (``MID_SAMPLES``) where only the corner grid's would (or where a near mesh no
        longer fits).  With :attr:`load_objects`, the objects of the tiles within their object
        distance (:meth:`object_distances` of ``object_scale``, default ``pixel_scale``, ``far`` and
        ``fog_density``) are
        paged too, reserved in the same nearest-first pass (a tile's mesh, then its objects; once
        one kind no longer fits, no farther tile gets that kind).  Evict the others at once, queue
        the missing ones for the loader."""
        dist = self.distances(eye)
        level = np.where(dist <= self.near_radius, self.near_samples, 0)
        mid = min(MID_SAMPLES, self.near_samples)
        e = np.asarray(eye, dtype=np.float64).reshape(-1)[:3]
        d3 = None
        if len(self.tiles) and (pixel_scale is not None or (self.load_objects and self.object_counts)):
            d = np.maximum(np.maximum(self.lo - e, e - self.hi), 0.0)
            d3 = np.sqrt((d * d).sum(1))  # metres from the eye to each tile's box
        if pixel_scale is not None and len(self.tiles):
            allowed = pixel_error * np.maximum(d3, 1e-9) / float(pixel_scale)  # metres
            level = np.where(level > 0, level, np.where(self._mid > allowed, self.near_samples,
                                                        np.where(self._chord > allowed, mid, 0)))
        has_obj = np.zeros(len(self.tiles), bool)
        if self.load_objects and self.object_counts and d3 is not None:
            has_obj = np.array([t in self.object_counts and t not in self._objects_bad for t in self.tiles])
            scale = pixel_scale if object_scale is None else object_scale
            has_obj &= d3 <= self.object_distances(e, scale, far, fog_density)
        close = np.nonzero((level > 0) | has_obj)[0]
        order = [(float(dist[i]), self.tiles[i], int(level[i]), bool(has_obj[i]))
                 for i in close[np.argsort(dist[close], kind="stable")]]
        room = self.budget - self._far_bytes
        want, objs_want = [], []
        mesh_full = objs_full = False
        for d, t, k, obj in order:
            if t in self.bad:
                continue
            if k and not mesh_full:
                cost = self._near_estimate[t] if k == self.near_samples else self._near_bytes(0, t, k)
                if cost > room and k != mid:  # no room for a near mesh: the middle level, if that fits
                    k, cost = mid, self._near_bytes(0, t, mid)
                if cost > room:
                    mesh_full = True
                else:
                    room -= cost
                    want.append((d, t, k))
            if obj and not objs_full:
                cost = self.object_bytes[t]
                if cost > room:
                    objs_full = True
                else:
                    room -= cost
                    objs_want.append((d, t))
        with self._lock:
            self._wanted = {t: k for _, t, k in want}
            self._objects_wanted = {t for _, t in objs_want}
            for t in [t for t in self.near if self._wanted.get(t) != self.near_level.get(t)]:
                del self.near[t]
                self.vis.pop(t, None)
                self.near_level.pop(t, None)
            for t in [t for t in self.objects if t not in self._objects_wanted]:
                del self.objects[t]
            todo = [(d, 0, t) for d, t, _ in want if t not in self.near and t not in self._pending]
            todo += [(d, 1, t) for d, t in objs_want if t not in self.objects and t not in self._objects_pending]
            self._pending.update(t for _, what, t in todo if what == 0)
            self._objects_pending.update(t for _, what, t in todo if what == 1)
        if len(self.exact_errors) + len(self._errors_pending) < len(self.tiles):
            # block errors measured, nearest first, for the tiles where they can choose a stride: those
            # whose blocks' largest error at the coarsest stride would show at the tile's nearest point
            # (:meth:`block_strides` at ``pixel_error``); every tile without a pixel scale
            need = (np.nonzero(self._stride_err[:, -1] * float(pixel_scale) > float(pixel_error) * d3)[0]
                    if pixel_scale is not None else range(len(self.tiles)))
            with self._lock:
                more = [(float(dist[i]), 2, self.tiles[i]) for i in need if self.tiles[i] not in self.exact_errors
                        and self.tiles[i] not in self._errors_pending and self.tiles[i] not in self.bad]
                self._errors_pending.update(t for _, _, t in more)
            todo = todo + more
        for item in todo:
            self._queue.put(item)

    def wait_idle(self, timeout: float = 60.0) -> None:
        """Block until the loader has nothing queued (tests, offline rendering)."""
        t0 = time.perf_counter()
        while True:
            with self._lock:
                busy = bool(self._pending or self._objects_pending or self._errors_pending)
            if not busy:
                break
            if time.perf_counter() - t0 > timeout:
                raise TimeoutError("tile loader still busy")
            time.sleep(0.002)
        if self.errors:
            raise self.errors[0]

    def far_stride(self, eye: npt.ArrayLike, t: tuple[int, int]) -> int:
        """The far level of tile ``t`` seen from ``eye``: corner stride 1 within ``far_lod_distance``,
        2 within twice that, 4 within four times, else 8."""
        d = self.distance(eye, t) / self.far_lod_distance
        return next((k for k in FAR_STRIDES if d < k), FAR_STRIDES[-1])

    def far_strides(self, eye: npt.ArrayLike, pixel_scale: float, pixel_error: float = FAR_PIXEL_ERROR) -> np.ndarray:
        """The far level of every tile of :attr:`tiles` seen from ``eye`` ``(3,)``: the coarsest
        stride whose height error (its blocks' largest, :attr:`blocks`)
        projects to at most ``pixel_error`` pixels at the tile's nearest point, ``pixel_scale``
        pixels a radian (image height / (2 tan(fov_y / 2))); ``(n,)`` int."""
        eye = np.asarray(eye, dtype=np.float64)
        d = np.maximum(np.maximum(self.lo - eye, eye - self.hi), 0.0)
        dist = np.sqrt((d * d).sum(1))
        allowed = dist * pixel_error / max(float(pixel_scale), 1e-9)  # metres of error allowed
        out = np.ones(len(self.tiles), int)
        for j, k in enumerate(FAR_STRIDES[1:]):  # the coarsest level whose error (on top of the chords') fits
            out = np.where(self._stride_err[:, j] <= allowed, k, out)
        return out

    def block_columns(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The far blocks' boxes and errors (:attr:`_blk`) by columns, contiguous: ``lo, hi (3, nb)``,
        ``err (len(FAR_STRIDES) - 1, nb)`` float64 (made once)."""
        got = self.__dict__.get("_blk_cols")
        if got is None or got[0] is not self._blk["lo"]:
            with self._lock:  # (the loader writes measured errors into both)
                cols = tuple(np.ascontiguousarray(np.asarray(self._blk[k], dtype=np.float64).reshape(-1, w).T)
                             for k, w in (("lo", 3), ("hi", 3), ("err", len(FAR_STRIDES) - 1)))
                got = self.__dict__["_blk_cols"] = (self._blk["lo"], cols)
        return got[1]

    def block_strides(self, eye: npt.ArrayLike, pixel_scale: float, tile_strides: np.ndarray,
                      pixel_error: float = FAR_PIXEL_ERROR) -> np.ndarray:
        """The stride of every far block (:attr:`block_start`, :func:`far_blocks`) seen from ``eye``
        ``(3,)``: the coarsest whose error projects to at most ``pixel_error`` pixels at the block's
        nearest point (``pixel_scale`` pixels a radian), at least its tile's ``tile_strides (n,)``
        (:meth:`far_strides`, by the tile's largest error at its nearest point); ``(nb,)`` int."""
        eye = np.asarray(eye, dtype=np.float64).reshape(3)
        lo, hi, err = self.block_columns()
        d2 = np.zeros(lo.shape[1])
        for j in range(3):  # (by columns: a million-patch world has ~16k blocks)
            q = np.maximum(lo[j] - eye[j], eye[j] - hi[j])
            np.maximum(q, 0.0, out=q)
            d2 += q * q
        allowed = np.sqrt(d2) * pixel_error / max(float(pixel_scale), 1e-9)
        out = np.ones(lo.shape[1], np.int64)
        for j, k in enumerate(FAR_STRIDES[1:]):
            out[err[j] <= allowed] = k
        return np.maximum(out, np.repeat(np.asarray(tile_strides, np.int64), np.diff(self.block_start)))

    def morph_factors(self, eye: npt.ArrayLike, pixel_scale: float, pixel_error: float | None) -> dict:
        """Geomorph factor of every resident near or middle tile seen from ``eye``: ``{tile: f}``,
        f = clamp(e / pixel_error - 1, 0, 1) where e is the pixels the coarser level's error
        (:attr:`mid_error` under a near mesh, :attr:`chord_error` under a middle one) projects to at
        the tile's nearest point.  A tile changes level where its error crosses ``pixel_error``
        (:meth:`update`), exactly where its mesh is drawn fully morphed (f = 0) onto the coarser
        level, so switching levels does not pop; ``pixel_error`` None: 1 (no morphing)."""
        with self._lock:
            level = dict(self.near_level)
        if pixel_error is None or not level:
            return {t: 1.0 for t in level}
        e = [float(x) for x in np.asarray(eye, dtype=np.float64).reshape(3)]
        out = {}
        for t, k in level.items():  # (a few tiles: plain floats)
            i = self.tile_index.get(t)
            if i is None:
                continue
            lo, hi = self.lo[i].tolist(), self.hi[i].tolist()
            d = math.sqrt(sum(max(a - x, x - b, 0.0) ** 2 for a, b, x in zip(lo, hi, e)))
            err = self.mid_error[t] if k > MID_SAMPLES else self.chord_error[t]
            px = err * float(pixel_scale) / max(d, 1e-9)
            out[t] = min(max(px / float(pixel_error) - 1.0, 0.0), 1.0)
        return out

    def draw_list(self, eye: npt.ArrayLike | None = None, mask: np.ndarray | None = None, pixel_scale: float | None = None,
                  pixel_error: float = FAR_PIXEL_ERROR) -> list:
        """``[(tile, level, TileMesh)]``: a near mesh where one is resident, else the far one at the
        stride for ``eye`` (``"far1"``, ``"far2"``, ...; the full corner grid without ``eye``):
        by screen error with ``pixel_scale`` (:meth:`far_strides` at ``pixel_error`` pixels), else by
        distance (:meth:`far_stride`); ``mask (n,)`` bool keeps only those of :attr:`tiles`."""
        with self._lock:
            near = dict(self.near)
            level = dict(self.near_level)
        if eye is not None and pixel_scale is not None:
            strides = self.far_strides(eye, pixel_scale, pixel_error)
        elif eye is not None:
            d = self.distances(eye) / self.far_lod_distance
            strides = np.select([d < k for k in FAR_STRIDES[:-1]], FAR_STRIDES[:-1], FAR_STRIDES[-1])
        else:
            strides = np.ones(len(self.tiles), int)
        out = []
        for i in (range(len(self.tiles)) if mask is None else np.nonzero(mask)[0]):
            t = self.tiles[i]
            if t in near:
                out.append((t, "near" if level.get(t) == self.near_samples else "mid", near[t]))
            else:
                k = int(strides[i])
                out.append((t, f"far{k}", self.far[t][k]))
        return out

    def close(self) -> None:
        self._stop = True
        self._queue.put((-1.0, -1, None))
        self._thread.join(timeout=5)


def world_fog_density(cache: TileCache) -> float:
    """The fog a bundle of the same terrain gets (:func:`piste.render.frame.scene_fog_density`:
    the default density, thinner for worlds larger than the default course), per metre."""
    diag = float(np.hypot(*(cache.hi[:, :2].max(0) - cache.lo[:, :2].min(0)))) if len(cache.tiles) else 1.0
    return DEFAULT_FOG_DENSITY * min(1.0, FOG_REFERENCE_SIZE / max(diag, 1e-9))


@functools.lru_cache(maxsize=64)
def _patch_blocks(ny: int, nx: int) -> np.ndarray:
    """The far block of each patch of a ``(ny, nx)``-patch tile (row-major): ``(ny nx,)`` int64, read-only."""
    bx = -(-nx // FAR_BLOCK)
    out = ((np.arange(ny) // FAR_BLOCK)[:, None] * bx + (np.arange(nx) // FAR_BLOCK)[None, :]).reshape(-1)
    out.flags.writeable = False
    return out


def _boxes_visible(planes: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Axis-aligned boxes ``lo, hi (n, 3)`` against inward frustum planes ``(6, 4)`` (the positive
    vertex test): ``(n,)`` bool, False only for boxes wholly outside one plane."""
    n = np.asarray(planes, dtype=np.float64)[:, :3]  # each box's corner furthest along a plane's normal:
    far = hi @ np.maximum(n, 0.0).T + lo @ np.minimum(n, 0.0).T  # (n, 6), without an (n, 6, 3) temporary
    return (far + np.asarray(planes, dtype=np.float64)[:, 3] >= 0.0).all(-1)


def _boxes_visible_cols(planes: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                        bound: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """:func:`_boxes_visible` of boxes given by columns, ``lo, hi (3, n)`` float64 (contiguous):
    plane by plane on whole columns (no matrix products: ~2x faster on a tile's 4,096 patches).
    ``bound``: ``(lo, hi) (3,)`` a box holding them all: a plane it lies wholly inside is not tested
    box by box (every box is inside it), and one it lies wholly outside culls them all (the same
    answer as without it)."""
    out = np.ones(lo.shape[1], bool)
    pl = np.asarray(planes, dtype=np.float64)
    if bound is not None:
        blo, bhi = bound
        n = pl[:, :3]
        near = (np.where(n > 0, blo, bhi) * n).sum(1)  # each plane's value at the bound's nearest and
        far = (np.where(n > 0, bhi, blo) * n).sum(1)  # farthest corners (monotone: no box beyond them)
        if (far < -pl[:, 3]).any():
            return np.zeros(lo.shape[1], bool)
        pl = pl[near < -pl[:, 3]]
    for nx, ny, nz, w in pl:
        f = (hi[0] if nx > 0 else lo[0]) * nx
        f += (hi[1] if ny > 0 else lo[1]) * ny
        f += (hi[2] if nz > 0 else lo[2]) * nz
        out &= f >= -w
    return out


class StreamingRenderer:
    """Renders a tiled world through a :class:`TileCache` (headless EGL by default).

    Parameters
    ----------
    root : the tiled world folder
    size : (width, height)
    budget_bytes, near_radius, near_samples, object_distance : see :class:`TileCache`
    background : clear colour (RGB 0..1); the sky colour by default
    fog_density : per metre, towards the sky's horizon colour, per vertex like the course
        (default: :func:`piste.render.frame.scene_fog_density` of the world's extent, what a bundle of
        the same terrain uses); the tiles also fade to it over the last fifth of the far plane
    sky : draw the sky gradient (:class:`piste.render.sky_pass.SkyPass`) where no tile is
    pixel_error : tiles whose far grid would be off by more than this many pixels get near meshes
        (evaluated patches), nearest first under the budget; None: only those within ``near_radius``.
        The far tiles' blocks take the coarsest stride whose error fits it too (None:
        ``FAR_PIXEL_ERROR``; :attr:`far_pixel_error`); a number > 0
    visibility : near tiles draw only the patches their visibility sets (built with ``cell > 0``)
        say an eye over the tile and within the sets' band can see (:attr:`stats` ``vis_culled``)
    """

    def __init__(self, root, size=(640, 448), budget_bytes: int = 256 << 20, near_radius: float | None = None,
                 ctx=None, background=SKY, fog_density: float | None = None, sky: bool = True,
                 pixel_error: float | None = FAR_PIXEL_ERROR, visibility: bool = True, near_samples: int | None = None,
                 object_distance: float | None = None):
        if pixel_error is not None and (isinstance(pixel_error, bool) or not isinstance(pixel_error, (int, float, np.floating))
                                        or not 0.0 < float(pixel_error) < math.inf):
            raise ConfigError(f"{root}: pixel_error: expected a number of pixels > 0 (or None), got {pixel_error!r}")
        self.cache = TileCache(root, budget_bytes=budget_bytes, near_radius=near_radius, near_samples=near_samples,
                               object_distance=object_distance)
        self.ctx = ctx or create_context()
        self.size = (int(size[0]), int(size[1]))
        self.fbo = Offscreen(self.ctx, self.size)
        self.prog = self.ctx.program(vertex_shader=_VERT, fragment_shader=_FRAG)
        self.background = tuple(float(c) for c in background)
        self.pixel_error = None if pixel_error is None else float(pixel_error)
        self.fog_density = world_fog_density(self.cache) if fog_density is None else float(fog_density)
        self.sky = None
        if sky:
            self.sky = SkyPass(self.ctx)
        import moderngl

        snow = snow_texture()  # the course's base texture, filtered as terrain_pass does
        self.base = mipmapped_texture(self.ctx, np.concatenate([snow[..., :3], np.full(snow.shape[:2] + (1,), 255,
                                                                                         np.uint8)], 2))
        self.base.filter = (moderngl.LINEAR_MIPMAP_NEAREST, moderngl.LINEAR)
        self.base.repeat_x = self.base.repeat_y = True
        g = self.cache.grid
        s = g.samples_per_patch
        self._patch = (1.0 / (s * g.spacing[0]), 1.0 / (s * g.spacing[1]))
        self._lights: dict = {}  # tile -> its light-map texture
        self._gpu: dict = {}  # (tile, level) -> (vbo_pos, ibo, vao, mesh id, vbo_targets or None)
        self._vis_gpu: dict = {}  # ((tile, level), mesh id, packed set) -> (ibo, vao, triangles)
        #: near tiles draw only the patches their visibility sets say the eye can see
        self.visibility = bool(visibility)
        #: a middle tile draws the patches whose far-grid error is under ``pixel_error`` on screen
        #: (at the nearest point of the patch) from its full corner grid, the others from its middle
        #: mesh, geomorphed per vertex (fully onto the corner grid wherever it meets a far patch: no
        #: cracks, no pops); one indirect multi-draw a mesh (``glMultiDrawElementsIndirect``, GL 4.3;
        #: :attr:`stats` ``mid_far_patches``)
        self.mix_levels = self.ctx.version_code >= 430
        self._boxes: dict = {}  # (tile, level) -> (mesh id, patch_boxes)
        self._indirect = None  # the frame's indirect draw commands
        #: tile -> (key: its blocks' and neighbours' strides and its blocks in view, [(stride, "far" or
        #: "zip", commands, triangles)], blocks out of view); (tile, stride) -> (key: that stride's blocks
        #: in view and their neighbours' strides, its part of those draws)
        self._far_runs: dict = {}
        self._glue: dict = {}  # (tile, level) -> (index buffer, vertex array, mesh id, glued sides packed, triangles)
        #: far tiles drawn by block draw each stride's runs from one index list of their own
        #: (:meth:`_far_index_draws`); False: by a multi-draw of the runs
        self.far_indices = True
        self._far_gpu: dict = {}  # (tile, stride) -> (index buffer, vertex array, mesh id)
        #: near and middle tiles test the box holding their patches first: against the frustum's
        #: planes (those holding it whole are not tested patch by patch) and against the pixel error
        #: (a tile whose largest corner-grid error fits at its nearest point is drawn wholly from the
        #: corner grid); False: every patch on its own (the same draws, slower)
        self.tile_bounds = True
        self._coarse_runs: dict = {}  # tile -> ((strides, in view), [(job, commands)]): a near tile's far blocks
        self.stats: dict = {}

    def _light(self, t):
        """The GL texture of tile ``t``'s welded light map (made on first use), and its uniforms."""
        import moderngl

        got = self._lights.get(t)
        if got is None:
            img = self.cache.light[t]
            h, w = img.shape[:2]
            tex = self.ctx.texture((w, h), 3, np.ascontiguousarray(img).tobytes(), alignment=1)
            tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
            tex.repeat_x = tex.repeat_y = False
            r = self.cache.res - 1
            x0, y0, _, _ = self.cache.grid.tile_bounds_xy(*t)
            got = self._lights[t] = (tex, (float(x0), float(y0)), (r / w, r / h, 0.5 / w, 0.5 / h))
        return got

    def _vao(self, key, mesh: TileMesh):
        got = self._gpu.get(key)
        if got is not None and got[3] == id(mesh):
            return got[2]
        if got is not None:
            self._release(key)
        pos = self.ctx.buffer(np.ascontiguousarray(mesh.positions))
        ibo = self.ctx.buffer(np.ascontiguousarray(mesh.indices))
        extra = [(self.ctx.buffer(np.ascontiguousarray(a)), fmt, name)
                 for a, fmt, name in ((mesh.targets, "1f", "in_target"), (mesh.corner, "1f", "in_corner"),
                                      (mesh.errors, "2f", "in_err")) if a is not None]
        vao = self.ctx.vertex_array(self.prog, self._attributes(pos, extra), index_buffer=ibo, index_element_size=4)
        self._gpu[key] = (pos, ibo, vao, id(mesh), extra)
        return vao

    @staticmethod
    def _attributes(pos, extra: list) -> list:
        """The vertex arrays' attributes: positions and a near or middle mesh's geomorph heights and
        errors ``extra`` (a far mesh has none: drawn with u_morph = 1, u_verr = 0)."""
        return [(pos, "3f", "in_pos")] + list(extra)

    def _patch_boxes(self, key, mesh: TileMesh):
        """:func:`patch_boxes` of a resident mesh and its :func:`patch_corner_errors` (made once while
        the mesh stays resident): ``(centre, half extent, errors or None, low corner, high corner)``,
        each ``(3, n)`` float64 by columns (contiguous, :func:`_boxes_visible_cols`), and ``(low,
        high) (3,)`` the box holding them all (:meth:`_patch_bound`)."""
        got = self._boxes.get(key)
        if got is None or got[0] != id(mesh):
            py0, py1, px0, px1 = self.cache.grid.patch_range(*key[0])
            shape = (py1 - py0, px1 - px0)
            boxes = patch_boxes(mesh, shape)  # (drawn this way only with them: a patch-major mesh)
            assert boxes is not None, f"tile {key[0]}: its {key[1]} mesh is not patch-major"
            c, h = boxes
            cols = [np.ascontiguousarray(a.T, dtype=np.float64) for a in (c, h, c - h, c + h)]
            got = self._boxes[key] = (id(mesh), (cols[0], cols[1], patch_corner_errors(mesh, shape), cols[2], cols[3],
                                                 (cols[2].min(1), cols[3].max(1))))
        return got[1]

    def _block_shape(self, t) -> tuple[int, int]:
        """``(by, bx)``: the far blocks of tile ``t``."""
        shapes = self.__dict__.setdefault("_bshape", {})
        got = shapes.get(t)
        if got is None:
            py0, py1, px0, px1 = self.cache.grid.patch_range(*t)
            got = shapes[t] = (-(-(py1 - py0) // FAR_BLOCK), -(-(px1 - px0) // FAR_BLOCK))
        return got

    def _block_grid(self) -> tuple:
        """Where every far block of :attr:`TileCache.tiles` lies in the world's grid of blocks (tile
        ``(ty, tx)``'s block ``(r, c)`` at row ``ty B + r``, column ``tx B + c``, ``B`` blocks a full
        tile side, one empty row and column around): ``(flat index (nb,) int64, grid shape, {tile:
        (row, column) of its first block})``, made once."""
        got = self.__dict__.get("_bgrid")
        if got is None:
            c = self.cache
            per = -(-c.grid.tile_patches // FAR_BLOCK)
            shape = (c.grid.shape[0] * per + 2, c.grid.shape[1] * per + 2)
            flat, first = [], {}
            for t in c.tiles:
                by, bx = self._block_shape(t)
                r0, c0 = t[0] * per + 1, t[1] * per + 1
                first[t] = (r0, c0)
                flat.append(((r0 + np.arange(by))[:, None] * shape[1] + (c0 + np.arange(bx))[None, :]).reshape(-1))
            flat_a = np.concatenate(flat).astype(np.int64) if flat else np.zeros(0, np.int64)
            got = self.__dict__["_bgrid"] = (flat_a, shape, first)
        return got

    def _border_grid(self, strides: np.ndarray, block_tiles: set) -> np.ndarray:
        """The world's grid of far blocks (:meth:`_block_grid`): each block's stride ``strides (nb,)``
        where its tile is among ``block_tiles`` (drawn by blocks this frame), else 0; ``(rows, cols)``
        int64, what :meth:`_border_strides` reads its neighbours' strides from."""
        flat, shape, _ = self._block_grid()
        g = np.zeros(shape, np.int64)
        if block_tiles:
            tm = np.zeros(len(self.cache.tiles), bool)
            tm[[self.cache.tile_index[t] for t in block_tiles]] = True
            bm = np.repeat(tm, np.diff(self.cache.block_start))
            g.reshape(-1)[flat[bm]] = np.asarray(strides)[bm]
        return g

    def _block_ring(self, t, grid: np.ndarray) -> np.ndarray:
        """Tile ``t``'s blocks in ``grid`` (:meth:`_border_grid`) with the ring of its neighbours'
        blocks along its sides around them (the corners, diagonal neighbours, 0): ``(by + 2, bx + 2)``
        int64, a copy (what a far tile's draws depend on besides which blocks are in view)."""
        (r0, c0), (by, bx) = self._block_grid()[2][t], self._block_shape(t)
        ring = grid[r0 - 1:r0 + by + 1, c0 - 1:c0 + bx + 1].copy()
        ring[::by + 1, ::bx + 1] = 0
        return ring

    def _border_strides(self, t, strides: np.ndarray, block_tiles: set, grid: np.ndarray | None = None) -> tuple:
        """The strides ``(bx,), (by,), (bx,), (by,)`` of the blocks of tile ``t``'s south, east, north
        and west neighbours along its sides (:func:`block_runs`' ``border``), 0 where a neighbour is
        not among ``block_tiles`` (drawn by blocks this frame) or its blocks do not line up;
        ``strides`` every block's (:meth:`TileCache.block_strides`); ``grid``: :meth:`_border_grid`
        of them (sliced instead of looking at each neighbour: the same strides)."""
        by, bx = self._block_shape(t)
        if grid is not None:
            ring = self._block_ring(t, grid)
            return ring[0, 1:-1], ring[1:-1, -1], ring[-1, 1:-1], ring[1:-1, 0]
        ty, tx = t
        out = []
        for (dy, dx), n, edge in (((-1, 0), bx, lambda g: g[-1]), ((0, 1), by, lambda g: g[:, 0]),
                                  ((1, 0), bx, lambda g: g[0]), ((0, -1), by, lambda g: g[:, -1])):
            nt = (ty + dy, tx + dx)
            e = None
            if nt in block_tiles:
                j = self.cache.tile_index[nt]
                e = edge(strides[self.cache.block_start[j]:self.cache.block_start[j + 1]].reshape(self._block_shape(nt)))
            out.append(np.asarray(e, np.int64) if e is not None and len(e) == n else np.zeros(n, np.int64))
        return tuple(out)

    def _coarse_blocks(self, t, coarse: np.ndarray, blocks: tuple, every: bool = False) -> tuple:
        """The blocks of near or middle tile ``t`` whose patches are all ``coarse (n,) bool`` (every
        vertex fully on the corner grid) and whose far stride (``blocks``: every block's stride and
        whether it is in view, :meth:`draw`'s) is coarser than 1, drawn like a far tile's blocks; the
        other blocks' edges there are the corner grid's (its patches, or mesh patches glued to them),
        so the corner grid's zippers join them exactly.  ``(patches (n,) bool`` so drawn, ``[((t, kind,
        mesh, vertex array), commands)])``.  ``every``: ``coarse`` is all True (told, not counted)."""
        py0, py1, px0, px1 = self.cache.grid.patch_range(*t)
        ny, nx = py1 - py0, px1 - px0
        by, bx = -(-ny // FAR_BLOCK), -(-nx // FAR_BLOCK)
        pb = _patch_blocks(ny, nx)
        i = self.cache.tile_index[t]
        sl = slice(self.cache.block_start[i], self.cache.block_start[i + 1])
        if every:
            full = blocks[0][sl] > 1
        else:
            full = (np.bincount(pb, weights=~np.asarray(coarse, bool), minlength=by * bx) == 0) & (blocks[0][sl] > 1)
        out: list = []
        if not full.any():
            return np.zeros(ny * nx, bool), out
        st = np.where(full, blocks[0][sl], 1)  # (the others' edges: the corner grid's)
        vis = blocks[1][sl] & full
        ckey = (st.tobytes(), vis.tobytes())
        got = self._coarse_runs.get(t)
        if got is not None and got[0] == ckey:
            return full[pb], got[1]
        for k in FAR_STRIDES[1:]:
            if (vis & (st == k)).any():
                fk = self.cache.far[t][k]
                main, zips = block_runs(fk, (ny, nx), st, vis, k)
                vao = self._vao((t, f"far{k}"), fk)
                out += [((t, what, fk, vao), cmd) for what, cmd in (("far", main), ("zip", zips)) if len(cmd)]
        pad = _pad1(st.reshape(by, bx))
        other = np.stack([pad[:-2, 1:-1], pad[1:-1, 2:], pad[2:, 1:-1], pad[1:-1, :-2]], -1)  # south, east, north, west
        f1 = self.cache.far[t][1]
        z = zip_runs(f1, ~full, other, 1)
        if len(z):
            out.append(((t, "zip", f1, self._vao((t, "far1"), f1)), z))
        self._coarse_runs[t] = (ckey, out)
        return full[pb], out

    def _far_index_draws(self, t, draws: list) -> list:
        """Far tile ``t``'s ``draws`` ``[(stride, "far" or "zip", commands, triangles)]`` with each
        stride's commands gathered into one index list (:func:`command_indices`) in the tile's index
        buffer of that stride (rewritten when they change; grown when short), its commands replaced
        by ``(vertex array, first index, indices)``: one glDrawElements a stride and kind instead of
        a multi-draw of tens of runs (llvmpipe sets up every draw of a multi-draw on its own)."""
        out = []
        for k in sorted({d[0] for d in draws}):
            mine = [d for d in draws if d[0] == k]
            fk = self.cache.far[t][k]
            parts = [command_indices(fk.indices, cmd) for _, _, cmd, _ in mine]
            data = np.concatenate(parts).tobytes()
            self._vao((t, f"far{k}"), fk)  # the vertex buffers
            got = self._far_gpu.get((t, k))
            if got is None or got[2] != id(fk) or got[0].size < len(data):
                if got is not None:
                    got[1].release()
                    got[0].release()
                ibo = self.ctx.buffer(reserve=max(2 * len(data), 4096), dynamic=True)
                g = self._gpu[(t, f"far{k}")]
                vao = self.ctx.vertex_array(self.prog, self._attributes(g[0], g[4]), index_buffer=ibo,
                                            index_element_size=4)
                got = self._far_gpu[(t, k)] = (ibo, vao, id(fk))
            got[0].write(data)
            at = 0
            for (_, what, _, ntri), idx in zip(mine, parts):
                out.append((k, what, (got[1], at, len(idx)), ntri))
                at += len(idx)
        return out

    def _glue_vao(self, key, mesh: TileMesh, glued: np.ndarray):
        """A vertex array drawing near or middle ``mesh``'s patches with sides ``glued (ny, nx, 4)
        bool`` (:func:`glue_indices`) through the mesh's vertex buffers, its index buffer rewritten
        when they change (grown when short); ``(vertex array, triangles)``."""
        self._vao(key, mesh)  # the vertex buffers
        got = self._glue.get(key)
        mark = np.packbits(glued).tobytes()
        if got is not None and got[2] == id(mesh) and got[3] == mark:
            return got[1], got[4]
        py0, py1, px0, px1 = self.cache.grid.patch_range(*key[0])
        idx = glue_indices(mesh, (py1 - py0, px1 - px0), glued)
        data = np.ascontiguousarray(idx, dtype=np.uint32).tobytes()
        if got is None or got[2] != id(mesh) or got[0].size < len(data):
            if got is not None:
                got[1].release()
                got[0].release()
            ibo = self.ctx.buffer(reserve=max(2 * len(data), 4096), dynamic=True)
            g = self._gpu[key]
            vao = self.ctx.vertex_array(self.prog, self._attributes(g[0], g[4]), index_buffer=ibo, index_element_size=4)
            got = (ibo, vao, id(mesh))
        got[0].write(data)
        self._glue[key] = (*got[:3], mark, len(idx))
        return got[1], len(idx)

    def _release(self, key) -> None:
        self._boxes.pop(key, None)
        glue = self._glue.pop(key, None)
        if glue is not None:
            glue[1].release()
            glue[0].release()
        got = self._gpu.pop(key)
        for obj in (got[2], got[1], got[0], *(b for b, _, _ in got[4])):
            obj.release()
        for k in [k for k in self._vis_gpu if k[0] == key]:
            for obj in self._vis_gpu.pop(k)[:2][::-1]:
                obj.release()

    def _vis_vao(self, key, mesh: TileMesh, seen: np.ndarray):
        """A vertex array drawing only the patches ``seen (n,) bool`` of near ``mesh`` (and its
        skirts): the mesh's positions with its own index buffer, kept while the mesh is resident."""
        self._vao(key, mesh)  # the positions
        vkey = (key, id(mesh), np.packbits(seen).tobytes())
        got = self._vis_gpu.get(vkey)
        if got is None:
            if len(self._vis_gpu) >= 32:  # a few cells' worth; the oldest go first
                for obj in self._vis_gpu.pop(next(iter(self._vis_gpu)))[:2][::-1]:
                    obj.release()
            py0, py1, px0, px1 = self.cache.grid.patch_range(*key[0])
            idx = visible_indices(mesh, seen, patch_order(py1 - py0, px1 - px0))
            ibo = self.ctx.buffer(idx)
            g = self._gpu[key]
            vao = self.ctx.vertex_array(self.prog, self._attributes(g[0], g[4]), index_buffer=ibo,
                                        index_element_size=4)
            got = self._vis_gpu[vkey] = (ibo, vao, len(idx))
        return got[1], got[2]

    def render(self, camera: Camera, wait: bool = False, read: bool = True) -> np.ndarray | None:
        """One frame from ``camera`` (:class:`piste.world.camera.Camera`): ``(H, W, 3)`` uint8.

        ``wait``: block until every wanted near tile is loaded first (offline rendering, tests);
        otherwise tiles still loading show their far stand-ins.  ``read=False`` leaves the image in
        the target (a window's screen) and returns None.
        """
        t0 = time.perf_counter()
        cam = camera.with_aspect(*self.size)
        self.update(cam, wait)
        return self.draw(cam, read, t0)

    @property
    def far_pixel_error(self) -> float:
        """The pixels of error the far tiles' and far blocks' strides may show
        (:meth:`TileCache.far_strides`, :meth:`TileCache.block_strides`): :attr:`pixel_error`, or
        ``FAR_PIXEL_ERROR`` where that is None (near meshes only within ``near_radius``)."""
        return FAR_PIXEL_ERROR if self.pixel_error is None else float(self.pixel_error)

    def lod_scale(self, fov_y: float) -> float:
        """Pixels a radian the levels' errors are counted in (``pixel_error`` pixels at this scale):
        the target's own, but at least a ``LOD_REFERENCE_LINES``-line frame's, so a smaller target
        keeps the same angular error (as the course's LOD thresholds are angles)."""
        return max(self.size[1], LOD_REFERENCE_LINES) / (2.0 * np.tan(np.radians(fov_y) / 2.0))

    def update(self, camera: Camera | _View, wait: bool = False) -> None:
        """Page tiles for ``camera`` (nearest first under the budget; scene objects by their own
        distance for this view, its far plane and the world's fog); ``wait``: until loaded."""
        far = getattr(camera, "far", None)
        scale = self.size[1] / (2.0 * np.tan(np.radians(camera.fov_y) / 2.0))
        if self.pixel_error is None:
            self.cache.update(camera.eye, far=far, fog_density=self.fog_density, object_scale=scale)
        else:
            self.cache.update(camera.eye, self.lod_scale(camera.fov_y), self.pixel_error, far=far,
                              fog_density=self.fog_density, object_scale=scale)
        if wait:
            self.cache.wait_idle()
        elif self.cache.errors:
            raise self.cache.errors[0]

    def draw(self, cam: Camera, read: bool = True, t0: float | None = None, sky: bool = True) -> np.ndarray | None:
        """Draw the resident tiles for ``cam`` (its aspect the target's) into :attr:`fbo`, cleared
        to the background (and the sky gradient over it with a sky pass and ``sky``); the image
        ``(H, W, 3) uint8`` with ``read``, else None (more passes follow)."""
        import moderngl

        t0 = time.perf_counter() if t0 is None else t0
        vp = cam.view_projection()
        planes = frustum_planes(vp)  # (cam.frustum_planes() computes vp again)
        self.fbo.use()
        self.fbo.clear((*self.background, 1.0))
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.CULL_FACE)
        self.prog["u_vp"].write(vp.astype(np.float32).T.tobytes())
        self.prog["u_eye"].value = tuple(float(x) for x in cam.eye)
        self.prog["u_fog"].value = (*HORIZON, self.fog_density)
        self.prog["u_fade"].value = (0.8 * cam.far, cam.far)
        self.prog["u_patch"].value = self._patch
        self.prog["u_base"].value = 0
        self.prog["u_light"].value = 1
        self.base.use(0)
        drawn = {"near": 0, "far": 0, "culled": 0, "near_patches": 0, "far_patches": 0, "triangles": 0,
                 "vis_culled": 0, "mid": 0}
        live = set()
        visible = _boxes_visible(planes, self.cache.lo, self.cache.hi)
        drawn["culled"] = int((~visible).sum())
        pixel_scale = self.lod_scale(cam.fov_y)
        morph = self.cache.morph_factors(cam.eye, pixel_scale, self.pixel_error)
        far_error = self.far_pixel_error  # the far tiles' and blocks' strides
        todo = self.cache.draw_list(cam.eye, visible, pixel_scale=pixel_scale, pixel_error=far_error)
        if len(todo) > 1:  # nearest first: what they hide fails the depth test before it is shaded
            dist = self.cache.distances(cam.eye)[[self.cache.tile_index[t] for t, _, _ in todo]]
            todo = [todo[i] for i in np.argsort(dist, kind="stable")]
        order = {t: i for i, (t, _, _) in enumerate(todo)}  # (the jobs of a tile together, in this order)
        sets = self.visibility and self.cache.sets_hold(cam.eye, {t: level for t, level, _ in todo})
        drawn["vis_off"] = int(self.visibility and not sets)  # the sets' tiles drawn too coarse this frame
        drawn["mid_far_patches"] = drawn["frustum_culled"] = drawn["bound_coarse"] = 0
        # the per-vertex geomorph: pixels on screen of a metre of error at 1 m, over the limit
        err_scale = pixel_scale / self.pixel_error if self.pixel_error else None
        e = np.asarray(cam.eye, dtype=np.float64).reshape(3)
        blocks = None  # far tiles by block: every block's stride and whether its box is in view
        drawn["far_blocks"] = drawn["far_blocks_culled"] = drawn["far_block_triangles"] = 0
        if self.mix_levels and len(self.cache.tiles):
            blo, bhi, _ = self.cache.block_columns()
            blocks = (self.cache.block_strides(e, pixel_scale, self.cache.far_strides(e, pixel_scale, far_error), far_error),
                      _boxes_visible_cols(planes, blo, bhi))
        jobs, commands, ncmd = [], [], 0  # what each tile draws (all the indirect commands first)
        seen_of = {t: self.cache.visible_patches(t, cam.eye) if sets and (not level.startswith("far") or level == "far1")
                   else None for t, level, _ in todo}
        block_tiles = set() if blocks is None else {  # the far tiles drawn by block
            t for t, level, mesh in todo if level.startswith("far") and seen_of[t] is None and mesh.blocks is not None}
        bgrid = self._border_grid(blocks[0], block_tiles) if block_tiles else None
        for t, level, mesh in todo:
            key = (t, level)
            live.add(key)
            kind = "far" if level.startswith("far") else "near"  # near and mid: evaluated patches
            drawn["mid"] += level == "mid"
            drawn[kind] += 1
            seen = seen_of[t]
            # near and middle meshes: geomorphed per vertex by the errors of the patches around it
            verr = err_scale if kind == "near" and t in morph and err_scale and mesh.errors is not None else 0.0
            if t in block_tiles:
                # a far tile: each block at its own stride (:meth:`TileCache.block_strides`), those in view
                i = self.cache.tile_index[t]
                st = blocks[0][self.cache.block_start[i]:self.cache.block_start[i + 1]]
                vis = blocks[1][self.cache.block_start[i]:self.cache.block_start[i + 1]]
                # (its blocks' strides and its neighbours' along its sides: the grid around it, corners cleared)
                ring = self._block_ring(t, bgrid)
                bkey = (ring.tobytes(), np.packbits(vis).tobytes())
                got = self._far_runs.get(t)
                if got is None or got[0] != bkey:
                    border = (ring[0, 1:-1], ring[1:-1, -1], ring[-1, 1:-1], ring[1:-1, 0])
                    other = np.stack([ring[:-2, 1:-1], ring[1:-1, 2:], ring[2:, 1:-1], ring[1:-1, :-2]], -1).reshape(-1, 4)
                    py0, py1, px0, px1 = self.cache.grid.patch_range(*t)
                    draws = []
                    for k in FAR_STRIDES:  # a stride's draws depend only on its blocks in view and their neighbours
                        sel = vis & (st == k)
                        if not sel.any():
                            continue
                        kkey = (np.packbits(sel).tobytes(), other[sel].tobytes())
                        gk = self._far_runs.get((t, k))
                        if gk is None or gk[0] != kkey:
                            pair = block_runs(self.cache.far[t][k], (py1 - py0, px1 - px0), st, vis, k, border)
                            dk = [(k, what, cmd, int(cmd[:, 0].sum()) // 3)  # (the zippers two-sided)
                                  for what, cmd in zip(("far", "zip"), pair) if len(cmd)]
                            if self.far_indices and dk:  # one list of indices (kept while they stay)
                                dk = self._far_index_draws(t, dk)
                            gk = self._far_runs[(t, k)] = (kkey, dk)
                        draws += gk[1]
                    got = self._far_runs[t] = (bkey, draws, len(vis) - int(np.count_nonzero(vis)))
                for k, what, cmd, ntri in got[1]:
                    fk = self.cache.far[t][k]
                    if isinstance(cmd, tuple):  # (vertex array, first index, indices) of :meth:`_far_index_draws`
                        jobs.append((t, what, fk, cmd[0], ("at", cmd[1], cmd[2]), 0.0))
                    else:
                        jobs.append((t, what, fk, self._vao((t, f"far{k}"), fk), (ncmd, len(cmd)), 0.0))
                        commands.append(cmd)
                        ncmd += len(cmd)
                    drawn["triangles"] += ntri
                    drawn["far_block_triangles"] += ntri
                drawn["far_patches"] += self.cache.patches[t]
                drawn["far_blocks"] += int(len(st))
                drawn["far_blocks_culled"] += got[2]
                continue
            if not (self.mix_levels and mesh.patch_triangles and (verr or level == "far1")):
                if seen is not None and mesh.patch_triangles and not seen.all():
                    vao, ntri = self._vis_vao(key, mesh, seen)
                    jobs.append((t, kind, mesh, vao, -1, verr))
                    drawn[f"{kind}_patches"] += int(seen.sum())
                    drawn["vis_culled"] += int((~seen).sum())
                    drawn["triangles"] += ntri
                else:
                    jobs.append((t, kind, mesh, self._vao(key, mesh), None, verr))
                    drawn[f"{kind}_patches"] += self.cache.patches[t]
                    drawn["triangles"] += mesh.whole_triangles
                continue
            # per patch, like the course's error-driven levels: out of the frustum (or the sets), not
            # drawn; where the corner grid's error fits pixel_error pixels at the patch's box (every
            # vertex of it fully morphed onto the corner grid), drawn from the corner grid; else from
            # the mesh, each vertex between the levels by its own error on screen
            vao = self._vao(key, mesh)
            py0, py1, px0, px1 = self.cache.grid.patch_range(*t)
            po = patch_order(py1 - py0, px1 - px0)  # the mesh's patch order
            c, h, perr, blo, bhi, bound = self._patch_boxes(key, mesh)
            inside = _boxes_visible_cols(planes, blo, bhi, bound if self.tile_bounds else None)
            drawn["frustum_culled"] += int((~inside).sum())
            if seen is not None:
                drawn["vis_culled"] += int((~seen).sum())
                inside &= seen
            drawn[f"{kind}_patches"] += self.cache.patches[t] - (0 if seen is None else int((~seen).sum()))
            if not verr:  # a full corner grid: its patches in view
                mine = patch_runs(inside, mesh.patch_triangles, mesh.whole_triangles, order=po)
                jobs.append((t, kind, mesh, vao, (ncmd, len(mine)), 0.0))
                commands.append(mine)
                ncmd += len(mine)
                drawn["triangles"] += int(mine[:, 0].sum()) // 3
                continue
            # (the tile's largest error fitting at its bound, with a margin for rounding: every patch's
            # own test would pass, each patch's box being no nearer)
            q3 = np.maximum(np.maximum(bound[0] - e, e - bound[1]), 0.0)
            if self.tile_bounds and (float(perr.max()) * verr) ** 2 * (1.0 + 1e-9) <= float(q3 @ q3) * (1.0 - 1e-9):
                coarse = np.ones(len(perr), bool)
                drawn["bound_coarse"] += 1
            else:
                d2 = 0.0  # squared metres to each patch's box
                for j in range(3):
                    q = np.abs(c[j] - e[j])
                    q -= h[j]
                    np.maximum(q, 0.0, out=q)
                    d2 = d2 + q * q
                coarse = (perr * verr) ** 2 <= d2
            every = bool(coarse.all())
            far = self.cache.far[t][1]
            if seen is None and blocks is not None:  # blocks wholly on the corner grid at a coarser stride
                own, bjobs = self._coarse_blocks(t, coarse, blocks, every)
                for job, cmd in bjobs:
                    jobs.append((*job, (ncmd, len(cmd)), 0.0))
                    commands.append(cmd)
                    ncmd += len(cmd)
                    drawn["triangles"] += int(cmd[:, 0].sum()) // 3
                inside = inside & ~own
            # the mesh's patches beside a corner-grid patch are glued to its edge (:func:`glue_indices`)
            ny, nx = py1 - py0, px1 - px0
            gl = np.zeros(ny * nx, bool)
            if not every:  # (every patch on the corner grid: none to glue)
                cg = _pad1(coarse.reshape(ny, nx))  # (a neighbour beyond the tile's border: not coarse)
                fine = (inside & ~coarse).reshape(ny, nx)
                sides = (cg[:-2, 1:-1], cg[1:-1, 2:], cg[2:, 1:-1], cg[1:-1, :-2])  # south, east, north, west
                gl = (fine & (sides[0] | sides[1] | sides[2] | sides[3])).reshape(-1)
            if gl.any():
                glued = fine[..., None] & np.stack(sides, -1)
                gvao, ntri = self._glue_vao(key, mesh, glued)
                jobs.append((t, kind, mesh, gvao, 3 * ntri, verr))
                drawn["triangles"] += ntri
            mine = patch_runs(inside & ~coarse & ~gl, mesh.patch_triangles, mesh.whole_triangles, order=po)  # + skirts
            grid = patch_runs(inside & coarse, far.patch_triangles, len(far.indices), skirts=False, order=po)
            live.add((t, "far1"))
            jobs.append((t, kind, mesh, vao, (ncmd, len(mine)), verr))
            jobs.append((t, "far", far, self._vao((t, "far1"), far), (ncmd + len(mine), len(grid)), 0.0))
            commands += [mine, grid]
            ncmd += len(mine) + len(grid)
            drawn["mid_far_patches"] += int((inside & coarse).sum())
            drawn["triangles"] += (int(mine[:, 0].sum()) + int(grid[:, 0].sum())) // 3
        drawn["commands"] = ncmd  # indirect draw commands (runs) this frame
        if commands:
            data = np.concatenate(commands).tobytes()
            if self._indirect is None or self._indirect.size < len(data):
                if self._indirect is not None:
                    self._indirect.release()
                self._indirect = self.ctx.buffer(reserve=max(2 * len(data), 4096), dynamic=True)
            self._indirect.write(data)
        # back faces culled (a height field seen from above hides its back faces behind front ones;
        # skirts face out of their tile, :func:`_border_sides`; zippers are drawn two-sided)
        self.ctx.front_face, self.ctx.cull_face = "ccw", "back"
        self.ctx.enable(moderngl.CULL_FACE)
        culling = True
        last: tuple = (None, None, None)  # the tile, u_morph and u_verr set last (jobs of a tile come together)
        # a tile's zippers after its other draws (one culling switch a tile, not one a stride)
        jobs.sort(key=lambda j: j[1] == "zip")
        jobs.sort(key=lambda j: order.get(j[0], 0))
        u_origin, u_light_uv, u_morph, u_verr = (self.prog[n] for n in ("u_origin", "u_light_uv", "u_morph", "u_verr"))
        state = {"draws": 0, "light_binds": 0, "uniform_writes": 0, "cull_switches": 0}
        gl_s = 0.0  # seconds in the draw calls (the driver: llvmpipe shades and bins vertices there)
        for t, kind, mesh, vao, run, vmorph in jobs:
            if (kind != "zip") != culling:  # zippers are seen from both sides
                culling = not culling
                (self.ctx.enable if culling else self.ctx.disable)(moderngl.CULL_FACE)
                state["cull_switches"] += 1
            if t != last[0]:
                tex, origin, luv = self._light(t)
                tex.use(1)
                u_origin.value = origin
                u_light_uv.value = luv
                state["light_binds"] += 1
                state["uniform_writes"] += 2
            um = 1.0 if kind in ("far", "zip") or mesh.targets is None else morph.get(t, 1.0)
            if um != last[1]:
                u_morph.value = um
                state["uniform_writes"] += 1
            if vmorph != last[2]:
                u_verr.value = vmorph
                state["uniform_writes"] += 1
            last = (t, um, vmorph)
            state["draws"] += 1
            g0 = time.perf_counter()
            if isinstance(run, int):  # indices of a vertex array (a visibility set's, glued patches'; -1: all)
                vao.render(moderngl.TRIANGLES, vertices=run)
            elif run is None:  # a whole mesh
                vao.render(moderngl.TRIANGLES, vertices=3 * mesh.whole_triangles)
            elif run[0] == "at":  # indices [first, first + count) of the vertex array's own buffer
                vao.render(moderngl.TRIANGLES, vertices=run[2], first=run[1])
            elif run[1]:
                vao.render_indirect(self._indirect, moderngl.TRIANGLES, count=run[1], first=run[0])
            gl_s += time.perf_counter() - g0
        with self.cache._lock:
            resident = {t: id(m) for t, m in self.cache.near.items()}
        for key in [k for k in self._gpu if k[1] in ("near", "mid") and k not in live
                    and resident.get(k[0]) != self._gpu[k][3]]:
            self._release(key)  # evicted (or replaced) near tiles leave the GPU too
        self.ctx.disable(moderngl.CULL_FACE)
        if self.sky is not None and sky:
            g0 = time.perf_counter()
            self.sky.draw(vp)  # last: only where no tile was drawn
            gl_s += time.perf_counter() - g0
        image = self.fbo.read()[..., :3].copy() if read else None
        #: ``draw_ms``: the frame's draw calls (the tiles' and the sky's) as the driver took them
        self.stats = {**drawn, **state, "resident_bytes": self.cache.resident_bytes, "draw_ms": gl_s * 1e3,
                      "ms": (time.perf_counter() - t0) * 1e3}
        return image

    def close(self) -> None:
        for ibo, vao, _ in self._far_gpu.values():
            vao.release()
            ibo.release()
        self._far_gpu.clear()
        for key in list(self._gpu):
            self._release(key)
        for tex, _, _ in self._lights.values():
            tex.release()
        self._lights.clear()
        if self._indirect is not None:
            self._indirect.release()
            self._indirect = None
        self.base.release()
        self.prog.release()
        self.fbo.release()
        self.cache.close()


class StreamingTerrain:
    """A tiled world as the runtime's terrain: the interface of
    :class:`piste.render.frame.TerrainRenderer` that :class:`piste.render.scene_renderer.SceneRenderer`
    and :class:`piste.pipeline.preview.ScenePreview` draw with (``prepare``, ``draw``, ``render``,
    ``target``, ``ctx``, ``size``, ``levels``, ``set_visibility``, ``cull_stats``), so riders, objects
    and projected shadows are drawn over the streamed tiles by the same passes as on the course.

    Parameters
    ----------
    root : the tiled world folder
    net : the local :class:`~piste.terrain.net.PatchNet` the scene stands on (a tile and its
        neighbours: riders, objects, shadows); the shadow receivers are its patches tessellated at
        the tiles' light-map grid (the near meshes' vertices)
    size, ctx, budget_bytes, near_radius : see :class:`StreamingRenderer`
    wait : every frame waits for the tiles it wants (offline frames: the same picture whatever the
        loader's timing); False in a window (far stand-ins while tiles load)
    objects : the scene's objects as a :class:`piste.render.object_pass.ObjectGroups` (a tiled
        world's, :func:`piste.pipeline.tiles_source.open_tiles`), or None: the objects of the tiles
        paged in, one group a tile (key ``(ty, tx)``), added when a tile comes within its object
        distance (:meth:`TileCache.object_distances`: beyond the near and middle meshes, out to where
        its objects would be a pixel or two tall) and removed when it leaves (:meth:`page_objects`),
        so the object pass drawing the set draws the objects of the resident tiles.  Paged from the
        set's ``visible`` (whoever culls the objects pages the tiles for that view first: the culled
        set and the drawn one agree)
    object_distance : metres within which tiles' objects are paged (None: by their size on screen,
        :class:`TileCache`)
    pixel_error : the levels' and far blocks' error on screen, pixels (see :class:`StreamingRenderer`)
    """

    def __init__(self, root, net, size=(640, 448), ctx=None, budget_bytes: int = 256 << 20,
                 near_radius: float | None = None, wait: bool = True, objects=None,
                 object_distance: float | None = None, pixel_error: float | None = FAR_PIXEL_ERROR):
        self.streaming = StreamingRenderer(root, size=size, budget_bytes=budget_bytes, near_radius=near_radius,
                                           ctx=ctx, sky=True, object_distance=object_distance, pixel_error=pixel_error)
        self.objects = objects if objects is not None and hasattr(objects, "groups") else None
        self._paged_eye = None  # the eye the tiles were last paged for
        if self.objects is not None:
            self.streaming.cache.load_objects = True
            self.objects.on_visible = self._on_visible
        self.ctx = self.streaming.ctx
        self.net = net
        self.wait = bool(wait)
        #: the world's fog (what a bundle of the same terrain uses), what ``fog="scene"`` draws
        self.fog_density = self.streaming.fog_density
        self.visibility = None
        self.cull_stats: dict = {}
        self.level = max(int(self.streaming.cache.res), 2)

    @property
    def target(self) -> Offscreen:
        return self.streaming.fbo

    @target.setter
    def target(self, value: Offscreen) -> None:  # a window wraps its screen (render.window._wrap_screen)
        self.streaming.fbo = value

    @property
    def size(self) -> tuple[int, int]:
        return self.streaming.size

    def start_resident(self) -> None:
        """(Nothing to build: tiles load as the camera moves.)"""

    def set_visibility(self, visibility: Any = None) -> None:  # a pipeline Visibility (upward import: Any)
        """(The interface's; a tiled world's near tiles use their own per-tile sets, built with
        ``cell > 0``: :attr:`StreamingRenderer.visibility`.)"""
        self.visibility = visibility

    def levels(self, camera: Camera, lod: bool = True) -> int:
        return self.level

    def _update(self, cam) -> None:
        self.streaming.update(cam, wait=self.wait)
        self._paged_eye = tuple(float(x) for x in cam.eye)

    def _on_visible(self, planes, eye) -> None:
        """The object set's hook (:attr:`ObjectGroups.on_visible`): page the tiles for a view not
        paged yet (the eye ``(3,)``, the vertical field of view from the frustum's bottom and top
        ``planes``), then :meth:`page_objects`."""
        if eye is not None and tuple(float(x) for x in np.asarray(eye).reshape(3)) != self._paged_eye:
            cos = float(np.clip(np.dot(planes[2, :3], planes[3, :3]), -1.0, 1.0))
            fov = 180.0 - float(np.degrees(np.arccos(cos)))  # the inward normals of bottom and top: 180 - fov apart
            e = np.asarray(eye, dtype=np.float64).reshape(3)
            far = float(np.dot(planes[5, :3], e) + planes[5, 3])  # the eye's distance to the far plane
            if fov > 1e-6:
                self._update(_View(e, fov, far if far > 0.0 else None))
        self.page_objects()

    def page_objects(self) -> dict:
        """Make the object set's groups the objects of the tiles paged in now
        (:meth:`TileCache.resident_objects`): evicted tiles' groups removed, newly resident tiles'
        added; ``{"added": n, "removed": n, "tiles": n}``."""
        if self.objects is None:
            return {"added": 0, "removed": 0, "tiles": 0}
        res = {t: o for t, o in self.streaming.cache.resident_objects().items() if len(o[0])}
        gone = [k for k in self.objects.groups if k not in res]
        new = [t for t in sorted(res) if t not in self.objects.groups]
        self.objects.change({t: res[t] for t in new}, gone)  # (the set's arrays concatenated once)
        self.cull_stats.update(object_tiles=len(self.objects.groups), objects_resident=len(self.objects))
        return {"added": len(new), "removed": len(gone), "tiles": len(self.objects.groups)}

    def prepare(self, camera: Camera, lod: bool = True, levels: np.ndarray | int | None = None,
                timings: dict | None = None) -> TerrainMesh:
        """Page the tiles for ``camera`` and return the local net's patches in view, tessellated at
        the tiles' grid (a :class:`~piste.terrain.TerrainMesh`: the shadow receivers' triangles)."""
        t0 = time.perf_counter()
        cam = camera.with_aspect(*self.size)
        self._update(cam)
        pids = patch_tree(self.net).cull(cam.frustum_planes())
        self.cull_stats.update(frustum_patches=int(len(pids)), drawn_patches=int(len(pids)))
        t1 = time.perf_counter()
        mesh = tessellate(self.net, self.level, patches=pids)
        if timings is not None:
            timings.update(lod=0.0, cull=(t1 - t0) * 1e3, tessellate=(time.perf_counter() - t1) * 1e3)
        return mesh

    def draw(self, camera: Camera, mesh: TerrainMesh | None = None, lightmap_mode: str = "modulate", debug: str | None = None,
             fog: float | str | None = None, sky: bool = True, clear: tuple[float, float, float, float] | None = None, read: bool = True,
             timings: dict | None = None, resolve: bool = True, sync: bool = True) -> Frame:
        """Draw the streamed tiles like the course's terrain in modulate mode (base texture x light
        map; the other light-map and debug modes are not drawn differently), fogged with ``fog``
        (density per metre, "scene": :attr:`fog_density`, None or 0: none), the sky over the rest
        with ``sky``; a :class:`piste.render.frame.Frame`."""
        cam = camera.with_aspect(*self.size)
        t0 = time.perf_counter()
        density = self.fog_density if isinstance(fog, str) else float(fog or 0.0)
        self.streaming.fog_density, own = density, self.streaming.fog_density
        try:
            self.streaming.draw(cam, read=False, t0=t0, sky=sky)
        finally:
            self.streaming.fog_density = own
        if sync and not read:
            self.ctx.finish()
        t1 = time.perf_counter()
        image = self.streaming.fbo.read() if read else None  # (a fresh array; waits for the GL)
        st = self.streaming.stats
        self.cull_stats.update(near_tiles=st["near"], far_tiles=st["far"], resident_bytes=st["resident_bytes"],
                               vis_culled=st["vis_culled"])
        t = {"lod": 0.0, "cull": 0.0, "tessellate": 0.0, **(timings or {})}
        t.update(upload=0.0, draw=(t1 - t0) * 1e3, readback=(time.perf_counter() - t1) * 1e3)
        t["cpu"] = t["lod"] + t["cull"] + t["tessellate"]
        t["gpu"] = t["draw"] + t["readback"]
        t["total"] = t["cpu"] + t["gpu"]
        total = sum(self.streaming.cache.patches.values())
        kinds = {4: st["far_patches"], 6: 0, 8: st["near_patches"], 0: 0, -1: 0}
        return Frame(image, st["near_patches"] + st["far_patches"], total, kinds, st["triangles"],
                     0, t)

    def frame_mode(self, lightmap_mode: str = "modulate", debug: str | None = None) -> TerrainMode:
        """How a scene frame draws the streamed tiles: their own pass (see :meth:`draw`)."""
        return TerrainMode(self, lightmap_mode, debug)

    def render(self, camera: Camera, lod: bool = True, lightmap_mode: str = "modulate", debug: str | None = None,
               fog: float | str | None = "scene", read: bool = True, **_ignored: Any) -> Frame:
        """One frame of the tiles alone (:meth:`prepare` + :meth:`draw`)."""
        cam = camera.with_aspect(*self.size)
        self._update(cam)
        return self.draw(cam, read=read, fog=fog)

    def release(self) -> None:
        if self.objects is not None and self.objects.on_visible == self._on_visible:
            self.objects.on_visible = None
        self.streaming.close()


@dataclass
class _View:
    """What :meth:`StreamingRenderer.update` reads of a camera: its eye ``(3,)`` and ``fov_y`` degrees."""

    eye: np.ndarray
    fov_y: float
    far: float | None = None


def fly_path(index: dict, frames: int, fps: float = 30.0, speed: float = 100.0, height: float = 120.0,
             fov: float = 60.0, far: float | None = None) -> Iterator[Camera]:
    """Cameras of a straight flight across the world's diagonal at ``speed`` m/s, ``height`` m
    above the tiles' top, looking ahead and down."""
    g = TileGrid.from_dict(index["grid"])
    b = np.array([t["bounds"] for t in index["tiles"].values()])
    lo, hi = b[:, 0].min(0), b[:, 1].max(0)
    start = np.array([lo[0], lo[1], 0.0]) + 0.1 * (hi - lo)
    d = np.array([hi[0] - lo[0], hi[1] - lo[1], 0.0])
    d /= np.linalg.norm(d)
    z = hi[2] + height
    tile = g.tile_patches * g.samples_per_patch * max(g.spacing)
    far = far or max(4.0 * tile, 3000.0)
    for k in range(frames):
        eye = start + d * speed * k / fps
        eye[2] = z
        yield Camera(eye, eye + d * 400.0 - np.array([0.0, 0.0, 150.0]), fov_y=fov, near=1.0, far=far)


def render_flight(root: str | os.PathLike[str], out: str | os.PathLike[str] | None = None,
                  size: tuple[int, int] = (640, 448), frames: int = 1, fps: float = 30.0, speed: float = 100.0,
                  budget_mb: float = 256.0, video: str | os.PathLike[str] | None = None, wait: bool = True,
                  progress: bool = False, camera: Camera | None = None, pixel_error: float | None = FAR_PIXEL_ERROR) -> dict:
    """``piste render WORLD.tiles``: fly across a tiled world; PNG of the first frame, optional MP4.
    ``camera``: a :class:`~piste.world.camera.Camera` that stays put for every frame instead of the
    flight (:func:`fly_path`); ``pixel_error``: :class:`StreamingRenderer`'s.

    Returns ``{"frames", "ms" (per frame), "resident_mb" (max), "near", "far"}``.
    """
    import contextlib

    root = Path(root)
    if not root.is_dir():
        raise ConfigError(f"{root}: no such tiled world (build one: piste build SCENE with terrain.tiles)")
    if speed <= 0 or budget_mb <= 0:
        raise ConfigError(f"speed and budget must be > 0, got {speed} and {budget_mb}")
    r = StreamingRenderer(root, size=size, budget_bytes=int(budget_mb * 2**20), pixel_error=pixel_error)
    times, resident = [], []
    try:
        with contextlib.ExitStack() as stack:
            writer = None
            if video is not None:
                writer = stack.enter_context(VideoWriter(video, fps=int(fps)))
            cams = fly_path(r.cache.index, frames, fps, speed) if camera is None else (camera for _ in range(frames))
            if progress:
                from tqdm import tqdm

                cams = tqdm(cams, total=frames, desc="frames", unit="frame", leave=False)
            for k, cam in enumerate(cams):
                img = r.render(cam, wait=wait)
                times.append(r.stats["ms"])
                resident.append(r.stats["resident_bytes"])
                if k == 0 and out is not None:
                    save_png(out, img)
                if writer is not None:
                    writer.append(img)
        stats = dict(r.stats)
    finally:
        r.close()
    return {"frames": frames, "ms": times, "resident_mb": max(resident) / 2**20, "near": stats.get("near", 0),
            "far": stats.get("far", 0)}


def window_net(root: str | os.PathLike[str], cameras: list, size: tuple[int, int] = (640, 448)) -> PatchNet:
    """One :class:`piste.terrain.PatchNet` of a tiled world's fitted patches (the tiles' control
    points, bit for bit) whose boxes meet the frustum of any of ``cameras`` (each with its own far
    plane, its aspect set to ``size``): the surface a flight along them shows, as one net that the
    bundle runtime (:class:`piste.render.TerrainRenderer`) can draw.  Only tiles within the largest
    far plane of an eye (in x and y) are read.  ConfigError when no patch is in view."""
    store = TileStore(root)
    grid = store.grid()
    cams = [c.with_aspect(*size) for c in cameras]
    if not cams:
        raise ConfigError(f"{root}: window_net needs at least one camera")
    eyes = np.array([c.eye for c in cams], dtype=np.float64)
    reach = max(float(c.far) for c in cams)
    lo_xy, hi_xy = eyes[:, :2].min(0) - reach, eyes[:, :2].max(0) + reach
    planes = [c.frustum_planes() for c in cams]
    cps, uvs = [], []
    for t in grid.tiles():
        x0, y0, x1, y1 = grid.tile_bounds_xy(*t)
        if x1 < lo_xy[0] or x0 > hi_xy[0] or y1 < lo_xy[1] or y0 > hi_xy[1]:
            continue
        a = store.read_fit(grid, *t)
        cp = a["control_points"]
        lo, hi = cp.min((1, 2)), cp.max((1, 2))  # (p, 3) the patches' boxes
        keep = np.zeros(len(cp), bool)
        for pl in planes:
            keep |= _boxes_visible(pl, lo, hi)
        cps.append(cp[keep])
        uvs.append(a["uv"][keep])
    if not cps or not sum(len(c) for c in cps):
        raise ConfigError(f"{root}: no patch of the world is in view of the {len(cams)} cameras")
    s = grid.samples_per_patch
    return PatchNet(np.concatenate(cps), uv=np.concatenate(uvs), tol=1e-6 * s * min(grid.spacing),
                    name=f"{Path(root).name}: the patches in view")
