"""The ``.piste`` bundle: everything ``piste build`` pre-processed for a scene, in one file.

Layout: a zip archive with

* ``manifest.json`` -- ``{"format": "piste.bundle/2", ...}``: the scene's name, lights, cameras,
  riders, objects, settings, and a ``members`` table (shape, dtype and SHA-256 of each array);
* one ``.npy`` member per array, named by path (``terrain/control_points.npy``,
  ``lightmap/atlas.npy``, ``visibility/patch_bits.npy``, ``characters/<model>/lod0/strips.npy``, ...);
  the terrain net's topology as the build computed it (:data:`TOPOLOGY_MEMBERS`, ``terrain.topology``
  in the manifest: a load checks it against the control points instead of welding them again; a
  bundle without it is still read, its topology computed).

Format 2 (``piste.bundle/2``) adds the terrain's GPU-resident vertex blocks as the member
``terrain/resident_blocks`` (``manifest.terrain.resident``; stored without compression, so a load
reads them at disk speed instead of a fresh process building them before its first frame).  A
``piste.bundle/1`` bundle is still read (the blocks are then built at run time); any other version
is refused with a message naming ``piste build``.

Members are sorted, every timestamp is 1980-01-01 and arrays are written with fixed headers, so the
same content gives the same bytes.  The file is written atomically (temp file + rename).

:func:`read_bundle` checks the format version and every member (zip CRC, shape, dtype, and the
manifest's SHA-256) and raises :class:`~piste.errors.FormatError` naming the file and member on a
wrong version or a corrupt file.  The uncompressed members are read-only views of the file mapped
into memory (POSIX; elsewhere read), each checked once: by its SHA-256 when verifying (the zip's
CRC-32 only where the hash fails, to tell a corrupt member from a wrong checksum), else by the
CRC-32; the others are read by zipfile (CRC-32) and hashed.  A ``.npy`` header that is
byte for byte the one :func:`write_bundle` writes for the manifest's shape and dtype is matched, not
parsed (numpy parses any other).

This module only reads and writes arrays and metadata (:class:`BundleData`); it imports nothing
from the layers above.  Turning them into the scene's objects (terrain net, light map, lights,
cameras, visibility, objects, characters) is :func:`piste.pipeline.load_bundle`
(:mod:`piste.pipeline.bundle_objects`).

API
---
BUNDLE_FORMAT                         "piste.bundle/2" (READ_FORMATS: also reads "piste.bundle/1")
write_bundle(path, manifest, arrays)  atomic, deterministic (STORED_MEMBERS uncompressed)
read_bundle(path, verify=True) -> BundleData   ``.path``, ``.manifest``, ``.arrays`` (checked)
read_bundle_deferred(path, verify=True) -> (BundleData, finish)   the big members checked in the background
read_manifest(path) -> dict           the manifest only (cheap)
camera_to_dict(camera) -> dict        a camera's manifest entry (any object with eye/target/up/fov_y/...)
load_bundle(path)                     deprecated here: use :func:`piste.pipeline.load_bundle`
"""

from __future__ import annotations

import contextlib
import io
import json
import mmap
import os
import sys
import warnings
import zlib
from collections.abc import Callable, Collection, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

import numpy as np

from piste._data import DataMethods
from piste.errors import FormatError
from piste.formats.atomic import atomic_path
from piste.formats.bundle_schema import MAX_MEMBER_BYTES, check_manifest
from piste.formats.safe_io import loads_json, open_file
from piste.formats.ziplite import STORED, BadZip, member_bytes, read_index

if TYPE_CHECKING:
    import zipfile

__all__ = ["BUNDLE_FORMAT", "REQUIRED_MEMBERS", "TOPOLOGY_MEMBERS", "write_bundle", "read_bundle", "read_bundle_deferred",
           "read_manifest", "BundleData",
           "camera_to_dict", "load_bundle", "READ_FORMATS", "RESIDENT_MEMBER", "STORED_MEMBERS"]

