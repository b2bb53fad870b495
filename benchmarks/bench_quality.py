"""Broadcast quality (issue 27): each feature's error against the reference piste computes the slow,
exact way, and its cost, side by side in one run.  Every line states the flags it measures.

Bake side (``piste bake``), on the valley test scene (:func:`piste.lighting.gi.valley_scene`: a floor
between a sunlit wall and a shaded one facing it, 18 patches):

* ``--bounces N``: mean (and 95th percentile) relative luminance error against
  :func:`piste.lighting.gi.path_traced_reference` (independent Monte Carlo paths of up to N + 1
  segments, shadow rays at every vertex, ``--paths`` per point) at sample points off the valley's
  folds; ``--bounces 0`` (today's light) is the first line, for scale.
* ``--bounces 2 --tracer embree``: the gather rays through Embree on a tessellation (``bench`` extra).
* ``--sun-radius DEG``: the penumbra error, mean ``|V - V_ref|`` of the sun's visibility (64 rays, 8 on the rim first)
  over the points the reference shows in penumbra (``0.02 < V_ref < 0.98``), against the area light
  traced with 32 x 32 rays per point (other jitter); the hard sun's error on the same points beside
  it.  Points: the floor across the shaded wall's shadow edge, 1 cm apart.

Cost: the bake's wall time with the feature over the plain bake's (same scene, same resolution,
one process), as "+x of the bake" (the extra time as a fraction of the plain bake), medians of
``--rounds`` interleaved rounds.  Plain script, not a test; ``--quick``: fewer points and paths.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from piste.lighting import bake_lightmap, light_terms, sample_points
from piste.lighting.gi import off_fold, path_traced_reference, reference_error, valley_scene
from piste.lighting.shadows import shadow_visibility

sys.path.insert(0, str(Path(__file__).parent))
from _timing import interleaved, record, stat  # noqa: E402


def cost(times: dict, plain: str) -> dict:
    base = stat(times[plain])[0]
    return {k: (stat(t)[0], stat(t)[0] / base - 1.0) for k, t in times.items()}


def line(flags: str, error: str, t: float, extra: float | None) -> str:
    c = "" if extra is None else f"+{extra:.1f}x of the bake" if extra >= 1 else f"+{extra * 100:.0f} % of the bake"
    return f"  {flags:<52} {error:<52} {t * 1e3:9.1f} ms  {c}"


def bake_gi(args) -> None:
    net, lights = valley_scene()
    res = 8
    pos, nrm = sample_points(net, res)
    pos, nrm = pos.reshape(-1, 3), nrm.reshape(-1, 3)
    rng = np.random.default_rng(7)
    pick = np.sort(rng.choice(np.flatnonzero(off_fold(net, res)), args.points, replace=False))
    t0 = time.perf_counter()
    refs = {n: path_traced_reference(net, lights, pos[pick], nrm[pick], n, paths=args.paths, seed=3) for n in (1, 2, 3)}
    t_ref = time.perf_counter() - t0
    print(f"global illumination: valley scene ({len(net)} patches, res {res}, {len(pos)} samples); reference: "
          f"{args.points} points off the folds x {args.paths} paths, N = 1, 2, 3 in {t_ref:.1f} s")
    configs = {"plain": dict(), "b1": dict(bounces=1), "b2": dict(bounces=2), "b3": dict(bounces=3),
               "b2r16": dict(bounces=2, gather_rays=16), "b2r256": dict(bounces=2, gather_rays=256)}
    try:
        import embreex  # noqa: F401

        configs["b2em"] = dict(bounces=2, tracer="embree")
    except ImportError:
        print("  (--tracer embree skipped: embreex is not installed; pip install 'piste[bench]')")
    out = {}

    def runner(name):
        def go():
            out[name] = bake_lightmap(net, lights, res=res, jobs=1, **configs[name])
        return go

    times = interleaved({k: runner(k) for k in configs}, rounds=args.rounds)
    c = cost(times, "plain")
    rows = [("plain", "--bounces 0 (today's light)", 2), ("b1", "--bounces 1", 1), ("b2", "--bounces 2", 2),
            ("b3", "--bounces 3", 3), ("b2r16", "--bounces 2, 16 gather rays (4x4)", 2),
            ("b2r256", "--bounces 2, 256 gather rays (16x16)", 2), ("b2em", "--bounces 2 --tracer embree", 2)]
    for name, flags, n in rows:
        if name not in out:
            continue
        e = reference_error(out[name].tiles().reshape(-1, 3)[pick], refs[n])
        flags = flags + (", 64 gather rays (8x8)" if name in ("b1", "b2", "b3", "b2em") else "")
        err = f"vs path-traced N={n}: mean {e.mean() * 100:5.2f} %, p95 {np.percentile(e, 95) * 100:5.1f} %"
        print(line(flags, err, c[name][0], None if name == "plain" else c[name][1]))
        if name == "b2":
            record("quality", "bake --bounces 2: mean rel. error vs path-traced reference", "<= 3 %",
                   f"{e.mean() * 100:.2f} %", "", f"+{c[name][1]:.1f}x bake", bool(e.mean() <= 0.03))


def bake_soft_sun(args) -> None:
    net, lights = valley_scene()
    res = 16
    # the estimator measured on a dense line of floor points across the shadow's edge (1 cm apart, 5
    # rows): light-map samples (1 m apart) would catch a real sun's 12 cm penumbra a few times only
    x, y = np.meshgrid(np.arange(0.005, 12.0, 0.01), np.linspace(4.0, 20.0, 5))
    pos = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], -1)
    nrm = np.broadcast_to(np.array([0.0, 0.0, 1.0]), pos.shape).copy()
    terms = light_terms(lights, pos, nrm)
    ids = np.arange(len(pos))

    def vis(where, **kw):
        return shadow_visibility(net, lights, pos[where], nrm[where], terms[where], ids=ids[where], **kw)[:, 0]

    hard = vis(ids)
    print(f"soft shadows: valley scene, the shaded wall's shadow on the floor at {len(pos)} points 1 cm apart; "
          "reference: 32 x 32 rays per point where a 1.5x wider sun's 64 rays see a penumbra; "
          f"cost: bakes at res {res}")
    radii = (0.27, 1.0, 2.0)
    out = {}

    def runner(r):
        def go():
            out[r] = bake_lightmap(net, lights, res=res, jobs=1, sun_radius=r)
        return go

    fns = {"plain": lambda: bake_lightmap(net, lights, res=res, jobs=1)}
    fns.update({r: runner(r) for r in radii})
    times = interleaved(fns, rounds=args.rounds)
    c = cost(times, "plain")
    print(line("--sun-radius 0 (hard sun, the default)", "", c["plain"][0], None))
    for r in radii:
        wider = vis(ids, sun_radius=1.5 * r, sun_rays=64, seed=7)
        cand = np.flatnonzero((wider > 0.0) & (wider < 1.0))
        ref = np.where(wider >= 1.0, 1.0, 0.0)
        ref[cand] = vis(cand, sun_radius=r, sun_rays=1024, seed=99)
        pen = (ref > 0.02) & (ref < 0.98)
        soft = vis(ids, sun_radius=r)
        full = vis(ids, sun_radius=r, sun_adaptive=False)
        few = vis(ids, sun_radius=r, sun_rays=16, sun_adaptive=False)
        es, eh = np.abs(soft - ref)[pen].mean(), np.abs(hard - ref)[pen].mean()
        err = f"penumbra ({int(pen.sum())} pts): |dV| {es:.3f} (hard sun {eh:.3f})"
        print(line(f"--sun-radius {r:g} (64 sun rays, 8 on the rim first)", err, c[r][0], c[r][1]))
        print(f"  {'':<52} (all 64 everywhere: {np.abs(full - ref)[pen].mean():.3f}; "
              f"16 everywhere: {np.abs(few - ref)[pen].mean():.3f})")
        if r == 0.27:
            record("quality", "bake --sun-radius 0.27: penumbra |dV| vs 1024-ray area light", "", f"{es:.3f}",
                   f"hard {eh:.3f}", f"+{c[r][1]:.1f}x bake", None)


def render_aa(args) -> None:
    """Run-time side, anti-aliasing (issue 27 item 1), on the default demo scene (``piste demo``'s
    bundle, chase camera, frames at t = 0 and 1 s, 640x448): the edge error (mean |difference|, 0..255
    a channel, over the pixels where the reference's luma gradient is >= 24) of each ``--aa`` mode and
    of ``--supersample 2`` against ``--supersample 4``; cost: a frame's wall time (draw + read back)
    over ``--aa off``'s, medians of ``--rounds`` interleaved rounds."""
    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.default_scene import build_default_scene
    from piste.pipeline.preview import ScenePreview
    from piste.render.aa import edge_error
    from piste.render.context import create_context

    print("render: anti-aliasing, default demo scene 640x448, 2 chase frames; edge error vs --supersample 4")
    bundle = load_bundle(build_default_scene(0).path, verify=False, warm=True)
    ctx = create_context()
    times = (0.0, 1.0)
    modes = {"--aa off": ("off", 1), "--aa msaa2": ("msaa2", 1), "--aa msaa4": ("msaa4", 1),
             "--aa msaa8": ("msaa8", 1), "--aa fxaa": ("fxaa", 1), "--supersample 2": ("off", 2),
             "--supersample 4": ("off", 4)}
    previews = {k: ScenePreview(bundle, size=(640, 448), ctx=ctx, object_lighting="dynamic", aa=aa, supersample=n)
                for k, (aa, n) in modes.items()}
    try:
        images = {k: [p.render(None, t) for t in times] for k, p in previews.items()}
        tm = interleaved({k: (lambda p=p: [p.render(None, t) for t in times]) for k, p in previews.items()},
                         args.rounds)
        base = stat(tm["--aa off"])[0]
        ref = images["--supersample 4"]
        for k, p in previews.items():
            e = float(np.mean([edge_error(a, r)[0] for a, r in zip(images[k], ref)]))
            t = stat(tm[k])[0] / len(times)
            extra = stat(tm[k])[0] / base - 1.0
            s = p.stats.get("aa_samples")
            err = f"edge error {e:5.2f}" + (f" ({s} samples asked)" if s else "")
            print(f"  {k:<52} {err:<52} {t * 1e3:9.1f} ms  {extra * 100:+.0f} % of the frame")
            record("quality", f"render {k}: edge error vs --supersample 4", "", f"{e:.2f}", "",
                   f"{extra * 100:+.0f} % frame", None)
    finally:
        for p in previews.values():
            p.release()
        ctx.release()


def render_dof(args) -> None:
    """Run-time side, depth of field (issue 27 item 3), on the default demo scene (640x448, the
    chase camera at t = 0.5 s): mean |difference| (0..255 a channel) of ``--dof 8:0.1`` and of the
    pinhole frame against the accumulation reference (the mean of 32 pinhole frames over the lens
    disc, each re-aimed at the focus point), over all pixels and over those the lens changes by more
    than 8 levels; cost: the frame's wall time with the pass over the pinhole frame's, medians of
    ``--rounds`` interleaved rounds."""
    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.default_scene import build_default_scene
    from piste.pipeline.preview import ScenePreview
    from piste.render.context import create_context
    from piste.render.dof import lens_cameras

    focus, aperture, t = 8.0, 0.1, 0.5
    print("render: depth of field, default demo scene 640x448, chase camera; vs the mean of 32 pinhole frames "
          "over the lens disc")
    bundle = load_bundle(build_default_scene(0).path, verify=False, warm=True)
    ctx = create_context()
    pin = ScenePreview(bundle, size=(640, 448), ctx=ctx, object_lighting="dynamic")
    dof = ScenePreview(bundle, size=(640, 448), ctx=ctx, object_lighting="dynamic", dof=(focus, aperture))
    try:
        pin.render(None, t)
        cam = pin.frame.scene.camera
        ref = np.mean([pin.render(c, t) for c in lens_cameras(cam, focus, aperture, 32)], axis=0)
        images = {"(pinhole)": pin.render(cam, t).astype(np.float64),
                  f"--dof {focus:g}:{aperture:g}": dof.render(cam, t).astype(np.float64)}
        tm = interleaved({"(pinhole)": lambda: pin.render(cam, t), "dof": lambda: dof.render(cam, t)}, args.rounds)
        base = stat(tm["(pinhole)"])[0]
        lens = np.abs(images["(pinhole)"] - ref).max(axis=-1) > 8
        for (k, img), tk in zip(images.items(), ("(pinhole)", "dof")):
            d = np.abs(img - ref)
            extra = stat(tm[tk])[0] / base - 1.0
            err = f"|err| {d.mean():5.2f}, {d[lens].mean():5.2f} where the lens blurs ({lens.mean():.1%})"
            print(f"  {k:<52} {err:<52} {stat(tm[tk])[0] * 1e3:9.1f} ms  {extra * 100:+.0f} % of the frame")
            record("quality", f"render {k}: |err| vs 32-frame lens reference", "", f"{d.mean():.2f}",
                   f"{d[lens].mean():.2f} lens px", f"{extra * 100:+.0f} % frame", None)
    finally:
        pin.release()
        dof.release()
        ctx.release()


def render_soft_shadows(args) -> None:
    """Run-time side, soft rider shadows (issue 27 item 5): the demo's first rider (its low LOD, as
    the shadow pass draws it, at t = 0) over flat snow, standing on it and 3 m up in a jump, seen
    from above (128 px over the shadow's 7 m x 7 m square); error: mean ``|V - V_ref|`` of the sun's
    visibility over the pixels the reference shows in penumbra (``0.02 < V_ref < 0.98``), against
    :func:`piste.render.shadow_pass.area_light_visibility` (128 rays over the disc per pixel), for
    the hard pass and ``--soft-shadows`` (PCSS).  Cost: a frame of the default demo scene (640x448,
    chase frames at t = 0 and 1 s) with ``--soft-shadows`` over without, medians of ``--rounds``
    interleaved rounds."""
    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.default_scene import build_default_scene
    from piste.pipeline.preview import ScenePreview
    from piste.render.context import create_context
    from piste.render.shadow_pass import area_light_visibility, shadow_on_plane

    bundle = load_bundle(build_default_scene(0).path, verify=False, warm=True)
    ctx = create_context()
    previews = {k: ScenePreview(bundle, size=(640, 448), ctx=ctx, object_lighting="dynamic", soft_shadows=k)
                for k in (False, True)}
    try:
        r = previews[False].renderer
        plan = r._plan(0.0)
        pos = np.asarray(plan["frames"][0].shadow[0][0], np.float64)
        idx = np.asarray(r.casts[0].lods[-1].mesh.indices)
        sun = np.asarray(r.scene.sun.direction, np.float64)
        print(f"render: soft rider shadows, the demo's rider ({len(idx)} low-LOD triangles) over flat snow, "
              "128 px over 7 m; reference: 128 sun-disc rays per pixel")
        for lift in (0.0, 3.0):
            p = pos - [0.0, 0.0, pos[:, 2].min() - lift]
            c = p.mean(0)
            d = sun / np.linalg.norm(sun)
            centre = c[:2] + d[:2] / max(-d[2], 1e-3) * c[2]  # where the sun's ray through the rider lands
            rect = (centre[0] - 3.5, centre[1] - 3.5, centre[0] + 3.5, centre[1] + 3.5)
            for radius in (0.27, 1.0, 2.0):
                t0 = time.perf_counter()
                v = {k: shadow_on_plane(ctx, p, idx, sun, rect, res=128, soft=k, sun_radius=radius,
                                        tile=r.shadows.tile)[0] for k in (False, True)}
                pts = shadow_on_plane(ctx, p, idx, sun, rect, res=128)[1]
                ref = area_light_visibility(pts.reshape(-1, 3), p[idx], sun, radius, rays=128).reshape(pts.shape[:2])
                pen = (ref > 0.02) & (ref < 0.98)
                eh, es = (float(np.abs(v[k] - ref)[pen].mean()) for k in (False, True))
                flags = f"--soft-shadows, sun {radius:g} deg, rider {lift:g} m up"
                err = f"penumbra ({int(pen.sum())} px): |dV| {es:.3f} (hard {eh:.3f})"
                print(f"  {flags:<52} {err:<52} (reference {time.perf_counter() - t0:.1f} s)")
                if radius == 0.27:
                    record("quality", f"render --soft-shadows (rider {lift:g} m up): penumbra |dV| vs area light",
                           "", f"{es:.3f}", f"hard {eh:.3f}", "", None)
        times = (0.0, 1.0)
        tm = interleaved({k: (lambda p=p: [p.render(None, t) for t in times]) for k, p in previews.items()}, args.rounds)
        base, soft = stat(tm[False])[0], stat(tm[True])[0]
        print(f"  {'--soft-shadows (default scene, 2 chase frames)':<52} {'':<52} {soft / len(times) * 1e3:9.1f} ms  "
              f"{(soft / base - 1.0) * 100:+.0f} % of the frame ({base / len(times) * 1e3:.1f} ms without)")
        record("quality", "render --soft-shadows: frame cost", "", f"{(soft / base - 1.0) * 100:+.0f} % frame", "", "", None)
    finally:
        for p in previews.values():
            p.release()
        ctx.release()


def render_occlusion(args) -> None:
    """Run-time side, occlusion culling (issue 27 item 6): on the default course (``piste demo``'s
    bundle, 640x448) from the demo's chase camera (t = 0, 2, 4 s), the course's flight camera (5
    points along it) and examples/scenes/default.toml's ``start`` camera: the terrain patches and
    objects ``--occlusion on`` culls and the pixels that differ from ``--occlusion off`` (must be 0);
    cost: the frame's wall time with it over without (chase frames), medians of ``--rounds``."""
    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.default_scene import build_default_scene
    from piste.pipeline.preview import ScenePreview, camera_at
    from piste.render.context import create_context
    from piste.world.camera import Camera

    bundle = load_bundle(build_default_scene(0).path, verify=False, warm=True)
    ctx = create_context()
    cams = [(f"chase t={t:g}", None, t) for t in (0.0, 2.0, 4.0)]
    cams += [(f"flight {i}/4", camera_at(bundle, "flight", i, 5), 0.0) for i in range(5)]
    cams += [("start", Camera(np.array([255.0, 115.0, 356.0]), np.array([236.0, 160.0, 336.0]),
                              up=np.array([0.0, 0.0, 1.0]), fov_y=55.0, near=0.5, far=4000.0), 0.0)]
    previews = {k: ScenePreview(bundle, size=(640, 448), ctx=ctx, object_lighting="dynamic", occlusion=k)
                for k in (False, True)}
    print("render: occlusion culling, default course 640x448 (software hierarchical-Z of the 256 nearest patches, "
          "8 px cells)")
    try:
        for p in previews.values():
            p.render(None, 0.0)  # (the first frame of a process waits for the resident blocks)
        tot = np.zeros(4, np.int64)
        worst = 0
        for name, cam, t in cams:
            a = previews[False].render(cam, t)
            b = previews[True].render(cam, t)
            off, on = previews[False].frame.stats, previews[True].frame.stats
            diff = int(np.any(a != b, axis=-1).sum())
            worst = max(worst, diff)
            tot += [on["occluded_patches"], off["terrain_patches"], on["occluded_objects"], off["objects_drawn"]]
            what = (f"patches {on['occluded_patches']:4d} of {off['terrain_patches']:4d}, objects "
                    f"{on['occluded_objects']:3d} of {off['objects_drawn']:3d} culled")
            print(f"  {'--occlusion on, ' + name:<52} {what:<52} {diff} px differ")
        times = (0.0, 2.0)
        tm = interleaved({k: (lambda p=p: [p.render(None, t) for t in times]) for k, p in previews.items()}, args.rounds)
        base, occ = stat(tm[False])[0], stat(tm[True])[0]
        print(f"  {'--occlusion on (all cameras)':<52} "
              f"{f'patches {tot[0]} of {tot[1]}, objects {tot[2]} of {tot[3]}; max {worst} px differ':<52} "
              f"{occ / len(times) * 1e3:9.1f} ms  {(occ / base - 1.0) * 100:+.0f} % of the frame "
              f"({base / len(times) * 1e3:.1f} ms without, chase t=0, 2)")
        record("quality", "render --occlusion on: patches / objects culled, pixels differing (9 cameras)", "0 px",
               f"{tot[0]}/{tot[1]} patches, {tot[2]}/{tot[3]} objects, {worst} px", "",
               f"{(occ / base - 1.0) * 100:+.0f} % frame", worst == 0)
    finally:
        for p in previews.values():
            p.release()
        ctx.release()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="64 points x 1024 paths, 3 rounds")
    ap.add_argument("--points", type=int, default=256)
    ap.add_argument("--paths", type=int, default=4096)
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    if args.quick:
        args.points, args.paths, args.rounds = 64, 1024, 3
    print("piste bench_quality: feature, its error against piste's own reference, its cost (one process)")
    bake_gi(args)
    bake_soft_sun(args)
    render_aa(args)
    render_dof(args)
    render_soft_shadows(args)
    render_occlusion(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
