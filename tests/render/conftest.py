"""Render-test helpers: small synthetic patch nets and reference-image comparison."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

REFERENCE_DIR = Path(__file__).parent / "reference"


def make_grid_net(nx: int = 3, ny: int = 3, size: float = 10.0, relief: float = 3.0, wave: float = 0.0):
    """A C0 net of ``nx x ny`` patches over ``[0, nx*size] x [0, ny*size]`` (Z up): a smooth hill.

    ``wave`` bends the patch edges sideways in x-y (metres), so that a T-junction between
    different levels would open a gap visible from straight above.  Shared boundary control
    points are samples of one function, so the net is exactly C0.
    """
    from piste.terrain import PatchNet

    gx = np.linspace(0.0, nx * size, 3 * nx + 1)
    gy = np.linspace(0.0, ny * size, 3 * ny + 1)
    x, y = np.meshgrid(gx, gy, indexing="ij")
    sx, sy = x / (nx * size), y / (ny * size)
    z = relief * (np.sin(np.pi * sx) * np.sin(np.pi * sy) + 0.3 * np.cos(3.0 * np.pi * sx) * np.sin(2.0 * np.pi * sy))
    xw = x + wave * np.sin(2.0 * np.pi * 1.5 * sy) * np.sin(np.pi * sx)
    yw = y + wave * np.sin(2.0 * np.pi * 1.5 * sx) * np.sin(np.pi * sy)
    g = np.stack([xw, yw, z], axis=-1)
    cp = np.empty((nx * ny, 4, 4, 3))
    k = 0
    for b in range(ny):
        for a in range(nx):
            cp[k] = g[3 * a : 3 * a + 4, 3 * b : 3 * b + 4]
            k += 1
    return PatchNet(cp, name=f"grid{nx}x{ny}")


@pytest.fixture(scope="session")
def grid_net():
    return make_grid_net


def image_diff(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(mean absolute difference over RGB, fraction of pixels with a channel off by > 16)."""
    d = np.abs(a[..., :3].astype(np.int16) - b[..., :3].astype(np.int16))
    return float(d.mean()), float((d.max(axis=-1) > 16).mean())


@pytest.fixture
def reference_image():
    """``check(name, image)``: compare with ``reference/<name>.png`` (mean abs diff < 2 and < 0.5 %
    of pixels off by more than 16 steps).  ``PISTE_UPDATE_REFERENCES=1`` rewrites the reference."""
    from PIL import Image

    from piste.render import save_png

    def check(name: str, image: np.ndarray) -> None:
        path = REFERENCE_DIR / f"{name}.png"
        if os.environ.get("PISTE_UPDATE_REFERENCES") or not path.exists():
            if not os.environ.get("PISTE_UPDATE_REFERENCES"):
                pytest.fail(f"{path} missing: run with PISTE_UPDATE_REFERENCES=1 to create it")
            save_png(path, image[..., :3])
            return
        ref = np.asarray(Image.open(path).convert("RGB"))
        assert ref.shape[:2] == image.shape[:2], f"{name}: size {image.shape[:2]} != reference {ref.shape[:2]}"
        mean, frac = image_diff(image, ref)
        if mean >= 2.0 or frac >= 0.005:
            out = Path(os.environ.get("PISTE_FAILED_IMAGES", "/tmp")) / f"piste-{name}-actual.png"
            save_png(out, image[..., :3])
            pytest.fail(f"{name}: differs from {path}: mean abs diff {mean:.2f}, {100 * frac:.2f} % pixels off by > 16 "
                        f"(actual image written to {out})")

    return check
