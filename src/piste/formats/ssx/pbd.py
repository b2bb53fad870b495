"""SSX Tricky ``.pbd`` level files: the patch section read, edited and written back.

Facts from ``/work/shared/SSX-FORMATS.md`` (public community documentation; no code copied):

* little-endian; a 136-byte header: bytes 0-2 the version ``00 15 1B``, byte 3 the platform
  (0 generic, 1 PS2, 2 Xbox, 3 GameCube), 15 u32 counts (:data:`COUNT_NAMES`), 18 u32 absolute
  offsets (:data:`OFFSET_NAMES`);
* ``count`` contiguous 448-byte patch records from the patch offset (:data:`PATCH_DTYPE`);
* a patch's surface is stored as power-basis coefficients ``C = M P Mᵀ`` (``M`` below, rows =
  powers of the parameter, ``P[i][j]`` with ``i`` along ``u``) in *reversed* order: the file holds
  ``C[3][3], C[3][2], ..., C[0][0]``; world units are centimetres.

Light records (92 bytes, :data:`LIGHT_DTYPE`; SSX-Library ``PBDHandler.cs`` ``struct Light`` and
OpenSlope ``Trailmap/specs/220-level-pbd.md`` "Light record", facts only) are decoded on request
(:meth:`Pbd.read_lights`), with the light name hashes of the hash section
(:meth:`Pbd.light_hashes`: a 52-byte header of 13 u32 - total length, then (count, offset relative
to the section) for five lists: unknown, instances, unknown, lights, unknown, cameras in that
order, ``HASH_HEADER_FIELDS`` - then (u32 hash, u32 object index) pairs; the Multitool writes each
list sorted by hash).

Only the patch records are interpreted; every other byte of the file (the header's other fields
and the sections piste does not interpret: instances, lights, splines, models, ...) is kept as it
was read, so an unedited :class:`Pbd` is written back byte for byte.  Patches whose control points
were edited get their power basis, bounding box and corners recomputed; patches left alone keep
their stored floats (which a float64 -> float32 re-encode would not always reproduce).

The patch count of a file read from disk cannot change: the sections after the patches hold
absolute pointers piste does not interpret.  To make a level with other patches use
:func:`piste.pipeline.ssx_synth.make_level`, which lays the whole file out itself.  The patches as a
:class:`~piste.terrain.net.PatchNet` are :func:`piste.pipeline.ssx_level.pbd_to_net` (this module
reads and writes arrays; it imports no terrain code).

API
---
::

    read_pbd(path) -> Pbd / parse_pbd(data, path) -> Pbd
    Pbd.read_lights() -> (k,) LIGHT_DTYPE; Pbd.light_hashes() -> (k,) int64 or None;
    Pbd.hash_list(kind, k) -> (k,) int64
    hash_section_bytes(light_hashes) -> bytes   a hash section holding only a light list
    write_pbd(pbd, path)                 atomic
    bezier_to_power(cp) / power_to_bezier(c)   (n, 4, 4, 3) <-> (n, 16, 3) stored order
    records_from_net(net, ...)           PatchNet (metres) -> (n,) PATCH_DTYPE records (centimetres)
"""

from __future__ import annotations

import os
import struct
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import numpy.typing as npt

from piste.errors import FormatError, ValidationError
from piste.formats.atomic import write_bytes_atomic
from piste.formats.safe_io import read_regular

#: the largest file the reader accepts (bytes)
MAX_FILE_BYTES = 512 << 20  # a big retail level is a few tens of MB

__all__ = [
    "Pbd", "read_pbd", "parse_pbd", "write_pbd", "PATCH_DTYPE", "PATCH_SIZE", "HEADER_SIZE", "VERSION",
    "PLATFORMS", "COUNT_NAMES", "OFFSET_NAMES", "bezier_to_power", "power_to_bezier", "records_from_arrays",
    "records_from_net", "default_lightmap_tiles", "UV_TO_NET", "NET_TO_UV", "GAME_SCALE", "PAGE_TILES",
    "LIGHT_DTYPE", "LIGHT_SIZE", "HASH_HEADER_FIELDS", "hash_section_bytes", "weld_candidates",
]

