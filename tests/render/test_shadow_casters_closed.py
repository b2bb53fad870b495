"""The shadow casters drawn closed (caps over their holes) with back faces culled
(:func:`piste.render.shadow_pass.closed_caster_indices`, ``ShadowPass.cull_casters``): the same
silhouettes as every triangle drawn double-sided."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import RenderError
from piste.render.shadow_pass import ShadowPass, closed_caster_indices, shadow_matrices


def _open_box(lo=(-0.5, -0.4, -0.3), hi=(0.5, 0.4, 0.9), split_seam: bool = True):
    """A box without its top face, outward-facing triangles ``(t, 3)``, its vertices ``(v, 3) float32``;
    ``split_seam``: the bottom's corners repeated (a UV seam: the same positions, other indices)."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], np.float32)
    walls = [[0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]]
    bottom = [[0, 2, 1], [0, 3, 2]]
    if split_seam:
        v = np.concatenate([v, v[:4]])
        bottom = [[8, 10, 9], [8, 11, 10]]
    return np.array(walls + bottom, np.int64), v


def _directed_edges_closed(tri: np.ndarray, pos: np.ndarray) -> bool:
    _, weld = np.unique(pos, axis=0, return_inverse=True)
    w = weld.reshape(-1)[tri]
    e = np.concatenate([w[:, [0, 1]], w[:, [1, 2]], w[:, [2, 0]]])
    e = e[e[:, 0] != e[:, 1]]
    fwd = {tuple(x) for x in e.tolist()}
    return all((b, a) in fwd for a, b in e.tolist())


def test_caps_close_an_open_box_with_its_own_vertices():
    tri, pos = _open_box()
    assert not _directed_edges_closed(tri, pos)
    out = closed_caster_indices(tri, pos)
    assert out.dtype == np.uint32 and out.shape[1] == 3
    np.testing.assert_array_equal(out[:len(tri)], tri)  # the caster's own triangles first, unchanged
    assert len(out) == len(tri) + 2  # the top's square: a fan of two triangles
    assert out.max() < len(pos)  # nothing new to skin
    assert _directed_edges_closed(out.astype(np.int64), pos)
    # the caps face out (up), as the box's faces do
    p = pos.astype(np.float64)
    cap = p[out[len(tri):].astype(np.int64)]
    n = np.cross(cap[:, 1] - cap[:, 0], cap[:, 2] - cap[:, 0])
    assert (n[:, 2] > 0).all()


def test_closed_mesh_and_bad_input():
    tri, pos = _open_box()
    closed = closed_caster_indices(tri, pos).astype(np.int64)
    np.testing.assert_array_equal(closed_caster_indices(closed, pos), closed)  # nothing left to cap
    assert closed_caster_indices(np.zeros((0, 3), np.int64), pos).shape == (0, 3)
    with pytest.raises(RenderError, match="indices"):
        closed_caster_indices(tri + 100, pos)


def _tiles(gl, pos, tri, cull: bool, d=(0.3, 0.2, -1.0)):
    """The hard shadow tile of ``pos (v, 3)``, ``tri`` drawn culled-closed or every triangle, seen
    from the sun ``d``: ``(tile, tile) uint8``."""
    sp = ShadowPass(gl, n_max=1, tile=128)
    try:
        sp.cull_casters = cull
        lvp = shadow_matrices(pos.mean(0)[None].astype(np.float64), 1.2, np.asarray(d, float))
        sp.render_casters(pos[None].astype(np.float32), tri, lvp)
        return sp.read_tiles()
    finally:
        sp.release()


@pytest.mark.parametrize("d", [(0.3, 0.2, -1.0), (0.0, 0.0, -1.0), (-0.8, 0.5, -0.4), (0.2, -0.3, 1.0)])
def test_open_box_shadow_culled_is_the_double_sided_one(gl, d):
    tri, pos = _open_box()
    full = _tiles(gl, pos, tri, cull=False, d=d).astype(int)
    culled = _tiles(gl, pos, tri, cull=True, d=d).astype(int)
    assert (full > 0).sum() > 2000
    # the open top is inside the silhouette from every side: the same texels (a few at the edge for
    # the rasterizer's tie-breaking between the cap's and the walls' shared edges)
    assert (full != culled).sum() <= 8


def test_without_the_caps_the_culled_box_loses_its_opening(gl):
    """(What the caps are for: culled without them, the box seen with its opening on the kept side
    loses the texels seen through it.)"""
    tri, pos = _open_box()
    lost = []
    for d in [(0.3, 0.2, -1.0), (0.2, -0.3, 1.0)]:
        full = _tiles(gl, pos, tri, cull=False, d=d).astype(int)
        sp = ShadowPass(gl, n_max=1, tile=128)
        try:
            lvp = shadow_matrices(pos.mean(0)[None].astype(np.float64), 1.2, np.asarray(d, float))
            sp.render_casters(pos[None].astype(np.float32), tri, lvp)
            c = sp._casts[0]
            c["vao_c"], c["nt_c"] = c["vao"], c["nt"]  # the open box, culled
            sp.render_casters(pos[None].astype(np.float32), tri, lvp)
            lost.append(int(((full > 0) & (sp.read_tiles() == 0)).sum()))
        finally:
            sp.release()
    assert max(lost) > 500


