"""glTF import and export speed: piste's load_gltf against trimesh and pygltflib, piste's export
of the default scene against a pygltflib round trip of the same file.

Run: ``.venv/bin/python benchmarks/bench_gltf.py [--quick] [--rounds N]``

Import: every sample model in ../shared/data/gltf, timed interleaved in one process (median and
range over the rounds):

* ``piste``: :func:`piste.formats.load_gltf` (parse, validate, decode every accessor, skins,
  clips, morphs, textures decoded to RGBA);
* ``trimesh``: ``trimesh.load(path)`` (meshes and textures into a Scene; no skins or clips);
* ``pygltflib``: ``GLTF2().load(path)`` (the JSON/GLB container only: no accessor decoded), the
  floor every Python reader pays.

Export: the default scene (``examples/scenes/default.toml`` built with the cache; ``--quick``: the
default course's terrain at level 4 with a placeholder light map and the default rider, no build)
written by :func:`piste.formats.gltf.write.export_gltf` to ``.glb``, against ``pygltflib``
loading and re-saving that same file (``load`` + ``save_to_bytes``), and ``trimesh`` loading it.
Ratios are piste / peer (below 1: piste is faster).
"""

from __future__ import annotations

import argparse
import io
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import interleaved, ms, record, stat  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "gltf"


def _peers():
    try:
        import trimesh
    except ImportError:
        trimesh = None
    import pygltflib

    return trimesh, pygltflib


def bench_import(rounds: int, quick: bool) -> list:
    from piste.formats import load_gltf

    trimesh, pygltflib = _peers()
    files = sorted(p for p in DATA.glob("*/*") if p.suffix.lower() in (".glb", ".gltf"))
    if quick:
        files = [p for p in files if p.stem in ("CesiumMan", "Fox", "RiggedSimple")]
    rows = []
    print(f"{'import':<22} {'piste load_gltf':>26} {'trimesh.load':>26} {'pygltflib load':>26} {'piste/trimesh':>14}")
    for f in files:
        fns = {"piste": lambda f=f: load_gltf(f), "pygltflib": lambda f=f: pygltflib.GLTF2().load(str(f))}
        if trimesh is not None:
            fns["trimesh"] = lambda f=f: trimesh.load(str(f))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t = interleaved(fns, rounds)
        ratio = stat(t["piste"])[0] / stat(t["trimesh"])[0] if "trimesh" in t else float("nan")
        print(f"{f.stem:<22} {ms(t['piste']):>26} {ms(t['trimesh']) if 'trimesh' in t else 'n/a':>26} "
              f"{ms(t['pygltflib']):>26} {ratio:>13.2f}x")
        rows.append((f.stem, t, ratio))
    if rows:
        r = [x[2] for x in rows if np.isfinite(x[2])]
        if r:
            print(f"piste/trimesh over {len(r)} models: median {np.median(r):.2f}x, range {min(r):.2f}-{max(r):.2f}x")
            record("gltf", "import sample models", "comparable to trimesh", f"{np.median(r):.2f}x trimesh time",
                   "trimesh.load", f"{np.median(r):.2f}")
    return rows


def _default_scene_parts(quick: bool):
    from piste.formats.gltf.write import CharacterExport, TerrainExport
    from piste.terrain.tessellate import terrain_mesh

    if not quick:
        from piste.commands.export import bundle_parts
        from piste.commands.render import load_or_build

        b = load_or_build(ROOT / "examples" / "scenes" / "default.toml")
        return bundle_parts(b, 4), f"default scene ({len(b.net)} patches, {len(b.manifest.get('riders', []))} riders)"
    from piste.character import default_rider
    from piste.render.textures import placeholder_lightmap, snow_texture
    from piste.world.course import default_course

    net = default_course()
    atlas = placeholder_lightmap(net)
    rider = default_rider(0)
    chars = []
    for i in range(3):
        m = np.eye(4)
        m[:3, 3] = (200.0 + 5 * i, 200.0, 300.0)
        chars.append(CharacterExport(rider, m, name=f"r{i}", clips=["ride"], prefix=f"r{i}:"))
    return {"terrain": TerrainExport(terrain_mesh(net, 4), atlas, snow_texture()), "characters": chars}, \
        f"default course ({len(net)} patches) + 3 riders, no build"


def bench_export(rounds: int, quick: bool) -> None:
    from piste.formats import load_gltf
    from piste.formats.gltf.write import export_gltf

    trimesh, pygltflib = _peers()
    parts, what = _default_scene_parts(quick)
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "scene.glb"
        rep = export_gltf(out, **parts)
        size = out.stat().st_size

        def roundtrip():
            g = pygltflib.GLTF2().load(str(out))
            b"".join(g.save_to_bytes())

        fns = {"piste export": lambda: export_gltf(out, **parts), "pygltflib round trip": roundtrip,
               "piste load_gltf": lambda: load_gltf(out)}
        if trimesh is not None:
            fns["trimesh.load"] = lambda: trimesh.load(str(out))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t = interleaved(fns, rounds)
    print(f"\nexport: {what}: {size / 1e6:.2f} MB, terrain {rep.terrain_triangles:,} triangles, {rep.characters} "
          f"riders, {rep.animations} clips, {rep.objects} objects")
    for k, v in t.items():
        print(f"  {k:<22} {ms(v):>30}")
    pe = stat(t["piste export"])[0]
    rt = stat(t["pygltflib round trip"])[0]
    print(f"  piste export / pygltflib round trip: {pe / rt:.2f}x")
    if "trimesh.load" in t:
        print(f"  piste load_gltf / trimesh.load of the export: {stat(t['piste load_gltf'])[0] / stat(t['trimesh.load'])[0]:.2f}x")
    record("gltf", "export default scene", "same order as a pygltflib round trip", f"{pe * 1e3:.0f} ms",
           f"pygltflib round trip {rt * 1e3:.0f} ms", f"{pe / rt:.2f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="three models, no scene build, fewer rounds (a smoke run)")
    ap.add_argument("--rounds", type=int, help="timing rounds (default 7, quick 2)")
    args = ap.parse_args(argv)
    rounds = args.rounds or (2 if args.quick else 7)
    trimesh, _ = _peers()
    if trimesh is None:
        print("trimesh is not installed (pip install 'piste[bench]'): its columns are left out")
    bench_import(rounds, args.quick)
    bench_export(rounds, args.quick)
    return 0


if __name__ == "__main__":
    sys.exit(main())
