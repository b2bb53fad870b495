"""Export: the Blender scene as piste's inputs -- a scene ``.toml``, a glTF of the lights and
cameras (Blender's own glTF exporter, read back by piste's ``[[gltf]]`` import), a height-field
``.npz`` sampled from the terrain object, one glTF model per mesh used by objects, and copies of
the files riders and the terrain name -- all in one folder, so ``piste build SCENE.toml`` works.

Axes: piste's are Blender's (metres, +Z up).  piste's height fields start at (0, 0), so the whole
scene is shifted by minus the terrain object's lowest x, y corner (the ``[[gltf]]`` ``offset``
carries the same shift for the lights and cameras)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import bpy
from mathutils import Vector
from mathutils.bvhtree import BVHTree

from .scene_toml import dumps_scene, heightfield_npz_bytes, write_if_changed

INLINE = "inline"


def export_dir(context) -> Path:
    s = context.scene.piste
    path = bpy.path.abspath(s.export_dir or "//piste")
    if path.startswith("//") or not path:
        raise ValueError("save the .blend first or give the piste export folder as an absolute path")
    return Path(path)


def scene_name(context) -> str:
    return bpy.path.clean_name(context.scene.piste.scene_name or context.scene.name)


def scene_path(context) -> Path:
    return export_dir(context) / f"{scene_name(context)}.toml"


def _role(obj) -> str:
    return obj.piste.role if hasattr(obj, "piste") else "AUTO"


def terrain_object(context):
    s = context.scene.piste
    if s.terrain_mode != "OBJECT":
        return None
    if s.terrain_object is not None:
        return s.terrain_object
    return next((o for o in context.scene.objects if o.type == "MESH" and _role(o) == "TERRAIN"), None)


def _is_inline_light(obj) -> bool:
    return obj.piste.light_kind == "AMBIENT" or obj.piste.negative


def _copy_asset(src, out: Path, siblings=()) -> str:
    """Copy ``src`` (and its sibling files that exist) into ``out/assets``; the scene-relative path."""
    src = Path(bpy.path.abspath(src))
    if not src.is_file():
        raise ValueError(f"{src}: no such file")
    assets = out / "assets"
    assets.mkdir(parents=True, exist_ok=True)
    for p in (src, *siblings):
        p = Path(p)
        if p.is_file():
            write_if_changed(assets / p.name, p.read_bytes())
    if src.suffix.lower() == ".gltf":  # its buffers and images
        doc = json.loads(src.read_text())
        for item in doc.get("buffers", []) + doc.get("images", []):
            uri = item.get("uri", "")
            if uri and not uri.startswith("data:"):
                if Path(uri).is_absolute() or ".." in Path(uri).parts or "%" in uri:
                    raise ValueError(f"{src}: buffer/image uri {uri!r} is not a plain path beside the file "
                                     "(piste reads only files inside the model's folder): export it as .glb")
                dst = assets / uri
                dst.parent.mkdir(parents=True, exist_ok=True)
                write_if_changed(dst, (src.parent / uri).read_bytes())
    return f"assets/{src.name}"


def _level_siblings(src) -> list:
    src = Path(bpy.path.abspath(src))
    return [src.with_suffix(".ssh"), src.with_name(src.stem + "_L.ssh")]


def _heightfield(context, obj, out: Path) -> tuple:
    """Sample ``obj``'s evaluated surface on a grid; writes ``assets/NAME_terrain.npz``; returns
    ``(relative path, (x0, y0) shift origin)``."""
    s = context.scene.piste
    dg = context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(dg)
    mesh = ev.to_mesh()
    try:
        mw = ev.matrix_world
        verts = [mw @ v.co for v in mesh.vertices]
        polys = [tuple(p.vertices) for p in mesh.polygons]
    finally:
        ev.to_mesh_clear()
    if not polys:
        raise ValueError(f"terrain object {obj.name!r} has no faces")
    x0, x1 = min(v.x for v in verts), max(v.x for v in verts)
    y0, y1 = min(v.y for v in verts), max(v.y for v in verts)
    z0, z1 = min(v.z for v in verts), max(v.z for v in verts)
    spp = s.samples_per_patch
    step = s.terrain_spacing or max(x1 - x0, y1 - y0) / 64.0
    cols = max(1, int((x1 - x0) / step + 1e-6) // spp) * spp + 1
    rows = max(1, int((y1 - y0) / step + 1e-6) // spp) * spp + 1
    tree = BVHTree.FromPolygons(verts, polys)
    top, down = z1 + 1.0, Vector((0.0, 0.0, -1.0))
    eps = 1e-5 * step  # rays exactly on the mesh's outer edges can miss: nudged inside
    z = []
    for i in range(rows):
        row = []
        for j in range(cols):
            x, y = min(max(x0 + j * step, x0 + eps), x1 - eps), min(max(y0 + i * step, y0 + eps), y1 - eps)
            hit = tree.ray_cast(Vector((x, y, top)), down)
            row.append(hit[0].z if hit[0] is not None else None)
        z.append(row)
    for row in z:  # misses (holes, a ragged edge): the nearest hit in the row, else the lowest point
        for j, h in enumerate(row):
            if h is None:
                near = [(abs(k - j), v) for k, v in enumerate(row) if v is not None]
                row[j] = min(near)[1] if near else z0
    rel = f"assets/{bpy.path.clean_name(obj.name)}_terrain.npz"
    write_if_changed(out / rel, heightfield_npz_bytes(z, step, step))
    return rel, (x0, y0)


def _model_glb(context, obj, out: Path) -> str:
    """``obj``'s mesh (modifiers applied, materials, at the identity transform) as ``assets/MESH.glb``."""
    name = bpy.path.clean_name(obj.data.name)
    rel = f"assets/{name}.glb"
    tmp = out / "assets" / f".{name}.export.glb"
    tmp.parent.mkdir(parents=True, exist_ok=True)
    saved = obj.matrix_world.copy()
    with _selection(context, [obj]):
        try:
            obj.matrix_world = ((1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1))
            bpy.ops.export_scene.gltf(filepath=str(tmp), export_format="GLB", use_selection=True, export_apply=True,
                                      export_cameras=False, export_lights=False, export_animations=False)
        finally:
            obj.matrix_world = saved
    _move_if_changed(tmp, out / rel)
    return rel


