"""The riders' draw: per-vertex lit skinned characters, then a specular-map second pass.

Skinning happens on the CPU (:meth:`piste.world.scene.Scene.update`: the SSX Tricky blended
matrices, one palette per LOD, the rider's world matrix folded into each palette matrix, all riders
of a LOD in one sparse product), so this pass streams world-space positions and normals.  Why the
CPU and not palette uniforms in the vertex shader: the palettes are 51-110 matrices per rider
(llvmpipe runs vertex shaders on the same two cores anyway), the skinned low-LOD vertices are
needed on the CPU for the projected shadows, and the CPU path is the one the tests compare
against :func:`piste.character.skin`.

Lighting (``character.vert.glsl``): the talk's 1 ambient + 3 directional lights per vertex,
``ambient + C * max(D * n, 0)``, with each rider's ``D`` and ``C`` chosen at its position from the
world's lights (:func:`piste.lighting.vertex.choose_lights_many`).

Material (a glTF rider's, :func:`piste.pipeline.characters.rider_material`): alphaMode MASK
compiles the base pass with the alpha test (texels below 0.5 discarded: the cutoff is baked into the
texture's alpha); a material that is not double-sided culls back faces (counter-clockwise fronts,
glTF's winding); no material (the built-in and SSX riders): no alpha test, no culling.

Specular: Blinn-Phong highlights of the sun scaled by a specular map, added to the lit texture.
The talk draws them as a second pass over the same triangles (``character_specular.frag.glsl``:
GL_LEQUAL, no depth writes, additive blending ``(ONE, ONE)``); by default
(:attr:`CharacterPass.fold_specular`) the base pass adds them itself (``character.frag.glsl``
compiled with ``CHARACTER_SPECULAR``): the same sum on the same pixels (the nearest fragment's
colour plus its highlight, the colour clamped first as the 8-bit frame buffer clamps it), rounded
once instead of twice, without a second vertex and fragment pass over every rider (measured on
llvmpipe at 640x448: see the commit that folded it).  ``fold_specular = False`` draws the talk's
two passes.  :func:`specular_map` makes the map for the default rider: goggles (lens and strap),
board (top sheet and rails) and jacket (a duller sheen).

API
---
::

    CharacterPass(ctx, lods, texture, spec_map=None, max_riders=6, rider_atlas=True, material=None)
        ``.upload(skinned)``, ``.draw(vp, eye, lights, sun=None, fog=None, specular=True)``
    specular_map(texture) -> (H, W, 4) uint8      r = strength, g = shininess scale
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import numpy.typing as npt

from piste.character import rider as _rider
from piste.errors import RenderError
from piste.render.context import load_shader, set_depth_write
from piste.render.textures import mipmapped_texture

if TYPE_CHECKING:
    import moderngl

    from piste.character.lod import LOD
    from piste.character.model import SkinnedMesh
    from piste.lighting.lights import DirectionalLight

__all__ = ["CharacterPass", "specular_map", "rider_textures", "SHININESS", "JACKETS"]

#: jacket colours of the pack (rider i wears JACKETS[i % 6]); pants get a darker partner
JACKETS = ((214, 52, 38), (30, 120, 200), (250, 180, 30), (40, 160, 90), (150, 60, 170), (240, 240, 245))

#: Blinn-Phong exponent (scaled by 0.25 + the map's green channel)
SHININESS = 32.0


def _near(rgb: np.ndarray, colour: npt.ArrayLike, tol: int = 2) -> np.ndarray:
    """``(H, W) bool``: texels of ``rgb (H, W, 3)`` (int16/int32) within ``tol`` of ``colour (3,)`` on
    every channel, i.e. ``abs(rgb - colour).max(-1) <= tol``, one channel at a time (numpy's max
    over a last axis of 3 cost ~0.6 ms a 128 x 128 atlas, ~3 ms of a fresh process's set-up)."""
    c = [int(x) for x in np.asarray(colour).reshape(3)]
    return ((np.abs(rgb[..., 0] - c[0]) <= tol) & (np.abs(rgb[..., 1] - c[1]) <= tol)
            & (np.abs(rgb[..., 2] - c[2]) <= tol))


def specular_map(texture: npt.ArrayLike) -> np.ndarray:
    """The default rider's specular map, ``(H, W, 4) uint8`` matching its texture atlas.

    Red = specular strength: goggle lenses 1.0 and strap 0.5, the board's top sheet 0.8 and
    rails 0.9, the jacket and sleeves 0.3 (waterproof shell), everything else 0.  Green =
    shininess scale (lenses and board sharp, jacket broad).
    """
    tex = np.asarray(texture)
    h, w = tex.shape[:2]
    out = np.zeros((h, w, 4), np.uint8)
    out[..., 3] = 255
    v, u = np.mgrid[0:h, 0:w]
    uu, vv = (u + 0.5) / w, (v + 0.5) / h
    tiles = getattr(_rider, "_TILES", {})

    def tile(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if name not in tiles:
            return np.zeros((h, w), bool), uu, vv
        u0, v0, u1, v1 = tiles[name]
        m = (uu >= u0) & (uu < u1) & (vv >= v0) & (vv < v1)
        return m, (uu - u0) / (u1 - u0), (vv - v0) / (v1 - v0)

    rgb = tex[..., :3].astype(np.int16)
    for name in ("jacket", "sleeve"):
        m, _, _ = tile(name)
        out[m, 0], out[m, 1] = 77, 40
    m, lu, lv = tile("board")
    out[m, 0], out[m, 1] = 204, 200
    out[m & (np.abs(lv - 0.5) > 0.3), 0] = 230
    m, lu, lv = tile("head")
    lens = m & _near(rgb, (255, 150, 30))  # the goggle lens colour
    strap = m & (np.abs(lv - 0.74) < 0.03) & ~lens
    out[strap, 0], out[strap, 1] = 128, 120
    out[lens, 0], out[lens, 1] = 255, 255
    return out


def rider_textures(texture: npt.ArrayLike, n: int) -> list[np.ndarray]:
    """``n`` variants of a rider texture atlas ``(H, W, 4) uint8``, one jacket colour each
    (:data:`JACKETS`): the jacket and sleeve tiles' dominant colour (and its darker zip shade) is
    replaced, keeping the stripes.  Variant 0 keeps the original colours."""
    tex = np.asarray(texture)
    tiles = getattr(_rider, "_TILES", {})
    h, w = tex.shape[:2]
    v, u = np.mgrid[0:h, 0:w]
    uu, vv = (u + 0.5) / w, (v + 0.5) / h
    mask = np.zeros((h, w), bool)
    for name in ("jacket", "sleeve"):
        if name in tiles:
            u0, v0, u1, v1 = tiles[name]
            mask |= (uu >= u0) & (uu < u1) & (vv >= v0) & (vv < v1)
    out = [tex.copy()]
    if not mask.any():
        return out * n
    rgb = tex[..., :3].astype(np.int32)
    # the most common colour under the mask (the first in (r, g, b) order on a tie): one int a texel
    # (r, g, b ordered as the rows np.unique(axis=0) sorts) instead of a unique over rows (~3 ms)
    keys, counts = np.unique(rgb[mask] @ np.array([1 << 16, 1 << 8, 1]), return_counts=True)
    key = int(keys[counts.argmax()])
    base = np.array([key >> 16, (key >> 8) & 255, key & 255])
    body = mask & _near(rgb, base)
    zip_ = mask & _near(rgb, (base * 0.6).astype(np.int32))
    for i in range(1, n):
        c = np.array(JACKETS[i % len(JACKETS)])
        t = tex.copy()
        t[body, :3] = c
        t[zip_, :3] = (c * 0.6).astype(np.uint8)
        out.append(t)
    return out


class _LodBuffers:
    """GPU buffers of one LOD for up to ``n`` riders: static UVs and indices, streamed positions
    and normals."""

    def __init__(self, ctx: moderngl.Context, mesh: SkinnedMesh, n: int, progs: dict[str, Any]) -> None:
        self.ctx = ctx
        self.v = int(mesh.n_vertices)
        self.t = int(mesh.n_triangles)
        self.n = int(n)
        off = (np.arange(n, dtype=np.uint32) * self.v)[:, None, None]
        idx = (np.asarray(mesh.indices, np.uint32)[None] + off).reshape(-1)
        uv = np.tile(np.asarray(mesh.uv, np.float32), (n, 1))
        self.index = ctx.buffer(idx.tobytes())
        self.uv = ctx.buffer(uv.tobytes())
        self.pos = ctx.buffer(reserve=n * self.v * 12, dynamic=True)
        self.nrm = ctx.buffer(reserve=n * self.v * 12, dynamic=True)
        self.vaos: dict = {}
        for k, p in progs.items():
            self.vao(k, p)
        self.count = 0

    def vao(self, which: str, prog: Any) -> Any:
        """The vertex array of program ``which`` (made on first use)."""
        vao = self.vaos.get(which)
        if vao is None:
            content = [(self.pos, "3f", "in_pos"), (self.nrm, "3f", "in_nrm"), (self.uv, "2f", "in_uv")]
            vao = self.vaos[which] = self.ctx.vertex_array(prog, content, self.index, index_element_size=4,
                                                           skip_errors=True)
        return vao

    def write(self, pos: np.ndarray, nrm: np.ndarray) -> None:
        k = len(pos)
        if k > self.n:
            raise RenderError(f"character pass: {k} riders at one LOD, room for {self.n}")
        self.count = k
        if k:
            self.pos.write(np.ascontiguousarray(pos, dtype=np.float32).tobytes())
            self.nrm.write(np.ascontiguousarray(nrm, dtype=np.float32).tobytes())

    def release(self) -> None:
        for vao in self.vaos.values():
            vao.release()
        for b in (self.index, self.uv, self.pos, self.nrm):
            b.release()


class CharacterPass:
    """Draws CPU-skinned riders, lit per vertex, plus the specular-map pass.

    Parameters
    ----------
    ctx : moderngl.Context
    lods : list of :class:`piste.character.LOD` (their meshes; skinned positions arrive per frame)
    texture : (H, W, 4) uint8 the riders' texture atlas
    spec_map : (H, W, 4) uint8 (default :func:`specular_map` of ``texture``)
    max_riders : riders per LOD at most
    rider_atlas : the texture is the default rider's atlas (jacket colours per rider, its specular
        map); False for other models (one texture for all, no specular unless ``spec_map``)
    material : MaterialInfo or None (alpha mode MASK: alpha test; not double-sided: back faces culled)

    Attributes
    ----------
    fold_specular : True (default): the specular highlights added by the base pass (one pass, the
        same pixels within a rounding step); False: the talk's separate additive second pass
    """

    def __init__(self, ctx: moderngl.Context, lods: Sequence[LOD], texture: npt.ArrayLike,
                 spec_map: npt.ArrayLike | None = None, max_riders: int = 6, rider_atlas: bool = True,
                 material: Any = None) -> None:
        import moderngl

        self.ctx = ctx
        self.alpha_test = material is not None and getattr(material, "alpha_mode", "OPAQUE") in ("MASK", "BLEND")
        self.cull_back = material is not None and not getattr(material, "double_sided", False)
        vs = load_shader("character.vert.glsl")
        fs = load_shader("character.frag.glsl")
        if self.alpha_test:
            head, _, rest = fs.partition("\n")
            fs = head + "\n#define CHARACTER_ALPHA_TEST 1\n" + rest
        self._vs, self._fs = vs, fs
        self.fold_specular = True
        # the programs are compiled on first use: a frame with the specular folded in (the default)
        # draws with the lit program only (the plain base and the separate specular pass cost a fresh
        # process ~4 ms of llvmpipe compiling each, with an empty shader cache, for nothing)
        # (Any: moderngl types prog["name"] as a union of uniform, block, attribute and varying)
        self._prog_lit: Any = None  # the base pass with the specular added
        self._prog: Any = None  # the base pass without it (light_only, no sun, or specular off)
        self._prog_spec: Any = None  # the talk's separate additive specular pass (fold_specular False)
        tex = np.asarray(texture)
        if tex.dtype != np.uint8 or tex.ndim != 3 or tex.shape[2] != 4:
            raise RenderError(f"character texture: expected (H, W, 4) uint8, got {tex.shape} {tex.dtype}")
        if spec_map is not None:
            spec = np.asarray(spec_map, np.uint8)
        elif rider_atlas:
            spec = specular_map(tex)
        else:
            spec = np.zeros((4, 4, 4), np.uint8)
        self.textures = [self._tex(t) for t in (rider_textures(tex, max_riders) if rider_atlas else [tex])]
        self.texture = self.textures[0]
        self.spec = self._tex(spec)
        for t in self.textures + [self.spec]:
            t.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        self.lods = [_LodBuffers(ctx, lod.mesh, max_riders, {}) for lod in lods]  # vertex arrays: on first use
        self.riders = [np.zeros(0, np.int64) for _ in lods]

    def _tex(self, img: np.ndarray) -> moderngl.Texture:
        """A mip-mapped texture (levels computed on the CPU: no GPU mipmap blit to compile)."""
        return mipmapped_texture(self.ctx, img)

    @property
    def triangles(self) -> int:
        """Triangles drawn by the last upload (one pass)."""
        return int(sum(b.t * b.count for b in self.lods))

    def upload(self, skinned: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> None:
        """Stream this frame's skinned riders: ``skinned[l] = (rider indices (k,), positions (k, v, 3),
        normals (k, v, 3))`` per LOD ``l`` (world space; see :class:`piste.world.scene.SceneFrame`)."""
        if len(skinned) != len(self.lods):
            raise RenderError(f"character pass: {len(skinned)} LOD groups for {len(self.lods)} LODs")
        for level, (idx, pos, nrm) in enumerate(skinned):
            self.lods[level].write(pos, nrm)
            self.riders[level] = np.asarray(idx)

    def draw(self, vp: npt.ArrayLike, eye: npt.ArrayLike, lights: Any, sun: DirectionalLight | None = None,
             fog: tuple[float, float, float, float] | None = None, specular: bool = True, light_only: bool = False,
             base: bool = True) -> None:
        """Draw the uploaded riders into the bound framebuffer (depth test on).

        Parameters
        ----------
        vp : (4, 4) view-projection;  eye : (3,) camera position
        lights : VertexLights batch indexed by rider (``SceneFrame.rider_lights``)
        sun : DirectionalLight for the specular pass (None: no specular pass)
        fog : None or (r, g, b, density per metre)
        light_only : draw the per-vertex light without the texture (tests)
        base : draw the lit base pass (False: only the specular pass, over a base drawn before)
        """
        import moderngl

        ctx = self.ctx
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        if self.cull_back:  # a glTF rider of single-sided materials (restored below)
            ctx.front_face = "ccw"
            ctx.cull_face = "back"
            ctx.enable(moderngl.CULL_FACE)
        ctx.depth_func = "<"
        try:
            self._draw(ctx, vp, eye, lights, sun, fog, specular, light_only, base)
        finally:
            ctx.disable(moderngl.CULL_FACE)

    def _draw(self, ctx: moderngl.Context, vp: npt.ArrayLike, eye: npt.ArrayLike, lights: Any,
              sun: DirectionalLight | None, fog: tuple[float, float, float, float] | None, specular: bool,
              light_only: bool, base: bool) -> None:
        import moderngl

        vp_bytes = np.asarray(vp, dtype=np.float32).T.tobytes()
        fog = (0.0, 0.0, 0.0, 0.0) if fog is None else tuple(float(x) for x in fog)
        eye = tuple(float(x) for x in eye)
        shiny = specular and sun is not None and not light_only
        lit = base and shiny and self.fold_specular  # one pass: the lit texture plus the highlights
        if base:
            p = self._lit_program() if lit else self.prog
            if lit:
                self._sun_uniforms(p, sun)
                self.spec.use(1)
            p["u_mvp"].write(vp_bytes)
            p["u_eye"].value = eye
            p["u_fog"].value = fog
            p["u_mode"].value = 1 if light_only else 0
            self._draw_all("lit" if lit else "base", p, lights)
        if lit or not shiny:
            return
        q = self.prog_spec
        q["u_mvp"].write(vp_bytes)
        q["u_eye"].value = eye
        q["u_fog"].value = fog
        self._sun_uniforms(q, sun)
        self.spec.use(1)
        ctx.enable(moderngl.BLEND)
        ctx.blend_equation = moderngl.FUNC_ADD
        ctx.blend_func = (moderngl.ONE, moderngl.ONE, moderngl.ZERO, moderngl.ONE)
        ctx.depth_func = "<="
        set_depth_write(ctx, False)
        try:
            self._draw_all("spec", q, lights)
        finally:
            ctx.disable(moderngl.BLEND)
            ctx.blend_func = moderngl.DEFAULT_BLENDING
            set_depth_write(ctx, True)
            ctx.depth_func = "<"

    @property
    def prog(self) -> Any:
        """The base pass's program (the texture lit per vertex; compiled on first use)."""
        if self._prog is None:
            self._prog = self.ctx.program(vertex_shader=self._vs, fragment_shader=self._fs)
            self._prog["u_tex"].value = 0
        return self._prog

    @property
    def prog_spec(self) -> Any:
        """The separate additive specular pass's program (compiled on first use)."""
        if self._prog_spec is None:
            self._prog_spec = self.ctx.program(vertex_shader=self._vs,
                                               fragment_shader=load_shader("character_specular.frag.glsl"))
            self._prog_spec["u_spec"].value = 1
        return self._prog_spec

    def _lit_program(self) -> Any:
        """The base pass compiled with the specular term (``CHARACTER_SPECULAR``)."""
        if self._prog_lit is None:
            head, _, rest = self._fs.partition("\n")
            p = cast(Any, self.ctx.program(vertex_shader=self._vs,
                                           fragment_shader=head + "\n#define CHARACTER_SPECULAR 1\n" + rest))
            p["u_tex"].value = 0
            p["u_spec"].value = 1
            self._prog_lit = p
        return self._prog_lit

    @staticmethod
    def _sun_uniforms(prog: Any, sun: DirectionalLight) -> None:
        prog["u_sun_dir"].value = tuple(float(-x) for x in sun.direction)
        prog["u_sun_color"].value = tuple(float(sun.intensity * c) for c in sun.color)
        prog["u_shininess"].value = SHININESS

    def _draw_all(self, which: str, prog: Any, lights: Any) -> None:
        import moderngl

        for buf, idx in zip(self.lods, self.riders):
            vao = buf.vao(which, prog)
            n = 3 * buf.t
            for j, r in enumerate(idx):
                if which != "spec":
                    self.textures[int(r) % len(self.textures)].use(0)
                u = lights[int(r)].uniforms()
                if "u_light_dir" in prog:
                    prog["u_light_dir"].write(u["u_light_dir"])
                    prog["u_light_color"].write(u["u_light_color"])
                    prog["u_ambient"].value = u["u_ambient"]
                vao.render(moderngl.TRIANGLES, vertices=n, first=j * n)

    def release(self) -> None:
        for b in self.lods:
            b.release()
        for obj in self.textures + [self.spec]:
            obj.release()
        for prog in (self._prog, self._prog_spec, self._prog_lit):
            if prog is not None:
                prog.release()
