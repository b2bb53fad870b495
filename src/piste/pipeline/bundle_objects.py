"""A built bundle as the scene's objects: the runtime's view of a ``.piste`` file.

:mod:`piste.formats.bundle` reads and writes the arrays and the manifest (:class:`BundleData`);
this module turns them into the objects the renderer draws: the terrain :class:`PatchNet` (with
its light-map tiles), the :class:`LightMap`, the :class:`Lights`, the cameras, the visibility
sets, and, when first asked for, the placed objects and the riders' character model and LODs.

API
---
::

    load_bundle(path, verify=True, warm=False) -> Bundle
    Bundle                 ``.net``, ``.lightmap``, ``.lights``, ``.cameras``, ``.visibility``, ``.centerline``,
                           ``.objects()``, ``.vertex_colors()``, ``.rider_model()``, ``.rider_lods()``,
                           ``.track_texture()``, ``.lightmap_texels()``, ``.arrays``, ``.manifest``, ``.camera(name)``
    bundle_from_data(BundleData) -> Bundle
    lights_from_dict(d) -> Lights          ``Lights.to_dict()`` back (infinite ranges may be "inf")
    camera_from_dict(d) -> Camera          :func:`piste.formats.bundle.camera_to_dict` back
    resident_members(net) -> (arrays, manifest entry)   the terrain's vertex blocks as the build stores them
    lod_error_members(net) -> (arrays, manifest entry)  the terrain LOD's per-patch error table, likewise

The terrain's GPU-resident vertex blocks (:class:`piste.terrain.resident.ResidentTerrain`) are
stored by the build (:data:`RESIDENT_MEMBER`, uncompressed, for nets up to
:data:`STORED_BLOCKS_BUDGET`): a load keeps them on the net, so the first frame draws at once (a
fresh process built them in a background thread and its first frame waited ~0.1 s for them).
Bundles without them (``piste.bundle/1``, big nets, another block layout) still load: the blocks
are then built at run time as before.  Likewise the terrain LOD's per-patch errors of the flat and
coarsest levels (:data:`LOD_ERRORS_MEMBER`, the ``lod_errors`` build step): a load keeps them on
the net (:func:`piste.terrain.lod.keep_patch_errors`) so the first frame does not compute them;
without them (or of another format or levels) they are computed at the first frame as before.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt

from piste._data import DataMethods
from piste.character.lod import LOD
from piste.character.model import Model
from piste.errors import ConfigError, FormatError, PisteError
from piste.formats.bundle import RESIDENT_MEMBER, BundleData, camera_to_dict, read_bundle_deferred
from piste.lighting.lightmap import LightMap
from piste.lighting.lights import AmbientLight, DirectionalLight, Lights, PointLight, SpotLight
from piste.lighting.vertex import choose_lights_many
from piste.pipeline.characters import lods_from_arrays, model_from_arrays
from piste.pipeline.visibility import Visibility
from piste.render.textures import LIGHT_CLIP, TRACK_TEXEL, light_texels_in_range
from piste.terrain.lod import LEVELS, STORED_ERROR_LEVELS, keep_patch_errors, kept_bounds, patch_error_table
from piste.terrain.net import TOPOLOGY_ARRAYS, TOPOLOGY_FORMAT, PatchNet
from piste.terrain.resident import (RESIDENT_FLOATS, RESIDENT_FORMAT, ResidentTerrain, keep_resident, resident_fits,
                                    resident_terrain)
from piste.world.camera import Camera
from piste.world.object_lod import LOD_ARRAYS, stored_lods
from piste.world.objects import CompressedMesh, ObjectSet, normal_matrix

__all__ = ["Bundle", "load_bundle", "bundle_from_data", "lights_from_dict", "camera_from_dict", "camera_to_dict",
           "resident_members", "RESIDENT_MEMBER", "STORED_BLOCKS_BUDGET", "lod_error_members", "LOD_ERRORS_MEMBER",
           "LOD_ERRORS_FORMAT"]

_T = TypeVar("_T")

#: the largest vertex blocks a build stores (bytes, uncompressed: 44 B a vertex, 116 vertices a
#: patch, ~13k patches); bigger nets' blocks are built at run time (they would swell the bundle)
STORED_BLOCKS_BUDGET = 64 << 20


def resident_members(net: PatchNet) -> tuple[dict, dict | None]:
    """The terrain's resident vertex blocks as the build stores them: ``({RESIDENT_MEMBER: (N B, 11)
    float32}, manifest entry {"levels", "format"})`` for ``net`` (light-map rects set), or ``({},
    None)`` when they are not drawn resident or exceed :data:`STORED_BLOCKS_BUDGET`.  Written
    uncompressed (:data:`piste.formats.bundle.STORED_MEMBERS`: inflating them cost as much as building them)."""
    if not resident_fits(net) or len(net) * sum(n * n for n in LEVELS) * RESIDENT_FLOATS * 4 > STORED_BLOCKS_BUDGET:
        return {}, None
    return {RESIDENT_MEMBER: ResidentTerrain(net, LEVELS).vertices}, {"levels": [int(x) for x in LEVELS],
                                                                      "format": RESIDENT_FORMAT}


#: the terrain LOD's per-patch error table (the ``lod_errors`` build step)
LOD_ERRORS_MEMBER = "lod_errors/patch_errors"
#: what its manifest entry's ``format`` says (bump when the errors are computed otherwise: an older
#: table is then ignored and the errors computed at the first frame, as for a bundle without one)
LOD_ERRORS_FORMAT = 1


def lod_error_members(net: PatchNet) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The terrain LOD's per-patch errors as the build stores them: ``({LOD_ERRORS_MEMBER: (N, 2)
    float64}, manifest entry {"levels", "format"})`` (:func:`piste.terrain.lod.patch_error_table`
    for the flat and coarsest levels), so that a fresh process's first frame need not compute them."""
    return ({LOD_ERRORS_MEMBER: patch_error_table(net, STORED_ERROR_LEVELS)},
            {"levels": [int(x) for x in STORED_ERROR_LEVELS], "format": LOD_ERRORS_FORMAT})