def _move_if_changed(tmp: Path, dst: Path) -> None:
    try:
        write_if_changed(dst, tmp.read_bytes())
    finally:
        tmp.unlink(missing_ok=True)


class _selection:
    def __init__(self, context, objects):
        self.context, self.objects = context, objects

    def __enter__(self):
        vl = self.context.view_layer
        self.saved = [o for o in vl.objects if o.select_get()]
        self.active = vl.objects.active
        for o in self.saved:
            o.select_set(False)
        for o in self.objects:
            o.select_set(True)

    def __exit__(self, *exc):
        for o in self.objects:
            o.select_set(False)
        for o in self.saved:
            o.select_set(True)
        self.context.view_layer.objects.active = self.active


def _lights_cameras_gltf(context, objects, out: Path, name: str) -> str | None:
    if not objects:
        return None
    rel = f"{name}_lights_cameras.gltf"
    tmp = out / f".{name}.export.gltf"
    with _selection(context, objects):
        kw = {"convert_lighting_mode": "SPEC"} if "convert_lighting_mode" in \
            bpy.ops.export_scene.gltf.get_rna_type().properties.keys() else {}
        bpy.ops.export_scene.gltf(filepath=str(tmp), export_format="GLTF_SEPARATE", use_selection=True,
                                  export_cameras=True, export_lights=True, export_animations=False, **kw)
    _move_if_changed(tmp, out / rel)
    return rel


def _xy(obj, shift) -> list:
    p = obj.matrix_world.translation
    return [round(p.x + shift[0], 6), round(p.y + shift[1], 6)]


def _heading(obj) -> float:
    return round(math.degrees(obj.matrix_world.to_euler("XYZ").z), 6)


def _scale(obj) -> float:
    sc = obj.matrix_world.to_scale()
    return round(abs(sc.x * sc.y * sc.z) ** (1.0 / 3.0), 6)


