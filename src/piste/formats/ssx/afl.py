"""SSX Tricky (PS2) rider animation banks, ``.afl``: read, write back byte for byte, and play the
clips on an ``.mpf`` rider as piste :class:`~piste.character.Clip` objects.

Facts (public; read for facts only, no code copied): OpenSlope's Apache-2.0 offline tool
``Trailmap/tools/analysis/afl_pose.py`` (the curve format "recovered from the PAL ELF") and its
notes ``Trailmap/tools/README.md`` / ``Trailmap/research/rider-telemetry.md`` (a 60-channel body
pose: root translation + 57 local Euler channels of a 19-bone body; "negate local XYZ, then compose
Rz·Ry·Rx, matching the MPF/glTF path and recovered AFL poses"), and the notes
``notes/animation-format.md`` of the public repository ``ed-slopper/SSX-TRICKY-RUST-REWRITE`` (no
licence file: facts only), whose author decoded 1,519 clips of 446 retail files (header bytes 76,
17; track kind 1 = the board; event frames in the clip record; 30 fps "looks right"). SSX-Library
and SSX-Research hold nothing on ``.afl``. No retail ``.afl`` is public: every byte layout below is
checked only against files written from these facts (by hand in the tests, and by the encoder).

Layout (little-endian)
----------------------
* Header, 12 bytes: u8 console, u8 unknown (retail: 76, 17), u16 header count, u32 curve-pointer
  table offset, u32 curve data offset (both absolute).
* Header table at 12: ``count`` records of 36 bytes (:data:`HEADER_DTYPE`): u32 key, u32 index of
  the first curve pointer, u8 kind, u8 related-record count, 11 u16 fields, u32 tail.
  A **named clip** is a record of kind 255 whose key is the engine's string hash of the clip name
  (:func:`afl_hash`) and whose first field is its frame count (the other ten: event frames, 65535 =
  none; not interpreted); the ``related`` records right after it are its **tracks**. A track record of kind ``k`` uses :data:`TRACK_CHANNELS` ``[k]``
  consecutive curve pointers from its pointer index, one curve a channel.
* Track kind 0 is the **body**: 60 channels, the root translation (3, cm, the ``.mpf``'s axes) then
  3 Euler angles (radians) for each of the body's 19 bones in ``.mpf`` bone order. The angles are
  the bone's whole local rotation (not an offset from the bind pose), composed
  ``Rz(-z)·Ry(-y)·Rx(-x)`` (signs negated, the ``.mpf`` bind convention); a root (parentless) bone
  sits at the root translation, the others keep their bind translation. Track kind 1 is the
  **board**: its position (3, cm) and Euler triple (3, same convention) in the same space (the
  board at the origin along +Y, +X toe side, +Z up). Kinds 4-15 (3 to 23 channels) are cut-scene
  tracks (faces, props, cameras).
* Curve pointers: u32 each, relative to the curve data offset.
* A curve starts with a u16 descriptor, kind = low 4 bits, count = high 12 bits:
  kind 0 a constant (one packed float; 5 bytes); kinds 1-3 a polynomial of that degree in the
  frame number, ``kind + 1`` packed coefficients, highest power first (``2 + 3 (kind + 1)``
  bytes); kind 4 ``count`` f32 samples; kind 6 a packed base, a packed scale and ``count`` u8
  samples; kind 7 the same with u16 samples (value = base + scale x sample); kind 5 a group of
  ``count`` segments (each any kind but 5) laid end to end, each segment's count being its
  duration in frames: consecutive segments share their boundary frame (segment ``k`` covers local
  frames ``0 .. duration_k - 1`` and starts at ``sum_{j<k} (duration_j - 1)``); past the last
  segment the value is 0. A zero-duration segment in a group is an error.
* Sampled kinds (4, 6, 7) at frame ``f``: nearest sample ``s = round(f)``, signed residual
  ``r = f - s``, value ``v[s] + r (v[s+1] - v[s])``, indices clamped to the samples.
* Packed float: 3 bytes, the upper three bytes of a little-endian IEEE-754 float32 whose low byte
  is ``0x80``.
* String hash: ``h = (h << 4) + byte`` (32 bits) per byte; when the top nibble ``t = h & 0xF0000000``
  is set, ``h ^= t >> 23``; then the top nibble is cleared.

piste's assumptions (what the facts leave open)
-----------------------------------------------
* The pointer table lies after the header table and before the curve data, which runs to the end
  of the file; bytes between them are kept as read (:attr:`AflFile.pads`).
* Frame rate: **30 frames a second** (``fps=``): world-prop clips are stated in measured 30 fps
  frames (OpenSlope ``120-objects.md``) and the rewrite's author plays rider clips at 30 ("looks
  right, not confirmed in code"); the game ticks at 60 Hz.
* Body tracks drive the ``.mpf`` body bones; a board track drives the skeleton's bone named
  ``board`` (when there is one the body track does not drive), as a local transform under its
  parent's animated pose. Cut-scene tracks are decoded (:meth:`AflFile.sample`), not mapped.
* Clip names: the file holds only hashes (the game's name table is in its executable); names
  resolve from ``names=`` and :data:`KNOWN_CLIP_NAMES` (the ride clips OpenSlope names, for the
  three board sets ``bx`` / ``fr`` / ``ex``, and ``bxT_NOSEGRAB``); the others are called
  ``clip_XXXXXXXX`` (the hex hash).
* The encoder writes header bytes 76, 17, clip records with pointer index 0 and no events (65535),
  track records with key 0 and zero fields, no padding, and each distinct curve once.

API
---
read_afl(path, names=()) -> AflFile / parse_afl(data, path, names=()) -> AflFile
afl_bytes(afl) -> bytes / write_afl(afl, path)          atomic; byte-identical for an unedited file
AflFile.sample(clip, frames=None) -> [(m, c) per track]; AflFile.evaluate(offsets, frames) -> (m, c)
encode_afl(clips, console=76, unknown=17) -> AflFile       clips: AflClipData (name, frames, tracks)
afl_clips(afl, skeleton, bones=None, fps=30, board_bone="board") -> {name: Clip}
mpf_body_bones(model) -> list[str | None]                the body bones' names in .mpf file order
body_track(root_cm (F, 3), euler (F, b, 3)) -> list[Curve]    60 curves (constant or 16-bit)
clip_channels(clip, skeleton, bones, fps=30) -> (root_cm (F, 3), euler (F, 19, 3))   piste -> AFL values
Curve, Segment, constant(), polynomial(), sampled(), group(); curve_bytes(curve) -> bytes
afl_hash(name) -> int; afl_rotation(euler (..., 3)) -> (..., 3, 3)
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from piste.character.animation import sample_poses
from piste.character.model import Clip, Skeleton, Track
from piste.character.skeleton import world_from_local
from piste.errors import ConfigError, FormatError, ValidationError
from piste.formats.atomic import write_bytes_atomic
from piste.formats.safe_io import read_regular
from piste.formats.ssx.mpf_model import CM, SSX_TO_PISTE, bone_euler, bone_rotation
from piste.transforms import compose_trs, decompose_trs, invert_affine, matrix_to_quat, quat_to_matrix

if TYPE_CHECKING:
    from piste.formats.ssx.mpf_model import SsxModel

__all__ = [
    "AflFile", "AflClip", "AflClipData", "Curve", "Segment", "HEADER_DTYPE", "TRACK_CHANNELS", "KIND_CLIP",
    "BODY_TRACK", "BOARD_TRACK", "BODY_BONES", "BODY_BONE_NAMES", "KNOWN_CLIP_NAMES", "DEFAULT_FPS", "read_afl",
    "parse_afl", "afl_bytes", "write_afl",
    "encode_afl", "afl_clips", "mpf_body_bones", "body_track", "clip_channels", "constant", "polynomial", "sampled",
    "group", "curve_bytes", "afl_hash", "afl_rotation", "MAX_FILE_BYTES", "MAX_BAKED_VALUES",
]

HEADER_DTYPE = np.dtype([("key", "<u4"), ("pointer_index", "<u4"), ("kind", "u1"), ("related", "u1"),
                         ("fields", "<u2", (11,)), ("tail", "<u4")])
assert HEADER_DTYPE.itemsize == 36
#: curve pointers (channels) used by a track record of each kind (OpenSlope afl_pose.py)
TRACK_CHANNELS = {0: 60, 1: 6, 4: 12, 5: 6, 6: 6, 7: 6, 8: 12, 9: 12, 10: 23, 11: 6, 12: 3, 13: 12, 14: 6, 15: 3}
KIND_CLIP = 255
BODY_TRACK = 0
BOARD_TRACK = 1
BODY_BONES = 19  # (60 - 3) / 3
#: the retail body's 19 bones in .mpf order, the order of the body track's Euler triples (the
#: rewrite's notes; the bone table of the public retail ``moby_body.mpf`` holds exactly these)
BODY_BONE_NAMES = ("hips", "lower_back", "upper_back", "neck", "head", "l_clav", "l_bicep", "l_forearm", "l_hand",
                   "r_clav", "r_bicep", "r_forearm", "r_hand", "l_thigh", "l_calf", "l_foot", "r_thigh", "r_calf",
                   "r_foot")
#: the ride clips named in OpenSlope's afl_pose.py (the bank holds only their hashes)
KNOWN_CLIP_NAMES = tuple(p + n for p in ("fr", "bx", "ex") for n in (
    "RL_BASECYCLEFAST", "RL_CROUCHCYCLE", "R_TURNHS", "R_TURNTS", "RC_TURNHS", "RC_TURNTS", "C_ANTIC")) + (
    "bxT_NOSEGRAB",)
DEFAULT_FPS = 30.0
MAX_FILE_BYTES = 64 << 20
#: most channel values baked over all clips of one conversion (frames x channels): 16 M float64
MAX_BAKED_VALUES = 1 << 24
_HEAD = struct.Struct("<BBHII")
_SAMPLED = (4, 6, 7)
_F32_MAX = float(np.finfo(np.float32).max)


# ----------------------------------------------------------------------------------- small facts
def afl_hash(name: str) -> int:
    """The engine's string hash of a clip name (the key of its kind-255 record)."""
    h = 0
    for b in name.encode("ascii"):
        h = ((h << 4) + b) & 0xFFFFFFFF
        top = h & 0xF0000000
        if top:
            h ^= top >> 23
        h &= 0x0FFFFFFF
    return h


