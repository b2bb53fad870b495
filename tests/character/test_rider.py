"""The procedural default rider."""

from __future__ import annotations

import numpy as np
import pytest

from piste.character.rider import RIDER_CLIPS, RIDER_MORPHS, default_rider
from piste.character.skinning import skin


@pytest.fixture(scope="module")
def rider():
    return default_rider()


def test_counts_and_contents(rider):
    sk = rider.skeleton
    mesh = rider.meshes[0]
    assert 20 <= sk.n_bones <= 30
    assert 2500 <= mesh.n_triangles <= 3500
    assert set(RIDER_CLIPS) <= set(rider.clips)
    assert list(mesh.morph_names) == list(RIDER_MORPHS)
    assert mesh.texture.shape == (128, 128, 4) and mesh.texture.dtype == np.uint8
    assert mesh.uv.min() >= 0 and mesh.uv.max() <= 1
    for name in ("board", "head", "jaw", "hand_l", "foot_r", "spine3"):
        assert sk.get(name) is not None


def test_deterministic_and_seeded():
    a, b, c = default_rider(0), default_rider(0), default_rider(3)
    ma, mb, mc = a.meshes[0], b.meshes[0], c.meshes[0]
    for f in ("positions", "normals", "uv", "indices", "joints", "weights", "morph_positions", "texture"):
        assert np.array_equal(getattr(ma, f), getattr(mb, f)), f
    for name in a.clips:
        for bone, tracks in a.clips[name].tracks.items():
            for kind, tr in tracks.items():
                assert np.array_equal(tr.values, b.clips[name].tracks[bone][kind].values)
    assert np.array_equal(ma.indices, mc.indices)  # same topology for every seed
    assert not np.array_equal(ma.texture, mc.texture) or not np.array_equal(ma.positions, mc.positions)


def test_no_degenerate_triangles_and_valid_skin(rider):
    mesh = rider.meshes[0]
    p = mesh.positions.astype(np.float64)
    t = mesh.indices.astype(np.int64)
    area = 0.5 * np.linalg.norm(np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]), axis=1)
    assert area.min() > 1e-8
    assert len(set(map(tuple, np.sort(t, axis=1)))) == len(t)
    assert np.allclose(mesh.weights.sum(1), 1.0, atol=1e-6)
    assert mesh.joints.max() < rider.skeleton.n_bones
    infl = (mesh.weights > 0).sum(1)
    assert infl.max() <= 4 and (infl >= 3).any()  # smooth blends near joints
    assert np.allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-5)


def test_looks_like_a_rider(rider):
    mesh = rider.meshes[0]
    lo, hi = mesh.bounds()
    assert 1.6 < hi[1] - lo[1] < 2.0  # a person's height (board included)
    assert 1.5 < hi[0] - lo[0] < 1.7  # the board's length along X
    board = mesh.joints[:, 0] == rider.skeleton.bone_index("board")
    assert mesh.positions[board, 1].max() < 0.15  # the board lies under the feet


def test_rest_pose_reproduces_bind(rider):
    sk = rider.skeleton
    p, n = skin(rider.meshes[0], sk.skin_matrices(sk.rest_pose()), "exact")
    assert np.abs(p - rider.meshes[0].positions).max() < 1e-5


def test_clips_loop_and_keep_feet_on_the_board(rider):
    sk = rider.skeleton
    foot = [sk.bone_index("foot_l"), sk.bone_index("foot_r")]
    board = sk.bone_index("board")
    bind = np.linalg.inv(sk.inverse_bind)
    for name in RIDER_CLIPS:
        clip = rider.clips[name]
        w0 = sk.world_matrices(clip.sample(0.0))
        w1 = sk.world_matrices(clip.sample(clip.duration))
        assert np.abs(w0 - w1).max() < 1e-6, name
        for t in np.linspace(0, clip.duration, 7):
            w = sk.world_matrices(clip.sample(t, loop=True))
            # ankles where the board carries them (IK at the keys, slerp in between)
            want = w[board] @ sk.inverse_bind[board] @ bind[foot][:, :, 3, None]
            got = w[foot][:, :, 3]
            assert np.abs(got - want[..., 0]).max() < 0.03, (name, t)
    spin = rider.clips["spin"]
    q = spin.sample(spin.duration / 2).rotation[sk.bone_index("root")]
    assert abs(abs(q[3]) - 0.0) < 0.05  # half-way through the spin: 180 degrees


def test_face_morphs_only_move_the_head(rider):
    mesh = rider.meshes[0]
    moved = np.abs(mesh.morph_positions).max(axis=(0, 2)) > 0
    head = rider.skeleton.bone_index("head")
    jaw = rider.skeleton.bone_index("jaw")
    assert moved.sum() > 20
    assert np.isin(mesh.joints[moved, 0], [head, jaw, rider.skeleton.bone_index("neck")]).all()
    for k in range(mesh.n_morphs):
        assert np.abs(mesh.morph_positions[k]).max() > 0.004  # visible: millimetres to centimetres


def test_rider_parts_face_outward():
    """Every closed part (torso, limbs, board) is wound outward, so its normals point out of the body."""
    from piste.character import default_rider
    from piste.world.scene import orient_outward

    _, flipped = orient_outward(default_rider(0).meshes[0])
    assert flipped == 0


def test_shipped_key_tables_equal_the_posed_ones(tmp_path, monkeypatch):
    """The seed-0 rider's clip keys shipped as package data (piste/data/rider_keys.npz) equal what the
    rig's IK poses (regenerate with ``piste.character.rider.write_key_tables()``); without the file
    the keys are posed and the clips are the same."""
    import numpy as np

    from piste.character import rider as R

    shipped = R.shipped_key_tables()
    assert shipped is not None, f"{R.RIDER_KEYS_FILE} is missing or unreadable"
    J = R._joint_positions(1.0)
    sk = R._skeleton(J)
    for name in R.RIDER_CLIPS:
        rot, tra = R.key_tables(sk, J, name)
        # equal to the last bits on the machine that wrote the table; numpy's SIMD paths differ by CPU
        # (an AVX-512 machine poses them 2-7e-16 apart), so a few ulps, never more
        assert np.allclose(shipped[name][0], rot, rtol=0, atol=1e-12), name
        assert np.allclose(shipped[name][1], tra, rtol=0, atol=1e-12), name
    with_file = R.default_rider(0)
    bad = tmp_path / "k.npz"
    bad.write_bytes(b"not an npz")
    monkeypatch.setattr(R, "RIDER_KEYS_FILE", bad)
    assert R.shipped_key_tables() is None
    posed = R.default_rider(0)
    for name, clip in posed.clips.items():
        other = with_file.clips[name]
        assert clip.tracks.keys() == other.tracks.keys()
        for bone, bt in clip.tracks.items():
            for path, tr in bt.items():
                assert np.allclose(tr.values, other.tracks[bone][path].values, rtol=0, atol=1e-12)
                assert np.array_equal(tr.times, other.tracks[bone][path].times)
