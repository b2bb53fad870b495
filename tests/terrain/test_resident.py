"""Resident terrain (vertex blocks + shape templates + per-frame index lists), tree culling and
geomorphing: the same triangles as the CPU path, crack-free at every morph factor, numba and numpy
bit-identical."""

import types

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from piste import _jit
from piste.terrain import PatchNet, tessellate
from piste.terrain import _kernels
from piste.terrain.cull import PatchTree
from piste.terrain.resident import ResidentTerrain, _side_seq, uniform_grids
from piste.terrain.tessellate import VERTEX_FLOATS, _cache, open_edges
from piste.transforms import cull_boxes, frustum_planes, look_at, perspective

from nets import TEAPOT, grid_net


def tri_set(positions, indices):
    p = np.asarray(positions, np.float32)[np.asarray(indices, np.int64)]
    return {bytes(t) for t in p.reshape(len(p), -1)}


def random_side_levels(net, pids, rng):
    """Per-edge random level indices 0..2 expanded to the sides of ``pids``, plus the per-edge array."""
    lev = rng.integers(0, 3, net.n_edges)
    return lev[net.side_edge[pids]], lev


def planes_for(eye, target, fov=60.0):
    return frustum_planes(perspective(fov, 1.4, 0.5, 400.0) @ look_at(np.asarray(eye, float), np.asarray(target, float),
                                                                         (0.0, 0.0, 1.0)))


@pytest.mark.parametrize("use_numba", [False, True] if _kernels.HAVE_NUMBA else [False])
def test_tree_cull_equals_flat_cull(use_numba):
    net = grid_net(12, 17, seed=3, flips=False)
    lo, hi = net.patch_bounds
    rng = np.random.default_rng(0)
    for leaf in (1, 4, 16):
        tree = PatchTree(lo, hi, leaf)
        for _ in range(12):
            eye = rng.uniform([-20, -20, 5], [190, 140, 60])
            target = rng.uniform([0, 0, -5], [170, 120, 5])
            pl = planes_for(eye, target, fov=rng.uniform(20, 90))
            flat = np.nonzero(cull_boxes(((lo + hi) / 2).T, ((hi - lo) / 2).T, pl))[0]
            assert np.array_equal(tree.cull(pl, use_numba=use_numba), flat)


def test_resident_frame_has_the_cpu_paths_triangles():
    net = grid_net(4, 5, seed=1)
    r = ResidentTerrain(net)
    rng = np.random.default_rng(2)
    pids = np.sort(rng.choice(len(net), 14, replace=False))
    li, lev = random_side_levels(net, pids, rng)
    m = r.frame(np.zeros(3), patches=pids, side_levels=li, morph=False)
    levels = np.array((4, 6, 8), np.int16)[lev]
    ref = tessellate(net, levels, patches=pids)
    assert m.n_triangles == ref.n_triangles and m.n_vertices == ref.n_vertices
    assert tri_set(r.vertices[:, :3], m.indices) == tri_set(ref.positions, ref.indices)
    assert np.array_equal(np.sort(m.to_mesh().patch_ids), pids)
    kinds = {int(p): int(k) for p, k in zip(ref.patch_ids, ref.patch_kind)}
    assert [kinds[int(p)] for p in m.patch_ids] == m.patch_kind.tolist()


def shared_edges_identical(net, r, m, pos_of):
    """Shared edges of the drawn patches: the same bytes in both patches at their level."""
    where = {int(p): k for k, p in enumerate(m.patch_ids)}
    for e in net.shared_edges:
        rows = []
        for slot in (0, 1):
            p, s = int(net.edge_patches[e, slot]), int(net.edge_sides[e, slot])
            if p not in where:
                break
            n = int(m.patch_levels[where[p], s])
            idx = r.level_offset[n] + _side_seq(n, s) + p * r.block
            if net.side_flip[p, s]:
                idx = idx[::-1]
            rows.append(pos_of(idx))
        if len(rows) == 2:
            assert rows[0].tobytes() == rows[1].tobytes(), f"edge {e} differs between its patches"


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), big=st.booleans(), factor=st.sampled_from(["random", 0.0, 1.0, 0.5]))
def test_geomorph_shared_edges_bit_identical_at_every_factor(seed, big, factor):
    offset = (3.1e4, -2.7e4, 1.2e3) if big else (0, 0, 0)
    net = grid_net(3, 4, seed=seed % 1000, offset=offset)
    r = ResidentTerrain(net)
    rng = np.random.default_rng(seed)
    pids = np.arange(len(net))
    li, lev = random_side_levels(net, pids, rng)
    m = r.frame(np.zeros(3), patches=pids, side_levels=li, morph=True)
    if factor == "random":
        m.factors[:] = rng.uniform(0, 1, m.factors.shape).astype(np.float32)
    else:
        m.factors[:] = factor
    shared_edges_identical(net, r, m, m.morphed_positions)
    pos, idx = m.compact()
    oe = open_edges(types.SimpleNamespace(positions=pos, indices=idx))
    levels = np.array((4, 6, 8))[lev]
    assert len(oe) == int(sum(levels[e] - 1 for e in net.boundary_edges))


