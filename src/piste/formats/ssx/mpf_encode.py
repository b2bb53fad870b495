"""The encoder: a piste rider (the default rider or a skinned glTF) as an SSX Tricky body ``.mpf``.

``model_to_mpf(model)`` -> ``(MpfFile, report)``: each LOD a sub-model (``Body3000`` /
``Body1500`` / ``Body750``) and a ``BodyShdw750`` shadow model, within the game's limits (<= 55
vertices a chunk, <= 25 palette matrices a link, weights in 25 % steps, at most 3 bones a vertex).

``model_to_mpf_pair(model)`` -> ``(body MpfFile, head MpfFile, report)``: the game's split of a rider
into ``<name>_body.mpf`` (file id 0: ``Body3000`` / ``1500`` / ``750`` + shadow) and
``<name>_head.mpf`` (file id 2: ``Head3000`` / ``1500`` / ``750``): the head bone's subtree goes to
the head file, its root parented onto a body bone by (file id 0, bone); each LOD's triangles whose
three vertices weigh at least half on head bones go to the head sub-model; palette entries name
their bone by (file id, bone in that file), across the two files where a vertex needs it.

``texture_bank(model)`` -> ``(SshBank, report)``: the rider's texture as the character texture bank
the game keeps beside the model (``RIDER.ssh``): one 8-bit indexed image (type 2, <= 256-colour
RGBA palette quantised with Pillow, stored half-bright) named for the material's main texture id
(``suit``), its sides powers of two of at most 256 texels (the sizes the game's banks use).
Frames, units and the bone-record conventions it writes are described in
:mod:`piste.formats.ssx.mpf_model` (they are what the decoder reads back).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from piste.character.lod import make_lods
from piste.character.model import Model, Skeleton, SkinnedMesh
from piste.character.palette import Palette
from piste.character.retarget import bone_roles
from piste.character.skinning import BlendedMesh, skin_exact
from piste.character.strips import stripify
from piste.errors import ConfigError, ValidationError
from piste.formats.ssx.mpf import (
    BONE_DTYPE, GROUP_MORPH, GROUP_RENDER, GROUP_SHADOW, MATERIAL_DTYPE, ENCODER_CHUNK_VERTICES, MAX_GROUP_MATRICES,
    MORPH_SCALE, NORMAL_SCALE, PALETTE_ENTRY_DTYPE, SLOT_NORMAL_BASE, SLOT_TRANSFORM_BASE, UV_SCALE, Group, Link,
    Mesh, MorphKey, MpfFile, SubModel, pack_chunks,
)
from piste.formats.ssx.mpf_model import CM, SSX_TO_PISTE, bone_euler
from piste.formats.ssx.ssh import SshBank, SshImage, half_bright
from piste.transforms import invert_affine

__all__ = ["model_to_mpf", "model_to_mpf_pair", "texture_bank", "MATERIAL_ID", "HEAD_FILE_ID"]

#: the file id of a rider's head file (OpenSlope spec 240: 0 body, 1 board, 2 head)
HEAD_FILE_ID = 2

#: the VU program a chunk whose vertices each follow one bone calls (MSCAL 10: all 48 such retail chunks
#: are single-bone; the other 97 retail render chunks call 0, 80 of them blending 2-3 bones)
RIGID_PROGRAM = 10

#: the main texture id of the one material the encoder writes (an image of that name in the bank)
MATERIAL_ID = "suit"


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


def _merged_source(model: Model) -> SkinnedMesh:
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
                       weights=np.concatenate([m.weights for m in meshes]),
                       morph_positions=morph,  # type: ignore[arg-type]  # None: __post_init__ makes it empty
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
    e = bone_euler(a @ rot @ a.T)
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
    out: list[tuple[list[int], list[int]]] = []
    cur: list[int] = []
    entries: set[int] = set()
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


def _encode_lod(name: str, mesh: SkinnedMesh, pal: Palette, file_id: int, step: float, morph_keys: int,
                report: dict[str, Any], shadow: bool = False, bone_ref: np.ndarray | None = None) -> SubModel:
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
    for bb, uu in zip(pal.bones, pal.units):  # bone_ref: skeleton bone -> (file id, bone in that file)
        ent = [(int(u) * pct, int(b_), file_id) if bone_ref is None else (int(u) * pct, int(bone_ref[b_][1]),
                                                                         int(bone_ref[b_][0]))
               for b_, u in zip(bb, uu) if u > 0]
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
                chunks, index = pack_chunks(strips, None, None, pos, ENCODER_CHUNK_VERTICES,
                                            shadow_slots=uv_l[:, 2].astype("<u4"), return_index=True)
            else:
                chunks, index = pack_chunks(strips, uv_l, nrm_i, pos, ENCODER_CHUNK_VERTICES, return_index=True)
                one = np.array([len(palettes[e]) == 1 for e in entries])
                for c in chunks:  # retail: every MSCAL 10 chunk skins each vertex with a single bone
                    c.program = RIGID_PROGRAM if one[np.unique(c.slots)].all() else 0
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
    mat["textures"][0, 0] = np.void(MATERIAL_ID.encode("ascii"))
    mat["unused"] = 1.0 / 255.0
    return SubModel(name=name, file_id=file_id, materials=mat, groups=groups, palettes=palettes,
                    morph_keys=morph_keys if is_morph.any() else 0)


def model_to_mpf(model: Model, ratios: Sequence[float] = (1.0, 0.5, 0.25),
                 names: Sequence[str] = ("Body3000", "Body1500", "Body750"), step: float = 0.25,
                 max_bones: int = 3, file_id: int = 0, pose_time: float | None = None, clip: str | None = None,
                 shadow: str | None = "BodyShdw750",
                 _split: tuple[list[int], tuple[str, ...], int] | None = None) -> tuple[Any, ...]:
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
    report: dict[str, Any] = {"uv_clipped": 0, "morph_clipped": 0, "morph_max_error_m": 0.0, "max_link_matrices": 0,
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
    head_subs, ref = [], None
    if _split is not None:
        head, head_names, head_id = _split
        if head_id == file_id:
            raise ConfigError(f"the head file needs a file id other than the body's ({file_id})")
        bones, head_rec, ref = _split_records(bones, sk, head, file_id, head_id)
        on_head = np.zeros(sk.n_bones, bool)
        on_head[head] = True
        report["split"] = {"head_bones": [sk.names[i] for i in head], "lods": []}
    for li, (nm, lod) in enumerate(zip(names, lods)):
        m, pal = lod.mesh, lod.palette
        if _split is None:
            sub = _encode_lod(nm, m, pal, file_id, step, m.n_morphs, report)
        else:  # triangles whose vertices weigh >= 1/2 on head bones go to the head file
            vh = (m.weights * on_head[m.joints.astype(np.int64)]).sum(1) >= 0.5
            th = vh[m.indices.astype(np.int64)].all(1)
            parts = []
            for mask in (~th, th):
                sm, vs = _submesh(m, mask)
                parts.append((sm, _subpalette(pal, vs)))
            (bm, bp), (hm, hp) = parts
            sub = _encode_lod(nm, bm, bp, file_id, step, bm.n_morphs, report, bone_ref=ref)
            hname = head_names[li] if li < len(head_names) else f"Head{li}"
            if hm.n_triangles:
                hs = _encode_lod(hname, hm, hp, head_id, step, hm.n_morphs, report, bone_ref=ref)
                hs.bones = head_rec.copy()
                head_subs.append(hs)
            report["split"]["lods"].append({"body": int(bm.n_triangles), "head": int(hm.n_triangles)})
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
        exact, _ = skin_exact(m, skin_m)
        got, _ = BlendedMesh(pal, back.astype(np.float32), m.normals).apply(skin_m)
        perr = max(perr, float(np.linalg.norm(got - exact, axis=1).max(initial=0.0)))
        chunks = [c for lk in sub.links for me in lk.meshes for c in me.chunks]
        if _split is not None and head_subs and head_subs[-1].name == hname:
            chunks += [c for lk in head_subs[-1].links for me in lk.meshes for c in me.chunks]
        report["lods"].append({"name": nm, "triangles": int(m.n_triangles), "palette": int(pal.size),
                               "links": len(sub.links), "chunks": len(chunks),
                               "stored_vertices": int(sum(c.n_vertices for c in chunks)),
                               "morph_keys": int(sub.morph_keys)})
    report.update(weights_changed=wchg, max_weight_error=werr, max_bind_error_m=berr, max_pose_error_m=perr,
                  step=float(step), max_bones=int(max_bones), pose=f"{clip}@{pose_time if pose_time is not None else 'mid'}"
                  if clip else "bind")
    if shadow:
        sub = _encode_lod(shadow, lods[-1].mesh, lods[-1].palette, file_id, step, 0, report, shadow=True,
                          bone_ref=ref)
        sub.bones = bones.copy()
        subs.append(sub)
    if _split is not None:
        return MpfFile(models=subs), MpfFile(models=head_subs), report
    return MpfFile(models=subs), report


def _pow2(n: int, cap: int) -> int:
    p = 8
    while p < n and p < cap:
        p *= 2
    return p


def texture_bank(model: Model, name: str = MATERIAL_ID, max_size: int = 256) -> tuple[SshBank | None, dict[str, Any]]:
    """The rider's texture as an ``.ssh`` bank: ``(SshBank, report)``, or ``(None, report)`` when
    no mesh has a texture. The first textured mesh's texture is used (a model whose primitives
    carry different textures keeps only that one: ``report['note']`` says so); it is resized to
    power-of-two sides of at most ``max_size``, stored half-bright (:func:`half_bright`) and
    quantised to 256 colours with Pillow. ``report``: ``size``, ``colours``, ``mean_error`` and
    ``max_error`` (8-bit RGBA levels, the bank's display decode vs the resized texture)."""
    from PIL import Image

    texs = [m.texture for m in model.meshes if m.texture is not None]
    report: dict[str, Any] = {"name": name, "note": ""}
    if not texs:
        report["note"] = "the model has no texture: no bank written"
        return None, report
    if any(t is not texs[0] and (t.shape != texs[0].shape or not np.array_equal(t, texs[0])) for t in texs[1:]):
        report["note"] = f"{len(texs)} primitives carry different textures: only the first one's is written"
    src = np.ascontiguousarray(texs[0], np.uint8)
    if src.ndim != 3 or src.shape[2] not in (3, 4):
        raise ValidationError(f"model {model.name!r}: expected an (h, w, 3|4) texture, got {src.shape}")
    if src.shape[2] == 3:
        src = np.concatenate([src, np.full(src.shape[:2] + (1,), 255, np.uint8)], axis=2)
    h, w = src.shape[:2]
    size = (_pow2(w, max_size), _pow2(h, max_size))
    img = Image.fromarray(src, "RGBA")
    if size != (w, h):
        img = img.resize(size, Image.Resampling.LANCZOS)
    want = np.asarray(img, np.uint8)
    stored = half_bright(want)
    colours, inv = np.unique(stored.reshape(-1, 4), axis=0, return_inverse=True)
    if len(colours) <= 256:  # exact
        idx, pal = inv.reshape(stored.shape[:2]).astype(np.uint8), colours.astype(np.uint8)
    else:
        q = Image.fromarray(stored, "RGBA").quantize(256, method=Image.Quantize.FASTOCTREE)
        idx = np.asarray(q, np.uint8)
        pal = np.asarray(q.getpalette("RGBA"), np.uint8).reshape(-1, 4)[: int(idx.max()) + 1].copy()
    im = SshImage(name, 2, idx, pal, long_name="")
    err = np.abs(im.rgba().astype(np.int16) - want.astype(np.int16))
    report.update(size=[int(size[0]), int(size[1])], source_size=[int(w), int(h)], colours=int(len(pal)),
                  mean_error=float(err.mean()), max_error=int(err.max()))
    return SshBank([im], creator=b"G277"), report


def _submesh(mesh: SkinnedMesh, tri_mask: np.ndarray) -> tuple[SkinnedMesh, np.ndarray]:
    """The triangles ``tri_mask`` of ``mesh`` on their own vertices: ``(SkinnedMesh, vertex ids)``."""
    tris = mesh.indices[tri_mask].astype(np.int64)
    vs, inv = np.unique(tris, return_inverse=True)
    mp = mesh.morph_positions[:, vs] if mesh.n_morphs else None
    sub = SkinnedMesh(name=mesh.name, positions=mesh.positions[vs], indices=inv.reshape(-1, 3),
                      normals=mesh.normals[vs], uv=mesh.uv[vs], joints=mesh.joints[vs], weights=mesh.weights[vs],
                      morph_positions=mp,  # type: ignore[arg-type]  # None: __post_init__ makes it empty
                      morph_names=list(mesh.morph_names) if mp is not None else [],
                      skinned=True, group=mesh.group)
    return sub, vs


def _subpalette(pal: Palette, vs: np.ndarray) -> Palette:
    """``pal`` restricted to the entries the vertices ``vs`` use (index renumbered)."""
    used, inv = np.unique(pal.index[vs], return_inverse=True)
    return replace(pal, bones=pal.bones[used], weights=pal.weights[used], units=pal.units[used],
                   index=inv.reshape(-1).astype(pal.index.dtype))


def _head_bones(sk: Skeleton, head_bone: str | None) -> list:
    """The head file's bones: ``head_bone`` (default: the bone labelled ``head`` by
    :func:`piste.character.retarget.bone_roles`, else one named ``head``) and its descendants."""
    if head_bone is None:
        roles = bone_roles(sk)
        head_bone = next((n for n, r in roles.items() if r == "head"), "head")
    h = sk.get(head_bone)
    if h is None:
        raise ConfigError(f"no head bone {head_bone!r} in the skeleton to split the head file at "
                          f"(bones: {', '.join(sk.names[:10])}, ...)")
    inside = np.zeros(sk.n_bones, bool)
    inside[h] = True
    for i in range(sk.n_bones):  # parents come before children
        if sk.parents[i] >= 0 and inside[sk.parents[i]]:
            inside[i] = True
    if int(sk.parents[h]) < 0:
        raise ConfigError(f"head bone {head_bone!r} is a root: the head file's bones must hang off a body bone")
    return [int(i) for i in np.nonzero(inside)[0]]


def _split_records(bones: np.ndarray, sk: Skeleton, head: list, body_id: int,
                   head_id: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bone records of the body and head files: parents and mirror partners as (file id, local bone)."""
    hs = set(head)
    lists = ([i for i in range(sk.n_bones) if i not in hs], list(head))
    ref = np.zeros((sk.n_bones, 2), np.int64)
    for fid, lst in zip((body_id, head_id), lists):
        for k, i in enumerate(lst):
            ref[i] = (fid, k)
    out = []
    for fid, lst in zip((body_id, head_id), lists):
        rec = bones[lst].copy()
        for k, i in enumerate(lst):
            par = int(sk.parents[i])
            rec["parent_file"][k], rec["parent_bone"][k] = (-1, -1) if par < 0 else (int(ref[par][0]), int(ref[par][1]))
            m = int(bones["mirror"][i])
            rec["mirror"][k] = ref[m][1] if ref[m][0] == fid else k
        out.append(rec)
    return out[0], out[1], ref


def model_to_mpf_pair(model: Model, head_bone: str | None = None,
                      head_names: Sequence[str] = ("Head3000", "Head1500", "Head750"),
                      head_file_id: int = HEAD_FILE_ID, **kw: Any) -> tuple[MpfFile, MpfFile, dict[str, Any]]:
    """Encode a piste rider as the game's ``_body.mpf`` + ``_head.mpf`` pair: ``(body, head, report)``.

    ``head_bone`` (default: the skeleton's head) and its descendants become the head file's bones
    (file id ``head_file_id``; the subtree's root names its body parent by file id 0); see the
    module docstring for how triangles are divided. ``kw`` as :func:`model_to_mpf` (whose report
    this extends with ``split``: the head bones and each LOD's head / body triangles)."""
    if model.skeleton is None:
        raise ConfigError(f"model {model.name!r} has no skeleton: an .mpf rider needs a skinned model")
    head = _head_bones(model.skeleton, head_bone)
    return model_to_mpf(model, _split=(head, tuple(head_names), int(head_file_id)), **kw)
