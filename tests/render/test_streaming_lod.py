"""Per-patch screen-space-error LOD in the streamed tiles (issue 26): near and middle tiles draw
each patch by its own error on screen (the corner grid where that fits, glued to the mesh beside
it), far tiles each block of 8 x 8 patches at its own stride (zipped to coarser blocks), so a frame
draws far fewer triangles than near tiles at full detail, with the same picture and no cracks."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from piste.pipeline.tiled_build import SyntheticSource, build_tiles, synthetic_spec
from piste.render import streaming as S
from piste.render.block_errors import block_stride_errors
from piste.terrain.bezier import bernstein
from piste.terrain.query import height_at
from piste.terrain.tiles import tile_net
from piste.world.camera import Camera

MAGENTA = (1.0, 0.0, 1.0)
GREY = np.array([0.299, 0.587, 0.114])
SIZE = (320, 224)


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """48 x 48 patches (2.88 km square) of hills 300 m high in 2 x 2 tiles of 24 x 24 patches: 3 x 3
    far blocks a tile."""
    root = tmp_path_factory.mktemp("streaming_lod") / "w.tiles"
    spec = synthetic_spec(root, 48, tile_patches=24, res=3, spacing=20.0, shadows=False)
    n = spec.grid.samples[0]
    spec.source = SyntheticSource((n, n), (20.0, 20.0), 0, relief=300.0, wavelength=1500.0)
    build_tiles(spec)
    return root


def _magenta(img: np.ndarray) -> int:
    return int((np.asarray(img) == (255, 0, 255)).all(-1).sum())


def _low_cameras(cache, n: int, seed: int = 0) -> list:
    """Eyes 10 to 120 m over the tiles' top looking across and down the world."""
    rng = np.random.default_rng(seed)
    lo, hi = cache.lo.min(0), cache.hi.max(0)
    out = []
    for _ in range(n):
        x, y = rng.uniform(lo[:2] + 200.0, hi[:2] - 200.0)
        a = rng.uniform(0.0, 2.0 * np.pi)
        eye = np.array([x, y, hi[2] + rng.uniform(10.0, 120.0)])
        out.append(Camera(eye, eye + np.array([np.cos(a), np.sin(a), 0.0]) * 1500.0 - [0.0, 0.0, 600.0],
                          near=1.0, far=6000.0))
    return out


def _steep_cameras(cache) -> list:
    """Eyes over the world looking steeply down at it: only terrain in the picture."""
    lo, hi = cache.lo.min(0), cache.hi.max(0)
    mid = 0.5 * (lo + hi)
    out = []
    for dx, dy in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
        eye = np.array([mid[0] + 200.0 * dx, mid[1] + 200.0 * dy, hi[2] + 300.0])
        out.append(Camera(eye, np.array([mid[0] - 100.0 * dx, mid[1] - 100.0 * dy, lo[2]]), near=1.0, far=6000.0))
    return out


def test_near_tiles_draw_each_patch_by_its_error_on_screen(world, gl):
    """The near and middle tiles' patches follow their error on screen: far fewer triangles than the
    same tiles drawn whole (near meshes at full detail), the picture within the issue's tolerance of
    it (grey mean <= 4, 95th percentile <= 12) and no more background through the terrain; a larger
    pixel error draws fewer triangles, a tiny one every near patch from the mesh."""
    r = S.StreamingRenderer(world, size=SIZE, ctx=gl, background=MAGENTA, sky=False)
    try:
        steep = _steep_cameras(r.cache)
        cams = steep + _low_cameras(r.cache, 6) + list(S.fly_path(r.cache.index, 31))[::10]
        diffs, tris, mixed = [], {True: 0, False: 0}, 0
        for k, cam in enumerate(cams):
            img = {}
            for mix in (True, False):
                r.mix_levels = mix
                img[mix] = r.render(cam, wait=True)
                tris[mix] += r.stats["triangles"]
            mixed += r.stats["near"] + r.stats["mid"] > 0
            r.mix_levels = True
            if k < len(steep):  # only terrain in the picture: not a pixel of background
                assert _magenta(img[True]) == _magenta(img[False]) == 0
            else:  # the sky over the horizon: the same but for the silhouette's pixels (levels differ there)
                assert abs(_magenta(img[True]) - _magenta(img[False])) <= SIZE[0] // 4
            diffs.append(np.abs(img[True].astype(float) @ GREY - img[False].astype(float) @ GREY).ravel())
        d = np.concatenate(diffs)
        assert mixed == len(cams)  # near or middle tiles in every view
        assert tris[True] < 0.5 * tris[False], tris
        assert d.mean() <= 4.0 and np.percentile(d, 95) <= 12.0, (d.mean(), np.percentile(d, 95))
        # the pixel error drives the patches' levels
        cam = cams[-1]  # along the flight: the terrain from under the eye to the horizon
        count = {}
        for pe in (0.01, 1.0, 3.0, 9.0):
            r.pixel_error = pe
            r.render(cam, wait=True)
            count[pe] = (r.stats["triangles"], r.stats["mid_far_patches"])
        assert count[0.01][1] == 0  # every near patch from its mesh
        assert count[0.01][0] > count[1.0][0] > count[3.0][0] > count[9.0][0], count
        assert count[1.0][1] > 0  # (patches of near and middle tiles from the corner grid)
    finally:
        r.close()


