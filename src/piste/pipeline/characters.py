"""The character build step: a rider model -> LODs, palettes, batches, strips and clip tables as arrays.

For each LOD (:func:`piste.character.make_lods`): the simplified mesh, its blended-matrix palette
(the talk's ~250 / ~150 / ~75 matrices), the draw batches under the PS2 budget
(:func:`piste.character.batch_mesh`) and one triangle strip per batch
(:func:`piste.character.stripify`, restart-joined).  Clips are resampled at ``rate`` Hz into
per-bone translation / rotation / scale tables (what :class:`piste.world.riders.ClipTable` plays),
so loading never samples the original curves.  Morph targets travel per LOD
(``lod<i>/morph_positions``, ``lod<i>/morph_normals`` ``(k, v, 3) float32``, names in the meta's
``morphs``), so riders in a bundle move their faces too.

Array names below ``<prefix>`` (``characters/<model id>/``): ``skeleton/{parents, rest_translation,
rest_rotation, rest_scale, inverse_bind}``, ``texture``, ``clips/<name>/{translation, rotation, scale}``
``(F, b, 3|4) float32``, and per LOD ``lod<i>/{positions, normals, uv, indices, joints, weights,
palette_bones, palette_weights, palette_units, palette_index, batch_vertices, batch_matrices,
batch_triangles, batch_offsets (nb + 1, 3) [vertices, matrices, triangles], strips, strip_offsets}``.

API
---
character_arrays(model, ratios, steps, max_bones, rate) -> (arrays, meta)
model_from_arrays(arrays, prefix, meta) -> piste.character.Model
lods_from_arrays(arrays, prefix, meta, model) -> list[piste.character.LOD]
merged_mesh(model) -> SkinnedMesh          all skinned primitives of a model as one mesh
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, cast

import numpy as np

# the mesh batcher, the stripifier and the LOD maker (the character step's) and the glTF material
# through the packages' lazy names (PEP 562): a bundle load reads their results, it does not import them
from piste import character as _character
from piste.character.lod import LOD, pose_skins, screen_errors
from piste.character.model import Clip, Model, Skeleton, SkinnedMesh, Track
from piste.character.palette import Palette
from piste.errors import ConfigError, FormatError
from piste.formats import gltf as _gltf
from piste.pipeline.object_atlas import pack_object_atlas, primitive_images
from piste.world.riders import merged_mesh as _merged

if TYPE_CHECKING:
    from piste.formats.gltf.material import MaterialInfo

__all__ = ["character_arrays", "model_from_arrays", "lods_from_arrays", "merged_mesh", "CLIP_RATE",
           "CHARACTERS_VERSION"]

CLIP_RATE = 30.0
#: what the character step writes (part of its cache key): 2 = morph targets per LOD
CHARACTERS_VERSION = 5  # 3: several primitives keep their own base colours (one packed texture); 4: material;
#                        5: each LOD's screen-space error ("distance", metres: riders' LOD by pixels)
DEFAULT_STEPS = (0.1, 0.2, 0.25)


def merged_mesh(model: Model) -> SkinnedMesh:
    """One :class:`SkinnedMesh` of every skinned primitive of ``model`` (see
    :func:`piste.world.riders.merged_mesh`); with several primitives their base colours (texture x
    factor, or the factor) are packed into one texture and the UVs remapped
    (:func:`piste.pipeline.object_atlas.pack_object_atlas`), so each keeps its own material."""
    from dataclasses import replace

    mesh = _merged(model)
    prims = [m for m in model.meshes if m.skinned] or list(model.meshes)
    material = rider_material(prims)
    if len(prims) < 2:
        if material is not None and material.alpha_mode == "MASK" and prims[0].texture is not None:
            tex = np.array(mesh.texture, dtype=np.uint8)  # the cutoff baked into the alpha, as for objects
            tex[..., 3] = primitive_images(Model(model.name, None, prims[:1]))[0][2][..., 3]
            mesh = replace(mesh, texture=tex)
        return replace(mesh, material=material) if material is not None else mesh
    imgs = primitive_images(Model(model.name, None, prims))
    tex, uvs = pack_object_atlas(np.zeros((0, 0, 4), np.uint8), {"rider": (mesh.uv, imgs)})
    return replace(mesh, uv=uvs["rider"], texture=tex, material=material)


def rider_material(prims: Sequence[SkinnedMesh]) -> MaterialInfo | None:
    """The one material a rider is drawn with (:class:`piste.formats.gltf.extensions.MaterialInfo`, or
    None when no primitive has a glTF material): ``alpha_mode`` MASK when any primitive is MASK or
    BLEND (riders have no blend pass: BLEND is cut out at 0.5, the texture's alpha holds each
    primitive's cutoff baked to 0 / 255 by :func:`primitive_images`), OPAQUE otherwise;
    ``double_sided`` when any primitive is (the character pass then draws back faces; a rider of
    single-sided materials has its back faces culled)."""
    # SkinnedMesh.material is typed ``object`` (the character core does not import the glTF formats)
    mats = [cast("MaterialInfo", m.material) for m in prims if getattr(m, "material", None) is not None]
    if not mats:
        return None
    mask = any(m.alpha_mode in ("MASK", "BLEND") for m in mats)
    return _gltf.MaterialInfo(alpha_mode="MASK" if mask else "OPAQUE", alpha_cutoff=0.5,
                        double_sided=any(m.double_sided for m in mats))


def _steps(ratios: Sequence[float], steps: Sequence[float] | None) -> tuple[float, ...]:
    steps = tuple(steps) if steps is not None else DEFAULT_STEPS
    return tuple(steps[min(i, len(steps) - 1)] for i in range(len(ratios)))


def character_arrays(model: Model, ratios: Sequence[float] = (1.0, 0.5, 0.25), steps: Sequence[float] | None = None,
                     max_bones: int = 3, rate: float = CLIP_RATE) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Everything the runtime needs of a rider model, pre-processed: ``(arrays, meta)``."""
    if model.skeleton is None:
        raise ConfigError(f"rider model {model.name!r} has no skeleton: riders need a skinned glTF")
    sk = model.skeleton
    mesh = merged_mesh(model)
    steps = _steps(ratios, steps)
    lods = getattr(model, "lods", None)  # a model that ships its own LODs (an .mpf's Body3000/1500/750)
    if not lods or len(lods) != len(ratios):
        lods = _character.make_lods(mesh, ratios=ratios, steps=steps, max_bones=max_bones)
    # each level's error on screen (geometry + palette in the clips' poses), measured here once rather than
    # at every renderer's first frame (~0.27 s of a fresh process with scipy's k-d tree import)
    distance = screen_errors(lods, pose_skins(model))
    a: dict = {
        "skeleton/parents": sk.parents.astype(np.int32),
        "skeleton/rest_translation": sk.rest_translation,
        "skeleton/rest_rotation": sk.rest_rotation,
        "skeleton/rest_scale": sk.rest_scale,
        "skeleton/inverse_bind": sk.inverse_bind,
    }
    tex = mesh.texture if mesh.texture is not None else np.full((4, 4, 4), 255, np.uint8)
    a["texture"] = np.ascontiguousarray(tex, dtype=np.uint8)
    meta: dict = {"name": model.name, "bones": list(sk.names), "clips": {}, "lods": [], "rate": float(rate),
                  "max_bones": int(max_bones), "morphs": list(mesh.morph_names)}
    if mesh.material is not None:  # glTF riders: how the character pass draws them
        mat = cast("MaterialInfo", mesh.material)
        meta["material"] = {"alpha_mode": mat.alpha_mode, "double_sided": bool(mat.double_sided)}
    for cname, clip in sorted(model.clips.items()):
        f = int(np.ceil(clip.duration * rate)) + 1
        times = np.minimum(np.arange(f) / rate, clip.duration)
        poses = [clip.sample(float(t), skeleton=sk) for t in times]
        a[f"clips/{cname}/translation"] = np.stack([p.translation for p in poses]).astype(np.float32)
        a[f"clips/{cname}/rotation"] = np.stack([p.rotation for p in poses]).astype(np.float32)
        a[f"clips/{cname}/scale"] = np.stack([p.scale for p in poses]).astype(np.float32)
        meta["clips"][cname] = {"duration": float(clip.duration), "frames": f}
    for i, lod in enumerate(lods):
        m, pal = lod.mesh, lod.palette
        p = f"lod{i}/"
        if m.morph_positions.shape[0]:
            a[p + "morph_positions"] = np.ascontiguousarray(m.morph_positions, np.float32)
            a[p + "morph_normals"] = np.ascontiguousarray(m.morph_normals, np.float32)
        a.update({p + "positions": m.positions, p + "normals": m.normals, p + "uv": m.uv,
                  p + "indices": m.indices.astype(np.uint32), p + "joints": m.joints, p + "weights": m.weights,
                  p + "palette_bones": pal.bones.astype(np.int32), p + "palette_weights": pal.weights.astype(np.float32),
                  p + "palette_units": pal.units.astype(np.int32), p + "palette_index": pal.index.astype(np.int32)})
        batches = _character.batch_mesh(m, palette=pal)
        verts = [b.vertices for b in batches]
        mats = [b.matrices for b in batches]
        tris = [b.triangles for b in batches]
        strips = [_character.stripify(b.triangles) for b in batches]
        counts = np.array([[len(v), len(mm), len(t)] for v, mm, t in zip(verts, mats, tris)], np.int64).reshape(-1, 3)
        a[p + "batch_offsets"] = np.concatenate([np.zeros((1, 3), np.int64), np.cumsum(counts, axis=0)])
        a[p + "batch_vertices"] = np.concatenate(verts).astype(np.int32) if verts else np.zeros(0, np.int32)
        a[p + "batch_matrices"] = np.concatenate(mats).astype(np.int32) if mats else np.zeros(0, np.int32)
        a[p + "batch_triangles"] = (np.concatenate(tris).astype(np.int32) if tris else np.zeros((0, 3), np.int32))
        a[p + "strip_offsets"] = np.concatenate([[0], np.cumsum([len(s) for s in strips])]).astype(np.int64)
        a[p + "strips"] = np.concatenate(strips).astype(np.int32) if strips else np.zeros(0, np.int32)
        strip_len = int(sum(len(s) for s in strips))
        meta["lods"].append({"name": lod.name, "ratio": float(lod.ratio), "step": float(lod.step),
                             "error": float(lod.error), "distance": float(distance[i]),
                             "triangles": int(m.n_triangles), "vertices": int(m.n_vertices),
                             "palette": int(pal.size), "batches": len(batches), "strip_indices": strip_len})
    return a, meta


def _morphs(arrays: dict, prefix: str, meta: dict) -> dict:
    """The morph-target keywords of a LOD's SkinnedMesh (none when the bundle has none)."""
    if prefix + "morph_positions" not in arrays:
        return {}
    names = list(meta.get("morphs") or [])
    mp, mn = arrays[prefix + "morph_positions"], arrays.get(prefix + "morph_normals")
    v = arrays[prefix + "positions"].shape[0]
    if mp.ndim != 3 or mp.shape[1:] != (v, 3) or mn is None or mn.shape != mp.shape:
        raise FormatError(None, f"expected (k, {v}, 3) morph deltas, got {mp.shape} and "
                                f"{None if mn is None else mn.shape}", field=prefix + "morph_positions")
    k = mp.shape[0]
    return {"morph_positions": arrays[prefix + "morph_positions"], "morph_normals": arrays[prefix + "morph_normals"],
            "morph_names": names[:k]}


def _material(meta: dict) -> MaterialInfo | None:
    m = meta.get("material")
    if not isinstance(m, dict):
        return None
    mode = m.get("alpha_mode", "OPAQUE")
    return _gltf.MaterialInfo(alpha_mode=mode if mode in ("OPAQUE", "MASK") else "OPAQUE",
                        double_sided=bool(m.get("double_sided", False)))


def model_from_arrays(arrays: dict, prefix: str, meta: dict) -> Model:
    """The rider :class:`Model` (skeleton, LOD-0 mesh with texture, clips as LINEAR tracks)."""
    g = lambda k: arrays[prefix + k]  # noqa: E731
    sk = Skeleton(meta["bones"], g("skeleton/parents"), g("skeleton/rest_translation"), g("skeleton/rest_rotation"),
                  g("skeleton/rest_scale"), g("skeleton/inverse_bind"))
    p = "lod0/"
    mesh = SkinnedMesh(name=meta["name"], positions=g(p + "positions"), indices=g(p + "indices"),
                       normals=g(p + "normals"), uv=g(p + "uv"), joints=g(p + "joints"), weights=g(p + "weights"),
                       texture=g("texture"), skinned=True, group=meta["name"], material=_material(meta),
                       **_morphs(arrays, prefix + p, meta))
    rate = float(meta.get("rate", CLIP_RATE))
    clips = {}
    for cname, info in meta.get("clips", {}).items():
        tr, ro, sc = (g(f"clips/{cname}/{k}").astype(np.float64) for k in ("translation", "rotation", "scale"))
        f = tr.shape[0]
        times = np.minimum(np.arange(f) / rate, info["duration"])
        if f > 1 and times[-1] <= times[-2]:  # the last key clamped onto the one before
            times[-1] = times[-2] + 1e-6
        tracks = {}
        for b, name in enumerate(meta["bones"]):
            tracks[name] = {"translation": Track(times, tr[:, b]), "rotation": Track(times, ro[:, b]),
                            "scale": Track(times, sc[:, b])}
        clips[cname] = Clip(cname, float(info["duration"]), tracks, skeleton=sk)
    return Model(name=meta["name"], skeleton=sk, meshes=[mesh], clips=clips)


def lods_from_arrays(arrays: dict, prefix: str, meta: dict, model: Model | None = None) -> list[LOD]:
    """The LODs as built (meshes and palettes), :class:`piste.character.LOD` items."""
    out = []
    for i, info in enumerate(meta["lods"]):
        g = lambda k, i=i: arrays[f"{prefix}lod{i}/{k}"]  # noqa: E731
        mesh = SkinnedMesh(name=f"{meta['name']}/{info['name']}", positions=g("positions"), indices=g("indices"),
                           normals=g("normals"), uv=g("uv"), joints=g("joints"), weights=g("weights"),
                           texture=arrays[prefix + "texture"], skinned=True, group=meta["name"],
                           **_morphs(arrays, f"{prefix}lod{i}/", meta))
        pal = Palette(g("palette_bones"), g("palette_weights"), g("palette_units"), g("palette_index"),
                      float(info["step"]), int(meta.get("max_bones", 3)))
        d = info.get("distance")  # (bundles from before CHARACTERS_VERSION 5: None, measured on use)
        out.append(LOD(info["name"], mesh, pal, float(info["ratio"]), float(info["step"]), float(info["error"]),
                       float(d) if d is not None else None))
    return out
