"""Run inside headless Blender by tests/blender/test_addon.py (not collected by pytest: no test_ prefix).

``blender -b --factory-startup --python addon_driver.py -- CONFIG.json``: installs the add-on from
the zip, then does the config's ``steps`` in order and writes what it saw to ``config["result"]``:

* ``scene``: builds the small scene (terrain mesh, two riders, a camera, three lights), presses Export;
* ``preview``: starts the headless preview for ``frames`` frames, moves a light, lets the debounced
  re-export run and waits for the view to write its frames (the image "piste preview" loaded);
* ``import``: imports each file of ``imports`` (bundle, level, rider) and records objects and materials;
* ``writeback``: moves one control point of the imported level's cage and writes the level back;
* ``screenshot``: renders the scene with Workbench to ``screenshot`` (for the docs).
"""

import json
import math
import sys
import time
import traceback

import bpy
from mathutils import Matrix, Vector

cfg = json.loads(open(sys.argv[sys.argv.index("--") + 1]).read())
result = {"steps": [], "errors": []}


def height(x, y):
    return 0.25 * (100.0 - y) + 4.0 * math.sin(x / 15.0) * math.cos(y / 20.0)


def clear():
    for coll in (bpy.data.objects, bpy.data.meshes, bpy.data.lights, bpy.data.cameras, bpy.data.images,
                 bpy.data.materials, bpy.data.armatures, bpy.data.actions):
        for item in list(coll):
            coll.remove(item)


def build_scene():
    clear()
    sc = bpy.context.scene
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = 320, 224, 100
    n, step, x0, y0 = cfg["grid"], cfg["spacing"], cfg["origin"][0], cfg["origin"][1]
    verts = [(x0 + j * step, y0 + i * step, height(j * step, i * step)) for i in range(n) for j in range(n)]
    faces = [(i * n + j, i * n + j + 1, (i + 1) * n + j + 1, (i + 1) * n + j) for i in range(n - 1) for j in range(n - 1)]
    mesh = bpy.data.meshes.new("snow")
    mesh.from_pydata(verts, [], faces)
    terrain = bpy.data.objects.new("Terrain", mesh)
    sc.collection.objects.link(terrain)
    terrain.piste.role = "TERRAIN"
    for r in cfg["riders"]:
        bpy.ops.mesh.primitive_cone_add(radius1=0.6, depth=1.8)  # a stand-in the artist sees
        o = bpy.context.active_object
        o.name = r["name"]
        o.data.transform(Matrix.Translation((0.0, 0.0, 0.9)))
        o.color = (1.0, 0.45, 0.1, 1.0)
        o.location = (x0 + r["position"][0], y0 + r["position"][1], height(*r["position"]))  # on the snow
        o.rotation_euler.z = math.radians(r["heading"])
        o.piste.role, o.piste.model, o.piste.clip, o.piste.phase = "RIDER", "builtin:rider", r["clip"], r["phase"]
    hut = bpy.data.meshes.new("Hut")  # one mesh, two objects using it: instances of one model
    hut.from_pydata([(x, y, z) for z in (0.0, 3.0) for y in (-2.0, 2.0) for x in (-2.0, 2.0)], [],
                    [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)])
    for ob in cfg["objects"]:
        o = bpy.data.objects.new(ob["name"], hut if ob["model"] == "mesh" else None)
        sc.collection.objects.link(o)
        o.location = (x0 + ob["position"][0], y0 + ob["position"][1], height(*ob["position"]))
        o.rotation_euler.z = math.radians(ob["heading"])
        o.scale = (ob["scale"],) * 3
        o.piste.role, o.piste.model = "OBJECT", "MESH" if ob["model"] == "mesh" else ob["model"]
    c = cfg["camera"]
    cam = bpy.data.objects.new(c["name"], bpy.data.cameras.new(c["name"]))
    sc.collection.objects.link(cam)
    eye, target = Vector(c["eye"]) + Vector((x0, y0, 0)), Vector(c["target"]) + Vector((x0, y0, 0))
    cam.location = eye
    cam.rotation_euler = (target - eye).to_track_quat("-Z", "Y").to_euler()
    cam.data.sensor_fit, cam.data.angle_y = "VERTICAL", math.radians(c["fov"])
    cam.data.clip_start, cam.data.clip_end = c["near"], c["far"]
    sc.camera = cam
    lights = {}
    for L in cfg["lights"]:
        kind = {"directional": "SUN", "point": "POINT", "ambient": "POINT"}[L["type"]]
        o = bpy.data.objects.new(L["name"], bpy.data.lights.new(L["name"], kind))
        sc.collection.objects.link(o)
        o.data.color = L["color"]
        if L["type"] == "directional":
            o.data.energy = L["intensity"]
            o.rotation_euler = Vector(L["direction"]).to_track_quat("-Z", "Y").to_euler()
        elif L["type"] == "ambient":
            o.piste.light_kind, o.piste.piste_intensity = "AMBIENT", L["intensity"]
        else:
            o.location = Vector(L["position"]) + Vector((x0, y0, 0))
            o.piste.negative, o.piste.piste_intensity, o.piste.piste_range = True, -L["intensity"], L["range"]
        lights[L["name"]] = o
    s = sc.piste
    s.export_dir, s.scene_name = cfg["out"], "authored"
    s.terrain_spacing, s.ambient_from_world = step, False
    s.lod_preset, s.lightmap_res, s.fog_mode = "ssx_tricky", 8, "OFF"
    s.visibility_cell, s.preview_camera = 40.0, cam
    bpy.context.view_layer.update()
    return terrain, lights


