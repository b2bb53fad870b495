"""SSX Tricky levels: read a 4,000-patch .pbd and build its PatchNet (target < 0.2 s); bake its
game-format light maps with shadows (target < 15 s on the 2-core machine); read + convert the
largest retail-layout ``.mpf`` rider (target >= 5x a per-record ``struct`` reader).

Run: ``.venv/bin/python benchmarks/bench_ssx.py [--quick] [--rounds N] [--patches N] [--jobs N] [--mpf-only]``

The level is piste's own encoder output (:func:`piste.pipeline.ssx_synth.make_level`: a hilly slope of
50 x 80 patches with near-equal seams, the size of a big retail level), written to a temporary
folder.  Timed, interleaved round by round so both see the same machine load:

* read: ``read_pbd`` + ``pipeline.ssx_level.pbd_to_net`` (numpy structured records, power basis decoded in float64,
  welded) against a peer reader that unpacks each 448-byte record with ``struct`` in a Python loop
  (what a record-by-record reader does) and decodes each patch with its own matrix products;
* bake: :func:`piste.pipeline.ssx_level.bake_level` (8x8 edge-aligned texels per patch, shadow rays,
  Cs/As against the 8x8-reduced textures, pages packed) against piste's generic atlas baker
  :func:`piste.lighting.bake_lightmap` on the same net (8x8 texels, shadows, gutters).

* mpf: ``read_mpf`` + ``MpfFile.to_model`` (body + head file: skeleton, every LOD's mesh with
  weights and morph targets) of the largest retail-layout model -- the retail ``*_body.mpf`` (with
  its ``_head.mpf``) found under ``PISTE_SSX_TRICKY_DIR`` when that is set, else piste's encoder's
  body + head pair of the default rider -- against :func:`peer_read_mpf`, a reader written here
  that unpacks every record (directory entry, bone, palette entry, group, link, mesh header, strip
  entry, vertex, morph delta) with ``struct`` in Python loops and builds the same outputs (bind
  joints, each LOD tier's triangle corners: positions, normals, UVs, bone weights, morph deltas),
  which are compared with piste's before timing. With ``PISTE_SSX_TRICKY_DIR`` set, every ``.mpf``
  under it is opened and written back, and the counts printed.

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

from piste.formats.ssx import read_pbd  # noqa: E402
from piste.pipeline.ssx_synth import make_level  # noqa: E402
from piste.formats.ssx.mpf import mpf_bytes, read_mpf, write_mpf  # noqa: E402
from piste.formats.ssx.mpf_model import mpf_partners  # noqa: E402
from piste.formats.ssx.pbd import M_INV  # noqa: E402
from piste.lighting import bake_lightmap  # noqa: E402
from piste.lighting.lights import loads_lights  # noqa: E402
from piste.pipeline.ssx_level import bake_level, load_level, pbd_to_net  # noqa: E402
from piste.terrain.net import PatchNet  # noqa: E402

READ_TARGET_S = 0.2
MPF_TARGET_RATIO = 5.0
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


def _rot(e) -> np.ndarray:
    """A bone record's rotation, Rz(-z) Ry(-y) Rx(-x), for one bone (3 x 3)."""
    x, y, z = (-a for a in e)
    cx, sx, cy, sy, cz, sz = np.cos(x), np.sin(x), np.cos(y), np.sin(y), np.cos(z), np.sin(z)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def peer_read_mpf(paths) -> dict:
    """A record-by-record ``.mpf`` reader (``struct.unpack_from`` per record and per vertex): the
    bind joints ``{bone name: (3,) metres}`` and, per LOD tier (``3000`` / ``1500`` / ``750``), the
    triangle corners' ``positions (3t, 3)``, ``normals (3t, 3)``, ``uv (3t, 2)``, ``weights (3t,
    bones)`` and ``morph (k, 3t, 3)`` in piste's frame (metres, +Y up)."""
    u = struct.unpack_from
    files = []
    for path in paths:
        data = Path(path).read_bytes()
        _, count, diroff, start = u("<IhhI", data, 0)
        subs = []
        for i in range(count):
            e = diroff + 80 * i
            name = data[e:e + 16].split(b"\0", 1)[0].decode("ascii", "replace")
            off, _size = u("<II", data, e + 16)
            sec = u("<7I", data, e + 24)
            cnt = u("<7h", data, e + 60)
            fid = u("<b", data, e + 74)[0]
            subs.append((name, start + off, sec, cnt, fid))
        files.append((data, subs))
    # skeleton: the first sub-model with bones of each file id
    bones, base, names = {}, {}, []
    for data, subs in files:
        for name, b0, sec, cnt, fid in subs:
            if cnt[3] and fid not in bones:
                recs = []
                for k in range(cnt[3]):
                    o = b0 + sec[0] + 84 * k
                    bn = data[o:o + 16].split(b"\0", 1)[0].decode("ascii", "replace")
                    pf, pb = u("<hh", data, o + 16)
                    t = u("<3f", data, o + 24)
                    r = u("<3f", data, o + 36)
                    recs.append((bn, pf, pb, t, r))
                bones[fid] = recs
                base[fid] = len(names)
                names += [bn if bn not in names else f"{bn}.{fid}" for bn, *_ in recs]
    a = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])
    world = [None] * len(names)
    flat = [(fid, k, rec) for fid, recs in bones.items() for k, rec in enumerate(recs)]

    def solve(i):
        fid, k, (bn, pf, pb, t, r) = flat[i]
        m = np.eye(4)
        m[:3, :3] = _rot(r)
        m[:3, 3] = t
        if pf >= 0 and pb >= 0 and pf in base:
            j = base[pf] + pb
            if world[j] is None:
                solve(j)
            m = world[j] @ m
        world[i] = m

    for i in range(len(flat)):
        if world[i] is None:
            solve(i)
    joints = {n: (a @ w[:3, 3]) * 0.01 for n, w in zip(names, world)}
    # meshes, by tier
    tiers = {}
    for data, subs in files:
        for name, b0, sec, cnt, fid in subs:
            if "shdw" in name.lower():
                continue
            tier = next((t for t in ("3000", "1500", "750") if name.endswith(t)), "")
            pals = []
            for k in range(cnt[0]):
                n, o, _c = u("<3I", data, b0 + sec[6] + 12 * k)
                w = np.zeros(len(names))
                for q in range(n):
                    pct, bone, f = u("<hBB", data, b0 + o + 4 * q)
                    w[base[f] + bone] += pct / 100.0
                pals.append(w)
            refs = []
            for k in range(cnt[1]):
                n, o = u("<2I", data, b0 + sec[5] + 8 * k)
                refs.append([u("<I", data, b0 + o + 4 * q)[0] for q in range(n)])
            out = tiers.setdefault(tier, {"positions": [], "normals": [], "uv": [], "weights": [], "morph": [],
                                          "channels": []})
            first_channel = len(out["channels"])
            if cnt[6]:  # each sub-model's morph keys are channels of their own (Face3000.morph0, ...)
                out["channels"] += [f"{name}.morph{i}" for i in range(cnt[6])]
            li = 0
            for g in range(cnt[2]):
                gtype, _mat, _unk, nlink, loff = u("<5I", data, b0 + sec[2] + 20 * g)
                for lk in range(nlink):
                    moff, nmesh = u("<2I", data, b0 + loff + 8 * lk)
                    ref = refs[li]
                    li += 1
                    if gtype == 17:
                        continue
                    for me in range(nmesh):
                        mo, mk, msz = u("<3I", data, b0 + moff + 12 * me)
                        p = b0 + mo
                        verts = []
                        tris = []
                        while data[p + 31] == 0x6C:
                            ns, _w1, _w2, nv = u("<4I", data, p + 48)
                            lengths = [u("<I", data, p + 64 + 16 * s)[0] for s in range(ns)]
                            q = p + 64 + 16 * ns + 16 + 48
                            uv = [u("<4h", data, q + 8 * v) for v in range(nv)]
                            q = q + (8 * nv + 15) // 16 * 16 + 48
                            nr = [u("<3h", data, q + 6 * v) for v in range(nv)]
                            q = q + (6 * nv + 15) // 16 * 16 + 48
                            ps = [u("<3f", data, q + 12 * v) for v in range(nv)]
                            q = q + (12 * nv + 15) // 16 * 16
                            first = len(verts)
                            verts += list(zip(uv, nr, ps))
                            s0 = first
                            for ln in lengths:
                                for i in range(ln - 2):
                                    x, y, z = s0 + i, s0 + i + 1, s0 + i + 2
                                    tri = (y, x, z) if i % 2 else (x, y, z)
                                    pa, pb, pc = verts[tri[0]][2], verts[tri[1]][2], verts[tri[2]][2]
                                    if pa != pb and pb != pc and pa != pc:
                                        tris.append(tri)
                                s0 += ln
                            p = q + 32
                        keys = []
                        if mk != 0xFFFFFFFF and cnt[6]:
                            kp = p
                            for _ in range(cnt[6]):
                                num = data[kp + 30]
                                keys.append([u("<3b", data, kp + 32 + 3 * v) for v in range(num)])
                                kp += msz
                        for tri in tris:
                            for c in tri:
                                (uu, vv, slot, _n), (nx, ny, nz), (px, py, pz) = verts[c]
                                out["positions"].append((px * 0.01, pz * 0.01, -py * 0.01))
                                ln = (nx * nx + ny * ny + nz * nz) ** 0.5 or 1.0
                                out["normals"].append((nx / ln, nz / ln, -ny / ln))
                                out["uv"].append((uu / 4096.0, vv / 4096.0))
                                out["weights"].append(pals[ref[(slot - 14) // 4]])
                                ds = [key[c] if c < len(key) else (0, 0, 0) for key in keys]
                                out["morph"].append((first_channel, [(d[0] / 1280.0, d[2] / 1280.0, -d[1] / 1280.0)
                                                                     for d in ds]))
    result = {"joints": joints, "tiers": {}}
    for tier, o in tiers.items():
        morph = np.zeros((len(o["channels"]), len(o["positions"]), 3))
        for i, (c0, m) in enumerate(o["morph"]):
            if m:
                morph[c0:c0 + len(m), i] = m
        result["tiers"][tier] = {"positions": np.array(o["positions"]), "normals": np.array(o["normals"]),
                                 "uv": np.array(o["uv"]), "weights": np.array(o["weights"]), "morph": morph}
    return result


def _mpf_inputs(folder: Path) -> tuple:
    """``(body path, head path or None, label)``: the largest retail rider under
    PISTE_SSX_TRICKY_DIR, else piste's encoder's pair of the default rider written to ``folder``."""
    import os

    root = os.environ.get("PISTE_SSX_TRICKY_DIR")
    if root:
        files = [p for p in Path(root).rglob("*") if p.suffix.lower() == ".mpf" and p.is_file()
                 and p.read_bytes()[:4] != b"xDFP"]
        bodies = [p for p in files if p.stem.lower().endswith("_body")] or files
        if bodies:
            body = max(bodies, key=lambda p: p.stat().st_size + (mpf_partners(p)[0].stat().st_size
                                                                  if mpf_partners(p)[0] else 0))
            return body, mpf_partners(body)[0], "retail"
    from piste.character import default_rider
    from piste.formats.ssx.mpf_encode import model_to_mpf_pair

    body, head, _ = model_to_mpf_pair(default_rider(0))
    write_mpf(body, folder / "rider_body.mpf")
    write_mpf(head, folder / "rider_head.mpf")
    return folder / "rider_body.mpf", folder / "rider_head.mpf", "piste encoder (retail layout)"


def _piste_outputs(model) -> dict:
    """piste's model as the peer's outputs (triangle corners per tier)."""
    sk = model.skeleton
    w = np.linalg.inv(sk.inverse_bind)[:, :3, 3]
    out = {"joints": dict(zip(sk.names, w)), "tiers": {}}
    for tier, lod in zip(("3000", "1500", "750"), model.lods):
        m = lod.mesh
        c = m.indices.reshape(-1)
        dense = np.zeros((m.n_vertices, sk.n_bones))
        np.add.at(dense, (np.repeat(np.arange(m.n_vertices), m.joints.shape[1]), m.joints.reshape(-1).astype(np.int64)),
                  m.weights.reshape(-1))
        morph = m.morph_positions[:, c] if m.morph_positions is not None else np.zeros((0, len(c), 3))
        out["tiers"][tier] = {"positions": m.positions[c], "normals": m.normals[c], "uv": m.uv[c],
                              "weights": dense[c], "morph": morph}
    return out


def _same(a: dict, b: dict, names_b) -> None:
    """Assert piste's outputs ``a`` equal the peer's ``b`` (weights by bone name)."""
    for n, j in a["joints"].items():
        assert np.allclose(j, b["joints"][n], atol=1e-5), n
    order = [names_b.index(n) for n in a["joints"]]
    for tier, x in a["tiers"].items():
        y = b["tiers"][tier]
        assert x["positions"].shape == y["positions"].shape, (tier, x["positions"].shape, y["positions"].shape)
        assert np.allclose(x["positions"], y["positions"], atol=1e-6)
        assert np.allclose(x["normals"], y["normals"], atol=1e-5)
        assert np.allclose(x["uv"], y["uv"], atol=1e-7)
        assert np.allclose(x["weights"], y["weights"][:, order], atol=1e-6)
        assert x["morph"].shape == y["morph"].shape and np.allclose(x["morph"], y["morph"], atol=1e-6), tier


def bench_mpf(folder: Path, rounds: int) -> None:
    import os

    body, head, label = _mpf_inputs(folder)
    paths = [body] + ([head] if head is not None else [])
    size = sum(p.stat().st_size for p in paths)

    def piste():
        return read_mpf(body).to_model(*([read_mpf(head)] if head is not None else []))

    model = piste()
    peer = peer_read_mpf(paths)
    _same(_piste_outputs(model), peer, list(peer["joints"]))
    tris = [lod.n_triangles for lod in model.lods]
    print(f"mpf: {label}: {' + '.join(p.name for p in paths)} ({size / 1e3:.0f} kB), {model.skeleton.n_bones} bones, "
          f"{' / '.join(str(t) for t in tris)} triangles; outputs equal the peer's")
    t = interleaved({"piste": piste, "peer": lambda: peer_read_mpf(paths)}, rounds)
    pm, pp = stat(t["piste"])[0], stat(t["peer"])[0]
    ok = pp / pm >= MPF_TARGET_RATIO
    print(f"read + to_model  piste {ms(t['piste'])}   peer (struct per record) {ms(t['peer'])}   peer/piste "
          f"{pp / pm:.1f}x   target >= {MPF_TARGET_RATIO:.0f}x: {'met' if ok else 'MISSED'}")
    record("ssx", f"read + to_model {label} .mpf rider ({' / '.join(str(x) for x in tris)} triangles)",
           f">= {MPF_TARGET_RATIO:.0f}x peer", ms(t["piste"]), ms(t["peer"]), f"{pp / pm:.1f}x", ok)
    root = os.environ.get("PISTE_SSX_TRICKY_DIR")
    if not root:
        print("retail .mpf files: PISTE_SSX_TRICKY_DIR not set, none opened")
        return
    files = sorted(p for p in Path(root).rglob("*") if p.suffix.lower() == ".mpf" and p.is_file())
    opened = same = subs = 0
    failed = []
    for p in files:
        try:
            f = read_mpf(p)
        except Exception as e:  # noqa: BLE001 - counted and named
            failed.append(f"{p.name}: {e}")
            continue
        opened += 1
        subs += len(f.models)
        same += mpf_bytes(f) == p.read_bytes()
    print(f"retail .mpf files under {root}: {opened} of {len(files)} opened ({subs} sub-models), {same} written back "
          f"byte-identical" + ("".join(f"\n  not opened: {x}" for x in failed)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a smaller level and fewer rounds (a smoke run)")
    ap.add_argument("--rounds", type=int, help="timing rounds for the read (default 7, quick 3)")
    ap.add_argument("--patches", type=int, help="patches (rows x 80; default 4000, quick 800)")
    ap.add_argument("--jobs", type=int, default=1, help="bake worker processes (default 1; 0 = every core)")
    ap.add_argument("--no-peer-bake", action="store_true", help="skip the generic baker comparison")
    ap.add_argument("--mpf-only", action="store_true", help="only the .mpf read + convert benchmark")
    args = ap.parse_args(argv)
    rounds = args.rounds or (3 if args.quick else 7)
    patches = args.patches or (800 if args.quick else 4000)
    cols = 80 if patches >= 80 else patches
    rows = max(1, patches // cols)
    if args.mpf_only:
        with tempfile.TemporaryDirectory() as d:
            bench_mpf(Path(d), rounds)
        return 0
    with tempfile.TemporaryDirectory() as d:
        bench_mpf(Path(d), rounds)
        path = make_level(rows=rows, cols=cols, seed=0).write(Path(d), "BIG")
        n = read_pbd(path).n_patches
        print(f"level: {n} patches ({rows} x {cols}), {path.stat().st_size / 1e6:.2f} MB .pbd")

        # ---------------------------------------------------------------- read + net
        t = interleaved({"piste": lambda: pbd_to_net(read_pbd(path)), "peer": lambda: peer_read(path)}, rounds)
        a, b = pbd_to_net(read_pbd(path)), peer_read(path)
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
