"""Skinning three ways: exact LBS (reference), SSX post-transform, SSX Tricky blended palette."""

from __future__ import annotations

import numpy as np
import pytest

from piste.character.model import Pose, Skeleton, SkinnedMesh
from piste.character.skinning import BlendedMesh, PostTransformMesh, skin, skin_exact
from piste.errors import ConfigError, ValidationError
from piste.transforms import quat_normalize

SKINNED = ["CesiumMan", "Fox", "Girl", "RiggedFigure", "RiggedSimple", "SimpleSkin", "RobotExpressive"]


def _tube(weights_mode="smooth"):
    """A tube along +Y with a 3-bone chain; returns (mesh, skeleton)."""
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    ys = np.linspace(0, 3, 25)
    Y, A = np.meshgrid(ys, ang, indexing="ij")
    pos = np.stack([0.2 * np.cos(A), Y, 0.2 * np.sin(A)], -1).reshape(-1, 3)
    nrm = np.stack([np.cos(A), 0 * A, np.sin(A)], -1).reshape(-1, 3)
    r, c = len(ys), len(ang)
    i = np.arange(r - 1)[:, None] * c
    j = np.arange(c)[None, :]
    a, b = i + j, i + (j + 1) % c
    idx = np.concatenate([np.stack([a, a + c, b], -1).reshape(-1, 3), np.stack([b, a + c, b + c], -1).reshape(-1, 3)])
    yb = np.array([0.0, 1.0, 2.0])
    if weights_mode == "smooth":
        w = np.maximum(0, 1 - np.abs(pos[:, 1:2] - (yb + 0.5)[None]) / 1.0) ** 2
    else:  # weights that are exact multiples of 0.25
        w = np.where(pos[:, 1:2] < 1.5, [[0.5, 0.25, 0.25]], [[0.25, 0.5, 0.25]])
    w /= w.sum(1, keepdims=True)
    joints = np.zeros((len(pos), 4), np.uint16)
    joints[:, :3] = [0, 1, 2]
    W = np.zeros((len(pos), 4))
    W[:, :3] = w
    mesh = SkinnedMesh("tube", pos, idx, normals=nrm, joints=joints, weights=W, skinned=True)
    ib = np.tile(np.eye(4), (3, 1, 1))
    ib[:, 1, 3] = -yb
    sk = Skeleton(["a", "b", "c"], [-1, 0, 1], [[0, 0, 0], [0, 1, 0], [0, 1, 0]], [[0, 0, 0, 1]] * 3, np.ones((3, 3)), ib)
    return mesh, sk


def _bent_pose(sk):
    pose = sk.rest_pose()
    pose.rotation[1] = quat_normalize(np.array([0, 0, np.sin(0.5), np.cos(0.5)]))
    pose.rotation[2] = quat_normalize(np.array([np.sin(0.3), 0, 0, np.cos(0.3)]))
    pose.scale[2] = [1.0, 1.5, 1.0]  # non-uniform scale: normals need the inverse-transpose
    return pose


def _angle_deg(a, b):
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1)))


@pytest.mark.parametrize("name", SKINNED)
def test_exact_rest_pose_reproduces_bind_positions(gltf_model, name):
    from piste.transforms import decompose_trs

    model = gltf_model(name)
    sk = model.skeleton
    # the bind pose as local TRS: local_i = inverse(bind_world[parent]) @ bind_world[i]
    bind = np.linalg.inv(sk.inverse_bind)
    parent = np.where(sk.parents[:, None, None] >= 0, bind[np.maximum(sk.parents, 0)], np.eye(4))
    t, r, s = decompose_trs(np.linalg.inv(parent) @ bind)
    pose = Pose(t, r, s)
    mats = sk.skin_matrices(pose)
    for mesh in model.meshes:
        if not mesh.skinned:
            continue
        p, n = skin_exact(mesh, mats)
        size = float(np.ptp(mesh.positions, axis=0).max())
        assert np.abs(p - mesh.positions).max() <= 1e-5 * size
        assert _angle_deg(n, mesh.normals).max() < 0.01


def test_all_schemes_agree_at_rest_and_post_transform_positions_are_exact():
    mesh, sk = _tube()
    rest = sk.skin_matrices(sk.rest_pose())
    for scheme in ("exact", "post_transform", "blended"):
        p, n = skin(mesh, rest, scheme, inverse_bind=sk.inverse_bind)
        assert np.abs(p - mesh.positions).max() < 1e-5
        assert _angle_deg(n, mesh.normals).max() < 0.01
    mats = sk.skin_matrices(_bent_pose(sk))
    pe, ne = skin(mesh, mats, "exact")
    pp, npt = skin(mesh, mats, "post_transform", inverse_bind=sk.inverse_bind)
    assert np.abs(pp - pe).max() < 1e-5
    # identity bone spaces: same arithmetic, same result
    pi, ni = skin(mesh, mats, "post_transform")
    assert np.abs(pi - pe).max() < 1e-5 and _angle_deg(ni, npt).max() < 0.01


def test_exact_normals_use_inverse_transpose():
    mesh, sk = _tube()
    mats = sk.skin_matrices(_bent_pose(sk))
    p, n = skin_exact(mesh, mats)
    # normals stay perpendicular to skinned surface tangents along the ring
    ring = 12
    v = np.arange(ring) + 24 * ring - ring  # the last ring, driven by the scaled bone only
    tang = p[v[(np.arange(ring) + 1) % ring]] - p[v[(np.arange(ring) - 1) % ring]]
    assert np.abs(np.sum(tang * n[v], axis=1) / np.linalg.norm(tang, axis=1)).max() < 1e-3
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-5)


