"""Fuzz GeoTIFF DEMs (read_geotiff): seeds written by piste's own write_geotiff, mutated byte-wise,
at the TIFF directory level (an IFD entry's type, count or value/offset replaced by boundary values)
and at the tag level (the GeoTIFF tags rewritten with wrong counts, types and values).  Each case
loads or raises a PisteError naming the file, under a time and a memory cap (see fuzzlib)."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from fuzzlib import byte_mutations, check, fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

tifffile = pytest.importorskip("tifffile")

from piste.formats.geotiff import read_geotiff, write_geotiff  # noqa: E402

_SCALE, _TIE, _GEOKEYS, _DOUBLES, _NODATA, _TRANSFORM = 33550, 33922, 34735, 34736, 42113, 34264


def _heights(h=9, w=11):
    y, x = np.mgrid[0:h, 0:w]
    return 100.0 + 3.0 * np.sin(x / 2.0) + 0.5 * y


@pytest.fixture(scope="session")
def geotiff_seed(tmp_path_factory):
    """A 9 x 11 float32 DEM with a nodata sample, an EPSG code and foot heights."""
    d = tmp_path_factory.mktemp("geotiff")
    z = _heights()
    z[4, 5] = -9999.0
    return write_geotiff(d / "dem.tif", z, (10.0, 12.5), origin=(500_000.0, 4_000_000.0), nodata=-9999.0,
                         vertical_units="foot", epsg=32633)


def _load(path):
    read_geotiff(path)


def test_seed_loads(geotiff_seed):
    assert check(_load, geotiff_seed, "geotiff seeds") == "loaded"


@pytest.fixture(scope="session")
def geotiff_zlib(geotiff_seed):
    """The seed rewritten deflate-compressed in 4-row strips (same GeoTIFF tags)."""
    with tifffile.TiffFile(geotiff_seed) as tf:
        page = tf.pages[0]
        z = page.asarray()
        tags = [(t.code, t.dtype, t.count, t.value, False) for t in page.tags.values()
                if t.code in (_SCALE, _TIE, _GEOKEYS, _NODATA)]
    out = geotiff_seed.with_name("dem_zlib.tif")
    tifffile.imwrite(out, z, extratags=tags, compression="zlib", rowsperstrip=4, photometric="minisblack")
    return out


def test_zlib_seed_loads(geotiff_zlib):
    assert check(_load, geotiff_zlib, "geotiff seeds") == "loaded"


@pytest.mark.parametrize("compressed", [False, True], ids=["raw", "zlib"])
@given(data=st.data())
@fuzz_settings(15)
def test_geotiff_bytes(geotiff_seed, geotiff_zlib, compressed, tmp_path_factory, data):
    seed = geotiff_zlib if compressed else geotiff_seed
    target = tmp_path_factory.mktemp("m") / "mutant.tif"
    target.write_bytes(data.draw(byte_mutations(seed.read_bytes())))
    check(_load, target, "geotiff byte-wise")


def _ifd_entries(data: bytes) -> list[int]:
    """Byte offsets of the first IFD's 12-byte entries (classic little-endian TIFF)."""
    assert data[:4] == b"II*\0"
    (off,) = struct.unpack_from("<I", data, 4)
    (n,) = struct.unpack_from("<H", data, off)
    return [off + 2 + 12 * k for k in range(n)]


@given(data=st.data())
@fuzz_settings(30)
def test_geotiff_ifd_entries(geotiff_seed, tmp_path_factory, data):
    """An IFD entry's type (u16), count (u32) or value/offset (u32) set to a boundary value: counts
    past the file's end, offsets into the header or past the end, types TIFF does not have."""
    raw = bytearray(geotiff_seed.read_bytes())
    entries = _ifd_entries(bytes(raw))
    for _ in range(data.draw(st.integers(1, 3))):
        e = data.draw(st.sampled_from(entries))
        part = data.draw(st.sampled_from(["type", "count", "value"]))
        if part == "type":
            struct.pack_into("<H", raw, e + 2, data.draw(st.sampled_from([0, 1, 2, 5, 7, 12, 13, 16, 17, 99, 0xFFFF])))
        else:
            v = data.draw(st.one_of(st.sampled_from([0, 1, 2, 3, 7, 8, len(raw) - 1, len(raw), len(raw) + 1,
                                                      1 << 20, 0x7FFFFFFF, 0xFFFFFFFF]),
                                    st.integers(0, 0xFFFFFFFF)))
            struct.pack_into("<I", raw, e + (4 if part == "count" else 8), v)
    target = tmp_path_factory.mktemp("m") / "mutant.tif"
    target.write_bytes(bytes(raw))
    check(_load, target, "geotiff IFD entries")