def test_far_blocks_meet_without_cracks(world, gl, monkeypatch):
    """Far tiles (no near ones) drawn by block at strides 1 and 8 in a checkerboard: steep views
    see no background (the finer blocks' zippers close every step; without them it shows), the
    blocks' own strides draw fewer triangles than their tiles' strides."""
    r = S.StreamingRenderer(world, size=SIZE, ctx=gl, background=MAGENTA, sky=False, near_radius=-1.0,
                            pixel_error=None)
    try:
        cams = _steep_cameras(r.cache)
        for cam in cams:
            assert _magenta(r.render(cam, wait=True)) == 0
            assert r.stats["near"] == 0 and r.stats["far_blocks"] > 0
        across = _low_cameras(r.cache, 6)
        by_block = sum(r.render(cam, wait=True) is not None and r.stats["triangles"] for cam in across)
        monkeypatch.setattr(r.cache, "block_strides", lambda eye, scale, tiles, error=3.0: np.repeat(
            np.asarray(tiles), np.diff(r.cache.block_start)))
        by_tile = sum(r.render(cam, wait=True) is not None and r.stats["triangles"] for cam in across)
        assert by_block < by_tile
        # strides 1 and 8 side by side everywhere
        n = len(r.cache._blk["lo"])
        checker = np.where(np.arange(n) % 2 == 0, 1, 8)
        monkeypatch.setattr(r.cache, "block_strides", lambda eye, scale, tiles, error=3.0: checker)
        holes = [_magenta(r.render(cam, wait=True)) for cam in cams]
        assert holes == [0, 0, 0, 0]
        for t in r.cache.tiles:  # without the zippers
            for mesh in r.cache.far[t].values():
                mesh.blocks["zip_count"] = np.zeros_like(mesh.blocks["zip_count"])
        r._far_runs.clear()
        assert sum(_magenta(r.render(cam, wait=True)) for cam in cams) > 0
    finally:
        r.close()


def test_far_block_strides_follow_their_error():
    """Each block takes the coarsest stride whose error fits the pixel error at its distance, at
    least its tile's stride."""
    cache = S.TileCache.__new__(S.TileCache)
    cache._blk = {"lo": np.array([[0.0, 0.0, 0.0], [1000.0, 0.0, 0.0], [5000.0, 0.0, 0.0]]),
                  "hi": np.array([[10.0, 10.0, 10.0], [1010.0, 10.0, 10.0], [5010.0, 10.0, 10.0]]),
                  "err": np.array([[1.0, 2.0, 4.0], [5.0, 20.0, 40.0], [5.0, 20.0, 40.0]]),
                  "patches": np.array([64, 64, 64])}
    cache.block_start = np.array([0, 2, 3])
    cache._lock = threading.Lock()
    eye = np.array([5.0, 5.0, 5.0])  # inside block 0; 995 m and 4995 m from the others
    # 3 px at 300 px a radian: 0.01 m of error a metre
    got = cache.block_strides(eye, 300.0, np.array([1, 1]), 3.0)
    assert got.tolist() == [1, 2, 8]
    assert cache.block_strides(eye, 300.0, np.array([4, 1]), 3.0).tolist() == [4, 4, 8]  # at least the tile's


