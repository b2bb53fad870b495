"""How a bundle is read at every start: the big members stored uncompressed, headers matched instead
of parsed, the stored bytes checked once (by the manifest's SHA-256 when verifying, else by the
zip's CRC-32) -- the same arrays and the same errors as numpy's own reader."""

from __future__ import annotations

import io
import json
import zipfile

import numpy as np
import pytest

from piste.errors import FormatError
from piste.formats.bundle import RESIDENT_MEMBER, STORED_MEMBERS, read_bundle, write_bundle


def _bundle(tmp_path, name="b.piste"):
    rng = np.random.default_rng(3)
    arrays = {
        "terrain/control_points": rng.normal(size=(4, 4, 4, 3)),
        "terrain/uv": rng.random((4, 4, 2), dtype=np.float32),
        "lightmap/atlas": rng.random((20, 20, 3), dtype=np.float32),
        "lightmap/rects": rng.random((4, 4), dtype=np.float32),
        "a/flags": rng.random(7) > 0.5,
        "a/scalar": np.array(3.5),
        "a/empty": np.zeros((0, 3), np.int16),
        "a/big_endian": np.arange(6, dtype=">u4").reshape(2, 3),
        RESIDENT_MEMBER: rng.random((10, 11), dtype=np.float32),
    }
    return write_bundle(tmp_path / name, {"name": "x"}, arrays), arrays


def _flipped(path, member, tmp_path):
    """A copy of bundle ``path`` (``tmp_path / "flipped.piste"``) with one bit flipped three bytes
    before the end of ``member``'s data."""
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo(member + ".npy")
        offset = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra) + info.compress_size - 3
    raw = bytearray(path.read_bytes())
    raw[offset] ^= 0x10
    flipped = tmp_path / "flipped.piste"
    flipped.write_bytes(bytes(raw))
    return flipped


def _rewrite(src, dst, edit):
    """Copy bundle ``src`` to ``dst`` with ``edit(name, data, manifest) -> data`` applied to each member."""
    with zipfile.ZipFile(src) as zf:
        man = json.loads(zf.read("manifest.json"))
        items = [(i, zf.read(i.filename)) for i in zf.infolist()]
    out = [(i, edit(i.filename, d, man)) for i, d in items if i.filename != "manifest.json"]
    with zipfile.ZipFile(dst, "w") as zf:
        zf.writestr("manifest.json", json.dumps(man))
        for info, data in out:
            zf.writestr(info, data)
    return dst


