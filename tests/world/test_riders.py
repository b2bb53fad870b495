"""Riders on the course: on the exact surface, oriented to the slope, clips from the table."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import ConfigError


@pytest.fixture(scope="module")
def pack():
    from piste.character import default_rider
    from piste.world.course import default_course, track_centerline
    from piste.world.riders import RiderSet

    net = default_course(0)
    line = track_centerline(0)
    return net, line, RiderSet(net, line, model=default_rider(0))


def _fd_normal(net, xy, h=0.05):
    from piste.terrain.query import height_at

    pts = np.concatenate([xy + [h, 0], xy - [h, 0], xy + [0, h], xy - [0, h]])
    z, hit, _, _ = height_at(net, pts)
    k = len(xy)
    dzdx = (z[:k] - z[k:2 * k]) / (2 * h)
    dzdy = (z[2 * k:3 * k] - z[3 * k:]) / (2 * h)
    n = np.stack([-dzdx, -dzdy, np.ones(k)], 1)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


@pytest.mark.parametrize("t", [0.0, 1.3, 4.7])
def test_riders_stand_on_the_surface_oriented_to_the_slope(pack, t):
    from piste.terrain.query import height_at

    net, line, riders = pack
    st = riders.state(t)
    assert len(st) == 6 and st.skin.shape == (6, riders.model.skeleton.n_bones, 4, 4)
    z, hit, _, _ = height_at(net, st.anchor[:, :2])
    assert hit.all()
    np.testing.assert_allclose(st.anchor[:, 2], z, atol=1e-9)
    # up = surface normal (checked against finite differences of the height query)
    np.testing.assert_allclose(st.matrix[:, :3, 1], _fd_normal(net, st.anchor[:, :2]), atol=2e-4)
    # a rigid frame: forward tangent to the surface, right-handed
    r = st.matrix[:, :3, :3]
    np.testing.assert_allclose(r.transpose(0, 2, 1) @ r, np.broadcast_to(np.eye(3), r.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-12)
    assert np.abs((st.forward * st.normal).sum(1)).max() < 1e-12
    # moving downhill
    assert (st.forward[:, 2] < 0).all()


def test_board_on_the_surface(pack):
    """The board bone sits on the surface for grounded clips (ride, crouch) and above it (by the
    clip's jump height) for the air clips; the board's vertices hug the surface."""
    from piste.terrain.query import height_at

    net, line, riders = pack
    model = riders.model
    sk = model.skeleton
    board = sk.bone_index("board")
    mesh = model.meshes[0]
    on_board = (mesh.joints[:, 0] == board) & (mesh.weights[:, 0] > 0.99)
    assert on_board.sum() > 20
    for t in (0.0, 0.8, 2.1):
        st = riders.state(t)
        for i, clip in enumerate(st.clip):
            bone = (st.skin[i, board] @ np.linalg.inv(sk.inverse_bind[board]))[:3, 3]  # board bone origin, world
            height = (bone - st.anchor[i]) @ st.normal[i]
            if clip in ("ride", "crouch"):
                assert abs(height) < 1e-6
                # board vertices: within 8 cm of the curved surface under them
                p = np.einsum("ij,vj->vi", st.skin[i, board][:3, :3], mesh.positions[on_board].astype(np.float64))
                p += st.skin[i, board][:3, 3]
                zs, hit, _, _ = height_at(net, p[:, :2])
                gap = (p[:, 2] - zs) * st.normal[i, 2]  # ~ distance along the normal
                assert hit.all() and abs(gap.min()) < 0.03 and gap.max() < 0.15
            else:
                assert -1e-6 < height < 0.8


def test_clip_table_matches_clip_sampling(pack):
    net, line, riders = pack
    tab = riders.table
    sk = riders.model.skeleton
    rng = np.random.default_rng(0)
    for name in tab.names:
        c = tab.clip_index(name)
        for t in rng.uniform(0, tab.duration[c], 4):
            want = sk.world_matrices(riders.model.clips[name].sample(float(t), loop=True))[:, :3, 3]
            got = tab.skin_matrices([c], [t])[0] @ np.linalg.inv(sk.inverse_bind)
            assert np.abs(got[:, :3, 3] - want).max() < 1e-3  # joints within a millimetre


def test_riders_move_down_the_track_and_play_different_clips(pack):
    net, line, riders = pack
    a, b = riders.state(0.0), riders.state(1.0)
    assert (b.along > a.along).all()
    assert len(set(a.clip)) == 4
    # poses differ between riders (different clips / phases)
    assert np.abs(a.skin[0] - a.skin[1]).max() > 0.01


def test_follow_camera_behind_and_above(pack):
    from piste.terrain.query import height_at
    from piste.world.riders import follow_camera

    net, line, riders = pack
    st = riders.state(2.0)
    cam = follow_camera(st, 0, net=net)
    to_rider = st.anchor[0] - cam.eye
    assert to_rider @ st.forward[0] > 0  # the rider is in front of the camera
    z, _, _, _ = height_at(net, cam.eye[None, :2])
    assert cam.eye[2] >= z[0] + 1.5 - 1e-9
    # the rider is inside the view frustum
    assert (cam.frustum_planes() @ np.append(st.anchor[0] + st.normal[0], 1.0) > 0).all()


def test_bad_clip_name(pack):
    from piste.world.riders import RiderSet

    net, line, riders = pack
    with pytest.raises(ConfigError):
        RiderSet(net, line, model=riders.model, pack=[("backflip", 0, 0, 0, 0, 1)])
