"""Optional compilation with numba, loaded lazily and warmed in the background.

``HAVE_NUMBA`` says whether numba is installed (found without importing it: importing numba and
loading its cached kernels costs a fresh process ~0.8 s, which it should not pay before its first
frame).  ``lazy_njit(fn, example)`` returns a kernel compiled with ``numba.njit(cache=True)``:

* ``kernel(*args)`` compiles (or loads from the on-disk cache) on first call, synchronously;
* ``kernel.ready()`` is True once compiled; the first time it is asked (and False) it starts one
  background thread that imports numba and warms every registered kernel with its ``example()``
  arguments.  Dispatchers that have a numpy twin use the compiled kernel only when ready, so the
  first frames run the numpy paths (bit-identical results) while numba loads.

``warm_up()`` compiles everything now (benchmarks and tests call it before timing or comparing).
``WarmUpHold()`` holds the background warm-up back until its ``release()``: numba's import holds
the GIL for most of its ~0.8 s, and a fresh process's first frame (which asks ``ready()``) took
~0.13 s longer with it running beside; :class:`piste.pipeline.ScenePreview` holds it through its
set-up and first frame.
``PISTE_NO_NUMBA=1`` disables numba everywhere.
"""

from __future__ import annotations

import importlib.util
import threading
from collections.abc import Callable
from typing import Any

from piste.extras import environ

__all__ = ["HAVE_NUMBA", "KERNEL_MODULES", "lazy_njit", "warm_up", "warm_up_async", "WarmUpHold"]

HAVE_NUMBA = not environ("PISTE_NO_NUMBA") and importlib.util.find_spec("numba") is not None
_KERNELS: list = []
_LOCK = threading.Lock()  # compilation
_START = threading.Lock()  # starting the warm-up thread
_THREAD: list = [None]
_HOLDS = [0, False]  # [holds in force, warm-up asked for while held]


class _Lazy:
    def __init__(self, fn: Callable[..., Any], example: Callable[[], tuple[Any, ...]] | None = None) -> None:
        self.fn = fn
        self.example = example
        self.compiled: Any = None
        self._ready = False
        self.__doc__ = fn.__doc__
        self.__name__ = fn.__name__

    def _compile(self) -> Any:
        with _LOCK:
            if self.compiled is None:
                import numba

                self.compiled = numba.njit(cache=True, nogil=True, boundscheck=False)(self.fn)
        return self.compiled

    def warm(self) -> None:
        c = self._compile()
        if self.example is not None:
            c(*self.example())  # loads (or compiles) the specialisation for these types

    def ready(self) -> bool:
        """Compiled and loaded (else start warming all kernels in the background, once)."""
        if self._ready:
            return True
        if self.compiled is not None and (self.example is None or self.compiled.signatures):
            self._ready = True  # (numba's ``signatures`` costs ~50 us a call: ask once)
            return True
        warm_up_async()
        return False

    def __call__(self, *args: Any) -> Any:
        c = self.compiled
        if c is None:
            c = self._compile()
        return c(*args)


def lazy_njit(fn: Callable[..., Any], example: Callable[[], tuple[Any, ...]] | None = None) -> Any:
    """``fn`` compiled on first call (numba), or None when numba is not available.  ``example()``
    returns arguments of the types it is called with (for the background warm-up).  (Typed ``Any``:
    callers test for None through their own flags, e.g. ``_compiled(use_numba)``, which mypy cannot follow.)"""
    if not HAVE_NUMBA:
        return None
    k = _Lazy(fn, example)
    _KERNELS.append(k)
    return k


#: the modules that define kernels (imported by the warm-up, so it does not depend on import order)
KERNEL_MODULES = ("piste.terrain._kernels", "piste.character.skinning")


def warm_up() -> None:
    """Compile / load every kernel now (no-op without numba)."""
    if not HAVE_NUMBA:
        return
    for name in KERNEL_MODULES:
        importlib.import_module(name)
    for k in list(_KERNELS):
        k.warm()


def warm_up_async() -> None:
    """Start warming every kernel in a background thread (once per process)."""
    if not HAVE_NUMBA or _THREAD[0] is not None:
        return
    with _START:
        if _HOLDS[0]:
            _HOLDS[1] = True  # started when the last hold is released
            return
        if _THREAD[0] is None:
            t = threading.Thread(target=_warm_quietly, name="piste-numba-warm-up", daemon=True)
            _THREAD[0] = t
            t.start()


class WarmUpHold:
    """Keep :func:`warm_up_async` from starting its thread until :meth:`release` (idempotent);
    a warm-up asked for meanwhile starts when the last hold is released (with ``start=False``,
    e.g. a preview closed after one frame, not: the next ``ready()`` asks again).  (:func:`warm_up`
    is not held.)"""

    def __init__(self) -> None:
        with _START:
            _HOLDS[0] += 1
        self.held = True

    def release(self, start: bool = True) -> None:
        with _START:
            if not self.held:
                return
            self.held = False
            _HOLDS[0] -= 1
            go = start and _HOLDS[0] == 0 and _HOLDS[1]
            if go:
                _HOLDS[1] = False
        if go:
            warm_up_async()


def _warm_quietly() -> None:
    try:
        warm_up()
    except Exception:  # pragma: no cover - a failed warm-up leaves the numpy paths in use
        pass
