"""Visibility is conservative for every eye the scene's cameras reach: the build samples eyes up to
the highest camera above the snow (the band), an eye above the band gets no set (all drawn), and
``piste render`` warns about cameras above it.  Rendered with and without the sets, views at 1.7,
9, 35 and 100 m above a track down a valley lose no pixel."""

from __future__ import annotations

import numpy as np
import pytest


def _valley():
    from piste.terrain.fit import fit_heightfield

    n = 65
    y, x = np.mgrid[0:n, 0:n] * 4.0
    z = (30.0 * (1 - np.exp(-((x - 128.0) / 40.0) ** 2)) + 25.0 * np.exp(-((y - 150.0) / 12.0) ** 2) * (np.abs(x - 128) > 20)
         + 6.0 * np.sin(x / 11.0) * np.cos(y / 17.0) - 0.25 * y + 12.0 * np.exp(-((x - 128.0) ** 2 + (y - 100.0) ** 2) / 200.0))
    return fit_heightfield(z, 4.0), z


def _views(net):
    from piste.terrain.query import height_at
    from piste.world.camera import Camera

    track = np.stack([128.0 + 20 * np.sin(np.linspace(0, 3, 30)), np.linspace(10, 240, 30)], 1)
    g, _, _, _ = height_at(net, track)
    out = []
    for h in (1.7, 9.0, 35.0, 100.0):
        for i in range(0, 28, 3):
            out.append((h, Camera(np.array([track[i, 0], track[i, 1], g[i] + h]),
                                  np.array([track[i + 2, 0], track[i + 2, 1], g[i + 2]]), far=2000.0)))
    return out


@pytest.mark.slow
def test_no_pixel_lost_at_any_height(gl):
    from piste.pipeline.visibility import compute_visibility, scene_eye_heights
    from piste.render import TerrainRenderer

    net, _ = _valley()
    views = _views(net)
    heights = scene_eye_heights(net, (1.7, 9.0), np.array([c.eye for _, c in views]), 32.0)
    assert heights[:2] == (1.7, 9.0) and heights[-1] >= 100.0
    vis = compute_visibility(net, 32.0, heights)
    low = compute_visibility(net, 32.0, (1.7, 9.0))  # the old fixed band
    r = TerrainRenderer(net, size=(96, 64), ctx=gl)
    r.resident_wait = True  # every frame on the same (resident) path: pixel-exact comparisons
    try:
        culled, lost_without_guard = 0, 0
        for h, cam in views:
            r.set_visibility(None)
            ref = r.render(cam).image
            r.set_visibility(vis)
            img = r.render(cam).image
            assert np.array_equal(img, ref), f"pixels lost at {h} m above the track"
            culled += r.cull_stats["frustum_patches"] - r.cull_stats["drawn_patches"]
            # the fixed band: its guard draws everything above 9 m (no pixel lost either) ...
            r.set_visibility(low)
            assert np.array_equal(r.render(cam).image, ref)
            # ... without the guard it loses pixels high above the track (what the band fixes)
            low.ground_min, saved = None, low.ground_min
            r.set_visibility(low)
            lost_without_guard += int((r.render(cam).image != ref).any(-1).sum())
            low.ground_min = saved
        assert culled > 0  # the sets still cull
        assert lost_without_guard > 0
    finally:
        r.release()


def test_band_and_guard():
    from piste.pipeline.visibility import band_warnings, compute_visibility, height_above

    net, _ = _valley()
    vis = compute_visibility(net, 64.0, (1.7, 20.0))
    assert vis.band == 20.0 and vis.ground_min is not None
    views = _views(net)
    low = [c for h, c in views if h == 9.0][0]
    high = [c for h, c in views if h == 100.0][0]
    assert vis.in_band(low.eye) and vis.patches_at(low.eye) is not None
    assert not vis.in_band(high.eye) and vis.patches_at(high.eye) is None and vis.objects_at(high.eye) is None
    msgs = band_warnings(net, vis, [low, high], ["low", "high"])
    assert len(msgs) == 1 and msgs[0].startswith("high is 100.0 m above")
    assert abs(height_above(net, high.eye)[0] - 100.0) < 1e-6
    # the band survives the bundle's arrays
    arrays, meta = vis.to_arrays()
    back = type(vis).from_arrays(arrays, meta)
    assert not back.in_band(high.eye) and back.band == 20.0


def test_bad_band_arrays_are_format_errors():
    from piste.errors import FormatError
    from piste.pipeline.visibility import Visibility, compute_visibility

    net, _ = _valley()
    arrays, meta = compute_visibility(net, 64.0, (1.7, 20.0)).to_arrays()
    with pytest.raises(FormatError, match="level_bits"):
        Visibility.from_arrays(dict(arrays, level_bits=arrays["level_bits"][:, :1]), meta)
    with pytest.raises(FormatError, match="ground_min"):
        Visibility.from_arrays(dict(arrays, ground_min=arrays["ground_min"][:2]), meta)


def test_render_warns_when_a_camera_leaves_the_band(small_scene, gl, tmp_path, monkeypatch, capsys, piste_cache):
    from piste.cli import main
    from piste.pipeline import visibility

    high = '\n[[cameras]]\nname = "high"\neye = [64.0, 64.0, 90.0]\ntarget = [64.0, 100.0, 20.0]\n'
    scene = small_scene(riders=False, extra=high)
    assert main(["build", str(scene), "--quiet"]) == 0
    from piste.pipeline import load_bundle

    b = load_bundle(scene.with_suffix(".piste"))
    assert max(b.visibility.eye_heights) >= 60.0  # the band reaches the high camera
    png = tmp_path / "x.png"
    cmd = ["render", str(scene.with_suffix(".piste")), "--camera", "high", "--out", str(png), "--size", "48", "32"]
    assert main(cmd) == 0
    assert "visibility band" not in capsys.readouterr().err  # the build's band covers the scene's cameras
    monkeypatch.setattr(visibility.Visibility, "band", property(lambda self: 2.0))
    assert main(cmd) == 0
    err = capsys.readouterr().err
    assert "warning: high frame 0 is" in err and "above the visibility band (2 m)" in err
