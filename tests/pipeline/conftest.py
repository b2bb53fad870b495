"""Fixtures for the pipeline tests: small scenes written into tmp_path (8 x 8 patches, 8x8 light maps)."""

from __future__ import annotations

import numpy as np
import pytest

SMALL_SCENE = """\
name = "small"

[terrain]
source = "hill.npz"

[lightmap]
res = 8

[visibility]
cell = 32.0

{riders}
[[objects]]
name = "tree"
model = "builtin:tree"
position = [70.0, 70.0]

[[objects]]
name = "rock"
model = "builtin:rock"
position = [40.0, 90.0]

[[lights]]
type = "ambient"
color = [0.5, 0.6, 0.8]
intensity = 0.4

[[lights]]
type = "directional"
direction = [0.3, 0.6, -0.6]
color = [1.0, 0.9, 0.8]
intensity = 1.0

[[cameras]]
name = "main"
eye = [64.0, -20.0, 60.0]
target = [64.0, 64.0, 20.0]
{extra}"""

RIDER = """\
[[riders]]
name = "rider"
position = [60.0, 60.0]
clip = "ride"
"""


def write_hill(folder, n: int = 33, spacing: float = 4.0) -> None:
    y, x = np.mgrid[0:n, 0:n] * spacing
    z = 30.0 - 0.3 * y + 3.0 * np.sin(x / 15.0) + 2.0 * np.cos(y / 9.0) + 6.0 * np.exp(-((x - 64) ** 2 + (y - 40) ** 2) / 60.0)
    np.savez(folder / "hill.npz", z=z, dx=np.float64(spacing))


@pytest.fixture
def small_scene(tmp_path):
    """``small_scene(riders=True, extra="")`` -> path of a small scene TOML in a fresh folder."""
    count = [0]

    def make(riders: bool = True, extra: str = "", text: str | None = None):
        count[0] += 1
        d = tmp_path / f"scene{count[0]}"
        d.mkdir()
        write_hill(d)
        p = d / "small.toml"
        p.write_text(text if text is not None else SMALL_SCENE.format(riders=RIDER if riders else "", extra=extra))
        return p

    return make


def mini_bundle_parts(net) -> tuple[dict, dict]:
    """``(manifest, arrays)`` of a minimal bundle of ``net`` (terrain, a flat light map, one camera):
    what tests of one stored member add theirs to before ``write_bundle``."""
    arrays = {"terrain/control_points": net.control_points, "terrain/uv": net.uv,
              "lightmap/atlas": np.full((20, 20, 3), 0.5, np.float32), "lightmap/rects": net.lightmap_rect}
    man = {"name": "mini", "terrain": {"name": "mini", "tol": net.tol}, "lights": {},
           "cameras": [{"name": "c", "eye": [-4.0, -6.0, 14.0], "target": [16.0, 16.0, 0.0], "up": [0.0, 0.0, 1.0],
                        "fov_y": 60.0, "near": 0.1, "far": 200.0, "ortho_height": None}],
           "lightmap": {"res": 8, "gutter": 1}}
    return man, arrays
