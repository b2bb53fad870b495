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
- ``LOD``: ``name``, ``mesh``, ``palette``, ``ratio``, ``step``, ``error``, ``distance``
- ``lod_errors(lods) -> (l,)``: each level's bind-pose Hausdorff-like distance to level 0 (metres)
- ``palette_errors(lods, skins) -> (l,)``: how far each level's palette moves its vertices from level 0's
- ``pose_skins(model, per_clip=3) -> (k, b, 4, 4)``: skin matrices of poses sampled from the model's clips
- ``screen_errors(lods, skins) -> (l,)``: the error a level shows, for choosing it by pixels (the sum)
- ``lod_digest(lods, model) -> str``: what :func:`screen_errors` of ``pose_skins(model)`` depends on, hashed;
  ``MEASURED_ERRORS[digest]``: the built-in rider's, measured once (a test keeps it current)
- ``surface_distance`` / ``max_surface_distance``: exact point-to-mesh distances (vectorised, pruned)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from piste._data import DataMethods
from piste.character.animation import sample_poses
from piste.character.model import Model, SkinnedMesh
from piste.character.palette import Palette, palette as make_palette
from piste.character.skeleton import world_from_local
from piste.character.skinning import BlendedMesh
from piste.errors import ConfigError
from piste.transforms import compose_trs

__all__ = ["LOD", "LOD_NAMES", "simplify_mesh", "compact_mesh", "make_lods", "lod_errors", "surface_distance", "max_surface_distance",
           "palette_errors", "pose_skins", "screen_errors", "lod_digest", "MEASURED_ERRORS"]

LOD_NAMES = ("high", "medium", "low")

#: :func:`screen_errors` already measured, by :func:`lod_digest` of the levels and the model: the built-in
#: rider's levels as :class:`piste.world.scene.Scene` makes them (``default_rider(0)``, ``make_lods``
#: defaults), so a fresh process's first frame does not measure them again (~0.27 s with scipy's k-d tree
#: import; a bundle's character step stores its own, ``LOD.distance``).  Levels not listed are measured
#: on use; tests/world/test_rider_lod.py checks the entry against a fresh measure.
MEASURED_ERRORS: dict[str, tuple[float, ...]] = {
    "f611891b9f4e429aefe56066702a2fdc": (0.0, 0.0288, 0.0517),  # default_rider(0): high / medium / low
}


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class LOD(DataMethods):
    """One level: ``mesh`` (a SkinnedMesh), its ``palette``, the triangle ``ratio`` asked for,
    the weight ``step`` of its palette and meshoptimizer's relative ``error`` (0 for the original);
    ``distance``: the error it shows in metres (:func:`screen_errors`: geometry and palette against
    level 0), measured where it was built (a bundle's character step), or None (measured on use)."""

    name: str
    mesh: SkinnedMesh
    palette: Palette
    ratio: float
    step: float
    error: float
    distance: float | None = None

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


