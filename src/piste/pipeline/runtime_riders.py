"""Riders for a source that has none of its own (an SSX level, a bare terrain): the default rider
model standing on the terrain, added to the runtime scene the way a scene build adds riders
(``characters/rider/*`` arrays, ``riders/matrix``, the manifest's ``riders`` and ``characters``),
so the one runtime (:class:`piste.pipeline.preview.ScenePreview`) animates, skins, lights,
shadows and draws them like a scene file's riders.

API
---
standing_positions(net, n, spacing=3.0) -> (n, 2) float64     points on the terrain nearest its centre
standing_matrices(net, xy) -> (n, 4, 4) float64               rider -> world, facing down the fall line
add_standing_riders(bundle, n) -> Bundle                      a copy with n default riders
"""

from __future__ import annotations

import functools
from dataclasses import replace

import numpy as np

from piste.errors import ConfigError
from piste.pipeline.bundle_objects import Bundle
from piste.pipeline.characters import character_arrays
from piste.pipeline.sources import load_rider_model
from piste.terrain.query import height_at
from piste.world.riders import surface_frame

__all__ = ["standing_positions", "standing_matrices", "add_standing_riders"]

#: riders a source may be given (``--riders``)
MAX_RIDERS = 64


def standing_positions(net, n: int, spacing: float = 3.0) -> np.ndarray:
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


def standing_matrices(net, xy) -> np.ndarray:
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
def _default_character():
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
    return replace(bundle, manifest=man, arrays=new, _cache={})
