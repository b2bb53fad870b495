import numpy as np
import pytest

from piste.errors import ConfigError
from piste.terrain import edge_levels, format_stats, stats, tessellate, visible_patches
from piste.transforms import cull_boxes, frustum_planes, look_at, perspective

from nets import grid_net


def test_edge_levels_by_distance():
    net = grid_net(10, 10, flips=False, size=10)
    eye = np.array([5.0, 5.0, 5.0])
    lv = edge_levels(net, eye, near=20, far=50)
    d = np.linalg.norm(net.edge_midpoints() - eye, axis=1)
    assert (lv[d < 20] == 8).all() and (lv[(d >= 20) & (d < 50)] == 6).all() and (lv[d >= 50] == 4).all()
    assert set(np.unique(lv)) == {4, 6, 8}
    # one level per edge: both patches of a shared edge see the same value by construction
    mesh = tessellate(net, lv)
    assert (mesh.patch_kind == 0).any()  # glue patches appear at level transitions
    with pytest.raises(ConfigError):
        edge_levels(net, eye, near=50, far=20)


def test_frustum_culling():
    net = grid_net(10, 10, flips=False, size=10)
    eye, target = np.array([50.0, -20.0, 10.0]), np.array([50.0, 30.0, 0.0])
    vis = visible_patches(net, eye, target, fov_y=40)
    assert 0 < len(vis) < len(net)
    # patches behind the camera (y < -20) can't be visible; ones straight ahead must be
    centres = net.control_points.reshape(len(net), 16, 3).mean(1)
    ahead = np.argmin(np.linalg.norm(centres[:, :2] - [50, 30], axis=1))
    assert ahead in vis
    planes = frustum_planes(perspective(60, 1.0, 0.1, 100) @ look_at([0, 0, 0], [0, 1, 0]))
    centre = np.array([[0, 6, 0], [0, -9, 0]], float).T
    assert cull_boxes(centre, np.ones((3, 2)), planes).tolist() == [True, False]


def test_stats_table():
    net = grid_net(20, 20, flips=False, size=10)
    s = stats(net, eye=[100, -10, 20], target=[100, 100, 0], near=25, far=60)
    shares = s["pct_4"] + s["pct_6"] + s["pct_8"] + s["pct_nonuniform"] + s["pct_other"]
    assert abs(shares - 100) < 1e-9
    assert s["polys_no_lod"] == 98 * s["patches"]
    assert 18 <= s["avg_polys_per_patch"] <= 98
    assert np.isclose(s["no_lod_ratio"], s["polys_no_lod"] / s["polys"])
    assert np.isclose(s["pct_more"], 100 * (s["no_lod_ratio"] - 1))
    assert s["mpolys_per_s"] > 0
    text = format_stats(s)
    assert "average polygons per patch" in text and "29.68" in text
