"""Compiled inner loops of the terrain's per-frame work, each with a numpy twin.

numba is optional (the ``fast`` extra; also in ``dev`` and ``bench``): with it these loops are
compiled on first use (cached on disk next to this module; numba is imported then, so a fresh
process does not pay for it before it needs it); without it, or with ``PISTE_NO_NUMBA=1`` in
the environment, the numpy versions run.  Both give bit-identical outputs (the tests compare them);
nothing here does floating-point arithmetic, only copies and integer offsets.

Kernels
-------
frame_indices      per-frame index list from resident shape templates (vertex pulling by block)
tess_plan          the CPU tessellation path, first half: patches sorted by shape, shapes found
tess_gather        second half: vertices copied from the per-level vertex cache and indices
                   offset per patch, straight into the outputs
side_lod           per-side level, shape key and morph factors of the visible patches
cull_tree          depth-first frustum walk of a :class:`piste.terrain.cull.PatchTree`
"""

from __future__ import annotations

import numpy as np

from piste._jit import HAVE_NUMBA, lazy_njit

__all__ = ["HAVE_NUMBA", "frame_indices", "tess_plan", "tess_gather", "same_bytes", "ragged_arange", "side_lod",
           "cull_tree"]


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
#: shape keys: ((((glue * 65 + m) * 65 + n0) * 65 + n1) * 65 + n2) * 65 + n3 (levels <= 64)
KEY_BASE = 65


def _tess_plan_py(lv, side_edge, pids, n_patches, max_level, pids_out, side_out, kind_out, shape_of, ukey, ucount,
                  check):
    """The patches ``pids`` sorted by shape key (stable), and the shapes they use.

    Fills the sorted ids ``pids_out``, their side levels ``side_out (p, 4) int16``, their kind
    ``kind_out (p,) int8`` (the level of a uniform patch, 0 for a glue patch), ``shape_of (p,)``
    (index into the shapes) and the shapes' keys ``ukey`` and patch counts ``ucount`` (ascending
    keys).  ``check`` gets the lowest and highest level of ``lv`` and 1 if a patch id is outside
    ``0..n_patches-1`` (nothing else is written then, nor when a level is outside 2..max_level).
    Returns the number of shapes.

    The sort is a counting sort over the keys rewritten with the levels present in ``lv`` ranked
    (the same order; a small key space when few levels are in use, as with distance LOD: 486
    buckets for 4/6/8), or a stable argsort when too many levels are present for that."""
    p = pids.shape[0]
    ne = lv.shape[0]
    lmin = np.int64(lv[0]) if ne else np.int64(2)
    lmax = lmin
    for e in range(np.uint64(ne)):
        x = np.int64(lv[e])
        lmin = min(lmin, x)
        lmax = max(lmax, x)
    bad = 0
    for i in range(p):
        if pids[i] < 0 or pids[i] >= n_patches:
            bad = 1
    check[0] = lmin
    check[1] = lmax
    check[2] = bad
    if bad or lmin < 2 or lmax > max_level or p == 0:
        return 0
    rank = np.zeros(max_level + 1, np.int64)
    for e in range(np.uint64(ne)):
        rank[lv[e]] = 1
    level_of = np.empty(max_level + 1, np.int64)
    nl = 0
    for n in range(max_level + 1):
        if rank[n]:
            rank[n] = nl
            level_of[nl] = n
            nl += 1
    n_buckets = 2 * nl ** 5
    if n_buckets <= 65536:  # counting sort on the ranked key
        ck = np.empty(p, np.int64)
        hist = np.zeros(n_buckets, np.int64)
        for i in range(np.uint64(p)):  # (unsigned indices: no wrap-around tests, ~1.7x faster)
            q = np.uint64(pids[i])
            a = rank[np.uint64(lv[np.uint64(side_edge[q, 0])])]
            b = rank[np.uint64(lv[np.uint64(side_edge[q, 1])])]
            c = rank[np.uint64(lv[np.uint64(side_edge[q, 2])])]
            d = rank[np.uint64(lv[np.uint64(side_edge[q, 3])])]
            m = max(max(a, b), max(c, d))
            glue = 1 if (a != m or b != m or c != m or d != m) else 0
            k = ((((glue * nl + m) * nl + a) * nl + b) * nl + c) * nl + d
            ck[i] = k
            hist[np.uint64(k)] += 1
        bucket_shape = np.empty(n_buckets, np.int64)
        slev = np.empty((p, 4), np.int64)
        skind = np.empty(p, np.int64)
        u = 0
        o = 0
        for k in range(n_buckets):
            cnt = hist[k]
            if cnt:
                r = k
                lvl = np.empty(6, np.int64)
                for dgt in range(5, -1, -1):
                    lvl[dgt] = r % nl if dgt else r
                    r //= nl
                glue = lvl[0]
                key = glue
                for dgt in range(1, 6):
                    key = key * 65 + level_of[lvl[dgt]]
                for s in range(4):
                    slev[u, s] = level_of[lvl[2 + s]]
                skind[u] = 0 if glue else level_of[lvl[1]]
                ukey[u] = key
                ucount[u] = cnt
                bucket_shape[k] = u
                u += 1
            hist[k] = o
            o += cnt
        for i in range(np.uint64(p)):
            k = np.uint64(ck[i])
            j = np.uint64(hist[k])
            hist[k] = j + 1
            g = bucket_shape[k]
            pids_out[j] = pids[i]
            shape_of[j] = g
            g = np.uint64(g)
            for s in range(4):
                side_out[j, s] = slev[g, s]
            kind_out[j] = skind[g]
        return u
    key = np.empty(p, np.int64)
    for i in range(p):
        q = pids[i]
        a = np.int64(lv[side_edge[q, 0]])
        b = np.int64(lv[side_edge[q, 1]])
        c = np.int64(lv[side_edge[q, 2]])
        d = np.int64(lv[side_edge[q, 3]])
        m = max(max(a, b), max(c, d))
        glue = 1 if (a != m or b != m or c != m or d != m) else 0
        key[i] = ((((glue * 65 + m) * 65 + a) * 65 + b) * 65 + c) * 65 + d
    order = np.argsort(key, kind="mergesort")  # stable, as numpy's
    u = -1
    prev = -1
    for j in range(p):
        i = order[j]
        k = key[i]
        if k != prev:
            u += 1
            ukey[u] = k
            ucount[u] = 0
            prev = k
        ucount[u] += 1
        shape_of[j] = u
        q = pids[i]
        pids_out[j] = q
        m = 0
        for s in range(4):
            x = lv[side_edge[q, s]]
            side_out[j, s] = x
            m = max(m, np.int64(x))
        kind_out[j] = 0 if k >= 65 ** 5 else m
    return u + 1