VERSION = b"\x00\x15\x1b"
PLATFORMS = {0: "generic", 1: "ps2", 2: "xbox", 3: "gamecube"}
HEADER_SIZE = 136
PATCH_SIZE = 448
#: metres per game unit (the game works in centimetres)
GAME_SCALE = 0.01
#: light-map tiles per page side (a 128 x 128 page of 8 x 8 tiles)
PAGE_TILES = 16
COUNT_NAMES = (
    "player_starts", "patches", "instances", "particle_instances", "materials", "material_blocks", "lights",
    "splines", "spline_segments", "flipbooks", "models", "particle_models", "textures", "cameras",
    "lightmap_size",
)
OFFSET_NAMES = (
    "player_starts", "patches", "instances", "particle_instances", "materials", "material_blocks", "lights",
    "splines", "spline_segments", "flipbooks", "model_pointers", "models", "particle_model_pointers",
    "particle_models", "camera_pointers", "cameras", "hash", "mesh_data",
)

#: one 448-byte patch record
PATCH_DTYPE = np.dtype(
    [
        ("lightmap_rect", "<f4", (4,)),  # 0x000 x, y, w, h within the 128x128 page (0..1)
        ("uv", "<f4", (4, 4)),  # 0x010 corner UVs (x, y used; z = w = 1)
        ("power", "<f4", (16, 4)),  # 0x050 power basis, reversed; w = 1
        ("aabb_min", "<f4", (3,)),  # 0x150
        ("aabb_max", "<f4", (3,)),  # 0x15C
        ("corners", "<f4", (4, 4)),  # 0x168 cp0, cp12, cp3, cp15 (w = 1)
        ("surface_type", "<u4"),  # 0x1A8
        ("kind_tags", "<u2"),  # 0x1AC resource-kind tags (retail 0x29)
        ("visibility", "<i2"),  # 0x1AE negative = trick-only
        ("texture", "<i2"),  # 0x1B0 index into <NAME>.ssh
        ("lightmap_page", "<i2"),  # 0x1B2 index into <NAME>_L.ssh
        ("unused_ids", "<i2", (2,)),  # 0x1B4 both -1
        ("residue", "<u4", (2,)),  # 0x1B8 compiler residue
    ]
)
assert PATCH_DTYPE.itemsize == PATCH_SIZE
#: one 92-byte light record (SSX-Library PBDHandler.cs struct Light; OpenSlope 220-level-pbd.md)
LIGHT_DTYPE = np.dtype(
    [
        ("type", "<u4"),  # 0x00 0 directional (sun), 1 point, 2 decorative flare, 3 ambient
        ("sprite_res", "<u4"),  # 0x04 glow-sprite resolution, 0 = none
        ("unknown_float1", "<f4"),  # 0x08
        ("unknown_int1", "<u4"),  # 0x0C
        ("colour", "<f4", (3,)),  # 0x10 RGB
        ("direction", "<f4", (3,)),  # 0x1C
        ("position", "<f4", (3,)),  # 0x28 game units
        ("lowest", "<f4", (3,)),  # 0x34 influence box min
        ("highest", "<f4", (3,)),  # 0x40 influence box max
        ("unknown_float2", "<f4"),  # 0x4C
        ("unknown_int2", "<u4"),  # 0x50
        ("unknown_float3", "<f4"),  # 0x54
        ("unknown_int3", "<u4"),  # 0x58
    ]
)
LIGHT_SIZE = 92
assert LIGHT_DTYPE.itemsize == LIGHT_SIZE
#: the hash section's 13-u32 header, in file order
HASH_HEADER_FIELDS = ("total_length", "count_u1", "offset_u1", "count_instances", "offset_instances", "count_u2",
                      "offset_u2", "count_lights", "offset_lights", "count_u4", "offset_u4", "count_cameras",
                      "offset_cameras")
_HEADER_DTYPE = np.dtype([("version", "u1", (3,)), ("platform", "u1"), ("counts", "<u4", (15,)), ("offsets", "<u4", (18,))])
assert _HEADER_DTYPE.itemsize == HEADER_SIZE