def test_far_blocks_follow_the_renderers_pixel_error(world, gl):
    """The far tiles' blocks take their strides at the renderer's ``pixel_error`` (they were always
    chosen at 3 px): with only far tiles (a budget the far field just fits), a larger pixel error
    draws the far blocks coarser (fewer triangles), a smaller one finer, every block at the stride
    :meth:`TileCache.block_strides` gives at that error, without cracks; the default (3 px) draws the
    same pixels as ``pixel_error=None`` (far blocks at ``FAR_PIXEL_ERROR``)."""
    c = S.TileCache(world)
    try:
        budget = c._far_bytes + 1024  # no room for a near or middle mesh: every tile far
    finally:
        c.close()
    cams = _steep_cameras(c) + _low_cameras(c, 6, seed=7)
    r = S.StreamingRenderer(world, size=SIZE, ctx=gl, background=MAGENTA, sky=False, budget_bytes=budget)
    try:
        assert r.pixel_error == S.FAR_PIXEL_ERROR == r.far_pixel_error
        default = [r.render(cam, wait=True) for cam in cams]
        used: list = []
        chosen = r.cache.block_strides

        def spy(*args):
            used.append(chosen(*args))
            return used[-1]

        r.cache.block_strides = spy
        tris, strides = {}, {}
        for pe in (1.0, S.FAR_PIXEL_ERROR, 9.0):
            r.pixel_error = pe
            tris[pe], strides[pe] = 0, []
            for k, cam in enumerate(cams):
                img = r.render(cam, wait=True)
                assert r.stats["near"] == r.stats["mid"] == 0 and r.stats["far_blocks"] > 0
                if k < 4:  # steep views: only terrain, whatever the strides
                    assert _magenta(img) == 0
                tris[pe] += r.stats["far_block_triangles"]
                e, scale = np.asarray(cam.eye, dtype=np.float64), r.lod_scale(cam.fov_y)
                want = S.TileCache.block_strides(r.cache, e, scale, r.cache.far_strides(e, scale, pe), pe)
                assert np.array_equal(used[-1], want)  # what the frame drew its blocks at
                strides[pe].append(want)
        assert tris[1.0] > tris[S.FAR_PIXEL_ERROR] > tris[9.0], tris
        fine, mid, coarse = (np.concatenate(strides[pe]) for pe in (1.0, S.FAR_PIXEL_ERROR, 9.0))
        assert (fine <= mid).all() and (mid <= coarse).all() and (fine < mid).any() and (mid < coarse).any()
        r.pixel_error = S.FAR_PIXEL_ERROR
        assert all(np.array_equal(a, r.render(cam, wait=True)) for a, cam in zip(default, cams))
    finally:
        r.close()
    n = S.StreamingRenderer(world, size=SIZE, ctx=gl, background=MAGENTA, sky=False, budget_bytes=budget,
                            pixel_error=None)
    try:
        assert n.far_pixel_error == S.FAR_PIXEL_ERROR
        assert all(np.array_equal(a, n.render(cam, wait=True)) for a, cam in zip(default, cams))
    finally:
        n.close()


def test_streaming_terrain_passes_its_pixel_error_to_the_far_blocks(world, gl):
    """The runtime's tiled terrain (:class:`StreamingTerrain`, what ``piste render|view WORLD.tiles``
    draw with) takes a ``pixel_error`` to its streaming renderer: a larger one draws the far blocks
    coarser than the default, from the same camera."""
    c = S.TileCache(world)
    try:
        budget, net = c._far_bytes + 1024, tile_net(c.store, *c.tiles[0])
    finally:
        c.close()
    tris = {}
    for pe in (S.FAR_PIXEL_ERROR, 9.0):
        st = S.StreamingTerrain(world, net, size=SIZE, ctx=gl, budget_bytes=budget, pixel_error=pe)
        try:
            assert st.streaming.far_pixel_error == pe
            tris[pe] = 0
            for cam in _low_cameras(st.streaming.cache, 4, seed=11):
                st.render(cam)
                tris[pe] += st.streaming.stats["far_block_triangles"]
        finally:
            st.release()
    assert tris[9.0] < tris[S.FAR_PIXEL_ERROR], tris


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), "3", True])
def test_a_bad_pixel_error_is_a_config_error(world, bad):
    from piste.errors import ConfigError

    with pytest.raises(ConfigError, match="pixel_error: expected a number of pixels > 0"):
        S.StreamingRenderer(world, size=SIZE, pixel_error=bad)


