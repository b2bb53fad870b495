"""The terrain draw: GPU buffers for a TerrainMesh, base texture, light-map atlas, and the passes.

Light-map modes
---------------
``modulate``
    one pass, ``Cd x CL`` in the fragment shader (what modern GPUs do).
``ps2``
    the talk's two passes for hardware that cannot multiply by the frame buffer: the base texture
    ``Cd`` first, then ``(Cd - Cs) x As`` by blending (``FUNC_REVERSE_SUBTRACT``,
    ``SRC_ALPHA, SRC_ALPHA``; alpha kept by separate alpha blending), with
    ``As = max(CL.r, CL.g, CL.b)`` and ``Cs = Cd - Cd x CL / As``.

Debug views (``debug=``): ``base`` (Cd only), ``lightmap`` (CL only), ``lod`` (patches coloured by
kind, 4x4 / 6x6 / 8x8 / glue, over the light map, with a wireframe overlay), ``wire`` (the lit
terrain with a wireframe overlay).

Geometry
--------
``upload(mesh)`` takes a CPU-tessellated :class:`piste.terrain.TerrainMesh` (streamed every frame)
or a :class:`piste.terrain.resident.ResidentMesh`: then the patches' vertex blocks stay on the GPU
(uploaded once per net) and a frame sends only its index list and the morph factors (a float
texture), and the vertex shader geomorphs.  The first pass's fragment shader is compiled once per
mode (no run-time mode branch).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from piste.errors import ConfigError, RenderError
from piste.render.context import load_shader, set_depth_write
from piste.render.textures import LOD_COLORS, light_texels, mipmapped_texture, snow_texture, track_texels
from piste.terrain.resident import ResidentMesh

if TYPE_CHECKING:
    import moderngl

    from piste.terrain.tessellate import TerrainMesh

__all__ = ["TerrainPass", "LIGHTMAP_MODES", "DEBUG_VIEWS", "RESIDENT_FORMAT"]

LIGHTMAP_MODES = ("modulate", "ps2")
DEBUG_VIEWS = (None, "base", "lightmap", "lod", "wire")
_MODE_ID = {"modulate": 0, "base": 1, "lightmap": 2, "lod": 3, "flat": 4, "lod_wire": 5}
_MORPH_UNIT = 4
_RESIDENT_FORMAT = ("3f 3f 2f 2f 1f", "in_pos", "in_target", "in_uv", "in_uvl", "in_morph")
#: the resident vertex blocks' layout (:meth:`TerrainPass.resident_blocks`): a moderngl format and its
#: attribute names (position, morph target, base UV, light-map UV, morph slot), 44 bytes a vertex
RESIDENT_FORMAT = _RESIDENT_FORMAT


def _with_defines(source: str, **defines) -> str:
    """``source`` with ``#define NAME value`` lines after its ``#version`` line."""
    head, _, rest = source.partition("\n")
    return head + "\n" + "".join(f"#define {k} {v}\n" for k, v in defines.items()) + rest


