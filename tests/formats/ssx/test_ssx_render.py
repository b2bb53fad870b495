"""Rendering a synthetic 3-patch SSX level with its own textures and light maps (modulate, ps2)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from piste.formats.ssx import gs_blend
from piste.pipeline.ssx_synth import make_level
from piste.pipeline.ssx_level import load_level
from piste.world.camera import Camera

DATA = Path(__file__).parent / "data"
SIZE = (160, 112)


@pytest.fixture(scope="module")
def level(tmp_path_factory):
    d = tmp_path_factory.mktemp("ssx3")
    return load_level(make_level(rows=1, cols=3, seed=2).write(d, "TRI"))


def _camera(level):
    lo, hi = level.net.bounds
    c = (lo + hi) / 2
    return Camera(c + np.array([-4.0, -16.0, 12.0]), c, fov_y=50.0, near=0.5, far=500.0)


def _preview(level, gl, mode):
    """The one runtime on the level (what ``piste ssx render|view`` and ``piste render|view`` draw
    with): a :class:`ScenePreview` whose terrain is the level's :class:`SsxTerrainRenderer`."""
    from piste.pipeline.preview import ScenePreview
    from piste.pipeline.ssx_source import level_bundle
    from piste.render.ssx_pass import SsxTerrainRenderer

    p = ScenePreview(level_bundle(level), size=SIZE, ctx=gl, lightmap_mode=mode if mode in ("modulate", "ps2") else None)
    assert isinstance(p.terrain, SsxTerrainRenderer) and p.renderer is None
    return p


def _frame(p, camera, mode):
    """One ``(H, W, 4) uint8`` frame: "modulate" / "ps2" as the runtime draws them (alpha 255),
    "base" (the base textures alone, transparent background) or "source" (the stored Cs/As texels
    unblended, background alpha 0) from the runtime's terrain renderer."""
    from dataclasses import replace

    if mode == "source":
        return p.terrain.source_frame(replace(camera, aspect=SIZE[0] / SIZE[1]))
    if mode == "base":
        cam = replace(camera, aspect=SIZE[0] / SIZE[1])
        return p.terrain.render(cam, debug="base", sky=False, clear=(0.0, 0.0, 0.0, 0.0)).image.copy()
    img = p.render(camera)
    return np.concatenate([img, np.full(img.shape[:2] + (1,), 255, np.uint8)], axis=-1)


def _render(level, gl, mode):
    p = _preview(level, gl, mode)
    try:
        return _frame(p, _camera(level), mode)
    finally:
        p.release()


def test_level_prepared_for_rendering(level):
    assert level.info["patches"] == 3 and level.info["textures"] == 3 and level.info["lightmap_pages"] == 1
    assert level.light.dtype == np.float32 and level.light.max() > 1.0  # the synthetic sun is over-bright
    assert level.source.shape[2] == 4 and level.source[..., 3].max() > 128
    # patch k uses texture k: its corner UVs lie in that texture's atlas cell
    from piste.pipeline.ssx_level import texture_atlas

    _, origins, (w, h) = texture_atlas(level.textures)
    for k in range(3):
        x0, y0 = origins[k] / (w, h)
        assert (level.net.uv[k, :, 0] >= x0).all() and (level.net.uv[k, :, 0] <= x0 + 64 / w).all()
        assert (level.net.uv[k, :, 1] >= y0).all() and (level.net.uv[k, :, 1] <= y0 + 64 / h).all()


def test_ps2_mode_blends_stored_cs_as_like_the_gs(level, gl):
    base = _render(level, gl, "base")
    source = _render(level, gl, "source")
    ps2 = _render(level, gl, "ps2")
    mask = (base[..., 3] == 255) & (source[..., 3] > 0)
    assert mask.mean() > 0.3
    want = gs_blend(base[..., :3][mask], source[..., :3][mask], source[..., 3][mask]).astype(int)
    got = ps2[..., :3][mask].astype(int)
    err = np.abs(got - want)
    assert np.percentile(err, 99) <= 3 and err.mean() < 1.0
    # and the light map does something: ps2 differs from the base texture
    assert np.abs(got - base[..., :3][mask].astype(int)).mean() > 5