def test_border_strides_read_from_the_block_grid_equal_each_neighbours(world, gl):
    """The neighbours' block strides along a tile's sides sliced from the frame's world grid of
    blocks equal those looked up neighbour by neighbour, whichever tiles are drawn by block."""
    r = S.StreamingRenderer(world, size=SIZE, ctx=gl)
    try:
        rng = np.random.default_rng(1)
        tiles = r.cache.tiles
        assert len(tiles) == 4
        seen = 0
        for _ in range(6):
            st = rng.choice(np.array(S.FAR_STRIDES), len(r.cache._blk["lo"]))
            block_tiles = {t for t in tiles if rng.random() < 0.7}
            grid = r._border_grid(st, block_tiles)
            for t in tiles:
                want = r._border_strides(t, st, block_tiles)
                got = r._border_strides(t, st, block_tiles, grid)
                assert [g.tolist() for g in got] == [w.tolist() for w in want]
                seen += sum(int(w.astype(bool).sum()) for w in want)
        assert seen > 0  # (some sides had neighbours drawn by block)
    finally:
        r.close()


def test_tiles_are_drawn_nearest_first_each_in_one_go(world, gl, monkeypatch):
    """A frame binds each drawn tile's light map once (its draws together, zippers last) and the
    tiles nearest the eye first (what they hide fails the depth test unshaded); the counts of
    draws and state changes in :attr:`stats` are the calls made."""
    r = S.StreamingRenderer(world, size=SIZE, ctx=gl, near_radius=-1.0)
    try:
        bound: list = []
        light = r._light
        monkeypatch.setattr(r, "_light", lambda t: bound.append(t) or light(t))
        lo, hi = r.cache.lo.min(0), r.cache.hi.max(0)
        eye = np.array([hi[0] - 100.0, hi[1] - 100.0, hi[2] + 200.0])  # over the last tile, looking back
        cam = Camera(eye, np.array([lo[0], lo[1], lo[2]]), near=1.0, far=6000.0)
        r.render(cam, wait=True)
        assert bound[0] == r.cache.tiles[-1]
        assert len(bound) == len(set(bound)) == r.stats["light_binds"] >= 2
        d = r.cache.distances(cam.eye)[[r.cache.tile_index[t] for t in bound]]
        assert (np.diff(d) >= 0).all()
        assert r.stats["draws"] >= len(bound) and r.stats["commands"] >= r.stats["draws"] - len(bound)
        assert r.stats["cull_switches"] <= 2 * len(bound) + 1
    finally:
        r.close()


def _under_terrain(img: np.ndarray) -> np.ndarray:
    """``(h, w) bool``: background pixels with terrain above them in their column."""
    bg = (np.asarray(img) == (255, 0, 255)).all(-1)
    above = np.maximum.accumulate(~bg, axis=0)
    return bg & np.vstack([np.zeros((1, bg.shape[1]), bool), above[:-1]])


def _deepest_below_surface(cache, cam, pixels, size, step: float = 2.0) -> np.ndarray:
    """For each pixel ``(k, 2)`` (row, column) of an image of ``size`` from ``cam``: how far its
    ray dips below the exact surface of the tiles (metres, > 0: it meets the terrain) before it
    leaves the world or the far plane."""
    nets = {t: tile_net(cache.store, *t) for t in cache.tiles}
    c = cam.with_aspect(*size)
    inv = np.linalg.inv(c.view_projection())
    ts = np.arange(c.near, c.far, step)
    out = []
    for py, px in pixels:
        ndc = [(px + 0.5) / size[0] * 2 - 1, 1 - (py + 0.5) / size[1] * 2]
        a, b = inv @ [*ndc, -1.0, 1.0], inv @ [*ndc, 1.0, 1.0]
        d = b[:3] / b[3] - a[:3] / a[3]
        p = c.eye + ts[:, None] * (d / np.linalg.norm(d))
        z = np.full(len(p), np.nan)
        for t, net in nets.items():
            x0, y0, x1, y1 = cache.grid.tile_bounds_xy(*t)
            m = (p[:, 0] >= x0) & (p[:, 0] < x1) & (p[:, 1] >= y0) & (p[:, 1] < y1)
            if m.any():
                z[m] = height_at(net, p[m, :2])[0]
        out.append(np.nanmax(np.concatenate([[0.0], z - p[:, 2]])))
    return np.asarray(out)


