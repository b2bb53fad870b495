"""glTF's cameras and ``KHR_lights_punctual`` lights <-> piste's one camera and light family.

:func:`piste.formats.gltf.read.load_gltf` gives a file's lights and cameras as
:mod:`piste.scene_data` objects through :func:`light_from_gltf` / :func:`camera_from_gltf`;
:func:`piste.formats.gltf.write.export_gltf` writes piste's through :func:`light_to_gltf` /
:func:`camera_to_gltf`.  The conventions:

Axes
----
glTF is right-handed, +Y up, -Z forward (Blender's exporter maps Blender's ``(x, y, z)`` to glTF
``(x, z, -y)``); piste is right-handed, +Z up.  A glTF point ``(x, y, z)`` becomes piste
``offset + scale * (x, -z, y)`` (``up = "y"``, the default) -- exactly Blender's own coordinates
again -- or ``offset + scale * (x, y, z)`` for files already Z-up (``up = "z"``).  Directions
(light directions, camera forward and up) use the same rotation without offset and scale
(:class:`GltfFrame`).  The writer takes piste's coordinates and wraps the scene in a root node
turning Z up into Y up (:data:`piste.formats.gltf.write.Y_UP_ROOT_ROTATION`).

Light units
-----------
KHR_lights_punctual gives directional lights in lux (lm/m^2) and point and spot lights in candela
(lm/sr), with inverse-square falloff (``E = I / d^2``) cut off at an optional ``range``.  piste's
lights are relative: 1.0 is full white, and point/spot lights fade as ``(1 - d/range)^falloff``.
With ``white`` the illuminance in lux that piste shows as 1.0 (default 683 lux: Blender's exporter
writes a sun of strength 1 W/m^2 as 683 lux, so a strength-1 sun gives piste intensity 1.0):

* directional: ``intensity = lux / white``;
* point and spot: ``falloff = 2``; ``range`` = the glTF range (times ``scale``), or where
  ``I / d^2`` drops to ``white / 256`` (below one step of an 8-bit half-bright light map) when the
  file gives none: ``range = sqrt(256 I / white)``; ``intensity`` matches the inverse-square
  illuminance at a quarter of the range: ``intensity = I / (white d_q^2 (3/4)^2)`` with
  ``d_q = range / 4`` (so piste's light is within a factor of ~2 of the physical one between
  ~range/6 and ~range/2 and fades to exactly zero at ``range`` where glTF's only approaches it);
* spot cone: glTF ``innerConeAngle`` / ``outerConeAngle`` (radians, from the axis) become piste's
  ``inner_angle`` / ``outer_angle`` half-angles in degrees (both blend smoothly between them);
* colours are linear RGB in both.  glTF has no ambient light: give one inline (``[[lights]]``).

Written back (:func:`light_to_gltf`, the inverse): ``lux = intensity * white``; a point or spot
light with a finite ``range``: ``candela = intensity * white * (range / 4)^2 * (3/4)^2`` and glTF
``range = range`` (importing the file gives back the same intensity and range); with an infinite
range (no fall-off in piste): ``candela = intensity * white * 10^2`` (the same illuminance at
:data:`INFINITE_RANGE_MATCH` m), no glTF range.  Ambient lights and negative (darkening) lights
have no glTF form: :func:`lights_without_gltf_form` lists them, in piste's units, for the scene's
``extras``.

Cameras
-------
Perspective: ``yfov`` (radians) <-> ``fov_y`` degrees; ``znear`` <-> ``near``; ``zfar`` <-> ``far``;
``aspectRatio`` <-> ``aspect``.  A file's camera without ``zfar`` (infinite) reads as ``far = inf``,
one without ``znear`` (0) as ``near = 0``: the planes the file leaves open, which the pipeline
fills by the scene cameras' rule (:mod:`piste.pipeline.gltf_import`).  The camera looks down its
node's -Z with the node's +Y as up (roll is kept).  Orthographic: ``ortho_height = 2 * ymag *
scale`` (``aspect = xmag / ymag``); written back ``ymag = ortho_height / 2``, ``xmag = ymag *
aspect``.

API
---
::

    GltfFrame(up="y", offset=(0, 0, 0), scale=1.0, white=683.0)   a file's axes, placement, white
    axis_matrix(up) -> (3, 3)                  the file's axes -> piste's
    light_from_gltf(fields, position, direction, frame, index) -> DirectionalLight | PointLight | SpotLight
    camera_from_gltf(fields, position, forward, up, frame, index) -> Camera
    light_to_gltf(light, white) -> dict | None     the KHR definition (+ "position", "direction"), or None
    lights_without_gltf_form(lights) -> {"ambient": [...], "negative": [...]}
    camera_to_gltf(camera) -> dict             type, yfov / xmag, ymag, znear, zfar, aspect
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from piste.errors import ConfigError, ValidationError
from piste.scene_data import AmbientLight, AnyLight, Camera, DirectionalLight, PointLight, SpotLight

__all__ = ["DEFAULT_WHITE_LUX", "INFINITE_RANGE_MATCH", "GltfFrame", "axis_matrix", "light_from_gltf",
           "camera_from_gltf", "light_to_gltf", "lights_without_gltf_form", "camera_to_gltf"]

#: the illuminance (lux) piste shows as 1.0 (Blender's sun strength 1 W/m^2)
DEFAULT_WHITE_LUX = 683.0
#: distance (m) at which a piste light without fall-off is matched by an inverse-square glTF light
INFINITE_RANGE_MATCH = 10.0
#: glTF (x, y, z) -> piste (x, -z, y)
_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def axis_matrix(up: str = "y") -> np.ndarray:
    """Rotation ``(3, 3) float64`` from a file's axes to piste's (Z up): ``up`` "y" (glTF) or "z"."""
    if up == "y":
        return _Y_UP.copy()
    if up == "z":
        return np.eye(3)
    raise ConfigError(f"glTF up axis must be 'y' or 'z', got {up!r}")


@dataclass(frozen=True)
class GltfFrame:
    """How a file's lights and cameras land in piste's world: its ``up`` axis ("y" or "z"), then
    ``offset + scale * point`` (metres), and ``white``, the lux piste shows as 1.0."""

    up: str = "y"
    offset: tuple = (0.0, 0.0, 0.0)
    scale: float = 1.0
    white: float = DEFAULT_WHITE_LUX

    def __post_init__(self) -> None:
        axis_matrix(self.up)  # "y" or "z", else a ConfigError now

    def point(self, p: npt.ArrayLike) -> np.ndarray:
        """A file point ``(3,)`` in piste's world, ``(3,) float64``."""
        return np.asarray(self.offset, dtype=np.float64) + self.scale * (axis_matrix(self.up) @ np.asarray(p, dtype=np.float64))

    def direction(self, d: npt.ArrayLike) -> tuple:
        """A file direction ``(3,)`` as a unit piste direction (3 floats)."""
        return _unit(axis_matrix(self.up) @ np.asarray(d, dtype=np.float64))