def _point_triangle_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Distance ``(...,)`` from points ``p (..., 3)`` to triangles ``a, b, c (..., 3)`` (broadcast):
    the projection on the plane where it falls inside the triangle, else the nearest point of its
    three edges (degenerate triangles: their edges).  Component by component (no ``(..., 3)``
    temporaries: ~4x faster than dot products over a last axis of 3)."""
    px, py, pz = (p[..., i] for i in range(3))
    ax, ay, az = (a[..., i] for i in range(3))
    ux, uy, uz = (b[..., i] - a[..., i] for i in range(3))  # ab
    vx, vy, vz = (c[..., i] - a[..., i] for i in range(3))  # ac
    wx, wy, wz = px - ax, py - ay, pz - az  # ap
    uu, uv, vv = ux * ux + uy * uy + uz * uz, ux * vx + uy * vy + uz * vz, vx * vx + vy * vy + vz * vz
    uw, vw = ux * wx + uy * wy + uz * wz, vx * wx + vy * wy + vz * wz
    den = uu * vv - uv * uv
    with np.errstate(divide="ignore", invalid="ignore"):
        s_, t_ = (vv * uw - uv * vw) / den, (uu * vw - uv * uw) / den  # barycentric (b, c)
        dx, dy, dz = wx - s_ * ux - t_ * vx, wy - s_ * uy - t_ * vy, wz - s_ * uz - t_ * vz
        face = np.sqrt(dx * dx + dy * dy + dz * dz)
        inside = (den > 0) & (s_ >= 0) & (t_ >= 0) & (s_ + t_ <= 1)
        best = np.full(np.shape(den), np.inf)
        # the edges a-b, a-c (from a) and b-c: the nearest point on each, parameters clamped to [0, 1]
        for ex, ey, ez, ox, oy, oz, ee in ((ux, uy, uz, wx, wy, wz, uu), (vx, vy, vz, wx, wy, wz, vv),
                                           (vx - ux, vy - uy, vz - uz, wx - ux, wy - uy, wz - uz, None)):
            ee = ex * ex + ey * ey + ez * ez if ee is None else ee
            tt = np.clip((ex * ox + ey * oy + ez * oz) / np.maximum(ee, 1e-300), 0.0, 1.0)
            qx, qy, qz = ox - tt * ex, oy - tt * ey, oz - tt * ez
            d = qx * qx + qy * qy + qz * qz
            best = np.minimum(best, d)
    out: np.ndarray = np.where(inside, face, np.sqrt(best))
    return out


def _surface_bounds(pts: np.ndarray, corners: np.ndarray, k: int) -> np.ndarray:
    """An upper bound ``(n,)`` of each point's distance to the triangles ``corners (t, 3, 3)``: the
    nearest of the ``k`` triangles with the nearest centroids (a k-d tree) and of the corners
    themselves (they lie on the surface)."""
    from scipy.spatial import cKDTree

    kk = min(int(k), len(corners))
    _, near = cKDTree(corners.mean(axis=1)).query(pts, k=kk)
    c = corners[np.asarray(near).reshape(len(pts), kk)]  # (n, k, 3, 3)
    upper = _point_triangle_distance(pts[:, None, :], c[..., 0, :], c[..., 1, :], c[..., 2, :]).min(axis=1)
    return np.minimum(upper, cKDTree(np.unique(corners.reshape(-1, 3), axis=0)).query(pts)[0])


def _exact_distance(pts: np.ndarray, corners: np.ndarray, upper: np.ndarray | None = None, chunk: int = 256) -> np.ndarray:
    """Each point's distance ``(n,)`` to the nearest of the triangles ``corners (t, 3, 3)``, exactly.
    With ``upper (n,)`` (bounds from :func:`_surface_bounds`) only the triangles whose bounding
    sphere about their centroid comes nearer than the bound are measured (no other can hold a
    nearer point); without, every pair, ``chunk`` points a batch."""
    from scipy.spatial.distance import cdist

    out = np.empty(len(pts))
    centre = corners.mean(axis=1)
    rad = np.sqrt(((corners - centre[:, None]) ** 2).sum(axis=2)).max(axis=1)  # (t,)
    for s in range(0, len(pts), chunk):
        p = pts[s:s + chunk]
        if upper is None:
            out[s:s + chunk] = _point_triangle_distance(p[:, None, :], corners[None, :, 0], corners[None, :, 1],
                                                        corners[None, :, 2]).min(axis=1)
            continue
        u = upper[s:s + chunk]
        pi, ti = np.nonzero(cdist(p, centre) - rad[None] <= u[:, None])  # (candidate pairs)
        d = _point_triangle_distance(p[pi], corners[ti, 0], corners[ti, 1], corners[ti, 2])
        o = u.copy()
        np.minimum.at(o, pi, d)
        out[s:s + chunk] = o
    return out


def _mesh_corners(positions: npt.ArrayLike, indices: npt.ArrayLike) -> np.ndarray:
    pos = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    tri = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    if len(tri) == 0:
        raise ConfigError("surface distance: the mesh has no triangles")
    return pos[tri]


def surface_distance(points: npt.ArrayLike, positions: npt.ArrayLike, indices: npt.ArrayLike) -> np.ndarray:
    """Exact distance ``(n,) float64`` from each of ``points (n, 3)`` to the surface of the mesh
    ``positions (v, 3)``, ``indices (t, 3)`` (the nearest point of any triangle; brute force,
    vectorised in batches)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return _exact_distance(pts, _mesh_corners(positions, indices))


