"""The completed real-time scene, one frame: terrain + projected rider shadows + objects + riders +
specular.

Order of a frame (``SceneRenderer.render``)::

    CPU  1. scene update (piste.world.scene.Scene.update): animation, rider LOD, blended-matrix
            skinning, light choice, object culling;
         2. terrain: per-edge LOD, frustum culling, tessellation (TerrainRenderer.prepare);
         3. shadows: one orthographic sun frustum per rider, the terrain patches each touches;
    GPU  4. shadow casters: each rider's low-LOD model into its tile of the shadow texture;
         5. terrain (+ sky) (TerrainRenderer.draw, not read back);
         6. the shadow receivers: the extra pass over the shadowed patches only;
         7. objects (compressed formats, instanced per kind);
         8. riders (per-vertex 1 + 3 lights) with their specular map's highlights (added in the
            same pass: CharacterPass.fold_specular; the talk's second pass with it off);
         9. glFinish and read back.

API
---
::

    SceneRenderer(scene, size=(640, 448), ctx=None, lightmap="placeholder", object_lighting="dynamic",
                  shadows=True, specular=True)
    SceneRenderer.render(t) -> SceneImage      image, the terrain Frame, the SceneFrame, stats, timings
    summarize_scene(images) -> dict            means of the timings and counts
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from piste._data import DataMethods
from piste.character.animation import clip_time, sample_track
from piste.character.morph import FaceSkin, face_weights
from piste import render as _render  # (occlude_frame by its lazy name: imported when occlusion is on)
from piste.errors import ConfigError
from piste.render.character_pass import CharacterPass
from piste.render.context import check_gl_error, flush
from piste.render.frame import TerrainRenderer
from piste.render.object_pass import ObjectPass
from piste.render.shadow_pass import SUN_RADIUS, ShadowPass, sun_visibility, shadow_matrices, shadow_patches
from piste.render.sky_pass import HORIZON
from piste.render.trace import NULL_TRACER
from piste.terrain.cull import patch_tree
from piste.world.course import TRACK_HALF_WIDTH
from piste.world.object_lod import DEFAULT_LOD_PIXELS

if TYPE_CHECKING:
    import moderngl

    from piste.world.camera import Camera
    from piste.world.riders import RiderState
    from piste.world.scene import Scene

__all__ = ["SceneRenderer", "SceneImage", "summarize_scene"]


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class SceneImage(DataMethods):
    """One rendered frame of the scene.

    image : (H, W, 4) uint8 or None;  terrain : piste.render.Frame (terrain counts, timings)
    scene : piste.world.scene.SceneFrame;  shadow_patches : list of patches per rider
    stats : counts (rider triangles, objects drawn, shadow patches, ...);  timings : ms per stage
    casts : the SceneFrames of the renderer's other rider models (``SceneRenderer(casts=...)``)
    """

    image: np.ndarray | None
    terrain: object
    scene: object
    shadow_patches: list
    stats: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    casts: list = field(default_factory=list)


class SceneRenderer:
    """Renders a :class:`piste.world.scene.Scene` off-screen (see the module docstring).

    Parameters
    ----------
    scene : Scene
    size : (W, H) pixels
    ctx : moderngl context to share (default: a new headless one)
    lightmap : the terrain's light map (see :class:`piste.render.TerrainRenderer`)
    object_lighting : "dynamic" | "baked" | "points"
    object_lod : the objects' levels of detail: the simplification error an instance may show, in
        pixels (0: every object drawn with its full mesh; :class:`piste.render.object_pass.ObjectPass`)
    shadows, specular : draw the projected shadows / the riders' specular highlights
    soft_shadows : the rider shadows' penumbrae from a sun of ``sun_radius`` degrees (PCSS,
        :class:`piste.render.shadow_pass.ShadowPass`); off: the talk's hard shadows
    occlusion : cull the terrain patches and objects the near terrain hides (a software
        hierarchical-Z, :mod:`piste.render.occlusion`; the same pixels); stats count them
    shadow_tile : pixels per rider shadow tile
    casts : more riders with other models: Scene-like objects (``model``, ``lods``, ``skinners``,
        ``riders``, ``update(t, aspect, camera=...)``; e.g. ``Scene(net, line, lights, model=m,
        pack=pack_for(m, 3))``) animated, skinned, lit, shadowed and drawn with the scene's own
        riders, each model with its own LODs, palettes and textures.  ``scene`` keeps the camera
        and the objects.  Default: ``scene.casts`` when the scene has them (a bundle with several
        rider models, :class:`piste.pipeline.preview.BundleScene`).
    face : faces that move: "morph" (morph targets added after skinning), "null_bones" (their
        null-bone fit) or None (the neutral face).  Weights come from the rider's clip when it
        animates them (glTF morph animations), else from :func:`piste.character.morph.face_weights`
        (blink and mouth for the default rider, other models' expressions in turn).
    terrain : a terrain renderer to draw with instead of making a :class:`TerrainRenderer` (then
        ``ctx``, ``lightmap`` and the terrain keywords are its own): e.g. an SSX level's
        :class:`piste.render.ssx_pass.SsxTerrainRenderer`, whose ``ps2`` mode blends the level's
        stored Cs/As (its public ``ssx_source`` pass) over the base texture, riders and all.
    """

    def __init__(self, scene: Scene, size: tuple[int, int] = (640, 448), ctx: moderngl.Context | None = None,
                 lightmap: Any = "placeholder", object_lighting: str = "dynamic",
                 shadows: bool = True, specular: bool = True, shadow_tile: int = 128, casts: Iterable[Any] = (),
                 face: str | None = "morph", terrain: Any = None, sunlight: tuple[np.ndarray, np.ndarray] | None = None,
                 object_lod: float = DEFAULT_LOD_PIXELS,
                 soft_shadows: bool = False, sun_radius: float = SUN_RADIUS, occlusion: bool = False,
                 **terrain_kw: Any) -> None:
        self.scene = scene
        terrain_kw.setdefault("track", scene.line)
        terrain_kw.setdefault("track_half_width", TRACK_HALF_WIDTH)
        self.terrain = terrain if terrain is not None else TerrainRenderer(scene.net, size=size, ctx=ctx,
                                                                           lightmap=lightmap, **terrain_kw)
        self.terrain.start_resident()  # built while the passes below set up; joined by the first frame
        self.ctx = self.terrain.ctx
        casts = list(casts) or list(getattr(scene, "casts", None) or ())  # a bundle scene lists its own
        self.casts = [scene] + [c for c in casts if len(c.riders)]
        n = sum(len(c.riders) for c in self.casts)
        self.cast_passes = [
            CharacterPass(self.ctx, c.lods, c.model.meshes[0].texture, max_riders=len(c.riders),
                          rider_atlas=getattr(c, "rider_atlas", c.model.name == "rider"),
                          material=getattr(c.model.meshes[0], "material", None))  # a glTF rider's MASK / double-sided
            for c in self.casts]
        self.characters = self.cast_passes[0]
        self.objects = ObjectPass(self.ctx, scene.objects, scene.lights, mode=object_lighting,
                                  lod_pixels=object_lod) if scene.objects is not None else None
        self.shadows = ShadowPass(self.ctx, n_max=n, tile=shadow_tile, soft=soft_shadows,
                                  sun_radius=sun_radius) if shadows else None
        self.occlusion = bool(occlusion)
        if self.shadows is not None and scene.sun is not None:
            # riders' shadows darken only terrain that sees the sun (no double darkening)
            # (``sunlight``: the same ``(field, rect)`` pre-computed, e.g. stored in a bundle at build time)
            self.shadows.set_sunlight(*(sunlight if sunlight is not None else
                                        sun_visibility(scene.net, scene.sun.direction)))
        self.specular = bool(specular)
        # the terrain renderer's per-patch boxes when it drew this net (net.patch_bounds is ~3 ms a call)
        same = isinstance(self.terrain, TerrainRenderer) and self.terrain.net is scene.net
        self.patch_lo, self.patch_hi = self.terrain.bounds if same else scene.net.patch_bounds
        # caster bounding sphere per model: the low LOD's bind-pose extent (riders lift and spin: a margin)
        self.cast_radius = []
        for c in self.casts:
            b = c.lods[-1].mesh.bounds()
            self.cast_radius.append(0.5 * float(np.linalg.norm(b[1] - b[0])) + 0.25)
        self.caster_radius = self.cast_radius[0]
        self.face = face
        self.faces = [[FaceSkin(lod.mesh, lod.palette.index, face) for lod in c.lods] if face else []
                      for c in self.casts]
        #: the performance analyzer (piste.render.trace): spans per step and pass; a no-op by default
        self.tracer = NULL_TRACER

    @property
    def size(self) -> tuple[int, int]:
        return self.terrain.size

    def render(self, t: float, read: bool = True, fog: float | None = None, camera: Camera | None = None, lod: bool = True,
               lightmap_mode: str = "modulate", light_only: bool = False, debug: str | None = None,
               count_rider_pixels: bool = False, face_time: float | None = None) -> SceneImage:
        """Render the scene at ``t`` seconds.  ``camera`` overrides the chase camera; ``light_only``
        draws riders and objects with their per-vertex light only (tests); ``debug`` is the terrain's
        debug view (e.g. "lod"); ``count_rider_pixels`` counts the riders' pixels that pass the depth
        test (an occlusion query: ``stats["rider_pixels"]``); ``face_time`` is the face animation's
        time (default ``t``).  The picture depends only on these arguments, not on the frames drawn
        before (no LOD hysteresis, distance-based geomorphing): a fresh process's first frames, drawn
        with numpy while numba loads in the background, are byte-identical to the same frames later
        (tests/render/test_scene_pipelined.py).  (With ``terrain.resident_wait = False`` the first
        frames take the CPU terrain path until the resident blocks are built: a few grey levels off.)"""
        with self.tracer.frame():  # (a no-op inside a frame the caller opened)
            plan = self._plan(t, camera=camera, lod=lod, lightmap_mode=lightmap_mode, debug=debug, face_time=face_time)
            self._issue(plan, fog=fog, light_only=light_only, count_rider_pixels=count_rider_pixels)
            return self._finish(plan, read)

    def frames(self, times: Iterable[float], read: bool = True, fog: float | None = None,
               cameras: Sequence[Camera | None] | None = None, lod: bool = True,
               lightmap_mode: str = "modulate", face_times: Sequence[float | None] | None = None) -> Iterator[SceneImage]:
        """Render the scene at each of ``times``, pipelined: yields a :class:`SceneImage` per time, the
        same pictures as :meth:`render`, byte for byte, whatever was drawn before.  While the GL rasterizes frame ``i`` (handed over with
        ``glFlush``, not waited for), the CPU work of frame ``i + 1`` (animation, skinning, LOD,
        culling, shadow frustums) runs; then frame ``i`` is read back.  (On llvmpipe only that planning
        can overlap: it bins a frame on the calling thread and rasterizes it after the flush;
        ``bench_frame.py`` measured 0.90-1.03x the one-at-a-time frame time.)  ``cameras``: one camera
        (or None: the chase camera) per time; ``face_times``: the face animation's time per frame
        (default ``times``).

        A frame's ``timings["total"]`` covers its issue, wait and read-back (not its overlapped CPU
        work, which is in ``timings["cpu"]``); measure throughput by wall time over the loop."""
        times = [float(x) for x in times]
        cams = list(cameras) if cameras is not None else [None] * len(times)
        faces = list(face_times) if face_times is not None else [None] * len(times)
        if len(cams) != len(times) or len(faces) != len(times):
            raise ConfigError(f"frames: {len(times)} times need as many cameras and face times, "
                              f"got {len(cams)} and {len(faces)}")
        kw: dict[str, Any] = dict(lod=lod, lightmap_mode=lightmap_mode)
        plan = self._plan(times[0], camera=cams[0], face_time=faces[0], **kw) if times else None
        for i in range(len(times)):
            self._issue(plan, fog=fog)
            flush(self.ctx)
            nxt = self._plan(times[i + 1], camera=cams[i + 1], face_time=faces[i + 1], **kw) \
                if i + 1 < len(times) else None
            yield self._finish(plan, read)
            plan = nxt

    def _plan(self, t: float, camera: Camera | None = None, lod: bool = True, lightmap_mode: str = "modulate",
              debug: str | None = None, face_time: float | None = None) -> dict:
        """A frame's CPU side (no GL call): scene update (animation, LOD, skinning, lights, object
        culling), faces, terrain LOD / culling / indices, shadow frustums and their patches."""
        with self.tracer.span("plan", t=float(t)):
            return self._plan_steps(t, camera, lod, lightmap_mode, debug, face_time)

    def _plan_steps(self, t, camera, lod, lightmap_mode, debug, face_time) -> dict:
        w, h = self.size
        tr = self.tracer
        t0 = time.perf_counter()
        with tr.span("scene update"):
            sf = self.scene.update(t, aspect=w / h, camera=camera, height_px=h)
        cam = sf.camera
        # the other models' riders, seen by the same camera
        with tr.span("casts + faces"):
            frames = [sf] + [c.update(t, aspect=w / h, camera=cam, height_px=h) for c in self.casts[1:]]
            for c, f, faces in zip(self.casts, frames, self.faces):
                if faces:
                    self._add_faces(c, f, faces, t, t if face_time is None else face_time)
        t1 = time.perf_counter()
        tt: dict = {}
        # how this frame draws its terrain (an SSX level's ps2 frame: base texture + stored texels)
        mode = self.terrain.frame_mode(lightmap_mode, debug)
        with tr.span("terrain LOD + cull + tessellate"):
            mesh = mode.prepare(cam, lod=lod, timings=tt)
        occ = None
        if self.occlusion:
            with tr.span("occlusion"):
                mesh, sf.objects_visible, occ = _render.occlude_frame(
                    self.terrain, mesh, cam, (w, h), self.patch_lo, self.patch_hi, self.scene.objects,
                    sf.objects_visible, prepare=lambda: mode.prepare(cam, lod=lod))
        t2 = time.perf_counter()
        patches = []
        light_vp = None
        sun = self.scene.sun
        if self.shadows is not None and sun is not None:
            with tr.span("shadow frusta"):
                centers = np.concatenate([f.riders.anchor + f.riders.normal * 0.9 for f in frames])
                radius = np.concatenate([np.full(len(f.riders), r) for f, r in zip(frames, self.cast_radius)])
                light_vp = shadow_matrices(centers, radius, sun.direction)
                patches = shadow_patches(self.patch_lo, self.patch_hi, light_vp, candidates=mesh.patch_ids,
                                         tree=patch_tree(self.scene.net))
        t3 = time.perf_counter()
        return dict(sf=sf, cam=cam, frames=frames, mesh=mesh, patches=patches, light_vp=light_vp, tt=tt, occ=occ,
                    mode=mode, stamps=[t0, t1, t2, t3])

    def _issue(self, plan: dict, fog: float | None = None, light_only: bool = False,
               count_rider_pixels: bool = False) -> None:
        """A planned frame's GPU work, issued (uploads, casters, terrain, receivers, objects, riders);
        :meth:`_finish` waits for it."""
        fog = self.terrain.fog_density if fog is None else fog  # the scene's size (scene_fog_density)
        w, h = self.size
        sf, cam, frames, mesh, tt = plan["sf"], plan["cam"], plan["frames"], plan["mesh"], plan["tt"]
        light_vp, sun = plan["light_vp"], self.scene.sun
        t3 = time.perf_counter()
        tr = self.tracer
        # ---- GPU work (uploads count as CPU time: they are memcpy on the CPU side)
        with tr.span("upload riders"):
            for cp, f in zip(self.cast_passes, frames):
                cp.upload(f.skinned)
        if self.shadows is not None and sun is not None:
            with tr.gpu_pass("shadow casters"):
                first = 0
                # (a rider whose shadow frustum meets no patch drawn this frame: its tile is never sampled)
                seen = np.array([len(p) > 0 for p in plan["patches"]], dtype=bool)
                for g, (c, f) in enumerate(zip(self.casts, frames)):
                    k = len(f.riders)
                    self.shadows.render_casters(f.shadow[0], c.lods[-1].mesh.indices, light_vp[first:first + k],
                                                first=first, group=g, draw=seen[first:first + k])
                    first += k
        t4 = time.perf_counter()
        with tr.gpu_pass("terrain"):
            # (a ps2 frame resolves here: the 8-bit frame buffer the rest blends on)
            frame = plan["mode"].draw(cam, mesh, fog=fog, timings=tt)
        t5 = time.perf_counter()
        vp = frame_vp = cam.with_aspect(w, h).view_projection()
        fog_rgba = (*HORIZON, float(fog)) if fog and plan["mode"].fog else None  # (the SSX ps2 frame has none)
        if self.shadows is not None and sun is not None:
            with tr.gpu_pass("shadow receivers"):
                self.shadows.draw_receivers(mesh, plan["patches"], frame_vp, terrain=getattr(self.terrain, "terrain", None))
        if self.objects is not None:
            with tr.gpu_pass("objects"):
                self.objects.draw(vp, cam.eye, sf.objects_visible, fog=fog_rgba, light_only=light_only)
        with tr.gpu_pass("riders"):
            rider_pixels = self._draw_riders(plan, vp, cam, fog_rgba, light_only, count_rider_pixels)
        plan.update(frame=frame, rider_pixels=rider_pixels,
                    objects_drawn=self.objects.drawn if self.objects is not None else 0,
                    object_triangles=self.objects.triangles if self.objects is not None else 0,
                    rider_triangles=int(sum(cp.triangles for cp in self.cast_passes)),
                    shadow_triangles=self.shadows.triangles if self.shadows is not None else 0)
        plan["stamps"] += [t3, t4, t5]

    def _draw_riders(self, plan, vp, cam, fog_rgba, light_only, count_rider_pixels):
        """Every model's riders (base pass, specular); the riders' pixels when counted, else None."""
        frames, sun = plan["frames"], self.scene.sun
        query = self.ctx.query(samples=True) if count_rider_pixels else None
        rider_pixels = 0
        for cp, f in zip(self.cast_passes, frames):
            if query is not None:
                with query:
                    cp.draw(vp, cam.eye, f.rider_lights, sun=None, fog=fog_rgba, light_only=light_only)
                rider_pixels += int(query.samples)
            if query is None or (self.specular and not light_only):
                # with the query the base pass is drawn inside it; the specular pass adds on top
                cp.draw(vp, cam.eye, f.rider_lights, sun=sun if self.specular else None, fog=fog_rgba,
                        light_only=light_only, base=query is None)
        return rider_pixels if query is not None else None

    def _finish(self, plan: dict, read: bool) -> SceneImage:
        """Wait for an issued frame, read it back, and gather its timings and counts."""
        with self.tracer.span("wait (glFinish)"):
            self.ctx.finish()
        t6 = time.perf_counter()
        with self.tracer.span("read back"):
            image = self.terrain.target.read() if read else None
        t7 = time.perf_counter()
        check_gl_error(self.ctx, "drawing the scene")
        t0, t1, t2, t3, t3b, t4, t5 = plan["stamps"]
        sf, frames, frame, tt, patches = plan["sf"], plan["frames"], plan["frame"], plan["tt"], plan["patches"]
        tm = {}
        tm.update(sf.timings)
        for f in frames[1:]:
            for k, v in f.timings.items():
                tm[k] = tm.get(k, 0.0) + v
        tm.update(terrain_lod=tt.get("lod", 0.0), terrain_cull=tt.get("cull", 0.0), tessellate=tt.get("tessellate", 0.0),
                  shadow_cull=(t3 - t2) * 1e3, upload=frame.timings["upload"] + (t4 - t3b) * 1e3,
                  terrain_draw=frame.timings["draw"], scene_draw=(t6 - t5) * 1e3, readback=(t7 - t6) * 1e3)
        # the talk's CPU side: animation, skinning, LOD, tessellation, culling
        tm["cpu"] = (sf.timings["cpu"] + tm["terrain_lod"] + tm["terrain_cull"] + tm["tessellate"] + tm["shadow_cull"])
        tm["gpu"] = tm["upload"] + tm["terrain_draw"] + tm["scene_draw"] + tm["readback"]
        tm["total"] = (t3 - t0 + t7 - t3b) * 1e3  # (pipelined: the CPU side ran while the frame before drew)
        counts = [len(p) for p in patches]
        allp = np.concatenate(patches) if patches else np.zeros(0, np.int64)
        union = int(np.count_nonzero(np.bincount(allp))) if len(allp) else 0  # (np.unique imports numpy.ma)
        stats = {
            "riders": int(sum(len(f.riders) for f in frames)),
            "rider_lod": [int(x) for f in frames for x in f.rider_lod],
            "rider_triangles": plan["rider_triangles"],
            "rider_models": len(self.casts),
            "objects_drawn": plan["objects_drawn"],
            "object_triangles": plan["object_triangles"],
            "shadow_patches": int(sum(counts)),
            "shadow_patches_union": union,
            "shadow_patches_per_rider": counts,
            "shadow_triangles": plan["shadow_triangles"],
            "terrain_patches": frame.patches,
            "terrain_triangles": frame.triangles,
        }
        if plan["rider_pixels"] is not None:
            stats["rider_pixels"] = plan["rider_pixels"]
        if plan.get("occ") is not None:
            stats.update(plan["occ"])
        frame.image = image
        return SceneImage(image, frame, sf, patches, stats, tm, frames[1:])

    @staticmethod
    def face_weights(cast: Any, state: RiderState, t: float, face_t: float, riders: np.ndarray) -> np.ndarray:
        # cast: a Scene or a Scene-like cast (SceneRenderer(casts=...): model, lods, riders), hence Any
        """Morph weights ``(len(riders), k)`` of ``cast``'s riders: their clip's weight track
        when it has one for the whole mesh (a glTF morph animation), else the procedural face."""
        mesh = cast.lods[0].mesh
        k = mesh.morph_positions.shape[0]
        out = face_weights(mesh.morph_names, face_t, riders)
        clips = cast.model.clips
        rs = cast.riders
        times = rs.clip_times(t) if hasattr(rs, "clip_times") else np.asarray(rs.phase, np.float64) + t
        for j, r in enumerate(riders):
            clip = clips.get(state.clip[r])
            tracks = [tr for tr in (clip.weight_tracks.values() if clip is not None else ())
                      if np.asarray(tr.values).reshape(len(tr.times), -1).shape[1] == k]
            if len(tracks) == 1:
                tt = clip_time(float(times[r]) - t + face_t, clip.duration, True)
                out[j] = np.asarray(sample_track(tracks[0], tt), np.float32).reshape(k)
        return out

    def _add_faces(self, cast, frame, faces, t, face_t) -> None:
        st = frame.riders
        for level, (idx, pos, nrm) in enumerate(frame.skinned):
            fs = faces[level]
            if not fs or not len(idx):
                continue
            pal = cast.skinners[level].palette_matrices(st.skin[idx])
            fs.apply(pos, nrm, pal, self.face_weights(cast, st, t, face_t, idx))

    def release(self) -> None:
        for p in (*self.cast_passes, self.objects, self.shadows):
            if p is not None:
                p.release()
        self.terrain.release()


def summarize_scene(images: Sequence[SceneImage]) -> dict:
    """Means over frames: every timing (``<stage>_ms``), ``fps`` from the mean total, and the mean
    counts (rider triangles, objects, shadow patches)."""
    if not images:
        raise ConfigError("summarize_scene: no frames")
    out = {f"{k}_ms": float(np.mean([im.timings[k] for im in images])) for k in images[0].timings}
    out["cpu_median_ms"] = float(np.median([im.timings["cpu"] for im in images]))
    out["fps"] = 1e3 / out["total_ms"] if out["total_ms"] > 0 else float("inf")
    for k in ("rider_triangles", "objects_drawn", "object_triangles", "shadow_patches", "shadow_patches_union",
              "shadow_triangles", "terrain_patches", "terrain_triangles"):
        out[k] = float(np.mean([im.stats[k] for im in images]))
    out["shadow_patches_max"] = int(max(im.stats["shadow_patches"] for im in images))
    out["frames"] = len(images)
    return out
