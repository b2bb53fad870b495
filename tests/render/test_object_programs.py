"""The objects' per-mode programs (constants instead of run-time uniforms, instance data as
per-instance attributes, the alpha test compiled out for an opaque atlas) draw the pictures of the
one generic program they replaced."""

from __future__ import annotations

import numpy as np
import pytest

from piste.lighting import PointLight
from piste.render.context import Offscreen
from piste.render.object_pass import ObjectPass
from piste.world.camera import Camera
from piste.world.course import default_course, track_centerline
from piste.world.objects import place_objects
from piste.world.scene import default_lights


@pytest.fixture(scope="module")
def course_objects():
    net = default_course()
    lights = default_lights() + _lamp(net)
    return place_objects(net, track_centerline(), lights, seed=0, n_trees=40, n_signs=6), lights


def _lamp(net):
    from piste.lighting import Lights

    lo, hi = net.bounds
    return Lights((PointLight(tuple((lo + hi) / 2 + [0, 0, 20]), (1.0, 0.8, 0.6), 0.8, range=200.0),))


@pytest.mark.parametrize("mode", ["dynamic", "baked", "points"])
@pytest.mark.parametrize("light_only", [False, True])
def test_specialised_programs_draw_the_generic_programs_picture(gl, course_objects, mode, light_only):
    objs, lights = course_objects
    line = track_centerline()
    eye = line[len(line) // 3] + [0.0, 0.0, 25.0]
    cam = Camera(eye, line[len(line) // 2], fov_y=60, aspect=160 / 112)
    op = ObjectPass(gl, objs, lights, mode=mode)
    target = Offscreen(gl, (160, 112))
    images = {}
    try:
        for spec in (True, False):
            op.specialised = spec
            target.use()
            target.clear((0, 0, 0, 1))
            op.draw(cam.view_projection(), cam.eye, fog=(0.7, 0.8, 0.9, 0.002), light_only=light_only)
            images[spec] = target.read()
            assert op.drawn == len(objs)
    finally:
        op.release()
        target.release()
    assert (images[False][..., :3].max(-1) > 0).sum() > 100  # objects on screen
    diff = np.abs(images[True].astype(int) - images[False].astype(int))
    assert diff.max() <= 2 and (diff > 0).mean() < 0.01


def test_alpha_test_compiled_only_for_atlases_with_cut_out_texels(gl, course_objects):
    objs, lights = course_objects
    assert not ObjectPass(gl, objs, lights).alpha_test or (objs.texture[..., 3] < 128).any()
    tex = objs.texture.copy()
    tex[0, 0, 3] = 0
    cut = ObjectPass(gl, type(objs)(**{**objs.__dict__, "texture": tex}), lights)
    try:
        assert cut.alpha_test
    finally:
        cut.release()
