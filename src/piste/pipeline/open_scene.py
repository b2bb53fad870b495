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
``NAME.tiles/``           a tiled world: streamed by its own terrain renderer (:func:`source_kind`
                          says ``"tiles"``; see :mod:`piste.render.streaming`)
========================  ====================================================================

A new source is one new module with an ``open_<kind>(path, quiet, warm) -> Bundle`` function and
one :class:`Source` row in :data:`SOURCES`.

API
---
SOURCES                                       the registry, in matching order
source_kind(path) -> str                      "bundle", "scene", "ssx", "tiles" (ConfigError otherwise)
open_source(path, quiet=True, warm=False, riders=0) -> Bundle
load_or_build(scene, quiet=True, warm=False) -> Bundle     (= open_source: every kind but tiles)
load_net(path=None) -> PatchNet         a .bpt / .npz patch net, or the default course (``piste bake``, ``piste ssx``)
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from piste.errors import ConfigError
from piste.pipeline.build import build_scene
from piste.pipeline.bundle_objects import Bundle, load_bundle
from piste.pipeline.runtime_riders import add_standing_riders
from piste.pipeline.ssx_source import open_ssx_level
from piste.terrain.net import PatchNet
from piste.world.course import default_course

__all__ = ["Source", "SOURCES", "source_kind", "open_source", "load_or_build", "load_net"]


def load_net(path=None) -> PatchNet:
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


def _open_tiles(path: Path, quiet: bool, warm: bool) -> Bundle:
    raise ConfigError(f"{path}: a tiled world is streamed by piste.render.streaming (piste render|view WORLD.tiles); "
                      "it has no single patch net to open as a scene")


@dataclass(frozen=True)
class Source:
    """One kind of source: ``kind``, ``suffix`` (lower case, with the dot; a folder for tiles) and
    ``open(path, quiet, warm) -> Bundle``."""

    kind: str
    suffix: str
    open: Callable[[Path, bool, bool], Bundle]
    folder: bool = False


#: every source the runtime opens, in matching order
SOURCES: list[Source] = [
    Source("bundle", ".piste", _open_bundle),
    Source("scene", ".toml", _open_scene_file),
    Source("ssx", ".pbd", open_ssx_level),
    Source("tiles", ".tiles", _open_tiles, folder=True),
]


def _source(path) -> Source:
    name = str(path).rstrip("/\\").lower()
    for s in SOURCES:
        if name.endswith(s.suffix):
            return s
    kinds = ", ".join(f"{s.kind} ({s.suffix})" for s in SOURCES)
    raise ConfigError(f"{path}: not a source piste opens; expected one of: {kinds}")


def source_kind(path) -> str:
    """The kind of source ``path`` is (:data:`SOURCES`): "bundle", "scene", "ssx" or "tiles"."""
    return _source(path).kind


def open_source(path, quiet: bool = True, warm: bool = False, riders: int = 0) -> Bundle:
    """The runtime scene of ``path`` (any kind in :data:`SOURCES` but tiles).  ``warm``: start the
    terrain's resident vertex blocks at load (see :func:`load_bundle`).  ``riders``: add that many
    default riders standing on the terrain when the source has none of its own
    (:func:`piste.pipeline.runtime_riders.add_standing_riders`)."""
    src = _source(path)
    p = Path(str(path).rstrip("/\\")) if src.folder else Path(path)
    bundle = src.open(p, quiet, warm)
    if riders and not bundle.manifest.get("riders") and not bundle.manifest.get("pack"):
        bundle = add_standing_riders(bundle, int(riders))
    return bundle


def load_or_build(scene, quiet: bool = True, warm: bool = False) -> Bundle:
    """A loaded bundle for ``scene``: a ``.piste`` file, a ``.toml`` scene built (cached) beside it,
    or an SSX level (:func:`open_source`)."""
    return open_source(scene, quiet=quiet, warm=warm)
