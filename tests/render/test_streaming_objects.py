"""A tiled world's scene objects page in and out with its tiles (issue 26): flying a camera across a
world of 4 x 4 tiles, the object pass holds exactly the objects of the tiles paged in (those it
reaches join, those it leaves go), draws them as a set of the same objects does, pixel for pixel,
and a tile whose objects do not read back keeps its terrain without them."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from piste.pipeline.tile_objects import ObjectRule, add_tile_objects
from piste.pipeline.tiled_build import ArraySource, TiledSpec, build_tiles
from piste.terrain.tiles import TileGrid, TileStore, npz_bytes, read_tile_objects
from piste.world.camera import Camera

SPP, SP = 3, 10.0
SIZE = (160, 112)


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """24 x 24 patches (720 m) in 4 x 4 tiles, trees on the gentle slopes, rocks on a wall in the east."""
    root = tmp_path_factory.mktemp("objworld") / "w.tiles"
    n = 24 * SPP + 1
    x, y = np.meshgrid(np.arange(n) * SP, np.arange(n) * SP)
    z = 0.05 * x + 3.0 * np.sin(y / 90.0) + np.where(x > 480.0, (x - 480.0) * 0.9, 0.0)
    rules = (ObjectRule("tree", 20.0, slope=(0.0, 20.0)), ObjectRule("rock", 10.0, slope=(30.0, 60.0)))
    spec = TiledSpec(str(root), ArraySource(z, (SP, SP)), TileGrid((n, n), SPP, 6, (SP, SP)), "", res=2,
                     shadows=False, objects=rules)
    build_tiles(spec)
    return spec


def _camera(x: float) -> Camera:
    """Low over the world's first tile row at ``x`` metres, looking north over it."""
    return Camera(np.array([x, 60.0, 120.0]), np.array([x, 260.0, 0.0]), fov_y=60, near=1.0, far=3000.0)


def _stored(spec, tiles) -> int:
    store = TileStore(spec.root)
    return sum(len(read_tile_objects(store, spec.grid, *t, 4)[0]) for t in tiles)


def test_objects_follow_the_resident_tiles_across_the_world(gl, world):
    from piste.pipeline.preview import ScenePreview
    from piste.pipeline.tiles_source import open_tiles

    b = open_tiles(world.root)
    objs = b.objects()
    assert objs is not None and len(objs) == 0 and b.manifest["objects"]["streamed"]
    p = ScenePreview(b, size=SIZE, ctx=gl)
    try:
        cache = p.terrain.streaming.cache
        seen, left, drawn = set(), set(), 0
        for x in np.linspace(30.0, 690.0, 9):  # west to east across all four tile columns
            before = set(objs.groups)
            p.render(_camera(float(x)))
            with cache._lock:
                paged = {t for t in cache.near}
            with_objects = {t for t in paged if _stored(world, [t])}
            assert set(objs.groups) == with_objects  # exactly the paged tiles' objects
            assert len(objs) == _stored(world, with_objects) > 0
            assert p.objects.objects is objs and len(p.objects.rows) == len(objs)
            for t, sl in objs.slices().items():  # each group holds its tile's stored instances
                k, m = read_tile_objects(TileStore(world.root), world.grid, *t, 4)
                assert np.array_equal(objs.kind[sl], k) and np.array_equal(objs.matrix[sl], m)
            assert 0 <= p.stats["objects_drawn"] <= len(objs)
            drawn += p.stats["objects_drawn"]
            seen |= with_objects
            left |= before - set(objs.groups)
        assert drawn > 100 and {tx for _, tx in seen} == {0, 1, 2, 3}  # reached every tile column
        assert (0, 0) in left and (0, 0) not in objs.groups  # and the first ones went when it flew on
    finally:
        p.release()


@pytest.mark.parametrize("riders", [0, 2])
def test_streamed_objects_draw_as_the_same_objects_in_one_set(gl, world, riders):
    """The picture: a frame whose objects were paged in equals the frame of a scene holding those
    tiles' objects as one set (baked colours included), with and without riders."""
    from piste.pipeline.furnish import add_standing_riders
    from piste.pipeline.preview import ScenePreview
    from piste.pipeline.tiles_source import open_tiles

    cam = _camera(300.0)
    b = open_tiles(world.root)
    if riders:
        b = add_standing_riders(b, riders)
        assert b.objects() is not None and hasattr(b.objects(), "groups")  # kept through the copy
    p = ScenePreview(b, size=SIZE, ctx=gl)
    try:
        p.render(_camera(30.0))  # (from elsewhere first: this frame's objects are paged in, others out)
        img = p.render(cam)
        tiles = sorted(b.objects().groups)
        n = p.stats["objects_drawn"]
    finally:
        p.release()
    assert tiles and n > 0
    plain = add_tile_objects(replace(b, _cache={}), TileStore(world.root), world.grid, tiles)
    assert not hasattr(plain.objects(), "groups") and len(plain.objects()) == _stored(world, tiles)
    q = ScenePreview(plain, size=SIZE, ctx=gl)
    try:
        ref = q.render(cam)
        assert q.stats["objects_drawn"] == n
    finally:
        q.release()
    diff = np.abs(img.astype(int) - ref.astype(int)).max(2)
    assert (diff > 0).sum() == 0, f"{int((diff > 0).sum())} pixels differ"
    r = ScenePreview(replace(b, _cache={"objects": None}), size=SIZE, ctx=gl)  # and objects are in the picture
    try:
        bare = r.render(cam)
    finally:
        r.release()
    assert (np.abs(img.astype(int) - bare.astype(int)).max(2) > 24).sum() > 20


def test_a_tile_whose_objects_do_not_read_back_keeps_its_terrain(gl, world, tmp_path, caplog):
    import shutil

    from piste.pipeline.preview import ScenePreview
    from piste.pipeline.tiles_source import open_tiles

    root = tmp_path / "w.tiles"
    shutil.copytree(world.root, root)
    store = TileStore(root)
    a = store.read("lit", 0, 1)
    a["objects_matrix"] = np.zeros((len(a["objects_kind"]), 4, 4))  # bottom row 0: refused
    store.path("lit", 0, 1).write_bytes(npz_bytes({"key": np.array("x"), **a}))
    b = open_tiles(root)
    p = ScenePreview(b, size=SIZE, ctx=gl)
    try:
        with caplog.at_level("WARNING"):
            p.render(_camera(200.0))
        cache = p.terrain.streaming.cache
        assert (0, 1) in cache.near and (0, 1) not in cache.bad  # its terrain is drawn
        assert (0, 1) not in b.objects().groups and len(b.objects().groups) > 0
        assert "objects_matrix" in caplog.text
    finally:
        p.release()
