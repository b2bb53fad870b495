"""glTF objects keep their own textures: each primitive's base colour (texture x factor, or the
factor alone) is packed into the objects' texture atlas beside the built-in tiles, and its UVs are
remapped into its region, so the object pass (one atlas for every kind) draws them unchanged.

Convention: a region is the primitive's image (scaled down to at most ``max_size`` texels a side)
with a ``gutter``-texel border replicating its edge; UVs ``(u, v)`` are clamped to ``[0, 1]`` (a
repeating texture on an object shows its edge texels beyond the first tile) and mapped to texel
centres: ``u' = (x0 + 0.5 + u (w - 1)) / W``.  KHR_texture_transform is already in the UVs
(:mod:`piste.formats.gltf.extensions`).  The atlas is RGBA uint8, rows are ``v`` from 0 (no flip), like
the built-in one.

Alpha: OPAQUE primitives get alpha 255 (glTF ignores it); MASK keeps texels at or above its
``alphaCutoff`` (255) and drops the rest (0): the object shader discards texels with alpha below
0.5; BLEND keeps its alpha, and a model with a BLEND primitive is a blended kind
(:func:`blends`, ``ObjectSet.blend``): the object pass draws it after the opaque kinds with alpha
blending, sorted back to front (its OPAQUE / MASK primitives, alpha 255 / 0, look the same there).

Double-sided materials (``doubleSided: true``) are made double-sided in the geometry: the
primitive's triangles are added again, reversed, on copies of its vertices with negated normals
(the object pass culls back faces and lights with the normal).

API
---
primitive_images(model) -> list[(v0, v1, (h, w, 4) uint8)]   per mesh, in load_object_mesh's order
pack_object_atlas(base, parts, builtin=None, max_size=256, gutter=2) -> (atlas, {kind: uv (v, 2) float32})
double_sided(mesh, model, images) -> (ObjectMesh, images)  back faces added for doubleSided materials
blends(model) -> bool   whether any primitive's material is alphaMode BLEND
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from piste.character.model import Model
    from piste.world.objects import ObjectMesh

__all__ = ["primitive_images", "pack_object_atlas", "double_sided", "blends"]


def _srgb_u8(c: Any) -> np.ndarray:
    """Linear RGBA factor -> 8-bit sRGB RGBA (the texture's encoding)."""
    c = np.clip(np.asarray(c, dtype=np.float64), 0.0, 1.0)
    rgb = np.where(c[:3] <= 0.0031308, 12.92 * c[:3], 1.055 * c[:3] ** (1 / 2.4) - 0.055)
    return np.round(np.concatenate([rgb, c[3:]]) * 255).astype(np.uint8)


def primitive_images(model: Model) -> list[tuple[int, int, np.ndarray]]:
    """``[(v0, v1, image)]``: the vertex range of each of ``model.meshes`` (concatenated in order, as
    :func:`piste.pipeline.sources.load_object_mesh` merges them) and its base colour as an RGBA
    uint8 image: the texture times the factor, or a 4x4 image of the factor alone."""
    out = []
    v0 = 0
    for m in model.meshes:
        v1 = v0 + m.n_vertices
        f = np.asarray(m.base_color if m.base_color is not None else np.ones(4), dtype=np.float64)
        if m.texture is not None:
            img = np.asarray(m.texture, dtype=np.float64)
            if not np.allclose(f, 1.0):
                lin = np.where(img[..., :3] / 255 <= 0.04045, img[..., :3] / 255 / 12.92,
                               ((img[..., :3] / 255 + 0.055) / 1.055) ** 2.4) * f[:3]
                rgb = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * np.clip(lin, 0, 1) ** (1 / 2.4) - 0.055)
                img = np.concatenate([rgb * 255, img[..., 3:] * f[3]], axis=-1)
            img = np.round(np.clip(img, 0, 255)).astype(np.uint8)
        else:
            img = np.tile(_srgb_u8(f), (4, 4, 1))
        info = getattr(m, "material", None)
        mode = getattr(info, "alpha_mode", "OPAQUE") if info is not None else "OPAQUE"
        img = img.copy()
        if mode == "OPAQUE":  # glTF: alpha is ignored
            img[..., 3] = 255
        elif mode == "MASK":  # its cutoff baked: the object shader discards alpha < 0.5
            cut = float(getattr(info, "alpha_cutoff", 0.5))
            img[..., 3] = np.where(img[..., 3] >= round(cut * 255), 255, 0).astype(np.uint8)
        # BLEND: the alpha as it is (the object pass's blend programs)
        out.append((v0, v1, img))
        v0 = v1
    return out


def blends(model: Model) -> bool:
    """Whether any of ``model.meshes`` has a material with ``alphaMode`` BLEND."""
    return any(getattr(getattr(m, "material", None), "alpha_mode", "OPAQUE") == "BLEND" for m in model.meshes)


