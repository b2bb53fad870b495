"""Light-map atlas: layout, texel-centre sampling, gutters, seam-consistent samples, shadows,
no LOD popping, and accuracy against per-pixel lighting."""

from __future__ import annotations

import numpy as np
import pytest
from lighting_nets import hill_net, make_lights, shuffle_orientation, wall_scene

from piste.lighting import (
    AmbientLight,
    DirectionalLight,
    Lights,
    PointLight,
    assemble_atlas,
    atlas_layout,
    bake_lightmap,
    lightmap_uv,
    sample_atlas,
    sample_points,
    shade,
    with_lightmap_layout,
)
from piste.lighting.lightmap import lightmap_params
from piste.lighting.lights import light_terms
from piste.lighting.shadows import shadow_visibility
from piste.terrain.net import default_lightmap_rects


@pytest.mark.parametrize("n", [1, 2, 7, 30, 2560])
@pytest.mark.parametrize("res", [8, 16])
def test_layout_matches_the_nets_default_rects(n, res):
    lay = atlas_layout(n, res)
    np.testing.assert_array_equal(lay.rects(), default_lightmap_rects(n, res, 1))
    o = lay.origins()
    assert o.min() >= 1 and (o[:, 0] + res + 1 <= lay.width).all() and (o[:, 1] + res + 1 <= lay.height).all()
    assert len({(int(x), int(y)) for x, y in o}) == n


def test_with_lightmap_layout_returns_a_copy(hill):
    net16 = with_lightmap_layout(hill, 16)
    np.testing.assert_array_equal(net16.lightmap_rect, atlas_layout(len(hill), 16).rects())
    np.testing.assert_array_equal(hill.lightmap_rect, default_lightmap_rects(len(hill), 8))
    assert net16.control_points is hill.control_points  # a cheap shallow copy


def test_texel_centres_hold_the_samples(hill, lights):
    lm = bake_lightmap(hill, lights, res=8, shadows=False)
    u, v = lightmap_params(8)
    p = np.repeat(np.arange(len(hill)), 64)
    uu, vv = np.tile(u, len(hill)), np.tile(v, len(hill))
    pos, nrm = sample_points(hill, 8)
    want = shade(lights, pos.reshape(-1, 3), nrm.reshape(-1, 3))
    for mode in ("point", "bilinear"):
        got = lm.sample(p, uu, vv, mode=mode)
        np.testing.assert_allclose(got, want, atol=2e-5)  # float32 rects: ~1e-5 texel off centre
    np.testing.assert_array_equal(lm.tiles().reshape(-1, 3), want)


def test_gutters_stop_bilinear_bleeding():
    n, res = 6, 8
    colors = np.random.default_rng(0).uniform(0, 1, (n, 3)).astype(np.float32)
    tiles = np.broadcast_to(colors[:, None, None, :], (n, res, res, 3))
    rng = np.random.default_rng(1)
    p = rng.integers(0, n, 4000)
    # parameters up to half a texel past the tile's border texel centres (UVs extrapolated by
    # interpolation / precision, or a filter footprint reaching over the border)
    over = 0.5 / (res - 1)
    u, v = rng.uniform(-over, 1 + over, 4000), rng.uniform(-over, 1 + over, 4000)
    for gutter, bleeds in ((1, False), (0, True)):
        lay = atlas_layout(n, res, gutter)
        atlas = assemble_atlas(tiles, lay)
        got = sample_atlas(atlas, lightmap_uv(lay.rects(), p, u, v))
        err = np.abs(got - colors[p]).max()
        assert (err > 1e-3) == bleeds, (gutter, err)


def test_sample_atlas_modes():
    atlas = np.arange(12, dtype=np.float32).reshape(3, 4)
    centre = lambda x, y: [(x + 0.5) / 4, (y + 0.5) / 3]  # noqa: E731
    assert sample_atlas(atlas, [centre(2, 1)], "point")[0] == 6
    assert sample_atlas(atlas, [centre(2, 1)], "bilinear")[0] == 6
    mid = [(centre(1, 1)[0] + centre(2, 1)[0]) / 2, centre(1, 1)[1]]
    assert sample_atlas(atlas, [mid], "bilinear")[0] == pytest.approx(5.5)
    assert sample_atlas(atlas, [mid], "point")[0] in (5, 6)
    assert sample_atlas(atlas, [[-1.0, -1.0]])[0] == 0  # clamp to edge
    rgb = np.stack([atlas, 2 * atlas, 3 * atlas], -1)
    np.testing.assert_allclose(sample_atlas(rgb, [mid])[0], [5.5, 11.0, 16.5])


