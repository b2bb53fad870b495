"""Cameras: view and projection matrices, view frusta, and a camera that flies down a track.

Conventions: Z up, metres, OpenGL clip space (column vectors, ``clip = P @ V @ [x, y, z, 1]``,
camera looks down its local -Z).  Pure numpy; the renderer turns these into uniforms.

API
---
Camera                    piste.scene_data.Camera (the one camera type), re-exported
look_at, perspective, orthographic   4x4 float64 matrices
frustum_planes            (6, 4) planes of a view-projection matrix, normals pointing inside
track_camera              a Camera riding down a centre line (k, 3) at fraction t
FlyCamera                 position + yaw/pitch, moved by keys and mouse (``piste view``)
far_for_extent            a far plane reaching every corner of a box (the terrain's bounds) from an eye
camera_planes             (near, far) for a scene camera: the ones given, else defaults that reach the terrain
terrain_view_problem      why a camera sees none of the terrain (beyond the far plane, looking away), or None
warn_if_no_terrain        log that reason once (``piste: camera ...: sees no terrain: ...``)
DEFAULT_FAR, MAX_DEPTH_RATIO
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from piste._data import DataMethods
from piste.errors import ConfigError
from piste.scene_data import Camera  # (the one camera type, in the foundation; re-exported here)
from piste.transforms import frustum_planes, look_at, orthographic, perspective  # noqa: F401  (re-exported)

__all__ = ["DEFAULT_FAR", "MAX_DEPTH_RATIO", "Camera", "FlyCamera", "camera_planes", "far_for_extent", "frustum_planes", "look_at",
           "orthographic", "perspective", "terrain_view_problem", "track_camera", "warn_if_no_terrain"]

log = logging.getLogger(__name__)

#: the far plane (metres) of a camera that says none and of worlds smaller than it (the default course)
DEFAULT_FAR = 4000.0
#: largest far / near ratio a scene camera may ask for: beyond it a 24-bit depth buffer has no
#: precision left and the projection's inverse is singular in float64 (1e300 / 1e-300: LinAlgError)
MAX_DEPTH_RATIO = 1e7


def _arc_length_point(points: np.ndarray, s: npt.ArrayLike) -> np.ndarray:
    """Points at arc lengths ``s`` (clamped) along a polyline ``(k, 3)``."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    s = np.clip(np.asarray(s, dtype=np.float64), 0.0, cum[-1])
    return np.stack([np.interp(s, cum, points[:, k]) for k in range(3)], axis=-1)


def track_camera(
    centerline: npt.ArrayLike,
    t: float,
    height: float = 12.0,
    behind: float = 14.0,
    look_ahead: float = 60.0,
    lift: float = 0.5,
    fov_y: float = 60.0,
    aspect: float = 640.0 / 448.0,
    near: float = 0.5,
    far: float = 4000.0,
) -> Camera:
    """A chase camera riding down a track.

    Parameters
    ----------
    centerline : (k, 3) float, points down the track (the rider's line)
    t : position along the track as a fraction of its length, in [0, 1]
    height : metres above the line
    behind : metres back along the line from the rider's point
    look_ahead : metres ahead along the line to the look-at point
    lift : the look-at point is ``lift * height`` above the line there (below 1: the camera looks
        down the slope at the track)
    """
    pts = np.asarray(centerline, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 2:
        raise ConfigError(f"track_camera: centerline must have shape (k>=2, 3), got {pts.shape}")
    length = float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())
    s = float(np.clip(t, 0.0, 1.0)) * length
    eye = _arc_length_point(pts, s - behind) + np.array([0.0, 0.0, height])
    if s - behind < 0:  # before the start: extrapolate backwards along the first segment
        d = pts[1] - pts[0]
        eye = eye - d / np.linalg.norm(d) * (behind - s)
    target = _arc_length_point(pts, s + look_ahead)
    if s + look_ahead > length:
        d = pts[-1] - pts[-2]
        target = target + d / np.linalg.norm(d) * (s + look_ahead - length)
    target = target + np.array([0.0, 0.0, lift * height])
    return Camera(eye, target, fov_y=fov_y, aspect=aspect, near=near, far=far)


