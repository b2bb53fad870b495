"""Camera matrices, frustum planes and the track camera."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import ConfigError
from piste.world.camera import Camera, frustum_planes, look_at, perspective, track_camera


def _project(m, p):
    h = m @ np.append(p, 1.0)
    return h[:3] / h[3]


def test_view_projection_maps_target_to_centre():
    cam = Camera([10.0, -20.0, 15.0], [3.0, 4.0, 1.0], fov_y=50, aspect=1.5)
    ndc = _project(cam.view_projection(), cam.target)
    assert np.allclose(ndc[:2], 0.0, atol=1e-9) and -1 < ndc[2] < 1
    # Z up: a point above the target projects above the centre
    assert _project(cam.view_projection(), cam.target + [0, 0, 1])[1] > 0
    v = look_at(cam.eye, cam.target)
    assert np.allclose(v[:3, :3] @ v[:3, :3].T, np.eye(3))
    assert np.allclose(v @ np.append(cam.eye, 1.0), [0, 0, 0, 1])


def test_frustum_planes_contain_exactly_the_visible_points():
    cam = Camera([0.0, 0.0, 0.0], [0.0, 10.0, 0.0], fov_y=60, aspect=1.0, near=1.0, far=100.0)
    planes = cam.frustum_planes()
    assert np.allclose(np.linalg.norm(planes[:, :3], axis=1), 1.0)
    rng = np.random.default_rng(0)
    pts = rng.uniform(-120, 120, (2000, 3))
    inside = ((planes[:, :3] @ pts.T + planes[:, 3:4]) >= 0).all(axis=0)
    ndc = np.array([_project(cam.view_projection(), p) for p in pts])
    clip = cam.view_projection() @ np.c_[pts, np.ones(len(pts))].T
    visible = (clip[3] > 0) & (np.abs(ndc) <= 1).all(axis=1)
    assert np.array_equal(inside, visible)


def test_orthographic_camera():
    cam = Camera([5.0, 5.0, 50.0], [5.0, 5.0, 0.0], up=(0, 1, 0), ortho_height=20, aspect=2.0, near=1, far=100)
    vp = cam.view_projection()
    assert np.allclose(_project(vp, [5.0 + 20.0, 5.0 + 10.0, 0.0])[:2], [1.0, 1.0])
    assert frustum_planes(vp).shape == (6, 4)


def test_bad_cameras_raise_config_errors():
    with pytest.raises(ConfigError, match="same point"):
        look_at([1, 2, 3], [1, 2, 3])
    with pytest.raises(ConfigError, match="near"):
        perspective(60, 1.0, 10.0, 1.0)
    with pytest.raises(ConfigError, match="fov_y"):
        perspective(180, 1.0, 1.0, 10.0)
    with pytest.raises(ConfigError, match="centerline"):
        track_camera(np.zeros((1, 3)), 0.5)


def test_track_camera_rides_above_the_line_looking_ahead():
    y = np.linspace(0.0, 500.0, 50)
    line = np.stack([10 * np.sin(y / 80.0), y, 300.0 - 0.4 * y], axis=1)
    for t in (0.0, 0.5, 1.0):
        cam = track_camera(line, t, height=8.0, behind=10.0, look_ahead=40.0)
        assert cam.forward[1] > 0.5  # looks down the track (+y)
        assert cam.forward[2] < 0.0  # and down the slope
        # the eye is ~height above the line at its own y
        z_line = np.interp(cam.eye[1], line[:, 1], line[:, 2])
        assert 6.0 < cam.eye[2] - z_line < 14.0


def test_fly_camera_moves_and_turns():
    from piste.world.camera import FlyCamera

    cam = track_camera(np.array([[0.0, 0.0, 100.0], [0.0, 100.0, 60.0]]), 0.5)
    fly = FlyCamera.from_camera(cam, speed=10.0)
    assert np.allclose(fly.forward, cam.forward)
    start = fly.position.copy()
    fly.move(1.0, 0.0, 0.0, 0.5)
    assert np.allclose(fly.position - start, 5.0 * cam.forward)
    fly.look(np.pi / 2, 0.0)
    assert fly.forward[0] > 0.9 * np.cos(fly.pitch)  # turned right: now looking along +x
    fly.look(0.0, 10.0)
    assert np.degrees(fly.pitch) == pytest.approx(89.0)
    assert np.allclose(fly.camera().forward, fly.forward)
