"""Open a scene for rendering or export: a built ``.piste`` bundle, or a ``.toml`` scene built
first (with the step cache beside it).  Used by ``piste render``, ``piste export`` and ``piste ssx``.

API
---
load_or_build(scene, quiet=True, warm=False) -> Bundle
load_net(path=None) -> PatchNet         a .bpt / .npz patch net, or the default course (``piste bake``, ``piste ssx``)
"""

from __future__ import annotations

import sys
from pathlib import Path

from piste.errors import ConfigError
from piste.pipeline.build import build_scene
from piste.pipeline.bundle_objects import Bundle, load_bundle
from piste.terrain.net import PatchNet
from piste.world.course import default_course

__all__ = ["load_or_build", "load_net"]


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


def load_or_build(scene, quiet: bool = True, warm: bool = False) -> Bundle:
    """A loaded bundle for ``scene``: a ``.piste`` file, or a ``.toml`` scene built (cached) beside it.
    ``warm``: start the terrain's resident vertex blocks at load (see :func:`load_bundle`)."""
    p = Path(scene)
    if p.suffix.lower() == ".piste":
        return load_bundle(p, warm=warm)
    if p.suffix.lower() != ".toml":
        raise ConfigError(f"{scene}: expected a scene (.toml) or a bundle (.piste)")
    r = build_scene(p, progress=not quiet and sys.stderr.isatty())
    return load_bundle(r.path, warm=warm)
