"""piste build / render / view SCENE through the command line."""

from __future__ import annotations

from piste.cli import main


def test_build_then_render_png_and_video(small_scene, gl, tmp_path, capsys):
    scene = small_scene()
    assert main(["build", str(scene), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "built" in out and "visibility" in out
    bundle = scene.with_suffix(".piste")
    assert bundle.exists()
    assert main(["build", str(scene), "--quiet"]) == 0
    assert "cached" in capsys.readouterr().out
    png, mp4 = tmp_path / "a.png", tmp_path / "a.mp4"
    assert main(["render", str(bundle), "--camera", "main", "--out", str(png), "--size", "64", "48",
                 "--frames", "3", "--video", str(mp4), "--quiet"]) == 0
    assert png.stat().st_size > 100 and mp4.stat().st_size > 100
    assert main(["render", str(bundle), "--list"]) == 0
    assert "main" in capsys.readouterr().out


def test_render_a_toml_directly_and_errors(small_scene, gl, tmp_path, capsys):
    scene = small_scene(riders=False)
    png = tmp_path / "b.png"
    assert main(["render", str(scene), "--out", str(png), "--size", "48", "32", "--quiet"]) == 0
    assert png.exists()
    assert main(["render", str(scene.with_suffix(".piste")), "--camera", "nope", "--out", str(png)]) == 1
    assert "no camera 'nope'" in capsys.readouterr().err
    assert main(["render", str(tmp_path / "x.obj")]) == 1
    scene.write_text(scene.read_text() + "\nunknown_key = 1\n")
    assert main(["build", str(scene), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "unknown_key" in err and "line" in err


def test_view_scene_headless(small_scene, gl, tmp_path):
    scene = small_scene(riders=False)
    out = tmp_path / "frames"
    assert main(["view", str(scene), "--headless", "--out", str(out), "--size", "48", "32", "--frames", "1"]) == 0
    assert (out / "frame_0000.png").exists()


def test_view_scene_in_a_window_under_xvfb(small_scene, gl_context, tmp_path):
    import os
    import shutil
    import subprocess
    import sys

    import numpy as np
    import pytest
    from PIL import Image

    if shutil.which("xvfb-run") is None:
        pytest.skip("xvfb-run not installed (apt-get install xvfb)")
    pytest.importorskip("pyglet")
    scene = small_scene(riders=False)
    out = tmp_path / "shot.png"
    cmd = ["xvfb-run", "-a", "-s", "-screen 0 640x480x24", sys.executable, "-m", "piste.cli", "view", str(scene),
           "--size", "96", "64", "--frames", "3", "--out", str(out)]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=dict(os.environ))
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert "3 frames" in r.stdout
    img = np.asarray(Image.open(out))
    assert img.shape == (64, 96, 3) and img.std() > 2
