"""Frame time at 640x448 on this machine (llvmpipe/EGL without a GPU), measured against the
machine's floor, per pass, and as the world grows.

Sections (every configuration interleaved frame by frame in one process; medians with [min-max]):

1. **Floor**: clear + one full-screen textured quad + read-back at the same size: what any frame
   costs here, timed the same way in every section (``Floor.steady``: between frames, one settling
   run, then the median of four back to back).  Every frame time below is also printed as a multiple
   of it (target <= 4x).
2. **Terrain**: the default course flown down the track: the GPU-resident path with geomorphing
   (the default), without geomorphing, the CPU tessellation path (vertices streamed every frame),
   the PS2 two-pass light map, LOD off.
   Then each renderer change against what it replaced (A/B on the same frames, with the mean pixel
   difference): per-mode terrain shader vs the run-time ``u_mode`` if-chain, nearest-mip vs
   trilinear base texture, geomorphing, resident vs streamed vertices.
3. **Completed scene**: six riders chased by the camera, objects, projected shadows, specular: the
   full scene, without shadows / specular, and a per-pass profile (``glFinish`` around each pass:
   what llvmpipe spends in each); then each scene change A/B on its own pass (the objects' per-mode
   programs with per-instance attributes, levels of detail against full meshes and at <= 1 px against
   <= 0.5 px of error, 6 levels a kind against 4, and, as an upper bound for impostors,
   the instances under 8 px of radius left out; the terrain's back-face culling, whole
   back-facing patches left out by normal cones (off by default: no gain measured), error-driven
   edges (flat, 2 corners, or coarsest where under 1 px, and 1 px against 0.5 px), visibility sets and per-vertex track distance; the shadow mips by compute dispatches, level l read as an image; the shadow casters closed by caps and culled against every triangle both sides; the shadow
   receivers cut to their frusta by clip distances, and drawn from the terrain's resident blocks by index), with the pixels changed;
   then whole frames, without the per-pass syncs: the terrain flushed to llvmpipe's rasterizer threads
   as soon as it is issued against everything rasterized at the frame's end (wall and CPU time);
   then blocks of 10 frames, order rotated: one at a time (``render``), pipelined (``frames``) and
   the GL work alone (each frame planned untimed, then issued, waited for and read back: the bound
   under any change to piste's CPU side).
   3b. **``piste render``'s runtime**: ``examples/scenes/default.toml`` built (the step cache beside it)
   and drawn by the objects ``piste render SCENE --camera flight --frames N`` uses (``ScenePreview``
   with the command's defaults, the flight camera's frame ``i`` of ``N`` at ``t = i / 30``), frames
   read back, interleaved with the floor in the same context (also under ``--scene``; alone with
   ``--render-only``).
4. **Scaling**: frame time and CPU side against the number of patches (2,560 / 10k / 40k; the
   camera's far plane at 1 km caps the visible set; ``bench_terrain.py`` takes the CPU side to 160k)
   and riders (6 / 24 / 96), with the fitted exponent ``t ~ n^k``.

Targets (issue 15): 60 fps (16.7 ms) for the completed scene, CPU side <= 4 ms, frame <= 4x floor.

Run: ``.venv/bin/python benchmarks/bench_frame.py [--quick] [--frames N] [--size W H] [--scene | --render-only]``
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
from _timing import fit_exponent, record  # noqa: E402

_FLOOR_VS = """#version 330 core
out vec2 v_uv;
void main() {
    vec2 p = vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1));
    v_uv = p;
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""
_FLOOR_FS = """#version 330 core
uniform sampler2D u_tex;
in vec2 v_uv;
out vec4 f_color;
void main() { f_color = texture(u_tex, v_uv); }
"""


class Floor:
    """The machine's floor at ``size``: clear, one full-screen textured quad (bilinear, mip-mapped
    like the terrain's base texture), glFinish, read-back."""

    def __init__(self, ctx, size):
        import moderngl

        from piste.render.context import Offscreen

        self.ctx = ctx
        self.target = Offscreen(ctx, size)
        rng = np.random.default_rng(0)
        img = rng.integers(0, 256, (256, 256, 4), dtype=np.uint8)
        self.tex = ctx.texture((256, 256), 4, img.tobytes())
        self.tex.build_mipmaps()
        self.tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        self.prog = ctx.program(vertex_shader=_FLOOR_VS, fragment_shader=_FLOOR_FS)
        self.vao = ctx.vertex_array(self.prog, [])
        #: each steady() call's settling run: a single floor right after a frame (the method before 2026-11-27)
        self.after_frame: list[float] = []

    def run(self) -> float:
        import moderngl

        t0 = time.perf_counter()
        self.target.use()
        self.target.clear((0.0, 0.0, 0.0, 1.0))
        self.tex.use(0)
        self.ctx.disable(moderngl.DEPTH_TEST)
        self.vao.render(moderngl.TRIANGLE_STRIP, vertices=4)
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.finish()
        self.target.read()
        return (time.perf_counter() - t0) * 1e3

    def steady(self, runs: int = 4) -> float:
        """The floor as every section times it, between its frames: one run to settle (the frame
        before leaves llvmpipe's threads and the caches in its own state), then the median of ``runs``
        back-to-back runs (ms).  The scene section and ``piste render``'s runtime section time their
        floors this same way, so their ratios compare (a single run right after a frame reads
        ~0.3-0.8 ms slower on this machine)."""
        self.after_frame.append(self.run())
        return med([self.run() for _ in range(runs)])

    def release(self):
        for o in (self.vao, self.prog, self.tex):
            o.release()
        self.target.release()


def med(xs) -> float:
    return float(np.median(xs))


def rng_str(xs) -> str:
    return f"{med(xs):7.2f} [{min(xs):.1f}-{max(xs):.1f}]"


