"""Moved to :mod:`piste.formats.gltf.checks` (glTF lives in one subpackage, ``piste.formats.gltf``);
this module keeps the old name working and re-exports its public names."""

from piste.formats.gltf.checks import (  # noqa: F401
    MAX_LIGHT_INTENSITY, float_array, light_fields, normal_matrix, number, rest_inverse, singular, vector,
)
from piste.formats.gltf.checks import __all__  # noqa: F401
