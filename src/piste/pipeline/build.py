"""``piste build``: a scene description -> one ``.piste`` bundle, every step pre-processed and cached.

Steps (each keyed by a content hash of what it reads; a key found in the cache is reused):

============== ============================================================ =====================
step           reads                                                        makes
============== ============================================================ =====================
terrain        the terrain source's bytes (or the course seed), settings    control points, UVs
lod_errors     terrain key                                                  the LOD's per-patch
                                                                            error table
lightmap       terrain key, lights, res / gutter / shadows                  the baked atlas
shadow         terrain key, the sun's direction                             where the terrain sees
                                                                            the sun (riders' shadows)
characters     the rider model (file bytes or built-in name), LOD ratios    LOD meshes, palettes,
                                                                            batches, strips, clips
objects        terrain key, object models and placements, lights            compressed meshes,
                                                                            instances, vertex RGBs
visibility     terrain key, visibility settings                             per-cell patch bits
object_vis...  terrain key, object bounds, visibility settings              per-cell object bits
============== ============================================================ =====================

(``object_visibility`` is its own step so that moving an object re-tests only the objects: with
up to :data:`OBJECT_RAYS_MAX` objects by exact rays, ~0.2 s on the default course.)

Lights and cameras (inline and from glTF) and rider placements are cheap and computed each time.
The bundle holds no timestamps or absolute paths: rebuilding unchanged inputs gives the same bytes.

API
---
build_scene(scene, out=None, cache_dir=None, progress=False, jobs=1, steps=None) -> BuildResult
default_cache_dir(scene_path) -> Path        ``<scene folder>/.piste-cache``
BUILD_VERSION
BUILD_STEPS                                  the steps above, in order: :class:`BuildStep` rows
register_step(step, after=) / unregister_step(name)    add a step (ARCHITECTURE.md: how to add one)
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, cast

import numpy as np

from piste.errors import ConfigError
from piste.formats.bundle import camera_to_dict, write_bundle
from piste.formats.gltf import load_gltf
from piste.formats.ssx.mpf_model import mpf_partners
from piste.lighting.baker import BAKE_VERSION, bake_lightmap
from piste.lighting.lights import Lights, default_lights
from piste.pipeline.bundle_objects import (LOD_ERRORS_FORMAT, camera_from_dict, lights_from_dict, lod_error_members,
                                          resident_members)
from piste.pipeline.cache import Cache, content_key
from piste.pipeline.characters import CHARACTERS_VERSION, character_arrays
from piste.pipeline.gltf_import import import_gltf
from piste.pipeline.object_atlas import blends, double_sided, pack_object_atlas, primitive_images
from piste.pipeline.sources import add_rider_clips, load_object_mesh, load_rider_model, load_terrain, object_matrices, rider_matrices
from piste.pipeline.ssx_level import bundle_arrays, level_key
from piste.pipeline.ssx_rider import load_mpf_rider
from piste.pipeline.visibility import (Visibility, camera_eyes, compute_visibility, culling_report,
                                       scene_eye_heights)
from piste.render.shadow_pass import sun_visibility
from piste.render.textures import TRACK_TEXEL, light_texels, track_field, track_texels
from piste.terrain.net import TOPOLOGY_FORMAT, PatchNet
from piste.world.camera import Camera, camera_planes, track_camera
from piste.world.course import track_centerline
from piste.world.object_lod import lod_arrays, object_lods
from piste.world.objects import ObjectSet, bake_vertex_colors, compress_mesh, normal_matrix, object_texture
from piste.world.scene import sun_light
from piste.world.scene_file import ActorSpec, SceneFile, load_scene

__all__ = ["build_scene", "BuildResult", "default_cache_dir", "BUILD_VERSION", "scene_lights", "scene_cameras",
           "BuildStep", "BuildContext", "BUILD_STEPS", "register_step", "unregister_step", "bake_partial_dir",
           "clean_command"]

_PathLike = str | os.PathLike[str]

#: bumped whenever a step's output for the same input changes
BUILD_VERSION = "piste.build/1"
#: the sun-visibility step's version (bump when :func:`piste.render.shadow_pass.sun_visibility` changes)
SHADOW_VERSION = 1
#: up to this many objects, their visibility bits come from exact rays (cheap, and exact)
OBJECT_RAYS_MAX = 64


@dataclass
class BuildResult:
    """What a build did: ``path`` of the bundle, ``steps`` ``{name: {"cached": bool, "seconds": float}}``,
    ``report`` (counts, visibility statistics), ``seconds`` in all, ``bytes`` of the bundle."""

    path: Path
    steps: dict[str, dict[str, Any]] = field(default_factory=dict)
    report: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0
    bytes: int = 0

    @property
    def cached(self) -> list[str]:
        return [k for k, v in self.steps.items() if v.get("cached")]

    @property
    def rebuilt(self) -> list[str]:
        return [k for k, v in self.steps.items() if not v.get("cached")]


def default_cache_dir(scene_path: _PathLike) -> Path:
    return Path(scene_path).resolve().parent / ".piste-cache"


def bake_partial_dir(scene_path: _PathLike, cache_dir: _PathLike | None = None) -> Path:
    """The folder where ``piste build`` keeps a light-map bake's resumable chunks:
    ``CACHE/bake-partial`` (``cache_dir``, default :func:`default_cache_dir`)."""
    return (Path(cache_dir) if cache_dir is not None else default_cache_dir(scene_path)) / "bake-partial"


def clean_command(scene_path: _PathLike, cache_dir: _PathLike | None = None) -> str:
    """The shell command that removes the chunks under :func:`bake_partial_dir` (``piste build --clean``)."""
    import shlex

    cmd = f"piste build --clean {shlex.quote(str(scene_path))}"
    return cmd + (f" --cache {shlex.quote(str(cache_dir))}" if cache_dir is not None else "")


def _json_lights(lights: Lights) -> dict[str, list[dict[str, Any]]]:
    """``Lights.to_dict()`` with infinite ranges as the string "inf" (strict JSON)."""
    out = {}
    for kind, items in lights.to_dict().items():
        out[kind] = [{k: ("inf" if isinstance(v, float) and math.isinf(v) else v) for k, v in it.items()} for it in items]
    return out


def scene_lights(scene: SceneFile, gltf_cache: dict[str, Any] | None = None) -> Lights:
    """The scene's :class:`piste.lighting.Lights`: inline ``[[lights]]`` plus every ``[[gltf]]``
    file's lights; the default course's lights when the scene gives none."""
    items = list(scene.lights)
    for g in scene.gltf:
        if g.lights:
            imported = gltf_cache.get(str(g.file)) if gltf_cache is not None else None
            if imported is None:
                imported = import_gltf(g)
                if gltf_cache is not None:
                    gltf_cache[str(g.file)] = imported
            items.extend(imported[0])
    if not items:
        return default_lights()
    return Lights(tuple(items), name=scene.name)


def scene_cameras(scene: SceneFile, net: PatchNet | None, centerline: np.ndarray | None,
                  gltf_cache: dict[str, Any] | None = None) -> list[dict[str, Any]]:
    """The scene's cameras as manifest dicts (``name``, eye, target, ..., optional ``track``)."""
    out = []
    lo, hi = net.bounds if net is not None else (None, None)  # planes not given follow the terrain's size
    for c in scene.cameras:
        if c.track is not None:
            if centerline is None:  # loads_scene refuses track cameras off the default course
                raise ConfigError(f"{scene.path}: camera {c.name!r}: a track camera needs the default course's track")
            cam = track_camera(centerline, c.track[0], height=c.height, fov_y=c.fov)
            near, far = camera_planes(cam.eye, lo, hi, c.near, c.far)
            d = camera_to_dict(replace(cam, near=near, far=far))
            d.update(track=[float(x) for x in c.track], height=float(c.height))
        else:
            near, far = camera_planes(np.array(c.eye), lo, hi, c.near, c.far)
            d = camera_to_dict(Camera(np.array(c.eye), np.array(c.target), up=np.array(c.up), fov_y=c.fov,
                                      near=near, far=far))
        d["name"] = c.name
        d["source"] = "scene"
        out.append(d)
    for g in scene.gltf:
        if not g.cameras:
            continue
        imported = gltf_cache.get(str(g.file)) if gltf_cache is not None else None
        if imported is None:
            imported = import_gltf(g)
            if gltf_cache is not None:
                gltf_cache[str(g.file)] = imported
        cams = imported[1]
        if hasattr(cams, "fitted"):  # planes the file did not give follow the terrain, as a scene camera's
            cams = cams.fitted(lo, hi)
        for name, cam in cams.items():
            d = camera_to_dict(cam)
            d["name"] = name
            d["source"] = Path(g.file).name
            out.append(d)
    if not out:
        if centerline is not None:
            cam = track_camera(centerline, 0.12, height=9.0)
            d = camera_to_dict(cam)
            d.update(name="track", track=[0.12, 0.45], height=9.0, source="default")
        else:
            if net is None:
                raise ConfigError(f"{scene.path}: a default camera needs the terrain (no net given)")
            lo, hi = net.bounds
            c = (lo + hi) / 2.0
            ext = float(np.linalg.norm(hi - lo))
            eye = c + np.array([-0.35, -0.6, 0.55]) * ext
            d = camera_to_dict(Camera(eye, c, near=max(ext * 1e-3, 1e-3), far=ext * 4.0))
            d.update(name="overview", source="default")
        out.append(d)
    names = [d["name"] for d in out]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise ConfigError(f"{scene.path}: camera names must be unique, {', '.join(sorted(dup))} given twice "
                          "(inline and in a glTF file?)")
    return out


