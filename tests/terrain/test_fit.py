"""Least-squares height-field fit: the real DEM inside matplotlib, exactness, continuity, errors."""

import numpy as np
import pytest

from piste.errors import PisteError, ValidationError
from piste.terrain import PatchNet, fit_error, fit_heightfield
from piste.terrain.bezier import evaluate
from piste.terrain.net import SIDE_INDEX


@pytest.fixture(scope="module")
def dem():
    """Jacksboro fault DEM (344 x 403 samples, 3 arc-seconds): heights in metres, spacing in metres."""
    from matplotlib import cbook

    data = cbook.get_sample_data("jacksboro_fault_dem.npz")
    z = np.asarray(data["elevation"], dtype=np.float64)
    lat = np.radians(0.5 * (float(data["ymin"]) + float(data["ymax"])))
    dx = float(data["dx"]) * 111_320.0 * np.cos(lat)
    dy = float(data["dy"]) * 111_320.0
    return z, (dx, dy)


def side_points(net, patch, side):
    """Control points of patch sides in the edge's canonical direction, (m, 4, 3)."""
    ij = SIDE_INDEX[side]
    pts = net.control_points[patch[:, None], ij[..., 0], ij[..., 1]]
    flip = net.side_flip[patch, side]
    pts[flip] = pts[flip, ::-1]
    return pts


def shared_edge_gap(net):
    """Largest difference between the two patches' control points on every shared edge."""
    e = net.shared_edges
    a = side_points(net, net.edge_patches[e, 0], net.edge_sides[e, 0])
    b = side_points(net, net.edge_patches[e, 1], net.edge_sides[e, 1])
    return float(np.abs(a - b).max())


def block_errors(net, z, s=4):
    """Fit minus samples at every sample of every patch, evaluated through the patches themselves."""
    py, px = net.grid_shape
    t = np.arange(s + 1) / s
    v, u = np.meshgrid(t, t, indexing="ij")
    pos = evaluate(net.control_points, u.ravel(), v.ravel(), normals=False).reshape(py, px, s + 1, s + 1, 3)
    rows = np.arange(py)[:, None, None, None] * s + np.arange(s + 1)[None, None, :, None]
    cols = np.arange(px)[None, :, None, None] * s + np.arange(s + 1)[None, None, None, :]
    return pos[..., 2] - z[rows, cols]


