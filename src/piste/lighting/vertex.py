"""Per-vertex lighting as SSX does it for characters and objects: 1 ambient + 3 directional lights.

The talk ("Object rendering", "Character rendering"): *1 ambient + 3 directional; light directional
matrix, color matrix*.  Per vertex with unit normal ``n``::

    c = ambient + C @ max(0, D @ n)

* ``D (3, 3)`` the light-direction matrix: row ``i`` is the unit vector *towards* light ``i``
  (in the space the normals are in: world space for CPU-skinned riders, object space when
  :meth:`VertexLights.to_object_space` has rotated it);
* ``max(0, .)`` clamps each light's Lambert term at 0 (a light never lights the back of a surface);
* ``C (3, 3)`` the light-colour matrix: column ``i`` is light ``i``'s ``intensity * colour``,
  attenuated (point / spot) at the character's position; columns may be negative (negative lights);
* ``ambient (3,)`` the sum of the world's ambient lights.

The final colour is clamped below at 0 (as :func:`piste.lighting.shade` does).  The same three
arrays feed the GLSL shaders as ``uniform mat3`` / ``vec3`` (:meth:`VertexLights.uniforms`), so a
rendered vertex colour can be compared with :func:`vertex_light` directly.

Which three lights: :func:`choose_lights` turns every direct light of a :class:`Lights` into a
direction plus an attenuated colour *at one position* (the character's or object's centre: point
and spot lights become directional lights there) and keeps the ``k`` strongest by
``|intensity| * attenuation * cone * luminance(colour)``.  Negative lights compete on their
magnitude.  The attenuation and cone factors come from :func:`piste.lighting.light_terms`, the
baker's own equation, so the two never disagree.

API
---
VertexLights                ``directions (3, 3)``, ``colors (3, 3)``, ``ambient (3,)``
choose_lights(lights, position, k=3) -> VertexLights
choose_lights_many(lights, positions, k=3) -> VertexLights with (m, 3, 3) / (m, 3) arrays
vertex_light(normals, vlights) -> (v, 3) float32
light_strengths(lights, positions) -> (m, L) float64 and (m, L, 3) directions, colours
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from piste._data import DataMethods
from piste.errors import ValidationError
from piste.lighting.lights import Lights, light_terms, light_vectors
from piste.scene_data import AnyLight

__all__ = ["VertexLights", "choose_lights", "choose_lights_many", "vertex_light", "light_strengths", "LUMA"]

#: Rec. 709 luminance weights: how bright a light colour looks (used to rank lights)
LUMA = np.array([0.2126, 0.7152, 0.0722])


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class VertexLights(DataMethods):
    """The per-vertex light set of one character / object (or of ``m`` of them).

    Attributes
    ----------
    directions : (3, 3) or (m, 3, 3) float32, rows = unit vectors towards each light (zero rows
        for unused slots)
    colors : (3, 3) or (m, 3, 3) float32, columns = each light's attenuated ``intensity * colour``
    ambient : (3,) or (m, 3) float32
    chosen : (3,) or (m, 3) int64, index into ``lights.direct`` of each slot (-1: unused)
    """

    directions: np.ndarray
    colors: np.ndarray
    ambient: np.ndarray
    chosen: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.directions = np.asarray(self.directions, dtype=np.float32)
        self.colors = np.asarray(self.colors, dtype=np.float32)
        self.ambient = np.asarray(self.ambient, dtype=np.float32)
        if self.directions.shape[-2:] != (3, 3) or self.colors.shape[-2:] != (3, 3) or self.ambient.shape[-1] != 3:
            raise ValidationError(
                f"VertexLights: expected directions and colors (..., 3, 3) and ambient (..., 3), got "
                f"{self.directions.shape}, {self.colors.shape}, {self.ambient.shape}"
            )

    def __len__(self) -> int:
        return 1 if self.directions.ndim == 2 else len(self.directions)

    def __getitem__(self, i: int | slice | np.ndarray) -> "VertexLights":
        """The light set of item ``i`` of a batch."""
        ch = None if self.chosen is None else self.chosen[i]
        return VertexLights(self.directions[i], self.colors[i], self.ambient[i], ch)

    def to_object_space(self, rotation: npt.ArrayLike) -> "VertexLights":
        """The same lights with directions in the object space of a rigid ``rotation (3, 3)``
        (object -> world): ``D_obj = D_world @ R`` (so ``D_obj @ n_obj = D_world @ R n_obj``).
        For objects with non-uniform scale light in world space with inverse-transpose normals
        instead (as :mod:`piste.render.object_pass` does)."""
        r = np.asarray(rotation, dtype=np.float32)
        return VertexLights(self.directions @ r, self.colors, self.ambient, self.chosen)

    def uniforms(self) -> dict:
        """GLSL uniform bytes of one light set: ``u_light_dir`` (mat3, ``u_light_dir * n`` = ``D @ n``),
        ``u_light_color`` (mat3, ``u_light_color * x`` = ``C @ x``), ``u_ambient`` (vec3)."""
        if self.directions.ndim != 2:
            raise ValidationError("VertexLights.uniforms: index a batch first (vlights[i])")
        # GLSL matrices are column-major: the bytes of M.T in C order are M in column-major order
        return {
            "u_light_dir": np.ascontiguousarray(self.directions.T, dtype=np.float32).tobytes(),
            "u_light_color": np.ascontiguousarray(self.colors.T, dtype=np.float32).tobytes(),
            "u_ambient": tuple(float(x) for x in self.ambient),
        }


@lru_cache(maxsize=512)
def _single(light: AnyLight) -> Lights:
    """A one-light :class:`Lights` (cached: lights are immutable and hashable)."""
    return Lights((light,))


def light_strengths(lights: Lights, positions: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every direct light of ``lights`` seen from ``m`` positions as a directional light.

    Parameters
    ----------
    lights : piste.lighting.Lights
    positions : (m, 3) float

    Returns
    -------
    strength : (m, L) float64, ``|intensity| * attenuation * cone * luminance(colour)``
    directions : (m, L, 3) float64, unit vectors from each position towards each light
    colors : (m, L, 3) float64, ``intensity * colour * attenuation * cone`` (signed)
    """
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    m = len(positions)
    direct = lights.direct
    n = len(direct)
    strength = np.zeros((m, n))
    dirs = np.zeros((m, n, 3))
    cols = np.zeros((m, n, 3))
    for j, light in enumerate(direct):  # a handful of lights; each is vectorised over positions
        L, _ = light_vectors(light, positions)
        L = np.ascontiguousarray(L)
        # the baker's own attenuation x cone: its Lambert factor is 1 for a normal facing the light
        factor = light_terms(_single(light), positions, L)[:, 0]
        ic = light.intensity * np.asarray(light.color, dtype=np.float64)
        dirs[:, j] = L
        cols[:, j] = factor[:, None] * ic[None, :]
        strength[:, j] = abs(light.intensity) * factor * float(np.abs(np.asarray(light.color)) @ LUMA)
    return strength, dirs, cols


