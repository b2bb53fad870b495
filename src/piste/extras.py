"""Optional dependencies, grouped into the package's extras (``pip install 'piste[gl]'``).

The numpy cores (terrain, character, lighting, formats) need only the hard dependencies; OpenGL,
windows, video, Draco, GeoTIFF and Dask come from extras.  :func:`require` imports an optional
module or raises :class:`piste.errors.MissingExtraError` naming the extra to install.

It is also the one place the library reads the environment (besides the command line, ``cli.py``):
:data:`ENVIRONMENT` lists every variable piste honours and :func:`environ` reads one of them;
:func:`child_environment` sets variables for the child processes started inside it.  Behaviour
otherwise reaches the cores as parameters (``tests/test_architecture.py`` checks).
"""

from __future__ import annotations

import contextlib
import importlib
import os
from collections.abc import Iterator
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


#: every environment variable piste reads -> what it does
ENVIRONMENT: dict[str, str] = {
    "PISTE_CACHE_DIR": "the cache folder (built default scenes, baked light maps); default "
                       "$XDG_CACHE_HOME/piste or ~/.cache/piste (piste.pipeline.cache.cache_root)",
    "XDG_CACHE_HOME": "the user's cache folder (XDG base directories); piste's cache is its piste/ folder",
    "PISTE_ALLOW_PATHS": "extra folders (os.pathsep-separated) that file references may read "
                         "(piste.formats.safe_io)",
    "PISTE_NO_NUMBA": "set to anything: never compile with numba, run the numpy paths (piste._jit)",
    "DISPLAY": "an X11 display: piste view opens a window (piste.render.window.has_display)",
    "WAYLAND_DISPLAY": "a Wayland display: piste view opens a window",
    # glcontext's own variables, obeyed as glcontext obeys them where piste makes the EGL context itself
    # (piste.render.context names the GL libraries: no find_library)
    "GLCONTEXT_LINUX_LIBGL": "the GL library the headless EGL context loads (default libGL.so.1)",
    "GLCONTEXT_LINUX_LIBEGL": "the EGL library the headless EGL context loads (default libEGL.so.1)",
    "GLCONTEXT_DEVICE_INDEX": "the EGL device the headless context opens (glcontext's default 0)",
    "GLCONTEXT_GLVERSION": "the OpenGL version glcontext asks the EGL context for (e.g. 330)",
}


def environ(name: str) -> str | None:
    """The value of environment variable ``name`` (one of :data:`ENVIRONMENT`), or None when it is
    unset or empty.  A name not listed there is a programming error (KeyError)."""
    if name not in ENVIRONMENT:
        raise KeyError(f"piste does not read the environment variable {name!r}: list it in piste.extras.ENVIRONMENT")
    return os.environ.get(name) or None


@contextlib.contextmanager
def child_environment(values: dict[str, str]) -> Iterator[None]:
    """Set ``values`` in the environment while the block runs (child processes started in it inherit
    them, e.g. one BLAS thread per worker), then restore what was there."""
    saved = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def available(module: str) -> bool:
    """Whether ``module`` can be imported (without raising)."""
    try:
        importlib.import_module(module)
    except ImportError:
        return False
    return True
