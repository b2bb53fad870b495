"""piste.formats.gltf.units: glTF's cameras and KHR_lights_punctual units <-> piste's one Camera and
light family, both ways."""

from __future__ import annotations

import math

import numpy as np
import pytest

from piste.errors import ConfigError
from piste.formats.gltf.units import (GltfFrame, camera_from_gltf, camera_to_gltf, light_from_gltf, light_to_gltf,
                                      lights_without_gltf_form)
from piste.scene_data import AmbientLight, Camera, DirectionalLight, Lights, PointLight, SpotLight

LIGHTS = [DirectionalLight(direction=(0.3, 0.4, -0.8), color=(1.0, 0.9, 0.8), intensity=1.2, name="sun"),
          PointLight(position=(5.0, 6.0, 7.0), intensity=0.7, range=40.0, falloff=2.0, name="lamp"),
          SpotLight(position=(1.0, 2.0, 30.0), direction=(0.0, 0.1, -1.0), intensity=0.9, range=60.0,
                    inner_angle=10.0, outer_angle=28.0, falloff=2.0, name="spot")]


def _khr(d: dict) -> dict:
    """light_to_gltf's definition as the reader's checked fields."""
    spot = d.get("spot", {})
    return {"name": d["name"], "type": d["type"], "color": d["color"], "intensity": d["intensity"],
            "range": d.get("range"), "inner_cone": spot.get("innerConeAngle", 0.0),
            "outer_cone": spot.get("outerConeAngle", math.pi / 4)}


@pytest.mark.parametrize("light", LIGHTS, ids=lambda x: x.name)
def test_a_light_written_and_read_back_is_the_same(light):
    d = light_to_gltf(light)
    back = light_from_gltf(_khr(d), d["position"] if "position" in d else np.zeros(3), d["direction"],
                           GltfFrame(up="z"))
    assert type(back) is type(light) and back.name == light.name
    for k in ("intensity", "range", "inner_angle", "outer_angle"):
        if hasattr(light, k):
            assert getattr(back, k) == pytest.approx(getattr(light, k), rel=1e-12), k
    for k in ("position", "direction"):
        if hasattr(light, k):
            assert np.allclose(getattr(back, k), getattr(light, k), atol=1e-12), k


def test_units_and_the_frame():
    d = light_to_gltf(LIGHTS[0], white=683.0)
    assert d["intensity"] == pytest.approx(1.2 * 683.0)  # lux
    lamp = {"name": "", "type": "point", "color": (1, 1, 1), "intensity": 2000.0, "range": 10.0}
    f = GltfFrame(up="y", offset=(100.0, 0.0, 5.0), scale=2.0)
    p = light_from_gltf(lamp, (1.0, 2.0, 3.0), (0, 0, -1), f, index=4)
    assert p.name == "gltf light 4" and p.range == 20.0  # lengths scale
    assert p.position == (102.0, -6.0, 9.0)  # glTF (x, y, z) -> offset + scale * (x, -z, y)
    assert light_to_gltf(PointLight(intensity=0.5))["intensity"] == pytest.approx(0.5 * 683.0 * 100.0)  # matched at 10 m
    with pytest.raises(ConfigError, match="up axis"):
        GltfFrame(up="x")


def test_lights_glTF_cannot_hold():
    lights = Lights((AmbientLight(intensity=0.3), PointLight(intensity=-0.5, range=5.0, name="dark"), *LIGHTS))
    # (canonical order: ambient, directional, point, spot)
    assert [light_to_gltf(x) is None for x in lights] == [True, False, True, False, False]
    other = lights_without_gltf_form(lights)
    assert [x["name"] for x in other["ambient"]] == ["light0"] and [x["name"] for x in other["negative"]] == ["dark"]


def test_cameras_both_ways():
    cams = [Camera([10.0, -20.0, 15.0], [10.0, -19.2, 14.4], fov_y=50.0, aspect=1.5, near=0.5, far=900.0, name="c"),
            Camera([0.0, 0.0, 100.0], [0.0, 1.0, 0.0], near=1.0, far=math.inf, aspect=2.0, ortho_height=80.0, name="o")]
    for c in cams:
        f = camera_to_gltf(c)
        back = camera_from_gltf(f, f["position"], f["forward"], f["up"], GltfFrame(up="z"))
        assert back.name == c.name and np.allclose(back.eye, c.eye) and np.allclose(back.forward, c.forward)
        assert (back.near, back.far, back.aspect, back.ortho_height) == (c.near, c.far, c.aspect, c.ortho_height)
        assert back.fov_y == pytest.approx(c.fov_y)
    assert camera_to_gltf(cams[1])["zfar"] is None  # infinite: no zfar in the file
    # the planes a file leaves open stay open (the pipeline fills them)
    open_cam = camera_from_gltf({"type": "perspective", "yfov": 0.8, "znear": 0.0, "zfar": None}, np.zeros(3),
                                (0, 0, -1), (0, 1, 0), index=2)
    assert (open_cam.name, open_cam.near, open_cam.far) == ("gltf camera 2", 0.0, math.inf)
