"""Compiled inner loops of the terrain's per-frame work, each with a numpy twin.

numba is optional (the ``fast`` extra; also in ``dev`` and ``bench``): with it these loops are
compiled on first use (cached on disk next to this module; numba is imported then, so a fresh
process does not pay for it before it needs it); without it, or with ``PISTE_NO_NUMBA=1`` in
the environment, the numpy versions run.  Both give bit-identical outputs (the tests compare them);
nothing here does floating-point arithmetic, only copies and integer offsets.

Kernels
-------
frame_indices      per-frame index list from resident shape templates (vertex pulling by block)
tess_frame         the CPU tessellation path in one call: patches sorted by shape, the vertex
                   cache checked, vertices copied from it and indices offset per patch,
                   straight into the outputs
side_lod           per-side level, shape key and morph factors of the visible patches
front_indices      the index list without the patches wholly facing away (normal cones)
cull_tree          depth-first frustum walk of a :class:`piste.terrain.cull.PatchTree`
"""

from __future__ import annotations

from typing import Any, no_type_check

import numpy as np
import numpy.typing as npt

from piste._jit import HAVE_NUMBA, lazy_njit

__all__ = ["HAVE_NUMBA", "frame_indices", "tess_frame", "same_bytes", "ragged_arange", "side_lod",
           "cull_tree", "front_indices"]


_jit = lazy_njit  # compiled on first call (numba is imported then, not when piste is)

# The kernel bodies (the ``_*_py`` functions compiled by ``_jit``) are left unannotated: numba types
# them from the example arguments, with numpy scalar types (uint64 offsets, int64 keys) that mypy's
# numpy stubs would reject where a body rebinds a name: each is marked @no_type_check (which only
# sets an attribute on the function numba compiles), and the typed wrappers below are the module's API.


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
@no_type_check
def _frame_indices_py(key, base, tmpl, tstart, tcount, out_start, out):
    # unsigned offsets: numba then emits no negative-index wrap-around and LLVM vectorises the copy + add
    for i in range(key.shape[0]):
        k = key[i]
        s = np.uint64(tstart[k])
        o = np.uint64(out_start[i])
        b = base[i]
        for j in range(np.uint64(tcount[k])):
            out[o + j] = tmpl[s + j] + b


def _ex_frame_indices() -> tuple:
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


#: :func:`tess_frame` status codes
TESS_OK, TESS_INVALID, TESS_EMPTY, TESS_NEW_SHAPES, TESS_STALE = 0, 1, 2, 3, 4


