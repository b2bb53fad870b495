"""Terrain per-frame cost: the GPU-resident path's CPU side, the CPU tessellation path against this
machine's copy bandwidth, surface evaluation against geomdl and `bezier`, and scaling with the net.

1. One frame of the default course (a camera on the track, LOD + culling as the renderer does):
   the resident path's CPU side (hierarchical culling + per-side LOD + index list: no vertex is
   written), the CPU tessellation path (compiled with numba, the compiled path as it was before
   issue 15's rewrite (commit db55903) as the A/B baseline, and numpy; for export and tests), the
   frame evaluated from scratch, and the old per-frame LOD + flat culling; all interleaved.  The
   tessellation's bytes written per second are printed as a fraction of a numpy copy of as many
   bytes (the machine's floor for moving that output).  Then the CPU tessellation along the track
   (a new camera every frame), before/after and numpy, interleaved.
2. The same surface points evaluated by piste, geomdl (NURBS-Python) and `bezier` (dhermes), on
   the same patches, the same number of rounds, interleaved.
3. Scaling: the resident path's CPU side and the old flat culling + LOD on nets of 2,560 (the
   default course) to 160,000 patches (10 m patches; the camera's far plane at 1 km caps the visible set),
   with the fitted exponent ``t ~ n^k``.

Every figure is the median over interleaved rounds with its range [min-max].

Run: ``.venv/bin/python benchmarks/bench_terrain.py [--quick] [--rounds N]``
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

# one BLAS thread: on 2 shared cores OpenBLAS's spinning worker threads steal the CPU from whatever
# runs next (llvmpipe's threads, the next contender), which made every timing after a BLAS call noisy
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from _timing import fit_exponent, interleaved, ms, record, stat  # noqa: E402


def geomdl_points(cp: np.ndarray, uv: np.ndarray) -> np.ndarray:
    from geomdl import BSpline

    out = []
    for patch in cp:
        s = BSpline.Surface()
        s.degree_u = s.degree_v = 3
        s.ctrlpts_size_u = s.ctrlpts_size_v = 4
        s.ctrlpts = patch.reshape(16, 3).tolist()
        s.knotvector_u = s.knotvector_v = [0, 0, 0, 0, 1, 1, 1, 1]
        out.append(s.evaluate_list(uv.tolist()))
    return np.asarray(out)


def bezier_points(cp: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Tensor-product evaluation with bezier.Curve: the 4 u-curves at all u, then a v-curve per u."""
    import bezier

    nu = len(u)
    out = np.empty((len(cp), nu, len(v), 3))
    for k, patch in enumerate(cp):
        rows = np.stack([bezier.Curve(np.asfortranarray(patch[:, j].T), degree=3).evaluate_multi(u) for j in range(4)])
        for a in range(nu):
            out[k, a] = bezier.Curve(np.asfortranarray(rows[:, :, a].T), degree=3).evaluate_multi(v).T
    return out


def mesh_bytes(m) -> int:
    return sum(getattr(m, k).nbytes for k in ("positions", "normals", "uv", "uv_lightmap", "uv_projected", "param",
                                               "indices"))


