"""Animation compression and morph-target vs null-bone figures on the test models.

Prints, per model: bytes of all clips as glTF stores them, compressed bytes, ratio, the error bound
and the achieved ACL-style object-space error (at the default bound 1e-4 x skeleton size and a
looser 1e-3 x size); then for each morph mesh the memory, cost and error of morph targets vs
null bones. Plain script, not a test.

Run: ``.venv/bin/python benchmarks/bench_animation.py [--quick]`` (``--quick``: the first two models)
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

from piste.character import compression_report, morph_report, morphs_to_null_bones
from piste.formats import load_gltf
from piste.character.compress import default_tolerances

DATA = Path(os.environ.get("PISTE_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")) / "gltf"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="only the first two models")
    args = ap.parse_args(argv)
    files = sorted(p for p in DATA.glob("*/*") if p.suffix in (".gltf", ".glb"))
    if args.quick:
        files = files[:2]
    print(f"{'model':18s} {'bound':>9s} {'vdist':>7s} {'clips':>5s} {'bytes before':>12s} {'after':>7s} "
          f"{'ratio':>6s} {'max err':>9s} {'keys':>11s} {'time s':>6s}")
    for f in files:
        m = load_gltf(f)
        if m.skeleton is None or not m.clips:
            continue
        base, vd = default_tolerances(m.skeleton)
        for mult in (1, 10):
            t = time.perf_counter()
            rows = compression_report(m, max_error=base * mult, virtual_distance=vd)
            dt = time.perf_counter() - t
            b0 = sum(r["bytes_before"] for r in rows)
            b1 = sum(r["bytes_after"] for r in rows)
            err = max(r["achieved_error"] for r in rows)
            k0 = sum(r["keys_before"] for r in rows)
            k1 = sum(r["keys_after"] for r in rows)
            print(f"{m.name:18s} {base * mult:9.3g} {vd:7.3g} {len(rows):5d} {b0:12d} {b1:7d} {b0 / b1:6.1f} "
                  f"{err:9.3g} {k0:5d}->{k1:<5d} {dt:6.2f}")
    print()
    print(f"{'mesh':28s} {'k':>2s} {'moved':>5s} {'J':>3s} {'morph B':>8s} {'null B':>7s} {'morph flop':>10s} "
          f"{'null flop':>9s} {'morph us':>8s} {'null us':>7s} {'max err':>8s} {'rel':>6s} {'nrm deg':>7s}")
    for f in files:
        m = load_gltf(f)
        for mesh in m.meshes:
            if not mesh.n_morphs or not mesh.morph_positions.any():
                continue
            for J in (4, 16, 32):
                rig = morphs_to_null_bones(mesh, J)
                r = morph_report(mesh, rig, timing_repeats=200)
                print(f"{m.name + '/' + mesh.name:28s} {r['targets']:2d} {r['moved_vertices']:5d} {r['null_bones']:3d} "
                      f"{r['bytes_morph_dense']:8d} {r['bytes_null_bones']:7d} {r['flops_morph']:10d} "
                      f"{r['flops_null_bones']:9d} {r['seconds_morph'] * 1e6:8.1f} {r['seconds_null_bones'] * 1e6:7.1f} "
                      f"{r['max_error']:8.3g} {r['relative_error']:6.3f} {r['normal_error_deg']:7.2f}")


if __name__ == "__main__":
    main()
