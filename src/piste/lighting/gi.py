"""Global illumination for the light-map bake: diffuse inter-reflection, sky light, an area sun.

Beyond the game (the talk's closing "Better lighting (Global illumination?); Soft shadows").

The light-map value ``L(p)`` is what the terrain's texture colour is multiplied by, so a surface of
albedo ``rho`` under light-map value ``L`` sends radiance ``rho L`` (in light-map units: a white
surface under an unoccluded uniform sky of radiance ``S`` has ``L = S``).  With ``bounces = N >= 1``
the baker computes, at every sample point ``p`` with normal ``n``::

    L0(p) = max(0, D(p) + G0(p))                         sky light, no inter-reflection
    Lk(p) = max(0, D(p) + G0(p) + rho H[L(k-1)](p))      k = 1 .. N

* ``D(p)``: the direct lights with their shadows (the lighting equation of
  :mod:`piste.lighting.lights` without its ambient term, not clamped);
* ``G0(p) = S * (fraction of the cosine-weighted hemisphere that escapes to the sky)``: the ambient
  lights become a uniform sky of radiance ``S = sum I_a c_a`` that the terrain occludes;
* ``H[L](p)``: the cosine-weighted mean over the hemisphere of ``L`` at the surface each direction
  first hits (0 where it escapes or hits a surface's back).

Both integrals are estimated with the same ``rays`` (``s x s`` strata of the cosine-weighted
hemisphere, one jittered direction per stratum) from each sample, hit-tested against the exact
surface (:func:`piste.terrain.query.ray_intersect`); ``L(k-1)`` at a hit is the previous bounce's
light map bilinearly interpolated at the hit's patch parameters.  The rays are cast once; each bounce
is then a gather of texels.  Jitter comes from a counter-based hash of ``(seed, sample, ray)``, so a
sample's rays do not depend on batching, chunking or the number of workers: the bake stays
deterministic.

``bounces = 0`` is the lighting equation as before (ambient light everywhere, unoccluded).

Tracers: ``"exact"`` (the default) hit-tests the exact bicubic patches; ``"embree"`` (Intel Embree
through ``embreex``, the ``bench`` extra) the net tessellated at 16 vertices a side, a hit's patch
parameters interpolated from its triangle's corners, each ray's origin lifted off the surface by
twice its patch's chord error (a ray leaving a concave surface would meet the chords above its
origin).  The two give slightly different light maps (each deterministic), so the tracer is part
of a bake's inputs (its key and manifest), never chosen by what happens to be installed.

:func:`path_traced_reference` is the slow, exact way to the same quantity: independent Monte Carlo
paths of up to ``N + 1`` diffuse segments with the direct lights evaluated (shadow rays) at every
vertex on the exact surface, no light-map interpolation and no strata.

The area sun (:func:`~piste.lighting.sampling.disc_directions`): a directional light with ``sun_radius`` degrees is a
disc of that angular radius; the shadow ray of each sample goes to ``sun_rays`` points on it
(``s x s`` strata of the disc, jittered per sample; eight on the rim first, the rest only in a
penumbra: :mod:`piste.lighting.shadows`), visibility = the unoccluded fraction.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from piste.errors import MissingExtraError, ValidationError
from piste.lighting.lightmap import sample_points
from piste.lighting.lights import AmbientLight, DirectionalLight, Lights, light_terms
from piste.lighting.sampling import cosine_directions, disc_directions, frame, hash_uniform, strata_side
from piste.lighting.shadows import ray_offset, shadow_visibility
from piste.terrain.net import PatchNet
from piste.terrain.query import ray_intersect
from piste.terrain.tessellate import tessellate

__all__ = [
    "DEFAULT_GATHER_RAYS",
    "off_fold",
    "DEFAULT_ALBEDO",
    "REAL_SUN_RADIUS",
    "GatherHits",
    "TRACERS",
    "EmbreeGather",
    "hash_uniform",
    "strata_side",
    "cosine_directions",
    "disc_directions",
    "direct_light",
    "gather_hits",
    "tile_lookup",
    "bounce_light",
    "path_traced_reference",
    "valley_scene",
    "reference_error",
    "check_bounces",
    "check_sun_radius",
    "MAX_BOUNCES",
]

#: gather rays per sample (8 x 8 strata)
DEFAULT_GATHER_RAYS = 64
#: the terrain's diffuse albedo for inter-reflection (fresh-ish snow)
DEFAULT_ALBEDO = 0.8
#: the real sun's angular radius, degrees
REAL_SUN_RADIUS = 0.27
#: most bounces accepted
MAX_BOUNCES = 16

def direct_light(lights: Lights, positions: np.ndarray, normals: np.ndarray, shadow: npt.ArrayLike | None = None) -> np.ndarray:
    """The direct lights' part of the lighting equation (no ambient term, not clamped).

    positions, normals (k, 3); shadow None or (k, m) visibility -> (k, 3) float64."""
    terms = light_terms(lights, positions, normals)
    if shadow is not None:
        terms = terms * np.asarray(shadow, dtype=np.float64)
    out = np.zeros((len(terms), 3))
    for col, light in enumerate(lights.direct):
        out += terms[:, col, None] * (light.intensity * np.asarray(light.color))[None, :]
    return out


#: the gather rays' tracers (see the module docstring)
TRACERS = ("exact", "embree")


class EmbreeGather:
    """Closest hits of rays on ``net`` tessellated at ``level`` vertices a side, through Embree.

    ``hits(origins (k, 3), directions (k, 3))`` -> ``patch (k,) int64`` (-1: no hit), ``u, v (k,)``
    float64 patch parameters, ``front (k,) bool`` (the ray meets the patch's normal side).
    :attr:`patch_chord`: how far each patch's triangles stray from it (callers lift ray origins by
    twice that: a ray leaving a concave surface would otherwise meet the chords above its origin)."""

    def __init__(self, net: PatchNet, level: int = 16) -> None:
        try:
            from embreex.mesh_construction import TriangleMesh
            from embreex.rtcore_scene import EmbreeScene
        except ImportError:
            raise MissingExtraError("bench", "the bake's Embree tracer", "embreex") from None
        m = tessellate(net, int(level), cache=False)
        self.tris = np.asarray(m.indices, dtype=np.int64)
        self.param = np.asarray(m.param, dtype=np.float64)
        self.vpatch = np.asarray(m.patch_ids, dtype=np.int64)[np.asarray(m.vertex_patch, dtype=np.int64)]
        pos = np.asarray(m.positions, dtype=np.float64)
        # chord error: the exact surface at each triangle's parameter centroid vs the triangle's centroid
        cpar = self.param[self.tris].mean(axis=1)
        tp = self.vpatch[self.tris[:, 0]]
        exact = _eval_at(net, tp, cpar[:, 0], cpar[:, 1])
        chord = np.linalg.norm(exact - pos[self.tris].mean(axis=1), axis=1)
        #: (n,) float64: each patch's largest chord error (at its triangles' centroids), model units
        self.patch_chord = np.zeros(len(net))
        np.maximum.at(self.patch_chord, tp, chord)
        self.scene = EmbreeScene()
        TriangleMesh(self.scene, np.ascontiguousarray(pos, dtype=np.float32), np.ascontiguousarray(self.tris, dtype=np.int32))

    def hits(self, origins: npt.ArrayLike, directions: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        o = np.ascontiguousarray(origins, dtype=np.float32)
        d = np.ascontiguousarray(directions, dtype=np.float32)
        r = self.scene.run(o, d, output=1)
        prim = np.asarray(r["primID"], dtype=np.int64)
        hit = prim >= 0
        tri = self.tris[np.where(hit, prim, 0)]
        bu = np.asarray(r["u"], dtype=np.float64)[:, None]
        bv = np.asarray(r["v"], dtype=np.float64)[:, None]
        par = (1.0 - bu - bv) * self.param[tri[:, 0]] + bu * self.param[tri[:, 1]] + bv * self.param[tri[:, 2]]
        patch = np.where(hit, self.vpatch[tri[:, 0]], -1)
        front = (np.asarray(r["Ng"], dtype=np.float64) * np.asarray(directions, dtype=np.float64)).sum(1) < 0.0
        return patch, np.clip(par[:, 0], 0.0, 1.0), np.clip(par[:, 1], 0.0, 1.0), front


def _eval_at(net: PatchNet, patch: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Exact surface points of ``patch (k,)`` at ``(u, v) (k,)``: ``(k, 3)`` float64 (cubic Bernstein)."""
    cp = np.asarray(net.control_points, dtype=np.float64)[patch]  # (k, 4, 4, 3): [i (u), j (v)]

    def bern(t: np.ndarray) -> np.ndarray:
        s = 1.0 - t
        return np.stack([s * s * s, 3 * s * s * t, 3 * s * t * t, t * t * t], -1)

    return np.einsum("kj,ki,kijc->kc", bern(v), bern(u), cp)


