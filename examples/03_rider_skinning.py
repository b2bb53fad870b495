"""Skin the default rider three ways
=================================

Build the default rider, skin one frame three ways, and show what SSX Tricky's palette costs.

Usage: python examples/03_rider_skinning.py [clip] [time]
Prints the palette size and error of the blended scheme per weight step, the post-transform
normal error, LODs, ps2 batches and strips; writes ``rider.png`` (a matplotlib picture of the
posed rider) into $PISTE_EXAMPLE_OUT (default: the current directory).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from piste.character import (batch_mesh, default_rider, frame_bytes, make_lods, palette, skin, strip_stats,
                             stripify)


def angle_deg(a, b):
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1)))


def picture(mesh, positions, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    tri = mesh.indices.astype(np.int64)
    p = positions[tri].astype(np.float64)
    fn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    fn /= np.linalg.norm(fn, axis=1, keepdims=True) + 1e-12
    # texture colour at each triangle's mean UV, simple directional light, camera looking at -Z
    uv = mesh.uv[tri].mean(1)
    h, w = mesh.texture.shape[:2]
    col = mesh.texture[np.clip((uv[:, 1] * h).astype(int), 0, h - 1), np.clip((uv[:, 0] * w).astype(int), 0, w - 1), :3] / 255.0
    light = np.array([0.3, 0.8, 0.5]) / np.linalg.norm([0.3, 0.8, 0.5])
    col = col * (0.35 + 0.65 * np.clip(fn @ light, 0, 1))[:, None]
    front = fn[:, 2] > 0
    order = np.argsort(p[:, :, 2].mean(1))  # painter's algorithm, far to near
    order = order[front[order]]
    fig, ax = plt.subplots(figsize=(4, 5))
    ax.add_collection(PolyCollection(p[order][:, :, :2], facecolors=col[order], edgecolors="none"))
    ax.set_xlim(-1.0, 1.0)
    ax.set_ylim(positions[:, 1].min() - 0.1, positions[:, 1].min() + 2.0)
    ax.set_aspect("equal")
    ax.axis("off")
    fig.savefig(path, dpi=80)
    plt.close(fig)


def main(argv) -> int:
    clip_name = argv[1] if len(argv) > 1 else "ride"
    t = float(argv[2]) if len(argv) > 2 else 0.5
    rider = default_rider()
    sk, mesh = rider.skeleton, rider.meshes[0]
    print(f"rider: {sk.n_bones} bones, {mesh.n_vertices} vertices, {mesh.n_triangles} triangles, "
          f"clips {sorted(rider.clips)}, morphs {mesh.morph_names}")
    mats = sk.skin_matrices(rider.clips[clip_name].sample(t, loop=True))
    pe, ne = skin(mesh, mats, "exact")
    height = float(np.ptp(pe[:, 1]))
    pp, npt = skin(mesh, mats, "post_transform", inverse_bind=sk.inverse_bind)
    print(f"post-transform: position error {np.abs(pp - pe).max():.1e} m, dominant-bone normals up to "
          f"{angle_deg(npt, ne).max():.1f} deg off")
    for step in (0.1, 0.2, 0.25):
        pb, nb = skin(mesh, mats, "blended", step=step, max_bones=3)
        d = np.linalg.norm(pb - pe, axis=1) / height
        print(f"blended step {step:4}: {palette(mesh, step, 3).size:4d} matrices, position error max "
              f"{100 * d.max():.2f} % mean {100 * d.mean():.3f} % of the height, normals max {angle_deg(nb, ne).max():.1f} deg")
    for lod in make_lods(mesh):
        print(f"LOD {lod.name:6s}: {lod.n_triangles:5d} triangles, {lod.n_matrices:4d} matrices (step {lod.step})")
    batches = batch_mesh(mesh, "ps2", step=0.25)
    strips = [stripify(b.triangles, "restart") for b in batches]
    fb = frame_bytes(batches, strips=strips)
    sent = sum(strip_stats(b.triangles, s)["nonindexed_vertices"] for b, s in zip(batches, strips))
    print(f"ps2 batches: {fb['batches']} (<= 25 matrices, <= 55 vertices), {fb['total_bytes'] / 1024:.1f} KB a frame "
          f"with non-indexed strips, {sent / mesh.n_triangles:.2f} vertices sent per triangle")
    out = Path(os.environ.get("PISTE_EXAMPLE_OUT", "."))
    picture(mesh, pe, out / "rider.png")
    print(f"wrote {out / 'rider.png'}")
    return 0


if __name__ == "__main__":
    if rc := main(sys.argv):  # exit only on failure: the docs gallery runs this file in-process
        sys.exit(rc)
