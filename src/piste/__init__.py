"""piste: the rendering system of SSX / SSX Tricky (GDC 2002), real, fast and usable today.

Subpackages
-----------
terrain     bicubic Bézier patch nets, per-edge LOD, crack-free tessellation, fitting, queries
character   glTF import, skeletons, clips, compression, skinning schemes, palettes, strips, morphs
lighting    lights, light-map baking, the PS2 blend trick, per-vertex lighting
world       the default course, objects, cameras, scenes
formats     file formats (.bpt, glTF, bundles)
render      OpenGL (moderngl) renderer, headless through EGL
"""

import logging

from piste.errors import ConfigError, FormatError, PisteError, RenderError, ValidationError

#: the one place the version is written (pyproject.toml reads it: ``[tool.setuptools.dynamic]``)
__version__ = "0.2.0"

# the library reports through the ``piste`` logger and prints nothing itself; `piste -v/-q` sets its level
logging.getLogger("piste").addHandler(logging.NullHandler())

__all__ = ["PisteError", "FormatError", "ValidationError", "ConfigError", "RenderError", "__version__"]
