"""Scene-file numbers are finite and in range (issue 24 item 3): a camera's near/far (and their
ratio), field of view, seeds, sizes, scales and coordinates are refused by a SceneError naming the
file, line and key, never a LinAlgError (or a huge allocation) deep in the pipeline."""

from __future__ import annotations

import re

import numpy as np
import pytest

from piste.world.camera import MAX_DEPTH_RATIO, Camera
from piste.world.scene_file import MAX_FAR_NEAR_RATIO, SceneError, loads_scene

CAM = '[[cameras]]\nname = "c"\neye = [0.0, 0.0, 10.0]\ntarget = [100.0, 0.0, 0.0]\n'


def test_near_1e_300_far_1e300_is_a_scene_error(tmp_path):
    with pytest.raises(SceneError, match=r"s\.toml, line 5, key 'cameras\[0\]\.near': expected metres in "
                                         r"\[0\.0001, 1e\+07\], got 1e-300"):
        loads_scene(CAM + "near = 1e-300\nfar = 1e300\n", tmp_path / "s.toml")
    with pytest.raises(SceneError, match=r"key 'cameras\[0\]\.far': expected metres in \[0\.0001, 1e\+08\], got 1e\+300"):
        loads_scene(CAM + "far = 1e300\n", tmp_path / "s.toml")


def test_far_near_ratio_bounded(tmp_path):
    assert MAX_FAR_NEAR_RATIO == MAX_DEPTH_RATIO
    with pytest.raises(SceneError, match=r"key 'cameras\[0\]\.far': expected far / near <= 1e\+07 .*ratio 1e\+08"):
        loads_scene(CAM + "near = 0.001\nfar = 100000.0\n", tmp_path / "s.toml")
    with pytest.raises(SceneError, match=r"'cameras\[0\]\.far': expected near < far"):
        loads_scene(CAM + "near = 10.0\nfar = 5.0\n", tmp_path / "s.toml")
    cam = loads_scene(CAM + "near = 0.01\nfar = 100000.0\n", tmp_path / "s.toml").cameras[0]
    assert (cam.near, cam.far) == (0.01, 100000.0)


def test_unset_planes_are_left_to_the_terrain(tmp_path):
    cam = loads_scene(CAM, tmp_path / "s.toml").cameras[0]
    assert cam.near is None and cam.far is None


@pytest.mark.parametrize(("extra", "key"), [
    ("fov = 0.0\n", "fov"), ("fov = 180.0\n", "fov"), ("fov = -10.0\n", "fov"), ("fov = 1e300\n", "fov"),
    ("fov = nan\n", "fov"), ("near = inf\n", "near"), ("near = -1.0\n", "near"), ("height = -5.0\n", "height"),
    ("height = 1e300\n", "height"),
])
def test_camera_numbers(tmp_path, extra, key):
    with pytest.raises(SceneError, match=rf"s\.toml, line \d+, key 'cameras\[0\]\.{key}': expected"):
        loads_scene(CAM + extra, tmp_path / "s.toml")


def test_camera_coordinates_bounded(tmp_path):
    with pytest.raises(SceneError, match=r"key 'cameras\[0\]\.eye': expected metres in \[-1e\+08, 1e\+08\]"):
        loads_scene(CAM.replace("[0.0, 0.0, 10.0]", "[1e300, 0.0, 10.0]"), tmp_path / "s.toml")


@pytest.mark.parametrize(("text", "key"), [
    ("[terrain]\nseed = -1\n", "terrain.seed"),
    ("[terrain]\nseed = 4294967296\n", "terrain.seed"),
    ("[terrain]\nsamples_per_patch = 100000\n", "terrain.samples_per_patch"),
    ("[terrain]\nheight_scale = 1e300\n", "terrain.height_scale"),
    ("[terrain]\nheight_offset = -1e300\n", "terrain.height_offset"),
    ("[visibility]\ncell = 1e-300\n", "visibility.cell"),
    ("[visibility]\neye_heights = [1.7, 1e300]\n", "visibility.eye_heights"),
    ("[lod]\nfar = 1e300\n", "lod.far"),
    ("[lod]\ncharacter = [14.0, 1e300]\n", "lod.character"),
    ("[render]\nfog = 1e300\n", "render.fog"),
    ("[auto_objects]\nseed = -1\n", "auto_objects.seed"),
    ('[[objects]]\nmodel = "builtin:tree"\nposition = [0.0, 0.0]\nscale = 1e300\n', "objects[0].scale"),
    ('[[objects]]\nmodel = "builtin:tree"\nposition = [1e300, 0.0]\n', "objects[0].position"),
    ('[[riders]]\nposition = [0.0, 0.0]\nheading = 1e300\n', "riders[0].heading"),
])
def test_other_numbers(tmp_path, text, key):
    with pytest.raises(SceneError, match=rf"s\.toml, line \d+, key '{re.escape(key)}': expected .* in \["):
        loads_scene(text, tmp_path / "s.toml")


def test_plausible_numbers_load(tmp_path):
    s = loads_scene("[terrain]\nseed = 4294967295\n[visibility]\ncell = 1.0\n[render]\nfog = 0.002\n" + CAM
                    + "fov = 179.0\nnear = 0.05\nfar = 400000.0\n", tmp_path / "s.toml")
    assert s.terrain.seed == 2**32 - 1 and s.render.fog == 0.002 and s.cameras[0].far == 400000.0


def test_bounded_planes_give_an_invertible_projection():
    """The extremes the scene file lets through still give a finite, invertible view-projection."""
    for near, far in [(1e-4, 1e3), (10.0, 1e8), (1e-4 * 1.0001, 1e-4 * MAX_FAR_NEAR_RATIO)]:
        for fov in (1e-3, 179.999):
            vp = Camera(np.zeros(3), np.array([1.0, 2.0, 0.5]), fov_y=fov, near=near, far=far).view_projection()
            assert np.isfinite(vp).all() and np.isfinite(np.linalg.inv(vp)).all()
