"""Moved to :mod:`piste.formats.gltf.write` (glTF lives in one subpackage, ``piste.formats.gltf``);
this module keeps the old name working and re-exports its public names."""

from piste.formats.gltf.write import (  # noqa: F401
    CharacterExport, ExportReport, ObjectsExport, TerrainExport, Y_UP_ROOT_ROTATION, export_gltf,
    lightmap_to_png_array,
)
from piste.formats.gltf.write import __all__  # noqa: F401
