"""glTF scenes as the artist's tool: KHR_lights_punctual lights and cameras -> piste (axes, units)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from piste.lighting.lights import DirectionalLight, PointLight, SpotLight
from piste.formats.gltf.units import GltfFrame, light_from_gltf
from piste.pipeline.gltf_import import axis_matrix, import_gltf, write_scene_gltf
from piste.world.scene_file import GltfSpec

LIGHTS = [
    {"type": "directional", "name": "sun", "intensity": 683.0, "direction": (0.3, 0.8, -0.5), "color": (1.0, 0.9, 0.8)},
    {"type": "spot", "name": "spot", "intensity": 5000.0, "position": (10.0, 20.0, 30.0), "direction": (0.0, 0.0, -1.0),
     "range": 40.0, "inner_cone": 0.2, "outer_cone": 0.5},
    {"type": "point", "name": "lamp", "intensity": 100.0, "position": (1.0, 2.0, 3.0)},
]
CAMERAS = [{"name": "cam", "eye": (100.0, 50.0, 300.0), "target": (100.0, 150.0, 260.0), "yfov": math.radians(40.0),
            "znear": 0.25, "zfar": 900.0}]


def test_axis_matrix_is_blenders_export_inverted():
    a = axis_matrix("y")
    # Blender (x, y, z) is written to glTF as (x, z, -y); importing gives Blender's coordinates back
    blender = np.array([1.0, 2.0, 3.0])
    gltf = np.array([blender[0], blender[2], -blender[1]])
    assert np.allclose(a @ gltf, blender)
    assert np.allclose(a @ a.T, np.eye(3)) and np.isclose(np.linalg.det(a), 1.0)
    assert np.array_equal(axis_matrix("z"), np.eye(3))


@pytest.mark.parametrize("up", ["y", "z"])
def test_lights_and_cameras_round_trip_through_a_gltf_file(tmp_path, up):
    path = write_scene_gltf(tmp_path / "scene.gltf", LIGHTS, CAMERAS, up=up)
    lights, cams = import_gltf(GltfSpec(file=path, up=up))
    sun, spot, lamp = lights
    assert isinstance(sun, DirectionalLight) and isinstance(spot, SpotLight) and isinstance(lamp, PointLight)
    d = np.array([0.3, 0.8, -0.5])
    assert np.allclose(sun.direction, d / np.linalg.norm(d))
    assert sun.intensity == pytest.approx(1.0)  # 683 lux = white
    assert sun.color == pytest.approx((1.0, 0.9, 0.8))
    assert np.allclose(spot.position, (10.0, 20.0, 30.0)) and np.allclose(spot.direction, (0.0, 0.0, -1.0))
    assert spot.inner_angle == pytest.approx(math.degrees(0.2)) and spot.outer_angle == pytest.approx(math.degrees(0.5))
    assert spot.range == 40.0 and spot.falloff == 2.0
    assert np.allclose(lamp.position, (1.0, 2.0, 3.0))
    cam = cams["cam"]
    assert np.allclose(cam.eye, (100.0, 50.0, 300.0))
    f = np.array([0.0, 100.0, -40.0])
    assert np.allclose(cam.forward, f / np.linalg.norm(f))
    assert cam.fov_y == pytest.approx(40.0) and cam.near == 0.25 and cam.far == 900.0
    assert cam.up @ cam.forward == pytest.approx(0.0, abs=1e-12) and cam.up[2] > 0.9


def test_offset_and_scale(tmp_path):
    path = write_scene_gltf(tmp_path / "s.gltf", LIGHTS[2:], CAMERAS)
    lights, cams = import_gltf(GltfSpec(file=path, offset=(100.0, 0.0, 5.0), scale=2.0))
    assert np.allclose(lights[0].position, (102.0, 4.0, 11.0))
    assert np.allclose(cams["cam"].eye, (300.0, 100.0, 605.0))


def test_photometric_conversion():
    white = 683.0
    cd = 2000.0
    lamp = {"name": "lamp", "type": "point", "color": np.ones(3), "intensity": cd, "range": None}
    p = light_from_gltf(lamp, np.zeros(3), np.array([0, 0, -1.0]), GltfFrame(up="z", white=white))
    # no glTF range: piste's range is where I/d^2 falls to white/256
    assert p.range == pytest.approx(math.sqrt(256 * cd / white))
    # piste's (1 - d/r)^2 ramp matches the inverse-square illuminance at a quarter of the range
    d = p.range / 4
    assert p.intensity * (1 - d / p.range) ** 2 == pytest.approx(cd / d**2 / white)
    ranged = dict(lamp, range=30.0)
    assert light_from_gltf(ranged, np.zeros(3), np.array([0, 0, -1.0]), GltfFrame(up="z")).range == 30.0


def test_wysiwyg_gltf_lights_bake_like_the_same_lights_inline(small_scene):
    """A scene lit in a glTF file bakes the same light map as the scene with those lights typed in."""
    from piste.pipeline.bundle_objects import load_bundle
    from piste.pipeline.build import build_scene

    inline = small_scene(riders=False)
    lights, _ = import_gltf(GltfSpec(file=write_scene_gltf(inline.parent / "l.gltf", LIGHTS[:1], CAMERAS)))
    sun = lights[0]
    text = inline.read_text().replace(
        "direction = [0.3, 0.6, -0.6]\ncolor = [1.0, 0.9, 0.8]\nintensity = 1.0",
        f"direction = {list(sun.direction)}\ncolor = {list(sun.color)}\nintensity = {sun.intensity!r}\nname = 'sun'")
    inline.write_text(text)
    from_gltf = small_scene(riders=False)
    write_scene_gltf(from_gltf.parent / "l.gltf", LIGHTS[:1], CAMERAS)
    t = from_gltf.read_text()
    start = t.index("[[lights]]\ntype = \"directional\"")
    end = t.index("[[cameras]]")
    from_gltf.write_text(t[:start] + t[end:] + '\n[[gltf]]\nfile = "l.gltf"\n')
    a = load_bundle(build_scene(inline).path)
    b = load_bundle(build_scene(from_gltf).path)
    assert np.array_equal(a.arrays["lightmap/atlas"], b.arrays["lightmap/atlas"])
    assert "cam" in b.cameras and np.allclose(b.cameras["cam"].eye, CAMERAS[0]["eye"])


def test_camera_without_zfar_follows_the_terrain(tmp_path):
    """No ``zfar`` (infinite): 4 km until the terrain is known, then the scene cameras' rule
    (a far plane reaching the terrain, never under 4 km); a given ``zfar`` / ``znear`` stays."""
    from piste.world.camera import camera_planes

    open_cam = dict(CAMERAS[0], name="open", zfar=None)
    path = write_scene_gltf(tmp_path / "s.gltf", [], [open_cam, CAMERAS[0]])
    _, cams = import_gltf(GltfSpec(file=path))
    assert cams["open"].far == 4000.0 and cams["open"].near == 0.25
    lo, hi = np.array([0.0, 0.0, 0.0]), np.array([30000.0, 20000.0, 500.0])
    fitted = cams.fitted(lo, hi)
    assert fitted["open"].far == pytest.approx(camera_planes(cams["open"].eye, lo, hi, 0.25)[1])
    assert fitted["open"].far >= np.linalg.norm(hi - cams["open"].eye) and fitted["open"].near == 0.25
    assert fitted["cam"].far == 900.0 and fitted["cam"].near == 0.25
    small = cams.fitted(np.zeros(3), np.array([100.0, 100.0, 10.0]))  # the default course's size: 4 km stays
    assert small["open"].far == 4000.0