BUNDLE_FORMAT = "piste.bundle/2"
#: the versions :func:`read_bundle` reads (1: without the stored resident vertex blocks)
READ_FORMATS = ("piste.bundle/1", BUNDLE_FORMAT)
_EPOCH = (1980, 1, 1, 0, 0, 0)
#: members every bundle has (the terrain and its light map)
REQUIRED_MEMBERS = ("terrain/control_points", "terrain/uv", "lightmap/atlas", "lightmap/rects")
#: what the terrain net is made of (read first: see :func:`read_bundle`'s ``on_terrain``)
_NET_MEMBERS = ("terrain/control_points", "terrain/uv", "lightmap/rects")
#: the terrain net's topology as the build stores it (``manifest.terrain.topology`` = 1; older bundles
#: have none and the load computes it): member -> (dtype, ndim, length of the last axis or None).
#: The same arrays as :data:`piste.terrain.net.TOPOLOGY_ARRAYS` (tests/formats/test_bundle_topology.py)
TOPOLOGY_MEMBERS = {"terrain/side_edge": ("<i4", 2, 4), "terrain/side_flip": ("|b1", 2, 4),
                    "terrain/edge_patches": ("<i4", 2, 2), "terrain/edge_sides": ("<i4", 2, 2),
                    "terrain/edge_degenerate": ("|b1", 1, None), "terrain/corner_ids": ("<i4", 2, 4)}
#: the members :func:`read_bundle` reads first (the net and its topology)
TERRAIN_MEMBERS = frozenset(_NET_MEMBERS) | frozenset(TOPOLOGY_MEMBERS)
#: the terrain's GPU-resident vertex blocks (format 2; :mod:`piste.pipeline.bundle_objects` makes and reads them)
RESIDENT_MEMBER = "terrain/resident_blocks"
#: members written without compression: big, read at every start, and inflating them cost a fresh
#: process about as much as computing them (13 MB of blocks: 46 ms to inflate, 2 ms to CRC, 6 ms to
#: hash); the light-map atlas (3.1 MB of float32, deflated only to 45 %: 10 ms to inflate) and the
#: control points (1 MB, deflated to 32 %: 2.5 ms) likewise, for 2.3 MB more file at the default course;
#: the track's float16 field (1.4 MB: a view, hashed, never inflated) and the light map's float16
#: texels as uploaded (1.6 MB) too
STORED_MEMBERS = frozenset({RESIDENT_MEMBER, "lightmap/atlas", "terrain/control_points", "terrain/track_field",
                            "lightmap/texels"})
#: members of at most this many bytes are written without compression too: inflating the default
#: course's ~140 small members (1.6 MB, deflated to 0.36 MB) cost a fresh process ~2.9 ms; stored,
#: the file is ~1.2 MB bigger and each is copied from the mapped file instead (the bigger ones of a
#: large world stay deflated)
SMALL_MEMBER_BYTES = 128 * 1024


def _sha256(data: bytes | memoryview) -> str:
    """Hex SHA-256 of ``data``.  OpenSSL is loaded on first use (importing the runtime never loads it:
    tests/test_lazy_imports.py), through ``_hashlib.openssl_sha256``, the very constructor
    ``hashlib.sha256`` is where OpenSSL is there: importing hashlib itself also sets up every other
    algorithm (~0.8 ms more of a fresh process's first load); hashlib where there is no ``_hashlib``."""
    try:
        from _hashlib import openssl_sha256 as sha256
    except ImportError:  # (a Python built without OpenSSL: hashlib's own implementation)
        from hashlib import sha256
    return sha256(data).hexdigest()


def _c_order(arr: Any) -> np.ndarray:
    """``arr`` as a C-contiguous array of its own shape (``np.ascontiguousarray`` makes a 0-d array
    shape ``(1,)``: a scalar member would come back as a 1-element array)."""
    a = np.asarray(arr)
    return a if a.flags.c_contiguous else np.array(a, order="C")


def _npy_bytes(arr: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, _c_order(arr), allow_pickle=False)
    return buf.getvalue()


