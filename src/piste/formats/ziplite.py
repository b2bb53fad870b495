"""The index and members of the plain zip archives piste reads at every start (``.piste`` bundles, the
``.npz`` files shipped in ``piste/data``), read without :mod:`zipfile`.

Importing :mod:`zipfile` (with :mod:`shutil`, :mod:`bz2`, :mod:`lzma`) cost a fresh process ~2.5 ms,
and each :class:`zipfile.ZipFile` ~0.8 ms to index a bundle of ~150 members; a bundle render read
three archives.  This module reads only what piste writes: one disk, no zip64 records, no encryption,
members stored or deflated, names in ASCII or flagged UTF-8.  For anything else :func:`read_index`
returns None and the caller reads the archive with :mod:`zipfile` (which reports what is wrong);
likewise :func:`member_bytes` for a member whose local header is not a plain one.

API
---
::

    ZipEntry                         filename, header_offset, flag_bits, compress_type, compress_size,
                                     file_size, CRC (the fields of zipfile.ZipInfo the readers use)
    read_index(buf) -> list[ZipEntry] | None     the central directory of ``buf`` (bytes or a mapped file)
    member_bytes(buf, entry) -> memoryview | bytes | None   a stored member's view, a deflated one inflated
    BadZip                           a member whose data is corrupt (size, CRC-32, deflate stream)
    read_npz(path) -> dict           an ``.npz`` file's arrays (numpy's ``np.load`` for anything unusual)
    STORED, DEFLATED                 the two compression methods (zipfile.ZIP_STORED / ZIP_DEFLATED)
"""

from __future__ import annotations

import io
import os
import re
import struct
import zlib
from typing import Any

import numpy as np

__all__ = ["ZipEntry", "read_index", "member_bytes", "BadZip", "read_npz", "STORED", "DEFLATED"]

#: zipfile.ZIP_STORED / zipfile.ZIP_DEFLATED
STORED, DEFLATED = 0, 8
_EOCD = b"PK\x05\x06"
_EOCD64_LOCATOR = b"PK\x06\x07"
_CENTRAL = b"PK\x01\x02"
_LOCAL = b"PK\x03\x04"
_CENTRAL_HEAD = struct.Struct("<4s4B4HL2L5H2L")  # 46 bytes (zipfile's structCentralDir)
_EOCD_HEAD = struct.Struct("<4s4H2LH")  # 22 bytes (zipfile's structEndArchive)


class BadZip(Exception):
    """A member's data is corrupt: its size, CRC-32 or deflate stream (the message as zipfile's)."""


class ZipEntry:
    """One central directory entry (the :class:`zipfile.ZipInfo` fields piste's readers use)."""

    __slots__ = ("filename", "header_offset", "flag_bits", "compress_type", "compress_size", "file_size", "CRC")

    def __init__(self, filename: str, header_offset: int, flag_bits: int, compress_type: int, compress_size: int,
                 file_size: int, crc: int) -> None:
        self.filename, self.header_offset, self.flag_bits = filename, header_offset, flag_bits
        self.compress_type, self.compress_size, self.file_size, self.CRC = compress_type, compress_size, file_size, crc

    def __repr__(self) -> str:
        return f"ZipEntry({self.filename!r}, compress_type={self.compress_type}, file_size={self.file_size})"


def read_index(buf: Any) -> list[ZipEntry] | None:
    """The central directory of the archive in ``buf`` (bytes, or a mapped file), in its order, or
    None when it is not a plain archive this reads (no end record, a comment, a zip64 record, more
    than one disk, data before the archive, a size or offset out of range, an encrypted or
    non-ASCII-named member without the UTF-8 flag): then :mod:`zipfile` reads it."""
    n = len(buf)
    if n < _EOCD_HEAD.size:
        return None
    end = n - _EOCD_HEAD.size  # (piste writes no archive comment: the end record is the last 22 bytes)
    sig, disk, cd_disk, count_here, count, cd_size, cd_offset, comment = _EOCD_HEAD.unpack(buf[end:n])
    if sig != _EOCD or disk or cd_disk or count_here != count or comment or cd_offset + cd_size != end:
        return None
    if end >= 20 and buf[end - 20:end - 16] == _EOCD64_LOCATOR:
        return None
    out = []
    at, stop = cd_offset, end
    head = _CENTRAL_HEAD
    for _ in range(count):
        if at + head.size > stop:
            return None
        (sig, _vmade, _smade, _vneed, _sneed, flags, method, _time, _date, crc, csize, usize, name_len, extra_len,
         comment_len, disk_start, _iattr, _eattr, offset) = head.unpack(buf[at:at + head.size])
        name_at = at + head.size
        at = name_at + name_len + extra_len + comment_len
        if sig != _CENTRAL or at > stop or disk_start or flags & 1 or method not in (STORED, DEFLATED) or \
                0xFFFFFFFF in (csize, usize, offset) or offset + 30 + csize > cd_offset:
            return None
        raw = bytes(buf[name_at:name_at + name_len])
        if flags & 0x800:
            try:
                name = raw.decode("utf-8")
            except UnicodeDecodeError:
                return None
        elif raw.isascii():
            name = raw.decode("ascii")
        else:
            return None  # (cp437: zipfile's decoding)
        out.append(ZipEntry(name, offset, flags, method, csize, usize, crc))
    if at != stop:
        return None
    return out