_VALUES = st.sampled_from([
    (), (0.0,), (1.0, 1.0), (np.nan, 1.0, 0.0), (np.inf, 10.0, 0.0), (-10.0, 10.0, 0.0), (0.0, 0.0, 0.0),
    (1e308, 1e308, 1e308), (1e-308, 1e-308, 0.0), (10.0, 10.0, 0.0, 0.0, 0.0, 0.0),
    (0.0, 0.0, 0.0, 1e308, -1e308, 0.0), (0.0, 0.0, 0.0, np.nan, 0.0, 0.0), (1e9, 1e9, 0.0, 5.0, 5.0, 0.0),
    tuple(float(v) for v in range(16)), (1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0, 0, 0, 1),
    (0.0,) * 16, (2.0, 1.0, 0.0, 0.0, 1.0, -2.0) + (0.0,) * 10,
])
_KEYS = st.sampled_from([
    (), (1, 1, 0), (1, 1, 0, 1), (1, 1, 0, 0xFFFF), (1, 1, 0, 1, 1024, 0, 1, 2),
    (1, 1, 0, 2, 1024, 0, 1, 2, 1025, 0, 1, 2), (1, 1, 0, 1, 4099, 0, 1, 1234), (1, 1, 0, 1, 4099, 0, 1, 32767),
    (1, 1, 0, 1, 4099, _DOUBLES, 1, 0), (1, 1, 0, 1, 4099, _DOUBLES, 0xFFFF, 0xFFFF),
    (1, 1, 0, 1, 3076, _DOUBLES, 3, 0), (1, 1, 0, 1, 1025, _DOUBLES, 2, 0), (1, 1, 0, 1, 3076, 0, 1, 9036),
    (1, 1, 0, 2, 1024, 0, 1, 2, 4099, 0, 1, 9002), (0xFFFF,) * 8,
])
_NODATAS = st.sampled_from(["", "nan", "-inf", "1e999", "abc", "100", "-9999", "\x00", "1,5", "0x10"])


@given(data=st.data())
@fuzz_settings(40)
def test_geotiff_tags(tmp_path_factory, data):
    """The GeoTIFF tags themselves rewritten (a valid TIFF around them): scales, tie points and
    transforms of wrong lengths and non-finite, zero, negative or huge values; GeoKey directories
    shorter than their header, keys in the doubles tag past its end, unknown unit codes; nodata
    texts that are not numbers; tags stored as text; rasters of odd shapes and sample types."""
    shape = data.draw(st.sampled_from([(9, 11)] * 4 + [(1, 11), (2, 2), (9, 1), (3, 4, 2), (9, 11, 1), (0, 0)]))
    dtype = data.draw(st.sampled_from(["float32"] * 3 + ["float64", "int16", "uint8", "complex64", "bool"]))
    z = np.zeros(shape, dtype=dtype) if 0 in shape else (np.arange(int(np.prod(shape))) % 7).reshape(shape).astype(dtype)
    tags = {_SCALE: (_SCALE, "d", 3, (10.0, 10.0, 0.0), False), _TIE: (_TIE, "d", 6, (0.0, 0.0, 0.0, 5e5, 4e6, 0.0), False),
            _GEOKEYS: (_GEOKEYS, "H", 8, (1, 1, 0, 1, 1024, 0, 1, 1), False)}
    for code in data.draw(st.lists(st.sampled_from([_SCALE, _TIE, _GEOKEYS, _DOUBLES, _NODATA, _TRANSFORM]),
                                   max_size=3, unique=True)):
        if data.draw(st.integers(0, 4)) == 0:
            tags.pop(code, None)
            continue
        if code == _GEOKEYS:
            v = data.draw(_KEYS)
            tags[code] = (code, "H", len(v), v, False) if v else (code, "s", 0, "text", False)
        elif code == _NODATA:
            tags[code] = (code, "s", 0, data.draw(_NODATAS), False)
        else:
            v = data.draw(_VALUES)
            tags[code] = (code, "d", len(v), v, False) if v else (code, "s", 0, "1 2 3", False)
    target = tmp_path_factory.mktemp("m") / "tags.tif"
    try:
        tifffile.imwrite(target, z, extratags=list(tags.values()))
    except Exception:  # tifffile refuses to write it: nothing to read
        return
    check(_load, target, "geotiff tags")


