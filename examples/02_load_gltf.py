"""Load a glTF character
=====================

Load a glTF 2.0 character and print its skeleton, clips and morph targets.

Usage: python examples/02_load_gltf.py [path/to/model.glb]
(default: RobotExpressive from ../shared/data/gltf, or CesiumMan, whichever is found; set
PISTE_DATA to point elsewhere).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from piste.character import compress_clip
from piste.formats import load_gltf


def find_default() -> Path | None:
    if "PISTE_DATA" in os.environ:  # the docs gallery sets it (it runs examples without __file__)
        data = Path(os.environ["PISTE_DATA"])
    else:
        data = Path(__file__).resolve().parents[2] / "shared" / "data"
    for rel in ("gltf/RobotExpressive/RobotExpressive.glb", "gltf/CesiumMan/CesiumMan.glb"):
        if (data / rel).is_file():
            return data / rel
    return None


def main(argv: list[str]) -> int:
    path = Path(argv[1]) if len(argv) > 1 else find_default()
    if path is None:
        print("no model given and no test models found; pass a .gltf/.glb path")
        return 0
    model = load_gltf(path)
    print(f"{model.name}: {len(model.meshes)} meshes, {model.n_vertices} vertices, {model.n_triangles} triangles, "
          f"size {model.size():.3g} units")
    sk = model.skeleton
    if sk is not None:
        print(f"skeleton: {sk.n_bones} bones ({int(sk.is_joint.sum())} skin joints), depth {len(sk.levels)}")
        lines = []
        stack = [(i, 0) for i in np.flatnonzero(sk.parents < 0)[::-1]]
        while stack:  # depth-first, as a tree
            i, d = stack.pop()
            lines.append(f"  {'  ' * d}{sk.names[i]}{'' if sk.is_joint[i] else '  (node)'}")
            stack += [(c, d + 1) for c in np.flatnonzero(sk.parents == i)[::-1]]
        print("\n".join(lines[:16]) + (f"\n  ... {len(lines) - 16} more" if len(lines) > 16 else ""))
    for n, (name, clip) in enumerate(model.clips.items()):
        line = f"clip {name!r}: {clip.duration:.3f} s, {len(clip.tracks)} bones, {len(clip.weight_tracks)} morph tracks"
        if sk is not None and clip.tracks and n < 3:  # compress a few (seconds each on big clips)
            cc = compress_clip(clip)
            line += (f", {clip.nbytes} -> {cc.nbytes} bytes compressed "
                     f"(error {cc.achieved_error:.2g} <= {cc.max_error:.2g} units)")
        print(line)
    for mesh, names in model.morph_targets.items():
        print(f"morph targets of {mesh}: {', '.join(names)}")
    return 0


if __name__ == "__main__":
    if rc := main(sys.argv):  # exit only on failure: the docs gallery runs this file in-process
        sys.exit(rc)
