"""glTF scenes as the artist's tool: lights (KHR_lights_punctual) and cameras into piste.

An artist lights and frames a scene in Blender, exports glTF, and names the file in the scene's
``[[gltf]]`` table; :func:`import_gltf` reads it with :func:`piste.formats.gltf.load_gltf` in the
table's frame (``up``, ``offset``, ``scale``, ``white``), which gives the file's lights and cameras
as piste's own (:mod:`piste.scene_data`) by the axis and unit conventions of
:mod:`piste.formats.gltf.units`, and gives the cameras the planes their file leaves open.

Cameras
-------
A camera without ``zfar`` (infinite) or ``znear`` gets the planes of a scene camera that names none
(:func:`piste.world.camera.camera_planes`): 4000 m until the terrain is known, then a far plane
reaching the whole terrain (never under 4000 m; :meth:`GltfCameras.fitted`, called by the build);
the aspect ratio is the render's.

API
---
::

    import_gltf(spec) -> (lights, cameras)    piste lights (list) and ``{name: piste.scene_data.Camera}``
    axis_matrix(up) -> (3, 3)                 glTF axes -> piste axes (:mod:`piste.formats.gltf.units`)
    write_scene_gltf(path, lights, cameras)   a small glTF with KHR_lights_punctual lights and cameras
                                              (examples and tests: what Blender would export)
"""

from __future__ import annotations

import math
from dataclasses import replace
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from piste.formats.atomic import write_bytes_atomic
from piste.formats.gltf import load_gltf
from piste.formats.gltf.units import DEFAULT_WHITE_LUX, GltfFrame, axis_matrix
from piste.transforms import look_rotation
from piste.world.camera import Camera, camera_planes

if TYPE_CHECKING:
    import numpy.typing as npt

    from piste.world.scene_file import GltfSpec

__all__ = ["axis_matrix", "import_gltf", "GltfCameras", "write_scene_gltf", "DEFAULT_WHITE_LUX"]


class GltfCameras(dict):
    """``{name: Camera}`` imported from a glTF file, remembering which planes the file gave:
    ``planes_given[name]`` is ``(znear, zfar)`` in metres, None where the file has none (an
    infinite ``zfar``).  :meth:`fitted` re-derives the missing planes once the terrain is known."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.planes_given: dict[str, tuple[float | None, float | None]] = {}

    @classmethod
    def from_file(cls, cameras: Iterable[Camera]) -> "GltfCameras":
        """The runtime cameras of a file's (:attr:`piste.character.Model.cameras`: ``far = inf``
        / ``near = 0`` where the file leaves a plane open): open planes are 4000 m far / 0.5 m near
        (:func:`piste.world.camera.camera_planes`) until :meth:`fitted`."""
        out = cls()
        for cam in cameras:
            given_near = float(cam.near) if cam.near > 0 else None
            given_far = float(cam.far) if math.isfinite(cam.far) else None
            near, far = camera_planes(cam.eye, None, None, given_near, given_far)
            out[cam.name] = replace(cam, near=near, far=far)
            out.planes_given[cam.name] = (given_near, given_far)
        return out

    def fitted(self, lo: npt.ArrayLike | None = None, hi: npt.ArrayLike | None = None) -> dict[str, Camera]:
        """``{name: Camera}`` with the planes the file did not give following the terrain bounded
        by ``lo..hi`` (``(3,)`` each; None: unknown) by the scene cameras' rule
        (:func:`piste.world.camera.camera_planes`); cameras whose file gave both are unchanged."""
        out = {}
        for name, cam in self.items():
            near, far = self.planes_given.get(name, (cam.near, cam.far))
            if near is None or far is None:
                near, far = camera_planes(cam.eye, lo, hi, near, far)
                cam = replace(cam, near=near, far=far)
            out[name] = cam
        return out


def import_gltf(spec: GltfSpec) -> tuple[list[Any], GltfCameras]:
    """Lights and cameras of a :class:`piste.world.scene_file.GltfSpec`'s file, in piste's terms."""
    frame = GltfFrame(spec.up, tuple(spec.offset), float(spec.scale), float(spec.white))
    model = load_gltf(spec.file, allow_paths=getattr(spec, "allow_paths", ()), frame=frame)
    lights = list(model.lights) if spec.lights else []
    cameras = GltfCameras.from_file(model.cameras) if spec.cameras else GltfCameras()
    return lights, cameras


# ----------------------------------------------------------------------------- writing
def _quat_looking(forward: npt.ArrayLike, up: npt.ArrayLike) -> list[float]:
    """glTF node rotation ``[x, y, z, w]`` whose -Z axis is ``forward`` and +Y is (nearly) ``up``."""
    return look_rotation(forward, up, fallback=(0.0, 0.0, 1.0))


def write_scene_gltf(path: str | Path, lights: Sequence[Mapping[str, Any]] = (),
                     cameras: Sequence[Mapping[str, Any]] = (), up: str = "y") -> Path:
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