def test_post_transform_normals_follow_the_dominant_bone():
    mesh, sk = _tube()
    mats = sk.skin_matrices(_bent_pose(sk))
    pt = PostTransformMesh.build(mesh, sk.inverse_bind)
    p, n = pt.apply(mats)
    dom = pt.bones[:, 0]
    ref = np.einsum("vij,vj->vi", pt.bone_matrices(mats)[dom][:, :, :3], pt.bone_normals)
    ref /= np.linalg.norm(ref, axis=1, keepdims=True)
    assert _angle_deg(n, ref).max() < 0.01
    assert pt.bone_positions.shape == (mesh.n_vertices, 4, 3)


def test_blended_is_exact_when_weights_are_already_quantized():
    mesh, sk = _tube("quantized")
    mats = sk.skin_matrices(_bent_pose(sk))
    pe, _ = skin(mesh, mats, "exact")
    pb, nb = skin(mesh, mats, "blended", step=0.25, max_bones=3)
    assert np.abs(pb - pe).max() < 1e-5
    assert np.allclose(np.linalg.norm(nb, axis=1), 1.0, atol=1e-5)


def test_sparse_and_gather_paths_agree():
    mesh, sk = _tube()
    mats = sk.skin_matrices(_bent_pose(sk))
    a = BlendedMesh.build(mesh, 0.1, 3, use_sparse=True).apply(mats)
    b = BlendedMesh.build(mesh, 0.1, 3, use_sparse=False).apply(mats)
    assert np.abs(a[0] - b[0]).max() < 1e-5 and np.abs(a[1] - b[1]).max() < 1e-5


# stated bounds (max position error as a fraction of the posed height, mean, max normal error)
BOUNDS = {
    "CesiumMan": {0.1: (0.016, 0.001, 25.0), 0.2: (0.027, 0.0015, 25.0), 0.25: (0.036, 0.0015, 25.0)},
    "rider": {0.1: (0.004, 0.0003, 8.0), 0.2: (0.005, 0.0003, 8.0), 0.25: (0.006, 0.0004, 9.0)},
}


def _errors(model, step, times):
    sk = model.skeleton
    clip = next(iter(model.clips.values()))
    out = []
    for t in times:
        mats = sk.skin_matrices(clip.sample(t, loop=True))
        for mesh in model.meshes:
            pe, ne = skin(mesh, mats, "exact")
            pb, nb = skin(mesh, mats, "blended", step=step, max_bones=3)
            size = float(np.ptp(pe, axis=0).max())
            out.append((np.linalg.norm(pb - pe, axis=1) / size, _angle_deg(nb, ne)))
    return np.concatenate([o[0] for o in out]), np.concatenate([o[1] for o in out])


@pytest.mark.parametrize("step", [0.1, 0.2, 0.25])
def test_blended_error_within_stated_bounds(gltf_model, rider_model, step):
    for name, model in (("CesiumMan", gltf_model("CesiumMan")), ("rider", rider_model)):
        dist, ang = _errors(model, step, [0.3, 0.9])
        max_b, mean_b, ang_b = BOUNDS[name][step]
        assert dist.max() < max_b, (name, step, dist.max())
        assert dist.mean() < mean_b, (name, step, dist.mean())
        assert ang.max() < ang_b, (name, step, ang.max())


def test_coarser_steps_need_fewer_matrices_and_err_more(gltf_model):
    from piste.character.palette import palette

    mesh = gltf_model("CesiumMan").meshes[0]
    sizes = [palette(mesh, s, 3).size for s in (0.1, 0.2, 0.25)]
    assert sizes[0] > sizes[1] > sizes[2]


def test_skin_errors():
    mesh, sk = _tube()
    mats = sk.skin_matrices(sk.rest_pose())
    with pytest.raises(ConfigError):
        skin(mesh, mats, "dual_quaternion")
    with pytest.raises(ValidationError):
        skin(mesh, mats[:2], "blended")
    with pytest.raises(ValidationError):
        skin(mesh, np.zeros((3, 3, 3)), "exact")


@pytest.fixture(scope="module")
def rider_model():
    from piste.character.rider import default_rider

    return default_rider()


def test_apply_many_matches_apply(rider_model):
    sk = rider_model.skeleton
    mesh = rider_model.meshes[0]
    poses = [rider_model.clips[n].sample(0.4, loop=True) for n in ("ride", "grab", "spin")]
    mats = np.stack([sk.skin_matrices(p) for p in poses])
    for sparse in (True, False):
        bm = BlendedMesh.build(mesh, 0.25, 3, use_sparse=sparse)
        pos, nrm = bm.apply_many(mats)
        assert pos.shape == (3, mesh.n_vertices, 3)
        for i in range(3):
            p, n = bm.apply(mats[i])
            assert np.abs(pos[i] - p).max() < 1e-5 and np.abs(nrm[i] - n).max() < 1e-5


def test_skinning_report(gltf_model):
    from piste.character.skinning import skinning_report

    rows = skinning_report(gltf_model("CesiumMan"), times=[0.5])
    assert [r["palette"] for r in rows] == [269, 130, 94]
    assert all(r["post_pos_max"] < 1e-5 and 0 < r["pos_max"] < 0.04 for r in rows)
    assert skinning_report(gltf_model("AnimatedMorphCube")) == []


def test_post_transform_checks_matrix_count():
    mesh, sk = _tube()
    mats = sk.skin_matrices(sk.rest_pose())
    with pytest.raises(ValidationError):
        skin(mesh, mats[:2], "post_transform", inverse_bind=sk.inverse_bind)
