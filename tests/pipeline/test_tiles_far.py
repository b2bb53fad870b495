"""The far field a tiled build writes for the streaming renderer: ``far_error`` (how far each tile's
patches leave the corner grid and the middle level), checked when a world is opened."""

from __future__ import annotations

import numpy as np
import pytest

from piste.pipeline.tiled_build import build_tiles, far_errors, synthetic_spec
from piste.terrain.bezier import evaluate, grid_params
from piste.terrain.tiles import TileError, TileStore


def _patch(z) -> np.ndarray:
    """One 30 m patch over [0, 30]^2 with control-point heights ``z (4, 4)`` ([j (v), i (u)])."""
    cp = np.zeros((1, 4, 4, 3))
    g = np.linspace(0.0, 30.0, 4)
    cp[0, :, :, 0] = g[None, :]
    cp[0, :, :, 1] = g[:, None]
    cp[0, :, :, 2] = z
    return cp


def test_far_errors_measure_the_levels_chords():
    plane = _patch(2.0 * np.linspace(0, 30, 4)[None, :] + 0.5 * np.linspace(0, 30, 4)[:, None])
    assert np.allclose(far_errors(plane), 0.0, atol=1e-9)  # a plane is its own triangulation
    bump = _patch(np.array([[0, 0, 0, 0], [0, 9, 9, 0], [0, 9, 9, 0], [0, 0, 0, 0]], float))
    corner, mid = far_errors(bump)
    centre = evaluate(bump, np.array([0.5]), np.array([0.5]), normals=False)[0, 0, 2]
    assert corner == pytest.approx(centre, rel=1e-9)  # the corner grid is flat at 0: the peak is missed
    assert 0.0 < mid < corner  # the middle level holds the centre: only the shoulders are off
    # the corner grid is flat at 0 here: its error is the surface's highest point, found densely too
    u, v = grid_params(33)
    z = evaluate(bump, u, v, normals=False)[0, :, 2].reshape(33, 33)
    assert np.abs(z).max() == pytest.approx(corner, rel=1e-6)


def test_tiles_carry_far_error_and_bad_ones_name_the_member(tmp_path):
    from piste.render.streaming import TileCache

    root = tmp_path / "w.tiles"
    build_tiles(synthetic_spec(root, 8, tile_patches=4, res=3, spacing=20.0, shadows=False))
    store = TileStore(root)
    fe = store.read("lit", 1, 0)["far_error"]
    assert fe.shape == (2,) and fe.dtype == np.float64 and fe[0] >= fe[1] > 0.0
    cache = TileCache(root)
    try:
        assert cache.chord_error[(1, 0)] == fe[0] and cache.mid_error[(1, 0)] == fe[1]
    finally:
        cache.close()
    p = store.path("lit", 1, 0)
    a = dict(np.load(p))
    for bad, what in ((np.array([1.0, -2.0]), "errors >= 0"), (np.array([1.0, 2.0, 3.0]), r"expected \(2,\)")):
        a["far_error"] = bad
        with open(p, "wb") as fh:
            np.savez(fh, **a)
        cache = TileCache(root)
        try:
            assert (1, 0) in cache.bad  # left out and named; the other tiles are drawn
            exc = cache.bad[(1, 0)]
            assert isinstance(exc, TileError) and exc.field == "far_error" and str(p) in str(exc)
            assert len(cache.far) == 3
        finally:
            cache.close()
        import re

        assert re.search(what, str(exc))
