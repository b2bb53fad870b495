"""Terrain per-frame cost: the GPU-resident path's CPU side, the CPU tessellation path against this
machine's copy bandwidth, surface evaluation against geomdl and `bezier`, and scaling with the net.

1. One frame of the default course (a camera on the track, LOD + culling as the renderer does):
   the resident path's CPU side (hierarchical culling + per-side LOD + index list: no vertex is
   written), the CPU tessellation path (compiled with numba and numpy; for export and tests), the
   frame evaluated from scratch, and the old per-frame LOD + flat culling; all interleaved.  The
   tessellation's bytes written per second are printed as a fraction of a numpy copy of as many
   bytes (the machine's floor for moving that output).
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
from _timing import copy_bandwidth, fit_exponent, interleaved, ms, record, stat  # noqa: E402


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


def frame_section(rounds: int) -> None:
    from piste.terrain import _kernels, edge_levels, tessellate, visible_patches
    from piste.terrain.cull import patch_tree
    from piste.terrain.resident import resident_terrain
    from piste.transforms import frustum_planes, look_at, perspective
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
    tree = patch_tree(net)
    res.frame(eye, planes)  # compile / warm
    mesh = tessellate(net, levels, patches=vis)
    tris, nbytes = mesh.n_triangles, mesh_bytes(mesh)
    src = np.ones(nbytes // 4, np.float32)
    dst = np.empty_like(src)
    fns = {
        "resident CPU side (tree cull + LOD + index list)": lambda: res.frame(eye, planes),
        "old CPU side: LOD (all edges) + flat cull": lambda: (edge_levels(net, eye), visible_patches(net, eye, target)),
        "CPU tessellation, compiled (numba)": lambda: tessellate(net, levels, patches=vis),
        "CPU tessellation, numpy": lambda: tessellate(net, levels, patches=vis, use_numba=False),
        "evaluated every frame (cache=False)": lambda: tessellate(net, levels, patches=vis, cache=False),
        "numpy copy of the tessellation's bytes": lambda: np.copyto(dst, src),
    }
    if not _kernels.HAVE_NUMBA:
        fns.pop("CPU tessellation, compiled (numba)")
    t = interleaved(fns, rounds, warmup=3, inner=3)  # 3 calls a round: fewer one-off stalls in the median
    f = res.frame(eye, planes)
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
    old = stat(t["old CPU side: LOD (all edges) + flat cull"])[0]
    key = "CPU tessellation, compiled (numba)" if _kernels.HAVE_NUMBA else "CPU tessellation, numpy"
    tess = stat(t[key])[0]
    tess_np = stat(t["CPU tessellation, numpy"])[0]
    print(f"\nterrain CPU side per frame (resident): {rc * 1e3:.3f} ms (target <= 0.5 ms: "
          f"{'met' if rc <= 5e-4 else 'missed'}); the old LOD + cull alone took {old * 1e3:.3f} ms before "
          f"tessellating ({old / rc:.1f}x)")
    print(f"CPU tessellation path: {tris / tess / 1e6:.1f} M triangles/s (target >= 100: "
          f"{'met' if tris / tess >= 1e8 else 'missed'}), {copy_med / tess:.2f} of the numpy copy bandwidth for "
          f"its output bytes ({nbytes / copy_med / 1e9:.1f} GB/s); numpy path {tris / tess_np / 1e6:.1f} M triangles/s")
    record("terrain", "terrain CPU side / frame, default course", "<= 0.5 ms", f"{rc * 1e3:.3f} ms",
           f"old LOD+cull {old * 1e3:.3f} ms", f"{old / rc:.1f}x", rc <= 5e-4)
    record("terrain", "CPU tessellation (typical frame)", ">= 100 M tris/s", f"{tris / tess / 1e6:.1f} M/s",
           f"numpy path {tris / tess_np / 1e6:.1f} M/s", f"{tess_np / tess:.2f}x", tris / tess >= 1e8)
    record("terrain", "tessellation bytes/s vs numpy copy", "(fraction)", f"{nbytes / tess / 1e9:.2f} GB/s",
           f"copy {nbytes / copy_med / 1e9:.2f} GB/s", f"{copy_med / tess:.2f}")
    return net, vis


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


def scaling_section(sizes, rounds: int) -> None:
    from piste.terrain.cull import patch_tree
    from piste.terrain.resident import ResidentTerrain
    from piste.transforms import cull_boxes
    from piste.world.camera import Camera
    from piste.world.course import default_course

    print(f"\n== scaling with the net: CPU side per frame, median [range] over {rounds} interleaved rounds, "
          f"far plane {FAR:.0f} m ==")
    print(f"{'patches':>8s} {'visible':>8s} {'tris':>8s} | {'resident: tree cull + LOD + indices':>36s} | "
          f"{'old: flat cull + LOD (all)':>30s}")
    rows = []
    for n in sizes:
        net = default_course() if n == 2560 else grid_of(n)
        lo, hi = net.patch_bounds
        xmid = float((lo[:, 0].min() + hi[:, 0].max()) / 2)
        y0 = float(lo[:, 1].min())
        z = float(hi[:, 2].max())
        if n == 2560:
            from piste.world.course import track_centerline

            tr = track_centerline()
            i = len(tr) // 5
            cam = Camera(tr[i] + [0.0, 0.0, 4.0], tr[min(i + len(tr) // 20, len(tr) - 1)], aspect=640 / 448, far=FAR)
        else:
            cam = Camera([xmid, y0 - 20.0, z + 30.0], [xmid, y0 + 400.0, z - 20.0], aspect=640 / 448, far=FAR)
        planes = cam.frustum_planes()
        res = ResidentTerrain(net)
        tree = patch_tree(net)
        centre, half = ((lo + hi) / 2).T.copy(), ((hi - lo) / 2).T.copy()
        mids = net.edge_midpoints()

        def old():
            vis = np.nonzero(cull_boxes(centre, half, planes))[0]
            d = np.linalg.norm(mids - cam.eye, axis=1)
            return vis, np.where(d < 60, 8, np.where(d < 180, 6, 4))

        res.frame(cam.eye, planes)
        t = interleaved({"res": lambda: res.frame(cam.eye, planes), "old": old}, rounds, warmup=2)
        f = res.frame(cam.eye, planes)
        rows.append((n, len(f.patch_ids), f.n_triangles, stat(t["res"])[0], stat(t["old"])[0]))
        print(f"{len(net):8d} {len(f.patch_ids):8d} {f.n_triangles:8d} | {ms(t['res']):>36s} | {ms(t['old']):>30s}")
        del tree, res
    ns = [r[0] for r in rows]
    k_res = fit_exponent(ns, [r[3] for r in rows])
    k_old = fit_exponent(ns, [r[4] for r in rows])
    print(f"fitted exponent t ~ n^k: resident CPU side k = {k_res:.2f} (the visible set is capped by the far plane), "
          f"old flat cull + LOD k = {k_old:.2f}")
    big = rows[-1]
    print(f"largest net ({big[0]:,} patches): resident CPU side {big[3] * 1e3:.3f} ms (target <= 5 ms for 100k: "
          f"{'met' if big[3] <= 5e-3 else 'missed'}), old {big[4] * 1e3:.2f} ms")
    record("terrain", f"terrain CPU side, {big[0]:,}-patch net", "<= 5 ms (100k)", f"{big[3] * 1e3:.3f} ms",
           f"old flat {big[4] * 1e3:.2f} ms", f"{big[4] / big[3]:.0f}x", big[3] <= 5e-3)
    record("terrain", "scaling exponent of the CPU side (patches)", "< 1 (sub-linear)", f"n^{k_res:.2f}",
           f"old n^{k_old:.2f}", "", k_res < 1)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer rounds, nets up to 40k patches")
    ap.add_argument("--rounds", type=int, help="interleaved rounds per measurement (default 30, quick 10)")
    args = ap.parse_args(argv)
    rounds = args.rounds or (10 if args.quick else 30)
    from piste import _jit

    _jit.warm_up()  # compile / load the numba kernels before timing (else the first frames run numpy)
    net, vis = frame_section(rounds)
    peer_section(net, vis, 3 if args.quick else 7)
    scaling_section((2560, 10_000, 40_000) if args.quick else (2560, 10_000, 40_000, 160_000), rounds)
    return 0


if __name__ == "__main__":
    sys.exit(main())
