"""The built-in default scene: what ``piste demo`` builds (cached) before it renders.

The default course of a seed, its default lights (:func:`piste.lighting.default_lights`) and the
baked light map (8 x 8 texels a patch, terrain shadows), with a camera flying down the track, the
six riders of the default pack following the track (``[pack] follow = "track"``, the camera chasing
the first) and the course's trees, signs, rocks and rails placed along it (``[auto_objects]``, the
course's seed).  It
is an ordinary scene file, written into the piste cache folder
(:func:`piste.pipeline.cache.cache_root`, then ``scenes/``) and built by :func:`piste.pipeline.build_scene` with the
step cache beside it, so the first ``piste demo`` bakes the light map and every later one loads
the bundle.  The runtime (:func:`piste.pipeline.preview.track_scene`) makes the pack and the
objects from those keys.

API
---
DEFAULT_SCENE_TOML                      the scene file (``{seed}`` filled in)
default_scene_path(seed, root=None)     where the scene file lives (written when missing or changed)
build_default_scene(seed=0, root=None, progress=False) -> BuildResult
"""

from __future__ import annotations

from pathlib import Path

from piste.formats.atomic import write_bytes_atomic
from piste.pipeline.build import BuildResult, build_scene
from piste.pipeline.cache import cache_root

__all__ = ["DEFAULT_SCENE_TOML", "default_scene_path", "build_default_scene"]

#: the built-in default scene
DEFAULT_SCENE_TOML = """\
# The built-in default scene of `piste demo` (written by piste.pipeline.default_scene).
name = "default course (seed {seed})"

[terrain]
source = "default"
seed = {seed}

[lightmap]
res = 8
shadows = true

[lod]
near = 60.0
far = 180.0

[visibility]
enabled = true                # the chase camera is inside the sampled band: 10-30 % of the patches
                              #   in the frustum are hidden behind the slope and not drawn

[render]
fog = "auto"
face = "morph"

[pack]
follow = "track"
start = 0.12

[auto_objects]
seed = {seed}
trees = 220
signs = 16
rocks = 40
rails = 6

[[cameras]]
name = "flight"
track = [0.12, 0.45]
height = 12.0
fov = 60.0
"""


def default_scene_path(seed: int = 0, root: str | Path | None = None) -> Path:
    """The default scene file of ``seed`` under ``root`` (default: :func:`piste.pipeline.cache.cache_root` / ``scenes``),
    written (atomically) when missing or different."""
    folder = Path(root) if root is not None else cache_root() / "scenes"
    path = folder / f"default-seed{int(seed)}.toml"
    text = DEFAULT_SCENE_TOML.format(seed=int(seed)).encode()
    if not path.is_file() or path.read_bytes() != text:
        folder.mkdir(parents=True, exist_ok=True)
        write_bytes_atomic(path, text)
    return path


def build_default_scene(seed: int = 0, root: str | Path | None = None, progress: bool = False) -> BuildResult:
    """Build (or load from the cache) the default scene of ``seed``: the bundle is
    ``default-seed<seed>.piste`` beside the scene file, the step cache ``.piste-cache`` beside it."""
    path = default_scene_path(seed, root)
    return build_scene(path, progress=progress)
