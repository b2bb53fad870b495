"""weld_points without scipy gives scipy's clusters (k-d tree pairs + connected components)."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from piste.terrain import PatchNet
from piste.terrain.net import _weld_scipy, weld_points

from nets import TEAPOT, grid_net


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 400), spread=st.sampled_from([1e-3, 1.0, 100.0]),
       tol=st.sampled_from([0.0, 1e-6, 1e-3, 0.05]))
def test_weld_matches_kdtree(seed, n, spread, tol):
    rng = np.random.default_rng(seed)
    base = rng.uniform(-spread, spread, (max(n // 3, 1), 3))
    pts = base[rng.integers(0, len(base), n)]  # exact duplicates
    pts = pts + rng.normal(0, tol * 0.4, pts.shape) * (rng.random((n, 1)) < 0.5)  # near duplicates
    assert np.array_equal(weld_points(pts, tol), _weld_scipy(pts, tol))


def test_real_nets_weld_alike():
    for net in (PatchNet.from_bpt(TEAPOT), grid_net(5, 6, seed=2)):
        pts = net.control_points.reshape(-1, 3)
        assert np.array_equal(weld_points(pts, net.tol), _weld_scipy(pts, net.tol))
        assert np.array_equal(weld_points(pts, 0.05), _weld_scipy(pts, 0.05))
