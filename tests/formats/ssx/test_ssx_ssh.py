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
    # the game's writer: header + directory reserved in 112 bytes (<= 12 images), "Buy ERTS" right
    # after the directory, "Buy ERTS" before every later image, none after the last
    off = struct.unpack_from("<I", data, 20)[0]
    assert off == 112 and data[16 + 24:16 + 32] == b"Buy ERTS"
    off1, off2 = struct.unpack_from("<I", data, 28)[0], struct.unpack_from("<I", data, 36)[0]
    assert data[off1 - 16:off1 - 8] == b"Buy ERTS" and data[off2 - 16:off2 - 8] == b"Buy ERTS"
    assert b"Buy ERTS" not in data[off2:]
    word, w, h = struct.unpack_from("<Ihh", data, off)
    assert word & 0xFF == 2 and (w, h) == (8, 16) and (word >> 8) == 16 + 128  # explicit size
    pal = off + (word >> 8)
    word2, pw, ph, px = struct.unpack_from("<Ihhh", data, pal)
    assert word2 == 33 and pw * ph == 256 and px == 256  # palette: implied size 0, x = colour count
    name = pal + 16 + 1024
    assert data[name:name + 4] == b"\x70\0\0\0" and data[name + 4:name + 11] == b"snow_a\0"
    # the 4-bit image: two pixels a byte, the left one in the low nibble
    im = _bank().images[1]
    first = data[off1 + 16]
    assert first == (im.pixels[0, 0] | (im.pixels[0, 1] << 4))
    # 4 bytes of 8 for 15 images -> the 128-byte steps: 112 + 128 for 13..28 images
    many = SshBank([SshImage(f"{i:04d}", 5, np.zeros((2, 2, 4), np.uint8), long_name="") for i in range(13)])
    assert struct.unpack_from("<I", many.to_bytes(), 20)[0] == 240


def test_swizzled_8bit_and_clut_order_round_trip():
    rng = np.random.default_rng(3)
    pix = rng.integers(0, 256, (32, 64), dtype=np.uint8)
    pal = rng.integers(0, 256, (256, 4), dtype=np.uint8)
    bank = SshBank([SshImage("swz0", 2, pix, pal, flags=0x2000, long_name="", palette_flags=0x2000)])
    data = bank.to_bytes()
    back = parse_ssh(data).images[0]
    np.testing.assert_array_equal(back.pixels, pix)
    np.testing.assert_array_equal(back.palette, pal)
    assert parse_ssh(data).to_bytes() == data
    # stored bytes follow the spec's block decomposition and CLUT bit swap
    from piste.formats.ssx.ssh import clut_order, swizzle8_order

    off = struct.unpack_from("<I", data, 20)[0]
    stored = np.frombuffer(data, np.uint8, 64 * 32, off + 16)
    np.testing.assert_array_equal(stored[swizzle8_order(64, 32)], pix.ravel())
    x, y = 5, 3
    block, swap = 0, (((y + 2) >> 2) & 1) * 4
    src = block + ((((y & ~3) >> 1) + (y & 1)) & 7) * 64 * 2 + ((x + swap) & 7) * 4 + ((y >> 1) & 1) + ((x >> 2) & 2)
    assert stored[src] == pix[y, x]
    assert clut_order(256)[8] == 16 and clut_order(256)[16] == 8 and clut_order(256)[7] == 7
    pal_off = off + 16 + 64 * 32 + 16
    np.testing.assert_array_equal(np.frombuffer(data, np.uint8, 4, pal_off + 4 * 16), pal[8])


def test_display_decode_undoes_half_bright():
    from piste.formats.ssx.ssh import half_bright

    pal = np.array([[0, 64, 128, 128], [10, 20, 30, 0]], np.uint8)
    im = SshImage("a", 2, np.array([[0, 1]], np.uint8), pal)
    np.testing.assert_array_equal(im.rgba()[0, 0], [0, 127, 255, 255])
    np.testing.assert_array_equal(half_bright(im.rgba())[0, 0], [0, 64, 128, 128])
    full = SshImage("b", 2, np.array([[0]], np.uint8), np.array([[200, 100, 50, 255]], np.uint8))
    np.testing.assert_array_equal(full.rgba()[0, 0], [200, 100, 50, 255])  # full range: left alone


def test_half_range_alpha():
    bank = synthetic_textures(1)
    im = bank.images[0]
    assert (im.palette[:, 3] == 0x80).all() and im.palette[:, :3].max() <= 128  # stored half-bright
    assert (im.rgba()[..., 3] == 255).all() and im.rgba()[..., :3].max() > 200


def test_unknown_chunk_and_swizzle_and_refpack():
    data = bytearray(_bank().to_bytes())
    off = struct.unpack_from("<I", data, 20)[0]
    bad = bytearray(data)
    bad[off] = 77
    with pytest.raises(FormatError, match="unknown chunk type 77") as e:
        parse_ssh(bytes(bad), "x.ssh")
    assert "image 0 ('tex0')" in str(e.value) and e.value.field == "chunk type"
    sw = bytearray(data)
    off1 = struct.unpack_from("<I", data, 28)[0]  # the 4-bit image
    struct.pack_into("<I", sw, off1 + 12, 0x2000)
    with pytest.raises(FormatError, match="swizzled 4-bit images .* not supported yet"):
        parse_ssh(bytes(sw), "x.ssh")
    sw = bytearray(data)
    struct.pack_into("<I", sw, off + 12, 0x2000)  # an 8x16 8-bit image: no swizzle covers that size
    with pytest.raises(FormatError, match="not a size the PS2 8-bit swizzle covers"):
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
    with pytest.raises(FormatError, match="(?i)no such file"):
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


