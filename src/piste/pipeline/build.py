"""``piste build``: a scene description -> one ``.piste`` bundle, every step pre-processed and cached.

Steps (each keyed by a content hash of what it reads; a key found in the cache is reused):

============== ============================================================ =====================
step           reads                                                        makes
============== ============================================================ =====================
terrain        the terrain source's bytes (or the course seed), settings    control points, UVs
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
build_scene(scene, out=None, cache_dir=None, progress=False, jobs=1) -> BuildResult
default_cache_dir(scene_path) -> Path        ``<scene folder>/.piste-cache``
BUILD_VERSION
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from piste.errors import ConfigError
from piste.formats.bundle import camera_to_dict, write_bundle
from piste.formats.gltf import load_gltf
from piste.formats.ssx.mpf_model import mpf_partners
from piste.lighting.baker import BAKE_VERSION, bake_lightmap
from piste.lighting.lights import Lights, default_lights
from piste.pipeline.bundle_objects import camera_from_dict, lights_from_dict
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
from piste.terrain.net import TOPOLOGY_FORMAT, PatchNet
from piste.world.camera import Camera, camera_planes, track_camera
from piste.world.course import track_centerline
from piste.world.objects import ObjectSet, bake_vertex_colors, compress_mesh, normal_matrix, object_texture
from piste.world.scene import sun_light
from piste.world.scene_file import SceneFile, load_scene

__all__ = ["build_scene", "BuildResult", "default_cache_dir", "BUILD_VERSION", "scene_lights", "scene_cameras"]

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
    steps: dict = field(default_factory=dict)
    report: dict = field(default_factory=dict)
    seconds: float = 0.0
    bytes: int = 0

    @property
    def cached(self) -> list:
        return [k for k, v in self.steps.items() if v.get("cached")]

    @property
    def rebuilt(self) -> list:
        return [k for k, v in self.steps.items() if not v.get("cached")]


def default_cache_dir(scene_path) -> Path:
    return Path(scene_path).resolve().parent / ".piste-cache"


def bake_partial_dir(scene_path, cache_dir=None) -> Path:
    """The folder where ``piste build`` keeps a light-map bake's resumable chunks:
    ``CACHE/bake-partial`` (``cache_dir``, default :func:`default_cache_dir`)."""
    return (Path(cache_dir) if cache_dir is not None else default_cache_dir(scene_path)) / "bake-partial"


def clean_command(scene_path, cache_dir=None) -> str:
    """The shell command that removes the chunks under :func:`bake_partial_dir` (``piste build --clean``)."""
    import shlex

    cmd = f"piste build --clean {shlex.quote(str(scene_path))}"
    return cmd + (f" --cache {shlex.quote(str(cache_dir))}" if cache_dir is not None else "")


def _json_lights(lights) -> dict:
    """``Lights.to_dict()`` with infinite ranges as the string "inf" (strict JSON)."""
    out = {}
    for kind, items in lights.to_dict().items():
        out[kind] = [{k: ("inf" if isinstance(v, float) and math.isinf(v) else v) for k, v in it.items()} for it in items]
    return out


def scene_lights(scene, gltf_cache: dict | None = None):
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


def scene_cameras(scene, net, centerline, gltf_cache: dict | None = None) -> list:
    """The scene's cameras as manifest dicts (``name``, eye, target, ..., optional ``track``)."""
    out = []
    lo, hi = net.bounds if net is not None else (None, None)  # planes not given follow the terrain's size
    for c in scene.cameras:
        if c.track is not None:
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


def _file_key(path) -> str:
    return content_key(Path(path))


def _allow_key(scene) -> tuple:
    """The scene's ``allow_paths`` as cache-key parts (none when empty, so existing keys stand):
    a step built while a folder was allowed is not reused once it no longer is."""
    return (("allow_paths", [str(p) for p in scene.allow_paths]),) if getattr(scene, "allow_paths", ()) else ()


