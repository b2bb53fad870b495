"""Build benchmark: the default scene (examples/scenes/default.toml) built cold and warm, and loaded.

    python benchmarks/bench_build.py [--jobs N] [--no-render] [--quick] [--bundle B.piste [--runs N]]
                                     [--baseline-src DIR]

Prints the build time per step cold (empty cache) and warm (every step cached, the bundle rewritten
byte-identical), the bundle's size, the time to load it (``load_bundle``) and to the first frame
(load + renderer set-up + one rendered frame, headless), and the visibility report (% of patches drawn
with frustum culling alone vs with the pre-computed visibility sets, along the track), and the
time from bundle to first frame in a fresh process (imports, GL context, load, set-up, frame:
median of 5 runs with the byte code cached, as installed, and from source), also with an empty
Mesa shader cache (a machine's first run: llvmpipe compiles every shader; later processes load them
from ``~/.cache/mesa_shader_cache``), against its peer, interleaved (order rotated) and timed the
same way: a fresh process that opens an EGL context, draws one textured quad at 640x448 and reads
it back (target: the bundle's first frame <= 1.5x that process), with moderngl's usual call and, the
stricter peer the target is judged against, with its GL libraries named as piste's context names them.
``--quick``: one (cold) build, one fresh-process run.  ``--bundle B.piste``: only the fresh-process
runs, on that bundle (no build), ``--runs`` of them.  ``--baseline-src DIR``: another copy of piste's
sources (e.g. ``git archive REV src | tar -x -C /tmp/base``, then ``/tmp/base/src``) timed the same way
in the same rounds (its own fresh process, ``PYTHONPATH=DIR``, the order rotated with the others): the
before/after of a change, interleaved, with the per-round ratio.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _timing import record  # noqa: E402

SCENE = Path(__file__).resolve().parents[1] / "examples" / "scenes" / "default.toml"

_FRESH = """
import sys, threading, time
t0 = time.perf_counter()
done = {}
run = threading.Thread.run
def timed_run(self):  # when each background thread (the resident vertex blocks) finishes
    try:
        run(self)
    finally:
        done[self.name] = time.perf_counter()
threading.Thread.run = timed_run
import numpy, moderngl  # (what the peer imports too: timed apart, the same modules either way)
tn = time.perf_counter()
from piste.pipeline.bundle_objects import load_bundle
from piste.pipeline.preview import ScenePreview, camera_at
from piste.render.context import create_context
import moderngl
drawn = set()  # the programs the first frame draws with (llvmpipe compiles each at its first draw)
_draw = moderngl.VertexArray.render
def counted_draw(self, *a, **k):
    drawn.add(self.program.glo)
    return _draw(self, *a, **k)
moderngl.VertexArray.render = counted_draw
t1 = time.perf_counter()
ctx = create_context()
t2 = time.perf_counter()
b = load_bundle(sys.argv[1], warm=True)  # as piste render / demo / view load it
t3 = time.perf_counter()
p = ScenePreview(b, size=(640, 448), ctx=ctx)
t4 = time.perf_counter()
p.render(camera_at(b, "flight"))
t5 = time.perf_counter()
p.render(camera_at(b, "flight"))  # the same frame again (not in the total): the frame's own work
t6 = time.perf_counter()
print(len(drawn), done.get("piste-resident-terrain", t0) - t0, t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4, t5 - t0,
      tn - t0, t6 - t5)
"""


#: the peer: a fresh process that opens a headless EGL context (moderngl), draws one textured quad at
#: 640x448 and reads it back -- the least any fresh GL process pays for a first frame here.  Two ways
#: to open the context, each its own peer: ``plain`` (moderngl's usual call: glcontext looks the GL and
#: EGL libraries up with ctypes.util.find_library, which runs ``ldconfig -p`` twice) and ``named`` (the
#: libraries named, as piste.render.context.create_context opens its context: the stricter peer)
_BARE = """
import sys, time
t0 = time.perf_counter()
import moderngl
import numpy as np
if sys.argv[1] == "named":
    from glcontext import egl
    raw = egl.create_context(mode="standalone", glversion=330, libgl="libGL.so.1", libegl="libEGL.so.1")
    ctx = moderngl.create_standalone_context(require=330, context=raw)
else:
    ctx = moderngl.create_standalone_context(require=330, backend="egl")
