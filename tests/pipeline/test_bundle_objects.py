"""A bundle as the scene's objects (piste.pipeline.bundle_objects): the net, light map, lights,
cameras and visibility built from the arrays that piste.formats.bundle reads."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import FormatError
from piste.formats.bundle import camera_to_dict, write_bundle
from piste.pipeline import Bundle, load_bundle
from piste.pipeline.bundle_objects import camera_from_dict, lights_from_dict
from piste.terrain.net import PatchNet


def _minimal(tmp_path, control_points=None):
    g = np.zeros((7, 7, 3))
    g[..., 0], g[..., 1] = np.meshgrid(np.arange(7.0), np.arange(7.0))
    g[..., 2] = 0.1 * g[..., 0]
    net = PatchNet.from_control_grid(g)
    arrays = {
        "terrain/control_points": net.control_points if control_points is None else control_points,
        "terrain/uv": net.uv,
        "lightmap/atlas": np.full((20, 20, 3), 0.5, np.float32),
        "lightmap/rects": net.lightmap_rect,
    }
    man = {"name": "mini", "terrain": {"name": "mini", "tol": net.tol},
           "lights": {"ambient": [{"color": [1.0, 1.0, 1.0], "intensity": 0.5, "name": ""}],
                      "point": [{"position": [0.0, 0.0, 1.0], "color": [1.0, 1.0, 1.0], "intensity": 1.0, "range": "inf",
                                 "falloff": 1.0, "shadows": True, "name": "p"}]},
           "cameras": [{"name": "c", "eye": [0.0, -5.0, 5.0], "target": [3.0, 3.0, 0.0], "up": [0.0, 0.0, 1.0],
                        "fov_y": 50.0, "near": 0.1, "far": 100.0, "ortho_height": None}],
           "lightmap": {"res": 8, "gutter": 1}}
    return write_bundle(tmp_path / "b.piste", man, arrays), arrays


def test_objects_built_from_the_arrays(tmp_path):
    path, arrays = _minimal(tmp_path)
    b = load_bundle(path)
    assert isinstance(b, Bundle) and b.name == "mini"
    assert len(b.net) == 4 and np.array_equal(b.net.control_points, arrays["terrain/control_points"])
    assert b.lightmap.atlas.shape == (20, 20, 3) and b.lightmap.atlas.dtype == np.float32
    assert len(b.lights) == 2 and np.isinf(b.lights.direct[0].range)
    assert b.camera("c").fov_y == 50.0 and b.camera().near == 0.1
    assert b.objects() is None and b.rider_model() is None and b.visibility is None and b.centerline is None


def test_camera_and_lights_round_trip(tmp_path):
    path, _ = _minimal(tmp_path)
    b = load_bundle(path)
    cam = b.camera("c")
    again = camera_from_dict(camera_to_dict(cam))
    assert np.allclose(again.eye, cam.eye) and again.far == cam.far and again.ortho_height is None
    lights = lights_from_dict(b.manifest["lights"])
    assert [type(x).__name__ for x in lights] == [type(x).__name__ for x in b.lights]


def test_bad_terrain_names_the_member(tmp_path):
    path, _ = _minimal(tmp_path, control_points=np.zeros((4, 3, 3, 3)))
    with pytest.raises(FormatError) as e:
        load_bundle(path)
    assert e.value.field == "terrain/control_points.npy" and "invalid terrain" in str(e.value)


def test_warm_load_starts_the_resident_blocks(tmp_path):
    """load_bundle(warm=True) (piste demo / render / view) starts the terrain's resident vertex
    blocks in the background as soon as the net exists; a plain load starts nothing."""
    from piste.terrain.resident import resident_terrain

    path, _ = _minimal(tmp_path)
    cold = load_bundle(path)
    assert not cold.net.__dict__.get("_resident_pending") and not cold.net.__dict__.get("_resident")
    warm = load_bundle(path, warm=True)
    jobs = warm.net.__dict__.get("_resident_pending") or {}
    assert len(jobs) == 1
    next(iter(jobs.values()))["thread"].join(30)
    r = resident_terrain(warm.net, wait=False)  # built: returned at once, not started again
    assert r is not None and r.vertices.shape == (len(warm.net) * r.block, 11)


def test_the_light_map_atlas_is_the_stored_member_not_a_copy(tmp_path):
    """The light map's atlas is the bundle's float32 member as read (a read-only view of the mapped
    file, no copy a start); the net's control points are its own writable copy."""
    path, arrays = _minimal(tmp_path)
    b = load_bundle(path)
    assert b.lightmap.atlas is b.arrays["lightmap/atlas"] or np.shares_memory(b.lightmap.atlas, b.arrays["lightmap/atlas"])
    assert np.array_equal(b.lightmap.atlas, arrays["lightmap/atlas"]) and not b.lightmap.atlas.flags.writeable
    assert b.net.control_points.flags.writeable and not np.shares_memory(b.net.control_points,
                                                                         b.arrays["terrain/control_points"])
