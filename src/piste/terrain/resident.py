"""Resident terrain: every patch tessellated once per LOD level, kept (on the GPU); each frame only
decides levels and lists indices.

The talk's per-edge LOD with uniform and glue patches, without re-assembling vertices every frame:

* **Vertex blocks** (built once): patch ``p`` owns the block of ``B = sum(n^2)`` vertices starting
  at ``p B`` holding its uniform grids at every LOD level ``n`` (4, 6, 8: ``B = 116``), in the
  :func:`piste.terrain.get_shape` layout.  Corners and edge vertices are the canonical ones of the
  vertex cache (bit-identical in both patches of an edge), so any mix of levels is crack-free.
* **Shape templates** (built once): for every combination of side levels (``4^4 = 256``: the
  flat level, 2 vertices a side, and the three levels), the triangles of that uniform or glue shape
  as block-local vertex indices: a glue patch's side ``s`` at level ``n`` takes its vertices from the
  level-``n`` grid, its inner mesh from the level-``m`` grid, all inside the patch's own block.  The
  flat level needs no vertices of its own: its corners are the coarsest grid's (the block layout is
  unchanged by it).
* **Per frame**: hierarchical frustum culling (:class:`piste.terrain.cull.PatchTree`), the level
  of each visible side (its edge midpoint's distance; flat or coarsest where the error of its
  patches' meshes seen from the eye is below ``flat_error``, :mod:`piste.terrain.lod`; the same
  arithmetic on the same inputs in both patches), and the index list ``template + p B`` (:func:`piste.terrain._kernels.frame_indices`).
  No vertex is written on the CPU.

Geomorphing
-----------
Each vertex also stores its **morph target**: where the next coarser level's tessellation has the
same parameter point (edge vertices: linear along the coarser edge polyline, computed once per
edge in the edge's canonical direction and copied into both patches; inner vertices: the coarser
uniform grid's triangle at that (u, v); corners and the coarsest level: themselves), and a
**morph slot** (edge id for edge vertices, ``n_edges + p`` for inner vertices).  Each frame gives
every visible slot a factor ``f`` in [0, 1] (:meth:`ResidentTerrain.frame`): 1 deep inside a
level's distance band, falling to 0 at the band's far end, where the edge switches to the coarser
level; the drawn position is ``target + f (position - target)``.  An edge vertex gets its edge's
factor in both patches, so shared edges stay bit-identical at every factor; an inner grid at level
``m`` takes the largest factor of the patch's level-``m`` sides.  The coarsest level does not morph
towards the flat one: an edge goes flat only where its error is below ``flat_error`` on screen.  ``morph=False`` draws the
positions themselves (the talk's exact behaviour, pictures identical to the CPU path's).

API
---
::

    ResidentTerrain(net, levels=(4, 6, 8), vertices=None)    the blocks and templates (``vertices (N B, 11)
        float32``; given: blocks built before, e.g. stored in a bundle, checked, not rebuilt)
    keep_resident(net, vertices, levels)     such stored blocks kept on the net (resident_terrain returns them)
    ResidentTerrain.frame(eye, planes, ...)  -> ResidentMesh (indices, patch list, morph factors)
    shape_templates(levels) -> the 256 shapes' block-local index templates (shipped for 4/6/8:
        shipped_templates / write_templates / TEMPLATES_FILE)
    ResidentMesh.morphed_positions(rows)     CPU twin of the vertex shader's morph (tests, shadows)
    ResidentMesh.to_mesh()                   the same frame as a classic TerrainMesh (debug views, export)
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from piste._data import DataMethods
from piste.errors import ConfigError, ValidationError
from piste.formats.ziplite import read_npz
from piste.terrain import _kernels
from piste.terrain._kernels import frame_indices
from piste.terrain.cull import patch_tree
from piste.terrain.lod import (DEFAULT_FAR, DEFAULT_NEAR, FLAT_ERROR, FLAT_LEVEL, LEVELS, error_limit, flat_bounds,
                              level_errors)
from piste.terrain.net import SIDE_CORNERS, PatchNet
from piste.terrain.bezier import blend_tables, eval_edges, params
from piste.terrain.tessellate import (MAX_LEVEL, TerrainMesh, _bilinear_weights, _cache, _glue_sources, _Snapshot,
                                      get_shape, tessellate)

__all__ = ["ResidentTerrain", "ResidentMesh", "RESIDENT_FLOATS", "RESIDENT_FORMAT", "MORPH_BAND", "RESIDENT_BUDGET",
           "BUILD_CHUNK", "resident_terrain", "resident_fits", "keep_resident", "morph_setting", "uniform_grids",
           "edge_points"]

#: floats per resident vertex: position 3, morph target 3, uv 2, light-map uv 2, morph slot 1
RESIDENT_FLOATS = 11
#: version of the blocks' layout and arithmetic: blocks stored by a build (a bundle's
#: ``terrain/resident_blocks``) are used only when it is this one -- bump it when :class:`ResidentTerrain`
#: would build other bits (``tests/terrain/test_resident_stored.py`` compares stored and built blocks)
RESIDENT_FORMAT = 1
#: fraction of each level's distance band over which its vertices morph towards the coarser level
MORPH_BAND = 0.3
#: patches per step of the blocks' build (bounds its temporary memory; the result does not depend on it)
BUILD_CHUNK = 8192


def _full_index(n: int) -> np.ndarray:
    """Local vertex index of grid point ``(i, j)`` of a uniform ``n x n`` shape: ``full[j, i]``, ``(n, n)``."""
    sh = get_shape((n,) * 4)
    full = np.empty((n, n), dtype=np.int64)
    mi = n - 2
    full[1:-1, 1:-1] = sh.inner_off + np.arange(mi * mi).reshape(mi, mi)
    seq = []
    for s in range(4):
        a, b = SIDE_CORNERS[s]
        seq.append(np.concatenate([[a], 4 + sh.side_off[s] + np.arange(n - 2), [b]]))
    full[0, :], full[:, -1] = seq[0], seq[1]
    full[-1, :], full[:, 0] = seq[2], seq[3]
    return full


def _inner_weights(c: int, n: int) -> np.ndarray:
    """``((n-2)^2, c^2) float64``: the level-``n`` inner grid points (row ``j * (n-2) + i``) as blends of the
    level-``c`` uniform grid (column ``j * c + i``): the coarse triangle holding each point (cells split
    along (i, j)-(i+1, j+1)), barycentric weights."""
    key = (int(c), int(n))
    w = _INNER_WEIGHTS.get(key)
    if w is None:
        ti = np.arange(1, n - 1, dtype=np.float64) / (n - 1) * (c - 1)
        vv, uu = np.meshgrid(ti, ti, indexing="ij")  # inner point (i, j) at [j-1, i-1]
        x, y = uu.ravel(), vv.ravel()
        ci = np.minimum(np.floor(x).astype(np.int64), c - 2)
        cj = np.minimum(np.floor(y).astype(np.int64), c - 2)
        fx, fy = x - ci, y - cj
        lower = fx >= fy
        a, b, cc, d = cj * c + ci, cj * c + ci + 1, (cj + 1) * c + ci + 1, (cj + 1) * c + ci
        w = np.zeros((len(x), c * c), np.float64)
        r = np.arange(len(x))
        np.add.at(w, (r, a), np.where(lower, 1 - fx, 1 - fy))
        np.add.at(w, (r, b), np.where(lower, fx - fy, 0.0))
        np.add.at(w, (r, cc), np.where(lower, fy, fx))
        np.add.at(w, (r, d), np.where(lower, 0.0, fy - fx))
        _INNER_WEIGHTS[key] = w
    return w


_INNER_WEIGHTS: dict = {}


def _side_seq(n: int, s: int) -> np.ndarray:
    """Local indices along side ``s`` of a uniform level-``n`` shape, corners included, ``(n,)``."""
    a, b = SIDE_CORNERS[s]
    return np.concatenate([[a], 4 + s * (n - 2) + np.arange(n - 2), [b]]).astype(np.int64)


def edge_points(net: PatchNet, n: int) -> np.ndarray:
    """Every edge's inner points at level ``n`` in its canonical direction, ``(e (n-2), 3)`` float32
    relative to the net's origin (the vertex cache's arithmetic; empty for ``n <= 2``)."""
    if n <= 2:
        return np.zeros((0, 3), np.float32)
    return eval_edges(_cache(net).edge_cp[np.arange(net.n_edges)], n).reshape(-1, 3)


def uniform_grids(net: PatchNet, levels: Iterable[int], patches: np.ndarray | slice | None = None,
                  edges: dict | None = None) -> dict:
    """Every patch's uniform grid at each level: ``{n: (positions (N, n^2, 3) float32, uvs (N, n^2, 4)
    float32: uv then light-map uv)}`` in the :func:`piste.terrain.get_shape` layout.

    Bit-identical to the vertex cache's positions and UVs (``tessellate(net, n, cache=False)``: the
    same blend-table arithmetic on the same arrays: corners, each edge once in its canonical
    direction, inner grids by one product per level) without its normals, parameters and projected
    UVs, which the resident blocks do not hold (about half the cache's build time).

    ``patches``: only these patches (``(k,)`` ids or a slice; the result has ``k`` rows), e.g. a
    chunk of a big net; ``edges``: ``{n: edge_points(net, n)}`` computed once for all chunks (every
    edge evaluated once, so both patches of an edge get its bits whatever chunks they fall in).
    """
    cache = _cache(net)
    ids = np.arange(len(net))[patches] if patches is not None else np.arange(len(net))
    N = len(ids)
    r = net.lightmap_rect[ids]
    lm_corners = np.stack([r[:, [0, 2, 2, 0]], r[:, [1, 1, 3, 3]]], axis=1)  # (N, 2, 4)
    corner_attr = np.concatenate([net.uv[ids].transpose(0, 2, 1), lm_corners], axis=1)  # (N, 4, 4)
    flat = cache.packed[ids].reshape(N * 3, 16)
    side_edge, side_flip = net.side_edge[ids], net.side_flip[ids]
    out = {}
    for n in (int(x) for x in levels):
        sh = get_shape((n,) * 4)
        nv = sh.n_verts
        pos = np.empty((N, nv, 3), dtype=np.float32)
        pos[:, :4] = cache.corners[ids]
        if n > 2:
            edge = edges[n] if edges is not None and n in edges else edge_points(net, n)  # (e (n-2), 3)
            kk = np.arange(n - 2)
            for s in range(4):
                rows = (side_edge[:, s] * (n - 2))[:, None] + np.where(side_flip[:, s][:, None], kk[::-1], kk)
                o = 4 + int(sh.side_off[s])
                pos[:, o:o + n - 2] = edge.take(rows, axis=0)
            ti = params(n)[1:-1]
            vv, uu = np.meshgrid(ti, ti, indexing="ij")
            t, _, _ = blend_tables(tuple(uu.ravel()), tuple(vv.ravel()), "float32")
            pos[:, sh.inner_off:] = (flat @ t).reshape(N, 3, -1).transpose(0, 2, 1)
        pos += cache.origin32
        uvs = np.empty((N, nv, 4), dtype=np.float32)
        attr = (corner_attr.reshape(N * 4, 4) @ _bilinear_weights(sh.param).T).reshape(N, 4, nv)
        uvs[..., :2] = attr[:, :2].transpose(0, 2, 1)
        uvs[..., 2:] = attr[:, 2:].transpose(0, 2, 1)
        out[n] = (pos, uvs)
    return out


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class ResidentMesh(DataMethods):
    """One frame of resident terrain.

    Attributes
    ----------
    resident : ResidentTerrain
    indices : (t, 3) uint32, into the resident vertex blocks
    patch_ids : (p,) int64, the patches drawn (ascending)
    patch_levels : (p, 4) int16, vertices per side
    patch_kind : (p,) int8, the level of uniform patches (2: flat), 0 for glue patches
    tri_start : (p + 1,) int64, triangles of the k-th drawn patch
    vertex_first : (p,) int64, first vertex of each drawn patch's block; vertex_count : (p,) block size
    factors : (s,) float32, the morph factor of every slot (``n_edges + n_patches`` used, padded to
        rows of 1024; valid at the drawn ones; the live array, overwritten by the next frame)
    morph : bool, whether the factors apply (False: positions drawn as they are)
    n_vertices : distinct vertices drawn (the shapes' vertex counts summed)
    eye : (3,) float64, the eye the frame was made for (None: unknown)
    shape_key : (p,) int64, each drawn patch's shape (row of the templates; None: unknown)
    """

    resident: "ResidentTerrain"
    indices: np.ndarray
    patch_ids: np.ndarray
    patch_levels: np.ndarray
    patch_kind: np.ndarray
    tri_start: np.ndarray
    vertex_first: np.ndarray
    vertex_count: np.ndarray
    factors: np.ndarray
    morph: bool
    n_vertices: int
    eye: np.ndarray | None = None
    shape_key: np.ndarray | None = None

    @property
    def n_triangles(self) -> int:
        return len(self.indices)

    def front_indices(self) -> np.ndarray:
        """:attr:`indices` without the patches whose every triangle faces away from :attr:`eye`
        (:meth:`ResidentTerrain.facing`: what back-face culling would drop whole), ``(t', 3)`` uint32;
        :attr:`indices` itself when none does or the eye is unknown."""
        if self.eye is None or self.shape_key is None or not len(self.patch_ids):
            return self.indices
        r = self.resident
        if _kernels.front_ready():
            st = r._cone_state()
            args = (self.patch_ids, self.shape_key, st[7], self.vertex_first, r.tmpl, r.tmpl_start, r.tmpl_count,
                    st[1], st[2], st[3], st[4], st[5], st[6], self.eye, self.indices.size)
            out = _kernels.front_indices(*args)
            if out is None:  # cones not computed yet for some patches: compute them, then again
                r.facing(self.patch_ids, self.shape_key, self.eye)
                out = _kernels.front_indices(*args)
            assert out is not None  # the cones are computed now
            return self.indices if out.size == self.indices.size else out.reshape(-1, 3)
        keep = r.facing(self.patch_ids, self.shape_key, self.eye)
        if keep.all():
            return self.indices
        flat, _ = frame_indices(self.shape_key[keep], self.vertex_first[keep], r.tmpl, r.tmpl_start, r.tmpl_count)
        return flat.reshape(-1, 3)

    def edge_levels(self) -> np.ndarray:
        """Per-edge levels ``(e,)`` int16 of this frame (edges of undrawn patches: the coarse level)."""
        r = self.resident
        lv = np.full(r.net.n_edges, r.levels[0], dtype=np.int16)
        lv[r.net.side_edge[self.patch_ids]] = self.patch_levels
        return lv

    def morphed_positions(self, rows: np.ndarray) -> np.ndarray:
        """World positions ``(k, 3) float32`` of resident vertex ``rows``, morphed as the vertex shader
        does (``target + f (position - target)`` in float32)."""
        v = self.resident.vertices[np.asarray(rows, dtype=np.int64)]
        pos = v[:, 0:3]
        if not self.morph:
            return pos.copy()
        tgt = v[:, 3:6]
        f = self.factors[v[:, 10].astype(np.int64)][:, None]
        return (tgt + f * (pos - tgt)).astype(np.float32)

    def to_mesh(self) -> TerrainMesh:
        """This frame's patches and levels as a classic :class:`piste.terrain.TerrainMesh` (unmorphed;
        for debug views and export)."""
        return tessellate(self.resident.net, self.edge_levels(), patches=self.patch_ids)

    def compact(self) -> tuple[np.ndarray, np.ndarray]:
        """``(positions (m, 3) float32 morphed, indices (t, 3) uint32)`` over only the vertices used."""
        rows, inv = np.unique(self.indices.ravel(), return_inverse=True)
        return self.morphed_positions(rows), inv.reshape(-1, 3).astype(np.uint32)


class ResidentTerrain:
    """Per-patch vertex blocks at every LOD level with morph targets, and the shape templates.

    Parameters
    ----------
    net : PatchNet
    levels : (coarse, medium, fine) vertices per edge (strictly increasing, 2..64)

    Attributes
    ----------
    block : int
        B, vertices per patch (:attr:`vertices` holds ``N B`` of them)
    level_offset : dict
        ``{n: offset of level n's grid in a block}``
    """

    def __init__(self, net: PatchNet, levels: Iterable[int] = LEVELS, vertices: np.ndarray | None = None) -> None:
        levels = tuple(int(x) for x in levels)
        if len(levels) != 3 or list(levels) != sorted(set(levels)) or levels[0] < 2 or levels[-1] > MAX_LEVEL:
            raise ConfigError(f"resident terrain levels must be 3 increasing values in 2..{MAX_LEVEL}, got {levels}")
        self.net = net
        self.levels = levels
        self.level_offset = {}
        o = 0
        for n in levels:
            self.level_offset[n] = o
            o += n * n
        self.block = o
        # the flat level's corners: the coarsest grid's (its first 4 vertices)
        self.level_offset.setdefault(FLAT_LEVEL, self.level_offset[levels[0]])
        # compared every frame (resident_terrain): one compiled pass over the raw bytes (0.14 ms for a
        # 160k-patch net's UVs and rects, where np.array_equal took 0.2-0.7 ms)
        self._snapshot = (_Snapshot(net.uv), _Snapshot(net.lightmap_rect))
        self._vertices = None  # built on first use (a frame's LOD and index list do not need them)
        self.build_chunk = BUILD_CHUNK
        self._build_templates()
        self.edge_mid = np.ascontiguousarray(net.edge_midpoints())
        self.side_edge = np.ascontiguousarray(net.side_edge, dtype=np.int64)
        self.degenerate = np.ascontiguousarray(net.edge_degenerate, dtype=np.bool_)
        slots = net.n_edges + len(net)
        self.factors = np.ones(-(-slots // 1024) * 1024, dtype=np.float32)  # rows of 1024 (the GPU's texture)
        if vertices is not None:
            self._vertices = self._checked(vertices)

    def _checked(self, vertices: Any) -> np.ndarray:
        """Blocks built before (e.g. stored in a bundle): ``(N B, 11) float32`` whose morph slots
        index this net's factors, else :class:`~piste.errors.ValidationError` (they are used as given)."""
        v = vertices
        n, b = len(self.net), self.block
        if not isinstance(v, np.ndarray) or v.dtype != np.float32 or v.shape != (n * b, RESIDENT_FLOATS):
            got = f"{v.shape} {v.dtype}" if isinstance(v, np.ndarray) else type(v).__name__
            raise ValidationError(f"{self.net.name}: resident vertex blocks must be an ({n * b}, {RESIDENT_FLOATS}) "
                                  f"float32 array for {n} patches at levels {self.levels}, got {got}")
        if len(v):
            slot = v[:, 10]
            lo, hi = float(slot.min()), float(slot.max())
            if not (lo >= 0.0 and hi < self.net.n_edges + n):  # (False for NaN too)
                raise ValidationError(f"{self.net.name}: resident vertex blocks' morph slots must be in "
                                      f"0..{self.net.n_edges + n - 1}, got {lo}..{hi}")
        return np.ascontiguousarray(v)

    # ------------------------------------------------------------------ build (once)
    @property
    def vertices(self) -> np.ndarray:
        """``(N B, 11) float32``: position, morph target, uv, light-map uv, morph slot (built on first use)."""
        if self._vertices is None:
            self._build_vertices()
        assert self._vertices is not None  # _build_vertices sets it
        return self._vertices

    def _build_vertices(self) -> None:
        """The blocks, :data:`BUILD_CHUNK` patches at a time: peak memory is the blocks plus one
        chunk's grids and float64 morph arithmetic (the whole net at once took ~4x the blocks),
        and every step is per patch, so the bits do not depend on the chunking."""
        net = self.net
        N, B = len(net), self.block
        out = np.empty((N, B, RESIDENT_FLOATS), dtype=np.float32)
        edges = {n: edge_points(net, n) for n in self.levels}  # each edge once, shared by the chunks
        chunk = max(int(self.build_chunk), 1)
        for c0 in range(0, N, chunk):
            sl = slice(c0, min(c0 + chunk, N))
            self._build_chunk(out[sl], sl, edges)
        self._vertices = out.reshape(N * B, RESIDENT_FLOATS)

    def _build_chunk(self, out: np.ndarray, sl: slice, edges: dict) -> None:
        """Blocks ``out (k, B, 11)`` of the patches ``sl``."""
        net = self.net
        both = uniform_grids(net, self.levels, sl, edges)  # positions and UVs only (no normals)
        grids = {n: both[n][0] for n in self.levels}
        pids = np.arange(len(net))[sl]
        side_edge, side_flip = net.side_edge[sl], net.side_flip[sl]
        for li, n in enumerate(self.levels):
            g = grids[n]
            blk = out[:, self.level_offset[n]:self.level_offset[n] + n * n]
            blk[..., 0:3] = g
            blk[..., 6:10] = both[n][1]
            # morph slots: corners 0 (target = position), sides their edge, inner n_edges + p
            slot = np.zeros((len(pids), n * n), dtype=np.int64)
            for s in range(4):
                slot[:, 4 + s * (n - 2):4 + (s + 1) * (n - 2)] = side_edge[:, s:s + 1]
            slot[:, 4 + 4 * (n - 2):] = net.n_edges + pids[:, None]
            blk[..., 10] = slot
            if li == 0:
                blk[..., 3:6] = g[..., 0:3]
                continue
            c = self.levels[li - 1]
            blk[..., 3:6] = self._targets(grids[c], c, g, n, side_flip)

    def _targets(self, gc: np.ndarray, c: int, g: np.ndarray, n: int, side_flip: np.ndarray) -> np.ndarray:
        """Morph targets ``(k, n^2, 3) float32`` of the level-``n`` grids ``g`` towards the level-``c``
        ones ``gc`` (``k`` patches, ``side_flip (k, 4)`` theirs)."""
        N = len(g)
        tgt = np.empty((N, n * n, 3), dtype=np.float32)
        pc = gc[..., 0:3]
        tgt[:, :4] = g[:, :4, 0:3]  # corners stay
        # edges: the coarse edge polyline in the edge's canonical direction (the same bits in both
        # patches of an edge: its vertices are the canonical ones), interpolated, then back to the side
        t = np.arange(1, n - 1, dtype=np.float64) / (n - 1) * (c - 1)
        j = np.minimum(np.floor(t).astype(np.int64), c - 2)
        a = (t - j)[None, :, None]
        for s in range(4):
            seq = pc[:, _side_seq(c, s)]  # (k, c, 3) in side direction
            flip = side_flip[:, s][:, None, None]
            canon = np.where(flip, seq[:, ::-1], seq)
            e = (canon[:, j].astype(np.float64) * (1.0 - a) + canon[:, j + 1].astype(np.float64) * a).astype(np.float32)
            tgt[:, 4 + s * (n - 2):4 + (s + 1) * (n - 2)] = np.where(flip, e[:, ::-1], e)
        # inner: the coarse uniform grid's triangle (cells split along (i, j)-(i+1, j+1)): each point a
        # fixed barycentric blend of 3 coarse grid points, all patches at once as one float64 product
        grid = pc[:, _full_index(c).ravel()].transpose(1, 0, 2).reshape(c * c, N * 3).astype(np.float64)  # (c^2, 3k)
        inner = (_inner_weights(c, n) @ grid).reshape(-1, N, 3)  # ((n-2)^2, k, 3)
        tgt[:, 4 + 4 * (n - 2):] = inner.transpose(1, 0, 2)
        return tgt

    def _build_templates(self) -> None:
        t = shipped_templates(self.levels)
        if t is None:
            t = shape_templates(self.levels)
        self.tmpl, self.tmpl_start, self.tmpl_count = t["tmpl"], t["tmpl_start"], t["tmpl_count"]
        self.shape_kind, self.shape_verts = t["shape_kind"], t["shape_verts"]
        self.level_array = np.array(self.levels, dtype=np.int16)
        keys = np.arange(256)
        #: (256, 4) int16: the vertices per side of each shape key ((d0 * 4 + d1) * 4 + d2) * 4 + d3,
        #: digit d = level index + 1 (0: the flat level)
        shape_levels = np.array((FLAT_LEVEL,) + self.levels, dtype=np.int16)
        self.key_levels = shape_levels[np.stack([(keys // 4 ** (3 - s)) % 4 for s in range(4)], axis=1)]

    def stale(self) -> bool:
        """True when the net's corner UVs or light-map rects changed since the blocks were built."""
        s = self._snapshot
        return not (s[0].same(self.net.uv) and s[1].same(self.net.lightmap_rect))

    @property
    def nbytes(self) -> int:
        """Bytes of the vertex blocks (``N B 44``)."""
        return len(self.net) * self.block * RESIDENT_FLOATS * 4

    # ------------------------------------------------------------------ per frame
    def frame(self, eye: npt.ArrayLike, planes: npt.ArrayLike | None = None, near: float = DEFAULT_NEAR, far: float = DEFAULT_FAR,
              lod: bool = True, morph: bool = True, patches: npt.ArrayLike | None = None, side_levels: npt.ArrayLike | None = None,
              morph_band: float = MORPH_BAND,
              use_numba: bool | None = None, flat_error: float | None = FLAT_ERROR) -> ResidentMesh:
        """Levels, culling and the index list for a camera at ``eye``.

        Parameters
        ----------
        eye : (3,) camera position
        planes : (6, 4) inward frustum planes (None: every patch)
        near, far : LOD thresholds (as :func:`piste.terrain.edge_levels`: ``d < near`` fine,
            ``d < far`` medium, else coarse)
        lod : False draws every patch at the fine level
        morph : geomorph between levels (False: the talk's exact positions)
        patches : (p,) explicit patch ids (overrides ``planes``)
        side_levels : (p, 4) explicit level indices 0..2 per side of ``patches``, or -1 for the flat
            level (tests); with ``morph``, the factors must then be set by the caller in :attr:`factors`
        flat_error : edges whose patches' flat (2 vertices) or coarsest meshes are within this angle
            (radians) seen from the eye are drawn so (:func:`piste.terrain.lod.edge_levels`); None or
            0: the levels by distance alone
        use_numba : None (compiled when numba is installed), False (numpy; the same result)
        """
        net = self.net
        eye = np.asarray(eye, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(eye)):
            raise ConfigError(f"eye must be finite, got {eye.tolist()}")
        if not (0 <= near <= far):
            raise ConfigError(f"LOD thresholds must satisfy 0 <= near <= far, got near={near}, far={far}")
        if flat_error and not (np.isfinite(flat_error) and flat_error > 0):
            raise ConfigError(f"flat_error must be a positive angle in radians or None, got {flat_error}")
        tol = float(flat_error) if (flat_error and lod) else 0.0
        if patches is not None:
            pids = np.asarray(patches, dtype=np.int64).ravel()
            if len(pids) and (pids.min() < 0 or pids.max() >= len(net)):
                raise ValidationError(f"{net.name}: patch ids must be in 0..{len(net) - 1}")
        elif planes is None:
            pids = np.arange(len(net), dtype=np.int64)
        else:
            pids = patch_tree(net).cull(planes)
        fac = self.factors
        if side_levels is None and (use_numba or (use_numba is None and _kernels.side_lod_ready())):
            ferr, flo, fhi = flat_bounds(net) if tol else self._no_flat()
            cerr = level_errors(net, self.levels[0]) if tol else ferr
            key = _kernels.side_lod(pids, self.side_edge, self.edge_mid, self.degenerate, eye, near, far, morph_band,
                                    lod, morph or not lod, fac, ferr, flo, fhi, tol, cerr)
            return self._mesh(pids, key, morph, use_numba, eye)
        se = net.side_edge[pids]  # (p, 4)
        if side_levels is not None:
            li = np.asarray(side_levels, dtype=np.int64).reshape(len(pids), 4)
            if li.size and (li.min() < -1 or li.max() > 2):
                raise ValidationError("side_levels must be level indices 0..2 or -1 (flat)")
        elif not lod:
            li = np.full((len(pids), 4), 2, dtype=np.int64)
            fac[se] = 1.0
            fac[net.n_edges + pids] = 1.0
        else:
            d = self.edge_mid[se] - eye  # (p, 4, 3)
            d2 = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2]
            dist = np.sqrt(d2)
            li = np.where(dist < near, 2, np.where(dist < far, 1, 0))
            li[net.edge_degenerate[se]] = 0
            if tol:
                lim = error_limit(net, eye, se, tol)
                li[(li > 0) & (level_errors(net, self.levels[0])[se] < lim)] = 0
                li[flat_bounds(net)[0][se] < lim] = -1
            if morph:
                w = float(morph_band)
                f_fine = (near - dist) / max(w * near, 1e-12)
                f_mid = (far - dist) / max(w * (far - near), 1e-12)
                f = np.clip(np.where(li == 2, f_fine, np.where(li == 1, f_mid, 1.0)), 0.0, 1.0).astype(np.float32)
                fac[se] = f
                mx = li.max(axis=1) if len(li) else np.zeros(0, np.int64)
                fin = np.where(li == mx[:, None], f, np.float32(0.0)).max(axis=1) if len(li) else np.zeros(0, np.float32)
                fac[net.n_edges + pids] = fin
        d = li + 1  # key digits: 0 flat, 1..3 the levels
        key = ((d[:, 0] * 4 + d[:, 1]) * 4 + d[:, 2]) * 4 + d[:, 3]
        return self._mesh(pids, key, morph, use_numba, eye)

    def _no_flat(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Empty stand-ins for :func:`piste.terrain.lod.flat_bounds` (the compiled LOD with the flat level off)."""
        z = np.zeros(1, np.float64)
        return z, np.zeros((1, 3), np.float64), np.zeros((1, 3), np.float64)

    # ------------------------------------------------------------------ back-facing patches
    def _cone_state(self) -> tuple:
        """Lazily filled per-patch normal cones, one per shape family ``j`` (shapes whose side digits
        are all ``<= j``: 0 the flat patch, 1 flat or coarsest sides, 2 up to the medium level, 3 all):
        ``(family triangles [(T_j, 3) block-local], axis (4, N, 3), cos (4, N), sin (4, N),
        done (4, N) bool, centre (N, 3), radius (N,))``."""
        c = self.__dict__.get("_cone_state_")
        if c is None:
            tris = []
            digits = np.stack([(np.arange(256) // 4 ** (3 - s)) % 4 for s in range(4)], axis=1).max(axis=1)
            for j in range(4):
                t = np.concatenate([self.tmpl[self.tmpl_start[k]:self.tmpl_start[k] + self.tmpl_count[k]]
                                    for k in np.nonzero(digits <= j)[0]])
                tris.append(np.unique(t.reshape(-1, 3).astype(np.int64), axis=0))  # orientation kept
            N = len(self.net)
            lo, hi = self.net.patch_bounds  # holds the surface, so every vertex and morph target
            centre = np.ascontiguousarray((lo + hi) * 0.5, dtype=np.float64)
            radius = np.ascontiguousarray(np.sqrt((((hi - lo) * 0.5) ** 2).sum(-1)), dtype=np.float64)
            c = (tris, np.zeros((4, N, 3)), np.full((4, N), -1.0), np.zeros((4, N)), np.zeros((4, N), dtype=bool),
                 centre, radius, np.ascontiguousarray(digits, dtype=np.int64))
            self.__dict__["_cone_state_"] = c
        return c

    def _fill_cones(self, j: int, pids: np.ndarray, chunk: int = 512) -> None:
        """Compute family ``j``'s cones of ``pids``: the normals of its every triangle at each of the
        8 ends of its vertices' morphs (a morphed triangle's normal is multilinear in its three morph
        factors, so a convex combination of those 8), their mean direction and the widest angle to it."""
        tris, axis, cos, sin, done = self._cone_state()[:5]
        t = tris[j]
        B = self.block
        v_all = self.vertices.reshape(len(self.net), B, RESIDENT_FLOATS)
        for a in range(0, len(pids), chunk):
            p = pids[a:a + chunk]
            v = v_all[p].astype(np.float64)
            ends = (v[..., 0:3], v[..., 3:6])
            ns = []
            for sa in (0, 1):
                x0 = ends[sa][:, t[:, 0]]
                for sb in (0, 1):
                    e1 = ends[sb][:, t[:, 1]] - x0
                    for sc in (0, 1):
                        ns.append(np.cross(e1, ends[sc][:, t[:, 2]] - x0))
                    if j <= 1:  # the flat and coarsest levels never morph: one end is all
                        break
                if j <= 1:
                    break
            n = np.concatenate(ns, axis=1)  # (k, 8 T, 3)
            ln = np.sqrt((n * n).sum(-1))
            unit = n / np.where(ln > 0, ln, 1.0)[..., None]
            sm = unit.sum(axis=1)
            ls = np.sqrt((sm * sm).sum(-1))
            ax = sm / np.where(ls > 0, ls, 1.0)[:, None]
            cmin = np.where(ln > 0, (unit * ax[:, None]).sum(-1), 1.0).min(axis=1)
            ok = (ls > 0) & (cmin > 0.01)
            axis[j, p] = ax
            cos[j, p] = np.where(ok, cmin, -1.0)
            sin[j, p] = np.sqrt(np.maximum(1.0 - cos[j, p] ** 2, 0.0))
            done[j, p] = True

    def facing(self, pids: np.ndarray, key: np.ndarray, eye: npt.ArrayLike) -> np.ndarray:
        """``(p,)`` bool: False where patch ``pids[i]`` drawn as shape ``key[i]`` faces wholly away from
        ``eye`` (every triangle's plane has the eye behind it, at any morph factor), True otherwise.

        Each patch is tested against the cone of its shape's family (:meth:`_cone_state`; computed
        for a patch the first time it is asked): with ``v`` from the eye to the centre of the patch's
        box, ``a`` the cone's axis and ``theta`` its half-angle, every normal ``n`` in the cone has
        ``v . n >= (v . a) cos theta - |v x a| sin theta``; above the box's radius (plus a margin),
        every point of every triangle lies in front of the eye along its normal: back-facing.
        Conservative: a patch with one triangle the GPU would draw is kept."""
        pids = np.asarray(pids, dtype=np.int64)
        tris, axis, cos, sin, done, centre, radius, digits = self._cone_state()
        fam = digits[np.asarray(key, dtype=np.int64)]
        for j in np.unique(fam):
            p = pids[fam == j]
            p = p[~done[j, p]]
            if len(p):
                self._fill_cones(int(j), p)
        eye = np.asarray(eye, dtype=np.float64).reshape(3)
        v = centre[pids] - eye
        ax = axis[fam, pids]
        va = (v * ax).sum(-1)
        vv = (v * v).sum(-1)
        vp = np.sqrt(np.maximum(vv - va * va, 0.0))
        c = cos[fam, pids]
        back = (c > 0) & (va * c - vp * sin[fam, pids] > radius[pids] * (1.0 + 1e-6) + 1e-6 * np.sqrt(vv))
        return ~back

    def _mesh(self, pids: np.ndarray, key: np.ndarray, morph: bool, use_numba: bool | None = None,
              eye: npt.ArrayLike | None = None) -> ResidentMesh:
        base = pids * self.block
        flat, start = frame_indices(key, base, self.tmpl, self.tmpl_start, self.tmpl_count, use_numba=use_numba)
        return ResidentMesh(
            resident=self,
            indices=flat.reshape(-1, 3),
            patch_ids=pids,
            patch_levels=self.key_levels[key],
            patch_kind=self.shape_kind[key],
            tri_start=start // 3,
            vertex_first=base,
            vertex_count=np.full(len(pids), self.block, dtype=np.int64),
            factors=self.factors,
            morph=bool(morph),
            n_vertices=int(self.shape_verts[key].sum()),
            eye=None if eye is None else np.array(eye, dtype=np.float64),
            shape_key=key,
        )


def shape_templates(levels: Sequence[int] = LEVELS) -> dict:
    """The index templates of every patch shape (``4^4`` side-level combinations: the flat level,
    :data:`piste.terrain.lod.FLAT_LEVEL`, then ``levels``) over a resident block of ``levels``: ``tmpl``
    (concatenated uint32 block-local indices), ``tmpl_start``, ``tmpl_count`` (int64 per shape),
    ``shape_kind`` (int8: the level of uniform shapes, 0 for glue), ``shape_verts`` (int64 distinct
    vertices).  Shape key ``((d0 * 4 + d1) * 4 + d2) * 4 + d3``, digit 0 the flat level, ``i + 1`` level
    ``levels[i]``.  The flat level's corners are the coarsest grid's (every grid's corners are the
    same canonical points)."""
    offset, o = {}, 0
    for n in (int(x) for x in levels):
        offset[n] = o
        o += n * n
    offset.setdefault(FLAT_LEVEL, offset[int(levels[0])])
    L = (FLAT_LEVEL,) + tuple(int(x) for x in levels)
    k = len(L)
    tm, start, count, kind, nverts = [], [], [], [], []
    o = 0
    for key in range(k ** 4):
        li = [(key // k ** (3 - s)) % k for s in range(4)]
        lv = tuple(L[i] for i in li)
        sh = get_shape(lv)
        lvl, slot = _glue_sources(lv)
        local = np.array([offset[int(n)] for n in lvl], dtype=np.int64) + slot
        t = local[sh.tris].astype(np.uint32).ravel()
        tm.append(t)
        start.append(o)
        count.append(len(t))
        o += len(t)
        kind.append(lv[0] if sh.uniform else 0)
        nverts.append(sh.n_verts)
    return {"tmpl": np.concatenate(tm).astype(np.uint32), "tmpl_start": np.array(start, dtype=np.int64),
            "tmpl_count": np.array(count, dtype=np.int64), "shape_kind": np.array(kind, dtype=np.int8),
            "shape_verts": np.array(nverts, dtype=np.int64)}


#: the default levels' templates as computed by :func:`shape_templates`, shipped with the package
#: (a fresh process built them in ~45 ms of Python, on the first frame's critical path);
#: ``tests/terrain/test_resident_templates.py`` checks the file against the code
TEMPLATES_FILE = Path(__file__).resolve().parents[1] / "data" / "resident_templates.npz"


def shipped_templates(levels: Sequence[int]) -> dict | None:
    """:func:`shape_templates` of ``levels`` from :data:`TEMPLATES_FILE`, or None when the file is
    missing, unreadable or for other levels (then the caller computes them)."""
    try:  # (read without zipfile: piste.formats.ziplite)
        z = read_npz(TEMPLATES_FILE)
        if tuple(int(x) for x in z["levels"]) != tuple(int(x) for x in levels):
            return None
        out = {k: z[k] for k in ("tmpl", "tmpl_start", "tmpl_count", "shape_kind", "shape_verts")}
    except Exception:  # noqa: BLE001 - any unreadable file (OSError, EOFError, ValueError, a pickle refused): compute
        return None
    n = (len(levels) + 1) ** 4
    if any(len(out[k]) != n for k in ("tmpl_start", "tmpl_count", "shape_kind", "shape_verts")) or \
            int(out["tmpl_count"].sum()) != len(out["tmpl"]):
        return None
    return out


def write_templates(path: str | os.PathLike[str] = TEMPLATES_FILE, levels: Sequence[int] = LEVELS) -> Path:
    """Write :func:`shape_templates` of ``levels`` to ``path`` (regenerates the shipped file)."""
    t = shape_templates(levels)
    path = Path(path)
    with open(path, "wb") as f:
        np.savez_compressed(f, levels=np.array(levels, dtype=np.int64), **t)
    return path


#: memory the resident blocks may take (44 bytes a vertex, 116 vertices a patch: ~210k patches, e.g. a
#: 160k-patch world's 817 MB); bigger nets are drawn on the CPU path (or tiled, :mod:`piste.terrain.tiles`)
RESIDENT_BUDGET = 1 << 30


def resident_fits(net: PatchNet, levels: Iterable[int] = LEVELS, budget: int = RESIDENT_BUDGET) -> bool:
    """Whether ``net``'s resident blocks (``N x 116 x 44`` bytes for levels 4/6/8) stay within
    ``budget`` bytes.  They are built from the control points (:func:`uniform_grids`), not from the
    vertex cache, and :data:`BUILD_CHUNK` patches at a time, so the blocks are what the budget counts
    (it used to add the cache's 56 bytes a vertex, which sent nets above ~46k patches to the CPU path).
    Bigger nets are drawn on the CPU path, visible patches evaluated per frame."""
    block = sum(int(n) * int(n) for n in levels)
    return len(net) * block * RESIDENT_FLOATS * 4 <= budget


def keep_resident(net: PatchNet, vertices: np.ndarray, levels: Iterable[int] = LEVELS) -> ResidentTerrain:
    """Keep blocks built before (a bundle's stored ``terrain/resident_blocks``: the bits
    :class:`ResidentTerrain` builds for ``net`` at ``levels`` with :data:`RESIDENT_FORMAT`) on ``net``:
    :func:`resident_terrain` returns them at once (a fresh process's first frame waited ~0.1 s for
    the background build).  ``vertices`` ``(N B, 11) float32``; checked (shape, dtype, morph slots:
    :class:`~piste.errors.ValidationError`), not copied when contiguous."""
    key = tuple(int(x) for x in levels)
    r = ResidentTerrain(net, key, vertices=vertices)
    net.__dict__.setdefault("_resident", {})[key] = r
    return r


def morph_setting(explicit: bool | None = None) -> bool:
    """Whether to geomorph: ``explicit`` (the CLI's ``--lod-morph``, passed down as a parameter,
    else the scene file's ``[lod] morph``, else a caller's choice), or on when None."""
    return True if explicit is None else bool(explicit)


def resident_terrain(net: PatchNet, levels: Iterable[int] = LEVELS, wait: bool = True) -> ResidentTerrain | None:
    """The :class:`ResidentTerrain` of ``net`` at ``levels`` with its vertex blocks, built once and
    kept on the net (rebuilt when its UVs or light-map rects change).

    ``wait=False`` never blocks: it returns None while the blocks are built in a background thread
    (started by the first such call), so a fresh process can draw its first frames on the CPU path
    (only the visible patches evaluated) instead of waiting ~0.3 s for every patch at every level.
    """
    key = tuple(int(x) for x in levels)
    store = net.__dict__.setdefault("_resident", {})
    pending = net.__dict__.setdefault("_resident_pending", {})
    r = store.get(key)
    if r is not None and not r.stale():
        return r
    job = pending.get(key)
    if job is not None and not job["thread"].is_alive():
        pending.pop(key)
        if job["error"] is not None:
            raise job["error"]
        r = job["result"]
        if r is not None and not r.stale():
            store[key] = r
            return r
        job = None
    if wait:
        if job is not None:
            job["thread"].join()
            return resident_terrain(net, levels, wait=True)
        r = ResidentTerrain(net, key)
        r.vertices  # noqa: B018  (build the blocks now)
        store[key] = r
        return r
    if job is None:
        job = {"result": None, "error": None}

        def build() -> None:
            try:
                rr = ResidentTerrain(net, key)
                rr.vertices  # noqa: B018
                job["result"] = rr
            except Exception as exc:  # re-raised by the next call, on the caller's thread
                job["error"] = exc

        job["thread"] = threading.Thread(target=build, name="piste-resident-terrain", daemon=True)
        pending[key] = job
        job["thread"].start()
    return None
