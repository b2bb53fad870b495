"""Small nets for terrain tests (generated, deterministic)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from piste.terrain import PatchNet

DATA = Path(os.environ.get("PISTE_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))
TEAPOT = str(DATA / "patches" / "teapot.bpt")


def grid_net(rows: int, cols: int, seed: int = 0, size: float = 10.0, offset=(0.0, 0.0, 0.0), flips=True) -> PatchNet:
    """A random C0 height-field-like net of ``rows x cols`` patches; with ``flips`` some patches
    have their parameter directions reversed or swapped, so edges are traversed both ways."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0 : 3 * rows + 1, 0 : 3 * cols + 1] * (size / 3)
    z = rng.normal(0, size * 0.2, x.shape) + 0.05 * x
    g = np.stack([x, y, z], -1) + np.asarray(offset)
    net = PatchNet.from_control_grid(g)
    if not flips:
        return net
    cp = net.control_points.copy()
    kind = rng.integers(0, 4, len(cp))
    cp[kind == 1] = cp[kind == 1][:, ::-1]  # reverse u
    cp[kind == 2] = cp[kind == 2][:, :, ::-1]  # reverse v
    cp[kind == 3] = cp[kind == 3].transpose(0, 2, 1, 3)  # swap u and v
    return PatchNet(cp)
