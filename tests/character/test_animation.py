"""Track and clip sampling (LINEAR/STEP/CUBICSPLINE, clamp/loop) and animation sharing (retargeting)."""

from __future__ import annotations

import numpy as np
import pytest

from piste.character import Clip, Skeleton, Track
from piste.character.animation import sample_track_many
from piste.errors import ConfigError, ValidationError
from piste.transforms import quat_angle, quat_multiply, quat_normalize


def two_bone():
    return Skeleton(["root", "arm"], [-1, 0], [[0, 0, 0], [0, 1, 0]], [[0, 0, 0, 1]] * 2, [[1, 1, 1]] * 2,
                    np.tile(np.eye(4), (2, 1, 1)))


def zrot(a):
    return np.array([0, 0, np.sin(a / 2), np.cos(a / 2)])


def test_linear_step_cubic_tracks():
    lin = Track([0, 1, 3], [[0.0], [1.0], [5.0]])
    assert sample_track_many(lin, [-1, 0, 0.5, 2, 3, 9])[:, 0].tolist() == [0, 0, 0.5, 3, 5, 5]
    step = Track([0, 1, 3], [[0.0], [1.0], [5.0]], "STEP")
    assert sample_track_many(step, [0.5, 1.0, 2.9, 3.0])[:, 0].tolist() == [0, 1, 1, 5]
    # cubic: Hermite through (0,0) slope 0 and (1,1) slope 0 -> smoothstep; tangents are per second
    cub = Track([0, 2], [[0.0], [1.0]], "CUBICSPLINE", in_tangents=[[0.0], [0.0]], out_tangents=[[0.0], [0.0]])
    u = np.linspace(0, 1, 11)
    assert np.allclose(sample_track_many(cub, 2 * u)[:, 0], 3 * u ** 2 - 2 * u ** 3)
    # linear data expressed as a cubic spline (slope 0.5/s) is reproduced exactly
    cub2 = Track([0, 2], [[0.0], [1.0]], "CUBICSPLINE", in_tangents=[[0.5], [0.5]], out_tangents=[[0.5], [0.5]])
    assert np.allclose(sample_track_many(cub2, 2 * u)[:, 0], u)
    single = Track([0.5], [[7.0, 8.0, 9.0]])
    assert np.allclose(single.sample(3.0), [7, 8, 9])
    with pytest.raises(ValidationError):
        Track([0, 1], [[0], [1]], "CUBICSPLINE")
    with pytest.raises(ValidationError):
        Track([0, 1], [[0], [1]], "BEZIER")


def test_rotation_slerp_constant_speed():
    tr = Track([0, 1], [zrot(0), zrot(2.0)])
    for t in (0.1, 0.5, 0.9):
        assert quat_angle(tr.sample(t, rotation=True), zrot(0)) == pytest.approx(2.0 * t)


def test_clip_sample_clamp_loop_and_rest_for_untracked():
    sk = two_bone()
    clip = Clip("wave", 2.0, {"arm": {"rotation": Track([0, 2], [zrot(0), zrot(1.0)])}}, skeleton=sk)
    p = clip.sample(1.0)
    assert quat_angle(p.rotation[1], zrot(0.5)) < 1e-6
    assert np.allclose(p.translation, sk.rest_translation) and np.allclose(p.rotation[0], [0, 0, 0, 1])
    assert quat_angle(clip.sample(5.0).rotation[1], zrot(1.0)) < 1e-6  # clamped
    assert quat_angle(clip.sample(2.5, loop=True).rotation[1], zrot(0.25)) < 1e-6  # wrapped
    assert quat_angle(clip.sample(-1.0).rotation[1], zrot(0)) < 1e-6
    assert clip.bones == ["arm"] and clip.nbytes > 0
    with pytest.raises(ConfigError):
        clip.sample(0.0, sk, retarget="magic")
    with pytest.raises(ValidationError):
        Clip("orphan", 1.0).sample(0.0)


def test_real_clips_sample_every_model(gltf_model):
    for name in ("CesiumMan", "Fox", "Girl", "RobotExpressive", "RiggedSimple", "SimpleSkin", "RiggedFigure"):
        m = gltf_model(name)
        for clip in m.clips.values():
            for t in np.linspace(0, clip.duration, 5):
                pose = clip.sample(t)
                assert np.all(np.isfinite(pose.translation))
                assert np.allclose(np.linalg.norm(pose.rotation, axis=1), 1.0)
                w = m.skeleton.world_matrices(pose)
                assert np.all(np.isfinite(w))


