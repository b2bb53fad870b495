"""The vispy peer for drawing terrain: a piste :class:`~piste.terrain.TerrainMesh` drawn with
``vispy.gloo`` in vispy's own headless EGL canvas (Mesa llvmpipe, no display), the way piste's
``TerrainPass`` draws it in ``modulate`` mode: base texture (mip-mapped, bilinear within the nearest
level, repeated) times the light-map atlas (half-float, bilinear, clamped), depth test ``<``,
back faces culled when piste culls them, into an off-screen RGBA8 + depth-24 frame buffer.

Set-up notes (what it takes here):

* vispy's ``egl`` backend calls ``eglGetDisplay(EGL_DEFAULT_DISPLAY)``; without a display Mesa then
  fails ("Could not import backend "EGL": Could not initialize").  ``EGL_PLATFORM=surfaceless``
  (set by :func:`make_canvas` unless already set, before vispy loads the backend) makes Mesa give a
  surfaceless display, and vispy's pbuffer canvas works on llvmpipe.
* ``vispy.gloo`` textures offer ``nearest`` / ``linear`` only, no mip-maps: the base texture's mip
  levels are made with ``glGenerateMipmap`` and its filter set through ``vispy.gloo.gl`` on the
  texture's GL handle (else vispy would sample the full-size texture everywhere: a different
  picture and a different cost).
* gloo queues GL commands (GLIR) and runs them on ``context.flush_commands()``; a frame here is
  queue + flush + ``glFinish``, all of which vispy pays in a real application too.

The shader is GLSL 1.20 (vispy's desktop GL is a compatibility context); piste's is GLSL 3.30.
"""

from __future__ import annotations

import os

import numpy as np

_VS = """
#version 120
uniform mat4 u_mvp;
attribute vec3 a_pos;
attribute vec2 a_uv;
attribute vec2 a_uvl;
varying vec2 v_uv;
varying vec2 v_uvl;
void main() {
    gl_Position = u_mvp * vec4(a_pos, 1.0);
    v_uv = a_uv;
    v_uvl = a_uvl;
}
"""

_FS = """
#version 120
uniform sampler2D u_base;
uniform sampler2D u_light;
varying vec2 v_uv;
varying vec2 v_uvl;
void main() {
    gl_FragColor = vec4(texture2D(u_base, v_uv).rgb * texture2D(u_light, v_uvl).rgb, 1.0);
}
"""

GL_RGBA8 = 0x8058
GL_DEPTH_COMPONENT24 = 0x81A6


def _plain(a, dtype) -> np.ndarray:
    """``a`` C-contiguous with numpy's own ``dtype`` object.  Arrays made by numba kernels (piste's
    compiled tessellation) carry an equal but distinct float32 dtype object (``dtype.isbuiltin == 0``);
    vispy's ``VertexBuffer`` then takes ``(n, 3)`` data for ``3n`` scalars ("All attributes must have
    the same size")."""
    return np.ascontiguousarray(a, dtype=dtype).view(dtype)


def make_canvas(size):
    """A hidden vispy canvas on the ``egl`` backend: ``(canvas, description)``.  Raises RuntimeError
    (vispy's own message) when vispy cannot create one."""
    os.environ.setdefault("EGL_PLATFORM", "surfaceless")
    import vispy
    from vispy import app

    vispy.use(app="egl")
    canvas = app.Canvas(size=tuple(int(s) for s in size), show=False)
    canvas.set_current()
    return canvas, f"vispy {vispy.__version__}, app backend {canvas.app.backend_name} ({canvas.app.backend_module.which})"


