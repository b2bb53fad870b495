"""OpenGL contexts (headless EGL) and off-screen framebuffers with pixel read-back.

On a machine without a GPU, ``moderngl.create_standalone_context(backend="egl")`` runs on Mesa's
llvmpipe (GL 4.5 core).  It needs the Debian packages ``libegl1 libgl1 libgl1-mesa-dri``.

API
---
create_context      a headless moderngl context, or RenderError saying what to install
Offscreen           colour RGBA8 + depth framebuffer of W x H with ``read() -> (H, W, 4) uint8``
save_png            write an (H, W, 3|4) uint8 image atomically
load_shader         the text of a shader in ``piste/render/shaders``
check_gl_error      raise RenderError if the context has a pending GL error
set_depth_write     turn depth writes of the bound framebuffer on/off (``ctx.depth_mask`` is no GL state)
flush               glFlush: start the GL on what was issued, without waiting (pipelined frames)
"""

from __future__ import annotations

import contextlib
import os
import sys
from functools import lru_cache
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import numpy.typing as npt

from piste.errors import RenderError
from piste.extras import environ, require as require_extra
from piste.formats.atomic import atomic_path

if TYPE_CHECKING:
    import moderngl

__all__ = ["create_context", "Offscreen", "save_png", "load_shader", "check_gl_error", "set_depth_write", "release_framebuffer", "APT_PACKAGES"]

#: Debian/Ubuntu packages that provide headless OpenGL through EGL (Mesa llvmpipe without a GPU)
APT_PACKAGES = ("libegl1", "libgl1", "libgl1-mesa-dri")
SHADER_DIR = Path(__file__).parent / "shaders"


def create_context(backend: str | None = "egl", require: tuple[int, int] = (3, 3)) -> moderngl.Context:
    """A standalone (window-less) moderngl context.

    Parameters
    ----------
    backend : "egl" (headless, the default) or None for the platform default (GLX/WGL/CGL)
    require : the minimum OpenGL version (major, minor)

    Raises
    ------
    RenderError naming the packages to install when no context can be created.
    """
    moderngl = require_extra("moderngl", "OpenGL rendering")
    kwargs: dict[str, Any] = {"require": require[0] * 100 + require[1] * 10}
    if backend == "egl":
        ctx = _egl_context(moderngl, kwargs["require"])
        if ctx is not None:
            return ctx
    if backend:
        kwargs["backend"] = backend
    try:
        return moderngl.create_standalone_context(**kwargs)
    except Exception as exc:
        raise RenderError(
            f"cannot create a headless OpenGL {require[0]}.{require[1]} context (backend={backend!r}): {exc}. "
            f"On Debian/Ubuntu install the Mesa EGL driver: "
            f"`sudo apt-get install -y --no-install-recommends {' '.join(APT_PACKAGES)}` "
            "(`make demo` does this for you)."
        ) from None


#: the GL and EGL libraries glcontext's EGL backend loads, named (the names ``find_library`` gives on
#: Linux): glcontext otherwise looks each up with ``ctypes.util.find_library``, which imports ctypes.util
#: and subprocess and runs ``ldconfig -p`` twice, ~10 ms of a fresh process's start (of ~30 ms for the
#: whole context).  ``GLCONTEXT_LINUX_LIBGL`` / ``GLCONTEXT_LINUX_LIBEGL`` still choose others.
EGL_LIBRARIES = {"libgl": "libGL.so.1", "libegl": "libEGL.so.1"}


