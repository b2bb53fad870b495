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

First the six riders side by side against Panda3D's C++ CPU skinning under the same rules: both
get the same 72-entry palette (piste's quantized blend matrices; Panda3D one ``UserVertexTransform``
per entry and each vertex blended by its entry alone), the palettes are handed over outside the timed
region (Panda's ``setMatrix`` calls are set-up, like piste's palette argument), and only the skinning
calls are timed: piste's ``BlendedMesh.skin_palette`` (compiled) against Panda's C++
``GeomVertexData.animateVertices`` (no copy-out), interleaved rounds with the order rotated, medians
with [min-max]; the positions AND normals of the last timed calls are compared (they must agree).
"""

from __future__ import annotations

import argparse
import sys
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


def panda_palette_mesh(me, bm):
    """Panda3D's input for the palette comparison: ``me`` with one UserVertexTransform per palette
    entry and every vertex blended by its entry alone (weight 1), so Panda's C++ skinning does the
    same work as piste's palette call (one 3x4 per vertex, positions and normals)."""
    view = SkinnedMesh(me.name, me.positions, me.indices, normals=me.normals,
                       joints=np.stack([bm.palette.index] + [np.zeros_like(bm.palette.index)] * 3, 1).astype(np.uint16),
                       weights=np.repeat(np.array([[1.0, 0.0, 0.0, 0.0]], np.float32), me.n_vertices, 0), skinned=True)
    return panda_mesh(view, bm.palette.size)


def panda_set(xf, pal):
    """Hand Panda3D one palette ``(p, 3, 4)`` through its API (row vectors: transposed); not timed."""
    from panda3d.core import LMatrix4f

    m4 = np.zeros((len(xf), 4, 4), np.float32)
    m4[:, :3] = pal
    m4[:, 3, 3] = 1.0
    for i, t in enumerate(xf):
        t.setMatrix(LMatrix4f(*m4[i].T.ravel()))


def panda_out(animated):
    """Positions and normals ``(v, 3)`` float32 each of an animated Panda3D GeomVertexData (a copy)."""
    out = np.frombuffer(memoryview(animated.getArray(0)).cast("B"), np.float32).reshape(-1, 6)
    return out[:, :3].copy(), out[:, 3:].copy()