def _file_key(path: _PathLike) -> str:
    return content_key(Path(path))


def _allow_key(scene: SceneFile) -> tuple[tuple[str, list[str]], ...]:
    """The scene's ``allow_paths`` as cache-key parts (none when empty, so existing keys stand):
    a step built while a folder was allowed is not reused once it no longer is."""
    return (("allow_paths", [str(p) for p in scene.allow_paths]),) if getattr(scene, "allow_paths", ()) else ()


# ----------------------------------------------------------------------------- the step registry
# a step's arrays ({"name": ndarray}) and its metadata (JSON-able), as the cache stores them (a plain comment:
# a "#:" one made autodoc document the alias, and viewcode list a "builtins" page that does not exist)
Arrays = dict[str, np.ndarray]
Meta = dict[str, Any]
StepOutput = tuple[Arrays, Meta]


@dataclass
class BuildContext:
    """What the steps of one build share: the scene and the build's options, the bundle being made
    (``arrays``: member name -> array, ``manifest``), and what earlier steps left for later ones.

    The terrain step sets the net (:meth:`set_terrain`); the lights step the scene's lights
    (:meth:`set_lights`); a step reads them as ``ctx.net``, ``ctx.lights``, ``ctx.centerline``.
    ``keys`` holds the full content key of every cached step run so far (``keys["terrain"]`` is
    what every terrain-dependent key includes); ``shared`` anything else a step leaves for a later
    one (``"visibility"``: the patch sets' arrays and metadata for ``object_visibility``).
    """

    scene: SceneFile
    cache: Cache
    result: BuildResult
    cache_dir: str | os.PathLike[str] | None = None  # as given (the clean command names it)
    progress: bool = False
    jobs: int = 1
    arrays: Arrays = field(default_factory=dict)
    manifest: dict[str, Any] = field(default_factory=dict)
    keys: dict[str, str] = field(default_factory=dict)
    shared: dict[str, Any] = field(default_factory=dict)
    gltf_cache: dict[str, Any] = field(default_factory=dict)
    centerline: np.ndarray | None = None
    spheres: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))  # (n, 4) objects' bounding spheres
    _net: PatchNet | None = None
    _lights: Lights | None = None

    @property
    def net(self) -> PatchNet:
        """The terrain net (set by the terrain step)."""
        if self._net is None:
            raise RuntimeError("the terrain step has not run: a build step reading ctx.net must come after it")
        return self._net

    @property
    def lights(self) -> Lights:
        """The scene's lights (set by the lights step)."""
        if self._lights is None:
            raise RuntimeError("the lights step has not run: a build step reading ctx.lights must come after it")
        return self._lights

    @property
    def terrain_key(self) -> str:
        """The terrain step's content key (part of every key that depends on the terrain)."""
        return self.keys["terrain"]

    def set_terrain(self, net: PatchNet, centerline: np.ndarray | None) -> None:
        self._net, self.centerline = net, centerline

    def set_lights(self, lights: Lights) -> None:
        self._lights = lights

    def cached(self, name: str, key: str, make: Callable[[], StepOutput]) -> StepOutput:
        """``make()``'s output, from the cache under ``(name, key)`` when it is there (else made and
        stored); records ``result.steps[name]`` (``cached``, ``seconds``, the key's first 16 digits)."""
        t0 = time.perf_counter()
        got = self.cache.get(name, key)
        hit = got is not None
        if got is None:
            got = make()
            self.cache.put(name, key, *got)
        self.result.steps[name] = {"cached": hit, "seconds": time.perf_counter() - t0, "key": key[:16]}
        return got[0], got[1]

    def skipped(self, name: str) -> None:
        """Record step ``name`` as having nothing to do for this scene (key ``"none"``)."""
        self.result.steps[name] = {"cached": True, "seconds": 0.0, "key": "none"}


