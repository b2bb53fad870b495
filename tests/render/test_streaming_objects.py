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


def _within(cache, eye, r: float) -> set:
    """The tiles whose box (skirts included) lies within ``r`` metres of ``eye``."""
    d = np.maximum(np.maximum(cache.lo - eye, eye - cache.hi), 0.0)
    return {t for t, x in zip(cache.tiles, np.sqrt((d * d).sum(1))) if x <= r}


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
        cache.object_distance = 200.0  # (by size on screen every tile of this small world would stay)
        seen, left, drawn = set(), set(), 0
        for x in np.linspace(30.0, 690.0, 9):  # west to east across all four tile columns
            before = set(objs.groups)
            p.render(_camera(float(x)))
            paged = _within(cache, _camera(float(x)).eye, 200.0)
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


# ------------------------------------------------------------------ objects beyond the terrain's mesh ring
def _far_camera() -> Camera:
    """Low in the south-west corner looking across the world to the north-east: one near tile, the
    rest far stand-ins."""
    return Camera(np.array([20.0, 20.0, 30.0]), np.array([700.0, 700.0, 0.0]), fov_y=60, near=1.0, far=3000.0)


def test_objects_of_tiles_beyond_the_middle_ring_are_paged_and_drawn_coarsest(gl, world):
    from piste.pipeline.preview import ScenePreview
    from piste.pipeline.tiles_source import open_tiles
    from piste.render.streaming import OBJECT_MIN_PIXELS

    b = open_tiles(world.root)
    objs = b.objects()
    p = ScenePreview(b, size=SIZE, ctx=gl)
    try:
        cam = _far_camera()
        p.render(cam)
        cache = p.terrain.streaming.cache
        scale = SIZE[1] / (2.0 * np.tan(np.radians(cam.fov_y) / 2.0))
        beyond = set(objs.groups) - set(cache.near)
        assert len(cache.near) <= 2 and len(beyond) >= 8  # trees out where the terrain is far stand-ins
        # exactly the tiles whose tallest object stands >= OBJECT_MIN_PIXELS tall at their nearest point
        want = set()
        for t in cache.tiles:
            k, m = read_tile_objects(TileStore(world.root), world.grid, *t, 4)
            if len(k) and t in _within(cache, cam.eye, cache.object_height[t] * scale / OBJECT_MIN_PIXELS):
                want.add(t)
        assert set(objs.groups) == want and (0, 3) not in want  # (the rocks' column: too small that far)
        # instances in view over far stand-ins draw through their kind's LOD chain: the coarsest level far away
        sl = objs.slices()
        far_idx = np.concatenate([np.arange(len(objs))[sl[t]] for t in beyond])
        planes = cam.with_aspect(*SIZE).frustum_planes()
        vis = np.intersect1d(far_idx, objs.visible(planes, max_distance=cam.far, eye=cam.eye))
        po = p.objects
        coarsest = np.isfinite(po.lod_errors).sum(1) - 1
        from piste.world.object_lod import choose_lods
        lv = choose_lods(po.lod_errors[objs.kind[vis]], objs.center[vis], objs.radius[vis], po.scale[vis],
                         cam.with_aspect(*SIZE).view_projection(), SIZE[1], po.lod_pixels)
        far_away = np.linalg.norm(objs.center[vis] - cam.eye, axis=1) > 600.0
        assert far_away.sum() > 50 and (lv[far_away] == coarsest[objs.kind[vis][far_away]]).all()
        assert (lv > 0).all()  # (the nearer ones at finer levels of the same chain, by their error)
    finally:
        p.release()


