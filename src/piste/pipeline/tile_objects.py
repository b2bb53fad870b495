"""Scene objects of a tiled world, placed by rules per tile at build time.

A tiled build (:mod:`piste.pipeline.tiled_build`) given :class:`ObjectRule` s places the course's
objects (:data:`piste.world.objects.OBJECT_KINDS`: trees, signs, rocks, rails) on every tile while
it bakes the tile, and stores them in the tile's ``lit`` file (members ``objects_kind`` and
``objects_matrix``, read back and checked by :func:`piste.terrain.tiles.read_tile_objects`), so
that they travel with their tile.

Placement is a pure function of the world, not of the tiling: each rule lays a grid of square cells
(``density`` candidates a hectare) over the whole world from the grid's origin; each cell holds one
candidate jittered inside it by an integer hash of the cell's global indices, the rule's index and
the seed (:func:`_hash`, no random generator state); a tile keeps the candidates that fall inside
it and pass the rule's slope and altitude ranges, on the exact surface of its fitted patches.
Tiles therefore agree whatever order or worker bakes them (and the same world cut into other
tiles holds the same objects), and no object is placed twice along a seam.

API
---
::

    ObjectRule(kind, density, slope=(0, 90), altitude=(-inf, inf), scale=(0.7, 1.4))
    DEFAULT_RULES                                   trees on gentle slopes, rocks on steep ones
    rules_key(rules) -> list                        what the build's key hashes
    place_tile_objects(control_points, grid, ty, tx, rules, seed=0) -> (kind (k,) int64, matrix (k, 4, 4) float64)
    object_set(kind, matrix, lights=None) -> ObjectSet   instances for the object pass
    tiles_objects(store, grid, tiles) -> (kind, matrix)  the stored objects of some tiles, checked
    add_tile_objects(bundle, store, grid, tiles) -> Bundle   a runtime scene holding them (vertex colours baked)
    stream_tile_objects(bundle) -> Bundle           a runtime scene whose objects are paged with the tiles:
        an empty ObjectGroups the streamed terrain fills with the objects of the tiles it pages in

    # riders across tiles
    track_tiles(grid, xy, halo=1) -> [(ty, tx), ...]        the tiles under a track (and around it)
    track_net(store, grid, tiles) -> PatchNet                those tiles' fitted patches as one net
    world_track(store, grid, start_xy, end_xy, step=5) -> (line (k, 3), net)   a straight track across
        tiles on the exact surface, and the ground its riders need
    add_track_riders(bundle, store, grid, start_xy, end_xy, start=0.12, riders=6) -> Bundle   a runtime scene
        whose pack of ``riders`` riders follows that track ([pack] follow = "track": the runtime's track_scene), its
        ``net`` the track's tiles (riders stand, carve and cast shadows on them while the world streams)
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from piste.errors import ConfigError, ValidationError
from piste.lighting.vertex import choose_lights_many
from piste.pipeline.furnish import keep_streamed_objects, object_arrays
from piste.render.object_pass import ObjectGroups
from piste.terrain.net import PatchNet
from piste.terrain.query import height_at
from piste.terrain.query import eval_points
from piste.terrain.tiles import TileError, TileGrid, read_tile_objects
from piste.world.objects import OBJECT_KINDS, ObjectSet, compress_mesh, make_mesh, normal_matrix, object_texture

if TYPE_CHECKING:
    import numpy.typing as npt

    from piste.lighting.lights import Lights
    from piste.pipeline.bundle_objects import Bundle
    from piste.terrain.tiles import TileStore

#: tile indices ``(ty, tx)``
Tiles = Sequence[tuple[int, int]]

__all__ = ["ObjectRule", "DEFAULT_RULES", "rules_key", "place_tile_objects", "object_set", "MAX_TILE_OBJECTS",
           "tiles_objects", "add_tile_objects", "stream_tile_objects", "track_tiles", "track_net", "world_track", "add_track_riders",
           "MAX_TRACK_TILES"]

#: most tiles a track's ground may span (its net is held in memory while riders run on it)
MAX_TRACK_TILES = 256

#: most objects one tile may hold (a build refuses rules that would place more)
MAX_TILE_OBJECTS = 200_000


@dataclass(frozen=True)
class ObjectRule:
    """Where one kind of object grows.

    Attributes
    ----------
    kind : one of :data:`piste.world.objects.OBJECT_KINDS`
    density : candidates a hectare (one per square cell of ``100 / sqrt(density)`` metres)
    slope : (min, max) degrees from horizontal where a candidate is kept
    altitude : (min, max) metres where a candidate is kept
    scale : (min, max) size of an instance (1: the mesh as built)
    """

    kind: str
    density: float
    slope: tuple = (0.0, 90.0)
    altitude: tuple = (-math.inf, math.inf)
    scale: tuple = (0.7, 1.4)

    def __post_init__(self) -> None:
        what = f"object rule {self.kind!r}"
        if self.kind not in OBJECT_KINDS:
            raise ValidationError(f"{what}: kind must be one of {', '.join(OBJECT_KINDS)}")
        if not (isinstance(self.density, (int, float)) and 0.0 < self.density <= 10_000.0):
            raise ValidationError(f"{what}: density must be in (0, 10000] a hectare, got {self.density!r}")
        for name, lo_ok, hi_ok in (("slope", 0.0, 90.0), ("altitude", -math.inf, math.inf), ("scale", 1e-3, 1e3)):
            v = getattr(self, name)
            ok = (isinstance(v, (tuple, list)) and len(v) == 2 and all(isinstance(x, (int, float)) for x in v)
                  and not any(math.isnan(x) for x in v) and lo_ok <= v[0] <= v[1] <= hi_ok)
            if not ok:
                raise ValidationError(f"{what}: {name} must be (min, max) with {lo_ok:g} <= min <= max <= {hi_ok:g}, "
                                      f"got {v!r}")
            object.__setattr__(self, name, (float(v[0]), float(v[1])))

    @property
    def cell(self) -> float:
        """The side of a rule's cell, metres."""
        return 100.0 / math.sqrt(self.density)