def _ex_tess_plan():
    i8 = np.zeros(1, np.int64)
    return (np.full(4, 4, np.int16), np.zeros((1, 4), np.int32), i8, 1, 64, i8.copy(), np.zeros((1, 4), np.int16),
            np.zeros(1, np.int8), i8.copy(), i8.copy(), i8.copy(), np.zeros(3, np.int64))


_tess_plan_nb = _jit(_tess_plan_py, _ex_tess_plan)


def _tess_gather_py(pids, shape_of, stab, src_level, src_slot, tris, level_row, grid, vertex_start, tri_start):
    """Vertices, indices and vertex -> patch of the sorted patches ``pids`` from the level-major
    vertex cache ``grid (rows, f) float32``, in one pass straight into the outputs.

    Offsets are unsigned: numba then drops the negative-index wrap-around test, and the copy loops
    vectorise (2-4x faster)."""
    p = pids.shape[0]
    v = 0
    t = 0
    for i in range(p):
        vertex_start[i] = v
        tri_start[i] = t
        g = shape_of[i]
        v += stab[g, 0]
        t += stab[g, 1]
    vertex_start[p] = v
    tri_start[p] = t
    vert = np.empty((v, grid.shape[1]), np.float32)
    indices = np.empty((t, 3), np.uint32)
    vpatch = np.empty(v, np.int32)
    nf = np.uint64(grid.shape[1])
    g1 = grid.reshape(-1)
    v1 = vert.reshape(-1)
    i1 = indices.reshape(-1)
    t1 = tris.reshape(-1)
    for i in range(p):
        q = np.uint64(pids[i])
        g = shape_of[i]
        nv = np.uint64(stab[g, 0])
        v0 = np.uint64(vertex_start[i])
        b = v0 * nf
        if stab[g, 2]:  # uniform: one contiguous block of the level's grid
            a = (np.uint64(level_row[stab[g, 3]]) + q * nv) * nf
            for k in range(nv * nf):
                v1[b + k] = g1[a + k]
        else:
            s0 = np.uint64(stab[g, 4])
            for k in range(nv):
                n = np.uint64(src_level[s0 + k])
                a = (np.uint64(level_row[n]) + q * n * n + np.uint64(src_slot[s0 + k])) * nf
                bk = b + k * nf
                for f in range(nf):
                    v1[bk + f] = g1[a + f]
        pi = np.int32(i)
        for k in range(nv):
            vpatch[v0 + k] = pi
        off = np.uint32(v0)
        t0 = np.uint64(tri_start[i]) * np.uint64(3)
        ts = np.uint64(stab[g, 5]) * np.uint64(3)
        for k in range(np.uint64(stab[g, 1]) * np.uint64(3)):
            i1[t0 + k] = t1[ts + k] + off
    return vert, indices, vpatch