class FakeLayout:
    """Stands in for a panel's layout (no UI in background mode): every prop must exist, every operator be registered."""

    def __init__(self, seen):
        self.seen = seen

    def prop(self, data, name, **kw):
        assert name in data.bl_rna.properties, f"{type(data).__name__} has no property {name!r}"
        self.seen.append(name)

    def operator(self, idname, **kw):
        mod, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, mod), name) and getattr(getattr(bpy.ops, mod), name).get_rna_type(), idname
        self.seen.append(idname)

    def column(self, **kw):
        return self

    row = box = column

    def label(self, **kw):
        pass

    def separator(self, **kw):
        pass


def draw_panels():
    """Draw the three panels for each kind of active object and each terrain mode (what they show)."""
    from piste_addon import ui
    seen = []
    sc = bpy.context.scene
    for mode in ("OBJECT", "FILE", "DEFAULT"):
        sc.piste.terrain_mode = mode
        ui.PISTE_PT_scene.draw(type("P", (), {"layout": FakeLayout(seen)})(), bpy.context)
    sc.piste.terrain_mode = "OBJECT"
    for name in ("Terrain", "lead", "hut1", "Sun", "Sky", "Shadow", "Overview"):
        bpy.context.view_layer.objects.active = bpy.data.objects[name]
        ui.PISTE_PT_object.draw(type("P", (), {"layout": FakeLayout(seen)})(), bpy.context)
    ui.PISTE_PT_actions.draw(type("P", (), {"layout": FakeLayout(seen)})(), bpy.context)
    result["panel_items"] = sorted(set(seen))


def step_scene():
    build_scene()
    draw_panels()
    assert bpy.ops.piste.export() == {"FINISHED"}
    result["toml"] = bpy.context.scene["piste_last_export"]


def step_preview():
    from piste_addon import preview
    bpy.context.scene.piste.export_dir = cfg["out"] + "_preview"  # the exported scene stays as it was
    t0 = time.monotonic()
    proc = preview.start(bpy.context, headless=True, frames=cfg["frames"], seconds=120)
    frames_dir = preview.state.frames_dir
    while not (frames_dir / "frame_0000.png").exists() and proc.poll() is None and time.monotonic() - t0 < 120:
        time.sleep(0.1)
    preview.tick()
    result["first_frame_loaded"] = bpy.data.images.get(preview.IMAGE) is not None
    exports_before = preview.state.exports
    # an artist moves the sun: the depsgraph handler marks the scene dirty, the timer re-exports
    sun = bpy.data.objects[cfg["move_light"]]
    t_move = time.monotonic()
    sun.rotation_euler.x += 0.6
    bpy.context.view_layer.update()
    result["marked_dirty"] = preview.state.dirty_since is not None
    time.sleep(bpy.context.scene.piste.preview_debounce + 0.05)
    preview.tick()
    result["reexports"] = preview.state.exports - exports_before
    while not (frames_dir / "frame_0001.png").exists() and proc.poll() is None and time.monotonic() - t0 < 120:
        time.sleep(0.02)
    result["change_to_frame_s"] = time.monotonic() - t_move  # reported, never asserted
    while proc.poll() is None and time.monotonic() - t0 < 120:
        time.sleep(0.1)
    result["view_exit"] = proc.returncode
    result["frames"] = sorted(p.name for p in frames_dir.glob("frame_*.png"))
    preview.tick()
    img = bpy.data.images.get(preview.IMAGE)
    result["preview_image"] = [img.filepath, list(img.size)] if img else None
    preview.stop()


