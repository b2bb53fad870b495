"""Rendering an SSX Tricky level with its own textures and light maps.

``modulate``: the terrain renderer's one pass, base texture x linear light ``CL`` (recovered from
the stored ``Cs``/``As``, see :mod:`piste.formats.ssx.lightmap`).

``ps2``: the game's way with the stored texels.  The terrain renderer draws the base texture
(``Cd``) first; :class:`SourcePass` then draws the same triangles (depth ``<=``) with the stored
``(Cs, As)`` light-map texels, blended ``(Cd - Cs) x As`` as the GS does (``As`` 128 = 1.0; above
1.0 in a second, additive stage, since GL blend factors stop at 1).  8-bit rounding differs from
the GS's truncating ``>> 7`` by at most a level or two per stage.

API
---
::

    SourcePass(ctx)                 .set_source((h, w, 4) uint8), .draw(mesh, mvp, stage)
    SsxTerrainRenderer(net, source, **TerrainRenderer kwargs)   ps2 mode with the stored Cs/As
        .render(camera, lightmap_mode=...), .source_frame(camera) -> (H, W, 4) uint8
    SourceMode(terrain, "ps2")      an SSX level's ps2 frame for SceneRenderer
                                    (SsxTerrainRenderer.frame_mode("ps2"); render.terrain_mode)

A level is drawn by the one runtime (:func:`piste.pipeline.open_scene.open_source` +
:class:`piste.pipeline.preview.ScenePreview`, which picks this renderer for a level's terrain):
``piste render|view LEVEL.pbd`` and ``piste ssx render|view``.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from piste.errors import RenderError
from piste.render.context import check_gl_error, load_shader, set_depth_write
from piste.render.frame import TerrainRenderer
from piste.render.terrain_mode import TerrainMode

if TYPE_CHECKING:
    from piste.render.frame import Frame
    from piste.scene_data import Camera
    from piste.terrain.resident import ResidentMesh
    from piste.terrain.tessellate import TerrainMesh

__all__ = ["SourcePass", "SsxTerrainRenderer", "SourceMode"]


class SourcePass:
    """Draws a terrain mesh with an SSX light-map source atlas ``(Cs, As)`` (see the module)."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.prog = ctx.program(vertex_shader=load_shader("ssx_source.vert.glsl"),
                                fragment_shader=load_shader("ssx_source.frag.glsl"))
        self.prog["u_source"].value = 0
        self.source = None
        self.overbright = False
        self._bufs = []
        self._vao = None
        self._n = 0

    def set_source(self, image: np.ndarray) -> None:
        """Use ``(h, w, 4) uint8`` stored texels (RGB = Cs, A = As) laid out by the net's
        ``lightmap_rect``; sampled bilinearly, clamped."""
        import moderngl

        img = np.asarray(image)
        if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 4:
            raise RenderError(f"light-map source: expected (h, w, 4) uint8, got {img.shape} {img.dtype}")
        if self.source is not None:
            self.source.release()
        h, w = img.shape[:2]
        self.source = self.ctx.texture((w, h), 4, np.ascontiguousarray(img).tobytes(), alignment=1)
        self.source.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.source.repeat_x = self.source.repeat_y = False
        self.overbright = bool((img[..., 3] > 128).any())

    def upload(self, mesh: TerrainMesh) -> None:
        """Upload a terrain mesh's positions, light-map UVs and indices; an empty mesh (nothing in
        view: the camera sees only sky) uploads nothing and :meth:`draw` then draws nothing (GL
        buffers cannot be empty)."""
        self._release_geometry()
        n = int(np.asarray(mesh.indices).size)
        if n == 0 or len(np.asarray(mesh.positions)) == 0:
            return
        pos = self.ctx.buffer(np.ascontiguousarray(mesh.positions, dtype=np.float32).tobytes())
        uvl = self.ctx.buffer(np.ascontiguousarray(mesh.uv_lightmap, dtype=np.float32).tobytes())
        idx = self.ctx.buffer(np.ascontiguousarray(mesh.indices, dtype=np.uint32).tobytes())
        self._bufs = [pos, uvl, idx]
        self._vao = self.ctx.vertex_array(self.prog, [(pos, "3f", "in_pos"), (uvl, "2f", "in_uvl")], idx,
                                          index_element_size=4)
        self._n = int(np.asarray(mesh.indices).size)

    def draw(self, mvp: np.ndarray, stage: str = "blend") -> None:
        """Draw the uploaded mesh into the bound framebuffer.  ``stage``: "blend" (the GS blend,
        both stages) or "raw" (the texels, no blending)."""
        import moderngl

        if self.source is None or self._vao is None or self._n == 0:
            return
        ctx = self.ctx
        self.prog["u_mvp"].write(np.asarray(mvp, dtype=np.float32).T.tobytes())
        self.prog["u_depth_bias"].value = 2e-5
        self.source.use(0)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE)
        ctx.depth_func = "<="
        set_depth_write(ctx, False)
        try:
            if stage == "raw":
                ctx.disable(moderngl.BLEND)
                self.prog["u_stage"].value = 2
                self._vao.render(moderngl.TRIANGLES, vertices=self._n)
                return
            ctx.enable(moderngl.BLEND)
            ctx.blend_equation = (moderngl.FUNC_REVERSE_SUBTRACT, moderngl.FUNC_ADD)
            ctx.blend_func = (moderngl.SRC_ALPHA, moderngl.SRC_ALPHA, moderngl.ZERO, moderngl.ONE)
            self.prog["u_stage"].value = 0
            self._vao.render(moderngl.TRIANGLES, vertices=self._n)
            if self.overbright:
                ctx.blend_equation = moderngl.FUNC_ADD
                ctx.blend_func = (moderngl.DST_COLOR, moderngl.ONE, moderngl.ZERO, moderngl.ONE)
                self.prog["u_stage"].value = 1
                self._vao.render(moderngl.TRIANGLES, vertices=self._n)
        finally:
            ctx.blend_equation = moderngl.FUNC_ADD
            ctx.blend_func = moderngl.DEFAULT_BLENDING
            ctx.disable(moderngl.BLEND)
            set_depth_write(ctx, True)
            ctx.depth_func = "<"

    def _release_geometry(self) -> None:
        if self._vao is not None:
            self._vao.release()
            self._vao = None
        for b in self._bufs:
            b.release()
        self._bufs = []

    def release(self) -> None:
        self._release_geometry()
        if self.source is not None:
            self.source.release()
            self.source = None
        self.prog.release()


