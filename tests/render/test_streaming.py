"""Streaming a tiled world: paging under a fixed memory budget with a background loader, near and
far meshes that close every tile border (skirts), frames without holes, and ``piste render WORLD.tiles``."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import ConfigError
from piste.pipeline.tiled_build import build_tiles, synthetic_spec
from piste.render import streaming as S
from piste.terrain.tiles import TileStore
from piste.world.camera import Camera

MAGENTA = (1.0, 0.0, 1.0)


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """48 x 48 patches (2.88 km square) in 6 x 6 tiles of 8 x 8 patches, 3 x 3 light-map texels."""
    root = tmp_path_factory.mktemp("streaming") / "w.tiles"
    build_tiles(synthetic_spec(root, 48, tile_patches=8, res=3, spacing=20.0, shadows=False))
    return root


def test_pages_nearest_tiles_within_the_budget(world):
    one = S.mesh_bytes(8 * 2 + 1, 8 * 2 + 1, morph=True)  # a near tile's mesh (with its geomorph targets)
    lit = TileStore(world).read("lit", 0, 0)  # far levels: the corner grid at strides 1..8 (every tile alike)
    far = sum(S.far_mesh(lit, 1.0, k).nbytes for k in S.FAR_STRIDES) * 36
    far += 17 * 17 * 3 * 36  # and each tile's welded light map (near and far levels sample it)
    cache = S.TileCache(world, budget_bytes=far + 3 * one + 100, near_radius=1000.0, near_samples=3)
    try:
        assert cache.resident_bytes == far and not cache.near  # far stand-ins for every tile up front
        seen = set()
        for x in np.linspace(100.0, 2780.0, 9):  # fly along the diagonal
            cache.update((x, x, 0.0))
            cache.wait_idle()
            assert cache.resident_bytes <= cache.budget
            assert len(cache.near) == 3
            d = sorted(cache.distance((x, x), t) for t in cache.bounds)
            assert sorted(cache.distance((x, x), t) for t in cache.near) == d[:3]  # the nearest ones
            for t, m in cache.near.items():
                assert m.nbytes == cache._near_estimate[t] == one
            seen |= set(cache.near)
        assert len(seen) > 6 and cache.loaded_count >= len(seen)  # tiles were paged out and in
        kinds = [k for _, k, _ in cache.draw_list()]
        assert kinds.count("near") == 3 and kinds.count("far1") == 33
        # far tiles coarsen with distance: stride 1 next to the eye, 8 across the world
        strides = {cache.far_stride((100.0, 100.0), t) for t in cache.bounds}
        assert strides == {1, 2, 4, 8} and cache.far_stride((100.0, 100.0), (0, 0)) == 1
    finally:
        cache.close()
    with pytest.raises(ConfigError, match="below the far field"):
        S.TileCache(world, budget_bytes=far // 2)


def test_per_frame_choices_match_the_per_tile_formulas(world):
    """The per-frame tile choices work on whole arrays (one per tile precomputed at load): the same
    far strides as the per-tile rule, the same boxes in view as the per-corner test."""
    cache = S.TileCache(world, budget_bytes=256 << 20)
    try:
        rng = np.random.default_rng(3)
        seen = set()
        for eye in rng.uniform([-500.0, -500.0, 0.0], [3400.0, 3400.0, 900.0], (12, 3)):
            for scale in (50.0, 400.0, 3000.0):
                allowed = np.sqrt((np.maximum(np.maximum(cache.lo - eye, eye - cache.hi), 0.0) ** 2).sum(1)) \
                    * S.FAR_PIXEL_ERROR / scale
                want = [max([1] + [k for j, k in enumerate(S.FAR_STRIDES[1:])  # its blocks' largest error fits
                                   if cache.blocks[t]["err"][:, j].max() <= allowed[i]])
                        for i, t in enumerate(cache.tiles)]
                assert cache.far_strides(eye, scale).tolist() == want
                seen |= set(want)
        assert len(seen) > 1  # eyes and scales that choose different levels
    finally:
        cache.close()
    lo = rng.uniform(-10.0, 10.0, (500, 3))
    hi = lo + rng.uniform(0.0, 5.0, (500, 3))
    for _ in range(5):
        planes = np.concatenate([rng.normal(size=(6, 3)), rng.uniform(-5.0, 5.0, (6, 1))], 1)
        p = np.where(planes[None, :, :3] >= 0.0, hi[:, None, :], lo[:, None, :])  # each box's positive vertex
        want = ((p * planes[None, :, :3]).sum(-1) + planes[None, :, 3] >= 0.0).all(-1)
        got = S._boxes_visible(planes, lo, hi)
        assert (got == want).all() and 0 < got.sum() < len(got)


def test_meshes_share_tile_borders(world):
    store = TileStore(world)
    a, b = store.read("lit", 2, 2), store.read("lit", 2, 3)
    fa, fb = S.far_mesh(a, 10.0), S.far_mesh(b, 10.0)
    ga, gb = fa.positions[:81].reshape(9, 9, 3), fb.positions[:81].reshape(9, 9, 3)
    assert np.array_equal(ga[:, -1], gb[:, 0])  # far grids meet exactly
    coarse = S.far_mesh(a, 10.0, stride=4).positions[:9].reshape(3, 3, 3)  # corners 0, 4, 8
    assert np.array_equal(coarse, ga[::4, ::4])
    na = S.near_mesh(store.read("fit", 2, 2), a, (8, 8), 10.0)
    nb = S.near_mesh(store.read("fit", 2, 3), b, (8, 8), 10.0)
    pa, pb = na.positions[:17 * 17].reshape(17, 17, 3), nb.positions[:17 * 17].reshape(17, 17, 3)
    assert np.allclose(pa[:, -1], pb[:, 0], atol=1e-3)  # near borders: the same edge curves
    assert np.array_equal(pa[::2, -1], ga[:, -1].astype(np.float32))  # patch corners are the far vertices
    # every triangle index is in range; skirts hang below the border
    assert na.indices.max() < len(na.positions)
    skirts = na.positions[17 * 17:].reshape(4, 2, 17, 3)  # each side: its border, then its copy 10 m lower
    assert np.allclose(skirts[:, 1], skirts[:, 0] - [0.0, 0.0, 10.0], atol=1e-3)


def _holes(renderer, cams) -> list[int]:
    out = []
    for cam in cams:
        img = renderer.render(cam, wait=True)
        out.append(int((img == (255, 0, 255)).all(-1).sum()))
    return out


def _views(world):
    import json

    idx = json.loads((world / "index.json").read_text())
    ztop = max(t["bounds"][1][2] for t in idx["tiles"].values())
    # steep views from inside the world: only terrain can be in the picture, across several tile
    # borders between near and far tiles
    eyes = [(1440.0, 1000.0), (1300.0, 1300.0), (1700.0, 1200.0), (1000.0, 1500.0)]
    return [Camera(np.array([x, y, ztop + 150.0]), np.array([x + 250.0, y + 420.0, ztop - 500.0]), near=1.0,
                   far=6000.0) for x, y in eyes]


def test_no_background_through_tile_borders(world, gl, monkeypatch):
    r = S.StreamingRenderer(world, size=(200, 150), budget_bytes=4 << 20, near_radius=250.0, ctx=gl,
                            background=MAGENTA, pixel_error=None, sky=False)
    try:
        holes = _holes(r, _views(world))
        assert r.stats["near"] >= 1 and r.stats["far"] >= 4  # both levels and their borders in view
        assert holes == [0, 0, 0, 0]
        assert r.stats["resident_bytes"] <= 4 << 20
    finally:
        r.close()
    # the same views without skirts do show the background at near/far borders: the test can fail
    monkeypatch.setattr(S, "_with_skirts", lambda p, c, t, sides, depth, f=S._with_skirts: f(p, c, t, sides, 0.0))
    monkeypatch.setattr(S, "far_mesh", lambda lit, depth, stride=1, f=S.far_mesh: f(lit, 0.0, stride))
    r = S.StreamingRenderer(world, size=(200, 150), budget_bytes=4 << 20, near_radius=250.0, ctx=gl,
                            background=MAGENTA, pixel_error=None, sky=False)
    try:
        assert sum(_holes(r, _views(world))) > 0
    finally:
        r.close()


def test_far_stand_ins_while_loading_and_cli(world, gl, tmp_path, capsys):
    r = S.StreamingRenderer(world, size=(96, 64), budget_bytes=4 << 20, ctx=gl)
    try:
        cam = next(S.fly_path(r.cache.index, 1))
        cam = Camera(cam.eye, cam.eye + np.array([60.0, 60.0, -400.0]), near=1.0, far=6000.0)  # the tile below
        img = r.render(cam, wait=False)  # nothing near yet: far stand-ins only, still a full picture
        assert r.stats["far"] > 0 and img.std() > 5
        r.cache.wait_idle()
        r.render(cam)
        assert r.stats["near"] > 0
    finally:
        r.close()
    from piste.cli import main

    out = tmp_path / "f.png"
    assert main(["render", str(world), "--out", str(out), "--frames", "4", "--size", "64", "48", "--budget", "4",
                 "--quiet"]) == 0
    text = capsys.readouterr().out
    assert out.stat().st_size > 100 and "4 frame(s) flying at 100 m/s" in text
    assert main(["render", str(tmp_path / "none.tiles")]) == 1
    assert "no such tiled world" in capsys.readouterr().err


def test_piste_view_tiles_headless_and_in_a_window(world, gl_context, tmp_path, monkeypatch, capsys):
    import os
    import shutil
    import subprocess
    import sys

    from PIL import Image

    from piste.cli import main

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    out = tmp_path / "v.png"
    assert main(["view", str(world), "--out", str(out), "--size", "64", "48"]) == 0
    assert "no display" in capsys.readouterr().err
    assert np.asarray(Image.open(out)).std() > 5
    if shutil.which("xvfb-run") is None:
        if os.environ.get("PISTE_REQUIRE_TOOLS") == "1":
            pytest.fail("xvfb-run is missing (apt-get install xvfb)")
        pytest.skip("xvfb-run not installed (apt-get install xvfb)")
    pytest.importorskip("pyglet")
    shot = tmp_path / "w.png"
    cmd = ["xvfb-run", "-a", "-s", "-screen 0 640x480x24", sys.executable, "-m", "piste.cli", "view", str(world),
           "--size", "96", "64", "--frames", "4", "--out", str(shot)]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=dict(os.environ))
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert "4 frames" in r.stdout
    img = np.asarray(Image.open(shot))
    assert img.shape == (64, 96, 3) and img.std() > 5


@pytest.fixture(scope="module")
def rough_world(tmp_path_factory):
    """24 x 24 patches of 600 m relief in 3 x 3 tiles, with per-tile visibility sets (60 m cells)."""
    from piste.pipeline.tiled_build import SyntheticSource

    root = tmp_path_factory.mktemp("streaming_vis") / "w.tiles"
    spec = synthetic_spec(root, 24, tile_patches=8, res=3, spacing=20.0, shadows=False, cell=60.0)
    spec.source = SyntheticSource(spec.source.shape, spec.source.spacing, 0, relief=600.0, wavelength=400.0)
    build_tiles(spec)
    return root


def _ground_cameras(cache, n: int, seed: int = 0) -> list:
    """``n`` eyes 2 m over the snow (riders' eyes: within the sets' band), looking level-ish."""
    from piste.terrain.query import height_at
    from piste.terrain.tiles import tile_net

    rng = np.random.default_rng(seed)
    cams = []
    for _ in range(n):
        x, y = rng.uniform(100.0, 1340.0, 2)
        z = float(height_at(tile_net(cache.store, *cache.grid.tile_of(x, y)), np.array([[x, y]]))[0][0])
        a = rng.uniform(0.0, 2.0 * np.pi)
        look = np.array([x + 300.0 * np.cos(a), y + 300.0 * np.sin(a), z - 20.0])
        cams.append(Camera(np.array([x, y, z + 2.0]), look, near=0.5, far=5000.0))
    return cams


def test_visibility_sets_cull_near_patches_without_losing_pixels(rough_world, gl):
    """The sets of the tile under the eye cull its own patches and its neighbours' (near, middle and
    full-corner-grid meshes), and not a pixel is lost (issue 26: with a tile's own patches alone,
    5 of 3200 near patches were left out over these eyes)."""
    r = S.StreamingRenderer(rough_world, size=(160, 120), near_radius=100.0, pixel_error=None, ctx=gl)
    try:
        drawn = {True: 0, False: 0}
        culled = lost = neighbours = 0
        for cam in _ground_cameras(r.cache, 24):
            img = {}
            for v in (False, True):
                r.visibility = v
                img[v] = r.render(cam, wait=True)
                drawn[v] += r.stats["near_patches"] + r.stats["far_patches"]
            culled += r.stats["vis_culled"]
            lost += int((img[True] != img[False]).any(-1).sum())
            under = r.cache.grid.tile_of(*cam.eye[:2])
            for t in r.cache.tiles:
                seen = r.cache.visible_patches(t, cam.eye)
                neighbours += int((~seen).sum()) if seen is not None and t != under else 0
        assert all(r.cache.vis[t] is not None for t in r.cache.near)  # the build's sets were read
    finally:
        r.close()
    assert culled > 100 and drawn[True] == drawn[False] - culled  # patches left out ...
    assert neighbours > 0  # (the sets say what the eye's tile sees of its neighbours)
    assert lost == 0  # ... and not a pixel lost


def test_sets_are_not_used_while_their_tiles_are_drawn_coarser(rough_world, gl):
    """The sets' occluders were lowered to the near, middle and full corner-grid meshes: while a
    tile of theirs in view is drawn coarser (a far level of stride > 1 sags further), the frame
    draws every patch."""
    r = S.StreamingRenderer(rough_world, size=(160, 120), near_radius=100.0, pixel_error=None, ctx=gl)
    try:
        cams = _ground_cameras(r.cache, 8, seed=3)
        for cam in cams:
            r.render(cam, wait=True)
            assert r.stats["vis_off"] == 0 and r.cache.vis[r.cache.grid.tile_of(*cam.eye[:2])].levels == (2, 3, 4)
        r.cache.far_strides = lambda eye, scale, error=3.0: np.full(len(r.cache.tiles), 8)  # every far tile at stride 8
        off = 0
        for cam in cams:
            r.render(cam, wait=True)
            off += r.stats["vis_off"]
            assert r.stats["vis_culled"] == 0 or not r.stats["vis_off"]
        assert off > 0
    finally:
        r.close()


def test_bad_visibility_sets_name_the_tile(rough_world, tmp_path):
    import shutil

    from piste.terrain.tiles import TileError

    root = tmp_path / "w.tiles"
    shutil.copytree(rough_world, root)
    cache = S.TileCache(root)
    try:
        assert cache._read_vis((1, 1)) is not None
        p = cache.store.path("lit", 1, 1)
        a = dict(np.load(p))
        a["vis_patch_bits"] = a["vis_patch_bits"][:, :3]
        with open(p, "wb") as fh:
            np.savez(fh, **a)
        with pytest.raises(TileError, match="patch bits") as exc:
            cache._read_vis((1, 1))
        assert "1,1" in str(exc.value) or "(1, 1)" in str(exc.value)
    finally:
        cache.close()


def test_a_level_switch_does_not_pop(world, gl):
    """The camera still, the pixel error set just above and then just below one tile's far-grid
    error on screen: the tile goes from its far grid to the middle level (evaluated patches), drawn
    fully morphed onto the far grid at that point, so the picture stays the same; without the
    geomorph the switch shows."""
    r = S.StreamingRenderer(world, size=(160, 120), ctx=gl)
    try:
        cam = next(S.fly_path(r.cache.index, 1)).with_aspect(160, 120)
        c, e = r.cache, np.asarray(cam.eye)
        ps = r.lod_scale(cam.fov_y)  # pixels a radian the levels are chosen at
        seen = S._boxes_visible(cam.frustum_planes(), c.lo, c.hi)
        d3 = np.sqrt((np.maximum(np.maximum(c.lo - e, e - c.hi), 0.0) ** 2).sum(1))
        px = [(c.chord_error[t] * ps / d3[i], t) for i, t in enumerate(c.tiles)
              if seen[i] and c.distances(e)[i] > c.near_radius]
        err, tile = max(px)  # the far tile whose grid shows most
        assert err > 0.5

        def pair(morph: bool):
            out = []
            for pe in (err * 1.001, err * 0.999):
                r.pixel_error = pe
                if not morph:
                    c.morph_factors = lambda eye, p, q: {}
                img = r.render(cam, wait=True).astype(float)
                out.append((img, c.near_level.get(tile)))
            return out

        (a, la), (b, lb) = pair(True)
        assert la is None and lb == S.MID_SAMPLES  # the tile switched from far to middle
        assert np.abs(a - b).max() <= 2.0  # no pop (rounding at most)
        (a, _), (b, _) = pair(False)
        assert (np.abs(a - b).max(-1) > 8).sum() > 10  # without the geomorph it pops
    finally:
        r.close()


def test_patch_runs_draw_the_chosen_patches_and_the_skirts():
    inside = np.array([1, 1, 0, 1, 0, 0, 1, 1, 1], bool)
    cmd = S.patch_runs(inside, 8, 9 * 8 + 5)
    assert cmd.dtype == np.uint32 and cmd.shape == (4, 5)
    assert cmd[:, 1].tolist() == [1] * 4 and not cmd[:, 3:].any()  # one instance, no base vertex
    assert cmd[:, 2].tolist() == [0, 3 * 24, 6 * 24, 9 * 24]  # first index of each run, then the skirts'
    assert cmd[:, 0].tolist() == [2 * 24, 24, 3 * 24, 5 * 3]
    drawn = np.concatenate([np.arange(f, f + c, 3) for c, _, f, _, _ in cmd]) // 3  # the triangles drawn
    assert drawn.tolist() == [t for t in range(9 * 8) if inside[t // 8]] + list(range(72, 77))
    assert S.patch_runs(inside, 8, 77, skirts=False).shape == (3, 5)
    assert S.patch_runs(np.zeros(9, bool), 8, 77, skirts=False).shape == (0, 5)


def test_middle_tiles_draw_their_far_patches_from_the_corner_grid(world, gl):
    """A middle tile draws the patches whose corner-grid error is under the pixel error on screen from
    its corner grid (the middle mesh geomorphed per vertex onto it where they meet, glued to its
    edges): fewer triangles, no background through the seams, the same picture but for a few
    pixels of rounding on silhouettes."""
    r = S.StreamingRenderer(world, size=(320, 224), ctx=gl, background=MAGENTA, sky=False)
    try:
        cams = list(S.fly_path(r.cache.index, 31))[::10]
        mixed_any = 0
        for cam in cams:
            r.mix_levels = True
            a = r.render(cam, wait=True).astype(int)
            sa = dict(r.stats)
            r.mix_levels = False
            b = r.render(cam, wait=True).astype(int)
            sb = dict(r.stats)
            mixed_any += sa["mid_far_patches"]
            assert sa["mid"] == sb["mid"] > 0 and sb["mid_far_patches"] == 0
            assert sa["triangles"] < sb["triangles"] or sa["mid_far_patches"] == 0
            assert (a == (255, 0, 255)).all(-1).sum() == (b == (255, 0, 255)).all(-1).sum()  # no holes
            assert (np.abs(a - b).max(-1) > 8).sum() <= 5
        assert mixed_any > 100
        # the glue: a middle patch beside a corner-grid one draws that side as the corner grid's edge
        t = next(t for t in r.cache.near if r.cache.near_level[t] == S.MID_SAMPLES)
        mesh = r.cache.near[t]
        glued = np.zeros((64, 4), bool)
        glued[10, 0] = glued[10, 3] = True  # patch (1, 2): its south and west sides
        tri = S.glue_indices(mesh, (8, 8), glued)
        row, col = tri // 17, tri % 17  # the middle mesh's 17 x 17 grid, 2 cells a patch
        assert len(tri) == 6 and tri.max() < 17 * 17  # 8 triangles less the 2 collapsed to nothing
        assert ((row >= 2) & (row <= 4) & (col >= 4) & (col <= 6)).all()  # patch (1, 2)'s vertices ...
        assert not ((row == 2) & (col == 5)).any() and not ((col == 4) & (row == 3)).any()  # ... less its sides' midpoints
        p = mesh.positions[tri.astype(int)][..., :2].astype(np.float64)
        u, w = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
        area = (u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]) / 2.0
        assert (area > 0).all() and np.isclose(area.sum(), 60.0 * 60.0)  # the patch, once, counter-clockwise
        assert S.glue_indices(mesh, (8, 8), np.zeros((64, 4), bool)).shape == (0, 3)
    finally:
        r.close()


def test_window_net_holds_the_patches_in_view_bit_for_bit(world):
    """The one-net reference of bench_large's decomposition: exactly the tiles' patches whose boxes
    meet a camera's frustum (its own far plane), their control points unchanged; a farther far
    plane takes more; no patch in view is an error."""
    from piste.terrain.tiles import tile_net

    store = TileStore(world)
    grid = store.grid()
    cams = _views(world)[:2]
    near = [Camera(c.eye, c.target, near=1.0, far=800.0) for c in cams]
    net = S.window_net(world, near)
    every = np.concatenate([tile_net(store, *t).control_points for t in grid.tiles()])
    lo, hi = every.min((1, 2)), every.max((1, 2))
    want = np.zeros(len(every), bool)
    for c in near:
        want |= S._boxes_visible(c.with_aspect(640, 448).frustum_planes(), lo, hi)
    assert 0 < want.sum() < len(every)
    got = {a.tobytes() for a in net.control_points}
    assert got == {a.tobytes() for a in every[want]}
    assert len(S.window_net(world, cams)) > len(net)
    away = [Camera(np.array([-5000.0, -5000.0, 100.0]), np.array([-6000.0, -6000.0, 100.0]), near=1.0, far=500.0)]
    with pytest.raises(ConfigError, match="no patch"):
        S.window_net(world, away)
