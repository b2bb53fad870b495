"""Character LODs: simplified meshes keep their skin attributes and get their own palettes."""

from __future__ import annotations

import numpy as np
import pytest

from piste.character.lod import compact_mesh, make_lods, simplify_mesh
from piste.character.skinning import skin
from piste.errors import ConfigError


def test_lods_of_cesiumman(gltf_model):
    model = gltf_model("CesiumMan")
    lods = make_lods(model.meshes[0], ratios=(1.0, 0.5, 0.25), steps=(0.1, 0.2, 0.25))
    tris = [l.n_triangles for l in lods]
    mats = [l.n_matrices for l in lods]
    assert tris[0] == model.meshes[0].n_triangles
    assert tris[0] > tris[1] > tris[2] and abs(tris[2] - 0.25 * tris[0]) < 0.05 * tris[0]
    assert mats[0] > mats[1] > mats[2]
    assert mats[0] == 269  # the talk: ~250 / ~150 / ~75
    for l in lods:
        m = l.mesh
        assert m.indices.max() < m.n_vertices and np.unique(m.indices).size == m.n_vertices
        assert np.allclose(m.weights.sum(1), 1.0, atol=1e-5)
        # a lower level skins like the original at its surviving vertices
        sk = model.skeleton
        mats_ = sk.skin_matrices(next(iter(model.clips.values())).sample(0.5))
        p, _ = skin(m, mats_, "exact")
        assert np.isfinite(p).all()


def test_compact_mesh_keeps_attributes_per_vertex():
    from piste.character.rider import default_rider

    mesh = default_rider().meshes[0]
    sub = mesh.indices[100:200]
    c = compact_mesh(mesh, sub)
    assert np.array_equal(c.positions[c.indices], mesh.positions[sub])
    assert np.array_equal(c.joints[c.indices], mesh.joints[sub])
    assert np.array_equal(c.uv[c.indices], mesh.uv[sub])
    assert np.array_equal(c.morph_positions[:, c.indices], mesh.morph_positions[:, sub])
    s, err = simplify_mesh(mesh, mesh.n_triangles // 3)
    assert s.n_triangles <= mesh.n_triangles // 3 + 1 and err < 0.05
    with pytest.raises(ConfigError):
        simplify_mesh(mesh, 0)
    with pytest.raises(ConfigError):
        make_lods(mesh, ratios=(1.0, 1.5), steps=0.1)


def test_lods_weld_flat_shaded_meshes(gltf_model):
    mesh = gltf_model("Fox").meshes[0]  # 3 vertices a triangle: nothing shared before welding
    lods = make_lods(mesh)
    assert lods[2].n_triangles <= 0.3 * mesh.n_triangles
    assert lods[0].n_matrices > lods[1].n_matrices > lods[2].n_matrices
