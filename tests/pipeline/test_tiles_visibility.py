"""A tiled world's visibility sets (issue 26): eyes over a tile, targets and occluders the tile and
its neighbours, occluders lowered to the coarse meshes the streaming renderer may draw, extra eye
heights so steep cells keep sets; the lit file says whose patches the bits are."""

from __future__ import annotations

import json

import numpy as np
import pytest

from piste.errors import ConfigError
from piste.pipeline.tiled_build import SyntheticSource, build_tiles, synthetic_spec
from piste.pipeline.visibility import compute_visibility, drawn_floor
from piste.terrain.net import PatchNet
from piste.terrain.query import height_at
from piste.terrain.tiles import TileError, TileStore, neighbourhood_net, npz_bytes, triangulated_heights


@pytest.fixture(scope="module")
def rough(tmp_path_factory):
    """12 x 12 patches of 300 m relief in 3 x 3 tiles of 4 x 4 patches, sets in 40 m cells."""
    root = tmp_path_factory.mktemp("tilevis") / "w.tiles"
    spec = synthetic_spec(root, 12, tile_patches=4, res=2, spacing=20.0, shadows=False, cell=40.0)
    spec.source = SyntheticSource(spec.source.shape, spec.source.spacing, 0, relief=300.0, wavelength=300.0)
    build_tiles(spec)
    return spec


def test_drawn_floor_is_the_lowest_triangulated_mesh(rough):
    store, g = TileStore(rough.root), rough.grid
    ring, _ = neighbourhood_net(store, g, 1, 1)
    rng = np.random.default_rng(0)
    patch = rng.integers(0, len(ring), 400)
    uv = rng.uniform(0.0, 1.0, (400, 2))
    from piste.terrain.bezier import evaluate, grid_params

    for m in (2, 3, 4):
        gu, gv = grid_params(m)
        z = evaluate(ring.control_points, gu, gv, normals=False)[..., 2].reshape(len(ring), m, m)
        t = np.linspace(0.0, 1.0, 7)  # on a 7 x 7 parameter grid: triangulated_heights' own answer
        want = triangulated_heights(z, t)
        ii, jj = np.meshgrid(np.arange(7), np.arange(7))
        pts = np.stack([t[ii.ravel()], t[jj.ravel()]], 1)
        got = drawn_floor(ring, np.zeros(49, np.int64), pts, (m,))
        assert np.allclose(got, want[0][jj.ravel(), ii.ravel()])
    floor = drawn_floor(ring, patch, uv, (2, 3, 4))
    assert np.isfinite(floor).all()
    assert np.array_equal(floor, np.minimum.reduce([drawn_floor(ring, patch, uv, (m,)) for m in (2, 3, 4)]))


def test_region_sets_see_the_neighbours_and_levels_only_add(rough):
    store, g = TileStore(rough.root), rough.grid
    ring, centre = neighbourhood_net(store, g, 1, 1)
    region = g.tile_bounds_xy(1, 1)
    own = compute_visibility(PatchNet(ring.control_points[centre]), cell=40.0, method="horizon", azimuths=180)
    exact = compute_visibility(ring, cell=40.0, method="horizon", azimuths=180, region=region)
    coarse = compute_visibility(ring, cell=40.0, method="horizon", azimuths=180, region=region, levels=(2, 3, 4))
    assert exact.shape == own.shape and np.allclose(exact.origin, region[:2])  # cells over the tile alone
    assert exact.n_patches == len(ring) == 9 * len(centre)
    m_own, m_ex, m_co = own.patch_matrix(), exact.patch_matrix(), coarse.patch_matrix()
    assert not m_ex.all()  # some neighbour patches are hidden from over the tile
    assert (m_ex[:, centre] <= m_own).all()  # more occluders: never more of its own patches seen
    assert (m_ex <= m_co).all() and (m_co.sum() > m_ex.sum())  # lowered occluders: more seen, never less
    with pytest.raises(ConfigError, match="region must be"):
        compute_visibility(ring, cell=40.0, region=(0.0, 0.0, 1e6, 10.0))


def test_cover_ground_adds_heights_up_to_the_steepest_cell(rough):
    store, g = TileStore(rough.root), rough.grid
    ring, _ = neighbourhood_net(store, g, 1, 1)
    region = g.tile_bounds_xy(1, 1)
    v = compute_visibility(ring, cell=40.0, eye_heights=(1.7, 9.0), method="horizon", azimuths=180, region=region,
                           cover_ground=True)
    assert v.eye_heights[:2] == (1.7, 9.0) and len(v.eye_heights) > 2
    # an eye 2 m over the highest sampled ground of any cell is within the band
    xs = np.linspace(region[0] + 1.0, region[2] - 1.0, 24)
    ys = np.linspace(region[1] + 1.0, region[3] - 1.0, 24)
    xy = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    z, hit, _, _ = height_at(ring, xy)
    inside = [v.in_band(np.array([x, y, zz + 2.0])) for (x, y), zz in zip(xy, z)]
    assert np.mean(inside) > 0.95
    assert v.level_bits is not None and len(v.level_bits) == len(v.eye_heights) - 1


def test_the_build_says_whose_patches_the_bits_are(rough, tmp_path):
    import shutil

    from piste.render.streaming import TileCache

    store, g = TileStore(rough.root), rough.grid
    a = store.read("lit", 1, 1)
    meta = json.loads(str(a["vis_meta"]))
    assert meta["tiles"] == [[y, x, 16] for y in range(3) for x in range(3)] and meta["levels"] == [2, 3, 4]
    assert a["vis_patch_bits"].shape[1] == (9 * 16 + 7) // 8
    corner = json.loads(str(store.read("lit", 0, 0)["vis_meta"]))
    assert corner["tiles"] == [[0, 0, 16], [0, 1, 16], [1, 0, 16], [1, 1, 16]]
    root = tmp_path / "w.tiles"
    shutil.copytree(rough.root, root)
    cache = TileCache(root)
    try:
        sets = cache._read_vis((1, 1))
        assert sets.tiles[(1, 1)] == (4 * 16, 16) and sets.levels == (2, 3, 4)
        bad = dict(meta, tiles=[[y, x, 16] for y in range(3) for x in range(3)][:-1] + [[0, 0, 16]])
        b = dict(store.read("lit", 1, 1))
        b["vis_meta"] = np.array(json.dumps(bad))
        TileStore(root).path("lit", 1, 1).write_bytes(npz_bytes({"key": np.array("x"), **b}))
        with pytest.raises(TileError, match="visibility sets list tile") as exc:
            cache._read_vis((1, 1))
        assert exc.value.field == "vis_meta"
    finally:
        cache.close()
