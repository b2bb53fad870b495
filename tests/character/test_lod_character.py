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


# ---------------------------------------------------------------- geometric error of a level (rider LOD by pixels)
def _dense_distance(points, positions, indices, n=4000):
    """A reference: each point's distance to a dense sampling of every triangle (>= the true distance)."""
    rng = np.random.default_rng(1)
    uv = rng.random((n, 2))
    flip = uv.sum(1) > 1
    uv[flip] = 1 - uv[flip]
    uv = np.concatenate([uv, [[0, 0], [1, 0], [0, 1], [0.5, 0], [0, 0.5], [0.5, 0.5]]])
    c = np.asarray(positions, float)[np.asarray(indices, int)]
    samples = (c[:, None, 0] + uv[None, :, :1] * (c[:, None, 1] - c[:, None, 0])
               + uv[None, :, 1:] * (c[:, None, 2] - c[:, None, 0])).reshape(-1, 3)
    return np.array([np.linalg.norm(samples - p, axis=1).min() for p in np.asarray(points, float)])


def test_surface_distance_exact_on_a_triangle():
    from piste.character.lod import surface_distance

    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    tri = np.array([[0, 1, 2]])
    pts = np.array([[0.2, 0.2, 0.5],    # over the face: its height
                    [-1.0, -1.0, 0.0],  # beyond corner 0: to the corner
                    [0.5, -2.0, 1.0],   # beside edge 0-1: to the edge
                    [1.0, 1.0, 0.0],    # beyond the hypotenuse
                    [0.1, 0.1, 0.0]])   # on the face
    want = [0.5, np.sqrt(2.0), np.sqrt(5.0), np.sqrt(0.5), 0.0]
    assert np.allclose(surface_distance(pts, pos, tri), want, atol=1e-12)
    # a degenerate triangle (a segment) measures to its edges
    seg = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], float)
    assert np.isclose(surface_distance([[1.0, 3.0, 4.0]], seg, tri)[0], 5.0)
    with pytest.raises(ConfigError, match="no triangles"):
        surface_distance(pts, pos, np.zeros((0, 3), int))


def test_surface_distance_matches_a_dense_sampling():
    from piste.character.lod import max_surface_distance, surface_distance

    rng = np.random.default_rng(0)
    pos = rng.normal(size=(30, 3))
    tri = rng.integers(0, 30, size=(40, 3))
    pts = rng.normal(size=(300, 3)) * 1.5
    d = surface_distance(pts, pos, tri)
    ref = _dense_distance(pts, pos, tri)
    assert (d <= ref + 1e-9).all()  # never above a point of the surface
    assert np.abs(d - ref).max() < 0.05  # (the sampling's spacing)
    # the pruned maximum is the brute-force maximum, exactly
    assert max_surface_distance(pts, pos, tri, k=2, batch=16) == pytest.approx(d.max(), abs=1e-12)


def test_lod_errors_are_the_two_way_distance(rider_lods):
    from piste.character.lod import lod_errors, surface_distance

    err = lod_errors(rider_lods)
    assert err[0] == 0.0 and (np.diff(err) >= 0).all() and err[-1] > 0
    full = rider_lods[0].mesh
    fp, ft = full.positions.astype(float), full.indices.astype(int)
    m = rider_lods[1].mesh
    mp, mt = m.positions.astype(float), m.indices.astype(int)
    one = surface_distance(np.concatenate([fp, fp[ft].mean(1)]), mp, mt).max()
    other = surface_distance(np.concatenate([mp, mp[mt].mean(1)]), fp, ft).max()
    assert err[1] == pytest.approx(max(one, other), abs=1e-12)


@pytest.fixture(scope="module")
def rider_lods():
    from piste.character import default_rider

    return make_lods(default_rider(0).meshes[0])
