"""No double darkening: a rider's projected shadow darkens only terrain that sees the sun; inside
the terrain's own shadow (already without the sun in its light map) it leaves the pixels alone."""

from __future__ import annotations

import numpy as np


def test_sun_visibility_behind_a_ridge(grid_net):
    from piste.terrain.fit import fit_heightfield
    from piste.render.shadow_pass import sun_visibility

    n = 41
    y, x = np.mgrid[0:n, 0:n] * 5.0
    z = 40.0 * np.exp(-((x - 100.0) / 8.0) ** 2)  # a ridge along y at x = 100 m
    net = fit_heightfield(z, 5.0)
    sun = np.array([1.0, 0.0, -0.5])  # light travelling towards +x, ~27 degrees up
    f, (x0, y0, x1, y1) = sun_visibility(net, sun, spacing=2.5, soften=0)
    col = lambda xm: f[f.shape[0] // 2, int(round((xm - x0) / (x1 - x0) * (f.shape[1] - 1)))]  # noqa: E731
    assert col(60.0) == 1.0 and col(95.0) == 1.0  # facing the sun
    assert col(115.0) == 0.0 and col(150.0) == 0.0  # behind the ridge: its shadow reaches ~80 m
    assert col(195.0) == 1.0  # beyond the shadow


def test_rider_shadow_spares_terrain_in_shadow(gl):
    from piste.render.scene_renderer import SceneRenderer
    from piste.world.scene import Scene

    scene = Scene.default(0, objects=False)
    r = SceneRenderer(scene, size=(160, 112), ctx=gl, lightmap=None, face=None)
    r.terrain.resident_wait = True  # every frame on the same (resident) path: pixel-exact comparisons
    try:
        assert r.shadows.sunlit.size[0] > 10  # the course's own sun visibility is in use
        sh, r.shadows = r.shadows, None
        off = r.render(1.0).image
        r.shadows = sh
        r.shadows.set_sunlight(np.ones((2, 2)), (0.0, 0.0, 1e4, 1e4))  # all sunlit
        lit = r.render(1.0).image
        r.shadows.set_sunlight(np.zeros((2, 2)), (0.0, 0.0, 1e4, 1e4))  # all in the terrain's shadow
        shaded = r.render(1.0).image
    finally:
        r.release()
    assert (np.abs(lit.astype(int) - off.astype(int)).max(-1) > 8).sum() > 10  # the riders' shadows
    assert np.array_equal(shaded, off)  # ... not drawn again over the terrain's own shadow


def test_sun_visibility_blur_matches_scipy_gaussian_filter():
    """The numpy blur (no scipy import at run time) is scipy.ndimage.gaussian_filter's filter."""
    from scipy.ndimage import gaussian_filter

    from piste.render.shadow_pass import _gaussian_blur

    rng = np.random.default_rng(3)
    for shape in [(40, 57), (3, 5), (1, 9)]:
        for sigma in (0.3, 1.0, 2.5):
            f = (rng.random(shape) > 0.5).astype(np.float32)
            out = _gaussian_blur(f, sigma)
            assert out.dtype == np.float32 and out.shape == f.shape
            np.testing.assert_allclose(out, gaussian_filter(f, sigma), atol=1e-6)
