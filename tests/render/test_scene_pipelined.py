"""Pipelined frames (SceneRenderer.frames): the same pictures and counts as one render() a frame,
with the next frame's CPU side planned while the GL draws; and the sky's per-vertex view ray."""

from __future__ import annotations

import numpy as np
import pytest


def test_frames_match_render(gl):
    from piste.render.scene_renderer import SceneRenderer
    from piste.world.scene import Scene

    r = SceneRenderer(Scene.default(0), size=(160, 112), ctx=gl)
    r.terrain.resident_wait = True  # every frame on the resident path (not the CPU one until it is built)
    try:
        times = [0.0, 0.4, 0.8, 1.2]
        one = [r.render(t) for t in times]
        piped = list(r.frames(times))
        assert len(piped) == len(times)
        for a, b in zip(one, piped):
            # (byte-identical, also while numba loads in the background: the numpy twins give the
            # compiled kernels' bits, see test_first_frames_while_numba_loads_are_the_later_frames)
            assert np.array_equal(a.image, b.image)
            assert a.stats == b.stats
            assert b.timings["cpu"] > 0 and b.timings["total"] > 0
        # consecutive frames differ (the riders move): the generator did not repeat one frame
        assert np.abs(piped[0].image.astype(int) - piped[-1].image.astype(int)).max() > 16
        # explicit cameras, one per time; a wrong count is a clear error
        cams = [im.scene.camera for im in one]
        again = list(r.frames(times[:2], cameras=cams[2:]))
        for t, cam, im in zip(times[:2], cams[2:], again):
            assert np.array_equal(im.image, r.render(t, camera=cam).image)
        from piste.errors import ConfigError

        with pytest.raises(ConfigError, match="cameras"):
            list(r.frames(times, cameras=cams[:2]))
        assert list(r.frames([])) == []
    finally:
        r.release()


def test_frames_alternating_cameras_match_render(gl):
    """Pipelined frames cannot be mixed up: two very different views alternate (the chase camera and
    one high above the course looking down), and every pipelined picture, its counts and its camera
    are those :meth:`SceneRenderer.render` gives for its own time and camera.  A frame issued, read
    back or planned with its neighbour's camera, target, shadows or terrain fails here (consecutive
    pictures differ in most pixels)."""
    from piste.render.scene_renderer import SceneRenderer
    from piste.world.camera import Camera
    from piste.world.scene import Scene

    scene = Scene.default(0)
    r = SceneRenderer(scene, size=(160, 112), ctx=gl)
    r.terrain.resident_wait = True
    try:
        lo, hi = scene.net.bounds
        mid = (np.asarray(lo, float) + np.asarray(hi, float)) / 2.0
        above = Camera(eye=mid + np.array([0.0, -40.0, 0.6 * float(hi[2] - lo[2]) + 250.0]), target=mid, far=8000.0)
        times = [0.0, 0.1, 0.2, 0.3, 0.4, 0.5]
        cams = [None if i % 2 == 0 else above for i in range(len(times))]
        piped = list(r.frames(times, cameras=cams))
        one = [r.render(t, camera=c) for t, c in zip(times, cams)]
        for a, b in zip(one, piped):
            assert np.array_equal(a.image, b.image)
            assert a.stats == b.stats
            np.testing.assert_allclose(b.scene.camera.eye, a.scene.camera.eye)
        # the two views really differ: a frame shown for its neighbour would fail above
        for a, b in zip(piped, piped[1:]):
            assert np.mean(np.abs(a.image.astype(int) - b.image.astype(int)).max(axis=-1) > 16) > 0.2
    finally:
        r.release()



