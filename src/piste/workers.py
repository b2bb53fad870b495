"""Worker processes that die with their parent.

A process pool's workers outlive a parent that is killed (SIGKILL, an OOM kill, a closed
terminal): they keep computing, and they and multiprocessing's resource tracker hold the caller's
pipes open (a test harness waiting for EOF then hangs).  :func:`die_with_parent` (a pool
``initializer``) asks Linux to SIGKILL the worker when its parent goes (``PR_SET_PDEATHSIG`` via
``prctl``); once the workers are gone the resource tracker sees EOF on its pipe and exits too.
:func:`kill_pool` ends a pool's workers at once when the parent stops on an exception or Ctrl-C
instead of waiting for their running tasks.

API
---
die_with_parent(parent_pid, init=None, *args)    pool initializer: set the death signal, then init(*args)
kill_pool(pool)                                  cancel pending tasks and terminate the workers now
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
from collections.abc import Callable
from typing import Any

__all__ = ["die_with_parent", "kill_pool"]

_PR_SET_PDEATHSIG = 1


def _set_pdeathsig(sig: int = signal.SIGKILL) -> bool:
    """Ask the kernel to send ``sig`` to this process when its parent exits (Linux only)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(_PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def die_with_parent(parent_pid: int, init: Callable[..., Any] | None = None, *args: Any) -> None:
    """Pool ``initializer``: the worker is killed when process ``parent_pid`` ends (and exits at
    once if it already has), then runs ``init(*args)``."""
    _set_pdeathsig()
    if os.getppid() != parent_pid:  # the parent died before the signal was armed
        os._exit(1)
    if init is not None:
        init(*args)


def kill_pool(pool: Any) -> None:
    """Cancel ``pool``'s pending futures and terminate its worker processes now (a
    :class:`concurrent.futures.ProcessPoolExecutor`); the caller's ``with pool:`` then joins them
    quickly instead of waiting for the running tasks."""
    procs = dict(getattr(pool, "_processes", None) or {})  # shutdown() forgets them
    with contextlib.suppress(Exception):
        pool.shutdown(wait=False, cancel_futures=True)
    for p in list(procs.values()):
        with contextlib.suppress(Exception):
            p.terminate()
    for p in list(procs.values()):
        with contextlib.suppress(Exception):
            p.join(5)
