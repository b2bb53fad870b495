"""Animation compression: bound on the ACL-style object-space error, bytes shrink, exact serialization."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from piste.character import Clip, Skeleton, Track
from piste.character.compress import (_pack_bits, _unpack_bits, clip_error, compress_clip, compression_report,
                                      default_tolerances)
from piste.errors import ValidationError


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 24), st.integers(0, 50), st.integers(0, 2 ** 31))
def test_bit_packing_roundtrip(bits, m, seed):
    q = np.random.default_rng(seed).integers(0, 1 << bits, size=m, dtype=np.uint64).astype(np.uint32)
    data = _pack_bits(q, bits)
    assert len(data) == (m * bits + 7) // 8
    assert np.array_equal(_unpack_bits(data, bits, m), q)


def chain():
    return Skeleton(["root", "arm"], [-1, 0], [[0, 0, 0], [0, 1, 0]], [[0, 0, 0, 1]] * 2, [[1, 1, 1]] * 2,
                    np.tile(np.eye(4), (2, 1, 1)))


def zrot(a):
    return np.array([0, 0, np.sin(a / 2), np.cos(a / 2)])


def test_clip_error_matches_geometry():
    """Root rotated by theta: the arm's farthest virtual point (1 + d from the pivot) moves by
    2 sin(theta/2) (1 + d)."""
    sk = chain()
    a = Clip("a", 1.0, {"root": {"rotation": Track([0, 1], [zrot(0), zrot(0)])}}, skeleton=sk)
    theta = 0.01
    b = Clip("b", 1.0, {"root": {"rotation": Track([0, 1], [zrot(theta), zrot(theta)])}}, skeleton=sk)
    d = 0.25
    err, per = clip_error(a, b, sk, d)
    assert err == pytest.approx(2 * np.sin(theta / 2) * (1 + d), rel=1e-9)
    assert per[0] == pytest.approx(2 * np.sin(theta / 2) * d, rel=1e-9)
    assert clip_error(a, a, sk, d)[0] == 0.0


def test_synthetic_reduction_and_bound():
    sk = chain()
    t = np.linspace(0, 2, 121)
    rot = np.stack([zrot(a) for a in 0.8 * np.sin(3 * t)])
    lin = np.stack([np.zeros_like(t), 1 + 0.5 * t, np.zeros_like(t)], 1)  # linear: 2 keys suffice
    clip = Clip("c", 2.0, {"root": {"rotation": Track(t, rot)}, "arm": {"translation": Track(t, lin)}}, skeleton=sk)
    cc = compress_clip(clip, max_error=1e-3, virtual_distance=0.1)
    assert cc.achieved_error <= 1e-3
    by = {(tr.target, tr.path): tr for tr in cc.tracks}
    assert by[("arm", "translation")].n_keys == 2
    assert 2 < by[("root", "rotation")].n_keys < 121
    lossy = cc.decompress()
    rng = np.random.default_rng(1)
    e, _ = clip_error(clip, lossy, sk, 0.1, rng.uniform(0, 2, 500))
    assert e <= 1e-3 * 1.05
    assert len(cc.to_bytes()) == cc.nbytes
    # looser bound: fewer bytes
    loose = compress_clip(clip, max_error=1e-2, virtual_distance=0.1)
    assert loose.nbytes < cc.nbytes and loose.achieved_error <= 1e-2
    with pytest.raises(ValidationError):
        compress_clip(clip, max_error=0)


def test_default_and_constant_tracks_cost_nothing():
    sk = chain()
    t = np.linspace(0, 1, 30)
    clip = Clip("still", 1.0, {"arm": {"translation": Track(t, np.tile([0, 1, 0], (30, 1))),
                                       "rotation": Track(t, np.tile(zrot(0.3), (30, 1)))}}, skeleton=sk)
    cc = compress_clip(clip, max_error=1e-4, virtual_distance=0.1)
    kinds = {tr.path: tr.kind for tr in cc.tracks}
    assert kinds == {"translation": "default", "rotation": "constant"}
    p = cc.decompress().sample(0.5)
    assert np.allclose(p.translation[1], [0, 1, 0]) and np.allclose(p.rotation[1], zrot(0.3), atol=1e-6)


@pytest.mark.parametrize("folder", ["CesiumMan", "Fox", "Girl", "RiggedFigure", "RiggedSimple", "SimpleSkin",
                                    "RobotExpressive"])
def test_real_clips_within_bound_and_smaller(folder, gltf_model):
    m = gltf_model(folder)
    max_err, vd = default_tolerances(m.skeleton)
    clip = next(iter(m.clips.values()))
    cc = compress_clip(clip, m.skeleton, max_error=max_err, virtual_distance=vd)
    assert cc.achieved_error <= max_err
    rows = compression_report([clip], m.skeleton, max_error=max_err, virtual_distance=vd)
    (row,) = rows
    assert row["bytes_after"] < row["bytes_before"] and row["ratio"] > 2
    assert row["keys_after"] <= row["keys_before"]
    assert len(cc.to_bytes()) == cc.nbytes
    # independent check at random times (not the compressor's evaluation grid)
    t = np.random.default_rng(0).uniform(0, clip.duration, 300)
    e, _ = clip_error(clip, cc.decompress(), m.skeleton, vd, t)
    assert e <= max_err * 1.05


def test_robot_weight_tracks_compressed(gltf_model):
    m = gltf_model("RobotExpressive")
    clip = m.clips["Wave"]
    cc = compress_clip(clip, max_error=1e-3, weight_tolerance=1e-3)
    lossy = cc.decompress()
    assert set(lossy.weight_tracks) == set(clip.weight_tracks)
    for t in np.linspace(0, clip.duration, 40):
        for key in clip.weight_tracks:
            assert np.allclose(lossy.sample_weights(t, key), clip.sample_weights(t, key), atol=1e-3)


def test_compressed_clip_retargets_like_the_original(gltf_model):
    m = gltf_model("Fox")
    src = m.skeleton
    tgt = Skeleton(src.names, src.parents, src.rest_translation * 2, src.rest_rotation, src.rest_scale,
                   src.inverse_bind)
    clip = m.clips["Walk"]
    lossy = compress_clip(clip).decompress()
    a = tgt.world_matrices(clip.sample(0.3, tgt))[:, :3, 3]
    b = tgt.world_matrices(lossy.sample(0.3, tgt))[:, :3, 3]
    assert np.abs(a - b).max() < 0.1


def test_clip_error_without_a_skeleton_is_a_clear_error():
    """Was an AttributeError on None (found by mypy); now a ValidationError, as compress_clip gives."""
    clip = Clip("c", 1.0, {"a": {"translation": Track(np.array([0.0, 1.0]), np.zeros((2, 3)))}})
    with pytest.raises(ValidationError, match="no skeleton"):
        clip_error(clip, clip)