class SsxTerrainRenderer(TerrainRenderer):
    """A :class:`TerrainRenderer` whose ``ps2`` mode blends an SSX level's stored light-map texels
    (``source (h, w, 4) uint8``: RGB = Cs, A = As, laid out by the net's ``lightmap_rect``) over the
    base texture with :class:`SourcePass`, as the GS does; every other mode is the terrain
    renderer's own.  The runtime's terrain renderer for an SSX level (``piste render|view LEVEL.pbd``,
    ``piste ssx render|view``) and for scene files with an ``ssx_pbd`` terrain (bundle member
    ``lightmap/source``; :func:`piste.pipeline.preview.terrain_renderer`)."""

    def __init__(self, net, source, **kwargs):
        super().__init__(net, **kwargs)
        self.ssx_source = SourcePass(self.ctx)
        self.ssx_source.set_source(source)

    def render(self, camera: Camera, lod: bool = True, lightmap_mode: str = "modulate", debug: str | None = None,
               read: bool = True, levels: np.ndarray | int | None = None, **kwargs: Any) -> Frame:
        mode = self.frame_mode(lightmap_mode, debug)
        if not isinstance(mode, SourceMode):  # every mode but ps2 is the terrain renderer's own
            return super().render(camera, lod=lod, lightmap_mode=lightmap_mode, debug=debug, read=read,
                                  levels=levels, **kwargs)
        cam = replace(camera, aspect=self.size[0] / self.size[1])
        mesh = self.prepare(cam, lod=lod, levels=levels) if levels is not None else mode.prepare(cam, lod=lod)
        kwargs.pop("fog", None)
        kwargs.setdefault("sync", True)
        frame = mode.draw(cam, mesh, **kwargs)
        self.ctx.finish()
        check_gl_error(self.ctx, "drawing the SSX light-map pass")
        if read:
            frame.image = self.target.read().copy()
        return frame

    def frame_mode(self, lightmap_mode: str = "modulate", debug: str | None = None) -> TerrainMode:
        """How a scene frame draws this level: :class:`SourceMode` in ``ps2`` mode without a debug
        view (the stored texels), else the terrain renderer's own pass."""
        if lightmap_mode == "ps2" and debug is None:
            return SourceMode(self, lightmap_mode, debug)
        return super().frame_mode(lightmap_mode, debug)

    def source_frame(self, camera: Camera, lod: bool = True) -> np.ndarray:
        """The stored texels under each pixel, unblended: ``(H, W, 4) uint8`` (RGB = Cs, A = As;
        background alpha 0), for checking the blend against the GS formula."""
        cam = replace(camera, aspect=self.size[0] / self.size[1])
        mesh = self.prepare(cam, lod=lod, levels=self.levels(cam, lod))
        self.draw(cam, mesh, debug="base", read=False, sky=False, clear=(0.0, 0.0, 0.0, 0.0))
        self.ssx_source.upload(mesh)
        self.target.use()
        self.ssx_source.draw(cam.view_projection(), stage="raw")
        self.ctx.finish()
        return self.target.read().copy()

    def release(self) -> None:
        self.ssx_source.release()
        super().release()


class SourceMode(TerrainMode):
    """An SSX level's ``ps2`` frame, the game's way with its stored texels: the base texture ``Cd``,
    then ``(Cd - Cs) x As`` by the renderer's :class:`SourcePass` (``ssx_source``) over the same,
    CPU-tessellated triangles (explicit levels); no fog."""

    fog = False

    def prepare(self, camera: Camera, lod: bool = True, timings: dict | None = None) -> TerrainMesh | ResidentMesh:
        return self.terrain.prepare(camera, lod=lod, levels=self.terrain.levels(camera, lod), timings=timings)

    def draw(self, camera: Camera, mesh: TerrainMesh | ResidentMesh, fog: Any = None, timings: dict | None = None,
             sync: bool = False, **kwargs: Any) -> Frame:
        """The base texture, then the stored texels blended over it (``fog`` is ignored: none);
        ``kwargs`` go to the base pass (``sky``, ``clear``)."""
        t = self.terrain
        frame = t.draw(camera, mesh, debug="base", read=False, timings=timings, sync=sync, **kwargs)
        t.ssx_source.upload(mesh)  # a CPU-tessellated TerrainMesh (explicit levels in prepare)
        t.target.use()
        t.ssx_source.draw(camera.with_aspect(*t.size).view_projection())
        return frame