def write_bundle(path: str | os.PathLike[str], manifest: dict, arrays: dict, compresslevel: int = 1,
                 stored: Collection[str] = STORED_MEMBERS) -> Path:
    """Write a bundle atomically: ``manifest`` (JSON-able dict; ``format`` and ``members`` are set
    here) and ``arrays`` (``{"a/b": ndarray}``, stored as ``a/b.npy``).  ``stored``: names of
    ``arrays`` written without compression (big members read at every start: no inflating), as is
    every member of at most :data:`SMALL_MEMBER_BYTES`.  Returns the path."""

    man = dict(manifest)
    man["format"] = BUNDLE_FORMAT
    blobs = {}
    members = {}
    for name in sorted(arrays):
        a = _c_order(arrays[name])
        if a.dtype == object:
            raise FormatError(path, "object arrays cannot be stored", field=name)
        data = _npy_bytes(a)
        blobs[f"{name}.npy"] = data
        members[name] = {"shape": list(a.shape), "dtype": a.dtype.str, "sha256": _sha256(data)}
    man["members"] = members
    text = (json.dumps(man, indent=1, sort_keys=True, allow_nan=False) + "\n").encode()
    import zipfile  # (imported where used: a bundle render reads through piste.formats.ziplite)

    path = Path(path)
    with atomic_path(path) as tmp:
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=compresslevel) as zf:
            entries = [("manifest.json", text)] + sorted(blobs.items())
            for name, data in entries:
                info = zipfile.ZipInfo(name, date_time=_EPOCH)
                info.compress_type = zipfile.ZIP_STORED if name[:-4] in stored or \
                    (name != "manifest.json" and len(data) <= SMALL_MEMBER_BYTES) else zipfile.ZIP_DEFLATED
                info.external_attr = 0o644 << 16
                info.create_system = 3
                zf.writestr(info, data, compresslevel=compresslevel)
    return path


def _zip_errors() -> tuple[type[BaseException], ...]:
    """What a corrupt archive raises: ziplite's and zlib's errors, I/O errors and, once it is imported
    (an archive ziplite does not read), zipfile's (an ``except`` clause evaluates this only when an
    exception is being matched)."""
    zf = sys.modules.get("zipfile")
    return (BadZip, zlib.error, OSError, EOFError) + ((zf.BadZipFile,) if zf is not None else ())


class _Archive:
    """An opened bundle: its file mapped read-only (POSIX) and indexed by :mod:`piste.formats.ziplite`
    (no :mod:`zipfile` import: ~2.5 ms of a fresh process), or, for an archive ziplite does not read
    (or a file that cannot be mapped), a :class:`zipfile.ZipFile`.  ``infolist()``, ``read(name)``,
    ``open(entry)`` as zipfile's; ``mm``: the mapping or None."""

    def __init__(self, fh: Any) -> None:
        self.fh = fh
        self.mm = _mapped(fh)
        self._index = read_index(self.mm) if self.mm is not None else None
        self._zf: zipfile.ZipFile | None = None
        if self._index is None:
            self._zip()  # (BadZipFile etc. for what is not a zip archive)

    def _zip(self) -> zipfile.ZipFile:
        """The archive as a :class:`zipfile.ZipFile` (opened on first use)."""
        if self._zf is None:
            import zipfile

            self._zf = zipfile.ZipFile(self.fh)
        return self._zf

    def infolist(self) -> list[Any]:
        return list(self._index) if self._index is not None else self._zip().infolist()

    def read(self, name: str) -> bytes:
        """Member ``name``'s bytes, its CRC-32 checked (KeyError when there is none)."""
        if self._index is not None and self.mm is not None:
            entry = next((e for e in self._index if e.filename == name), None)
            if entry is None:
                raise KeyError(name)
            data = member_bytes(self.mm, entry)
            if data is not None:
                if entry.compress_type == STORED and zlib.crc32(data) != entry.CRC:
                    raise BadZip(f"Bad CRC-32 for file {name!r}")
                return bytes(data)
        return self._zip().read(name)

    def open(self, entry: Any) -> Any:
        """Member ``entry`` as zipfile opens it (its CRC-32 checked as it is read)."""
        return self._zip().open(entry.filename)

    def close(self) -> None:
        if self._zf is not None:
            self._zf.close()


