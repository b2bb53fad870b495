"""Whole back-facing patches left out by normal cones (ResidentTerrain.facing): conservative (every
triangle of a left-out patch faces away from the eye, at any morph factor, whatever its shape) and
real (a net seen from below is left out whole, from above nothing is)."""

import numpy as np
import pytest

from piste import _jit
from piste.terrain import PatchNet, _kernels
from piste.terrain.resident import ResidentTerrain

from nets import TEAPOT, grid_net


def back_facing(m, eye):
    """``(t,)`` bool: triangles of ``m`` (morphed as drawn) whose plane has ``eye`` behind it."""
    p = m.morphed_positions(m.indices.ravel()).reshape(-1, 3, 3).astype(np.float64)
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    return ((p[:, 0] - eye) * n).sum(-1) > 0


@pytest.mark.parametrize("make, some", [(lambda: grid_net(5, 6, seed=4), True),
                                        (lambda: grid_net(4, 4, seed=9, flips=False), True),
                                        (lambda: PatchNet.from_bpt(TEAPOT), False)])  # (curved: wide cones)
def test_left_out_patches_face_away_at_every_morph_factor(make, some):
    net = make()
    r = ResidentTerrain(net)
    rng = np.random.default_rng(5)
    lo, hi = net.bounds
    ext = float(np.max(hi - lo))
    pids = np.arange(len(net))
    dropped = 0
    for trial in range(24):
        eye = rng.uniform(lo - ext, hi + ext)
        lev = rng.integers(-1, 3, net.n_edges)
        m = r.frame(eye, patches=pids, side_levels=lev[net.side_edge], morph=True)
        m.factors[:] = rng.choice([0.0, 1.0, 0.5], 1)[0] if trial % 2 else rng.uniform(0, 1, m.factors.shape)
        assert np.array_equal(m.eye, eye)
        keep = r.facing(m.patch_ids, m.shape_key, eye)
        back = back_facing(m, eye)
        tri_patch = np.repeat(np.arange(len(m.patch_ids)), np.diff(m.tri_start))
        assert back[~keep[tri_patch]].all(), "a left-out patch has a triangle facing the eye"
        front = m.front_indices()
        assert len(front) == int(keep[tri_patch].sum())
        assert {bytes(t) for t in front} == {bytes(t) for t in m.indices[keep[tri_patch]]}
        dropped += int((~keep).sum())
    assert dropped > 0 or not some


def test_a_net_seen_from_below_is_left_out_whole_and_from_above_kept():
    y, x = np.mgrid[0:13, 0:13] * (10.0 / 3)
    g = np.stack([x, y, 0.5 * np.sin(x / 7.0) + 0.3 * np.cos(y / 5.0)], -1)
    net = PatchNet.from_control_grid(g)
    r = ResidentTerrain(net)
    for lod in (True, False):
        below = r.frame(np.array([20.0, 20.0, -30.0]), lod=lod, near=10.0, far=25.0)
        assert len(below.front_indices()) == 0 and below.n_triangles > 0
        above = r.frame(np.array([20.0, 20.0, 30.0]), lod=lod, near=10.0, far=25.0)
        assert above.front_indices() is above.indices
    # no eye known (a mesh made without one): every triangle
    m = r.frame(np.array([20.0, 20.0, -30.0]))
    m.eye = None
    assert m.front_indices() is m.indices


@pytest.mark.skipif(not _kernels.HAVE_NUMBA, reason="numba not installed: only the numpy path exists")
def test_compiled_and_numpy_front_indices_equal(monkeypatch):
    _jit.warm_up()
    assert _kernels.front_ready()
    net = grid_net(6, 6, seed=2, flips=False)
    r = ResidentTerrain(net)
    rng = np.random.default_rng(1)
    lo, hi = net.bounds
    seen = 0
    for _ in range(12):
        eye = rng.uniform(lo - 30.0, hi + 30.0)
        m = r.frame(eye, near=15.0, far=30.0, flat_error=0.05)
        a = m.front_indices()  # compiled (computes the missing cones on the way)
        with monkeypatch.context() as mp:
            mp.setattr(_kernels, "front_ready", lambda: False)
            b = m.front_indices()
        assert np.array_equal(a, b)
        seen += len(a) < len(m.indices)
    assert seen > 0
