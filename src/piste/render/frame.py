"""One frame of terrain, as the talk does it: camera -> per-edge LOD -> frustum cull -> tessellate
the visible patches -> upload -> draw (sky, terrain passes) -> read back.

API
---
TerrainRenderer     owns a context, an off-screen target, the sky and terrain passes
Frame               one rendered frame: image, what was drawn, timings (ms)
summarize           the talk's statistics over many frames (a dict for ``terrain.format_stats``)
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from piste._data import DataMethods
from piste.errors import ConfigError
from piste.render.context import Offscreen, check_gl_error, create_context, flush, load_shader
from piste.render.sky_pass import HORIZON, SkyPass
from piste.render.terrain_pass import TerrainPass
from piste.render.terrain_mode import TerrainMode
from piste.render.textures import placeholder_lightmap, track_field
from piste.terrain.cull import patch_tree
from piste.terrain.lod import FLAT_ERROR, kept_patch_bounds
from piste.terrain.resident import morph_setting, resident_fits, resident_terrain
from piste.terrain.tessellate import tessellate

from piste.transforms import cull_boxes  # noqa: E402  (re-exported)

if TYPE_CHECKING:
    from piste.scene_data import Camera
    from piste.terrain.net import PatchNet
    from piste.terrain.resident import ResidentMesh
    from piste.terrain.tessellate import TerrainMesh

__all__ = ["TerrainRenderer", "Frame", "summarize", "cull_boxes", "DEFAULT_FOG_DENSITY", "scene_fog_density"]

_RESOLVE_FS = """
#version 330
uniform sampler2D u_color;
uniform sampler2D u_depth;
out vec4 f_color;
void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    f_color = clamp(texelFetch(u_color, p, 0), 0.0, 1.0);
    gl_FragDepth = texelFetch(u_depth, p, 0).r;
}
"""

#: the terrain's simplification error on screen, pixels of a 448-line frame: edges flat (2 corners) or
#: at the coarsest level where that is under it.  1 px, as the objects' levels of detail
#: (:data:`piste.world.object_lod.DEFAULT_LOD_PIXELS`): on the default scene 20 % fewer terrain
#: triangles than the terrain core's 0.5 px (:data:`piste.terrain.lod.FLAT_ERROR`), a mean pixel
#: difference under 0.01 levels and at most 0.02 % of the pixels off by more than 16 (a silhouette
#: moved by a pixel here and there; bench_frame.py's A/B)
LOD_ERROR_PX = 1.0
#: the pixels :data:`piste.terrain.lod.FLAT_ERROR` (an angle) stands for at 640 x 448
FLAT_ERROR_PX = 0.5

#: fog density per metre (about 45 % haze at 1 km)
DEFAULT_FOG_DENSITY = 6e-4
#: the scene size (xy diagonal, metres) the default density is made for: the default course
FOG_REFERENCE_SIZE = 1077.0


def scene_fog_density(net: PatchNet, density: float = DEFAULT_FOG_DENSITY) -> float:
    """Fog in units of the scene's size: ``density`` per metre for scenes up to the default
    course's size, thinner in proportion for larger ones (a 1 km-spacing DEM would otherwise be
    uniform haze: the same share of the view fogged at any scale)."""
    lo, hi = net.bounds
    diag = float(np.hypot(*(np.asarray(hi[:2], float) - np.asarray(lo[:2], float))))
    return float(density) * min(1.0, FOG_REFERENCE_SIZE / max(diag, 1e-9))


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class Frame(DataMethods):
    """One rendered frame.

    Attributes
    ----------
    image : (H, W, 4) uint8, top row first (None when not read back)
    patches : patches drawn (after culling), patches_total : patches in the net
    kind_counts : {4: n, 6: n, 8: n, 0: n (glue), -1: n (uniform at other levels)}
    triangles, vertices : drawn
    timings : ms per stage: ``lod``, ``cull``, ``tessellate``, ``upload`` (CPU), ``draw`` (GL calls +
        glFinish), ``readback``; plus ``cpu`` and ``gpu`` sums and ``total``
    """

    image: np.ndarray | None
    patches: int
    patches_total: int
    kind_counts: dict
    triangles: int
    vertices: int
    timings: dict = field(default_factory=dict)


def faces_up(net: PatchNet) -> bool:
    """Whether every patch of ``net`` faces up: the two triangles of its corner quad (the coarsest
    tessellation, drawn with the renderer's winding) have normals with z > 0.  Then, seen from
    above, the first surface a view ray meets is an upper side, and back faces can be culled
    (a patch net with flipped patches or overhangs is drawn unculled)."""
    if len(net) == 0:
        return False
    # a Bezier patch passes through its corner control points: the level-2 tessellation's vertices
    # (0, 0), (1, 0), (1, 1), (0, 1) in (u, v), triangles (0, 1, 2) and (0, 2, 3), without tessellating
    # (a fresh process's first tessellate cost ~40 ms); float32 as the tessellator writes them
    cp = net.control_points  # the corners rounded to float32 (after taking them: 1/4 of the points)
    q = np.stack([cp[:, 0, 0], cp[:, 3, 0], cp[:, 3, 3], cp[:, 0, 3]], axis=1).astype(np.float32).astype(np.float64)
    p = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])  # (2 n, 3, 3)
    a, b = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    return bool(np.all(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0] > 0.0))


class TerrainRenderer:
    """Renders a :class:`piste.terrain.PatchNet` off-screen.

    Parameters
    ----------
    net : PatchNet
    size : (W, H) pixels
    ctx : a moderngl context to share (default: a new headless EGL context)
    lightmap : "placeholder" (normals lit by a fixed sun, :func:`placeholder_lightmap`), an atlas
        ``(H, W, 3|4)`` laid out by ``net.lightmap_rect``, float linear light (e.g. a baked
        ``LightMap.atlas``) or uint8 (255 = 1.0), or None (unlit)
    base_texture : (N, N, 3|4) uint8 (default: procedural snow)
    lod_near, lod_far : per-edge LOD distance thresholds (default: the terrain core's)
    lod_error : an edge is drawn flat (its two corners) or at the coarsest level where that shows at
        most this many pixels of error in a 448-line frame (the same angle at any size; see
        :func:`piste.terrain.lod.edge_levels`' ``flat_error``; :data:`LOD_ERROR_PX`); None: levels by
        distance alone
    track : (k, 3) centre line of a groomed track to mark on the snow (projected texture), or None
    track_half_width : metres from the centre line to the track's dye lines
    track_texture : ``(field (H, W), rect (4,))``: ``track``'s projected texture as computed before
        (a bundle stores :func:`piste.render.textures.track_field` of its centre line, as float16
        :func:`~piste.render.textures.track_texels`), used instead of computing it; None: computed
    lod_morph : geomorph between LOD levels (False: the talk's exact positions, which pop); None: on
        (the runtime passes the CLI's ``--lod-morph`` or the scene file's ``[lod] morph``)
    resident : keep every patch's vertices on the GPU and send only index lists (False: tessellate
        on the CPU every frame, the talk's way; same triangles).  Nets too big for
        :data:`piste.terrain.resident.RESIDENT_BUDGET` (~46k patches) take the CPU path.

    ``ps2`` light-map mode renders into a half-float (RGBA16F) target and resolves it into the
    8-bit one (or the window) at the end of the frame: the blend's ``As`` reaches 2.0 (the PS2's
    half-bright alpha, 255 ~ 1.99) instead of clamping at 1, so over-bright light maps give the
    same picture as ``modulate`` (within 2 levels; tested on the default course).  ``modulate``
    multiplies in the shader and draws straight into the 8-bit target (the float target costs
    ~5 ms a frame at 640x448 on llvmpipe).
    """

    def __init__(self, net, size=(640, 448), ctx=None, lightmap="placeholder", base_texture=None,
                 lod_near: float | None = None, lod_far: float | None = None, track=None,
                 track_half_width: float = 16.0, lod_morph: bool | None = None, resident: bool = True,
                 lod_error: float | None = LOD_ERROR_PX, track_texture: tuple[Any, Any] | None = None):
        self.net = net
        self.lod_morph = morph_setting(lod_morph)
        self.resident = bool(resident)
        # True (default): the first frame waits for the vertex blocks, so every frame's picture is the
        # same whatever the timing; False (interactive windows): draw at once on the CPU path while
        # they build in the background
        self.resident_wait = True
        self.ctx = ctx if ctx is not None else create_context()
        self.target = Offscreen(self.ctx, size)
        if isinstance(lightmap, str):
            if lightmap != "placeholder":
                raise ConfigError(f"lightmap must be 'placeholder', an atlas image or None, got {lightmap!r}")
            lightmap = placeholder_lightmap(net)
        self.terrain = TerrainPass(self.ctx, lightmap=lightmap, base_texture=base_texture)
        # back-face culling only where it cannot cost a picture: every patch faces up
        self.terrain.cull_back = faces_up(net)
        if track is not None:  # (``track_texture``: the field and rect a bundle stores for this track)
            self.terrain.set_track(*(track_texture if track_texture is not None else track_field(track, net.bounds)),
                                   half_width=track_half_width)
        self.sky = SkyPass(self.ctx)
        self.lod_kwargs = {k: v for k, v in (("near", lod_near), ("far", lod_far)) if v is not None}
        if lod_error is None:
            self.lod_kwargs["flat_error"] = None
        else:
            if not (np.isfinite(lod_error) and lod_error > 0):
                raise ConfigError(f"lod_error must be a positive number of pixels or None, got {lod_error!r}")
            self.lod_kwargs["flat_error"] = float(lod_error) * FLAT_ERROR / FLAT_ERROR_PX
        self.bounds = kept_patch_bounds(net)  # (the same values, kept on the net: computed once a process)
        lo, hi = self.bounds
        self._centre = np.ascontiguousarray(((lo + hi) / 2.0).T)  # (3, n): boxes as centre +- half
        self._half = np.ascontiguousarray(((hi - lo) / 2.0).T)
        self.mesh = None
        self.fog_density = scene_fog_density(net)  # what fog="scene" uses
        self._hdr = None  # the half-float target of ps2 frames (made when first needed)
        self._resolve = None  # its resolve pass
        self.active = self.target  # where the current frame is drawn (see draw / resolve)
        self.visibility = None  # see set_visibility
        self.cull_stats: dict = {}
        #: ``draw(sync=False)`` flushes the terrain to the GL (see draw); False: everything issued in the
        #: frame is rasterized at its end (bench_frame.py's A/B)
        self.flush_early = True

    def start_resident(self) -> None:
        """Start building the resident vertex blocks in the background now (e.g. while the other
        passes set up); the first :meth:`prepare` with ``resident_wait`` joins it (the same blocks
        either way).  Nothing when the blocks are not used or already built."""
        if self.resident and resident_fits(self.net):
            resident_terrain(self.net, wait=False)

    def set_visibility(self, visibility: Any = None) -> None:  # a pipeline Visibility (upward import: Any)
        """Pre-computed visibility in front of frustum culling (a bundle's per-cell sets, see
        :class:`piste.pipeline.visibility.Visibility`): any object whose ``patches_at(eye)`` gives an
        ``(n,)`` bool mask of the patches seen from the eye's cell, or None (outside: keep all).
        None removes it.  After each :meth:`visible`, ``cull_stats`` holds ``frustum_patches`` and
        ``drawn_patches``."""
        self.visibility = visibility

    @property
    def size(self) -> tuple[int, int]:
        return self.target.size

    def set_lightmap(self, atlas: np.ndarray | None, half_bright: bool = False) -> None:
        """Plug in another light-map atlas (see :meth:`TerrainPass.set_lightmap`)."""
        self.terrain.set_lightmap(atlas, half_bright=half_bright)

    # ------------------------------------------------------------------ CPU side
    def levels(self, camera: Camera, lod: bool = True) -> np.ndarray | int:
        """Vertices per edge for ``camera``: ``(e,)`` int array, or the int 8 with ``lod=False``."""
        return self.net.edge_levels(camera.eye, **self.lod_kwargs) if lod else 8

    def visible(self, camera: Camera) -> np.ndarray:
        """Patches whose control-point boxes meet the view frustum, ``(p,)`` int64 ascending
        (hierarchical: :class:`piste.terrain.cull.PatchTree`, the same set as the flat test), then
        cut by the pre-computed visibility when one is set (:meth:`set_visibility`)."""
        ids = patch_tree(self.net).cull(camera.frustum_planes())
        frustum = len(ids)
        if self.visibility is not None:
            keep = self.visibility.patches_at(camera.eye)
            if keep is not None:
                ids = ids[keep[ids]]
        self.cull_stats = {"frustum_patches": int(frustum), "drawn_patches": int(len(ids))}
        return ids

    def prepare(self, camera: Camera, lod: bool = True, levels: np.ndarray | int | None = None,
                timings: dict | None = None) -> TerrainMesh | ResidentMesh:
        """LOD, cull and tessellate for ``camera``; returns the :class:`TerrainMesh`.

        ``levels`` overrides the LOD (an ``(e,)`` array or one int for every edge).
        """
        t = timings if timings is not None else {}
        # GPU-resident blocks: only culling, LOD and indices here.  With resident_wait=False, until they
        # are built in the background, frames take the CPU path (visible patches only).
        use = self.resident and levels is None and resident_fits(self.net)
        res = resident_terrain(self.net, wait=self.resident_wait) if use else None
        if res is not None:
            t0 = time.perf_counter()
            pids = self.visible(camera)
            t1 = time.perf_counter()
            mesh = res.frame(camera.eye, patches=pids, lod=lod, morph=self.lod_morph, **self.lod_kwargs)
            t2 = time.perf_counter()
            t.update(lod=0.0, cull=(t1 - t0) * 1e3, tessellate=(t2 - t1) * 1e3)
            return mesh
        t0 = time.perf_counter()
        if levels is None:
            levels = self.levels(camera, lod)
        t1 = time.perf_counter()
        pids = self.visible(camera)
        t2 = time.perf_counter()
        mesh = tessellate(self.net, levels, patches=pids, cache=False if use else None)
        t3 = time.perf_counter()
        t.update(lod=(t1 - t0) * 1e3, cull=(t2 - t1) * 1e3, tessellate=(t3 - t2) * 1e3)
        return mesh

    # ------------------------------------------------------------------ a frame
    def render(self, camera: Camera, lod: bool = True, lightmap_mode: str = "modulate", debug: str | None = None,
               fog: float | None | str = "scene", sky: bool = True,
               clear: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0),
               levels: np.ndarray | int | None = None, read: bool = True) -> Frame:
        """Render one frame of the terrain seen by ``camera`` (its aspect is set to the target's).

        Parameters
        ----------
        lod : per-edge distance LOD (False: every patch 8x8)
        lightmap_mode : "modulate" (one pass) or "ps2" (base pass + blended light-map pass)
        debug : None, "base", "lightmap", "lod" (patches coloured by LOD + wireframe), "wire"
        fog : density per metre (None or 0: no fog; "scene": :attr:`fog_density`, the default
            density scaled to the scene's size, :func:`scene_fog_density`); debug views have no fog
        sky : draw the gradient sky (else the clear colour shows)
        levels : override the LOD levels (``(e,)`` or an int)
        read : read the image back
        """
        camera = replace(camera, aspect=self.size[0] / self.size[1])
        t: dict = {}
        mesh = self.prepare(camera, lod=lod, levels=levels, timings=t)
        return self.draw(camera, mesh, lightmap_mode=lightmap_mode, debug=debug, fog=fog, sky=sky, clear=clear,
                         read=read, timings=t)

    def frame_mode(self, lightmap_mode: str = "modulate", debug: str | None = None) -> TerrainMode:
        """How a scene frame draws this terrain (:class:`piste.render.terrain_mode.TerrainMode`):
        this renderer's own pass in ``lightmap_mode``."""
        return TerrainMode(self, lightmap_mode, debug)

    def draw(self, camera: Camera, mesh: TerrainMesh | ResidentMesh, lightmap_mode: str = "modulate",
             debug: str | None = None, fog: float | None | str = "scene", sky: bool = True,
             clear: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0),
             read: bool = True, timings: dict | None = None, resolve: bool = True, sync: bool = True) -> Frame:
        """Upload and draw a given :class:`TerrainMesh` (any mesh with its fields) for ``camera``;
        the second half of :meth:`render`.  ``resolve=False`` leaves a ps2 frame in the half-float
        target (:attr:`active`, still bound) for more passes; :meth:`resolve` finishes it.
        ``sync=False`` (with ``read=False``) returns without waiting for the GL (more passes follow;
        the ``draw`` timing is then the issue time only), the terrain flushed to the GL
        (:attr:`flush_early`)."""
        camera = replace(camera, aspect=self.size[0] / self.size[1])
        t = {"lod": 0.0, "cull": 0.0, "tessellate": 0.0}
        t.update(timings or {})
        t0 = time.perf_counter()
        self.terrain.upload(mesh, kinds=debug == "lod")
        t1 = time.perf_counter()
        vp = camera.view_projection()
        self.active = self._hdr_target() if lightmap_mode == "ps2" and debug is None else self.target
        self.active.use()
        self.active.clear(clear)
        if isinstance(fog, str):
            fog = self.fog_density
        fog_rgba = None if not fog or debug is not None else (*HORIZON, float(fog))
        self.terrain.draw(vp, camera.eye, lightmap_mode=lightmap_mode, debug=debug, fog=fog_rgba)
        if sky:
            self.sky.draw(vp)  # last: only where no terrain was drawn
        if resolve:
            self.resolve()
        if sync or read:
            self.ctx.finish()
        elif self.flush_early:
            # the terrain (+ sky) handed to llvmpipe's rasterizer threads now (glFlush: it bins a scene
            # on this thread and rasterizes it only when flushed), so that they fill it while this
            # thread issues the passes that follow (receivers, objects, riders) instead of after them
            flush(self.ctx)
        t2 = time.perf_counter()
        image = self.target.read() if read else None
        t3 = time.perf_counter()
        check_gl_error(self.ctx, "drawing the terrain")
        t.update(upload=(t1 - t0) * 1e3, draw=(t2 - t1) * 1e3, readback=(t3 - t2) * 1e3)
        t["cpu"] = t["lod"] + t["cull"] + t["tessellate"] + t["upload"]
        t["gpu"] = t["draw"] + t["readback"]
        t["total"] = t["cpu"] + t["gpu"]
        kind = np.asarray(mesh.patch_kind)
        counts = {k: int(np.count_nonzero(kind == k)) for k in (4, 6, 8, 0)}
        counts[-1] = int(len(kind) - sum(counts.values()))
        self.mesh = mesh
        return Frame(image, len(kind), len(self.net), counts, int(mesh.n_triangles), int(mesh.n_vertices), t)

    def _hdr_target(self):
        if self._hdr is None or self._hdr.size != self.target.size:
            if self._hdr is not None:
                self._hdr.release()
            ctx = self.ctx
            w, h = self.target.size
            color = ctx.texture((w, h), 4, dtype="f2")
            depth = ctx.depth_texture((w, h))
            depth.compare_func = ""  # sampled as plain depth values by the resolve pass
            t = Offscreen.wrap(ctx, ctx.framebuffer(color_attachments=[color], depth_attachment=depth),
                               color=color, depth=depth, owned=True)
            self._hdr = t
            if self._resolve is None:
                import moderngl

                prog = ctx.program(vertex_shader=load_shader("fullscreen.vert.glsl"), fragment_shader=_RESOLVE_FS)
                prog["u_color"].value, prog["u_depth"].value = 0, 1
                self._resolve = (prog, ctx.vertex_array(prog, []), moderngl)
        return self._hdr

    def resolve(self) -> None:
        """Copy a frame drawn in the half-float target into :attr:`target`, colour (clamped to
        0..1 as any 8-bit frame buffer does) and depth, by a full-screen pass (a blit cannot copy
        depth into a window whose depth format differs); nothing for frames drawn straight into
        the target."""
        if self.active is self.target:
            return
        prog, vao, mgl = self._resolve
        ctx = self.ctx
        self.target.use()
        self.active.color.use(0)
        self.active.depth.use(1)
        ctx.disable(mgl.BLEND | mgl.CULL_FACE)
        ctx.enable(mgl.DEPTH_TEST)
        ctx.depth_func = "1"  # always: every pixel's depth written as it was
        vao.render(mgl.TRIANGLES, vertices=3)
        ctx.depth_func = "<"
        self.active = self.target

    def release(self) -> None:
        if self._hdr is not None:
            self._hdr.release()
            self._hdr = None
        if self._resolve is not None:
            self._resolve[1].release()
            self._resolve[0].release()
            self._resolve = None
        self.terrain.release()
        self.sky.release()
        self.target.release()


def summarize(frames: list[Frame]) -> dict:
    """The talk's statistics over ``frames`` (all patches drawn, summed), as a dict with the keys
    of :func:`piste.terrain.stats` (so :func:`piste.terrain.format_stats` prints it), plus mean
    timings ``lod_ms``, ``cull_ms``, ``tess_ms``, ``upload_ms``, ``cpu_ms``, ``draw_ms``,
    ``readback_ms``, ``frame_ms`` and ``fps``."""
    if not frames:
        raise ConfigError("summarize: no frames")
    p = sum(f.patches for f in frames)
    polys = sum(f.triangles for f in frames)
    kc = {k: sum(f.kind_counts[k] for f in frames) for k in (4, 6, 8, 0, -1)}
    pct = (lambda k: 100.0 * kc[k] / p) if p else (lambda k: 0.0)
    mean = {k: float(np.mean([f.timings[k] for f in frames])) for k in frames[0].timings}
    no_lod = 98 * p
    tess_s = sum(f.timings["tessellate"] for f in frames) / 1e3
    return {
        "frames": len(frames),
        "patches": round(p / len(frames)),
        "patches_total": frames[0].patches_total,
        "pct_4": pct(4),
        "pct_6": pct(6),
        "pct_8": pct(8),
        "pct_other": pct(-1),
        "pct_nonuniform": pct(0),
        "polys": round(polys / len(frames)),
        "vertices": round(sum(f.vertices for f in frames) / len(frames)),
        "avg_polys_per_patch": polys / p if p else 0.0,
        "tess_ms": mean["tessellate"],
        "mpolys_per_s": polys / tess_s / 1e6 if tess_s > 0 else float("inf"),
        "polys_no_lod": round(no_lod / len(frames)),
        "no_lod_ratio": no_lod / polys if polys else 0.0,
        "pct_more": 100.0 * (no_lod / polys - 1.0) if polys else 0.0,
        "lod_ms": mean["lod"],
        "cull_ms": mean["cull"],
        "upload_ms": mean["upload"],
        "cpu_ms": mean["cpu"],
        "draw_ms": mean["draw"],
        "readback_ms": mean["readback"],
        "frame_ms": mean["total"],
        "fps": 1e3 / mean["total"] if mean["total"] > 0 else float("inf"),
    }
