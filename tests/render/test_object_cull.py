"""Back faces culled for the objects whose meshes bound closed solids (closed_outward): the same
pixels as drawing every triangle, never for open or inward-wound meshes, nor for a run of
instances with a mirroring matrix (their winding flips on screen)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from piste.render.context import Offscreen
from piste.render.object_pass import ObjectPass, closed_outward
from piste.world.camera import Camera
from piste.world.course import default_course, track_centerline
from piste.world.objects import _icosphere, normal_matrix, place_objects
from piste.world.scene import default_lights


def test_closed_outward():
    v, f = _icosphere(1)
    f = np.asarray(f, np.int64)
    assert closed_outward(v, f)
    assert not closed_outward(v, f[:, ::-1])  # wound inwards: negative volume
    assert not closed_outward(v, f[1:])  # a hole: edges without their twins
    assert not closed_outward(v, np.concatenate([f, f[:1]]))  # a triangle twice: an edge used twice
    assert not closed_outward(v, np.zeros((0, 3), np.int64))


@pytest.fixture(scope="module")
def rocks():
    net = default_course()
    return place_objects(net, track_centerline(), default_lights(), seed=0, n_trees=20, n_signs=4, n_rocks=30,
                         n_rails=2)


def _draw(gl, objs, cull):
    line = track_centerline()
    eye = line[len(line) // 3] + [0.0, 0.0, 25.0]
    cam = Camera(eye, line[len(line) // 2], fov_y=60, aspect=160 / 112)
    op = ObjectPass(gl, objs, default_lights())
    target = Offscreen(gl, (160, 112))
    try:
        op.cull_closed = cull
        target.use()
        target.clear((0, 0, 0, 1))
        op.draw(cam.view_projection(), cam.eye)
        return target.read()[..., :3].astype(int), op
    finally:
        op.release()
        target.release()


def test_closed_kinds_culled_with_the_same_pixels(gl, rocks):
    culled, op = _draw(gl, rocks, True)
    closed = {name: info["closed"] for name, info in zip(rocks.kinds, op.kinds)}
    assert all(closed["rock"])  # the rocks are closed solids, wound outwards, at every level
    assert not any(closed["tree"])  # the trees are open (their cones' rims)
    whole, _ = _draw(gl, rocks, False)
    assert (whole.max(-1) > 0).sum() > 100  # objects on screen
    assert np.array_equal(culled, whole)


def test_mirrored_instances_are_not_culled(gl, rocks):
    flip = np.diag([-1.0, 1.0, 1.0, 1.0])
    m = rocks.matrix @ flip  # every instance mirrored in its own x: the same solids, wound the other way
    mirrored = dataclasses.replace(rocks, matrix=m, normal_matrix=normal_matrix(m))
    culled, op = _draw(gl, mirrored, True)
    assert op.mirrored.all()
    whole, _ = _draw(gl, mirrored, False)
    assert (whole.max(-1) > 0).sum() > 100
    assert np.array_equal(culled, whole)  # (culled as wound, the rocks' front faces would go)