def test_morph_targets_lie_on_the_coarser_level():
    net = PatchNet.from_bpt(TEAPOT)
    r = ResidentTerrain(net)
    v = r.vertices.reshape(len(net), r.block, -1)
    # factor 0 puts a level-8 edge vertex on the level-6 edge polyline; level 4 (coarsest) never moves
    lo4 = r.level_offset[4]
    assert np.array_equal(v[:, lo4:lo4 + 16, 0:3], v[:, lo4:lo4 + 16, 3:6])
    for n, c in ((6, 4), (8, 6)):
        o = r.level_offset[n]
        assert np.array_equal(v[:, o:o + 4, 0:3], v[:, o:o + 4, 3:6])  # corners stay
        # side 0 of every patch: targets between consecutive coarse side points (collinear)
        oc = r.level_offset[c]
        coarse = v[:, oc + _side_seq(c, 0), 0:3].astype(np.float64)
        t = np.arange(1, n - 1) / (n - 1) * (c - 1)
        j = np.minimum(np.floor(t).astype(int), c - 2)
        a = (t - j)[None, :, None]
        expect = coarse[:, j] * (1 - a) + coarse[:, j + 1] * a
        got = v[:, o + 4:o + 4 + n - 2, 3:6]
        size = float(np.ptp(net.control_points.reshape(-1, 3), axis=0).max())
        assert np.abs(got - expect).max() < 1e-5 * size
        # the morph moves inner points by less than the coarse level's deviation from the surface
        disp = np.linalg.norm(v[:, o:o + n * n, 0:3] - v[:, o:o + n * n, 3:6], axis=-1)
        assert disp.max() < 0.05 * size and disp.max() > 0


def test_morph_factor_falls_to_zero_at_the_switch():
    """As an edge's distance rises to the threshold, its factor falls continuously to 0 (the
    coarser level's shape), so switching level moves nothing."""
    net = grid_net(3, 3, seed=4, flips=False)
    r = ResidentTerrain(net)
    mid = net.edge_midpoints()
    e = int(net.shared_edges[0])
    direction = np.array([0.0, 0.0, 1.0])
    factors = []
    for d in (10.0, 40.0, 55.0, 59.0, 59.99):
        m = r.frame(mid[e] + direction * d, near=60.0, far=180.0, morph=True)
        k = np.nonzero(net.side_edge[m.patch_ids] == e)
        assert (m.patch_levels[k] == 8).all()
        factors.append(float(m.factors[e]))
    assert factors[0] == 1.0 and factors[-1] < 1e-3
    assert all(a >= b for a, b in zip(factors, factors[1:]))
    m = r.frame(mid[e] + direction * 60.01, near=60.0, far=180.0, morph=True)
    assert (m.patch_levels[np.nonzero(net.side_edge[m.patch_ids] == e)] == 6).all()
    assert m.factors[e] == 1.0


@pytest.mark.skipif(not _kernels.HAVE_NUMBA, reason="numba not installed: only the numpy path exists")
def test_numba_and_numpy_frames_bit_identical():
    _jit.warm_up()
    assert _kernels.side_lod_ready() and _kernels.cull_ready() and _kernels.ready(_kernels._frame_indices_nb)
    net = PatchNet.from_bpt(TEAPOT)
    r = ResidentTerrain(net)
    for eye in ([0, -6, 3], [3, 1, 1], [20, 20, 10]):
        pl = planes_for(eye, [0, 0, 1])
        for lod in (True, False):
            a = r.frame(eye, pl, near=2.0, far=6.0, lod=lod)
            fa = a.factors.copy()
            b = r.frame(eye, pl, near=2.0, far=6.0, lod=lod, use_numba=False)
            assert np.array_equal(a.indices, b.indices) and np.array_equal(a.patch_ids, b.patch_ids)
            assert np.array_equal(fa, b.factors)
            assert np.array_equal(a.patch_levels, b.patch_levels)