def _keep_lod_errors(path: str | os.PathLike[str], man: dict[str, Any], arrays: dict[str, np.ndarray],
                     net: PatchNet) -> bool:
    """Keep the bundle's stored LOD error table on ``net`` (True), or False when it has none this
    piste reads (older bundles, other levels or format: computed at the first frame as before).
    FormatError naming the member when it does not fit the net (shape, dtype, not finite)."""
    info = man.get("lod_errors")
    if not isinstance(info, dict) or LOD_ERRORS_MEMBER not in arrays or info.get("format") != LOD_ERRORS_FORMAT \
            or info.get("levels") != [int(x) for x in STORED_ERROR_LEVELS]:
        return False
    try:
        keep_patch_errors(net, arrays[LOD_ERRORS_MEMBER], STORED_ERROR_LEVELS)
    except PisteError as exc:
        raise FormatError(path, f"invalid terrain LOD error table ({exc})", field=f"{LOD_ERRORS_MEMBER}.npy") from None
    return True


def _stored_blocks(man: dict) -> bool:
    """Whether the bundle stores vertex blocks this piste draws (its levels and block format)."""
    info = (man.get("terrain") or {}).get("resident")
    return isinstance(info, dict) and info.get("format") == RESIDENT_FORMAT and \
        info.get("levels") == [int(x) for x in LEVELS] and RESIDENT_MEMBER in man.get("members", {})


def lights_from_dict(d: dict) -> Lights:
    """:class:`piste.lighting.Lights` from ``Lights.to_dict()`` output (infinite ranges may be
    the string "inf")."""
    kinds = {"ambient": AmbientLight, "directional": DirectionalLight, "point": PointLight, "spot": SpotLight}
    out = []
    for kind, items in d.items():
        for item in items:
            kw = dict(item)
            if isinstance(kw.get("range"), str):
                kw["range"] = float(kw["range"])
            out.append(kinds[kind](**kw))
    return Lights(tuple(out))


def camera_from_dict(d: dict) -> Camera:
    """The :class:`piste.world.camera.Camera` of a manifest entry (:func:`camera_to_dict`)."""
    return Camera(np.array(d["eye"]), np.array(d["target"]), up=np.array(d["up"]), fov_y=d["fov_y"], near=d["near"],
                  far=d["far"], ortho_height=d.get("ortho_height"), name=str(d.get("name") or ""))