def _unit(v: npt.ArrayLike) -> tuple[float, ...]:
    v = np.asarray(v, dtype=np.float64)
    return tuple(float(x) for x in v / max(float(np.linalg.norm(v)), 1e-300))


def light_from_gltf(fields: dict[str, Any], position: npt.ArrayLike, direction: npt.ArrayLike, frame: GltfFrame = GltfFrame(),
                    index: int = 0) -> DirectionalLight | PointLight | SpotLight:
    """The piste light of one checked ``KHR_lights_punctual`` light (``fields``: name, type, color,
    intensity, range, inner_cone, outer_cone, as :func:`piste.formats.gltf.checks.light_fields`
    gives them) placed at its node's world ``position (3,)`` looking along ``direction (3,)`` (the
    node's -Z), in ``frame`` (see the module docstring); unnamed: "gltf light INDEX"."""
    name = fields.get("name") or f"gltf light {index}"
    color = tuple(float(c) for c in np.asarray(fields["color"], dtype=np.float64).reshape(3))
    d = frame.direction(direction)
    p = tuple(float(x) for x in frame.point(position))
    kind, white, scale = fields["type"], frame.white, frame.scale
    if kind == "directional":
        return DirectionalLight(direction=d, color=color, intensity=float(fields["intensity"]) / white, name=name)
    cd = float(fields["intensity"])
    if fields.get("range") is not None and float(fields["range"]) > 0:
        rng = float(fields["range"]) * scale
    else:
        rng = math.sqrt(256.0 * abs(cd) / white) if cd != 0 else 1.0
    dq = rng / 4.0
    intensity = cd / (white * dq * dq * 0.5625) if rng > 0 else 0.0
    if kind == "spot":
        inner = math.degrees(float(fields["inner_cone"]))
        outer = math.degrees(float(fields["outer_cone"]))
        return SpotLight(position=p, direction=d, color=color, intensity=intensity, range=rng,
                         inner_angle=min(inner, outer), outer_angle=outer, falloff=2.0, name=name)
    if kind == "point":
        return PointLight(position=p, color=color, intensity=intensity, range=rng, falloff=2.0, name=name)
    raise ConfigError(f"glTF light {name!r}: unknown type {kind!r} (expected directional, point or spot)")