def test_far_objects_in_the_picture_equal_one_set_of_the_same_objects(gl, world):
    """The picture: the trees over the far stand-ins are drawn (many pixels more than with only
    the near tile's objects), as a scene holding those tiles' objects as one set draws them."""
    from piste.pipeline.preview import ScenePreview
    from piste.pipeline.tiles_source import open_tiles

    cam = _far_camera()
    b = open_tiles(world.root)
    p = ScenePreview(b, size=SIZE, ctx=gl)
    try:
        img = p.render(cam)
        tiles = sorted(b.objects().groups)
        near = set(p.terrain.streaming.cache.near)
        p.terrain.streaming.cache.object_distance = 0.0  # only the tile under the eye keeps its objects
        p.render(Camera(cam.eye + 1.0, cam.target, fov_y=60, near=1.0, far=3000.0))  # (re-paged)
        ring = p.render(cam)
        assert set(b.objects().groups) <= near
    finally:
        p.release()
    plain = add_tile_objects(replace(b, _cache={}), TileStore(world.root), world.grid, tiles)
    q = ScenePreview(plain, size=SIZE, ctx=gl)
    try:
        ref = q.render(cam)
    finally:
        q.release()
    assert (np.abs(img.astype(int) - ref.astype(int)).max(2) > 0).sum() == 0
    more = (np.abs(img.astype(int) - ring.astype(int)).max(2) > 24).sum()
    assert more > 150, f"{more} pixels of far objects"


# ------------------------------------------------------------------ object bytes in the budget
def test_object_instance_bytes_are_what_a_paged_tile_holds(world):
    """:func:`object_instance_bytes` is the bytes the cache, the object set and the pass hold for
    one instance of each kind (measured on a tile's real objects)."""
    from piste.lighting.lights import default_lights
    from piste.render.object_pass import ObjectGroups, _pack_rows, instance_rows
    from piste.render.streaming import TileCache, object_instance_bytes
    from piste.pipeline.tile_objects import object_set
    from piste.world.objects import bake_vertex_colors

    store = TileStore(world.root)
    kind, matrix = read_tile_objects(store, world.grid, 1, 1, 4)
    assert len(kind) > 20
    base = object_set(np.zeros(0, np.int64), np.zeros((0, 4, 4)))
    lights = default_lights()
    g = ObjectGroups(base.meshes, base.kinds, base.texture, base.blend, world_lights=lights)
    part = g.add((1, 1), kind, matrix)

    def arrays(s):
        vl = s.lights
        return sum(a.nbytes for a in (s.kind, s.matrix, s.normal_matrix, s.center, s.radius, vl.directions,
                                      vl.colors, vl.ambient))

    rows = instance_rows(part)
    baked = sum(c.nbytes for c in bake_vertex_colors(part, lights).values())
    measured = kind.nbytes + matrix.nbytes + arrays(part) + arrays(g) + 2 * rows.nbytes + _pack_rows(rows).nbytes \
        + 2 * baked
    counts = np.bincount(kind, minlength=4)
    assert int((counts * object_instance_bytes()).sum()) == measured
    cache = TileCache(world.root)
    try:
        assert cache.object_bytes[(1, 1)] == measured and np.array_equal(cache.object_counts[(1, 1)], counts)
    finally:
        cache.close()


def test_object_bytes_count_in_the_streaming_budget(world):
    from piste.render.streaming import TileCache

    eye = np.array([20.0, 20.0, 30.0])
    scale = 97.0  # pixels a radian
    probe = TileCache(world.root)
    try:
        far = probe._far_bytes
        order = sorted(probe.object_bytes, key=lambda t: probe.distance(eye, t))
        assert len(order) == 16 and all(v > 0 for v in probe.object_bytes.values())
    finally:
        probe.close()
    got = []
    for extra in (0, 200_000, 800_000, 2_000_000, 64 << 20):
        cache = TileCache(world.root, budget_bytes=far + extra, near_radius=0.0, object_distance=1e4)
        cache.load_objects = True
        try:
            cache.update(eye, scale, far=3000.0)
            cache.wait_idle()
            with cache._lock:
                meshes = sum(m.nbytes for m in cache.near.values())
                paged = set(cache.objects)
            objects = sum(cache.object_bytes[t] for t in paged)
            assert cache.resident_bytes == far + meshes + objects <= far + extra  # counted, and under the budget
            n = len(paged)
            assert paged == set(order[:n]) or paged == {t for t in order[:n + 1]} - {order[n]}  # nearest first
            got.append(n)
        finally:
            cache.close()
    assert got[0] == 0 and got == sorted(got) and got[-1] >= 12 and len(set(got)) >= 3