def _manifest_errors(fn: Callable[..., _T]) -> Callable[..., _T]:
    """A damaged manifest (its SHA-256 sums cover the arrays, not the manifest) or inconsistent
    arrays give a FormatError naming the bundle, never a raw KeyError / ValueError (issue 10)."""

    @functools.wraps(fn)
    def wrapper(obj: Any, *args: Any, **kwargs: Any) -> _T:
        path = getattr(obj, "path", None)
        try:
            return fn(obj, *args, **kwargs)
        except FormatError as exc:
            if exc.path is not None:
                raise
            raise FormatError(path, str(exc).split(": ", 1)[-1], field=exc.field) from None
        except PisteError as exc:  # a light or camera the manifest describes is invalid
            raise FormatError(path, f"invalid manifest entry: {exc}", field="manifest.json") from None
        except (KeyError, TypeError, ValueError, IndexError, AttributeError, ZeroDivisionError, OverflowError) as exc:
            raise FormatError(path, f"damaged bundle: the manifest does not match its arrays "
                                    f"({type(exc).__name__}: {exc})", field="manifest.json") from None

    return wrapper


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class Bundle(DataMethods):
    """A loaded bundle.

    Attributes
    ----------
    path : Path;  manifest : dict;  arrays : {name: ndarray}
    net : piste.terrain.PatchNet (light-map rects set);  lightmap : piste.lighting.LightMap (its atlas
    read-only when the bundle stores it uncompressed: copy it to edit it)
    lights : piste.lighting.Lights;  cameras : {name: piste.world.camera.Camera} (in scene order)
    visibility : piste.pipeline.visibility.Visibility or None
    centerline : (k, 3) track centre line (the default course) or None
    """

    path: Path
    manifest: dict
    arrays: dict
    net: PatchNet
    lightmap: LightMap
    lights: Lights
    cameras: dict
    visibility: Visibility | None = None
    centerline: np.ndarray | None = None
    _cache: dict = field(default_factory=dict, repr=False)

    @property
    def name(self) -> str:
        return str(self.manifest.get("name", self.path.stem))

    def camera(self, name: str | None = None) -> Camera:
        """The camera called ``name`` (default: the first)."""
        if not self.cameras:
            raise ConfigError(f"{self.path}: the scene has no cameras")
        if name is None:
            return next(iter(self.cameras.values()))
        if name not in self.cameras:
            raise ConfigError(f"{self.path}: no camera {name!r}; the scene has {', '.join(self.cameras)}")
        return self.cameras[name]

    @_manifest_errors
    def objects(self) -> ObjectSet | None:
        """The placed objects as a :class:`piste.world.objects.ObjectSet` (None when there are none)."""
        if "objects" in self._cache:
            return self._cache["objects"]
        info = self.manifest.get("objects") or {}
        kinds = tuple(info.get("kinds", ()))
        if not kinds:
            self._cache["objects"] = None
            return None
        a = self.arrays
        meshes = {}
        for k in kinds:
            p = f"objects/meshes/{k}/"
            m = info["meshes"][k]
            meshes[k] = CompressedMesh(k, a[p + "positions"], a[p + "pos_offset"], a[p + "pos_extent"], a[p + "uv"],
                                       a[p + "uv_offset"], a[p + "uv_extent"], a[p + "normals"], int(m["normal_bits"]),
                                       a[p + "indices"], float(m["radius"]), lods=self._object_lods(p))
        kind = a["objects/kind"].astype(np.int64)
        matrix = a["objects/matrix"].astype(np.float64)
        vl = None
        if len(self.lights.direct) or len(self.lights.ambient):
            vl = choose_lights_many(self.lights, a["objects/center"])
        tex = a.get("objects/texture")
        counts = {k: int(np.count_nonzero(kind == i)) for i, k in enumerate(kinds)}
        blend = tuple(k for k in kinds if info["meshes"][k].get("blend", False))  # glTF alphaMode BLEND kinds
        objs = ObjectSet(meshes, kinds, kind, matrix, normal_matrix(matrix), a["objects/center"].astype(np.float64),
                         a["objects/radius"].astype(np.float64), vl, tex, counts, blend)
        self._cache["objects"] = objs
        return objs

    def _object_lods(self, prefix: str) -> list | None:
        """The level chain stored beside the object mesh at ``prefix`` (``objects/meshes/KIND/``: the
        build's :func:`piste.world.object_lod.object_lods`, so a renderer's set-up does not simplify
        every kind again), or None when the bundle has none (built before they were stored).  FormatError
        naming the member when they do not fit the mesh."""
        a = self.arrays
        if not all(prefix + n in a for n in LOD_ARRAYS):
            return None
        try:
            idx, tris, err = (a[prefix + n] for n in LOD_ARRAYS)
            return stored_lods(idx, tris, err, len(a[prefix + "positions"]), len(a[prefix + "indices"]))
        except PisteError as exc:
            member = str(exc).split(":", 1)[0] if str(exc).split(":", 1)[0] in LOD_ARRAYS else LOD_ARRAYS[0]
            raise FormatError(self.path, f"invalid object levels of detail ({exc})", field=f"{prefix}{member}.npy") from None

    @_manifest_errors
    def vertex_colors(self) -> dict:
        """Baked per-instance vertex colours ``{kind: (k, v, 3) uint8}`` half-bright."""
        info = self.manifest.get("objects") or {}
        return {k: self.arrays[f"objects/colors/{k}"] for k in info.get("kinds", ())}

    @_manifest_errors
    def rider_model(self) -> Model | None:
        """The riders' character :class:`piste.character.Model` (skeleton, LOD-0 mesh, clips) or None."""
        if "rider_model" in self._cache:
            return self._cache["rider_model"]
        info = self.manifest.get("characters") or {}
        if not info:
            self._cache["rider_model"] = None
            return None
        name = sorted(info)[0]
        m = model_from_arrays(self.arrays, f"characters/{name}/", info[name])
        self._cache["rider_model"] = m
        return m

    @_manifest_errors
    def rider_lods(self) -> list[LOD] | None:
        """The riders' LODs (:class:`piste.character.LOD` list, palettes as built) or None."""
        if "rider_lods" in self._cache:
            return self._cache["rider_lods"]
        info = self.manifest.get("characters") or {}
        if not info:
            return None
        name = sorted(info)[0]
        lods = lods_from_arrays(self.arrays, f"characters/{name}/", info[name], self.rider_model())
        self._cache["rider_lods"] = lods
        return lods


    def track_texture(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The track's projected texture as the build stored it: ``(field (H, W) float16, rect (4,)
        float64)``, :func:`piste.render.textures.track_field` of :attr:`centerline` over the net's
        bounds as :func:`~piste.render.textures.track_texels` uploads it (a renderer's set-up need not
        compute it: ~3-5 ms of a fresh process), or None when the bundle has none or made it at another
        grid spacing (the renderer then computes it).  FormatError naming the member when it does not
        fit the net's bounds at that spacing."""
        info = self.manifest.get("terrain") or {}
        f, rect = self.arrays.get("terrain/track_field"), self.arrays.get("terrain/track_rect")
        if f is None or rect is None or self.centerline is None or info.get("track_texel") != TRACK_TEXEL:
            return None
        # (the net's bounds from its per-patch bounds, which the renderer's culling tree keeps anyway)
        lo, hi = (np.asarray(b, dtype=np.float64)[:2] for b in kept_bounds(self.net))
        w, h = (max(int(np.ceil((hi[i] - lo[i]) / TRACK_TEXEL)), 2) for i in (0, 1))
        want = np.array([lo[0], lo[1], lo[0] + w * TRACK_TEXEL, lo[1] + h * TRACK_TEXEL])
        if f.dtype != np.float16 or f.shape != (h, w):
            raise FormatError(self.path, f"expected the track field as a ({h}, {w}) float16 array (the net's bounds at "
                                         f"{TRACK_TEXEL} m texels), got {f.shape} {f.dtype}", field="terrain/track_field.npy")
        if np.shape(rect) != (4,) or not np.array_equal(np.asarray(rect, dtype=np.float64), want):
            raise FormatError(self.path, f"expected the track field's rectangle {want.tolist()} (the net's bounds), got "
                                         f"{np.asarray(rect).tolist()}", field="terrain/track_rect.npy")
        return f, want

    def lightmap_texels(self) -> np.ndarray:
        """The light map as the terrain pass uploads it: the build's stored ``lightmap/texels``
        (``(H, W, 3) float16``, :func:`piste.render.textures.light_texels` of the atlas: a renderer's
        set-up need not convert the float32 atlas, ~2-4 ms of a fresh process), or :attr:`lightmap`'s
        atlas itself when the bundle has no texels (an older bundle) or the atlas was replaced after
        loading (the renderer converts it).  FormatError naming the member when the stored texels are
        not the atlas's shape in float16 or hold a texel outside ``[0, LIGHT_CLIP]`` (NaN, inf, negative)."""
        atlas, t = self.lightmap.atlas, self.arrays.get("lightmap/texels")
        if t is None or atlas is not self.arrays.get("lightmap/atlas"):
            return atlas
        want = (*np.shape(atlas)[:2], 3)
        if t.dtype != np.float16 or t.shape != want:
            raise FormatError(self.path, f"expected the light-map texels as a {want} float16 array (the atlas's "
                                         f"size), got {t.shape} {t.dtype}", field="lightmap/texels.npy")
        if not light_texels_in_range(t):
            raise FormatError(self.path, f"expected light-map texels in [0, {LIGHT_CLIP}] (finite, not negative)",
                              field="lightmap/texels.npy")
        return t

    def sun_visibility(self, direction: npt.ArrayLike) -> tuple[np.ndarray, tuple[float, ...]] | None:
        """Where the terrain sees a sun shining along ``direction`` (3,), as the build stored it
        (the ``shadow`` step: ``(field (H, W) float32, rect (x0, y0, x1, y1))``, exactly what
        :func:`piste.render.shadow_pass.sun_visibility` gives), or None when the bundle has none or
        holds it for another direction (the runtime then computes it)."""
        info = self.manifest.get("shadow") or {}
        f, rect = self.arrays.get("shadow/sun_visibility"), self.arrays.get("shadow/sun_rect")
        stored = info.get("sun_direction")
        if f is None or rect is None or stored is None or f.ndim != 2 or np.shape(rect) != (4,):
            return None
        try:
            same = np.array_equal(np.asarray(stored, dtype=np.float64).ravel(),
                                  np.asarray(direction, dtype=np.float64).ravel())
        except (TypeError, ValueError):
            return None
        if not same:
            return None
        return np.asarray(f, dtype=np.float32), tuple(float(x) for x in rect)


