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
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="rider cases only, shorter timing")
    args = ap.parse_args(argv)
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
