"""Riders and objects for a source that has none of its own (an SSX level, a tiled world).

* riders: the default rider model standing on the terrain, added to the runtime scene the way a
  scene build adds riders (``characters/rider/*`` arrays, ``riders/matrix``, the manifest's
  ``riders`` and ``characters``), so the one runtime (:class:`piste.pipeline.preview.ScenePreview`)
  animates, skins, lights, shadows and draws them like a scene file's riders;
* objects: the course's trees, signs, rocks and rails (:func:`piste.world.objects.place_objects`)
  along a line down the middle of the terrain, their vertex colours baked as the build does, so the
  object pass draws them in every lighting mode.

API
---
standing_positions(net, n, spacing=3.0) -> (n, 2) float64     points on the terrain nearest its centre
standing_matrices(net, xy) -> (n, 4, 4) float64               rider -> world, facing down the fall line
add_standing_riders(bundle, n) -> Bundle                      a copy with n default riders
add_objects(bundle, n, seed=0) -> Bundle                      a copy with n of the course's objects
keep_streamed_objects(old, new) -> Bundle                     a copy keeping a tiled world's paged objects
"""

from __future__ import annotations

import functools
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from piste.errors import ConfigError, PisteError
from piste.pipeline.bundle_objects import Bundle
from piste.pipeline.characters import character_arrays
from piste.pipeline.sources import load_rider_model
from piste.terrain.query import height_at
from piste.world.object_lod import lod_arrays, object_lods
from piste.world.objects import bake_vertex_colors, place_objects
from piste.world.riders import surface_frame

if TYPE_CHECKING:
    from piste.lighting.lights import Lights
    from piste.terrain.net import PatchNet
    from piste.world.objects import ObjectSet

__all__ = ["standing_positions", "standing_matrices", "add_standing_riders", "add_objects", "keep_streamed_objects"]

#: riders a source may be given (``--riders``)
MAX_RIDERS = 64
#: objects a source may be given (``--scatter``)
MAX_OBJECTS = 10_000


def standing_positions(net: PatchNet, n: int, spacing: float = 3.0) -> np.ndarray:
    """``(n, 2)`` float64 points on ``net``'s surface ``spacing`` metres apart on a grid, the ``n``
    nearest the centre of its bounds (ConfigError when the terrain has fewer)."""
    lo, hi = (np.asarray(b, dtype=np.float64) for b in net.bounds)
    step = max(float(spacing), float(max(hi[0] - lo[0], hi[1] - lo[1])) / 200.0)
    xs = np.arange(lo[0] + step / 2, hi[0], step)
    ys = np.arange(lo[1] + step / 2, hi[1], step)
    gx, gy = np.meshgrid(xs, ys)
    pts = np.stack([gx.ravel(), gy.ravel()], 1)
    if len(pts):
        _, hit, _, _ = height_at(net, pts)
        pts = pts[hit]
    if len(pts) < n:
        raise ConfigError(f"riders: the terrain has room for {len(pts)} standing rider(s) {step:.1f} m apart, "
                          f"asked for {n}")
    centre = (lo[:2] + hi[:2]) / 2.0
    order = np.argsort(np.hypot(*(pts - centre).T), kind="stable")
    return pts[order[:n]]


def standing_matrices(net: PatchNet, xy: npt.ArrayLike) -> np.ndarray:
    """``(n, 4, 4)`` rider -> world matrices (the rider model is Y up, board along +X) standing on
    the exact surface at ``xy (n, 2)``, facing down the fall line (+X where the ground is flat)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    _, normal, _ = surface_frame(net, xy, np.tile([1.0, 0.0], (len(xy), 1)))
    down = normal[:, :2].copy()
    flat = np.hypot(down[:, 0], down[:, 1]) < 1e-6
    down[flat] = (1.0, 0.0)
    anchor, normal, fwd = surface_frame(net, xy, down)
    m = np.zeros((len(xy), 4, 4))
    m[:, :3, 0] = fwd
    m[:, :3, 1] = normal
    m[:, :3, 2] = np.cross(fwd, normal)
    m[:, :3, 3] = anchor
    m[:, 3, 3] = 1.0
    return m


@functools.lru_cache(maxsize=1)
def _default_character() -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The built-in rider's character arrays and meta (as the build's ``characters`` step makes them)."""
    arrays, meta = character_arrays(load_rider_model("builtin:rider"))
    return arrays, dict(meta, model="builtin:rider")