def test_modulate_and_ps2_agree(level, gl):
    mod = _render(level, gl, "modulate")[..., :3].astype(int)
    ps2 = _render(level, gl, "ps2")[..., :3].astype(int)
    assert np.abs(mod - ps2).mean() < 3.0


@pytest.mark.parametrize("mode", ["modulate", "ps2"])
def test_reference_image(level, gl, mode):
    from PIL import Image

    img = _render(level, gl, mode)[..., :3]
    ref_path = DATA / f"tri_{mode}.png"
    if os.environ.get("PISTE_UPDATE_GOLDEN"):
        Image.fromarray(img).save(ref_path)
    ref = np.asarray(Image.open(ref_path).convert("RGB")).astype(int)
    diff = np.abs(img.astype(int) - ref)
    assert diff.mean() < 1.5 and np.percentile(diff, 99) < 12, (diff.mean(), np.percentile(diff, 99))


def test_light_map_bank_with_the_games_short_name(tmp_path):
    from piste.pipeline.ssx_level import level_files

    make_level(rows=1, cols=1).write(tmp_path, "elysium")
    (tmp_path / "elysium_L.ssh").rename(tmp_path / "elysiu_L.ssh")
    ssh, lssh = level_files(tmp_path / "elysium.pbd")
    assert ssh.name == "elysium.ssh" and lssh.name == "elysiu_L.ssh"


def _sky_camera(level):
    """Looking straight up from above the level: no patch in view."""
    lo, hi = level.net.bounds
    c = (lo + hi) / 2
    return Camera(c + np.array([0.0, 0.0, 50.0]), c + np.array([0.0, 1.0, 400.0]), fov_y=50.0, near=0.5, far=500.0)


@pytest.mark.parametrize("mode", ["modulate", "ps2", "source", "base"])
def test_nothing_in_view_draws_the_sky(level, gl, mode):
    """Issue 22: a view of only sky (an empty draw) in every light-map mode draws the sky, no GL error."""
    p = _preview(level, gl, mode)
    try:
        img = _frame(p, _sky_camera(level), mode)
        seen = _frame(p, _camera(level), mode)  # and it still draws after
    finally:
        p.release()
    assert img.shape == (SIZE[1], SIZE[0], 4)
    if mode in ("modulate", "ps2"):
        rgb = img[..., :3].astype(int)
        assert (rgb[..., 2] > rgb[..., 0]).mean() > 0.99  # blue sky everywhere
        assert not np.array_equal(seen[..., :3], img[..., :3])
    else:
        assert (img[..., 3] == 0).all()  # transparent background, nothing drawn


def test_window_view_pressing_m_at_the_sky(level, gl):
    """`piste ssx view` / `piste view LEVEL.pbd`: the window's view (the runtime's PreviewView) draws
    the sky in both modes (M toggles) without a crash."""
    from piste.pipeline.live import PreviewView
    from piste.render.window import ViewOptions

    view = PreviewView(_preview(level, gl, "modulate"))
    try:
        for mode in ("modulate", "ps2", "modulate", "ps2"):
            frame = view.draw(_sky_camera(level), 0.0, ViewOptions(lightmap_mode=mode))
            assert frame.terrain is not None
    finally:
        view.release()


def test_window_view_ps2_is_the_runtimes_ps2_picture(level, gl):
    """In the window, an SSX level's ps2 mode blends the level's stored texels as the runtime's render
    does (it drew the general terrain's ps2 blend of piste's own light map before: up to 5 levels off)."""
    from piste.pipeline.live import PreviewView
    from piste.render.window import ViewOptions

    cam = _camera(level)
    want = _frame(_preview(level, gl, "ps2"), cam, "ps2")[..., :3].astype(int)
    view = PreviewView(_preview(level, gl, "ps2"))
    try:
        view.draw(cam, 0.0, ViewOptions(lightmap_mode="ps2"))
        got = view.preview.terrain.target.read()[..., :3].astype(int)
    finally:
        view.release()
    assert got.shape == want.shape
    assert np.abs(got - want).max() == 0
