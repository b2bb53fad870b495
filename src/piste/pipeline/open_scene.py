"""Open any source as the runtime's scene: one registry, one return type.

Every source becomes a :class:`~piste.pipeline.bundle_objects.Bundle` (terrain net with its light
map, lights, cameras, riders, objects, visibility), which the one runtime
(:class:`piste.pipeline.preview.ScenePreview`) draws: ``piste render|view|export`` take any of
them with the same flags.

========================  ====================================================================
source                    adapter
========================  ====================================================================
``NAME.piste``            a built bundle (:func:`piste.pipeline.bundle_objects.load_bundle`)
``NAME.toml``             a scene file, built first with the step cache beside it
``NAME.pbd``              an SSX Tricky level with its ``.ssh`` / ``_L.ssh`` (:mod:`piste.pipeline.ssx_source`)
``NAME.tiles/``           a tiled world, its tiles streamed as the terrain (:mod:`piste.pipeline.tiles_source`)
========================  ====================================================================

A new source is one new module with an ``open_<kind>(path, quiet, warm, **options) -> Bundle``
function and one :class:`Source` row in :data:`SOURCES`.  How a source's terrain is drawn is the
runtime's choice by the manifest's ``terrain.source`` (:func:`piste.pipeline.preview.terrain_renderer`).

API
---
::

    SOURCES                                       the registry, in matching order
    source_kind(path) -> str                      "bundle", "scene", "ssx", "tiles" (ConfigError otherwise)
    open_source(path, quiet=True, warm=False, riders=0, objects=0, **options) -> Bundle   (tiles: ``budget_mb``,
        ``track``: a pack of ``riders`` riders, default six, rides (x0, y0, x1, y1) across the tiles)
    load_or_build(scene, quiet=True, warm=False) -> Bundle     (= open_source)
    eye_camera(eye, target, fov_y=50) -> Camera | None            ``--eye``/``--target`` (render, view)
    load_net(path=None) -> PatchNet         a .bpt / .npz patch net, or the default course (``piste bake``, ``piste ssx``)
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from piste.errors import ConfigError
from piste.pipeline.build import build_scene
from piste.pipeline.bundle_objects import Bundle, load_bundle
from piste.pipeline.furnish import add_objects, add_standing_riders
from piste.pipeline.ssx_source import open_ssx_level
from piste.pipeline.tiles_source import open_tiles
from piste.terrain.net import PatchNet
from piste.world.camera import Camera
from piste.world.course import default_course

__all__ = ["Source", "SOURCES", "source_kind", "open_source", "load_or_build", "load_net", "eye_camera"]


def load_net(path: str | os.PathLike[str] | None = None) -> PatchNet:
    """The patch net in ``path`` (``.bpt`` or a saved ``.npz`` net), or the default course when None."""
    if path is None:
        return default_course()
    p = Path(path)
    if p.suffix.lower() == ".bpt":
        return PatchNet.from_bpt(p)
    if p.suffix.lower() == ".npz":
        return PatchNet.load(p)
    raise ConfigError(f"{path}: expected a .bpt or .npz patch net")


def _open_bundle(path: Path, quiet: bool, warm: bool) -> Bundle:
    return load_bundle(path, warm=warm)


def _open_scene_file(path: Path, quiet: bool, warm: bool) -> Bundle:
    r = build_scene(path, progress=not quiet and sys.stderr.isatty())
    return load_bundle(r.path, warm=warm)


@dataclass(frozen=True)
class Source:
    """One kind of source: ``kind``, ``suffix`` (lower case, with the dot; a folder for tiles),
    ``open(path, quiet, warm, **options) -> Bundle`` and the ``options`` it takes."""

    kind: str
    suffix: str
    open: Callable[..., Bundle]
    folder: bool = False
    options: tuple = ()


#: every source the runtime opens, in matching order
SOURCES: list[Source] = [
    Source("bundle", ".piste", _open_bundle),
    Source("scene", ".toml", _open_scene_file),
    Source("ssx", ".pbd", open_ssx_level),
    Source("tiles", ".tiles", open_tiles, folder=True, options=("budget_mb", "track", "track_riders")),
]


def _source(path: str | os.PathLike[str]) -> Source:
    name = str(path).rstrip("/\\").lower()
    for s in SOURCES:
        if name.endswith(s.suffix):
            return s
    kinds = ", ".join(f"{s.kind} ({s.suffix})" for s in SOURCES)
    raise ConfigError(f"{path}: not a source piste opens; expected one of: {kinds}")


def source_kind(path: str | os.PathLike[str]) -> str:
    """The kind of source ``path`` is (:data:`SOURCES`): "bundle", "scene", "ssx" or "tiles"."""
    return _source(path).kind


def open_source(path: str | os.PathLike[str], quiet: bool = True, warm: bool = False, riders: int = 0, objects: int = 0,
                **options: Any) -> Bundle:
    """The runtime scene of ``path`` (any kind in :data:`SOURCES`).  ``warm``: start the terrain's
    resident vertex blocks at load (see :func:`load_bundle`).  ``riders``: add that many default
    riders standing on the terrain when the source has none of its own, ``objects`` that many of
    the course's objects (:mod:`piste.pipeline.furnish`); on a tiled world with a ``track``,
    ``riders`` is the size of the pack riding it instead.  ``options``: the source's own (a tiled
    world's ``budget_mb`` and ``track``); options another kind takes are ignored."""
    src = _source(path)
    p = Path(str(path).rstrip("/\\")) if src.folder else Path(path)
    if riders and src.kind == "tiles" and options.get("track") is not None:  # the pack riding the track: N riders
        options = {**options, "track_riders": int(riders)}
    bundle = src.open(p, quiet, warm, **{k: v for k, v in options.items() if k in src.options and v is not None})
    if riders and not bundle.manifest.get("riders") and not bundle.manifest.get("pack"):
        bundle = add_standing_riders(bundle, int(riders))
    if objects and bundle.objects() is None and not bundle.manifest.get("auto_objects"):
        bundle = add_objects(bundle, int(objects))
    return bundle


def eye_camera(eye: npt.ArrayLike | None, target: npt.ArrayLike | None, fov_y: float = 50.0) -> Camera | None:
    """A camera of one's own at ``eye (3,)`` looking at ``target (3,)`` (metres; ``fov_y`` degrees;
    the far plane 20 times their distance, at least 1 km), None when both are None."""
    if eye is None and target is None:
        return None
    if eye is None or target is None:
        raise ConfigError("--eye and --target go together")
    e, t = (np.asarray(v, dtype=np.float64).reshape(3) for v in (eye, target))
    d = float(np.linalg.norm(e - t))
    if not d > 0.0:
        raise ConfigError("--eye and --target must differ")
    return Camera(e, t, fov_y=float(fov_y), near=0.1, far=max(d * 20.0, 1000.0))


def load_or_build(scene: str | os.PathLike[str], quiet: bool = True, warm: bool = False) -> Bundle:
    """A loaded bundle for ``scene``: a ``.piste`` file, a ``.toml`` scene built (cached) beside it,
    or an SSX level (:func:`open_source`)."""
    return open_source(scene, quiet=quiet, warm=warm)
