"""Batches under a budget: split a skinned mesh so each batch references at most M matrices and
V vertices (VU1 memory on the PS2, a uniform array on a GPU).

SSX Tricky sends its blended (palette) matrices to VU1 in batches together with the vertices that
use them; per the community's notes on SSX Tricky models a batch holds at most 25 matrices and 55
vertices (the ``ps2`` preset). A vertex used by two batches is sent twice.

Algorithm (greedy, construction time): triangles are visited in meshoptimizer's vertex-cache
order; a triangle joins the open batch if its new vertices and new matrices still fit, else the
batch is *filled* (the next ``lookahead`` unvisited triangles that fit are pulled in) and closed.
Every triangle ends in exactly one batch and every batch is within budget (checked by
:func:`check_batches`).

API
---
::

    - ``Budget(max_matrices, max_vertices, name)``; ``BUDGETS``: ``ps2`` (25, 55), ``gpu256``
      (256 matrices, 65,536 vertices), ``gpu64`` (64, 65,536)
    - ``make_batches(indices, vertex_matrices, budget="ps2") -> list[Batch]``
    - ``batch_mesh(mesh, budget="ps2", step=0.25, max_bones=3, palette=None) -> list[Batch]``
    - ``check_batches(batches, indices, vertex_matrices, budget)``: raises ValidationError if broken
    - ``frame_bytes(batches, matrix_bytes=48, vertex_bytes=32) -> dict``
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from piste.character.model import SkinnedMesh
from piste.character.palette import Palette, palette as make_palette
from piste.character.strips import RESTART
from piste.errors import ConfigError, ValidationError

__all__ = ["Budget", "BUDGETS", "Batch", "make_batches", "batch_mesh", "check_batches", "frame_bytes"]


@dataclass(frozen=True)
class Budget:
    """Per-batch limits: ``max_matrices`` palette (or bone) matrices and ``max_vertices``."""

    max_matrices: int
    max_vertices: int
    name: str = "custom"


BUDGETS = {
    "ps2": Budget(25, 55, "ps2"),
    "gpu256": Budget(256, 65536, "gpu256"),
    "gpu64": Budget(64, 65536, "gpu64"),
}


def _budget(budget: Budget | str | tuple[int, int]) -> Budget:
    if isinstance(budget, Budget):
        b = budget
    elif isinstance(budget, str):
        if budget not in BUDGETS:
            raise ConfigError(f"unknown batch budget {budget!r}; expected one of {sorted(BUDGETS)} or (matrices, vertices)")
        b = BUDGETS[budget]
    else:
        try:
            m, v = budget
            b = Budget(int(m), int(v))
        except (TypeError, ValueError):
            raise ConfigError(f"batch budget must be a name, a Budget or (matrices, vertices), got {budget!r}") from None
    if b.max_matrices < 1 or b.max_vertices < 3:
        raise ConfigError(f"batch budget needs >= 1 matrix and >= 3 vertices, got {b}")
    return b


@dataclass
class Batch:
    """One draw batch.

    Attributes
    ----------
    vertices : (n,) int64        mesh vertex of each batch vertex (n <= max_vertices)
    matrices : (m,) int64        palette (or bone) matrices uploaded for the batch (m <= max_matrices)
    triangles : (t, 3) int64     triangles in batch-local vertex indices
    triangle_ids : (t,) int64    the mesh triangle each came from
    vertex_slots : (n, k) int64  each batch vertex's matrices as slots into ``matrices`` (-1 unused)
    """

    vertices: np.ndarray
    matrices: np.ndarray
    triangles: np.ndarray
    triangle_ids: np.ndarray
    vertex_slots: np.ndarray

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_matrices(self) -> int:
        return int(self.matrices.shape[0])

    @property
    def n_triangles(self) -> int:
        return int(self.triangles.shape[0])


def _vertex_matrices(vertex_matrices: npt.ArrayLike, n_vertices: int | None = None) -> np.ndarray:
    vm = np.asarray(vertex_matrices)
    if vm.ndim == 1:
        vm = vm[:, None]
    if vm.ndim != 2:
        raise ValidationError(f"vertex matrices must be (v,) or (v, k), got {vm.shape}")
    vm = vm.astype(np.int64)
    if n_vertices is not None and vm.shape[0] < n_vertices:
        raise ValidationError(f"indices use {n_vertices} vertices but only {vm.shape[0]} have matrices")
    return vm


def _cache_order(tris: np.ndarray, nv: int) -> np.ndarray:
    """Triangle visiting order from meshoptimizer's vertex-cache optimizer (identity fallback)."""
    try:
        import meshoptimizer
    except ImportError:  # pragma: no cover
        return np.arange(tris.shape[0])
    src = np.ascontiguousarray(tris.reshape(-1), dtype=np.uint32)
    dst = np.zeros_like(src)
    meshoptimizer.optimize_vertex_cache(dst, src, src.size, nv)
    # map optimized triangles back to their ids (the optimizer only permutes whole triangles)
    key_src = _tri_keys(tris)
    key_dst = _tri_keys(dst.reshape(-1, 3).astype(np.int64))
    order_src = np.argsort(key_src, kind="stable")
    pos = np.searchsorted(key_src[order_src], key_dst)
    ids = order_src[np.clip(pos, 0, len(order_src) - 1)]
    # duplicate triangles map to the same id: make them unique while keeping the order
    seen = np.zeros(tris.shape[0], bool)
    out = []
    for i in ids:  # construction time
        if not seen[i]:
            seen[i] = True
            out.append(i)
    out.extend(np.flatnonzero(~seen).tolist())
    return np.array(out, dtype=np.int64)