#: the Bézier -> power basis matrix (rows = powers 0..3 of the parameter)
M = np.array([[1.0, 0.0, 0.0, 0.0], [-3.0, 3.0, 0.0, 0.0], [3.0, -6.0, 3.0, 0.0], [-1.0, 3.0, -3.0, 1.0]])
M_INV = np.linalg.inv(M)
#: control-point indices (i, j) of the stored corners cp0, cp12, cp3, cp15
CORNER_IJ = np.array([(0, 0), (3, 0), (0, 3), (3, 3)])
#: SSX corner UV order (u0,v0), (u1,v0), (u0,v1), (u1,v1) -> PatchNet's c0..c3 (0,0), (1,0), (1,1), (0,1)
UV_TO_NET = np.array([0, 1, 3, 2])
NET_TO_UV = np.array([0, 1, 3, 2])


# ----------------------------------------------------------------------------- the basis
def power_to_bezier(stored: npt.ArrayLike) -> np.ndarray:
    """Bézier control points from stored (reversed) power-basis coefficients, in float64.

    Parameters
    ----------
    stored : (n, 16, 3) coefficients as the file holds them (``C[3][3]`` first, ``C[0][0]`` last)

    Returns
    -------
    (n, 4, 4, 3) float64 ``P = M⁻¹ C M⁻ᵀ``.
    """
    c = np.asarray(stored, dtype=np.float64)[:, ::-1].reshape(-1, 4, 4, 3).transpose(0, 3, 1, 2)  # (n, 3, 4, 4)
    return np.ascontiguousarray((M_INV @ c @ M_INV.T).transpose(0, 2, 3, 1))


def bezier_to_power(cp: npt.ArrayLike) -> np.ndarray:
    """Stored (reversed) power-basis coefficients of Bézier patches.

    Parameters
    ----------
    cp : (n, 4, 4, 3) control points

    Returns
    -------
    (n, 16, 3) float64, ``C[3][3]`` first (round to float32 to store).
    """
    p = np.asarray(cp, dtype=np.float64).transpose(0, 3, 1, 2)  # (n, 3, 4, 4)
    c = (M @ p @ M.T).transpose(0, 2, 3, 1)
    return c.reshape(-1, 16, 3)[:, ::-1]


