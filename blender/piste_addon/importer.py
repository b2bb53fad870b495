"""Import a piste bundle, scene or SSX level (.piste, .toml, .pbd with its textures and light
maps) or an SSX rider (.mpf) through piste's glTF export and Blender's glTF importer; an SSX
level also comes in as its patches' control cage ("LEVEL patches": :mod:`.ssx_patches`), which
Write Back turns into an edited level through piste's Multitool route
(``piste ssx convert --to multitool`` then ``piste ssx import``)."""

from __future__ import annotations

from pathlib import Path

import bpy
from bpy_extras.io_utils import ImportHelper

from .preview import piste_exe
from .runner import PisteFailed, PisteNotFound, run_piste
from .ssx_patches import CORNERS, apply_cage, cage_from_patches, load_patches, save_patches


def _work_dir(context, src: Path) -> Path:
    try:
        from .exporter import export_dir
        base = export_dir(context)
    except ValueError:
        base = src.parent
    return base / "imports" / src.stem


def _numpy_compat() -> None:
    """Debian 12's Blender 3.4 glTF importer uses ``np.bool``, which numpy 1.24 removed."""
    try:
        import numpy
    except ImportError:
        return
    if not hasattr(numpy, "bool"):
        numpy.bool = bool


def import_file(context, path) -> list:
    """Import ``path``; returns the new objects."""
    src = Path(path).resolve()
    exe = piste_exe(context)
    work = _work_dir(context, src)
    work.mkdir(parents=True, exist_ok=True)
    glb = work / f"{src.stem}.glb"
    suffix = src.suffix.lower()
    if suffix == ".mpf":
        run_piste(exe, ["mpf", "export", src, glb])
    elif suffix in (".piste", ".toml", ".pbd"):
        run_piste(exe, ["export", "--quiet", "--instancing", "nodes", src, glb])  # one object per instance
    else:
        raise ValueError(f"{src}: expected a .piste bundle, a scene .toml, an SSX level .pbd or an SSX rider .mpf")
    before = set(bpy.data.objects)
    _numpy_compat()
    bpy.ops.import_scene.gltf(filepath=str(glb))
    new = [o for o in bpy.data.objects if o not in before]
    for o in new:
        o["piste_source"] = str(src)
    if suffix == ".pbd":
        new.append(import_patches(context, src, work))
    return new


def import_patches(context, pbd: Path, work: Path):
    project = work / "project"
    run_piste(piste_exe(context), ["ssx", "convert", "--to", "multitool", "--out", project, pbd])
    _, patches = load_patches(project / "Patches.json")
    verts, faces, uvs = cage_from_patches(patches)
    mesh = bpy.data.meshes.new(f"{pbd.stem} patches")
    mesh.from_pydata(verts, [], faces)
    layer = mesh.uv_layers.new(name="UVPoints")
    for i, uv in enumerate(uvs):
        layer.data[i].uv = uv
    mesh.update()
    obj = bpy.data.objects.new(f"{pbd.stem} patches", mesh)
    context.scene.collection.objects.link(obj)
    obj["piste_ssx_level"] = str(pbd)
    obj["piste_ssx_project"] = str(project)
    obj.piste.role = "IGNORE"
    obj.display_type = "WIRE"
    return obj


def cage_corner_uvs(mesh) -> list:
    """Per patch the UVs of its 4 corner vertices (first loop found at each)."""
    layer = mesh.uv_layers.get("UVPoints") or mesh.uv_layers.active
    at = {}
    for li, loop in enumerate(mesh.loops):
        at.setdefault(loop.vertex_index, tuple(layer.data[li].uv))
    n = len(mesh.vertices) // 16
    return [[at.get(16 * k + c, (0.0, 0.0)) for c in CORNERS] for k in range(n)]


def write_back(context, obj, out=None) -> tuple:
    """Write the edited cage ``obj`` back as a level; returns ``(out .pbd, patches changed)``."""
    level, project = Path(obj["piste_ssx_level"]), Path(obj["piste_ssx_project"])
    if out is None:
        out = context.scene.piste.writeback_out
        out = Path(bpy.path.abspath(out)) if out else level.with_name(level.stem + "_edited.pbd")
    doc, patches = load_patches(project / "Patches.json")
    mw = obj.matrix_world
    verts = [tuple(mw @ v.co) for v in obj.data.vertices]
    changed = apply_cage(patches, verts, cage_corner_uvs(obj.data))
    save_patches(project / "Patches.json", doc)
    run_piste(piste_exe(context), ["ssx", "import", "--out", out, project])
    return Path(out), changed


class PISTE_OT_import(bpy.types.Operator, ImportHelper):
    """Import a piste bundle or scene, an SSX Tricky level (.pbd) or rider (.mpf) through piste's glTF export"""
    bl_idname = "piste.import_file"
    bl_label = "Import via piste"
    filter_glob: bpy.props.StringProperty(default="*.piste;*.toml;*.pbd;*.mpf", options={"HIDDEN"})

    def execute(self, context):
        try:
            new = import_file(context, self.filepath)
        except (PisteNotFound, PisteFailed, ValueError, OSError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        self.report({"INFO"}, f"piste: imported {len(new)} objects from {self.filepath}")
        return {"FINISHED"}


class PISTE_OT_write_back(bpy.types.Operator):
    """Write the edited patch cage back as an SSX level (.pbd) through piste ssx"""
    bl_idname = "piste.ssx_write_back"
    bl_label = "Write back SSX level"

    @classmethod
    def poll(cls, context):
        o = context.active_object
        return o is not None and "piste_ssx_project" in o

    def execute(self, context):
        try:
            out, changed = write_back(context, context.active_object)
        except (PisteNotFound, PisteFailed, ValueError, OSError, KeyError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        self.report({"INFO"}, f"piste: wrote {out} ({changed} patches changed)")
        return {"FINISHED"}


def menu_import(self, context):
    self.layout.operator(PISTE_OT_import.bl_idname, text="piste / SSX Tricky (.piste, .toml, .pbd, .mpf)")


CLASSES = (PISTE_OT_import, PISTE_OT_write_back)