def test_rider_shadow_culled_matches(gl):
    """The default rider's coarsest level (open parts, holes at the joints), skinned in three poses
    (the caps made once, from the first pose, as the scene does): the culled, capped casters' tiles
    are the double-sided ones' within a few texels."""
    from piste.character import default_rider, make_lods
    from piste.character.skinning import BlendedMesh
    from piste.world.scene import orient_outward

    model = default_rider(0)
    low = make_lods(orient_outward(model.meshes[0])[0])[-1]
    tri = np.asarray(low.mesh.indices, np.int64)
    rot = np.eye(4)
    rot[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # rider +Y up -> world +Z up
    skins = np.stack([rot @ model.skeleton.skin_matrices(model.clips["ride"].sample(t, loop=True)) for t in (0.0, 0.4, 0.9)])
    poses = BlendedMesh(low.palette, low.mesh.positions, low.mesh.normals).apply_many(skins)[0]
    closed = closed_caster_indices(tri, poses[0])
    assert len(closed) > len(tri)  # (it has holes to cap)
    sp = {on: ShadowPass(gl, n_max=3, tile=128) for on in (True, False)}
    try:
        for d in [(0.3, 0.2, -1.0), (0.7, -0.4, -0.6), (-0.2, 0.9, -0.5)]:
            lvp = shadow_matrices(poses.mean(1).astype(np.float64), 1.3, np.asarray(d, float))
            tiles = {}
            for on, p in sp.items():
                p.cull_casters = on
                p.render_casters(poses.astype(np.float32), tri, lvp)
                tiles[on] = p.read_tiles().astype(int)
            assert (tiles[False] > 0).sum() > 3 * 500
            assert (tiles[True] != tiles[False]).sum() <= 0.005 * (tiles[False] > 0).sum()
    finally:
        for p in sp.values():
            p.release()


def test_tiles_drawn_only_where_asked(gl):
    """``render_casters(draw=...)``: the riders left out keep a clear tile, the others' tiles are as drawn
    with every rider."""
    tri, pos = _open_box()
    poses = np.stack([pos, pos + [3.0, 0.0, 0.0], pos + [0.0, 3.0, 0.0]]).astype(np.float32)
    lvp = shadow_matrices(poses.mean(1).astype(np.float64), 1.2, np.array([0.3, 0.2, -1.0]))
    sp = ShadowPass(gl, n_max=3, tile=64)
    try:
        sp.render_casters(poses, tri, lvp)
        every = sp.read_tiles().astype(int)
        sp.render_casters(poses, tri, lvp, draw=np.array([True, False, True]))
        some = sp.read_tiles().astype(int)
    finally:
        sp.release()
    assert (every[:, 64:128] > 0).sum() > 300
    assert (some[:, 64:128] == 0).all()
    np.testing.assert_array_equal(some[:, :64], every[:, :64])
    np.testing.assert_array_equal(some[:, 128:], every[:, 128:])


def test_scene_skips_the_casters_whose_shadows_are_out_of_view(gl):
    """The scene draws a rider's caster tile only when its shadow frustum meets a patch drawn this frame;
    the picture is the one with every tile drawn."""
    from piste.render.scene_renderer import SceneRenderer
    from piste.world.camera import Camera
    from piste.world.scene import Scene

    scene = Scene.default(0, objects=False)
    r = SceneRenderer(scene, size=(160, 112), ctx=gl, lightmap=None, face=None)
    r.terrain.resident_wait = True
    sp = r.shadows
    asked = []
    real = sp.render_casters

    def spy(*a, draw=None, **k):
        asked.append(None if draw is None else np.asarray(draw, bool).copy())
        return real(*a, draw=draw, **k)

    try:
        t = 2.0
        st = scene.riders.state(t)
        a = st.anchor[0]
        f = np.append(st.track_dir[0], 0.0)
        # a little ahead of rider 0, looking back up the course at it: the riders further down are
        # behind the camera
        cam = Camera(a + f * 4.0 + np.array([0.0, 0.0, 2.0]), a, fov_y=40.0, near=0.5, far=4000.0)
        sp.render_casters = spy
        im = r.render(t, camera=cam)
        sp.render_casters = lambda *a, draw=None, **k: real(*a, **k)  # every tile drawn
        every = r.render(t, camera=cam)
    finally:
        sp.render_casters = real
        r.release()
    mask = np.concatenate(asked)
    per = np.asarray(im.stats["shadow_patches_per_rider"])
    np.testing.assert_array_equal(mask, per > 0)
    assert mask[0] and not mask.all(), per
    np.testing.assert_array_equal(im.image, every.image)