# ---------------------------------------------------------------------------------------- terrain
def terrain_section(args, floor_ms: list) -> dict:
    from piste.render import TerrainRenderer
    from piste.world.camera import track_camera
    from piste.world.course import TRACK_HALF_WIDTH, default_course, track_centerline

    net = default_course()
    line = track_centerline()
    size = tuple(args.size)
    t0 = time.perf_counter()
    kw = dict(size=size, track=line, track_half_width=TRACK_HALF_WIDTH)
    r = TerrainRenderer(net, **kw)
    r_plain = TerrainRenderer(net, ctx=r.ctx, lod_morph=False, **kw)
    r_cpu = TerrainRenderer(net, ctx=r.ctx, resident=False, lod_morph=False, **kw)
    floor = Floor(r.ctx, size)
    for rr in (r, r_plain, r_cpu):
        rr.resident_wait = True  # time the steady state, not the first frames' background build
    print(f"GL: {r.ctx.info['GL_RENDERER']}, {size[0]}x{size[1]}; set-up {time.perf_counter() - t0:.2f} s")
    cams = [track_camera(line, t) for t in np.linspace(0.1, 0.9, args.frames)]
    configs = {
        "resident + geomorph (default)": (r, {}),
        "resident, morph off": (r_plain, {}),
        "CPU path (streamed vertices)": (r_cpu, {}),
        "resident, ps2 (2 passes)": (r, dict(lightmap_mode="ps2")),
        "resident, LOD off (all 8x8)": (r, dict(lod=False)),
    }
    for rr, k in configs.values():  # warm-up: shaders, vertex blocks, caches, numba
        rr.render(cams[0], **k)
    floor.run()
    res = {name: [] for name in configs}
    for cam in cams:
        for name, (rr, k) in configs.items():
            res[name].append(rr.render(cam, **k))
        floor_ms.append(floor.steady())
    cols = ("cull", "tessellate", "upload", "cpu", "draw", "readback", "total")
    print(f"\n== terrain, {args.frames} frames down the track (loaded machine: medians [min-max] ms) ==")
    head = f"{'configuration':31s} {'tris':>7s} " + " ".join(f"{c:>10s}" for c in cols) + f" {'fps':>6s} {'x floor':>8s}"
    print(head + "\n" + "-" * len(head))
    fl = med(floor_ms)
    out = {}
    for name, frames in res.items():
        m = {c: med([f.timings[c] for f in frames]) for c in cols}
        tris = int(med([f.triangles for f in frames]))
        out[name] = m
        print(f"{name:31s} {tris:7d} " + " ".join(f"{m[c]:10.2f}" for c in cols) +
              f" {1e3 / m['total']:6.1f} {m['total'] / fl:8.2f}")
    print(f"{'floor (clear + quad + read)':31s} {'':7s} " + " " * 66 + f"{fl:10.2f}")
    a, b, c = out["resident + geomorph (default)"], out["resident, morph off"], out["CPU path (streamed vertices)"]
    print(f"\nresident vs CPU path: CPU side {c['cpu']:.2f} -> {b['cpu']:.2f} ms ({c['cpu'] / max(b['cpu'], 1e-9):.1f}x), "
          f"frame {c['total']:.1f} -> {b['total']:.1f} ms; geomorphing costs {a['total'] - b['total']:+.2f} ms a frame "
          "(a texture fetch per vertex)")
    for o in (r, r_plain, r_cpu, floor):
        o.release()
    record("frame", "terrain frame, default course", "x floor", f"{a['total']:.1f} ms", f"floor {fl:.2f} ms",
           f"{a['total'] / fl:.1f}x")
    record("frame", "terrain CPU side (cull + LOD + index list + upload)", "<= 0.5 ms (+upload)", f"{a['cpu']:.2f} ms",
           f"CPU path {c['cpu']:.2f} ms", f"{c['cpu'] / max(a['cpu'], 1e-9):.1f}x")
    return out


# ---------------------------------------------------------------------------------------- effects
def effects_section(args) -> None:
    """Each renderer change against what it replaced, A/B interleaved on the same frames: the terrain
    shader compiled per mode vs the run-time ``u_mode`` if-chain it replaced, the base texture's
    nearest-mip bilinear vs trilinear filtering, geomorphing on vs off, resident vs streamed."""
    import moderngl

    from piste.render import TerrainRenderer
    from piste.render.context import load_shader
    from piste.world.camera import track_camera
    from piste.world.course import TRACK_HALF_WIDTH, default_course, track_centerline

    net = default_course()
    line = track_centerline()
    kw = dict(size=tuple(args.size), track=line, track_half_width=TRACK_HALF_WIDTH, lod_morph=False)
    new = TerrainRenderer(net, **kw)
    chain = TerrainRenderer(net, ctx=new.ctx, **kw)
    tri = TerrainRenderer(net, ctx=new.ctx, **kw)
    morph = TerrainRenderer(net, ctx=new.ctx, **{**kw, "lod_morph": True})
    stream = TerrainRenderer(net, ctx=new.ctx, **{**kw, "resident": False})
    # the if-chain shader: the same source with the mode as a uniform again
    fs = load_shader("terrain.frag.glsl").replace("const int u_mode = TERRAIN_MODE;", "uniform int u_mode;")
    old = new.ctx.program(vertex_shader=load_shader("terrain.vert.glsl"), fragment_shader=fs)
    old["u_mode"].value = 0
    chain.terrain._programs[chain.terrain._key(0)] = chain.terrain._apply(old)
    tri.terrain.base.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
    for r in (new, chain, tri, morph, stream):
        r.resident_wait = True
    cams = [track_camera(line, t) for t in np.linspace(0.1, 0.9, args.frames)]
    V = {"now (per-mode shader, nearest-mip, resident, morph off)": new,
         "u_mode if-chain (before)": chain, "trilinear base texture (before)": tri,
         "geomorph on": morph, "CPU path, streamed vertices (before)": stream}
    for r in V.values():
        r.render(cams[0])
    res = {k: [] for k in V}
    imgs = {k: [] for k in V}
    for cam in cams:
        for name, r in V.items():
            f = r.render(cam)
            res[name].append(f.timings["total"])
            imgs[name].append(f.image)
    print(f"\n== each change's effect, A/B interleaved over {args.frames} terrain frames (frame ms, median [range]) ==")
    base = med(res[next(iter(V))])
    for name, ts in res.items():
        diff = np.mean([np.abs(a.astype(int) - b).mean() for a, b in zip(imgs[name], imgs[next(iter(V))])])
        print(f"  {name:58s} {rng_str(ts)}  {med(ts) / base:5.2f}x   mean pixel diff {diff:.3f}")
    for name in ("u_mode if-chain (before)", "trilinear base texture (before)", "CPU path, streamed vertices (before)"):
        record("frame", f"effect: {name.replace(' (before)', '')} -> now", "faster", f"{base:.1f} ms",
               f"{med(res[name]):.1f} ms", f"{med(res[name]) / base:.2f}x")
    old.release()
    for r in V.values():
        r.release()


# ---------------------------------------------------------------------------------------- scene
def _profile(r):
    """Wrap each pass of a SceneRenderer with glFinish + timer; returns (accumulator, undo)."""
    ctx = r.ctx
    acc: dict = {}
    wrapped = []

    def wrap(obj, name, label):
        if obj is None:
            return
        fn = getattr(obj, name)

        def w(*a, **k):
            ctx.finish()
            t0 = time.perf_counter()
            out = fn(*a, **k)
            ctx.finish()
            acc.setdefault(label, []).append((time.perf_counter() - t0) * 1e3)
            return out

        setattr(obj, name, w)
        wrapped.append((obj, name))

    wrap(r.shadows, "render_casters", "shadow casters")
    wrap(r.terrain.terrain, "draw", "terrain")
    wrap(r.terrain.sky, "draw", "sky")
    wrap(r.shadows, "draw_receivers", "shadow receivers")
    wrap(r.objects, "draw", "objects")
    for cp in r.cast_passes:
        wrap(cp, "draw", "riders + specular")
    wrap(r.terrain.target, "read", "read-back")

    def undo():
        for obj, name in wrapped:
            delattr(obj, name)

    return acc, undo