def _tri_keys(t: np.ndarray) -> np.ndarray:
    r = np.argmin(t, axis=1)
    idx = (r[:, None] + np.arange(3)[None, :]) % 3
    c = np.take_along_axis(t, idx, axis=1).astype(np.int64)
    m = int(c.max()) + 1 if c.size else 1
    return (c[:, 0] * m + c[:, 1]) * m + c[:, 2]


def make_batches(indices: npt.ArrayLike, vertex_matrices: npt.ArrayLike, budget: Budget | str | tuple[int, int] = "ps2", lookahead: int = 64,
                 order: str = "cache") -> list[Batch]:
    """Split triangles into batches within ``budget``.

    Parameters
    ----------
    indices : (t, 3) int             mesh triangles
    vertex_matrices : (v,) or (v, k) int   the matrix (palette entry) of each vertex, or its k
                                     matrices (bones, -1 = none)
    budget : "ps2" | "gpu256" | "gpu64" | Budget | (matrices, vertices)
    lookahead : int                  unvisited triangles scanned to fill a batch before closing it
    order : "cache" | "given"        triangle visiting order

    Returns
    -------
    list of :class:`Batch`

    Raises
    ------
    ConfigError
        a single triangle needs more than the budget.
    """
    b = _budget(budget)
    tris = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    nv = int(tris.max()) + 1 if tris.size else 0
    vm = _vertex_matrices(vertex_matrices, nv)
    if tris.shape[0] == 0:
        return []
    tri_mats = [set(int(m) for m in vm[list(t)].reshape(-1) if m >= 0) for t in tris]
    need_m = max(len(s) for s in tri_mats)
    if need_m > b.max_matrices:
        raise ConfigError(f"a triangle needs {need_m} matrices but the budget allows {b.max_matrices} a batch")
    seq = _cache_order(tris, nv) if order == "cache" else np.arange(tris.shape[0])
    done = np.zeros(tris.shape[0], bool)
    batches = []
    pos = 0
    n = len(seq)
    while pos < n:
        verts: dict[int, int] = {}
        mats: dict[int, int] = {}
        chosen: list[int] = []

        # (this batch's state bound as defaults: a closure over loop variables would see later batches')
        def fits(t: int, verts: dict[int, int] = verts,
                 mats: dict[int, int] = mats) -> tuple[bool, list[int], list[int]]:
            new_v = [int(x) for x in set(tris[t].tolist()) if int(x) not in verts]
            new_m = [m for m in tri_mats[t] if m not in mats]
            return (len(verts) + len(new_v) <= b.max_vertices and len(mats) + len(new_m) <= b.max_matrices,
                    new_v, new_m)

        def add(t: int, new_v: list[int], new_m: list[int], verts: dict[int, int] = verts, mats: dict[int, int] = mats,
                chosen: list[int] = chosen) -> None:
            for x in tris[t].tolist():
                if x not in verts:
                    verts[x] = len(verts)
            for m in sorted(new_m):
                mats[m] = len(mats)
            chosen.append(t)
            done[t] = True

        while pos < n:
            t = int(seq[pos])
            if done[t]:
                pos += 1
                continue
            ok, new_v, new_m = fits(t)
            if not ok:
                break
            add(t, new_v, new_m)
            pos += 1
        # fill: pull in later triangles that still fit
        scanned = 0
        q = pos
        while q < n and scanned < lookahead:
            t = int(seq[q])
            q += 1
            if done[t]:
                continue
            scanned += 1
            ok, new_v, new_m = fits(t)
            if ok:
                add(t, new_v, new_m)
        batches.append(_make_batch(tris, vm, chosen, verts, mats))
    return batches


