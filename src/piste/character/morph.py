"""Morph targets (blend shapes) and their null-bone alternative.

- ``vertex_normals(positions, indices) -> (v, 3) float32``: area-weighted smooth normals.
- ``blend_morphs(mesh, weights) -> (positions (v,3), normals (v,3))``: base + sum_k w_k delta_k,
  normals renormalised; one GEMV over all targets.
"""

from __future__ import annotations

import numpy as np

__all__ = ["vertex_normals", "blend_morphs"]


def vertex_normals(positions, indices) -> np.ndarray:
    """Area-weighted vertex normals ``(v, 3) float32`` of a triangle mesh; unused vertices get +Z."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    f = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    n = np.zeros_like(p)
    if f.size:
        fn = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
        for c in range(3):
            np.add.at(n, f[:, c], fn)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    out = np.where(ln > 1e-30, n / np.where(ln > 1e-30, ln, 1.0), np.array([0.0, 0.0, 1.0]))
    return out.astype(np.float32)


def _normalize_rows(v):
    ln = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(ln > 1e-30, v / np.where(ln > 1e-30, ln, 1.0), v)


def blend_morphs(mesh, weights):
    """Blended ``(positions (v, 3) float32, normals (v, 3) float32)`` of ``mesh`` at ``weights (k,)``.

    ``positions = mesh.positions + sum_k weights[k] * mesh.morph_positions[k]`` and likewise the
    normals, which are then renormalised. Computed as one ``(k,) @ (k, v*3)`` product.
    """
    w = np.asarray(weights, dtype=np.float32).reshape(-1)
    k = mesh.morph_positions.shape[0]
    if w.shape[0] != k:
        from piste.errors import ValidationError

        raise ValidationError(f"mesh {mesh.name!r} has {k} morph targets, got {w.shape[0]} weights")
    v = mesh.positions.shape[0]
    if k == 0:
        return mesh.positions.copy(), mesh.normals.copy()
    pos = mesh.positions + (w @ mesh.morph_positions.reshape(k, v * 3)).reshape(v, 3)
    nrm = mesh.normals + (w @ mesh.morph_normals.reshape(k, v * 3)).reshape(v, 3)
    return pos.astype(np.float32), _normalize_rows(nrm).astype(np.float32)