def choose_lights_many(lights: Lights, positions: npt.ArrayLike, k: int = 3) -> VertexLights:
    """The ``k`` strongest direct lights at each of ``m`` positions (see the module docstring).

    Parameters
    ----------
    lights : piste.lighting.Lights (ambient lights are summed; every other light competes)
    positions : (m, 3) float
    k : slots, at most 3 (the talk's three directional lights); fewer lights leave zero slots

    Returns
    -------
    VertexLights with ``directions (m, 3, 3)``, ``colors (m, 3, 3)``, ``ambient (m, 3)``,
    ``chosen (m, 3)`` (slots in decreasing strength; lights with zero strength are not chosen).
    """
    if not 1 <= int(k) <= 3:
        raise ValidationError(f"choose_lights: k must be 1, 2 or 3 (the talk's 3 directional lights), got {k!r}")
    k = int(k)
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    m = len(positions)
    strength, dirs, cols = light_strengths(lights, positions)
    n = strength.shape[1]
    D = np.zeros((m, 3, 3))
    C = np.zeros((m, 3, 3))
    chosen = np.full((m, 3), -1, dtype=np.int64)
    if n:
        kk = min(k, n)
        order = np.argsort(-strength, axis=1, kind="stable")[:, :kk]  # (m, kk)
        rows = np.arange(m)[:, None]
        ok = strength[rows, order] > 0.0
        D[:, :kk] = np.where(ok[..., None], dirs[rows, order], 0.0)
        C[:, :, :kk] = np.where(ok[..., None], cols[rows, order], 0.0).transpose(0, 2, 1)
        chosen[:, :kk] = np.where(ok, order, -1)
    amb = np.broadcast_to(lights.ambient_color(), (m, 3))
    return VertexLights(D, C, amb, chosen)


def choose_lights(lights: Lights, position: npt.ArrayLike, k: int = 3) -> VertexLights:
    """The ``k`` (<= 3) strongest direct lights at one ``position (3,)``: a single light set
    (``directions (3, 3)``, ``colors (3, 3)``, ``ambient (3,)``)."""
    return choose_lights_many(lights, np.asarray(position, dtype=np.float64).reshape(1, 3), k)[0]


def vertex_light(normals: npt.ArrayLike, vlights: VertexLights) -> np.ndarray:
    """``ambient + C @ max(0, D @ n)`` for every normal, clamped at 0.

    Parameters
    ----------
    normals : (v, 3) float, unit, in the space of ``vlights.directions``
    vlights : one light set (``directions (3, 3)``)

    Returns
    -------
    (v, 3) float32 linear RGB
    """
    n = np.asarray(normals, dtype=np.float32).reshape(-1, 3)
    if vlights.directions.ndim != 2:
        raise ValidationError("vertex_light: expected one light set, got a batch (index it first)")
    lam = np.maximum(n @ vlights.directions.T, 0.0)  # (v, 3): D @ n for every vertex
    c = lam @ vlights.colors.T + vlights.ambient[None, :]
    return np.maximum(c, 0.0).astype(np.float32, copy=False)
