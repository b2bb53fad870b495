"""Retargeting clips between rigs with different bone names: explicit and built-in bone maps, and
the warning when a clip drives fewer than half of a skeleton's bones."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from piste.character import default_rider
from piste.character.retarget import (
    MIXAMO,
    RetargetWarning,
    bone_roles,
    builtin_bone_map,
    check_coverage,
    coverage,
    retarget_clip,
)
from piste.errors import ConfigError
from piste.formats.gltf import load_gltf

DATA = Path("/work/shared/data/gltf")
if not DATA.is_dir():
    DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "gltf"


def _renamed(model, names):
    """A copy of a model whose skeleton's bones and clip tracks are renamed ``old -> names[old]``."""
    from dataclasses import replace

    sk = model.skeleton
    new = [names.get(n, n) for n in sk.names]
    sk2 = type(sk)(new, sk.parents, sk.rest_translation, sk.rest_rotation, sk.rest_scale, sk.inverse_bind,
                   sk.node_index, sk.is_joint)
    clips = {k: replace(c, tracks={names.get(b, b): t for b, t in c.tracks.items()}, skeleton=sk2)
             for k, c in model.clips.items()}
    return replace(model, skeleton=sk2, clips=clips)


@pytest.fixture(scope="module")
def fox_and_cesium():
    return load_gltf(DATA / "Fox" / "Fox.glb"), load_gltf(DATA / "CesiumMan" / "CesiumMan.glb")


def test_fox_run_on_cesiumman_warns_naming_bones(fox_and_cesium):
    fox, cm = fox_and_cesium
    with pytest.warns(RetargetWarning, match=r"drives 0 of the skeleton's \d+ bones; unmatched: node\d+"):
        pose = fox.clips["Run"].sample(0.3, cm.skeleton)
    assert np.allclose(pose.rotation, cm.skeleton.rest_rotation)  # what the warning is about


def test_builtin_map_fox_to_cesiumman(fox_and_cesium):
    fox, cm = fox_and_cesium
    m = builtin_bone_map(fox.skeleton, cm.skeleton)
    assert len(m) >= 19 and len(set(m.values())) == len(m)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RetargetWarning)
        clip = retarget_clip(fox.clips["Run"], cm.skeleton)
        driven, unmatched = coverage(clip, cm.skeleton)
        assert len(driven) >= 0.85 * (len(driven) + len(unmatched))  # the fox's toes are not animated
        pose = clip.sample(0.3, cm.skeleton, loop=True)
    moved = np.abs(pose.rotation - cm.skeleton.rest_rotation).max(axis=1) > 1e-3
    assert moved.sum() >= 10
    # left stays left: the fox's left thigh drives the bone CesiumMan's geometry calls left
    assert bone_roles(cm.skeleton)[m["b_LeftLeg01_015"]] == "thigh_l"


def test_structure_alone_labels_the_rider_like_its_names():
    """The CesiumMan path (bones named node<i>): hierarchy + rest geometry give the same roles as
    the default rider's own names."""
    rider = default_rider(0)
    by_name = bone_roles(rider.skeleton)
    anon = _renamed(rider, {n: f"node{i}" for i, n in enumerate(rider.skeleton.names)})
    by_structure = bone_roles(anon.skeleton)
    idx = {f"node{i}": n for i, n in enumerate(rider.skeleton.names)}
    got = {idx[k]: v for k, v in by_structure.items()}
    core = ("pelvis", "neck", "head", "thigh_l", "shin_l", "foot_l", "toe_l", "thigh_r", "shin_r", "foot_r", "toe_r",
            "upperarm_l", "lowerarm_l", "hand_l", "upperarm_r", "lowerarm_r", "hand_r", "spine1", "spine3")
    for bone, role in by_name.items():
        if role in core:
            assert got.get(bone) == role, (bone, role, got.get(bone))


def test_mixamo_names_play_the_riders_clip_exactly():
    rider = default_rider(0)
    inv = {v: "mixamorig:" + k for k, v in MIXAMO.items()}
    mix = _renamed(rider, inv)
    m = builtin_bone_map(mix.skeleton, rider.skeleton)
    assert all(m[inv[r]] == r for r in inv if r in rider.skeleton.names)
    clip = retarget_clip(mix.clips["ride"], rider.skeleton)
    for t in (0.0, 0.4, 0.9):
        a = rider.clips["ride"].sample(t, rider.skeleton)
        b = clip.sample(t, rider.skeleton, retarget="none")
        assert np.allclose(a.rotation, b.rotation) and np.allclose(a.translation, b.translation)


