"""Procedural snow texture and the placeholder light-map atlas."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import RenderError, ValidationError
from piste.render.textures import SUN_DIRECTION, lightmap_atlas_size, placeholder_lightmap, snow_texture
from piste.terrain import PatchNet


def test_snow_is_bright_deterministic_and_tileable():
    a = snow_texture(64, seed=3)
    assert a.shape == (64, 64, 4) and a.dtype == np.uint8
    assert np.array_equal(a, snow_texture(64, seed=3))
    assert not np.array_equal(a, snow_texture(64, seed=4))
    lum = a[..., :3].astype(float)
    assert 200 < lum.mean() < 245 and (a[..., 3] == 255).all()
    # tileable: the step across the wrap-around seam is no larger than steps inside the texture
    # (the sparkles are single texels, so compare the median steps)
    inner = np.median(np.abs(np.diff(lum, axis=1)))
    seam = np.median(np.abs(lum[:, 0] - lum[:, -1]))
    assert seam <= 2.0 * inner + 1.0
    with pytest.raises(ValidationError, match="power of two"):
        snow_texture(100)


def test_snow_noise_is_the_full_spectrum_formula():
    """The half-spectrum FFTs (rfft2/irfft2) give the texture of the full complex spectrum."""
    from piste.render.textures import _periodic_noise

    def full(n, rng, beta, lo, hi):
        f = np.fft.fftfreq(n) * n
        fr = np.hypot(f[:, None], f[None, :])
        amp = np.where((fr >= lo) & (fr <= hi), np.maximum(fr, 1.0) ** (-beta / 2.0), 0.0)
        out = np.real(np.fft.ifft2(np.fft.fft2(rng.standard_normal((n, n))) * amp))
        return out / max(np.abs(out).max(), 1e-12)

    for n, beta, lo, hi in ((256, 3.0, 1, 32), (64, 1.0, 4, 32), (8, 1.0, 1, 4)):
        a = _periodic_noise(n, np.random.default_rng(n), beta, lo, hi)
        b = full(n, np.random.default_rng(n), beta, lo, hi)
        assert a.shape == (n, n) and np.abs(a - b).max() < 1e-12


def _flat_net(n=3, tilt=0.0):
    cp = np.zeros((n, 4, 4, 3))
    i, j = np.meshgrid(np.arange(4), np.arange(4), indexing="ij")
    for k in range(n):
        cp[k, ..., 0] = i + 3 * k
        cp[k, ..., 1] = j
        cp[k, ..., 2] = tilt * cp[k, ..., 0]
    return PatchNet(cp)


def test_placeholder_lightmap_layout_and_shading():
    net = _flat_net(3)
    w, h = lightmap_atlas_size(net)
    atlas = placeholder_lightmap(net)
    assert atlas.shape == (h, w, 4) and atlas.dtype == np.uint8
    # a flat, up-facing net is lit the same everywhere, gutters included
    rect = net.lightmap_rect
    x0 = np.round(rect[:, 0] * w - 0.5).astype(int)
    y0 = np.round(rect[:, 1] * h - 0.5).astype(int)
    tiles = np.stack([atlas[y - 1 : y + 9, x - 1 : x + 9, :3] for x, y in zip(x0, y0)])
    assert (tiles == tiles[0, 0, 0]).all()
    expect = np.clip(np.array([0.36, 0.40, 0.48]) + SUN_DIRECTION[2] * np.array([0.72, 0.68, 0.60]), 0, 1) * 255
    assert np.allclose(tiles[0, 0, 0], expect, atol=1)
    # cells outside every tile stay black
    assert atlas[..., :3].sum(axis=-1).min() == 0


def test_placeholder_lightmap_follows_normals():
    # patch 0 tilts towards the sun (x down-slope faces -x, where the sun is), the others are flat
    net = _flat_net(1, tilt=0.5)
    flat = placeholder_lightmap(_flat_net(1))
    tilted = placeholder_lightmap(net)
    assert tilted[..., :3].astype(int).sum() > flat[..., :3].astype(int).sum()


def test_lightmap_atlas_size_rejects_bad_rects():
    net = _flat_net(2)
    net.lightmap_rect[1] = (0.5, 0.5, 0.4, 0.6)
    with pytest.raises(ValidationError, match="patch 1"):
        lightmap_atlas_size(net)


def test_track_field_signed_distance():
    from piste.render.textures import track_field

    y = np.linspace(0.0, 100.0, 40)
    line = np.stack([50.0 + 5.0 * np.sin(y / 15.0), y, -y], axis=1)
    bounds = (np.array([0.0, 0.0, -100.0]), np.array([100.0, 100.0, 0.0]))
    field, rect = track_field(line, bounds, texel=1.0)
    assert field.shape == (100, 100) and rect.tolist() == [0.0, 0.0, 100.0, 100.0]
    # travelling +y, +x is on the right: positive
    row = 50  # world y = 50.5
    xc = 50.0 + 5.0 * np.sin(50.5 / 15.0)
    xs = np.arange(100) + 0.5
    near = np.abs(xs - xc) < 15
    slope = 5.0 / 15.0 * np.cos(50.5 / 15.0)
    expect = (xs - xc) / np.sqrt(1 + slope**2)
    assert np.allclose(field[row, near], expect[near], atol=0.15)
    # a line that doubles back takes the general (k-d tree) path and agrees near the line
    hook = np.concatenate([line, line[-1] + np.array([[10.0, -5.0, 0.0], [20.0, -10.0, 0.0]])])
    general, _ = track_field(hook, bounds, texel=1.0)
    assert np.allclose(general[20:80][np.abs(field[20:80]) < 8], field[20:80][np.abs(field[20:80]) < 8], atol=0.3)


@pytest.mark.parametrize("down", [True, False])
def test_track_field_bits_of_the_whole_field_computed_at_once(down):
    """The field computed a band of rows at a time is, bit for bit, the whole (h, w) float64 field
    ``(x - x_c(y)) / sqrt(1 + x_c'(y)^2)`` (negated for a line running down y) rounded to float32,
    for a field of many bands (the default course's size)."""
    from piste.render.textures import track_field

    ys = np.linspace(400.0, -400.0, 90) if down else np.linspace(-400.0, 400.0, 90)
    line = np.stack([60.0 * np.sin(ys / 90.0), ys, np.zeros_like(ys)], axis=1)
    bounds = (np.array([-500.0, -200.0, 0.0]), np.array([500.0, 200.0, 10.0]))
    field, rect = track_field(line, bounds, texel=0.75)
    w, h = int(np.ceil(1000.0 / 0.75)), int(np.ceil(400.0 / 0.75))
    assert field.shape == (h, w) and field.dtype == np.float32 and (1 << 16) // w < h  # several bands
    xs, gy = -500.0 + (np.arange(w) + 0.5) * 0.75, -200.0 + (np.arange(h) + 0.5) * 0.75
    order = np.argsort(line[:, 1])
    xc = np.interp(gy, line[order, 1], line[order, 0])
    slope = np.gradient(xc, gy)
    ref = (xs[None, :] - xc[:, None]) / np.sqrt(1.0 + slope * slope)[:, None]
    ref = (-ref if down else ref).astype(np.float32)
    assert np.array_equal(field.view(np.uint32), ref.view(np.uint32))
    assert np.array_equal(rect, [-500.0, -200.0, -500.0 + w * 0.75, -200.0 + h * 0.75])


def test_track_texels_are_the_clipped_float16_field_and_a_stored_one_is_taken_as_it_is():
    from piste.render.textures import TRACK_CLIP, track_texels

    f = np.array([[-5000.0, -999.9, 0.0, 12.34], [np.nan, 1000.0, 1e6, -np.inf]], np.float32)
    t = track_texels(f)
    assert t.dtype == np.float16
    assert np.array_equal(t, np.clip(f, -TRACK_CLIP, TRACK_CLIP).astype(np.float16), equal_nan=True)
    ok = t[:1].copy()
    assert track_texels(ok) is ok  # in range: uploaded as stored, no copy
    for bad in (np.array([[np.inf, 0.0]], np.float16), np.array([[1100.0, 0.0]], np.float16)):
        assert np.array_equal(track_texels(bad), np.clip(bad.astype(np.float32), -TRACK_CLIP, TRACK_CLIP).astype(np.float16))
    nan = np.array([[np.nan, 1.0]], np.float16)
    assert np.isnan(track_texels(nan)[0, 0]) and track_texels(nan)[0, 1] == 1.0


def test_light_texels_clip_and_keep_stored_texels_as_they_are():
    from piste.render.textures import LIGHT_CLIP, light_texels, light_texels_in_range

    a = np.array([[[0.25, 1.5, 70000.0, 0.5], [-0.0, 0.0, 3.0, 1.0]]], np.float32)  # (1, 2, 4): RGBA
    t = light_texels(a)
    assert t.dtype == np.float16 and t.shape == (1, 2, 3)
    assert np.array_equal(t, np.array([[[0.25, 1.5, LIGHT_CLIP], [0.0, 0.0, 3.0]]], np.float16))
    assert light_texels(t) is t and light_texels_in_range(t)  # (-0.0 stays in range)
    neg = np.array([[[-0.5, 1.0, 1.0]]], np.float32)
    assert np.array_equal(light_texels(neg), np.array([[[0.0, 1.0, 1.0]]], np.float16))  # clipped, as before
    assert not light_texels_in_range(neg.astype(np.float16))
    with pytest.raises(RenderError, match="finite"):
        light_texels(np.array([[[np.nan, 1.0, 1.0]]], np.float16))
