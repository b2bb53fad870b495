"""Degenerate geometry (issue 10 item 3): a patch collapsed to a point (zero area) is handled:
finite positions and normals when tessellated, finite light when baked; never a numpy error."""

from __future__ import annotations

import numpy as np

from piste.lighting import bake_lightmap, default_lights
from piste.terrain import PatchNet, tessellate


def _net_with_a_point_patch():
    g = np.stack(np.meshgrid(np.arange(4.0), np.arange(4.0), indexing="ij"), -1)
    cp = np.zeros((2, 4, 4, 3))
    cp[0, ..., :2] = g
    cp[1, ..., :2] = g + [3.0, 0.0]
    cp[1] = cp[1][0, 0]  # every control point of patch 1 at one place
    return PatchNet(cp)


def test_zero_area_patch_tessellates_and_bakes_finite():
    net = _net_with_a_point_patch()
    for cache in (True, False):
        m = tessellate(net, 6, cache=cache)
        assert np.isfinite(m.positions).all() and np.isfinite(m.normals).all()
    lm = bake_lightmap(net, default_lights(), res=4)
    assert np.isfinite(lm.atlas).all()
