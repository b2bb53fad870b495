"""SSX Tricky rider models (``.mpf``) <-> piste's character :class:`~piste.character.Model`.

The format layer builds the character data classes (as :mod:`piste.formats.gltf` does); the bytes
live in :mod:`piste.formats.ssx.mpf`, which imports nothing from the character package. (So there
is no ``MpfFile.to_model`` method: it would make the byte module import this one, which imports it
back; ``mpf_to_model(mpf)`` is that method.)

``mpf_to_model(*files)`` turns one or more read ``.mpf`` files (a body file, optionally its head
file: bones parent across files by file id) into an :class:`SsxModel`: a :class:`Model` whose
skeleton comes from the bone records, whose meshes are the top LOD's sub-models (``Body3000``,
``Head3000``, ...) with joints and weights from the file's weight palettes and morph targets from
its morph keys, plus ``lods`` (one :class:`~piste.character.LOD` per LOD tier ``3000`` / ``1500``
/ ``750``, each carrying **the file's own palettes** as its blended-matrix palette).

``model_to_mpf(model)`` is the reverse: a piste rider (the default rider or a skinned glTF) as a
body ``.mpf`` the game's limits allow (<= 55 vertices a chunk, <= 25 palette matrices a link,
weights in 25 % steps, at most 3 bones a vertex), with a report of what was quantised and the
resulting error.

Frames and units (piste's assumptions where the facts are silent)
-----------------------------------------------------------------
* The file is centimetres, Z up (SSX's world convention; the board deck lies along X); piste's
  models are metres, +Y up. ``p_piste = A p_ssx / 100`` with ``A`` mapping SSX ``(x, y, z)`` to
  piste ``(x, z, -y)``; rotations are conjugated by ``A``.
* A bone's bind rotation triple ``(rx, ry, rz)`` is read as ``R = Rz(rz) Ry(ry) Rx(rx)`` (x first).
  The facts say only "Euler XYZ, radians": this is piste's reading, and the encoder writes the same.
* Bone records written by the encoder: channel flags 3 (animated translation + rotation) for
  roots, 2 (rotation) for the others; mirror partner by ``_l``/``_r`` (``l_``/``r_``, ``Left``/
  ``Right``) name swap; mirror rotation offset ``(0, 0, pi)`` on roots, 0 elsewhere; mirror scales
  ``(1, -1, -1)`` rotation and ``(1, -1, 1)`` translation (the rider root's values in the facts).
* Morph-key triangles (any vertex that moves in a morph target) go to group type 256, one chunk
  per mesh header so the deltas are parallel to that chunk; the rest to type-1 render groups.
* Materials: one record (``suit``), blend 0, the two unread floats 1/255. Textures live in the
  character ``.ssh`` banks, not in the ``.mpf``; decoded models have none (``texture=None``).

API
---
mpf_to_model(*files, name=None) -> SsxModel
model_to_mpf(model, ratios=(1, .5, .25), step=0.25, max_bones=3, pose_time=None) -> (MpfFile, report)
SsxModel: Model + ``lods``, ``notes``
euler_to_matrix / matrix_to_euler, SSX_TO_PISTE
"""

from __future__ import annotations

from dataclasses import dataclass, field
from math import gcd

import numpy as np

from piste.character.lod import LOD, make_lods
from piste.character.model import Model, Skeleton, SkinnedMesh
from piste.character.palette import Palette
from piste.character.skinning import BlendedMesh, skin_exact
from piste.character.strips import stripify
from piste.errors import ConfigError, ValidationError
from piste.formats.ssx.mpf import (
    BONE_DTYPE, GROUP_MORPH, GROUP_RENDER, GROUP_SHADOW, MATERIAL_DTYPE, MAX_CHUNK_VERTICES, MAX_GROUP_MATRICES,
    MORPH_SCALE, NORMAL_SCALE, PALETTE_ENTRY_DTYPE, SLOT_NORMAL_BASE, SLOT_TRANSFORM_BASE, UV_SCALE, Group, Link,
    Mesh, MorphKey, MpfFile, SubModel, pack_chunks, strip_triangles,
)
from piste.transforms import compose_trs, invert_affine, matrix_to_quat

