"""Skeleton: ordering, batched world matrices vs a naive recursion, skin matrices, bind checks."""

from __future__ import annotations

import numpy as np
import pytest

from piste.character import Pose, Skeleton
from piste.character.skeleton import bone_depths, depth_levels, topological_order, world_from_local
from piste.errors import ValidationError
from piste.transforms import compose_trs, invert_affine, quat_normalize


def random_tree(n, seed=0):
    rng = np.random.default_rng(seed)
    parents = np.array([-1] + [int(rng.integers(0, i)) for i in range(1, n)])
    t = rng.normal(size=(n, 3))
    r = quat_normalize(rng.normal(size=(n, 4)))
    s = rng.uniform(0.5, 1.5, size=(n, 3))
    return parents, t, r, s


def naive_world(parents, local):
    out = np.empty_like(local)
    for i in range(len(parents)):
        m, j = local[i], parents[i]
        while j >= 0:
            m = local[j] @ m
            j = parents[j]
        out[i] = m
    return out


def test_world_matrices_match_naive_recursion():
    parents, t, r, s = random_tree(40)
    sk = Skeleton([f"b{i}" for i in range(40)], parents, t, r, s, np.tile(np.eye(4), (40, 1, 1)))
    local = compose_trs(t, r, s)
    assert np.allclose(sk.local_matrices(sk.rest_pose()), local)
    assert np.allclose(sk.world_matrices(sk.rest_pose()), naive_world(parents, local), atol=1e-10)
    # batched poses through world_from_local
    both = world_from_local(np.stack([local, local]), parents)
    assert both.shape == (2, 40, 4, 4) and np.allclose(both[1], naive_world(parents, local), atol=1e-10)


def test_levels_and_depths():
    parents = np.array([-1, 0, 0, 1, 3, -1])
    assert list(bone_depths(parents)) == [0, 1, 1, 2, 3, 0]
    lv = depth_levels(parents)
    assert [list(x) for x in lv] == [[0, 5], [1, 2], [3], [4]]
    with pytest.raises(ValidationError):
        bone_depths([1, 0])


def test_ordered_reorders_parents_first_and_keeps_mapping():
    parents, t, r, s = random_tree(25, seed=3)
    perm = np.random.default_rng(1).permutation(25)
    inv = np.argsort(perm)
    sp = np.where(parents[perm] >= 0, inv[np.maximum(parents[perm], 0)], -1)  # shuffled hierarchy
    names = [f"b{i}" for i in perm]
    ibm = invert_affine(naive_world(parents, compose_trs(t, r, s)))
    with pytest.raises(ValidationError):
        Skeleton(names, sp, t[perm], r[perm], s[perm], ibm[perm])
    sk, order = Skeleton.ordered(names, sp, t[perm], r[perm], s[perm], ibm[perm], node_index=perm)
    assert np.all(sk.parents < np.arange(25))
    assert [names[i] for i in order] == sk.names
    w = sk.world_matrices()
    for k, name in enumerate(sk.names):
        orig = int(name[1:])
        assert np.allclose(w[k], naive_world(parents, compose_trs(t, r, s))[orig], atol=1e-10)
    # inverse binds are the inverse rest world: skin matrices at rest are identities
    assert np.allclose(sk.skin_matrices(sk.rest_pose()), np.eye(4), atol=1e-9)
    assert np.allclose(sk.bind_pose_world(), w, atol=1e-9)


def test_bone_index_and_rest_pose_copy():
    parents, t, r, s = random_tree(5)
    sk = Skeleton(list("abcde"), parents, t, r, s, np.tile(np.eye(4), (5, 1, 1)))
    assert sk.bone_index("c") == 2 and sk.get("zz") is None
    with pytest.raises(KeyError):
        sk.bone_index("zz")
    p = sk.rest_pose()
    p.translation[:] = 0
    assert np.allclose(sk.rest_translation, t)
    assert isinstance(p, Pose) and p.n_bones == 5
    with pytest.raises(ValidationError):
        Skeleton(list("aacde"), parents, t, r, s, np.tile(np.eye(4), (5, 1, 1)))


def test_skin_matrices_move_vertices_with_bones(gltf_model):
    """Rotating a bone by 90 degrees moves a vertex bound fully to it by that rotation about the
    bone's world position (CesiumMan)."""
    m = gltf_model("CesiumMan")
    sk = m.skeleton
    mesh = m.meshes[0]
    v = int(np.argmax(mesh.weights[:, 0]))
    b = int(mesh.joints[v, 0])
    assert mesh.weights[v, 0] == pytest.approx(1.0)
    pose = sk.rest_pose()
    extra = np.array([0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)])
    from piste.transforms import quat_multiply
    pose.rotation[b] = quat_multiply(pose.rotation[b], extra)
    s0 = sk.skin_matrices()
    s1 = sk.skin_matrices(pose)
    p0 = s0[b] @ np.r_[mesh.positions[v], 1]
    p1 = s1[b] @ np.r_[mesh.positions[v], 1]
    w = sk.world_matrices()[b]
    # distance to the bone's origin is preserved, the point moved
    assert np.linalg.norm(p0[:3] - w[:3, 3]) == pytest.approx(np.linalg.norm(p1[:3] - w[:3, 3]), rel=1e-6)
    # and equals rotating by the bone's world rotation delta
    rot = w[:3, :3] @ compose_trs([0, 0, 0], extra, [1, 1, 1])[:3, :3] @ np.linalg.inv(w[:3, :3])
    assert np.allclose(p1[:3] - w[:3, 3], rot @ (p0[:3] - w[:3, 3]), atol=1e-6)
