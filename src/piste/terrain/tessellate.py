"""Tessellation of a PatchNet at per-edge levels: uniform patches and non-uniform glue patches.

A patch whose four edges have the same level ``n`` is tessellated as a uniform ``n x n`` grid
(``2 (n-1)^2`` triangles: 18, 50, 98 for 4, 6, 8).  Any other patch is a *glue patch* (the talk's
"non-uniform mesh"): a uniform inner mesh at ``m = max(levels)`` (its ``(m-2) x (m-2)`` interior
points) plus four glue strips, each zipping the inner ring to that edge's own ``n`` vertices.

Vertices on an edge are computed once per edge per frame from the edge's canonical control points
(:func:`piste.terrain.bezier.eval_edges`) and copied into both patches, and corners are the
welded control points themselves, so a shared edge is bit-identical in both patches whatever
their levels: no cracks by construction.  Normals on edges and corners are the average of the
adjacent patches' normals, so they agree too (smooth shading across C0 seams).

Per-patch vertex block layout (local indices)::

    0..3                       corners c0..c3
    4 + side_off[s] + k        interior vertices of side s (k = 0..n_s-3), in the side's direction
    inner_off + (j-1)(m-2) + (i-1)   inner grid point (i/(m-1), j/(m-1)), i, j = 1..m-2

Everything per frame is a handful of whole-batch numpy operations: one blend-table product per
inner level, one per (side, level) for edge normals, and ragged gathers of cached per-shape
index buffers.  With the per-level vertex cache and numba, a frame is one compiled call
(:func:`piste.terrain._kernels.tess_frame`: the patches sorted by shape, then vertices, indices
and vertex -> patch written straight into the outputs), bit-identical to the numpy path.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
import numpy.typing as npt

from piste._data import DataMethods, FrozenDataMethods
from piste.errors import ConfigError, ValidationError
from piste.terrain import _kernels
from piste.terrain.bezier import (
    _limit_normals,
    blend_tables,
    eval_edges,
    eval_packed,
    pack_control_points,
    params,
    unit_normals,
)
from piste.terrain.net import CORNER_INDEX, SIDE_CORNERS, PatchNet

RESTART = np.uint32(0xFFFFFFFF)
MAX_LEVEL = 64


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class TerrainMesh(DataMethods):
    """The tessellated terrain of one frame.

    Attributes
    ----------
    positions : (m, 3) float32
    normals : (m, 3) float32, unit
    uv : (m, 2) float32, base texture (corner UVs interpolated bilinearly)
    uv_lightmap : (m, 2) float32, light-map atlas (each patch's tile, ``net.lightmap_rect``)
    uv_projected : (m, 2) float32, planar world-xy coordinates for projected textures
        (``(x, y) / projection_scale``)
    param : (m, 2) float32, the patch parameter (u, v) of each vertex
    indices : (t, 3) uint32, counter-clockwise seen from the normal (``du x dv``) side
    patch_ids : (p,) int64, the patches tessellated
    patch_kind : (p,) int8, 4 / 6 / 8 (or any level) for uniform patches, 0 for glue patches
    patch_levels : (p, 4) int16, vertices per edge of each side
    vertex_patch : (m,) int32, index into ``patch_ids`` of each vertex
    vertex_start, tri_start : (p + 1,) int64, the vertices / triangles of the k-th tessellated patch
    strips : (s,) uint32 or None, triangle strips with primitive restart ``0xFFFFFFFF``
    """

    positions: np.ndarray
    normals: np.ndarray
    uv: np.ndarray
    uv_lightmap: np.ndarray
    uv_projected: np.ndarray
    param: np.ndarray
    indices: np.ndarray
    patch_ids: np.ndarray
    patch_kind: np.ndarray
    patch_levels: np.ndarray
    vertex_patch: np.ndarray
    vertex_start: np.ndarray
    tri_start: np.ndarray
    strips: np.ndarray | None = None

    @property
    def n_triangles(self) -> int:
        return len(self.indices)

    @property
    def n_vertices(self) -> int:
        return len(self.positions)


# ---------------------------------------------------------------------------------------- shapes
@dataclass(frozen=True, repr=False, eq=False)  # (repr / eq / hash: piste._data.FrozenDataMethods)
class Shape(FrozenDataMethods):
    """Cached tessellation of one combination of edge levels (its local vertex layout and triangles)."""

    levels: tuple
    m: int
    n_verts: int
    side_off: np.ndarray  # (4,) offset of each side's interior block after the 4 corners
    inner_off: int
    param: np.ndarray  # (n_verts, 2) float32
    tris: np.ndarray  # (t, 3) int64, local
    strip: np.ndarray  # (s,) int64, local, -1 = restart

    @property
    def uniform(self) -> bool:
        return len(set(self.levels)) == 1


def _side_uv(s: int, t: np.ndarray) -> np.ndarray:
    """Parameter points along side ``s`` at side parameters ``t``: ``(k, 2)``."""
    one, zero = np.ones_like(t), np.zeros_like(t)
    return np.stack([(t, zero), (one, t), (t, one), (zero, t)][s], axis=1)


def _orient(tris: np.ndarray, param: np.ndarray) -> np.ndarray:
    """Flip triangles that are clockwise in (u, v)."""
    a, b, c = param[tris[:, 0]], param[tris[:, 1]], param[tris[:, 2]]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    tris = tris.copy()
    tris[area < 0] = tris[area < 0][:, [0, 2, 1]]
    return tris


def _zipper(outer: np.ndarray, t_outer: np.ndarray, inner: np.ndarray, t_inner: np.ndarray) -> list:
    """Triangulate the band between two vertex rows by merging them in parameter order."""
    tris = []
    i = j = 0
    while i < len(outer) - 1 or j < len(inner) - 1:
        adv_outer = j == len(inner) - 1 or (i < len(outer) - 1 and t_outer[i + 1] <= t_inner[j + 1])
        if adv_outer:
            tris.append((outer[i], outer[i + 1], inner[j]))
            i += 1
        else:
            tris.append((outer[i], inner[j + 1], inner[j]))
            j += 1
    return tris


def _strip_rows(rows: list[tuple[np.ndarray, np.ndarray]]) -> list:
    """Strips for bands between pairs of rows of equal length (a grid): one strip per band."""
    out = []
    for lo, hi in rows:
        seq = np.empty(2 * len(lo), dtype=np.int64)
        seq[0::2], seq[1::2] = hi, lo
        out.extend(seq.tolist())
        out.append(-1)
    return out


def _strip_zipper(outer: np.ndarray, t_outer: np.ndarray, inner: np.ndarray, t_inner: np.ndarray) -> list:
    """One strip for a zipper band.

    The zipper's consecutive triangles share an edge; a strip appends one vertex per triangle and
    keeps the last two as the shared edge, so where the vertex that must stay is not the last one
    a swap (a repeat of the second-last vertex, a degenerate triangle) is inserted first.
    """
    seq = [int(inner[0]), int(outer[0])]
    i = j = 0
    while i < len(outer) - 1 or j < len(inner) - 1:
        if j == len(inner) - 1 or (i < len(outer) - 1 and t_outer[i + 1] <= t_inner[j + 1]):
            stay, i = inner[j], i + 1
            nxt = outer[i]
        else:
            stay, j = outer[i], j + 1
            nxt = inner[j]
        if seq[-1] != stay:
            seq.append(seq[-2])
        seq.append(int(nxt))
    return seq + [-1]


def _fix_parity(strip: list, param: np.ndarray) -> list:
    """Make every restart-separated strip start counter-clockwise in (u, v) (prepend a repeat if not)."""
    out, seg = [], []
    for x in strip + [-1]:
        if x != -1:
            seg.append(x)
            continue
        for k in range(len(seg) - 2):
            a, b, c = (param[seg[k + d]] for d in range(3))
            area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
            if abs(area) > 1e-12:
                if (area < 0) == (k % 2 == 0):
                    seg = [seg[0]] + seg
                break
        out.extend(seg + [-1])
        seg = []
    return out[:-1]


@lru_cache(maxsize=None)
def get_shape(levels: tuple) -> Shape:
    """The cached :class:`Shape` of a patch with ``levels = (n0, n1, n2, n3)`` vertices per side."""
    levels = tuple(int(x) for x in levels)
    if any(n < 2 or n > MAX_LEVEL for n in levels):
        raise ValidationError(f"vertices per edge must be in 2..{MAX_LEVEL}, got {levels}")
    m = max(levels)
    uniform = len(set(levels)) == 1
    side_len = np.array([n - 2 for n in levels])
    side_off = np.concatenate([[0], np.cumsum(side_len)[:-1]])
    inner_off = 4 + int(side_len.sum())
    mi = max(m - 2, 0)
    n_verts = inner_off + mi * mi
    param = np.zeros((n_verts, 2))
    param[:4] = [(0, 0), (1, 0), (1, 1), (0, 1)]
    side_seq, side_t = [], []
    for s, n in enumerate(levels):
        t = params(n)
        idx = 4 + side_off[s] + np.arange(n - 2)
        param[idx] = _side_uv(s, t[1:-1])
        a, b = SIDE_CORNERS[s]
        side_seq.append(np.concatenate([[a], idx, [b]]))
        side_t.append(t)
    ti = params(m)[1:-1]
    grid = inner_off + np.arange(mi * mi).reshape(mi, mi)  # grid[j-1, i-1]
    vv, uu = np.meshgrid(ti, ti, indexing="ij")
    param[inner_off:] = np.stack([uu.ravel(), vv.ravel()], axis=1)

    if uniform:
        n = m
        full = np.empty((n, n), dtype=np.int64)  # full[j, i]
        full[1:-1, 1:-1] = grid
        full[0, :], full[:, -1] = side_seq[0], side_seq[1]
        full[-1, :], full[:, 0] = side_seq[2], side_seq[3]
        a, b, c, d = full[:-1, :-1], full[:-1, 1:], full[1:, 1:], full[1:, :-1]
        tris = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
        strip_l = _strip_rows([(full[j], full[j + 1]) for j in range(n - 1)])
    else:
        a, b, c, d = grid[:-1, :-1], grid[:-1, 1:], grid[1:, 1:], grid[1:, :-1]
        tri_l = [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
        strip_l = _strip_rows([(grid[j], grid[j + 1]) for j in range(mi - 1)])
        inner_rows = [grid[0, :], grid[:, -1], grid[-1, :], grid[:, 0]]
        for s in range(4):
            z = _zipper(side_seq[s], side_t[s], inner_rows[s], ti)
            tri_l.append(np.array(z, dtype=np.int64).reshape(-1, 3))
            strip_l += _strip_zipper(side_seq[s], side_t[s], inner_rows[s], ti)
        tris = np.concatenate(tri_l)
    tris = _orient(tris.astype(np.int64), param)
    strip = np.array(_fix_parity(strip_l[:-1], param), dtype=np.int64)
    for arr in (param, tris, strip, side_off):
        arr.setflags(write=False)
    return Shape(levels, m, n_verts, side_off, inner_off, param.astype(np.float32), tris, strip)


def decode_strips(strips: np.ndarray, restart: int | np.integer = RESTART) -> np.ndarray:
    """Triangles of a strip index buffer (restart-separated), degenerate ones dropped: ``(t, 3)``.

    Odd triangles of a strip are flipped, as the GPU does, so windings match the indexed triangles.
    """
    strips = np.asarray(strips).astype(np.int64)
    restart = np.int64(restart) if restart != -1 else np.int64(-1)
    a, b, c = strips[:-2], strips[1:-1], strips[2:]
    valid = (a != restart) & (b != restart) & (c != restart)
    # parity within each strip: position since the last restart
    pos = np.arange(len(strips))
    last = np.maximum.accumulate(np.where(strips == restart, pos, -1))
    parity = (pos - last - 1)[:-2] % 2
    tri = np.stack([a, b, c], 1)
    tri[parity == 1] = tri[parity == 1][:, [1, 0, 2]]
    keep = valid & (a != b) & (b != c) & (a != c)
    return tri[keep]


# ---------------------------------------------------------------------------------------- net cache
class _NetCache:
    """Per-net data that does not change with the levels (packed control points, corner normals)."""

    def __init__(self, net: PatchNet):
        cp = net.control_points
        self.origin = cp.reshape(-1, 3).mean(0)
        rel = cp - self.origin
        self.packed = pack_control_points(rel, np.float32)  # (n, 3, 16)
        self.edge_cp = (net.edge_cp - self.origin).astype(np.float32)  # (e, 4, 3)
        self.corners = rel[:, CORNER_INDEX[:, 0], CORNER_INDEX[:, 1]].astype(np.float32)  # (n, 4, 3)
        self.corner_normals = self._corner_normals(net)
        self.origin32 = self.origin.astype(np.float32)
        self.edge_normals: dict[int, np.ndarray] = {}
        self.grid_levels: dict[int, np.ndarray] = {}
        self.grid_flat: np.ndarray | None = None
        self.grid_offset: dict[int, int] = {}
        self.grid_snapshot: tuple[_Snapshot, _Snapshot] | None = None
        self.grid_rows_: tuple[np.ndarray, np.ndarray] | None = None
        self.scale4 = (net.patch_size.astype(np.float32) ** 4).astype(np.float32)
        lo, hi = net.bounds
        self.proj_origin = lo[:2].astype(np.float32)
        self.proj_scale = np.float32(max(float(np.max(hi[:2] - lo[:2])), 1e-12))

    def grids(self, net: PatchNet, levels: Iterable[int]) -> tuple[np.ndarray, dict]:
        """The vertex cache: every patch tessellated uniformly at each of ``levels``, as one flat
        float32 array of ``VERTEX_FLOATS``-float vertices, and each level's offset (in floats).

        Rebuilt when the net's corner UVs or light-map rects change (nets are otherwise immutable).
        """
        if self.uv_changed(net):
            self.grid_levels, self.grid_flat, self.grid_offset, self.grid_rows_ = {}, None, {}, None
            self.grid_snapshot = (_Snapshot(net.uv), _Snapshot(net.lightmap_rect))
        want = sorted(set(int(n) for n in levels) | set(self.grid_levels))
        if self.grid_flat is None or any(n not in self.grid_levels for n in want):
            for n in want:
                if n not in self.grid_levels:
                    mesh = tessellate(net, n, cache=False)
                    self.grid_levels[n] = np.concatenate(
                        [mesh.positions, mesh.normals, mesh.param, mesh.uv, mesh.uv_lightmap, mesh.uv_projected], axis=1
                    ).astype(np.float32)
            parts: list[np.ndarray] = []
            offset: dict[int, int] = {}
            o = 0
            for n in want:
                offset[n] = o
                parts.append(self.grid_levels[n].ravel())
                o += parts[-1].size
            self.grid_flat, self.grid_offset = np.concatenate(parts) if parts else np.zeros(0, np.float32), offset
        assert self.grid_flat is not None  # built above
        return self.grid_flat, self.grid_offset

    def compiled_state(self, net: PatchNet, used: Iterable[int] = ()) -> tuple:
        """What :func:`piste.terrain._kernels.tess_frame` reads of the vertex cache, with every
        level of ``used`` built: ``(grid (rows, VERTEX_FLOATS) float32, level_row (MAX_LEVEL + 1,)
        int64 (-1: level not built), (uv_now, uv_snap, lm_now, lm_snap) raw bytes)``; the kernel
        compares the UVs' bytes itself (the net's arrays may be edited in place).  Where the UVs'
        layout changed or is not dense, the comparison is made here and empty bytes passed."""
        if self.grid_rows_ is None or any(n not in self.grid_levels for n in used) or self.uv_changed(net):
            flat, offset = self.grids(net, used)
            level_row = np.full(MAX_LEVEL + 1, -1, np.int64)
            for n, o in offset.items():
                level_row[n] = o // VERTEX_FLOATS
            self.grid_rows_ = (flat.reshape(-1, VERTEX_FLOATS), level_row)
        grid, level_row = self.grid_rows_
        assert self.grid_snapshot is not None  # taken by grids() with the rows
        raw: tuple = tuple(s.raw_now(a) for s, a in zip(self.grid_snapshot, (net.uv, net.lightmap_rect)))
        if raw[0] is None or raw[1] is None:
            if self.uv_changed(net):
                return self.compiled_state(net, used)
            raw = ((_NO_BYTES, _NO_BYTES), (_NO_BYTES, _NO_BYTES))
        return grid, level_row, (raw[0][0], raw[0][1], raw[1][0], raw[1][1])

    def uv_changed(self, net: PatchNet) -> bool:
        """Whether the net's corner UVs or light-map rects differ (bitwise) from the vertex cache's."""
        snap = self.grid_snapshot
        return snap is None or not (snap[0].same(net.uv) and snap[1].same(net.lightmap_rect))

    def _corner_normals(self, net: PatchNet) -> np.ndarray:
        """Corner normals averaged over every patch meeting at the welded corner, ``(n, 4, 3)`` float32."""
        packed64 = pack_control_points(net.control_points - self.origin, np.float64)
        cu = tuple(float(x) for x in (0, 1, 1, 0))
        cv = tuple(float(x) for x in (0, 0, 1, 1))
        _, tu, tv = blend_tables(cu, cv, "float64")
        nrm, ok = unit_normals(eval_packed(packed64, tu), eval_packed(packed64, tv))
        if not ok.all():
            nrm = _limit_normals(packed64, np.array(cu), np.array(cv), nrm, ok, "float64")
        ids = net.corner_ids.ravel()
        acc = np.zeros((ids.max() + 1, 3))
        np.add.at(acc, ids, nrm.reshape(-1, 3))
        length = np.linalg.norm(acc, axis=1)
        avg = acc / np.where(length > 1e-12, length, 1.0)[:, None]
        out = np.where((length > 1e-12)[ids, None], avg[ids], nrm.reshape(-1, 3))
        return out.reshape(-1, 4, 3).astype(np.float32)


def _raw_bytes(a: np.ndarray, axes: tuple[int, ...] | None = None) -> np.ndarray | None:
    """The memory of a dense array (C order or any other axis order: ``axes``, largest stride
    first) as a 1-D uint8 view, else None."""
    if a.flags.c_contiguous:
        return a.reshape(-1).view(np.uint8)
    t = a.transpose(np.argsort(a.strides)[::-1] if axes is None else axes)
    return t.reshape(-1).view(np.uint8) if t.flags.c_contiguous else None


class _Snapshot:
    """A copy of an array, compared bitwise with the array's current contents (~2 us for the
    default course's UVs, whatever their memory layout: one pass over the raw bytes, where
    ``np.array_equal`` on the strided (n, 4, 2) UVs took ~60 us)."""

    def __init__(self, a: np.ndarray) -> None:
        a = np.asarray(a)
        self.meta = (a.shape, a.strides, a.dtype)
        self.axes = tuple(int(x) for x in np.argsort(a.strides)[::-1])
        raw = _raw_bytes(a, self.axes)
        self.raw = raw.copy() if raw is not None else None
        self.full = a.copy() if raw is None else None

    def raw_now(self, a: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """``(a's raw bytes, the snapshot's)`` when ``a`` has the snapshot's shape, dtype and dense
        layout (compare those), else None."""
        if self.raw is None or not isinstance(a, np.ndarray) or (a.shape, a.strides, a.dtype) != self.meta:
            return None
        raw = _raw_bytes(a, self.axes)
        return None if raw is None else (raw, self.raw)

    def same(self, a: np.ndarray) -> bool:
        """Whether ``a`` holds the same bits as when the snapshot was taken (any change of shape,
        dtype or layout counts as a change)."""
        a = np.asarray(a)
        if self.raw is None or (a.shape, a.strides, a.dtype) != self.meta:
            full = self.full
            return full is not None and a.shape == full.shape and a.dtype == full.dtype and np.array_equal(full, a)
        raw = _raw_bytes(a, self.axes)
        return raw is not None and _kernels.same_bytes(raw, self.raw)


_NO_BYTES = np.zeros(0, np.uint8)


def _cache(net: PatchNet) -> _NetCache:
    c = net.__dict__.get("_tess_cache")
    if c is None:
        c = _NetCache(net)
        net.__dict__["_tess_cache"] = c
    return c


@lru_cache(maxsize=None)
def _side_tables(s: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Derivative blend tables at the interior points of side ``s`` with ``n`` vertices: ``(16, n-2)`` x2."""
    t = params(n)[1:-1]
    uv = _side_uv(s, t)
    _, tu, tv = blend_tables(tuple(uv[:, 0]), tuple(uv[:, 1]), "float32")
    return tu, tv, uv


