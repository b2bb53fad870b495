"""SSX Tricky ``.ssh`` texture banks (``SHPS``) and the light-map bank ``<NAME>_L.ssh``.

Facts from ``/work/shared/SSX-FORMATS.md``: a 16-byte header (magic ``SHPS``, u32 file size, u32
image count, 4-char creator ``G278``), then per image a 4-char name and a u32 absolute offset;
images are separated by the text ``Buy ERTS``.  An image is a chain of chunks, each with a 16-byte
header: u8 type, u24 size including the header (0 = the last chunk), i16 width, i16 height, i16 x,
i16 y, u32 flags (``0x2000`` = swizzled).  Types: 1 4-bit indexed, 2 8-bit indexed, 5 32-bit
RGBA, 33 palette (RGBA), 112 long name, 130 RefPack-compressed 8-bit, 124 hot-spot list (HUD and
front-end images) and 105 metal-alpha marker: piste does not interpret the last two but keeps each
as the bytes it was read from, at its place in the image's chunk chain, and writes it back
unchanged (:attr:`SshImage.extra`).  Alpha is half range (``0x80`` = opaque, up to 255
over-bright in light maps).

Layout facts checked against OpenSlope's ``Trailmap/specs/210-textures-ssh.md`` (Apache-2.0 prose):
4-bit pixels hold the left pixel in the **low** nibble; a chunk size of 0 means "implied by the
dimensions": the header plus exactly ``width x height x bytes per pixel``, **not padded** to 16
(as SSX-Library reads it; a type-124 chunk of size 0 spans ``6 + 8 x count`` bytes, 16-aligned);
an image's chunks run to the next image's offset, or to its ``Buy ERTS`` terminator.  piste
writes a size-0 chunk only where its data is a multiple of 16 bytes (otherwise an explicit size),
so every reader finds the next chunk where piste put it.  The game's writer reserves the header and directory in 128-byte steps (112 bytes for
up to 12 images, +128 per further 16), writes ``Buy ERTS`` before every image but the first
(which it follows in the directory padding), gives indexed image chunks an explicit size and
palette, RGBA and long-name chunks size 0, and puts a (usually empty) long-name chunk
(``70 00 00 00`` + NUL-terminated text, 16-aligned) on every image.  :meth:`SshBank.to_bytes`
writes that layout.

Flag ``0x2000`` (swizzled): on a palette chunk the entries are in the PS2 CLUT order (bits 3 and
4 of the index swapped), undone on reading and redone on writing; on an 8-bit image chunk the
pixels are in the PS2 block-swizzled layout (the spec's block decomposition), undone and redone
likewise.  Not handled yet, each a clear :class:`~piste.errors.FormatError`: swizzled 4-bit and
32-bit images, RefPack images (type 130), any unknown chunk type.

Half-bright storage (the PS2's 128 = 1.0): :meth:`SshImage.rgba` is the display decode of the
spec: alpha doubled (capped at 255) when no value exceeds 128, and RGB brightened ``clamp(2c - 1,
0, 255)`` when the image's opaque RGB does not exceed 128 (a full-range image is left alone);
:func:`half_bright` is the inverse used when encoding.  Light-map pages are never brightened
(:func:`lightmap_pages` returns the stored ``Cs``/``As``).

Light maps: pages are 128 x 128 RGBA (type 5) cut without gutters into 16 x 16 tiles of 8 x 8
texels; a patch's tile is applied with ``u`` and ``v`` transposed (tile row = ``u``, column =
``v``) and edge-aligned (parameter 0 on the outer texel edge, texel ``i`` centred on ``(i + 0.5) /
8``).  :func:`extract_tiles` and :func:`place_tiles` convert between pages and tiles in piste's
orientation ``[patch, j (v), i (u)]``.

API
---
SshImage, SshBank, read_ssh(path), parse_ssh(data, path), write_ssh(bank, path)
SshBank.to_bytes() (the bytes read while unedited) / .encode() (piste's layout of the game's writer)
lightmap_pages(bank) -> (P, 128, 128, 4) uint8;  lightmap_bank(pages) -> SshBank
extract_tiles(pages, rect, page) -> (n, 8, 8, 4);  place_tiles(tiles, rect, page, n_pages) -> pages
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from piste.errors import FormatError, ValidationError
from piste.formats.atomic import write_bytes_atomic
from piste.formats.safe_io import read_regular

#: the largest file the reader accepts (bytes)
MAX_FILE_BYTES = 256 << 20  # a retail bank is a few MB

__all__ = [
    "SshImage", "SshBank", "read_ssh", "parse_ssh", "write_ssh", "lightmap_pages", "lightmap_bank",
    "extract_tiles", "place_tiles", "tile_origins", "PAGE_SIZE", "TILE", "SWIZZLED", "half_bright",
    "swizzle8_order", "clut_order",
]

MAGIC = b"SHPS"
CREATOR = b"G278"
SEPARATOR = b"Buy ERTS"
SWIZZLED = 0x2000
PAGE_SIZE = 128
TILE = 8
INDEXED = {1: 4, 2: 8}
RGBA32 = 5
PALETTE = 33
LONG_NAME = 112
REFPACK = 130
METAL_ALPHA = 105
HOT_SPOTS = 124
#: chunk types kept as raw bytes and written back unchanged
KEPT = (METAL_ALPHA, HOT_SPOTS)
#: largest image side accepted (hostile sizes are refused before allocating)
MAX_SIDE = 4096
_CHUNK = struct.Struct("<I4hI")


def swizzle8_order(w: int, h: int) -> np.ndarray:
    """PS2 block swizzle of an 8-bit image (210-textures-ssh): ``(h * w,)`` int, the stored byte of
    output pixel ``y * w + x``.  Raises ValueError when the size does not give a permutation."""
    y, x = np.mgrid[0:h, 0:w].astype(np.int64)
    block = (y & ~15) * w + (x & ~15) * 2
    swap = (((y + 2) >> 2) & 1) * 4
    pos_y = (((y & ~3) >> 1) + (y & 1)) & 7
    column = pos_y * w * 2 + ((x + swap) & 7) * 4
    byte = ((y >> 1) & 1) + ((x >> 2) & 2)
    src = (block + column + byte).ravel()
    if w % 16 or h % 4 or src.max(initial=0) >= w * h or len(np.unique(src)) != w * h:
        raise ValueError(f"{w}x{h} is not a size the PS2 8-bit swizzle covers")
    return src


def clut_order(k: int) -> np.ndarray:
    """PS2 CLUT order of a ``k``-entry palette: stored position of entry ``i`` (bits 3 and 4 of the
    index swapped), ``(k,)`` int; ``k`` must be a multiple of 32."""
    i = np.arange(k)
    return (i & 0xE7) | ((i & 8) << 1) | ((i & 16) >> 1)


def half_bright(rgba: npt.ArrayLike) -> np.ndarray:
    """The inverse of the display decode (:meth:`SshImage.rgba`): RGB ``(c + 1) // 2`` and alpha
    ``(a + 1) // 2``, ``(..., 4) uint8``."""
    a = np.asarray(rgba, dtype=np.uint16)
    return ((a + 1) // 2).astype(np.uint8)


@dataclass
class SshImage:
    """One image of a bank.

    Attributes
    ----------
    name : 4-character directory name
    kind : 1 (4-bit indexed), 2 (8-bit indexed) or 5 (32-bit RGBA)
    pixels : (h, w) uint8 palette indices (kinds 1, 2) or (h, w, 4) uint8 RGBA as stored (kind 5)
    palette : (k, 4) uint8 RGBA as stored (alpha half range), indexed kinds only
    x, y, flags : the image chunk's header fields (flags ``0x2000``: stored swizzled)
    long_name : text of a long-name chunk ("" for the game's empty ones), or None for none
    palette_flags : the palette chunk's flags (``0x2000``: stored in the PS2 CLUT order)
    extra : chunks piste keeps without interpreting (types 124 hot-spot list, 105 metal alpha):
        ``[(position, raw bytes)]``, ``position`` the chunk's index in the image's chain (image,
        palette, long name and these), the bytes from its header to the next chunk
    """

    name: str
    kind: int
    pixels: np.ndarray
    palette: np.ndarray | None = None
    x: int = 0
    y: int = 0
    flags: int = 0
    long_name: str | None = None
    palette_flags: int = 0
    extra: list = field(default_factory=list)

    @property
    def width(self) -> int:
        return int(self.pixels.shape[1])

    @property
    def height(self) -> int:
        return int(self.pixels.shape[0])

    def stored_rgba(self) -> np.ndarray:
        """``(h, w, 4) uint8`` as stored: palette looked up, alpha still half range."""
        if self.kind == RGBA32:
            return self.pixels
        assert self.palette is not None  # indexed kinds are read and built with one
        return self.palette[self.pixels]

    def rgba(self) -> np.ndarray:
        """``(h, w, 4) uint8`` for display, the half-bright storage undone (module docstring):
        alpha doubled (cap 255) when no stored alpha exceeds 128; RGB ``clamp(2 c - 1, 0, 255)``
        when no opaque pixel's RGB exceeds 128.  Guards leave full-range images as stored."""
        out = self.stored_rgba().astype(np.int32)
        alpha = out[..., 3]
        if alpha.max(initial=0) <= 128:
            out[..., 3] = np.minimum(alpha * 2, 255)
        opaque = out[..., 3] > 0
        if not opaque.any() or out[..., :3][opaque].max(initial=0) <= 128:
            out[..., :3] = np.clip(out[..., :3] * 2 - 1, 0, 255)
        return out.astype(np.uint8)

    def _data(self) -> bytes:
        if self.kind == RGBA32:
            return np.ascontiguousarray(self.pixels, dtype=np.uint8).tobytes()
        if self.kind == 2:
            if self.flags & SWIZZLED:
                stored = np.empty(self.width * self.height, np.uint8)
                stored[swizzle8_order(self.width, self.height)] = np.asarray(self.pixels, np.uint8).ravel()
                return stored.tobytes()
            return np.ascontiguousarray(self.pixels, dtype=np.uint8).tobytes()
        flat = np.asarray(self.pixels, dtype=np.uint8).ravel()
        if len(flat) % 2:
            flat = np.concatenate([flat, [0]]).astype(np.uint8)
        return ((flat[0::2] & 15) | ((flat[1::2] & 15) << 4)).astype(np.uint8).tobytes()

    def validate(self) -> None:
        p = np.asarray(self.pixels)
        if p.dtype != np.uint8:
            raise ValidationError(f"ssh image {self.name!r}: pixels must be uint8, got {p.dtype}")
        if self.kind == RGBA32:
            if p.ndim != 3 or p.shape[2] != 4:
                raise ValidationError(f"ssh image {self.name!r}: a type-5 image needs (h, w, 4) pixels, got {p.shape}")
        elif self.kind in INDEXED:
            k = 1 << INDEXED[self.kind]
            pal = None if self.palette is None else np.asarray(self.palette)
            if p.ndim != 2:
                raise ValidationError(f"ssh image {self.name!r}: an indexed image needs (h, w) pixels, got {p.shape}")
            if pal is None or pal.dtype != np.uint8 or pal.ndim != 2 or pal.shape[1] != 4 or not 0 < len(pal) <= k:
                raise ValidationError(f"ssh image {self.name!r}: needs a (<= {k}, 4) uint8 palette")
            if p.size and int(p.max()) >= len(pal):
                raise ValidationError(f"ssh image {self.name!r}: index {int(p.max())} past its {len(pal)}-colour palette")
        else:
            raise ValidationError(f"ssh image {self.name!r}: kind must be 1, 2 or 5, got {self.kind}")
        if self.flags & SWIZZLED:
            if self.kind != 2:
                raise ValidationError(f"ssh image {self.name!r}: only 8-bit images can be written swizzled")
            try:
                swizzle8_order(self.width, self.height)
            except ValueError as exc:
                raise ValidationError(f"ssh image {self.name!r}: {exc}") from None
        if self.palette_flags & SWIZZLED and (self.palette is None or len(self.palette) % 32):
            raise ValidationError(f"ssh image {self.name!r}: a CLUT-ordered palette needs a multiple of 32 colours")
        if len(self.name.encode("latin-1", "replace")) > 4:
            raise ValidationError(f"ssh image {self.name!r}: names are at most 4 characters")
        for k, item in enumerate(self.extra):
            ok = isinstance(item, tuple) and len(item) == 2 and isinstance(item[0], int) and item[0] >= 0
            if not ok or not isinstance(item[1], (bytes, bytearray)) or len(item[1]) < 4 or item[1][0] not in KEPT:
                raise ValidationError(f"ssh image {self.name!r}: extra chunk {k} must be (position, bytes of a "
                                      f"type {' or '.join(map(str, KEPT))} chunk)")


def _state(im: SshImage) -> tuple:
    """Everything :meth:`SshBank.encode` writes of an image (to tell an edited image)."""
    pix = np.asarray(im.pixels)
    pal = None if im.palette is None else np.asarray(im.palette)
    return (im.name, im.kind, pix.dtype.str, pix.shape, pix.tobytes(), None if pal is None else (pal.shape, pal.tobytes()),
            im.x, im.y, im.flags, im.long_name, im.palette_flags, tuple((int(p), bytes(b)) for p, b in im.extra))


@dataclass
class SshBank:
    """A texture bank: ``images`` in directory order, ``creator`` (4 bytes, ``G278``).  A bank read
    from bytes remembers them: :meth:`to_bytes` gives those bytes back while no image was changed
    (whatever layout the writer of the file used), else :meth:`encode`'s layout."""

    images: list[SshImage]
    creator: bytes = CREATOR
    read_from: tuple | None = field(default=None, repr=False, compare=False)

    def __len__(self) -> int:
        return len(self.images)

    def __getitem__(self, i: int) -> SshImage:
        return self.images[i]

    def edited(self) -> bool:
        """Whether the bank differs from the bytes it was read from (True for a bank made in memory)."""
        if self.read_from is None:
            return True
        data, creator, states = self.read_from
        return (creator != self.creator or len(states) != len(self.images)
                or any(_state(im) != st for im, st in zip(self.images, states)))

    def to_bytes(self) -> bytes:
        """The bank's bytes: as read when nothing changed (:meth:`edited`), else :meth:`encode`."""
        if not self.edited() and self.read_from is not None:  # (edited() is True without read_from)
            return self.read_from[0]
        return self.encode()

    def encode(self) -> bytes:
        """Encode the bank (canonical layout: each image 16-byte aligned after ``Buy ERTS``)."""
        for im in self.images:
            im.validate()
        n = len(self.images)
        # the game's writer: header + directory reserved in 128-byte steps, "Buy ERTS" right after
        # the directory, then the images, "Buy ERTS" (16-aligned) between them, none after the last
        reserved = 112 + 128 * (-(-max(n - 12, 0) // 16))
        blobs = [_encode_image(im) for im in self.images]
        offsets = []
        pos = reserved
        for k, blob in enumerate(blobs):
            offsets.append(pos)
            pos += len(blob) + (16 if k < n - 1 else 0)
        out = bytearray(MAGIC + struct.pack("<II", pos, n) + self.creator)
        for im, off in zip(self.images, offsets):
            out += im.name.encode("latin-1", "replace").ljust(4, b"\0")[:4] + struct.pack("<I", off)
        out += SEPARATOR
        out += b"\0" * (reserved - len(out))
        for k, blob in enumerate(blobs):
            out += blob
            if k < n - 1:
                out += SEPARATOR + b"\0" * 8
        return bytes(out)


def _chunk(kind: int, data: bytes, w: int, h: int, x: int = 0, y: int = 0, flags: int = 0,
           explicit: bool = True) -> bytes:
    """A chunk padded to 16 bytes; size 0 ("implied", which readers do not pad) only where the
    data needs no padding, an explicit size otherwise."""
    body = data + b"\0" * (-(16 + len(data)) % 16)
    size = 16 + len(body) if explicit or len(body) != len(data) else 0
    return _CHUNK.pack(kind | (size << 8), w, h, x, y, flags) + body


def _encode_image(im: SshImage) -> bytes:
    """The game's chunk chain: an indexed image chunk with an explicit size, then its palette
    (size 0, x = the colour count); an RGBA chunk with size 0; then the long-name chunk; the
    kept chunks (:attr:`SshImage.extra`) at their positions in the chain, as read."""
    chain = [_chunk(im.kind, im._data(), im.width, im.height, im.x, im.y, im.flags, explicit=im.kind in INDEXED)]
    if im.kind in INDEXED:
        pal = np.ascontiguousarray(im.palette, dtype=np.uint8)
        if im.palette_flags & SWIZZLED:
            stored = np.empty_like(pal)
            stored[clut_order(len(pal))] = pal
            pal = stored
        chain.append(_chunk(PALETTE, pal.tobytes(), len(pal), 1, len(pal), 0, im.palette_flags, explicit=False))
    if im.long_name is not None:
        text = im.long_name.encode("latin-1", "replace") + b"\0"
        text += b"\0" * (-(4 + len(text)) % 16)
        chain.append(struct.pack("<I", LONG_NAME) + text)
    for pos, raw in sorted(im.extra, key=lambda e: e[0]):
        chain.insert(min(pos, len(chain)), bytes(raw))
    return b"".join(chain)


def _implied_size(kind: int, w: int, h: int) -> int:
    """The length of a size-0 chunk: its header and its data, not padded (SSX-Library)."""
    if kind == HOT_SPOTS:  # a 6-byte header, then count x 8 bytes, 16-aligned
        n = 6 + 8 * max(w, 0)
        return n + (-n % 16)
    return 16 + {1: (w * h + 1) // 2, 2: w * h, 5: w * h * 4, PALETTE: w * h * 4}.get(kind, max(w, 0) * max(h, 0))


def parse_ssh(data: bytes, path: str | os.PathLike[str] | None = None) -> SshBank:
    """Parse an ``.ssh`` bank's bytes (see :func:`read_ssh`)."""
    data = bytes(data)
    size = len(data)
    if size < 16:
        raise FormatError(path, f"truncated: {size} bytes, an .ssh header is 16", field="header")
    if data[:4] != MAGIC:
        raise FormatError(path, f"expected magic 'SHPS' (PS2 texture bank), got {data[:4]!r}", field="magic")
    n = struct.unpack_from("<I", data, 8)[0]
    creator = data[12:16]
    if 16 + 8 * n > size:
        raise FormatError(path, f"{n} images need a {16 + 8 * n}-byte directory, the file has {size} bytes",
                          field="image count")
    directory = [(data[16 + 8 * i:20 + 8 * i].rstrip(b"\0").decode("latin-1"),
                  struct.unpack_from("<I", data, 20 + 8 * i)[0]) for i in range(n)]
    images = []
    starts = sorted({off for _, off in directory} | {size})
    for i, (name, off) in enumerate(directory):
        where = f"image {i} ({name!r})"
        if off + 16 > size:
            raise FormatError(path, f"{where}: offset {off} lies past the end ({size} bytes)", field="offset")
        end = next(e for e in starts if e > off) if off < size else size
        term = data.find(SEPARATOR, off, end)
        images.append(_parse_image(data, off, term if term >= 0 else end, name, where, path))
    return SshBank(images, creator, (data, creator, [_state(im) for im in images]))


def _parse_image(data: bytes, off: int, end: int, name: str, where: str, path: str | os.PathLike[str] | None) -> SshImage:
    """Walk an image's chunks from ``off`` to ``end`` (the next image or its terminator); a chunk
    size of 0 is implied by the chunk's dimensions (not padded); a long-name chunk's text runs to
    its NUL, the next chunk 16-aligned after it; chunks of the kept types (124, 105) are kept as
    their bytes at their place in the chain."""
    size = len(data)
    pos = off
    image = None
    palette = None
    palette_flags = 0
    long_name = None
    extra = []
    for index in range(64):
        if pos + 4 > end:
            break
        word = struct.unpack_from("<I", data, pos)[0]
        kind, csize = word & 0xFF, word >> 8
        if kind == LONG_NAME:  # its size bytes are unused: NUL-terminated text, then 16-aligned
            stop = data.find(b"\0", pos + 4, end)
            stop = end if stop < 0 else stop
            long_name = data[pos + 4:stop].decode("latin-1")
            nxt = stop + 1
            pos = nxt + (-(nxt - off) % 16)
            continue
        if kind == HOT_SPOTS:
            if pos + 6 > end:
                raise FormatError(path, f"{where}: hot-spot chunk (type 124) at {pos} is truncated", field="chunk")
            count = struct.unpack_from("<h", data, pos + 4)[0]
            need = _implied_size(HOT_SPOTS, count, 1)
            length = csize if csize else need
            if count < 0 or length < 6 + 8 * count or pos + length > end:
                raise FormatError(path, f"{where}: hot-spot chunk (type 124) at {pos}: {count} points in {length} "
                                        f"bytes do not fit the image's {end - pos} bytes left", field="chunk")
            extra.append((index, data[pos:pos + length]))
            pos += length
            continue
        if pos + 16 > size:
            raise FormatError(path, f"{where}: chunk header at {pos} is truncated", field="chunk")
        _, w, h, x, y, flags = _CHUNK.unpack_from(data, pos)
        body = pos + 16
        if csize == 0:
            csize = _implied_size(kind, w, h)
        if csize < 16:
            raise FormatError(path, f"{where}: chunk at {pos} declares {csize} bytes, less than its 16-byte header",
                              field="chunk size")
        if kind == METAL_ALPHA:
            if pos + csize > end:
                raise FormatError(path, f"{where}: metal-alpha chunk (type 105) at {pos} runs {csize} bytes, past "
                                        f"the image's end at {end}", field="chunk size")
            extra.append((index, data[pos:pos + csize]))
        elif kind in INDEXED or kind == RGBA32:
            if flags & SWIZZLED and kind != 2:
                raise FormatError(path, f"{where}: swizzled {'4-bit' if kind == 1 else '32-bit'} images (flag 0x2000) "
                                        "are not supported yet", field="flags")
            if not (0 < w <= MAX_SIDE and 0 < h <= MAX_SIDE):
                raise FormatError(path, f"{where}: image size {w}x{h} outside 1..{MAX_SIDE}", field="size")
            nbytes = {1: (w * h + 1) // 2, 2: w * h, 5: w * h * 4}[kind]
            if body + nbytes > size:
                raise FormatError(path, f"{where}: {w}x{h} type-{kind} pixels need {nbytes} bytes from {body}, "
                                        f"the file has {size}", field="pixels")
            raw = np.frombuffer(data, np.uint8, count=nbytes, offset=body)
            pix: np.ndarray
            if kind == RGBA32:
                pix = raw.reshape(h, w, 4).copy()
            elif kind == 2:
                if flags & SWIZZLED:
                    try:
                        raw = raw[swizzle8_order(w, h)]
                    except ValueError as exc:
                        raise FormatError(path, f"{where}: swizzled image: {exc}", field="flags") from None
                pix = raw.reshape(h, w).copy()
            else:
                pix = np.stack([raw & 15, raw >> 4], axis=1).ravel()[: w * h].reshape(h, w).copy()
            image = (kind, pix, x, y, flags)
        elif kind == PALETTE:
            k = w * h
            if not 0 < k <= 256 or body + 4 * k > size:
                raise FormatError(path, f"{where}: palette of {w}x{h} colours is out of range or truncated",
                                  field="palette")
            palette = np.frombuffer(data, np.uint8, count=4 * k, offset=body).reshape(k, 4).copy()
            palette_flags = flags
            if flags & SWIZZLED:
                if k % 32:
                    raise FormatError(path, f"{where}: a CLUT-ordered palette of {k} colours (not a multiple "
                                            "of 32) is not supported yet", field="palette")
                palette = palette[clut_order(k)]
        elif kind == REFPACK:
            raise FormatError(path, f"{where}: RefPack-compressed images (type 130) are not supported yet",
                              field="chunk type")
        else:
            raise FormatError(path, f"{where}: unknown chunk type {kind} at offset {pos} (known: 1, 2, 5, 33, "
                                    "105, 112, 124, 130)", field="chunk type")
        pos += csize
    if image is None:
        raise FormatError(path, f"{where}: no image chunk (type 1, 2 or 5)", field="chunk type")
    kind, pix, x, y, flags = image
    if kind in INDEXED:
        if palette is None:
            raise FormatError(path, f"{where}: an indexed image without a palette chunk (33)", field="palette")
        if pix.size and int(pix.max()) >= len(palette):
            raise FormatError(path, f"{where}: pixel index {int(pix.max())} past the {len(palette)}-colour palette",
                              field="pixels")
    return SshImage(name, kind, pix, palette, x, y, flags, long_name, palette_flags, extra)


def read_ssh(path: str | os.PathLike[str]) -> SshBank:
    """Read a ``.ssh`` texture bank; bad input raises :class:`~piste.errors.FormatError` naming the
    file, the image and the field."""
    path = Path(path)
    data = read_regular(path, MAX_FILE_BYTES, what="texture bank")  # regular files only, size-capped
    return parse_ssh(data, path)


def write_ssh(bank: SshBank, path: str | os.PathLike[str]) -> None:
    """Write ``bank`` to ``path`` atomically."""
    write_bytes_atomic(path, bank.to_bytes())


# ----------------------------------------------------------------------------- light maps
def lightmap_pages(bank: SshBank, path: str | os.PathLike[str] | None = None) -> np.ndarray:
    """The pages of a light-map bank as stored: ``(P, 128, 128, 4) uint8`` (RGB = Cs, A = As)."""
    pages = []
    for i, im in enumerate(bank.images):
        if im.kind != RGBA32 or im.pixels.shape[:2] != (PAGE_SIZE, PAGE_SIZE):
            raise FormatError(path, f"image {i} ({im.name!r}): a light-map page must be a 128x128 type-5 image, "
                                    f"got {im.width}x{im.height} type {im.kind}", field="image")
        pages.append(im.pixels)
    if not pages:
        return np.zeros((0, PAGE_SIZE, PAGE_SIZE, 4), np.uint8)
    return np.stack(pages)


def lightmap_bank(pages: npt.ArrayLike) -> SshBank:
    """A light-map bank from ``(P, 128, 128, 4) uint8`` pages (names ``0000``, ``0001``, ...)."""
    pages = np.asarray(pages)
    if pages.dtype != np.uint8 or pages.ndim != 4 or pages.shape[1:] != (PAGE_SIZE, PAGE_SIZE, 4):
        raise ValidationError(f"light-map pages must be (P, 128, 128, 4) uint8, got {pages.shape} {pages.dtype}")
    return SshBank([SshImage(f"{i:04d}", RGBA32, pages[i].copy(), long_name="") for i in range(len(pages))])


def tile_origins(rect: npt.ArrayLike, page: npt.ArrayLike, n_pages: int | None = None, path: str | os.PathLike[str] | None = None,
                 pages_path: str | os.PathLike[str] | None = None) -> np.ndarray:
    """Texel origins ``(n, 2)`` int (x, y) of each patch's tile in its page from the stored rects
    ``(n, 4)`` (x, y, w, h in 0..1); checks tiles are 8x8 inside the page and pages exist.  A
    refusal names ``path``, the file holding the rects and pages (the ``.pbd``), and ``pages_path``,
    the bank whose page count they were checked against (the ``_L.ssh``)."""
    rect = np.asarray(rect, dtype=np.float64)
    page = np.asarray(page)
    x0 = np.rint(rect[:, 0] * PAGE_SIZE).astype(np.int64)
    y0 = np.rint(rect[:, 1] * PAGE_SIZE).astype(np.int64)
    bad_rect = (x0 < 0) | (y0 < 0) | (x0 + TILE > PAGE_SIZE) | (y0 + TILE > PAGE_SIZE)
    bad_page = page < 0
    if n_pages is not None:
        bad_page |= page >= n_pages
    bad = bad_rect | bad_page
    if bad.any():
        k = int(np.argmax(bad))
        where = f" of {Path(pages_path).name}" if pages_path is not None else ""
        what = (f"light-map page {int(page[k])} is not one of the {n_pages} page(s){where}" if bad_page[k] else
                f"light-map tile {rect[k].tolist()} lies outside its 128x128 page")
        raise FormatError(path, f"patch {k}: {what}", field="lightmap_page" if bad_page[k] else "lightmap_rect")
    return np.stack([x0, y0], axis=1)


def extract_tiles(pages: npt.ArrayLike, rect: npt.ArrayLike, page: npt.ArrayLike, path: str | os.PathLike[str] | None = None,
                  pages_path: str | os.PathLike[str] | None = None) -> np.ndarray:
    """Each patch's 8x8 light-map tile in piste's orientation: ``(n, 8, 8, C)`` with
    ``[k, j, i]`` the texel at ``u = (i + 0.5) / 8``, ``v = (j + 0.5) / 8`` (the page holds it
    transposed: page row = ``u``, column = ``v``).  ``path``: the file of ``rect`` and ``page``
    (the ``.pbd``), ``pages_path``: the file of ``pages`` (the ``_L.ssh``), for error messages."""
    pages = np.asarray(pages)
    o = tile_origins(rect, page, len(pages), path, pages_path)
    r = np.arange(TILE)
    page = np.asarray(page, dtype=np.int64)
    # page[y0 + i, x0 + j] -> tile[j, i]
    rows = o[:, 1, None, None] + r[None, None, :]  # (n, j, i) -> y0 + i
    cols = o[:, 0, None, None] + r[None, :, None]  # (n, j, i) -> x0 + j
    return pages[page[:, None, None], rows, cols]


def place_tiles(tiles: npt.ArrayLike, rect: npt.ArrayLike, page: npt.ArrayLike, n_pages: int, fill: npt.ArrayLike | None = None) -> np.ndarray:
    """Inverse of :func:`extract_tiles`: pages ``(n_pages, 128, 128, C)`` holding every tile."""
    tiles = np.asarray(tiles)
    c = tiles.shape[-1]
    out = np.zeros((n_pages, PAGE_SIZE, PAGE_SIZE, c), tiles.dtype)
    if fill is not None:
        out[...] = fill
    o = tile_origins(rect, page, n_pages)
    r = np.arange(TILE)
    page = np.asarray(page, dtype=np.int64)
    rows = o[:, 1, None, None] + r[None, None, :]
    cols = o[:, 0, None, None] + r[None, :, None]
    out[page[:, None, None], rows, cols] = tiles
    return out
