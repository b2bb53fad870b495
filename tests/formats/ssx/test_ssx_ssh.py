"""SSX .ssh texture banks and light-map pages: round trips, layout facts, bad input."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from piste.errors import FormatError
from piste.formats.ssx import (
    SshBank, SshImage, extract_tiles, lightmap_bank, lightmap_pages, parse_ssh, place_tiles, read_ssh, write_ssh,
)
from piste.formats.ssx.synth import synthetic_textures


def _bank():
    rng = np.random.default_rng(0)
    pal8 = rng.integers(0, 256, (256, 4), dtype=np.uint8)
    pal4 = rng.integers(0, 256, (16, 4), dtype=np.uint8)
    return SshBank([
        SshImage("tex0", 2, rng.integers(0, 256, (16, 8), dtype=np.uint8), pal8, long_name="snow_a"),
        SshImage("tex1", 1, rng.integers(0, 16, (6, 5), dtype=np.uint8), pal4),
        SshImage("lm00", 5, rng.integers(0, 256, (4, 4, 4), dtype=np.uint8), x=3, y=2),
    ])


def test_round_trip(tmp_path):
    bank = _bank()
    path = tmp_path / "T.ssh"
    write_ssh(bank, path)
    data = path.read_bytes()
    back = read_ssh(path)
    assert [im.name for im in back.images] == ["tex0", "tex1", "lm00"]
    for a, b in zip(bank.images, back.images):
        assert a.kind == b.kind and (a.x, a.y) == (b.x, b.y) and a.long_name == b.long_name
        np.testing.assert_array_equal(a.pixels, b.pixels)
        if a.palette is not None:
            np.testing.assert_array_equal(a.palette, b.palette)
    assert back.to_bytes() == data


def test_layout_facts():
    data = _bank().to_bytes()
    assert data[:4] == b"SHPS" and data[12:16] == b"G278"
    size, count = struct.unpack_from("<II", data, 4)
    assert size == len(data) and count == 3
    assert data[16:20] == b"tex0"
    off = struct.unpack_from("<I", data, 20)[0]
    assert data[off - 8:off] == b"Buy ERTS" or b"Buy ERTS" in data[16 + 24:off]
    word, w, h = struct.unpack_from("<Ihh", data, off)
    assert word & 0xFF == 2 and (w, h) == (8, 16) and (word >> 8) == 16 + 128  # image chunk: header + pixels
    pal = off + (word >> 8)
    word2, pw, ph = struct.unpack_from("<Ihh", data, pal)
    assert word2 & 0xFF == 33 and pw * ph == 256
    # the 4-bit image: two pixels a byte, the left one in the low nibble
    im = _bank().images[1]
    off1 = struct.unpack_from("<I", data, 28)[0]
    first = data[off1 + 16]
    assert first == (im.pixels[0, 0] | (im.pixels[0, 1] << 4))


def test_half_range_alpha():
    bank = synthetic_textures(1)
    im = bank.images[0]
    assert (im.palette[:, 3] == 0x80).all()
    assert (im.rgba()[..., 3] == 255).all()


def test_unknown_chunk_and_swizzle_and_refpack():
    data = bytearray(_bank().to_bytes())
    off = struct.unpack_from("<I", data, 20)[0]
    bad = bytearray(data)
    bad[off] = 77
    with pytest.raises(FormatError, match="unknown chunk type 77") as e:
        parse_ssh(bytes(bad), "x.ssh")
    assert "image 0 ('tex0')" in str(e.value) and e.value.field == "chunk type"
    sw = bytearray(data)
    struct.pack_into("<I", sw, off + 12, 0x2000)
    with pytest.raises(FormatError, match="swizzled images .* not supported yet"):
        parse_ssh(bytes(sw), "x.ssh")
    rp = bytearray(data)
    rp[off] = 130
    with pytest.raises(FormatError, match="RefPack"):
        parse_ssh(bytes(rp), "x.ssh")


def test_truncated_and_bad_magic(tmp_path):
    data = _bank().to_bytes()
    with pytest.raises(FormatError, match="SHPS"):
        parse_ssh(b"XXXX" + data[4:], "x.ssh")
    with pytest.raises(FormatError, match="truncated|past the end|need"):
        parse_ssh(data[: len(data) - 40], "x.ssh")
    huge = bytearray(data)
    struct.pack_into("<I", huge, 8, 10**9)
    with pytest.raises(FormatError, match="directory") as e:
        parse_ssh(bytes(huge), "x.ssh")
    assert e.value.field == "image count"
    with pytest.raises(FormatError, match="no such file"):
        read_ssh(tmp_path / "missing.ssh")


def test_lightmap_tiles_are_transposed_and_edge_aligned():
    n = 300  # two pages
    rng = np.random.default_rng(1)
    tiles = rng.integers(0, 256, (n, 8, 8, 4), dtype=np.uint8)
    k = np.arange(n)
    rect = np.stack([(k % 256 % 16) / 16, (k % 256 // 16) / 16, np.full(n, 1 / 16), np.full(n, 1 / 16)], 1)
    page = k // 256
    pages = place_tiles(tiles, rect, page, 2)
    assert pages.shape == (2, 128, 128, 4)
    # tile [j (v), i (u)] sits at page row y0 + i (u), column x0 + j (v)
    p = 17
    assert (pages[0, 8 * 1 + 3, 8 * 1 + 5] == tiles[p, 5, 3]).all()
    np.testing.assert_array_equal(extract_tiles(pages, rect, page), tiles)
    bank = lightmap_bank(pages)
    back = lightmap_pages(parse_ssh(bank.to_bytes()))
    np.testing.assert_array_equal(back, pages)
    with pytest.raises(FormatError, match="patch 2: light-map tile"):
        extract_tiles(pages, rect[:3] + [[0, 0, 0, 0], [0, 0, 0, 0], [0.99, 0, 0, 0]], page[:3])