__all__ = ["SsxModel", "mpf_to_model", "model_to_mpf", "euler_to_matrix", "matrix_to_euler", "SSX_TO_PISTE",
           "LOD_TIERS"]

#: SSX (x, y, z) -> piste (x, z, -y)
SSX_TO_PISTE = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
CM = 0.01
LOD_TIERS = ("3000", "1500", "750")
_LOD_NAMES = ("high", "medium", "low")


@dataclass
class SsxModel(Model):
    """A :class:`Model` decoded from ``.mpf`` files: ``lods`` (:class:`LOD` per tier, the file's
    palettes), ``notes`` (what could not be represented), ``files`` (the MpfFile objects)."""

    lods: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    files: list = field(default_factory=list)


# ----------------------------------------------------------------------------------- rotations
def euler_to_matrix(e) -> np.ndarray:
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


def matrix_to_euler(m) -> np.ndarray:
    """Inverse of :func:`euler_to_matrix`: ``(..., 3, 3)`` -> ``(..., 3)`` radians."""
    m = np.asarray(m, np.float64)
    y = np.arcsin(np.clip(-m[..., 2, 0], -1.0, 1.0))
    x = np.arctan2(m[..., 2, 1], m[..., 2, 2])
    z = np.arctan2(m[..., 1, 0], m[..., 0, 0])
    gimbal = np.abs(m[..., 2, 0]) > 1.0 - 1e-9
    x = np.where(gimbal, np.arctan2(-m[..., 1, 2], m[..., 1, 1]), x)
    z = np.where(gimbal, 0.0, z)
    return np.stack([x, y, z], -1)


def _mirror_name(name: str) -> str:
    for a, b in (("_l", "_r"), ("_L", "_R"), ("Left", "Right")):
        if name.endswith(a):
            return name[: -len(a)] + b
        if name.endswith(b):
            return name[: -len(b)] + a
    for a, b in (("l_", "r_"), ("L_", "R_"), ("Left", "Right")):
        if name.startswith(a):
            return b + name[len(a):]
        if name.startswith(b):
            return a + name[len(b):]
    return name


# ------------------------------------------------------------------------------- mpf -> model
def _tier(name: str) -> str | None:
    if "shdw" in name.lower():
        return None
    for t in LOD_TIERS:
        if name.endswith(t):
            return t
    return ""


def _skeleton(files: list, notes: list):
    """Merged skeleton of the files: ``(Skeleton, base {file id: first global index}, order)``."""
    source = {}
    for f in files:
        for s in f.models:
            if len(s.bones) and s.file_id not in source:
                source[s.file_id] = s
    base, names, parents, t, r = {}, [], [], [], []
    for fid, s in source.items():
        base[fid] = len(names)
        names += [f"{n}" if f"{n}" not in names else f"{n}.{fid}" for n in s.bone_names]
    for fid, s in source.items():
        for b in s.bones:
            pf, pb = int(b["parent_file"]), int(b["parent_bone"])
            if pb < 0 or pf < 0:
                parents.append(-1)
            elif pf not in base or pb >= len(source[pf].bones):
                notes.append(f"bone {bytes(b['name']).decode('ascii', 'replace')!r}: parent (file {pf}, bone {pb}) "
                             f"is not in the files given; made a root")
                parents.append(-1)
            else:
                parents.append(base[pf] + pb)
            t.append(b["translation"])
            r.append(b["rotation"])
    if not names:
        return None, base, None
    a = SSX_TO_PISTE
    t = (np.asarray(t, np.float64) @ a.T) * CM
    rm = a @ euler_to_matrix(np.asarray(r, np.float64)) @ a.T
    q = matrix_to_quat(rm)
    n = len(names)
    local = compose_trs(t, q, np.ones((n, 3)))
    parents = np.asarray(parents, np.int64)
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


