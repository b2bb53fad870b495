"""Pre-computed visibility: conservative against exact rays, bitsets, lookup, and the culling report."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import ConfigError
from piste.pipeline import visibility as V
from piste.terrain.fit import fit_heightfield


@pytest.fixture(scope="module")
def ridge_net():
    """32 x 32 m patches over 256 m: a tall ridge across the middle hides one side from the other."""
    n = 65
    y, x = np.mgrid[0:n, 0:n] * 4.0
    z = 40.0 * np.exp(-((y - 128.0) / 14.0) ** 2) + 2.0 * np.sin(x / 20.0) + 0.02 * x
    return fit_heightfield(z, 4.0, samples_per_patch=8)


def test_ridge_hides_the_far_side(ridge_net):
    vis = V.compute_visibility(ridge_net, cell=64.0, eye_heights=(1.7, 20.0))  # the band holds the camera
    assert vis.method == "horizon" and vis.shape == (4, 4)
    near = vis.patches_at((100.0, 20.0, 0.0))
    lo, hi = ridge_net.patch_bounds
    cy = (lo[:, 1] + hi[:, 1]) / 2
    assert near[cy < 100].mean() > 0.8  # its own side: (nearly) all seen
    assert not near[cy > 200].any()  # behind the ridge: none
    assert 0.3 < near.mean() < 0.9


def test_horizon_is_conservative_against_exact_rays(ridge_net):
    rng = np.random.default_rng(3)
    from piste.terrain.query import height_at

    xy = np.stack([rng.uniform(5, 250, 6), rng.uniform(5, 250, 6)], 1)
    z, hit, _, _ = height_at(ridge_net, xy)
    eyes = np.column_stack([xy, z + 1.7])
    targets = V.patch_targets(ridge_net).reshape(-1, 3)
    lo, hi = ridge_net.bounds
    grid = V._HeightGrid(ridge_net, 2.0, 0.25)
    hz = V._horizon_visible(grid, eyes, targets, 720, 2.0, float(np.hypot(*(hi[:2] - lo[:2]))), 0.25)
    rays = V._rays_visible(ridge_net, eyes, targets, 0.25)
    assert rays.any() and (~rays).any()
    assert not (rays & ~hz).any(), "the horizon test hid a point an exact ray sees"
    assert (hz & ~rays).mean() < 0.1  # and it is not much more than the exact answer


def test_rays_method_and_auto_on_a_non_height_field():
    from piste.terrain.net import PatchNet

    # a folded sheet: a patch whose normals point down is not a height field
    g = np.zeros((4, 7, 3))
    g[..., 0], g[..., 1] = np.meshgrid(np.arange(7.0), np.arange(4.0))
    g[:, 3:, 2] = 2.0
    g[:, 4:, 0] = 6.0 - g[:, 4:, 0] + 0.0
    net = PatchNet.from_control_grid(g)
    assert not V.is_heightfield(net)
    vis = V.compute_visibility(net, cell=3.0, eye_heights=(1.0,))
    assert vis.method == "rays"
    assert vis.patch_matrix().shape == (vis.shape[0] * vis.shape[1], len(net))


def test_bitsets_round_trip_and_lookup(ridge_net):
    spheres = np.array([[128.0, 30.0, 5.0, 2.0], [128.0, 240.0, 3.0, 2.0]])
    vis = V.compute_visibility(ridge_net, cell=64.0, eye_heights=(1.7, 9.0), objects=spheres)
    arrays, meta = vis.to_arrays()
    assert arrays["patch_bits"].dtype == np.uint8 and arrays["patch_bits"].shape == (16, (len(ridge_net) + 7) // 8)
    back = V.Visibility.from_arrays(arrays, meta)
    assert np.array_equal(back.patch_matrix(), vis.patch_matrix())
    seen = back.objects_at((128.0, 10.0, 3.0))
    assert seen.tolist() == [True, False]  # the far object is behind the ridge
    assert back.patches_at((-50.0, 10.0, 0.0)) is None  # outside the grid: draw everything
    assert back.cell_of((255.9, 255.9)) == 15


def test_culling_report_counts(ridge_net):
    from piste.world.camera import Camera

    vis = V.compute_visibility(ridge_net, cell=64.0, eye_heights=(1.7, 20.0))  # the band holds the camera
    cams = [Camera(np.array([128.0, 10.0, 12.0]), np.array([128.0, 250.0, 0.0]), far=1000.0)]
    rep = V.culling_report(ridge_net, vis, cams)
    assert rep["frames"] == 1 and rep["patches"] == len(ridge_net)
    assert rep["visible_pct"] < rep["frustum_pct"] and rep["saved_pct"] > 10.0


def test_bad_settings():
    from piste.world.course import default_course  # noqa: F401 - cheap import check only

    with pytest.raises(ConfigError):
        V.compute_visibility(fit_heightfield(np.zeros((9, 9)), 1.0), cell=0.0)
    with pytest.raises(ConfigError):
        V.compute_visibility(fit_heightfield(np.zeros((9, 9)), 1.0), method="magic")
