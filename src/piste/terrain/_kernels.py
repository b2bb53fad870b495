"""Compiled inner loops of the terrain's per-frame work, each with a numpy twin.

numba is optional (the ``fast`` extra; also in ``dev`` and ``bench``): with it these loops are
compiled on first use (cached on disk next to this module; numba is imported then, so a fresh
process does not pay for it before it needs it); without it, or with ``PISTE_NO_NUMBA=1`` in
the environment, the numpy versions run.  Both give bit-identical outputs (the tests compare them);
nothing here does floating-point arithmetic, only copies and integer offsets.

Kernels
-------
frame_indices      per-frame index list from resident shape templates (vertex pulling by block)
gather_cached      the CPU tessellation path: vertices gathered from the per-level vertex cache
                   and indices offset per patch, in one fused pass
side_lod           per-side level, shape key and morph factors of the visible patches
cull_tree          depth-first frustum walk of a :class:`piste.terrain.cull.PatchTree`
"""

from __future__ import annotations

import numpy as np

from piste._jit import HAVE_NUMBA, lazy_njit

__all__ = ["HAVE_NUMBA", "frame_indices", "gather_cached", "ragged_arange", "side_lod", "cull_tree"]


_jit = lazy_njit  # compiled on first call (numba is imported then, not when piste is)