@contextlib.contextmanager
def _open(path: Path) -> Iterator[_Archive]:
    """The bundle as an :class:`_Archive`, opened through :func:`piste.formats.safe_io.open_file`
    (regular files only: a pipe or device is refused before a read, a link below a confinement root too)."""
    try:
        fh = open_file(path, what="bundle")
    except FormatError as exc:
        reason = getattr(exc, "reason", str(exc))
        if "No such file" in reason:
            raise FormatError(path, "no such file") from None
        if "(a folder)" in reason:
            raise FormatError(path, "is a folder, expected a .piste bundle") from None
        raise
    with fh:
        try:
            zf = _Archive(fh)
        except _zip_errors() + (ValueError,) as exc:
            raise FormatError(path, f"not a piste bundle (not a zip archive: {exc})") from None
        try:
            yield zf
        finally:
            zf.close()


def _manifest(path: Path, zf: _Archive) -> dict:
    try:
        raw = zf.read("manifest.json")
    except KeyError:
        raise FormatError(path, "not a piste bundle: no manifest.json member", field="manifest.json") from None
    except _zip_errors() as exc:
        raise FormatError(path, f"corrupt member ({exc})", field="manifest.json") from None
    try:  # nesting bounded before parsing (safe_io), so no RecursionError
        man = loads_json(raw.decode("utf-8"), path, field="manifest.json")
    except UnicodeDecodeError as exc:
        raise FormatError(path, f"manifest is not valid JSON ({exc})", field="manifest.json") from None
    if not isinstance(man, dict):
        raise FormatError(path, "manifest must be a JSON object", field="manifest.json")
    fmt = man.get("format")
    if fmt not in READ_FORMATS:
        raise FormatError(path, f"bundle format {fmt!r}, this piste reads {' or '.join(map(repr, READ_FORMATS))}: "
                                "rebuild it with `piste build SCENE`", field="format")
    if not isinstance(man.get("members"), dict):
        raise FormatError(path, "manifest has no 'members' table", field="members")
    check_manifest(man, path)  # every field the loaders read has its type and a sane size
    return man


def read_manifest(path: str | os.PathLike[str]) -> dict:
    """The manifest of the bundle at ``path`` (version-checked)."""
    path = Path(path)
    with _open(path) as zf:
        return _manifest(path, zf)


def _mapped(fh: Any) -> mmap.mmap | None:
    """The bundle's file mapped read-only (POSIX), or None (then every member is read by zipfile)."""
    if os.name != "posix":  # (elsewhere a mapped file could not be replaced by a rebuild while in use)
        return None
    try:
        return mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    except (AttributeError, OSError, ValueError, io.UnsupportedOperation):
        return None


