"""The flat level below the coarsest (a patch side drawn with its 2 corners when its patches' error
seen from the eye allows): conservative errors, the same choice on the CPU and resident paths,
crack-free against finer neighbours, the CPU path's triangles, numba and numpy identical."""

import types

import numpy as np
import pytest

from piste import _jit
from piste.errors import ConfigError, ValidationError
from piste.terrain import PatchNet, _kernels, tessellate
from piste.terrain import lod
from piste.terrain.resident import ResidentTerrain, uniform_grids
from piste.terrain.tessellate import open_edges

from nets import TEAPOT, grid_net
from test_resident import planes_for, shared_edges_identical, tri_set


def quad_at(c, u, v):
    """The corner quad (triangles (0, 1, 2), (0, 2, 3)) at (u, v): ``c (n, 4, 3)`` -> ``(n, k, 3)``."""
    c0, c1, c2, c3 = (c[:, i][:, None, :] for i in range(4))
    u, v = u[None, :, None], v[None, :, None]
    return np.where(u >= v, c0 + u * (c1 - c0) + v * (c2 - c1), c0 + v * (c3 - c0) + u * (c2 - c3))


@pytest.mark.parametrize("make", [lambda: grid_net(4, 5, seed=3), lambda: PatchNet.from_bpt(TEAPOT)])
def test_patch_error_bounds_the_finer_grids(make):
    """Every level-4/6/8 grid vertex lies within the patch's error of the flat quad at its (u, v)."""
    from piste.terrain.tessellate import get_shape

    net = make()
    err = lod._flat_patch_errors(net)
    grids = uniform_grids(net, (4, 6, 8))
    worst = np.zeros(len(net))
    for n in (4, 8):
        pos = grids[n][0].astype(np.float64)
        prm = get_shape((n,) * 4).param.astype(np.float64)
        d = np.linalg.norm(pos - quad_at(pos[:, :4], prm[:, 0], prm[:, 1]), axis=-1).max(axis=1)
        worst = np.maximum(worst, d)
        size = float(np.ptp(net.control_points.reshape(-1, 3), axis=0).max())
        assert (d <= err + 1e-5 * size).all()
    assert (worst > 0.5 * err).all()  # (the bound samples more (u, v) than the grids, but not far off)
    # level 6 is not sampled; it stays close to the bound
    pos = grids[6][0].astype(np.float64)
    prm = get_shape((6,) * 4).param.astype(np.float64)
    d6 = np.linalg.norm(pos - quad_at(pos[:, :4], prm[:, 0], prm[:, 1]), axis=-1).max(axis=1)
    assert (d6 <= 1.2 * err + 1e-5 * size).all()
    # each edge carries the larger error of its patches and a box holding both
    e_err, e_lo, e_hi = lod.flat_bounds(net)
    plo, phi = net.patch_bounds
    for slot in (0, 1):
        p = net.edge_patches[:, slot]
        ok = p >= 0
        assert (e_err[ok] >= err[p[ok]]).all()
        assert (e_lo[ok] <= plo[p[ok]]).all() and (e_hi[ok] >= phi[p[ok]]).all()


def test_a_plane_seen_from_afar_is_two_triangles_a_patch():
    y, x = np.mgrid[0:13, 0:13] * (10.0 / 3)
    g = np.stack([x, y, 0.01 * x + 0.02 * y], -1)
    net = PatchNet.from_control_grid(g)
    eye = np.array([20.0, 20.0, 500.0])
    lv = lod.edge_levels(net, eye)
    assert (lv == lod.FLAT_LEVEL).all()
    assert (lod.edge_levels(net, eye, flat_error=None) == 4).all()
    r = ResidentTerrain(net)
    m = r.frame(eye)
    assert m.n_triangles == 2 * len(net) and (m.patch_kind == 2).all()
    mesh = tessellate(net, lv)
    assert mesh.n_triangles == 2 * len(net)
    assert r.frame(eye, flat_error=None).n_triangles == 18 * len(net)
    # an edge whose patches' box holds the eye never goes flat, even a plane's (d = 0)
    eye = np.array([21.0, 19.0, 0.59])  # on the plane
    _, lo, hi = lod.flat_bounds(net)
    inside = ((lo <= eye) & (eye <= hi)).all(axis=1)
    lv = lod.edge_levels(net, eye, near=0.0, far=0.0)
    assert inside.any() and (lv[inside] == 4).all() and (lv[~inside] == 2).all()
    assert r.frame(eye, near=0.0, far=0.0).n_triangles > 2 * len(net)