def build_scene(scene, out=None, cache_dir=None, progress: bool = False, jobs: int = 1, use_cache: bool = True) -> BuildResult:
    """Build the bundle of ``scene`` (a :class:`~piste.world.scene_file.SceneFile` or a path).

    Parameters
    ----------
    out : bundle path (default: the scene's path with suffix ``.piste``)
    cache_dir : step cache folder (default: ``.piste-cache`` beside the scene)
    progress : tqdm bars (steps, bake, visibility)
    jobs : light-map bake worker processes (1 = in this process)
    use_cache : False recomputes every step (and stores nothing)
    """
    t_all = time.perf_counter()
    if not isinstance(scene, SceneFile):
        scene = load_scene(scene)
    out = Path(out) if out is not None else Path(scene.path).with_suffix(".piste")
    cache = Cache((Path(cache_dir) if cache_dir is not None else default_cache_dir(scene.path)) if use_cache else None)
    result = BuildResult(out)
    arrays: dict = {}
    manifest: dict = {"name": scene.name, "scene": Path(scene.path).name, "build": BUILD_VERSION}
    gltf_cache: dict = {}

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=8, desc="build", unit="step", leave=False)

    def step(name: str, key: str, make):
        t0 = time.perf_counter()
        if bar is not None:
            bar.set_postfix_str(name)
        got = cache.get(name, key)
        cached = got is not None
        if not cached:
            got = make()
            cache.put(name, key, *got)
        result.steps[name] = {"cached": cached, "seconds": time.perf_counter() - t0, "key": key[:16]}
        if bar is not None:
            bar.update(1)
        return got

    # -------------------------------------------------------------- terrain
    ts = scene.terrain
    src = _file_key(ts.path) if ts.path is not None else f"seed {ts.seed}"
    if ts.kind == "ssx_pbd":  # the .pbd and the texture / light-map banks beside it
        src = level_key(ts.path)
    terrain_key = content_key(BUILD_VERSION, "terrain", ts.kind, src, ts.seed, ts.spacing, ts.height_scale,
                              ts.height_offset, ts.key, ts.samples_per_patch, ts.smooth,
                              *((ts.nodata, ts.vertical_units) if ts.kind == "geotiff" else ()))

    def make_terrain():
        net = load_terrain(ts)
        a = {"control_points": net.control_points, "uv": net.uv}
        if ts.kind == "default":
            a["centerline"] = track_centerline(ts.seed)
        return a, {"name": net.name, "tol": float(net.tol)}

    ta, tm = step("terrain", terrain_key, make_terrain)
    net = PatchNet(ta["control_points"], uv=ta["uv"], tol=tm["tol"], name=tm["name"])
    centerline = ta.get("centerline")
    arrays["terrain/control_points"] = net.control_points
    arrays["terrain/uv"] = net.uv
    # the welded topology, so a load need not weld and match edges again (~0.1 s of a fresh process)
    arrays.update({f"terrain/{k}": v for k, v in net.topology().items()})
    if centerline is not None:
        arrays["terrain/centerline"] = centerline
    lo, hi = net.bounds
    manifest["terrain"] = {"name": tm["name"], "tol": tm["tol"], "kind": ts.kind, "patches": len(net),
                           "topology": TOPOLOGY_FORMAT, "bounds": [[float(x) for x in lo], [float(x) for x in hi]], "key": terrain_key}

    # -------------------------------------------------------------- lights and cameras
    lights = scene_lights(scene, gltf_cache)
    manifest["lights"] = _json_lights(lights)
    manifest["cameras"] = scene_cameras(scene, net, centerline, gltf_cache)

    # -------------------------------------------------------------- light map
    lm_spec = scene.lightmap
    # bounces / sun radius join the key only when set: the keys of existing builds stay as they are
    lm_gi = [lm_spec.bounces, lm_spec.sun_radius] if (lm_spec.bounces or lm_spec.sun_radius) else []
    lm_key = content_key(BUILD_VERSION, "lightmap", BAKE_VERSION, terrain_key, manifest["lights"], lm_spec.res,
                         lm_spec.gutter, lm_spec.shadows, *lm_gi)

    def make_lightmap():
        if ts.kind == "ssx_pbd":  # an SSX level brings its own light maps and textures (pipeline.ssx_level)
            return bundle_arrays(ts.path), {"stats": {}}
        partial = bake_partial_dir(scene.path, cache.root) if cache.root is not None else None
        lm = bake_lightmap(net, lights, res=lm_spec.res, gutter=lm_spec.gutter, shadows=lm_spec.shadows, jobs=jobs,
                           partial_dir=partial, progress=progress, bounces=lm_spec.bounces,
                           sun_radius=lm_spec.sun_radius, clean_command=clean_command(scene.path, cache_dir))
        if partial is not None:
            import shutil

            shutil.rmtree(partial / lm.manifest["key"], ignore_errors=True)
        st = {k: int(v) for k, v in (getattr(lm, "stats", None) or {}).items()}
        return {"atlas": lm.atlas.astype(np.float32), "rects": lm.rects.astype(np.float32)}, {"stats": st}

    la, lmeta = step("lightmap", lm_key, make_lightmap)
    arrays["lightmap/atlas"] = la["atlas"]
    arrays["lightmap/rects"] = la["rects"]
    if "base_texture" in la:
        arrays["terrain/base_texture"] = la["base_texture"]
    if "source" in la:  # an SSX level's stored Cs / As texels (ps2 mode, piste.render.ssx_pass)
        arrays["lightmap/source"] = la["source"]
    net.lightmap_rect = la["rects"].copy()
    manifest["lightmap"] = {"res": lm_spec.res, "gutter": lm_spec.gutter, "shadows": lm_spec.shadows,
                            **({"bounces": lm_spec.bounces, "sun_radius": lm_spec.sun_radius} if lm_gi else {}),
                            "atlas_size": [int(la["atlas"].shape[1]), int(la["atlas"].shape[0])],
                            "encoding": "float32 linear light, 1.0 = full", "stats": lmeta.get("stats", {})}

    # -------------------------------------------------------------- shadow (sun visibility)
    # where the terrain sees the sun, for the riders' shadows: computed here, not at every renderer
    # set-up (~0.2 s of a fresh process's first frame); the sun exactly as the runtime reads it back
    sun = sun_light(lights_from_dict(manifest["lights"]))
    if sun is not None:
        sun_dir = [float(x) for x in np.asarray(sun.direction, dtype=np.float64).ravel()]
        sv_key = content_key(BUILD_VERSION, "shadow", SHADOW_VERSION, terrain_key, sun_dir)

        def make_shadow():
            f, rect = sun_visibility(net, sun_dir)
            return {"sun_visibility": f, "sun_rect": np.asarray(rect, dtype=np.float64)}, {"sun_direction": sun_dir}

        sa, smeta = step("shadow", sv_key, make_shadow)
        arrays["shadow/sun_visibility"] = sa["sun_visibility"]
        arrays["shadow/sun_rect"] = sa["sun_rect"]
        manifest["shadow"] = {"sun_direction": smeta["sun_direction"], "version": SHADOW_VERSION}
    else:
        result.steps["shadow"] = {"cached": True, "seconds": 0.0, "key": "none"}

    # -------------------------------------------------------------- characters
    manifest["characters"] = {}
    manifest["riders"] = []
    if scene.riders:
        # one character per rider model (any number: each its own LODs, palettes, batches, clips);
        # the first keeps the id "rider", the others "rider2", "rider3", ... in the order of the file
        models = list(dict.fromkeys(r.model for r in scene.riders))
        ratios = tuple(scene.lod.ratios)
        cid_of = {}
        clips_of: dict = {}
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

            def make_characters(model=model, clip_srcs=clip_srcs, tex=tex):
                m = load_mpf_rider(model, texture=tex) if tex else load_rider_model(model, allow_paths=scene.allow_paths)
                own_clips, sources = sorted(m.clips), []  # which clips each rider may default to
                for f, b in clip_srcs:
                    before = set(m.clips)
                    m = add_rider_clips(m, [(f, json.loads(b))], allow_paths=scene.allow_paths)
                    sources.append(sorted(set(m.clips) - before))  # in clip_srcs' order
                a, meta = character_arrays(m, ratios=ratios)
                return a, dict(meta, own_clips=own_clips, clip_sources=sources)

            ca, cmeta = step("characters", ch_key, make_characters)
            steps_done.append(result.steps["characters"])
            cid = "rider" if k == 0 else f"rider{k + 1}"
            cid_of[model] = cid
            for name, v in ca.items():
                arrays[f"characters/{cid}/{name}"] = v
            cmeta = dict(cmeta)
            clips_of[cid] = (cmeta.pop("own_clips", None), cmeta.pop("clip_sources", None), clip_srcs)  # not in the manifest
            cmeta["model"] = model if model.startswith("builtin:") else Path(model).name
            manifest["characters"][cid] = cmeta
        result.steps["characters"] = {"cached": all(d["cached"] for d in steps_done),
                                      "seconds": sum(d["seconds"] for d in steps_done),
                                      "key": steps_done[0]["key"], "models": len(models)}
        arrays["riders/matrix"] = rider_matrices(net, scene.riders)
        for r in scene.riders:
            cid = cid_of[r.model]
            cmeta = manifest["characters"][cid]
            clip = r.clip or _default_clip(r, cmeta, *clips_of[cid])
            if clip is not None and clip not in cmeta["clips"]:
                raise ConfigError(f"{scene.path}, line {r.line}: rider {r.name!r}: no clip {clip!r} in its model; "
                                  f"clips: {', '.join(sorted(cmeta['clips']))}")
            manifest["riders"].append({"name": r.name, "character": cid, "clip": clip, "phase": r.phase,
                                       "heading": r.heading, "scale": r.scale})
    else:
        result.steps["characters"] = {"cached": True, "seconds": 0.0, "key": "none"}
        if bar is not None:
            bar.update(1)
    manifest["lod"] = {"near": scene.lod.near, "far": scene.lod.far, "character": list(scene.lod.character),
                       "ratios": list(scene.lod.ratios), "morph": bool(scene.lod.morph)}

    # -------------------------------------------------------------- objects
    spheres = np.zeros((0, 4))
    manifest["objects"] = {"kinds": [], "meshes": {}, "instances": []}
    if scene.objects:
        srcs = sorted({o.model for o in scene.objects})
        src_keys = [m if m.startswith("builtin:") else _file_key(m) for m in srcs]
        placements = [(o.name, o.model, list(o.position), o.heading, o.scale) for o in scene.objects]
        obj_key = content_key(BUILD_VERSION, "objects", "object_atlas/4", terrain_key, srcs, src_keys, placements,
                              manifest["lights"], *_allow_key(scene))

        def make_objects():
            return _objects_arrays(net, scene.objects, srcs, lights, scene.allow_paths)

        oa, ometa = step("objects", obj_key, make_objects)
        for k, v in oa.items():
            arrays[f"objects/{k}"] = v
        manifest["objects"] = ometa
        spheres = np.column_stack([oa["center"], oa["radius"]])
    else:
        result.steps["objects"] = {"cached": True, "seconds": 0.0, "key": "none"}
        if bar is not None:
            bar.update(1)

    # -------------------------------------------------------------- visibility
    vs = scene.visibility
    if vs.enabled:
        # the band the scene needs: the file's heights up to its highest camera eye (along its
        # flight) or rider head above the snow (piste.pipeline.visibility.scene_eye_heights)
        heads = (np.asarray(arrays["riders/matrix"])[:, :3, 3] + [0.0, 0.0, 1.7]) if "riders/matrix" in arrays \
            else np.zeros((0, 3))
        eye_heights = scene_eye_heights(net, vs.eye_heights,
                                        np.concatenate([camera_eyes(manifest["cameras"], centerline), heads]), vs.cell)
        vis_key = content_key(BUILD_VERSION, "visibility", terrain_key, vs.cell, list(eye_heights), vs.method)

        def make_visibility():
            v = compute_visibility(net, vs.cell, eye_heights, method=vs.method, progress=progress)
            return v.to_arrays()

        va, vmeta = step("visibility", vis_key, make_visibility)
        # the objects' bits on their own: moving an object does not redo the patches
        obj_method = "rays" if 0 < len(spheres) <= OBJECT_RAYS_MAX else vmeta["method"]
        ov_key = content_key(BUILD_VERSION, "object_visibility", terrain_key, spheres, vs.cell, list(eye_heights),
                             obj_method)

        def make_object_visibility():
            v = compute_visibility(net, vs.cell, eye_heights, objects=spheres, method=obj_method, patches=False)
            return {"object_bits": v.object_bits}, {"method": obj_method}

        if len(spheres):
            oa_, _ = step("object_visibility", ov_key, make_object_visibility)
            obits = oa_["object_bits"]
        else:
            obits = np.zeros((va["patch_bits"].shape[0], 0), np.uint8)
            result.steps["object_visibility"] = {"cached": True, "seconds": 0.0, "key": "none"}
        arrays["visibility/patch_bits"] = va["patch_bits"]
        arrays["visibility/object_bits"] = obits
        extra = {k: va[k] for k in ("ground_min", "level_bits") if k in va}  # the band (Visibility.in_band)
        for k, v in extra.items():
            arrays[f"visibility/{k}"] = v
        vmeta = dict(vmeta, n_objects=int(len(spheres)))
        manifest["visibility"] = vmeta
        vis = Visibility.from_arrays({"patch_bits": va["patch_bits"], "object_bits": obits, **extra}, vmeta)
        manifest["report"] = {"visibility": _visibility_report(net, vis, manifest["cameras"], centerline)}
    else:
        result.steps["visibility"] = {"cached": True, "seconds": 0.0, "key": "none"}
        manifest["visibility"] = None
        manifest["report"] = {}
        if bar is not None:
            bar.update(1)
    manifest["render"] = {"size": list(scene.render.size), "lightmap_mode": scene.render.lightmap_mode,
                          "fog": scene.render.fog, "face": scene.render.face,
                          "object_lod": scene.render.object_lod, "aa": scene.render.aa, "dof": scene.render.dof,
                          "soft_shadows": scene.render.soft_shadows, "occlusion": scene.render.occlusion}
    # riders following the track and objects placed along it, made by the runtime (pipeline.preview)
    manifest["pack"] = dict(scene.pack) if scene.pack else None
    manifest["auto_objects"] = dict(scene.auto_objects) if scene.auto_objects else None
    manifest["inputs"] = {k: v["key"] for k, v in sorted(result.steps.items())}

    # -------------------------------------------------------------- write
    t0 = time.perf_counter()
    write_bundle(out, manifest, arrays)
    result.steps["write"] = {"cached": False, "seconds": time.perf_counter() - t0}
    if bar is not None:
        bar.update(1)
        bar.close()
    result.bytes = out.stat().st_size
    result.report = dict(manifest.get("report", {}))
    result.report["patches"] = len(net)
    result.report["riders"] = len(scene.riders)
    result.report["objects"] = len(scene.objects)
    result.report["lights"] = len(lights)
    result.report["cameras"] = [c["name"] for c in manifest["cameras"]]
    result.seconds = time.perf_counter() - t_all
    return result


