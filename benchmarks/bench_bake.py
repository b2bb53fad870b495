"""Light-map bake of the default course (2,560 patches) with terrain shadows, at 8x8 and 16x16.

Prints, per resolution and worker count: wall time, samples/s, shadow rays and rays/s; the same
bake without shadows; a per-patch Python loop over the same equation (the naive peer) on a subset,
with the ratio; the accuracy of the baked maps against the lighting equation evaluated per pixel
(64 x 64 points per patch on 60 patches, with shadows); and the PS2 blend's error over the scene
(snow base texture x baked light map).  Target: 8x8 with shadows under 10 s on 2 cores.
Plain script, not a test.  ``--quick``: 8x8 only.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from piste.lighting import bake_lightmap, default_lights, encode_half_bright, ps2_error_report, sample_points, shade
from piste.lighting.lights import light_terms
from piste.lighting.shadows import shadow_visibility
from piste.world.course import default_course


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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="8x8 texels only")
    quick = ap.parse_args(argv).quick
    net, dt = timed(default_course)
    lights = default_lights()
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


if __name__ == "__main__":
    main()
