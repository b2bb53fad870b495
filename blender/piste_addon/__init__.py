"""piste for Blender: author piste scenes (terrain, riders, objects, lights, cameras), export the
scene .toml and glTF piste builds from, preview them live in piste's renderer, and import piste
bundles and SSX Tricky levels / riders (with write-back of edited level patches).

The add-on talks to piste only through the ``piste`` command line and files (glTF, scene .toml,
Multitool projects): set the path to ``piste`` (or its virtual environment) in the add-on's
preferences.  ``piste blender-addon --out piste_addon.zip`` writes the installable zip."""

bl_info = {
    "name": "piste",
    "author": "piste contributors",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "View3D > Sidebar > piste; File > Import > piste / SSX Tricky",
    "description": "Author piste scenes, preview them in piste's in-game renderer, import SSX Tricky levels",
    "category": "Import-Export",
}

try:
    import bpy
except ImportError:  # outside Blender: the pure-Python modules (scene_toml, runner, ssx_patches) still import
    bpy = None

if bpy is not None:
    from . import exporter, importer, preview, props, ui

    _MODULES = (exporter, preview, importer, ui)


def register():
    props.register()
    for m in _MODULES:
        for c in m.CLASSES:
            bpy.utils.register_class(c)
    bpy.types.TOPBAR_MT_file_import.append(importer.menu_import)


def unregister():
    preview.stop()
    bpy.types.TOPBAR_MT_file_import.remove(importer.menu_import)
    for m in reversed(_MODULES):
        for c in reversed(m.CLASSES):
            bpy.utils.unregister_class(c)
    props.unregister()
