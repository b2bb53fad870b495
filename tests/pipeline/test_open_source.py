"""Every source opens as the one runtime scene (pipeline.open_scene.open_source) and is drawn by
ScenePreview/SceneRenderer: an SSX level written by piste's own encoder, with and without riders."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import ConfigError
from piste.pipeline.ssx_synth import make_level
from piste.pipeline.open_scene import SOURCES, open_source, source_kind
from piste.pipeline.preview import ScenePreview
from piste.pipeline.ssx_level import load_level
from piste.pipeline.ssx_source import level_camera
from piste.render.scene_renderer import SceneRenderer
from piste.render.ssx_pass import SsxTerrainRenderer

SIZE = (128, 96)


@pytest.fixture(scope="module")
def level(tmp_path_factory):
    d = tmp_path_factory.mktemp("ssx")
    return make_level(rows=2, cols=3, seed=2).write(d, "LV")


def test_source_kinds():
    assert [source_kind(p) for p in ("a.piste", "b.TOML", "c.pbd", "w.tiles/", "w.tiles")] == \
        ["bundle", "scene", "ssx", "tiles", "tiles"]
    assert {s.kind for s in SOURCES} == {"bundle", "scene", "ssx", "tiles"}
    with pytest.raises(ConfigError, match=r"x\.obj.*expected one of"):
        source_kind("x.obj")


@pytest.mark.parametrize("mode", ["modulate", "ps2"])
def test_ssx_level_through_the_runtime_is_the_level_renderers_picture(level, gl, mode):
    b = open_source(level)
    assert b.manifest["source"] == "ssx" and len(b.net) == 6 and not b.manifest["riders"]
    p = ScenePreview(b, size=SIZE, ctx=gl, lightmap_mode=mode)
    try:
        assert isinstance(p.terrain, SsxTerrainRenderer) and p.renderer is None
        img = p.render()
    finally:
        p.release()
    lv = load_level(level)  # the level's own renderer alone (what `piste ssx render` drew before issue 25)
    r = SsxTerrainRenderer(lv.net, lv.source, size=SIZE, ctx=gl, lightmap=lv.light, base_texture=lv.base_atlas,
                           lod_near=30.0, lod_far=150.0)
    try:
        ref = r.render(level_camera(lv.net), lightmap_mode=mode, fog=None).image[..., :3].copy()
    finally:
        r.release()
    assert np.array_equal(img, ref)


def test_ssx_level_with_riders_draws_them_with_shadows(level, gl):
    bare = open_source(level)
    b = open_source(level, riders=3)
    assert [r["character"] for r in b.manifest["riders"]] == ["rider"] * 3
    assert b.arrays["riders/matrix"].shape == (3, 4, 4)
    z = b.arrays["riders/matrix"][:, 2, 3]
    from piste.terrain.query import height_at

    hz, hit, _, _ = height_at(b.net, b.arrays["riders/matrix"][:, :2, 3])
    assert hit.all() and np.allclose(z, hz)  # standing on the surface
    p = ScenePreview(b, size=SIZE, ctx=gl, lightmap_mode="ps2")
    try:
        assert isinstance(p.renderer, SceneRenderer) and isinstance(p.renderer.terrain, SsxTerrainRenderer)
        img = p.render().astype(int)
        assert p.stats["riders"] == 3 and p.stats["shadow_patches"] > 0
    finally:
        p.release()
    t = ScenePreview(bare, size=SIZE, ctx=gl, lightmap_mode="ps2")
    try:
        terrain = t.render().astype(int)
    finally:
        t.release()
    d = np.abs(img - terrain).max(-1)
    assert (d > 30).sum() >= 20  # the riders are drawn
    assert np.median(d) == 0  # the rest is the level's own picture
    with pytest.raises(ConfigError, match="riders"):
        open_source(level, riders=100)


def test_cli_renders_a_level_with_riders(level, gl, tmp_path, capsys):
    from PIL import Image

    from piste.cli import main

    a, b = tmp_path / "a.png", tmp_path / "b.png"
    assert main(["render", str(level), "--size", *map(str, SIZE), "--out", str(a)]) == 0
    assert main(["render", str(level), "--size", *map(str, SIZE), "--out", str(b), "--riders", "2"]) == 0
    ia, ib = (np.asarray(Image.open(x)).astype(int) for x in (a, b))
    assert (np.abs(ia - ib).max(-1) > 30).sum() >= 10
    lo, hi = open_source(level).net.bounds
    c = (np.asarray(lo) + np.asarray(hi)) / 2
    assert main(["render", str(level), "--size", *map(str, SIZE), "--out", str(a), "--eye", str(c[0]), str(c[1] - 30),
                 "20", "--target", *map(str, c)]) == 0
    assert np.asarray(Image.open(a)).std() > 5
    assert main(["render", str(level), "--eye", "0", "0", "1", "--out", str(a)]) != 0
    assert "--eye and --target go together" in capsys.readouterr().err


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """16 x 16 patches (320 m square) in 2 x 2 tiles of 8 x 8 patches, 3 x 3 light-map texels."""
    from piste.pipeline.tiled_build import build_tiles, synthetic_spec

    root = tmp_path_factory.mktemp("tiles") / "w.tiles"
    build_tiles(synthetic_spec(root, 16, tile_patches=8, res=3, spacing=20.0, shadows=False))
    return root


def _near(bundle):
    """A camera 12 m behind the riders' middle, looking at them."""
    from piste.world.camera import Camera

    m = bundle.arrays["riders/matrix"][:, :3, 3].mean(0)
    return Camera(m + np.array([0.0, -12.0, 5.0]), m, fov_y=50.0, near=0.1, far=5000.0)


