"""The objects' draw: compressed vertex formats decoded in the vertex shader, object matrices with
(non-uniform) scale, per-vertex lighting.

Per object kind one static vertex array: positions 3 x uint16, UVs 2 x uint16, octahedral normals
2 x int8 (or int16), uint16 indices (:class:`piste.world.objects.CompressedMesh`); the shader
(``object.vert.glsl``) decodes them with the kind's offset / extent uniforms.  Instances are drawn
with one instanced draw per kind; each visible instance is one row of 16 RGBA32F texels in an
instance-data texture (object matrix, inverse-transpose normal matrix, its 1 + 3 light matrices),
rebuilt per frame from rows computed once (:func:`instance_rows`).

Transparency (glTF alphaMode BLEND, the kinds in ``objects.blend``): drawn after the opaque and
MASK kinds in a second pass of programs that write the texel's alpha, with depth test on, depth
write off and ``SRC_ALPHA, ONE_MINUS_SRC_ALPHA`` blending; each frame the visible blended instances
are sorted back to front by the distance of their bounding-sphere centres to the eye (one numpy
argsort) and drawn in that order, one instanced draw per run of one kind (the triangles within one
instance are not sorted).

Levels of detail (:mod:`piste.world.object_lod`): every kind has a chain of index lists over its one
set of vertices; each frame a visible instance takes the coarsest level whose simplification error,
projected at its distance, stays under ``lod_pixels`` (default one pixel), and each (kind, level)
is one instanced draw.  ``lod_pixels=0`` draws every instance in full.

Lighting modes (``mode``): ``dynamic`` (the talk's SSX objects: 1 ambient + 3 directional chosen
per object), ``baked`` (pre-calculated RGBs per instance vertex, half-bright RGB8, from
:func:`piste.world.objects.bake_vertex_colors`), ``points`` (every world light evaluated per
vertex: dynamic point and spot lights with attenuation and cone).

API
---
ObjectPass(ctx, objects, lights, mode="dynamic", lod_pixels=1.0)   ``.draw(vp, eye, visible, fog=None, mode=None)``,
``.add_group(key, kind, matrix, colors=None)``, ``.remove_group(key)`` (instances that come and go)

instance_rows(objects) -> (n, 16, 4) float32
light_uniforms(lights) -> dict of the ``points`` mode's uniform arrays
ObjectGroups(meshes, kinds, texture=None, blend=(), world_lights=None)   an ObjectSet of instance groups

Instance groups (a tiled world's objects, paged in and out with their tiles): an
:class:`ObjectGroups` is an :class:`~piste.world.objects.ObjectSet` whose instances are the
concatenation of groups added and removed by key (``.add(key, kind, matrix, colors=None)``,
``.remove(key)``, many at once: ``.change(add={key: (kind, matrix)}, remove=keys)``), changed in
place (whoever holds the set, e.g. a scene culling it, sees the same instances as the pass) with a
``version`` that counts the changes.  A pass drawing one follows it
before each draw: only a new group's instance rows are computed (meshes, LOD chains, programs and
the atlas stay; instance buffers grow by doubling); baked vertex colours are kept per group (given,
or baked for that group on first use).  ``ObjectPass.add_group`` / ``remove_group`` turn a pass's
plain set into groups (its own instances the group ``None``).
"""

from __future__ import annotations

from collections.abc import Hashable, Iterable, Mapping
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from piste.errors import ConfigError, RenderError
from piste.lighting.lights import DirectionalLight, SpotLight
from piste.render.context import load_shader
from piste.render.textures import mipmapped_texture
from piste.lighting.vertex import VertexLights, choose_lights_many
from piste.world.object_lod import DEFAULT_LOD_PIXELS, choose_lods, instance_scale, object_lods
from piste.world.objects import ObjectSet, bake_vertex_colors, normal_matrix

if TYPE_CHECKING:
    import moderngl

    from piste.lighting.lights import Lights

__all__ = ["ObjectPass", "ObjectGroups", "instance_rows", "light_uniforms", "MAX_POINT_LIGHTS"]

MAX_POINT_LIGHTS = 12
_MODES = {"dynamic": 0, "baked": 1, "points": 2}


def _with_defines(source: str, **defines) -> str:
    """``source`` with ``#define NAME value`` lines after its ``#version`` line."""
    head, _, rest = source.partition("\n")
    return head + "\n" + "".join(f"#define {k} {v}\n" for k, v in defines.items()) + rest


_INSTANCE_BYTES = 13 * 16  # one instance's packed attributes (see _pack_rows)