def _bone_map(text: str):
    text = text.strip()
    if not text or text == "builtin":
        return "builtin"
    pairs = {}
    for item in text.split(","):
        if "=" not in item:
            raise ValueError(f"bone map {text!r}: expected 'builtin' or clip bone=model bone pairs")
        a, b = item.split("=", 1)
        pairs[a.strip()] = b.strip()
    return pairs


def _inline_light(obj, shift) -> dict:
    ps, data = obj.piste, obj.data
    color = [round(c, 6) for c in data.color]
    if ps.light_kind == "AMBIENT":
        return {"type": "ambient", "name": obj.name, "color": color, "intensity": round(ps.piste_intensity, 6)}
    intensity = round(-abs(ps.piste_intensity) if ps.negative else ps.piste_intensity, 6)
    d = obj.matrix_world.to_3x3() @ Vector((0.0, 0.0, -1.0))
    direction = [round(x, 6) for x in d.normalized()]
    if data.type == "SUN":
        return {"type": "directional", "name": obj.name, "direction": direction, "color": color,
                "intensity": intensity}
    p = obj.matrix_world.translation
    light = {"type": "spot" if data.type == "SPOT" else "point", "name": obj.name,
             "position": [round(p.x + shift[0], 6), round(p.y + shift[1], 6), round(p.z, 6)],
             "color": color, "intensity": intensity}
    rng = ps.piste_range or (getattr(data, "cutoff_distance", 0.0) if getattr(data, "use_custom_distance", False) else 0.0)
    if rng > 0:
        light["range"] = round(rng, 6)
    if data.type == "SPOT":
        light["direction"] = direction
        outer = math.degrees(data.spot_size) / 2.0
        light["outer_angle"] = round(outer, 6)
        light["inner_angle"] = round(outer * (1.0 - data.spot_blend), 6)
    return light


