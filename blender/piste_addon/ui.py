"""The "piste" tab of the 3D View's sidebar (N): scene settings, the active object's role, and
Export / Preview / Import / Write back."""

from __future__ import annotations

import bpy

from . import preview


class _Panel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "piste"


class PISTE_PT_scene(_Panel, bpy.types.Panel):
    bl_label = "piste scene"

    def draw(self, context):
        s, col = context.scene.piste, self.layout.column()
        col.prop(s, "export_dir")
        col.prop(s, "scene_name")
        col.prop(s, "terrain_mode")
        if s.terrain_mode == "OBJECT":
            col.prop(s, "terrain_object")
            col.prop(s, "terrain_spacing")
            col.prop(s, "samples_per_patch")
            col.prop(s, "smooth")
        elif s.terrain_mode == "FILE":
            col.prop(s, "terrain_file")
        else:
            col.prop(s, "seed")
        box = col.box()
        box.prop(s, "lod_preset")
        if s.lod_preset == "custom":
            row = box.row()
            row.prop(s, "lod_near")
            row.prop(s, "lod_far")
        box.prop(s, "lod_character")
        box.prop(s, "lod_morph")
        box = col.box()
        box.prop(s, "lightmap_res")
        box.prop(s, "lightmap_shadows")
        box.prop(s, "lightmap_mode")
        box.prop(s, "ambient_from_world")
        box.prop(s, "ambient_intensity")
        box = col.box()
        box.prop(s, "fog_mode")
        if s.fog_mode == "DENSITY":
            box.prop(s, "fog_density")
        box.prop(s, "visibility_enabled")
        box.prop(s, "visibility_cell")
        box.prop(s, "visibility_band")


class PISTE_PT_object(_Panel, bpy.types.Panel):
    bl_label = "piste object"

    @classmethod
    def poll(cls, context):
        return context.active_object is not None

    def draw(self, context):
        o = context.active_object
        p, col = o.piste, self.layout.column()
        col.label(text=o.name, icon="OBJECT_DATA")
        col.prop(p, "role")
        if p.role in ("RIDER", "OBJECT"):
            col.prop(p, "model")
            if p.model == "FILE":
                col.prop(p, "model_file")
                if p.role == "RIDER":
                    col.prop(p, "texture")
        if p.role == "RIDER":
            col.prop(p, "clip")
            col.prop(p, "phase")
            col.prop(p, "clips_from")
            if p.clips_from:
                col.prop(p, "bone_map")
        if o.type == "LIGHT" and p.role == "AUTO":
            col.prop(p, "light_kind")
            col.prop(p, "negative")
            if p.light_kind == "AMBIENT" or p.negative:
                col.prop(p, "piste_intensity")
                if p.negative and o.data.type in ("POINT", "SPOT"):
                    col.prop(p, "piste_range")


class PISTE_PT_actions(_Panel, bpy.types.Panel):
    bl_label = "piste actions"

    def draw(self, context):
        col = self.layout.column()
        col.operator("piste.export", icon="EXPORT")
        if preview.running():
            col.operator("piste.preview_stop", icon="CANCEL")
        else:
            col.operator("piste.preview", icon="PLAY")
        if preview.state.error:
            col.label(text=preview.state.error[:160], icon="ERROR")
        col.prop(context.scene.piste, "preview_camera")
        col.prop(context.scene.piste, "preview_debounce")
        col.separator()
        col.operator("piste.import_file", icon="IMPORT")
        col.prop(context.scene.piste, "writeback_out")
        col.operator("piste.ssx_write_back", icon="FILE_REFRESH")


CLASSES = (PISTE_PT_scene, PISTE_PT_object, PISTE_PT_actions)
