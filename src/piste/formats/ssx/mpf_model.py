"""SSX Tricky rider models (``.mpf``) <-> piste's character :class:`~piste.character.Model`.

The format layer builds the character data classes (as :mod:`piste.formats.gltf` does). The bytes
live in :mod:`piste.formats.ssx.mpf` (``MpfFile.to_model()`` calls :func:`mpf_to_model`), the
layout facts both use in :mod:`piste.formats.ssx.mpf_layout` (so this module never imports the byte
module), the encoder in :mod:`piste.formats.ssx.mpf_encode`.

``mpf_to_model(*files)`` turns one or more read ``.mpf`` files (a body file, optionally its head
file: bones parent across files by file id) into an :class:`SsxModel`: a :class:`Model` whose
skeleton comes from the bone records, whose meshes are the top LOD's sub-models (``Body3000``,
``Head3000``, ...) with joints and weights from the file's weight palettes and morph targets from
its morph keys, plus ``lods`` (one :class:`~piste.character.LOD` per LOD tier ``3000`` / ``1500``
/ ``750``, each carrying **the file's own palettes** as its blended-matrix palette).

``model_to_mpf(model)`` (:mod:`piste.formats.ssx.mpf_encode`) is the reverse: a piste rider (the
default rider or a skinned glTF) as a body ``.mpf`` the game's limits allow (<= 55 vertices a
chunk, <= 25 palette matrices a link, weights in 25 % steps, at most 3 bones a vertex), with a
report of what was quantised and the resulting error.

Frames and units (piste's assumptions where the facts are silent)
-----------------------------------------------------------------
* The file is centimetres, Z up (SSX's world convention; the board deck lies along X); piste's
  models are metres, +Y up. ``p_piste = A p_ssx / 100`` with ``A`` mapping SSX ``(x, y, z)`` to
  piste ``(x, z, -y)``; rotations are conjugated by ``A``.
* A bone's bind rotation triple ``(rx, ry, rz)`` is ``R = Rz(-rz) Ry(-ry) Rx(-rx)``: the angles
  negated (:func:`bone_rotation`; SSX-Library ``glftHandler.cs`` builds ``Euler.ToQuaternion(-x,
  -y, -z)``, OpenSlope ``tools/analysis/afl_pose.py`` "signs negated"). On the retail
  ``moby_body.mpf`` + ``moby_head.mpf`` rider the 1,659 top-LOD vertices weighted 100 % to one
  bone sit a median 8.5 cm from their bone's segments this way, 42 cm with the angles unnegated
  (``tests/formats/ssx/test_mpf_errors.py::test_real_files`` measures it). The encoder writes
  the same convention (:func:`bone_euler`).
* Bone records written by the encoder: channel flags 3 (animated translation + rotation) for
  roots, 2 (rotation) for the others; mirror partner by ``_l``/``_r`` (``l_``/``r_``, ``Left``/
  ``Right``) name swap; mirror rotation offset ``(0, 0, pi)`` on roots, 0 elsewhere; mirror scales
  ``(1, -1, -1)`` rotation and ``(1, -1, 1)`` translation (the rider root's values in the facts).
* Morph-key triangles (any vertex that moves in a morph target) go to group type 256, one chunk
  per mesh header so the deltas are parallel to that chunk; the rest to type-1 render groups.
* Materials: one record (``suit``), blend 0, the two unread floats 1/255. Textures live in the
  character ``.ssh`` banks, not in the ``.mpf``; decoded models carry none (``texture=None``) but
  name each vertex's material (``SsxModel.materials``), and :mod:`piste.pipeline.ssx_rider` applies
  a bank. :func:`mpf_partners` names the files that go with a rider: the ``_head.mpf`` beside a
  ``_body.mpf``, and texture banks (given, or ``<stem>.ssh`` beside each model file).

API
---
::

    mpf_to_model(*files, name=None) -> SsxModel
    mpf_partners(path, texture=None) -> (head .mpf or None, [texture .ssh banks])
    MpfFile.to_model(*other_files)  (the same, from the byte module)
    SsxModel: Model + ``lods``, ``notes``
    euler_to_matrix / matrix_to_euler (Rz Ry Rx), bone_rotation / bone_euler (a bone record's convention), SSX_TO_PISTE
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from math import gcd
from pathlib import Path
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from piste.character.lod import LOD
from piste.character.model import Model, Skeleton, SkinnedMesh
from piste.character.palette import Palette
from piste.errors import ConfigError, ValidationError
from piste.formats.ssx.mpf_layout import (
    GROUP_SHADOW, MORPH_SCALE, NORMAL_SCALE, SLOT_TRANSFORM_BASE, UV_SCALE, strip_triangles,
)
from piste.transforms import compose_trs, invert_affine, matrix_to_quat

# piste.formats.ssx.mpf's MpfFile / SubModel are typed Any here: mpf imports this module, and an
# import back (even under TYPE_CHECKING) is a cycle tests/test_architecture.py refuses
_MpfFile = Any
_SubModel = Any

__all__ = ["SsxModel", "mpf_to_model", "mpf_partners", "euler_to_matrix", "matrix_to_euler", "bone_rotation", "bone_euler",
           "SSX_TO_PISTE", "LOD_TIERS", "CM"]

#: SSX (x, y, z) -> piste (x, z, -y)
SSX_TO_PISTE = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
CM = 0.01
LOD_TIERS = ("3000", "1500", "750")
_LOD_NAMES = ("high", "medium", "low")


@dataclass
class SsxModel(Model):
    """A :class:`Model` decoded from ``.mpf`` files: ``lods`` (:class:`LOD` per tier, the file's
    palettes), ``notes`` (what could not be represented), ``files`` (the MpfFile objects);
    ``materials`` (each distinct ``(main texture id, material index)`` of the sub-models' material
    records) with ``mesh_materials`` / ``lod_materials`` naming each vertex's material (its
    group's), so a texture bank can be applied (:mod:`piste.pipeline.ssx_rider`)."""

    lods: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    files: list = field(default_factory=list)
    materials: list = field(default_factory=list)       # [(main texture id, material index)], distinct
    mesh_materials: list = field(default_factory=list)  # per mesh: (v,) int32 index into materials
    lod_materials: list = field(default_factory=list)   # per LOD: (v,) int32 index into materials


