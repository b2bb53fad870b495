"""Levels of detail for objects, chosen per instance by their error in pixels.

A distant tree that covers 20 pixels does not need the 212 triangles of its near self; on a software
rasterizer the per-triangle cost dominates such objects.  Each object kind gets a chain of index
lists over **the same vertices** (meshoptimizer's quadric simplifier; seams, where one position
carries two normals or UVs, collapse as pairs), each with its absolute object-space error in model
units.  At draw time an instance takes the coarsest level whose error, scaled by the instance and
projected at its nearest distance, stays under ``max_pixels`` (default one pixel: the scene's
pictures hold within their reference tolerance, ~0.05 % of pixels off by > 16 against full meshes,
with ~30 % fewer object triangles than at half a pixel).  The vertex buffers, baked per-vertex
colours (indexed by vertex) and compressed formats are shared by every level; only the index list
differs.

API
---
::

    object_lods(positions (v, 3), indices (t, 3), ratio=0.5, min_triangles=8, max_levels=6, prune=False) -> [ObjectLOD]
    lod_arrays(lods) -> {"lod_indices": (m,) uint32, "lod_triangles": (l,) int64, "lod_errors": (l,) float64}
    stored_lods(lod_indices, lod_triangles, lod_errors, n_vertices, n_triangles) -> [ObjectLOD]   (checked)
    choose_lods(errors (l,), centers (n, 3), radius (n,), scale (n,), view_projection (4, 4), height_px,
                max_pixels=1.0) -> (n,) int level per instance
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from piste._data import FrozenDataMethods
from piste.errors import ConfigError, ValidationError

__all__ = ["ObjectLOD", "object_lods", "choose_lods", "instance_scale", "DEFAULT_LOD_PIXELS", "lod_arrays", "stored_lods",
           "LOD_ARRAYS"]

#: the arrays of one mesh's stored level chain (:func:`lod_arrays`; a bundle keeps them beside the mesh so a
#: renderer's set-up need not simplify every object kind again: ~3 ms of a fresh process's start)
LOD_ARRAYS = ("lod_indices", "lod_triangles", "lod_errors")

#: the largest projected simplification error an instance may show, in pixels (was 0.5: at 1 px the
#: default scene draws ~15k object triangles instead of ~21k, its frames within the reference
#: tolerance of the full meshes; 2 px would also hold but shows more: 0.17 % of pixels off by > 16)
DEFAULT_LOD_PIXELS = 1.0


@dataclass(frozen=True, repr=False, eq=False)  # (repr / eq / hash: piste._data.FrozenDataMethods)
class ObjectLOD(FrozenDataMethods):
    """One level: ``indices (t, 3)`` into the kind's vertices and its absolute ``error`` (model
    units, 0 for the full mesh)."""

    indices: np.ndarray
    error: float

    @property
    def n_triangles(self) -> int:
        return len(self.indices)


def object_lods(positions: npt.ArrayLike, indices: npt.ArrayLike, ratio: float = 0.5, min_triangles: int = 8,
                max_levels: int = 6, prune: bool = False) -> list:
    """The level chain of one mesh, level 0 the mesh itself.

    Parameters
    ----------
    positions : (v, 3) float vertex positions (model units)
    indices : (t, 3) int triangles
    ratio : triangles of each level as a fraction of the one before (a level that does not reach
        ``1 - (1 - ratio) / 2`` of the previous count is dropped and the chain ends)
    min_triangles : no level below this many triangles
    max_levels : at most this many levels (the full mesh included)
    prune : where a level cannot be reached keeping every part, let the simplifier remove small
        disconnected parts (its error counts them)

    Returns
    -------
    list of :class:`ObjectLOD`, errors strictly increasing, triangle counts strictly decreasing.
    """
    import meshoptimizer

    if not 0.0 < ratio < 1.0:
        raise ConfigError(f"object LOD ratio must be in (0, 1), got {ratio}")
    pos = np.ascontiguousarray(positions, dtype=np.float32).reshape(-1, 3)
    idx = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    levels = [ObjectLOD(idx.astype(np.uint32), 0.0)]
    if len(idx) == 0 or len(pos) == 0:
        return levels
    # not welded: meshoptimizer pairs the vertices of a seam (same position, other normal or UV)
    # itself and collapses them together, so each triangle keeps the vertex of its own side
    src = np.ascontiguousarray(idx.reshape(-1), dtype=np.uint32)
    last_err = 0.0
    while len(levels) < max_levels:
        n_prev = levels[-1].n_triangles
        target = max(int(n_prev * ratio), int(min_triangles))
        if target >= n_prev:
            break
        # each level simplifies the full mesh to its own target (errors do not compound); where the
        # connected simplification stalls (a tree's separate trunk and crown cones), the level is
        # tried again letting meshoptimizer drop whole small parts (PRUNE: counted in its error)
        found = None
        for opts in ((0, meshoptimizer.SIMPLIFY_PRUNE) if prune else (0,)):
            dst = np.zeros_like(src)
            err = np.zeros(1, np.float32)
            count = meshoptimizer.simplify(dst, src, pos, target_index_count=3 * target, target_error=1e9,
                                           options=meshoptimizer.SIMPLIFY_ERROR_ABSOLUTE | opts, result_error=err)
            tris = dst[:count].astype(np.int64).reshape(-1, 3)
            e = float(err[0])
            if 0 < len(tris) <= n_prev * (1.0 - (1.0 - ratio) / 2.0) and e > last_err:
                found = (tris, e)
                break
        if found is None:
            break
        levels.append(ObjectLOD(found[0].astype(np.uint32), found[1]))
        last_err = found[1]
    return levels


def lod_arrays(lods: list) -> dict[str, np.ndarray]:
    """A level chain (:func:`object_lods`) as arrays to store: ``lod_indices (m,) uint32`` (every
    level's triangles, level after level, flat), ``lod_triangles (l,) int64`` (triangles per level),
    ``lod_errors (l,) float64`` (each level's error, exactly as :class:`ObjectLOD` holds it)."""
    return {"lod_indices": np.concatenate([np.asarray(lv.indices, np.uint32).reshape(-1) for lv in lods]),
            "lod_triangles": np.array([lv.n_triangles for lv in lods], np.int64),
            "lod_errors": np.array([lv.error for lv in lods], np.float64)}


def stored_lods(lod_indices: npt.ArrayLike, lod_triangles: npt.ArrayLike, lod_errors: npt.ArrayLike,
                n_vertices: int, n_triangles: int) -> list:
    """The level chain :func:`lod_arrays` stored, checked against the mesh it belongs to (``n_vertices``,
    ``n_triangles``: level 0 is the full mesh): the same list of :class:`ObjectLOD` as
    :func:`object_lods` gave.  Raises :class:`~piste.errors.ValidationError` naming the array that
    does not fit (its shape, a count, an index past the vertices, errors not increasing)."""
    idx, tris, err = (np.asarray(a) for a in (lod_indices, lod_triangles, lod_errors))
    if idx.ndim != 1 or idx.dtype != np.uint32:
        raise ValidationError(f"lod_indices: expected a flat uint32 array, got {idx.shape} {idx.dtype}")
    if tris.ndim != 1 or tris.dtype.kind not in "iu" or not 1 <= len(tris) <= 64:
        raise ValidationError(f"lod_triangles: expected 1..64 integer counts, got {tris.shape} {tris.dtype}")
    if err.shape != tris.shape or err.dtype.kind != "f":
        raise ValidationError(f"lod_errors: expected {len(tris)} floats (one per level), got {err.shape} {err.dtype}")
    if int(tris[0]) != n_triangles or (tris < 1).any() or (np.diff(tris) >= 0).any():
        raise ValidationError(f"lod_triangles: expected {n_triangles} first (the full mesh), then strictly fewer, "
                              f"got {tris.tolist()}")
    if not np.isfinite(err).all() or err[0] != 0.0 or (np.diff(err) <= 0).any():
        raise ValidationError(f"lod_errors: expected 0 then strictly increasing finite errors, got {err.tolist()}")
    if 3 * int(tris.sum()) != len(idx):
        raise ValidationError(f"lod_indices: expected {3 * int(tris.sum())} indices (3 per triangle of every level), "
                              f"got {len(idx)}")
    if len(idx) and int(idx.max()) >= n_vertices:
        raise ValidationError(f"lod_indices: index {int(idx.max())} past the mesh's {n_vertices} vertices")
    ends = 3 * np.cumsum(tris)
    return [ObjectLOD(idx[e - 3 * int(t):e].reshape(-1, 3), float(x)) for t, e, x in zip(tris, ends, err)]


def instance_scale(matrix: npt.ArrayLike) -> np.ndarray:
    """The largest axis scale ``(n,)`` of object matrices ``(n, 4, 4)`` (how much a model-unit
    error grows in the world)."""
    m = np.asarray(matrix, dtype=np.float64).reshape(-1, 4, 4)
    return np.linalg.norm(m[:, :3, :3], axis=1).max(axis=1)


def choose_lods(errors: npt.ArrayLike, centers: npt.ArrayLike, radius: npt.ArrayLike, scale: npt.ArrayLike,
                view_projection: npt.ArrayLike, height_px: float,
                max_pixels: float = DEFAULT_LOD_PIXELS) -> np.ndarray:
    """The level ``(n,) int64`` each instance draws at: the coarsest whose projected error is at most
    ``max_pixels``.

    Parameters
    ----------
    errors : (l,) or (n, l) absolute model-space error of each level (ascending, ``errors[..., 0] == 0``;
        ``inf`` pads the levels a kind does not have)
    centers : (n, 3) world bounding-sphere centres;  radius : (n,) their radii
    scale : (n,) instance scales (:func:`instance_scale`)
    view_projection : (4, 4) perspective view-projection matrix (column vectors)
    height_px : the viewport's height in pixels
    max_pixels : the error allowed on screen (0 or less: always level 0)

    The distance is the instance's nearest view depth (centre depth minus radius, at least the
    near-plane scale ``1e-3``), so an instance the camera is inside keeps its full mesh; an instance
    whose sphere lies wholly behind the eye (no pixel of it can show) takes its coarsest level (else
    the clamped depth gave it the full mesh); an orthographic view scales every depth alike.
    """
    err = np.asarray(errors, dtype=np.float64)
    c = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
    n = len(c)
    if n == 0 or err.shape[-1] <= 1 or max_pixels <= 0:
        return np.zeros(n, np.int64)
    err = np.broadcast_to(err, (n, err.shape[-1]))
    vp = np.asarray(view_projection, dtype=np.float64)
    f = float(np.linalg.norm(vp[1, :3]))  # 1 / tan(fov_y / 2) for a rigid view (2 / height: orthographic)
    behind = np.zeros(n, bool)
    if np.abs(vp[3, :3]).max() > 0.0:  # perspective: clip w is the view depth
        r = np.broadcast_to(np.asarray(radius, dtype=np.float64), (n,))
        centre = c @ vp[3, :3] + vp[3, 3]
        behind = centre + r <= 0.0
        depth = np.maximum(centre - r, 1e-3)
    else:  # orthographic: the same scale at every depth
        depth = np.ones(n)
    px_per_unit = f * 0.5 * float(height_px) * np.asarray(scale, dtype=np.float64) / depth  # (n,)
    # level l is fine when err[l] * px_per_unit <= max_pixels; errors ascend, so count the fine ones
    ok = err * px_per_unit[:, None] <= float(max_pixels)
    ok[behind] = np.isfinite(err[behind])  # (the coarsest level each has: inf pads missing levels)
    return np.maximum(ok.sum(axis=1) - 1, 0).astype(np.int64)