# ----------------------------------------------------------------------------- kept chunks (issue 22 item 6)
def _hot_spots(points) -> bytes:
    """A type-124 hot-spot chunk as SSX-Library reads it: type, u24 size, i16 count, count x 8
    bytes (two i32), 16-aligned."""
    body = struct.pack("<h", len(points)) + b"".join(struct.pack("<ii", x, y) for x, y in points)
    n = 4 + len(body)
    n += -n % 16
    return (struct.pack("<I", 124 | (n << 8)) + body).ljust(n, b"\0")


def _metal_alpha() -> bytes:
    """A type-105 metal-alpha marker as SSX-Library writes it: size 16, width 0, height 128."""
    return struct.pack("<I4hI", 105 | (16 << 8), 0, 128, 0, 0, 0)


def test_hot_spot_and_metal_alpha_chunks_written_back_unchanged(tmp_path):
    bank = _bank()
    hs = _hot_spots([(329, 394), (359, 400), (357, 405)])
    bank.images[0].extra = [(2, hs)]  # image, palette, hot spots, long name
    bank.images[1].extra = [(2, _metal_alpha())]  # image, palette, metal alpha
    data = bank.to_bytes()
    off0 = struct.unpack_from("<I", data, 20)[0]
    assert data.find(hs, off0) > 0
    path = tmp_path / "H.ssh"
    path.write_bytes(data)
    back = read_ssh(path)
    assert back.images[0].extra == [(2, hs)] and back.images[0].long_name == "snow_a"
    assert back.images[1].extra == [(2, _metal_alpha())]
    np.testing.assert_array_equal(back.images[0].pixels, bank.images[0].pixels)
    assert back.to_bytes() == data  # byte for byte
    # a hot-spot chunk of size 0: its size implied by the count (6 + 8 x count, 16-aligned)
    z = bytearray(hs)
    z[1:4] = b"\0\0\0"
    bank.images[0].extra = [(2, bytes(z))]
    again = parse_ssh(bank.to_bytes(), "z.ssh")
    assert again.images[0].extra == [(2, bytes(z))] and again.images[0].long_name == "snow_a"
    # a count running past the image is refused, naming the file, the image and the field
    bad = bytearray(data)
    at = bad.find(hs)
    struct.pack_into("<h", bad, at + 4, 3000)
    struct.pack_into("<I", bad, at, 124)  # size 0: implied by the (huge) count
    with pytest.raises(FormatError, match="hot-spot chunk") as e:
        parse_ssh(bytes(bad), "bad.ssh")
    assert "bad.ssh" in str(e.value) and "image 0" in str(e.value) and e.value.field == "chunk"


def test_size_zero_chunk_is_not_padded():
    """A size-0 chunk spans its header and data exactly (SSX-Library): a 3-colour palette (12 bytes)
    is followed by the long-name chunk at +28, not at the next 16-byte boundary."""
    pix = np.array([[0, 1], [2, 1]], np.uint8)
    pal = np.array([[10, 20, 30, 128], [40, 50, 60, 128], [70, 80, 90, 64]], np.uint8)
    img = struct.pack("<I4hI", 2 | (32 << 8), 2, 2, 0, 0, 0) + pix.tobytes().ljust(16, b"\0")
    pchunk = struct.pack("<I4hI", 33, 3, 1, 3, 0, 0) + pal.tobytes()  # size 0, 12 data bytes, unpadded
    name = struct.pack("<I", 112) + b"abc\0"
    chain = img + pchunk + name
    head = b"SHPS" + struct.pack("<II", 16 + 8 + len(chain), 1) + b"G278" + b"t000" + struct.pack("<I", 24)
    bank = parse_ssh(head + chain, "p.ssh")
    im = bank.images[0]
    np.testing.assert_array_equal(im.palette, pal)
    assert im.long_name == "abc"
    np.testing.assert_array_equal(im.stored_rgba(), pal[pix])
    # unedited, the bank writes back the bytes it was read from, whatever their layout
    assert bank.to_bytes() == head + chain and not bank.edited()
    # piste's own layout writes such a palette with an explicit size (its padding would otherwise be misread)
    bank.images[0].pixels[0, 0] = 2
    assert bank.edited()
    out = bank.to_bytes()
    assert out == bank.encode() != head + chain
    off = struct.unpack_from("<I", out, 20)[0]
    poff = off + 32
    assert out[poff] == 33 and struct.unpack_from("<I", out, poff)[0] >> 8 == 32
    back = parse_ssh(out, "q.ssh")
    np.testing.assert_array_equal(back.images[0].palette, pal)
    assert back.images[0].long_name == "abc" and back.images[0].pixels[0, 0] == 2
    # a whole 256-colour palette keeps size 0 (as the game writes it)
    full = _bank().to_bytes()
    o = struct.unpack_from("<I", full, 20)[0]
    p = o + 16 + 16 * 8
    assert full[p] == 33 and struct.unpack_from("<I", full, p)[0] >> 8 == 0
