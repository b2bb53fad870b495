"""SSX Tricky riders in scenes: a scene's ``model = "ssx:RIDER.mpf"`` becomes a playable rider.

The ``.mpf`` holds the body (and a ``<name>_head.mpf`` beside a ``<name>_body.mpf`` is read with
it: head bones parent onto body bones across the two files); animation clips are not in model
files, so the rider plays piste's shared clips (the default rider's ``ride``, ``crouch``, ``grab``,
``spin``), matched to the model's bones **by name** (:class:`piste.character.Clip`'s retarget
rule). A model built by piste's encoder from the default rider has the same bone names and plays
them exactly; a retail model's bones (``hips``, ``l_clav``, ``l_thigh``, ``r_calf``, ...) are
matched by role through the built-in bone map of :mod:`piste.character.retarget` (``notes`` says
how many); a model none of whose bones can be matched stands in its bind pose (``notes`` says so).

The LODs the character build step uses are the file's own (``Body3000`` / ``1500`` / ``750``,
each with its own weight palettes) when the scene asks for three levels.

API
---
load_mpf_rider(path) -> piste.formats.ssx.SsxModel (with clips; lifted to stand on its origin)
stand_on_origin(model) -> lift in metres (a hips-centred retail rider stood on the ground)
shared_clips(model) -> dict of the default rider's clips, and how many bones they drive
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from piste.character.retarget import builtin_bone_map, retarget_clip
from piste.character.rider import default_rider
from piste.errors import ConfigError
from piste.formats.ssx.mpf import read_mpf
from piste.character.model import Clip, Track
from piste.formats.ssx.afl import AflFile, afl_clips, mpf_body_bones
from piste.formats.ssx.mpf_model import CM, SSX_TO_PISTE, mpf_partners, mpf_to_model
from piste.formats.ssx.ssh import read_ssh
from piste.pipeline.object_atlas import pack_object_atlas
from piste.world.riders import merged_mesh

if TYPE_CHECKING:
    from piste.character.model import Skeleton
    from piste.formats.ssx.mpf_model import SsxModel
    from piste.formats.ssx.ssh import SshBank, SshImage

__all__ = ["load_mpf_rider", "shared_clips", "apply_texture_banks", "material_images", "stand_on_origin"]


def material_images(model: SsxModel, banks: Sequence[SshBank], where: Sequence[str] = ()) -> list[np.ndarray | None]:
    """One ``(h, w, 4) uint8`` display image (half-bright undone) per entry of ``model.materials``:
    the bank image whose 4-character name is the material's main texture id (first bank first,
    as the game resolves ids by shortname); failing that, image ``i`` of the first bank for
    material index ``i`` (piste's assumption for banks whose names do not match); else None.
    ``model.notes`` lists the materials that found no image."""
    named: dict[str, SshImage] = {}
    im: SshImage | None
    for bank in banks:
        for im in bank.images:
            named.setdefault(im.name.rstrip("\0 "), im)
    first = banks[0].images if banks else []
    out: list[np.ndarray | None] = []
    for tid, mi in model.materials:
        im = named.get(tid) if tid else None
        how = "by name"
        if im is None and 0 <= mi < len(first):
            im, how = first[mi], f"by index (image {mi} of {where[0] if where else 'the first bank'})"
        if im is None:
            model.notes.append(f"material {mi} ({tid or 'no id'}): no image in the texture bank(s); drawn white")
            out.append(None)
            continue
        if how != "by name":
            model.notes.append(f"material {mi} ({tid or 'no id'}): no image named {tid!r}; textured {how}")
        out.append(im.rgba())
    return out


def apply_texture_banks(model: SsxModel, banks: Sequence[SshBank], where: Sequence[str] = ()) -> SsxModel:
    """Texture a decoded ``.mpf`` rider (:class:`~piste.formats.ssx.mpf_model.SsxModel`) from
    ``banks`` (:class:`~piste.formats.ssx.ssh.SshBank`): each material's image
    (:func:`material_images`); one material's image is the rider's texture as it is (its UVs
    unchanged, so tiling survives), several are packed into one texture
    (:func:`piste.pipeline.object_atlas.pack_object_atlas`, UVs clamped into each region) with the
    UVs of the meshes and of the file's LODs remapped alike. The top-LOD meshes become one mesh
    carrying that texture (what the character build step and glTF export take). In place; returns
    ``model``."""
    imgs = material_images(model, banks, where)
    if not any(i is not None for i in imgs):
        return model
    white = np.full((4, 4, 4), 255, np.uint8)
    imgs = [white if i is None else i for i in imgs]
    meshes = list(model.meshes) + [lod.mesh for lod in model.lods]
    mats = list(model.mesh_materials) + list(model.lod_materials)
    used = sorted({int(k) for m in mats for k in np.unique(m)})
    if len(used) == 1:
        tex = imgs[used[0]]
        uvs = [m.uv for m in meshes]
    else:
        uv = np.concatenate([m.uv for m in meshes])
        mat = np.concatenate(mats)
        order = np.argsort(mat, kind="stable")
        bounds = np.searchsorted(mat[order], used + [used[-1] + 1])
        parts = [(int(bounds[k]), int(bounds[k + 1]), imgs[u]) for k, u in enumerate(used)]
        tex, packed = pack_object_atlas(np.zeros((0, 0, 4), np.uint8), {"rider": (uv[order], parts)})
        back = np.empty_like(packed["rider"])
        back[order] = packed["rider"]
        cuts = np.cumsum([0] + [m.n_vertices for m in meshes])
        uvs = [back[a:b] for a, b in zip(cuts[:-1], cuts[1:])]
    for m, u in zip(meshes, uvs):
        m.uv = np.ascontiguousarray(u, np.float32)
        m.texture = tex
    if len(model.meshes) > 1:
        one = merged_mesh(model)
        one.texture = tex
        model.meshes = [one]
        model.mesh_materials = [np.concatenate(model.mesh_materials)]
    return model


def shared_clips(model: SsxModel) -> tuple[dict[str, Clip], int]:
    """The default rider's clips for ``model`` and the number of ``model``'s bones they animate.

    When every bone the clips animate has its name in ``model`` they play as they are; otherwise
    (a retail rider's ``hips``, ``l_thigh``, ``r_calf``, ...) they are retargeted through the
    built-in bone map (:func:`piste.character.retarget.builtin_bone_map`: roles from the names,
    or from the hierarchy) with the ``world`` rule baked in (each mapped bone turns in world space
    as its source bone does: an SSX rig's bones carry other local frames than the default rider's,
    and the local-delta rules lay the retail ``moby`` rider on its back or bend its limbs 20-130
    degrees off); bones the map leaves out keep their rest pose; ``model.notes`` says how many
    bones that mapped."""
    src = default_rider(0)
    sk = cast("Skeleton", model.skeleton)  # None for an .mpf without bones: not checked (an AttributeError)
    names = set(sk.names)
    animated = {b for c in src.clips.values() for b in c.tracks}
    if animated <= names:
        return dict(src.clips), len(animated)
    bone_map = builtin_bone_map(cast("Skeleton", src.skeleton), sk)  # the default rider has a skeleton
    clips = {n: retarget_clip(c, sk, bone_map, source=src.skeleton, warn=False, mode="world")
             for n, c in src.clips.items()}
    driven = {b for c in clips.values() for b in c.tracks}
    by_role = [f"{k} -> {v}" for k, v in bone_map.items() if k != v and k in animated]
    notes = getattr(model, "notes", None)
    if driven and notes is not None:
        shown = f" ({', '.join(by_role[:4])}{', ...' if len(by_role) > 4 else ''})" if by_role else ""
        notes.append(f"shared clips retargeted by the built-in bone map: {len(driven)} of the model's {sk.n_bones} "
                     f"bones driven, {len(by_role)} matched by role{shown}; the others keep their rest pose")
    return clips, len(driven)


def stand_on_origin(model: SsxModel, tolerance: float = 0.05) -> float:
    """Lift a decoded ``.mpf`` rider so its lowest bind-pose vertex is at height 0, in place;
    returns the lift in metres (0 when the model already stands within ``tolerance`` of it).

    The game's rider models are centred on the hips (the retail ``moby`` body reaches 0.98 m
    below its origin: the game places the hips over the board), while a piste scene stands a
    rider's origin on the ground. The meshes (the top LOD's and every LOD's), the root bones' rest
    translations and the inverse bind matrices move together, so skinning is unchanged."""
    meshes = list({id(m): m for m in list(model.meshes) + [lod.mesh for lod in model.lods]}.values())
    low = min((float(m.positions[:, 1].min()) for m in meshes if m.n_vertices), default=0.0)
    if low >= -tolerance:
        return 0.0
    h = -low
    up = np.array([0.0, h, 0.0], np.float32)
    for m in meshes:
        m.positions = (m.positions + up).astype(np.float32)
    sk = cast("Skeleton", model.skeleton)
    roots = sk.parents < 0
    sk.rest_translation[roots] += up
    down = np.eye(4)
    down[1, 3] = -h
    sk.inverse_bind = sk.inverse_bind @ down
    model.notes.append(f"lifted {h:.2f} m so the rider stands on its origin (the file's origin is at the hips)")
    return h


def load_mpf_rider(path: str | os.PathLike[str],
                   texture: str | Path | Sequence[str | os.PathLike[str]] | None = None) -> SsxModel:
    """Read an ``.mpf`` rider (plus its ``_head.mpf`` partner when ``path`` is a ``_body.mpf``),
    convert it, texture it from its ``.ssh`` bank(s) (``texture``: a path or a list; default: the
    banks with the model files' stems beside them, :func:`piste.formats.ssx.mpf_model.mpf_partners`)
    and give it the shared clips."""
    path = Path(path)
    head, banks = mpf_partners(path, texture)
    files = [read_mpf(path)] + ([read_mpf(head)] if head is not None else [])
    model = mpf_to_model(*files, name=path.stem)
    if not model.meshes:
        raise ConfigError(f"{path}: no render sub-models to draw")
    if model.skeleton is None:
        raise ConfigError(f"{path}: no sub-model holds bones: a rider needs a skeleton to stand on its origin and "
                          "play the shared clips")
    stand_on_origin(model)
    if banks:
        apply_texture_banks(model, [read_ssh(b) for b in banks], [str(b) for b in banks])
    model.clips, driven = shared_clips(model)
    if driven == 0:
        model.notes.append("none of the shared clips' bones are in this model: it stands in its bind pose")
    return model


def afl_rider_clips(model: SsxModel, afl: AflFile, fps: float | None = None) -> dict[str, Clip]:
    """The clips of the ``.afl`` bank ``afl`` (:func:`piste.formats.ssx.afl.afl_clips`: the body
    track's channels on the body bones in ``.mpf`` file order, the board track on ``board``) for the
    ``.mpf`` rider ``model`` (:func:`load_mpf_rider`). The root channels are in the file's
    coordinates: a rider lifted to stand on its origin (:func:`stand_on_origin`) gets the same lift
    on its root tracks, so the game's clips play at the height the rider is drawn at. ``fps``: the
    bank's frame rate (None: afl's default)."""
    kw: dict[str, Any] = {} if fps is None else {"fps": fps}
    clips = afl_clips(afl, cast("Skeleton", model.skeleton), mpf_body_bones(model), **kw)
    sk = cast("Skeleton", model.skeleton)
    lift = {}  # root bone -> (3,) metres: its rest translation less the file's bind translation
    for sub in model.files[0].models:
        if len(sub.bones):
            for rec, n in zip(sub.bones, sub.bone_names):
                j = sk.get(n)
                if j is not None and sk.parents[j] < 0:
                    bind = (np.asarray(rec["translation"], np.float64)[:3] @ SSX_TO_PISTE.T) * CM
                    lift[n] = np.asarray(sk.rest_translation[j], np.float64) - bind
            break
    for c in clips.values():
        for b, off in lift.items():
            t = c.tracks.get(b, {}).get("translation")
            if t is not None and np.any(off != 0):
                c.tracks[b]["translation"] = Track(t.times, t.values + off)
    return clips
