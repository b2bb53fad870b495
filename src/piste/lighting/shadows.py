"""Terrain self-shadowing for the light-map baker: shadow rays against the exact patch surfaces.

Every sample point that a direct light actually reaches (``light_terms > 0``) casts one ray towards
the light: towards ``-direction`` for a directional light, to the light's position for point and
spot lights (stopping just short of it).  Rays go to :func:`piste.terrain.query.ray_intersect`
(a BVH over patch bounds, exact Newton intersection) in any-hit mode.

Cost (default course, 8x8, sun at 23 degrees): ~160k sun rays, 2 % occluded, ~25 us per ray on one
core.  A conservative height-field pre-test (an upper-bound height grid over x, y) was tried and
dropped: a ray starting on the surface is always below the bound of its own cell, so the near
field needs the exact test anyway, and exact rays cut to 5 m still cost ~60 % of full-length ones.

An area sun (``sun_radius > 0`` degrees): each point's ray towards a directional light is replaced
by rays to jittered strata of the sun's disc (:func:`piste.lighting.sampling.disc_directions`):
eight rim strata first, and all ``sun_rays`` (64: 8 x 8) only where those disagree; the visibility
is the unoccluded fraction (soft shadows, penumbrae).  Sampling the rim eight ways finds every
penumbra sample of the tests' and benchmark's scenes (same error as casting all 64 everywhere) at
about 8 rays a lit sample.  ``sun_radius = 0`` is the
hard sun, one ray, bit-identical to before.

Far-field occluders (:func:`far_field_occluded`): a tiled build bakes each tile against the exact
patches of its 3 x 3 neighbourhood only; beyond it, rays towards a directional light are marched
over a coarse height grid of the whole world (the surface every 7.5 m for 30 m patches, max-pooled
when that grid has more than 2,048 cells a side), so a mountain casts its shadow as far as the sun
angle says.
Elementwise arithmetic only (no BLAS): the same bits in any process.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from piste.lighting.lights import DirectionalLight, Lights, PointLight, SpotLight, light_vectors
from piste.lighting.sampling import disc_directions, strata_side
from piste.terrain.net import PatchNet
from piste.terrain.query import ray_intersect

__all__ = ["shadow_rays", "shadow_visibility", "ray_offset", "far_field_occluded"]


def ray_offset(net: PatchNet) -> float:
    """Distance shadow-ray origins are lifted off the surface: 1e-5 of the net's diagonal,
    at least 1e-6 (model units)."""
    lo, hi = net.bounds
    return max(float(np.linalg.norm(hi - lo)) * 1e-5, 1e-6)


def shadow_rays(light: DirectionalLight | PointLight | SpotLight, positions: np.ndarray, normals: np.ndarray,
                eps: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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


def _exact_occluded(net: PatchNet, origins: np.ndarray, directions: np.ndarray, t_max: np.ndarray) -> np.ndarray:
    if len(origins) == 0:
        return np.zeros(0, dtype=bool)
    hits = ray_intersect(net, origins, directions, t_max=t_max, any_hit=True)
    return np.asarray(hits.hit, dtype=bool)


def shadow_visibility(net: PatchNet, lights: Lights, positions: npt.ArrayLike, normals: npt.ArrayLike, terms: np.ndarray,
                      stats: dict[str, int] | None = None, sun_radius: float = 0.0,
                      sun_rays: int = 64, ids: npt.ArrayLike | None = None, seed: int = 0,
                      sun_adaptive: bool = True) -> np.ndarray:
    """Visibility of every direct light at every point, 1 = lit, 0 = shadowed (fractions under an
    area sun).

    Parameters
    ----------
    net : PatchNet (the occluders)
    lights : Lights
    positions, normals : (k, 3) float64 sample points
    terms : (k, m) float64 from :func:`~piste.lighting.lights.light_terms` (rays are cast only
        where a light contributes and casts shadows)
    stats : optional dict, incremented with ``rays`` and ``rays_occluded``
    sun_radius : angular radius of directional lights in degrees (0: a point sun, one ray)
    sun_rays : rays per point to the sun's disc (a square number: strata) when ``sun_radius > 0``
    ids : (k,) int global sample indices (the disc jitter's counters; default ``arange(k)``)
    seed : the jitter's seed
    sun_adaptive : first the rays of eight rim strata (the corners and the middle of each side of
        the ``s x s`` strata: the disc's rim eight ways); all ``sun_rays`` only where those disagree
        (a penumbra); False: all rays everywhere (the references)

    Returns
    -------
    (k, m) float64 in [0, 1] (0.0 / 1.0 without an area sun).
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
        if sun_radius > 0.0 and isinstance(light, DirectionalLight):
            sid = np.arange(len(positions)) if ids is None else np.asarray(ids)
            frac, n_rays, n_occ = _soft_visibility(net, light, positions[idx], normals[idx], sid[idx], eps,
                                                   sun_radius, sun_rays, seed, sun_adaptive)
            vis[idx, col] = frac
        else:
            o, dvec, tm = shadow_rays(light, positions[idx], normals[idx], eps)
            occ = _exact_occluded(net, o, dvec, tm)
            vis[idx[occ], col] = 0.0
            n_rays, n_occ = len(idx), int(occ.sum())
        if stats is not None:
            stats["rays"] = stats.get("rays", 0) + n_rays
            stats["rays_occluded"] = stats.get("rays_occluded", 0) + n_occ
    return vis


def _soft_visibility(net: PatchNet, light: DirectionalLight, positions: np.ndarray, normals: np.ndarray, ids: np.ndarray, eps: float, radius: float, rays: int, seed: int,
                     adaptive: bool = True, batch: int = 65536) -> tuple[np.ndarray, int, int]:
    """Unoccluded fraction of ``rays`` rays per point to the disc of ``light`` (radius degrees):
    ``(k,)`` float64, the rays cast and how many were occluded.  ``adaptive``: eight rim strata
    first, the rest only where those disagree."""
    k = len(positions)
    frac = np.empty(k)
    n_rays = n_occ = 0
    axis = -np.asarray(light.direction, dtype=np.float64)
    s = strata_side(rays, "sun_rays")
    # the rim, eight ways: the corner strata and one stratum in the middle of each side
    m = s // 2
    rim = [0, s - 1, s * (s - 1), s * s - 1, m, (s - 1) * s + (s - 1 - m), m * s + s - 1, (s - 1 - m) * s]
    first = np.unique(rim) if adaptive and s >= 4 else np.arange(rays)
    rest = np.setdiff1d(np.arange(rays), first)
    step = max(1, batch // rays)

    def occluded(p: np.ndarray, n: np.ndarray, d: np.ndarray) -> np.ndarray:
        o = np.repeat(p + eps * n, d.shape[1], axis=0) + eps * d.reshape(-1, 3)
        dd = np.ascontiguousarray(d.reshape(-1, 3))
        return _exact_occluded(net, o, dd, np.full(len(dd), np.inf)).reshape(d.shape[:2])

    for lo in range(0, k, step):
        hi = min(lo + step, k)
        d = disc_directions(axis, ids[lo:hi], rays, radius, seed)  # (b, rays, 3)
        occ = np.zeros(d.shape[:2], dtype=bool)
        occ[:, first] = occluded(positions[lo:hi], normals[lo:hi], d[:, first])
        n_rays += len(occ) * len(first)
        mixed = np.flatnonzero(occ[:, first].any(axis=1) & ~occ[:, first].all(axis=1)) if len(rest) else np.zeros(0, np.int64)
        if len(mixed):
            occ[np.ix_(mixed, rest)] = occluded(positions[lo:hi][mixed], normals[lo:hi][mixed], d[mixed][:, rest])
            n_rays += len(mixed) * len(rest)
        agree = np.ones(len(occ), dtype=bool)
        if len(mixed):
            agree[mixed] = False
        # where the rim rays agree the disc is taken as whole (lit or shadowed): their value for all
        frac[lo:hi] = np.where(agree, 1.0 - occ[:, first].mean(axis=1), 1.0 - occ.mean(axis=1))
        n_occ += int(occ.sum())
    return frac, n_rays, n_occ


def far_field_occluded(heights: npt.ArrayLike, origin: Sequence[float] | np.ndarray, cell: Sequence[float] | np.ndarray,
                       origins: npt.ArrayLike, directions: npt.ArrayLike, box: Sequence[float] | np.ndarray, batch: int = 1 << 22) -> np.ndarray:
    """Which rays pass below a coarse height grid outside an excluded box (the far-field shadow test).

    The grid's nodes are at ``(origin[0] + j * cell[0], origin[1] + i * cell[1])`` holding
    ``heights[i, j]``; between nodes the surface is bilinear.  Each ray is marched from where it
    leaves ``box`` (the region whose occluders were tested exactly) until it leaves the grid or
    climbs above its highest node, in steps of half a cell horizontally; a ray is occluded when it
    passes below the surface at any step.

    Parameters
    ----------
    heights : (ny, nx) float64 metres, ny, nx >= 2
    origin, cell : (x, y) of node ``[0, 0]`` and the node spacing (positive), metres
    origins, directions : (k, 3) float64 ray origins and unit directions
    box : (x0, y0, x1, y1) the excluded region (rays starting outside it are marched from their start)
    batch : most ray samples held at once

    Returns
    -------
    (k,) bool, True where the far field occludes the ray.
    """
    h = np.asarray(heights, dtype=np.float64)
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    k = len(o)
    out = np.zeros(k, dtype=bool)
    ny, nx = h.shape
    if k == 0 or ny < 2 or nx < 2:
        return out
    cx, cy = float(cell[0]), float(cell[1])
    gx0, gy0 = float(origin[0]), float(origin[1])
    gx1, gy1 = gx0 + (nx - 1) * cx, gy0 + (ny - 1) * cy
    zmax = float(h.max())

    def leave(lo: float, hi: float, p: np.ndarray, v: np.ndarray) -> np.ndarray:  # the ray parameter where p + t v leaves [lo, hi] (inf when v == 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(v > 0, (hi - p) / v, np.where(v < 0, (lo - p) / v, np.inf))
        return np.maximum(t, 0.0)

    bx0, by0, bx1, by1 = (float(v) for v in box)
    inside = (o[:, 0] >= bx0) & (o[:, 0] <= bx1) & (o[:, 1] >= by0) & (o[:, 1] <= by1)
    t0 = np.where(inside, np.minimum(leave(bx0, bx1, o[:, 0], d[:, 0]), leave(by0, by1, o[:, 1], d[:, 1])), 0.0)
    t1 = np.minimum(leave(gx0, gx1, o[:, 0], d[:, 0]), leave(gy0, gy1, o[:, 1], d[:, 1]))
    with np.errstate(divide="ignore", invalid="ignore"):
        top = np.where(d[:, 2] > 0, (zmax - o[:, 2]) / d[:, 2], np.inf)
    t1 = np.minimum(t1, np.maximum(top, 0.0))
    dxy = np.hypot(d[:, 0], d[:, 1])
    with np.errstate(divide="ignore"):
        dt = np.where(dxy > 1e-9, 0.5 * min(cx, cy) / dxy, np.inf)
    live = np.flatnonzero((t1 > t0) & np.isfinite(dt))
    if len(live) == 0:
        return out
    steps = np.floor((t1[live] - t0[live]) / dt[live]).astype(np.int64) + 2  # both ends included
    order = live[np.argsort(steps, kind="stable")]
    steps = np.sort(steps, kind="stable")
    rows = max(1, batch // int(steps[-1]))  # rays of similar length together (sorted by length)
    for lo in range(0, len(order), rows):
        hi = min(lo + rows, len(order))
        width = int(steps[hi - 1])
        r = order[lo:hi]
        j = np.arange(width, dtype=np.float64)[None, :]
        t = np.minimum(t0[r, None] + j * dt[r, None], t1[r, None])
        px = o[r, 0, None] + t * d[r, 0, None]
        py = o[r, 1, None] + t * d[r, 1, None]
        pz = o[r, 2, None] + t * d[r, 2, None]
        fx = np.clip((px - gx0) / cx, 0.0, nx - 1.0)
        fy = np.clip((py - gy0) / cy, 0.0, ny - 1.0)
        ix = np.minimum(fx.astype(np.int64), nx - 2)
        iy = np.minimum(fy.astype(np.int64), ny - 2)
        ux, uy = fx - ix, fy - iy
        z0 = h[iy, ix] + ux * (h[iy, ix + 1] - h[iy, ix])
        z1 = h[iy + 1, ix] + ux * (h[iy + 1, ix + 1] - h[iy + 1, ix])
        surf = z0 + uy * (z1 - z0)
        out[r] = (pz < surf).any(axis=1)
    return out