@dataclass(frozen=True)
class BuildStep:
    """One step of :func:`build_scene`, in the order of :data:`BUILD_STEPS`.

    A **cached** step (``cache=True``, the usual kind) gives

    * ``key(ctx) -> str | None``: the content key of everything the step reads
      (:func:`piste.pipeline.cache.content_key` of :data:`BUILD_VERSION`, the step's name and version,
      ``ctx.terrain_key`` when it depends on the terrain, the scene's settings ...), or None when the
      scene has nothing for it (it is recorded with key ``"none"`` and ``absent(ctx)`` is called);
    * ``make(ctx) -> (arrays, meta)``: the work, run only when the cache has no entry for the key;
    * ``store(ctx, (arrays, meta))``: puts the output into ``ctx.arrays`` (bundle members
      ``<step>/<name>``) and ``ctx.manifest``, and leaves what later steps need on ``ctx``.

    A step with ``cache=False`` is cheap and computed each time (``make`` then ``store``; no key,
    not in :attr:`BuildResult.steps`).  ``when(ctx)`` False leaves the step out of this build
    altogether (not recorded).  A step with several cache entries gives ``run(ctx)`` instead and
    calls :meth:`BuildContext.cached` for each (the characters: one entry per rider model).
    ``reads`` says in words what the key covers, for a reader of :data:`BUILD_STEPS` (the table
    at the top of this module).
    """

    name: str
    reads: str
    key: Callable[[BuildContext], str | None] | None = None
    make: Callable[[BuildContext], StepOutput] | None = None
    store: Callable[[BuildContext, StepOutput], None] | None = None
    absent: Callable[[BuildContext], None] | None = None
    when: Callable[[BuildContext], bool] | None = None
    run: Callable[[BuildContext], None] | None = None
    cache: bool = True

    def __post_init__(self) -> None:
        if self.run is None and (self.make is None or self.store is None or (self.cache and self.key is None)):
            raise ConfigError(f"build step {self.name!r}: give run, or make and store (and key for a cached step)")

    def execute(self, ctx: BuildContext) -> None:
        """Run this step in ``ctx`` (what :func:`build_scene` does for each step in order)."""
        if self.when is not None and not self.when(ctx):
            return
        if self.run is not None:
            self.run(ctx)
            return
        assert self.make is not None and self.store is not None
        make = self.make
        if not self.cache:
            self.store(ctx, make(ctx))
            return
        assert self.key is not None
        key = self.key(ctx)
        if key is None:
            ctx.skipped(self.name)
            if self.absent is not None:
                self.absent(ctx)
            return
        ctx.keys[self.name] = key
        self.store(ctx, ctx.cached(self.name, key, lambda: make(ctx)))


# -------------------------------------------------------------- terrain
def _terrain_key(ctx: BuildContext) -> str:
    ts = ctx.scene.terrain
    src = _file_key(ts.path) if ts.path is not None else f"seed {ts.seed}"
    if ts.kind == "ssx_pbd":  # the .pbd and the texture / light-map banks beside it
        src = level_key(cast(Path, ts.path))  # an ssx_pbd terrain names its file (scene_file checks)
    return content_key(BUILD_VERSION, "terrain", ts.kind, src, ts.seed, ts.spacing, ts.height_scale,
                       ts.height_offset, ts.key, ts.samples_per_patch, ts.smooth,
                       *((ts.nodata, ts.vertical_units) if ts.kind == "geotiff" else ()))


def _make_terrain(ctx: BuildContext) -> StepOutput:
    ts = ctx.scene.terrain
    net = load_terrain(ts)
    a = {"control_points": net.control_points, "uv": net.uv}
    if ts.kind == "default":
        a["centerline"] = track_centerline(ts.seed)
    return a, {"name": net.name, "tol": float(net.tol)}


