"""Moved to :mod:`piste.formats.gltf.schema` (glTF lives in one subpackage, ``piste.formats.gltf``);
this module keeps the old name working and re-exports its public names."""

from piste.formats.gltf.schema import (  # noqa: F401
    ANY, BOOL, IDX, INT, LIGHT, NUM, POS, SCHEMA, STR, TEXINFO, UINT, arr, check_gltf_types, obj,
    precheck_gltf,
)
from piste.formats.gltf.schema import __all__  # noqa: F401