def _make_batch(tris: np.ndarray, vm: np.ndarray, chosen: list[int], verts: dict[int, int], mats: dict[int, int]) -> Batch:
    vertices = np.array(list(verts.keys()), dtype=np.int64)
    matrices = np.array(list(mats.keys()), dtype=np.int64)
    lut = {v: i for v, i in verts.items()}
    tri_ids = np.array(chosen, dtype=np.int64)
    local = np.vectorize(lut.__getitem__, otypes=[np.int64])(tris[tri_ids]) if len(chosen) else np.zeros((0, 3), np.int64)
    mlut = np.full(int(matrices.max()) + 2 if matrices.size else 1, -1, np.int64)
    mlut[matrices] = np.arange(matrices.size)
    vmv = vm[vertices]
    slots = np.where(vmv >= 0, mlut[np.maximum(vmv, 0)], -1)
    return Batch(vertices, matrices, local.reshape(-1, 3), tri_ids, slots)


def batch_mesh(mesh: SkinnedMesh, budget: Budget | str | tuple[int, int] = "ps2", step: float = 0.25, max_bones: int = 3,
               palette: Palette | None = None, **kw: Any) -> list[Batch]:
    """Batches of a skinned mesh for the blended-matrix scheme: each vertex references its
    palette entry (``palette`` or ``palette(mesh, step, max_bones)``)."""
    if palette is None:
        palette = make_palette(mesh, step, max_bones)
    return make_batches(mesh.indices, palette.index, budget, **kw)


def check_batches(batches: Sequence[Batch], indices: npt.ArrayLike, vertex_matrices: npt.ArrayLike, budget: Budget | str | tuple[int, int]) -> None:
    """Raise ValidationError unless every triangle is in exactly one batch, batch triangles are
    the mesh's (same vertices, same winding), and every batch is within ``budget``."""
    b = _budget(budget)
    tris = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    vm = _vertex_matrices(vertex_matrices)
    count = np.zeros(tris.shape[0], np.int64)
    for k, bt in enumerate(batches):
        if bt.n_vertices > b.max_vertices or bt.n_matrices > b.max_matrices:
            raise ValidationError(f"batch {k} has {bt.n_vertices} vertices and {bt.n_matrices} matrices, "
                                  f"budget {b.max_vertices} / {b.max_matrices}")
        if len(set(bt.vertices.tolist())) != bt.n_vertices or len(set(bt.matrices.tolist())) != bt.n_matrices:
            raise ValidationError(f"batch {k} lists a vertex or matrix twice")
        if not np.array_equal(bt.vertices[bt.triangles], tris[bt.triangle_ids]):
            raise ValidationError(f"batch {k} triangles differ from the mesh's")
        need = vm[bt.vertices]
        have = set(bt.matrices.tolist())
        if any(int(m) not in have for m in need[need >= 0]):
            raise ValidationError(f"batch {k} uses a matrix it does not upload")
        np.add.at(count, bt.triangle_ids, 1)
    if np.any(count != 1):
        bad = int(np.flatnonzero(count != 1)[0])
        raise ValidationError(f"triangle {bad} is in {int(count[bad])} batches (expected exactly 1)")


def frame_bytes(batches: Sequence[Batch], matrix_bytes: int = 48, vertex_bytes: int = 32,
                strips: Sequence[npt.ArrayLike] | None = None) -> dict[str, Any]:
    """Bytes sent per frame by a list of batches.

    ``matrix_bytes``: 48 (3x4 float32, PS2 VU1 style) or 64 (4x4). ``vertex_bytes``: 32 by
    default (position 3 x f32 with the matrix slot in w, normal 3 x f32 ... packed as on VU1:
    12 + 12 + 8 for the UV). If ``strips`` (one non-indexed strip per batch) are given, vertex
    bytes count strip positions (vertices re-sent by the strip), else each batch vertex once.

    Returns ``{"batches", "matrices", "vertices", "matrix_bytes", "vertex_bytes", "total_bytes",
    "matrices_per_batch", "vertices_per_batch"}``.
    """
    nb = len(batches)
    mats = sum(b.n_matrices for b in batches)
    if strips is not None:
        verts = sum(int(np.sum(np.asarray(s) != RESTART)) for s in strips)
    else:
        verts = sum(b.n_vertices for b in batches)
    mb = mats * matrix_bytes
    vb = verts * vertex_bytes
    return {
        "batches": nb,
        "matrices": mats,
        "vertices": verts,
        "matrix_bytes": mb,
        "vertex_bytes": vb,
        "total_bytes": mb + vb,
        "matrices_per_batch": mats / max(nb, 1),
        "vertices_per_batch": sum(b.n_vertices for b in batches) / max(nb, 1),
    }