def _store_terrain(ctx: BuildContext, out: StepOutput) -> None:
    ta, tm = out
    net = PatchNet(ta["control_points"], uv=ta["uv"], tol=tm["tol"], name=tm["name"])
    centerline = ta.get("centerline")
    ctx.set_terrain(net, centerline)
    arrays = ctx.arrays
    arrays["terrain/control_points"] = net.control_points
    arrays["terrain/uv"] = ta["uv"] if net.uv is None else net.uv  # (a net built with uv keeps it)
    # the welded topology, so a load need not weld and match edges again (~0.1 s of a fresh process)
    arrays.update({f"terrain/{k}": v for k, v in net.topology().items()})
    track = {}
    if centerline is not None:
        arrays["terrain/centerline"] = centerline
        # the groomed track's projected texture as the terrain pass uploads it (float16, clipped),
        # made here instead of in every fresh process's renderer set-up (~3-5 ms)
        field, rect = track_field(centerline, net.bounds, texel=TRACK_TEXEL)
        arrays["terrain/track_field"], arrays["terrain/track_rect"] = track_texels(field), rect
        track = {"track_texel": TRACK_TEXEL}
    lo, hi = net.bounds
    ctx.manifest["terrain"] = {"name": tm["name"], "tol": tm["tol"], "kind": ctx.scene.terrain.kind, "patches": len(net),
                               "topology": TOPOLOGY_FORMAT, "bounds": [[float(x) for x in lo], [float(x) for x in hi]],
                               "key": ctx.terrain_key, **track}


# -------------------------------------------------------------- terrain LOD error table
# per patch, the errors of the flat and coarsest meshes (piste.terrain.lod): computed here, not in a
# fresh process's first frame (10-30 ms; 50-160 ms on a loaded machine)
def _lod_errors_key(ctx: BuildContext) -> str:
    return content_key(BUILD_VERSION, "lod_errors", LOD_ERRORS_FORMAT, ctx.terrain_key)


def _make_lod_errors(ctx: BuildContext) -> StepOutput:
    return lod_error_members(ctx.net)


def _store_lod_errors(ctx: BuildContext, out: StepOutput) -> None:
    arrays, meta = out
    ctx.arrays.update(arrays)
    ctx.manifest["lod_errors"] = dict(meta)


# -------------------------------------------------------------- lights and cameras (cheap: each time)
def _run_lights(ctx: BuildContext) -> None:
    lights = scene_lights(ctx.scene, ctx.gltf_cache)
    ctx.set_lights(lights)
    ctx.manifest["lights"] = _json_lights(lights)
    ctx.manifest["cameras"] = scene_cameras(ctx.scene, ctx.net, ctx.centerline, ctx.gltf_cache)


def _store_manifest(ctx: BuildContext, out: StepOutput) -> None:
    """Metadata straight into the manifest (a step whose output is only manifest entries)."""
    ctx.manifest.update(out[1])


# -------------------------------------------------------------- light map
def _lightmap_gi(ctx: BuildContext) -> list[float]:
    """Bounces / sun radius: in the key and the manifest only when set (existing keys stand)."""
    lm = ctx.scene.lightmap
    return [lm.bounces, lm.sun_radius] if (lm.bounces or lm.sun_radius) else []


def _lightmap_key(ctx: BuildContext) -> str:
    lm = ctx.scene.lightmap
    return content_key(BUILD_VERSION, "lightmap", BAKE_VERSION, ctx.terrain_key, ctx.manifest["lights"], lm.res,
                       lm.gutter, lm.shadows, *_lightmap_gi(ctx))


def _make_lightmap(ctx: BuildContext) -> StepOutput:
    scene, ts, lm_spec = ctx.scene, ctx.scene.terrain, ctx.scene.lightmap
    if ts.kind == "ssx_pbd":  # an SSX level brings its own light maps and textures (pipeline.ssx_level)
        return bundle_arrays(cast(Path, ts.path)), {"stats": {}}
    partial = bake_partial_dir(scene.path, ctx.cache.root) if ctx.cache.root is not None else None
    lm = bake_lightmap(ctx.net, ctx.lights, res=lm_spec.res, gutter=lm_spec.gutter, shadows=lm_spec.shadows,
                       jobs=ctx.jobs, partial_dir=partial, progress=ctx.progress, bounces=lm_spec.bounces,
                       sun_radius=lm_spec.sun_radius, clean_command=clean_command(scene.path, ctx.cache_dir))
    if partial is not None:
        import shutil

        shutil.rmtree(partial / lm.manifest["key"], ignore_errors=True)
    st = {k: int(v) for k, v in (getattr(lm, "stats", None) or {}).items()}
    return {"atlas": lm.atlas.astype(np.float32), "rects": lm.rects.astype(np.float32)}, {"stats": st}


def _store_lightmap(ctx: BuildContext, out: StepOutput) -> None:
    la, lmeta = out
    lm_spec, arrays = ctx.scene.lightmap, ctx.arrays
    arrays["lightmap/atlas"] = la["atlas"]
    arrays["lightmap/rects"] = la["rects"]
    # the atlas as the terrain pass uploads it (float16 RGB, clipped), so a fresh process's renderer
    # set-up need not convert 3 MB of float32 (~2-4 ms): Bundle.lightmap_texels
    arrays["lightmap/texels"] = light_texels(la["atlas"])
    if "base_texture" in la:
        arrays["terrain/base_texture"] = la["base_texture"]
    if "source" in la:  # an SSX level's stored Cs / As texels (ps2 mode, piste.render.ssx_pass)
        arrays["lightmap/source"] = la["source"]
    ctx.net.lightmap_rect = la["rects"].copy()
    ctx.manifest["lightmap"] = {"res": lm_spec.res, "gutter": lm_spec.gutter, "shadows": lm_spec.shadows,
                                **({"bounces": lm_spec.bounces, "sun_radius": lm_spec.sun_radius}
                                   if _lightmap_gi(ctx) else {}),
                                "atlas_size": [int(la["atlas"].shape[1]), int(la["atlas"].shape[0])],
                                "encoding": "float32 linear light, 1.0 = full", "stats": lmeta.get("stats", {})}


# -------------------------------------------------------------- resident vertex blocks
# the terrain's GPU vertex blocks (pipeline.bundle_objects.resident_members), stored uncompressed so a
# fresh process's first frame does not wait for them (~0.1 s of `piste render`'s cold start); they
# need the light-map rects, so this step follows the light map
def _make_resident(ctx: BuildContext) -> StepOutput:
    arrays, meta = resident_members(ctx.net)
    return arrays, meta or {}


