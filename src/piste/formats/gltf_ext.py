"""Moved to :mod:`piste.formats.gltf.extensions` (glTF lives in one subpackage, ``piste.formats.gltf``);
this module keeps the old name working and re-exports its public names."""

from piste.formats.gltf.extensions import (  # noqa: F401
    Document, MaterialInfo, Node_, QUANTIZED_COMPS, SUPPORTED, apply_uv_transform, check_required,
    material_info, prepare_primitive, read_document, texture_transform_matrix, to_float, vertex_comps,
)
from piste.formats.gltf.extensions import __all__  # noqa: F401
