"""Terrain tessellation throughput: piste vs geomdl and the `bezier` package, side by side.

Tessellates a frame of the default course with the distance LOD of a camera on the track (a
realistic mix of 4x4 / 6x6 / 8x8 and glue patches, culled to the view), and measures M
triangles/s including glue patches and index output.  Then evaluates the same surface points
with geomdl (NURBS-Python, per patch) and with `bezier` (dhermes; tensor product through its
curve evaluator), on a sample of the patches, and prints points/s and the ratios.

Run: ``.venv/bin/python benchmarks/bench_terrain.py``
"""

from __future__ import annotations

import time

import numpy as np


def best_of(fn, repeat=20, min_time=0.5):
    best, total, n = np.inf, 0.0, 0
    while n < repeat or total < min_time:
        t0 = time.perf_counter()
        out = fn()
        dt = time.perf_counter() - t0
        best, total, n = min(best, dt), total + dt, n + 1
        if n > 1000:
            break
    return best, out


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


def main():
    from piste.terrain import edge_levels, evaluate, format_stats, stats, tessellate, visible_patches
    from piste.world.course import default_course, track_centerline

    t0 = time.perf_counter()
    net = default_course()
    print(f"default course: {len(net)} patches, built in {time.perf_counter() - t0:.2f} s")
    track = track_centerline()
    i = len(track) // 5
    eye = track[i] + [0.0, 0.0, 4.0]
    target = track[min(i + len(track) // 20, len(track) - 1)]
    levels = edge_levels(net, eye)
    vis = visible_patches(net, eye, target)

    print("\n== piste: one frame (LOD + cull as the renderer does) ==")
    t_frame, mesh = best_of(lambda: tessellate(net, levels, patches=vis))
    tris, verts = mesh.n_triangles, mesh.n_vertices
    print(f"visible patches {len(vis)}, triangles {tris:,}, vertices {verts:,}")
    print(f"tessellate (positions, normals, 3 UV sets, indices): {t_frame * 1e3:.2f} ms  "
          f"-> {tris / t_frame / 1e6:.1f} M triangles/s, {verts / t_frame / 1e6:.1f} M points/s")
    t_eval, _ = best_of(lambda: tessellate(net, levels, patches=vis, cache=False), repeat=10)
    print(f"same frame evaluated from scratch (cache=False, blend-table products every frame): "
          f"{t_eval * 1e3:.2f} ms -> {tris / t_eval / 1e6:.1f} M triangles/s")
    t_all, mesh_all = best_of(lambda: tessellate(net, levels), repeat=5)
    print(f"whole course at this LOD: {mesh_all.n_triangles:,} triangles in {t_all * 1e3:.2f} ms "
          f"-> {mesh_all.n_triangles / t_all / 1e6:.1f} M triangles/s")
    t8, m8 = best_of(lambda: tessellate(net, 8, patches=vis), repeat=5)
    print(f"all 8x8 (no LOD), visible: {m8.n_triangles:,} triangles in {t8 * 1e3:.2f} ms "
          f"-> {m8.n_triangles / t8 / 1e6:.1f} M triangles/s")
    print()
    print(format_stats(stats(net, eye, target)))

    print("\n== the same surface points: piste evaluate vs peers ==")
    n_u = 8
    t = np.linspace(0, 1, n_u)
    vv, uu = np.meshgrid(t, t, indexing="ij")
    uv = np.stack([uu.ravel(), vv.ravel()], 1)
    sample = net.control_points[vis[:40]]
    pts = len(sample) * n_u * n_u
    t_p, ref = best_of(lambda: evaluate(net.control_points[vis], uu.ravel(), vv.ravel(), normals=False), repeat=10)
    piste_pps = len(vis) * n_u * n_u / t_p
    t_g, g = best_of(lambda: geomdl_points(sample, uv), repeat=1, min_time=0)
    t_b, b = best_of(lambda: bezier_points(sample, t, t), repeat=1, min_time=0)
    ref_s = evaluate(sample, uu.ravel(), vv.ravel(), normals=False)
    b = b.transpose(0, 2, 1, 3).reshape(len(sample), -1, 3)
    print(f"max |piste - geomdl| = {np.abs(ref_s - g).max():.2e}, max |piste - bezier| = {np.abs(ref_s - b).max():.2e}")
    rows = [
        ("piste evaluate (blend-table GEMM, float64)", piste_pps),
        ("piste tessellate (vertices incl. normals, UVs, indices)", verts / t_frame),
        ("geomdl (per patch)", pts / t_g),
        ("bezier (dhermes, curve-based tensor product)", pts / t_b),
    ]
    for name, r in rows:
        print(f"  {name:58s} {r / 1e6:10.3f} M points/s")
    print(f"ratio piste tessellate / geomdl: {verts / t_frame / (pts / t_g):,.0f}x   "
          f"piste evaluate / geomdl: {piste_pps / (pts / t_g):,.0f}x")
    print(f"ratio piste tessellate / bezier: {verts / t_frame / (pts / t_b):,.0f}x   "
          f"piste evaluate / bezier: {piste_pps / (pts / t_b):,.0f}x")
    print(f"\ntargets: >= 100 M triangles/s (measured {tris / t_frame / 1e6:.1f}); "
          f">= 1,000x geomdl (measured {verts / t_frame / (pts / t_g):,.0f}x); PS2: 5.9 M polys/s")


if __name__ == "__main__":
    main()
