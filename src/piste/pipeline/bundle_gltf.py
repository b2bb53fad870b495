"""A runtime scene (:class:`~piste.pipeline.bundle_objects.Bundle`, any source) to glTF: the glue
behind ``piste export`` and ``piste ssx convert --to gltf``.

Writes the terrain (tessellated at ``--level`` 4, 6 or 8 vertices per edge, or at the LOD a named
camera sees with ``--level camera:NAME``), its light-map atlas (occlusion texture on TEXCOORD_1)
and base texture, the riders as skinned meshes with their clips, the objects as instanced nodes
(``--instancing ext|nodes``), the lights (KHR_lights_punctual) and the cameras.  The format's
conventions are in :mod:`piste.formats.gltf.write`; this module is the glue from a bundle.
(:mod:`piste.commands.export` parses the flags and calls :func:`export_bundle`.)

Light units (piste -> KHR_lights_punctual), the inverse of :mod:`piste.pipeline.gltf_import`
------------------------------------------------------------------------------------------------
With ``white`` = 683 lux (Blender's sun strength 1 W/m^2) shown by piste as 1.0:

* directional: ``lux = intensity * white``;
* point and spot with a finite ``range``: ``candela = intensity * white * (range / 4)^2 * (3/4)^2``
  and glTF ``range = range`` (the inverse-square light equals piste's ``(1 - d/range)^2`` light at a
  quarter of the range; importing the file gives back the same intensity and range);
* point and spot with an infinite range (no fall-off in piste): ``candela = intensity * white * 10^2``
  (the same illuminance at 10 m), no glTF range;
* spot cones: piste's half-angles in degrees -> radians;
* ambient lights and negative (darkening) lights have no glTF form: they are listed, in piste's
  units, in the scene's ``extras.piste_ambient`` and ``extras.piste_negative_lights``.

Cameras: ``fov_y`` degrees -> ``yfov`` radians, ``near``/``far`` -> ``znear``/``zfar``, the aspect ratio of
the scene's render size; orthographic cameras get ``ymag = ortho_height / 2``.

API (for other glue, e.g. levels)
---------------------------------
bundle_parts(bundle, level=4, with_base_texture=True) -> dict of export_gltf keyword arguments
export_bundle(bundle, path, level=4, instancing="ext") -> ExportReport
piste_lights_to_gltf(lights, white=683.0) -> (list[piste.character.Light], {ambient, negative})
piste_cameras_to_gltf({name: Camera}, aspect) -> list[piste.character.Camera]
"""

from __future__ import annotations

import math

import numpy as np

from piste.character import Camera as GltfCamera
from piste.character import Light as GltfLight
from piste.errors import ConfigError
from piste.formats.gltf.write import CharacterExport, ObjectsExport, TerrainExport, export_gltf
from piste.lighting.lights import AmbientLight, DirectionalLight, PointLight, SpotLight
from piste.pipeline.characters import model_from_arrays
from piste.render.textures import snow_texture
from piste.terrain.lod import edge_levels
from piste.terrain.tessellate import terrain_mesh

__all__ = ["WHITE_LUX", "INFINITE_RANGE_MATCH", "piste_lights_to_gltf", "piste_cameras_to_gltf", "terrain_levels",
           "bundle_parts", "export_bundle"]

WHITE_LUX = 683.0
#: distance (m) at which a piste light without fall-off is matched by an inverse-square glTF light
INFINITE_RANGE_MATCH = 10.0


def piste_lights_to_gltf(lights, white: float = WHITE_LUX):
    """KHR_lights_punctual lights (:class:`piste.character.Light`, glTF units) for piste ``Lights``,
    and ``{"ambient": [...], "negative": [...]}`` the lights glTF cannot hold, as dicts (see the
    module docstring)."""

    out, ambient, negative = [], [], []
    for i, li in enumerate(lights.lights):
        name = li.name or f"light{i}"
        color = np.asarray(li.color, dtype=np.float64)
        if isinstance(li, AmbientLight):
            ambient.append({"name": name, "color": [float(x) for x in color], "intensity": float(li.intensity)})
            continue
        if li.intensity < 0:
            d = {"type": type(li).__name__, "name": name}
            for k in ("position", "direction", "color", "intensity", "range", "falloff", "inner_angle", "outer_angle"):
                if hasattr(li, k):
                    v = getattr(li, k)
                    d[k] = [float(x) for x in v] if np.ndim(v) else (float(v) if math.isfinite(float(v)) else "inf")
            negative.append(d)
            continue
        if isinstance(li, DirectionalLight):
            out.append(GltfLight(name=name, type="directional", color=color, intensity=float(li.intensity) * white,
                             direction=np.asarray(li.direction, dtype=np.float64)))
            continue
        rng = float(li.range)
        if math.isfinite(rng) and rng > 0:
            cd = float(li.intensity) * white * (rng / 4.0) ** 2 * 0.5625
            grange = rng
        else:
            cd = float(li.intensity) * white * INFINITE_RANGE_MATCH ** 2
            grange = None
        if isinstance(li, SpotLight):
            out.append(GltfLight(name=name, type="spot", color=color, intensity=cd, range=grange,
                             inner_cone=math.radians(li.inner_angle), outer_cone=math.radians(li.outer_angle),
                             position=np.asarray(li.position, dtype=np.float64),
                             direction=np.asarray(li.direction, dtype=np.float64)))
        elif isinstance(li, PointLight):
            out.append(GltfLight(name=name, type="point", color=color, intensity=cd, range=grange,
                             position=np.asarray(li.position, dtype=np.float64)))
    return out, {"ambient": ambient, "negative": negative}