def test_clip_keys_reproduced_at_key_times(gltf_model):
    m = gltf_model("Fox")
    clip = m.clips["Walk"]
    name, bt = next(iter(clip.tracks.items()))
    tr = bt["rotation"]
    j = m.skeleton.bone_index(name)
    for k in (0, len(tr.times) // 2, len(tr.times) - 1):
        q = clip.sample(tr.times[k]).rotation[j]
        assert quat_angle(q, quat_normalize(tr.values[k])) < 1e-6


def _joint_positions(sk, pose):
    return sk.world_matrices(pose)[:, :3, 3]


def test_retarget_scaled_skeleton_scales_joint_positions(gltf_model):
    """Rule 'scaled': a skeleton that is the source scaled by k plays the clip with joints x k."""
    m = gltf_model("Fox")
    src = m.skeleton
    k = 2.5
    tgt = Skeleton(src.names, src.parents, src.rest_translation * k, src.rest_rotation, src.rest_scale,
                   src.inverse_bind)
    for clip in m.clips.values():
        for t in (0.0, clip.duration * 0.37, clip.duration):
            a = _joint_positions(src, clip.sample(t))
            b = _joint_positions(tgt, clip.sample(t, tgt))
            assert np.allclose(b, k * a, atol=1e-6 * k)


def test_retarget_between_models_cesiumman_to_riggedfigure(gltf_model):
    """CesiumMan's clip on RiggedFigure (same bone names, different proportions and bind pose):
    rotations come from the clip, bone lengths stay the target's."""
    cm, rf = gltf_model("CesiumMan"), gltf_model("RiggedFigure")
    clip = cm.clips["animation0"]
    tgt = rf.skeleton
    pose = clip.sample(0.8, tgt)
    src_pose = clip.sample(0.8)
    for name in clip.tracks:
        i, j = tgt.bone_index(name), cm.skeleton.bone_index(name)
        assert quat_angle(pose.rotation[i], src_pose.rotation[j]) < 1e-6
        ls, lt = np.linalg.norm(cm.skeleton.rest_translation[j]), np.linalg.norm(tgt.rest_translation[i])
        if ls > 1e-9:
            assert np.linalg.norm(pose.translation[i]) == pytest.approx(
                lt * np.linalg.norm(src_pose.translation[j]) / ls, rel=1e-9)
    w = tgt.world_matrices(pose)
    assert np.all(np.isfinite(w))
    # the retargeted figure is not its rest pose (the clip really drives it)
    assert not np.allclose(w, tgt.world_matrices(), atol=1e-3)


def test_retarget_relative_applies_delta_from_source_rest():
    src = two_bone()
    tgt_rot = np.array([[0, 0, 0, 1], zrot(0.7)])
    tgt = Skeleton(["root", "arm"], [-1, 0], [[0, 0, 0], [0, 3, 0]], tgt_rot, [[1, 1, 1]] * 2,
                   np.tile(np.eye(4), (2, 1, 1)))
    # a clip holding the source rest pose leaves the target at its own rest
    hold = Clip("hold", 1.0, {"arm": {"rotation": Track([0], [[0, 0, 0, 1]]),
                                      "translation": Track([0], [[0, 1, 0]])}}, skeleton=src)
    p = hold.sample(0.5, tgt, retarget="relative")
    assert np.allclose(p.rotation, tgt.rest_rotation) and np.allclose(p.translation, tgt.rest_translation)
    # a clip rotating 0.4 rad about Z from the source rest adds 0.4 rad to the target's rest
    turn = Clip("turn", 1.0, {"arm": {"rotation": Track([0], [zrot(0.4)])}}, skeleton=src)
    p = turn.sample(0.0, tgt, retarget="relative")
    assert quat_angle(p.rotation[1], quat_multiply(zrot(0.7), zrot(0.4))) < 1e-6
    # "scaled" would have overwritten the target's rest rotation
    assert quat_angle(turn.sample(0.0, tgt).rotation[1], zrot(0.4)) < 1e-6
    # same skeleton: defaults to no retargeting
    assert np.allclose(turn.sample(0.0).rotation[1], zrot(0.4))