def six_riders_vs_panda(rounds: int) -> None:
    """Six riders, the same 72-entry palettes to both, only the skinning calls timed (interleaved,
    order rotated), outputs compared on the timed paths."""
    from piste.character.skinning import _blend_nb

    rider = default_rider()
    sk = rider.skeleton
    me = rider.meshes[0]
    names = ["ride", "crouch", "grab", "spin", "ride", "grab"]
    bm = BlendedMesh.build(me, 0.25, 3)
    # 8 frames of six poses each, a new frame every round (no contender can reuse a result)
    stacks = [np.stack([sk.skin_matrices(rider.clips[n].sample(0.2 * i + 0.1 + 0.037 * f, loop=True))
                        for i, n in enumerate(names)]) for f in range(8)]
    pals = [np.ascontiguousarray(bm.palette_matrices(st), dtype=np.float32) for st in stacks]  # (6, p, 3, 4) each
    verts = 6 * me.n_vertices
    compiled = _blend_nb is not None
    print(f"\n== six riders ({verts:,} vertices a frame), each vertex by its entry of the same {bm.palette.size}-entry "
          f"palette (step 0.25, 3 bones); positions + unit normals; {rounds} interleaved rounds, order rotated ==")
    print(f"piste: BlendedMesh.skin_palette ({'compiled, numba, one thread' if compiled else 'scipy sparse: numba missing'})"
          f"; Panda3D: GeomVertexData.animateVertices (C++), 6 calls; palettes handed over outside the timed region")
    k = {}
    got = {}

    def nxt(name):
        k[name] = (k.get(name, -1) + 1) % len(pals)

    def piste_call():
        got["piste"] = (k["piste"], bm.skin_palette(pals[k["piste"]], inverse_transpose=True))

    fns = {"piste": (lambda: nxt("piste"), piste_call)}
    try:
        import panda3d  # noqa: F401
    except ImportError:
        print("Panda3D not installed (pip install 'piste[bench]'): the peer comparison is skipped")
        record("skinning", "six riders vs Panda3D, same palette", ">= 4x", "", "skipped: panda3d not installed", "")
        return
    from panda3d.core import Thread

    thread = Thread.getCurrentThread()
    panda = [panda_palette_mesh(me, bm) for _ in range(6)]

    def panda_setup():
        nxt("panda")
        for (vd, xf), pal in zip(panda, pals[k["panda"]]):
            panda_set(xf, pal)

    def panda_call():
        got["panda"] = (k["panda"], [vd.animateVertices(True, thread) for vd, _ in panda])

    fns["panda"] = (panda_setup, panda_call)
    t = interleaved(fns, rounds, warmup=2)
    (kp, (pp, pn)), (kq, animated) = got["piste"], got["panda"]
    assert kp == kq, "the last timed calls skinned different frames"
    qp = np.stack([panda_out(a)[0] for a in animated])
    qn = np.stack([panda_out(a)[1] for a in animated])
    dp, dn = float(np.abs(pp - qp).max()), float(np.abs(pn - qn).max())
    # the float64 answer both approximate: each vertex by its entry's 3x4, normals by the inverse-transpose
    a = pals[kp].astype(np.float64)[:, bm.palette.index]  # (6, v, 3, 4)
    rp = np.einsum("nvij,vj->nvi", a[..., :3], me.positions.astype(np.float64)) + a[..., 3]
    rn = np.einsum("nvji,vj->nvi", np.linalg.inv(a[..., :3]), me.normals.astype(np.float64))
    rn /= np.linalg.norm(rn, axis=-1, keepdims=True)
    size = float(np.ptp(pp[0], axis=0).max())
    print(f"outputs of the last timed calls (the same frame): max |piste - Panda3D| positions {dp:.1e} m (a {size:.2f} m "
          f"rider), unit normals {dn:.1e}; against float64: piste {np.abs(pp - rp).max():.1e} / "
          f"{np.abs(pn - rn).max():.1e}, Panda3D {np.abs(qp - rp).max():.1e} / {np.abs(qn - rn).max():.1e} "
          f"(positions / normals)")
    assert dp < 1e-5 * size and dn < 1e-2, "piste and Panda3D did not compute the same vertices"
    for name, label in (("piste", "piste skin_palette"), ("panda", "Panda3D animateVertices (C++)")):
        print(f"  {label:32s} {ms(t[name]):>28s}  {verts / stat(t[name])[0] / 1e6:7.1f} M vertices/s")
    pm, sm = stat(t["panda"])[0], stat(t["piste"])[0]
    ratio = t["panda"] / t["piste"]  # per round (the pair ran back to back)
    print(f"piste is {pm / sm:.1f}x Panda3D (per-round ratios {ratio.min():.1f}-{ratio.max():.1f}; target >= 4x: "
          f"{'met' if pm / sm >= 4 else 'missed'})")
    record("skinning", "six riders vs Panda3D, same 72-entry palette, skinning call only", ">= 4x",
           f"{sm * 1e6:.0f} us ({verts / sm / 1e6:.0f} M verts/s)", f"{pm * 1e6:.0f} us ({verts / pm / 1e6:.0f} M verts/s)",
           f"{pm / sm:.1f}x [{ratio.min():.1f}-{ratio.max():.1f}]", pm / sm >= 4)
    # the whole per-frame skinning as piste's scene runs it (bone matrices -> palette -> vertices), for reference
    st = {}
    t2 = interleaved({"apply_many": (lambda: st.__setitem__("k", (st.get("k", -1) + 1) % len(stacks)),
                                     lambda: bm.apply_many(stacks[st["k"]])),
                      "scipy": (lambda: st.__setitem__("j", (st.get("j", -1) + 1) % len(stacks)),
                                lambda: bm.apply_many(stacks[st["j"]], use_numba=False))}, rounds, warmup=2)
    print(f"  (for reference: piste's whole frame from bone matrices, apply_many: {ms(t2['apply_many'])}; "
          f"the scipy sparse reference: {ms(t2['scipy'])})")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="rider cases only, shorter timing")
    ap.add_argument("--rounds", type=int, help="interleaved rounds of the Panda3D comparison (default 40, quick 15)")
    args = ap.parse_args(argv)
    from piste import _jit

    _jit.warm_up()  # compile / load the numba kernels before timing (else the first frames run numpy)
    six_riders_vs_panda(args.rounds or (15 if args.quick else 40))
    print()
    tp_rounds = 7 if args.quick else 21
    print(f"skinning throughput, M vertices/s (positions + normals; medians of {tp_rounds} interleaved rounds, the "
          f"schemes in the same rounds, order rotated), ratio to the exact numpy reference")
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
            return frame

        fns = {
            "exact": run(lambda i, me, m: skin_exact(me, m)),
            "lbs32": run(lambda i, me, m: lbs_float32(me, m)),
            "post": run(lambda i, me, m: post[i].apply(m)),
            "bl25": run(lambda i, me, m: bl25[i].apply(m)),
            "bl10": run(lambda i, me, m: bl10[i].apply(m)),
            "bl25nn": run(lambda i, me, m: bl25[i].apply(m, normalize=False)),
        }
        if len(instances) > 1:  # one call for all instances (same mesh, different poses)
            stack = np.stack(mats)
            many = [BlendedMesh.build(me, 0.25, 3) for me in meshes0]
            fns["many"] = lambda: [bm.apply_many(stack) for bm in many]
        t = interleaved(fns, tp_rounds, warmup=1)  # every scheme in the same rounds, the order rotated
        r = {k: verts / stat(ts)[0] / 1e6 for k, ts in t.items()}
        many_rate = r.pop("many", None)
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