def ragged_arange(starts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Concatenation of ``arange(s, s + c)`` for each pair, vectorised: ``(counts.sum(),)`` int64."""
    counts = np.asarray(counts, dtype=np.int64)
    nz = counts > 0
    starts, counts = np.asarray(starts, dtype=np.int64)[nz], counts[nz]
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64)
    step = np.ones(total, dtype=np.int64)
    ends = np.cumsum(counts)
    step[0] = starts[0]
    step[ends[:-1]] = starts[1:] - (starts[:-1] + counts[:-1] - 1)
    return np.cumsum(step)


# ------------------------------------------------------------------------------ frame indices
def _frame_indices_py(key, base, tmpl, tstart, tcount, out_start, out):
    for i in range(key.shape[0]):
        k = key[i]
        s = tstart[k]
        o = out_start[i]
        b = base[i]
        for j in range(tcount[k]):
            out[o + j] = tmpl[s + j] + b


def _ex_frame_indices():
    i8, u4 = np.zeros(1, np.int64), np.zeros(3, np.uint32)
    return i8, np.zeros(1, np.uint32), u4, i8, np.full(1, 3, np.int64), np.array([0, 3], np.int64), u4.copy()


_frame_indices_nb = _jit(_frame_indices_py, _ex_frame_indices)


def frame_indices(key: np.ndarray, base: np.ndarray, tmpl: np.ndarray, tstart: np.ndarray, tcount: np.ndarray,
                  use_numba: bool | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The index list of one frame: each patch's shape template offset by its vertex block.

    Parameters
    ----------
    key : (p,) int64, the shape of each drawn patch (row of ``tstart`` / ``tcount``)
    base : (p,) int64, first vertex of each patch's block in the resident vertex buffer
    tmpl : (s,) uint32, all shape templates (block-local vertex indices, 3 per triangle)
    tstart, tcount : (k,) int64, where each shape's template starts in ``tmpl`` and its length

    Returns
    -------
    indices (t,) uint32 and start (p + 1,) int64 (first index of each patch; ``start[-1] = t``).
    """
    key = np.ascontiguousarray(key, dtype=np.int64)
    base = np.ascontiguousarray(base, dtype=np.int64)
    cnt = tcount[key]
    start = np.zeros(len(key) + 1, dtype=np.int64)
    np.cumsum(cnt, out=start[1:])
    total = int(start[-1])
    if (ready(_frame_indices_nb) if use_numba is None else use_numba) and total:
        out = np.empty(total, dtype=np.uint32)
        _frame_indices_nb(key, base.astype(np.uint32), tmpl, tstart, tcount, start, out)
        return out, start
    src = ragged_arange(tstart[key], cnt)
    out = tmpl[src] + np.repeat(base.astype(np.uint32), cnt)
    return out.astype(np.uint32, copy=False), start


# ------------------------------------------------------------------------------ CPU tessellation
def _gather_cached_py(pids, shape_of, vertex_start, tri_start, src_start, src_level, src_slot, tri_src_start,
                      tris, level_row, grid, vert, indices):
    nf = grid.shape[1]
    g1 = grid.reshape(-1)
    v1 = vert.reshape(-1)
    i1 = indices.reshape(-1)
    t1 = tris.reshape(-1)
    for i in range(pids.shape[0]):
        p = pids[i]
        g = shape_of[i]
        v0 = vertex_start[i]
        nv = vertex_start[i + 1] - v0
        s0 = src_start[g]
        n0 = src_level[s0]
        uniform = True
        for k in range(nv):
            if src_level[s0 + k] != n0 or src_slot[s0 + k] != k:
                uniform = False
                break
        if uniform:  # one contiguous block of the level's grid
            a = (level_row[n0] + p * n0 * n0) * nf
            b = v0 * nf
            for q in range(nv * nf):
                v1[b + q] = g1[a + q]
        else:
            for k in range(nv):
                n = src_level[s0 + k]
                a = (level_row[n] + p * n * n + src_slot[s0 + k]) * nf
                b = (v0 + k) * nf
                for f in range(nf):
                    v1[b + f] = g1[a + f]
        t0 = tri_start[i] * 3
        nt = (tri_start[i + 1] - tri_start[i]) * 3
        ts = tri_src_start[g] * 3
        for k in range(nt):
            i1[t0 + k] = t1[ts + k] + v0


def _ex_gather():
    i8 = np.zeros(1, np.int64)
    two = np.array([0, 1], np.int64)
    return (i8, i8, two, two, i8, np.full(1, 4, np.int64), i8, i8, np.zeros((1, 3), np.uint32), np.zeros(65, np.int64),
            np.zeros((16, 14), np.float32), np.zeros((1, 14), np.float32), np.zeros((1, 3), np.uint32))


_gather_cached_nb = _jit(_gather_cached_py, _ex_gather)


def ready(kernel) -> bool:
    """Whether ``kernel`` is compiled and loaded (False without numba; the first False starts the
    background warm-up of every kernel, see :mod:`piste._jit`)."""
    return kernel is not None and kernel.ready()


def gather_ready() -> bool:
    return ready(_gather_cached_nb)


def gather_cached(pids, shape_of, vertex_start, tri_start, src_start, src_level, src_slot, tri_src_start, tris,
                  level_row, grid, vert, indices) -> None:
    """Fill ``vert (V, f) float32`` and ``indices (T, 3) uint32`` for the patches ``pids`` (in
    output order) from the level-major vertex cache ``grid (rows, f) float32``.

    ``shape_of (p,)`` indexes the per-shape tables: ``src_start`` into ``src_level``/``src_slot``
    (the level and slot in that level's uniform grid of every local vertex), ``tri_src_start``
    into ``tris (s, 3) uint32`` (local triangles).  ``level_row[n]`` is the first row of level
    ``n``'s grid; patch ``p``'s slot ``s`` at level ``n`` is row ``level_row[n] + p n^2 + s``.
    Needs numba (the numpy path is :func:`piste.terrain.tessellate`'s own)."""
    _gather_cached_nb(pids, shape_of, vertex_start, tri_start, src_start, src_level, src_slot, tri_src_start, tris,
                      level_row, grid, vert, indices)


# ------------------------------------------------------------------------------ LOD per visible side
def _side_lod_py(pids, side_edge, edge_mid, degenerate, eye, near, far, band, lod, morph, n_edges, factors, key):
    """Level index (0 coarse, 1 medium, 2 fine) of every side of ``pids``, the shape key, and the
    morph factors of their edges and inner grids (written into ``factors``)."""
    ex, ey, ez = eye[0], eye[1], eye[2]
    bf = band * near
    if bf < 1e-12:
        bf = 1e-12
    bm = band * (far - near)
    if bm < 1e-12:
        bm = 1e-12
    for i in range(pids.shape[0]):
        p = pids[i]
        k = 0
        lmax = 0
        fin = 0.0
        for s in range(4):
            e = side_edge[p, s]
            if not lod:
                li = 2
                f = 1.0
            else:
                dx = edge_mid[e, 0] - ex
                dy = edge_mid[e, 1] - ey
                dz = edge_mid[e, 2] - ez
                d = np.sqrt(dx * dx + dy * dy + dz * dz)
                if degenerate[e]:
                    li = 0
                elif d < near:
                    li = 2
                elif d < far:
                    li = 1
                else:
                    li = 0
                if li == 2:
                    f = (near - d) / bf
                elif li == 1:
                    f = (far - d) / bm
                else:
                    f = 1.0
                f = min(max(f, 0.0), 1.0)
            if morph:
                factors[e] = np.float32(f)
            if li > lmax:
                lmax = li
                fin = f
            elif li == lmax and f > fin:
                fin = f
            k = k * 3 + li
        if morph:
            factors[n_edges + p] = np.float32(fin)
        key[i] = k


def _ex_side_lod():
    return (np.zeros(1, np.int64), np.zeros((1, 4), np.int64), np.zeros((1, 3)), np.zeros(1, np.bool_), np.zeros(3),
            60.0, 180.0, 0.3, True, True, 1, np.ones(1024, np.float32), np.zeros(1, np.int64))


_side_lod_nb = _jit(_side_lod_py, _ex_side_lod)


def side_lod_ready() -> bool:
    return ready(_side_lod_nb)


def side_lod(pids, side_edge, edge_mid, degenerate, eye, near, far, band, lod, morph, factors) -> np.ndarray:
    """Compiled per-side LOD (see :meth:`piste.terrain.resident.ResidentTerrain.frame`): returns the
    shape key ``(p,)`` int64 and fills ``factors`` when ``morph``.  Needs numba."""
    key = np.empty(len(pids), dtype=np.int64)
    _side_lod_nb(pids, side_edge, edge_mid, degenerate, np.asarray(eye, dtype=np.float64), float(near), float(far),
                 float(band), bool(lod), bool(morph), edge_mid.shape[0], factors, key)
    return key


# ------------------------------------------------------------------------------ tree culling
def _cull_tree_py(node_lo, node_hi, leaf_start, leaf_end, lo_sorted, hi_sorted, depth, planes, out):
    """Depth-first walk of the implicit tree (heap order); writes sorted positions of the visible
    boxes into ``out``, returns how many."""
    nabs = np.abs(planes[:, :3])
    stack = np.empty(2 * depth + 8, dtype=np.int64)
    sl = np.empty(2 * depth + 8, dtype=np.int64)
    top = 0
    stack[0] = 0
    sl[0] = 0
    top = 1
    cnt = 0
    first_leaf = (1 << depth) - 1
    while top > 0:
        top -= 1
        node = stack[top]
        lvl = sl[top]
        cx0 = node_lo[node, 0]
        cy0 = node_lo[node, 1]
        cz0 = node_lo[node, 2]
        cx = (cx0 + node_hi[node, 0]) * 0.5
        cy = (cy0 + node_hi[node, 1]) * 0.5
        cz = (cz0 + node_hi[node, 2]) * 0.5
        hx = (node_hi[node, 0] - cx0) * 0.5
        hy = (node_hi[node, 1] - cy0) * 0.5
        hz = (node_hi[node, 2] - cz0) * 0.5
        outside = False
        inside = True
        for k in range(6):
            dist = planes[k, 0] * cx + planes[k, 1] * cy + planes[k, 2] * cz + planes[k, 3]
            reach = nabs[k, 0] * hx + nabs[k, 1] * hy + nabs[k, 2] * hz
            if dist + reach < 0.0:
                outside = True
                break
            if dist - reach < 0.0:
                inside = False
        if outside:
            continue
        if inside:
            span = 1 << (depth - lvl)
            fl = (node - ((1 << lvl) - 1)) * span
            ll = fl + span - 1
            if ll >= leaf_end.shape[0]:
                ll = leaf_end.shape[0] - 1
            for q in range(leaf_start[fl], leaf_end[ll]):
                out[cnt] = q
                cnt += 1
            continue
        if lvl == depth:
            leaf = node - first_leaf
            for q in range(leaf_start[leaf], leaf_end[leaf]):
                cx = (lo_sorted[q, 0] + hi_sorted[q, 0]) * 0.5
                cy = (lo_sorted[q, 1] + hi_sorted[q, 1]) * 0.5
                cz = (lo_sorted[q, 2] + hi_sorted[q, 2]) * 0.5
                hx = (hi_sorted[q, 0] - lo_sorted[q, 0]) * 0.5
                hy = (hi_sorted[q, 1] - lo_sorted[q, 1]) * 0.5
                hz = (hi_sorted[q, 2] - lo_sorted[q, 2]) * 0.5
                vis = True
                for k in range(6):
                    dist = planes[k, 0] * cx + planes[k, 1] * cy + planes[k, 2] * cz + planes[k, 3]
                    reach = nabs[k, 0] * hx + nabs[k, 1] * hy + nabs[k, 2] * hz
                    if dist + reach < 0.0:
                        vis = False
                        break
                if vis:
                    out[cnt] = q
                    cnt += 1
            continue
        # children (right first so the left one is walked first)
        stack[top] = 2 * node + 2
        sl[top] = lvl + 1
        top += 1
        stack[top] = 2 * node + 1
        sl[top] = lvl + 1
        top += 1
    return cnt


def _ex_cull():
    box = np.zeros((1, 3))
    return (box, box, np.zeros(1, np.int64), np.ones(1, np.int64), box, box, 0, np.zeros((6, 4)), np.zeros(1, np.int64))


_cull_tree_nb = _jit(_cull_tree_py, _ex_cull)


def cull_ready() -> bool:
    return ready(_cull_tree_nb)


def cull_tree(node_lo, node_hi, leaf_start, leaf_end, lo_sorted, hi_sorted, depth, planes) -> np.ndarray:
    """Sorted-order positions of the boxes that meet ``planes`` (compiled walk; needs numba)."""
    out = np.empty(len(lo_sorted), dtype=np.int64)
    k = _cull_tree_nb(node_lo, node_hi, leaf_start, leaf_end, lo_sorted, hi_sorted, int(depth),
                      np.ascontiguousarray(planes, dtype=np.float64), out)
    return out[:k]
