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

import importlib
import logging
import sys
from collections.abc import Callable

from piste.errors import ConfigError, FormatError, PisteError, RenderError, ValidationError

#: the one place the version is written (pyproject.toml reads it: ``[tool.setuptools.dynamic]``)
__version__ = "0.2.0"

# the library reports through the ``piste`` logger and prints nothing itself; `piste -v/-q` sets its level
logging.getLogger("piste").addHandler(logging.NullHandler())

__all__ = ["PisteError", "FormatError", "ValidationError", "ConfigError", "RenderError", "__version__"]


def _lazy_exports(package: str, exports: dict[str, tuple[str, ...]]) -> tuple[list[str], Callable, Callable]:
    """``(__all__, __getattr__, __dir__)`` for package ``package`` re-exporting ``exports``
    (``{submodule (relative, e.g. "build"): (names...)}``) lazily (PEP 562 module ``__getattr__``).

    A name's submodule is imported the first time the name is asked for (``piste.pipeline.build_scene``,
    ``from piste.render import SceneRenderer``), then the value is stored on the package, so later
    look-ups cost nothing: a fresh ``piste render BUNDLE`` imports only what a render uses, not the
    build, the baker, the glTF importer, the SSX readers or Dask.  Each ``__init__`` also imports the
    same names under ``if TYPE_CHECKING:`` (type checkers, tests/test_architecture.py's import graph);
    tests/test_lazy_imports.py checks the two lists agree and every name in ``__all__`` resolves.

    A name that is also a submodule's name (``piste.terrain.stats``, the function in the submodule of
    that name) stays lazy too: the import system binds a submodule on its package when anything imports
    it, and the package's class (:class:`_LazyPackage`) declines that one binding, so the package's name
    stays the function, looked up from the submodule when first asked for."""
    where = {name: f"{package}.{module}" for module, names in exports.items() for name in names}
    shadowed = {name for name, module in where.items() if module == f"{package}.{name}"}
    if shadowed:
        _SHADOWED[package] = frozenset(shadowed)
        sys.modules[package].__class__ = _LazyPackage

    def __getattr__(name: str):
        module = where.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(where))

    return list(where), __getattr__, __dir__


#: package -> its lazily re-exported names that are also its submodules' names (:class:`_LazyPackage`)
_SHADOWED: dict[str, frozenset[str]] = {}


class _LazyPackage(type(sys)):
    """A package whose lazily re-exported function shares its name with the submodule it lives in:
    binding that submodule on the package (what importing ``package.name`` does) is skipped, so the
    package's attribute is the function (:func:`_lazy_exports`), as if the ``__init__`` had imported it."""

    def __setattr__(self, name: str, value: object) -> None:
        if name in _SHADOWED.get(self.__name__, ()) and isinstance(value, type(sys)) \
                and value.__name__ == f"{self.__name__}.{name}":
            return
        super().__setattr__(name, value)