def _unpack3(raw: bytes) -> np.ndarray:
    """Packed floats ``(n,) float32`` from ``3 n`` bytes (each the top 3 bytes of a float32, low byte 0x80)."""
    n = len(raw) // 3  # 1 to 4 a segment: struct beats numpy's per-call overhead here
    return np.array(struct.unpack(f"<{n}f", b"".join(b"\x80" + raw[i:i + 3] for i in range(0, 3 * n, 3))), np.float32)


def _pack3(values: npt.ArrayLike) -> bytes:
    """``(n,)`` values as packed floats (nearest: the float32's top 3 bytes)."""
    bits = np.asarray(values, np.float32).reshape(-1).view(np.uint32)
    out = np.stack([(bits >> 8) & 0xFF, (bits >> 16) & 0xFF, bits >> 24], axis=1).astype(np.uint8)
    return out.tobytes()


def _packed(values: npt.ArrayLike) -> np.ndarray:
    """What packed floats read back as: ``(n,) float32``."""
    return _unpack3(_pack3(values))


def afl_rotation(euler: npt.ArrayLike) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` of AFL / ``.mpf`` Euler triples ``(..., 3)`` radians:
    ``Rz(-z) @ Ry(-y) @ Rx(-x)`` (the public convention: angles negated), the same as a bone
    record's (:func:`piste.formats.ssx.mpf_model.bone_rotation`)."""
    return bone_rotation(euler)


_rotation_euler = bone_euler  # the inverse of afl_rotation: (..., 3, 3) -> (..., 3) radians


# ----------------------------------------------------------------------------------- curves
def _sampled_eval(v: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Sampled curves ``v (n, k)`` (n samples each) at local frames ``u (m,)`` -> ``(m, k)``: the
    nearest sample ``s = round(u)``, plus the signed residual ``u - s`` times the step to sample
    ``s + 1`` (indices clamped)."""
    n = v.shape[0]
    s = np.rint(u)
    r = (u - s)[:, None]
    si = np.clip(s, 0, n - 1).astype(np.int64)
    fi = np.minimum(si + 1, n - 1)
    return v[si] + r * (v[fi] - v[si])


@dataclass
class Segment:
    """One curve segment: ``kind`` (0 constant, 1-3 polynomial, 4 f32 samples, 6/7 8/16-bit samples),
    ``count`` (the descriptor's 12-bit count: duration in a group, the sample count of 4/6/7),
    ``params (k,) float32`` (0: the value; 1-3: coefficients, highest power first; 4: the samples;
    6/7: base, scale), ``samples (n,) uint8/uint16`` (6/7 only)."""

    kind: int
    count: int
    params: np.ndarray
    samples: np.ndarray | None = None

    def values(self) -> np.ndarray:
        """The sample values ``(n,) float64`` of a sampled segment (4, 6, 7)."""
        if self.kind == 4:
            return self.params.astype(np.float64)
        assert self.samples is not None  # kinds 6/7 always carry their samples
        return float(self.params[0]) + float(self.params[1]) * self.samples.astype(np.float64)

    def evaluate(self, u: npt.ArrayLike) -> np.ndarray:
        """Values ``(m,) float64`` at local frames ``u (m,)``."""
        u = np.asarray(u, np.float64)
        if self.kind == 0:
            return np.full(u.shape, float(self.params[0]))
        if self.kind <= 3:
            v = np.full(u.shape, float(self.params[0]))
            with np.errstate(over="ignore", invalid="ignore"):  # a huge polynomial: refused by afl_clips
                for c in self.params[1:]:
                    v = u * v + float(c)
            return v
        return _sampled_eval(self.values()[:, None], u)[:, 0]

    def to_bytes(self) -> bytes:
        head = struct.pack("<H", (self.count << 4) | self.kind)
        if self.kind <= 3:
            return head + _pack3(self.params)
        if self.kind == 4:
            return head + np.asarray(self.params, "<f4").tobytes()
        dt = "u1" if self.kind == 6 else "<u2"
        return head + _pack3(self.params) + np.asarray(self.samples, dt).tobytes()


@dataclass
class Curve:
    """One channel's curve: a single segment, or (``grouped``) a kind-5 group of segments."""

    segments: list
    grouped: bool = False

    def evaluate(self, frames: npt.ArrayLike) -> np.ndarray:
        """Values ``(m,) float64`` at clip frames ``frames (m,)`` (fractional allowed)."""
        f = np.atleast_1d(np.asarray(frames, np.float64))
        if not self.grouped:
            return self.segments[0].evaluate(f)
        out = np.zeros(f.shape)
        if not self.segments:
            return out
        d = np.array([s.count for s in self.segments], np.float64)
        ends = np.cumsum(d - 1.0)  # segment k covers global frames up to ends[k] (= the next one's start)
        starts = ends - (d - 1.0)
        idx = np.searchsorted(ends, f, side="left")
        order = np.argsort(idx, kind="stable")
        bounds = np.searchsorted(idx[order], np.arange(len(self.segments) + 1))
        for k in np.flatnonzero(np.diff(bounds)):  # only the segments some frame falls in
            sel = order[bounds[k]:bounds[k + 1]]
            out[sel] = self.segments[k].evaluate(f[sel] - starts[k])
        return out


def curve_bytes(curve: Curve) -> bytes:
    """The bytes of ``curve`` as the file stores it."""
    if not curve.grouped:
        return curve.segments[0].to_bytes()
    return struct.pack("<H", (len(curve.segments) << 4) | 5) + b"".join(s.to_bytes() for s in curve.segments)


def constant(value: float, duration: int = 0) -> Segment:
    """A constant segment (``duration``: its length in a group)."""
    return Segment(0, int(duration), _packed([value]))


def polynomial(coefficients: npt.ArrayLike, duration: int = 0) -> Segment:
    """A polynomial segment of degree 1-3 in the frame, ``coefficients`` highest power first."""
    c = _packed(coefficients)
    if not 2 <= c.size <= 4:
        raise ValidationError("a polynomial segment has 2 to 4 coefficients")
    return Segment(c.size - 1, int(duration), c)


def sampled(values: npt.ArrayLike, bits: int = 16) -> Segment:
    """A sampled segment of ``values (n,)`` (1 <= n <= 4095): ``bits`` 32 (f32, kind 4), 16 (kind 7)
    or 8 (kind 6: base + scale x integer, quantised to the nearest step)."""
    v = np.asarray(values, np.float64).reshape(-1)
    if not 1 <= v.size <= 4095:
        raise ValidationError("a sampled segment holds 1 to 4095 samples")
    if bits not in (8, 16, 32):
        raise ValidationError(f"a sampled segment has 8, 16 or 32-bit samples, got {bits}")
    if bits == 32:
        return Segment(4, v.size, v.astype(np.float32))
    top = (1 << bits) - 1
    lo, hi = float(v.min()), float(v.max())
    base = _packed([lo])[0]
    scale = _packed([(hi - float(base)) / top if hi > base else 1.0])[0]
    q = np.clip(np.rint((v - float(base)) / float(scale)), 0, top)
    return Segment(7 if bits == 16 else 6, v.size, np.array([base, scale], np.float32),
                   q.astype(np.uint16 if bits == 16 else np.uint8))


def group(segments: Sequence[Segment]) -> Curve:
    """A kind-5 curve of ``segments`` (each with its duration as ``count``)."""
    return Curve(list(segments), grouped=True)


def _segment_size(kind: int, count: int) -> int | None:
    if kind == 0:
        return 5
    if kind <= 3:
        return 2 + 3 * (kind + 1)
    if kind == 4:
        return 2 + 4 * count
    if kind == 6:
        return 8 + count
    if kind == 7:
        return 8 + 2 * count
    return None


class _Reader:
    def __init__(self, data: bytes, path: str | os.PathLike[str] | None, base: int) -> None:
        self.data, self.path, self.base = data, path, base

    def err(self, field_: str, msg: str) -> FormatError:
        return FormatError(self.path, msg, field=field_)

    def segment(self, off: int, where: str, in_group: bool) -> tuple[Segment, int]:
        d = self.data
        if off + 2 > len(d):
            raise self.err(f"{where}.descriptor", f"expected a 2-byte segment descriptor at {off}, past the end "
                                                  f"of the file ({len(d)} bytes)")
        desc = d[off] | (d[off + 1] << 8)
        kind, count = desc & 0xF, desc >> 4
        if kind == 5:
            raise self.err(f"{where}.kind", "expected a segment kind 0-4, 6 or 7 inside a group, got a nested group (5)"
                           if in_group else "internal: group read as a segment")
        size = _segment_size(kind, count)
        if size is None:
            raise self.err(f"{where}.kind", f"expected a segment kind 0-7, got {kind}")
        if kind in _SAMPLED and count == 0:
            raise self.err(f"{where}.count", f"expected at least one sample in a kind-{kind} segment, got 0")
        if in_group and count == 0:
            raise self.err(f"{where}.count", "expected a duration >= 1 frame for a segment in a group, got 0")
        if off + size > len(d):
            raise self.err(f"{where}.count", f"a kind-{kind} segment of count {count} needs {size} bytes at {off}, "
                                             f"but the file ends at {len(d)}")
        p = off + 2
        samples = None
        if kind <= 3:
            params = _unpack3(d[p:p + 3 * (kind + 1)])
        elif kind == 4:
            params = np.frombuffer(d, "<f4", count, p).astype(np.float32)
        else:
            params = _unpack3(d[p:p + 6])
            samples = np.frombuffer(d, "u1" if kind == 6 else "<u2", count, p + 6).copy()
        if not np.isfinite(params).all():
            raise self.err(f"{where}.values", f"expected finite numbers in a kind-{kind} segment, got "
                                              f"{params[~np.isfinite(params)][0]}")
        return Segment(kind, count, params, samples), size

    def curve(self, rel: int, where: str) -> tuple[Curve, int]:
        off = self.base + rel
        if off + 2 > len(self.data):
            raise self.err(where, f"expected a curve at data offset {rel} (file offset {off}), past the end of the "
                                  f"file ({len(self.data)} bytes)")
        desc = self.data[off] | (self.data[off + 1] << 8)
        if desc & 0xF != 5:
            seg, size = self.segment(off, where, False)
            return Curve([seg]), size
        n = desc >> 4
        segs, p = [], off + 2
        for k in range(n):  # n < 4096 and each segment needs >= 5 bytes: bounded by the file
            seg, size = self.segment(p, f"{where}.segment[{k}]", True)
            segs.append(seg)
            p += size
        return Curve(segs, grouped=True), p - off


# ----------------------------------------------------------------------------------- the file
@dataclass
class AflClip:
    """A named clip of a bank: ``name`` (resolved, or ``clip_XXXXXXXX``), ``key`` (hash),
    ``frames``, ``header`` (index of its kind-255 record) and ``tracks``: ``(kind, [pointer
    offsets relative to the curve data] or None when the kind is unknown)`` per track record."""

    name: str
    key: int
    frames: int
    header: int
    tracks: list

    @property
    def body(self) -> list | None:
        """The curve offsets of the clip's first body track (60), or None."""
        for kind, offs in self.tracks:
            if kind == BODY_TRACK and offs is not None:
                return offs
        return None


@dataclass
class AflFile:
    """An ``.afl`` bank: the 12-byte header's ``console`` and ``unknown`` bytes, ``headers (n,)
    HEADER_DTYPE``, ``pointers (p,) uint32`` (curve offsets relative to the curve data), ``data``
    (the curve data as read, to the end of the file), ``pads`` (the bytes between header table and
    pointer table, and between pointer table and curve data), ``curves`` (decoded curves by
    relative offset, those the clips use), ``clips`` (:class:`AflClip`), ``notes``, ``path``."""

    console: int
    unknown: int
    headers: np.ndarray
    pointers: np.ndarray
    data: bytes
    pads: tuple = (b"", b"")
    curves: dict = field(default_factory=dict)
    clips: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    path: str | None = None

    def clip(self, name: str) -> AflClip:
        for c in self.clips:
            if c.name == name:
                return c
        key = afl_hash(name) if name.isascii() else -1
        for c in self.clips:
            if c.key == key:
                return c
        raise KeyError(f"no clip {name!r} in {self.path or 'the .afl'} ({len(self.clips)} clips)")

    def sample(self, clip: AflClip | str, frames: npt.ArrayLike | None = None) -> list:
        """Channel values of every track of ``clip`` at ``frames (m,)`` (default: every frame):
        one ``(m, c) float64`` array per track, None for a track of unknown kind."""
        c = self.clip(clip) if isinstance(clip, str) else clip
        f = np.arange(max(c.frames, 1), dtype=np.float64) if frames is None else np.atleast_1d(
            np.asarray(frames, np.float64))
        return [None if offs is None else self.evaluate(offs, f) for _, offs in c.tracks]

    def evaluate(self, offsets: Sequence[int], frames: npt.ArrayLike) -> np.ndarray:
        """Values ``(m, c) float64`` of the curves at data offsets ``offsets (c,)`` at ``frames (m,)``:
        each distinct curve once; the single-segment constants, and the single-segment sampled curves
        of one sample count, in one vectorised gather each; the others curve by curve."""
        f = np.atleast_1d(np.asarray(frames, np.float64))
        uniq, inv = np.unique(np.asarray(offsets, np.int64), return_inverse=True)
        res = np.empty((f.shape[0], uniq.shape[0]))
        batches: dict = {}
        for u, o in enumerate(uniq.tolist()):
            cv = self.curves[o]
            s0 = None if cv.grouped else cv.segments[0]
            if s0 is not None and s0.kind == 0:
                batches.setdefault(0, []).append((u, s0))
            elif s0 is not None and s0.kind in _SAMPLED:
                batches.setdefault(s0.count, []).append((u, s0))  # count >= 1 (parse refuses 0)
            else:
                res[:, u] = cv.evaluate(f)
        for n, items in batches.items():
            cols = [u for u, _ in items]
            if n == 0:
                res[:, cols] = np.array([float(sg.params[0]) for _, sg in items])[None]
            else:
                res[:, cols] = _sampled_eval(np.stack([sg.values() for _, sg in items], axis=1), f)
        return res[:, inv.reshape(-1)]


def parse_afl(data: bytes, path: str | os.PathLike[str] = "<bytes>", names: Iterable[str] = ()) -> AflFile:
    """An :class:`AflFile` from the bytes of an ``.afl`` (FormatError naming file and field on bad
    input). ``names``: clip names to resolve the hashes with (besides :data:`KNOWN_CLIP_NAMES`)."""
    data = bytes(data)
    if len(data) < 12:
        raise FormatError(path, f"expected at least the 12-byte header, got {len(data)} bytes", field="header")
    console, unknown, n, ptr_off, data_off = _HEAD.unpack_from(data, 0)
    hdr_end = 12 + n * HEADER_DTYPE.itemsize
    if hdr_end > len(data):
        raise FormatError(path, f"{n} header records need {hdr_end} bytes, but the file has {len(data)}",
                          field="header_count")
    if not hdr_end <= ptr_off <= len(data):
        raise FormatError(path, f"expected the curve-pointer table between the end of the header table ({hdr_end}) "
                                f"and the end of the file ({len(data)}), got offset {ptr_off}", field="pointer_offset")
    if not ptr_off <= data_off <= len(data):
        raise FormatError(path, f"expected the curve data between the pointer table ({ptr_off}) and the end of the "
                                f"file ({len(data)}), got offset {data_off}", field="data_offset")
    headers = np.frombuffer(data, HEADER_DTYPE, n, 12).copy()
    n_ptr = (data_off - ptr_off) // 4
    pointers = np.frombuffer(data, "<u4", n_ptr, ptr_off).astype(np.uint32)
    pads = (data[hdr_end:ptr_off], data[ptr_off + 4 * n_ptr:data_off])
    afl = AflFile(console, unknown, headers, pointers, data[data_off:], pads, path=str(path))
    lookup = {afl_hash(s): s for s in (*KNOWN_CLIP_NAMES, *names) if s.isascii()}
    r = _Reader(data, path, data_off)
    kinds = headers["kind"]
    seen: set = set()
    for i in np.flatnonzero(kinds == KIND_CLIP):
        h = headers[i]
        rel = int(h["related"])
        if i + rel >= n:
            raise FormatError(path, f"clip record {i} names {rel} track records, but the table ends after record "
                                    f"{n - 1}", field=f"headers[{i}].related")
        key = int(h["key"])
        name = lookup.get(key, f"clip_{key:08x}")
        if name in seen:  # two records with one hash: keep both, named apart by record index
            name = f"{name}@{i}"
        seen.add(name)
        tracks: list[tuple[int, list[int] | None]] = []
        for j in range(i + 1, i + 1 + rel):
            kind = int(kinds[j])
            nch = TRACK_CHANNELS.get(kind)
            if nch is None:
                afl.notes.append(f"clip {name}: track record {j} has kind {kind}, which piste does not know; skipped")
                tracks.append((kind, None))
                continue
            first = int(headers[j]["pointer_index"])
            if first + nch > n_ptr:
                raise FormatError(path, f"a kind-{kind} track uses {nch} curve pointers from {first}, but the table "
                                        f"holds {n_ptr}", field=f"headers[{j}].pointer_index")
            offs = [int(x) for x in pointers[first:first + nch]]
            for k, o in enumerate(offs):
                if o not in afl.curves:
                    afl.curves[o] = r.curve(o, f"curve[{first + k}]")[0]
            tracks.append((kind, offs))
        afl.clips.append(AflClip(name, key, int(h["fields"][0]), int(i), tracks))
    return afl


def read_afl(path: str | os.PathLike[str], names: Iterable[str] = ()) -> AflFile:
    """Read an ``.afl`` (regular files only, at most :data:`MAX_FILE_BYTES`)."""
    return parse_afl(read_regular(Path(path), MAX_FILE_BYTES, what="animation bank"), path, names)


def afl_bytes(afl: AflFile) -> bytes:
    """The file's bytes: header, header table, pointer table and curve data (offsets follow the layout)."""
    headers = np.ascontiguousarray(afl.headers, HEADER_DTYPE)
    ptr_off = 12 + headers.nbytes + len(afl.pads[0])
    data_off = ptr_off + 4 * len(afl.pointers) + len(afl.pads[1])
    return b"".join([_HEAD.pack(afl.console, afl.unknown, len(headers), ptr_off, data_off), headers.tobytes(),
                     afl.pads[0], np.asarray(afl.pointers, "<u4").tobytes(), afl.pads[1], bytes(afl.data)])


def write_afl(afl: AflFile, path: str | os.PathLike[str]) -> None:
    """Write ``afl`` to ``path`` atomically (no half-written file on failure)."""
    write_bytes_atomic(path, afl_bytes(afl))


# ----------------------------------------------------------------------------------- encoder
@dataclass
class AflClipData:
    """A clip for :func:`encode_afl`: ``name``, ``frames`` and ``tracks``: ``(kind, [Curve] x
    TRACK_CHANNELS[kind])`` per track."""

    name: str
    frames: int
    tracks: list


def encode_afl(clips: Iterable[AflClipData], console: int = 76, unknown: int = 17) -> AflFile:
    """A bank of ``clips`` (:class:`AflClipData`) in the layout :func:`parse_afl` reads (each
    distinct curve stored once); returned as parsed from its own bytes."""
    headers: list[np.ndarray] = []
    pointers: list[int] = []
    blobs: list[bytes] = []
    where: dict[bytes, int] = {}
    size = 0
    for c in clips:
        if not 0 <= int(c.frames) <= 0xFFFF:
            raise ValidationError(f"clip {c.name!r}: frames must fit in 16 bits")
        h = np.zeros((), HEADER_DTYPE)
        h["key"], h["kind"], h["related"] = afl_hash(c.name), KIND_CLIP, len(c.tracks)
        h["fields"][:] = 0xFFFF  # no events
        h["fields"][0] = int(c.frames)
        headers.append(h)
        for kind, curves in c.tracks:
            if kind not in TRACK_CHANNELS:
                raise ValidationError(f"clip {c.name!r}: track kind {kind} is not one of {sorted(TRACK_CHANNELS)}")
            if len(curves) != TRACK_CHANNELS[kind]:
                raise ValidationError(f"clip {c.name!r}: a kind-{kind} track has {TRACK_CHANNELS[kind]} channels, "
                                 f"got {len(curves)} curves")
            t = np.zeros((), HEADER_DTYPE)
            t["kind"], t["pointer_index"] = kind, len(pointers)
            headers.append(t)
            for cv in curves:
                b = curve_bytes(cv)
                if b not in where:
                    where[b] = size
                    blobs.append(b)
                    size += len(b)
                pointers.append(where[b])
    hdr = np.array(headers, HEADER_DTYPE) if headers else np.zeros(0, HEADER_DTYPE)
    raw = AflFile(console, unknown, hdr, np.asarray(pointers, np.uint32), b"".join(blobs))
    return parse_afl(afl_bytes(raw), "<encoded>", names=[c.name for c in clips])


def body_track(root_cm: npt.ArrayLike, euler: npt.ArrayLike, bits: int = 16) -> list:
    """The 60 curves of a body track from ``root_cm (F, 3)`` and ``euler (F, 19, 3)`` (fewer bones:
    the rest held at 0): a constant where a channel does not change, else ``bits`` samples."""
    root = np.asarray(root_cm, np.float64).reshape(-1, 3)
    e = np.asarray(euler, np.float64).reshape(root.shape[0], -1, 3)
    ch = np.zeros((root.shape[0], 3 + 3 * BODY_BONES))
    ch[:, :3] = root
    k = min(e.shape[1], BODY_BONES)
    ch[:, 3:3 + 3 * k] = e[:, :k].reshape(root.shape[0], -1)
    flat = np.ptp(ch, axis=0) == 0
    return [Curve([constant(ch[0, j])]) if flat[j] else Curve([sampled(ch[:, j], bits)]) for j in range(ch.shape[1])]


# ----------------------------------------------------------------------------------- clips
def mpf_body_bones(model: SsxModel) -> list:
    """The names, in the piste skeleton of ``model`` (an :class:`~piste.formats.ssx.SsxModel`), of
    the body bones in ``.mpf`` file order (the first sub-model with bones of the first file): the
    bones a body track drives, channel triple ``i`` for bone ``i``. A bone the skeleton does not
    hold by that name is None."""
    files = getattr(model, "files", None) or []
    sk = model.skeleton
    if sk is None:
        raise ValidationError("mpf_body_bones: the model has no skeleton (expected an .mpf rider's model)")
    for f in files[:1]:
        for s in f.models:
            if len(s.bones):
                return [n if sk.get(n) is not None else None for n in s.bone_names]
    return list(sk.names)


_AXES = np.argmax(np.abs(SSX_TO_PISTE), axis=1)          # SSX_TO_PISTE is a signed permutation
_SIGNS = SSX_TO_PISTE[np.arange(3), _AXES]


def _to_piste(rm: np.ndarray) -> np.ndarray:
    """``A @ rm @ A.T`` for rotation matrices ``rm (..., 3, 3)`` in SSX axes (A = SSX_TO_PISTE), by
    indexing (A permutes and signs the axes) instead of two batched matmuls."""
    return rm[..., _AXES[:, None], _AXES[None, :]] * (_SIGNS[:, None] * _SIGNS[None, :])


def _default_bones(skeleton: Skeleton) -> list:
    if all(skeleton.get(n) is not None for n in BODY_BONE_NAMES):
        return list(BODY_BONE_NAMES)
    return list(skeleton.names[:BODY_BONES])


def _continuous(q: npt.ArrayLike) -> np.ndarray:
    """Quaternions ``(F, ..., 4)`` with each track's sign flipped to stay on one hemisphere (slerp)."""
    q = np.array(q, np.float64)
    dots = np.einsum("t...i,t...i->t...", q[1:], q[:-1])
    flip = np.cumprod(np.where(dots < 0, -1.0, 1.0), axis=0)
    q[1:] *= flip[..., None]
    return q


def _checked(afl: AflFile, c: AflClip, ch: np.ndarray, what: str) -> np.ndarray:
    ok = np.abs(ch) <= _F32_MAX  # the game evaluates in float32: beyond it is inf
    if not ok.all():
        j = int(np.flatnonzero(~ok.all(0))[0])
        raise FormatError(afl.path, f"clip {c.name}: {what} channel {j} evaluates to a non-finite value (past the "
                                    f"float32 range)", field=f"headers[{c.header}]")
    return ch


def afl_clips(afl: AflFile, skeleton: Skeleton, bones: Iterable[str | None] | None = None, fps: float = DEFAULT_FPS,
              clips: Iterable[str] | None = None,
              board_bone: str | None = "board") -> dict:
    """The bank's clips as piste :class:`Clip` objects for ``skeleton`` (an ``.mpf`` rider's).

    ``bones``: the skeleton's names of the bones the body track drives, in ``.mpf`` file order
    (:func:`mpf_body_bones`; default: :data:`BODY_BONE_NAMES` when the skeleton has them all, else
    its first 19 bones); None entries and bones past
    the 19 the track holds are not driven (they keep their rest pose). Each clip is baked at every
    frame (``times = frame / fps``, LINEAR): a rotation track per driven bone (the AFL Euler
    triple, ``Rz(-z) Ry(-y) Rx(-x)``, in piste's axes), a translation track on the driven roots
    (the root channels, cm -> m); a clip's board track drives ``board_bone`` when the skeleton
    has it and the body track does not drive it (translation + rotation, relative to its parent's
    animated pose). Clips without a body track are skipped (``afl.notes``). ``clips``: names to
    convert (default: all).
    """
    if not (isinstance(fps, (int, float)) and np.isfinite(fps) and fps > 0):
        raise ConfigError(f"fps must be a finite number > 0, got {fps!r}")
    names = _default_bones(skeleton) if bones is None else list(bones)[:BODY_BONES]
    idx = [(i, skeleton.get(n)) for i, n in enumerate(names) if n is not None and skeleton.get(n) is not None]
    file_i = np.array([i for i, _ in idx], np.int64)
    sk_i = np.array([j for _, j in idx], np.int64)
    jb = skeleton.get(board_bone) if board_bone else None
    if jb in set(sk_i.tolist()):
        jb = None
    chosen = afl.clips if clips is None else [afl.clip(n) for n in clips]
    total = sum(max(c.frames, 1) * (3 + 3 * BODY_BONES + 6) for c in chosen if c.body is not None)
    if total > MAX_BAKED_VALUES:
        raise FormatError(afl.path, f"the clips' frame counts ask for {total} channel values, more than the limit of "
                                    f"{MAX_BAKED_VALUES}", field="frames")
    a = SSX_TO_PISTE
    roots = sk_i[skeleton.parents[sk_i] < 0]
    work = []  # (clip, frames, body channels (F, 60), board channels (F, 6) or None)
    for c in chosen:
        kinds = [k for k, offs in c.tracks if offs is not None]
        body = c.body  # the first body track: present exactly when BODY_TRACK is in kinds
        if body is None:
            afl.notes.append(f"clip {c.name}: no body track; not converted")
            continue
        f = max(c.frames, 1)
        frames = np.arange(f, dtype=np.float64)
        ch = _checked(afl, c, afl.evaluate(body, frames), "body")
        board = None
        if jb is not None and BOARD_TRACK in kinds:
            offs = next(o for k, o in c.tracks if k == BOARD_TRACK and o is not None)
            board = _checked(afl, c, afl.evaluate(offs, frames), "board")
        work.append((c, f, ch, board))
    if not work:
        return {}
    # every clip's frames at once: rotations (sum F, k) in one batch
    allch = np.concatenate([w[2] for w in work])
    q_all = matrix_to_quat(_to_piste(afl_rotation(allch[:, 3:].reshape(-1, BODY_BONES, 3)[:, file_i])))
    root_all = (allch[:, :3] @ a.T) * CM
    cuts = np.cumsum([0] + [w[1] for w in work])
    out = {}
    for (c, f, _, board), lo, hi in zip(work, cuts[:-1], cuts[1:]):
        times = np.arange(f) / float(fps)
        q = _continuous(q_all[lo:hi])                                        # (F, k, 4) piste axes
        root = root_all[lo:hi]                                               # (F, 3) m
        tracks = {}
        for k, j in enumerate(sk_i.tolist()):
            bt = {"rotation": Track(times, q[:, k])}
            if skeleton.parents[j] < 0:
                bt["translation"] = Track(times, root)
            tracks[skeleton.names[j]] = bt
        if board is not None:
            world = compose_trs((board[:, :3] @ a.T) * CM, matrix_to_quat(_to_piste(afl_rotation(board[:, 3:]))),
                                np.ones((f, 3)))                             # (F, 4, 4) board in model space
            parent = int(skeleton.parents[jb])
            if parent >= 0:  # under its parent as this clip poses it
                rest = skeleton.rest_pose()
                t = np.repeat(rest.translation[None], f, 0)
                r = np.repeat(rest.rotation[None], f, 0)
                r[:, sk_i] = q
                t[:, roots] = root[:, None]
                pw = world_from_local(compose_trs(t, r, np.repeat(rest.scale[None], f, 0)), skeleton.parents,
                                      skeleton.levels)[:, parent]
                world = invert_affine(pw) @ world
            bt_t, bt_r, _ = decompose_trs(world)
            assert jb is not None  # a board track is evaluated only with a board bone
            tracks[skeleton.names[jb]] = {"translation": Track(times, bt_t), "rotation": Track(times, _continuous(bt_r))}
        out[c.name] = Clip(c.name, float(times[-1]), tracks, skeleton=skeleton)
    return out


def clip_channels(clip: Clip, skeleton: Skeleton, bones: Iterable[str | None] | None = None,
                  fps: float = DEFAULT_FPS) -> tuple[np.ndarray, np.ndarray]:
    """A piste clip as AFL body values (the inverse of :func:`afl_clips`): ``root_cm (F, 3)`` (the
    first driven root's translation, cm, ``.mpf`` axes) and ``euler (F, 19, 3)`` (radians, the
    negated ``Rz Ry Rx`` convention) of ``bones`` (default as :func:`afl_clips`), sampled at
    ``F = round(duration * fps) + 1`` frames; bones that are None or missing get zeros."""
    if not (isinstance(fps, (int, float)) and np.isfinite(fps) and fps > 0):
        raise ConfigError(f"fps must be a finite number > 0, got {fps!r}")
    names = _default_bones(skeleton) if bones is None else list(bones)[:BODY_BONES]
    f = round(clip.duration * fps) + 1
    if f > 0xFFFF:
        raise ValidationError(f"clip {clip.name!r}: {f} frames at {fps} fps do not fit the 16-bit frame count")
    times = np.arange(f) / float(fps)
    t, r, _ = sample_poses(clip, times, skeleton)
    a = SSX_TO_PISTE
    euler = np.zeros((f, BODY_BONES, 3))
    root = np.zeros((f, 3))
    have_root = False
    for i, n in enumerate(names):
        j = None if n is None else skeleton.get(n)
        if j is None:
            continue
        euler[:, i] = _rotation_euler(a.T @ quat_to_matrix(r[:, j]) @ a)
        if skeleton.parents[j] < 0 and not have_root:
            root = (t[:, j] @ a) / CM
            have_root = True
    return root, euler
