"""A runtime scene (:class:`~piste.pipeline.bundle_objects.Bundle`, any source) to glTF: the glue
behind ``piste export`` and ``piste ssx convert --to gltf``.

Writes the terrain (tessellated at ``--level`` 4, 6 or 8 vertices per edge, or at the LOD a named
camera sees with ``--level camera:NAME``), its light-map atlas (occlusion texture on TEXCOORD_1)
and base texture, the riders as skinned meshes with their clips, the objects as instanced nodes
(``--instancing ext|nodes``), the lights (KHR_lights_punctual) and the cameras.  The format's
conventions are in :mod:`piste.formats.gltf.write`; this module is the glue from a bundle.
(:mod:`piste.commands.export` parses the flags and calls :func:`export_bundle`.)

Lights and cameras are written as the runtime holds them (:mod:`piste.scene_data`); the glTF
units and axes (lux / candela, radians, ``white`` = 683 lux shown by piste as 1.0, an infinite
range matched at 10 m) are :mod:`piste.formats.gltf.units`'s.  Ambient and negative (darkening)
lights have no glTF form: they are listed, in piste's units, in the scene's ``extras.piste_ambient``
and ``extras.piste_negative_lights``.  Cameras get the aspect ratio of the scene's render size.

API (for other glue, e.g. levels)
---------------------------------
bundle_parts(bundle, level=4, with_base_texture=True) -> dict of export_gltf keyword arguments
export_bundle(bundle, path, level=4, instancing="ext") -> ExportReport
"""

from __future__ import annotations

import os
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from piste.errors import ConfigError
from piste.formats.gltf.write import CharacterExport, ObjectsExport, TerrainExport, export_gltf
from piste.formats.gltf.units import DEFAULT_WHITE_LUX as WHITE_LUX
from piste.formats.gltf.units import INFINITE_RANGE_MATCH, lights_without_gltf_form
from piste.pipeline.characters import model_from_arrays
from piste.render.textures import snow_texture
from piste.terrain.lod import edge_levels
from piste.terrain.tessellate import terrain_mesh

if TYPE_CHECKING:
    from piste.formats.gltf.write import ExportReport
    from piste.pipeline.bundle_objects import Bundle

__all__ = ["WHITE_LUX", "INFINITE_RANGE_MATCH", "terrain_levels", "bundle_parts", "export_bundle"]


def terrain_levels(bundle: Bundle, level: int | str) -> int | np.ndarray:
    """``4``/``6``/``8`` (int) or per-edge levels ``(edges,)`` for ``"camera:NAME"`` (the bundle's LOD distances)."""

    if isinstance(level, str) and level.startswith("camera:"):
        cam = bundle.camera(level.split(":", 1)[1])
        lod = bundle.manifest.get("lod") or {}
        kw: dict[str, Any] = {k: float(lod[k]) for k in ("near", "far") if k in lod}
        return edge_levels(bundle.net, cam.eye, **kw)
    try:
        lv = int(level)
    except (TypeError, ValueError):
        raise ConfigError(f"--level must be 4, 6, 8 or camera:NAME, got {level!r}") from None
    if lv not in (4, 6, 8):
        raise ConfigError(f"--level must be 4, 6, 8 or camera:NAME, got {level!r}")
    return lv


def bundle_parts(bundle: Bundle, level: int | str = 4, with_base_texture: bool = True) -> dict[str, Any]:
    """Keyword arguments of :func:`piste.formats.gltf.write.export_gltf` for a loaded bundle."""

    base = None
    if with_base_texture:
        base = bundle.arrays.get("terrain/base_texture")  # an SSX level's own textures (pipeline.ssx_level)
        if base is None:
            base = snow_texture()
    mesh = terrain_mesh(bundle.net, terrain_levels(bundle, level))
    parts: dict[str, Any] = {"terrain": TerrainExport(mesh, bundle.lightmap.atlas, base)}
    info = bundle.manifest.get("characters") or {}
    models: dict = {}
    chars = []
    if info:
        mats = bundle.arrays["riders/matrix"]
        for i, r in enumerate(bundle.manifest.get("riders", [])):
            name = r.get("name") or f"rider{i}"
            cid = r.get("character") or sorted(info)[0]
            if cid not in models:  # each rider model of the scene (riders of one model share it)
                models[cid] = model_from_arrays(bundle.arrays, f"characters/{cid}/", info[cid])
            model = models[cid]
            chars.append(CharacterExport(model, mats[i], name=name, clips=[r["clip"]] if r.get("clip") else [],
                                         prefix=f"{name}:", extras={"piste_rider": {"clip": r.get("clip"),
                                                                                    "phase": float(r.get("phase", 0.0))}}))
    parts["characters"] = chars
    objs = bundle.objects()
    if objs is not None:
        meshes = {}
        for k in objs.kinds:
            p, n, uv = objs.meshes[k].decode()
            meshes[k] = (p, n, uv, objs.meshes[k].indices)
        inst = (bundle.manifest.get("objects") or {}).get("instances") or []
        names: list[Any] | None
        names = [d.get("name") if isinstance(d, dict) else None for d in inst]
        if len(names) != len(objs.kind) or not all(names):
            names = None
        parts["objects"] = ObjectsExport(meshes, tuple(objs.kinds), objs.kind, objs.matrix, objs.texture, names)
    other = lights_without_gltf_form(bundle.lights)
    parts["lights"] = bundle.lights
    size = (bundle.manifest.get("render") or {}).get("size") or (640, 448)
    parts["cameras"] = [replace(c, name=name, aspect=size[0] / size[1]) for name, c in bundle.cameras.items()]
    parts["extras"] = {"piste_scene": bundle.name, "piste_ambient": other["ambient"],
                       "piste_negative_lights": other["negative"]}
    return parts


def export_bundle(bundle: Bundle, path: str | os.PathLike[str], level: int | str = 4, instancing: str = "ext",
                  with_base_texture: bool = True) -> ExportReport:
    """Write ``bundle`` as glTF (see :func:`piste.formats.gltf.write.export_gltf`); returns its ExportReport."""
    return export_gltf(path, instancing=instancing, **bundle_parts(bundle, level, with_base_texture))
