"""Scene objects in tiled worlds: placed by rules per tile at build time, stored in the tile's lit
file, the same whatever the tiling, order or worker, checked when read back."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest

from piste.errors import ValidationError
from piste.pipeline.tile_objects import ObjectRule, object_set, place_tile_objects
from piste.pipeline.tiled_build import ArraySource, TiledSpec, build_tiles, lit_task
from piste.terrain.tiles import TileError, TileGrid, TileStore, npz_bytes, read_tile_objects
from piste.world.objects import OBJECT_KINDS

SPP, SP = 3, 10.0


def _world(root, tile_patches: int = 4, rules=None, seed: int = 0) -> TiledSpec:
    """24 x 24 patches (720 m): a plain rising east, a 35-degree-plus wall beyond x = 480 m."""
    n = 24 * SPP + 1
    x, y = np.meshgrid(np.arange(n) * SP, np.arange(n) * SP)
    z = 0.05 * x + 3.0 * np.sin(y / 90.0) + np.where(x > 480.0, (x - 480.0) * 0.9, 0.0)
    grid = TileGrid((n, n), SPP, tile_patches, (SP, SP))
    rules = rules if rules is not None else (ObjectRule("tree", 20.0, slope=(0.0, 20.0), altitude=(-1e9, 30.0)),
                                             ObjectRule("rock", 10.0, slope=(30.0, 60.0)))
    return TiledSpec(str(root), ArraySource(z, (SP, SP)), grid, "", res=2, shadows=False, objects=rules,
                     object_seed=seed)


def _objects(spec) -> tuple[np.ndarray, np.ndarray]:
    store = TileStore(spec.root)
    parts = [read_tile_objects(store, spec.grid, ty, tx, len(OBJECT_KINDS)) for ty, tx in spec.grid.tiles()]
    kind = np.concatenate([p[0] for p in parts])
    mat = np.concatenate([p[1] for p in parts])
    order = np.lexsort((mat[:, 1, 3], mat[:, 0, 3], kind))
    return kind[order], mat[order]


def test_rules_place_objects_by_slope_altitude_and_density(tmp_path):
    spec = _world(tmp_path / "w")
    r = build_tiles(spec)
    kind, mat = _objects(spec)
    trees, rocks = kind == OBJECT_KINDS.index("tree"), kind == OBJECT_KINDS.index("rock")
    assert sum(v["objects"] for v in r.lit.values()) == len(kind)
    xy, z = mat[:, :2, 3], mat[:, 2, 3]
    # trees on the gentle plain below 30 m, rocks on the wall only
    assert trees.sum() > 100 and rocks.sum() > 20
    assert (xy[trees, 0] < 480.0).all() and (z[trees] <= 30.0).all()
    assert (xy[rocks, 0] > 480.0).all()
    # density: the plain below 30 m (x < ~560 / 0.05 capped by the wall: x < 480 m, 720 m deep) is
    # 480 x 720 m = 34.6 ha at 20 a hectare, ~691 candidates, all kept (slope 3 degrees, z < 27 m)
    assert abs(int(trees.sum()) - 691) <= 40
    # every object stands on the surface: a tree's base 0.3 m under the terrain at its xy
    from piste.terrain.net import PatchNet
    from piste.terrain.query import height_at

    store = TileStore(spec.root)
    net = PatchNet(np.concatenate([store.read_fit(spec.grid, *t)["control_points"] for t in spec.grid.tiles()]))
    zs, hit, _, _ = height_at(net, xy[trees])
    assert hit.all() and np.allclose(z[trees], zs - 0.3, atol=1e-6)


def test_placement_is_the_same_whatever_the_tiling_order_or_worker(tmp_path):
    a = _world(tmp_path / "a", tile_patches=4)
    build_tiles(a)
    b = _world(tmp_path / "b", tile_patches=6)  # other tiles: the same objects (cells are global)
    build_tiles(b)
    ka, ma = _objects(a)
    kb, mb = _objects(b)
    assert np.array_equal(ka, kb) and np.allclose(ma, mb, rtol=0, atol=1e-9)
    # no object twice along a seam: every (kind, x, y) once
    keys = np.round(ma[:, :2, 3], 6)
    assert len(np.unique(np.column_stack([ka, keys]), axis=0)) == len(ka)
    # a tile baked alone, in reverse order, in a fresh store: the same bytes
    c = replace(_world(tmp_path / "c", tile_patches=4))
    from piste.pipeline.tiled_build import fit_task

    for t in reversed(c.grid.tiles()):
        fit_task(c, *t)
    for t in reversed(c.grid.tiles()):
        lit_task(c, *t)
    for t in a.grid.tiles():
        assert TileStore(c.root).path("lit", *t).read_bytes() == TileStore(a.root).path("lit", *t).read_bytes()
    # another seed: other objects
    d = _world(tmp_path / "d", seed=1)
    build_tiles(d)
    assert not np.array_equal(_objects(d)[1], ma)


def test_no_rules_no_members_and_rules_change_the_key(tmp_path):
    spec = _world(tmp_path / "w", rules=())
    build_tiles(spec)
    store = TileStore(spec.root)
    assert "objects_kind" not in store.read("lit", 0, 0)
    k, m = read_tile_objects(store, spec.grid, 0, 0, len(OBJECT_KINDS))
    assert k.shape == (0,) and m.shape == (0, 4, 4)
    assert spec.lit_key(0, 0) != _world(tmp_path / "w").lit_key(0, 0)
    assert _world(tmp_path / "w").lit_key(0, 0) != _world(tmp_path / "w", seed=3).lit_key(0, 0)


def _rewrite(store, t, **members):
    a = store.read("lit", *t)
    a.update(members)
    a = {k: v for k, v in a.items() if v is not None}
    store.path("lit", *t).write_bytes(npz_bytes({"key": np.array("x"), **a}))


@pytest.mark.parametrize("members, field, words", [
    ({"objects_matrix": None}, "objects_matrix", "without"),
    ({"objects_kind": np.array([[0]])}, "objects_kind", "(k,) integers"),
    ({"objects_kind": np.array([7, 0])}, "objects_kind", "kinds 0..3"),
    ({"objects_matrix": np.zeros((2, 4, 4))}, "objects_matrix", "bottom row"),
    ({"objects_matrix": np.full((2, 4, 4), np.nan)}, "objects_matrix", "finite"),
    ({"objects_matrix": np.zeros((3, 4, 4))}, "objects_matrix", "(2, 4, 4)"),
])
def test_bad_object_members_are_named(tmp_path, members, field, words):
    spec = _world(tmp_path / "w")
    build_tiles(spec)
    store = TileStore(spec.root)
    base = {"objects_kind": np.array([0, 2]), "objects_matrix": np.tile(np.eye(4), (2, 1, 1))}
    base["objects_matrix"][:, :2, 3] = 10.0
    _rewrite(store, (0, 0), **{**base, **members})
    with pytest.raises(TileError, match=re.escape(words)) as exc:
        read_tile_objects(store, spec.grid, 0, 0, len(OBJECT_KINDS))
    assert exc.value.field == field and "t_0000_0000.npz" in str(exc.value)


def test_object_outside_its_tile_is_named(tmp_path):
    spec = _world(tmp_path / "w")
    build_tiles(spec)
    store = TileStore(spec.root)
    m = np.tile(np.eye(4), (1, 1, 1))
    m[0, :2, 3] = (500.0, 10.0)  # tile (0, 0) spans 0..120 m
    _rewrite(store, (0, 0), objects_kind=np.array([0]), objects_matrix=m)
    with pytest.raises(TileError, match="outside the tile"):
        read_tile_objects(store, spec.grid, 0, 0, len(OBJECT_KINDS))


def test_bad_rules_are_validation_errors():
    with pytest.raises(ValidationError, match="kind must be one of"):
        ObjectRule("cactus", 1.0)
    with pytest.raises(ValidationError, match="density"):
        ObjectRule("tree", 0.0)
    with pytest.raises(ValidationError, match="slope"):
        ObjectRule("tree", 1.0, slope=(40.0, 10.0))


def test_object_set_of_tile_objects(tmp_path):
    spec = _world(tmp_path / "w")
    build_tiles(spec)
    kind, mat = _objects(spec)
    objs = object_set(kind, mat)
    assert len(objs) == len(kind) and objs.counts["tree"] == int((kind == 0).sum())
    assert np.all(objs.radius > 0) and np.allclose(objs.center[:, :2], mat[:, :2, 3], atol=3.0)
    cp = TileStore(spec.root).read_fit(spec.grid, 0, 0)["control_points"]
    k2, m2 = place_tile_objects(cp, spec.grid, 0, 0, spec.objects, 0)
    k0, m0 = read_tile_objects(TileStore(spec.root), spec.grid, 0, 0, len(OBJECT_KINDS))
    assert np.array_equal(k2, k0) and np.array_equal(m2, m0)


def test_open_tiles_streams_the_objects_and_add_tile_objects_holds_some(tmp_path):
    """open_tiles: an empty set of groups the streamed terrain fills as tiles page in
    (tests/render/test_streaming_objects.py); a world without objects has none.  add_tile_objects
    holds the objects of given tiles, a tile whose objects do not read back left out."""
    from piste.pipeline.tile_objects import add_tile_objects
    from piste.pipeline.tiles_source import open_tiles
    from piste.render.object_pass import ObjectGroups

    spec = _world(tmp_path / "w.tiles", tile_patches=6)  # 4 x 4 tiles
    build_tiles(spec)
    b = open_tiles(spec.root)
    objs = b.objects()
    assert isinstance(objs, ObjectGroups) and len(objs) == 0 and objs.kinds == OBJECT_KINDS
    assert b.manifest["objects"]["placed"] == "tiles" and b.manifest["objects"]["streamed"]
    assert b.vertex_colors()["tree"].shape[0] == 0
    bare = replace(spec, root=str(tmp_path / "bare.tiles"), objects=())
    build_tiles(bare)
    assert open_tiles(bare.root).objects() is None
    store = TileStore(spec.root)
    near = [(1, 1), (1, 2), (2, 1)]
    want = sum(len(read_tile_objects(store, spec.grid, y, x, 4)[0]) for y, x in near)
    held = add_tile_objects(replace(b, _cache={}), store, spec.grid, near)
    assert len(held.objects()) == want > 0
    assert held.arrays["objects/colors/tree"].shape[0] == held.objects().counts["tree"]  # vertex colours baked
    k = len(read_tile_objects(store, spec.grid, 1, 1, 4)[0])
    _rewrite(store, (1, 1), objects_matrix=None)
    assert len(add_tile_objects(replace(b, _cache={}), store, spec.grid, near, skip_bad=True).objects()) == want - k


def _scene(tmp_path, rules: str):
    from piste.world.scene_file import load_scene

    n = 12 * SPP + 1
    x = np.arange(n) * SP
    np.savez(tmp_path / "h.npz", elevation=np.tile(0.05 * x, (n, 1)))
    (tmp_path / "s.toml").write_text(f'[terrain]\nsource = "h.npz"\nspacing = {SP}\nsamples_per_patch = {SPP}\n'
                                     f'tiles = "s.tiles"\ntile_patches = 4\n[lightmap]\nres = 2\nshadows = false\n'
                                     f'[visibility]\nenabled = false\n' + rules)
    return load_scene(tmp_path / "s.toml")


def test_scene_file_tile_objects_reach_the_tiled_build(tmp_path):
    from piste.pipeline.tiled_build import spec_from_scene
    from piste.world.scene_file import TileObjectSpec

    scene = _scene(tmp_path, '[[tile_objects]]\nkind = "tree"\ndensity = 20.0\nslope = [0.0, 10.0]\n'
                             '[[tile_objects]]\nkind = "rock"\ndensity = 5\naltitude = [10.0, 100.0]\n')
    assert scene.tile_objects == [TileObjectSpec("tree", 20.0, slope=(0.0, 10.0)),
                                  TileObjectSpec("rock", 5.0, altitude=(10.0, 100.0))]
    spec = spec_from_scene(scene)
    assert spec.objects == (ObjectRule("tree", 20.0, slope=(0.0, 10.0)), ObjectRule("rock", 5.0, altitude=(10.0, 100.0)))
    build_tiles(spec)
    kind, mat = _objects(spec)
    assert (kind == 0).sum() > 50 and (mat[kind == 2, 2, 3] >= 9.0).all()


@pytest.mark.parametrize("rules, key, words", [
    ('[[tile_objects]]\nkind = "cactus"\ndensity = 1.0\n', "tile_objects[0].kind", "one of tree"),
    ('[[tile_objects]]\nkind = "tree"\n', "tile_objects[0].density", "missing"),
    ('[[tile_objects]]\nkind = "tree"\ndensity = 1.0\nslope = [40.0, 10.0]\n', "tile_objects[0].slope", "min <= max"),
    ('[[tile_objects]]\nkind = "tree"\ndensity = 1.0\nslope = [0.0, 100.0]\n', "tile_objects[0].slope", "[0, 90]"),
    ('[[tile_objects]]\nkind = "tree"\ndensity = 1.0\nheight = 3\n', "tile_objects[0].height", "unknown"),
])
def test_bad_tile_object_rules_name_the_key(tmp_path, rules, key, words):
    from piste.world.scene_file import SceneError

    with pytest.raises(SceneError, match=re.escape(words)) as exc:
        _scene(tmp_path, rules)
    assert key in str(exc.value) and "s.toml" in str(exc.value)


def _long_world(root) -> TiledSpec:
    """6 x 2 tiles of 120 m: a slope falling along +x with rolls across it."""
    ny, nx = 2 * 4 * SPP + 1, 6 * 4 * SPP + 1
    x, y = np.meshgrid(np.arange(nx) * SP, np.arange(ny) * SP)
    z = 300.0 - 0.3 * x + 4.0 * np.sin(x / 40.0) * np.cos(y / 35.0)
    return TiledSpec(str(root), ArraySource(z, (SP, SP)), TileGrid((ny, nx), SPP, 4, (SP, SP)), "", res=2,
                     shadows=False)


def test_riders_follow_a_track_across_tiles(tmp_path):
    from piste.pipeline.tile_objects import track_tiles, world_track
    from piste.terrain.net import PatchNet
    from piste.terrain.query import height_at
    from piste.world.riders import RiderSet

    spec = _long_world(tmp_path / "w")
    build_tiles(spec)
    store, g = TileStore(spec.root), spec.grid
    line, net = world_track(store, g, (15.0, 110.0), (705.0, 130.0))
    assert len(track_tiles(g, line[:, :2], halo=0)) == 6 and len(net) == 2 * 6 * 16  # every tile, both rows
    whole = PatchNet(np.concatenate([store.read_fit(g, *t)["control_points"] for t in g.tiles()]))
    zs, hit, _, _ = height_at(whole, line[:, :2])
    assert hit.all() and np.allclose(line[:, 2], zs, atol=1e-6)  # the track lies on the world's surface
    riders = RiderSet(net, line, start=20.0, speed=11.0)
    tiles_seen = set()
    for t in np.arange(0.0, 55.0, 2.5):  # 600 m of track at 11 m/s
        st = riders.state(float(t))
        z, hit, _, _ = height_at(whole, st.anchor[:, :2])
        assert hit.all() and np.allclose(st.anchor[:, 2], z, atol=1e-4)  # standing on the exact surface
        tiles_seen.add(g.tile_of(*st.anchor[0, :2]))
    assert {tx for _, tx in tiles_seen} >= {0, 1, 2, 3, 4, 5}  # rider 0 rode across every tile column


def test_add_track_riders_gives_the_runtime_a_pack_on_the_track(tmp_path):
    from piste.pipeline.preview import track_scene
    from piste.pipeline.tile_objects import add_track_riders
    from piste.pipeline.tiles_source import open_tiles
    from piste.errors import ConfigError

    spec = _long_world(tmp_path / "w.tiles")
    build_tiles(spec)
    b = open_tiles(spec.root)
    b2 = add_track_riders(b, TileStore(spec.root), spec.grid, (15.0, 110.0), (705.0, 130.0), start=0.1)
    assert b2.manifest["pack"] == {"follow": "track", "start": 0.1, "riders": 6} and b2.centerline.shape[1] == 3
    assert len(b2.net) == 192 and b2.lightmap.rects.shape[0] == 192 and b.net is not b2.net
    scene = track_scene(b2)
    st = scene.riders.state(30.0)
    assert st.anchor[:, 0].max() > 240.0  # riders 3 tiles from the world's start after 30 s
    with pytest.raises(ConfigError, match="off the world"):
        add_track_riders(b, TileStore(spec.root), spec.grid, (15.0, 110.0), (905.0, 130.0))


def test_track_pack_of_n_riders(tmp_path):
    """A pack of N riders on a tiled world's track (``--riders N`` with ``--track``): the default six's
    rows first, then again 48 m further ahead; the track it needs grows with it; bad counts named."""
    from dataclasses import replace

    from piste.errors import ConfigError, FormatError
    from piste.pipeline.preview import PACK_TRACK_AHEAD, pack_track_ahead, track_pack, track_scene
    from piste.pipeline.tile_objects import add_track_riders
    from piste.pipeline.tiles_source import open_tiles
    from piste.world.riders import DEFAULT_PACK

    assert track_pack(6) == DEFAULT_PACK and track_pack(2) == DEFAULT_PACK[:2]
    rows = track_pack(20)
    ahead = np.array([r[2] for r in rows])
    assert len(rows) == 20 and len(np.unique(ahead)) == 20 and np.diff(np.sort(ahead)).max() <= 9.0
    assert pack_track_ahead(1) == pack_track_ahead(6) == PACK_TRACK_AHEAD
    assert pack_track_ahead(20) == PACK_TRACK_AHEAD + ahead.max() - 41.0
    for bad in (0, 65):
        with pytest.raises(ConfigError, match="1..64"):
            track_pack(bad)
    spec = _long_world(tmp_path / "w.tiles")
    build_tiles(spec)
    b = open_tiles(spec.root, track=(15.0, 110.0, 705.0, 130.0), track_riders=11)
    assert b.manifest["pack"]["riders"] == 11
    scene = track_scene(b)
    assert len(scene.riders) == 11 and scene.riders.state(5.0).anchor.shape == (11, 3)
    assert len(track_scene(open_tiles(spec.root, track=(15.0, 110.0, 705.0, 130.0))).riders) == 6
    with pytest.raises(ConfigError, match="1..64"):
        add_track_riders(b, TileStore(spec.root), spec.grid, (15.0, 110.0), (705.0, 130.0), riders=0)
    with pytest.raises(ConfigError, match="needs a track"):
        open_tiles(spec.root, track_riders=3)
    with pytest.raises(ConfigError, match="a pack of 40 riders needs more than"):
        open_tiles(spec.root, track=(15.0, 110.0, 405.0, 130.0), track_riders=40)
    for bad in (0, 2.5, "6", True):
        man = dict(b.manifest, pack={**b.manifest["pack"], "riders": bad})
        with pytest.raises(FormatError, match="pack.riders"):
            track_scene(replace(b, manifest=man))