def test_tiled_world_through_the_runtime(world, gl):
    from piste.render.streaming import StreamingRenderer, StreamingTerrain

    b = open_source(world, budget_mb=8)
    assert b.manifest["terrain"]["source"] == "tiles" and len(b.net) == 64 and list(b.cameras) == ["flight", "centre"]
    p = ScenePreview(b, size=SIZE, ctx=gl)
    try:
        assert isinstance(p.terrain, StreamingTerrain) and p.renderer is None
        img = p.render()
        assert p.stats["near_tiles"] + p.stats["far_tiles"] > 0
    finally:
        p.release()
    r = StreamingRenderer(world, size=SIZE, budget_bytes=8 << 20, ctx=gl)
    try:
        ref = r.render(b.cameras["flight"], wait=True)
    finally:
        r.close()
    assert np.array_equal(img, ref)  # the tiles' own picture
    withr = open_source(world, budget_mb=8, riders=3)
    cam = _near(withr)
    p = ScenePreview(withr, size=SIZE, ctx=gl)
    try:
        assert isinstance(p.renderer, SceneRenderer) and isinstance(p.renderer.terrain, StreamingTerrain)
        img = p.render(cam).astype(int)
        assert p.stats["riders"] == 3 and p.stats["shadow_patches"] > 0
    finally:
        p.release()
    p = ScenePreview(b, size=SIZE, ctx=gl)
    try:
        bare = p.render(cam).astype(int)
    finally:
        p.release()
    d = np.abs(img - bare).max(-1)
    assert (d > 30).sum() >= 50 and np.median(d) == 0  # riders (and shadows) over the same tiles


def test_cli_renders_a_tiled_world_from_any_camera_with_riders(world, gl, tmp_path, capsys):
    from PIL import Image

    from piste.cli import main

    b = open_source(world, riders=2)
    cam = _near(b)
    eye, tgt = (list(map(str, v)) for v in (cam.eye, cam.target))
    a, r = tmp_path / "a.png", tmp_path / "r.png"
    base = ["render", str(world), "--size", *map(str, SIZE), "--budget", "8", "--quiet"]
    assert main(base + ["--out", str(a), "--eye", *eye, "--target", *tgt]) == 0
    assert "1 frame(s) from the camera" in capsys.readouterr().out
    assert main(base + ["--out", str(r), "--eye", *eye, "--target", *tgt, "--riders", "2"]) == 0
    ia, ir = (np.asarray(Image.open(x)).astype(int) for x in (a, r))
    assert (np.abs(ia - ir).max(-1) > 30).sum() >= 30
    assert main(base + ["--out", str(a), "--camera", "centre", "--frames", "2"]) == 0
    assert "2 frame(s) from centre" in capsys.readouterr().out
    assert main(base + ["--list"]) == 0
    assert "flight" in capsys.readouterr().out


def test_objects_on_sources_without_their_own(level, world, gl):
    """``--add-objects N``: the course's objects on an SSX level and a tiled world, stored as a build
    stores them (bundle.objects() reads them back, colours baked) and drawn by the object pass."""
    b = open_source(level, objects=20)
    objs = b.objects()
    assert len(objs.kind) == 20 and set(objs.kinds) == {"tree", "sign", "rock", "rail"}
    assert set(b.vertex_colors()) == set(objs.kinds)
    from piste.terrain.query import height_at

    _, hit, _, _ = height_at(b.net, objs.matrix[:, :2, 3])
    assert hit.all()
    bare = open_source(level)
    imgs = []
    for bb in (bare, b):
        p = ScenePreview(bb, size=SIZE, ctx=gl)
        try:
            imgs.append(p.render().astype(int))
            drawn = p.stats.get("objects_drawn", 0)
        finally:
            p.release()
    assert drawn > 0 and (np.abs(imgs[0] - imgs[1]).max(-1) > 30).sum() >= 50
    w = open_source(world, budget_mb=8, riders=2, objects=30)
    p = ScenePreview(w, size=SIZE, ctx=gl)
    try:
        p.render(_near(w))
        assert p.stats["riders"] == 2 and len(w.objects().kind) == 30
    finally:
        p.release()
    with pytest.raises(ConfigError, match="objects"):
        open_source(level, objects=10**6)


def test_cli_view_takes_the_same_source_flags(level, world, gl, tmp_path, monkeypatch):
    """``piste view`` (no display: one frame off-screen) of a level and a tiled world with riders,
    objects and a camera of one's own, as ``piste render`` takes them."""
    from PIL import Image

    from piste.cli import main

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    cam = _near(open_source(world, riders=2))
    eye, tgt = (list(map(str, v)) for v in (cam.eye, cam.target))
    out = {}
    for name, extra in (("bare", []), ("furnished", ["--riders", "2", "--add-objects", "10"])):
        out[name] = tmp_path / f"{name}.png"
        assert main(["view", str(world), "--size", *map(str, SIZE), "--budget", "8", "--eye", *eye, "--target", *tgt,
                     "--out", str(out[name]), *extra]) == 0
    a, b = (np.asarray(Image.open(out[k])).astype(int) for k in ("bare", "furnished"))
    assert (np.abs(a - b).max(-1) > 30).sum() >= 30
    assert main(["view", str(level), "--size", *map(str, SIZE), "--riders", "1", "--out", str(tmp_path / "l.png")]) == 0
    assert np.asarray(Image.open(tmp_path / "l.png")).std() > 5