def test_big_members_stored_the_rest_deflated(tmp_path):
    """The members read at every start and every small one are stored; a big other one is deflated
    (and reads back the same)."""
    from piste.formats.bundle import SMALL_MEMBER_BYTES

    _, arrays = _bundle(tmp_path)
    arrays["a/big"] = np.zeros(SMALL_MEMBER_BYTES // 8 + 1)  # just over the bound
    arrays["a/just_small"] = np.zeros((SMALL_MEMBER_BYTES - 128) // 8)  # (its .npy header: 128 bytes)
    path = write_bundle(tmp_path / "big.piste", {"name": "x"}, arrays)
    assert {"lightmap/atlas", "terrain/control_points", RESIDENT_MEMBER} <= STORED_MEMBERS
    with zipfile.ZipFile(path) as zf:
        kinds = {i.filename[:-4]: i.compress_type for i in zf.infolist() if i.filename.endswith(".npy")}
        assert zf.getinfo("manifest.json").compress_type == zipfile.ZIP_DEFLATED
    assert {n for n, c in kinds.items() if c == zipfile.ZIP_DEFLATED} == {"a/big"}
    got = read_bundle(path).arrays
    assert all(np.array_equal(got[n], a) for n, a in arrays.items() if n != "a/scalar")
    assert got["a/big"].flags.writeable and got["a/just_small"].flags.writeable  # (not in STORED_MEMBERS: copies)


@pytest.mark.parametrize("verify", [True, False])
def test_arrays_as_numpy_reads_them(tmp_path, verify):
    """Every member equals ``np.lib.format.read_array`` of its bytes (dtype, shape, values); the
    stored ones are read-only views, the others writable copies of their own."""
    path, arrays = _bundle(tmp_path)
    got = read_bundle(path, verify=verify).arrays
    with zipfile.ZipFile(path) as zf:
        for name in arrays:
            ref = np.lib.format.read_array(io.BytesIO(zf.read(name + ".npy")))
            a = got[name]
            assert a.dtype == ref.dtype and a.shape == ref.shape and np.array_equal(a, ref), name
            assert a.flags.writeable == (name not in STORED_MEMBERS), name
            if name not in STORED_MEMBERS:
                assert a.flags.owndata or a.base is not None and a.base.flags.owndata


@pytest.mark.parametrize("version", [(1, 0), (2, 0), (3, 0)])
def test_other_headers_parsed(tmp_path, version):
    """A member whose .npy header is not byte for byte the one piste writes (another version, Fortran
    order) is parsed as numpy parses it: the same array (a stored member's too, as a view)."""
    path, arrays = _bundle(tmp_path)
    import hashlib

    def edit(name, data, man):
        if name not in ("a/big_endian.npy", "lightmap/atlas.npy"):
            return data
        a = arrays[name[:-4]]
        buf = io.BytesIO()
        fortran = version == (1, 0) and name == "a/big_endian.npy"  # (stored members must be C order)
        np.lib.format.write_array(buf, np.asfortranarray(a) if fortran else a, version=version)
        man["members"][name[:-4]]["sha256"] = hashlib.sha256(buf.getvalue()).hexdigest()
        return buf.getvalue()

    other = _rewrite(path, tmp_path / "other.piste", edit)
    got = read_bundle(other).arrays
    for name in ("a/big_endian", "lightmap/atlas"):
        assert np.array_equal(got[name], arrays[name]) and got[name].dtype == arrays[name].dtype


def test_a_manifest_that_lies_about_a_member(tmp_path):
    """A shape or dtype in the manifest that is not the member's: the header does not match, numpy
    parses it, and the check names the member."""
    path, _ = _bundle(tmp_path)
    for field, value in (("shape", [5, 2]), ("dtype", "<i4")):
        def edit(name, data, man, field=field, value=value):
            man["members"]["a/big_endian"][field] = value
            return data

        bad = _rewrite(path, tmp_path / f"lie_{field}.piste", edit)
        with pytest.raises(FormatError, match="expected shape") as e:
            read_bundle(bad, verify=False)
        assert e.value.field == "a/big_endian.npy"


@pytest.mark.parametrize("member", ["lightmap/atlas", RESIDENT_MEMBER, "lightmap/rects"])
def test_a_flipped_byte_is_a_corrupt_member_whether_verifying_or_not(tmp_path, member):
    """A byte flipped in a member's data: "corrupt member" (the CRC-32: computed by zipfile, or for a
    stored member whose SHA-256 failed, by the reader), verified or not; a right CRC with a wrong
    SHA-256: "checksum mismatch"."""
    path, _ = _bundle(tmp_path)
    flipped = _flipped(path, member, tmp_path)
    for verify in (True, False):
        with pytest.raises(FormatError, match="corrupt member") as e:
            read_bundle(flipped, verify=verify)
        assert e.value.field == member + ".npy"

    def edit(name, data, man):
        man["members"][member]["sha256"] = "f" * 64
        return data

    wrong = _rewrite(path, tmp_path / "wrong.piste", edit)
    with pytest.raises(FormatError, match="checksum mismatch") as e:
        read_bundle(wrong)
    assert e.value.field == member + ".npy"
    read_bundle(wrong, verify=False)  # not verified: read


def test_a_truncated_member_names_it(tmp_path):
    """A member shorter than the zip says (its sizes edited in the index): a FormatError naming it."""
    path, _ = _bundle(tmp_path)
    raw = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo("lightmap/atlas.npy")
    # the central directory entry of the member: its compressed and uncompressed sizes one byte more
    name = info.filename.encode()
    at = raw.index(name, raw.index(b"PK\x01\x02")) - 46
    assert raw[at:at + 4] == b"PK\x01\x02"
    for off in (20, 24):
        size = int.from_bytes(raw[at + off:at + off + 4], "little")
        raw[at + off:at + off + 4] = (size + 1).to_bytes(4, "little")
    bad = tmp_path / "short.piste"
    bad.write_bytes(bytes(raw))
    for verify in (True, False):
        with pytest.raises(FormatError) as e:
            read_bundle(bad, verify=verify)
        assert e.value.field == "lightmap/atlas.npy"


def test_stored_members_are_views_of_the_mapped_file(tmp_path):
    """The uncompressed members are read-only views of the bundle's mapped bytes (no copy), and keep
    their values when a rebuild replaces the file (written to a temporary file and renamed)."""
    import mmap
    import os

    path, arrays = _bundle(tmp_path)
    got = read_bundle(path).arrays
    for name in STORED_MEMBERS & set(arrays):
        a = got[name]
        assert not a.flags.writeable and np.array_equal(a, arrays[name])
        base = a
        while getattr(base, "base", None) is not None and not isinstance(base, (memoryview, mmap.mmap)):
            base = base.base
        if os.name == "posix":
            assert isinstance(base, memoryview) and isinstance(base.obj, mmap.mmap), name
    other = {k: (v + 1 if v.dtype.kind == "f" else v) for k, v in arrays.items()}
    write_bundle(path, {"name": "x"}, other)  # atomic: a new file renamed over the old one
    for name in STORED_MEMBERS & set(arrays):
        assert np.array_equal(got[name], arrays[name])
    assert np.array_equal(read_bundle(path).arrays["lightmap/atlas"], arrays["lightmap/atlas"] + 1)


def test_big_stored_members_are_hashed_by_a_second_thread_and_checked_before_return(tmp_path, monkeypatch):
    """The big uncompressed members that are not the terrain's go to a second thread's SHA-256 (here
    every such member: the size bound at 0): the same arrays in the manifest's order, and a wrong byte or
    hash still names the member; ``on_terrain`` is called before any of them is in the arrays."""
    import threading

    from piste.formats import bundle as fmt

    monkeypatch.setattr(fmt._Hasher, "MIN_BYTES", 0)
    monkeypatch.setattr(fmt._Hasher, "HAND_OFF_SHARE", 1.0)
    hashed = []
    real = fmt._sha256
    monkeypatch.setattr(fmt, "_sha256", lambda data: hashed.append(threading.current_thread().name) or real(data))
    path, _ = _bundle(tmp_path)
    seen = {}
    got = read_bundle(path, on_terrain=lambda man, part: seen.update(part))
    plain = read_bundle(path, verify=False).arrays  # (no second thread when not verifying)
    assert list(got.arrays) == list(plain)  # (the terrain's first, as read)
    assert all(np.array_equal(got.arrays[n], a) and got.arrays[n].dtype == a.dtype for n, a in plain.items())
    assert hashed.count("piste-bundle-sha256") == 2  # the atlas and the vertex blocks (not the terrain's)
    assert "lightmap/atlas" not in seen and RESIDENT_MEMBER not in seen and "terrain/control_points" in seen
    for member in ("lightmap/atlas", RESIDENT_MEMBER):
        flipped = _flipped(path, member, tmp_path)
        with pytest.raises(FormatError, match="corrupt member") as e:
            read_bundle(flipped)
        assert e.value.field == member + ".npy"

        def edit(name, data, man, member=member):
            man["members"][member]["sha256"] = "0" * 64
            return data

        with pytest.raises(FormatError, match="checksum mismatch") as e:
            read_bundle(_rewrite(path, tmp_path / "wrong.piste", edit))
        assert e.value.field == member + ".npy"


def test_deferred_checks_name_the_corrupt_member_when_finished(tmp_path, monkeypatch):
    """read_bundle_deferred: the big uncompressed members (here every one not the terrain's) are
    checked in the second thread after it returns -- SHA-256 when verifying, else the zip's CRC-32 --
    and ``finish()`` raises the FormatError naming a corrupt one (once; later calls do nothing); the
    arrays are those read_bundle returns."""
    import threading

    from piste.formats import bundle as fmt

    monkeypatch.setattr(fmt._Hasher, "MIN_BYTES", 0)
    threads = []
    real_run = fmt._Hasher._run
    monkeypatch.setattr(fmt._Hasher, "_run", lambda self: threads.append(threading.current_thread().name) or real_run(self))
    path, arrays = _bundle(tmp_path)
    for verify in (True, False):
        data, finish = fmt.read_bundle_deferred(path, verify=verify)
        finish()
        finish()
        assert list(data.arrays) == list(read_bundle(path, verify=verify).arrays)
        assert all(np.array_equal(data.arrays[n], a) for n, a in arrays.items())
    assert threads.count("piste-bundle-sha256") >= 2  # (the CRC-32 too when not verifying)
    flipped = _flipped(path, RESIDENT_MEMBER, tmp_path)
    for verify in (True, False):
        data, finish = fmt.read_bundle_deferred(flipped, verify=verify)  # (returns: the check is pending)
        with pytest.raises(FormatError, match="corrupt member") as e:
            finish()
        assert e.value.field == RESIDENT_MEMBER + ".npy"
        finish()  # (reported once)
        with pytest.raises(FormatError, match="corrupt member") as e:
            read_bundle(flipped, verify=verify)
        assert e.value.field == RESIDENT_MEMBER + ".npy"


def test_a_corrupt_member_is_named_before_what_its_bytes_broke(tmp_path, monkeypatch):
    """A handed-off member whose bad bytes make the reader (or the caller's own work) fail before its
    check is reported as the corrupt member it is, not by what it broke."""
    from piste.formats import bundle as fmt

    monkeypatch.setattr(fmt._Hasher, "MIN_BYTES", 0)
    path, _ = _bundle(tmp_path)

    def edit(name, data, man):  # a bad .npy header in the atlas (its hash in the manifest is the old one)
        return data.replace(b"'descr'", b"'descX'") if name == "lightmap/atlas.npy" else data

    bad = _rewrite(path, tmp_path / "bad_header.piste", edit)
    for reader in (read_bundle, lambda p: fmt.read_bundle_deferred(p)[1]()):
        with pytest.raises(FormatError, match="checksum mismatch") as e:
            reader(bad)
        assert e.value.field == "lightmap/atlas.npy"


def test_the_member_hash_is_hashlibs_sha256():
    """The reader's SHA-256 (OpenSSL's constructor, loaded without hashlib's other algorithms) is
    hashlib.sha256's hex digest, for bytes and for views of a mapped file alike."""
    import hashlib

    from piste.formats.bundle import _sha256

    data = np.random.default_rng(0).bytes(70_001)
    assert _sha256(data) == _sha256(memoryview(data)[:]) == hashlib.sha256(data).hexdigest()
    assert _sha256(b"") == hashlib.sha256(b"").hexdigest()