def member_bytes(buf: Any, entry: Any) -> memoryview | bytes | None:
    """Member ``entry`` (a :class:`ZipEntry` or :class:`zipfile.ZipInfo`) of the archive in ``buf``: a
    stored one as a view of ``buf`` (no copy; its CRC-32 not computed here), a deflated one inflated
    (at most its declared size) and its CRC-32 checked.  None where its local header is not a plain
    one or the method is another (the caller reads it with :mod:`zipfile`, which reports what is
    wrong); :class:`BadZip` / ``zlib.error`` when the data is corrupt."""
    at = entry.header_offset
    head = buf[at:at + 30]
    if len(head) != 30 or head[:4] != _LOCAL or entry.flag_bits & 1:
        return None
    n, extra = struct.unpack("<HH", head[26:30])
    start = at + 30 + n + extra
    if buf[at + 30:at + 30 + n] != entry.filename.encode() or start + entry.compress_size > len(buf):
        return None
    raw = memoryview(buf)[start:start + entry.compress_size]
    if entry.compress_type == STORED:
        return raw if entry.compress_size == entry.file_size else None
    if entry.compress_type != DEFLATED:
        return None
    inflate = zlib.decompressobj(-15)
    data = inflate.decompress(raw, entry.file_size + 1)  # bounded: a member inflating past its size is corrupt
    if len(data) != entry.file_size or not inflate.eof or zlib.crc32(data) != entry.CRC:
        raise BadZip(f"Bad CRC-32 or size for file {entry.filename!r}")
    return data


def read_npz(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """The arrays of the ``.npz`` file at ``path`` (``{name without .npy: array}``, each its own
    writable copy), as ``np.load(path, allow_pickle=False)`` gives them; that call reads any file
    this does not (another layout, a member's .npy header other than version 1.0 / 2.0 of a plain
    array), so its errors (OSError, ValueError, ...) are what a bad file raises."""
    with open(path, "rb") as fh:
        buf = fh.read()
    entries = read_index(buf)
    out = {}
    try:
        if entries is None:
            raise ValueError("not a plain archive")
        for e in entries:
            data = member_bytes(buf, e)
            if data is None or not e.filename.endswith(".npy") or \
                    (e.compress_type == STORED and zlib.crc32(data) != e.CRC):
                raise ValueError(e.filename)
            out[e.filename[:-4]] = _npy_array(data)
    except (ValueError, BadZip, zlib.error):
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    return out


def _npy_array(data: bytes | memoryview) -> np.ndarray:
    """The array of ``.npy`` bytes (a copy); ValueError when they are not a plain one (the caller
    then lets numpy read the whole file)."""
    m = _PLAIN_HEADER.match(bytes(data[:256]))
    if m is not None and struct.unpack("<H", m.group(1))[0] == m.end() - 10:
        # the header numpy writes, matched (numpy's parser evaluates it as a Python literal: ~0.1 ms)
        dtype = np.dtype(m.group(2).decode())
        shape = tuple(int(x) for x in m.group(4).split(b",") if x.strip())
        fortran, offset = m.group(3) == b"True", m.end()
    else:
        fp = io.BytesIO(data)
        shape, fortran, dtype = _parsed_header(fp)
        offset = fp.tell()
    count = int(np.prod(shape, dtype=np.int64))
    if dtype.hasobject or len(data) - offset != count * dtype.itemsize:
        raise ValueError("not a plain array")
    a = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
    return (a.reshape(shape[::-1]).T if fortran else a.reshape(shape)).copy(order="K")


#: a version 1.0 ``.npy`` header as numpy writes it: magic, length, the dict (a plain dtype string,
#: the order, the shape), the padding and newline (group 1: the length field)
_PLAIN_HEADER = re.compile(rb"\x93NUMPY\x01\x00(..)\{'descr': '([<>|=][a-zA-Z]\d*)', 'fortran_order': (True|False), "
                           rb"'shape': \(((?:\d+, ?)*\d*)\), \} *\n", re.S)


def _parsed_header(fp: io.BytesIO) -> tuple[tuple[int, ...], bool, np.dtype]:
    """numpy's own parse of an ``.npy`` header (versions 1.0 and 2.0; ValueError for others)."""
    version = np.lib.format.read_magic(fp)
    if version == (1, 0):
        return np.lib.format.read_array_header_1_0(fp)
    if version == (2, 0):
        return np.lib.format.read_array_header_2_0(fp)
    raise ValueError(f".npy version {version}")