def test_no_background_under_terrain_and_cracks_are_rays_into_the_surface(world, gl, monkeypatch):
    """Low views across the world (over the tops, and near the ground) show no background under
    terrain; where the far blocks' zippers are gone the cracks that open do, and their rays are
    ones that meet the exact surface (how background under terrain in a large world's views is told
    from sky seen past its edge or its far plane: those rays pass over the surface)."""
    r = S.StreamingRenderer(world, size=SIZE, ctx=gl, background=MAGENTA, sky=False)
    try:
        cams = _low_cameras(r.cache, 8, seed=5)
        rng = np.random.default_rng(2)
        lo, hi = r.cache.lo.min(0), r.cache.hi.max(0)
        for _ in range(8):  # 2 to 30 m over the snow, looking across it
            x, y = rng.uniform(lo[:2] + 100.0, hi[:2] - 100.0)
            z = float(height_at(tile_net(r.cache.store, *r.cache.grid.tile_of(x, y)), np.array([[x, y]]))[0][0])
            a = rng.uniform(0.0, 2.0 * np.pi)
            eye = np.array([x, y, z + rng.uniform(2.0, 30.0)])
            cams.append(Camera(eye, eye + np.array([np.cos(a), np.sin(a), rng.uniform(-0.3, 0.05)]) * 1000.0,
                               near=1.0, far=6000.0))
        assert [int(_under_terrain(r.render(cam, wait=True)).sum()) for cam in cams] == [0] * len(cams)
        # the control: far tiles only, strides 1 and 8 side by side without zippers: cracks, and
        # their rays go into the surface
        r.close()
        r = S.StreamingRenderer(world, size=SIZE, ctx=gl, background=MAGENTA, sky=False, near_radius=-1.0,
                                pixel_error=None)
        checker = np.where(np.arange(len(r.cache._blk["lo"])) % 2 == 0, 1, 8)
        monkeypatch.setattr(r.cache, "block_strides", lambda eye, scale, tiles, error=3.0: checker)
        for t in r.cache.tiles:
            for mesh in r.cache.far[t].values():
                mesh.blocks["zip_count"] = np.zeros_like(mesh.blocks["zip_count"])
        deep = []
        for cam in _steep_cameras(r.cache):
            px = np.argwhere(_under_terrain(r.render(cam, wait=True)))[:10]
            if len(px):
                deep.append(_deepest_below_surface(r.cache, cam, px, SIZE).max())
        assert deep and min(deep) > 1.0
    finally:
        r.close()


def test_command_indices_are_what_the_commands_draw():
    """The indices a list of indirect commands draws, back to back (instances 0: none; base vertex
    added), and a command beyond the buffer is refused."""
    idx = np.arange(30, dtype=np.uint32).reshape(10, 3)
    cmd = np.array([[6, 1, 3, 0, 0], [3, 0, 12, 0, 0], [3, 1, 24, 100, 0]], np.uint32)
    assert S.command_indices(idx, cmd).tolist() == [3, 4, 5, 6, 7, 8, 124, 125, 126]
    assert len(S.command_indices(idx, np.zeros((0, 5), np.uint32))) == 0
    with pytest.raises(ValueError, match="reach index"):
        S.command_indices(idx, np.array([[6, 1, 27, 0, 0]], np.uint32))


def test_far_tiles_draw_their_runs_as_index_lists_with_the_same_picture(world, gl):
    """Far tiles drawn by block from one index list a stride and kind draw the picture the
    multi-draw of their runs does, with fewer indirect commands."""
    r = S.StreamingRenderer(world, size=SIZE, ctx=gl, near_radius=-1.0, pixel_error=None)
    try:
        for cam in _low_cameras(r.cache, 4, seed=7) + _steep_cameras(r.cache)[:2]:
            r.far_indices = True
            a = r.render(cam, wait=True)
            sa = dict(r.stats)
            r.far_indices = False
            r._far_runs.clear()
            b = r.render(cam, wait=True)
            sb = dict(r.stats)
            r._far_runs.clear()
            assert np.array_equal(a, b)
            assert sa["triangles"] == sb["triangles"] and sa["draws"] == sb["draws"]
            assert sa["far_blocks"] > 0 and sa["commands"] < sb["commands"]
    finally:
        r.close()