def test_first_frames_while_numba_loads_are_the_later_frames(gl, monkeypatch):
    """A fresh process draws its first frames with the numpy twins of the compiled kernels (numba
    loads in a background thread, :mod:`piste._jit`) and switches to the kernels at a moment set by
    the warm-up's timing.  The pictures must not change there: the same frames with every kernel
    "not ready yet" and with every kernel loaded are byte-identical.  (Issue 23: the riders'
    numpy skinning summed in another order, so a fresh process's first ``frames()`` / ``render()``
    / ``piste render --frames N`` pictures differed from later ones by up to 145 grey levels on
    ~60 rider pixels, and from run to run.)"""
    from piste import _jit
    from piste.render.scene_renderer import SceneRenderer
    from piste.world.scene import Scene

    _jit.warm_up()
    r = SceneRenderer(Scene.default(0), size=(640, 448), ctx=gl)
    r.terrain.resident_wait = True
    try:
        times = [0.0, 0.1, 0.2, 0.367]
        loaded = [im.image for im in r.frames(times)]
        monkeypatch.setattr(_jit._Lazy, "ready", lambda self: False)  # every dispatcher: its numpy twin
        loading = [im.image for im in r.frames(times)]
        one = [r.render(t).image for t in times]
        for a, b, c in zip(loaded, loading, one):
            assert np.array_equal(a, b) and np.array_equal(b, c)
    finally:
        r.release()

@pytest.mark.parametrize("look", ["ahead", "sun", "down"])
def test_sky_matches_the_per_pixel_ray(gl, look):
    """The sky pass (ray per vertex, interpolated) against the formula evaluated per pixel in numpy:
    looking ahead, into the sun (the glow, computed by squaring and only near the sun) and down
    (below the horizon)."""
    from piste.render.context import Offscreen
    from piste.render.sky_pass import HORIZON, ZENITH, SkyPass
    from piste.render.textures import SUN_DIRECTION
    from piste.world.camera import Camera

    w, h = 96, 64
    sun_dir = np.asarray(SUN_DIRECTION, float) / np.linalg.norm(SUN_DIRECTION)
    target = {"ahead": (30, 40, 14), "sun": tuple(np.array([0, 0, 10]) + 50 * sun_dir),
              "down": (30, 40, -20)}[look]
    cam = Camera(eye=(0, 0, 10), target=target, fov_y=60, aspect=w / h, near=0.5, far=1000)
    vp = cam.view_projection()
    sky = SkyPass(gl)
    t = Offscreen(gl, (w, h))
    try:
        t.use()
        t.fbo.clear(0, 0, 0, 1, depth=1.0)
        sky.draw(vp)
        img = t.read()[..., :3].astype(float) / 255.0
    finally:
        t.release()
        sky.release()
    inv = np.linalg.inv(vp)
    ys, xs = np.mgrid[0:h, 0:w]
    ndc = np.stack([(xs + 0.5) / w * 2 - 1, 1 - (ys + 0.5) / h * 2], -1)  # image rows top first
    a = np.concatenate([ndc, -np.ones((h, w, 1)), np.ones((h, w, 1))], -1) @ inv.T
    b = np.concatenate([ndc, np.ones((h, w, 1)), np.ones((h, w, 1))], -1) @ inv.T
    d = b[..., :3] / b[..., 3:] - a[..., :3] / a[..., 3:]
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    hz = np.clip(d[..., 2:], 0, 1)
    c = np.array(HORIZON) + (np.array(ZENITH) - HORIZON) * (1 - np.exp(-2.2 * hz))
    c = c + (np.array(HORIZON) * 0.9 - c) * (1 - np.exp(np.minimum(d[..., 2:], 0) * 3))
    sun = np.asarray(SUN_DIRECTION, float) / np.linalg.norm(SUN_DIRECTION)
    s = np.maximum(d @ sun, 0)[..., None]
    c = np.minimum(c + np.array([1.0, 0.95, 0.85]) * (0.25 * s ** 24 + 0.6 * s ** 900), 1.0)
    assert np.abs(img - c).max() < 2.5 / 255
    if look == "sun":  # the glow is in the picture (the test covers it)
        assert s.max() > 0.999 and img[..., 2].max() == 1.0 and np.ptp(img[..., 1]) > 0.1