def test_dem_fit_rmse_and_zero_seam_gap(dem, record_property):
    z, spacing = dem
    net = fit_heightfield(z, spacing)
    py, px = net.grid_shape
    assert (py, px) == ((z.shape[0] - 1) // 4, (z.shape[1] - 1) // 4) == (85, 100)
    assert len(net) == 8500
    rmse, max_err, count = fit_error(net, z, spacing)
    assert count == (4 * py + 1) * (4 * px + 1)
    # the same figures through direct evaluation of the patches (each sample once per patch it is in)
    err = block_errors(net, z)
    print(f"\njacksboro DEM {z.shape}, {len(net)} patches of 4x4 sample intervals: C0 RMSE {rmse:.3f} m, "
          f"max {max_err:.2f} m (relief {z.max() - z.min():.0f} m)")
    record_property("dem_c0_rmse_m", round(rmse, 4))
    record_property("dem_c0_max_m", round(max_err, 3))
    assert 1.0 < rmse < 3.0  # DESIGN.md measured ~2.0 m for this fit
    assert max_err < 30.0
    assert np.abs(err).max() == pytest.approx(max_err, rel=1e-6)
    # C0 by construction: shared edges identical, boundary edges only on the rim
    assert shared_edge_gap(net) == 0.0
    assert len(net.boundary_edges) == 2 * (px + py)
    assert len(net.shared_edges) == (px - 1) * py + px * (py - 1)
    # normals point up everywhere
    _, nrm = net.evaluate([0.0, 0.5, 1.0], [0.0, 0.5, 1.0])
    assert (nrm[..., 2] > 0).all()


def test_dem_smooth_fits(dem, record_property):
    z, spacing = dem
    crop = z[:161, :201]  # a large crop keeps this quick
    results = {}
    for smooth in (False, "c1", "c2"):
        net = fit_heightfield(crop, spacing, smooth=smooth)
        rmse, max_err, _ = fit_error(net, crop, spacing)
        results[smooth] = rmse
        record_property(f"dem_crop_{smooth or 'c0'}_rmse_m", round(rmse, 4))
        py, px = net.grid_shape
        cp = net.control_points.reshape(py, px, 4, 4, 3)[..., 2]
        # slope jump across x seams (u direction) and y seams (v direction), in the z control points
        jump_x = np.abs((cp[:, :-1, 3] - cp[:, :-1, 2]) - (cp[:, 1:, 1] - cp[:, 1:, 0])).max()
        jump_y = np.abs((cp[:-1, :, :, 3] - cp[:-1, :, :, 2]) - (cp[1:, :, :, 1] - cp[1:, :, :, 0])).max()
        if smooth:
            assert jump_x < 1e-9 and jump_y < 1e-9  # C1 (and C2) across every seam
        else:
            assert jump_x > 1.0  # the C0 fit has slope jumps (creases in lighting)
        if smooth == "c2":
            # second differences match across seams too
            d2a = cp[:, :-1, 3] - 2 * cp[:, :-1, 2] + cp[:, :-1, 1]
            d2b = cp[:, 1:, 2] - 2 * cp[:, 1:, 1] + cp[:, 1:, 0]
            assert np.abs(d2a - d2b).max() < 1e-9
        assert shared_edge_gap(net) == 0.0
    print(f"\njacksboro crop {crop.shape}: RMSE C0 {results[False]:.2f} m, C1 {results['c1']:.2f} m, "
          f"C2 {results['c2']:.2f} m")
    assert results[False] < results["c1"] < results["c2"]
    assert fit_heightfield(crop, spacing, smooth=True).control_points.tolist() == (
        fit_heightfield(crop, spacing, smooth="c1").control_points.tolist()
    )


@pytest.mark.parametrize("smooth", [False, "c1", "c2"])
def test_cubic_polynomial_is_reproduced_exactly(smooth):
    y, x = np.mgrid[0:25, 0:37].astype(float)
    x, y = x * 2.0, y * 3.0
    f = 1e-3 * x**3 - 2e-4 * x * y**2 + 0.01 * x * y - 0.2 * y + 5.0
    net = fit_heightfield(f, (2.0, 3.0), smooth=smooth)
    assert np.abs(block_errors(net, f)).max() < 1e-9


def test_sparse_method_matches_separable():
    rng = np.random.default_rng(0)
    z = rng.normal(size=(21, 29)).cumsum(0).cumsum(1)
    for smooth in (False, "c1", "c2"):
        a = fit_heightfield(z, 1.0, smooth=smooth)
        b = fit_heightfield(z, 1.0, smooth=smooth, method="sparse")
        np.testing.assert_allclose(a.control_points, b.control_points, atol=1e-8)


def test_crop_pad_origin_uv_and_samples_per_patch():
    rng = np.random.default_rng(1)
    z = rng.normal(size=(23, 30))  # 22 x 29 intervals: not multiples of 4
    net = fit_heightfield(z, (2.0, 3.0), origin=(100.0, -50.0))
    assert net.grid_shape == (5, 7)
    (x0, y0, _), (x1, y1, _) = net.bounds
    assert (x0, y0, x1, y1) == (100.0, -50.0, 100.0 + 7 * 8.0, -50.0 + 5 * 12.0)
    padded = fit_heightfield(z, (2.0, 3.0), edge="pad")
    assert padded.grid_shape == (6, 8)
    # pad: the last row/column repeat, so the fit still passes near the original samples
    assert np.abs(block_errors(padded, np.pad(z, ((0, 2), (0, 3)), mode="edge"))).max() < 5
    # corner UVs: one repeat per patch by default, world units / uv_scale otherwise
    np.testing.assert_array_equal(net.uv[0], [[0, 0], [1, 0], [1, 1], [0, 1]])
    np.testing.assert_array_equal(net.uv[7 + 2], [[2, 1], [3, 1], [3, 2], [2, 2]])
    scaled = fit_heightfield(z, (2.0, 3.0), uv_scale=4.0)
    np.testing.assert_allclose(scaled.uv[1], [[2, 0], [4, 0], [4, 3], [2, 3]])
    three = fit_heightfield(z, 1.0, samples_per_patch=3)
    assert three.grid_shape == (7, 9)
    # with 3 intervals per patch the cubic interpolates its 4x4 samples
    assert np.abs(block_errors(three, z, 3)).max() < 1e-9


def test_from_heightfield_delegates():
    z = np.add.outer(np.arange(9.0), np.arange(13.0))
    net = PatchNet.from_heightfield(z, 1.5, name="ramp")
    assert isinstance(net, PatchNet) and net.name == "ramp" and len(net) == 6
    assert np.abs(block_errors(net, z)).max() < 1e-9


def test_errors_name_the_field():
    z = np.zeros((9, 13))
    z[4, 7] = np.nan
    with pytest.raises(ValidationError, match=r"'z'.*row 4, column 7"):
        fit_heightfield(z, 1.0)
    with pytest.raises(ValidationError, match="2-D"):
        fit_heightfield(np.zeros(20), 1.0)
    with pytest.raises(ValidationError, match="at least 2 patches"):
        fit_heightfield(np.zeros((5, 5)), 1.0)
    with pytest.raises(ValidationError, match="samples_per_patch"):
        fit_heightfield(np.zeros((9, 13)), 1.0, samples_per_patch=2)
    with pytest.raises(ValidationError, match="spacing"):
        fit_heightfield(np.zeros((9, 13)), (1.0, -1.0))
    with pytest.raises(ValidationError, match="edge"):
        fit_heightfield(np.zeros((9, 13)), 1.0, edge="wrap")
    with pytest.raises(PisteError, match="smooth"):
        fit_heightfield(np.zeros((9, 13)), 1.0, smooth="c3")


def test_progress_goes_to_the_piste_logger_not_stdout(caplog, capsys):
    """``progress=True`` reports the fit's stages at INFO on ``piste.terrain.*`` (the CLI shows them;
    ``piste -q`` hides them); without it they are DEBUG; nothing is printed."""
    import logging

    z = np.random.default_rng(0).normal(size=(13, 13))
    with caplog.at_level(logging.DEBUG, logger="piste"):
        PatchNet.from_heightfield(z, 1.0, progress=True)
    info = [r for r in caplog.records if r.levelno == logging.INFO]
    assert info and all(r.name.startswith("piste.terrain.") for r in info)
    assert any("PatchNet of" in r.getMessage() for r in info)
    caplog.clear()
    with caplog.at_level(logging.DEBUG, logger="piste"):
        PatchNet.from_heightfield(z, 1.0)
    assert caplog.records and all(r.levelno == logging.DEBUG for r in caplog.records)
    out = capsys.readouterr()
    assert out.out == "" and out.err == ""


def test_single_threaded_pins_blas_until_the_last_caller_leaves():
    import threading

    from threadpoolctl import threadpool_info, threadpool_limits

    from piste.terrain.heightfield import single_threaded

    def threads():
        return {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}

    with threadpool_limits(limits=2):
        assert threads() == {2}
        inside, release = threading.Event(), threading.Event()

        def task():
            with single_threaded():
                inside.set()
                release.wait(10)

        worker = threading.Thread(target=task)
        worker.start()
        inside.wait(10)
        with single_threaded():
            with single_threaded():  # re-entrant
                assert threads() == {1}
        assert threads() == {1}  # the other task is still inside: its pool stays pinned
        release.set()
        worker.join(10)
        assert threads() == {2}  # the last one out restores the limit