def _terrain_net(path: str | os.PathLike[str], man: dict[str, Any], arrays: dict[str, np.ndarray]) -> PatchNet:
    """The bundle's terrain :class:`PatchNet`: its stored topology taken (checked) when the build
    stored one of this format, else computed.  FormatError naming the member when invalid."""
    t = man.get("terrain") or {}
    kw = dict(uv=arrays["terrain/uv"], lightmap_rect=arrays["lightmap/rects"], tol=t.get("tol"),
              name=t.get("name", "terrain"))
    topo = None  # the topology the build stored (read_bundle checked its members), else computed here
    if t.get("topology") == TOPOLOGY_FORMAT:
        topo = {k: arrays[f"terrain/{k}"] for k in TOPOLOGY_ARRAYS}
    try:
        return (PatchNet(arrays["terrain/control_points"], **kw) if topo is None else
                PatchNet.from_topology(arrays["terrain/control_points"], topo, **kw))
    except Exception as exc:
        member = "control_points"
        if topo is not None and "stored topology " in str(exc):
            member = str(exc).split("stored topology ", 1)[1].split(":", 1)[0]
        raise FormatError(path, f"invalid terrain ({exc})", field=f"terrain/{member}.npy") from None


def _keep_blocks(path: str | os.PathLike[str], man: dict[str, Any], arrays: dict[str, np.ndarray], net: PatchNet) -> bool:
    """Keep the bundle's stored vertex blocks on ``net`` (True), or False when it has none this
    piste draws.  FormatError naming the member when they do not fit the net."""
    if not _stored_blocks(man) or RESIDENT_MEMBER not in arrays:
        return False
    try:
        keep_resident(net, arrays[RESIDENT_MEMBER], LEVELS)
    except PisteError as exc:
        raise FormatError(path, f"invalid resident vertex blocks ({exc})", field=f"{RESIDENT_MEMBER}.npy") from None
    return True


