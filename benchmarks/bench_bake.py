"""Light-map bake of the default course (2,560 patches) with terrain shadows, at 8x8 and 16x16.

Prints, per resolution and worker count: wall time, samples/s, shadow rays and rays/s; the same
bake without shadows; a per-patch Python loop over the same equation (the naive peer) on a subset,
with the ratio; the accuracy of the baked maps against the lighting equation evaluated per pixel
(64 x 64 points per patch on 60 patches, with shadows); and the PS2 blend's error over the scene
(snow base texture x baked light map).  Target: 8x8 with shadows under 10 s on 2 cores.

Then the shadow rays side by side with a real ray tracer, Intel Embree (through ``embreex``, from the
``bench`` extra): the bake's own rays (origins lifted off the exact surface, unit directions to each
light, ``t_max``), piste's :func:`~piste.terrain.query.ray_intersect` (any hit, as the baker calls
it) against Embree's ``rtcOccluded`` on the same terrain tessellated into triangles by piste's
tessellator (level 8, the talk's finest; ``--full`` also 16 and 32), timed alike (interleaved
rounds, medians with [min-max]), with the agreement: hit/miss per ray and, for rays both call hit,
the nearest-hit distances against the tessellation's chord error.  Embree's extra hits are mostly
self-hits (a shadow ray's origin, lifted 1e-5 of the course's diagonal off the exact surface, can lie
under the triangles where the surface is concave; at level 8 the 8x8 samples are mesh vertices).  Embree traces a tessellated
approximation, piste the exact patches: they differ where a ray passes within the chord error of
the surface (grazing rays, rays starting below the triangles).
Plain script, not a test.  ``--quick``: 8x8 only, Embree at level 8 only, 3 rounds.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from piste.lighting import bake_lightmap, default_lights, encode_half_bright, ps2_error_report, sample_points, shade
from piste.lighting.lights import light_terms
from piste.lighting.shadows import ray_offset, shadow_rays, shadow_visibility
from piste.world.course import default_course

sys.path.insert(0, str(Path(__file__).parent))
from _timing import interleaved, ms, record, stat  # noqa: E402


def timed(fn, *a, **k):
    t = time.perf_counter()
    out = fn(*a, **k)
    return out, time.perf_counter() - t


def naive_bake(net, lights, res, patches):
    """The peer: one patch at a time (Python loop over patches), same equation and rays."""
    from piste.terrain.bezier import evaluate, grid_params

    u, v = grid_params(res)
    out = []
    for p in patches:
        pos, nrm = evaluate(net.control_points[p : p + 1], u, v)
        pos, nrm = pos[0], nrm[0]
        vis = shadow_visibility(net, lights, pos, nrm, light_terms(lights, pos, nrm))
        out.append(shade(lights, pos, nrm, vis))
    return out


def bake_rays(net, lights, res):
    """The bake's shadow rays at ``res`` x ``res`` texels a patch, built as the baker builds them
    (:func:`~piste.lighting.shadows.shadow_visibility`): origins ``(k, 3)``, unit directions ``(k, 3)``,
    ``t_max (k,)`` float64 (inf towards the sun)."""
    pos, nrm = sample_points(net, res)
    pos, nrm = pos.reshape(-1, 3), nrm.reshape(-1, 3)
    terms = light_terms(lights, pos, nrm)
    eps = ray_offset(net)
    o, d, t = [], [], []
    for col, light in enumerate(lights.direct):
        if not light.shadows or light.intensity == 0.0:
            continue
        idx = np.nonzero(terms[:, col] > 0.0)[0]
        oo, dd, tt = shadow_rays(light, pos[idx], nrm[idx], eps)
        o.append(oo), d.append(dd), t.append(tt)
    return np.concatenate(o), np.concatenate(d), np.concatenate(t)


def chord_error(net, mesh, sample: int = 200_000, seed: int = 0) -> tuple[float, float]:
    """Distance between the exact surface and the triangles of ``mesh`` (a
    :class:`~piste.terrain.tessellate.TerrainMesh`): at the centroid and edge midpoints (in patch
    parameters) of up to ``sample`` random triangles, the exact point against the triangle's linear
    interpolation.  ``(max, p99)`` in model units (an estimate of the tessellation's error)."""
    from piste.terrain.query import eval_points

    tri = mesh.indices
    if len(tri) > sample:
        tri = tri[np.random.default_rng(seed).choice(len(tri), sample, replace=False)]
    tri = tri.astype(np.int64)
    patch = mesh.patch_ids[mesh.vertex_patch[tri[:, 0]]]
    prm = mesh.param[tri].astype(np.float64)  # (t, 3, 2)
    pos = mesh.positions[tri].astype(np.float64)  # (t, 3, 3)
    w = np.array([[1, 1, 1], [1, 1, 0], [0, 1, 1], [1, 0, 1]], dtype=np.float64)
    w /= w.sum(1, keepdims=True)  # centroid and the three edge midpoints
    err = []
    for wk in w:
        uv = np.einsum("k,tkc->tc", wk, prm)
        exact = eval_points(net.control_points[patch], uv[:, 0], uv[:, 1], derivatives=False)
        err.append(np.linalg.norm(exact - np.einsum("k,tkc->tc", wk, pos), axis=1))
    err = np.max(err, axis=0)
    return float(err.max()), float(np.percentile(err, 99))


def embree_peer(net, lights, res: int, levels, rounds: int) -> None:
    """Shadow rays of the bake: piste's exact any-hit query vs Embree on the tessellated terrain."""
    print("\n== shadow rays: piste (exact patches) vs Embree via embreex (tessellated triangles) ==")
    try:
        import embreex
        from embreex.mesh_construction import TriangleMesh
        from embreex.rtcore_scene import EmbreeScene
    except ImportError as exc:
        print(f"Embree peer skipped: embreex is not installed ({exc}); pip install 'piste[bench]'")
        record("bake", "shadow rays vs Embree", "comparable", "", "skipped: embreex not installed", "")
        return
    from piste.terrain.query import PatchBVH, clear_cache, ray_intersect
    from piste.terrain.tessellate import tessellate

    o, d, tmax = bake_rays(net, lights, res)
    k = len(o)
    o32, d32 = o.astype(np.float32), d.astype(np.float32)
    tf32 = np.minimum(tmax, 1e37).astype(np.float32)  # embreex's "no limit" is 1e37
    print(f"{k:,} shadow rays of the {res}x{res} bake ({np.isinf(tmax).sum():,} to the sun, the rest to point "
          f"and spot lights); embreex {getattr(embreex, '__version__', '?')}; piste numpy, one process; "
          f"load {os.getloadavg()[0]:.2f}")

    # build: piste's BVH over exact sub-patches vs piste's tessellation + Embree's BVH
    def build_piste():
        clear_cache(net)
        return PatchBVH(net)

    piste_hits = ray_intersect(net, o, d, t_max=tmax, any_hit=True)  # warms numpy and the cache
    scenes = {}
    for lv in levels:
        t0 = time.perf_counter()
        mesh = tessellate(net, lv, cache=False)
        t1 = time.perf_counter()
        scene = EmbreeScene()
        TriangleMesh(scene, np.ascontiguousarray(mesh.positions, dtype=np.float32),
                     np.ascontiguousarray(mesh.indices, dtype=np.int32))
        scene.run(o32[:1], d32[:1], dists=tf32[:1].copy(), query="OCCLUDED")  # commits (builds the BVH)
        t2 = time.perf_counter()
        scenes[lv] = (scene, mesh, t1 - t0, t2 - t1)
    lv0 = levels[0]

    def build_embree():
        sc = EmbreeScene()
        m = tessellate(net, lv0, cache=False)
        TriangleMesh(sc, np.ascontiguousarray(m.positions, dtype=np.float32), np.ascontiguousarray(m.indices, dtype=np.int32))
        sc.run(o32[:1], d32[:1], dists=tf32[:1].copy(), query="OCCLUDED")

    tb = interleaved({"piste": build_piste, "embree": build_embree}, max(rounds, 3), warmup=0)
    print(f"build ({len(tb['piste'])} interleaved rounds): piste PatchBVH {ms(tb['piste'])}; level {lv0} tessellation + "
          f"Embree BVH {ms(tb['embree'])}" + "".join(
              f"; level {lv}: {len(m.indices):,} triangles, tessellate {a * 1e3:.0f} ms + Embree BVH {b * 1e3:.0f} ms (once)"
              for lv, (_, m, a, b) in scenes.items()))
    _ = ray_intersect(net, o[:10], d[:10], t_max=tmax[:10], any_hit=True)  # rebuild the cached BVH

    out = {}

    def run_piste():
        out["piste"] = ray_intersect(net, o, d, t_max=tmax, any_hit=True).hit

    fns = {"piste": run_piste}
    for lv, (scene, _, _, _) in scenes.items():
        def run_embree(scene=scene, lv=lv):
            out[lv] = scene.run(o32, d32, dists=tf32.copy(), query="OCCLUDED") >= 0
        fns[f"embree {lv}"] = run_embree
    t = interleaved(fns, rounds, warmup=1)
    pm = stat(t["piste"])[0]
    c0, w0 = time.process_time(), time.perf_counter()
    fns[f"embree {levels[0]}"]()
    c1, w1 = time.process_time(), time.perf_counter()
    print(f"Embree: CPU time / wall time of one run {(c1 - c0) / (w1 - w0):.2f} (1.0 = one busy core; below it, waiting for the CPU)")
    print(f"timing ({rounds} interleaved rounds, median [min-max]; load {os.getloadavg()[0]:.2f}):")
    print(f"  {'contender':28s} {'time / all rays':>28s} {'rays/s':>12s} {'Embree faster':>13s}")
    print(f"  {'piste ray_intersect (exact)':28s} {ms(t['piste']):>28s} {k / pm:12,.0f}")
    for lv in scenes:
        em = stat(t[f"embree {lv}"])[0]
        print(f"  {f'Embree occluded, level {lv}':28s} {ms(t[f'embree {lv}']):>28s} {k / em:12,.0f} "
              f"{pm / em:12.0f}x")
    assert np.array_equal(out["piste"], piste_hits.hit)

    # agreement: hit/miss per ray; nearest-hit distances where both hit, against the chord error
    print("agreement (Embree traces triangles, piste the exact patches: the difference is the tessellation's):")
    for lv, (scene, mesh, _, _) in scenes.items():
        eh = out[lv]
        ph = piste_hits.hit
        agree = float((eh == ph).mean())
        emax, e99 = chord_error(net, mesh)
        both = np.nonzero(eh | ph)[0]
        pn = ray_intersect(net, o[both], d[both], t_max=tmax[both], any_hit=False)
        dist = scene.run(o32[both], d32[both], dists=tf32[both].copy(), query="DISTANCE")
        eb = dist < tf32[both]
        bb = pn.hit & eb
        dt = np.abs(pn.t[bb] - dist[bb].astype(np.float64))
        cos = np.abs(np.einsum("kc,kc->k", d[both][bb], pn.normal[bb]))
        off = dt * cos  # the two hits' separation along the surface normal
        within = float((off <= emax).mean()) if bb.any() else float("nan")
        # Embree-only hits this close to the origin are self-hits: the origin, lifted ray_offset off the
        # exact surface, lies under the triangles where a chord passes above a concave surface (at level
        # 8 the 8x8 samples are mesh vertices, so the lifted origins are above the triangles there)
        eonly = eb & ~pn.hit
        selfhit = int((eonly & (dist < emax)).sum())
        print(f"  level {lv:2d}: chord error max {emax:.4f} (p99 {e99:.4f}) model units; hit/miss agree on "
              f"{agree:.3%} of rays ({int((eh & ~ph).sum()):,} hit only by Embree, {selfhit:,} of them nearer the origin than the largest "
              f"chord error, median distance {np.median(dist[eonly]) if eonly.any() else 0:.3f}; {int((ph & ~eh).sum()):,} only by piste); both hit: {int(bb.sum()):,}, |t difference| median {np.median(dt) if bb.any() else 0:.4f} "
              f"max {dt.max() if bb.any() else 0:.3f}, along the normal within the chord error for {within:.2%}")
        if lv == levels[0]:
            em = stat(t[f"embree {lv}"])[0]
            record("bake", f"shadow rays ({k // 1000}k, any hit) vs Embree, level {lv} triangles",
                   "comparable", f"{k / pm / 1e3:.0f} k rays/s (exact)", f"Embree {k / em / 1e6:.1f} M rays/s",
                   f"{pm / em:.0f}x slower; agree {agree:.2%}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="8x8 texels only; Embree at level 8 only, 3 rounds")
    ap.add_argument("--rays", action="store_true", help="only the shadow rays against Embree (no bake)")
    args = ap.parse_args(argv)
    quick = args.quick
    net, dt = timed(default_course)
    lights = default_lights()
    if args.rays:
        embree_peer(net, lights, 8, (8,) if quick else (8, 16, 32), 3 if quick else 7)
        return
    print(f"default course: {len(net)} patches (built in {dt:.2f} s); lights: {len(lights)} "
          f"({', '.join(type(x).__name__ for x in lights)}); cores: {os.cpu_count()}")
    print(f"{'res':>5s} {'jobs':>4s} {'shadows':>7s} {'time s':>7s} {'samples':>9s} {'samples/s':>10s} "
          f"{'rays':>9s} {'occluded':>8s} {'rays/s':>9s}")
    results = {}
    for res in (8,) if quick else (8, 16):
        for jobs, shadows in ((1, True), (2, True), (1, False)):
            lm, dt = timed(bake_lightmap, net, lights, res=res, jobs=jobs, shadows=shadows)
            st = lm.manifest["stats"]
            s = lm.manifest["samples"]
            results[(res, jobs, shadows)] = (lm, dt)
            rays = st.get("rays", 0)
            print(f"{res:5d} {jobs:4d} {str(shadows):>7s} {dt:7.2f} {s:9,d} {s / dt:10,.0f} {rays:9,d} "
                  f"{st.get('rays_occluded', 0):8,d} {rays / dt if rays else 0:9,.0f}")
    best8 = min(dt for (r, j, sh), (_, dt) in results.items() if r == 8 and sh)
    print(f"8x8 with shadows: best {best8:.2f} s (target < 10 s): {'met' if best8 < 10 else 'MISSED'}")
    record("bake", "light map 8x8 with shadows, default course", "< 10 s", f"{best8:.2f} s", "", "", best8 < 10)

    # the naive peer on a subset
    sub = np.arange(0, len(net), 40)
    _, dt_naive = timed(naive_bake, net, lights, 8, sub)
    per_patch_naive = dt_naive / len(sub)
    per_patch = results[(8, 1, True)][1] / len(net)
    print(f"peer: per-patch Python loop, 8x8 with shadows: {per_patch_naive * 1e3:.2f} ms/patch vs baker "
          f"{per_patch * 1e3:.2f} ms/patch (x{per_patch_naive / per_patch:.1f})")

    # accuracy: bilinear light map vs the equation per pixel on the exact surface
    rng = np.random.default_rng(0)
    pick = np.sort(rng.choice(len(net), 60, replace=False))
    t = (np.arange(64) + 0.5) / 64
    vv, uu = np.meshgrid(t, t, indexing="ij")
    u, v = uu.ravel(), vv.ravel()
    pos, nrm = net.evaluate(u, v)
    pos, nrm = pos[pick].reshape(-1, 3), nrm[pick].reshape(-1, 3)
    want = shade(lights, pos, nrm, shadow_visibility(net, lights, pos, nrm, light_terms(lights, pos, nrm)))
    p = np.repeat(pick, len(u))
    for res in (8,) if quick else (8, 16):
        lm = results[(res, 1, True)][0]
        for mode in ("bilinear", "point"):
            err = np.abs(lm.sample(p, np.tile(u, len(pick)), np.tile(v, len(pick)), mode) - want)
            print(f"accuracy {res:2d}x{res:<2d} {mode:8s}: mean {err.mean():.4f}  p99 {np.percentile(err, 99):.4f}  "
                  f"max {err.max():.4f}  (linear light, 1.0 = full)")

    # the PS2 blend over the scene: snow base texture (Cd) x light map (CL), 16 x 16 pixels a patch
    from piste.render.textures import snow_texture

    snow = snow_texture(256)[..., :3]
    res = 8 if quick else 16
    lm = results[(res, 1, True)][0]
    g = (np.arange(16) + 0.5) / 16
    gv, gu = np.meshgrid(g, g, indexing="ij")
    pp = np.repeat(np.arange(len(net)), 256)
    uu, vv = np.tile(gu.ravel(), len(net)), np.tile(gv.ravel(), len(net))
    cl = encode_half_bright(lm.sample(pp, uu, vv))
    c = net.uv[pp]  # corner base UVs, bilinear over the patch
    buv = ((1 - uu) * (1 - vv))[:, None] * c[:, 0] + (uu * (1 - vv))[:, None] * c[:, 1] \
        + (uu * vv)[:, None] * c[:, 2] + ((1 - uu) * vv)[:, None] * c[:, 3]
    tex = np.floor(buv * 256).astype(int) % 256
    cd = snow[tex[:, 1], tex[:, 0]]
    for method in ("talk", "exact", "best"):
        rep, dt = timed(ps2_error_report, cd, cl, method)
        print(f"ps2 blend ({method:5s}) over {rep['pixels']:,} pixels: mean |err| {np.round(rep['mean_abs'], 3).tolist()} "
              f"max {rep['max_abs']} levels, exact {rep['exact_fraction']:.1%}, over-bright {rep['overbright_fraction']:.1%}, "
              f"Cs<0 needed {rep['cs_negative_needed']:,} ({dt:.2f} s)")

    embree_peer(net, lights, 8, (8,) if quick else (8, 16, 32), 3 if quick else 7)


if __name__ == "__main__":
    main()
