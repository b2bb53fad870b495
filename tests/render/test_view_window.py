"""``piste view``: the headless fallback, and the window itself under Xvfb when it is installed."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from piste.cli import main


def test_view_without_display_falls_back_to_an_image(gl_context, tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    out = tmp_path / "view.png"
    assert main(["view", "--size", "64", "48", "--lighting", "placeholder", "--out", str(out)]) == 0
    assert "no display" in capsys.readouterr().err
    assert np.asarray(Image.open(out)).shape == (48, 64, 3)


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="xvfb-run not installed (apt-get install xvfb)")
def test_view_window_under_xvfb(gl_context, tmp_path):
    pytest.importorskip("pyglet")
    out = tmp_path / "shot.png"
    cmd = ["xvfb-run", "-a", "-s", "-screen 0 640x480x24", sys.executable, "-m", "piste.cli", "view",
           "--size", "96", "64", "--frames", "3", "--lighting", "placeholder", "--out", str(out)]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=dict(os.environ))
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert "3 frames" in r.stdout
    img = np.asarray(Image.open(out))
    assert img.shape == (64, 96, 3) and img.std() > 5