def _egl_context(mgl: Any, version: int) -> moderngl.Context | None:
    """A standalone moderngl context on glcontext's EGL backend, created the way the backend's own
    factory creates it (``glcontext.egl.create_context(mode="standalone", ...)``, glcontext's
    ``GLCONTEXT_*`` environment variables applied) but with :data:`EGL_LIBRARIES` named, then handed
    to moderngl (``context=``).  None where that does not work here (not Linux, another glcontext,
    libraries of other names): the caller then takes moderngl's usual path, which says what failed."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        from glcontext import egl
    except ImportError:
        return None
    kw: dict[str, Any] = {"mode": "standalone", "glversion": version, **EGL_LIBRARIES}
    raw = None
    try:
        for name, env, kind in (("device_index", "GLCONTEXT_DEVICE_INDEX", int), ("glversion", "GLCONTEXT_GLVERSION", int),
                                ("libgl", "GLCONTEXT_LINUX_LIBGL", str), ("libegl", "GLCONTEXT_LINUX_LIBEGL", str)):
            value = environ(env)
            if value:
                kw[name] = kind(value)
        raw = egl.create_context(**kw)
        return cast("moderngl.Context", mgl.create_standalone_context(require=version, context=raw))
    except Exception:
        if raw is not None:
            with contextlib.suppress(Exception):
                raw.release()
        return None


def check_gl_error(ctx: moderngl.Context, where: str = "") -> None:
    """Raise :class:`RenderError` if ``ctx.error`` is not ``GL_NO_ERROR``."""
    err = ctx.error
    if err != "GL_NO_ERROR":
        raise RenderError(f"OpenGL error {err}" + (f" after {where}" if where else ""))


def set_depth_write(ctx: moderngl.Context, on: bool) -> bool:
    """Turn writing to the depth buffer on or off for the draws that follow; returns the previous
    setting.

    moderngl (5.x) keeps the depth mask on the *framebuffer* (``Framebuffer.depth_mask``, applied
    by ``glDepthMask`` when it is bound or set while bound); ``Context`` has no such property, so
    ``ctx.depth_mask = False`` only sets a Python attribute and depth is still written.  This sets
    it on the bound framebuffer, ``ctx.fbo``.  Passes that turn it off restore it (True) in a
    ``finally``.
    """
    fbo = ctx.fbo
    if fbo is None:  # (a standalone context before any framebuffer was bound: nothing to mask)
        return True
    was = bool(fbo.depth_mask)
    fbo.depth_mask = bool(on)
    return was


@lru_cache(maxsize=None)
def load_shader(name: str) -> str:
    """Source of ``piste/render/shaders/<name>``, with ``#include "file"`` lines replaced by the
    text of that file (one level, from the same folder)."""
    path = SHADER_DIR / name
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise RenderError(f"{path}: shader not found (is the package installed with its data files?)") from None
    lines = []
    for line in text.splitlines():
        if line.startswith("#include"):
            inc = line.split('"')[1] if line.count('"') == 2 else ""
            if not inc or inc == name:
                raise RenderError(f"{path}: bad include line {line!r}")
            line = load_shader(inc)
        lines.append(line)
    return "\n".join(lines) + "\n"


class Offscreen:
    """An off-screen render target: colour RGBA8 (+ depth 24) of ``size = (W, H)``.

    ``read()`` returns the colour buffer as ``(H, W, 4) uint8`` with row 0 at the top of the image.
    """

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int], depth: bool = True) -> None:
        w, h = int(size[0]), int(size[1])
        if w < 1 or h < 1 or w > 16384 or h > 16384:
            raise RenderError(f"framebuffer size must be between 1x1 and 16384x16384, got {w}x{h}")
        self.ctx = ctx
        self.size: tuple[int, int] = (w, h)
        self.color = ctx.renderbuffer((w, h), 4)
        self.depth = ctx.depth_renderbuffer((w, h)) if depth else None
        self.fbo = ctx.framebuffer(color_attachments=[self.color], depth_attachment=self.depth)
        self._owned = True
        self._buf = np.empty((h, w, 4), dtype=np.uint8)

    @classmethod
    def wrap(cls, ctx: moderngl.Context, fbo: moderngl.Framebuffer, color: Any = None, depth: Any = None,
             owned: bool = False) -> "Offscreen":
        """Use an existing framebuffer (e.g. a window's ``ctx.screen``) as the target.

        ``color``/``depth`` are its attachments when the caller wants them reachable (e.g. textures
        a later pass samples).  ``owned=False`` (default): :meth:`release` leaves the framebuffer
        alone; ``owned=True``: :meth:`release` frees it and the given attachments, as for a target
        this class made itself."""
        self = cls.__new__(cls)
        self.ctx = ctx
        self.size = cast("tuple[int, int]", tuple(fbo.size))
        self.color, self.depth = color, depth
        self.fbo = fbo
        self._owned = bool(owned)
        self._buf = np.empty((self.size[1], self.size[0], 4), dtype=np.uint8)
        return self

    @property
    def width(self) -> int:
        return self.size[0]

    @property
    def height(self) -> int:
        return self.size[1]

    def use(self) -> None:
        self.fbo.use()
        self.ctx.viewport = (0, 0, *self.size)

    def clear(self, rgba: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0), depth: float = 1.0) -> None:
        self.fbo.clear(*rgba, depth=depth)

    def read(self) -> np.ndarray:
        """The colour buffer, ``(H, W, 4) uint8``, top row first (a fresh array)."""
        self.fbo.read_into(self._buf, components=4, alignment=1)
        return self._buf[::-1].copy()

    def release(self) -> None:
        if not self._owned:
            return
        release_framebuffer(self.ctx, self.fbo, self.color, self.depth)


def release_framebuffer(ctx: moderngl.Context, fbo: moderngl.Framebuffer, *attachments: Any) -> None:
    """Release ``fbo`` and its ``attachments`` (None skipped), unbinding it first when bound:
    moderngl binds the "current" framebuffer again after it creates the next one, and binding a
    deleted one is GL_INVALID_OPERATION (the next ``ctx.framebuffer`` would fail)."""
    if ctx.fbo is fbo:
        (ctx.screen or ctx.detect_framebuffer(0)).use()
    for obj in (fbo, *attachments):
        if obj is not None:
            obj.release()


def save_png(path: str | os.PathLike[str], image: npt.ArrayLike) -> Path:
    """Write ``image`` ``(H, W, 3|4) uint8`` (or ``(H, W)``) to ``path`` as PNG, atomically."""
    from PIL import Image

    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] not in (3, 4)):
        raise RenderError(f"save_png({path}): expected an (H, W, 3|4) uint8 image, got {img.shape} {img.dtype}")
    path = Path(path)
    with atomic_path(path) as tmp:
        Image.fromarray(np.ascontiguousarray(img)).save(tmp, format="PNG")
        tmp.chmod(0o644)  # mkstemp makes 0600 files; an image is for everyone
    return path


@lru_cache(maxsize=1)
def _gl_flush() -> Callable[[], None] | None:
    """``glFlush`` of the GL library (GLVND's ``libGL``/``libOpenGL`` dispatch to the current
    context, EGL or GLX alike), or None when neither library loads."""
    import ctypes

    for name in ("libGL.so.1", "libOpenGL.so.0"):
        try:
            fn = ctypes.CDLL(name).glFlush
        except (OSError, AttributeError):
            continue
        fn.restype = None
        fn.argtypes = []
        return fn
    return None


def flush(ctx: moderngl.Context) -> bool:
    """Hand the commands issued so far to the GL (``glFlush``, which moderngl does not expose) without
    waiting for them: llvmpipe's rasterizer threads start on the frame while the caller goes on (the
    next frame's CPU work).  Returns False where no GL library gave ``glFlush`` (then nothing
    overlaps, and everything is still drawn by the next read or finish)."""
    fn = _gl_flush()
    if fn is None:
        return False
    fn()
    return True
