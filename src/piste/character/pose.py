"""A skeleton's pose: the local transforms of every bone (shared by model.py and animation.py).

API
---
Pose(translation (b, 3), rotation (b, 4) xyzw, scale (b, 3))   float64; ``.n_bones``, ``.copy()``
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from piste._data import DataMethods

__all__ = ["Pose"]


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class Pose(DataMethods):
    """Local transforms of every bone: ``translation (b,3)``, ``rotation (b,4)`` xyzw, ``scale (b,3)``, float64."""

    translation: np.ndarray
    rotation: np.ndarray
    scale: np.ndarray

    def __post_init__(self) -> None:
        self.translation = np.asarray(self.translation, dtype=np.float64).reshape(-1, 3)
        self.rotation = np.asarray(self.rotation, dtype=np.float64).reshape(-1, 4)
        self.scale = np.asarray(self.scale, dtype=np.float64).reshape(-1, 3)

    @property
    def n_bones(self) -> int:
        return self.translation.shape[0]

    def copy(self) -> "Pose":
        return Pose(self.translation.copy(), self.rotation.copy(), self.scale.copy())
