"""The shadow receivers drawn from the terrain's resident vertex blocks by index (geomorphed on the
GPU as the terrain is) give the same pixels as the receivers gathered, morphed and uploaded on the
CPU; the index lists name the same triangles."""

from __future__ import annotations

import numpy as np
import pytest


def _setup(gl, grid_net):
    from piste.render.frame import TerrainRenderer
    from piste.render.shadow_pass import ShadowPass, shadow_matrices, shadow_patches
    from piste.terrain.query import height_at
    from piste.world.camera import Camera
    from piste.world.objects import _icosphere

    net = grid_net(4, 4, size=10.0, relief=3.0)
    zc = float(height_at(net, np.array([18.0, 20.0]))[0])
    centre = np.array([18.0, 20.0, zc + 3.5])
    d = np.array([0.55, 0.35, -1.0])
    # a low perspective camera: patches at several levels, edges in their morph bands
    cam = Camera(eye=(20.0, -12.0, 14.0), target=(20.0, 22.0, 0.0), near=0.5, far=300.0)
    tr = TerrainRenderer(net, size=(160, 120), ctx=gl, lightmap=None)
    sp = ShadowPass(gl, n_max=2, tile=128)
    v, f = _icosphere(3)
    pos = np.stack([v * 2.5 + centre, v * 1.8 + centre + [6.0, -4.0, 0.0]]).astype(np.float32)
    light_vp = shadow_matrices(np.stack([centre, centre + [6.0, -4.0, 0.0]]), [2.6, 1.9], d)
    sp.render_casters(pos, f.astype(np.uint32), light_vp)
    frame = tr.render(cam, fog=None, sky=False, read=False)  # (after the casters, as a scene frame draws them)
    patches = shadow_patches(*net.patch_bounds, light_vp, candidates=tr.mesh.patch_ids)
    return tr, sp, cam, patches, frame


def test_resident_indices_name_the_gathered_triangles(gl, grid_net):
    from piste.render.shadow_pass import resident_shadow_triangles, shadow_triangles
    from piste.terrain.resident import ResidentMesh

    tr, sp, cam, patches, _ = _setup(gl, grid_net)
    try:
        mesh = tr.mesh
        assert isinstance(mesh, ResidentMesh) and mesh.morph
        idx, ranges = resident_shadow_triangles(mesh, patches + [np.array([], np.int64)])
        pos, want, want_ranges = shadow_triangles(mesh, patches + [np.array([], np.int64)])
        assert idx.dtype == np.uint32 and idx.shape == want.shape
        np.testing.assert_array_equal(ranges, want_ranges)
        # the same corners, morphed as the vertex shader does
        np.testing.assert_array_equal(mesh.morphed_positions(idx.ravel()), pos[want.ravel()])
        assert ranges[-1].tolist() == [len(idx), 0]
    finally:
        sp.release()
        tr.release()


@pytest.mark.parametrize("morph", [True, False])
def test_resident_receivers_draw_the_same_pixels(gl, grid_net, morph):
    tr, sp, cam, patches, _ = _setup(gl, grid_net)
    try:
        if not morph:
            tr.lod_morph = False
            tr.render(cam, fog=None, sky=False, read=False)
        assert tr.terrain.resident_blocks(tr.mesh) is not None
        assert (tr.terrain.resident_blocks(tr.mesh)[1] is not None) == morph
        vp = cam.with_aspect(160, 120).view_projection()
        images = {}
        for resident in (True, False):
            sp.resident_receivers = resident
            tr.draw(cam, tr.mesh, fog=None, sky=False, read=False)
            sp.draw_receivers(tr.mesh, patches, vp, terrain=tr.terrain)
            gl.finish()
            images[resident] = tr.target.read()[..., :3].astype(int)
        assert sp._receiver_res is not None  # (the resident path was taken)
        tr.draw(cam, tr.mesh, fog=None, sky=False, read=False)
        gl.finish()
        plain = tr.target.read()[..., :3].astype(int)
        shaded = (images[True] < plain - 8).any(-1)
        assert shaded.sum() > 80  # the shadows are there
        assert np.abs(images[True] - images[False]).max() <= 1
    finally:
        sp.release()
        tr.release()


def test_resident_blocks_only_for_the_uploaded_resident_mesh(gl, grid_net):
    from piste.render.frame import TerrainRenderer

    tr, sp, cam, patches, _ = _setup(gl, grid_net)
    other = TerrainRenderer(grid_net(4, 4, size=10.0, relief=3.0), size=(32, 32), ctx=gl, lightmap=None,
                            resident=False)
    try:
        other.render(cam, fog=None, sky=False, read=False)
        assert other.terrain.resident_blocks(other.mesh) is None  # a streamed (CPU-tessellated) mesh
        assert tr.terrain.resident_blocks(other.mesh) is None
        buf, morph = tr.terrain.resident_blocks(tr.mesh)
        assert buf.size == tr.mesh.resident.vertices.nbytes
    finally:
        other.release()
        sp.release()
        tr.release()
