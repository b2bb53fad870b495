"""One camera type and one light family (piste.scene_data), shared by the scene file, glTF import
and export, the bundle, the baker and the renderer (issue 25)."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

from piste import scene_data
from piste.errors import ValidationError

SRC = Path(__file__).resolve().parents[1] / "src" / "piste"


def test_the_layers_re_export_the_same_classes():
    import piste.character
    from piste.lighting import lights
    from piste.world import camera

    assert camera.Camera is scene_data.Camera
    for name in ("AmbientLight", "DirectionalLight", "PointLight", "SpotLight", "Lights"):
        assert getattr(lights, name) is getattr(scene_data, name)
    assert not hasattr(piste.character, "Camera") and not hasattr(piste.character, "Light")


def test_no_second_camera_or_light_class_anywhere():
    """A class named Camera, or a light class (``*Light``), is defined only in scene_data."""
    found = []
    for path in sorted(SRC.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ClassDef) and (node.name == "Camera" or node.name.endswith("Light")):
                found.append(f"{path.relative_to(SRC)}:{node.lineno} {node.name}")
    assert found and all(f.startswith("scene_data.py:") for f in found), found


def test_camera_carries_a_name_and_its_matrices():
    c = scene_data.Camera([0, -10, 5], [0, 0, 0], fov_y=50.0, near=1.0, far=100.0, name="main")
    assert c.name == "main" and c.with_aspect(4, 3).aspect == pytest.approx(4 / 3)
    p = c.view_projection() @ np.array([0.0, 0.0, 0.0, 1.0])
    assert abs(p[0] / p[3]) < 1e-9 and abs(p[1] / p[3]) < 1e-9  # the target is at the centre
    assert scene_data.Camera([0, 0, 0], [1, 0, 0]).name == ""


@pytest.mark.parametrize("make, field", [
    (lambda: scene_data.PointLight(position=(0, 0, math.nan), color=(2e6, 0, 0)), "point light '' position"),
    (lambda: scene_data.SpotLight(direction=(0, 0, 0)), "spot light '' direction"),
    (lambda: scene_data.SpotLight(inner_angle=40.0, outer_angle=30.0), "inner_angle <= outer_angle"),
    (lambda: scene_data.DirectionalLight(color=(1, 1), name="sun"), "directional light 'sun' color"),
    (lambda: scene_data.AmbientLight(intensity=math.inf), "ambient light '' intensity"),
    (lambda: scene_data.PointLight(range=0.0), "point light '' range"),
    (lambda: scene_data.PointLight(falloff=-1.0), "point light '' falloff"),
])
def test_bad_light_fields_are_named_in_order(make, field):
    with pytest.raises(ValidationError, match=field):
        make()


def test_lights_are_normalised_on_construction():
    s = scene_data.SpotLight(direction=(0, 0, -2), shadows=0, name="s")
    assert s.direction == (0.0, 0.0, -1.0) and s.shadows is False and isinstance(s.color, tuple)
    d = scene_data.DirectionalLight(direction=(0.0, 0.6, -0.8))
    assert d.direction == (0.0, 0.6, -0.8)  # a unit vector is kept bit for bit


def test_a_bundle_camera_keeps_its_name():
    from piste.formats.bundle import camera_to_dict
    from piste.pipeline.bundle_objects import camera_from_dict

    d = dict(camera_to_dict(scene_data.Camera([0, -10, 5], [0, 0, 0], near=1.0, far=100.0)), name="main")
    c = camera_from_dict(d)
    assert isinstance(c, scene_data.Camera) and c.name == "main" and (c.near, c.far) == (1.0, 100.0)
