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
("upload + draw", as piste's CPU path streams it every frame).  A third, diagnostic contender draws
on piste's context with moderngl and vispy's minimal shader (GLSL 3.30, base x light map, the same
textures): where it matches vispy and piste does not, the difference is piste's terrain shader (its
world-position varying, track, fog and geomorph branches), not the API.  The two pictures are compared
(mean and max difference, pixels more than 2 levels apart) to show they draw the same thing.

If vispy cannot run headless here, the reason (vispy's error text) is printed and recorded instead
of a number.

Run: ``.venv/bin/python benchmarks/bench_draw.py [--quick] [--frames N] [--rounds R] [--size W H]``
``--quick``: one camera, 9 rounds.
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


_MIN_VS = """#version 330 core
uniform mat4 u_mvp;
in vec3 in_pos;
in vec2 in_uv;
in vec2 in_uvl;
out vec2 v_uv;
out vec2 v_uvl;
void main() { gl_Position = u_mvp * vec4(in_pos, 1.0); v_uv = in_uv; v_uvl = in_uvl; }
"""
_MIN_FS = """#version 330 core
uniform sampler2D u_base;
uniform sampler2D u_light;
in vec2 v_uv;
in vec2 v_uvl;
out vec4 f_color;
void main() { f_color = vec4(texture(u_base, v_uv).rgb * texture(u_light, v_uvl).rgb, 1.0); }
"""


class MinimalShader:
    """Diagnostic: piste's context and textures, moderngl, vispy's minimal shader."""

    def __init__(self, ctx, terrain_pass):
        self.ctx, self.tp = ctx, terrain_pass
        self.prog = ctx.program(vertex_shader=_MIN_VS, fragment_shader=_MIN_FS)
        self.prog["u_base"].value, self.prog["u_light"].value = 0, 1
        self.vao, self.bufs = None, []

    def upload(self, mesh) -> None:
        for b in self.bufs + ([self.vao] if self.vao else []):
            b.release()
        ctx = self.ctx
        self.bufs = [ctx.buffer(np.ascontiguousarray(a, dtype=dt)) for a, dt in
                     ((mesh.positions, np.float32), (mesh.uv, np.float32), (mesh.uv_lightmap, np.float32),
                      (mesh.indices, np.uint32))]
        self.vao = ctx.vertex_array(self.prog, [(self.bufs[0], "3f", "in_pos"), (self.bufs[1], "2f", "in_uv"),
                                                (self.bufs[2], "2f", "in_uvl")], self.bufs[3], index_element_size=4)

    def draw(self, vp) -> None:
        import moderngl

        ctx = self.ctx
        self.tp.base.use(0)
        self.tp.light.use(1)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.BLEND)
        if self.tp.cull_back:
            ctx.enable(moderngl.CULL_FACE)
            ctx.cull_face = "back"
        ctx.depth_func = "<"
        self.prog["u_mvp"].write(np.asarray(vp, dtype=np.float32).T.tobytes())
        self.vao.render(moderngl.TRIANGLES)
        ctx.disable(moderngl.CULL_FACE)

    def release(self) -> None:
        for b in self.bufs + [self.vao, self.prog]:
            if b is not None:
                b.release()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    ap.add_argument("--quick", action="store_true", help="one camera, 9 rounds")
    ap.add_argument("--frames", type=int, default=3, help="cameras down the track (default 3; --quick: 1)")
    ap.add_argument("--rounds", type=int, default=None, help="interleaved rounds per camera (default 11; --quick: 9)")
    ap.add_argument("--size", type=int, nargs=2, default=(640, 448), metavar=("W", "H"))
    args = ap.parse_args(argv)
    frames = 1 if args.quick else max(args.frames, 1)
    rounds = args.rounds or (9 if args.quick else 11)
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

    differ = 0.0  # the largest fraction of pixels more than 2 levels apart (vispy vs piste) over the cameras
    ts = np.linspace(0.3, 0.8, frames) if frames > 1 else [0.3]
    with ctx:
        mini = MinimalShader(ctx, r.terrain)
    res = {k: [] for k in ("piste draw", "vispy draw", "piste upload+draw", "vispy upload+draw", "moderngl min. shader")}
    print(f"\n{'camera t':>8s} {'tris':>8s}  " + "  ".join(f"{k:>30s}" for k in res)
          + f"  {'vispy-piste img mean/max':>24s} {'>2 lv':>6s} {'min. shader-piste':>17s}")
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

        def mini_draw():
            with ctx:
                r.target.use()
                r.target.clear((0.0, 0.0, 0.0, 1.0))
                mini.draw(vp)
                ctx.finish()

        with ctx:
            r.terrain.upload(mesh)
            mini.upload(mesh)
        vt.upload(mesh)
        tt = interleaved({"piste draw": piste_draw, "vispy draw": lambda: vt.draw(vp),
                          "piste upload+draw": piste_upload_draw, "vispy upload+draw": vispy_upload_draw,
                          "moderngl min. shader": mini_draw}, rounds, warmup=2)
        for k, v in tt.items():
            res[k].append(v)
        # the same picture?
        piste_draw()
        with ctx:
            a = r.target.read()[..., :3].astype(np.int16)
        vt.draw(vp)
        b = vt.read()[..., :3].astype(np.int16)
        d = np.abs(a - b)
        differ = max(differ, float((d.max(axis=2) > 2).mean()))
        mini_draw()
        with ctx:
            dm = np.abs(r.target.read()[..., :3].astype(np.int16) - a)
        if os.environ.get("BENCH_DRAW_DUMP"):
            from PIL import Image

            Image.fromarray(np.concatenate([a, b], axis=1).astype(np.uint8)).save(os.environ["BENCH_DRAW_DUMP"])
        print(f"{t:8.2f} {mesh.n_triangles:8,d}  " + "  ".join(f"{ms(tt[k]):>30s}" for k in res)
              + f"  {d.mean():17.3f}/{d.max():<6d} {(d.max(axis=2) > 2).mean():6.2%} {dm.mean():10.3f}/{dm.max():<6d}")

    allt = {k: np.concatenate(v) for k, v in res.items()}
    print(f"\nall cameras ({frames} x {rounds} interleaved rounds; load {os.getloadavg()[0]:.2f}):")
    for what in ("draw", "upload+draw"):
        p, v = stat(allt[f"piste {what}"])[0], stat(allt[f"vispy {what}"])[0]
        print(f"  {what:12s} piste {ms(allt[f'piste {what}'])}   vispy {ms(allt[f'vispy {what}'])}   "
              f"piste takes {p / v:.2f}x vispy's time")
        record("draw", f"terrain mesh {what} vs vispy.gloo ({size[0]}x{size[1]}, "
               + ("same picture)" if differ < 1e-3 else f"{differ:.1%} of pixels differ)"), "<= vispy's time",
               f"{p * 1e3:.2f} ms", f"vispy {v * 1e3:.2f} ms", f"piste {p / v:.2f}x vispy's time", p <= v * 1.05)
    m = stat(allt["moderngl min. shader"])[0]
    print(f"  diagnostic: moderngl + the minimal shader on piste's context {ms(allt['moderngl min. shader'])}: "
          f"piste's terrain shader costs {stat(allt['piste draw'])[0] / m:.2f}x the minimal one's time; vispy takes "
          f"{stat(allt['vispy draw'])[0] / m:.2f}x it")
    vt.release()
    with ctx:
        mini.release()
        r.release()
    return 0


if __name__ == "__main__":
    sys.exit(main())
