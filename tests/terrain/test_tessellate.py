import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from piste.errors import ValidationError
from piste.terrain import PatchNet, decode_strips, get_shape, tessellate
from piste.terrain.net import SIDE_CORNERS
from piste.terrain.tessellate import open_edges, weld_exact

from nets import TEAPOT, grid_net


def side_vertices(mesh, k, s):
    """Vertex indices along side s of the k-th tessellated patch, in the side's direction."""
    sh = get_shape(tuple(mesh.patch_levels[k]))
    base = mesh.vertex_start[k]
    a, b = SIDE_CORNERS[s]
    o = 4 + sh.side_off[s]
    return np.concatenate([[a], np.arange(o, o + sh.levels[s] - 2), [b]]) + base


def check_crack_free(net, levels, mesh):
    """Shared edges bit-identical in both patches; open mesh edges only on the true boundary."""
    where = {int(p): k for k, p in enumerate(mesh.patch_ids)}
    for e in net.shared_edges:
        rows = []
        for slot in (0, 1):
            p, s = net.edge_patches[e, slot], net.edge_sides[e, slot]
            idx = side_vertices(mesh, where[p], s)
            if net.side_flip[p, s]:
                idx = idx[::-1]
            rows.append(mesh.positions[idx])
        assert rows[0].tobytes() == rows[1].tobytes(), f"edge {e} differs between its patches"
    lv = np.broadcast_to(levels, (net.n_edges,))
    expected = int(sum(lv[e] - 1 for e in net.boundary_edges))
    oe = open_edges(mesh)
    assert len(oe) == expected, f"{len(oe)} open mesh edges, the net's boundary has {expected}"
    # every open edge's vertices lie on a boundary side of their patch
    boundary_side = np.zeros((len(net), 4), bool)
    for e in net.boundary_edges:
        boundary_side[net.edge_patches[e, 0], net.edge_sides[e, 0]] = True
    prm = mesh.param[oe.ravel()]
    patch = mesh.patch_ids[mesh.vertex_patch[oe.ravel()]]
    on = np.stack([prm[:, 1] == 0, prm[:, 0] == 1, prm[:, 1] == 1, prm[:, 0] == 0], 1) & boundary_side[patch]
    assert on.any(axis=1).all()


def test_uniform_counts():
    net = grid_net(2, 3, flips=False)
    for n, tris in ((4, 18), (6, 50), (8, 98)):
        m = tessellate(net, n)
        assert m.n_triangles == 6 * tris
        assert m.n_vertices == 6 * n * n
        assert (m.patch_kind == n).all()


def test_glue_patch_structure():
    sh = get_shape((8, 4, 6, 8))
    assert not sh.uniform and sh.m == 8
    # inner mesh (m-2)^2 points, 2 (m-3)^2 triangles; strips (n-1)+(m-3) triangles each
    assert len(sh.tris) == 2 * 5 * 5 + sum((n - 1) + 5 for n in (8, 4, 6, 8))
    # glue patches tile the parameter square exactly: triangle areas sum to 1, all counter-clockwise
    p = sh.param.astype(np.float64)
    a, b, c = p[sh.tris[:, 0]], p[sh.tris[:, 1]], p[sh.tris[:, 2]]
    area = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    assert (area > 0).all()
    assert np.isclose(area.sum(), 1.0)


@settings(max_examples=25, deadline=None)
@given(
    rows=st.integers(1, 4),
    cols=st.integers(1, 4),
    seed=st.integers(0, 2**31 - 1),
    choices=st.sampled_from([(4, 6, 8), (2, 3, 4, 5, 6, 7, 8), (4, 8)]),
    big=st.booleans(),
    cache=st.booleans(),
)
def test_random_nets_are_crack_free(rows, cols, seed, choices, big, cache):
    offset = (3.1e4, -2.7e4, 1.2e3) if big else (0, 0, 0)
    net = grid_net(rows, cols, seed=seed, offset=offset)
    levels = np.random.default_rng(seed).choice(choices, net.n_edges).astype(np.int16)
    mesh = tessellate(net, levels, cache=cache)
    check_crack_free(net, levels, mesh)
    assert np.isfinite(mesh.positions).all()
    assert np.allclose(np.linalg.norm(mesh.normals, axis=1), 1, atol=1e-5)


@pytest.mark.parametrize("seed", range(6))
def test_teapot_crack_free_every_level_mix(seed):
    net = PatchNet.from_bpt(TEAPOT)
    levels = np.random.default_rng(seed).choice([4, 6, 8], net.n_edges)
    mesh = tessellate(net, levels)
    check_crack_free(net, levels, mesh)
    assert np.allclose(np.linalg.norm(mesh.normals, axis=1), 1, atol=1e-5)
    # the lid's apex: degenerate corner, still a valid (upward) unit normal
    apex = np.all(np.abs(mesh.positions - [0, 0, 3.15]) < 1e-6, axis=1)
    assert apex.any() and (np.abs(mesh.normals[apex, 2]) > 0.99).all()
    assert len(np.unique(np.sign(mesh.normals[apex, 2]))) == 1


