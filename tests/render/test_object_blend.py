"""glTF alphaMode BLEND objects: drawn after the opaque ones with real alpha blending (depth test
on, depth write off), their instances sorted back to front each frame."""

from __future__ import annotations

import numpy as np
import pytest

from piste.render.context import Offscreen
from piste.render.object_pass import ObjectPass
from piste.world.camera import Camera
from piste.world.objects import ObjectMesh, ObjectSet, compress_mesh, normal_matrix

# atlas regions (4 x 4 texels each): the colour of each kind, alpha 128 for the transparent ones
COLORS = {"wall": (100, 100, 100, 255), "red": (255, 0, 0, 128), "blue": (0, 0, 255, 128)}
SIZE = (48, 48)


def _quad(name, region, n_regions):
    u = (4 * region + 2) / (4 * n_regions)
    pos = [(-1, 0, -1), (1, 0, -1), (1, 0, 1), (-1, 0, 1)]
    return ObjectMesh(name, pos, [(0, -1, 0)] * 4, [(u, 0.5)] * 4, [(0, 1, 2), (0, 2, 3)])


def _objects(placed, kinds=("wall", "red", "blue"), blend=("red", "blue")):
    """``placed``: [(kind, y, scale)] quads facing -y at depth ``y``."""
    atlas = np.concatenate([np.tile(np.array(COLORS[k], np.uint8), (4, 4, 1)) for k in kinds], axis=1)
    meshes = {k: compress_mesh(_quad(k, i, len(kinds))) for i, k in enumerate(kinds)}
    kind = np.array([kinds.index(k) for k, _, _ in placed], dtype=np.int64)
    matrix = np.zeros((len(placed), 4, 4))
    for i, (_, y, s) in enumerate(placed):
        matrix[i] = np.diag([s, s, s, 1.0])
        matrix[i, 1, 3] = y
    center = matrix[:, :3, 3].copy()
    return ObjectSet(meshes, tuple(kinds), kind, matrix, normal_matrix(matrix), center,
                     np.full(len(placed), 1.5), None, atlas,
                     {k: int(np.count_nonzero(kind == i)) for i, k in enumerate(kinds)}, tuple(blend))


def _draw(gl, objs, specialised=True, depth=False):
    cam = Camera(np.array([0.0, -10.0, 0.0]), np.array([0.0, 0.0, 0.0]), fov_y=60, aspect=1.0)
    op = ObjectPass(gl, objs, None, mode="baked",
                    colors={k: np.full((objs.counts[k], 4, 3), 128, np.uint8) for k in objs.kinds})
    op.specialised = specialised
    target = Offscreen(gl, SIZE)
    try:
        target.use()
        target.clear((0, 0, 0, 1))
        op.draw(cam.view_projection(), cam.eye)
        assert op.drawn == len(objs)
        if depth:
            return np.frombuffer(target.fbo.read(components=1, attachment=-1, dtype="f4"), np.float32).reshape(SIZE[1], SIZE[0])
        return target.read()[..., :3].astype(float)
    finally:
        op.release()
        target.release()


def _over(src, dst, a=128 / 255):
    return a * np.asarray(src, float) + (1 - a) * np.asarray(dst, float)


@pytest.mark.parametrize("specialised", [True, False])
def test_half_transparent_quad_blends_with_what_is_behind(gl, specialised):
    img = _draw(gl, _objects([("wall", 2.0, 8.0), ("red", -2.0, 1.0)]), specialised)
    c = SIZE[0] // 2
    np.testing.assert_allclose(img[c, c], _over((255, 0, 0), (100, 100, 100)), atol=3)
    np.testing.assert_allclose(img[2, 2], (100, 100, 100), atol=2)  # the wall alone at the corner


@pytest.mark.parametrize("specialised", [True, False])
def test_overlapping_transparent_objects_composite_back_to_front_in_any_scene_order(gl, specialised):
    near_blue = _over((0, 0, 255), _over((255, 0, 0), (100, 100, 100)))
    c = SIZE[0] // 2
    placed = [("wall", 2.0, 8.0), ("red", -1.0, 1.0), ("blue", -3.0, 1.0)]
    for order in (placed, placed[::-1], [placed[2], placed[0], placed[1]]):
        for kinds in (("wall", "red", "blue"), ("blue", "red", "wall")):
            img = _draw(gl, _objects(order, kinds), specialised)
            np.testing.assert_allclose(img[c, c], near_blue, atol=3)
    # swapped depths: red in front now
    img = _draw(gl, _objects([("wall", 2.0, 8.0), ("red", -3.0, 1.0), ("blue", -1.0, 1.0)]), specialised)
    np.testing.assert_allclose(img[c, c], _over((255, 0, 0), _over((0, 0, 255), (100, 100, 100))), atol=3)


def test_transparent_object_behind_an_opaque_one_is_hidden_and_does_not_hide(gl):
    # red behind the wall: depth-tested away; a wall drawn later in the scene order still shows
    img = _draw(gl, _objects([("red", 4.0, 1.0), ("wall", 2.0, 8.0)]))
    c = SIZE[0] // 2
    np.testing.assert_allclose(img[c, c], (100, 100, 100), atol=2)


def test_same_kind_instances_sorted_too(gl):
    # two red quads of one kind overlapping a blue one between them: three runs (red, blue, red)
    placed = [("red", -1.0, 1.0), ("red", -5.0, 0.5), ("blue", -3.0, 1.0), ("wall", 2.0, 8.0)]
    img = _draw(gl, _objects(placed))
    c = SIZE[0] // 2
    want = _over((255, 0, 0), _over((0, 0, 255), _over((255, 0, 0), (100, 100, 100))))
    np.testing.assert_allclose(img[c, c], want, atol=3)


def test_transparent_objects_do_not_write_depth(gl):
    c = SIZE[0] // 2
    wall = _draw(gl, _objects([("wall", 2.0, 8.0)]), depth=True)
    both = _draw(gl, _objects([("wall", 2.0, 8.0), ("red", -2.0, 1.0)]), depth=True)
    opaque_red = _draw(gl, _objects([("wall", 2.0, 8.0), ("red", -2.0, 1.0)], blend=()), depth=True)
    assert both[c, c] == pytest.approx(wall[c, c], abs=1e-6)
    assert opaque_red[c, c] < wall[c, c] - 1e-3  # (the same quad drawn opaque writes its nearer depth)
