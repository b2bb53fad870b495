"""Open a scene for rendering or export: a built ``.piste`` bundle, or a ``.toml`` scene built
first (with the step cache beside it).  Used by ``piste render``, ``piste export`` and ``piste ssx``.

API
---
load_or_build(scene, quiet=True) -> Bundle
"""

from __future__ import annotations

import sys
from pathlib import Path

from piste.errors import ConfigError
from piste.pipeline.build import build_scene
from piste.pipeline.bundle_objects import Bundle, load_bundle

__all__ = ["load_or_build"]


def load_or_build(scene, quiet: bool = True) -> Bundle:
    """A loaded bundle for ``scene``: a ``.piste`` file, or a ``.toml`` scene built (cached) beside it."""
    p = Path(scene)
    if p.suffix.lower() == ".piste":
        return load_bundle(p)
    if p.suffix.lower() != ".toml":
        raise ConfigError(f"{scene}: expected a scene (.toml) or a bundle (.piste)")
    r = build_scene(p, progress=not quiet and sys.stderr.isatty())
    return load_bundle(r.path)
