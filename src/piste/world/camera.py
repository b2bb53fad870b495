"""Cameras: view and projection matrices, view frusta, and a camera that flies down a track.

Conventions: Z up, metres, OpenGL clip space (column vectors, ``clip = P @ V @ [x, y, z, 1]``,
camera looks down its local -Z).  Pure numpy; the renderer turns these into uniforms.

API
---
Camera                    eye, target, up, fov_y, near, far, aspect (+ matrices, frustum planes)
look_at, perspective, orthographic   4x4 float64 matrices
frustum_planes            (6, 4) planes of a view-projection matrix, normals pointing inside
track_camera              a Camera riding down a centre line (k, 3) at fraction t
FlyCamera                 position + yaw/pitch, moved by keys and mouse (``piste view``)
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from piste.errors import ConfigError

from piste.transforms import frustum_planes, look_at, orthographic, perspective  # noqa: E402  (re-exported)

__all__ = ["Camera", "FlyCamera", "look_at", "perspective", "orthographic", "frustum_planes", "track_camera"]


@dataclass
class Camera:
    """A pinhole camera (or an orthographic one when ``ortho_height`` is set).

    Attributes
    ----------
    eye, target : (3,) float64 world positions
    up : (3,) float64, the world's up (Z)
    fov_y : vertical field of view in degrees
    near, far : clip distances in metres
    aspect : width / height
    ortho_height : height of the view volume in metres for an orthographic camera, else None
    """

    eye: np.ndarray
    target: np.ndarray
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    fov_y: float = 60.0
    near: float = 0.5
    far: float = 4000.0
    aspect: float = 640.0 / 448.0
    ortho_height: float | None = None

    def __post_init__(self):
        self.eye = np.asarray(self.eye, dtype=np.float64).reshape(3)
        self.target = np.asarray(self.target, dtype=np.float64).reshape(3)
        self.up = np.asarray(self.up, dtype=np.float64).reshape(3)

    @property
    def forward(self) -> np.ndarray:
        """Unit view direction ``(3,)``."""
        d = self.target - self.eye
        return d / np.linalg.norm(d)

    def view_matrix(self) -> np.ndarray:
        return look_at(self.eye, self.target, self.up)

    def projection_matrix(self) -> np.ndarray:
        if self.ortho_height is not None:
            h = self.ortho_height / 2.0
            w = h * self.aspect
            return orthographic(-w, w, -h, h, self.near, self.far)
        return perspective(self.fov_y, self.aspect, self.near, self.far)

    def view_projection(self) -> np.ndarray:
        """``P @ V``, ``(4, 4) float64``."""
        return self.projection_matrix() @ self.view_matrix()

    def frustum_planes(self) -> np.ndarray:
        """``(6, 4) float64`` inward planes, see :func:`frustum_planes`."""
        return frustum_planes(self.view_projection())

    def with_aspect(self, width: int, height: int) -> "Camera":
        return replace(self, aspect=float(width) / float(height))


def _arc_length_point(points: np.ndarray, s) -> np.ndarray:
    """Points at arc lengths ``s`` (clamped) along a polyline ``(k, 3)``."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    s = np.clip(np.asarray(s, dtype=np.float64), 0.0, cum[-1])
    return np.stack([np.interp(s, cum, points[:, k]) for k in range(3)], axis=-1)


def track_camera(
    centerline,
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


@dataclass
class FlyCamera:
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

    def __post_init__(self):
        self.position = np.asarray(self.position, dtype=np.float64).reshape(3).copy()

    @classmethod
    def from_camera(cls, cam: Camera, **kwargs) -> "FlyCamera":
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
