"""Run-time occlusion culling (issue 27 item 6): a conservative software hierarchical-Z of the near
terrain, built on the CPU each frame before anything is drawn.

1. :func:`occluder_depth`: the nearest terrain patches' triangles (this frame's mesh, the same
   positions the GPU draws) rasterized at a low resolution (``cell`` pixels a cell).  Only
   front-facing triangles wholly between the near and far planes count (the terrain may cull back
   faces).  They make surfaces (triangles joined by shared edges; vertices matched by position);
   what a surface covers on the screen is bounded by its *rim* (the edges only one triangle has:
   silhouettes, the occluder set's border), so a cell no rim edge of the surface touches is covered
   by it all over or not at all: covered when the cell's centre lies in one of its triangles.  Then
   every pixel of the cell ends the terrain pass at least as near as the largest depth, over the
   cell's corners, of the planes of the surface's triangles that reach into the cell (depth is
   affine in screen space).  A cell's value is the smallest over the surfaces that cover it, +inf
   where none does.
2. :class:`HiZ`: the max-depth pyramid of those cells (each level the largest of 2 x 2 below).
3. :meth:`HiZ.occluded`: a box ``(lo, hi)`` is hidden when all eight corners lie in front of the
   eye and the nearest corner's depth is beyond (by ``eps``) the largest cell value over the box's
   screen rectangle (one pyramid level where it spans at most 2 x 2 texels).  Then every fragment
   of anything inside the box fails the depth test against terrain that *is* drawn (the triangle
   that sets a cell's value belongs to a patch that cannot itself be hidden: its box is nearer than
   that value), so culling it changes no pixel.

Terrain patches are tested with their control-point boxes (a Bezier patch and its geomorphs lie in
the hull of its control points), objects with their bounding spheres' boxes.

API
---
::

    occluder_depth(positions, indices, vp, size, cell=8) -> (gh, gw) float64 NDC depth (+inf: none)
    HiZ(depth, vp, size, cell=8, eps=1e-5)
    HiZ.occluded(lo, hi) -> (n,) bool
    near_patches(lo, hi, ids, eye, count) -> (k,) the ``count`` patch ids nearest the eye
    occlude_frame(terrain, mesh, camera, size, patch_lo, patch_hi, objects, objects_visible, prepare)
        -> (mesh, objects_visible, stats)       one frame: hidden patches re-prepared away, objects dropped
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from piste.errors import RenderError
from piste.render.shadow_pass import shadow_triangles

if TYPE_CHECKING:
    from piste.world.camera import Camera

__all__ = ["occluder_depth", "HiZ", "near_patches", "occlude_frame", "OCCLUDER_PATCHES", "CELL"]

#: pixels a side of one cell of the occluder depth (640x448: an 80 x 56 grid)
CELL = 8
#: how many of the nearest visible patches are rasterized as occluders
OCCLUDER_PATCHES = 256


def near_patches(lo: np.ndarray, hi: np.ndarray, ids: npt.ArrayLike, eye: npt.ArrayLike, count: int = OCCLUDER_PATCHES) -> np.ndarray:
    """The ``count`` of ``ids (p,)`` whose boxes ``lo, hi (N, 3)`` come nearest ``eye (3,)``, ``(k,) int64``."""
    ids = np.asarray(ids, dtype=np.int64)
    if len(ids) <= count:
        return ids
    e = np.asarray(eye, dtype=np.float64)
    d = np.linalg.norm(np.maximum(np.maximum(lo[ids] - e, e - hi[ids]), 0.0), axis=1)
    return ids[np.argsort(d, kind="stable")[:count]]


def _project(points: npt.ArrayLike, vp: npt.ArrayLike) -> np.ndarray:
    """``(n, 3)`` world points -> ``(n, 4)`` clip coordinates through ``vp (4, 4)``."""
    p = np.asarray(points, dtype=np.float64)
    m = np.asarray(vp, dtype=np.float64)
    return p @ m[:, :3].T + m[:, 3]


def occluder_depth(positions: npt.ArrayLike, indices: npt.ArrayLike, vp: npt.ArrayLike, size: Sequence[int], cell: int = CELL) -> np.ndarray:
    """The conservative low-resolution depth of the triangles (see the module docstring).

    Parameters
    ----------
    positions : (m, 3) float vertices;  indices : (t, 3) triangles into them
    vp : (4, 4) the camera's view-projection;  size : (W, H) pixels;  cell : pixels a cell

    Returns
    -------
    (gh, gw) float64 NDC depth (-1 near .. 1 far), row 0 at the bottom (GL's window y), +inf where
    the triangles do not surely cover the whole cell.
    """
    w, h = int(size[0]), int(size[1])
    if cell < 1 or w < 1 or h < 1:
        raise RenderError(f"occlusion: bad size {size} or cell {cell}")
    gw, gh = -(-w // cell), -(-h // cell)
    out = np.full((gh, gw), np.inf)
    idx = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    pos = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if len(idx) == 0:
        return out
    clip = _project(pos, vp)
    cw = clip[:, 3]
    front = cw > 1e-9
    ndc = clip[:, :3] / np.where(front, cw, 1.0)[:, None]
    sx = (ndc[:, 0] + 1.0) * 0.5 * w  # window pixels, y up
    sy = (ndc[:, 1] + 1.0) * 0.5 * h
    sz = ndc[:, 2]
    good_v = front & (sz >= -1.0) & (sz <= 1.0)  # inside the near and far planes
    a, b, c = idx[:, 0], idx[:, 1], idx[:, 2]
    x0, y0, x1, y1, x2, y2 = sx[a], sy[a], sx[b], sy[b], sx[c], sy[c]
    area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
    ok = good_v[a] & good_v[b] & good_v[c] & (area > 1e-9)  # front-facing (counter-clockwise), whole
    idx, area = idx[ok], area[ok]
    if len(idx) == 0:
        return out
    a, b, c = idx[:, 0], idx[:, 1], idx[:, 2]
    # 1. the boundary of what these triangles cover: edges only one of them has (vertices matched by
    # position: each patch has its own copy of its border's vertices); every cell such an edge touches
    # may be partly uncovered
    q = np.round(pos / 1e-3).astype(np.int64)  # millimetres
    q -= q.min(0)
    if len(q) and q.max() < (1 << 21):  # three 21-bit fields in one int64 (unique of rows sorts ~10x slower)
        _, vid = np.unique((q[:, 0] << 42) | (q[:, 1] << 21) | q[:, 2], return_inverse=True)
    else:
        _, vid = np.unique(q, axis=0, return_inverse=True)
    vid = vid.ravel()
    ev = np.stack([np.stack([a, b], 1), np.stack([b, c], 1), np.stack([c, a], 1)], 1).reshape(-1, 2)
    ea, eb = np.minimum(vid[ev[:, 0]], vid[ev[:, 1]]), np.maximum(vid[ev[:, 0]], vid[ev[:, 1]])
    _, inv, cnt = np.unique(ea * (int(vid.max()) + 1) + eb, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    lone = cnt[inv] == 1
    edge, edge_tri = ev[lone], np.flatnonzero(lone) // 3
    # the triangles joined by their shared edges: one surface each (a hill's face and the slope seen
    # past its crest are two: the back faces between them are not drawn)
    order = np.argsort(inv, kind="stable")
    first = np.flatnonzero(np.r_[True, inv[order][1:] != inv[order][:-1]])
    pair = (cnt[inv[order[first]]] >= 2)
    t1, t2 = order[first[pair]] // 3, order[first[pair] + 1] // 3
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    g = coo_matrix((np.ones(len(t1)), (t1, t2)), shape=(len(idx), len(idx)))
    comp = connected_components(g, directed=False)[1].astype(np.int64)
    G = gh * gw
    broken_keys = np.zeros(0, np.int64)
    if len(edge):
        p0 = np.stack([sx[edge[:, 0]], sy[edge[:, 0]]], 1)
        p1 = np.stack([sx[edge[:, 1]], sy[edge[:, 1]]], 1)
        step = 0.5 * cell
        ns = np.ceil(np.linalg.norm(p1 - p0, axis=1) / step).astype(np.int64) + 1
        ns = np.minimum(ns, 4 * (gw + gh))  # (clipped: an edge far off the screen)
        e = np.repeat(np.arange(len(edge)), ns)
        f = (np.arange(int(ns.sum())) - np.repeat(np.cumsum(ns) - ns, ns)) / np.maximum(np.repeat(ns, ns) - 1, 1)
        q = p0[e] + (p1[e] - p0[e]) * f[:, None]
        # every point of the edge lies within step / 2 of a sample (and the last samples' spacing is
        # at most step): the square of half-size step / 2 + slack round each sample, smaller than a
        # cell, meets every cell the edge does; its four corners name them
        r = 0.5 * step + 0.25
        for dx in (-r, r):
            for dy in (-r, r):
                ix = np.floor((q[:, 0] + dx) / cell).astype(np.int64)
                iy = np.floor((q[:, 1] + dy) / cell).astype(np.int64)
                m = (ix >= 0) & (ix < gw) & (iy >= 0) & (iy < gh)
                broken_keys = np.concatenate([broken_keys, comp[edge_tri[e[m]]] * G + iy[m] * gw + ix[m]])
    # 2. per (triangle, cell its screen bounds meet): the triangle's largest depth over the cell, and
    # whether it covers the cell's centre.  A cell no boundary edge touches is covered all over or
    # not at all; covered, every point of it is at least as near as the largest of the depths of the
    # triangles that reach into it
    X, Y = np.stack([sx[a], sx[b], sx[c]], 1), np.stack([sy[a], sy[b], sy[c]], 1)
    cx0 = np.clip(np.floor(X.min(1) / cell), 0, gw).astype(np.int64)
    cx1 = np.clip(np.floor(X.max(1) / cell), -1, gw - 1).astype(np.int64)
    cy0 = np.clip(np.floor(Y.min(1) / cell), 0, gh).astype(np.int64)
    cy1 = np.clip(np.floor(Y.max(1) / cell), -1, gh - 1).astype(np.int64)
    nx, ny = np.maximum(cx1 - cx0 + 1, 0), np.maximum(cy1 - cy0 + 1, 0)
    n = nx * ny
    tri = np.repeat(np.arange(len(idx)), n)
    j = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
    rx = np.repeat(np.maximum(nx, 1), n)
    ix = cx0[tri] + j % rx
    iy = cy0[tri] + j // rx
    cell_id = iy * gw + ix
    vx, vy, vz = X[tri], Y[tri], np.stack([sz[a], sz[b], sz[c]], 1)[tri]
    # the cell's centre inside the triangle (edges included: the interior edges are shared)
    px, py = (ix + 0.5) * cell, (iy + 0.5) * cell
    inside = np.ones(len(tri), dtype=bool)
    for k in range(3):
        k1 = (k + 1) % 3
        inside &= (vx[:, k1] - vx[:, k]) * (py - vy[:, k]) - (vy[:, k1] - vy[:, k]) * (px - vx[:, k]) >= 0.0
    # the depth plane z = za + p (x - xa) + q (y - ya), its largest over the cell's corners
    dx1, dy1, dz1 = vx[:, 1] - vx[:, 0], vy[:, 1] - vy[:, 0], vz[:, 1] - vz[:, 0]
    dx2, dy2, dz2 = vx[:, 2] - vx[:, 0], vy[:, 2] - vy[:, 0], vz[:, 2] - vz[:, 0]
    den = area[tri]
    pp = (dz1 * dy2 - dz2 * dy1) / den
    qq = (dx1 * dz2 - dx2 * dz1) / den
    x_lo, y_lo = ix * cell - vx[:, 0], iy * cell - vy[:, 0]
    zmax = (vz[:, 0] + np.maximum(pp * x_lo, pp * (x_lo + cell)) + np.maximum(qq * y_lo, qq * (y_lo + cell)))
    # per (surface, cell): covered (its centre in one of the surface's triangles, no rim edge of the
    # surface in the cell) and the surface's largest depth there; a cell takes its nearest such surface
    key = comp[tri] * G + cell_id
    uk, kinv = np.unique(key, return_inverse=True)
    kinv = kinv.ravel()
    far = np.full(len(uk), -np.inf)
    np.maximum.at(far, kinv, zmax)
    cov = np.zeros(len(uk), dtype=bool)
    cov[kinv[inside]] = True
    cov &= ~np.isin(uk, broken_keys)
    np.minimum.at(out.ravel(), (uk % G)[cov], far[cov])
    return out


class HiZ:
    """The max-depth pyramid of :func:`occluder_depth` and the box test (see the module docstring).

    Parameters
    ----------
    depth : (gh, gw) cell depths;  vp : (4, 4) the same view-projection;  size : (W, H) pixels
    cell : pixels a cell;  eps : NDC depth a box must lie beyond the cells by (the GPU's rounding)
    """

    def __init__(self, depth: npt.ArrayLike, vp: npt.ArrayLike, size: Sequence[int], cell: int = CELL,
                 eps: float = 1e-5) -> None:
        d = np.asarray(depth, dtype=np.float64)
        self.levels = [d]
        while max(d.shape) > 1:
            hh, ww = -(-d.shape[0] // 2), -(-d.shape[1] // 2)
            pad = np.full((2 * hh, 2 * ww), np.inf)
            pad[:d.shape[0], :d.shape[1]] = d
            d = pad.reshape(hh, 2, ww, 2).max(axis=(1, 3))
            self.levels.append(d)
        self.vp = np.asarray(vp, dtype=np.float64)
        self.size = (int(size[0]), int(size[1]))
        self.cell = int(cell)
        self.eps = float(eps)

    @property
    def covered(self) -> float:
        """The fraction of cells some occluder covers."""
        return float(np.isfinite(self.levels[0]).mean())

    def occluded(self, lo: npt.ArrayLike, hi: npt.ArrayLike) -> np.ndarray:
        """Which boxes ``lo, hi (n, 3)`` are certainly hidden by the occluders: ``(n,) bool``."""
        lo = np.asarray(lo, dtype=np.float64).reshape(-1, 3)
        hi = np.asarray(hi, dtype=np.float64).reshape(-1, 3)
        n = len(lo)
        if n == 0:
            return np.zeros(0, dtype=bool)
        sel = np.array([[i >> 0 & 1, i >> 1 & 1, i >> 2 & 1] for i in range(8)], dtype=bool)  # (8, 3)
        corners = np.where(sel[None], hi[:, None, :], lo[:, None, :])  # (n, 8, 3)
        clip = _project(corners.reshape(-1, 3), self.vp).reshape(n, 8, 4)
        w = clip[..., 3]
        front = (w > 1e-6).all(axis=1)
        sw = np.where(w > 1e-6, w, 1.0)
        ndc = clip[..., :3] / sw[..., None]
        W, H = self.size
        sx = (ndc[..., 0] + 1.0) * 0.5 * W
        sy = (ndc[..., 1] + 1.0) * 0.5 * H
        znear = ndc[..., 2].min(axis=1)
        g0 = self.levels[0]
        gh, gw = g0.shape
        # the cells the rectangle touches (a pixel of slack), clamped to the screen
        cx0 = np.clip(np.floor((sx.min(1) - 1.0) / self.cell), 0, gw - 1).astype(np.int64)
        cx1 = np.clip(np.floor((sx.max(1) + 1.0) / self.cell), 0, gw - 1).astype(np.int64)
        cy0 = np.clip(np.floor((sy.min(1) - 1.0) / self.cell), 0, gh - 1).astype(np.int64)
        cy1 = np.clip(np.floor((sy.max(1) + 1.0) / self.cell), 0, gh - 1).astype(np.int64)
        span = np.maximum(cx1 - cx0, cy1 - cy0) + 1
        level = np.ceil(np.log2(np.maximum(span, 1))).astype(np.int64)
        level = np.minimum(level, len(self.levels) - 1)
        bound = np.full(n, np.inf)
        for lv in np.unique(level):
            m = np.flatnonzero(level == lv)
            g = self.levels[int(lv)]
            ax0, ax1 = cx0[m] >> lv, np.minimum(cx1[m] >> lv, g.shape[1] - 1)
            ay0, ay1 = cy0[m] >> lv, np.minimum(cy1[m] >> lv, g.shape[0] - 1)
            bound[m] = np.maximum(np.maximum(g[ay0, ax0], g[ay0, ax1]), np.maximum(g[ay1, ax0], g[ay1, ax1]))
        return front & np.isfinite(bound) & (znear > bound + self.eps)


class _Hidden:
    """A terrain visibility hook (:meth:`piste.render.frame.TerrainRenderer.set_visibility`) that
    drops ``hidden (k,)`` patch ids from what ``inner`` (another hook or None) keeps."""

    def __init__(self, inner: Any, n: int, hidden: npt.ArrayLike) -> None:
        self.inner, self.n, self.hidden = inner, int(n), np.asarray(hidden, dtype=np.int64)

    def patches_at(self, eye: npt.ArrayLike) -> np.ndarray:
        keep = self.inner.patches_at(eye) if self.inner is not None else None
        keep = np.ones(self.n, dtype=bool) if keep is None else np.array(keep, dtype=bool)
        keep[self.hidden] = False
        return keep


def occlude_frame(terrain: Any, mesh: Any, camera: Camera, size: Sequence[int], patch_lo: np.ndarray, patch_hi: np.ndarray,
                  objects: Any = None, objects_visible: np.ndarray | None = None,
                  prepare: Callable[[], Any] | None = None, count: int = OCCLUDER_PATCHES, cell: int = CELL
                  ) -> tuple[Any, Any, dict[str, Any]]:
    """One frame's occlusion culling: the hierarchical-Z of the ``count`` nearest patches of
    ``mesh`` (this frame's prepared terrain), the patches and objects it hides dropped.

    Parameters
    ----------
    terrain : the :class:`piste.render.frame.TerrainRenderer` that prepared ``mesh``
    camera : its camera;  size : (W, H);  patch_lo, patch_hi : (N, 3) the net's patch bounds
    objects : the scene's objects (``center (n, 3)``, ``radius (n,)``) or None;  objects_visible : (m,) ids
    prepare : ``prepare()`` -> a new mesh with the terrain's current visibility hook (the same
        arguments the frame's mesh was prepared with)

    Returns
    -------
    (mesh, objects_visible, stats): the mesh without the hidden patches (re-prepared: the kept
    patches' triangles are the same), the objects kept, and the counts ``occluded_patches``,
    ``occluded_objects``, ``occluder_cells`` (fraction of cells covered).
    """
    w, h = int(size[0]), int(size[1])
    vp = camera.with_aspect(w, h).view_projection()
    pid = np.asarray(mesh.patch_ids, dtype=np.int64)
    near = near_patches(patch_lo, patch_hi, pid, camera.eye, count)
    pos, idx, _ = shadow_triangles(mesh, [near])
    hz = HiZ(occluder_depth(pos, idx, vp, (w, h), cell), vp, (w, h), cell)
    hidden = pid[hz.occluded(patch_lo[pid], patch_hi[pid])] if len(pid) else pid
    if len(hidden) and prepare is not None:
        inner = terrain.visibility
        terrain.visibility = _Hidden(inner, len(patch_lo), hidden)
        try:
            mesh = prepare()
        finally:
            terrain.visibility = inner
    n_obj = 0
    if objects is not None and objects_visible is not None and len(objects_visible):
        vis = np.asarray(objects_visible, dtype=np.int64)
        c, r = objects.center[vis], np.asarray(objects.radius, dtype=np.float64)[vis][:, None]
        gone = hz.occluded(c - r, c + r)
        n_obj = int(gone.sum())
        objects_visible = vis[~gone]
    return mesh, objects_visible, {"occluded_patches": int(len(hidden)), "occluded_objects": n_obj,
                                   "occluder_cells": hz.covered}