#: trees on slopes up to 30 degrees, rocks where it is steeper
DEFAULT_RULES = (ObjectRule("tree", 6.0, slope=(0.0, 30.0)), ObjectRule("rock", 2.0, slope=(25.0, 70.0),
                                                                        scale=(0.8, 2.0)))


def rules_key(rules: Iterable[ObjectRule]) -> list[list[Any]]:
    """The rules as plain lists (what a build's content key hashes)."""
    return [[r.kind, float(r.density), list(r.slope), list(r.altitude), list(r.scale)] for r in rules]


def _hash(ix: np.ndarray, iy: np.ndarray, salt: int) -> np.ndarray:
    """Values in [0, 1) from integer cell indices and a salt (a 64-bit integer mix: the same bits
    on any machine), ``ix`` and ``iy`` broadcast."""
    h = ix.astype(np.int64).astype(np.uint64) * np.uint64(0xD6E8FEB86659FD93)
    h ^= iy.astype(np.int64).astype(np.uint64) * np.uint64(0xA0761D6478BD642F)
    h ^= np.uint64((salt * 0x9E3779B97F4A7C15 + 0x632BE59BD9B4E019) & 0xFFFFFFFFFFFFFFFF)
    h ^= h >> np.uint64(32)
    h *= np.uint64(0xE7037ED1A0B428DB)
    h ^= h >> np.uint64(29)
    h *= np.uint64(0x94D049BB133111EB)
    h ^= h >> np.uint64(32)
    return (h >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0)