@dataclass
class GatherHits:
    """Where each gather ray of ``k`` samples went: ``patch (k, rays) int32`` (-1 escaped to the
    sky, -2 hit a surface's back), ``u, v (k, rays) float32`` patch parameters of the hit."""

    patch: np.ndarray
    u: np.ndarray
    v: np.ndarray

    @property
    def escaped(self) -> np.ndarray:
        """Fraction of each sample's rays that reached the sky, ``(k,)`` float64."""
        return (self.patch == -1).mean(axis=1)


def gather_hits(net: PatchNet, positions: npt.ArrayLike, normals: npt.ArrayLike, ids: npt.ArrayLike, rays: int = DEFAULT_GATHER_RAYS, seed: int = 0,
                batch: int = 4096, stats: dict[str, Any] | None = None, tracer: EmbreeGather | None = None,
                patches: npt.ArrayLike | None = None) -> GatherHits:
    """Cast every sample's cosine-weighted gather rays against the exact surface (or through
    ``tracer``, an :class:`EmbreeGather` of the net: origins lifted by twice their patch's chord
    error, ``patches (k,)`` each sample's patch).

    positions, normals : (k, 3) float64; ids : (k,) global sample indices (jitter counters).
    ``stats`` (optional dict) gets ``gather_rays`` and ``gather_escaped`` added."""
    pos = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    ids = np.asarray(ids)
    k = len(pos)
    patch = np.empty((k, rays), dtype=np.int32)
    u = np.empty((k, rays), dtype=np.float32)
    v = np.empty((k, rays), dtype=np.float32)
    eps = ray_offset(net)
    step = max(1, int(batch) // max(rays, 1) * 16)
    for lo in range(0, k, step):
        hi = min(lo + step, k)
        d = cosine_directions(nrm[lo:hi], ids[lo:hi], rays, seed).reshape(-1, 3)
        if tracer is None:
            o = np.repeat(pos[lo:hi] + eps * nrm[lo:hi], rays, axis=0)
            p, hu, hv, front = _exact_hits(net, o, d, eps)
        else:
            lift = eps + 2.0 * tracer.patch_chord[np.asarray(patches)[lo:hi]]
            o = np.repeat(pos[lo:hi] + lift[:, None] * nrm[lo:hi], rays, axis=0) + eps * d  # (Embree has no t_min)
            p, hu, hv, front = tracer.hits(o, d)
        p = np.where((p >= 0) & ~front, -2, p)
        patch[lo:hi] = p.reshape(hi - lo, rays)
        u[lo:hi] = hu.reshape(hi - lo, rays)
        v[lo:hi] = hv.reshape(hi - lo, rays)
    if stats is not None:
        stats["gather_rays"] = stats.get("gather_rays", 0) + int(patch.size)
        stats["gather_escaped"] = stats.get("gather_escaped", 0) + int((patch == -1).sum())
    return GatherHits(patch, u, v)


def _exact_hits(net: PatchNet, o: np.ndarray, d: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``patch (k,)`` (-1 none), ``u, v (k,)``, ``front (k,) bool`` of rays on the exact surface."""
    h = ray_intersect(net, o, d, t_min=eps)
    p = np.where(h.hit, h.patch, -1)
    front = ~h.hit | ((h.normal * d).sum(1) < 0.0)
    return p, np.nan_to_num(h.u), np.nan_to_num(h.v), front


def tile_lookup(tiles: np.ndarray, patch: npt.ArrayLike, u: npt.ArrayLike, v: npt.ArrayLike) -> np.ndarray:
    """Bilinear light of ``tiles (n, res, res, C)`` at patch parameters: ``patch, u, v (...)`` ->
    ``(..., C)`` float64 (texel ``[p, j, i]`` sits at ``(i / (res-1), j / (res-1))``).  Entries with
    ``patch < 0`` give 0."""
    t = np.asarray(tiles)
    res = t.shape[1]
    p = np.asarray(patch)
    ok = p >= 0
    pp = np.where(ok, p, 0)
    x = np.clip(np.asarray(u, dtype=np.float64), 0.0, 1.0) * (res - 1)
    y = np.clip(np.asarray(v, dtype=np.float64), 0.0, 1.0) * (res - 1)
    i0 = np.minimum(np.floor(x).astype(np.int64), res - 2)
    j0 = np.minimum(np.floor(y).astype(np.int64), res - 2)
    fx, fy = (x - i0)[..., None], (y - j0)[..., None]
    out = ((t[pp, j0, i0] * (1 - fx) + t[pp, j0, i0 + 1] * fx) * (1 - fy)
           + (t[pp, j0 + 1, i0] * (1 - fx) + t[pp, j0 + 1, i0 + 1] * fx) * fy)
    return np.where(ok[..., None], out, 0.0)


def bounce_light(direct: npt.ArrayLike, hits: GatherHits, sky: npt.ArrayLike, bounces: int,
                 albedo: npt.ArrayLike = DEFAULT_ALBEDO, batch: int = 8192,
                 weld: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
    """Iterate the bounces (module docstring) over whole tiles.

    Parameters
    ----------
    direct : (n, res, res, 3) float64 ``D`` (unclamped)
    hits : gather hits of the ``n * res * res`` samples, in tile order
    sky : (3,) sky radiance ``S``
    bounces : N >= 1
    albedo : scalar or (3,) diffuse albedo
    weld : optional ``callable(tiles) -> tiles`` applied to each bounce's light before it is gathered
        (the baker passes :func:`~piste.lighting.lightmap.weld_seam_light`: the bounce sees the
        light the renderer shows, seams welded)

    Returns
    -------
    (n, res, res, 3) float64 ``L_N`` (>= 0).
    """
    D = np.asarray(direct, dtype=np.float64)
    shape = D.shape
    flat_d = D.reshape(-1, 3)
    rho = np.broadcast_to(np.asarray(albedo, dtype=np.float64), (3,))
    base = flat_d + hits.escaped[:, None] * np.asarray(sky, dtype=np.float64)[None, :]
    L = np.maximum(base, 0.0)
    k, rays = hits.patch.shape
    for _ in range(int(bounces)):
        prev = L.reshape(shape) if weld is None else weld(L.reshape(shape))
        gathered = np.empty_like(base)
        for lo in range(0, k, batch):
            hi = min(lo + batch, k)
            vals = tile_lookup(prev, hits.patch[lo:hi], hits.u[lo:hi], hits.v[lo:hi])  # (b, rays, 3)
            gathered[lo:hi] = vals.sum(axis=1) / rays
        L = np.maximum(base + rho[None, :] * gathered, 0.0)
    return L.reshape(shape)


def path_traced_reference(net: PatchNet, lights: Lights, positions: npt.ArrayLike, normals: npt.ArrayLike, bounces: int, paths: int = 1024,
                          albedo: npt.ArrayLike = DEFAULT_ALBEDO, seed: int = 0, batch: int = 1 << 16) -> np.ndarray:
    """Monte Carlo path-traced light-map values at points: the reference for :func:`bounce_light`.

    Independent (not stratified) cosine-weighted paths of up to ``bounces + 1`` segments from each
    point; at every surface vertex the direct lights are evaluated with exact shadow rays from its
    exact position and normal, escapes collect the sky ``S`` (the ambient colour).  Estimates
    ``L_N`` without the clamps (the test scenes have no negative lights).

    positions, normals : (k, 3) float64 -> (k, 3) float64.  Cost: ``k * paths * (2 .. 2N + 2)`` rays.
    """
    pos = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    rho = np.broadcast_to(np.asarray(albedo, dtype=np.float64), (3,))
    sky = lights.ambient_color()
    eps = ray_offset(net)
    rng = np.random.default_rng(seed)

    def direct(p: np.ndarray, n: np.ndarray) -> np.ndarray:
        terms = light_terms(lights, p, n)
        vis = shadow_visibility(net, lights, p, n, terms)
        return direct_light(lights, p, n, vis)

    out = direct(pos, nrm)
    acc = np.zeros_like(out)
    k = len(pos)
    per = max(1, batch // paths)
    for lo in range(0, k, per):
        hi = min(lo + per, k)
        m = (hi - lo) * paths
        owner = np.repeat(np.arange(lo, hi), paths)
        p = np.repeat(pos[lo:hi], paths, axis=0)
        n = np.repeat(nrm[lo:hi], paths, axis=0)
        thr = np.ones((m, 3))
        alive = np.arange(m)
        for depth in range(int(bounces) + 1):
            if len(alive) == 0:
                break
            u1, u2 = rng.random(len(alive)), rng.random(len(alive))
            r, phi = np.sqrt(u1), 2.0 * np.pi * u2
            t, b = frame(n)
            d = (r * np.cos(phi))[:, None] * t + (r * np.sin(phi))[:, None] * b + np.sqrt(np.maximum(1 - u1, 1e-12))[:, None] * n
            h = ray_intersect(net, p + eps * n, d, t_min=eps)
            esc = ~h.hit
            np.add.at(acc, owner[alive[esc]], thr[esc] * sky[None, :])
            front = h.hit & ((h.normal * d).sum(1) < 0.0)
            if depth == int(bounces):
                break
            keep = np.nonzero(front)[0]
            alive, thr = alive[keep], thr[keep] * rho[None, :]
            p, n = h.position[keep], h.normal[keep]
            np.add.at(acc, owner[alive], thr * direct(p, n))
    return out + acc / paths


def check_bounces(bounces: Any) -> int:
    """``bounces`` as an int in [0, MAX_BOUNCES], else a ValidationError."""
    if isinstance(bounces, bool) or not isinstance(bounces, (int, np.integer)) or not 0 <= int(bounces) <= MAX_BOUNCES:
        raise ValidationError(f"bake: bounces must be an integer in [0, {MAX_BOUNCES}], got {bounces!r}")
    return int(bounces)


def check_sun_radius(radius: Any) -> float:
    """``radius`` degrees as a float in [0, 10], else a ValidationError."""
    try:
        r = float(radius)
    except (TypeError, ValueError):
        r = math.nan
    if isinstance(radius, (bool, str)) or not (0.0 <= r <= 10.0):
        raise ValidationError(f"bake: sun_radius must be a number of degrees in [0, 10], got {radius!r}")
    return r


def _flat_patches(p00: npt.ArrayLike, du: npt.ArrayLike, dv: npt.ArrayLike, nu: int, nv: int) -> np.ndarray:
    """``nu x nv`` flat bicubic patches spanning the parallelogram ``p00 + a du + b dv``:
    control points ``(nu * nv, 4, 4, 3)``; normal ``du x dv``."""
    s = np.linspace(0.0, 1.0, 3 * nu + 1)
    t = np.linspace(0.0, 1.0, 3 * nv + 1)
    tt, ss = np.meshgrid(t, s, indexing="ij")
    g = (np.asarray(p00, dtype=np.float64)[None, None] + ss[..., None] * np.asarray(du, dtype=np.float64)
         + tt[..., None] * np.asarray(dv, dtype=np.float64))
    return PatchNet.from_control_grid(g).control_points


def valley_scene(width: float = 12.0, length: float = 24.0, height: float = 10.0) -> tuple[PatchNet, Lights]:
    """The test scene of the bounce bake: a flat valley floor (``2 x 3`` patches, z = 0, x in
    ``[0, width]``) between two vertical walls (``2 x 3`` patches each) facing each other: the wall
    at x = 0 faces +x and the sun (sunlit), the wall at x = ``width`` faces -x, away from the sun
    (lit only by the sky and by what the valley reflects).  Its lights: a blue sky ambient and a sun
    travelling towards -x (it shadows the floor near the shaded wall's foot).  Patches 0-5 are the
    floor, 6-11 the sunlit wall, 12-17 the shaded wall."""
    W, D, H = float(width), float(length), float(height)
    net = PatchNet(np.concatenate([
        _flat_patches((0, 0, 0), (W, 0, 0), (0, D, 0), 2, 3),
        _flat_patches((0, 0, H), (0, 0, -H), (0, D, 0), 2, 3),
        _flat_patches((W, 0, 0), (0, 0, H), (0, D, 0), 2, 3),
    ]), name="valley")
    lights = Lights((AmbientLight((0.45, 0.55, 0.75), 0.4, name="sky"),
                     DirectionalLight((-0.6, 0.2, -0.77), (1.0, 0.92, 0.8), 1.0, name="sun")), name="valley")
    return net, lights


#: luminance weights (Rec. 709) for the relative errors
_LUMA = np.array([0.2126, 0.7152, 0.0722])


def off_fold(net: PatchNet, res: int) -> np.ndarray:
    """Light-map samples not on a fold, ``(k,)`` bool over ``sample_points(net, res)``'s samples: on
    a fold (the valley's floor-wall corners) the baker welds the two faces' light into one texel, a
    convention of the seams, not of the light transport, so comparisons with the path-traced
    reference leave those samples out."""
    pos, nrm = sample_points(net, res, smooth_seams=False)
    pos, nrm = pos.reshape(-1, 3), nrm.reshape(-1, 3)
    _, inv = np.unique(np.round(pos, 6), axis=0, return_inverse=True)
    inv = inv.ravel()
    fold = np.zeros(len(pos), dtype=bool)
    for g in np.unique(inv[np.bincount(inv)[inv] > 1]):
        members = np.flatnonzero(inv == g)
        if (nrm[members] @ nrm[members].T).min() < 0.5:
            fold[members] = True
    return ~fold


def reference_error(values: npt.ArrayLike, reference: npt.ArrayLike) -> np.ndarray:
    """Relative error of luminance, ``|Y(values) - Y(reference)| / Y(reference)``: ``(k, 3)`` each
    -> ``(k,)`` float64 (reference luminance must be > 0)."""
    y = np.asarray(values, dtype=np.float64) @ _LUMA
    yr = np.asarray(reference, dtype=np.float64) @ _LUMA
    return np.abs(y - yr) / yr