@pytest.mark.skipif(not _kernels.HAVE_NUMBA, reason="numba not installed: only the numpy path exists")
@pytest.mark.parametrize("seed", range(3))
def test_compiled_cpu_tessellation_bit_identical_to_numpy(seed):
    _jit.warm_up()
    assert _kernels.gather_ready()  # else both calls below would run numpy
    net = grid_net(4, 5, seed=seed)
    rng = np.random.default_rng(seed)
    levels = rng.choice([4, 6, 8], net.n_edges)
    pids = np.sort(rng.choice(len(net), 13, replace=False))
    for patches in (None, pids):
        a = tessellate(net, levels, patches=patches)
        b = tessellate(net, levels, patches=patches, use_numba=False)
        for k in ("positions", "normals", "uv", "uv_lightmap", "uv_projected", "param", "indices", "patch_ids",
                  "patch_kind", "patch_levels", "vertex_patch", "vertex_start", "tri_start"):
            assert np.array_equal(getattr(a, k), getattr(b, k)), k


@pytest.mark.parametrize("make", [lambda: grid_net(6, 7, seed=5), lambda: grid_net(5, 4, seed=2, flips=False),
                                  lambda: PatchNet.from_bpt(TEAPOT)])
def test_uniform_grids_bit_identical_to_the_vertex_cache(make):
    """The resident blocks' positions and UVs, built without normals, are the vertex cache's bits."""
    net = make()
    rng = np.random.default_rng(7)
    net.lightmap_rect = rng.uniform(0.0, 1.0, (len(net), 4)).astype(np.float32)
    levels = (3, 4, 6, 8)
    got = uniform_grids(net, levels)
    flat, off = _cache(net).grids(net, levels)
    N = len(net)
    for n in levels:
        g = flat[off[n]:off[n] + N * n * n * VERTEX_FLOATS].reshape(N, n * n, VERTEX_FLOATS)
        assert np.array_equal(got[n][0].view(np.uint32), np.ascontiguousarray(g[..., 0:3]).view(np.uint32))
        assert np.array_equal(got[n][1].view(np.uint32), np.ascontiguousarray(g[..., 8:12]).view(np.uint32))


@pytest.mark.parametrize("make", [lambda: grid_net(6, 7, seed=5), lambda: PatchNet.from_bpt(TEAPOT)])
def test_blocks_built_in_chunks_share_every_edge_bit(make):
    """The blocks are built BUILD_CHUNK patches at a time (bounded memory for big nets).  Any chunking
    gives the one-step build's bits at every corner and edge vertex, positions and morph targets (both
    patches of an edge in different chunks: crack-free), the same UVs and slots everywhere; a patch's
    own inner grid is one BLAS product per chunk, whose last bit may depend on the chunk's size."""
    net = make()
    whole = ResidentTerrain(net)
    whole.build_chunk = len(net)
    ref = whole.vertices.reshape(len(net), whole.block, -1)
    shared = np.zeros(whole.block, bool)
    for n, o in whole.level_offset.items():
        shared[o:o + 4 + 4 * (n - 2)] = True
    size = float(np.ptp(ref[..., 0:3].reshape(-1, 3), axis=0).max())
    for chunk in (1, 5, 13):
        r = ResidentTerrain(net)
        r.build_chunk = chunk
        got = r.vertices.reshape(len(net), r.block, -1)
        assert np.array_equal(got[:, shared].view(np.uint32), ref[:, shared].view(np.uint32)), chunk
        assert np.array_equal(got[..., 6:].view(np.uint32), ref[..., 6:].view(np.uint32)), chunk
        assert np.abs(got[..., 0:6] - ref[..., 0:6]).max() <= 1e-6 * size, chunk


def test_budget_counts_the_blocks_only():
    """resident_fits counts the blocks (N x 116 x 44 bytes at levels 4/6/8), not the vertex cache they
    are no longer built from: a 160k-patch net fits the default budget (817 MB of 1 GiB)."""
    from piste.terrain import resident as R

    net = grid_net(3, 3, seed=1)
    need = len(net) * 116 * 44
    assert R.resident_fits(net, budget=need) and not R.resident_fits(net, budget=need - 1)
    assert 160_000 * 116 * R.RESIDENT_FLOATS * 4 <= R.RESIDENT_BUDGET
