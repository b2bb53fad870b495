"""glTF scenes as the artist's tool: lights (KHR_lights_punctual) and cameras into piste.

An artist lights and frames a scene in Blender, exports glTF, and names the file in the scene's
``[[gltf]]`` table; :func:`import_gltf` turns what :func:`piste.formats.gltf.load_gltf` parsed
(``Model.lights``, ``Model.cameras``, placed by their nodes' world transforms) into piste's lighting
classes and cameras.

Axes
----
glTF is right-handed, +Y up, -Z forward (Blender's exporter maps Blender's ``(x, y, z)`` to glTF
``(x, z, -y)``); piste is right-handed, +Z up.  A glTF point ``(x, y, z)`` becomes piste
``offset + scale * (x, -z, y)`` (``up = "y"``, the default) -- exactly Blender's own coordinates
again -- or ``offset + scale * (x, y, z)`` for files already Z-up (``up = "z"``).  Directions
(light directions, camera forward and up) use the same rotation without offset and scale.

Light units
-----------
KHR_lights_punctual gives directional lights in lux (lm/m^2) and point and spot lights in candela
(lm/sr), with inverse-square falloff (``E = I / d^2``) cut off at an optional ``range``.  piste's
lights are relative: 1.0 is full white, and point/spot lights fade as ``(1 - d/range)^falloff``.
With ``white`` the illuminance in lux that piste shows as 1.0 (default 683 lux: Blender's exporter
writes a sun of strength 1 W/m^2 as 683 lux, so a strength-1 sun gives piste intensity 1.0):

* directional: ``intensity = lux / white``;
* point and spot: ``falloff = 2``; ``range`` = the glTF range, or where ``I / d^2`` drops to
  ``white / 256`` (below one step of an 8-bit half-bright light map) when the file gives none:
  ``range = sqrt(256 I / white)``; ``intensity`` matches the inverse-square illuminance at a quarter
  of the range: ``intensity = I / (white d_q^2 (3/4)^2)`` with ``d_q = range / 4`` (so piste's light
  is within a factor of ~2 of the physical one between ~range/6 and ~range/2 and fades to exactly
  zero at ``range`` where glTF's only approaches it);
* spot cone: glTF ``innerConeAngle`` / ``outerConeAngle`` (radians, from the axis) become piste's
  ``inner_angle`` / ``outer_angle`` half-angles in degrees (both blend smoothly between them);
* colours are linear RGB in both.  glTF has no ambient light: give one inline (``[[lights]]``).

Cameras
-------
Perspective: ``yfov`` (radians) -> ``fov_y`` degrees; ``znear`` -> ``near``; ``zfar`` -> ``far``.  A
camera without ``zfar`` (infinite) or ``znear`` gets the planes of a scene camera that names none
(:func:`piste.world.camera.camera_planes`): 4000 m until the terrain is known, then a far plane
reaching the whole terrain (never under 4000 m; :meth:`GltfCameras.fitted`, called by the build);
the aspect ratio is the render's.  The camera looks down its node's -Z with the
node's +Y as up (roll is kept).  Orthographic: ``ortho_height = 2 * ymag * scale``.

API
---
::

    axis_matrix(up) -> (3, 3)                 glTF axes -> piste axes
    import_gltf(spec) -> (lights, cameras)    piste lights (list) and ``{name: piste.world.camera.Camera}``
    convert_lights(model_lights, ...), convert_cameras(model_cameras, ...)
    write_scene_gltf(path, lights, cameras)   a small glTF with KHR_lights_punctual lights and cameras
                                              (examples and tests: what Blender would export)
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from piste.errors import ConfigError
from piste.formats.atomic import write_bytes_atomic
from piste.formats.gltf import load_gltf
from piste.lighting.lights import DirectionalLight, PointLight, SpotLight
from piste.transforms import look_rotation
from piste.world.camera import Camera, camera_planes

__all__ = ["axis_matrix", "import_gltf", "convert_lights", "convert_cameras", "GltfCameras", "write_scene_gltf", "DEFAULT_WHITE_LUX"]

DEFAULT_WHITE_LUX = 683.0
#: glTF (x, y, z) -> piste (x, -z, y)
_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def axis_matrix(up: str = "y") -> np.ndarray:
    """Rotation ``(3, 3) float64`` from a file's axes to piste's (Z up): ``up`` "y" (glTF) or "z"."""
    if up == "y":
        return _Y_UP.copy()
    if up == "z":
        return np.eye(3)
    raise ConfigError(f"glTF up axis must be 'y' or 'z', got {up!r}")


def _unit(v) -> tuple:
    v = np.asarray(v, dtype=np.float64)
    return tuple(float(x) for x in v / max(float(np.linalg.norm(v)), 1e-300))


def convert_lights(model_lights, up: str = "y", offset=(0.0, 0.0, 0.0), scale: float = 1.0,
                   white: float = DEFAULT_WHITE_LUX) -> list:
    """piste lights for :class:`piste.character.Light` items (see the module docstring)."""
    a = axis_matrix(up)
    off = np.asarray(offset, dtype=np.float64)
    out = []
    for i, li in enumerate(model_lights):
        name = li.name or f"gltf light {i}"
        color = tuple(float(c) for c in np.asarray(li.color, dtype=np.float64).reshape(3))
        direction = _unit(a @ np.asarray(li.direction, dtype=np.float64))
        position = tuple(float(x) for x in off + scale * (a @ np.asarray(li.position, dtype=np.float64)))
        if li.type == "directional":
            out.append(DirectionalLight(direction=direction, color=color, intensity=float(li.intensity) / white, name=name))
            continue
        cd = float(li.intensity)
        if li.range is not None and float(li.range) > 0:
            rng = float(li.range) * scale
        else:
            rng = math.sqrt(256.0 * abs(cd) / white) if cd != 0 else 1.0
        dq = rng / 4.0
        intensity = cd / (white * dq * dq * 0.5625) if rng > 0 else 0.0
        if li.type == "spot":
            inner = math.degrees(float(li.inner_cone))
            outer = math.degrees(float(li.outer_cone))
            out.append(SpotLight(position=position, direction=direction, color=color, intensity=intensity, range=rng,
                                 inner_angle=min(inner, outer), outer_angle=outer, falloff=2.0, name=name))
        elif li.type == "point":
            out.append(PointLight(position=position, color=color, intensity=intensity, range=rng, falloff=2.0, name=name))
        else:
            raise ConfigError(f"glTF light {name!r}: unknown type {li.type!r} (expected directional, point or spot)")
    return out


class GltfCameras(dict):
    """``{name: Camera}`` imported from a glTF file, remembering which planes the file gave:
    ``planes_given[name]`` is ``(znear, zfar)`` in metres, None where the file has none (an
    infinite ``zfar``).  :meth:`fitted` re-derives the missing planes once the terrain is known."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.planes_given: dict = {}

    def fitted(self, lo=None, hi=None) -> dict:
        """``{name: Camera}`` with the planes the file did not give following the terrain bounded
        by ``lo..hi`` (``(3,)`` each; None: unknown) by the scene cameras' rule
        (:func:`piste.world.camera.camera_planes`); cameras whose file gave both are unchanged."""
        from dataclasses import replace

        out = {}
        for name, cam in self.items():
            near, far = self.planes_given.get(name, (cam.near, cam.far))
            if near is None or far is None:
                near, far = camera_planes(cam.eye, lo, hi, near, far)
                cam = replace(cam, near=near, far=far)
            out[name] = cam
        return out