def gather(context, out: Path) -> dict:
    """Write the assets into ``out`` and return the scene ``dict`` (:mod:`.scene_toml`)."""
    sc, s = context.scene, context.scene.piste
    name = scene_name(context)
    scene = {"name": sc.piste.scene_name or sc.name}
    shift = (0.0, 0.0)
    terrain = {}
    tobj = terrain_object(context)
    if s.terrain_mode == "OBJECT":
        if tobj is None:
            raise ValueError("no terrain: pick a terrain object in the piste panel (or give the role "
                             "'Terrain source' to a mesh), or choose a terrain file or the default course")
        rel, (x0, y0) = _heightfield(context, tobj, out)
        shift = (-x0, -y0)
        terrain = {"source": rel, "samples_per_patch": s.samples_per_patch, "smooth": s.smooth}
    elif s.terrain_mode == "FILE":
        if not s.terrain_file:
            raise ValueError("terrain mode 'File' needs a terrain file")
        src = s.terrain_file
        rel = _copy_asset(src, out, _level_siblings(src) if src.lower().endswith(".pbd") else ())
        terrain = {"source": rel}
    else:
        terrain = {"source": "default", "seed": s.seed}
    scene["terrain"] = terrain
    scene["lightmap"] = {"res": s.lightmap_res, "shadows": s.lightmap_shadows}
    lod = {"near": s.lod_near, "far": s.lod_far} if s.lod_preset == "custom" else \
        {"preset": s.lod_preset} if s.lod_preset != "AUTO" else {}
    lod.update({"character": [round(x, 6) for x in s.lod_character], "morph": s.lod_morph})
    scene["lod"] = lod
    scene["visibility"] = {"enabled": s.visibility_enabled, "cell": round(s.visibility_cell, 6),
                           "eye_heights": [round(x, 6) for x in s.visibility_band]}
    r = sc.render
    size = [max(16, int(r.resolution_x * r.resolution_percentage / 100)),
            max(16, int(r.resolution_y * r.resolution_percentage / 100))]
    fog = {"AUTO": "auto", "OFF": 0.0, "DENSITY": s.fog_density}[s.fog_mode]
    scene["render"] = {"size": size, "lightmap_mode": s.lightmap_mode, "fog": fog}

    objs = [o for o in sc.objects if _role(o) != "IGNORE" and o.visible_get()]
    gltf_objs = [o for o in objs if (o.type == "CAMERA" and _role(o) in ("AUTO",))
                 or (o.type == "LIGHT" and _role(o) == "AUTO" and not _is_inline_light(o))]
    rel = _lights_cameras_gltf(context, gltf_objs, out, name)
    if rel:
        scene["gltf"] = [{"file": rel, "lights": True, "cameras": True, "offset": [shift[0], shift[1], 0.0]}]
    riders, objects = [], []
    for o in sorted(objs, key=lambda o: o.name):
        ps = o.piste
        if ps.role == "RIDER":
            item = {"name": o.name}
            if ps.model == "FILE":
                if not ps.model_file:
                    raise ValueError(f"rider {o.name!r}: model 'File' needs a model file")
                mpf = ps.model_file.lower().endswith(".mpf")
                sib = [Path(bpy.path.abspath(ps.model_file)).with_suffix(".ssh")] if mpf else []
                rel = _copy_asset(ps.model_file, out, sib)
                item["model"] = ("ssx:" + rel) if mpf else rel
                if ps.texture:
                    item["texture"] = _copy_asset(ps.texture, out)
            else:
                item["model"] = "builtin:rider"
            item.update({"position": _xy(o, shift), "heading": _heading(o), "clip": ps.clip or "ride",
                         "phase": round(ps.phase, 6)})
            if ps.clips_from:
                item["clips_from"] = _copy_asset(ps.clips_from, out)
                item["bone_map"] = _bone_map(ps.bone_map)
            sc_ = _scale(o)
            if abs(sc_ - 1.0) > 1e-6:
                item["scale"] = sc_
            riders.append(item)
        elif ps.role == "OBJECT":
            if ps.model == "MESH":
                if o.type != "MESH":
                    raise ValueError(f"object {o.name!r}: model 'This mesh' needs a mesh object")
                model = _model_glb(context, o, out)
            elif ps.model == "FILE":
                model = _copy_asset(ps.model_file, out)
            elif ps.model == "builtin:rider":
                raise ValueError(f"object {o.name!r}: the built-in rider is a rider's model (role 'Rider')")
            else:
                model = ps.model
            objects.append({"name": o.name, "model": model, "position": _xy(o, shift), "heading": _heading(o),
                            "scale": _scale(o)})
    if riders:
        scene["riders"] = riders
    if objects:
        scene["objects"] = objects
    lights = []
    if s.ambient_from_world and sc.world is not None:
        col = list(sc.world.color)
        lights.append({"type": "ambient", "name": "World", "color": [round(c, 6) for c in col],
                       "intensity": round(s.ambient_intensity, 6)})
    lights += [_inline_light(o, shift) for o in sorted(objs, key=lambda o: o.name)
               if o.type == "LIGHT" and _role(o) == "AUTO" and _is_inline_light(o)]
    if lights:
        scene["lights"] = lights
    return scene


HEADER = ("Written by the piste Blender add-on (Export): edit the .blend, not this file.\n"
          "  piste build {name}.toml && piste render {name}.piste --out {name}.png")


def export_scene(context) -> Path:
    """Export the scene into its folder; returns the ``.toml`` path."""
    out = export_dir(context)
    out.mkdir(parents=True, exist_ok=True)
    scene = gather(context, out)
    path = out / f"{scene_name(context)}.toml"
    write_if_changed(path, dumps_scene(scene, HEADER.format(name=scene_name(context))).encode())
    return path


class PISTE_OT_export(bpy.types.Operator):
    """Write the piste scene (.toml), its glTF and assets into the export folder"""
    bl_idname = "piste.export"
    bl_label = "Export piste scene"
    bl_options = {"REGISTER"}

    def execute(self, context):
        try:
            path = export_scene(context)
        except (ValueError, OSError) as exc:
            self.report({"ERROR"}, f"piste export: {exc}")
            return {"CANCELLED"}
        context.scene["piste_last_export"] = str(path)
        self.report({"INFO"}, f"piste: wrote {path}")
        return {"FINISHED"}


CLASSES = (PISTE_OT_export,)