# ------------------------------------------------------------------------------ regressions (findings)
from piste.errors import FormatError  # noqa: E402


def _set_entry(data: bytes, tag: int, type_=None, count=None, value=None) -> bytes:
    raw = bytearray(data)
    for e in _ifd_entries(data):
        if struct.unpack_from("<H", raw, e)[0] == tag:
            if type_ is not None:
                struct.pack_into("<H", raw, e + 2, type_)
            if count is not None:
                struct.pack_into("<I", raw, e + 4, count)
            if value is not None:
                struct.pack_into("<I", raw, e + 8, value)
            return bytes(raw)
    raise AssertionError(f"no tag {tag}")


def test_huge_image_width_in_a_small_file_is_refused_before_decoding(geotiff_seed, tmp_path):
    """Finding: ImageWidth 59,652,435 in a 500-byte file made tifffile allocate 2 GiB."""
    p = tmp_path / "wide.tif"
    p.write_bytes(_set_entry(geotiff_seed.read_bytes(), 256, value=59_652_435))
    with pytest.raises(FormatError, match="wide.tif") as e:
        read_geotiff(p)
    assert e.value.field == "StripByteCounts"


def test_image_width_stored_as_bytes_is_a_format_error(geotiff_seed, tmp_path):
    """Finding: ImageWidth retyped to BYTE x 3 gave ``int(tuple)``: a raw TypeError."""
    p = tmp_path / "w.tif"
    p.write_bytes(_set_entry(geotiff_seed.read_bytes(), 256, type_=1, count=3))
    with pytest.raises(FormatError, match="w.tif"):
        read_geotiff(p)


@pytest.mark.parametrize("code,field", [(_SCALE, "ModelPixelScaleTag"), (_TIE, "ModelTiepointTag"),
                                        (_TRANSFORM, "ModelTransformationTag"), (_GEOKEYS, "GeoKeyDirectoryTag")])
def test_georeferencing_tags_holding_text_are_format_errors(tmp_path, code, field):
    """Finding: a GeoTIFF tag stored as ASCII gave ``float('1 2 3')``: a raw ValueError."""
    tags = [(code, "s", 0, "1 2 3", False)]
    if code != _SCALE and code != _TRANSFORM:
        tags += [(_SCALE, "d", 3, (1.0, 1.0, 0.0), False), (_TIE, "d", 6, (0.0,) * 6, False)]
    tags = {t[0]: t for t in reversed(tags)}.values()  # the text tag wins
    p = tmp_path / "t.tif"
    tifffile.imwrite(p, np.zeros((4, 4), np.float32), extratags=list(tags))
    with pytest.raises(FormatError, match="t.tif") as e:
        read_geotiff(p)
    assert e.value.field == field


def test_geokey_values_past_64_bits_are_a_format_error(geotiff_seed, tmp_path):
    """Finding: GeoKeyDirectory retyped to RATIONAL/LONG8 values past int64 gave an OverflowError."""
    p = tmp_path / "k.tif"
    tifffile.imwrite(p, np.zeros((4, 4), np.float32), extratags=[
        (_SCALE, "d", 3, (1.0, 1.0, 0.0), False), (_TIE, "d", 6, (0.0,) * 6, False),
        (_GEOKEYS, "Q", 4, (1, 1, 0, 2**64 - 1), False)])
    with pytest.raises(FormatError, match="k.tif") as e:
        read_geotiff(p)
    assert e.value.field == "GeoKeyDirectoryTag"
