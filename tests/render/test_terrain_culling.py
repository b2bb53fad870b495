"""Back-face culling of the terrain: from above the surface the picture is the unculled one (up to
silhouette pixels); from below, the culled terrain is not drawn at all (so the culling is real)."""

from __future__ import annotations

import numpy as np

from piste.render import TerrainRenderer
from piste.world.camera import Camera


def _pair(gl, net, cam, **render_kw):
    r = TerrainRenderer(net, size=(128, 96), ctx=gl, lod_near=14.0, lod_far=30.0)
    r.resident_wait = True
    out = {}
    try:
        for cull in (False, True):
            r.terrain.cull_back = cull
            out[cull] = r.render(cam, sky=False, fog=0, **render_kw).image
    finally:
        r.release()
    return out


def test_culling_keeps_the_picture_from_above(gl, grid_net):
    net = grid_net(4, 4, size=10.0, relief=5.0, wave=2.0)
    cam = Camera([4.0, -6.0, 14.0], [22.0, 22.0, 0.0], fov_y=60)
    for kw in (dict(), dict(lightmap_mode="ps2")):
        img = _pair(gl, net, cam, **kw)
        assert (img[True][..., :3].max(-1) > 0).mean() > 0.5  # the terrain fills the view
        diff = np.abs(img[True].astype(int) - img[False].astype(int)).max(-1)
        assert (diff > 0).mean() < 0.005, f"{(diff > 0).sum()} pixels differ"


def test_culling_drops_the_underside(gl, grid_net):
    net = grid_net(4, 4, size=10.0, relief=1.0)
    cam = Camera([20.0, 20.0, -30.0], [20.0, 21.0, 0.0], fov_y=60)  # below, looking up
    img = _pair(gl, net, cam)
    assert (img[False][..., :3].max(-1) > 0).mean() > 0.3  # the underside, unculled
    assert (img[True][..., :3].max(-1) > 0).mean() < 0.01  # culled


def test_culling_only_when_every_patch_faces_up(gl, grid_net):
    from piste.render.frame import faces_up
    from piste.terrain import PatchNet

    net = grid_net(3, 3, size=10.0, relief=2.0)
    assert faces_up(net)
    cp = np.array(net.control_points, copy=True)
    cp[4] = cp[4].transpose(1, 0, 2)  # one patch with u and v swapped: drawn facing down
    flipped = PatchNet(cp)
    assert not faces_up(flipped)
    for n, want in ((net, True), (flipped, False)):
        r = TerrainRenderer(n, size=(32, 24), ctx=gl)
        try:
            assert r.terrain.cull_back is want
        finally:
            r.release()


def test_faces_up_equals_the_tessellated_corner_quads(grid_net):
    """faces_up reads the corner control points; the same answer as the level-2 tessellation's
    triangles (what it stands for) on nets that face up, flipped ones and a tilted, folded one."""
    from piste.render.frame import faces_up
    from piste.terrain import PatchNet, tessellate
    from piste.world.course import default_course

    def by_tessellation(net):
        m = tessellate(net, 2, cache=False)
        p = np.asarray(m.positions, dtype=np.float64)[np.asarray(m.indices, dtype=np.int64)]
        a, b = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
        return bool(np.all(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0] > 0.0))

    base = grid_net(3, 3, size=10.0, relief=2.0)
    cp = np.array(base.control_points, copy=True)
    flipped = cp.copy()
    flipped[4] = flipped[4].transpose(1, 0, 2)
    mirrored = cp * np.array([-1.0, 1.0, 1.0])  # every patch wound the other way
    tilted = cp.copy()
    tilted[..., 0] += 3.0 * tilted[..., 2]  # sheared in x by height: still up, or folded over
    nets = [base, PatchNet(flipped), PatchNet(mirrored), PatchNet(tilted), default_course(0)]
    got = [faces_up(n) for n in nets]
    assert got == [by_tessellation(n) for n in nets]
    assert got[0] and not got[1] and not got[2] and got[4]


def test_back_facing_patches_left_out_keep_the_picture(gl, grid_net):
    """Whole back-facing patches left out of the index list on the CPU (normal cones): the same
    picture as the GPU culling them triangle by triangle, fewer indices sent; the debug views, which
    draw back faces, get every patch again."""
    net = grid_net(6, 6, size=10.0, relief=12.0, wave=2.0)
    r = TerrainRenderer(net, size=(160, 112), ctx=gl, lod_near=14.0, lod_far=30.0)
    r.resident_wait = True
    try:
        for eye, target in (([-10.0, -10.0, 20.0], [40.0, 40.0, 0.0]), ([30.0, 30.0, 40.0], [30.0, 31.0, 0.0]),
                            ([30.0, -20.0, 3.0], [30.0, 60.0, 5.0])):
            cam = Camera(eye, target, fov_y=60)
            img, sent = {}, {}
            for on in (False, True):
                r.terrain.cull_back_patches = on
                img[on] = r.render(cam, sky=False, fog=0).image
                sent[on] = r.terrain.n_indices
            assert np.array_equal(img[True], img[False])
            assert sent[True] <= sent[False] == r.mesh.indices.size
        assert sent[True] < sent[False]  # (the last view looks across the hill: its far side is left out)
        base = r.render(cam, sky=False, fog=0, debug="base")
        assert r.terrain.n_indices == r.mesh.indices.size and base.image is not None
    finally:
        r.release()