@no_type_check
def _tess_frame_py(lv, side_edge, pids, n_patches, max_level, reg_keys, reg_rows, stab, src_level, src_slot, tris,
                   level_row, grid, uv_now, uv_snap, lm_now, lm_snap, pids_out, side_out, kind_out, shape_of, ukey,
                   check):
    """One frame of the cached CPU tessellation: sort, check, gather (see :func:`tess_frame`)."""
    nf0 = grid.shape[1]
    # -- the patches sorted by shape key (stable), the shapes they use
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
    u_count = 0
    if not (bad or lmin < 2 or lmax > max_level or p == 0):
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
                    full_key = glue
                    for dgt in range(1, 6):
                        full_key = full_key * 65 + level_of[lvl[dgt]]
                    for s in range(4):
                        slev[u, s] = level_of[lvl[2 + s]]
                    skind[u] = 0 if glue else level_of[lvl[1]]
                    ukey[u] = full_key
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
            u_count = u
        else:
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
                    prev = k
                shape_of[j] = u
                q = pids[i]
                pids_out[j] = q
                m = 0
                for s in range(4):
                    x = lv[side_edge[q, s]]
                    side_out[j, s] = x
                    m = max(m, np.int64(x))
                kind_out[j] = 0 if k >= 65 ** 5 else m
            u_count = u + 1
    u = u_count
    if u == 0:
        status = TESS_INVALID if (check[2] or check[0] < 2 or check[1] > max_level) else TESS_EMPTY
        return (status, 0, np.empty((0, nf0), np.float32), np.empty((0, 3), np.uint32), np.empty(0, np.int32),
                np.zeros(1, np.int64), np.zeros(1, np.int64))
    # each shape's row in the registry (binary search of its sorted keys)
    rows = np.empty(u, np.int64)
    nreg = reg_keys.shape[0]
    missing = False
    for j in range(u):
        lo = 0
        hi = nreg
        k = ukey[j]
        while lo < hi:
            mid = (lo + hi) // 2
            if reg_keys[mid] < k:
                lo = mid + 1
            else:
                hi = mid
        if lo < nreg and reg_keys[lo] == k:
            rows[j] = reg_rows[lo]
        else:
            missing = True
    stale = False
    if not missing:
        for j in range(u):
            r = rows[j]
            if level_row[stab[r, 3]] < 0:
                stale = True
            for c in range(6, 10):
                if level_row[stab[r, c]] < 0:
                    stale = True
        d = np.uint64(0)  # the vertex cache's UVs still the net's (bitwise)?
        if uv_now.shape[0] != uv_snap.shape[0] or lm_now.shape[0] != lm_snap.shape[0]:
            stale = True
        else:
            for a, b in ((uv_now, uv_snap), (lm_now, lm_snap)):
                n8 = a.shape[0] // 8 * 8
                a8 = a[:n8].view(np.uint64)
                b8 = b[:n8].view(np.uint64)
                for i in range(np.uint64(a8.shape[0])):  # 8 bytes a step, unsigned: vectorised
                    d |= a8[i] ^ b8[i]
                for i in range(n8, a.shape[0]):
                    d |= np.uint64(a[i] ^ b[i])
            stale = stale or d != 0
    if missing or stale:
        return (TESS_NEW_SHAPES if missing else TESS_STALE, u, np.empty((0, nf0), np.float32),
                np.empty((0, 3), np.uint32), np.empty(0, np.int32), np.zeros(1, np.int64), np.zeros(1, np.int64))
    # the gather: vertices from the level-major vertex cache, indices offset, vertex -> patch.  Offsets
    # are unsigned: numba then drops the negative-index wrap-around test and the copies vectorise.
    p = pids_out.shape[0]
    vertex_start = np.empty(p + 1, np.int64)
    tri_start = np.empty(p + 1, np.int64)
    v = 0
    t = 0
    for i in range(p):
        vertex_start[i] = v
        tri_start[i] = t
        g = rows[shape_of[i]]
        v += stab[g, 0]
        t += stab[g, 1]
    vertex_start[p] = v
    tri_start[p] = t
    vert = np.empty((v, nf0), np.float32)
    indices = np.empty((t, 3), np.uint32)
    vpatch = np.empty(v, np.int32)
    nf = np.uint64(nf0)
    g1 = grid.reshape(-1)
    v1 = vert.reshape(-1)
    i1 = indices.reshape(-1)
    t1 = tris.reshape(-1)
    for i in range(p):
        q = np.uint64(pids_out[i])
        g = rows[shape_of[i]]
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
    return TESS_OK, u, vert, indices, vpatch, vertex_start, tri_start


def _ex_tess_frame() -> tuple:
    i8 = np.zeros(1, np.int64)
    stab = np.array([[4, 2, 1, 2, 0, 0, 2, 2, 2, 2]], np.int64)
    level_row = np.full(65, -1, np.int64)
    level_row[2] = 0
    u8 = np.zeros(8, np.uint8)
    key = np.array([((((0 * 65 + 2) * 65 + 2) * 65 + 2) * 65 + 2) * 65 + 2], np.int64)  # uniform, level 2
    return (np.full(4, 2, np.int16), np.zeros((1, 4), np.int32), i8, 1, 64, key, i8.copy(), stab,
            np.full(4, 2, np.int64), np.arange(4, dtype=np.int64), np.array([[0, 1, 2], [0, 2, 3]], np.uint32),
            level_row, np.zeros((4, 14), np.float32), u8, u8.copy(), u8.copy(), u8.copy(), i8.copy(),
            np.zeros((1, 4), np.int16), np.zeros(1, np.int8), i8.copy(), i8.copy(), np.zeros(3, np.int64))


