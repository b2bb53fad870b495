"""Light-map seams at folds: two patches whose normals differ by more than 90 degrees along part of
their shared edge.  Normals are averaged only where the patches agree (smoothly: no switch along
the edge), and the baked light is welded along the seam: both tiles hold the same values, so no
jump shows at the seam."""

from __future__ import annotations

import numpy as np


def _fold_net():
    """Patch A flat (z = 0) for x in [-1, 0]; patch B leaves the shared edge x = 0 at an angle
    from 60 degrees (y = 0) to 120 degrees (y = 1, folding back over A)."""
    from piste.terrain import PatchNet

    t = np.linspace(0.0, 1.0, 4)
    a = np.zeros((4, 4, 3))
    for i, x in enumerate(np.linspace(-1.0, 0.0, 4)):
        for j, y in enumerate(t):
            a[i, j] = (x, y, 0.0)
    b = np.zeros((4, 4, 3))
    for j, y in enumerate(t):
        th = np.radians(60.0 + 60.0 * y)
        for i, s in enumerate(t):
            b[i, j] = (s * np.cos(th), y, s * np.sin(th))
    return PatchNet(np.stack([a, b]), name="fold")


def _edge(net, values, res):
    """Values along the shared edge in both patches, in the same order ``(2, res, ...)``."""
    from piste.lighting.lightmap import _side_slots

    slots = _side_slots(res)
    e = int(np.asarray(net.shared_edges)[0])
    out = []
    for k in range(2):
        p, s = net.edge_patches[e, k], net.edge_sides[e, k]
        v = values[p][slots[s]]
        out.append(v[::-1] if net.side_flip[p, s] else v)
    return np.stack(out)


def test_fold_normals_have_no_jump_along_the_edge():
    from piste.lighting.lightmap import sample_points, seam_weight

    net = _fold_net()
    assert len(net.shared_edges) == 1
    res = 16
    _, nrm = sample_points(net, res)
    na, nb = _edge(net, nrm, res)
    own = sample_points(net, res, smooth_seams=False)[1]
    oa, ob = _edge(net, own, res)
    cos = (oa * ob).sum(-1)
    assert cos.max() > 0.4 and cos.min() < -0.4  # the fold passes 90 degrees along the edge
    # where the patches agree within 60 degrees: one normal for both
    agree = cos >= np.cos(np.radians(60.0)) - 1e-9
    assert agree.any() and np.allclose(na[agree], nb[agree])
    # past 90 degrees: each keeps its own
    apart = cos <= 0.0
    assert np.allclose(na[apart], oa[apart]) and np.allclose(nb[apart], ob[apart])
    # and between: no jump from one sample to the next (the old rule switched by ~45 degrees)
    step = np.degrees(np.arccos(np.clip((na[1:] * na[:-1]).sum(-1), -1, 1)))
    assert step.max() < 15.0, step
    assert seam_weight(1.0) == 1.0 and seam_weight(-0.5) == 0.0


def test_baked_light_is_welded_at_the_fold():
    from piste.lighting import bake_lightmap
    from piste.lighting.lights import AmbientLight, DirectionalLight, Lights
    from piste.lighting.lightmap import lightmap_params

    net = _fold_net()
    lights = Lights([AmbientLight((1.0, 1.0, 1.0), 0.2), DirectionalLight((0.3, 0.2, -1.0), (1.0, 1.0, 1.0), 1.0)])
    res = 8
    lm = bake_lightmap(net, lights, res=res, gutter=1, shadows=False, jobs=1)
    from piste.lighting.lightmap import lightmap_uv, sample_atlas

    u, v = lightmap_params(res)
    tiles = np.stack([sample_atlas(lm.atlas, lightmap_uv(lm.rects, np.full(len(u), p), u, v), mode="point")
                      for p in range(2)])  # (2, res*res, 3)
    la, lb = _edge(net, tiles, res)
    assert np.array_equal(la, lb)  # the seam holds one light value on both sides