def test_shared_edges_get_identical_points_normals_and_texels(lights):
    net = shuffle_orientation(hill_net(4, 3, crease=0.8), seed=3)
    assert net.side_flip.any()
    res = 8
    pos, nrm = sample_points(net, res)
    lm = bake_lightmap(net, lights, res=res, shadows=True)
    tiles = lm.tiles().reshape(len(net), -1, 3)
    slots = np.stack([np.arange(res), np.arange(res) * res + res - 1, (res - 1) * res + np.arange(res), np.arange(res) * res])
    pa, pb = net.edge_patches[net.shared_edges].T
    sa, sb = net.edge_sides[net.shared_edges].T
    checked = 0
    for a, b, s_a, s_b in zip(pa, pb, sa, sb):
        ia, ib = slots[s_a], slots[s_b]
        if net.side_flip[a, s_a] != net.side_flip[b, s_b]:
            ib = ib[::-1]
        np.testing.assert_array_equal(pos[a, ia], pos[b, ib])
        np.testing.assert_array_equal(nrm[a, ia], nrm[b, ib])
        np.testing.assert_array_equal(tiles[a, ia], tiles[b, ib])
        checked += 1
    assert checked == len(net.shared_edges) > 10


def test_seam_normals_remove_creases():
    """A C0 net with slope jumps at every seam: each patch's own normals light the two sides of a
    seam differently (a visible crease); the shared normals do not."""
    net = hill_net(3, 3, crease=1.0)
    lights = Lights((DirectionalLight((1.0, 0.2, -0.6)),))
    res = 8
    _, own = sample_points(net, res, smooth_seams=False)
    pos, shared = sample_points(net, res)
    slots = {1: np.arange(res) * res + res - 1, 3: np.arange(res) * res, 0: np.arange(res), 2: (res - 1) * res + np.arange(res)}
    crease = smooth = 0.0
    for e in net.shared_edges:
        (a, b), (s_a, s_b) = net.edge_patches[e], net.edge_sides[e]
        ia, ib = slots[int(s_a)], slots[int(s_b)]
        crease = max(crease, np.abs(shade(lights, pos[a, ia], own[a, ia]) - shade(lights, pos[b, ib], own[b, ib])).max())
        smooth = max(smooth, np.abs(shade(lights, pos[a, ia], shared[a, ia]) - shade(lights, pos[b, ib], shared[b, ib])).max())
    assert crease > 0.05 and smooth == 0.0, (crease, smooth)


def test_terrain_casts_shadows():
    net = wall_scene()
    amb = AmbientLight((0.2, 0.2, 0.2), 1.0)
    sun = DirectionalLight((-1.0, 0.0, -0.5), (1.0, 1.0, 1.0), 1.0)  # from +x, 26.6 degrees up
    lights = Lights((amb, sun))
    res = 8
    lm = bake_lightmap(net, lights, res=res)
    pos, _ = sample_points(net, res)
    col = lm.tiles().reshape(-1, 3)[:, 0]
    x, y, z = pos.reshape(-1, 3).T
    ground = np.arange(len(col)) < 16 * res * res
    lit_value = 0.2 + 1.0 * (0.5 / np.sqrt(1.25))  # ambient + n.L on flat ground
    shadowed = ground & (x > 1) & (x < 19) & (y > 11) & (y < 29)
    lit = ground & ((x > 21) | (y < 9) | (y > 31))
    assert shadowed.sum() > 50 and lit.sum() > 300
    np.testing.assert_allclose(col[shadowed], 0.2, rtol=1e-6)
    np.testing.assert_allclose(col[lit], lit_value, rtol=1e-5)
    wall = ~ground  # faces +x, lit by the sun
    assert (col[wall] > 0.2 + 0.5).all()
    unshadowed = bake_lightmap(net, lights, res=res, shadows=False).tiles().reshape(-1, 3)[:, 0]
    np.testing.assert_allclose(unshadowed[shadowed], lit_value, rtol=1e-5)


def test_negative_light_makes_a_dark_spot(hill):
    amb = AmbientLight((0.6, 0.6, 0.6), 1.0)
    centre = hill.evaluate([0.5], [0.5])[0][4, 0]  # middle of the middle patch
    neg = PointLight(tuple(centre + [0, 0, 1.0]), (1, 1, 1), -0.5, range=6.0, shadows=False)
    lm = bake_lightmap(hill, Lights((amb, neg)), res=8)
    tiles = lm.tiles()[..., 0]
    assert tiles[4].min() < 0.4 and tiles[0].min() == pytest.approx(0.6)


