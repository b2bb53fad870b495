"""Object levels of detail in the draw: a row of trees from near to far, drawn with LOD (half a pixel
of error, and the default: one pixel) and in full: far fewer triangles, the same picture within a
pixel's worth."""

from __future__ import annotations

import numpy as np
import pytest

from piste.lighting import AmbientLight, DirectionalLight, Lights
from piste.lighting.vertex import choose_lights_many
from piste.world.object_lod import DEFAULT_LOD_PIXELS

LIGHTS = Lights((AmbientLight((0.35, 0.4, 0.5), 0.5),
                 DirectionalLight((-0.35, 0.75, -0.55), (1.0, 0.9, 0.75), 0.8, name="key")))


def _trees(n=40):
    from piste.world.objects import ObjectSet, compress_mesh, make_mesh, normal_matrix, object_texture

    kinds = ("tree", "rock")
    meshes = {k: compress_mesh(make_mesh(k)) for k in kinds}
    d = np.geomspace(6.0, 400.0, n)  # along +y from the camera, zig-zagging sideways
    mats = np.tile(np.eye(4), (n, 1, 1))
    mats[:, 0, 3] = np.where(np.arange(n) % 2, 1.0, -1.0) * 0.25 * d
    mats[:, 1, 3] = d
    kind = np.arange(n) % 2
    centre = mats[:, :3, 3] + np.array([0, 0, 3.0])
    return ObjectSet(meshes, kinds, kind, mats, normal_matrix(mats), centre, np.full(n, 8.0),
                     choose_lights_many(LIGHTS, centre), object_texture())


def _draw(gl, objs, lod_pixels, mode="dynamic"):
    from piste.render.context import Offscreen
    from piste.render.object_pass import ObjectPass
    from piste.world.camera import Camera

    op = ObjectPass(gl, objs, LIGHTS, mode=mode, lod_pixels=lod_pixels)
    target = Offscreen(gl, (320, 224))
    try:
        cam = Camera(eye=(0.0, -2.0, 3.0), target=(0.0, 100.0, 3.0), fov_y=60, aspect=320 / 224, near=0.5, far=1000)
        target.use()
        target.fbo.clear(0.8, 0.86, 0.93, 1.0)
        op.draw(cam.view_projection(), cam.eye)
        return target.read()[..., :3].astype(int), op.triangles, op.lod_counts.copy(), op.drawn
    finally:
        target.release()
        op.release()


@pytest.mark.parametrize("mode", ["dynamic", "baked"])
@pytest.mark.parametrize("lod_pixels", [0.5, DEFAULT_LOD_PIXELS])
def test_lod_keeps_the_picture_with_fewer_triangles(gl, mode, lod_pixels):
    objs = _trees()
    full, t_full, counts_full, n = _draw(gl, objs, 0.0, mode)
    lod, t_lod, counts, n2 = _draw(gl, objs, lod_pixels, mode)
    assert n == n2 == len(objs)
    assert counts_full.tolist()[0] == n and counts_full[1:].sum() == 0
    assert counts.sum() == n and counts[1:].sum() > n // 2  # most of the row is far away
    assert t_lod < 0.6 * t_full
    diff = np.abs(full - lod).max(axis=2)
    assert (diff > 0).any()  # it did draw something else
    assert np.mean(diff > 24) < 0.004, f"{np.mean(diff > 24):.4f} of pixels differ by > 24"
    assert np.abs(full - lod).mean() < 0.5


def test_lod_pixels_zero_is_the_full_mesh(gl):
    objs = _trees(8)
    a, ta, _, _ = _draw(gl, objs, 0.0)
    b, tb, _, _ = _draw(gl, objs, 0.0)
    assert ta == tb == sum(objs.meshes[objs.kinds[k]].n_triangles for k in objs.kind)
    assert np.array_equal(a, b)


def test_default_lod_is_one_pixel_and_coarser_than_half_a_pixel(gl):
    """The default error (1 px: the scene's pictures hold within their reference tolerance) draws
    fewer triangles than half a pixel did, and a pass made without ``lod_pixels`` takes it."""
    from piste.render.object_pass import ObjectPass

    assert DEFAULT_LOD_PIXELS == 1.0
    objs = _trees()
    op = ObjectPass(gl, objs, LIGHTS)
    try:
        assert op.lod_pixels == DEFAULT_LOD_PIXELS
    finally:
        op.release()
    _, t_half, counts_half, _ = _draw(gl, objs, 0.5)
    _, t_one, counts_one, _ = _draw(gl, objs, DEFAULT_LOD_PIXELS)
    assert t_one < t_half
    # every instance at a level at least as coarse: the mean level rises
    lv = np.arange(len(counts_one))
    assert (counts_one * lv).sum() > (counts_half * lv).sum()