def _palette_tables(sub: SubModel, base: dict, new_index: np.ndarray):
    """The sub-model's palettes as ``bones (p, k) int64`` (skeleton indices), ``percent (p, k)``."""
    k = max([len(p) for p in sub.palettes] + [1])
    bones = np.zeros((len(sub.palettes), k), np.int64)
    pct = np.zeros((len(sub.palettes), k), np.int64)
    for i, p in enumerate(sub.palettes):
        for j, e in enumerate(p):
            f = int(e["file"])
            if f not in base:
                raise ValidationError(f"{sub.name}: palette {i} names bone {int(e['bone'])} of file id {f}, which "
                                      f"is not among the files given (pass the matching body/head file too)")
            bones[i, j] = new_index[base[f] + int(e["bone"])]
            pct[i, j] = int(e["weight"])
    return bones, pct


def _weld(key: np.ndarray):
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


def _decode_sub(sub: SubModel, pal_bones, pal_pct, weld: bool):
    """Arrays of one sub-model's render and morph groups (shadow groups skipped); the chunks are
    gathered first and decoded in one vectorised pass (strips -> triangles, slots -> palettes)."""
    pos, nrm, uv, refs_cat, ref_base, nvs, strips, morph = [], [], [], [], [], [], [], []
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
                morph.append(d)
                for c in chunks:
                    pos.append(c.positions)
                    nrm.append(c.normals)
                    uv.append(c.uv)
                    strips.append(c.strip_lengths)
                    nvs.append(c.n_vertices)
                    ref_base.append(nref)
            nref += len(lk.refs)
    if not pos:
        return None
    a = SSX_TO_PISTE.astype(np.float32)
    raw_pos = np.concatenate(pos)
    uv_raw = np.concatenate(uv)
    slots = (uv_raw[:, 2].astype(np.int64) - SLOT_TRANSFORM_BASE) // 4
    pidx = np.concatenate(refs_cat)[np.repeat(np.asarray(ref_base, np.int64), nvs) + slots]
    tris = strip_triangles(np.concatenate(strips))
    p0, p1, p2 = raw_pos[tris[:, 0]], raw_pos[tris[:, 1]], raw_pos[tris[:, 2]]
    tris = tris[~((p0 == p1).all(1) | (p1 == p2).all(1) | (p0 == p2).all(1))]  # degenerate
    pos = (raw_pos @ a.T) * np.float32(CM)
    nrm = (np.concatenate(nrm).astype(np.float32) / np.float32(NORMAL_SCALE)) @ a.T
    uv = uv_raw[:, :2].astype(np.float32) / np.float32(UV_SCALE)
    morph = np.concatenate(morph, axis=1).astype(np.float32) @ a.T * np.float32(CM / MORPH_SCALE)
    if weld and len(pos):
        first, inv = _weld(np.concatenate([pos, nrm, uv, pidx[:, None].astype(np.float32),
                                           morph.transpose(1, 0, 2).reshape(len(pos), -1)], axis=1))
        pos, nrm, uv, pidx, morph = pos[first], nrm[first], uv[first], pidx[first], morph[:, first]
        tris = inv[tris]
        keep = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2])
        tris = tris[keep]
    ln = np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = np.where(ln > 0, nrm / np.maximum(ln, 1e-12), np.array([0, 1, 0], np.float32))
    return pos, nrm, uv, pidx, tris, morph


def _mesh_from(name, arrays, pal_bones, pal_pct, morph_names):
    pos, nrm, uv, pidx, tris, morph = arrays
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


def _file_palette(pal_bones, pal_pct, pidx) -> Palette:
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


