"""SSX Tricky rider models: read + convert a 3,000-triangle rider with three LODs (target < 50 ms).

Run: ``.venv/bin/python benchmarks/bench_mpf.py [--quick] [--rounds N]``

The file is piste's encoder output for the default rider (Body3000 / Body1500 / Body750: 3,084 /
1,542 / 770 triangles, weights in 25 % steps, morph targets in type-256 groups), written to a
temporary folder. Timed, interleaved round by round (so both see the same machine load):

* ``piste .mpf``: ``read_mpf`` (bytes -> every chunk, palette and morph key as arrays) and
  ``mpf_to_model`` (skeleton, welded meshes, morphs, three LODs with the file's palettes);
* peer ``glTF``: the same rider exported to ``.glb`` (one LOD, with its clips) and loaded with
  ``piste.formats.load_gltf`` (pygltflib) - the other way piste gets a rider from a file.

Printed: median and range (min - max) per stage in milliseconds, the ratio to the peer, and the
50 ms target.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from piste.character import default_rider
from piste.formats import load_gltf
from piste.formats.gltf.write import CharacterExport, export_gltf
from piste.formats.ssx.mpf import read_mpf, write_mpf
from piste.formats.ssx.mpf_encode import model_to_mpf
from piste.formats.ssx.mpf_model import mpf_to_model

TARGET_MS = 50.0


def _ms(fn):
    t0 = time.perf_counter()
    out = fn()
    return (time.perf_counter() - t0) * 1000.0, out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="5 rounds instead of 30")
    ap.add_argument("--rounds", type=int, default=None, help="timed rounds (default 30, 5 with --quick)")
    args = ap.parse_args(argv)
    rounds = args.rounds or (5 if args.quick else 30)
    rider = default_rider(0)
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        t_enc, (f, report) = _ms(lambda: model_to_mpf(rider))
        write_mpf(f, d / "RIDER.mpf")
        export_gltf(d / "rider.glb", characters=[CharacterExport(rider, name="rider")])
        size_mpf, size_glb = (d / "RIDER.mpf").stat().st_size, (d / "rider.glb").stat().st_size
        read_mpf(d / "RIDER.mpf")  # warm the page cache and imports
        load_gltf(d / "rider.glb")
        t = {"read": [], "convert": [], "total": [], "gltf": []}
        for _ in range(rounds):
            a, mpf = _ms(lambda: read_mpf(d / "RIDER.mpf"))
            b, model = _ms(lambda: mpf_to_model(mpf))
            t["read"].append(a)
            t["convert"].append(b)
            t["total"].append(a + b)
            c, _ = _ms(lambda: load_gltf(d / "rider.glb"))
            t["gltf"].append(c)
    tris = [lod.n_triangles for lod in model.lods]
    print(f"rider: {' / '.join(map(str, tris))} triangles in {len(tris)} LODs, {model.skeleton.n_bones} bones, "
          f"{sum(len(s.palettes) for s in f.models)} palettes; .mpf {size_mpf / 1024:.0f} KiB, "
          f".glb {size_glb / 1024:.0f} KiB; encode {t_enc:.0f} ms (once)")
    print(f"{rounds} interleaved rounds, milliseconds: median (min - max)")
    peer = float(np.median(t["gltf"]))
    for k, label in (("read", "piste read_mpf"), ("convert", "piste mpf_to_model"),
                     ("total", "piste read + convert"), ("gltf", "peer load_gltf (.glb)")):
        v = np.array(t[k])
        print(f"  {label:24s} {np.median(v):7.2f}  ({v.min():6.2f} - {v.max():6.2f})   "
              f"x peer {np.median(v) / peer:5.2f}")
    med = float(np.median(t["total"]))
    print(f"read + convert median {med:.1f} ms: {'within' if med < TARGET_MS else 'OVER'} the {TARGET_MS:.0f} ms target")
    return 0


if __name__ == "__main__":
    sys.exit(main())