def _warm(net: PatchNet) -> None:
    """Start building the net's GPU-resident vertex blocks in the background (a renderer is about to
    draw it): they overlap the rest of the load and the renderer's set-up."""
    if resident_fits(net):
        resident_terrain(net, wait=False)


@_manifest_errors
def bundle_from_data(data: BundleData, warm: bool = False, net: PatchNet | None = None) -> Bundle:
    """Build the terrain net, light map, lights, cameras and visibility of a read bundle (objects
    and characters are built when first asked for).  Raises :class:`~piste.errors.FormatError`
    naming the file and member when they are not valid.  ``warm``: as soon as the net exists, start
    building its GPU-resident vertex blocks in the background (for a renderer about to draw it).
    ``net``: the terrain net already made from these arrays (:func:`load_bundle` makes it while the
    other members are still being read)."""
    path, man, arrays = data.path, data.manifest, data.arrays
    if net is None:
        net = _terrain_net(path, man, arrays)
        if not _keep_blocks(path, man, arrays, net) and warm:
            _warm(net)
    else:
        _keep_blocks(path, man, arrays, net)
    _keep_lod_errors(path, man, arrays, net)
    lm_info = man.get("lightmap", {})
    # the atlas as read (a read-only view of the bundle's mapped bytes: no 3 MB copy a start) when float32
    lightmap = LightMap(atlas=np.asarray(arrays["lightmap/atlas"], dtype=np.float32), rects=arrays["lightmap/rects"],
                        res=int(lm_info.get("res", 8)), gutter=int(lm_info.get("gutter", 1)), manifest=lm_info)
    try:
        lights = lights_from_dict(man.get("lights", {}))
        cameras = {c["name"]: camera_from_dict(c) for c in man.get("cameras", [])}
    except (KeyError, TypeError, ValueError) as exc:
        raise FormatError(path, f"bad lights or cameras in the manifest ({exc})", field="manifest.json") from None
    vis = None
    if man.get("visibility"):
        vis = Visibility.from_arrays({"patch_bits": arrays["visibility/patch_bits"],
                                      "object_bits": arrays["visibility/object_bits"],
                                      **{k: arrays[f"visibility/{k}"] for k in ("ground_min", "level_bits")
                                         if f"visibility/{k}" in arrays}}, man["visibility"])
    line = arrays.get("terrain/centerline")
    return Bundle(path, man, arrays, net, lightmap, lights, cameras, vis, line)