def test_flat_needs_the_error_under_the_angle():
    net = grid_net(5, 5, seed=1, flips=False)
    eye = np.array([25.0, 25.0, 40.0])
    err, lo, hi = lod.flat_bounds(net)
    g = np.maximum(np.maximum(lo - eye, eye - hi), 0.0)
    d = np.sqrt((g * g).sum(1))
    for tol in (1e-4, 1e-3, 1e-2, 0.05, 0.3):
        lv = lod.edge_levels(net, eye, near=0.0, far=0.0, flat_error=tol)
        assert np.array_equal(lv == 2, err < tol * d)
    assert 0 < (lod.edge_levels(net, eye, near=0.0, far=0.0, flat_error=0.05) == 2).sum() < net.n_edges
    # fine and medium edges too: flat under the angle, else the coarse level when its mesh is within
    # it, else what the distance says
    e4 = lod.level_errors(net, 4)
    assert (e4 <= err + 1e-9).all()  # (the finer mesh is the closer one here)
    for tol in (1e-3, 0.02, 0.05, 0.2):
        for near, far, by_distance in ((1e4, 1e4, 8), (0.0, 1e4, 6)):
            lv = lod.edge_levels(net, eye, near=near, far=far, flat_error=tol)
            want = np.where(err < tol * d, 2, np.where(e4 < tol * d, 4, by_distance))
            assert np.array_equal(lv, want)
    assert {2, 4, 8} <= {int(x) for tol in (0.01, 0.05) for x in
                         lod.edge_levels(net, eye, near=1e4, far=1e4, flat_error=tol)}
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ConfigError):
            lod.edge_levels(net, eye, flat_error=bad)
        with pytest.raises(ConfigError):
            ResidentTerrain(net).frame(eye, flat_error=bad)


@pytest.mark.parametrize("seed", range(3))
def test_resident_flat_sides_have_the_cpu_paths_triangles(seed):
    net = grid_net(4, 5, seed=seed)
    r = ResidentTerrain(net)
    rng = np.random.default_rng(seed)
    pids = np.sort(rng.choice(len(net), 14, replace=False))
    lev = rng.integers(-1, 3, net.n_edges)
    m = r.frame(np.zeros(3), patches=pids, side_levels=lev[net.side_edge[pids]], morph=False)
    levels = np.array((4, 6, 8, 2), np.int16)[lev]
    ref = tessellate(net, levels, patches=pids)
    assert m.n_triangles == ref.n_triangles and m.n_vertices == ref.n_vertices
    assert tri_set(r.vertices[:, :3], m.indices) == tri_set(ref.positions, ref.indices)
    kinds = {int(p): int(k) for p, k in zip(ref.patch_ids, ref.patch_kind)}
    assert [kinds[int(p)] for p in m.patch_ids] == m.patch_kind.tolist()
    assert np.array_equal(m.edge_levels()[net.side_edge[pids]], levels[net.side_edge[pids]])
    with pytest.raises(ValidationError):
        r.frame(np.zeros(3), patches=pids, side_levels=np.full((len(pids), 4), -2), morph=False)