def _track_programs(tp):
    """``(key, now, before)``: the terrain's modulate program (the track's distance looked up per
    vertex) and the same shader with the look-up per pixel (what it replaced), or None without a
    track."""
    from piste.render.terrain_pass import _MODE_ID, _with_defines

    key = tp._key(_MODE_ID["modulate"])
    if key[1] != 1:
        return None
    now = tp._program(_MODE_ID["modulate"])
    vs = tp._vs.replace("out float v_track_d;", "out float v_track_d;\nout vec2 v_trk;").replace(
        "    v_kind = in_kind;", "    v_kind = in_kind;\n    v_trk = (p.xy - u_track_rect.xy) * u_track_rect.zw;")
    fs = tp._fs.replace("in float v_track_d;", "in vec2 v_trk;\nuniform sampler2D u_track;").replace(
        "base_color(v_uv, v_track_d)", "base_color(v_uv, texture(u_track, v_trk).r)")
    before = tp.ctx.program(vertex_shader=_with_defines(vs, TERRAIN_TRACK=1),
                            fragment_shader=_with_defines(fs, TERRAIN_MODE=0, TERRAIN_TRACK=1))
    return key, now, before


def _receiver_programs(shadows):
    """``[now, before, {program id: its vertex array}]``: the hard shadows' receiver program (triangles cut to the
    frustum by clip distances, no discard) and the one it replaced (whole triangles, discard
    outside the frustum), for the A/B; None without shadows."""
    if shadows is None:
        return None
    from piste.render.context import load_shader

    vs = "\n".join(line for line in load_shader("shadow_receiver.vert.glsl").splitlines() if "gl_ClipDistance" not in line)
    fs = load_shader("shadow_receiver.frag.glsl").replace(" * (inside ? 1.0 : 0.0);", ";\n    if (!inside) discard;")
    before = shadows.ctx.program(vertex_shader=vs, fragment_shader=fs)
    for name in ("u_shadow", "u_sunlit", "u_sun_rect"):
        before[name].value = shadows.receiver[name].value
    return [shadows.receiver, before, {}]


# the shaders the scene's A/B compares the current ones with (what they replaced)
_SKY_FS_BEFORE = """#version 330 core
// Gradient sky: horizon haze to zenith blue by the view ray's elevation, plus a soft sun glow.
uniform vec3 u_horizon;
uniform vec3 u_zenith;
uniform vec3 u_sun;
in vec3 v_ray;
out vec4 f_color;
void main() {
    vec3 d = normalize(v_ray);
    float h = clamp(d.z, 0.0, 1.0);
    vec3 c = mix(u_horizon, u_zenith, 1.0 - exp(-2.2 * h));
    c = mix(c, u_horizon * 0.9, 1.0 - exp(min(d.z, 0.0) * 3.0));  // a little darker below the horizon
    float s = max(dot(d, u_sun), 0.0);
    float s3 = s * s * s;
    float s24 = s3 * s3;
    s24 *= s24;
    s24 *= s24;  // s^24 by squaring (a pow per pixel costs llvmpipe more)
    c += vec3(1.0, 0.95, 0.85) * (0.25 * s24 + 0.6 * pow(s, 900.0));
    f_color = vec4(min(c, vec3(1.0)), 1.0);
}
"""