def mpf_to_model(*files: MpfFile, name: str | None = None, weld: bool = True) -> SsxModel:
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
    if sk is None:
        raise ValidationError("the .mpf files hold no bones: not a rider model")
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
    lods, top_meshes = [], []
    for li, t in enumerate(ordered):
        subs = tiers[t]
        meshes, pals, pidx_all, off = [], [], [], 0
        bones_all, pct_all = [], []
        for s in subs:
            pb, pp = _palette_tables(s, base, new_index)
            arrays = _decode_sub(s, pb, pp, weld)
            if arrays is None:
                continue
            mnames = [f"{s.name}.morph{i}" for i in range(s.morph_keys)]
            meshes.append(_mesh_from(s.name, arrays, pb, pp, mnames))
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
        if not top_meshes:
            top_meshes = meshes
    n0 = max(lods[0].n_triangles, 1)
    for lod in lods:
        lod.ratio = lod.n_triangles / n0
    nm = name or (files[0].path and str(files[0].path).rsplit("/", 1)[-1].rsplit(".", 1)[0]) or "mpf"
    return SsxModel(name=nm, skeleton=sk, meshes=top_meshes, lods=lods, notes=notes, files=list(files),
                    path=files[0].path)


def _merge(name, meshes):
    if len(meshes) == 1:
        m = meshes[0]
        return SkinnedMesh(name=name, positions=m.positions, indices=m.indices, normals=m.normals, uv=m.uv,
                           joints=m.joints, weights=m.weights, morph_positions=m.morph_positions,
                           morph_names=m.morph_names, skinned=True, group=name)
    off = np.cumsum([0] + [m.n_vertices for m in meshes])[:-1]
    return SkinnedMesh(name=name, positions=np.concatenate([m.positions for m in meshes]),
                       indices=np.concatenate([m.indices + o for m, o in zip(meshes, off)]),
                       normals=np.concatenate([m.normals for m in meshes]), uv=np.concatenate([m.uv for m in meshes]),
                       joints=np.concatenate([m.joints for m in meshes]),
                       weights=np.concatenate([m.weights for m in meshes]), skinned=True, group=name)


# ------------------------------------------------------------------------------- model -> mpf
def _merged_source(model) -> SkinnedMesh:
    meshes = [m for m in model.meshes if m.skinned] or list(model.meshes)
    if not meshes:
        raise ConfigError(f"model {model.name!r} has no meshes")
    if len(meshes) == 1:
        return meshes[0]
    ks = {m.n_morphs for m in meshes}
    off = np.cumsum([0] + [m.n_vertices for m in meshes])[:-1]
    morph = None
    if len(ks) == 1 and ks != {0}:
        morph = np.concatenate([m.morph_positions for m in meshes], axis=1)
    return SkinnedMesh(name=model.name, positions=np.concatenate([m.positions for m in meshes]),
                       indices=np.concatenate([m.indices + o for m, o in zip(meshes, off)]),
                       normals=np.concatenate([m.normals for m in meshes]), uv=np.concatenate([m.uv for m in meshes]),
                       joints=np.concatenate([m.joints for m in meshes]),
                       weights=np.concatenate([m.weights for m in meshes]), morph_positions=morph,
                       morph_names=meshes[0].morph_names if morph is not None else [], skinned=True, group=model.name)


