"""Resident vertex blocks built before (a bundle stores them): kept on the net as given (checked, not
rebuilt), the same frames as built blocks, and a guard that the blocks' bits still match
RESIDENT_FORMAT (stored bundles hold the old bits: change the arithmetic, bump the format)."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import ValidationError
from piste.terrain.net import PatchNet
from piste.terrain.resident import RESIDENT_FORMAT, ResidentTerrain, keep_resident, resident_terrain


def _net():
    g = np.zeros((7, 10, 3))
    g[..., 0], g[..., 1] = np.meshgrid(np.arange(10.0) * 3.0, np.arange(7.0) * 5.0)
    g[..., 2] = 0.25 * g[..., 0] + 2.0 * np.cos(0.3 * g[..., 1]) + 0.01 * g[..., 0] * g[..., 1]
    return PatchNet.from_control_grid(g)


def test_the_blocks_bits_are_those_of_resident_format_1():
    """Weighted column sums of a fixed net's blocks (position, morph target, uv, light-map uv, slot).
    If this fails because the blocks' layout or arithmetic changed on purpose, bump
    ``RESIDENT_FORMAT`` (bundles built before then build their blocks at run time) and update the
    numbers here."""
    v = ResidentTerrain(_net()).vertices.astype(np.float64)
    assert v.shape == (6 * 116, 11) and RESIDENT_FORMAT == 1
    w = np.arange(len(v)) % 7 + 1.0
    want = [37509.6000490189, 41592.9999418259, 14942.6080408096, 37509.6001422405, 41592.9999411447, 14930.2853232957,
            1388.7333598435, 1381.8666935414, 1389.2710908577, 1387.5033544004, 34931.0]
    assert np.allclose(w @ v, want, rtol=1e-7, atol=0)


def test_kept_blocks_are_returned_as_given_and_draw_the_same_frames():
    built = ResidentTerrain(_net())
    net = _net()
    stored = built.vertices.copy()
    stored.flags.writeable = False  # as a bundle's member view
    r = keep_resident(net, stored)
    assert r.vertices is stored
    assert resident_terrain(net, wait=False) is r and not net.__dict__.get("_resident_pending")
    eye = np.array([2.0, -3.0, 9.0])
    a, b = built.frame(eye, near=8.0, far=20.0), r.frame(eye, near=8.0, far=20.0)
    assert np.array_equal(a.indices, b.indices) and np.array_equal(a.factors, b.factors)
    rows = np.unique(a.indices.ravel())
    assert np.array_equal(a.morphed_positions(rows), b.morphed_positions(rows))


def test_kept_blocks_go_stale_when_the_net_changes():
    net = _net()
    r = keep_resident(net, ResidentTerrain(_net()).vertices)
    net.lightmap_rect = net.lightmap_rect * 0.5
    assert r.stale()
    again = resident_terrain(net, wait=True)  # rebuilt from the net
    assert again is not r and not np.array_equal(again.vertices, r.vertices)


@pytest.mark.parametrize("bad", ["shape", "dtype", "list", "slot_high", "slot_negative", "slot_nan"])
def test_bad_blocks_are_refused(bad):
    net = _net()
    v = ResidentTerrain(_net()).vertices.copy()
    if bad == "shape":
        v = v[:-116]
    elif bad == "dtype":
        v = v.astype(np.float64)
    elif bad == "list":
        v = v.tolist()
    elif bad == "slot_high":
        v[3, 10] = net.n_edges + len(net)
    elif bad == "slot_negative":
        v[3, 10] = -1
    else:
        v[3, 10] = np.nan
    with pytest.raises(ValidationError) as e:
        keep_resident(net, v)
    assert "resident vertex blocks" in str(e.value)
    assert not net.__dict__.get("_resident")