def _store_resident(ctx: BuildContext, out: StepOutput) -> None:
    arrays, meta = out
    ctx.arrays.update(arrays)
    if meta:
        ctx.manifest["terrain"]["resident"] = meta


# -------------------------------------------------------------- shadow (sun visibility)
# where the terrain sees the sun, for the riders' shadows: computed here, not at every renderer
# set-up (~0.2 s of a fresh process's first frame); the sun exactly as the runtime reads it back
def _sun_direction(ctx: BuildContext) -> list[float] | None:
    sun = sun_light(lights_from_dict(ctx.manifest["lights"]))
    if sun is None:
        return None
    return [float(x) for x in np.asarray(sun.direction, dtype=np.float64).ravel()]


def _shadow_key(ctx: BuildContext) -> str | None:
    sun_dir = _sun_direction(ctx)
    return None if sun_dir is None else content_key(BUILD_VERSION, "shadow", SHADOW_VERSION, ctx.terrain_key, sun_dir)


def _make_shadow(ctx: BuildContext) -> StepOutput:
    sun_dir = _sun_direction(ctx)
    f, rect = sun_visibility(ctx.net, sun_dir)
    return {"sun_visibility": f, "sun_rect": np.asarray(rect, dtype=np.float64)}, {"sun_direction": sun_dir}


def _store_shadow(ctx: BuildContext, out: StepOutput) -> None:
    sa, smeta = out
    ctx.arrays["shadow/sun_visibility"] = sa["sun_visibility"]
    ctx.arrays["shadow/sun_rect"] = sa["sun_rect"]
    ctx.manifest["shadow"] = {"sun_direction": smeta["sun_direction"], "version": SHADOW_VERSION}


# -------------------------------------------------------------- characters (one cache entry per rider model)
def _run_characters(ctx: BuildContext) -> None:
    scene, arrays, manifest = ctx.scene, ctx.arrays, ctx.manifest
    manifest["characters"] = {}
    manifest["riders"] = []
    if not scene.riders:
        ctx.skipped("characters")
        return
    # one character per rider model (any number: each its own LODs, palettes, batches, clips);
    # the first keeps the id "rider", the others "rider2", "rider3", ... in the order of the file
    models = list(dict.fromkeys(r.model for r in scene.riders))
    ratios = tuple(scene.lod.ratios)
    cid_of: dict[str, str] = {}
    clips_of: dict[str, tuple[Any, Any, list[tuple[str, str]]]] = {}
    steps_done = []
    for k, model in enumerate(models):
        msrc = model if model.startswith("builtin:") else _file_key(model)
        own = [r for r in scene.riders if r.model == model]
        clip_srcs = sorted({(r.clips_from, json.dumps(r.bone_map, sort_keys=True)) for r in own if r.clips_from})
        tex = next((r.texture for r in own if getattr(r, "texture", None)), None)  # an .mpf's .ssh bank
        partners = mpf_partners(model, tex) if model.lower().endswith(".mpf") else (None, [])
        ch_key = content_key(BUILD_VERSION, "characters", CHARACTERS_VERSION, "clip-sources/1", msrc, ratios,
                             [(_file_key(f), b) for f, b in clip_srcs],
                             [_file_key(f) for f in [partners[0]] + partners[1] if f is not None],
                             *_allow_key(scene))

        def make_characters(model: str = model, clip_srcs: list[tuple[str, str]] = clip_srcs,
                            tex: str | None = tex) -> StepOutput:
            m: Any = load_mpf_rider(model, texture=tex) if tex else load_rider_model(model, allow_paths=scene.allow_paths)
            own_clips, sources = sorted(m.clips), []  # which clips each rider may default to
            for f, b in clip_srcs:
                before = set(m.clips)
                m = add_rider_clips(m, [(f, json.loads(b))], allow_paths=scene.allow_paths)
                sources.append(sorted(set(m.clips) - before))  # in clip_srcs' order
            a, meta = character_arrays(m, ratios=ratios)
            return a, dict(meta, own_clips=own_clips, clip_sources=sources)

        ca, cmeta = ctx.cached("characters", ch_key, make_characters)
        steps_done.append(ctx.result.steps["characters"])
        cid = "rider" if k == 0 else f"rider{k + 1}"
        cid_of[model] = cid
        for name, v in ca.items():
            arrays[f"characters/{cid}/{name}"] = v
        cmeta = dict(cmeta)
        clips_of[cid] = (cmeta.pop("own_clips", None), cmeta.pop("clip_sources", None), clip_srcs)  # not in the manifest
        cmeta["model"] = model if model.startswith("builtin:") else Path(model).name
        manifest["characters"][cid] = cmeta
    ctx.result.steps["characters"] = {"cached": all(d["cached"] for d in steps_done),
                                      "seconds": sum(d["seconds"] for d in steps_done),
                                      "key": steps_done[0]["key"], "models": len(models)}
    arrays["riders/matrix"] = rider_matrices(ctx.net, scene.riders)
    for r in scene.riders:
        cid = cid_of[r.model]
        cmeta = manifest["characters"][cid]
        clip = r.clip or _default_clip(r, cmeta, *clips_of[cid])
        if clip is not None and clip not in cmeta["clips"]:
            raise ConfigError(f"{scene.path}, line {r.line}: rider {r.name!r}: no clip {clip!r} in its model; "
                              f"clips: {', '.join(sorted(cmeta['clips']))}")
        manifest["riders"].append({"name": r.name, "character": cid, "clip": clip, "phase": r.phase,
                                   "heading": r.heading, "scale": r.scale})


# -------------------------------------------------------------- objects
def _object_sources(ctx: BuildContext) -> list[str]:
    return sorted({o.model for o in ctx.scene.objects})