def _ex_tess_gather():
    i8 = np.zeros(1, np.int64)
    stab = np.array([[4, 2, 1, 2, 0, 0]], np.int64)
    return (i8, i8.copy(), stab, np.full(4, 2, np.int64), np.arange(4, dtype=np.int64),
            np.array([[0, 1, 2], [0, 2, 3]], np.uint32), np.zeros(65, np.int64), np.zeros((4, 14), np.float32),
            np.zeros(2, np.int64), np.zeros(2, np.int64))


_tess_gather_nb = _jit(_tess_gather_py, _ex_tess_gather)


def _same_bytes_py(a, b):
    n8 = a.shape[0] // 8 * 8
    a8 = a[:n8].view(np.uint64)
    b8 = b[:n8].view(np.uint64)
    d = np.uint64(0)
    for i in range(np.uint64(a8.shape[0])):  # 8 bytes a step, unsigned: vectorised
        d |= a8[i] ^ b8[i]
    for i in range(n8, a.shape[0]):
        d |= np.uint64(a[i] ^ b[i])
    return d == 0


def _ex_same_bytes():
    return np.zeros(8, np.uint8), np.zeros(8, np.uint8)


_same_bytes_nb = _jit(_same_bytes_py, _ex_same_bytes)


def same_bytes(a: np.ndarray, b: np.ndarray, use_numba: bool | None = None) -> bool:
    """Whether two 1-D uint8 arrays hold the same bytes (compiled: one vectorised pass, no
    temporary; numpy: ``np.array_equal``)."""
    if a.shape != b.shape:
        return False
    if ready(_same_bytes_nb) if use_numba is None else use_numba:
        return bool(_same_bytes_nb(a, b))
    return bool(np.array_equal(a, b))


def ready(kernel) -> bool:
    """Whether ``kernel`` is compiled and loaded (False without numba; the first False starts the
    background warm-up of every kernel, see :mod:`piste._jit`)."""
    return kernel is not None and kernel.ready()


def gather_ready() -> bool:
    """Whether the compiled CPU tessellation path (:func:`tess_plan` + :func:`tess_gather`) is ready."""
    return ready(_tess_plan_nb) and ready(_tess_gather_nb)


def tess_plan(lv, side_edge, pids, n_patches, max_level):
    """Compiled first half of the cached CPU tessellation (needs numba; the numpy path is
    :func:`piste.terrain.tessellate`'s own).

    Parameters
    ----------
    lv : (e,) int16, vertices per edge
    side_edge : (n, 4) int32, the net's edge of each side
    pids : (p,) int64, the patches to tessellate

    Returns
    -------
    ``(check, pids, side_levels, kind, shape_of, keys, counts)``: ``check (3,) int64`` = lowest
    level, highest level, 1 if a patch id is out of range (then, or if a level is outside
    ``2..max_level``, the other outputs are meaningless); the patches sorted by shape key
    (stable), ``(p,) int64``; their ``(p, 4) int16`` side levels; ``(p,) int8`` kind (level of a
    uniform patch, 0 glue); ``(p,) int64`` index of each one's shape; the shapes' keys
    (ascending, :data:`KEY_BASE` digits glue, m, n0..n3) and patch counts, ``(u,) int64``."""
    p = len(pids)
    out = (np.empty(p, np.int64), np.empty((p, 4), np.int16), np.empty(p, np.int8), np.empty(p, np.int64),
           np.empty(p, np.int64), np.empty(p, np.int64))
    check = np.empty(3, np.int64)
    u = _tess_plan_nb(lv, side_edge, pids, n_patches, max_level, *out, check)
    return check, out[0], out[1], out[2], out[3], out[4][:u], out[5][:u]


def tess_gather(pids, shape_of, stab, src_level, src_slot, tris, level_row, grid):
    """Compiled second half of the cached CPU tessellation: every patch's vertices copied from the
    level-major vertex cache ``grid (rows, f) float32`` and its triangles offset to its block,
    straight into the outputs (needs numba).

    ``stab (u, 6) int64`` holds per shape: vertices, triangles, uniform (0/1), inner level ``m``,
    first entry in ``src_level``/``src_slot`` (the level and the slot in that level's uniform
    grid of each vertex of a glue shape) and first triangle in ``tris (s, 3) uint32`` (local
    triangles of every shape).  ``level_row[n]`` is the first row of level ``n``'s grid; patch
    ``q``'s slot ``s`` at level ``n`` is row ``level_row[n] + q n^2 + s``.

    Returns ``(vert (V, f) float32, indices (T, 3) uint32, vertex_patch (V,) int32, vertex_start
    (p + 1,) int64, tri_start (p + 1,) int64)``."""
    p = len(pids)
    vertex_start, tri_start = np.empty(p + 1, np.int64), np.empty(p + 1, np.int64)
    vert, indices, vpatch = _tess_gather_nb(pids, shape_of, stab, src_level, src_slot, tris, level_row, grid,
                                            vertex_start, tri_start)
    return vert, indices, vpatch, vertex_start, tri_start


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
