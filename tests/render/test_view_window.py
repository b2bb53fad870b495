"""``piste view``: the headless fallback, the overlay, and the window itself driven under Xvfb by
real X key and mouse events (xdotool)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from piste.cli import main


def _need(tool: str, package: str):
    """Skip without ``tool``; fail instead when PISTE_REQUIRE_TOOLS is set (CI)."""
    if shutil.which(tool) is None:
        msg = f"{tool} not installed (apt-get install {package}; tools/setup-test-tools.sh)"
        if os.environ.get("PISTE_REQUIRE_TOOLS"):
            pytest.fail(msg)
        pytest.skip(msg)


@pytest.fixture
def xserver():
    """A private Xvfb display; yields the environment to run clients on it."""
    _need("Xvfb", "xvfb")
    pytest.importorskip("pyglet")
    r, w = os.pipe()
    proc = subprocess.Popen(["Xvfb", "-displayfd", str(w), "-screen", "0", "800x600x24", "-nolisten", "tcp"],
                            pass_fds=(w,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(w)
    try:
        with os.fdopen(r) as f:
            display = f.readline().strip()
        assert display, "Xvfb did not report a display number"
        env = dict(os.environ, DISPLAY=f":{display}")
        env.pop("WAYLAND_DISPLAY", None)
        yield env
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_view_without_display_falls_back_to_an_image(gl_context, tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    out = tmp_path / "view.png"
    assert main(["view", "--size", "64", "48", "--lighting", "placeholder", "--terrain-only", "--out", str(out)]) == 0
    assert "no display" in capsys.readouterr().err
    assert np.asarray(Image.open(out)).shape == (48, 64, 3)


def test_overlay_table_and_plot(gl):
    """The overlay image holds the talk's table (one row per statistic) and a plot whose LOD mix
    columns take the LOD view's colours."""
    from piste.render import Frame
    from piste.render.overlay import LOD_COLOURS, OverlayPass, StatsHistory, overlay_image

    hist = StatsHistory(10)
    for i in range(10):
        f = Frame(None, 100, 400, {4: 70, 6: 20, 8: 10, 0: 0, -1: 0}, 3000, 2000, {"tessellate": 1.0})
        hist.add(f, 20.0 + i, {"riders": 6, "rider_triangles": 1000, "objects": 5})
    rows = dict((a, b) for a, b, _ in hist.table_rows())
    assert rows["4x4 / 6x6 / 8x8"] == "70 / 20 / 10 %" and rows["polys per patch"] == "30.00"
    assert rows["riders / tris"] == "6 / 1,000"
    img = overlay_image(hist, "test")
    assert img.shape[2] == 4 and img.shape[1] == 300
    colours = {tuple(c) for c in img[..., :3].reshape(-1, 3)}
    assert {LOD_COLOURS[4], LOD_COLOURS[6], LOD_COLOURS[8]} <= colours
    # blended over a target: the corner changes, the rest does not
    from piste.render.context import Offscreen

    target = Offscreen(gl, (400, 300))
    target.use()
    target.clear((0.0, 0.0, 0.0, 1.0))
    p = OverlayPass(gl)
    p.update(img)
    p.draw((400, 300))
    out = target.read()
    p.release()
    target.release()
    assert out[5:40, 5:200].max() > 100 and out[-20:, -20:, :3].max() == 0


def _wait_window(env, name="piste view", timeout=60.0):
    r = subprocess.run(["xdotool", "search", "--sync", "--onlyvisible", "--name", name], env=env, capture_output=True,
                       text=True, timeout=timeout)
    assert r.returncode == 0 and r.stdout.split(), r.stderr
    return r.stdout.split()[0]


def _x(env, *args):
    subprocess.run(["xdotool", *args], env=env, check=True, timeout=20)


def test_view_flies_and_draws_riders_under_a_real_x_server(gl_context, xserver, tmp_path):
    """W held (a real X key event) flies the camera forward; a mouse drag turns it; F leaves the
    chase camera where it was; riders are drawn (occlusion-query pixel count)."""
    _need("xdotool", "xdotool")
    state, shot = tmp_path / "state.json", tmp_path / "shot.png"
    cmd = [sys.executable, "-m", "piste.cli", "view", "--size", "160", "112", "--lighting", "placeholder",
           "--follow", "0", "--exit-after", "90", "--state", str(state), "--out", str(shot)]
    proc = subprocess.Popen(cmd, env=xserver, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wid = _wait_window(xserver)
        time.sleep(1.0)  # a few frames of the chase camera
        _x(xserver, "mousemove", "--window", wid, "80", "56")
        _x(xserver, "windowfocus", "--sync", wid)
        _x(xserver, "key", "f")  # leave the chase camera: fly from where it was
        time.sleep(0.5)
        _x(xserver, "keydown", "w")
        time.sleep(1.2)
        _x(xserver, "keyup", "w")
        _x(xserver, "mousedown", "1")
        _x(xserver, "mousemove_relative", "--", "40", "0")
        time.sleep(0.4)
        _x(xserver, "mouseup", "1")
        _x(xserver, "key", "m")  # ps2 light-map mode: the half-float frame resolved into the window
        time.sleep(0.8)
        _x(xserver, "key", "Escape")
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, out[-2000:] + err[-2000:]
    st = json.loads(state.read_text())
    assert st["follow"] is None  # F left the chase camera
    assert st["toggles"]["lightmap_mode"] == "ps2"
    assert st["max_riders_in_view"] >= 1 and st["max_rider_pixels"] > 50
    # W moved the fly camera along its forward direction
    start = np.array(st["fly_start"]["position"])
    end = np.array(st["end_fly"]["position"])
    fwd = np.array(st["fly_start"]["forward"])
    moved = end - start
    assert float(moved @ fwd) > 3.0, (start, end)
    assert np.linalg.norm(moved - (moved @ fwd) * fwd) < 0.1 * np.linalg.norm(moved)
    # the mouse drag turned it (to the right: yaw grows)
    assert st["end_fly"]["yaw"] > st["fly_start"]["yaw"] + 0.05, (st["fly_start"], st["end_fly"])
    img = np.asarray(Image.open(shot))
    assert img.shape == (112, 160, 3) and img.std() > 5


def test_view_benchmark_prints_fps(gl_context, xserver):
    r = subprocess.run([sys.executable, "-m", "piste.cli", "view", "--size", "96", "64", "--lighting", "placeholder",
                        "--terrain-only", "--benchmark", "3"], env=xserver, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert "fps" in r.stdout and "terrain only" in r.stdout


def test_view_fallback_draws_extra_rider_models(gl_context, tmp_path, monkeypatch, capsys):
    """``--rider-model FILE:N`` adds riders of another model to the default course (the headless
    fallback renders the frame the window would show)."""
    data = Path(os.environ.get("PISTE_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))
    cesium = data / "gltf" / "CesiumMan" / "CesiumMan.glb"
    if not cesium.exists():
        pytest.skip(f"test model {cesium} not found")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    base = ["view", "--size", "96", "64", "--lighting", "none", "--follow", "0"]
    assert main(base + ["--out", str(a)]) == 0
    assert main(base + ["--rider-model", f"{cesium}:2", "--out", str(b)]) == 0
    ia, ib = (np.asarray(Image.open(x)).astype(int) for x in (a, b))
    assert (np.abs(ia - ib).max(-1) > 30).sum() > 5
    assert main(base + ["--rider-model", str(tmp_path / "nope.glb")]) == 1
    assert "no such file" in capsys.readouterr().err
