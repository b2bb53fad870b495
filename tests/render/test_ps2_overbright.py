"""``--lightmap ps2`` equals ``modulate`` on the default course, over-bright light included: the
ps2 frame is drawn into a half-float target, so ``As`` up to 2.0 survives the reverse-subtract
blend (on an 8-bit target it clamps at 1 and a fifth of the pixels were off by > 16 levels)."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def course():
    from piste.render.textures import placeholder_lightmap
    from piste.world.course import default_course, track_centerline

    net = default_course(0)
    line = track_centerline(0)
    # the placeholder light map made over-bright (up to ~1.9: a baked map with bounce and a strong sun)
    base = placeholder_lightmap(net).astype(np.float32)
    base = base[..., :3] / 255.0 if base.dtype == np.uint8 or base.max() > 4 else base[..., :3]
    atlas = np.clip(base * 1.9, 0.0, 1.98).astype(np.float32)
    assert atlas.max() > 1.5
    return net, line, atlas


def _diff(a, b):
    return np.abs(a[..., :3].astype(np.int16) - b[..., :3].astype(np.int16)).max(-1)


def test_ps2_equals_modulate_over_bright(gl, course):
    from piste.render import TerrainRenderer
    from piste.world.camera import track_camera
    from piste.world.course import TRACK_HALF_WIDTH

    net, line, atlas = course
    r = TerrainRenderer(net, size=(160, 112), ctx=gl, lightmap=atlas, track=line, track_half_width=TRACK_HALF_WIDTH)
    r.resident_wait = True  # both modes on the same (resident) path
    try:
        for f in (0.15, 0.5, 0.85):
            cam = track_camera(line, f)
            a = r.render(cam, lightmap_mode="modulate").image
            b = r.render(cam, lightmap_mode="ps2").image
            d = _diff(a, b)
            assert (d > 16).sum() == 0, f
            assert (d > 2).mean() < 1e-3, (f, (d > 2).mean(), d.max())
            # and over-bright light really is on screen: brighter than the base texture alone
            base = r.render(cam, debug="base", fog=0).image
            assert (a[..., :3].astype(int) > base[..., :3].astype(int) + 20).any()
    finally:
        r.release()


def test_ps2_scene_resolves_into_the_target(gl, course):
    """The completed scene in ps2 mode: riders and objects drawn into the half-float frame too,
    then resolved; equal to modulate away from nothing but the terrain's light."""
    from piste.render.scene_renderer import SceneRenderer
    from piste.world.scene import Scene

    net, line, atlas = course
    scene = Scene.default(0, objects=False)
    r = SceneRenderer(scene, size=(160, 112), ctx=gl, lightmap=atlas)
    r.terrain.resident_wait = True
    try:
        a = r.render(0.5, lightmap_mode="modulate", count_rider_pixels=True)
        b = r.render(0.5, lightmap_mode="ps2", count_rider_pixels=True)
    finally:
        r.release()
    assert b.stats["rider_pixels"] == a.stats["rider_pixels"] > 0
    d = _diff(a.image, b.image)
    assert (d > 16).sum() == 0 and (d > 2).mean() < 1e-3
