"""Riders on the course: six snowboarders playing their clips while they follow the track.

Each rider has a clip (``ride``, ``crouch``, ``grab``, ``spin``), a phase in it, a place in the
pack (metres ahead along the track, metres across it) and a carving rhythm (S-turns across the
track).  At time ``t`` (seconds) :meth:`RiderSet.state` gives, for all riders at once:

* the anchor: the point of the **exact** terrain surface under the rider
  (:func:`piste.terrain.query.height_at`), with the surface normal ``dQ/du x dQ/dv`` there;
* the rider's matrix ``(4, 4)`` (rider space -> world): the rider model is +Y up, board along +X
  (the nose, the travel direction), facing +Z (toe edge); the matrix maps +Y to the surface
  normal, +X to the track direction projected onto the surface's tangent plane, +Z to X x Y,
  and the origin (the board's base) to the anchor.  So the board stands on the surface and is
  oriented to the slope;
* the skin matrices of each rider's pose, already in world space: ``M_rider @ world_matrices(pose)
  @ inverse_bind`` (``(n, b, 4, 4)``), ready for the blended-matrix palette
  (:meth:`piste.character.BlendedMesh.apply_many`).

Animation cost: :class:`ClipTable` resamples each clip once, at ``rate`` Hz, into local
translation / rotation / scale tables with :meth:`piste.character.Clip.sample` (the reference);
each frame all riders' poses are one vectorised gather + lerp / nlerp + batched hierarchy product
(~0.1 ms for six riders instead of ~1.4 ms a rider sampling clips one by one).  The table agrees
with ``Clip.sample`` to well under a millimetre at 60 Hz (tested).

:func:`follow_camera` puts a chase camera behind a rider, above the snow.

API
---
RiderSet.default(net, centerline, model=None, n=6)   the pack
RiderSet.state(t) -> RiderState                      anchors, normals, matrices, skin matrices
ClipTable(model, rate=60)                            pre-sampled clips; ``.local(clip_ids, times)``
follow_camera(state, i, ...) -> piste.world.camera.Camera
merged_mesh(model) -> SkinnedMesh                     a model's skinned primitives as one mesh
rider_model(model) -> Model                          the model with that one mesh (what a Scene draws)
pack_for(model, n, ahead=0.0, across=0.0) -> pack    a pack playing the model's own clips

Different riders: a :class:`RiderSet` plays one model; a scene with several rider models has one
set (one :class:`piste.world.scene.Scene` "cast") per model, each with its own LODs, palettes,
batches and clip tables; :class:`piste.render.scene_renderer.SceneRenderer` draws them together.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from piste._data import DataMethods
from piste.character import default_rider
from piste.character.animation import sample_poses
from piste.character.model import Model, Skeleton, SkinnedMesh
from piste.character.skeleton import world_from_local
from piste.errors import ConfigError, ValidationError
from piste.terrain.net import PatchNet
from piste.terrain.query import eval_points, height_at
from piste.transforms import compose_trs
from piste.world.camera import Camera

__all__ = ["RiderSet", "RiderState", "ClipTable", "follow_camera", "surface_frame", "DEFAULT_PACK", "merged_mesh",
           "rider_model", "pack_for"]

#: the default pack: (clip, phase in [0, 1), metres ahead of rider 0, metres across the track,
#: carving amplitude in metres, carving period in seconds)
DEFAULT_PACK = (
    ("ride", 0.00, 0.0, -1.0, 2.5, 3.2),
    ("crouch", 0.30, 9.0, 3.5, 2.0, 2.8),
    ("grab", 0.10, 17.0, -4.0, 1.5, 3.6),
    ("ride", 0.55, 24.0, 1.5, 3.0, 3.0),
    ("spin", 0.20, 33.0, -1.5, 1.0, 4.0),
    ("crouch", 0.75, 41.0, 4.0, 2.5, 3.4),
)


def _unit(v: npt.ArrayLike) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


class ClipTable:
    """Clips of a model resampled at ``rate`` Hz into local-pose tables (see the module docstring).

    Attributes
    ----------
    names : list of clip names (``clip_ids`` index it)
    translation : list of (F_c, b, 3);  rotation : list of (F_c, b, 4) xyzw (sign-continuous);
    scale : list of (F_c, b, 3) float64 — one table per clip, ``F_c = ceil(duration * rate) + 1``
    duration : (c,) float64
    """

    def __init__(self, model: Model, rate: float = 60.0) -> None:
        if model.skeleton is None or not model.clips:
            raise ValidationError(f"ClipTable: model {model.name!r} needs a skeleton and clips")
        self.skeleton = model.skeleton
        self.rate = float(rate)
        self.names = list(model.clips)
        self.duration = np.array([model.clips[n].duration for n in self.names], dtype=np.float64)
        b = self.skeleton.n_bones
        fmax = int(np.ceil(self.duration.max() * self.rate)) + 1
        # one padded table for all clips: (c, F, b, ...) so all riders gather in one call
        self.frames = np.zeros(len(self.names), dtype=np.int64)
        self._t = np.zeros((len(self.names), fmax, b, 3))
        self._r = np.zeros((len(self.names), fmax, b, 4))
        self._s = np.ones((len(self.names), fmax, b, 3))
        for c, name in enumerate(self.names):  # set-up only: a few hundred samples
            clip = model.clips[name]
            f = int(np.ceil(clip.duration * self.rate)) + 1
            times = np.minimum(np.arange(f) / self.rate, clip.duration)
            if clip.skeleton is self.skeleton:  # no retargeting: every time in one call per track
                self._t[c, :f], self._r[c, :f], self._s[c, :f] = sample_poses(clip, times, self.skeleton)
            else:
                for k, tt in enumerate(times):
                    pose = clip.sample(float(tt), skeleton=self.skeleton)
                    self._t[c, k], self._r[c, k], self._s[c, k] = pose.translation, pose.rotation, pose.scale
            r = self._r[c, :f]
            for k in range(1, f):  # keep neighbouring keys in the same hemisphere (nlerp)
                flip = (r[k] * r[k - 1]).sum(-1) < 0
                r[k, flip] *= -1
            self.frames[c] = f

    @classmethod
    def from_samples(cls, skeleton: Skeleton, rate: float, names: Sequence[str], duration: npt.ArrayLike,
                     translation: Sequence[np.ndarray], rotation: Sequence[np.ndarray],
                     scale: Sequence[np.ndarray]) -> "ClipTable":
        """A table from clips already sampled at ``rate`` Hz (a bundle's pre-sampled clips): no curve
        sampling.  For clip ``names[c]``: ``translation[c]`` ``(F_c, b, 3)``, ``rotation[c]``
        ``(F_c, b, 4)`` xyzw, ``scale[c]`` ``(F_c, b, 3)``; ``duration`` ``(c,)`` seconds."""
        names = list(names)
        duration = np.asarray(duration, dtype=np.float64).reshape(-1)
        if not names or not (len(names) == len(duration) == len(translation) == len(rotation) == len(scale)):
            raise ValidationError(f"ClipTable.from_samples: {len(names)} clips, {len(duration)} durations, "
                                  f"{len(translation)}/{len(rotation)}/{len(scale)} tables: expected the same count (>= 1)")
        b = skeleton.n_bones
        frames = np.array([len(t) for t in translation], dtype=np.int64)
        table = cls.__new__(cls)
        table.skeleton = skeleton
        table.rate = float(rate)
        table.names = names
        table.duration = duration
        table.frames = frames
        fmax = int(frames.max())
        table._t = np.zeros((len(names), fmax, b, 3))
        table._r = np.zeros((len(names), fmax, b, 4))
        table._s = np.ones((len(names), fmax, b, 3))
        for c in range(len(names)):
            f = frames[c]
            for what, src, dst, w in (("translation", translation, table._t, 3), ("rotation", rotation, table._r, 4),
                                      ("scale", scale, table._s, 3)):
                a = np.asarray(src[c], dtype=np.float64)
                if a.shape != (f, b, w):
                    raise ValidationError(f"ClipTable.from_samples: clip {names[c]!r} {what} has shape {a.shape}, "
                                          f"expected {(int(f), b, w)}")
                dst[c, :f] = a
        return table

    def clip_index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise ConfigError(f"no clip {name!r}: the model has {', '.join(self.names)}") from None

    def local(self, clip_ids: npt.ArrayLike, times: npt.ArrayLike, loop: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Local poses of ``n`` instances: ``translation (n, b, 3)``, ``rotation (n, b, 4)``,
        ``scale (n, b, 3)`` of clip ``clip_ids[i]`` at ``times[i]`` seconds (looping)."""
        c = np.asarray(clip_ids, dtype=np.int64)
        t = np.asarray(times, dtype=np.float64)
        dur = self.duration[c]
        t = np.mod(t, dur) if loop else np.clip(t, 0.0, dur)
        x = t * self.rate
        f0 = np.minimum(np.floor(x).astype(np.int64), self.frames[c] - 2)
        a = (x - f0)[:, None, None]
        t0, t1 = self._t[c, f0], self._t[c, f0 + 1]
        r0, r1 = self._r[c, f0], self._r[c, f0 + 1]
        s0, s1 = self._s[c, f0], self._s[c, f0 + 1]
        r1 = np.where(((r0 * r1).sum(-1) < 0)[..., None], -r1, r1)
        r = _unit(r0 + a * (r1 - r0))
        return t0 + a * (t1 - t0), r, s0 + a * (s1 - s0)

    def skin_matrices(self, clip_ids: npt.ArrayLike, times: npt.ArrayLike, model_matrices: npt.ArrayLike | None = None, loop: bool = True) -> np.ndarray:
        """Skin matrices ``(n, b, 4, 4)`` (bind space -> world when ``model_matrices (n, 4, 4)``
        is given, else -> model space)."""
        tr, rot, sc = self.local(clip_ids, times, loop)
        sk = self.skeleton
        world = world_from_local(compose_trs(tr, rot, sc), sk.parents, sk.levels)
        if model_matrices is not None:
            world = np.asarray(model_matrices, dtype=np.float64)[:, None] @ world
        return world @ sk.inverse_bind


def surface_frame(net: PatchNet, xy: npt.ArrayLike, heading: npt.ArrayLike,
                  probe_xy: npt.ArrayLike | None = None) -> tuple[np.ndarray, ...]:
    """Anchors, normals and frames on the exact surface of ``net``.

    Parameters
    ----------
    net : PatchNet (a height field over x-y)
    xy : (n, 2) float positions
    heading : (n, 2) or (n, 3) float travel directions (projected onto the tangent plane)

    probe_xy : (k, 2) extra points whose surface heights are wanted too (one query for all)

    Returns
    -------
    anchor (n, 3), normal (n, 3) unit (z > 0), forward (n, 3) unit tangent, all float64 (and the
    probes' heights ``(k,)``, NaN off the terrain, when ``probe_xy`` is given);
    raises ValidationError for rider points off the terrain.
    """
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    n_pts = len(xy)
    if probe_xy is not None:
        probe_xy = np.asarray(probe_xy, dtype=np.float64).reshape(-1, 2)
        z_all, hit_all, patch_all, uv_all = height_at(net, np.concatenate([xy, probe_xy]))
        z, hit, patch, uv = z_all[:n_pts], hit_all[:n_pts], patch_all[:n_pts], uv_all[:n_pts]
    else:
        z, hit, patch, uv = height_at(net, xy)
    if not np.all(hit):
        raise ValidationError(f"riders: {int((~hit).sum())} rider position(s) lie off the terrain: {xy[~hit][:3].tolist()}")
    q, du, dv = eval_points(net.control_points[patch], uv[:, 0], uv[:, 1])
    n = _unit(np.cross(du, dv))
    n = np.where(n[:, 2:3] < 0, -n, n)
    h = np.asarray(heading, dtype=np.float64)
    if h.shape[-1] == 2:
        h = np.concatenate([h, np.zeros(h.shape[:-1] + (1,))], -1)
    f = _unit(h - (h * n).sum(-1, keepdims=True) * n)
    anchor = np.stack([xy[:, 0], xy[:, 1], z], 1)
    if probe_xy is not None:
        return anchor, n, f, z_all[n_pts:]
    return anchor, n, f


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class RiderState(DataMethods):
    """All riders at one instant.

    t : seconds;  anchor (n, 3) on the surface;  normal (n, 3);  forward (n, 3);
    matrix (n, 4, 4) rider -> world;  skin (n, b, 4, 4) bind space -> world;
    clip (n,) clip names;  along (n,) metres along the track;
    heading (n, 2) unit horizontal travel direction (with the carving);
    track_dir (n, 2) unit horizontal direction of the track there (what the chase camera follows);
    probe_z (k,) surface heights at the extra ``probe_xy`` points asked of :meth:`RiderSet.state`
    """

    t: float
    anchor: np.ndarray
    normal: np.ndarray
    forward: np.ndarray
    matrix: np.ndarray
    skin: np.ndarray
    clip: tuple
    along: np.ndarray
    heading: np.ndarray | None = None
    probe_z: np.ndarray | None = None
    track_dir: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.anchor)


