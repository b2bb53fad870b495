"""Shadows across tiles: a tiled bake sees occluders beyond its 3 x 3 neighbourhood through the
world's far heights (a ridge three tiles away shadows a valley as the non-tiled bake does)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from piste.lighting.lights import AmbientLight, DirectionalLight, Lights, dumps_lights
from piste.lighting.shadows import far_field_occluded
from piste.pipeline import tiled_build
from piste.pipeline.tiled_build import ArraySource, TiledSpec, _bake_tile, build_tiles, far_heights
from piste.terrain.tiles import TileError, TileGrid, TileStore

SPP, TP, SP = 3, 4, 10.0  # samples a patch, patches a tile, metres a sample: tiles of 120 m
TILE_M = TP * SPP * SP


def _ridge_world(root, elevation: float, far_shadows: bool = True) -> TiledSpec:
    """7 x 3 tiles: a 250 m ridge along y in tile column 4 (x = 540 m), lower ground elsewhere; a
    sun from +x at ``elevation`` degrees.  Tile (1, 1) (x 120..240 m) lies three tiles from the ridge."""
    nx, ny = 7 * TP * SPP + 1, 3 * TP * SPP + 1
    x, y = np.meshgrid(np.arange(nx) * SP, np.arange(ny) * SP)
    z = 250.0 * np.exp(-((x - 4.5 * TILE_M) / 45.0) ** 2) + 5.0 * np.sin(y / 70.0)
    e = np.radians(elevation)
    lights = Lights((AmbientLight(color=(0.3, 0.3, 0.35)), DirectionalLight(direction=(-np.cos(e), 0.0, -np.sin(e)))))
    grid = TileGrid((ny, nx), SPP, TP, (SP, SP))
    return TiledSpec(str(root), ArraySource(z, (SP, SP)), grid, dumps_lights(lights), res=4, shadows=True,
                     far_shadows=far_shadows)


def _shadowed(texels: np.ndarray, lit: np.ndarray) -> np.ndarray:
    """Texels in the sun's shadow: over 15 grey levels darker than the same texels all sun-lit
    (``lit``; the sun lights the valley ~3x brighter than the sky alone): (n, res, res) bool."""
    return texels[..., 1].astype(int) < lit[..., 1].astype(int) - 15


@pytest.mark.parametrize("elevation", [12.0, 34.8])
def test_ridge_three_tiles_away_shadows_the_valley_as_the_single_bake_does(tmp_path, elevation):
    spec = _ridge_world(tmp_path / "w", elevation)
    r = build_tiles(spec)
    assert r.lit[(1, 1)]["far_rays"] > 0
    tiled = TileStore(spec.root).read("lit", 1, 1)["texels"]
    # the reference: the same tile's samples, shading and encoding, shadow rays against every exact
    # patch of the world (a non-tiled bake); and the bake as it was (occluders within one tile only)
    ref, _ = _bake_tile(replace(spec, far_shadows=False), 1, 1, halo=99)
    near, _ = _bake_tile(replace(spec, far_shadows=False), 1, 1, halo=1)
    ref, near = ref["texels"], near["texels"]
    sr = _shadowed(ref, near)
    assert sr.mean() > 0.4  # the ridge's shadow covers the valley, or part of it
    d_near = np.abs(near.astype(int) - ref.astype(int))
    d_tiled = np.abs(tiled.astype(int) - ref.astype(int))
    assert d_near.mean() > 20.0  # today: lit where the single bake is in shadow
    # tolerance: a mean of 10 grey levels, the shadow's edge within two texel lines across the tile
    # (the far heights are the patch-corner grid: chords 30 m long round off the ridge's crest)
    assert d_tiled.mean() <= 10.0
    side = TP * spec.res
    assert abs(int(_shadowed(tiled, near).sum()) - int(sr.sum())) <= 2 * side
    if elevation < 20.0:  # the whole valley in shadow: exactly the single bake's texels
        assert np.array_equal(tiled, ref)


def test_far_shadows_off_is_the_old_bake_and_changes_the_key(tmp_path):
    on, off = _ridge_world(tmp_path / "a", 34.8), _ridge_world(tmp_path / "b", 34.8, far_shadows=False)
    assert on.lit_key(1, 1) != off.lit_key(1, 1)
    build_tiles(off)
    assert not (tmp_path / "b" / "far").exists()
    assert off.uses_far_heights is False and on.uses_far_heights is True


@pytest.mark.parametrize("max_cells", [7, 5])  # strides 16 (even) and 23 (odd, nodes beyond the edge)
def test_far_heights_are_the_surface_grid_and_max_pooled_beyond_the_limit(tmp_path, monkeypatch, max_cells):
    spec = _ridge_world(tmp_path / "w", 30.0)
    build_tiles(spec)
    far = far_heights(spec)
    h, frame = far["heights"], far["frame"]
    z = spec.source.z
    k = tiled_build.FAR_SUBDIV  # points a patch side - 1: 28 x 12 patches -> 28 k x 12 k cells
    assert h.shape == (12 * k + 1, 28 * k + 1) and np.allclose(frame, [0.0, 0.0, 30.0 / k, 30.0 / k])
    assert np.allclose(h[::k, ::k], z[::SPP, ::SPP], atol=1.0)  # the fitted corners follow the samples
    monkeypatch.setattr(tiled_build, "FAR_MAX_CELLS", max_cells)
    pooled = far_heights(spec)
    hp, st = pooled["heights"], -(-28 * k // max_cells)
    assert hp.shape == (-(-12 * k // st) + 1, -(-28 * k // st) + 1)
    assert np.allclose(pooled["frame"], [0.0, 0.0, 30.0 / k * st, 30.0 / k * st])
    # each node: the highest point within half a stride of it, the grid edge-padded beyond its end
    pad = np.pad(h, ((0, (hp.shape[0] - 1) * st + st), (0, (hp.shape[1] - 1) * st + st)), mode="edge")
    for i in range(hp.shape[0]):
        for j in range(hp.shape[1]):
            r0, c0 = max(st * i - st // 2, 0), max(st * j - st // 2, 0)
            assert hp[i, j] == pad[r0:st * i + st // 2 + 1, c0:st * j + st // 2 + 1].max()


def test_far_heights_stale_or_torn_is_a_tile_error(tmp_path):
    spec = _ridge_world(tmp_path / "w", 30.0)
    build_tiles(spec)
    p = TileStore(spec.root).path("far", 0, 0)
    p.write_bytes(p.read_bytes()[:200])
    tiled_build._FAR_CACHE.clear()
    with pytest.raises(TileError, match="far"):
        tiled_build._bake_tile(spec, 1, 1)


def test_far_field_occluded_marches_only_outside_the_box():
    h = np.zeros((11, 11))
    h[:, 8] = 100.0  # a wall at x = 80
    o = np.array([[10.0, 50.0, 0.0], [10.0, 50.0, 0.0], [10.0, 50.0, 0.0], [90.0, 50.0, 0.0]])
    up = np.array([0.7, 0.0, 0.7]) / np.hypot(0.7, 0.7)  # 45 degrees: at x = 80 the ray is 70 m up
    d = np.array([[1.0, 0.0, 0.2], up, [-1.0, 0.0, 0.2], [1.0, 0.0, 0.2]])
    d[0] /= np.linalg.norm(d[0])
    d[2] /= np.linalg.norm(d[2])
    d[3] /= np.linalg.norm(d[3])
    occ = far_field_occluded(h, (0.0, 0.0), (10.0, 10.0), o, d, (0.0, 0.0, 30.0, 100.0))
    assert occ.tolist() == [True, True, False, False]  # low and 45-degree rays hit the wall; away/past: lit
    # the wall (bilinear: its foot from x = 70 to 90) inside the excluded box is not an occluder
    assert not far_field_occluded(h, (0.0, 0.0), (10.0, 10.0), o[:1], d[:1], (0.0, 0.0, 95.0, 100.0)).any()
    # a steeper ray clears it
    steep = np.array([[1.0, 0.0, 2.0]]) / np.sqrt(5.0)
    assert not far_field_occluded(h, (0.0, 0.0), (10.0, 10.0), o[:1], steep, (0.0, 0.0, 30.0, 100.0)).any()


def test_far_shadows_and_objects_are_byte_identical_on_dask_workers(tmp_path):
    """The far heights (one task after every fit) and the per-tile objects: a 2-process Dask build
    writes the bytes of the local one (the far task ran, the valley tile was shadowed from afar)."""
    distributed = pytest.importorskip("distributed")
    from piste.pipeline.dask_build import build_tiles_dask
    from piste.pipeline.tile_objects import DEFAULT_RULES

    local = replace(_ridge_world(tmp_path / "local", 34.8), objects=DEFAULT_RULES)
    build_tiles(local)
    spec = replace(_ridge_world(tmp_path / "dask", 34.8), objects=DEFAULT_RULES)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, protocol="tcp://",
                                  host="127.0.0.1", dashboard_address="127.0.0.1:0") as cluster, \
            distributed.Client(cluster) as client:
        r = build_tiles_dask(spec, client)
    assert r.lit[(1, 1)]["far_rays"] > 0 and sum(v["objects"] for v in r.lit.values()) > 0

    def files(root):
        return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}

    a, b = files(tmp_path / "local"), files(tmp_path / "dask")
    assert "far/t_0000_0000.npz" in a and a == b


def test_low_sun_over_a_fractal_range_matches_the_whole_world_bake(tmp_path):
    """A seeded fractal range (synthetic_spec: 40 x 40 patches of 30 m in 5 x 5 tiles) under a sun 8
    degrees up: tiles whose texels today (3 x 3 occluders) differ from the whole-world exact bake
    agree with it once the far heights are marched."""
    from piste.pipeline.tiled_build import synthetic_spec

    e, az = np.radians(8.0), np.radians(30.0)
    lights = Lights((AmbientLight(color=(0.3, 0.3, 0.35)),
                     DirectionalLight(direction=(-np.cos(e) * np.cos(az), -np.cos(e) * np.sin(az), -np.sin(e)))))
    spec = replace(synthetic_spec(tmp_path / "w", 40, tile_patches=8, res=4, shadows=True),
                   lights_toml=dumps_lights(lights))
    build_tiles(spec)
    store = TileStore(spec.root)
    off_before = off_after = checked = 0
    for tile in [(0, 0), (0, 2), (2, 0), (1, 1), (2, 2)]:  # downwind of the range (the sun comes from +x, +y)
        ref = _bake_tile(replace(spec, far_shadows=False), *tile, halo=99)[0]["texels"].astype(int)
        near = _bake_tile(replace(spec, far_shadows=False), *tile, halo=1)[0]["texels"].astype(int)
        tiled = store.read("lit", *tile)["texels"].astype(int)
        off_before += int((np.abs(near - ref) > 2).sum())
        off_after += int((np.abs(tiled - ref) > 2).sum())
        checked += ref.size
    assert off_before > 0.01 * checked  # today: long shadows cut off at the neighbourhood's edge
    assert off_after <= 0.001 * checked