fbo = ctx.simple_framebuffer((640, 448), components=4)
fbo.use()
tex = ctx.texture((64, 64), 4, np.full((64, 64, 4), 200, np.uint8).tobytes())
VS = '''#version 330 core
out vec2 v_uv;
void main() { vec2 p = vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1)); v_uv = p;
              gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0); }'''
FS = '''#version 330 core
uniform sampler2D u_tex; in vec2 v_uv; out vec4 f_color;
void main() { f_color = texture(u_tex, v_uv); }'''
prog = ctx.program(vertex_shader=VS, fragment_shader=FS)
tex.use(0)
vao = ctx.vertex_array(prog, [])
vao.render(moderngl.TRIANGLE_STRIP, vertices=4)
img = fbo.read(components=4)
t1 = time.perf_counter()
assert len(img) == 640 * 448 * 4 and img[:4] == bytes([200, 200, 200, 200])
print(t1 - t0)
"""


#: appended to both processes' scripts: their CPU time (user + sys, every thread) on the last line
_CPU = "\nimport resource as _r\n_u = _r.getrusage(_r.RUSAGE_SELF)\nprint(_u.ru_utime + _u.ru_stime)\n"


def fresh_first_frame(bundle: Path, runs: int, baseline_src: Path | None = None) -> None:
    """Bundle to first frame in a fresh Python process (after the interpreter starts).

    The processes use a byte-code cache (``PYTHONPYCACHEPREFIX``, a temporary folder, filled by one
    untimed run), as an installed package has: with ``PYTHONDONTWRITEBYTECODE`` set (as in some
    sandboxes) every run would compile piste's ~100 modules from source (~0.25 s more), which is
    printed beside it (``from source``).  Mesa's shader cache is the user's (warm after the untimed
    run); ``empty shader cache`` runs point ``MESA_SHADER_CACHE_DIR`` at a new empty folder each."""
    import os

    import numpy as np

    cpu: dict = {"piste": [], "peer": [], "named": [], "base": []}  # the processes' CPU time (every thread), cached runs
    programs: list[int] = []  # the programs each run's first frame drew with

    def times(env, kind=None):
        out = subprocess.run([sys.executable, "-c", _FRESH + _CPU, str(bundle)], capture_output=True, text=True,
                             check=True, env=env)
        v = [float(x) for x in out.stdout.split()[-11:]]
        programs.append(int(v[0]))
        if kind:
            cpu[kind].append(v[-1])
        return v[1:-1]

    def bare(env, kind=None, how="plain"):
        out = subprocess.run([sys.executable, "-c", _BARE + _CPU, how], capture_output=True, text=True, check=True,
                             env=env)
        v = [float(x) for x in out.stdout.split()[-2:]]
        if kind:
            cpu[kind].append(v[-1])
        return v[0]

    with tempfile.TemporaryDirectory() as pyc, tempfile.TemporaryDirectory() as shaders:
        cached = {k: v for k, v in os.environ.items() if k not in ("PYTHONDONTWRITEBYTECODE", "MESA_SHADER_CACHE_DIR")}
        cached["PYTHONPYCACHEPREFIX"] = pyc
        source = {**cached, "PYTHONDONTWRITEBYTECODE": "1"}
        source.pop("PYTHONPYCACHEPREFIX", None)
        times(cached)  # fills the byte-code and shader caches (untimed)
        bare(cached)
        bare(cached, how="named")
        based = None
        if baseline_src is not None:  # the baseline sources first on the path (their byte code cached too)
            based = {**cached, "PYTHONPATH": os.pathsep.join([str(baseline_src)] + [p for p in [cached.get("PYTHONPATH")] if p])}
            times(based)
        res, src, cold, peer, named, base = [], [], [], [], [], []
        for i in range(runs):  # interleaved, the order rotated
            jobs = [lambda: res.append(times(cached, "piste")), lambda: peer.append(bare(cached, "peer")),
                    lambda: named.append(bare(cached, "named", "named")),
                    lambda: src.append(times(source)[6]),
                    lambda i=i: cold.append(times({**cached, "MESA_SHADER_CACHE_DIR": str(Path(shaders) / str(i))})[6])]
            if based is not None:
                jobs.insert(1, lambda: base.append(times(based, "base")))
            k = i % len(jobs)
            for job in jobs[k:] + jobs[:k]:
                job()
    a = np.array(res)
    resident, a = a[:, 0], a[:, 1:]
    m = np.median(a, axis=0)
    print(f"fresh process, bundle -> first frame (median of {runs} [range], byte code cached): imports {m[0]:.3f} s"
          f" + GL context {m[1]:.3f} s + load {m[2]:.3f} s + renderer set-up {m[3]:.3f} s + first frame {m[4]:.3f} s"
          f" = {m[5]:.3f} s [{a[:, 5].min():.3f}-{a[:, 5].max():.3f}]; compiling from source each run: "
          f"{np.median(src):.2f} s "
          f"[{min(src):.2f}-{max(src):.2f}]; with an empty Mesa shader cache: {np.median(cold):.2f} s "
          f"[{min(cold):.2f}-{max(cold):.2f}]")
    shared, again = m[6], m[7]
    print(f"  of the imports, numpy + moderngl (the peer imports them too) {shared:.3f} s, piste's own {m[0] - shared:.3f} s; "
          f"the same frame drawn again in that process {again:.3f} s (the frame's own work: the first frame's "
          f"{m[4] - again:.3f} s more are llvmpipe making each program's variant at its first draw and the first uploads)")
    print(f"  the first frame draws with {max(programs)} shader programs (llvmpipe compiles each at its first draw, "
          f"from the Mesa shader cache when it has them); the peer with 1")
    end_setup = np.median(a[:, :4].sum(axis=1))
    if resident.max() > 0:
        print(f"  the terrain's resident vertex blocks (background thread) ready at {np.median(resident):.2f} s, "
              f"set-up done at {end_setup:.2f} s: the first frame {'waits for them' if np.median(resident) > end_setup else 'does not wait'}")
    else:
        from piste.formats.bundle import read_manifest

        man = read_manifest(bundle)
        stored = bool((man.get("terrain") or {}).get("resident"))
        print(f"  bundle format {man.get('format')}: the terrain's resident vertex blocks "
              + ("stored in it (read with the bundle, no background build)" if stored else "not built (not drawn resident)"))
    pm, pn = float(np.median(peer)), float(np.median(named))
    ratio = a[:, 5] / np.asarray(peer)  # per run (the pair ran in the same round)
    ratio_n = a[:, 5] / np.asarray(named)
    print(f"  the peer, a fresh process that opens an EGL context, draws one textured quad at 640x448 and reads it "
          f"back (timed the same way, from the script's first line): {pm:.3f} s [{min(peer):.3f}-{max(peer):.3f}] "
          f"with moderngl's usual call; piste is {m[5] / pm:.2f}x it [{ratio.min():.2f}-{ratio.max():.2f} per run]")
    print(f"  the stricter peer, its GL and EGL libraries named as piste names them (no find_library, no "
          f"ldconfig run): {pn:.3f} s [{min(named):.3f}-{max(named):.3f}]; piste is {m[5] / pn:.2f}x it "
          f"[{ratio_n.min():.2f}-{ratio_n.max():.2f} per run] (target <= 1.5x: {'met' if m[5] / pn <= 1.5 else 'missed'})")
    floor = shared + m[1] + again
    print(f"  the floor under piste's figure: numpy + moderngl imports + GL context + the frame's own work = {floor:.3f} s "
          f"= {floor / pn:.2f}x the stricter peer before any of piste's start-up work; that work (piste's imports, load, "
          f"set-up, the first frame's extra) is {m[5] - floor:.3f} s, and 1.5x leaves it {max(1.5 * pn - floor, 0.0):.3f} s")
    if base:
        b = np.array(base)[:, 1:]
        mb = np.median(b, axis=0)
        gain = b[:, 5] - a[:, 5]  # per round (the two ran in the same round)
        print(f"  baseline sources ({baseline_src}), the same rounds: imports {mb[0]:.3f} s + GL context {mb[1]:.3f} s + "
              f"load {mb[2]:.3f} s + renderer set-up {mb[3]:.3f} s + first frame {mb[4]:.3f} s = {mb[5]:.3f} s "
              f"[{b[:, 5].min():.3f}-{b[:, 5].max():.3f}], {mb[5] / pn:.2f}x the stricter peer; the sources under test "
              f"(piste's figure above) {np.median(gain) * 1e3:+.1f} ms faster than them per round [{gain.min() * 1e3:+.1f} to {gain.max() * 1e3:+.1f}]")
    cp, cq, cn = (float(np.median(cpu[k])) for k in ("piste", "peer", "named"))
    print(f"  CPU time of each whole process (user + sys, every thread: llvmpipe's too; the interpreter's start "
          f"included; less swayed by other processes than the wall times): piste {cp:.3f} s, the peer {cq:.3f} s "
          f"({cp / cq:.2f}x), the stricter peer {cn:.3f} s ({cp / cn:.2f}x)")
    print(f"  (load average {os.getloadavg()[0]:.1f}; another process on the machine slows every figure)")
    record("build", f"bundle -> first frame, fresh process ({bundle.name}, {runs} runs)", "<= 1.5x bare GL",
           f"{m[5]:.2f} s", f"bare EGL quad process, libraries named {pn:.2f} s (moderngl's usual call {pm:.2f} s)",
           f"{m[5] / pn:.2f}x ({m[5] / pm:.2f}x)", m[5] / pn <= 1.5)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2, help="bake worker processes (default 2)")
    ap.add_argument("--no-render", action="store_true", help="skip the first-frame timing (no OpenGL)")
    ap.add_argument("--quick", action="store_true", help="one cold build, one fresh-process run")
    ap.add_argument("--bundle", type=Path, help="time only the fresh-process first frame of this built bundle")
    ap.add_argument("--runs", type=int, default=5, help="fresh-process runs with --bundle (default 5)")
    ap.add_argument("--baseline-src", type=Path, help="with --bundle: also time piste from these sources "
                                                          "(a checkout's src folder), interleaved")
    args = ap.parse_args()
    if args.bundle is not None:
        fresh_first_frame(args.bundle.resolve(), 1 if args.quick else max(1, args.runs),
                          args.baseline_src.resolve() if args.baseline_src is not None else None)
        return

    from piste.commands.build import format_result
    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.build import build_scene

    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        shutil.copy(SCENE, work / SCENE.name)
        scene = work / SCENE.name
        cold = build_scene(scene, jobs=args.jobs)
        first = cold.path.read_bytes()
        warm = cold if args.quick else build_scene(scene, jobs=args.jobs)
        same = warm.path.read_bytes() == first
        print("cold build (empty cache):")
        print(format_result(cold))
        print()
        print("warm build (unchanged inputs):")
        print(format_result(warm))
        print(f"  bundle byte-identical to the cold build: {same}")
        print()
        loads = []
        for _ in range(5):
            t0 = time.perf_counter()
            b = load_bundle(cold.path)
            loads.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        load_bundle(cold.path, verify=False)
        t_noverify = time.perf_counter() - t0
        print(f"load_bundle: best {min(loads) * 1e3:.0f} ms, median {sorted(loads)[2] * 1e3:.0f} ms "
              f"({cold.bytes / 1e6:.2f} MB; without SHA-256 checks {t_noverify * 1e3:.0f} ms)")
        if not args.no_render:
            from piste.pipeline.preview import ScenePreview, camera_at
            from piste.render.context import create_context

            ctx = create_context()
            t0 = time.perf_counter()
            b = load_bundle(cold.path)
            t1 = time.perf_counter()
            p = ScenePreview(b, size=(640, 448), ctx=ctx)
            t2 = time.perf_counter()
            p.render(camera_at(b, "flight"))
            t3 = time.perf_counter()
            p.render(camera_at(b, "flight", 1, 60), t=1 / 30)
            t4 = time.perf_counter()
            print(f"first frame (640x448, headless): load {1e3 * (t1 - t0):.0f} ms + renderer set-up "
                  f"{1e3 * (t2 - t1):.0f} ms + first frame {1e3 * (t3 - t2):.0f} ms = {t3 - t0:.2f} s "
                  f"(GL context made beforehand); the next frame {1e3 * (t4 - t3):.0f} ms")
            p.release()
            ctx.release()
            fresh_first_frame(cold.path, 1 if args.quick else 5)
        print()
        if not args.quick:
            print(f"cold / warm build: {cold.seconds:.2f} s / {warm.seconds:.2f} s = {cold.seconds / warm.seconds:.0f}x")
        vis = cold.report.get("visibility", {}).get("track")
        if vis:
            print(f"visibility along the track ({vis['frames']} cameras): frustum culling alone draws "
                  f"{vis['frustum_pct']:.1f}% of the {vis['patches']} patches, frustum + visibility sets "
                  f"{vis['visible_pct']:.1f}%: {vis['saved_pct']:.1f}% fewer patches")


if __name__ == "__main__":
    main()