def _objects_key(ctx: BuildContext) -> str | None:
    scene = ctx.scene
    if not scene.objects:
        return None
    srcs = _object_sources(ctx)
    src_keys = [m if m.startswith("builtin:") else _file_key(m) for m in srcs]
    placements = [(o.name, o.model, list(o.position), o.heading, o.scale) for o in scene.objects]
    return content_key(BUILD_VERSION, "objects", "object_atlas/4", "object_lods/1", ctx.terrain_key, srcs, src_keys, placements,
                       ctx.manifest["lights"], *_allow_key(scene))


def _make_objects(ctx: BuildContext) -> StepOutput:
    return _objects_arrays(ctx.net, ctx.scene.objects, _object_sources(ctx), ctx.lights, ctx.scene.allow_paths)


def _store_objects(ctx: BuildContext, out: StepOutput) -> None:
    oa, ometa = out
    for k, v in oa.items():
        ctx.arrays[f"objects/{k}"] = v
    ctx.manifest["objects"] = ometa
    ctx.spheres = np.column_stack([oa["center"], oa["radius"]])


def _no_objects(ctx: BuildContext) -> None:
    ctx.manifest["objects"] = {"kinds": [], "meshes": {}, "instances": []}


# -------------------------------------------------------------- visibility
def _eye_heights(ctx: BuildContext) -> tuple[float, ...]:
    """The band the scene needs: the file's heights up to its highest camera eye (along its flight)
    or rider head above the snow (:func:`piste.pipeline.visibility.scene_eye_heights`)."""
    if "eye_heights" not in ctx.shared:
        vs = ctx.scene.visibility
        heads = (np.asarray(ctx.arrays["riders/matrix"])[:, :3, 3] + [0.0, 0.0, 1.7]) if "riders/matrix" in ctx.arrays \
            else np.zeros((0, 3))
        eyes = np.concatenate([camera_eyes(ctx.manifest["cameras"], ctx.centerline), heads])
        ctx.shared["eye_heights"] = scene_eye_heights(ctx.net, vs.eye_heights, eyes, vs.cell)
    heights: tuple[float, ...] = ctx.shared["eye_heights"]
    return heights


def _visibility_key(ctx: BuildContext) -> str | None:
    vs = ctx.scene.visibility
    if not vs.enabled:
        return None
    return content_key(BUILD_VERSION, "visibility", ctx.terrain_key, vs.cell, list(_eye_heights(ctx)), vs.method)


def _make_visibility(ctx: BuildContext) -> StepOutput:
    vs = ctx.scene.visibility
    v = compute_visibility(ctx.net, vs.cell, _eye_heights(ctx), method=vs.method, progress=ctx.progress)
    arrays, meta = v.to_arrays()
    return arrays, meta


def _store_visibility(ctx: BuildContext, out: StepOutput) -> None:
    ctx.shared["visibility"] = out  # the objects' bits and the report follow (object_visibility)


def _no_visibility(ctx: BuildContext) -> None:
    ctx.manifest["visibility"] = None
    ctx.manifest["report"] = {}


# the objects' bits on their own: moving an object does not redo the patches
def _object_method(ctx: BuildContext) -> str:
    """Exact rays up to :data:`OBJECT_RAYS_MAX` objects, else the patches' method."""
    method: str = ctx.shared["visibility"][1]["method"]
    return "rays" if 0 < len(ctx.spheres) <= OBJECT_RAYS_MAX else method


def _object_visibility_key(ctx: BuildContext) -> str | None:
    if not len(ctx.spheres):
        return None
    vs = ctx.scene.visibility
    return content_key(BUILD_VERSION, "object_visibility", ctx.terrain_key, ctx.spheres, vs.cell,
                       list(_eye_heights(ctx)), _object_method(ctx))


def _make_object_visibility(ctx: BuildContext) -> StepOutput:
    method = _object_method(ctx)
    v = compute_visibility(ctx.net, ctx.scene.visibility.cell, _eye_heights(ctx), objects=ctx.spheres, method=method,
                           patches=False)
    return {"object_bits": v.object_bits}, {"method": method}


def _store_object_visibility(ctx: BuildContext, out: StepOutput) -> None:
    _finish_visibility(ctx, out[0]["object_bits"])


def _no_object_visibility(ctx: BuildContext) -> None:
    va = ctx.shared["visibility"][0]
    _finish_visibility(ctx, np.zeros((va["patch_bits"].shape[0], 0), np.uint8))


def _finish_visibility(ctx: BuildContext, obits: np.ndarray) -> None:
    """The visibility members, manifest entry and culling report, once the objects' bits are known."""
    va, vmeta = ctx.shared["visibility"]
    arrays = ctx.arrays
    arrays["visibility/patch_bits"] = va["patch_bits"]
    arrays["visibility/object_bits"] = obits
    extra = {k: va[k] for k in ("ground_min", "level_bits") if k in va}  # the band (Visibility.in_band)
    for k, v in extra.items():
        arrays[f"visibility/{k}"] = v
    vmeta = dict(vmeta, n_objects=int(len(ctx.spheres)))
    ctx.manifest["visibility"] = vmeta
    vis = Visibility.from_arrays({"patch_bits": va["patch_bits"], "object_bits": obits, **extra}, vmeta)
    ctx.manifest["report"] = {"visibility": _visibility_report(ctx.net, vis, ctx.manifest["cameras"], ctx.centerline)}


# -------------------------------------------------------------- settings the runtime reads (each time)
def _make_settings(ctx: BuildContext) -> StepOutput:
    scene = ctx.scene
    lod, render = scene.lod, scene.render
    return {}, {
        "lod": {"near": lod.near, "far": lod.far, "character": list(lod.character), "ratios": list(lod.ratios),
                "morph": bool(lod.morph), "character_pixels": float(lod.character_pixels)},
        "render": {"size": list(render.size), "lightmap_mode": render.lightmap_mode, "fog": render.fog,
                   "face": render.face, "object_lod": render.object_lod, "aa": render.aa, "dof": render.dof,
                   "soft_shadows": render.soft_shadows, "occlusion": render.occlusion},
        # riders following the track and objects placed along it, made by the runtime (pipeline.preview)
        "pack": scene.pack.as_dict() if scene.pack else None,
        "auto_objects": scene.auto_objects.as_dict() if scene.auto_objects else None,
    }


