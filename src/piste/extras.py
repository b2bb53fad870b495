"""Optional dependencies, grouped into the package's extras (``pip install 'piste[gl]'``).

The numpy cores (terrain, character, lighting, formats) need only the hard dependencies; OpenGL,
windows, video, Draco, GeoTIFF and Dask come from extras.  :func:`require` imports an optional
module or raises :class:`piste.errors.MissingExtraError` naming the extra to install.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from piste.errors import MissingExtraError

#: importable module -> the extra that installs it
EXTRA_OF: dict[str, str] = {
    "moderngl": "gl",
    "pyglet": "gl",
    "imageio": "video",
    "imageio_ffmpeg": "video",
    "DracoPy": "gltf",
    "tifffile": "dask",
    "dask": "dask",
    "distributed": "dask",
    "numba": "fast",
}


def require(module: str, feature: str = "this feature") -> ModuleType:
    """Import ``module`` (e.g. ``"moderngl"`` or ``"imageio.v2"``) or raise :class:`MissingExtraError`.

    ``feature`` names what needs it ("piste demo", "MP4 output").
    """
    top = module.split(".")[0]
    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingExtraError(EXTRA_OF.get(top, "all"), feature, top) from None


def available(module: str) -> bool:
    """Whether ``module`` can be imported (without raising)."""
    try:
        importlib.import_module(module)
    except ImportError:
        return False
    return True