def test_boxes_by_columns_are_culled_as_boxes_by_rows():
    """The frustum test of boxes given by columns keeps exactly the boxes the row test keeps."""
    rng = np.random.default_rng(4)
    c, h = rng.uniform(-500.0, 500.0, (2000, 3)), rng.uniform(1.0, 40.0, (2000, 3))
    for _ in range(5):
        eye = rng.uniform(-200.0, 200.0, 3)
        planes = Camera(eye, eye + rng.normal(size=3) * 100.0, near=1.0, far=600.0).frustum_planes()
        want = S._boxes_visible(planes, c - h, c + h)
        got = S._boxes_visible_cols(planes, np.ascontiguousarray((c - h).T), np.ascontiguousarray((c + h).T))
        assert 0 < want.sum() < len(want)
        assert np.array_equal(got, want)


def test_boxes_in_a_bound_are_culled_as_without_it():
    """With a box holding them all, the column test skips the planes the bound lies wholly inside and
    culls all when it lies wholly outside one: the same boxes kept as without it, for eyes inside,
    beside and far from the boxes (some planes skipped, some not, some frames culling all)."""
    rng = np.random.default_rng(5)
    c, h = rng.uniform(-300.0, 300.0, (4096, 3)), rng.uniform(1.0, 20.0, (4096, 3))
    lo, hi = np.ascontiguousarray((c - h).T), np.ascontiguousarray((c + h).T)
    bound = (lo.min(1), hi.max(1))
    kinds = set()
    for k in range(60):
        eye = rng.uniform(-2500.0, 2500.0, 3) if k % 2 else rng.uniform(-250.0, 250.0, 3)
        planes = Camera(eye, eye + rng.normal(size=3) * 100.0, near=1.0, far=rng.uniform(200.0, 5000.0)).frustum_planes()
        want = S._boxes_visible_cols(planes, lo, hi)
        assert np.array_equal(S._boxes_visible_cols(planes, lo, hi, bound), want)
        n = planes[:, :3]
        inside = (np.where(n > 0, bound[0], bound[1]) * n).sum(1) >= -planes[:, 3]  # planes skipped
        outside = ((np.where(n > 0, bound[1], bound[0]) * n).sum(1) < -planes[:, 3]).any()  # all culled at once
        kinds.add("cull all" if outside else "skip some" if 0 < inside.sum() < 6 and 0 < want.sum() < len(want)
                  else "other")
    assert {"cull all", "skip some"} <= kinds, kinds