_tess_frame_nb = _jit(_tess_frame_py, _ex_tess_frame)


@no_type_check
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


def _ex_same_bytes() -> tuple:
    return np.zeros(8, np.uint8), np.zeros(8, np.uint8)


_same_bytes_nb = _jit(_same_bytes_py, _ex_same_bytes)


def same_bytes(a: np.ndarray, b: np.ndarray, use_numba: bool | None = None) -> bool:
    """Whether two 1-D uint8 arrays hold the same bytes (compiled: one vectorised pass, no
    temporary; numpy: ``np.array_equal``).  Default: compiled once numba has loaded it; unlike
    the other dispatchers this one does not start numba's warm-up (the numpy tessellation path
    asks it every frame, and with ``use_numba=False`` it should not pull numba in)."""
    if a.shape != b.shape:
        return False
    k = _same_bytes_nb
    if (k is not None and k.compiled is not None and k.ready()) if use_numba is None else use_numba:
        return bool(_same_bytes_nb(a, b))
    return bool(np.array_equal(a, b))


def ready(kernel: Any) -> bool:
    """Whether ``kernel`` is compiled and loaded (False without numba; the first False starts the
    background warm-up of every kernel, see :mod:`piste._jit`)."""
    return kernel is not None and kernel.ready()


def tess_ready() -> bool:
    """Whether the compiled CPU tessellation (:func:`tess_frame`) is compiled and loaded."""
    return ready(_tess_frame_nb)


gather_ready = tess_ready  # (its earlier name: tests/terrain/test_resident.py asks it)


