"""SSX Tricky levels: read a 4,000-patch .pbd and build its PatchNet (target < 0.2 s); bake its
game-format light maps with shadows (target < 15 s on the 2-core machine).

Run: ``.venv/bin/python benchmarks/bench_ssx.py [--quick] [--rounds N] [--patches N] [--jobs N]``

The level is piste's own encoder output (:func:`piste.formats.ssx.make_level`: a hilly slope of
50 x 80 patches with near-equal seams, the size of a big retail level), written to a temporary
folder.  Timed, interleaved round by round so both see the same machine load:

* read: ``read_pbd`` + ``Pbd.to_net`` (numpy structured records, power basis decoded in float64,
  welded) against a peer reader that unpacks each 448-byte record with ``struct`` in a Python loop
  (what a record-by-record reader does) and decodes each patch with its own matrix products;
* bake: :func:`piste.pipeline.ssx_level.bake_level` (8x8 edge-aligned texels per patch, shadow rays,
  Cs/As against the 8x8-reduced textures, pages packed) against piste's generic atlas baker
  :func:`piste.lighting.bake_lightmap` on the same net (8x8 texels, shadows, gutters).

Printed: medians with ranges (min - max), ratios, and whether the targets are met.
"""

from __future__ import annotations

import argparse
import struct
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import interleaved, ms, record, stat  # noqa: E402

from piste.formats.ssx import make_level, read_pbd  # noqa: E402
from piste.formats.ssx.pbd import M_INV  # noqa: E402
from piste.lighting import bake_lightmap  # noqa: E402
from piste.lighting.lights import loads_lights  # noqa: E402
from piste.pipeline.ssx_level import bake_level, load_level  # noqa: E402
from piste.terrain.net import PatchNet  # noqa: E402

READ_TARGET_S = 0.2
BAKE_TARGET_S = 15.0
LIGHTS = """
[[ambient]]
color = [0.45, 0.5, 0.65]
intensity = 0.5

[[directional]]
direction = [0.85, 0.3, -0.3]
color = [1.0, 0.9, 0.75]
intensity = 1.0
shadows = true
"""


def peer_read(path: Path) -> PatchNet:
    """A record-by-record reader: struct.unpack per patch, per-patch decode, then the same net."""
    data = path.read_bytes()
    n = struct.unpack_from("<I", data, 0x08)[0]
    off = struct.unpack_from("<I", data, 0x44)[0]
    cps = []
    for k in range(n):
        base = off + 448 * k
        coef = struct.unpack_from("<64f", data, base + 0x50)
        c = np.array(coef, dtype=np.float64).reshape(16, 4)[::-1, :3].reshape(4, 4, 3)
        p = np.stack([M_INV @ c[:, :, i] @ M_INV.T for i in range(3)], axis=-1)
        cps.append(p)
    return PatchNet(np.array(cps) * 0.01, tol=0.01, name=path.name)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a smaller level and fewer rounds (a smoke run)")
    ap.add_argument("--rounds", type=int, help="timing rounds for the read (default 7, quick 3)")
    ap.add_argument("--patches", type=int, help="patches (rows x 80; default 4000, quick 800)")
    ap.add_argument("--jobs", type=int, default=1, help="bake worker processes (default 1; 0 = every core)")
    ap.add_argument("--no-peer-bake", action="store_true", help="skip the generic baker comparison")
    args = ap.parse_args(argv)
    rounds = args.rounds or (3 if args.quick else 7)
    patches = args.patches or (800 if args.quick else 4000)
    cols = 80 if patches >= 80 else patches
    rows = max(1, patches // cols)
    with tempfile.TemporaryDirectory() as d:
        path = make_level(rows=rows, cols=cols, seed=0).write(Path(d), "BIG")
        n = read_pbd(path).n_patches
        print(f"level: {n} patches ({rows} x {cols}), {path.stat().st_size / 1e6:.2f} MB .pbd")

        # ---------------------------------------------------------------- read + net
        t = interleaved({"piste": lambda: read_pbd(path).to_net(), "peer": lambda: peer_read(path)}, rounds)
        a, b = read_pbd(path).to_net(), peer_read(path)
        assert np.allclose(a.control_points, b.control_points, atol=1e-6) and a.n_edges == b.n_edges
        pm, pp = stat(t["piste"])[0], stat(t["peer"])[0]
        print(f"read + PatchNet  piste {ms(t['piste'])}   peer (struct loop) {ms(t['peer'])}   "
              f"peer/piste {pp / pm:.1f}x   target < {READ_TARGET_S * 1e3:.0f} ms: {'met' if pm < READ_TARGET_S else 'MISSED'}")
        record("ssx", f"read {n}-patch .pbd + PatchNet", f"< {READ_TARGET_S} s", ms(t["piste"]), ms(t["peer"]),
               f"{pp / pm:.1f}x", pm < READ_TARGET_S)

        # ---------------------------------------------------------------- bake
        lights = loads_lights(LIGHTS)
        level = load_level(path)
        fns = {"piste ssx-tricky": lambda: bake_level(level, lights, shadows=True, jobs=args.jobs)}
        if not args.no_peer_bake:
            fns["generic atlas baker"] = lambda: bake_lightmap(level.net, lights, res=8, shadows=True,
                                                               jobs=max(args.jobs, 1))
        tb = interleaved(fns, 1 if args.quick else 3, warmup=0)
        baked = bake_level(level, lights, shadows=True, jobs=args.jobs)
        bm = stat(tb["piste ssx-tricky"])[0]
        line = f"bake (shadows, jobs={args.jobs})  piste ssx-tricky {ms(tb['piste ssx-tricky'])}"
        if "generic atlas baker" in tb:
            gm = stat(tb["generic atlas baker"])[0]
            line += f"   generic atlas baker {ms(tb['generic atlas baker'])}   generic/ssx {gm / bm:.2f}x"
        print(line + f"   target < {BAKE_TARGET_S:.0f} s: {'met' if bm < BAKE_TARGET_S else 'MISSED'}")
        print(f"  {len(baked.pages)} pages, {baked.stats.get('rays', 0):,} shadow rays "
              f"({baked.stats.get('rays_occluded', 0):,} occluded)")
        record("ssx", f"bake {n}-patch level, game format, shadows", f"< {BAKE_TARGET_S} s", ms(tb["piste ssx-tricky"]),
               ms(tb["generic atlas baker"]) if "generic atlas baker" in tb else "", "", bm < BAKE_TARGET_S)
    return 0


if __name__ == "__main__":
    sys.exit(main())
