"""World objects: procedural meshes, compressed vertex formats, object matrices, placement, lighting."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from piste.errors import ConfigError
from piste.world.objects import (
    NORMAL_ERROR_DEG,
    OBJECT_KINDS,
    ObjectMesh,
    compress_mesh,
    make_mesh,
    normal_matrix,
    oct_decode,
    oct_encode,
    transform_mesh,
)


def _angle_deg(a, b):
    """Angle between rows in degrees (atan2: accurate for tiny angles, unlike arccos)."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    b = b / np.linalg.norm(b, axis=1, keepdims=True)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), (a * b).sum(1)))


@pytest.mark.parametrize("kind", OBJECT_KINDS)
def test_meshes_are_deterministic_and_closed_form(kind):
    a, b = make_mesh(kind), make_mesh(kind)
    np.testing.assert_array_equal(a.positions, b.positions)
    np.testing.assert_array_equal(a.indices, b.indices)
    assert a.n_triangles > 10 and a.indices.max() < a.n_vertices
    np.testing.assert_allclose(np.linalg.norm(a.normals, axis=1), 1.0, atol=1e-5)
    assert (a.uv >= 0).all() and (a.uv <= 1).all()
    assert a.positions[:, 2].min() >= -1e-6  # base at z = 0, standing up


@pytest.mark.parametrize("kind", OBJECT_KINDS)
@pytest.mark.parametrize("bits", [8, 16])
def test_compressed_round_trip_within_stated_error(kind, bits):
    m = make_mesh(kind)
    c = compress_mesh(m, normal_bits=bits)
    assert c.positions.dtype == np.uint16 and c.uv.dtype == np.uint16
    assert c.normals.dtype == (np.int8 if bits == 8 else np.int16)
    p, n, t = c.decode()
    # positions: <= extent / 65535 / 2 per axis (plus float32 rounding of the decode)
    tol_p = c.position_error * (1 + 1e-3) + 4 * np.finfo(np.float32).eps * np.abs(m.positions).max(0)
    assert (np.abs(p - m.positions) <= tol_p).all()
    tol_t = c.uv_error * (1 + 1e-3) + 4 * np.finfo(np.float32).eps
    assert (np.abs(t - m.uv) <= tol_t).all()
    assert _angle_deg(n.astype(np.float64), m.normals.astype(np.float64)).max() <= NORMAL_ERROR_DEG[bits] + 1e-3
    assert c.nbytes < c.uncompressed_nbytes(m.n_vertices, m.n_triangles) / 2


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.sampled_from([8, 16]))
def test_octahedral_normals_within_stated_angle(seed, bits):
    rng = np.random.default_rng(seed)
    n = rng.normal(size=(2000, 3))
    n[:10] = np.eye(3).repeat(4, 0)[:10] * np.array([[1], [-1]] * 5)  # axes, both signs
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = oct_decode(oct_encode(n, bits), bits)
    assert _angle_deg(d, n).max() <= NORMAL_ERROR_DEG[bits]


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_position_round_trip_random_meshes(seed):
    rng = np.random.default_rng(seed)
    scale = 10.0 ** rng.uniform(-2, 3)
    p = rng.normal(size=(50, 3)) * scale + rng.uniform(-1e3, 1e3, 3)
    n = rng.normal(size=(50, 3))
    m = ObjectMesh("r", p, n / np.linalg.norm(n, axis=1, keepdims=True), rng.uniform(0, 1, (50, 2)), [[0, 1, 2]])
    c = compress_mesh(m)
    q, _, _ = c.decode()
    tol = c.position_error * 1.001 + 8 * np.finfo(np.float32).eps * np.abs(m.positions).max(0)
    assert (np.abs(q - m.positions) <= tol).all()


