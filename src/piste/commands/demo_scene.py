"""``piste demo --scene full`` (the default): the completed real-time scene.

Six riders playing their clips down the default course, the camera chasing the first; trees,
signs, rocks and rails; projected rider shadows; per-vertex lit riders and objects with the
specular pass.  Frames are real time: frame ``i`` is ``t = i / fps`` seconds after rider 0 was at
``--start`` (a fraction of the track).  Prints the terrain table (the talk's statistics), the
characters (bones, palette sizes per LOD, batches), the objects (instances, compressed bytes,
lighting memory vs error), shadow patches per frame and the frame-time breakdown.

Not a CLI command of its own: :mod:`piste.commands.demo` calls :func:`run_scene`.
"""

from __future__ import annotations

import contextlib


def _objects_table(scene, lights) -> list[str]:
    from piste.world.objects import lighting_report

    objs = scene.objects
    st = objs.stats()
    lines = ["Objects (compressed: 16-bit positions + UVs, octahedral 8-bit normals, uint16 indices):",
             f"  {'kind':<6} {'instances':>9} {'triangles':>9} {'vertices':>8} {'bytes/vertex':>12} {'mesh bytes':>10} "
             f"{'as float':>9}"]
    for k, s in st.items():
        lines.append(f"  {k:<6} {s['instances']:>9} {s['triangles']:>9} {s['vertices']:>8} {s['vertex_bytes']:>12} "
                     f"{s['bytes']:>10} {s['bytes_float']:>9}")
    rep = lighting_report(objs, lights)
    lines.append("  lighting options vs the full lighting equation per vertex (all lights):")
    names = {"dynamic": "1 ambient + 3 directional (SSX)", "baked": "pre-calculated RGB8 per vertex",
             "points": "dynamic point + spot lights"}
    for k, r in rep.items():
        lines.append(f"    {names[k]:<34} {r['bytes']:>8} bytes   mean error {r['mean_error']:.4f}   "
                     f"max error {r['max_error']:.3f}")
    return lines