def tess_frame(lv: np.ndarray, side_edge: np.ndarray, pids: np.ndarray, n_patches: int, max_level: int, registry: tuple,
               level_row: np.ndarray, grid: np.ndarray, uv_check: tuple) -> tuple:
    """One frame of the cached CPU tessellation, compiled (needs numba; the numpy path is
    :func:`piste.terrain.tessellate`'s own).  In one call: the patches sorted by shape key
    (stable: a counting sort over the keys with the present levels ranked, or an argsort when
    many levels are present), each shape found in the registry, the vertex cache checked (every
    level built, the UVs unchanged), then every patch's vertices copied from the level-major cache
    and its triangles offset to its block, straight into the outputs.

    Parameters
    ----------
    lv : (e,) int16, vertices per edge
    side_edge : (n, 4) int32, the net's edge of each side
    pids : (p,) int64, the patches to tessellate
    registry : ``(keys, rows, stab, src_level, src_slot, tris)``: the known shape keys sorted
        ``(g,) int64`` and their rows of ``stab (g, 10) int64`` (vertices, triangles, uniform,
        inner level ``m``, first entry in ``src_level`` / ``src_slot``, first triangle in ``tris
        (t, 3) uint32``, levels n0..n3); ``src_level`` / ``src_slot`` hold the level and the slot
        in that level's uniform grid of each vertex of each shape
    level_row : (max_level + 1,) int64, first row of each level's grid in ``grid (rows, f)
        float32`` (-1: not built); patch ``q``'s slot ``s`` at level ``n`` is row ``level_row[n]
        + q n^2 + s``
    uv_check : ``(uv_now, uv_snap, lm_now, lm_snap)``, 1-D uint8: the net's UVs and light-map
        rects as raw bytes and the vertex cache's snapshot of them

    Returns
    -------
    ``(status, keys, check, pids, side_levels, kind, shape_of, vert, indices, vertex_patch,
    vertex_start, tri_start)``.  ``status``: :data:`TESS_OK`; :data:`TESS_INVALID` (``check (3,) int64`` holds
    the lowest and highest level and 1 if a patch id is out of range); :data:`TESS_EMPTY`;
    :data:`TESS_NEW_SHAPES` (``keys`` has shapes not in the registry) or :data:`TESS_STALE` (a
    level is not built or the UVs changed): register / rebuild and call again.  ``keys (u,)
    int64`` the shapes' keys ascending (:data:`KEY_BASE` digits glue, m, n0..n3); the patches
    sorted ``(p,) int64``, their ``(p, 4) int16`` side levels, ``(p,) int8`` kind (level of a
    uniform patch, 0 glue) and ``(p,) int64`` index into ``keys``; ``vert (V, f) float32``,
    ``indices (T, 3) uint32``, ``vertex_patch (V,) int32``, ``vertex_start`` and ``tri_start
    (p + 1,) int64``."""
    p = len(pids)
    pids_out, shape_of, ukey = np.empty(p, np.int64), np.empty(p, np.int64), np.empty(p, np.int64)
    side_out, kind_out = np.empty((p, 4), np.int16), np.empty(p, np.int8)
    check = np.empty(3, np.int64)
    status, u, vert, indices, vpatch, vertex_start, tri_start = _tess_frame_nb(
        lv, side_edge, pids, n_patches, max_level, *registry, level_row, grid, *uv_check, pids_out, side_out,
        kind_out, shape_of, ukey, check)
    # arrays numba allocated carry dtype objects numpy does not call builtin (some consumers, e.g.
    # vispy, then misread them): plain views with numpy's own dtypes
    vert, indices, vpatch = vert.view(np.float32), indices.view(np.uint32), vpatch.view(np.int32)
    vertex_start, tri_start = vertex_start.view(np.int64), tri_start.view(np.int64)
    return (status, ukey[:u], check, pids_out, side_out, kind_out, shape_of, vert, indices, vpatch, vertex_start,
            tri_start)


# ------------------------------------------------------------------------------ LOD per visible side
@no_type_check
def _side_lod_py(pids, side_edge, edge_mid, degenerate, eye, near, far, band, lod, morph, n_edges, factors, flat_err,
                 coarse_err, flat_lo, flat_hi, flat_tol, key):
    """Level index (-1 flat, 0 coarse, 1 medium, 2 fine) of every side of ``pids``, the shape key
    (digits level index + 1, base 4), and the morph factors of their edges and inner grids (written
    into ``factors``).  With ``lim = flat_tol * d``, ``d`` the eye's distance to the edge's box
    ``flat_lo[e], flat_hi[e]``: a side goes flat when ``flat_err[e] < lim``, else coarse when
    ``coarse_err[e] < lim`` (``flat_tol`` 0: by distance alone)."""
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
        lmax = -2
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
                if flat_tol > 0.0:
                    gx = max(max(flat_lo[e, 0] - ex, ex - flat_hi[e, 0]), 0.0)
                    gy = max(max(flat_lo[e, 1] - ey, ey - flat_hi[e, 1]), 0.0)
                    gz = max(max(flat_lo[e, 2] - ez, ez - flat_hi[e, 2]), 0.0)
                    lim = flat_tol * np.sqrt(gx * gx + gy * gy + gz * gz)
                    if flat_err[e] < lim:
                        li = -1
                    elif li > 0 and coarse_err[e] < lim:
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
            k = k * 4 + li + 1
        if morph:
            factors[n_edges + p] = np.float32(fin)
        key[i] = k


def _ex_side_lod() -> tuple:
    return (np.zeros(1, np.int64), np.zeros((1, 4), np.int64), np.zeros((1, 3)), np.zeros(1, np.bool_), np.zeros(3),
            60.0, 180.0, 0.3, True, True, 1, np.ones(1024, np.float32), np.zeros(1), np.zeros(1), np.zeros((1, 3)),
            np.zeros((1, 3)), 0.0, np.zeros(1, np.int64))


