"""An SSX Tricky level (``LEVEL.pbd`` + ``LEVEL.ssh`` + ``LEVEL_L.ssh``) as the runtime's scene.

:func:`open_ssx_level` reads the level (:func:`piste.pipeline.ssx_level.load_level`: the patches
as a :class:`~piste.terrain.net.PatchNet` in metres, the level textures in one atlas, the stored
light-map pages) and returns an in-memory :class:`~piste.pipeline.bundle_objects.Bundle`, the same
runtime scene a built ``.piste`` is, with the members a scene build of ``[terrain] ssx_pbd`` stores
(``terrain/base_texture``, ``lightmap/source`` for ``ps2`` mode) so that
:class:`piste.pipeline.preview.ScenePreview` draws it with
:class:`piste.render.ssx_pass.SsxTerrainRenderer`, riders and objects included when the scene has
them (:func:`piste.pipeline.furnish.add_standing_riders`).

The scene's settings are those ``piste ssx render`` always used: the ``ssx_tricky`` LOD preset
(30 / 150 m), no fog, 640 x 448, ``modulate`` light maps, one camera ``level`` looking at the whole
level from the south-west, above (:func:`level_camera`); the default lights (for riders).

API
---
open_ssx_level(path, quiet=True, warm=False) -> Bundle
level_bundle(level) -> Bundle            an already loaded :class:`~piste.pipeline.ssx_level.SsxLevel`
level_camera(net) -> Camera
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from piste.errors import ConfigError
from piste.formats.bundle import camera_to_dict
from piste.lighting.lightmap import LightMap
from piste.lighting.lights import default_lights
from piste.pipeline.bundle_objects import Bundle, camera_from_dict
from piste.pipeline.ssx_level import SSX_TRICKY_LOD, SsxLevel, load_level
from piste.terrain.resident import resident_fits, resident_terrain
from piste.world.camera import Camera

if TYPE_CHECKING:
    from piste.terrain.net import PatchNet

__all__ = ["open_ssx_level", "level_bundle", "level_camera"]


def level_camera(net: PatchNet) -> Camera:
    """A camera looking at the whole level from the south-west, above (``piste ssx render``'s)."""
    lo, hi = net.bounds
    c = (lo + hi) / 2.0
    ext = float(np.linalg.norm(hi - lo))
    return Camera(c + np.array([-0.35, -0.6, 0.55]) * ext, c, fov_y=50.0, near=max(ext * 1e-3, 0.05), far=ext * 4.0)


def level_bundle(level: SsxLevel, warm: bool = False) -> Bundle:
    """The runtime scene of a loaded level (see the module docstring)."""
    net = level.net
    if warm and resident_fits(net):
        resident_terrain(net, wait=False)
    cam = camera_to_dict(level_camera(net))
    manifest = {
        "name": level.path.stem,
        "source": "ssx",
        "terrain": {"name": level.path.stem, "source": "ssx_pbd"},
        "lod": {"near": SSX_TRICKY_LOD["near"], "far": SSX_TRICKY_LOD["far"], "morph": True},
        "render": {"size": [640, 448], "fog": 0.0, "lightmap_mode": "modulate"},
        "lights": default_lights().to_dict(),
        "cameras": [{"name": "level", "source": "ssx level", **cam}],
        "riders": [],
        "characters": {},
    }
    arrays = {"terrain/base_texture": level.base_atlas, "lightmap/source": level.source,
              "lightmap/atlas": level.light.astype(np.float32),
              "lightmap/rects": np.asarray(net.lightmap_rect, np.float32)}
    lightmap = LightMap(atlas=arrays["lightmap/atlas"], rects=arrays["lightmap/rects"], res=8, gutter=1, manifest={})
    lights = default_lights()
    return Bundle(level.path, manifest, arrays, net, lightmap, lights, {"level": camera_from_dict(cam)})


def open_ssx_level(path: str | Path, quiet: bool = True, warm: bool = False) -> Bundle:
    """``LEVEL.pbd`` (and the banks beside it) as a runtime scene (see the module docstring)."""
    p = Path(path)
    if p.suffix.lower() != ".pbd":
        raise ConfigError(f"{path}: expected an SSX Tricky level (.pbd)")
    return level_bundle(load_level(p), warm=warm)
