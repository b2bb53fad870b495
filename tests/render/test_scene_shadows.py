"""Projected shadows: the shadow lands where a ray cast towards the sun says it should."""

from __future__ import annotations

import numpy as np
import pytest


def _sphere(center, radius):
    from piste.world.objects import _icosphere

    v, f = _icosphere(3)
    return (v * radius + center).astype(np.float32), f.astype(np.uint32)


def test_shadow_matrices_frame_the_caster():
    from piste.render.shadow_pass import shadow_matrices

    c = np.array([[10.0, 20.0, 5.0], [0.0, 0.0, 0.0]])
    d = np.array([0.5, 0.3, -1.0])
    vp = shadow_matrices(c, 1.5, d, reach=30.0)
    for i in range(2):
        q = vp[i] @ np.append(c[i], 1.0)
        np.testing.assert_allclose(q[:2], 0.0, atol=1e-12)
        assert -1 < q[2] < 1
        # a point 1.5 m to the side (perpendicular to the light) sits on the frustum's edge
        side = np.cross(d, [0, 0, 1.0])
        side /= np.linalg.norm(side)
        e = vp[i] @ np.append(c[i] + 1.5 * side, 1.0)
        assert abs(np.hypot(e[0], e[1]) - 1.0) < 1e-9
        # 25 m down the light from the caster is still inside; 40 m is beyond the reach
        dn = d / np.linalg.norm(d)
        assert -1 < (vp[i] @ np.append(c[i] + 25 * dn, 1.0))[2] < 1
        assert (vp[i] @ np.append(c[i] + 40 * dn, 1.0))[2] > 1


def test_shadow_triangles_gather_the_patches(grid_net):
    from piste.render.shadow_pass import shadow_triangles
    from piste.terrain import tessellate

    net = grid_net(3, 3)
    mesh = tessellate(net, 6)
    lists = [np.array([4]), np.array([0, 8, 4]), np.array([], dtype=np.int64)]
    pos, idx, ranges = shadow_triangles(mesh, lists)
    k = list(mesh.patch_ids).index(4)
    per = mesh.tri_start[k + 1] - mesh.tri_start[k]
    assert ranges.tolist() == [[0, per], [per, 3 * per], [4 * per, 0]]
    # rider 0's triangles are patch 4's, in the same vertex positions
    want = mesh.positions[mesh.indices[mesh.tri_start[k]:mesh.tri_start[k + 1]]]
    np.testing.assert_array_equal(pos[idx[:per]], want)
    assert idx.max() < len(pos)


def test_shadow_lands_where_the_ray_cast_says(gl, grid_net):
    from piste.render.frame import TerrainRenderer
    from piste.render.shadow_pass import ShadowPass, shadow_matrices, shadow_patches
    from piste.terrain.query import height_at
    from piste.world.camera import Camera

    net = grid_net(3, 3, size=10.0, relief=2.0)
    zc = float(height_at(net, np.array([14.0, 16.0]))[0])
    centre = np.array([14.0, 16.0, zc + 3.0])
    radius = 1.5
    d = np.array([0.55, 0.35, -1.0])
    d /= np.linalg.norm(d)
    W = 128
    S = 16.0  # metres across the image
    cam = Camera(eye=(15.0, 15.0, 60.0), target=(15.0, 15.0, 0.0), up=(0.0, 1.0, 0.0), ortho_height=S,
                 aspect=1.0, near=1.0, far=200.0)
    tr = TerrainRenderer(net, size=(W, W), ctx=gl, lightmap=None)
    sp = ShadowPass(gl, n_max=1, tile=256)
    try:
        base = tr.render(cam, lod=False, fog=None, sky=False, clear=(0, 0, 0, 1)).image[..., :3].astype(float)
        pos, tri = _sphere(centre, radius)
        light_vp = shadow_matrices(centre[None], radius * 1.05, d, reach=40.0)
        sp.render_casters(pos[None], tri, light_vp)
        tiles = sp.read_tiles()
        assert 0.4 < (tiles > 128).mean() < 0.9  # the sphere fills its tile's disc
        tr.draw(cam, tr.mesh, fog=None, sky=False, clear=(0, 0, 0, 1), read=False)
        patches = shadow_patches(*net.patch_bounds, light_vp, candidates=tr.mesh.patch_ids)
        assert 0 < len(patches[0]) < len(net)
        sp.draw_receivers(tr.mesh, patches, cam.with_aspect(W, W).view_projection())
        gl.finish()
        shaded = tr.target.read()[..., :3].astype(float)
    finally:
        sp.release()
        tr.release()
    rendered = (shaded / np.maximum(base, 1.0)).mean(-1) < 0.85
    # ray-cast prediction: the surface point under each pixel centre, then a ray towards the sun
    px = (np.arange(W) + 0.5) / W * S - S / 2
    X, Y = np.meshgrid(15.0 + px, 15.0 - px)  # image rows from the top (+y) down
    xy = np.stack([X.ravel(), Y.ravel()], 1)
    z, hit, _, _ = height_at(net, xy)
    p = np.concatenate([xy, z[:, None]], 1)
    to_c = centre - p
    along = to_c @ (-d)
    dist2 = (to_c * to_c).sum(1) - along ** 2
    predicted = (hit & (along > 0) & (dist2 < radius ** 2)).reshape(W, W)
    assert predicted.sum() > 500
    # compare away from the shadow's edge (a pixel either side)
    from scipy.ndimage import binary_dilation, binary_erosion

    edge = binary_dilation(predicted, iterations=2) & ~binary_erosion(predicted, iterations=2)
    wrong = (rendered != predicted) & ~edge
    assert wrong.sum() <= 0.002 * W * W, f"{wrong.sum()} pixels disagree with the ray cast"
    inter = (rendered & predicted).sum()
    union = (rendered | predicted).sum()
    assert inter / union > 0.85
