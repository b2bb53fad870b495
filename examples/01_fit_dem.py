"""Fit a patch net to a real DEM
=============================

Fit a Bézier patch net to a real DEM and report how well it fits.

Usage: python examples/01_fit_dem.py [samples_per_patch]

The DEM is ``jacksboro_fault_dem.npz``, which ships inside matplotlib (344 x 403 samples at
3 arc-seconds, heights in metres).  The global least-squares fit shares every boundary control
point between neighbouring patches, so the net is C0 with zero seam gap; the C1 fit removes the
slope jumps across seams at some cost in RMSE.  Then the exact surface is queried: heights at
random points and a few rays.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from matplotlib import cbook

from piste.terrain import fit_error, fit_heightfield, height_at, ray_intersect


def main(argv: list[str]) -> int:
    s = int(argv[1]) if len(argv) > 1 else 4
    data = cbook.get_sample_data("jacksboro_fault_dem.npz")
    z = np.asarray(data["elevation"], dtype=np.float64)
    lat = np.radians(0.5 * (float(data["ymin"]) + float(data["ymax"])))
    spacing = (float(data["dx"]) * 111_320.0 * np.cos(lat), float(data["dy"]) * 111_320.0)
    print(f"DEM {z.shape[0]} x {z.shape[1]} samples, spacing {spacing[0]:.1f} x {spacing[1]:.1f} m, "
          f"heights {z.min():.0f}..{z.max():.0f} m")
    for smooth in (False, "c1"):
        t0 = time.perf_counter()
        net = fit_heightfield(z, spacing, samples_per_patch=s, smooth=smooth, name="jacksboro")
        dt = time.perf_counter() - t0
        rmse, max_err, count = fit_error(net, z, spacing)
        py, px = net.grid_shape
        print(f"{'C1' if smooth else 'C0'} fit: {len(net):,} patches ({px} x {py}, {s}x{s} sample intervals each) "
              f"in {dt:.2f} s; RMSE {rmse:.2f} m, max error {max_err:.2f} m over {count:,} samples; "
              f"{len(net.shared_edges):,} shared edges, {len(net.boundary_edges)} on the rim")

    # exact-surface queries on the C0 net
    net = fit_heightfield(z, spacing, samples_per_patch=s)
    rng = np.random.default_rng(0)
    (x0, y0, _), (x1, y1, z1) = net.bounds
    xy = rng.uniform([x0, y0], [x1, y1], (100_000, 2))
    t0 = time.perf_counter()
    h, hit, _, _ = height_at(net, xy)
    dt = time.perf_counter() - t0
    print(f"height_at: {len(xy):,} points in {dt:.2f} s ({len(xy) / dt:,.0f}/s), all hit: {bool(hit.all())}")
    o = np.c_[xy[:1000], np.full(1000, z1 + 100.0)]
    r = ray_intersect(net, o, np.tile([0.3, 0.1, -1.0], (1000, 1)))
    print(f"ray_intersect: {r.hit.sum()} of 1,000 oblique rays from above hit; "
          f"first at ({r.position[0, 0]:.1f}, {r.position[0, 1]:.1f}, {r.position[0, 2]:.1f}) m")
    return 0


if __name__ == "__main__":
    if rc := main(sys.argv):  # exit only on failure: the docs gallery runs this file in-process
        sys.exit(rc)
