"""The riders' jacket variants (piste.render.character_pass.rider_textures): the jacket and sleeve
tiles' dominant colour found as numpy's row-wise unique finds it (the first in (r, g, b) order on a
tie), then recoloured."""

from __future__ import annotations

import numpy as np

from piste.character import default_rider
from piste.render import character_pass
from piste.render.character_pass import JACKETS, rider_textures


def _mask(tex):
    tiles = character_pass._rider._TILES
    h, w = tex.shape[:2]
    v, u = np.mgrid[0:h, 0:w]
    uu, vv = (u + 0.5) / w, (v + 0.5) / h
    m = np.zeros((h, w), bool)
    for name in ("jacket", "sleeve"):
        u0, v0, u1, v1 = tiles[name]
        m |= (uu >= u0) & (uu < u1) & (vv >= v0) & (vv < v1)
    return m


def _dominant(tex, mask):
    cols, counts = np.unique(tex[..., :3].astype(np.int32)[mask], axis=0, return_counts=True)
    return cols[counts.argmax()]


def test_the_dominant_jacket_colour_is_replaced():
    tex = default_rider(0).meshes[0].texture
    mask = _mask(tex)
    base = _dominant(tex, mask)
    out = rider_textures(tex, 3)
    assert np.array_equal(out[0], tex)
    body = mask & (tex[..., :3] == base).all(-1)
    assert body.sum() > 100
    for i in (1, 2):
        assert (out[i][body, :3] == JACKETS[i]).all()
        assert np.array_equal(out[i][~mask], tex[~mask])  # only the jacket and sleeves change


def test_a_tie_takes_the_first_colour_in_rgb_order():
    """Two colours as common as each other under the mask: the one first in (r, g, b) order (as
    ``np.unique(axis=0)`` sorts rows) is the jacket's; its texels, and only those, are recoloured."""
    tex = default_rider(0).meshes[0].texture.copy()
    mask = _mask(tex)
    ys, xs = np.nonzero(mask)
    a, b = np.array([40, 200, 10], np.uint8), np.array([40, 100, 250], np.uint8)  # b first: (40, 100) < (40, 200)
    tex[ys[0::2], xs[0::2], :3] = a
    tex[ys[1::2], xs[1::2], :3] = b
    if len(ys) % 2:
        tex[ys[-1], xs[-1], :3] = (7, 7, 7)
    assert np.array_equal(_dominant(tex, mask), b)
    out = rider_textures(tex, 2)[1]
    assert (out[ys[1::2], xs[1::2], :3] == JACKETS[1]).all()
    assert np.array_equal(out[ys[0::2][: len(ys) // 2], xs[0::2][: len(ys) // 2], :3],
                          tex[ys[0::2][: len(ys) // 2], xs[0::2][: len(ys) // 2], :3])


def test_near_is_the_max_over_channels():
    """``_near`` (one channel at a time, what specular_map and rider_textures select texels with)
    is ``abs(rgb - colour).max(-1) <= tol`` exactly, at and around the tolerance's edge."""
    from piste.render.character_pass import _near

    rng = np.random.default_rng(3)
    colour = np.array([200, 120, 30])
    rgb = np.clip(colour + rng.integers(-4, 5, (64, 48, 3)), 0, 255)
    for dtype in (np.int16, np.int32):
        got = _near(rgb.astype(dtype), colour)
        assert np.array_equal(got, np.abs(rgb - colour).max(-1) <= 2)
        assert got.any() and not got.all()
    assert np.array_equal(_near(rgb.astype(np.int32), colour, tol=0), (rgb == colour).all(-1))