def _bone_records(sk: Skeleton, file_id: int, report: dict) -> np.ndarray:
    if sk.n_bones > 255:
        raise ConfigError(f"an .mpf palette entry names its bone in one byte: at most 255 bones, got {sk.n_bones}")
    bind_world = invert_affine(sk.inverse_bind)
    par = sk.parents
    local = bind_world.copy()
    has = par >= 0
    local[has] = invert_affine(bind_world[par[has]]) @ bind_world[has]
    lin = local[:, :3, :3]
    u, s, vt = np.linalg.svd(lin)
    rot = u @ vt
    report["bone_scale_dropped"] = float(np.abs(s - 1.0).max()) if len(s) else 0.0
    a = SSX_TO_PISTE.T  # piste -> SSX
    t = (local[:, :3, 3] @ a.T) / CM
    e = matrix_to_euler(a @ rot @ a.T)
    b = np.zeros(sk.n_bones, BONE_DTYPE)
    names, renamed = [], {}
    for i, n in enumerate(sk.names):
        enc = n.encode("ascii", "replace")
        if len(enc) > 16:  # an .mpf bone name holds 16 characters: shorten, keep names unique
            enc = enc[:16]
            k = 0
            while enc in names or any(enc == x.encode("ascii", "replace") for x in sk.names[i + 1:]):
                k += 1
                enc = enc[:16 - len(str(k)) - 1] + b"~" + str(k).encode()
            renamed[n] = enc.decode("ascii")
        names.append(enc)
    report["renamed_bones"] = renamed
    b["name"] = names
    b["parent_file"] = np.where(has, file_id, -1)
    b["parent_bone"] = np.where(has, par, -1)
    b["flags"] = np.where(has, 2, 3)
    idx = {n: i for i, n in enumerate(sk.names)}
    b["mirror"] = [idx.get(_mirror_name(n), i) for i, n in enumerate(sk.names)]
    b["translation"] = t
    b["rotation"] = e
    b["mirror_offset"] = np.where(has[:, None], 0.0, [0.0, 0.0, np.pi])
    b["mirror_scale"] = [1.0, -1.0, -1.0, 1.0, -1.0, 1.0]
    return b


def _links(tri_pal: list, cap: int) -> list:
    """Greedy partition of triangles (each a set of palette entries) into links of <= ``cap``
    entries; triangles visited sorted by their entry tuple so neighbours in weight share links."""
    order = sorted(range(len(tri_pal)), key=lambda i: tri_pal[i])
    out, cur, entries = [], [], set()
    for i in order:
        s = entries.union(tri_pal[i])
        if len(s) > cap and cur:
            out.append((cur, sorted(entries)))
            cur, s = [], set(tri_pal[i])
        cur.append(i)
        entries = s
    if cur:
        out.append((cur, sorted(entries)))
    return out