@pytest.mark.parametrize("seed", range(4))
def test_flat_sides_crack_free_at_every_morph_factor(seed):
    net = grid_net(3, 4, seed=seed)
    r = ResidentTerrain(net)
    rng = np.random.default_rng(seed)
    pids = np.arange(len(net))
    lev = rng.integers(-1, 3, net.n_edges)
    m = r.frame(np.zeros(3), patches=pids, side_levels=lev[net.side_edge], morph=True)
    m.factors[:] = rng.uniform(0, 1, m.factors.shape).astype(np.float32)
    shared_edges_identical(net, r, m, m.morphed_positions)
    pos, idx = m.compact()
    oe = open_edges(types.SimpleNamespace(positions=pos, indices=idx))
    levels = np.array((4, 6, 8, 2))[lev]
    assert len(oe) == int(sum(levels[e] - 1 for e in net.boundary_edges))


def test_resident_and_cpu_paths_choose_the_same_flat_edges():
    net = grid_net(8, 9, seed=6, flips=False)
    r = ResidentTerrain(net)
    seen = set()
    for tol in (0.02, 0.05):
        for eye in ([40.0, 45.0, 30.0], [-60.0, 10.0, 80.0], [200.0, 200.0, 5.0]):
            eye = np.asarray(eye)
            pl = planes_for(eye, [40.0, 45.0, 0.0], fov=80.0)
            m = r.frame(eye, pl, near=20.0, far=40.0, flat_error=tol, use_numba=False)
            lv = lod.edge_levels(net, eye, near=20.0, far=40.0, flat_error=tol)
            assert np.array_equal(m.patch_levels, lv[net.side_edge[m.patch_ids]])
            seen |= set(np.unique(m.patch_levels).tolist())
    assert {2, 4, 6} <= seen


@pytest.mark.skipif(not _kernels.HAVE_NUMBA, reason="numba not installed: only the numpy path exists")
def test_flat_numba_and_numpy_frames_bit_identical():
    _jit.warm_up()
    assert _kernels.side_lod_ready()
    net = grid_net(8, 9, seed=2)
    r = ResidentTerrain(net)
    flat = False
    for eye in ([40.0, 45.0, 30.0], [-60.0, 10.0, 80.0]):
        pl = planes_for(eye, [40.0, 45.0, 0.0], fov=80.0)
        for tol in (None, 0.01, 0.05):
            a = r.frame(eye, pl, near=20.0, far=40.0, flat_error=tol)
            fa = a.factors.copy()
            b = r.frame(eye, pl, near=20.0, far=40.0, flat_error=tol, use_numba=False)
            assert np.array_equal(a.indices, b.indices) and np.array_equal(a.patch_levels, b.patch_levels)
            assert np.array_equal(fa, b.factors)
            flat |= bool((a.patch_levels == 2).any())
    assert flat


def test_patch_bounds_computed_once_for_what_is_kept_from_them(monkeypatch):
    """The flat level's edge boxes and the culling tree are kept on the net, and so are the per-patch
    bounds both are made from: computed once (two folds, min and max), the same values."""
    import piste.terrain.net as net_mod
    from piste.terrain.cull import patch_tree

    net = grid_net(4, 5, seed=3)
    want = net.patch_bounds
    folds = []
    real = net_mod._fold
    monkeypatch.setattr(net_mod, "_fold", lambda *a: folds.append(1) or real(*a))
    tree = patch_tree(net)
    err, lo, hi = lod.flat_bounds(net)
    assert len(folds) == 2
    assert all(np.array_equal(a, b) for a, b in zip(lod.kept_patch_bounds(net), want))
    assert np.array_equal(tree.lo_sorted, want[0][tree.order])
    ep = net.edge_patches
    other = np.where(ep[:, 1] >= 0, ep[:, 1], ep[:, 0])
    assert np.array_equal(lo, np.minimum(want[0][ep[:, 0]], want[0][other]))
    folds.clear()
    for a, b in zip(lod.kept_bounds(net), net.bounds):  # the net's bounds from them: no fold, the same values
        assert a.shape == (3,) and a.dtype == np.float64 and np.array_equal(a, b)
    assert not folds