def _read_arrays(path: Path, zf: _Archive, members: dict, verify: bool,
                 on_terrain: Callable[[dict], Any] | None = None,
                 hand_off_share: float | None = None) -> tuple[dict, Callable[[], None]]:
    """The members' arrays (read, parsed) and ``finish()``, which waits for the second thread's checks
    of the big uncompressed members it was handed and raises FormatError naming the first that fails
    (see :func:`read_bundle_deferred`).  ``hand_off_share``: at most this share of the bytes to check
    goes to that thread (default :attr:`_Hasher.HAND_OFF_SHARE`)."""
    out: dict[str, np.ndarray] = {}
    infos = {i.filename: i for i in zf.infolist()}  # the zip's index, read once
    mm = zf.mm
    # the terrain's members first: ``on_terrain(out)`` can start on the net (e.g. the renderer's vertex
    # blocks, in the background) while the light map, characters and objects are read
    first = [n for n in members if n in TERRAIN_MEMBERS]
    order = first + [n for n in members if n not in TERRAIN_MEMBERS]
    # big uncompressed members that are not the terrain's (the vertex blocks: 13 MB, ~8 ms of SHA-256)
    # are handed first to a second thread that checks them (SHA-256 when verifying, else the zip's
    # CRC-32: hashlib and zlib let go of the GIL) while this one reads and checks the rest; they are
    # parsed here, but given to ``on_terrain`` and returned only with the others (``finish`` checks them)
    background = _Hasher(verify) if mm is not None else None
    deferred: list[tuple[str, Any, Any, bool]] = []
    handed: set[str] = set()
    if background is not None:
        # the biggest first, while the thread's share of the bytes to check stays at most the share
        # (this thread has the inflating and parsing besides: the default course hands off the 13 MB
        # of vertex blocks, 60 % of its bytes)
        size = {n: infos[f"{n}.npy"].file_size if f"{n}.npy" in infos else 0 for n in order}
        share = _Hasher.HAND_OFF_SHARE if hand_off_share is None else hand_off_share
        budget = share * sum(size.values())
        for name in sorted((n for n in order[len(first):] if n in STORED_MEMBERS), key=lambda n: -size[n]):
            if size[name] <= budget:  # (a member that cannot go to the thread is read below in the order)
                _read_member(path, zf, mm, infos, members, name, verify, out, background, deferred, hand_off=True)
                budget -= size[name] if deferred and deferred[-1][0] == name else 0
        handed = {d[0] for d in deferred}
        background.start()
    finished = False

    def finish() -> None:
        nonlocal finished
        if finished:
            return
        finished = True
        checks = background.digests() if background is not None else {}
        for name, data, zi, crc_checked in deferred:
            _check_member(path, zi, data, members[name], checks[name] if verify else None, crc_checked,
                          crc=None if verify else checks[name])

    try:
        for k, name in enumerate(order):
            if on_terrain is not None and k == len(first):
                on_terrain(out)
            if name not in handed:
                _read_member(path, zf, mm, infos, members, name, verify, out, None, deferred)
        if on_terrain is not None and len(first) == len(order):
            on_terrain(out)
        for name, data, _zi, _crc in deferred:
            out[name] = _member_array(path, name, f"{name}.npy", data, members[name])
    except BaseException:
        finish()  # a corrupt handed-off member is named as such, not by what its bytes broke
        raise
    return ({n: out[n] for n in order} if deferred else out), finish


class _Hasher:
    """Checks of bundle members in a second thread, in the order added (:func:`_read_arrays`): their
    SHA-256 when verifying, else their CRC-32.  The members are added, then :meth:`start` checks them
    all (no queue: ~0.8 ms of imports)."""

    #: uncompressed members at least this big go to the second thread (smaller ones: not worth a hand-off)
    MIN_BYTES = 1 << 20
    #: at most this share of the bytes to check goes to the second thread when :func:`read_bundle`
    #: waits for it (:func:`read_bundle_deferred` hands off every big uncompressed member)
    HAND_OFF_SHARE = 0.65

    def __init__(self, verify: bool = True) -> None:
        self._verify = verify
        self._jobs: list[tuple[str, bytes | memoryview]] = []
        self._out: dict[str, Any] = {}
        self._thread: Any = None

    def add(self, name: str, data: bytes | memoryview) -> None:
        self._jobs.append((name, data))

    def start(self) -> None:
        import threading

        if self._jobs:
            self._thread = threading.Thread(target=self._run, name="piste-bundle-sha256", daemon=True)
            self._thread.start()

    def _run(self) -> None:
        for name, data in self._jobs:
            self._out[name] = _sha256(data) if self._verify else zlib.crc32(data)

    def digests(self) -> dict[str, Any]:
        """Every added member's hex SHA-256 (verifying) or CRC-32 (waits for the thread)."""
        if self._thread is not None:
            self._thread.join()
        return self._out


def _check_member(path: Path, zi: Any, data: bytes | memoryview, info: dict, digest: str | None,
                  crc_checked: bool, crc: int | None = None) -> None:
    """FormatError naming the member when its SHA-256 (``digest``; None: not verifying) is not the
    manifest's, or, not verifying, when an unchecked member's CRC-32 (``crc`` when already computed)
    is not the zip's."""
    member = zi.filename
    if digest is not None and digest != info.get("sha256"):
        if not crc_checked and zlib.crc32(data) != zi.CRC:  # a corrupt member, as zipfile says it
            raise FormatError(path, f"corrupt member (Bad CRC-32 for file {member!r})", field=member)
        raise FormatError(path, "checksum mismatch (the file is corrupt)", field=member)
    if digest is None and not crc_checked and (zlib.crc32(data) if crc is None else crc) != zi.CRC:
        raise FormatError(path, f"corrupt member (Bad CRC-32 for file {member!r})", field=member)


