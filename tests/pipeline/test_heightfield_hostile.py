"""Hostile height fields (issue 10 item 3): pixel and array sizes checked from headers before
decoding (a 130 KB PNG took 13.9 GB), .npz members validated, non-finite heights refused."""

from __future__ import annotations

import io
import struct
import zipfile
import zlib

import numpy as np
import pytest

from piste.errors import FormatError
from piste.pipeline.sources import load_heightfield
from piste.world.scene_file import TerrainSpec


def _spec(path, **kw):
    kind = "heightfield"
    return TerrainSpec(kind=kind, path=path, **kw)


def _png_header_only(w, h):
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b""))


def test_png_with_huge_dimensions_refused_from_its_header(tmp_path):
    p = tmp_path / "bomb.png"
    p.write_bytes(_png_header_only(8000, 8000))
    with pytest.raises(FormatError, match=r"bomb\.png: height field of 8000 x 8000 samples is more than"):
        load_heightfield(_spec(p, spacing=(1.0, 1.0)))


def _npz_with_header(path, name, shape, dtype="<f8"):
    """An .npz whose member only *claims* ``shape`` (header, no data)."""
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": dtype, "fortran_order": False, "shape": shape})
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr(name + ".npy", buf.getvalue())


def test_npz_member_claiming_huge_shape_refused_before_reading(tmp_path):
    p = tmp_path / "big.npz"
    _npz_with_header(p, "z", (200000, 200000))
    with pytest.raises(FormatError, match=r"big\.npz, field 'z': array 'z' of shape \(200000, 200000\)"):
        load_heightfield(_spec(p, spacing=(1.0, 1.0)))


def test_npz_truncated_member(tmp_path):
    p = tmp_path / "short.npz"
    _npz_with_header(p, "z", (10, 10))
    with pytest.raises(FormatError, match=r"short\.npz.*'z'"):
        load_heightfield(_spec(p, spacing=(1.0, 1.0)))


@pytest.mark.parametrize("extra, match", [
    ({"dx": np.array(-1.0)}, "field 'dx'"),
    ({"dx": np.array(np.nan)}, "field 'dx'"),
    ({"dx": np.zeros((0,))}, "field 'dx'"),
    ({"spacing": np.zeros((0,))}, "field 'spacing'"),
    ({"dx": np.array(["a"])}, "field 'dx'"),
])
def test_npz_bad_spacing_members(tmp_path, extra, match):
    p = tmp_path / "h.npz"
    np.savez(p, z=np.zeros((9, 9)), **extra)
    with pytest.raises(FormatError, match=match):
        load_heightfield(_spec(p))


def test_npz_non_finite_heights(tmp_path):
    z = np.zeros((9, 9))
    z[3, 3] = np.nan
    p = tmp_path / "nan.npz"
    np.savez(p, z=z, dx=np.array(2.0))
    with pytest.raises(FormatError, match=r"nan\.npz: height field has 1 non-finite"):
        load_heightfield(_spec(p))


def test_npz_single_npy_is_refused(tmp_path):
    p = tmp_path / "one.npz"
    with open(p, "wb") as fh:
        np.save(fh, np.zeros((9, 9)))
    with pytest.raises(FormatError, match=r"one\.npz"):
        load_heightfield(_spec(p))


def test_valid_npz_and_png_still_load(tmp_path):
    from PIL import Image

    np.savez(tmp_path / "ok.npz", z=np.arange(81.0).reshape(9, 9), dx=np.array(2.0))
    z, sp = load_heightfield(_spec(tmp_path / "ok.npz"))
    assert z.shape == (9, 9) and sp == (2.0, 2.0)
    Image.fromarray(np.arange(81, dtype=np.uint8).reshape(9, 9)).save(tmp_path / "ok.png")
    z, sp = load_heightfield(_spec(tmp_path / "ok.png", spacing=(1.0, 1.0)))
    assert z.shape == (9, 9) and z[1, 0] == 9