def max_surface_distance(points: npt.ArrayLike, positions: npt.ArrayLike, indices: npt.ArrayLike, k: int = 8,
                         batch: int = 256) -> float:
    """The largest of :func:`surface_distance` over ``points (n, 3)`` (exactly), without measuring
    every point against every triangle: an upper bound per point (:func:`_surface_bounds`), then
    exact distances in descending order of the bounds, ``batch`` points at a time, until the
    largest exact distance found is at least every bound left."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        return 0.0
    corners = _mesh_corners(positions, indices)
    upper = _surface_bounds(pts, corners, k)
    order = np.argsort(-upper)
    best = 0.0
    for s in range(0, len(pts), int(batch)):
        if best >= upper[order[s]]:
            break
        sel = order[s:s + batch]
        best = max(best, float(_exact_distance(pts[sel], corners, upper[sel]).max()))
    return best


def lod_errors(lods: Sequence[LOD]) -> np.ndarray:
    """Each level's geometric error ``(l,) float64`` in model units against level 0 (the full mesh),
    for choosing a level by its projected size (:func:`piste.world.object_lod.choose_lods`).

    A Hausdorff-like distance, both ways, in the bind pose: the largest distance from the full
    mesh's vertices and triangle centroids to the level's surface, and from the level's vertices
    and triangle centroids to the full surface (:func:`max_surface_distance`).  Level 0 is 0;
    the errors are made non-decreasing (a level is never counted finer than one before it).
    """
    if not lods:
        return np.zeros(0)
    full = lods[0].mesh
    fpos = np.asarray(full.positions, dtype=np.float64)
    ftri = np.asarray(full.indices, dtype=np.int64).reshape(-1, 3)
    fpts = np.concatenate([fpos, fpos[ftri].mean(axis=1)])
    out = np.zeros(len(lods))
    for i, lod in enumerate(lods[1:], start=1):
        pos = np.asarray(lod.mesh.positions, dtype=np.float64)
        tri = np.asarray(lod.mesh.indices, dtype=np.int64).reshape(-1, 3)
        if len(tri) == 0:
            out[i] = np.inf
            continue
        pts = np.concatenate([pos, pos[tri].mean(axis=1)])
        out[i] = max(max_surface_distance(fpts, pos, tri), max_surface_distance(pts, fpos, ftri))
    return np.maximum.accumulate(out)


def pose_skins(model: Model, per_clip: int = 3) -> np.ndarray:
    """Skin matrices ``(k, b, 4, 4) float64`` (bind space -> model space) of poses sampled from every clip
    of ``model``: ``per_clip`` times evenly over each clip's duration (the first at 0), clips in name
    order; the rest pose alone when the model has no clips.  Raises ConfigError without a skeleton."""
    sk = model.skeleton
    if sk is None:
        raise ConfigError(f"model {model.name!r} has no skeleton: no poses to measure its levels in")
    clips = [model.clips[k] for k in sorted(model.clips)]
    out = []
    for clip in clips:
        times = np.arange(int(per_clip)) * (float(clip.duration) / max(int(per_clip), 1))
        tr, rot, sc = sample_poses(clip, times, sk)
        out.append(compose_trs(tr, rot, sc))
    if not out:
        rest = sk.rest_pose()
        out.append(compose_trs(np.asarray(rest.translation)[None], np.asarray(rest.rotation)[None],
                               np.asarray(rest.scale)[None]))
    local = np.concatenate(out)
    skins: np.ndarray = world_from_local(local, sk.parents, sk.levels) @ sk.inverse_bind
    return skins


def palette_errors(lods: Sequence[LOD], skins: npt.ArrayLike) -> np.ndarray:
    """How far each level's own palette moves its vertices ``(l,) float64`` (metres; level 0: 0): the
    largest distance, over the poses ``skins (k, b, 4, 4)``, between a level's vertex skinned with the
    level's palette and the same vertex (the level-0 vertex at the same bind position) skinned with
    level 0's.  Vertices with no twin in level 0 are not counted."""
    sk = np.asarray(skins, dtype=np.float64)
    out = np.zeros(len(lods))
    if len(lods) < 2 or len(sk) == 0:
        return out
    full = np.ascontiguousarray(lods[0].mesh.positions, dtype=np.float32)
    p0, _ = BlendedMesh(lods[0].palette, lods[0].mesh.positions, lods[0].mesh.normals).apply_many(sk, normalize=False)
    for i, lod in enumerate(lods[1:], start=1):
        pos = np.ascontiguousarray(lod.mesh.positions, dtype=np.float32)
        # each vertex's twin in level 0: the same position (one sort of both sets' rows)
        _, first, inv = np.unique(np.concatenate([full, pos]), axis=0, return_index=True, return_inverse=True)
        inv = inv.reshape(-1)
        twin = first[inv[len(full):]]
        has = twin < len(full)
        if not has.any():
            continue
        p, _ = BlendedMesh(lod.palette, lod.mesh.positions, lod.mesh.normals).apply_many(sk, normalize=False)
        out[i] = float(np.linalg.norm(p[:, has].astype(np.float64) - p0[:, twin[has]], axis=2).max())
    return out