def _member_array(path: Path, name: str, member: str, data: bytes | memoryview, info: dict) -> np.ndarray:
    """The checked member's array, of the manifest's shape and dtype (FormatError naming it otherwise)."""
    try:
        a = _known_array(data, info, copy=name not in STORED_MEMBERS)
        if a is None:  # not the header piste writes for that shape and dtype: numpy parses it
            a = _view_array(data) if name in STORED_MEMBERS else np.lib.format.read_array(io.BytesIO(data),
                                                                                          allow_pickle=False)
    except Exception as exc:
        raise FormatError(path, f"not a valid .npy array ({exc})", field=member) from None
    if list(a.shape) != list(info.get("shape", [])) or a.dtype.str != info.get("dtype"):
        raise FormatError(path, f"expected shape {info.get('shape')} dtype {info.get('dtype')}, got "
                                f"{list(a.shape)} {a.dtype.str}", field=member)
    return a


def _read_member(path: Path, zf: _Archive, mm: mmap.mmap | None, infos: dict, members: dict, name: str,
                 verify: bool, out: dict, background: _Hasher | None, deferred: list, hand_off: bool = False) -> None:
    """Read, check and parse member ``name`` into ``out``, or, when it is a big uncompressed one not of
    the terrain and ``background`` hashes, hand its hash to that thread and list it in ``deferred``
    (``hand_off``: only that; a member that cannot go to the thread is left to the call in the read
    order, a corrupt one raises FormatError naming it as that call would)."""
    info = members[name]
    member = f"{name}.npy"
    zi = infos.get(member)
    if zi is None:
        raise FormatError(path, "member listed in the manifest is missing", field=member)
    if zi.file_size > MAX_MEMBER_BYTES:  # a zip bomb: checked before inflating
        raise FormatError(path, f"member of {zi.file_size} bytes is larger than the limit of "
                                f"{MAX_MEMBER_BYTES}", field=member)
    # uncompressed members: a view of the mapped file, checked once (by the SHA-256 when verifying,
    # else by the zip's CRC-32); deflated ones: CRC-32 checked as they are inflated
    if hand_off and (zi is None or zi.file_size > MAX_MEMBER_BYTES or zi.compress_type != STORED
                     or zi.file_size < _Hasher.MIN_BYTES):
        return
    try:
        # (a view of the mapping: reading the 13 MB of vertex blocks into new memory cost a fresh
        # process ~10 ms more; None where the local header is not a plain one: zipfile reads it)
        data = member_bytes(mm, zi) if mm is not None else None
        crc_checked = data is None or zi.compress_type != STORED
        if data is None:
            with zf.open(zi) as fh:
                data = fh.read()
    except _zip_errors() as exc:
        raise FormatError(path, f"corrupt member ({exc})", field=member) from None
    if len(data) != zi.file_size:
        raise FormatError(path, f"corrupt member ({len(data)} bytes, the zip says {zi.file_size})", field=member)
    if background is not None and name not in TERRAIN_MEMBERS and not crc_checked and \
            len(data) >= _Hasher.MIN_BYTES:
        background.add(name, data)
        deferred.append((name, data, zi, crc_checked))
        return
    if hand_off:
        return
    _check_member(path, zi, data, info, _sha256(data) if verify else None, crc_checked)
    out[name] = _member_array(path, name, member, data, info)