def default_lightmap_tiles(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The game's packing of ``n`` patches into light-map pages: patch ``k`` on page ``k // 256``,
    tile column ``k % 16``, row ``(k // 16) % 16``.  Returns ``(rect (n, 4) float32 (x, y, w, h),
    page (n,) int16)``."""
    k = np.arange(n)
    t = k % (PAGE_TILES * PAGE_TILES)
    w = np.float32(1.0 / PAGE_TILES)
    rect = np.stack([(t % PAGE_TILES) * w, (t // PAGE_TILES) * w, np.full(n, w), np.full(n, w)], axis=1)
    return rect.astype(np.float32), (k // (PAGE_TILES * PAGE_TILES)).astype(np.int16)


def _geometry_fields(rec: np.ndarray, cp: np.ndarray) -> None:
    """Fill ``power``, ``aabb_*`` and ``corners`` of records ``rec`` from control points ``cp``
    (game units, (k, 4, 4, 3))."""
    k = len(cp)
    power = np.ones((k, 16, 4), np.float32)
    power[:, :, :3] = bezier_to_power(cp)
    rec["power"] = power
    pts = cp.reshape(k, 16, 3)
    rec["aabb_min"] = pts.min(axis=1)
    rec["aabb_max"] = pts.max(axis=1)
    corners = np.ones((k, 4, 4), np.float32)
    corners[:, :, :3] = cp[:, CORNER_IJ[:, 0], CORNER_IJ[:, 1]]
    rec["corners"] = corners


def records_from_arrays(control_points: npt.ArrayLike, uv: npt.ArrayLike | None = None, lightmap_rect: npt.ArrayLike | None = None,
                        lightmap_page: npt.ArrayLike | None = None, texture_index: npt.ArrayLike | None = None,
                        surface_type: npt.ArrayLike | None = None, trick_only: npt.ArrayLike | None = None) -> np.ndarray:
    """New patch records (game units) from per-patch arrays.

    Parameters
    ----------
    control_points : (n, 4, 4, 3) Bézier points in game units (centimetres)
    uv : (n, 4, 2) SSX corner order (u0,v0), (u1,v0), (u0,v1), (u1,v1); default 0..1
    lightmap_rect, lightmap_page : (n, 4) (x, y, w, h) and (n,); default :func:`default_lightmap_tiles`
    texture_index, surface_type : (n,); default 0 and 1 (snow)
    trick_only : (n,) bool; default False

    Returns
    -------
    (n,) :data:`PATCH_DTYPE`
    """
    cp = np.asarray(control_points, dtype=np.float64)
    if cp.ndim != 4 or cp.shape[1:] != (4, 4, 3):
        raise ValidationError(f"control_points must have shape (n, 4, 4, 3), got {cp.shape}")
    n = len(cp)
    bad = ~np.isfinite(cp).reshape(n, 48).all(axis=1)
    if bad.any():
        raise ValidationError(f"patch {int(np.argmax(bad))}: control points must be finite")
    rec = np.zeros(n, PATCH_DTYPE)
    _geometry_fields(rec, cp)
    lm_rect, lm_page = default_lightmap_tiles(n)
    rec["lightmap_rect"] = lm_rect if lightmap_rect is None else lightmap_rect
    rec["lightmap_page"] = lm_page if lightmap_page is None else lightmap_page
    uvs = np.ones((n, 4, 4), np.float32)
    uvs[:, :, :2] = np.array([(0, 0), (1, 0), (0, 1), (1, 1)], np.float32) if uv is None else uv
    rec["uv"] = uvs
    rec["texture"] = 0 if texture_index is None else texture_index
    rec["surface_type"] = 1 if surface_type is None else surface_type
    rec["kind_tags"] = 0x29
    rec["visibility"] = 0 if trick_only is None else np.where(np.asarray(trick_only, bool), -1, 0)
    rec["unused_ids"] = -1
    return rec


def records_from_net(net: Any, scale: float = GAME_SCALE, **fields: Any) -> np.ndarray:  # net: a terrain PatchNet
    """Patch records from a :class:`~piste.terrain.net.PatchNet` in metres (``scale`` metres a
    game unit).  The net's corner UVs become the patch UVs (reordered to the SSX corner order);
    light-map tiles, textures and the rest come from ``fields`` (see :func:`records_from_arrays`)."""
    uv = np.asarray(net.uv, dtype=np.float32)[:, NET_TO_UV]
    fields.setdefault("uv", uv)
    return records_from_arrays(np.asarray(net.control_points) / scale, **fields)


# ----------------------------------------------------------------------------- the file
class Pbd:
    """A ``.pbd`` level: its patches decoded, everything else kept as bytes.

    Per-patch arrays (edit them in place or assign new arrays of the same shape)
    ----------------------------------------------------------------------------
    control_points : (n, 4, 4, 3) float64 Bézier points, game units (cm), decoded in float64
    uv : (n, 4, 2) float32 texture UVs of corners (u0,v0), (u1,v0), (u0,v1), (u1,v1)
    lightmap_rect : (n, 4) float32 (x, y, w, h) of the tile within its 128x128 page, 0..1
    lightmap_page : (n,) int16 page index into ``<NAME>_L.ssh``
    texture_index : (n,) int16 texture index into ``<NAME>.ssh``
    surface_type : (n,) uint32 (1 snow, 2 off-track, 3 powder, 5 ice, 9 rock, ...)
    trick_only : (n,) bool (stored as a negative visibility)

    Other attributes
    ----------------
    version : bytes (3), platform : int, counts : dict (:data:`COUNT_NAMES`), offsets : dict
    (:data:`OFFSET_NAMES`), records : (n,) :data:`PATCH_DTYPE` as read, raw : the file's bytes.
    """

    def __init__(self, raw: bytes, records: np.ndarray, path: str | os.PathLike[str] | None = None) -> None:
        self.raw = bytes(raw)
        self.path = path
        head = np.frombuffer(self.raw[:HEADER_SIZE], _HEADER_DTYPE)[0]
        self.version = bytes(head["version"])
        self.platform = int(head["platform"])
        self.counts = {k: int(v) for k, v in zip(COUNT_NAMES, head["counts"])}
        self.offsets = {k: int(v) for k, v in zip(OFFSET_NAMES, head["offsets"])}
        self.records = records
        self.control_points = power_to_bezier(records["power"][:, :, :3])
        self._cp_read = self.control_points.copy()
        self.uv = records["uv"][:, :, :2].copy()
        self.lightmap_rect = records["lightmap_rect"].copy()
        self.lightmap_page = records["lightmap_page"].copy()
        self.texture_index = records["texture"].copy()
        self.surface_type = records["surface_type"].copy()
        self.trick_only = records["visibility"] < 0

    # ------------------------------------------------------------------ views
    @property
    def n_patches(self) -> int:
        return len(self.records)

    def __len__(self) -> int:
        return len(self.records)

    @property
    def patch_offset(self) -> int:
        return self.offsets["patches"]

    @property
    def sections(self) -> dict:
        """Every section by name as bytes, from its offset to the next larger offset (or the end)."""
        ends = sorted(set(self.offsets.values()) | {len(self.raw)})
        out = {}
        for name, off in self.offsets.items():
            nxt = next((e for e in ends if e > off), off)
            out[name] = self.raw[off:nxt] if off else b""
        return out

    def read_lights(self) -> np.ndarray:
        """The light records, ``(counts["lights"],)`` :data:`LIGHT_DTYPE` (FormatError when the
        section runs past the end of the file)."""
        k, off = self.counts["lights"], self.offsets["lights"]
        if k and (off < HEADER_SIZE or off + k * LIGHT_SIZE > len(self.raw)):
            raise FormatError(self.path, f"{k} lights of {LIGHT_SIZE} bytes from offset {off} need "
                                         f"{off + k * LIGHT_SIZE} bytes, the file has {len(self.raw)}",
                              field="counts.lights")
        return np.frombuffer(self.raw, LIGHT_DTYPE, count=k, offset=off if k else 0).copy()

    def hash_header(self) -> dict | None:
        """The hash section's header (:data:`HASH_HEADER_FIELDS`), or None without a hash section
        (offset 0, or fewer than its 52 bytes before the next section)."""
        off = self._hash_span()[0]
        if off is None:
            return None
        return dict(zip(HASH_HEADER_FIELDS, struct.unpack_from(f"<{len(HASH_HEADER_FIELDS)}I", self.raw, off)))

    def _hash_span(self) -> tuple:
        """``(start, end)`` of the hash section (it ends where the mesh data starts, or at the end
        of the file), ``(None, None)`` when it is absent or shorter than its header."""
        off, mesh = self.offsets["hash"], self.offsets["mesh_data"]
        end = mesh if mesh >= off else len(self.raw)
        if not off or end - off < 4 * len(HASH_HEADER_FIELDS):
            return None, None
        return off, end

    def light_hashes(self) -> np.ndarray | None:
        """Each light's name hash from the hash section's light list, ``(counts["lights"],)`` int64
        (signed 32-bit values, as the Multitool's JSON holds them; 0 for a light the list does not
        name, as the Multitool leaves it), or None without a hash section."""
        if self.hash_header() is None:
            return None
        return self.hash_list("lights", self.counts["lights"])

    def hash_list(self, kind: str, k: int) -> np.ndarray:
        """Each of ``k`` records' hash from the hash section's ``kind`` list (``"lights"`` or
        ``"instances"``: ``(hash, index)`` pairs of signed 32-bit values; the first pair naming a record
        wins; 0 for a record no pair names, as the Multitool leaves it), ``(k,)`` int64; all 0 without a
        hash section.  FormatError (``hash.count_<kind>``) when the list runs past the section."""
        out = np.zeros(k, np.int64)
        h = self.hash_header()
        if h is None:
            return out
        start, end = self._hash_span()
        off, n = start + h[f"offset_{kind}"], h[f"count_{kind}"]
        if off + 8 * n > end:
            raise FormatError(self.path, f"the hash section's {n} {kind[:-1]} hashes from offset {off} run past the "
                                         f"end of the section ({end})", field=f"hash.count_{kind}")
        pairs = np.frombuffer(self.raw, "<i4", count=2 * n, offset=off).reshape(n, 2).astype(np.int64)
        ok = (pairs[:, 1] >= 0) & (pairs[:, 1] < k)
        out[pairs[ok, 1][::-1]] = pairs[ok, 0][::-1]  # the first pair naming a record wins
        return out

    # ------------------------------------------------------------------ encoding
    def edited(self) -> np.ndarray:
        """Patches whose control points differ from what was read, ``(n,)`` bool."""
        cp = np.asarray(self.control_points, dtype=np.float64)
        if cp.shape != self._cp_read.shape:
            raise ValidationError(f"{self._name()}: control_points has shape {cp.shape}, the file "
                                  f"{self._cp_read.shape}: the patch count of a file read from disk cannot change")
        return (cp != self._cp_read).reshape(len(cp), -1).any(axis=1)

    def to_records(self) -> np.ndarray:
        """The patch records to write: read records with every per-patch array applied; edited
        patches get their power basis, AABB and corners recomputed.  ``(n,)`` :data:`PATCH_DTYPE`."""
        n = len(self.records)
        for name, shape in (("uv", (n, 4, 2)), ("lightmap_rect", (n, 4)), ("lightmap_page", (n,)),
                            ("texture_index", (n,)), ("surface_type", (n,)), ("trick_only", (n,))):
            a = np.asarray(getattr(self, name))
            if a.shape != shape:
                raise ValidationError(f"{self._name()}: {name} must have shape {shape}, got {a.shape}")
        edited = self.edited()
        rec = self.records.copy()
        if edited.any():
            cp = np.asarray(self.control_points, dtype=np.float64)[edited]
            bad = ~np.isfinite(cp).reshape(len(cp), -1).all(axis=1)
            if bad.any():
                p = int(np.nonzero(edited)[0][np.argmax(bad)])
                raise ValidationError(f"{self._name()}: patch {p}: control points must be finite")
            sub = rec[edited]
            _geometry_fields(sub, cp)
            rec[edited] = sub
        rec["uv"][:, :, :2] = self.uv
        rec["lightmap_rect"] = self.lightmap_rect
        rec["lightmap_page"] = self.lightmap_page
        rec["texture"] = self.texture_index
        rec["surface_type"] = self.surface_type
        trick = np.asarray(self.trick_only, dtype=bool)
        vis = rec["visibility"]
        rec["visibility"] = np.where(trick == (vis < 0), vis, np.where(trick, -1, 0))
        return rec

    def to_bytes(self) -> bytes:
        """The file's bytes: the raw file with the patch records re-encoded."""
        po = self.patch_offset
        rec = self.to_records()
        return self.raw[:po] + rec.tobytes() + self.raw[po + rec.nbytes:]

    def _name(self) -> str:
        return self.display_name

    @property
    def display_name(self) -> str:
        """The file's name (``"pbd"`` for bytes without a path): errors and the net's name use it."""
        return Path(self.path).name if self.path is not None else "pbd"


def hash_section_bytes(light_hashes: npt.ArrayLike) -> bytes:
    """A hash section (the Multitool's layout, ``PBDHandler.cs`` ``SaveNew``) whose only list is
    the lights': ``(hash, index)`` for each entry of ``light_hashes (k,)`` (signed 32-bit), sorted
    by hash (signed, as the Multitool sorts); the other lists empty."""
    h = np.asarray(light_hashes, np.int64).reshape(-1)
    k = len(h)
    head = 4 * len(HASH_HEADER_FIELDS)
    order = np.argsort(h, kind="stable")
    pairs = np.stack([h[order], order], axis=1).astype("<i4")
    end = head + 8 * k
    fields = (end, 0, head, 0, head, 0, head, k, head, 0, end, 0, end)
    return struct.pack(f"<{len(fields)}I", *fields) + pairs.tobytes()


def weld_candidates(cp: npt.ArrayLike) -> list[float]:
    """Weld tolerances (game units) to try, smallest first: of 1, 4 and 16 units, those from the
    smallest that pairs up as many patch corners as 16 units does."""
    from scipy.spatial import cKDTree

    steps = [1.0, 4.0, 16.0]
    corners = np.asarray(cp)[:, CORNER_IJ[:, 0], CORNER_IJ[:, 1]].reshape(-1, 3)
    if len(corners) < 2:
        return steps
    pairs = cKDTree(corners).query_pairs(steps[-1], output_type="ndarray")
    dist = np.linalg.norm(corners[pairs[:, 0]] - corners[pairs[:, 1]], axis=1)
    counts = [int((dist <= t).sum()) for t in steps]
    first = next(i for i, c in enumerate(counts) if c == counts[-1])
    return steps[first:]


def _fail(path: str | os.PathLike[str] | None, msg: str, field: str | None = None) -> NoReturn:
    raise FormatError(path, msg, field=field)


def parse_pbd(data: bytes, path: str | os.PathLike[str] | None = None) -> Pbd:
    """Parse the bytes of a ``.pbd`` (see :func:`read_pbd`)."""
    data = bytes(data)
    if len(data) < HEADER_SIZE:
        _fail(path, f"truncated: {len(data)} bytes, a .pbd header alone is {HEADER_SIZE}", "header")
    head = np.frombuffer(data[:HEADER_SIZE], _HEADER_DTYPE)[0]
    if bytes(head["version"]) != VERSION:
        _fail(path, f"expected version bytes 00 15 1b (SSX Tricky), got {bytes(head['version']).hex(' ')}", "version")
    plat = int(head["platform"])
    if plat not in PLATFORMS:
        _fail(path, f"expected platform byte 0-3 ({', '.join(f'{k} {v}' for k, v in PLATFORMS.items())}), got {plat}",
              "platform")
    size = len(data)
    n = int(head["counts"][1])
    po = int(head["offsets"][1])
    if n and po < HEADER_SIZE:
        _fail(path, f"patch offset {po} lies inside the header", "offsets.patches")
    if po + n * PATCH_SIZE > size:
        _fail(path, f"{n} patches of {PATCH_SIZE} bytes from offset {po} need {po + n * PATCH_SIZE} bytes, "
                    f"the file has {size} (truncated, or a wrong count)", "counts.patches")
    size = len(data)
    for name, off in zip(OFFSET_NAMES, head["offsets"]):
        if int(off) > size:
            _fail(path, f"offset {int(off)} lies past the end of the file ({size} bytes)", f"offsets.{name}")
    rec = np.frombuffer(data, PATCH_DTYPE, count=n, offset=po).copy()
    coef = rec["power"][:, :, :3].reshape(n, 48)
    bad = ~np.isfinite(coef)
    if bad.any():
        p, k = (int(x) for x in np.argwhere(bad)[0])
        _fail(path, f"patch {p}: power-basis coefficient {k // 3} ({'xyz'[k % 3]}) is {coef[p, k]}: expected a "
                    "finite number", "patches.power")
    for fld in ("lightmap_rect", "uv"):
        vals = rec[fld].reshape(n, int(np.prod(PATCH_DTYPE[fld].shape)))  # (n, k): also for n = 0
        bad = ~np.isfinite(vals)
        if bad.any():
            p = int(np.argwhere(bad)[0][0])
            _fail(path, f"patch {p}: {fld} holds a non-finite value", f"patches.{fld}")
    return Pbd(data, rec, path)


def read_pbd(path: str | os.PathLike[str]) -> Pbd:
    """Read an SSX Tricky ``.pbd`` level.

    Raises :class:`~piste.errors.FormatError` naming the file, the record (``patch 1234``) and the
    field for a truncated file, a wrong version or platform byte, counts or offsets past the end,
    or non-finite coefficients.
    """
    path = Path(path)
    data = read_regular(path, MAX_FILE_BYTES, what="level file")  # regular files only, size-capped
    return parse_pbd(data, path)


def write_pbd(pbd: Pbd, path: str | os.PathLike[str]) -> None:
    """Write ``pbd`` to ``path`` atomically (an unedited level gives the bytes it was read from)."""
    write_bytes_atomic(path, pbd.to_bytes())