def convert_cameras(model_cameras, up: str = "y", offset=(0.0, 0.0, 0.0), scale: float = 1.0) -> GltfCameras:
    """``{name: piste.world.camera.Camera}`` for :class:`piste.character.Camera` items (a
    :class:`GltfCameras`: missing planes are 4000 m far / 0.5 m near until :meth:`GltfCameras.fitted`)."""
    a = axis_matrix(up)
    off = np.asarray(offset, dtype=np.float64)
    out = GltfCameras()
    for i, c in enumerate(model_cameras):
        name = c.name or f"gltf camera {i}"
        eye = off + scale * (a @ np.asarray(c.position, dtype=np.float64))
        fwd = np.asarray(_unit(a @ np.asarray(c.forward, dtype=np.float64)))
        upv = np.asarray(_unit(a @ np.asarray(c.up, dtype=np.float64)))
        given_near = max(float(c.znear) * scale, 1e-3) if c.znear else None
        given_far = float(c.zfar) * scale if c.zfar else None
        if given_far is not None and given_near is not None:
            given_far = max(given_far, given_near * 2.0)
        near, far = camera_planes(eye, None, None, given_near, given_far)
        if c.type == "orthographic":
            cam = Camera(eye, eye + 10.0 * fwd, up=upv, near=near, far=far,
                         ortho_height=2.0 * float(c.ymag or 1.0) * scale)
        else:
            cam = Camera(eye, eye + 10.0 * fwd, up=upv, fov_y=math.degrees(float(c.yfov)), near=near, far=far)
        out[name] = cam
        out.planes_given[name] = (given_near, given_far)
    return out