#: the steps :func:`build_scene` walks, in order (see :class:`BuildStep`; add one with :func:`register_step`)
BUILD_STEPS: list[BuildStep] = [
    BuildStep("terrain", "the terrain source's bytes (or the course seed) and the [terrain] settings",
              _terrain_key, _make_terrain, _store_terrain),
    BuildStep("lod_errors", "terrain key (the LOD's per-patch flat / coarsest errors)",
              _lod_errors_key, _make_lod_errors, _store_lod_errors),
    BuildStep("lights", "inline and glTF lights and cameras (cheap: computed each time)",
              run=_run_lights, cache=False),
    BuildStep("lightmap", "terrain key, lights, [lightmap] res / gutter / shadows (bounces, sun_radius when set)",
              _lightmap_key, _make_lightmap, _store_lightmap),
    BuildStep("resident", "the terrain net and its light-map rects (computed each time: ~30 ms)",
              make=_make_resident, store=_store_resident, cache=False),
    BuildStep("shadow", "terrain key, the sun's direction (none without a sun)",
              _shadow_key, _make_shadow, _store_shadow),
    BuildStep("characters", "each rider model's bytes (or built-in name), clip sources, LOD ratios",
              run=_run_characters),
    BuildStep("objects", "terrain key, object models' bytes and placements, lights",
              _objects_key, _make_objects, _store_objects, absent=_no_objects),
    BuildStep("visibility", "terrain key, [visibility] cell, eye heights (the scene's band), method",
              _visibility_key, _make_visibility, _store_visibility, absent=_no_visibility),
    BuildStep("object_visibility", "terrain key, object bounds, cell, eye heights, method",
              _object_visibility_key, _make_object_visibility, _store_object_visibility,
              absent=_no_object_visibility, when=lambda ctx: ctx.scene.visibility.enabled),
    BuildStep("settings", "[lod], [render], [pack], [auto_objects] (cheap: computed each time)",
              make=_make_settings, store=_store_manifest, cache=False),
]


def register_step(step: BuildStep, *, after: str | None = None, before: str | None = None) -> BuildStep:
    """Add ``step`` to :data:`BUILD_STEPS`: after step ``after``, before step ``before``, or last
    (before the bundle is written).  Returns ``step``."""
    names = [s.name for s in BUILD_STEPS]
    if step.name in names or step.name == "write":
        raise ConfigError(f"build step {step.name!r} is registered already")
    for where in (after, before):
        if where is not None and where not in names:
            raise ConfigError(f"no build step {where!r} to place {step.name!r} beside: steps are {', '.join(names)}")
    i = names.index(after) + 1 if after is not None else names.index(before) if before is not None else len(names)
    BUILD_STEPS.insert(i, step)
    return step


def unregister_step(name: str) -> BuildStep:
    """Remove the step called ``name`` from :data:`BUILD_STEPS` (and return it)."""
    for i, s in enumerate(BUILD_STEPS):
        if s.name == name:
            return BUILD_STEPS.pop(i)
    raise ConfigError(f"no build step {name!r}: steps are {', '.join(s.name for s in BUILD_STEPS)}")


def build_scene(scene: SceneFile | str | os.PathLike[str], out: str | os.PathLike[str] | None = None,
                cache_dir: str | os.PathLike[str] | None = None, progress: bool = False, jobs: int = 1,
                use_cache: bool = True, steps: Sequence[BuildStep] | None = None) -> BuildResult:
    """Build the bundle of ``scene`` (a :class:`~piste.world.scene_file.SceneFile` or a path).

    Parameters
    ----------
    out : bundle path (default: the scene's path with suffix ``.piste``)
    cache_dir : step cache folder (default: ``.piste-cache`` beside the scene)
    progress : tqdm bars (steps, bake, visibility)
    jobs : light-map bake worker processes (1 = in this process)
    use_cache : False recomputes every step (and stores nothing)
    steps : the steps to walk, in order (default: :data:`BUILD_STEPS`)
    """
    t_all = time.perf_counter()
    if not isinstance(scene, SceneFile):
        scene = load_scene(scene)
    out_path = Path(out) if out is not None else Path(scene.path).with_suffix(".piste")
    cache = Cache((Path(cache_dir) if cache_dir is not None else default_cache_dir(scene.path)) if use_cache else None)
    result = BuildResult(out_path)
    ctx = BuildContext(scene, cache, result, cache_dir=cache_dir,
                       progress=progress, jobs=jobs,
                       manifest={"name": scene.name, "scene": Path(scene.path).name, "build": BUILD_VERSION})
    walk = tuple(BUILD_STEPS if steps is None else steps)

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=sum(s.cache for s in walk) + 1, desc="build", unit="step", leave=False)
    for step in walk:
        if bar is not None and step.cache:
            bar.set_postfix_str(step.name)
        step.execute(ctx)
        if bar is not None and step.cache:
            bar.update(1)
    manifest = ctx.manifest
    manifest["inputs"] = {k: v["key"] for k, v in sorted(result.steps.items())}

    # -------------------------------------------------------------- write
    t0 = time.perf_counter()
    write_bundle(out_path, manifest, ctx.arrays)
    result.steps["write"] = {"cached": False, "seconds": time.perf_counter() - t0}
    if bar is not None:
        bar.update(1)
        bar.close()
    result.bytes = out_path.stat().st_size
    result.report = dict(manifest.get("report", {}))
    result.report["patches"] = len(ctx.net)
    result.report["riders"] = len(scene.riders)
    result.report["objects"] = len(scene.objects)
    result.report["lights"] = len(ctx.lights)
    result.report["cameras"] = [c["name"] for c in manifest["cameras"]]
    result.seconds = time.perf_counter() - t_all
    return result


