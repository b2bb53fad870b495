"""Drawing the same terrain mesh with piste's TerrainPass and with vispy (gloo), 640x448, llvmpipe.

The mesh is one frame of the default course seen by the track camera (piste's LOD, culling and CPU
tessellation: positions, base UVs, light-map UVs, indices), textured with piste's snow texture
(mip-mapped) times the placeholder light-map atlas, drawn off-screen (RGBA8 + depth 24, depth test,
back faces culled), no sky, no fog, no track.  Contenders, each timed the same way (interleaved
rounds in one process, medians with [min-max]; every frame makes its own GL context current, clears,
draws and waits with glFinish):

* piste ``TerrainPass.draw`` (moderngl on piste's EGL context, the ``modulate`` shader);
* vispy ``gloo.Program.draw`` on vispy's own headless EGL canvas (``benchmarks/_vispy_peer.py``:
  GLSL 1.20, base x light map, the same GL state);

both with the buffers already on the GPU ("draw") and with the mesh written into them first
("upload + draw", as piste's CPU path streams it every frame).  The two pictures are compared
(mean and max difference, pixels more than 2 levels apart) to show they draw the same thing.

If vispy cannot run headless here, the reason (vispy's error text) is printed and recorded instead
of a number.

Run: ``.venv/bin/python benchmarks/bench_draw.py [--quick] [--frames N] [--rounds R] [--size W H]``
``--quick``: one camera, 5 rounds.
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _timing import interleaved, ms, record, stat  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    ap.add_argument("--quick", action="store_true", help="one camera, 5 rounds")
    ap.add_argument("--frames", type=int, default=3, help="cameras down the track (default 3; --quick: 1)")
    ap.add_argument("--rounds", type=int, default=None, help="interleaved rounds per camera (default 11; --quick: 5)")
    ap.add_argument("--size", type=int, nargs=2, default=(640, 448), metavar=("W", "H"))
    args = ap.parse_args(argv)
    frames = 1 if args.quick else max(args.frames, 1)
    rounds = args.rounds or (5 if args.quick else 11)
    size = tuple(args.size)

    from piste.render import TerrainRenderer
    from piste.render.textures import placeholder_lightmap, snow_texture
    from piste.world.camera import track_camera
    from piste.world.course import default_course, track_centerline

    net = default_course()
    line = track_centerline()
    light = placeholder_lightmap(net)
    base = snow_texture()
    r = TerrainRenderer(net, size=size, lightmap=light, base_texture=base, resident=False, lod_morph=False)
    ctx = r.ctx
    print(f"piste: {ctx.info['GL_RENDERER']}, GL {ctx.version_code}, {size[0]}x{size[1]}; load {os.getloadavg()[0]:.2f} "
          f"(2 shared cores)")

    from _vispy_peer import VispyTerrain, make_canvas

    try:
        canvas, desc = make_canvas(size)
    except (ImportError, RuntimeError) as exc:  # vispy missing or no headless context: say why, record it
        why = f"{type(exc).__name__}: {str(exc).strip()}".replace("\n", " ")
        print(f"vispy peer not run: {why}")
        record("draw", "terrain mesh draw vs vispy.gloo", "comparable", "", f"not run: {why}"[:120], "")
        r.release()
        return 0
    vt = VispyTerrain(canvas, size, base, light, cull_back=r.terrain.cull_back)
    gl = vt.gl
    print(f"vispy: {desc}; {gl.glGetParameter(gl.GL_RENDERER)}, {gl.glGetParameter(gl.GL_VERSION)}")

    ts = np.linspace(0.3, 0.8, frames) if frames > 1 else [0.3]
    res = {k: [] for k in ("piste draw", "vispy draw", "piste upload+draw", "vispy upload+draw")}
    print(f"\n{'camera t':>8s} {'tris':>8s}  " + "  ".join(f"{k:>30s}" for k in res) + f"  {'img mean/max':>13s} {'>2 lv':>6s}")
    for t in ts:
        cam = track_camera(line, t)
        cam = replace(cam, aspect=size[0] / size[1])
        mesh = r.prepare(cam)
        vp = cam.view_projection()
        eye = cam.eye

        def piste_draw():
            with ctx:
                r.target.use()
                r.target.clear((0.0, 0.0, 0.0, 1.0))
                r.terrain.draw(vp, eye)
                ctx.finish()

        def piste_upload_draw():
            with ctx:
                r.terrain.upload(mesh)
            piste_draw()

        def vispy_upload_draw():
            vt.upload(mesh)
            vt.draw(vp)

        with ctx:
            r.terrain.upload(mesh)
        vt.upload(mesh)
        tt = interleaved({"piste draw": piste_draw, "vispy draw": lambda: vt.draw(vp),
                          "piste upload+draw": piste_upload_draw, "vispy upload+draw": vispy_upload_draw}, rounds, warmup=2)
        for k, v in tt.items():
            res[k].append(v)
        # the same picture?
        piste_draw()
        with ctx:
            a = r.target.read()[..., :3].astype(np.int16)
        vt.draw(vp)
        b = vt.read()[..., :3].astype(np.int16)
        d = np.abs(a - b)
        if os.environ.get("BENCH_DRAW_DUMP"):
            from PIL import Image

            Image.fromarray(np.concatenate([a, b], axis=1).astype(np.uint8)).save(os.environ["BENCH_DRAW_DUMP"])
        print(f"{t:8.2f} {mesh.n_triangles:8,d}  " + "  ".join(f"{ms(tt[k]):>30s}" for k in res)
              + f"  {d.mean():6.3f}/{d.max():<6d} {(d.max(axis=2) > 2).mean():6.2%}")

    allt = {k: np.concatenate(v) for k, v in res.items()}
    print(f"\nall cameras ({frames} x {rounds} interleaved rounds; load {os.getloadavg()[0]:.2f}):")
    for what in ("draw", "upload+draw"):
        p, v = stat(allt[f"piste {what}"])[0], stat(allt[f"vispy {what}"])[0]
        print(f"  {what:12s} piste {ms(allt[f'piste {what}'])}   vispy {ms(allt[f'vispy {what}'])}   "
              f"vispy / piste time {v / p:.2f}x")
        record("draw", f"terrain mesh {what} vs vispy.gloo ({size[0]}x{size[1]})", "<= vispy",
               f"{p * 1e3:.2f} ms", f"vispy {v * 1e3:.2f} ms", f"{v / p:.2f}x", p <= v * 1.05)
    vt.release()
    with ctx:
        r.release()
    return 0


if __name__ == "__main__":
    sys.exit(main())