def _pack_rows(rows: np.ndarray) -> np.ndarray:
    """:func:`instance_rows` ``(n, 16, 4)`` as the per-instance attributes ``(n, 13, 4) float32``:
    texels 0-12, with texel 13 (ambient, baked row) in the ``.w`` of texels 4-7 (unused there)."""
    out = np.ascontiguousarray(rows[:, :13, :], dtype=np.float32).copy()
    out[:, 4:8, 3] = rows[:, 13, :]
    return out


def instance_rows(objects: ObjectSet) -> np.ndarray:
    """Per-instance shader data ``(n, 16, 4) float32``: texels 0-3 the object matrix's columns,
    4-6 the normal matrix's columns, 7-9 the light-direction matrix's rows, 10-12 the
    light-colour matrix's columns, 13 the ambient colour with the instance's index within its
    kind in ``.w`` (its row in the baked-colour texture)."""
    n = len(objects)
    rows = np.zeros((n, 16, 4), np.float32)
    rows[:, 0:4, :] = np.swapaxes(objects.matrix, 1, 2)  # columns
    rows[:, 4:7, :3] = np.swapaxes(objects.normal_matrix, 1, 2)
    vl = objects.lights
    if vl is not None:
        rows[:, 7:10, :3] = vl.directions  # rows
        rows[:, 10:13, :3] = np.swapaxes(vl.colors, 1, 2)  # columns
        rows[:, 13, :3] = vl.ambient
    local = np.zeros(n)
    for k in range(len(objects.kinds)):
        idx = np.nonzero(objects.kind == k)[0]
        local[idx] = np.arange(len(idx))
    rows[:, 13, 3] = local
    return rows


def light_uniforms(lights: Lights) -> dict:
    """The ``points`` mode's uniforms from a :class:`piste.lighting.Lights`: every direct light
    (at most :data:`MAX_POINT_LIGHTS`) as position/type, direction/range, colour/falloff and cone."""
    direct = lights.direct
    if len(direct) > MAX_POINT_LIGHTS:
        raise ConfigError(f"object lighting 'points': at most {MAX_POINT_LIGHTS} direct lights, the world has {len(direct)}")
    pos = np.zeros((MAX_POINT_LIGHTS, 4), np.float32)
    dirs = np.zeros((MAX_POINT_LIGHTS, 4), np.float32)
    col = np.zeros((MAX_POINT_LIGHTS, 4), np.float32)
    cone = np.zeros((MAX_POINT_LIGHTS, 4), np.float32)
    for i, light in enumerate(direct):
        col[i, :3] = light.intensity * np.asarray(light.color)
        if isinstance(light, DirectionalLight):
            pos[i] = (*(-np.asarray(light.direction)), 0.0)
            continue
        pos[i] = (*light.position, 2.0 if isinstance(light, SpotLight) else 1.0)
        dirs[i, 3] = light.range if np.isfinite(light.range) else 0.0
        col[i, 3] = light.falloff
        if isinstance(light, SpotLight):
            dirs[i, :3] = light.direction
            cone[i, :2] = (np.cos(np.radians(light.outer_angle)), np.cos(np.radians(light.inner_angle)))
    return {"u_n_lights": len(direct), "u_lpos": pos, "u_ldir": dirs, "u_lcol": col, "u_lcone": cone,
            "u_world_ambient": tuple(float(x) for x in lights.ambient_color())}


def _concat_lights(parts) -> VertexLights | None:
    """The vertex lights of ``parts`` (ObjectSets) one after another (a part without: zero slots)."""
    if all(p.lights is None for p in parts):
        return None
    d, c, a = [], [], []
    for p in parts:
        n = len(p)
        vl = p.lights
        d.append(np.zeros((n, 3, 3), np.float32) if vl is None else vl.directions.reshape(n, 3, 3))
        c.append(np.zeros((n, 3, 3), np.float32) if vl is None else vl.colors.reshape(n, 3, 3))
        a.append(np.zeros((n, 3), np.float32) if vl is None else vl.ambient.reshape(n, 3))
    return VertexLights(np.concatenate(d), np.concatenate(c), np.concatenate(a))