def _known_array(data: bytes | memoryview, info: dict, copy: bool) -> np.ndarray | None:
    """The array of ``.npy`` bytes whose header is exactly the one :func:`write_bundle` writes for
    the manifest's shape and dtype (``np.lib.format``'s version 1.0 header of a C-order array),
    without parsing it (``read_array`` evaluates each header as a Python literal: ~20 us a member);
    a copy (writable) or, ``copy=False``, a read-only view of ``data``.  None when the header is
    another (another writer, padding or version; a manifest that does not match): the caller parses it."""
    shape, dtype = info.get("shape"), info.get("dtype")
    if not isinstance(shape, list) or not isinstance(dtype, str) or \
            not all(isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in shape):
        return None
    try:
        dt = np.dtype(dtype)
        if dt.hasobject or dt.str != dtype:
            return None
        header = io.BytesIO()
        np.lib.format.write_array_header_1_0(header, {"descr": np.lib.format.dtype_to_descr(dt),
                                                    "fortran_order": False, "shape": tuple(shape)})
    except (TypeError, ValueError):
        return None
    head = header.getvalue()
    count = int(np.prod(shape, dtype=np.int64))
    if bytes(data[:len(head)]) != head or len(data) - len(head) != count * dt.itemsize:
        return None
    a = np.frombuffer(data, dtype=dt, count=count, offset=len(head)).reshape(shape)
    return a.copy() if copy else a


