"""The default snow texture shipped with the package (``piste/data/snow_256.npz``, issue 23 item 4:
a fresh process's first frame no longer pays numpy.fft's start-up) is exactly what the code computes."""

from __future__ import annotations

import numpy as np

from piste.render import textures
from piste.render.textures import SNOW_FILE, compute_snow_texture, snow_texture


def test_the_shipped_snow_texture_is_the_computed_one():
    stored = textures._stored_snow()
    assert stored is not None, f"{SNOW_FILE} is missing or not a (256, 256, 4) uint8 array"
    assert np.array_equal(stored, compute_snow_texture(256, 0))
    got = snow_texture()
    assert got.dtype == np.uint8 and got.shape == (256, 256, 4) and np.array_equal(got, stored)
    got[0, 0] = 0  # the caller's own copy
    assert np.array_equal(snow_texture(), stored)


def test_other_sizes_and_seeds_are_computed():
    assert np.array_equal(snow_texture(64, seed=3), compute_snow_texture(64, 3))
    assert not np.array_equal(snow_texture(256, seed=1), snow_texture(256, seed=0))


def test_a_missing_or_damaged_file_falls_back_to_computing(tmp_path, monkeypatch):
    for content in (None, b"not an npz"):
        path = tmp_path / "snow.npz"
        if content is not None:
            path.write_bytes(content)
        monkeypatch.setattr(textures, "SNOW_FILE", path)
        textures._stored_snow.cache_clear()
        try:
            assert textures._stored_snow() is None
            assert np.array_equal(snow_texture(), compute_snow_texture(256, 0))
        finally:
            textures._stored_snow.cache_clear()
    np.savez(tmp_path / "small.npz", snow=np.zeros((8, 8, 4), np.uint8))
    monkeypatch.setattr(textures, "SNOW_FILE", tmp_path / "small.npz")
    textures._stored_snow.cache_clear()
    try:
        assert textures._stored_snow() is None
    finally:
        textures._stored_snow.cache_clear()