class VispyTerrain:
    """Draws a terrain mesh with vispy.gloo.

    Parameters
    ----------
    canvas : from :func:`make_canvas`
    size : (W, H) of the off-screen target
    base : (N, N, 4) uint8 tileable base texture (piste's snow)
    light : (H, W, 3|4) light-map atlas, float linear light or uint8 (255 = 1.0), uploaded as RGB16F
        (as piste's :meth:`~piste.render.terrain_pass.TerrainPass.set_lightmap` does)
    cull_back : cull back faces (as piste's terrain pass does for nets whose patches face up)
    """

    def __init__(self, canvas, size, base, light, cull_back: bool = True):
        from vispy import gloo

        self.gloo = gloo
        self.gl = gloo.gl
        self.canvas = canvas
        self.size = (int(size[0]), int(size[1]))
        w, h = self.size
        canvas.set_current()
        self.fbo = gloo.FrameBuffer(color=gloo.RenderBuffer((h, w), format=GL_RGBA8),
                                    depth=gloo.RenderBuffer((h, w), format=GL_DEPTH_COMPONENT24))
        self.prog = gloo.Program(_VS, _FS)
        self.base = gloo.Texture2D(np.ascontiguousarray(base), interpolation="linear", wrapping="repeat")
        light = np.asarray(light)
        light = light[..., :3].astype(np.float32) / (255.0 if light.dtype == np.uint8 else 1.0)
        self.light = gloo.Texture2D(np.ascontiguousarray(light), internalformat="rgb16f",
                                    interpolation="linear", wrapping="clamp_to_edge")
        self.prog["u_base"] = self.base
        self.prog["u_light"] = self.light
        self.pos = gloo.VertexBuffer(np.zeros((3, 3), np.float32))
        self.uv = gloo.VertexBuffer(np.zeros((3, 2), np.float32))
        self.uvl = gloo.VertexBuffer(np.zeros((3, 2), np.float32))
        self.index = gloo.IndexBuffer(np.zeros(3, np.uint32))
        self.prog["a_pos"] = self.pos
        self.prog["a_uv"] = self.uv
        self.prog["a_uvl"] = self.uvl
        self.cull_back = bool(cull_back)
        self.draw(np.eye(4))  # gloo creates the GL objects when a draw first uses them
        # mip-maps for the base texture (gloo has no API for them): on its GL handle
        gl = self.gl
        handle = canvas.context.shared.parser.get_object(self.base.id).handle
        gl.glBindTexture(gl.GL_TEXTURE_2D, handle)
        gl.glGenerateMipmap(gl.GL_TEXTURE_2D)
        gl.glTexParameteri(gl.GL_TEXTURE_2D, gl.GL_TEXTURE_MIN_FILTER, gl.GL_LINEAR_MIPMAP_NEAREST)
        gl.glBindTexture(gl.GL_TEXTURE_2D, 0)

    def flush(self) -> None:
        self.canvas.context.flush_commands()

    def upload(self, mesh) -> None:
        """Write a :class:`~piste.terrain.TerrainMesh`'s positions, UVs and indices into the buffers."""
        self.canvas.set_current()
        self.pos.set_data(_plain(mesh.positions, np.float32))
        self.uv.set_data(_plain(mesh.uv, np.float32))
        self.uvl.set_data(_plain(mesh.uv_lightmap, np.float32))
        self.index.set_data(_plain(mesh.indices, np.uint32).ravel())

    def draw(self, mvp, clear=(0.0, 0.0, 0.0, 1.0)) -> None:
        """Clear and draw the uploaded mesh into the off-screen target with ``mvp`` (4, 4) (column
        vectors, as piste's camera gives it), then wait for the GL (``glFinish``)."""
        gloo = self.gloo
        self.canvas.set_current()
        with self.fbo:
            gloo.set_viewport(0, 0, *self.size)
            gloo.set_state(depth_test=True, blend=False, cull_face=self.cull_back)
            if self.cull_back:
                gloo.set_cull_face("back")
            gloo.set_depth_func("less")
            gloo.set_clear_color(clear)
            gloo.clear(color=True, depth=True)
            self.prog["u_mvp"] = np.ascontiguousarray(np.asarray(mvp, dtype=np.float32).T)  # GL reads column-major
            self.prog.draw("triangles", self.index)
        self.flush()
        self.gl.glFinish()

    def read(self) -> np.ndarray:
        """The colour buffer, ``(H, W, 4) uint8``, top row first."""
        gl = self.gl
        self.canvas.set_current()
        with self.fbo:  # (FrameBuffer.read gives zeros here: the bind is queued, the read is not)
            self.flush()
            gl.glPixelStorei(gl.GL_PACK_ALIGNMENT, 1)
            data = gl.glReadPixels(0, 0, self.size[0], self.size[1], gl.GL_RGBA, gl.GL_UNSIGNED_BYTE)
        self.flush()
        return np.frombuffer(data, np.uint8).reshape(self.size[1], self.size[0], 4)[::-1].copy()

    def release(self) -> None:
        self.canvas.set_current()
        for obj in (self.prog, self.base, self.light, self.pos, self.uv, self.uvl, self.index, self.fbo):
            obj.delete()
        self.flush()
        self.canvas.close()