def load_bundle(path: str | os.PathLike[str], verify: bool = True, warm: bool = False) -> Bundle:
    """Load a ``.piste`` bundle as the scene's objects (:func:`piste.formats.bundle.read_bundle`, then
    :func:`bundle_from_data`).

    ``verify`` checks each member's SHA-256 against the manifest (the zip CRC is always checked).
    Raises :class:`~piste.errors.FormatError` on a missing file, a wrong format version, a missing
    or corrupt member.  ``warm``: start the terrain's resident vertex blocks in the background at
    once (``piste demo``/``render``/``view``: a fresh process's first frame waited for them).
    """
    early: dict = {}

    def terrain_ready(man: dict, arrays: dict) -> None:  # the terrain members are read, the rest not yet
        early["net"] = _terrain_net(path, man, arrays)
        if warm and not _stored_blocks(man):  # (stored blocks: kept once read, nothing to build)
            _warm(early["net"])

    # the big members' SHA-256 (or CRC-32) is checked in a second thread while the objects are built
    # (~10 ms of hashing for the default course's 21 MB, overlapping ~8 ms of this thread's work); a
    # corrupt member is named as such even when what its bytes broke raised first
    data, finish = read_bundle_deferred(path, verify, on_terrain=terrain_ready)
    try:
        return bundle_from_data(data, warm=warm, net=early.get("net"))
    finally:
        finish()  # (raises the corrupt member's FormatError, also over what its bytes broke)
