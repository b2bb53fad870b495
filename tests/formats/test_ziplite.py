"""piste.formats.ziplite: the plain zip archives piste reads at every start (bundles, the shipped
``.npz`` files) indexed and read without :mod:`zipfile` -- the same entries and arrays as zipfile /
``np.load``; anything it does not read (zip64, a comment, data before the archive, encryption) is
left to zipfile (None), and a bundle render imports no zipfile at all."""

from __future__ import annotations

import io
import json
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from piste.formats.bundle import read_bundle, write_bundle
from piste.formats.ziplite import DEFLATED, STORED, BadZip, member_bytes, read_index, read_npz

DATA = Path(__file__).resolve().parents[2] / "src" / "piste" / "data"


def _fields(entries):
    return [(e.filename, e.header_offset, e.flag_bits, e.compress_type, e.compress_size, e.file_size, e.CRC)
            for e in entries]


def _zip(members, **kw) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", **kw) as zf:
        for name, data, method in members:
            zf.writestr(zipfile.ZipInfo(name), data, compress_type=method)
    return buf.getvalue()


def test_the_index_and_members_are_zipfiles():
    raw = _zip([("a.npy", b"x" * 1000, zipfile.ZIP_STORED), ("b/c.npy", b"yz" * 5000, zipfile.ZIP_DEFLATED),
                ("é.txt", b"utf-8 name", zipfile.ZIP_STORED), ("empty", b"", zipfile.ZIP_DEFLATED)])
    got = read_index(raw)
    with zipfile.ZipFile(io.BytesIO(raw)) as zf:
        assert got is not None and _fields(got) == _fields(zf.infolist())
        for e in got:
            data = member_bytes(raw, e)
            assert data is not None and bytes(data) == zf.read(e.filename)
    assert {e.compress_type for e in got} == {STORED, DEFLATED}


@pytest.mark.parametrize("how", ["comment", "prefix", "zip64", "truncated", "not_a_zip", "empty"])
def test_what_it_does_not_read_is_left_to_zipfile(how):
    raw = _zip([("a.npy", b"x" * 100, zipfile.ZIP_STORED)])
    if how == "comment":
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w") as zf:
            zf.writestr("a", b"x")
            zf.comment = b"hello"
        raw = buf.getvalue()
    elif how == "prefix":
        raw = b"#!/bin/sh\n" + raw
    elif how == "zip64":
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w") as zf, zf.open("a", "w", force_zip64=True) as fh:
            fh.write(b"x" * 10)
        raw = buf.getvalue()
        # (zipfile writes a zip64 end record only past its limits: add one as a bigger archive has it)
        with zipfile.ZipFile(io.BytesIO(raw)) as zf:
            assert zf.read("a") == b"x" * 10
        raw = raw[:-22] + b"PK\x06\x07" + b"\0" * 16 + raw[-22:]
    elif how == "truncated":
        raw = raw[:-30] + raw[-22:]
    elif how == "not_a_zip":
        raw = b"just some bytes, no archive at all" * 3
    else:
        raw = b""
    assert read_index(raw) is None


def test_a_corrupt_deflated_member_raises():
    raw = bytearray(_zip([("a.npy", bytes(range(256)) * 40, zipfile.ZIP_DEFLATED)]))
    e = read_index(bytes(raw))[0]
    raw[e.header_offset + 30 + len(e.filename) + 5] ^= 0xFF
    with pytest.raises((BadZip, __import__("zlib").error)):
        member_bytes(bytes(raw), e)