def import_gltf(spec) -> tuple[list, dict]:
    """Lights and cameras of a :class:`piste.world.scene_file.GltfSpec`'s file, in piste's terms."""
    model = load_gltf(spec.file, allow_paths=getattr(spec, "allow_paths", ()))
    lights = convert_lights(model.lights, spec.up, spec.offset, spec.scale, spec.white) if spec.lights else []
    cameras = convert_cameras(model.cameras, spec.up, spec.offset, spec.scale) if spec.cameras else GltfCameras()
    return lights, cameras


# ----------------------------------------------------------------------------- writing
def _quat_looking(forward, up) -> list:
    """glTF node rotation ``[x, y, z, w]`` whose -Z axis is ``forward`` and +Y is (nearly) ``up``."""
    return look_rotation(forward, up, fallback=(0.0, 0.0, 1.0))


def write_scene_gltf(path, lights=(), cameras=(), up: str = "y") -> Path:
    """Write a glTF file (JSON, no buffers) holding KHR_lights_punctual lights and cameras -- what
    Blender exports for a lit, framed scene.  Positions and directions are given in **piste**
    coordinates (Z up) and converted to the file's axes (``up``), so importing the file back gives
    them again.

    Parameters
    ----------
    lights : dicts with ``type`` ("directional" | "point" | "spot"), ``name``, ``color``, glTF
        ``intensity`` (lux or candela), ``position`` and/or ``direction``, optional ``range``,
        ``inner_cone`` / ``outer_cone`` (radians)
    cameras : dicts with ``name``, ``eye``, ``target``, optional ``yfov`` (radians), ``znear``, ``zfar``
    """
    import pygltflib

    inv = axis_matrix(up).T  # piste -> file
    nodes, defs, cams = [], [], []
    for i, li in enumerate(lights):
        d = {"type": li["type"], "name": li.get("name", f"light{i}"), "color": list(map(float, li.get("color", (1, 1, 1)))),
             "intensity": float(li.get("intensity", 1.0))}
        if li.get("range") is not None:
            d["range"] = float(li["range"])
        if li["type"] == "spot":
            d["spot"] = {"innerConeAngle": float(li.get("inner_cone", 0.0)),
                         "outerConeAngle": float(li.get("outer_cone", math.pi / 4))}
        defs.append(d)
        direction = inv @ np.asarray(li.get("direction", (0.0, 0.0, -1.0)), dtype=np.float64)
        world_up = inv @ np.array([0.0, 0.0, 1.0])
        node = pygltflib.Node(name=d["name"], rotation=_quat_looking(direction, world_up),
                              extensions={"KHR_lights_punctual": {"light": i}})
        if "position" in li:
            node.translation = [float(x) for x in inv @ np.asarray(li["position"], dtype=np.float64)]
        nodes.append(node)
    for c in cameras:
        eye = np.asarray(c["eye"], dtype=np.float64)
        fwd = inv @ (np.asarray(c["target"], dtype=np.float64) - eye)
        cams.append(pygltflib.Camera(name=c["name"], type="perspective",
                                     perspective=pygltflib.Perspective(yfov=float(c.get("yfov", math.radians(60.0))),
                                                                      znear=float(c.get("znear", 0.5)),
                                                                      zfar=c.get("zfar", 4000.0))))
        nodes.append(pygltflib.Node(name=c["name"], camera=len(cams) - 1, translation=[float(x) for x in inv @ eye],
                                    rotation=_quat_looking(fwd, inv @ np.array([0.0, 0.0, 1.0]))))
    g = pygltflib.GLTF2(asset=pygltflib.Asset(version="2.0", generator="piste write_scene_gltf"),
                        scene=0, scenes=[pygltflib.Scene(nodes=list(range(len(nodes))))], nodes=nodes, cameras=cams)
    if defs:
        g.extensionsUsed = ["KHR_lights_punctual"]
        g.extensions = {"KHR_lights_punctual": {"lights": defs}}
    text = g.to_json(indent=1, sort_keys=True)
    path = Path(path)
    write_bytes_atomic(path, (text + "\n").encode())
    return path