# ------------------------------------------------------------------ no LOD popping
def _containing_triangle(mesh, patch_index, u, v):
    """Triangle of ``mesh`` (in the parameter plane of its ``patch_index``-th patch) holding each
    ``(u, v)``, and barycentric weights: ``(k, 3)`` vertex ids and ``(k, 3)`` weights."""
    t0, t1 = mesh.tri_start[patch_index], mesh.tri_start[patch_index + 1]
    tris = mesh.indices[t0:t1].astype(np.int64)
    a, b, c = (mesh.param[tris[:, i]].astype(np.float64) for i in range(3))
    q = np.stack([u, v], 1)[:, None, :]
    v0, v1, v2 = (b - a)[None], (c - a)[None], q - a[None]
    d00 = (v0 * v0).sum(-1)
    d01 = (v0 * v1).sum(-1)
    d11 = (v1 * v1).sum(-1)
    d20 = (v2 * v0).sum(-1)
    d21 = (v2 * v1).sum(-1)
    den = d00 * d11 - d01 * d01
    wb = (d11 * d20 - d01 * d21) / den
    wc = (d00 * d21 - d01 * d20) / den
    w = np.stack([1 - wb - wc, wb, wc], -1)  # (k, t, 3)
    inside = w.min(-1) >= -1e-9
    first = np.argmax(inside, axis=1)
    assert inside.any(axis=1).all()
    k = np.arange(len(u))
    return tris[first], w[k, first]


def test_no_lod_popping_unlike_gouraud():
    """The colour at a surface point looked up from the light map is the same at every
    tessellation level; per-vertex (Gouraud) lighting of the same lights is not."""
    from piste.terrain.tessellate import tessellate

    net = hill_net(2, 2)
    lamp = PointLight((8.0, 9.0, 3.5), (1.0, 0.7, 0.4), 2.0, range=12.0, falloff=2.0)
    lights = Lights((AmbientLight((0.3, 0.3, 0.35), 1.0), DirectionalLight((0.3, 0.4, -0.8)), lamp))
    lm = bake_lightmap(net, lights, res=16)
    net = lm.apply(net)
    rng = np.random.default_rng(0)
    u, v = rng.uniform(0, 1, 300), rng.uniform(0, 1, 300)
    patch = 0
    exact_lookup = lm.sample(np.full(300, patch), u, v)
    looked_up, gouraud, corner_texels = {}, {}, {}
    for level in (4, 6, 8):
        mesh = tessellate(net, level)
        k = int(np.nonzero(mesh.patch_ids == patch)[0][0])
        tri, w = _containing_triangle(mesh, k, u, v)
        uv_lm = (mesh.uv_lightmap[tri].astype(np.float64) * w[..., None]).sum(1)  # the rasteriser's UV
        looked_up[level] = sample_atlas(lm.atlas, uv_lm)
        vcol = shade(lights, mesh.positions.astype(np.float64), mesh.normals.astype(np.float64))
        gouraud[level] = (vcol[tri].astype(np.float64) * w[..., None]).sum(1)
        v0 = mesh.vertex_start[k]
        corner_texels[level] = sample_atlas(lm.atlas, mesh.uv_lightmap[v0 : v0 + 4], "point")
    for level in (4, 6, 8):
        np.testing.assert_allclose(looked_up[level], exact_lookup, atol=1e-5)
        np.testing.assert_array_equal(corner_texels[level], corner_texels[4])  # shared vertices: identical
    lm_pop = max(np.abs(looked_up[a] - looked_up[b]).max() for a, b in ((4, 6), (4, 8), (6, 8)))
    gouraud_pop = max(np.abs(gouraud[a] - gouraud[b]).max() for a, b in ((4, 6), (4, 8), (6, 8)))
    print(f"light map across levels: {lm_pop:.2e}, Gouraud: {gouraud_pop:.3f}")
    assert lm_pop < 1e-5 and gouraud_pop > 0.05, (lm_pop, gouraud_pop)


# ------------------------------------------------------------------ accuracy
def _per_pixel_error(net, lights, res, pos, nrm, want, p, u, v):
    lm = bake_lightmap(net, lights, res=res)
    got = lm.sample(p, u, v, mode="bilinear")
    err = np.abs(got - want)
    return float(err.mean()), float(err.max())


def test_16x16_is_closer_than_8x8():
    """The light map, bilinearly filtered, against the lighting equation (with shadows) evaluated
    per pixel on the exact surface (64 x 64 points per patch)."""
    net = hill_net(3, 3, relief=4.0)
    lights = make_lights()
    t = (np.arange(64) + 0.5) / 64
    vv, uu = np.meshgrid(t, t, indexing="ij")
    u, v = uu.ravel(), vv.ravel()
    pos, nrm = net.evaluate(u, v)
    pos, nrm = pos.reshape(-1, 3), nrm.reshape(-1, 3)
    vis = shadow_visibility(net, lights, pos, nrm, light_terms(lights, pos, nrm))
    want = shade(lights, pos, nrm, vis)
    p = np.repeat(np.arange(len(net)), len(u))
    uu, vv = np.tile(u, len(net)), np.tile(v, len(net))
    mean8, max8 = _per_pixel_error(net, lights, 8, pos, nrm, want, p, uu, vv)
    mean16, max16 = _per_pixel_error(net, lights, 16, pos, nrm, want, p, uu, vv)
    assert mean16 < 0.6 * mean8, (mean8, mean16)
    assert max16 <= max8
    assert mean8 < 0.05