def _far_distance(cp: np.ndarray, g: np.ndarray, stride: int, per_patch: int = 24, seed: int = 0) -> np.ndarray:
    """The largest vertical distance, per far block, between a tile's patches ``cp (ny nx, 4, 4, 3)``
    and its far mesh at ``stride`` (the mesh's own triangles, found point by point): random points
    and each patch's centre and edge midpoints, ``(by bx,)``."""
    ny, nx = g.shape[0] - 1, g.shape[1] - 1
    mesh = S.far_mesh({"far_positions": g, "far_colors": np.zeros(g.shape, np.uint8)}, 10.0, stride)
    cells = 2 * (len(S._stride_index(ny + 1, stride)) - 1) * (len(S._stride_index(nx + 1, stride)) - 1)
    tri = mesh.positions.astype(np.float64)[mesh.indices[:cells].astype(np.int64)]  # (t, 3, 3)
    rng = np.random.default_rng(seed)
    s, t = rng.uniform(0.0, 1.0, (2, ny * nx, per_patch))
    s[:, :5], t[:, :5] = [0.5, 0.0, 1.0, 0.5, 0.5], [0.5, 0.5, 0.5, 0.0, 1.0]
    p = np.einsum("nma,nabd,nmb->nmd", bernstein(s), np.asarray(cp, np.float64), bernstein(t)).reshape(-1, 3)
    pid = np.repeat(np.arange(ny * nx), per_patch)
    bx = -(-nx // S.FAR_BLOCK)
    blk = (pid // nx // S.FAR_BLOCK) * bx + pid % nx // S.FAR_BLOCK
    out = np.zeros(int(blk.max()) + 1)
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    e0, e1 = (b - a)[None, :, :2], (c - a)[None, :, :2]
    den = e0[..., 0] * e1[..., 1] - e1[..., 0] * e0[..., 1]
    for i in range(0, len(p), 1000):
        q = p[i:i + 1000, None, :2] - a[None, :, :2]
        l1 = (q[..., 0] * e1[..., 1] - e1[..., 0] * q[..., 1]) / den
        l2 = (e0[..., 0] * q[..., 1] - q[..., 0] * e0[..., 1]) / den
        inside = (l1 >= -1e-9) & (l2 >= -1e-9) & (l1 + l2 <= 1.0 + 1e-9)
        assert inside.any(1).all()
        j, r = inside.argmax(1), np.arange(len(q))
        h = (1.0 - l1[r, j] - l2[r, j]) * a[j, 2] + l1[r, j] * b[j, 2] + l2[r, j] * c[j, 2]
        np.maximum.at(out, blk[i:i + 1000], np.abs(p[i:i + 1000, 2] - h))
    return out


def test_block_errors_bound_the_surfaces_distance_from_each_stride(world):
    """The loader measures every tile's far block errors against its patches; they bound the
    surface's distance from each stride's far mesh (sampled densely, the mesh's own triangles)
    over every block, also where a tile's patch count is not a multiple of the stride, and tightly
    (not a loose or infinite bound)."""
    cache = S.TileCache(world, budget_bytes=256 << 20)
    try:
        cache.update(cache.hi.max(0) + 100.0, pixel_scale=300.0)
        cache.wait_idle()
        assert cache.exact_errors == set(cache.tiles)
        t = cache.tiles[0]
        cp = cache._read("fit", t, ("control_points",))["control_points"]
        g = cache._read("lit", t, ("far_positions",))["far_positions"]
    finally:
        cache.close()
    n = g.shape[0] - 1
    assert n == 24
    assert np.array_equal(cache.blocks[t]["err"], block_stride_errors(cp, g[..., 2], (n, n), S.FAR_BLOCK,
                                                                      S.FAR_STRIDES[1:]))
    for m in (24, 20):  # the whole tile; its first 20 x 20 patches (a short trailing cell at stride 8)
        c2, g2 = cp.reshape(n, n, 4, 4, 3)[:m, :m].reshape(-1, 4, 4, 3), g[:m + 1, :m + 1]
        bound = block_stride_errors(c2, g2[..., 2], (m, m), S.FAR_BLOCK, S.FAR_STRIDES)
        for j, k in enumerate(S.FAR_STRIDES):
            true = _far_distance(c2, g2, k)
            assert (true <= bound[:, j]).all(), (m, k, true - bound[:, j])
            assert (bound[:, j] <= 1.35 * true + 0.5).all(), (m, k, bound[:, j] / true)


def _local_estimate(far_positions: np.ndarray, chord: float) -> np.ndarray:
    """The block errors the streaming renderer once chose strides by (``far_blocks``' old ``err``):
    each coarser stride's bilinear error against the corner grid over the block plus a chord
    estimate (a quarter of the largest second difference of the corner heights around the block, at
    most the tile's ``chord``): ``(nb, 3)`` metres."""
    z = np.asarray(far_positions, dtype=np.float64)[..., 2]
    sd = np.zeros_like(z)
    sd[1:-1] = np.abs(z[2:] - 2.0 * z[1:-1] + z[:-2])
    sd[:, 1:-1] = np.maximum(sd[:, 1:-1], np.abs(z[:, 2:] - 2.0 * z[:, 1:-1] + z[:, :-2]))
    sd = np.maximum(sd, np.maximum(np.roll(sd, 1, 0), np.roll(sd, -1, 0)))
    sd = np.maximum(sd, np.maximum(np.roll(sd, 1, 1), np.roll(sd, -1, 1)))
    ch = np.minimum(S._block_reduce(sd, np.maximum) / 4.0, chord)
    grids = S.stride_error_grids(far_positions)
    return np.stack([S._block_reduce(grids[k], np.maximum) + ch for k in S.FAR_STRIDES[1:]], -1).reshape(-1, 3)


def test_exact_block_errors_choose_strides_no_finer_than_the_estimate(world):
    """Against the local estimate they replace (corner-grid bilinear error plus a chord estimate with
    a 2x safety factor), the measured errors draw fewer triangles over many eyes, and any block drawn
    finer than before is one where the estimate was below (or within 15 % of) the surface's true
    distance: the estimate was no bound there."""
    cache = S.TileCache(world, budget_bytes=256 << 20)
    try:
        cache.update(cache.hi.max(0) + 100.0, pixel_scale=300.0)
        cache.wait_idle()
        old, true = [], []
        for t in cache.tiles:
            cp = cache._read("fit", t, ("control_points",))["control_points"]
            lit = cache._read("lit", t, ("far_positions", "far_error"))
            old.append(_local_estimate(lit["far_positions"], float(lit["far_error"][0])))
            true.append(np.stack([_far_distance(cp, lit["far_positions"], k) for k in S.FAR_STRIDES[1:]], -1))
        old, true = np.concatenate(old), np.concatenate(true)
        assert (cache._blk["err"] >= true).all()

        def strides(err, eye, scale):
            c = S.TileCache.__new__(S.TileCache)
            c._blk = dict(cache._blk, err=err)
            c.block_start, c._lock = cache.block_start, threading.Lock()
            return c.block_strides(eye, scale, np.ones(len(cache.tiles), np.int64))

        rng = np.random.default_rng(5)
        lo, hi = cache.lo.min(0), cache.hi.max(0)
        patches = cache._blk["patches"]
        finer = coarser = 0
        tris_old = tris_new = 0.0
        for eye in rng.uniform(lo - [500.0, 500.0, 0.0], hi + [500.0, 500.0, 800.0], (30, 3)):
            for scale in (100.0, 300.0, 1000.0):
                a, b = strides(old, eye, scale), strides(cache._blk["err"], eye, scale)
                tris_old += (2 * patches / a ** 2).sum()
                tris_new += (2 * patches / b ** 2).sum()
                bad = b < a
                finer += int(bad.sum())
                coarser += int((b > a).sum())
                for i in np.nonzero(bad)[0]:  # the estimate was below (or near) the truth at b's stride
                    j = S.FAR_STRIDES.index(int(a[i])) - 1
                    assert old[i, j] < 1.15 * true[i, j], (i, old[i, j], true[i, j])
        assert coarser > 5 * max(finer, 1) and tris_new < 0.95 * tris_old
    finally:
        cache.close()


def test_kept_glue_and_tile_bounds_draw_what_a_fresh_frame_draws(world, gl):
    """Frames drawn one after another (glued patches' index lists kept while their sides stay, near and
    middle tiles tested by their bound first) equal frames drawn between other views and frames
    with ``tile_bounds`` off and the glue rebuilt every frame, pixel for pixel; the views glue
    patches and draw tiles wholly from the corner grid by their bound."""
    low = _low_cameras(S.TileCache(world), 8, seed=3)
    cams = low + [Camera(c.eye + [0.0, 0.0, 800.0], c.target, near=1.0, far=6000.0) for c in low]  # (and higher)
    a = S.StreamingRenderer(world, size=SIZE, ctx=gl, background=MAGENTA, sky=False)
    b = S.StreamingRenderer(world, size=SIZE, ctx=gl, background=MAGENTA, sky=False)
    try:
        seq, glued, bound = [], 0, 0
        for cam in cams + cams[::-1]:
            seq.append(a.render(cam, wait=True))
            glued += sum(got[4] for got in a._glue.values())
            bound += a.stats["bound_coarse"]
        other = _steep_cameras(b.cache)
        mixed = []
        for k, cam in enumerate(cams + cams[::-1]):
            b.render(other[k % len(other)], wait=True)
            mixed.append(b.render(cam, wait=True))
        # the shortcuts off: every patch's own test, the glue rebuilt every frame
        b.tile_bounds = False
        plain = []
        for cam in cams + cams[::-1]:
            for got in b._glue.values():
                got[1].release()
                got[0].release()
            b._glue.clear()
            plain.append(b.render(cam, wait=True))
        assert glued > 0 and bound > 0 and b.stats["bound_coarse"] == 0
        for x, y, z in zip(seq, mixed, plain):
            assert np.array_equal(x, y) and np.array_equal(x, z)
    finally:
        a.close()
        b.close()
