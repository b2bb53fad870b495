"""A big DEM scene is never blank by default: scene cameras without ``far`` get a far plane that
reaches the whole terrain (issue 24 item 3); one whose far plane stops short says why."""

from __future__ import annotations

import logging

import numpy as np

from piste.pipeline.build import build_scene
from piste.pipeline.bundle_objects import load_bundle
from piste.pipeline.preview import ScenePreview, camera_at

SCENE = """\
[terrain]
source = "dem.npz"
[lightmap]
res = 4
[visibility]
enabled = false

[[cameras]]
name = "default"
eye = [-6000.0, -6000.0, 6000.0]
target = [8000.0, 8000.0, 0.0]

[[cameras]]
name = "short"
eye = [-6000.0, -6000.0, 6000.0]
target = [8000.0, 8000.0, 0.0]
far = 4000.0
"""


def test_big_dem_renders_by_default_and_a_short_far_plane_warns(tmp_path, gl, caplog):
    n = 33  # 32 x 500 m = a 16 km DEM; its nearest point is 10 km from the cameras
    y, x = np.mgrid[0:n, 0:n] * 500.0
    z = 150.0 + 120.0 * np.sin(x / 2500.0) * np.cos(y / 3100.0)
    np.savez(tmp_path / "dem.npz", z=z, dx=np.float64(500.0))
    (tmp_path / "dem.toml").write_text(SCENE)
    b = load_bundle(build_scene(tmp_path / "dem.toml").path)
    cams = {c["name"]: c for c in b.manifest["cameras"]}
    assert cams["default"]["far"] > 22000.0 and cams["short"]["far"] == 4000.0
    p = ScenePreview(b, size=(96, 64), ctx=gl)
    try:
        with caplog.at_level(logging.WARNING, logger="piste"):
            seen = p.render(camera_at(b, "default")).astype(int)
            drawn = p.stats["drawn_patches"]
            assert not [r for r in caplog.records if "sees no terrain" in r.getMessage()]
            blank = p.render(camera_at(b, "short")).astype(int)
            assert p.stats["drawn_patches"] == 0  # sky only
    finally:
        p.release()
    assert drawn > 0.5 * 64  # the default far plane shows most of the 8 x 8 patches
    assert (np.abs(seen - blank).sum(-1) > 30).mean() > 0.08  # the whole 16 km square in view (12 % of it)
    warnings = [r.getMessage() for r in caplog.records if "sees no terrain" in r.getMessage()]
    assert len(warnings) == 1
    assert "beyond the far plane at 4000 m" in warnings[0] and "16000 x 16000" in warnings[0]


GLTF_SCENE = """\
[terrain]
source = "dem.npz"
[lightmap]
res = 4
[visibility]
enabled = false

[[gltf]]
file = "cams.gltf"
lights = false
up = "z"
"""


def test_gltf_camera_without_zfar_reaches_a_big_terrain(tmp_path):
    """A glTF camera with an infinite ``zfar`` gets the scene cameras' far plane (one reaching the
    whole terrain), not 4 km; one whose file gives ``zfar`` keeps it."""
    from piste.pipeline.gltf_import import write_scene_gltf

    n = 33  # a 16 km DEM, its nearest point 10 km from the cameras
    z = np.full((n, n), 150.0)
    np.savez(tmp_path / "dem.npz", z=z, dx=np.float64(500.0))
    eye, target = (-6000.0, -6000.0, 6000.0), (8000.0, 8000.0, 0.0)
    write_scene_gltf(tmp_path / "cams.gltf", cameras=[
        {"name": "open", "eye": eye, "target": target, "znear": 0.5, "zfar": None},
        {"name": "closed", "eye": eye, "target": target, "znear": 0.5, "zfar": 900.0}], up="z")
    (tmp_path / "g.toml").write_text(GLTF_SCENE)
    b = load_bundle(build_scene(tmp_path / "g.toml", use_cache=False).path)
    cams = {c["name"]: c for c in b.manifest["cameras"]}
    far_corner = np.linalg.norm(np.array([16000.0, 16000.0, 150.0]) - np.array(eye))
    assert cams["open"]["far"] >= far_corner > 22000.0
    assert cams["closed"]["far"] == 900.0 and cams["open"]["near"] == 0.5