def test_explicit_map_and_errors(fox_and_cesium):
    fox, cm = fox_and_cesium
    m = {"b_Hip_01": "node2", "b_Spine01_02": "node11"}
    with pytest.warns(RetargetWarning, match="drives 2 of"):
        clip = retarget_clip(fox.clips["Run"], cm.skeleton, bone_map=m)
    assert set(clip.tracks) == {"node2", "node11"}
    assert clip.skeleton.get("node2") is not None and clip.skeleton.get("b_Hip_01") is None
    with pytest.raises(ConfigError, match="no bone 'hips' in the clip's skeleton"):
        retarget_clip(fox.clips["Run"], cm.skeleton, bone_map={"hips": "node2"})
    with pytest.raises(ConfigError, match="no bone 'nodeX' in the target"):
        retarget_clip(fox.clips["Run"], cm.skeleton, bone_map={"b_Hip_01": "nodeX"})
    with pytest.raises(ConfigError, match="both map to 'node2'"):
        retarget_clip(fox.clips["Run"], cm.skeleton, bone_map={"b_Hip_01": "node2", "b_Spine01_02": "node2"})
    with pytest.raises(ConfigError, match="'builtin' or a table"):
        retarget_clip(fox.clips["Run"], cm.skeleton, bone_map="guess")


def test_own_skeleton_never_warns():
    rider = default_rider(0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RetargetWarning)
        rider.clips["spin"].sample(0.2)
        assert check_coverage(rider.clips["spin"], rider.skeleton)


def test_baked_relative_equals_sampled_relative(fox_and_cesium):
    """mode="relative" bakes the rule into the keys: sampling the baked clip with no retargeting
    gives the pose Clip.sample computes with retarget="relative" from the renamed clip."""
    fox, cm = fox_and_cesium
    renamed = retarget_clip(fox.clips["Run"], cm.skeleton, warn=False)
    baked = retarget_clip(fox.clips["Run"], cm.skeleton, warn=False, mode="relative")
    assert baked.skeleton is cm.skeleton
    for t in (0.1, 0.37, 0.6):
        a = renamed.sample(t, cm.skeleton, retarget="relative")
        b = baked.sample(t, cm.skeleton)
        dots = np.abs((a.rotation * b.rotation).sum(1))
        assert np.allclose(dots, 1.0, atol=1e-9) and np.allclose(a.translation, b.translation, atol=1e-9)


def _scene(folder, rider_extra):
    import shutil

    shutil.copy(DATA / "Fox" / "Fox.glb", folder / "Fox.glb")
    n, spacing = 17, 4.0
    y, x = np.mgrid[0:n, 0:n] * spacing
    np.savez(folder / "hill.npz", z=30.0 - 0.3 * y, dx=np.float64(spacing))
    p = folder / "s.toml"
    p.write_text(f"""name = "fox run"
[terrain]
source = "hill.npz"
[lightmap]
res = 8
[visibility]
enabled = false
[[riders]]
name = "runner"
position = [30.0, 30.0]
{rider_extra}
[[cameras]]
name = "main"
eye = [30.0, 10.0, 30.0]
target = [30.0, 30.0, 20.0]
""")
    return p


def test_scene_file_clips_from_with_bone_map(tmp_path):
    """A scene's rider plays the Fox's Run on the default rider through the built-in map (and an
    explicit table); bad bone_map values name the key."""
    from piste.pipeline.build import build_scene
    from piste.pipeline.bundle_objects import load_bundle
    from piste.world.scene_file import SceneError, load_scene

    p = _scene(tmp_path, 'clip = "Run"\nclips_from = "Fox.glb"\nbone_map = "builtin"')
    with warnings.catch_warnings():
        warnings.simplefilter("error", RetargetWarning)
        b = load_bundle(build_scene(load_scene(p), out=tmp_path / "s.piste").path)
    m = b.rider_model()
    assert "Run" in m.clips and {"ride", "spin"} <= set(m.clips)
    pose = m.clips["Run"].sample(0.3, m.skeleton, loop=True)
    moved = np.abs(np.abs((pose.rotation * m.skeleton.rest_rotation).sum(1)) - 1) > 1e-4
    assert moved.sum() >= 8
    # an explicit table: only those bones move
    d2 = tmp_path / "explicit"
    d2.mkdir()
    p2 = _scene(d2, 'clip = "Run"\nclips_from = "Fox.glb"\nbone_map = { b_Spine01_02 = "spine1", b_Neck_04 = "neck" }')
    with pytest.warns(RetargetWarning, match="drives 2 of"):
        b2 = load_bundle(build_scene(load_scene(p2), out=d2 / "s.piste").path)
    m2 = b2.rider_model()
    pose = m2.clips["Run"].sample(0.3, m2.skeleton, loop=True)
    moved = np.abs(np.abs((pose.rotation * m2.skeleton.rest_rotation).sum(1)) - 1) > 1e-6
    assert {m2.skeleton.names[i] for i in np.flatnonzero(moved)} <= {"spine1", "neck"} and moved.any()
    for extra, match in (('clips_from = "Fox.glb"\nbone_map = 3', "riders\\[0\\].bone_map"),
                         ('bone_map = "builtin"', "needs clips_from"),
                         ('clips_from = "nope.glb"', "no such file")):
        d3 = tmp_path / f"bad{len(extra)}"
        d3.mkdir()
        with pytest.raises(SceneError, match=match):
            load_scene(_scene(d3, extra))