class ObjectGroups(ObjectSet):
    """An :class:`~piste.world.objects.ObjectSet` made of instance groups added and removed by key
    (see the module docstring): its instance arrays are the groups' in the order they were added.

    Parameters
    ----------
    meshes, kinds, texture, blend : as an ObjectSet's (shared by every group)
    world_lights : the world's :class:`piste.lighting.Lights` each instance's vertex lights are
        chosen from (None: none)

    Attributes
    ----------
    groups : ``{key: ObjectSet}`` the groups, in order
    colors : ``{key: {kind: (k, v, 3) uint8} or None}`` their baked vertex colours
    version : changes made so far
    on_visible : a callable ``(planes, eye)`` run first by :meth:`visible` (e.g. a streamed
        terrain paging the groups for that view), or None
    """

    def __init__(self, meshes, kinds, texture=None, blend=(), world_lights=None):
        kinds = tuple(kinds)
        super().__init__(dict(meshes), kinds, np.zeros(0, np.int64), np.zeros((0, 4, 4)), np.zeros((0, 3, 3)),
                         np.zeros((0, 3)), np.zeros(0), None, texture, {k: 0 for k in kinds}, tuple(blend))
        self.world_lights = world_lights
        self.groups: dict = {}
        self.colors: dict = {}
        self.version = 0
        self.on_visible = None
        # the mesh-space bounding-sphere centres and radii (a group's spheres from its matrices)
        self._mesh_center = np.stack([np.asarray(meshes[k].pos_offset, np.float64)
                                      + np.asarray(meshes[k].pos_extent, np.float64) / 2.0 for k in kinds])
        self._mesh_radius = np.array([float(meshes[k].radius) for k in kinds])

    @classmethod
    def of(cls, objects: ObjectSet, colors: Mapping[str, np.ndarray] | None = None,
           world_lights: Lights | None = None) -> "ObjectGroups":
        """``objects`` (an ObjectSet) as the group ``None`` of a new set (its ``colors``, if any)."""
        g = cls(objects.meshes, objects.kinds, objects.texture, objects.blend, world_lights)
        g.groups[None] = objects
        g.colors[None] = None if colors is None else {k: np.asarray(c) for k, c in colors.items()}
        g._concat()
        return g

    def part(self, kind: npt.ArrayLike, matrix: npt.ArrayLike) -> ObjectSet:
        """The ObjectSet of instances ``kind (k,) int64`` (into :attr:`kinds`) and ``matrix (k, 4, 4)``
        object -> world: bounding spheres, normal matrices and vertex lights (from
        :attr:`world_lights`) computed for them alone (RenderError: bad shapes or kinds)."""
        kind = np.asarray(kind).reshape(-1)
        matrix = np.asarray(matrix, dtype=np.float64)
        if kind.dtype.kind not in "iu" or matrix.shape != (len(kind), 4, 4) or not np.isfinite(matrix).all():
            raise RenderError(f"object group: expected kind (k,) integers and finite matrix (k, 4, 4), got "
                              f"{kind.shape} {kind.dtype} and {matrix.shape}")
        if len(kind) and (kind.min() < 0 or kind.max() >= len(self.kinds)):
            raise RenderError(f"object group: kinds must index {self.kinds}, got {int(kind.min())}..{int(kind.max())}")
        kind = kind.astype(np.int64)
        center = np.einsum("nij,nj->ni", matrix[:, :3, :3], self._mesh_center[kind]) + matrix[:, :3, 3]
        radius = self._mesh_radius[kind] * np.linalg.norm(matrix[:, :3, :3], axis=1).max(axis=1) if len(kind) \
            else np.zeros(0)
        wl = self.world_lights
        vl = choose_lights_many(wl, center) if wl is not None and len(kind) and (len(wl.direct) or len(wl.ambient)) \
            else None
        counts = {k: int(np.count_nonzero(kind == i)) for i, k in enumerate(self.kinds)}
        return ObjectSet(self.meshes, self.kinds, kind, matrix, normal_matrix(matrix), center, radius, vl,
                         self.texture, counts, self.blend)

    def add(self, key: Hashable, kind: npt.ArrayLike, matrix: npt.ArrayLike,
            colors: Mapping[str, np.ndarray] | None = None) -> ObjectSet:
        """Add (or replace) group ``key``: instances ``kind (k,)``, ``matrix (k, 4, 4)`` (:meth:`part`),
        their baked vertex colours ``{kind: (k_kind, v, 3) uint8}`` or None (baked when drawn)."""
        part = self.part(kind, matrix)
        if colors is not None:
            colors = {k: np.asarray(c) for k, c in colors.items()}
            for name in self.kinds:
                want = (part.counts[name], len(self.meshes[name].positions), 3)
                c = colors.get(name)
                if c is None or c.shape != want or c.dtype != np.uint8:
                    raise RenderError(f"object group {key!r}: baked colours of {name!r}: expected {want} uint8, got "
                                      f"{None if c is None else (c.shape, str(c.dtype))}")
        self.groups.pop(key, None)
        self.groups[key] = part
        self.colors[key] = colors
        self._concat()
        return part

    def remove(self, key: Hashable) -> bool:
        """Drop group ``key`` (True if it was there)."""
        if key not in self.groups:
            return False
        del self.groups[key]
        self.colors.pop(key, None)
        self._concat()
        return True

    def change(self, add: Mapping[Hashable, tuple[npt.ArrayLike, npt.ArrayLike]] | None = None,
               remove: Iterable[Hashable] = ()) -> int:
        """Drop the groups ``remove`` (keys; absent ones ignored), then add (or replace) ``add``
        ``{key: (kind, matrix)}`` (:meth:`add`, colours baked when drawn), the set's arrays
        concatenated once (many tiles paging in at once); the number of groups changed."""
        gone = [k for k in remove if k in self.groups]
        parts = {key: self.part(kind, matrix) for key, (kind, matrix) in (add or {}).items()}
        if not gone and not parts:
            return 0
        for k in gone:
            del self.groups[k]
            self.colors.pop(k, None)
        for key, part in parts.items():
            self.groups.pop(key, None)
            self.groups[key] = part
            self.colors[key] = None
        self._concat()
        return len(gone) + len(parts)

    def slices(self) -> dict:
        """``{key: slice}`` each group's instances in the set."""
        out, a = {}, 0
        for key, p in self.groups.items():
            out[key] = slice(a, a + len(p))
            a += len(p)
        return out

    def _concat(self) -> None:
        parts = list(self.groups.values())
        if parts:
            self.kind = np.concatenate([p.kind for p in parts]).astype(np.int64)
            self.matrix = np.concatenate([p.matrix for p in parts])
            self.normal_matrix = np.concatenate([p.normal_matrix for p in parts])
            self.center = np.concatenate([p.center for p in parts])
            self.radius = np.concatenate([p.radius for p in parts])
        else:
            self.kind, self.matrix, self.normal_matrix = np.zeros(0, np.int64), np.zeros((0, 4, 4)), np.zeros((0, 3, 3))
            self.center, self.radius = np.zeros((0, 3)), np.zeros(0)
        self.lights = _concat_lights(parts)
        self.counts = {k: int(np.count_nonzero(self.kind == i)) for i, k in enumerate(self.kinds)}
        self.version += 1

    def visible(self, planes: np.ndarray, max_distance: float | None = None, eye: npt.ArrayLike | None = None) -> np.ndarray:
        """As :meth:`ObjectSet.visible`, after :attr:`on_visible` (which may change the groups)."""
        if self.on_visible is not None:
            self.on_visible(np.asarray(planes, dtype=np.float64), eye)
        return super().visible(planes, max_distance=max_distance, eye=eye)


