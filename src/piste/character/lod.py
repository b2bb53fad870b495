"""Character levels of detail: high / medium / low meshes, each with its own palette.

SSX Tricky kept ~250 blended matrices for the high-resolution rider (~3,000 polygons), ~150 for
the medium and ~75 for the low one. Here the lower levels come from meshoptimizer's
simplifier (quadric edge collapse on positions); the surviving vertices keep all their attributes
(normals, UVs, joints, weights, morph deltas), unused vertices are dropped, and each level gets
its own quantized palette, usually with a coarser weight step (fewer matrices).

API
---
- ``simplify_mesh(mesh, target_triangles, target_error=0.05, lock_border=False) -> SkinnedMesh``
- ``compact_mesh(mesh, indices) -> SkinnedMesh``: keep only the vertices ``indices`` use
- ``make_lods(mesh, ratios=(1.0, 0.5, 0.25), steps=(0.1, 0.2, 0.25), max_bones=3) -> list[LOD]``
- ``LOD``: ``name``, ``mesh``, ``palette``, ``ratio``, ``step``, ``error``
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from piste.character.model import SkinnedMesh
from piste.character.palette import Palette, palette as make_palette
from piste.errors import ConfigError

__all__ = ["LOD", "LOD_NAMES", "simplify_mesh", "compact_mesh", "make_lods"]

LOD_NAMES = ("high", "medium", "low")


@dataclass
class LOD:
    """One level: ``mesh`` (a SkinnedMesh), its ``palette``, the triangle ``ratio`` asked for,
    the weight ``step`` of its palette and meshoptimizer's relative ``error`` (0 for the original)."""

    name: str
    mesh: SkinnedMesh
    palette: Palette
    ratio: float
    step: float
    error: float

    @property
    def n_triangles(self) -> int:
        return int(self.mesh.n_triangles)

    @property
    def n_matrices(self) -> int:
        return self.palette.size


def compact_mesh(mesh: SkinnedMesh, indices: npt.ArrayLike) -> SkinnedMesh:
    """A copy of ``mesh`` with triangles ``indices (t, 3)`` and only the vertices they use (all
    per-vertex attributes, including morph deltas, follow their vertex)."""
    idx = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    used = np.unique(idx)
    remap = np.full(mesh.n_vertices, -1, np.int64)
    remap[used] = np.arange(used.size)
    return replace(
        mesh,
        positions=mesh.positions[used],
        indices=remap[idx].astype(np.uint32),
        normals=mesh.normals[used],
        uv=mesh.uv[used],
        joints=mesh.joints[used],
        weights=mesh.weights[used],
        morph_positions=mesh.morph_positions[:, used],
        morph_normals=mesh.morph_normals[:, used],
        morph_names=list(mesh.morph_names),
    )


def simplify_mesh(mesh: SkinnedMesh, target_triangles: int, target_error: float = 0.05, lock_border: bool = False,
                  weld: bool = True) -> tuple[SkinnedMesh, float]:
    """Simplify ``mesh`` to about ``target_triangles`` with meshoptimizer (indices only), then
    compact the vertices. Returns ``(mesh, error)`` where ``error`` is meshoptimizer's relative
    error (fraction of the mesh extent).

    ``weld``: simplify the mesh welded by position (vertices split for UV or normal seams, or
    flat-shaded meshes with 3 vertices a triangle, would otherwise be borders the simplifier
    cannot collapse); each welded vertex is then represented by the first original vertex at
    that position, whose attributes it keeps.
    """
    import meshoptimizer

    target = int(target_triangles)
    if target < 1:
        raise ConfigError(f"target_triangles must be >= 1, got {target_triangles}")
    if target >= mesh.n_triangles:
        return compact_mesh(mesh, mesh.indices), 0.0
    idx = mesh.indices.astype(np.int64)
    positions = np.ascontiguousarray(mesh.positions, dtype=np.float32)
    rep = np.arange(mesh.n_vertices)
    if weld and mesh.n_vertices:
        upos, first, inverse = np.unique(positions, axis=0, return_index=True, return_inverse=True)
        idx = inverse.reshape(-1)[idx]
        positions = np.ascontiguousarray(upos, dtype=np.float32)
        rep = first
    src = np.ascontiguousarray(idx.reshape(-1), dtype=np.uint32)
    dst = np.zeros_like(src)
    err = np.zeros(1, np.float32)
    opts = meshoptimizer.SIMPLIFY_LOCK_BORDER if lock_border else 0
    count = meshoptimizer.simplify(dst, src, positions, target_index_count=3 * target,
                                   target_error=float(target_error), options=opts, result_error=err)
    tris = rep[dst[:count].astype(np.int64)].reshape(-1, 3)
    return compact_mesh(mesh, tris), float(err[0])


def make_lods(mesh: SkinnedMesh, ratios: Sequence[float] = (1.0, 0.5, 0.25), steps: float | Sequence[float] = (0.1, 0.2, 0.25),
              max_bones: int = 3, target_error: float = 0.05, names: Sequence[str] = LOD_NAMES) -> list[LOD]:
    """High / medium / low levels of ``mesh``: triangle ``ratios`` of the original, each with its
    own palette at the matching weight ``step`` (a float applies to every level)."""
    ratios = list(ratios)
    steps = [float(steps)] * len(ratios) if isinstance(steps, (int, float)) else list(steps)
    if len(steps) != len(ratios):
        raise ConfigError(f"need one weight step per LOD ratio, got {len(steps)} steps for {len(ratios)} ratios")
    names = list(names) + [f"lod{i}" for i in range(len(names), len(ratios))]
    out = []
    for name, r, s in zip(names, ratios, steps):
        if not (0.0 < r <= 1.0):
            raise ConfigError(f"LOD ratio must be in (0, 1], got {r}")
        m, e = simplify_mesh(mesh, max(1, int(round(r * mesh.n_triangles))), target_error)
        out.append(LOD(name, m, make_palette(m, s, max_bones), float(r), float(s), e))
    return out
