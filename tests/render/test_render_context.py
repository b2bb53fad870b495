"""Headless context, off-screen target and PNG output."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from piste.errors import RenderError
from piste.render import Offscreen, create_context, save_png
from piste.render.context import check_gl_error, load_shader


def test_context_is_gl33_or_better(gl):
    assert gl.version_code >= 330


def test_offscreen_read_is_top_down(gl):
    target = Offscreen(gl, (8, 6))
    try:
        target.use()
        target.clear((0.0, 0.0, 1.0, 1.0))
        # GL's origin is bottom-left: clear the top two rows red
        target.fbo.clear(1.0, 0.0, 0.0, 1.0, viewport=(0, 4, 8, 2))
        img = target.read()
        assert img.shape == (6, 8, 4) and img.dtype == np.uint8
        assert (img[:2, :, :3] == (255, 0, 0)).all()
        assert (img[2:, :, :3] == (0, 0, 255)).all()
    finally:
        target.release()


def test_offscreen_wrap_releases_only_what_it_owns(gl):
    """``Offscreen.wrap(..., owned=True)`` frees the framebuffer and the given attachments (the
    frame's HDR target); a plain wrap (a window's screen) leaves them alive."""
    color, depth = gl.texture((4, 4), 4), gl.depth_texture((4, 4))
    fbo = gl.framebuffer(color_attachments=[color], depth_attachment=depth)
    owned = Offscreen.wrap(gl, fbo, color=color, depth=depth, owned=True)
    assert owned.color is color and owned.depth is depth and owned.size == (4, 4)
    owned.release()
    assert [type(o.mglo).__name__ for o in (fbo, color, depth)] == ["InvalidObject"] * 3
    color2 = gl.texture((4, 4), 4)
    fbo2 = gl.framebuffer(color_attachments=[color2])
    Offscreen.wrap(gl, fbo2).release()
    assert [type(o.mglo).__name__ for o in (fbo2, color2)] == ["Framebuffer", "Texture"]
    fbo2.release()
    color2.release()


def test_offscreen_rejects_bad_size(gl):
    with pytest.raises(RenderError, match="between 1x1"):
        Offscreen(gl, (0, 10))


def test_bad_backend_names_packages():
    with pytest.raises(RenderError, match="libgl1-mesa-dri"):
        create_context(backend="no-such-backend")


_FRESH_CONTEXT = """
import sys
from piste.render.context import create_context
ctx = create_context()
fbo = ctx.simple_framebuffer((4, 4)); fbo.use(); ctx.clear(0.0, 1.0, 0.0, 1.0)
print(fbo.read()[:3] == bytes([0, 255, 0]), ctx.version_code >= 330, "ctypes.util" in sys.modules)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the EGL libraries are named for Linux")
def test_egl_context_names_its_libraries_and_works(gl):
    """A fresh process's EGL context is made with glcontext's libraries named (no find_library: no
    ctypes.util, no ``ldconfig -p`` run twice) and draws."""
    out = subprocess.run([sys.executable, "-c", _FRESH_CONTEXT], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["True", "True", "False"]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the EGL libraries are named for Linux")
def test_egl_library_environment_variable_is_still_obeyed(gl):
    """glcontext's ``GLCONTEXT_LINUX_LIBEGL`` still chooses the EGL library: a missing one is the usual
    RenderError naming the packages, not a context from the default library."""
    env = {**os.environ, "GLCONTEXT_LINUX_LIBEGL": "libpiste-no-such-egl.so"}
    code = ("from piste.errors import RenderError\nfrom piste.render.context import create_context\n"
            "try:\n    create_context()\nexcept RenderError as e:\n    print('RenderError', 'libgl1-mesa-dri' in str(e))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["RenderError", "True"]


def test_save_png_roundtrip_and_atomic(tmp_path):
    img = np.random.default_rng(0).integers(0, 256, (5, 7, 4), dtype=np.uint8)
    path = save_png(tmp_path / "sub" / "a.png", img)
    assert np.array_equal(np.asarray(Image.open(path)), img)
    assert [p.name for p in path.parent.iterdir()] == ["a.png"]  # no temp file left
    with pytest.raises(RenderError, match="uint8"):
        save_png(tmp_path / "b.png", img.astype(np.float32))
    assert not (tmp_path / "b.png").exists()


def test_shaders_ship_and_gl_errors_are_raised(gl):
    assert "#version 330" in load_shader("terrain.vert.glsl")
    with pytest.raises(RenderError, match="not found"):
        load_shader("nope.glsl")
    check_gl_error(gl)  # no pending error