_side_lod_nb = _jit(_side_lod_py, _ex_side_lod)


def side_lod_ready() -> bool:
    return ready(_side_lod_nb)


def side_lod(pids: np.ndarray, side_edge: np.ndarray, edge_mid: np.ndarray, degenerate: np.ndarray, eye: npt.ArrayLike, near: float, far: float,
             band: float, lod: bool, morph: bool, factors: np.ndarray, flat_err: np.ndarray | None = None,
             flat_lo: np.ndarray | None = None, flat_hi: np.ndarray | None = None, flat_tol: float = 0.0,
             coarse_err: np.ndarray | None = None) -> np.ndarray:
    """Compiled per-side LOD (see :meth:`piste.terrain.resident.ResidentTerrain.frame`): returns the
    shape key ``(p,)`` int64 and fills ``factors`` when ``morph``.  ``flat_err (e,)``, ``flat_lo``,
    ``flat_hi (e, 3)`` float64 (:func:`piste.terrain.lod.flat_bounds`), ``coarse_err (e,)``
    (:func:`piste.terrain.lod.level_errors` of the coarse level) with ``flat_tol > 0``: sides go flat,
    or coarse, where the error seen from the eye allows.  Needs numba."""
    key = np.empty(len(pids), dtype=np.int64)
    if flat_err is None or not flat_tol:
        flat_err, flat_lo, flat_hi, flat_tol = np.zeros(1), np.zeros((1, 3)), np.zeros((1, 3)), 0.0
    if coarse_err is None:  # (never coarser than the distance says)
        coarse_err = np.full(len(flat_err), np.inf)
    _side_lod_nb(pids, side_edge, edge_mid, degenerate, np.asarray(eye, dtype=np.float64), float(near), float(far),
                 float(band), bool(lod), bool(morph), edge_mid.shape[0], factors, flat_err, coarse_err, flat_lo,
                 flat_hi, float(flat_tol), key)
    return key


# ------------------------------------------------------------------------------ back-facing patches
@no_type_check
def _front_py(pids, key, family, base, tmpl, tstart, tcount, axis, cos, sin, done, centre, radius, eye, out):
    """Indices of the patches not wholly facing away from ``eye`` into ``out``; their count, or -1
    when a patch's cone is not computed yet (nothing written then)."""
    n = pids.shape[0]
    for i in range(n):
        if not done[family[key[i]], pids[i]]:
            return -1
    ex, ey, ez = eye[0], eye[1], eye[2]
    o = 0
    for i in range(n):
        p = pids[i]
        j = family[key[i]]
        c = cos[j, p]
        if c > 0.0:
            vx = centre[p, 0] - ex
            vy = centre[p, 1] - ey
            vz = centre[p, 2] - ez
            va = vx * axis[j, p, 0] + vy * axis[j, p, 1] + vz * axis[j, p, 2]
            vv = vx * vx + vy * vy + vz * vz
            q = vv - va * va
            vp = np.sqrt(q) if q > 0.0 else 0.0
            if va * c - vp * sin[j, p] > radius[p] * (1.0 + 1e-6) + 1e-6 * np.sqrt(vv):
                continue
        k = key[i]
        st = tstart[k]
        b = np.uint32(base[i])
        for t in range(tcount[k]):
            out[o + t] = tmpl[st + t] + b
        o += tcount[k]
    return o


def _ex_front() -> tuple:
    i8 = np.zeros(1, np.int64)
    return (i8, i8.copy(), np.zeros(1, np.int64), i8.copy(), np.zeros(3, np.uint32), i8.copy(), np.full(1, 3, np.int64),
            np.zeros((4, 1, 3)), np.zeros((4, 1)), np.zeros((4, 1)), np.ones((4, 1), np.bool_), np.zeros((1, 3)),
            np.zeros(1), np.zeros(3), np.zeros(3, np.uint32))