def run_scene(args, bundle, lightmap, lighting: str, t0: float) -> int:
    """The full scene on the built default course ``bundle`` (see :func:`piste.commands.demo.run`):
    the six riders following the track and the course's objects are the default scene file's
    ``[pack]`` and ``[auto_objects]``, made and drawn by the runtime of ``piste render``
    (:class:`piste.pipeline.preview.ScenePreview`); ``--start`` moves the pack."""
    import sys
    import time

    import numpy as np

    from piste.pipeline.preview import ScenePreview, rider_casts  # --rider-model: other models beside the pack
    from piste.render import summarize
    from piste.render.context import save_png
    from piste.render.scene_renderer import summarize_scene
    from piste.render.video import VideoWriter
    from piste.terrain import format_stats

    w, h = args.size
    net, lights = bundle.net, bundle.lights
    preview = ScenePreview(bundle, size=(w, h), lightmap=lightmap, object_lighting=args.objects,
                           shadows=not args.no_shadows, specular=not args.no_specular, lightmap_mode=args.lightmap,
                           start=args.start, casts=rider_casts(args.rider_model),
                           object_lod=getattr(args, "object_lod", None))
    scene, renderer = preview.scene, preview.renderer
    lod_on = args.lod == "on"
    from piste._jit import warm_up
    from piste.terrain.resident import resident_fits, resident_terrain

    warm_up()  # the compiled kernels and the terrain's resident vertex blocks, before anything is timed
    if resident_fits(net):
        resident_terrain(net)
    for k in range(3):  # warm-up frames (not timed, not written): shaders, GL buffers, caches
        preview.render(None, k / args.fps, lod=lod_on, read=False)
    setup_s = time.perf_counter() - t0
    images = []
    try:
        from tqdm import tqdm

        with VideoWriter(args.video, fps=args.fps) if args.video else contextlib.nullcontext() as video:
            bar = tqdm(total=args.frames, desc="rendering", unit="frame",
                       disable=args.no_progress or args.frames < 2, file=sys.stderr)
            t_loop = time.perf_counter()
            # pipelined: each frame's CPU side runs while the GL draws the one before
            for i, image in enumerate(preview.frames([i / args.fps for i in range(args.frames)], lod=lod_on)):
                bar.update(1)
                if i == 0:
                    out = save_png(args.out, image)
                if video is not None:
                    video.append(image)
                im = preview.frame
                im.image = None
                im.terrain.image = None
                images.append(im)
            bar.close()
            loop_s = time.perf_counter() - t_loop
        timed = list(images)
        while len(timed) < 5:  # time at least five frames (medians below); the extra ones are not written
            preview.render(None, len(timed) / args.fps, lod=lod_on)
            im = preview.frame
            im.image = im.terrain.image = None
            timed.append(im)
    finally:
        preview.release()
    med = {f"{k}_ms": float(np.median([im.timings[k] for im in timed])) for k in timed[0].timings}
    med["fps"] = 1e3 / med["total_ms"] if med["total_ms"] > 0 else float("inf")
    s = summarize([im.terrain for im in images])
    sc = summarize_scene(images)
    lod = "on" if lod_on else "off (all 8x8)"
    print(format_stats(s, title=(f"Terrain statistics: {net.name}, {len(images)} frame(s) at {w}x{h}, LOD {lod}, "
                                 f"light map {args.lightmap}, lighting {lighting}")))
    print()
    print(f"Characters: {len(scene.riders)} riders, clips {', '.join(scene.riders.clips)}; blended-matrix palettes "
          f"skinned on the CPU (see piste.render.character_pass)")
    print(f"  {'LOD':<7} {'triangles':>9} {'vertices':>8} {'bones':>5} {'weight step':>11} {'palette matrices':>16} "
          f"{'batches':>7}")
    for c in scene.character_stats():
        print(f"  {c['lod']:<7} {c['triangles']:>9} {c['vertices']:>8} {c['bones']:>5} {c['step']:>11.2f} "
              f"{c['palette']:>16} {c['batches']:>7}")
    lods = np.array([im.scene.rider_lod for im in images])
    print(f"  riders per LOD (mean over frames): high {np.mean(lods == 0) * 6:.1f}, medium {np.mean(lods == 1) * 6:.1f}, "
          f"low {np.mean(lods == 2) * 6:.1f};  rider triangles per frame {sc['rider_triangles']:.0f} "
          f"(+ specular pass)")
    print()
    for line_ in _objects_table(scene, lights):
        print(line_)
    ob = renderer.objects
    levels = ", ".join(f"{n}" for n in ob.lod_counts) if ob is not None else "-"
    print(f"  drawn per frame (frustum-culled, lighting '{args.objects}'): {sc['objects_drawn']:.0f} objects, "
          f"{sc['object_triangles']:.0f} triangles; last frame's objects per LOD level {levels} "
          f"(error <= {ob.lod_pixels if ob is not None else 0:g} px)")
    print()
    print(f"Projected shadows: {len(scene.riders)} low-LOD riders ({scene.lods[-1].n_triangles} triangles each) into "
          f"{renderer.shadows.tile if renderer.shadows else 0}x{renderer.shadows.tile if renderer.shadows else 0} tiles;"
          f" extra pass on the patches each shadow frustum touches:")
    print(f"  shadow patches per frame: {sc['shadow_patches']:.1f} (max {sc['shadow_patches_max']}; "
          f"{sc['shadow_patches_union']:.1f} distinct), {sc['shadow_triangles']:.0f} triangles, "
          f"vs {sc['terrain_patches']:.0f} terrain patches drawn")
    print()
    print(f"frame times (median over {len(timed)} warmed-up frame(s), llvmpipe/EGL):")
    rows = [
        ("animation (clips, rider matrices, camera)", "animation_ms"),
        ("character LOD + skinning (palettes)", "lod_skinning_ms"),
        ("light choice (1 + 3 per rider)", "lights_ms"),
        ("object culling", "objects_ms"),
        ("terrain LOD", "terrain_lod_ms"),
        ("terrain culling", "terrain_cull_ms"),
        ("tessellation", "tessellate_ms"),
        ("shadow frusta + patch culling", "shadow_cull_ms"),
    ]
    for label, key in rows:
        print(f"  {label:<42} {med[key]:7.2f} ms")
    print(f"  {'LOD + cull + tessellation (terrain)':<42} {med['terrain_lod_ms'] + med['terrain_cull_ms'] + med['tessellate_ms']:7.2f} ms")
    print(f"  {'CPU side':<42} {med['cpu_ms']:7.2f} ms")
    print(f"  {'upload':<42} {med['upload_ms']:7.2f} ms")
    print(f"  {'draw terrain (GL issue)':<42} {med['terrain_draw_ms']:7.2f} ms")
    print(f"  {'draw shadows, objects, riders, specular + wait':<42} {med['scene_draw_ms']:7.2f} ms")
    print(f"  {'read back':<42} {med['readback_ms']:7.2f} ms")
    print(f"  {'frame':<42} {med['total_ms']:7.2f} ms = {med['fps']:.1f} fps")
    if len(images) >= 2:
        print(f"  {'pipelined loop (wall time / frames)':<42} {1e3 * loop_s / len(images):7.2f} ms = "
              f"{len(images) / loop_s:.1f} fps  ({len(images)} frames, PNG/video writing included)")
    print(f"  (set-up, not in the frame times: course, light map, riders, objects, GL context, shaders: {setup_s:.2f} s)")
    print(f"wrote {out}" + (f" and {args.video} ({len(images)} frames at {args.fps} fps)" if args.video else ""))
    return 0
