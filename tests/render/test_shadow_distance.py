"""A distant rider's projected shadow stays one soft shape (a mip-mapped shadow texture), where
point samples of its thin limbs and board broke it into dashes."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage


@pytest.fixture(scope="module")
def one_rider():
    from piste.world.riders import DEFAULT_PACK
    from piste.world.scene import Scene

    return Scene.default(0, objects=False, pack=DEFAULT_PACK[:1])


def _shadow_pieces(r, scene, t, dist):
    from piste.world.camera import Camera

    st = scene.riders.state(t)
    a = st.anchor[0]
    f = np.append(st.track_dir[0], 0.0)
    cam = Camera(a - f * dist + np.array([0.0, 0.0, dist * 0.5]), a, fov_y=60.0, near=0.5, far=4000.0)
    on = r.render(t, camera=cam).image[..., :3].astype(int)
    sh, r.shadows = r.shadows, None
    off = r.render(t, camera=cam).image[..., :3].astype(int)
    r.shadows = sh
    mask = (off - on).max(-1) > 4
    _, n = ndimage.label(mask, structure=np.ones((3, 3)))
    return int(mask.sum()), n


def test_distant_shadow_is_not_dashed(gl, one_rider):
    from piste.render.scene_renderer import SceneRenderer

    r = SceneRenderer(one_rider, size=(320, 224), ctx=gl, lightmap=None, face=None)
    r.terrain.resident_wait = True
    try:
        assert r.shadows.mip_levels >= 3
        for t in (1.0, 2.0):
            px, pieces = _shadow_pieces(r, one_rider, t, 30.0)
            assert px >= 8 and pieces <= 2, (t, px, pieces)
        # without the mip levels the same shadow falls apart (what this guards against)
        r.shadows.mip_levels = 0
        broken = [_shadow_pieces(r, one_rider, t, 30.0) for t in (1.0, 2.0)]
        assert max(n for _, n in broken) >= 3, broken
    finally:
        r.release()