# ----------------------------------------------------------------------------------- rotations
def euler_to_matrix(e: npt.ArrayLike) -> np.ndarray:
    """``(..., 3)`` radians -> ``(..., 3, 3)``: ``Rz(z) @ Ry(y) @ Rx(x)``."""
    e = np.asarray(e, np.float64)
    cx, cy, cz = np.cos(e[..., 0]), np.cos(e[..., 1]), np.cos(e[..., 2])
    sx, sy, sz = np.sin(e[..., 0]), np.sin(e[..., 1]), np.sin(e[..., 2])
    m = np.empty(e.shape[:-1] + (3, 3))
    m[..., 0, 0] = cz * cy
    m[..., 0, 1] = cz * sy * sx - sz * cx
    m[..., 0, 2] = cz * sy * cx + sz * sx
    m[..., 1, 0] = sz * cy
    m[..., 1, 1] = sz * sy * sx + cz * cx
    m[..., 1, 2] = sz * sy * cx - cz * sx
    m[..., 2, 0] = -sy
    m[..., 2, 1] = cy * sx
    m[..., 2, 2] = cy * cx
    return m


def matrix_to_euler(m: npt.ArrayLike) -> np.ndarray:
    """Inverse of :func:`euler_to_matrix`: ``(..., 3, 3)`` -> ``(..., 3)`` radians."""
    m = np.asarray(m, np.float64)
    y = np.arcsin(np.clip(-m[..., 2, 0], -1.0, 1.0))
    x = np.arctan2(m[..., 2, 1], m[..., 2, 2])
    z = np.arctan2(m[..., 1, 0], m[..., 0, 0])
    gimbal = np.abs(m[..., 2, 0]) > 1.0 - 1e-9
    x = np.where(gimbal, np.arctan2(-m[..., 1, 2], m[..., 1, 1]), x)
    z = np.where(gimbal, 0.0, z)
    return np.stack([x, y, z], -1)


