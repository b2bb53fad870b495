"""Regenerate the example scenes' assets with piste's own code (deterministic; no external data).

    python examples/scenes/make_assets.py [OUT_DIR]      (default: examples/scenes/assets)

* ``hill.png``: a 16-bit grey height field (65 x 65 samples, 0.01 m a level: heights 0-655 m),
  a valley between two ridges with a knoll, for ``blender_lit.toml``;
* ``valley.npz``: a height field array ``z`` with its spacing ``dx`` / ``dy`` (metres), for ``valley.toml``;
* ``lights_cameras.gltf``: what Blender exports for a lit, framed scene: a sun (lux), a warm spot and a
  point light (candela) in KHR_lights_punctual, and two cameras, all on glTF's Y-up axes.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np


def hill_png(path: Path) -> None:
    from PIL import Image

    from piste.formats.atomic import atomic_path

    n = 65
    y, x = np.mgrid[0:n, 0:n] / (n - 1.0)
    z = 30.0 - 22.0 * y + 9.0 * (np.abs(x - 0.5) * 2.0) ** 1.6 + 4.0 * np.exp(-((x - 0.3) ** 2 + (y - 0.55) ** 2) / 0.004)
    levels = np.clip(np.rint(z / 0.01), 0, 65535).astype(np.uint16)  # 0.01 m a grey level
    with atomic_path(path) as tmp:
        Image.fromarray(levels).save(tmp, format="PNG")


def valley_npz(path: Path) -> None:
    from piste.formats.atomic import atomic_path

    n = 49
    y, x = np.mgrid[0:n, 0:n] * 5.0
    z = 120.0 - 0.35 * y + 0.004 * (x - 120.0) ** 2 + 6.0 * np.sin(x / 23.0) * np.cos(y / 31.0)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, z=z, dx=np.float64(5.0), dy=np.float64(5.0))


def lights_cameras_gltf(path: Path) -> None:
    from piste.pipeline.gltf_import import write_scene_gltf

    # positions and directions in piste coordinates (Z up, metres); the file stores them Y up
    write_scene_gltf(
        path,
        lights=[
            {"type": "directional", "name": "Sun", "color": (1.0, 0.92, 0.8), "intensity": 820.0,
             "direction": (0.45, 0.55, -0.7)},
            {"type": "spot", "name": "Floodlight", "color": (1.0, 0.7, 0.4), "intensity": 40000.0,
             "position": (160.0, 380.0, 95.0), "direction": (0.0, 0.3, -1.0), "range": 90.0,
             "inner_cone": math.radians(15.0), "outer_cone": math.radians(35.0)},
            {"type": "point", "name": "Lantern", "color": (1.0, 0.55, 0.3), "intensity": 9000.0,
             "position": (300.0, 250.0, 72.0)},
        ],
        cameras=[
            {"name": "Overview", "eye": (320.0, -60.0, 200.0), "target": (320.0, 300.0, 60.0), "yfov": math.radians(50.0),
             "znear": 0.5, "zfar": 3000.0},
            {"name": "Valley", "eye": (200.0, 200.0, 95.0), "target": (320.0, 420.0, 50.0), "yfov": math.radians(60.0)},
        ],
    )


def main(out=None) -> None:
    out = Path(out) if out is not None else Path(__file__).resolve().parent / "assets"
    out.mkdir(parents=True, exist_ok=True)
    hill_png(out / "hill.png")
    valley_npz(out / "valley.npz")
    lights_cameras_gltf(out / "lights_cameras.gltf")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