# ------------------------------------------------------------------ objects with the tiles' visibility sets
@pytest.fixture(scope="module")
def rough(tmp_path_factory):
    """18 x 18 patches of 600 m relief in 3 x 3 tiles of 6 x 6 patches, visibility sets in 60 m
    cells, trees on the gentler slopes and rocks on the steep ones."""
    from piste.pipeline.tiled_build import SyntheticSource, synthetic_spec

    root = tmp_path_factory.mktemp("roughobj") / "w.tiles"
    spec = synthetic_spec(root, 18, tile_patches=6, res=2, spacing=20.0, shadows=False, cell=60.0)
    spec.source = SyntheticSource(spec.source.shape, spec.source.spacing, 0, relief=600.0, wavelength=400.0)
    spec.objects = (ObjectRule("tree", 30.0, slope=(0.0, 35.0)), ObjectRule("rock", 15.0, slope=(35.0, 80.0)))
    build_tiles(spec)
    return spec


def test_objects_with_visibility_sets_draw_what_they_draw_without(gl, rough):
    """``piste render|view`` on a tiled world with objects and visibility sets: the sets cull hidden
    patches and the frames (objects included) are those drawn without the sets, pixel for pixel."""
    from piste.pipeline.preview import ScenePreview
    from piste.pipeline.tiles_source import open_tiles
    from piste.terrain.net import PatchNet
    from piste.terrain.query import height_at

    store, g = TileStore(rough.root), rough.grid
    whole = PatchNet(np.concatenate([store.read_fit(g, *t)["control_points"] for t in g.tiles()]))
    rng = np.random.default_rng(5)
    xy = rng.uniform(60.0, 1020.0, (12, 2))
    z, hit, _, _ = height_at(whole, xy)
    assert hit.all()
    b = open_tiles(rough.root)
    assert hasattr(b.objects(), "groups")
    p = ScenePreview(b, size=SIZE, ctx=gl)
    culled = drawn = 0
    try:
        for (x, y), h, a in zip(xy, z, rng.uniform(0.0, 2.0 * np.pi, len(xy))):
            eye = np.array([x, y, h + 2.0])
            cam = Camera(eye, eye + np.array([np.cos(a), np.sin(a), -0.07]) * 300.0, fov_y=60, near=0.5, far=3000.0)
            p.terrain.streaming.visibility = True
            img = p.render(cam)
            culled += p.terrain.cull_stats["vis_culled"]
            drawn += p.stats["objects_drawn"]
            p.terrain.streaming.visibility = False
            ref = p.render(cam)
            diff = (np.abs(img.astype(int) - ref.astype(int)).max(2) > 0).sum()
            assert diff == 0, f"{diff} pixels differ at {eye}"
    finally:
        p.release()
    assert culled > 5 and drawn > 1000


@pytest.mark.parametrize("members", [
    {"objects_kind": np.zeros((3, 2), np.int64)},                      # not (k,)
    {"objects_kind": np.array([0, 9]), "objects_matrix": np.tile(np.eye(4), (2, 1, 1))},  # a kind out of range
    {"objects_matrix": np.tile(np.eye(4), (2, 1, 1))},                  # a matrix without kinds
])
def test_object_members_that_do_not_read_back_are_warned_once_and_cost_nothing(world, tmp_path, caplog, members):
    import shutil

    from piste.render.streaming import TileCache

    root = tmp_path / "w.tiles"
    shutil.copytree(world.root, root)
    store = TileStore(root)
    a = {k: v for k, v in store.read("lit", 0, 1).items() if not k.startswith("objects_")}
    store.path("lit", 0, 1).write_bytes(npz_bytes({**a, **members}))
    cache = TileCache(root, object_distance=1e4)
    cache.load_objects = True
    try:
        with caplog.at_level("WARNING"):
            for _ in range(3):
                cache.update(np.array([200.0, 60.0, 50.0]), 97.0)
                cache.wait_idle()
        assert (0, 1) not in cache.objects and (0, 1) not in cache.bad and len(cache.objects) == 15
        assert caplog.text.count("tile (0, 1)") == 1 and "objects_" in caplog.text  # asked once, named
        assert cache.resident_bytes == cache._far_bytes + sum(m.nbytes for m in cache.near.values()) \
            + sum(cache.object_bytes[t] for t in cache.objects)
    finally:
        cache.close()
