"""``piste demo --rider-model FILE[:N]``: the completed scene with a second rider model beside the
default pack (the demo shows two different models)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from piste.cli import main


@pytest.mark.slow
def test_demo_with_two_rider_models(gl_context, tmp_path, capsys):
    data = Path(os.environ.get("PISTE_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
    cesium = data / "gltf" / "CesiumMan" / "CesiumMan.glb"
    if not cesium.exists():
        pytest.skip(f"test model {cesium} not found")
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    base = ["demo", "--size", "96", "64", "--lighting", "none", "--frames", "1", "--no-progress"]
    assert main(base + ["--out", str(a)]) == 0
    assert main(base + ["--rider-model", f"{cesium}:2", "--out", str(b)]) == 0
    capsys.readouterr()
    ia, ib = (np.asarray(Image.open(x)).astype(int) for x in (a, b))
    assert (np.abs(ia - ib).max(-1) > 30).sum() > 5  # the CesiumMen are in the picture
