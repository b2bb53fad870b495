"""Rendering a built scene: the glue between a :class:`~piste.pipeline.bundle_objects.Bundle` and the renderer.

The renderer's entry point for a full scene is :class:`piste.render.scene_renderer.SceneRenderer`,
which draws a :class:`piste.world.scene.Scene` (course, riders following the track, objects).  A
bundle's scene differs in two ways, handled here without touching the renderer:

* riders stand where the scene file placed them and play their clips (:class:`PlacedRiders`, the
  :class:`~piste.world.riders.RiderSet` interface);
* the pre-computed visibility cuts the terrain patches and objects before frustum culling
  (:class:`BundleScene` filters objects; the terrain renderer's public
  :meth:`~piste.render.frame.TerrainRenderer.set_visibility` hook cuts the patches);
* objects are lit by the RGBs the build baked into the bundle
  (:meth:`~piste.render.object_pass.ObjectPass.set_vertex_colors`), not baked again.

A scene whose file has ``[pack] follow = "track"`` (the built-in default scene of ``piste demo``)
gets the riders running down the track, chased by the camera, and ``[auto_objects]`` the course's
trees, signs, rocks and rails placed along it (:func:`track_scene`): made here, at load, from the
keys the build carried into the manifest.

A scene without riders is drawn by :class:`piste.render.TerrainRenderer` plus the object pass.

API
---
::

    ScenePreview(bundle, size=None, ctx=None, visibility=True)   ``.render(camera, t) -> (H, W, 3) uint8``,
                                                                  ``.stats`` of the last frame, ``.reload(bundle)``
    track_scene(bundle, start=None, casts=()) -> Scene            the [pack] riders + [auto_objects] of a bundle
    track_pack(n=6) -> rows;  pack_track_ahead(n=6) -> metres     a pack of n riders, the track it needs ahead
    rider_casts(["FILE[:N]", ...]) -> [(model, pack rows)]        other rider models beside the pack
    cast_model(model) -> Model                                    a glTF rider as drawn (materials kept)
    camera_at(bundle, name, i, n) -> Camera                       a scene camera at frame i of n (track cameras fly)
    render_image(bundle, camera=None, size=None, t=0.0) -> image
    render_frames(bundle, camera, frames, size, fps, video=None, first_png=None) -> list of stats
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from piste._jit import WarmUpHold
from piste.character import BlendedMesh
from piste.errors import ConfigError, FormatError
# the glTF reader, the SSX terrain, the streamed tiles, depth of field, interlacing and video through the
# packages' lazy names (PEP 562): imported when a --rider-model, an SSX level, a tiled world, --dof,
# an interlaced or a video render asks, not by every bundle render
from piste import formats as _formats, render as _render
from piste.pipeline.bundle_objects import camera_from_dict
from piste.pipeline.characters import lods_from_arrays, merged_mesh, model_from_arrays
from piste.render.aa import AATarget, check_aa, downsample
from piste.render.context import create_context, save_png
from piste.render.frame import DEFAULT_FOG_DENSITY, TerrainRenderer
from piste.render.object_pass import ObjectPass
from piste.render.scene_renderer import SceneRenderer
from piste.render.sky_pass import HORIZON
from piste.render.trace import make_tracer
from piste.terrain.resident import resident_fits, resident_terrain
from piste.world.camera import Camera, track_camera, warn_if_no_terrain
from piste.world.course import TRACK_HALF_WIDTH
from piste.world.object_lod import DEFAULT_LOD_PIXELS
from piste.world.objects import place_objects
from piste.world.riders import DEFAULT_PACK, ClipTable, RiderState, pack_for, rider_model
from piste.world.scene import LOD_DISTANCES, RIDER_LOD_PIXELS, Scene, sun_light

if TYPE_CHECKING:
    import moderngl
    import numpy.typing as npt

    from piste.character.model import Model
    from piste.pipeline.bundle_objects import Bundle
    from piste.world.objects import ObjectSet

__all__ = ["PlacedRiders", "BundleScene", "clip_table", "cast_model", "rider_casts", "track_scene", "track_pack",
           "pack_track_ahead", "ScenePreview", "camera_at", "render_image", "render_frames"]


class PlacedRiders:
    """Riders at fixed places playing their clips (the :class:`piste.world.riders.RiderSet` interface).

    Parameters
    ----------
    model : the rider Model (clips);  matrices : (n, 4, 4) rider -> world
    clips : n clip names;  phases : (n,) seconds into each clip at t = 0
    """

    def __init__(self, model: Model, matrices: npt.ArrayLike, clips: Iterable[str], phases: npt.ArrayLike,
                 rate: float = 30.0, table: ClipTable | None = None) -> None:
        self.model = model
        self.table = table if table is not None else ClipTable(model, rate)
        self.matrix = np.asarray(matrices, dtype=np.float64).reshape(-1, 4, 4)
        self.clips = tuple(clips)
        self.clip_ids = np.array([self.table.clip_index(c) for c in self.clips], dtype=np.int64)
        self.phase = np.asarray(phases, dtype=np.float64).reshape(-1)

    def __len__(self) -> int:
        return len(self.clips)

    def state(self, t: float, camera_rider: int | None = None, **_ignored: Any) -> RiderState:
        """All riders at ``t`` seconds (:class:`piste.world.riders.RiderState`); the chase-camera
        keywords of :meth:`RiderSet.state` are accepted and ignored (scene cameras are used)."""
        m = self.matrix
        anchor = m[:, :3, 3].copy()
        normal = m[:, :3, 1] / np.linalg.norm(m[:, :3, 1], axis=1, keepdims=True)
        fwd = m[:, :3, 0] / np.linalg.norm(m[:, :3, 0], axis=1, keepdims=True)
        skin = self.table.skin_matrices(self.clip_ids, self.phase + float(t), m)
        return RiderState(float(t), anchor, normal, fwd, m, skin, self.clips, np.zeros(len(self)))


def clip_table(bundle: Bundle, character: str = "rider") -> ClipTable:
    """A :class:`piste.world.riders.ClipTable` filled straight from the bundle's pre-sampled clip
    tables (no curve sampling at load: the build did it)."""
    meta = bundle.manifest["characters"][character]
    prefix = f"characters/{character}/clips/"
    names = sorted(meta["clips"])
    skeleton = (bundle.rider_model() if character == _first_character(bundle) else
                model_from_arrays(bundle.arrays, f"characters/{character}/", meta)).skeleton
    return ClipTable.from_samples(skeleton, float(meta.get("rate", 30.0)), names,
                                  [meta["clips"][n]["duration"] for n in names],
                                  [bundle.arrays[prefix + n + "/translation"] for n in names],
                                  [bundle.arrays[prefix + n + "/rotation"] for n in names],
                                  [bundle.arrays[prefix + n + "/scale"] for n in names])


def _first_character(bundle: Bundle) -> str:
    chars = bundle.manifest.get("characters") or {}
    return "rider" if "rider" in chars else next(iter(chars), "rider")


class BundleScene(Scene):
    """A :class:`piste.world.scene.Scene` made from a bundle (riders placed, visibility applied).

    A bundle with several rider models (characters ``rider``, ``rider2``, ...): this scene holds
    the first one's riders and the objects; :attr:`casts` holds one BundleScene per other model
    (``character=``), which :class:`~piste.render.scene_renderer.SceneRenderer` draws with it.
    """

    def __init__(self, bundle: Bundle, character: str | None = None) -> None:  # noqa: D401 - Scene's own __init__ builds the default pack
        man = bundle.manifest
        first = _first_character(bundle)
        cid = character or first
        self.bundle = bundle
        self.character = cid
        self.net = bundle.net
        self.line = bundle.centerline
        self.lights = bundle.lights
        self.sun = sun_light(self.lights)
        if cid == first:
            self.model = bundle.rider_model()
            self.lods = bundle.rider_lods()
        else:
            meta = man["characters"][cid]
            self.model = model_from_arrays(bundle.arrays, f"characters/{cid}/", meta)
            self.lods = lods_from_arrays(bundle.arrays, f"characters/{cid}/", meta, self.model)
        self.skinners = [BlendedMesh(lod.palette, lod.mesh.positions, lod.mesh.normals) for lod in self.lods]
        all_riders = man.get("riders", [])
        mine = [i for i, r in enumerate(all_riders) if r.get("character", first) == cid]
        riders = [all_riders[i] for i in mine]
        rate = float(man["characters"][cid].get("rate", 30.0))
        self.riders = PlacedRiders(self.model, np.asarray(bundle.arrays["riders/matrix"])[mine], [r["clip"] for r in riders],
                                   [r["phase"] for r in riders], rate=rate, table=clip_table(bundle, cid))
        self.follow = 0
        self.casts = [BundleScene(bundle, c) for c in (man.get("characters") or {}) if c != cid] \
            if character is None else []
        if character is not None and cid != first:  # a cast: riders only
            self.objects = None
            self.lod_distances = tuple(man.get("lod", {}).get("character", LOD_DISTANCES))
            self.lod_pixels = float(man.get("lod", {}).get("character_pixels", RIDER_LOD_PIXELS))
            self.camera_kw = {}
            self.visibility = None
            return
        self.objects = bundle.objects()
        self.lod_distances = tuple(man.get("lod", {}).get("character", LOD_DISTANCES))
        self.lod_pixels = float(man.get("lod", {}).get("character_pixels", RIDER_LOD_PIXELS))
        self.camera_kw = {}
        self.visibility = bundle.visibility

    def update(self, t: float, aspect: float = 640.0 / 448.0, fov_y: float = 60.0, camera: Camera | None = None,
               height_px: float = 448.0) -> Any:
        sf = super().update(t, aspect=aspect, fov_y=fov_y, camera=camera, height_px=height_px)
        if self.visibility is not None and len(sf.objects_visible):
            keep = self.visibility.objects_at(sf.camera.eye)
            if keep is not None:
                sf.objects_visible = sf.objects_visible[keep[sf.objects_visible]]
        return sf


#: metres of track the pack needs ahead of its first rider's start
PACK_TRACK_AHEAD = 120.0
#: most riders a [pack] runs (``riders``; default the six of :data:`piste.world.riders.DEFAULT_PACK`)
MAX_PACK_RIDERS = 64
#: metres between one six of a larger pack and the next (the default six span 41 m, 8 m apart)
_PACK_PERIOD = 48.0


def track_pack(n: int = len(DEFAULT_PACK)) -> tuple:
    """The rows (:data:`piste.world.riders.DEFAULT_PACK`'s) of a pack of ``n`` riders running down
    the track: the default pack's first ``n``, and beyond six the default six again every
    ``_PACK_PERIOD`` metres further ahead (their carving phases shifted), so riders keep about 8 m
    apart."""
    n = int(n)
    if not 1 <= n <= MAX_PACK_RIDERS:
        raise ConfigError(f"a pack runs 1..{MAX_PACK_RIDERS} riders, got {n}")
    six = len(DEFAULT_PACK)
    out = []
    for i in range(n):
        clip, phase, ahead, across, amp, period = DEFAULT_PACK[i % six]
        k = i // six
        out.append((clip, (phase + 0.37 * k) % 1.0, ahead + _PACK_PERIOD * k, across, amp, period))
    return tuple(out)


def pack_track_ahead(n: int = len(DEFAULT_PACK)) -> float:
    """Metres of track a pack of ``n`` riders (:func:`track_pack`) needs ahead of rider 0's start:
    :data:`PACK_TRACK_AHEAD`, plus how much farther ahead its leading rider runs than the default
    pack's."""
    lead = max(r[2] for r in track_pack(n))
    return PACK_TRACK_AHEAD + max(lead - max(r[2] for r in DEFAULT_PACK), 0.0)
#: [auto_objects] count keys -> place_objects' keywords
_AUTO_COUNTS = {"trees": "n_trees", "signs": "n_signs", "rocks": "n_rocks", "rails": "n_rails"}


def auto_objects(bundle: Bundle) -> ObjectSet | None:
    """The course's objects placed along the track from the manifest's ``auto_objects``
    (``{"seed", "trees", "signs", "rocks", "rails"}``, the scene file's ``[auto_objects]``), or None."""
    auto = bundle.manifest.get("auto_objects")
    if not auto:
        return None
    if bundle.centerline is None:
        raise FormatError(bundle.path, "auto_objects need the default course's centre line", field="auto_objects")
    try:
        kw = {_AUTO_COUNTS[k]: int(auto[k]) for k in _AUTO_COUNTS if k in auto}
        seed = int(auto.get("seed", 0))
    except (TypeError, ValueError):
        raise FormatError(bundle.path, f"manifest.json: auto_objects: expected integers, got {auto!r}",
                          field="auto_objects") from None
    if not all(0 <= v <= 10_000 for v in kw.values()):
        raise FormatError(bundle.path, f"manifest.json: auto_objects: expected counts in 0..10000, got {auto!r}",
                          field="auto_objects")
    return place_objects(bundle.net, bundle.centerline, bundle.lights, seed=seed,
                         track_half_width=TRACK_HALF_WIDTH, **kw)


def cast_model(model: Model) -> Model:
    """A glTF rider model as the runtime draws it, the way a scene build makes it: its skinned
    primitives merged into one mesh whose packed texture keeps each primitive's own base colour and
    material (:func:`piste.pipeline.characters.merged_mesh`; merged by
    :func:`piste.world.riders.rider_model` alone, a model of base-colour factors such as BrainStem or
    RobotExpressive was drawn white), then checked and given its RGBA texture by ``rider_model``."""
    return rider_model(replace(model, meshes=[merged_mesh(model)]))


def rider_casts(specs: Iterable[str]) -> list[tuple[Model, Any]]:
    """``FILE[:N]`` specs (``--rider-model``) -> ``[(rider model, pack rows)]``: N riders (default 2)
    of each skinned glTF model, placed between the default pack's riders (``track_scene(casts=)``)."""
    out = []
    for k, spec in enumerate(specs):
        path, _, n = str(spec).rpartition(":") if ":" in str(spec) and str(spec).rsplit(":", 1)[1].isdigit() \
            else (str(spec), "", "2")
        if not Path(path).is_file():
            raise ConfigError(f"--rider-model {spec}: no such file {path}")
        m = cast_model(_formats.load_gltf(path))
        out.append((m, pack_for(m, int(n), ahead=4.0 + 2.0 * k, across=0.0, spacing=9.0)))
    return out


def track_scene(bundle: Bundle, start: float | None = None, casts: Iterable[tuple[Model, Any]] = ()) -> Scene:
    """The :class:`piste.world.scene.Scene` of a bundle built with ``[pack] follow = "track"``: a
    pack of ``pack.riders`` riders (default the six of the default pack; :func:`track_pack`)
    running down the track (rider 0 at fraction ``start`` of it at t = 0; default: the scene file's
    ``pack.start``), the camera chasing rider 0, and the ``[auto_objects]`` (else the bundle's own
    objects).  ``casts``: ``[(rider model, pack rows)]`` of other models to run beside the pack
    (``piste demo --rider-model``)."""
    pack = bundle.manifest.get("pack") or {}
    line = bundle.centerline
    if line is None:
        raise FormatError(bundle.path, "a [pack] following the track needs the default course's centre line",
                          field="pack")
    n = pack.get("riders", len(DEFAULT_PACK))
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_PACK_RIDERS:
        raise FormatError(bundle.path, f"manifest.json: pack.riders: expected an integer in 1..{MAX_PACK_RIDERS}, "
                                       f"got {n!r}", field="pack.riders")
    rows = track_pack(n)
    frac = float(pack.get("start", 0.12)) if start is None else float(start)
    length = float(np.linalg.norm(np.diff(line[:, :2], axis=0), axis=1).sum())
    at = frac * length
    ahead = pack_track_ahead(n)
    if at > length - ahead:
        raise ConfigError(f"--start {frac}: the {n} riders need {ahead:.0f} m of track ahead; use at most "
                          f"{max(length - ahead, 0.0) / length:.2f}")
    objs = auto_objects(bundle)
    if objs is None:
        objs = bundle.objects()
    net, lights = bundle.net, bundle.lights
    scene = Scene(net, line, lights, objects=objs, start=at, pack=rows)
    scene.casts = [Scene(net, line, lights, model=m, pack=rows, start=at) for m, rows in casts]
    scene.lod_distances = tuple(bundle.manifest.get("lod", {}).get("character", scene.lod_distances))
    scene.lod_pixels = float(bundle.manifest.get("lod", {}).get("character_pixels", RIDER_LOD_PIXELS))
    for c in scene.casts:
        c.lod_distances, c.lod_pixels = scene.lod_distances, scene.lod_pixels
    return scene


def terrain_renderer(bundle: Bundle, size: tuple[int, int], ctx: moderngl.Context | None, atlas: Any, lightmap: Any = "bundle",
                     stream_wait: bool = True, kw: dict[str, Any] | None = None) -> Any:
    """The terrain renderer a source's manifest asks for (``terrain.source``), or None for the
    default :class:`~piste.render.frame.TerrainRenderer`: a tiled world streams its tiles
    (:class:`~piste.render.streaming.StreamingTerrain`; the bundle's net is the local terrain), an
    SSX level with its stored light-map texels blends them in ``ps2`` mode
    (:class:`~piste.render.ssx_pass.SsxTerrainRenderer`), riders and all."""
    kw = dict(kw or {})
    t = bundle.manifest.get("terrain") or {}
    if t.get("source") == "tiles":
        return _render.StreamingTerrain(t["root"], bundle.net, size=size, ctx=ctx,
                                budget_bytes=int(float(t.get("budget_mb", 256.0)) * 2**20), wait=stream_wait,
                                objects=bundle.objects())  # a tiled world's objects page with its tiles
    if "lightmap/source" in bundle.arrays and lightmap == "bundle":  # an SSX level: ps2 mode
        return _render.SsxTerrainRenderer(bundle.net, bundle.arrays["lightmap/source"], size=size, ctx=ctx, lightmap=atlas, **kw)
    return None


def camera_at(bundle: Bundle, name: str | None = None, i: int = 0, n: int = 1) -> Camera:
    """The scene camera ``name`` (default: the first) at frame ``i`` of ``n``: a track camera flies
    from its first to its second fraction of the track; other cameras stay put."""
    cams = bundle.manifest.get("cameras", [])
    if not cams:
        raise ConfigError(f"{bundle.path}: the scene has no cameras")
    if name is None:
        d = cams[0]
    else:
        d = next((c for c in cams if c["name"] == name), None)
        if d is None:
            raise ConfigError(f"{bundle.path}: no camera {name!r}; the scene has {', '.join(c['name'] for c in cams)}")
    if d.get("track") and bundle.centerline is not None:
        a, b = d["track"]
        f = a if n <= 1 else a + (b - a) * i / (n - 1)
        return track_camera(bundle.centerline, f, height=d.get("height", 9.0), fov_y=d["fov_y"], near=d["near"],
                            far=d["far"])
    return camera_from_dict(d)


def _flag(opt: dict, rman: dict, key: str) -> bool:
    """An on/off render option: the caller's, else the scene file's ``[render]`` key, else off."""
    v = opt[key] if opt[key] is not None else rman.get(key, False)
    if not isinstance(v, bool):
        raise ConfigError(f"{key} must be true or false, got {v!r}")
    return v


class ScenePreview:
    """The runtime: renders a bundle's scene off-screen with the renderer's passes (see the module
    docstring).  ``piste render``, ``piste view SCENE`` and ``piste demo`` all make their frames
    here (:meth:`render`).

    Parameters
    ----------
    bundle : Bundle;  size : (W, H) (default: the scene's render size)
    ctx : a moderngl context to share (default: a new headless one)
    visibility : apply the bundle's visibility sets (False: frustum culling alone)
    scene : a :class:`piste.world.scene.Scene` on the bundle's terrain, lights and centre line to
        draw instead of the bundle's own riders and objects (``piste demo``: six riders running down
        the track, chased by the camera, and the course's objects placed at run time); default: the
        bundle's scene
    lightmap : the light-map atlas: "bundle" (the baked one, default), "placeholder" (lit from the
        normals, no shadows) or None (unlit)
    object_lighting : "baked" (default: the RGBs the bundle holds), "dynamic" or "points"
    shadows, specular : the riders' projected shadows and specular pass
    lightmap_mode : "modulate" or "ps2" (default: the scene's)
    start : a ``[pack]`` scene: fraction of the track where rider 0 starts (default: the scene file's)
    casts : a ``[pack]`` scene: ``[(rider model, pack rows)]`` of other models beside the pack
    terrain_only : draw the terrain alone (no riders, no objects)
    face : the riders' faces, "morph", "null_bones" or "off" (default: the scene file's
        ``render.face``, else "morph")
    fog : fog density per metre, or "auto" (the default density scaled to the scene's size);
        default: the scene file's ``render.fog``, else "auto"
    object_lod : the objects' LOD error allowed on screen in pixels (0: full meshes); default: the
        scene file's ``render.object_lod``, else 0.5
    lod_morph : geomorph the terrain between LOD levels (the CLI's ``--lod-morph``); default: the
        scene file's ``[lod] morph``, else on
    stream_wait : a tiled world: every frame waits for the tiles it wants (default; the same picture
        whatever the loader's timing); False in a window (far stand-ins while tiles load)
    trace : a ``.json`` path: every frame's CPU steps and GPU passes recorded as a Chrome / Perfetto
        trace (:mod:`piste.render.trace`; the CLI's ``--trace``), written by :meth:`release`
    aa : anti-aliasing, "off", "msaa2", "msaa4", "msaa8" or "fxaa" (:mod:`piste.render.aa`; the
        CLI's ``--aa``); default: the scene file's ``render.aa``, else "off"
    soft_shadows, occlusion : PCSS rider shadows / occlusion culling (issue 27; the CLI's
        ``--soft-shadows`` / ``--occlusion on|off``); default: the scene file's ``render`` keys, else off
    supersample : draw at N x N the size and box-filter down (the anti-aliasing reference; the
        objects' LOD error scaled by N so the same meshes are drawn); default 1
    dof : depth of field, ``(focus metres, aperture = lens radius metres)`` (:mod:`piste.render.dof`;
        the CLI's ``--dof FOCUS_M:APERTURE``), or "off"; default: the scene file's ``render.dof``, else off

    Notes
    -----
    After :meth:`render`, ``stats`` holds the frame's counts and ``frame`` the renderer's own
    result (a :class:`piste.render.Frame` for terrain-only scenes, else a
    :class:`piste.render.SceneImage`) with its timings.
    """

    def __init__(self, bundle: Bundle, size: Sequence[int] | None = None, ctx: moderngl.Context | None = None,
                 visibility: bool = True, scene: Scene | None = None, lightmap: Any = "bundle",
                 object_lighting: str = "baked", shadows: bool = True, specular: bool = True,
                 lightmap_mode: str | None = None, start: float | None = None, casts: Iterable[tuple[Model, Any]] = (),
                 terrain_only: bool = False, face: str | None = None, fog: float | str | None = None, object_lod: float | None = None,
                 lod_morph: bool | None = None, stream_wait: bool = True, trace: str | os.PathLike[str] | None = None,
                 aa: str | None = None, supersample: int = 1, dof: str | tuple[float, float] | None = None,
                 soft_shadows: bool | None = None, occlusion: bool | None = None) -> None:
        if not (isinstance(lightmap, str) and lightmap in ("bundle", "placeholder")) and lightmap is not None:
            raise ConfigError(f"lightmap must be 'bundle', 'placeholder' or None, got {lightmap!r}")
        self.ctx = ctx if ctx is not None else create_context()
        self._own_ctx = ctx is None
        self.use_visibility = bool(visibility)
        self.size = tuple(size) if size is not None else tuple(bundle.manifest.get("render", {}).get("size", (640, 448)))
        if isinstance(supersample, bool) or not isinstance(supersample, int) or not 1 <= supersample <= 8:
            raise ConfigError(f"supersample must be an integer in 1..8, got {supersample!r}")
        self.supersample = supersample
        self.render_size = (self.size[0] * supersample, self.size[1] * supersample)  # what the renderers draw
        self.options: dict[str, Any] = {"scene": scene, "lightmap": lightmap, "object_lighting": object_lighting,
                        "shadows": bool(shadows), "specular": bool(specular), "lightmap_mode": lightmap_mode,
                        "start": start, "casts": list(casts), "terrain_only": bool(terrain_only), "face": face,
                        "fog": fog, "object_lod": object_lod, "lod_morph": lod_morph,
                        "stream_wait": bool(stream_wait), "aa": aa, "dof": dof, "soft_shadows": soft_shadows,
                        "occlusion": occlusion}
        self.stats: dict = {}
        self.frame: Any = None  # the last frame drawn: a Frame (terrain only) or a SceneImage
        self.tracer = make_tracer(trace, self.ctx)  # the no-op NULL_TRACER without a trace file
        # numba's background import (~0.8 s, mostly holding the GIL) waits until the first frame is
        # drawn: beside it a fresh process's first frame took ~0.13 s longer (released by the next
        # frame; release() drops it without starting numba: `piste render` draws one frame)
        self._warm_up_hold = WarmUpHold()
        self._setup(bundle)

    def _setup(self, bundle: Bundle) -> None:
        self.bundle = bundle
        streamed = (bundle.manifest.get("terrain") or {}).get("source") == "tiles"
        if not streamed and resident_fits(bundle.net):  # the terrain's resident vertex blocks, built (in the background)
            resident_terrain(bundle.net, wait=False)  # while the scene and passes set up: a fresh
            # process's first frame waited ~0.2 s for them when they started with the terrain pass
        man = bundle.manifest
        opt = self.options
        lod = man.get("lod", {})
        morph = opt["lod_morph"] if opt["lod_morph"] is not None else lod.get("morph", True)
        kw = {"lod_near": lod.get("near"), "lod_far": lod.get("far"), "lod_morph": bool(morph)}
        if bundle.centerline is not None:  # (with the track's texture when the build stored it)
            kw.update(track=bundle.centerline, track_half_width=TRACK_HALF_WIDTH, track_texture=bundle.track_texture())
        if "terrain/base_texture" in bundle.arrays:  # an SSX level's own textures (pipeline.ssx_level)
            kw["base_texture"] = bundle.arrays["terrain/base_texture"]
        # (the build's float16 texels, as uploaded, when it stored them)
        atlas = bundle.lightmap_texels() if opt["lightmap"] == "bundle" else opt["lightmap"]
        self.lightmap_mode = opt["lightmap_mode"] or man.get("render", {}).get("lightmap_mode", "modulate")
        mode = opt["object_lighting"]
        colors = bundle.vertex_colors()
        rman = man.get("render") or {}
        face = opt["face"] or rman.get("face") or "morph"
        if face not in ("morph", "null_bones", "off"):
            raise ConfigError(f"face must be 'morph', 'null_bones' or 'off', got {face!r}")
        fog = opt["fog"] if opt["fog"] is not None else rman.get("fog", "auto")
        if fog != "auto" and (isinstance(fog, (bool, str)) or not isinstance(fog, (int, float)) or not fog >= 0):
            raise ConfigError(f"fog must be a density per metre >= 0 or 'auto', got {fog!r}")
        self.face = face
        self.aa = check_aa(opt["aa"] if opt["aa"] is not None else rman.get("aa", "off"))
        dof = opt["dof"] if opt["dof"] is not None else rman.get("dof")
        self.dof = None if dof is None or dof == "off" else _render.check_dof(*dof) if isinstance(dof, (list, tuple)) and \
            len(dof) == 2 else _render.check_dof(dof, None)
        if self.dof is not None and self.dof[1] == 0.0:
            self.dof = None  # (a pinhole: nothing to blur)
        self.fog = None if fog == "auto" else float(fog)  # None: the renderer's scene-sized default
        olod = opt["object_lod"] if opt["object_lod"] is not None else rman.get("object_lod", DEFAULT_LOD_PIXELS)
        if isinstance(olod, bool) or not isinstance(olod, (int, float)) or not 0 <= olod <= 64:
            raise ConfigError(f"object_lod must be pixels in 0..64 (0: full meshes), got {olod!r}")
        olod = olod * self.supersample  # the same meshes as at the output size
        pack = bool(man.get("pack")) and not opt["terrain_only"]
        # a run-time scene or riders following the track ([pack]): the camera chases rider 0
        self.follow = (opt["scene"] is not None or pack) and not opt["terrain_only"]
        if self.follow or (man.get("riders") and not opt["terrain_only"]):
            if opt["scene"] is not None:
                self.scene = opt["scene"]
            elif pack:
                self.scene = track_scene(bundle, opt["start"], opt["casts"])
            else:
                self.scene = BundleScene(bundle)
            if self.scene.net is not bundle.net:  # (a scene of its own: the stored track texture is the bundle net's)
                kw.pop("track_texture", None)
            terrain = terrain_renderer(bundle, self.render_size, self.ctx, atlas, opt["lightmap"], opt["stream_wait"], kw)
            sun = getattr(self.scene, "sun", None)  # the build's sun visibility when it is this scene's
            sunlight = bundle.sun_visibility(sun.direction) \
                if sun is not None and opt["shadows"] and self.scene.net is bundle.net else None
            self.renderer = SceneRenderer(self.scene, size=self.render_size, ctx=self.ctx, lightmap=atlas,
                                          object_lighting=mode, shadows=opt["shadows"], specular=opt["specular"],
                                          face=None if face == "off" else face, terrain=terrain, sunlight=sunlight,
                                          object_lod=float(olod), occlusion=_flag(opt, rman, "occlusion"),
                                          soft_shadows=_flag(opt, rman, "soft_shadows"), **kw)
            self.terrain = self.renderer.terrain
            self.renderer.tracer = self.tracer
            self.objects = None
            if self.renderer.objects is not None and mode == "baked" and self.scene.objects is bundle.objects():
                self.renderer.objects.set_vertex_colors(colors)
        else:
            self.scene = None
            self.renderer = None
            self.terrain = terrain_renderer(bundle, self.render_size, self.ctx, atlas, opt["lightmap"], opt["stream_wait"], kw)
            if self.terrain is None:
                self.terrain = TerrainRenderer(bundle.net, size=self.render_size, ctx=self.ctx, lightmap=atlas, **kw)
            objs = None if opt["terrain_only"] else (auto_objects(bundle) or bundle.objects())
            self.objects = None
            if objs is not None:
                self.objects = ObjectPass(self.ctx, objs, bundle.lights, mode=mode, lod_pixels=float(olod),
                                          colors=colors if mode == "baked" and objs is bundle.objects() else None)
        if self.aa != "off" or self.dof is not None:  # the frame drawn into a target that post-processes it when read
            old = self.terrain.target
            self.terrain.target = AATarget(self.ctx, old.size, self.aa, dof=self.dof)
            old.release()
            self.stats["aa_samples"] = self.terrain.target.samples
        # the pre-computed visibility in front of frustum culling
        self.terrain.set_visibility(bundle.visibility if self.use_visibility else None)

    def reload(self, bundle: Bundle) -> None:
        """Swap in a rebuilt bundle (the GL context is kept)."""
        self._release_passes()
        self._setup(bundle)

    def render(self, camera: Camera | None = None, t: float = 0.0, lod: bool = True, debug: str | None = None,
               read: bool = True) -> np.ndarray | None:
        """One frame ``(H, W, 3) uint8`` for ``camera`` at ``t`` seconds (None with ``read=False``);
        see :meth:`_render_frame`.  Traced as one frame (``trace=``)."""
        with self.tracer.frame():
            return self._render_frame(camera, t, lod, debug, read)

    def _render_frame(self, camera=None, t: float = 0.0, lod: bool = True, debug: str | None = None,
                      read: bool = True) -> np.ndarray | None:
        """One frame ``(H, W, 3) uint8`` for ``camera`` at ``t`` seconds (None with ``read=False``).

        ``camera`` defaults to the chase camera of a run-time ``scene``, else the scene's first
        camera; ``lod=False`` draws every patch 8x8; ``debug`` is a terrain debug view ("lod",
        "wire", "base", "lightmap")."""
        if self.frame is not None:  # (a frame was drawn: numba may warm up now)
            self._warm_up_hold.release()
        w, h = self.size
        if camera is None and not self.follow:
            camera = camera_at(self.bundle)
        cam = replace(camera, aspect=w / h) if camera is not None else None
        if cam is not None and getattr(self.bundle, "net", None) is not None:  # a blank frame says why, once
            if self.__dict__.get("_bounds_of") is not self.bundle.net:
                self._bounds_of, self._bounds = self.bundle.net, self.bundle.net.bounds
            warn_if_no_terrain(cam, *self._bounds, seen=self.__dict__.setdefault("_no_terrain_seen", set()))
        if self.renderer is not None:
            img = self.renderer.render(t, camera=cam, lod=lod, lightmap_mode=self.lightmap_mode, debug=debug,
                                       read=read and self.dof is None, fog=self.fog)
            if self.dof is not None:  # the post pass needs the frame's camera (a chase camera is made by the renderer)
                self.terrain.target.camera = img.scene.camera
                img.image = self.terrain.target.read() if read else None
            self.frame = img
            self.stats.update(img.stats)
            self.stats.update(self.terrain.cull_stats)
            return self._output(img.image) if read else None
        if self.dof is not None:
            self.terrain.target.camera = cam
        with self.tracer.gpu_pass("terrain"):
            frame = self.terrain.render(cam, lod=lod, lightmap_mode=self.lightmap_mode, debug=debug,
                                        read=read and self.objects is None, fog="scene" if self.fog is None else self.fog)
        self.frame = frame
        image = frame.image
        if self.objects is not None:
            vis_objs = self.objects.objects.visible(cam.frustum_planes(), max_distance=cam.far, eye=cam.eye)
            if self.use_visibility and self.bundle.visibility is not None and len(vis_objs):
                keep = self.bundle.visibility.objects_at(cam.eye)
                if keep is not None:
                    vis_objs = vis_objs[keep[vis_objs]]
            density = DEFAULT_FOG_DENSITY if self.fog is None else self.fog
            with self.tracer.gpu_pass("objects"):
                self.objects.draw(cam.view_projection(), cam.eye, vis_objs, fog=(*HORIZON, density) if density else None)
            self.ctx.finish()
            self.stats["objects_drawn"] = int(len(vis_objs))
            image = self.terrain.target.read() if read else None
            frame.image = image
        self.stats.update(self.terrain.cull_stats)
        self.stats.update(terrain_patches=frame.patches, terrain_triangles=frame.triangles)
        return self._output(image) if read else None

    def _output(self, image: np.ndarray) -> np.ndarray:
        """A frame as returned: ``(H, W, 3) uint8``, box-filtered down from the drawn size when
        supersampled."""
        return downsample(image[..., :3], self.supersample)

    def frames(self, times: Iterable[float], lod: bool = True, read: bool = True) -> Iterator[np.ndarray | None]:
        """Frames ``(H, W, 3) uint8`` (None without ``read``) at each of ``times`` along the chase
        camera, pipelined where the scene has riders (:meth:`piste.render.SceneRenderer.frames`: the
        next frame's CPU work runs while the GL draws this one); else one :meth:`render` a frame.
        After each, :attr:`frame` and :attr:`stats` describe that frame."""
        if self.renderer is None or not self.follow or self.dof is not None:
            for t in times:
                yield self.render(None, t, lod=lod, read=read)
            return
        for img in self._traced(self.renderer.frames(times, read=read, lod=lod, lightmap_mode=self.lightmap_mode,
                                                     fog=self.fog)):
            self.frame = img
            self.stats.update(img.stats)
            self.stats.update(self.terrain.cull_stats)
            yield self._output(img.image) if read else None
            self._warm_up_hold.release()

    def _traced(self, frames):
        """``frames`` (a generator) with each step traced as a frame: in a pipelined loop a frame's
        span holds its passes and the next frame's planning, which runs while the GPU draws it."""
        it = iter(frames)
        while True:
            with self.tracer.frame():
                item = next(it, None)
            if item is None:
                return
            yield item

    def _release_passes(self) -> None:
        if self.renderer is not None:
            self.renderer.release()
        else:
            self.terrain.release()
            if self.objects is not None:
                self.objects.release()
        self.renderer = self.objects = None

    def release(self) -> None:
        self._warm_up_hold.release(start=False)  # (no frames follow: numba need not load)
        self._release_passes()
        self.tracer.close()  # (before the context goes: the trace names its renderer)
        if self._own_ctx:
            self.ctx.release()


def render_image(bundle: Bundle, camera: str | None = None, size: Sequence[int] | None = None, t: float = 0.0,
                 ctx: moderngl.Context | None = None) -> np.ndarray:
    """One image ``(H, W, 3) uint8`` of ``bundle`` from scene camera ``camera``."""
    p = ScenePreview(bundle, size=size, ctx=ctx)
    try:
        return p.render(camera_at(bundle, camera), t)
    finally:
        p.release()


def render_frames(bundle: Bundle, camera: str | Camera | Sequence[Camera] | None = None, frames: int = 1,
                  size: Sequence[int] | None = None, fps: int = 30, video: str | os.PathLike[str] | None = None,
                  first_png: str | os.PathLike[str] | None = None, ctx: moderngl.Context | None = None,
                  progress: bool = False, interlace: bool = False,
                  flicker_filter: bool = False, **preview_kw: Any) -> list[dict[str, Any]]:
    """Render ``frames`` frames (time ``i / fps``; track cameras fly), writing the first to
    ``first_png`` and all to the MP4 ``video`` when given.  Returns each frame's stats.  ``camera``:
    a scene camera's name, a :class:`piste.world.camera.Camera` (stays put), a list of cameras (one
    a frame: a tiled world's flight) or None (the first
    scene camera; a ``[pack]`` scene, riders following the track, is seen by the chase camera, as in
    ``piste demo``).  ``preview_kw``: :class:`ScenePreview` options (``lod_morph``, ``trace``, ...).

    ``interlace``: each frame woven from two fields drawn half a frame apart (even lines at
    ``i / fps``, odd lines at ``(i + 0.5) / fps``: :mod:`piste.render.interlace`), each vertically
    filtered [1 2 1] / 4 first with ``flicker_filter``; a returned frame's ``ms`` covers both fields."""
    if flicker_filter and not interlace:
        raise ConfigError("flicker_filter filters the fields of interlaced video: use it with interlace")
    p = ScenePreview(bundle, size=size, ctx=ctx, **preview_kw)
    writer = None
    out = []
    try:
        if video is not None:
            writer = _render.VideoWriter(video, fps=fps)
        it = range(frames)
        if progress:
            from tqdm import tqdm

            it = tqdm(it, desc="rendering", unit="frame", leave=False)
        for i in it:
            chase = camera is None and p.follow

            def cam_at(k, i=i, chase=chase):  # k: a frame (k + 0.5: a frame's second field)
                if isinstance(camera, (list, tuple)):
                    return camera[i]
                return camera if isinstance(camera, Camera) else (None if chase else camera_at(bundle, camera, k, frames))
            t0 = time.perf_counter()
            if interlace:
                img = _render.weave(*(p.render(cam_at(i + h), (i + h) / float(fps)) for h in (0.0, 0.5)),
                            filtered=flicker_filter)
            else:
                img = p.render(cam_at(i), i / float(fps))
            ms = (time.perf_counter() - t0) * 1e3
            if i == 0 and first_png is not None:
                save_png(first_png, img)
            if writer is not None:
                writer.append(img)
            out.append(dict(p.stats, ms=ms))
        if writer is not None:
            writer.close()
            writer = None
    finally:
        if writer is not None:
            writer.abort()
        p.release()
    return out