def step_import():
    from piste_addon import importer
    clear()
    bpy.context.scene.piste.export_dir = cfg["out"]
    result["imports"] = {}
    for key, path in cfg["imports"].items():
        images = set(bpy.data.images)
        new = importer.import_file(bpy.context, path)
        info = {"objects": len(new), "meshes": sorted(o.name for o in new if o.type == "MESH"),
                "armatures": sum(o.type == "ARMATURE" for o in new),
                "materials": sorted({s.material.name for o in new if o.type == "MESH"
                                     for s in o.material_slots if s.material}),
                "images": len(set(bpy.data.images) - images)}
        meshes = [o for o in new if o.type == "MESH"]
        info["placed"] = {o.name: [list(o.matrix_world.translation), math.degrees(o.matrix_world.to_euler().z),
                                   o.data.name] for o in meshes}
        if meshes:
            pts = [o.matrix_world @ Vector(b) for o in meshes for b in o.bound_box]
            info["bounds"] = [[min(p[i] for p in pts) for i in range(3)], [max(p[i] for p in pts) for i in range(3)]]
        cage = next((o for o in new if "piste_ssx_project" in o), None)
        if cage is not None:
            info["cage_vertices"] = len(cage.data.vertices)
            info["cage_bounds"] = [[min(v.co[i] for v in cage.data.vertices) for i in range(3)],
                                   [max(v.co[i] for v in cage.data.vertices) for i in range(3)]]
            info["cage"] = cage.name
        result["imports"][key] = info


def step_writeback():
    from piste_addon import importer
    cage = bpy.data.objects[result["imports"]["level"]["cage"]]
    mesh = cage.data
    # the artist raises the level's highest point (every patch corner there: they are welded in the game)
    top = max(mesh.vertices, key=lambda v: v.co.z).co.copy()
    moved = [v.index for v in mesh.vertices if (v.co - top).length < 1e-3]
    for i in moved:
        mesh.vertices[i].co.z += cfg["edit_dz"]
    # and shifts patch 0's first corner UV
    layer = mesh.uv_layers["UVPoints"]
    for li, loop in enumerate(mesh.loops):
        if loop.vertex_index == 0:
            layer.data[li].uv = (layer.data[li].uv[0] + cfg["edit_du"], layer.data[li].uv[1])
    out, changed = importer.write_back(bpy.context, cage, cfg["writeback"])
    result["writeback"] = {"out": str(out), "changed": changed, "moved": moved, "top": list(top)}


def step_level_scene():
    """A scene on an SSX level (terrain file): the level and its banks copied beside the scene."""
    clear()
    sc = bpy.context.scene
    s = sc.piste
    s.export_dir, s.scene_name, s.terrain_mode, s.terrain_file = cfg["out"], "on_level", "FILE", cfg["imports"]["level"]
    s.lod_preset, s.ambient_from_world = "AUTO", True
    o = bpy.data.objects.new("rider", None)
    sc.collection.objects.link(o)
    o.location = (12.0, 10.0, 0.0)
    o.piste.role, o.piste.model = "RIDER", "builtin:rider"
    assert bpy.ops.piste.export() == {"FINISHED"}
    result["level_toml"] = sc["piste_last_export"]
    s.terrain_file = cfg["out"] + "/missing.pbd"
    try:
        result["missing_terrain"] = sorted(bpy.ops.piste.export())
    except RuntimeError as exc:  # an operator's ERROR report, called from Python
        result["missing_terrain"] = str(exc)


def step_screenshot():
    sc = bpy.context.scene
    sc.render.engine = "BLENDER_WORKBENCH"
    sc.display.shading.light = "STUDIO"
    sc.display.shading.color_type = "OBJECT"
    bpy.data.objects["Terrain"].color = (0.85, 0.9, 1.0, 1.0)
    if sc.world is None:
        sc.world = bpy.data.worlds.new("World")
    sc.world.color = (0.45, 0.55, 0.75)
    sc.render.filepath = cfg["screenshot"]
    bpy.ops.render.render(write_still=True)
    result["screenshot"] = cfg["screenshot"]


try:
    bpy.ops.preferences.addon_install(filepath=cfg["zip"], overwrite=True)
    bpy.ops.preferences.addon_enable(module="piste_addon")
    bpy.context.preferences.addons["piste_addon"].preferences.piste_path = cfg["piste"]
    for name in cfg["steps"]:
        globals()["step_" + name]()
        result["steps"].append(name)
except Exception:
    result["errors"].append(traceback.format_exc())
with open(cfg["result"], "w") as fh:
    json.dump(result, fh, indent=1)
