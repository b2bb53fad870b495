"""Cold start: the resident vertex blocks built in the background while the renderer sets up give
the same blocks and the same picture as blocks built on the first frame."""

from __future__ import annotations

import numpy as np

from piste.render import TerrainRenderer
from piste.terrain.resident import ResidentMesh
from piste.world.camera import Camera


def test_start_resident_builds_the_same_blocks_in_the_background(gl, grid_net):
    cam = Camera([4.0, -6.0, 12.0], [22.0, 22.0, 0.0], fov_y=60)
    images, blocks = [], []
    for early in (False, True):
        net = grid_net(4, 4, size=10.0, relief=5.0)  # a fresh net: no blocks kept on it yet
        r = TerrainRenderer(net, size=(96, 64), ctx=gl, lod_near=14.0, lod_far=30.0)
        try:
            if early:
                r.start_resident()
                assert net.__dict__.get("_resident_pending") or net.__dict__.get("_resident")  # under way
            r.resident_wait = True
            images.append(r.render(cam).image)
            assert isinstance(r.mesh, ResidentMesh)
            blocks.append(r.mesh.resident.vertices.copy())
        finally:
            r.release()
    assert np.array_equal(blocks[0], blocks[1])
    assert np.array_equal(images[0], images[1])
