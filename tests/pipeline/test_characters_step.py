"""The character build step: LODs, palettes, batches within the PS2 budget, strips, clip tables."""

from __future__ import annotations

import numpy as np
import pytest

from piste.character import BUDGETS
from piste.character.strips import canonical_triangles, unstripify
from piste.pipeline.bundle_objects import load_bundle
from piste.pipeline.build import build_scene



def _bundle(small_scene):
    return load_bundle(build_scene(small_scene()).path)


def test_lods_palettes_batches_strips(small_scene):
    b = _bundle(small_scene)
    meta = b.manifest["characters"]["rider"]
    lods = meta["lods"]
    assert [x["name"] for x in lods] == ["high", "medium", "low"]
    tri = [x["triangles"] for x in lods]
    pal = [x["palette"] for x in lods]
    assert tri[0] > tri[1] > tri[2] and pal[0] > pal[1] > pal[2]
    budget = BUDGETS["ps2"]
    a = b.arrays
    for i, info in enumerate(lods):
        p = f"characters/rider/lod{i}/"
        off = a[p + "batch_offsets"]
        assert len(off) == info["batches"] + 1
        idx = a[p + "indices"].astype(np.int64)
        covered = []
        so = a[p + "strip_offsets"]
        for k in range(info["batches"]):
            (v0, m0, t0), (v1, m1, t1) = off[k], off[k + 1]
            assert v1 - v0 <= budget.max_vertices and m1 - m0 <= budget.max_matrices
            verts = a[p + "batch_vertices"][v0:v1].astype(np.int64)
            local = a[p + "batch_triangles"][t0:t1].astype(np.int64)
            strip = a[p + "strips"][so[k]:so[k + 1]]
            # the strip draws exactly the batch's triangles, winding kept
            assert np.array_equal(canonical_triangles(unstripify(strip)), canonical_triangles(local))
            covered.append(verts[local])
        assert np.array_equal(canonical_triangles(np.concatenate(covered)), canonical_triangles(idx))
    # the palette of each LOD indexes every vertex
    lods_ = b.rider_lods()
    assert [lod.palette.size for lod in lods_] == pal
    assert all(lod.palette.index.max() < lod.palette.size for lod in lods_)


def test_bundle_clip_table_matches_the_model(small_scene):
    from piste.pipeline.preview import clip_table
    from piste.world.riders import ClipTable

    b = _bundle(small_scene)
    fast = clip_table(b)
    ref = ClipTable(b.rider_model(), 30.0)
    ids = np.array([fast.clip_index(n) for n in fast.names])
    assert fast.names == ref.names
    for t in (0.0, 0.37, 1.1):
        a = fast.skin_matrices(ids, np.full(len(ids), t))
        r = ref.skin_matrices(ids, np.full(len(ids), t))
        assert np.abs(a - r).max() < 1e-5


def test_rider_stands_on_the_surface_along_its_heading(small_scene):
    from piste.terrain.query import height_at

    b = _bundle(small_scene)
    m = b.arrays["riders/matrix"][0]
    z, hit, _, _ = height_at(b.net, m[None, :2, 3])
    assert hit[0] and m[2, 3] == pytest.approx(z[0])
    assert m[2, 1] > 0.9  # the rider's up (+Y) is the surface normal, mostly +z
    assert m[1, 0] > 0.9  # heading 0: the board (+X) points along +y
