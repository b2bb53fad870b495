"""Morph targets: blending (vs a naive loop) and the null-bone alternative (error, memory, cost)."""

from __future__ import annotations

import numpy as np
import pytest

from piste.character import SkinnedMesh, blend_morphs
from piste.character.morph import morph_report, morphs_to_null_bones, vertex_normals
from piste.errors import ValidationError


def naive_blend(mesh, w):
    p = mesh.positions.astype(np.float64).copy()
    n = mesh.normals.astype(np.float64).copy()
    for k in range(mesh.n_morphs):
        p += w[k] * mesh.morph_positions[k]
        n += w[k] * mesh.morph_normals[k]
    return p, n / np.linalg.norm(n, axis=1, keepdims=True)


MORPH_MODELS = ["RobotExpressive", "AnimatedMorphCube", "SimpleMorph", "MorphPrimitivesTest"]


@pytest.mark.parametrize("folder", MORPH_MODELS)
def test_blend_matches_naive(folder, gltf_model):
    m = gltf_model(folder)
    rng = np.random.default_rng(0)
    for mesh in [x for x in m.meshes if x.n_morphs]:
        for w in [np.zeros(mesh.n_morphs), np.eye(mesh.n_morphs)[0], rng.uniform(0, 1, mesh.n_morphs)]:
            p, n = blend_morphs(mesh, w)
            rp, rn = naive_blend(mesh, w)
            assert p.dtype == np.float32 and p.shape == (mesh.n_vertices, 3)
            assert np.allclose(p, rp, atol=1e-5)
            assert np.allclose(n, rn, atol=1e-4)
            assert np.allclose(np.linalg.norm(n, axis=1), 1, atol=1e-5)


def test_simple_morph_exact_targets(gltf_model):
    mesh = gltf_model("SimpleMorph").meshes[0]
    p, _ = blend_morphs(mesh, [1.0, 0.0])
    assert np.allclose(p - mesh.positions, mesh.morph_positions[0])
    p, _ = blend_morphs(mesh, mesh.morph_default_weights)
    assert np.allclose(p - mesh.positions, 0.5 * mesh.morph_positions.sum(0))
    with pytest.raises(ValidationError):
        blend_morphs(mesh, [1.0])


def test_animated_weights_drive_the_cube(gltf_model):
    m = gltf_model("AnimatedMorphCube")
    mesh = m.meshes[0]
    clip = m.clips["Square"]
    moved = []
    for t in np.linspace(0, clip.duration, 20):
        p, _ = blend_morphs(mesh, clip.sample_weights(t, mesh))
        moved.append(np.abs(p - mesh.positions).max())
    assert max(moved) > min(moved) + 0.1


def test_vertex_normals_of_a_quad():
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    n = vertex_normals(p, [[0, 1, 2], [0, 2, 3]])
    assert np.allclose(n, [0, 0, 1])


@pytest.mark.parametrize("folder, n_bones", [("AnimatedMorphCube", 2), ("SimpleMorph", 1),
                                             ("MorphPrimitivesTest", 4)])
def test_null_bones_exact_for_simple_morph_sets(folder, n_bones, gltf_model):
    for mesh in [x for x in gltf_model(folder).meshes if x.n_morphs]:
        rig = morphs_to_null_bones(mesh, n_bones)
        r = morph_report(mesh, rig, n_samples=8, timing_repeats=2)
        assert r["max_error"] < 1e-5


def test_null_bones_robot_face(gltf_model):
    m = gltf_model("RobotExpressive")
    face = next(x for x in m.meshes if x.n_morphs and np.any(x.morph_positions))
    assert face.morph_names == ["Angry", "Surprised", "Sad"]
    errs = {}
    for J in (4, 32):
        rig = morphs_to_null_bones(face, J, max_influences=2, seed=0)
        assert np.all(rig.weights >= 0) and np.all(rig.weights.sum(1) <= 1 + 1e-6)
        assert rig.joints.max() < rig.n_bones
        r = morph_report(face, rig, n_samples=16, timing_repeats=2)
        errs[J] = r["max_error"]
        assert r["bytes_null_bones"] < r["bytes_morph_dense"]
        assert r["flops_null_bones"] < r["flops_morph"]
        assert r["normal_error_deg"] >= 0
    assert errs[32] <= errs[4]
    assert errs[32] < 0.1 * r["max_displacement"]
    # deterministic
    a = morphs_to_null_bones(face, 8, seed=3)
    b = morphs_to_null_bones(face, 8, seed=3)
    assert np.array_equal(a.offsets, b.offsets)


def test_null_bones_translation_api():
    # two vertices moved by one target in the same direction, different amounts
    p = np.zeros((3, 3), np.float32)
    d = np.array([[[1, 0, 0], [0.5, 0, 0], [0, 0, 0]]], np.float32)
    mesh = SkinnedMesh("m", p, [[0, 1, 2]], morph_positions=d)
    rig = morphs_to_null_bones(mesh, 1)
    assert list(rig.vertices) == [0, 1]
    assert np.allclose(rig.apply(mesh, [0.4]), blend_morphs(mesh, [0.4])[0], atol=1e-6)
    assert rig.bone_translations([1.0]).shape == (1, 3)
    with pytest.raises(ValidationError):
        morphs_to_null_bones(SkinnedMesh("n", p, [[0, 1, 2]]), 2)