def _box_corners(lo: npt.ArrayLike, hi: npt.ArrayLike) -> np.ndarray:
    """The 8 corners ``(8, 3) float64`` of the box ``lo..hi``."""
    lo, hi = np.asarray(lo, dtype=np.float64).reshape(3), np.asarray(hi, dtype=np.float64).reshape(3)
    sel = (np.arange(8)[:, None] >> np.arange(3)) & 1  # (8, 3) 0/1
    return np.where(sel == 1, hi, lo)


def far_for_extent(eye: npt.ArrayLike, lo: npt.ArrayLike, hi: npt.ArrayLike, minimum: float = DEFAULT_FAR, margin: float = 1.05) -> float:
    """A far plane (metres) that reaches every corner of the box ``lo..hi`` (``(3,)`` each: the
    terrain's bounds) from ``eye`` (``(3,)``), with ``margin``; at least ``minimum``, so worlds
    smaller than :data:`DEFAULT_FAR` keep it and bigger ones (a 50 km DEM) are never cut off."""
    d = np.linalg.norm(_box_corners(lo, hi) - np.asarray(eye, dtype=np.float64).reshape(3), axis=1).max()
    return float(max(minimum, d * margin))


def camera_planes(eye: npt.ArrayLike, lo: npt.ArrayLike | None = None, hi: npt.ArrayLike | None = None,
                  near: float | None = None, far: float | None = None) -> tuple[float, float]:
    """``(near, far)`` in metres for a camera at ``eye`` (``(3,)``) over terrain bounded by
    ``lo..hi`` (``(3,)`` each; None: unknown): the given planes where given, else a far plane
    reaching the whole terrain (:func:`far_for_extent`, at least :data:`DEFAULT_FAR`) and a near
    plane of 0.5 m (``far / 1e5`` beyond a 50 km far plane, for depth precision), with
    ``near < far`` and ``far / near <= MAX_DEPTH_RATIO``."""
    if far is None:
        far = DEFAULT_FAR if lo is None or hi is None else far_for_extent(eye, lo, hi)
        if near is not None:
            far = min(max(far, near * 10.0), near * MAX_DEPTH_RATIO)
    if near is None:
        near = min(max(0.5, far * 1e-5), far * 0.1)
    return float(near), float(far)


def terrain_view_problem(camera: Camera, lo: npt.ArrayLike, hi: npt.ArrayLike) -> str | None:
    """Why ``camera`` can see none of the terrain whose bounds are ``lo..hi`` (``(3,)`` each), or
    None when some of it may be in view (the box meets the view frustum; conservative).

    The reasons: the terrain's nearest point lies beyond the far plane (with the far plane that
    would reach all of it), or the box lies wholly outside one side of the view (looking away)."""
    lo, hi = np.asarray(lo, dtype=np.float64).reshape(3), np.asarray(hi, dtype=np.float64).reshape(3)
    corners = _box_corners(lo, hi)
    size = " x ".join(f"{x:.0f}" for x in hi - lo)
    nearest = float(np.linalg.norm(camera.eye - np.clip(camera.eye, lo, hi)))
    if nearest > camera.far:
        return (f"the terrain's nearest point is {nearest:.0f} m from the eye, beyond the far plane at "
                f"{camera.far:.0f} m (the terrain spans {size} m; far = {far_for_extent(camera.eye, lo, hi, 0.0):.0f} "
                "would reach all of it)")
    planes = camera.frustum_planes()
    outside = (corners @ planes[:, :3].T + planes[:, 3] < 0).all(axis=0)  # (6,) every corner behind that plane
    if outside[5]:
        return (f"the terrain lies beyond the far plane at {camera.far:.0f} m in the view direction (the terrain "
                f"spans {size} m; far = {far_for_extent(camera.eye, lo, hi, 0.0):.0f} would reach all of it)")
    if outside.any():
        side = ("left", "right", "bottom", "top", "near", "far")[int(np.flatnonzero(outside)[0])]
        return (f"the camera looks away from the terrain: its bounds {np.round(lo, 1).tolist()} .. "
                f"{np.round(hi, 1).tolist()} lie wholly outside the view's {side} side (eye "
                f"{np.round(camera.eye, 1).tolist()}, target {np.round(camera.target, 1).tolist()})")
    return None


