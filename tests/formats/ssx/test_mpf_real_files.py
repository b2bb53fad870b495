"""Optional: the user's own SSX Tricky ``.mpf`` models (never in the repo).

Set ``PISTE_SSX_TRICKY_DIR`` to a folder holding retail files (searched recursively; e.g. the three
public models of ``Erickson400/TheTrickyModels``, ``mpf/resources/*.mpf``). Every ``.mpf`` found
opens, writes back byte-identical, has only chunks piste's retail layout rule reproduces, and is
laid out anew identically except in bytes no structure claims; every rider (a ``_body.mpf`` read
with its ``_head.mpf``, or a file with bones of its own) builds with its skeleton fitting its mesh,
within the game's limits, plays piste's shared clips, and exports to glTF with no validator error.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import pytest

from piste.errors import PisteError
from piste.formats.ssx.mpf import game_limits, mpf_bytes, read_mpf, tag_differences
from piste.formats.ssx.mpf_model import mpf_partners

ROOT = os.environ.get("PISTE_SSX_TRICKY_DIR")
pytestmark = pytest.mark.skipif(not ROOT, reason="PISTE_SSX_TRICKY_DIR is not set (point it at a folder holding your "
                                                  "own SSX Tricky .mpf files to run this test)")


def _files() -> list:
    files = sorted(p for p in Path(ROOT).rglob("*") if p.suffix.lower() == ".mpf" and p.is_file()
                   and p.read_bytes()[:4] != b"xDFP")  # the interactive-music graph shares the extension
    if not files:
        pytest.skip(f"no SSX Tricky .mpf model under PISTE_SSX_TRICKY_DIR={ROOT}")
    return files


def _riders(files) -> list:
    """``(model file, partner files)``: a ``_body.mpf`` with the ``_head.mpf`` beside it; any other
    file with bones that is not such a head partner."""
    heads = {mpf_partners(p)[0] for p in files} - {None}
    return [p for p in files if p not in heads and any(len(s.bones) for s in read_mpf(p).models)]


def single_bone_fit(model) -> np.ndarray:
    """Distance ``(n,) float64`` (metres) of each top-LOD vertex weighted 100 % to one bone from that
    bone's segments (joint to each child joint; the joint itself for a leaf), bind pose."""
    sk = model.skeleton
    joints = np.linalg.inv(sk.inverse_bind)[:, :3, 3]
    mesh = model.lods[0].mesh
    one = mesh.weights[:, 0] > 0.999
    p, bone = mesh.positions[one].astype(np.float64), mesh.joints[one, 0].astype(np.int64)
    best = np.linalg.norm(p - joints[bone], axis=1)
    for c in range(sk.n_bones):
        par = int(sk.parents[c])
        if par < 0:
            continue
        sel = bone == par
        a, ab = joints[par], joints[c] - joints[par]
        t = np.clip((p[sel] - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
        best[sel] = np.minimum(best[sel], np.linalg.norm(p[sel] - (a + t[:, None] * ab), axis=1))
    return best


def test_every_mpf_opens_and_writes_back_byte_identical(capsys):
    from piste.formats.ssx import mpf as mpf_module

    files = _files()
    subs = chunks = relaid = 0
    for p in files:
        data = p.read_bytes()
        f = read_mpf(p)
        assert mpf_bytes(f) == data, f"{p}: not written back byte for byte"
        assert tag_differences(f) == [], f"{p}: chunks piste's retail layout rule would write differently"
        for s in f.models:  # laid out anew: identical except in bytes no structure claims (uninitialised padding)
            blob, secs, counts = mpf_module._rebuild_blob(s)
            assert len(blob) == len(s.source) and list(secs) == list(s.entry["sections"]), (p, s.name)
            same = np.frombuffer(blob, np.uint8) == np.frombuffer(s.source, np.uint8)
            for w, o, n, _ in f.unknown:
                if w == f"{s.name} blob":
                    same[o:o + n] = True
            assert same.all(), f"{p} {s.name}: re-laid out, byte {int(np.argmin(same))} differs"
            relaid += bytes(blob) == s.source
            subs += 1
            chunks += sum(len(m.chunks) for lk in s.links for m in lk.meshes)
    with capsys.disabled():
        print(f"\n  real .mpf: {len(files)} files, {subs} sub-models, {chunks} chunks opened and written back "
              f"byte-identical; {relaid} sub-models laid out anew byte-identical, the rest differ only in "
              f"unclaimed padding")


def test_every_rider_builds_fits_animates_and_exports(tmp_path, capsys):
    from piste.character.skinning import skin_exact
    from piste.cli import main
    from piste.pipeline.ssx_rider import load_mpf_rider

    from ..gltf_tools import assert_valid

    riders = _riders(_files())
    assert riders, f"no rider model (a file with bones) under {ROOT}"
    lines = []
    for p in riders:
        head = mpf_partners(p)[0]
        partners = [read_mpf(head)] if head is not None else []
        assert game_limits(read_mpf(p), *partners) == [], p
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = load_mpf_rider(p)
        sk = model.skeleton
        d = single_bone_fit(model)
        if sk.n_bones >= 10:  # a rider: single-bone vertices hug their bones (a board has one bone)
            assert np.median(d) <= 0.12, f"{p.name}: single-bone vertices a median {np.median(d):.3f} m from their bones"
        bind, _ = skin_exact(model.lods[0].mesh, sk.skin_matrices(None))
        size = np.ptp(bind, axis=0).max()
        for name, clip in model.clips.items():
            for t in np.linspace(0.0, clip.duration, 5):
                q, _ = skin_exact(model.lods[0].mesh, sk.skin_matrices(clip.sample(float(t), skeleton=sk)))
                assert np.isfinite(q).all() and np.ptp(q, axis=0).max() < 1.5 * size, (p.name, name, t)
        out = tmp_path / f"{p.stem}.glb"
        try:
            assert main(["mpf", "export", str(p), str(out)]) == 0
        except PisteError as e:  # pragma: no cover - reported with the file
            raise AssertionError(f"{p}: export failed: {e}") from e
        assert_valid(out)
        lines.append(f"{p.name}{' + ' + head.name if head else ''}: {sk.n_bones} bones, "
                     f"{model.lods[0].n_triangles} top-LOD triangles, {len(d)} single-bone vertices a median "
                     f"{np.median(d) * 100:.1f} cm from their bones, {len(model.clips)} clips")
    with capsys.disabled():
        print(f"\n  real .mpf riders: {len(riders)} built, animated and exported with 0 validator errors")
        for line in lines:
            print("   ", line)