_front_nb = _jit(_front_py, _ex_front)


def front_ready() -> bool:
    return ready(_front_nb)


def front_indices(pids: np.ndarray, key: np.ndarray, family: np.ndarray, base: np.ndarray, tmpl: np.ndarray, tstart: np.ndarray, tcount: np.ndarray, axis: np.ndarray,
                  cos: np.ndarray, sin: np.ndarray, done: np.ndarray, centre: np.ndarray, radius: np.ndarray, eye: npt.ArrayLike,
                  total: int) -> np.ndarray | None:
    """Compiled: the frame's index list (as :func:`frame_indices`) without the patches whose family
    cone (``axis (4, N, 3)``, ``cos``, ``sin (4, N)``, ``done (4, N)`` bool) and box sphere (``centre
    (N, 3)``, ``radius (N,)``) put every triangle behind the eye (see
    :meth:`piste.terrain.resident.ResidentTerrain.facing`); ``(t',)`` uint32, or None when a cone is
    missing.  ``total``: the full list's length.  Needs numba."""
    out = np.empty(total, dtype=np.uint32)
    k = _front_nb(pids, key, family, base, tmpl, tstart, tcount, axis, cos, sin, done, centre, radius,
                  np.asarray(eye, dtype=np.float64), out)
    return None if k < 0 else out[:k]


# ------------------------------------------------------------------------------ tree culling
@no_type_check
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


def _ex_cull() -> tuple:
    box = np.zeros((1, 3))
    return (box, box, np.zeros(1, np.int64), np.ones(1, np.int64), box, box, 0, np.zeros((6, 4)), np.zeros(1, np.int64))


_cull_tree_nb = _jit(_cull_tree_py, _ex_cull)


def cull_ready() -> bool:
    return ready(_cull_tree_nb)


def cull_tree(node_lo: np.ndarray, node_hi: np.ndarray, leaf_start: np.ndarray, leaf_end: np.ndarray, lo_sorted: np.ndarray, hi_sorted: np.ndarray,
              depth: int, planes: npt.ArrayLike) -> np.ndarray:
    """Sorted-order positions of the boxes that meet ``planes`` (compiled walk; needs numba)."""
    out = np.empty(len(lo_sorted), dtype=np.int64)
    k = _cull_tree_nb(node_lo, node_hi, leaf_start, leaf_end, lo_sorted, hi_sorted, int(depth),
                      np.ascontiguousarray(planes, dtype=np.float64), out)
    return out[:k]


