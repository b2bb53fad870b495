"""Terrain self-shadowing for the light-map baker: shadow rays against the exact patch surfaces.

Every sample point that a direct light actually reaches (``light_terms > 0``) casts one ray towards
the light: towards ``-direction`` for a directional light, to the light's position for point and
spot lights (stopping just short of it).  Rays go to :func:`piste.terrain.query.ray_intersect`
(a BVH over patch bounds, exact Newton intersection) in any-hit mode.

:class:`HeightBound` is a conservative pre-test for nets that are mostly height fields (terrain,
Z up): a grid over x, y holding, per cell, the highest control point of every patch whose bounds
touch the cell or its eight neighbours.  The convex-hull property puts the surface below that
height, so a ray segment that stays above it cannot hit anything there; a ray whose every segment
is clear (until it leaves the net's bounds or climbs over its top) is unoccluded without an exact
test.  Only the rest go to the exact intersector, so the pre-test never changes a result, it only
removes work.  It is valid for any net (overhangs included); it just helps less there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from piste.lighting.lights import DirectionalLight, Lights, light_vectors

__all__ = ["HeightBound", "shadow_rays", "shadow_visibility", "ray_offset"]


def ray_offset(net) -> float:
    """Distance shadow-ray origins are lifted off the surface: 1e-5 of the net's diagonal,
    at least 1e-6 (model units)."""
    lo, hi = net.bounds
    return max(float(np.linalg.norm(hi - lo)) * 1e-5, 1e-6)


def shadow_rays(light, positions, normals, eps: float):
    """Shadow rays from surface points towards ``light``.

    Parameters
    ----------
    light : DirectionalLight | PointLight | SpotLight
    positions, normals : (k, 3) float64
    eps : lift of the origin along the normal (and along the ray), model units

    Returns
    -------
    origins (k, 3), directions (k, 3) unit, t_max (k,) float64 (``inf`` for directional lights).
    """
    L, d = light_vectors(light, positions)
    origins = positions + eps * normals + eps * L
    if isinstance(light, DirectionalLight):
        t_max = np.full(len(positions), np.inf)
    else:
        t_max = np.maximum(d - 2.0 * eps, 0.0)
    return origins, np.ascontiguousarray(L), t_max


@dataclass
class HeightBound:
    """Upper bound of a net's height over an x, y grid (see the module docstring).

    Attributes
    ----------
    lo : (2,) float64 x, y of the grid's corner
    cell : float, cell size
    hmax : (ny, nx) float64, bound per cell, dilated by one cell (3 x 3 maximum)
    zmax : float, top of the whole net
    hi : (2,) float64 far x, y corner of the net's bounds
    """

    lo: np.ndarray
    hi: np.ndarray
    cell: float
    hmax: np.ndarray
    zmax: float

    @classmethod
    def build(cls, net, cells: int = 256) -> "HeightBound":
        """Grid of at most ``cells`` per side, cells no smaller than half the median patch size."""
        bmin, bmax = net.patch_bounds
        lo, hi = net.bounds
        ext = np.maximum(hi[:2] - lo[:2], 1e-9)
        size = max(float(ext.max()) / cells, 0.5 * float(np.median(net.patch_size)), 1e-9)
        nx, ny = (np.floor(ext / size).astype(int) + 1).tolist()
        ix0 = np.clip(((bmin[:, 0] - lo[0]) / size).astype(int), 0, nx - 1)
        ix1 = np.clip(((bmax[:, 0] - lo[0]) / size).astype(int), 0, nx - 1)
        iy0 = np.clip(((bmin[:, 1] - lo[1]) / size).astype(int), 0, ny - 1)
        iy1 = np.clip(((bmax[:, 1] - lo[1]) / size).astype(int), 0, ny - 1)
        sx, sy = ix1 - ix0 + 1, iy1 - iy0 + 1
        counts = sx * sy
        pid = np.repeat(np.arange(len(sx)), counts)
        local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
        cx = ix0[pid] + local % sx[pid]
        cy = iy0[pid] + local // sx[pid]
        grid = np.full((ny, nx), -np.inf)
        np.maximum.at(grid, (cy, cx), bmax[pid, 2])
        # dilate by one cell so a segment of xy length <= cell is covered from its start cell
        pad = np.pad(grid, 1, mode="constant", constant_values=-np.inf)
        dil = grid.copy()
        for dy in (0, 1, 2):
            for dx in (0, 1, 2):
                np.maximum(dil, pad[dy : dy + ny, dx : dx + nx], out=dil)
        return cls(lo=lo[:2].astype(np.float64), hi=hi[:2].astype(np.float64), cell=size, hmax=dil, zmax=float(hi[2]))

    def clear(self, origins, directions, t_max) -> np.ndarray:
        """Rays that certainly hit nothing, ``(k,)`` bool (False = unknown: test exactly).

        Parameters
        ----------
        origins, directions : (k, 3) float64 (directions unit)
        t_max : (k,) float64, may be ``inf``
        """
        o = np.asarray(origins, dtype=np.float64)
        d = np.asarray(directions, dtype=np.float64)
        k = len(o)
        # the end of the part of each ray that can meet the net: inside the xy box and below zmax
        t_end = np.asarray(t_max, dtype=np.float64).copy()
        with np.errstate(divide="ignore", invalid="ignore"):
            for axis in (0, 1):
                lo, hi = self.lo[axis], self.hi[axis]
                dv = d[:, axis]
                t_exit = np.where(dv > 0, (hi - o[:, axis]) / dv, np.where(dv < 0, (lo - o[:, axis]) / dv, np.inf))
                t_end = np.minimum(t_end, np.maximum(t_exit, 0.0))
            t_top = np.where(d[:, 2] > 0, (self.zmax - o[:, 2]) / d[:, 2], np.inf)
        t_end = np.minimum(t_end, np.maximum(t_top, 0.0))
        dxy = np.sqrt(d[:, 0] ** 2 + d[:, 1] ** 2)
        # parameter step so each segment moves at most one cell in x, y
        step = np.where(dxy > 1e-12, self.cell / np.maximum(dxy, 1e-12), np.inf)
        clear = np.ones(k, dtype=bool)
        ny, nx = self.hmax.shape
        active = np.arange(k)
        t0 = np.zeros(k)
        while len(active):
            oa, da = o[active], d[active]
            ta = t0[active]
            tb = np.minimum(ta + step[active], t_end[active])
            pa = oa + ta[:, None] * da
            zb = oa[:, 2] + tb * da[:, 2]
            ix = np.clip(((pa[:, 0] - self.lo[0]) / self.cell).astype(np.int64), 0, nx - 1)
            iy = np.clip(((pa[:, 1] - self.lo[1]) / self.cell).astype(np.int64), 0, ny - 1)
            ok = np.minimum(pa[:, 2], zb) > self.hmax[iy, ix]
            clear[active[~ok]] = False
            done = ~ok | (tb >= t_end[active])
            t0[active] = tb
            active = active[~done]
        return clear


def _exact_occluded(net, origins, directions, t_max) -> np.ndarray:
    from piste.terrain.query import ray_intersect

    if len(origins) == 0:
        return np.zeros(0, dtype=bool)
    hits = ray_intersect(net, origins, directions, t_max=t_max, any_hit=True)
    return np.asarray(hits.hit, dtype=bool)


def shadow_visibility(net, lights: Lights, positions, normals, terms, bound: HeightBound | None = None, stats=None):
    """Visibility of every direct light at every point, 1 = lit, 0 = shadowed.

    Parameters
    ----------
    net : PatchNet (the occluders)
    lights : Lights
    positions, normals : (k, 3) float64 sample points
    terms : (k, m) float64 from :func:`~piste.lighting.lights.light_terms` (rays are cast only
        where a light contributes and casts shadows)
    bound : optional :class:`HeightBound` pre-test
    stats : optional dict, incremented with ``rays``, ``rays_pretest_clear``, ``rays_exact``

    Returns
    -------
    (k, m) float64 of 0.0 / 1.0.
    """
    positions = np.asarray(positions, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    vis = np.ones(terms.shape)
    eps = ray_offset(net)
    for col, light in enumerate(lights.direct):
        if not light.shadows or light.intensity == 0.0:
            continue
        idx = np.nonzero(terms[:, col] > 0.0)[0]
        if len(idx) == 0:
            continue
        o, dvec, tm = shadow_rays(light, positions[idx], normals[idx], eps)
        todo = np.arange(len(idx))
        n_clear = 0
        if bound is not None:
            clear = bound.clear(o, dvec, tm)
            n_clear = int(clear.sum())
            todo = np.nonzero(~clear)[0]
        occ = _exact_occluded(net, o[todo], dvec[todo], tm[todo])
        vis[idx[todo[occ]], col] = 0.0
        if stats is not None:
            stats["rays"] = stats.get("rays", 0) + len(idx)
            stats["rays_pretest_clear"] = stats.get("rays_pretest_clear", 0) + n_clear
            stats["rays_exact"] = stats.get("rays_exact", 0) + len(todo)
            stats["rays_occluded"] = stats.get("rays_occluded", 0) + int(occ.sum())
    return vis
