"""The completed real-time scene (the talk's last demo): course + riders + objects + lights + camera.

:class:`Scene` holds everything that does not change from frame to frame (the course net, its
centre line, the world's lights, the rider model with its three LODs and their blended-matrix
skinners, the pack of riders, the placed objects).  :meth:`Scene.update` does the per-frame CPU
work that is not the terrain's (the renderer's :class:`piste.render.TerrainRenderer` does terrain
LOD, culling and tessellation):

1. **animation**: every rider's pose from the pre-sampled clip tables, rider matrices on the exact
   surface (:class:`piste.world.riders.RiderSet`);
2. **character LOD**: ``high`` / ``medium`` / ``low`` per rider, the coarsest whose error projects
   under ``lod_pixels`` (default 1 px, the objects' rule: :func:`piste.world.object_lod.choose_lods`
   on the rider's bounding sphere) -- each level's error (:meth:`Scene.rider_lod_errors`: stored in a
   bundle, else measured once) is its bind-pose Hausdorff-like distance to the full mesh plus how far
   its coarser palette moves its vertices in the clips' poses; ``lod_pixels=0``: by distance to the camera
   (``lod_distances``, what it was);
3. **skinning** on the CPU with the SSX Tricky blended-matrix palette (one palette per LOD, the
   rider's world matrix folded into the palette, so vertices come out in world space): the riders
   of one LOD in one call; every rider also at the low LOD for its projected shadow;
4. **lights**: each rider's 1 ambient + 3 directional lights chosen at its position;
5. **objects**: the instances whose bounding spheres meet the view frustum.

Pure numpy (no OpenGL): the render passes take a :class:`SceneFrame`.

API
---
Scene.default(seed=0, lights=None, n_objects="default")   the default course scene
Scene.update(t, aspect=640/448, height_px=448) -> SceneFrame
Scene.rider_lod_errors() -> (l,) float64 metres            each rider LOD's error (computed once)
SceneFrame                                                one frame's CPU results + timings (ms)
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

# the default rider and the batcher through the package's lazy names (PEP 562), looked up where used: a
# bundle's scene brings its own model, and a bundle render does not import the batcher
from piste import character as _character
from piste._data import DataMethods
from piste.character import BlendedMesh, make_lods
from piste.character.lod import MEASURED_ERRORS, lod_digest, pose_skins, screen_errors
from piste.character.model import Model, SkinnedMesh
from piste.errors import ConfigError
from piste.graph import connected_parts
from piste.lighting.lights import DirectionalLight, Lights, default_lights
from piste.lighting.vertex import choose_lights_many
from piste.scene_data import Camera
from piste.terrain.net import PatchNet
from piste.world.course import TRACK_HALF_WIDTH, default_course, track_centerline
from piste.world.object_lod import DEFAULT_LOD_PIXELS, choose_lods
from piste.world.objects import ObjectSet, place_objects
from piste.world.riders import RiderSet, RiderState, follow_camera

__all__ = ["Scene", "SceneFrame", "LOD_DISTANCES", "RIDER_LOD_PIXELS", "sun_light", "orient_outward"]

#: the chase camera's distance behind the followed rider (metres)
CAMERA_BEHIND = 6.0
#: camera distances (metres) where riders switch from high to medium and from medium to low
LOD_DISTANCES = (14.0, 35.0)
#: the largest projected error a rider's level of detail may show (pixels; the objects' rule).  The
#: default rider's levels: ~24 mm (medium) and ~44 mm (low) of error, so at 640x448 and 60 degrees
#: the chased rider (~6 m) keeps the full mesh, the medium level from ~9 m, the low from ~17 m
RIDER_LOD_PIXELS = DEFAULT_LOD_PIXELS


def sun_light(lights: Lights) -> DirectionalLight | None:
    """The strongest directional light of ``lights`` (the one that casts projected shadows), or None."""
    d = [x for x in lights.direct if isinstance(x, DirectionalLight)]
    if not d:
        return None
    return max(d, key=lambda x: abs(x.intensity) * float(np.abs(np.asarray(x.color)).sum()))


def orient_outward(mesh: SkinnedMesh) -> tuple[SkinnedMesh, int]:
    """A copy of a SkinnedMesh whose closed parts all face outward.

    Each connected part's signed volume (divergence theorem, ``sum v0 . (v1 x v2) / 6``) tells
    whether its triangles wind inward; inward parts get their winding reversed and their normals
    (and morph normal deltas) negated.  :func:`piste.character.default_rider` is wound outward
    at the source; this guards meshes from elsewhere (glTF files exported inside-out).

    Returns ``(mesh, flipped_parts)``.
    """
    from dataclasses import replace

    tri = np.asarray(mesh.indices, dtype=np.int64)
    v = mesh.n_vertices
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    n_parts, label = connected_parts(v, e)
    p = mesh.positions.astype(np.float64)
    part = label[tri[:, 0]]
    centre = np.zeros((n_parts, 3))
    np.add.at(centre, label, p)
    centre /= np.maximum(np.bincount(label, minlength=n_parts), 1)[:, None]
    a, b, c = (p[tri[:, k]] - centre[part] for k in range(3))
    vol = np.bincount(part, weights=np.einsum("ij,ij->i", a, np.cross(b, c)), minlength=n_parts) / 6.0
    inward = vol < 0
    if not inward.any():
        return mesh, 0
    flip_t = inward[part]
    new_tri = tri.copy()
    new_tri[flip_t] = tri[flip_t][:, ::-1]
    sign = np.where(inward[label], -1.0, 1.0).astype(np.float32)[:, None]
    out = replace(mesh, indices=new_tri.astype(np.uint32), normals=mesh.normals * sign,
                  morph_normals=mesh.morph_normals * sign[None])
    return out, int(inward.sum())


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class SceneFrame(DataMethods):
    """The CPU side of one frame.

    Attributes
    ----------
    t : seconds;  camera : piste.world.camera.Camera
    riders : piste.world.riders.RiderState
    rider_lod : (n,) int, 0 high / 1 medium / 2 low (by projected error, or by distance: ``Scene.lod_pixels``)
    skinned : list (per LOD) of ``(rider indices (k,), positions (k, v, 3) float32, normals (k, v, 3) float32)``
        in world space
    shadow : ``(positions (n, v_low, 3), normals)`` every rider at the low LOD (shadow casters)
    rider_lights : VertexLights batch (n)
    objects_visible : (m,) int64 instances of ``scene.objects`` in the view frustum
    timings : ms: ``animation`` (poses, rider matrices, camera), ``lod_skinning``, ``lights``,
        ``objects`` (culling), ``cpu`` (their sum)
    """

    t: float
    camera: object
    riders: object
    rider_lod: np.ndarray
    skinned: list
    shadow: tuple
    rider_lights: object
    objects_visible: np.ndarray
    timings: dict = field(default_factory=dict)


class Scene:
    """The default course with six riders, objects and the world's lights (see the module docstring).

    Parameters
    ----------
    net : PatchNet;  centerline : (k, 3);  lights : piste.lighting.Lights
    model : the rider Model (default: :func:`piste.character.default_rider`)
    objects : an ObjectSet (or None for none)
    follow : the rider the camera chases
    lod_distances : (high -> medium, medium -> low) metres: the rule when ``lod_pixels`` is 0
    lod_pixels : (attribute) the projected error a rider's level may show, pixels (:data:`RIDER_LOD_PIXELS`);
        0 or less: levels by ``lod_distances``
    riders_kw : passed to :class:`piste.world.riders.RiderSet` (``start``, ``speed``, ``pack``)
    """

    #: pixels of projected error a rider's level may show (0: by ``lod_distances``); a class default so
    #: scenes that set themselves up otherwise (a bundle's) have it too
    lod_pixels: float = RIDER_LOD_PIXELS

    def __init__(self, net: PatchNet, centerline: npt.ArrayLike, lights: Lights, model: Model | None = None,
                 objects: ObjectSet | None = None, follow: int = 0,
                 lod_distances: tuple[float, float] = LOD_DISTANCES, camera_kw: dict[str, Any] | None = None,
                 **riders_kw: Any) -> None:
        self.net = net
        self.line = np.asarray(centerline, dtype=np.float64)
        self.lights = lights
        self.sun = sun_light(lights)
        self.model = model if model is not None else _character.default_rider(0)
        mesh, self.flipped_parts = orient_outward(self.model.meshes[0])
        self.lods = make_lods(mesh)
        # the LOD's own palette (quantized weights) drives the blended-matrix skinning
        self.skinners = [BlendedMesh(lod.palette, lod.mesh.positions, lod.mesh.normals) for lod in self.lods]
        self.riders = RiderSet(net, self.line, model=self.model, **riders_kw)
        if not 0 <= int(follow) < len(self.riders):
            raise ConfigError(f"scene: follow must name one of the {len(self.riders)} riders, got {follow}")
        self.follow = int(follow)
        self.objects = objects
        self.lod_distances = tuple(float(x) for x in lod_distances)
        self.camera_kw = dict(camera_kw or {})

    @classmethod
    def default(cls, seed: int = 0, lights: Lights | None = None, objects: bool = True, model: Model | None = None,
                **kw: Any) -> "Scene":
        """The default course of ``seed`` with its default lights (:func:`piste.lighting.default_lights`),
        six riders and the placed objects."""
        net = default_course(seed)
        line = track_centerline(seed)
        lights = lights if lights is not None else default_lights()
        objs = place_objects(net, line, lights, seed=seed, track_half_width=TRACK_HALF_WIDTH) if objects else None
        return cls(net, line, lights, model=model, objects=objs, **kw)

    # ------------------------------------------------------------------ stats
    def character_stats(self) -> list[dict]:
        """Per LOD: name, triangles, vertices, bones, palette matrices (the talk: ~250 / 150 / 75)."""
        out = []
        for lod in self.lods:
            batches = _character.make_batches(lod.mesh.indices, lod.palette.index)
            out.append({
                "lod": lod.name,
                "triangles": lod.n_triangles,
                "vertices": int(lod.mesh.n_vertices),
                "bones": int(self.model.skeleton.n_bones) if self.model.skeleton is not None else 0,
                "palette": lod.n_matrices,
                "step": lod.step,
                "batches": len(batches),
            })
        return out

    # ------------------------------------------------------------------ rider LOD
    def rider_lod_errors(self) -> np.ndarray:
        """Each rider level's error ``(l,) float64`` in metres (level 0: 0): the levels' ``distance`` where
        they were measured when built (a bundle's character step), else measured once here the same way
        (:func:`piste.character.lod.screen_errors` in the poses of the model's clips:
        :func:`~piste.character.lod.pose_skins`; ~0.1-0.3 s): the bind-pose Hausdorff-like distance to
        the full mesh plus how far the level's coarser palette moves its vertices."""
        key = tuple(id(lod) for lod in self.lods)
        cached = self.__dict__.get("_rider_lod_errors")
        if cached is not None and cached[0] == key:
            return cached[1]
        stored = [getattr(lod, "distance", None) for lod in self.lods]
        if all(d is not None for d in stored):
            err = np.asarray(stored, dtype=np.float64)
        else:  # the built-in rider's, measured once (MEASURED_ERRORS), or measured now
            known = MEASURED_ERRORS.get(lod_digest(self.lods, self.model))
            if known is not None and len(known) == len(self.lods):
                err = np.asarray(known, dtype=np.float64)
            else:
                err = screen_errors(self.lods, pose_skins(self.model))
        self.__dict__["_rider_lod_errors"] = (key, err)
        return err

    def rider_radius(self) -> float:
        """The bounding-sphere radius (metres) about ``anchor + 0.9 normal`` the LOD choice projects: half
        the full mesh's bind-pose diagonal plus 0.25 (riders lift and spin; the shadow casters' sphere)."""
        key = id(self.lods[0])
        cached = self.__dict__.get("_rider_radius")
        if cached is None or cached[0] != key:
            b = self.lods[0].mesh.bounds()
            cached = (key, 0.5 * float(np.linalg.norm(np.asarray(b[1]) - np.asarray(b[0]))) + 0.25)
            self.__dict__["_rider_radius"] = cached
        return cached[1]

    def choose_rider_lods(self, state: RiderState, cam: Camera, height_px: float = 448.0) -> np.ndarray:
        """Each rider's level ``(n,) int64``: the coarsest whose error (:meth:`rider_lod_errors`) projects
        under :attr:`lod_pixels` on a viewport ``height_px`` high, at the nearest depth of the rider's
        bounding sphere (:func:`piste.world.object_lod.choose_lods`); with ``lod_pixels <= 0``, by the
        anchor's distance to the eye (``lod_distances``)."""
        if self.lod_pixels <= 0:
            d = np.linalg.norm(state.anchor - cam.eye, axis=1)
            return np.searchsorted(np.asarray(self.lod_distances), d).astype(np.int64)  # 0, 1, 2
        centers = state.anchor + 0.9 * state.normal
        n = len(centers)
        if getattr(cam, "ortho_height", None) is None:
            # what choose_lods reads of a perspective view-projection (its focal scale, and the view depth
            # as clip w), without building the whole matrix (~0.1 ms of look_at and perspective a frame)
            fwd = np.asarray(cam.target, np.float64) - np.asarray(cam.eye, np.float64)
            fwd /= np.linalg.norm(fwd)
            vp = np.zeros((4, 4))
            vp[1, 1] = 1.0 / np.tan(np.radians(float(cam.fov_y)) * 0.5)
            vp[3, :3], vp[3, 3] = fwd, -float(fwd @ np.asarray(cam.eye, np.float64))
        else:
            vp = cam.view_projection()
        return choose_lods(self.rider_lod_errors(), centers, np.full(n, self.rider_radius()), np.ones(n),
                           vp, float(height_px), self.lod_pixels)

    # ------------------------------------------------------------------ a frame
    def camera(self, state: RiderState, aspect: float = 640.0 / 448.0, fov_y: float = 60.0) -> Camera:
        kw = {"behind": CAMERA_BEHIND, "height": 2.6, "look_ahead": 9.0}
        kw.update(self.camera_kw)
        return follow_camera(state, self.follow, net=self.net, aspect=aspect, fov_y=fov_y, far=4000.0, **kw)

    def update(self, t: float, aspect: float = 640.0 / 448.0, fov_y: float = 60.0, camera: Camera | None = None,
               height_px: float = 448.0) -> SceneFrame:
        """The CPU work of one frame at ``t`` seconds (see the module docstring).  ``camera``
        overrides the chase camera; ``height_px``: the viewport's height (the riders' LOD projects
        its error in pixels of it)."""
        tm: dict[str, float] = {}
        t0 = time.perf_counter()
        st = self.riders.state(t, camera_rider=self.follow if camera is None else None,
                               camera_behind=self.camera_kw.get("behind", CAMERA_BEHIND))
        cam = camera if camera is not None else self.camera(st, aspect, fov_y)
        t1 = time.perf_counter()
        lod = self.choose_rider_lods(st, cam, height_px)
        skinned = []
        for level, sk in enumerate(self.skinners):
            idx = np.nonzero(lod == level)[0]
            if len(idx):
                pos, nrm = sk.apply_many(st.skin[idx])
            else:
                pos = nrm = np.zeros((0, sk.n_vertices, 3), np.float32)
            skinned.append((idx, pos, nrm))
        low_idx, low_pos, low_nrm = skinned[-1]
        if len(low_idx) == len(st):
            shadow = (low_pos, low_nrm)
        else:  # the riders drawn at the low level already have their casters; the others skinned for them
            rest = np.nonzero(lod != len(self.skinners) - 1)[0]
            rpos, rnrm = self.skinners[-1].apply_many(st.skin[rest], normalize=False)
            spos, snrm = (np.empty((len(st),) + a.shape[1:], np.float32) for a in (rpos, rnrm))
            spos[rest], snrm[rest] = rpos, rnrm
            spos[low_idx], snrm[low_idx] = low_pos, low_nrm
            shadow = (spos, snrm)
        t2 = time.perf_counter()
        lights = choose_lights_many(self.lights, st.anchor + st.normal)  # at the rider's middle
        t3 = time.perf_counter()
        if self.objects is not None:
            vis = self.objects.visible(cam.frustum_planes(), max_distance=cam.far, eye=cam.eye)
        else:
            vis = np.zeros(0, np.int64)
        t4 = time.perf_counter()
        tm.update(animation=(t1 - t0) * 1e3, lod_skinning=(t2 - t1) * 1e3, lights=(t3 - t2) * 1e3,
                  objects=(t4 - t3) * 1e3)
        tm["cpu"] = sum(tm.values())
        return SceneFrame(float(t), cam, st, lod, skinned, shadow, lights, vis, tm)