# ------------------------------------------------------------------------------------------------
# The compiled CPU tessellation path as it was before issue 15 item 1's rewrite (commit db55903),
# kept here only as the A/B baseline: numpy front half (levels, argsort by shape key, per-patch
# offsets), per-frame np.array_equal of the net's UVs against the vertex cache's snapshot, and the
# old fused gather kernel (signed offsets, a per-vertex uniformity test).  Same outputs.
def _gather_cached_before(pids, shape_of, vertex_start, tri_start, src_start, src_level, src_slot, tri_src_start,
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
        if uniform:
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


class TessellateBefore:
    """``tessellate(net, levels, patches)`` (cached, compiled) as of commit db55903."""

    def __init__(self, net):
        import numba

        self.kernel = numba.njit(nogil=True, boundscheck=False)(_gather_cached_before)
        self.net = net
        self.snap = (net.uv.copy(), net.lightmap_rect.copy())
        self.tables = {}

    def _shape_tables(self, levels: tuple):
        from piste.terrain.tessellate import _glue_sources, get_shape

        if levels not in self.tables:
            shapes = [get_shape(lv) for lv in levels]
            src = [_glue_sources(lv) for lv in levels]
            nv = np.array([len(x[0]) for x in src], dtype=np.int64)
            src_start = np.concatenate([[0], np.cumsum(nv)[:-1]]).astype(np.int64)
            src_level = np.concatenate([x[0] for x in src]).astype(np.int64)
            src_slot = np.concatenate([x[1] for x in src]).astype(np.int64)
            nt = np.array([len(sh.tris) for sh in shapes], dtype=np.int64)
            tri_src_start = np.concatenate([[0], np.cumsum(nt)[:-1]]).astype(np.int64)
            tris = np.concatenate([sh.tris for sh in shapes]).astype(np.uint32)
            used = sorted({n for lv in levels for n in lv})
            self.tables[levels] = (src_start, src_level, src_slot, tri_src_start, tris, used)
        return self.tables[levels]

    def __call__(self, levels, patches):
        from piste.terrain.tessellate import (MAX_LEVEL, VERTEX_FLOATS, TerrainMesh, _as_levels, _cache,
                                              get_shape)

        net = self.net
        lv = _as_levels(net, levels)
        pids = np.asarray(patches, dtype=np.int64).ravel()
        if len(pids) and (pids.min() < 0 or pids.max() >= len(net)):
            raise ValueError("patch ids")
        side_lv = lv[net.side_edge[pids]].astype(np.int64)
        m = side_lv.max(axis=1)
        glue = (side_lv != m[:, None]).any(axis=1)
        key = ((((glue * 65 + m) * 65 + side_lv[:, 0]) * 65 + side_lv[:, 1]) * 65 + side_lv[:, 2]) * 65 + side_lv[:, 3]
        order = np.argsort(key, kind="stable")
        pids, side_lv, m, key, glue = pids[order], side_lv[order], m[order], key[order], glue[order]
        new = np.empty(len(key), dtype=bool)
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
        V, T = int(vertex_start[-1]), int(tri_start[-1])
        indices = np.empty((T, 3), dtype=np.uint32)
        tables = self._shape_tables(tuple(sh.levels for sh in shapes))
        if not (np.array_equal(self.snap[0], net.uv) and np.array_equal(self.snap[1], net.lightmap_rect)):
            raise RuntimeError("UVs changed")  # (the old vertex cache's per-frame check, same cost)
        c = _cache(net)
        if c.grid_flat is None or any(n not in c.grid_levels for n in tables[-1]):
            c.grids(net, tables[-1])
        flat, offset = c.grid_flat, c.grid_offset  # (the check above was the old grids()'s; not the new one too)
        level_row = np.zeros(MAX_LEVEL + 1, np.int64)
        for n, o in offset.items():
            level_row[n] = o // VERTEX_FLOATS
        vert = np.empty((V, VERTEX_FLOATS), dtype=np.float32)
        self.kernel(pids, shape_of, vertex_start, tri_start, *tables[:-1], level_row, flat.reshape(-1, VERTEX_FLOATS),
                    vert, indices)
        vpatch = np.repeat(np.arange(len(pids), dtype=np.int32), nv_p)
        return TerrainMesh(positions=vert[:, 0:3], normals=vert[:, 3:6], uv=vert[:, 8:10], uv_lightmap=vert[:, 10:12],
                           uv_projected=vert[:, 12:14], param=vert[:, 6:8], indices=indices, patch_ids=pids,
                           patch_kind=np.where(glue, 0, m).astype(np.int8), patch_levels=side_lv.astype(np.int16),
                           vertex_patch=vpatch, vertex_start=vertex_start, tri_start=tri_start)


def frame_section(rounds: int) -> None:
    from piste.terrain import _kernels, edge_levels, tessellate, visible_patches
    from piste.terrain.resident import resident_terrain
    from piste.transforms import cull_boxes, frustum_planes, look_at, perspective
    from piste.world.course import default_course, track_centerline

    t0 = time.perf_counter()
    net = default_course()
    print(f"default course: {len(net)} patches, built in {time.perf_counter() - t0:.2f} s; numba "
          f"{'on' if _kernels.HAVE_NUMBA else 'not installed (numpy paths)'}")
    track = track_centerline()
    i = len(track) // 5
    eye = track[i] + [0.0, 0.0, 4.0]
    target = track[min(i + len(track) // 20, len(track) - 1)]
    planes = frustum_planes(perspective(60.0, 640 / 448, 0.5, 5000.0) @ look_at(eye, target, (0.0, 0.0, 1.0)))
    levels = edge_levels(net, eye)
    vis = visible_patches(net, eye, target)
    res = resident_terrain(net)
    res.frame(eye, planes)  # compile / warm
    # the best previous CPU side: flat box cull + LOD of every edge, with the boxes and edge midpoints
    # (which never change) cached as the old renderer kept them, not recomputed every frame
    lo, hi = net.patch_bounds
    centre, half, mids = ((lo + hi) / 2).T.copy(), ((hi - lo) / 2).T.copy(), net.edge_midpoints()

    def old_cpu_side():
        vis_ = np.nonzero(cull_boxes(centre, half, planes))[0]
        d = np.linalg.norm(mids - eye, axis=1)
        lv = np.where(d < 60, 8, np.where(d < 180, 6, 4)).astype(np.int16)
        lv[net.edge_degenerate] = 4
        return vis_, lv
    mesh = tessellate(net, levels, patches=vis)
    tris, nbytes = mesh.n_triangles, mesh_bytes(mesh)
    src = np.ones(nbytes // 4, np.float32)
    dst = np.empty_like(src)
    before = TessellateBefore(net) if _kernels.HAVE_NUMBA else None
    if before is not None:
        same = before(levels, vis)
        for k in ("positions", "normals", "uv", "uv_lightmap", "uv_projected", "param", "indices", "patch_ids",
                  "patch_kind", "patch_levels", "vertex_patch", "vertex_start", "tri_start"):
            assert getattr(same, k).tobytes() == getattr(mesh, k).tobytes(), k  # the A/B compare like with like
    fns = {
        "resident CPU side (tree cull + LOD + index list)": lambda: res.frame(eye, planes),
        "resident CPU side, distance levels only (the old's work)": lambda: res.frame(eye, planes, flat_error=None),
        "old CPU side: flat cull + LOD (all edges), cached": old_cpu_side,
        "CPU tessellation, compiled (numba)": lambda: tessellate(net, levels, patches=vis),
        "CPU tessellation, compiled, before (db55903)": lambda: before(levels, vis),
        "CPU tessellation, numpy": lambda: tessellate(net, levels, patches=vis, use_numba=False),
        "evaluated every frame (cache=False)": lambda: tessellate(net, levels, patches=vis, cache=False),
        "numpy copy of the tessellation's bytes": lambda: np.copyto(dst, src),
    }
    if not _kernels.HAVE_NUMBA:
        fns.pop("CPU tessellation, compiled (numba)")
        fns.pop("CPU tessellation, compiled, before (db55903)")
    t = interleaved(fns, rounds, warmup=3, inner=3)  # 3 calls a round: fewer one-off stalls in the median
    # like with like: the old CPU side picks levels by distance alone, as the resident path does without the
    # error-driven flat/coarse levels (lod flat_error=None); the renderer's default adds them (timed above too)
    f = res.frame(eye, planes, flat_error=None)
    ov, olv = old_cpu_side()
    assert np.array_equal(ov, f.patch_ids), "the old and resident CPU sides cull differently"
    assert np.array_equal(olv[net.side_edge[ov]], f.patch_levels), "the old and resident CPU sides pick other levels"
    print(f"\n== one frame: {len(vis)} visible patches, {tris:,} triangles, {mesh.n_vertices:,} vertices, "
          f"{nbytes / 1e6:.2f} MB of CPU-tessellated output; resident index list {f.indices.nbytes / 1e3:.0f} kB ==")
    print(f"{'':52s} {'median [range]':>26s} {'M tris/s':>9s} {'GB/s out':>9s} {'of copy':>8s}")
    copy_med = stat(t["numpy copy of the tessellation's bytes"])[0]
    for name, ts in t.items():
        med = stat(ts)[0]
        rate = tris / med / 1e6
        bw = nbytes / med / 1e9
        frac = copy_med / med
        tail = f"{rate:9.1f} {bw:9.2f} {frac:8.2f}" if "tessellation" in name or "evaluated" in name else \
            (f"{'':9s} {bw:9.2f} {1.0:8.2f}" if "copy" in name else "")
        print(f"{name:52s} {ms(ts):>26s} {tail}")
    rc = stat(t["resident CPU side (tree cull + LOD + index list)"])[0]
    rc_same = stat(t["resident CPU side, distance levels only (the old's work)"])[0]
    old = stat(t["old CPU side: flat cull + LOD (all edges), cached"])[0]
    key = "CPU tessellation, compiled (numba)" if _kernels.HAVE_NUMBA else "CPU tessellation, numpy"
    tess = stat(t[key])[0]
    tess_np = stat(t["CPU tessellation, numpy"])[0]
    print(f"\nterrain CPU side per frame (resident): {rc * 1e3:.3f} ms (target <= 0.5 ms: "
          f"{'met' if rc <= 5e-4 else 'missed'}; with the error-driven flat/coarse levels, the renderer's default); "
          f"the same work as the old (distance levels only, outputs checked equal) {rc_same * 1e3:.3f} ms, the old "
          f"LOD + cull alone {old * 1e3:.3f} ms before tessellating ({old / rc_same:.1f}x)")
    rates = tris / t[key]
    print(f"CPU tessellation path: {tris / tess / 1e6:.1f} M triangles/s [{rates.min() / 1e6:.1f}-"
          f"{rates.max() / 1e6:.1f}] (target >= 100: {'met' if tris / tess >= 1e8 else 'missed'}), "
          f"{copy_med / tess:.2f} of the numpy copy bandwidth for its output bytes "
          f"({nbytes / copy_med / 1e9:.1f} GB/s); "
          f"numpy path {tris / tess_np / 1e6:.1f} M triangles/s")
    if before is not None:
        b = t["CPU tessellation, compiled, before (db55903)"]
        ratio = b / t[key]  # per round: the A/B pairs ran back to back
        print(f"compiled path before/after (interleaved, same rounds): {tris / stat(b)[0] / 1e6:.1f} -> "
              f"{tris / tess / 1e6:.1f} M triangles/s, {np.median(ratio):.2f}x faster "
              f"[{ratio.min():.2f}-{ratio.max():.2f} over the rounds]")
        record("terrain", "CPU tessellation, compiled: before (db55903) -> after", "(speed-up)",
               f"{tris / tess / 1e6:.1f} M/s", f"before {tris / stat(b)[0] / 1e6:.1f} M/s", f"{np.median(ratio):.2f}x")
    record("terrain", "terrain CPU side / frame, default course (the renderer's default: error-driven flat levels)",
           "<= 0.5 ms", f"{rc * 1e3:.3f} ms", "", "", rc <= 5e-4)
    record("terrain", "terrain CPU side / frame, distance levels only vs the old LOD + cull (same outputs)", "faster",
           f"{rc_same * 1e3:.3f} ms", f"old LOD+cull {old * 1e3:.3f} ms", f"{old / rc_same:.1f}x")
    record("terrain", "CPU tessellation (typical frame)", ">= 100 M tris/s", f"{tris / tess / 1e6:.1f} M/s",
           f"numpy path {tris / tess_np / 1e6:.1f} M/s", f"{tess_np / tess:.2f}x", tris / tess >= 1e8)
    record("terrain", "tessellation bytes/s vs numpy copy", "(fraction)", f"{nbytes / tess / 1e9:.2f} GB/s",
           f"copy {nbytes / copy_med / 1e9:.2f} GB/s", f"{copy_med / tess:.2f}")
    if before is not None:
        moving_camera(net, track, before, rounds)
    return net, vis


def moving_camera(net, track, before, rounds: int) -> None:
    """The CPU tessellation path along the track: a new camera (LOD + visible set) every frame, so
    the mix of patch shapes changes; the before path's tables per mix of shapes are emptied each
    round (a first pass along the track meets a new mix in about half the frames; the new path
    registers each shape once per process and has no such cache)."""
    from piste.terrain import edge_levels, tessellate, visible_patches

    frames = []
    for i in range(0, len(track) - 30, max(1, len(track) // 60)):
        eye = track[i] + [0.0, 0.0, 4.0]
        vis = visible_patches(net, eye, track[i + 20])
        if len(vis):
            frames.append((edge_levels(net, eye), vis))
    tris = sum(tessellate(net, lv, patches=v).n_triangles for lv, v in frames)

    def after():
        for lv, v in frames:
            tessellate(net, lv, patches=v)

    def old():
        before.tables.clear()
        for lv, v in frames:
            before(lv, v)

    def numpy_path():
        for lv, v in frames:
            tessellate(net, lv, patches=v, use_numba=False)

    t = interleaved({"compiled": after, "compiled, before (db55903)": old, "numpy": numpy_path}, rounds, warmup=1)
    print(f"\n== moving camera: {len(frames)} frames along the track, {tris:,} triangles in all, the before path's "
          f"shape-table cache emptied each round; median [range] over {rounds} interleaved rounds ==")
    for name, ts in t.items():
        print(f"  CPU tessellation, {name:28s} {ms(ts):>30s} per {len(frames)} frames  "
              f"{tris / stat(ts)[0] / 1e6:7.1f} M triangles/s")
    ratio = t["compiled, before (db55903)"] / t["compiled"]
    print(f"  compiled before/after: {np.median(ratio):.2f}x faster "
          f"[{ratio.min():.2f}-{ratio.max():.2f} over the rounds]")
    record("terrain", "CPU tessellation, moving camera", ">= 100 M tris/s",
           f"{tris / stat(t['compiled'])[0] / 1e6:.1f} M/s",
           f"before {tris / stat(t['compiled, before (db55903)'])[0] / 1e6:.1f} M/s", f"{np.median(ratio):.2f}x",
           tris / stat(t["compiled"])[0] >= 1e8)


def peer_section(net, vis, rounds: int) -> None:
    from piste.terrain import evaluate

    n_u = 8
    tt = np.linspace(0, 1, n_u)
    vv, uu = np.meshgrid(tt, tt, indexing="ij")
    uv = np.stack([uu.ravel(), vv.ravel()], 1)
    sample = net.control_points[vis[:40]]
    pts = len(sample) * n_u * n_u
    fns = {"piste evaluate (blend tables, float64)": lambda: evaluate(sample, uu.ravel(), vv.ravel(), normals=False)}
    peers = {}
    try:
        import geomdl  # noqa: F401

        fns["geomdl (NURBS-Python, per patch)"] = lambda: geomdl_points(sample, uv)
        peers["geomdl"] = "geomdl (NURBS-Python, per patch)"
    except ImportError:
        print("geomdl not installed (pip install 'piste[bench]'): skipped")
    try:
        import bezier  # noqa: F401

        fns["bezier (dhermes, curve tensor product)"] = lambda: bezier_points(sample, tt, tt)
        peers["bezier"] = "bezier (dhermes, curve tensor product)"
    except ImportError:
        print("bezier not installed (pip install 'piste[bench]'): skipped")
    ref = evaluate(sample, uu.ravel(), vv.ravel(), normals=False)
    if "geomdl" in peers:
        print(f"max |piste - geomdl| = {np.abs(ref - geomdl_points(sample, uv)).max():.2e}", end="; ")
    if "bezier" in peers:
        b = bezier_points(sample, tt, tt).transpose(0, 2, 1, 3).reshape(len(sample), -1, 3)
        print(f"max |piste - bezier| = {np.abs(ref - b).max():.2e}")
    t = interleaved(fns, rounds, warmup=1)
    print(f"\n== the same {pts:,} surface points ({len(sample)} patches x {n_u}x{n_u}), {rounds} interleaved rounds ==")
    base = stat(t["piste evaluate (blend tables, float64)"])[0]
    for name, ts in t.items():
        med, lo, hi = stat(ts)
        print(f"  {name:42s} {ms(ts):>30s}  {pts / med / 1e6:9.3f} M points/s  "
              f"piste {med / base:8.0f}x faster [{lo / base:.0f}-{hi / base:.0f}]" if name not in
              ("piste evaluate (blend tables, float64)",) else
              f"  {name:42s} {ms(ts):>30s}  {pts / med / 1e6:9.3f} M points/s")
    for peer, name in peers.items():
        med = stat(t[name])[0]
        goal = ">= 1000x" if peer == "geomdl" else "(peer)"
        record("terrain", f"surface points vs {peer}", goal, f"{pts / base / 1e6:.2f} M pts/s",
               f"{pts / med / 1e6:.4f} M pts/s", f"{med / base:.0f}x", med / base >= 1000 if peer == "geomdl" else None)


def grid_of(n_patches: int, size: float = 10.0):
    from piste.terrain import PatchNet

    side = int(round(np.sqrt(n_patches)))
    y, x = np.mgrid[0:3 * side + 1, 0:3 * side + 1] * (size / 3)
    z = 12.0 * np.sin(x / 90.0) + 9.0 * np.cos(y / 130.0) + 0.02 * y
    return PatchNet.from_control_grid(np.stack([x, y, z], -1))


#: the scaling cameras' far plane (metres): it caps the visible set as the net grows
FAR = 1000.0


def renderer_cpu_side(net, resident: bool = True):
    """A :class:`piste.render.frame.TerrainRenderer` of ``net`` whose :meth:`prepare` (the renderer's
    CPU side: whichever path it takes, resident index lists or CPU tessellation) is timed.  prepare
    touches no GL object, so the renderer is made without its GL resources (no context, target,
    textures: a 160k-patch light-map atlas would only cost set-up here); every attribute prepare
    reads is the constructor's."""
    from piste.render.frame import TerrainRenderer
    from piste.terrain.resident import morph_setting

    r = object.__new__(TerrainRenderer)
    r.net = net
    r.lod_morph = morph_setting(None)
    r.resident = bool(resident)
    r.resident_wait = True
    r.lod_kwargs = {}
    r.visibility = None
    r.cull_stats = {}
    return r


def _scaling_row(n: int, rounds: int) -> tuple:
    """One net of ``n`` patches: ``(patches, visible, path, first frame s, after s, before s, flat s)``."""
    from piste.terrain.resident import ResidentMesh
    from piste.transforms import cull_boxes
    from piste.world.camera import Camera
    from piste.world.course import default_course, track_centerline

    net = default_course() if n == 2560 else grid_of(n)
    lo, hi = net.patch_bounds
    if n == 2560:
        tr = track_centerline()
        i = len(tr) // 5
        cam = Camera(tr[i] + [0.0, 0.0, 4.0], tr[min(i + len(tr) // 20, len(tr) - 1)], aspect=640 / 448, far=FAR)
    else:
        xmid = float((lo[:, 0].min() + hi[:, 0].max()) / 2)
        y0, z = float(lo[:, 1].min()), float(hi[:, 2].max())
        cam = Camera([xmid, y0 - 20.0, z + 30.0], [xmid, y0 + 400.0, z - 20.0], aspect=640 / 448, far=FAR)
    planes = cam.frustum_planes()
    after, before = renderer_cpu_side(net), renderer_cpu_side(net, resident=False)
    t0 = time.perf_counter()
    m_after = after.prepare(cam)  # the first frame waits for the resident blocks (built once)
    first = time.perf_counter() - t0
    m_before = before.prepare(cam)  # (its vertex cache, when it fits, built here)
    path = "resident" if isinstance(m_after, ResidentMesh) else "CPU"
    # the same output on the timed paths: the same patches drawn, each side at the same level (the CPU
    # path lists its patches grouped by shape, the resident one by id)
    oa, ob = np.argsort(m_after.patch_ids, kind="stable"), np.argsort(m_before.patch_ids, kind="stable")
    assert np.array_equal(m_after.patch_ids[oa], m_before.patch_ids[ob]), "the two paths draw other patches"
    assert np.array_equal(m_after.patch_levels[oa], m_before.patch_levels[ob]), "the two paths pick other levels"
    centre, half = ((lo + hi) / 2).T.copy(), ((hi - lo) / 2).T.copy()
    mids = net.edge_midpoints()

    def flat():
        vis = np.nonzero(cull_boxes(centre, half, planes))[0]
        d = np.linalg.norm(mids - cam.eye, axis=1)
        return vis, np.where(d < 60, 8, np.where(d < 180, 6, 4))

    # the same renderer without the flat level below the coarsest (the resident path as it was before it)
    three = renderer_cpu_side(net)
    three.lod_kwargs = {"flat_error": None}
    t = interleaved({"after": lambda: after.prepare(cam), "before": lambda: before.prepare(cam), "flat": flat,
                     "three": lambda: three.prepare(cam)}, rounds, warmup=2)
    print(f"{len(net):8d} {len(m_after.patch_ids):8d} {path:>9s} {first:10.2f}s | {ms(t['after']):>26s} | "
          f"{ms(t['before']):>26s} | {ms(t['flat']):>26s} | {ms(t['three']):>26s}")
    return (len(net), len(m_after.patch_ids), path, first, stat(t["after"])[0], stat(t["before"])[0],
            stat(t["flat"])[0], stat(t["three"])[0])


def scaling_section(sizes, rounds: int) -> None:
    from piste.terrain.resident import RESIDENT_BUDGET

    print(f"\n== scaling with the net: the renderer's CPU side per frame (TerrainRenderer.prepare: cull + LOD + index "
          f"list or tessellation), median [range] over {rounds} interleaved rounds, order rotated; camera 640x448, "
          f"60 deg, far plane {FAR:.0f} m; resident budget {RESIDENT_BUDGET / 2**20:.0f} MiB ==")
    print("  after: the renderer as it is (resident blocks up to the budget); before: the same renderer with "
          "resident=False, the CPU path it took above ~46k patches before (vertex cache under 512 MB, else "
          "evaluated); flat: flat box cull + LOD of every edge with the boxes and midpoints cached (no index list); "
          "3 levels: the renderer as it is without the flat level below the coarsest (lod flat_error=None)")
    print(f"{'patches':>8s} {'visible':>8s} {'path':>9s} {'first frame':>11s} | {'after':>26s} | {'before':>26s} | "
          f"{'flat cull + LOD (cached)':>26s} | {'3 levels (no flat edges)':>26s}")
    rows = [_scaling_row(n, rounds) for n in sizes]
    ns = [r[0] for r in rows]
    k_after = fit_exponent(ns, [r[4] for r in rows])
    k_before = fit_exponent(ns, [r[5] for r in rows])
    print(f"fitted exponent t ~ n^k over {', '.join(f'{n:,}' for n in ns)} patches: the renderer's CPU side k = "
          f"{k_after:.2f} (before: {k_before:.2f}); the far plane caps the visible set")
    big = rows[-1]
    print(f"largest net ({big[0]:,} patches, {big[2]} path): the renderer's CPU side {big[4] * 1e3:.3f} ms "
          f"(target <= 2 ms at 160k: {'met' if big[4] <= 2e-3 else 'missed'}), before {big[5] * 1e3:.2f} ms, "
          f"without the flat level {big[7] * 1e3:.3f} ms; "
          f"the first frame {big[3]:.1f} s (builds the resident blocks once; the renderer starts that in the background)")
    for r in rows:
        record("terrain", f"renderer CPU side, {r[0]:,} patches ({r[2]}, far {FAR:.0f} m)",
               "<= 2 ms (160k)" if r is big else "", f"{r[4] * 1e3:.3f} ms", f"before {r[5] * 1e3:.2f} ms",
               f"{r[5] / r[4]:.0f}x", (r[4] <= 2e-3) if r is big else None)
    record("terrain", "scaling exponent of the renderer's CPU side (patches)", "< 1 (sub-linear)", f"n^{k_after:.2f}",
           f"before n^{k_before:.2f}", "", k_after < 1)
    record("terrain", f"first frame at {big[0]:,} patches (resident blocks built once)", "", f"{big[3]:.1f} s", "", "")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    ap.add_argument("--quick", action="store_true", help="fewer rounds (the same nets: 2.5k, 64k, 160k patches)")
    ap.add_argument("--rounds", type=int, help="interleaved rounds per measurement (default 30, quick 10)")
    ap.add_argument("--sections", nargs="+", choices=("frame", "peers", "scaling"), default=("frame", "peers", "scaling"),
                    help="which parts to run (default: all)")
    args = ap.parse_args(argv)
    rounds = args.rounds or (10 if args.quick else 30)
    from piste import _jit

    _jit.warm_up()  # compile / load the numba kernels before timing (else the first frames run numpy)
    if "frame" in args.sections or "peers" in args.sections:
        net, vis = frame_section(rounds) if "frame" in args.sections else (None, None)
        if "peers" in args.sections:
            if net is None:
                from piste.terrain import visible_patches
                from piste.world.course import default_course, track_centerline

                net, tr = default_course(), track_centerline()
                i = len(tr) // 5
                vis = visible_patches(net, tr[i] + [0.0, 0.0, 4.0], tr[min(i + len(tr) // 20, len(tr) - 1)])
            peer_section(net, vis, 3 if args.quick else 7)
    if "scaling" in args.sections:
        scaling_section((2560, 64_000, 160_000), rounds)
    return 0


if __name__ == "__main__":
    sys.exit(main())
