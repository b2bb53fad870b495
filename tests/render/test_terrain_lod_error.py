"""TerrainRenderer's ``lod_error``: the on-screen error (pixels of a 448-line frame) under which an
edge is drawn flat or at its coarsest level; 1 px by default (the objects' LOD bound)."""

from __future__ import annotations

import numpy as np
import pytest


def test_lod_error_sets_the_flat_error_angle(gl, grid_net):
    from piste.render.frame import FLAT_ERROR_PX, LOD_ERROR_PX, TerrainRenderer
    from piste.terrain.lod import FLAT_ERROR

    net = grid_net(3, 3)
    r = TerrainRenderer(net, size=(32, 24), ctx=gl, lightmap=None)
    try:
        assert LOD_ERROR_PX == 1.0
        assert r.lod_kwargs["flat_error"] == pytest.approx(FLAT_ERROR * LOD_ERROR_PX / FLAT_ERROR_PX)
    finally:
        r.release()
    r = TerrainRenderer(net, size=(32, 24), ctx=gl, lightmap=None, lod_error=None)
    try:
        assert r.lod_kwargs["flat_error"] is None  # levels by distance alone
    finally:
        r.release()


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf")])
def test_lod_error_must_be_a_positive_number(gl, grid_net, bad):
    from piste.errors import ConfigError
    from piste.render.frame import TerrainRenderer

    with pytest.raises(ConfigError, match="lod_error"):
        TerrainRenderer(grid_net(2, 2), size=(16, 16), ctx=gl, lightmap=None, lod_error=bad)


def test_a_larger_error_draws_fewer_triangles_where_the_levels_allow(gl, grid_net):
    from piste.render.frame import TerrainRenderer
    from piste.world.camera import Camera

    net = grid_net(6, 6, size=10.0, relief=1.0)
    cam = Camera(eye=(30.0, -40.0, 25.0), target=(30.0, 40.0, 0.0), near=0.5, far=500.0)
    tris = {}
    for err in (None, 0.5, 1.0, 50.0):
        r = TerrainRenderer(net, size=(160, 112), ctx=gl, lightmap=None, lod_error=err)
        try:
            tris[err] = r.render(cam, fog=None, sky=False, read=False).triangles
        finally:
            r.release()
    assert tris[None] >= tris[0.5] >= tris[1.0] >= tris[50.0]
    assert tris[50.0] < tris[None]  # an error that large takes every edge it can flat
    assert tris[50.0] == 2 * len(net)  # every patch down to its two corner triangles
