"""Projected rider shadows, as the talk does them: *low resolution model rendered into a texture from
the light's perspective; shadow texture projected onto terrain; extra pass for shadowed terrain
patches.*

Per rider ``i`` (all numpy until the draw):

1. :func:`shadow_matrices`: an orthographic view of the rider from the sun: a square of
   ``2 r`` around its bounding sphere, looking along the sun's direction, depth from ``r`` in front
   of the rider (towards the sun) to ``reach`` metres behind it;
2. the rider's **low-LOD** skinned model is drawn in white into its tile of one shadow texture
   (:meth:`ShadowPass.render_casters`, tiles side by side), closed once by caps over its holes and
   drawn with back faces culled (:func:`closed_caster_indices`: the same silhouette from about half
   the triangles; the scene's caster pass 1.65 -> 1.14 ms on llvmpipe, bench_frame.py's A/B), and
   only for riders whose shadow meets a patch drawn this frame;
3. :func:`shadow_patches`: the terrain patches whose control-point boxes meet that frustum
   (the frustum's six planes against the patch bounds, :func:`piste.render.frame.cull_boxes`),
   restricted to the patches tessellated this frame;
4. :meth:`ShadowPass.draw_receivers`: the extra pass: only those patches' triangles drawn again
   with the terrain's depth (``invariant`` positions, GL_LEQUAL, a tiny bias), the texture
   projected by the sun's matrix, multiplying the frame buffer (blend ``DST_COLOR, ZERO``) by
   ``shade`` where the texture is covered.  Points outside the tile or in front of the rider
   (nearer the sun) are left alone.  A resident terrain's triangles are drawn from its vertex blocks
   on the GPU by index (:func:`resident_shadow_triangles`, geomorphed as the terrain is); a streamed
   :class:`piste.terrain.TerrainMesh`'s are gathered and uploaded (:func:`shadow_triangles`).

The stats report the patches per rider and per frame (:attr:`ShadowPass.patch_counts`).

Soft shadows (``ShadowPass(soft=True, sun_radius=0.27)``, the CLI's ``--soft-shadows``, off by
default): percentage-closer soft shadows.  The casters also write their nearest light depth
(``shadow_caster_soft.frag.glsl``: alpha, blend MIN, over the caster's bounding sphere), and the
receivers (``shadow_receiver_soft.frag.glsl``) search the blockers in the disc a sun of that
angular radius can see past, size the penumbra ``(receiver - blocker) tan(radius)`` from their mean
depth and average the coverage over it.  :func:`area_light_visibility` is the reference: the
fraction of the sun's disc each point sees past the caster's triangles, ray traced in numpy.

API
---
::

    closed_caster_indices(indices, positions) -> (t + c, 3) the caster's triangles and caps over its holes
    shadow_matrices(centers, radius, sun_direction, reach=40.0) -> (n, 4, 4) light view-projections
    shadow_patches(patch_lo, patch_hi, light_vp, candidates=None) -> list of (k_i,) patch ids
    shadow_triangles(mesh, patch_lists) -> positions, indices, per-rider (first, count)
    resident_shadow_triangles(mesh, patch_lists) -> indices into the resident blocks, per-rider (first, count)
    area_light_visibility(points, triangles, sun_direction, sun_radius, rays=64) -> (p,) visibility
    ShadowPass(ctx, n_max=6, tile=128, soft=False, sun_radius=0.27)
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from piste.errors import RenderError
from piste.render.context import Offscreen, load_shader, release_framebuffer, set_depth_write
from piste.render.terrain_pass import RESIDENT_FORMAT
from piste.render.textures import MipLevels
from piste.terrain.query import height_at
from piste.world.camera import look_at, orthographic

if TYPE_CHECKING:
    import moderngl

    from piste.terrain.cull import PatchTree
    from piste.terrain.net import PatchNet
    from piste.terrain.resident import ResidentMesh
    from piste.terrain.tessellate import TerrainMesh

__all__ = ["closed_caster_indices", "shadow_matrices", "shadow_patches", "shadow_triangles", "resident_shadow_triangles", "ShadowPass", "SHADE", "sun_visibility",
           "area_light_visibility", "SUN_RADIUS", "ComputeMips"]

#: colour multiplier in full shadow (what the sun adds over the sky's blue ambient is taken away)
SHADE = (0.55, 0.6, 0.75)

#: the real sun's angular radius, degrees (the soft shadows' default)
SUN_RADIUS = 0.27

_GL_CLIP_DISTANCE0 = 0x3000
_MORPH_UNIT = 5  # the resident receivers' morph factors (3: the shadow texture, 4: the terrain's sunlight)


def closed_caster_indices(indices: npt.ArrayLike, positions: npt.ArrayLike) -> np.ndarray:
    """A caster's triangles closed by caps over its holes, to draw with back faces culled.

    Parameters
    ----------
    indices : (t, 3) the caster's triangles;  positions : (v, 3) its vertices (any pose: welded by
        position, so vertices split at UV / normal seams count as one)

    Returns
    -------
    (t + c, 3) uint32: ``indices`` then ``c`` cap triangles, into the same vertices (nothing new to skin).

    Why: the projected shadow is the casters' silhouette, and a *closed* oriented surface's silhouette is
    covered by its front faces alone (a line that crosses the surface crosses it as often one way as the
    other), so the caster pass can cull back faces and rasterize about half the triangles.  A rider's
    parts are open (limbs and head end in holes inside the torso), so each hole is capped first: the
    boundary of the triangles as a chain (the directed edges whose reverse is missing, with
    multiplicity) is a set of loops; every boundary edge ``a -> b`` gets the triangle ``(b, a, o)``, ``o``
    one vertex of its loop (its connected set of boundary edges): a fan that closes the loop whatever
    its shape.  The culled silhouette is then the open mesh's plus where a cap shows past it (the holes
    sit inside other parts: on the scene's riders a few texels of the 128-px tiles, tests/render/
    test_shadow_casters_closed.py).
    """
    tri = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    pos = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if len(tri) == 0:
        return np.zeros((0, 3), np.uint32)
    if tri.min() < 0 or tri.max() >= len(pos):
        raise RenderError(f"closed_caster_indices: indices must lie in 0..{len(pos) - 1}, got {tri.min()}..{tri.max()}")
    _, first, weld = np.unique(pos, axis=0, return_index=True, return_inverse=True)
    w = weld.reshape(-1)[tri]  # (t, 3) welded ids
    nv = int(w.max()) + 1
    e = np.stack([w[:, [0, 1]], w[:, [1, 2]], w[:, [2, 0]]], 1).reshape(-1, 2)
    e = e[e[:, 0] != e[:, 1]]  # (degenerate triangles' zero-length edges close nothing)
    # net count of each undirected edge's two directions: > 0 a -> b left over, < 0 b -> a
    lo, hi = np.minimum(e[:, 0], e[:, 1]), np.maximum(e[:, 0], e[:, 1])
    key, inv = np.unique(lo * nv + hi, return_inverse=True)
    net = np.bincount(inv.reshape(-1), weights=np.where(e[:, 0] == lo, 1.0, -1.0), minlength=len(key)).astype(np.int64)
    ka, kb = key // nv, key % nv
    m = np.abs(net)
    a = np.repeat(np.where(net > 0, ka, kb), m)  # boundary edges a -> b, each as often as it is left over
    b = np.repeat(np.where(net > 0, kb, ka), m)
    if len(a) == 0:
        return np.ascontiguousarray(tri, dtype=np.uint32)
    # loops: connected sets of boundary vertices (union-find by label propagation over the edges)
    label = np.arange(nv)
    while True:
        low = np.minimum(label[a], label[b])
        new = label.copy()
        np.minimum.at(new, a, low)
        np.minimum.at(new, b, low)
        new = new[new]
        if np.array_equal(new, label):
            break
        label = new
    o = label[a]  # the loop's lowest vertex: the fan's apex
    cap = np.stack([b, a, o], 1)
    cap = cap[(a != o) & (b != o)]  # (the apex's own edges: degenerate)
    return np.ascontiguousarray(np.concatenate([tri, first[cap]]), dtype=np.uint32)


def sun_disc_directions(sun_direction: npt.ArrayLike, sun_radius: float, rays: int) -> np.ndarray:
    """``rays`` unit directions ``(rays, 3) float64`` *towards* the sun, spread evenly over its disc
    of angular radius ``sun_radius`` degrees (Vogel's spiral in the disc's tangent plane)."""
    d = -np.asarray(sun_direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    a = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(d, a)
    u /= np.linalg.norm(u)
    v = np.cross(d, u)
    i = np.arange(int(rays), dtype=np.float64)
    r = np.tan(np.radians(float(sun_radius))) * np.sqrt((i + 0.5) / rays)
    ang = i * 2.39996323
    out = d + (r * np.cos(ang))[:, None] * u + (r * np.sin(ang))[:, None] * v
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def area_light_visibility(points: npt.ArrayLike, triangles: npt.ArrayLike, sun_direction: npt.ArrayLike, sun_radius: float = SUN_RADIUS, rays: int = 64,
                          chunk: int = 1 << 22) -> np.ndarray:
    """The reference of the soft shadows: the fraction of the sun's disc each point sees.

    Parameters
    ----------
    points : (p, 3) receiver points;  triangles : (t, 3, 3) the caster's triangles (world space)
    sun_direction : (3,) the way the light travels;  sun_radius : the disc's angular radius, degrees
    rays : directions over the disc per point (:func:`sun_disc_directions`)

    Returns
    -------
    (p,) float64 in 0..1: 1 sees the whole disc.  Every ray against every triangle
    (Moller-Trumbore), ``chunk`` ray-triangle pairs at a time, for the points whose cone of rays
    meets the triangles' bounding sphere (the others see the whole disc).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    if rays < 1:
        raise RenderError(f"area_light_visibility: rays must be >= 1, got {rays}")
    dirs = sun_disc_directions(sun_direction, sun_radius, rays)
    v0 = tri[:, 0]
    e1, e2 = tri[:, 1] - v0, tri[:, 2] - v0
    hit = np.zeros((len(pts), len(dirs)), dtype=bool)
    if len(tri) == 0 or len(pts) == 0:
        return np.ones(len(pts))
    # only the points whose cone of rays meets the caster's bounding sphere can be shaded
    flat = tri.reshape(-1, 3)
    centre = 0.5 * (flat.min(0) + flat.max(0))
    rad = float(np.linalg.norm(flat - centre, axis=1).max()) * 1.001 + 1e-9
    d = -np.asarray(sun_direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    rel = centre - pts
    along = rel @ d
    miss = np.linalg.norm(rel - along[:, None] * d, axis=1)
    spread = np.linalg.norm(rel, axis=1) * np.tan(np.radians(float(sun_radius))) * 1.001
    near = np.flatnonzero((along > -rad) & (miss <= rad + spread))
    step = max(1, chunk // (len(tri) * len(dirs)))
    for s0 in range(0, len(near), step):
        s = near[s0:s0 + step]
        o = pts[s, None, None, :] - v0  # (q, 1, t, 3)
        d = dirs[None, :, None, :]  # (1, k, 1, 3)
        pv = np.cross(d, e2)  # (1, k, t, 3)
        det = np.einsum("...i,...i", pv, e1)  # (1, k, t)
        inv = 1.0 / np.where(np.abs(det) < 1e-12, np.inf, det)
        u = np.einsum("...i,...i", o, pv) * inv  # (q, k, t)
        qv = np.cross(o, e1)  # (q, 1, t, 3)
        v = np.einsum("...i,...i", d, qv) * inv
        tt = np.einsum("...i,...i", qv, e2) * inv
        ok = (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (tt > 1e-6)
        hit[s] = ok.any(axis=2)
    return 1.0 - hit.mean(axis=1)


def shadow_matrices(centers: npt.ArrayLike, radius: npt.ArrayLike, sun_direction: npt.ArrayLike, reach: float = 40.0) -> np.ndarray:
    """Orthographic light view-projection matrices ``(n, 4, 4) float64`` of ``n`` shadow casters.

    Parameters
    ----------
    centers : (n, 3) bounding-sphere centres;  radius : (n,) or scalar radii (metres)
    sun_direction : (3,) the way the sun's light travels
    reach : how far behind the caster (along the light) the shadow can land, metres
    """
    c = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
    r = np.broadcast_to(np.asarray(radius, dtype=np.float64), (len(c),))
    d = np.asarray(sun_direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    up = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.95 else np.array([0.0, 1.0, 0.0])
    back = 2.0 * float(r.max()) + 1.0
    # every caster shares the view rotation (one light direction): only the translation differs
    view = np.broadcast_to(look_at(-d * back, np.zeros(3), up), (len(c), 4, 4)).copy()
    view[:, :3, 3] -= c @ view[0, :3, :3].T
    proj = np.zeros((len(c), 4, 4))
    for ri in sorted(set(r.tolist())):  # usually one radius for all (np.unique imports numpy.ma)
        sel = r == ri
        proj[sel] = orthographic(-ri, ri, -ri, ri, back - ri, back + reach)
    return proj @ view


def shadow_patches(patch_lo: np.ndarray, patch_hi: np.ndarray, light_vp: np.ndarray,
                   candidates: np.ndarray | None = None, tree: PatchTree | None = None) -> list:
    """Terrain patches each shadow frustum touches.

    Parameters
    ----------
    patch_lo, patch_hi : (p, 3) per-patch control-point bounds (``net.patch_bounds``)
    light_vp : (n, 4, 4) from :func:`shadow_matrices`
    candidates : (c,) patch ids to consider (the ones tessellated this frame), default all
    tree : the net's :class:`piste.terrain.cull.PatchTree` (same result, per rider a tree walk instead
        of one ``(6 n, c)`` product: linear in the riders and cheap for many)

    Returns
    -------
    list of n ``(k_i,) int64`` patch ids.  All ``6 n`` frustum planes are tested against all
    candidate boxes in one ``(6 n, 3) @ (3, c)`` product (a box is dropped only when it lies wholly
    outside one plane, as :func:`piste.render.frame.cull_boxes` does).
    """
    lo, hi = np.asarray(patch_lo), np.asarray(patch_hi)
    ids = np.arange(len(lo)) if candidates is None else np.asarray(candidates, dtype=np.int64)
    vps = np.asarray(light_vp, dtype=np.float64).reshape(-1, 4, 4)
    if len(vps) == 0:
        return []
    centre = ((lo[ids] + hi[ids]) * 0.5).T
    half = ((hi[ids] - lo[ids]) * 0.5).T
    r0, r1, r2, r3 = (vps[:, k] for k in range(4))  # rows of every matrix, (n, 4) each
    planes = np.stack([r3 + r0, r3 - r0, r3 + r1, r3 - r1, r3 + r2, r3 - r2], 1).reshape(-1, 4)
    planes = planes / np.linalg.norm(planes[:, :3], axis=1, keepdims=True)  # as frustum_planes()
    if tree is not None:  # hierarchical: each small shadow frustum walks the patch tree (O(n log N))
        keep = np.zeros(tree.n, dtype=bool)
        keep[ids] = True
        out = []
        for pl6 in planes.reshape(len(vps), 6, 4):
            got = tree.cull(pl6)
            out.append(got[keep[got]])
        return out
    ok = (planes[:, :3] @ centre + planes[:, 3:4] + np.abs(planes[:, :3]) @ half >= 0.0)
    ok = ok.reshape(len(vps), 6, -1).all(axis=1)
    return [ids[row] for row in ok]


def _ragged(starts, counts):
    counts = np.asarray(counts, dtype=np.int64)
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, np.int64)
    off = np.repeat(np.cumsum(counts) - counts, counts)
    return np.repeat(np.asarray(starts, dtype=np.int64), counts) + np.arange(total) - off


def shadow_triangles(mesh: TerrainMesh | ResidentMesh, patch_lists: Sequence[npt.ArrayLike],
                     light_vp: npt.ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The triangles of the given patches in this frame's terrain mesh, for the extra pass.

    Parameters
    ----------
    mesh : piste.terrain.TerrainMesh (``patch_ids``, ``vertex_start``, ``tri_start``)
    patch_lists : list of (k_i,) patch ids per rider
    light_vp : (n, 4, 4) or None: also drop the triangles of those patches that lie wholly outside
        their rider's shadow box (orthographic, so a box test of the 3 vertices is exact enough);
        this cuts the extra pass's fill to the shadows' neighbourhood

    Returns
    -------
    positions, indices, ranges : (m, 3) float32, (t, 3) uint32 into them, (n, 2) int64
        ranges are ``(first triangle, triangle count)`` per rider.  A patch shadowed by two riders
        is emitted twice (one draw per rider, each with its own shadow tile).
    """
    pid = np.asarray(mesh.patch_ids)
    lookup = np.full(int(pid.max()) + 1 if len(pid) else 1, -1, np.int64)
    lookup[pid] = np.arange(len(pid))
    slots, owner = [], []
    for i, pl in enumerate(patch_lists):
        pl = np.asarray(pl, dtype=np.int64)
        pl = pl[pl < len(lookup)]
        k = lookup[pl]
        k = k[k >= 0]
        slots.append(k)
        owner.append(np.full(len(k), i))
    k = np.concatenate(slots) if slots else np.zeros(0, np.int64)
    ts = np.asarray(mesh.tri_start)
    if hasattr(mesh, "vertex_first"):  # resident terrain: each patch's vertex block (geomorphed below)
        vfirst, vcount = np.asarray(mesh.vertex_first)[k], np.asarray(mesh.vertex_count)[k]
    else:
        vs = np.asarray(mesh.vertex_start)
        vfirst, vcount = vs[k], vs[k + 1] - vs[k]
    tcount = ts[k + 1] - ts[k]
    vsel = _ragged(vfirst, vcount)
    tsel = _ragged(ts[k], tcount)
    new_start = np.cumsum(vcount) - vcount  # where each slot's vertices land
    shift = np.repeat(new_start - vfirst, tcount)
    idx = (np.asarray(mesh.indices)[tsel].astype(np.int64) + shift[:, None]).astype(np.uint32)
    if hasattr(mesh, "morphed_positions"):
        pos = mesh.morphed_positions(vsel)
    else:
        pos = np.asarray(mesh.positions)[vsel].astype(np.float32)
    slot_owner = np.concatenate(owner) if len(k) else np.zeros(0, np.int64)
    tri_owner = np.repeat(slot_owner, tcount)
    if light_vp is not None and len(idx):
        # keep only the triangles whose light-space bounds meet the shadow tile's box: each rider's
        # vertices (contiguous: slots are listed rider by rider) through its own matrix, then a box
        # test of every triangle's three vertices
        vps = np.asarray(light_vp, dtype=np.float64)
        q = np.empty((len(pos), 3))
        vend = np.cumsum(np.bincount(slot_owner, weights=vcount, minlength=len(patch_lists))).astype(np.int64)
        for i, (v0, v1) in enumerate(zip(np.concatenate([[0], vend[:-1]]), vend)):
            if v1 > v0:
                q[v0:v1] = pos[v0:v1] @ vps[i, :3, :3].T + vps[i, :3, 3]
        # the corners' bounds element-wise ((t, 3) each): min/max over an axis of (t, 3, 3) was 10x slower
        a, b, c = q[idx[:, 0]], q[idx[:, 1]], q[idx[:, 2]]
        lo, hi = np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)
        keep = ((lo <= 1.0) & (hi >= -1.0)).all(1)
        idx, tri_owner = idx[keep], tri_owner[keep]
    per = np.bincount(tri_owner, minlength=len(patch_lists)).astype(np.int64)
    first = np.cumsum(per) - per
    return pos, idx, np.stack([first, per], 1)


def resident_shadow_triangles(mesh: ResidentMesh, patch_lists: Sequence[npt.ArrayLike]) -> tuple[np.ndarray, np.ndarray]:
    """:func:`shadow_triangles` for a :class:`~piste.terrain.resident.ResidentMesh` whose vertex blocks
    are on the GPU (:meth:`piste.render.terrain_pass.TerrainPass.resident_blocks`): the shadowed
    patches' triangles as indices into the blocks; nothing gathered, morphed or uploaded but them.

    Returns
    -------
    indices, ranges : (t, 3) uint32 rows of the resident blocks, (n, 2) int64
        ``(first triangle, triangle count)`` per rider.  Every triangle of the listed patches: no test against the
        rider's shadow box on the CPU (which needs the morphed positions), the receivers' clip
        distances cut each triangle to its frustum on the GPU (the same pixels; on the default
        course ~2,000 triangles instead of ~140, and the pass 0.37 ms instead of 0.62 on llvmpipe).
    """
    pid = np.asarray(mesh.patch_ids)
    lookup = np.full(int(pid.max()) + 1 if len(pid) else 1, -1, np.int64)
    lookup[pid] = np.arange(len(pid))
    ts = np.asarray(mesh.tri_start)
    starts, counts = [], []
    for pl in patch_lists:
        pl = np.asarray(pl, dtype=np.int64)
        k = lookup[pl[(pl >= 0) & (pl < len(lookup))]]
        k = k[k >= 0]
        starts.append(ts[k])
        counts.append(ts[k + 1] - ts[k])
    tcount = np.concatenate(counts) if counts else np.zeros(0, np.int64)
    idx = np.asarray(mesh.indices)[_ragged(np.concatenate(starts) if starts else tcount, tcount)]
    per = np.array([int(c.sum()) for c in counts], dtype=np.int64)
    first = np.cumsum(per) - per
    return np.ascontiguousarray(idx, dtype=np.uint32).reshape(-1, 3), np.stack([first, per], 1).reshape(-1, 2)


# sun_direction: a (3,) direction, typed Any: pipeline.build passes its Optional sun (the step runs only
# when it is set), which ArrayLike would reject
def sun_visibility(net: PatchNet, sun_direction: Any, spacing: float | None = None,
                   soften: float = 1.0) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """Where a height-field terrain sees the sun: ``(field (H, W) float32 0..1, rect (x0, y0, x1, y1))``.

    A grid of ``spacing`` metres (default: a quarter of the median patch) over the net's xy; each
    point marches towards the sun and is shadowed when the terrain rises above the sun's ray
    (a point 0.5 m above the snow, so the surface does not shadow itself).  ``soften`` blurs the
    edge (grid cells).  Points off the terrain count as sunlit.
    """
    lo, hi = net.bounds
    step = float(spacing) if spacing is not None else max(float(np.median(net.patch_size)) / 4.0, 0.5)
    nx = int(np.ceil((hi[0] - lo[0]) / step)) + 1
    ny = int(np.ceil((hi[1] - lo[1]) / step)) + 1
    x = lo[0] + step * np.arange(nx)
    y = lo[1] + step * np.arange(ny)
    xy = np.stack(np.meshgrid(x, y, indexing="xy"), -1).reshape(-1, 2)
    z, hit, _, _ = height_at(net, np.minimum(xy, hi[:2]))
    zg = np.where(hit, z, -np.inf).reshape(ny, nx)
    d = -np.asarray(sun_direction, dtype=np.float64)
    d = d / np.linalg.norm(d)  # towards the sun
    horiz = float(np.hypot(d[0], d[1]))
    lit = np.ones((ny, nx), bool)
    if horiz > 1e-6 and d[2] > 0:
        u = d[:2] / horiz
        tan_e = d[2] / horiz
        rise = float(hi[2] - lo[2])
        n_steps = int(min(np.ceil(rise / max(tan_e, 1e-3) / step), 4 * max(nx, ny))) + 1
        base = np.where(np.isfinite(zg), zg, np.inf) + 0.5
        iy, ix = np.mgrid[0:ny, 0:nx]
        for k in range(1, n_steps + 1):
            r = k * step
            jx = np.rint(ix + u[0] * k).astype(np.int64)
            jy = np.rint(iy + u[1] * k).astype(np.int64)
            ok = (jx >= 0) & (jx < nx) & (jy >= 0) & (jy < ny)
            if not ok.any():
                break
            h = np.full((ny, nx), -np.inf)
            h[ok] = zg[jy[ok], jx[ok]]
            lit &= ~(h > base + r * tan_e)
    f = lit.astype(np.float32)
    if soften:
        f = _gaussian_blur(f, float(soften))
    return f, (float(x[0]), float(y[0]), float(x[-1]), float(y[-1]))


def _gaussian_blur(f: np.ndarray, sigma: float) -> np.ndarray:
    """``f (H, W)`` blurred by a Gaussian of ``sigma`` cells: ``(H, W) float32``.

    numpy only (scipy.ndimage's import cost a fresh process ~0.25 s before its first frame); the
    same filter as ``scipy.ndimage.gaussian_filter(f, sigma)``: separable, radius
    ``int(4 sigma + 0.5)``, edges mirrored (``reflect``: d c b a | a b c d | d c b a), float64 sums.
    """
    r = int(4.0 * sigma + 0.5)
    if r < 1:
        return f.astype(np.float32)
    k = np.exp(-0.5 * (np.arange(-r, r + 1, dtype=np.float64) / sigma) ** 2)
    k /= k.sum()
    out = f.astype(np.float64)
    for axis in (0, 1):
        n = out.shape[axis]
        # mirror with the edge repeated: -1 -> 0, -2 -> 1, n -> n-1, n+1 -> n-2 (period 2n)
        j = np.mod(np.arange(-r, n + r), 2 * n)
        j = np.where(j >= n, 2 * n - 1 - j, j)
        pad = np.take(out, j, axis=axis)
        acc = np.zeros_like(out)
        for t in range(2 * r + 1):
            sl = [slice(None), slice(None)]
            sl[axis] = slice(t, t + n)
            acc += k[t] * pad[tuple(sl)]
        out = acc
    return out.astype(np.float32)


def _light_spans(light_vp) -> tuple[float, float]:
    """An orthographic light matrix's tile width ``2 r`` and depth range ``far - near``, metres."""
    m = np.asarray(light_vp, dtype=np.float64)
    return 2.0 / float(np.linalg.norm(m[0, :3])), 2.0 / float(np.linalg.norm(m[2, :3]))


class ComputeMips:
    """Mip levels ``1`` to ``levels`` of an RGBA8 texture redrawn from level 0 by a compute shader
    (``mip_levels.comp.glsl``), two levels a dispatch: the same levels as
    :class:`piste.render.textures.MipLevels` (and :func:`piste.render.textures.mip_chain`).

    Why: :class:`~piste.render.textures.MipLevels` binds a framebuffer per level, and llvmpipe
    ends its scene (rasterizes what was drawn) at each framebuffer change, and each level's draw
    samples the level the one before wrote: four waits for the rasterizer threads.  The two
    dispatches wait for none (measured on llvmpipe, 2 cores: the 4 levels of the 768 x 128 shadow
    texture 0.25 ms vs 0.38 ms; the scene's caster pass 1.35 vs 1.49 ms).  Each dispatch reads level
    ``l`` bound as an image (image unit 2; units 0 and 1 take the two levels written): ``texelFetch``
    through a sampler cost llvmpipe ~3x as much (0.57 ms vs 0.20 standalone; the caster pass 1.50 vs
    1.31 ms in bench_frame's A/B).  The levels must already exist (a
    :class:`~piste.render.textures.MipLevels` of the same texture allocates them, and is the
    fallback where this is not :meth:`supported`)."""

    def __init__(self, ctx, texture, levels: int):
        import moderngl

        if not self.supported(ctx, texture, levels):
            raise RenderError(f"ComputeMips: expected an RGBA8 texture whose sides halve exactly {levels} times "
                              f"(an even count, >= 2) and OpenGL 4.3, got {texture.size} on {ctx.version_code}")
        self.ctx, self.texture, self.levels = ctx, texture, int(levels)
        self.cs = ctx.compute_shader(load_shader("mip_levels.comp.glsl"))
        self._barrier = moderngl.TEXTURE_FETCH_BARRIER_BIT | moderngl.SHADER_IMAGE_ACCESS_BARRIER_BIT
        w, h = texture.size
        self._steps = [(lv, (w >> (lv + 2), h >> (lv + 2))) for lv in range(0, self.levels, 2)]

    @staticmethod
    def supported(ctx: moderngl.Context, texture: moderngl.Texture, levels: int) -> bool:
        """Whether this GL runs compute shaders (4.3) and ``texture`` is RGBA8 with sides that halve
        exactly ``levels`` (even, >= 2) times."""
        levels = int(levels)
        w, h = texture.size
        return (ctx.version_code >= 430 and levels >= 2 and levels % 2 == 0 and texture.components == 4
                and texture.dtype == "f1" and w % (1 << levels) == 0 and h % (1 << levels) == 0)

    def build(self) -> None:
        """Redraw levels ``1 .. levels`` from level 0 (what was drawn into the texture)."""
        ctx, tex, cs = self.ctx, self.texture, self.cs
        for lv, (w, h) in self._steps:
            cs["u_size"].value = (w, h)
            tex.bind_to_image(2, read=True, write=False, level=lv)  # (images, not a sampler: see the shader)
            tex.bind_to_image(0, read=False, write=True, level=lv + 1)
            tex.bind_to_image(1, read=False, write=True, level=lv + 2)
            cs.run((w + 7) // 8, (h + 7) // 8)
            ctx.memory_barrier(self._barrier)  # the next dispatch and the receivers sample these levels

    def release(self) -> None:
        self.cs.release()


class ShadowPass:
    """The shadow texture (``n_max`` tiles of ``tile`` x ``tile`` side by side) and both draws.

    ``soft``: percentage-closer soft shadows from a sun of ``sun_radius`` degrees (see the module
    docstring); False (default): the talk's hard projected shadows."""

    def __init__(self, ctx, n_max: int = 6, tile: int = 128, soft: bool = False, sun_radius: float = SUN_RADIUS):
        import moderngl

        sun_radius = float(sun_radius)
        if not 0.0 <= sun_radius <= 10.0 or not np.isfinite(sun_radius):
            raise RenderError(f"shadow pass: sun_radius must be 0..10 degrees, got {sun_radius}")
        self.soft = bool(soft)
        self.sun_radius = sun_radius
        self.ctx = ctx
        self.n_max = int(n_max)
        self.tile = int(tile)
        w, h = self.tile * self.n_max, self.tile
        self.texture = ctx.texture((w, h), 4)
        # mip-mapped (a few levels: tiles sit side by side): a distant rider's shadow covers a few
        # pixels, and point samples of its thin limbs and board would break it into dashes
        self.mip_levels = max(0, min(4, int(np.log2(self.tile)) - 3))
        # the levels redrawn by piste's own program (textures.MipLevels: from the shader cache, where
        # Mesa's glGenerateMipmap compiles its blit shader in every process, 70-110 ms at first use)
        self._mips = MipLevels(ctx, self.texture, self.mip_levels) \
            if MipLevels.supported(ctx, self.texture, self.mip_levels) else None
        if self._mips is None:
            self.texture.build_mipmaps(0, self.mip_levels)
        # two levels a compute dispatch where the GL has compute shaders (no framebuffer per level)
        self._mips_cs = ComputeMips(ctx, self.texture, self.mip_levels) \
            if self._mips is not None and ComputeMips.supported(ctx, self.texture, self.mip_levels) else None
        self.texture.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        self.texture.repeat_x = self.texture.repeat_y = False
        self.fbo = ctx.framebuffer(color_attachments=[self.texture])
        soft_name = "_soft" if self.soft else ""
        self.caster = ctx.program(vertex_shader=load_shader("shadow_caster.vert.glsl"),
                                  fragment_shader=load_shader(f"shadow_caster{soft_name}.frag.glsl"))
        self._receiver_fs = load_shader(f"shadow_receiver{soft_name}.frag.glsl")
        # the gathered receivers' program (:attr:`receiver`), compiled at its first use like the resident
        # one: a frame over resident terrain never draws it (~0.3 ms of a fresh process's set-up)
        self._receiver: Any = None
        # the uniforms both receiver programs share (each is compiled on first use)
        self._receiver_uniforms: dict = {"u_shadow": 3, "u_sunlit": 4, "u_morph": _MORPH_UNIT}
        if self.soft:
            self._receiver_uniforms.update(u_tan=float(np.tan(np.radians(sun_radius))), u_texel=1.0 / self.tile)
        #: draw the receivers from the terrain's resident vertex blocks by index where the frame's
        #: terrain is resident (``draw_receivers(terrain=...)``); False: gather, morph and upload the
        #: shadowed patches' vertices every frame (the same pixels; bench_frame.py's A/B)
        self.resident_receivers = True
        self._receiver_res: Any = None  # its program (RECEIVER_RESIDENT), compiled on first use
        self.sunlit = None
        self.set_sunlight(None)
        self._casts: dict = {}  # per caster group (one per rider model): its buffers
        #: hard shadows: draw the casters closed by caps over their holes with back faces culled
        #: (:func:`closed_caster_indices`: the same silhouettes from about half the triangles rasterized);
        #: False: every triangle, both sides (bench_frame.py's A/B).  Soft shadows draw every triangle
        #: (their nearest depth is not the culled surface's everywhere)
        self.cull_casters = True
        self._recv = {"pos": None, "idx": None, "vao": None}
        self._recv_res: dict = {"idx": None, "vao": None, "buf": None}  # the resident path's index buffer
        self.light_vp = np.zeros((0, 4, 4))
        self.patch_counts = []
        self.triangles = 0

    # ------------------------------------------------------------------ casters
    def render_casters(self, positions: np.ndarray, indices: np.ndarray, light_vp: np.ndarray, first: int = 0, group: int = 0,
                       draw: npt.ArrayLike | None = None) -> None:
        """Draw ``n`` riders' low-LOD meshes (``positions (n, v, 3)`` world space, shared
        ``indices (t, 3)``) into tiles ``first .. first + n - 1`` with ``light_vp (n, 4, 4)``.

        Several rider models: one call per model (``group`` names its buffers), the first with
        ``first=0`` clears the texture, later ones add their tiles.  ``draw``: ``(n,) bool``, the riders
        whose tiles are drawn (the scene passes those with shadow patches in view: no receiver samples
        the others' tiles, left clear); default all."""
        import moderngl

        pos = np.ascontiguousarray(positions, dtype=np.float32)
        n, v = pos.shape[:2]
        if first + n > self.n_max:
            raise RenderError(f"shadow pass: {first + n} casters, room for {self.n_max}")
        ctx = self.ctx
        c = self._casts.setdefault(group, {"pos": None, "idx": None, "vao": None, "nv": 0, "n": 0, "nt": 0,
                                           "src": None, "idx_c": None, "vao_c": None, "nt_c": 0})
        if c["vao"] is None or c["nv"] != v or c["n"] != n or (c["src"] is not indices and not np.array_equal(c["src"], indices)):
            for key in ("vao", "pos", "idx", "vao_c", "idx_c"):
                if c[key] is not None:
                    c[key].release()
                    c[key] = None
            offs = (np.arange(n, dtype=np.uint32) * v)[:, None, None]
            idx = (np.asarray(indices, np.uint32)[None] + offs).reshape(-1)
            c["pos"] = ctx.buffer(reserve=max(pos.nbytes, 4), dynamic=True)
            c["idx"] = ctx.buffer(idx.tobytes() if len(idx) else b"\0\0\0\0")
            c["vao"] = ctx.vertex_array(self.caster, [(c["pos"], "3f", "in_pos")], c["idx"], index_element_size=4)
            c["nv"], c["n"], c["nt"] = v, n, int(np.asarray(indices).shape[0])
            c["src"] = indices if isinstance(indices, np.ndarray) and not indices.flags.writeable else np.array(indices)
            if n and v and len(idx):  # the closed casters, made once per model (the first rider's pose welds them)
                closed = closed_caster_indices(indices, pos[0])
                idx_c = (closed[None] + offs).reshape(-1)
                c["idx_c"] = ctx.buffer(idx_c.tobytes())
                c["vao_c"] = ctx.vertex_array(self.caster, [(c["pos"], "3f", "in_pos")], c["idx_c"], index_element_size=4)
                c["nt_c"] = len(closed)
        if pos.nbytes:
            c["pos"].write(pos.tobytes())
        lvp = np.asarray(light_vp, dtype=np.float64).reshape(-1, 4, 4)
        if first == 0:
            self.light_vp = lvp
        else:
            self.light_vp = np.concatenate([self.light_vp[:first], lvp])
        self.fbo.use()
        if first == 0:
            self.fbo.clear(0.0, 0.0, 0.0, 1.0 if self.soft else 0.0)
        ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE | moderngl.BLEND)
        if self.soft:  # coverage: the largest; depth (alpha): the nearest
            ctx.enable(moderngl.BLEND)
            ctx.blend_equation = (moderngl.MAX, moderngl.MIN)
        closed = self.cull_casters and not self.soft and c["vao_c"] is not None
        vao, nt = (c["vao_c"], 3 * c["nt_c"]) if closed else (c["vao"], 3 * c["nt"])
        if closed:
            ctx.enable(moderngl.CULL_FACE)
            ctx.cull_face = "back"
        todo = range(n) if draw is None else np.flatnonzero(np.asarray(draw, dtype=bool).reshape(-1)[:n]).tolist()
        for i in todo:
            ctx.viewport = ((first + i) * self.tile, 0, self.tile, self.tile)
            self.caster["u_light_vp"].write(lvp[i].astype(np.float32).T.tobytes())
            if self.soft:
                span, depth = _light_spans(lvp[i])
                self.caster["u_depth_scale"].value = depth / span
            vao.render(moderngl.TRIANGLES, vertices=nt, first=i * nt)
        if closed:
            ctx.disable(moderngl.CULL_FACE)
        if self.soft:
            ctx.blend_equation = moderngl.FUNC_ADD
            ctx.disable(moderngl.BLEND)
        # this frame's tiles mip-mapped here, before the frame's main passes: glGenerateMipmap must wait
        # for what it reads, and after the terrain's draw llvmpipe waited for the whole terrain there
        if self._mips_cs is not None and self._mips_cs.levels == self.mip_levels:
            self._mips_cs.build()
        elif self._mips is not None and self._mips.levels == self.mip_levels:
            self._mips.build()
        else:  # (no exact halving, or mip_levels changed since set-up)
            self.texture.build_mipmaps(0, self.mip_levels)
        # and finished now (a few small tiles): a texture still being written when a later draw samples
        # it makes llvmpipe flush and wait for everything issued before that draw (the terrain)
        ctx.finish()
        ctx.enable(moderngl.DEPTH_TEST)

    def set_sunlight(self, field: np.ndarray | None = None,
                     rect: tuple[float, float, float, float] = (0.0, 0.0, 1.0, 1.0)) -> None:
        """Where the terrain itself sees the sun: ``field (H, W)`` float 0..1 over world xy
        ``rect = (x0, y0, x1, y1)`` (:func:`sun_visibility`), rows along y.  A rider's shadow
        darkens only sunlit terrain (inside the terrain's own shadow the light map already lacks
        the sun).  None: sunlit everywhere."""
        import moderngl

        f = np.ones((1, 1), np.float32) if field is None else np.asarray(field, np.float32)
        if self.sunlit is not None:
            self.sunlit.release()
        self.sunlit = self.ctx.texture((f.shape[1], f.shape[0]), 1, np.ascontiguousarray(f).tobytes(), dtype="f4")
        self.sunlit.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.sunlit.repeat_x = self.sunlit.repeat_y = False
        x0, y0, x1, y1 = (float(v) for v in rect)
        self._receiver_uniforms["u_sun_rect"] = (x0, y0, max(x1 - x0, 1e-9), max(y1 - y0, 1e-9))
        for p in (self._receiver, self._receiver_res):
            if p is not None:
                self._set_receiver_uniforms(p)

    @property
    def receiver(self) -> Any:
        """The receivers' program over gathered (uploaded) vertices, compiled at first use."""
        if self._receiver is None:
            self._receiver = self.ctx.program(vertex_shader=load_shader("shadow_receiver.vert.glsl"),
                                              fragment_shader=self._receiver_fs)
            self._set_receiver_uniforms(self._receiver)
        return self._receiver

    @receiver.setter
    def receiver(self, program: Any) -> None:
        self._receiver = program

    def _set_receiver_uniforms(self, p: Any) -> None:
        for name, value in self._receiver_uniforms.items():
            if name in p:
                p[name].value = value

    def _resident_receiver(self, buffer: moderngl.Buffer, idx: np.ndarray) -> tuple[Any, Any]:
        """The resident receivers' program and a vertex array over the terrain's ``buffer`` with this
        frame's ``idx`` written into its (orphaned) index buffer."""
        if self._receiver_res is None:
            vs = load_shader("shadow_receiver.vert.glsl").replace("#version 330 core\n",
                                                                  "#version 330 core\n#define RECEIVER_RESIDENT 1\n", 1)
            self._receiver_res = self.ctx.program(vertex_shader=vs, fragment_shader=self._receiver_fs)
            self._set_receiver_uniforms(self._receiver_res)
        r = self._recv_res
        if r["idx"] is None or r["idx"].size < idx.nbytes:
            for key in ("vao", "idx"):
                if r[key] is not None:
                    r[key].release()
            r["idx"] = self.ctx.buffer(reserve=max(idx.nbytes * 2, 4096), dynamic=True)
            r["vao"] = None
        if r["vao"] is None or r["buf"] is not buffer:  # (a new net's blocks: a new buffer)
            if r["vao"] is not None:
                r["vao"].release()
            # position, morph target, (the two UV pairs skipped), morph slot
            fmt = RESIDENT_FORMAT[0].replace("2f 2f", "16x")
            r["vao"] = self.ctx.vertex_array(self._receiver_res, [(buffer, fmt, "in_pos", "in_target", "in_morph")],
                                             r["idx"], index_element_size=4)
            r["buf"] = buffer
        r["idx"].orphan()
        r["idx"].write(idx)
        return self._receiver_res, r["vao"]

    def read_tiles(self) -> np.ndarray:
        """The shadow texture ``(tile, n_max * tile) uint8`` coverage, top row first (debugging, tests)."""
        # through the framebuffer: Texture.read() (glGetTexImage) of level 0 once the compute mips have
        # bound the texture as an image returned the first frame's tiles again on llvmpipe (Mesa 24)
        data = np.frombuffer(self.fbo.read(components=4), np.uint8).reshape(self.tile, self.tile * self.n_max, 4)
        return data[::-1, :, 0].copy()

    # ------------------------------------------------------------------ receivers
    def draw_receivers(self, mesh: TerrainMesh | ResidentMesh, patch_lists: Sequence[npt.ArrayLike], vp: np.ndarray,
                       shade: tuple[float, float, float] = SHADE, depth_bias: float = 2e-5,
                       terrain: Any = None) -> None:
        """The extra terrain pass (see the module docstring) into the bound framebuffer.

        ``terrain``: the :class:`~piste.render.terrain_pass.TerrainPass` that drew ``mesh`` this frame;
        when its vertex blocks are resident on the GPU (:meth:`~piste.render.terrain_pass.TerrainPass.resident_blocks`)
        the receivers draw them by index, geomorphed by the same factors (:attr:`resident_receivers`),
        instead of gathering, morphing and uploading the shadowed patches' vertices."""
        import moderngl

        self.patch_counts = [len(p) for p in patch_lists]
        find = getattr(terrain, "resident_blocks", None) if self.resident_receivers else None
        blocks = find(mesh) if find is not None else None
        if blocks is not None:
            idx, ranges = resident_shadow_triangles(mesh, patch_lists)
        else:
            pos, idx, ranges = shadow_triangles(mesh, patch_lists, self.light_vp)
        self.triangles = int(len(idx))
        if len(idx) == 0:
            return
        ctx = self.ctx
        if blocks is not None:
            p, vao = self._resident_receiver(blocks[0], idx)
            p["u_morph_on"].value = int(blocks[1] is not None)
            if blocks[1] is not None:
                blocks[1].use(_MORPH_UNIT)
        else:
            r = self._recv
            if r["pos"] is None or r["pos"].size < pos.nbytes or r["idx"].size < idx.nbytes:
                for key in ("vao", "pos", "idx"):
                    if r[key] is not None:
                        r[key].release()
                r["pos"] = ctx.buffer(reserve=max(pos.nbytes * 2, 4096), dynamic=True)
                r["idx"] = ctx.buffer(reserve=max(idx.nbytes * 2, 4096), dynamic=True)
                r["vao"] = ctx.vertex_array(self.receiver, [(r["pos"], "3f", "in_pos")], r["idx"], index_element_size=4)
            r["pos"].orphan()
            r["pos"].write(pos.tobytes())
            r["idx"].orphan()
            r["idx"].write(idx.tobytes())
            p, vao = self.receiver, r["vao"]
        p["u_mvp"].write(np.asarray(vp, dtype=np.float32).T.tobytes())
        p["u_depth_bias"].value = float(depth_bias)
        p["u_shade"].value = tuple(float(x) for x in shade)
        self.texture.use(3)
        self.sunlit.use(4)
        ctx.enable(moderngl.DEPTH_TEST | moderngl.BLEND)
        ctx.depth_func = "<="
        set_depth_write(ctx, False)
        ctx.blend_equation = moderngl.FUNC_ADD
        ctx.blend_func = (moderngl.DST_COLOR, moderngl.ZERO, moderngl.ZERO, moderngl.ONE)
        w = 1.0 / self.n_max
        for k in range(6):  # the triangles cut to each shadow frustum (shadow_receiver.vert.glsl)
            ctx.enable_direct(_GL_CLIP_DISTANCE0 + k)
        try:
            for i, (first, count) in enumerate(ranges):
                if count == 0:
                    continue
                p["u_light_vp"].write(self.light_vp[i].astype(np.float32).T.tobytes())
                p["u_tile"].value = (i * w, 0.0, w, 1.0)
                if self.soft:
                    p["u_span"].value = _light_spans(self.light_vp[i])
                vao.render(moderngl.TRIANGLES, vertices=int(3 * count), first=int(3 * first))
        finally:
            for k in range(6):
                ctx.disable_direct(_GL_CLIP_DISTANCE0 + k)
            ctx.disable(moderngl.BLEND)
            ctx.blend_func = moderngl.DEFAULT_BLENDING
            set_depth_write(ctx, True)
            ctx.depth_func = "<"

    def release(self) -> None:
        for d in (*self._casts.values(), self._recv, self._recv_res):
            for key in ("vao", "pos", "idx", "vao_c", "idx_c"):
                if d.get(key) is not None:
                    d[key].release()
        if self._receiver_res is not None:
            self._receiver_res.release()
        for m in (self._mips, self._mips_cs):
            if m is not None:
                m.release()
        release_framebuffer(self.ctx, self.fbo, self.texture)  # (render_casters leaves it bound)
        for obj in (self.caster, self._receiver, self.sunlit):
            if obj is not None:
                obj.release()


def shadow_on_plane(ctx: moderngl.Context, positions: np.ndarray, indices: np.ndarray, sun_direction: npt.ArrayLike,
                    rect: tuple[float, float, float, float], res: int = 96, soft: bool = False,
                    sun_radius: float = SUN_RADIUS, tile: int = 128,
                    radius: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """One caster's projected shadow on the flat ground ``z = 0`` as the pass draws it, seen from
    straight above: the visibility the receivers leave (1 lit, 0 fully shadowed) and the ground
    points of the pixels, to compare with :func:`area_light_visibility` (tests, benchmarks).

    Parameters
    ----------
    positions : (v, 3) the caster's vertices, world space;  indices : (t, 3) its triangles
    rect : (x0, y0, x1, y1) the ground square drawn, metres;  res : its pixels a side
    radius : the caster's bounding-sphere radius (default: the vertices' extent around their centre)

    Returns
    -------
    visibility (res, res) float64 0..1 rows along y, points (res, res, 3) float64 pixel centres.
    """
    from types import SimpleNamespace

    pos = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    lo, hi = pos.min(0), pos.max(0)
    centre = 0.5 * (lo + hi)
    r = float(radius) if radius is not None else 0.5 * float(np.linalg.norm(hi - lo)) + 0.05
    lvp = shadow_matrices(centre[None], r, sun_direction)
    sp = ShadowPass(ctx, n_max=1, tile=tile, soft=soft, sun_radius=sun_radius)
    target = Offscreen(ctx, (res, res))
    try:
        sp.render_casters(pos[None].astype(np.float32), indices, lvp)
        x0, y0, x1, y1 = (float(v) for v in rect)
        n = 64  # the ground: one patch of n x n quads
        gx, gy = np.meshgrid(np.linspace(x0, x1, n + 1), np.linspace(y0, y1, n + 1), indexing="xy")
        ground = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], -1).astype(np.float32)
        k = np.arange(n * n)
        a = (k // n) * (n + 1) + k % n
        tris = np.concatenate([np.stack([a, a + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + n + 1], 1)])
        mesh = SimpleNamespace(patch_ids=np.array([0]), vertex_start=np.array([0, len(ground)]),
                               tri_start=np.array([0, len(tris)]), indices=tris.astype(np.uint32), positions=ground)
        # looking straight down, x right and y up on the picture
        ortho = np.array([[2.0 / (x1 - x0), 0, 0, -(x1 + x0) / (x1 - x0)],
                          [0, 2.0 / (y1 - y0), 0, -(y1 + y0) / (y1 - y0)],
                          [0, 0, -0.1, 0.0], [0, 0, 0, 1.0]])
        target.use()
        target.clear((1.0, 1.0, 1.0, 1.0))
        sp.draw_receivers(mesh, [np.array([0])], ortho, shade=(0.0, 0.0, 0.0), depth_bias=0.0)
        ctx.finish()
        img = target.read()
    finally:
        sp.release()
        target.release()
    vis = img[::-1, :, 0].astype(np.float64) / 255.0  # read() is top row first: rows along y again
    px = x0 + (np.arange(res) + 0.5) * (x1 - x0) / res
    py = y0 + (np.arange(res) + 0.5) * (y1 - y0) / res
    X, Y = np.meshgrid(px, py, indexing="xy")
    return vis, np.stack([X, Y, np.zeros_like(X)], -1)
