"""Batched quaternion / matrix helpers against scipy's Rotation (independent reference)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from piste.transforms import (compose_trs, decompose_trs, invert_affine, matrix_to_quat, quat_angle,
                              quat_conjugate, quat_identity, quat_multiply, quat_nlerp, quat_normalize,
                              quat_rotate, quat_slerp, quat_to_matrix, transform_points, transform_vectors,
                              translation_matrix)

rng = np.random.default_rng(0)


def rand_quats(n):
    return quat_normalize(rng.normal(size=(n, 4)))


def test_identity_and_normalize():
    assert np.array_equal(quat_identity(), [0, 0, 0, 1])
    assert quat_identity((2, 3)).shape == (2, 3, 4)
    assert np.allclose(quat_normalize([[0, 0, 0, 0], [0, 0, 0, 2]]), [[0, 0, 0, 1], [0, 0, 0, 1]])


def test_matrix_matches_scipy():
    q = rand_quats(200)
    assert np.allclose(quat_to_matrix(q), Rotation.from_quat(q).as_matrix(), atol=1e-12)
    m = Rotation.from_quat(q).as_matrix()
    back = matrix_to_quat(m)
    assert np.allclose(np.abs(np.sum(back * q, axis=1)), 1.0, atol=1e-9)


def test_matrix_to_quat_all_branches():
    # 180-degree rotations about each axis exercise the x / y / z branches
    for axis in np.eye(3):
        r = Rotation.from_rotvec(axis * np.pi)
        q = matrix_to_quat(r.as_matrix())
        assert np.allclose(quat_to_matrix(q), r.as_matrix(), atol=1e-12)


def test_multiply_rotate_conjugate():
    a, b = rand_quats(50), rand_quats(50)
    ref = (Rotation.from_quat(a) * Rotation.from_quat(b)).as_matrix()
    assert np.allclose(quat_to_matrix(quat_multiply(a, b)), ref, atol=1e-12)
    v = rng.normal(size=(50, 3))
    assert np.allclose(quat_rotate(a, v), Rotation.from_quat(a).apply(v), atol=1e-12)
    assert np.allclose(quat_multiply(a, quat_conjugate(a)), [0, 0, 0, 1], atol=1e-12)
    assert np.allclose(quat_angle(a, a), 0, atol=1e-6)


@settings(max_examples=40, deadline=None)
@given(st.floats(0, 1), st.integers(0, 2 ** 31))
def test_slerp_constant_speed_shortest_arc(t, seed):
    r = np.random.default_rng(seed)
    a, b = quat_normalize(r.normal(size=(2, 4)))
    q = quat_slerp(a, b, t)
    total = quat_angle(a, b)
    assert np.isclose(np.linalg.norm(q), 1.0)
    assert np.isclose(quat_angle(a, q), t * total, atol=1e-6)
    assert np.isclose(quat_angle(q, b), (1 - t) * total, atol=1e-6)
    n = quat_nlerp(a, b, t)
    assert quat_angle(a, n) <= total + 1e-9


def test_slerp_endpoints_and_parallel():
    a, b = rand_quats(2)
    assert np.allclose(quat_slerp(a, b, 0.0), a)
    assert np.allclose(np.abs(quat_slerp(a, b, 1.0) @ b), 1.0)
    assert np.allclose(quat_slerp(a, a, 0.3), a)
    assert np.allclose(quat_slerp(a, -a, 0.3) @ a, 1.0) or np.allclose(quat_slerp(a, -a, 0.3) @ a, -1.0)


def test_trs_roundtrip_and_inverse():
    t = rng.normal(size=(30, 3))
    q = rand_quats(30)
    s = rng.uniform(0.5, 2, size=(30, 3))
    m = compose_trs(t, q, s)
    t2, q2, s2 = decompose_trs(m)
    assert np.allclose(t2, t) and np.allclose(s2, s)
    assert np.allclose(np.abs(np.sum(q2 * q, axis=1)), 1.0)
    assert np.allclose(invert_affine(m) @ m, np.eye(4), atol=1e-10)
    p = rng.normal(size=(30, 3))
    assert np.allclose(transform_points(m[0], p), (m[0] @ np.c_[p, np.ones(30)].T).T[:, :3])
    assert np.allclose(transform_points(m, p), np.einsum("nij,nj->ni", m, np.c_[p, np.ones(30)])[:, :3])
    assert np.allclose(transform_vectors(m[0], p), p @ m[0, :3, :3].T)
    assert np.allclose(translation_matrix([1, 2, 3])[:3, 3], [1, 2, 3])


def test_decompose_negative_scale():
    m = compose_trs([0, 0, 0], [0, 0, 0, 1], [-2, 1, 1])
    t, q, s = decompose_trs(m)
    assert np.allclose(compose_trs(t, q, s), m)


@pytest.mark.parametrize("forward, up", [((0.3, -1.0, 0.2), (0, 1, 0)), ((0, 0, -1), (0, 1, 0)), ((0, 1, 0), (0, 1, 0)),
                                         ((1, 0, 0), (1, 0, 0))])
def test_look_rotation_points_minus_z_along_forward_and_y_towards_up(forward, up):
    from piste.transforms import look_rotation, quat_to_matrix

    m = quat_to_matrix(np.array(look_rotation(forward, up, fallback=(0.0, 0.0, 1.0))))
    f = np.asarray(forward, float) / np.linalg.norm(forward)
    np.testing.assert_allclose(-m[:3, 2], f, atol=1e-12)
    np.testing.assert_allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-12)
    if np.linalg.norm(np.cross(f, up)) > 1e-6:  # +Y leans towards up, in the plane of forward and up
        assert m[:3, 1] @ np.asarray(up, float) > 0 and abs(np.cross(f, up) @ m[:3, 1]) < 1e-12