def _encode_lod(name, mesh, pal, file_id, step, morph_keys, report, shadow: bool = False) -> SubModel:
    a = SSX_TO_PISTE.T
    pos = (mesh.positions.astype(np.float64) @ a.T / CM).astype("<f4")
    nrm = mesh.normals.astype(np.float64) @ a.T
    nrm_i = np.clip(np.round(nrm * NORMAL_SCALE), -32768, 32767).astype("<i2")
    uvs = np.round(mesh.uv.astype(np.float64) * UV_SCALE)
    report["uv_clipped"] += int(np.count_nonzero((uvs < -32768) | (uvs > 32767)))
    uv_i = np.zeros((mesh.n_vertices, 4), "<i2")
    uv_i[:, :2] = np.clip(uvs, -32768, 32767)
    pct = int(round(step * 100))
    palettes = []
    for bb, uu in zip(pal.bones, pal.units):
        ent = [(int(u) * pct, int(b_), file_id) for b_, u in zip(bb, uu) if u > 0]
        palettes.append(np.array(ent, PALETTE_ENTRY_DTYPE))
    tris = mesh.indices.astype(np.int64)
    tri_pal = [tuple(sorted(set(x))) for x in pal.index[tris].tolist()]
    if morph_keys and not shadow:
        d = mesh.morph_positions.astype(np.float64) @ a.T / CM * MORPH_SCALE  # (k, v, 3) stored units
        di = np.round(d)
        report["morph_clipped"] += int(np.count_nonzero(np.abs(di) > 127))
        di = np.clip(di, -128, 127)
        err = np.abs(di - d).max() / MORPH_SCALE * CM if d.size else 0.0
        report["morph_max_error_m"] = max(report["morph_max_error_m"], float(err))
        moves = np.any(di != 0, axis=(0, 2))
        is_morph = moves[tris].any(1)
    else:
        di = None
        is_morph = np.zeros(len(tris), bool)
    groups = []
    kinds = ((GROUP_SHADOW, np.ones(len(tris), bool)),) if shadow else \
        ((GROUP_RENDER, ~is_morph), (GROUP_MORPH, is_morph))
    for gtype, sel in kinds:
        ids = np.nonzero(sel)[0]
        if ids.size == 0:
            continue
        links = []
        for members, entries in _links([tri_pal[i] for i in ids], MAX_GROUP_MATRICES):
            slot_of = np.full(pal.size, -1, np.int64)
            slot_of[entries] = np.arange(len(entries))
            uv_l = uv_i.copy()
            s = slot_of[pal.index]
            uv_l[:, 2] = np.where(s >= 0, SLOT_TRANSFORM_BASE + 4 * s, 0)
            uv_l[:, 3] = np.where(s >= 0, SLOT_NORMAL_BASE + 3 * s, 0)
            strips = stripify(tris[ids[members]], join=None)
            if shadow:  # positions + a per-vertex transform address, no UV or normal section
                chunks, index = pack_chunks(strips, None, None, pos, MAX_CHUNK_VERTICES,
                                            shadow_slots=uv_l[:, 2].astype("<u4"), return_index=True)
            else:
                chunks, index = pack_chunks(strips, uv_l, nrm_i, pos, MAX_CHUNK_VERTICES, return_index=True)
            if gtype == GROUP_MORPH:
                meshes = [Mesh([c], morphs=[MorphKey(deltas=di[k][ix].astype("i1")) for k in range(morph_keys)])
                          for c, ix in zip(chunks, index)]
            else:
                meshes = [Mesh(chunks)]
            links.append(Link(meshes, np.array(entries, "<u4")))
            report["max_link_matrices"] = max(report["max_link_matrices"], len(entries))
            report["max_chunk_vertices"] = max(report["max_chunk_vertices"], max(c.n_vertices for c in chunks))
        groups.append(Group(gtype, 0, links))
    mat = np.zeros(1, MATERIAL_DTYPE)
    mat["textures"][0, 0] = np.void(b"suit")
    mat["unused"] = 1.0 / 255.0
    return SubModel(name=name, file_id=file_id, materials=mat, groups=groups, palettes=palettes,
                    morph_keys=morph_keys if is_morph.any() else 0)