def test_normals_under_non_uniform_scale_match_analytic():
    """A unit sphere under diag(a, b, c) is an ellipsoid whose normal at (a x, b y, c z) is
    proportional to (x / a, y / b, z / c)."""
    rng = np.random.default_rng(0)
    n = rng.normal(size=(300, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    a, b, c = 3.0, 0.5, 1.7
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    m = np.eye(4)
    m[:3, :3] = rot @ np.diag([a, b, c])
    m[:3, 3] = (5.0, -2.0, 1.0)
    wp, wn = transform_mesh(n, n, m)
    want = (n / np.array([a, b, c])) @ rot.T
    want /= np.linalg.norm(want, axis=1, keepdims=True)
    np.testing.assert_allclose(wn, want, atol=1e-12)
    np.testing.assert_allclose(wp, (n * [a, b, c]) @ rot.T + m[:3, 3], atol=1e-12)
    # the plain 3x3 would be wrong here
    wrong = n @ m[:3, :3].T
    wrong /= np.linalg.norm(wrong, axis=1, keepdims=True)
    assert _angle_deg(wrong, want).max() > 10.0


def test_normal_matrix_keeps_normals_perpendicular_under_shear():
    m = make_mesh("rail")
    mat = np.eye(4)
    mat[:3, 0] = (12.0, 1.0, -3.0)  # a sloped, sheared rail
    mat[:3, 1] = (-0.08, 0.99, 0.0)
    wp, wn = transform_mesh(m.positions, m.normals, mat)
    tri = m.indices
    e1 = wp[tri[:, 1]] - wp[tri[:, 0]]
    e2 = wp[tri[:, 2]] - wp[tri[:, 0]]
    for e in (e1, e2):
        e = e / np.linalg.norm(e, axis=1, keepdims=True)
        assert np.abs((e * wn[tri[:, 0]]).sum(1)).max() < 1e-9  # flat faces: normal perpendicular to edges
    np.testing.assert_allclose(normal_matrix(mat), np.linalg.inv(mat[:3, :3]).T)


def test_bad_kind_and_bits():
    with pytest.raises(ConfigError):
        make_mesh("snowman")
    with pytest.raises(ConfigError):
        oct_encode(np.eye(3), bits=12)


# ---------------------------------------------------------------------------- placement
@pytest.fixture(scope="module")
def course_objects():
    from piste.lighting import default_lights
    from piste.world.course import default_course, track_centerline
    from piste.world.objects import place_objects

    net = default_course(0)
    line = track_centerline(0)
    lights = default_lights()
    return net, line, lights, place_objects(net, line, lights, seed=0)


def test_placement_on_the_surface_and_deterministic(course_objects):
    from piste.terrain.query import height_at
    from piste.world.objects import place_objects

    net, line, lights, objs = course_objects
    assert set(objs.counts) == set(OBJECT_KINDS) and all(v > 0 for v in objs.counts.values())
    base = objs.matrix[:, :3, 3]
    z, hit, _, _ = height_at(net, base[:, :2])
    assert hit.all()
    # bases sit at most 0.5 m into the snow (trees 0.3, signs 0.2, rocks scaled), never above it
    assert (base[:, 2] <= z + 1e-9).all() and (base[:, 2] >= z - 0.5).all()
    again = place_objects(net, line, lights, seed=0)
    np.testing.assert_array_equal(again.matrix, objs.matrix)
    # trees and signs stand upright; trees have non-uniform scale
    for k in ("tree", "sign"):
        i = objs.instances(k)
        up = objs.matrix[i, :3, 2]
        np.testing.assert_allclose(up[:, :2], 0.0, atol=1e-12)
    t = objs.instances("tree")
    sx = np.linalg.norm(objs.matrix[t, :3, 0], axis=1)
    sz = np.linalg.norm(objs.matrix[t, :3, 2], axis=1)
    assert np.abs(sx - sz).max() > 0.1


def test_trees_keep_off_the_track_and_signs_face_up_the_hill(course_objects):
    net, line, lights, objs = course_objects
    t = objs.instances("tree")
    d = np.linalg.norm(objs.matrix[t, None, :2, 3] - line[None, :, :2], axis=2).min(1)
    assert d.min() > 16.0
    s = objs.instances("sign")
    face = -objs.matrix[s, :3, 1]  # the sign graphic is on the panel's -y face
    tangent = np.gradient(line[:, :2], axis=0)
    k = np.linalg.norm(objs.matrix[s, None, :2, 3] - line[None, :, :2], axis=2).argmin(1)
    assert ((face[:, :2] * tangent[k]).sum(1) < 0).all()  # facing riders coming down


def test_rail_ends_on_the_surface(course_objects):
    from piste.terrain.query import height_at

    net, line, lights, objs = course_objects
    r = objs.instances("rail")
    m = objs.matrix[r]
    end = np.einsum("nij,j->ni", m, [1.0, 0.0, 0.0, 1.0])[:, :3]  # object x = 1: the far post's foot
    z, hit, _, _ = height_at(net, end[:, :2])
    assert hit.all() and np.abs(end[:, 2] - (z - 0.05)).max() < 1e-6


def test_lights_chosen_per_object_and_report(course_objects):
    from piste.world.objects import bake_vertex_colors, lighting_report

    net, line, lights, objs = course_objects
    assert objs.lights.directions.shape == (len(objs), 3, 3)
    few = objs.instances("sign")
    baked = bake_vertex_colors(objs, lights, instances=few)
    assert baked["sign"].shape == (len(few), objs.meshes["sign"].n_vertices, 3) and baked["sign"].dtype == np.uint8
    rep = lighting_report(objs, lights)
    assert rep["baked"]["max_error"] <= 0.5 / 128 + 1e-6  # only the 8-bit half-bright rounding
    assert rep["points"]["max_error"] <= rep["dynamic"]["max_error"] + 1e-9
    assert rep["baked"]["bytes"] > rep["dynamic"]["bytes"]


def test_visible_culls_by_frustum(course_objects):
    from piste.world.camera import Camera

    net, line, lights, objs = course_objects
    cam = Camera(eye=line[40] + (0, 0, 10), target=line[60])
    vis = objs.visible(cam.frustum_planes())
    assert 0 < len(vis) < len(objs)
    behind = Camera(eye=line[40] + (0, 0, 10), target=line[20])
    assert set(vis.tolist()) != set(objs.visible(behind.frustum_planes()).tolist())
