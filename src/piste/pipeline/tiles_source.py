"""A tiled world (``WORLD.tiles/``, ``piste build`` with ``terrain.tiles``) as the runtime's scene.

:func:`open_tiles` returns a :class:`~piste.pipeline.bundle_objects.Bundle` like any other source:
its ``net`` is the *local* terrain (the tile under the world's centre, from the build's fitted
patches: where default riders stand, objects sit and shadows fall), its manifest names the world
(``terrain.source = "tiles"``, ``terrain.root``, ``terrain.budget_mb``), so that
:class:`piste.pipeline.preview.ScenePreview` draws the whole world with
:class:`piste.render.streaming.StreamingTerrain` (tiles paged in and out under the budget) and the
riders, objects and shadows with the same passes as the course.

Objects: a world built with object rules gets, as its objects, an empty
:class:`piste.render.object_pass.ObjectGroups` (:func:`piste.pipeline.tile_objects.stream_tile_objects`)
that the streamed terrain fills with the objects of the tiles it pages in and empties of those it
evicts, so a camera flying across the world sees the objects of the tiles around it: out to where
they would be a pixel or two tall (:meth:`piste.render.streaming.TileCache.object_distances`),
beyond the tiles drawn with near or middle meshes, their bytes within the streaming budget.

Cameras: ``flight`` (the first camera of :func:`piste.render.streaming.fly_path`, ``piste render
WORLD.tiles``' flight start) and ``centre`` (looking at the local tile from the south, above).

API
---
::

    open_tiles(path, quiet=True, warm=False, budget_mb=256.0, track=None, track_riders=None) -> Bundle
        track (x0, y0, x1, y1) metres: a pack of track_riders riders (default six) rides a straight
        track across the tiles (piste render|view WORLD.tiles --track X0 Y0 X1 Y1 [--riders N]),
        chased by the camera
    flight_cameras(bundle, frames, fps=30, speed=100) -> list[Camera]    the flight across the world
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from piste.errors import ConfigError
from piste.formats.bundle import camera_to_dict
from piste.lighting.lightmap import LightMap
from piste.lighting.lights import default_lights
from piste.pipeline.bundle_objects import Bundle, camera_from_dict
from piste.pipeline.preview import pack_track_ahead
from piste.pipeline.tile_objects import add_track_riders, stream_tile_objects
from piste.render.streaming import fly_path
from piste.terrain.tiles import TileError, TileStore, read_tile_objects, tile_entries, tile_net
from piste.world.camera import Camera
from piste.world.objects import OBJECT_KINDS

if TYPE_CHECKING:
    import numpy.typing as npt

    from piste.terrain.net import PatchNet
    from piste.terrain.tiles import TileGrid

__all__ = ["open_tiles", "flight_cameras"]


def _centre_camera(net: PatchNet) -> Camera:
    lo, hi = (np.asarray(b, dtype=np.float64) for b in net.bounds)
    c = (lo + hi) / 2.0
    ext = float(np.linalg.norm(hi[:2] - lo[:2]))
    eye = c + np.array([0.0, -0.45, 0.35]) * ext
    return Camera(eye, c, fov_y=50.0, near=1.0, far=max(8.0 * ext, 3000.0))


def open_tiles(path: str | Path, quiet: bool = True, warm: bool = False, budget_mb: float = 256.0,
               track: npt.ArrayLike | None = None,
               track_riders: int | None = None) -> Bundle:
    """The runtime scene of a tiled world (see the module docstring).  ``track``: ``(x0, y0, x1, y1)``
    metres, a straight track a pack of ``track_riders`` riders (None: the default six; 1..64)
    follows across the tiles (:func:`piste.pipeline.tile_objects.add_track_riders`; rider 0 starts
    12 % along it, or where the pack still has :func:`piste.pipeline.preview.pack_track_ahead`
    metres ahead), the runtime's camera chasing rider 0 (ConfigError: a track off the world or too
    short for the pack, ``track_riders`` without a track or out of range)."""
    root = Path(path)
    if not root.is_dir():
        raise ConfigError(f"{root}: no such tiled world (build one: piste build SCENE with terrain.tiles)")
    if not budget_mb > 0:
        raise ConfigError(f"budget must be > 0 MiB, got {budget_mb}")
    store = TileStore(root)
    index = store.read_index()
    grid = store.grid()
    entries = tile_entries(index, grid, store.index_path)  # at least one tile, finite bounds (issue 24)
    b = np.array([e["bounds"] for e in entries.values()], dtype=np.float64)
    lo, hi = b[:, 0].min(0), b[:, 1].max(0)
    centre = np.array(grid.tile_of(*((lo[:2] + hi[:2]) / 2.0)))
    net: PatchNet | None = None
    first: TileError | None = None
    for ty, tx in sorted(entries, key=lambda t: (float(np.abs(np.array(t) - centre).sum()), t)):  # a bad tile:
        try:  # the nearest good one stands in (the streamed view leaves the bad one out)
            net = tile_net(store, ty, tx)
            break
        except TileError as exc:
            first = first or exc
    if net is None:
        raise cast(TileError, first)  # entries holds at least one tile: a None net had an error
    cams = {"flight": next(fly_path(index, 1)), "centre": _centre_camera(net)}
    manifest: dict[str, Any] = {
        "name": root.stem,
        "source": "tiles",
        "terrain": {"name": root.stem, "source": "tiles", "root": str(root), "budget_mb": float(budget_mb),
                    "local_tile": [ty, tx]},
        "render": {"size": [640, 448]},
        "lights": default_lights().to_dict(),
        "cameras": [{"name": k, "source": "tiled world", **camera_to_dict(c)} for k, c in cams.items()],
        "riders": [],
        "characters": {},
    }
    rects = np.asarray(net.lightmap_rect, np.float32)
    atlas = np.ones((1, 1, 3), np.float32)
    arrays = {"lightmap/atlas": atlas, "lightmap/rects": rects}
    lightmap = LightMap(atlas=atlas, rects=rects, res=1, gutter=0, manifest={})
    cameras = {d["name"]: camera_from_dict(d) for d in manifest["cameras"]}
    bundle = Bundle(root, manifest, arrays, net, lightmap, default_lights(), cameras)
    # the scene objects the build placed (piste.pipeline.tile_objects): paged in and out with the
    # tiles by the streamed terrain, when the world holds any (the tiles nearest the centre asked)
    order = sorted(entries, key=lambda t: (float(np.abs(np.array(t) - centre).sum()), t))
    if any(_has_objects(store, grid, t) for t in order[:OBJECT_PROBE_TILES]):
        bundle = stream_tile_objects(bundle)
    if track_riders is not None and track is None:
        raise ConfigError("a pack's rider count (--riders with --track) needs a track")
    if track is not None:
        bundle = _track_riders(bundle, store, grid, track, 6 if track_riders is None else track_riders)
    return bundle


def _track_riders(bundle: Bundle, store: TileStore, grid: TileGrid, track: npt.ArrayLike, riders: int = 6) -> Bundle:
    """``bundle`` whose pack of ``riders`` rides the straight track ``(x0, y0, x1, y1)`` (see
    :func:`open_tiles`)."""
    try:
        t = np.asarray(track, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        t = np.zeros(0)
    if t.shape != (4,) or not np.isfinite(t).all():
        raise ConfigError(f"--track: expected X0 Y0 X1 Y1 (metres, finite), got {track!r}")
    if isinstance(riders, bool) or not isinstance(riders, (int, np.integer)) or not 1 <= int(riders) <= 64:
        raise ConfigError(f"--riders with --track: the pack runs 1..64 riders, got {riders!r}")
    ahead = pack_track_ahead(int(riders))
    length = float(np.hypot(t[2] - t[0], t[3] - t[1]))
    if length <= ahead + 10.0:
        raise ConfigError(f"--track: {length:.0f} m long; a pack of {int(riders)} riders needs more than "
                          f"{ahead + 10.0:.0f} m (its first rider rides {ahead:.0f} m ahead)")
    start = min(0.12, (length - ahead - 5.0) / length)
    return add_track_riders(bundle, store, grid, t[:2], t[2:], start=start, riders=int(riders))


#: tiles (nearest the world's centre first) asked whether the world holds scene objects
OBJECT_PROBE_TILES = 64


def _has_objects(store: TileStore, grid: TileGrid, t: Sequence[int]) -> bool:
    try:
        return len(read_tile_objects(store, grid, t[0], t[1], len(OBJECT_KINDS))[0]) > 0
    except TileError:
        return False


def flight_cameras(bundle: Bundle, frames: int, fps: float = 30.0, speed: float = 100.0) -> list[Camera]:
    """The cameras of a straight flight across the tiled world of ``bundle`` at ``speed`` m/s
    (:func:`piste.render.streaming.fly_path`), one per frame."""
    if not speed > 0:
        raise ConfigError(f"speed must be > 0 m/s, got {speed}")
    index = TileStore(bundle.manifest["terrain"]["root"]).read_index()
    return list(fly_path(index, int(frames), fps, speed))