def _view_array(data: bytes | memoryview) -> np.ndarray:
    """The array of ``.npy`` bytes as a read-only view of them (no copy: ``read_array`` copies a
    13 MB member twice, 256 KB at a time); ValueError when they are not a plain C-order array."""
    fp = io.BytesIO(data)
    version = np.lib.format.read_magic(fp)
    if version == (1, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_1_0(fp)
    elif version == (2, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_2_0(fp)
    else:
        return np.lib.format.read_array(io.BytesIO(data), allow_pickle=False)
    count = int(np.prod(shape, dtype=np.int64))
    if fortran or dtype.hasobject or len(data) - fp.tell() != count * dtype.itemsize:
        raise ValueError(f"expected {count * dtype.itemsize} bytes of C-order {dtype} data after the header, "
                         f"got {len(data) - fp.tell()}{' (Fortran order)' if fortran else ''}")
    return np.frombuffer(data, dtype=dtype, count=count, offset=fp.tell()).reshape(shape)


def camera_to_dict(cam: Any) -> dict:
    """The manifest entry of a camera (any object with ``eye``, ``target``, ``up``, ``fov_y``,
    ``near``, ``far``, ``ortho_height``); :func:`piste.pipeline.bundle_objects.camera_from_dict`
    reads it back."""
    return {"eye": [float(x) for x in cam.eye], "target": [float(x) for x in cam.target], "up": [float(x) for x in cam.up],
            "fov_y": float(cam.fov_y), "near": float(cam.near), "far": float(cam.far),
            "ortho_height": None if cam.ortho_height is None else float(cam.ortho_height)}


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class BundleData(DataMethods):
    """A bundle's contents as read: ``path`` (Path), ``manifest`` (dict, version-checked) and
    ``arrays`` (``{member name: ndarray}``, each checked against the manifest's shape, dtype and
    SHA-256).  No objects are built here (see :func:`piste.pipeline.load_bundle`)."""

    path: Path
    manifest: dict
    arrays: dict


def read_bundle(path: str | os.PathLike[str], verify: bool = True,
                on_terrain: Callable[[dict, dict], Any] | None = None) -> BundleData:
    """Read a ``.piste`` bundle's manifest and arrays (see the module docstring).

    ``verify`` checks each member's SHA-256 against the manifest (the zip CRC is always checked).
    Raises :class:`~piste.errors.FormatError` on a missing file, a wrong format version, a missing
    or corrupt member, or a missing required member (:data:`REQUIRED_MEMBERS`).  The arrays of
    :data:`STORED_MEMBERS` are read-only views of the member's bytes (no copy); every other array is
    its own writable copy.

    ``on_terrain(man, arrays)``: called once the :data:`TERRAIN_MEMBERS` the bundle has are read and
    checked (the manifest and those arrays; the topology members' dtypes and shapes are checked
    before), before the others are read: :func:`piste.pipeline.load_bundle` starts building the
    terrain's vertex blocks there.  An error in a later member still raises (after the call).
    """
    data, finish = read_bundle_deferred(path, verify, on_terrain, hand_off_share=_Hasher.HAND_OFF_SHARE)
    finish()
    return data


def read_bundle_deferred(path: str | os.PathLike[str], verify: bool = True,
                         on_terrain: Callable[[dict, dict], Any] | None = None,
                         hand_off_share: float = 1.0) -> tuple[BundleData, Callable[[], None]]:
    """:func:`read_bundle`, but the checks of the big uncompressed members (SHA-256 when ``verify``,
    else the zip's CRC-32: every one of at least 1 MiB that is not the terrain's, up to
    ``hand_off_share`` of the bytes to check) go on in a second thread after this returns:
    ``(data, finish)``, where ``finish()`` waits for them and raises the
    :class:`~piste.errors.FormatError` naming the first member that fails (as :func:`read_bundle`
    would have; later calls do nothing).  The arrays may be used before (e.g. turned into the scene's
    objects, overlapping the ~10 ms of SHA-256 of the default course's 21 MB), but are trusted only
    once ``finish()`` returned; a caller whose own work on them fails calls ``finish()`` first, so
    that a corrupt member is named as such rather than by what its bytes broke
    (:func:`piste.pipeline.load_bundle`).  Every other member is checked before this returns."""
    path = Path(path)
    finish: Callable[[], None] = lambda: None  # noqa: E731
    try:
        with _open(path) as zf:
            man = _manifest(path, zf)

            def terrain_ready(part: dict) -> None:
                if on_terrain is not None and all(n in part for n in _NET_MEMBERS):
                    _check_topology_members(path, man, part)
                    on_terrain(man, part)

            arrays, finish = _read_arrays(path, zf, man["members"], verify,
                                          terrain_ready if on_terrain is not None else None, hand_off_share)
        for need in REQUIRED_MEMBERS:
            if need not in arrays:
                raise FormatError(path, "required member is missing", field=f"{need}.npy")
        _check_topology_members(path, man, arrays)
    except BaseException:
        finish()
        raise
    return BundleData(path, man, arrays), finish


def _check_topology_members(path: Path, man: dict, arrays: dict) -> None:
    """A bundle whose manifest says it stores the terrain's topology (``terrain.topology``) has every
    member of :data:`TOPOLOGY_MEMBERS`, each of its dtype and shape (``(n, 4)`` per patch)."""
    if not (man.get("terrain") or {}).get("topology"):
        return
    n = len(arrays["terrain/control_points"])
    for name, (dtype, ndim, last) in TOPOLOGY_MEMBERS.items():
        a = arrays.get(name)
        if a is None:
            raise FormatError(path, "member missing (the manifest's terrain.topology says the build stored it)",
                              field=f"{name}.npy")
        per_patch = last == 4
        if a.dtype.str != dtype or a.ndim != ndim or (last is not None and a.shape[-1] != last) \
                or (per_patch and a.shape[0] != n):
            want = f"({n}, 4)" if per_patch else ("(e, 2)" if last == 2 else "(e,)")
            raise FormatError(path, f"expected a {want} {dtype} array, got {a.shape} {a.dtype.str}", field=f"{name}.npy")


def load_bundle(path: str | os.PathLike[str], verify: bool = True) -> BundleData:
    """Deprecated here: :func:`piste.pipeline.load_bundle` loads a bundle as the scene's objects
    (``.net``, ``.lightmap``, ``.cameras``, ...).  This returns :func:`read_bundle`'s
    :class:`BundleData` (manifest and arrays only) and warns."""
    warnings.warn("piste.formats.bundle.load_bundle now returns the raw BundleData (manifest and arrays); use "
                  "piste.pipeline.load_bundle for the scene objects, or piste.formats.bundle.read_bundle",
                  DeprecationWarning, stacklevel=2)
    return read_bundle(path, verify)


def __getattr__(name: str) -> NoReturn:
    if name in ("Bundle", "lights_from_dict", "camera_from_dict"):
        raise AttributeError(f"piste.formats.bundle.{name} moved to piste.pipeline.bundle_objects (the format layer "
                             f"reads and writes arrays only): from piste.pipeline import {name}")
    raise AttributeError(f"module 'piste.formats.bundle' has no attribute {name!r}")