def camera_from_gltf(fields: dict[str, Any], position: npt.ArrayLike, forward: npt.ArrayLike, up: npt.ArrayLike, frame: GltfFrame = GltfFrame(), index: int = 0) -> Camera:
    """The :class:`~piste.scene_data.Camera` of one checked glTF camera (``fields``: name, type,
    yfov, aspect, znear, zfar, xmag, ymag; zfar None = infinite) at its node's world ``position``
    looking along ``forward`` (node -Z) with ``up`` (node +Y), each ``(3,)``, in ``frame``.

    The planes the file leaves open stay open: ``far = inf`` without ``zfar``, ``near = 0``
    without ``znear`` (the pipeline fills them); a given ``znear`` is at least 1 mm and a given
    ``zfar`` at least twice it.  Unnamed: "gltf camera INDEX"."""
    name = fields.get("name") or f"gltf camera {index}"
    scale = frame.scale
    eye = frame.point(position)
    fwd = np.asarray(frame.direction(forward))
    upv = np.asarray(frame.direction(up))
    znear, zfar = fields.get("znear"), fields.get("zfar")
    near = max(float(znear) * scale, 1e-3) if znear else 0.0
    far = float(zfar) * scale if zfar else math.inf
    if near > 0 and math.isfinite(far):
        far = max(far, near * 2.0)
    if fields.get("type") == "orthographic":
        ymag = float(fields.get("ymag") or 1.0)
        xmag = fields.get("xmag")
        kw = {"aspect": float(xmag) / ymag} if xmag else {}
        return Camera(eye, eye + 10.0 * fwd, up=upv, near=near, far=far, ortho_height=2.0 * ymag * scale, name=name,
                      **kw)
    kw = {"aspect": float(fields["aspect"])} if fields.get("aspect") is not None else {}
    return Camera(eye, eye + 10.0 * fwd, up=upv, fov_y=math.degrees(float(fields["yfov"])), near=near, far=far,
                  name=name, **kw)