def _edge_normals(net: PatchNet, cache: _NetCache, edges: np.ndarray, n: int) -> np.ndarray:
    """Normals at the interior vertices of ``edges`` at level ``n``, averaged over the adjacent
    patches, in each edge's canonical direction: ``(k, n - 2, 3)`` float32."""
    acc = np.zeros((len(edges), n - 2, 3), dtype=np.float32)
    first: np.ndarray | None = None
    for slot in (0, 1):
        pat = net.edge_patches[edges, slot]
        side = net.edge_sides[edges, slot]
        for s in range(4):
            sel = np.nonzero((pat >= 0) & (side == s))[0]
            if not len(sel):
                continue
            p = pat[sel]
            tu, tv, uv = _side_tables(s, n)
            pk = cache.packed[p]
            nrm, ok = unit_normals(eval_packed(pk, tu), eval_packed(pk, tv))
            if not ok.all():
                nrm = _limit_normals(pk, uv[:, 0], uv[:, 1], nrm, ok, "float32").astype(np.float32)
            flip = net.side_flip[p, s]
            nrm[flip] = nrm[flip, ::-1]
            acc[sel] += nrm
            if slot == 0:
                first = first if first is not None else np.zeros_like(acc)
                first[sel] = nrm
    length = np.linalg.norm(acc, axis=-1, keepdims=True)
    good = length > 1e-6
    assert first is not None  # every edge has a patch in slot 0
    return np.where(good, acc / np.where(good, length, 1.0), first)


