"""The renderer's public hooks that the bundle runtime (piste.pipeline.preview) uses instead of
writing into private state: TerrainRenderer.set_visibility, ObjectPass(colors=)/set_vertex_colors."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import RenderError
from piste.render.frame import TerrainRenderer
from piste.world.camera import Camera

from .conftest import make_grid_net


class _OnlyEven:
    """A visibility set keeping the even patches (the Visibility interface: patches_at(eye))."""

    def __init__(self, n):
        self.mask = np.arange(n) % 2 == 0

    def patches_at(self, eye):
        return self.mask


def test_set_visibility_cuts_the_frustum_set(gl):
    net = make_grid_net(4, 4)
    r = TerrainRenderer(net, size=(64, 48), ctx=gl)
    try:
        cam = Camera(np.array([20.0, -30.0, 25.0]), np.array([20.0, 20.0, 0.0]), far=500.0)
        all_ids = r.visible(cam)
        assert r.cull_stats == {"frustum_patches": len(all_ids), "drawn_patches": len(all_ids)}
        r.set_visibility(_OnlyEven(len(net)))
        cut = r.visible(cam)
        assert np.array_equal(cut, all_ids[all_ids % 2 == 0]) and len(cut) < len(all_ids)
        assert r.cull_stats == {"frustum_patches": len(all_ids), "drawn_patches": len(cut)}
        frame = r.render(cam)
        assert frame.patches == len(cut)
        r.set_visibility(None)
        assert np.array_equal(r.visible(cam), all_ids)
    finally:
        r.release()


def test_object_pass_draws_the_given_colours(gl):
    """Baked mode draws the RGBs it is given (a bundle's), not colours of its own."""
    from piste.lighting.lights import default_lights
    from piste.render.context import Offscreen
    from piste.render.object_pass import ObjectPass
    from piste.world.course import default_course, track_centerline
    from piste.world.objects import bake_vertex_colors, place_objects

    net, line, lights = default_course(0), track_centerline(0), default_lights()
    objs = place_objects(net, line, lights, seed=0, n_trees=2, n_signs=1, n_rocks=1, n_rails=1)
    baked = bake_vertex_colors(objs, lights)
    dark = {k: np.zeros_like(c) for k, c in baked.items()}
    target = Offscreen(gl, (64, 48))
    p = ObjectPass(gl, objs, lights, mode="baked", colors=dark)
    i = int(objs.instances(objs.kinds[0])[0])
    c, r = objs.center[i], float(objs.radius[i])
    cam = Camera(c + np.array([0.0, -3.0 * r, 0.5 * r]), c, far=100.0 * r, aspect=64 / 48)

    def draw():
        target.fbo.use()
        gl.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        p.draw(cam.view_projection(), cam.eye, np.array([i]))
        gl.finish()
        return target.read()[..., :3].astype(int)

    try:
        black = draw()
        p.set_vertex_colors(baked)
        lit = draw()
        assert black.max() <= 2 and lit.max() > 40, (black.max(), lit.max())
        k0 = objs.kinds[0]
        with pytest.raises(RenderError, match=repr(k0)):
            p.set_vertex_colors({**baked, k0: baked[k0][:, :1]})
    finally:
        p.release()
        target.release()