def light_to_gltf(light: AnyLight, white: float = DEFAULT_WHITE_LUX, index: int = 0) -> dict[str, Any] | None:
    """The ``KHR_lights_punctual`` definition of a piste light (``type``, ``name``, ``color``,
    ``intensity`` in lux or candela, optional ``range`` and ``spot``) plus its node's ``position``
    and ``direction`` (piste's coordinates, ``(3,) float64``); None for a light glTF cannot hold
    (ambient or negative: :func:`lights_without_gltf_form`).  Unnamed: "lightINDEX"."""
    if isinstance(light, AmbientLight) or light.intensity < 0:
        return None
    if not isinstance(light, (DirectionalLight, PointLight, SpotLight)):
        raise ValidationError(f"light {getattr(light, 'name', index)!r}: expected a piste light, got {type(light).__name__}")
    name = light.name or f"light{index}"
    color = [float(np.clip(x, 0.0, None)) for x in np.asarray(light.color, dtype=np.float64).reshape(3)]
    if isinstance(light, DirectionalLight):
        return {"type": "directional", "name": name, "color": color, "intensity": float(light.intensity) * white,
                "direction": np.asarray(light.direction, dtype=np.float64)}
    rng = float(light.range)
    if math.isfinite(rng) and rng > 0:
        out = {"intensity": float(light.intensity) * white * (rng / 4.0) ** 2 * 0.5625, "range": rng}
    else:
        out = {"intensity": float(light.intensity) * white * INFINITE_RANGE_MATCH ** 2}
    d = {"type": "point", "name": name, "color": color, **out, "position": np.asarray(light.position, dtype=np.float64),
         "direction": np.array([0.0, 0.0, -1.0])}
    if isinstance(light, SpotLight):
        outer = float(np.clip(math.radians(light.outer_angle), 1e-4, math.pi / 2))
        d.update(type="spot", direction=np.asarray(light.direction, dtype=np.float64),
                 spot={"innerConeAngle": float(np.clip(math.radians(light.inner_angle), 0.0, outer - 1e-6)),
                       "outerConeAngle": outer})
    return d


def lights_without_gltf_form(lights: Iterable[AnyLight]) -> dict[str, list[dict[str, Any]]]:
    """``{"ambient": [...], "negative": [...]}``: the ambient and the negative (darkening) lights
    of ``lights`` (any iterable of piste lights), which glTF cannot hold, as dicts in piste's units
    (infinite numbers as "inf") for a file's ``extras``."""
    ambient, negative = [], []
    for i, li in enumerate(lights):
        name = li.name or f"light{i}"
        if isinstance(li, AmbientLight):
            ambient.append({"name": name, "color": [float(x) for x in np.asarray(li.color, dtype=np.float64)],
                            "intensity": float(li.intensity)})
        elif li.intensity < 0:
            d: dict[str, Any] = {"type": type(li).__name__, "name": name}
            for k in ("position", "direction", "color", "intensity", "range", "falloff", "inner_angle", "outer_angle"):
                if hasattr(li, k):
                    v = getattr(li, k)
                    d[k] = [float(x) for x in v] if np.ndim(v) else (float(v) if math.isfinite(float(v)) else "inf")
            negative.append(d)
    return {"ambient": ambient, "negative": negative}


def camera_to_gltf(camera: Camera) -> dict:
    """A glTF camera's fields for a :class:`~piste.scene_data.Camera`: ``type``, ``yfov`` (radians)
    or ``xmag`` / ``ymag``, ``znear``, ``zfar`` (None: infinite), ``aspect``; with the node's
    ``position``, ``forward`` (unit) and ``up`` in piste's coordinates."""
    eye = np.asarray(camera.eye, dtype=np.float64)
    fwd = np.asarray(camera.target, dtype=np.float64) - eye
    fwd = fwd / max(float(np.linalg.norm(fwd)), 1e-300)
    a = float(camera.aspect)
    zfar = float(camera.far) if math.isfinite(float(camera.far)) else None
    out = {"name": camera.name, "position": eye, "forward": fwd, "up": np.asarray(camera.up, dtype=np.float64),
           "znear": float(camera.near), "zfar": zfar, "aspect": a}
    if camera.ortho_height is not None:
        ymag = float(camera.ortho_height) / 2
        out.update(type="orthographic", ymag=ymag, xmag=float(camera.ortho_height) / 2 * a)
    else:
        out.update(type="perspective", yfov=math.radians(float(camera.fov_y)))
    return out