def bone_rotation(e: npt.ArrayLike) -> np.ndarray:
    """A bone record's bind rotation: ``(..., 3)`` radians -> ``(..., 3, 3)``
    ``Rz(-z) @ Ry(-y) @ Rx(-x)`` (the angles negated: module docstring)."""
    return euler_to_matrix(-np.asarray(e, np.float64))


def bone_euler(m: npt.ArrayLike) -> np.ndarray:
    """Inverse of :func:`bone_rotation`: ``(..., 3, 3)`` -> ``(..., 3)`` radians as a bone record holds them."""
    return -matrix_to_euler(m)


# ------------------------------------------------------------------------------- mpf -> model
def _tier(name: str) -> str | None:
    if "shdw" in name.lower():
        return None
    for t in LOD_TIERS:
        if name.endswith(t):
            return t
    return ""


def _skeleton(files: list, notes: list) -> tuple[Skeleton | None, dict[int, int], np.ndarray | None]:
    """Merged skeleton of the files: ``(Skeleton, base {file id: first global index}, order)``."""
    source: dict[int, Any] = {}
    for f in files:
        for s in f.models:
            if len(s.bones) and s.file_id not in source:
                source[s.file_id] = s
    base: dict[int, int] = {}
    names: list[str] = []
    parents_l: list[int] = []
    t_l: list[np.ndarray] = []
    r_l: list[np.ndarray] = []
    for fid, s in source.items():
        base[fid] = len(names)
        names += [f"{n}" if f"{n}" not in names else f"{n}.{fid}" for n in s.bone_names]
    for fid, s in source.items():
        for b in s.bones:
            pf, pb = int(b["parent_file"]), int(b["parent_bone"])
            if pb < 0 or pf < 0:
                parents_l.append(-1)
            elif pf not in base or pb >= len(source[pf].bones):
                notes.append(f"bone {bytes(b['name']).decode('ascii', 'replace')!r}: parent (file {pf}, bone {pb}) "
                             f"is not in the files given; made a root")
                parents_l.append(-1)
            else:
                parents_l.append(base[pf] + pb)
            t_l.append(b["translation"])
            r_l.append(b["rotation"])
    if not names:
        return None, base, None
    a = SSX_TO_PISTE
    t = (np.asarray(t_l, np.float64) @ a.T) * CM
    rm = a @ bone_rotation(np.asarray(r_l, np.float64)) @ a.T
    q = matrix_to_quat(rm)
    n = len(names)
    local = compose_trs(t, q, np.ones((n, 3)))
    parents = np.asarray(parents_l, np.int64)
    # world matrices in any parent order (iterate to a fixed point; depth <= n)
    world = local.copy()
    done = parents < 0
    for _ in range(n):
        todo = ~done & (parents >= 0)
        ready = todo & done[np.maximum(parents, 0)]
        if not ready.any():
            break
        idx = np.nonzero(ready)[0]
        world[idx] = world[parents[idx]] @ local[idx]
        done[idx] = True
    if not done.all():
        raise ValidationError("the .mpf bone parents form a cycle")
    if np.all(parents < np.arange(n)):  # already parents-first: keep the file's order
        return Skeleton(names, parents, t, q, np.ones((n, 3)), invert_affine(world)), base, np.arange(n)
    sk, order = Skeleton.ordered(names, parents, t, q, np.ones((n, 3)), invert_affine(world))
    return sk, base, order


