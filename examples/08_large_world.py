"""A large world in miniature
==========================

A large world in miniature: a GeoTIFF DEM, a tiled build (locally and on a Dask LocalCluster),
and a streamed flight across it.

Writes ``dem.tif`` (a synthetic range, 10 m pixels, georeferenced in UTM metres, with a block of
nodata samples), a scene that names it with ``tiles = "range.tiles"``, then runs
``piste build`` (fit, bake and visibility per tile: 48 x 48 patches in 3 x 3 tiles), again with
``--dask local`` into a second folder (the tiles come out byte-identical), and ``piste render
range.tiles`` (a flight at 100 m/s, tiles paged in and out under a 16 MiB budget).  Nothing is
fetched from the network.  Outputs go to ``$PISTE_EXAMPLE_OUT`` (default ``out/examples``).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from piste.cli import main as piste
from piste.formats.geotiff import read_geotiff, write_geotiff
from piste.pipeline.tiled_build import SyntheticSource

SCENE = """\
name = "range"

[terrain]
source = "dem.tif"          # spacing, nodata and units come from the GeoTIFF's tags
nodata = "nearest"
samples_per_patch = 3
tiles = "range.tiles"
tile_patches = 16

[lightmap]
res = 3

[visibility]
cell = 240.0
"""


def _files(root: Path) -> dict:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def main(argv: list[str]) -> int:
    out = Path(os.environ.get("PISTE_EXAMPLE_OUT", "out/examples")) / "large_world"
    out.mkdir(parents=True, exist_ok=True)
    n = 3 * 48 + 1
    z = SyntheticSource((n, n), (10.0, 10.0), seed=7, relief=900.0, wavelength=900.0).window(slice(0, n), slice(0, n))
    z[40:46, 90:100] = -9999.0  # a hole in the survey
    write_geotiff(out / "dem.tif", z, 10.0, origin=(386_000.0, 5_112_000.0), nodata=-9999.0, epsg=32632)
    dem = read_geotiff(out / "dem.tif")
    print(f"dem.tif: {dem.z.shape[1]} x {dem.z.shape[0]} samples of {dem.spacing[0]:g} m at "
          f"E {dem.origin[0]:.0f} N {dem.origin[1]:.0f}, {dem.mask.sum()} nodata samples filled, "
          f"heights {dem.z.min():.0f}..{dem.z.max():.0f} {dem.vertical_units}s")
    (out / "range.toml").write_text(SCENE)

    if piste(["build", str(out / "range.toml"), "--quiet"]):
        return 1
    if piste(["build", str(out / "range.toml"), "--quiet", "--dask", "local", "--workers", "2",
              "--out", str(out / "range-dask.tiles")]):
        return 1
    same = _files(out / "range.tiles") == _files(out / "range-dask.tiles")
    print(f"Dask tiles byte-identical to the local build: {same}")
    if not same:
        return 1
    rc = piste(["render", str(out / "range.tiles"), "--out", str(out / "flight.png"), "--frames", "8",
                "--size", "320", "224", "--budget", "16", "--quiet"])
    return rc


if __name__ == "__main__":
    if rc := main(sys.argv):  # exit only on failure: the docs gallery runs this file in-process
        sys.exit(rc)