def pack_object_atlas(base: np.ndarray, parts: dict[str, Any], builtin: dict[str, np.ndarray] | None = None,
                      max_size: int = 256, gutter: int = 2) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The built-in atlas ``base (H, W, 4) uint8`` with every part's regions added below it.

    ``parts``: ``{kind: (uv (v, 2), [(v0, v1, image), ...])}``; ``builtin``: ``{kind: uv (v, 2)}``
    of meshes addressing ``base`` (rescaled to the grown atlas).  Returns ``(atlas, {kind: uv'})``
    with the remapped UVs ``(v, 2) float32`` of both.  Shelf packing, rows of regions under the base.
    """
    base = np.asarray(base, dtype=np.uint8)
    if not parts:
        return base, {k: np.asarray(v, dtype=np.float32) for k, v in (builtin or {}).items()}
    regions = []  # (kind, index, image)
    for kind, (uv, imgs) in parts.items():
        for k, (_, _, img) in enumerate(imgs):
            img = np.asarray(img, dtype=np.uint8)
            h, w = img.shape[:2]
            s = min(1.0, max_size / max(h, w))
            if s < 1.0:
                from PIL import Image  # (here: ~13 ms of imports a renderer loading a bundle never needs)

                img = np.asarray(Image.fromarray(img, "RGBA").resize((max(1, round(w * s)), max(1, round(h * s))),
                                                                     Image.Resampling.LANCZOS))
            regions.append((kind, k, img))
    width = max(base.shape[1], max(r[2].shape[1] + 2 * gutter for r in regions))
    # shelves, tallest first
    order = sorted(range(len(regions)), key=lambda i: -regions[i][2].shape[0])
    place = {}
    x = y = shelf_h = 0
    y = base.shape[0]
    for i in order:
        h, w = regions[i][2].shape[:2]
        bw, bh = w + 2 * gutter, h + 2 * gutter
        if x + bw > width:
            x, y = 0, y + shelf_h
            shelf_h = 0
        place[i] = (x + gutter, y + gutter)
        x += bw
        shelf_h = max(shelf_h, bh)
    height = y + shelf_h
    atlas = np.zeros((height, width, 4), np.uint8)
    atlas[:base.shape[0], :base.shape[1]] = base
    for i, (kind, k, img) in enumerate(regions):
        x0, y0 = place[i]
        h, w = img.shape[:2]
        padded = np.pad(img, ((gutter, gutter), (gutter, gutter), (0, 0)), mode="edge")
        atlas[y0 - gutter:y0 + h + gutter, x0 - gutter:x0 + w + gutter] = padded
    out = {}
    index = {(r[0], r[1]): i for i, r in enumerate(regions)}
    for kind, (uv, imgs) in parts.items():
        uv = np.clip(np.asarray(uv, dtype=np.float64), 0.0, 1.0)
        new = np.empty_like(uv)
        for k, (v0, v1, _) in enumerate(imgs):
            i = index[(kind, k)]
            x0, y0 = place[i]
            h, w = regions[i][2].shape[:2]
            new[v0:v1, 0] = (x0 + 0.5 + uv[v0:v1, 0] * (w - 1)) / width
            new[v0:v1, 1] = (y0 + 0.5 + uv[v0:v1, 1] * (h - 1)) / height
        out[kind] = new.astype(np.float32)
    sx, sy = base.shape[1] / width, base.shape[0] / height
    for kind, uv in (builtin or {}).items():  # the base stays at the top-left: scale its UVs
        out[kind] = (np.asarray(uv, dtype=np.float64) * [sx, sy]).astype(np.float32)
    return atlas, out


def double_sided(mesh: ObjectMesh, model: Model, images: Sequence[tuple[int, int, np.ndarray]]
                 ) -> tuple[ObjectMesh, list[tuple[int, int, np.ndarray]]]:
    """``mesh`` (the merged ObjectMesh of ``model``'s meshes, in order) with every primitive whose
    material is double-sided given reversed back-face triangles on its own vertex copies, and
    ``images`` (:func:`primitive_images`) extended with those copies' ranges.  Returns
    ``(mesh, images)``."""
    from dataclasses import replace as _replace

    ranges = []
    for m, (v0, v1, img) in zip(model.meshes, images):
        info = getattr(m, "material", None)
        if info is not None and getattr(info, "double_sided", False):
            ranges.append((v0, v1, img))
    if not ranges:
        return mesh, list(images)
    pos, nrm, uv, tri = mesh.positions, mesh.normals, mesh.uv, mesh.indices.astype(np.int64)
    add_p, add_n, add_uv, add_t = [], [], [], []
    out_images = list(images)
    n = len(pos)
    for a, b, img in ranges:
        sel = tri[(tri[:, 0] >= a) & (tri[:, 0] < b)]
        add_p.append(pos[a:b])
        add_n.append(-nrm[a:b])
        add_uv.append(uv[a:b])
        add_t.append(sel[:, ::-1] - a + n)
        out_images.append((n, n + b - a, img))
        n += b - a
    mesh = _replace(mesh, positions=np.concatenate([pos] + add_p), normals=np.concatenate([nrm] + add_n),
                    uv=np.concatenate([uv] + add_uv), indices=np.concatenate([tri] + add_t).astype(np.uint32))
    return mesh, out_images