def _palette_tables(sub: _SubModel, base: dict, new_index: np.ndarray,
                    counts: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The sub-model's palettes as ``bones (p, k) int64`` (skeleton indices), ``percent (p, k)``.
    ``counts``: bones per file id; a palette naming a bone past its file's list is refused (it
    would skin with another file's bone, or none)."""
    k = max([len(p) for p in sub.palettes] + [1])
    bones = np.zeros((len(sub.palettes), k), np.int64)
    pct = np.zeros((len(sub.palettes), k), np.int64)
    for i, p in enumerate(sub.palettes):
        for j, e in enumerate(p):
            f = int(e["file"])
            if f not in base:
                raise ValidationError(f"{sub.name}: palette {i} names bone {int(e['bone'])} of file id {f}, which "
                                      f"is not among the files given (pass the matching body/head file too)")
            if counts is not None and not 0 <= int(e["bone"]) < counts[f]:
                raise ValidationError(f"{sub.name}: palette {i} names bone {int(e['bone'])} of file id {f}, which has "
                                      f"{counts[f]} bones")
            bones[i, j] = new_index[base[f] + int(e["bone"])]
            pct[i, j] = int(e["weight"])
    return bones, pct


def _weld(key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``key (n, c) float32`` that are bit-identical: ``first (u,)`` (one row of each
    kind, in first-seen order of the sorted hashes) and ``inverse (n,)``. Rows are hashed to 64
    bits and the hashes sorted; a collision (never seen) falls back to sorting the whole rows."""
    k = np.ascontiguousarray(key, np.float32)
    words = k.view(np.uint32).astype(np.uint64)
    h = np.full(len(k), 1469598103934665603, np.uint64)
    with np.errstate(over="ignore"):
        for c in range(words.shape[1]):
            h = (h ^ words[:, c]) * np.uint64(1099511628211)
            h ^= h >> np.uint64(29)
    _, first, inv = np.unique(h, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    if not np.array_equal(k[first][inv].view(np.uint32), k.view(np.uint32)):  # a hash collision
        v = k.view(np.dtype((np.void, 4 * k.shape[1]))).ravel()
        _, first, inv = np.unique(v, return_index=True, return_inverse=True)
        inv = inv.reshape(-1)
    return first, inv


def _decode_sub(sub: _SubModel, pal_bones: np.ndarray, pal_pct: np.ndarray, weld: bool) -> tuple[np.ndarray, ...] | None:
    """Arrays of one sub-model's render and morph groups (shadow groups skipped); the chunks are
    gathered first and decoded in one vectorised pass (strips -> triangles, slots -> palettes)."""
    pos_l: list[np.ndarray] = []
    nrm_l: list[np.ndarray] = []
    uv_l: list[np.ndarray] = []
    refs_cat: list[np.ndarray] = []
    ref_base: list[int] = []
    nvs: list[int] = []
    strips: list[np.ndarray] = []
    morph_l: list[np.ndarray] = []
    mats_l: list[np.ndarray] = []
    k = sub.morph_keys
    nref = 0
    for g in sub.groups:
        if g.type == GROUP_SHADOW:
            continue
        for lk in g.links:
            refs_cat.append(np.asarray(lk.refs, np.int64))
            for m in lk.meshes:
                chunks = [c for c in m.chunks if not c.shadow]
                if not chunks:
                    continue
                nv = sum(c.n_vertices for c in chunks)
                d = np.zeros((k, nv, 3), np.int8)
                for ki, key in enumerate(m.morphs[:k]):
                    n = min(nv, len(key.deltas))
                    d[ki, :n] = key.deltas[:n]
                morph_l.append(d)
                for c in chunks:
                    assert c.uv is not None and c.normals is not None  # not a shadow chunk
                    mats_l.append(np.full(c.n_vertices, g.material, np.int64))
                    pos_l.append(c.positions)
                    nrm_l.append(c.normals)
                    uv_l.append(c.uv)
                    strips.append(c.strip_lengths)
                    nvs.append(c.n_vertices)
                    ref_base.append(nref)
            nref += len(lk.refs)
    if not pos_l:
        return None
    a = SSX_TO_PISTE.astype(np.float32)
    raw_pos = np.concatenate(pos_l)
    uv_raw = np.concatenate(uv_l)
    slots = (uv_raw[:, 2].astype(np.int64) - SLOT_TRANSFORM_BASE) // 4
    pidx = np.concatenate(refs_cat)[np.repeat(np.asarray(ref_base, np.int64), nvs) + slots]
    tris = strip_triangles(np.concatenate(strips))
    p0, p1, p2 = raw_pos[tris[:, 0]], raw_pos[tris[:, 1]], raw_pos[tris[:, 2]]
    tris = tris[~((p0 == p1).all(1) | (p1 == p2).all(1) | (p0 == p2).all(1))]  # degenerate
    pos = (raw_pos @ a.T) * np.float32(CM)
    nrm = (np.concatenate(nrm_l).astype(np.float32) / np.float32(NORMAL_SCALE)) @ a.T
    uv = uv_raw[:, :2].astype(np.float32) / np.float32(UV_SCALE)
    morph = np.concatenate(morph_l, axis=1).astype(np.float32) @ a.T * np.float32(CM / MORPH_SCALE)
    mats = np.concatenate(mats_l)
    if weld and len(pos):
        first, inv = _weld(np.concatenate([pos, nrm, uv, pidx[:, None].astype(np.float32), mats[:, None].astype(np.float32),
                                           morph.transpose(1, 0, 2).reshape(len(pos), -1)], axis=1))
        pos, nrm, uv, pidx, morph, mats = pos[first], nrm[first], uv[first], pidx[first], morph[:, first], mats[first]
        tris = inv[tris]
        keep = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2])
        tris = tris[keep]
    ln = np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = np.where(ln > 0, nrm / np.maximum(ln, 1e-12), np.array([0, 1, 0], np.float32))
    return pos, nrm, uv, pidx, tris, morph, mats


def _mesh_from(name: str, arrays: tuple[np.ndarray, ...], pal_bones: np.ndarray, pal_pct: np.ndarray,
               morph_names: list[str]) -> SkinnedMesh:
    pos, nrm, uv, pidx, tris, morph = arrays[:6]
    bones, pct = pal_bones[pidx], pal_pct[pidx]
    order = np.argsort(-pct, axis=1, kind="stable")[:, :4]
    j = np.take_along_axis(bones, order, 1)
    w = np.take_along_axis(pct, order, 1).astype(np.float32)
    w /= np.maximum(w.sum(1, keepdims=True), 1)
    j = np.where(w > 0, j, 0)
    if j.shape[1] < 4:
        j = np.pad(j, ((0, 0), (0, 4 - j.shape[1])))
        w = np.pad(w, ((0, 0), (0, 4 - w.shape[1])))
    return SkinnedMesh(name=name, positions=pos, indices=tris, normals=nrm, uv=uv, joints=j, weights=w,
                       morph_positions=morph, morph_names=morph_names, skinned=True, group=name)


def _file_palette(pal_bones: np.ndarray, pal_pct: np.ndarray, pidx: np.ndarray) -> Palette:
    """A piste :class:`Palette` of the file's own palettes (entries used by ``pidx``)."""
    used, index = np.unique(pidx, return_inverse=True)
    b, p = pal_bones[used], pal_pct[used]
    nz = p[p > 0]
    g = 100
    for x in np.unique(nz):
        g = gcd(g, int(x))
    # canonical slot order: used slots by ascending bone, unused last with bone 0 (as palette() does)
    key = np.where(p > 0, b, np.iinfo(np.int64).max)
    o = np.argsort(key, axis=1, kind="stable")
    b, p = np.take_along_axis(b, o, 1), np.take_along_axis(p, o, 1)
    b = np.where(p > 0, b, 0)
    return Palette(bones=b.astype(np.int32), weights=(p / 100.0).astype(np.float32),
                   units=(p // g).astype(np.int32), index=index.astype(np.int32).reshape(-1), step=g / 100.0,
                   max_bones=int(b.shape[1]))


def mpf_to_model(*files: _MpfFile, name: str | None = None, weld: bool = True) -> SsxModel:
    """Decode ``.mpf`` files (a body file and optionally its head file) into an :class:`SsxModel`.

    ``meshes``: one :class:`SkinnedMesh` per sub-model of the top LOD tier (``...3000``, or all
    non-shadow sub-models without a tier), joints/weights from the palettes (at most 4 a vertex,
    from integer percent), morph targets from the morph keys (metres), vertices that are
    identical in every attribute welded (``weld``). ``lods``: one LOD per tier present, its mesh
    the tier's sub-models merged and its palette the file's own palettes.
    """
    if not files:
        raise ConfigError("mpf_to_model needs at least one MpfFile")
    notes: list = []
    sk, base, order = _skeleton(list(files), notes)
    counts: dict[int, int] = {}
    for f in files:
        for s in f.models:
            if len(s.bones):
                counts.setdefault(s.file_id, len(s.bones))
    if sk is None:
        raise ValidationError("the .mpf files hold no bones: not a rider model")
    assert order is not None  # None only without bones (sk is None)
    new_index = np.empty(len(order), np.int64)
    new_index[order] = np.arange(len(order))
    tiers: dict = {}
    for f in files:
        for s in f.models:
            t = _tier(s.name)
            if t is not None:
                tiers.setdefault(t, []).append(s)
    ordered = [t for t in LOD_TIERS if t in tiers] + ([""] if "" in tiers else [])
    if not ordered:
        raise ValidationError("the .mpf files hold no render sub-models")
    lods: list[LOD] = []
    top_meshes: list[SkinnedMesh] = []
    mat_of: dict[tuple[str, int], int] = {}
    lod_mats: list[np.ndarray] = []
    top_mats: list[np.ndarray] = []  # (texture id, index) per distinct material
    for li, t in enumerate(ordered):
        subs = tiers[t]
        meshes: list[SkinnedMesh] = []
        pidx_all: list[np.ndarray] = []
        vmats: list[np.ndarray] = []
        off = 0
        bones_all: list[np.ndarray] = []
        pct_all: list[np.ndarray] = []
        for s in subs:
            pb, pp = _palette_tables(s, base, new_index, counts)
            arrays = _decode_sub(s, pb, pp, weld)
            if arrays is None:
                continue
            mnames = [f"{s.name}.morph{i}" for i in range(s.morph_keys)]
            meshes.append(_mesh_from(s.name, arrays, pb, pp, mnames))
            ids = [_texture_id(s, int(mi)) for mi in range(max(int(arrays[6].max(initial=0)) + 1, 0))]
            lut = np.array([mat_of.setdefault((tid, mi), len(mat_of)) for mi, tid in enumerate(ids)], np.int32)
            vmats.append(lut[arrays[6]])
            bones_all.append(pb)
            pct_all.append(pp)
            pidx_all.append(arrays[3] + off)
            off += len(pb)
        if not meshes:
            continue
        kmax = max(b.shape[1] for b in bones_all)
        pb = np.concatenate([np.pad(b, ((0, 0), (0, kmax - b.shape[1]))) for b in bones_all])
        pp = np.concatenate([np.pad(p, ((0, 0), (0, kmax - p.shape[1]))) for p in pct_all])
        pal = _file_palette(pb, pp, np.concatenate(pidx_all))
        merged = _merge(f"{name or 'mpf'}/{t or 'lod'}", meshes)
        lods.append(LOD(_LOD_NAMES[li] if li < 3 else f"lod{li}", merged, pal, 1.0, float(pal.step), 0.0))
        lod_mats.append(np.concatenate(vmats))
        if not top_meshes:
            top_meshes, top_mats = meshes, vmats
    n0 = max(lods[0].n_triangles, 1)
    for lod in lods:
        lod.ratio = lod.n_triangles / n0
    nm = name or (files[0].path and str(files[0].path).rsplit("/", 1)[-1].rsplit(".", 1)[0]) or "mpf"
    materials = sorted(mat_of, key=lambda m: mat_of[m])
    return SsxModel(name=nm, skeleton=sk, meshes=top_meshes, lods=lods, notes=notes, files=list(files),
                    path=files[0].path, materials=materials, mesh_materials=top_mats, lod_materials=lod_mats)


def _texture_id(sub: _SubModel, i: int) -> str:
    """The main texture id (4 characters, e.g. ``suit``) of material ``i`` of ``sub`` ("" when
    the slot is empty or the index is past the material records)."""
    if not 0 <= i < len(sub.materials):
        return ""
    raw = bytes(sub.materials["textures"][i, 0])
    return raw.split(b"\0", 1)[0].decode("ascii", "replace").strip()


def _merge(name: str, meshes: list[SkinnedMesh]) -> SkinnedMesh:
    if len(meshes) == 1:
        m = meshes[0]
        return SkinnedMesh(name=name, positions=m.positions, indices=m.indices, normals=m.normals, uv=m.uv,
                           joints=m.joints, weights=m.weights, morph_positions=m.morph_positions,
                           morph_names=m.morph_names, skinned=True, group=name)
    off = np.cumsum([0] + [m.n_vertices for m in meshes])[:-1]
    names = list(dict.fromkeys(n for m in meshes for n in m.morph_names))  # e.g. Body3000.morph0, Head3000.morph0
    morph = None
    if names:  # each target's deltas on its own sub-model's vertices, zeros elsewhere
        morph = np.zeros((len(names), sum(m.n_vertices for m in meshes), 3), np.float32)
        for m, o in zip(meshes, off):
            for j, n in enumerate(m.morph_names):
                morph[names.index(n), o:o + m.n_vertices] = m.morph_positions[j]
    return SkinnedMesh(name=name, positions=np.concatenate([m.positions for m in meshes]),
                       indices=np.concatenate([m.indices + o for m, o in zip(meshes, off)]),
                       normals=np.concatenate([m.normals for m in meshes]), uv=np.concatenate([m.uv for m in meshes]),
                       joints=np.concatenate([m.joints for m in meshes]),
                       weights=np.concatenate([m.weights for m in meshes]),
                       morph_positions=morph,  # type: ignore[arg-type]  # None: __post_init__ makes it empty
                       morph_names=names, skinned=True, group=name)


def _beside(path: Path, stem: str, suffix: str) -> Path | None:
    for suf in (suffix.lower(), suffix.upper()):
        q = path.with_name(stem + suf)
        if q.is_file():
            return q
    return None


def mpf_partners(path: str | os.PathLike[str],
                 texture: str | Path | Sequence[str | os.PathLike[str]] | None = None) -> tuple:
    """The files that go with the rider model ``path``: ``(head, banks)``. ``head``: the
    ``<name>_head.mpf`` beside a ``<name>_body.mpf`` (None when absent or not a body file);
    ``banks``: ``texture`` (a path or a list of paths, as given) or else the ``.ssh`` banks with the
    same stem beside the model and its head file (``RIDER.ssh``, ``mac_body.ssh``, ``mac_head.ssh``)."""
    path = Path(path)
    stem, head = path.stem, None
    if stem.lower().endswith("_body"):
        head = _beside(path, stem[:-5] + ("_HEAD" if stem.endswith("_BODY") else "_head"), path.suffix)
    if texture is not None:
        banks = [Path(t) for t in ([texture] if isinstance(texture, (str, Path)) else texture)]
    else:
        banks = [b for b in (_beside(path, stem, ".ssh"), head and _beside(head, head.stem, ".ssh")) if b is not None]
    return head, banks
