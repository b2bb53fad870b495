"""Optional compilation with numba, loaded lazily.

``HAVE_NUMBA`` says whether numba is installed (found without importing it: importing numba costs
~0.2 s, which a fresh process should not pay before its first frame).  ``lazy_njit(fn)`` returns a
callable that compiles ``fn`` with ``numba.njit(cache=True)`` on its first call (later processes
load the compiled code from the on-disk cache), or None without numba.  ``PISTE_NO_NUMBA=1``
disables numba everywhere (the numpy twins run; tests compare the two bit for bit).
"""

from __future__ import annotations

import importlib.util
import os

__all__ = ["HAVE_NUMBA", "lazy_njit"]

HAVE_NUMBA = not os.environ.get("PISTE_NO_NUMBA") and importlib.util.find_spec("numba") is not None


class _Lazy:
    def __init__(self, fn):
        self.fn = fn
        self.compiled = None
        self.__doc__ = fn.__doc__
        self.__name__ = fn.__name__

    def __call__(self, *args):
        c = self.compiled
        if c is None:
            import numba

            c = self.compiled = numba.njit(cache=True, nogil=True, boundscheck=False)(self.fn)
        return c(*args)


def lazy_njit(fn):
    """``fn`` compiled on first call (numba), or None when numba is not available."""
    return _Lazy(fn) if HAVE_NUMBA else None