def piste_cameras_to_gltf(cameras: dict, aspect: float | None = None) -> list:
    """:class:`piste.character.Camera` items for ``{name: piste.world.camera.Camera}``."""

    out = []
    for name, c in cameras.items():
        fwd = np.asarray(c.target, dtype=np.float64) - np.asarray(c.eye, dtype=np.float64)
        fwd = fwd / max(np.linalg.norm(fwd), 1e-300)
        a = float(aspect if aspect is not None else c.aspect)
        if c.ortho_height is not None:
            out.append(GltfCamera(name=name, position=np.asarray(c.eye, np.float64), forward=fwd, up=np.asarray(c.up, np.float64),
                              yfov=0.0, znear=float(c.near), zfar=float(c.far), type="orthographic",
                              xmag=float(c.ortho_height) / 2 * a, ymag=float(c.ortho_height) / 2, aspect=a))
        else:
            out.append(GltfCamera(name=name, position=np.asarray(c.eye, np.float64), forward=fwd, up=np.asarray(c.up, np.float64),
                              yfov=math.radians(float(c.fov_y)), aspect=a, znear=float(c.near), zfar=float(c.far)))
    return out


def terrain_levels(bundle, level):
    """``4``/``6``/``8`` (int) or per-edge levels ``(edges,)`` for ``"camera:NAME"`` (the bundle's LOD distances)."""

    if isinstance(level, str) and level.startswith("camera:"):
        cam = bundle.camera(level.split(":", 1)[1])
        lod = bundle.manifest.get("lod") or {}
        kw = {k: float(lod[k]) for k in ("near", "far") if k in lod}
        return edge_levels(bundle.net, cam.eye, **kw)
    try:
        lv = int(level)
    except (TypeError, ValueError):
        raise ConfigError(f"--level must be 4, 6, 8 or camera:NAME, got {level!r}") from None
    if lv not in (4, 6, 8):
        raise ConfigError(f"--level must be 4, 6, 8 or camera:NAME, got {level!r}")
    return lv


def bundle_parts(bundle, level=4, with_base_texture: bool = True) -> dict:
    """Keyword arguments of :func:`piste.formats.gltf.write.export_gltf` for a loaded bundle."""

    base = None
    if with_base_texture:
        base = bundle.arrays.get("terrain/base_texture")  # an SSX level's own textures (pipeline.ssx_level)
        if base is None:
            base = snow_texture()
    mesh = terrain_mesh(bundle.net, terrain_levels(bundle, level))
    parts = {"terrain": TerrainExport(mesh, bundle.lightmap.atlas, base)}
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
        names = [d.get("name") if isinstance(d, dict) else None for d in inst]
        if len(names) != len(objs.kind) or not all(names):
            names = None
        parts["objects"] = ObjectsExport(meshes, tuple(objs.kinds), objs.kind, objs.matrix, objs.texture, names)
    lights, other = piste_lights_to_gltf(bundle.lights)
    parts["lights"] = lights
    size = (bundle.manifest.get("render") or {}).get("size") or (640, 448)
    parts["cameras"] = piste_cameras_to_gltf(bundle.cameras, aspect=size[0] / size[1])
    parts["extras"] = {"piste_scene": bundle.name, "piste_ambient": other["ambient"],
                       "piste_negative_lights": other["negative"]}
    return parts


def export_bundle(bundle, path, level=4, instancing: str = "ext", with_base_texture: bool = True):
    """Write ``bundle`` as glTF (see :func:`piste.formats.gltf.write.export_gltf`); returns its ExportReport."""
    return export_gltf(path, instancing=instancing, **bundle_parts(bundle, level, with_base_texture))