def test_read_npz_is_np_load(tmp_path):
    arrays = {"a": np.arange(12.0).reshape(3, 4), "b": np.zeros((0, 3), np.int16), "c": np.array(3.5),
              "f": np.asfortranarray(np.arange(6).reshape(2, 3)), "be": np.arange(4, dtype=">u4"),
              "s": np.array(["ab", "c"]), "rec": np.zeros(2, dtype=[("x", "<f4"), ("y", "u1")])}
    for save in (np.savez, np.savez_compressed):
        path = tmp_path / f"{save.__name__}.npz"
        save(path, **arrays)
        got = read_npz(path)
        with np.load(path) as z:
            want = {k: z[k] for k in z.files}
        assert list(got) == list(want)
        for k, a in want.items():
            assert got[k].dtype == a.dtype and got[k].shape == a.shape and np.array_equal(got[k], a), k
            assert got[k].flags.f_contiguous == a.flags.f_contiguous and got[k].flags.writeable, k
    for shipped in sorted(DATA.glob("*.npz")):  # the files a render reads
        with np.load(shipped) as z:
            want = {k: z[k] for k in z.files}
        got = read_npz(shipped)
        assert list(got) == list(want) and all(np.array_equal(got[k], want[k]) for k in want), shipped.name


def test_read_npz_errors_are_np_loads(tmp_path):
    with pytest.raises(OSError):
        read_npz(tmp_path / "missing.npz")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not an archive")
    with pytest.raises(Exception) as e:  # noqa: PT011 - whatever np.load raises for it
        read_npz(bad)
    with pytest.raises(type(e.value)):
        np.load(bad)
    # a member whose bytes rotted: np.load (zipfile) reads it and reports the bad CRC-32
    path = tmp_path / "ok.npz"
    np.savez(path, a=np.arange(100))
    raw = bytearray(path.read_bytes())
    raw[raw.index(b"NUMPY") + 200] ^= 0x01
    path.write_bytes(bytes(raw))
    with pytest.raises(zipfile.BadZipFile):
        read_npz(path)


def test_a_bundle_reads_the_same_without_and_through_zipfile(tmp_path, monkeypatch):
    """The bundle reader through ziplite and, for an archive it does not read, through zipfile: the
    same manifest and arrays."""
    from piste.formats import bundle as fmt

    rng = np.random.default_rng(1)
    arrays = {"terrain/control_points": rng.normal(size=(4, 4, 4, 3)), "terrain/uv": rng.random((4, 4, 2), np.float32),
              "lightmap/atlas": rng.random((20, 20, 3), np.float32), "lightmap/rects": rng.random((4, 4), np.float32),
              "x/big": np.zeros(100_000)}
    path = write_bundle(tmp_path / "b.piste", {"name": "x"}, arrays)
    fast = read_bundle(path)
    monkeypatch.setattr(fmt, "read_index", lambda buf: None)
    slow = read_bundle(path)
    assert json.dumps(fast.manifest, sort_keys=True) == json.dumps(slow.manifest, sort_keys=True)
    assert list(fast.arrays) == list(slow.arrays)
    assert all(np.array_equal(fast.arrays[k], slow.arrays[k]) for k in arrays)


def test_a_bundle_render_imports_no_zipfile(tmp_path):
    """Reading a bundle and the shipped files a render reads (the resident templates, the snow
    texture) imports no zipfile, bz2 or lzma in a fresh process (tests/test_lazy_imports.py checks
    what importing the runtime does)."""
    arrays = {"terrain/control_points": np.zeros((1, 4, 4, 3)), "terrain/uv": np.zeros((1, 4, 2), np.float32),
              "lightmap/atlas": np.zeros((4, 4, 3), np.float32), "lightmap/rects": np.zeros((1, 4), np.float32)}
    path = write_bundle(tmp_path / "b.piste", {"name": "x"}, arrays)
    code = ("import sys\nfrom piste.formats.bundle import read_bundle\n"
            "from piste.terrain.resident import LEVELS, shipped_templates\n"
            "from piste.render.textures import snow_texture\n"
            f"read_bundle({str(path)!r})\nassert shipped_templates(LEVELS) is not None\nsnow_texture()\n"
            "print(sorted(m for m in ('zipfile', 'bz2', 'lzma') if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.splitlines()[-1] == "[]"