@pytest.mark.parametrize("mode", [None, "relative", "scaled", "world"])
def test_partial_retarget_leaves_unmatched_bones_at_rest(mode):
    """A clip retargeted onto a rig that shares only some bones (the rest renamed, a 'monster'):
    every target bone without a mapped track samples exactly its rest pose, at every time and in
    every mode, and the driven bones move."""
    src = default_rider(0)
    limbs = ("clavicle", "arm", "hand", "shin", "foot", "toe")
    monster = _renamed(src, {n: "tentacle_" + n for n in src.skeleton.names if any(k in n for k in limbs)})
    sk = monster.skeleton
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RetargetWarning)
        clip = retarget_clip(src.clips["grab"], sk, "builtin", source=src.skeleton, warn=False, mode=mode)
        rest = sk.rest_pose()
        undriven = [j for j, n in enumerate(sk.names) if n not in clip.tracks]
        driven = [j for j, n in enumerate(sk.names) if n in clip.tracks]
        assert len(undriven) >= 12 and driven and not any(sk.names[j].startswith("tentacle_") for j in driven)
        moved = 0.0
        for t in np.linspace(0.0, clip.duration, 9):
            pose = clip.sample(float(t), skeleton=sk)
            np.testing.assert_array_equal(pose.translation[undriven], rest.translation[undriven])
            np.testing.assert_array_equal(pose.rotation[undriven], rest.rotation[undriven])
            np.testing.assert_array_equal(pose.scale[undriven], rest.scale[undriven])
            assert np.isfinite(pose.translation).all() and np.isfinite(pose.rotation).all()
            moved = max(moved, float(np.abs(pose.rotation[driven] - rest.rotation[driven]).max()))
    assert moved > 0.05


def test_world_mode_follows_the_source_on_a_rig_with_other_bone_frames():
    """The same joints with every bone's local frame turned (as an SSX Tricky rig's are against
    the default rider's): ``mode="world"`` moves every joint exactly as the source moves it, at
    every key; the local-delta ``relative`` rule does not."""
    from piste.character.model import Skeleton
    from piste.transforms import compose_trs, matrix_to_quat, quat_multiply, quat_conjugate, quat_rotate

    src = default_rider(0)
    sk = src.skeleton
    rng = np.random.default_rng(3)
    q = rng.normal(size=(sk.n_bones, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)  # each bone's frame turn
    par = sk.parents
    qp = np.where(par[:, None] >= 0, q[np.maximum(par, 0)], [0.0, 0.0, 0.0, 1.0])
    rot = quat_multiply(quat_conjugate(qp), quat_multiply(sk.rest_rotation, q))
    trans = quat_rotate(quat_conjugate(qp), sk.rest_translation)
    world = np.zeros((sk.n_bones, 4, 4))
    local = compose_trs(trans, rot, np.ones((sk.n_bones, 3)))
    for j, p in enumerate(par):
        world[j] = local[j] if p < 0 else world[p] @ local[j]
    other = Skeleton(sk.names, par, trans, rot, np.ones((sk.n_bones, 3)), np.linalg.inv(world))
    assert not np.allclose(matrix_to_quat(world[:, :3, :3])[2], sk.rest_rotation[2])

    def joints(skel, pose):
        return (skel.skin_matrices(pose) @ np.linalg.inv(skel.inverse_bind))[:, :3, 3]

    np.testing.assert_allclose(joints(other, None), joints(sk, None), atol=1e-9)
    for name in ("ride", "spin"):
        c = src.clips[name]
        w = retarget_clip(c, other, "builtin", source=sk, warn=False, mode="world")
        r = retarget_clip(c, other, "builtin", source=sk, warn=False, mode="relative")
        keys = np.unique(np.concatenate([tr.times for bt in c.tracks.values() for tr in bt.values()]))
        worst_rel = 0.0
        for t in keys:
            want = joints(sk, c.sample(float(t), skeleton=sk))
            np.testing.assert_allclose(joints(other, w.sample(float(t), skeleton=other)), want, atol=1e-6)
            worst_rel = max(worst_rel, float(np.abs(joints(other, r.sample(float(t), skeleton=other)) - want).max()))
        assert worst_rel > 0.05, name
