"""The visibility sets skip patches without changing a pixel (what they cull is truly hidden)."""

from __future__ import annotations

import numpy as np

from piste.pipeline.bundle_objects import load_bundle
from piste.pipeline.build import build_scene
from piste.pipeline.preview import ScenePreview
from piste.world.camera import Camera


def test_culled_patches_change_no_pixel(tmp_path, gl):
    n = 65
    y, x = np.mgrid[0:n, 0:n] * 4.0
    z = 40.0 * np.exp(-((y - 128.0) / 14.0) ** 2) + 2.0 * np.sin(x / 20.0) + 0.02 * x - 0.05 * y
    np.savez(tmp_path / "ridge.npz", z=z, dx=np.float64(4.0))
    (tmp_path / "ridge.toml").write_text('[terrain]\nsource = "ridge.npz"\n[lightmap]\nres = 4\n[visibility]\n'
                                         'cell = 32.0\n')
    b = load_bundle(build_scene(tmp_path / "ridge.toml").path)
    with_vis = ScenePreview(b, size=(96, 64), ctx=gl, visibility=True)
    without = ScenePreview(b, size=(96, 64), ctx=gl, visibility=False)
    try:
        saved = 0
        for eye, target in [((128.0, 10.0, 8.0), (128.0, 250.0, 0.0)), ((30.0, 60.0, 5.0), (200.0, 240.0, 10.0)),
                            ((128.0, 250.0, 6.0), (128.0, 0.0, 5.0)), ((200.0, 150.0, 45.0), (60.0, 20.0, 0.0))]:
            cam = Camera(np.array(eye), np.array(target), far=2000.0)
            a = with_vis.render(cam)
            drawn, frustum = with_vis.stats["drawn_patches"], with_vis.stats["frustum_patches"]
            ref = without.render(cam)
            assert np.array_equal(a, ref), f"visibility culling changed the image from {eye}"
            saved += frustum - drawn
        assert saved > 50  # and it did skip patches (those behind the ridge)
    finally:
        with_vis.release()
        without.release()
