"""Far planes that follow the world's size, and a camera that sees no terrain says why (issue 24 item 3)."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from piste.world.camera import (DEFAULT_FAR, MAX_DEPTH_RATIO, Camera, camera_planes, far_for_extent,
                                terrain_view_problem, warn_if_no_terrain)

LO, HI = np.array([0.0, 0.0, 0.0]), np.array([16000.0, 16000.0, 300.0])  # a 16 km DEM


def test_far_reaches_every_corner_of_a_big_terrain():
    eye = np.array([-6000.0, -6000.0, 1500.0])
    far = far_for_extent(eye, LO, HI)
    corner = np.linalg.norm(np.array([16000.0, 16000.0, 0.0]) - eye)
    assert corner < far <= corner * 1.06
    near, far2 = camera_planes(eye, LO, HI)
    assert far2 == far and near == 0.5  # a 31 km far plane keeps the 0.5 m near plane


def test_small_worlds_keep_the_default_far_plane():
    assert far_for_extent(np.array([10.0, 10.0, 50.0]), np.zeros(3), np.array([500.0, 800.0, 60.0])) == DEFAULT_FAR
    assert camera_planes(np.zeros(3)) == (0.5, DEFAULT_FAR)  # no terrain known


def test_given_planes_are_kept_and_defaults_respect_them():
    eye = np.array([-6000.0, -6000.0, 1500.0])
    assert camera_planes(eye, LO, HI, near=2.0, far=900.0) == (2.0, 900.0)
    near, far = camera_planes(eye, LO, HI, near=1e-4)  # only near given: far stays within the ratio
    assert near == 1e-4 and far == pytest.approx(1e-4 * MAX_DEPTH_RATIO)
    near, far = camera_planes(eye, LO, HI, far=0.2)  # only a tiny far given: near below it
    assert far == 0.2 and 0 < near < far
    near, far = camera_planes(np.zeros(3), np.full(3, -3e6), np.full(3, 3e6))  # a continent: near grows
    assert far > 5e6 and near == pytest.approx(far * 1e-5) and far / near <= MAX_DEPTH_RATIO


def test_reasons():
    c = np.array([8000.0, 8000.0, 0.0])
    looking = Camera(np.array([-6000.0, -6000.0, 1500.0]), c, far=4000.0)
    assert "beyond the far plane at 4000 m" in terrain_view_problem(looking, LO, HI)
    assert "16000 x 16000 x 300 m" in terrain_view_problem(looking, LO, HI)
    assert terrain_view_problem(Camera(looking.eye, c, far=far_for_extent(looking.eye, LO, HI)), LO, HI) is None
    away = Camera(np.array([8000.0, 8000.0, 500.0]), np.array([8000.0, 8000.0, 900.0]), far=50000.0)  # straight up
    assert "looks away from the terrain" in terrain_view_problem(away, LO, HI)
    # the eye near the terrain, looking along it: the far plane cuts it off in the view direction only
    skim = Camera(np.array([-100.0, 8000.0, 100.0]), np.array([-200.0, 8000.0, 100.0]), far=50000.0)
    assert "looks away" in terrain_view_problem(skim, LO, HI)


def test_a_camera_looking_away_warns_once(caplog):
    away = Camera(np.array([8000.0, 8000.0, 500.0]), np.array([8000.0, 8000.0, 900.0]), far=50000.0)
    seen: set = set()
    with caplog.at_level(logging.WARNING, logger="piste"):
        for _ in range(3):
            assert warn_if_no_terrain(away, LO, HI, name="camera 'up'", seen=seen) is not None
        assert warn_if_no_terrain(Camera(np.array([8000.0, 8000.0, 500.0]), np.array([8000.0, 8100.0, 0.0]),
                                         far=50000.0), LO, HI, seen=seen) is None
    msgs = [r.getMessage() for r in caplog.records if r.name.startswith("piste")]
    assert len(msgs) == 1 and msgs[0].startswith("camera 'up' sees no terrain: the camera looks away")
