"""The material a mesh was imported with (:class:`MaterialInfo`), apart from the extension decoders.

:func:`piste.formats.gltf.extensions.material_info` reads it from a glTF file; a bundle stores its
fields, and the runtime (:func:`piste.pipeline.characters.model_from_arrays`) rebuilds it without
importing the glTF extension machinery.  :mod:`piste.formats.gltf.extensions` re-exports it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["MaterialInfo"]


@dataclass
class MaterialInfo:
    """What piste keeps of a glTF material.

    base_color : (4,) float32 linear RGBA factor;  base_texture : texture index or None
    texcoord : UV set of the base-colour texture;  uv_transform : (3, 3) KHR_texture_transform matrix
    alpha_mode : "OPAQUE" | "MASK" | "BLEND";  alpha_cutoff;  double_sided
    emissive : (3,) linear RGB (factor x KHR_materials_emissive_strength);  unlit (KHR_materials_unlit)
    """

    name: str = ""
    base_color: np.ndarray = field(default_factory=lambda: np.ones(4, np.float32))
    base_texture: int | None = None
    texcoord: int = 0
    uv_transform: np.ndarray = field(default_factory=lambda: np.eye(3))
    alpha_mode: str = "OPAQUE"
    alpha_cutoff: float = 0.5
    double_sided: bool = False
    emissive: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    unlit: bool = False