def _objects_arrays(net, objects, sources, lights, allow_paths=()):
    """Compressed meshes per model, instance arrays and baked vertex colours of the placed objects."""
    kinds = []
    meshes = {}
    for s in sources:
        mesh = load_object_mesh(s, allow_paths=allow_paths)
        kind = s.split(":", 1)[1] if s.startswith("builtin:") else "gltf_" + "".join(
            ch if ch.isalnum() else "_" for ch in Path(s).stem)
        kinds.append(kind)
        meshes[kind] = mesh
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
    a = {"kind": kind, "matrix": matrix, "center": center, "radius": radius, "texture": objs.texture}
    meta = {"kinds": list(kinds), "meshes": {}, "instances": [o.name for o in objects],
            "vertex_colors": "half-bright RGB8 per instance vertex (128 = 1.0), full lighting equation, no shadows"}
    for k in kinds:
        cm = meshes[k]
        p = f"meshes/{k}/"
        a.update({p + "positions": cm.positions, p + "pos_offset": cm.pos_offset, p + "pos_extent": cm.pos_extent,
                  p + "uv": cm.uv, p + "uv_offset": cm.uv_offset, p + "uv_extent": cm.uv_extent,
                  p + "normals": cm.normals, p + "indices": cm.indices})
        a[f"colors/{k}"] = colors[k]
        meta["meshes"][k] = {"normal_bits": int(cm.normal_bits), "radius": float(cm.radius), "blend": k in blend,
                             "vertices": cm.n_vertices,
                             "triangles": cm.n_triangles, "bytes": int(cm.nbytes),
                             "bytes_float": int(cm.uncompressed_nbytes(cm.n_vertices, cm.n_triangles))}
    return a, meta


def _default_clip(rider, cmeta: dict, own_clips, sources, clip_srcs):
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


def _visibility_report(net, vis, cameras, centerline) -> dict:
    """% of patches drawn, frustum alone vs frustum + visibility: along the track (default course)
    and from the scene's cameras."""
    out = {}
    if centerline is not None:
        cams = [track_camera(centerline, float(t), height=9.0) for t in np.linspace(0.02, 0.98, 49)]
        out["track"] = culling_report(net, vis, cams)
    cams = [camera_from_dict(c) for c in cameras]
    out["cameras"] = culling_report(net, vis, cams)
    mat = vis.patch_matrix()
    out["mean_visible_pct"] = float(100.0 * mat.mean())
    return out
