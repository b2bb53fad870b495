"""Fog in units of the scene's size: the default density up to the default course's size, thinner
in proportion for larger scenes (a 1 km-spacing DEM is not uniform haze)."""

from __future__ import annotations

import numpy as np


def test_fog_density_scales_with_the_scene(grid_net):
    from piste.render.frame import DEFAULT_FOG_DENSITY, scene_fog_density
    from piste.world.course import default_course

    small = grid_net(3, 3, size=10.0)
    assert scene_fog_density(small) == DEFAULT_FOG_DENSITY  # small scenes keep the default
    assert abs(scene_fog_density(default_course(0)) - DEFAULT_FOG_DENSITY) < 0.01 * DEFAULT_FOG_DENSITY
    big = grid_net(3, 3, size=10_000.0, relief=300.0)  # 30 km across
    d = scene_fog_density(big)
    diag = np.hypot(30_000.0, 30_000.0)
    # the same share of the view fogged across the scene: density x size constant
    assert abs(d * diag - DEFAULT_FOG_DENSITY * 1077.0) < 1e-6 * diag


def test_big_dem_is_not_uniform_haze(gl, grid_net):
    """Seen from above, a 30 km scene keeps its relief through the fog (the fixed density made
    everything beyond a few km the horizon colour)."""
    from piste.render import TerrainRenderer
    from piste.render.frame import DEFAULT_FOG_DENSITY
    from piste.world.camera import Camera

    big = grid_net(3, 3, size=10_000.0, relief=3000.0)
    r = TerrainRenderer(big, size=(96, 64), ctx=gl)
    try:
        cam = Camera(np.array([15_000.0, -8_000.0, 9_000.0]), np.array([15_000.0, 15_000.0, 0.0]), far=80_000.0,
                     near=10.0)
        scaled = r.render(cam).image[..., :3].astype(float)
        fixed = r.render(cam, fog=DEFAULT_FOG_DENSITY).image[..., :3].astype(float)
        clear = r.render(cam, fog=0).image[..., :3].astype(float)
    finally:
        r.release()
    # the fixed density turns the mountain into the horizon colour; the scaled one keeps it (some haze)
    far_off = np.abs(fixed - clear).mean()
    assert far_off > 5.0
    assert 0.0 < np.abs(scaled - clear).mean() < 0.3 * far_off
