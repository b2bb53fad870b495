"""piste view SCENE: a changed source file is rebuilt (cached steps reused) and shows in the next frame."""

from __future__ import annotations

import os
import threading
import time

import numpy as np
from PIL import Image

from piste.pipeline.live import LiveScene, run_headless


def _touch_later(path, new_text, wait_for, timeout=30.0):
    """Rewrite ``path`` once ``wait_for`` exists (from a thread: GL stays on the main thread)."""

    def go():
        t0 = time.time()
        while not wait_for.exists() and time.time() - t0 < timeout:
            time.sleep(0.02)
        path.write_text(new_text)
        st = path.stat()
        os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 10_000_000))  # a coarse clock still sees it

    th = threading.Thread(target=go, daemon=True)
    th.start()
    return th


def test_headless_view_renders_a_new_frame_per_change(small_scene, gl, tmp_path):
    scene = small_scene(riders=False)
    live = LiveScene(scene, size=(64, 48), ctx=gl)
    out = tmp_path / "frames"
    red = scene.read_text().replace("color = [0.5, 0.6, 0.8]\nintensity = 0.4", "color = [1.5, 0.1, 0.1]\nintensity = 1.0")
    assert red != scene.read_text()
    th = _touch_later(scene, red, out / "frame_0000.png")
    try:
        files = run_headless(live, out, frames=2, seconds=60, interval=0.02, log=lambda m: None)
    finally:
        live.release()
    th.join()
    assert [p.name for p in files] == ["frame_0000.png", "frame_0001.png"]
    a = np.asarray(Image.open(files[0])).astype(float)
    b = np.asarray(Image.open(files[1])).astype(float)
    # the ambient light turned red: the snow is redder than before
    assert (b[..., 0] - b[..., 2]).mean() > (a[..., 0] - a[..., 2]).mean() + 10
    assert set(live.last_build.rebuilt) == {"lightmap", "objects", "write"}
    assert "terrain" in live.last_build.cached and "visibility" in live.last_build.cached


def test_a_broken_edit_keeps_the_last_good_scene(small_scene, gl):
    scene = small_scene(riders=False)
    live = LiveScene(scene, size=(32, 24), ctx=gl)
    try:
        good = scene.read_text()
        assert not live.poll()
        scene.write_text(good + "\nbogus = 1\n")
        os.utime(scene, ns=(0, scene.stat().st_mtime_ns + 10_000_000))
        assert not live.poll()
        assert live.last_error is not None and "bogus" in str(live.last_error)
        img = live.render()  # still the last good bundle
        assert img.shape == (24, 32, 3)
        scene.write_text(good.replace("intensity = 0.4", "intensity = 0.5"))
        os.utime(scene, ns=(0, scene.stat().st_mtime_ns + 20_000_000))
        assert live.poll() and live.rebuilds == 1
    finally:
        live.release()


def test_a_changed_gltf_file_is_watched(small_scene, gl):
    from piste.pipeline.gltf_import import write_scene_gltf

    scene = small_scene(riders=False, extra='\n[[gltf]]\nfile = "l.gltf"\n')
    sun = {"type": "directional", "name": "s", "intensity": 683.0, "direction": (0.0, 0.5, -1.0)}
    write_scene_gltf(scene.parent / "l.gltf", [sun], [])
    live = LiveScene(scene, size=(32, 24), ctx=gl)
    try:
        assert (scene.parent / "l.gltf").resolve() in [p for p in live._files]
        atlas0 = live.bundle.lightmap.atlas.copy()
        write_scene_gltf(scene.parent / "l.gltf", [dict(sun, intensity=200.0)], [])
        p = scene.parent / "l.gltf"
        os.utime(p, ns=(0, p.stat().st_mtime_ns + 10_000_000))
        assert live.poll()
        assert live.bundle.lightmap.atlas.mean() < atlas0.mean()
    finally:
        live.release()


def test_headless_view_logs_through_the_piste_logger(small_scene, gl, tmp_path, caplog, capsys):
    """The library prints nothing: without ``log=`` the frames written go to the ``piste`` logger."""
    live = LiveScene(small_scene(riders=False), size=(32, 24), ctx=gl)
    try:
        with caplog.at_level("INFO", logger="piste"):
            files = run_headless(live, tmp_path / "frames", frames=1, seconds=0)
    finally:
        live.release()
    assert [p.name for p in files] == ["frame_0000.png"]
    assert any(r.name == "piste.pipeline.live" and "frame_0000.png" in r.getMessage() for r in caplog.records)
    assert capsys.readouterr().err == ""
