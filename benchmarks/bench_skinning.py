"""Skinning throughput: exact LBS (numpy reference), SSX post-transform, SSX Tricky blended
matrices (palette), in M vertices/s (positions + normals per frame), with the ratio to the exact
reference.

Run: ``.venv/bin/python benchmarks/bench_skinning.py [--quick]``

Cases: every skinned test model in ../shared/data/gltf, the default rider, six riders in
different poses (the talk's scene: 6 models on screen; also skinned all at once with
``BlendedMesh.apply_many``, one sparse x dense product), and a 100k-vertex mesh (58 riders merged
into one mesh). Per frame the blended scheme includes building the palette matrices from the bone
matrices; all per-mesh precomputation (quantization, bone-space copies, the sparse map) is done
once before timing, as the game does offline.

Also printed per case: palette size at step 0.25 / 0.1 and the ps2-budget batches.

Then the six riders side by side against Panda3D's C++ CPU skinning (``GeomVertexData.
animateVertices`` with a ``TransformBlendTable``: exact linear blend skinning), every contender
timed alike (interleaved rounds, medians with [min-max]): piste's blended palette compiled (numba)
and as the scipy sparse product, piste's exact float64 LBS, Panda3D (bone matrices set through its
Python API, then the C++ skinning, positions and normals copied out as piste returns them).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _timing import interleaved, ms, record, stat  # noqa: E402

from piste.character import default_rider, palette
from piste.formats import load_gltf
from piste.character.batches import batch_mesh, frame_bytes
from piste.character.model import SkinnedMesh
from piste.character.skinning import BlendedMesh, PostTransformMesh, skin_exact

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "gltf"


def lbs_float32(mesh, mats):
    """Peer: a plain float32 einsum LBS (blend 4 matrices per vertex, then transform)."""
    m = mats[:, :3, :].astype(np.float32)
    a = np.einsum("vk,vkij->vij", mesh.weights, m[mesh.joints.astype(np.intp)])
    p = np.einsum("vij,vj->vi", a[:, :, :3], mesh.positions) + a[:, :, 3]
    n = np.einsum("vij,vj->vi", a[:, :, :3], mesh.normals)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return p, n


def timeit(fn, min_time=0.25, blocks=15):
    """Seconds per call: the best block average over ``blocks`` blocks of ``min_time / blocks``
    seconds each (the minimum filters out other processes on a shared 2-core machine)."""
    fn()
    best = np.inf
    for _ in range(blocks):
        n = 0
        t0 = time.perf_counter()
        while True:
            fn()
            n += 1
            dt = time.perf_counter() - t0
            if dt >= min_time / blocks:
                break
        best = min(best, dt / n)
    return best


def cases(quick: bool):
    out = []
    if not quick:
        for f in sorted(DATA.glob("*/*")):
            if f.suffix not in (".glb", ".gltf"):
                continue
            m = load_gltf(f)
            meshes = [me for me in m.meshes if me.skinned]
            if m.skeleton is None or not meshes or not m.clips:
                continue
            clip = next(iter(m.clips.values()))
            out.append((m.name, m.skeleton, [(meshes, clip.sample(clip.duration * 0.37, loop=True))]))
    rider = default_rider()
    sk = rider.skeleton
    out.append(("rider", sk, [(rider.meshes, rider.clips["ride"].sample(0.3, loop=True))]))
    names = ["ride", "crouch", "grab", "spin", "ride", "grab"]
    six = [(rider.meshes, rider.clips[n].sample(0.2 * i + 0.1, loop=True)) for i, n in enumerate(names)]
    out.append(("6 riders", sk, six))
    me = rider.meshes[0]
    k = int(np.ceil(100_000 / me.n_vertices))
    offs = np.arange(k, dtype=np.float32)[:, None, None] * np.array([2.0, 0, 0], np.float32)
    big = SkinnedMesh(
        "crowd", (me.positions[None] + offs).reshape(-1, 3),
        (me.indices[None].astype(np.int64) + (np.arange(k) * me.n_vertices)[:, None, None]).reshape(-1, 3),
        normals=np.tile(me.normals, (k, 1)), joints=np.tile(me.joints, (k, 1)),
        weights=np.tile(me.weights, (k, 1)), skinned=True)
    out.append((f"{big.n_vertices // 1000}k verts", sk, [([big], rider.clips["ride"].sample(0.3, loop=True))]))
    return out


def panda_mesh(me, n_bones):
    """A Panda3D GeomVertexData of ``me`` skinned by a TransformBlendTable of ``n_bones``
    UserVertexTransforms (Panda's own CPU animation path); returns ``(vdata, transforms)``."""
    from panda3d.core import (Geom, GeomVertexAnimationSpec, GeomVertexArrayFormat, GeomVertexData,
                              GeomVertexFormat, GeomVertexWriter, InternalName, SparseArray, TransformBlend,
                              TransformBlendTable, UserVertexTransform)

    arr = GeomVertexArrayFormat()
    arr.addColumn(InternalName.getVertex(), 3, Geom.NTFloat32, Geom.CPoint)
    arr.addColumn(InternalName.getNormal(), 3, Geom.NTFloat32, Geom.CNormal)
    tb = GeomVertexArrayFormat()
    tb.addColumn(InternalName.getTransformBlend(), 1, Geom.NTUint16, Geom.CIndex)
    fmt = GeomVertexFormat()
    fmt.addArray(arr)
    fmt.addArray(tb)
    spec = GeomVertexAnimationSpec()
    spec.setPanda()
    fmt.setAnimation(spec)
    fmt = GeomVertexFormat.registerFormat(fmt)
    vd = GeomVertexData(me.name, fmt, Geom.UHDynamic)
    vd.uncleanSetNumRows(me.n_vertices)
    mv = memoryview(vd.modifyArray(0)).cast("B").cast("f")
    np.frombuffer(mv, np.float32)[:] = np.concatenate([me.positions, me.normals], 1).astype(np.float32).ravel()
    xf = [UserVertexTransform(f"bone{i}") for i in range(n_bones)]
    tbt = TransformBlendTable()
    w = me.weights / np.maximum(me.weights.sum(1, keepdims=True), 1e-12)
    idx = []
    for v in range(me.n_vertices):
        b = TransformBlend()
        for j, ww in zip(me.joints[v], w[v]):
            if ww > 0:
                b.addTransform(xf[int(j)], float(ww))
        idx.append(tbt.addBlend(b))
    tbt.setRows(SparseArray.lowerOn(me.n_vertices))
    vd.setTransformBlendTable(tbt)
    wr = GeomVertexWriter(vd, InternalName.getTransformBlend())
    for i in idx:
        wr.setData1i(int(i))
    return vd, xf


def panda_skin(vd, xf, skin_matrices):
    """One frame: set the bone matrices (Panda: row vectors, so transposed), skin in C++, copy out."""
    from panda3d.core import LMatrix4f, Thread

    m = np.asarray(skin_matrices, dtype=np.float32)
    for i, t in enumerate(xf):
        t.setMatrix(LMatrix4f(*m[i].T.ravel()))
    an = vd.animateVertices(True, Thread.getCurrentThread())
    out = np.frombuffer(memoryview(an.getArray(0)).cast("B"), np.float32).reshape(-1, 6)
    return out[:, :3].copy(), out[:, 3:].copy()


def six_riders_vs_panda(rounds: int) -> None:
    from piste.character.skinning import _blend_nb

    rider = default_rider()
    sk = rider.skeleton
    me = rider.meshes[0]
    names = ["ride", "crouch", "grab", "spin", "ride", "grab"]
    poses = [(n, 0.2 * i + 0.1) for i, n in enumerate(names)]
    frame = [0]

    def mats():  # a new pose every call (so no one can cache)
        frame[0] += 1
        return np.stack([sk.skin_matrices(rider.clips[n].sample(t + 0.01 * frame[0], loop=True)) for n, t in poses])

    stacks = [mats() for _ in range(8)]
    bm = BlendedMesh.build(me, 0.25, 3)
    k = [0]

    def nxt():
        k[0] = (k[0] + 1) % len(stacks)
        return stacks[k[0]]

    fns = {}
    if _blend_nb is not None:
        fns["piste blended, compiled (numba)"] = lambda: bm.apply_many(nxt())
    fns["piste blended, scipy sparse"] = lambda: bm.apply_many(nxt(), use_numba=False)
    fns["piste exact LBS (float64 numpy)"] = lambda: [skin_exact(me, m) for m in nxt()]
    try:
        import panda3d  # noqa: F401
    except ImportError:
        print("\nPanda3D not installed (pip install 'piste[bench]'): the peer comparison is skipped")
        panda = None
    else:
        panda = [panda_mesh(me, sk.n_bones) for _ in range(6)]
        p, n = panda_skin(*panda[0], stacks[0][0])
        pe, ne = skin_exact(me, stacks[0][0])
        print(f"\nPanda3D vs piste exact: max position difference {np.abs(p - pe).max():.1e} "
              f"(the model is {np.ptp(pe, axis=0).max():.2f} m tall)")
        fns["Panda3D animateVertices (C++)"] = lambda: [panda_skin(vd, xf, m) for (vd, xf), m in zip(panda, nxt())]
    t = interleaved(fns, rounds, warmup=2)
    verts = 6 * me.n_vertices
    print(f"== six riders side by side ({verts:,} vertices a frame), {rounds} interleaved rounds ==")
    for name, ts in t.items():
        print(f"  {name:34s} {ms(ts):>28s}  {verts / stat(ts)[0] / 1e6:7.1f} M vertices/s")
    if panda is not None:
        best = "piste blended, compiled (numba)" if _blend_nb is not None else "piste blended, scipy sparse"
        pm, p_lo, p_hi = stat(t["Panda3D animateVertices (C++)"])
        sm = stat(t[best])[0]
        print(f"{best} is {pm / sm:.1f}x Panda3D (target >= 4x: {'met' if pm / sm >= 4 else 'missed'}); "
              f"note Panda3D does exact LBS with every influence, piste the talk's quantized palette")
        record("skinning", "six riders vs Panda3D CPU skinning", ">= 4x", f"{verts / sm / 1e6:.0f} M verts/s",
               f"{verts / pm / 1e6:.1f} M verts/s", f"{pm / sm:.1f}x", pm / sm >= 4)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="rider cases only, shorter timing")
    ap.add_argument("--rounds", type=int, help="interleaved rounds of the Panda3D comparison (default 40, quick 15)")
    args = ap.parse_args(argv)
    from piste import _jit

    _jit.warm_up()  # compile / load the numba kernels before timing (else the first frames run numpy)
    six_riders_vs_panda(args.rounds or (15 if args.quick else 40))
    print()
    min_time = 0.1 if args.quick else 0.25
    print("skinning throughput, M vertices/s (positions + normals), ratio to the exact numpy reference")
    hdr = (f"{'case':14s} {'verts':>7s} | {'exact':>6s} {'lbs32':>6s} {'post':>6s} {'bl.25':>6s} {'bl.1':>6s} "
           f"{'bl.25nn':>7s} | {'x lbs32':>7s} {'x post':>6s} {'x bl.25':>7s} {'x bl.1':>6s} | "
           f"{'pal.25':>6s} {'pal.1':>5s} {'ps2 batches':>11s} {'KB/frame':>8s}")
    print(hdr)
    print("-" * len(hdr))
    for name, sk, instances in cases(args.quick):
        verts = sum(me.n_vertices for meshes, _ in instances for me in meshes)
        mats = [sk.skin_matrices(pose) for _, pose in instances]
        meshes0 = instances[0][0]
        post = [PostTransformMesh.build(me, sk.inverse_bind) for me in meshes0]
        bl25 = [BlendedMesh.build(me, 0.25, 3) for me in meshes0]
        bl10 = [BlendedMesh.build(me, 0.1, 3) for me in meshes0]

        def run(fn):
            def frame():
                for (meshes, _), m in zip(instances, mats):
                    for i, me in enumerate(meshes):
                        fn(i, me, m)
            return verts / timeit(frame, min_time) / 1e6

        if len(instances) > 1:  # one call for all instances (same mesh, different poses)
            stack = np.stack(mats)
            many = [BlendedMesh.build(me, 0.25, 3) for me in meshes0]
            dt = timeit(lambda: [bm.apply_many(stack) for bm in many], min_time)
            many_rate = verts / dt / 1e6
        else:
            many_rate = None
        r = {
            "exact": run(lambda i, me, m: skin_exact(me, m)),
            "lbs32": run(lambda i, me, m: lbs_float32(me, m)),
            "post": run(lambda i, me, m: post[i].apply(m)),
            "bl25": run(lambda i, me, m: bl25[i].apply(m)),
            "bl10": run(lambda i, me, m: bl10[i].apply(m)),
            "bl25nn": run(lambda i, me, m: bl25[i].apply(m, normalize=False)),
        }
        pal25 = sum(palette(me, 0.25, 3).size for me in meshes0)
        pal10 = sum(palette(me, 0.1, 3).size for me in meshes0)
        nb, kb = 0, 0.0
        if verts < 60_000:
            for me in meshes0:
                bs = batch_mesh(me, "ps2", step=0.25)
                fb = frame_bytes(bs)
                nb += fb["batches"] * len(instances)
                kb += fb["total_bytes"] * len(instances) / 1024
        e = r["exact"]
        print(f"{name:14s} {verts:7d} | {e:6.1f} {r['lbs32']:6.1f} {r['post']:6.1f} {r['bl25']:6.1f} {r['bl10']:6.1f} "
              f"{r['bl25nn']:7.1f} | {r['lbs32'] / e:7.2f} {r['post'] / e:6.2f} {r['bl25'] / e:7.2f} {r['bl10'] / e:6.2f} | "
              f"{pal25:6d} {pal10:5d} {nb:11d} {kb:8.1f}")
        if many_rate is not None:
            print(f"{'  (one call)':14s} {verts:7d} | {'':6s} {'':6s} {'':6s} {many_rate:6.1f} {'':6s} {'':7s} | "
                  f"{'':7s} {'':6s} {many_rate / e:7.2f}")
    print("\nexact: float64 reference (inverse-transpose normals); lbs32: float32 einsum LBS peer; post: SSX "
          "post-transform;\nbl.25 / bl.1: SSX Tricky blended palette at step 0.25 / 0.1 (normals renormalised); "
          "bl.25nn: without renormalising.\nKB/frame: ps2 batches (25 matrices, 55 vertices), 48-byte matrices + "
          "32-byte vertices, step 0.25.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