def screen_errors(lods: Sequence[LOD], skins: npt.ArrayLike) -> np.ndarray:
    """The error each level shows ``(l,) float64`` in metres, for choosing a level by its projected size:
    :func:`lod_errors` (geometry, bind pose) plus :func:`palette_errors` (the coarser palettes in the
    poses ``skins``), made non-decreasing and rounded up to 0.1 mm (the same value from a bundle as
    measured again: the last bits of float32 skinning do not flip a choice)."""
    err = np.maximum.accumulate(lod_errors(lods) + palette_errors(lods, skins))
    out: np.ndarray = np.ceil(err * 1e4) / 1e4
    return out


def lod_digest(lods: Sequence[LOD], model: Model) -> str:
    """A hash (hex) of everything :func:`screen_errors` of :func:`pose_skins` ``(model)`` reads: each
    level's positions, triangles and palette, and the model's skeleton and clips (key times and values),
    for looking the errors up in :data:`MEASURED_ERRORS` (~0.2 ms)."""
    import hashlib

    h = hashlib.blake2b(digest_size=16)

    def add(x: object) -> None:
        a = np.ascontiguousarray(x)
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())

    for lod in lods:
        for x in (lod.mesh.positions, lod.mesh.indices, lod.palette.index, lod.palette.bones, lod.palette.weights,
                  lod.palette.units):
            add(x)
    sk = model.skeleton
    if sk is not None:
        for x in (sk.parents, sk.inverse_bind, sk.rest_translation, sk.rest_rotation, sk.rest_scale):
            add(x)
        h.update(repr(list(sk.names)).encode())
    for name in sorted(model.clips):
        clip = model.clips[name]
        h.update(repr((name, float(clip.duration))).encode())
        for bone in sorted(clip.tracks):
            for path in sorted(clip.tracks[bone]):
                tr = clip.tracks[bone][path]
                h.update(repr((bone, path, tr.interpolation)).encode())
                add(tr.times)
                add(tr.values)
                for tangents in (tr.in_tangents, getattr(tr, "out_tangents", None)):
                    if tangents is not None:
                        add(tangents)
    return h.hexdigest()
