"""The default course: deterministic, big enough, closed C0, a track lower than its surroundings."""

import time

import numpy as np
import pytest

import piste.terrain
import piste.world
from piste.terrain import height_at, ray_intersect
from piste.terrain.bezier import evaluate
from piste.terrain.net import SIDE_INDEX
from piste.world.course import COURSE_LENGTH, COURSE_WIDTH, course_heightfield, default_course, track_centerline


@pytest.fixture(scope="module")
def course():
    return default_course(0)


def test_reexported():
    assert default_course is piste.world.default_course
    assert not hasattr(piste.terrain, "default_course")  # the terrain layer does not import the world


def test_deterministic_and_seeded(course):
    again = default_course(0)
    assert again is not course  # an independent copy
    np.testing.assert_array_equal(again.control_points, course.control_points)
    again.control_points[0, 0, 0, 2] += 1.0
    assert default_course(0).control_points[0, 0, 0, 2] == course.control_points[0, 0, 0, 2]
    other = default_course(1)
    assert other.control_points.shape == course.control_points.shape
    assert np.abs(other.control_points - course.control_points).max() > 1.0
    np.testing.assert_array_equal(track_centerline(0, 50), track_centerline(0, 50))
    assert np.abs(track_centerline(1, 50) - track_centerline(0, 50)).max() > 1.0


def test_size_and_closed_c0(course):
    py, px = course.grid_shape
    assert len(course) == px * py >= 2000
    (x0, y0, z0), (x1, y1, z1) = course.bounds
    assert (x0, y0, x1, y1) == (0.0, 0.0, COURSE_WIDTH, COURSE_LENGTH)
    assert 250.0 < z1 - z0 < 500.0
    # boundary only at the outer rim; every other edge shared by two patches with identical points
    assert len(course.boundary_edges) == 2 * (px + py)
    assert len(course.shared_edges) == (px - 1) * py + px * (py - 1)
    assert not course.edge_degenerate.any()
    e = course.shared_edges
    pts = []
    for k in range(2):
        p, s = course.edge_patches[e, k], course.edge_sides[e, k]
        ij = SIDE_INDEX[s]
        q = course.control_points[p[:, None], ij[..., 0], ij[..., 1]]
        flip = course.side_flip[p, s]
        q[flip] = q[flip, ::-1]
        pts.append(q)
    assert np.array_equal(pts[0], pts[1])
    # the fit follows the procedural field closely
    z, spacing, origin = course_heightfield(0)
    assert z.shape == (4 * py + 1, 4 * px + 1)
    from piste.terrain import fit_error

    rmse, max_err, _ = fit_error(course, z, spacing, origin)
    assert rmse < 0.3 and max_err < 4.0


def test_descends_along_y(course):
    py, px = course.grid_shape
    pos = evaluate(course.control_points, [0.5], [0.5], normals=False)[:, 0].reshape(py, px, 3)
    rows = pos[..., 2].mean(1)
    assert rows[0] - rows[-1] > 250.0
    assert (np.diff(rows) < 0).mean() > 0.95


def test_track_centerline(course):
    c = track_centerline(0, 400)
    assert c.shape == (400, 3) and c.dtype == np.float64
    assert np.isfinite(c).all()
    assert (np.diff(c[:, 1]) > 0).all()  # runs down the hill (+y)
    dz = np.diff(c[:, 2])
    assert c[0, 2] - c[-1, 2] > 250.0
    assert (dz < 0).mean() > 0.9 and dz.max() < 1.0  # monotone-ish: kickers may lift it a little
    # the points are on the exact surface
    z, hit, _, _ = height_at(course, c[:, :2])
    assert hit.all()
    np.testing.assert_allclose(c[:, 2], z, atol=1e-9)
    # it winds: the track is not a straight line down the fall line
    assert np.ptp(c[:, 0]) > 60.0
    assert (c[:, 0] > 40.0).all() and (c[:, 0] < COURSE_WIDTH - 40.0).all()


def test_track_lower_than_surroundings(course):
    c = track_centerline(0, 300)
    for off in (22.0, 30.0):
        left = height_at(course, c[:, :2] - [off, 0.0])[0]
        right = height_at(course, c[:, :2] + [off, 0.0])[0]
        assert (np.minimum(left, right) > c[:, 2]).mean() > 0.97
        assert (0.5 * (left + right) - c[:, 2]).mean() > 4.0


def test_course_features_differ_from_a_plain_slope(course):
    # rocks and undulations: heights off the track deviate from a smooth fall-line profile by metres
    z, spacing, _ = course_heightfield(0)
    rough = z - np.median(z, axis=1, keepdims=True)
    assert np.ptp(rough) > 30.0


def test_shadow_rays_on_the_course(course, record_property):
    """Shadow rays from the surface towards a low sun: some shadowed (rocks, track walls), most lit.

    Prints the rays/s of ``ray_intersect(any_hit=True)`` (a figure, not an assertion)."""
    py, px = course.grid_shape
    rng = np.random.default_rng(0)
    patches = rng.integers(0, len(course), 20000)
    uv = rng.uniform(0.0, 1.0, (20000, 2))
    from piste.terrain.query import eval_points

    cp = course.control_points[patches]
    o = eval_points(cp, uv[:, 0], uv[:, 1], derivatives=False)
    sun = np.array([np.cos(np.radians(25)) * np.cos(np.radians(200)), np.cos(np.radians(25)) * np.sin(np.radians(200)),
                    np.sin(np.radians(25))])
    d = np.broadcast_to(sun, o.shape)
    ray_intersect(course, o[:10], d[:10], any_hit=True, t_min=1e-4)  # build the BVH outside the timing
    t = time.perf_counter()
    r = ray_intersect(course, o, d, any_hit=True, t_min=1e-4)
    el = time.perf_counter() - t
    print(f"\ndefault course: {len(o)} shadow rays (sun 25 deg) in {el:.2f} s = {len(o) / el:,.0f} rays/s, "
          f"{r.hit.mean():.1%} shadowed")
    record_property("shadow_rays_per_s", round(len(o) / el))
    assert 0.01 < r.hit.mean() < 0.9
    # a ray straight up from the surface is never shadowed on a height field
    up = ray_intersect(course, o[:2000], np.tile([0.0, 0.0, 1.0], (2000, 1)), any_hit=True, t_min=1e-4)
    assert not up.hit.any()
