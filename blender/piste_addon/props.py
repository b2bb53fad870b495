"""The add-on's data: ``scene.piste`` (scene settings) and ``object.piste`` (per-object role),
PropertyGroups saved in the .blend like any Blender custom property, and the preferences."""

from __future__ import annotations

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty, PointerProperty,
                       StringProperty)

ADDON = __package__


class PistePreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON

    piste_path: StringProperty(name="piste executable", subtype="FILE_PATH", default="",
                               description="the 'piste' program, or the virtual environment piste is installed in "
                                           "(empty: $PISTE, then 'piste' on PATH)")

    def draw(self, context):
        self.layout.prop(self, "piste_path")


def _is_mesh(self, obj):
    return obj.type == "MESH"


class PisteSceneSettings(bpy.types.PropertyGroup):
    export_dir: StringProperty(name="Export folder", subtype="DIR_PATH", default="//piste",
                               description="the folder the scene .toml, its glTF and assets are written to")
    scene_name: StringProperty(name="Name", default="", description="the scene's name (default: the Blender scene's)")
    terrain_mode: EnumProperty(name="Terrain", default="OBJECT", items=[
        ("OBJECT", "Mesh object", "sample the terrain object's surface as a height field"),
        ("FILE", "File", "a terrain file piste reads (.pbd SSX level, height-field .png/.npz, .bpt, PatchNet .npz)"),
        ("DEFAULT", "Default course", "piste's seeded default course")])
    terrain_object: PointerProperty(name="Terrain object", type=bpy.types.Object, poll=_is_mesh)
    terrain_file: StringProperty(name="Terrain file", subtype="FILE_PATH", default="")
    terrain_spacing: FloatProperty(name="Sample spacing", default=0.0, min=0.0, unit="LENGTH",
                                   description="metres between height samples (0: the longer side / 64)")
    samples_per_patch: IntProperty(name="Samples per patch", default=4, min=3, max=64)
    smooth: BoolProperty(name="Smooth (C2) fit", default=False)
    seed: IntProperty(name="Seed", default=0, min=0)
    lod_preset: EnumProperty(name="LOD", default="AUTO", items=[
        ("AUTO", "Auto", "piste's default: the game's for an SSX level, else piste's"),
        ("piste", "piste", "60 / 180 m"), ("ssx_tricky", "SSX Tricky", "the game's 30 / 150 m (3000 / 15000 units)"),
        ("custom", "Custom", "switch distances given here")])
    lod_near: FloatProperty(name="Near", default=60.0, min=0.0, unit="LENGTH")
    lod_far: FloatProperty(name="Far", default=180.0, min=0.0, unit="LENGTH")
    lod_character: FloatVectorProperty(name="Rider LOD", size=2, default=(14.0, 35.0), min=0.0)
    lod_morph: BoolProperty(name="Geomorph", default=True)
    lightmap_res: IntProperty(name="Light-map texels", default=8, min=2, max=64)
    lightmap_shadows: BoolProperty(name="Terrain shadows", default=True)
    fog_mode: EnumProperty(name="Fog", default="AUTO", items=[
        ("AUTO", "Auto", "6e-4 per metre scaled to the scene"), ("OFF", "Off", "no fog"),
        ("DENSITY", "Density", "the density given here")])
    fog_density: FloatProperty(name="Density", default=6e-4, min=0.0, max=10.0, precision=5)
    visibility_enabled: BoolProperty(name="Visibility sets", default=True)
    visibility_cell: FloatProperty(name="Cell", default=50.0, min=1.0, unit="LENGTH")
    visibility_band: FloatVectorProperty(name="Eye band", size=2, default=(1.7, 9.0),
                                         description="eye heights (metres above the snow) the visibility sets sample")
    ambient_from_world: BoolProperty(name="Ambient from World colour", default=True)
    ambient_intensity: FloatProperty(name="Ambient", default=0.35, soft_min=0.0, soft_max=2.0)
    lightmap_mode: EnumProperty(name="Light maps", default="modulate", items=[
        ("modulate", "Modulate", ""), ("ps2", "PS2", "the game's half-bright blend")])
    preview_camera: PointerProperty(name="Preview camera", type=bpy.types.Object,
                                    poll=lambda self, o: o.type == "CAMERA")
    preview_debounce: FloatProperty(name="Debounce", default=0.3, min=0.05, max=5.0, unit="TIME_ABSOLUTE")
    writeback_out: StringProperty(name="Write back to", subtype="FILE_PATH", default="",
                                  description="the edited level's .pbd (default: LEVEL_edited.pbd beside the level)")


class PisteObjectSettings(bpy.types.PropertyGroup):
    role: EnumProperty(name="Role", default="AUTO", items=[
        ("AUTO", "Auto", "lights and cameras as themselves; other objects left out"),
        ("TERRAIN", "Terrain source", "the course's surface"),
        ("RIDER", "Rider", "a rider ([[riders]])"),
        ("OBJECT", "Object / instance", "an object placed on the course ([[objects]])"),
        ("IGNORE", "Ignore", "left out of the piste scene")])
    model: EnumProperty(name="Model", default="MESH", items=[
        ("MESH", "This mesh", "exported as a glTF model (objects sharing mesh data are instances of one model)"),
        ("builtin:rider", "Built-in rider", ""), ("builtin:tree", "Built-in tree", ""),
        ("builtin:sign", "Built-in sign", ""), ("builtin:rock", "Built-in rock", ""),
        ("builtin:rail", "Built-in rail", ""), ("FILE", "File", "a .gltf/.glb (or an SSX .mpf rider)")])
    model_file: StringProperty(name="Model file", subtype="FILE_PATH", default="")
    texture: StringProperty(name="Texture bank", subtype="FILE_PATH", default="",
                            description="an SSX .mpf rider's .ssh (default: beside it)")
    clip: StringProperty(name="Clip", default="ride")
    phase: FloatProperty(name="Phase", default=0.0, unit="TIME_ABSOLUTE")
    clips_from: StringProperty(name="Clips from", subtype="FILE_PATH", default="",
                               description="a .gltf/.glb whose clips are retargeted onto the model")
    bone_map: StringProperty(name="Bone map", default="builtin",
                             description="'builtin', or clip bone=model bone pairs separated by commas")
    light_kind: EnumProperty(name="piste light", default="AUTO", items=[
        ("AUTO", "As in Blender", "sun, point or spot through glTF (KHR_lights_punctual)"),
        ("AMBIENT", "Ambient", "the ambient term (colour x piste intensity)")])
    negative: BoolProperty(name="Negative", default=False,
                           description="a negative light: darkens what it lights (the talk's shadow lights)")
    piste_intensity: FloatProperty(name="piste intensity", default=1.0, soft_min=0.0, soft_max=4.0,
                                   description="intensity in piste's units for ambient and negative lights "
                                               "(glTF has neither)")
    piste_range: FloatProperty(name="Range", default=0.0, min=0.0, unit="LENGTH",
                               description="negative point/spot lights: metres to zero (0: the light's custom "
                                           "distance, else infinite)")


CLASSES = (PistePreferences, PisteSceneSettings, PisteObjectSettings)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)
    bpy.types.Scene.piste = PointerProperty(type=PisteSceneSettings)
    bpy.types.Object.piste = PointerProperty(type=PisteObjectSettings)


def unregister():
    del bpy.types.Object.piste
    del bpy.types.Scene.piste
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