def add_standing_riders(bundle: Bundle, n: int) -> Bundle:
    """A copy of ``bundle`` with ``n`` default riders (the built-in model) standing on its terrain
    (:func:`standing_positions`), each playing the model's first clip from its own phase."""
    if not 1 <= int(n) <= MAX_RIDERS:
        raise ConfigError(f"riders: expected 1..{MAX_RIDERS}, got {n}")
    if bundle.manifest.get("characters"):
        raise ConfigError(f"{bundle.path}: the scene has riders of its own")
    n = int(n)
    arrays, meta = _default_character()
    mats = standing_matrices(bundle.net, standing_positions(bundle.net, n))
    clip = next(iter(meta["clips"]))  # the model's own first clip
    man = dict(bundle.manifest)
    man["characters"] = {"rider": meta}
    man["riders"] = [{"name": f"rider{i}", "character": "rider", "clip": clip, "phase": 0.37 * i, "heading": 0.0,
                      "scale": 1.0} for i in range(n)]
    new = dict(bundle.arrays)
    new.update({f"characters/rider/{k}": v for k, v in arrays.items()})
    new["riders/matrix"] = mats
    return keep_streamed_objects(bundle, replace(bundle, manifest=man, arrays=new, _cache={}))


def keep_streamed_objects(old: Bundle, new: Bundle) -> Bundle:
    """``new`` (a copy of ``old`` made with ``dataclasses.replace(..., _cache={})``) holding ``old``'s
    streamed objects again (a tiled world's, paged with its tiles:
    :func:`piste.pipeline.tile_objects.stream_tile_objects`; they live in the bundle's cache, not in
    its arrays); ``new`` itself otherwise."""
    objs = old._cache.get("objects") if (old.manifest.get("objects") or {}).get("streamed") else None
    if objs is not None and "objects" not in new._cache:
        new._cache["objects"] = objs
    return new


def add_objects(bundle: Bundle, n: int, seed: int = 0) -> Bundle:
    """A copy of ``bundle`` with ``n`` of the course's objects (about 60 % trees, 25 % rocks, 10 %
    signs, 5 % rails) placed by :func:`piste.world.objects.place_objects` along a line down the
    middle of its terrain (x at the centre of its bounds, along y), a 2 m "track" kept clear; their
    vertex colours baked from the scene's lights (``objects/colors/<kind>``, as a build stores them)."""
    if not 1 <= int(n) <= MAX_OBJECTS:
        raise ConfigError(f"objects: expected 1..{MAX_OBJECTS}, got {n}")
    if bundle.objects() is not None:
        raise ConfigError(f"{bundle.path}: the scene has objects of its own")
    n = int(n)
    counts = {"n_rails": n // 20, "n_signs": n // 10, "n_rocks": n // 4}
    counts["n_trees"] = n - sum(counts.values())
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bundle.net.bounds)
    cx = (lo[0] + hi[0]) / 2.0
    ys = np.linspace(hi[1], lo[1], 17)  # down the middle (the slope's fall is the scene's business)
    line = np.stack([np.full_like(ys, cx), ys, np.zeros_like(ys)], 1)
    try:
        objs = place_objects(bundle.net, line, bundle.lights, seed=int(seed), track_half_width=2.0, **counts)
    except PisteError as exc:
        raise ConfigError(f"{bundle.path}: objects: {exc}") from None
    man = dict(bundle.manifest)
    arrays = dict(bundle.arrays)
    meta = object_arrays(objs, bundle.lights, arrays)
    man["objects"] = dict(meta, placed="furnish")
    return replace(bundle, manifest=man, arrays=arrays, _cache={})


def object_arrays(objs: ObjectSet, lights: Lights, arrays: dict[str, Any]) -> dict[str, Any]:
    """Write an :class:`~piste.world.objects.ObjectSet` into ``arrays`` under ``objects/...`` the way
    a scene build stores it (what :meth:`piste.pipeline.bundle_objects.Bundle.objects` reads back,
    vertex colours baked from ``lights``); returns the manifest's ``objects`` entry."""
    meta: dict[str, Any] = {"kinds": list(objs.kinds), "meshes": {}}
    for k in objs.kinds:
        m = objs.meshes[k]
        p = f"objects/meshes/{k}/"
        for name in ("positions", "pos_offset", "pos_extent", "uv", "uv_offset", "uv_extent", "normals", "indices"):
            arrays[p + name] = getattr(m, name)
        # the level chain a renderer would simplify at every start, stored beside the mesh
        arrays.update({p + n: v for n, v in lod_arrays(m.lods or object_lods(m.decode()[0], m.indices)).items()})
        meta["meshes"][k] = {"normal_bits": int(m.normal_bits), "radius": float(m.radius), "blend": k in objs.blend}
    arrays["objects/kind"] = objs.kind.astype(np.int64)
    arrays["objects/matrix"] = objs.matrix.astype(np.float64)
    arrays["objects/center"] = objs.center.astype(np.float64)
    arrays["objects/radius"] = objs.radius.astype(np.float64)
    if objs.texture is not None:
        arrays["objects/texture"] = objs.texture
    for k, c in bake_vertex_colors(objs, lights).items():
        arrays[f"objects/colors/{k}"] = np.asarray(c, np.uint8)
    return meta