def model_to_mpf(model, ratios=(1.0, 0.5, 0.25), names=("Body3000", "Body1500", "Body750"), step: float = 0.25,
                 max_bones: int = 3, file_id: int = 0, pose_time: float | None = None, clip: str | None = None,
                 shadow: str | None = "BodyShdw750"):
    """Encode a piste rider as an SSX Tricky body ``.mpf``: ``(MpfFile, report)``.

    Each LOD (``ratios`` of the triangles, :func:`make_lods`) becomes a sub-model named from
    ``names``; weights are quantised to ``step`` (25 %: the game's steps) with at most
    ``max_bones`` bones; triangles are partitioned into links of at most 25 palette matrices and
    their strips cut into chunks of at most 55 vertices. ``shadow``: the name of a shadow
    sub-model (group type 17, positions and transform addresses only) made from the last LOD, or
    None for none.

    ``report``: ``lods`` (triangles, stored vertices, chunks, links, palette size per LOD),
    ``weights_changed`` (vertices whose weights moved), ``max_weight_error``,
    ``max_bind_error_m`` (position round trip), ``max_pose_error_m`` (file palettes vs exact
    skinning with the original weights at ``pose_time`` of ``clip``, default: mid first clip),
    ``morph_max_error_m``, ``morph_clipped``, ``uv_clipped``, ``max_link_matrices``,
    ``max_chunk_vertices``, ``bone_scale_dropped`` (largest bind-matrix scale departure from 1,
    which the file cannot hold), ``renamed_bones`` (names longer than 16 characters, shortened).
    """
    sk = model.skeleton
    if sk is None:
        raise ConfigError(f"model {model.name!r} has no skeleton: an .mpf rider needs a skinned model")
    if len(names) < len(ratios):
        raise ConfigError(f"need a sub-model name per LOD ratio, got {len(names)} names for {len(ratios)} ratios")
    report = {"uv_clipped": 0, "morph_clipped": 0, "morph_max_error_m": 0.0, "max_link_matrices": 0,
              "max_chunk_vertices": 0, "lods": []}
    bones = _bone_records(sk, file_id, report)
    mesh = _merged_source(model)
    if int(mesh.joints.max(initial=0)) >= sk.n_bones:
        raise ValidationError(f"mesh joints reach bone {int(mesh.joints.max())} of a {sk.n_bones}-bone skeleton")
    lods = make_lods(mesh, ratios=ratios, steps=step, max_bones=max_bones)
    # pose for the error figure
    if clip is None and model.clips:
        clip = next(iter(model.clips))
    pose = None
    if clip is not None:
        c = model.clips[clip]
        pose = c.sample(c.duration / 2 if pose_time is None else pose_time, skeleton=sk)
    skin_m = sk.skin_matrices(pose)
    subs, wchg, werr, berr, perr = [], 0, 0.0, 0.0, 0.0
    for nm, lod in zip(names, lods):
        m, pal = lod.mesh, lod.palette
        sub = _encode_lod(nm, m, pal, file_id, step, m.n_morphs, report)
        sub.bones = bones.copy()
        subs.append(sub)
        # weights: dense original vs quantised
        v = m.n_vertices
        dense = np.zeros((v, sk.n_bones))
        np.add.at(dense, (np.repeat(np.arange(v), 4), m.joints.reshape(-1).astype(np.int64)), m.weights.reshape(-1))
        dense /= np.maximum(dense.sum(1, keepdims=True), 1e-12)
        qb, qw = pal.vertex_weights()
        qd = np.zeros_like(dense)
        np.add.at(qd, (np.repeat(np.arange(v), qb.shape[1]), qb.reshape(-1)), qw.reshape(-1))
        diff = np.abs(qd - dense).max(1)
        wchg += int(np.count_nonzero(diff > 1e-6))
        werr = max(werr, float(diff.max(initial=0.0)))
        a = SSX_TO_PISTE.T
        back = ((m.positions.astype(np.float64) @ a.T / CM).astype(np.float32).astype(np.float64) / 100.0) @ a
        berr = max(berr, float(np.abs(back - m.positions).max(initial=0.0)))
        ref, _ = skin_exact(m, skin_m)
        got, _ = BlendedMesh(pal, back.astype(np.float32), m.normals).apply(skin_m)
        perr = max(perr, float(np.linalg.norm(got - ref, axis=1).max(initial=0.0)))
        chunks = [c for lk in sub.links for me in lk.meshes for c in me.chunks]
        report["lods"].append({"name": nm, "triangles": int(m.n_triangles), "palette": int(pal.size),
                               "links": len(sub.links), "chunks": len(chunks),
                               "stored_vertices": int(sum(c.n_vertices for c in chunks)),
                               "morph_keys": int(sub.morph_keys)})
    report.update(weights_changed=wchg, max_weight_error=werr, max_bind_error_m=berr, max_pose_error_m=perr,
                  step=float(step), max_bones=int(max_bones), pose=f"{clip}@{pose_time if pose_time is not None else 'mid'}"
                  if clip else "bind")
    if shadow:
        sub = _encode_lod(shadow, lods[-1].mesh, lods[-1].palette, file_id, step, 0, report, shadow=True)
        sub.bones = bones.copy()
        subs.append(sub)
    return MpfFile(models=subs), report