class ObjectPass:
    """Draws an :class:`piste.world.objects.ObjectSet`.

    Parameters
    ----------
    ctx : moderngl.Context
    objects : ObjectSet (its ``lights`` are the dynamic mode's light sets)
    lights : the world's Lights (baked and points modes)
    mode : "dynamic" | "baked" | "points" (default for :meth:`draw`)
    colors : the baked mode's pre-calculated RGBs ``{kind: (k, v, 3) uint8}`` half-bright (e.g. a
        bundle's ``vertex_colors()``; default: baked from ``lights`` on first use), see
        :meth:`set_vertex_colors`
    lod_pixels : the projected simplification error an instance may show (pixels); 0 draws every
        instance with its full mesh (:attr:`lod_pixels` may be changed between frames)
    """

    def __init__(self, ctx, objects, lights=None, mode: str = "dynamic", colors=None,
                 lod_pixels: float = DEFAULT_LOD_PIXELS):
        import moderngl

        if mode not in _MODES:
            raise ConfigError(f"object lighting must be one of {', '.join(_MODES)}, got {mode!r}")
        self.ctx = ctx
        self.objects = objects
        self.lights = lights
        self.mode = mode
        self._vs, self._fs = load_shader("object.vert.glsl"), load_shader("object.frag.glsl")
        tex = objects.texture
        # the alpha test can discard only when some texel is below the cutoff (a filtered sample is a
        # weighted mean of texels): without such texels the shader is compiled without it
        self.alpha_test = bool(tex.ndim == 3 and tex.shape[2] == 4 and (np.asarray(tex)[..., 3] < 128).any())
        # True: a program compiled per (lighting mode, light_only) with constants instead of the
        # run-time if-chains (the same pictures); False: the one program with uniforms (benchmarks' A/B)
        self.specialised = True
        self._programs: dict = {}  # key -> (program, {kind index: vertex array}), each compiled on first use
        self.texture = mipmapped_texture(ctx, tex)  # levels computed on the CPU: no GPU mipmap blit to compile
        self.texture.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        self.rows = instance_rows(objects)
        self.packed = _pack_rows(self.rows)
        n = max(len(objects), 1)
        self.inst = ctx.texture((16, n), 4, dtype="f4")
        self.inst.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.lod_pixels = float(lod_pixels)
        self.kinds = []
        for k, name in enumerate(objects.kinds):
            m = objects.meshes[name]
            lods = m.lods or object_lods(m.decode()[0], m.indices)  # (a bundle's mesh: the chain stored with it)
            # every level's indices in one buffer, level after level (drawn with ``first``)
            idx = np.concatenate([lv.indices.reshape(-1) for lv in lods]).astype(m.indices.dtype)
            sizes = [lv.indices.size for lv in lods]
            buf = [ctx.buffer(np.ascontiguousarray(m.positions).tobytes()),
                   ctx.buffer(np.ascontiguousarray(m.uv).tobytes()),
                   ctx.buffer(np.ascontiguousarray(m.normals).tobytes()),
                   ctx.buffer(np.ascontiguousarray(idx).tobytes())]
            count = max(int(np.count_nonzero(objects.kind == k)), 1)
            self.kinds.append({"mesh": m, "buffers": buf, "baked": None, "lods": lods,
                               "first": np.cumsum([0] + sizes[:-1]).tolist(), "sizes": sizes,
                               "instances": [ctx.buffer(reserve=count * _INSTANCE_BYTES) for _ in lods]})
        n_levels = max((len(info["lods"]) for info in self.kinds), default=1)
        self.lod_errors = np.full((max(len(self.kinds), 1), n_levels), np.inf)  # (kinds, levels), inf: none
        for k, info in enumerate(self.kinds):
            self.lod_errors[k, :len(info["lods"])] = [lv.error for lv in info["lods"]]
        self.scale = instance_scale(objects.matrix) if len(objects) else np.zeros(0)
        self.lod_counts = np.zeros(n_levels, np.int64)  # instances drawn at each level last frame
        self._points = None
        self.colors = None
        self._version = None  # the grouped set's version the instance arrays follow (ObjectGroups)
        self._part_rows: dict = {}  # group key -> (its ObjectSet, its instance rows)
        self._part_baked: dict = {}  # group key -> (its ObjectSet, its colours baked here)
        self._follow()
        if colors is not None:
            self.set_vertex_colors(colors)
        self.drawn = 0
        self.triangles = 0

    @property
    def prog(self) -> moderngl.Program:
        """The generic program (run-time uniforms; drawn with when :attr:`specialised` is False),
        compiled on first use: a specialised frame never uses it (~4 ms of llvmpipe compiling in a
        fresh process with an empty shader cache)."""
        return self._program(None)[0]

    def _program(self, key, blend: bool = False):
        """``(program, vertex arrays by kind)`` for ``key = (mode id, light_only)`` (None: the
        generic program) and the blend pass or not, compiled on first use."""
        got = self._programs.get((key, blend))
        if got is None:
            frag = {"OBJECT_ALPHA_TEST": 0, "OBJECT_BLEND": 1} if blend else {}
            if key is None:
                vs, fs = self._vs, _with_defines(self._fs, **frag) if frag else self._fs
            else:
                vs = _with_defines(self._vs, OBJECT_MODE=key[0], OBJECT_INSTANCE_ATTRIBS=1)
                fs = _with_defines(self._fs, OBJECT_MODE_FRAG=int(key[1]),
                                   **(frag or {"OBJECT_ALPHA_TEST": int(self.alpha_test)}))
            prog = self.ctx.program(vertex_shader=vs, fragment_shader=fs)
            for name, unit in (("u_tex", 0), ("u_inst", 1), ("u_baked", 2)):
                if name in prog:
                    prog[name].value = unit
            got = self._programs[(key, blend)] = (prog, {})
        return got

    def _vao(self, key, k: int, blend: bool = False, level: int = 0):
        prog, vaos = self._program(key, blend)
        vao = vaos.get((k, level))
        if vao is None:
            info = self.kinds[k]
            m, buf = info["mesh"], info["buffers"]
            nfmt = "2i1" if m.normal_bits == 8 else "2i2"
            # only the attributes this program uses (a specialised one may drop the uv or the normal)
            content = [(b, fmt, name) for b, fmt, name in
                       ((buf[0], "3u2", "in_pos"), (buf[1], "2u2", "in_uv"), (buf[2], nfmt, "in_nrm")) if name in prog]
            if key is not None:  # per-instance attributes from this kind's instance buffer (unused ones skipped)
                names = [f"in_i{j}" for j in range(13) if f"in_i{j}" in prog]
                fmt = " ".join("4f" if f"in_i{j}" in prog else "16x" for j in range(13)) + "/i"
                content.append((info["instances"][level], fmt, *names))
            vao = vaos[(k, level)] = self.ctx.vertex_array(prog, content, buf[3], index_element_size=m.indices.itemsize)
        return vao

    def set_vertex_colors(self, colors: Mapping[str, np.ndarray]) -> None:
        """Use pre-calculated RGBs for the baked mode: ``{kind: (k, v, 3) uint8}`` half-bright, the
        instances of each kind in the order of ``objects.instances(kind)`` (what
        :func:`piste.world.objects.bake_vertex_colors` returns and a bundle stores)."""
        colors = {k: np.asarray(c) for k, c in colors.items()}
        self._follow()
        for name in self.objects.kinds:
            c = colors.get(name)
            want = (len(self.objects.instances(name)), len(self.objects.meshes[name].positions), 3)
            if c is None or c.shape != want or c.dtype != np.uint8:
                got = None if c is None else f"{c.shape} {c.dtype}"
                raise RenderError(f"baked colours of {name!r}: expected {want} uint8, got {got}")
        if isinstance(self.objects, ObjectGroups):  # each group's share, in the set's order
            start = dict.fromkeys(colors, 0)
            for key, part in self.objects.groups.items():
                self.objects.colors[key] = {k: colors[k][start[k]:start[k] + part.counts[k]] for k in self.objects.kinds}
                for k in self.objects.kinds:
                    start[k] += part.counts[k]
        self.colors = colors
        for info in self.kinds:
            if info["baked"] is not None:
                info["baked"].release()
                info["baked"] = None

    def _baked_textures(self):
        if isinstance(self.objects, ObjectGroups):
            baked = self._group_colors()
        elif self.colors is not None:
            baked = self.colors
        elif self.lights is None:
            raise RenderError("object lighting 'baked' needs the world's lights")
        else:
            baked = bake_vertex_colors(self.objects, self.lights)
        for k, name in enumerate(self.objects.kinds):
            c = baked[name]  # (k, v, 3)
            kk, v = max(c.shape[0], 1), c.shape[1]
            img = np.zeros((kk, v, 4), np.uint8)
            img[: c.shape[0], :, :3] = c
            img[..., 3] = 255
            t = self.ctx.texture((v, kk), 4, np.ascontiguousarray(img).tobytes(), alignment=1)
            import moderngl

            t.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self.kinds[k]["baked"] = t

    def draw(self, vp: np.ndarray, eye: np.ndarray, visible: np.ndarray | None = None,
             fog: tuple[float, float, float, float] | None = None, mode: str | None = None, light_only: bool = False) -> None:
        """Draw the ``visible (k,)`` instances (default: all) into the bound framebuffer.

        ``mode`` overrides the lighting mode; ``light_only`` draws the light without the texture."""
        import moderngl

        mode = self.mode if mode is None else mode
        if mode not in _MODES:
            raise ConfigError(f"object lighting must be one of {', '.join(_MODES)}, got {mode!r}")
        self._follow()
        objs = self.objects
        vis = np.arange(len(objs)) if visible is None else np.asarray(visible, dtype=np.int64)
        self.drawn = 0
        self.triangles = 0
        if len(vis) == 0:
            return
        blend_kind = np.array([name in objs.blend for name in objs.kinds], dtype=bool)
        is_blend = blend_kind[objs.kind[vis]]
        # each instance's level of detail (0: the full mesh), by its projected error
        level = np.zeros(len(objs), np.int64)
        level[vis] = choose_lods(self.lod_errors[objs.kind[vis]], objs.center[vis], objs.radius[vis], self.scale[vis],
                                 vp, self.ctx.viewport[3], self.lod_pixels)
        self.lod_counts = np.bincount(level[vis], minlength=self.lod_errors.shape[1])
        n_lv = self.lod_errors.shape[1]
        opaque, trans = vis[~is_blend], vis[is_blend]
        group = objs.kind * n_lv + level  # (n,) one draw per (kind, level)
        order = opaque[np.argsort(group[opaque], kind="stable")]
        if len(trans):  # back to front: farthest bounding-sphere centre first
            dist = np.linalg.norm(objs.center[trans] - np.asarray(eye, dtype=np.float64), axis=1)
            trans = trans[np.argsort(-dist, kind="stable")]
        group_of = group[order]
        key = (_MODES[mode], bool(light_only)) if self.specialised else None
        if key is None:
            rows = np.concatenate([order, trans])
            self.inst.write(np.ascontiguousarray(self.rows[rows]).tobytes(), viewport=(0, 0, 16, len(rows)))
        if mode == "points" and self._points is None:
            if self.lights is None:
                raise RenderError("object lighting 'points' needs the world's lights")
            self._points = light_uniforms(self.lights)
        if mode == "baked" and self.kinds[0]["baked"] is None:
            self._baked_textures()
        self.texture.use(0)
        self.inst.use(1)
        ctx = self.ctx
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        ctx.depth_func = "<"
        if len(order):
            p = self._uniforms(key, False, vp, eye, fog, mode, light_only)
            cuts = np.flatnonzero(np.diff(group_of)) + 1  # runs of one (kind, level)
            for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(order)]):
                k, lv = divmod(int(group_of[a]), n_lv)
                if key is not None:  # the run's rows into its (kind, level) instance buffer, used by this draw alone
                    self.kinds[k]["instances"][lv].write(np.ascontiguousarray(self.packed[order[a:b]]).tobytes())
                self._draw_kind(p, key, k, int(a), int(b - a), mode, False, lv)
        if len(trans):
            p = self._uniforms(key, True, vp, eye, fog, mode, light_only)
            ctx.enable(moderngl.BLEND)
            ctx.blend_func = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA, moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
            fbo = ctx.fbo  # (the bound framebuffer: moderngl keeps the depth mask there)
            fbo.depth_mask = False
            try:
                tg = group[trans]
                cuts = np.flatnonzero(np.diff(tg)) + 1  # runs of one (kind, level), in the sorted order
                for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(trans)]):
                    k, lv = divmod(int(tg[a]), n_lv)
                    if key is not None:  # (written between draws: GL keeps the earlier draws' data)
                        self.kinds[k]["instances"][lv].write(np.ascontiguousarray(self.packed[trans[a:b]]).tobytes())
                    self._draw_kind(p, key, k, len(order) + int(a), int(b - a), mode, True, lv)
            finally:
                fbo.depth_mask = True
                ctx.blend_func = moderngl.DEFAULT_BLENDING
                ctx.disable(moderngl.BLEND)

    # ------------------------------------------------------------------ instance groups
    def add_group(self, key: Hashable, kind: npt.ArrayLike, matrix: npt.ArrayLike,
                  colors: Mapping[str, np.ndarray] | None = None) -> None:
        """Add (or replace) the instances ``kind (k,) int64`` (into the set's kinds) with object ->
        world ``matrix (k, 4, 4)`` as group ``key``, their baked colours ``{kind: (k_kind, v, 3)
        uint8}`` or None (baked from the world's lights when the baked mode draws them); only their
        instance rows are computed (:class:`ObjectGroups`).  A plain set becomes the group None."""
        self._groups().add(key, kind, matrix, colors)
        self._follow()

    def remove_group(self, key: Hashable) -> bool:
        """Drop group ``key``'s instances (True if it was there)."""
        gone = self._groups().remove(key)
        self._follow()
        return gone

    @property
    def group_keys(self) -> list:
        """The keys of the groups drawn (a plain set: ``[None]``)."""
        return list(self.objects.groups) if isinstance(self.objects, ObjectGroups) else [None]

    def _groups(self) -> ObjectGroups:
        if not isinstance(self.objects, ObjectGroups):
            self.objects = ObjectGroups.of(self.objects, colors=self.colors, world_lights=self.lights)
        return self.objects

    def _follow(self) -> None:
        """Catch up with a grouped set's changes: the instance rows of new groups, the whole set's
        rows concatenated, instance buffers grown, baked-colour textures redone on next use."""
        objs = self.objects
        version = getattr(objs, "version", None)
        if not isinstance(objs, ObjectGroups) or version == self._version:
            return
        self._version = version
        got = {}
        for key, part in objs.groups.items():
            old = self._part_rows.get(key)
            got[key] = old if old is not None and old[0] is part else (part, instance_rows(part))
        self._part_rows = got
        self._part_baked = {k: v for k, v in self._part_baked.items() if k in got and got[k][0] is v[0]}
        rows = np.concatenate([r for _, r in got.values()]) if got else np.zeros((0, 16, 4), np.float32)
        for k in range(len(objs.kinds)):  # each instance's row in its kind's baked colours, over the whole set
            idx = np.flatnonzero(objs.kind == k)
            rows[idx, 13, 3] = np.arange(len(idx))
        self.rows, self.packed = rows, _pack_rows(rows)
        self.scale = instance_scale(objs.matrix) if len(objs) else np.zeros(0)
        import moderngl

        if len(objs) > self.inst.height:  # the generic program's instance texture
            self.inst.release()
            self.inst = self.ctx.texture((16, max(len(objs), 2 * self.inst.height)), 4, dtype="f4")
            self.inst.filter = (moderngl.NEAREST, moderngl.NEAREST)
        for k, info in enumerate(self.kinds):
            cap = info["instances"][0].size // _INSTANCE_BYTES
            count = objs.counts[objs.kinds[k]]
            if count > cap:  # grown by doubling; the vertex arrays reading the old buffers go
                for b in info["instances"]:
                    b.release()
                info["instances"] = [self.ctx.buffer(reserve=max(count, 2 * cap) * _INSTANCE_BYTES)
                                     for _ in info["lods"]]
                for _, vaos in self._programs.values():
                    for vk in [vk for vk in vaos if vk[0] == k]:
                        vaos.pop(vk).release()
            if info["baked"] is not None:
                info["baked"].release()
                info["baked"] = None
        self.colors = None  # (a grouped set's colours are its groups')

    def _group_colors(self) -> dict:
        """The baked colours of a grouped set, ``{kind: (k, v, 3) uint8}``: each group's own, or baked
        here from the world's lights (once per group)."""
        objs = self.objects
        parts = []
        for key, part in objs.groups.items():
            c = objs.colors.get(key)
            if c is None:
                old = self._part_baked.get(key)
                if old is None or old[0] is not part:
                    if self.lights is None:
                        raise RenderError("object lighting 'baked' needs the world's lights")
                    old = self._part_baked[key] = (part, bake_vertex_colors(part, self.lights))
                c = old[1]
            parts.append(c)
        return {name: np.concatenate([c[name] for c in parts]) if parts else
                np.zeros((0, len(objs.meshes[name].positions), 3), np.uint8) for name in objs.kinds}

    def _uniforms(self, key, blend, vp, eye, fog, mode, light_only):
        """The program of ``key`` (blend pass or not) with this draw's uniforms set."""
        p = self._program(key, blend)[0]
        p["u_vp"].write(np.asarray(vp, dtype=np.float32).T.tobytes())
        p["u_eye"].value = tuple(float(x) for x in eye)
        p["u_fog"].value = (0.0, 0.0, 0.0, 0.0) if fog is None else tuple(float(x) for x in fog)
        if key is None:
            p["u_mode"].value = _MODES[mode]
            p["u_mode_frag"].value = 1 if light_only else 0
        if mode == "points":
            for name, val in self._points.items():
                if name in p:
                    if isinstance(val, np.ndarray):
                        p[name].write(val.astype(np.float32).tobytes())
                    else:
                        p[name].value = val
        return p

    def _draw_kind(self, p, key, k: int, start: int, count: int, mode: str, blend: bool, level: int = 0) -> None:
        """``count`` instances of kind ``k`` at LOD ``level`` (rows ``start..`` of the instance texture
        for the generic program; the (kind, level) instance buffer for a specialised one)."""
        import moderngl

        info = self.kinds[k]
        m = info["mesh"]
        for name, value in (("u_base_row", start), ("u_pos_offset", tuple(float(x) for x in m.pos_offset)),
                            ("u_pos_extent", tuple(float(x) for x in m.pos_extent)),
                            ("u_uv_offset", tuple(float(x) for x in m.uv_offset)),
                            ("u_uv_extent", tuple(float(x) for x in m.uv_extent)),
                            ("u_nmax", float((1 << (m.normal_bits - 1)) - 1))):
            if name in p:  # (a specialised program drops what its mode does not use)
                p[name].value = value
        if mode == "baked":
            info["baked"].use(2)
        self._vao(key, k, blend, level).render(moderngl.TRIANGLES, vertices=info["sizes"][level],
                                               first=info["first"][level], instances=count)
        self.drawn += count
        self.triangles += count * info["lods"][level].n_triangles

    def release(self) -> None:
        for prog, vaos in self._programs.values():
            for vao in vaos.values():
                vao.release()
            prog.release()
        self._programs = {}
        for info in self.kinds:
            for b in info["instances"]:
                b.release()
            for b in info["buffers"]:
                b.release()
            if info["baked"] is not None:
                info["baked"].release()
        for obj in (self.texture, self.inst):
            obj.release()
