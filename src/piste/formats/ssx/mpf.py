"""SSX Tricky (PS2) rider and board models, ``.mpf``: read, edit, write back byte for byte.

Bytes <-> arrays (numpy). ``MpfFile.to_model()`` converts to piste's character
:class:`~piste.character.Model` (:mod:`piste.formats.ssx.mpf_model`); the encoder from a piste
rider is :mod:`piste.formats.ssx.mpf_encode`; the layout constants are in
:mod:`piste.formats.ssx.mpf_layout`.

Facts
-----
From ``/work/shared/SSX-FORMATS.md``, OpenSlope's Apache-2.0 prose spec
``Trailmap/specs/240-models-mpf.md``, checked against SSX-Library / the SSX Collection Multitool's
``TrickyPS2MPF.cs`` and ``MpfStructure.go`` of ``Erickson400/TheTrickyModels`` (read for facts
only; no code from them is in this module) and against the bytes of the three public retail models.

* Little-endian. Header 12 bytes: u32 format id (8 = Tricky PS2), i16 sub-model count, i16
  directory offset (12), u32 data start (= 12 + 80 n + 4); the directory is ``n`` 80-byte entries
  then 4 unused bytes (:data:`DIR_DTYPE`). Blob ``i`` is ``size`` bytes at ``data start + offset``;
  its seven section offsets are blob-relative (bones, IK points, mesh groups, mesh data,
  materials, weight-reference lists, weight palettes) and its seven i16 counts are (palettes,
  weight-reference lists, groups, bones, materials, IK points, morph keys); i8 file id.
* Bone 84 bytes (:data:`BONE_DTYPE`): name, parent file id, parent bone, channel flags, mirror
  partner, bind translation (cm), bind rotation (3 radians), mirror rotation offset, mirror
  rotation scale + translation scale. IK point 16 bytes: 3 f32 + u32 bone. Material 32 bytes:
  five 4-char texture ids, f32 second-pass blend, 2 f32 unread.
* Mesh groups, three levels: group header 20 bytes (type 1 render / 17 shadow / 256 morph,
  material, unknown, link count, link offset); link 8 bytes (offset, count of mesh headers),
  paired 1:1 in file order with the weight-reference lists; mesh header 12 bytes (chunk-stream
  offset, morph-key offset relative to it or -1, morph-key packet size or -1).
* Weight palette header 12 bytes (count, offset, constant 36); entry 4 bytes: i16 integer percent,
  u8 bone, u8 file id, summing to 100. Weight-reference list 8 bytes: count, offset of ``count``
  u32 palette indices. A vertex's slot indexes its link's list.
* Mesh data: chunks (render/morph chunks of at most 59 vertices, shadow chunks 165: the retail
  figures). A chunk (checked against the retail bytes of ``board.mpf``, ``moby_body.mpf`` and
  ``moby_head.mpf``, all 175 of their chunks):

  - a 32-byte preamble: DMA CNT tag (qwc = 1 + the GIF tag, strip-table header and strips), 2
    zero words, then VIF ``NOP, STCYCL 1/1, NOP, UNPACK V4-32`` (NUM = strips + 2, FLG): byte 31
    is 0x6C, which is how a chunk is recognised;
  - a 16-byte GIF tag: NLOOP = vertices, EOP, PRE; render and morph chunks PRIM 0x5C (strip,
    Gouraud, textured, blended), 3 registers 0x412 (ST, RGBAQ, XYZ2); shadow chunks PRIM 0x44, one
    register 0x4 (XYZ2);
  - the strip table: a 16-byte header (u32 strip count, u32 14, u32 114 or 0 on shadow chunks,
    u32 vertex count) and a 16-byte entry per strip (u32 vertex count, 12 zero bytes);
  - **a 16-byte DMA CNT quadword** whose qwc counts the attribute sections after it. SSX-Library
    (``TrickyPS2MPF.cs``: its reader skips 16 bytes after the strips, its writer emits a "set new
    rowcount" quadword) and ``MpfStructure.go`` (``BlockRowHeader``) both have it; OpenSlope's
    spec 240 and an earlier version of piste's fact sheet leave it out. The retail bytes side with
    SSX-Library: in every retail chunk the quadword is there and its qwc equals the sections'
    length exactly;
  - the attribute sections, each a 48-byte VIF header ``[NOP, STROW, r0, r1] [r2, r3, STMASK,
    mask] [NOP, STCYCL, NOP, UNPACK]`` then its data, zero-padded to 16 bytes: UV (row 0, 0,
    0x1000, 0x1000, mask 0x50505050, STCYCL 1/3, UNPACK V4-16 to strips + 2; v x 4 i16: u, v /
    4096, skin-transform address ``14 + 4 slot``, normal-matrix address ``114 + 3 slot``), normals
    (row 0, 0, 0, 0x8000, mask 0x40404040, STCYCL 1/3, masked UNPACK V3-16 to strips + 3; v x 3
    i16 / 32768), positions (row 0, 0, 0, 1.0f, same mask, STCYCL 1/3, masked UNPACK V3-32 to
    strips + 4; v x 3 f32, model space, cm). Shadow chunks have one section: row 0, 0, 0, 1.0f,
    mask 0x40404040, STCYCL 1/1, UNPACK V4-32 to strips + 2; v x (3 f32 + u32 slot address);
  - a 32-byte trailer: render chunks DMA CNT (qwc 1), 2 zero words, ``STCYCL 1/1, MSCAL p, x,
    y`` where ``p`` is 0 or 10 (kept per chunk: :attr:`Chunk.program`) and ``x, y`` are 0, 0 on
    the 1st, 3rd, ... chunk of a stream, MSCAL 6, MSCAL 6 on the 2nd, 4th, ..., and MSCAL 8,
    MSCAL 6 when the stream ends on an odd-numbered chunk; shadow chunks DMA CNT (1), ``0, 0, 0,
    STCYCL 1/1, 0, MSCAL 4``; morph chunks DMA RET (1), ``0, 0, 0, STCYCL 1/1, 0, 0``.

  After each mesh: its morph keys (type-256 meshes), then the **end packets**: A = DMA RET (1),
  ``0, 0, 0, STCYCL 1/1, 0, 0`` (32 bytes) after every mesh except a morph mesh that is not its
  group's last, and B = DMA RET (1), ``0, 0, 0, 0, 0, STCYCL 1/1, 0, FLUSHE, 0, MSCAL 0`` (48
  bytes) after each group's last mesh (piste also writes A after a morph mesh without keys,
  which retail files do not have). Strips: triangle ``i`` of a strip is ``(i, i+1, i+2)``,
  odd ones flipped; degenerate triangles are dropped.
* Morph keys (type-256 groups): the directory's morph-key count of packets, each a 32-byte head
  (DMA RET tag, qwc = 2 + deltas / 16; ``0, 0, 0, STCYCL 4/4, 0``, masked UNPACK V3-8 whose NUM =
  byte 30, to 0xB6 FLG), ``NUM`` x 3 i8 deltas (1/12.8 model unit each), 16-aligned, then a 16-byte
  tail ``0, FLUSHE, 0, MSCAL 2``. The mesh header's morph offset is the keys' start relative to
  the mesh, its morph size one key's bytes.
* Blob layout (retail, and what :func:`write_mpf` writes for a blob laid out anew): materials,
  bones, IK points, weight-palette headers + entries, weight-reference headers + indices, group
  headers, links, mesh headers, zero padding to 16, then the meshes' data in group / link / mesh
  order. Blobs follow each other 16-aligned after the directory.

piste's assumptions (what the facts leave open)
-----------------------------------------------
* What ``MSCAL 10`` rather than ``MSCAL 0`` selects is not documented; in the retail files every
  one of the 48 chunks calling 10 skins each vertex with a single bone (a rigid path, it seems),
  while 17 of the 97 chunks calling 0 could have. A chunk read keeps its program; the encoder
  writes 10 exactly when all of a chunk's vertices follow one bone, else 0.
* Every tag byte of a chunk is *kept* (in the sub-model's source) when read, and regenerated by
  the rule above only when a blob is laid out anew; :func:`tag_differences` says which read
  chunks the rule would change (none of the retail ones).

Round trip
----------
A file read from disk keeps its bytes (:attr:`MpfFile.source`, :attr:`SubModel.source`). When
only values change (vertex positions, UVs, weights, bone transforms, names...) and no count,
:func:`write_mpf` writes the values back into those bytes at the offsets they were read from, so
everything piste does not interpret survives and an unedited file is written back identical.
When the shape changes (or for a model piste built), the blob is laid out anew as above.
:attr:`MpfFile.unknown` lists every byte range no parsed structure claims (gaps, trailing bytes,
non-zero unused fields; zero alignment padding under 16 bytes is not listed); they are kept, never
silently dropped. Chunk tag bytes are claimed by their chunk (and kept); :func:`tag_differences`
names the chunks whose tags differ from what piste would write, i.e. what a re-layout would change.

API
---
::

    read_mpf(path) -> MpfFile / parse_mpf(data, path) -> MpfFile
    write_mpf(mpf, path) -> list[str]          atomic; returns notes (what was laid out anew)
    mpf_bytes(mpf) -> bytes
    MpfFile, SubModel, Group, Link, Mesh, Chunk, MorphKey; MpfFile.to_model(*other_files) -> SsxModel
    pack_chunks(strips, uv, normals, positions, max_vertices=55) -> list[Chunk]  (the encoder's packer)
    strip_triangles(strip_lengths) -> (t, 3) int64   local vertex indices of a chunk's strips
    game_limits(mpf) -> list[(sub-model, problem)]     what the game would not take (59 / 165 vertices a chunk,
                                                       25 matrices a link, 25 % steps, ~3000/1500/750 triangles)
    tag_differences(mpf) -> list                       chunks whose kept tag bytes differ from piste's layout
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, overload

import numpy as np
import numpy.typing as npt

from piste.errors import FormatError, ValidationError
from piste.formats.atomic import write_bytes_atomic
from piste.formats.safe_io import read_regular
from piste.formats.ssx.mpf_layout import (  # noqa: F401  (re-exported: the module's public names)
    BONE_DTYPE, DIR_DTYPE, ENCODER_CHUNK_VERTICES, FORMAT_TRICKY_PS2, GROUP_DTYPE, GROUP_MORPH, GROUP_RENDER,
    GROUP_SHADOW, IK_DTYPE, LINK_DTYPE, LOD_TRIANGLE_BUDGETS, MATERIAL_DTYPE, MAX_CHUNK_VERTICES,
    MAX_SHADOW_CHUNK_VERTICES, MAX_FILE_BYTES, MAX_GROUP_MATRICES, MAX_VERTICES_READ,
    MESH_DTYPE, MORPH_SCALE, NORMAL_SCALE, PALETTE_CONST, PALETTE_ENTRY_DTYPE, PALHDR_DTYPE, REF_DTYPE,
    SLOT_NORMAL_BASE, SLOT_TRANSFORM_BASE, UV_SCALE, strip_triangles,
)
from piste.formats.ssx.mpf_model import mpf_to_model

if TYPE_CHECKING:
    from piste.formats.ssx.mpf_model import SsxModel

__all__ = [
    "MpfFile", "SubModel", "Group", "Link", "Mesh", "Chunk", "MorphKey", "read_mpf", "parse_mpf", "write_mpf",
    "mpf_bytes", "pack_chunks", "strip_triangles", "game_limits", "tag_differences", "FORMAT_TRICKY_PS2", "MAX_CHUNK_VERTICES",
    "MAX_SHADOW_CHUNK_VERTICES", "ENCODER_CHUNK_VERTICES", "LOD_TRIANGLE_BUDGETS", "MAX_GROUP_MATRICES",
    "UV_SCALE", "NORMAL_SCALE", "MORPH_SCALE", "BONE_DTYPE", "MATERIAL_DTYPE", "IK_DTYPE", "DIR_DTYPE",
    "PALETTE_ENTRY_DTYPE", "GROUP_RENDER", "GROUP_SHADOW", "GROUP_MORPH", "SLOT_TRANSFORM_BASE", "SLOT_NORMAL_BASE",
]

MAX_CHUNK_REFS = 1 << 16  # chunks referenced by one sub-model's mesh headers (a rider: a few hundred)
_SECTIONS = ("bones", "ik", "groups", "mesh_data", "materials", "weight_refs", "palettes")
_COUNTS = ("palettes", "weight_refs", "groups", "bones", "materials", "ik", "morph_keys")
_NONE = 0xFFFFFFFF

# VIF codes (cmd << 24 | num << 16 | imm)
_NOP = 0x00000000
_STCYCL_11 = 0x01000101
_STCYCL_13 = 0x01000103  # CL 3, WL 1: every third quadword
_STCYCL_44 = 0x01000404
_STROW = 0x30000000
_STMASK = 0x20000000
_FLUSHE = 0x10000000
_MSCAL = 0x14000000
_UNPACK_V4_32, _UNPACK_V3_32, _UNPACK_V4_16, _UNPACK_V3_16, _UNPACK_V3_8 = 0x6C, 0x68, 0x6D, 0x69, 0x6A
_MASK = 0x10
_FLG = 0x8000  # UNPACK address relative to TOPS
_DMA_CNT, _DMA_RET = 1, 6
_U4, _U1 = struct.Struct("<4I"), struct.Struct("<I")
_GIF_RENDER = (0x5C, 3, 0x412)  # PRIM, NREG, REGS: strip | Gouraud | textured | blended; ST, RGBAQ, XYZ2
_GIF_SHADOW = (0x44, 1, 0x4)    # strip | blended; XYZ2
#: the end packets after a mesh (module docstring): A after a mesh, B after a group's last mesh
_END_A = np.array([(_DMA_RET << 28) | 1, 0, 0, 0, _NOP, _STCYCL_11, _NOP, _NOP], "<u4").tobytes()
_END_B = np.array([(_DMA_RET << 28) | 1, 0, 0, 0, _NOP, _NOP, _NOP, _STCYCL_11, _NOP, _FLUSHE, _NOP, _MSCAL],
                  "<u4").tobytes()
#: section headers' (row, mask, STCYCL, UNPACK cmd) for UV, normals, positions; and the shadow section
_SECTION_TAGS = (((0, 0, 0x1000, 0x1000), 0x50505050, _STCYCL_13, _UNPACK_V4_16),
                 ((0, 0, 0, 0x8000), 0x40404040, _STCYCL_13, _UNPACK_V3_16 | _MASK),
                 ((0, 0, 0, 0x3F800000), 0x40404040, _STCYCL_13, _UNPACK_V3_32 | _MASK))
_SHADOW_SECTION_TAG = ((0, 0, 0, 0x3F800000), 0x40404040, _STCYCL_11, _UNPACK_V4_32)


def _align(n: int, a: int = 16) -> int:
    return (n + a - 1) // a * a


def _vif(cmd: int, num: int = 0, imm: int = 0) -> int:
    return (cmd << 24) | ((num & 0xFF) << 16) | (imm & 0xFFFF)


def _dma(qwc: int, kind: int) -> tuple:
    return (qwc & 0xFFFF) | (kind << 28), 0


def _words(*w: int) -> bytes:
    return np.array(w, "<u4").tobytes()


# ------------------------------------------------------------------------------------------ data
@dataclass
class Chunk:
    """One VU chunk (retail: <= 59 vertices, <= 165 on shadow chunks), its arrays exactly as stored.

    Attributes
    ----------
    strip_lengths : (s,) uint32       vertex count of each strip (they partition the vertices)
    positions : (v, 3) float32        model space (bind pose), centimetres
    uv : (v, 4) int16 or None         u, v (/4096), skin-transform address (14 + 4 slot),
                                      normal-matrix address (114 + 3 slot); None on shadow chunks
    normals : (v, 3) int16 or None    /32768; None on shadow chunks
    shadow_slots : (v,) uint32 or None  per-vertex transform address of shadow chunks
    table_words : (2,) uint32         the strip-table header's 2nd and 3rd words (14, 114; 0 = shadow)
    program : int                     the VU program address the render trailer calls first (MSCAL 0, or
                                      10: retail uses it only on chunks whose vertices follow one bone)
    raw : dict                        as read: ``strip_tail (s, 3) uint32`` (each strip entry after its
                                      count) and ``span`` (blob offsets of the chunk: its tag bytes,
                                      kept in the sub-model's source); regenerated when laid out anew
    offset : int | None               blob offset it was read from
    """

    strip_lengths: np.ndarray
    positions: np.ndarray
    uv: np.ndarray | None = None
    normals: np.ndarray | None = None
    shadow_slots: np.ndarray | None = None
    table_words: np.ndarray = field(default_factory=lambda: np.array([SLOT_TRANSFORM_BASE, SLOT_NORMAL_BASE], "<u4"))
    raw: dict = field(default_factory=dict)
    offset: int | None = None
    program: int = 0

    @property
    def shadow(self) -> bool:
        return self.uv is None

    @property
    def n_vertices(self) -> int:
        return int(self.positions.shape[0])

    @property
    def slots(self) -> np.ndarray:
        """Weight slot of each vertex ``(v,) int64`` (index into the link's weight-reference list)."""
        if self.uv is None:  # a shadow mesh: its slots are stored apart
            assert self.shadow_slots is not None
            a = self.shadow_slots.astype(np.int64)
        else:
            a = self.uv[:, 2].astype(np.int64)
        return (a - SLOT_TRANSFORM_BASE) // 4

    def uv_float(self) -> np.ndarray:
        """``(v, 2) float32`` texture coordinates."""
        return (self.uv[:, :2].astype(np.float32) / UV_SCALE) if self.uv is not None else \
            np.zeros((self.n_vertices, 2), np.float32)

    def normals_float(self) -> np.ndarray:
        """``(v, 3) float32`` normals (as stored, not renormalised)."""
        return (self.normals.astype(np.float32) / NORMAL_SCALE) if self.normals is not None else \
            np.zeros((self.n_vertices, 3), np.float32)

    def triangles(self) -> np.ndarray:
        """``(t, 3) int64`` chunk-local triangles of the strips, degenerate ones (a repeated
        position) dropped."""
        t = strip_triangles(self.strip_lengths)
        if t.size:
            p = self.positions
            same = (np.all(p[t[:, 0]] == p[t[:, 1]], 1) | np.all(p[t[:, 1]] == p[t[:, 2]], 1)
                    | np.all(p[t[:, 0]] == p[t[:, 2]], 1))
            t = t[~same]
        return t


@dataclass
class MorphKey:
    """One morph target of a mesh: ``deltas (n, 3) int8`` (x 1/12.8 model units), parallel to the
    mesh's vertices; ``raw`` keeps the packet's head (32 bytes) and tail bytes as read."""

    deltas: np.ndarray
    raw: dict = field(default_factory=dict)
    offset: int | None = None


@dataclass
class Mesh:
    """Level 3: a chunk stream and its morph keys (``morphs`` empty when none)."""

    chunks: list
    morphs: list = field(default_factory=list)
    end: bytes | None = None          # the end packets read after the mesh (A, A + B or none: module docstring)
    header: np.ndarray | None = None  # (MESH_DTYPE) as read
    offset: int | None = None         # blob offset of its 12-byte header

    @property
    def n_vertices(self) -> int:
        return sum(c.n_vertices for c in self.chunks)


@dataclass
class Link:
    """Level 2: meshes sharing one weight-reference list ``refs (k,) uint32`` (palette indices,
    addressed by the vertices' slots; at most 25 in the game)."""

    meshes: list
    refs: np.ndarray
    offset: int | None = None
    refs_offset: int | None = None


@dataclass
class Group:
    """Level 1: ``type`` (1 render, 17 shadow, 256 morph), ``material`` index, ``unknown`` word."""

    type: int
    material: int
    links: list
    unknown: int = 0
    offset: int | None = None


@dataclass
class SubModel:
    """One named sub-model (``Body3000``, ``Head3000``, ...) of an ``.mpf``.

    Attributes
    ----------
    name : str
    file_id : int                     the model's file id (cross-file bone parents and skinning)
    bones : (b,) BONE_DTYPE
    ik : (n,) IK_DTYPE
    materials : (m,) MATERIAL_DTYPE
    groups : list[Group]
    palettes : list[(k,) PALETTE_ENTRY_DTYPE]   weight palettes (percent, bone, file id)
    palette_consts : (p,) uint32      the palette headers' third word (36)
    morph_keys : int                  the directory's morph-key count
    entry : (DIR_DTYPE) record        the directory entry as read (unused bytes kept)
    source : bytes | None             the blob as read
    """

    name: str
    file_id: int = 0
    bones: np.ndarray = field(default_factory=lambda: np.zeros(0, BONE_DTYPE))
    ik: np.ndarray = field(default_factory=lambda: np.zeros(0, IK_DTYPE))
    materials: np.ndarray = field(default_factory=lambda: np.zeros(0, MATERIAL_DTYPE))
    groups: list = field(default_factory=list)
    palettes: list = field(default_factory=list)
    palette_consts: np.ndarray | None = None
    morph_keys: int = 0
    entry: np.ndarray | None = None
    source: bytes | None = None
    _shape: tuple | None = None
    _offsets: dict = field(default_factory=dict)

    @property
    def links(self) -> list:
        return [lk for g in self.groups for lk in g.links]

    @property
    def bone_names(self) -> list:
        return [b.decode("ascii", "replace") for b in self.bones["name"]]

    @property
    def n_vertices(self) -> int:
        return sum(m.n_vertices for lk in self.links for m in lk.meshes)

    @property
    def n_triangles(self) -> int:
        return sum(len(c.triangles()) for lk in self.links for m in lk.meshes for c in m.chunks)

    def shape(self) -> tuple:
        """Everything that fixes the byte layout (counts, sizes); equal shapes can be patched in place."""
        groups = tuple((len(g.links), tuple((len(lk.refs), tuple(
            (tuple((len(c.strip_lengths), c.n_vertices, c.shadow) for c in m.chunks),
             tuple(len(k.deltas) for k in m.morphs)) for m in lk.meshes)) for lk in g.links)) for g in self.groups)
        return (len(self.bones), len(self.ik), len(self.materials), groups,
                tuple(len(p) for p in self.palettes), self.morph_keys)


@dataclass
class MpfFile:
    """A whole ``.mpf``: ``format_id`` (8), ``models`` (list of :class:`SubModel`), ``dir_tail``
    (the 4 bytes after the directory), ``source`` (the file as read), ``unknown`` (byte ranges
    no structure claims: ``(where, offset, size, note)``, kept, not dropped), ``path``."""

    models: list
    format_id: int = FORMAT_TRICKY_PS2
    dir_tail: bytes = b"\0\0\0\0"
    source: bytes | None = None
    unknown: list = field(default_factory=list)
    path: str | None = None

    def __getitem__(self, name: str) -> SubModel:
        for m in self.models:
            if m.name == name:
                return m
        raise KeyError(f"no sub-model {name!r} in {self.path or 'the .mpf'}: it has "
                       f"{', '.join(m.name for m in self.models)}")

    @property
    def names(self) -> list:
        return [m.name for m in self.models]

    def to_model(self, *others: "MpfFile", name: str | None = None, weld: bool = True) -> SsxModel:
        """piste's :class:`~piste.character.Model` of this file (plus ``others``, e.g. the head
        file of a body file): :func:`piste.formats.ssx.mpf_model.mpf_to_model`."""
        return mpf_to_model(self, *others, name=name, weld=weld)


# ------------------------------------------------------------------------------------ strips
@overload
def pack_chunks(strips: Iterable[npt.ArrayLike], uv: np.ndarray | None, normals: np.ndarray | None,
                positions: np.ndarray, max_vertices: int = ..., shadow_slots: np.ndarray | None = ...,
                return_index: Literal[False] = ...) -> list[Chunk]: ...


@overload
def pack_chunks(strips: Iterable[npt.ArrayLike], uv: np.ndarray | None, normals: np.ndarray | None,
                positions: np.ndarray, max_vertices: int = ..., shadow_slots: np.ndarray | None = ..., *,
                return_index: Literal[True]) -> tuple[list[Chunk], list[np.ndarray]]: ...


def pack_chunks(strips: Iterable[npt.ArrayLike], uv: np.ndarray | None, normals: np.ndarray | None,
                positions: np.ndarray, max_vertices: int = ENCODER_CHUNK_VERTICES,
                shadow_slots: np.ndarray | None = None,
                return_index: bool = False) -> list[Chunk] | tuple[list[Chunk], list[np.ndarray]]:
    """Pack non-indexed strips into chunks of at most ``max_vertices`` vertices.

    ``strips`` is a list of vertex-index arrays into the per-vertex arrays ``uv (n, 4) int16``,
    ``normals (n, 3) int16``, ``positions (n, 3) float32`` (``uv``/``normals`` None and
    ``shadow_slots (n,) uint32`` for a shadow mesh). A strip longer than a chunk is cut into pieces
    that overlap by two vertices and start at even offsets, so every triangle keeps its winding.
    Returns the chunks, and with ``return_index`` also each chunk's source vertex indices.
    """
    if max_vertices < 4:
        raise ValidationError(f"max_vertices must be >= 4, got {max_vertices}")
    pieces = []
    step = (max_vertices - 2) // 2 * 2  # even, so every piece starts at an even offset
    for s in strips:
        s = np.asarray(s, np.int64)
        if s.size < 3:
            continue
        start = 0
        while True:  # pieces of step + 2 vertices: consecutive pieces share exactly one edge
            piece = s[start:start + step + 2] if s.size - start > max_vertices else s[start:]
            pieces.append(piece)
            if start + piece.size >= s.size:
                break
            start += step
    chunks: list[Chunk] = []
    cur: list[np.ndarray] = []
    index: list[np.ndarray] = []
    size = 0
    for p in pieces + [None]:
        if p is None or size + p.size > max_vertices:
            if cur:
                idx = np.concatenate(cur)
                index.append(idx)
                chunks.append(Chunk(
                    strip_lengths=np.array([c.size for c in cur], "<u4"),
                    positions=np.ascontiguousarray(positions[idx], "<f4"),
                    uv=None if uv is None else np.ascontiguousarray(uv[idx], "<i2"),
                    normals=None if normals is None else np.ascontiguousarray(normals[idx], "<i2"),
                    shadow_slots=None if shadow_slots is None else np.ascontiguousarray(shadow_slots[idx], "<u4"),
                    table_words=np.array([SLOT_TRANSFORM_BASE, 0 if uv is None else SLOT_NORMAL_BASE], "<u4")))
            cur, size = [], 0
            if p is None:
                break
        cur.append(p)
        size += p.size
    return (chunks, index) if return_index else chunks


# ------------------------------------------------------------------------------------ reading
class _Reader:
    def __init__(self, path: str | os.PathLike[str] | None, data: bytes, base: int, size: int, where: str,
                 buf: bytearray | None = None) -> None:
        self.path, self.data, self.base, self.size, self.where = path, data, base, size, where
        # arrays are writable views of one private copy of the file (no copy per array)
        self.buf = bytearray(data) if buf is None else buf
        self.claimed: list[tuple[int, int]] = []  # (offset, size) blob-relative

    def err(self, field_name: str, message: str) -> FormatError:
        return FormatError(self.path, f"{self.where}: {message}", field=field_name)

    def need(self, off: int, n: int, field_name: str) -> None:
        if off < 0 or n < 0 or off + n > self.size:
            raise self.err(field_name, f"{n} bytes at blob offset {off} run past the end of the "
                                       f"{self.size}-byte blob")

    def arr(self, off: int, dtype: npt.DTypeLike, count: int, field_name: str, claim: bool = True) -> np.ndarray:
        dtype = np.dtype(dtype)
        if count < 0 or count > self.size:
            raise self.err(field_name, f"count {count} is impossible in a {self.size}-byte blob")
        if count == 0:  # an empty section's offset is never followed
            return np.zeros(0, dtype)
        self.need(off, dtype.itemsize * count, field_name)
        if claim and count:
            self.claimed.append((off, dtype.itemsize * count))
        return np.frombuffer(self.buf, dtype, count, self.base + off)

    def raw(self, off: int, n: int, field_name: str) -> bytes:
        self.need(off, n, field_name)
        if n:
            self.claimed.append((off, n))
        return bytes(self.data[self.base + off:self.base + off + n])

    def byte(self, off: int) -> int:
        return self.data[self.base + off]


def _read_chunk(r: _Reader, off: int, where: str) -> tuple:
    """Parse one chunk at blob offset ``off``; returns ``(Chunk, next offset)``. The chunk's
    whole span (tags included) is claimed at once; its tag bytes stay in the sub-model's source.
    (Scalars are read with ``struct`` and error texts built only on failure: a rider has hundreds
    of chunks and this runs for each.)"""
    if off < 0 or off + 64 > r.size:
        r.need(off, 64, f"{where}.strip_table")
    base = r.base
    b0 = base + off
    n_strips, w1, w2, n_vert = _U4.unpack_from(r.data, b0 + 48)
    if n_strips > MAX_VERTICES_READ:
        raise r.err(f"{where}.strip_count", f"{where}: strip count {n_strips} is more than {MAX_VERTICES_READ}")
    if n_vert > MAX_VERTICES_READ:
        raise r.err(f"{where}.vertex_count", f"{where}: vertex count {n_vert} is more than {MAX_VERTICES_READ}")
    cnt = off + 64 + 16 * n_strips  # the DMA CNT quadword covering the attribute sections
    if cnt + 16 > r.size:
        r.need(off + 64, 16 * n_strips + 16, f"{where}.strips")
    strips = np.frombuffer(r.buf, "<u4", 4 * n_strips, b0 + 64).reshape(n_strips, 4)
    lengths = strips[:, 0]
    total = int(lengths.sum())
    if total != n_vert:
        raise r.err(f"{where}.strip_lengths", f"{where}: strip lengths sum to {total} but the "
                                               f"strip table declares {n_vert} vertices")
    shadow = w2 == 0
    p = cnt + 16
    if shadow:
        at0 = p + 48
        p = _align(at0 + 16 * n_vert)
    else:
        at0 = p + 48
        at1 = _align(at0 + 8 * n_vert) + 48
        at2 = _align(at1 + 6 * n_vert) + 48
        p = _align(at2 + 12 * n_vert)
    tag = _U1.unpack_from(r.data, base + cnt)[0]
    want = (p - cnt - 16) // 16
    if (tag >> 28) & 7 != _DMA_CNT or tag & 0xFFFF != want:
        raise r.err(f"{where}.dma_cnt", f"{where}: expected the 16-byte DMA CNT quadword after the strip table "
                                        f"(qwc {want}, covering the {'position' if shadow else 'UV, normal and position'}"
                                        f" sections) at blob offset {cnt}, found tag 0x{tag:08X} (a file written "
                                        f"without it, e.g. by piste before 2026-11-26, must be re-encoded)")
    end = p + 32  # the chunk's trailer (DMA tag + VIF codes)
    if end > r.size:
        r.need(off, end - off, f"{where}.{'positions' if shadow else 'uv'}")
    r.claimed.append((off, end - off))
    uv = normals = slots = None
    if not shadow:
        uv = np.frombuffer(r.buf, "<i2", 4 * n_vert, base + at0).reshape(n_vert, 4)
        normals = np.frombuffer(r.buf, "<i2", 3 * n_vert, base + at1).reshape(n_vert, 3)
        pos = np.frombuffer(r.buf, "<f4", 3 * n_vert, base + at2).reshape(n_vert, 3)
    else:
        both = np.frombuffer(r.buf, "<u4", 4 * n_vert, base + at0).reshape(n_vert, 4)
        pos = both[:, :3].copy().view("<f4")
        slots = both[:, 3].copy()
    if not np.isfinite(pos).all():
        raise r.err(f"{where}.positions", f"{where}: positions contain NaN or infinity")
    call = _U1.unpack_from(r.data, base + p + 20)[0]
    program = call & 0xFFFF if call >> 24 == _MSCAL >> 24 else 0
    ch = Chunk(strip_lengths=lengths, positions=pos, uv=uv, normals=normals, shadow_slots=slots,
               table_words=np.array([w1, w2], "<u4"), raw={"strip_tail": strips[:, 1:], "span": (off, end)},
               offset=off, program=program)
    return ch, end


def _read_stream(r: _Reader, off: int, where: str, starts: frozenset[int] | set[int] = frozenset()) -> tuple:
    """The chunks from blob offset ``off`` on, up to a non-chunk or another mesh's start (blob
    offsets ``starts``): ``(chunks, offset after the last)``."""
    chunks: list[Chunk] = []
    p = off
    r.need(off, 32, f"{where}.chunk0.preamble")
    if r.byte(off + 31) != _UNPACK_V4_32:
        raise r.err(f"{where}.chunk0.preamble", f"{where}: no chunk at blob offset {off} (byte 31 is "
                                                f"0x{r.byte(off + 31):02X}, a chunk preamble has 0x6C)")
    while p + 32 <= r.size and r.byte(p + 31) == _UNPACK_V4_32 and (p == off or p not in starts):
        ch, p = _read_chunk(r, p, f"{where}.chunk{len(chunks)}")
        chunks.append(ch)
    return chunks, p


def _read_end(r: _Reader, p: int, where: str) -> bytes | None:
    """The end packets (A, A + B) at blob offset ``p``, claimed; None when there are none."""
    out = b""
    for name, pk in (("end", _END_A), ("group_end", _END_B)):
        n = len(pk)
        if p + n <= r.size and bytes(r.data[r.base + p:r.base + p + n]) == pk:
            out += r.raw(p, n, f"{where}.{name}")
            p += n
        else:
            break
    return out or None


def _read_morphs(r: _Reader, off: int, count: int, size: int, where: str) -> tuple:
    """``count`` morph keys from blob offset ``off``: ``(keys, offset after the last)``. Keys of
    one packet size (the mesh header's; retail: always) are read as one block."""
    keys = []
    p = off
    if count and size != _NONE and size >= 48 and off >= 0 and off + count * size <= r.size:
        block = np.frombuffer(r.buf, np.uint8, count * size, r.base + off).reshape(count, size)
        nums = block[:, 30]
        num = int(nums[0])
        if np.all(nums == num) and 32 + _align(3 * num) + 16 <= size:
            r.claimed.append((off, count * size))
            deltas = block[:, 32:32 + 3 * num].view(np.int8).reshape(count, num, 3)
            keys = [MorphKey(deltas=deltas[k], raw={"head": block[k, :32], "tail": block[k, 32 + 3 * num:]},
                             offset=off + k * size) for k in range(count)]
            return keys, off + count * size
    for k in range(count):
        head = r.raw(p, 32, f"{where}.morph{k}.head")
        num = head[30]
        span = _align(3 * num)
        one = r.arr(p + 32, "i1", 3 * num, f"{where}.morph{k}.deltas").reshape(num, 3)
        total = size if size != _NONE and size >= 32 + span else 32 + span + 16
        tail = r.raw(p + 32 + 3 * num, total - 32 - 3 * num, f"{where}.morph{k}.tail")
        keys.append(MorphKey(deltas=one, raw={"head": head, "tail": tail}, offset=p))
        p += total
    return keys, p


def _read_submodel(path: str | os.PathLike[str] | None, data: bytes, base: int, entry: np.ndarray, index: int, buf: bytearray | None = None) -> tuple:
    name = bytes(entry["name"]).split(b"\0", 1)[0].decode("ascii", "replace")
    where = f"sub-model {index} {name!r}"
    size = int(entry["size"])
    r = _Reader(path, data, base, size, where, buf)
    sec = {k: int(v) for k, v in zip(_SECTIONS, entry["sections"])}
    cnt = {k: int(v) for k, v in zip(_COUNTS, entry["counts"])}
    for k, v in cnt.items():
        if v < 0:
            raise r.err(f"{where}.count.{k}", f"negative {k} count {v}")
    sub = SubModel(name=name, file_id=int(entry["file_id"]), morph_keys=cnt["morph_keys"], entry=entry.copy(),
                   source=bytes(data[base:base + size]))
    sub.bones = r.arr(sec["bones"], BONE_DTYPE, cnt["bones"], "bones")
    bad = ~(np.isfinite(sub.bones["translation"]).all(1) & np.isfinite(sub.bones["rotation"]).all(1))
    if bad.any():
        raise r.err("bones.translation", f"bone {int(np.argmax(bad))}: bind translation or rotation is NaN or infinite")
    sub.ik = r.arr(sec["ik"], IK_DTYPE, cnt["ik"], "ik_points")
    sub.materials = r.arr(sec["materials"], MATERIAL_DTYPE, cnt["materials"], "materials")
    ph = r.arr(sec["palettes"], PALHDR_DTYPE, cnt["palettes"], "palettes")
    sub.palette_consts = ph["const"].copy()
    pal_off = [int(o) for o in ph["offset"]]
    n_ent = ph["count"].astype(np.int64)
    ends = np.asarray(pal_off, np.int64) + 4 * n_ent
    if len(ph) and n_ent.min() > 0 and np.array_equal(ends[:-1], pal_off[1:]):  # contiguous: one read
        allent = r.arr(pal_off[0], PALETTE_ENTRY_DTYPE, int(n_ent.sum()), "palettes.entries")
        sub.palettes = np.split(allent, np.cumsum(n_ent)[:-1])
        totals = np.add.reduceat(allent["weight"].astype(np.int64), np.concatenate([[0], np.cumsum(n_ent)[:-1]]))
    else:
        sub.palettes = [r.arr(o, PALETTE_ENTRY_DTYPE, int(c), f"palette{i}.entries")
                        for i, (o, c) in enumerate(zip(pal_off, n_ent))]
        totals = np.array([int(e["weight"].astype(np.int64).sum()) for e in sub.palettes], np.int64)
    if np.any(totals != 100):
        i = int(np.argmax(totals != 100))
        raise r.err(f"palette{i}.weight", f"weight palette {i}: weights sum to {int(totals[i])} %, expected 100")
    rh = r.arr(sec["weight_refs"], REF_DTYPE, cnt["weight_refs"], "weight_refs")
    refs, refs_off = [], []
    for i, h in enumerate(rh):
        a = r.arr(int(h["offset"]), "<u4", int(h["count"]), f"weight_ref{i}.indices")
        if a.size and int(a.max()) >= len(sub.palettes):
            raise r.err(f"weight_ref{i}.indices", f"weight-reference list {i} names palette {int(a.max())} "
                                                  f"but there are {len(sub.palettes)}")
        refs.append(a)
        refs_off.append(int(h["offset"]))
    gh = r.arr(sec["groups"], GROUP_DTYPE, cnt["groups"], "groups")
    starts: set[int] = set()  # every mesh's chunk-stream offset: a stream ends where another begins
    for gi, g in enumerate(gh):
        for lk in r.arr(int(g["link_offset"]), LINK_DTYPE, int(g["link_count"]), f"group{gi}.links", claim=False):
            mh = r.arr(int(lk["offset"]), MESH_DTYPE, int(lk["count"]), f"group{gi}.meshes", claim=False)
            starts.update(int(x) for x in mh["mesh_offset"])
    n_link = n_refs = 0
    streams: dict = {}
    for gi, g in enumerate(gh):
        links = []
        lh = r.arr(int(g["link_offset"]), LINK_DTYPE, int(g["link_count"]), f"group{gi}.links")
        for li, lk in enumerate(lh):
            gw = f"group{gi}.link{li}"
            mh = r.arr(int(lk["offset"]), MESH_DTYPE, int(lk["count"]), f"{gw}.meshes")
            meshes = []
            for mi, m in enumerate(mh):
                mw = f"{gw}.mesh{mi}"
                mo = int(m["mesh_offset"])
                key = (mo, int(m["morph_offset"]), int(m["morph_size"]))
                if key not in streams:  # a stream named by several mesh headers is parsed once
                    chunks, after = _read_stream(r, mo, mw, starts)
                    morphs = []
                    if int(m["morph_offset"]) != _NONE and sub.morph_keys:
                        morphs, after = _read_morphs(r, mo + int(m["morph_offset"]), sub.morph_keys,
                                                     int(m["morph_size"]), mw)
                    streams[key] = (chunks, morphs, _read_end(r, after, mw))
                chunks, morphs, end = streams[key]
                n_refs += len(chunks)
                if n_refs > MAX_CHUNK_REFS:
                    raise r.err(f"{mw}.mesh_offset", f"{mw}: more than {MAX_CHUNK_REFS} chunk references "
                                                     f"(mesh headers naming the same streams over and over)")
                meshes.append(Mesh(chunks=chunks, morphs=morphs, end=end, header=m.copy(),
                                   offset=int(lk["offset"]) + MESH_DTYPE.itemsize * mi))
            if n_link >= len(refs):
                raise r.err(f"{gw}.weight_refs", f"{gw}: link {n_link} has no weight-reference list "
                                                 f"(the model has {len(refs)})")
            nslot = len(refs[n_link])
            cs = [(mi, ci, c) for mi, m in enumerate(meshes) for ci, c in enumerate(m.chunks)]
            if cs:
                allslots = np.concatenate([c.slots for _, _, c in cs])
                if allslots.size and (int(allslots.min()) < 0 or int(allslots.max()) >= nslot):
                    for mi, ci, c in cs:  # name the first chunk at fault
                        s = c.slots
                        if s.size and (int(s.min()) < 0 or int(s.max()) >= nslot):
                            raise r.err(f"{gw}.mesh{mi}.chunk{ci}.uv", f"{gw}.mesh{mi}.chunk{ci}: vertex weight "
                                        f"slot {int(s.max() if s.max() >= nslot else s.min())} is outside the "
                                        f"link's {nslot}-entry weight-reference list")
            links.append(Link(meshes=meshes, refs=refs[n_link], offset=int(g["link_offset"]) + 8 * li,
                              refs_offset=refs_off[n_link]))
            n_link += 1
        sub.groups.append(Group(type=int(g["type"]), material=int(g["material"]), unknown=int(g["unknown"]),
                                links=links, offset=sec["groups"] + GROUP_DTYPE.itemsize * gi))
    if n_link != len(refs):
        raise r.err("weight_refs", f"{len(refs)} weight-reference lists but {n_link} links (they pair 1:1)")
    sub._offsets = {"sections": sec, "palettes": pal_off}
    sub._shape = sub.shape()
    return sub, _gaps(r.claimed, size)


def _gaps(claimed: list, size: int) -> list:
    """Byte ranges ``(offset, size)`` of ``[0, size)`` not covered by ``claimed``."""
    out, p = [], 0
    for o, n in sorted(claimed):
        if o > p:
            out.append((p, o - p))
        p = max(p, o + n)
    if p < size:
        out.append((p, size - p))
    return out


def parse_mpf(data: bytes, path: str | os.PathLike[str] = "<bytes>") -> MpfFile:
    """Parse ``.mpf`` bytes (see the module docstring); FormatError names file, sub-model, field."""
    data = bytes(data)
    if len(data) < 12:
        raise FormatError(path, f"file of {len(data)} bytes is shorter than the 12-byte .mpf header", field="header")
    fmt = int(np.frombuffer(data, "<u4", 1, 0)[0])
    count, dir_off = (int(x) for x in np.frombuffer(data, "<i2", 2, 4))
    start = int(np.frombuffer(data, "<u4", 1, 8)[0])
    if data[:4] == b"xDFP":
        raise FormatError(path, "this .mpf is an interactive-music graph (xDFP), not a model", field="header.format_id")
    if fmt != FORMAT_TRICKY_PS2:
        raise FormatError(path, f"format id {fmt}: piste reads SSX Tricky PS2 models (format id 8; 3 = SSX 2000, "
                                f"13 = SSX 3, 14 = On Tour)", field="header.format_id")
    if count < 0 or count > 1024:
        raise FormatError(path, f"sub-model count {count} (expected 0-1024)", field="header.count")
    if dir_off < 12 or dir_off + 80 * count + 4 > len(data):
        raise FormatError(path, f"a directory of {count} entries at offset {dir_off} runs past the end of the "
                                f"{len(data)}-byte file", field="header.directory_offset")
    if start < dir_off + 80 * count + 4:
        raise FormatError(path, f"data start {start} lies inside the directory of {count} entries at offset {dir_off} "
                                f"(expected >= {dir_off + 80 * count + 4})", field="header.data_start")
    if start > len(data):
        raise FormatError(path, f"data start {start} is past the end of the {len(data)}-byte file",
                          field="header.data_start")
    entries = np.frombuffer(data, DIR_DTYPE, count, dir_off).copy()
    mpf = MpfFile(models=[], format_id=fmt, dir_tail=data[dir_off + 80 * count:dir_off + 80 * count + 4],
                  source=data, path=str(path))
    claimed = [(0, 12), (dir_off, 80 * count + 4)]
    buf = bytearray(data)
    for i, e in enumerate(entries):
        base, size = start + int(e["offset"]), int(e["size"])
        if base + size > len(data):
            raise FormatError(path, f"sub-model {i}: blob of {size} bytes at offset {base} runs past the end of "
                                    f"the {len(data)}-byte file", field=f"directory[{i}].offset")
        sub, gaps = _read_submodel(path, data, base, e, i, buf)
        mpf.models.append(sub)
        claimed.append((base, size))
        for o, n in gaps:
            if n < 16 and not any(data[base + o:base + o + n]):
                continue  # zero alignment padding
            mpf.unknown.append((f"{sub.name} blob", o, n, "bytes no structure claims (kept)"))
        if bytes(e["unused8"]) != bytes(8) or bytes(e["unused4"]) != bytes(4) or bytes(e["pad"]) != b"\0":
            mpf.unknown.append((f"directory[{i}]", dir_off + 80 * i + 0x34, 8, "non-zero unused directory bytes (kept)"))
        for j, c in enumerate(sub.palette_consts):
            if int(c) != PALETTE_CONST:
                mpf.unknown.append((f"{sub.name} palette{j}", 0, 4, f"header constant {int(c)} (not 36; kept)"))
    for o, n in _gaps(claimed, len(data)):
        mpf.unknown.append(("file", o, n, "bytes outside the header, directory and blobs (kept)"))
    if mpf.dir_tail != bytes(4):
        mpf.unknown.append(("directory tail", dir_off + 80 * count, 4, "non-zero bytes after the directory (kept)"))
    return mpf


def read_mpf(path: str | os.PathLike[str]) -> MpfFile:
    """Read an SSX Tricky ``.mpf`` model file."""
    return parse_mpf(read_regular(Path(path), MAX_FILE_BYTES, what="model file"), path)


def tag_differences(mpf: MpfFile) -> list:
    """Chunks whose stored bytes differ from what piste's layout writes for the same values (the
    VIF/DMA tags piste does not interpret: kept as read, regenerated only when a blob is laid out
    anew): ``(sub-model, chunks that differ, chunks, bytes that differ)`` per sub-model read from
    a file; empty for files piste wrote."""
    out = []
    for s in mpf.models:
        if s.source is None:
            continue
        n = nbytes = total = 0
        for g in s.groups:
            for m in (m for lk in g.links for m in lk.meshes):
                for ci, c in enumerate(m.chunks):
                    span = c.raw.get("span")
                    if span is None:
                        continue
                    total += 1
                    have = np.frombuffer(s.source, np.uint8, span[1] - span[0], span[0])
                    mine = np.frombuffer(_chunk_bytes(c, g.type, ci, len(m.chunks)), np.uint8)
                    if have.size != mine.size:
                        n += 1
                        nbytes += max(have.size, mine.size)
                    elif not np.array_equal(have, mine):
                        n += 1
                        nbytes += int(np.count_nonzero(have != mine))
        if n:
            out.append((s.name, n, total, nbytes))
    return out


def game_limits(mpf: MpfFile, *partners: MpfFile) -> list:
    """What would stop the game from taking the file, or what the retail models never do: a list
    of ``(sub-model, problem)`` (empty when none). Checked: render/morph chunks of more than 59
    vertices and shadow chunks of more than 165 (the retail maxima), links referencing more than
    25 palettes (the vector unit holds 25 blended matrices), weight palettes not in 25 % steps or
    with more than 3 entries (retail never has them; the loader itself accepts any integer
    percent), a LOD tier over the talk's triangle budget (the triangles of every non-shadow
    sub-model whose name ends ``3000`` / ``1500`` / ``750``, in ``mpf`` and its ``partners``, e.g.
    the head file of a body file, against ~3,000 / 1,500 / 750 with 10 % slack: the retail
    ``moby`` rider's tiers hold 3,076 / 1,486 / 714), names the engine's 15-character compare
    cannot tell apart, bone indices past a file's bone list."""
    out = []
    counts: dict[int, int] = {}
    for s in mpf.models:
        counts.setdefault(s.file_id, len(s.bones))
    seen: dict[str, Any] = {}
    for s in mpf.models:
        key = s.name[:15]
        if key in seen and seen[key] != s.name:
            out.append((s.name, f"the engine compares 15 characters: {s.name!r} and {seen[key]!r} look the same"))
        seen[key] = s.name
        for i, lk in enumerate(s.links):
            if len(lk.refs) > MAX_GROUP_MATRICES:
                out.append((s.name, f"link {i} references {len(lk.refs)} palettes (the game holds {MAX_GROUP_MATRICES})"))
            for m in lk.meshes:
                for c in m.chunks:
                    cap = MAX_SHADOW_CHUNK_VERTICES if c.shadow else MAX_CHUNK_VERTICES
                    if c.n_vertices > cap:
                        out.append((s.name, f"link {i}: a {'shadow ' if c.shadow else ''}chunk of {c.n_vertices} "
                                            f"vertices (retail {'shadow ' if c.shadow else ''}chunks hold at most {cap})"))
        for i, p in enumerate(s.palettes):
            w = np.asarray(p["weight"], np.int64)
            if np.any(w % 25) or len(p) > 3:
                out.append((s.name, f"palette {i} {w.tolist()} is not 1-3 weights in 25 % steps"))
            for e in p:
                f, b = int(e["file"]), int(e["bone"])
                if f in counts and b >= counts[f]:
                    out.append((s.name, f"palette {i} names bone {b} of file {f}, which has {counts[f]} bones"))
    tiers: dict = {}
    for s in [m for f in (mpf, *partners) for m in f.models]:
        tier = next((t for t in LOD_TRIANGLE_BUDGETS if s.name.endswith(t)), None)
        if tier is not None and "shdw" not in s.name.lower():
            tiers.setdefault(tier, []).append(s)
    for tier, subs in tiers.items():
        nt, budget = sum(s.n_triangles for s in subs), LOD_TRIANGLE_BUDGETS[tier]
        if nt > budget * 1.1:
            out.append((subs[0].name, f"LOD {tier} ({', '.join(s.name for s in subs)}): {nt:,} triangles, over "
                                      f"the talk's ~{budget:,}-triangle budget for that LOD"))
    return out


# ------------------------------------------------------------------------------------ writing
def _chunk_bytes(c: Chunk, gtype: int = GROUP_RENDER, i: int = 0, n: int = 1) -> bytes:
    """Chunk ``i`` of ``n`` in a mesh of a group of type ``gtype``, laid out by the retail rule
    (module docstring)."""
    v, s = c.n_vertices, len(c.strip_lengths)
    if v > 255:
        raise ValidationError(f"a chunk holds at most 255 vertices (VIF NUM), got {v}")
    table_q = 2 + s  # GIF tag, strip-table header, strips
    lo, hi = _dma(1 + table_q, _DMA_CNT)
    out = [_words(lo, hi, _NOP, _NOP, _NOP, _STCYCL_11, _NOP, _vif(_UNPACK_V4_32, table_q, _FLG))]
    prim, nreg, regs = _GIF_SHADOW if c.shadow else _GIF_RENDER
    gif_lo = v | (1 << 15) | (1 << 46) | (prim << 47) | (nreg << 60)
    out.append(np.array([gif_lo, regs], "<u8").tobytes())
    out.append(_words(s, int(c.table_words[0]), int(c.table_words[1]), v))
    st = np.zeros((s, 4), "<u4")
    st[:, 0] = c.strip_lengths
    out.append(st.tobytes())
    if c.uv is not None:
        data = [np.ascontiguousarray(c.uv, "<i2").tobytes(), np.ascontiguousarray(c.normals, "<i2").tobytes(),
                np.ascontiguousarray(c.positions, "<f4").tobytes()]
        tags: tuple[Any, ...] = _SECTION_TAGS
    else:
        both = np.zeros((v, 4), "<u4")
        both[:, :3] = np.ascontiguousarray(c.positions, "<f4").view("<u4")
        both[:, 3] = c.shadow_slots
        data, tags = [both.tobytes()], (_SHADOW_SECTION_TAG,)
    lo, hi = _dma(sum(3 + _align(len(d)) // 16 for d in data), _DMA_CNT)
    out.append(_words(lo, hi, _NOP, _NOP))
    for k, (d, (row, mask, cycle, cmd)) in enumerate(zip(data, tags)):
        out.append(_words(_NOP, _STROW, row[0], row[1], row[2], row[3], _STMASK, mask, _NOP, cycle, _NOP,
                          _vif(cmd, v, (table_q + k) | _FLG)))
        out.append(d + bytes(_align(len(d)) - len(d)))
    if gtype == GROUP_MORPH:
        lo, hi = _dma(1, _DMA_RET)
        out.append(_words(lo, hi, _NOP, _NOP, _NOP, _STCYCL_11, _NOP, _NOP))
    else:
        lo, hi = _dma(1, _DMA_CNT)
        if c.shadow:
            out.append(_words(lo, hi, _NOP, _NOP, _NOP, _STCYCL_11, _NOP, _MSCAL | 4))
        else:  # double-buffered: the 2nd of each pair (or a stream's odd last chunk) runs the rest
            x, y = (_MSCAL | 6, _MSCAL | 6) if i % 2 else ((_MSCAL | 8, _MSCAL | 6) if i == n - 1 else (_NOP, _NOP))
            out.append(_words(lo, hi, _NOP, _NOP, _STCYCL_11, _MSCAL | (int(c.program) & 0xFFFF), x, y))
    return b"".join(out)


def _morph_bytes(k: MorphKey) -> bytes:
    d = np.ascontiguousarray(k.deltas, "i1").reshape(-1, 3)
    num = d.shape[0]
    if num > 255:
        raise ValidationError(f"a morph key holds at most 255 vertices, got {num}")
    span = _align(3 * num)
    lo, hi = _dma(2 + span // 16, _DMA_RET)
    head = _words(lo, hi, _NOP, _NOP, _NOP, _STCYCL_44, _NOP, _vif(_UNPACK_V3_8 | _MASK, num, 0xB6 | _FLG))
    return head + d.tobytes() + bytes(span - 3 * num) + _words(_NOP, _FLUSHE, _NOP, _MSCAL | 2)


class _Buf:
    def __init__(self) -> None:
        self.b = bytearray()

    def at(self) -> int:
        return len(self.b)

    def pad(self, a: int = 16) -> None:
        self.b += bytes(_align(len(self.b), a) - len(self.b))

    def put(self, data: bytes) -> int:
        o = len(self.b)
        self.b += data
        return o


def _rebuild_blob(sub: SubModel) -> tuple:
    """Lay a sub-model out anew; returns ``(blob, sections (7,), counts (7,))``."""
    links = sub.links
    meshes = [m for lk in links for m in lk.meshes]
    b = _Buf()
    sec = dict.fromkeys(_SECTIONS, 0)
    sec["materials"] = b.put(np.ascontiguousarray(sub.materials, MATERIAL_DTYPE).tobytes())
    sec["bones"] = b.put(np.ascontiguousarray(sub.bones, BONE_DTYPE).tobytes())
    sec["ik"] = b.put(np.ascontiguousarray(sub.ik, IK_DTYPE).tobytes())
    sec["palettes"] = b.put(bytes(12 * len(sub.palettes)))
    pal_off = [b.put(np.ascontiguousarray(p, PALETTE_ENTRY_DTYPE).tobytes()) for p in sub.palettes]
    sec["weight_refs"] = b.put(bytes(8 * len(links)))
    ref_off = [b.put(np.ascontiguousarray(lk.refs, "<u4").tobytes()) for lk in links]
    sec["groups"] = b.put(bytes(20 * len(sub.groups)))
    link_at = b.put(bytes(8 * len(links)))
    mesh_at = b.put(bytes(12 * len(meshes)))
    b.pad()
    sec["mesh_data"] = b.at()
    mesh_hdr = np.zeros(len(meshes), MESH_DTYPE)
    i = 0
    for g in sub.groups:
        gm = [m for lk in g.links for m in lk.meshes]
        for j, m in enumerate(gm):
            if not m.chunks:
                raise ValidationError(f"{sub.name}: mesh {i} has no chunks")
            start = b.at()
            for ci, c in enumerate(m.chunks):
                b.put(_chunk_bytes(c, g.type, ci, len(m.chunks)))
            mesh_hdr[i] = (start, _NONE, _NONE)
            if m.morphs:
                if len(m.morphs) != sub.morph_keys:
                    raise ValidationError(f"{sub.name}: mesh {i} has {len(m.morphs)} morph keys, the sub-model "
                                          f"declares {sub.morph_keys}")
                packets = [_morph_bytes(k) for k in m.morphs]
                if len({len(p) for p in packets}) != 1:
                    raise ValidationError(f"{sub.name}: mesh {i}: morph keys must all have the same vertex count")
                mesh_hdr[i] = (start, b.at() - start, len(packets[0]))
                for p in packets:
                    b.put(p)
            last = j == len(gm) - 1
            if not (m.morphs and g.type == GROUP_MORPH) or last:  # retail: none between a group's morph meshes
                b.put(_END_A)
            if last:
                b.put(_END_B)
            i += 1
    b.pad()
    blob = b.b
    consts = sub.palette_consts if sub.palette_consts is not None and len(sub.palette_consts) == len(sub.palettes) \
        else np.full(len(sub.palettes), PALETTE_CONST, "<u4")
    ph = np.zeros(len(sub.palettes), PALHDR_DTYPE)
    for i, p in enumerate(sub.palettes):
        ph[i] = (len(p), pal_off[i], int(consts[i]))
    blob[sec["palettes"]:sec["palettes"] + ph.nbytes] = ph.tobytes()
    rh = np.zeros(len(links), REF_DTYPE)
    for i, lk in enumerate(links):
        rh[i] = (len(lk.refs), ref_off[i])
    blob[sec["weight_refs"]:sec["weight_refs"] + rh.nbytes] = rh.tobytes()
    blob[mesh_at:mesh_at + mesh_hdr.nbytes] = mesh_hdr.tobytes()
    lh = np.zeros(len(links), LINK_DTYPE)
    gh = np.zeros(len(sub.groups), GROUP_DTYPE)
    li = mi = 0
    for gi, g in enumerate(sub.groups):
        gh[gi] = (g.type, g.material, g.unknown, len(g.links), link_at + 8 * li)
        for lk in g.links:
            lh[li] = (mesh_at + 12 * mi, len(lk.meshes))
            li += 1
            mi += len(lk.meshes)
    blob[link_at:link_at + lh.nbytes] = lh.tobytes()
    blob[sec["groups"]:sec["groups"] + gh.nbytes] = gh.tobytes()
    counts = [len(sub.palettes), len(links), len(sub.groups), len(sub.bones), len(sub.materials), len(sub.ik),
              sub.morph_keys]
    return bytes(blob), [sec[k] for k in _SECTIONS], counts


def _patch_blob(sub: SubModel) -> bytes:
    """Write ``sub``'s values back into its source blob at the offsets they were read from."""
    assert sub.source is not None  # mpf_bytes patches only blobs read from a file
    b = bytearray(sub.source)
    sec = sub._offsets["sections"]

    def put(off: int, arr: np.ndarray) -> None:
        data = np.ascontiguousarray(arr).tobytes()
        b[off:off + len(data)] = data

    put(sec["bones"], np.asarray(sub.bones, BONE_DTYPE))
    put(sec["ik"], np.asarray(sub.ik, IK_DTYPE))
    put(sec["materials"], np.asarray(sub.materials, MATERIAL_DTYPE))
    for p, off in zip(sub.palettes, sub._offsets["palettes"]):
        put(off, np.asarray(p, PALETTE_ENTRY_DTYPE))
    if sub.palette_consts is not None:
        for i, c in enumerate(sub.palette_consts):
            put(sec["palettes"] + 12 * i + 8, np.array([c], "<u4"))
    for g in sub.groups:
        put(g.offset, np.array([g.type, g.material, g.unknown], "<u4"))
        for lk in g.links:
            put(lk.refs_offset, np.asarray(lk.refs, "<u4"))
            for m in lk.meshes:
                for c in m.chunks:
                    o = c.offset
                    put(o + 52, np.asarray(c.table_words, "<u4"))
                    put(o + 64, np.column_stack([np.asarray(c.strip_lengths, "<u4"),
                                                 np.asarray(c.raw["strip_tail"], "<u4").reshape(-1, 3)]))
                    p = o + 64 + 16 * len(c.strip_lengths) + 16 + 48  # strips, DMA CNT, section header
                    v = c.n_vertices
                    if c.uv is not None:
                        put(p, np.asarray(c.uv, "<i2"))
                        p = _align(p + 8 * v) + 48
                        put(p, np.asarray(c.normals, "<i2"))
                        p = _align(p + 6 * v) + 48
                        put(p, np.asarray(c.positions, "<f4"))
                    else:
                        both = np.zeros((v, 4), "<u4")
                        both[:, :3] = np.asarray(c.positions, "<f4").view("<u4")
                        both[:, 3] = c.shadow_slots
                        put(p, both)
                for k in m.morphs:
                    put(k.offset + 32, np.asarray(k.deltas, "i1"))
    return bytes(b)


def _check_values(sub: SubModel) -> None:
    for i, p in enumerate(sub.palettes):
        t = int(np.asarray(p["weight"], np.int64).sum())
        if t != 100:
            raise ValidationError(f"{sub.name}: weight palette {i} sums to {t} %, expected 100")
    for lk in sub.links:
        for m in lk.meshes:
            for c in m.chunks:
                if not np.all(np.isfinite(c.positions)):
                    raise ValidationError(f"{sub.name}: chunk positions contain NaN or infinity")


def mpf_bytes(mpf: MpfFile, notes: list | None = None) -> bytes:
    """The file's bytes: patched in place where the shape is unchanged, else laid out anew."""
    notes = [] if notes is None else notes
    blobs, entries = [], []
    for i, sub in enumerate(mpf.models):
        _check_values(sub)
        e = np.zeros((), DIR_DTYPE) if sub.entry is None else np.array(sub.entry, DIR_DTYPE)
        stored = bytes(e["name"]).split(b"\0", 1)[0].decode("ascii", "replace") if sub.entry is not None else None
        if stored != sub.name:  # renamed (or new): the name must be plain ASCII of <= 16 characters
            try:
                name = sub.name.encode("ascii")
            except UnicodeEncodeError:
                raise ValidationError(f"sub-model name {sub.name!r} is not plain ASCII") from None
            if len(name) > 16:
                raise ValidationError(f"sub-model name {sub.name!r} is longer than 16 characters")
            e["name"] = name
        if not -128 <= sub.file_id <= 127:
            raise ValidationError(f"{sub.name}: file id {sub.file_id} does not fit a signed byte")
        e["file_id"] = sub.file_id
        if sub.source is not None and sub._shape == sub.shape():
            blob = _patch_blob(sub)
            counts = list(e["counts"])
            counts[6] = sub.morph_keys
            e["counts"] = counts
        else:
            blob, secs, counts = _rebuild_blob(sub)
            e["sections"], e["counts"] = secs, counts
            if sub.source is not None:
                notes.append(f"{sub.name}: its counts changed, so the blob was laid out anew: tag bytes and "
                             f"bytes piste does not interpret were regenerated")
        e["size"] = len(blob)
        blobs.append(blob)
        entries.append(e)
    n = len(mpf.models)
    src = mpf.source
    if src is not None and len(mpf.models) == int(np.frombuffer(src, "<i2", 1, 4)[0]):
        dir_off = int(np.frombuffer(src, "<i2", 1, 6)[0])
        start = int(np.frombuffer(src, "<u4", 1, 8)[0])
        old = np.frombuffer(src, DIR_DTYPE, n, dir_off)
        if all(len(bl) == int(o["size"]) for bl, o in zip(blobs, old)):
            out = bytearray(src)
            out[0:4] = np.array([mpf.format_id], "<u4").tobytes()
            for i, (bl, e) in enumerate(zip(blobs, entries)):
                e["offset"] = old[i]["offset"]
                out[dir_off + 80 * i:dir_off + 80 * (i + 1)] = np.array(e, DIR_DTYPE).tobytes()
                o = start + int(old[i]["offset"])
                out[o:o + len(bl)] = bl
            out[dir_off + 80 * n:dir_off + 80 * n + 4] = mpf.dir_tail
            return bytes(out)
        notes.append("a blob changed size: the file was laid out anew (bytes outside the blobs were dropped: "
                     + ", ".join(f"{w}@{o}+{s}" for w, o, s, _ in mpf.unknown if w == "file") + ")")
    start = 12 + 80 * n + 4
    buf = _Buf()
    buf.put(np.array([mpf.format_id], "<u4").tobytes() + np.array([n, 12], "<i2").tobytes()
            + np.array([start], "<u4").tobytes())
    dir_at = buf.put(bytes(80 * n))
    buf.put(bytes(mpf.dir_tail))
    for i, bl in enumerate(blobs):
        buf.pad()
        entries[i]["offset"] = buf.at() - start
        buf.put(bl)
    for i, e in enumerate(entries):
        buf.b[dir_at + 80 * i:dir_at + 80 * (i + 1)] = np.array(e, DIR_DTYPE).tobytes()
    return bytes(buf.b)


def write_mpf(mpf: MpfFile, path: str | os.PathLike[str]) -> list:
    """Write ``mpf`` atomically; returns notes on what had to be laid out anew (empty when every
    blob was patched in place)."""
    notes: list = []
    write_bytes_atomic(path, mpf_bytes(mpf, notes))
    return notes
