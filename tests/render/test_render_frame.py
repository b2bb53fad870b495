"""Frustum culling of boxes, frame statistics and the MP4 writer."""

from __future__ import annotations

import numpy as np
import pytest

from piste.errors import ConfigError, RenderError
from piste.render import Frame, VideoWriter, cull_boxes, summarize
from piste.world.camera import Camera


def test_cull_boxes_is_conservative_and_tight():
    cam = Camera([0.0, 0.0, 10.0], [0.0, 50.0, 0.0], fov_y=50, aspect=1.4, near=1.0, far=200.0)
    planes = cam.frustum_planes()
    rng = np.random.default_rng(3)
    lo = rng.uniform(-150, 150, (3000, 3))
    hi = lo + rng.uniform(0.1, 20, (3000, 3))
    keep = cull_boxes(((lo + hi) / 2).T, ((hi - lo) / 2).T, planes)
    corners = np.stack([np.where(np.array([(k >> i) & 1 for i in range(3)], bool), hi, lo) for k in range(8)], 1)
    d = np.einsum("nck,pk->ncp", corners, planes[:, :3]) + planes[:, 3]  # (n, 8, 6)
    outside_one_plane = (d < 0).all(axis=1).any(axis=1)
    assert np.array_equal(keep, ~outside_one_plane)
    # every box with a corner strictly inside the frustum is kept
    assert keep[(d > 0).all(axis=2).any(axis=1)].all()


def test_summarize_matches_the_talks_table_keys():
    f = Frame(None, 10, 100, {4: 7, 6: 1, 8: 1, 0: 1, -1: 0}, 18 * 7 + 50 + 98 + 60, 500,
              {"lod": 0.1, "cull": 0.1, "tessellate": 1.0, "upload": 0.2, "draw": 5.0, "readback": 0.5,
               "cpu": 1.4, "gpu": 5.5, "total": 6.9})
    s = summarize([f, f])
    assert s["pct_4"] == 70.0 and s["pct_nonuniform"] == 10.0
    assert s["avg_polys_per_patch"] == pytest.approx(33.4)
    assert s["no_lod_ratio"] == pytest.approx(980 / 334)
    assert s["fps"] == pytest.approx(1e3 / 6.9)
    from piste.terrain import format_stats

    assert "4x4 patches" in format_stats(s)
    with pytest.raises(ConfigError):
        summarize([])


def test_video_writer_is_atomic_and_checks_frames(tmp_path):
    path = tmp_path / "v.mp4"
    with VideoWriter(path, fps=10) as v:
        for k in range(3):
            v.append(np.full((32, 48, 3), 40 * k, np.uint8))
        with pytest.raises(RenderError, match="earlier frames"):
            v.append(np.zeros((16, 48, 3), np.uint8))
    assert path.stat().st_size > 0 and [p.name for p in tmp_path.iterdir()] == ["v.mp4"]
    with pytest.raises(RenderError, match="even width"):
        with VideoWriter(tmp_path / "odd.mp4") as v:
            v.append(np.zeros((31, 48, 3), np.uint8))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["v.mp4"]  # the failed video left nothing