def _level_array(net: PatchNet, levels: int | np.ndarray) -> np.ndarray:
    """``levels`` (one int, or one per edge) as a contiguous ``(e,) int16`` array: the shape is
    checked here, the values by the caller (the compiled path checks them in its kernel)."""
    if np.isscalar(levels) or np.ndim(levels) == 0:
        return np.full(net.n_edges, int(levels), dtype=np.int16)
    lv = np.asarray(levels)
    if lv.shape != (net.n_edges,):
        raise ValidationError(
            f"{net.name}: levels must be one int or one per edge, shape ({net.n_edges},), got {lv.shape}"
        )
    return np.ascontiguousarray(lv, dtype=np.int16)


def _as_levels(net: PatchNet, levels: int | np.ndarray) -> np.ndarray:
    lv = _level_array(net, levels)
    if lv.min() < 2 or lv.max() > MAX_LEVEL:
        raise ValidationError(f"{net.name}: vertices per edge must be in 2..{MAX_LEVEL}, got {lv.min()}..{lv.max()}")
    return lv


def _normals_cm(du: np.ndarray, dv: np.ndarray, scale4: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit ``du x dv`` for coordinate-major ``(k, 3, s)`` float32 derivatives (contiguous rows,
    so each step is one fast whole-array operation).

    ``scale4`` is ``(k,)``: the fourth power of each patch's size; a normal shorter than
    ``1e-4 * size^2`` is degenerate (a collapsed edge).  Returns ``(normals (k, 3, s), ok (k, s))``.
    """
    ax, ay, az = du[:, 0], du[:, 1], du[:, 2]
    bx, by, bz = dv[:, 0], dv[:, 1], dv[:, 2]
    n = np.empty_like(du)
    np.subtract(ay * bz, az * by, out=n[:, 0])
    np.subtract(az * bx, ax * bz, out=n[:, 1])
    np.subtract(ax * by, ay * bx, out=n[:, 2])
    len2 = n[:, 0] * n[:, 0]
    len2 += n[:, 1] * n[:, 1]
    len2 += n[:, 2] * n[:, 2]
    ok = len2 > (1e-8 * scale4)[:, None]
    inv = 1.0 / np.sqrt(np.where(ok, len2, 1.0))
    n *= inv[:, None, :]
    return n, ok


def _edge_normal_cache(net: PatchNet, cache: _NetCache, n: int) -> np.ndarray:
    """Averaged normals at the interior vertices of every edge at level ``n``, ``(e, n-2, 3)``
    float32, computed on first use and kept (they depend only on the net and the level)."""
    store = cache.edge_normals
    if n not in store:
        store[n] = _edge_normals(net, cache, np.arange(net.n_edges), n)
    return store[n]


class _Frame:
    """Per-frame evaluation shared by the uniform and glue paths: each edge at its level once,
    inner grids by one blend-table product per (block, level)."""

    def __init__(self, net: PatchNet, cache: _NetCache, lv: np.ndarray, pids: np.ndarray,
                 used_levels: Iterable[int]) -> None:
        self.net, self.cache = net, cache
        self.edge_pos: dict[int, np.ndarray] = {}
        self.edge_nrm: dict[int, np.ndarray] = {}
        self.edge_row: dict[int, np.ndarray] = {}
        needed = np.zeros(net.n_edges, dtype=bool)
        needed[net.side_edge[pids]] = True
        for n in used_levels:
            n = int(n)
            if n <= 2 or n in self.edge_row:
                continue
            en = np.flatnonzero((lv == n) & needed)
            row = np.full(net.n_edges, -1, dtype=np.int64)
            row[en] = np.arange(len(en))
            self.edge_row[n] = row
            self.edge_pos[n] = eval_edges(cache.edge_cp[en], n)  # (k, n-2, 3)
            self.edge_nrm[n] = _edge_normal_cache(net, cache, n)[en]

    def side(self, pids: np.ndarray, s: int, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Positions and normals of side ``s`` (level ``n``) of ``pids`` in the side's direction: 2x ``(k, n-2, 3)``."""
        rows = self.edge_row[n][self.net.side_edge[pids, s]]
        kk = np.arange(n - 2)
        flat = (rows * (n - 2))[:, None] + np.where(self.net.side_flip[pids, s][:, None], kk[::-1], kk)
        return (self.edge_pos[n].reshape(-1, 3).take(flat, axis=0),
                self.edge_nrm[n].reshape(-1, 3).take(flat, axis=0))

    def inner(self, pids: np.ndarray, mm: int) -> tuple[np.ndarray, np.ndarray]:
        """Inner grid positions and normals at level ``mm``: 2x ``(k, (mm-2)^2, 3)`` (transposed views)."""
        ti = params(mm)[1:-1]
        vv, uu = np.meshgrid(ti, ti, indexing="ij")
        t, tu, tv = blend_tables(tuple(uu.ravel()), tuple(vv.ravel()), "float32")
        k = len(pids)
        pk = self.cache.packed[pids]
        flat = pk.reshape(k * 3, 16)
        p_in = (flat @ t).reshape(k, 3, -1)
        n_in, ok = _normals_cm((flat @ tu).reshape(k, 3, -1), (flat @ tv).reshape(k, 3, -1), self.cache.scale4[pids])
        n_in = n_in.transpose(0, 2, 1)
        if not ok.all():
            n_in = _limit_normals(pk, uu.ravel(), vv.ravel(), n_in, ok, "float32").astype(np.float32)
        return p_in.transpose(0, 2, 1), n_in


def _bilinear_weights(prm: np.ndarray) -> np.ndarray:
    """Weights of corners c0..c3 at parameters ``(s, 2)``: ``(s, 4)``."""
    u, v = prm[:, 0], prm[:, 1]
    return np.stack([(1 - u) * (1 - v), u * (1 - v), u * v, (1 - u) * v], axis=1).astype(np.float32)


def tessellate(net: PatchNet, levels: int | np.ndarray, patches: npt.ArrayLike | None = None, strips: bool = False,
               cache: bool | None = None,
               use_numba: bool | None = None) -> TerrainMesh:
    """Tessellate ``net`` with per-edge ``levels``.

    Parameters
    ----------
    net : PatchNet
    levels : int or (e,) int array, vertices per edge (4, 6, 8 are the talk's; any 2..64 works)
    patches : (p,) int array, optional: tessellate only these patches (e.g. after frustum culling)
    strips : also build ``mesh.strips`` (triangle strips with primitive restart)
    cache : use the net's vertex cache (each patch evaluated once per level, then every frame is
        gathers of cached vertices: a memory-for-speed trade, ~56 bytes a vertex, 16 MB for the
        default course at levels 4, 6 and 8).  ``False`` evaluates everything this frame with the
        blend tables.  Default: on when the cache stays under 512 MB.  Both give bit-identical
        corners and edges (so both are crack-free); inner points agree to float32 rounding.
    use_numba : the cached path compiled (:func:`piste.terrain._kernels.tess_frame`: patches
        sorted by shape, then vertices, indices and vertex -> patch written straight into the
        outputs, in one call).  Default: when numba is installed and its kernels are loaded (see
        :mod:`piste._jit`); True: whenever numba is installed; False: the numpy path.  Both give
        bit-identical meshes (``cache=False`` always runs numpy).

    Returns
    -------
    TerrainMesh.  Patches come out uniform ones first, grouped by level, then the glue patches
    grouped by shape (``mesh.patch_ids`` gives the order).  Uniform groups are written with
    contiguous slice operations from cached index buffers; glue patches, typically a few percent,
    in one ragged pass over all their shapes.
    """
    if cache is None:
        cache = len(net) * 116 * VERTEX_FLOATS * 4 < 512 * 2**20
    if cache and ((use_numba and _kernels.HAVE_NUMBA) or (use_numba is None and _kernels.tess_ready())):
        return _tessellate_compiled(net, levels, patches, strips)
    lv = _as_levels(net, levels)
    pids = np.arange(len(net), dtype=np.int64) if patches is None else np.asarray(patches, dtype=np.int64).ravel()
    if len(pids) and (pids.min() < 0 or pids.max() >= len(net)):
        raise ValidationError(f"{net.name}: patch ids must be in 0..{len(net) - 1}")
    if len(pids) == 0:  # nothing in view (camera in the sky, below the ground, outside the world)
        return empty_mesh(strips)
    side_lv = lv[net.side_edge[pids]].astype(np.int64)  # (p, 4)
    m = side_lv.max(axis=1) if len(pids) else np.zeros(0, np.int64)
    glue = (side_lv != m[:, None]).any(axis=1)
    key = ((((glue * 65 + m) * 65 + side_lv[:, 0]) * 65 + side_lv[:, 1]) * 65 + side_lv[:, 2]) * 65 + side_lv[:, 3]
    order = np.argsort(key, kind="stable")
    pids, side_lv, m, key, glue = pids[order], side_lv[order], m[order], key[order], glue[order]
    new = np.empty(len(key), dtype=bool)  # keys are sorted: a shape starts where the key changes
    new[:1] = True
    np.not_equal(key[1:], key[:-1], out=new[1:])
    first_of = np.flatnonzero(new)
    shape_of = np.cumsum(new) - 1
    shapes = [get_shape(tuple(side_lv[i].tolist())) for i in first_of]
    s_nv = np.array([sh.n_verts for sh in shapes], dtype=np.int64)
    s_nt = np.array([len(sh.tris) for sh in shapes], dtype=np.int64)
    nv_p, nt_p = s_nv[shape_of], s_nt[shape_of]
    vertex_start = np.concatenate([[0], np.cumsum(nv_p)]).astype(np.int64)
    tri_start = np.concatenate([[0], np.cumsum(nt_p)]).astype(np.int64)
    T = int(tri_start[-1])
    n_uniform = int(np.count_nonzero(~glue))
    indices = np.empty((T, 3), dtype=np.uint32)
    if cache:
        vert = _gather_cached(net, pids, side_lv, m, glue, shapes, shape_of, first_of, vertex_start, n_uniform)
        fields = _vertex_fields(vert)
    else:
        pos, nrm, param, uv, uv_lm, uv_proj = _evaluate_frame(
            net, lv, pids, side_lv, m, glue, shapes, shape_of, first_of, vertex_start, n_uniform)
        fields = {"positions": pos, "normals": nrm, "param": param, "uv": uv, "uv_lightmap": uv_lm,
                  "uv_projected": uv_proj}
    _write_indices(indices, shapes, shape_of, first_of, vertex_start, tri_start, n_uniform)
    vpatch = np.repeat(np.arange(len(pids), dtype=np.int32), nv_p)
    strip_buf = _strips(shapes, shape_of, vertex_start) if strips else None
    return TerrainMesh(
        **fields,
        indices=indices,
        patch_ids=pids,
        patch_kind=np.where(glue, 0, m).astype(np.int8),
        patch_levels=side_lv.astype(np.int16),
        vertex_patch=vpatch,
        vertex_start=vertex_start,
        tri_start=tri_start,
        strips=strip_buf,
    )


def empty_mesh(strips: bool = False) -> TerrainMesh:
    """A TerrainMesh with no patches (what :func:`tessellate` gives for an empty patch list)."""
    f2, f3 = np.zeros((0, 2), np.float32), np.zeros((0, 3), np.float32)
    return TerrainMesh(
        positions=f3, normals=f3.copy(), uv=f2, uv_lightmap=f2.copy(), uv_projected=f2.copy(),
        param=f2.copy(), indices=np.zeros((0, 3), np.uint32), patch_ids=np.zeros(0, np.int64),
        patch_kind=np.zeros(0, np.int8), patch_levels=np.zeros((0, 4), np.int16),
        vertex_patch=np.zeros(0, np.int32), vertex_start=np.zeros(1, np.int64),
        tri_start=np.zeros(1, np.int64), strips=np.zeros(0, np.uint32) if strips else None,
    )


#: floats per cached vertex: position 3, normal 3, param 2, uv 2, light-map uv 2, projected uv 2
VERTEX_FLOATS = 14


def _vertex_fields(vert: np.ndarray) -> dict:
    """The :class:`TerrainMesh` fields held by cached vertices ``(k, VERTEX_FLOATS)`` (views)."""
    return {"positions": vert[:, 0:3], "normals": vert[:, 3:6], "param": vert[:, 6:8], "uv": vert[:, 8:10],
            "uv_lightmap": vert[:, 10:12], "uv_projected": vert[:, 12:14]}


def _strips(shapes: list[Shape], shape_of: np.ndarray, vertex_start: np.ndarray) -> np.ndarray:
    parts = []
    for i in range(len(shape_of)):
        st = np.append(shapes[shape_of[i]].strip, -1)
        parts.append(np.where(st < 0, -1, st + vertex_start[i]))
    sb = np.concatenate(parts)[:-1] if parts else np.zeros(0, np.int64)
    return np.where(sb < 0, RESTART, sb).astype(np.uint32)


def _write_indices(indices: np.ndarray, shapes: list[Shape], shape_of: np.ndarray, first_of: np.ndarray, vertex_start: np.ndarray,
                   tri_start: np.ndarray, n_uniform: int) -> None:
    """Cached index buffers, offset per patch: one broadcast per uniform level, one ragged
    gather for all glue patches."""
    for g, sh in enumerate(shapes):
        a = int(first_of[g])
        if a >= n_uniform:
            continue
        k = int(np.count_nonzero(shape_of == g))
        firstv = vertex_start[a:a + k]
        indices[tri_start[a]:tri_start[a + k]].reshape(k, len(sh.tris), 3)[:] = sh.tris[None] + firstv[:, None, None]
    if n_uniform < len(shape_of):
        so = shape_of[n_uniform:]
        gshapes = np.unique(so)
        s_nt = np.array([len(sh.tris) for sh in shapes], dtype=np.int64)
        s_tstart = np.zeros(len(shapes), np.int64)
        s_tstart[gshapes] = np.concatenate([[0], np.cumsum(s_nt[gshapes])[:-1]])
        all_tris = np.concatenate([shapes[g].tris for g in gshapes])
        nt = s_nt[so]
        tsrc = _kernels.ragged_arange(s_tstart[so], nt)
        indices[tri_start[n_uniform]:] = all_tris[tsrc] + np.repeat(vertex_start[n_uniform:-1], nt)[:, None]


def _tessellate_compiled(net: PatchNet, levels: int | np.ndarray, patches: npt.ArrayLike | None,
                         strips: bool) -> TerrainMesh:
    """The cached path compiled (:func:`piste.terrain._kernels.tess_frame`, one call a frame):
    bit-identical to the numpy path, with no per-frame intermediate the size of the output."""
    lv = _level_array(net, levels)
    pids = np.arange(len(net), dtype=np.int64) if patches is None else np.asarray(patches, dtype=np.int64).ravel()
    pids = np.ascontiguousarray(pids)
    side_edge = net.side_edge
    if side_edge.dtype != np.int32 or not side_edge.flags.c_contiguous:
        side_edge = np.ascontiguousarray(side_edge, dtype=np.int32)
    # numba types read-only arrays apart: keep to the warmed-up signature (no compile mid-frame)
    lv, pids, side_edge = (a if a.flags.writeable else a.copy() for a in (lv, pids, side_edge))
    c = _cache(net)
    for _ in range(4):  # (a new shape, a level not built or edited UVs: register / rebuild, once each)
        grid, level_row, uv_check = c.compiled_state(net)
        status, keys, check, pids_s, side_lv, kind, shape_of, vert, indices, vpatch, vertex_start, tri_start = (
            _kernels.tess_frame(lv, side_edge, pids, len(net), MAX_LEVEL, _SHAPES.arrays, level_row, grid, uv_check))
        if status == _kernels.TESS_OK:
            break
        if status == _kernels.TESS_INVALID:
            if check[0] < 2 or check[1] > MAX_LEVEL:
                raise ValidationError(
                    f"{net.name}: vertices per edge must be in 2..{MAX_LEVEL}, got {check[0]}..{check[1]}")
            raise ValidationError(f"{net.name}: patch ids must be in 0..{len(net) - 1}")
        if status == _kernels.TESS_EMPTY:
            return empty_mesh(strips)
        if status == _kernels.TESS_NEW_SHAPES:
            _SHAPES.add(keys.tolist())
        else:
            c.compiled_state(net, sorted({n for k in keys.tolist() for n in key_levels(int(k))}))
    else:  # pragma: no cover - each cause is fixed by one pass
        raise RuntimeError("compiled tessellation: vertex cache did not settle")
    strip_buf = _strips([get_shape(key_levels(int(k))) for k in keys], shape_of, vertex_start) if strips else None
    return TerrainMesh(
        **_vertex_fields(vert),
        indices=indices,
        patch_ids=pids_s,
        patch_kind=kind,
        patch_levels=side_lv,
        vertex_patch=vpatch,
        vertex_start=vertex_start,
        tri_start=tri_start,
        strips=strip_buf,
    )


def key_levels(key: int) -> tuple:
    """The side levels ``(n0, n1, n2, n3)`` of a shape key (:data:`piste.terrain._kernels.KEY_BASE` digits)."""
    b = _kernels.KEY_BASE
    return tuple(int(key // b ** k % b) for k in (3, 2, 1, 0))


class _ShapeRegistry:
    """Every shape the compiled path has met (process-wide, append-only): its row of the per-shape
    table, its glue sources and its triangles, appended once, and the keys sorted for the kernel's
    binary search (:func:`piste.terrain._kernels.tess_frame`)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.row: dict[int, int] = {}
        #: (keys sorted (g,) int64, their rows (g,), stab (g, 10) int64, src_level, src_slot (s,) int64,
        #: tris (t, 3) uint32), replaced whole (a reader sees the old or the new tables, both valid)
        self.arrays = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 10), np.int64),
                       np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3), np.uint32))

    def add(self, keys: Iterable[Any]) -> None:
        """Register the shapes of ``keys`` not registered yet."""
        with self.lock:
            new = [int(k) for k in dict.fromkeys(keys) if int(k) not in self.row]
            if not new:
                return
            _, _, stab, src_level, src_slot, tris = self.arrays
            shapes = [get_shape(key_levels(k)) for k in new]
            src = [_glue_sources(sh.levels) for sh in shapes]
            nv = np.array([sh.n_verts for sh in shapes], dtype=np.int64)
            nt = np.array([len(sh.tris) for sh in shapes], dtype=np.int64)
            add = np.zeros((len(shapes), 10), dtype=np.int64)
            add[:, 0], add[:, 1] = nv, nt
            add[:, 2] = [sh.uniform for sh in shapes]
            add[:, 3] = [sh.m for sh in shapes]
            add[:, 4] = len(src_level) + np.concatenate([[0], np.cumsum(nv)[:-1]])
            add[:, 5] = len(tris) + np.concatenate([[0], np.cumsum(nt)[:-1]])
            add[:, 6:10] = [sh.levels for sh in shapes]
            for i, k in enumerate(new):
                self.row[k] = len(stab) + i
            keys = np.array(list(self.row), dtype=np.int64)
            order = np.argsort(keys)
            self.arrays = (keys[order], np.array(list(self.row.values()), dtype=np.int64)[order],
                           np.concatenate([stab, add]),
                           np.concatenate([src_level] + [x[0] for x in src]).astype(np.int64),
                           np.concatenate([src_slot] + [x[1] for x in src]).astype(np.int64),
                           np.ascontiguousarray(np.concatenate([tris] + [sh.tris for sh in shapes]).astype(np.uint32)))


_SHAPES = _ShapeRegistry()


@lru_cache(maxsize=None)
def _glue_sources(levels: tuple) -> tuple[np.ndarray, np.ndarray]:
    """For a glue shape: the level and the slot in that level's uniform grid of every vertex."""
    sh = get_shape(levels)
    lvl = np.full(sh.n_verts, sh.m, dtype=np.int64)
    slot = np.empty(sh.n_verts, dtype=np.int64)
    slot[:4] = np.arange(4)
    for s, n in enumerate(levels):
        o = 4 + int(sh.side_off[s])
        lvl[o:o + n - 2] = n
        slot[o:o + n - 2] = 4 + s * (n - 2) + np.arange(n - 2)
    mi = (sh.m - 2) ** 2
    slot[sh.inner_off:] = 4 + 4 * (sh.m - 2) + np.arange(mi)
    return lvl, slot


def _gather_cached(net: PatchNet, pids: np.ndarray, side_lv: np.ndarray, m: np.ndarray, glue: Any, shapes: list[Shape], shape_of: np.ndarray,
                   first_of: np.ndarray, vertex_start: np.ndarray, n_uniform: int) -> np.ndarray:
    """Vertices ``(V, VERTEX_FLOATS)`` float32 gathered from the net's per-level vertex cache."""
    cache = _cache(net)
    flat, offset = cache.grids(net, np.unique(side_lv))
    vert = np.empty((int(vertex_start[-1]), VERTEX_FLOATS), dtype=np.float32)
    for g, sh in enumerate(shapes):
        a = int(first_of[g])
        if a >= n_uniform:
            continue
        k, n = int(np.count_nonzero(shape_of == g)), sh.m
        grid = flat[offset[n]:offset[n] + len(net) * n * n * VERTEX_FLOATS].reshape(len(net), n * n, VERTEX_FLOATS)
        np.take(grid, pids[a:a + k], axis=0, out=vert[vertex_start[a]:vertex_start[a + k]].reshape(k, n * n, -1))
    if n_uniform < len(pids):
        so = shape_of[n_uniform:]
        gshapes = np.unique(so)
        src = [_glue_sources(shapes[g].levels) for g in gshapes]
        nv = np.array([shapes[g].n_verts for g in gshapes], dtype=np.int64)
        start = np.zeros(len(shapes), np.int64)
        start[gshapes] = np.concatenate([[0], np.cumsum(nv)[:-1]])
        lvl = np.concatenate([x[0] for x in src])
        slot = np.concatenate([x[1] for x in src])
        nv_p = np.array([sh.n_verts for sh in shapes], dtype=np.int64)[so]
        vsrc = _kernels.ragged_arange(start[so], nv_p)
        pid = np.repeat(pids[n_uniform:], nv_p)
        lv_v = lvl[vsrc]
        off = np.zeros(MAX_LEVEL + 1, np.int64)
        for n, o in offset.items():
            off[n] = o
        rows = (off[lv_v] // VERTEX_FLOATS) + pid * lv_v * lv_v + slot[vsrc]
        np.take(flat.reshape(-1, VERTEX_FLOATS), rows, axis=0, out=vert[vertex_start[n_uniform]:])
    return vert


def _evaluate_frame(net: PatchNet, lv: np.ndarray, pids: np.ndarray, side_lv: np.ndarray, m: np.ndarray, glue: Any, shapes: list[Shape],
                    shape_of: np.ndarray, first_of: np.ndarray, vertex_start: np.ndarray,
                    n_uniform: int) -> tuple[np.ndarray, ...]:
    """Evaluate every vertex of this frame with the blend tables (no vertex cache)."""
    cache = _cache(net)
    V = int(vertex_start[-1])
    nv_p = np.array([sh.n_verts for sh in shapes], dtype=np.int64)[shape_of]

    pos = np.empty((V, 3), dtype=np.float32)
    nrm = np.empty((V, 3), dtype=np.float32)
    param = np.empty((V, 2), dtype=np.float32)
    uv = np.empty((V, 2), dtype=np.float32)
    uv_lm = np.empty((V, 2), dtype=np.float32)
    frame = _Frame(net, cache, lv, pids, np.unique(side_lv))
    # per-patch corner attributes (p, 4 attrs, 4 corners): base u, v and light-map u, v at c0..c3
    r = net.lightmap_rect[pids]
    lm_corners = np.stack([r[:, [0, 2, 2, 0]], r[:, [1, 1, 3, 3]]], axis=1)  # (p, 2, 4)
    corner_attr = np.concatenate([net.uv[pids].transpose(0, 2, 1), lm_corners], axis=1)  # (p, 4, 4)

    # uniform patches: one contiguous block per level
    for g in range(len(shapes)):
        a = int(first_of[g])
        if glue[a] if len(glue) else True:
            continue
        sh = shapes[g]
        b = a + int(np.count_nonzero(shape_of == g))
        k, nv, n = b - a, sh.n_verts, sh.m
        vs, ve = vertex_start[a], vertex_start[b]
        P, N = pos[vs:ve].reshape(k, nv, 3), nrm[vs:ve].reshape(k, nv, 3)
        sub = pids[a:b]
        P[:, :4] = cache.corners[sub]
        N[:, :4] = cache.corner_normals[sub]
        for s in range(4):
            if n > 2:
                o = 4 + int(sh.side_off[s])
                P[:, o:o + n - 2], N[:, o:o + n - 2] = frame.side(sub, s, n)
        if n > 2:
            P[:, sh.inner_off:], N[:, sh.inner_off:] = frame.inner(sub, n)
        prm = sh.param
        param[vs:ve].reshape(k, nv, 2)[:] = prm
        attr = (corner_attr[a:b].reshape(k * 4, 4) @ _bilinear_weights(prm).T).reshape(k, 4, nv)
        uv[vs:ve].reshape(k, nv, 2)[:] = attr[:, :2].transpose(0, 2, 1)
        uv_lm[vs:ve].reshape(k, nv, 2)[:] = attr[:, 2:].transpose(0, 2, 1)

    # glue patches: one ragged pass over all of them, whatever their shapes
    if n_uniform < len(pids):
        a = n_uniform
        sub = pids[a:]
        base = vertex_start[a:-1]
        gshapes = np.unique(shape_of[a:])
        s_nv = np.array([sh.n_verts for sh in shapes], dtype=np.int64)
        s_vstart = np.zeros(len(shapes), np.int64)
        s_vstart[gshapes] = np.concatenate([[0], np.cumsum(s_nv[gshapes])[:-1]])
        all_param = np.concatenate([shapes[g].param for g in gshapes])
        so = shape_of[a:]
        dst = base[:, None] + np.arange(4)
        pos[dst] = cache.corners[sub]
        nrm[dst] = cache.corner_normals[sub]
        off = np.stack([shapes[g].side_off for g in range(len(shapes))])[so]  # (q, 4)
        lvq = side_lv[a:]
        for s in range(4):
            for n in np.unique(lvq[:, s]):
                n = int(n)
                if n <= 2:
                    continue
                rows = np.flatnonzero(lvq[:, s] == n)
                dst = (base[rows] + 4 + off[rows, s])[:, None] + np.arange(n - 2)
                pos[dst], nrm[dst] = frame.side(sub[rows], s, n)
        inner_off = np.array([sh.inner_off for sh in shapes])[so]
        mq = m[a:]
        for mm in np.unique(mq):
            mm = int(mm)
            rows = np.flatnonzero(mq == mm)
            dst = (base[rows] + inner_off[rows])[:, None] + np.arange((mm - 2) ** 2)
            pos[dst], nrm[dst] = frame.inner(sub[rows], mm)
        vs = vertex_start[a]
        vsrc = _kernels.ragged_arange(s_vstart[so], nv_p[a:])
        prm = all_param[vsrc]
        param[vs:] = prm
        vp = np.repeat(np.arange(len(sub)), nv_p[a:])
        attr = np.einsum("sc,sxc->sx", _bilinear_weights(prm), corner_attr[a:][vp])  # (vq, 4)
        uv[vs:], uv_lm[vs:] = attr[:, :2], attr[:, 2:]

    pos += cache.origin32
    uv_proj = ((pos[:, :2] - cache.proj_origin) / cache.proj_scale).astype(np.float32)
    return pos, nrm, param, uv, uv_lm, uv_proj


# ---------------------------------------------------------------------------------------- checks
def weld_exact(positions: np.ndarray) -> np.ndarray:
    """Ids of bit-identical positions, ``(m,)`` int64 (vertices with the same float32 bits share an id)."""
    bits = np.ascontiguousarray(positions, dtype=np.float32).view(np.uint32).reshape(-1, 3)
    _, ids = np.unique(bits, axis=0, return_inverse=True)
    return ids.ravel()


def open_edges(mesh: TerrainMesh) -> np.ndarray:
    """Mesh edges used by exactly one non-degenerate triangle, after welding bit-identical vertices.

    Returns ``(k, 2)`` int64 pairs of vertex indices (into ``mesh.positions``).  On a crack-free
    tessellation these lie only on the net's true boundary.
    """
    ids = weld_exact(mesh.positions)
    t = ids[mesh.indices.astype(np.int64)]
    keep = (t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2])
    tri = mesh.indices.astype(np.int64)[keep]
    t = t[keep]
    e_ids = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    e_vtx = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    key = np.sort(e_ids, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return e_vtx[cnt[inv.ravel()] == 1]


def terrain_mesh(net: PatchNet, level: int | np.ndarray = 4) -> TerrainMesh:
    """The terrain tessellated for export (:func:`piste.formats.gltf.write.export_gltf`'s
    ``TerrainExport(mesh)``): every edge at ``level`` (4, 6 or 8, or any level 2..64), or per-edge
    levels ``(edges,) int`` (e.g. a camera's ``edge_levels``).  Not cached."""
    if np.ndim(level) == 0:
        lv = int(level)
        if not 2 <= lv <= 64:
            raise ConfigError(f"terrain level must be between 2 and 64 vertices per edge (4, 6 or 8), got {level!r}")
        levels: int | np.ndarray = lv
    else:
        levels = np.asarray(level, dtype=np.int64)
    return tessellate(net, levels, cache=False)