_warned: set = set()


def warn_if_no_terrain(camera: Camera, lo: np.ndarray, hi: np.ndarray, name: str = "the camera", seen: set | None = None) -> str | None:
    """Log at WARNING on the ``piste`` logger (``piste: the camera sees no terrain: REASON``) when
    ``camera`` sees none of the terrain ``lo..hi`` (see :func:`terrain_view_problem`); returns the
    reason or None.  Each kind of reason is logged once per ``name`` and ``seen`` set (default: once
    per process), so a flight past the terrain's end says it once, not every frame."""
    reason = terrain_view_problem(camera, lo, hi)
    seen = _warned if seen is None else seen
    if reason is not None and (name, reason[:20]) not in seen:
        seen.add((name, reason[:20]))
        log.warning("%s sees no terrain: %s", name, reason)
    return reason


@dataclass(repr=False, eq=False)  # (repr / eq: piste._data.DataMethods)
class FlyCamera(DataMethods):
    """A free-flying camera for interactive viewing: position, yaw and pitch.

    Attributes
    ----------
    position : (3,) float64 metres
    yaw : radians about Z, 0 looks along +y, positive turns towards +x
    pitch : radians above the horizontal (clamped to +-89 degrees)
    speed : metres per second for :meth:`move`
    """

    position: np.ndarray
    yaw: float = 0.0
    pitch: float = 0.0
    speed: float = 40.0
    fov_y: float = 60.0
    near: float = 0.5
    far: float = 4000.0

    def __post_init__(self) -> None:
        self.position = np.asarray(self.position, dtype=np.float64).reshape(3).copy()

    @classmethod
    def from_camera(cls, cam: Camera, **kwargs: Any) -> "FlyCamera":
        f = cam.forward
        return cls(cam.eye, yaw=float(np.arctan2(f[0], f[1])), pitch=float(np.arcsin(np.clip(f[2], -1, 1))),
                   fov_y=cam.fov_y, near=cam.near, far=cam.far, **kwargs)

    @property
    def forward(self) -> np.ndarray:
        cp = np.cos(self.pitch)
        return np.array([cp * np.sin(self.yaw), cp * np.cos(self.yaw), np.sin(self.pitch)])

    @property
    def right(self) -> np.ndarray:
        return np.array([np.cos(self.yaw), -np.sin(self.yaw), 0.0])

    def move(self, forward: float, right: float, up: float, dt: float) -> None:
        """Fly ``forward``/``right``/``up`` (each -1..1, scaled by ``speed``) for ``dt`` seconds."""
        d = forward * self.forward + right * self.right + up * np.array([0.0, 0.0, 1.0])
        self.position = self.position + d * self.speed * dt

    def look(self, dyaw: float, dpitch: float) -> None:
        """Turn by ``dyaw`` and ``dpitch`` radians."""
        self.yaw = float(self.yaw + dyaw)
        self.pitch = float(np.clip(self.pitch + dpitch, -np.radians(89.0), np.radians(89.0)))

    def camera(self, aspect: float = 640.0 / 448.0) -> Camera:
        return Camera(self.position, self.position + self.forward, fov_y=self.fov_y, near=self.near, far=self.far,
                      aspect=aspect)