class _Stream:
    """A GPU buffer that grows by doubling and is orphaned before every rewrite."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.buffer = None

    def write(self, data: np.ndarray) -> bool:
        """Upload ``data``; returns True when the buffer object was replaced (VAOs must be rebuilt)."""
        nbytes = data.nbytes
        if self.buffer is None or self.buffer.size < nbytes:
            cap = max(nbytes, 4096, int(self.buffer.size * 2) if self.buffer is not None else 0)
            if self.buffer is not None:
                self.buffer.release()
            self.buffer = self.ctx.buffer(reserve=cap, dynamic=True)
            self.buffer.write(np.ascontiguousarray(data))
            return True
        self.buffer.orphan(self.buffer.size)
        self.buffer.write(np.ascontiguousarray(data))
        return False

    def release(self) -> None:
        if self.buffer is not None:
            self.buffer.release()
            self.buffer = None


class TerrainPass:
    """Draws tessellated terrain with a base texture and a light-map atlas.

    Parameters
    ----------
    ctx : moderngl.Context
    lightmap : (H, W, 3|4) atlas, float linear light or uint8 (see :meth:`set_lightmap`;
        layout in :mod:`piste.render.textures`), or None for a 1x1 white map (unlit)
    base_texture : (N, N, 3|4) uint8 tileable base texture, default :func:`snow_texture`
    """

    def __init__(self, ctx, lightmap=None, base_texture=None):
        self.ctx = ctx
        self._vs = load_shader("terrain.vert.glsl")
        self._fs = load_shader("terrain.frag.glsl")
        # (mode id, track on) -> the first pass compiled for that mode, with or without the groomed
        # track (a run-time ``u_track_on`` branch cost ~20 % of the draw on terrain without a track);
        # ("ps2", track) the PS2 second pass, ("fog", 0) its fog pass; each compiled on first use
        self._programs: dict = {}
        # back-facing triangles skipped (not in the debug views): seen from above the surface, the first
        # surface a view ray meets is its upper (front) side, so only silhouette pixels can change
        # (llvmpipe: ~30 % of the terrain pass on the default course); False for nets with overhangs
        # seen from below
        self.cull_back = True
        # with cull_back, leave resident patches whose every triangle faces away from the eye out of the
        # index list on the CPU (normal cones: ResidentTerrain.facing; the same picture).  Off: on the
        # default course the cones prove ~300 of ~1,450 visible patches back-facing (1.4k of 18.5k
        # triangles; the GPU rejects the other 8k back faces one by one), and A/B (60 interleaved scene
        # frames, load 4.3) the terrain draw's CPU was 7.06 ms with vs 7.09 without, the upload +0.1 ms
        self.cull_back_patches = False
        # uniforms every terrain program gets (applied when a program is first used / after a change)
        cols = [LOD_COLORS[k] for k in (0, 4, 6, 8)]
        self._uniforms = {"u_base": 0, "u_light": 1, "u_track": 2, "u_track_on": 0, "u_morph": _MORPH_UNIT,
                          "u_morph_on": 0, "u_lod_colors": [tuple(c / 255.0 for c in col) for col in cols]}
        self._stamp = 0
        self._applied: dict = {}
        self.base = None
        self.light = None
        self.track = None
        self.set_base_texture(snow_texture() if base_texture is None else base_texture)
        self.set_lightmap(lightmap)
        self._streams = {k: _Stream(ctx) for k in ("pos", "uv", "uvl", "kind", "index")}
        self._vaos: dict = {}  # (program key, source) -> vertex array
        self.n_indices = 0
        self.has_kind = False
        self._source = "stream"  # or "resident"
        self._resident = None  # the ResidentTerrain whose blocks are on the GPU
        self._resident_buf = None
        self._morph_tex = None
        self._morph = False
        # a resident frame whose wholly back-facing patches were left out of the index list (culled
        # whole on the CPU: ResidentMesh.front_indices); the debug views, which draw back faces, put
        # them back (see draw)
        self._front_of = None

    @property
    def prog(self) -> moderngl.Program:
        """The modulate first-pass program (compiled on first use)."""
        return self._program(_MODE_ID["modulate"])

    @property
    def prog_ps2(self) -> moderngl.Program:
        """The PS2 scheme's second pass, ``(Cd - Cs) x As`` (compiled on first use)."""
        return self._program("ps2")

    @property
    def prog_fog(self) -> moderngl.Program:
        """The PS2 scheme's fog pass, blended over the second (compiled on first use)."""
        return self._program("fog")

    def _key(self, mode):
        return (mode, 0 if mode == "fog" else int(self._uniforms["u_track_on"]))

    def _program(self, mode):
        key = self._key(mode)
        p = self._programs.get(key)
        if p is None:
            if mode == "fog":
                fs = load_shader("fog.frag.glsl")
            elif mode == "ps2":
                fs = _with_defines(load_shader("ps2_lightmap.frag.glsl"), TERRAIN_TRACK=key[1])
            else:
                fs = _with_defines(self._fs, TERRAIN_MODE=mode, TERRAIN_TRACK=key[1])
            # (the vertex shader looks the track's distance up when the track is on: TERRAIN_TRACK)
            p = self.ctx.program(vertex_shader=_with_defines(self._vs, TERRAIN_TRACK=key[1]), fragment_shader=fs)
            self._programs[key] = p
        return self._apply(p)

    def _apply(self, p):
        """Write the shared uniforms into ``p`` if they changed since it last got them."""
        if self._applied.get(id(p)) != self._stamp:
            for name, value in self._uniforms.items():
                if name in p:
                    p[name].value = value
            self._applied[id(p)] = self._stamp
        return p

    def _set_uniforms(self, **values) -> None:
        self._uniforms.update(values)
        self._stamp += 1

    # ------------------------------------------------------------------ textures
    def _texture(self, image, name: str, mipmaps: bool = False):
        img = np.asarray(image)
        if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] not in (3, 4):
            raise RenderError(f"{name}: expected an (H, W, 3|4) uint8 image, got {img.shape} {img.dtype}")
        if img.shape[2] == 3:
            img = np.concatenate([img, np.full(img.shape[:2] + (1,), 255, np.uint8)], axis=2)
        if mipmaps:  # the levels computed on the CPU (no GPU mipmap blit to compile at start-up)
            return mipmapped_texture(self.ctx, img)
        h, w = img.shape[:2]
        return self.ctx.texture((w, h), 4, np.ascontiguousarray(img).tobytes(), alignment=1)

    def set_base_texture(self, image: np.ndarray) -> None:
        """Use ``image`` ``(N, N, 3|4) uint8`` (tileable) as the base texture, mip-mapped and repeated."""
        import moderngl

        if self.base is not None:
            self.base.release()
        self.base = self._texture(image, "base texture", mipmaps=True)
        # bilinear within the nearest mip level: trilinear (LINEAR_MIPMAP_LINEAR) costs llvmpipe ~14 %
        # of the terrain draw for a mean difference of 0.02 levels on the default course
        self.base.filter = (moderngl.LINEAR_MIPMAP_NEAREST, moderngl.LINEAR)
        self.base.repeat_x = self.base.repeat_y = True
        # anisotropic filtering triples the fill cost on llvmpipe (15 -> 42 ms a frame): off

    def set_lightmap(self, atlas: np.ndarray | None, half_bright: bool = False) -> None:
        """Use a light-map atlas (``None``: white, i.e. unlit).

        Parameters
        ----------
        atlas : (H, W, 3 or 4) float (linear light, 1.0 = full, over-bright allowed, e.g. a baked
            ``LightMap.atlas``) or uint8 (255 = 1.0, or 128 = 1.0 with ``half_bright``, the PS2's
            storage).  Rows are texture ``v`` from 0 up (no flip).
        half_bright : uint8 texels are ``round(128 c)``

        Notes
        -----
        Uploaded as a half-float texture, sampled bilinearly, clamped, without mip-maps (tiles have
        gutters; mip-maps would bleed between patches).  In ``ps2`` mode light above 1.0 survives
        the blend because :class:`~piste.render.frame.TerrainRenderer` draws ps2 frames into a
        half-float target (As up to 2.0; on an 8-bit target it would clamp at 1).
        """
        import moderngl

        if atlas is None:
            atlas = np.ones((1, 1, 3), np.float32)
        a = np.asarray(atlas)
        if a.ndim != 3 or a.shape[2] not in (3, 4) or not (a.dtype == np.uint8 or a.dtype.kind == "f"):
            raise RenderError(f"light-map atlas: expected an (H, W, 3|4) uint8 or float image, got {a.shape} {a.dtype}")
        if a.dtype == np.uint8:  # 0 .. 255/128: in the half-float range
            rgb = (a[..., :3].astype(np.float32) / (128.0 if half_bright else 255.0)).astype(np.float16)
        else:  # (a bundle's stored float16 texels as they are)
            rgb = light_texels(a)
        if self.light is not None:
            self.light.release()
        h, w = rgb.shape[:2]
        self.light = self.ctx.texture((w, h), 3, np.ascontiguousarray(rgb).tobytes(), dtype="f2", alignment=1)
        self.light.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.light.repeat_x = self.light.repeat_y = False

    def set_track(self, field: np.ndarray | None, rect: tuple[float, float, float, float] | np.ndarray,
                  half_width: float = 16.0) -> None:
        """Mark a groomed track (cooler groomed snow, dye lines on its lips) as a projected texture.

        Parameters
        ----------
        field : (H, W) float signed distance across the track in metres (see
            :func:`piste.render.textures.track_field`; uploaded as :func:`~piste.render.textures.track_texels`
            makes it), or None to remove the track
        rect : (x0, y0, x1, y1) world rectangle of the field
        half_width : metres from the centre line to the dye lines
        """
        import moderngl

        if self.track is not None:
            self.track.release()
            self.track = None
        if field is None:
            self._set_uniforms(u_track_on=0)
            return
        f = track_texels(field)  # (a bundle's stored float16 field as it is)
        if f.ndim != 2:
            raise RenderError(f"track field: expected an (H, W) array, got {f.shape}")
        h, w = f.shape
        self.track = self.ctx.texture((w, h), 1, np.ascontiguousarray(f).tobytes(), dtype="f2", alignment=1)
        self.track.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.track.repeat_x = self.track.repeat_y = False
        x0, y0, x1, y1 = (float(v) for v in rect)
        self._set_uniforms(u_track_on=1, u_track_rect=(x0, y0, 1.0 / (x1 - x0), 1.0 / (y1 - y0)),
                           u_track_half=float(half_width))

    # ------------------------------------------------------------------ geometry
    def upload(self, mesh: TerrainMesh | ResidentMesh, kinds: bool = False) -> None:
        """Upload a frame's terrain: a :class:`piste.terrain.TerrainMesh` (buffers are reused and
        orphaned) or a :class:`piste.terrain.resident.ResidentMesh` (the net's vertex blocks are
        uploaded once; each frame writes only its indices and morph factors).

        ``kinds``: also upload each vertex's patch kind (for the LOD debug view; a resident frame is
        then tessellated on the CPU for this view).
        """
        if isinstance(mesh, ResidentMesh):
            if not kinds:
                self._upload_resident(mesh)
                return
            mesh = mesh.to_mesh()
        s = self._streams
        self._source = "stream"
        self._front_of = None
        self._morph = False
        changed = s["pos"].write(np.asarray(mesh.positions, dtype=np.float32))
        changed |= s["uv"].write(np.asarray(mesh.uv, dtype=np.float32))
        changed |= s["uvl"].write(np.asarray(mesh.uv_lightmap, dtype=np.float32))
        changed |= s["index"].write(np.asarray(mesh.indices, dtype=np.uint32))
        if kinds:
            kind = np.asarray(mesh.patch_kind, dtype=np.float32)[mesh.vertex_patch]
            changed |= s["kind"].write(kind)
        if changed or (kinds and not self.has_kind):
            self._release_vaos()
        self.has_kind = kinds
        self.n_indices = int(np.asarray(mesh.indices).size)

    def _upload_resident(self, mesh: ResidentMesh) -> None:
        r = mesh.resident
        if self._resident is not r:
            if self._resident_buf is not None:
                self._resident_buf.release()
            if self._morph_tex is not None:
                self._morph_tex.release()
            # the array itself (no bytes copy of the ~13 MB blocks first: ~5 ms of a fresh process's first frame)
            self._resident_buf = self.ctx.buffer(np.ascontiguousarray(r.vertices))
            self._morph_tex = self.ctx.texture((1024, len(r.factors) // 1024), 1, dtype="f4")
            self._resident = r
            self._release_vaos()
        # with back faces culled, patches whose every triangle faces away from the frame's eye are not
        # sent at all (the GPU would drop each of their triangles after transforming its vertices)
        front = mesh.front_indices() if self.cull_back and self.cull_back_patches else mesh.indices
        self._front_of = mesh if front is not mesh.indices else None
        if self._streams["index"].write(np.asarray(front, dtype=np.uint32)):
            self._release_vaos()
        if mesh.morph:
            self._morph_tex.write(r.factors)
        self._source = "resident"
        self._morph = bool(mesh.morph)
        self.has_kind = False
        self.n_indices = int(front.size)

    def resident_blocks(self, mesh: object) -> tuple[moderngl.Buffer, moderngl.Texture | None] | None:
        """The GPU copy of ``mesh``'s vertex blocks, when ``mesh`` is the
        :class:`~piste.terrain.resident.ResidentMesh` this pass last uploaded: ``(vertex buffer, morph
        factor texture or None when the frame does not morph)``, laid out as :data:`RESIDENT_FORMAT`
        (another pass, e.g. the shadow receivers, draws the same vertices by index); else None."""
        if self._source != "resident" or not isinstance(mesh, ResidentMesh) or mesh.resident is not self._resident:
            return None
        return self._resident_buf, (self._morph_tex if mesh.morph else None)

    def _release_vaos(self) -> None:
        for vao in self._vaos.values():
            vao.release()
        self._vaos = {}

    def _vao(self, prog):
        key = (id(prog), self._source)
        vao = self._vaos.get(key)
        if vao is None:
            s = self._streams
            if self._source == "resident":
                content = [(self._resident_buf, *_RESIDENT_FORMAT)]
            else:
                content = [(s["pos"].buffer, "3f", "in_pos"), (s["uv"].buffer, "2f", "in_uv"),
                           (s["uvl"].buffer, "2f", "in_uvl")]
                if self.has_kind:
                    content.append((s["kind"].buffer, "1f", "in_kind"))
            vao = self.ctx.vertex_array(prog, content, s["index"].buffer, index_element_size=4, skip_errors=True)
            self._vaos[key] = vao
        return vao

    # ------------------------------------------------------------------ drawing
    def draw(self, mvp: np.ndarray, eye: np.ndarray, lightmap_mode: str = "modulate", debug: str | None = None,
             fog: tuple[float, float, float, float] | None = None) -> None:
        """Draw the uploaded terrain into the bound framebuffer (depth test on).

        Parameters
        ----------
        mvp : (4, 4) view-projection matrix (column vectors)
        eye : (3,) camera position (for fog)
        lightmap_mode : "modulate" or "ps2"
        debug : None, "base", "lightmap", "lod" or "wire"
        fog : None or (r, g, b, density per metre)
        """
        import moderngl

        if lightmap_mode not in LIGHTMAP_MODES:
            raise ConfigError(f"lightmap mode must be one of {', '.join(LIGHTMAP_MODES)}, got {lightmap_mode!r}")
        if debug not in DEBUG_VIEWS:
            raise ConfigError(f"debug view must be one of {', '.join(str(d) for d in DEBUG_VIEWS[1:])}, got {debug!r}")
        if debug == "lod" and not self.has_kind:
            raise RenderError("the LOD view needs the mesh uploaded with kinds=True")
        if self._front_of is not None and (debug is not None or not self.cull_back):
            full = self._front_of  # these draw back faces: every patch's triangles again
            self._front_of = None
            if self._streams["index"].write(np.asarray(full.indices, dtype=np.uint32)):
                self._release_vaos()
            self.n_indices = int(full.indices.size)
        if self.n_indices == 0:
            return
        ctx = self.ctx
        mvp_bytes = np.asarray(mvp, dtype=np.float32).T.tobytes()  # column-major for GLSL
        fog = (0.0, 0.0, 0.0, 0.0) if fog is None else tuple(float(x) for x in fog)
        eye = tuple(float(x) for x in eye)
        self.base.use(0)
        self.light.use(1)
        if self.track is not None:
            self.track.use(2)
        if self._morph:
            self._morph_tex.use(_MORPH_UNIT)
        if self._uniforms["u_morph_on"] != int(self._morph):
            self._set_uniforms(u_morph_on=int(self._morph))
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        if self.cull_back and debug is None:
            ctx.enable(moderngl.CULL_FACE)
            ctx.cull_face = "back"
        ctx.depth_func = "<"
        ps2 = lightmap_mode == "ps2" and debug in (None, "wire")
        first = {None: "modulate", "wire": "modulate", "base": "base", "lightmap": "lightmap", "lod": "lod"}[debug]
        if ps2:
            first = "base"
        p = self._program(_MODE_ID[first])
        p["u_mvp"].write(mvp_bytes)
        p["u_depth_bias"].value = 0.0
        if "u_eye" in p:
            p["u_eye"].value = eye
        if "u_fog" in p:
            p["u_fog"].value = (0.0, 0.0, 0.0, 0.0) if ps2 else fog
        self._vao(p).render(moderngl.TRIANGLES, vertices=self.n_indices)
        if ps2:
            self._draw_ps2(mvp_bytes, eye, fog)
        ctx.disable(moderngl.CULL_FACE)
        if debug in ("lod", "wire"):
            w = self._program(_MODE_ID["lod_wire"] if debug == "lod" else _MODE_ID["flat"])
            w["u_mvp"].write(mvp_bytes)
            if "u_color" in w:
                w["u_color"].value = (0.35, 0.38, 0.45)
            w["u_depth_bias"].value = 2e-4
            ctx.depth_func = "<="
            ctx.wireframe = True
            try:
                self._vao(w).render(moderngl.TRIANGLES, vertices=self.n_indices)
            finally:
                ctx.wireframe = False
                ctx.depth_func = "<"
                w["u_depth_bias"].value = 0.0

    def _draw_ps2(self, mvp_bytes: bytes, eye, fog) -> None:
        import moderngl

        ctx = self.ctx
        q = self.prog_ps2
        q["u_mvp"].write(mvp_bytes)
        q["u_depth_bias"].value = 0.0
        ctx.depth_func = "=="
        set_depth_write(ctx, False)
        ctx.enable(moderngl.BLEND)
        # colour: dst*As - src*As = (Cd - Cs) x As;  alpha: dst*1 + src*0 (destination alpha kept)
        ctx.blend_equation = (moderngl.FUNC_REVERSE_SUBTRACT, moderngl.FUNC_ADD)
        ctx.blend_func = (moderngl.SRC_ALPHA, moderngl.SRC_ALPHA, moderngl.ZERO, moderngl.ONE)
        try:
            self._vao(q).render(moderngl.TRIANGLES, vertices=self.n_indices)
            if fog[3] > 0.0:
                f = self.prog_fog
                f["u_mvp"].write(mvp_bytes)
                f["u_depth_bias"].value = 0.0
                f["u_eye"].value = eye
                f["u_fog"].value = fog
                ctx.blend_equation = moderngl.FUNC_ADD
                ctx.blend_func = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA, moderngl.ZERO, moderngl.ONE)
                self._vao(f).render(moderngl.TRIANGLES, vertices=self.n_indices)
        finally:
            ctx.blend_equation = moderngl.FUNC_ADD
            ctx.blend_func = moderngl.DEFAULT_BLENDING
            ctx.disable(moderngl.BLEND)
            set_depth_write(ctx, True)
            ctx.depth_func = "<"

    def release(self) -> None:
        self._release_vaos()
        for s in self._streams.values():
            s.release()
        for obj in (self.base, self.light, self.track, self._resident_buf, self._morph_tex, *self._programs.values()):
            if obj is not None:
                obj.release()
        self._programs = {}
        self._resident = self._resident_buf = self._morph_tex = None