def _objects_arrays(net: PatchNet, objects: Sequence[ActorSpec], sources: Sequence[str], lights: Lights,
                    allow_paths: tuple[Path, ...] = ()) -> StepOutput:
    """Compressed meshes per model, instance arrays and baked vertex colours of the placed objects."""
    kinds: list[str] = []
    meshes: dict[str, Any] = {}
    for s in sources:
        mesh = load_object_mesh(s, allow_paths=allow_paths)
        kname = s.split(":", 1)[1] if s.startswith("builtin:") else "gltf_" + "".join(
            ch if ch.isalnum() else "_" for ch in Path(s).stem)
        kinds.append(kname)
        meshes[kname] = mesh
    # glTF objects keep their own base colours (regions of the objects' atlas) and double-sided
    # materials (back faces added): pipeline.object_atlas
    # and alphaMode BLEND (drawn blended, sorted: ObjectSet.blend)
    parts = {}
    blend = []
    for s, k in zip(sources, kinds):
        if not s.startswith("builtin:"):
            gm = load_gltf(s, allow_paths=allow_paths)
            meshes[k], imgs = double_sided(meshes[k], gm, primitive_images(gm))
            parts[k] = (meshes[k].uv, imgs)
            if blends(gm) and k not in blend:
                blend.append(k)
    texture, uvs = pack_object_atlas(object_texture(), parts, {k: m.uv for k, m in meshes.items() if k not in parts})
    meshes = {k: compress_mesh(replace(m, uv=uvs[k]) if k in uvs else m) for k, m in meshes.items()}
    kind_of = dict(zip(sources, kinds))
    matrix = object_matrices(net, objects)
    kind = np.array([kinds.index(kind_of[o.model]) for o in objects], dtype=np.int64)
    # bounding spheres: each mesh's box centre, radius over its vertices, under the object matrix
    center = np.zeros((len(objects), 3))
    radius = np.zeros(len(objects))
    for i, (o, m) in enumerate(zip(objects, matrix)):
        cm = meshes[kinds[kind[i]]]
        p, _, _ = cm.decode()
        c = (p.min(0) + p.max(0)) / 2.0
        center[i] = m[:3, :3] @ c + m[:3, 3]
        radius[i] = float(np.linalg.norm(p - c, axis=1).max()) * abs(o.scale)
    objs = ObjectSet(meshes, tuple(kinds), kind, matrix, normal_matrix(matrix), center, radius, None, texture,
                     {k: int(np.count_nonzero(kind == i)) for i, k in enumerate(kinds)}, tuple(blend))
    colors = bake_vertex_colors(objs, lights)
    a: Arrays = {"kind": kind, "matrix": matrix, "center": center, "radius": radius,
                 "texture": np.asarray(objs.texture)}
    meta: Meta = {"kinds": list(kinds), "meshes": {}, "instances": [o.name for o in objects],
            "vertex_colors": "half-bright RGB8 per instance vertex (128 = 1.0), full lighting equation, no shadows"}
    for k in kinds:
        cm = meshes[k]
        p = f"meshes/{k}/"
        a.update({p + "positions": cm.positions, p + "pos_offset": cm.pos_offset, p + "pos_extent": cm.pos_extent,
                  p + "uv": cm.uv, p + "uv_offset": cm.uv_offset, p + "uv_extent": cm.uv_extent,
                  p + "normals": cm.normals, p + "indices": cm.indices})
        a[f"colors/{k}"] = colors[k]
        # its level chain as the renderer would simplify it at every start (stored: ~3 ms less a start)
        a.update({p + n: v for n, v in lod_arrays(object_lods(cm.decode()[0], cm.indices)).items()})
        meta["meshes"][k] = {"normal_bits": int(cm.normal_bits), "radius": float(cm.radius), "blend": k in blend,
                             "vertices": cm.n_vertices,
                             "triangles": cm.n_triangles, "bytes": int(cm.nbytes),
                             "bytes_float": int(cm.uncompressed_nbytes(cm.n_vertices, cm.n_triangles))}
    return a, meta


def _default_clip(rider: ActorSpec, cmeta: dict[str, Any], own_clips: list[str] | None, sources: list[list[str]] | None,
                  clip_srcs: Sequence[tuple[str, str]]) -> str | None:
    """The clip a rider without ``clip`` plays: the first of its own clips, i.e. of its
    ``clips_from`` file's when it has one, else of its model's own (not the clips another rider of
    the same model brought with its ``clips_from``); the first of all with a character step cached
    before these were recorded.  ``sources[i]``: the clips ``clip_srcs[i]`` added."""
    if rider.clips_from and sources is not None:
        key = (rider.clips_from, json.dumps(rider.bone_map, sort_keys=True))
        i = next((i for i, src in enumerate(clip_srcs) if tuple(src) == key), None)
        if i is not None and i < len(sources) and sources[i]:
            return sources[i][0]
    elif own_clips:
        return own_clips[0]
    return next(iter(sorted(cmeta["clips"])), None)


def _visibility_report(net: PatchNet, vis: Visibility, cameras: list[dict[str, Any]],
                       centerline: np.ndarray | None) -> dict[str, Any]:
    """% of patches drawn, frustum alone vs frustum + visibility: along the track (default course)
    and from the scene's cameras."""
    out: dict[str, Any] = {}
    if centerline is not None:
        cams = [track_camera(centerline, float(t), height=9.0) for t in np.linspace(0.02, 0.98, 49)]
        out["track"] = culling_report(net, vis, cams)
    cams = [camera_from_dict(c) for c in cameras]
    out["cameras"] = culling_report(net, vis, cams)
    mat = vis.patch_matrix()
    out["mean_visible_pct"] = float(100.0 * mat.mean())
    return out