# ---------------------------------------------------------------------------- height queries
@no_type_check
def _height_newton_py(cp, p, target, u, v, tol, max_iter, done, z):
    """Newton on ``Q(u, v).xy = target`` for each (query, patch) pair, as
    :func:`piste.terrain.query.height_at` iterates in numpy: ``u, v`` updated in place (clipped to
    ``[-0.5, 1.5]`` a step), ``done`` where ``max |Q.xy - target| <= tol``; then ``z`` at the
    parameters clipped to ``[0, 1]``.  A pair whose Jacobian is singular stops (not done)."""
    for k in range(p.shape[0]):
        c = cp[p[k]]
        uu = u[k]
        vv = v[k]
        for _ in range(max_iter):
            su = 1.0 - uu
            sv = 1.0 - vv
            bu0, bu1, bu2, bu3 = su * su * su, 3.0 * uu * su * su, 3.0 * uu * uu * su, uu * uu * uu
            bv0, bv1, bv2, bv3 = sv * sv * sv, 3.0 * vv * sv * sv, 3.0 * vv * vv * sv, vv * vv * vv
            du0, du1 = -3.0 * su * su, 3.0 * su * su - 6.0 * uu * su
            du2, du3 = 6.0 * uu * su - 3.0 * uu * uu, 3.0 * uu * uu
            dv0, dv1 = -3.0 * sv * sv, 3.0 * sv * sv - 6.0 * vv * sv
            dv2, dv3 = 6.0 * vv * sv - 3.0 * vv * vv, 3.0 * vv * vv
            qx = qy = ux = uy = vx = vy = 0.0
            for i in range(4):
                bi = bu0 if i == 0 else (bu1 if i == 1 else (bu2 if i == 2 else bu3))
                di = du0 if i == 0 else (du1 if i == 1 else (du2 if i == 2 else du3))
                ax = c[i, 0, 0] * bv0 + c[i, 1, 0] * bv1 + c[i, 2, 0] * bv2 + c[i, 3, 0] * bv3
                ay = c[i, 0, 1] * bv0 + c[i, 1, 1] * bv1 + c[i, 2, 1] * bv2 + c[i, 3, 1] * bv3
                ex = c[i, 0, 0] * dv0 + c[i, 1, 0] * dv1 + c[i, 2, 0] * dv2 + c[i, 3, 0] * dv3
                ey = c[i, 0, 1] * dv0 + c[i, 1, 1] * dv1 + c[i, 2, 1] * dv2 + c[i, 3, 1] * dv3
                qx += bi * ax
                qy += bi * ay
                ux += di * ax
                uy += di * ay
                vx += bi * ex
                vy += bi * ey
            fx = qx - target[k, 0]
            fy = qy - target[k, 1]
            if max(abs(fx), abs(fy)) <= tol:
                done[k] = True
                break
            det = ux * vy - uy * vx
            if not abs(det) > 1e-300:
                break
            uu = min(max(uu - (fx * vy - fy * vx) / det, -0.5), 1.5)
            vv = min(max(vv - (ux * fy - uy * fx) / det, -0.5), 1.5)
        u[k] = uu
        v[k] = vv
        if done[k]:
            cu = min(max(uu, 0.0), 1.0)
            cv = min(max(vv, 0.0), 1.0)
            su = 1.0 - cu
            sv = 1.0 - cv
            bu = (su * su * su, 3.0 * cu * su * su, 3.0 * cu * cu * su, cu * cu * cu)
            bv = (sv * sv * sv, 3.0 * cv * sv * sv, 3.0 * cv * cv * sv, cv * cv * cv)
            zz = 0.0
            for i in range(4):
                zz += bu[i] * (c[i, 0, 2] * bv[0] + c[i, 1, 2] * bv[1] + c[i, 2, 2] * bv[2] + c[i, 3, 2] * bv[3])
            z[k] = zz


def _ex_height_newton() -> tuple:
    cp = np.zeros((1, 4, 4, 3))
    return (cp, np.zeros(1, np.int64), np.zeros((1, 2)), np.zeros(1), np.zeros(1), 1e-9, 30,
            np.zeros(1, np.bool_), np.zeros(1))


_height_newton_nb = _jit(_height_newton_py, _ex_height_newton)


def height_newton_ready() -> bool:
    return ready(_height_newton_nb)


def height_newton(cp: npt.ArrayLike, p: np.ndarray, target: npt.ArrayLike, u: npt.ArrayLike, v: npt.ArrayLike,
                  tol: float, max_iter: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Compiled Newton for :func:`piste.terrain.query.height_at` (see :func:`_height_newton_py`):
    returns ``(u, v, done, z)`` for the ``(m,)`` pairs.  Needs numba."""
    m = len(p)
    u = np.ascontiguousarray(u, dtype=np.float64).copy()
    v = np.ascontiguousarray(v, dtype=np.float64).copy()
    done = np.zeros(m, dtype=np.bool_)
    z = np.full(m, np.nan)
    _height_newton_nb(np.ascontiguousarray(cp, dtype=np.float64), np.ascontiguousarray(p, dtype=np.int64),
                      np.ascontiguousarray(target, dtype=np.float64), u, v, float(tol), int(max_iter), done, z)
    return u, v, done, z