def test_positions_match_exact_surface():
    net = grid_net(3, 3, seed=4)
    levels = np.random.default_rng(0).choice([4, 6, 8], net.n_edges)
    mesh = tessellate(net, levels)
    pid = mesh.patch_ids[mesh.vertex_patch]
    from piste.terrain.bezier import bernstein

    ref = np.einsum("vijc,vi,vj->vc", net.control_points[pid], bernstein(mesh.param[:, 0]), bernstein(mesh.param[:, 1]))
    assert np.abs(mesh.positions - ref).max() < 1e-4


def test_uv_sets():
    net = grid_net(2, 2, flips=False)
    net.uv[:] = [(0, 0), (2, 0), (2, 3), (0, 3)]
    mesh = tessellate(net, 6)
    u, v = mesh.param[:, 0], mesh.param[:, 1]
    assert np.allclose(mesh.uv, np.stack([2 * u, 3 * v], 1), atol=1e-6)
    r = net.lightmap_rect[mesh.patch_ids[mesh.vertex_patch]]
    assert np.allclose(mesh.uv_lightmap, r[:, :2] + mesh.param * (r[:, 2:] - r[:, :2]), atol=1e-6)
    assert mesh.uv_projected.min() >= -1e-6 and mesh.uv_projected.max() <= 1 + 1e-6


def test_subset_and_strips():
    net = grid_net(4, 4, seed=9)
    levels = np.random.default_rng(1).choice([4, 6, 8], net.n_edges)
    sub = np.array([0, 5, 6, 10, 15])
    mesh = tessellate(net, levels, patches=sub, strips=True)
    assert sorted(mesh.patch_ids.tolist()) == sorted(sub.tolist())
    tri = decode_strips(mesh.strips)
    canon = lambda t: {tuple(np.roll(x, -int(np.argmin(x)))) for x in t.tolist()}
    assert canon(tri) == canon(mesh.indices)
    # strip vertices sent per triangle is well below the 3 of a plain list
    assert len(mesh.strips) / len(mesh.indices) < 2.0
    # patch blocks: triangles of patch k only reference its own vertices
    k = 2
    t = mesh.indices[mesh.tri_start[k]:mesh.tri_start[k + 1]]
    assert t.min() >= mesh.vertex_start[k] and t.max() < mesh.vertex_start[k + 1]


def test_bad_levels():
    net = grid_net(1, 1)
    with pytest.raises(ValidationError, match="one per edge"):
        tessellate(net, np.array([4, 4]))
    with pytest.raises(ValidationError, match="2..64"):
        tessellate(net, 1)
    with pytest.raises(ValidationError, match="patch ids"):
        tessellate(net, 4, patches=[7])


def test_weld_exact():
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 0]], np.float32)
    ids = weld_exact(p)
    assert ids[0] == ids[2] != ids[1]


def test_vertex_cache_matches_evaluation():
    """Cached and evaluated tessellations agree: corners and edges bit for bit, inner points to
    float32 rounding (BLAS may sum a batch of a different size in another order)."""
    net = PatchNet.from_bpt(TEAPOT)
    for seed in range(3):
        levels = np.random.default_rng(seed).choice([4, 6, 8], net.n_edges)
        a = tessellate(net, levels, cache=False)
        b = tessellate(net, levels, cache=True)
        for f in ("param", "indices", "patch_ids"):
            assert np.array_equal(getattr(a, f), getattr(b, f)), f
        for f in ("uv", "uv_lightmap", "uv_projected"):
            assert np.allclose(getattr(a, f), getattr(b, f), atol=1e-6), f
        assert np.allclose(a.positions, b.positions, atol=1e-5) and np.allclose(a.normals, b.normals, atol=1e-5)
        p = a.param
        on_edge = (p == 0).any(axis=1) | (p == 1).any(axis=1)
        assert np.array_equal(a.positions[on_edge], b.positions[on_edge])


def test_vertex_cache_follows_uv_changes():
    net = grid_net(2, 2, flips=False)
    before = tessellate(net, 4, cache=True).uv_lightmap.copy()
    net.lightmap_rect[:] = [0.25, 0.25, 0.5, 0.5]
    after = tessellate(net, 4, cache=True)
    assert not np.array_equal(before, after.uv_lightmap)
    assert np.array_equal(after.uv_lightmap, tessellate(net, 4, cache=False).uv_lightmap)


@pytest.mark.parametrize("cache", [True, False])
def test_fitted_dem_is_crack_free(cache):
    """Real data: a net fitted to matplotlib's Jacksboro fault DEM, random per-edge levels."""
    from matplotlib.cbook import get_sample_data

    from piste.terrain import fit_heightfield

    dem = get_sample_data("jacksboro_fault_dem.npz")
    z = np.asarray(dem["elevation"], dtype=np.float64)[:81, :97]
    net = fit_heightfield(z, 10.0)
    assert len(net) == 20 * 24
    levels = np.random.default_rng(7).choice([4, 6, 8], net.n_edges)
    mesh = tessellate(net, levels, cache=cache)
    check_crack_free(net, levels, mesh)