class _MipsTexelFetch:
    """The shadow mips' compute pass as it was before it read level ``l`` as an image: ``texelFetch``
    through a sampler at lod ``u_level`` (the same levels; bench A/B only)."""

    def __init__(self, cm):
        from piste.render.context import load_shader

        src = load_shader("mip_levels.comp.glsl")
        old = src.replace("layout(rgba8, binding = 2) readonly uniform image2D u_src;  // level l",
                          "uniform sampler2D u_src;\nuniform int u_level;").replace(
            "imageLoad(u_src, p)", "texelFetch(u_src, p, u_level)")
        assert old != src
        self.cm, self.levels = cm, cm.levels
        self.cs = cm.ctx.compute_shader(old)

    def build(self):
        ctx, tex, cs = self.cm.ctx, self.cm.texture, self.cs
        unit = ctx.default_texture_unit
        tex.use(unit)
        cs["u_src"].value = unit
        for lv, (w, h) in self.cm._steps:
            cs["u_level"].value = lv
            cs["u_size"].value = (w, h)
            tex.bind_to_image(0, read=False, write=True, level=lv + 1)
            tex.bind_to_image(1, read=False, write=True, level=lv + 2)
            cs.run((w + 7) // 8, (h + 7) // 8)
            ctx.memory_barrier(self.cm._barrier)


_TRACK_MATH_BEFORE = """        float w = max(fwidth(d), 1e-4);
        float groomed = 1.0 - smoothstep(u_track_half - 1.0, u_track_half, ad);
        c *= mix(vec3(1.0), vec3(0.95, 0.97, 1.0), groomed);  // groomed snow: a little cooler
        float hw = 0.3;
        float line = clamp((hw - abs(ad - u_track_half)) / w + 0.5, 0.0, 1.0) * min(1.0, 2.0 * hw / w);
"""


def _track_math_programs(tp):
    """``(key, now, before)``: the terrain's modulate program and the same with the track's groomed
    tint and dye lines as they were written before (a smoothstep and two divisions a pixel), or
    None without a track."""
    from piste.render.terrain_pass import _MODE_ID, _with_defines

    key = tp._key(_MODE_ID["modulate"])
    if key[1] != 1:
        return None
    fs = tp._fs
    a = fs.index("        // (one division a pixel")
    b = fs.index("        c = mix(c, vec3(0.18, 0.32, 0.85), 0.85 * line);")
    before = tp.ctx.program(vertex_shader=_with_defines(tp._vs, TERRAIN_TRACK=1),
                            fragment_shader=_with_defines(fs[:a] + _TRACK_MATH_BEFORE + fs[b:], TERRAIN_MODE=0,
                                                          TERRAIN_TRACK=1))
    return key, tp._program(_MODE_ID["modulate"]), before


def _sky_programs(sky):
    """``set(on)`` for the A/B: the sky pass's program (now) or the one it replaced (two exps and a
    pow(s, 900) at every sky pixel), each with its own vertex array."""
    from piste.render.context import load_shader

    before = sky.ctx.program(vertex_shader=load_shader("sky.vert.glsl"), fragment_shader=_SKY_FS_BEFORE)
    for name in ("u_horizon", "u_zenith", "u_sun"):
        before[name].value = sky.prog[name].value
    progs = {True: (sky.prog, sky.vao), False: (before, sky.ctx.vertex_array(before, []))}

    def set_sky(on):
        sky.prog, sky.vao = progs[on]

    return set_sky


def _terrain_fragment_costs(r, one, rounds: int) -> tuple[dict, dict]:
    """What the terrain's pixels cost: its pass (glFinish around it) with the modulate program as it
    is and with one part of its fragment shader taken out (a constant colour; no track; no light-map
    fetch; no base-texture fetch), interleaved round by round with the order rotated; and the
    fragments that pass the depth test (an occlusion query) in the terrain and sky passes, in
    screens: the terrain's overdraw, and where the sky shades.  ``({variant: [ms]}, {pass: [screens]})``."""
    from piste.render.terrain_pass import _MODE_ID, _with_defines

    tp = r.terrain.terrain
    key = tp._key(_MODE_ID["modulate"])
    now = tp._program(_MODE_ID["modulate"])
    fs = tp._fs
    cuts = {"a constant colour": fs.replace("f_color = vec4(c, 1.0);", "f_color = vec4(0.5, 0.6, 0.7, 1.0);"),
            "no light-map fetch": fs.replace("* texture(u_light, v_uvl).rgb", "* vec3(v_uvl, 1.0)"),
            "no base-texture fetch": fs.replace("vec3 c = texture(u_base, uv).rgb;", "vec3 c = vec3(0.9, 0.9, uv.x);")}
    if key[1] == 1:
        cuts["no track"] = fs.replace("base_color(v_uv, v_track_d)", "texture(u_base, v_uv).rgb")
    progs = {"as drawn": now}
    for name, f in cuts.items():
        if f == fs:
            continue  # (the shader changed: this cut no longer applies)
        progs[name] = tp._apply(tp.ctx.program(vertex_shader=_with_defines(tp._vs, TERRAIN_TRACK=key[1]),
                                                fragment_shader=_with_defines(f, TERRAIN_MODE=0, TERRAIN_TRACK=key[1])))
    acc, undo = _profile(r)
    times: dict = {name: [] for name in progs}
    names = list(progs)
    try:
        for i in range(rounds):
            for name in names[i % len(names):] + names[:i % len(names)]:
                tp._programs[key] = progs[name]
                acc.clear()
                one(i / 30.0)
                times[name].append(acc["terrain"][0])
    finally:
        tp._programs[key] = now
        undo()
        for name, p in progs.items():
            if p is not now:
                p.release()
    # fragments passing the depth test, per pass (the sky: depth LEQUAL against the cleared 1.0)
    ctx = r.ctx
    screens: dict = {}
    wrapped = []
    for label, obj in (("terrain", tp), ("sky", r.terrain.sky)):
        fn = obj.draw

        def w(*a, fn=fn, label=label, **k):
            q = ctx.query(samples=True)
            with q:
                out = fn(*a, **k)
            screens.setdefault(label, []).append(q.samples / float(np.prod(r.terrain.size)))
            return out

        obj.draw = w
        wrapped.append(obj)
    try:
        for i in range(3):
            one(i / 30.0)
    finally:
        for obj in wrapped:
            del obj.draw
    return times, screens


def scene_section(args, floor_ms: list) -> dict:
    from piste.render.scene_renderer import summarize_scene

    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.default_scene import build_default_scene
    from piste.pipeline.preview import ScenePreview

    # what `piste demo` draws: the built-in default scene's bundle (built once into the cache: light
    # map, visibility sets), its riders following the track and its objects, through ScenePreview
    bundle = load_bundle(build_default_scene(0, progress=False).path)
    t0 = time.perf_counter()
    preview = ScenePreview(bundle, size=tuple(args.size), object_lighting="dynamic")
    r = preview.renderer
    r.terrain.resident_wait = True
    floor = Floor(r.ctx, tuple(args.size))
    print(f"\nscene set-up (bundle -> riders + LODs, objects, GL, shaders): {time.perf_counter() - t0:.2f} s")

    def one(t, shadows=True, specular=True):
        sh, sp = r.shadows, r.specular
        try:
            if not shadows:
                r.shadows = None
            r.specular = specular
            return r.render(t, read=True)
        finally:
            r.shadows, r.specular = sh, sp

    configs = {"full scene": dict(), "no shadows": dict(shadows=False), "no specular": dict(specular=False)}
    for kw in configs.values():
        one(0.0, **kw)
    ims = {name: [] for name in configs}
    for i in range(args.frames):
        for name, kw in configs.items():
            im = one(i / 30.0, **kw)
            im.image = None
            ims[name].append(im)
        floor_ms.append(floor.steady())
    # per-pass profile (extra glFinish calls: the sum is a little above the plain frame)
    acc, undo = _profile(r)
    prof_total = []
    for i in range(max(args.frames // 2, 3)):
        t1 = time.perf_counter()
        one(i / 30.0)
        prof_total.append((time.perf_counter() - t1) * 1e3)
    undo()
    # A/B, each change against what it replaced (on its own pass, interleaved frame by frame):
    # * objects: programs compiled per (lighting mode, light_only), instance data as per-instance
    #   attributes, no alpha test when no texel is below its cutoff, vs the one program with run-time
    #   uniforms and the instance texture;
    # * terrain: back-facing triangles culled vs drawn
    def set_objects(on):
        r.objects.specialised = on

    def set_cull(on):
        r.terrain.terrain.cull_back = on

    lod_now = r.objects.lod_pixels if r.objects is not None else 0.0  # the scene's setting (the default)

    def set_object_lod(on):
        r.objects.lod_pixels = lod_now if on else 0.0

    def set_object_lod_1px(on):  # (lod_now restored after its A/B)
        r.objects.lod_pixels = 1.0 if on else 0.5

    errors_now = r.objects.lod_errors.copy() if r.objects is not None else None
    errors_four = None
    if errors_now is not None and errors_now.shape[1] > 4:
        errors_four = errors_now.copy()
        errors_four[:, 4:] = np.inf  # (inf: a level no instance takes)

    def set_object_lod_levels(on):
        r.objects.lod_errors = errors_now if on else errors_four

    def set_visibility(on):
        r.terrain.set_visibility(bundle.visibility if on else None)

    rider_px = [c.lod_pixels for c in r.casts]  # every model's scene: its riders' LOD rule (1 px)

    def set_rider_lod(on):  # (0 px: the distance rule, Scene.lod_distances)
        for c, px in zip(r.casts, rider_px):
            c.lod_pixels = px if on else 0.0

    compute_mips = getattr(r.shadows, "_mips_cs", None)
    receivers = _receiver_programs(r.shadows)

    def set_receiver_clip(on):
        r.shadows.resident_receivers = False  # (both programs on the gathered vertices: set_resident_receivers)
        prog, cur = receivers[0] if on else receivers[1], r.shadows.receiver
        if prog is not cur:  # (each program its own vertex array)
            receivers[2][id(cur)] = r.shadows._recv
            r.shadows._recv = receivers[2].get(id(prog), {"pos": None, "idx": None, "vao": None})
            r.shadows.receiver = prog
    def set_resident_receivers(on):
        r.shadows.resident_receivers = on

    track_progs = _track_programs(r.terrain.terrain)
    track_math = _track_math_programs(r.terrain.terrain)

    def set_track_math(on):
        if track_math is not None:
            key, now, before = track_math
            r.terrain.terrain._programs[key] = now if on else r.terrain.terrain._apply(before)

    def set_track_per_vertex(on):
        if track_progs is not None:
            key, now, before = track_progs
            r.terrain.terrain._programs[key] = now if on else r.terrain.terrain._apply(before)

    def set_compute_mips(on):
        r.shadows._mips_cs = compute_mips if on else None

    mips_fetch = _MipsTexelFetch(compute_mips) if compute_mips is not None else None

    def set_mips_image(on):
        r.shadows._mips_cs = compute_mips if on else mips_fetch

    def set_cull_casters(on):
        r.shadows.cull_casters = on

    set_sky = _sky_programs(r.terrain.sky)

    def set_cone_cull(on):  # (on: the default, every patch sent)
        r.terrain.terrain.cull_back_patches = not on

    flat_now = r.terrain.lod_kwargs.get("flat_error")  # the renderer's (frame.LOD_ERROR_PX: 1 px)

    def set_flat(on):
        r.terrain.lod_kwargs["flat_error"] = flat_now if on else None

    def set_flat_1px(on):
        from piste.terrain.lod import FLAT_ERROR

        r.terrain.lod_kwargs["flat_error"] = flat_now if on else FLAT_ERROR

    changes = [("objects", set_objects, "objects: per-mode programs, instance attributes, no discard",
                "objects: one program, 14 texelFetch a vertex, u_mode + discard"),
               ("objects", set_object_lod, "objects: levels of detail, as the scene sets them",
                "objects: every instance with its full mesh"),
               ("objects", set_object_lod_1px, "objects: levels of detail, <= 1 px of error",
                "objects: levels of detail, <= 0.5 px of error"),
               ("riders + specular", set_rider_lod, "riders: levels by projected error, <= 1 px (both passes)",
                "riders: levels by distance to the eye (14 / 35 m)"),
               ("objects", set_object_lod_levels, "objects: up to 6 levels a kind (rocks down to 10 triangles)",
                "objects: up to 4 levels a kind"),
               ("terrain", set_cull, "terrain: back faces culled", "terrain: back faces drawn"),
               ("terrain", set_cone_cull, "terrain: every visible patch sent (the default)",
                "terrain: wholly back-facing patches left out (normal cones, off)"),
               ("terrain", set_flat, "terrain: edges flat (2 corners) or coarsest where under 1 px",
                "terrain: levels by distance alone (4 a side at the coarsest)"),
               ("terrain", set_flat_1px, "terrain: edges flat or coarsest where under 1 px (the default)",
                "terrain: ... where under 0.5 px (the terrain core's FLAT_ERROR)"),
               ("terrain", set_visibility, "terrain: the bundle's visibility sets", "terrain: frustum culling alone"),
               ("shadow casters", set_mips_image, "shadow mips: level l read as an image (imageLoad)",
                "shadow mips: level l read by texelFetch through a sampler"),
               ("shadow casters", set_compute_mips, "shadow mips: two levels a compute dispatch",
                "shadow mips: a framebuffer (and a rasterizer wait) per level"),
               ("shadow casters", set_cull_casters, "casters closed (holes capped), back faces culled",
                "casters: every triangle, both sides"),
               ("terrain", set_track_per_vertex, "terrain: track distance looked up per vertex",
                "terrain: track distance looked up per pixel"),
               ("terrain", set_track_math, "terrain: the track's tint and dye lines with one division a pixel",
                "terrain: ... a smoothstep and two divisions a pixel"),
               ("shadow receivers", set_receiver_clip, "receivers cut to the shadow frustum (clip distances)",
                "receivers: whole triangles, discard outside the frustum"),
               ("shadow receivers", set_resident_receivers, "receivers: the terrain's resident blocks by index",
                "receivers: vertices gathered, morphed, box-culled on the CPU, uploaded"),
               ("sky", set_sky, "sky: one exp a pixel, the sun's glow by squaring near the sun",
                "sky: two exps and pow(s, 900) a pixel")]
    # an upper bound, not a change: the objects pass with the instances whose bounding sphere projects
    # under 8 px of radius left out altogether (what impostors for far objects could save at most)
    far_cut = {"px": 0.0}
    if r.objects is not None:
        draw_objects = r.objects.draw  # (the instance attribute: _profile below wraps this, its undo removes both)

        def _draw_near(vp, eye, visible=None, *a, **k):
            ob = r.objects
            if far_cut["px"] > 0.0:
                vis = np.arange(len(ob.objects)) if visible is None else np.asarray(visible, dtype=np.int64)
                m = np.asarray(vp, dtype=np.float64)
                depth = np.maximum(ob.objects.center[vis] @ m[3, :3] + m[3, 3], 1e-3)
                rad_px = np.linalg.norm(m[1, :3]) * 0.5 * args.size[1] * ob.objects.radius[vis] * ob.scale[vis] / depth
                visible = vis[rad_px >= far_cut["px"]]
            return draw_objects(vp, eye, visible, *a, **k)
        r.objects.draw = _draw_near

    def set_far_cut(on):
        far_cut["px"] = 0.0 if on else 8.0

    changes.append(("objects", set_far_cut, "objects: every visible instance drawn",
                    "bound: instances under 8 px of bounding radius left out (impostors' most)"))
    ab_res = []
    acc2, undo2 = _profile(r)
    for label, setter, now_name, before_name in changes:
        if label == "objects" and r.objects is None or label == "shadow casters" and (
                r.shadows is None or r.shadows.soft or compute_mips is None and setter is not set_cull_casters) \
                or setter is set_track_per_vertex and track_progs is None \
                or setter is set_track_math and track_math is None \
                or setter is set_object_lod_levels and errors_four is None or label == "shadow receivers" and \
                (r.shadows is None or r.shadows.soft):
            continue
        ab = {True: [], False: []}
        ab_frame = {True: [], False: []}
        ab_diff = []
        for i in range(max(args.frames // 2, 3)):
            pair = {}
            for on in ((True, False) if i % 2 == 0 else (False, True)):  # the order alternated
                setter(on)
                acc2.clear()
                t1 = time.perf_counter()
                pair[on] = one(i / 30.0).image
                ab_frame[on].append((time.perf_counter() - t1) * 1e3)
                # (the riders' pass: its base and specular draws together)
                ab[on].append(sum(acc2[label]) if label == "riders + specular" else acc2[label][0])
            d = np.abs(pair[True].astype(int) - pair[False].astype(int)).max(-1)
            ab_diff.append((int(d.max()), int((d > 0).sum())))
        setter(True)
        if r.objects is not None:
            r.objects.lod_pixels = lod_now  # (the 1 px A/B leaves the scene's own setting)
        ab_res.append((label, now_name, before_name, ab, ab_frame, ab_diff))
    undo2()
    # whole frames (no per-pass syncs: what they change is when llvmpipe rasterizes), interleaved frame
    # by frame, the order alternated: the terrain flushed to the rasterizer threads as soon as it is
    # issued (they fill it while this thread issues the receivers, objects and riders) vs everything
    # rasterized at the frame's end
    frame_ab = {True: [], False: []}
    frame_cpu = {True: [], False: []}
    for i in range(max(args.frames, 6) * 2):
        for on in ((True, False) if i % 2 == 0 else (False, True)):
            r.terrain.flush_early = on
            c1, t1 = time.process_time(), time.perf_counter()
            one(i / 30.0)
            frame_ab[on].append((time.perf_counter() - t1) * 1e3)
            frame_cpu[on].append((time.process_time() - c1) * 1e3)
    r.terrain.flush_early = True
    frag_times, frag_screens = _terrain_fragment_costs(r, one, max(args.frames // 2, 5))
    # one frame at a time (render: plan, draw, wait, read) against pipelined frames (frames: the next
    # frame planned while the GL draws this one), wall time per frame over blocks of 10, interleaved
    # and the GL work alone: each frame planned first (untimed, then glFinish), then issued, waited for
    # and read back -- what no change to piste's CPU side (planning, culling, skinning, LOD) can go under
    modes = {"one at a time": [], "pipelined": [], "GL work alone": []}

    def one_at_a_time(ts):
        for t in ts:
            r.render(t)

    def pipelined(ts):
        for _ in r.frames(ts):
            pass

    def gl_alone(ts) -> float:
        spent = 0.0
        for t in ts:
            plan = r._plan(t)
            r.ctx.finish()
            t1 = time.perf_counter()
            r._issue(plan)
            r._finish(plan, True)
            spent += time.perf_counter() - t1
        return spent

    for b in range(max(args.frames // 5, 3)):
        ts = [(b * 10 + i) / 30.0 for i in range(10)]
        names = list(modes)
        for j in range(len(names)):  # the order rotated every block
            name = names[(b + j) % len(names)]
            t1 = time.perf_counter()
            if name == "GL work alone":
                spent = gl_alone(ts)
            else:
                (one_at_a_time if name == "one at a time" else pipelined)(ts)
                spent = time.perf_counter() - t1
            modes[name].append(spent * 1e3 / len(ts))
    cols = ("animation", "lod_skinning", "lights", "objects", "terrain_cull", "tessellate", "shadow_cull", "cpu",
            "upload", "terrain_draw", "scene_draw", "readback", "total")
    short = ("anim", "skin", "lights", "objcull", "t.cull", "t.index", "shadcull", "CPU", "upload", "terrain", "scene",
             "read", "frame")
    fl = med(floor_ms)
    print(f"\nfloor (Floor.steady) {rng_str(floor_ms)} ms; a single floor right after a frame (the settling runs, "
          f"the method before 2026-11-27) {rng_str(floor.after_frame)} ms")
    print(f"\n== completed scene, {args.frames} frames (t = i / 30 s), medians ms (loaded machine) ==")
    head = f"{'configuration':14s} " + " ".join(f"{c:>8s}" for c in short) + f" {'fps':>6s} {'x floor':>8s}"
    print(head + "\n" + "-" * len(head))
    out = {}
    for name, lst in ims.items():
        m = {k: med([im.timings.get(k, 0.0) for im in lst]) for k in cols}
        out[name] = m
        print(f"{name:14s} " + " ".join(f"{m[c]:8.2f}" for c in cols) + f" {1e3 / m['total']:6.1f} {m['total'] / fl:8.2f}")
    full = summarize_scene(ims["full scene"])
    m = out["full scene"]
    print("(upload: the terrain's index list and morph factors, the riders' skinned vertices, and the whole shadow "
          "caster pass, whose data are only the casters' low-LOD vertices (~31 kB for six riders): its time is the "
          "casters' draws, their rasterization, which the mips' compute dispatch waits for, and the mips)")
    print(f"\nper pass (glFinish around each; frame {med(prof_total):.1f} ms with the extra syncs):")
    for label, ts in sorted(acc.items(), key=lambda kv: -med(kv[1])):
        print(f"  {label:18s} {rng_str(ts)} ms  ({100 * med(ts) / med(prof_total):4.1f} %)")
    print(f"\n== the terrain's pixels: its pass with a part of its fragment shader taken out, {len(frag_times['as drawn'])} "
          "rounds interleaved, order rotated (ms, median [range]) ==")
    base_ms = med(frag_times["as drawn"])
    for name, ts in frag_times.items():
        print(f"  {name:24s} {rng_str(ts)} ms  ({med(ts) - base_ms:+5.2f} ms)")
    print("  fragments passing the depth test, in screens: " + ", ".join(
        f"{label} {med(v):.2f}" for label, v in frag_screens.items()) + " (terrain + sky = 1: no overdraw to save)")
    if ab_res:
        print("\n== each change's effect on its pass, A/B interleaved over the scene frames (ms, median [range]; "
              "frames with the per-pass syncs) ==")
    for label, now_name, before_name, ab, ab_frame, ab_diff in ab_res:
        for on, name in ((True, now_name + " (now)"), (False, before_name + " (before)")):
            print(f"  {name:68s} {label} {rng_str(ab[on])}  {med(ab[on]) / med(ab[True]):5.2f}x   "
                  f"frame {rng_str(ab_frame[on])}")
        print(f"    pixels: max difference {max(x[0] for x in ab_diff)} (of 255), at most "
              f"{max(x[1] for x in ab_diff)} pixels a frame differ")
        if before_name.startswith("bound:"):
            continue
        record("frame", f"effect: {before_name} -> {now_name}", "faster", f"{med(ab[True]):.1f} ms",
               f"{med(ab[False]):.1f} ms", f"{med(ab[False]) / med(ab[True]):.2f}x")
    print("\n== whole frames, A/B interleaved frame by frame (ms, median [range]; CPU: every thread's, llvmpipe's too) ==")
    for on, name in ((True, "terrain flushed to the rasterizer once issued (now)"),
                     (False, "everything rasterized at the frame's end (before)")):
        print(f"  {name:56s} frame {rng_str(frame_ab[on])}  {med(frame_ab[on]) / med(frame_ab[True]):5.2f}x   "
              f"CPU {rng_str(frame_cpu[on])}")
    print("\n== one frame at a time vs pipelined (wall time a frame over blocks of 10 frames, interleaved) ==")
    for name, ts in modes.items():
        print(f"  {name:14s} {rng_str(ts)} ms  ({1e3 / med(ts):5.1f} fps, {med(ts) / fl:5.2f}x the floor)")
    print(f"  pipelined / one at a time: {med(modes['pipelined']) / med(modes['one at a time']):.2f}x; the GL work "
          f"alone is {med(modes['GL work alone']) / med(modes['one at a time']):.2f}x a whole frame")
    best = min(med(modes["pipelined"]), med(modes["one at a time"]))
    glw = med(modes["GL work alone"])
    record("frame", "completed scene: its GL work alone (a planned frame issued, waited for, read back) vs machine "
           "floor", "(bound)", f"{glw:.1f} ms", f"floor {fl:.2f} ms", f"{glw / fl:.1f}x", None)
    print(f"\nfull scene: {full['rider_triangles']:.0f} rider + {full['object_triangles']:.0f} object + "
          f"{full['terrain_triangles']:.0f} terrain triangles, {full['objects_drawn']:.0f} objects")
    print(f"target 60 fps = 16.7 ms: {best:.1f} ms a frame, the faster of the two ({1e3 / best:.1f} fps, "
          f"{'met' if best <= 16.7 else 'missed'}); CPU side {m['cpu']:.2f} ms (target <= 4: "
          f"{'met' if m['cpu'] <= 4.0 else 'missed'}); {best / fl:.1f}x the floor ({fl:.2f} ms; target <= 4x: "
          f"{'met' if best <= 4 * fl else 'missed'})")
    record("frame", "completed scene fps (640x448, llvmpipe)", ">= 60 fps", f"{1e3 / best:.1f} fps",
           f"pipelined {1e3 / med(modes['pipelined']):.1f}, one at a time {1e3 / med(modes['one at a time']):.1f}",
           "", best <= 16.7)
    record("frame", "completed scene CPU side", "<= 4 ms", f"{m['cpu']:.2f} ms", "", "", m["cpu"] <= 4.0)
    record("frame", "completed scene vs machine floor", "<= 4x", f"{best:.1f} ms", f"floor {fl:.2f} ms",
           f"{best / fl:.1f}x", best <= 4 * fl)
    floor.release()
    preview.release()
    return out


# ---------------------------------------------------------------------------------------- piste render
RENDER_SCENE = Path(__file__).resolve().parents[1] / "examples" / "scenes" / "default.toml"


def render_runtime_section(args, camera: str = "flight") -> dict:
    """``examples/scenes/default.toml`` through ``piste render``'s runtime, against the floor.

    The command's code path (:func:`piste.commands.render.run`): the scene built with the step cache
    beside it (``.piste-cache``; only the bundle goes to a temporary folder, not beside the scene
    file where other processes may read it) and loaded with its terrain warming, as
    :func:`piste.pipeline.open_scene.open_source` does for a ``.toml``; then
    :func:`piste.pipeline.preview.render_frames`' objects: one :class:`ScenePreview` with the
    options the command passes by default (the scene's size unless ``--size``, no trace, AA, DOF,
    soft shadows or occlusion flags) and, frame ``i`` of ``n``, ``camera_at(bundle, camera, i, n)``
    at ``t = i / 30`` (``--fps 30``), the frame read back.  ``render_frames`` makes its own context and
    loops over every frame itself, so its loop body is called here instead, in the preview's context,
    interleaved frame by frame with the :class:`Floor`.  The per-pass split: the renderer's own
    timings (no extra syncs), then a few frames with ``glFinish`` around each pass (:func:`_profile`)."""
    import tempfile

    from piste.pipeline.build import build_scene
    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.preview import ScenePreview, camera_at

    size = tuple(args.size)
    n = args.frames
    tmp = tempfile.TemporaryDirectory()  # (kept until the runtime is released)
    t0 = time.perf_counter()
    built = build_scene(RENDER_SCENE, out=Path(tmp.name) / "default.piste", progress=False)
    t_build = time.perf_counter() - t0
    t0 = time.perf_counter()
    bundle = load_bundle(built.path, warm=True)
    p = ScenePreview(bundle, size=size, lod_morph=None, aa=None, supersample=1, trace=None, dof=None,
                     soft_shadows=None, occlusion=None)
    floor = Floor(p.ctx, size)
    print(f"\n{RENDER_SCENE.relative_to(RENDER_SCENE.parents[2])}: build (step cache) {t_build:.2f} s, "
          f"load + runtime set-up {time.perf_counter() - t0:.2f} s")
    if p.renderer is not None:
        p.renderer.terrain.resident_wait = True  # the steady state, not the first frames' background build
    else:
        p.terrain.resident_wait = True

    def frame(i):
        t1 = time.perf_counter()
        p.render(camera_at(bundle, camera, i, n), i / 30.0)  # render_frames' loop body (fps 30, read back)
        return (time.perf_counter() - t1) * 1e3

    frame(0)  # warm-up: shaders, vertex blocks, caches
    floor.run()
    ms, fl_ms, timings = [], [], []
    for i in range(n):  # interleaved frame by frame, the order alternated
        if i % 2:
            fl_ms.append(floor.steady())
            ms.append(frame(i))
        else:
            ms.append(frame(i))
            fl_ms.append(floor.steady())
        timings.append(dict(getattr(p.frame, "timings", {}) or {}))
    fl = med(fl_ms)
    fm = med(ms)
    what = f"{size[0]}x{size[1]}, --camera {camera}, {n} frames"
    print(f"== {RENDER_SCENE.name} through `piste render`'s runtime ({what}), interleaved with the floor "
          f"frame by frame (ms, median [min-max]) ==")
    print(f"  frame  {rng_str(ms)} ms  {1e3 / fm:6.1f} fps  {fm / fl:5.2f}x the floor")
    print(f"  floor  {rng_str(fl_ms)} ms  (Floor.steady: one settling run, then the median of 4, between frames, "
          f"as in the scene section; the settling runs, right after a frame: {rng_str(floor.after_frame)} ms)")
    cols = [c for c in ("cpu", "upload", "terrain_draw", "scene_draw", "readback", "total") if all(c in t for t in timings)]
    if cols:
        print("  the renderer's own split (medians ms): " + ", ".join(f"{c} {med([t[c] for t in timings]):.2f}"
                                                                  for c in cols))
    if p.renderer is not None:  # per pass, as the scene section profiles it (glFinish around each: a few extra frames)
        acc, undo = _profile(p.renderer)
        prof = []
        for i in range(max(n // 2, 3)):
            prof.append(frame(i))
        undo()
        print(f"  per pass (glFinish around each; frame {med(prof):.1f} ms with the extra syncs): " + ", ".join(
            f"{label} {med(ts):.2f}" for label, ts in sorted(acc.items(), key=lambda kv: -med(kv[1]))))
    record("frame", "examples/scenes/default.toml via piste render's runtime vs machine floor", "<= 4x",
           f"{fm:.1f} ms ({1e3 / fm:.0f} fps; {what})", f"floor {fl:.2f} ms", f"{fm / fl:.1f}x", fm <= 4 * fl)
    floor.release()
    p.release()
    tmp.cleanup()
    return {"frame": fm, "floor": fl}


# ---------------------------------------------------------------------------------------- scaling
def scaling_section(args) -> None:
    from piste.render import TerrainRenderer
    from piste.render.context import create_context
    from piste.render.scene_renderer import SceneRenderer
    from piste.character import default_rider
    from piste.world.camera import Camera
    from piste.world.course import default_course, track_centerline
    from piste.world.riders import pack_for
    from piste.world.scene import Scene

    sys.path.insert(0, str(Path(__file__).parent))
    from bench_terrain import FAR, grid_of

    frames = max(args.frames // 2, 4)
    print(f"\n== scaling: patches (far plane {FAR:.0f} m caps the visible set; unlit), {frames} frames each, "
          f"the sizes interleaved frame by frame (order rotated) ==")
    print(f"{'patches':>8s} {'visible':>8s} {'tris':>8s} {'CPU side':>10s} {'frame':>10s}")
    rows = []
    sizes = (2560, 10_000) if args.quick else (2560, 10_000, 40_000)
    setups = []
    ctx = create_context()  # one GL context for every renderer (frames interleaved between them)
    for n in sizes:
        net = default_course() if n == 2560 else grid_of(n)
        lo, hi = net.patch_bounds
        if n == 2560:
            tr = track_centerline()
            cams = [Camera(tr[i] + [0.0, 0.0, 4.0], tr[min(i + 40, len(tr) - 1)], far=FAR)
                    for i in np.linspace(len(tr) // 10, len(tr) // 2, frames).astype(int)]
        else:
            xm = float((lo[:, 0].min() + hi[:, 0].max()) / 2)
            y0, z = float(lo[:, 1].min()), float(hi[:, 2].max())
            cams = [Camera([xm + dx, y0 - 20.0, z + 30.0], [xm + dx, y0 + 400.0, z - 20.0], far=FAR)
                    for dx in np.linspace(-50, 50, frames)]
        r = TerrainRenderer(net, size=tuple(args.size), lightmap=None, ctx=ctx)
        r.resident_wait = True
        r.render(cams[0])  # warm-up (and the resident blocks built)
        setups.append((n, r, cams, []))
    for i in range(frames):  # interleaved frame by frame, the order rotated
        k0 = i % len(setups)
        for n, r, cams, fs in setups[k0:] + setups[:k0]:
            fs.append(r.render(cams[i]))
    for n, r, cams, fs in setups:
        r.release()
        row = (n, med([f.patches for f in fs]), med([f.triangles for f in fs]), med([f.timings["cpu"] for f in fs]),
               med([f.timings["total"] for f in fs]))
        rows.append(row)
        print(f"{row[0]:8d} {row[1]:8.0f} {row[2]:8.0f} {row[3]:10.2f} {row[4]:10.2f}")
    ns = [r_[0] for r_ in rows]
    print(f"fitted exponent: CPU side n^{fit_exponent(ns, [r_[3] for r_ in rows]):.2f}, frame "
          f"n^{fit_exponent(ns, [r_[4] for r_ in rows]):.2f}")

    print(f"\n== scaling: riders (the completed scene), {frames} frames each, interleaved frame by frame (order "
          f"rotated) ==")
    print(f"{'riders':>8s} {'CPU side':>10s} {'anim':>8s} {'skin':>8s} {'frame':>10s}")
    model = default_rider(0)
    rrows = []
    setups = []
    for k in ((6, 24) if args.quick else (6, 24, 96)):
        scene = Scene.default(0, model=model, pack=pack_for(model, k, spacing=max(2.0, 48.0 / k)))
        r = SceneRenderer(scene, size=tuple(args.size), ctx=ctx)
        r.terrain.resident_wait = True
        r.render(0.0)  # warm-up
        setups.append((k, r, []))
    for i in range(frames):  # interleaved frame by frame, the order rotated
        j0 = i % len(setups)
        for k, r, ims in setups[j0:] + setups[:j0]:
            ims.append(r.render(i / 30.0))
    for k, r, ims in setups:
        r.release()
        row = (k, med([im.timings["cpu"] for im in ims]), med([im.timings["animation"] for im in ims]),
               med([im.timings["lod_skinning"] for im in ims]), med([im.timings["total"] for im in ims]))
        rrows.append(row)
        print(f"{row[0]:8d} {row[1]:10.2f} {row[2]:8.2f} {row[3]:8.2f} {row[4]:10.2f}")
    ks = [r_[0] for r_ in rrows]
    kc = fit_exponent(ks, [r_[1] for r_ in rrows])
    print(f"fitted exponent: CPU side n^{kc:.2f} (target <= 1), frame n^{fit_exponent(ks, [r_[4] for r_ in rrows]):.2f}")
    record("frame", "riders: CPU side scaling exponent", "<= 1 (linear)", f"n^{kc:.2f}", "", "", kc <= 1.05)
    ctx.release()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="8 frames, smaller scaling tables")
    ap.add_argument("--frames", type=int, help="frames per configuration (default 30, quick 8)")
    ap.add_argument("--size", type=int, nargs=2, default=(640, 448))
    ap.add_argument("--scene", action="store_true", help="only the completed scene (no terrain-only or scaling runs)")
    ap.add_argument("--no-scaling", action="store_true", help="skip the scaling tables")
    ap.add_argument("--render-only", action="store_true",
                    help="only examples/scenes/default.toml through `piste render`'s runtime vs the floor")
    args = ap.parse_args(argv)
    args.frames = args.frames or (8 if args.quick else 30)
    from piste import _jit

    _jit.warm_up()  # compile / load the numba kernels before timing (else the first frames run numpy)
    floor_ms: list = []
    if not (args.scene or args.render_only):
        terrain_section(args, floor_ms)
        effects_section(args)
    if not args.render_only:
        scene_section(args, floor_ms)
    render_runtime_section(args)
    if not (args.scene or args.render_only or args.no_scaling):
        scaling_section(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