def _surface(control_points: np.ndarray, grid: TileGrid, ty: int, tx: int, xy: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """Heights ``(k,)`` and unit up-facing normals ``(k, 3)`` of the tile's exact surface at
    ``xy (k, 2)`` (inside the tile): the patch and its (u, v) found directly (x, y are linear in
    u, v on a fitted height field)."""
    py0, py1, px0, px1 = grid.patch_range(ty, tx)
    nx = px1 - px0
    s = grid.samples_per_patch
    (dx, dy), (ox, oy) = grid.spacing, grid.origin
    fx = (xy[:, 0] - ox) / (s * dx) - px0
    fy = (xy[:, 1] - oy) / (s * dy) - py0
    cx = np.clip(np.floor(fx).astype(np.int64), 0, nx - 1)
    cy = np.clip(np.floor(fy).astype(np.int64), 0, py1 - py0 - 1)
    u, v = np.clip(fx - cx, 0.0, 1.0), np.clip(fy - cy, 0.0, 1.0)
    q, du, dv = eval_points(control_points[cy * nx + cx], u, v)
    n = np.cross(du, dv)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(n[:, 2:3] < 0.0, -n, n)
    return q[:, 2], n


def place_tile_objects(control_points: np.ndarray, grid: TileGrid, ty: int, tx: int,
                       rules: Iterable[ObjectRule] = DEFAULT_RULES,
                       seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The objects of tile ``(ty, tx)`` (see the module docstring).

    Parameters
    ----------
    control_points : (n, 4, 4, 3) float64, the tile's fitted patches (row-major over its patch rows)
    grid : the world's :class:`~piste.terrain.tiles.TileGrid`
    rules : ObjectRule s
    seed : placement seed

    Returns
    -------
    kind (k,) int64 (an index into :data:`~piste.world.objects.OBJECT_KINDS`), matrix (k, 4, 4)
    float64 object -> world (trees, signs and rails upright, rocks tilted to the surface), in rule
    order, then by cell row and column.
    """
    cp = np.asarray(control_points, dtype=np.float64)
    x0, y0, x1, y1 = grid.tile_bounds_xy(ty, tx)
    ox, oy = grid.origin
    kinds: list[np.ndarray] = []
    mats: list[np.ndarray] = []
    gx: np.ndarray  # (cells,) int64 (numpy types meshgrid's outputs 2-D)
    gy: np.ndarray
    for ri, rule in enumerate(rules):
        c = rule.cell
        iy = np.arange(math.floor((y0 - oy) / c), math.floor((y1 - oy) / c) + 1, dtype=np.int64)
        ix = np.arange(math.floor((x0 - ox) / c), math.floor((x1 - ox) / c) + 1, dtype=np.int64)
        if len(ix) * len(iy) > 16 * MAX_TILE_OBJECTS:
            raise ValidationError(f"object rule {rule.kind!r}: {len(ix) * len(iy):,} cells a tile at density "
                                  f"{rule.density:g}: more than {16 * MAX_TILE_OBJECTS:,}")
        gy, gx = np.meshgrid(iy, ix, indexing="ij")
        gy, gx = gy.ravel(), gx.ravel()
        salt = (int(seed) * 1_000_003 + ri) * 8
        x = ox + (gx + _hash(gx, gy, salt)) * c
        y = oy + (gy + _hash(gx, gy, salt + 1)) * c
        keep = (x >= x0) & (x < x1) & (y >= y0) & (y < y1)
        gx, gy, x, y = gx[keep], gy[keep], x[keep], y[keep]
        if len(x) == 0:
            continue
        xy = np.stack([x, y], 1)
        z, nrm = _surface(cp, grid, ty, tx, xy)
        slope = np.degrees(np.arccos(np.clip(nrm[:, 2], -1.0, 1.0)))
        ok = ((slope >= rule.slope[0]) & (slope <= rule.slope[1]) & (z >= rule.altitude[0])
              & (z <= rule.altitude[1]))
        gx, gy, xy, z, nrm = gx[ok], gy[ok], xy[ok], z[ok], nrm[ok]
        k = len(z)
        if k == 0:
            continue
        yaw = 2.0 * np.pi * _hash(gx, gy, salt + 2)
        size = rule.scale[0] + (rule.scale[1] - rule.scale[0]) * _hash(gx, gy, salt + 3)
        m = np.zeros((k, 4, 4))
        m[:, 3, 3] = 1.0
        cs, sn = np.cos(yaw), np.sin(yaw)
        if rule.kind == "rock":  # tilted to the surface, squashed non-uniformly (as place_objects' rocks)
            xa = np.stack([cs, sn, np.zeros(k)], 1)
            xa -= (xa * nrm).sum(1, keepdims=True) * nrm
            xa /= np.linalg.norm(xa, axis=1, keepdims=True)
            ya = np.cross(nrm, xa)
            sq = np.stack([size, size * (0.6 + 0.4 * _hash(gx, gy, salt + 4)),
                           size * (0.4 + 0.3 * _hash(gx, gy, salt + 5))], 1)
            m[:, :3, 0], m[:, :3, 1], m[:, :3, 2] = xa * sq[:, :1], ya * sq[:, 1:2], nrm * sq[:, 2:]
            sink = 0.15 * sq[:, 2]
        else:  # upright, turned about z; trees a little wider or narrower than tall
            w = size * (0.75 + 0.4 * _hash(gx, gy, salt + 4)) if rule.kind == "tree" else size
            m[:, 0, 0], m[:, 0, 1], m[:, 1, 0], m[:, 1, 1] = cs * w, -sn * w, sn * w, cs * w
            m[:, 2, 2] = size
            sink = np.full(k, 0.3 if rule.kind == "tree" else 0.1)
        m[:, :3, 3] = np.stack([xy[:, 0], xy[:, 1], z - sink], 1)
        kinds.append(np.full(k, OBJECT_KINDS.index(rule.kind), dtype=np.int64))
        mats.append(m)
    kind = np.concatenate(kinds) if kinds else np.zeros(0, np.int64)
    matrix = np.concatenate(mats) if mats else np.zeros((0, 4, 4))
    if len(kind) > MAX_TILE_OBJECTS:
        raise ValidationError(f"tile ({ty}, {tx}): the object rules place {len(kind):,} objects, more than "
                              f"{MAX_TILE_OBJECTS:,} a tile")
    return kind, matrix


def object_set(kind: np.ndarray, matrix: np.ndarray, lights: Lights | None = None, normal_bits: int = 8) -> ObjectSet:
    """The :class:`~piste.world.objects.ObjectSet` of instances ``kind (k,) int64`` and ``matrix
    (k, 4, 4) float64`` (e.g. the objects of the tiles in view, concatenated): meshes, bounding
    spheres (the mesh's radius times the matrix's largest column), each instance's vertex lights
    from ``lights`` (None: none)."""
    kind = np.asarray(kind, dtype=np.int64).reshape(-1)
    matrix = np.asarray(matrix, dtype=np.float64).reshape(-1, 4, 4)
    meshes = {k: compress_mesh(make_mesh(k), normal_bits) for k in OBJECT_KINDS}
    centers_obj = np.stack([(meshes[k].pos_offset + meshes[k].pos_extent / 2.0) for k in OBJECT_KINDS])
    co = centers_obj.astype(np.float64)[kind]
    center = np.einsum("nij,nj->ni", matrix[:, :3, :3], co) + matrix[:, :3, 3]
    mesh_r = np.array([meshes[k].radius for k in OBJECT_KINDS], dtype=np.float64)
    radius = mesh_r[kind] * np.linalg.norm(matrix[:, :3, :3], axis=1).max(axis=1)
    vl = None
    if lights is not None and len(kind):
        vl = choose_lights_many(lights, center)
    counts = {k: int(np.count_nonzero(kind == i)) for i, k in enumerate(OBJECT_KINDS)}
    return ObjectSet(meshes, OBJECT_KINDS, kind, matrix, normal_matrix(matrix), center, radius, vl, object_texture(),
                     counts)


def tiles_objects(store: TileStore, grid: TileGrid, tiles: Iterable[tuple[int, int]]) -> tuple[np.ndarray, np.ndarray]:
    """The objects stored in ``tiles`` (``[(ty, tx), ...]``, in that order), concatenated: ``kind
    (k,) int64``, ``matrix (k, 4, 4) float64`` (:func:`piste.terrain.tiles.read_tile_objects`:
    TileError naming a bad tile)."""
    parts = [read_tile_objects(store, grid, ty, tx, len(OBJECT_KINDS)) for ty, tx in tiles]
    if not parts:
        return np.zeros(0, np.int64), np.zeros((0, 4, 4))
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def add_tile_objects(bundle: Bundle, store: TileStore, grid: TileGrid, tiles: Tiles, skip_bad: bool = False) -> Bundle:
    """A copy of ``bundle`` (a tiled world's runtime scene) holding the objects stored in ``tiles``
    (their vertex colours baked from the bundle's lights, as a build stores them); ``bundle`` itself
    when those tiles hold none.  ``skip_bad``: a tile whose objects do not read back (TileError) is
    left out, as the streamed view leaves a bad tile out (else the TileError propagates)."""


    good = []
    for t in tiles:
        try:
            read_tile_objects(store, grid, t[0], t[1], len(OBJECT_KINDS))
            good.append(t)
        except TileError:
            if not skip_bad:
                raise
    kind, matrix = tiles_objects(store, grid, good)
    if len(kind) == 0:
        return bundle
    arrays = dict(bundle.arrays)
    meta = object_arrays(object_set(kind, matrix), bundle.lights, arrays)
    man = dict(bundle.manifest)
    man["objects"] = dict(meta, placed="tiles", tiles=[list(t) for t in tiles])
    return replace(bundle, manifest=man, arrays=arrays, _cache={})


def stream_tile_objects(bundle: Bundle) -> Bundle:
    """A copy of ``bundle`` (a tiled world's runtime scene) whose objects are paged with its tiles:
    ``bundle.objects()`` is an empty :class:`piste.render.object_pass.ObjectGroups` (every kind's
    mesh, the atlas, vertex lights chosen from the bundle's lights) that the streamed terrain
    (:class:`piste.render.streaming.StreamingTerrain`, ``objects=``) fills with one group a tile as
    tiles page in and empties as they leave; the manifest's ``objects`` says ``placed = "tiles"``,
    ``streamed = true``, and the baked colours start empty (each group's are baked when drawn)."""
    base = object_set(np.zeros(0, np.int64), np.zeros((0, 4, 4)))
    groups = ObjectGroups(base.meshes, base.kinds, base.texture, base.blend, world_lights=bundle.lights)
    arrays = dict(bundle.arrays)
    for k in base.kinds:
        arrays[f"objects/colors/{k}"] = np.zeros((0, len(base.meshes[k].positions), 3), np.uint8)
    man = dict(bundle.manifest)
    man["objects"] = {"kinds": list(base.kinds), "placed": "tiles", "streamed": True,
                      "meshes": {k: {"normal_bits": int(base.meshes[k].normal_bits), "radius": float(base.meshes[k].radius),
                                     "blend": False} for k in base.kinds}}
    return replace(bundle, manifest=man, arrays=arrays, _cache={"objects": groups})


def track_tiles(grid: TileGrid, xy: npt.ArrayLike, halo: int = 1) -> list[tuple[int, int]]:
    """The tiles under the polyline ``xy (k, 2)`` metres (sampled every eighth of a tile) and within
    ``halo`` tiles of them, sorted: ``[(ty, tx), ...]`` (ConfigError: a point off the world, more
    than :data:`MAX_TRACK_TILES`)."""
    pts = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    x0, y0, _, _ = grid.tile_bounds_xy(0, 0)
    _, _, x1, y1 = grid.tile_bounds_xy(grid.shape[0] - 1, grid.shape[1] - 1)
    off = (pts[:, 0] < x0) | (pts[:, 0] > x1) | (pts[:, 1] < y0) | (pts[:, 1] > y1) | ~np.isfinite(pts).all(1)
    if off.any():
        i = int(np.flatnonzero(off)[0])
        raise ConfigError(f"track: point {i} ({pts[i, 0]:.6g}, {pts[i, 1]:.6g}) lies off the world "
                          f"(x {x0:.6g}..{x1:.6g}, y {y0:.6g}..{y1:.6g})")
    tx0, ty0, tx1, ty1 = grid.tile_bounds_xy(0, 0)
    step = min(tx1 - tx0, ty1 - ty0) / 8.0
    samples = [pts[:1]]
    for a, b in zip(pts[:-1], pts[1:]):
        n = max(int(np.ceil(np.linalg.norm(b - a) / step)), 1)
        samples.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    under = {grid.tile_of(float(x), float(y)) for x, y in np.concatenate(samples)}
    out = sorted({(y, x) for ty, tx in under for y in range(max(ty - halo, 0), min(ty + halo + 1, grid.shape[0]))
                  for x in range(max(tx - halo, 0), min(tx + halo + 1, grid.shape[1]))})
    if len(out) > MAX_TRACK_TILES:
        raise ConfigError(f"track: its ground spans {len(out)} tiles, more than {MAX_TRACK_TILES}")
    return out


def track_net(store: TileStore, grid: TileGrid, tiles: Tiles) -> PatchNet:
    """The fitted patches of ``tiles`` as one :class:`~piste.terrain.net.PatchNet` (shared tile
    edges are bit-identical: the riders' ground has no seams)."""

    parts = [store.read_fit(grid, ty, tx) for ty, tx in tiles]
    return PatchNet(np.concatenate([p["control_points"] for p in parts]), uv=np.concatenate([p["uv"] for p in parts]),
                    tol=1e-6 * grid.samples_per_patch * min(grid.spacing), name=f"track ({len(tiles)} tiles)")


def world_track(store: TileStore, grid: TileGrid, start_xy: npt.ArrayLike, end_xy: npt.ArrayLike,
                step: float = 5.0) -> tuple[np.ndarray, PatchNet]:
    """A straight track from ``start_xy`` to ``end_xy`` (metres, on the world) across as many tiles
    as it crosses: ``line (k, 3)`` float64 points every ``step`` metres on the exact surface, and
    the net of the tiles under it and around it (:func:`track_tiles`, :func:`track_net`)."""

    a, b = np.asarray(start_xy, dtype=np.float64), np.asarray(end_xy, dtype=np.float64)
    if a.shape != (2,) or b.shape != (2,) or not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise ConfigError(f"track: expected start and end as (x, y) metres, got {start_xy!r}, {end_xy!r}")
    if not step > 0:
        raise ConfigError(f"track: step must be > 0 m, got {step}")
    length = float(np.linalg.norm(b - a))
    if length < 2.0 * step:
        raise ConfigError(f"track: {length:.3g} m from start to end, expected at least {2.0 * step:g} m")
    n = int(np.ceil(length / step)) + 1
    xy = a + (b - a) * np.linspace(0.0, 1.0, n)[:, None]
    net = track_net(store, grid, track_tiles(grid, xy))
    z, hit, _, _ = height_at(net, xy)
    if not hit.all():
        raise ConfigError(f"track: {int((~hit).sum())} of its points lie off the terrain")
    return np.column_stack([xy, z]), net


def add_track_riders(bundle: Bundle, store: TileStore, grid: TileGrid, start_xy: npt.ArrayLike, end_xy: npt.ArrayLike,
                     start: float = 0.12, riders: int = 6) -> Bundle:
    """A copy of ``bundle`` (a tiled world's runtime scene) whose pack of ``riders`` riders (1..64,
    :func:`piste.pipeline.preview.track_pack`) follows a straight track from ``start_xy`` to
    ``end_xy`` across tiles: the centre line (``terrain/centerline``), ``[pack] follow = "track"``
    (rider 0 at fraction ``start`` at t = 0, ``riders``) and, as its ``net``, the tiles under the
    track and around it (:func:`world_track`)."""

    if not 0.0 <= float(start) <= 1.0:
        raise ConfigError(f"track: start must be a fraction of the track in [0, 1], got {start}")
    if isinstance(riders, bool) or not isinstance(riders, (int, np.integer)) or not 1 <= int(riders) <= 64:
        raise ConfigError(f"track: the pack runs 1..64 riders, got {riders!r}")
    line, net = world_track(store, grid, start_xy, end_xy)
    man = dict(bundle.manifest)
    man["pack"] = {"follow": "track", "start": float(start), "riders": int(riders)}
    arrays = dict(bundle.arrays)
    arrays["terrain/centerline"] = line
    rects = np.asarray(net.lightmap_rect, np.float32)  # the local net's placeholder light map, resized
    arrays["lightmap/rects"] = rects
    lm = replace(bundle.lightmap, rects=rects)
    return keep_streamed_objects(bundle, replace(bundle, manifest=man, arrays=arrays, net=net, lightmap=lm,
                                                 centerline=line, _cache={}))
