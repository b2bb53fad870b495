"""Quantized weight palettes: the SSX Tricky "blended matrices" precomputation.

SSX Tricky quantizes every vertex's skin weights to a step (10 %-25 %), keeps at most 3 bones,
and finds the unique (bones, quantized weights) combinations of the whole mesh. Per frame the CPU
builds one weighted matrix per combination (the *palette*) and each vertex is transformed by its
single palette matrix, so VU1 never blends.

API
---
- ``quantize_weights(joints, weights, step, max_bones) -> (bones (v,k) int32, units (v,k) int32)``
- ``palette(mesh, step=0.25, max_bones=3) -> Palette``
- ``Palette``: ``bones (p,k) int32``, ``weights (p,k) float32``, ``index (v,) int32``,
  ``matrices(bone_matrices) -> (p,3,4) float32``.

Quantization rule (largest remainder)
-------------------------------------
1. Duplicate joints of a vertex are merged (their weights added); the ``max_bones`` largest
   weights are kept (ties: lower slot first) and renormalised to sum 1 (a vertex with no weight
   is bound fully to its first joint).
2. With ``n = 1/step`` units (``step`` must divide 1: 0.1, 0.2, 0.25, 0.5, ...), each weight
   gets ``floor(w * n)`` units and the ``n - sum`` missing units go, one each, to the largest
   fractional parts (ties: the larger weight first). So quantized weights always sum to exactly
   1 and no weight moves by more than one step.
3. Bones left with 0 units are dropped. A combination is the bone tuple (sorted by bone index)
   with its units; padding slots have bone 0 and weight 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from piste._data import DataMethods
from piste.character.model import SkinnedMesh
from piste.errors import ConfigError, ValidationError

__all__ = ["Palette", "palette", "quantize_weights", "step_units"]


def step_units(step: float) -> int:
    """Number of units ``1/step`` (int); ConfigError unless ``step`` divides 1 (0 < step <= 1)."""
    try:
        step = float(step)
    except (TypeError, ValueError):
        raise ConfigError(f"weight step must be a number such as 0.1, 0.2 or 0.25, got {step!r}") from None
    if not (0.0 < step <= 1.0):
        raise ConfigError(f"weight step must be in (0, 1], got {step}")
    n = int(round(1.0 / step))
    if abs(n * step - 1.0) > 1e-6:
        raise ConfigError(f"weight step must divide 1 exactly (0.1, 0.2, 0.25, 0.5, ...), got {step}")
    return n


def _check_max_bones(max_bones: Any) -> int:
    if int(max_bones) != max_bones or int(max_bones) < 1:
        raise ConfigError(f"max_bones must be a positive integer, got {max_bones!r}")
    return int(max_bones)


def _top_weights(joints: npt.ArrayLike, weights: npt.ArrayLike, max_bones: int) -> tuple[np.ndarray, np.ndarray]:
    """Merge duplicate joints, keep the ``max_bones`` largest, renormalise.

    Returns ``bones (v,k) int32`` and ``w (v,k) float64`` sorted by weight, descending, with
    ``k = min(max_bones, slots)``; rows sum to 1.
    """
    joints = np.asarray(joints)
    weights = np.asarray(weights, dtype=np.float64)
    if joints.ndim != 2 or weights.shape != joints.shape:
        raise ValidationError(f"joints and weights must both be (v, n) arrays, got {joints.shape} and {weights.shape}")
    if not np.all(np.isfinite(weights)):
        raise ValidationError("skin weights contain NaN or infinity")
    if np.any(weights < 0):
        raise ValidationError("skin weights must be >= 0")
    j = joints.astype(np.int32)
    w = weights.copy()
    s = j.shape[1]
    for a in range(s):  # merge repeated joints (few slots: loop over slot pairs, not vertices)
        for b in range(a + 1, s):
            same = (j[:, a] == j[:, b]) & (w[:, b] > 0)
            w[same, a] += w[same, b]
            w[same, b] = 0.0
    order = np.argsort(-w, axis=1, kind="stable")
    k = min(max_bones, s)
    order = order[:, :k]
    bones = np.take_along_axis(j, order, axis=1)
    w = np.take_along_axis(w, order, axis=1)
    total = w.sum(1)
    empty = total <= 0
    w[empty, 0] = 1.0
    total[empty] = 1.0
    w /= total[:, None]
    return bones, w


def quantize_weights(joints: npt.ArrayLike, weights: npt.ArrayLike, step: float = 0.25,
                     max_bones: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Quantize skin weights to multiples of ``step`` with at most ``max_bones`` bones.

    Parameters
    ----------
    joints : (v, n) int     bone index per influence slot
    weights : (v, n) float  weights (any row sum > 0; renormalised)

    Returns
    -------
    bones : (v, k) int32    bones sorted by descending original weight, ``k = min(max_bones, n)``
    units : (v, k) int32    quantized weights in units of ``step``; rows sum to ``1/step``;
                            slots with 0 units are unused
    """
    n = step_units(step)
    max_bones = _check_max_bones(max_bones)
    bones, w = _top_weights(joints, weights, max_bones)
    scaled = w * n
    units = np.floor(scaled + 1e-9)
    frac = scaled - units
    missing = (n - units.sum(1)).round().astype(np.int64)  # 0 .. k-1 units still to hand out
    # rank slots by fractional part, descending; stable keeps the larger weight first on ties
    rank_order = np.argsort(-np.round(frac, 9), axis=1, kind="stable")
    ranks = np.empty_like(rank_order)
    np.put_along_axis(ranks, rank_order, np.arange(w.shape[1])[None, :].repeat(w.shape[0], 0), axis=1)
    units += ranks < missing[:, None]
    return bones, units.astype(np.int32)


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class Palette(DataMethods):
    """Unique quantized weight combinations of a mesh and each vertex's entry.

    Attributes
    ----------
    bones : (p, k) int32      bones of each entry (sorted ascending among used slots; unused
                              slots hold bone 0 with weight 0)
    weights : (p, k) float32  quantized weights, rows sum to 1
    units : (p, k) int32      the same weights in units of ``step``
    index : (v,) int32        palette entry of each vertex
    step : float
    max_bones : int
    """

    bones: np.ndarray
    weights: np.ndarray
    units: np.ndarray
    index: np.ndarray
    step: float
    max_bones: int

    @property
    def size(self) -> int:
        """Number of palette matrices generated per frame."""
        return int(self.bones.shape[0])

    def __len__(self) -> int:
        return self.size

    @property
    def counts(self) -> np.ndarray:
        """Vertices per entry ``(p,) int64``."""
        return np.bincount(self.index, minlength=self.size)

    @property
    def bones_per_entry(self) -> np.ndarray:
        """Bones actually used by each entry ``(p,) int32``."""
        return (self.units > 0).sum(1).astype(np.int32)

    def vertex_weights(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-vertex quantized influences: ``bones (v,k) int32``, ``weights (v,k) float32``."""
        return self.bones[self.index], self.weights[self.index]

    def matrices(self, bone_matrices: npt.ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """Blend the palette for one frame: ``(p, 3, 4) float32``, the top three rows of
        ``sum_i w_i * bone_matrices[bone_i]``.

        ``bone_matrices`` are skin matrices ``(b, 4, 4)`` (or ``(b, 3, 4)``); vectorised over all
        entries (a loop over the <= ``max_bones`` slots only).
        """
        m = np.asarray(bone_matrices)
        if m.ndim != 3 or m.shape[1:] not in ((4, 4), (3, 4)):
            raise ValidationError(f"bone matrices must be (b, 4, 4), got {m.shape}")
        if self.size and int(self.bones.max()) >= m.shape[0]:
            raise ValidationError(f"palette references bone {int(self.bones.max())} but only "
                                  f"{m.shape[0]} bone matrices were given")
        m = np.ascontiguousarray(m[:, :3, :], dtype=np.float32)
        if out is None:
            out = np.empty((self.size, 3, 4), np.float32)
        np.multiply(m[self.bones[:, 0]], self.weights[:, 0, None, None], out=out)
        for k in range(1, self.bones.shape[1]):
            out += m[self.bones[:, k]] * self.weights[:, k, None, None]
        return out


def palette(mesh: SkinnedMesh, step: float = 0.25, max_bones: int = 3) -> Palette:
    """Build the blended-matrix palette of a skinned mesh.

    ``mesh`` needs ``joints (v,4)`` and ``weights (v,4)`` (a :class:`SkinnedMesh`); see the module
    docstring for the quantization rule. The palette size is the number of matrices generated
    per frame (CesiumMan: 269 / 130 / 94 at step 0.1 / 0.2 / 0.25 with 3 bones).
    """
    n = step_units(step)
    bones, units = quantize_weights(mesh.joints, mesh.weights, step, max_bones)
    v, k = bones.shape
    used = units > 0
    # canonical key: used slots sorted by bone index, unused slots last (bone sentinel)
    big = np.iinfo(np.int32).max
    keyb = np.where(used, bones, big)
    order = np.argsort(keyb, axis=1, kind="stable")
    sb = np.take_along_axis(keyb, order, axis=1)
    su = np.take_along_axis(units, order, axis=1)
    key = np.concatenate([sb, su], axis=1)
    if v == 0:
        uniq = np.zeros((0, 2 * k), np.int64)
        inverse = np.zeros(0, np.int64)
    else:
        uniq, inverse = np.unique(key, axis=0, return_inverse=True)
    pb = uniq[:, :k].astype(np.int64)
    pu = uniq[:, k:].astype(np.int32)
    pb = np.where(pu > 0, pb, 0).astype(np.int32)
    return Palette(bones=pb, weights=(pu / n).astype(np.float32), units=pu,
                   index=np.asarray(inverse, dtype=np.int32).reshape(-1), step=float(step),
                   max_bones=int(max_bones))