class RiderSet:
    """A pack of riders sharing one model (see the module docstring).

    Parameters
    ----------
    net : PatchNet;  centerline : (k, 3) float down the track
    model : a character Model with clips (default: :func:`piste.character.default_rider`)
    pack : rows ``(clip, phase, ahead_m, across_m, carve_amplitude_m, carve_period_s)``
    start : metres along the track of rider 0 at ``t = 0``;  speed : metres a second
    rate : clip table rate in Hz
    """

    def __init__(self, net: PatchNet, centerline: npt.ArrayLike, model: Model | None = None,
                 pack: Sequence[tuple[str, float, float, float, float, float]] = DEFAULT_PACK, start: float = 150.0, speed: float = 11.0,
                 rate: float = 60.0) -> None:
        if model is None:
            model = default_rider(0)
        self.net = net
        self.model = model
        self.table = ClipTable(model, rate)
        line = np.asarray(centerline, dtype=np.float64)
        if line.ndim != 2 or line.shape[1] != 3 or len(line) < 2:
            raise ConfigError(f"riders: centerline must have shape (k >= 2, 3), got {line.shape}")
        self.line = line
        seg = np.linalg.norm(np.diff(line[:, :2], axis=0), axis=1)
        self._cum = np.concatenate([[0.0], np.cumsum(seg)])
        self.length = float(self._cum[-1])
        pack = list(pack)
        if not pack:
            raise ConfigError("riders: the pack is empty")
        self.clips = tuple(str(p[0]) for p in pack)
        self.clip_ids = np.array([self.table.clip_index(c) for c in self.clips])
        arr = np.array([p[1:] for p in pack], dtype=np.float64)
        self.phase, self.ahead, self.across, self.carve_amp, self.carve_period = arr.T
        self.start = float(start)
        self.speed = float(speed)

    def __len__(self) -> int:
        return len(self.clips)

    def _track(self, s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        s = np.clip(s, 0.0, self.length)
        cum, line = self._cum, self.line
        p = np.stack([np.interp(s, cum, line[:, 0]), np.interp(s, cum, line[:, 1])], 1)
        a, b = np.maximum(s - 2.0, 0.0), np.minimum(s + 2.0, self.length)
        d = np.stack([np.interp(b, cum, line[:, k]) - np.interp(a, cum, line[:, k]) for k in range(2)], 1)
        d = _unit(d)
        return p, d, np.stack([d[:, 1], -d[:, 0]], 1)  # side: to the right of the travel direction

    def state(self, t: float, camera_rider: int | None = None, camera_behind: float = 7.0) -> RiderState:
        """Every rider at ``t`` seconds (see :class:`RiderState`).

        ``camera_rider``: also query the surface height ``camera_behind`` metres behind that rider
        (where :func:`follow_camera` puts its eye) in the same height query (``state.probe_z``)."""
        t = float(t)
        s = self.start + self.ahead + self.speed * t
        s = np.clip(s, 0.0, self.length - 1.0)
        p, d, side = self._track(s)
        w = 2 * np.pi / self.carve_period
        ph = 2 * np.pi * self.phase
        lat = self.across + self.carve_amp * np.sin(w * t + ph)
        dlat = self.carve_amp * w * np.cos(w * t + ph) / max(self.speed, 1e-6)  # metres across per metre along
        xy = p + side * lat[:, None]
        heading = _unit(d + side * dlat[:, None])
        probe = None
        if camera_rider is not None:
            probe = xy[int(camera_rider)][None] - camera_behind * d[int(camera_rider)][None]
            anchor, normal, fwd, probe_z = surface_frame(self.net, xy, heading, probe_xy=probe)
        else:
            anchor, normal, fwd = surface_frame(self.net, xy, heading)
            probe_z = None
        z_axis = np.cross(fwd, normal)
        n = len(self)
        m = np.zeros((n, 4, 4))
        m[:, :3, 0], m[:, :3, 1], m[:, :3, 2], m[:, :3, 3] = fwd, normal, z_axis, anchor
        m[:, 3, 3] = 1.0
        times = self.phase * self.table.duration[self.clip_ids] + t
        skin = self.table.skin_matrices(self.clip_ids, times, m)
        return RiderState(t, anchor, normal, fwd, m, skin, self.clips, s, heading, probe_z, d)

    def clip_times(self, t: float) -> np.ndarray:
        """``(n,)`` seconds into each rider's clip at ``t`` (unwrapped; clips loop)."""
        return self.phase * self.table.duration[self.clip_ids] + float(t)

    @classmethod
    def default(cls, net: PatchNet, centerline: np.ndarray, model: Model | None = None, **kw: Any) -> "RiderSet":
        return cls(net, centerline, model=model, **kw)


def follow_camera(state: RiderState, i: int = 0, behind: float = 7.0, height: float = 3.0, look_ahead: float = 10.0,
                  net: PatchNet | None = None, clearance: float = 1.5, **camera_kw: Any) -> Camera:
    """A chase camera behind rider ``i``: ``behind`` metres back along the track's direction (not
    the rider's carving heading: the camera stays calm through the turns), ``height`` above it,
    looking at a point ``look_ahead`` metres ahead along the track, 1 m above the snow; kept ``clearance`` metres above the terrain (the height probed by
    ``RiderSet.state(t, camera_rider=i, camera_behind=behind)``, else queried from ``net``)."""
    if state.track_dir is not None:
        f = np.append(state.track_dir[i], 0.0)
    else:
        f = state.forward[i].copy()
        f[2] = 0.0
        f = _unit(f)
    eye = state.anchor[i] - behind * f + np.array([0.0, 0.0, height])
    ground = None
    if state.probe_z is not None and len(state.probe_z) and np.isfinite(state.probe_z[0]):
        ground = float(state.probe_z[0])
    elif net is not None:
        z, hit, _, _ = height_at(net, eye[None, :2])
        ground = float(z[0]) if hit[0] else None
    if ground is not None:
        eye[2] = max(eye[2], ground + clearance)
    ahead = f * look_ahead
    ahead[2] = look_ahead * float(state.forward[i, 2])  # follow the slope down
    target = state.anchor[i] + ahead + np.array([0.0, 0.0, 1.0])
    return Camera(eye=eye, target=target, **camera_kw)


def merged_mesh(model: Model) -> SkinnedMesh:
    """One :class:`~piste.character.model.SkinnedMesh` of every skinned primitive of ``model``
    (texture: the first one's).  Morph targets are merged by name."""
    meshes = [m for m in model.meshes if m.skinned] or list(model.meshes)
    if not meshes:
        raise ConfigError(f"rider model {model.name!r} has no meshes")
    if len(meshes) == 1:
        return meshes[0]
    off = np.cumsum([0] + [m.n_vertices for m in meshes])[:-1]
    tex = next((m.texture for m in meshes if m.texture is not None), None)
    # morph targets: the union of the primitives' target names (a primitive without one: zeros)
    names = list(dict.fromkeys(n for m in meshes for n in m.morph_names))
    kw: dict[str, Any] = {}
    if names:
        k = len(names)
        mp = [np.zeros((k, m.n_vertices, 3), np.float32) for m in meshes]
        mn = [np.zeros((k, m.n_vertices, 3), np.float32) for m in meshes]
        dw = np.zeros(k, np.float32)
        for m, a, b in zip(meshes, mp, mn):
            for j, n in enumerate(m.morph_names):
                i = names.index(n)
                a[i], b[i] = m.morph_positions[j], m.morph_normals[j]
                dw[i] = m.morph_default_weights[j]
        kw = {"morph_positions": np.concatenate(mp, axis=1), "morph_normals": np.concatenate(mn, axis=1),
              "morph_names": names, "morph_default_weights": dw}
    return SkinnedMesh(
        name=model.name, positions=np.concatenate([m.positions for m in meshes]),
        indices=np.concatenate([m.indices + o for m, o in zip(meshes, off)]),
        normals=np.concatenate([m.normals for m in meshes]), uv=np.concatenate([m.uv for m in meshes]),
        joints=np.concatenate([m.joints for m in meshes]), weights=np.concatenate([m.weights for m in meshes]),
        texture=tex, skinned=True, group=model.name, **kw)


def rider_model(model: Model) -> Model:
    """``model`` with all its skinned primitives merged into one mesh and an RGBA texture (white
    when it has none): what a scene cast draws.  Raises ConfigError without a skin or clips."""
    from dataclasses import replace

    if model.skeleton is None or not model.clips:
        raise ConfigError(f"rider model {model.name!r}: a rider needs a skin and at least one animation")
    mesh = merged_mesh(model)
    tex = mesh.texture
    if tex is None:  # the base colour factor (sRGB-ish bytes) as a flat texture
        c = np.clip(np.asarray(mesh.base_color, np.float64) ** (1 / 2.2) * 255.0 + 0.5, 0, 255).astype(np.uint8)
        tex = np.tile(c, (4, 4, 1))
    else:
        tex = np.asarray(tex)
        if tex.ndim == 3 and tex.shape[2] == 3:
            tex = np.concatenate([tex, np.full(tex.shape[:2] + (1,), 255, tex.dtype)], axis=2)
        tex = np.ascontiguousarray(tex, dtype=np.uint8)
    return replace(model, meshes=[replace(mesh, texture=tex)])


def pack_for(model: Model, n: int, ahead: float = 0.0, across: float = 0.0,
             spacing: float = 8.0) -> tuple[tuple[str, float, float, float, float, float], ...]:
    """A pack of ``n`` riders of ``model`` playing its clips in turn: rows for :class:`RiderSet`
    starting ``ahead`` metres ahead of the track position, ``spacing`` metres apart, zig-zagging
    ``across`` +- 3 m."""
    clips = sorted(model.clips)
    if not clips:
        raise ConfigError(f"rider model {model.name!r} has no clips")
    return tuple((clips[i % len(clips)], (0.37 * i) % 1.0, ahead + spacing * i, across + (3.0 if i % 2 else -3.0),
                  2.0, 3.0 + 0.3 * i) for i in range(int(n)))
