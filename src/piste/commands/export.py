"""``piste export SCENE OUT.glb``: a scene (.toml, built first with the cache) or a bundle (.piste) to glTF.

Writes the terrain (tessellated at ``--level`` 4, 6 or 8 vertices per edge, or at the LOD a named
camera sees with ``--level camera:NAME``), its light-map atlas (occlusion texture on TEXCOORD_1)
and base texture, the riders as skinned meshes with their clips, the objects as instanced nodes
(``--instancing ext|nodes``), the lights (KHR_lights_punctual) and the cameras.  The format's
conventions are in :mod:`piste.formats.gltf_export`; this module is the glue from a bundle.

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

WHITE_LUX = 683.0
#: distance (m) at which a piste light without fall-off is matched by an inverse-square glTF light
INFINITE_RANGE_MATCH = 10.0


def add_arguments(parser) -> None:
    from piste.commands import _numbers as N

    parser.add_argument("scene", help="a scene (.toml), a bundle (.piste) or an SSX level (.pbd)")
    parser.add_argument("out", help="output .glb (one file) or .gltf (JSON + .bin)")
    parser.add_argument("--level", default="4",
                        help="terrain tessellation: 4, 6 or 8 vertices per edge, or camera:NAME for the per-edge LOD "
                             "that camera sees (default: 4)")
    parser.add_argument("--instancing", choices=("ext", "nodes"), default="ext",
                        help="objects as EXT_mesh_gpu_instancing nodes (ext, default) or one plain node per instance")
    parser.add_argument("--no-base-texture", action="store_true", help="leave out the terrain's snow texture")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.add_argument("--riders", type=N.integer(0, 64), default=0, metavar="N",
                        help="stand N default riders on the terrain of a source without riders of its own (an SSX level)")
    parser.add_argument("--add-objects", type=N.integer(0, 10_000), default=0, metavar="N",
                        help="place N of the course's objects (trees, rocks, signs, rails) on the terrain of a source "
                             "without objects of its own (an SSX level, a tiled world)")


def piste_lights_to_gltf(lights, white: float = WHITE_LUX):
    """KHR_lights_punctual lights (:class:`piste.character.Light`, glTF units) for piste ``Lights``,
    and ``{"ambient": [...], "negative": [...]}`` the lights glTF cannot hold, as dicts (see the
    module docstring)."""
    from piste.character import Light
    from piste.lighting.lights import AmbientLight, DirectionalLight, PointLight, SpotLight

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
            out.append(Light(name=name, type="directional", color=color, intensity=float(li.intensity) * white,
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
            out.append(Light(name=name, type="spot", color=color, intensity=cd, range=grange,
                             inner_cone=math.radians(li.inner_angle), outer_cone=math.radians(li.outer_angle),
                             position=np.asarray(li.position, dtype=np.float64),
                             direction=np.asarray(li.direction, dtype=np.float64)))
        elif isinstance(li, PointLight):
            out.append(Light(name=name, type="point", color=color, intensity=cd, range=grange,
                             position=np.asarray(li.position, dtype=np.float64)))
    return out, {"ambient": ambient, "negative": negative}


def piste_cameras_to_gltf(cameras: dict, aspect: float | None = None) -> list:
    """:class:`piste.character.Camera` items for ``{name: piste.world.camera.Camera}``."""
    from piste.character import Camera

    out = []
    for name, c in cameras.items():
        fwd = np.asarray(c.target, dtype=np.float64) - np.asarray(c.eye, dtype=np.float64)
        fwd = fwd / max(np.linalg.norm(fwd), 1e-300)
        a = float(aspect if aspect is not None else c.aspect)
        if c.ortho_height is not None:
            out.append(Camera(name=name, position=np.asarray(c.eye, np.float64), forward=fwd, up=np.asarray(c.up, np.float64),
                              yfov=0.0, znear=float(c.near), zfar=float(c.far), type="orthographic",
                              xmag=float(c.ortho_height) / 2 * a, ymag=float(c.ortho_height) / 2, aspect=a))
        else:
            out.append(Camera(name=name, position=np.asarray(c.eye, np.float64), forward=fwd, up=np.asarray(c.up, np.float64),
                              yfov=math.radians(float(c.fov_y)), aspect=a, znear=float(c.near), zfar=float(c.far)))
    return out


def terrain_levels(bundle, level):
    """``4``/``6``/``8`` (int) or per-edge levels ``(edges,)`` for ``"camera:NAME"`` (the bundle's LOD distances)."""
    from piste.errors import ConfigError

    if isinstance(level, str) and level.startswith("camera:"):
        from piste.terrain.lod import edge_levels

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
    """Keyword arguments of :func:`piste.formats.gltf_export.export_gltf` for a loaded bundle."""
    from piste.formats.gltf_export import CharacterExport, ObjectsExport, TerrainExport
    from piste.pipeline.characters import model_from_arrays

    base = None
    if with_base_texture:
        from piste.render.textures import snow_texture

        base = bundle.arrays.get("terrain/base_texture")  # an SSX level's own textures (pipeline.ssx_level)
        if base is None:
            base = snow_texture()
    parts = {"terrain": TerrainExport(bundle.net, bundle.lightmap.atlas, terrain_levels(bundle, level), base)}
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
    """Write ``bundle`` as glTF (see :func:`piste.formats.gltf_export.export_gltf`); returns its ExportReport."""
    from piste.formats.gltf_export import export_gltf

    return export_gltf(path, instancing=instancing, **bundle_parts(bundle, level, with_base_texture))


def run(args) -> int:
    from piste.errors import ConfigError
    from piste.pipeline.open_scene import open_source, source_kind

    if source_kind(args.scene) == "tiles":
        raise ConfigError(f"{args.scene}: a tiled world is streamed tile by tile; export a scene, a bundle or an "
                          "SSX level (a whole world in one glTF file is not supported)")
    b = open_source(args.scene, quiet=args.quiet, riders=args.riders, objects=args.add_objects)
    r = export_bundle(b, args.out, level=args.level, instancing=args.instancing,
                      with_base_texture=not args.no_base_texture)
    print(f"wrote {', '.join(str(f) for f in r.files)} ({r.bytes / 1e6:.2f} MB): terrain {r.terrain_triangles:,} triangles, "
          f"{r.characters} riders ({r.animations} clips), {r.objects} objects"
          + (f" ({r.baked_objects} baked)" if r.baked_objects else "")
          + f", {r.lights} lights, {r.cameras} cameras")
    return 0
