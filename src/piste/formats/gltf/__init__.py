"""glTF 2.0 in one place: reading, writing, the extensions piste reads, and the checks a file passes
before anything is allocated.

Modules::

    read        load_gltf(path, frame=GltfFrame()) -> piste.character.Model (meshes, skeleton, clips,
                lights and cameras as piste.scene_data's)
    write       export_gltf(path, terrain=TerrainExport(mesh), characters=..., objects=...) -> ExportReport
    extensions  the extensions piste reads (KHR_texture_transform, KHR_mesh_quantization, Draco, ...)
    material    MaterialInfo, the material a mesh was imported with
    schema      precheck_gltf(path): size, GLB chunks, nesting, counts and the JSON types of every field read
    checks      number / vector / light and camera fields, rest inverses and normal matrices
    units       glTF's axes, cameras and light units <-> piste's one Camera and light family
                (GltfFrame, light_from_gltf, camera_from_gltf, light_to_gltf, camera_to_gltf)

The conversion between piste's relative light units and glTF's lux / candela (and Z up / Y up) is
:mod:`piste.formats.gltf.units`; a bundle's export is :mod:`piste.pipeline.bundle_gltf`.  The old module names (``piste.formats.gltf_export``,
``gltf_ext``, ``gltf_schema``, ``gltf_checks``) re-export these modules' names.
"""

from typing import TYPE_CHECKING

from piste import _lazy_exports

# every name is imported when first asked for (PEP 562; tests/test_lazy_imports.py): a bundle
# render that asks for MaterialInfo does not import the reader, the writer or the extension decoders
__all__, __getattr__, __dir__ = _lazy_exports(__name__, {
    "read": ("load_gltf",),
    "write": ("TerrainExport", "CharacterExport", "ObjectsExport", "ExportReport", "export_gltf"),
    "material": ("MaterialInfo",),
    "schema": ("precheck_gltf", "check_gltf_types"),
    "units": ("GltfFrame",),
})

if TYPE_CHECKING:  # the same names, eagerly, for type checkers and the import graph
    from piste.formats.gltf.read import load_gltf  # noqa: F401
    from piste.formats.gltf.write import CharacterExport, ExportReport, ObjectsExport, TerrainExport, export_gltf  # noqa: F401
    from piste.formats.gltf.material import MaterialInfo  # noqa: F401
    from piste.formats.gltf.schema import check_gltf_types, precheck_gltf  # noqa: F401
    from piste.formats.gltf.units import GltfFrame  # noqa: F401
